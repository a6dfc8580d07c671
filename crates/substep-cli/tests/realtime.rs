//! `substep run --realtime`: the wall-clock run equals the offline run and reports deadlines.

use std::process::Command;

#[test]
fn realtime_run_equals_offline_and_reports_latency() {
    let dir = std::env::temp_dir().join(format!("substep-rt-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/default.toml"))
        .unwrap()
        .replace("duration = 20.0", "duration = 1.0");
    assert!(
        cfg.contains("duration = 1.0"),
        "the default example changed: adapt this test"
    );
    std::fs::write(dir.join("short.toml"), cfg).unwrap();
    let run = |extra: &[&str], out: &str| {
        let mut args = vec!["run", "short.toml", "--out", out, "--quiet", "--no-plots"];
        args.extend_from_slice(extra);
        let o = Command::new(env!("CARGO_BIN_EXE_substep"))
            .args(&args)
            .current_dir(&dir)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    run(&[], "offline");
    run(&["--realtime"], "rt");
    let read = |p: &str| -> Vec<Vec<f64>> {
        std::fs::read_to_string(dir.join(p))
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect()
    };
    let (off, rt) = (read("offline/history.csv"), read("rt/history.csv"));
    assert_eq!(off.len(), rt.len());
    assert_eq!(rt.len(), 101);
    // columns t, u1, v1, a1, fc1 are the same in both files
    let peak = off.iter().map(|r| r[1].abs()).fold(0.0, f64::max);
    for (a, b) in off.iter().zip(&rt) {
        assert!((a[1] - b[1]).abs() <= 1e-12 * peak, "u: {} vs {}", a[1], b[1]);
        assert!(
            (a[4] - b[4]).abs() <= 1e-9 * (1.0 + a[4].abs()),
            "fc: {} vs {}",
            a[4],
            b[4]
        );
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("rt/realtime.json")).unwrap()).unwrap();
    assert_eq!(report["steps"], 100);
    assert_eq!(report["substeps"], 400);
    assert!(report["wake_up_latency"]["count"].as_u64().unwrap() >= 400);
    assert!(report["missed_deadlines"].is_u64());
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("rt/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["completed"], true);
}
