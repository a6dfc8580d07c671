//! Response spectrum and Fourier amplitude of a ground motion.
//!
//! The elastic response spectrum is the peak response of a linear SDOF oscillator of period `T`
//! and damping ratio `ζ` (5 % by convention), relative to the ground:
//! `ü + 2ζω u̇ + ω² u = −a_g(t)`, `ω = 2π/T`, from rest. The record is linear between samples
//! (the convention of [`Record`](super::Record)), and each step is integrated exactly for that
//! piecewise-linear load (first-order-hold map, [`FohMap`]), so the spectrum has no
//! integration error beyond the sampling of the record (the Nigam–Jennings approach). Peaks are
//! taken at the samples. For each period it gives
//!
//! * `S_d = max |u|` \[m\], pseudo-velocity `PS_v = ω S_d` [m/s], pseudo-acceleration
//!   `PS_a = ω² S_d` [m/s²],
//! * the peak absolute acceleration `S_a = max |ü + a_g| = max |2ζω u̇ + ω² u|` [m/s²].
//!
//! The Fourier amplitude is [`amplitude_spectrum`](crate::analysis::spectral::amplitude_spectrum)
//! of the record (Hann window, amplitude-corrected).

use crate::error::{Result, require_non_negative, require_positive};
use crate::integrate::FohMap;
use nalgebra::DMatrix;
use std::f64::consts::PI;

/// Peak responses of one oscillator.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SpectralOrdinate {
    /// Period `T` \[s\].
    pub period: f64,
    /// Spectral displacement `S_d` \[m\].
    pub sd: f64,
    /// Pseudo-velocity `ω S_d` [m/s].
    pub psv: f64,
    /// Pseudo-acceleration `ω² S_d` [m/s²].
    pub psa: f64,
    /// Peak absolute acceleration [m/s²].
    pub sa: f64,
}

/// Peak response of one damped SDOF oscillator to `accel` sampled at `dt` (see module docs).
pub fn sdof_peak(accel: &[f64], dt: f64, period: f64, zeta: f64) -> Result<SpectralOrdinate> {
    require_positive("response spectrum dt", dt)?;
    require_positive("response spectrum period", period)?;
    require_non_negative("response spectrum damping ratio", zeta)?;
    let w = 2.0 * PI / period;
    let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -w * w, -2.0 * zeta * w]);
    let b = DMatrix::from_row_slice(2, 1, &[0.0, -1.0]);
    let map = FohMap::new(&a, &b, dt)?;
    let (p, g0, g1) = (&map.phi, &map.gamma0, &map.gamma1);
    let (mut u, mut v) = (0.0_f64, 0.0_f64);
    let (mut sd, mut sa) = (0.0_f64, 0.0_f64);
    for pair in accel.windows(2) {
        let (f0, df) = (pair[0], pair[1] - pair[0]);
        let un = p[(0, 0)] * u + p[(0, 1)] * v + g0[(0, 0)] * f0 + g1[(0, 0)] * df;
        let vn = p[(1, 0)] * u + p[(1, 1)] * v + g0[(1, 0)] * f0 + g1[(1, 0)] * df;
        u = un;
        v = vn;
        sd = sd.max(u.abs());
        sa = sa.max((2.0 * zeta * w * v + w * w * u).abs());
    }
    Ok(SpectralOrdinate {
        period,
        sd,
        psv: w * sd,
        psa: w * w * sd,
        sa,
    })
}

/// The response spectrum at `periods` (each > 0).
pub fn response_spectrum(accel: &[f64], dt: f64, periods: &[f64], zeta: f64) -> Result<Vec<SpectralOrdinate>> {
    periods.iter().map(|&t| sdof_peak(accel, dt, t, zeta)).collect()
}

/// `count` periods spaced logarithmically from `t_min` to `t_max` (both > 0, `count ≥ 2`).
pub fn log_periods(t_min: f64, t_max: f64, count: usize) -> Vec<f64> {
    let count = count.max(2);
    let (a, b) = (t_min.ln(), t_max.ln());
    (0..count)
        .map(|i| (a + (b - a) * i as f64 / (count - 1) as f64).exp())
        .collect()
}
