//! An experimental substructure with phase-lag compensation of its actuators.

use super::{GuardTrip, PhaseLagCompensator, PhaseLagReport, Ramp};
use crate::error::{Error, Result};
use crate::substructure::ExperimentalSubstructure;

/// Wraps an experimental substructure and replaces each command `d` by `d_cmd = d + h Δu`
/// (docs/theory.md §6.1), one [`PhaseLagCompensator`] per coupling DOF; the measured force and displacement
/// are passed back unchanged.
///
/// The ramp `h` is evaluated at the count of sub-steps executed through the wrapper. While the
/// wrapper is [frozen](Self::set_frozen), the compensators keep their parameters and the ramp
/// holds its value, so the wrapper is a time-invariant linear map of its state (the inner state,
/// the last measured displacement and the compensators' histories) and
/// [`is_linear`](ExperimentalSubstructure::is_linear) is `Ok` if the inner side is linear.
///
/// `S` is the wrapped type; the default `dyn ExperimentalSubstructure` takes any boxed site,
/// a concrete `S` keeps access to it through [`inner`](Self::inner).
pub struct CompensatedSite<S: ExperimentalSubstructure + ?Sized = dyn ExperimentalSubstructure> {
    compensators: Vec<Box<dyn PhaseLagCompensator>>,
    ramp: Ramp,
    count: usize,
    frozen: bool,
    command: Vec<f64>,
    measured_prev: Vec<f64>,
    correction: Vec<f64>,
    tracking_error: Vec<f64>,
    h: f64,
    inner: Box<S>,
}

impl<S: ExperimentalSubstructure + ?Sized> CompensatedSite<S> {
    /// One compensator per coupling DOF of `inner`.
    pub fn new(inner: Box<S>, compensators: Vec<Box<dyn PhaseLagCompensator>>, ramp: Ramp) -> Result<Self> {
        let n_c = inner.n_coupling();
        if compensators.len() != n_c {
            return Err(Error::invalid(
                "phase_lag",
                format!(
                    "needs one compensator per coupling DOF ({n_c}), got {}",
                    compensators.len()
                ),
            ));
        }
        ramp.validate()?;
        Ok(Self {
            compensators,
            ramp,
            count: 0,
            frozen: false,
            command: vec![0.0; n_c],
            measured_prev: vec![0.0; n_c],
            correction: vec![0.0; n_c],
            tracking_error: vec![0.0; n_c],
            h: 0.0,
            inner,
        })
    }

    pub fn inner(&self) -> &S {
        &self.inner
    }
    pub fn inner_mut(&mut self) -> &mut S {
        &mut self.inner
    }
    pub fn compensators(&self) -> &[Box<dyn PhaseLagCompensator>] {
        &self.compensators
    }
    /// Set every compensator's parameters (the analysis at converged parameters; see
    /// [`PhaseLagCompensator::set_parameters`]).
    pub fn set_parameters(&mut self, parameters: &[f64]) {
        for c in &mut self.compensators {
            c.set_parameters(parameters);
        }
    }
    /// `d − y` of the last sub-step per coupling DOF (target minus measured displacement).
    pub fn tracking_error(&self) -> &[f64] {
        &self.tracking_error
    }
    /// `Δu` of the last sub-step per coupling DOF (before the ramp).
    pub fn correction(&self) -> &[f64] {
        &self.correction
    }
    /// The command sent in the last sub-step (`d + h Δu`).
    pub fn command_sent(&self) -> &[f64] {
        &self.command
    }
    /// `h` of the last sub-step.
    pub fn ramp_value(&self) -> f64 {
        self.h
    }
    /// Sub-steps executed so far.
    pub fn substeps(&self) -> usize {
        self.count
    }
    /// Per coupling DOF: why the guard disabled its compensator, if it did.
    pub fn warnings(&self) -> impl Iterator<Item = (usize, super::GuardTrip)> + '_ {
        self.compensators
            .iter()
            .enumerate()
            .filter_map(|(i, c)| c.trip().map(|t| (i, t)))
    }
    pub fn is_frozen(&self) -> bool {
        self.frozen
    }
    /// Freeze (or release) all compensators' parameters and the ramp.
    pub fn set_frozen(&mut self, frozen: bool) {
        self.frozen = frozen;
        for c in &mut self.compensators {
            c.set_frozen(frozen);
        }
    }
}

impl<S: ExperimentalSubstructure + ?Sized> ExperimentalSubstructure for CompensatedSite<S> {
    fn n_coupling(&self) -> usize {
        self.inner.n_coupling()
    }

    fn substep(
        &mut self,
        command: &[f64],
        ag: (f64, f64),
        dtau: f64,
        force: &mut [f64],
        displacement: &mut [f64],
    ) -> Result<()> {
        let h = self.ramp.value(self.count);
        self.h = h;
        for (i, c) in self.compensators.iter_mut().enumerate() {
            let du = c.correction(command[i], self.measured_prev[i], h);
            self.correction[i] = du;
            self.command[i] = command[i] + h * du;
        }
        self.inner.substep(&self.command, ag, dtau, force, displacement)?;
        for i in 0..command.len() {
            self.measured_prev[i] = displacement[i];
            self.tracking_error[i] = command[i] - displacement[i];
        }
        if !self.frozen {
            self.count += 1;
        }
        Ok(())
    }

    fn true_force(&self) -> Option<&[f64]> {
        self.inner.true_force()
    }
    fn true_displacement(&self) -> Option<&[f64]> {
        self.inner.true_displacement()
    }
    fn phase_lag(&self) -> Option<&dyn PhaseLagReport> {
        Some(self)
    }
    fn take_stop_log(&mut self) -> Option<crate::substructure::StopLog> {
        self.inner.take_stop_log()
    }
    fn request_stop(&mut self, reason: &str) -> bool {
        self.inner.request_stop(reason)
    }
    fn lab_stats(&self) -> Option<&crate::substructure::LabStats> {
        self.inner.lab_stats()
    }
    fn pace_ramp(&mut self, clock: Option<Box<dyn crate::substructure::RampClock>>) -> bool {
        self.inner.pace_ramp(clock)
    }

    fn is_linear(&self) -> Result<()> {
        if !self.frozen {
            return Err(Error::invalid(
                "phase_lag",
                "the compensators adapt (or their guard may trip); freeze them for the linear analysis",
            ));
        }
        self.inner.is_linear()
    }

    /// `[inner state, y_{j−1} per DOF, compensator states…]`.
    fn state_len(&self) -> usize {
        self.inner.state_len()
            + self.measured_prev.len()
            + self.compensators.iter().map(|c| c.state_len()).sum::<usize>()
    }
    fn write_state(&self, out: &mut [f64]) {
        let n = self.inner.state_len();
        self.inner.write_state(&mut out[..n]);
        let n_c = self.measured_prev.len();
        out[n..n + n_c].copy_from_slice(&self.measured_prev);
        let mut at = n + n_c;
        for c in &self.compensators {
            let l = c.state_len();
            c.write_state(&mut out[at..at + l]);
            at += l;
        }
    }
    fn read_state(&mut self, s: &[f64]) {
        let n = self.inner.state_len();
        self.inner.read_state(&s[..n]);
        let n_c = self.measured_prev.len();
        self.measured_prev.copy_from_slice(&s[n..n + n_c]);
        let mut at = n + n_c;
        for c in &mut self.compensators {
            let l = c.state_len();
            c.read_state(&s[at..at + l]);
            at += l;
        }
    }
}

impl<S: ExperimentalSubstructure + ?Sized> PhaseLagReport for CompensatedSite<S> {
    fn tracking_error(&self) -> &[f64] {
        &self.tracking_error
    }
    fn correction(&self) -> &[f64] {
        &self.correction
    }
    fn command_sent(&self) -> &[f64] {
        &self.command
    }
    fn ramp_value(&self) -> f64 {
        self.h
    }
    fn kinds(&self) -> Vec<&'static str> {
        self.compensators.iter().map(|c| c.kind()).collect()
    }
    fn trips(&self) -> Vec<(usize, GuardTrip)> {
        self.warnings().collect()
    }
}
