//! Time-domain verification of the analysis (docs/theory.md §9.6): steady-state harmonic runs against the
//! discrete frequency response, and free-vibration growth against the spectral radius.

use super::AnalysisCase;
use crate::error::Result;
use std::f64::consts::PI;

/// Amplification `h = |u₁| ω²/|a_g|` measured in the time domain: the analysis model is driven
/// by `a_g = sin(r t)` (dimensionless, `ω = 1`) until the transient has decayed to
/// `settle` (relative), then the Fourier coefficient of `u₁` at the excitation frequency is
/// taken over an integer number of excitation periods.
pub fn harmonic_amplification(case: &AnalysisCase, r: f64, settle_steps: usize, measure_steps: usize) -> Result<f64> {
    let mut test = case.build_test()?;
    let dt = case.dt();
    let w = r; // excitation frequency, ω = 1
    let ag = |i: usize| (w * i as f64 * dt).sin();
    for i in 0..settle_steps {
        test.step(ag(i), ag(i + 1), &mut ())?;
    }
    // integer number of periods in the measuring window (as close as the grid allows)
    let period_steps = 2.0 * PI / (w * dt);
    let periods = (measure_steps as f64 / period_steps).floor().max(1.0);
    let n = (periods * period_steps).round() as usize;
    let (mut s, mut c) = (0.0, 0.0);
    for i in settle_steps..settle_steps + n {
        test.step(ag(i), ag(i + 1), &mut ())?;
        let t = (i + 1) as f64 * dt;
        let u = test.controller.state().u[0];
        s += u * (w * t).sin();
        c += u * (w * t).cos();
    }
    Ok(2.0 * (s * s + c * c).sqrt() / n as f64)
}

/// Growth per step of a free vibration started by a ground-acceleration pulse: the ratio of
/// the peak |u₁| in the last quarter of `steps` to that in the second quarter, to the power
/// `1/(steps/2)`. About `ρ` when one mode pair dominates.
pub fn free_vibration_growth(case: &AnalysisCase, steps: usize) -> Result<f64> {
    let mut test = case.build_test()?;
    let mut u = Vec::with_capacity(steps);
    for i in 0..steps {
        let (ag0, ag1) = (if i == 1 { 1.0 } else { 0.0 }, if i == 0 { 1.0 } else { 0.0 });
        match test.step(ag0, ag1, &mut ()) {
            Ok(()) => u.push(test.controller.state().u[0]),
            Err(_) => return Ok(f64::INFINITY),
        }
    }
    let q = steps / 4;
    let peak = |a: usize, b: usize| u[a..b].iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let (early, late) = (peak(q, 2 * q), peak(3 * q, steps));
    if early == 0.0 {
        return Ok(0.0);
    }
    Ok((late / early).powf(1.0 / (2 * q) as f64))
}

/// A stepped-sine sweep: [`harmonic_amplification`] on each frequency ratio of `ratios`
/// (ascending); returns the curve and its (up to two, largest) local maxima as
/// [`super::frequency::Peak`]s, located to the grid's resolution.
pub fn stepped_sine_sweep(
    case: &AnalysisCase,
    ratios: &[f64],
    settle_steps: usize,
    measure_steps: usize,
) -> Result<(Vec<f64>, Vec<super::frequency::Peak>)> {
    let h = ratios
        .iter()
        .map(|&r| harmonic_amplification(case, r, settle_steps, measure_steps))
        .collect::<Result<Vec<f64>>>()?;
    let mut maxima: Vec<usize> = (1..h.len().saturating_sub(1))
        .filter(|&i| h[i] > h[i - 1] && h[i] >= h[i + 1])
        .collect();
    maxima.sort_by(|&a, &b| h[b].total_cmp(&h[a]));
    maxima.truncate(2);
    maxima.sort_unstable();
    let peaks = maxima
        .iter()
        .map(|&i| super::frequency::Peak {
            freq_ratio: ratios[i],
            h: h[i],
        })
        .collect();
    Ok((h, peaks))
}
