//! The output folder of a run (`substep run CONFIG --out DIR`, Python's
//! `substep.run(config, out_dir=DIR)`): [`RunFolder`] observes the run ([`crate::run`]: the
//! step loop, the reference and the summary), streams `history.csv`, `substeps.csv` and
//! `response.csv` into the folder, keeps the decimated series for the figures, and at the end
//! writes the ground-motion tables, the figures and `summary.json`. [`run_in_folder`] is the
//! whole run in one call; the CLI adds its printing, progress bar and live monitor around the
//! same calls, so both front ends write the same files byte for byte.

use super::files::{Decimated, HistoryWriter, SubstepWriter, cannot_write, prepare_dir, write_atomic};
use super::response::{ResponseWriter, ground_motion_outputs};
use crate::figure::{Curve, Figure, Panel, PlotFormat, line_chart, output_path};
use crate::io::TestDefinition;
use crate::run::{InputMotion, Layout, Run, RunObserver, RunSummary, StepRow};
use crate::substructure::{ErrorForceSpec, SubstepObserver};
use crate::{Error, Result};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// Rows kept for the plots (decimated beyond that).
const PLOT_ROWS: usize = 20_000;
/// Curves per displacement / acceleration chart.
const MAX_CURVES: usize = 4;

/// `compensation_force.png` (with error-force compensation: f_u and its ideal value, DOF of the
/// first coupling) and `tracking_error.png` (with phase-lag compensation).
fn compensation_charts(
    def: &TestDefinition,
    table: &Decimated,
    dir: &Path,
    format: PlotFormat,
) -> Result<Vec<PathBuf>> {
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
            format,
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
        out.push(output_path(&path, format));
    }
    if s.phase_lag.is_some() && wants("tracking_error") {
        let path = dir.join("tracking_error.png");
        line_chart(
            &path,
            format,
            &format!("DOF {dof}: tracking error d − y (last sub-step of each step)"),
            "time t [s]",
            "tracking error [m]",
            &[Curve {
                label: String::new(),
                x: t,
                y: table.column(3),
            }],
        )?;
        out.push(output_path(&path, format));
    }
    Ok(out)
}

/// The test as the reference figure names it: its scheme, and k_sub for a substructure test
/// (`average_acceleration, k_sub = 4`; `cr, k_sub = 10`).
fn test_label(def: &TestDefinition) -> String {
    match &def.substructure {
        Some(s) => format!("{}, k_sub = {}", def.integrator.name, s.substeps),
        None => def.integrator.name.clone(),
    }
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
    /// `test`: how the reference figure names the test (its scheme and k_sub).
    fn charts(&self, reference: Option<&str>, test: &str, window: Option<(f64, f64)>) -> Vec<Chart> {
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
                    "DOF {}: test ({test}) vs reference ({scheme}): peak error {:.2} % of its peak",
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

struct Chart {
    file: &'static str,
    figure: Figure,
}

/// What a run writes besides its tables: figures (and in which format).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FolderOptions {
    /// Draw the figures (`[output] plots`, unless `--no-plots`); `[output.plots] figures`
    /// chooses which.
    pub plots: bool,
    pub plot_format: PlotFormat,
}

impl FolderOptions {
    /// The test definition's own choice: `[output] plots` and `[output.plots] format` (PNG
    /// unless given), refused up front when this build cannot draw that format.
    pub fn of(def: &TestDefinition) -> Result<Self> {
        let plot_format = match def.output.plot_options.format.as_deref() {
            Some(name) => PlotFormat::from_name(name).ok_or_else(|| {
                Error::invalid(
                    format!("{}: output.plots.format", def.source),
                    format!("unknown format `{name}` (png, svg or pdf)"),
                )
            })?,
            None => PlotFormat::Png,
        };
        let options = Self {
            plots: def.output.plots,
            plot_format,
        };
        options.check(&format!("{}: output.plots.format", def.source))?;
        Ok(options)
    }

    /// A front end's figure options over the definition's: `plots` (the CLI's `--no-plots`
    /// turns them off; Python's `plots=`), `plot_format` with the name of the option that gave
    /// it (`--plot-format`, `plot_format`) over `[output.plots] format`. A format this build
    /// cannot draw is refused, naming that option or the key, when figures are drawn.
    pub fn resolve(def: &TestDefinition, plots: bool, plot_format: Option<(PlotFormat, &str)>) -> Result<Self> {
        match plot_format {
            Some((plot_format, option)) => {
                let options = Self { plots, plot_format };
                options.check(option)?;
                Ok(options)
            }
            None if plots => Self::of(def),
            None => Ok(Self {
                plots,
                plot_format: PlotFormat::Png,
            }),
        }
    }

    /// Refuse a figure format this build cannot draw (`what` names the option).
    pub fn check(&self, what: &str) -> Result<()> {
        if self.plots {
            crate::figure::check_format(self.plot_format, what)?;
        }
        Ok(())
    }
}

/// The observer that writes a run's output folder: streams the rows to `history.csv`,
/// `substeps.csv` and `response.csv`, keeps the decimated series for the figures and flushes
/// the files every ~0.5 s (a killed run leaves the rows up to then). A write error stops the
/// run; [`finish`](Self::finish) returns it.
pub struct RunFolder {
    dir: PathBuf,
    options: FolderOptions,
    summary_path: PathBuf,
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
    /// Called with the step number every 64 steps (a front end's progress bar).
    progress: Option<Box<dyn FnMut(usize)>>,
    last_flush: Instant,
    error: Option<Error>,
}

impl RunFolder {
    /// Empty `dir` of an earlier run's outputs ([`prepare_dir`]), open the tables of `layout`
    /// and write a `summary.json` that says the run is in progress (a killed process leaves a
    /// summary that does not claim completion, and history rows flushed up to the last ~0.5 s).
    pub fn create(def: &TestDefinition, layout: &Layout, dir: &Path, options: FolderOptions) -> Result<Self> {
        // No output of an earlier run survives into this one (a stopped run must not leave an
        // old `completed: true`, nor substeps.csv or plots it did not write).
        prepare_dir(dir)?;
        let history_path = dir.join("history.csv");
        let history = HistoryWriter::create(&history_path, &layout.history_columns())
            .map_err(|e| cannot_write(&history_path, e))?;
        let substeps_path = dir.join("substeps.csv");
        let substeps = match layout.substeps {
            Some(_) => {
                Some(SubstepWriter::create(&substeps_path, layout).map_err(|e| cannot_write(&substeps_path, e))?)
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
        let summary_path = dir.join("summary.json");
        let running = serde_json::json!({
            "completed": false,
            "status": "running (a run that was killed leaves this summary; history.csv holds the steps flushed so far)",
            "config": def.source,
        });
        write_atomic(&summary_path, (running.to_string() + "\n").as_bytes())
            .map_err(|e| cannot_write(&summary_path, e))?;
        let n_c = layout.coupling_dofs.len();
        let first_of = |name: &str| layout.extra_groups.iter().position(|g| *g == name).map(|g| g * n_c);
        Ok(Self {
            dir: dir.to_path_buf(),
            options,
            summary_path,
            history,
            history_path,
            substeps,
            substeps_path,
            response,
            plot: PlotRecorder::new(layout.n_dofs, &layout.coupling_dofs),
            comp_table: Decimated::new(4, PLOT_ROWS),
            fei: first_of("fei"),
            te: first_of("te"),
            steps: def.integrator.steps,
            progress: None,
            last_flush: Instant::now(),
            error: None,
        })
    }

    /// Call `progress` with the step number every 64 steps.
    pub fn with_progress(mut self, progress: Box<dyn FnMut(usize)>) -> Self {
        self.progress = Some(progress);
        self
    }

    /// Where `summary.json` goes.
    pub fn summary_path(&self) -> &Path {
        &self.summary_path
    }

    fn write(&mut self, row: &StepRow<'_>) -> Result<()> {
        self.history.row(row).map_err(|e| cannot_write(&self.history_path, e))?;
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
        if row.step.is_multiple_of(64)
            && let Some(p) = &mut self.progress
        {
            p(row.step);
        }
        if self.last_flush.elapsed() > Duration::from_millis(500) {
            self.history.flush().map_err(|e| cannot_write(&self.history_path, e))?;
            if let Some(w) = &mut self.substeps {
                w.flush().map_err(|e| cannot_write(&self.substeps_path, e))?;
            }
            self.last_flush = Instant::now();
        }
        Ok(())
    }

    /// After the run that ended with `summary`: close the tables, write the ground-motion
    /// tables of `motion`, the figures and `summary.json` (with the list of outputs, also
    /// returned, `summary.json` last). A write error during the run is returned here.
    pub fn finish(
        self,
        def: &TestDefinition,
        motion: Option<&InputMotion>,
        summary: &mut RunSummary,
    ) -> Result<Vec<PathBuf>> {
        if let Some(e) = self.error {
            return Err(e);
        }
        let Self {
            dir,
            options,
            summary_path,
            history,
            history_path,
            substeps,
            substeps_path,
            mut response,
            plot,
            comp_table,
            ..
        } = self;
        history.finish().map_err(|e| cannot_write(&history_path, e))?;
        let mut outputs = vec![history_path];
        if let Some(w) = substeps {
            w.finish().map_err(|e| cannot_write(&substeps_path, e))?;
            outputs.push(substeps_path);
        }
        if let Some(w) = &mut response {
            outputs.push(w.finish()?);
        }
        let (gm_files, gm_figures) = match motion {
            Some(motion) => ground_motion_outputs(def, motion, &dir)?,
            None => (Vec::new(), Vec::new()),
        };
        outputs.extend(gm_files);
        let plot_opts = &def.output.plot_options;
        let format = options.plot_format;
        if options.plots && plot.table.rows() > 1 {
            let scheme = summary.reference.as_ref().map(|r| r.scheme);
            let mut figures: Vec<(&str, Figure)> = plot
                .charts(scheme, &test_label(def), plot_opts.window)
                .into_iter()
                .map(|c| (c.file, c.figure))
                .collect();
            if let (Some(w), Some(e)) = (&response, &summary.engineering) {
                figures.extend(w.figures(e));
            }
            figures.extend(gm_figures);
            for (file, fig) in figures {
                if plot_opts.wants(file) {
                    outputs.push(crate::figure::figure(&dir.join(file), &fig, format)?);
                }
            }
        }
        if options.plots && comp_table.rows() > 1 {
            outputs.extend(compensation_charts(def, &comp_table, &dir, format)?);
        }
        outputs.push(summary_path.clone());
        summary.outputs = outputs.iter().map(|p| p.display().to_string()).collect();
        write_atomic(&summary_path, summary.to_json().as_bytes()).map_err(|e| cannot_write(&summary_path, e))?;
        Ok(outputs)
    }
}

impl SubstepObserver for RunFolder {
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

impl RunObserver for RunFolder {
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

/// A finished run in a folder: its summary (with `outputs`) and the files written.
#[derive(Debug)]
pub struct FolderRun {
    pub summary: RunSummary,
    pub outputs: Vec<PathBuf>,
}

/// Run `def` into `dir` in one call (what `substep run CONFIG --out DIR` writes, without its
/// printing): the summary says whether the run completed, diverged or stopped (its `failure`
/// holds the error). Input that cannot be run is refused before anything is written.
pub fn run_in_folder(def: &TestDefinition, dir: &Path, options: FolderOptions) -> Result<FolderRun> {
    let mut run = Run::new(def)?;
    let layout = run.layout().clone();
    let mut folder = RunFolder::create(def, &layout, dir, options)?;
    let mut summary = run.execute(&mut folder, &AtomicBool::new(false));
    let outputs = folder.finish(def, run.input_motion(), &mut summary)?;
    Ok(FolderRun { summary, outputs })
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
