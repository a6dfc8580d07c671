//! Single-right-hand-side solves `L Lᵀ x = b` with a supernodal Cholesky factor, written for
//! the one thing a time step needs: stream the factor through the core as fast as memory
//! delivers it (theory §11.4).
//!
//! The factor is faer's (same values, same supernodes); only the solve is ours. faer's general
//! solve handles many right-hand sides through its matrix kernels, which for one column costs a
//! dispatch per supernode and reads every `usize` row index; here each supernode is one
//! contiguous column-major block `[L_diag; L_off]` read front to back, row indices are `u32`,
//! four columns are combined per pass over the off-diagonal block (forward: one update of the
//! gathered right-hand side per four columns; backward: four dot products per pass over it),
//! and on x86-64 the kernels run with AVX2 + FMA when the CPU has them.

use crate::error::{Error, Result};

/// One supernode: columns `start .. start + ncols` of `L`, with `rows` off-diagonal rows
/// `pattern[pat .. pat + rows]` and values `values[val ..]` (column-major, leading dimension
/// `ncols + rows`).
#[derive(Debug, Clone, Copy)]
struct Node {
    start: usize,
    ncols: usize,
    rows: usize,
    pat: usize,
    val: usize,
}

/// A supernodal `L` (values in faer's layout) with its fill-reducing permutation.
pub(crate) struct SupernodalSolve {
    n: usize,
    /// `fwd[i]`: the original index of permuted row `i`.
    fwd: Vec<u32>,
    nodes: Vec<Node>,
    pattern: Vec<u32>,
    values: Vec<f64>,
    /// Permuted right-hand side (`n`) and the gathered rows of one supernode.
    work: Vec<f64>,
    tmp: Vec<f64>,
    use_fma: bool,
}

impl SupernodalSolve {
    /// Take faer's supernodal structure and the values of its numeric `L Lᵀ`.
    pub(crate) fn new(
        symbolic: &faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky<usize>,
        perm_fwd: Option<&[usize]>,
        values: Vec<f64>,
    ) -> Result<Self> {
        let n = symbolic.nrows();
        if n > u32::MAX as usize {
            return Err(Error::invalid(
                "structure",
                format!("{n} DOFs are too many for the sparse solver"),
            ));
        }
        let ns = symbolic.n_supernodes();
        let (begin, end) = (symbolic.supernode_begin(), symbolic.supernode_end());
        let col_val = symbolic.col_ptr_for_val();
        let mut nodes = Vec::with_capacity(ns);
        let mut pattern = Vec::new();
        let mut max_rows = 0;
        for s in 0..ns {
            let p = symbolic.supernode(s).pattern();
            let node = Node {
                start: begin[s],
                ncols: end[s] - begin[s],
                rows: p.len(),
                pat: pattern.len(),
                val: col_val[s],
            };
            debug_assert_eq!(col_val[s + 1] - col_val[s], (node.ncols + node.rows) * node.ncols);
            pattern.extend(p.iter().map(|&i| i as u32));
            max_rows = max_rows.max(p.len());
            nodes.push(node);
        }
        let fwd = match perm_fwd {
            Some(p) => p.iter().map(|&i| i as u32).collect(),
            None => (0..n as u32).collect(),
        };
        Ok(Self {
            n,
            fwd,
            nodes,
            pattern,
            values,
            work: vec![0.0; n],
            tmp: vec![0.0; max_rows],
            use_fma: has_fma(),
        })
    }

    /// Stored values of `L` (including the unused upper parts of the diagonal blocks).
    pub(crate) fn len_val(&self) -> usize {
        self.values.len()
    }

    pub(crate) fn n_supernodes(&self) -> usize {
        self.nodes.len()
    }

    /// Bytes read by one solve: the values twice, the row indices twice.
    pub(crate) fn bytes_per_solve(&self) -> usize {
        let vals: usize = self
            .nodes
            .iter()
            .map(|s| s.ncols * (s.ncols + 1) / 2 + s.ncols * s.rows)
            .sum();
        2 * (8 * vals + 4 * self.pattern.len())
    }

    /// Overwrite `x` with `A⁻¹ x`.
    pub(crate) fn solve_in_place(&mut self, x: &mut [f64]) {
        assert_eq!(x.len(), self.n);
        for (w, &f) in self.work.iter_mut().zip(&self.fwd) {
            *w = x[f as usize];
        }
        #[cfg(target_arch = "x86_64")]
        if self.use_fma {
            // SAFETY: `use_fma` is true only when the CPU reports AVX2 and FMA.
            unsafe { self.sweeps_fma() };
        } else {
            self.sweeps_plain();
        }
        #[cfg(not(target_arch = "x86_64"))]
        self.sweeps_plain();
        for (w, &f) in self.work.iter().zip(&self.fwd) {
            x[f as usize] = *w;
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn sweeps_fma(&mut self) {
        sweeps::<true>(&self.nodes, &self.pattern, &self.values, &mut self.work, &mut self.tmp);
    }

    fn sweeps_plain(&mut self) {
        sweeps::<false>(&self.nodes, &self.pattern, &self.values, &mut self.work, &mut self.tmp);
    }
}

fn has_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `a · b + c`, fused when `FMA`.
#[inline(always)]
fn madd<const FMA: bool>(a: f64, b: f64, c: f64) -> f64 {
    if FMA { a.mul_add(b, c) } else { a * b + c }
}

/// Forward then backward substitution over all supernodes.
#[inline(always)]
fn sweeps<const FMA: bool>(nodes: &[Node], pattern: &[u32], values: &[f64], w: &mut [f64], tmp: &mut [f64]) {
    for s in nodes {
        forward_node::<FMA>(s, &pattern[s.pat..s.pat + s.rows], values, w, &mut tmp[..s.rows]);
    }
    for s in nodes.iter().rev() {
        backward_node::<FMA>(s, &pattern[s.pat..s.pat + s.rows], values, w, &mut tmp[..s.rows]);
    }
}

/// `y = L_diag⁻¹ w_s`, then `w_pattern −= L_off y`.
#[inline(always)]
fn forward_node<const FMA: bool>(s: &Node, pat: &[u32], values: &[f64], w: &mut [f64], tmp: &mut [f64]) {
    let (nc, ld) = (s.ncols, s.ncols + s.rows);
    let block = &values[s.val..s.val + ld * nc];
    let top = &mut w[s.start..s.start + nc];
    for j in 0..nc {
        let col = &block[j * ld..j * ld + nc];
        let yj = top[j] / col[j];
        top[j] = yj;
        for (t, &l) in top[j + 1..].iter_mut().zip(&col[j + 1..]) {
            *t = madd::<FMA>(-l, yj, *t);
        }
    }
    if s.rows == 0 {
        return;
    }
    // tmp = L_off y, four columns per pass.
    let off = |j: usize| &block[j * ld + nc..(j + 1) * ld];
    let mut j = 0;
    tmp.fill(0.0);
    while j + 4 <= nc {
        let (y0, y1, y2, y3) = (top[j], top[j + 1], top[j + 2], top[j + 3]);
        let r = tmp.len();
        let (c0, c1, c2, c3) = (&off(j)[..r], &off(j + 1)[..r], &off(j + 2)[..r], &off(j + 3)[..r]);
        for k in 0..r {
            let mut t = tmp[k];
            t = madd::<FMA>(c0[k], y0, t);
            t = madd::<FMA>(c1[k], y1, t);
            t = madd::<FMA>(c2[k], y2, t);
            t = madd::<FMA>(c3[k], y3, t);
            tmp[k] = t;
        }
        j += 4;
    }
    while j < nc {
        let (y, c) = (top[j], off(j));
        for (t, &l) in tmp.iter_mut().zip(c) {
            *t = madd::<FMA>(l, y, *t);
        }
        j += 1;
    }
    for (&p, &t) in pat.iter().zip(tmp.iter()) {
        w[p as usize] -= t;
    }
}

/// `w_s −= L_offᵀ w_pattern`, then `w_s = L_diag⁻ᵀ w_s`.
#[inline(always)]
fn backward_node<const FMA: bool>(s: &Node, pat: &[u32], values: &[f64], w: &mut [f64], tmp: &mut [f64]) {
    let (nc, ld) = (s.ncols, s.ncols + s.rows);
    let block = &values[s.val..s.val + ld * nc];
    if s.rows > 0 {
        for (t, &p) in tmp.iter_mut().zip(pat) {
            *t = w[p as usize];
        }
        let off = |j: usize| &block[j * ld + nc..(j + 1) * ld];
        let mut j = 0;
        while j + 4 <= nc {
            let r = tmp.len();
            let (c0, c1, c2, c3) = (&off(j)[..r], &off(j + 1)[..r], &off(j + 2)[..r], &off(j + 3)[..r]);
            // Four lanes per column: independent chains that vectorise.
            let (mut d0, mut d1, mut d2, mut d3) = ([0.0; 4], [0.0; 4], [0.0; 4], [0.0; 4]);
            let full = r - r % 4;
            for k in (0..full).step_by(4) {
                for l in 0..4 {
                    let t = tmp[k + l];
                    d0[l] = madd::<FMA>(c0[k + l], t, d0[l]);
                    d1[l] = madd::<FMA>(c1[k + l], t, d1[l]);
                    d2[l] = madd::<FMA>(c2[k + l], t, d2[l]);
                    d3[l] = madd::<FMA>(c3[k + l], t, d3[l]);
                }
            }
            for k in full..r {
                let t = tmp[k];
                d0[0] = madd::<FMA>(c0[k], t, d0[0]);
                d1[0] = madd::<FMA>(c1[k], t, d1[0]);
                d2[0] = madd::<FMA>(c2[k], t, d2[0]);
                d3[0] = madd::<FMA>(c3[k], t, d3[0]);
            }
            let sum = |d: [f64; 4]| (d[0] + d[1]) + (d[2] + d[3]);
            let (d0, d1, d2, d3) = (sum(d0), sum(d1), sum(d2), sum(d3));
            let top = &mut w[s.start + j..s.start + j + 4];
            top[0] -= d0;
            top[1] -= d1;
            top[2] -= d2;
            top[3] -= d3;
            j += 4;
        }
        while j < nc {
            w[s.start + j] -= dot::<FMA>(off(j), tmp);
            j += 1;
        }
    }
    let top = &mut w[s.start..s.start + nc];
    for j in (0..nc).rev() {
        let col = &block[j * ld..j * ld + nc];
        let d = dot::<FMA>(&col[j + 1..], &top[j + 1..]);
        top[j] = (top[j] - d) / col[j];
    }
}

/// Dot product with eight partial sums (vectorises; the order is fixed, so reruns are
/// bit-identical).
#[inline(always)]
fn dot<const FMA: bool>(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut s = [0.0; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..8 {
            s[k] = madd::<FMA>(x[k], y[k], s[k]);
        }
    }
    let mut t = ((s[0] + s[4]) + (s[1] + s[5])) + ((s[2] + s[6]) + (s[3] + s[7]));
    for (x, y) in ra.iter().zip(rb) {
        t = madd::<FMA>(*x, *y, t);
    }
    t
}
