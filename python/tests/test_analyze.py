"""`substep.analyze` and `substep.benchmark` against the CLI: the same numbers (parsed from
the CLI's CSV / JSON, compared exactly)."""

import json

import numpy as np
import pandas as pd
import pytest

import substep
from conftest import read_csv_exact, run_cli


def test_stability_map_equals_stability_csv(cli, tmp_path):
    p = run_cli(cli, "analyze", "stability", "--k-sub", "1,3", "--omega", "0.1:3:12", "--vary", "zeta_s=0:0.5:4",
                "--eta-p", "0.5", "--out", str(tmp_path), "--quiet", "--no-plots")
    assert p.returncode == 0, p.stderr
    csv = read_csv_exact(tmp_path / "stability.csv")
    m = substep.analyze.stability(k_sub=[1, 3], omega=(0.1, 3, 12), vary=("zeta_s", (0, 0.5, 4)), eta_p=0.5)
    assert list(m) == list(csv.columns)
    for name in csv.columns:
        np.testing.assert_array_equal(m[name], csv[name].to_numpy(), err_msg=name)
    # ρ ≤ 1 somewhere and > 1 somewhere on this grid: the map is not trivial.
    assert m["rho"].min() < 1 < m["rho"].max()
    m2 = substep.analyze.stability(k_sub=[1, 3], omega="0.1:3:12", vary="zeta_s=0:0.5:4", eta_p=0.5)
    np.testing.assert_array_equal(m2["rho"], m["rho"])


def test_accuracy_equals_accuracy_csv(cli, tmp_path):
    p = run_cli(cli, "analyze", "accuracy", "--k-sub", "1,2", "--eta-t", "0.01,0.05", "--eta-p", "0,0.5",
                "--error-force", "pid:1", "--out", str(tmp_path), "--quiet", "--no-plots")
    assert p.returncode == 0, p.stderr
    csv = read_csv_exact(tmp_path / "accuracy.csv")
    a = substep.analyze.accuracy(k_sub=[1, 2], eta_t=[0.01, 0.05], eta_p=[0, 0.5], error_force="pid:1")
    assert list(a) == list(csv.columns)
    for name in csv.columns:
        np.testing.assert_array_equal(a[name], csv[name].to_numpy(dtype=float), err_msg=name)


def test_analysis_errors_name_the_parameter():
    with pytest.raises(substep.ConfigError, match="^vary: 'Omega' is the x axis already"):
        substep.analyze.stability(vary=("Omega", (0, 1, 3)))
    with pytest.raises(substep.ConfigError, match="^eta_t: 0.7 is outside"):
        substep.analyze.accuracy(eta_t=[0.7])
    with pytest.raises(substep.ConfigError, match="^case: unknown case 'big'"):
        substep.analyze.accuracy(case="big")


def test_rths_equals_the_cli_json(cli):
    p = run_cli(cli, "benchmark", "rths", "--case", "1", "--json")
    assert p.returncode == 0, p.stderr
    expected = json.loads(p.stdout)
    got = substep.benchmark.rths(case=1)
    for key in ("controller", "record", "intensity", "algorithm"):
        assert got[key] == expected[key], key
    assert got["cases"] == expected["cases"]
    assert 0 < got["cases"][0]["J4"] < 100
    with pytest.raises(substep.ConfigError, match="^intensity: must be a finite number >= 0"):
        substep.benchmark.rths(case=1, intensity=-1)


def test_rths_perturbed_plants_and_k_sub_series_equal_the_cli_json(cli, tmp_path):
    # The robustness study: perturbed plants of a seed, J statistics over the stable runs.
    p = run_cli(cli, "benchmark", "rths", "--case", "2", "--perturbed", "3", "--seed", "7", "--json")
    assert p.returncode == 0, p.stderr
    expected = json.loads(p.stdout)
    got = substep.benchmark.rths(case=2, perturbed=3, seed=7)
    assert got == expected
    pert = got["cases"][0]["perturbed"]
    assert pert["n"] == len(pert["runs"]) == 3 and got["seed"] == 7
    stable = [r for r in pert["runs"] if r["stable"]]
    assert pert["stable"] == len(stable)
    # The statistics are those of the runs (the mean rounded to 0.01 as the CLI prints it).
    if stable:
        assert pert["mean"]["J4"] == pytest.approx(sum(r["J4"] for r in stable) / len(stable), abs=0.005)
        assert pert["max"]["J4"] == pytest.approx(max(r["J4"] for r in stable), abs=0.005)
    # Another seed draws other plants.
    other = substep.benchmark.rths(case=2, perturbed=3, seed=8)["cases"][0]["perturbed"]["runs"]
    assert [r["k_e"] for r in other] != [r["k_e"] for r in pert["runs"]]
    # A k_sub series of the sub-step algorithm on a record of the user's (a 2 s, 1 Hz sine).
    rec = tmp_path / "sine.csv"
    rec.write_text("".join(f"{i * 0.005},{np.sin(2 * np.pi * i * 0.005)}\n" for i in range(401)))
    p = run_cli(cli, "benchmark", "rths", "--case", "1", "--algorithm", "substep", "--k-sub", "2,4",
                "--record", str(rec), "--json")
    assert p.returncode == 0, p.stderr
    got = substep.benchmark.rths(case=1, algorithm="substep", k_sub=[2, 4], record=rec)
    assert got == json.loads(p.stdout)
    assert [r["k_sub"] for r in got["cases"]] == [2, 4] and got["record"] == str(rec)
    with pytest.raises(substep.ConfigError, match="^k_sub: applies to the sub-step algorithm only; set algorithm to substep"):
        substep.benchmark.rths(case=1, k_sub=[2])
    with pytest.raises(substep.ConfigError, match="^perturbed: must be in 1..=10000, got 0"):
        substep.benchmark.rths(case=1, perturbed=0)
    with pytest.raises(substep.ConfigError, match="^perturbed: must be a whole number"):
        substep.benchmark.rths(case=1, perturbed=-2)
    with pytest.raises(substep.ConfigError, match="^case: must be a whole number in 0..=255, got 300"):
        substep.benchmark.rths(case=300)
    with pytest.raises(substep.ConfigError, match="cannot read"):
        substep.benchmark.rths(case=1, record=tmp_path / "missing.csv")


def test_plan_equals_plan_csv(cli, root, tmp_path, monkeypatch):
    monkeypatch.chdir(root)
    p = run_cli(cli, "analyze", "plan", "examples/tmd_substructure.toml", "--out", str(tmp_path), "--quiet")
    assert p.returncode == 0, p.stderr
    import csv

    with open(tmp_path / "plan.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    got = substep.analyze.plan("examples/tmd_substructure.toml")
    assert len(got["dt"]) == len(rows) > 0
    timing = ("us_per_step", "budget_share")
    for name in rows[0]:
        if name in timing:
            continue
        for i, row in enumerate(rows):
            x = got[name][i]
            if name in ("class", "dominant"):
                assert x == row[name], (name, i)
            elif row[name] == "":
                assert np.isnan(x), (name, i)
            else:
                assert float(x) == float(row[name]), (name, i, x, row[name])
    assert got["recommended"] is None or got["recommended"]["k_sub"] in set(got["k_sub"])


def test_plan_refuses_a_monolithic_test(root, monkeypatch):
    monkeypatch.chdir(root)
    with pytest.raises(substep.ConfigError, match="^examples/monolithic_tmd.toml: plan needs a \\[substructure\\]"):
        substep.analyze.plan("examples/monolithic_tmd.toml")


def test_transfer_function_peaks_are_the_accuracy_peaks():
    a = substep.analyze.accuracy(k_sub=[2], eta_t=[0.05])
    r = np.linspace(0.5, 1.5, 20001)
    tf = substep.analyze.transfer_function(k_sub=2, eta_t=0.05, r=r)
    h, h_exact = tf["h"], tf["h_exact"]
    for peak_r, peak_h, col in ((a["freq_ratio"], a["h"], h), (a["freq_ratio_exact"], a["h_exact"], h_exact)):
        for rp, hp in zip(peak_r, peak_h):
            near = np.abs(r - rp) < 0.02
            # The grid's largest value near each peak is the peak (to the grid's resolution).
            assert col[near].max() == pytest.approx(hp, rel=1e-4)
    # Two peaks of a tuned mass damper, around r = 0.89 and 1.11, in both.
    assert len(a["peak"]) == 2


def test_verify_equals_verify_csv(cli, tmp_path):
    p = run_cli(cli, "analyze", "verify", "--out", str(tmp_path), "--quiet")
    assert p.returncode == 0, p.stderr
    import csv

    with open(tmp_path / "verify.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    v = substep.analyze.verify()
    assert v["all_agree"] is True
    assert [k for k in v if k != "all_agree"] == list(rows[0])
    assert len(v["check"]) == len(rows) > 10
    for i, r in enumerate(rows):
        for k in ("check", "case", "quantity"):
            assert v[k][i] == r[k]
        assert v["k_sub"][i] == int(r["k_sub"])
        for k in ("Omega", "eta_p", "frequency_domain", "time_domain"):
            assert v[k][i] == float(r[k]), (k, i)
        assert bool(v["agrees"][i]) == (r["agrees"] == "true")
    # What the checks mean: inside the boundary ρ < 1 and the free vibration decays, outside
    # both grow; the PID compensation turns ρ > 1 into ρ < 1 at the same point.
    check, rho, growth = v["check"], v["frequency_domain"], v["time_domain"]
    inside, outside = check == "boundary_inside", check == "boundary_outside"
    assert inside.any() and outside.any()
    assert (rho[inside] < 1).all() and (growth[inside] < 1).all()
    assert (rho[outside] > 1).all() and (growth[outside] > 1).all()
    pid = rho[check == "pid"]
    assert len(pid) == 2 and pid[0] > 1 > pid[1]


def test_compare_equals_the_cli_json(cli):
    # The controllers side by side, reduced (case 1, one perturbed plant): the same numbers as
    # the CLI's --compare --json; the CPU times are measured, so they only have to be there.
    p = run_cli(cli, "benchmark", "rths", "--compare", "--case", "1", "--perturbed", "1", "--json")
    assert p.returncode == 0, p.stderr
    expected = json.loads(p.stdout)
    got = substep.benchmark.compare(case=1, perturbed=1)
    strip = lambda rows: [{k: v for k, v in r.items() if k != "cpu_us_per_sample"} for r in rows]
    assert strip(got["comparison"]) == strip(expected["comparison"])
    assert [(r["controller"], r["noise"]) for r in got["comparison"]] == [
        (k, n) for k in ("none", "sample", "polynomial", "ats", "amb", "arx") for n in (True, False)
    ]
    arx = got["comparison"][10]
    assert arx["stable"] and 0 < arx["J4"] < 10 and arx["cpu_us_per_sample"] > 0
    assert got["comparison"][0]["J2"] is None  # none diverges
    with pytest.raises(substep.ConfigError, match="^perturbed: must be a whole number"):
        substep.benchmark.compare(perturbed=-1)


def test_marths_equals_the_cli_json(cli):
    """`substep.benchmark.marths` is `substep benchmark marths --json`: the same J lists (the
    toolset's order and lengths), the trial mean; bad input and a diverged run raise."""
    p = run_cli(cli, "benchmark", "marths", "--record", "kobe", "--trials", "2", "--seed", "5", "--json")
    assert p.returncode == 0, p.stderr
    expected = json.loads(p.stdout)
    got = substep.benchmark.marths(record="kobe", trials=2, seed=5)
    for key in ["J%d" % i for i in range(1, 11)] + ["J_raw", "nominal", "per_trial", "realizable", "peak_volts"]:
        assert got[key] == expected[key], key
    assert [len(got["J%d" % i]) for i in range(1, 11)] == [2, 2, 2, 2, 2, 2, 2, 4, 2, 4]
    ideal = substep.benchmark.marths(ideal=True, controller="none")
    assert all(v == 0.0 for k in ("J1", "J2", "J3", "J4", "J5", "J6") for v in ideal[k])
    assert ideal["J7"][0] > 5
    with pytest.raises(substep.ConfigError, match="^record: unknown record `nosuch`"):
        substep.benchmark.marths(record="nosuch")
    with pytest.raises(substep.ConfigError, match="^controller: unknown controller `pid`"):
        substep.benchmark.marths(controller="pid")
