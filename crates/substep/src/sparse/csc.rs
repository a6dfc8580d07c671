//! Square sparse matrices in compressed sparse column (CSC) form.

use crate::error::{Error, Result};
use nalgebra::DMatrix;

/// A square sparse matrix in compressed sparse column form: column `j` holds the row indices
/// `row_idx[col_ptr[j]..col_ptr[j + 1]]` (strictly increasing) and their values. Both triangles
/// of a symmetric matrix are stored, so a column is also a row and products can gather.
#[derive(Debug, Clone, PartialEq)]
pub struct CscMatrix {
    n: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    values: Vec<f64>,
}

impl CscMatrix {
    /// The `n × n` zero matrix (no stored entries).
    pub fn zeros(n: usize) -> Self {
        Self {
            n,
            col_ptr: vec![0; n + 1],
            row_idx: Vec::new(),
            values: Vec::new(),
        }
    }

    /// A diagonal matrix.
    pub fn from_diagonal(d: &[f64]) -> Self {
        let n = d.len();
        Self {
            n,
            col_ptr: (0..=n).collect(),
            row_idx: (0..n).collect(),
            values: d.to_vec(),
        }
    }

    /// Assemble from `(row, column, value)` triplets; entries at the same position are summed
    /// (finite-element assembly). Indices must be `< n` (panics otherwise: a programming error).
    pub fn from_triplets(n: usize, triplets: &[(usize, usize, f64)]) -> Self {
        let mut counts = vec![0usize; n + 1];
        for &(i, j, _) in triplets {
            assert!(i < n && j < n, "triplet ({i}, {j}) outside a {n}x{n} matrix");
            counts[j + 1] += 1;
        }
        for j in 0..n {
            counts[j + 1] += counts[j];
        }
        // Bucket by column, then sort each column by row and merge duplicates.
        let mut next = counts.clone();
        let mut rows = vec![0usize; triplets.len()];
        let mut vals = vec![0.0; triplets.len()];
        for &(i, j, v) in triplets {
            rows[next[j]] = i;
            vals[next[j]] = v;
            next[j] += 1;
        }
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::with_capacity(triplets.len());
        let mut values = Vec::with_capacity(triplets.len());
        col_ptr.push(0);
        let mut order: Vec<usize> = Vec::new();
        for j in 0..n {
            let (lo, hi) = (counts[j], counts[j + 1]);
            order.clear();
            order.extend(lo..hi);
            order.sort_unstable_by_key(|&k| rows[k]);
            for &k in &order {
                if row_idx.len() > col_ptr[j] && *row_idx.last().expect("non-empty") == rows[k] {
                    *values.last_mut().expect("non-empty") += vals[k];
                } else {
                    row_idx.push(rows[k]);
                    values.push(vals[k]);
                }
            }
            col_ptr.push(row_idx.len());
        }
        Self {
            n,
            col_ptr,
            row_idx,
            values,
        }
    }

    /// The non-zero entries of a dense square matrix.
    pub fn from_dense(m: &DMatrix<f64>) -> Self {
        assert_eq!(m.nrows(), m.ncols(), "CscMatrix::from_dense needs a square matrix");
        let n = m.nrows();
        let mut col_ptr = Vec::with_capacity(n + 1);
        let (mut row_idx, mut values) = (Vec::new(), Vec::new());
        col_ptr.push(0);
        for j in 0..n {
            for i in 0..n {
                let v = m[(i, j)];
                if v != 0.0 {
                    row_idx.push(i);
                    values.push(v);
                }
            }
            col_ptr.push(row_idx.len());
        }
        Self {
            n,
            col_ptr,
            row_idx,
            values,
        }
    }

    /// The dense `n × n` matrix (for small models, tests and the dense-only analyses).
    pub fn to_dense(&self) -> DMatrix<f64> {
        let mut m = DMatrix::zeros(self.n, self.n);
        for j in 0..self.n {
            let (rows, vals) = self.col(j);
            for (&i, &v) in rows.iter().zip(vals) {
                m[(i, j)] = v;
            }
        }
        m
    }

    pub fn n(&self) -> usize {
        self.n
    }
    /// Stored entries.
    pub fn nnz(&self) -> usize {
        self.values.len()
    }
    /// Stored entries over `n²`.
    pub fn density(&self) -> f64 {
        if self.n == 0 {
            0.0
        } else {
            self.nnz() as f64 / (self.n as f64 * self.n as f64)
        }
    }
    pub fn col_ptr(&self) -> &[usize] {
        &self.col_ptr
    }
    pub fn row_idx(&self) -> &[usize] {
        &self.row_idx
    }
    pub fn values(&self) -> &[f64] {
        &self.values
    }
    /// Row indices and values of column `j`.
    pub fn col(&self, j: usize) -> (&[usize], &[f64]) {
        let (lo, hi) = (self.col_ptr[j], self.col_ptr[j + 1]);
        (&self.row_idx[lo..hi], &self.values[lo..hi])
    }
    /// Entry `(i, j)` (0 if not stored).
    pub fn get(&self, i: usize, j: usize) -> f64 {
        let (rows, vals) = self.col(j);
        rows.binary_search(&i).map_or(0.0, |k| vals[k])
    }
    /// The diagonal.
    pub fn diagonal(&self) -> Vec<f64> {
        (0..self.n).map(|j| self.get(j, j)).collect()
    }
    /// Whether every stored entry lies on the diagonal.
    pub fn is_diagonal(&self) -> bool {
        (0..self.n).all(|j| self.col(j).0.iter().all(|&i| i == j))
    }
    /// Largest `|i − j|` over the stored entries (0 for a diagonal or empty matrix).
    pub fn half_bandwidth(&self) -> usize {
        (0..self.n)
            .map(|j| {
                let (rows, _) = self.col(j);
                match (rows.first(), rows.last()) {
                    (Some(&lo), Some(&hi)) => (j.saturating_sub(lo)).max(hi.saturating_sub(j)),
                    _ => 0,
                }
            })
            .max()
            .unwrap_or(0)
    }
    /// Largest absolute value (0 for an empty matrix).
    pub fn amax(&self) -> f64 {
        self.values.iter().fold(0.0, |m, v| m.max(v.abs()))
    }

    /// `y = alpha · A x + beta · y` for a **symmetric** `A`: column `i` of `A` is its row `i`, so
    /// each `y_i` is a gathered dot product (no scattered writes). Allocation-free.
    pub fn sym_mul_add(&self, alpha: f64, x: &[f64], beta: f64, y: &mut [f64]) {
        assert_eq!(x.len(), self.n, "sym_mul_add: x has the wrong length");
        assert_eq!(y.len(), self.n, "sym_mul_add: y has the wrong length");
        for (yi, w) in y.iter_mut().zip(self.col_ptr.windows(2)) {
            // Four partial sums: one chain of dependent additions per row would make the
            // product wait on the adder's latency instead of on memory (fixed order, so
            // reruns stay bit-identical).
            let (rows, vals) = (&self.row_idx[w[0]..w[1]], &self.values[w[0]..w[1]]);
            if rows.len() < 8 {
                // Short columns (a chain's three entries): the plain loop, as before the
                // partial sums (they cost a chain 5-7 % for nothing).
                let mut acc = 0.0;
                for (&r, &v) in rows.iter().zip(vals) {
                    acc += v * x[r];
                }
                *yi = if beta == 0.0 {
                    alpha * acc
                } else {
                    alpha * acc + beta * *yi
                };
                continue;
            }
            let (rc, vc) = (rows.chunks_exact(4), vals.chunks_exact(4));
            let (rr, vr) = (rc.remainder(), vc.remainder());
            let mut s = [0.0; 4];
            for (r4, v4) in rc.zip(vc) {
                for k in 0..4 {
                    s[k] += v4[k] * x[r4[k]];
                }
            }
            let mut acc = (s[0] + s[1]) + (s[2] + s[3]);
            for (&r, &v) in rr.iter().zip(vr) {
                acc += v * x[r];
            }
            *yi = if beta == 0.0 {
                alpha * acc
            } else {
                alpha * acc + beta * *yi
            };
        }
    }

    /// `Σ c_k A_k` over matrices of one size, on the union of their patterns.
    pub fn linear_combination(terms: &[(f64, &CscMatrix)]) -> Self {
        let n = terms.first().map_or(0, |t| t.1.n);
        assert!(
            terms.iter().all(|t| t.1.n == n),
            "linear_combination of matrices of different sizes"
        );
        let mut col_ptr = Vec::with_capacity(n + 1);
        let (mut row_idx, mut values) = (Vec::new(), Vec::new());
        col_ptr.push(0);
        // Dense accumulator column plus a marker of which rows are set.
        let mut acc = vec![0.0; n];
        let mut mark = vec![usize::MAX; n];
        let mut rows: Vec<usize> = Vec::new();
        for j in 0..n {
            rows.clear();
            for &(c, a) in terms {
                let (ri, vi) = a.col(j);
                for (&i, &v) in ri.iter().zip(vi) {
                    if mark[i] != j {
                        mark[i] = j;
                        acc[i] = 0.0;
                        rows.push(i);
                    }
                    acc[i] += c * v;
                }
            }
            rows.sort_unstable();
            for &i in &rows {
                row_idx.push(i);
                values.push(acc[i]);
            }
            col_ptr.push(row_idx.len());
        }
        Self {
            n,
            col_ptr,
            row_idx,
            values,
        }
    }

    /// The matrix scaled by `c`.
    pub fn scaled(&self, c: f64) -> Self {
        let mut m = self.clone();
        m.values.iter_mut().for_each(|v| *v *= c);
        m
    }

    /// The lower triangle (`i ≥ j`) as `(col_ptr, row_idx, values)`.
    pub fn lower_triangle(&self) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
        let mut col_ptr = Vec::with_capacity(self.n + 1);
        let (mut row_idx, mut values) = (Vec::new(), Vec::new());
        col_ptr.push(0);
        for j in 0..self.n {
            let (rows, vals) = self.col(j);
            for (&i, &v) in rows.iter().zip(vals) {
                if i >= j {
                    row_idx.push(i);
                    values.push(v);
                }
            }
            col_ptr.push(row_idx.len());
        }
        (col_ptr, row_idx, values)
    }

    /// `A` grown to `m ≥ n` rows and columns (the new ones are zero).
    pub fn grown(&self, m: usize) -> Self {
        assert!(m >= self.n);
        let mut col_ptr = self.col_ptr.clone();
        col_ptr.resize(m + 1, self.nnz());
        Self {
            n: m,
            col_ptr,
            row_idx: self.row_idx.clone(),
            values: self.values.clone(),
        }
    }

    /// The principal submatrix `A[keep, keep]`; `keep` is strictly increasing (the rows and
    /// columns of the result follow its order).
    pub fn principal(&self, keep: &[usize]) -> Self {
        let mut new_index = vec![usize::MAX; self.n];
        for (k, &i) in keep.iter().enumerate() {
            new_index[i] = k;
        }
        let mut col_ptr = Vec::with_capacity(keep.len() + 1);
        let mut row_idx = Vec::new();
        let mut values = Vec::new();
        col_ptr.push(0);
        for &j in keep {
            let (rows, vals) = self.col(j);
            for (&r, &v) in rows.iter().zip(vals) {
                if new_index[r] != usize::MAX {
                    row_idx.push(new_index[r]);
                    values.push(v);
                }
            }
            col_ptr.push(row_idx.len());
        }
        Self {
            n: keep.len(),
            col_ptr,
            row_idx,
            values,
        }
    }

    /// Error unless every entry is finite and `A` is symmetric to `1e-9 · max|A|`; `name` is the
    /// config key used in messages (1-based entry numbers, as for dense matrices).
    pub fn check_symmetric(&self, name: &str) -> Result<()> {
        for j in 0..self.n {
            let (rows, vals) = self.col(j);
            if let Some(k) = vals.iter().position(|v| !v.is_finite()) {
                return Err(Error::invalid(
                    name,
                    format!("entry ({}, {}) is not finite", rows[k] + 1, j + 1),
                ));
            }
        }
        let tol = 1e-9 * self.amax().max(f64::MIN_POSITIVE);
        for j in 0..self.n {
            let (rows, vals) = self.col(j);
            for (&i, &v) in rows.iter().zip(vals) {
                if i > j {
                    let w = self.get(j, i);
                    if (v - w).abs() > tol {
                        return Err(Error::invalid(
                            name,
                            format!(
                                "is not symmetric: entry ({}, {}) = {} but ({}, {}) = {}",
                                i + 1,
                                j + 1,
                                v,
                                j + 1,
                                i + 1,
                                w
                            ),
                        ));
                    }
                }
            }
            // Entries stored only in the upper triangle are caught from the other side.
            for &i in rows.iter().filter(|&&i| i < j) {
                if self.col(i).0.binary_search(&j).is_err() {
                    let v = self.get(i, j);
                    if v.abs() > tol {
                        return Err(Error::invalid(
                            name,
                            format!(
                                "is not symmetric: entry ({}, {}) = {} but ({}, {}) = 0",
                                i + 1,
                                j + 1,
                                v,
                                j + 1,
                                i + 1
                            ),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// Bytes held by the three arrays.
    pub fn heap_bytes(&self) -> usize {
        (self.col_ptr.len() + self.row_idx.len()) * std::mem::size_of::<usize>() + self.values.len() * 8
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dmatrix;

    #[test]
    fn triplets_sum_duplicates_and_round_trip() {
        let a = CscMatrix::from_triplets(3, &[(0, 0, 1.0), (2, 0, 2.0), (0, 0, 3.0), (1, 1, 5.0), (0, 2, 2.0)]);
        assert_eq!(a.nnz(), 4);
        assert_eq!(a.to_dense(), dmatrix![4.0, 0.0, 2.0; 0.0, 5.0, 0.0; 2.0, 0.0, 0.0]);
        assert_eq!(CscMatrix::from_dense(&a.to_dense()), a);
        assert_eq!(a.half_bandwidth(), 2);
        a.check_symmetric("A").unwrap();
    }

    #[test]
    fn products_and_combinations_match_dense() {
        let d = dmatrix![4.0, -1.0, 0.0; -1.0, 4.0, -2.0; 0.0, -2.0, 5.0];
        let e = dmatrix![1.0, 0.0, 0.0; 0.0, 2.0, 0.0; 0.0, 0.0, 3.0];
        let (a, b) = (CscMatrix::from_dense(&d), CscMatrix::from_dense(&e));
        let x = [1.0, -2.0, 0.5];
        let mut y = [1.0, 1.0, 1.0];
        a.sym_mul_add(2.0, &x, 3.0, &mut y);
        let want = &d * nalgebra::DVector::from_row_slice(&x) * 2.0 + nalgebra::DVector::from_element(3, 3.0);
        assert_eq!(y.to_vec(), want.as_slice().to_vec());
        let c = CscMatrix::linear_combination(&[(1.0, &a), (0.5, &b)]);
        assert_eq!(c.to_dense(), &d + &e * 0.5);
        let (cp, ri, _) = a.lower_triangle();
        assert_eq!(cp, vec![0, 2, 4, 5]);
        assert_eq!(ri, vec![0, 1, 1, 2, 2]);
    }

    #[test]
    fn asymmetry_is_reported_with_one_based_entries() {
        let a = CscMatrix::from_triplets(2, &[(0, 0, 1.0), (1, 0, 2.0), (0, 1, 2.5), (1, 1, 1.0)]);
        let e = a.check_symmetric("structure.stiffness").unwrap_err().to_string();
        assert_eq!(
            e,
            "structure.stiffness: is not symmetric: entry (2, 1) = 2 but (1, 2) = 2.5"
        );
        let b = CscMatrix::from_triplets(2, &[(0, 0, 1.0), (0, 1, 2.0), (1, 1, 1.0)]);
        let e = b.check_symmetric("K").unwrap_err().to_string();
        assert_eq!(e, "K: is not symmetric: entry (1, 2) = 2 but (2, 1) = 0");
    }
}
