//! Continuous linear time-invariant (LTI) SISO systems: transfer functions in `s` and state
//! space, integrated at a fixed step.
//!
//! A transfer function `G(s) = (b_m s^m + … + b_0) / (a_n s^n + … + a_0)` (coefficients in
//! descending powers, `m ≤ n`) is realised in controllable canonical form after dividing by
//! `a_n`:
//!
//! ```text
//! ẋ = A x + B u,  y = C x + D u,   A = companion(−a_0 … −a_{n−1}),  B = e_n,
//! D = b_n,  C_i = b_i − a_i b_n          (all normalised by a_n)
//! ```
//!
//! Two ways to advance it over a step `h` with the input held (zero-order hold):
//!
//! * [`Rk4Lti`]: classical fixed-step RK4, the integrator of the RTHS benchmark (Silva et al.
//!   2020), which integrates every continuous block with RK4 at the controller rate; to
//!   reproduce its numbers bit for bit the same scheme is needed. Its local error is `O(h⁵)`.
//! * [`StateSpace::zoh`]: the exact ZOH map `x_{k+1} = Φ x_k + Γ u_k`, `Φ = e^{Ah}`,
//!   `Γ = ∫₀ʰ e^{Aσ} dσ B`, from the exponential of `[[A h, B h], [0, 0]]`.
//!
//! Both are allocation-free per step.

use crate::error::{Error, Result};
use nalgebra::{Complex, DMatrix, DVector};

/// A continuous transfer function, coefficients in descending powers of `s`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferFunction {
    num: Vec<f64>,
    den: Vec<f64>,
}

impl TransferFunction {
    /// Validate and store `num / den`. `what` names the thing in errors (e.g.
    /// `controller.feedback`). Leading zeros of the numerator are dropped; the denominator's
    /// leading coefficient must be non-zero; the function must be proper (`deg num ≤ deg den`).
    pub fn new(what: &str, num: &[f64], den: &[f64]) -> Result<Self> {
        if den.is_empty() {
            return Err(Error::invalid(format!("{what}.den"), "is empty"));
        }
        if num.is_empty() {
            return Err(Error::invalid(format!("{what}.num"), "is empty"));
        }
        if let Some(v) = num.iter().chain(den).find(|v| !v.is_finite()) {
            return Err(Error::invalid(what, format!("coefficient {v} is not finite")));
        }
        if den[0] == 0.0 {
            return Err(Error::invalid(
                format!("{what}.den"),
                "leading coefficient is zero (strip leading zeros; an all-zero denominator is no transfer function)",
            ));
        }
        let first = num.iter().position(|&v| v != 0.0).unwrap_or(num.len() - 1);
        let num = num[first..].to_vec();
        if num.len() > den.len() {
            return Err(Error::invalid(
                what,
                format!(
                    "improper transfer function: numerator degree {} exceeds denominator degree {}",
                    num.len() - 1,
                    den.len() - 1
                ),
            ));
        }
        Ok(Self { num, den: den.to_vec() })
    }

    pub fn num(&self) -> &[f64] {
        &self.num
    }
    pub fn den(&self) -> &[f64] {
        &self.den
    }
    /// Order `n` (degree of the denominator).
    pub fn order(&self) -> usize {
        self.den.len() - 1
    }

    /// `G(s)` at a complex `s`.
    pub fn eval(&self, s: Complex<f64>) -> Complex<f64> {
        polyval_complex(&self.num, s) / polyval_complex(&self.den, s)
    }

    /// `G(j 2π f)`.
    pub fn frequency_response(&self, f_hz: f64) -> Complex<f64> {
        self.eval(Complex::new(0.0, 2.0 * std::f64::consts::PI * f_hz))
    }

    /// Gain `|G(jω)|` and phase delay `−arg G(jω)/ω` \[s\] at `f_hz > 0` (the phase is unwrapped
    /// to `(−2π, 0]`, i.e. read as a lag).
    pub fn gain_and_delay(&self, f_hz: f64) -> (f64, f64) {
        let g = self.frequency_response(f_hz);
        let mut phase = g.arg();
        if phase > 0.0 {
            phase -= 2.0 * std::f64::consts::PI;
        }
        (g.norm(), -phase / (2.0 * std::f64::consts::PI * f_hz))
    }

    /// `G(0)`; infinite for a pole at the origin.
    pub fn dc_gain(&self) -> f64 {
        self.num[self.num.len() - 1] / self.den[self.den.len() - 1]
    }

    /// The controllable canonical realisation (see the module docs).
    pub fn to_state_space(&self) -> StateSpace {
        let n = self.order();
        let a_n = self.den[0];
        // a_i, b_i in ascending powers, normalised.
        let a: Vec<f64> = self.den.iter().rev().map(|v| v / a_n).collect();
        let mut b = vec![0.0; n + 1];
        for (i, v) in self.num.iter().rev().enumerate() {
            b[i] = v / a_n;
        }
        let d = b[n];
        let mut am = DMatrix::zeros(n, n);
        for i in 0..n.saturating_sub(1) {
            am[(i, i + 1)] = 1.0;
        }
        for j in 0..n {
            am[(n - 1, j)] = -a[j];
        }
        let mut bm = DVector::zeros(n);
        if n > 0 {
            bm[n - 1] = 1.0;
        }
        let c = DVector::from_fn(n, |i, _| b[i] - a[i] * d);
        StateSpace { a: am, b: bm, c, d }
    }
}

pub(crate) fn polyval_complex(p: &[f64], s: Complex<f64>) -> Complex<f64> {
    p.iter().fold(Complex::new(0.0, 0.0), |acc, &c| acc * s + c)
}

/// `p · q` for polynomials in descending powers.
pub fn poly_mul(p: &[f64], q: &[f64]) -> Vec<f64> {
    if p.is_empty() || q.is_empty() {
        return Vec::new();
    }
    let mut out = vec![0.0; p.len() + q.len() - 1];
    for (i, a) in p.iter().enumerate() {
        for (j, b) in q.iter().enumerate() {
            out[i + j] += a * b;
        }
    }
    out
}

/// `p + q` for polynomials in descending powers (aligned at the constant term).
pub fn poly_add(p: &[f64], q: &[f64]) -> Vec<f64> {
    let n = p.len().max(q.len());
    let mut out = vec![0.0; n];
    for (i, v) in p.iter().enumerate() {
        out[n - p.len() + i] += v;
    }
    for (i, v) in q.iter().enumerate() {
        out[n - q.len() + i] += v;
    }
    out
}

/// A continuous SISO state-space model `ẋ = A x + B u`, `y = C·x + D u`.
#[derive(Debug, Clone, PartialEq)]
pub struct StateSpace {
    pub a: DMatrix<f64>,
    pub b: DVector<f64>,
    pub c: DVector<f64>,
    pub d: f64,
}

impl StateSpace {
    /// Validate the shapes and finiteness (`what` names the thing in errors).
    pub fn new(what: &str, a: DMatrix<f64>, b: DVector<f64>, c: DVector<f64>, d: f64) -> Result<Self> {
        let n = a.nrows();
        if a.ncols() != n || b.len() != n || c.len() != n {
            return Err(Error::invalid(
                what,
                format!(
                    "inconsistent sizes: A is {}×{}, B has {}, C has {} entries",
                    a.nrows(),
                    a.ncols(),
                    b.len(),
                    c.len()
                ),
            ));
        }
        if a.iter().chain(b.iter()).chain(c.iter()).any(|v| !v.is_finite()) || !d.is_finite() {
            return Err(Error::invalid(what, "has a non-finite entry"));
        }
        Ok(Self { a, b, c, d })
    }

    pub fn order(&self) -> usize {
        self.a.nrows()
    }

    /// Exact zero-order-hold discretisation at step `h`.
    pub fn zoh(&self, h: f64) -> Result<ZohLti> {
        crate::error::require_positive("lti.h", h)?;
        let n = self.order();
        let mut aug = DMatrix::zeros(n + 1, n + 1);
        aug.view_mut((0, 0), (n, n)).copy_from(&(&self.a * h));
        aug.view_mut((0, n), (n, 1)).copy_from(&(&self.b * h));
        let e = aug.exp();
        if e.iter().any(|v| !v.is_finite()) {
            return Err(Error::numerical("lti.zoh", "matrix exponential is not finite"));
        }
        Ok(ZohLti {
            phi: e.view((0, 0), (n, n)).into_owned(),
            gamma: e.view((0, n), (n, 1)).column(0).into_owned(),
            c: self.c.clone(),
            d: self.d,
            x: DVector::zeros(n),
            scratch: DVector::zeros(n),
        })
    }

    /// RK4 integrator at step `h` from rest.
    pub fn rk4(&self, h: f64) -> Result<Rk4Lti> {
        crate::error::require_positive("lti.h", h)?;
        let n = self.order();
        Ok(Rk4Lti {
            sys: self.clone(),
            h,
            x: DVector::zeros(n),
            k: [
                DVector::zeros(n),
                DVector::zeros(n),
                DVector::zeros(n),
                DVector::zeros(n),
            ],
            tmp: DVector::zeros(n),
        })
    }
}

/// Exact ZOH stepping of a [`StateSpace`].
#[derive(Debug, Clone)]
pub struct ZohLti {
    pub phi: DMatrix<f64>,
    pub gamma: DVector<f64>,
    c: DVector<f64>,
    d: f64,
    x: DVector<f64>,
    scratch: DVector<f64>,
}

impl ZohLti {
    /// Output now for input `u`, then advance one step with `u` held.
    pub fn step(&mut self, u: f64) -> f64 {
        let y = self.c.dot(&self.x) + self.d * u;
        self.scratch.gemv(1.0, &self.phi, &self.x, 0.0);
        self.scratch.axpy(u, &self.gamma, 1.0);
        std::mem::swap(&mut self.x, &mut self.scratch);
        y
    }
    pub fn state(&self) -> &DVector<f64> {
        &self.x
    }
    /// Output `C x + D u` without advancing.
    pub fn output(&self, u: f64) -> f64 {
        self.c.dot(&self.x) + self.d * u
    }
}

/// One classical RK4 step of `ẋ = A x + s f` over `h` with the forcing `s f` held (`k`, `tmp`:
/// work space of `x`'s size). Shared by the SISO and the MIMO integrators.
pub(crate) fn rk4_held(
    a: &DMatrix<f64>,
    forcing: &DVector<f64>,
    scale: f64,
    h: f64,
    x: &mut DVector<f64>,
    k: &mut [DVector<f64>; 4],
    tmp: &mut DVector<f64>,
) {
    let stages = [0.0, 0.5 * h, 0.5 * h, h];
    for i in 0..4 {
        tmp.copy_from(x);
        if i > 0 {
            let (prev, _) = k.split_at_mut(i);
            tmp.axpy(stages[i], &prev[i - 1], 1.0);
        }
        let ki = &mut k[i];
        ki.gemv(1.0, a, tmp, 0.0);
        ki.axpy(scale, forcing, 1.0);
    }
    for (i, ki) in k.iter().enumerate() {
        let w = if i == 1 || i == 2 { h / 3.0 } else { h / 6.0 };
        x.axpy(w, ki, 1.0);
    }
}

/// Fixed-step RK4 of a [`StateSpace`] with the input held over the step.
#[derive(Debug, Clone)]
pub struct Rk4Lti {
    sys: StateSpace,
    h: f64,
    x: DVector<f64>,
    k: [DVector<f64>; 4],
    tmp: DVector<f64>,
}

impl Rk4Lti {
    /// Output now for input `u`, then advance one RK4 step with `u` held.
    pub fn step(&mut self, u: f64) -> f64 {
        let y = self.output(u);
        rk4_held(
            &self.sys.a,
            &self.sys.b,
            u,
            self.h,
            &mut self.x,
            &mut self.k,
            &mut self.tmp,
        );
        y
    }
    pub fn output(&self, u: f64) -> f64 {
        self.sys.c.dot(&self.x) + self.sys.d * u
    }
    pub fn state(&self) -> &DVector<f64> {
        &self.x
    }
}
