//! Substructure tests with a model-based explicit scheme, CR or KR-α (docs/theory.md §2.9),
//! beside the sub-step algorithm.
//!
//! [`crate::integrate::KrAlpha`] gives the displacement of the next step before its restoring
//! force is known, so the coupling DOFs are commanded to it directly, with no gain and no
//! prediction of the force:
//!
//! ```text
//! u_{i+1} = u_i + Δt v_i + (½ + γ) Δt² α₁ a_i,      v_{i+1} = v_i + Δt α₁ a_i,
//! d^{(j)} = u_{i,c} + (j/k) (u_{i+1,c} − u_{i,c}),   j = 1 … k_sub,
//! M (I − α₃) a_{i+1} = f_{l,α} − K₀ u_α − d(u_α) − C v_α − M α₃ a_i + Sᵀ f_{c,α},
//! f_{c,α} = (1 − α_f) f_{c,i} + α_f f^{(k)},
//! ```
//!
//! where `f^{(k)}` is the force measured at the end of the last sub-step (at `u_{i+1,c}` with an
//! ideal actuator) and `f_{c,i}` that of the step before. The numerical substructure's springs
//! are evaluated at `u_α` as in the monolithic scheme (one-point form); the specimen's force is
//! weighted between the two measured ones (two-point form, OpenSees' `KRAlphaExplicit_TP` for an
//! experimental element: a specimen cannot be held at `u_α` and then moved on to `u_{i+1}`).
//! For CR `α_f = 1` and both forms coincide; for a linear specimen they coincide for every ρ∞,
//! so an ideal test of a linear specimen is the monolithic scheme on the assembled model.
//!
//! The ramp is linear from the last step's target; the sub-steps only pace the actuators (the
//! sub-step algorithm's gain `G_cc` feedback is absent). Error-force compensation does not
//! apply; the error force `f^{(k)} − f^{(k−1)}` is still reported. None of the phases allocates.

use super::controller::check_coupling_dofs;
use super::test_run::CouplingController;
use crate::error::{Error, Result};
use crate::integrate::{Integrator, Kinematics, KrAlpha};
use crate::model::Springs;
use nalgebra::{DMatrix, DVector};

/// The numerical side of a CR / KR-α substructure test (see the module docs).
pub struct ExplicitController {
    scheme: KrAlpha,
    coupling: Vec<usize>,
    k_sub: usize,
    /// `u_{i,c}` (where this step's ramp starts) and `u_{i+1,c}`.
    target_prev: Vec<f64>,
    target: Vec<f64>,
    command: Vec<f64>,
    /// `f_{c,i}` of the last completed step, `f^{(j)}` and `f^{(j−1)}` of the current one.
    force: Vec<f64>,
    force_last: Vec<f64>,
    force_before: Vec<f64>,
    weighted: Vec<f64>,
    error_force: Vec<f64>,
    /// No error-force compensation: always zero (for the step record).
    compensation_force: Vec<f64>,
    /// `f_l,i+1`, given at the step's beginning, used at its end.
    load_next: DVector<f64>,
    /// The step's right-hand side without `f^{(k)}` is computed ([`Self::prepare_step`]).
    prepared: bool,
    /// No noise-free forces are kept: zeros (for the real-time runner's bookkeeping).
    true_last: Vec<f64>,
    substep: usize,
}

impl ExplicitController {
    /// `scheme` at rest (built for the numerical model with its springs and `f_l(0)`), driving
    /// `coupling_dofs` (0-based, distinct) through `substeps` sub-steps per step.
    pub fn new(scheme: KrAlpha, coupling_dofs: &[usize], substeps: usize) -> Result<Self> {
        let n = scheme.state().u.len();
        if substeps == 0 {
            return Err(Error::invalid("substructure.substeps", "must be at least 1"));
        }
        check_coupling_dofs(coupling_dofs, n)?;
        let n_c = coupling_dofs.len();
        let zeros = || vec![0.0; n_c];
        Ok(Self {
            scheme,
            coupling: coupling_dofs.to_vec(),
            k_sub: substeps,
            target_prev: zeros(),
            target: zeros(),
            command: zeros(),
            force: zeros(),
            force_last: zeros(),
            force_before: zeros(),
            weighted: zeros(),
            error_force: zeros(),
            compensation_force: zeros(),
            load_next: DVector::zeros(n),
            prepared: false,
            true_last: zeros(),
            substep: 0,
        })
    }

    /// `cr` or `kr_alpha`.
    pub fn scheme_name(&self) -> &'static str {
        self.scheme.name()
    }
    /// Coupling part of this step's target `u_{i+1,c}` \[m\] (after [`begin_step`](CouplingController::begin_step)).
    pub fn target(&self) -> &[f64] {
        &self.target
    }
    /// Coupling part of the last step's target `u_{i,c}`, where this step's ramp starts \[m\].
    pub fn target_prev(&self) -> &[f64] {
        &self.target_prev
    }

    /// The step's right-hand side without the force of its end, `f_{l,α} + Sᵀ (1 − α_f) f_{c,i}
    /// − K₀ u_α − d(u_α) − C v_α − M α₃ a_i` (springs committed at `u_α`): known when the step
    /// begins, so the real-time runner computes it during the sub-steps; `finish_step` then only
    /// adds `α_f f^{(k)}` and solves. Call after `begin_step`.
    pub fn prepare_step(&mut self) {
        let af = self.scheme.alpha_f();
        for k in 0..self.coupling.len() {
            self.weighted[k] = (1.0 - af) * self.force[k];
        }
        self.scheme.prepare(&self.load_next, &self.coupling, &self.weighted);
        self.prepared = true;
    }

    /// The maps of the next target (real-time runner, docs/realtime.md): `Pᵀ` (n × n_c), with
    /// `P` the coupling rows of `(½ + γ) Δt · Δt α₁ (M (I − α₃))⁻¹`, so that after
    /// [`prepare_step`](Self::prepare_step) of step `i` the next target is
    /// `u_{i+2,c} = u_{i+1,c} + Δt v_{i+1,c} + P (rhs + α_f Sᵀ f^{(k)})`; and `H = α_f P Sᵀ`
    /// (n_c × n_c). Allocates; call once at set-up.
    pub fn target_maps(&self) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        let (dt_alpha1, scale, inverse) = self.scheme.displacement_maps()?;
        let n = inverse.nrows();
        let n_c = self.coupling.len();
        let rows = DMatrix::from_fn(n_c, n, |r, j| dt_alpha1[(self.coupling[r], j)] * scale);
        let p = rows * inverse;
        let af = self.scheme.alpha_f();
        let h = DMatrix::from_fn(n_c, n_c, |r, j| af * p[(r, self.coupling[j])]);
        Ok((p.transpose(), h))
    }

    /// `W_c = u_{i+1,c} + Δt v_{i+1,c} + P rhs` of the prepared step into `out` (n_c · n work;
    /// `p_t` is the `Pᵀ` of [`target_maps`](Self::target_maps)).
    pub fn known_target(&self, p_t: &DMatrix<f64>, out: &mut [f64]) {
        let next = self.scheme.predicted();
        let rhs = self.scheme.prepared();
        let dt = self.dt();
        for (r, &c) in self.coupling.iter().enumerate() {
            out[r] = next.u[c] + dt * next.v[c] + p_t.column(r).dot(rhs);
        }
    }

    /// The real-time coupling loop's results of the step: `f^{(k−1)}`, `f^{(k)}` and the last
    /// command; `finish_step` then closes the step as if the sub-steps had run here.
    pub fn set_substep_results(&mut self, before: &[f64], last: &[f64], last_command: &[f64]) {
        self.force_before.copy_from_slice(before);
        self.force_last.copy_from_slice(last);
        self.command.copy_from_slice(last_command);
        self.substep = self.k_sub;
    }

    /// Zeros: no noise-free force is kept (see [`SubstepController::true_force_last`]).
    ///
    /// [`SubstepController::true_force_last`]: super::SubstepController::true_force_last
    pub fn true_force_last(&self) -> &[f64] {
        &self.true_last
    }
}

impl CouplingController for ExplicitController {
    fn begin_step(&mut self, load_next: &DVector<f64>) {
        self.load_next.copy_from(load_next);
        self.scheme.predict();
        let next = &self.scheme.predicted().u;
        for (k, &c) in self.coupling.iter().enumerate() {
            self.target[k] = next[c];
        }
        self.force_last.copy_from_slice(&self.force);
        self.force_before.copy_from_slice(&self.force);
        self.substep = 0;
    }

    fn next_command(&mut self) -> &[f64] {
        debug_assert!(self.substep < self.k_sub, "next_command called after the last sub-step");
        // d^{(j)} = (1 − r) x_prev + r x in the real-time coupling loop's operation order (at
        // r = 1 this is the target exactly).
        let r = (self.substep + 1) as f64 / self.k_sub as f64;
        for k in 0..self.coupling.len() {
            self.command[k] = r * self.target[k] + (1.0 - r) * self.target_prev[k];
        }
        &self.command
    }

    fn feedback(&mut self, measured_force: &[f64]) {
        std::mem::swap(&mut self.force_before, &mut self.force_last);
        self.force_last.copy_from_slice(measured_force);
        self.substep += 1;
    }

    fn finish_step(&mut self) {
        debug_assert_eq!(self.substep, self.k_sub, "finish_step before all sub-steps");
        if !self.prepared {
            self.prepare_step();
        }
        let af = self.scheme.alpha_f();
        for k in 0..self.coupling.len() {
            self.weighted[k] = af * self.force_last[k];
            self.error_force[k] = self.force_last[k] - self.force_before[k];
        }
        self.scheme.close(&self.coupling, &self.weighted);
        self.prepared = false;
        self.force.copy_from_slice(&self.force_last);
        self.target_prev.copy_from_slice(&self.target);
    }

    fn substeps(&self) -> usize {
        self.k_sub
    }
    fn dt(&self) -> f64 {
        self.scheme.dt()
    }
    fn coupling_dofs(&self) -> &[usize] {
        &self.coupling
    }
    fn command(&self) -> &[f64] {
        &self.command
    }
    fn state(&self) -> &Kinematics {
        self.scheme.state()
    }
    fn springs(&self) -> Option<&Springs> {
        self.scheme.springs()
    }
    fn coupling_force(&self) -> &[f64] {
        &self.force
    }
    fn error_force(&self) -> &[f64] {
        &self.error_force
    }
    fn compensation_force(&self) -> &[f64] {
        &self.compensation_force
    }

    fn is_linear(&self) -> Result<()> {
        if self.springs().is_some_and(|s| !s.is_linear()) {
            return Err(Error::invalid(
                "structure.storeys.hysteresis",
                "the numerical substructure is nonlinear; the linear analysis needs a linear model",
            ));
        }
        Ok(())
    }

    /// `[u, v, a, f_l,i, u_{i,c}, f_{c,i}, springs]`.
    fn state_len(&self) -> usize {
        4 * self.scheme.state().u.len() + 2 * self.coupling.len() + self.springs().map_or(0, |s| s.state_len())
    }
    fn write_state(&self, out: &mut [f64]) {
        let s = self.scheme.state();
        let (n, n_c) = (s.u.len(), self.coupling.len());
        out[..n].copy_from_slice(s.u.as_slice());
        out[n..2 * n].copy_from_slice(s.v.as_slice());
        out[2 * n..3 * n].copy_from_slice(s.a.as_slice());
        // the load enters the next weighted equilibrium with 1 − α_f
        out[3 * n..4 * n].copy_from_slice(self.scheme.load_prev().as_slice());
        let at = 4 * n;
        out[at..at + n_c].copy_from_slice(&self.target_prev);
        out[at + n_c..at + 2 * n_c].copy_from_slice(&self.force);
        if let Some(springs) = self.springs() {
            springs.write_state(&mut out[at + 2 * n_c..]);
        }
    }
    fn read_state(&mut self, state: &[f64]) {
        let n = self.scheme.state().u.len();
        let n_c = self.coupling.len();
        {
            let s = self.scheme.state_mut();
            s.u.copy_from_slice(&state[..n]);
            s.v.copy_from_slice(&state[n..2 * n]);
            s.a.copy_from_slice(&state[2 * n..3 * n]);
        }
        self.scheme.load_prev_mut().copy_from_slice(&state[3 * n..4 * n]);
        let at = 4 * n;
        self.target_prev.copy_from_slice(&state[at..at + n_c]);
        self.force.copy_from_slice(&state[at + n_c..at + 2 * n_c]);
        if let Some(springs) = self.scheme.springs_mut() {
            springs.read_state(&state[at + 2 * n_c..]);
        }
        self.substep = 0;
    }
}
