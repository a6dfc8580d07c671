//! Discrete SISO filters and the Tustin (bilinear) discretisation of a continuous transfer
//! function.
//!
//! Tustin at sample time `h` substitutes `s = (2/h)(z − 1)/(z + 1)`. For
//! `G(s) = Σ b_i s^i / Σ a_i s^i` of order `n` both polynomials are multiplied by `(z + 1)^n`:
//! `s^i → (2/h)^i (z − 1)^i (z + 1)^{n−i}`. After normalising the leading denominator
//! coefficient to 1 the filter is
//!
//! ```text
//! y_k = Σ_{i=0}^{n} β_i x_{k−i} − Σ_{i=1}^{n} α_i y_{k−i}
//! ```
//!
//! realised in transposed direct form II ([`DiscreteFilter::step`], allocation-free). The
//! discretisation is refused (an error, never a panic) when a pole of the discrete filter lies
//! outside the unit circle (`|z| > 1 + 1e-9`; poles on the circle, e.g. the integrator of a PI
//! controller at `z = 1`, are accepted), or when `s = 2/h` is a pole of `G` (Tustin maps it to
//! infinity).

use super::lti::{TransferFunction, poly_add, poly_mul};
use crate::error::{Error, Result};
use nalgebra::DMatrix;

/// How far outside the unit circle a pole may lie before the filter is refused.
pub const UNIT_CIRCLE_TOLERANCE: f64 = 1e-9;

/// A discrete filter `B(z)/A(z)`, `a[0] = 1`, in transposed direct form II.
#[derive(Debug, Clone, PartialEq)]
pub struct DiscreteFilter {
    b: Vec<f64>,
    a: Vec<f64>,
    w: Vec<f64>,
}

impl DiscreteFilter {
    /// `b`, `a` in powers of `z⁻¹` (`a[0] ≠ 0`; both normalised by it). `what` names the thing.
    pub fn new(what: &str, b: &[f64], a: &[f64]) -> Result<Self> {
        if a.is_empty() || a[0] == 0.0 || !a[0].is_finite() {
            return Err(Error::invalid(
                format!("{what}.a"),
                "leading coefficient must be finite and non-zero",
            ));
        }
        if b.is_empty() {
            return Err(Error::invalid(format!("{what}.b"), "is empty"));
        }
        if b.iter().chain(a).any(|v| !v.is_finite()) {
            return Err(Error::invalid(what, "has a non-finite coefficient"));
        }
        let n = a.len().max(b.len());
        let mut bb = vec![0.0; n];
        let mut aa = vec![0.0; n];
        for (i, v) in b.iter().enumerate() {
            bb[i] = v / a[0];
        }
        for (i, v) in a.iter().enumerate() {
            aa[i] = v / a[0];
        }
        Ok(Self {
            b: bb,
            a: aa,
            w: vec![0.0; n - 1],
        })
    }

    /// Tustin discretisation of `tf` at sample time `h`, refused if unstable (module docs).
    pub fn tustin(what: &str, tf: &TransferFunction, h: f64) -> Result<Self> {
        crate::error::require_positive(&format!("{what}.sample_time"), h)?;
        let n = tf.order();
        let c = 2.0 / h;
        let map = |p: &[f64]| -> Vec<f64> {
            // p in descending powers of s, degree ≤ n → polynomial in z (descending), degree n.
            let deg = p.len() - 1;
            let mut out = vec![0.0; n + 1];
            for (k, &coef) in p.iter().enumerate() {
                let i = deg - k; // power of s
                let mut term = vec![coef * c.powi(i as i32)];
                for _ in 0..i {
                    term = poly_mul(&term, &[1.0, -1.0]);
                }
                for _ in 0..(n - i) {
                    term = poly_mul(&term, &[1.0, 1.0]);
                }
                out = poly_add(&out, &term);
            }
            out
        };
        let b = map(tf.num());
        let a = map(tf.den());
        if a[0].abs() <= 1e-12 * a.iter().fold(0.0f64, |m, v| m.max(v.abs())) {
            return Err(Error::invalid(
                what,
                format!("has a pole at s = 2/h = {c} (Tustin maps it to infinity)"),
            ));
        }
        let filter = Self::new(what, &b, &a)?;
        let r = filter
            .pole_radius()
            .ok_or_else(|| Error::numerical(what, "poles of the discretised filter could not be computed"))?;
        if r > 1.0 + UNIT_CIRCLE_TOLERANCE {
            return Err(Error::invalid(
                what,
                format!("discretised controller is unstable: a pole lies outside the unit circle (|z| = {r:.6})"),
            ));
        }
        Ok(filter)
    }

    /// `β_i` (powers of `z⁻¹`).
    pub fn b(&self) -> &[f64] {
        &self.b
    }
    /// `α_i`, `α_0 = 1`.
    pub fn a(&self) -> &[f64] {
        &self.a
    }

    /// Largest pole modulus (0 for a FIR filter); `None` if the eigenvalues did not converge.
    pub fn pole_radius(&self) -> Option<f64> {
        let n = self.a.len() - 1;
        if n == 0 {
            return Some(0.0);
        }
        let mut comp = DMatrix::zeros(n, n);
        for j in 0..n {
            comp[(0, j)] = -self.a[j + 1];
        }
        for i in 1..n {
            comp[(i, i - 1)] = 1.0;
        }
        crate::linalg::eigenvalues(&comp).map(|ev| ev.iter().map(|z| z.norm()).fold(0.0, f64::max))
    }

    /// One sample: input `x_k` → output `y_k`.
    #[inline]
    pub fn step(&mut self, x: f64) -> f64 {
        let n = self.w.len();
        if n == 0 {
            return self.b[0] * x;
        }
        let y = self.b[0] * x + self.w[0];
        for i in 0..n - 1 {
            self.w[i] = self.b[i + 1] * x - self.a[i + 1] * y + self.w[i + 1];
        }
        self.w[n - 1] = self.b[n] * x - self.a[n] * y;
        y
    }

    /// The transposed-direct-form-II state (for checkpoints and the linear analysis).
    pub fn state(&self) -> &[f64] {
        &self.w
    }
    /// Set the state written by [`Self::state`].
    pub fn set_state(&mut self, w: &[f64]) {
        self.w.copy_from_slice(w);
    }

    /// Back to rest.
    pub fn reset(&mut self) {
        self.w.iter_mut().for_each(|w| *w = 0.0);
    }
}
