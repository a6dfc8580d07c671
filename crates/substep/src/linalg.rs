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
    balance(&mut b)?;
    let schur = nalgebra::Schur::try_new(b, f64::EPSILON, 200 * n.max(10))?;
    let ev: Vec<Complex<f64>> = schur.complex_eigenvalues().iter().copied().collect();
    ev.iter().all(|z| z.re.is_finite() && z.im.is_finite()).then_some(ev)
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
    eigenvalues(m).map_or(f64::NAN, |ev| ev.iter().map(|z| z.norm()).fold(0.0, f64::max))
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
