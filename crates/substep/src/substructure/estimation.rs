//! Error-force compensation by estimation (on-line identification, docs/theory.md §4.4).
//!
//! Per coupling DOF `m` an ARX model of the sub-step sequence of the measured force `f`, the
//! command `d` and the external load `w` on that DOF,
//!
//! ```text
//! f^{(j)} = Σ_{l=1}^{n_u} A_l f^{(j−l)} + Σ_{l=0}^{n_u} B_l d^{(j−l)} + Σ_{l=0}^{n_u} C_l w^{(j−l)}
//! ```
//!
//! is identified with [`Rls`] (forgetting factor `λ`) after every sub-step, from the DOF's own
//! history: a SISO model per coupling DOF (for `n_c > 1` the cross-coupling between DOFs is not
//! modelled; it enters the fit only through the correlation of the histories).
//!
//! At the last sub-step `k` the model predicts `f̂^{(k)}(d) = c₀ + B₀ d^{(k)}` (`c₀` the part known
//! from the history) and the last command is solved consistently with it,
//!
//! ```text
//! d^{(k)} = x̂_c + G_cc f̂^{(k)}(d^{(k)})   ⇔   (I − G_cc diag(B₀)) d^{(k)} = x̂_c + G_cc c₀
//! ```
//!
//! (SISO: `d = (x̂_c + G c₀)/(1 − G B₀)`); the step closes with `u = x̂ + G_{:,c} f̂^{(k)}`, the
//! error force is `e = f^{(k)} − f̂^{(k)}` and the compensation force of the next step is
//! `f_u = e` (P = 1). The plain algorithm with P = 1 is the same scheme with the zero-order
//! predictor `f̂^{(k)} = f^{(k−1)}`; the estimation replaces that predictor by the identified one.
//!
//! **Deviations from the dissertation's model (docs/theory.md §4.5), and why** (measured on the typical TMD system,
//! `tests/error_force_estimation.rs`):
//!
//! 1. *Load input `w`.* A specimen with its own mass (a TMD) responds to the absolute motion of
//!    its support, i.e. to `d` and to the ground motion; its force is not an ARX system of `d`
//!    alone, and without `w` the noise-free prediction is 2–20× worse. `w^{(j)}` is the external
//!    load `f_l` on the coupling DOF, linear over the sub-steps of a step (the ground acceleration
//!    the virtual specimen sees, times `−m ι` of the DOF); it is known to the controller.
//! 2. *Difference basis.* At sub-step rate successive samples are nearly collinear (a 1 Hz signal
//!    changes by 1.6 % per 2.5 ms sub-step) and RLS with forgetting cannot resolve the shift form.
//!    The regressor holds the backward differences instead,
//!    `[Δ^m f^{(j−1)}]_{m<n} ∪ [Δ^m d^{(j)}]_{m≤n} ∪ [Δ^m w^{(j)}]_{m≤n}` — the same span, so the same
//!    model class — each entry divided by its running RMS (forgetting [`SCALE_FORGETTING`]) and the
//!    target by that of `f`; the estimator is rescaled ([`Rls::rescale`]) as the scales move, so
//!    the model itself does not change. This keeps `p0` meaningful in any unit.
//! 3. *Regularised forgetting.* In closed loop the command carries the previous force
//!    (`d^{(j)} = … + G f^{(j−1)}`), so with force noise the high differences of `d` and `f` are
//!    nearly collinear noise; orders ≥ 8 then identified garbage and were worse than the plain
//!    algorithm. One parameter per sub-step gets a pseudo-measurement pulling it towards the
//!    zero-order predictor (`A_1 = 1`, all else 0) with weight [`RIDGE`] (in normalised samples,
//!    [`Rls::regularize`]), a ridge that forgetting does not erase. It costs little noise-free
//!    accuracy and makes every order 2…12 better than the plain algorithm with 1 % noise.
//!
//! Guards (a step that fails one is closed with the plain algorithm, `f̂^{(k)} = f^{(k−1)}`, and
//! counted in [`EstimationStats`]):
//!
//! * **warm-up**: the model has seen at least 10 samples per parameter and its recent one-step
//!   prediction error is small: the exponentially weighted (weight `λ`, at most
//!   [`MAX_ERROR_FORGETTING`]) mean square of the
//!   a-priori error is below [`ACCEPT_RATIO`] times that of the zero-order predictor
//!   `f^{(j)} − f^{(j−1)}` that the plain algorithm uses — the estimate is used only where it
//!   predicts better than the plain algorithm;
//! * **ill-conditioned**: the smallest pivot of `I − G_cc diag(B₀)` (SISO: `|1 − G B₀|`) is below
//!   [`MIN_PIVOT`];
//! * **implausible**: a non-finite prediction or command, or `|f̂^{(k)} − f^{(k−1)}|` larger than
//!   [`PLAUSIBLE_FACTOR`] × the RMS zero-order prediction error (the recent size of a sub-step's
//!   force change).
//!
//! Everything is sized at construction; the per-sub-step path does not allocate.

use crate::error::Result;
use crate::ident::Rls;
use nalgebra::{DMatrix, DVector};

/// The estimate is used when its mean-square one-step error is below this fraction of the
/// zero-order predictor's.
pub const ACCEPT_RATIO: f64 = 1.0;
/// Smallest admissible pivot of `I − G_cc diag(B₀)` (SISO: `|1 − G B₀|`); below it a model error
/// would be amplified more than 1/MIN_PIVOT-fold in the command.
pub const MIN_PIVOT: f64 = 0.1;
/// Largest admissible `|f̂^{(k)} − f^{(k−1)}|` in units of the RMS zero-order prediction error.
pub const PLAUSIBLE_FACTOR: f64 = 10.0;
/// Upper bound of the weight of the running mean-square prediction errors (they use `λ`, so
/// that with `λ = 1` they still follow the recent past).
pub const MAX_ERROR_FORGETTING: f64 = 0.995;
/// Forgetting factor of the running RMS that scales the regressor entries.
pub const SCALE_FORGETTING: f64 = 0.999;
/// Weight of the ridge towards the zero-order predictor, in samples of a normalised regressor.
pub const RIDGE: f64 = 1e-3;

/// How the last step was closed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EstimationOutcome {
    /// With the estimate `f̂^{(k)}`.
    Estimated,
    /// Plain algorithm: the model is still warming up or predicts worse than the plain algorithm.
    WarmUp,
    /// Plain algorithm: `I − G_cc diag(B₀)` is nearly singular.
    IllConditioned,
    /// Plain algorithm: the prediction or the command was non-finite or implausibly large.
    Implausible,
}

/// Counts of the steps by [`EstimationOutcome`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EstimationStats {
    pub steps: u64,
    pub estimated: u64,
    pub warm_up: u64,
    pub ill_conditioned: u64,
    pub implausible: u64,
}

impl EstimationStats {
    /// Steps closed with the plain algorithm.
    pub fn fallbacks(&self) -> u64 {
        self.warm_up + self.ill_conditioned + self.implausible
    }
    /// Steps that fell back after the model had once been used (ill-conditioned or implausible).
    pub fn guard_fallbacks(&self) -> u64 {
        self.ill_conditioned + self.implausible
    }
}

/// The model of one coupling DOF; see the [module docs](self) for the regressor, the scaling
/// and the regularisation.
#[derive(Debug, Clone)]
struct DofModel {
    n: usize,
    with_load: bool,
    rls: Rls,
    /// Newest first: `f^{(j−1)} … f^{(j−n)}`, and the noise-free forces `f°^{(j−1)} …`.
    fhist: Vec<f64>,
    ftrue: Vec<f64>,
    /// Newest first, with a free slot 0 for the current sample: `[d^{(j)}, d^{(j−1)} … d^{(j−n)}]`.
    d: Vec<f64>,
    w: Vec<f64>,
    /// The measured `f^{(j−1)}` (zero-order predictor).
    f_prev: f64,
    /// Binomial coefficients with sign: `binom[m][i] = (−1)^i C(m, i)`, row length n + 1.
    binom: Vec<f64>,
    /// Raw regressor, scales per entry, normalised regressor, rescale factors.
    raw: Vec<f64>,
    scale: Vec<f64>,
    phi: Vec<f64>,
    factors: Vec<f64>,
    s_f: f64,
    /// Running mean squares of the regressor entries and of the force (for the scales).
    ms: Vec<f64>,
    ms_f: f64,
    mse_model: f64,
    mse_zoh: f64,
    samples: u64,
    /// Prediction of the coming sample as `c0 + b0 d` (b0 in N/m).
    c0: f64,
    b0: f64,
    /// The noise-free counterpart of the last a-priori prediction.
    ideal_prediction: f64,
}

impl DofModel {
    fn new(n: usize, lambda: f64, p0: f64, with_load: bool) -> Result<Self> {
        let np = 2 * n + 1 + with_load as usize * (n + 1);
        let w = n + 1;
        let mut binom = vec![0.0; w * w];
        for m in 0..w {
            let mut c = 1.0;
            for i in 0..=m {
                binom[m * w + i] = if i % 2 == 0 { c } else { -c };
                c = c * (m - i) as f64 / (i + 1) as f64;
            }
        }
        Ok(Self {
            n,
            with_load,
            rls: Rls::new(np, lambda, p0)?,
            fhist: vec![0.0; n],
            ftrue: vec![0.0; n],
            d: vec![0.0; n + 1],
            w: vec![0.0; n + 1],
            f_prev: 0.0,
            binom,
            raw: vec![0.0; np],
            scale: vec![0.0; np],
            phi: vec![0.0; np],
            factors: vec![1.0; np],
            s_f: 0.0,
            ms: vec![0.0; np],
            ms_f: 0.0,
            mse_model: 0.0,
            mse_zoh: 0.0,
            samples: 0,
            c0: 0.0,
            b0: 0.0,
            ideal_prediction: f64::NAN,
        })
    }

    /// `Σ_i binom[m][i] h[i]`.
    fn diff(&self, m: usize, h: &[f64]) -> f64 {
        let row = &self.binom[m * (self.n + 1)..];
        (0..=m).map(|i| row[i] * h[i]).sum()
    }

    /// The raw regressor for the force history `hist` and the inputs in `self.d`, `self.w`
    /// (slot 0 = the current sample).
    fn fill_raw(&mut self, use_true: bool) {
        let n = self.n;
        for m in 0..n {
            let hist = if use_true { &self.ftrue } else { &self.fhist };
            self.raw[m] = self.diff(m, hist);
        }
        for m in 0..=n {
            self.raw[n + m] = self.diff(m, &self.d);
        }
        if self.with_load {
            for m in 0..=n {
                self.raw[2 * n + 1 + m] = self.diff(m, &self.w);
            }
        }
    }

    /// `Σ θ_i raw_i / scale_i · s_f` (the model's prediction in N).
    fn predict_raw(&self) -> f64 {
        let th = self.rls.theta();
        let p: f64 = th
            .iter()
            .zip(&self.raw)
            .zip(&self.scale)
            .filter(|(_, s)| **s > 0.0)
            .map(|((t, r), s)| t * r / s)
            .sum();
        p * self.s_f
    }

    /// `∂f̂/∂d^{(j)}` [N/m]: `d^{(j)}` enters every `Δ^m d^{(j)}` with coefficient 1.
    fn input_gain(&self) -> f64 {
        let (n, th) = (self.n, self.rls.theta());
        let mut g = 0.0;
        for m in 0..=n {
            if self.scale[n + m] > 0.0 {
                g += th[n + m] / self.scale[n + m];
            }
        }
        g * self.s_f
    }

    /// `c0`, `b0` of the coming sample, whose load input is `w`.
    fn prepare(&mut self, w: f64) {
        self.d[0] = 0.0;
        self.w[0] = if self.with_load && w.is_finite() { w } else { 0.0 };
        self.fill_raw(false);
        self.c0 = self.predict_raw();
        self.b0 = self.input_gain();
    }

    fn ready(&self, warmup: u64) -> bool {
        self.samples >= warmup
            && self.mse_zoh > 0.0
            && self.mse_model.is_finite()
            && self.mse_model < ACCEPT_RATIO * self.mse_zoh
    }

    /// Sample `j`: command `d`, load input `w`, measured force `f`, optionally the noise-free one.
    fn observe(&mut self, d: f64, w: f64, f: f64, f_true: Option<f64>) {
        let n = self.n;
        self.d[0] = if d.is_finite() { d } else { self.d[1] };
        self.w[0] = if self.with_load && w.is_finite() { w } else { 0.0 };
        self.ideal_prediction = if f_true.is_some() {
            self.fill_raw(true);
            self.predict_raw()
        } else {
            f64::NAN
        };
        self.fill_raw(false);
        let predicted = self.predict_raw();
        let usable = f.is_finite() && d.is_finite() && predicted.is_finite();
        if usable {
            if self.samples > 0 {
                let lw = self.rls.forgetting_factor().min(MAX_ERROR_FORGETTING);
                let (em, ez) = (f - predicted, f - self.f_prev);
                self.mse_model = lw * self.mse_model + (1.0 - lw) * em * em;
                self.mse_zoh = lw * self.mse_zoh + (1.0 - lw) * ez * ez;
            }
            // Update the scales (running RMS); rescale the estimator so that the model does not
            // change.
            let ls = SCALE_FORGETTING;
            let ms_f = if self.ms_f > 0.0 {
                ls * self.ms_f + (1.0 - ls) * f * f
            } else {
                f * f
            };
            let s_f = ms_f.sqrt();
            self.ms_f = ms_f;
            for i in 0..self.raw.len() {
                let r2 = self.raw[i] * self.raw[i];
                self.ms[i] = if self.ms[i] > 0.0 {
                    ls * self.ms[i] + (1.0 - ls) * r2
                } else {
                    r2
                };
                let s = self.ms[i].sqrt();
                // θ_i multiplies raw_i·s_f/scale_i: keep θ_i·s_f/scale_i fixed.
                self.factors[i] = if self.scale[i] > 0.0 && s > 0.0 && s_f > 0.0 && self.s_f > 0.0 {
                    (s / self.scale[i]) * (self.s_f / s_f)
                } else {
                    1.0
                };
                self.scale[i] = s;
            }
            self.rls.rescale(&self.factors);
            self.s_f = s_f;
            if s_f > 0.0 {
                for i in 0..self.raw.len() {
                    self.phi[i] = if self.scale[i] > 0.0 {
                        self.raw[i] / self.scale[i]
                    } else {
                        0.0
                    };
                }
                self.rls.update(&self.phi, f / s_f);
                // Regularised forgetting: one parameter per sample is pulled towards the
                // zero-order predictor (A_1 = 1, everything else 0).
                let np = self.raw.len();
                let i = (self.samples % np as u64) as usize;
                let lw = self.rls.forgetting_factor();
                let prior = if i == 0 && self.scale[0] > 0.0 {
                    self.scale[0] / s_f
                } else {
                    0.0
                };
                self.rls.regularize(i, RIDGE * np as f64 * (1.0 - lw), prior);
            }
            self.samples += 1;
        }
        let fhist = if f.is_finite() { f } else { self.fhist[0] };
        let ftrue = match f_true {
            Some(ft) if ft.is_finite() => ft,
            _ => self.ftrue[0],
        };
        if n > 1 {
            self.fhist.copy_within(0..n - 1, 1);
            self.ftrue.copy_within(0..n - 1, 1);
        }
        self.fhist[0] = fhist;
        self.ftrue[0] = ftrue;
        self.d.copy_within(0..n, 1);
        self.w.copy_within(0..n, 1);
        if f.is_finite() {
            self.f_prev = f;
        }
    }

    /// `[A_1 … A_n, B_0 … B_n (N/m), C_0 … C_n]` of the shift form.
    fn shift_parameters(&self, out: &mut [f64]) {
        let (n, th) = (self.n, self.rls.theta());
        let w = n + 1;
        out.iter_mut().for_each(|v| *v = 0.0);
        let coef = |i: usize| {
            if self.scale[i] > 0.0 {
                th[i] / self.scale[i] * self.s_f
            } else {
                0.0
            }
        };
        // Δ^m f^{(j−1)} = Σ_i binom[m][i] f^{(j−1−i)} → A_{1+i}.
        for m in 0..n {
            let c = coef(m);
            for (o, b) in out[..=m].iter_mut().zip(&self.binom[m * w..]) {
                *o += c * b;
            }
        }
        let blocks = if self.with_load { 2 } else { 1 };
        for blk in 0..blocks {
            let at = n + blk * w;
            for m in 0..=n {
                let c = coef(at + m);
                for (o, b) in out[at..=at + m].iter_mut().zip(&self.binom[m * w..]) {
                    *o += c * b;
                }
            }
        }
    }
}

/// The estimators of all coupling DOFs and the consistent solve of the last command.
#[derive(Debug, Clone)]
pub(crate) struct ForceEstimation {
    dofs: Vec<DofModel>,
    warmup: u64,
    /// Scratch for the `n_c × n_c` solve (row-major) and its right-hand side.
    mat: Vec<f64>,
    rhs: Vec<f64>,
    /// `f̂^{(k)}` of the current step, and whether the last command used it.
    pub(crate) closing: Vec<f64>,
    pub(crate) active: bool,
    pub(crate) outcome: EstimationOutcome,
    pub(crate) stats: EstimationStats,
}

impl ForceEstimation {
    /// One model per row of `gain_cc` (`G_cc`).
    pub(crate) fn new(order: usize, lambda: f64, p0: f64, gain_cc: &DMatrix<f64>) -> Result<Self> {
        let n_c = gain_cc.nrows();
        let dofs = (0..n_c)
            .map(|_| DofModel::new(order, lambda, p0, true))
            .collect::<Result<Vec<_>>>()?;
        let warmup = 10 * dofs.first().map_or(1, |m| m.rls.n_params()) as u64;
        Ok(Self {
            dofs,
            warmup,
            mat: vec![0.0; n_c * n_c],
            rhs: vec![0.0; n_c],
            closing: vec![0.0; n_c],
            active: false,
            outcome: EstimationOutcome::WarmUp,
            stats: EstimationStats::default(),
        })
    }

    /// The last command of a step: if the models are ready, solve
    /// `(I − G_cc diag(B₀)) d = x̂_c + G_cc c₀` into `command`, set `closing = f̂^{(k)}` and return
    /// `true`; otherwise leave `command` alone and return `false` (plain algorithm).
    pub(crate) fn last_command(
        &mut self,
        predictor_c: &DVector<f64>,
        load_c: &[f64],
        gain_cc: &DMatrix<f64>,
        force_last: &DVector<f64>,
        command: &mut DVector<f64>,
    ) -> bool {
        let n_c = self.dofs.len();
        self.active = false;
        for (m, &w) in self.dofs.iter_mut().zip(load_c) {
            m.prepare(w);
        }
        if !self.dofs.iter().all(|m| m.ready(self.warmup)) {
            self.outcome = EstimationOutcome::WarmUp;
            return false;
        }
        // A = I − G diag(b0/g), rhs = x̂ + G c0.
        for r in 0..n_c {
            let mut acc = predictor_c[r];
            for c in 0..n_c {
                let gm = gain_cc[(r, c)];
                let m = &self.dofs[c];
                acc += gm * m.c0;
                self.mat[r * n_c + c] = (r == c) as u8 as f64 - gm * m.b0;
            }
            self.rhs[r] = acc;
        }
        if !solve_in_place(&mut self.mat, &mut self.rhs, n_c, MIN_PIVOT) {
            self.outcome = EstimationOutcome::IllConditioned;
            return false;
        }
        for (c, m) in self.dofs.iter().enumerate() {
            let d = self.rhs[c];
            let f_hat = m.c0 + m.b0 * d;
            let limit = PLAUSIBLE_FACTOR * m.mse_zoh.sqrt();
            if !(d.is_finite() && f_hat.is_finite()) || (f_hat - force_last[c]).abs() > limit {
                self.outcome = EstimationOutcome::Implausible;
                return false;
            }
            self.closing[c] = f_hat;
        }
        command.copy_from_slice(&self.rhs);
        self.active = true;
        self.outcome = EstimationOutcome::Estimated;
        true
    }

    pub(crate) fn n_params(&self) -> usize {
        self.dofs[0].rls.n_params()
    }

    /// Sub-step sample of coupling DOF `m`.
    pub(crate) fn observe(&mut self, m: usize, d: f64, w: f64, f: f64, f_true: Option<f64>) {
        self.dofs[m].observe(d, w, f, f_true);
    }

    /// The noise-free counterpart of the last a-priori prediction of DOF `m` (NaN without true
    /// forces).
    pub(crate) fn ideal_prediction(&self, m: usize) -> f64 {
        self.dofs[m].ideal_prediction
    }

    pub(crate) fn count_step(&mut self) {
        let s = &mut self.stats;
        s.steps += 1;
        match self.outcome {
            EstimationOutcome::Estimated => s.estimated += 1,
            EstimationOutcome::WarmUp => s.warm_up += 1,
            EstimationOutcome::IllConditioned => s.ill_conditioned += 1,
            EstimationOutcome::Implausible => s.implausible += 1,
        }
    }

    /// `[A_1 … A_n, B_0 … B_n]` of DOF `m` with `B` in N/m.
    pub(crate) fn parameters(&self, m: usize, out: &mut [f64]) {
        self.dofs[m].shift_parameters(out);
    }
}

/// Solve `A x = b` in place (`A` row-major `n × n`, overwritten; `b` becomes `x`) by Gaussian
/// elimination with partial pivoting. Returns `false` if a pivot is smaller than `min_pivot`
/// (relative to the largest row entry of `A`, at least 1).
fn solve_in_place(a: &mut [f64], b: &mut [f64], n: usize, min_pivot: f64) -> bool {
    let norm = a.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    for col in 0..n {
        let (mut p, mut best) = (col, a[col * n + col].abs());
        for r in col + 1..n {
            if a[r * n + col].abs() > best {
                p = r;
                best = a[r * n + col].abs();
            }
        }
        if !(best.is_finite() && best >= min_pivot * norm) {
            return false;
        }
        if p != col {
            for c in 0..n {
                a.swap(p * n + c, col * n + c);
            }
            b.swap(p, col);
        }
        let piv = a[col * n + col];
        for r in col + 1..n {
            let f = a[r * n + col] / piv;
            if f != 0.0 {
                for c in col..n {
                    a[r * n + c] -= f * a[col * n + c];
                }
                b[r] -= f * b[col];
            }
        }
    }
    for col in (0..n).rev() {
        let mut acc = b[col];
        for c in col + 1..n {
            acc -= a[col * n + c] * b[c];
        }
        b[col] = acc / a[col * n + col];
    }
    b.iter().all(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_solve_matches_and_refuses_singular() {
        let mut a = vec![0.0, 2.0, 1.0, 1.0];
        let mut b = vec![4.0, 3.0];
        assert!(solve_in_place(&mut a, &mut b, 2, 1e-12));
        assert!((b[0] - 1.0).abs() < 1e-12 && (b[1] - 2.0).abs() < 1e-12, "{b:?}");
        let mut a = vec![1.0, 2.0, 2.0, 4.0];
        let mut b = vec![1.0, 2.0];
        assert!(!solve_in_place(&mut a, &mut b, 2, 0.1));
    }

    #[test]
    fn arx_model_learns_a_known_system() {
        // f_j = 1.5 f_{j−1} − 0.6 f_{j−2} + 0.2 x_j − 0.1 x_{j−1}, persistent input.
        let mut m = DofModel::new(2, 1.0, 100.0, false).unwrap();
        let (mut f1, mut f2, mut x1) = (0.0, 0.0, 0.0);
        for j in 0..400 {
            let x = (0.37 * j as f64).sin() + (0.11 * j as f64).cos();
            let f = 1.5 * f1 - 0.6 * f2 + 0.2 * x - 0.1 * x1;
            m.observe(x, 0.0, f, None);
            (f2, f1, x1) = (f1, f, x);
        }
        let mut th = vec![0.0; 5];
        m.shift_parameters(&mut th);
        assert!((th[0] - 1.5).abs() < 2e-2 && (th[1] + 0.6).abs() < 2e-2, "{th:?}");
        assert!((th[2] - 0.2).abs() < 2e-2 && (th[3] + 0.1).abs() < 2e-2, "{th:?}");
        assert!(m.ready(50));
    }
}
