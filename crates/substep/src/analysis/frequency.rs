//! Transfer functions, peaks, amplitude and period errors (docs/theory.md §9.5).
//!
//! For the analysis model the response quantity is the dynamic amplification of the primary
//! (coupling) DOF, `h = |u₁| ω² / |a_g|`, as a function of the frequency ratio `r = ω_exc/ω`.

use super::AnalysisCase;
use crate::error::Result;
use nalgebra::{Complex, DMatrix, DVector};

/// A peak of `h(r)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peak {
    pub freq_ratio: f64,
    pub h: f64,
}

/// Amplification of the assembled continuous 2-DOF system at frequency ratio `r`
/// (`(−r² M + i r C + K) U = −M ι`, `ω = 1`).
pub fn exact_amplification(case: &AnalysisCase, r: f64) -> Result<f64> {
    let m = case.assembled_model()?;
    Ok(exact_amplification_of(&m, r))
}

fn exact_amplification_of(m: &crate::model::StructuralModel, r: f64) -> f64 {
    continuous_response(m, 0, r).norm()
}

/// Continuous frequency response `U_out / A_g` of a linear model to harmonic ground
/// acceleration at circular frequency `omega`: `(−ω² M + iω C + K) U = −M ι`.
pub fn continuous_response(m: &crate::model::StructuralModel, output: usize, omega: f64) -> Complex<f64> {
    let n = m.n_dofs();
    let z = DMatrix::from_fn(n, n, |i, j| {
        Complex::new(
            m.stiffness[(i, j)] - omega * omega * m.mass[(i, j)],
            omega * m.damping[(i, j)],
        )
    });
    let mi = m.effective_mass_vector();
    let rhs = DVector::from_fn(n, |i, _| Complex::new(-mi[i], 0.0));
    z.lu()
        .solve(&rhs)
        .map_or(Complex::new(f64::NAN, f64::NAN), |u| u[output])
}

/// The substructure algorithm's discrete amplification at frequency ratio `r`.
pub struct DiscreteResponse {
    map: super::StepMap,
    omega_dt: f64,
}

impl DiscreteResponse {
    pub fn new(case: &AnalysisCase) -> Result<Self> {
        Ok(Self {
            map: case.step_map()?,
            omega_dt: case.omega_dt,
        })
    }
    /// `h(r)`; output state 0 is the primary displacement `u₁`.
    pub fn amplification(&self, r: f64) -> f64 {
        self.map.frequency_response(0, r * self.omega_dt).norm()
    }
    pub fn spectral_radius(&self) -> f64 {
        self.map.spectral_radius()
    }
}

/// Up to two peaks (largest local maxima, sorted by frequency) of `h` on `[r_min, r_max]`,
/// located on a grid of `samples` points and refined by golden-section search.
pub fn find_peaks(h: impl Fn(f64) -> f64, r_min: f64, r_max: f64, samples: usize) -> Vec<Peak> {
    let step = (r_max - r_min) / (samples - 1) as f64;
    let values: Vec<f64> = (0..samples).map(|i| h(r_min + i as f64 * step)).collect();
    let mut maxima: Vec<usize> = (1..samples - 1)
        .filter(|&i| values[i] > values[i - 1] && values[i] >= values[i + 1])
        .collect();
    maxima.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
    maxima.truncate(2);
    let mut peaks: Vec<Peak> = maxima
        .into_iter()
        .map(|i| {
            let c = r_min + i as f64 * step;
            let r = golden_max(&h, c - step, c + step);
            Peak { freq_ratio: r, h: h(r) }
        })
        .collect();
    peaks.sort_by(|a, b| a.freq_ratio.total_cmp(&b.freq_ratio));
    peaks
}

fn golden_max(h: &impl Fn(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (h(c), h(d));
    for _ in 0..80 {
        if fc > fd {
            b = d;
            (d, fd) = (c, fc);
            c = b - g * (b - a);
            fc = h(c);
        } else {
            a = c;
            (c, fc) = (d, fd);
            d = a + g * (b - a);
            fd = h(d);
        }
        if (b - a).abs() < 1e-12 * (1.0 + a.abs()) {
            break;
        }
    }
    0.5 * (a + b)
}

/// Amplitude and period errors of one peak against the exact peak.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeakError {
    pub peak: usize,
    pub sub: Peak,
    pub exact: Peak,
    /// `h/h_exact − 1`.
    pub amplitude_error: f64,
    /// `r_exact/r − 1` (= `T_sub/T_exact − 1`).
    pub period_error: f64,
}

/// Peaks of the algorithm's response and of the exact 2-DOF response, paired in frequency
/// order. The search range is `r ∈ [0.05, min(3, 0.95 π/Ω)]` (below the Nyquist frequency).
pub fn peak_errors(case: &AnalysisCase) -> Result<Vec<PeakError>> {
    let resp = DiscreteResponse::new(case)?;
    let model = case.assembled_model()?;
    let r_max = 3.0f64.min(0.95 * std::f64::consts::PI / case.omega_dt);
    let sub = find_peaks(|r| resp.amplification(r), 0.05, r_max, 1500);
    let exact = find_peaks(|r| exact_amplification_of(&model, r), 0.05, r_max, 1500);
    Ok(sub
        .iter()
        .zip(exact.iter())
        .enumerate()
        .map(|(i, (s, e))| PeakError {
            peak: i + 1,
            sub: *s,
            exact: *e,
            amplitude_error: s.h / e.h - 1.0,
            period_error: e.freq_ratio / s.freq_ratio - 1.0,
        })
        .collect())
}
