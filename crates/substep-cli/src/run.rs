//! `substep run`: load a test definition, step it, record `history.csv`, `substeps.csv`,
//! `summary.json` and the plots, compare with the monolithic reference, print a summary.

use crate::output::{Decimated, ErrorStats, ErrorTracker, HistoryWriter, Peak, PeakTracker, SubstepWriter};
use crate::plots::{Curve, line_chart};
use crate::{DEFAULT_CONFIG, DEFAULT_CONFIG_NAME, RunArgs};
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use substep::io::{Reference, Simulation, SubstructureDefinition, TestDefinition};
use substep::specimen::SpecimenSpec;
use substep::substructure::ErrorForceSpec;
use substep::transfer::Dynamics;

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
}

#[derive(Debug, Serialize)]
struct CouplingError {
    dof: usize,
    displacement: ErrorStats,
    force: ErrorStats,
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
    /// Wall time of the stepping loop including recording [s].
    wall_time_s: f64,
    /// Compute time of the simulation steps alone per step [µs].
    us_per_step: f64,
    peaks: Vec<DofPeaks>,
    #[serde(skip_serializing_if = "Option::is_none")]
    coupling_peaks: Option<Vec<CouplingPeaks>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    reference: Option<ReferenceSummary>,
    outputs: Vec<String>,
}

fn substructure_json(s: &SubstructureDefinition) -> Value {
    let a = s.actuator;
    let actuator = match a.dynamics {
        Dynamics::Ideal => json!({ "kind": "ideal", "delay": a.delay }),
        Dynamics::FirstOrder { time_constant } => {
            json!({ "kind": "first_order", "time_constant": time_constant, "delay": a.delay })
        }
        Dynamics::SecondOrder { frequency_hz, zeta } => {
            json!({ "kind": "second_order", "frequency": frequency_hz, "zeta": zeta, "delay": a.delay })
        }
    };
    let error_force = match s.error_force {
        ErrorForceSpec::None => json!({ "kind": "none" }),
        ErrorForceSpec::Pid { p, i, d } => json!({ "kind": "pid", "p": p, "i": i, "d": d }),
        ErrorForceSpec::PidResidual { p } => json!({ "kind": "pid_residual", "p": p }),
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
        },
        "error_force": error_force,
    })
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

fn path_list(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

pub fn run(args: &RunArgs) -> Result<()> {
    let def = match &args.config {
        None => TestDefinition::from_toml(DEFAULT_CONFIG, DEFAULT_CONFIG_NAME, Path::new("."))?,
        Some(p) => TestDefinition::from_file(p)?,
    };
    let out_dir = args
        .out
        .clone()
        .or_else(|| def.output.dir.clone())
        .unwrap_or_else(|| PathBuf::from("results"));
    let draw_plots = def.output.plots && !args.no_plots;
    let mut sim = Simulation::new(&def)?;
    let mut reference = Reference::new(&def)?;

    let n = def.model.n_dofs();
    let dt = def.integrator.dt;
    let steps = def.integrator.steps;
    let sub = def.substructure.as_ref();
    let coupling: Vec<usize> = sub.map_or_else(Vec::new, |s| s.coupling_dofs.clone());
    let n_c = coupling.len();

    if !args.quiet {
        match &args.config {
            None => println!(
                "substep run: no config given, running the embedded default example (examples/default.toml):\n  \
                 the typical TMD system as a virtual substructure test"
            ),
            Some(p) => println!("substep run: {}", p.display()),
        }
        let kind = match sub {
            None => format!("monolithic, scheme {}", def.integrator.name),
            Some(s) => format!(
                "substructured, scheme {}, coupling DOF(s) {:?}, k_sub = {}",
                def.integrator.name,
                coupling.iter().map(|c| c + 1).collect::<Vec<_>>(),
                s.substeps
            ),
        };
        println!("  model: {n} DOF(s), {kind}");
        println!(
            "  ground motion: {}; dt = {dt} s, {steps} steps ({} s)",
            def.ground_motion.description,
            def.time(steps)
        );
    }

    std::fs::create_dir_all(&out_dir).with_context(|| format!("cannot create {}", out_dir.display()))?;
    // A summary from an earlier run must not survive a run that stops early.
    let summary_path = out_dir.join("summary.json");
    if summary_path.exists() {
        std::fs::remove_file(&summary_path).with_context(|| format!("cannot remove {}", summary_path.display()))?;
    }
    let history_path = out_dir.join("history.csv");
    let mut history = HistoryWriter::create(&history_path, n, n_c, reference.is_some())
        .with_context(|| format!("cannot write {}", history_path.display()))?;
    let substeps_path = out_dir.join("substeps.csv");
    let mut substep_writer = match sub {
        Some(s) => Some(
            SubstepWriter::create(&substeps_path, n_c, dt, s.substeps)
                .with_context(|| format!("cannot write {}", substeps_path.display()))?,
        ),
        None => None,
    };
    let mut outputs = vec![history_path.clone()];
    if substep_writer.is_some() {
        outputs.push(substeps_path.clone());
    }

    // Plot table: t, u(sel), a(sel), then per coupling DOF fc, fe, dm, uref.
    let sel = plotted_dofs(n, &coupling);
    let n_sel = sel.len();
    let width = 1 + 2 * n_sel + 4 * n_c;
    let mut table = Decimated::new(width, PLOT_ROWS);
    let mut row = vec![0.0; width];

    let mut peak_u = PeakTracker::new(n);
    let mut peak_v = PeakTracker::new(n);
    let mut peak_a = PeakTracker::new(n);
    let mut peak_fc = PeakTracker::new(n_c);
    let mut peak_fe = PeakTracker::new(n_c);
    let mut err_u = ErrorTracker::new(n);
    let mut err_f = ErrorTracker::new(n_c);

    let progress = ProgressBar::with_draw_target(Some(steps as u64), ProgressDrawTarget::hidden());
    progress.set_style(
        ProgressStyle::with_template("{spinner} {elapsed_precise} [{wide_bar}] {pos}/{len} steps, ETA {eta}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    let mut progress_shown = false;

    let started = Instant::now();
    let mut compute = Duration::ZERO;
    let mut failure: Option<substep::Error> = None;
    let mut coupling_f: Vec<f64> = vec![0.0; n_c];
    loop {
        let i = sim.steps_done();
        let t = sim.time();
        let state = sim.state();
        let record = sim.coupling();
        let reference_u = reference.as_ref().map(|r| r.u());
        history
            .row(t, state, record.as_ref(), reference_u)
            .with_context(|| format!("cannot write {}", history_path.display()))?;
        peak_u.update(state.u.as_slice(), t);
        peak_v.update(state.v.as_slice(), t);
        peak_a.update(state.a.as_slice(), t);
        row[0] = t;
        for (k, &d) in sel.iter().enumerate() {
            row[1 + k] = state.u[d];
            row[1 + n_sel + k] = state.a[d];
        }
        if let Some(rec) = &record {
            peak_fc.update(rec.coupling_force, t);
            peak_fe.update(rec.error_force, t);
            coupling_f.copy_from_slice(rec.coupling_force);
            let base = 1 + 2 * n_sel;
            for k in 0..n_c {
                row[base + 4 * k] = rec.coupling_force[k];
                row[base + 4 * k + 1] = rec.error_force[k];
                row[base + 4 * k + 2] = rec.measured_displacement[k];
                row[base + 4 * k + 3] = reference.as_ref().map_or(f64::NAN, |r| r.u()[coupling[k]]);
            }
        }
        if let Some(r) = &reference {
            err_u.update(state.u.as_slice(), r.u());
            err_f.update(&coupling_f, r.coupling_force());
        }
        table.push(&row);

        if i == steps {
            break;
        }
        if i % 64 == 0 {
            if !progress_shown && !args.quiet && started.elapsed() > Duration::from_secs(1) {
                progress.set_draw_target(ProgressDrawTarget::stderr());
                progress_shown = true;
            }
            progress.set_position(i as u64);
        }
        let t0 = Instant::now();
        let result = match &mut substep_writer {
            Some(w) => sim.step(w),
            None => sim.step(&mut ()),
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
    progress.finish_and_clear();
    let wall = started.elapsed().as_secs_f64();
    history
        .finish()
        .with_context(|| format!("cannot write {}", history_path.display()))?;
    if let Some(w) = substep_writer {
        w.finish()
            .with_context(|| format!("cannot write {}", substeps_path.display()))?;
    }
    let done = sim.steps_done();

    // Summary.
    let reference_summary = reference.as_ref().map(|r| {
        let dofs: Vec<DofError> = (0..n)
            .map(|k| DofError {
                dof: k + 1,
                displacement: err_u.stats(k),
            })
            .collect();
        let coupling_err: Vec<CouplingError> = (0..n_c)
            .map(|k| CouplingError {
                dof: coupling[k] + 1,
                displacement: err_u.stats(coupling[k]),
                force: err_f.stats(k),
            })
            .collect();
        let max = |it: &mut dyn Iterator<Item = f64>| it.filter(|x| x.is_finite()).fold(0.0, f64::max);
        ReferenceSummary {
            scheme: r.scheme(),
            n_dofs: r.n_dofs(),
            max_displacement_error: max(&mut dofs.iter().map(|d| d.displacement.peak_error)),
            max_force_error: max(&mut coupling_err.iter().map(|c| c.force.peak_error)),
            dofs,
            coupling: coupling_err,
        }
    });
    let (stopped_at_step, reason) = match &failure {
        Some(substep::Error::Diverged { step, reason, .. }) => (Some(*step), Some(reason.clone())),
        Some(e) => (Some(done + 1), Some(e.to_string())),
        None => (None, None),
    };

    let mut plot_paths = Vec::new();
    if draw_plots && table.rows() > 1 {
        let time = table.column(0);
        let curves = |offset: usize| -> Vec<Curve> {
            sel.iter()
                .enumerate()
                .map(|(k, &d)| Curve {
                    label: format!("DOF {}", d + 1),
                    x: time.clone(),
                    y: table.column(offset + k),
                })
                .collect()
        };
        let mut charts: Vec<(&str, String, &str, Vec<Curve>, &str)> = vec![
            (
                "displacement.png",
                "Relative displacement".into(),
                "displacement u [m]",
                curves(1),
                "time t [s]",
            ),
            (
                "acceleration.png",
                "Relative acceleration".into(),
                "acceleration a [m/s²]",
                curves(1 + n_sel),
                "time t [s]",
            ),
        ];
        if n_c > 0 {
            let base = 1 + 2 * n_sel;
            let per_coupling = |j: usize, x: &dyn Fn(usize) -> Vec<f64>| -> Vec<Curve> {
                (0..n_c.min(MAX_CURVES))
                    .map(|k| Curve {
                        label: format!("DOF {}", coupling[k] + 1),
                        x: x(k),
                        y: table.column(base + 4 * k + j),
                    })
                    .collect()
            };
            let t_of = |_k: usize| time.clone();
            let dm_of = |k: usize| table.column(base + 4 * k + 2);
            charts.push((
                "coupling_force.png",
                "Measured coupling force on the structure".into(),
                "force f_c [N]",
                per_coupling(0, &t_of),
                "time t [s]",
            ));
            charts.push((
                "error_force.png",
                "Error force f(k) − f(k−1)".into(),
                "error force [N]",
                per_coupling(1, &t_of),
                "time t [s]",
            ));
            charts.push((
                "hysteresis.png",
                "Coupling force vs measured displacement".into(),
                "force f_c [N]",
                per_coupling(0, &dm_of),
                "measured displacement d_m [m]",
            ));
            if let Some(r) = &reference {
                let k = 0;
                charts.push((
                    "reference.png",
                    format!(
                        "DOF {}: substructure test vs reference ({})",
                        coupling[k] + 1,
                        r.scheme()
                    ),
                    "displacement u [m]",
                    vec![
                        Curve {
                            label: format!("reference ({})", r.scheme()),
                            x: time.clone(),
                            y: table.column(base + 4 * k + 3),
                        },
                        Curve {
                            label: "substructure test".into(),
                            x: time.clone(),
                            y: table.column(
                                1 + sel
                                    .iter()
                                    .position(|&d| d == coupling[k])
                                    .expect("coupling DOF is plotted"),
                            ),
                        },
                    ],
                    "time t [s]",
                ));
            }
        }
        for (file, title, y_label, curves, x_label) in charts {
            let path = out_dir.join(file);
            line_chart(&path, &title, x_label, y_label, &curves)?;
            plot_paths.push(path);
        }
    }
    outputs.extend(plot_paths.iter().cloned());
    outputs.push(summary_path.clone());

    let summary = Summary {
        config: match &args.config {
            None => DEFAULT_CONFIG_NAME.to_string(),
            Some(p) => p.display().to_string(),
        },
        scheme: def.integrator.name.clone(),
        dt,
        steps,
        duration: def.time(steps),
        n_dofs: n,
        ground_motion: def.ground_motion.description.clone(),
        substructure: sub.map(substructure_json),
        completed: failure.is_none(),
        steps_done: done,
        stopped_at_step,
        reason: reason.clone(),
        wall_time_s: wall,
        us_per_step: compute.as_secs_f64() * 1e6 / done.max(1) as f64,
        peaks: (0..n)
            .map(|k| DofPeaks {
                dof: k + 1,
                u: peak_u.0[k],
                v: peak_v.0[k],
                a: peak_a.0[k],
            })
            .collect(),
        coupling_peaks: sub.map(|_| {
            (0..n_c)
                .map(|k| CouplingPeaks {
                    dof: coupling[k] + 1,
                    force: peak_fc.0[k],
                    error_force: peak_fe.0[k],
                })
                .collect()
        }),
        reference: reference_summary,
        outputs: outputs.iter().map(|p| p.display().to_string()).collect(),
    };
    let json = serde_json::to_string_pretty(&summary).expect("summary serialises");
    std::fs::write(&summary_path, json + "\n").with_context(|| format!("cannot write {}", summary_path.display()))?;

    if !args.quiet {
        match &failure {
            None => println!(
                "  completed {done} steps in {wall:.3} s wall time ({:.2} µs per step of computation)",
                summary.us_per_step
            ),
            Some(e) => println!("  STOPPED after {done} of {steps} steps: {e}"),
        }
        let show = |name: &str, unit: &str, p: &PeakTracker| {
            let (k, peak) = p.largest();
            println!(
                "  peak |{name}| = {:.4e} {unit} (DOF {}, t = {:.3} s)",
                peak.max_abs,
                k + 1,
                peak.t
            );
        };
        show("u", "m", &peak_u);
        show("v", "m/s", &peak_v);
        show("a", "m/s²", &peak_a);
        if n_c > 0 {
            let (k, p) = peak_fc.largest();
            let (ke, pe) = peak_fe.largest();
            println!(
                "  peak coupling force {:.4e} N (DOF {}, t = {:.3} s), peak |error force| {:.4e} N (DOF {})",
                p.max_abs,
                coupling[k] + 1,
                p.t,
                pe.max_abs,
                coupling[ke] + 1
            );
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
        }
        println!("  outputs in {}: {}", out_dir.display(), {
            let names: Vec<PathBuf> = outputs
                .iter()
                .map(|p| p.file_name().map(PathBuf::from).unwrap_or_default())
                .collect();
            path_list(&names)
        });
    }
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
