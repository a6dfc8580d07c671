//! The amplification matrix of one complete step, probed from the implementation.

use crate::error::{Error, Result};
use crate::substructure::{CouplingController, SubstructureTest};
use nalgebra::{Complex, DMatrix, DVector};

/// Stability class of a step map; `tolerance` is the band around `ρ = 1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stability {
    Stable,
    /// `|ρ − 1| ≤ tolerance` (limited stability: constant amplitude).
    Limited,
    Unstable,
}

impl Stability {
    pub fn classify(rho: f64, tolerance: f64) -> Self {
        if !rho.is_finite() || rho > 1.0 + tolerance {
            Stability::Unstable
        } else if rho >= 1.0 - tolerance {
            Stability::Limited
        } else {
            Stability::Stable
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Stability::Stable => "stable",
            Stability::Limited => "limited",
            Stability::Unstable => "unstable",
        }
    }
}

/// `X_{i+1} = A X_i + B0 a_g,i + B1 a_g,i+1` of the full algorithm state `X` (controller state
/// followed by the experimental side's state, see [`SubstructureTest::write_state`]).
#[derive(Debug, Clone)]
pub struct StepMap {
    pub a: DMatrix<f64>,
    pub b0: DVector<f64>,
    pub b1: DVector<f64>,
}

impl StepMap {
    /// Probe the map by applying one step to each unit state (zero load) and to unit ground
    /// accelerations from the zero state. The test's state is restored afterwards. Fails with
    /// a message naming the part if the experimental side is not linear.
    pub fn probe<C: CouplingController>(test: &mut SubstructureTest<C>) -> Result<Self> {
        let n = test.state_len();
        let mut a = DMatrix::zeros(n, n);
        let mut x = vec![0.0; n];
        let mut saved = vec![0.0; n];
        probe_transition(test, &mut a, &mut x, &mut saved)?;
        let mut b0 = DVector::zeros(n);
        let mut b1 = DVector::zeros(n);
        // `x` is zero again after `probe_transition`.
        let probed = probe_column(test, &x, (1.0, 0.0), b0.as_mut_slice())
            .and_then(|()| probe_column(test, &x, (0.0, 1.0), b1.as_mut_slice()));
        test.read_state(&saved);
        probed?;
        Ok(Self { a, b0, b1 })
    }

    /// Only the transition matrix `A` of [`Self::probe`] (the `n` unit-state probes, not the two
    /// load probes): what the spectral radius needs, with the same arithmetic per column, so
    /// `A` is bit for bit the one of [`Self::probe`].
    pub fn probe_transition<C: CouplingController>(test: &mut SubstructureTest<C>) -> Result<DMatrix<f64>> {
        let n = test.state_len();
        let mut a = DMatrix::zeros(n, n);
        let (mut x, mut saved) = (vec![0.0; n], vec![0.0; n]);
        probe_transition(test, &mut a, &mut x, &mut saved)?;
        Ok(a)
    }

    /// The part of `A` that carries dynamics: states that never influence anything (zero
    /// column) or are never set (zero row) only add eigenvalues 0 and are removed, repeatedly.
    /// Returns the reduced matrix and the kept indices.
    pub fn reduced(&self) -> (DMatrix<f64>, Vec<usize>) {
        let keep = prune(&self.a, |i, row_zero, col_zero| {
            let _ = i;
            row_zero || col_zero
        });
        let m = DMatrix::from_fn(keep.len(), keep.len(), |r, c| self.a[(keep[r], keep[c])]);
        (m, keep)
    }

    /// Eigenvalues of `A` (zero eigenvalues of removed states omitted).
    pub fn eigenvalues(&self) -> Result<Vec<Complex<f64>>> {
        let (m, _) = self.reduced();
        crate::linalg::eigenvalues(&m)
            .ok_or_else(|| Error::numerical("amplification matrix", "eigenvalue iteration did not converge"))
    }

    /// Spectral radius `ρ = max |λ|` (NaN if the eigenvalues could not be computed).
    pub fn spectral_radius(&self) -> f64 {
        spectral_radius_of(&self.a)
    }

    /// Discrete frequency response of state `output` to a harmonic ground acceleration
    /// `a_g(t_i) = e^{iωt_i}`: `e_outᵀ (zI − A)⁻¹ (B0 + z B1)`, `z = e^{iωΔt}`.
    pub fn frequency_response(&self, output: usize, omega_dt: f64) -> Complex<f64> {
        let n = self.a.nrows();
        let z = Complex::new(omega_dt.cos(), omega_dt.sin());
        let mut m = self.a.map(|v| Complex::new(-v, 0.0));
        for i in 0..n {
            m[(i, i)] += z;
        }
        let rhs = DVector::from_fn(n, |i, _| Complex::new(self.b0[i], 0.0) + z * self.b1[i]);
        match m.lu().solve(&rhs) {
            Some(x) => x[output],
            None => Complex::new(f64::NAN, f64::NAN),
        }
    }
}

/// Column `k` of `A` for `k = 0..n` into `a` (`n × n`, `n = test.state_len()`): one step from the
/// unit state `e_k` at zero load. `x` and `saved` are `n`-long workspaces; `x` is left zero and
/// the test's state is restored, also on failure.
fn probe_transition<C: CouplingController>(
    test: &mut SubstructureTest<C>,
    a: &mut DMatrix<f64>,
    x: &mut [f64],
    saved: &mut [f64],
) -> Result<()> {
    test.controller.is_linear()?;
    test.site.is_linear()?;
    let n = test.state_len();
    test.write_state(saved);
    x.iter_mut().for_each(|v| *v = 0.0);
    let mut result = Ok(());
    for k in 0..n {
        x[k] = 1.0;
        // A column of a column-major matrix is contiguous: the step writes its state into it.
        let col = &mut a.as_mut_slice()[k * n..(k + 1) * n];
        result = probe_column(test, x, (0.0, 0.0), col);
        x[k] = 0.0;
        if result.is_err() {
            break;
        }
    }
    test.read_state(saved);
    result
}

/// One probing step: state `x`, ground accelerations `ag = (a_g,i, a_g,i+1)`; the new state
/// into `out`.
fn probe_column<C: CouplingController>(
    test: &mut SubstructureTest<C>,
    x: &[f64],
    ag: (f64, f64),
    out: &mut [f64],
) -> Result<()> {
    test.read_state(x);
    test.step(ag.0, ag.1, &mut ())
        .map_err(|e| Error::numerical("amplification matrix", format!("probing step failed: {e}")))?;
    test.write_state(out);
    Ok(())
}

/// `ρ(A) = max |λ|` of a probed transition matrix: the states [`StepMap::reduced`] drops only add
/// eigenvalues 0, so the eigenvalues are those of the kept block (NaN if they could not be
/// computed). Without a dropped state the kept block is `A` itself and is not copied.
pub fn spectral_radius_of(a: &DMatrix<f64>) -> f64 {
    let keep = prune(a, |_, row_zero, col_zero| row_zero || col_zero);
    if keep.len() == a.nrows() {
        return crate::linalg::spectral_radius(a);
    }
    let m = DMatrix::from_fn(keep.len(), keep.len(), |r, c| a[(keep[r], keep[c])]);
    crate::linalg::spectral_radius_owned(m)
}

/// The states of `a` kept after repeatedly dropping those for which `drop(i, zero row, zero
/// column)` holds (rows and columns restricted to the kept states). Each pass is `O(n²)`: the
/// nonzero counts are kept per row and column and updated as states go.
fn prune(a: &DMatrix<f64>, drop: impl Fn(usize, bool, bool) -> bool) -> Vec<usize> {
    let n = a.nrows();
    let mut alive = vec![true; n];
    let mut row_nz: Vec<usize> = (0..n).map(|i| (0..n).filter(|&c| a[(i, c)] != 0.0).count()).collect();
    let mut col_nz: Vec<usize> = (0..n).map(|j| (0..n).filter(|&r| a[(r, j)] != 0.0).count()).collect();
    loop {
        let gone: Vec<usize> = (0..n)
            .filter(|&i| alive[i] && drop(i, row_nz[i] == 0, col_nz[i] == 0))
            .collect();
        if gone.is_empty() {
            break;
        }
        for &i in &gone {
            alive[i] = false;
        }
        for &i in &gone {
            for k in 0..n {
                if a[(i, k)] != 0.0 && alive[k] {
                    col_nz[k] -= 1;
                }
                if a[(k, i)] != 0.0 && alive[k] {
                    row_nz[k] -= 1;
                }
            }
            // Entries between two removed states were counted on both; `alive` is already
            // false for them, so they are skipped above and need no correction.
        }
    }
    (0..n).filter(|&i| alive[i]).collect()
}

/// The discrete frequency response of one state, prepared for many frequencies: `A` is reduced
/// once to upper Hessenberg form `A = Q H Qᵀ` (`O(n³)`), after which each frequency costs one
/// Hessenberg solve `(zI − H) y = Qᵀ(B0 + z B1)`, `O(n²)`, instead of a dense LU, `O(n³)`.
/// Agrees with [`StepMap::frequency_response`] to round-off.
#[derive(Debug, Clone)]
pub struct FrequencyResponse {
    h: DMatrix<f64>,
    qt_b0: DVector<f64>,
    qt_b1: DVector<f64>,
    /// Row `output` of `Q`.
    q_out: DVector<f64>,
}

impl FrequencyResponse {
    pub fn new(map: &StepMap, output: usize) -> Result<Self> {
        let n = map.a.nrows();
        if output >= n {
            return Err(Error::invalid(
                "frequency response",
                format!("output state {output} is outside the {n} states"),
            ));
        }
        // States that feed nothing (zero column; not the output) and states that are never set
        // and never driven (zero row, zero B) do not change the output's response: drop them,
        // repeatedly (a delay line keeps many such states).
        let keep = prune(&map.a, |i, row_zero, col_zero| {
            i != output && (col_zero || (row_zero && map.b0[i] == 0.0 && map.b1[i] == 0.0))
        });
        let m = keep.len();
        let a = DMatrix::from_fn(m, m, |r, c| map.a[(keep[r], keep[c])]);
        let b0 = DVector::from_fn(m, |r, _| map.b0[keep[r]]);
        let b1 = DVector::from_fn(m, |r, _| map.b1[keep[r]]);
        let out = keep.iter().position(|&i| i == output).unwrap_or(0);
        let (q, h) = a.hessenberg().unpack();
        Ok(Self {
            qt_b0: q.tr_mul(&b0),
            qt_b1: q.tr_mul(&b1),
            q_out: q.row(out).transpose(),
            h,
        })
    }
    /// `e_outᵀ (zI − A)⁻¹ (B0 + z B1)`, `z = e^{iΩ}` (NaN if `zI − A` is singular).
    pub fn at(&self, omega_dt: f64) -> Complex<f64> {
        let n = self.h.nrows();
        let z = Complex::new(omega_dt.cos(), omega_dt.sin());
        // Gaussian elimination of the upper Hessenberg `zI − H` with partial pivoting between
        // neighbouring rows; `m` is row-major, `n × n`, allocated per call (the planner calls this
        // a few thousand times per grid point, far off any step path).
        let mut m: Vec<Complex<f64>> = Vec::with_capacity(n * n);
        for r in 0..n {
            for c in 0..n {
                let d = if r == c { z } else { Complex::new(0.0, 0.0) };
                m.push(d - self.h[(r, c)]);
            }
        }
        let mut y: Vec<Complex<f64>> = (0..n).map(|i| self.qt_b0[i] + z * self.qt_b1[i]).collect();
        for k in 0..n {
            if k + 1 < n && m[(k + 1) * n + k].norm_sqr() > m[k * n + k].norm_sqr() {
                for c in k..n {
                    m.swap(k * n + c, (k + 1) * n + c);
                }
                y.swap(k, k + 1);
            }
            let p = m[k * n + k];
            if p.norm_sqr() == 0.0 {
                return Complex::new(f64::NAN, f64::NAN);
            }
            if k + 1 < n {
                let f = m[(k + 1) * n + k] / p;
                if f.norm_sqr() != 0.0 {
                    for c in k..n {
                        let v = m[k * n + c];
                        m[(k + 1) * n + c] -= f * v;
                    }
                    let v = y[k];
                    y[k + 1] -= f * v;
                }
            }
        }
        for k in (0..n).rev() {
            let mut s = y[k];
            for c in k + 1..n {
                s -= m[k * n + c] * y[c];
            }
            y[k] = s / m[k * n + k];
        }
        (0..n).fold(Complex::new(0.0, 0.0), |acc, i| acc + y[i] * self.q_out[i])
    }
}
