//! Helpers shared by the integration tests: excitation, simulation driver, error measures.
//! Nothing here computes a reference solution; the references live in the test files.

#![allow(dead_code)]

pub mod yielding;

use nalgebra::{DMatrix, DVector};
use std::f64::consts::PI;
use substep::integrate::{Kinematics, Scheme};
use substep::model::StructuralModel;

/// The named three-point schemes of docs/theory.md §2.1 `(name, β, γ)`, plus one general Newmark
/// member (`γ = 0.6`, `β = (γ + ½)²/4`).
pub const FAMILY: [(&str, f64, f64); 7] = [
    ("central difference", 0.0, 0.5),
    ("Fox-Goodwin", 1.0 / 12.0, 0.5),
    ("linear acceleration", 1.0 / 6.0, 0.5),
    ("average acceleration", 0.25, 0.5),
    ("Galerkin", 0.8, 1.5),
    ("backward difference", 1.0, 1.5),
    ("general Newmark", 0.3025, 0.6),
];

/// Linear sine sweep `amp · sin(2π (f0 t + (f1 − f0) t² / (2 T)))`, sampled at `t_i = i dt`,
/// `i = 0..=round(T/dt)`.
pub fn sine_sweep(f0: f64, f1: f64, duration: f64, dt: f64, amp: f64) -> Vec<f64> {
    let n = (duration / dt).round() as usize;
    (0..=n)
        .map(|i| {
            let t = i as f64 * dt;
            amp * (2.0 * PI * (f0 * t + (f1 - f0) * t * t / (2.0 * duration))).sin()
        })
        .collect()
}

/// Ground-motion loads `f_i = −M ι a_g,i` (docs/theory.md §1.3).
pub fn ground_loads(model: &StructuralModel, ag: &[f64]) -> Vec<DVector<f64>> {
    let m_iota = &model.mass * &model.influence;
    ag.iter().map(|&a| &m_iota * (-a)).collect()
}

/// Run `scheme` from rest through the loads; returns the states at steps `0..loads.len()`.
pub fn simulate(scheme: Scheme, model: &StructuralModel, dt: f64, loads: &[DVector<f64>]) -> Vec<Kinematics> {
    let mut integrator = scheme.build(model, dt, &loads[0]).expect("build integrator");
    let mut out = Vec::with_capacity(loads.len());
    out.push(integrator.state().clone());
    for f in &loads[1..] {
        integrator.step(f);
        out.push(integrator.state().clone());
    }
    out
}

/// `max |x − r| / max |r|` over all steps and DOFs.
pub fn rel_error<'a>(
    x: impl IntoIterator<Item = &'a DVector<f64>>,
    r: impl IntoIterator<Item = &'a DVector<f64>>,
) -> f64 {
    let (mut diff, mut scale) = (0.0f64, 0.0f64);
    for (a, b) in x.into_iter().zip(r) {
        assert_eq!(a.len(), b.len());
        diff = diff.max((a - b).amax());
        scale = scale.max(b.amax());
    }
    assert!(scale > 0.0, "reference is identically zero");
    diff / scale
}

/// Relative errors `[u, v, a]` of a simulated history against a reference history.
pub fn rel_errors(x: &[Kinematics], r: &[Kinematics]) -> [f64; 3] {
    assert_eq!(x.len(), r.len(), "histories differ in length");
    [
        rel_error(x.iter().map(|k| &k.u), r.iter().map(|k| &k.u)),
        rel_error(x.iter().map(|k| &k.v), r.iter().map(|k| &k.v)),
        rel_error(x.iter().map(|k| &k.a), r.iter().map(|k| &k.a)),
    ]
}

/// Closed form of the uniform fixed-free shear chain with `n` floors of mass `m` and first
/// period `period`: story stiffness `k = m (ω₁ / (2 sin(π/(2(2N+1)))))²`, and with
/// `θ_j = (2j−1)π/(2N+1)` the frequencies `ω_j = 2√(k/m) sin(θ_j/2)` and mass-normalised
/// shapes `φ_j(r) = 2 sin(r θ_j)/√(m(2N+1))`, `r = 1..N`. Returns `(k, ω, Φ)`.
pub fn shear_chain_modes(n: usize, m: f64, period: f64) -> (f64, Vec<f64>, DMatrix<f64>) {
    let w1 = 2.0 * PI / period;
    let k = m * (w1 / (2.0 * (PI / (2.0 * (2 * n + 1) as f64)).sin())).powi(2);
    let theta: Vec<f64> = (1..=n).map(|j| (2 * j - 1) as f64 * PI / (2 * n + 1) as f64).collect();
    let omega = theta.iter().map(|t| 2.0 * (k / m).sqrt() * (t / 2.0).sin()).collect();
    let norm = 2.0 / (m * (2 * n + 1) as f64).sqrt();
    let phi = DMatrix::from_fn(n, n, |r, j| norm * ((r + 1) as f64 * theta[j]).sin());
    (k, omega, phi)
}
