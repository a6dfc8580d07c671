//! What the real-time runner needs of the controller it drives, beyond the step phases of
//! [`CouplingController`]: the numerical thread's overlapped work and the real-time thread's
//! coupling loop. Two implementations:
//!
//! * [`SubstepController`] (the sub-step algorithm): `W` of the next predictor during the
//!   sub-steps, `x̂_c = W_c + H f^{(k−1)} + G_cc f_u` on the real-time thread, hysteretic springs
//!   through the one-sub-step pipeline (module docs of [`crate::realtime`]).
//! * [`ExplicitController`] (CR / KR-α, docs/theory.md §2.9): the step's right-hand side
//!   without its last force and `W_c = u_{i+1,c} + Δt v_{i+1,c} + P rhs` during the sub-steps,
//!   the next target `x_c = W_c + H f^{(k)}` on the real-time thread (n_c × n_c work between
//!   the last sub-step and the next); the springs are evaluated at `u_α`, known when the step
//!   begins, so no pipeline is needed.

use super::overlap::{CouplingLoop, OverlapPredictor};
use crate::error::{Error, Result};
use crate::model::ModelRef;
use crate::substructure::{CouplingController, ErrorForceSpec, ExplicitController, SubstepController};
use nalgebra::{DMatrix, DVector};

/// A controller the real-time runner can drive (see the module docs).
pub trait RealtimeController: CouplingController + Sized {
    /// The numerical thread's work state (set up once, no allocation afterwards).
    type Overlap: Send;
    /// Refuse a model that is not the test's, or a setting the runner cannot mirror.
    fn check_realtime(&self, model: ModelRef<'_>) -> Result<()>;
    /// Hysteretic springs through the one-sub-step pipeline.
    fn uses_pipeline(&self) -> bool;
    /// Set up the overlap (before the run; allocates).
    fn overlap(&mut self) -> Result<Self::Overlap>;
    /// The real-time thread's coupling loop for the current step (it has begun).
    fn coupling_loop(&self, overlap: &Self::Overlap) -> CouplingLoop;
    /// Inside step `m − 1`: the known part of step `m`'s coupling target into `w_c`
    /// (`load_after` is `f_l` at `t_{m+1}`). `false`: the pipeline posts it later.
    fn precompute(&mut self, overlap: &mut Self::Overlap, load_after: &DVector<f64>, w_c: &mut [f64]) -> bool;
    /// The real-time thread's results of the step: `f^{(k−1)}`, `f^{(k)}`, the last command and
    /// the noise-free forces. Then [`CouplingController::finish_step`] (unless the pipeline
    /// closed the step) completes it.
    fn take_end(&mut self, before: &[f64], last: &[f64], command: &[f64], truth: Option<(&[f64], &[f64])>);
    /// Begin the next step (`load_next` is `f_l` at its end; `before` is `f^{(k−1)}` of the step
    /// just finished).
    fn begin_next(&mut self, overlap: &mut Self::Overlap, before: &[f64], load_next: &DVector<f64>);
    /// The ideal error force of the last step, if kept.
    fn ideal_error_force(&self) -> Option<&[f64]>;
    /// The last noise-free force the controller was given.
    fn true_force_last(&self) -> &[f64];
    /// Pipeline only: close the step's kinematics with `f^{(k−1)}` and `d^{(k)}`.
    fn pipeline_close(&mut self, _before: &[f64], _command: &[f64], _more: bool) {}
    /// Pipeline only: the next predictor's coupling rows with the springs' share.
    fn pipeline_coupling<'o>(&mut self, _overlap: &'o mut Self::Overlap) -> &'o [f64] {
        &[]
    }
    /// Pipeline only: the rest of the springs' share, off the critical path.
    fn pipeline_subtract(&mut self, _overlap: &mut Self::Overlap) {}
}

impl RealtimeController for SubstepController {
    type Overlap = OverlapPredictor;

    fn check_realtime(&self, model: ModelRef<'_>) -> Result<()> {
        let n = model.n_dofs();
        let core = self.newmark_core();
        // The controller's M ι must be the given model's (the load the runner applies).
        let same_mass = core.n_dofs() == n && {
            let iota = match model {
                ModelRef::Dense(m) => m.influence.clone(),
                ModelRef::Sparse(m) => m.influence.clone(),
            };
            let m_iota = model.effective_mass_vector();
            let probe = core.mass_damping_columns(1.0, 0.0, &DMatrix::from_column_slice(n, 1, iota.as_slice()));
            probe
                .iter()
                .zip(m_iota.iter())
                .all(|(a, b)| (a - b).abs() <= 1e-12 * m_iota.amax().max(1e-300))
        };
        if !same_mass {
            return Err(Error::invalid(
                "realtime.model",
                "is not the model the substructure test was built from",
            ));
        }
        if matches!(self.compensation().spec, ErrorForceSpec::Arx { .. }) {
            // The estimation changes the last command of each step from the identified model;
            // the real-time coupling loop only mirrors the plain ramp.
            return Err(Error::invalid(
                "substructure.error_force.kind",
                "\"arx\" is not supported by the real-time runner yet (use none or pid)",
            ));
        }
        Ok(())
    }
    fn uses_pipeline(&self) -> bool {
        self.is_nonlinear()
    }
    fn overlap(&mut self) -> Result<OverlapPredictor> {
        Ok(OverlapPredictor::new(self))
    }
    fn coupling_loop(&self, overlap: &OverlapPredictor) -> CouplingLoop {
        CouplingLoop::new(self, overlap)
    }
    fn precompute(&mut self, overlap: &mut OverlapPredictor, load_after: &DVector<f64>, w_c: &mut [f64]) -> bool {
        overlap.precompute(self, load_after);
        if self.is_nonlinear() {
            return false;
        }
        let w = overlap.known();
        for (i, &c) in self.coupling_dofs().iter().enumerate() {
            w_c[i] = w[c];
        }
        true
    }
    fn take_end(&mut self, before: &[f64], last: &[f64], command: &[f64], truth: Option<(&[f64], &[f64])>) {
        // The noise-free forces first: closing the forces computes the ideal error force.
        self.set_true_results(truth);
        if self.is_nonlinear() {
            self.close_with_last_force(last);
        } else {
            self.set_substep_results(before, last, command);
        }
    }
    fn begin_next(&mut self, overlap: &mut OverlapPredictor, before: &[f64], _load_next: &DVector<f64>) {
        let x = overlap.predictor(self, before);
        self.begin_step_with_predictor(x);
    }
    fn ideal_error_force(&self) -> Option<&[f64]> {
        SubstepController::ideal_error_force(self)
    }
    fn true_force_last(&self) -> &[f64] {
        SubstepController::true_force_last(self)
    }
    fn pipeline_close(&mut self, before: &[f64], command: &[f64], more: bool) {
        self.close_kinematics_with(before, command, more);
    }
    fn pipeline_coupling<'o>(&mut self, overlap: &'o mut OverlapPredictor) -> &'o [f64] {
        overlap.deviation_coupling(self)
    }
    fn pipeline_subtract(&mut self, overlap: &mut OverlapPredictor) {
        overlap.subtract_deviation(self);
    }
}

/// The numerical side of a CR / KR-α test in real time: `Pᵀ` and `H` of
/// [`ExplicitController::target_maps`].
pub struct ExplicitOverlap {
    p_t: DMatrix<f64>,
    h_cc: DMatrix<f64>,
}

impl RealtimeController for ExplicitController {
    type Overlap = ExplicitOverlap;

    fn check_realtime(&self, model: ModelRef<'_>) -> Result<()> {
        if self.state().u.len() != model.n_dofs() {
            return Err(Error::invalid(
                "realtime.model",
                "is not the model the substructure test was built from",
            ));
        }
        Ok(())
    }
    fn uses_pipeline(&self) -> bool {
        false
    }
    fn overlap(&mut self) -> Result<ExplicitOverlap> {
        let (p_t, h_cc) = self.target_maps()?;
        Ok(ExplicitOverlap { p_t, h_cc })
    }
    fn coupling_loop(&self, overlap: &ExplicitOverlap) -> CouplingLoop {
        CouplingLoop::explicit(self, &overlap.h_cc)
    }
    fn precompute(&mut self, overlap: &mut ExplicitOverlap, _load_after: &DVector<f64>, w_c: &mut [f64]) -> bool {
        self.prepare_step();
        self.known_target(&overlap.p_t, w_c);
        true
    }
    fn take_end(&mut self, before: &[f64], last: &[f64], command: &[f64], _truth: Option<(&[f64], &[f64])>) {
        self.set_substep_results(before, last, command);
    }
    fn begin_next(&mut self, _overlap: &mut ExplicitOverlap, _before: &[f64], load_next: &DVector<f64>) {
        self.begin_step(load_next);
    }
    fn ideal_error_force(&self) -> Option<&[f64]> {
        None
    }
    fn true_force_last(&self) -> &[f64] {
        ExplicitController::true_force_last(self)
    }
}
