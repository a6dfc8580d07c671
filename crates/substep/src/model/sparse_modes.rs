//! The lowest natural frequencies of a large sparse model by subspace iteration
//! (Bathe): `Y = K⁻¹ M X`, Rayleigh–Ritz on `span Y`, repeat. Only `n × p` blocks are stored
//! (`p` a little larger than the number of modes wanted), never an `n × n` matrix.

use crate::error::{Error, Result};
use crate::sparse::{CscMatrix, FactorKind, SymmetricFactor};
use nalgebra::DMatrix;

/// Circular frequencies `ω_1 ≤ … ≤ ω_count` [rad/s] of `K φ = ω² M φ` for symmetric positive
/// definite `K` and `M`.
pub fn lowest_frequencies(mass: &CscMatrix, stiffness: &CscMatrix, count: usize) -> Result<Vec<f64>> {
    let n = mass.n();
    if count == 0 || count > n {
        return Err(Error::invalid(
            "structure.rayleigh.modes",
            format!("mode number {count} is outside 1..={n}"),
        ));
    }
    lowest_modes(
        mass,
        stiffness,
        count,
        "structure.stiffness (modal analysis needs a supported structure)",
    )
    .map(|m| m.omega)
}

/// The lowest modes of a sparse model: circular frequencies [rad/s] and mass-normalised shapes
/// (`n × count`, `φᵀ M φ = I`).
#[derive(Debug, Clone)]
pub struct SparseModes {
    pub omega: Vec<f64>,
    pub shapes: DMatrix<f64>,
}

/// The lowest `count ≤ n` modes of `K φ = ω² M φ` (`K` positive definite, `M` positive
/// semi-definite with at least `count` DOFs of mass; its massless DOFs follow statically).
/// `what` names `K` in the error when it cannot be factorised.
pub fn lowest_modes(mass: &CscMatrix, stiffness: &CscMatrix, count: usize, what: &str) -> Result<SparseModes> {
    let n = mass.n();
    assert!(count >= 1 && count <= n, "lowest_modes: count {count} outside 1..={n}");
    let p = n.min((2 * count).max(count + 8));
    let mut k_fac = SymmetricFactor::new(stiffness, FactorKind::Auto, what)?;
    // Start vectors: the diagonal of M (a ground-motion-like load) and smooth deterministic
    // patterns of increasing wave number.
    let md = mass.diagonal();
    let mut x = DMatrix::from_fn(n, p, |i, j| {
        if j == 0 {
            md[i].abs().max(f64::MIN_POSITIVE)
        } else {
            ((i + 1) as f64 * (j as f64 * 0.913 + 0.271)).sin() + 0.1 * ((i * (j + 3)) % 7) as f64
        }
    });
    let mut y = DMatrix::zeros(n, p);
    let mut ky = DMatrix::zeros(n, p);
    let mut lambda_old = vec![f64::INFINITY; count];
    for _ in 0..MAX_ITERATIONS {
        // Y = K⁻¹ M X
        for j in 0..p {
            let (xj, mut yj) = (x.column(j), y.column_mut(j));
            mass.sym_mul_add(1.0, xj.as_slice(), 0.0, yj.as_mut_slice());
            k_fac.solve_in_place(yj.as_mut_slice());
        }
        // Reduced matrices Yᵀ K Y, Yᵀ M Y (M Y kept in x as scratch).
        for j in 0..p {
            stiffness.sym_mul_add(1.0, y.column(j).as_slice(), 0.0, ky.column_mut(j).as_mut_slice());
            mass.sym_mul_add(1.0, y.column(j).as_slice(), 0.0, x.column_mut(j).as_mut_slice());
        }
        let kr = symmetrise(y.transpose() * &ky);
        let mr = symmetrise(y.transpose() * &x);
        let reduced = super::modes(&mr, &kr).map_err(|e| {
            Error::numerical(
                "modal analysis (subspace iteration)",
                format!("reduced problem failed: {e}"),
            )
        })?;
        x = &y * &reduced.shapes;
        let lambda: Vec<f64> = reduced.omega.iter().take(count).map(|w| w * w).collect();
        let converged = lambda
            .iter()
            .zip(&lambda_old)
            .all(|(l, o)| (l - o).abs() <= 1e-12 * l.abs().max(f64::MIN_POSITIVE));
        if converged {
            return Ok(SparseModes {
                omega: lambda.iter().map(|l| l.sqrt()).collect(),
                shapes: x.columns(0, count).into_owned(),
            });
        }
        lambda_old = lambda;
    }
    Err(Error::numerical(
        "modal analysis (subspace iteration)",
        format!("the lowest {count} frequencies did not converge in {MAX_ITERATIONS} iterations"),
    ))
}

/// Subspace iterations before a modal analysis gives up.
pub const MAX_ITERATIONS: usize = 200;

fn symmetrise(a: DMatrix<f64>) -> DMatrix<f64> {
    (&a + a.transpose()) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chain_frequencies_match_the_closed_form() {
        // Uniform shear chain: ω_j = 2 √(k/m) sin((2j−1)π / (2(2N+1))).
        let (n, k, m) = (400, 2.0e7, 1.0e5);
        let mut t = Vec::new();
        for i in 0..n {
            t.push((i, i, if i + 1 < n { 2.0 * k } else { k }));
            if i + 1 < n {
                t.push((i, i + 1, -k));
                t.push((i + 1, i, -k));
            }
        }
        let kk = CscMatrix::from_triplets(n, &t);
        let mm = CscMatrix::from_diagonal(&vec![m; n]);
        let w = lowest_frequencies(&mm, &kk, 3).unwrap();
        for (j, wj) in w.iter().enumerate() {
            let exact =
                2.0 * (k / m).sqrt() * (((2 * j + 1) as f64) * std::f64::consts::PI / (2.0 * (2 * n + 1) as f64)).sin();
            assert!((wj - exact).abs() < 1e-9 * exact, "mode {}: {wj} vs {exact}", j + 1);
        }
    }
}
