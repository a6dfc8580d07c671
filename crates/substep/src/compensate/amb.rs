//! Adaptive model-based compensation AMB (after the model-based feed-forward of Fermandois 2019
//! on this benchmark and its adaptive / robust variants), in the sub-step convention of
//! [`super`] (docs/theory.md §6.9).
//!
//! The lab identifies its plant `G(s)` (command → measured displacement) off line, and the
//! feed-forward is the inverse of that model, truncated to a polynomial in `s`:
//!
//! ```text
//! 1/G(σ) = g₀ + g₁ σ + g₂ σ² + g₃ σ³ + O(σ⁴)        (σ = s Δτ, per sub-step)
//! u_j = c₀ d_j + c₁ D d_j + c₂ D² d_j + c₃ D³ d_j,     Δu_j = u_j − d_j,
//! D x_j = (x_j − x_{j−s})/s  (and its powers: backward differences of span s)
//! ```
//!
//! The backward difference is `D = (1 − e^{−sσ})/s = σ − sσ²/2 + s²σ³/6 − …`, so matching
//! `Σ cᵢ Dⁱ` to the series term by term gives the **model coefficients**
//!
//! ```text
//! c₀ = g₀,  c₁ = g₁,  c₂ = g₂ + c₁ s/2,  c₃ = g₃ + c₂ s − c₁ s²/6
//! ```
//!
//! (a pure delay of `L` sub-steps: `g = (1, L, L²/2, L³/6)`).
//!
//! **Adaptation**: the plant drifts from the model (specimen stiffness, oil temperature), so the
//! coefficients are re-identified on line, by recursive least squares with exponential
//! forgetting `λ` of the same equation-error form as [`super::Ats`] — the command sent against
//! the measured displacement and its differences, both through the low-pass `F`:
//!
//! ```text
//! F u_k ≈ Σ cᵢ Dⁱ F y_k,      cᵢ = θᵢ mᵢ   (mᵢ the model coefficients, θ = 1 at the start)
//! ```
//!
//! What makes it model-based and robust rather than ATS with one more term: the parameters are
//! the *ratios* `θᵢ` to the lab's model, each projected onto `[1 − r, 1 + r]` after every update
//! (a coefficient the model says is 0 is never adapted), the RLS covariance is capped at its
//! initial trace (no wind-up while the test is quiet), and adaptation starts once `|F y|`
//! exceeds a threshold. Allocation-free after construction.

use super::ats::Smoother;
use super::{Guard, GuardTrip, History, PhaseLagCompensator};
use crate::error::{Error, Result};
use crate::transfer::lti::TransferFunction;

/// Terms of the feed-forward: `d`, `Dd`, `D²d`, `D³d`.
const TERMS: usize = 4;

/// Configuration of [`Amb`]; lengths in sub-steps, displacements in m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmbSpec {
    /// The series `g₀ … g₃` of the plant model's inverse, `1/G(σ) = Σ gᵢ σⁱ` \[sub-stepsⁱ\]; the
    /// model coefficients `cᵢ` of the differences follow with the span
    /// ([`AmbSpec::model`]); a zero `cᵢ` is never adapted.
    pub series: [f64; TERMS],
    /// Span `s` of the differences \[sub-steps\].
    pub span: usize,
    /// Time constant of each of the two low-pass stages on the measured displacement and the
    /// command \[sub-steps\]; 0 = no filter.
    pub smoothing: f64,
    /// Adaptation starts once `|F y|` has exceeded this \[m\]; also the scale of the RLS rows.
    pub threshold: f64,
    /// RLS forgetting factor per row.
    pub lambda: f64,
    /// One RLS row every `subsample` sub-steps.
    pub subsample: usize,
    /// Relative band `r`: each adapted `θᵢ` stays within `[1 − r, 1 + r]`; 0 = the fixed model.
    pub deviation: f64,
    /// How many of the terms are adapted, from the lowest (`c₀`, then `c₁`, …); the others keep
    /// the model's value and their part is taken off the command before the fit.
    pub adapted_terms: usize,
    /// Initial RLS covariance of each `θᵢ` (and the cap on its trace, per adapted term).
    pub p0: f64,
    /// Instrumental variables: correlate the rows with the filtered *target* and its differences,
    /// delayed by the model's lag `round(g₁)`, instead of the measured displacement's own — the
    /// sensor noise in the regressors then biases nothing (plain RLS shrinks the lead).
    pub instruments: bool,
    /// Output guard factor ([`Guard`]).
    pub guard_factor: f64,
}

impl AmbSpec {
    /// The model with inverse series `g` (sub-step units; the coefficients of the differences
    /// follow from it, module docs) and the defaults: differences of span `s`, two low-pass
    /// stages of `s` sub-steps, threshold 0.1 mm, one RLS row every sub-step with `λ = 0.9995`
    /// (test definitions and the benchmark set `λ = 1 − Δτ / 2 s`, a memory of 2 s), `c₀` and
    /// `c₁` adapted within ±50 %, `p0 = 0.01`, instrumental variables. docs/theory.md §6.9
    /// gives the source of each.
    pub fn from_inverse_series(g: [f64; TERMS], span: usize) -> Self {
        Self {
            series: g,
            span,
            smoothing: span as f64,
            threshold: 1e-4,
            lambda: 0.9995,
            subsample: 1,
            deviation: 0.5,
            adapted_terms: 2,
            p0: 0.01,
            instruments: true,
            guard_factor: 10.0,
        }
    }

    /// A pure delay of `lead` sub-steps as the model (no identified plant available): the span
    /// is a third of the lead (at least 1).
    pub fn pure_delay(lead: f64) -> Self {
        let l = lead.max(0.0);
        Self::from_inverse_series([1.0, l, l * l / 2.0, l * l * l / 6.0], default_span(l))
    }

    /// The model of a plant `G` (continuous, seconds) at sub-step `dtau` \[s\]; `None` if its
    /// inverse has no power series at `s = 0` (a zero DC gain).
    pub fn from_plant(plant: &TransferFunction, dtau: f64) -> Option<Self> {
        let g = inverse_series(plant, dtau)?;
        Some(Self::from_inverse_series(g, default_span(g[1])))
    }

    /// The model coefficients `c₀ … c₃` of `u = Σ cᵢ Dⁱ d` \[sub-stepsⁱ\].
    pub fn model(&self) -> [f64; TERMS] {
        difference_coefficients(self.series, self.span as f64)
    }

    pub fn build(&self) -> Result<Amb> {
        Amb::new(*self)
    }
}

/// A third of the low-frequency lag `lag` \[sub-steps\], at least 1: the differences of a
/// third-order term over neighbouring sub-steps are mostly the noise of the measurement.
fn default_span(lag: f64) -> usize {
    if lag.is_finite() && lag > 3.0 {
        (lag / 3.0).round().min(4096.0) as usize
    } else {
        1
    }
}

/// `cᵢ` of `Σ cᵢ Dⁱ` from the series `gᵢ` of `Σ gᵢ σⁱ`, `D` the backward difference of span `s`.
pub fn difference_coefficients(g: [f64; TERMS], s: f64) -> [f64; TERMS] {
    let c1 = g[1];
    let c2 = g[2] + c1 * s / 2.0;
    let c3 = g[3] + c2 * s - c1 * s * s / 6.0;
    [g[0], c1, c2, c3]
}

/// The first four coefficients of the power series of `1/G(s)` at `s = 0`, in sub-step units
/// (`s = σ/Δτ`); `None` if `G(0) = 0` or a coefficient is not finite.
pub fn inverse_series(plant: &TransferFunction, dtau: f64) -> Option<[f64; TERMS]> {
    // Ascending powers: 1/G = den/num; divide the series den by num.
    let asc = |p: &[f64]| -> [f64; TERMS] {
        let mut out = [0.0; TERMS];
        for (i, v) in p.iter().rev().take(TERMS).enumerate() {
            out[i] = *v;
        }
        out
    };
    let (num, den) = (asc(plant.num()), asc(plant.den()));
    if num[0] == 0.0 {
        return None;
    }
    let mut q = [0.0; TERMS];
    for k in 0..TERMS {
        let mut r = den[k];
        for i in 1..=k {
            r -= num[i] * q[k - i];
        }
        q[k] = r / num[0];
    }
    let mut out = [0.0; TERMS];
    for (k, o) in out.iter_mut().enumerate() {
        *o = q[k] / dtau.powi(k as i32);
    }
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// `[x, Dx, D²x, D³x]` of the newest samples of `h`.
fn terms(h: &History, s: usize) -> [f64; TERMS] {
    terms_at(h, s, 0)
}

/// `[x, Dx, D²x, D³x]` of `h` as it was `age` pushes ago.
fn terms_at(h: &History, s: usize, age: usize) -> [f64; TERMS] {
    let x = |k: usize| h.get(age + k * s);
    let sf = s as f64;
    [
        x(0),
        (x(0) - x(1)) / sf,
        (x(0) - 2.0 * x(1) + x(2)) / (sf * sf),
        (x(0) - 3.0 * x(1) + 3.0 * x(2) - x(3)) / (sf * sf * sf),
    ]
}

/// The adaptive model-based compensator (see the module docs).
#[derive(Debug, Clone)]
pub struct Amb {
    spec: AmbSpec,
    /// The model coefficients ([`AmbSpec::model`]).
    model: [f64; TERMS],
    /// Ratios to the model.
    theta: [f64; TERMS],
    /// The coefficients in use, `θᵢ mᵢ`.
    c: [f64; TERMS],
    /// RLS covariance of `θ` (rows and columns of terms not adapted stay 0).
    p: [[f64; TERMS]; TERMS],
    p_trace_cap: f64,
    filter_y: Smoother,
    filter_u: Smoother,
    filter_d: Smoother,
    /// `F d`, newest first, `3 s + L + 1` samples (the instruments).
    fd: History,
    /// The instruments' delay `L` \[sub-steps\].
    instrument_delay: usize,
    fy: History,
    targets: History,
    last_sent: f64,
    calls: usize,
    adapting: bool,
    frozen: bool,
    guard: Guard,
}

impl Amb {
    pub fn new(spec: AmbSpec) -> Result<Self> {
        let bad = |key: &str, why: String| Err(Error::invalid(format!("phase_lag.{key}"), why));
        if spec.span == 0 || spec.span > 1 << 12 {
            return bad("span", format!("must be 1 to 4096 sub-steps, got {}", spec.span));
        }
        if let Some(v) = spec.series.iter().find(|v| !v.is_finite()) {
            return bad("inverse_series", format!("coefficient {v} is not finite"));
        }
        if spec.series[0] == 0.0 {
            return bad(
                "inverse_series",
                "g0 (the inverse of the plant's static gain) must not be 0".to_string(),
            );
        }
        let model = spec.model();
        if let Some(v) = model.iter().find(|v| !v.is_finite()) {
            return bad("inverse_series", format!("model coefficient {v} is not finite"));
        }
        if spec.subsample == 0 || spec.subsample > 1 << 16 {
            return bad(
                "subsample",
                format!("must be 1 to 65536 sub-steps, got {}", spec.subsample),
            );
        }
        if !(spec.smoothing.is_finite() && (0.0..=1e6).contains(&spec.smoothing)) {
            return bad(
                "smoothing",
                format!("must be 0 to 1e6 sub-steps, got {}", spec.smoothing),
            );
        }
        if !(spec.threshold.is_finite() && spec.threshold > 0.0) {
            return bad(
                "threshold",
                format!("must be a finite number > 0 m, got {}", spec.threshold),
            );
        }
        if !(spec.lambda > 0.5 && spec.lambda <= 1.0) {
            return bad("forgetting_factor", format!("must be in (0.5, 1], got {}", spec.lambda));
        }
        if !(spec.deviation.is_finite() && (0.0..=10.0).contains(&spec.deviation)) {
            return bad(
                "deviation",
                format!("must be 0 to 10 (relative to the model), got {}", spec.deviation),
            );
        }
        if spec.adapted_terms > TERMS {
            return bad(
                "adapted_terms",
                format!("must be 0 to {TERMS} (c0 … c3), got {}", spec.adapted_terms),
            );
        }
        if !(spec.p0.is_finite() && spec.p0 > 0.0) {
            return bad("p0", format!("must be a finite number > 0, got {}", spec.p0));
        }
        let instrument_delay = if spec.instruments {
            spec.series[1].round().clamp(0.0, 65536.0) as usize
        } else {
            0
        };
        let p = initial_covariance(&spec, &model);
        let adapted = (0..TERMS).filter(|&i| p[i][i] > 0.0).count();
        Ok(Self {
            spec,
            model,
            theta: [1.0; TERMS],
            c: model,
            p,
            p_trace_cap: spec.p0 * adapted as f64,
            filter_y: Smoother::new(spec.smoothing),
            filter_u: Smoother::new(spec.smoothing),
            filter_d: Smoother::new(spec.smoothing),
            fd: History::new(3 * spec.span + instrument_delay + 1),
            instrument_delay,
            fy: History::new(3 * spec.span + 1),
            targets: History::new(3 * spec.span + 1),
            last_sent: 0.0,
            calls: 0,
            adapting: false,
            frozen: false,
            guard: Guard::new(spec.guard_factor, 1e-6)?,
        })
    }

    /// `[c₀, c₁, c₂, c₃]` now.
    pub fn coefficients(&self) -> [f64; TERMS] {
        self.c
    }

    /// Whether the threshold has been reached (the coefficients adapt).
    pub fn is_adapting(&self) -> bool {
        self.adapting
    }

    /// One RLS row: `F u / scale ≈ Σ θᵢ (mᵢ Dⁱ F y / scale)`, with the instruments `z` (the
    /// regressors themselves for plain RLS): `k = P z / (λ + φᵀ P z)`, `P ← (P − k φᵀ P)/λ`.
    // Indices read as the matrix algebra they implement.
    #[allow(clippy::needless_range_loop)]
    fn update(&mut self, regressors: [f64; TERMS], instruments: [f64; TERMS], regressand: f64) {
        let scale = 1.0 / self.spec.threshold;
        let mut phi = [0.0; TERMS];
        let mut z = [0.0; TERMS];
        for i in 0..TERMS {
            phi[i] = regressors[i] * self.model[i] * scale;
            z[i] = if i < self.spec.adapted_terms {
                instruments[i] * self.model[i] * scale
            } else {
                0.0
            };
        }
        // The fixed terms' part of the command is not the fit's to explain.
        let fixed: f64 = (self.spec.adapted_terms..TERMS)
            .map(|i| self.c[i] * regressors[i])
            .sum();
        for p in phi.iter_mut().skip(self.spec.adapted_terms) {
            *p = 0.0;
        }
        let y = (regressand - fixed) * scale;
        // P z and φᵀ P (P is not symmetric with instruments).
        let mut p_z = [0.0; TERMS];
        let mut phi_p = [0.0; TERMS];
        for i in 0..TERMS {
            p_z[i] = (0..TERMS).map(|j| self.p[i][j] * z[j]).sum();
            phi_p[i] = (0..TERMS).map(|j| phi[j] * self.p[j][i]).sum();
        }
        let denom = self.spec.lambda + (0..TERMS).map(|i| phi[i] * p_z[i]).sum::<f64>();
        if !(denom.is_finite() && denom > 0.5 * self.spec.lambda) {
            return;
        }
        let err = y - (0..TERMS).map(|i| self.theta[i] * phi[i]).sum::<f64>();
        let r = self.spec.deviation;
        for i in 0..TERMS {
            let gain = p_z[i] / denom;
            self.theta[i] = (self.theta[i] + gain * err).clamp(1.0 - r, 1.0 + r);
        }
        let mut trace = 0.0;
        for i in 0..TERMS {
            for j in 0..TERMS {
                self.p[i][j] = (self.p[i][j] - p_z[i] * phi_p[j] / denom) / self.spec.lambda;
            }
            trace += self.p[i][i];
        }
        if !trace.is_finite() || trace <= 0.0 {
            self.reset_covariance();
        } else if trace > self.p_trace_cap {
            let shrink = self.p_trace_cap / trace;
            self.p.iter_mut().flatten().for_each(|v| *v *= shrink);
        }
        for i in 0..TERMS {
            self.c[i] = self.theta[i] * self.model[i];
        }
    }

    fn reset_covariance(&mut self) {
        self.p = initial_covariance(&self.spec, &self.model);
    }
}

/// `p0` on the diagonal of each adapted term (the lowest `adapted_terms` whose model coefficient
/// is not 0), 0 elsewhere: a row and column of zeros keeps its coefficient where it is.
fn initial_covariance(spec: &AmbSpec, model: &[f64; TERMS]) -> [[f64; TERMS]; TERMS] {
    let mut p = [[0.0; TERMS]; TERMS];
    for (i, row) in p.iter_mut().enumerate() {
        if i < spec.adapted_terms && model[i] != 0.0 && spec.deviation > 0.0 {
            row[i] = spec.p0;
        }
    }
    p
}

impl PhaseLagCompensator for Amb {
    fn correction(&mut self, target: f64, measured_prev: f64, h: f64) -> f64 {
        if !self.guard.admit(target, measured_prev) {
            return 0.0;
        }
        // The pair of the previous sub-step: the command sent then, the displacement it produced.
        let fy = self.filter_y.step(measured_prev);
        let fu = self.filter_u.step(self.last_sent);
        self.fy.push(fy);
        // F d_{j−1} is the newest in `fd` until the target of this call is pushed below.
        self.calls += 1;
        if !self.frozen {
            self.adapting |= fy.abs() > self.spec.threshold;
            if self.adapting && self.calls > 3 * self.spec.span && self.calls.is_multiple_of(self.spec.subsample) {
                let regressors = terms(&self.fy, self.spec.span);
                let instruments = if self.spec.instruments {
                    terms_at(&self.fd, self.spec.span, self.instrument_delay)
                } else {
                    regressors
                };
                self.update(regressors, instruments, fu);
            }
        }
        self.targets.push(target);
        if self.spec.instruments {
            self.fd.push(self.filter_d.step(target));
        }
        let d = terms(&self.targets, self.spec.span);
        let u: f64 = (0..TERMS).map(|i| self.c[i] * d[i]).sum();
        let du = self.guard.output(u - target, h);
        self.last_sent = target + h * du;
        du
    }
    fn kind(&self) -> &'static str {
        "amb"
    }
    fn is_adaptive(&self) -> bool {
        self.spec.deviation > 0.0 && self.spec.adapted_terms > 0
    }
    fn set_frozen(&mut self, frozen: bool) {
        self.frozen = frozen;
        self.guard.set_frozen(frozen);
    }
    fn trip(&self) -> Option<GuardTrip> {
        self.guard.trip()
    }
    fn parameters(&self) -> &[f64] {
        &self.c
    }
    fn set_parameters(&mut self, parameters: &[f64]) {
        if let [c0, c1, c2, c3] = *parameters {
            self.c = [c0, c1, c2, c3];
            for i in 0..TERMS {
                if self.model[i] != 0.0 {
                    self.theta[i] = self.c[i] / self.model[i];
                }
            }
        }
    }
    /// The targets `d_{j−1} … d_{j−3s}` (all a frozen AMB depends on: an FIR of the target).
    fn state_len(&self) -> usize {
        3 * self.spec.span
    }
    fn write_state(&self, out: &mut [f64]) {
        self.targets.write(out);
    }
    fn read_state(&mut self, s: &[f64]) {
        self.targets.read(s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::compensate::test_signals::broadband as target;

    #[test]
    fn the_inverse_series_of_known_plants() {
        // G = 1/(1 + T s): 1/G = 1 + T s, in sub-steps T/Δτ.
        let g = inverse_series(&TransferFunction::new("g", &[1.0], &[0.02, 1.0]).unwrap(), 1e-3).unwrap();
        assert_eq!(g, [1.0, 20.0, 0.0, 0.0]);
        // G = ω²/(s² + 2ζω s + ω²): 1/G = 1 + (2ζ/ω) s + s²/ω².
        let (w, z) = (2.0 * std::f64::consts::PI * 10.0, 0.7);
        let g = inverse_series(
            &TransferFunction::new("g", &[w * w], &[1.0, 2.0 * z * w, w * w]).unwrap(),
            1.0,
        )
        .unwrap();
        let want = [1.0, 2.0 * z / w, 1.0 / (w * w), 0.0];
        for i in 0..4 {
            assert!((g[i] - want[i]).abs() < 1e-15, "{g:?} vs {want:?}");
        }
        // A zero: G = (1 + a s)/(1 + b s): 1/G = (1 + b s)(1 − a s + a² s² − a³ s³ …).
        let (a, b) = (0.1, 0.3);
        let g = inverse_series(&TransferFunction::new("g", &[a, 1.0], &[b, 1.0]).unwrap(), 1.0).unwrap();
        let want = [1.0, b - a, a * a - a * b, -a * a * a + a * a * b];
        for i in 0..4 {
            assert!((g[i] - want[i]).abs() < 1e-15, "{g:?} vs {want:?}");
        }
        assert!(inverse_series(&TransferFunction::new("g", &[1.0, 0.0], &[1.0, 1.0]).unwrap(), 1.0).is_none());
    }

    /// `Σ cᵢ Dⁱ` equals `1/G` to third order: applied to `x = e^{σ t}` with small σ.
    #[test]
    fn difference_coefficients_match_the_series_to_third_order() {
        let (g, s) = ([1.0, 7.0, 30.0, 80.0], 3.0);
        let c = difference_coefficients(g, s);
        let remainder = |sigma: f64| {
            let d = (1.0 - (-s * sigma).exp()) / s;
            let lhs: f64 = (0..4).map(|i| c[i] * d.powi(i as i32)).sum();
            let rhs: f64 = (0..4).map(|i| g[i] * sigma.powi(i as i32)).sum();
            lhs - rhs
        };
        // O(σ⁴): halving σ divides the remainder by 16 (a wrong c₂ or c₃ leaves σ² or σ³).
        for sigma in [4e-3, 2e-3] {
            let ratio = remainder(sigma) / remainder(sigma / 2.0);
            assert!((ratio - 16.0).abs() < 0.5, "σ = {sigma}: ratio {ratio}");
        }
    }

    /// A plant defined by `u_j = Σ cᵢ Dⁱ y_j` (the exact inverse of the model form): from a
    /// model 30 % off, AMB identifies `c` (noise-free, no filter) and the tracking error
    /// vanishes.
    #[test]
    fn an_exact_model_plant_is_identified_from_a_wrong_start() {
        let truth = [1.05, 6.0, 14.0, 12.0];
        let span = 1;
        // The series whose difference coefficients at span 1 are 0.7 × truth.
        let c = truth.map(|v| v * 0.7);
        let series = [c[0], c[1], c[2] - c[1] / 2.0, c[3] - c[2] + c[1] / 6.0];
        let spec = AmbSpec {
            series,
            smoothing: 0.0,
            threshold: 1e-3,
            deviation: 0.9,
            lambda: 0.999,
            adapted_terms: 4,
            // The covariance cap must not bind: D³y is 10⁻⁵ of y here.
            p0: 1e6,
            ..AmbSpec::pure_delay(6.0)
        };
        let spec = AmbSpec { span, ..spec };
        let model = spec.model();
        for i in 0..4 {
            assert!((model[i] - c[i]).abs() < 1e-12 * c[i], "{model:?} vs {c:?}");
        }
        let mut amb = spec.build().unwrap();
        // y history newest first (y_k, y_{k−1}, y_{k−2}); solve Σ cᵢ Dⁱ y_new = u for y_new.
        let mut ys = [0.0f64; 3];
        let lead: f64 = truth.iter().sum();
        let mut y = 0.0;
        let mut err2 = 0.0;
        let n = 40_000;
        for j in 0..n {
            let d = target(j);
            let du = amb.correction(d, y, 1.0);
            let u = d + du;
            // u = c0 y + c1 (y − y1) + c2 (y − 2y1 + y2) + c3 (y − 3y1 + 3y2 − y3)
            let known =
                -truth[1] * ys[0] + truth[2] * (-2.0 * ys[0] + ys[1]) + truth[3] * (-3.0 * ys[0] + 3.0 * ys[1] - ys[2]);
            y = (u - known) / lead;
            ys = [y, ys[0], ys[1]];
            if j > n - 5000 {
                err2 += (d - y).powi(2);
            }
        }
        let c = amb.coefficients();
        for i in 0..4 {
            assert!((c[i] - truth[i]).abs() < 1e-6 * truth[i], "{c:?} vs {truth:?}");
        }
        // Model and plant agree: the plant is the model's exact inverse, so y follows d.
        let signal: f64 = ((n - 4999)..n).map(|j| target(j).powi(2)).sum();
        assert!(err2 < 1e-12 * signal, "{err2:e} vs {signal:e}");
    }

    #[test]
    fn a_pure_delay_is_tracked_with_the_delay_model() {
        for lead in [4usize, 12] {
            let mut line = std::collections::VecDeque::from(vec![0.0; lead]);
            let mut amb = AmbSpec::pure_delay(lead as f64).build().unwrap();
            let (mut y, mut e2, mut plain2) = (0.0, 0.0, 0.0);
            let n = 30_000;
            for j in 0..n {
                let d = target(j);
                let du = amb.correction(d, y, 1.0);
                line.push_back(d + du);
                y = line.pop_front().unwrap();
                if j > n / 2 {
                    e2 += (d - y).powi(2);
                    plain2 += (d - target(j - lead)).powi(2);
                }
            }
            assert!(amb.trip().is_none());
            assert!(e2 < plain2 / 100.0, "delay {lead}: {e2:e} vs {plain2:e}");
        }
    }

    #[test]
    fn bad_settings_name_the_key() {
        let err = |s: AmbSpec| s.build().unwrap_err().to_string();
        assert!(
            err(AmbSpec {
                series: [0.0, 1.0, 0.0, 0.0],
                ..AmbSpec::pure_delay(2.0)
            })
            .starts_with("phase_lag.inverse_series:")
        );
        assert!(
            err(AmbSpec {
                lambda: 1.5,
                ..AmbSpec::pure_delay(2.0)
            })
            .starts_with("phase_lag.forgetting_factor:")
        );
        assert!(
            err(AmbSpec {
                threshold: 0.0,
                ..AmbSpec::pure_delay(2.0)
            })
            .starts_with("phase_lag.threshold:")
        );
    }
}
