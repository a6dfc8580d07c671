//! The overlap of the numerical step with the sub-steps (the math is in the module docs of
//! [`crate::realtime`]): [`OverlapPredictor`] is the numerical side (n-sized work, one thread),
//! [`CouplingLoop`] the real-time side (coupling-sized work only).

use crate::substructure::{CouplingController, ErrorForceCompensation, ExplicitController, SubstepController};
use nalgebra::{DMatrix, DVector};

/// `out[r] = w[r] + Σ_j h[r, j] p[j] + Σ_j g[r, j] f_u[j]` for the rows `rows` of `h` and `g`
/// (`out` and `w` indexed like `rows`). Both sides use this one function, so the coupling rows
/// that the real-time loop computes are bit-identical to those of the full predictor.
fn assemble(
    w: &[f64],
    h: &DMatrix<f64>,
    g: &DMatrix<f64>,
    rows: impl Iterator<Item = usize>,
    p: &[f64],
    f_u: &[f64],
    out: &mut [f64],
) {
    for (i, r) in rows.enumerate() {
        let mut x = w[i];
        for (j, pj) in p.iter().enumerate() {
            x += h[(r, j)] * pj;
        }
        for (j, fj) in f_u.iter().enumerate() {
            x += g[(r, j)] * fj;
        }
        out[i] = x;
    }
}

/// The numerical side of the overlapped step: `H` and the work vectors. Per step, with the
/// controller between `begin_step*` and `finish_step` of step `i → i+1`:
///
/// 1. [`OverlapPredictor::precompute`] — `W = K̂⁻¹(F̂(ū, v̄, ā) + f_l,i+2)` (all the n×n work),
///    while the sub-steps of the step run;
/// 2. once `f^{(k−1)}`, `f^{(k)}` are measured: `set_substep_results` + `finish_step` on the
///    controller, then [`OverlapPredictor::predictor`] — `x̂ = W + H f^{(k−1)} + G_{:,c} f_u,i+1`
///    (n × n_c work) — and `begin_step_with_predictor`.
///
/// Nothing here allocates after [`OverlapPredictor::new`].
pub struct OverlapPredictor {
    h: DMatrix<f64>,
    w: DVector<f64>,
    x: DVector<f64>,
    /// Nonlinear substructure: `K̂⁻¹ d(ũ)` and the coupling rows `W_c − G_{:,c}ᵀ d` posted to the
    /// real-time thread.
    deviation: DVector<f64>,
    w_c: Vec<f64>,
}

impl OverlapPredictor {
    pub fn new(controller: &mut SubstepController) -> Self {
        let n = controller.state().u.len();
        Self {
            h: controller.overlap_gain(),
            w: DVector::zeros(n),
            x: DVector::zeros(n),
            deviation: DVector::zeros(if controller.is_nonlinear() { n } else { 0 }),
            w_c: vec![0.0; controller.n_coupling()],
        }
    }

    /// `H = K̂⁻¹ (α M + β′ C) G_{:,c}` (n × n_c).
    pub fn gain(&self) -> &DMatrix<f64> {
        &self.h
    }

    /// Step 1: the known part `W` of the next predictor; `load_after` is `f_l` at the end of the
    /// next step. Call after the current step has begun.
    pub fn precompute(&mut self, controller: &mut SubstepController, load_after: &DVector<f64>) {
        controller.overlap_known_predictor(load_after, &mut self.w);
    }

    /// `W` of the last [`OverlapPredictor::precompute`].
    pub fn known(&self) -> &DVector<f64> {
        &self.w
    }

    /// Nonlinear substructure, once the springs are at the next step's `ũ`
    /// ([`SubstepController::close_kinematics_with`]): the coupling rows of the known part with
    /// the springs' share, `W_c − [K̂⁻¹ d]_c`, for the real-time thread. `K̂` is symmetric, so the
    /// coupling rows of `K̂⁻¹` are the columns of `G_{:,c}`: `[K̂⁻¹ d]_c = G_{:,c}ᵀ d`, `n · n_c`
    /// work instead of a solve — the part that has to fit one sub-step.
    pub fn deviation_coupling(&mut self, controller: &SubstepController) -> &[f64] {
        let g = controller.gain_columns();
        let d = controller.deviation().expect("a nonlinear substructure");
        for (i, &c) in controller.coupling_dofs().iter().enumerate() {
            self.w_c[i] = self.w[c] - g.column(i).dot(d);
        }
        &self.w_c
    }

    /// Then, off the critical path: `W ← W − K̂⁻¹ d` (one solve), its coupling rows set to the
    /// values [`deviation_coupling`](Self::deviation_coupling) posted, so that both threads
    /// assemble the next predictor from the same numbers.
    pub fn subtract_deviation(&mut self, controller: &mut SubstepController) {
        controller.deviation_response(&mut self.deviation);
        self.w -= &self.deviation;
        for (i, &c) in controller.coupling_dofs().iter().enumerate() {
            self.w[c] = self.w_c[i];
        }
    }

    /// Step 2, after `finish_step`: the next predictor `W + H f^{(k−1)} + G_{:,c} f_u` with
    /// `before = f^{(k−1)}` of the step just finished and the controller's new `f_u`.
    pub fn predictor(&mut self, controller: &SubstepController, before: &[f64]) -> &DVector<f64> {
        assemble(
            self.w.as_slice(),
            &self.h,
            controller.gain_columns(),
            0..self.w.len(),
            before,
            controller.compensation_force(),
            self.x.as_mut_slice(),
        );
        &self.x
    }
}

/// The coupling-DOF side of the controller as the real-time loop runs it: the command ramp,
/// the measured forces of the step, the error-force compensation (on a copy of the controller's,
/// run with the same inputs) and the coupling rows of the next predictor. `next_command` and
/// `feedback` repeat [`SubstepController::next_command`] / [`SubstepController::feedback`]
/// operation for operation.
pub struct CouplingLoop {
    k: usize,
    dt: f64,
    gain_cc: DMatrix<f64>,
    /// Coupling rows of `H` (n_c × n_c).
    h_cc: DMatrix<f64>,
    predictor_c_prev: DVector<f64>,
    predictor_c: DVector<f64>,
    predictor_c_next: DVector<f64>,
    has_next: bool,
    /// `f_c` of the last completed step, and `f^{(j)}`, `f^{(j−1)}` of the current one.
    force: DVector<f64>,
    force_last: DVector<f64>,
    force_before: DVector<f64>,
    command: DVector<f64>,
    hold: DVector<f64>,
    compensation: ErrorForceCompensation,
    compensation_force: Vec<f64>,
    error_force: Vec<f64>,
    substep: usize,
    /// A CR / KR-α test: the next target follows from `f^{(k)}` (not `f^{(k−1)}`), and the ramp
    /// has no gain term.
    explicit: bool,
}

impl CouplingLoop {
    /// The coupling loop of a CR / KR-α test ([`ExplicitController`]) whose current step has
    /// begun: the ramp `d^{(j)} = (1 − r) x_prev + r x` to the step's target, and the next target
    /// `x_next = W_c + H f^{(k)}` (`h_cc` from [`ExplicitController::target_maps`]).
    pub fn explicit(controller: &ExplicitController, h_cc: &DMatrix<f64>) -> Self {
        let n_c = controller.n_coupling();
        let force = DVector::from_column_slice(controller.coupling_force());
        Self {
            k: controller.substeps(),
            dt: controller.dt(),
            gain_cc: DMatrix::zeros(n_c, n_c),
            h_cc: h_cc.clone(),
            predictor_c_prev: DVector::from_column_slice(controller.target_prev()),
            predictor_c: DVector::from_column_slice(controller.target()),
            predictor_c_next: DVector::zeros(n_c),
            has_next: false,
            force_last: force.clone(),
            force_before: force.clone(),
            force,
            command: DVector::zeros(n_c),
            hold: DVector::zeros(n_c),
            compensation: ErrorForceCompensation::none(n_c),
            compensation_force: vec![0.0; n_c],
            error_force: vec![0.0; n_c],
            substep: 0,
            explicit: true,
        }
    }

    /// From a controller whose current step has begun (`begin_step`).
    pub fn new(controller: &SubstepController, overlap: &OverlapPredictor) -> Self {
        let n_c = controller.n_coupling();
        let c = controller.coupling_dofs();
        let h = overlap.gain();
        Self {
            k: controller.substeps(),
            dt: controller.dt(),
            gain_cc: controller.gain_cc().clone(),
            h_cc: DMatrix::from_fn(n_c, n_c, |r, j| h[(c[r], j)]),
            predictor_c_prev: DVector::from_column_slice(controller.predictor_c_prev()),
            predictor_c: DVector::from_column_slice(controller.predictor_c()),
            predictor_c_next: DVector::zeros(n_c),
            has_next: false,
            force: DVector::from_column_slice(controller.coupling_force()),
            force_last: DVector::from_column_slice(controller.coupling_force()),
            force_before: DVector::from_column_slice(controller.coupling_force()),
            command: DVector::zeros(n_c),
            hold: DVector::zeros(n_c),
            compensation: controller.compensation().clone(),
            compensation_force: controller.compensation_force().to_vec(),
            error_force: vec![0.0; n_c],
            substep: 0,
            explicit: false,
        }
    }

    pub fn has_next(&self) -> bool {
        self.has_next
    }
    pub fn force_before(&self) -> &[f64] {
        self.force_before.as_slice()
    }
    pub fn force_last(&self) -> &[f64] {
        self.force_last.as_slice()
    }
    pub fn command(&self) -> &[f64] {
        self.command.as_slice()
    }

    /// Start the next step with the predictor taken by [`CouplingLoop::take_predictor`].
    pub fn begin_next(&mut self) {
        debug_assert!(self.has_next);
        std::mem::swap(&mut self.predictor_c_prev, &mut self.predictor_c);
        std::mem::swap(&mut self.predictor_c, &mut self.predictor_c_next);
        self.has_next = false;
        self.force_last.copy_from(&self.force);
        self.force_before.copy_from(&self.force);
        self.substep = 0;
    }

    /// As [`SubstepController::next_command`] (or [`ExplicitController`]'s ramp).
    pub fn next_command(&mut self) -> &[f64] {
        let r = (self.substep + 1) as f64 / self.k as f64;
        if self.explicit {
            for k in 0..self.command.len() {
                self.command[k] = r * self.predictor_c[k] + (1.0 - r) * self.predictor_c_prev[k];
            }
            return self.command.as_slice();
        }
        self.command.copy_from(&self.predictor_c_prev);
        self.command.scale_mut(1.0 - r);
        self.command.axpy(r, &self.predictor_c, 1.0);
        self.command.gemv(1.0, &self.gain_cc, &self.force_last, 1.0);
        self.command.as_slice()
    }

    /// As [`SubstepController::feedback`].
    pub fn feedback(&mut self, measured_force: &[f64]) {
        std::mem::swap(&mut self.force_before, &mut self.force_last);
        self.force_last.copy_from_slice(measured_force);
        self.substep += 1;
    }

    /// After the last sub-step: error force and the compensation for the next step (as in
    /// [`SubstepController::finish_step`]).
    pub fn end_step(&mut self) {
        debug_assert_eq!(self.substep, self.k);
        for k in 0..self.error_force.len() {
            self.error_force[k] = self.force_last[k] - self.force_before[k];
        }
        self.force.copy_from(&self.force_last);
        self.compensation
            .update(&self.error_force, self.dt, &mut self.compensation_force);
    }

    /// The coupling rows of the next predictor from the coupling rows `w_c` of `W`
    /// (after [`CouplingLoop::end_step`]).
    pub fn take_predictor(&mut self, w_c: &[f64]) {
        let forces = if self.explicit {
            &self.force_last
        } else {
            &self.force_before
        };
        assemble(
            w_c,
            &self.h_cc,
            &self.gain_cc,
            0..w_c.len(),
            forces.as_slice(),
            &self.compensation_force,
            self.predictor_c_next.as_mut_slice(),
        );
        self.has_next = true;
    }

    /// Command for hold sub-step `h` (0-based) while the next predictor is late: the previous
    /// ramp extrapolated by one sub-step, `d^{(k)} + (x̂_c − x̂_c^{prev})/k`, then held there.
    pub fn hold_command(&mut self, h: usize) -> &[f64] {
        if h == 0 {
            self.hold.copy_from(&self.command);
            self.hold.axpy(1.0 / self.k as f64, &self.predictor_c, 1.0);
            self.hold.axpy(-1.0 / self.k as f64, &self.predictor_c_prev, 1.0);
        }
        self.hold.as_slice()
    }
}
