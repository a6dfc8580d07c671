//! The on-line stability indicator (docs/theory.md §15) against closed forms and against the
//! amplification-matrix analysis run directly; the operator's stop through the safety ramp.

use std::f64::consts::PI;
use std::path::Path;
use substep::analysis::StepMap;
use substep::io::TestDefinition;
use substep::model::sdof;
use substep::monitor::energy::EnergyIndicator;
use substep::monitor::model_view::{Identification, ModelView};
use substep::monitor::{Controls, StopRequest, frame_ring, token_matches};
use substep::run::Simulation;
use substep::specimen::SpecimenSpec;
use substep::substructure::{ErrorForceSpec, SubstepController, SubstepSettings, SubstructureTest};
use substep::transfer::{ActuatorSpec, Dynamics, SensorSpec, VirtualLab};

/// Spring `k` and dashpot `c` behind a pure delay `τ`, command `A sin ωt`, sampled every `dt`:
/// (force on the structure, command, measured displacement) at step `i`.
fn delayed_spring(i: usize, dt: f64, a: f64, w: f64, tau: f64, k: f64, c: f64) -> (f64, f64, f64) {
    let t = i as f64 * dt;
    let d = a * (w * t).sin();
    let x = a * (w * (t - tau)).sin();
    let xdot = a * w * (w * (t - tau)).cos();
    (-(k * x + c * xdot), d, x)
}

#[test]
fn energy_added_by_a_pure_delay_matches_the_closed_form() {
    // Per cycle: W_m = π c ω A², W_n = −π k A² sin ωτ + π c ω A² cos ωτ, so the transfer system
    // adds E_a = π A² (k sin ωτ + c ω (1 − cos ωτ)) and η = E_a / W_m (no numerical damping).
    let (a, f, tau, k, c) = (0.01, 1.0, 0.012, 2.0e4, 300.0);
    let w = 2.0 * PI * f;
    let dt = 1e-3;
    let per_cycle = 1000; // steps of one period
    let cycles = 5;
    let mut e = EnergyIndicator::new(1, 2 * per_cycle);
    for i in 0..=cycles * per_cycle {
        let (force, d, x) = delayed_spring(i, dt, a, w, tau, k, c);
        e.push(&[force], &[d], &[x], 0.0, 0.0);
    }
    let added = PI * a * a * (k * (w * tau).sin() + c * w * (1.0 - (w * tau).cos()));
    let measured = PI * c * w * a * a;
    let rel = |x: f64, r: f64| ((x - r) / r).abs();
    assert!(
        rel(e.total_added(), cycles as f64 * added) < 1e-4,
        "added {} vs {}",
        e.total_added(),
        cycles as f64 * added
    );
    assert!(rel(e.total_measured_work(), cycles as f64 * measured) < 1e-4);
    assert!(rel(e.window_added(), 2.0 * added) < 1e-4);
    let eta = added / measured;
    assert!(rel(e.eta(), eta) < 1e-4, "eta {} vs {eta}", e.eta());
}

#[test]
fn energy_indicator_without_delay_adds_nothing_and_counts_numerical_damping() {
    let (a, w, k, c, dt) = (0.02, 2.0 * PI * 0.5, 1.0e4, 50.0, 2e-3);
    let mut e = EnergyIndicator::new(1, 1000);
    // Numerical damping c_n ẋ ẋ dissipates π c_n ω A² per cycle; feed it as E_D.
    let c_n = 150.0;
    let per_cycle = 2000;
    for i in 0..=2 * per_cycle {
        let (force, d, x) = delayed_spring(i, dt, a, w, 0.0, k, c);
        let t = i as f64 * dt;
        let ed = c_n * a * a * w * w * (t / 2.0 - (2.0 * w * t).sin() / (4.0 * w));
        e.push(&[force], &[d], &[x], ed, 0.0);
    }
    assert_eq!(e.total_added(), 0.0);
    assert_eq!(e.eta(), 0.0);
    // One cycle of window (2 s): dissipation π (c + c_n) ω A².
    let expect = PI * (c + c_n) * w * a * a;
    assert!(((e.window_dissipated() - expect) / expect).abs() < 1e-5);
}

#[test]
fn identification_recovers_stiffness_damping_and_lag() {
    let (a, w, tau, k, c, dt) = (0.01, 2.0 * PI * 1.5, 0.004, 3.0e4, 120.0, 1e-3);
    let mut id = Identification::new(1, dt, 2000);
    for i in 0..6000 {
        let (force, d, x) = delayed_spring(i, dt, a, w, tau, k, c);
        id.push(&[force], &[d], &[x]);
    }
    let rel = |x: f64, r: f64| ((x - r) / r).abs();
    assert!(rel(id.stiffness()[0], k) < 1e-4, "k {}", id.stiffness()[0]);
    assert!(rel(id.damping()[0], c) < 2e-3, "c {}", id.damping()[0]);
    // The first-order lag fit of a sinusoid gives sin(ωτ)/ω (relative error (ωτ)²/6).
    assert!(rel(id.lag()[0], (w * tau).sin() / w) < 1e-3, "tau {}", id.lag()[0]);
    assert!(rel(id.lag()[0], tau) < 2e-3);
}

const SDOF_SPRING: &str = r#"
[structure.sdof]
mass = 1000.0
stiffness = 39478.4
damping = 251.3

[ground_motion]
generator = "harmonic"
amplitude = 0.5
frequency = 1.0
duration = 2.0

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
delay = 0.005
"#;

#[test]
fn model_view_equals_the_amplification_matrix_of_the_same_test_built_directly() {
    let def = TestDefinition::from_toml(SDOF_SPRING, "sdof_spring.toml", Path::new(".")).unwrap();
    let sub = def.substructure.as_ref().unwrap();
    let model = def.model.as_dense().unwrap();
    let view = ModelView::new(sub, model, 0.01).unwrap();
    for (k, c, tau) in [(2.0e4, 40.0, 0.005), (2.0e4, 40.0, 0.02), (5.0e3, 0.0, 0.0)] {
        let rho = view.spectral_radius(&[k], &[c], &[tau]).unwrap();
        // The same test by hand: controller, virtual lab with the spring behind a delay.
        let settings = SubstepSettings {
            dt: 0.01,
            beta: 0.25,
            gamma: 0.5,
            substeps: 4,
            coupling_dofs: vec![0],
            error_force: ErrorForceSpec::None,
        };
        let m = sdof(1000.0, 251.3, 39478.4).unwrap();
        let controller = SubstepController::new(&m, &settings, &nalgebra::DVector::zeros(1)).unwrap();
        let lab = VirtualLab::from_specs(
            &[0],
            &[SpecimenSpec::LinearSdof {
                dof: 0,
                mass: None,
                stiffness: k,
                damping: c,
            }],
            &[ActuatorSpec {
                dynamics: Dynamics::Ideal,
                delay: tau,
            }],
            &[SensorSpec::ideal()],
            &[SensorSpec::ideal()],
            0.01 / 4.0,
            1,
        )
        .unwrap();
        let mut test = SubstructureTest::new(&m, controller, Box::new(lab)).unwrap();
        let direct = StepMap::probe(&mut test).unwrap().spectral_radius();
        assert!((rho - direct).abs() < 1e-12, "k {k} c {c} tau {tau}: {rho} vs {direct}");
    }
    // A long delay on a stiff specimen is unstable, a short one stable (negative damping k τ
    // against c = 251 N s/m: τ_crit ≈ 12.6 ms here).
    assert!(view.spectral_radius(&[2.0e4], &[0.0], &[0.004]).unwrap() < 1.0);
    assert!(view.spectral_radius(&[2.0e4], &[0.0], &[0.03]).unwrap() > 1.0);
}

#[test]
fn model_view_without_specimen_is_newmark_of_the_sdof() {
    // k = c = 0 at the interface and no lag: the algorithm is average-acceleration Newmark of
    // the SDOF, whose eigenvalues have |λ|² = (1 + Ω²/4 − ζΩ)/(1 + Ω²/4 + ζΩ).
    let def = TestDefinition::from_toml(SDOF_SPRING, "sdof_spring.toml", Path::new(".")).unwrap();
    let view = ModelView::new(def.substructure.as_ref().unwrap(), def.model.as_dense().unwrap(), 0.01).unwrap();
    let rho = view.spectral_radius(&[0.0], &[0.0], &[0.0]).unwrap();
    let omega = (39478.4f64 / 1000.0).sqrt() * 0.01;
    let zeta = 251.3 / (2.0 * (39478.4f64 * 1000.0).sqrt());
    let q = 1.0 + omega * omega / 4.0;
    let exact = ((q - zeta * omega) / (q + zeta * omega)).sqrt();
    assert!((rho - exact).abs() < 1e-10, "{rho} vs {exact}");
}

#[test]
fn operator_stop_ramps_like_a_safety_limit() {
    let toml = format!("{SDOF_SPRING}\n[substructure.limits]\nramp_time = 0.05\n");
    let def = TestDefinition::from_toml(&toml, "sdof_spring.toml", Path::new(".")).unwrap();
    let mut sim = Simulation::new(&def).unwrap();
    for _ in 0..50 {
        sim.step(&mut ()).unwrap();
    }
    assert!(sim.request_stop("operator stop (monitor)"));
    let err = sim.step(&mut ()).unwrap_err();
    match err {
        substep::Error::Stopped { step, reason, .. } => {
            assert_eq!(step, 51);
            assert!(reason.starts_with("operator stop (monitor)"), "{reason}");
            assert!(reason.contains("ramped to 0 over 0.05 s"), "{reason}");
        }
        other => panic!("expected a stop, got {other}"),
    }
    // Without limits there is no ramp to use.
    let def = TestDefinition::from_toml(SDOF_SPRING, "sdof_spring.toml", Path::new(".")).unwrap();
    let mut sim = Simulation::new(&def).unwrap();
    assert!(!sim.request_stop("operator stop"));
}

#[test]
fn controls_record_the_first_stop_and_tokens_compare_exactly() {
    let c = Controls::default();
    assert_eq!(c.stop_requested(), None);
    c.request_stop(StopRequest::Stability);
    c.request_stop(StopRequest::Operator);
    assert_eq!(c.stop_requested(), Some(StopRequest::Stability));
    c.acknowledge();
    c.acknowledge();
    assert_eq!(c.acknowledgements(), 2);
    assert!(token_matches("abc123", "abc123"));
    assert!(!token_matches("abc124", "abc123"));
    assert!(!token_matches("abc12", "abc123"));
    assert!(!token_matches("", ""));
}

#[test]
fn frame_ring_drops_frames_when_full_and_keeps_order() {
    let (mut tx, mut rx) = frame_ring(8);
    for i in 0..20u64 {
        tx.push_or_drop(|f| f.step = i);
    }
    assert_eq!(tx.overflows(), 12);
    let got: Vec<u64> = std::iter::from_fn(|| rx.try_pop_with(|f| f.step)).collect();
    assert_eq!(got, (0..8).collect::<Vec<_>>());
    // Across threads: every frame that was not dropped arrives, in order.
    let (mut tx, mut rx) = frame_ring(64);
    let h = std::thread::spawn(move || {
        for i in 0..10_000u64 {
            tx.push_or_drop(|f| f.step = i);
        }
        tx.overflows()
    });
    let mut last = None;
    let mut n = 0u64;
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    while !h.is_finished() || rx.try_pop_with(|_| ()).is_some() {
        while let Some(s) = rx.try_pop_with(|f| f.step) {
            assert!(last.is_none_or(|l| s > l));
            last = Some(s);
            n += 1;
        }
        assert!(std::time::Instant::now() < deadline);
    }
    let dropped = h.join().unwrap();
    assert!(n + dropped >= 9_999 && n + dropped <= 10_000, "{n} + {dropped}");
}
