//! Model-based explicit schemes of real-time hybrid simulation (docs/theory.md §2.8): the
//! Chen–Ricles (CR) algorithm and KR-α (Kolay–Ricles), both explicit in displacement and velocity
//! and unconditionally stable for linear and softening systems.
//!
//! Both advance with integration-parameter matrices built once from the initial stiffness `K₀`:
//!
//! ```text
//! A   = M + γΔt C + βΔt² K₀,          α₁ = A⁻¹ M,
//! v_{n+1} = v_n + Δt α₁ a_n,
//! u_{n+1} = u_n + Δt v_n + (½ + γ) Δt² α₁ a_n,
//! ```
//!
//! so the displacement of the next step is known before its restoring force is: a specimen can
//! be commanded to `u_{n+1}` and measured, no iteration. The acceleration follows from one
//! equilibrium:
//!
//! * **CR** (`β = ¼`, `γ = ½`, so `α₁ = α₂ = 4 (4M + 2ΔtC + Δt²K₀)⁻¹ M`):
//!   `M a_{n+1} = f_{n+1} − C v_{n+1} − r(u_{n+1})`.
//! * **KR-α** with the spectral radius at infinite frequency `ρ∞ ∈ [0, 1]`, in OpenSees'
//!   `KRAlphaExplicit` form: `α_m = (2 − ρ∞)/(1 + ρ∞)`, `α_f = 1/(1 + ρ∞)`,
//!   `β = 1/(1 + ρ∞)²`, `γ = ½ (3 − ρ∞)/(1 + ρ∞)`,
//!   `α₃ = A⁻¹ [(1 − α_m) M + (1 − α_f)(γΔt C + βΔt² K₀)]` and
//!   `M (I − α₃) a_{n+1} = f_{n+α_f} − C v_{n+α_f} − r(u_{n+α_f}) − M α₃ a_n`, with
//!   `x_{n+α_f} = (1 − α_f) x_n + α_f x_{n+1}` for `u`, `v` and the load. The springs are
//!   evaluated and committed at `u_{n+α_f}` (OpenSees without `-updateElemDisp`).
//!
//! For a linear model KR-α with `ρ∞ = 1` is CR (the weighted equilibrium minus half of the one
//! at `t_n`); for a nonlinear one CR is OpenSees' `KRAlphaExplicit_TP 1.0`, whose restoring force
//! is weighted between `r(u_n)` and `r(u_{n+1})` instead.
//!
//! Steps do not allocate; the matrices are `n × n` dense (`3 n²` values), so these schemes are
//! for models up to a few thousand DOFs.

use super::{Integrator, Kinematics};
use crate::error::{Error, Result, require_positive};
use crate::model::{Springs, StructuralModel};
use nalgebra::{DMatrix, DVector, Dyn, LU};

/// CR or KR-α (see the module docs).
pub struct KrAlpha {
    name: &'static str,
    dt: f64,
    gamma: f64,
    /// Weight of the end of the step at the evaluation point (`1` for CR).
    alpha_f: f64,
    /// `Δt α₁`.
    dt_alpha1: DMatrix<f64>,
    /// `M α₃` (KR-α; `None` for CR).
    mass_alpha3: Option<DMatrix<f64>>,
    /// `M (I − α₃)` factorised (`M` for CR).
    effective_mass: LU<f64, Dyn, Dyn>,
    damping: DMatrix<f64>,
    stiffness: DMatrix<f64>,
    springs: Option<Springs>,
    state: Kinematics,
    next: Kinematics,
    load_prev: DVector<f64>,
    /// `Δt α₁ a_n`, then the evaluation point's displacement and velocity.
    increment: DVector<f64>,
    u_eval: DVector<f64>,
    v_eval: DVector<f64>,
}

impl KrAlpha {
    /// The Chen–Ricles algorithm.
    pub fn cr(model: &StructuralModel, dt: f64, springs: Option<Springs>, load0: &DVector<f64>) -> Result<Self> {
        Self::build(model, dt, Params::cr(), springs, load0)
    }

    /// KR-α with `ρ∞ = rho_inf` (OpenSees `KRAlphaExplicit rho_inf`).
    pub fn with_rho_inf(
        model: &StructuralModel,
        dt: f64,
        rho_inf: f64,
        springs: Option<Springs>,
        load0: &DVector<f64>,
    ) -> Result<Self> {
        check_rho_inf(rho_inf)?;
        Self::build(model, dt, Params::kr_alpha(rho_inf), springs, load0)
    }

    /// CR (`rho_inf = None`) or KR-α whose integration-parameter matrices are built from
    /// `parameter_stiffness` instead of the model's stiffness (which still gives the restoring
    /// force): the monolithic counterpart of a substructure test whose specimen stiffness is not
    /// part of `K₀` (docs/theory.md §2.9).
    pub fn with_parameter_stiffness(
        model: &StructuralModel,
        parameter_stiffness: &DMatrix<f64>,
        dt: f64,
        rho_inf: Option<f64>,
        springs: Option<Springs>,
        load0: &DVector<f64>,
    ) -> Result<Self> {
        let p = match rho_inf {
            None => Params::cr(),
            Some(r) => {
                check_rho_inf(r)?;
                Params::kr_alpha(r)
            }
        };
        if parameter_stiffness.shape() != model.stiffness.shape() {
            return Err(Error::invalid(
                "integrator.scheme",
                "the parameter stiffness K₀ must have the model's size",
            ));
        }
        Self::build_with(model, parameter_stiffness, dt, p, springs, load0)
    }

    fn build(
        model: &StructuralModel,
        dt: f64,
        p: Params,
        springs: Option<Springs>,
        load0: &DVector<f64>,
    ) -> Result<Self> {
        Self::build_with(model, &model.stiffness, dt, p, springs, load0)
    }

    fn build_with(
        model: &StructuralModel,
        parameter_stiffness: &DMatrix<f64>,
        dt: f64,
        p: Params,
        springs: Option<Springs>,
        load0: &DVector<f64>,
    ) -> Result<Self> {
        require_positive("integrator.dt", dt)?;
        let name = p.name;
        let mass = &model.mass;
        if mass.clone().cholesky().is_none() {
            return Err(Error::invalid(
                "integrator.scheme",
                format!(
                    "{name} solves M a = … every step and needs a positive-definite mass matrix (mass on every \
                     DOF); use an implicit Newmark scheme for a model with massless DOFs"
                ),
            ));
        }
        let a = mass + &model.damping * (p.gamma * dt) + parameter_stiffness * (p.beta * dt * dt);
        let a = a.lu();
        let singular = || Error::numerical(format!("{name} matrix M + γΔt C + βΔt² K₀"), "is singular");
        let dt_alpha1 = a.solve(mass).ok_or_else(singular)? * dt;
        let (mass_alpha3, effective_mass) = if p.alpha_f == 1.0 && p.alpha_m == 1.0 {
            (None, mass.clone().lu())
        } else {
            let b3 = mass * (1.0 - p.alpha_m)
                + (&model.damping * (p.gamma * dt) + parameter_stiffness * (p.beta * dt * dt)) * (1.0 - p.alpha_f);
            let alpha3 = a.solve(&b3).ok_or_else(singular)?;
            let mass_alpha3 = mass * &alpha3;
            (Some(mass_alpha3.clone()), (mass - mass_alpha3).lu())
        };
        if !effective_mass.is_invertible() {
            return Err(Error::numerical(
                format!("{name} effective mass M (I − α₃)"),
                "is singular",
            ));
        }
        let state = Kinematics::at_rest(model, load0)?;
        let n = model.n_dofs();
        Ok(Self {
            name,
            dt,
            gamma: p.gamma,
            alpha_f: p.alpha_f,
            dt_alpha1,
            mass_alpha3,
            effective_mass,
            damping: model.damping.clone(),
            stiffness: model.stiffness.clone(),
            springs,
            next: state.clone(),
            state,
            load_prev: load0.clone(),
            increment: DVector::zeros(n),
            u_eval: DVector::zeros(n),
            v_eval: DVector::zeros(n),
        })
    }
}

/// Refuse a spectral radius outside `[0, 1]`.
pub(crate) fn check_rho_inf(rho_inf: f64) -> Result<()> {
    if !(rho_inf.is_finite() && (0.0..=1.0).contains(&rho_inf)) {
        return Err(Error::invalid(
            "integrator.rho_inf",
            format!("the spectral radius at infinite frequency must lie in [0, 1], got {rho_inf}"),
        ));
    }
    Ok(())
}

struct Params {
    name: &'static str,
    alpha_m: f64,
    alpha_f: f64,
    beta: f64,
    gamma: f64,
}

impl Params {
    fn cr() -> Self {
        // α_m = α_f = 1: α₃ = 0 and equilibrium at t_{n+1}.
        Self {
            name: "cr",
            alpha_m: 1.0,
            alpha_f: 1.0,
            beta: 0.25,
            gamma: 0.5,
        }
    }
    fn kr_alpha(rho: f64) -> Self {
        Self {
            name: "kr_alpha",
            alpha_m: (2.0 - rho) / (1.0 + rho),
            alpha_f: 1.0 / (1.0 + rho),
            beta: 1.0 / ((1.0 + rho) * (1.0 + rho)),
            gamma: 0.5 * (3.0 - rho) / (1.0 + rho),
        }
    }
}

impl Integrator for KrAlpha {
    fn name(&self) -> &'static str {
        self.name
    }
    fn dt(&self) -> f64 {
        self.dt
    }
    fn state(&self) -> &Kinematics {
        &self.state
    }
    fn springs(&self) -> Option<&Springs> {
        self.springs.as_ref()
    }
    fn step(&mut self, load_next: &DVector<f64>) {
        self.predict();
        self.correct(load_next, &[], &[]);
    }
}

impl KrAlpha {
    /// The first half of a step: the explicit kinematics `u_{n+1}`, `v_{n+1}` (in
    /// [`predicted`](Self::predicted)) and the evaluation point `u_{n+α_f}`, `v_{n+α_f}`. They
    /// need nothing of the step's forces, so a substructure test can command the specimen to
    /// `u_{n+1}` before [`correct`](Self::correct) (crate::substructure::ExplicitController).
    pub fn predict(&mut self) {
        let (dt, af) = (self.dt, self.alpha_f);
        let (s, n) = (&self.state, &mut self.next);
        self.increment.gemv(1.0, &self.dt_alpha1, &s.a, 0.0);
        n.u.copy_from(&s.u);
        n.u.axpy(dt, &s.v, 1.0);
        n.u.axpy((0.5 + self.gamma) * dt, &self.increment, 1.0);
        n.v.copy_from(&s.v);
        n.v += &self.increment;
        self.u_eval.copy_from(&s.u);
        self.u_eval.axpy(af, &n.u, 1.0 - af);
        self.v_eval.copy_from(&s.v);
        self.v_eval.axpy(af, &n.v, 1.0 - af);
    }

    /// The second half: the acceleration `a_{n+1}` from the weighted equilibrium with the
    /// external forces `extra_force[k]` added at DOF `extra_dofs[k]` (a coupling force already
    /// weighted to `t_{n+α_f}`; empty for a monolithic step), then the step is committed.
    pub fn correct(&mut self, load_next: &DVector<f64>, extra_dofs: &[usize], extra_force: &[f64]) {
        self.prepare(load_next, extra_dofs, extra_force);
        self.close(&[], &[]);
    }

    /// The part of [`correct`](Self::correct) that needs no force of the step's end: the
    /// right-hand side `f_α + Sᵀ f_known − K₀ u_α − d(u_α) − C v_α − M α₃ a_n` (in the work
    /// vector, [`prepared`](Self::prepared)), the springs evaluated and committed at `u_α`.
    pub fn prepare(&mut self, load_next: &DVector<f64>, extra_dofs: &[usize], extra_force: &[f64]) {
        let af = self.alpha_f;
        let (s, n) = (&self.state, &mut self.next);
        n.a.copy_from(&self.load_prev);
        n.a.axpy(af, load_next, 1.0 - af);
        for (&dof, &f) in extra_dofs.iter().zip(extra_force) {
            n.a[dof] += f;
        }
        n.a.gemv(-1.0, &self.stiffness, &self.u_eval, 1.0);
        n.a.gemv(-1.0, &self.damping, &self.v_eval, 1.0);
        if let Some(ma3) = &self.mass_alpha3 {
            n.a.gemv(-1.0, ma3, &s.a, 1.0);
        }
        if let Some(springs) = &mut self.springs {
            springs.set_trial(self.u_eval.as_slice());
            springs.add_deviation(-1.0, n.a.as_mut_slice());
            springs.commit();
        }
        self.load_prev.copy_from(load_next);
    }

    /// The right-hand side of the last [`prepare`](Self::prepare).
    pub fn prepared(&self) -> &DVector<f64> {
        &self.next.a
    }

    /// After [`prepare`](Self::prepare): add `extra_force` at `extra_dofs` (the force of the
    /// step's end), solve for `a_{n+1}` and commit the step.
    pub fn close(&mut self, extra_dofs: &[usize], extra_force: &[f64]) {
        let n = &mut self.next;
        for (&dof, &f) in extra_dofs.iter().zip(extra_force) {
            n.a[dof] += f;
        }
        self.effective_mass.solve_mut(&mut n.a);
        std::mem::swap(&mut self.state, &mut self.next);
    }

    /// `Δt α₁` (n × n), `(½ + γ) Δt` and `(M (I − α₃))⁻¹` (allocates; for set-up): what maps
    /// a right-hand side to the next step's displacement, `u_{n+2} = u_{n+1} + Δt v_{n+1} +
    /// (½ + γ) Δt · Δt α₁ · (M (I − α₃))⁻¹ rhs`.
    pub fn displacement_maps(&self) -> Result<(&DMatrix<f64>, f64, DMatrix<f64>)> {
        let n = self.state.u.len();
        let inverse = self
            .effective_mass
            .solve(&DMatrix::identity(n, n))
            .ok_or_else(|| Error::numerical(format!("{} effective mass M (I − α₃)", self.name), "is singular"))?;
        Ok((&self.dt_alpha1, (0.5 + self.gamma) * self.dt, inverse))
    }

    /// `u_{n+1}`, `v_{n+1}` of the step begun by [`predict`](Self::predict) (its acceleration is
    /// not yet known).
    pub fn predicted(&self) -> &Kinematics {
        &self.next
    }
    /// The weight `α_f` of the step's end at the evaluation point (`1` for CR).
    pub fn alpha_f(&self) -> f64 {
        self.alpha_f
    }
    /// The committed state (as [`Integrator::state`]), mutable for checkpoints.
    pub(crate) fn state_mut(&mut self) -> &mut Kinematics {
        &mut self.state
    }
    /// The load of the last committed step (enters the next weighted equilibrium).
    pub(crate) fn load_prev(&self) -> &DVector<f64> {
        &self.load_prev
    }
    pub(crate) fn load_prev_mut(&mut self) -> &mut DVector<f64> {
        &mut self.load_prev
    }
    pub(crate) fn springs_mut(&mut self) -> Option<&mut Springs> {
        self.springs.as_mut()
    }
}
