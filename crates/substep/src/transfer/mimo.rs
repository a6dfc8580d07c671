//! Multi-input multi-output (MIMO) LTI plants: several actuators driving one specimen, where the
//! command of each actuator moves every measured displacement (control–structure interaction
//! through the specimen, e.g. the two actuators of the multi-axial benchmark on one coupler).
//!
//! A plant with `q` commands `u` and `p` measured outputs `y` is given either as a `p × q` matrix
//! of SISO transfer functions `H_ij(s)` (`y_i = Σ_j H_ij u_j`, each entry from polynomials or from
//! zeros, poles and a gain) or as a state-space model `ẋ = A x + B u`, `y = C x + D u`. The matrix
//! form is realised block-diagonally — each entry's controllable canonical form
//! ([`super::lti`]) is one block, driven by input `j`, summed into output `i`; `n = Σ n_ij`
//! states. This is the realisation of MATLAB's `ss(tf(...))` only up to a similarity transform,
//! which RK4 does not see: RK4 with the input held over the step is exact for the same
//! polynomial in `A h` in every basis, so the outputs agree to round-off.
//!
//! [`MimoStateSpace::rk4`] integrates the plant with classical RK4 at a fixed step, the input held
//! over the step (a D/A's zero-order hold) — what Simulink's fixed-step `ode4` does for a
//! continuous block fed by a sampled signal. No allocation per step.

use super::lti::{TransferFunction, poly_mul, rk4_held};
use crate::error::{Error, Result};
use nalgebra::{Complex, DMatrix, DVector};

/// Largest number of plant channels (`p`, `q`) and states accepted.
pub const MAX_CHANNELS: usize = 64;
pub const MAX_STATES: usize = 1024;

impl TransferFunction {
    /// `k Π(s − z_i) / Π(s − p_i)` from zeros, poles [rad/s] and the gain `k`. Complex zeros
    /// and poles must come in conjugate pairs (the polynomials are real).
    pub fn from_zpk(what: &str, zeros: &[Complex<f64>], poles: &[Complex<f64>], gain: f64) -> Result<Self> {
        let num = real_polynomial(&format!("{what}.zeros"), zeros)?;
        let den = real_polynomial(&format!("{what}.poles"), poles)?;
        if !gain.is_finite() {
            return Err(Error::invalid(
                format!("{what}.gain"),
                format!("must be finite, got {gain}"),
            ));
        }
        let num: Vec<f64> = num.iter().map(|c| c * gain).collect();
        TransferFunction::new(what, &num, &den)
    }
}

/// `Π (s − r_i)` in descending powers, real: every complex root needs its conjugate.
fn real_polynomial(what: &str, roots: &[Complex<f64>]) -> Result<Vec<f64>> {
    if roots.len() > MAX_STATES {
        return Err(Error::invalid(
            what,
            format!("{} roots, at most {MAX_STATES}", roots.len()),
        ));
    }
    let mut used = vec![false; roots.len()];
    let mut p = vec![1.0];
    for i in 0..roots.len() {
        if used[i] {
            continue;
        }
        let r = roots[i];
        if !(r.re.is_finite() && r.im.is_finite()) {
            return Err(Error::invalid(what, format!("root {r} is not finite")));
        }
        used[i] = true;
        if r.im == 0.0 {
            p = poly_mul(&p, &[1.0, -r.re]);
            continue;
        }
        let tol = 1e-9 * r.norm();
        let Some(j) = (i + 1..roots.len()).find(|&j| !used[j] && (roots[j] - r.conj()).norm() <= tol) else {
            return Err(Error::invalid(
                what,
                format!("complex root {r} has no conjugate partner (the polynomial must be real)"),
            ));
        };
        used[j] = true;
        // (s − r)(s − r̄) = s² − 2 Re r s + |r|²
        p = poly_mul(&p, &[1.0, -2.0 * r.re, r.norm_sqr()]);
    }
    Ok(p)
}

/// A `p × q` matrix of SISO transfer functions, row-major: `entries[i q + j] = H_ij`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferMatrix {
    outputs: usize,
    inputs: usize,
    entries: Vec<TransferFunction>,
}

impl TransferMatrix {
    /// `what` names the plant in errors. `entries` row by row; its length must be `p · q`.
    pub fn new(what: &str, outputs: usize, inputs: usize, entries: Vec<TransferFunction>) -> Result<Self> {
        check_channels(what, outputs, inputs)?;
        if entries.len() != outputs * inputs {
            return Err(Error::invalid(
                what,
                format!(
                    "a {outputs}×{inputs} plant needs {} transfer functions (row by row), got {}",
                    outputs * inputs,
                    entries.len()
                ),
            ));
        }
        let states: usize = entries.iter().map(TransferFunction::order).sum();
        if states > MAX_STATES {
            return Err(Error::invalid(what, format!("{states} states, at most {MAX_STATES}")));
        }
        Ok(Self {
            outputs,
            inputs,
            entries,
        })
    }
    pub fn outputs(&self) -> usize {
        self.outputs
    }
    pub fn inputs(&self) -> usize {
        self.inputs
    }
    pub fn entry(&self, i: usize, j: usize) -> &TransferFunction {
        &self.entries[i * self.inputs + j]
    }
    /// `H(0)` (`p × q`).
    pub fn dc_gain(&self) -> DMatrix<f64> {
        DMatrix::from_fn(self.outputs, self.inputs, |i, j| self.entry(i, j).dc_gain())
    }
    /// `H(j 2π f)` (`p × q`).
    pub fn frequency_response(&self, f_hz: f64) -> DMatrix<Complex<f64>> {
        DMatrix::from_fn(self.outputs, self.inputs, |i, j| {
            self.entry(i, j).frequency_response(f_hz)
        })
    }

    /// The block-diagonal realisation (see the module docs).
    pub fn to_state_space(&self) -> MimoStateSpace {
        let n: usize = self.entries.iter().map(TransferFunction::order).sum();
        let (p, q) = (self.outputs, self.inputs);
        let mut a = DMatrix::zeros(n, n);
        let mut b = DMatrix::zeros(n, q);
        let mut c = DMatrix::zeros(p, n);
        let mut d = DMatrix::zeros(p, q);
        let mut at = 0;
        for i in 0..p {
            for j in 0..q {
                let ss = self.entry(i, j).to_state_space();
                let m = ss.order();
                a.view_mut((at, at), (m, m)).copy_from(&ss.a);
                b.view_mut((at, j), (m, 1)).copy_from(&ss.b);
                c.view_mut((i, at), (1, m)).copy_from(&ss.c.transpose());
                d[(i, j)] = ss.d;
                at += m;
            }
        }
        MimoStateSpace { a, b, c, d }
    }
}

fn check_channels(what: &str, outputs: usize, inputs: usize) -> Result<()> {
    if !(1..=MAX_CHANNELS).contains(&outputs) || !(1..=MAX_CHANNELS).contains(&inputs) {
        return Err(Error::invalid(
            what,
            format!("must have 1..={MAX_CHANNELS} outputs and inputs, got {outputs}×{inputs}"),
        ));
    }
    Ok(())
}

/// `ẋ = A x + B u`, `y = C x + D u` with `q` inputs and `p` outputs.
#[derive(Debug, Clone, PartialEq)]
pub struct MimoStateSpace {
    pub a: DMatrix<f64>,
    pub b: DMatrix<f64>,
    pub c: DMatrix<f64>,
    pub d: DMatrix<f64>,
}

impl MimoStateSpace {
    /// Validate shapes (`A` n×n, `B` n×q, `C` p×n, `D` p×q) and finiteness.
    pub fn new(what: &str, a: DMatrix<f64>, b: DMatrix<f64>, c: DMatrix<f64>, d: DMatrix<f64>) -> Result<Self> {
        let n = a.nrows();
        let (p, q) = (d.nrows(), d.ncols());
        check_channels(what, p, q)?;
        if n > MAX_STATES {
            return Err(Error::invalid(what, format!("{n} states, at most {MAX_STATES}")));
        }
        if a.ncols() != n || b.nrows() != n || b.ncols() != q || c.nrows() != p || c.ncols() != n {
            return Err(Error::invalid(
                what,
                format!(
                    "inconsistent shapes: A {}×{}, B {}×{}, C {}×{}, D {p}×{q} (need A n×n, B n×q, C p×n, D p×q)",
                    a.nrows(),
                    a.ncols(),
                    b.nrows(),
                    b.ncols(),
                    c.nrows(),
                    c.ncols()
                ),
            ));
        }
        if a.iter()
            .chain(b.iter())
            .chain(c.iter())
            .chain(d.iter())
            .any(|v| !v.is_finite())
        {
            return Err(Error::invalid(what, "has a non-finite entry"));
        }
        Ok(Self { a, b, c, d })
    }
    pub fn states(&self) -> usize {
        self.a.nrows()
    }
    pub fn outputs(&self) -> usize {
        self.d.nrows()
    }
    pub fn inputs(&self) -> usize {
        self.d.ncols()
    }
    /// `D − C A⁻¹ B`; `None` if `A` is singular (a pole at the origin).
    pub fn dc_gain(&self) -> Option<DMatrix<f64>> {
        let x = self.a.clone().lu().solve(&self.b)?;
        Some(&self.d - &self.c * x)
    }
    /// RK4 at step `h` from rest.
    pub fn rk4(&self, h: f64) -> Result<MimoRk4> {
        crate::error::require_positive("plant.h", h)?;
        let n = self.states();
        Ok(MimoRk4 {
            sys: self.clone(),
            h,
            x: DVector::zeros(n),
            k: std::array::from_fn(|_| DVector::zeros(n)),
            tmp: DVector::zeros(n),
            bu: DVector::zeros(n),
        })
    }
}

/// Fixed-step RK4 of a [`MimoStateSpace`] with the input held over the step.
#[derive(Debug, Clone)]
pub struct MimoRk4 {
    sys: MimoStateSpace,
    h: f64,
    x: DVector<f64>,
    k: [DVector<f64>; 4],
    tmp: DVector<f64>,
    bu: DVector<f64>,
}

impl MimoRk4 {
    /// Write the output `y = C x + D u` now into `y` (`p` entries), then advance one RK4 step
    /// with `u` (`q` entries) held.
    pub fn step(&mut self, u: &[f64], y: &mut [f64]) {
        self.output(u, y);
        let s = &self.sys;
        let u = nalgebra::DVectorView::from_slice(u, s.inputs());
        self.bu.gemv(1.0, &s.b, &u, 0.0);
        rk4_held(&s.a, &self.bu, 1.0, self.h, &mut self.x, &mut self.k, &mut self.tmp);
    }
    /// `y = C x + D u` without advancing.
    pub fn output(&self, u: &[f64], y: &mut [f64]) {
        let s = &self.sys;
        for (i, yi) in y.iter_mut().enumerate().take(s.outputs()) {
            let mut v = 0.0;
            for (j, xj) in self.x.iter().enumerate() {
                v += s.c[(i, j)] * xj;
            }
            for (j, uj) in u.iter().enumerate() {
                v += s.d[(i, j)] * uj;
            }
            *yi = v;
        }
    }
    pub fn state(&self) -> &DVector<f64> {
        &self.x
    }
    pub fn reset(&mut self) {
        self.x.fill(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(re: f64, im: f64) -> Complex<f64> {
        Complex::new(re, im)
    }

    #[test]
    fn zpk_expands_to_the_product_of_its_factors() {
        let tf = TransferFunction::from_zpk("h", &[c(-2.0, 0.0)], &[c(-1.0, 3.0), c(-1.0, -3.0), c(-5.0, 0.0)], 7.0)
            .unwrap();
        // 7 (s + 2) / ((s² + 2 s + 10)(s + 5)) = (7 s + 14) / (s³ + 7 s² + 20 s + 50)
        assert_eq!(tf.num(), &[7.0, 14.0]);
        assert_eq!(tf.den(), &[1.0, 7.0, 20.0, 50.0]);
        assert!((tf.dc_gain() - 14.0 / 50.0).abs() < 1e-15);
        let e = TransferFunction::from_zpk("plant.h11", &[], &[c(-1.0, 3.0)], 1.0).unwrap_err();
        assert!(e.to_string().contains("conjugate"), "{e}");
    }

    #[test]
    fn a_coupled_plant_steps_like_its_channels_summed() {
        let tfs = vec![
            TransferFunction::new("h11", &[4.0], &[1.0, 4.0]).unwrap(),
            TransferFunction::new("h12", &[1.0], &[1.0, 3.0, 2.0]).unwrap(),
            TransferFunction::new("h21", &[0.5, 1.0], &[1.0, 2.0, 5.0]).unwrap(),
            TransferFunction::new("h22", &[2.0], &[1.0, 2.0]).unwrap(),
        ];
        let m = TransferMatrix::new("plant", 2, 2, tfs.clone()).unwrap();
        let dc = m.dc_gain();
        assert!((dc[(0, 1)] - 0.5).abs() < 1e-15 && (dc[(1, 0)] - 0.2).abs() < 1e-15);
        let ss = m.to_state_space();
        assert_eq!(ss.states(), 1 + 2 + 2 + 1);
        let ssdc = ss.dc_gain().unwrap();
        assert!((&ssdc - &dc).norm() < 1e-12, "{ssdc} {dc}");
        let h = 1e-3;
        let mut mimo = ss.rk4(h).unwrap();
        let mut siso: Vec<_> = tfs.iter().map(|t| t.to_state_space().rk4(h).unwrap()).collect();
        let mut y = [0.0; 2];
        for k in 0..2000 {
            let t = k as f64 * h;
            let u = [(7.0 * t).sin(), (3.0 * t).cos() - 1.0];
            mimo.step(&u, &mut y);
            let y1 = siso[0].step(u[0]) + siso[1].step(u[1]);
            let y2 = siso[2].step(u[0]) + siso[3].step(u[1]);
            assert!(
                (y[0] - y1).abs() < 1e-13 && (y[1] - y2).abs() < 1e-13,
                "{k}: {y:?} {y1} {y2}"
            );
        }
    }

    #[test]
    fn wrong_shapes_are_refused_with_the_shape() {
        let tf = TransferFunction::new("h", &[1.0], &[1.0, 1.0]).unwrap();
        let e = TransferMatrix::new("plant", 2, 2, vec![tf.clone(); 3]).unwrap_err();
        assert!(e.to_string().contains("2×2 plant needs 4"), "{e}");
        let e = MimoStateSpace::new(
            "plant",
            DMatrix::zeros(2, 2),
            DMatrix::zeros(2, 1),
            DMatrix::zeros(2, 2),
            DMatrix::zeros(2, 2),
        )
        .unwrap_err();
        assert!(e.to_string().contains("inconsistent shapes"), "{e}");
    }
}
