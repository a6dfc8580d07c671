//! Small dense helpers shared by the analysis and the model checks.

use nalgebra::{Complex, DMatrix};

/// Eigenvalues of a general real matrix, computed the safe way: Parlett–Reinsch balancing, then
/// a Schur decomposition with a bounded number of iterations (nalgebra's plain
/// `complex_eigenvalues` can loop forever on companion/shift matrices, see
/// docs/theory.md §11.1). Returns `None` if the iteration does not converge.
pub fn eigenvalues(m: &DMatrix<f64>) -> Option<Vec<Complex<f64>>> {
    if m.iter().any(|x| !x.is_finite()) {
        return None;
    }
    eigenvalues_owned(m.clone())
}

/// [`eigenvalues`] of a matrix the caller no longer needs (balanced in place, no copy).
pub fn eigenvalues_owned(mut b: DMatrix<f64>) -> Option<Vec<Complex<f64>>> {
    let n = b.nrows();
    if n == 0 {
        return Some(Vec::new());
    }
    if b.iter().any(|x| !x.is_finite()) {
        return None;
    }
    balance(&mut b)?;
    let (_, t) = nalgebra::Schur::try_new(b, f64::EPSILON, 200 * n.max(10))?.unpack();
    let ev = quasi_triangular_eigenvalues(&t);
    ev.iter().all(|z| z.re.is_finite() && z.im.is_finite()).then_some(ev)
}

/// The eigenvalues of a real Schur form `t` (1 × 1 and 2 × 2 diagonal blocks). A 2 × 2 block
/// `[a b; c d]` has `λ = (a + d)/2 ± √(((a − d)/2)² + b c)`, written so that a block with two
/// nearly equal real roots stays finite: nalgebra's own `complex_eigenvalues` returned NaN for
/// such a block (a pair at ±1.6e-8 in one point of a CR stability map, Ω = 3π/4).
fn quasi_triangular_eigenvalues(t: &DMatrix<f64>) -> Vec<Complex<f64>> {
    let n = t.nrows();
    let mut ev = Vec::with_capacity(n);
    let mut i = 0;
    while i < n {
        if i + 1 == n || t[(i + 1, i)] == 0.0 {
            ev.push(Complex::new(t[(i, i)], 0.0));
            i += 1;
            continue;
        }
        let (a, b, c, d) = (t[(i, i)], t[(i, i + 1)], t[(i + 1, i)], t[(i + 1, i + 1)]);
        let mean = 0.5 * (a + d);
        let half = 0.5 * (a - d);
        let disc = half * half + b * c;
        if disc >= 0.0 {
            let r = disc.sqrt();
            ev.push(Complex::new(mean + r, 0.0));
            ev.push(Complex::new(mean - r, 0.0));
        } else {
            let r = (-disc).sqrt();
            ev.push(Complex::new(mean, r));
            ev.push(Complex::new(mean, -r));
        }
        i += 2;
    }
    ev
}

/// Sweeps of [`balance`]: a balanced matrix needs a handful; the cap only matters for
/// matrices whose norms nearly overflow, where nalgebra's loop never ends.
const BALANCE_MAX_SWEEPS: usize = 100;

/// Parlett–Reinsch balancing (as nalgebra's `balance_parlett_reinsch`, radix 2, 2-norms) with
/// every loop bounded: at most `BALANCE_MAX_SWEEPS` sweeps, and scale factors limited to the
/// exponent range of `f64`. `None` for a matrix whose row or column norms are not finite.
/// Balancing is a similarity transform, so stopping early changes accuracy, not eigenvalues.
pub fn balance(m: &mut DMatrix<f64>) -> Option<()> {
    let n = m.nrows();
    for _ in 0..BALANCE_MAX_SWEEPS {
        let mut converged = true;
        for i in 0..n {
            let c2 = m.column(i).norm_squared();
            let r2 = m.row(i).norm_squared();
            if !(c2.is_finite() && r2.is_finite()) {
                return None;
            }
            let (mut c, mut r) = (c2.sqrt(), r2.sqrt());
            if c == 0.0 || r == 0.0 {
                continue;
            }
            let s = c2 + r2;
            let mut f: f64 = 1.0;
            // 2100 halvings or doublings span the whole f64 range.
            for _ in 0..2100 {
                if c >= r / 2.0 {
                    break;
                }
                c *= 2.0;
                r /= 2.0;
                f *= 2.0;
            }
            for _ in 0..2100 {
                if c < r * 2.0 {
                    break;
                }
                c /= 2.0;
                r *= 2.0;
                f /= 2.0;
            }
            if c * c + r * r < 0.95 * s && f.is_finite() && f > 0.0 {
                converged = false;
                m.column_mut(i).scale_mut(f);
                m.row_mut(i).unscale_mut(f);
            }
        }
        if converged {
            break;
        }
    }
    m.iter().all(|x| x.is_finite()).then_some(())
}

/// Largest 1-norm of a matrix whose exponential [`expm`] computes (scaled to norm ≤ 1 by
/// `⌈log2 ‖A‖₁⌉` squarings); beyond it the squarings lose every digit (an error of about
/// `‖A‖₁ · ε`), so the caller should refuse the input instead.
pub const EXPM_MAX_NORM: f64 = 1e12;

/// `exp(A)` without panics: `None` for non-finite input, a 1-norm above [`EXPM_MAX_NORM`] or a
/// non-finite result. Above a 1-norm of 1000, `A` is scaled by a power of two to 1-norm ≤ 1
/// before nalgebra's Padé approximant (which unwraps a failed LU solve when its own scaling
/// overflows, e.g. at ‖A‖₁ = 1e60), then squared back.
pub fn expm(a: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    if a.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let norm = one_norm(a);
    if norm > EXPM_MAX_NORM {
        return None;
    }
    // Up to a moderate norm nalgebra's own scaling is safe (and results stay as they were).
    let squarings = if norm > 1e3 { norm.log2().ceil() as i32 } else { 0 };
    let scaled = a * 2f64.powi(-squarings);
    let mut e = scaled.exp();
    for _ in 0..squarings {
        e = &e * &e;
    }
    e.iter().all(|x| x.is_finite()).then_some(e)
}

/// `‖A‖₁`, the largest absolute column sum.
pub fn one_norm(a: &DMatrix<f64>) -> f64 {
    a.column_iter()
        .map(|c| c.iter().map(|x| x.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// Spectral radius `max |λ|`, `NaN` if the eigenvalues could not be computed.
pub fn spectral_radius(m: &DMatrix<f64>) -> f64 {
    radius(eigenvalues(m))
}

/// [`spectral_radius`] of a matrix the caller no longer needs (no copy).
pub fn spectral_radius_owned(m: DMatrix<f64>) -> f64 {
    radius(eigenvalues_owned(m))
}

fn radius(ev: Option<Vec<Complex<f64>>>) -> f64 {
    ev.map_or(f64::NAN, |ev| ev.iter().map(|z| z.norm()).fold(0.0, f64::max))
}

/// `a + w b` for the fixed-size states of small plants (the RK4 stages of the benchmark's
/// numerical substructure and of the servo-hydraulic actuator).
#[inline]
pub fn axpy_array<const N: usize>(a: &[f64; N], w: f64, b: &[f64; N]) -> [f64; N] {
    let mut out = *a;
    for (o, &bi) in out.iter_mut().zip(b) {
        *o += w * bi;
    }
    out
}

/// The classical RK4 update `z₀ + h/6 (k₁ + 2k₂ + 2k₃ + k₄)` of a fixed-size state.
#[inline]
pub fn rk4_combine<const N: usize>(z0: &[f64; N], h: f64, k: [&[f64; N]; 4]) -> [f64; N] {
    let mut out = *z0;
    for i in 0..N {
        out[i] = z0[i] + h / 6.0 * (k[0][i] + 2.0 * k[1][i] + 2.0 * k[2][i] + k[3][i]);
    }
    out
}

#[cfg(test)]
mod eigen_tests {
    use super::*;

    /// The 2 × 2 block formula against the closed forms: a rotation-scaled block (complex
    /// pair), a block with two distinct real roots, and a block with two real roots 3e-8 apart,
    /// where the discriminant is tiny; and `eigenvalues` on a matrix whose Schur form has such a
    /// block equals the characteristic roots.
    #[test]
    fn schur_blocks_give_their_closed_form_eigenvalues() {
        let t = DMatrix::from_row_slice(2, 2, &[0.3, -0.8, 0.5, 0.3]);
        let ev = quasi_triangular_eigenvalues(&t);
        let r = (0.4f64).sqrt();
        assert!((ev[0] - Complex::new(0.3, r)).norm() < 1e-15 && (ev[1] - Complex::new(0.3, -r)).norm() < 1e-15);
        let t = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 0.5, -1.0]);
        let ev = quasi_triangular_eigenvalues(&t);
        let r = (2.0f64).sqrt();
        assert!((ev[0].re - r).abs() < 1e-15 && (ev[1].re + r).abs() < 1e-15 && ev[0].im == 0.0);
        let eps = 1.5e-8;
        let t = DMatrix::from_row_slice(2, 2, &[eps, 1.0, eps * eps, -eps]);
        let ev = quasi_triangular_eigenvalues(&t);
        let r = (2.0f64).sqrt() * eps;
        assert!((ev[0].re - r).abs() < 1e-22 && (ev[1].re + r).abs() < 1e-22, "{ev:?}");
        // diag(2, −1, 0.5) in another basis: the eigenvalues are the diagonal's.
        let q = DMatrix::from_row_slice(3, 3, &[1.0, 2.0, 0.0, 0.0, 1.0, 3.0, 1.0, 0.0, 1.0]);
        let m = &q
            * DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![2.0, -1.0, 0.5]))
            * q.clone().try_inverse().unwrap();
        let mut got: Vec<f64> = eigenvalues(&m).unwrap().iter().map(|z| z.re).collect();
        got.sort_by(f64::total_cmp);
        for (g, e) in got.iter().zip([-1.0, 0.5, 2.0]) {
            assert!((g - e).abs() < 1e-12, "{got:?}");
        }
    }
}
