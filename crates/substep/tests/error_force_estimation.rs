//! Error-force compensation by estimation (docs/theory.md §4.4) on the typical TMD system (§9.3):
//! numerical primary SDOF (1000 kg, 1 Hz, 5 %), TMD specimen (5 %, tuned, 10 %) on an ideal
//! actuator, Δt = 0.01 s, k_sub = 4, 20 s sine sweep 0.2 → 3 Hz.

use substep::analysis::spectral::band_coherence;
use substep::model::{TmdSystem, sdof};
use substep::specimen::LinearSpecimen;
use substep::substructure::{ErrorForceSpec, EstimationStats, SubstepController, SubstepSettings, SubstructureTest};
use substep::transfer::{ActuatorSpec, AttachedSpecimen, SensorSpec, VirtualLab};

const DT: f64 = 0.01;
const K_SUB: usize = 4;
const DURATION: f64 = 20.0;
/// Statistics from here on (after the estimator's warm-up).
const FROM: f64 = 2.0;

fn sweep() -> Vec<f64> {
    let n = (DURATION / DT).round() as usize;
    (0..=n)
        .map(|i| {
            let t = i as f64 * DT;
            (2.0 * std::f64::consts::PI * (0.2 * t + 2.8 * t * t / (2.0 * DURATION))).sin()
        })
        .collect()
}

struct Outcome {
    /// RMS of the recorded error force e (= the compensation force, P = 1) [N].
    rms_e: f64,
    /// RMS of its ideal (noise-free) value e° [N].
    rms_ideal: f64,
    /// RMS(e − e°) / RMS(e°).
    nrms_diff: f64,
    /// Coherence of e and e° over 0.2–3 Hz (the sweep's band).
    coherence: f64,
    /// Peak |true coupling force| [N].
    peak_force: f64,
    stats: Option<EstimationStats>,
}

fn build(ef: ErrorForceSpec, force_noise: f64) -> SubstructureTest {
    let p = TmdSystem::typical();
    let (kp, cp) = p.primary();
    let (ms, ks, cs) = p.absorber();
    let model = sdof(p.mass, cp, kp).unwrap();
    let settings = SubstepSettings {
        dt: DT,
        beta: 0.25,
        gamma: 0.5,
        substeps: K_SUB,
        coupling_dofs: vec![0],
        error_force: ef,
    };
    let ctrl = SubstepController::new(&model, &settings, &model.effective_mass_vector().scale(0.0)).unwrap();
    let lab = VirtualLab::new(
        &[ActuatorSpec::ideal()],
        vec![AttachedSpecimen {
            specimen: Box::new(LinearSpecimen::sdof(Some(ms), ks, cs).unwrap()),
            coupling_index: vec![0],
        }],
        &[SensorSpec {
            noise_std: force_noise,
            seed: 5,
            ..SensorSpec::ideal()
        }],
        &[SensorSpec::ideal()],
        DT / K_SUB as f64,
        1,
    )
    .unwrap();
    SubstructureTest::new(&model, ctrl, Box::new(lab)).unwrap()
}

fn run(ef: ErrorForceSpec, force_noise: f64) -> Outcome {
    let ag = sweep();
    let mut test = build(ef, force_noise);
    let (mut e, mut ideal) = (Vec::new(), Vec::new());
    let mut peak: f64 = 0.0;
    for i in 0..ag.len() - 1 {
        test.step(ag[i], ag[i + 1], &mut ()).unwrap();
        let c = &test.controller;
        let (ei, ii) = (
            c.error_force()[0],
            c.ideal_error_force().expect("the lab reports true forces")[0],
        );
        assert!(ei.is_finite() && ii.is_finite());
        assert_eq!(c.compensation_force()[0], ei, "P = 1");
        peak = peak.max(test.site.true_force().unwrap()[0].abs());
        if (i + 1) as f64 * DT > FROM {
            e.push(ei);
            ideal.push(ii);
        }
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let diff: Vec<f64> = e.iter().zip(&ideal).map(|(a, b)| a - b).collect();
    Outcome {
        rms_e: rms(&e),
        rms_ideal: rms(&ideal),
        nrms_diff: rms(&diff) / rms(&ideal),
        coherence: band_coherence(&e, &ideal, DT, 256, 0.2, 3.0),
        peak_force: peak,
        stats: test.controller.estimation_stats(),
    }
}

fn arx(order: usize) -> ErrorForceSpec {
    ErrorForceSpec::Arx {
        order,
        lambda: 0.98,
        p0: 100.0,
    }
}

const PID_P1: ErrorForceSpec = ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 };
const ORDERS: [usize; 6] = [2, 3, 4, 5, 8, 12];

#[test]
fn estimation_converges_noise_free_and_beats_pid_by_far() {
    let pid = run(PID_P1, 0.0);
    println!("PID P = 1: RMS error force {:.3e} N", pid.rms_e);
    for n in ORDERS {
        let a = run(arx(n), 0.0);
        let s = a.stats.unwrap();
        println!(
            "n_u = {n:2}: RMS error force {:.3e} N ({:.0}x smaller), estimated steps {}/{}",
            a.rms_e,
            pid.rms_e / a.rms_e,
            s.estimated,
            s.steps
        );
        // Noise-free the ideal value is the recorded one.
        assert!(a.nrms_diff < 1e-6, "n_u = {n}: {}", a.nrms_diff);
        assert!(s.estimated as f64 > 0.9 * s.steps as f64, "n_u = {n}: {s:?}");
        let factor = if n == 2 { 20.0 } else { 300.0 };
        assert!(
            pid.rms_e > factor * a.rms_e,
            "n_u = {n}: {} vs PID {}",
            a.rms_e,
            pid.rms_e
        );
    }
}

#[test]
fn with_one_percent_force_noise_the_estimation_beats_pid_and_follows_its_ideal() {
    let reference = run(PID_P1, 0.0);
    let sigma = 0.01 * reference.peak_force;
    let pid = run(PID_P1, sigma);
    println!(
        "force noise σ = {sigma:.2} N; PID P = 1: RMS e {:.3} N, ideal {:.3} N, RMS(e − e°) {:.2} σ, coherence {:.2}",
        pid.rms_e,
        pid.rms_ideal,
        pid.nrms_diff * pid.rms_ideal / sigma,
        pid.coherence
    );
    for n in ORDERS {
        let a = run(arx(n), sigma);
        let s = a.stats.unwrap();
        println!(
            "n_u = {n:2}: RMS e {:.3} N ({:.0} % of PID), ideal {:.3} N, RMS(e − e°) {:.2} σ, coherence {:.2}, estimated {}/{}",
            a.rms_e,
            100.0 * a.rms_e / pid.rms_e,
            a.rms_ideal,
            a.nrms_diff * a.rms_ideal / sigma,
            a.coherence,
            s.estimated,
            s.steps
        );
        assert!(
            a.rms_e < 0.85 * pid.rms_e,
            "n_u = {n}: {} vs PID {}",
            a.rms_e,
            pid.rms_e
        );
        assert!(a.rms_ideal < pid.rms_ideal, "n_u = {n}");
        // e − e° is the sensor noise of the last sample plus what the predictor passes on: at most
        // 15 % above σ (PID: f^(k) − f^(k−1) carries two samples' noise, √2 σ).
        assert!(a.nrms_diff * a.rms_ideal < 1.15 * sigma, "n_u = {n}");
        // The band coherence of e and e° is reported, not asserted: both are small and, for the
        // estimation, e° (the prediction error of a model fitted to noisy data) is broadband too;
        // it comes out at 0.2–0.4 against PID's 0.5.
        assert!(s.estimated as f64 > 0.8 * s.steps as f64, "n_u = {n}: {s:?}");
    }
}

#[test]
fn order_and_forgetting_factor_are_validated_naming_the_key() {
    for (spec, key) in [
        (arx(1), "substructure.error_force.order"),
        (arx(13), "substructure.error_force.order"),
        (
            ErrorForceSpec::Arx {
                order: 4,
                lambda: 0.0,
                p0: 100.0,
            },
            "substructure.error_force.forgetting_factor",
        ),
        (
            ErrorForceSpec::Arx {
                order: 4,
                lambda: 1.01,
                p0: 100.0,
            },
            "substructure.error_force.forgetting_factor",
        ),
        (
            ErrorForceSpec::Arx {
                order: 4,
                lambda: 0.98,
                p0: f64::NAN,
            },
            "substructure.error_force.p0",
        ),
    ] {
        let msg = spec.validate().unwrap_err().to_string();
        assert!(msg.contains(key), "{msg}");
    }
}

#[test]
fn a_diverging_specimen_never_produces_nan_and_the_guards_count() {
    // A destabilising case (undamped TMD, large time step, k_sub = 1) plus huge noise: the
    // estimation must fall back rather than produce non-finite commands.
    let mut test = build(arx(4), 50.0);
    let ag = sweep();
    for i in 0..600 {
        if test.step(ag[i], ag[i + 1], &mut ()).is_err() {
            break;
        }
        assert!(test.controller.command().iter().all(|v| v.is_finite()));
    }
    let s = test.controller.estimation_stats().unwrap();
    assert_eq!(s.steps, s.estimated + s.fallbacks());
    assert!(s.fallbacks() > 0);
}

#[test]
fn the_linear_analysis_refuses_the_estimation() {
    let mut test = build(arx(4), 0.0);
    let err = substep::analysis::StepMap::probe(&mut test).unwrap_err().to_string();
    assert!(err.contains("error_force.kind = \"arx\""), "{err}");
}

#[test]
fn two_coupling_dofs_get_one_model_each_and_stay_finite() {
    // examples/two_specimens.toml (3-storey frame, damper brace + TMD on two coupling DOFs,
    // actuator dynamics, noisy quantised sensors) with the estimation instead of PID.
    let text = include_str!("../../../examples/two_specimens.toml")
        .replace("kind = \"pid\"\np = 1.0", "kind = \"arx\"\norder = 3");
    assert!(text.contains("kind = \"arx\""));
    let dir = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples"));
    let def = substep::io::TestDefinition::from_toml(&text, "two_specimens.toml", dir).unwrap();
    let mut sim = substep::run::Simulation::new(&def).unwrap();
    while sim.steps_done() < sim.steps_total() {
        sim.step(&mut ()).unwrap();
        let test = sim.substructure_test().unwrap();
        assert!(test.controller.command().iter().all(|v| v.is_finite()));
        assert_eq!(test.controller.ideal_error_force().unwrap().len(), 2);
    }
    let test = sim.substructure_test().unwrap();
    let s = test.controller.estimation_stats().unwrap();
    println!("{s:?}");
    assert_eq!(s.steps as usize, sim.steps_total());
    assert!(s.estimated > s.steps / 2, "{s:?}");
    assert_eq!(test.controller.estimation_parameters(1).unwrap().len(), 3 + 4 + 4);
}
