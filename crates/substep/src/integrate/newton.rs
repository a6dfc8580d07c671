//! Implicit Newmark(β, γ) for a nonlinear model, solved by Newton–Raphson (docs/theory.md §14.3).
//!
//! The model is `M ü + C u̇ + r(u) = f(t)` with `r(u) = K₀ u + d(u)` (hysteretic springs, see
//! [`crate::model::Springs`]). With the Newmark relations `a_{i+1} = a0 (u − u_i) − a2 v_i − a3
//! a_i`, `v_{i+1} = v_i + a6 a_i + a7 a_{i+1}` the step is the root of
//!
//! ```text
//! R(u) = f_{i+1} − M a_{i+1}(u) − C v_{i+1}(u) − K₀ u − d(u) = 0,
//! ```
//!
//! iterated from `u⁰ = u_i` by `K̂_t Δu = R(u)`, `K̂_t = K_t(u) + a0 M + a1 C`, until
//! `‖Δu‖∞ ≤ tol · max(‖u‖∞, largest ‖u‖∞ of the run so far)` (`[integrator] tolerance`, default
//! 1e-10). The springs' trial states always start from the committed state of step `i`; the
//! converged state is committed. `K̂_t` is factorised again only when a spring's tangent
//! changed (the piecewise-linear laws change it at yield and unloading only); while every
//! spring is on its initial slope the factor of `K̂₀` is used. A step that does not converge
//! in `max_iterations` leaves the state of the step before and reports the failure (the run
//! stops with the step and the residual).

use super::{Integrator, Kinematics, NewmarkCore};
use crate::error::{Error, Result};
use crate::model::{ModelRef, Springs};
use crate::sparse::{CscMatrix, FactorKind, SymmetricFactor};
use nalgebra::{DMatrix, DVector};

/// Newton–Raphson settings (`[integrator] tolerance`, `max_iterations`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewtonSettings {
    /// Convergence when the displacement increment is at most this share of the displacement
    /// scale (see the module docs).
    pub tolerance: f64,
    pub max_iterations: usize,
}

impl Default for NewtonSettings {
    fn default() -> Self {
        Self {
            tolerance: 1e-10,
            max_iterations: 50,
        }
    }
}

/// `K̂₀` in the form the tangent is assembled from.
enum Base {
    Dense(DMatrix<f64>),
    Sparse(CscMatrix),
}

impl Base {
    /// `K₀` alone (the static state) of `model`.
    fn stiffness(model: ModelRef) -> Self {
        match model {
            ModelRef::Dense(m) => Base::Dense(m.stiffness.clone()),
            ModelRef::Sparse(m) => Base::Sparse(m.stiffness.clone()),
        }
    }

    /// `out −= B u`.
    fn mul_sub(&self, u: &DVector<f64>, out: &mut DVector<f64>) {
        match self {
            Base::Dense(k) => out.gemv(-1.0, k, u, 1.0),
            Base::Sparse(k) => k.sym_mul_add(-1.0, u.as_slice(), 1.0, out.as_mut_slice()),
        }
    }

    /// `B + Σ a aᵀ (k_t − k₀)` of the springs' trial state, factorised (`triplets`: work space).
    fn factor_with(
        &self,
        springs: &Springs,
        triplets: &mut Vec<(usize, usize, f64)>,
        what: &str,
    ) -> Result<TangentFactor> {
        Ok(match self {
            Base::Dense(k0) => {
                let mut k = k0.clone();
                springs.add_tangent_deviation(&mut k);
                TangentFactor::Dense(k.lu())
            }
            Base::Sparse(k0) => {
                springs.tangent_deviation_triplets(triplets);
                let dev = CscMatrix::from_triplets(k0.n(), triplets);
                let k = CscMatrix::linear_combination(&[(1.0, k0), (1.0, &dev)]);
                TangentFactor::Sparse(Box::new(SymmetricFactor::new(&k, FactorKind::Auto, what)?))
            }
        })
    }
}

enum TangentFactor {
    Dense(nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>),
    Sparse(Box<SymmetricFactor>),
}

impl TangentFactor {
    /// `x ← K⁻¹ x`; `false` if the matrix is singular.
    fn solve(&mut self, x: &mut DVector<f64>) -> bool {
        match self {
            TangentFactor::Dense(lu) => lu.solve_mut(x),
            TangentFactor::Sparse(f) => {
                f.solve_in_place(x.as_mut_slice());
                true
            }
        }
    }
}

/// Newmark + Newton–Raphson on a model with hysteretic springs.
pub struct NewmarkNewton {
    core: NewmarkCore,
    base: Base,
    springs: Springs,
    settings: NewtonSettings,
    state: Kinematics,
    next: Kinematics,
    residual: DVector<f64>,
    internal: DVector<f64>,
    /// Tangents of the springs in the current factor, and the factor (`None`: `K̂₀`'s).
    tangents: Vec<f64>,
    factor: Option<TangentFactor>,
    /// Work space of the sparse tangent's assembly.
    triplets: Vec<(usize, usize, f64)>,
    initial_tangents: Vec<f64>,
    scale: f64,
    failure: Option<String>,
    iterations: usize,
    most_iterations: usize,
}

impl NewmarkNewton {
    pub fn new<'a>(
        model: impl Into<ModelRef<'a>>,
        springs: Springs,
        dt: f64,
        beta: f64,
        gamma: f64,
        settings: NewtonSettings,
        load0: &DVector<f64>,
    ) -> Result<Self> {
        let model = model.into();
        if !(settings.tolerance.is_finite() && settings.tolerance > 0.0) {
            return Err(Error::invalid(
                "integrator.tolerance",
                format!("must be > 0, got {}", settings.tolerance),
            ));
        }
        let core = NewmarkCore::new(model, dt, beta, gamma)?;
        let a = core.c.a;
        let base = match model {
            ModelRef::Dense(m) => Base::Dense(&m.stiffness + &m.mass * a[0] + &m.damping * a[1]),
            ModelRef::Sparse(m) => Base::Sparse(CscMatrix::linear_combination(&[
                (1.0, &m.stiffness),
                (a[0], &m.mass),
                (a[1], &m.damping),
            ])),
        };
        let state = Kinematics::at_rest(model, load0)?;
        let n = model.n_dofs();
        let mut springs = springs;
        springs.set_trial(&vec![0.0; n]);
        let mut tangents = vec![0.0; springs.len()];
        springs.tangents_unchanged(&mut tangents);
        springs.revert();
        Ok(Self {
            core,
            base,
            springs,
            settings,
            next: state.clone(),
            state,
            residual: DVector::zeros(n),
            internal: DVector::zeros(n),
            initial_tangents: tangents.clone(),
            tangents,
            factor: None,
            triplets: Vec::new(),
            scale: 0.0,
            failure: None,
            iterations: 0,
            most_iterations: 0,
        })
    }

    /// Start from the static solution `u_s` of `r(u) = static_load` (Newton–Raphson on `K_t`;
    /// e.g. gravity, which OpenSees applies by a static analysis before `loadConst`): `u₀ = u_s`,
    /// `v₀ = 0`, `a₀` as constructed (the dynamic load at `t = 0` over `M`). The springs are
    /// committed at `u_s`. The loads of the steps must then include `static_load`.
    pub fn preload<'a>(&mut self, model: impl Into<ModelRef<'a>>, static_load: &DVector<f64>) -> Result<()> {
        let base = Base::stiffness(model.into());
        let n = self.state.u.len();
        let mut u = DVector::zeros(n);
        let mut r = DVector::zeros(n);
        for it in 1..=self.settings.max_iterations {
            self.springs.set_trial(u.as_slice());
            // R = F − K₀ u − d(u)
            r.copy_from(static_load);
            base.mul_sub(&u, &mut r);
            self.springs.add_deviation(-1.0, r.as_mut_slice());
            let solved = base
                .factor_with(
                    &self.springs,
                    &mut self.triplets,
                    "tangent stiffness of the static state",
                )?
                .solve(&mut r);
            if !solved || !r.iter().all(|x| x.is_finite()) {
                return Err(Error::numerical(
                    "structure.frame.gravity",
                    "the static state under gravity cannot be found (singular tangent stiffness)",
                ));
            }
            u += &r;
            if r.amax() <= self.settings.tolerance * u.amax() {
                self.springs.set_trial(u.as_slice());
                self.springs.commit();
                self.scale = u.amax();
                self.state.u.copy_from(&u);
                self.next.u.copy_from(&u);
                self.tangents.iter_mut().for_each(|t| *t = f64::NAN);
                return Ok(());
            }
            if it == self.settings.max_iterations {
                break;
            }
        }
        Err(Error::numerical(
            "structure.frame.gravity",
            format!(
                "Newton–Raphson found no static state under gravity in {} iterations",
                self.settings.max_iterations
            ),
        ))
    }

    /// Newton iterations of all steps so far, and the most in one step.
    pub fn iterations(&self) -> (usize, usize) {
        (self.iterations, self.most_iterations)
    }

    fn refactor(&mut self) -> Result<()> {
        if self.tangents == self.initial_tangents {
            self.factor = None;
            return Ok(());
        }
        self.factor = Some(
            self.base
                .factor_with(&self.springs, &mut self.triplets, "tangent effective stiffness")?,
        );
        Ok(())
    }

    fn solve(&mut self) -> bool {
        match &mut self.factor {
            None => {
                self.core.solve_in_place(&mut self.residual);
                true
            }
            Some(f) => f.solve(&mut self.residual),
        }
    }

    /// `residual = f − M a − C v − K₀ u − d(u)` at `next` (springs at their trial state).
    fn residual(&mut self, load: &DVector<f64>) {
        self.core.internal_force(&self.next, &mut self.internal);
        self.residual.copy_from(load);
        self.residual -= &self.internal;
        self.springs.add_deviation(-1.0, self.residual.as_mut_slice());
    }

    fn try_step(&mut self, load_next: &DVector<f64>) -> std::result::Result<(), String> {
        self.next.u.copy_from(&self.state.u);
        let n_max = self.settings.max_iterations;
        let mut last_increment = f64::NAN;
        for it in 1..=n_max {
            self.springs.set_trial(self.next.u.as_slice());
            self.core.update_kinematics(&self.state, &mut self.next);
            self.residual(load_next);
            if !self.springs.tangents_unchanged(&mut self.tangents) {
                self.refactor().map_err(|e| e.to_string())?;
            }
            if !self.solve() {
                return Err("the tangent effective stiffness is singular".into());
            }
            let du = self.residual.amax();
            self.next.u += &self.residual;
            let scale = self.next.u.amax().max(self.scale);
            if !du.is_finite() {
                return Err("the Newton iteration produced a non-finite displacement".into());
            }
            last_increment = du / scale;
            if du <= self.settings.tolerance * scale {
                self.springs.set_trial(self.next.u.as_slice());
                self.core.update_kinematics(&self.state, &mut self.next);
                self.iterations += it;
                self.most_iterations = self.most_iterations.max(it);
                self.scale = scale;
                return Ok(());
            }
        }
        self.springs.set_trial(self.next.u.as_slice());
        self.core.update_kinematics(&self.state, &mut self.next);
        self.residual(load_next);
        Err(format!(
            "Newton–Raphson did not converge in {n_max} iterations (the last displacement increment is {:.3e} of \
             the displacement scale, tolerance {:e}; largest residual force {:.3e} N): raise [integrator] \
             max_iterations or tolerance, or reduce dt",
            last_increment,
            self.settings.tolerance,
            self.residual.amax()
        ))
    }
}

impl Integrator for NewmarkNewton {
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
        if self.failure.is_some() {
            return;
        }
        match self.try_step(load_next) {
            Ok(()) => {
                self.springs.commit();
                std::mem::swap(&mut self.state, &mut self.next);
            }
            Err(reason) => {
                self.springs.revert();
                self.failure = Some(reason);
            }
        }
    }
    fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }
    fn springs(&self) -> Option<&Springs> {
        Some(&self.springs)
    }
    fn newton_iterations(&self) -> Option<(usize, usize)> {
        Some(self.iterations())
    }
}
