"""HDF5 and MATLAB result files read back equal to the CSV tables of the same run.

Runs the `substep` CLI (`SUBSTEP_BIN` or target/release/substep) on a short virtual substructure
test and reads results.h5 with h5py, the level-5 results.mat (`--format mat`, every build) with
SciPy's `scipy.io.loadmat`, the v7.3 results.mat (`--format mat73`)
with the two MATLAB v7.3 readers on PyPI (mat73, hdf5storage).
"""

import csv as csvlib
import json
import os
import pathlib
import subprocess

import numpy as np
import pandas as pd
import pytest
from conftest import read_csv_exact, run_cli

h5py = pytest.importorskip("h5py")
mat73 = pytest.importorskip("mat73")
hdf5storage = pytest.importorskip("hdf5storage")
scipy_io = pytest.importorskip("scipy.io")

ROOT = pathlib.Path(__file__).resolve().parents[2]
BIN = pathlib.Path(os.environ.get("SUBSTEP_BIN", ROOT / "target" / "release" / "substep"))
TABLES = ["history", "substeps", "response", "ground_motion", "fourier", "spectrum"]


def short_config(tmp_path):
    """The embedded default example, shortened to 2 s (keeps its substructure, noise, reference)."""
    text = (ROOT / "examples" / "default.toml").read_text()
    text = text.replace("duration = 20.0", "duration = 2.0")
    assert "duration = 2.0" in text
    path = tmp_path / "short.toml"
    path.write_text(text)
    return path


def run(tmp_path, fmt):
    if not BIN.exists():
        pytest.skip(f"{BIN} not built (cargo build --release)")
    out = tmp_path / fmt
    proc = subprocess.run(
        [str(BIN), "run", str(short_config(tmp_path)), "--out", str(out), "--no-plots", "--quiet",
         "--format", fmt],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    return out


def csv(out, table):
    """The table as {column: array}, parsed with Python's float() (exact for round-trip text)."""
    with open(out / f"{table}.csv", newline="") as f:
        rows = list(csvlib.reader(f))
    data = np.array([[float(x) for x in r] for r in rows[1:]]).reshape(-1, len(rows[0]))
    return pd.DataFrame(data, columns=rows[0])


def tables_in(out):
    return [t for t in TABLES if (out / f"{t}.csv").exists()]


def test_hdf5_reads_back_equal_to_the_csv(tmp_path):
    out = run(tmp_path, "hdf5")
    assert set(tables_in(out)) >= {"history", "substeps", "response"}
    with h5py.File(out / "results.h5", "r") as f:
        for table in tables_in(out):
            frame = csv(out, table)
            group = f[table]
            assert [c.decode() if isinstance(c, bytes) else c for c in group.attrs["columns"]] == list(frame.columns)
            for col in frame.columns:
                ds = group[col]
                assert ds.dtype == np.float64 and ds.ndim == 1
                assert ds.compression == "gzip" and ds.chunks is not None
                np.testing.assert_array_equal(ds[:], frame[col].to_numpy(), err_msg=f"{table}/{col}")
        assert f["history/u1"].attrs["units"] == "m"
        assert f["history/t"].attrs["units"] == "s"
        assert f["history/fc1"].attrs["units"] == "N"
        assert f["response/E_kinetic"].attrs["units"] == "J"
        summary = json.loads(f.attrs["summary"])
        assert summary == json.loads((out / "summary.json").read_text())
        assert summary["completed"] is True and summary["steps_done"] == 200
        assert "[substructure]" in f.attrs["config"]


def test_mat_level5_from_the_default_build_reads_back_equal_to_the_csv(tmp_path):
    """`--format mat` needs no HDF5: scipy.io.loadmat reads every table, the units, the summary
    and the config with the numbers of the CSV files."""
    out = run(tmp_path, "mat")
    path = out / "results.mat"
    head = path.read_bytes()[:128]
    assert head.startswith(b"MATLAB 5.0 MAT-file, Platform: GLNXA64, Created on: ")
    assert head[124:128] == b"\x00\x01IM"
    m = scipy_io.loadmat(str(path), simplify_cells=True)
    raw = scipy_io.loadmat(str(path))  # MATLAB's view: 1x1 structs of N x 1 double columns
    assert set(tables_in(out)) >= {"history", "substeps", "response"}
    for table in tables_in(out):
        frame = csv(out, table)
        assert list(m[table].keys()) == list(frame.columns)
        for col in frame.columns:
            expected = frame[col].to_numpy()
            column = raw[table][0, 0][col]
            assert column.dtype == np.float64 and column.shape == (len(expected), 1), (table, col, column.shape)
            np.testing.assert_array_equal(column[:, 0], expected, err_msg=f"loadmat {table}.{col}")
    assert m["units"]["history"]["u1"] == "m"
    assert m["units"]["history"]["t"] == "s"
    assert m["units"]["history"]["fc1"] == "N"
    assert m["units"]["response"]["E_kinetic"] == "J"
    assert json.loads(m["summary"]) == json.loads((out / "summary.json").read_text())
    assert "[substructure]" in m["config"]


def test_mat_v73_reads_back_equal_to_the_csv(tmp_path):
    out = run(tmp_path, "mat73")
    path = out / "results.mat"
    head = path.read_bytes()[:128]
    assert head.startswith(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: ")
    assert head[124:128] == b"\x00\x02IM"
    m = mat73.loadmat(str(path))
    s = hdf5storage.loadmat(str(path))
    for table in tables_in(out):
        frame = csv(out, table)
        assert sorted(m[table].keys()) == sorted(frame.columns)
        for col in frame.columns:
            expected = frame[col].to_numpy()
            np.testing.assert_array_equal(np.ravel(m[table][col]), expected, err_msg=f"mat73 {table}.{col}")
            # hdf5storage: a struct array of one element whose fields are MATLAB's N x 1 columns
            field = s[table][col][0]
            assert np.shape(field) == (len(expected), 1), (table, col, np.shape(field))
            np.testing.assert_array_equal(np.ravel(field), expected, err_msg=f"hdf5storage {table}.{col}")
    assert json.loads(m["summary"]) == json.loads((out / "summary.json").read_text())
    assert "[substructure]" in m["config"]


def test_python_save_writes_the_cli_containers(tmp_path):
    """Result.save("x.h5" | "x.mat") holds the same tables as the CLI's results.h5 / results.mat."""
    substep = pytest.importorskip("substep")
    out = run(tmp_path, "hdf5")
    result = substep.run(short_config(tmp_path))
    h5 = tmp_path / "py.h5"
    assert result.save(h5) == [str(h5)]
    with h5py.File(h5, "r") as mine, h5py.File(out / "results.h5", "r") as cli:
        for table in ("history", "substeps", "response"):
            assert list(mine[table].attrs["columns"]) == list(cli[table].attrs["columns"])
            for col in cli[table].attrs["columns"]:
                np.testing.assert_array_equal(mine[table][col][:], cli[table][col][:], err_msg=f"{table}/{col}")
                assert mine[table][col].attrs["units"] == cli[table][col].attrs["units"]
        assert json.loads(mine.attrs["summary"])["steps_done"] == 200
        # and equal to the history the run returned, column by column, to the bit
        columns = [str(c) for c in mine["history"].attrs["columns"]]
        assert columns == [n.rsplit(" [", 1)[0] for n in result.history.names]
        for col, name in zip(columns, result.history.names):
            np.testing.assert_array_equal(mine["history"][col][:], result.history[name], err_msg=col)
    mat = tmp_path / "py.mat"
    result.save(mat)
    m = scipy_io.loadmat(str(mat), simplify_cells=True)
    for name in result.history.names:
        field = "".join(c if c.isalnum() else "_" for c in name.rsplit(" [", 1)[0])
        np.testing.assert_array_equal(np.ravel(m["history"][field]), result.history[name], err_msg=name)


def test_benchmark_traces_in_hdf5_and_mat_score_the_run_again(cli, tmp_path):
    # Issue 28: `benchmark rths --out DIR --format hdf5|mat` gathers the trace CSV files into
    # traces.h5 / traces.mat: every column equal to the CSV's, with its unit, and J2 / J4
    # recomputed from the container equal to the run's unrounded J_raw to 1e-9.
    args = ("benchmark", "rths", "--case", "1", "--controller", "amb")
    p = run_cli(cli, *args, "--json")
    assert p.returncode == 0, p.stderr
    raw = json.loads(p.stdout)["J_raw"]

    def scores(target, measured, reference1):
        j2 = 100 * np.std(measured - target) / np.std(target)
        j4 = 100 * np.std(measured - reference1) / np.std(reference1)
        return j2, j4

    out = tmp_path / "h"
    p = run_cli(cli, *args, "--no-plots", "--out", str(out), "--format", "hdf5")
    assert p.returncode == 0, p.stderr
    assert "traces.h5" in p.stdout
    csv = read_csv_exact(out / "trace_case1.csv")
    with h5py.File(out / "traces.h5", "r") as f:
        group = f["trace_case1"]
        names = [str(c) for c in group.attrs["columns"]]
        assert names == [c.rsplit(" [", 1)[0] for c in csv.columns]
        for name, header in zip(names, csv.columns):
            np.testing.assert_array_equal(group[name][:], csv[header].to_numpy())
            assert group[name].attrs["units"] == header.rsplit("[", 1)[1].rstrip("]")
        j2, j4 = scores(group["target y_n"][:], group["measured x_m"][:], group["reference floor 1"][:])
        assert abs(j2 - raw[1]) < 1e-9 and abs(j4 - raw[3]) < 1e-9, (j2, j4, raw)
        assert json.loads(f.attrs["summary"])["J_raw"] == raw
        assert "floors_case1" in f
    out = tmp_path / "m"
    p = run_cli(cli, *args, "--no-plots", "--out", str(out), "--format", "mat")
    assert p.returncode == 0, p.stderr
    m = scipy_io.loadmat(out / "traces.mat", squeeze_me=True)
    trace = m["trace_case1"]
    j2, j4 = scores(trace["target_y_n"].item(), trace["measured_x_m"].item(), trace["reference_floor_1"].item())
    assert abs(j2 - raw[1]) < 1e-9 and abs(j4 - raw[3]) < 1e-9, (j2, j4, raw)
    assert m["units"]["trace_case1"].item()["actuator_force_F"].item() == "N"
    bad = run_cli(cli, *args, "--json", "--format", "hdf5")
    assert bad.returncode == 2 and "--format: writes the traces" in bad.stderr


def test_long_tables_cross_the_block_boundaries(tmp_path):
    """Tables longer than the writers' 8192-row blocks (and not a multiple of them), a second
    table of another width after the first, and a table of no rows: every value read back
    by h5py, mat73 and hdf5storage equal to the CSV's (the .h5 grows its datasets a block at a
    time, the .mat streams each column from a block-wise scratch copy)."""
    substep = pytest.importorskip("substep")
    rng = np.random.default_rng(41)
    tables = {
        "history": (["t [s]", "u1 [m]", "F1 [N]"], rng.standard_normal((20001, 3))),
        "substeps": (["t [s]", "x_c1 [m]"], rng.standard_normal((8192 * 2 + 1, 2))),
        "response": (["f [Hz]", "amplitude [m]"], np.empty((0, 2))),
    }
    for name, (header, values) in tables.items():
        with open(tmp_path / f"{name}.csv", "w", newline="") as f:
            f.write(",".join(header) + "\n")
            for row in values:
                f.write(",".join(repr(float(v)) for v in row) + "\n")
    summary = json.dumps({"steps_done": 20000})
    h5 = substep._substep.write_container(str(tmp_path), "hdf5", summary, "")
    with h5py.File(h5, "r") as f:
        for name, (header, values) in tables.items():
            cols = [c.rsplit(" [", 1)[0] for c in header]
            assert [str(c) for c in f[name].attrs["columns"]] == cols
            for k, col in enumerate(cols):
                np.testing.assert_array_equal(f[name][col][:], values[:, k], err_msg=f"{name}/{col}")
        assert f["history/u1"].chunks == (8192,) and f["history/u1"].compression == "gzip"
        assert json.loads(f.attrs["summary"]) == {"steps_done": 20000}
    mat = substep._substep.write_container(str(tmp_path), "mat73", summary, "")
    assert sorted(os.listdir(tmp_path)) == sorted([f"{n}.csv" for n in tables] + ["results.h5", "results.mat"]), \
        "the scratch copy is removed"
    with open(mat, "rb") as f:
        assert f.read(19) == b"MATLAB 7.3 MAT-file"
    m = mat73.loadmat(mat)
    s = hdf5storage.loadmat(mat)
    for name, (header, values) in tables.items():
        if len(values) == 0:
            continue
        for k, c in enumerate(header):
            col = c.rsplit(" [", 1)[0]
            np.testing.assert_array_equal(np.ravel(m[name][col]), values[:, k], err_msg=f"mat73 {name}.{col}")
            field = s[name][col]
            field = field[0] if field.dtype == object else field
            np.testing.assert_array_equal(np.ravel(field), values[:, k], err_msg=f"hdf5storage {name}.{col}")
    assert json.loads(m["summary"]) == {"steps_done": 20000}
