//! A site driven through a discrete tracking controller in the RTHS benchmark's structure: each
//! command `d` of the sub-step algorithm (after the phase-lag compensator, if any) becomes the
//! actuator command `u_j = C(z)(F(z) d_j − y_{j−1})`, with `C(z)` (feedback) and the optional
//! `F(z)` (feedforward, e.g. a phase lead; 1 if absent) the Tustin discretisations of continuous
//! `C(s)`, `F(s)` at the sub-step length, and `y_{j−1}` the displacement measured at the end of
//! the previous sub-step (the newest one a real controller has when it issues `u_j`). With an
//! integrator in `C(s)` (PI), `y → d` at steady state, whatever the actuator's static gain.

use super::discrete::DiscreteFilter;
use super::lti::TransferFunction;
use crate::error::{Error, Result};
use crate::substructure::ExperimentalSubstructure;

pub struct ControlledSite {
    filters: Vec<DiscreteFilter>,
    feedforward: Vec<DiscreteFilter>,
    measured_prev: Vec<f64>,
    command: Vec<f64>,
    inner: Box<dyn ExperimentalSubstructure>,
}

impl ControlledSite {
    /// One copy of `controller` per coupling DOF of `inner`, discretised at `dtau` \[s\]; `what`
    /// names the controller in errors (an unstable discretisation is refused).
    pub fn new(
        inner: Box<dyn ExperimentalSubstructure>,
        what: &str,
        controller: &TransferFunction,
        feedforward: Option<&TransferFunction>,
        dtau: f64,
    ) -> Result<Self> {
        let n_c = inner.n_coupling();
        let filter = DiscreteFilter::tustin(what, controller, dtau)?;
        let feedforward = match feedforward {
            Some(f) => vec![DiscreteFilter::tustin(&format!("{what}.feedforward"), f, dtau)?; n_c],
            None => Vec::new(),
        };
        Ok(Self {
            filters: vec![filter; n_c],
            feedforward,
            measured_prev: vec![0.0; n_c],
            command: vec![0.0; n_c],
            inner,
        })
    }

    /// The actuator commands of the last sub-step.
    pub fn command_sent(&self) -> &[f64] {
        &self.command
    }
}

impl ExperimentalSubstructure for ControlledSite {
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
        for (i, f) in self.filters.iter_mut().enumerate() {
            let target = match self.feedforward.get_mut(i) {
                Some(ff) => ff.step(command[i]),
                None => command[i],
            };
            self.command[i] = f.step(target - self.measured_prev[i]);
        }
        if let Some(i) = self.command.iter().position(|u| !u.is_finite()) {
            return Err(Error::numerical(
                "substructure.controller",
                format!("the command of coupling DOF #{} is not finite", i + 1),
            ));
        }
        self.inner.substep(&self.command, ag, dtau, force, displacement)?;
        self.measured_prev.copy_from_slice(displacement);
        Ok(())
    }

    fn true_force(&self) -> Option<&[f64]> {
        self.inner.true_force()
    }
    fn true_displacement(&self) -> Option<&[f64]> {
        self.inner.true_displacement()
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
        self.inner.is_linear()
    }

    /// `[inner state, y_{j−1} per DOF, feedback filter states…, feedforward filter states…]`.
    fn state_len(&self) -> usize {
        self.inner.state_len()
            + self.measured_prev.len()
            + self
                .filters
                .iter()
                .chain(&self.feedforward)
                .map(|f| f.state().len())
                .sum::<usize>()
    }
    fn write_state(&self, out: &mut [f64]) {
        let n = self.inner.state_len();
        self.inner.write_state(&mut out[..n]);
        let n_c = self.measured_prev.len();
        out[n..n + n_c].copy_from_slice(&self.measured_prev);
        let mut at = n + n_c;
        for f in self.filters.iter().chain(&self.feedforward) {
            let l = f.state().len();
            out[at..at + l].copy_from_slice(f.state());
            at += l;
        }
    }
    fn read_state(&mut self, s: &[f64]) {
        let n = self.inner.state_len();
        self.inner.read_state(&s[..n]);
        let n_c = self.measured_prev.len();
        self.measured_prev.copy_from_slice(&s[n..n + n_c]);
        let mut at = n + n_c;
        for f in self.filters.iter_mut().chain(self.feedforward.iter_mut()) {
            let l = f.state().len();
            f.set_state(&s[at..at + l]);
            at += l;
        }
    }
}
