//! The amplification matrix of one complete step, probed from the implementation.

use crate::error::{Error, Result};
use crate::substructure::SubstructureTest;
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
    pub fn probe(test: &mut SubstructureTest) -> Result<Self> {
        test.controller.is_linear()?;
        test.site.is_linear()?;
        let n = test.state_len();
        let mut saved = vec![0.0; n];
        test.write_state(&mut saved);
        let mut x = vec![0.0; n];
        let column = |test: &mut SubstructureTest, x: &[f64], ag: (f64, f64)| -> Result<DVector<f64>> {
            test.read_state(x);
            test.step(ag.0, ag.1, &mut ())
                .map_err(|e| Error::numerical("amplification matrix", format!("probing step failed: {e}")))?;
            let mut out = DVector::zeros(n);
            test.write_state(out.as_mut_slice());
            Ok(out)
        };
        let mut a = DMatrix::zeros(n, n);
        for k in 0..n {
            x.iter_mut().for_each(|v| *v = 0.0);
            x[k] = 1.0;
            let col = column(test, &x, (0.0, 0.0))?;
            a.set_column(k, &col);
        }
        x.iter_mut().for_each(|v| *v = 0.0);
        let b0 = column(test, &x, (1.0, 0.0))?;
        let b1 = column(test, &x, (0.0, 1.0))?;
        test.read_state(&saved);
        Ok(Self { a, b0, b1 })
    }

    /// The part of `A` that carries dynamics: states that never influence anything (zero
    /// column) or are never set (zero row) only add eigenvalues 0 and are removed, repeatedly.
    /// Returns the reduced matrix and the kept indices.
    pub fn reduced(&self) -> (DMatrix<f64>, Vec<usize>) {
        let mut keep: Vec<usize> = (0..self.a.nrows()).collect();
        loop {
            let drop = keep.iter().position(|&i| {
                keep.iter().all(|&r| self.a[(r, i)] == 0.0) || keep.iter().all(|&c| self.a[(i, c)] == 0.0)
            });
            match drop {
                Some(p) => {
                    keep.remove(p);
                }
                None => break,
            }
        }
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
        crate::linalg::spectral_radius(&self.reduced().0)
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
