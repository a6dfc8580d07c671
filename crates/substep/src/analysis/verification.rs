//! The verification study of docs/theory.md §9.6 (`substep analyze verify`): stepped-sine
//! sweeps against the peaks of the discrete frequency response, free-vibration runs inside, on
//! and outside the stability boundary against the spectral radius, and error-force compensation
//! moving an unstable point into the stable region. The primitives are in [`super::verify`].

use super::frequency::{DiscreteResponse, Peak, exact_amplification, find_peaks};
use super::verify::{free_vibration_growth, stepped_sine_sweep};
use super::{AnalysisCase, Parameter, Stability};
use crate::error::Result;
use crate::substructure::ErrorForceSpec;
use rayon::prelude::*;

/// Which checks to run (the default: the set of `substep analyze verify`).
#[derive(Debug, Clone, PartialEq)]
pub struct VerifySettings {
    /// Cases whose frequency-domain peaks are checked by stepped-sine sweeps.
    pub sweeps: Vec<(String, AnalysisCase)>,
    /// Resolution `Δr` of the sweeps around each peak (±16 points).
    pub sweep_step: f64,
    /// Cases whose stability boundary (in `Ω`) is checked inside, on and outside.
    pub boundaries: Vec<(String, AnalysisCase)>,
    /// Free-vibration steps of the boundary checks.
    pub boundary_steps: usize,
    /// An unstable point checked without and with each compensation.
    pub compensated: AnalysisCase,
    pub compensations: Vec<(String, ErrorForceSpec)>,
    /// Free-vibration steps of the compensation checks.
    pub compensation_steps: usize,
    /// Band around 1 of the stability classes, for `ρ` and for the growth.
    pub band: f64,
}

impl Default for VerifySettings {
    fn default() -> Self {
        let typical = |k_sub, eta_p| {
            AnalysisCase {
                k_sub,
                eta_p,
                ..AnalysisCase::typical_tmd()
            }
            .with(Parameter::EtaT, 0.02)
        };
        Self {
            sweeps: vec![
                ("typical".into(), typical(1, 0.0)),
                ("typical".into(), typical(4, 0.0)),
                ("typical".into(), typical(2, 0.5)),
                (
                    "large_mass_ratio".into(),
                    AnalysisCase {
                        k_sub: 2,
                        ..AnalysisCase::large_mass_ratio()
                    }
                    .with(Parameter::EtaT, 0.02),
                ),
            ],
            sweep_step: 0.005,
            boundaries: vec![
                (
                    "typical, ζ_s = 2 %".into(),
                    AnalysisCase {
                        k_sub: 1,
                        zeta_s: 0.02,
                        ..AnalysisCase::typical_tmd()
                    },
                ),
                (
                    "large_mass_ratio".into(),
                    AnalysisCase {
                        k_sub: 1,
                        ..AnalysisCase::large_mass_ratio()
                    },
                ),
                (
                    "large_mass_ratio".into(),
                    AnalysisCase {
                        k_sub: 2,
                        ..AnalysisCase::large_mass_ratio()
                    },
                ),
                (
                    "typical, ζ_s = 2 %, η_p = 1".into(),
                    AnalysisCase {
                        k_sub: 2,
                        zeta_s: 0.02,
                        eta_p: 1.0,
                        ..AnalysisCase::typical_tmd()
                    },
                ),
            ],
            boundary_steps: 4000,
            compensated: AnalysisCase {
                zeta: 0.0,
                zeta_s: 0.1,
                omega_dt: 0.628,
                k_sub: 1,
                ..AnalysisCase::large_mass_ratio()
            },
            compensations: vec![
                ("none".into(), ErrorForceSpec::None),
                ("PID P = 1".into(), ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 }),
            ],
            compensation_steps: 2000,
            band: 1e-3,
        }
    }
}

/// One peak of a sweep case: frequency domain, time domain (sweep) and exact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepCheck {
    /// 1-based peak number.
    pub peak: usize,
    pub frequency_domain: Peak,
    pub sweep: Peak,
    /// The exact 2-DOF peak of the same number (NaN if it has fewer peaks).
    pub exact: Peak,
    /// Sweep and frequency domain agree: `r` within one sweep step, `h` within 0.2 %.
    pub agrees: bool,
}

/// A sweep case and its peaks.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepCase {
    pub name: String,
    pub case: AnalysisCase,
    pub peaks: Vec<SweepCheck>,
}

/// A free-vibration run against the spectral radius.
#[derive(Debug, Clone, PartialEq)]
pub struct GrowthCheck {
    /// `inside`, `on` or `outside` (boundary checks) or the compensation's name.
    pub label: String,
    pub omega_dt: f64,
    pub rho: f64,
    pub predicted: Stability,
    /// Growth per step measured in the time domain ([`free_vibration_growth`]).
    pub growth: f64,
    pub observed: Stability,
    pub agrees: bool,
}

/// A boundary case: the critical `Ω` (`None`: no boundary in `(0, π]`) and the checks at
/// 0.7, 1 and 1.3 times it.
#[derive(Debug, Clone, PartialEq)]
pub struct BoundaryCase {
    pub name: String,
    pub case: AnalysisCase,
    pub omega_cr: Option<f64>,
    pub checks: Vec<GrowthCheck>,
}

/// The results of [`verify_analysis`].
#[derive(Debug, Clone, PartialEq)]
pub struct Verification {
    pub sweeps: Vec<SweepCase>,
    pub boundaries: Vec<BoundaryCase>,
    pub compensation: Vec<GrowthCheck>,
    /// Every check agrees.
    pub all_agree: bool,
}

/// One check as a row of `verify.csv` (and of `substep.analyze.verify()` in Python).
#[derive(Debug, Clone, PartialEq)]
pub struct VerifyRow {
    /// `sweep_peak`, `boundary_inside` / `boundary_on` / `boundary_outside`, or `pid` (the
    /// compensation checks).
    pub check: String,
    /// The case's name (for `pid`: the compensation's label).
    pub case: String,
    pub k_sub: usize,
    /// `Ω = ω Δt` of the point.
    pub omega_dt: f64,
    pub eta_p: f64,
    /// `peak1_r`, `peak2_r`, … (the peak's frequency ratio) or `growth` (per step).
    pub quantity: String,
    /// Frequency-domain value: the peak's `r`, or the spectral radius `ρ`.
    pub frequency_domain: f64,
    /// Time-domain value: the sweep's peak `r`, or the free-vibration growth per step.
    pub time_domain: f64,
    pub agrees: bool,
}

impl Verification {
    /// Every check as one row, in the order of the report: sweep peaks, boundary checks (none
    /// for a case without a boundary), compensation checks (`settings` gives their point).
    pub fn rows(&self, settings: &VerifySettings) -> Vec<VerifyRow> {
        let mut rows = Vec::new();
        for s in &self.sweeps {
            for p in &s.peaks {
                rows.push(VerifyRow {
                    check: "sweep_peak".into(),
                    case: s.name.clone(),
                    k_sub: s.case.k_sub,
                    omega_dt: s.case.omega_dt,
                    eta_p: s.case.eta_p,
                    quantity: format!("peak{}_r", p.peak),
                    frequency_domain: p.frequency_domain.freq_ratio,
                    time_domain: p.sweep.freq_ratio,
                    agrees: p.agrees,
                });
            }
        }
        for b in &self.boundaries {
            for g in &b.checks {
                rows.push(VerifyRow {
                    check: format!("boundary_{}", g.label),
                    case: b.name.clone(),
                    k_sub: b.case.k_sub,
                    omega_dt: g.omega_dt,
                    eta_p: b.case.eta_p,
                    quantity: "growth".into(),
                    frequency_domain: g.rho,
                    time_domain: g.growth,
                    agrees: g.agrees,
                });
            }
        }
        let c = &settings.compensated;
        for g in &self.compensation {
            rows.push(VerifyRow {
                check: "pid".into(),
                case: g.label.clone(),
                k_sub: c.k_sub,
                omega_dt: c.omega_dt,
                eta_p: c.eta_p,
                quantity: "growth".into(),
                frequency_domain: g.rho,
                time_domain: g.growth,
                agrees: g.agrees,
            });
        }
        rows
    }
}

/// Run the checks of `settings`.
///
/// ```
/// use substep::analysis::verification::{VerifySettings, verify_analysis};
/// // The compensation check alone (no sweeps, no boundaries) keeps the example fast.
/// let settings = VerifySettings { sweeps: vec![], boundaries: vec![], ..VerifySettings::default() };
/// let v = verify_analysis(&settings).unwrap();
/// assert_eq!(v.compensation.len(), 2);
/// assert!(v.compensation[0].rho > 1.0 && v.compensation[1].rho < 1.0);
/// assert!(v.all_agree);
/// ```
pub fn verify_analysis(settings: &VerifySettings) -> Result<Verification> {
    let step = settings.sweep_step;
    let mut all_agree = true;
    let mut sweeps = Vec::new();
    for (name, c) in &settings.sweeps {
        let resp = DiscreteResponse::new(c)?;
        let fd = find_peaks(|r| resp.amplification(r), 0.05, 3.0, 1500);
        let exact = find_peaks(|r| exact_amplification(c, r).unwrap_or(f64::NAN), 0.05, 3.0, 1500);
        let settle = (60.0 / c.omega_dt).ceil() as usize * 10;
        let td: Vec<Peak> = fd
            .par_iter()
            .map(|p| {
                let ratios: Vec<f64> = (-16..=16).map(|i| p.freq_ratio + step * i as f64).collect();
                let (_, peaks) = stepped_sine_sweep(c, &ratios, settle, settle / 3)?;
                // the largest local maximum of this window is the sweep's peak
                Ok(peaks.into_iter().max_by(|x, y| x.h.total_cmp(&y.h)).unwrap_or(NAN_PEAK))
            })
            .collect::<Result<Vec<_>>>()?;
        let peaks = fd
            .iter()
            .zip(&td)
            .enumerate()
            .map(|(i, (f, t))| {
                let agrees = (t.freq_ratio - f.freq_ratio).abs() <= step + 1e-12 && (t.h - f.h).abs() <= 2e-3 * f.h;
                all_agree &= agrees;
                SweepCheck {
                    peak: i + 1,
                    frequency_domain: *f,
                    sweep: *t,
                    exact: exact.get(i).copied().unwrap_or(NAN_PEAK),
                    agrees,
                }
            })
            .collect();
        sweeps.push(SweepCase {
            name: name.clone(),
            case: *c,
            peaks,
        });
    }
    let band = settings.band;
    let mut check = |label: &str, case: AnalysisCase, steps: usize| -> Result<GrowthCheck> {
        let rho = case.spectral_radius()?;
        let growth = free_vibration_growth(&case, steps)?;
        let (predicted, observed) = (Stability::classify(rho, band), Stability::classify(growth, band));
        let agrees = predicted == observed;
        all_agree &= agrees;
        Ok(GrowthCheck {
            label: label.into(),
            omega_dt: case.omega_dt,
            rho,
            predicted,
            growth,
            observed,
            agrees,
        })
    };
    let mut boundaries = Vec::new();
    for (name, c) in &settings.boundaries {
        let omega_cr = boundary(c)?;
        let mut checks = Vec::new();
        if let Some(w_cr) = omega_cr {
            for (label, w) in [("inside", 0.7 * w_cr), ("on", w_cr), ("outside", 1.3 * w_cr)] {
                checks.push(check(
                    label,
                    AnalysisCase { omega_dt: w, ..*c },
                    settings.boundary_steps,
                )?);
            }
        }
        boundaries.push(BoundaryCase {
            name: name.clone(),
            case: *c,
            omega_cr,
            checks,
        });
    }
    let compensation = settings
        .compensations
        .iter()
        .map(|(label, ef)| {
            let case = AnalysisCase {
                error_force: *ef,
                ..settings.compensated
            };
            check(label, case, settings.compensation_steps)
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Verification {
        sweeps,
        boundaries,
        compensation,
        all_agree,
    })
}

const NAN_PEAK: Peak = Peak {
    freq_ratio: f64::NAN,
    h: f64::NAN,
};

/// The smallest Ω in (0, π] with ρ = 1 (scan, then bisection), if any.
pub fn boundary(c: &AnalysisCase) -> Result<Option<f64>> {
    let rho = |w: f64| AnalysisCase { omega_dt: w, ..*c }.spectral_radius();
    let grid: Vec<f64> = (1..=100).map(|i| std::f64::consts::PI * i as f64 / 100.0).collect();
    let mut prev = (grid[0], rho(grid[0])?);
    if prev.1 > 1.0 {
        return Ok(None);
    }
    for &w in &grid[1..] {
        let r = rho(w)?;
        if r > 1.0 {
            let (mut lo, mut hi) = (prev.0, w);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if rho(mid)? > 1.0 { hi = mid } else { lo = mid }
            }
            return Ok(Some(0.5 * (lo + hi)));
        }
        prev = (w, r);
    }
    Ok(None)
}
