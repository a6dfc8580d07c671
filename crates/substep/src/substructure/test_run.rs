//! Offline coupling of the controller with an experimental substructure: one call per step.

#[allow(unused_imports)] // doc links
use super::StopLog;
use super::{ExperimentalSubstructure, SubstepController};
use crate::error::{Error, Result};
use crate::integrate::Kinematics;
use crate::model::{ModelRef, Springs};
use nalgebra::DVector;

/// The numerical side of a substructure test in step phases: [`begin_step`](Self::begin_step),
/// `k_sub` times [`next_command`](Self::next_command) / [`feedback`](Self::feedback), then
/// [`finish_step`](Self::finish_step); none of them allocates. The sub-step algorithm
/// ([`SubstepController`]) and the model-based explicit schemes
/// ([`super::ExplicitController`]) implement it, so both drive the same experimental sides.
pub trait CouplingController: Send {
    /// Begin step `i → i+1` with the external load `f_l,i+1` at its end.
    fn begin_step(&mut self, load_next: &DVector<f64>);
    /// The command of the next sub-step \[m\], one value per coupling DOF.
    fn next_command(&mut self) -> &[f64];
    /// The force measured at the end of that sub-step \[N\].
    fn feedback(&mut self, measured_force: &[f64]);
    /// Its noise-free value, when the experimental side knows it. Default: ignored.
    fn feedback_true(&mut self, _true_force: &[f64]) {}
    /// Close the step after its last sub-step.
    fn finish_step(&mut self);
    fn substeps(&self) -> usize;
    fn dt(&self) -> f64;
    fn coupling_dofs(&self) -> &[usize];
    fn n_coupling(&self) -> usize {
        self.coupling_dofs().len()
    }
    /// The last command \[m\].
    fn command(&self) -> &[f64];
    /// The state of the numerical DOFs after the last completed step.
    fn state(&self) -> &Kinematics;
    /// The hysteretic springs of a nonlinear numerical substructure, if any.
    fn springs(&self) -> Option<&Springs>;
    /// Measured coupling force of the last completed step \[N\].
    fn coupling_force(&self) -> &[f64];
    /// Error force `f^{(k)} − f^{(k−1)}` of the last completed step \[N\].
    fn error_force(&self) -> &[f64];
    /// Compensation force entering the next step \[N\] (zero without error-force compensation).
    fn compensation_force(&self) -> &[f64];
    /// `Ok` if one step is a linear map of the state (for the amplification-matrix analysis);
    /// otherwise an error naming the nonlinear part.
    fn is_linear(&self) -> Result<()>;
    /// Length of the algorithm state (amplification-matrix analysis, checkpoints).
    fn state_len(&self) -> usize;
    fn write_state(&self, out: &mut [f64]);
    fn read_state(&mut self, state: &[f64]);
}

impl CouplingController for SubstepController {
    fn begin_step(&mut self, load_next: &DVector<f64>) {
        SubstepController::begin_step(self, load_next)
    }
    fn next_command(&mut self) -> &[f64] {
        SubstepController::next_command(self)
    }
    fn feedback(&mut self, measured_force: &[f64]) {
        SubstepController::feedback(self, measured_force)
    }
    fn feedback_true(&mut self, true_force: &[f64]) {
        SubstepController::feedback_true(self, true_force)
    }
    fn finish_step(&mut self) {
        SubstepController::finish_step(self)
    }
    fn substeps(&self) -> usize {
        SubstepController::substeps(self)
    }
    fn dt(&self) -> f64 {
        SubstepController::dt(self)
    }
    fn coupling_dofs(&self) -> &[usize] {
        SubstepController::coupling_dofs(self)
    }
    fn command(&self) -> &[f64] {
        SubstepController::command(self)
    }
    fn state(&self) -> &Kinematics {
        SubstepController::state(self)
    }
    fn springs(&self) -> Option<&Springs> {
        SubstepController::springs(self)
    }
    fn coupling_force(&self) -> &[f64] {
        SubstepController::coupling_force(self)
    }
    fn error_force(&self) -> &[f64] {
        SubstepController::error_force(self)
    }
    fn compensation_force(&self) -> &[f64] {
        SubstepController::compensation_force(self)
    }
    fn is_linear(&self) -> Result<()> {
        SubstepController::is_linear(self)
    }
    fn state_len(&self) -> usize {
        SubstepController::state_len(self)
    }
    fn write_state(&self, out: &mut [f64]) {
        SubstepController::write_state(self, out)
    }
    fn read_state(&mut self, state: &[f64]) {
        SubstepController::read_state(self, state)
    }
}

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
    pub fn of(controller: &'a impl CouplingController, step: usize, measured_displacement: &'a [f64]) -> Self {
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

/// A substructure test: controller (the sub-step algorithm unless said otherwise) +
/// experimental side + ground motion load.
pub struct SubstructureTest<C: CouplingController = SubstepController> {
    pub controller: C,
    pub site: Box<dyn ExperimentalSubstructure>,
    /// `M ι`: the load is `−M ι a_g`.
    mass_influence: DVector<f64>,
    load: DVector<f64>,
    step: usize,
    measured_force: Vec<f64>,
    measured_displacement: Vec<f64>,
}

impl<C: CouplingController> SubstructureTest<C> {
    pub fn new<'a>(
        model: impl Into<ModelRef<'a>>,
        controller: C,
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
