//! Offline coupling of the controller with an experimental substructure: one call per step.

#[allow(unused_imports)] // doc links
use super::StopLog;
use super::{ExperimentalSubstructure, SubstepController};
use crate::error::{Error, Result};
use crate::model::ModelRef;
use nalgebra::DVector;

/// Receives every sub-step (for `substeps.csv` or live plots). The default does nothing.
pub trait SubstepObserver {
    fn substep(&mut self, _step: usize, _j: usize, _command: &[f64], _force: &[f64], _displacement: &[f64]) {}
    /// With phase-lag compensation: the tracking error `d − y` and the correction `Δu` of the
    /// sub-step, called just before [`substep`](Self::substep) for the same sub-step.
    fn phase_lag(&mut self, _tracking_error: &[f64], _correction: &[f64]) {}
    /// Against a lab target ([`crate::lab::LabTarget`]): whether this sub-step held the last
    /// measurement (no reply in time) and how many stray replies (late, duplicated,
    /// unexpected, malformed, stale) its exchange discarded; called just before
    /// [`substep`](Self::substep) for the same sub-step.
    fn lab(&mut self, _held: bool, _strays: u64) {}
    /// After a safety stop in step `step`: ramp sub-step `s` (1-based) to the safe position,
    /// numbered `j` after the step's executed sub-steps (see [`StopLog::replay`]).
    #[allow(clippy::too_many_arguments)]
    fn ramp(&mut self, _step: usize, _j: usize, _s: usize, _command: &[f64], _force: &[f64], _displacement: &[f64]) {}
}

impl SubstepObserver for () {}

/// What a step produced, borrowed from the test (no copies).
pub struct StepRecord<'a> {
    pub step: usize,
    pub time: f64,
    pub u: &'a [f64],
    pub v: &'a [f64],
    pub a: &'a [f64],
    pub coupling_force: &'a [f64],
    pub error_force: &'a [f64],
    pub compensation_force: &'a [f64],
    pub measured_displacement: &'a [f64],
}

impl<'a> StepRecord<'a> {
    /// The record of `controller`'s last completed step `step` (shared by every driver of the
    /// controller: offline, remote per-step).
    pub fn of(controller: &'a SubstepController, step: usize, measured_displacement: &'a [f64]) -> Self {
        let s = controller.state();
        StepRecord {
            step,
            time: step as f64 * controller.dt(),
            u: s.u.as_slice(),
            v: s.v.as_slice(),
            a: s.a.as_slice(),
            coupling_force: controller.coupling_force(),
            error_force: controller.error_force(),
            compensation_force: controller.compensation_force(),
            measured_displacement,
        }
    }
}

/// A substructure test: controller + experimental side + ground motion load.
pub struct SubstructureTest {
    pub controller: SubstepController,
    pub site: Box<dyn ExperimentalSubstructure>,
    /// `M ι`: the load is `−M ι a_g`.
    mass_influence: DVector<f64>,
    load: DVector<f64>,
    step: usize,
    measured_force: Vec<f64>,
    measured_displacement: Vec<f64>,
}

impl SubstructureTest {
    pub fn new<'a>(
        model: impl Into<ModelRef<'a>>,
        controller: SubstepController,
        site: Box<dyn ExperimentalSubstructure>,
    ) -> Result<Self> {
        let model = model.into();
        let n_c = controller.n_coupling();
        if site.n_coupling() != n_c {
            return Err(Error::invalid(
                "substructure",
                format!(
                    "the experimental side has {} coupling DOFs but the controller {n_c}",
                    site.n_coupling()
                ),
            ));
        }
        Ok(Self {
            controller,
            site,
            mass_influence: model.effective_mass_vector(),
            load: DVector::zeros(model.n_dofs()),
            step: 0,
            measured_force: vec![0.0; n_c],
            measured_displacement: vec![0.0; n_c],
        })
    }

    /// Advance from `t_i` (ground acceleration `ag_i`) to `t_{i+1}` (`ag_next`).
    pub fn step(&mut self, ag_i: f64, ag_next: f64, observer: &mut impl SubstepObserver) -> Result<()> {
        // f_l,i+1 = −M ι a_g(t_{i+1})
        self.load.copy_from(&self.mass_influence);
        self.load.scale_mut(-ag_next);
        self.controller.begin_step(&self.load);
        let k = self.controller.substeps();
        let dtau = self.controller.dt() / k as f64;
        for j in 1..=k {
            let ag = super::substep_ground_acceleration(ag_i, ag_next, j, k);
            let command = self.controller.next_command();
            let result = self.site.substep(
                command,
                ag,
                dtau,
                &mut self.measured_force,
                &mut self.measured_displacement,
            );
            if let Err(e) = result {
                if let Some(log) = self.site.take_stop_log() {
                    log.replay(self.step + 1, j, observer);
                }
                return Err(self.stopped(e));
            }
            if let Some(p) = self.site.phase_lag() {
                observer.phase_lag(p.tracking_error(), p.correction());
            }
            if let Some(s) = self.site.lab_stats() {
                observer.lab(s.last_held, s.last_strays);
            }
            observer.substep(
                self.step + 1,
                j,
                self.controller.command(),
                &self.measured_force,
                &self.measured_displacement,
            );
            if let Some(true_force) = self.site.true_force() {
                self.controller.feedback_true(true_force);
            }
            self.controller.feedback(&self.measured_force);
        }
        self.controller.finish_step();
        self.step += 1;
        if !self.controller.state().is_finite() || self.measured_force.iter().any(|f| !f.is_finite()) {
            return Err(Error::Diverged {
                step: self.step,
                time: self.step as f64 * self.controller.dt(),
                reason: "the response is no longer finite (NaN or overflow)".into(),
            });
        }
        Ok(())
    }

    /// Length of the full algorithm state: controller, then experimental side.
    pub fn state_len(&self) -> usize {
        self.controller.state_len() + self.site.state_len()
    }
    pub fn write_state(&self, out: &mut [f64]) {
        let n = self.controller.state_len();
        self.controller.write_state(&mut out[..n]);
        self.site.write_state(&mut out[n..]);
    }
    pub fn read_state(&mut self, state: &[f64]) {
        let n = self.controller.state_len();
        self.controller.read_state(&state[..n]);
        self.site.read_state(&state[n..]);
    }

    /// The experimental side failed during step `self.step + 1`: a controlled stop (a safety
    /// stop reported by the site keeps its reason).
    fn stopped(&self, e: Error) -> Error {
        stopped_at(self.step + 1, self.controller.dt(), e)
    }

    pub fn steps_done(&self) -> usize {
        self.step
    }

    pub fn record(&self) -> StepRecord<'_> {
        StepRecord::of(&self.controller, self.step, &self.measured_displacement)
    }
}

/// The experimental side failed during step `step` (time step `dt`): a controlled stop at that
/// step (a safety stop reported by the site keeps its reason). Shared by every driver, so a
/// stop reports the same step offline and in real time.
pub(crate) fn stopped_at(step: usize, dt: f64, e: Error) -> Error {
    let time = step as f64 * dt;
    match e {
        Error::Stopped { reason, .. } => Error::Stopped { step, time, reason },
        other => Error::Stopped {
            step,
            time,
            reason: format!("experimental side failed: {other}"),
        },
    }
}
