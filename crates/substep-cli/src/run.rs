//! `substep run`: load a test definition, run it ([`substep::run`]: the step loop, the
//! reference and the summary), stream `history.csv`, `substeps.csv` and `response.csv` to the
//! output directory, draw the plots, write `summary.json` and print a summary.

use crate::engineering::{ResponseWriter, ground_motion_outputs};
use crate::monitor::live::{Live, LiveObserver};
use crate::output::{Decimated, HistoryWriter, SubstepWriter, prepare_dir, write_atomic};
use crate::plots::{Curve, Figure, Panel, line_chart, output_path};
use crate::{DEFAULT_CONFIG, DEFAULT_CONFIG_NAME, RunArgs};
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use substep::format::percent;
use substep::io::TestDefinition;
use substep::run::{Layout, Run, RunObserver, RunSummary, StepRow, largest};
use substep::substructure::ErrorForceSpec;
use substep::substructure::SubstepObserver;

/// Rows kept for the plots (decimated beyond that).
const PLOT_ROWS: usize = 20_000;
/// Curves per displacement / acceleration chart.
const MAX_CURVES: usize = 4;

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

/// The summary's line on the error against the reference (offline and real-time runs).
pub(crate) fn print_reference_error(scheme: &str, max_displacement_error: f64, max_force_error: f64) {
    let what = match scheme {
        "exact" => "exact solution",
        "newmark_newton" => "monolithic Newmark + Newton solution (nonlinear)",
        _ => "monolithic Newmark solution",
    };
    println!(
        "  max error vs {what}: {} (displacement), {} (coupling force)",
        percent(max_displacement_error),
        percent(max_force_error)
    );
    println!("    (largest |test − reference| over the run and all DOFs, relative to that DOF's peak |reference|)");
}

/// The summary's line on the time step's share of the error (against the exact reference, or
/// the converged Newton one of a nonlinear structure, `reference`).
pub(crate) fn print_time_step_share(scheme: &str, reference: &str, split: &substep::run::SameIntegratorSummary) {
    let against = if reference == "exact" { "exact" } else { "Newton" };
    println!(
        "    the time step alone: {} (the assembled structure integrated with this test's {scheme} scheme and Δt \
         vs {against}); the substructure test vs that solution: {}",
        percent(split.integration_error),
        percent(split.max_displacement_error)
    );
}

/// The series kept for the plots: a decimated table `t, u(sel), a(sel), [fc, fe, dm, uref] per
/// coupling DOF`.
struct PlotRecorder {
    /// Plotted DOFs (0-based) and coupling DOFs (0-based).
    sel: Vec<usize>,
    coupling: Vec<usize>,
    table: Decimated,
    row: Vec<f64>,
}

impl PlotRecorder {
    fn new(n: usize, coupling: &[usize]) -> Self {
        let sel = plotted_dofs(n, coupling);
        let n_c = coupling.len();
        let width = 1 + 2 * sel.len() + 4 * n_c;
        Self {
            sel,
            coupling: coupling.to_vec(),
            table: Decimated::new(width, PLOT_ROWS),
            row: vec![0.0; width],
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

    fn record(&mut self, r: &StepRow<'_>) {
        self.row[0] = r.t;
        for k in 0..self.sel.len() {
            let (cu, ca) = (self.col_u(k), self.col_a(k));
            self.row[cu] = r.u[self.sel[k]];
            self.row[ca] = r.a[self.sel[k]];
        }
        if let Some(rec) = &r.coupling {
            for k in 0..self.coupling.len() {
                let c = self.col_coupling(k, 0);
                self.row[c] = rec.coupling_force[k];
                self.row[c + 1] = rec.error_force[k];
                self.row[c + 2] = rec.measured_displacement[k];
                self.row[c + 3] = r.reference.map_or(f64::NAN, |u| u[self.coupling[k]]);
            }
        }
        self.table.push(&self.row);
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
                "measured specimen displacement d_m [m]",
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
                        &format!("time t (zoom on {z0:.2} … {z1:.2} s) [s]"),
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
}

/// The peaks of the summary on stdout.
fn print_peaks(s: &RunSummary) {
    let show = |name: &str, unit: &str, (k, peak): (usize, substep::run::Peak)| {
        println!(
            "  peak {name} = {} {unit} (DOF {}, t = {:.3} s)",
            fixed(peak.max_abs),
            k + 1,
            peak.t
        );
    };
    show("relative displacement |u|", "m", largest(s.peaks.iter().map(|p| p.u)));
    show("relative velocity |u̇|", "m/s", largest(s.peaks.iter().map(|p| p.v)));
    show(
        "relative acceleration |ü|",
        "m/s²",
        largest(s.peaks.iter().map(|p| p.a)),
    );
    if let Some(c) = s.coupling_peaks.as_ref().filter(|c| !c.is_empty()) {
        let (k, p) = largest(c.iter().map(|p| p.force));
        let (ke, pe) = largest(c.iter().map(|p| p.error_force));
        println!(
            "  peak coupling force |f_c| = {} N (DOF {}, t = {:.3} s), peak |error force| = {} N (DOF {})",
            fixed(p.max_abs),
            c[k].dof,
            p.t,
            fixed(pe.max_abs),
            c[ke].dof
        );
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
    if let Some(t) = def.substructure.as_ref().and_then(|s| s.lab_target.as_ref()) {
        println!(
            "  experimental side: lab target at {} ({} over {}, exchange timeout {} ms, up to {} held sub-steps in a row)",
            t.address,
            t.protocol.name(),
            t.transport.name(),
            t.timeout.as_secs_f64() * 1e3,
            t.hold_limit
        );
    }
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

/// The CLI's observer of a run: streams the rows to `history.csv`, `substeps.csv` and
/// `response.csv`, keeps the decimated series for the plots, shows the progress and flushes
/// the files every ~0.5 s (a killed run leaves the rows up to then). A write error stops the
/// run; it is kept in `error`.
struct CliObserver {
    history: HistoryWriter,
    history_path: PathBuf,
    substeps: Option<SubstepWriter>,
    substeps_path: PathBuf,
    response: Option<ResponseWriter>,
    plot: PlotRecorder,
    /// t, f_u, its ideal value and the tracking error of the first coupling DOF.
    comp_table: Decimated,
    /// Columns of the first coupling DOF's `fei` and `te` in the extra groups.
    fei: Option<usize>,
    te: Option<usize>,
    steps: usize,
    progress: Progress,
    last_flush: Instant,
    error: Option<anyhow::Error>,
}

fn cannot_write(p: &Path) -> String {
    format!("cannot write {}", p.display())
}

impl CliObserver {
    fn create(def: &TestDefinition, layout: &Layout, dir: &Path, progress: bool) -> Result<Self> {
        let history_path = dir.join("history.csv");
        let history = HistoryWriter::create(&history_path, &layout.history_columns())
            .with_context(|| cannot_write(&history_path))?;
        let substeps_path = dir.join("substeps.csv");
        let substeps = match layout.substeps {
            Some(_) => {
                Some(SubstepWriter::create(&substeps_path, layout).with_context(|| cannot_write(&substeps_path))?)
            }
            None => None,
        };
        let response = match &layout.response_columns {
            Some(columns) => Some(ResponseWriter::create(
                columns,
                dir,
                def.hysteresis.as_ref().map_or(0, |_| def.model.n_dofs()),
            )?),
            None => None,
        };
        let n_c = layout.coupling_dofs.len();
        let first_of = |name: &str| layout.extra_groups.iter().position(|g| *g == name).map(|g| g * n_c);
        let steps = def.integrator.steps;
        Ok(Self {
            history,
            history_path,
            substeps,
            substeps_path,
            response,
            plot: PlotRecorder::new(layout.n_dofs, &layout.coupling_dofs),
            comp_table: Decimated::new(4, PLOT_ROWS),
            fei: first_of("fei"),
            te: first_of("te"),
            steps,
            progress: Progress::new(steps, progress),
            last_flush: Instant::now(),
            error: None,
        })
    }

    fn write(&mut self, row: &StepRow<'_>) -> Result<()> {
        self.history
            .row(row)
            .with_context(|| cannot_write(&self.history_path))?;
        if let (Some(w), Some(e)) = (&mut self.response, &row.engineering) {
            w.record(e)?;
        }
        self.plot.record(row);
        if let Some(rec) = &row.coupling {
            let first = |c: Option<usize>| c.map_or(f64::NAN, |c| row.extra[c]);
            self.comp_table
                .push(&[row.t, rec.compensation_force[0], first(self.fei), first(self.te)]);
        }
        if row.step == self.steps {
            return Ok(());
        }
        self.progress.update(row.step);
        if self.last_flush.elapsed() > Duration::from_millis(500) {
            self.history.flush().with_context(|| cannot_write(&self.history_path))?;
            if let Some(w) = &mut self.substeps {
                w.flush().with_context(|| cannot_write(&self.substeps_path))?;
            }
            self.last_flush = Instant::now();
        }
        Ok(())
    }
}

impl SubstepObserver for CliObserver {
    fn substep(&mut self, step: usize, j: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        if let Some(w) = &mut self.substeps {
            w.substep(step, j, command, force, displacement);
        }
    }
    fn phase_lag(&mut self, tracking_error: &[f64], correction: &[f64]) {
        if let Some(w) = &mut self.substeps {
            w.phase_lag(tracking_error, correction);
        }
    }
    fn lab(&mut self, held: bool, strays: u64) {
        if let Some(w) = &mut self.substeps {
            w.lab(held, strays);
        }
    }
    fn ramp(&mut self, step: usize, j: usize, s: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        if let Some(w) = &mut self.substeps {
            w.ramp(step, j, s, command, force, displacement);
        }
    }
}

impl RunObserver for CliObserver {
    fn step(&mut self, row: &StepRow<'_>) -> ControlFlow<()> {
        match self.write(row) {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => {
                self.error = Some(e);
                ControlFlow::Break(())
            }
        }
    }
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
    let container = crate::container::format(args.format.as_deref(), def.output.format)?;
    let result = run_definition(args, def, out_dir.clone());
    let result = crate::output::no_summary_left_running(&out_dir.join("summary.json"), result);
    crate::container::finish(args, &out_dir, container, result)
}

fn run_definition(args: &RunArgs, mut def: TestDefinition, out_dir: PathBuf) -> Result<()> {
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
    if def.output.plots && !args.no_plots {
        let what = if args.plot_format.is_some() {
            "--plot-format".to_string()
        } else {
            format!("{}: output.plots.format", def.source)
        };
        crate::plots::check_format(format, &what)?;
    }
    crate::plots::set_format(format);
    if args.realtime {
        let name = args
            .config
            .as_ref()
            .map_or(DEFAULT_CONFIG_NAME.to_string(), |p| p.display().to_string());
        return crate::realtime::run_realtime(args, &def, out_dir, name);
    }
    let config_name = def.source.clone();
    let mut live = Live::start(args, &mut def, &config_name, false)?;
    let def = def;
    let mut run = Run::new(&def)?;
    run.set_stability(live.stability_settings.clone())?;
    let layout = run.layout().clone();
    let steps = def.integrator.steps;
    if !args.quiet {
        print_header(args, &def);
    }

    // Everything above is validation; from here on outputs are written.
    // No output of an earlier run survives into this one (a stopped run must not leave an old
    // `completed: true`, nor substeps.csv or plots it did not write).
    prepare_dir(&out_dir)?;
    let summary_path = out_dir.join("summary.json");
    // Until the run ends, summary.json says it is in progress: a killed process leaves a
    // summary that does not claim completion, and history rows flushed up to the last ~0.5 s.
    let running = serde_json::json!({
        "completed": false,
        "status": "running (a run that was killed leaves this summary; history.csv holds the steps flushed so far)",
        "config": def.source,
    });
    let mut observer = CliObserver::create(&def, &layout, &out_dir, !args.quiet)?;
    write_atomic(&summary_path, (running.to_string() + "\n").as_bytes())
        .with_context(|| cannot_write(&summary_path))?;
    let mut watched = LiveObserver {
        inner: &mut observer,
        live: &mut live,
        quiet: args.quiet,
    };
    let mut summary = run.execute(&mut watched, &AtomicBool::new(false));
    if let Some(e) = observer.error.take() {
        return Err(e);
    }
    let CliObserver {
        history,
        history_path,
        substeps,
        substeps_path,
        response,
        plot,
        comp_table,
        progress,
        ..
    } = observer;
    progress.bar.finish_and_clear();
    history.finish().with_context(|| cannot_write(&history_path))?;
    let mut outputs = vec![history_path];
    if let Some(w) = substeps {
        w.finish().with_context(|| cannot_write(&substeps_path))?;
        outputs.push(substeps_path);
    }
    let done = summary.steps_done;

    let plot_opts = &def.output.plot_options;
    let plotting = def.output.plots && !args.no_plots;
    let mut response = response;
    if let Some(w) = &mut response {
        outputs.push(w.finish()?);
    }
    let (gm_files, gm_figures) = match run.input_motion() {
        Some(motion) => ground_motion_outputs(&def, motion, &out_dir)?,
        None => (Vec::new(), Vec::new()),
    };
    outputs.extend(gm_files);
    if plotting && plot.table.rows() > 1 {
        let scheme = summary.reference.as_ref().map(|r| r.scheme);
        let mut figures: Vec<(&str, Figure)> = plot
            .charts(scheme, plot_opts.window)
            .into_iter()
            .map(|c| (c.file, c.figure))
            .collect();
        if let (Some(w), Some(e)) = (&response, &summary.engineering) {
            figures.extend(w.figures(e));
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
    summary.outputs = outputs.iter().map(|p| p.display().to_string()).collect();
    let final_state = serde_json::json!({
        "completed": summary.completed, "reason": summary.reason, "stopped_by": summary.stopped_by,
        "steps_done": summary.steps_done, "steps": summary.steps,
    });
    write_atomic(&summary_path, summary.to_json().as_bytes()).with_context(|| cannot_write(&summary_path))?;

    let failure = summary.failure.take();
    if !args.quiet {
        match &failure {
            None => println!(
                "  completed {done} steps in {:.3} s wall time ({:.2} µs per step of computation)",
                summary.wall_time_s, summary.us_per_step
            ),
            Some(e) => println!("  STOPPED after {done} of {steps} steps: {e}"),
        }
        if let Some(ramp_substeps) = summary.ramp_substeps {
            println!(
                "  the {ramp_substeps} sub-steps of the ramp to the safe position are in substeps.csv (column ramp)"
            );
        }
        print_peaks(&summary);
        if let Some(e) = &summary.estimation {
            println!(
                "  error-force estimation: {} of {} steps closed with the estimate",
                e["estimated"], e["steps"]
            );
        }
        if let Some(l) = &summary.lab {
            println!("  {}", substep::lab::LabStats::summary_line(l));
        }
        for w in &summary.warnings {
            println!("  warning: {w}");
        }
        if let Some(st) = &summary.stability
            && st.alarm_count == 0
        {
            let show = |x: f64, f: &dyn Fn(f64) -> String| if x.is_finite() { f(x) } else { "–".to_string() };
            println!(
                "  stability indicator ({}): no alarm; largest energy ratio η {}, smallest model margin 1 − ρ {}",
                st.action,
                show(st.max_eta, &|x| format!("{x:.3}")),
                show(st.min_margin, &|x| format!("{x:.2e}"))
            );
        }
        if let Some(r) = &summary.reference {
            print_reference_error(r.scheme, r.max_displacement_error, r.max_force_error);
            if let Some(s) = &r.same_integrator {
                print_time_step_share(&summary.scheme, r.scheme, s);
            }
        } else if let Some(why) = substep::run::Reference::unavailable(&def) {
            println!("  no reference solution: {why}");
        }
        if let Some(e) = &summary.engineering {
            for line in crate::engineering::lines(e) {
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
    live.finish(final_state, &outputs, args.quiet);
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
