//! Cholesky factorisation `A = L Lᵀ` of a sparse symmetric positive definite matrix, factorised
//! once and then used for allocation-free solves (one per time step).
//!
//! Two back ends:
//! * **banded**: natural ordering, `L` stored by rows within the half-bandwidth `b`. For chains
//!   and narrow frames (`b` small) this is the fastest possible: contiguous rows, no index
//!   arrays, `2 n (b + 1)` flops per solve.
//! * **sparse**: faer 0.24's sparse Cholesky with approximate-minimum-degree ordering
//!   (simplicial or supernodal, chosen by faer), single-threaded (`Par::Seq`). For wide
//!   frames and general FE patterns, where a band would fill in.
//!
//! [`FactorKind::Auto`] takes the band when its storage `n (b + 1)` is no larger than the AMD
//! factor's (`len_val` of faer's symbolic analysis).

use super::CscMatrix;
use super::supernodal::SupernodalSolve;
use crate::error::{Error, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::perm::PermRef;
use faer::sparse::SparseColMatRef;
use faer::sparse::SymbolicSparseColMatRef;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::linalg::{SupernodalThreshold, SymbolicSupernodalParams};
use faer::{Par, Side};

/// Which factorisation to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FactorKind {
    /// Banded if the band is no larger than the AMD-ordered sparse factor, else sparse.
    #[default]
    Auto,
    /// Natural ordering, band storage.
    Banded,
    /// faer's supernodal sparse Cholesky (ordering: [`SparseOrdering`]).
    Sparse,
}

/// Fill-reducing ordering of the sparse factor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SparseOrdering {
    /// Both, keeping the one with the smaller factor.
    #[default]
    Auto,
    /// Approximate minimum degree (faer).
    Amd,
    /// Nested dissection (METIS `NodeND`).
    NestedDissection,
}

impl SparseOrdering {
    pub fn name(self) -> &'static str {
        match self {
            SparseOrdering::Auto => "auto",
            SparseOrdering::Amd => "AMD",
            SparseOrdering::NestedDissection => "nested dissection (METIS)",
        }
    }
}

/// A factorised SPD matrix; [`SymmetricFactor::solve_in_place`] never allocates.
pub struct SymmetricFactor {
    n: usize,
    inner: Inner,
}

enum Inner {
    Banded(BandCholesky),
    Sparse(Box<FaerCholesky>),
}

impl std::fmt::Debug for SymmetricFactor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SymmetricFactor")
            .field("n", &self.n)
            .field("kind", &self.describe())
            .finish()
    }
}

impl SymmetricFactor {
    /// Factorise the symmetric `a` (both triangles stored). `what` names the matrix in errors
    /// (e.g. "effective stiffness K + a0 M + a1 C").
    pub fn new(a: &CscMatrix, kind: FactorKind, what: &str) -> Result<Self> {
        Self::with_ordering(a, kind, SparseOrdering::Auto, what)
    }

    /// [`SymmetricFactor::new`] with the ordering of the sparse factor chosen.
    pub fn with_ordering(a: &CscMatrix, kind: FactorKind, ordering: SparseOrdering, what: &str) -> Result<Self> {
        let n = a.n();
        let not_pd = || Error::numerical(what, "is not positive definite (check K, M, C and dt)");
        let b = a.half_bandwidth();
        let band_len = n.saturating_mul(b + 1);
        // Bands beyond this many stored values are never worth it (and would not fit).
        const BAND_MAX_LEN: usize = 200_000_000;
        let use_band = match kind {
            FactorKind::Banded => true,
            FactorKind::Sparse => false,
            FactorKind::Auto if b <= 2 => true,
            FactorKind::Auto if band_len > BAND_MAX_LEN => false,
            FactorKind::Auto => {
                let (symbolic, _) = FaerCholesky::symbolic_with(a, ordering, what)?;
                band_len <= symbolic.len_val()
            }
        };
        let inner = if use_band {
            if band_len > BAND_MAX_LEN {
                return Err(Error::numerical(
                    what,
                    format!("band storage of {n} rows x {} would be too large", b + 1),
                ));
            }
            Inner::Banded(BandCholesky::new(a, b).ok_or_else(not_pd)?)
        } else {
            Inner::Sparse(Box::new(FaerCholesky::new(a, ordering, what)?))
        };
        Ok(Self { n, inner })
    }

    pub fn n(&self) -> usize {
        self.n
    }

    /// Stored values of `L`.
    pub fn factor_len(&self) -> usize {
        match &self.inner {
            Inner::Banded(b) => b.l.len() + b.inv_d.len(),
            Inner::Sparse(s) => s.solve.len_val(),
        }
    }

    /// `banded (half-bandwidth b)` or `sparse Cholesky (AMD)`.
    pub fn describe(&self) -> String {
        match &self.inner {
            Inner::Banded(b) => format!("banded Cholesky (half-bandwidth {})", b.b),
            Inner::Sparse(s) => format!(
                "supernodal Cholesky ({} ordering, {} supernodes)",
                s.ordering.name(),
                s.solve.n_supernodes()
            ),
        }
    }

    /// Bytes of `L` (values and row indices) one solve reads: the forward and the backward
    /// sweep each read all of it. Over the memory bandwidth this is the floor of a solve.
    pub fn bytes_per_solve(&self) -> usize {
        match &self.inner {
            Inner::Banded(b) => 2 * 8 * (b.l.len() + b.inv_d.len()),
            Inner::Sparse(s) => s.solve.bytes_per_solve(),
        }
    }

    /// Sweep the sparse factor on two cores from now on: a worker thread takes one half of the
    /// elimination tree (theory §11.4). Opt-in, for a machine with a core to spare; `false`
    /// when the factor is banded or its tree has no balanced split (then nothing changes).
    pub fn enable_second_core(&mut self) -> bool {
        match &mut self.inner {
            Inner::Banded(_) => false,
            Inner::Sparse(s) => s.solve.enable_second_core(),
        }
    }

    /// Whether solves run on two cores ([`SymmetricFactor::enable_second_core`]).
    pub fn uses_second_core(&self) -> bool {
        match &self.inner {
            Inner::Banded(_) => false,
            Inner::Sparse(s) => s.solve.uses_second_core(),
        }
    }

    /// The ordering of the sparse factor (`None` for the band).
    pub fn ordering(&self) -> Option<SparseOrdering> {
        match &self.inner {
            Inner::Banded(_) => None,
            Inner::Sparse(s) => Some(s.ordering),
        }
    }

    /// Overwrite `x` (length `n`) with `A⁻¹ x`.
    pub fn solve_in_place(&mut self, x: &mut [f64]) {
        assert_eq!(x.len(), self.n, "right-hand side of the wrong length");
        match &mut self.inner {
            Inner::Banded(b) => b.solve_in_place(x),
            Inner::Sparse(s) => s.solve_in_place(x),
        }
    }
}

/// `A = L D Lᵀ` of a band matrix with unit lower-triangular `L`, row by row: row `i` holds
/// `L[i, i−b .. i]` at `l[i b ..]` (entries before column 0 are zero padding), and `1 / D[i]`.
/// The unit diagonal keeps one multiply-add per row on the dependency chain of the solves.
struct BandCholesky {
    n: usize,
    b: usize,
    l: Vec<f64>,
    inv_d: Vec<f64>,
}

impl BandCholesky {
    /// `None` if `a` is not positive definite.
    fn new(a: &CscMatrix, b: usize) -> Option<Self> {
        let n = a.n();
        // Cholesky factor with its diagonal first: row i holds C[i, i−b ..= i] at i (b + 1).
        let w = b + 1;
        let mut c = vec![0.0; n * w];
        for j in 0..n {
            let (rows, vals) = a.col(j);
            for (&i, &v) in rows.iter().zip(vals) {
                if i >= j {
                    c[i * w + (j + b - i)] = v;
                }
            }
        }
        let mut inv_diag = vec![0.0; n];
        for i in 0..n {
            let k0 = i.saturating_sub(b);
            let row_i = i * w;
            for j in k0..=i {
                let row_j = j * w;
                // s = A_ij − Σ_{k0 ≤ k < j} C_ik C_jk  (k ≥ j − b holds since j ≤ i)
                let ci = &c[row_i + (k0 + b - i)..row_i + (j + b - i)];
                let cj = &c[row_j + (k0 + b - j)..row_j + b];
                let s = c[row_i + (j + b - i)] - dot(ci, cj);
                if j < i {
                    c[row_i + (j + b - i)] = s * inv_diag[j];
                } else {
                    if !(s > 0.0 && s.is_finite()) {
                        return None;
                    }
                    let d = s.sqrt();
                    c[row_i + b] = d;
                    inv_diag[i] = 1.0 / d;
                }
            }
        }
        // L = C diag(C)⁻¹, D = diag(C)².
        let mut l = vec![0.0; n * b];
        for i in 0..n {
            for k in i.saturating_sub(b)..i {
                l[i * b + (k + b - i)] = c[i * w + (k + b - i)] * inv_diag[k];
            }
        }
        let inv_d = inv_diag.iter().map(|x| x * x).collect();
        Some(Self { n, b, l, inv_d })
    }

    fn solve_in_place(&self, x: &mut [f64]) {
        let (n, b) = (self.n, self.b);
        if b == 0 {
            x.iter_mut().zip(&self.inv_d).for_each(|(x, d)| *x *= d);
            return;
        }
        if b == 1 {
            // Tridiagonal: row i holds L[i, i−1] at l[i]. The running value stays in a register,
            // so each row costs one multiply-add on the dependency chain; D⁻¹ is applied on the
            // way back, off the chain.
            let (l, inv_d) = (&self.l[..n], &self.inv_d[..n]);
            let mut prev = x[0];
            for (xi, li) in x[1..].iter_mut().zip(&l[1..]) {
                prev = *xi - li * prev;
                *xi = prev;
            }
            let mut next = x[n - 1] * inv_d[n - 1];
            x[n - 1] = next;
            for ((xi, di), li) in x[..n - 1]
                .iter_mut()
                .rev()
                .zip(inv_d[..n - 1].iter().rev())
                .zip(l[1..].iter().rev())
            {
                next = *xi * di - li * next;
                *xi = next;
            }
            return;
        }
        // L y = x (forward, row-oriented dot products).
        for i in 1..n {
            let k0 = i.saturating_sub(b);
            let row = &self.l[i * b + (k0 + b - i)..(i + 1) * b];
            x[i] -= dot(row, &x[k0..i]);
        }
        x.iter_mut().zip(&self.inv_d).for_each(|(x, d)| *x *= d);
        // Lᵀ x = z (backward: once x_i is final, remove L_ij x_i from the rows j < i).
        for i in (1..n).rev() {
            let xi = x[i];
            let k0 = i.saturating_sub(b);
            let row = &self.l[i * b + (k0 + b - i)..(i + 1) * b];
            for (xj, &lij) in x[k0..i].iter_mut().zip(row) {
                *xj -= lij * xi;
            }
        }
    }
}

#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    // Four partial sums: vectorises and shortens the dependency chain for wide bands.
    let mut s = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            s[k] += x[k] * y[k];
        }
    }
    let mut t = (s[0] + s[1]) + (s[2] + s[3]);
    for (x, y) in ra.iter().zip(rb) {
        t += x * y;
    }
    t
}

/// faer's sparse `L Lᵀ` (supernodal, forced) and our streaming single-right-hand-side solve.
struct FaerCholesky {
    solve: SupernodalSolve,
    ordering: SparseOrdering,
}

/// The lower triangle of `a` as faer's symbolic CSC pattern and its values.
fn lower(a: &CscMatrix) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    a.lower_triangle()
}

impl FaerCholesky {
    fn symbolic_with(
        a: &CscMatrix,
        ordering: SparseOrdering,
        what: &str,
    ) -> Result<(SymbolicCholesky<usize>, SparseOrdering)> {
        let (cp, ri, _) = lower(a);
        let n = a.n();
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &cp, None, &ri);
        // No relaxed amalgamation: faer's default merges small supernodes at up to 80 %
        // explicit zeros, which the dense kernels of a factorisation like but a solve, bound
        // by reading the factor, pays for (measured: 6 % at 10^4, 12 % at 10^5 DOFs of the
        // frame; docs/performance.md). Only merges that add no zero are kept.
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
            supernodal_params: SymbolicSupernodalParams {
                relax: Some(&[(usize::MAX, 0.0)]),
            },
            ..Default::default()
        };
        let run = |ord: SymmetricOrdering<'_, usize>| {
            factorize_symbolic_cholesky(sym, Side::Lower, ord, params)
                .map_err(|e| Error::numerical(what, format!("symbolic sparse Cholesky failed: {e:?}")))
        };
        match ordering {
            SparseOrdering::Amd => Ok((run(SymmetricOrdering::Amd)?, SparseOrdering::Amd)),
            SparseOrdering::NestedDissection => {
                let (fwd, inv) = super::ordering::nested_dissection(a)?;
                let perm = PermRef::new_checked(&fwd, &inv, n);
                Ok((run(SymmetricOrdering::Custom(perm))?, SparseOrdering::NestedDissection))
            }
            SparseOrdering::Auto => {
                // The smaller factor is the faster solve (it is read once per sweep).
                let amd = run(SymmetricOrdering::Amd)?;
                let (fwd, inv) = super::ordering::nested_dissection(a)?;
                let nd = run(SymmetricOrdering::Custom(PermRef::new_checked(&fwd, &inv, n)))?;
                if nd.len_val() < amd.len_val() {
                    Ok((nd, SparseOrdering::NestedDissection))
                } else {
                    Ok((amd, SparseOrdering::Amd))
                }
            }
        }
    }

    fn new(a: &CscMatrix, ordering: SparseOrdering, what: &str) -> Result<Self> {
        let n = a.n();
        let (symbolic, ordering) = Self::symbolic_with(a, ordering, what)?;
        let (cp, ri, vals) = lower(a);
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &cp, None, &ri);
        let mut l_values = vec![0.0; symbolic.len_val()];
        {
            let mut fbuf = MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()));
            symbolic
                .factorize_numeric_llt::<f64>(
                    &mut l_values,
                    SparseColMatRef::new(sym, &vals),
                    Side::Lower,
                    Default::default(),
                    Par::Seq,
                    MemStack::new(&mut fbuf),
                    Default::default(),
                )
                .map_err(|_| Error::numerical(what, "is not positive definite (check K, M, C and dt)"))?;
        }
        let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.raw() else {
            return Err(Error::numerical(
                what,
                "faer chose a simplicial factor although supernodal was forced",
            ));
        };
        let fwd = symbolic.perm().map(|p| p.arrays().0);
        let solve = SupernodalSolve::new(sn, fwd, l_values)?;
        Ok(Self { solve, ordering })
    }

    fn solve_in_place(&mut self, x: &mut [f64]) {
        self.solve.solve_in_place(x);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// A 2-D Laplacian-like SPD matrix on a `p × q` grid plus a diagonal shift.
    fn grid(p: usize, q: usize) -> CscMatrix {
        let idx = |i: usize, j: usize| i * q + j;
        let mut t = Vec::new();
        for i in 0..p {
            for j in 0..q {
                t.push((idx(i, j), idx(i, j), 4.5));
                if i + 1 < p {
                    t.push((idx(i, j), idx(i + 1, j), -1.0));
                    t.push((idx(i + 1, j), idx(i, j), -1.0));
                }
                if j + 1 < q {
                    t.push((idx(i, j), idx(i, j + 1), -1.0));
                    t.push((idx(i, j + 1), idx(i, j), -1.0));
                }
            }
        }
        CscMatrix::from_triplets(p * q, &t)
    }

    #[test]
    fn banded_and_sparse_solve_like_dense() {
        let a = grid(7, 5);
        let dense = a.to_dense();
        let rhs: Vec<f64> = (0..a.n()).map(|i| (i as f64 * 0.37).sin()).collect();
        let want = dense.clone().cholesky().unwrap().solve(&DVector::from_row_slice(&rhs));
        for kind in [FactorKind::Banded, FactorKind::Sparse, FactorKind::Auto] {
            let mut f = SymmetricFactor::new(&a, kind, "A").unwrap();
            let mut x = rhs.clone();
            f.solve_in_place(&mut x);
            let err = (DVector::from_row_slice(&x) - &want).amax() / want.amax();
            assert!(err < 1e-13, "{kind:?}: {err}");
        }
    }

    #[test]
    fn auto_takes_the_band_for_a_chain() {
        let n = 50;
        let mut t = Vec::new();
        for i in 0..n {
            t.push((i, i, 2.5));
            if i + 1 < n {
                t.push((i, i + 1, -1.0));
                t.push((i + 1, i, -1.0));
            }
        }
        let f = SymmetricFactor::new(&CscMatrix::from_triplets(n, &t), FactorKind::Auto, "A").unwrap();
        assert!(f.describe().starts_with("banded"), "{}", f.describe());
        assert_eq!(f.factor_len(), 2 * n);
    }

    #[test]
    fn indefinite_matrices_are_refused_by_both() {
        let a = CscMatrix::from_dense(&DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]));
        for kind in [FactorKind::Banded, FactorKind::Sparse] {
            let e = SymmetricFactor::new(&a, kind, "K_hat").unwrap_err().to_string();
            assert!(e.starts_with("K_hat: is not positive definite"), "{e}");
        }
    }
}
