//! Issue "Stable by construction": the default ARX phase-lag compensation on a grid of damper
//! tests nobody tuned it for (docs/vst.md, "The damper grid"): dampers 1–5 MN·s/m, delays of
//! half a step to two steps, `k_sub` 1–10, behind a pure delay and behind a second-order
//! actuator with the delay. Against the exact solution of the assembled structure.

use substep::study::vst::grid::{GridActuator, GridRow, GridSettings, counts, damper_grid};

fn table(name: &str, rows: &[GridRow]) {
    println!(
        "{name}: damper [MN·s/m], delay [ms], k_sub: error without / with ARX (ratio); against the same integrator"
    );
    for r in rows {
        println!(
            "  {:>4.1} {:>4.0} {:>3}: {:>10.3e} / {:>10.3e} ({:.3}); {:>10.3e} / {:>10.3e} ({:.3}){}{}",
            r.damper / 1e6,
            r.delay * 1e3,
            r.k_sub,
            r.error_none,
            r.error_arx,
            r.ratio(),
            r.integrator_error_none,
            r.integrator_error_arx,
            r.integrator_ratio(),
            if r.stable_without() {
                ""
            } else {
                "  uncompensated unstable"
            },
            if r.backed_off { "  supervisor backed off" } else { "" }
        );
    }
    println!("  {:?}", counts(rows));
}

/// Every run whose error against the reference exceeds 100 %, or that ran away, ended as
/// diverged (not completed), compensated or not.
fn no_silent_divergence(rows: &[GridRow]) {
    for r in rows {
        for (err, completed, diverged, what) in [
            (r.error_none, r.completed_none, r.diverged_none, "uncompensated"),
            (r.error_arx, r.completed_arx, r.diverged_arx, "ARX"),
        ] {
            if substep::run::exceeds(err, 1.0) {
                assert!(
                    diverged && !completed,
                    "{what} {} MN·s/m, {} ms, k_sub {}: error {err:e} but diverged = {diverged}, completed = {completed}",
                    r.damper / 1e6,
                    r.delay * 1e3,
                    r.k_sub
                );
            }
            if completed {
                assert!(err <= 1.0, "{what}: completed with an error of {err:e}");
            }
        }
    }
}

fn check(rows: &[GridRow]) {
    no_silent_divergence(rows);
    let c = counts(rows);
    // Never diverges where the uncompensated test is stable.
    assert_eq!(c.diverged_with, 0, "{c:?}");
    // Delays of a step or more: at most 0.7 × the uncompensated error in at least 3/4.
    assert!(4 * c.step_delays_better >= 3 * c.step_delays, "{c:?}");
    for r in rows.iter().filter(|r| r.stable_without()) {
        // At most 1.2 × the uncompensated error — except, as docs/vst.md reports, at half a
        // step of delay with the lighter dampers, where the uncompensated test hardly feels
        // the delay (its error equals the delay-free one) and leading the smooth command costs
        // up to 2.9 × (≤ 2.9 % of the peak).
        let half_step = r.delay < 0.75 * 0.01;
        if half_step && r.damper <= 2.5e6 {
            assert!(r.ratio() <= 3.0 && r.error_arx <= 0.03, "{r:?}");
            // Where it is over 1.2 ×, even a perfect compensator would be: the time step's own
            // error (the test with an actuator that follows its commands) exceeds 1.2 × the
            // uncompensated test's, whose lag cancels part of it.
            if r.ratio() > 1.2 {
                assert!(r.time_step_error > 1.2 * r.error_none, "{r:?}");
            }
        } else {
            assert!(r.ratio() <= 1.2, "{r:?}");
        }
        // Against the assembled structure integrated with the test's own Newmark scheme — the
        // solution the test would give with a delay-free actuator moving smoothly, without the
        // integrator's own error, which a lag partly cancels — the compensator is never worse
        // than 1.2 × the uncompensated test, at half a step of delay too.
        assert!(r.integrator_ratio() <= 1.2, "against the same integrator: {r:?}");
    }
    // … and at most 0.7 × in every setting with a delay of a step or more.
    assert_eq!(c.step_delays_better_vs_integrator, c.step_delays, "{c:?}");
    assert_eq!(c.worse_vs_integrator, 0, "{c:?}");
}

#[test]
fn arx_compensation_on_the_damper_grid_behind_a_pure_delay() {
    let rows = damper_grid(&GridSettings::full(GridActuator::PureDelay)).unwrap();
    table("pure delay", &rows);
    check(&rows);
    // The issue's own test: 2.5 MN·s/m behind 10 ms, k_sub 1–10 — 7.8 % without, 2·10³¹ % at
    // k_sub = 3 with the compensator as it stood; now at most 0.3 × without.
    for r in rows.iter().filter(|r| r.damper == 2.5e6 && r.delay == 0.01) {
        assert!(r.ratio() < 0.3, "{r:?}");
    }
    // The 5 MN·s/m damper at k_sub = 10 is unstable without compensation: G_cc c/Δτ > 1/2, the
    // sub-step iteration itself diverges, and no compensator can help; those runs end as
    // diverged.
    assert!(rows.iter().any(|r| !r.stable_without()));
}

#[test]
fn arx_compensation_on_the_damper_grid_behind_a_second_order_actuator() {
    let actuator = GridActuator::SecondOrder {
        frequency: 40.0,
        zeta: 0.7,
    };
    let rows = damper_grid(&GridSettings::full(actuator)).unwrap();
    table("second order 40 Hz + delay", &rows);
    check(&rows);
}

/// The floor displacements of one grid run, step by step.
struct Displacements(Vec<Vec<f64>>);

impl substep::substructure::SubstepObserver for Displacements {}

impl substep::run::RunObserver for Displacements {
    fn step(&mut self, row: &substep::run::StepRow<'_>) -> std::ops::ControlFlow<()> {
        self.0.push(row.u.to_vec());
        std::ops::ControlFlow::Continue(())
    }
}

fn displacements(damper: f64, delay: f64, k_sub: usize, actuator: GridActuator, arx: bool) -> Vec<Vec<f64>> {
    let def = substep::study::vst::grid::definition(damper, delay, k_sub, actuator, arx).unwrap();
    let mut out = Displacements(Vec::new());
    let s = substep::run::execute(&def, &mut out, &std::sync::atomic::AtomicBool::new(false)).unwrap();
    assert!(s.completed, "{damper} {delay} {k_sub} {actuator:?} {arx}");
    out.0
}

/// Largest difference of two runs over steps and floors, relative to the peak of `b`.
fn distance(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let (mut diff, mut peak) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(b) {
        for (xi, yi) in x.iter().zip(y) {
            diff = diff.max((xi - yi).abs());
            peak = peak.max(yi.abs());
        }
    }
    diff / peak
}

/// Why the ≤ 1.2 × line is out of reach at half a step of delay (docs/vst.md, "Half a step of
/// delay"): measured against the same test with a delay-free ideal actuator, (1) a pure delay
/// shorter than a step is not felt by the damper at all — the actuator reproduces the
/// piecewise-linear command path, the damper's force is `c` × the slope of the segment the
/// delayed time falls in, and the sub-steps of one step share nearly one slope — so there is no
/// delay effect to remove and any lead can only add error; (2) where the delay is felt (a step)
/// the compensator removes it (≤ 0.1 × the uncompensated distance); (3) behind the 40 Hz
/// actuator, whose smooth motion the damper does feel, the compensated test is closer to the
/// delay-free test than the uncompensated one at half a step too, even where it is farther from
/// the exact solution.
#[test]
fn at_half_a_step_the_compensator_removes_what_the_damper_feels_of_the_actuator() {
    let second_order = GridActuator::SecondOrder {
        frequency: 40.0,
        zeta: 0.7,
    };
    for damper in [1.0e6, 2.5e6] {
        for k_sub in [1, 3] {
            let ideal = displacements(damper, 0.0, k_sub, GridActuator::PureDelay, false);
            let half = displacements(damper, 0.005, k_sub, GridActuator::PureDelay, false);
            let felt = distance(&half, &ideal);
            println!("{damper:e} N·s/m, k_sub {k_sub}: 5 ms pure delay vs none: {felt:.2e}");
            assert!(felt < 2e-3, "{damper} {k_sub}: {felt:e}");

            let step = displacements(damper, 0.01, k_sub, GridActuator::PureDelay, false);
            let step_arx = displacements(damper, 0.01, k_sub, GridActuator::PureDelay, true);
            let (none, arx) = (distance(&step, &ideal), distance(&step_arx, &ideal));
            println!("  10 ms pure delay vs none: uncompensated {none:.2e}, ARX {arx:.2e}");
            assert!(none > 0.03 && arx < 0.1 * none, "{damper} {k_sub}: {none:e} {arx:e}");

            let smooth = displacements(damper, 0.005, k_sub, second_order, false);
            let smooth_arx = displacements(damper, 0.005, k_sub, second_order, true);
            let (none, arx) = (distance(&smooth, &ideal), distance(&smooth_arx, &ideal));
            println!("  40 Hz + 5 ms vs none: uncompensated {none:.2e}, ARX {arx:.2e}");
            assert!(arx < 0.9 * none, "{damper} {k_sub}: {none:e} {arx:e}");
        }
    }
}

/// The grid's second reference is Newmark (average acceleration, the test's Δt) of the
/// assembled structure: the same as a monolithic run of the frame with the damper written into
/// its damping matrix (Rayleigh coefficients computed here from the eigenvalues), and apart from
/// the exact solution by the integrator's own error. The summary's `same_integrator` errors are
/// those recomputed here from the test's, the monolithic run's and the exact reference's
/// displacement histories.
#[test]
fn the_same_integrator_reference_is_newmark_of_the_assembled_structure() {
    use nalgebra::{DMatrix, SymmetricEigen};
    let damper = 2.5e6;
    let def = substep::study::vst::grid::definition(damper, 0.01, 3, GridActuator::PureDelay, false).unwrap();
    let accel = def.ground_motion.accel.clone();
    let mut same = substep::run::Reference::same_integrator(&def).unwrap().unwrap();
    assert_eq!(same.scheme(), "newmark");

    let m = DMatrix::from_diagonal_element(3, 3, 2.0e5);
    let k = DMatrix::from_row_slice(3, 3, &[4e8, -2e8, 0.0, -2e8, 4e8, -2e8, 0.0, -2e8, 2e8]);
    let mut w: Vec<f64> = SymmetricEigen::new(&k / 2.0e5f64)
        .eigenvalues
        .iter()
        .map(|x: &f64| x.sqrt())
        .collect();
    w.sort_by(f64::total_cmp);
    let (a0, a1) = (2.0 * 0.02 * w[0] * w[1] / (w[0] + w[1]), 2.0 * 0.02 / (w[0] + w[1]));
    let mut c = &m * a0 + &k * a1;
    c[(0, 0)] += damper;
    let rows = |x: &DMatrix<f64>| {
        let r: Vec<String> = (0..3)
            .map(|i| format!("[{:e}, {:e}, {:e}]", x[(i, 0)], x[(i, 1)], x[(i, 2)]))
            .collect();
        format!("[{}]", r.join(", "))
    };
    let text = format!(
        "[structure]\nmass = {}\nstiffness = {}\ndamping = {}\n[ground_motion]\ngenerator = \"harmonic\"\n\
         amplitude = 1.0\nfrequency = 1.0\nduration = 30.0\n[integrator]\nscheme = \"average_acceleration\"\ndt = 0.01\n",
        rows(&m),
        rows(&k),
        rows(&c)
    );
    let mut mono = substep::io::TestDefinition::from_toml(&text, "monolithic", std::path::Path::new(".")).unwrap();
    mono.ground_motion.accel = accel.clone();
    let mut newmark = Displacements(Vec::new());
    let s = substep::run::execute(&mono, &mut newmark, &std::sync::atomic::AtomicBool::new(false)).unwrap();
    assert!(s.completed);
    for (i, u) in newmark.0.iter().enumerate() {
        if i > 0 {
            same.step(accel[i]).unwrap();
        }
        for (&u, &s) in u.iter().zip(same.u()) {
            assert!((u - s).abs() <= 1e-9 * 0.05, "step {i}: {u} {s}");
        }
    }

    // The test and its exact reference, step by step.
    let mut test = Displacements(Vec::new());
    let mut exact = References(Vec::new());
    let summary = substep::run::execute(&def, &mut Both(&mut test, &mut exact), &Default::default()).unwrap();
    let r = summary.reference.as_ref().unwrap();
    assert_eq!(r.scheme, "exact");
    let split = r.same_integrator.as_ref().unwrap();
    let test_error = largest_dof_error(&test.0, &newmark.0);
    let integration_error = largest_dof_error(&newmark.0, &exact.0);
    println!(
        "test vs Newmark {test_error:.4e} (summary {:.4e}); Newmark vs exact {integration_error:.4e} (summary {:.4e}); test vs exact {:.4e}",
        split.max_displacement_error, split.integration_error, r.max_displacement_error
    );
    assert!((split.max_displacement_error - test_error).abs() < 1e-9 * test_error);
    assert!((split.integration_error - integration_error).abs() < 1e-9 * integration_error);
    // Newmark at Δt = 10 ms is 1.4 % off the exact solution here; the delayed test 9 % off Newmark.
    assert!(
        integration_error > 5e-3 && integration_error < 3e-2,
        "{integration_error:e}"
    );
    assert!(test_error > 5e-2, "{test_error:e}");
}

/// The reference's displacements of a run, step by step.
struct References(Vec<Vec<f64>>);

impl substep::substructure::SubstepObserver for References {}

impl substep::run::RunObserver for References {
    fn step(&mut self, row: &substep::run::StepRow<'_>) -> std::ops::ControlFlow<()> {
        self.0.push(row.reference.unwrap().to_vec());
        std::ops::ControlFlow::Continue(())
    }
}

/// Two observers fed the same rows.
struct Both<'a>(&'a mut Displacements, &'a mut References);

impl substep::substructure::SubstepObserver for Both<'_> {}

impl substep::run::RunObserver for Both<'_> {
    fn step(&mut self, row: &substep::run::StepRow<'_>) -> std::ops::ControlFlow<()> {
        let _ = self.0.step(row);
        self.1.step(row)
    }
}

/// The summary's statistic: over the DOFs, the largest |a − b| relative to that DOF's peak |b|.
fn largest_dof_error(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    (0..b[0].len())
        .map(|k| {
            let err = a.iter().zip(b).map(|(x, y)| (x[k] - y[k]).abs()).fold(0.0, f64::max);
            let peak = b.iter().map(|y| y[k].abs()).fold(0.0, f64::max);
            err / peak
        })
        .fold(0.0, f64::max)
}
