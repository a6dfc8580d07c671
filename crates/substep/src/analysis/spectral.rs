//! Plain spectral estimates for comparing signals of a run (no FFT needed at these lengths):
//! a one-sided amplitude spectrum by DFT and Welch's magnitude-squared coherence.

use nalgebra::Complex;
use std::f64::consts::PI;

/// One-sided amplitude spectrum of `x` sampled at `dt` by a plain DFT with a Hann window
/// (amplitude-corrected: a sine of amplitude `A` at a bin frequency shows as `A`). Returns
/// `(frequency [Hz], amplitude)` for the bins `0 ..= n/2` up to `f_max`. `O(n · bins)`.
pub fn amplitude_spectrum(x: &[f64], dt: f64, f_max: f64) -> (Vec<f64>, Vec<f64>) {
    let n = x.len();
    if n < 2 || dt.is_nan() || dt <= 0.0 {
        return (Vec::new(), Vec::new());
    }
    let w: Vec<f64> = (0..n)
        .map(|i| 0.5 - 0.5 * (2.0 * PI * i as f64 / n as f64).cos())
        .collect();
    let wsum: f64 = w.iter().sum();
    let df = 1.0 / (n as f64 * dt);
    let bins = ((f_max / df).floor() as usize).min(n / 2);
    let mut freqs = Vec::with_capacity(bins + 1);
    let mut amps = Vec::with_capacity(bins + 1);
    for k in 0..=bins {
        let c = dft_bin(x, &w, k, n);
        let scale = if k == 0 { 1.0 } else { 2.0 };
        freqs.push(k as f64 * df);
        amps.push(scale * c.norm() / wsum);
    }
    (freqs, amps)
}

/// Welch-averaged amplitude spectrum: the RMS over Hann segments of `segment` samples (50 %
/// overlap) of the amplitude spectrum of [`amplitude_spectrum`]; smoother than one DFT of the
/// whole record, with resolution `1/(segment·dt)`. Returns `(frequency [Hz], amplitude)`.
pub fn averaged_amplitude_spectrum(x: &[f64], dt: f64, segment: usize, f_max: f64) -> (Vec<f64>, Vec<f64>) {
    if segment < 8 || x.len() < segment {
        return amplitude_spectrum(x, dt, f_max);
    }
    let mut freqs = Vec::new();
    let mut acc: Vec<f64> = Vec::new();
    let mut count = 0usize;
    let mut start = 0;
    while start + segment <= x.len() {
        let (f, a) = amplitude_spectrum(&x[start..start + segment], dt, f_max);
        if acc.is_empty() {
            acc = vec![0.0; a.len()];
            freqs = f;
        }
        for (s, v) in acc.iter_mut().zip(&a) {
            *s += v * v;
        }
        count += 1;
        start += segment / 2;
    }
    (freqs, acc.into_iter().map(|s| (s / count as f64).sqrt()).collect())
}

fn dft_bin(x: &[f64], w: &[f64], k: usize, n: usize) -> Complex<f64> {
    let step = -2.0 * PI * k as f64 / n as f64;
    let (mut re, mut im) = (0.0, 0.0);
    for (i, (&v, &wi)) in x.iter().zip(w).enumerate() {
        let a = step * i as f64;
        re += wi * v * a.cos();
        im += wi * v * a.sin();
    }
    Complex::new(re, im)
}

/// Welch estimate of the magnitude-squared coherence `|S_xy|² / (S_xx S_yy)` of `x` and `y`
/// (sampled at `dt`), Hann segments of `segment` samples (mean removed) with 50 % overlap: the
/// plain mean over the bins in `[f_lo, f_hi]` whose `S_yy` is above 1 % of its largest value in
/// the band (bins where the reference `y` has no content do not dilute the mean). NaN if there
/// is not enough data.
pub fn band_coherence(x: &[f64], y: &[f64], dt: f64, segment: usize, f_lo: f64, f_hi: f64) -> f64 {
    let n = x.len().min(y.len());
    if segment < 8 || n < segment || dt.is_nan() || dt <= 0.0 {
        return f64::NAN;
    }
    let hop = segment / 2;
    let w: Vec<f64> = (0..segment)
        .map(|i| 0.5 - 0.5 * (2.0 * PI * i as f64 / segment as f64).cos())
        .collect();
    let df = 1.0 / (segment as f64 * dt);
    let k0 = (f_lo / df).ceil().max(1.0) as usize;
    let k1 = ((f_hi / df).floor() as usize).min(segment / 2);
    if k1 < k0 {
        return f64::NAN;
    }
    let nb = k1 - k0 + 1;
    let (mut sxx, mut syy) = (vec![0.0; nb], vec![0.0; nb]);
    let mut sxy = vec![Complex::new(0.0, 0.0); nb];
    let mut start = 0;
    while start + segment <= n {
        let (xs, ys) = (&x[start..start + segment], &y[start..start + segment]);
        let mx = xs.iter().sum::<f64>() / segment as f64;
        let my = ys.iter().sum::<f64>() / segment as f64;
        let xd: Vec<f64> = xs.iter().map(|v| v - mx).collect();
        let yd: Vec<f64> = ys.iter().map(|v| v - my).collect();
        for b in 0..nb {
            let cx = dft_bin(&xd, &w, k0 + b, segment);
            let cy = dft_bin(&yd, &w, k0 + b, segment);
            sxx[b] += cx.norm_sqr();
            syy[b] += cy.norm_sqr();
            sxy[b] += cx * cy.conj();
        }
        start += hop;
    }
    let peak = syy.iter().copied().fold(0.0, f64::max);
    let (mut sum, mut count) = (0.0, 0usize);
    for b in 0..nb {
        if syy[b] > 0.01 * peak && sxx[b] > 0.0 {
            sum += sxy[b].norm_sqr() / (sxx[b] * syy[b]);
            count += 1;
        }
    }
    if count == 0 { f64::NAN } else { sum / count as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spectrum_finds_a_sine() {
        let dt = 0.01;
        let x: Vec<f64> = (0..1000)
            .map(|i| 3.0 * (2.0 * PI * 2.0 * i as f64 * dt).sin())
            .collect();
        let (f, a) = amplitude_spectrum(&x, dt, 10.0);
        let (k, peak) = a
            .iter()
            .enumerate()
            .fold((0, 0.0), |b, (k, &v)| if v > b.1 { (k, v) } else { b });
        assert!((f[k] - 2.0).abs() < 1e-9, "{}", f[k]);
        assert!((peak - 3.0).abs() < 0.05, "{peak}");
    }

    #[test]
    fn coherence_of_identical_and_independent_signals() {
        let dt = 0.01;
        let s: Vec<f64> = (0..4000).map(|i| (2.0 * PI * 1.3 * i as f64 * dt).sin()).collect();
        assert!((band_coherence(&s, &s, dt, 512, 0.5, 3.0) - 1.0).abs() < 1e-9);
        // A deterministic pseudo-random sequence is nearly incoherent with the sine.
        let mut v = 1u64;
        let noise: Vec<f64> = (0..4000)
            .map(|_| {
                v = v.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (v >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect();
        assert!(band_coherence(&noise, &s, dt, 512, 0.5, 3.0) < 0.3);
    }
}
