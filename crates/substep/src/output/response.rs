//! Engineering outputs of `substep run`: `response.csv` (absolute accelerations, drifts, storey
//! and base shear, energy balance per step), `ground_motion.csv`, `fourier.csv` and
//! `spectrum.csv` (the input record, its Fourier amplitude and 5 % response spectrum), their
//! figures and the printed lines. The quantities are recorded by the library
//! (`crate::run::EngineeringRecorder`, `crate::run::InputMotion`); this module only writes
//! and plots.

use super::files::{Decimated, cannot_write, num};
use crate::Result;
use crate::figure::{Curve, Figure, Panel};
use crate::format::{percent, sig};
use crate::io::TestDefinition;
use crate::run::{EngineeringRow, EngineeringSummary, InputMotion, round_time};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Rows kept for the figures.
const PLOT_ROWS: usize = 4000;

/// Figures by file stem.
pub type Figures = Vec<(&'static str, Figure)>;

/// `response.csv`, written row by row, and the decimated series of its figures.
pub struct ResponseWriter {
    w: BufWriter<File>,
    path: PathBuf,
    line: String,
    table: Decimated,
    /// Drift and storey shear of the first storeys of a nonlinear shear building (for
    /// `storey_hysteresis.png`), `None` otherwise.
    loops: Option<Decimated>,
}

/// Storeys shown in `storey_hysteresis.png` (the lowest ones yield most).
const LOOP_STOREYS: usize = 4;

impl ResponseWriter {
    /// `hysteretic_storeys`: the number of storeys of a nonlinear shear building (0: none).
    pub fn create(columns: &[String], dir: &Path, hysteretic_storeys: usize) -> Result<Self> {
        let path = dir.join("response.csv");
        let mut w = BufWriter::new(File::create(&path).map_err(|e| cannot_write(&path, e))?);
        w.write_all((columns.join(",") + "\n").as_bytes())
            .map_err(|e| cannot_write(&path, e))?;
        Ok(Self {
            w,
            path,
            line: String::new(),
            // t, ag, base shear, E_I, E_K, E_D, E_S, E_C, E_err
            table: Decimated::new(9, PLOT_ROWS),
            loops: (hysteretic_storeys > 0)
                .then(|| Decimated::new(2 * hysteretic_storeys.min(LOOP_STOREYS), PLOT_ROWS)),
        })
    }

    /// Write one step's row.
    pub fn record(&mut self, r: &EngineeringRow<'_>) -> Result<()> {
        let line = &mut self.line;
        line.clear();
        for (i, x) in r.values().enumerate() {
            if i > 0 {
                line.push(',');
            }
            num(line, x);
        }
        line.push('\n');
        self.w
            .write_all(line.as_bytes())
            .map_err(|e| cannot_write(&self.path, e))?;
        let e = r.energy;
        self.table.push(&[
            r.t,
            r.ag,
            r.base_shear,
            e.input,
            e.kinetic,
            e.damping,
            e.strain,
            e.coupling,
            r.energy_error,
        ]);
        if let Some(loops) = &mut self.loops {
            let m = loops.width / 2;
            if r.drift.len() >= m && r.storey_shear.len() >= m {
                let mut row = [0.0; 2 * LOOP_STOREYS];
                row[..m].copy_from_slice(&r.drift[..m]);
                row[m..2 * m].copy_from_slice(&r.storey_shear[..m]);
                loops.push(&row[..2 * m]);
            }
        }
        Ok(())
    }

    pub fn finish(&mut self) -> Result<PathBuf> {
        self.w.flush().map_err(|e| cannot_write(&self.path, e))?;
        Ok(self.path.clone())
    }

    /// `energy.png`, `base_shear.png` and (shear chains) `storeys.png`.
    pub fn figures(&self, s: &EngineeringSummary) -> Figures {
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
                        Panel::new("time t [s]", "residual [J]")
                            .curves(vec![curve("E_K + E_S + E_D − E_I − E_C", 8)])
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
        if let Some(loops) = &self.loops {
            let m = loops.width / 2;
            let mut fig = Figure::new("Storey shear (springs and damping) vs inter-storey drift").columns(m.min(3));
            for k in 0..m {
                let drift: Vec<f64> = loops.column(k).iter().map(|d| 1e3 * d).collect();
                let shear: Vec<f64> = loops.column(m + k).iter().map(|v| 1e-3 * v).collect();
                let storey = k + 1;
                fig = fig.panel(
                    Panel::new(
                        &format!("storey {storey}: drift δ{storey} [mm]"),
                        &format!("storey shear V{storey} [kN]"),
                    )
                    .curves(vec![Curve {
                        label: format!("storey {}", k + 1),
                        x: drift,
                        y: shear,
                    }]),
                );
            }
            figs.push(("storey_hysteresis", fig));
        }
        if s.peak_drift_m.len() > 1 {
            let n = s.peak_absolute_acceleration_m_s2.len();
            let storeys: Vec<f64> = (1..=n).map(|k| k as f64).collect();
            let drift: Vec<f64> = s.peak_drift_m.iter().map(|p| 1e3 * p.peak).collect();
            let shear: Vec<f64> = s.peak_storey_shear.iter().map(|p| 1e-3 * p.peak).collect();
            figs.push((
                "storeys",
                Figure::new("Peak storey response")
                    .columns(2)
                    .panel(
                        Panel::new("peak drift |δ| [mm]", "storey")
                            .integer_y()
                            .curves(vec![Curve {
                                label: "drift".into(),
                                x: drift,
                                y: storeys.clone(),
                            }])
                            .markers(),
                    )
                    .panel(
                        Panel::new("peak storey shear |V| [kN]", "storey")
                            .integer_y()
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

/// One-line summaries for stdout.
pub fn lines(s: &EngineeringSummary) -> Vec<String> {
    let e = &s.energy;
    // Significant digits, so that a diverged run's 10¹⁵⁰ J prints as such (not as 150 digits).
    let n = |x: f64| sig(x, 4);
    let mut out = vec![format!(
        "  energy at the end [J]: input {}, kinetic {}, strain {}, damping {}, coupling {}; balance error max {} of the energy put in",
        n(e.input),
        n(e.kinetic),
        n(e.strain),
        n(e.damping),
        n(e.coupling),
        percent(s.energy_error_relative_max)
    )];
    let (k, a) = s
        .peak_absolute_acceleration_m_s2
        .iter()
        .enumerate()
        .fold(
            (0, (0.0, 0.0)),
            |b, (k, p)| if p.peak > b.1.0 { (k, (p.peak, p.t)) } else { b },
        );
    out.push(format!(
        "  peak absolute acceleration {} m/s² ({} g, DOF {}, t = {:.3} s); peak base shear {} N (t = {:.3} s)",
        n(a.0),
        n(a.0 / crate::excitation::G),
        k + 1,
        a.1,
        n(s.peak_base_shear.peak),
        s.peak_base_shear.t
    ));
    if let Some((k, d)) = s
        .peak_drift_m
        .iter()
        .enumerate()
        .max_by(|x, y| x.1.peak.total_cmp(&y.1.peak))
    {
        out.push(format!(
            "  peak inter-storey drift {} mm (storey {}, t = {:.3} s)",
            n(1e3 * d.peak),
            k + 1,
            d.t
        ));
    }
    out
}

/// `ground_motion.csv` (t, a_g, and the Fourier amplitude on its own rows) and `spectrum.csv`
/// (5 % response spectrum), plus their figures.
pub fn ground_motion_outputs(
    def: &TestDefinition,
    motion: &InputMotion,
    dir: &Path,
) -> Result<(Vec<PathBuf>, Figures)> {
    let dt = def.integrator.dt;
    let ag = &def.ground_motion.accel;
    let mut files = Vec::new();
    let (freq, amp) = (motion.frequency.clone(), motion.amplitude.clone());
    let (periods, spectrum) = (&motion.periods, &motion.spectrum);
    let gm = dir.join("ground_motion.csv");
    let mut text = String::from("t,ag\n");
    for (i, &a) in ag.iter().enumerate() {
        num(&mut text, round_time(i as f64 * dt));
        text.push(',');
        num(&mut text, a);
        text.push('\n');
    }
    std::fs::write(&gm, text).map_err(|e| cannot_write(&gm, e))?;
    files.push(gm);
    let fa = dir.join("fourier.csv");
    let mut text = String::from("f_hz,amplitude_m_s2\n");
    for (f, a) in freq.iter().zip(&amp) {
        num(&mut text, *f);
        text.push(',');
        num(&mut text, *a);
        text.push('\n');
    }
    std::fs::write(&fa, text).map_err(|e| cannot_write(&fa, e))?;
    files.push(fa);
    let sp = dir.join("spectrum.csv");
    let mut text = String::from("period_s,sd_m,psv_m_s,psa_m_s2,sa_m_s2\n");
    for o in spectrum {
        for (i, x) in [o.period, o.sd, o.psv, o.psa, o.sa].into_iter().enumerate() {
            if i > 0 {
                text.push(',');
            }
            num(&mut text, x);
        }
        text.push('\n');
    }
    std::fs::write(&sp, text).map_err(|e| cannot_write(&sp, e))?;
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
                pga / crate::excitation::G
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
    Ok((files, figs))
}
