//! `substep bench --model chain|frame`: the JSON contract, the sweep and the comparison's
//! skip path (timing goals live in docs/performance.md, never in tests).

use std::process::{Command, Output};

fn substep(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_substep"))
        .args(args)
        .output()
        .expect("the substep binary runs")
}

fn json_of(out: &Output) -> serde_json::Value {
    assert!(out.status.success(), "stderr: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

#[test]
fn model_bench_prints_the_contract_fields() {
    for (model, dofs) in [("chain", 500usize), ("frame", 400)] {
        let n = dofs.to_string();
        let v = json_of(&substep(&[
            "bench",
            "--model",
            model,
            "--dofs",
            &n,
            "--steps",
            "5",
            "--substeps",
            "3",
            "--json",
        ]));
        for key in [
            "dofs",
            "steps",
            "substeps",
            "us_per_step_median",
            "us_per_step_p99",
            "peak_rss_bytes",
        ] {
            assert!(v.get(key).is_some(), "{model}: missing {key} in {v}");
        }
        assert_eq!(v["steps"], 5);
        assert_eq!(v["substeps"], 3);
        assert!(v["us_per_step_p99"].as_f64().unwrap() >= v["us_per_step_median"].as_f64().unwrap());
        assert!(v["peak_rss_bytes"].as_u64().unwrap() > 0);
        let d = v["dofs"].as_u64().unwrap() as usize;
        if model == "chain" {
            assert_eq!(d, dofs);
            assert!(v["solver"].as_str().unwrap().starts_with("banded"), "{v}");
        } else {
            assert!(d.abs_diff(dofs) < dofs / 2, "frame of about {dofs} DOFs: {d}");
        }
    }
}

#[test]
fn sweep_reports_each_size_and_the_budgets() {
    let v = json_of(&substep(&[
        "bench", "--model", "chain", "--sweep", "--sizes", "100,300", "--steps", "5", "--json",
    ]));
    let runs = v["runs"].as_array().unwrap();
    assert_eq!(
        runs.iter().map(|r| r["dofs"].as_u64().unwrap()).collect::<Vec<_>>(),
        vec![100, 300]
    );
    assert!(v.get("largest_dofs_within_1ms").is_some() && v.get("largest_dofs_within_10ms").is_some());
}

#[test]
fn bad_model_options_are_refused() {
    let out = substep(&["bench", "--model", "chain", "--steps", "5"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--dofs: is required with --model"));
    let out = substep(&["bench", "--dofs", "100"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--dofs: needs --model chain|frame"));
}

#[test]
fn compare_skips_missing_tools_cleanly() {
    // A Python that does not exist: both tools are reported as skipped, the run still succeeds.
    let out = Command::new(env!("CARGO_BIN_EXE_substep"))
        .args([
            "bench",
            "--compare",
            "--compare-dofs",
            "200",
            "--steps",
            "100",
            "--json",
        ])
        .env("SUBSTEP_PYTHON", "/nonexistent/python3")
        .output()
        .unwrap();
    let v = json_of(&out);
    assert_eq!(v["dofs"], 200);
    for t in v["tools"].as_array().unwrap() {
        assert!(t["us_per_step"].is_null(), "{t}");
        assert!(t["detail"].as_str().unwrap().starts_with("skipped: cannot run"), "{t}");
    }
}
