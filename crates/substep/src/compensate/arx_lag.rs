//! The dissertation's phase-lag compensation by on-line identification (docs/theory.md §6.4).

use super::{Guard, GuardTrip, History, PhaseLagCompensator};
use crate::error::{Error, Result};
use crate::ident::{Estimator, Rls, ScalarRls};

/// Longest history (`k_lag · (n_u + 1)` sub-steps) an [`ArxPhaseLag`] keeps.
pub const MAX_HISTORY: usize = 1 << 14;

/// Which signals the regressor holds at each lag `l·k_lag`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Regressor {
    /// The dissertation's form (docs/theory.md §6.4): `[−Δu, v, ε]` (`θ` has `3 n_u` entries).
    /// Nearly collinear in closed loop (see [`ArxPhaseLag`]); kept for comparison.
    Full,
    /// `[−Δu, v]` (`2 n_u` entries): an ARX model of the correction driven by the command
    /// velocity. Its autoregressive part can drift to an unstable polynomial.
    CorrectionVelocity,
    /// `[v, ε]` (`2 n_u` entries): the correction from the command velocity and the
    /// tracking-error history. The `ε` feedback can drift to an unstable loop.
    VelocityError,
    /// `[v]` (`n_u` entries): a FIR predictor of the correction from the command velocity. No
    /// internal feedback, so the identification is an ordinary least-squares problem. The default.
    #[default]
    Velocity,
}

impl Regressor {
    /// `(−Δu, v, ε)` present.
    fn blocks(self) -> (bool, bool, bool) {
        match self {
            Regressor::Full => (true, true, true),
            Regressor::CorrectionVelocity => (true, true, false),
            Regressor::VelocityError => (false, true, true),
            Regressor::Velocity => (false, true, false),
        }
    }
    fn width(self) -> usize {
        let (a, b, c) = self.blocks();
        a as usize + b as usize + c as usize
    }
}

/// Which regressor the tracking error observed at the end of sub-step `n` updates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ErrorPairing {
    /// The dissertation's form (docs/theory.md §6.4): `θ ← θ + K ε_n` with `K` from `φ_n` and
    /// `ε_n = (d_n − y_n) − (1 − h_n) Δu_n`.
    Current,
    /// The correction that reached the specimen at `n` was computed `k_lag` sub-steps earlier
    /// from `φ_{n−k_lag}`: fit `φ_{n−k_lag}ᵀθ` to the correction that would have cancelled the
    /// error, `h_{n−k_lag} Δu_{n−k_lag} + (d_n − y_n)`; i.e. `θ ← θ + K e` with `K` from
    /// `φ_{n−k_lag}` and `e = h Δu_{n−k_lag} + (d_n − y_n) − φ_{n−k_lag}ᵀθ` (which is the
    /// dissertation's `ε_n` with the correction taken at `n − k_lag`, if `θ` did not change since). The
    /// tracking-error signal is then `ε_n = (d_n − y_n) − (1 − h_{n−k_lag}) Δu_{n−k_lag}`.
    #[default]
    Delayed,
}

/// Configuration of [`ArxPhaseLag`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArxPhaseLagSpec {
    /// Number of lags `n_u` (1..=12; default 5).
    pub n_u: usize,
    /// Identification interval `k_lag` in sub-steps (≥ 1; about the delay in sub-steps): `θ` is
    /// updated every `k_lag` sub-steps, and the delayed pairing attributes an error to the
    /// correction sent `k_lag` sub-steps before.
    pub k_lag: usize,
    /// Forgetting factor `λ ∈ (0, 1]` (default 0.99).
    pub lambda: f64,
    /// Initial covariance `P = p0·I` of the normalised regressor (default 100).
    pub p0: f64,
    /// Covariance bound `trace P ≤ p_max · n_θ` (default `p0`).
    pub p_max: Option<f64>,
    /// Use the scalar-covariance RLS ([`ScalarRls`]) instead of the full one.
    pub scalar_covariance: bool,
    /// Guard: disable if `|h Δu| > guard_factor ×` the range of targets seen (default 10).
    pub guard_factor: f64,
    /// Signals in the regressor (default [`Regressor::Velocity`]).
    pub regressor: Regressor,
    /// Which regressor the observed tracking error updates (default [`ErrorPairing::Delayed`]).
    pub pairing: ErrorPairing,
    /// `S`: sub-steps over which each velocity sample is taken, `v_j = d̄_j − d̄_{j−S}`, and
    /// between two lags of the regressor (≥ 1; default `k_lag`; test definitions: one time step,
    /// `k_sub`).
    pub span: usize,
    /// `T_s`: time constant \[sub-steps\] of each of the two first-order low-pass stages that give
    /// the smoothed target `d̄` the velocities are taken from (≥ 0; 0: `d̄ = d`; default
    /// `span / 2`).
    pub smoothing: f64,
    /// The first lag of the regressor is the current sample `j` (`true`, default) or
    /// `j − k_lag` (`false`, as written in the dissertation). Only with [`Regressor::Velocity`]:
    /// the other blocks hold corrections not yet computed at `j`.
    pub from_current: bool,
    /// Start from the pure-delay predictor `θ₀` (a lead of `k_lag` sub-steps, see
    /// [`ArxPhaseLag::prior`]) instead of `θ = 0` (default `true`; only with
    /// [`Regressor::Velocity`]).
    pub prior: bool,
    /// Supervisor bound `ℓ_max` \[sub-steps\] on the lead the correction amounts to (see
    /// [`ArxPhaseLag`]); `None`: no supervisor. Default `4 k_lag + span`.
    pub max_lead: Option<f64>,
    /// Updates are skipped while the normalised regressor is shorter than this (the excitation
    /// is too low to identify anything; default 0.01).
    pub min_excitation: f64,
    /// The expected lead \[sub-steps\], fractional (default `k_lag`): the prior's lead and, with
    /// `period`, the ripple's.
    pub lead: f64,
    /// Sub-steps per time step `k` when the commands come from the sub-step algorithm, whose
    /// ripple repeats every step (default 1: no ripple term).
    pub period: usize,
}

impl ArxPhaseLagSpec {
    /// Defaults for an interval `k_lag`: `n_u = 5`, `λ = 0.99`, `p0 = 100`, full covariance,
    /// [`Regressor::Velocity`], [`ErrorPairing::Delayed`], guard factor 10, `span = k_lag`,
    /// `smoothing = span/2`, lags from the current sample, the pure-delay prior, the
    /// supervisor with `ℓ_max = 4 k_lag + span`, minimum excitation 0.01.
    pub fn new(k_lag: usize) -> Self {
        Self {
            n_u: 5,
            k_lag,
            lambda: 0.99,
            p0: 100.0,
            p_max: None,
            scalar_covariance: false,
            guard_factor: 10.0,
            regressor: Regressor::default(),
            pairing: ErrorPairing::default(),
            span: k_lag,
            smoothing: 0.0,
            from_current: true,
            prior: true,
            max_lead: None,
            min_excitation: 0.01,
            lead: k_lag as f64,
            period: 1,
        }
        .with_span(k_lag)
    }

    /// The defaults inside the sub-step algorithm (what `[substructure.phase_lag] kind = "arx"`
    /// gives): `lag` the actuator's low-frequency lag in sub-steps (delay plus dynamics,
    /// [`crate::transfer::ActuatorSpec::low_frequency_lag`]` / Δτ`), `k_sub` sub-steps per step:
    /// `k_lag = round(lag)` (at least 1), the prior's lead `lag` (at least 1), velocities over one
    /// step (`span = k_sub`, the step's ripple cancels in them), the ripple's period `k_sub`.
    pub fn for_substeps(lag: f64, k_sub: usize) -> Self {
        let k_lag = (lag.round() as usize).max(1);
        Self {
            lead: lag.max(1.0),
            period: k_sub,
            ..Self::new(k_lag).with_span(k_sub)
        }
    }

    /// Set the velocity span `S` and the defaults that follow it: `smoothing = S/2`,
    /// `max_lead = 4 k_lag + S`.
    pub fn with_span(mut self, span: usize) -> Self {
        self.span = span;
        self.smoothing = span as f64 / 2.0;
        self.max_lead = Some((4 * self.k_lag + 2 * span) as f64);
        self
    }

    /// The dissertation's method as written (docs/theory.md §6.4): [`Regressor::Full`],
    /// [`ErrorPairing::Current`], velocities of the raw target over `k_lag`, lags from `j − k_lag`,
    /// `θ = 0` at the start, no supervisor, every update applied.
    pub fn as_written(k_lag: usize) -> Self {
        Self {
            regressor: Regressor::Full,
            pairing: ErrorPairing::Current,
            ..Self::new(k_lag).project_v1()
        }
    }

    /// The form of project version 1 (before docs/theory.md §6.4's robust parameterisation): the
    /// default regressor and pairing with velocities of the raw target over `k_lag`, lags from
    /// `j − k_lag`, `θ = 0` at the start, no supervisor, every update applied. Kept to compare.
    pub fn project_v1(self) -> Self {
        Self {
            span: self.k_lag,
            smoothing: 0.0,
            from_current: false,
            prior: false,
            max_lead: None,
            min_excitation: 0.0,
            period: 1,
            ..self
        }
    }

    /// Length of `θ`.
    pub fn n_params(&self) -> usize {
        self.regressor.width() * self.n_u
    }

    pub fn validate(&self) -> Result<()> {
        if !(1..=12).contains(&self.n_u) {
            return Err(Error::invalid(
                "phase_lag.n_u",
                format!("must be in 1..=12, got {}", self.n_u),
            ));
        }
        if self.k_lag == 0 {
            return Err(Error::invalid("phase_lag.k_lag", "must be at least 1 sub-step"));
        }
        if self.span == 0 {
            return Err(Error::invalid("phase_lag.span", "must be at least 1 sub-step"));
        }
        if self.history_len() > MAX_HISTORY {
            return Err(Error::invalid(
                "phase_lag.k_lag",
                format!(
                    "k_lag and span larger than the history: 2·k_lag + n_u·span = 2·{} + {}·{} exceeds \
                     {MAX_HISTORY} sub-steps",
                    self.k_lag, self.n_u, self.span
                ),
            ));
        }
        if !(self.smoothing.is_finite() && (0.0..=MAX_HISTORY as f64).contains(&self.smoothing)) {
            return Err(Error::invalid(
                "phase_lag.smoothing",
                format!("must be in 0..={MAX_HISTORY} sub-steps, got {}", self.smoothing),
            ));
        }
        if self.regressor != Regressor::Velocity && (self.from_current || self.prior) {
            return Err(Error::invalid(
                "phase_lag.regressor",
                "lags from the current sample and the pure-delay prior need the velocity regressor \
                 (the other blocks hold corrections not yet computed)",
            ));
        }
        if let Some(l) = self.max_lead
            && !(l.is_finite() && l > 0.0)
        {
            return Err(Error::invalid(
                "phase_lag.max_lead",
                format!("must be a finite number > 0 of sub-steps, got {l}"),
            ));
        }
        if !(self.min_excitation.is_finite() && self.min_excitation >= 0.0) {
            return Err(Error::invalid(
                "phase_lag.min_excitation",
                format!("must be a finite number >= 0, got {}", self.min_excitation),
            ));
        }
        if !(self.lambda.is_finite() && self.lambda > 0.0 && self.lambda <= 1.0) {
            return Err(Error::invalid(
                "phase_lag.forgetting_factor",
                format!("must be in (0, 1], got {}", self.lambda),
            ));
        }
        if !(self.p0.is_finite() && self.p0 > 0.0) {
            return Err(Error::invalid(
                "phase_lag.p0",
                format!("must be a finite number > 0, got {}", self.p0),
            ));
        }
        if let Some(p) = self.p_max
            && !(p.is_finite() && p > 0.0)
        {
            return Err(Error::invalid(
                "phase_lag.p_max",
                format!("must be a finite number > 0, got {p}"),
            ));
        }
        Guard::new(self.guard_factor, 1e-6)?;
        Ok(())
    }

    /// Samples of the correction, velocity and error histories: the oldest lag of the regressor
    /// of a delayed update, `2 k_lag + (n_u − 1) span`, plus the newest.
    fn history_len(&self) -> usize {
        self.k_lag
            .saturating_mul(2)
            .saturating_add(self.n_u.saturating_mul(self.span))
            .saturating_add(1)
    }

    pub fn build(&self) -> Result<ArxPhaseLag> {
        ArxPhaseLag::new(*self)
    }
}

/// Phase-lag compensation by on-line identification (docs/theory.md §6.4); see the module docs of
/// [`crate::compensate`] for the timing. Per sub-step `j`, with `L = k_lag`, `S = span`:
///
/// ```text
/// d̄_j  = F(q) d_j                                    two first-order low-pass stages, T_s each
/// v_j  = d̄_j − d̄_{j−S}                               smoothed command velocity × span
/// ε_n  = (d_n − y_n) − (1 − h_m) Δu_m                tracking error (m = n, or n − L: ErrorPairing)
/// φ_j  = [−Δu_{j−o−lS}, v_{j−o−lS}, ε_{j−o−lS}]_{l=0…n_u−1}   (blocks as chosen by Regressor;
///                                                     o = 0 from the current sample, else L)
/// Δu_j = g_j φ_jᵀ θ_j
/// ```
///
/// Every `L` sub-steps (`j ≡ 0 mod L`) `θ` is updated by the RLS law
/// `K = Pφ/(λ + φᵀPφ)`, `θ ← θ + K e`, `P ← (P − Kφᵀ P)/λ` driven by the observed tracking
/// error: `(φ, e) = (φ_{j−1}, ε_{j−1})` as written in the dissertation ([`ErrorPairing::Current`]), or
/// the delayed pairing of [`ErrorPairing::Delayed`]. Regressor and error are scaled by `1/s`
/// (`s` = running maximum of `|v|` and `|d − y|`), which keeps `p0` meaningful in any unit and
/// cancels in `Δu = φᵀθ`; updates whose scaled regressor is shorter than `min_excitation` are
/// skipped (too little excitation to identify anything). The `θ_j` in use is blended linearly
/// from its value at the update to the new estimate over the `L` sub-steps of the interval (no
/// jumps in the command). At the start `θ` is the pure-delay prior [`ArxPhaseLag::prior`] (or 0).
///
/// **Supervisor.** With `max_lead = Some(ℓ_max)`, the compensator watches the lead its
/// correction amounts to, `ℓ_j = RMS(Δu) / RMS(v/S)` over an exponential window of
/// `4 (L + S)` sub-steps: how many sub-steps of the smoothed command's motion the correction
/// adds. A compensator that leads by a delay has `ℓ ≈ L`; one that has turned the loop unstable
/// drives corrections far beyond the command's own motion. When `ℓ > ℓ_max` (evaluated once
/// the command has moved), the supervisor backs off: the gain `g` falls linearly from 1 to 0
/// over `S` sub-steps (no jump in the command), the estimate stops adapting, and the test
/// continues uncompensated; [`PhaseLagCompensator::trip`] reports
/// [`GuardTrip::Unstable`].
///
/// **Deviations from the dissertation (the defaults), and why** (docs/theory.md §6.4 has the
/// measurements):
///
/// 1. *Regressor.* As written, `[−Δu, v, ε]` is nearly collinear in closed loop: with delay
///    `D ≈ L` and `h = 1`, `ε_n = (d_n − d_{n−D}) − Δu_{n−D}`, so each `ε` entry is minus the
///    next `−Δu` entry plus a command difference the `v` entries span; the data do not
///    constrain `θ` along that direction and it drifts until the loop `Δu → y → ε → Δu` bursts.
///    The default [`Regressor::Velocity`] keeps only `v`: `Δu` is a FIR filter of the command
///    and the identification an ordinary least-squares problem. The other forms stay available.
/// 2. *Error pairing.* As written, the error observed at `n` updates the regressor `φ_n`, but
///    the correction that caused it was computed from `φ_{n−D}`. [`ErrorPairing::Delayed`]
///    attributes it to `φ_{n−L}`, with the correction that would have cancelled it as the target.
/// 3. *Smoothed velocities over a time step.* Inside the sub-step algorithm the command carries
///    the sub-step iteration (`G_cc f^{(j−1)}`, a ripple at the sub-step and step rates) on
///    top of the structure's motion. Velocities of the raw command over `L` sub-steps let the
///    predictor extrapolate that ripple: its gain at high frequencies grows with the collinear,
///    large coefficients of a predictor of a smooth signal, and the loop through the specimen's
///    force closes at a frequency the structure does not have (the 50 Hz bursts of a damper
///    test at `Δt` = 10 ms). `d̄` (two stages, `T_s = S/2`) and `S` = one time step keep the
///    correction in the band the structure responds in.
/// 4. *Lags from the current sample, a prior, a supervisor, excitation monitoring*: the
///    predictor extrapolates `L` sub-steps rather than `2L`; it starts from a pure delay rather
///    than from no compensation; and no estimate can run away unnoticed.
pub struct ArxPhaseLag {
    spec: ArxPhaseLagSpec,
    est: Box<dyn Estimator>,
    theta_old: Vec<f64>,
    /// Blended `θ` used for the correction.
    theta: Vec<f64>,
    phi: Vec<f64>,
    /// Histories, age 0 = the last sample (`j − 1` during call `j`).
    du: History,
    /// Sent corrections `h Δu`.
    applied: History,
    v: History,
    eps: History,
    /// Smoothed targets `d̄_{j−1} … d̄_{j−S}`.
    smoothed: History,
    /// The two low-pass stages and their coefficient `1 − e^{−1/T_s}`.
    stage1: f64,
    stage2: f64,
    alpha: f64,
    /// Targets `d_{j−1} … d_{j−k−1}` (the tracking error and the ripple term).
    targets: History,
    count: usize,
    scale: f64,
    frozen: bool,
    guard: Guard,
    supervisor: Supervisor,
}

/// The lead watch of [`ArxPhaseLag`]: exponentially weighted mean squares of the correction and
/// of the smoothed command velocity per sub-step.
#[derive(Debug, Clone)]
struct Supervisor {
    max_lead: Option<f64>,
    weight: f64,
    ms_correction: f64,
    ms_velocity: f64,
    /// Largest `ms_velocity` seen (the lead is judged once the command moves).
    ms_velocity_peak: f64,
    /// Sub-steps the command has moved for (the lead is judged after one window of motion).
    moving_for: usize,
    window: usize,
    /// Largest lead seen while judged (for reports).
    lead_peak: f64,
    /// Output gain `g` and its decrement per sub-step once backing off.
    gain: f64,
    fade_step: f64,
    trip: Option<GuardTrip>,
}

impl Supervisor {
    fn new(spec: &ArxPhaseLagSpec) -> Self {
        let window = 4 * (spec.k_lag + spec.span);
        Self {
            max_lead: spec.max_lead,
            weight: 1.0 / window as f64,
            ms_correction: 0.0,
            ms_velocity: 0.0,
            ms_velocity_peak: 0.0,
            moving_for: 0,
            window,
            lead_peak: 0.0,
            gain: 1.0,
            fade_step: 1.0 / spec.span as f64,
            trip: None,
        }
    }

    /// Record one sub-step (`correction` before the gain, `velocity` per sub-step); once tripped,
    /// lower the gain.
    fn observe(&mut self, correction: f64, velocity: f64) {
        if self.trip.is_some() {
            self.gain = (self.gain - self.fade_step).max(0.0);
            return;
        }
        let Some(max_lead) = self.max_lead else {
            return;
        };
        let w = self.weight;
        self.ms_correction += w * (correction * correction - self.ms_correction);
        self.ms_velocity += w * (velocity * velocity - self.ms_velocity);
        self.ms_velocity_peak = self.ms_velocity_peak.max(self.ms_velocity);
        // Judged only while the command moves (not at rest, not in the decay of a record).
        if self.ms_velocity > 0.0 {
            self.moving_for += 1;
        }
        if self.moving_for > self.window && self.ms_velocity > 1e-4 * self.ms_velocity_peak {
            let lead = (self.ms_correction / self.ms_velocity).sqrt();
            self.lead_peak = self.lead_peak.max(lead);
            if lead > max_lead {
                self.trip = Some(GuardTrip::Unstable { lead, bound: max_lead });
            }
        }
    }
}

impl ArxPhaseLag {
    pub fn new(spec: ArxPhaseLagSpec) -> Result<Self> {
        spec.validate()?;
        let n = spec.n_params();
        let p_max = spec.p_max.unwrap_or(spec.p0);
        let mut est: Box<dyn Estimator> = if spec.scalar_covariance {
            Box::new(ScalarRls::new(n, spec.lambda, spec.p0)?.with_covariance_bound(p_max)?)
        } else {
            Box::new(Rls::new(n, spec.lambda, spec.p0)?.with_covariance_bound(p_max)?)
        };
        let prior = if spec.prior { Self::prior(&spec) } else { vec![0.0; n] };
        est.set_theta(&prior);
        let len = spec.history_len();
        let alpha = if spec.smoothing > 0.0 {
            1.0 - (-1.0 / spec.smoothing).exp()
        } else {
            1.0
        };
        Ok(Self {
            spec,
            est,
            theta_old: prior.clone(),
            theta: prior,
            phi: vec![0.0; n],
            du: History::new(len),
            applied: History::new(len),
            v: History::new(len),
            eps: History::new(len),
            smoothed: History::new(spec.span),
            stage1: 0.0,
            stage2: 0.0,
            alpha,
            targets: History::new(spec.period + 1),
            count: 0,
            scale: 0.0,
            frozen: false,
            guard: Guard::new(spec.guard_factor, 1e-6)?,
            supervisor: Supervisor::new(&spec),
        })
    }

    /// The pure-delay prior `θ₀` of the velocity regressor: the correction `Δu_j ≈ d_{j+L} − d_j`
    /// of a delay of `L = k_lag` sub-steps for a command whose velocity changes linearly.
    /// `v_{j−o}` is `S` times the velocity at the age `a = o + S/2 + 2 τ_s` sub-steps (`τ_s` the
    /// group delay `(1 − α)/α` of one smoothing stage); extrapolating the velocity from the
    /// first two lags to the middle of the lead, `j + L/2`, gives
    /// `θ₀ = [L (1 + c)/S, −L c/S, 0, …]` with `c = (L/2 + a)/S` (`[L/S]` for `n_u = 1`).
    pub fn prior(spec: &ArxPhaseLagSpec) -> Vec<f64> {
        let mut theta = vec![0.0; spec.n_params()];
        if spec.regressor != Regressor::Velocity {
            return theta;
        }
        let (l, s) = (spec.lead, spec.span as f64);
        let tau_s = if spec.smoothing > 0.0 {
            let alpha = 1.0 - (-1.0 / spec.smoothing).exp();
            (1.0 - alpha) / alpha
        } else {
            0.0
        };
        let origin = if spec.from_current { 0.0 } else { spec.k_lag as f64 };
        let age = origin + s / 2.0 + 2.0 * tau_s;
        if spec.n_u == 1 {
            theta[0] = l / s;
        } else {
            let c = (l / 2.0 + age) / s;
            theta[0] = l * (1.0 + c) / s;
            theta[1] = -l * c / s;
        }
        theta
    }

    pub fn spec(&self) -> &ArxPhaseLagSpec {
        &self.spec
    }
    /// The latest RLS estimate (the blended value in use is [`PhaseLagCompensator::parameters`]).
    pub fn estimate(&self) -> &[f64] {
        self.est.theta()
    }
    pub fn covariance_trace(&self) -> f64 {
        self.est.covariance_trace()
    }
    /// The largest lead \[sub-steps\] the supervisor has seen (0 before the command moved).
    pub fn peak_lead(&self) -> f64 {
        self.supervisor.lead_peak
    }
    /// The supervisor's output gain `g` (1 until it backs off, then falling to 0).
    pub fn gain(&self) -> f64 {
        self.supervisor.gain
    }

    /// The lead of the step-periodic ripple by the fractional part `r = lead mod k` of the lead
    /// (0 without a period): `(d_{j+r−k} − d_j) + (k − r)/k (d_j − d_{j−k})`, exact for a ripple
    /// of period `k` on a linear trend; `d_{j+r−k}` interpolated linearly.
    fn ripple(&self, target: f64) -> f64 {
        let k = self.spec.period;
        let r = self.spec.lead % k as f64;
        if k < 2 || r < 1e-9 || (!self.frozen && self.count < k) {
            return 0.0;
        }
        let at = |age: isize| {
            if age < 0 {
                target
            } else {
                self.targets.get(age as usize)
            }
        };
        // d_{j+r−k} is age k − r − 1 (age 0 = d_{j−1}, −1 = d_j).
        let age = k as f64 - r - 1.0;
        let a0 = age.floor();
        let frac = age - a0;
        let d_shift = (1.0 - frac) * at(a0 as isize) + frac * at(a0 as isize + 1);
        (d_shift - target) + (k as f64 - r) / k as f64 * (target - self.targets.get(k - 1))
    }

    /// First lag of the regressor: 0 (the current sample) or `k_lag`.
    fn origin(&self) -> usize {
        if self.spec.from_current { 0 } else { self.spec.k_lag }
    }

    /// Fill `self.phi` with the regressor whose entries `l = 0…n_u−1` are the samples
    /// `newest_age + l·S` pushes old (age 0 = sub-step `j − 1` during call `j`); age `−1` is the
    /// current sample, whose velocity `v_now` is not in the history yet (velocity block only).
    fn regressor(&mut self, newest_age: isize, v_now: f64) {
        let span = self.spec.span as isize;
        let (has_du, has_v, has_eps) = self.spec.regressor.blocks();
        let mut i = 0;
        for l in 0..self.spec.n_u as isize {
            let age = newest_age + l * span;
            let at = |h: &History| if age < 0 { 0.0 } else { h.get(age as usize) };
            if has_du {
                self.phi[i] = -at(&self.du);
                i += 1;
            }
            if has_v {
                self.phi[i] = if age < 0 { v_now } else { self.v.get(age as usize) };
                i += 1;
            }
            if has_eps {
                self.phi[i] = at(&self.eps);
                i += 1;
            }
        }
    }
}

impl PhaseLagCompensator for ArxPhaseLag {
    fn correction(&mut self, target: f64, measured_prev: f64, h: f64) -> f64 {
        if !self.guard.admit(target, measured_prev) {
            return 0.0;
        }
        let k = self.spec.k_lag;
        let lag = self.targets.get(0) - measured_prev;
        // Age of the correction the error of sub-step j − 1 is attributed to.
        let cause = match self.spec.pairing {
            ErrorPairing::Current => 0,
            ErrorPairing::Delayed => k,
        };
        // ε_{j−1}: the tracking error less the part of that correction that was not sent.
        let eps = lag - (self.du.get(cause) - self.applied.get(cause));
        self.eps.set(0, eps);
        self.stage1 += self.alpha * (target - self.stage1);
        self.stage2 += self.alpha * (self.stage1 - self.stage2);
        let v = self.stage2 - self.smoothed.get(self.spec.span - 1);
        self.scale = self.scale.max(v.abs()).max(lag.abs());
        let origin = self.origin() as isize;

        let adapting = !self.frozen && self.supervisor.trip.is_none();
        if adapting && self.count > 0 && self.count.is_multiple_of(k) {
            if self.scale > 0.0 {
                let s = self.scale;
                // The regressor of the correction sent at j − 1 − cause, normalised.
                self.regressor(cause as isize + origin, v);
                self.phi.iter_mut().for_each(|p| *p /= s);
                let excited = self.phi.iter().map(|p| p * p).sum::<f64>().sqrt() >= self.spec.min_excitation;
                if excited {
                    let e = match self.spec.pairing {
                        ErrorPairing::Current => eps,
                        ErrorPairing::Delayed => (self.applied.get(k) + lag) - self.est.predict(&self.phi) * s,
                    };
                    self.est.update_with_error(&self.phi, e / s);
                }
            }
            self.theta_old.copy_from_slice(&self.theta);
        }
        if adapting {
            let r = ((self.count % k) + 1) as f64 / k as f64;
            let new = self.est.theta();
            for ((t, old), new) in self.theta.iter_mut().zip(&self.theta_old).zip(new) {
                *t = old + r * (new - old);
            }
        }
        // φ_j: sample j − o − lS is age o + lS − 1 now.
        self.regressor(origin - 1, v);
        let du: f64 = self.phi.iter().zip(&self.theta).map(|(p, t)| p * t).sum::<f64>() + self.ripple(target);
        if !self.frozen {
            self.supervisor.observe(du, v / self.spec.span as f64);
        }
        let du = self.guard.output(self.supervisor.gain * du, h);

        self.du.push(du);
        self.applied.push(h * du);
        self.v.push(v);
        self.eps.push(0.0);
        self.smoothed.push(self.stage2);
        self.targets.push(target);
        self.count += 1;
        du
    }
    fn kind(&self) -> &'static str {
        "arx"
    }
    fn is_adaptive(&self) -> bool {
        !self.frozen && self.supervisor.trip.is_none()
    }
    fn set_frozen(&mut self, frozen: bool) {
        if self.frozen && !frozen {
            self.theta_old.copy_from_slice(&self.theta);
        }
        self.frozen = frozen;
        self.guard.set_frozen(frozen);
    }
    fn trip(&self) -> Option<GuardTrip> {
        self.guard.trip().or(self.supervisor.trip)
    }
    fn parameters(&self) -> &[f64] {
        &self.theta
    }
    /// Also re-arms the supervisor (gain 1): the analysis judges the parameters themselves.
    fn set_parameters(&mut self, parameters: &[f64]) {
        if parameters.len() == self.theta.len() && parameters.iter().all(|p| p.is_finite()) {
            self.theta.copy_from_slice(parameters);
            self.theta_old.copy_from_slice(parameters);
            self.est.set_theta(parameters);
            self.supervisor.gain = 1.0;
            self.supervisor.trip = None;
        }
    }
    /// `[low-pass stages (2), d history (k + 1), d̄ history (S), Δu history, h Δu history,
    /// v history, ε history]`, newest first.
    fn state_len(&self) -> usize {
        2 + self.targets.len() + self.smoothed.len() + 4 * self.du.len()
    }
    fn write_state(&self, out: &mut [f64]) {
        out[0] = self.stage1;
        out[1] = self.stage2;
        let mut at = 2;
        for h in [
            &self.targets,
            &self.smoothed,
            &self.du,
            &self.applied,
            &self.v,
            &self.eps,
        ] {
            h.write(&mut out[at..at + h.len()]);
            at += h.len();
        }
    }
    fn read_state(&mut self, s: &[f64]) {
        self.stage1 = s[0];
        self.stage2 = s[1];
        let mut at = 2;
        for h in [
            &mut self.targets,
            &mut self.smoothed,
            &mut self.du,
            &mut self.applied,
            &mut self.v,
            &mut self.eps,
        ] {
            let n = h.len();
            h.read(&s[at..at + n]);
            at += n;
        }
    }
}
