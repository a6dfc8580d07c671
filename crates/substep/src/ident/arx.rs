//! An ARX model identified on line by [`Rls`].

use super::{Rls, dot};
use crate::error::Result;

/// The ARX model
///
/// ```text
/// y_j = Σ_{l=1}^{na} a_l y_{j−l} + Σ_{l=0}^{nb} b_l u_{j−l}
/// ```
///
/// with parameter vector `θ = [a_1 … a_na, b_0 … b_nb]` (length `na + nb + 1`) and regressor
/// `φ_j = [y_{j−1} … y_{j−na}, u_j … u_{j−nb}]`. The history before the first sample is zero.
///
/// Per sample `j` call [`Arx::push`]`(u_j, y_j)`: it forms `φ_j`, makes one RLS step towards
/// `y_j`, and shifts the history. [`Arx::predict_next`]`(u_j)` is the model's prediction of the
/// next `y_j` before it is measured (`φ_jᵀθ`).
#[derive(Debug, Clone)]
pub struct Arx {
    na: usize,
    nb: usize,
    rls: Rls,
    /// `[y_{j−1} … y_{j−na}, (slot for u_j), u_{j−1} … u_{j−nb}]`.
    phi: Vec<f64>,
}

impl Arx {
    /// `na ≥ 0` autoregressive and `nb + 1 ≥ 1` input parameters; `lambda`, `p0` as
    /// [`Rls::new`].
    pub fn new(na: usize, nb: usize, lambda: f64, p0: f64) -> Result<Self> {
        let n = na + nb + 1;
        Ok(Self {
            na,
            nb,
            rls: Rls::new(n, lambda, p0)?,
            phi: vec![0.0; n],
        })
    }

    /// Replace the estimator (e.g. one built with a covariance bound or dead zone); it must have
    /// `na + nb + 1` parameters (panics otherwise).
    pub fn with_rls(mut self, rls: Rls) -> Self {
        assert_eq!(
            rls.n_params(),
            self.phi.len(),
            "the estimator's size does not match the ARX orders"
        );
        self.rls = rls;
        self
    }

    /// Sample `j`: input `u_j`, measured output `y_j`. Returns the a-priori error `y_j − φ_jᵀθ`.
    pub fn push(&mut self, u: f64, y: f64) -> f64 {
        let (na, nb) = (self.na, self.nb);
        self.phi[na] = u;
        let e = self.rls.update(&self.phi, y);
        if na > 0 {
            self.phi.copy_within(0..na - 1, 1);
            self.phi[0] = y;
        }
        if nb > 0 {
            // [u_j, u_{j−1} … u_{j−nb}] → [u_j (stays for the next u slot) …]: shift the past inputs.
            self.phi.copy_within(na..na + nb, na + 1);
        }
        e
    }

    /// Prediction of the next output given its input `u_j`: `φ_jᵀθ`.
    pub fn predict_next(&self, u: f64) -> f64 {
        let theta = self.rls.theta();
        let na = self.na;
        dot(&self.phi[..na], &theta[..na]) + theta[na] * u + dot(&self.phi[na + 1..], &theta[na + 1..])
    }

    /// `[a_1 … a_na]`.
    pub fn a(&self) -> &[f64] {
        &self.rls.theta()[..self.na]
    }
    /// `[b_0 … b_nb]`.
    pub fn b(&self) -> &[f64] {
        &self.rls.theta()[self.na..]
    }
    pub fn theta(&self) -> &[f64] {
        self.rls.theta()
    }
    pub fn rls(&self) -> &Rls {
        &self.rls
    }
    pub fn rls_mut(&mut self) -> &mut Rls {
        &mut self.rls
    }
    pub fn orders(&self) -> (usize, usize) {
        (self.na, self.nb)
    }
}
