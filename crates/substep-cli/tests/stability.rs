//! The on-line stability indicator on whole runs (docs/monitor.md): a virtual test whose
//! actuator delay ramps up part-way (`[substructure.delay_ramp]`) is warned about before its
//! response exceeds twice its stable peak, `stability = "stop"` stops it with the ramp-down
//! before that, no shipped example raises an alarm, and the indicator's columns in
//! `history.csv` are what the library's indicator gives when fed the run's own records.

use serde_json::Value;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use substep::io::TestDefinition;
use substep::monitor::{StabilityMonitor, StabilitySettings};

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
    // Warn does not stop the run; the run that diverges still ends as a failure (exit 1,
    // diverged, its error against the reference beyond 100 % or a runaway response).
    assert!(ramped["stopped_by"].is_null(), "{}", ramped["stopped_by"]);
    assert_eq!(code, 1, "{}", ramped["reason"]);
    assert_eq!(
        (&ramped["completed"], &ramped["diverged"]),
        (&Value::Bool(false), &Value::Bool(true))
    );
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

/// A CSV file as named columns (NaN for unparsable cells), with the header's order.
fn read_csv(path: &Path) -> (Vec<String>, HashMap<String, Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let names: Vec<String> = lines.next().unwrap().split(',').map(str::to_string).collect();
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    for l in lines {
        for (c, x) in cols.iter_mut().zip(l.split(',')) {
            c.push(x.parse().unwrap_or(f64::NAN));
        }
    }
    let map = names.iter().cloned().zip(cols).collect();
    (names, map)
}

/// Bit-equal, NaN equal to NaN (the CSV's numbers are shortest round-trip text).
fn same(a: f64, b: f64) -> bool {
    a == b || (a.is_nan() && b.is_nan())
}

/// The largest finite value of a column (NaN if none).
fn finite_max(v: impl Iterator<Item = f64>) -> f64 {
    v.filter(|x| x.is_finite())
        .fold(f64::NAN, |m, x| if m.is_nan() { x } else { m.max(x) })
}

#[test]
fn history_has_the_indicator_columns_and_they_are_the_indicator_fed_with_the_run_records() {
    // Two coupling DOFs (examples/two_specimens.toml), so that the per-DOF groups and the
    // command of each DOF are checked.
    let cfg = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../examples/two_specimens.toml"
    ));
    let dir = tmp("columns");
    let o = Command::new(env!("CARGO_BIN_EXE_substep"))
        .arg("run")
        .arg(cfg)
        .arg("--out")
        .arg(&dir)
        .args(["--no-plots", "--quiet", "--stability", "warn"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let def = TestDefinition::from_file(cfg).unwrap();
    let sub = def.substructure.as_ref().unwrap();
    let (n, n_c, k_sub) = (def.model.n_dofs(), sub.coupling_dofs.len(), sub.substeps);
    assert_eq!(n_c, 2);
    let (names, h) = read_csv(&dir.join("history.csv"));
    let mut tail: Vec<String> = vec!["eta".into(), "margin".into()];
    for p in ["k_id", "c_id", "lag_id"] {
        tail.extend((1..=n_c).map(|k| format!("{p}{k}")));
    }
    assert_eq!(names[names.len() - tail.len()..], tail[..], "{names:?}");
    let (_, sub_rows) = read_csv(&dir.join("substeps.csv"));
    // The command of step i is that of its last sub-step (`step` = i, `substep` = k_sub).
    let rows = h["t"].len();
    let mut command = vec![vec![0.0; n_c]; rows];
    for (r, (&step, &j)) in sub_rows["step"].iter().zip(&sub_rows["substep"]).enumerate() {
        if j as usize == k_sub {
            for (k, c) in command[step as usize].iter_mut().enumerate() {
                *c = sub_rows[&format!("cmd{}", k + 1)][r];
            }
        }
    }
    // Feed a fresh indicator the run's records: u, v of every DOF, fc, dm and the command.
    let mut m = StabilityMonitor::new(sub, &def.model, def.integrator.dt, StabilitySettings::default()).unwrap();
    let col = |name: String, i: usize| h[&name][i];
    let mut known = 0;
    for i in 0..rows {
        let u: Vec<f64> = (1..=n).map(|k| col(format!("u{k}"), i)).collect();
        let v: Vec<f64> = (1..=n).map(|k| col(format!("v{k}"), i)).collect();
        let fc: Vec<f64> = (1..=n_c).map(|k| col(format!("fc{k}"), i)).collect();
        let dm: Vec<f64> = (1..=n_c).map(|k| col(format!("dm{k}"), i)).collect();
        m.push(i, &u, &v, def.ground_motion.accel[i], &fc, &command[i], &dm);
        let id = m.identification();
        let expected = [m.eta(), m.margin()]
            .into_iter()
            .chain(id.stiffness().iter().chain(id.damping()).chain(id.lag()).copied());
        for (name, e) in tail.iter().zip(expected) {
            let got = h[name][i];
            assert!(same(got, e), "step {i}, {name}: history.csv {got}, indicator {e}");
        }
        known += usize::from(m.eta().is_finite() && m.margin().is_finite());
    }
    assert!(known > rows / 2, "only {known} of {rows} rows with both views known");
    // The summary's worst values are the columns' worst values.
    let s: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    let st = &s["stability"];
    assert_eq!(st["max_eta"].as_f64().unwrap(), finite_max(h["eta"].iter().copied()));
    assert_eq!(
        st["min_margin"].as_f64().unwrap(),
        -finite_max(h["margin"].iter().map(|x| -x))
    );
    assert_eq!(st["alarm_count"], 0);
    assert!(st["first_alarm_s"].is_null());
    let _ = std::fs::remove_dir_all(&dir);
}

/// The shipped test definitions with a substructure: `examples/*.toml` and the studies' base
/// tests (`examples/studies/*.toml` that are test definitions).
fn substructured_examples() -> Vec<PathBuf> {
    let examples = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples"));
    let mut names: Vec<PathBuf> = [examples.to_path_buf(), examples.join("studies")]
        .iter()
        .flat_map(|d| std::fs::read_dir(d).unwrap().map(|e| e.unwrap().path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .filter(|p| {
            let text = std::fs::read_to_string(p).unwrap();
            text.contains("[substructure]") && text.contains("[integrator]")
        })
        .collect();
    names.sort();
    names
}

#[test]
fn no_shipped_example_raises_a_stability_alarm() {
    let names = substructured_examples();
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
        assert_eq!(st["alarm_count"], 0, "{}", p.display());
        assert!(
            !s["warnings"]
                .as_array()
                .is_some_and(|w| w.iter().any(|w| w.as_str().unwrap_or("").contains("stability"))),
            "{}: {}",
            p.display(),
            s["warnings"]
        );
        // The history's columns agree with the summary's worst values.
        let (_, h) = read_csv(&dir.join("history.csv"));
        let max_eta = finite_max(h["eta"].iter().copied());
        let min_margin = -finite_max(h["margin"].iter().map(|x| -x));
        assert!(
            same(st["max_eta"].as_f64().unwrap_or(f64::NAN), max_eta),
            "{}",
            p.display()
        );
        assert!(
            same(st["min_margin"].as_f64().unwrap_or(f64::NAN), min_margin),
            "{}",
            p.display()
        );
        println!("{}: max η = {max_eta}, min margin = {min_margin}", p.display());
        checked += 1;
        let _ = std::fs::remove_dir_all(&dir);
    }
    assert!(checked >= 6, "only {checked} substructured examples");
}
