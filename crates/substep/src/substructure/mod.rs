//! The substructure algorithm with sub-step control (docs/theory.md §3) and error-force
//! compensation (docs/theory.md §4).
//!
//! [`SubstepController`] is the numerical side: it integrates the numerical substructure with
//! Newmark in effective-stiffness form and drives the coupling DOFs through `k_sub` sub-steps
//! per step. The experimental side is anything implementing [`ExperimentalSubstructure`]: the
//! virtual lab of [`crate::transfer`], or a remote site. [`SubstructureTest`] couples the two
//! for offline runs; a real-time runner calls the controller's step phases itself.

mod compensation;
mod controller;
mod estimation;
mod explicit;
mod report;
mod safety;
mod test_run;

pub use compensation::{ErrorForceCompensation, ErrorForceSpec};
pub use controller::{SubstepController, SubstepSettings};
pub use estimation::{EstimationOutcome, EstimationStats};
pub use explicit::ExplicitController;
pub use report::{GuardTrip, LabStats, PhaseLagReport, StabilityAction, StabilitySettings};
pub use safety::{LimitedSite, MAX_RAMP_SUBSTEPS, MAX_RAMP_TIME, RampClock, SafetyLimits, StopLog};
pub(crate) use test_run::stopped_at;
pub use test_run::{CouplingController, StepRecord, SubstepObserver, SubstructureTest};

use crate::error::Result;

/// Ground acceleration at the start and end of sub-step `j` (1-based) of `k`, interpolated
/// linearly between `a_g(t_i) = ag_i` and `a_g(t_{i+1}) = ag_next` (docs/theory.md §1.3). Every driver
/// of the controller (offline, real time, remote per-step sites, benchmarks) uses this one, so
/// their results agree bit for bit.
pub fn substep_ground_acceleration(ag_i: f64, ag_next: f64, j: usize, k: usize) -> (f64, f64) {
    let (r0, r1) = ((j - 1) as f64 / k as f64, j as f64 / k as f64);
    (ag_i + r0 * (ag_next - ag_i), ag_i + r1 * (ag_next - ag_i))
}

/// The experimental side as seen by the controller.
pub trait ExperimentalSubstructure: Send {
    /// Number of coupling DOFs (actuators / load cells).
    fn n_coupling(&self) -> usize;
    /// Execute one sub-step of length `dtau` \[s\]: the actuators move towards `command` \[m\]
    /// (one value per coupling DOF) while the ground acceleration ramps from `ag.0` to `ag.1`
    /// [m/s²]. On return, `force` holds the measured force on the numerical substructure \[N\]
    /// and `displacement` the measured coupling displacement \[m\].
    fn substep(
        &mut self,
        command: &[f64],
        ag: (f64, f64),
        dtau: f64,
        force: &mut [f64],
        displacement: &mut [f64],
    ) -> Result<()>;
    /// `Ok` if the experimental side is a linear map of its state and inputs (for the
    /// amplification-matrix analysis); otherwise an error naming the nonlinear part.
    fn is_linear(&self) -> Result<()>;
    fn state_len(&self) -> usize;
    fn write_state(&self, out: &mut [f64]);
    fn read_state(&mut self, state: &[f64]);

    /// The noise-free force on the numerical substructure at the end of the last sub-step, if the
    /// side knows it (virtual lab; used for the ideal error force). Default: `None`.
    fn true_force(&self) -> Option<&[f64]> {
        None
    }
    /// The noise-free achieved coupling displacement at the end of the last sub-step, if known
    /// (virtual lab). Default: `None`.
    fn true_displacement(&self) -> Option<&[f64]> {
        None
    }
    /// Phase-lag compensation of this side, if it has one ([`crate::compensate::CompensatedSite`]).
    fn phase_lag(&self) -> Option<&dyn crate::substructure::PhaseLagReport> {
        None
    }
    /// After a controlled stop of a [`LimitedSite`]: what it did (tripping sub-step and ramp),
    /// once. Default: `None`.
    fn take_stop_log(&mut self) -> Option<StopLog> {
        None
    }
    /// Ask for the controlled stop from outside (operator, stability indicator): the next
    /// sub-step is not executed; the actuators ramp from the last command to the safe position
    /// as after a tripped limit, and that sub-step returns [`crate::Error::Stopped`] with
    /// `reason`. `false` if this side has no [`LimitedSite`] to ramp with (default); wrappers
    /// forward it to the side they wrap.
    fn request_stop(&mut self, _reason: &str) -> bool {
        false
    }
    /// Pace the ramp of a controlled stop with `clock` (a real-time runner's schedule; `None`:
    /// as fast as the side runs, offline). `false` if this side has no [`LimitedSite`]
    /// (default); wrappers forward it.
    fn pace_ramp(&mut self, _clock: Option<Box<dyn RampClock>>) -> bool {
        false
    }
    /// The link statistics of a lab target ([`crate::lab::LabTarget`]), if this side is one or
    /// wraps one (wrappers forward it). Default: `None`.
    fn lab_stats(&self) -> Option<&crate::substructure::LabStats> {
        None
    }
}
