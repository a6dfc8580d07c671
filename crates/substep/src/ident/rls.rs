//! Recursive least squares: full covariance ([`Rls`]) and scalar covariance ([`ScalarRls`]).

use super::{Estimator, dot, unusable, validate};
use crate::error::{Error, Result};

/// Recursive least squares with exponential forgetting; see the [module docs](super).
#[derive(Debug, Clone)]
pub struct Rls {
    n: usize,
    lambda: f64,
    p0: f64,
    p_max: f64,
    dead_zone: f64,
    /// Covariance, row-major `n × n`.
    p: Vec<f64>,
    theta: Vec<f64>,
    /// Scratch: `Pφ`, then the candidate `θ`.
    pphi: Vec<f64>,
    theta_new: Vec<f64>,
    updates: u64,
}

impl Rls {
    /// `P = p0·I`, `θ = 0`. Errors name `order` (`n_params ≥ 1`), `forgetting_factor`
    /// (`λ ∈ (0, 1]`) and `p0` (`> 0`).
    pub fn new(n_params: usize, lambda: f64, p0: f64) -> Result<Self> {
        validate(n_params, lambda, p0)?;
        let n = n_params;
        let mut rls = Self {
            n,
            lambda,
            p0,
            p_max: p0,
            dead_zone: 0.0,
            p: vec![0.0; n * n],
            theta: vec![0.0; n],
            pphi: vec![0.0; n],
            theta_new: vec![0.0; n],
            updates: 0,
        };
        rls.reset_covariance();
        Ok(rls)
    }

    /// Start from `theta` instead of zero. Panics if the length is not `n_params`.
    pub fn with_theta(mut self, theta: &[f64]) -> Self {
        self.set_theta(theta);
        self
    }

    /// Bound the covariance: `trace P ≤ p_max·n` (default `p_max = p0`).
    pub fn with_covariance_bound(mut self, p_max: f64) -> Result<Self> {
        if !(p_max.is_finite() && p_max > 0.0) {
            return Err(Error::invalid(
                "p_max",
                format!("must be a finite number > 0, got {p_max}"),
            ));
        }
        self.p_max = p_max;
        self.bound_trace();
        Ok(self)
    }

    /// Skip updates whose a-priori error satisfies `|e| ≤ dead_zone` (default 0: none skipped).
    pub fn with_dead_zone(mut self, dead_zone: f64) -> Result<Self> {
        if !(dead_zone.is_finite() && dead_zone >= 0.0) {
            return Err(Error::invalid(
                "dead_zone",
                format!("must be a finite number >= 0, got {dead_zone}"),
            ));
        }
        self.dead_zone = dead_zone;
        Ok(self)
    }

    pub fn n_params(&self) -> usize {
        self.n
    }
    pub fn forgetting_factor(&self) -> f64 {
        self.lambda
    }

    /// `φᵀθ`.
    pub fn predict(&self, phi: &[f64]) -> f64 {
        dot(phi, &self.theta)
    }

    /// One RLS step with measurement `y`; returns the a-priori error `y − φᵀθ` (0 if that is
    /// not finite).
    pub fn update(&mut self, phi: &[f64], y: f64) -> f64 {
        Estimator::update(self, phi, y)
    }

    /// One RLS step driven by the a-priori error `e`; returns whether it was applied.
    pub fn update_with_error(&mut self, phi: &[f64], e: f64) -> bool {
        debug_assert_eq!(phi.len(), self.n);
        if !e.is_finite() || e.abs() <= self.dead_zone || unusable(phi) {
            return false;
        }
        let n = self.n;
        for i in 0..n {
            self.pphi[i] = dot(&self.p[i * n..(i + 1) * n], phi);
        }
        let s = dot(phi, &self.pphi);
        if !s.is_finite() {
            return false;
        }
        if s < 0.0 {
            // Round-off destroyed positive definiteness: restart the covariance, skip this datum.
            self.reset_covariance();
            return false;
        }
        let denom = self.lambda + s;
        for i in 0..n {
            self.theta_new[i] = self.theta[i] + self.pphi[i] / denom * e;
        }
        if self.theta_new.iter().any(|v| !v.is_finite()) {
            return false;
        }
        self.theta.copy_from_slice(&self.theta_new);
        // P ← (P − Pφ φᵀP / denom) / λ, symmetric by construction (upper triangle mirrored).
        let inv_lambda = 1.0 / self.lambda;
        let mut healthy = true;
        for i in 0..n {
            for j in i..n {
                let v =
                    (0.5 * (self.p[i * n + j] + self.p[j * n + i]) - self.pphi[i] * self.pphi[j] / denom) * inv_lambda;
                self.p[i * n + j] = v;
                self.p[j * n + i] = v;
            }
            let d = self.p[i * n + i];
            healthy &= d.is_finite() && d > 0.0;
        }
        if healthy {
            self.bound_trace();
        } else {
            self.reset_covariance();
        }
        self.updates += 1;
        true
    }

    pub fn theta(&self) -> &[f64] {
        &self.theta
    }

    /// Set `θ`; panics if the length is not `n_params`.
    pub fn set_theta(&mut self, theta: &[f64]) {
        assert_eq!(
            theta.len(),
            self.n,
            "theta has {} entries, the estimator {}",
            theta.len(),
            self.n
        );
        self.theta.copy_from_slice(theta);
    }

    /// The covariance, row-major `n × n`.
    pub fn covariance(&self) -> &[f64] {
        &self.p
    }

    pub fn covariance_trace(&self) -> f64 {
        (0..self.n).map(|i| self.p[i * self.n + i]).sum()
    }

    /// `P ← p0·I` (θ is kept).
    pub fn reset_covariance(&mut self) {
        let n = self.n;
        self.p.iter_mut().for_each(|v| *v = 0.0);
        for i in 0..n {
            self.p[i * n + i] = self.p0;
        }
        self.bound_trace();
    }

    /// Change the units of the parameters: `θ_i ← s_i θ_i`, `P_ij ← s_i s_j P_ij` (the regressor
    /// entry `i` is from now on divided by `s_i`). The covariance bound is re-applied. Panics if the
    /// length is not `n_params`; non-finite or non-positive factors are ignored (no change).
    pub fn rescale(&mut self, s: &[f64]) {
        assert_eq!(s.len(), self.n, "rescale needs one factor per parameter");
        if s.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return;
        }
        let n = self.n;
        for i in 0..n {
            self.theta[i] *= s[i];
            for j in 0..n {
                self.p[i * n + j] *= s[i] * s[j];
            }
        }
        self.bound_trace();
    }

    /// A pseudo-measurement of parameter `i` without forgetting: the RLS step for the regressor
    /// `√w·e_i` and the target `√w·prior` (adds `w (θ_i − prior)²` to the cost). Cycling it over
    /// the parameters keeps a ridge towards `prior` that forgetting cannot erase (regularised
    /// forgetting). Ignored for non-finite or non-positive `w`.
    pub fn regularize(&mut self, i: usize, w: f64, prior: f64) {
        if !(w.is_finite() && w > 0.0 && prior.is_finite()) || i >= self.n {
            return;
        }
        let n = self.n;
        let e = prior - self.theta[i];
        // Pφ = √w P_{:,i}, φᵀPφ = w P_ii.
        let pii = self.p[i * n + i];
        let denom = 1.0 + w * pii;
        if !(denom.is_finite() && pii > 0.0) {
            return;
        }
        for r in 0..n {
            self.pphi[r] = self.p[r * n + i];
        }
        let g = w / denom;
        for r in 0..n {
            self.theta_new[r] = self.theta[r] + self.pphi[r] * g * e;
        }
        if self.theta_new.iter().any(|v| !v.is_finite()) {
            return;
        }
        self.theta.copy_from_slice(&self.theta_new);
        for r in 0..n {
            for c in r..n {
                let v = 0.5 * (self.p[r * n + c] + self.p[c * n + r]) - g * self.pphi[r] * self.pphi[c];
                self.p[r * n + c] = v;
                self.p[c * n + r] = v;
            }
        }
        if (0..n).any(|r| !(self.p[r * n + r].is_finite() && self.p[r * n + r] > 0.0)) {
            self.reset_covariance();
        }
    }

    /// Number of updates applied so far.
    pub fn updates(&self) -> u64 {
        self.updates
    }

    fn bound_trace(&mut self) {
        let limit = self.p_max * self.n as f64;
        let tr = self.covariance_trace();
        if tr > limit {
            let s = limit / tr;
            self.p.iter_mut().for_each(|v| *v *= s);
        }
    }
}

impl Estimator for Rls {
    fn n_params(&self) -> usize {
        self.n
    }
    fn predict(&self, phi: &[f64]) -> f64 {
        Rls::predict(self, phi)
    }
    fn update_with_error(&mut self, phi: &[f64], e: f64) -> bool {
        Rls::update_with_error(self, phi, e)
    }
    fn theta(&self) -> &[f64] {
        &self.theta
    }
    fn set_theta(&mut self, theta: &[f64]) {
        Rls::set_theta(self, theta)
    }
    fn covariance_trace(&self) -> f64 {
        Rls::covariance_trace(self)
    }
    fn reset_covariance(&mut self) {
        Rls::reset_covariance(self)
    }
}

/// RLS with the covariance kept as `P = p·I`; same interface as [`Rls`], `O(n)` per update.
/// See the [module docs](super) for the scalar update.
#[derive(Debug, Clone)]
pub struct ScalarRls {
    n: usize,
    lambda: f64,
    p0: f64,
    p_max: f64,
    dead_zone: f64,
    p: f64,
    theta: Vec<f64>,
    updates: u64,
}

impl ScalarRls {
    /// `p = p0`, `θ = 0`; validation as [`Rls::new`].
    pub fn new(n_params: usize, lambda: f64, p0: f64) -> Result<Self> {
        validate(n_params, lambda, p0)?;
        Ok(Self {
            n: n_params,
            lambda,
            p0,
            p_max: p0,
            dead_zone: 0.0,
            p: p0,
            theta: vec![0.0; n_params],
            updates: 0,
        })
    }
    pub fn with_theta(mut self, theta: &[f64]) -> Self {
        self.set_theta(theta);
        self
    }
    /// Bound `p ≤ p_max` (default `p_max = p0`).
    pub fn with_covariance_bound(mut self, p_max: f64) -> Result<Self> {
        if !(p_max.is_finite() && p_max > 0.0) {
            return Err(Error::invalid(
                "p_max",
                format!("must be a finite number > 0, got {p_max}"),
            ));
        }
        self.p_max = p_max;
        self.p = self.p.min(p_max);
        Ok(self)
    }
    pub fn with_dead_zone(mut self, dead_zone: f64) -> Result<Self> {
        if !(dead_zone.is_finite() && dead_zone >= 0.0) {
            return Err(Error::invalid(
                "dead_zone",
                format!("must be a finite number >= 0, got {dead_zone}"),
            ));
        }
        self.dead_zone = dead_zone;
        Ok(self)
    }
    pub fn n_params(&self) -> usize {
        self.n
    }
    pub fn predict(&self, phi: &[f64]) -> f64 {
        dot(phi, &self.theta)
    }
    pub fn update(&mut self, phi: &[f64], y: f64) -> f64 {
        Estimator::update(self, phi, y)
    }
    pub fn update_with_error(&mut self, phi: &[f64], e: f64) -> bool {
        debug_assert_eq!(phi.len(), self.n);
        if !e.is_finite() || e.abs() <= self.dead_zone || unusable(phi) {
            return false;
        }
        let q = dot(phi, phi);
        let pq = self.p * q;
        if !pq.is_finite() {
            return false;
        }
        let denom = self.lambda + pq;
        let g = self.p / denom * e;
        if self.theta.iter().zip(phi).any(|(t, v)| !(t + g * v).is_finite()) {
            return false;
        }
        for (t, v) in self.theta.iter_mut().zip(phi) {
            *t += g * v;
        }
        let p = (self.p - self.p * pq / (self.n as f64 * denom)) / self.lambda;
        self.p = if p.is_finite() && p > 0.0 {
            p.min(self.p_max)
        } else {
            self.p0.min(self.p_max)
        };
        self.updates += 1;
        true
    }
    pub fn theta(&self) -> &[f64] {
        &self.theta
    }
    pub fn set_theta(&mut self, theta: &[f64]) {
        assert_eq!(
            theta.len(),
            self.n,
            "theta has {} entries, the estimator {}",
            theta.len(),
            self.n
        );
        self.theta.copy_from_slice(theta);
    }
    /// The scalar `p` of `P = p·I`.
    pub fn p(&self) -> f64 {
        self.p
    }
    pub fn covariance_trace(&self) -> f64 {
        self.p * self.n as f64
    }
    pub fn reset_covariance(&mut self) {
        self.p = self.p0.min(self.p_max);
    }
    pub fn updates(&self) -> u64 {
        self.updates
    }
}

impl Estimator for ScalarRls {
    fn n_params(&self) -> usize {
        self.n
    }
    fn predict(&self, phi: &[f64]) -> f64 {
        ScalarRls::predict(self, phi)
    }
    fn update_with_error(&mut self, phi: &[f64], e: f64) -> bool {
        ScalarRls::update_with_error(self, phi, e)
    }
    fn theta(&self) -> &[f64] {
        &self.theta
    }
    fn set_theta(&mut self, theta: &[f64]) {
        ScalarRls::set_theta(self, theta)
    }
    fn covariance_trace(&self) -> f64 {
        ScalarRls::covariance_trace(self)
    }
    fn reset_covariance(&mut self) {
        ScalarRls::reset_covariance(self)
    }
}
