//! Damping models: explicit matrix, Rayleigh (`C = α M + β K`) and modal damping
//! (`C = M Φ diag(2 ζ_j ω_j) Φᵀ M` with mass-normalised `Φ`).

use super::modal::modes;
use crate::error::{Error, Result, require_non_negative};
use nalgebra::{DMatrix, DVector};

#[derive(Debug, Clone, PartialEq)]
pub enum DampingSpec {
    Matrix(DMatrix<f64>),
    /// `C = alpha M + beta K`.
    Rayleigh {
        alpha: f64,
        beta: f64,
    },
    /// Rayleigh damping with ratio `zeta` at modes `modes.0` and `modes.1` (1-based).
    RayleighRatio {
        zeta: f64,
        modes: (usize, usize),
    },
    /// Modal damping; one ratio for all modes, or one per mode.
    Modal {
        zeta: Vec<f64>,
    },
}

impl DampingSpec {
    pub fn build(&self, mass: &DMatrix<f64>, stiffness: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        match self {
            DampingSpec::Matrix(c) => Ok(c.clone()),
            DampingSpec::Rayleigh { alpha, beta } => {
                require_non_negative("structure.rayleigh.alpha", *alpha)?;
                require_non_negative("structure.rayleigh.beta", *beta)?;
                Ok(mass * *alpha + stiffness * *beta)
            }
            DampingSpec::RayleighRatio { zeta, modes: (i, j) } => {
                require_non_negative("structure.rayleigh.zeta", *zeta)?;
                let m = modes(mass, stiffness)?;
                let n = m.omega.len();
                for (key, k) in [("first", *i), ("second", *j)] {
                    if k == 0 || k > n {
                        return Err(Error::invalid(
                            "structure.rayleigh.modes",
                            format!("{key} mode number {k} is outside 1..={n}"),
                        ));
                    }
                }
                if i == j {
                    return Err(Error::invalid("structure.rayleigh.modes", "the two modes must differ"));
                }
                let (alpha, beta) = rayleigh_coefficients(*zeta, m.omega[i - 1], m.omega[j - 1])?;
                Ok(mass * alpha + stiffness * beta)
            }
            DampingSpec::Modal { zeta } => {
                let n = mass.nrows();
                let z: Vec<f64> = match zeta.len() {
                    1 => vec![zeta[0]; n],
                    len if len == n => zeta.clone(),
                    len => {
                        return Err(Error::invalid(
                            "structure.modal.zeta",
                            format!("has {len} entries; give one value or one per mode ({n})"),
                        ));
                    }
                };
                for &v in &z {
                    require_non_negative("structure.modal.zeta", v)?;
                }
                modal_damping(mass, stiffness, &z)
            }
        }
    }
}

/// Rayleigh coefficients `(α, β)` that give ratio `zeta` at circular frequencies `w1`, `w2`.
pub fn rayleigh_coefficients(zeta: f64, w1: f64, w2: f64) -> Result<(f64, f64)> {
    if !(w1 > 0.0 && w2 > 0.0) || (w1 - w2).abs() < 1e-12 * w1.max(w2) {
        return Err(Error::invalid(
            "structure.rayleigh.modes",
            format!("need two distinct non-zero frequencies, got {w1} and {w2} rad/s"),
        ));
    }
    Ok((2.0 * zeta * w1 * w2 / (w1 + w2), 2.0 * zeta / (w1 + w2)))
}

/// `C = M Φ diag(2 ζ_j ω_j) Φᵀ M`.
pub fn modal_damping(mass: &DMatrix<f64>, stiffness: &DMatrix<f64>, zeta: &[f64]) -> Result<DMatrix<f64>> {
    if zeta.len() != mass.nrows() {
        return Err(Error::invalid(
            "structure.modal.zeta",
            format!("has {} entries but the model has {} modes", zeta.len(), mass.nrows()),
        ));
    }
    let m = modes(mass, stiffness)?;
    let d = DVector::from_iterator(zeta.len(), zeta.iter().zip(m.omega.iter()).map(|(z, w)| 2.0 * z * w));
    let mphi = mass * &m.shapes;
    let c = &mphi * DMatrix::from_diagonal(&d) * mphi.transpose();
    Ok((&c + c.transpose()) * 0.5)
}
