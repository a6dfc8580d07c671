//! The on-line stability indicator on whole runs (docs/monitor.md): a virtual test whose
//! actuator delay ramps up part-way (`[substructure.delay_ramp]`) is warned about before its
//! response exceeds twice its stable peak, `stability = "stop"` stops it with the ramp-down
//! before that, and no shipped example raises an alarm.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// SDOF (1000 kg, 1 Hz, 2 % damping) with a spring-dashpot specimen behind a 2 ms delay,
/// harmonic 0.5 Hz input; the extra delay that `ramp` adds makes it unstable near 14.5 ms
/// (negative damping k_s τ against c + c_s).
const BASE: &str = r#"
[structure.sdof]
mass = 1000.0
stiffness = 39478.4
damping = 251.3

[ground_motion]
generator = "harmonic"
amplitude = 0.5
frequency = 0.5
duration = 45.0

[integrator]
scheme = "average_acceleration"
dt = 0.01

[substructure]
coupling_dofs = [1]
substeps = 4

[[substructure.specimen]]
kind = "linear_sdof"
dof = 1
stiffness = 20000.0
damping = 40.0

[substructure.actuator]
kind = "delay"
delay = 0.002

[substructure.sensors]
force_noise = 0.5
seed = 3
"#;

const RAMP: &str = "\n[substructure.delay_ramp]\nstart = 10.0\nend = 40.0\ndelay = 0.04\n";

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("substep_stability_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Run `config` (text) and return (exit code, summary.json, the column `u1` of history.csv
/// with its times).
fn run(name: &str, config: &str, extra: &[&str]) -> (i32, Value, Vec<(f64, f64)>) {
    let dir = tmp(name);
    let cfg = dir.join("test.toml");
    std::fs::write(&cfg, config).unwrap();
    let out = dir.join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_substep"))
        .arg("run")
        .arg(&cfg)
        .arg("--out")
        .arg(&out)
        .args(["--no-plots", "--quiet"])
        .args(extra)
        .output()
        .unwrap();
    let summary: Value = serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let history = std::fs::read_to_string(out.join("history.csv")).unwrap();
    let mut lines = history.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let iu = head.iter().position(|h| *h == "u1").unwrap();
    let u = lines
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap_or(f64::NAN)).collect();
            (v[0], v[iu])
        })
        .collect();
    let _ = std::fs::remove_dir_all(&dir);
    (o.status.code().unwrap_or(-1), summary, u)
}

#[test]
fn a_delay_that_ramps_up_is_warned_about_before_the_response_doubles_and_stop_stops_it() {
    let warn = "\n[substructure.limits]\nstability = \"warn\"\nstability_refresh = 20\n";
    let (code, stable, u_stable) = run("stable", &format!("{BASE}{warn}"), &[]);
    assert_eq!(code, 0);
    assert!(stable["stability"]["alarm"].is_null(), "{}", stable["stability"]);
    let stable_peak = u_stable.iter().fold(0.0f64, |m, (_, u)| m.max(u.abs()));

    let (code, ramped, u) = run("warn", &format!("{BASE}{RAMP}{warn}"), &[]);
    assert_eq!(code, 0, "warn does not stop the run");
    let alarm = &ramped["stability"]["alarm"];
    let t_alarm = alarm["time"]
        .as_f64()
        .unwrap_or_else(|| panic!("no alarm: {}", ramped["stability"]));
    let t_double = u
        .iter()
        .find(|(_, x)| x.abs() > 2.0 * stable_peak)
        .map(|(t, _)| *t)
        .expect("the ramped test goes unstable");
    assert!(t_alarm > 10.0, "no alarm before the delay grows: {t_alarm}");
    assert!(
        t_alarm < t_double,
        "alarm at {t_alarm} s, response doubled at {t_double} s"
    );
    assert!(
        ramped["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("stability indicator"))
    );

    let stop = "\n[substructure.limits]\nstability = \"stop\"\nstability_refresh = 20\n";
    let (code, stopped, u) = run("stop", &format!("{BASE}{RAMP}{stop}"), &[]);
    assert_eq!(code, 1, "a stopped run exits with 1");
    assert_eq!(stopped["stopped_by"], "stability");
    assert_eq!(stopped["completed"], false);
    assert!(stopped["reason"].as_str().unwrap().contains("ramped to 0 over 1 s"));
    assert!(stopped["ramp_substeps"].as_u64().unwrap() > 0);
    let peak = u.iter().fold(0.0f64, |m, (_, x)| m.max(x.abs()));
    assert!(peak < 2.0 * stable_peak, "peak {peak} vs stable {stable_peak}");
}

#[test]
fn no_shipped_example_raises_a_stability_alarm() {
    let examples = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples"));
    let mut names: Vec<PathBuf> = std::fs::read_dir(examples)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    names.sort();
    let mut checked = 0;
    for p in names {
        let text = std::fs::read_to_string(&p).unwrap();
        if !text.contains("[substructure]") {
            continue;
        }
        let dir = tmp(p.file_stem().unwrap().to_str().unwrap());
        let o = Command::new(env!("CARGO_BIN_EXE_substep"))
            .arg("run")
            .arg(&p)
            .arg("--out")
            .arg(&dir)
            .args(["--no-plots", "--quiet", "--stability", "warn"])
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{}: {}",
            p.display(),
            String::from_utf8_lossy(&o.stderr)
        );
        let s: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
        let st = &s["stability"];
        assert!(st.is_object(), "{}: the indicator did not run", p.display());
        assert!(st["alarm"].is_null(), "{}: {}", p.display(), st["alarm"]);
        println!(
            "{}: max η = {}, min margin = {}",
            p.display(),
            st["max_eta"],
            st["min_margin"]
        );
        checked += 1;
        let _ = std::fs::remove_dir_all(&dir);
    }
    assert!(checked >= 5, "only {checked} substructured examples");
}
