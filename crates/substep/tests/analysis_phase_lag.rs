//! The stability map of the analysis model with a frozen phase-lag compensator (docs/theory.md §6.7, §9.1):
//! the actuator delay shrinks the stable region, polynomial extrapolation with the lead
//! `η_p · k_sub` sub-steps (frozen, a fixed linear filter) enlarges it again.

use substep::analysis::stability::{linear_grid, stability_map};
use substep::analysis::{AnalysisCase, FrozenPhaseLag, Parameter, Stability};

/// Share of the (Ω, ζ_s) grid that is stable or limited.
fn stable_share(case: &AnalysisCase, k: usize) -> f64 {
    let omegas = linear_grid("omega", 0.05, 1.5, 30).unwrap();
    let zetas = linear_grid("zeta_s", 0.0, 0.5, 11).unwrap();
    let points = stability_map(case, &[k], &omegas, Parameter::ZetaS, &zetas, &|_| {}).unwrap();
    points
        .iter()
        .filter(|p| Stability::classify(p.rho, 1e-9) != Stability::Unstable)
        .count() as f64
        / points.len() as f64
}

fn with_polynomial(case: AnalysisCase, order: usize) -> AnalysisCase {
    AnalysisCase {
        phase_lag: Some(FrozenPhaseLag::Polynomial { order }),
        ..case
    }
}

#[test]
fn frozen_polynomial_compensation_enlarges_the_stable_region_of_a_delayed_case() {
    for (eta_p, k, order) in [(0.5, 2, 1), (0.5, 2, 2), (0.5, 4, 1), (1.0, 2, 2), (1.0, 4, 1)] {
        let delayed = AnalysisCase {
            eta_p,
            ..AnalysisCase::typical_tmd()
        };
        let none = stable_share(&delayed, k);
        let with = stable_share(&with_polynomial(delayed, order), k);
        let no_delay = stable_share(&AnalysisCase { eta_p: 0.0, ..delayed }, k);
        println!(
            "η_p = {eta_p}, k_sub = {k}, order {order}: stable share {:.1} % without, {:.1} % with compensation ({:.1} % without delay)",
            100.0 * none,
            100.0 * with,
            100.0 * no_delay
        );
        assert!(none < no_delay, "the delay must cost stability here");
        assert!(
            with > none + 0.01,
            "η_p = {eta_p}, k_sub = {k}, order {order}: {with} vs {none}"
        );
    }
}

#[test]
fn a_long_cubic_extrapolation_can_shrink_it() {
    // Documented limitation: extrapolating 4 sub-steps ahead with a cubic amplifies the
    // high-frequency content of the command and destabilises large Ω.
    let delayed = AnalysisCase {
        eta_p: 1.0,
        ..AnalysisCase::typical_tmd()
    };
    let none = stable_share(&delayed, 4);
    let cubic = stable_share(&with_polynomial(delayed, 3), 4);
    println!(
        "η_p = 1, k_sub = 4: {:.1} % without, {:.1} % with cubic extrapolation",
        100.0 * none,
        100.0 * cubic
    );
    assert!(cubic < none);
}

#[test]
fn the_frozen_compensator_state_is_part_of_the_map() {
    let case = with_polynomial(
        AnalysisCase {
            eta_p: 0.5,
            k_sub: 2,
            ..AnalysisCase::typical_tmd()
        },
        2,
    );
    let plain = AnalysisCase {
        phase_lag: None,
        ..case
    };
    // The compensated map has the compensator's history (order entries) and y_{j−1} in addition.
    assert_eq!(
        case.step_map().unwrap().a.nrows(),
        plain.step_map().unwrap().a.nrows() + 3
    );
    let bad = with_polynomial(case, 4);
    let e = bad.step_map().unwrap_err().to_string();
    assert!(e.contains("phase_lag.order"), "{e}");
}

/// The ARX compensator in the analysis: frozen at the parameters it converges to in front of the
/// delayed actuator, the wrapper is a time-invariant linear map (probing it twice gives the same
/// spectral radius to rounding), and at an undamped TMD behind a step of delay it damps the
/// test (smaller ρ than without compensation).
#[test]
fn frozen_arx_at_converged_parameters_is_a_fixed_linear_map() {
    let delayed = AnalysisCase {
        eta_p: 1.0,
        zeta_s: 0.0,
        omega_dt: 0.2,
        k_sub: 4,
        ..AnalysisCase::typical_tmd()
    };
    let arx = AnalysisCase {
        phase_lag: Some(FrozenPhaseLag::Arx),
        ..delayed
    };
    let (r1, r2) = (arx.spectral_radius().unwrap(), arx.spectral_radius().unwrap());
    let none = delayed.spectral_radius().unwrap();
    println!("η_p = 1, ζ_s = 0, Ω = 0.2, k_sub = 4: ρ = {none:.6} without, {r1:.6} with the converged ARX compensator");
    assert!((r1 - r2).abs() <= 1e-12 * r1, "{r1} vs {r2}");
    assert!(r1 < none, "{r1} vs {none}");
}
