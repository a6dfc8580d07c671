//! Issue 38: yielding numerical substructures against the wall clock. A grid of real-time
//! tests (two yielding buildings × three intensities, from elastic to ductility > 5 × two
//! specimens × k_sub 2–10) at Δt = 5 ms with the default late policy (`hold`: the test keeps
//! the wall clock, as in a lab). Each run must miss < 1 % of its sub-step deadlines and stay
//! within 3 % of its converged Newmark + Newton reference (the offline run's `uref`).
//! Measured on the full grid (2-core VM, no SCHED_FIFO, error-force compensation P = 1): worst
//! error 2.06 % (3-storey, scale 2, ductility 34, k_sub 10), worst missed share 0.20 %, ductility
//! 0.70–0.81 (elastic level), 3.3–5.0, 19–34.
//!
//! In CI each cell of structure × intensity × specimen runs with one k_sub (2, 5, 10 in turn;
//! 12 runs of 4 s of El Centro's strong motion). `SUBSTEP_FULL_GRID=1` runs every k_sub in every
//! cell (36 runs, 8 s each). A cell that misses ≥ 1 % of its deadlines is rerun once (a VM stall
//! once hit one cell with 1.2 %, and a parallel build another with 42 %); a second miss, or more
//! than one rerun in the grid, fails.

use std::sync::atomic::AtomicBool;
use substep::io::TestDefinition;
use substep::realtime::{RealtimeOptions, RealtimeRunner, StepRecordOwned};
use substep::run::{HistoryTable, execute};

mod common;
use common::yielding::{SPECIMENS, STRUCTURES, Structure, write_record};

fn config(s: &Structure, scale: f64, specimen: &str, k_sub: usize, duration: f64) -> String {
    format!(
        r#"{storeys}
[structure.rayleigh]
zeta = 0.02
modes = [1, 2]
[ground_motion]
file = "elcentro_strong.csv"
scale = {scale}
[integrator]
scheme = "average_acceleration"
dt = 0.005
duration = {duration}
[substructure]
coupling_dofs = [1]
substeps = {k_sub}
[substructure.error_force]
kind = "pid"
p = 1.0
[[substructure.specimen]]
dof = 1
{specimen}
"#,
        storeys = s.storeys
    )
}

/// The test of `def` against the wall clock, built as `substep run --realtime` builds it.
fn realtime(def: &TestDefinition) -> (substep::realtime::RealtimeReport, Vec<StepRecordOwned>) {
    let sub = def.substructure.as_ref().unwrap();
    let accel = def.ground_motion.accel.clone();
    let load0 = -def.model.effective_mass_vector() * accel[0];
    let mut test = sub.build_test(&def.model, def.integrator.dt, &load0).unwrap();
    test.controller
        .set_springs(def.hysteresis.as_ref().unwrap().build(def.model.n_dofs()).unwrap());
    let runner = RealtimeRunner::new(&def.model, test, accel, RealtimeOptions::default()).unwrap();
    let mut records = Vec::new();
    match runner.run(|r: &StepRecordOwned| records.push(r.clone())) {
        Ok((report, _)) => (report, records),
        Err(f) => panic!("the real-time run failed: {f}"),
    }
}

/// Largest over the floors of peak |u − u_ref| over that floor's peak |u_ref|, as the summary's
/// `max_displacement_error`; and the largest storey ductility of the reference.
fn error_and_ductility(records: &[StepRecordOwned], reference: &HistoryTable, yield_drift: &[f64]) -> (f64, f64) {
    let n = yield_drift.len();
    let uref: Vec<&[f64]> = (1..=n)
        .map(|i| reference.history.column(&format!("uref{i}")).unwrap())
        .collect();
    assert_eq!(records.len(), uref[0].len());
    let mut error = 0.0f64;
    for (i, u) in uref.iter().enumerate() {
        let peak = u.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let diff = records.iter().map(|r| (r.u[i] - u[r.step]).abs()).fold(0.0, f64::max);
        error = error.max(diff / peak);
    }
    let ductility = (0..n)
        .map(|s| {
            let drift = (0..uref[0].len())
                .map(|t| (uref[s][t] - if s == 0 { 0.0 } else { uref[s - 1][t] }).abs())
                .fold(0.0, f64::max);
            drift / yield_drift[s]
        })
        .fold(0.0, f64::max);
    (error, ductility)
}

#[test]
fn a_grid_of_yielding_real_time_tests_keeps_time_and_its_reference() {
    let full = std::env::var_os("SUBSTEP_FULL_GRID").is_some_and(|v| v == "1");
    let duration = if full { 8.0 } else { 4.0 };
    let dir = std::env::temp_dir().join(format!("substep-rt-grid-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    write_record(&dir);
    let mut cell = 0usize;
    let mut worst_error = (0.0f64, String::new());
    let mut worst_missed = (0.0f64, String::new());
    let mut runs = 0;
    let mut reruns = 0;
    for s in &STRUCTURES {
        for (level, &scale) in s.scales.iter().enumerate() {
            for (specimen_name, specimen) in SPECIMENS {
                let ks: Vec<usize> = if full {
                    vec![2, 5, 10]
                } else {
                    vec![[2, 5, 10][cell % 3]]
                };
                cell += 1;
                for k_sub in ks {
                    let name = format!("{} × {scale} × {specimen_name} × k_sub {k_sub}", s.name);
                    let text = config(s, scale, specimen, k_sub, duration);
                    let def = TestDefinition::from_toml(&text, "grid.toml", &dir).unwrap();
                    let mut reference = HistoryTable::default();
                    let offline = execute(&def, &mut reference, &AtomicBool::new(false)).unwrap();
                    assert!(offline.completed, "{name}: offline {:?}", offline.failure);
                    let (mut report, mut records) = realtime(&def);
                    let share =
                        |r: &substep::realtime::RealtimeReport| r.missed as f64 / (r.substeps + r.hold_substeps) as f64;
                    if share(&report) >= 0.01 {
                        // A shared VM stalls now and then (a neighbour's burst, another test
                        // binary's build): one rerun of the cell, both printed; a cell that
                        // misses its deadlines twice fails.
                        println!(
                            "{name}: missed {} of {} ({:.3} %) — rerunning the cell once",
                            report.missed,
                            report.substeps + report.hold_substeps,
                            100.0 * share(&report)
                        );
                        (report, records) = realtime(&def);
                        reruns += 1;
                    }
                    let slots = report.substeps + report.hold_substeps;
                    let missed = share(&report);
                    let (error, ductility) = error_and_ductility(&records, &reference, s.yield_drift);
                    let offline_error = offline.reference.as_ref().unwrap().max_displacement_error;
                    println!(
                        "{name}: ductility {ductility:.2}, error vs Newton {:.3} % (offline {:.3} %), \
                         missed {} of {slots} ({:.3} %), holds {}, springs pipeline p99 {:?}",
                        100.0 * error,
                        100.0 * offline_error,
                        report.missed,
                        100.0 * missed,
                        report.hold_substeps,
                        report.pipeline.percentile(0.99)
                    );
                    match level {
                        0 => assert!(ductility < 1.0, "{name}: the elastic level yields ({ductility})"),
                        2 => assert!(ductility > 5.0, "{name}: ductility {ductility} ≤ 5"),
                        _ => assert!(
                            ductility > 1.0,
                            "{name}: the moderate level does not yield ({ductility})"
                        ),
                    }
                    assert!(missed < 0.01, "{name}: {:.3} % of the deadlines missed", 100.0 * missed);
                    assert!(error < 0.03, "{name}: {:.3} % from the Newton reference", 100.0 * error);
                    assert_eq!(records.len(), report.steps + 1, "{name}");
                    if error > worst_error.0 {
                        worst_error = (error, name.clone());
                    }
                    if missed >= worst_missed.0 {
                        worst_missed = (missed, name.clone());
                    }
                    runs += 1;
                }
            }
        }
    }
    println!(
        "{runs} runs ({reruns} rerun): worst error {:.3} % ({}), worst missed share {:.3} % ({})",
        100.0 * worst_error.0,
        worst_error.1,
        100.0 * worst_missed.0,
        worst_missed.1
    );
    // More than one stalled cell is not a noisy neighbour any more.
    assert!(
        reruns <= 1,
        "{reruns} cells missed more than 1 % of their deadlines on the first try"
    );
    assert_eq!(runs, if full { 36 } else { 12 });
}
