//! Synthetic ground motions: harmonic, linear sine sweep and Kanai–Tajimi filtered white noise.
//!
//! All generators sample `t_k = k·dt` for `k = 0..=floor(duration/dt + 1e-9)` and need at least
//! two samples. Frequencies must lie below the Nyquist frequency `1/(2 dt)` (Hz) or `π/dt`
//! (rad/s).

use super::Record;
use super::record::sample_count;
use crate::error::{Error, Result, require_non_negative, require_positive};
use nalgebra::Matrix3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use std::f64::consts::PI;

/// Validate `duration` and `dt` (`what.duration`, `what.dt`) and return the number of samples.
fn grid(what: &str, duration: f64, dt: f64) -> Result<usize> {
    let dt = require_positive(&format!("{what}.dt"), dt)?;
    let duration = require_positive(&format!("{what}.duration"), duration)?;
    let n = sample_count(what, duration, dt)?;
    if n < 2 {
        return Err(Error::invalid(
            format!("{what}.duration"),
            format!("must be at least dt = {dt} s, got {duration}"),
        ));
    }
    Ok(n)
}

fn require_finite(what: &str, value: f64) -> Result<f64> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(Error::invalid(what, format!("must be a finite number, got {value}")))
    }
}

/// Check that a frequency in Hz lies below the Nyquist frequency of `dt`.
fn require_below_nyquist(what: &str, f_hz: f64, dt: f64) -> Result<()> {
    let nyquist = 0.5 / dt;
    if f_hz < nyquist {
        Ok(())
    } else {
        Err(Error::invalid(
            what,
            format!("must be below the Nyquist frequency 1/(2 dt) = {nyquist} Hz, got {f_hz}"),
        ))
    }
}

/// `a_g(t) = A sin(2π f t)` in m/s² (`amplitude` A in m/s², `frequency_hz` f > 0 in Hz).
pub fn harmonic(amplitude: f64, frequency_hz: f64, duration: f64, dt: f64) -> Result<Record> {
    let n = grid("harmonic", duration, dt)?;
    let amplitude = require_finite("harmonic.amplitude", amplitude)?;
    let f = require_positive("harmonic.frequency_hz", frequency_hz)?;
    require_below_nyquist("harmonic.frequency_hz", f, dt)?;
    let accel = (0..n)
        .map(|k| amplitude * (2.0 * PI * f * k as f64 * dt).sin())
        .collect();
    Ok(Record { dt, accel })
}

/// Linear sine sweep from `f0_hz` at `t = 0` to `f1_hz` at `t = duration` (either may be the
/// larger): `a_g = A sin φ(t)`, `φ(t) = 2π (f0 t + (f1 − f0) t²/(2T))`, so that the instantaneous
/// frequency is `f0 + (f1 − f0) t/T`.
pub fn sine_sweep(amplitude: f64, f0_hz: f64, f1_hz: f64, duration: f64, dt: f64) -> Result<Record> {
    let n = grid("sine_sweep", duration, dt)?;
    let amplitude = require_finite("sine_sweep.amplitude", amplitude)?;
    let f0 = require_non_negative("sine_sweep.f0_hz", f0_hz)?;
    let f1 = require_non_negative("sine_sweep.f1_hz", f1_hz)?;
    require_below_nyquist("sine_sweep.f0_hz", f0, dt)?;
    require_below_nyquist("sine_sweep.f1_hz", f1, dt)?;
    let rate = (f1 - f0) / (2.0 * duration);
    let accel = (0..n)
        .map(|k| {
            let t = k as f64 * dt;
            amplitude * (2.0 * PI * t * (f0 + rate * t)).sin()
        })
        .collect();
    Ok(Record { dt, accel })
}

/// Amplitude envelope `e(t) ∈ [0, 1]` of a stochastic record.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Envelope {
    /// `e(t) = 1` (stationary record, apart from the filter starting at rest).
    #[default]
    None,
    /// Linear ramp from 0 to 1 over `rise` s, 1 for `hold` s, then linear decay to 0 at the
    /// end of the record. Requires `rise, hold >= 0` and `rise + hold <= duration`.
    Trapezoid { rise: f64, hold: f64 },
}

impl Envelope {
    /// The factor `e(t)` for a record of the given duration (clamped to `[0, 1]`).
    pub fn factor(&self, t: f64, duration: f64) -> f64 {
        match *self {
            Envelope::None => 1.0,
            Envelope::Trapezoid { rise, hold } => {
                let e = if t < rise {
                    t / rise
                } else if t <= rise + hold {
                    1.0
                } else {
                    let decay = duration - rise - hold;
                    if decay > 0.0 { (duration - t) / decay } else { 1.0 }
                };
                e.clamp(0.0, 1.0)
            }
        }
    }

    fn validate(&self, what: &str, duration: f64) -> Result<()> {
        if let Envelope::Trapezoid { rise, hold } = *self {
            require_non_negative(&format!("{what}.rise"), rise)?;
            require_non_negative(&format!("{what}.hold"), hold)?;
            if rise + hold > duration * (1.0 + 1e-12) {
                return Err(Error::invalid(
                    what,
                    format!("rise + hold = {} s exceeds the duration {duration} s", rise + hold),
                ));
            }
        }
        Ok(())
    }
}

/// Parameters of [`kanai_tajimi`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KanaiTajimi {
    /// If given, the record is scaled so that `max |a_g|` equals it (m/s², > 0). If `None`, the
    /// white noise has the unit two-sided spectral density `S₀ = 1 m²/s³`.
    pub pga_target: Option<f64>,
    /// Ground filter circular frequency `ω_g` in rad/s (> 0, below `π/dt`).
    pub omega_g: f64,
    /// Ground filter damping ratio `ζ_g` (> 0).
    pub zeta_g: f64,
    /// Record duration in s.
    pub duration: f64,
    /// Time step in s.
    pub dt: f64,
    /// Seed of the `ChaCha8Rng` noise generator; equal seeds give identical records.
    pub seed: u64,
    /// Amplitude envelope applied to the filter output.
    pub envelope: Envelope,
}

impl KanaiTajimi {
    /// Stationary standard deviation of `a_g` for white noise of two-sided spectral density
    /// `S₀ = 1 m²/s³` and no envelope: `σ² = π S₀ ω_g (1 + 4ζ_g²) / (2 ζ_g)` (continuous filter;
    /// the discrete record matches it up to the sampling of the noise, see [`kanai_tajimi`]).
    pub fn stationary_std(&self) -> f64 {
        let (w, z) = (self.omega_g, self.zeta_g);
        (PI * w * (1.0 + 4.0 * z * z) / (2.0 * z)).sqrt()
    }
}

/// Kanai–Tajimi filtered Gaussian white noise.
///
/// The ground filter `ẍ_f + 2ζ_g ω_g ẋ_f + ω_g² x_f = −w(t)` starts at rest and is driven by
/// white noise `w` held constant over each step (`w_k = σ_w ξ_k`, `ξ_k` standard normal from
/// `ChaCha8Rng::seed_from_u64(seed)`, `σ_w² = 2π S₀/dt` with `S₀ = 1 m²/s³`, i.e. two-sided
/// spectral density `S₀` below the Nyquist frequency). It is advanced with its exact
/// zero-order-hold discretisation. The record is the filter's absolute acceleration
/// `a_g = −(2ζ_g ω_g ẋ_f + ω_g² x_f)` (so `a_g(0) = 0`), multiplied by the envelope `e(t)`, and
/// finally scaled to `pga_target` if given.
pub fn kanai_tajimi(params: KanaiTajimi) -> Result<Record> {
    let KanaiTajimi {
        pga_target,
        omega_g,
        zeta_g,
        duration,
        dt,
        seed,
        envelope,
    } = params;
    let n = grid("kanai_tajimi", duration, dt)?;
    let w = require_positive("kanai_tajimi.omega_g", omega_g)?;
    let z = require_positive("kanai_tajimi.zeta_g", zeta_g)?;
    if w * dt >= PI {
        return Err(Error::invalid(
            "kanai_tajimi.omega_g",
            format!("must be below the Nyquist frequency π/dt = {} rad/s, got {w}", PI / dt),
        ));
    }
    if let Some(pga) = pga_target {
        require_positive("kanai_tajimi.pga_target", pga)?;
    }
    envelope.validate("kanai_tajimi.envelope", duration)?;

    // Exact ZOH step of ż = A z + B w_k, z = [x_f, ẋ_f]: exp(dt [[A, B], [0, 0]]) = [[Φ, Γ], [0, 1]].
    let e = Matrix3::new(0.0, dt, 0.0, -w * w * dt, -2.0 * z * w * dt, -dt, 0.0, 0.0, 0.0).exp();
    let (p00, p01, p10, p11) = (e[(0, 0)], e[(0, 1)], e[(1, 0)], e[(1, 1)]);
    let (g0, g1) = (e[(0, 2)], e[(1, 2)]);
    let sigma = (2.0 * PI / dt).sqrt();

    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut x, mut v) = (0.0, 0.0);
    let mut accel = Vec::with_capacity(n);
    for k in 0..n {
        let t = k as f64 * dt;
        accel.push(-(2.0 * z * w * v + w * w * x) * envelope.factor(t, duration));
        let wk = sigma * rng.sample::<f64, _>(StandardNormal);
        (x, v) = (p00 * x + p01 * v + g0 * wk, p10 * x + p11 * v + g1 * wk);
    }

    if let Some(target) = pga_target {
        let (i_max, peak) = accel.iter().enumerate().fold(
            (0, 0.0),
            |(im, m), (i, a)| {
                if a.abs() > m { (i, a.abs()) } else { (im, m) }
            },
        );
        if !(peak > 0.0 && peak.is_finite()) {
            return Err(Error::numerical(
                "kanai_tajimi",
                format!("cannot scale a record with peak {peak} to pga_target"),
            ));
        }
        let factor = target / peak;
        accel.iter_mut().for_each(|a| *a *= factor);
        accel[i_max] = target.copysign(accel[i_max]);
    }
    Ok(Record { dt, accel })
}
