//! The RTHS benchmark (Silva et al. 2020) and its building blocks against independent
//! references: the published table, the loop's own error, the generator's shipped draws, the
//! published difference equations and the plant's closed form.

use nalgebra::{DMatrix, DVector};
use substep::analysis::metrics::{nrms_error, peak_error, round_delay_ms, round_percent, tracking_delay};
use substep::benchmark::rths::*;
use substep::transfer::converter::Converter;
use substep::transfer::discrete::DiscreteFilter;
use substep::transfer::lti::{StateSpace, TransferFunction};
use substep::transfer::noise::{MinStdPolar, NoiseLevel};
use substep::transfer::servo::{Derivative, ServoActuator, ServoParams};

fn nominal(case: u8, kind: ControllerKind) -> RthsResult {
    run(&RthsInput::nominal(
        Case::new(case).unwrap(),
        ControllerSpec::preset(kind),
    ))
    .unwrap()
}

#[test]
fn sample_controller_reproduces_the_published_table() {
    for case in 1..=4u8 {
        let r = nominal(case, ControllerKind::Sample);
        assert!(r.stable && !r.capacity_exceeded, "case {case}");
        let j = r.criteria.unwrap().j;
        for (i, (got, want)) in j.iter().zip(PUBLISHED_SAMPLE[case as usize - 1]).enumerate() {
            assert!(
                (got - want).abs() <= 0.1 + 1e-9,
                "case {case} J{}: {got} vs published {want}",
                i + 1
            );
        }
    }
}

#[test]
fn ideal_transfer_gives_the_loops_own_error() {
    let mut input = RthsInput::nominal(Case::new(1).unwrap(), ControllerSpec::preset(ControllerKind::None));
    input.transfer = Transfer::Ideal;
    input.noise = false;
    let j = run(&input).unwrap().criteria.unwrap().j;
    let want = [1.76, 0.94, 1.77, 1.77, 0.94, 0.94];
    for (i, w) in want.iter().enumerate() {
        assert!((j[3 + i] - w).abs() <= 0.01 + 1e-9, "J{}: {} vs {w}", 4 + i, j[3 + i]);
    }
    assert_eq!(j[0], 0.0);
    assert_eq!(j[1], 0.0);
}

#[test]
fn uncompensated_loop_is_unstable() {
    let r = nominal(1, ControllerKind::None);
    assert!(!r.stable);
    assert!(r.criteria.is_none());
    assert!(r.diverged_at.unwrap() < 41.0);
}

#[test]
fn arx_phase_lag_beats_the_sample_controller_and_is_robust() {
    for case in 1..=4u8 {
        let sample = nominal(case, ControllerKind::Sample).criteria.unwrap().j;
        let arx = nominal(case, ControllerKind::Arx);
        assert!(arx.stable && !arx.capacity_exceeded, "case {case}");
        let j = arx.criteria.unwrap().j;
        assert!(j[1] < sample[1], "case {case}: J2 {} vs sample {}", j[1], sample[1]);
        assert!(j[3] < sample[3], "case {case}: J4 {} vs sample {}", j[3], sample[3]);
        let input = RthsInput::nominal(Case::new(case).unwrap(), ControllerSpec::preset(ControllerKind::Arx));
        let runs = run_perturbed(&input, 20, 1).unwrap();
        assert_eq!(runs.len(), 20);
        for (i, (p, r)) in runs.iter().enumerate() {
            assert!(
                r.stable && !r.capacity_exceeded,
                "case {case} perturbed run {i} ({p:?}): max F {}",
                r.max_force
            );
        }
    }
}

/// Issue "Stable by construction": without sensor noise the ARX compensator is at least as good
/// as with it (J2 and J4, every case, El Centro) — it no longer leans on the noise for
/// excitation — and both beat the sample controller on J2 and J4.
#[test]
fn arx_without_noise_is_at_least_as_good_as_with_noise() {
    for case in 1..=4u8 {
        let sample = nominal(case, ControllerKind::Sample).criteria.unwrap().j;
        let noisy = nominal(case, ControllerKind::Arx).criteria.unwrap().j;
        let mut input = RthsInput::nominal(Case::new(case).unwrap(), ControllerSpec::preset(ControllerKind::Arx));
        input.noise = false;
        let clean = run(&input).unwrap();
        assert!(clean.stable && !clean.capacity_exceeded, "case {case}");
        let clean = clean.criteria.unwrap().j;
        println!(
            "case {case}: J2 {:.2} noise-free / {:.2} noisy / {:.2} sample, J4 {:.2} / {:.2} / {:.2}",
            clean[1], noisy[1], sample[1], clean[3], noisy[3], sample[3]
        );
        for i in [1, 3] {
            assert!(
                clean[i] <= noisy[i],
                "case {case} J{}: noise-free {} vs noisy {}",
                i + 1,
                clean[i],
                noisy[i]
            );
            assert!(clean[i] < sample[i] && noisy[i] < sample[i], "case {case} J{}", i + 1);
        }
    }
}

/// Issue 28: ATS (the field's reference compensator) on the benchmark, with and without sensor
/// noise: stable and under capacity in every case and far better than the sample controller.
/// Against the thesis method (ARX), measured and documented in docs/benchmark.md: ARX is better
/// on J4 (the test against the true structure) in every case; ATS tracks its target better (J2)
/// in every case — by 0.13–0.17 points with noise, by about 0.5 without.
#[test]
fn ats_is_stable_and_arx_is_at_least_as_good() {
    for noise in [true, false] {
        for case in 1..=4u8 {
            let result = |kind| {
                let mut input = RthsInput::nominal(Case::new(case).unwrap(), ControllerSpec::preset(kind));
                input.noise = noise;
                run(&input).unwrap()
            };
            let ats = result(ControllerKind::Ats);
            assert!(
                ats.stable && !ats.capacity_exceeded && ats.guard_trip.is_none(),
                "case {case}: {:?}",
                ats.warnings()
            );
            let ats = ats.criteria.unwrap().j;
            let arx = result(ControllerKind::Arx).criteria.unwrap().j;
            let sample = nominal(case, ControllerKind::Sample).criteria.unwrap().j;
            println!(
                "noise {noise}, case {case}: J2 ARX {:.2} / ATS {:.2} / sample {:.2}, J4 {:.2} / {:.2} / {:.2}",
                arx[1], ats[1], sample[1], arx[3], ats[3], sample[3]
            );
            assert!(
                arx[3] <= ats[3],
                "noise {noise}, case {case} J4: ARX {} vs ATS {}",
                arx[3],
                ats[3]
            );
            assert!(
                ats[1] <= arx[1],
                "noise {noise}, case {case} J2: ATS {} vs ARX {}",
                ats[1],
                arx[1]
            );
            for i in [1, 3] {
                assert!(ats[i] < sample[i] / 1.5, "noise {noise}, case {case} J{}", i + 1);
            }
        }
    }
}

/// Issue 28: adaptive model-based compensation (AMB) on the benchmark: stable and under
/// capacity in every case with and without sensor noise, far better than the sample controller;
/// and its adaptation earns its keep on plants that differ from the model — over 20 perturbed
/// plants per case the worst J2 is lower than with the same feed-forward frozen at the nominal
/// model (`deviation = 0`; measured with noise: 1.72–2.71 % against 3.99–4.81 %), while on the
/// nominal plant, where the model is exact, the frozen model has the lower J4 (docs/benchmark.md).
#[test]
fn amb_is_stable_and_its_adaptation_helps_on_perturbed_plants() {
    for noise in [true, false] {
        for case in 1..=4u8 {
            let mut input = RthsInput::nominal(Case::new(case).unwrap(), ControllerSpec::preset(ControllerKind::Amb));
            input.noise = noise;
            let amb = run(&input).unwrap();
            assert!(
                amb.stable && !amb.capacity_exceeded && amb.guard_trip.is_none(),
                "noise {noise}, case {case}: {:?}",
                amb.warnings()
            );
            let j = amb.criteria.unwrap().j;
            let sample = nominal(case, ControllerKind::Sample).criteria.unwrap().j;
            for i in [1, 3] {
                assert!(j[i] < sample[i] / 1.5, "noise {noise}, case {case} J{}", i + 1);
            }
        }
    }
    let worst_j2 = |deviation: f64, case: u8| {
        let mut spec = ControllerSpec::preset(ControllerKind::Amb);
        if let Some(substep::compensate::PhaseLagSpec::Amb(a)) = &mut spec.phase_lag {
            a.deviation = deviation;
        }
        let input = RthsInput::nominal(Case::new(case).unwrap(), spec);
        let runs = run_perturbed(&input, 20, 1).unwrap();
        assert!(runs.iter().all(|(_, r)| r.stable && !r.capacity_exceeded));
        runs.iter()
            .map(|(_, r)| r.criteria.as_ref().unwrap().j[1])
            .fold(0.0, f64::max)
    };
    let (mut adapted_max, mut frozen_max) = (0.0f64, 0.0f64);
    for case in 1..=4u8 {
        let (adapted, frozen) = (worst_j2(0.5, case), worst_j2(0.0, case));
        println!("case {case}: worst perturbed J2 adapted {adapted:.2} / frozen model {frozen:.2}");
        assert!(adapted <= frozen, "case {case}: adapted {adapted} vs frozen {frozen}");
        adapted_max = adapted_max.max(adapted);
        frozen_max = frozen_max.max(frozen);
    }
    assert!(adapted_max < 0.7 * frozen_max, "{adapted_max} vs {frozen_max}");
}

#[test]
fn perturbed_plants_are_seeded_and_spread_as_specified() {
    let nominal = ServoParams::benchmark();
    assert_eq!(perturbed_plant(&nominal, 7, 3), perturbed_plant(&nominal, 7, 3));
    assert_ne!(perturbed_plant(&nominal, 7, 3), perturbed_plant(&nominal, 8, 3));
    let draws: Vec<ServoParams> = (0..4000).map(|i| perturbed_plant(&nominal, 1, i)).collect();
    let stats = |f: &dyn Fn(&ServoParams) -> f64| {
        let v: Vec<f64> = draws.iter().map(f).collect();
        let m = v.iter().sum::<f64>() / v.len() as f64;
        (
            m,
            (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64).sqrt(),
        )
    };
    for (f, mean, sigma) in [
        (&(|p: &ServoParams| p.k_e) as &dyn Fn(&ServoParams) -> f64, 1.19e6, 5e4),
        (&|p: &ServoParams| p.beta1, 425.0, 3.3),
        (&|p: &ServoParams| p.beta2, 9.9976e4, 3.3e3),
        (&|p: &ServoParams| p.a3, 3.3, 1.3),
    ] {
        let (m, s) = stats(f);
        // 4000 draws: the mean is within 4 σ/√n, the std within 5 %.
        assert!((m - mean).abs() < 4.0 * sigma / 4000f64.sqrt(), "mean {m} vs {mean}");
        assert!((s / sigma - 1.0).abs() < 0.05, "std {s} vs {sigma}");
    }
}

#[test]
fn substep_algorithm_runs_all_four_cases() {
    for case in 1..=4u8 {
        let mut input = RthsInput::nominal(Case::new(case).unwrap(), ControllerSpec::preset(ControllerKind::Sample));
        input.algorithm = Algorithm::Substep(SubstepSpec::default());
        let r = run(&input).unwrap();
        assert!(r.stable, "case {case}");
        let j = r.criteria.unwrap().j;
        assert!(j.iter().all(|v| v.is_finite()));
        // Same plant and controller: the tracking is that of the sample controller.
        assert!(j[1] > 5.0 && j[1] < 20.0, "case {case}: J2 {}", j[1]);
        assert!(j[3] < 100.0, "case {case}: J4 {}", j[3]);
    }
}

/// J of the sub-step algorithm with ideal transfer and no noise: its own error against the
/// exact reference.
fn substep_ideal(dt: f64, k_sub: usize, error_force: substep::substructure::ErrorForceSpec) -> [f64; 9] {
    let mut input = RthsInput::nominal(Case::new(1).unwrap(), ControllerSpec::preset(ControllerKind::None));
    input.transfer = Transfer::Ideal;
    input.noise = false;
    input.algorithm = Algorithm::Substep(SubstepSpec {
        dt,
        k_sub,
        error_force,
        ..SubstepSpec::default()
    });
    run(&input).unwrap().criteria.unwrap().raw
}

#[test]
fn substep_with_ideal_transfer_approaches_the_exact_reference() {
    use substep::substructure::ErrorForceSpec;
    // Δt = h with P = 1 error-force compensation: within 0.05 % of the exact solution (the
    // benchmark's own loop: 1.76 %).
    let j = substep_ideal(1.0 / 4096.0, 1, ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 });
    for (i, ji) in j.iter().enumerate().skip(3) {
        assert!(*ji < 0.05, "J{}: {ji}", i + 1);
    }
    // Without compensation at Δt = 4h the error falls as k_sub grows to one sub-step per sample.
    let j6: Vec<f64> = [1, 2, 4]
        .iter()
        .map(|&k| substep_ideal(1.0 / 1024.0, k, ErrorForceSpec::None)[5])
        .collect();
    assert!(j6[0] > j6[1] && j6[1] > j6[2], "{j6:?}");
}

#[test]
fn substep_dt_must_be_whole_samples() {
    let spec = SubstepSpec {
        dt: 0.001,
        ..SubstepSpec::default()
    };
    let e = spec.samples_per_step().unwrap_err().to_string();
    assert!(e.contains("substep.dt"), "{e}");
}

#[test]
fn noise_generator_reproduces_the_shipped_draws() {
    let text = include_str!("data/rths_noise_first1000.csv");
    let want: Vec<f64> = text.lines().skip(1).map(|l| l.trim().parse().unwrap()).collect();
    assert_eq!(want.len(), 1000);
    let mut g = MinStdPolar::benchmark();
    for (k, w) in want.iter().enumerate() {
        let got = g.normal();
        assert!((got - w).abs() <= 1e-15 * w.abs().max(1.0), "draw {k}: {got} vs {w}");
    }
    assert!(MinStdPolar::new(0).is_err());
}

#[test]
fn noise_power_gives_sigma() {
    let h = 1.0 / 4096.0;
    let sx = NoiseLevel::Power {
        p: 6.25e-14,
        sample_time: h,
    }
    .sigma("x")
    .unwrap();
    let sf = NoiseLevel::Power {
        p: 1.16e-3,
        sample_time: h,
    }
    .sigma("f")
    .unwrap();
    assert!((sx - 1.6e-5).abs() < 1e-18);
    assert!((sf - 2.179761).abs() < 1e-6);
    assert!(NoiseLevel::Sigma(-1.0).sigma("x").is_err());
}

#[test]
fn converters_saturate_quantise_and_round_half_away_from_zero() {
    let c = Converter::benchmark();
    let q = 1.0 / 262_144.0;
    assert_eq!(c.quantise(2.5 * q), 3.0 * q);
    assert_eq!(c.quantise(-2.5 * q), -3.0 * q);
    assert_eq!(c.quantise(2.4999 * q), 2.0 * q);
    // A/D saturates first: 3.8 is not a multiple of q, so the result is the step nearest 3.8.
    let nearest = q * (3.8f64 / q).round();
    assert_eq!(c.ad(5.0), nearest);
    // D/A saturates last: exactly the range.
    assert_eq!(c.da(5.0), 3.8);
    assert_eq!(c.da(-5.0), -3.8);
    assert!(nearest != 3.8);
    let c2 = Converter::new(1.0, 0.5).unwrap();
    assert_eq!(c2.ad(0.25), 0.5);
    assert_eq!(c2.ad(-0.75), -1.0);
    assert!(Converter::new(0.0, 0.1).is_err());
}

#[test]
fn tustin_reproduces_the_published_difference_equations() {
    let h = 1.0 / 4096.0;
    let gc = DiscreteFilter::tustin("gc", &sample_feedback(), h).unwrap();
    // u_k = u_{k−1} + 2.011596679688 e_k − 1.988403320312 e_{k−1}
    assert!((gc.a()[1] + 1.0).abs() < 1e-12);
    assert!((gc.b()[0] - 2.011596679688).abs() < 1e-11);
    assert!((gc.b()[1] + 1.988403320312).abs() < 1e-11);
    let gt = DiscreteFilter::tustin("gt", &sample_feedforward(), h).unwrap();
    // y_k = −0.022574177892 y_{k−1} + 25.353362720559 x_k − 24.330788542666 x_{k−1}
    assert!((gt.a()[1] - 0.022574177892).abs() < 1e-11);
    assert!((gt.b()[0] - 25.353362720559).abs() < 1e-11);
    assert!((gt.b()[1] + 24.330788542666).abs() < 1e-11);
    // The recursion itself: a unit step through G_C.
    let mut f = gc.clone();
    let (y0, y1) = (f.step(1.0), f.step(1.0));
    assert!((y0 - 2.011596679688).abs() < 1e-11);
    assert!((y1 - (y0 + 2.011596679688 - 1.988403320312)).abs() < 1e-11);
}

#[test]
fn tustin_refuses_unstable_and_bad_controllers() {
    let h = 1.0 / 4096.0;
    let unstable = TransferFunction::new("controller.feedback", &[1.0], &[1.0, -10.0]).unwrap();
    let e = DiscreteFilter::tustin("controller.feedback", &unstable, h)
        .unwrap_err()
        .to_string();
    assert!(e.contains("controller.feedback") && e.contains("unstable"), "{e}");
    let e = TransferFunction::new("controller.feedback", &[1.0], &[0.0, 0.0])
        .unwrap_err()
        .to_string();
    assert!(e.contains("controller.feedback.den"), "{e}");
    let e = TransferFunction::new("tf", &[1.0, 0.0, 0.0], &[1.0, 1.0])
        .unwrap_err()
        .to_string();
    assert!(e.contains("improper"), "{e}");
    assert!(TransferFunction::new("tf", &[f64::NAN], &[1.0, 1.0]).is_err());
    assert!(TransferFunction::new("tf", &[1.0], &[]).is_err());
}

#[test]
fn plant_closed_form_matches_the_spec() {
    let tf = ServoParams::benchmark().closed_form().unwrap();
    let num = 2.18384863e13;
    let den = [
        29.13,
        1.2590599867e4,
        8.4217765024e6,
        2.3284896331e9,
        5.4354658604e11,
        2.1675605752e13,
    ];
    assert!((tf.num()[0] / num - 1.0).abs() < 1e-8);
    for (a, b) in tf.den().iter().zip(den) {
        assert!((a / b - 1.0).abs() < 1e-9, "{a} vs {b}");
    }
    assert!((tf.dc_gain() - 1.0075).abs() < 5e-5);
    for (f, gain, delay_ms) in [(1.0, 0.999, 24.96), (3.61, 0.915, 23.73), (10.0, 0.633, 19.01)] {
        let (g, d) = tf.gain_and_delay(f);
        assert!((g - gain).abs() < 5e-4, "{f} Hz: gain {g}");
        assert!((d * 1e3 - delay_ms).abs() < 5e-3, "{f} Hz: delay {} ms", d * 1e3);
    }
}

/// Gain and phase delay of `x` against `sin(ωt)` by projection over whole periods.
fn measured_response(f: f64, derivative: Derivative) -> (f64, f64) {
    let h = 1.0 / 4096.0;
    let mut plant = ServoActuator::new(ServoParams::benchmark(), derivative, h).unwrap();
    let w = 2.0 * std::f64::consts::PI * f;
    let settle = (2.0 / h) as usize; // slowest pole −48 s⁻¹: 2 s is e⁻⁹⁶
    let periods = (4.0 * f).round().max(4.0);
    let span = (periods / f / h).round() as usize;
    let (mut s, mut c) = (0.0, 0.0);
    for k in 0..settle + span {
        let t = k as f64 * h;
        if k >= settle {
            let x = plant.displacement();
            s += x * (w * t).sin();
            c += x * (w * t).cos();
        }
        // u held over [t_k, t_k+1]: the mid-interval value keeps the hold's half-step lag out.
        plant.step((w * (t + 0.5 * h)).sin());
    }
    let (s, c) = (2.0 * s / span as f64, 2.0 * c / span as f64);
    let phase = c.atan2(s);
    ((s * s + c * c).sqrt(), -phase / w)
}

#[test]
fn block_model_follows_the_closed_form() {
    let tf = ServoParams::benchmark().closed_form().unwrap();
    for f in [1.0, 3.61, 10.0] {
        let (g0, d0) = tf.gain_and_delay(f);
        let (g, d) = measured_response(f, Derivative::Exact);
        assert!((g / g0 - 1.0).abs() < 2e-3, "{f} Hz: gain {g} vs {g0}");
        assert!((d - d0).abs() < 2e-5, "{f} Hz: delay {d} vs {d0}");
        // The finite-difference derivative block is close but not equal.
        let (gf, df) = measured_response(f, Derivative::FiniteDifference);
        assert!(
            (gf / g0 - 1.0).abs() < 2e-2 && (df - d0).abs() < 5e-4,
            "{f} Hz FD: {gf} {df}"
        );
    }
}

#[test]
fn lti_integrators_match_the_closed_form() {
    // G(s) = 2/(s + 5): unit step response 0.4 (1 − e^{−5t}).
    let tf = TransferFunction::new("g", &[2.0], &[1.0, 5.0]).unwrap();
    let ss = tf.to_state_space();
    let h = 0.01;
    let (mut rk, mut zoh) = (ss.rk4(h).unwrap(), ss.zoh(h).unwrap());
    // RK4 on ẋ = −5x + 2u with u held: x_{k+1} − x* = R(−5h)(x_k − x*), R(z) = Σ_{i≤4} z^i/i!.
    let z: f64 = -5.0 * h;
    let r = 1.0 + z + z * z / 2.0 + z.powi(3) / 6.0 + z.powi(4) / 24.0;
    for k in 0..200 {
        let want = 0.4 * (1.0 - (-5.0 * k as f64 * h).exp());
        let want_rk = 0.4 * (1.0 - r.powi(k));
        let (a, b) = (rk.step(1.0), zoh.step(1.0));
        assert!((b - want).abs() < 1e-14, "zoh {k}");
        assert!((a - want_rk).abs() < 1e-14, "rk4 {k}");
        assert!((a - want).abs() < 1e-8, "rk4 vs exact {k}");
    }
    // A biproper TF: the feedthrough D, and the second-order realisation against its ZOH.
    let tf2 = TransferFunction::new("g", &[1.0, 3.0, 0.0], &[1.0, 2.0, 10.0]).unwrap();
    let ss2 = tf2.to_state_space();
    assert_eq!(ss2.d, 1.0);
    let z = ss2.zoh(1e-3).unwrap();
    let mut rk2 = ss2.rk4(1e-3).unwrap();
    let mut z2 = z.clone();
    for k in 0..3000 {
        let u = (k as f64 * 1e-3 * 7.0).sin();
        assert!((rk2.step(u) - z2.step(u)).abs() < 1e-9);
    }
    // DC gain of the realisation equals the TF's.
    let a = ss2.a.clone();
    let x = a.lu().solve(&(-&ss2.b)).unwrap();
    assert!((ss2.c.dot(&x) + ss2.d - tf2.dc_gain()).abs() < 1e-12);
    assert!(StateSpace::new("ss", DMatrix::zeros(2, 2), DVector::zeros(3), DVector::zeros(2), 0.0).is_err());
}

#[test]
fn metrics_against_closed_forms() {
    let h = 1e-3;
    let r: Vec<f64> = (0..4000)
        .map(|k| (k as f64 * h * 2.0 * std::f64::consts::PI).sin())
        .collect();
    // x lags r by 7 samples.
    let x: Vec<f64> = (0..4000).map(|k| if k >= 7 { r[k - 7] } else { 0.0 }).collect();
    assert!((tracking_delay(&r, &x, h, 49).unwrap() - 0.007).abs() < 1e-12);
    // x = 1.1 r: NRMS = peak = 0.1.
    let y: Vec<f64> = r.iter().map(|v| 1.1 * v).collect();
    assert!((nrms_error(&y, &r).unwrap() - 0.1).abs() < 1e-12);
    assert!((peak_error(&y, &r).unwrap() - 0.1).abs() < 1e-12);
    assert!(nrms_error(&y, &r[..10]).is_err());
    assert!(nrms_error(&[1.0, 1.0], &[0.0, 0.0]).is_err());
    assert_eq!(round_percent(0.123449), 12.34);
    assert_eq!(round_percent(0.00125), 0.13);
    assert_eq!(round_delay_ms(0.00463867), 4.6);
    assert_eq!(round_delay_ms(0.00125), 1.3);
}

#[test]
fn record_parsing_errors_name_the_line() {
    let e = GroundRecord::parse_csv("r.csv", "t,a_g\n0,0\n0.1,1,2\n")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("r.csv: line 3") && e.contains("2 columns"), "{e}");
    let e = GroundRecord::parse_csv("r.csv", "0,0\n0.1\n").unwrap_err().to_string();
    assert!(e.contains("line 2"), "{e}");
    let e = GroundRecord::parse_csv("r.csv", "0,0\n0,1\n").unwrap_err().to_string();
    assert!(e.contains("does not increase"), "{e}");
    let e = GroundRecord::parse_csv("r.csv", "t,a\n").unwrap_err().to_string();
    assert!(e.contains("at least 2"), "{e}");
    let ok = GroundRecord::parse_csv("r.csv", "# c\n0,0\n0.5,1\n1.0,0\n").unwrap();
    let mut v = Vec::new();
    ok.sample_sorted([0.25, 0.5, 0.75, 2.0].into_iter(), 2.0, &mut v);
    assert_eq!(v, vec![1.0, 2.0, 1.0, 0.0]);
    let el = GroundRecord::elcentro();
    assert!((el.duration() - 41.18).abs() < 1e-12);
    assert!((el.peak() - 3.135).abs() < 1e-3);
    assert_eq!(
        RthsInput::nominal(Case::new(1).unwrap(), ControllerSpec::preset(ControllerKind::Sample)).samples(),
        168_674
    );
}

#[test]
fn reruns_are_bit_identical() {
    let a = nominal(2, ControllerKind::Arx).criteria.unwrap().raw;
    let b = nominal(2, ControllerKind::Arx).criteria.unwrap().raw;
    assert_eq!(a, b);
}

#[test]
fn config_parses_and_refuses_unknown_keys() {
    let c = BenchmarkConfig::parse("[controller]\nkind = \"arx\"\n[controller.arx]\nk_lag = 16\n", "c.toml").unwrap();
    assert_eq!(c.kind().unwrap(), Some(ControllerKind::Arx));
    let e = BenchmarkConfig::parse("[controller]\nbogus = 1\n", "c.toml")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("c.toml: line 2") && e.contains("bogus"), "{e}");
    let e = BenchmarkConfig::parse("[controller]\nfeedback = { num = [1.0], den = [0.0] }\n", "c.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("controller.feedback.den"), "{e}");
    let e = BenchmarkConfig::parse(
        "[controller]\nfeedback = { num = [1.0], den = [1.0, -5.0] }\n",
        "c.toml",
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("unstable"), "{e}");
    let e = BenchmarkConfig::parse("[substep]\ndt = 0.001\n", "c.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("substep.dt"), "{e}");
}

#[test]
fn shared_noise_drives_channels_with_one_sequence() {
    use substep::transfer::noise::SharedNoise;
    let mut shared = SharedNoise::new(MinStdPolar::benchmark(), vec![1.6e-5, 2.179761]);
    let mut single = MinStdPolar::benchmark();
    let mut out = [0.0; 2];
    for _ in 0..100 {
        shared.sample(&mut out);
        let n = single.normal();
        assert_eq!(out, [1.6e-5 * n, 2.179761 * n]);
    }
}
