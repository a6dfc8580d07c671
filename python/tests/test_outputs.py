"""`substep.run(config, out_dir=d)` writes what `substep run config --out d2` writes: the same
file names, the same bytes in every CSV table and figure, and the same summary (apart from the
wall-clock timings and the folder's name in the list of outputs), for every shipped example.

Both front ends call the library's `substep::output::RunFolder`; this test is what keeps a
front end from growing its own writer."""

import json
import re
from pathlib import Path

import pytest

import substep
from conftest import ROOT, run_cli, scaled_frame3d

EXAMPLES = sorted((ROOT / "examples").glob("*.toml"))
#: Summary keys measured on the wall clock (they differ between any two runs).
TIMINGS = {"wall_time_s", "us_per_step"}


def _files(d: Path):
    return sorted(p.name for p in d.iterdir())


def _summary(d: Path):
    s = json.loads((d / "summary.json").read_text())
    for k in TIMINGS:
        assert isinstance(s.pop(k), float), k
    s["outputs"] = [Path(p).name for p in s["outputs"]]
    if s.get("reduction"):
        # the reduction's own timings
        assert isinstance(s["reduction"].pop("seconds"), float)
        if s["reduction"].get("check"):
            assert isinstance(s["reduction"]["check"].pop("full_run_seconds"), float)
    return s


def test_every_shipped_example_is_covered():
    names = {p.stem for p in EXAMPLES}
    # the examples the docs walk through: a new one is picked up by the glob, a renamed one fails here
    assert {"default", "tmd_substructure", "yielding_building", "yielding_building_cr", "hinged_frame"} <= names
    assert len(EXAMPLES) >= 10


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda p: p.stem)
def test_python_writes_the_same_output_folder_as_the_cli(example, cli, tmp_path):
    d_cli, d_py = tmp_path / "cli", tmp_path / "py"
    if example.stem == "frame3d_reduced":
        example = scaled_frame3d(tmp_path)
    proc = run_cli(cli, "run", str(example), "--out", str(d_cli), "--quiet")
    assert proc.returncode == 0, proc.stderr
    result = substep.run(example, out_dir=d_py)
    assert result.completed

    names = _files(d_cli)
    assert names == _files(d_py)
    assert "history.csv" in names and "summary.json" in names
    assert [Path(p).name for p in result.outputs] == _summary(d_cli)["outputs"]
    figures = [n for n in names if n.endswith((".png", ".svg", ".pdf"))]
    # figures unless the example turns them off
    plots_off = re.search(r"^plots\s*=\s*false", example.read_text(), re.M) is not None
    assert bool(figures) != plots_off, names
    for name in names:
        if name == "summary.json":
            continue
        a, b = (d_cli / name).read_bytes(), (d_py / name).read_bytes()
        assert a == b, f"{example.stem}/{name}: {len(a)} bytes from the CLI, {len(b)} from Python"
    assert _summary(d_cli) == _summary(d_py)
    # the in-memory history is the file's
    assert result.history.names == (d_py / "history.csv").read_text().split("\n", 1)[0].split(",")


def test_output_options_follow_the_cli_flags(cli, tmp_path):
    example = ROOT / "examples" / "tmd_substructure.toml"
    d_cli, d_py = tmp_path / "cli", tmp_path / "py"
    proc = run_cli(cli, "run", str(example), "--out", str(d_cli), "--quiet", "--plot-format", "svg", "--format", "mat")
    assert proc.returncode == 0, proc.stderr
    substep.run(example, out_dir=d_py, plot_format="svg", format="mat")
    names = _files(d_cli)
    assert names == _files(d_py)
    assert "results.mat" in names and any(n.endswith(".svg") for n in names)
    assert not any(n.endswith(".png") for n in names)
    for name in names:
        if name.endswith((".csv", ".svg")):
            assert (d_cli / name).read_bytes() == (d_py / name).read_bytes(), name

    d_cli2, d_py2 = tmp_path / "cli2", tmp_path / "py2"
    proc = run_cli(cli, "run", str(example), "--out", str(d_cli2), "--quiet", "--no-plots")
    assert proc.returncode == 0, proc.stderr
    substep.run(example, out_dir=d_py2, plots=False)
    assert _files(d_cli2) == _files(d_py2)
    assert not any(n.endswith(".png") for n in _files(d_py2))


def test_bad_output_options_are_refused_naming_them(tmp_path):
    example = ROOT / "examples" / "tmd_substructure.toml"
    with pytest.raises(substep.ConfigError, match="plot_format.*unknown format"):
        substep.run(example, out_dir=tmp_path / "a", plot_format="gif")
    with pytest.raises(substep.ConfigError, match="format"):
        substep.run(example, out_dir=tmp_path / "b", format="xlsx")
    with pytest.raises(substep.ConfigError, match="give out_dir"):
        substep.run(example, plots=False)
    with pytest.raises(TypeError, match="plots: must be a bool"):
        substep.run(example, out_dir=tmp_path / "c", plots="no")
    with pytest.raises(TypeError, match="out_dir: must be a path"):
        substep.run(example, out_dir=3)
    # refused before anything is written
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
    # a folder that cannot be made: a file in the way
    (tmp_path / "file").write_text("x")
    with pytest.raises(substep.ConfigError, match="cannot create the output directory"):
        substep.run(example, out_dir=tmp_path / "file" / "out")


def test_result_plot_gives_the_cli_figures_and_jupyter_shows_them(cli, tmp_path):
    example = ROOT / "examples" / "default.toml"
    d_cli = tmp_path / "cli"
    proc = run_cli(cli, "run", str(example), "--out", str(d_cli), "--quiet")
    assert proc.returncode == 0, proc.stderr
    cli_figures = sorted(p.name for p in d_cli.iterdir() if p.suffix == ".png")
    assert {"displacement.png", "hysteresis.png", "reference.png"} <= set(cli_figures)

    # without out_dir (drawn from a rerun) and with it (read from the folder): the CLI's bytes
    for result in (substep.run(example), substep.run(example, out_dir=tmp_path / "py")):
        figures = result.plot()
        assert sorted(f + ".png" for f in figures.names()) == cli_figures
        for f in figures:
            assert f.data == (d_cli / f"{f.name}.png").read_bytes(), f.name
    assert figures["hysteresis"].name == "hysteresis"
    with pytest.raises(KeyError, match="no such figure"):
        figures["nothing"]
    svg = substep.run(example).plot(format="svg")["displacement"]
    assert svg.data.startswith(b"<svg")
    assert svg.save(tmp_path / "d.svg") and (tmp_path / "d.svg").read_bytes() == svg.data

    # Jupyter's formatter: a PNG figure is an image/png bundle, SVG an image/svg+xml one, the
    # list of figures an HTML page of inline images
    from IPython.core.formatters import DisplayFormatter

    fmt = DisplayFormatter()
    bundle, _ = fmt.format(figures["reference"])
    assert bundle["image/png"] == figures["reference"].data
    bundle, _ = fmt.format(svg)
    assert bundle["image/svg+xml"].startswith("<svg")
    bundle, _ = fmt.format(figures)
    assert bundle["text/html"].count("<img") == len(figures)

    with pytest.raises(substep.ConfigError, match="format"):
        figures = substep.run(example).plot(format="gif")
