"""`substep.run` against the CLI: the same summary (every number to the last bit, timings
aside), the same history and sub-step rows, the same one-line errors."""

import json
import signal
import threading
import time
import _thread

import numpy as np
import pandas as pd
import pytest

import substep
from conftest import read_csv_exact, run_cli, scaled_frame3d

TIMING = ("wall_time_s", "us_per_step")


def comparable(summary: dict) -> dict:
    """The summary without its timings and the list of files written."""
    return {k: v for k, v in summary.items() if k not in TIMING + ("outputs",)}


@pytest.fixture(scope="module")
def default_run(cli, root, tmp_path_factory, request):
    """The default example run by the CLI (into a temp dir) and by Python, both from the repo root."""
    out = tmp_path_factory.mktemp("cli_default")
    p = run_cli(cli, "run", "examples/default.toml", "--out", str(out), "--quiet", "--no-plots")
    assert p.returncode == 0, p.stderr
    cwd = request.config.invocation_params.dir
    import os

    os.chdir(root)
    try:
        result = substep.run("examples/default.toml")
    finally:
        os.chdir(cwd)
    return out, result


def test_summary_equals_the_cli_summary(default_run):
    out, result = default_run
    cli_summary = json.loads((out / "summary.json").read_text())
    assert comparable(result.summary) == comparable(cli_summary)
    # The numbers that matter, bit for bit (== on floats parsed from the shortest round-trip text).
    ref, cli_ref = result.summary["reference"], cli_summary["reference"]
    assert ref["max_displacement_error"] == cli_ref["max_displacement_error"]
    assert 0.001 < ref["max_displacement_error"] < 0.05
    assert result.summary["outputs"] == []
    assert result.completed and result.error is None


def test_to_pandas_equals_history_csv(default_run):
    out, result = default_run
    csv = read_csv_exact(out / "history.csv")
    df = result.to_pandas()
    assert list(df.columns) == list(csv.columns)
    pd.testing.assert_frame_equal(df, csv.astype(float), check_exact=True)
    sub = read_csv_exact(out / "substeps.csv")
    pd.testing.assert_frame_equal(result.substeps.to_pandas(), sub.astype(float), check_exact=True)
    resp = read_csv_exact(out / "response.csv")
    pd.testing.assert_frame_equal(result.response.to_pandas(), resp.astype(float), check_exact=True)


def test_arrays_are_the_history_columns(default_run):
    _, r = default_run
    steps = r.summary["steps"]
    assert r.t.shape == (steps + 1,) and r.t[0] == 0.0 and r.t[-1] == pytest.approx(20.0, abs=0)
    assert r.u.shape == (steps + 1, 1)
    np.testing.assert_array_equal(r.u[:, 0], r.history["u1"])
    np.testing.assert_array_equal(r.coupling_force[:, 0], r.history["fc1"])
    np.testing.assert_array_equal(r.measured_displacement[:, 0], r.history["dm1"])
    np.testing.assert_array_equal(r.reference[:, 0], r.history["uref1"])
    # The summary's peak is the largest |u| of the array, at its time.
    i = int(np.argmax(np.abs(r.u[:, 0])))
    assert r.summary["peaks"][0]["u"]["max_abs"] == abs(r.u[i, 0])
    assert r.summary["peaks"][0]["u"]["t"] == i * r.summary["dt"]
    assert len(r.substeps) == 4 * steps


def test_save_writes_the_cli_files(default_run, tmp_path):
    out, result = default_run
    written = result.save(tmp_path / "saved")
    for name in ("history.csv", "substeps.csv", "response.csv"):
        assert (tmp_path / "saved" / name).read_bytes() == (out / name).read_bytes(), name
    saved = json.loads((tmp_path / "saved" / "summary.json").read_text())
    assert comparable(saved) == comparable(json.loads((out / "summary.json").read_text()))
    assert saved["outputs"] == written
    result.save(tmp_path / "h.csv")
    assert (tmp_path / "h.csv").read_bytes() == (out / "history.csv").read_bytes()


def test_unknown_save_format_names_the_suffix(default_run, tmp_path):
    _, result = default_run
    with pytest.raises(substep.ConfigError, match="unknown output format '.xyz'"):
        result.save(tmp_path / "r.xyz")


def test_toml_text_and_dict_give_the_same_run(root, default_run):
    tomllib = pytest.importorskip("tomllib")
    _, by_path = default_run
    text = (root / "examples" / "default.toml").read_text()
    by_text = substep.run(text)
    by_dict = substep.run(tomllib.loads(text))
    for r, name in ((by_text, "<string>"), (by_dict, "<dict>")):
        assert r.summary["config"] == name
        assert {**comparable(r.summary), "config": None} == {**comparable(by_path.summary), "config": None}
        np.testing.assert_array_equal(r.history.values, by_path.history.values)


def test_a_dict_config_error_names_the_key_path(root):
    """A config given as a dict: the error names the key path in the dict, not a line of the
    TOML text the package wrote from it."""
    tomllib = pytest.importorskip("tomllib")
    config = tomllib.loads((root / "examples" / "default.toml").read_text())
    config["integrator"]["dtt"] = 0.01
    with pytest.raises(substep.ConfigError, match=r"^<dict>: integrator\.dtt: unknown field `dtt`"):
        substep.run(config)
    del config["integrator"]["dtt"]
    config["substructure"]["specimen"][0]["stifness"] = 1.0
    with pytest.raises(substep.ConfigError, match=r"^<dict>: substructure\.specimen\[0\]\.stifness: unknown field"):
        substep.run(config)


def test_monolithic_run_has_no_coupling_arrays(cli, root, tmp_path, monkeypatch):
    monkeypatch.chdir(root)
    r = substep.run("examples/monolithic_tmd.toml")
    assert r.coupling_force is None and r.substeps is None and r.reference is None
    p = run_cli(cli, "run", "examples/monolithic_tmd.toml", "--out", str(tmp_path), "--quiet", "--no-plots")
    assert p.returncode == 0, p.stderr
    assert comparable(r.summary) == comparable(json.loads((tmp_path / "summary.json").read_text()))
    csv = read_csv_exact(tmp_path / "history.csv")
    pd.testing.assert_frame_equal(r.to_pandas(), csv.astype(float), check_exact=True)


def test_bad_input_raises_config_error_with_the_cli_message(cli, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.toml").write_text(
        "[structure.sdof]\nmass = 1.0\nstiffness = -4.0\ndamping = 0.0\n"
        "[ground_motion]\ngenerator = \"sine\"\namplitude = 1.0\nfrequency = 1.0\nduration = 1.0\n"
        "[integrator]\nscheme = \"average_acceleration\"\ndt = 0.01\n"
    )
    p = run_cli(cli, "run", "bad.toml", "--quiet", "--no-plots", cwd=tmp_path)
    assert p.returncode == 2
    message = p.stderr.strip()
    assert message.startswith("error: bad.toml")
    with pytest.raises(substep.ConfigError) as e:
        substep.run("bad.toml")
    assert "error: " + str(e.value) == message
    with pytest.raises(substep.ConfigError, match="missing.toml"):
        substep.run("missing.toml")
    with pytest.raises(TypeError):
        substep.run(42)


def test_a_stopped_run_raises_run_error_with_the_cli_message(cli, root, tmp_path, monkeypatch):
    text = (root / "examples" / "default.toml").read_text()
    text += "\n[substructure.limits]\ndisplacement = 0.05\nramp_time = 0.2\n"
    (tmp_path / "limits.toml").write_text(text)
    monkeypatch.chdir(tmp_path)
    p = run_cli(cli, "run", "limits.toml", "--out", "out", "--quiet", "--no-plots", cwd=tmp_path)
    assert p.returncode == 1
    with pytest.raises(substep.RunError) as e:
        substep.run("limits.toml")
    assert "error: " + str(e.value) == p.stderr.strip()
    r = e.value.result
    cli_summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert comparable(r.summary) == comparable(cli_summary)
    assert not r.completed and r.summary["ramp_substeps"] == 80
    sub = read_csv_exact(tmp_path / "out" / "substeps.csv")
    pd.testing.assert_frame_equal(r.substeps.to_pandas(), sub.astype(float), check_exact=True)
    r2 = substep.run("limits.toml", raise_on_stop=False)
    assert r2.error == str(e.value)


DAMPER = """
[structure]
mass = [[2.0e5, 0.0, 0.0], [0.0, 2.0e5, 0.0], [0.0, 0.0, 2.0e5]]
stiffness = [[4.0e8, -2.0e8, 0.0], [-2.0e8, 4.0e8, -2.0e8], [0.0, -2.0e8, 2.0e8]]
[structure.rayleigh]
zeta = 0.02
[ground_motion]
generator = "sine_sweep"
amplitude = 2.0
f0 = 0.5
f1 = 5.0
duration = 8.0
[integrator]
scheme = "average_acceleration"
dt = 0.01
[substructure]
coupling_dofs = [1]
substeps = 10
[[substructure.specimen]]
kind = "linear_sdof"
dof = 1
stiffness = 0.0
damping = DAMPING
[substructure.actuator]
kind = "ideal"
delay = 0.01
[substructure.error_force]
kind = "pid"
p = 1.0
"""


def test_a_diverging_run_raises_run_error_and_says_diverged(cli, tmp_path, monkeypatch):
    # 5 MN s/m at k_sub = 10: G_cc c / dtau > 1/2, the sub-step iteration itself diverges.
    (tmp_path / "div.toml").write_text(DAMPER.replace("DAMPING", "5.0e6"))
    monkeypatch.chdir(tmp_path)
    p = run_cli(cli, "run", "div.toml", "--out", "out", "--quiet", "--no-plots", cwd=tmp_path)
    assert p.returncode == 1
    cli_summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert cli_summary["diverged"] is True and cli_summary["completed"] is False
    with pytest.raises(substep.RunError, match="diverged"):
        substep.run("div.toml")
    r = substep.run("div.toml", raise_on_stop=False)
    assert r.summary["diverged"] is True and not r.completed
    assert comparable(r.summary) == comparable(cli_summary)
    # The same test with half the damper is stable and says so.
    (tmp_path / "ok.toml").write_text(DAMPER.replace("DAMPING", "2.5e6"))
    ok = substep.run("ok.toml")
    assert ok.completed and ok.summary["diverged"] is False
    assert ok.summary["reference"]["max_displacement_error"] < 1.0


def test_the_stability_indicator_columns_and_summary_equal_the_cli(cli, root, tmp_path, monkeypatch):
    text = (root / "examples" / "default.toml").read_text()
    text += '\n[substructure.limits]\nstability = "warn"\n'
    (tmp_path / "stability.toml").write_text(text)
    monkeypatch.chdir(tmp_path)
    p = run_cli(cli, "run", "stability.toml", "--out", "out", "--quiet", "--no-plots", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    r = substep.run("stability.toml")
    assert r.history.names[-5:] == ["eta", "margin", "k_id1", "c_id1", "lag_id1"]
    csv = read_csv_exact(tmp_path / "out" / "history.csv")
    pd.testing.assert_frame_equal(r.to_pandas(), csv.astype(float), check_exact=True)
    cli_summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert comparable(r.summary) == comparable(cli_summary)
    st = r.summary["stability"]
    assert st["alarm"] is None and st["alarm_count"] == 0
    assert st["max_eta"] == np.nanmax(r.history["eta"])
    assert st["min_margin"] == np.nanmin(r.history["margin"])


def long_config(root) -> str:
    """The default example over 2000 s with 40 sub-steps per step: several seconds of work, long
    enough to be interrupted on any machine (the 4 sub-steps of the example ran 2000 s in about
    0.3 s, the time the interrupt takes to arrive)."""
    text = (root / "examples" / "default.toml").read_text()
    long = text.replace("duration = 20.0", "duration = 2000.0").replace("substeps = 4 ", "substeps = 40 ")
    assert long.count("2000.0") == 1 and "substeps = 40 " in long, "the default example changed"
    return long


def test_ctrl_c_interrupts_a_run(root):
    # A test run started as a background job inherits SIGINT ignored, and then interrupt_main
    # does nothing: give the interpreter its own handler, as an interactive Python has.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.3, _thread.interrupt_main)
    t0 = time.monotonic()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            substep.run(long_config(root))
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert time.monotonic() - t0 < 10


def test_the_gil_is_released_while_a_run_steps(root):
    text = (root / "examples" / "default.toml").read_text().replace("duration = 20.0", "duration = 100.0")
    ticks = []
    done = threading.Event()

    def count():
        while not done.is_set():
            ticks.append(time.monotonic())
            time.sleep(0.001)

    counter = threading.Thread(target=count)
    counter.start()
    try:
        t0 = time.monotonic()
        r = substep.run(text)
        t1 = time.monotonic()
    finally:
        done.set()
        counter.join(timeout=10)
    assert r.completed
    during = [t for t in ticks if t0 < t < t1]
    # A held GIL would let the counter run only at the signal checks (every 0.1 s).
    assert len(during) > 20 * (t1 - t0), (len(during), t1 - t0)


def test_help_is_useful():
    doc = substep.run.__doc__
    assert "ConfigError" in doc and "to_pandas" in doc and "Ctrl-C" in doc


def test_a_nonlinear_test_from_python_equals_the_cli_and_has_its_newton_reference(cli, root, tmp_path, monkeypatch):
    # The yielding building with a Bouc–Wen damper (docs/theory.md §14): same summary as the CLI,
    # its reference is the converged Newmark + Newton solution of the assembled structure.
    out = tmp_path / "cli"
    p = run_cli(cli, "run", "examples/yielding_building.toml", "--out", str(out), "--quiet", "--no-plots", cwd=root)
    assert p.returncode == 0, p.stderr
    cli_summary = json.loads((out / "summary.json").read_text())
    monkeypatch.chdir(root)
    r = substep.run("examples/yielding_building.toml")
    assert comparable(r.summary) == comparable(cli_summary)
    assert r.summary["reference"]["scheme"] == "newmark_newton"
    assert r.summary["reference"]["max_displacement_error"] < 0.03
    # A Newton iteration that cannot converge stops the run with exit 1 / RunError naming it.
    text = (root / "examples" / "yielding_building.toml").read_text()
    i, j = text.index("[substructure]"), text.index("[output]")
    mono = text[:i] + text[j:]
    mono = mono.replace('file = "records/elcentro.csv"', f'file = "{root / "examples" / "records" / "elcentro.csv"}"')
    mono = mono.replace("duration = 20.0", "duration = 20.0\nmax_iterations = 1")
    (tmp_path / "newton.toml").write_text(mono)
    p = run_cli(cli, "run", "newton.toml", "--out", "out", "--quiet", "--no-plots", cwd=tmp_path)
    assert p.returncode == 1
    assert "Newton–Raphson did not converge in 1 iterations" in p.stderr
    monkeypatch.chdir(tmp_path)
    with pytest.raises(substep.RunError, match="did not converge"):
        substep.run("newton.toml")


def test_a_reduced_structure_runs_from_python_as_from_the_cli(cli, root, tmp_path, monkeypatch):
    """`[structure.reduction]` (issue 42) through `substep.run`: examples/frame3d_reduced.toml
    scaled down to 120 DOFs gives the CLI's summary, reduction and check included, bit for bit."""
    (tmp_path / "reduced.toml").write_text(scaled_frame3d(tmp_path).read_text())
    monkeypatch.chdir(tmp_path)
    p = run_cli(cli, "run", "reduced.toml", "--out", "cli", "--quiet", "--no-plots", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    cli_summary = json.loads((tmp_path / "cli" / "summary.json").read_text())
    result = substep.run("reduced.toml")

    def untimed(reduction: dict) -> dict:
        r = {k: v for k, v in reduction.items() if k != "seconds"}
        r["check"] = {k: v for k, v in r["check"].items() if k != "full_run_seconds"}
        return r

    red = result.summary["reduction"]
    assert untimed(red) == untimed(cli_summary["reduction"])
    assert red["method"] == "ritz" and red["reduced_dofs"] == 14 and red["full_dofs"] == 120
    assert red["check"]["max_error"] <= red["error_estimate"] < 1e-2
    df = result.to_pandas()
    assert "u14" in df.columns and "u15" not in df.columns
