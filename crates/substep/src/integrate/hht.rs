//! Four-point schemes: HHT-α (docs/theory.md §2.4) and operator splitting α-OS (docs/theory.md §2.5).
//! Both are written in acceleration form with the matrix
//! `M + (1+α)γΔt C + (1+α)βΔt² K`, `γ = ½ − α`, `β = (1 − α)²/4`, factorised once.

use super::{Integrator, Kinematics, check_hilber_alpha};
use crate::error::{Error, Result};
use crate::model::{Springs, StructuralModel};
use nalgebra::{Cholesky, DMatrix, DVector, Dyn};

struct FourPoint {
    dt: f64,
    alpha: f64,
    beta: f64,
    gamma: f64,
    damping: DMatrix<f64>,
    stiffness: DMatrix<f64>,
    lhs: Cholesky<f64, Dyn>,
    state: Kinematics,
    next: Kinematics,
    /// `f*_i`, the load of the previous step (HHT uses it, not `f*_{i+1}` twice).
    load_prev: DVector<f64>,
    work: DVector<f64>,
}

impl FourPoint {
    fn new(model: &StructuralModel, dt: f64, alpha: f64, load0: &DVector<f64>) -> Result<Self> {
        check_hilber_alpha(alpha)?;
        crate::error::require_positive("integrator.dt", dt)?;
        let gamma = 0.5 - alpha;
        let beta = (1.0 - alpha).powi(2) / 4.0;
        let lhs = (&model.mass
            + &model.damping * ((1.0 + alpha) * gamma * dt)
            + &model.stiffness * ((1.0 + alpha) * beta * dt * dt))
            .cholesky()
            .ok_or_else(|| Error::numerical("HHT effective mass matrix", "is not positive definite"))?;
        let state = Kinematics::at_rest(model, load0)?;
        Ok(Self {
            dt,
            alpha,
            beta,
            gamma,
            damping: model.damping.clone(),
            stiffness: model.stiffness.clone(),
            lhs,
            next: state.clone(),
            state,
            load_prev: load0.clone(),
            work: DVector::zeros(model.n_dofs()),
        })
    }

    /// Predictors `ũ`, `ṽ` into `next.u`, `next.v`.
    fn predict(&mut self) {
        let (dt, s, n) = (self.dt, &self.state, &mut self.next);
        n.u.copy_from(&s.u);
        n.u.axpy(dt, &s.v, 1.0);
        n.u.axpy(dt * dt * (0.5 - self.beta), &s.a, 1.0);
        n.v.copy_from(&s.v);
        n.v.axpy((1.0 - self.gamma) * dt, &s.a, 1.0);
    }

    /// Solve for `a_{i+1}` (right-hand side in `next.a`), correct, and roll the state.
    fn correct(&mut self, load_next: &DVector<f64>) {
        let (dt, n) = (self.dt, &mut self.next);
        self.lhs.solve_mut(&mut n.a);
        n.u.axpy(self.beta * dt * dt, &n.a, 1.0);
        n.v.axpy(self.gamma * dt, &n.a, 1.0);
        self.load_prev.copy_from(load_next);
        std::mem::swap(&mut self.state, &mut self.next);
    }
}

/// Hilber–Hughes–Taylor α-method.
pub struct Hht(FourPoint);

impl Hht {
    pub fn new(model: &StructuralModel, dt: f64, alpha: f64, load0: &DVector<f64>) -> Result<Self> {
        Ok(Self(FourPoint::new(model, dt, alpha, load0)?))
    }
}

impl Integrator for Hht {
    fn name(&self) -> &'static str {
        "hht"
    }
    fn dt(&self) -> f64 {
        self.0.dt
    }
    fn state(&self) -> &Kinematics {
        &self.0.state
    }
    fn step(&mut self, load_next: &DVector<f64>) {
        let p = &mut self.0;
        let al = p.alpha;
        p.predict();
        // rhs = (1+α) f_{i+1} − α f_i − (1+α) C ṽ + α C v_i − (1+α) K ũ + α K u_i
        let (s, n) = (&p.state, &mut p.next);
        n.a.copy_from(load_next);
        n.a.scale_mut(1.0 + al);
        n.a.axpy(-al, &p.load_prev, 1.0);
        p.work.copy_from(&n.v);
        p.work.scale_mut(-(1.0 + al));
        p.work.axpy(al, &s.v, 1.0);
        n.a.gemv(1.0, &p.damping, &p.work, 1.0);
        p.work.copy_from(&n.u);
        p.work.scale_mut(-(1.0 + al));
        p.work.axpy(al, &s.u, 1.0);
        n.a.gemv(1.0, &p.stiffness, &p.work, 1.0);
        p.correct(load_next);
    }
}

/// α-OS: the restoring force is evaluated at the displacement predictor `ũ` (explicitly, as
/// a specimen would be measured) and the linear part is implicit with the initial stiffness.
/// For a linear model it coincides with HHT; it is kept separate because the restoring-force
/// path is where a measured specimen force enters.
pub struct AlphaOs {
    p: FourPoint,
    /// Hysteretic springs of a nonlinear model (`r̃ = K₀ ũ + d(ũ)`), committed at each predictor.
    springs: Option<Springs>,
    /// `r̃_i = K ũ_i` and `ṽ_i` of the previous step.
    restoring_prev: DVector<f64>,
    v_pred_prev: DVector<f64>,
    restoring: DVector<f64>,
    /// The form: OpenSees `AlphaOS` (one evaluation at `ũ_α`) or `AlphaOS_TP` (two points).
    form: AlphaOsForm,
    /// `ũ_i`, the predictor of the previous step (`AlphaOS` form), and `ũ_α`.
    u_pred_prev: DVector<f64>,
    u_alpha: DVector<f64>,
}

/// The two α-OS forms of OpenSees; identical for linear models (up to the start).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AlphaOsForm {
    /// `AlphaOS`: the restoring force is evaluated once per step at
    /// `ũ_α = (1+α) ũ_{i+1} − α ũ_i` (and the springs committed there); start `ũ_0 = u_0`.
    OnePoint,
    /// `AlphaOS_TP`: `(1+α) r(ũ_{i+1}) − α r(ũ_i)`, springs committed at `ũ_{i+1}`; start
    /// `ũ_0 = u_0 − βΔt² a_0`.
    TwoPoint,
}

impl AlphaOs {
    pub fn new(model: &StructuralModel, dt: f64, alpha: f64, load0: &DVector<f64>) -> Result<Self> {
        Self::with_springs(model, dt, alpha, AlphaOsForm::OnePoint, None, load0)
    }

    /// α-OS for a nonlinear model: `model` holds the initial stiffness `K₀`, `springs` the
    /// hysteretic part, evaluated once per step at a predictor (docs/theory.md §14.3).
    pub fn with_springs(
        model: &StructuralModel,
        dt: f64,
        alpha: f64,
        form: AlphaOsForm,
        mut springs: Option<Springs>,
        load0: &DVector<f64>,
    ) -> Result<Self> {
        let p = FourPoint::new(model, dt, alpha, load0)?;
        // Two-point form, consistent start: ũ_0 = u_0 − βΔt² a_0, ṽ_0 = v_0 − γΔt a_0.
        // One-point form (OpenSees AlphaOS): ũ_0 = u_0.
        let u_pred0 = match form {
            AlphaOsForm::TwoPoint => &p.state.u - &p.state.a * (p.beta * dt * dt),
            AlphaOsForm::OnePoint => p.state.u.clone(),
        };
        let v_pred_prev = &p.state.v - &p.state.a * (p.gamma * dt);
        let mut restoring_prev = &p.stiffness * &u_pred0;
        if let Some(s) = &mut springs {
            s.set_trial(u_pred0.as_slice());
            s.add_deviation(1.0, restoring_prev.as_mut_slice());
            s.commit();
        }
        let n = model.n_dofs();
        Ok(Self {
            p,
            springs,
            form,
            u_pred_prev: u_pred0,
            u_alpha: DVector::zeros(n),
            restoring_prev,
            v_pred_prev,
            restoring: DVector::zeros(n),
        })
    }
}

impl Integrator for AlphaOs {
    fn name(&self) -> &'static str {
        match self.form {
            AlphaOsForm::OnePoint => "alpha_os",
            AlphaOsForm::TwoPoint => "alpha_os_tp",
        }
    }
    fn springs(&self) -> Option<&Springs> {
        self.springs.as_ref()
    }
    fn dt(&self) -> f64 {
        self.p.dt
    }
    fn state(&self) -> &Kinematics {
        &self.p.state
    }
    fn step(&mut self, load_next: &DVector<f64>) {
        if self.form == AlphaOsForm::OnePoint {
            self.step_one_point(load_next);
            return;
        }
        let p = &mut self.p;
        let (al, dt) = (p.alpha, p.dt);
        p.predict();
        self.restoring.gemv(1.0, &p.stiffness, &p.next.u, 0.0);
        if let Some(springs) = &mut self.springs {
            springs.set_trial(p.next.u.as_slice());
            springs.add_deviation(1.0, self.restoring.as_mut_slice());
            springs.commit();
        }
        let (s, n) = (&p.state, &mut p.next);
        // rhs = (1+α) f_{i+1} − α f_i − (1+α) r̃_{i+1} + α r̃_i
        //       − (1+α) C ṽ_{i+1} + α C ṽ_i + αγΔt C a_i + αβΔt² K a_i
        n.a.copy_from(load_next);
        n.a.scale_mut(1.0 + al);
        n.a.axpy(-al, &p.load_prev, 1.0);
        n.a.axpy(-(1.0 + al), &self.restoring, 1.0);
        n.a.axpy(al, &self.restoring_prev, 1.0);
        p.work.copy_from(&n.v);
        p.work.scale_mut(-(1.0 + al));
        p.work.axpy(al, &self.v_pred_prev, 1.0);
        p.work.axpy(al * p.gamma * dt, &s.a, 1.0);
        n.a.gemv(1.0, &p.damping, &p.work, 1.0);
        n.a.gemv(al * p.beta * dt * dt, &p.stiffness, &s.a, 1.0);
        self.v_pred_prev.copy_from(&n.v);
        std::mem::swap(&mut self.restoring_prev, &mut self.restoring);
        p.correct(load_next);
    }
}

impl AlphaOs {
    /// OpenSees `AlphaOS`: with `α_O = 1 + α`,
    /// `M a_{i+1} + C[α_O v_{i+1} + (1−α_O) v_i] + r(ũ_α) + K₀[α_O (u_{i+1} − ũ_{i+1}) +
    /// (1−α_O)(u_i − ũ_i)] = α_O f_{i+1} + (1−α_O) f_i`, `ũ_α = α_O ũ_{i+1} + (1−α_O) ũ_i`.
    fn step_one_point(&mut self, load_next: &DVector<f64>) {
        let p = &mut self.p;
        let al = p.alpha;
        p.predict();
        // ũ_α and r(ũ_α) = K₀ ũ_α + d(ũ_α), springs committed there
        self.u_alpha.copy_from(&p.next.u);
        self.u_alpha.scale_mut(1.0 + al);
        self.u_alpha.axpy(-al, &self.u_pred_prev, 1.0);
        self.restoring.gemv(1.0, &p.stiffness, &self.u_alpha, 0.0);
        if let Some(springs) = &mut self.springs {
            springs.set_trial(self.u_alpha.as_slice());
            springs.add_deviation(1.0, self.restoring.as_mut_slice());
            springs.commit();
        }
        let (s, n) = (&p.state, &mut p.next);
        // rhs = (1+α) f_{i+1} − α f_i − r(ũ_α) − (1+α) C ṽ_{i+1} + α C v_i + α K₀ (u_i − ũ_i)
        n.a.copy_from(load_next);
        n.a.scale_mut(1.0 + al);
        n.a.axpy(-al, &p.load_prev, 1.0);
        n.a -= &self.restoring;
        p.work.copy_from(&n.v);
        p.work.scale_mut(-(1.0 + al));
        p.work.axpy(al, &s.v, 1.0);
        n.a.gemv(1.0, &p.damping, &p.work, 1.0);
        p.work.copy_from(&s.u);
        p.work -= &self.u_pred_prev;
        n.a.gemv(al, &p.stiffness, &p.work, 1.0);
        self.u_pred_prev.copy_from(&n.u);
        p.correct(load_next);
    }
}
