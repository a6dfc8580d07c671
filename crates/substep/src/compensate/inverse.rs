//! Baseline: an RLS-identified FIR inverse of the actuator applied to the extrapolated target.

use super::{Guard, GuardTrip, History, MAX_HISTORY, PhaseLagCompensator, lagrange_extrapolation_weights};
use crate::error::{Error, Result};
use crate::ident::Rls;

/// Configuration of [`InverseFir`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InverseFirSpec {
    /// The actuator's pure delay in sub-steps (may be fractional); the inverse is identified
    /// with the integer delay `D = ⌈lead⌉`.
    pub lead: f64,
    /// FIR length `m ≥ 1` (default 4).
    pub taps: usize,
    /// Order `p ∈ 1..=3` of the Lagrange extrapolation of the target (default 2).
    pub order: usize,
    /// Forgetting factor (default 0.995).
    pub lambda: f64,
    /// Initial covariance of the normalised regressor (default 100).
    pub p0: f64,
}

impl InverseFirSpec {
    pub fn new(lead: f64) -> Self {
        Self {
            lead,
            taps: 4,
            order: 2,
            lambda: 0.995,
            p0: 100.0,
        }
    }
    pub fn build(&self) -> Result<InverseFir> {
        InverseFir::new(*self)
    }
}

/// FIR inverse of the actuator, identified on line, applied to the extrapolated target.
///
/// Identification (every sub-step, RLS): the command sent `D = ⌈lead⌉` sub-steps before a
/// measurement is modelled from the measured history,
///
/// ```text
/// d_cmd,n−D ≈ Σ_{l=0}^{m−1} w_l y_{n−l}          (w = [1, 0, …] at the start: a pure delay of D)
/// ```
///
/// Compensation: the command that makes `y` follow the target is the inverse applied to the
/// desired output `D` sub-steps ahead,
///
/// ```text
/// d_cmd,j = Σ_l w_l d̂_{j+D−l},   Δu_j = d_cmd,j − d_j
/// ```
///
/// with `d̂` the target itself for past samples and its order-`p` Lagrange extrapolation for
/// future ones. For a pure integer delay this is [`Polynomial`](super::Polynomial) extrapolation;
/// the identified taps add the inverse of the actuator dynamics. Regressor and target are
/// scaled by the running maximum `|d|` (cancels in `w`).
#[derive(Debug, Clone)]
pub struct InverseFir {
    spec: InverseFirSpec,
    delay: usize,
    rls: Rls,
    /// `ex[(h−1)·(p+1) + i]`: weight of `d_{j−i}` in `d̂_{j+h}`, `h = 1…D`.
    ex: Vec<f64>,
    phi: Vec<f64>,
    /// `y_{j−1} … y_{j−m}` (after the push of call `j`).
    y: History,
    /// Sent commands, age 0 = the last one.
    sent: History,
    /// Past targets `d_{j−1}, …`.
    targets: History,
    scale: f64,
    frozen: bool,
    guard: Guard,
}

impl InverseFir {
    pub fn new(spec: InverseFirSpec) -> Result<Self> {
        if !(spec.lead.is_finite() && spec.lead >= 0.0) {
            return Err(Error::invalid(
                "phase_lag.lead",
                format!("must be a finite number of sub-steps >= 0, got {}", spec.lead),
            ));
        }
        if spec.taps == 0 || spec.taps > 64 {
            return Err(Error::invalid(
                "phase_lag.taps",
                format!("must be in 1..=64, got {}", spec.taps),
            ));
        }
        if !(1..=3).contains(&spec.order) {
            return Err(Error::invalid(
                "phase_lag.order",
                format!("polynomial extrapolation supports orders 1 to 3, got {}", spec.order),
            ));
        }
        let delay = spec.lead.ceil() as usize;
        if delay > MAX_HISTORY {
            return Err(Error::invalid(
                "phase_lag.lead",
                format!("{} sub-steps is longer than the history ({})", spec.lead, MAX_HISTORY),
            ));
        }
        let m = spec.taps;
        let p = spec.order;
        let mut theta = vec![0.0; m];
        theta[0] = 1.0;
        let rls = Rls::new(m, spec.lambda, spec.p0)
            .map_err(|e| match e {
                Error::InvalidInput { what, reason } => Error::invalid(format!("phase_lag.{what}"), reason),
                other => other,
            })?
            .with_theta(&theta);
        let ex = (1..=delay)
            .flat_map(|h| lagrange_extrapolation_weights(p, h as f64))
            .collect();
        Ok(Self {
            spec,
            delay,
            rls,
            ex,
            phi: vec![0.0; m],
            y: History::new(m),
            sent: History::new(delay + 1),
            targets: History::new(p.max(m.saturating_sub(delay + 1))),
            scale: 0.0,
            frozen: false,
            guard: Guard::default(),
        })
    }

    pub fn spec(&self) -> &InverseFirSpec {
        &self.spec
    }
    /// The identified taps `w`.
    pub fn taps(&self) -> &[f64] {
        self.rls.theta()
    }

    /// `d̂_{j+D−l}` for the current target `d_j` (`targets` holds `d_{j−1}, …`).
    fn desired(&self, target: f64, l: usize) -> f64 {
        let p = self.spec.order;
        let past = |i: usize| if i == 0 { target } else { self.targets.get(i - 1) };
        if l < self.delay {
            let h = self.delay - l;
            let w = &self.ex[(h - 1) * (p + 1)..h * (p + 1)];
            w.iter().enumerate().map(|(i, c)| c * past(i)).sum()
        } else {
            past(l - self.delay)
        }
    }
}

impl PhaseLagCompensator for InverseFir {
    fn correction(&mut self, target: f64, measured_prev: f64, h: f64) -> f64 {
        if !self.guard.admit(target, measured_prev) {
            return 0.0;
        }
        let m = self.spec.taps;
        self.y.push(measured_prev);
        self.scale = self.scale.max(target.abs()).max(measured_prev.abs());
        if !self.frozen && self.scale > 0.0 {
            let s = self.scale;
            for l in 0..m {
                self.phi[l] = self.y.get(l) / s;
            }
            self.rls.update(&self.phi, self.sent.get(self.delay) / s);
        }
        let w = self.rls.theta();
        let cmd: f64 = (0..m).map(|l| w[l] * self.desired(target, l)).sum();
        let du = self.guard.output(cmd - target, h);
        self.targets.push(target);
        self.sent.push(target + h * du);
        du
    }
    fn kind(&self) -> &'static str {
        "inverse_fir"
    }
    fn is_adaptive(&self) -> bool {
        !self.frozen
    }
    fn set_frozen(&mut self, frozen: bool) {
        self.frozen = frozen;
        self.guard.set_frozen(frozen);
    }
    fn trip(&self) -> Option<GuardTrip> {
        self.guard.trip()
    }
    fn parameters(&self) -> &[f64] {
        self.rls.theta()
    }
    /// `[y history (m), sent history (D + 1), target history]`, newest first.
    fn state_len(&self) -> usize {
        self.y.len() + self.sent.len() + self.targets.len()
    }
    fn write_state(&self, out: &mut [f64]) {
        let (a, b) = (self.y.len(), self.sent.len());
        self.y.write(&mut out[..a]);
        self.sent.write(&mut out[a..a + b]);
        self.targets.write(&mut out[a + b..]);
    }
    fn read_state(&mut self, s: &[f64]) {
        let (a, b) = (self.y.len(), self.sent.len());
        self.y.read(&s[..a]);
        self.sent.read(&s[a..a + b]);
        self.targets.read(&s[a + b..]);
    }
}
