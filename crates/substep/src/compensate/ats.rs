//! The adaptive time-series compensator ATS (Chae, Kazemibidokhti & Ricles 2013), as labs run
//! it, in the sub-step convention of [`super`] (docs/theory.md §6.8).
//!
//! The command is a feed-forward of the target and its derivatives,
//!
//! ```text
//! u_j = a₀ d_j + a₁ D d_j + a₂ D² d_j,     Δu_j = u_j − d_j,
//! D x_j = (x_j − x_{j−s})/s,  D² x_j = (x_j − 2 x_{j−s} + x_{j−2s})/s²   (per sub-step)
//! ```
//!
//! with the difference span `s` (1: neighbouring sub-steps; more where the sub-steps are so
//! short that a second difference of neighbours is mostly the noise of the signal).
//!
//! so `a₁` is a lead in sub-steps (`a₁ Δτ` in seconds) and `a₂` in sub-steps². The coefficients
//! are the least-squares fit of the **command sent** on the **measured** displacement and its
//! derivatives, both through the same low-pass filter `F`:
//!
//! ```text
//! F u_k ≈ a₀ F y_k + a₁ D F y_k + a₂ D² F y_k      over the last `window` sub-steps,
//!                                                   one row every `subsample` sub-steps
//! ```
//!
//! i.e. the fitted filter maps what the actuator did onto what it was told, an inverse of the
//! actuator; applied to the target it gives the command that makes the actuator follow the
//! target. For a pure delay of `L` sub-steps `a₁ → L`, `a₂ → L²/2 + L s/2` (the backward
//! difference's lag of half a span); for a first-order lag `ẏ = (u − y)/T` held over each sub-step
//! and `s = 1` the fit is exact, `a₀ = 1`, `a₁ = p/(1 − p)`, `a₂ = 0`, `p = e^{−Δτ/T}`
//! (`a₁ ≈ T/Δτ − ½`).
//!
//! Safeguards as in the lab implementations: adaptation starts only once the filtered measured
//! displacement has exceeded `threshold`; each update moves a coefficient by at most its rate
//! limit; the coefficients stay within bounds; the normal equations are solved with the columns
//! scaled to unit RMS and a small ridge, so a narrow-band signal (where `D²y ≈ −ω² y` makes the
//! columns collinear) leaves the estimate where it was instead of throwing it away. The
//! window's sums are kept running (added and removed row by row) and recomputed from the stored
//! rows once per window, so rounding does not accumulate. Allocation-free after construction.

use super::{Guard, GuardTrip, History, PhaseLagCompensator};
use crate::error::{Error, Result};

/// Configuration of [`Ats`]; lengths in sub-steps, displacements in m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AtsSpec {
    /// The expected actuator delay in sub-steps: the initial `a₁`; `a₂` starts at `a₁²/2`, `a₀`
    /// at 1 (Chae et al. 2013).
    pub initial_lead: f64,
    /// Sub-steps in the moving least-squares window.
    pub window: usize,
    /// One regression row every `subsample` sub-steps (and one update of the coefficients).
    pub subsample: usize,
    /// Span `s` of the differences \[sub-steps\].
    pub span: usize,
    /// Time constant of each of the two first-order low-pass stages on the measured
    /// displacement and the command \[sub-steps\]; 0 = no filter.
    pub smoothing: f64,
    /// Adaptation starts once `|F y|` has exceeded this \[m\].
    pub threshold: f64,
    /// Largest change of `a₀`, `a₁`, `a₂` per update.
    pub rate_limits: [f64; 3],
    /// Bounds `[min, max]` of `a₀`, `a₁`, `a₂`.
    pub bounds: [[f64; 2]; 3],
    /// Output guard factor ([`Guard`]).
    pub guard_factor: f64,
}

impl AtsSpec {
    /// Defaults for an expected delay of `initial_lead` sub-steps (docs/theory.md §6.8 gives the
    /// source of each): window 1000 sub-steps with a row every 4, differences of neighbouring
    /// sub-steps, a low-pass of `L₀/2` sub-steps per stage on both signals, threshold
    /// 0.1 mm, rate limits `[0.01, 0.02 L₀ + 0.01, 0.02 L₀² + 0.01]` per update, bounds
    /// `a₀ ∈ [0.5, 2]`, `a₁ ∈ [0, 4 L₀ + 4]`, `a₂ ∈ [−(4 L₀ + 4)², (4 L₀ + 4)²]`.
    pub fn new(initial_lead: f64) -> Self {
        let l = initial_lead.max(0.0);
        let span = 4.0 * l + 4.0;
        Self {
            initial_lead,
            window: 1000,
            subsample: 4,
            span: 1,
            smoothing: l / 2.0,
            threshold: 1e-4,
            rate_limits: [0.01, 0.02 * l + 0.01, 0.02 * l * l + 0.01],
            bounds: [[0.5, 2.0], [0.0, span], [-span * span, span * span]],
            guard_factor: 10.0,
        }
    }

    pub fn build(&self) -> Result<Ats> {
        Ats::new(*self)
    }
}

/// Two cascaded first-order low-pass stages `x ← x + α (input − x)`, `α = 1/(1 + T)`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Smoother {
    alpha: f64,
    stage: [f64; 2],
}

impl Smoother {
    pub(super) fn new(time_constant: f64) -> Self {
        Self {
            alpha: 1.0 / (1.0 + time_constant),
            stage: [0.0; 2],
        }
    }
    pub(super) fn step(&mut self, x: f64) -> f64 {
        self.stage[0] += self.alpha * (x - self.stage[0]);
        self.stage[1] += self.alpha * (self.stage[0] - self.stage[1]);
        self.stage[1]
    }
}

/// `(D x, D² x)` over span `s` of the newest samples of `h` (per sub-step).
pub(super) fn differences(h: &History, s: usize) -> (f64, f64) {
    let (x0, x1, x2) = (h.get(0), h.get(s), h.get(2 * s));
    let s = s as f64;
    ((x0 - x1) / s, (x0 - 2.0 * x1 + x2) / (s * s))
}

/// The adaptive time-series compensator (see the module docs).
#[derive(Debug, Clone)]
pub struct Ats {
    spec: AtsSpec,
    a: [f64; 3],
    /// Regression rows `[F y, D F y, D² F y, F u]`, a ring of `rows.len() / 4` rows.
    rows: Vec<f64>,
    next_row: usize,
    stored: usize,
    /// Running `XᵀX` (upper triangle, row-major 3×3) and `Xᵀu`.
    xtx: [f64; 9],
    xtu: [f64; 3],
    rows_since_recompute: usize,
    filter_y: Smoother,
    filter_u: Smoother,
    /// `F y` and `d`, newest first (3 samples each).
    fy: History,
    targets: History,
    /// The command sent in the previous call, `d + h Δu`.
    last_sent: f64,
    calls: usize,
    adapting: bool,
    frozen: bool,
    guard: Guard,
}

impl Ats {
    pub fn new(spec: AtsSpec) -> Result<Self> {
        let bad = |key: &str, why: String| Err(Error::invalid(format!("phase_lag.{key}"), why));
        if !(spec.initial_lead.is_finite() && spec.initial_lead >= 0.0) {
            return bad(
                "initial_lead",
                format!("must be a finite number of sub-steps >= 0, got {}", spec.initial_lead),
            );
        }
        if spec.span == 0 || spec.span > 1 << 12 {
            return bad("span", format!("must be 1 to 4096 sub-steps, got {}", spec.span));
        }
        if spec.subsample == 0 || spec.subsample > 1 << 16 {
            return bad(
                "subsample",
                format!("must be 1 to 65536 sub-steps, got {}", spec.subsample),
            );
        }
        let n_rows = spec.window / spec.subsample;
        if n_rows < 8 || spec.window > 1 << 22 {
            return bad(
                "window",
                format!(
                    "must hold at least 8 rows (window / subsample) and at most 4194304 sub-steps, got {} sub-steps / {}",
                    spec.window, spec.subsample
                ),
            );
        }
        if !(spec.smoothing.is_finite() && (0.0..=1e6).contains(&spec.smoothing)) {
            return bad(
                "smoothing",
                format!("must be 0 to 1e6 sub-steps, got {}", spec.smoothing),
            );
        }
        if !(spec.threshold.is_finite() && spec.threshold >= 0.0) {
            return bad(
                "threshold",
                format!("must be a finite number >= 0 m, got {}", spec.threshold),
            );
        }
        for (i, r) in spec.rate_limits.iter().enumerate() {
            if !(r.is_finite() && *r > 0.0) {
                return bad("rate_limits", format!("a{i}: must be a finite number > 0, got {r}"));
            }
        }
        let start = [1.0, spec.initial_lead, spec.initial_lead * spec.initial_lead / 2.0];
        for (i, [lo, hi]) in spec.bounds.iter().enumerate() {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return bad("bounds", format!("a{i}: needs finite min <= max, got [{lo}, {hi}]"));
            }
            if !(*lo..=*hi).contains(&start[i]) {
                return bad(
                    "bounds",
                    format!("a{i}: [{lo}, {hi}] does not contain its initial value {}", start[i]),
                );
            }
        }
        Ok(Self {
            spec,
            a: start,
            rows: vec![0.0; 4 * n_rows],
            next_row: 0,
            stored: 0,
            xtx: [0.0; 9],
            xtu: [0.0; 3],
            rows_since_recompute: 0,
            filter_y: Smoother::new(spec.smoothing),
            filter_u: Smoother::new(spec.smoothing),
            fy: History::new(2 * spec.span + 1),
            targets: History::new(2 * spec.span + 1),
            last_sent: 0.0,
            calls: 0,
            adapting: false,
            frozen: false,
            guard: Guard::new(spec.guard_factor, 1e-6)?,
        })
    }

    /// `[a₀, a₁, a₂]` now.
    pub fn coefficients(&self) -> [f64; 3] {
        self.a
    }

    /// Whether the threshold has been reached (the coefficients adapt).
    pub fn is_adapting(&self) -> bool {
        self.adapting
    }

    fn add_row(&mut self, row: [f64; 4], sign: f64) {
        for i in 0..3 {
            for j in i..3 {
                self.xtx[3 * i + j] += sign * row[i] * row[j];
            }
            self.xtu[i] += sign * row[i] * row[3];
        }
    }

    fn recompute_sums(&mut self) {
        self.xtx = [0.0; 9];
        self.xtu = [0.0; 3];
        let n = self.rows.len() / 4;
        for r in 0..self.stored.min(n) {
            let row = [
                self.rows[4 * r],
                self.rows[4 * r + 1],
                self.rows[4 * r + 2],
                self.rows[4 * r + 3],
            ];
            self.add_row(row, 1.0);
        }
        self.rows_since_recompute = 0;
    }

    fn push_row(&mut self, row: [f64; 4]) {
        let n = self.rows.len() / 4;
        let slot = self.next_row;
        if self.stored >= n {
            let old = [
                self.rows[4 * slot],
                self.rows[4 * slot + 1],
                self.rows[4 * slot + 2],
                self.rows[4 * slot + 3],
            ];
            self.add_row(old, -1.0);
        }
        self.rows[4 * slot..4 * slot + 4].copy_from_slice(&row);
        self.add_row(row, 1.0);
        self.next_row = (slot + 1) % n;
        self.stored = (self.stored + 1).min(n);
        self.rows_since_recompute += 1;
        if self.rows_since_recompute >= n {
            self.recompute_sums();
        }
    }

    /// Least squares over the window with columns scaled to unit RMS and a ridge of 1e-9 of the
    /// scaled diagonal; `None` if the system is singular.
    fn solve(&self) -> Option<[f64; 3]> {
        let m = |i: usize, j: usize| {
            if i <= j {
                self.xtx[3 * i + j]
            } else {
                self.xtx[3 * j + i]
            }
        };
        let mut scale = [0.0; 3];
        for (i, s) in scale.iter_mut().enumerate() {
            let d = m(i, i);
            if !(d.is_finite() && d > 0.0) {
                return None;
            }
            *s = 1.0 / d.sqrt();
        }
        let a = nalgebra::Matrix3::from_fn(|i, j| m(i, j) * scale[i] * scale[j] + if i == j { 1e-9 } else { 0.0 });
        let b = nalgebra::Vector3::from_fn(|i, _| self.xtu[i] * scale[i]);
        // A 3×3 Cholesky factor on the stack: no allocation in the sub-step path.
        let x = a.cholesky()?.solve(&b);
        let out = [x[0] * scale[0], x[1] * scale[1], x[2] * scale[2]];
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    fn update(&mut self) {
        if let Some(fit) = self.solve() {
            for (i, target) in fit.iter().enumerate() {
                let step = (target - self.a[i]).clamp(-self.spec.rate_limits[i], self.spec.rate_limits[i]);
                let [lo, hi] = self.spec.bounds[i];
                self.a[i] = (self.a[i] + step).clamp(lo, hi);
            }
        }
    }
}

impl PhaseLagCompensator for Ats {
    fn correction(&mut self, target: f64, measured_prev: f64, h: f64) -> f64 {
        if !self.guard.admit(target, measured_prev) {
            return 0.0;
        }
        // The pair of the previous sub-step: the command sent then, the displacement it produced.
        let fy = self.filter_y.step(measured_prev);
        let fu = self.filter_u.step(self.last_sent);
        self.fy.push(fy);
        self.calls += 1;
        if !self.frozen {
            self.adapting |= fy.abs() > self.spec.threshold;
            if self.calls > 2 * self.spec.span && self.calls.is_multiple_of(self.spec.subsample) {
                let (d1, d2) = differences(&self.fy, self.spec.span);
                self.push_row([self.fy.get(0), d1, d2, fu]);
                if self.adapting && self.stored >= 8 {
                    self.update();
                }
            }
        }
        self.targets.push(target);
        let (dd1, dd2) = differences(&self.targets, self.spec.span);
        let u = self.a[0] * target + self.a[1] * dd1 + self.a[2] * dd2;
        let du = self.guard.output(u - target, h);
        self.last_sent = target + h * du;
        du
    }
    fn kind(&self) -> &'static str {
        "ats"
    }
    fn is_adaptive(&self) -> bool {
        true
    }
    fn set_frozen(&mut self, frozen: bool) {
        self.frozen = frozen;
        self.guard.set_frozen(frozen);
    }
    fn trip(&self) -> Option<GuardTrip> {
        self.guard.trip()
    }
    fn parameters(&self) -> &[f64] {
        &self.a
    }
    fn set_parameters(&mut self, parameters: &[f64]) {
        if let [a0, a1, a2] = *parameters {
            self.a = [a0, a1, a2];
        }
    }
    /// The targets `d_{j−1} … d_{j−2s}` (all a frozen ATS depends on: it is an FIR of the
    /// target).
    fn state_len(&self) -> usize {
        2 * self.spec.span
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

    /// Drive an ATS through `plant` (`plant(command) -> measured at the end of the sub-step`)
    /// for `n` sub-steps; its coefficients and the RMS tracking error of the last half.
    fn drive(spec: AtsSpec, n: usize, mut plant: impl FnMut(f64) -> f64) -> ([f64; 3], f64) {
        let mut ats = spec.build().unwrap();
        let (mut y, mut err2, mut count) = (0.0, 0.0, 0);
        for j in 0..n {
            let d = target(j);
            let du = ats.correction(d, y, 1.0);
            y = plant(d + du);
            if j > n / 2 {
                err2 += (target(j) - y).powi(2);
                count += 1;
            }
        }
        assert!(ats.trip().is_none(), "{:?}", ats.trip());
        (ats.coefficients(), (err2 / count as f64).sqrt())
    }

    #[test]
    fn a_pure_delay_converges_to_its_length() {
        for lead in [4usize, 10, 25] {
            let mut line = std::collections::VecDeque::from(vec![0.0; lead]);
            // Start from a wrong guess: half the delay.
            let spec = AtsSpec::new(lead as f64 / 2.0);
            let (a, rms) = drive(spec, 60_000, |u| {
                line.push_back(u);
                line.pop_front().unwrap()
            });
            let l = lead as f64;
            assert!((a[1] - l).abs() < 0.05 * l, "delay {lead}: a = {a:?}");
            assert!((a[0] - 1.0).abs() < 0.02, "delay {lead}: a = {a:?}");
            // At least 10× below the uncompensated error d_j − d_{j−L}.
            let n = 60_000;
            let plain = ((n / 2 + 1..n)
                .map(|j| (target(j) - target(j - lead)).powi(2))
                .sum::<f64>()
                / (n / 2 - 1) as f64)
                .sqrt();
            assert!(
                rms < plain / 10.0,
                "delay {lead}: rms {rms:e} vs {plain:e} uncompensated, a = {a:?}"
            );
        }
    }

    #[test]
    fn a_first_order_lag_gives_its_exact_discrete_inverse() {
        for t_over_dtau in [5.0f64, 20.0] {
            let p = (-1.0 / t_over_dtau).exp();
            let mut y = 0.0;
            let (a, _) = drive(AtsSpec::new(t_over_dtau), 60_000, |u| {
                y = p * y + (1.0 - p) * u;
                y
            });
            let exact = p / (1.0 - p);
            assert!((a[0] - 1.0).abs() < 1e-3, "T = {t_over_dtau}: {a:?}");
            assert!(
                (a[1] - exact).abs() < 1e-3 * exact,
                "T = {t_over_dtau}: {a:?} vs {exact}"
            );
            assert!(a[2].abs() < 1e-2 * exact, "T = {t_over_dtau}: {a:?}");
            // To first order in Δτ/T the inverse is u = y + T ẏ: a₁ = T/Δτ − ½ + O(Δτ/T).
            assert!((a[1] - (t_over_dtau - 0.5)).abs() < 0.02, "{a:?}");
        }
    }

    #[test]
    fn below_the_threshold_nothing_adapts() {
        let spec = AtsSpec {
            threshold: 1.0,
            ..AtsSpec::new(3.0)
        };
        let mut line = std::collections::VecDeque::from(vec![0.0; 10]);
        let (a, _) = drive(spec, 5_000, |u| {
            line.push_back(u);
            line.pop_front().unwrap()
        });
        assert_eq!(a, [1.0, 3.0, 4.5]);
    }

    #[test]
    fn bad_settings_name_the_key() {
        let err = |s: AtsSpec| s.build().unwrap_err().to_string();
        assert!(err(AtsSpec::new(-1.0)).starts_with("phase_lag.initial_lead:"));
        assert!(
            err(AtsSpec {
                window: 10,
                ..AtsSpec::new(2.0)
            })
            .starts_with("phase_lag.window:")
        );
        assert!(
            err(AtsSpec {
                bounds: [[0.5, 2.0], [5.0, 9.0], [-1e3, 1e3]],
                ..AtsSpec::new(2.0)
            })
            .contains("does not contain its initial value 2")
        );
    }
}
