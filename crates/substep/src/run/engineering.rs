//! Engineering quantities recorded during a run (dense models up to [`MAX_DOFS`] DOFs): absolute
//! accelerations, inter-storey drifts, storey and base shear, and the energy balance per step
//! (the rows of `response.csv`), their peaks for the summary, and the input motion's PGA and
//! 5 % response spectrum. The numerics are `analysis::energy`, `analysis::storey` and
//! `excitation::spectrum`; this module only records.

use super::simulation::Simulation;
use crate::analysis::energy::{EnergyBalance, EnergyTerms};
use crate::analysis::spectral::amplitude_spectrum;
use crate::analysis::storey::StoreyResponse;
use crate::error::Result;
use crate::excitation::spectrum::{SpectralOrdinate, log_periods, response_spectrum};
use crate::format::round_time;
use crate::io::TestDefinition;
use serde::Serialize;

/// Largest model for which the per-step engineering quantities are computed (dense products
/// per step; larger models are benchmarks, not buildings to report on).
pub const MAX_DOFS: usize = 200;
/// Damping ratio of the response spectrum.
pub const SPECTRUM_ZETA: f64 = 0.05;

/// Per-step engineering quantities of a dense model of at most [`MAX_DOFS`] DOFs.
pub struct EngineeringRecorder {
    energy: EnergyBalance,
    storey: StoreyResponse,
    coupling: Vec<usize>,
    force: Vec<f64>,
    /// The springs' deviation force of a nonlinear model (work vector).
    deviation: Vec<f64>,
    ag: f64,
    peak_abs: Vec<(f64, f64)>,
    peak_drift: Vec<(f64, f64)>,
    peak_shear: Vec<(f64, f64)>,
    peak_base: (f64, f64),
}

/// One row of `response.csv`.
#[derive(Debug, Clone, Copy)]
pub struct EngineeringRow<'a> {
    pub t: f64,
    pub ag: f64,
    pub absolute_acceleration: &'a [f64],
    /// Empty unless the model is a shear chain.
    pub drift: &'a [f64],
    /// Empty unless the model is a shear chain.
    pub storey_shear: &'a [f64],
    pub base_shear: f64,
    pub energy: EnergyTerms,
    /// `E_K + E_S + E_D − E_I − E_C` \[J\].
    pub energy_error: f64,
}

impl EngineeringRow<'_> {
    /// The values in the order of [`EngineeringRecorder::columns`] (time rounded to 1 ns).
    pub fn values(&self) -> impl Iterator<Item = f64> + '_ {
        let e = self.energy;
        [round_time(self.t), self.ag]
            .into_iter()
            .chain(self.absolute_acceleration.iter().copied())
            .chain(self.drift.iter().copied())
            .chain(self.storey_shear.iter().copied())
            .chain([
                self.base_shear,
                e.input,
                e.kinetic,
                e.damping,
                e.strain,
                e.coupling,
                self.energy_error,
            ])
    }
}

/// Energy at the end of the run \[J\] (`summary.json` → `engineering.energy_J`).
#[derive(Debug, Clone, Serialize)]
pub struct EnergySummary {
    pub coupling: f64,
    pub damping: f64,
    pub error: f64,
    pub input: f64,
    pub kinetic: f64,
    pub strain: f64,
}

/// A peak of one storey or DOF (1-based).
#[derive(Debug, Clone, Serialize)]
pub struct StoreyPeak {
    pub dof: usize,
    pub peak: f64,
    pub t: f64,
}

/// A peak and its time.
#[derive(Debug, Clone, Serialize)]
pub struct PeakAt {
    pub peak: f64,
    pub t: f64,
}

/// The `engineering` block of `summary.json` (fields in the file's order).
#[derive(Debug, Clone, Serialize)]
pub struct EngineeringSummary {
    #[serde(rename = "energy_J")]
    pub energy: EnergySummary,
    pub energy_error_normalisation: &'static str,
    pub energy_error_relative_max: f64,
    pub peak_absolute_acceleration_m_s2: Vec<StoreyPeak>,
    #[serde(rename = "peak_base_shear_N")]
    pub peak_base_shear: PeakAt,
    pub peak_drift_m: Vec<StoreyPeak>,
    #[serde(rename = "peak_storey_shear_N")]
    pub peak_storey_shear: Vec<StoreyPeak>,
}

impl EngineeringRecorder {
    /// `None` for models that are sparse or larger than [`MAX_DOFS`].
    pub fn new(def: &TestDefinition) -> Option<Self> {
        if def.reduction.is_some() {
            return None; // a reduced model's DOFs past the kept ones are modal coordinates
        }
        let model = def.model.as_dense()?;
        let n = model.n_dofs();
        if n > MAX_DOFS {
            return None;
        }
        let storey = StoreyResponse::new(model);
        let chain = storey.is_shear_chain();
        let coupling = def
            .substructure
            .as_ref()
            .map_or_else(Vec::new, |s| s.coupling_dofs.clone());
        Some(Self {
            energy: EnergyBalance::new(model),
            storey,
            coupling,
            force: vec![0.0; n],
            deviation: vec![0.0; n],
            ag: 0.0,
            peak_abs: vec![(0.0, 0.0); n],
            peak_drift: vec![(0.0, 0.0); if chain { n } else { 0 }],
            peak_shear: vec![(0.0, 0.0); if chain { n } else { 0 }],
            peak_base: (0.0, 0.0),
        })
    }

    /// DOFs of the model.
    pub fn n_dofs(&self) -> usize {
        self.peak_abs.len()
    }

    /// The model is a shear chain (drifts and storey shears are recorded).
    pub fn is_shear_chain(&self) -> bool {
        self.storey.is_shear_chain()
    }

    /// The column names of `response.csv`.
    pub fn columns(&self) -> Vec<String> {
        let n = self.n_dofs();
        let mut c = vec!["t".to_string(), "ag".to_string()];
        c.extend((1..=n).map(|k| format!("a_abs{k}")));
        if self.is_shear_chain() {
            c.extend((1..=n).map(|k| format!("drift{k}")));
            c.extend((1..=n).map(|k| format!("shear{k}")));
        }
        for s in [
            "base_shear",
            "E_input",
            "E_kinetic",
            "E_damping",
            "E_strain",
            "E_coupling",
            "E_error",
        ] {
            c.push(s.to_string());
        }
        c
    }

    /// Record the current state of `sim` (once per step, from step 0).
    pub fn record(&mut self, sim: &Simulation) -> Result<()> {
        let s = sim.state();
        let (t, ag) = (sim.time(), sim.ground_acceleration(sim.steps_done()));
        self.ag = ag;
        self.force.iter_mut().for_each(|f| *f = 0.0);
        if let Some(rec) = sim.coupling() {
            // The force the coupling applies to the structure: measured force plus the
            // error-force compensation (the equation of motion's Sᵀ(f_c + f_u)).
            for (k, &c) in self.coupling.iter().enumerate() {
                self.force[c] += rec.coupling_force[k] + rec.compensation_force[k];
            }
        }
        let deviation = match sim.springs() {
            Some(springs) => {
                self.deviation.iter_mut().for_each(|d| *d = 0.0);
                springs.add_deviation(1.0, &mut self.deviation);
                Some(self.deviation.as_slice())
            }
            None => None,
        };
        self.energy
            .push_nonlinear(s.u.as_slice(), s.v.as_slice(), ag, &self.force, deviation)?;
        self.storey
            .update_nonlinear(s.u.as_slice(), s.v.as_slice(), s.a.as_slice(), ag, deviation)?;
        let peak = |p: &mut (f64, f64), x: f64| {
            if x.abs() > p.0 {
                *p = (x.abs(), t);
            }
        };
        let r = &self.storey;
        for (p, &x) in self.peak_abs.iter_mut().zip(&r.absolute_acceleration) {
            peak(p, x);
        }
        for (p, &x) in self.peak_drift.iter_mut().zip(&r.drift) {
            peak(p, x);
        }
        for (p, &x) in self.peak_shear.iter_mut().zip(&r.storey_shear) {
            peak(p, x);
        }
        peak(&mut self.peak_base, r.base_shear);
        Ok(())
    }

    /// The quantities of the last recorded step at time `t`.
    pub fn row(&self, t: f64) -> EngineeringRow<'_> {
        let r = &self.storey;
        EngineeringRow {
            t,
            ag: self.ag,
            absolute_acceleration: &r.absolute_acceleration,
            drift: &r.drift,
            storey_shear: &r.storey_shear,
            base_shear: r.base_shear,
            energy: self.energy.terms(),
            energy_error: self.energy.error(),
        }
    }

    /// The `engineering` block of the summary.
    pub fn summary(&self) -> EngineeringSummary {
        let e = self.energy.terms();
        let peaks = |v: &[(f64, f64)]| -> Vec<StoreyPeak> {
            v.iter()
                .enumerate()
                .map(|(k, &(peak, t))| StoreyPeak { dof: k + 1, peak, t })
                .collect()
        };
        EngineeringSummary {
            energy: EnergySummary {
                coupling: e.coupling,
                damping: e.damping,
                error: self.energy.error(),
                input: e.input,
                kinetic: e.kinetic,
                strain: e.strain,
            },
            energy_error_normalisation: "E_K + E_S + E_D − E_I − E_C over the largest E_0 + |E_I| + |E_C| so far",
            energy_error_relative_max: self.energy.max_relative_error(),
            peak_absolute_acceleration_m_s2: peaks(&self.peak_abs),
            peak_base_shear: PeakAt {
                peak: self.peak_base.0,
                t: self.peak_base.1,
            },
            peak_drift_m: peaks(&self.peak_drift),
            peak_storey_shear: peaks(&self.peak_shear),
        }
    }
}

/// The input motion of a test: its Fourier amplitude (up to 25 Hz or Nyquist) and 5 % response
/// spectrum (`fourier.csv`, `spectrum.csv`), and their summary.
#[derive(Debug, Clone)]
pub struct InputMotion {
    /// Frequencies \[Hz\] and Fourier amplitudes [m/s²].
    pub frequency: Vec<f64>,
    pub amplitude: Vec<f64>,
    /// Periods \[s\] of the spectrum, logarithmically spaced from 0.02 to 5 s.
    pub periods: Vec<f64>,
    pub spectrum: Vec<SpectralOrdinate>,
    pub summary: InputMotionSummary,
}

/// The spectrum's peak pseudo-acceleration and its period.
#[derive(Debug, Clone, Serialize)]
pub struct SpectrumPeak {
    pub period_s: f64,
    pub psa_m_s2: f64,
}

/// The `input_motion` block of `summary.json`.
#[derive(Debug, Clone, Serialize)]
pub struct InputMotionSummary {
    pub pga_g: f64,
    pub pga_m_s2: f64,
    pub spectrum_damping: f64,
    pub spectrum_peak: Option<SpectrumPeak>,
}

impl InputMotion {
    pub fn new(def: &TestDefinition) -> Result<Self> {
        let dt = def.integrator.dt;
        let ag = &def.ground_motion.accel;
        let nyquist = 0.5 / dt;
        // A DFT of at most 2^16 samples (decimated).
        let stride = ag.len().div_ceil(1 << 16).max(1);
        let sampled: Vec<f64> = ag.iter().step_by(stride).copied().collect();
        let (frequency, amplitude) = amplitude_spectrum(&sampled, dt * stride as f64, nyquist.min(25.0) / 1.0);
        let periods = log_periods(0.02, 5.0, 120);
        let spectrum = response_spectrum(ag, dt, &periods, SPECTRUM_ZETA)?;
        let pga = ag.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        let spectrum_peak = spectrum
            .iter()
            .max_by(|a, b| a.psa.total_cmp(&b.psa))
            .map(|o| SpectrumPeak {
                period_s: o.period,
                psa_m_s2: o.psa,
            });
        Ok(Self {
            frequency,
            amplitude,
            periods,
            spectrum,
            summary: InputMotionSummary {
                pga_g: pga / crate::excitation::G,
                pga_m_s2: pga,
                spectrum_damping: SPECTRUM_ZETA,
                spectrum_peak,
            },
        })
    }
}
