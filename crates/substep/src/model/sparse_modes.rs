//! The lowest natural modes of a large sparse model by shift-invert block Lanczos with full
//! reorthogonalisation.
//!
//! `K φ = ω² M φ` becomes `A φ = θ φ` with `A = K⁻¹ M` and `θ = 1/ω²`; `A` is self-adjoint in
//! the `M` inner product, and the lowest frequencies are its largest, best separated `θ`. The
//! Krylov basis `Q` (`Qᵀ M Q = I`) grows one vector per application of `A` (one sparse solve):
//! `w = A q_j`, orthogonalised against every vector so far (Gram–Schmidt in `M`, a second pass
//! when the first cancelled more than 30 % of `w`), which gives column `j` of the projection
//! `H = Qᵀ M A Q` exactly; the rest of `w` is the next vector. `BLOCK` start vectors make it a
//! band (block) Lanczos, so eigenvalues repeated up to `BLOCK` times (a symmetric plan) are all
//! found. With `m` vectors applied and `k` in the basis, the Ritz pairs `(θ, Q_m s)` of the
//! leading `m × m` block of `H` have the residual `‖A y − θ y‖_M = ‖H[m..k, ..m] s‖`; a mode is
//! converged when that is below `1e-10 θ` (its frequency is then exact to about 1e-20 over the
//! relative gap). Only `n × k` vectors are stored, never an `n × n` matrix, and the basis is kept
//! between calls, so asking for more modes continues the same iteration.
//!
//! `M` may be semi-definite: the start vectors are images `K⁻¹ M x`, so the whole basis lies in
//! the range of `A`, where `‖·‖_M` is a norm; massless DOFs follow statically.

use crate::error::{Error, Result};
use crate::sparse::{CscMatrix, FactorKind, SymmetricFactor};
use nalgebra::{DMatrix, DMatrixView, DVectorView};

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
    ModeSolver::new(mass, stiffness, what)?.lowest(count)
}

/// Start vectors of the block Lanczos iteration (and the largest multiplicity it resolves).
pub const BLOCK: usize = 4;

/// Relative residual `‖A y − θ y‖_M / θ` below which a mode counts as converged.
pub const TOLERANCE: f64 = 1e-10;

/// The most Lanczos vectors kept for `count` modes (before the iteration gives up).
pub fn max_vectors(count: usize) -> usize {
    4 * count + 8 * BLOCK + 40
}

/// An ongoing shift-invert block Lanczos iteration on `K φ = ω² M φ` (module docs); the factor
/// of `K` and the basis are kept, so [`ModeSolver::lowest`] with a larger count goes on from
/// where the last call stopped.
pub struct ModeSolver<'a> {
    mass: &'a CscMatrix,
    factor: SymmetricFactor,
    n: usize,
    /// The `M`-orthonormal basis, column-major `n × k`.
    basis: Vec<f64>,
    /// Column `j` of `H = Qᵀ M A Q` for each applied vector `j` (entries past its end are zero).
    projection: Vec<Vec<f64>>,
    /// Start vectors drawn so far (for a deterministic sequence).
    seeds: u64,
    /// No new direction can be found (the basis spans the range of `A`).
    exhausted: bool,
    work: Vec<f64>,
    mass_work: Vec<f64>,
}

impl<'a> ModeSolver<'a> {
    /// Factorise `K` (errors name it by `what`).
    pub fn new(mass: &'a CscMatrix, stiffness: &CscMatrix, what: &str) -> Result<Self> {
        let n = mass.n();
        let factor = SymmetricFactor::new(stiffness, FactorKind::Auto, what)?;
        Ok(Self {
            mass,
            factor,
            n,
            basis: Vec::new(),
            projection: Vec::new(),
            seeds: 0,
            exhausted: false,
            work: vec![0.0; n],
            mass_work: vec![0.0; n],
        })
    }

    /// The factor of `K` (for further solves with the same matrix).
    pub fn factor_mut(&mut self) -> &mut SymmetricFactor {
        &mut self.factor
    }

    /// Vectors in the basis so far.
    pub fn basis_len(&self) -> usize {
        self.basis.len() / self.n.max(1)
    }

    /// The lowest `count` modes (`1 ≤ count ≤ n`), continuing the iteration as far as needed.
    pub fn lowest(&mut self, count: usize) -> Result<SparseModes> {
        assert!(
            count >= 1 && count <= self.n,
            "lowest: count {count} outside 1..={}",
            self.n
        );
        let limit = self.n.min(max_vectors(count));
        if self.basis.is_empty() {
            for _ in 0..BLOCK {
                self.add_seed();
            }
        }
        let mut next_check = count;
        loop {
            let (k, m) = (self.basis_len(), self.projection.len());
            let finished = m == k; // nothing left to apply
            if m >= count && (m >= next_check || finished) {
                if let Some(modes) = self.ritz(count)? {
                    return Ok(modes);
                }
                next_check = m + (m / 8).max(BLOCK);
            }
            if finished {
                return Err(Error::numerical(
                    "modal analysis (Lanczos)",
                    if self.exhausted && m < count {
                        format!("the model has only {m} modes with mass, {count} asked")
                    } else {
                        format!("the lowest {count} frequencies did not converge with {k} Lanczos vectors")
                    },
                ));
            }
            self.apply(k < limit);
        }
    }

    /// Start the basis with `K⁻¹ b` for each load `b` (instead of pseudo-random images), in
    /// order; a load that adds no new direction is skipped. Must come before any other call.
    pub fn start_with(&mut self, loads: &[Vec<f64>]) {
        assert!(self.basis.is_empty(), "start_with on a started iteration");
        for b in loads {
            let mut x = b.clone();
            self.factor.solve_in_place(&mut x);
            let (_, before, after) = self.orthogonalise(&mut x);
            if before > 0.0 && after > 1e-8 * before {
                self.accept(&x, after, None);
            }
        }
    }

    /// The first `count ≤ n` vectors of the `M`-orthonormal Krylov basis (`n × count`), grown
    /// as far as needed: with [`start_with`](Self::start_with) the load-dependent Ritz vectors
    /// of those loads (Wilson, Yuan & Dickens 1982, here in block form).
    pub fn krylov_basis(&mut self, count: usize) -> Result<DMatrix<f64>> {
        assert!(count <= self.n, "krylov_basis: count {count} outside 0..={}", self.n);
        if self.basis.is_empty() {
            for _ in 0..BLOCK {
                self.add_seed();
            }
        }
        while self.basis_len() < count {
            if self.projection.len() == self.basis_len() {
                // Every vector applied (an invariant subspace): a fresh direction.
                self.add_seed();
                if self.projection.len() == self.basis_len() {
                    return Err(Error::numerical(
                        "Ritz vectors (Lanczos)",
                        format!(
                            "the model has only {} independent directions with mass, {count} asked",
                            self.basis_len()
                        ),
                    ));
                }
                continue;
            }
            self.apply(true);
        }
        Ok(DMatrix::from_column_slice(self.n, count, &self.basis[..self.n * count]))
    }

    /// `w = A q_m`, orthogonalised: column `m` of `H`, and the next basis vector if `grow`.
    fn apply(&mut self, grow: bool) {
        let (n, j) = (self.n, self.projection.len());
        let mut w = std::mem::take(&mut self.work);
        self.mass
            .sym_mul_add(1.0, &self.basis[j * n..(j + 1) * n], 0.0, &mut self.mass_work);
        w.copy_from_slice(&self.mass_work);
        self.factor.solve_in_place(&mut w);
        let (column, before, after) = self.orthogonalise(&mut w);
        self.projection.push(column);
        if grow {
            if after > 1e-10 * before {
                self.accept(&w, after, Some(j));
            } else {
                // A q_j lies in the basis already (an invariant subspace): a fresh direction.
                self.add_seed();
            }
        }
        self.work = w;
    }

    /// Append `w / norm` to the basis; its projection entry `H[k, j] = norm` if it came from `A q_j`.
    fn accept(&mut self, w: &[f64], norm: f64, from: Option<usize>) {
        let k = self.basis_len();
        self.basis.extend(w.iter().map(|x| x / norm));
        if let Some(j) = from {
            let column = &mut self.projection[j];
            column.resize(k + 1, 0.0);
            column[k] = norm;
        }
    }

    /// Add `K⁻¹ M x` for a fresh deterministic pseudo-random `x`, orthogonalised; marks the
    /// iteration exhausted when a few such vectors all lie in the basis.
    fn add_seed(&mut self) {
        let n = self.n;
        for _ in 0..3 {
            self.seeds += 1;
            let mut state = self.seeds.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
            let md = self.mass.diagonal();
            let mut x: Vec<f64> = (0..n)
                .map(|i| {
                    if self.seeds == 1 {
                        // A ground-motion-like load first.
                        return md[i];
                    }
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
                })
                .collect();
            self.mass.sym_mul_add(1.0, &x, 0.0, &mut self.mass_work);
            x.copy_from_slice(&self.mass_work);
            self.factor.solve_in_place(&mut x);
            let (_, before, after) = self.orthogonalise(&mut x);
            if before > 0.0 && after > 1e-8 * before {
                self.accept(&x, after, None);
                return;
            }
        }
        self.exhausted = true;
    }

    /// Remove from `w` its `M`-projection on the basis (one or two classical Gram–Schmidt
    /// passes); returns the coefficients and `‖w‖_M` before and after.
    fn orthogonalise(&mut self, w: &mut [f64]) -> (Vec<f64>, f64, f64) {
        let (n, k) = (self.n, self.basis_len());
        let q = DMatrixView::from_slice(&self.basis, n, k);
        let mut coefficients = vec![0.0; k];
        self.mass.sym_mul_add(1.0, w, 0.0, &mut self.mass_work);
        let norm = |w: &[f64], mw: &[f64]| w.iter().zip(mw).map(|(a, b)| a * b).sum::<f64>().max(0.0).sqrt();
        let before = norm(w, &self.mass_work);
        let mut current = before;
        for _ in 0..2 {
            if k == 0 {
                break;
            }
            let h = q.tr_mul(&DVectorView::from_slice(&self.mass_work, n));
            let mut wv = nalgebra::DVectorViewMut::from_slice(w, n);
            wv.gemv(-1.0, &q, &h, 1.0);
            coefficients.iter_mut().zip(h.iter()).for_each(|(c, h)| *c += h);
            self.mass.sym_mul_add(1.0, w, 0.0, &mut self.mass_work);
            let after = norm(w, &self.mass_work);
            let enough = after > 0.7 * current;
            current = after;
            if enough {
                break;
            }
        }
        (coefficients, before, current)
    }

    /// The `count` lowest Ritz modes of the applied part of the basis, if all have converged.
    fn ritz(&self, count: usize) -> Result<Option<SparseModes>> {
        let (n, k, m) = (self.n, self.basis_len(), self.projection.len());
        let entry = |i: usize, j: usize| self.projection[j].get(i).copied().unwrap_or(0.0);
        let h = faer::Mat::<f64>::from_fn(m, m, |i, j| 0.5 * (entry(i, j) + entry(j, i)));
        let eigen = h.self_adjoint_eigen(faer::Side::Lower).map_err(|e| {
            Error::numerical(
                "modal analysis (Lanczos)",
                format!("the projected eigenproblem failed: {e:?}"),
            )
        })?;
        let (theta, s) = (eigen.S().column_vector(), eigen.U());
        // Largest θ first (ascending order from faer).
        let wanted: Vec<usize> = (0..count).map(|c| m - 1 - c).collect();
        for &c in &wanted {
            if theta[c].is_nan() || theta[c] <= 0.0 {
                return Err(Error::numerical(
                    "modal analysis (Lanczos)",
                    "the structure has a mode without stiffness or mass (check supports and masses)",
                ));
            }
            let mut residual = 0.0;
            for i in m..k {
                let r: f64 = (0..m).map(|j| entry(i, j) * s[(j, c)]).sum();
                residual += r * r;
            }
            if residual.sqrt() > TOLERANCE * theta[c] {
                return Ok(None);
            }
        }
        let q = DMatrixView::from_slice(&self.basis[..n * m], n, m);
        let selected = DMatrix::from_fn(m, count, |j, c| s[(j, wanted[c])]);
        Ok(Some(SparseModes {
            omega: wanted.iter().map(|&c| 1.0 / theta[c].sqrt()).collect(),
            shapes: q * selected,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain(n: usize, k: f64) -> Vec<(usize, usize, f64)> {
        let mut t = Vec::new();
        for i in 0..n {
            t.push((i, i, if i + 1 < n { 2.0 * k } else { k }));
            if i + 1 < n {
                t.push((i, i + 1, -k));
                t.push((i + 1, i, -k));
            }
        }
        t
    }

    /// Uniform shear chain: ω_j = 2 √(k/m) sin((2j−1)π / (2(2N+1))).
    fn chain_omega(n: usize, k: f64, m: f64, j: usize) -> f64 {
        2.0 * (k / m).sqrt() * (((2 * j + 1) as f64) * std::f64::consts::PI / (2.0 * (2 * n + 1) as f64)).sin()
    }

    #[test]
    fn chain_frequencies_match_the_closed_form() {
        let (n, k, m) = (400, 2.0e7, 1.0e5);
        let kk = CscMatrix::from_triplets(n, &chain(n, k));
        let mm = CscMatrix::from_diagonal(&vec![m; n]);
        let w = lowest_frequencies(&mm, &kk, 3).unwrap();
        for (j, wj) in w.iter().enumerate() {
            let exact = chain_omega(n, k, m, j);
            assert!((wj - exact).abs() < 1e-9 * exact, "mode {}: {wj} vs {exact}", j + 1);
        }
        // Many modes, asked for in steps as the reduction does: the same iteration goes on.
        let mut solver = ModeSolver::new(&mm, &kk, "K").unwrap();
        for count in [10, 60, 150] {
            let modes = solver.lowest(count).unwrap();
            for (j, wj) in modes.omega.iter().enumerate() {
                let exact = chain_omega(n, k, m, j);
                assert!(
                    (wj - exact).abs() < 1e-9 * exact,
                    "{count}: mode {}: {wj} vs {exact}",
                    j + 1
                );
            }
            let orth = modes.shapes.transpose() * &modes.shapes * m;
            assert!((orth - DMatrix::<f64>::identity(count, count)).amax() < 1e-8);
        }
        assert!(solver.basis_len() <= max_vectors(150));
    }

    #[test]
    fn repeated_frequencies_are_all_found() {
        // Two identical chains side by side (and a third, stiffer one): every frequency of the
        // first two is double.
        let (n, k, m) = (60, 1.0e6, 1.0e3);
        let mut t = chain(n, k);
        t.extend(chain(n, k).into_iter().map(|(i, j, v)| (i + n, j + n, v)));
        t.extend(chain(n, 4.0 * k).into_iter().map(|(i, j, v)| (i + 2 * n, j + 2 * n, v)));
        let kk = CscMatrix::from_triplets(3 * n, &t);
        let mm = CscMatrix::from_diagonal(&vec![m; 3 * n]);
        let w = lowest_modes(&mm, &kk, 12, "K").unwrap().omega;
        let mut exact: Vec<f64> = (0..8)
            .flat_map(|j| {
                let w = chain_omega(n, k, m, j);
                [w, w, 2.0 * w]
            })
            .collect();
        exact.sort_by(f64::total_cmp);
        for (j, (a, b)) in w.iter().zip(&exact).enumerate() {
            assert!((a - b).abs() < 1e-9 * b, "mode {}: {a} vs {b}", j + 1);
        }
    }

    #[test]
    fn every_mode_of_a_small_model_and_massless_dofs() {
        // All modes of a 12-DOF chain, and a chain whose every other DOF is massless (its
        // modes are those of the condensed chain of springs in series: k/2 between masses).
        let (n, k, m) = (12, 3.0e5, 2.0e2);
        let kk = CscMatrix::from_triplets(n, &chain(n, k));
        let mm = CscMatrix::from_diagonal(&vec![m; n]);
        let w = lowest_frequencies(&mm, &kk, n).unwrap();
        for (j, wj) in w.iter().enumerate() {
            let exact = chain_omega(n, k, m, j);
            assert!((wj - exact).abs() < 1e-9 * exact, "mode {}: {wj} vs {exact}", j + 1);
        }
        let masses: Vec<f64> = (0..2 * n).map(|i| if i % 2 == 1 { m } else { 0.0 }).collect();
        let kk2 = CscMatrix::from_triplets(2 * n, &chain(2 * n, 2.0 * k));
        let mm2 = CscMatrix::from_diagonal(&masses);
        let w = lowest_frequencies(&mm2, &kk2, n).unwrap();
        for (j, wj) in w.iter().enumerate() {
            let exact = chain_omega(n, k, m, j);
            assert!(
                (wj - exact).abs() < 1e-9 * exact,
                "massless: mode {}: {wj} vs {exact}",
                j + 1
            );
        }
        // More modes than DOFs with mass: a clear error, not a hang.
        let e = lowest_modes(&mm2, &kk2, n + 1, "K").unwrap_err().to_string();
        assert!(e.contains(&format!("only {n} modes with mass")), "{e}");
    }

    #[test]
    fn ritz_vectors_of_a_load_span_its_krylov_space() {
        // The first Ritz vector is the static response K⁻¹ b; the basis is M-orthonormal and
        // spans {K⁻¹ b, (K⁻¹ M) K⁻¹ b, …} (checked against the plain power sequence).
        let (n, k, m) = (50, 1.0e6, 1.0e3);
        let kk = CscMatrix::from_triplets(n, &chain(n, k));
        let mm = CscMatrix::from_diagonal(&vec![m; n]);
        let load = vec![m; n];
        let mut solver = ModeSolver::new(&mm, &kk, "K").unwrap();
        solver.start_with(std::slice::from_ref(&load));
        let q = solver.krylov_basis(6).unwrap();
        let orth = q.transpose() * &q * m;
        assert!((orth - DMatrix::<f64>::identity(6, 6)).amax() < 1e-10);
        let dense_k = kk.to_dense();
        let chol = dense_k.clone().cholesky().unwrap();
        let mut v = chol.solve(&nalgebra::DVector::from_vec(load));
        for j in 0..6 {
            // v lies in span(q): its M-projection on q leaves nothing.
            let coeff = q.transpose() * &v * m;
            let rest = &v - &q * coeff;
            assert!(rest.norm() < 1e-9 * v.norm(), "power {j}: {}", rest.norm() / v.norm());
            if j == 0 {
                let cos = q.column(0).dot(&v).abs() * m.sqrt() / v.norm();
                assert!((cos - 1.0).abs() < 1e-12, "first vector is K⁻¹ b: {cos}");
            }
            v = chol.solve(&(&v * m));
            v /= v.norm();
        }
        assert!(solver.krylov_basis(n).is_ok());
    }
}
