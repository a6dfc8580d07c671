//! Phase-lag compensation of the actuators (docs/theory.md §6).
//!
//! The command sent to the actuator of a coupling DOF is
//!
//! ```text
//! d_cmd,j = d_j + h_j Δu_j
//! ```
//!
//! where `d_j` is the sub-step controller's target command of sub-step `j`, `Δu_j` the correction
//! of a [`PhaseLagCompensator`] and `h_j ∈ [0, 1]` a [`Ramp`]. [`CompensatedSite`] wraps any
//! [`ExperimentalSubstructure`](crate::substructure::ExperimentalSubstructure) and does this for
//! every coupling DOF.
//!
//! Timing convention (all compensators): sub-step `j` is called with the target `d_j` and the
//! displacement `y_{j−1}` measured at the end of the previous sub-step (before sub-step 0: the
//! measurement the site returned last, 0 at the start). A pure delay of `τ = L·Δτ` makes
//! `y_j = d_cmd(t_j − τ)`, so a perfect correction is `Δu_j = d_{j+L} − d_j` — a lead of `L`
//! sub-steps.
//!
//! Implementations:
//!
//! * [`Polynomial`] — Horiuchi's extrapolation of the target `lead` sub-steps ahead;
//! * [`ArxPhaseLag`] — the dissertation's on-line identification method;
//! * [`InverseFir`] — an RLS-identified FIR inverse of the actuator applied to the extrapolated
//!   target (baseline);
//! * [`Ats`] — the adaptive time-series compensator of Chae et al. (2013), the field's common
//!   reference: a feed-forward `a₀ d + a₁ ḋ + a₂ d̈` fitted by moving-window least squares;
//! * [`Amb`] — adaptive model-based compensation: the inverse of the lab's plant model as a
//!   feed-forward `Σ cᵢ Dⁱ d` (to the third derivative), its coefficients re-identified on line
//!   by RLS within a band around the model.
//!
//! Every compensator has a [`Guard`]: a non-finite input or correction, or a sent correction
//! `h Δu` larger than `factor ×` the range of targets seen so far, disables it (the correction is
//! 0 from then on) and records a [`GuardTrip`]; it never returns a non-finite value.
//!
//! Use a ramp-in ([`Ramp::new`]): a command that starts moving abruptly from rest makes the
//! extrapolation overshoot at the start (a cubic extrapolation `L` sub-steps ahead multiplies
//! the first increment by about `(L+1)(L+2)(L+3)/6`), and the identified methods start from
//! `θ = 0`; while `h = 0` nothing is sent and the guard does not trip.
//!
//! Measured reduction of the RMS tracking error `|d − y|` (1 Hz sine, Δτ = 1 ms, 10 ms delay,
//! `tests/compensate.rs`): polynomial p = 3 ≈ 56 000× (unaffected by displacement noise, which
//! it never sees, but 0.2× — worse than none — when 2 µm of noise rides on the command);
//! [`ArxPhaseLag`] ≈ 690× noise-free, ≈ 170× with 1 % displacement noise, ≈ 110× with the
//! command noise as well; [`InverseFir`] ≈ 1150× / 13×.

mod amb;
mod arx_lag;
mod ats;
mod inverse;
mod polynomial;
mod site;
mod spec;

pub use crate::substructure::{GuardTrip, PhaseLagReport};
pub use amb::{Amb, AmbSpec, difference_coefficients, inverse_series};
pub use arx_lag::{ArxPhaseLag, ArxPhaseLagSpec, ErrorPairing, MAX_HISTORY, Regressor};
pub use ats::{Ats, AtsSpec};
pub use inverse::{InverseFir, InverseFirSpec};
pub use polynomial::{Polynomial, lagrange_extrapolation_weights};
pub use site::CompensatedSite;
pub use spec::{PhaseLagDefinition, PhaseLagSpec};

use crate::error::{Error, Result};

/// Test signals shared by the compensators' unit tests.
#[cfg(test)]
pub(crate) mod test_signals {
    /// A broadband smooth target: sines from 0.3 to 3 Hz at Δτ = 1 ms, from rest (a 1 s cosine
    /// ramp-in, as a test would start).
    pub(crate) fn broadband(j: usize) -> f64 {
        let t = j as f64 * 1e-3;
        let ramp = if t < 1.0 {
            0.5 - 0.5 * (std::f64::consts::PI * t).cos()
        } else {
            1.0
        };
        ramp * [(0.3, 0.010), (0.7, 0.006), (1.3, 0.004), (2.1, 0.003), (3.0, 0.002)]
            .iter()
            .map(|(f, a)| a * (2.0 * std::f64::consts::PI * f * t).sin())
            .sum::<f64>()
    }
}

/// One coupling DOF's phase-lag compensator.
pub trait PhaseLagCompensator: Send {
    /// Sub-step `j`: given the target command `d_j`, the displacement `y_{j−1}` measured at the
    /// end of the previous sub-step and the ramp value `h_j` with which the result will be sent
    /// (`d_cmd = d + h Δu`; pass 1 when used alone), return the correction `Δu_j` (before the
    /// ramp). Always finite; the guard checks the part actually sent, `h Δu`.
    fn correction(&mut self, target: f64, measured_prev: f64, h: f64) -> f64;
    /// Short name for reports.
    fn kind(&self) -> &'static str;
    /// Whether the compensator changes its parameters while it runs.
    fn is_adaptive(&self) -> bool;
    /// Fix (or release) the parameters; a frozen compensator is a linear filter of its inputs.
    fn set_frozen(&mut self, frozen: bool);
    /// Why the guard disabled the compensator, if it did.
    fn trip(&self) -> Option<GuardTrip>;
    /// The parameter vector, if the compensator has one (identified methods).
    fn parameters(&self) -> &[f64] {
        &[]
    }
    /// Set the parameter vector (for the analysis at converged parameters, with
    /// [`set_frozen`](Self::set_frozen)); a slice of the wrong length is ignored, as is any
    /// slice for a compensator without parameters.
    fn set_parameters(&mut self, _parameters: &[f64]) {}
    /// History state (for the amplification-matrix analysis with frozen parameters); the layout
    /// is fixed at construction.
    fn state_len(&self) -> usize;
    fn write_state(&self, out: &mut [f64]);
    fn read_state(&mut self, state: &[f64]);
}

/// Output guard of a compensator: the bound on the sent correction `|h Δu|` is
/// `factor · max(range, floor)`, `range` the spread (max − min) of the finite targets seen so far
/// (including the initial 0). After a trip the correction is 0.
#[derive(Debug, Clone)]
pub struct Guard {
    factor: f64,
    floor: f64,
    min: f64,
    max: f64,
    trip: Option<GuardTrip>,
    frozen: bool,
}

impl Default for Guard {
    /// `factor = 10`, `floor = 1e-6` (m).
    fn default() -> Self {
        Self::new(10.0, 1e-6).expect("valid defaults")
    }
}

impl Guard {
    pub fn new(factor: f64, floor: f64) -> Result<Self> {
        if !(factor.is_finite() && factor > 0.0) {
            return Err(Error::invalid(
                "phase_lag.guard_factor",
                format!("must be a finite number > 0, got {factor}"),
            ));
        }
        if !(floor.is_finite() && floor >= 0.0) {
            return Err(Error::invalid(
                "phase_lag.guard_floor",
                format!("must be a finite number >= 0, got {floor}"),
            ));
        }
        Ok(Self {
            factor,
            floor,
            min: 0.0,
            max: 0.0,
            trip: None,
            frozen: false,
        })
    }

    /// Check the inputs of a sub-step; returns `false` (and trips) if one is not finite.
    pub fn admit(&mut self, target: f64, measured_prev: f64) -> bool {
        if self.trip.is_some() {
            return false;
        }
        if !(target.is_finite() && measured_prev.is_finite()) {
            self.trip = Some(GuardTrip::NonFiniteInput);
            return false;
        }
        if !self.frozen {
            self.min = self.min.min(target);
            self.max = self.max.max(target);
        }
        true
    }

    /// While frozen (the compensator is a fixed linear filter, e.g. during the amplification-
    /// matrix analysis) only finiteness is checked: the bound is not, and the range is not updated.
    pub fn set_frozen(&mut self, frozen: bool) {
        self.frozen = frozen;
    }

    /// `|h Δu|` allowed now.
    pub fn bound(&self) -> f64 {
        self.factor * (self.max - self.min).max(self.floor)
    }

    /// Pass `du` or trip and return 0 (the bound on `|h du|` is not checked while frozen).
    pub fn output(&mut self, du: f64, h: f64) -> f64 {
        if self.trip.is_some() {
            return 0.0;
        }
        if !du.is_finite() {
            self.trip = Some(GuardTrip::NonFiniteCorrection);
            return 0.0;
        }
        if !self.frozen {
            let bound = self.bound();
            if (h * du).abs() > bound {
                self.trip = Some(GuardTrip::Bound {
                    correction: h * du,
                    bound,
                });
                return 0.0;
            }
        }
        du
    }

    pub fn trip(&self) -> Option<GuardTrip> {
        self.trip
    }
    pub fn is_tripped(&self) -> bool {
        self.trip.is_some()
    }
    /// Re-enable and forget the range seen.
    pub fn reset(&mut self) {
        self.min = 0.0;
        self.max = 0.0;
        self.trip = None;
    }
}

/// The ramp `h_j ∈ [0, 1]` of the correction, as a function of the sub-step count `j` (0-based):
/// 0 before `start`; rising linearly over `ramp_in` sub-steps (`h = (j − start + 1)/ramp_in`);
/// 1 until `fade_out = Some((begin, length))` where it falls linearly to 0 over `length`
/// sub-steps (`h = 1 − (j − begin + 1)/length`), 0 after.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ramp {
    pub start: usize,
    pub ramp_in: usize,
    pub fade_out: Option<(usize, usize)>,
}

impl Default for Ramp {
    /// Full compensation from the first sub-step.
    fn default() -> Self {
        Self::full()
    }
}

impl Ramp {
    /// `h = 1` always.
    pub fn full() -> Self {
        Self {
            start: 0,
            ramp_in: 0,
            fade_out: None,
        }
    }
    /// 0 before `start`, then linear to 1 over `ramp_in` sub-steps.
    pub fn new(start: usize, ramp_in: usize) -> Self {
        Self {
            start,
            ramp_in,
            fade_out: None,
        }
    }
    pub fn with_fade_out(mut self, begin: usize, length: usize) -> Self {
        self.fade_out = Some((begin, length));
        self
    }
    pub fn validate(&self) -> Result<()> {
        if let Some((begin, _)) = self.fade_out
            && begin < self.start.saturating_add(self.ramp_in)
        {
            return Err(Error::invalid(
                "phase_lag.fade_out",
                format!(
                    "begins at sub-step {begin}, before the ramp-in ends (sub-step {})",
                    self.start.saturating_add(self.ramp_in)
                ),
            ));
        }
        Ok(())
    }
    /// `h_j`.
    pub fn value(&self, j: usize) -> f64 {
        if j < self.start {
            return 0.0;
        }
        let mut h = if self.ramp_in == 0 {
            1.0
        } else {
            ((j - self.start + 1) as f64 / self.ramp_in as f64).min(1.0)
        };
        if let Some((begin, length)) = self.fade_out
            && j >= begin
        {
            h = if length == 0 {
                0.0
            } else {
                (1.0 - (j - begin + 1) as f64 / length as f64).max(0.0)
            };
        }
        h
    }
    /// First sub-step with `h = 1`.
    pub fn full_from(&self) -> usize {
        self.start.saturating_add(self.ramp_in.saturating_sub(1))
    }
}

/// A fixed-length history of the newest samples (index 0 = newest). Allocation-free after
/// construction.
#[derive(Debug, Clone)]
pub(crate) struct History {
    values: Vec<f64>,
    head: usize,
}

impl History {
    pub(crate) fn new(len: usize) -> Self {
        Self {
            values: vec![0.0; len.max(1)],
            head: 0,
        }
    }
    pub(crate) fn len(&self) -> usize {
        self.values.len()
    }
    pub(crate) fn push(&mut self, v: f64) {
        let n = self.values.len();
        self.head = (self.head + 1) % n;
        self.values[self.head] = v;
    }
    /// The sample `age` pushes ago (0 = newest).
    pub(crate) fn get(&self, age: usize) -> f64 {
        let n = self.values.len();
        debug_assert!(age < n);
        self.values[(self.head + n - age) % n]
    }
    pub(crate) fn set(&mut self, age: usize, v: f64) {
        let n = self.values.len();
        self.values[(self.head + n - age) % n] = v;
    }
    /// Newest first.
    pub(crate) fn write(&self, out: &mut [f64]) {
        for (k, o) in out.iter_mut().enumerate() {
            *o = self.get(k);
        }
    }
    pub(crate) fn read(&mut self, s: &[f64]) {
        for (k, &v) in s.iter().enumerate() {
            self.set(k, v);
        }
    }
}
