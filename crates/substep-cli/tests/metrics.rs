//! J-style metrics in `summary.json` of `substep run`: tracking delay, NRMS and peak tracking
//! error per coupling DOF, NRMS error of every DOF against the reference — checked against a
//! known pure delay and against the same ratios computed here from `substeps.csv` and
//! `history.csv` (an independent two-pass computation).

use std::path::{Path, PathBuf};
use std::process::Command;

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-metrics-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples")
}

/// Columns of a CSV file by header name.
fn columns(path: &Path, names: &[&str]) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let idx: Vec<usize> = names
        .iter()
        .map(|n| {
            header
                .iter()
                .position(|h| h == n)
                .unwrap_or_else(|| panic!("no column {n}"))
        })
        .collect();
    let mut out = vec![Vec::new(); names.len()];
    for line in lines {
        let fields: Vec<&str> = line.split(',').collect();
        for (o, &i) in out.iter_mut().zip(&idx) {
            o.push(fields[i].parse::<f64>().unwrap());
        }
    }
    out
}

fn std(x: &[f64]) -> f64 {
    let m = x.iter().sum::<f64>() / x.len() as f64;
    (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (x.len() - 1) as f64).sqrt()
}

fn nrms(x: &[f64], r: &[f64]) -> f64 {
    let e: Vec<f64> = x.iter().zip(r).map(|(a, b)| a - b).collect();
    std(&e) / std(r)
}

fn peak(x: &[f64], r: &[f64]) -> f64 {
    let pe = x.iter().zip(r).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    pe / r.iter().fold(0.0f64, |m, v| m.max(v.abs()))
}

#[test]
fn summary_reports_the_delay_and_j_style_errors() {
    let dir = temp_dir("delay");
    // The TMD substructure test (k_sub = 10, Δt = 10 ms: 1 ms sub-steps) behind a pure 4 ms delay.
    let base = std::fs::read_to_string(examples().join("tmd_substructure.toml")).unwrap();
    let record = examples().join("ag_sweep.csv");
    let config = base
        .replace("kind = \"ideal\"", "kind = \"ideal\"\ndelay = 0.004")
        .replace(
            "file = \"ag_sweep.csv\"",
            &format!("file = {:?}", record.display().to_string()),
        );
    assert_ne!(config, base);
    let path = dir.join("delayed.toml");
    std::fs::write(&path, config).unwrap();
    let out = dir.join("out");
    let status = Command::new(env!("CARGO_BIN_EXE_substep"))
        .args([
            "run",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--quiet",
            "--no-plots",
        ])
        .status()
        .unwrap();
    assert!(status.success());
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();

    let tracking = &summary["tracking"][0];
    assert_eq!(tracking["dof"], 1);
    let delay = tracking["delay_s"].as_f64().unwrap();
    assert!((delay - 0.004).abs() < 1e-12, "delay {delay}");

    // Tracking errors against substeps.csv (command vs measured displacement, every sub-step).
    // The CSV holds 17 significant digits, so the ratios agree to round-off.
    let sub = columns(&out.join("substeps.csv"), &["cmd1", "dm1"]);
    let expected_nrms = nrms(&sub[1], &sub[0]);
    let expected_peak = peak(&sub[1], &sub[0]);
    let got_nrms = tracking["nrms_error"].as_f64().unwrap();
    let got_peak = tracking["peak_error"].as_f64().unwrap();
    assert!(
        (got_nrms - expected_nrms).abs() < 1e-9 * expected_nrms,
        "{got_nrms} vs {expected_nrms}"
    );
    assert!(
        (got_peak - expected_peak).abs() < 1e-9 * expected_peak,
        "{got_peak} vs {expected_peak}"
    );
    assert!(
        expected_nrms > 0.005,
        "a 4 ms delay leaves a visible tracking error: {expected_nrms}"
    );

    // NRMS error of the coupling DOF against the reference, from history.csv.
    let hist = columns(&out.join("history.csv"), &["u1", "uref1"]);
    let expected = nrms(&hist[0], &hist[1]);
    let dof = &summary["reference"]["dofs"][0];
    let got = dof["nrms_error"].as_f64().unwrap();
    assert!((got - expected).abs() < 1e-9 * expected, "{got} vs {expected}");
    assert_eq!(
        summary["reference"]["coupling"][0]["displacement_nrms_error"]
            .as_f64()
            .unwrap(),
        got
    );
}

#[test]
fn ideal_actuator_tracks_with_zero_delay_and_error() {
    let dir = temp_dir("ideal");
    let out = dir.join("out");
    let status = Command::new(env!("CARGO_BIN_EXE_substep"))
        .args([
            "run",
            "tmd_substructure.toml",
            "--out",
            out.to_str().unwrap(),
            "--quiet",
            "--no-plots",
        ])
        .current_dir(examples())
        .status()
        .unwrap();
    assert!(status.success());
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let tracking = &summary["tracking"][0];
    assert_eq!(tracking["delay_s"].as_f64(), Some(0.0));
    assert!(tracking["nrms_error"].as_f64().unwrap() < 1e-12);
}
