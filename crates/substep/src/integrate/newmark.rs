//! Newmark(β, γ) in effective-stiffness form (docs/theory.md §2.2) and its explicit member (β = 0).

use super::{Integrator, Kinematics};
use crate::error::{Error, Result};
use crate::model::{ModelRef, StructuralModel};
use crate::sparse::{CscMatrix, FactorKind, SparseOrdering, SymmetricFactor, SymmetricProduct};
use nalgebra::{Cholesky, DMatrix, DVector, Dyn};

/// The constants `a0 … a7` of docs/theory.md §2.2.
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

/// The parts of Newmark shared by the monolithic integrator and the sub-step controller: the
/// model matrices, the factorised effective stiffness `K̂ = K + a0 M + a1 C` and the work
/// vectors needed to form `F̂_i`. Dense models use nalgebra's dense Cholesky; sparse models
/// keep `M`, `C`, `K` in CSC form and factorise `K̂` once with [`SymmetricFactor`] (banded or
/// sparse Cholesky), so no step allocates and no `n × n` array exists on the sparse path.
pub struct NewmarkCore {
    pub c: NewmarkConstants,
    backend: Backend,
    work_m: DVector<f64>,
    work_c: DVector<f64>,
}

enum Backend {
    Dense {
        mass: DMatrix<f64>,
        damping: DMatrix<f64>,
        stiffness: DMatrix<f64>,
        k_hat: Cholesky<f64, Dyn>,
    },
    Sparse {
        mass: CscMatrix,
        /// The diagonal of `M` when `M` is diagonal (lumped masses): `F̂` in one gather pass.
        mass_diag: Option<Vec<f64>>,
        damping: CscMatrix,
        /// `C` stored once for the step's damping product (`None`: no damping, or too large
        /// for `u32` indices, then `damping` is used).
        damping_product: Option<Box<SymmetricProduct>>,
        stiffness: CscMatrix,
        k_hat: SymmetricFactor,
    },
}

const K_HAT: &str = "effective stiffness K + a0 M + a1 C";

/// `K̂ = K + a0 M + a1 C` of sparse matrices.
fn sparse_k_hat(stiffness: &CscMatrix, mass: &CscMatrix, damping: &CscMatrix, a: &[f64]) -> CscMatrix {
    CscMatrix::linear_combination(&[(1.0, stiffness), (a[0], mass), (a[1], damping)])
}

/// `out += C w`, by the once-stored lower half when there is one.
fn add_damping(damping: &CscMatrix, product: Option<&SymmetricProduct>, w: &[f64], out: &mut [f64]) {
    match product {
        Some(p) => p.mul_add(w, out),
        None if damping.nnz() > 0 => damping.sym_mul_add(1.0, w, 1.0, out),
        None => {}
    }
}

impl NewmarkCore {
    pub fn new<'a>(model: impl Into<ModelRef<'a>>, dt: f64, beta: f64, gamma: f64) -> Result<Self> {
        let model = model.into();
        let c = NewmarkConstants::new(beta, gamma, dt)?;
        let backend = match model {
            ModelRef::Dense(model) => {
                let k_eff = &model.stiffness + &model.mass * c.a[0] + &model.damping * c.a[1];
                let k_hat = k_eff
                    .cholesky()
                    .ok_or_else(|| Error::numerical(K_HAT, "is not positive definite (check K, C and dt)"))?;
                Backend::Dense {
                    mass: model.mass.clone(),
                    damping: model.damping.clone(),
                    stiffness: model.stiffness.clone(),
                    k_hat,
                }
            }
            ModelRef::Sparse(model) => {
                let k_eff = sparse_k_hat(&model.stiffness, &model.mass, &model.damping, &c.a);
                Backend::Sparse {
                    k_hat: SymmetricFactor::new(&k_eff, FactorKind::Auto, K_HAT)?,
                    mass_diag: model.mass.is_diagonal().then(|| model.mass.diagonal()),
                    mass: model.mass.clone(),
                    damping: model.damping.clone(),
                    damping_product: (model.damping.nnz() > 0)
                        .then(|| SymmetricProduct::new(&model.damping).map(Box::new))
                        .flatten(),
                    stiffness: model.stiffness.clone(),
                }
            }
        };
        let n = model.n_dofs();
        Ok(Self {
            c,
            backend,
            work_m: DVector::zeros(n),
            work_c: DVector::zeros(n),
        })
    }

    pub fn n_dofs(&self) -> usize {
        self.work_m.len()
    }

    /// `dense Cholesky`, or the sparse factorisation used (see [`SymmetricFactor::describe`]).
    pub fn solver(&self) -> String {
        match &self.backend {
            Backend::Dense { .. } => "dense Cholesky (nalgebra)".to_string(),
            Backend::Sparse { k_hat, .. } => k_hat.describe(),
        }
    }

    /// Sweep a sparse `K̂` on two cores (see [`SymmetricFactor::enable_second_core`]); `false`
    /// for dense and banded factors and trees without a balanced split.
    pub fn enable_second_core(&mut self) -> bool {
        match &mut self.backend {
            Backend::Dense { .. } => false,
            Backend::Sparse {
                k_hat,
                mass,
                damping,
                stiffness,
                ..
            } => {
                if k_hat.enable_second_core() {
                    return true;
                }
                if k_hat.ordering() != Some(SparseOrdering::Amd) {
                    return false;
                }
                // `Auto` kept AMD (its factor was smaller), whose elimination tree rarely has
                // two balanced halves; nested dissection's has them by construction. The same
                // K̂ factorised again, so the gain columns computed from the first stay valid.
                let k_eff = sparse_k_hat(stiffness, mass, damping, &self.c.a);
                let Ok(mut nd) =
                    SymmetricFactor::with_ordering(&k_eff, FactorKind::Sparse, SparseOrdering::NestedDissection, K_HAT)
                else {
                    return false;
                };
                if !nd.enable_second_core() {
                    return false;
                }
                *k_hat = nd;
                true
            }
        }
    }

    /// Bytes of the factor one solve reads (its floor is this over the memory bandwidth); for
    /// a dense factor the `n (n + 1) / 2` values read twice.
    pub fn solve_bytes(&self) -> usize {
        match &self.backend {
            Backend::Dense { .. } => {
                let n = self.n_dofs();
                8 * n * (n + 1)
            }
            Backend::Sparse { k_hat, .. } => k_hat.bytes_per_solve(),
        }
    }

    /// Overwrite `x` with `K̂⁻¹ x` (allocation-free).
    pub fn solve_in_place(&mut self, x: &mut DVector<f64>) {
        match &mut self.backend {
            Backend::Dense { k_hat, .. } => k_hat.solve_mut(x),
            Backend::Sparse { k_hat, .. } => k_hat.solve_in_place(x.as_mut_slice()),
        }
    }

    /// Overwrite each column of `x` with `K̂⁻¹` times it (e.g. the gain columns `K̂⁻¹ Sᵀ`).
    pub fn solve_columns_in_place(&mut self, x: &mut DMatrix<f64>) {
        match &mut self.backend {
            Backend::Dense { k_hat, .. } => k_hat.solve_mut(x),
            Backend::Sparse { k_hat, .. } => {
                for mut col in x.column_iter_mut() {
                    k_hat.solve_in_place(col.as_mut_slice());
                }
            }
        }
    }

    /// `α M X + β C X` for the columns of `X` (allocates; for set-up work such as the real-time
    /// runner's overlap gain).
    pub fn mass_damping_columns(&self, alpha: f64, beta: f64, x: &DMatrix<f64>) -> DMatrix<f64> {
        match &self.backend {
            Backend::Dense { mass, damping, .. } => {
                let mut out = mass * x * alpha;
                out.gemm(beta, damping, x, 1.0);
                out
            }
            Backend::Sparse { mass, damping, .. } => {
                let mut out = DMatrix::zeros(x.nrows(), x.ncols());
                for (j, col) in x.column_iter().enumerate() {
                    let mut o = out.column_mut(j);
                    let o = o.as_mut_slice();
                    mass.sym_mul_add(alpha, col.as_slice(), 0.0, o);
                    damping.sym_mul_add(beta, col.as_slice(), 1.0, o);
                }
                out
            }
        }
    }

    /// `out = M a + C v + K u` for the state `s` (allocation-free).
    pub fn internal_force(&self, s: &Kinematics, out: &mut DVector<f64>) {
        match &self.backend {
            Backend::Dense {
                mass,
                damping,
                stiffness,
                ..
            } => {
                out.gemv(1.0, mass, &s.a, 0.0);
                out.gemv(1.0, damping, &s.v, 1.0);
                out.gemv(1.0, stiffness, &s.u, 1.0);
            }
            Backend::Sparse {
                mass,
                damping,
                stiffness,
                ..
            } => {
                let o = out.as_mut_slice();
                mass.sym_mul_add(1.0, s.a.as_slice(), 0.0, o);
                damping.sym_mul_add(1.0, s.v.as_slice(), 1.0, o);
                stiffness.sym_mul_add(1.0, s.u.as_slice(), 1.0, o);
            }
        }
    }

    /// `out = F̂_i = M(a0 u + a2 v + a3 a) + C(a1 u + a4 v + a5 a)`.
    pub fn effective_load(&mut self, s: &Kinematics, out: &mut DVector<f64>) {
        let a = &self.c.a;
        if let Backend::Sparse {
            mass_diag: Some(md),
            damping,
            damping_product,
            ..
        } = &self.backend
        {
            // Lumped M: out_i = m_i (a0 u + a2 v + a3 a)_i + (C w_c)_i, w_c = a1 u + a4 v + a5 a.
            let (u, v, acc) = (s.u.as_slice(), s.v.as_slice(), s.a.as_slice());
            let o = out.as_mut_slice();
            for (((((oi, wc), m), u), v), acc) in o
                .iter_mut()
                .zip(self.work_c.as_mut_slice().iter_mut())
                .zip(md)
                .zip(u)
                .zip(v)
                .zip(acc)
            {
                *wc = a[1] * u + a[4] * v + a[5] * acc;
                *oi = m * (a[0] * u + a[2] * v + a[3] * acc);
            }
            add_damping(damping, damping_product.as_deref(), self.work_c.as_slice(), o);
            return;
        }
        self.work_m.copy_from(&s.u);
        self.work_m.scale_mut(a[0]);
        self.work_m.axpy(a[2], &s.v, 1.0);
        self.work_m.axpy(a[3], &s.a, 1.0);
        self.work_c.copy_from(&s.u);
        self.work_c.scale_mut(a[1]);
        self.work_c.axpy(a[4], &s.v, 1.0);
        self.work_c.axpy(a[5], &s.a, 1.0);
        match &self.backend {
            Backend::Dense { mass, damping, .. } => {
                out.gemv(1.0, mass, &self.work_m, 0.0);
                out.gemv(1.0, damping, &self.work_c, 1.0);
            }
            Backend::Sparse {
                mass,
                damping,
                damping_product,
                ..
            } => {
                let o = out.as_mut_slice();
                mass.sym_mul_add(1.0, self.work_m.as_slice(), 0.0, o);
                add_damping(damping, damping_product.as_deref(), self.work_c.as_slice(), o);
            }
        }
    }

    /// Given the new displacement in `s_next.u` and the old state, fill `s_next.a` and `s_next.v`:
    /// `a_{i+1} = a0 (u_{i+1} − u_i) − a2 v_i − a3 a_i`, `v_{i+1} = v_i + a6 a_i + a7 a_{i+1}`
    /// (one pass over the DOFs).
    pub fn update_kinematics(&self, s: &Kinematics, s_next: &mut Kinematics) {
        let a = &self.c.a;
        let (u, v, acc) = (s.u.as_slice(), s.v.as_slice(), s.a.as_slice());
        let Kinematics { u: un, v: vn, a: an } = s_next;
        let (a0, a2, a3, a6, a7) = (a[0], a[2], a[3], a[6], a[7]);
        for (((((an, vn), un), u), v), acc) in an
            .as_mut_slice()
            .iter_mut()
            .zip(vn.as_mut_slice().iter_mut())
            .zip(un.as_slice())
            .zip(u)
            .zip(v)
            .zip(acc)
        {
            let a_new = a0 * (un - u) - a2 * v - a3 * acc;
            *an = a_new;
            *vn = v + a6 * acc + a7 * a_new;
        }
    }
}

/// Implicit Newmark(β, γ), β > 0.
pub struct Newmark {
    core: NewmarkCore,
    state: Kinematics,
    next: Kinematics,
}

impl Newmark {
    pub fn new<'a>(
        model: impl Into<ModelRef<'a>>,
        dt: f64,
        beta: f64,
        gamma: f64,
        load0: &DVector<f64>,
    ) -> Result<Self> {
        let model = model.into();
        let core = NewmarkCore::new(model, dt, beta, gamma)?;
        let state = Kinematics::at_rest(model, load0)?;
        let next = state.clone();
        Ok(Self { core, state, next })
    }
}

impl Newmark {
    /// See [`NewmarkCore::enable_second_core`].
    pub fn enable_second_core(&mut self) -> bool {
        self.core.enable_second_core()
    }
    pub fn core(&self) -> &NewmarkCore {
        &self.core
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
        self.core.solve_in_place(&mut self.next.u);
        self.core.update_kinematics(&self.state, &mut self.next);
        std::mem::swap(&mut self.state, &mut self.next);
    }
}

/// Explicit Newmark (β = 0): `u_{i+1} = u_i + Δt v_i + Δt²/2 a_i`, then
/// `(M + γΔt C) a_{i+1} = f_{i+1} − C (v_i + (1−γ)Δt a_i) − K u_{i+1}`. With γ = ½ this is
/// algebraically the three-point central-difference scheme of docs/theory.md §2.1 (explicit form: §2.3).
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
