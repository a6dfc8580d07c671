//! `substep benchmark marths`: the JSON object the issue asks for, the traces, the sub-step
//! algorithm, bad input (one line, exit 2) and a diverging run (exit 1).

use std::process::{Command, Output};
use std::sync::Arc;
use substep::benchmark::marths::{ControllerKind, MarthsInput, PlantParameters, Record, Transfer, reference, run};

fn substep(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_substep"))
        .args(["benchmark", "marths"])
        .args(args)
        .output()
        .expect("the binary runs")
}

fn json(args: &[&str]) -> serde_json::Value {
    let mut a = args.to_vec();
    a.push("--json");
    let o = substep(&a);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

fn list(v: &serde_json::Value, key: &str) -> Vec<f64> {
    v[key]
        .as_array()
        .unwrap_or_else(|| panic!("{key} in {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

const LENGTHS: [(&str, usize); 10] = [
    ("J1", 2),
    ("J2", 2),
    ("J3", 2),
    ("J4", 2),
    ("J5", 2),
    ("J6", 2),
    ("J7", 2),
    ("J8", 4),
    ("J9", 2),
    ("J10", 4),
];

/// `--json`: keys J1…J10, each a list in the toolset's order, rounded to 0.1 as it reports;
/// `J_raw` unrounded and equal to the library's run of the same input; with `--trials N` the
/// mean over the per-trial lists, nominal excluded.
#[test]
fn json_gives_j1_to_j10_as_the_toolset_orders_them() {
    let v = json(&["--no-noise", "--controller", "rodeac"]);
    for (key, n) in LENGTHS {
        let j = list(&v, key);
        let raw = list(&v["J_raw"], key);
        assert_eq!(j.len(), n, "{key}");
        for (a, b) in j.iter().zip(&raw) {
            assert!((a - (b * 10.0).round() / 10.0).abs() < 1e-12, "{key}: {a} {b}");
        }
    }
    assert_eq!(list(&v, "J1"), list(&v, "J4"));
    let mut input = MarthsInput::new(Arc::new(Record::ElCentro.load()));
    input.transfer = Transfer::Plant {
        plant: PlantParameters::nominal().transfer_matrix().unwrap().to_state_space(),
        noise_seed: None,
    };
    input.controller = ControllerKind::Rodeac;
    let c = run(&input, &reference(&input).unwrap()).unwrap().criteria.unwrap();
    assert_eq!(list(&v["J_raw"], "J2"), c.j2.to_vec());
    assert_eq!(list(&v["J_raw"], "J8"), c.j8.to_vec());
    assert_eq!(v["realizable"], true);

    let v = json(&[
        "--trials",
        "3",
        "--seed",
        "9",
        "--controller",
        "arx",
        "--record",
        "kobe",
    ]);
    let trials = v["per_trial"].as_array().unwrap();
    assert_eq!(trials.len(), 3);
    for (key, _) in LENGTHS {
        let raw = list(&v["J_raw"], key);
        for (k, r) in raw.iter().enumerate() {
            let mean = trials.iter().map(|t| list(t, key)[k]).sum::<f64>() / 3.0;
            assert!((r - mean).abs() < 1e-12, "{key}");
        }
    }
    assert_eq!(v["record"], "kobe");
    assert_eq!(v["stable"], true);
}

/// `--ideal`: J1–J6 are 0 and J7–J10 the benchmark's floor; `--algorithm substep` reports
/// J5–J10.
#[test]
fn the_ideal_transfer_and_the_sub_step_algorithm_from_the_command_line() {
    let v = json(&["--ideal", "--controller", "none"]);
    for key in ["J1", "J2", "J3", "J4", "J5", "J6"] {
        assert!(list(&v, key).iter().all(|x| *x == 0.0), "{key}: {v}");
    }
    assert!(list(&v, "J7").iter().all(|x| *x > 5.0));
    let v = json(&["--algorithm", "substep", "--no-noise"]);
    for key in ["J5", "J6", "J7", "J8", "J9", "J10"] {
        assert!(list(&v, key).iter().all(|x| x.is_finite() && *x > 0.0), "{key}: {v}");
    }
    assert_eq!(v["algorithm"], "substep");
}

/// `--out`: trace.csv has every sample, and J2 recomputed from it equals the reported one.
#[test]
fn out_writes_the_traces_that_give_the_reported_criteria() {
    let dir = std::env::temp_dir().join(format!("substep-marths-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let o = substep(&["--out", dir.to_str().unwrap(), "--record", "morgan"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(dir.join("trace.csv")).unwrap();
    assert!(dir.join("marths.md").exists());
    let mut lines = text.lines();
    assert!(lines.next().unwrap().starts_with("t [s],target 1 [mm]"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), (39.97f64 * 1024.0).floor() as usize + 1);
    let v = json(&["--record", "morgan"]);
    for a in 0..2 {
        let target: Vec<f64> = rows.iter().map(|r| r[1 + a]).collect();
        let measured: Vec<f64> = rows.iter().map(|r| r[3 + a]).collect();
        let j2 = 100.0 * substep::analysis::metrics::nrms_error(&measured, &target).unwrap();
        assert!((j2 - list(&v["J_raw"], "J2")[a]).abs() < 1e-9, "{j2} {v}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

fn fails_with(args: &[&str], code: i32, needle: &str) {
    let o = substep(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(code), "{args:?}: {err}");
    assert_eq!(err.trim().lines().count(), 1, "{args:?}: one line, got {err}");
    assert!(err.contains(needle), "{args:?}: {err}");
}

/// Bad input: one clear line, exit 2 — an unknown record, controller or algorithm, a plant matrix
/// of the wrong shape, a coupler that cannot reach the target, bad numbers; a plant that makes
/// the test diverge: exit 1, no score.
#[test]
fn bad_input_exits_2_and_a_diverging_run_exits_1() {
    fails_with(&["--record", "nosuch"], 2, "unknown record `nosuch`");
    fails_with(&["--controller", "pid"], 2, "unknown controller `pid`");
    fails_with(&["--algorithm", "rk4"], 2, "unknown algorithm `rk4`");
    fails_with(&["--intensity=-1"], 2, "intensity");
    fails_with(&["--trials", "5000"], 2, "at most 1000");
    fails_with(
        &["--ideal", "--algorithm", "substep"],
        2,
        "not with the sub-step algorithm",
    );
    let dir = std::env::temp_dir().join(format!("substep-marths-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    let ch = "{ zeros = [], poles = [[-100.0, 0.0]], gain = 100.0 }";
    let wrong = write(
        "wrong.toml",
        &format!("[plant]\nh = [[{ch}, {ch}, {ch}], [{ch}, {ch}, {ch}]]\n"),
    );
    fails_with(&["--config", &wrong], 2, "must be a 2×2 matrix");
    // The Jacobian of this coupler turns singular at θ ≈ 0.01 rad, within twice the reference's
    // rotation: no unique position for the target.
    let far = write("far.toml", "[coupler]\nattachments = [[0.3, 10.0], [0.31, 9.656]]\n");
    fails_with(&["--config", &far], 2, "cannot reach the target");
    let flat = write("flat.toml", "[coupler]\nattachments = [[0.3, 0.0], [0.3, 180.0]]\n");
    fails_with(&["--config", &flat], 2, "same height");
    let unknown = write("unknown.toml", "[plant]\nH = 1\n");
    fails_with(&["--config", &unknown], 2, "unknown field");
    // Both actuators alike behind an unstable pole: the node translates away.
    let zero = "{ zeros = [], poles = [[-100.0, 0.0]], gain = 1e-12 }";
    let bad = "{ zeros = [], poles = [[20.0, 0.0]], gain = -20.0 }";
    let unstable = write(
        "unstable.toml",
        &format!("[plant]\nh = [[{bad}, {zero}], [{zero}, {bad}]]\n"),
    );
    fails_with(
        &["--config", &unstable, "--no-noise", "--controller", "none"],
        1,
        "diverged",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `[plant]` as a state space: the toolset's stored realisation (`plantFRAME_SS`) in `--config`
/// gives the criteria of the built-in plant (a similarity transform apart: to round-off); a
/// state space of the wrong shape is refused with its shapes.
#[test]
fn a_state_space_plant_from_the_config() {
    let stored = substep::benchmark::marths::data::stored_plant();
    let m = |v: &nalgebra::DMatrix<f64>| {
        let rows: Vec<String> = v
            .row_iter()
            .map(|r| {
                format!(
                    "[{}]",
                    r.iter().map(|x| format!("{x:e}")).collect::<Vec<_>>().join(", ")
                )
            })
            .collect();
        format!("[{}]", rows.join(", "))
    };
    let text = format!(
        "[plant]\na = {}\nb = {}\nc = {}\n",
        m(&stored.a),
        m(&stored.b),
        m(&stored.c)
    );
    let dir = std::env::temp_dir().join(format!("substep-marths-ss-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("ss.toml");
    std::fs::write(&path, &text).unwrap();
    let ours = json(&["--no-noise"]);
    let stored = json(&["--no-noise", "--config", path.to_str().unwrap()]);
    for (key, _) in LENGTHS {
        for (a, b) in list(&ours["J_raw"], key).iter().zip(list(&stored["J_raw"], key)) {
            assert!((a - b).abs() < 1e-6, "{key}: {a} {b}");
        }
    }
    let bad = dir.join("bad.toml");
    std::fs::write(
        &bad,
        "[plant]\na = [[-1.0]]\nb = [[1.0, 0.0, 0.0]]\nc = [[1.0], [1.0]]\n",
    )
    .unwrap();
    fails_with(&["--config", bad.to_str().unwrap()], 2, "got 2 outputs × 3 inputs");
    std::fs::write(
        &bad,
        "[plant]\na = [[-1.0]]\nb = [[1.0, 0.0], [0.0, 1.0]]\nc = [[1.0], [1.0]]\n",
    )
    .unwrap();
    fails_with(&["--config", bad.to_str().unwrap()], 2, "inconsistent shapes");
    let _ = std::fs::remove_dir_all(&dir);
}
