//! The frame integrated as the toolset does (`build_reference.m`, `build_numerical.m`): Newmark
//! average acceleration, one step per sample, from rest, with the ground acceleration of the
//! step's end time and the feedback force entering the right-hand side with a minus sign:
//!
//! ```text
//! K̄ U₁ = M (a₀U₀ + a₂V₀ + a₃A₀) + C (a₁U₀ + a₄V₀ + a₅A₀) − F − M ι a_g
//! A₁ = a₀(U₁ − U₀) − a₂V₀ − a₃A₀,   V₁ = V₀ + a₇A₁ + a₆A₀,   K̄ = K + a₀M + a₁C
//! ```
//!
//! Precomputed as `U₁ = [K̄⁻¹M  K̄⁻¹C] w − K̄⁻¹ Sᵀ F_c − K̄⁻¹Mι a_g` (one 29 × 58 product per
//! step; `F_c = [F₂₇, M₂₁, M₂₉]` the feedback at its three DOFs). The step is split into
//! [`NewmarkFrame::predict`] (everything but `F_c`) and [`NewmarkFrame::correct`] so that the
//! ideal transfer system can solve the coupled step implicitly.
//!
//! The virtual physical frame ([`FrameForce`]) gives the feedback from the measured `(x, θ)`:
//! `u = [x, θ, G(x, θ)]`, `f = K₅u + C₅u̇ + M₅ü` with the backward differences of Simulink's
//! Derivative block (0 at the first sample), `F₂₇ = f₁`, `M₂₁ = −f₂`, `M₂₉ = −f₃`.

use super::data::{DOF_THETA, DOF_THETA29, DOF_X1, N_DOF, VirtualFrame};
use crate::error::{Error, Result};
use nalgebra::{DMatrix, DVector, Matrix2, SMatrix, SVector, Vector2};

/// DOFs the feedback acts on, in the order of `F_c`.
pub const FORCE_DOFS: [usize; 3] = [DOF_X1, DOF_THETA, DOF_THETA29];

/// Newmark constants of `fcn_newmark_beta_const.m` (δ = 1/2, α = 1/4).
#[derive(Debug, Clone, Copy)]
struct Constants {
    a: [f64; 8],
}

impl Constants {
    fn new(dt: f64) -> Self {
        let (delta, alpha) = (0.5, 0.25);
        Self {
            a: [
                1.0 / (alpha * dt * dt),
                delta / (alpha * dt),
                1.0 / (alpha * dt),
                1.0 / (2.0 * alpha) - 1.0,
                delta / alpha - 1.0,
                dt / 2.0 * (delta / alpha - 2.0),
                dt * (1.0 - delta),
                delta * dt,
            ],
        }
    }
}

/// One structure (reference or numerical substructure), stepped per sample.
#[derive(Debug, Clone)]
pub struct NewmarkFrame {
    k: Constants,
    /// `[K̄⁻¹M  K̄⁻¹C]`.
    gain_mc: DMatrix<f64>,
    /// `K̄⁻¹ M ι`.
    gain_ground: DVector<f64>,
    /// `K̄⁻¹ Sᵀ` (columns at [`FORCE_DOFS`]).
    gain_force: SMatrix<f64, N_DOF, 3>,
    pub u: DVector<f64>,
    pub v: DVector<f64>,
    pub a: DVector<f64>,
    next: DVector<f64>,
    work: DVector<f64>,
}

impl NewmarkFrame {
    pub fn new(
        k: &DMatrix<f64>,
        m: &DMatrix<f64>,
        c: &DMatrix<f64>,
        influence: &[f64; N_DOF],
        dt: f64,
    ) -> Result<Self> {
        let consts = Constants::new(dt);
        let kbar = k + m * consts.a[0] + c * consts.a[1];
        let lu = kbar.lu();
        let solve = |rhs: &DMatrix<f64>| {
            lu.solve(rhs)
                .ok_or_else(|| Error::numerical("marths.structure", "the effective stiffness K̄ is singular"))
        };
        let gm = solve(m)?;
        let gc = solve(c)?;
        let mut gain_mc = DMatrix::zeros(N_DOF, 2 * N_DOF);
        gain_mc.view_mut((0, 0), (N_DOF, N_DOF)).copy_from(&gm);
        gain_mc.view_mut((0, N_DOF), (N_DOF, N_DOF)).copy_from(&gc);
        let iota = DVector::from_column_slice(influence);
        let gain_ground = &gm * &iota;
        let mut s = DMatrix::zeros(N_DOF, 3);
        for (j, &d) in FORCE_DOFS.iter().enumerate() {
            s[(d, j)] = 1.0;
        }
        let gf = solve(&s)?;
        let gain_force = SMatrix::<f64, N_DOF, 3>::from_fn(|i, j| gf[(i, j)]);
        Ok(Self {
            k: consts,
            gain_mc,
            gain_ground,
            gain_force,
            u: DVector::zeros(N_DOF),
            v: DVector::zeros(N_DOF),
            a: DVector::zeros(N_DOF),
            next: DVector::zeros(N_DOF),
            work: DVector::zeros(2 * N_DOF),
        })
    }

    /// The new displacements without the feedback force (kept inside until [`Self::commit`]).
    pub fn predict(&mut self, ag: f64) {
        let a = &self.k.a;
        for i in 0..N_DOF {
            self.work[i] = a[0] * self.u[i] + a[2] * self.v[i] + a[3] * self.a[i];
            self.work[N_DOF + i] = a[1] * self.u[i] + a[4] * self.v[i] + a[5] * self.a[i];
        }
        self.next.gemv(1.0, &self.gain_mc, &self.work, 0.0);
        self.next.axpy(-ag, &self.gain_ground, 1.0);
    }

    /// The predicted displacement of DOF `i`.
    pub fn predicted(&self, i: usize) -> f64 {
        self.next[i]
    }

    /// `K̄⁻¹ Sᵀ` row `i`: how DOF `i` moves per unit of each feedback component.
    pub fn force_gain(&self, i: usize) -> [f64; 3] {
        [
            self.gain_force[(i, 0)],
            self.gain_force[(i, 1)],
            self.gain_force[(i, 2)],
        ]
    }

    /// Subtract the feedback `F_c` (at [`FORCE_DOFS`]) from the prediction.
    pub fn correct(&mut self, force: [f64; 3]) {
        let f = SVector::<f64, 3>::from(force);
        let df = self.gain_force * f;
        for i in 0..N_DOF {
            self.next[i] -= df[i];
        }
    }

    /// Accept the step: `U₁`, then `A₁`, `V₁`.
    pub fn commit(&mut self) {
        let a = &self.k.a;
        for i in 0..N_DOF {
            let acc = a[0] * (self.next[i] - self.u[i]) - a[2] * self.v[i] - a[3] * self.a[i];
            self.v[i] += a[7] * acc + a[6] * self.a[i];
            self.a[i] = acc;
            self.u[i] = self.next[i];
        }
    }

    /// `predict`, `correct`, `commit`.
    pub fn step(&mut self, ag: f64, force: [f64; 3]) {
        self.predict(ag);
        self.correct(force);
        self.commit();
    }
}

/// The feedback force of the virtual physical frame from the measured `(x, θ)` (module docs).
#[derive(Debug, Clone)]
pub struct FrameForce {
    k: SMatrix<f64, 5, 5>,
    c: SMatrix<f64, 5, 5>,
    m: SMatrix<f64, 5, 5>,
    /// `u = T q`, `T = [I₂; G]`.
    t: SMatrix<f64, 5, 2>,
    dt: f64,
    u_prev: SVector<f64, 5>,
    ud_prev: SVector<f64, 5>,
    started: bool,
}

impl FrameForce {
    pub fn new(frame: &VirtualFrame, dt: f64) -> Self {
        let s = |m: &DMatrix<f64>| SMatrix::<f64, 5, 5>::from_fn(|i, j| m[(i, j)]);
        let t = SMatrix::<f64, 5, 2>::from_fn(|i, j| {
            if i < 2 {
                if i == j { 1.0 } else { 0.0 }
            } else {
                frame.condensation[(i - 2, j)]
            }
        });
        Self {
            k: s(&frame.k),
            c: s(&frame.c),
            m: s(&frame.m),
            t,
            dt,
            u_prev: SVector::zeros(),
            ud_prev: SVector::zeros(),
            started: false,
        }
    }

    fn select(f: &SVector<f64, 5>) -> [f64; 3] {
        [f[0], -f[1], -f[2]]
    }

    /// `F_c = [F₂₇, M₂₁, M₂₉]` for the measured `q = (x, θ)` of this sample; advances the
    /// differences.
    pub fn force(&mut self, q: [f64; 2]) -> [f64; 3] {
        let u = self.t * Vector2::new(q[0], q[1]);
        let (ud, udd) = if self.started {
            let ud = (u - self.u_prev) / self.dt;
            (ud, (ud - self.ud_prev) / self.dt)
        } else {
            (SVector::zeros(), SVector::zeros())
        };
        let f = self.k * u + self.c * ud + self.m * udd;
        self.u_prev = u;
        self.ud_prev = ud;
        self.started = true;
        Self::select(&f)
    }

    /// `F_c = A q + b` for this sample without advancing: the affine map the implicit ideal step
    /// solves with.
    pub fn affine(&self) -> (SMatrix<f64, 3, 2>, [f64; 3]) {
        let (ke, h) = if self.started {
            let (dt, dt2) = (self.dt, self.dt * self.dt);
            let ke = self.k + self.c / dt + self.m / dt2;
            let h = -(self.c * self.u_prev) / dt - self.m * (self.u_prev / dt2 + self.ud_prev / dt);
            (ke, h)
        } else {
            (self.k, SVector::zeros())
        };
        let a5 = ke * self.t;
        let a = SMatrix::<f64, 3, 2>::from_fn(|i, j| if i == 0 { a5[(0, j)] } else { -a5[(i, j)] });
        (a, Self::select(&h))
    }
}

/// The implicit step of the ideal transfer system (measured = target in the same sample): the
/// numerical substructure and the virtual frame solved together, `q = (U₂₇, −U₂₁)`:
/// `(I + S K̄⁻¹Sᵀ A) q = S U_p − S K̄⁻¹Sᵀ b`. Returns `q`; the frame is corrected but not committed.
pub fn solve_ideal(frame: &mut NewmarkFrame, force: &FrameForce) -> Result<[f64; 2]> {
    let (a, b) = force.affine();
    let gx = frame.force_gain(DOF_X1);
    let gt = frame.force_gain(DOF_THETA);
    // q = S U: q₀ = U₂₇, q₁ = −U₂₁.
    let sw = SMatrix::<f64, 2, 3>::from_fn(|i, j| if i == 0 { gx[j] } else { -gt[j] });
    let sb = sw * SVector::<f64, 3>::from(b);
    let sp = Vector2::new(frame.predicted(DOF_X1), -frame.predicted(DOF_THETA));
    let lhs = Matrix2::identity() + sw * a;
    let q = lhs
        .lu()
        .solve(&(sp - sb))
        .ok_or_else(|| Error::numerical("marths.ideal", "the coupled step is singular"))?;
    Ok([q[0], q[1]])
}
