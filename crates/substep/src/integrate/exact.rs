//! Exact discretisation of a linear model under a piecewise-linear load (first-order hold,
//! docs/theory.md §2.6), the reference for all accuracy checks.
//!
//! With `z = [u; u̇]`, `ż = A z + B f`, the step map comes from
//! `expm(Δt [[A, B, 0], [0, 0, I/Δt], [0, 0, 0]])`, whose first block row gives
//! `z_{i+1} = Φ z_i + Γ₀ f_i + Γ₁ (f_{i+1} − f_i)`. The matrix exponential is of size `4n`,
//! so this scheme is meant for models up to a few hundred DOFs.

use super::{Integrator, Kinematics};
use crate::error::{Error, Result};
use crate::model::StructuralModel;
use nalgebra::{Cholesky, DMatrix, DVector, Dyn};

/// The discrete FOH step map of `ż = A z + B f`.
#[derive(Debug, Clone)]
pub struct FohMap {
    pub phi: DMatrix<f64>,
    pub gamma0: DMatrix<f64>,
    pub gamma1: DMatrix<f64>,
}

impl FohMap {
    /// Discretise `ż = A z + B w` (A: s×s, B: s×m) over `dt` for `w` linear in time.
    pub fn new(a: &DMatrix<f64>, b: &DMatrix<f64>, dt: f64) -> Self {
        Self::with_rate(a, b, &DMatrix::zeros(a.nrows(), b.ncols()), dt)
    }

    /// Discretise `ż = A z + B w + D ẇ` over `dt` for `w` linear in time (so `ẇ = Δw/Δt` is
    /// constant): the augmented matrix is `[[A Δt, B Δt, D], [0, 0, I], [0, 0, 0]]` acting on
    /// `[z; w_i; Δw]`. The rate term is how a dashpot sees a linearly moving support.
    pub fn with_rate(a: &DMatrix<f64>, b: &DMatrix<f64>, d: &DMatrix<f64>, dt: f64) -> Self {
        let (s, m) = (a.nrows(), b.ncols());
        let mut aug = DMatrix::zeros(s + 2 * m, s + 2 * m);
        aug.view_mut((0, 0), (s, s)).copy_from(&(a * dt));
        aug.view_mut((0, s), (s, m)).copy_from(&(b * dt));
        aug.view_mut((0, s + m), (s, m)).copy_from(d);
        for i in 0..m {
            aug[(s + i, s + m + i)] = 1.0;
        }
        let e = aug.exp();
        Self {
            phi: e.view((0, 0), (s, s)).into_owned(),
            gamma0: e.view((0, s), (s, m)).into_owned(),
            gamma1: e.view((0, s + m), (s, m)).into_owned(),
        }
    }

    /// `z_next = Φ z + Γ₀ w_start + Γ₁ (w_end − w_start)`; `dw` is scratch of the input size.
    pub fn apply(
        &self,
        z: &DVector<f64>,
        w_start: &DVector<f64>,
        w_end: &DVector<f64>,
        dw: &mut DVector<f64>,
        z_next: &mut DVector<f64>,
    ) {
        dw.copy_from(w_end);
        dw.axpy(-1.0, w_start, 1.0);
        z_next.gemv(1.0, &self.phi, z, 0.0);
        z_next.gemv(1.0, &self.gamma0, w_start, 1.0);
        z_next.gemv(1.0, &self.gamma1, dw, 1.0);
    }
}

pub struct ExactFoh {
    dt: f64,
    map: FohMap,
    mass: Cholesky<f64, Dyn>,
    damping: DMatrix<f64>,
    stiffness: DMatrix<f64>,
    state: Kinematics,
    z: DVector<f64>,
    z_next: DVector<f64>,
    load_prev: DVector<f64>,
    load_delta: DVector<f64>,
}

impl ExactFoh {
    pub fn new(model: &StructuralModel, dt: f64, load0: &DVector<f64>) -> Result<Self> {
        crate::error::require_positive("integrator.dt", dt)?;
        let n = model.n_dofs();
        let mass = model
            .mass
            .clone()
            .cholesky()
            .ok_or_else(|| Error::invalid("structure.mass", "is not positive definite"))?;
        let minv = mass.inverse();
        let mut a = DMatrix::zeros(2 * n, 2 * n);
        a.view_mut((0, n), (n, n)).fill_with_identity();
        a.view_mut((n, 0), (n, n)).copy_from(&(-&minv * &model.stiffness));
        a.view_mut((n, n), (n, n)).copy_from(&(-&minv * &model.damping));
        let mut b = DMatrix::zeros(2 * n, n);
        b.view_mut((n, 0), (n, n)).copy_from(&minv);
        let map = FohMap::new(&a, &b, dt);
        if map.phi.iter().any(|x| !x.is_finite()) {
            return Err(Error::numerical("exact integrator", "matrix exponential is not finite"));
        }
        let state = Kinematics::at_rest(model, load0)?;
        Ok(Self {
            dt,
            map,
            mass,
            damping: model.damping.clone(),
            stiffness: model.stiffness.clone(),
            state,
            z: DVector::zeros(2 * n),
            z_next: DVector::zeros(2 * n),
            load_prev: load0.clone(),
            load_delta: DVector::zeros(n),
        })
    }
}

impl Integrator for ExactFoh {
    fn name(&self) -> &'static str {
        "exact"
    }
    fn dt(&self) -> f64 {
        self.dt
    }
    fn state(&self) -> &Kinematics {
        &self.state
    }
    fn step(&mut self, load_next: &DVector<f64>) {
        let n = self.state.u.len();
        self.z.rows_mut(0, n).copy_from(&self.state.u);
        self.z.rows_mut(n, n).copy_from(&self.state.v);
        self.map.apply(
            &self.z,
            &self.load_prev,
            load_next,
            &mut self.load_delta,
            &mut self.z_next,
        );
        self.state.u.copy_from(&self.z_next.rows(0, n));
        self.state.v.copy_from(&self.z_next.rows(n, n));
        // a = M⁻¹ (f − C v − K u)
        let s = &mut self.state;
        s.a.copy_from(load_next);
        s.a.gemv(-1.0, &self.damping, &s.v, 1.0);
        s.a.gemv(-1.0, &self.stiffness, &s.u, 1.0);
        self.mass.solve_mut(&mut s.a);
        self.load_prev.copy_from(load_next);
    }
}
