//! Engineering outputs against closed forms: the energy balance of average-acceleration
//! Newmark (exact by construction of the discrete energy identity, so the residual is round-off,
//! and the free vibration after a pulse keeps `E_K + E_S` constant), storey shears against the
//! storey springs and the equilibrium of the floor masses, and the response spectrum of a
//! harmonic record against the closed-form SDOF solution from rest.

mod common;

use common::{ground_loads, simulate, sine_sweep};
use nalgebra::DMatrix;
use std::f64::consts::PI;
use substep::analysis::energy::EnergyBalance;
use substep::analysis::storey::{StoreyResponse, is_shear_chain};
use substep::excitation::spectrum::{log_periods, response_spectrum, sdof_peak};
use substep::integrate::Scheme;
use substep::model::{DampingSpec, ShearBuilding, StructuralModel, sdof, shear_building};

fn building(stories: usize) -> (ShearBuilding, StructuralModel) {
    let b = ShearBuilding {
        stories,
        story_mass: 2.0e4,
        first_period: 0.5,
    };
    (b, shear_building(&b).expect("valid building"))
}

fn balance(model: &StructuralModel, scheme: Scheme, dt: f64, ag: &[f64]) -> (EnergyBalance, Vec<f64>) {
    let loads = ground_loads(model, ag);
    let states = simulate(scheme, model, dt, &loads);
    let mut e = EnergyBalance::new(model);
    let zeros = vec![0.0; model.n_dofs()];
    let mut mech = Vec::new();
    for (s, &a) in states.iter().zip(ag) {
        e.push(s.u.as_slice(), s.v.as_slice(), a, &zeros).unwrap();
        mech.push(e.terms().kinetic + e.terms().strain);
    }
    (e, mech)
}

#[test]
fn average_acceleration_conserves_energy_in_free_vibration() {
    let (_, model) = building(3);
    let dt = 0.005;
    // A 0.2 s half-sine pulse, then 2 s of free vibration (no damping).
    let ag: Vec<f64> = (0..=440)
        .map(|i| {
            let t = i as f64 * dt;
            if t < 0.2 { 2.0 * (PI * t / 0.2).sin() } else { 0.0 }
        })
        .collect();
    let aa = Scheme::Newmark { beta: 0.25, gamma: 0.5 };
    let (e, mech) = balance(&model, aa, dt, &ag);
    let after = &mech[41..];
    let e0 = after[0];
    assert!(e0 > 1.0, "the pulse puts energy in: {e0} J");
    let drift = after.iter().map(|&x| (x - e0).abs()).fold(0.0, f64::max) / e0;
    assert!(drift < 1e-12, "free vibration energy drifts by {drift:e}");
    assert!(
        e.max_relative_error() < 1e-12,
        "balance error {:e}",
        e.max_relative_error()
    );
    // Input energy equals what is left in the system (no damping, no coupling).
    let t = e.terms();
    assert!((t.input - (t.kinetic + t.strain)).abs() < 1e-10 * t.input, "{t:?}");
    assert_eq!(t.damping, 0.0);

    // A scheme without that identity (linear acceleration) leaves a visible residual.
    let la = Scheme::Newmark {
        beta: 1.0 / 6.0,
        gamma: 0.5,
    };
    let (e_la, _) = balance(&model, la, dt, &ag);
    assert!(e_la.max_relative_error() > 1e-6, "{:e}", e_la.max_relative_error());
}

#[test]
fn energy_balance_with_damping_closes_for_average_acceleration() {
    let (_, model) = building(4);
    let model = model
        .with_damping(&DampingSpec::RayleighRatio {
            zeta: 0.05,
            modes: (1, 3),
        })
        .unwrap();
    let dt = 0.01;
    let ag = sine_sweep(0.5, 8.0, 10.0, dt, 1.5);
    let aa = Scheme::Newmark { beta: 0.25, gamma: 0.5 };
    let (e, _) = balance(&model, aa, dt, &ag);
    let t = e.terms();
    assert!(t.damping > 0.1 * t.input, "damping dissipates a good part: {t:?}");
    assert!(e.max_relative_error() < 1e-11, "{:e}", e.max_relative_error());
}

#[test]
fn storey_shears_match_springs_and_floor_equilibrium() {
    let (b, model) = building(5);
    let beta = 2e-3;
    let model = StructuralModel::new(
        model.mass.clone(),
        &model.stiffness * beta,
        model.stiffness.clone(),
        None,
    )
    .unwrap();
    assert!(is_shear_chain(&model));
    let k = b.story_stiffness();
    let dt = 0.01;
    let ag = sine_sweep(0.5, 6.0, 5.0, dt, 2.0);
    let states = simulate(
        Scheme::Newmark { beta: 0.25, gamma: 0.5 },
        &model,
        dt,
        &ground_loads(&model, &ag),
    );
    let mut r = StoreyResponse::new(&model);
    let mut worst = 0.0_f64;
    let mut scale = 0.0_f64;
    for (s, &a) in states.iter().zip(&ag) {
        r.update(s.u.as_slice(), s.v.as_slice(), s.a.as_slice(), a).unwrap();
        scale = scale.max(r.base_shear.abs());
        // Storey j: spring k δ_j plus dashpot βk δ̇_j.
        for j in 0..5 {
            let below = |x: &nalgebra::DVector<f64>| if j == 0 { 0.0 } else { x[j - 1] };
            let spring = k * (s.u[j] - below(&s.u)) + beta * k * (s.v[j] - below(&s.v));
            worst = worst.max((r.storey_shear[j] - spring).abs());
            assert!((r.drift[j] - (s.u[j] - below(&s.u))).abs() < 1e-15);
        }
        // Base shear = first-storey shear = Σ of the floor inertia forces −m a_abs.
        let inertia: f64 = (0..5).map(|j| -b.story_mass * (s.a[j] + a)).sum();
        worst = worst.max((r.base_shear - r.storey_shear[0]).abs());
        worst = worst.max((r.base_shear - inertia).abs());
        for j in 0..5 {
            assert!((r.absolute_acceleration[j] - (s.a[j] + a)).abs() < 1e-12);
        }
    }
    assert!(scale > 1e4, "the record loads the building: {scale} N");
    assert!(worst < 1e-8 * scale, "storey shear mismatch {worst} N of {scale} N");
    // A model with rotational DOFs or a non-unit influence is not a shear chain.
    let m = DMatrix::from_diagonal_element(3, 3, 1.0);
    let full = DMatrix::from_element(3, 3, 1.0) + &m * 2.0;
    let frame = StructuralModel::new(m.clone(), m.clone() * 0.0, full, None).unwrap();
    assert!(!is_shear_chain(&frame));
    assert!(StoreyResponse::new(&frame).storey_shear.is_empty());
}

/// Closed-form response of `ü + 2ζω u̇ + ω² u = −A sin Ωt` from rest: `(u, u̇)` at `t`.
fn harmonic_sdof(w: f64, zeta: f64, amp: f64, big_w: f64, t: f64) -> (f64, f64) {
    let (p, q) = (w * w - big_w * big_w, 2.0 * zeta * w * big_w);
    let det = p * p + q * q;
    let (c, d) = (-amp * p / det, amp * q / det);
    let wd = w * (1.0 - zeta * zeta).sqrt();
    let e = -d;
    let f = (zeta * w * e - c * big_w) / wd;
    let decay = (-zeta * w * t).exp();
    let (s, co) = (wd * t).sin_cos();
    let u = c * (big_w * t).sin() + d * (big_w * t).cos() + decay * (e * co + f * s);
    let v = c * big_w * (big_w * t).cos() - d * big_w * (big_w * t).sin()
        + decay * (-zeta * w * (e * co + f * s) + wd * (-e * s + f * co));
    (u, v)
}

#[test]
fn response_spectrum_of_a_harmonic_record_matches_the_closed_form() {
    let (dt, amp, f) = (0.001, 1.5, 2.0);
    let big_w = 2.0 * PI * f;
    let n = 8001;
    let ag: Vec<f64> = (0..n).map(|i| amp * (big_w * i as f64 * dt).sin()).collect();
    let zeta = 0.05;
    let periods = log_periods(0.05, 3.0, 12);
    let spectrum = response_spectrum(&ag, dt, &periods, zeta).unwrap();
    for o in &spectrum {
        let w = 2.0 * PI / o.period;
        let (mut sd, mut sa) = (0.0_f64, 0.0_f64);
        for i in 0..n {
            let (u, v) = harmonic_sdof(w, zeta, amp, big_w, i as f64 * dt);
            sd = sd.max(u.abs());
            sa = sa.max((2.0 * zeta * w * v + w * w * u).abs());
        }
        let (e_sd, e_sa) = ((o.sd / sd - 1.0).abs(), (o.sa / sa - 1.0).abs());
        assert!(
            e_sd < 2e-5 && e_sa < 2e-5,
            "T = {} s: S_d {} vs {sd}, S_a {} vs {sa}",
            o.period,
            o.sd,
            o.sa
        );
        assert!((o.psa - w * w * o.sd).abs() <= 1e-12 * o.psa);
    }
    // Resonance: the 0.5 s oscillator reaches nearly the steady amplitude A / (2ζω²) at 16 cycles.
    let res = sdof_peak(&ag, dt, 1.0 / f, zeta).unwrap();
    let steady = amp / (2.0 * zeta * big_w * big_w);
    assert!(
        res.sd > 0.9 * steady && res.sd < 1.0001 * steady,
        "{} vs {steady}",
        res.sd
    );
    // Bad input names the parameter.
    let e = sdof_peak(&ag, dt, 0.0, zeta).unwrap_err().to_string();
    assert!(e.contains("period"), "{e}");
    let _ = sdof(1.0, 0.0, 1.0).unwrap();
}

#[test]
fn ground_motion_units_convert_to_si() {
    let dir = std::env::temp_dir().join(format!("substep-units-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("ag.csv"), "t,ag\n0.0,0.0\n0.01,0.5\n0.02,-0.25\n").unwrap();
    let cfg = |units: &str| {
        format!(
            "[structure.sdof]\nmass = 1.0\nstiffness = 100.0\ndamping = 0.1\n[ground_motion]\nfile = \"ag.csv\"\n{units}\n[integrator]\ndt = 0.01\n"
        )
    };
    let peak = |units: &str| -> Result<f64, String> {
        let def = substep::io::TestDefinition::from_toml(&cfg(units), "u.toml", &dir).map_err(|e| e.to_string())?;
        Ok(def.ground_motion.accel.iter().fold(0.0_f64, |m, a| m.max(a.abs())))
    };
    assert_eq!(peak("").unwrap(), 0.5);
    assert_eq!(peak("units = \"m/s2\"").unwrap(), 0.5);
    assert!((peak("units = \"g\"").unwrap() - 0.5 * 9.80665).abs() < 1e-12);
    assert!((peak("units = \"cm/s2\"\nscale = 2.0").unwrap() - 0.01).abs() < 1e-15);
    let e = peak("units = \"ft/s2\"").unwrap_err();
    assert!(e.contains("ground_motion.units") && e.contains("ft/s2"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
