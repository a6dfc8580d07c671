//! The run API (`substep::run`): the in-memory recorder holds the rows the summary is made of,
//! the summary's statistics agree with a straightforward recomputation from those rows, the
//! CSV form round-trips, and a run can be cancelled or stopped by its observer.

use std::ops::ControlFlow;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use substep::io::TestDefinition;
use substep::run::{HistoryTable, RunObserver, StepRow, execute};
use substep::substructure::SubstepObserver;

/// The default example (TMD on an SDOF, k_sub = 4, P = 1 compensation), 2 s instead of 20.
fn short_default(extra: &str) -> TestDefinition {
    let text = include_str!("../../../examples/default.toml").replace("duration = 20.0", "duration = 2.0") + extra;
    TestDefinition::from_toml(&text, "short.toml", Path::new(".")).unwrap()
}

fn max_abs(x: &[f64]) -> (usize, f64) {
    x.iter()
        .enumerate()
        .fold((0, 0.0_f64), |b, (i, &v)| if v.abs() > b.1 { (i, v.abs()) } else { b })
}

#[test]
fn summary_statistics_agree_with_the_recorded_rows() {
    let def = short_default("");
    let mut table = HistoryTable::default();
    let s = execute(&def, &mut table, &AtomicBool::new(false)).unwrap();
    assert!(s.completed && s.failure.is_none());
    assert_eq!(s.steps_done, 200);
    let h = &table.history;
    assert_eq!(h.rows(), 201, "one row per step from t = 0");
    assert_eq!(
        h.names,
        // The stability indicator runs by default: its columns close the row.
        [
            "t", "u1", "v1", "a1", "fc1", "fe1", "fu1", "dm1", "fei1", "uref1", "eta", "margin", "k_id1", "c_id1",
            "lag_id1"
        ]
    );
    let t = h.column("t").unwrap();
    assert_eq!((t[0], t[1], t[200]), (0.0, 0.01, 2.0));
    // Peaks: the largest |u|, |v|, |a|, |f_c| and the time they occurred.
    for (name, peak) in [("u1", s.peaks[0].u), ("v1", s.peaks[0].v), ("a1", s.peaks[0].a)] {
        let (i, m) = max_abs(h.column(name).unwrap());
        assert_eq!(peak.max_abs, m, "{name}");
        assert_eq!(peak.t, i as f64 * 0.01, "{name}");
    }
    let fc = s.coupling_peaks.as_ref().unwrap()[0].force;
    assert_eq!(fc.max_abs, max_abs(h.column("fc1").unwrap()).1);
    // Errors against the reference: peak and RMS of u − u_ref over the peak |u_ref|.
    let (u, uref) = (h.column("u1").unwrap(), h.column("uref1").unwrap());
    let err: Vec<f64> = u.iter().zip(uref).map(|(a, b)| a - b).collect();
    let peak_ref = max_abs(uref).1;
    let r = &s.reference.as_ref().unwrap().dofs[0];
    assert_eq!(r.displacement.reference_peak, peak_ref);
    assert_eq!(r.displacement.peak_error, max_abs(&err).1 / peak_ref);
    let rms = (err.iter().map(|e| e * e).sum::<f64>() / err.len() as f64).sqrt();
    assert!((r.displacement.rms_error - rms / peak_ref).abs() < 1e-12 * r.displacement.rms_error);
    // A test this close to the exact solution: below 5 % peak error, and not zero.
    assert!(
        r.displacement.peak_error > 1e-4 && r.displacement.peak_error < 0.05,
        "{r:?}"
    );
    // Sub-steps: k_sub = 4 rows per step, the last one of each step at t = i·Δt.
    let sub = table.substeps.as_ref().unwrap();
    assert_eq!(sub.names, ["step", "substep", "t", "cmd1", "fm1", "dm1"]);
    assert_eq!(sub.rows(), 800);
    assert_eq!(sub.column("t").unwrap()[7], 0.02);
    // The engineering rows (SDOF: a shear chain of one storey).
    let resp = table.response.as_ref().unwrap();
    assert_eq!(resp.rows(), 201);
    let e = s.engineering.as_ref().unwrap();
    assert_eq!(e.peak_base_shear.peak, max_abs(resp.column("base_shear").unwrap()).1);
}

#[test]
fn the_csv_form_round_trips() {
    let def = short_default("");
    let mut table = HistoryTable::default();
    execute(&def, &mut table, &AtomicBool::new(false)).unwrap();
    for t in [&table.history, table.substeps.as_ref().unwrap()] {
        let mut bytes = Vec::new();
        t.write_csv(&mut bytes).unwrap();
        let text = String::from_utf8(bytes).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next().unwrap(), t.names.join(","));
        let mut rows = 0;
        for (r, line) in lines.enumerate() {
            for (c, field) in line.split(',').enumerate() {
                let x: f64 = field.parse().unwrap();
                assert!(
                    x == t.columns[c][r] || (x.is_nan() && t.columns[c][r].is_nan()),
                    "{field}"
                );
            }
            rows += 1;
        }
        assert_eq!(rows, t.rows());
    }
}

#[test]
fn a_cancelled_run_says_so_and_keeps_its_rows() {
    let def = short_default("");
    let mut table = HistoryTable::default();
    let s = execute(&def, &mut table, &AtomicBool::new(true)).unwrap();
    assert!(!s.completed);
    assert_eq!((s.steps_done, s.stopped_at_step), (0, Some(1)));
    assert!(s.reason.as_deref().unwrap().contains("cancelled"), "{:?}", s.reason);
    assert_eq!(table.history.rows(), 1);
    // An interrupted caller does not wait for the input motion's spectrum.
    assert!(s.input_motion.pga_m_s2.is_nan() && s.input_motion.spectrum_peak.is_none());

    /// Stops after `n` steps.
    struct StopAfter(usize);
    impl SubstepObserver for StopAfter {}
    impl RunObserver for StopAfter {
        fn step(&mut self, row: &StepRow<'_>) -> ControlFlow<()> {
            if row.step == self.0 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        }
    }
    let s = execute(&def, &mut StopAfter(17), &AtomicBool::new(false)).unwrap();
    assert_eq!((s.completed, s.steps_done, s.stopped_at_step), (false, 17, Some(18)));
    let json = s.to_json();
    assert!(json.contains("\"completed\": false") && json.contains("\"stopped_at_step\": 18"));
}

#[test]
fn input_errors_come_before_the_first_row() {
    // A specimen on a DOF the model does not have: refused by the validation, nothing recorded.
    let text = include_str!("../../../examples/default.toml").replace("coupling_dofs = [1]", "coupling_dofs = [2]");
    let err = match TestDefinition::from_toml(&text, "bad.toml", Path::new(".")) {
        Err(e) => e,
        Ok(def) => {
            let mut table = HistoryTable::default();
            let e = execute(&def, &mut table, &AtomicBool::new(false)).unwrap_err();
            assert_eq!(table.history.rows(), 0);
            e
        }
    };
    assert!(err.to_string().starts_with("bad.toml"), "{err}");
}

/// The summary's `same_integrator` split: its `integration_error` is Newmark of the assembled
/// system against the exact solution, so it shrinks with the scheme's order of accuracy — four
/// times per halved Δt for the second-order average-acceleration scheme, twice for the
/// first-order backward-difference one (γ = 3/2) — and, being a property of the structure alone,
/// it does not change with the actuator.
#[test]
fn the_time_steps_share_shrinks_with_the_order_of_the_scheme() {
    let share = |scheme: &str, dt: f64, ideal_actuator: bool| {
        let mut text = include_str!("../../../examples/default.toml")
            .replace("duration = 20.0", "duration = 5.0")
            .replace("scheme = \"average_acceleration\"", &format!("scheme = \"{scheme}\""))
            .replace("dt = 0.01 ", &format!("dt = {dt} "));
        if ideal_actuator {
            let a = text.find("kind = \"second_order\"").unwrap();
            let b = text[a..].find("\n\n").unwrap();
            text.replace_range(a..a + b, "kind = \"ideal\"");
        }
        let def = TestDefinition::from_toml(&text, "order.toml", Path::new(".")).unwrap();
        assert_eq!(def.integrator.dt, dt);
        let s = execute(&def, &mut HistoryTable::default(), &AtomicBool::new(false)).unwrap();
        assert!(s.completed);
        let r = s.reference.unwrap();
        assert_eq!(r.scheme, "exact");
        r.same_integrator.unwrap().integration_error
    };
    for (scheme, order) in [("average_acceleration", 2), ("backward_difference", 1)] {
        let e: Vec<f64> = [0.0025, 0.005, 0.01]
            .iter()
            .map(|&dt| share(scheme, dt, false))
            .collect();
        let expected = 2f64.powi(order);
        println!("{scheme}: {e:?}, ratios {:.3} {:.3}", e[1] / e[0], e[2] / e[1]);
        for pair in e.windows(2) {
            let ratio = pair[1] / pair[0];
            assert!(
                (ratio / expected - 1.0).abs() < 0.1,
                "{scheme}: {ratio} for order {order}"
            );
        }
    }
    assert_eq!(
        share("average_acceleration", 0.01, true),
        share("average_acceleration", 0.01, false)
    );
}

/// Benchmark (docs/performance.md, "The same-integrator reference"; run with `--ignored
/// --nocapture`): what the second reference costs beside the exact one, on shear buildings of
/// 3 to 199 storeys with a damper specimen at floor 1 (20 s, Δt = 10 ms, k_sub = 4). Prints
/// numbers, asserts none.
#[test]
#[ignore]
fn same_integrator_cost() {
    use std::time::Instant;
    use substep::run::Reference;
    struct Nothing;
    impl SubstepObserver for Nothing {}
    impl RunObserver for Nothing {
        fn step(&mut self, _row: &StepRow<'_>) -> ControlFlow<()> {
            ControlFlow::Continue(())
        }
    }
    println!("storeys | whole run [s] | exact reference [s] | same-integrator reference [s] | its share of the run");
    for n in [3usize, 20, 60, 150, 199] {
        let text = format!(
            "[structure.shear_building]\nstories = {n}\nstory_mass = 1.0e5\nfirst_period = 1.0\n\
             [structure.modal]\nzeta = 0.05\n[ground_motion]\ngenerator = \"harmonic\"\namplitude = 1.0\n\
             frequency = 1.0\nduration = 20.0\n[integrator]\nscheme = \"average_acceleration\"\ndt = 0.01\n\
             [substructure]\ncoupling_dofs = [1]\nsubsteps = 4\n[[substructure.specimen]]\nkind = \"linear_sdof\"\n\
             dof = 1\nstiffness = 0.0\ndamping = 1.0e6\n[substructure.actuator]\nkind = \"ideal\"\n\
             [substructure.error_force]\nkind = \"pid\"\np = 1.0\n"
        );
        let mut def = TestDefinition::from_toml(&text, "cost", Path::new(".")).unwrap();
        def.substructure.as_mut().unwrap().stability_off = true;
        let t = Instant::now();
        assert!(execute(&def, &mut Nothing, &AtomicBool::new(false)).unwrap().completed);
        let run = t.elapsed().as_secs_f64();
        let accel = &def.ground_motion.accel;
        let time = |mut r: Reference| {
            let t = Instant::now();
            for &a in &accel[1..] {
                r.step(a).unwrap();
            }
            t.elapsed().as_secs_f64()
        };
        let exact = time(Reference::new(&def).unwrap().unwrap());
        let same = time(Reference::same_integrator(&def).unwrap().unwrap());
        println!("{n} | {run:.3} | {exact:.3} | {same:.3} | {:.0} %", 100.0 * same / run);
    }
}
