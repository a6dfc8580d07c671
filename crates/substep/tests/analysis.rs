//! The amplification-matrix analysis against a hand-derived closed form and time-domain runs.

use nalgebra::DMatrix;
use substep::analysis::frequency::{exact_amplification, find_peaks, peak_errors};
use substep::analysis::stability::{critical_omega, linear_grid, stability_map};
use substep::analysis::{AnalysisCase, Parameter, Stability};
use substep::linalg::spectral_radius;
use substep::substructure::ErrorForceSpec;

/// The k_sub = 1 step of the analysis model written out by hand on the reduced state
/// `[u, v, a, f_c, x_s, ẋ_s]` (m = 1, ω = 1, trapezoidal Newmark, ideal actuator):
/// predictor `x̂ = F̂/K̂`, `u' = x̂ + G f_c`, Newmark kinematics; the TMD's relative motion
/// `e = x_s − u_c` is a free damped oscillation during the step (the linear support motion is a
/// particular solution), `f_c' = k_s e' + c_s ė'`. With `k_t/k₀ ≠ 1` the operator splitting
/// moves `(k_t − k₀) ũ`, `ũ = u + Δt v + Δt² (½ − β) a`, to the predictor's right-hand side.
fn closed_form_matrix(c: &AnalysisCase) -> DMatrix<f64> {
    let dt = c.omega_dt;
    let (m, k, cc) = (1.0, 1.0, 2.0 * c.zeta);
    let ws = c.eta_f;
    let ms = c.eta_m;
    let (ks, cs) = (ms * ws * ws, 2.0 * c.zeta_s * ms * ws);
    let (beta, gamma) = (0.25, 0.5);
    let a0 = 1.0 / (beta * dt * dt);
    let a1 = gamma / (beta * dt);
    let a2 = 1.0 / (beta * dt);
    let a3 = 1.0 / (2.0 * beta) - 1.0;
    let a4 = gamma / beta - 1.0;
    let a5 = dt * (gamma / beta - 2.0) / 2.0;
    let a6 = (1.0 - gamma) * dt;
    let a7 = gamma * dt;
    let khat = k + a0 * m + a1 * cc;
    let zs = c.zeta_s;
    let wd = ws * (1.0 - zs * zs).sqrt();
    let step = |s: [f64; 6]| -> [f64; 6] {
        let [u, v, a, f, x, y] = s;
        let fhat = m * (a0 * u + a2 * v + a3 * a) + cc * (a1 * u + a4 * v + a5 * a);
        let u_pred = u + dt * v + dt * dt * (0.5 - beta) * a;
        let split = (c.stiffness_ratio - 1.0) * k * u_pred;
        let u1 = (fhat - split) / khat + f / khat;
        let acc1 = a0 * (u1 - u) - a2 * v - a3 * a;
        let v1 = v + a6 * a + a7 * acc1;
        let ud = (u1 - u) / dt;
        let (e0, ed0) = (x - u, y - ud);
        let decay = (-zs * ws * dt).exp();
        let (cs_, sn) = ((wd * dt).cos(), (wd * dt).sin());
        let e1 = decay * (e0 * cs_ + (ed0 + zs * ws * e0) / wd * sn);
        let ed1 = decay * (ed0 * cs_ - (zs * ws * ed0 + ws * ws * e0) / wd * sn);
        [u1, v1, acc1, ks * e1 + cs * ed1, u1 + e1, ud + ed1]
    };
    let mut a = DMatrix::zeros(6, 6);
    for j in 0..6 {
        let mut s = [0.0; 6];
        s[j] = 1.0;
        let col = step(s);
        for i in 0..6 {
            a[(i, j)] = col[i];
        }
    }
    a
}

#[test]
fn probed_rho_equals_closed_form_for_one_substep() {
    let mut worst: f64 = 0.0;
    let mut unstable_seen = false;
    for base in [AnalysisCase::typical_tmd(), AnalysisCase::large_mass_ratio()] {
        for zeta_s in [0.0, 0.05, 0.1, 0.3, 0.6] {
            for i in 1..=30 {
                let omega = 0.1 * i as f64;
                let case = AnalysisCase {
                    omega_dt: omega,
                    zeta_s,
                    ..base
                };
                let probed = case.spectral_radius().unwrap();
                let closed = spectral_radius(&closed_form_matrix(&case));
                unstable_seen |= closed > 1.0 + 1e-9;
                let err = (probed - closed).abs() / closed.max(1e-300);
                worst = worst.max(err);
                assert!(
                    err < 1e-12,
                    "Omega {omega}, zeta_s {zeta_s}: probed {probed} vs closed form {closed}"
                );
            }
        }
    }
    assert!(unstable_seen, "the grid should contain unstable points");
    println!("worst relative difference {worst:.2e}");
}

/// The stability of the splitting of a nonlinear numerical substructure (`k_t/k₀` from 0 to 2):
/// the probed spectral radius equals the hand-derived step; softening never destabilises it,
/// hardening does beyond a boundary in `Ω`.
#[test]
fn splitting_rho_equals_closed_form_over_stiffness_ratios() {
    let mut worst: f64 = 0.0;
    let (mut unstable_hardening, mut unstable_softening) = (0, 0);
    for base in [AnalysisCase::typical_tmd(), AnalysisCase::large_mass_ratio()] {
        for ratio in [0.0, 0.02, 0.25, 0.5, 1.0, 1.2, 1.5, 2.0] {
            for i in 1..=30 {
                let omega = 0.1 * i as f64;
                let case = AnalysisCase {
                    omega_dt: omega,
                    stiffness_ratio: ratio,
                    ..base
                };
                let probed = case.spectral_radius().unwrap();
                let closed = spectral_radius(&closed_form_matrix(&case));
                let err = (probed - closed).abs() / closed.max(1e-300);
                worst = worst.max(err);
                assert!(
                    err < 1e-11,
                    "k_t/k0 {ratio}, Omega {omega}: probed {probed} vs closed form {closed}"
                );
                let linear = spectral_radius(&closed_form_matrix(&AnalysisCase {
                    stiffness_ratio: 1.0,
                    ..case
                }));
                // Points where the linear algorithm is stable and the splitting is not.
                if closed > 1.0 + 1e-9 && linear <= 1.0 + 1e-9 {
                    if ratio > 1.0 {
                        unstable_hardening += 1;
                    } else {
                        unstable_softening += 1;
                    }
                }
            }
        }
    }
    println!(
        "worst relative difference {worst:.2e}, unstable: {unstable_hardening} hardening, {unstable_softening} softening"
    );
    assert_eq!(unstable_softening, 0, "softening must not destabilise a stable test");
    assert!(
        unstable_hardening > 10,
        "hardening beyond k0 should be unstable at large Omega"
    );
}

/// Peak free-vibration amplitude of the primary DOF in a window of steps.
fn window_peak(history: &[f64], from: usize, to: usize) -> f64 {
    history[from..to].iter().fold(0.0f64, |m, v| m.max(v.abs()))
}

#[test]
fn time_domain_growth_matches_rho() {
    let cases = [
        AnalysisCase {
            omega_dt: 0.6,
            zeta_s: 0.0,
            ..AnalysisCase::typical_tmd()
        },
        AnalysisCase {
            omega_dt: 0.6,
            ..AnalysisCase::large_mass_ratio()
        },
        AnalysisCase {
            omega_dt: 0.3,
            zeta_s: 0.3,
            ..AnalysisCase::large_mass_ratio()
        },
        AnalysisCase {
            omega_dt: 1.2,
            k_sub: 2,
            ..AnalysisCase::large_mass_ratio()
        },
        AnalysisCase {
            omega_dt: 0.5,
            k_sub: 3,
            ..AnalysisCase::typical_tmd()
        },
        AnalysisCase {
            omega_dt: 0.4,
            k_sub: 2,
            eta_p: 0.5,
            zeta_s: 0.02,
            ..AnalysisCase::typical_tmd()
        },
        // the splitting of a nonlinear numerical substructure, yielded and hardened
        AnalysisCase {
            omega_dt: 0.8,
            k_sub: 4,
            stiffness_ratio: 0.05,
            ..AnalysisCase::typical_tmd()
        },
        AnalysisCase {
            omega_dt: 2.5,
            k_sub: 4,
            stiffness_ratio: 1.8,
            ..AnalysisCase::typical_tmd()
        },
    ];
    let mut unstable = 0;
    for case in cases {
        let rho = case.spectral_radius().unwrap();
        let mut test = case.build_test().unwrap();
        let mut u = Vec::new();
        for i in 0..200 {
            // a ground-acceleration pulse at the first step, then free vibration
            let (ag0, ag1) = (if i == 1 { 1.0 } else { 0.0 }, if i == 0 { 1.0 } else { 0.0 });
            test.step(ag0, ag1, &mut ()).unwrap();
            u.push(test.controller.state().u[0]);
        }
        let growth = (window_peak(&u, 150, 200) / window_peak(&u, 50, 100)).powf(1.0 / 100.0);
        println!("{case:?}: rho {rho:.6}, time-domain {growth:.6}");
        // 100-step windows resolve the growth rate to a few 1e-3 (other modes still ring)
        assert!(
            (growth - rho).abs() < 4e-3 * rho,
            "rho {rho} vs time-domain growth {growth}"
        );
        assert_eq!(
            growth > 1.0,
            rho > 1.0,
            "classification differs: rho {rho}, growth {growth}"
        );
        if rho > 1.0 {
            unstable += 1;
        }
    }
    assert!(unstable >= 2);
}

#[test]
fn stability_classification_and_critical_omega() {
    assert_eq!(Stability::classify(0.99, 1e-9), Stability::Stable);
    assert_eq!(Stability::classify(1.0 + 1e-12, 1e-9), Stability::Limited);
    assert_eq!(Stability::classify(1.01, 1e-9), Stability::Unstable);
    assert_eq!(critical_omega(&[(0.1, 0.9), (0.2, 0.98), (0.3, 1.02)], 0.0), Some(0.25));
    assert_eq!(critical_omega(&[(0.1, 0.9), (0.2, 0.98)], 0.0), None);
    // An undamped TMD with k_sub = 1 is unstable from small Ω on; damping enlarges the region.
    let omegas = linear_grid("omega", 0.05, 1.5, 30).unwrap();
    let pts = stability_map(
        &AnalysisCase::typical_tmd(),
        &[1],
        &omegas,
        Parameter::ZetaS,
        &[0.0, 0.3],
        &|_| {},
    )
    .unwrap();
    let row = |z: f64| -> Vec<(f64, f64)> {
        pts.iter()
            .filter(|p| p.value == z)
            .map(|p| (p.omega_dt, p.rho))
            .collect()
    };
    let w0 = critical_omega(&row(0.0), 1e-9).unwrap();
    let w3 = critical_omega(&row(0.3), 1e-9);
    assert!(w3.is_none_or(|w| w > w0), "{w0} {w3:?}");
    assert!(
        linear_grid("omega", 1.0, 0.5, 10)
            .unwrap_err()
            .to_string()
            .contains("inverted")
    );
    assert!(
        linear_grid("omega", 0.0, 1.0, 0)
            .unwrap_err()
            .to_string()
            .contains("empty")
    );
}

#[test]
fn frequency_peaks_approach_exact_as_dt_shrinks() {
    let mut prev = f64::INFINITY;
    for eta_t in [0.05, 0.02, 0.005] {
        let case = AnalysisCase {
            k_sub: 4,
            error_force: ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 },
            ..AnalysisCase::typical_tmd()
        }
        .with(Parameter::EtaT, eta_t);
        let errs = peak_errors(&case).unwrap();
        assert_eq!(errs.len(), 2);
        let worst = errs
            .iter()
            .map(|e| e.amplitude_error.abs().max(e.period_error.abs()))
            .fold(0.0, f64::max);
        println!("eta_T {eta_t}: {errs:?}");
        assert!(worst < prev);
        prev = worst;
    }
    assert!(prev < 2e-3, "{prev}");
    // the exact peaks of the typical TMD system bracket r = 1
    let case = AnalysisCase::typical_tmd();
    let peaks = find_peaks(|r| exact_amplification(&case, r).unwrap(), 0.05, 3.0, 1500);
    assert_eq!(peaks.len(), 2);
    assert!(peaks[0].freq_ratio < 1.0 && peaks[1].freq_ratio > 1.0);
}

/// Steady-state harmonic runs in the time domain give the discrete frequency response.
#[test]
fn harmonic_runs_equal_discrete_frequency_response() {
    use substep::analysis::frequency::DiscreteResponse;
    use substep::analysis::verify::harmonic_amplification;
    let case = AnalysisCase {
        omega_dt: 0.1,
        k_sub: 3,
        eta_p: 0.3,
        ..AnalysisCase::typical_tmd()
    };
    let resp = DiscreteResponse::new(&case).unwrap();
    for r in [0.5, 0.89, 1.0, 1.11, 1.6] {
        let td = harmonic_amplification(&case, r, 6000, 2000).unwrap();
        let fd = resp.amplification(r);
        println!("r {r}: time domain {td:.8}, frequency domain {fd:.8}");
        assert!((td - fd).abs() < 1e-3 * fd, "r {r}: {td} vs {fd}");
    }
}

/// Peaks of a stepped-sine sweep in the time domain agree with the frequency-domain peaks
/// within the sweep's resolution.
#[test]
fn sine_sweep_peaks_agree_with_frequency_domain() {
    use substep::analysis::frequency::{DiscreteResponse, find_peaks};
    use substep::analysis::verify::stepped_sine_sweep;
    let case = AnalysisCase {
        omega_dt: 0.2,
        k_sub: 2,
        ..AnalysisCase::typical_tmd()
    };
    let resp = DiscreteResponse::new(&case).unwrap();
    let fd = find_peaks(|r| resp.amplification(r), 0.05, 3.0, 1500);
    let step = 0.01;
    let ratios: Vec<f64> = (0..=60).map(|i| 0.7 + step * i as f64).collect();
    let (_, td) = stepped_sine_sweep(&case, &ratios, 3000, 1000).unwrap();
    assert_eq!(td.len(), 2);
    for (t, f) in td.iter().zip(&fd) {
        println!("time domain {t:?}, frequency domain {f:?}");
        assert!((t.freq_ratio - f.freq_ratio).abs() <= step, "{t:?} vs {f:?}");
        assert!(t.h <= f.h * (1.0 + 1e-3) && t.h >= resp.amplification(t.freq_ratio) * (1.0 - 1e-3));
    }
}
