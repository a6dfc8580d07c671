//! `substep benchmark rths` end to end: JSON shape, files, and bad input (one `error:` line,
//! exit code 2).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-bench-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn substep(cwd: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_substep"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("the substep binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Exit code 2 and exactly one stderr line, starting with `error:` and containing `needle`.
fn assert_bad_input(out: &Output, needle: &str) {
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {err}");
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].starts_with("error: ") && lines[0].contains(needle), "{err}");
}

#[test]
fn json_has_the_criteria_and_flags() {
    let dir = temp_dir("json");
    let out = substep(&dir, &["benchmark", "rths", "--case", "2", "--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for i in 1..=9 {
        assert!(v[format!("J{i}")].is_number(), "J{i}");
    }
    assert_eq!(v["J1"], 4.6);
    assert!((v["J4"].as_f64().unwrap() - 33.1).abs() <= 0.1);
    assert!(v["max_force"].as_f64().unwrap() > 1000.0);
    assert_eq!(v["stable"], true);
    assert_eq!(v["capacity_exceeded"], false);
    assert_eq!(v["cases"].as_array().unwrap().len(), 1);
    // --json writes nothing.
    assert!(!dir.join("results").exists());
}

#[test]
fn perturbed_json_has_runs_and_statistics() {
    let dir = temp_dir("perturbed");
    let out = substep(
        &dir,
        &[
            "benchmark",
            "rths",
            "--case",
            "1",
            "--controller",
            "arx",
            "--perturbed",
            "3",
            "--seed",
            "5",
            "--json",
        ],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let p = &v["perturbed"];
    assert_eq!(p["n"], 3);
    assert_eq!(p["runs"].as_array().unwrap().len(), 3);
    assert_eq!(p["stable"], 3);
    assert_eq!(p["under_capacity"], 3);
    let runs = p["runs"].as_array().unwrap();
    let max_j2 = runs.iter().map(|r| r["J2"].as_f64().unwrap()).fold(0.0, f64::max);
    assert!((p["max"]["J2"].as_f64().unwrap() - max_j2).abs() < 1e-9);
    assert!(runs[0]["k_e"].as_f64().unwrap() != runs[1]["k_e"].as_f64().unwrap());
    // Seeded: the same command gives the same runs.
    let again = substep(
        &dir,
        &[
            "benchmark",
            "rths",
            "--case",
            "1",
            "--controller",
            "arx",
            "--perturbed",
            "3",
            "--seed",
            "5",
            "--json",
        ],
    );
    assert_eq!(out.stdout, again.stdout);
}

#[test]
fn table_markdown_and_plots_are_written() {
    let dir = temp_dir("table");
    let out = substep(&dir, &["benchmark", "rths", "--case", "3", "--out", "o"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("published"), "{stdout}");
    let md = std::fs::read_to_string(dir.join("o/benchmark.md")).unwrap();
    assert!(md.contains("| 3 |") && md.contains("3 published"), "{md}");
    for f in ["tracking_case3.png", "tracking_zoom_case3.png", "floors_case3.png"] {
        let b = std::fs::read(dir.join("o").join(f)).unwrap();
        assert!(b.starts_with(b"\x89PNG") && b.len() > 10_000, "{f}");
    }
}

#[test]
fn substep_algorithm_with_k_sub_list() {
    let dir = temp_dir("substep");
    let out = substep(
        &dir,
        &[
            "benchmark",
            "rths",
            "--case",
            "1",
            "--algorithm",
            "substep",
            "--k-sub",
            "1,2",
            "--json",
        ],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let cases = v["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 2);
    assert_eq!(cases[0]["k_sub"], 1);
    assert_eq!(cases[1]["k_sub"], 2);
    assert!(cases.iter().all(|c| c["stable"] == true));
}

#[test]
fn bad_input_is_one_line_and_exit_2() {
    let dir = temp_dir("bad");
    assert_bad_input(&substep(&dir, &["benchmark", "rths", "--case", "5"]), "--case");
    assert_bad_input(
        &substep(&dir, &["benchmark", "rths", "--controller", "lqg"]),
        "--controller",
    );
    assert_bad_input(
        &substep(&dir, &["benchmark", "rths", "--algorithm", "x"]),
        "--algorithm",
    );
    std::fs::write(dir.join("three.csv"), "t,a_g\n0,0\n0.02,0.1,7\n").unwrap();
    assert_bad_input(
        &substep(&dir, &["benchmark", "rths", "--record", "three.csv"]),
        "three.csv: line 3",
    );
    std::fs::write(dir.join("one.csv"), "0\n0.02\n").unwrap();
    assert_bad_input(
        &substep(&dir, &["benchmark", "rths", "--record", "one.csv"]),
        "one.csv: line 1",
    );
    assert_bad_input(
        &substep(&dir, &["benchmark", "rths", "--record", "missing.csv"]),
        "missing.csv",
    );
    std::fs::write(
        dir.join("zero.toml"),
        "[controller]\nfeedback = { num = [1.0], den = [0.0, 0.0] }\n",
    )
    .unwrap();
    assert_bad_input(
        &substep(&dir, &["benchmark", "rths", "--config", "zero.toml"]),
        "controller.feedback.den",
    );
    std::fs::write(
        dir.join("unstable.toml"),
        "[controller]\nfeedback = { num = [1.0], den = [1.0, -20.0] }\n",
    )
    .unwrap();
    assert_bad_input(
        &substep(&dir, &["benchmark", "rths", "--config", "unstable.toml"]),
        "unstable",
    );
    std::fs::write(dir.join("unknown.toml"), "[controller]\ngain = 3\n").unwrap();
    assert_bad_input(
        &substep(&dir, &["benchmark", "rths", "--config", "unknown.toml"]),
        "unknown.toml: line 2",
    );
    assert_bad_input(
        &substep(&dir, &["benchmark", "rths", "--perturbed", "0"]),
        "--perturbed",
    );
    assert_bad_input(&substep(&dir, &["benchmark", "rths", "--k-sub", "2"]), "--k-sub");
}

#[test]
fn user_record_runs() {
    let dir = temp_dir("record");
    // A 3 s, 2 Hz sine record without a header.
    let rows: String = (0..=300)
        .map(|i| {
            let t = i as f64 * 0.01;
            format!("{t},{}\n", (2.0 * std::f64::consts::PI * 2.0 * t).sin())
        })
        .collect();
    std::fs::write(dir.join("sine.csv"), rows).unwrap();
    let out = substep(
        &dir,
        &[
            "benchmark",
            "rths",
            "--case",
            "1",
            "--record",
            "sine.csv",
            "--intensity",
            "1",
            "--json",
        ],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["record"], "sine.csv");
    assert_eq!(v["stable"], true);
}

/// A benchmark run without a score is a failure (exit 1, the reason on stderr, `warnings` in
/// the JSON), and a run beyond the actuator's capacity says so (issue 25).
#[test]
fn no_score_fails_and_capacity_is_a_warning() {
    let dir = temp_dir("warnings");
    let out = substep(
        &dir,
        &[
            "benchmark",
            "rths",
            "--case",
            "1",
            "--intensity",
            "1e308",
            "--no-plots",
            "--out",
            "o",
        ],
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    let e = text(&out.stderr);
    assert!(e.contains("warning: case 1: no score: the run diverged at t = "), "{e}");
    assert_eq!(
        e.lines().last().unwrap(),
        "error: benchmark rths: no score for case 1: the run diverged (see the warnings)"
    );
    assert!(
        text(&out.stdout).contains("record elcentro × 1.00000e308"),
        "{}",
        text(&out.stdout)
    );
    let md = std::fs::read_to_string(dir.join("o/benchmark.md")).unwrap();
    assert!(md.contains("* case 1: no score"), "{md}");
    let out = substep(
        &dir,
        &["benchmark", "rths", "--case", "1", "--intensity", "1e308", "--json"],
    );
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_str(&text(&out.stdout)).unwrap();
    assert!(v["J2"].is_null());
    assert!(
        v["warnings"][0].as_str().unwrap().starts_with("case 1: no score"),
        "{v}"
    );
    // three times the record: scored, but beyond the 8900 N the specimen is rated for
    let out = substep(
        &dir,
        &["benchmark", "rths", "--case", "1", "--intensity", "3", "--json"],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(&text(&out.stdout)).unwrap();
    assert_eq!(v["capacity_exceeded"], true);
    assert!(v["max_force"].as_f64().unwrap() > 8900.0);
    let w = v["warnings"][0].as_str().unwrap();
    assert!(w.contains("beyond the benchmark's capacity of 8900 N"), "{w}");
    assert!(text(&out.stderr).contains("warning: case 1: the actuator force reached"));
}

/// Population standard deviation (the benchmark's `std`), written here independently of the
/// library's metrics.
fn population_std(v: &[f64]) -> f64 {
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / v.len() as f64).sqrt()
}

/// Issue 28: `--out` writes the traces, exact enough to score the run again: J2 (NRMS of
/// measured − target) and J4 (NRMS of measured − the reference's first floor) recomputed from
/// `trace_case1.csv` equal the unrounded `J_raw` of `--json` to 1e-9; `floors_case1.csv` has
/// the numerical substructure on its grid. Both algorithms.
#[test]
fn traces_reproduce_the_reported_criteria() {
    for algorithm in ["benchmark", "substep"] {
        let dir = temp_dir(&format!("traces-{algorithm}"));
        let args = ["benchmark", "rths", "--case", "1", "--algorithm", algorithm];
        let json = substep(&dir, &[&args[..], &["--json"]].concat());
        assert!(json.status.success(), "{}", text(&json.stderr));
        let v: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
        let raw: Vec<f64> = v["J_raw"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(raw.len(), 9);
        let files = substep(&dir, &[&args[..], &["--no-plots", "--out", "out"]].concat());
        assert!(files.status.success(), "{}", text(&files.stderr));
        let trace = std::fs::read_to_string(dir.join("out/trace_case1.csv")).unwrap();
        let mut lines = trace.lines();
        assert_eq!(
            lines.next().unwrap(),
            "t [s],target y_n [m],command u [m],measured x_m [m],actuator force F [N],reference floor 1 [m],reference floor 2 [m],reference floor 3 [m]"
        );
        let rows: Vec<Vec<f64>> = lines
            .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
            .collect();
        assert_eq!(rows.len(), 168_674, "one row per controller sample of El Centro");
        let column = |c: usize| rows.iter().map(|r| r[c]).collect::<Vec<f64>>();
        let (target, command, measured, reference1) = (column(1), column(2), column(3), column(5));
        let diff = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x - y).collect::<Vec<f64>>();
        let j2 = 100.0 * population_std(&diff(&measured, &target)) / population_std(&target);
        let j4 = 100.0 * population_std(&diff(&measured, &reference1)) / population_std(&reference1);
        assert!(
            (j2 - raw[1]).abs() < 1e-9,
            "{algorithm}: J2 from the trace {j2} vs {}",
            raw[1]
        );
        assert!(
            (j4 - raw[3]).abs() < 1e-9,
            "{algorithm}: J4 from the trace {j4} vs {}",
            raw[3]
        );
        // The command is the controller's own signal, not a copy of the target.
        assert!(
            command.iter().zip(&target).any(|(u, y)| (u - y).abs() > 1e-6),
            "{algorithm}"
        );
        let floors = std::fs::read_to_string(dir.join("out/floors_case1.csv")).unwrap();
        let n_floors = floors.lines().count() - 1;
        let expected = if algorithm == "benchmark" { 168_674 } else { 168_674 / 4 };
        assert!(n_floors.abs_diff(expected) <= 1, "{algorithm}: {n_floors} floor rows");
    }
}

/// Issue 28: `--compare` in a reduced form (case 1, one perturbed plant): every compared
/// controller with and without noise in `comparison.md`, the numbers equal to the single
/// controller's own run (`--controller K --json`), `none` diverging, and the flags that do not
/// apply refused in one line.
#[test]
fn compare_writes_the_side_by_side_table() {
    let dir = temp_dir("compare");
    let out = substep(
        &dir,
        &[
            "benchmark",
            "rths",
            "--compare",
            "--case",
            "1",
            "--perturbed",
            "1",
            "--out",
            "out",
        ],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let md = std::fs::read_to_string(dir.join("out/comparison.md")).unwrap();
    let rows: Vec<Vec<String>> = md
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| controller"))
        .map(|l| l.trim_matches('|').split('|').map(|c| c.trim().to_string()).collect())
        .collect();
    let names: Vec<(&str, &str)> = rows.iter().map(|r| (r[0].as_str(), r[1].as_str())).collect();
    let mut expected = Vec::new();
    for k in ["none", "sample", "polynomial", "ats", "amb", "arx"] {
        expected.push((k, "on"));
        expected.push((k, "off"));
    }
    assert_eq!(names, expected);
    let none = &rows[0];
    assert_eq!((none[3].as_str(), none[6].as_str()), ("–", "no"), "{none:?}");
    for (k, row) in ["ats", "amb", "arx"].iter().zip([&rows[6], &rows[8], &rows[10]]) {
        let single = substep(&dir, &["benchmark", "rths", "--controller", k, "--case", "1", "--json"]);
        let v: serde_json::Value = serde_json::from_slice(&single.stdout).unwrap();
        assert_eq!(row[3], format!("{:.2}", v["J2"].as_f64().unwrap()), "{k} J2");
        assert_eq!(row[4], format!("{:.2}", v["J4"].as_f64().unwrap()), "{k} J4");
        assert_eq!(row[7], "1/1", "{k}: the perturbed plant is stable");
        let cpu: f64 = row[12].parse().unwrap();
        assert!(cpu > 0.0 && cpu < 100.0, "{k}: {cpu} µs per sample");
    }
    let bad = substep(&dir, &["benchmark", "rths", "--compare", "--controller", "arx"]);
    assert_bad_input(&bad, "--compare: compares every controller with its preset setting");
    let refused = substep(
        &dir,
        &["benchmark", "rths", "--controller", "inverse_fir", "--case", "1"],
    );
    assert_bad_input(&refused, "--controller: inverse_fir cannot run on this benchmark");
}
