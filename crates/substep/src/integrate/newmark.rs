//! Newmark(β, γ) in effective-stiffness form (spec §2.2) and its explicit member (β = 0).

use super::{Integrator, Kinematics};
use crate::error::{Error, Result};
use crate::model::StructuralModel;
use nalgebra::{Cholesky, DMatrix, DVector, Dyn};

/// The constants `a0 … a7` of spec §2.2.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewmarkConstants {
    pub beta: f64,
    pub gamma: f64,
    pub dt: f64,
    pub a: [f64; 8],
}

impl NewmarkConstants {
    pub fn new(beta: f64, gamma: f64, dt: f64) -> Result<Self> {
        if !(beta.is_finite() && beta > 0.0) {
            return Err(Error::invalid(
                "integrator.beta",
                format!("must be > 0 for the implicit form, got {beta} (use central_difference for beta = 0)"),
            ));
        }
        if !(gamma.is_finite() && gamma >= 0.0) {
            return Err(Error::invalid(
                "integrator.gamma",
                format!("must be a finite number >= 0, got {gamma}"),
            ));
        }
        crate::error::require_positive("integrator.dt", dt)?;
        let a = [
            1.0 / (beta * dt * dt),
            gamma / (beta * dt),
            1.0 / (beta * dt),
            1.0 / (2.0 * beta) - 1.0,
            gamma / beta - 1.0,
            dt * (gamma / beta - 2.0) / 2.0,
            (1.0 - gamma) * dt,
            gamma * dt,
        ];
        Ok(Self { beta, gamma, dt, a })
    }
}

/// The parts of Newmark shared by the monolithic integrator and the sub-step controller:
/// matrices, the factorised effective stiffness `K̂ = K + a0 M + a1 C` and the two work vectors
/// needed to form `F̂_i`.
pub struct NewmarkCore {
    pub c: NewmarkConstants,
    pub mass: DMatrix<f64>,
    pub damping: DMatrix<f64>,
    pub stiffness: DMatrix<f64>,
    pub k_hat: Cholesky<f64, Dyn>,
    work_m: DVector<f64>,
    work_c: DVector<f64>,
}

impl NewmarkCore {
    pub fn new(model: &StructuralModel, dt: f64, beta: f64, gamma: f64) -> Result<Self> {
        let c = NewmarkConstants::new(beta, gamma, dt)?;
        let k_eff = &model.stiffness + &model.mass * c.a[0] + &model.damping * c.a[1];
        let k_hat = k_eff.cholesky().ok_or_else(|| {
            Error::numerical(
                "effective stiffness K + a0 M + a1 C",
                "is not positive definite (check K, C and dt)",
            )
        })?;
        let n = model.n_dofs();
        Ok(Self {
            c,
            mass: model.mass.clone(),
            damping: model.damping.clone(),
            stiffness: model.stiffness.clone(),
            k_hat,
            work_m: DVector::zeros(n),
            work_c: DVector::zeros(n),
        })
    }

    /// `out = F̂_i = M(a0 u + a2 v + a3 a) + C(a1 u + a4 v + a5 a)`.
    pub fn effective_load(&mut self, s: &Kinematics, out: &mut DVector<f64>) {
        let a = &self.c.a;
        self.work_m.copy_from(&s.u);
        self.work_m.scale_mut(a[0]);
        self.work_m.axpy(a[2], &s.v, 1.0);
        self.work_m.axpy(a[3], &s.a, 1.0);
        self.work_c.copy_from(&s.u);
        self.work_c.scale_mut(a[1]);
        self.work_c.axpy(a[4], &s.v, 1.0);
        self.work_c.axpy(a[5], &s.a, 1.0);
        out.gemv(1.0, &self.mass, &self.work_m, 0.0);
        out.gemv(1.0, &self.damping, &self.work_c, 1.0);
    }

    /// Given the new displacement in `s_next.u` and the old state, fill `s_next.a` and `s_next.v`.
    pub fn update_kinematics(&self, s: &Kinematics, s_next: &mut Kinematics) {
        let a = &self.c.a;
        // a_{i+1} = a0 (u_{i+1} − u_i) − a2 v_i − a3 a_i
        s_next.a.copy_from(&s_next.u);
        s_next.a.axpy(-1.0, &s.u, 1.0);
        s_next.a.scale_mut(a[0]);
        s_next.a.axpy(-a[2], &s.v, 1.0);
        s_next.a.axpy(-a[3], &s.a, 1.0);
        // v_{i+1} = v_i + a6 a_i + a7 a_{i+1}
        s_next.v.copy_from(&s.v);
        s_next.v.axpy(a[6], &s.a, 1.0);
        s_next.v.axpy(a[7], &s_next.a, 1.0);
    }
}

/// Implicit Newmark(β, γ), β > 0.
pub struct Newmark {
    core: NewmarkCore,
    state: Kinematics,
    next: Kinematics,
}

impl Newmark {
    pub fn new(model: &StructuralModel, dt: f64, beta: f64, gamma: f64, load0: &DVector<f64>) -> Result<Self> {
        let core = NewmarkCore::new(model, dt, beta, gamma)?;
        let state = Kinematics::at_rest(model, load0)?;
        let next = state.clone();
        Ok(Self { core, state, next })
    }
}

impl Integrator for Newmark {
    fn name(&self) -> &'static str {
        "newmark"
    }
    fn dt(&self) -> f64 {
        self.core.c.dt
    }
    fn state(&self) -> &Kinematics {
        &self.state
    }
    fn step(&mut self, load_next: &DVector<f64>) {
        self.core.effective_load(&self.state, &mut self.next.u);
        self.next.u += load_next;
        self.core.k_hat.solve_mut(&mut self.next.u);
        self.core.update_kinematics(&self.state, &mut self.next);
        std::mem::swap(&mut self.state, &mut self.next);
    }
}

/// Explicit Newmark (β = 0): `u_{i+1} = u_i + Δt v_i + Δt²/2 a_i`, then
/// `(M + γΔt C) a_{i+1} = f_{i+1} − C (v_i + (1−γ)Δt a_i) − K u_{i+1}`. With γ = ½ this is
/// algebraically the three-point central-difference scheme of spec §2.1.
pub struct ExplicitNewmark {
    dt: f64,
    gamma: f64,
    damping: DMatrix<f64>,
    stiffness: DMatrix<f64>,
    lhs: Cholesky<f64, Dyn>,
    state: Kinematics,
    next: Kinematics,
}

impl ExplicitNewmark {
    pub fn new(model: &StructuralModel, dt: f64, gamma: f64, load0: &DVector<f64>) -> Result<Self> {
        crate::error::require_positive("integrator.dt", dt)?;
        crate::error::require_non_negative("integrator.gamma", gamma)?;
        let lhs = (&model.mass + &model.damping * (gamma * dt))
            .cholesky()
            .ok_or_else(|| Error::numerical("M + gamma dt C", "is not positive definite"))?;
        let state = Kinematics::at_rest(model, load0)?;
        Ok(Self {
            dt,
            gamma,
            damping: model.damping.clone(),
            stiffness: model.stiffness.clone(),
            lhs,
            next: state.clone(),
            state,
        })
    }
}

impl Integrator for ExplicitNewmark {
    fn name(&self) -> &'static str {
        if self.gamma == 0.5 {
            "central_difference"
        } else {
            "explicit_newmark"
        }
    }
    fn dt(&self) -> f64 {
        self.dt
    }
    fn state(&self) -> &Kinematics {
        &self.state
    }
    fn step(&mut self, load_next: &DVector<f64>) {
        let (dt, g) = (self.dt, self.gamma);
        let (s, n) = (&self.state, &mut self.next);
        n.u.copy_from(&s.u);
        n.u.axpy(dt, &s.v, 1.0);
        n.u.axpy(0.5 * dt * dt, &s.a, 1.0);
        // predictor velocity, kept in n.v
        n.v.copy_from(&s.v);
        n.v.axpy((1.0 - g) * dt, &s.a, 1.0);
        n.a.copy_from(load_next);
        n.a.gemv(-1.0, &self.damping, &n.v, 1.0);
        n.a.gemv(-1.0, &self.stiffness, &n.u, 1.0);
        self.lhs.solve_mut(&mut n.a);
        n.v.axpy(g * dt, &n.a, 1.0);
        std::mem::swap(&mut self.state, &mut self.next);
    }
}
