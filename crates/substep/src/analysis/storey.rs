//! Engineering response quantities of a building model: absolute accelerations, inter-storey
//! drifts, storey shears and the base shear.
//!
//! * Absolute acceleration `a_abs = ü + ι a_g` (the library integrates relative motion).
//! * Restoring force `r = K u + C u̇` of the numerical substructure on its DOFs.
//! * Base shear `V_b = ιᵀ r`: the force the ground exerts through the numerical substructure in
//!   the direction of the excitation (for a shear building: the first-storey shear). It holds for
//!   any model.
//! * For a *shear chain* (DOF `j` is floor `j` counted from the ground: diagonal `M`, tridiagonal
//!   `K`, `ι = 1`; any `C`): drift `δ_j = u_j − u_{j−1}` (`u_0 = 0`) and storey shear
//!   `V_j = Σ_{i≥j} r_i`, the force the numerical substructure transmits through storey `j`
//!   (cut below floor `j`: by equilibrium of the floors above, `V_j = −Σ_{i≥j} m_i a_abs,i` in a
//!   monolithic run), so `V_1 = V_b`. With tridiagonal `C` (Rayleigh) this is the storey's spring
//!   and dashpot force; forces of specimens are not included (they are the coupling forces).

use crate::error::{Error, Result};
use crate::model::StructuralModel;
use nalgebra::DVector;

/// Whether `model` is a shear chain as described in the module docs.
pub fn is_shear_chain(model: &StructuralModel) -> bool {
    let n = model.n_dofs();
    let banded = |m: &nalgebra::DMatrix<f64>, band: usize| {
        (0..n).all(|i| (0..n).all(|j| i.abs_diff(j) <= band || m[(i, j)] == 0.0))
    };
    model.influence.iter().all(|&x| x == 1.0) && banded(&model.stiffness, 1) && banded(&model.mass, 0)
}

/// Per-step building response, with preallocated work vectors (no allocation per step).
#[derive(Debug, Clone)]
pub struct StoreyResponse {
    model: StructuralModel,
    shear_chain: bool,
    restoring: DVector<f64>,
    product: DVector<f64>,
    /// Absolute accelerations [m/s²] per DOF.
    pub absolute_acceleration: Vec<f64>,
    /// Inter-storey drifts \[m\] (empty unless a shear chain).
    pub drift: Vec<f64>,
    /// Storey shears \[N\] (empty unless a shear chain).
    pub storey_shear: Vec<f64>,
    /// Base shear \[N\].
    pub base_shear: f64,
}

impl StoreyResponse {
    pub fn new(model: &StructuralModel) -> Self {
        let n = model.n_dofs();
        let shear_chain = is_shear_chain(model);
        let m = if shear_chain { n } else { 0 };
        Self {
            model: model.clone(),
            shear_chain,
            restoring: DVector::zeros(n),
            product: DVector::zeros(n),
            absolute_acceleration: vec![0.0; n],
            drift: vec![0.0; m],
            storey_shear: vec![0.0; m],
            base_shear: 0.0,
        }
    }

    pub fn is_shear_chain(&self) -> bool {
        self.shear_chain
    }

    /// Update every quantity from one state (`u`, `u̇`, `ü` relative, `a_g` [m/s²]).
    // Several arrays of one length walked together: the index form reads like the formula.
    #[allow(clippy::needless_range_loop)]
    pub fn update(&mut self, u: &[f64], v: &[f64], a: &[f64], ag: f64) -> Result<()> {
        self.update_nonlinear(u, v, a, ag, None)
    }

    /// [`update`](Self::update) for a nonlinear model: `deviation` is the springs' deviation
    /// force `d` (docs/theory.md §14.2), part of the restoring force `K₀ u + d`.
    #[allow(clippy::needless_range_loop)]
    pub fn update_nonlinear(
        &mut self,
        u: &[f64],
        v: &[f64],
        a: &[f64],
        ag: f64,
        deviation: Option<&[f64]>,
    ) -> Result<()> {
        let n = self.model.n_dofs();
        if u.len() != n || v.len() != n || a.len() != n {
            return Err(Error::invalid(
                "storey response",
                format!("expected {n} values of u, v and a"),
            ));
        }
        for k in 0..n {
            self.absolute_acceleration[k] = a[k] + self.model.influence[k] * ag;
        }
        self.product.copy_from_slice(u);
        self.restoring.gemv(1.0, &self.model.stiffness, &self.product, 0.0);
        self.product.copy_from_slice(v);
        self.restoring.gemv(1.0, &self.model.damping, &self.product, 1.0);
        if let Some(d) = deviation {
            for (r, d) in self.restoring.iter_mut().zip(d) {
                *r += d;
            }
        }
        self.base_shear = self.model.influence.dot(&self.restoring);
        if self.shear_chain {
            let mut below = 0.0;
            for k in 0..n {
                self.drift[k] = u[k] - below;
                below = u[k];
            }
            let mut sum = 0.0;
            for k in (0..n).rev() {
                sum += self.restoring[k];
                self.storey_shear[k] = sum;
            }
        }
        Ok(())
    }
}
