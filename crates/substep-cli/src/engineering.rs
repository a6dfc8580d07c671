//! Engineering outputs of `substep run`: `response.csv` (absolute accelerations, drifts, storey
//! and base shear, energy balance per step), `ground_motion.csv` and `spectrum.csv` (the input
//! record, its Fourier amplitude and 5 % response spectrum), their figures and the summary block.
//! The numerics are in the library (`analysis::energy`, `analysis::storey`,
//! `excitation::spectrum`); this module only records, writes and plots.

use crate::output::{Decimated, num};
use crate::plots::{Curve, Figure, Panel};
use anyhow::{Context, Result};
use serde_json::{Value, json};
use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use substep::analysis::energy::EnergyBalance;
use substep::analysis::spectral::amplitude_spectrum;
use substep::analysis::storey::StoreyResponse;
use substep::excitation::spectrum::{log_periods, response_spectrum};
use substep::io::{Simulation, TestDefinition};

/// Largest model for which the per-step engineering quantities are computed (dense products
/// per step; larger models are benchmarks, not buildings to report on).
const MAX_DOFS: usize = 200;
/// Rows kept for the figures.
const PLOT_ROWS: usize = 4000;
/// Damping ratio of the response spectrum.
pub const SPECTRUM_ZETA: f64 = 0.05;

pub struct Engineering {
    energy: EnergyBalance,
    storey: StoreyResponse,
    coupling: Vec<usize>,
    force: Vec<f64>,
    w: BufWriter<File>,
    path: PathBuf,
    line: String,
    table: Decimated,
    peak_abs: Vec<(f64, f64)>,
    peak_drift: Vec<(f64, f64)>,
    peak_shear: Vec<(f64, f64)>,
    peak_base: (f64, f64),
    n: usize,
}

impl Engineering {
    /// `None` for models that are sparse or larger than [`MAX_DOFS`].
    pub fn create(def: &TestDefinition, dir: &Path) -> Result<Option<Self>> {
        let Some(model) = def.model.as_dense() else {
            return Ok(None);
        };
        let n = model.n_dofs();
        if n > MAX_DOFS {
            return Ok(None);
        }
        let storey = StoreyResponse::new(model);
        let chain = storey.is_shear_chain();
        let path = dir.join("response.csv");
        let mut w = BufWriter::new(File::create(&path).with_context(|| format!("cannot write {}", path.display()))?);
        let mut head = String::from("t,ag");
        for k in 1..=n {
            let _ = write!(head, ",a_abs{k}");
        }
        if chain {
            for k in 1..=n {
                let _ = write!(head, ",drift{k}");
            }
            for k in 1..=n {
                let _ = write!(head, ",shear{k}");
            }
        }
        head.push_str(",base_shear,E_input,E_kinetic,E_damping,E_strain,E_coupling,E_error\n");
        w.write_all(head.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
        let coupling = def
            .substructure
            .as_ref()
            .map_or_else(Vec::new, |s| s.coupling_dofs.clone());
        Ok(Some(Self {
            energy: EnergyBalance::new(model),
            storey,
            coupling,
            force: vec![0.0; n],
            w,
            path,
            line: String::new(),
            // t, ag, base shear, E_I, E_K, E_D, E_S, E_C, E_err
            table: Decimated::new(9, PLOT_ROWS),
            peak_abs: vec![(0.0, 0.0); n],
            peak_drift: vec![(0.0, 0.0); if chain { n } else { 0 }],
            peak_shear: vec![(0.0, 0.0); if chain { n } else { 0 }],
            peak_base: (0.0, 0.0),
            n,
        }))
    }

    /// Record the current state of `sim` (call once per step, from step 0).
    pub fn record(&mut self, sim: &Simulation) -> Result<()> {
        let s = sim.state();
        let (t, ag) = (sim.time(), sim.ground_acceleration(sim.steps_done()));
        self.force.iter_mut().for_each(|f| *f = 0.0);
        if let Some(rec) = sim.coupling() {
            // The force the coupling applies to the structure: measured force plus the
            // error-force compensation (the equation of motion's Sᵀ(f_c + f_u)).
            for (k, &c) in self.coupling.iter().enumerate() {
                self.force[c] += rec.coupling_force[k] + rec.compensation_force[k];
            }
        }
        self.energy.push(s.u.as_slice(), s.v.as_slice(), ag, &self.force)?;
        self.storey.update(s.u.as_slice(), s.v.as_slice(), s.a.as_slice(), ag)?;
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
        let e = self.energy.terms();
        let err = self.energy.error();
        let line = &mut self.line;
        line.clear();
        num(line, substep_time(t));
        for &x in std::iter::once(&ag)
            .chain(&r.absolute_acceleration)
            .chain(&r.drift)
            .chain(&r.storey_shear)
            .chain([r.base_shear, e.input, e.kinetic, e.damping, e.strain, e.coupling, err].iter())
        {
            line.push(',');
            num(line, x);
        }
        line.push('\n');
        self.w
            .write_all(line.as_bytes())
            .with_context(|| format!("cannot write {}", self.path.display()))?;
        self.table.push(&[
            t,
            ag,
            r.base_shear,
            e.input,
            e.kinetic,
            e.damping,
            e.strain,
            e.coupling,
            err,
        ]);
        Ok(())
    }

    pub fn finish(&mut self) -> Result<PathBuf> {
        self.w
            .flush()
            .with_context(|| format!("cannot write {}", self.path.display()))?;
        Ok(self.path.clone())
    }

    /// The `engineering` block of `summary.json`.
    pub fn summary(&self) -> Value {
        let e = self.energy.terms();
        let peaks = |v: &[(f64, f64)]| -> Vec<Value> {
            v.iter()
                .enumerate()
                .map(|(k, (p, t))| json!({"dof": k + 1, "peak": p, "t": t}))
                .collect()
        };
        json!({
            "energy_J": {
                "input": e.input,
                "kinetic": e.kinetic,
                "damping": e.damping,
                "strain": e.strain,
                "coupling": e.coupling,
                "error": self.energy.error(),
            },
            "energy_error_relative_max": self.energy.max_relative_error(),
            "energy_error_normalisation": "E_K + E_S + E_D − E_I − E_C over the largest E_0 + |E_I| + |E_C| so far",
            "peak_base_shear_N": {"peak": self.peak_base.0, "t": self.peak_base.1},
            "peak_absolute_acceleration_m_s2": peaks(&self.peak_abs),
            "peak_drift_m": peaks(&self.peak_drift),
            "peak_storey_shear_N": peaks(&self.peak_shear),
        })
    }

    /// One-line summaries for stdout.
    pub fn lines(&self) -> Vec<String> {
        let e = self.energy.terms();
        let mut out = vec![format!(
            "  energy at the end [J]: input {:.3}, kinetic {:.3}, strain {:.3}, damping {:.3}, coupling {:.3}; balance error max {:.3} % of the energy put in",
            e.input,
            e.kinetic,
            e.strain,
            e.damping,
            e.coupling,
            100.0 * self.energy.max_relative_error()
        )];
        let (k, a) = self
            .peak_abs
            .iter()
            .enumerate()
            .fold((0, (0.0, 0.0)), |b, (k, &p)| if p.0 > b.1.0 { (k, p) } else { b });
        out.push(format!(
            "  peak absolute acceleration {:.3} m/s² ({:.3} g, DOF {}, t = {:.3} s); peak base shear {:.1} N (t = {:.3} s)",
            a.0,
            a.0 / substep::excitation::G,
            k + 1,
            a.1,
            self.peak_base.0,
            self.peak_base.1
        ));
        if let Some((k, d)) = self
            .peak_drift
            .iter()
            .enumerate()
            .max_by(|x, y| x.1.0.total_cmp(&y.1.0))
        {
            out.push(format!(
                "  peak inter-storey drift {:.3} mm (storey {}, t = {:.3} s)",
                1e3 * d.0,
                k + 1,
                d.1
            ));
        }
        out
    }

    /// `energy.png`, `base_shear.png` and (shear chains) `storeys.png`.
    pub fn figures(&self) -> Vec<(&'static str, Figure)> {
        let t = self.table.column(0);
        let curve = |label: &str, c: usize| Curve {
            label: label.into(),
            x: t.clone(),
            y: self.table.column(c),
        };
        let mut figs = vec![
            (
                "energy",
                Figure::new("Energy balance of the numerical substructure")
                    .panel(Panel::new("time t [s]", "energy E [J]").curves(vec![
                        curve("input E_I", 3),
                        curve("kinetic E_K", 4),
                        curve("damping E_D", 5),
                        curve("strain E_S", 6),
                        curve("coupling E_C", 7),
                    ]))
                    .panel(
                        Panel::new("time t [s]", "E_K + E_S + E_D − E_I − E_C [J]")
                            .curves(vec![curve("residual E_err", 8)])
                            .height(0.35),
                    ),
            ),
            (
                "base_shear",
                Figure::new("Base shear and ground acceleration")
                    .panel(Panel::new("time t [s]", "base shear V_b [N]").curves(vec![curve("V_b", 2)]))
                    .panel(
                        Panel::new("time t [s]", "a_g [m/s²]")
                            .curves(vec![curve("ground acceleration", 1)])
                            .height(0.35),
                    ),
            ),
        ];
        if self.peak_drift.len() > 1 {
            let storeys: Vec<f64> = (1..=self.n).map(|k| k as f64).collect();
            let drift: Vec<f64> = self.peak_drift.iter().map(|p| 1e3 * p.0).collect();
            let shear: Vec<f64> = self.peak_shear.iter().map(|p| 1e-3 * p.0).collect();
            figs.push((
                "storeys",
                Figure::new("Peak storey response")
                    .columns(2)
                    .panel(
                        Panel::new("peak drift |δ| [mm]", "storey")
                            .curves(vec![Curve {
                                label: "drift".into(),
                                x: drift,
                                y: storeys.clone(),
                            }])
                            .markers(),
                    )
                    .panel(
                        Panel::new("peak storey shear |V| [kN]", "storey")
                            .curves(vec![Curve {
                                label: "shear".into(),
                                x: shear,
                                y: storeys,
                            }])
                            .markers(),
                    ),
            ));
        }
        figs
    }
}

/// A time rounded to 1 ns, so that `i·Δt` prints as `19.99`, not `19.990000000000002`.
pub fn substep_time(t: f64) -> f64 {
    (t * 1e9).round() / 1e9
}

/// `ground_motion.csv` (t, a_g, and the Fourier amplitude on its own rows) and `spectrum.csv`
/// (5 % response spectrum), plus their figures.
pub fn ground_motion_outputs(
    def: &TestDefinition,
    dir: &Path,
) -> Result<(Vec<PathBuf>, Vec<(&'static str, Figure)>, Value)> {
    let dt = def.integrator.dt;
    let ag = &def.ground_motion.accel;
    let mut files = Vec::new();
    let nyquist = 0.5 / dt;
    // Fourier amplitude up to 25 Hz or Nyquist; a DFT of at most 2^16 samples (decimated).
    let stride = ag.len().div_ceil(1 << 16).max(1);
    let sampled: Vec<f64> = ag.iter().step_by(stride).copied().collect();
    let (freq, amp) = amplitude_spectrum(&sampled, dt * stride as f64, nyquist.min(25.0) / 1.0);
    let periods = log_periods(0.02, 5.0, 120);
    let spectrum = response_spectrum(ag, dt, &periods, SPECTRUM_ZETA)?;
    let gm = dir.join("ground_motion.csv");
    let mut text = String::from("t,ag\n");
    for (i, &a) in ag.iter().enumerate() {
        num(&mut text, substep_time(i as f64 * dt));
        text.push(',');
        num(&mut text, a);
        text.push('\n');
    }
    std::fs::write(&gm, text).with_context(|| format!("cannot write {}", gm.display()))?;
    files.push(gm);
    let fa = dir.join("fourier.csv");
    let mut text = String::from("f_hz,amplitude_m_s2\n");
    for (f, a) in freq.iter().zip(&amp) {
        num(&mut text, *f);
        text.push(',');
        num(&mut text, *a);
        text.push('\n');
    }
    std::fs::write(&fa, text).with_context(|| format!("cannot write {}", fa.display()))?;
    files.push(fa);
    let sp = dir.join("spectrum.csv");
    let mut text = String::from("period_s,sd_m,psv_m_s,psa_m_s2,sa_m_s2\n");
    for o in &spectrum {
        for (i, x) in [o.period, o.sd, o.psv, o.psa, o.sa].into_iter().enumerate() {
            if i > 0 {
                text.push(',');
            }
            num(&mut text, x);
        }
        text.push('\n');
    }
    std::fs::write(&sp, text).with_context(|| format!("cannot write {}", sp.display()))?;
    files.push(sp);
    let step = ag.len().div_ceil(PLOT_ROWS).max(1);
    let t: Vec<f64> = (0..ag.len()).step_by(step).map(|i| i as f64 * dt).collect();
    let a: Vec<f64> = ag.iter().step_by(step).copied().collect();
    let pga = ag.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    let figs = vec![
        (
            "ground_motion",
            Figure::new(&format!(
                "Ground motion (PGA {:.3} m/s² = {:.3} g)",
                pga,
                pga / substep::excitation::G
            ))
            .panel(Panel::new("time t [s]", "a_g [m/s²]").curves(vec![Curve {
                label: "a_g".into(),
                x: t,
                y: a,
            }]))
            .panel(
                Panel::new("frequency f [Hz]", "Fourier amplitude [m/s²]")
                    .curves(vec![Curve {
                        label: "|A_g(f)|".into(),
                        x: freq,
                        y: amp,
                    }])
                    .height(0.45),
            ),
        ),
        (
            "response_spectrum",
            Figure::new("Elastic response spectrum, ζ = 5 %")
                .panel(
                    Panel::new("period T [s]", "acceleration [m/s²]")
                        .curves(vec![
                            Curve {
                                label: "pseudo-acceleration PS_a".into(),
                                x: periods.clone(),
                                y: spectrum.iter().map(|o| o.psa).collect(),
                            },
                            Curve {
                                label: "absolute acceleration S_a".into(),
                                x: periods.clone(),
                                y: spectrum.iter().map(|o| o.sa).collect(),
                            },
                        ])
                        .log_x(),
                )
                .panel(
                    Panel::new("period T [s]", "displacement S_d [m]")
                        .curves(vec![Curve {
                            label: "S_d".into(),
                            x: periods.clone(),
                            y: spectrum.iter().map(|o| o.sd).collect(),
                        }])
                        .log_x()
                        .height(0.45),
                ),
        ),
    ];
    let peak = spectrum
        .iter()
        .max_by(|a, b| a.psa.total_cmp(&b.psa))
        .map(|o| json!({"period_s": o.period, "psa_m_s2": o.psa}));
    let summary = json!({
        "pga_m_s2": pga,
        "pga_g": pga / substep::excitation::G,
        "spectrum_damping": SPECTRUM_ZETA,
        "spectrum_peak": peak,
    });
    Ok((files, figs, summary))
}
