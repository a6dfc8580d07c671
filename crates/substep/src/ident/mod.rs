//! On-line identification: recursive least squares with forgetting (docs/theory.md §5, used by
//! §4.4 and §6.4) and an ARX model helper.
//!
//! * [`Rls`] — full-covariance RLS. For a regressor `φ` and a measurement `y`:
//!
//!   ```text
//!   e = y − φᵀθ                          (a-priori error, returned)
//!   K = Pφ / (λ + φᵀPφ)
//!   θ ← θ + K e
//!   P ← (P − K φᵀ P) / λ,  then P ← (P + Pᵀ)/2
//!   ```
//!
//!   A datum `l` updates old weighs `λ^l` in the cost `Σ λ^{t−s} (y_s − φ_sᵀθ)²`; the start
//!   `θ = 0`, `P = p0·I` is a ridge regularisation of weight `1/p0`.
//! * [`ScalarRls`] — the cheap form with `P = p·I` kept scalar (docs/theory.md §5.3: small real-time
//!   targets). Its scalar is updated so that the trace of `P` follows the full update:
//!   `p ← (p − p²‖φ‖² / (n (λ + p‖φ‖²))) / λ`. It behaves like a normalised LMS whose step size
//!   settles where the forgetting and the information gain balance.
//! * [`Arx`] — an ARX model `y_j = Σ_{l=1}^{na} a_l y_{j−l} + Σ_{l=0}^{nb} b_l u_{j−l}` identified
//!   with [`Rls`], keeping the regressor history.
//!
//! Robustness (docs/theory.md §5.2: regularised start, covariance bounds, no divergence under poor
//! excitation), shared by both estimators:
//!
//! * updates with a non-finite or all-zero regressor, a non-finite error, or a non-finite
//!   `φᵀPφ` are skipped (the a-priori error is still returned, `0` if it is not finite);
//! * the covariance is bounded: when `trace P > p_max·n` it is rescaled to `trace P = p_max·n`
//!   (default `p_max = p0`). Without excitation and `λ < 1`, `P` would otherwise grow as `λ^{−t}`
//!   ("covariance wind-up") and the first excitation after a quiet phase would make `θ` jump;
//! * a covariance that lost positive definiteness (negative diagonal or `φᵀPφ < 0`, only
//!   possible by round-off) or became non-finite is reset to `p0·I`;
//! * an optional dead zone: errors with `|e| ≤ dead_zone` do not update (noise floor);
//! * an update that would make `θ` non-finite is discarded; with finite inputs `θ` and `P`
//!   stay finite.
//!
//! All buffers are sized at construction; `update` does not allocate.

mod arx;
mod rls;

pub use arx::Arx;
pub use rls::{Rls, ScalarRls};

/// The interface shared by [`Rls`] and [`ScalarRls`].
pub trait Estimator: Send {
    fn n_params(&self) -> usize;
    /// `φᵀθ`.
    fn predict(&self, phi: &[f64]) -> f64;
    /// RLS step with measurement `y`; returns the a-priori error `y − φᵀθ`.
    fn update(&mut self, phi: &[f64], y: f64) -> f64 {
        let e = y - self.predict(phi);
        self.update_with_error(phi, e);
        if e.is_finite() { e } else { 0.0 }
    }
    /// RLS step driven by an externally measured a-priori error `e` (`θ ← θ + K e`): the form
    /// used when the error is observed rather than computed from a target (docs/theory.md §5.1; use: §6.4).
    /// Returns whether the update was applied.
    fn update_with_error(&mut self, phi: &[f64], e: f64) -> bool;
    fn theta(&self) -> &[f64];
    fn set_theta(&mut self, theta: &[f64]);
    fn covariance_trace(&self) -> f64;
    /// `P ← p0·I` (θ is kept).
    fn reset_covariance(&mut self);
}

/// Validation shared by the estimators' constructors.
fn validate(n_params: usize, lambda: f64, p0: f64) -> crate::Result<()> {
    use crate::Error;
    if n_params == 0 {
        return Err(Error::invalid("order", "the estimator needs at least one parameter"));
    }
    if !(lambda.is_finite() && lambda > 0.0 && lambda <= 1.0) {
        return Err(Error::invalid(
            "forgetting_factor",
            format!("must be in (0, 1], got {lambda}"),
        ));
    }
    if !(p0.is_finite() && p0 > 0.0) {
        return Err(Error::invalid("p0", format!("must be a finite number > 0, got {p0}")));
    }
    Ok(())
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// A regressor that cannot carry information: non-finite or all zero.
fn unusable(phi: &[f64]) -> bool {
    phi.iter().any(|v| !v.is_finite()) || phi.iter().all(|&v| v == 0.0)
}
