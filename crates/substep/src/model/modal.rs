//! Generalised symmetric eigenproblem `K φ = ω² M φ` by Cholesky reduction
//! (`M = L Lᵀ`, `L⁻¹ K L⁻ᵀ y = λ y`, `φ = L⁻ᵀ y`), which keeps symmetry and gives
//! mass-normalised modes (`Φᵀ M Φ = I`).

use crate::error::{Error, Result};
use nalgebra::{DMatrix, DVector};

/// Modes sorted by increasing frequency.
#[derive(Debug, Clone)]
pub struct Modes {
    /// Circular frequencies `ω` [rad/s] (0 for rigid-body modes).
    pub omega: DVector<f64>,
    /// Mass-normalised mode shapes, one per column.
    pub shapes: DMatrix<f64>,
}

impl Modes {
    /// Natural frequencies in Hz.
    pub fn frequencies_hz(&self) -> Vec<f64> {
        self.omega.iter().map(|w| w / (2.0 * std::f64::consts::PI)).collect()
    }
}

pub fn modes(mass: &DMatrix<f64>, stiffness: &DMatrix<f64>) -> Result<Modes> {
    let n = mass.nrows();
    let chol = mass
        .clone()
        .cholesky()
        .ok_or_else(|| Error::invalid("structure.mass", "is not positive definite"))?;
    let l = chol.l();
    // X = L⁻¹ K, then A = L⁻¹ Xᵀ = L⁻¹ K L⁻ᵀ (K symmetric).
    let x = l
        .solve_lower_triangular(stiffness)
        .ok_or_else(|| Error::numerical("modal analysis", "singular mass factor"))?;
    let mut a = l
        .solve_lower_triangular(&x.transpose())
        .ok_or_else(|| Error::numerical("modal analysis", "singular mass factor"))?;
    a = (&a + a.transpose()) * 0.5;
    if a.iter().any(|x| !x.is_finite()) {
        return Err(Error::numerical(
            "modal analysis",
            "M⁻¹ᐟ² K M⁻ᐟ² is not finite (stiffness and mass outside what f64 can represent)",
        ));
    }
    // nalgebra's `SymmetricEigen::new` iterates until convergence without a cap.
    let eig = nalgebra::SymmetricEigen::try_new(a, f64::EPSILON, 1000 * n.max(10)).ok_or_else(|| {
        Error::numerical(
            "modal analysis",
            format!(
                "the eigenvalues of the {n}-DOF model did not converge in {} iterations",
                1000 * n.max(10)
            ),
        )
    })?;
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let scale = eig.eigenvalues.amax().max(f64::MIN_POSITIVE);
    let mut omega = DVector::zeros(n);
    let mut y = DMatrix::zeros(n, n);
    for (k, &i) in order.iter().enumerate() {
        let lambda = eig.eigenvalues[i];
        if lambda < -1e-9 * scale {
            return Err(Error::invalid(
                "structure.stiffness",
                format!("is not positive semi-definite (eigenvalue {lambda:.3e})"),
            ));
        }
        omega[k] = lambda.max(0.0).sqrt();
        y.set_column(k, &eig.eigenvectors.column(i));
    }
    let mut shapes = l
        .transpose()
        .solve_upper_triangular(&y)
        .ok_or_else(|| Error::numerical("modal analysis", "singular mass factor"))?;
    // Deterministic sign: the largest-magnitude component of each mode shape is positive.
    for mut col in shapes.column_iter_mut() {
        if col[col.iamax()] < 0.0 {
            col.neg_mut();
        }
    }
    Ok(Modes { omega, shapes })
}
