//! The sub-step controller (docs/theory.md §3).
//!
//! One step `i → i+1` runs in phases so that a real-time loop can call the sub-steps at its
//! own rate: [`SubstepController::begin_step`] (predictor), then `k_sub` times
//! [`SubstepController::next_command`] / [`SubstepController::feedback`], then
//! [`SubstepController::finish_step`]. None of them allocates.

use super::compensation::{ErrorForceCompensation, ErrorForceSpec};
use super::estimation::{EstimationOutcome, EstimationStats, ForceEstimation};
use crate::error::{Error, Result};
use crate::integrate::{Kinematics, NewmarkCore};
use crate::model::ModelRef;
use nalgebra::{DMatrix, DVector};

/// Parameters of the sub-step algorithm.
#[derive(Debug, Clone, PartialEq)]
pub struct SubstepSettings {
    /// Time step Δt \[s\].
    pub dt: f64,
    /// Newmark β, γ (average acceleration ¼, ½ by default).
    pub beta: f64,
    pub gamma: f64,
    /// Sub-steps per step `k_sub ≥ 1`.
    pub substeps: usize,
    /// Coupling DOFs, 0-based, distinct.
    pub coupling_dofs: Vec<usize>,
    pub error_force: ErrorForceSpec,
}

pub struct SubstepController {
    core: NewmarkCore,
    k_sub: usize,
    coupling: Vec<usize>,
    /// `G_{:,c} = K̂⁻¹ Sᵀ` (n × n_c) and its coupling rows `G_cc`.
    gain_columns: DMatrix<f64>,
    gain_cc: DMatrix<f64>,
    state: Kinematics,
    next: Kinematics,
    /// Predictor `x̂` of the current step, its coupling part, and that of the previous step.
    predictor: DVector<f64>,
    predictor_c: DVector<f64>,
    predictor_c_prev: DVector<f64>,
    /// `f_c,i` = `f^{(k)}` of the last step (the measured coupling force).
    force: DVector<f64>,
    /// `f^{(j)}` (latest measured in this step) and `f^{(j−1)}`.
    force_last: DVector<f64>,
    force_before: DVector<f64>,
    /// Compensation force `f_u` per coupling DOF and the last error force `e`.
    compensation_force: Vec<f64>,
    error_force: Vec<f64>,
    compensation: ErrorForceCompensation,
    command: DVector<f64>,
    /// Sub-steps done in the current step.
    substep: usize,
    /// Error-force compensation by estimation and the ideal error force (see the block at the end).
    est: EstimationState,
    /// Hysteretic springs of a nonlinear numerical substructure (operator splitting, see
    /// [`SubstepController::set_springs`]), the displacement predictor `ũ` they are evaluated
    /// at and their deviation force `d(ũ)` of the current step.
    nonlinear: Option<Box<Splitting>>,
}

/// The explicit part of the operator splitting (docs/theory.md §14.4).
struct Splitting {
    springs: crate::model::Springs,
    predictor: DVector<f64>,
    deviation: DVector<f64>,
}

/// Refuse an empty list of coupling DOFs (0-based), one out of range of `n` DOFs, or one listed
/// twice (every controller checks its coupling DOFs with this).
pub(crate) fn check_coupling_dofs(coupling_dofs: &[usize], n: usize) -> Result<()> {
    if coupling_dofs.is_empty() {
        return Err(Error::invalid(
            "substructure.coupling_dofs",
            "must list at least one DOF",
        ));
    }
    for (k, &c) in coupling_dofs.iter().enumerate() {
        if c >= n {
            return Err(Error::invalid(
                "substructure.coupling_dofs",
                format!("DOF {} is out of range (the model has DOFs 1..={n})", c + 1),
            ));
        }
        if coupling_dofs[..k].contains(&c) {
            return Err(Error::invalid(
                "substructure.coupling_dofs",
                format!("DOF {} is listed twice", c + 1),
            ));
        }
    }
    Ok(())
}

impl SubstepController {
    /// Set up for `model` at rest with initial load `load0 = f_l(0)` (initial coupling force 0).
    /// `model` is a `&StructuralModel`, `&SparseModel` or `&Model` (dense or sparse storage).
    pub fn new<'a>(model: impl Into<ModelRef<'a>>, settings: &SubstepSettings, load0: &DVector<f64>) -> Result<Self> {
        let model = model.into();
        let n = model.n_dofs();
        if settings.substeps == 0 {
            return Err(Error::invalid("substructure.substeps", "must be at least 1"));
        }
        let n_c = settings.coupling_dofs.len();
        check_coupling_dofs(&settings.coupling_dofs, n)?;
        let mut core = NewmarkCore::new(model, settings.dt, settings.beta, settings.gamma)?;
        // Gain columns by n_c solves with the factorised K̂ (never the full inverse).
        let mut gain_columns = DMatrix::zeros(n, n_c);
        for (k, &c) in settings.coupling_dofs.iter().enumerate() {
            gain_columns[(c, k)] = 1.0;
        }
        core.solve_columns_in_place(&mut gain_columns);
        let gain_cc = DMatrix::from_fn(n_c, n_c, |r, k| gain_columns[(settings.coupling_dofs[r], k)]);
        let state = Kinematics::at_rest(model, load0)?;
        let est = EstimationState::new(&settings.error_force, &gain_cc, &settings.coupling_dofs, load0)?;
        Ok(Self {
            core,
            k_sub: settings.substeps,
            coupling: settings.coupling_dofs.clone(),
            gain_columns,
            gain_cc,
            next: state.clone(),
            state,
            predictor: DVector::zeros(n),
            predictor_c: DVector::zeros(n_c),
            predictor_c_prev: DVector::zeros(n_c),
            force: DVector::zeros(n_c),
            force_last: DVector::zeros(n_c),
            force_before: DVector::zeros(n_c),
            compensation_force: vec![0.0; n_c],
            error_force: vec![0.0; n_c],
            compensation: ErrorForceCompensation::new(settings.error_force, n_c)?,
            command: DVector::zeros(n_c),
            substep: 0,
            est,
            nonlinear: None,
        })
    }

    /// Make the numerical substructure nonlinear: `r(u) = K₀ u + d(u)` with the model's
    /// stiffness as `K₀` and `springs` the hysteretic part (docs/theory.md §14.4). Each step then
    /// evaluates the springs at the Newmark displacement predictor
    /// `ũ_{i+1} = u_i + Δt v_i + Δt² (½ − β) a_i`, commits them there and moves `d(ũ_{i+1})` to
    /// the right-hand side of the predictor; `K̂` and the gains stay those of `K₀` (operator
    /// splitting in the manner of Nakashima's OS method: no iterations, one spring update and
    /// the usual solves per step, no allocation). Carrying the unbalance `d(u_{i+1}) −
    /// d(ũ_{i+1})` into the next step was tried and dropped: it makes the splitting unstable
    /// for `k_t/k₀ < 0.25` at `Ω > 0.5` (docs/theory.md §14.5).
    pub fn set_springs(&mut self, springs: crate::model::Springs) {
        let n = self.state.u.len();
        self.nonlinear = Some(Box::new(Splitting {
            springs,
            predictor: DVector::zeros(n),
            deviation: DVector::zeros(n),
        }));
    }

    /// The springs of a nonlinear numerical substructure (committed at the last predictor).
    pub fn springs(&self) -> Option<&crate::model::Springs> {
        self.nonlinear.as_ref().map(|s| &s.springs)
    }

    /// `d(ũ_{i+1})` into the splitting's work vector (springs committed at `ũ_{i+1}`).
    fn split_nonlinear_part(&mut self) {
        let Some(nl) = self.nonlinear.as_deref_mut() else {
            return;
        };
        let (dt, beta) = (self.core.c.dt, self.core.c.beta);
        let s = &self.state;
        nl.predictor.copy_from(&s.u);
        nl.predictor.axpy(dt, &s.v, 1.0);
        nl.predictor.axpy(dt * dt * (0.5 - beta), &s.a, 1.0);
        nl.springs.set_trial(nl.predictor.as_slice());
        nl.springs.commit();
        nl.deviation.fill(0.0);
        nl.springs.add_deviation(1.0, nl.deviation.as_mut_slice());
    }

    pub fn dt(&self) -> f64 {
        self.core.c.dt
    }
    /// The factorisation of `K̂` (see [`NewmarkCore::solver`]).
    pub fn solver(&self) -> String {
        self.core.solver()
    }
    /// Bytes of the factor the predictor solve reads (see [`NewmarkCore::solve_bytes`]).
    pub fn solve_bytes(&self) -> usize {
        self.core.solve_bytes()
    }
    /// Sweep a sparse `K̂` on two cores from now on (see [`NewmarkCore::enable_second_core`]).
    pub fn enable_second_core(&mut self) -> bool {
        self.core.enable_second_core()
    }
    pub fn substeps(&self) -> usize {
        self.k_sub
    }
    pub fn n_coupling(&self) -> usize {
        self.coupling.len()
    }
    pub fn coupling_dofs(&self) -> &[usize] {
        &self.coupling
    }
    pub fn state(&self) -> &Kinematics {
        &self.state
    }
    /// `G_cc`, the gain between coupling force and coupling displacement [m/N].
    pub fn gain_cc(&self) -> &DMatrix<f64> {
        &self.gain_cc
    }
    /// `G_{:,c}`.
    pub fn gain_columns(&self) -> &DMatrix<f64> {
        &self.gain_columns
    }
    /// Measured coupling force `f_c,i` of the last completed step \[N\].
    pub fn coupling_force(&self) -> &[f64] {
        self.force.as_slice()
    }
    /// Error force `e = f^{(k)} − f^{(k−1)}` of the last completed step \[N\].
    pub fn error_force(&self) -> &[f64] {
        &self.error_force
    }
    /// Compensation force `f_u` that enters the next predictor \[N\].
    pub fn compensation_force(&self) -> &[f64] {
        &self.compensation_force
    }
    /// The last command `d^{(j)}` \[m\].
    pub fn command(&self) -> &[f64] {
        self.command.as_slice()
    }
    /// Coupling part of the current predictor `x̂_c` \[m\].
    pub fn predictor_c(&self) -> &[f64] {
        self.predictor_c.as_slice()
    }
    /// Coupling part of the previous step's predictor `x̂_c^{(i)}` \[m\], where the command ramp
    /// of the current step starts (for a site that runs the sub-steps itself).
    pub fn predictor_c_prev(&self) -> &[f64] {
        self.predictor_c_prev.as_slice()
    }

    /// Step 1: predictor `x̂ = K̂⁻¹ (F̂_i + f_l,i+1 + Sᵀ f_u,i)`.
    pub fn begin_step(&mut self, load_next: &DVector<f64>) {
        self.split_nonlinear_part();
        self.core.effective_load(&self.state, &mut self.predictor);
        self.predictor += load_next;
        if let Some(nl) = &self.nonlinear {
            self.predictor -= &nl.deviation;
        }
        for (k, &c) in self.coupling.iter().enumerate() {
            self.predictor[c] += self.compensation_force[k];
        }
        self.core.solve_in_place(&mut self.predictor);
        for (k, &c) in self.coupling.iter().enumerate() {
            self.predictor_c[k] = self.predictor[c];
        }
        self.force_last.copy_from(&self.force);
        self.force_before.copy_from(&self.force);
        self.substep = 0;
        self.estimation_begin_step(load_next);
    }

    /// Step 2: the command `d^{(j)} = (1 − r_j) x̂_c^{(i)} + r_j x̂_c + G_cc f^{(j−1)}` of the next
    /// sub-step `j`, `r_j = j/k`.
    pub fn next_command(&mut self) -> &[f64] {
        debug_assert!(self.substep < self.k_sub, "next_command called after the last sub-step");
        let r = (self.substep + 1) as f64 / self.k_sub as f64;
        self.command.copy_from(&self.predictor_c_prev);
        self.command.scale_mut(1.0 - r);
        self.command.axpy(r, &self.predictor_c, 1.0);
        self.command.gemv(1.0, &self.gain_cc, &self.force_last, 1.0);
        if self.substep + 1 == self.k_sub {
            self.estimated_last_command();
        }
        self.command.as_slice()
    }

    /// The force `f^{(j)}` measured at the end of sub-step `j`.
    pub fn feedback(&mut self, measured_force: &[f64]) {
        std::mem::swap(&mut self.force_before, &mut self.force_last);
        self.force_last.copy_from_slice(measured_force);
        self.observe_substep();
        self.substep += 1;
    }

    /// Steps 3–5: close the step with `f^{(k−1)}`, Newmark kinematics, error force and the
    /// compensation for the next step.
    pub fn finish_step(&mut self) {
        debug_assert_eq!(self.substep, self.k_sub, "finish_step before all sub-steps");
        self.close_kinematics();
        self.close_forces();
    }

    /// The first half of [`finish_step`](Self::finish_step): the state `u_{i+1}`, `v_{i+1}`,
    /// `a_{i+1}`, which needs only `f^{(k−1)}` and the last command `d^{(k)}` — known once
    /// sub-step `k − 1` has been measured, one sub-step before the step ends (the real-time
    /// runner evaluates a nonlinear substructure's springs then, docs/realtime.md).
    fn close_kinematics(&mut self) {
        // u_{i+1} = x̂ + G_{:,c} f_close with f_close = f^{(k−1)} (or the estimate f̂^{(k)});
        // on the coupling DOFs this is d^{(k)}.
        self.select_closing_force();
        self.next.u.copy_from(&self.predictor);
        self.next.u.gemv(1.0, &self.gain_columns, &self.est.closing_force, 1.0);
        for (k, &c) in self.coupling.iter().enumerate() {
            self.next.u[c] = self.command[k];
        }
        self.core.update_kinematics(&self.state, &mut self.next);
        std::mem::swap(&mut self.state, &mut self.next);
    }

    /// The second half of [`finish_step`](Self::finish_step), with `f^{(k)}`: the error force
    /// and the compensation force for the next step.
    fn close_forces(&mut self) {
        for k in 0..self.coupling.len() {
            self.error_force[k] = self.force_last[k] - self.est.closing_force[k];
        }
        self.finish_ideal_error_force();
        self.force.copy_from(&self.force_last);
        self.predictor_c_prev.copy_from(&self.predictor_c);
        self.compensation
            .update(&self.error_force, self.core.c.dt, &mut self.compensation_force);
    }

    /// Residual of the equation of motion with the last measured force,
    /// `f_l + Sᵀ f_u,i + Sᵀ f_c,i+1 − (M a + C v + K u)`, for the state after `finish_step`;
    /// `compensation_used` is the `f_u` that entered this step's predictor. (A check of
    /// docs/theory.md §3.7; allocates, not for the hot path.)
    pub fn equilibrium_residual(&self, load: &DVector<f64>, compensation_used: &[f64]) -> DVector<f64> {
        let s = &self.state;
        let mut r = load.clone();
        for (k, &c) in self.coupling.iter().enumerate() {
            r[c] += compensation_used[k] + self.force[k];
        }
        let mut internal = DVector::zeros(r.len());
        self.core.internal_force(s, &mut internal);
        if let Some(nl) = &self.nonlinear {
            internal += &nl.deviation;
        }
        r - internal
    }

    /// Length of the algorithm state (for the amplification-matrix analysis and checkpoints):
    /// `[u, v, a, x̂_c^{(i)}, f_c, f_u, compensator]`.
    pub fn state_len(&self) -> usize {
        3 * self.state.u.len()
            + 3 * self.coupling.len()
            + self.compensation.state_len()
            + self.nonlinear.as_ref().map_or(0, |nl| nl.springs.state_len())
    }
    pub fn write_state(&self, out: &mut [f64]) {
        let (n, n_c) = (self.state.u.len(), self.coupling.len());
        out[..n].copy_from_slice(self.state.u.as_slice());
        out[n..2 * n].copy_from_slice(self.state.v.as_slice());
        out[2 * n..3 * n].copy_from_slice(self.state.a.as_slice());
        let at = 3 * n;
        out[at..at + n_c].copy_from_slice(self.predictor_c_prev.as_slice());
        out[at + n_c..at + 2 * n_c].copy_from_slice(self.force.as_slice());
        out[at + 2 * n_c..at + 3 * n_c].copy_from_slice(&self.compensation_force);
        let at = at + 3 * n_c;
        let m = self.compensation.state_len();
        self.compensation.write_state(&mut out[at..at + m]);
        if let Some(nl) = &self.nonlinear {
            nl.springs.write_state(&mut out[at + m..]);
        }
    }
    pub fn read_state(&mut self, s: &[f64]) {
        let (n, n_c) = (self.state.u.len(), self.coupling.len());
        self.state.u.copy_from_slice(&s[..n]);
        self.state.v.copy_from_slice(&s[n..2 * n]);
        self.state.a.copy_from_slice(&s[2 * n..3 * n]);
        let at = 3 * n;
        self.predictor_c_prev.copy_from_slice(&s[at..at + n_c]);
        self.force.copy_from_slice(&s[at + n_c..at + 2 * n_c]);
        self.compensation_force.copy_from_slice(&s[at + 2 * n_c..at + 3 * n_c]);
        let at = at + 3 * n_c;
        let m = self.compensation.state_len();
        self.compensation.read_state(&s[at..at + m]);
        if let Some(nl) = &mut self.nonlinear {
            nl.springs.read_state(&s[at + m..]);
        }
        self.substep = 0;
    }
}

// -------------------------------------------------------------------------------------------------
// Overlapped stepping for the real-time runner (`crate::realtime`).
//
// Added for the real-time runner; the methods above are unchanged. A real-time loop runs the
// sub-steps (`k_sub` commands and measurements on the coupling DOFs) on its own thread from a
// copy of the coupling state, while another thread keeps this controller and does the n-sized
// work of the next step during the sub-steps of the current one. The split rests on the next
// predictor being affine in `f^{(k−1)}` and `f_u` of the current step:
//
//     x̂_{i+2} = W_{i+2} + H f^{(k−1)} + G_{:,c} f_u,i+1,
//     W_{i+2} = K̂⁻¹ (F̂(ū, v̄, ā) + f_l,i+2),   H = K̂⁻¹ (α M + β′ C) G_{:,c},
//
// where `ū = x̂_{i+1}` and `v̄`, `ā` are the Newmark kinematics of `ū` (what `u_{i+1}`, `v_{i+1}`,
// `a_{i+1}` would be with `f^{(k−1)} = 0`), `α = a0 (1 + a2 a7 + a3)`, `β′ = a1 + a0 (a4 a7 + a5)`.

impl SubstepController {
    /// The Newmark core: matrices, constants and the factorised `K̂`.
    pub fn newmark_core(&self) -> &NewmarkCore {
        &self.core
    }
    /// The error-force compensation state (a real-time loop runs the same update on a copy).
    pub fn compensation(&self) -> &ErrorForceCompensation {
        &self.compensation
    }
    /// The full predictor `x̂` of the current step.
    pub fn predictor(&self) -> &DVector<f64> {
        &self.predictor
    }

    /// `H = K̂⁻¹ (α M + β′ C) G_{:,c}` (n × n_c), the sensitivity of the next predictor to
    /// `f^{(k−1)}` of the current step. Allocates; call once at set-up.
    pub fn overlap_gain(&mut self) -> DMatrix<f64> {
        let a = &self.core.c.a;
        let alpha = a[0] * (1.0 + a[2] * a[7] + a[3]);
        let beta = a[1] + a[0] * (a[4] * a[7] + a[5]);
        let mut h = self.core.mass_damping_columns(alpha, beta, &self.gain_columns);
        self.core.solve_columns_in_place(&mut h);
        h
    }

    /// The part of the next predictor that is known once the current step has begun:
    /// `out = W = K̂⁻¹ (F̂(ū, v̄, ā) + load_after)` with `ū` the current predictor and `v̄`, `ā` its
    /// Newmark kinematics; `load_after` is `f_l` at the end of the *next* step. Call between
    /// `begin_step*` and `finish_step`; does not allocate and does not change the step's result
    /// (it uses the work state that `finish_step` overwrites).
    pub fn overlap_known_predictor(&mut self, load_after: &DVector<f64>, out: &mut DVector<f64>) {
        self.next.u.copy_from(&self.predictor);
        self.core.update_kinematics(&self.state, &mut self.next);
        self.core.effective_load(&self.next, out);
        *out += load_after;
        self.core.solve_in_place(out);
    }

    /// Take the sub-step results of the current step from a loop that ran the sub-steps on its
    /// own copy of the coupling state: `before = f^{(k−1)}`, `last = f^{(k)}` and the last command
    /// `d^{(k)}`. Then [`SubstepController::finish_step`] closes the step as if the sub-steps had
    /// been run through [`SubstepController::next_command`] / [`SubstepController::feedback`].
    pub fn set_substep_results(&mut self, before: &[f64], last: &[f64], last_command: &[f64]) {
        self.force_before.copy_from_slice(before);
        self.force_last.copy_from_slice(last);
        self.command.copy_from_slice(last_command);
        self.substep = self.k_sub;
    }

    /// The noise-free forces `f°^{(k−1)}`, `f°^{(k)}` of the step's last two sub-steps when the
    /// sub-steps ran elsewhere (the real-time runner's coupling loop; `None`: the site reported
    /// none) — what [`feedback_true`](Self::feedback_true) leaves behind offline, for the
    /// [ideal error force](Self::ideal_error_force) of [`finish_step`](Self::finish_step).
    pub fn set_true_results(&mut self, before_and_last: Option<(&[f64], &[f64])>) {
        match before_and_last {
            Some((before, last)) => {
                self.est.true_before.copy_from_slice(before);
                self.est.true_last.copy_from_slice(last);
                self.est.true_seen = true;
            }
            None => self.est.true_seen = false,
        }
        self.est.true_pending = false;
    }

    /// The last noise-free force the controller was given (zeros before any).
    pub fn true_force_last(&self) -> &[f64] {
        &self.est.true_last
    }

    /// Whether the numerical substructure has hysteretic springs (the real-time runner then runs
    /// the one-sub-step pipeline of docs/realtime.md).
    pub fn is_nonlinear(&self) -> bool {
        self.nonlinear.is_some()
    }

    /// The real-time runner's first half of [`finish_step`](Self::finish_step), run as soon as
    /// sub-step `k − 1` has been measured: the state `u_{i+1}`, `v_{i+1}`, `a_{i+1}` from
    /// `before = f^{(k−1)}` and the last command `d^{(k)}`; then, if `split` (a next step
    /// follows), the springs at the next step's displacement predictor `ũ_{i+2}` — what
    /// [`begin_step`](Self::begin_step) of the next step does first, with the same state, so the
    /// result is the offline one. [`close_with_last_force`](Self::close_with_last_force) ends
    /// the step.
    pub fn close_kinematics_with(&mut self, before: &[f64], last_command: &[f64], split: bool) {
        self.force_before.copy_from_slice(before);
        self.command.copy_from_slice(last_command);
        self.substep = self.k_sub;
        self.close_kinematics();
        if split {
            self.split_nonlinear_part();
        }
    }

    /// The second half of [`finish_step`](Self::finish_step) after
    /// [`close_kinematics_with`](Self::close_kinematics_with): `last = f^{(k)}`, the error force
    /// and the compensation force.
    pub fn close_with_last_force(&mut self, last: &[f64]) {
        self.force_last.copy_from_slice(last);
        self.close_forces();
    }

    /// The springs' deviation force `d(ũ)` at the current predictor `ũ` (n; `None` for a linear
    /// substructure).
    pub fn deviation(&self) -> Option<&DVector<f64>> {
        self.nonlinear.as_ref().map(|nl| &nl.deviation)
    }

    /// `out = K̂⁻¹ d(ũ)`, the springs' share of the predictor (zeros for a linear substructure).
    pub fn deviation_response(&mut self, out: &mut DVector<f64>) {
        match &self.nonlinear {
            Some(nl) => out.copy_from(&nl.deviation),
            None => out.fill(0.0),
        }
        self.core.solve_in_place(out);
    }

    /// Step 1 with a predictor assembled elsewhere (`x̂ = W + H f^{(k−1)} + G_{:,c} f_u`, see the
    /// comment above this `impl`); otherwise as [`SubstepController::begin_step`].
    pub fn begin_step_with_predictor(&mut self, predictor: &DVector<f64>) {
        self.predictor.copy_from(predictor);
        for (k, &c) in self.coupling.iter().enumerate() {
            self.predictor_c[k] = self.predictor[c];
        }
        self.force_last.copy_from(&self.force);
        self.force_before.copy_from(&self.force);
        self.substep = 0;
    }
}

// ---------------------------------------------------------------------------------------------
// Error-force compensation by estimation (docs/theory.md §4.4) and the ideal error force of virtual
// tests (§4.7).
// ---------------------------------------------------------------------------------------------

/// State of the estimation and of the noise-free bookkeeping; see [`super::estimation`].
struct EstimationState {
    estimation: Option<ForceEstimation>,
    /// The force the step was closed with: `f^{(k−1)}` (plain) or `f̂^{(k)}` (estimation).
    closing_force: DVector<f64>,
    /// Noise-free forces `f°^{(j)}` and `f°^{(j−1)}`, if the site reports them.
    true_last: Vec<f64>,
    true_before: Vec<f64>,
    /// Set by `feedback_true` for the coming `feedback`.
    true_pending: bool,
    /// External load on the coupling DOFs at the start and the end of the step (`f_l,i`,
    /// `f_l,i+1`), interpolated over the sub-steps: the estimation's load input `w`.
    load_prev: Vec<f64>,
    load_next: Vec<f64>,
    /// Whether the last sub-step of the step came with a noise-free force.
    true_seen: bool,
    ideal_error_force: Vec<f64>,
}

impl EstimationState {
    fn new(spec: &ErrorForceSpec, gain_cc: &DMatrix<f64>, coupling: &[usize], load0: &DVector<f64>) -> Result<Self> {
        let n_c = gain_cc.nrows();
        let estimation = match *spec {
            ErrorForceSpec::Arx { order, lambda, p0 } => {
                spec.validate()?;
                Some(ForceEstimation::new(order, lambda, p0, gain_cc)?)
            }
            _ => None,
        };
        Ok(Self {
            estimation,
            closing_force: DVector::zeros(n_c),
            true_last: vec![0.0; n_c],
            true_before: vec![0.0; n_c],
            true_pending: false,
            load_prev: vec![0.0; n_c],
            load_next: coupling.iter().map(|&c| load0[c]).collect(),
            true_seen: false,
            ideal_error_force: vec![f64::NAN; n_c],
        })
    }
}

impl SubstepController {
    /// The noise-free force `f°^{(j)}` of the coming [`feedback`](Self::feedback) (virtual tests:
    /// [`crate::transfer::VirtualLab::true_force`]). Optional; with it the controller computes the
    /// [ideal error force](Self::ideal_error_force).
    pub fn feedback_true(&mut self, true_force: &[f64]) {
        std::mem::swap(&mut self.est.true_before, &mut self.est.true_last);
        self.est.true_last.copy_from_slice(true_force);
        self.est.true_pending = true;
    }

    /// The ideal value of the error force of the last step (and, with P = 1 or the estimation,
    /// of the compensation force): the same formula evaluated with the noise-free forces in place
    /// of the measured ones, with the same commands and model parameters —
    /// `f°^{(k)} − f°^{(k−1)}` for none/PID and for steps the estimation closed with the plain
    /// algorithm, `f°^{(k)} − [Σ A_l f°^{(k−l)} + Σ B_l d^{(k−l)}]` for steps it closed with the
    /// estimate. `None` if the site did not report noise-free forces
    /// ([`feedback_true`](Self::feedback_true)).
    pub fn ideal_error_force(&self) -> Option<&[f64]> {
        self.est.true_seen.then_some(self.est.ideal_error_force.as_slice())
    }

    /// The coupling force the last step was closed with: `f^{(k−1)}`, or the estimate `f̂^{(k)}`
    /// (error force `e = f^{(k)} −` this).
    pub fn closing_force(&self) -> &[f64] {
        self.est.closing_force.as_slice()
    }

    /// Counts of how the estimation closed the steps (`None` unless `error_force` is `arx`).
    pub fn estimation_stats(&self) -> Option<EstimationStats> {
        self.est.estimation.as_ref().map(|e| e.stats)
    }

    /// How the last step was closed by the estimation (`None` unless `error_force` is `arx`).
    pub fn estimation_outcome(&self) -> Option<EstimationOutcome> {
        self.est.estimation.as_ref().map(|e| e.outcome)
    }

    /// The identified `[A_1 … A_n, B_0 … B_n, C_0 … C_n]` (B in N/m, C for the load input,
    /// dimensionless) of coupling DOF `m` (`None` unless `error_force` is `arx`). Allocates.
    pub fn estimation_parameters(&self, m: usize) -> Option<Vec<f64>> {
        self.est.estimation.as_ref().map(|e| {
            let mut out = vec![0.0; e.n_params()];
            e.parameters(m, &mut out);
            out
        })
    }

    /// `Ok` if one step is a linear map of [`write_state`](Self::write_state)'s state (for the
    /// amplification-matrix analysis). The estimation adapts on line, switches between the
    /// estimate and the plain algorithm, and its histories are not part of the state: refused.
    pub fn is_linear(&self) -> Result<()> {
        if self.nonlinear.as_ref().is_some_and(|nl| !nl.springs.is_linear()) {
            return Err(Error::invalid(
                "structure.storeys.hysteresis",
                "the numerical substructure is nonlinear; the linear analysis uses its initial stiffness \
                 (analyze stability --vary stiffness_ratio) instead",
            ));
        }
        if self.est.estimation.is_some() {
            return Err(Error::invalid(
                "substructure.error_force",
                "error_force.kind = \"arx\" (estimation) identifies its model on line and switches to \
                 the plain algorithm when its guards trip; the linear analysis does not support it",
            ));
        }
        Ok(())
    }

    /// Last sub-step: replace the plain command by the one consistent with the estimate, if the
    /// estimation is on and ready.
    fn estimated_last_command(&mut self) {
        if let Some(est) = self.est.estimation.as_mut() {
            est.last_command(
                &self.predictor_c,
                &self.est.load_next,
                &self.gain_cc,
                &self.force_last,
                &mut self.command,
            );
        }
    }

    fn estimation_begin_step(&mut self, load_next: &DVector<f64>) {
        if self.est.estimation.is_none() {
            return;
        }
        std::mem::swap(&mut self.est.load_prev, &mut self.est.load_next);
        for (k, &c) in self.coupling.iter().enumerate() {
            self.est.load_next[k] = load_next[c];
        }
    }

    /// After `f^{(j)}` is stored in `force_last`: update the estimators.
    fn observe_substep(&mut self) {
        let with_true = self.est.true_pending;
        self.est.true_pending = false;
        self.est.true_seen = with_true;
        if let Some(est) = self.est.estimation.as_mut() {
            // Load input of sub-step j = substep + 1, linear over the step.
            let r = (self.substep + 1) as f64 / self.k_sub as f64;
            for m in 0..self.coupling.len() {
                let w = (1.0 - r) * self.est.load_prev[m] + r * self.est.load_next[m];
                let ft = with_true.then(|| self.est.true_last[m]);
                est.observe(m, self.command[m], w, self.force_last[m], ft);
            }
        }
    }

    fn select_closing_force(&mut self) {
        match self.est.estimation.as_mut() {
            Some(est) if est.active => self.est.closing_force.copy_from_slice(&est.closing),
            _ => self.est.closing_force.copy_from(&self.force_before),
        }
        if let Some(est) = self.est.estimation.as_mut() {
            est.count_step();
        }
    }

    fn finish_ideal_error_force(&mut self) {
        let est = &mut self.est;
        if !est.true_seen {
            est.ideal_error_force.iter_mut().for_each(|v| *v = f64::NAN);
            return;
        }
        let active = est.estimation.as_ref().is_some_and(|e| e.active);
        for m in 0..est.ideal_error_force.len() {
            let closing = match &est.estimation {
                Some(e) if active => e.ideal_prediction(m),
                _ => est.true_before[m],
            };
            est.ideal_error_force[m] = est.true_last[m] - closing;
        }
        if let Some(e) = est.estimation.as_mut() {
            e.active = false;
        }
    }
}
