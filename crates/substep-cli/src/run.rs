//! `substep run`: load a test definition, step it, record `history.csv`, `substeps.csv`,
//! `summary.json` and the plots, compare with the monolithic reference, print a summary.

use crate::monitor::live::{Live, Next, STABILITY_GROUPS};
use crate::output::{
    Decimated, ErrorStats, ErrorTracker, HistoryWriter, Peak, PeakTracker, SubstepWriter, prepare_dir, write_atomic,
};
use crate::plots::{Curve, Figure, Panel, line_chart, output_path};
use crate::{DEFAULT_CONFIG, DEFAULT_CONFIG_NAME, RunArgs};
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use substep::analysis::tracking::{ErrorAccumulator, TrackingMetrics};
use substep::compensate::{PhaseLagDefinition, PhaseLagSpec};
use substep::io::{Reference, Simulation, SubstructureDefinition, TestDefinition};
use substep::specimen::SpecimenSpec;
use substep::substructure::ErrorForceSpec;
use substep::substructure::SubstepObserver;
use substep::transfer::Dynamics;

/// Two sub-step observers fed in turn (the `substeps.csv` writer and the tracking metrics).
struct Both<'a, A, B>(&'a mut A, &'a mut B);

impl<A: SubstepObserver, B: SubstepObserver> SubstepObserver for Both<'_, A, B> {
    fn substep(&mut self, step: usize, j: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.0.substep(step, j, command, force, displacement);
        self.1.substep(step, j, command, force, displacement);
    }
    fn phase_lag(&mut self, tracking_error: &[f64], correction: &[f64]) {
        self.0.phase_lag(tracking_error, correction);
        self.1.phase_lag(tracking_error, correction);
    }
    #[allow(clippy::too_many_arguments)]
    fn ramp(&mut self, step: usize, j: usize, s: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.0.ramp(step, j, s, command, force, displacement);
        self.1.ramp(step, j, s, command, force, displacement);
    }
}

/// Rows kept for the plots (decimated beyond that).
const PLOT_ROWS: usize = 20_000;
/// Curves per displacement / acceleration chart.
const MAX_CURVES: usize = 4;

#[derive(Debug, Serialize)]
struct DofPeaks {
    dof: usize,
    u: Peak,
    v: Peak,
    a: Peak,
}

#[derive(Debug, Serialize)]
struct CouplingPeaks {
    dof: usize,
    force: Peak,
    error_force: Peak,
}

#[derive(Debug, Serialize)]
struct DofError {
    dof: usize,
    #[serde(flatten)]
    displacement: ErrorStats,
    /// J-style `std(u − u_ref) / std(u_ref)` (the benchmark's J4/J6 normalisation).
    nrms_error: f64,
}

#[derive(Debug, Serialize)]
struct CouplingError {
    dof: usize,
    displacement: ErrorStats,
    /// J-style `std(u − u_ref) / std(u_ref)` of the coupling DOF's displacement.
    displacement_nrms_error: f64,
    force: ErrorStats,
}

/// How well the measured displacement of a coupling DOF follows the command `d^{(j)}`, over
/// all sub-steps (the benchmark's J1–J3 for any test).
#[derive(Debug, Serialize)]
struct TrackingSummary {
    dof: usize,
    /// Cross-correlation lag of the measured displacement behind the command [s]; null when
    /// the command does not move. Equal to `max_delay_s` means "at least that".
    delay_s: Option<f64>,
    max_delay_s: f64,
    /// `std(x_m − d) / std(d)`.
    nrms_error: f64,
    /// `max|x_m − d| / max|d|`.
    peak_error: f64,
}

#[derive(Debug, Serialize)]
struct ReferenceSummary {
    /// `exact` (first-order hold) or `newmark`.
    scheme: &'static str,
    n_dofs: usize,
    /// Largest normalised peak error over the numerical DOFs' displacements.
    max_displacement_error: f64,
    /// Largest normalised peak error over the coupling forces.
    max_force_error: f64,
    dofs: Vec<DofError>,
    coupling: Vec<CouplingError>,
}

#[derive(Debug, Serialize)]
struct Summary {
    config: String,
    scheme: String,
    dt: f64,
    steps: usize,
    duration: f64,
    n_dofs: usize,
    ground_motion: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    substructure: Option<Value>,
    completed: bool,
    steps_done: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    stopped_at_step: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    reason: Option<String>,
    /// Sub-steps of the ramp to the safe position after a safety stop (in `substeps.csv`).
    /// Who or what stopped the run: `operator` (monitor page), `stability` (indicator),
    /// `safety_limit`, `site` (the experimental side failed), `diverged`.
    #[serde(skip_serializing_if = "Option::is_none")]
    stopped_by: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    ramp_substeps: Option<usize>,
    /// Wall time of the stepping loop including recording [s].
    wall_time_s: f64,
    /// Compute time of the simulation steps alone per step [µs].
    us_per_step: f64,
    peaks: Vec<DofPeaks>,
    #[serde(skip_serializing_if = "Option::is_none")]
    coupling_peaks: Option<Vec<CouplingPeaks>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    tracking: Option<Vec<TrackingSummary>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    reference: Option<ReferenceSummary>,
    /// Error-force compensation by estimation: how the steps were closed.
    #[serde(skip_serializing_if = "Option::is_none")]
    estimation: Option<Value>,
    /// Phase-lag compensation: kind and guard trips.
    #[serde(skip_serializing_if = "Option::is_none")]
    phase_lag: Option<Value>,
    /// Warnings of the run (e.g. a phase-lag compensator disabled by its guard).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    warnings: Vec<String>,
    /// PGA and response-spectrum peak of the input.
    input_motion: Value,
    /// Energy balance, base shear, drifts, absolute accelerations (dense models up to 200 DOFs).
    #[serde(skip_serializing_if = "Option::is_none")]
    engineering: Option<Value>,
    /// The on-line stability indicator (docs/monitor.md), when it ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    stability: Option<Value>,
    outputs: Vec<String>,
}

fn substructure_json(s: &SubstructureDefinition) -> Value {
    let a = &s.actuator;
    let mut actuator = match &a.dynamics {
        Dynamics::Ideal => json!({ "kind": "ideal", "delay": a.delay }),
        Dynamics::FirstOrder { time_constant } => {
            json!({ "kind": "first_order", "time_constant": time_constant, "delay": a.delay })
        }
        Dynamics::SecondOrder { frequency_hz, zeta } => {
            json!({ "kind": "second_order", "frequency": frequency_hz, "zeta": zeta, "delay": a.delay })
        }
        Dynamics::Lti(ss) => json!({
            "kind": "lti",
            "a": ss.a.row_iter().map(|r| r.iter().copied().collect::<Vec<f64>>()).collect::<Vec<_>>(),
            "b": ss.b.as_slice(),
            "c": ss.c.as_slice(),
            "d": ss.d,
            "delay": a.delay,
        }),
        Dynamics::ServoHydraulic(p) => json!({
            "kind": "servo_hydraulic",
            "g": p.g,
            "a1_beta0": p.a1_beta0,
            "beta1": p.beta1,
            "beta2": p.beta2,
            "a2": p.a2,
            "a3": p.a3,
            "csi_derivative": match p.derivative {
                substep::transfer::servo::Derivative::Exact => "exact",
                substep::transfer::servo::Derivative::FiniteDifference => "finite_difference",
            },
            "delay": a.delay,
        }),
    };
    if let Some(c) = &s.lab.command_converter {
        actuator["da_converter"] = json!({ "range": c.range(), "quantum": c.quantum() });
    }
    let error_force = match s.error_force {
        ErrorForceSpec::None => json!({ "kind": "none" }),
        ErrorForceSpec::Pid { p, i, d } => json!({ "kind": "pid", "p": p, "i": i, "d": d }),
        ErrorForceSpec::PidResidual { p } => json!({ "kind": "pid_residual", "p": p }),
        ErrorForceSpec::Arx { order, lambda, p0 } => {
            json!({ "kind": "arx", "order": order, "forgetting_factor": lambda, "p0": p0 })
        }
    };
    let specimens: Vec<Value> = s
        .specimens
        .iter()
        .map(|sp| {
            let dofs: Vec<usize> = sp.dofs().iter().map(|d| d + 1).collect();
            match sp {
                SpecimenSpec::LinearSdof {
                    mass,
                    stiffness,
                    damping,
                    ..
                } => {
                    json!({ "kind": sp.kind(), "dofs": dofs, "mass": mass, "stiffness": stiffness, "damping": damping })
                }
                SpecimenSpec::LumpedSdof {
                    mass,
                    stiffness,
                    damping,
                    ..
                } => {
                    json!({ "kind": sp.kind(), "dofs": dofs, "mass": mass, "stiffness": stiffness, "damping": damping })
                }
                _ => json!({ "kind": sp.kind(), "dofs": dofs }),
            }
        })
        .collect();
    let f = &s.force_sensors[0];
    let d = &s.displacement_sensors[0];
    json!({
        "coupling_dofs": s.coupling_dofs.iter().map(|c| c + 1).collect::<Vec<_>>(),
        "substeps": s.substeps,
        "inner_steps": s.inner_steps,
        "specimens": specimens,
        "actuator": actuator,
        "sensors": {
            "force_noise": f.noise_std, "displacement_noise": d.noise_std,
            "adc_bits": f.adc_bits.or(d.adc_bits), "lowpass_hz": f.lowpass_hz,
            "force_quantum": f.converter().map(|c| c.quantum()),
            "displacement_quantum": d.converter().map(|c| c.quantum()),
            "generator": match f.generator {
                substep::transfer::NoiseGenerator::ChaCha => "chacha",
                substep::transfer::NoiseGenerator::Benchmark => "benchmark",
            },
        },
        "force": if s.lab.force_from_motion { "from_motion" } else { "model" },
        "controller": s.controller.as_ref().map(|c| json!({
            "num": c.num(), "den": c.den(),
            "feedforward": s.controller_feedforward.as_ref().map(|f| json!({ "num": f.num(), "den": f.den() })),
        })),
        "error_force": error_force,
        "phase_lag": s.phase_lag.as_ref().map(phase_lag_json),
    })
}

// --- Phase-lag compensation, estimation and ideal error force: records and summary ---

fn phase_lag_json(p: &PhaseLagDefinition) -> Value {
    let ramp = json!({
        "start_substep": p.ramp.start, "ramp_substeps": p.ramp.ramp_in,
        "fade_out": p.ramp.fade_out.map(|(b, l)| [b, l]),
    });
    match p.spec {
        PhaseLagSpec::Polynomial {
            order,
            lead,
            guard_factor,
        } => {
            json!({ "kind": "polynomial", "order": order, "lead_substeps": lead, "guard_factor": guard_factor, "ramp": ramp })
        }
        PhaseLagSpec::Arx(a) => json!({
            "kind": "arx", "n_u": a.n_u, "k_lag": a.k_lag, "forgetting_factor": a.lambda,
            "guard_factor": a.guard_factor, "ramp": ramp,
        }),
        PhaseLagSpec::InverseFir(f) => json!({
            "kind": "inverse_fir", "lead_substeps": f.lead, "taps": f.taps, "order": f.order,
            "forgetting_factor": f.lambda, "ramp": ramp,
        }),
    }
}

/// Extra `history.csv` groups: `fei` (ideal error force) for every virtual (local) substructured
/// run — a remote site reports no noise-free force —, `te`, `du`
/// (tracking error and correction of the last sub-step) with phase-lag compensation.
fn extra_groups(def: &TestDefinition) -> Vec<&'static str> {
    match &def.substructure {
        None => Vec::new(),
        Some(s) if s.remote.is_some() && s.phase_lag.is_some() => vec!["te", "du"],
        Some(s) if s.remote.is_some() => Vec::new(),
        Some(s) if s.phase_lag.is_some() => vec!["fei", "te", "du"],
        Some(_) => vec!["fei"],
    }
}

/// Fill the extra columns (group-major, one value per coupling DOF) for the current step.
fn extra_values(sim: &Simulation, groups: &[&str], out: &mut [f64]) {
    let Some(test) = sim.substructure_test() else { return };
    let n_c = test.controller.n_coupling();
    for (g, name) in groups.iter().enumerate() {
        let cols = &mut out[g * n_c..(g + 1) * n_c];
        let src = match *name {
            "fei" if sim.steps_done() > 0 => test.controller.ideal_error_force(),
            "te" => test.site.phase_lag().map(|p| p.tracking_error()),
            "du" => test.site.phase_lag().map(|p| p.correction()),
            _ => None,
        };
        match src {
            Some(v) => cols.copy_from_slice(v),
            None => cols
                .iter_mut()
                .for_each(|c| *c = if sim.steps_done() == 0 { 0.0 } else { f64::NAN }),
        }
    }
}

/// `compensation_force.png` (with error-force compensation: f_u and its ideal value, DOF of the
/// first coupling) and `tracking_error.png` (with phase-lag compensation).
fn compensation_charts(def: &TestDefinition, table: &Decimated, dir: &Path) -> Result<Vec<PathBuf>> {
    let Some(s) = &def.substructure else {
        return Ok(Vec::new());
    };
    let dof = s.coupling_dofs[0] + 1;
    let t = table.column(0);
    let mut out = Vec::new();
    let wants = |f: &str| def.output.plot_options.wants(f);
    if s.error_force != ErrorForceSpec::None && wants("compensation_force") {
        let path = dir.join("compensation_force.png");
        line_chart(
            &path,
            &format!("DOF {dof}: compensation force f_u and its ideal (noise-free) value"),
            "time t [s]",
            "force [N]",
            &[
                Curve {
                    label: "f_u".into(),
                    x: t.clone(),
                    y: table.column(1),
                },
                Curve {
                    label: "ideal".into(),
                    x: t.clone(),
                    y: table.column(2),
                },
            ],
        )?;
        out.push(output_path(&path));
    }
    if s.phase_lag.is_some() && wants("tracking_error") {
        let path = dir.join("tracking_error.png");
        line_chart(
            &path,
            &format!("DOF {dof}: tracking error d − y (last sub-step of each step)"),
            "time t [s]",
            "tracking error [m]",
            &[Curve {
                label: String::new(),
                x: t,
                y: table.column(3),
            }],
        )?;
        out.push(output_path(&path));
    }
    Ok(out)
}

/// Estimation counts and phase-lag trips of a finished (or stopped) run, and the warnings.
fn compensation_summary(sim: &Simulation) -> (Option<Value>, Option<Value>, Vec<String>) {
    let mut warnings = Vec::new();
    let Some(test) = sim.substructure_test() else {
        return (None, None, warnings);
    };
    let estimation = test.controller.estimation_stats().map(|s| {
        if s.guard_fallbacks() > 0 {
            warnings.push(format!(
                "error-force estimation fell back to the plain algorithm in {} step(s) after its warm-up \
                 ({} ill-conditioned, {} implausible predictions)",
                s.guard_fallbacks(),
                s.ill_conditioned,
                s.implausible
            ));
        }
        json!({
            "steps": s.steps, "estimated": s.estimated, "fallbacks": s.fallbacks(),
            "warm_up": s.warm_up, "ill_conditioned": s.ill_conditioned, "implausible": s.implausible,
        })
    });
    let phase_lag = test.site.phase_lag().map(|p| {
        let trips: Vec<Value> = p
            .trips()
            .into_iter()
            .map(|(i, t)| {
                let dof = test.controller.coupling_dofs()[i] + 1;
                warnings.push(format!(
                    "phase-lag compensator of coupling DOF {dof} disabled by its guard: {t}"
                ));
                json!({ "dof": dof, "reason": t.to_string() })
            })
            .collect();
        json!({ "kinds": p.kinds(), "disabled": trips })
    });
    (estimation, phase_lag, warnings)
}

/// DOFs (0-based) shown in the displacement and acceleration charts: coupling DOFs, the last
/// DOF (roof), DOF 1; at most [`MAX_CURVES`].
fn plotted_dofs(n: usize, coupling: &[usize]) -> Vec<usize> {
    let mut dofs: Vec<usize> = Vec::new();
    let roof = n - 1;
    for &d in coupling.iter().take(MAX_CURVES - 1).chain([roof, 0].iter()) {
        if !dofs.contains(&d) && dofs.len() < MAX_CURVES {
            dofs.push(d);
        }
    }
    dofs
}

/// A ratio as a percentage, exponent notation when it is huge (a diverged run).
fn percent(ratio: f64) -> String {
    let p = 100.0 * ratio;
    if p.abs() < 1e4 {
        format!("{p:.3}")
    } else {
        format!("{p:.3e}")
    }
}

/// What is gathered between steps for `summary.json` and the plots: peaks, errors against the
/// reference, and a decimated table `t, u(sel), a(sel), [fc, fe, dm, uref] per coupling DOF`.
struct Recorder {
    /// Plotted DOFs (0-based) and coupling DOFs (0-based).
    sel: Vec<usize>,
    coupling: Vec<usize>,
    table: Decimated,
    row: Vec<f64>,
    /// Measured coupling force of the current step (zero for monolithic runs).
    force: Vec<f64>,
    peak_u: PeakTracker,
    peak_v: PeakTracker,
    peak_a: PeakTracker,
    peak_fc: PeakTracker,
    peak_fe: PeakTracker,
    err_u: ErrorTracker,
    err_f: ErrorTracker,
    nrms_u: Vec<ErrorAccumulator>,
}

impl Recorder {
    fn new(n: usize, coupling: &[usize]) -> Self {
        let sel = plotted_dofs(n, coupling);
        let n_c = coupling.len();
        let width = 1 + 2 * sel.len() + 4 * n_c;
        Self {
            sel,
            coupling: coupling.to_vec(),
            table: Decimated::new(width, PLOT_ROWS),
            row: vec![0.0; width],
            force: vec![0.0; n_c],
            peak_u: PeakTracker::new(n),
            peak_v: PeakTracker::new(n),
            peak_a: PeakTracker::new(n),
            peak_fc: PeakTracker::new(n_c),
            peak_fe: PeakTracker::new(n_c),
            err_u: ErrorTracker::new(n),
            err_f: ErrorTracker::new(n_c),
            nrms_u: vec![ErrorAccumulator::new(); n],
        }
    }

    fn col_u(&self, k: usize) -> usize {
        1 + k
    }
    fn col_a(&self, k: usize) -> usize {
        1 + self.sel.len() + k
    }
    /// Column of coupling quantity `j` (0 fc, 1 fe, 2 dm, 3 uref) of coupling DOF `k`.
    fn col_coupling(&self, k: usize, j: usize) -> usize {
        1 + 2 * self.sel.len() + 4 * k + j
    }

    fn record(&mut self, sim: &Simulation, reference: Option<&Reference>) {
        let t = sim.time();
        let s = sim.state();
        self.peak_u.update(s.u.as_slice(), t);
        self.peak_v.update(s.v.as_slice(), t);
        self.peak_a.update(s.a.as_slice(), t);
        self.row[0] = t;
        for k in 0..self.sel.len() {
            let (cu, ca) = (self.col_u(k), self.col_a(k));
            self.row[cu] = s.u[self.sel[k]];
            self.row[ca] = s.a[self.sel[k]];
        }
        if let Some(rec) = sim.coupling() {
            self.peak_fc.update(rec.coupling_force, t);
            self.peak_fe.update(rec.error_force, t);
            self.force.copy_from_slice(rec.coupling_force);
            for k in 0..self.coupling.len() {
                let c = self.col_coupling(k, 0);
                self.row[c] = rec.coupling_force[k];
                self.row[c + 1] = rec.error_force[k];
                self.row[c + 2] = rec.measured_displacement[k];
                self.row[c + 3] = reference.map_or(f64::NAN, |r| r.u()[self.coupling[k]]);
            }
        }
        if let Some(r) = reference {
            self.err_u.update(s.u.as_slice(), r.u());
            for (acc, (&u, &u_ref)) in self.nrms_u.iter_mut().zip(s.u.iter().zip(r.u())) {
                acc.push(u, u_ref);
            }
            self.err_f.update(&self.force, r.coupling_force());
        }
        self.table.push(&self.row);
    }

    fn reference_summary(&self, r: &Reference) -> ReferenceSummary {
        let dofs: Vec<DofError> = (0..self.peak_u.0.len())
            .map(|k| DofError {
                dof: k + 1,
                displacement: self.err_u.stats(k),
                nrms_error: self.nrms_u[k].nrms(),
            })
            .collect();
        let coupling: Vec<CouplingError> = self
            .coupling
            .iter()
            .enumerate()
            .map(|(k, &c)| CouplingError {
                dof: c + 1,
                displacement: self.err_u.stats(c),
                displacement_nrms_error: self.nrms_u[c].nrms(),
                force: self.err_f.stats(k),
            })
            .collect();
        let max = |it: &mut dyn Iterator<Item = f64>| it.filter(|x| x.is_finite()).fold(0.0, f64::max);
        ReferenceSummary {
            scheme: r.scheme(),
            n_dofs: r.n_dofs(),
            max_displacement_error: max(&mut dofs.iter().map(|d| d.displacement.peak_error)),
            max_force_error: max(&mut coupling.iter().map(|c| c.force.peak_error)),
            dofs,
            coupling,
        }
    }

    /// The figures of the run (`reference`: the reference's scheme name, if there is one;
    /// `window`: the `[output.plots] window` for the hysteresis and the zoom panel).
    fn charts(&self, reference: Option<&str>, window: Option<(f64, f64)>) -> Vec<Chart> {
        let time = self.table.column(0);
        let duration = time.last().copied().unwrap_or(0.0);
        let dof_curves = |col: &dyn Fn(usize) -> usize| -> Vec<Curve> {
            (0..self.sel.len())
                .map(|k| Curve {
                    label: format!("DOF {}", self.sel[k] + 1),
                    x: time.clone(),
                    y: self.table.column(col(k)),
                })
                .collect()
        };
        let one = |title: &str, x: &str, y: &str, curves: Vec<Curve>| Figure {
            size: Some((1100, 560)),
            ..Figure::new(title).panel(Panel::new(x, y).curves(curves))
        };
        let time_s = "time t [s]";
        let mut charts = vec![
            Chart {
                file: "displacement",
                figure: one(
                    "Displacement relative to the ground",
                    time_s,
                    "relative displacement u [m]",
                    dof_curves(&|k| self.col_u(k)),
                ),
            },
            Chart {
                file: "acceleration",
                figure: one(
                    "Acceleration relative to the ground (absolute: response.csv)",
                    time_s,
                    "relative acceleration ü [m/s²]",
                    dof_curves(&|k| self.col_a(k)),
                ),
            },
        ];
        if self.coupling.is_empty() {
            return charts;
        }
        // Quantity `j` of each coupling DOF against time.
        let coupling_curves = |j: usize| -> Vec<Curve> {
            (0..self.coupling.len().min(MAX_CURVES))
                .map(|k| Curve {
                    label: format!("DOF {}", self.coupling[k] + 1),
                    x: time.clone(),
                    y: self.table.column(self.col_coupling(k, j)),
                })
                .collect()
        };
        charts.push(Chart {
            file: "coupling_force",
            figure: one(
                "Measured coupling force on the structure",
                time_s,
                "coupling force f_c [N]",
                coupling_curves(0),
            ),
        });
        charts.push(Chart {
            file: "error_force",
            figure: one(
                "Error force f(k) − f(k−1) of the last sub-step",
                time_s,
                "error force [N]",
                coupling_curves(1),
            ),
        });
        // Hysteresis in the field's convention: the force on the specimen (−f_c) against the
        // specimen's measured displacement, over a window (default: 10 % of the record around
        // the peak displacement) so that the loops can be read.
        let dm0 = self.table.column(self.col_coupling(0, 2));
        let (w0, w1) = window.unwrap_or_else(|| {
            let (i, _) = dm0
                .iter()
                .enumerate()
                .fold((0, 0.0_f64), |b, (i, &x)| if x.abs() > b.1 { (i, x.abs()) } else { b });
            let centre = time.get(i).copied().unwrap_or(0.0);
            let half = 0.05 * duration;
            ((centre - half).max(0.0), (centre + half).min(duration.max(1e-9)))
        });
        let hyst: Vec<Curve> = (0..self.coupling.len().min(MAX_CURVES))
            .map(|k| {
                let (x, y): (Vec<f64>, Vec<f64>) = time
                    .iter()
                    .zip(self.table.column(self.col_coupling(k, 2)))
                    .zip(self.table.column(self.col_coupling(k, 0)))
                    .filter(|((t, _), _)| **t >= w0 && **t <= w1)
                    .map(|((_, d), f)| (d, -f))
                    .unzip();
                Curve {
                    label: format!("DOF {}", self.coupling[k] + 1),
                    x,
                    y,
                }
            })
            .collect();
        charts.push(Chart {
            file: "hysteresis",
            figure: one(
                &format!("Specimen force vs displacement, t = {w0:.2} … {w1:.2} s"),
                "specimen displacement d_m [m] (measured)",
                "force on the specimen −f_c [N]",
                hyst,
            ),
        });
        if let Some(scheme) = reference {
            // The first coupling DOF is always among the plotted DOFs.
            let c = self.coupling[0];
            let k = self.sel.iter().position(|&d| d == c).unwrap_or(0);
            let r = self.table.column(self.col_coupling(0, 3));
            let u = self.table.column(self.col_u(k));
            let err: Vec<f64> = u.iter().zip(&r).map(|(a, b)| a - b).collect();
            let (i_max, _) = err
                .iter()
                .enumerate()
                .fold((0, 0.0_f64), |b, (i, &x)| if x.abs() > b.1 { (i, x.abs()) } else { b });
            let (z0, z1) = window.unwrap_or_else(|| {
                let centre = time.get(i_max).copied().unwrap_or(0.0);
                let half = 0.03 * duration;
                ((centre - half).max(0.0), (centre + half).min(duration.max(1e-9)))
            });
            let peak_r = r.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
            let curves = vec![
                Curve {
                    label: format!("reference ({scheme})"),
                    x: time.clone(),
                    y: r.clone(),
                },
                Curve {
                    label: "substructure test".into(),
                    x: time.clone(),
                    y: u.clone(),
                },
            ];
            charts.push(Chart {
                file: "reference",
                figure: Figure::new(&format!(
                    "DOF {}: substructure test vs reference ({scheme}); peak error {:.2} % of the peak reference",
                    c + 1,
                    100.0 * err.get(i_max).map_or(0.0, |e| e.abs()) / peak_r.max(f64::MIN_POSITIVE)
                ))
                .panel(
                    Panel::new(time_s, "displacement u [m]")
                        .curves(curves.clone())
                        .highlight(z0, z1),
                )
                .panel(
                    Panel::new(time_s, "error u − u_ref [m]")
                        .curves(vec![Curve {
                            label: "test − reference".into(),
                            x: time.clone(),
                            y: err,
                        }])
                        .height(0.45),
                )
                .panel(
                    Panel::new(
                        &format!("time t [s] (zoom on {z0:.2} … {z1:.2} s)"),
                        "displacement u [m]",
                    )
                    .curves(curves)
                    .window(z0, z1)
                    .height(0.7),
                ),
            });
        }
        charts
    }

    fn print(&self) {
        let show = |name: &str, unit: &str, p: &PeakTracker| {
            let (k, peak) = p.largest();
            println!(
                "  peak {name} = {} {unit} (DOF {}, t = {:.3} s)",
                fixed(peak.max_abs),
                k + 1,
                peak.t
            );
        };
        show("relative displacement |u|", "m", &self.peak_u);
        show("relative velocity |u̇|", "m/s", &self.peak_v);
        show("relative acceleration |ü|", "m/s²", &self.peak_a);
        if !self.coupling.is_empty() {
            let (k, p) = self.peak_fc.largest();
            let (ke, pe) = self.peak_fe.largest();
            println!(
                "  peak coupling force |f_c| = {} N (DOF {}, t = {:.3} s), peak |error force| = {} N (DOF {})",
                fixed(p.max_abs),
                self.coupling[k] + 1,
                p.t,
                fixed(pe.max_abs),
                self.coupling[ke] + 1
            );
        }
    }
}

/// A number in fixed-point notation with about four significant digits (no exponent for
/// the magnitudes of a test: 1e-6 … 1e9).
fn fixed(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 || !a.is_finite() {
        return format!("{x}");
    }
    if !(1e-6..1e9).contains(&a) {
        return format!("{x:.3e}");
    }
    let digits = (3.0 - a.log10().floor()).clamp(0.0, 9.0) as usize;
    format!("{x:.digits$}")
}

struct Chart {
    file: &'static str,
    figure: Figure,
}

fn print_header(args: &RunArgs, def: &TestDefinition) {
    match &args.config {
        None => println!(
            "substep run: no config given, running the embedded default example (examples/default.toml):\n  \
             the typical TMD system as a virtual substructure test"
        ),
        Some(p) => println!("substep run: {}", p.display()),
    }
    let kind = match &def.substructure {
        None => format!("monolithic, scheme {}", def.integrator.name),
        Some(s) => format!(
            "substructured, scheme {}, coupling DOF(s) {:?}, k_sub = {}",
            def.integrator.name,
            s.coupling_dofs.iter().map(|c| c + 1).collect::<Vec<_>>(),
            s.substeps
        ),
    };
    println!(
        "  model: {} DOF(s), {} storage, {kind}",
        def.model.n_dofs(),
        def.model.storage_name()
    );
    let steps = def.integrator.steps;
    println!(
        "  ground motion: {}; dt = {} s, {steps} steps ({} s)",
        def.ground_motion.description,
        def.integrator.dt,
        def.time(steps)
    );
}

/// A progress bar that appears once a run has taken more than a second (on a terminal, unless
/// `--quiet`).
struct Progress {
    bar: ProgressBar,
    started: Instant,
    enabled: bool,
    shown: bool,
}

impl Progress {
    fn new(steps: usize, enabled: bool) -> Self {
        let bar = ProgressBar::with_draw_target(Some(steps as u64), ProgressDrawTarget::hidden());
        bar.set_style(
            ProgressStyle::with_template("{spinner} {elapsed_precise} [{wide_bar}] {pos}/{len} steps, ETA {eta}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        Self {
            bar,
            started: Instant::now(),
            enabled,
            shown: false,
        }
    }
    fn update(&mut self, step: usize) {
        if !step.is_multiple_of(64) {
            return;
        }
        if self.enabled && !self.shown && self.started.elapsed() > Duration::from_secs(1) {
            self.bar.set_draw_target(ProgressDrawTarget::stderr());
            self.shown = true;
        }
        self.bar.set_position(step as u64);
    }
}

pub fn run(args: &RunArgs) -> Result<()> {
    let mut def = match &args.config {
        None => TestDefinition::from_toml(DEFAULT_CONFIG, DEFAULT_CONFIG_NAME, Path::new("."))?,
        Some(p) => TestDefinition::from_file(p)?,
    };
    let out_dir = args
        .out
        .clone()
        .or_else(|| def.output.dir.clone())
        .unwrap_or_else(|| PathBuf::from("results"));
    let format = args
        .plot_format
        .or_else(|| {
            def.output
                .plot_options
                .format
                .as_deref()
                .and_then(crate::plots::PlotFormat::from_name)
        })
        .unwrap_or(crate::plots::PlotFormat::Png);
    crate::plots::set_format(format);
    if args.realtime {
        let name = args
            .config
            .as_ref()
            .map_or(DEFAULT_CONFIG_NAME.to_string(), |p| p.display().to_string());
        return crate::realtime::run_realtime(args, &def, out_dir, name);
    }
    let config_name = args
        .config
        .as_ref()
        .map_or(DEFAULT_CONFIG_NAME.to_string(), |p| p.display().to_string());
    let mut live = Live::start(args, &mut def, &config_name, false)?;
    let mut sim = Simulation::new(&def)?;
    let mut reference = Reference::new(&def)?;
    let n = def.model.n_dofs();
    let steps = def.integrator.steps;
    let coupling: Vec<usize> = def
        .substructure
        .as_ref()
        .map_or_else(Vec::new, |s| s.coupling_dofs.clone());
    if !args.quiet {
        print_header(args, &def);
    }

    // Everything above is validation; from here on outputs are written.
    let cannot_write = |p: &Path| format!("cannot write {}", p.display());
    // No output of an earlier run survives into this one (a stopped run must not leave an old
    // `completed: true`, nor substeps.csv or plots it did not write).
    prepare_dir(&out_dir)?;
    let summary_path = out_dir.join("summary.json");
    let history_path = out_dir.join("history.csv");
    let mut groups = extra_groups(&def);
    let stability_at = groups.len() * coupling.len();
    if live.has_indicator() {
        groups.extend(STABILITY_GROUPS);
    }
    let mut live_warnings: Vec<String> = Vec::new();
    let mut extra = vec![0.0; groups.len() * coupling.len()];
    let mut history = HistoryWriter::create(&history_path, n, coupling.len(), &groups, reference.is_some())
        .with_context(|| cannot_write(&history_path))?;
    let substeps_path = out_dir.join("substeps.csv");
    let mut substep_writer = match &def.substructure {
        Some(s) => Some(
            SubstepWriter::create(
                &substeps_path,
                coupling.len(),
                def.integrator.dt,
                s.substeps,
                s.phase_lag.is_some(),
                s.limits.is_some(),
            )
            .with_context(|| cannot_write(&substeps_path))?,
        ),
        None => None,
    };
    let mut outputs = vec![history_path.clone()];
    if substep_writer.is_some() {
        outputs.push(substeps_path.clone());
    }

    // Until the run ends, summary.json says it is in progress: a killed process leaves a
    // summary that does not claim completion, and history rows flushed up to the last ~0.5 s.
    let running = serde_json::json!({
        "completed": false,
        "status": "running (a run that was killed leaves this summary; history.csv holds the steps flushed so far)",
        "config": args.config.as_ref().map_or(DEFAULT_CONFIG_NAME.to_string(), |p| p.display().to_string()),
    });
    write_atomic(&summary_path, (running.to_string() + "\n").as_bytes())
        .with_context(|| cannot_write(&summary_path))?;
    let mut last_flush = Instant::now();

    let mut recorder = Recorder::new(n, &coupling);
    let mut engineering = crate::engineering::Engineering::create(&def, &out_dir)?;
    let substep_length = def
        .substructure
        .as_ref()
        .map_or(def.integrator.dt, |s| def.integrator.dt / s.substeps as f64);
    let mut tracking = TrackingMetrics::new(coupling.len(), substep_length);
    // t, f_u, its ideal value and the tracking error of the first coupling DOF.
    let mut comp_table = Decimated::new(4, PLOT_ROWS);
    let mut progress = Progress::new(steps, !args.quiet);
    let mut compute = Duration::ZERO;
    let mut failure: Option<substep::Error> = None;
    loop {
        let i = sim.steps_done();
        extra_values(&sim, &groups, &mut extra);
        let next = live.tick(
            &mut sim,
            reference.as_ref(),
            &coupling,
            &mut extra[stability_at..],
            &mut |w| {
                if !args.quiet {
                    println!("  warning: {w}");
                }
                live_warnings.push(w);
            },
        );
        history
            .row(
                sim.time(),
                sim.state(),
                sim.coupling().as_ref(),
                &extra,
                reference.as_ref().map(|r| r.u()),
            )
            .with_context(|| cannot_write(&history_path))?;
        recorder.record(&sim, reference.as_ref());
        if let Some(e) = &mut engineering {
            e.record(&sim)?;
        }
        if let Some(rec) = sim.coupling() {
            let first_of = |name: &str| {
                groups
                    .iter()
                    .position(|g| *g == name)
                    .map_or(f64::NAN, |g| extra[g * coupling.len()])
            };
            comp_table.push(&[sim.time(), rec.compensation_force[0], first_of("fei"), first_of("te")]);
        }
        if let Next::Abort(e) = next {
            failure = Some(e);
            break;
        }
        if i == steps {
            break;
        }
        progress.update(i);
        if last_flush.elapsed() > Duration::from_millis(500) {
            history.flush().with_context(|| cannot_write(&history_path))?;
            if let Some(w) = &mut substep_writer {
                w.flush().with_context(|| cannot_write(&substeps_path))?;
            }
            last_flush = Instant::now();
        }
        let t0 = Instant::now();
        let result = match &mut substep_writer {
            Some(w) => sim.step(&mut Both(w, &mut Both(&mut tracking, &mut live.last))),
            None => sim.step(&mut Both(&mut tracking, &mut live.last)),
        };
        compute += t0.elapsed();
        if let Err(e) = result {
            failure = Some(e);
            break;
        }
        if let Some(r) = &mut reference {
            r.step(sim.ground_acceleration(i + 1));
        }
    }
    progress.bar.finish_and_clear();
    let wall = progress.started.elapsed().as_secs_f64();
    history.finish().with_context(|| cannot_write(&history_path))?;
    let ramp_substeps = substep_writer.as_ref().map_or(0, SubstepWriter::ramp_rows);
    if let Some(w) = substep_writer {
        w.finish().with_context(|| cannot_write(&substeps_path))?;
    }
    let done = sim.steps_done();

    let plot_opts = &def.output.plot_options;
    let plotting = def.output.plots && !args.no_plots;
    if let Some(e) = &mut engineering {
        outputs.push(e.finish()?);
    }
    let (gm_files, gm_figures, gm_summary) = crate::engineering::ground_motion_outputs(&def, &out_dir)?;
    outputs.extend(gm_files);
    if plotting && recorder.table.rows() > 1 {
        let mut figures: Vec<(&str, Figure)> = recorder
            .charts(reference.as_ref().map(|r| r.scheme()), plot_opts.window)
            .into_iter()
            .map(|c| (c.file, c.figure))
            .collect();
        if let Some(e) = &engineering {
            figures.extend(e.figures());
        }
        figures.extend(gm_figures);
        for (file, fig) in figures {
            if plot_opts.wants(file) {
                outputs.push(crate::plots::figure(&out_dir.join(file), &fig)?);
            }
        }
    }
    if plotting && comp_table.rows() > 1 {
        for path in compensation_charts(&def, &comp_table, &out_dir)? {
            outputs.push(path);
        }
    }
    outputs.push(summary_path.clone());

    let (stopped_at_step, reason) = match &failure {
        Some(substep::Error::Diverged { step, reason, .. } | substep::Error::Stopped { step, reason, .. }) => {
            (Some(*step), Some(reason.clone()))
        }
        Some(e) => (Some(done + 1), Some(e.to_string())),
        None => (None, None),
    };
    let (estimation, phase_lag, mut warnings) = compensation_summary(&sim);
    warnings.extend(live_warnings);
    let stopped_by = match &failure {
        Some(substep::Error::Stopped { reason, .. }) => Some(
            live.stopped_by
                .unwrap_or(if reason.starts_with("safety stop") {
                    "safety_limit"
                } else {
                    "site"
                })
                .to_string(),
        ),
        Some(substep::Error::Diverged { .. }) => Some("diverged".to_string()),
        _ => None,
    };
    let summary = Summary {
        config: match &args.config {
            None => DEFAULT_CONFIG_NAME.to_string(),
            Some(p) => p.display().to_string(),
        },
        scheme: def.integrator.name.clone(),
        dt: def.integrator.dt,
        steps,
        duration: def.time(steps),
        n_dofs: n,
        ground_motion: def.ground_motion.description.clone(),
        substructure: def.substructure.as_ref().map(substructure_json),
        completed: failure.is_none(),
        steps_done: done,
        stopped_at_step,
        reason,
        stopped_by,
        ramp_substeps: (ramp_substeps > 0).then_some(ramp_substeps),
        wall_time_s: wall,
        us_per_step: compute.as_secs_f64() * 1e6 / done.max(1) as f64,
        peaks: (0..n)
            .map(|k| DofPeaks {
                dof: k + 1,
                u: recorder.peak_u.0[k],
                v: recorder.peak_v.0[k],
                a: recorder.peak_a.0[k],
            })
            .collect(),
        coupling_peaks: def.substructure.as_ref().map(|_| {
            coupling
                .iter()
                .enumerate()
                .map(|(k, &c)| CouplingPeaks {
                    dof: c + 1,
                    force: recorder.peak_fc.0[k],
                    error_force: recorder.peak_fe.0[k],
                })
                .collect()
        }),
        tracking: def.substructure.as_ref().map(|_| {
            coupling
                .iter()
                .enumerate()
                .map(|(k, &c)| {
                    let t = tracking.result(k);
                    TrackingSummary {
                        dof: c + 1,
                        delay_s: t.delay,
                        max_delay_s: t.max_delay,
                        nrms_error: t.nrms,
                        peak_error: t.peak,
                    }
                })
                .collect()
        }),
        reference: reference.as_ref().map(|r| recorder.reference_summary(r)),
        estimation,
        phase_lag,
        warnings,
        input_motion: gm_summary,
        engineering: engineering.as_ref().map(|e| e.summary()),
        stability: live.summary(),
        outputs: outputs.iter().map(|p| p.display().to_string()).collect(),
    };
    let json = serde_json::to_string_pretty(&summary).expect("summary serialises");
    write_atomic(&summary_path, (json + "\n").as_bytes()).with_context(|| cannot_write(&summary_path))?;

    if !args.quiet {
        match &failure {
            None => println!(
                "  completed {done} steps in {wall:.3} s wall time ({:.2} µs per step of computation)",
                summary.us_per_step
            ),
            Some(e) => println!("  STOPPED after {done} of {steps} steps: {e}"),
        }
        if ramp_substeps > 0 {
            println!(
                "  the {ramp_substeps} sub-steps of the ramp to the safe position are in substeps.csv (column ramp)"
            );
        }
        recorder.print();
        if let Some(e) = &summary.estimation {
            println!(
                "  error-force estimation: {} of {} steps closed with the estimate",
                e["estimated"], e["steps"]
            );
        }
        for w in &summary.warnings {
            println!("  warning: {w}");
        }
        if let Some(r) = &summary.reference {
            let what = if r.scheme == "exact" {
                "exact solution"
            } else {
                "monolithic Newmark solution"
            };
            println!(
                "  max error vs {what}: {} % (displacement), {} % (coupling force)",
                percent(r.max_displacement_error),
                percent(r.max_force_error)
            );
            println!(
                "    (largest |test − reference| over the run and all DOFs, relative to that DOF's peak |reference|)"
            );
        }
        if let Some(e) = &engineering {
            for line in e.lines() {
                println!("{line}");
            }
        }
        let names: Vec<String> = outputs
            .iter()
            .map(|p| {
                p.file_name()
                    .map_or_else(String::new, |f| f.to_string_lossy().into_owned())
            })
            .collect();
        println!("  outputs in {}: {}", out_dir.display(), names.join(", "));
    }
    live.finish(
        json!({ "completed": summary.completed, "reason": summary.reason, "stopped_by": summary.stopped_by,
                "steps_done": done, "steps": steps }),
        &outputs,
        args.quiet,
    );
    match failure {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plotted_dofs_are_distinct_and_bounded() {
        assert_eq!(plotted_dofs(1, &[0]), vec![0]);
        assert_eq!(plotted_dofs(10, &[]), vec![9, 0]);
        assert_eq!(plotted_dofs(10, &[3, 5, 7, 8, 9]), vec![3, 5, 7, 9]);
        assert_eq!(plotted_dofs(3, &[2]), vec![2, 0]);
    }
}
