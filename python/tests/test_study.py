"""substep.study: the 200-run Monte-Carlo study gives the same DataFrame on a Dask LocalCluster
of 2 workers as locally; rows equal single runs; a bad override names the run and the key and
does not lose the other rows; user metric functions add columns."""

import math

import numpy as np
import pandas as pd
import pytest

import substep

from conftest import ROOT


def base_text(duration=2.0):
    """The example studies' base test (examples/studies/tmd_base.toml), shortened."""
    text = (ROOT / "examples" / "studies" / "tmd_base.toml").read_text()
    out = text.replace("duration = 5.0", f"duration = {duration}")
    assert out != text
    return out


MC = {
    "n": 200,
    "seed": 2026,
    "params": {
        "substructure.specimen.0.stiffness": ("uniform", 0.9, 1.1, "relative"),
        "substructure.actuator.delay": ("uniform", 0.005, 0.015),
    },
}
METRICS = ["max_displacement_error", "rms_displacement_error", "max_force_error", "tracking_delay"]


@pytest.fixture(scope="module")
def local_mc():
    return substep.study(base_text(), samples=MC, metrics=METRICS)


def test_monte_carlo_rows_and_ranges(local_mc):
    df = local_mc
    assert len(df) == 200
    assert list(df.columns) == ["run", "substructure.actuator.delay", "substructure.specimen.0.stiffness",
                                "completed", *METRICS, "error"]
    assert list(df["run"]) == list(range(200))
    assert df["completed"].all()
    assert (df["error"] == "").all()
    k0 = 1973.9208802178716
    assert df["substructure.specimen.0.stiffness"].between(0.9 * k0, 1.1 * k0).all()
    assert df["substructure.actuator.delay"].between(0.005, 0.015).all()
    # the samples cover their ranges (200 uniform draws: each tenth of the range is hit)
    hist, _ = np.histogram(df["substructure.actuator.delay"], bins=10, range=(0.005, 0.015))
    assert (hist > 0).all()
    # the error grows with the actuator delay (a delay is a phase lag of the coupling)
    assert np.corrcoef(df["substructure.actuator.delay"], df["max_displacement_error"])[0, 1] > 0.9


def test_dask_local_cluster_gives_the_same_dataframe(local_mc):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        remote = substep.study(base_text(), samples=MC, metrics=METRICS, client=client)
    pd.testing.assert_frame_equal(remote, local_mc, check_exact=True)


def test_rows_equal_single_runs_and_a_grid_is_ordered():
    df = substep.study(base_text(1.0), grid={"substructure.substeps": [1, 4], "substructure.actuator.delay": [0.002]},
                       seeds=[3, 4], metrics=["max_displacement_error", "tracking_delay"])
    assert list(df.columns[1:4]) == ["substructure.actuator.delay", "substructure.substeps",
                                     "substructure.sensors.seed"]
    assert list(zip(df["substructure.substeps"], df["substructure.sensors.seed"])) == [(1, 3), (1, 4), (4, 3), (4, 4)]
    for _, row in df.iterrows():
        text = (base_text(1.0).replace("substeps = 4", f"substeps = {row['substructure.substeps']}")
                .replace("delay = 0.001 ", "delay = 0.002 ").replace("seed = 1", f"seed = {row['substructure.sensors.seed']}"))
        r = substep.run(text)
        expected = max(d["peak_error"] for d in r.summary["reference"]["dofs"])
        assert row["max_displacement_error"] == expected


def test_bad_overrides_name_run_and_key_and_keep_the_others():
    df = substep.study(base_text(1.0), grid={"substructure.actuator.delay": [0.002, -0.5, 0.004]},
                       metrics=["max_displacement_error"])
    assert list(df["completed"]) == [True, False, True]
    assert math.isnan(df.loc[1, "max_displacement_error"])
    assert df.loc[1, "error"].startswith("run 1 [substructure.actuator.delay = -0.5]: ")
    assert "substructure.actuator.delay: must be" in df.loc[1, "error"]
    assert df.loc[0, "error"] == "" and df.loc[2, "max_displacement_error"] > 0
    df = substep.study(base_text(1.0), grid={"substructure.actuator.dealy": [0.002]}, metrics=["steps_done"])
    assert not df.loc[0, "completed"]
    assert df.loc[0, "error"].startswith("run 0 [substructure.actuator.dealy = 0.002]: ")
    assert "unknown field `dealy`" in df.loc[0, "error"]
    with pytest.raises(substep.ConfigError, match="unknown metric `max_eror`"):
        substep.study(base_text(1.0), grid={"substructure.substeps": [1]}, metrics=["max_eror"])
    with pytest.raises(substep.ConfigError, match="samples.params.substructure.actuator.delay: uniform needs"):
        substep.study(base_text(1.0), samples={"n": 2, "substructure.actuator.delay": ("uniform", 1.0, 0.5)})


def test_user_metric_functions_add_columns():
    def peak_u1(summary):
        return summary["peaks"][0]["u"]["max_abs"]

    def both(summary):
        return {"steps": summary["steps_done"], "scheme": summary["scheme"]}

    def broken(summary):
        raise KeyError("nope")

    df = substep.study(base_text(1.0), grid={"substructure.substeps": [2, 4]},
                       metrics=["peak_displacement", peak_u1, both, broken])
    assert (df["peak_u1"] == df["peak_displacement"]).all()  # an SDOF: its only DOF's peak
    assert list(df["steps"]) == [100, 100]
    assert list(df["scheme"]) == ["average_acceleration"] * 2
    assert df["broken"].isna().all()
    assert df["error"].str.contains("metric broken: KeyError").all()
