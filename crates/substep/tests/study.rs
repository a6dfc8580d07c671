//! Parameter studies (substep::study): each row equals a run of the config edited by hand,
//! rows do not depend on the thread count or on which runs are run together, sampled
//! parameters follow their seeded distributions, and a bad override fails only its own run,
//! naming the run and the key.

use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use substep::io::TestDefinition;
use substep::run::{HistoryTable, execute};
use substep::study::{Metric, Study, summary_runner, to_csv};

/// The embedded default example (TMD behind a second-order actuator, noisy load cell, exact
/// reference), shortened to 1 s so that a run takes milliseconds.
fn base() -> String {
    let text = include_str!("../../../examples/default.toml").replace("duration = 20.0", "duration = 1.0");
    assert!(text.contains("duration = 1.0"));
    text
}

fn study(spec: &str) -> Study {
    Study::from_json(&base(), "default.toml", Path::new("."), spec).unwrap()
}

/// The metric `name` of a run of `text`, run directly (no study machinery).
fn direct(text: &str, names: &[&str]) -> Vec<f64> {
    let def = TestDefinition::from_toml(text, "edited.toml", Path::new(".")).unwrap();
    let summary = execute(&def, &mut HistoryTable::default(), &AtomicBool::new(false)).unwrap();
    let json = serde_json::to_value(&summary).unwrap();
    names.iter().map(|n| Metric::parse(n).unwrap().value(&json)).collect()
}

const METRICS: &[&str] = &[
    "max_displacement_error",
    "rms_force_error",
    "tracking_delay",
    "peak_displacement",
];

#[test]
fn grid_rows_equal_runs_of_the_edited_config() {
    let s = study(
        r#"{"grid": {"substructure.substeps": [1, 4], "substructure.actuator.delay": [0.001, 0.01]},
            "metrics": ["max_displacement_error", "rms_force_error", "tracking_delay", "peak_displacement"]}"#,
    );
    assert_eq!(s.len(), 4);
    // BTreeMap order of the keys: actuator.delay first (slowest), then substeps.
    assert_eq!(s.parameters(), ["substructure.actuator.delay", "substructure.substeps"]);
    let count = AtomicUsize::new(0);
    let rows = s
        .run_all(2, &summary_runner, &|| {
            count.fetch_add(1, Ordering::Relaxed);
        })
        .unwrap();
    assert_eq!(count.load(Ordering::Relaxed), 4);
    let expected = [(0.001, 1), (0.001, 4), (0.01, 1), (0.01, 4)];
    for (row, (delay, k)) in rows.iter().zip(expected) {
        assert!(row.completed, "{}", row.error);
        assert_eq!(row.values[0].as_float(), Some(delay));
        assert_eq!(row.values[1].as_integer(), Some(k));
        let edited = base()
            .replace("delay = 0.001 ", &format!("delay = {delay} "))
            .replace("substeps = 4 ", &format!("substeps = {k} "));
        assert_eq!(row.metrics, direct(&edited, METRICS), "delay {delay}, k_sub {k}");
    }
    // The variants differ: a 10 ms actuator delay tracks 9 ms later than a 1 ms one (±1 sub-step).
    let lag = rows[3].metrics[2] - rows[1].metrics[2];
    assert!((lag - 0.009).abs() <= 0.01 / 4.0 + 1e-12, "{lag}");
    assert!(rows[2].metrics[0] > rows[0].metrics[0], "more delay, larger error");
}

#[test]
fn rows_do_not_depend_on_threads_or_batches() {
    let s = study(
        r#"{"samples": {"n": 6, "seed": 3, "params": {
               "substructure.specimen.0.stiffness": {"dist": "uniform", "low": 0.9, "high": 1.1, "relative": true},
               "substructure.actuator.delay": {"dist": "uniform", "low": 0.005, "high": 0.015}}},
            "seeds": [1, 2]}"#,
    );
    assert_eq!(s.len(), 12);
    let serial = s.run_all(1, &summary_runner, &|| {}).unwrap();
    let parallel = s.run_all(2, &summary_runner, &|| {}).unwrap();
    let batch = s.run(&[7, 3], 2, &summary_runner, &|| {}).unwrap();
    let bits = |r: &substep::study::Row| {
        (
            r.index,
            r.values.clone(),
            r.completed,
            r.metrics.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        )
    };
    for (a, b) in serial.iter().zip(&parallel) {
        assert_eq!(bits(a), bits(b));
    }
    assert_eq!(bits(&batch[0]), bits(&serial[7]));
    assert_eq!(bits(&batch[1]), bits(&serial[3]));
    // Seeds vary fastest and share the sampled parameters; the noise seed changes the result.
    assert_eq!(serial[0].values[..2], serial[1].values[..2]);
    assert_eq!(serial[0].values[2].as_integer(), Some(1));
    assert_eq!(serial[1].values[2].as_integer(), Some(2));
    assert_ne!(serial[0].metrics[0], serial[1].metrics[0]);
    let k0 = 1973.9208802178716;
    for r in &serial {
        // sampled keys in name order: the delay, then the stiffness
        let d = r.values[0].as_float().unwrap();
        let k = r.values[1].as_float().unwrap();
        assert!((0.9 * k0..1.1 * k0).contains(&k), "{k}");
        assert!((0.005..0.015).contains(&d), "{d}");
        assert!(r.completed, "{}", r.error);
    }
    // the CSV: header, one line per run, in run order
    let csv = to_csv(&s, &serial);
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 13);
    assert!(lines[0].starts_with(
        "run,substructure.actuator.delay,substructure.specimen.0.stiffness,substructure.sensors.seed,completed,"
    ));
    assert!(lines[1].starts_with("0,"));
}

#[test]
fn a_bad_override_fails_only_its_run_and_names_run_and_key() {
    let s = study(
        r#"{"grid": {"substructure.actuator.delay": [0.002, -0.5, 0.004]}, "metrics": ["max_displacement_error"]}"#,
    );
    let rows = s.run_all(2, &summary_runner, &|| {}).unwrap();
    assert!(rows[0].completed && rows[2].completed);
    assert!(!rows[1].completed);
    assert!(rows[1].metrics[0].is_nan());
    let e = &rows[1].error;
    assert!(e.starts_with("run 1 [substructure.actuator.delay = -0.5]: "), "{e}");
    assert!(e.contains("substructure.actuator.delay"), "{e}");
    // an unknown key: the config parser's error, with the run and the key
    let s = study(r#"{"grid": {"substructure.actuator.dealy": [0.002]}, "metrics": ["max_displacement_error"]}"#);
    let rows = s.run_all(1, &summary_runner, &|| {}).unwrap();
    let e = &rows[0].error;
    assert!(!rows[0].completed);
    assert!(e.starts_with("run 0 [substructure.actuator.dealy = 0.002]: "), "{e}");
    assert!(e.contains("unknown field `dealy`"), "{e}");
    // a path through a number fails at the override, before the parser
    let s = study(r#"{"grid": {"integrator.dt.x": [1]}, "metrics": ["steps_done"]}"#);
    let rows = s.run_all(1, &summary_runner, &|| {}).unwrap();
    assert!(
        rows[0].error.contains("`integrator.dt` is a float, not a table"),
        "{}",
        rows[0].error
    );
}

#[test]
fn bad_study_settings_are_refused_naming_the_key() {
    let err = |spec: &str| {
        Study::from_json(&base(), "default.toml", Path::new("."), spec)
            .unwrap_err()
            .to_string()
    };
    assert_eq!(
        err(r#"{"samples": {"n": 2, "params": {"x.y": {"dist": "gamma", "low": 1}}}}"#),
        "study: samples.params.x.y: unknown distribution `gamma` (expected uniform, normal or log_uniform)"
    );
    assert_eq!(
        err(
            r#"{"samples": {"n": 2, "params": {"integrator.scheme": {"dist": "uniform", "low": 0.9, "high": 1.1, "relative": true}}}}"#
        ),
        "study: samples.params.integrator.scheme: relative = true needs a number at `integrator.scheme` in the base config"
    );
    assert!(err(r#"{"metrics": ["max_error"]}"#).starts_with("study: metrics: unknown metric `max_error`"));
    assert!(err(r#"{"grid": {"a": []}}"#).contains("grid.a: needs at least one value"));
    assert!(err(r#"{"gird": {}}"#).contains("unknown field `gird`"));
}
