//! Small dense helpers shared by the analysis and the model checks.

use nalgebra::{Complex, DMatrix};

/// Eigenvalues of a general real matrix, computed the safe way: Parlett–Reinsch balancing, then
/// a Schur decomposition with a bounded number of iterations (nalgebra's plain
/// `complex_eigenvalues` can loop forever on companion/shift matrices, see
/// docs/theory.md §11.1). Returns `None` if the iteration does not converge.
pub fn eigenvalues(m: &DMatrix<f64>) -> Option<Vec<Complex<f64>>> {
    let n = m.nrows();
    if n == 0 {
        return Some(Vec::new());
    }
    if m.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let mut b = m.clone();
    nalgebra::linalg::balancing::balance_parlett_reinsch(&mut b);
    let schur = nalgebra::Schur::try_new(b, f64::EPSILON, 200 * n.max(10))?;
    Some(schur.complex_eigenvalues().iter().copied().collect())
}

/// Spectral radius `max |λ|`, `NaN` if the eigenvalues could not be computed.
pub fn spectral_radius(m: &DMatrix<f64>) -> f64 {
    eigenvalues(m).map_or(f64::NAN, |ev| ev.iter().map(|z| z.norm()).fold(0.0, f64::max))
}
