//! `substep._substep`: the compiled part of the `substep` Python package. Thin over the library:
//! a run is `substep::run::execute` with the in-memory `HistoryTable`; the analyses and the RTHS
//! benchmark call the library functions the CLI calls. The Python layer (`substep/__init__.py`)
//! wraps the arrays in a `Result`.
//!
//! Long calls release the GIL; a run looks at Python's signals every `SIGNAL_CHECK` (100 ms) so that
//! Ctrl-C interrupts it (it stops between two steps and raises `KeyboardInterrupt`).

mod analyze;
mod benchmark;
mod study;

use numpy::PyArray2;
use numpy::PyReadonlyArray2;
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::ops::ControlFlow;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use substep::io::TestDefinition;
use substep::io::results::Format;
use substep::output::{FolderOptions, RunFolder};
use substep::run::{HistoryTable, Layout, Run, RunObserver, StepRow, Table};
use substep::session::live::{Live, LiveObserver, LiveOptions, StabilityChoice};
use substep::session::realtime::{RealtimeOutcome, RealtimeRunOptions};
use substep::substructure::SubstepObserver;

create_exception!(
    _substep,
    ConfigError,
    PyException,
    "Bad input: a config, file or parameter that cannot be used (the CLI's exit code 2). The message is the CLI's one-line error."
);
create_exception!(
    _substep,
    RunError,
    PyException,
    "A run that diverged or stopped (the CLI's exit code 1). `args[0]` is the CLI's one-line error; the attribute `result` holds the steps done (a `substep.Result`)."
);

/// How often a running test looks at Python's signals (Ctrl-C).
const SIGNAL_CHECK: Duration = Duration::from_millis(100);

/// The library's error as the Python exception the CLI's exit code corresponds to.
pub(crate) fn to_py(e: &substep::Error) -> PyErr {
    let message = e.to_string().split_whitespace().collect::<Vec<_>>().join(" ");
    match e {
        substep::Error::Diverged { .. } | substep::Error::Stopped { .. } => RunError::new_err(message),
        _ => ConfigError::new_err(message),
    }
}

/// A test definition from a path, TOML text or a JSON text (a Python dict).
pub(crate) fn definition(kind: &str, text: &str, name: &str, base_dir: &str) -> substep::Result<TestDefinition> {
    match kind {
        "path" => TestDefinition::from_file(text),
        "toml" => TestDefinition::from_toml(text, name, Path::new(base_dir)),
        "json" => {
            let json: serde_json::Value = serde_json::from_str(text)
                .map_err(|e| substep::Error::invalid(name, format!("not a JSON-compatible dict: {e}")))?;
            let value = toml::Value::try_from(json).map_err(|e| {
                substep::Error::invalid(name, format!("cannot be written as TOML (None is not a value): {e}"))
            })?;
            let toml = toml::to_string(&value)
                .map_err(|e| substep::Error::invalid(name, format!("cannot be written as TOML: {e}")))?;
            TestDefinition::from_generated_toml(&toml, name, Path::new(base_dir))
        }
        other => Err(substep::Error::invalid("config", format!("unknown kind {other:?}"))),
    }
}

/// The in-memory table, plus a look at Python's signals every [`SIGNAL_CHECK`] (with the GIL
/// taken only for that).
struct Collector {
    table: HistoryTable,
    last_check: Instant,
    interrupted: Option<PyErr>,
}

impl SubstepObserver for Collector {
    fn substep(&mut self, step: usize, j: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.table.substep(step, j, command, force, displacement);
    }
    fn phase_lag(&mut self, tracking_error: &[f64], correction: &[f64]) {
        self.table.phase_lag(tracking_error, correction);
    }
    fn lab(&mut self, held: bool, strays: u64) {
        self.table.lab(held, strays);
    }
    fn ramp(&mut self, step: usize, j: usize, s: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.table.ramp(step, j, s, command, force, displacement);
    }
}

impl RunObserver for Collector {
    fn start(&mut self, layout: &Layout) {
        self.table.start(layout);
    }
    fn step(&mut self, row: &StepRow<'_>) -> ControlFlow<()> {
        let flow = self.table.step(row);
        if self.last_check.elapsed() >= SIGNAL_CHECK {
            self.last_check = Instant::now();
            if let Err(e) = Python::attach(|py| py.check_signals()) {
                self.interrupted = Some(e);
                return ControlFlow::Break(());
            }
        }
        flow
    }
}

fn table_pair<'py>(py: Python<'py>, t: Table) -> PyResult<(Vec<String>, Bound<'py, PyArray2<f64>>)> {
    // Columns × rows (Python transposes it into a view); an empty table still has its columns.
    let array = PyArray2::from_vec2(py, &t.columns).map_err(|e| ConfigError::new_err(e.to_string()))?;
    Ok((t.names, array))
}

/// Run a test: `kind` is `"path"`, `"toml"` or `"json"`, `text` the path or the text, `name`
/// how messages and the summary name it, `base_dir` where relative paths in it start. Returns
/// a dict with `summary` (the JSON text of `summary.json`), `history`, `substeps`, `response`
/// (each `(column names, columns × rows array)` or None) and `error` (the one-line message of
/// a run that did not complete, else None).
#[pyfunction]
#[pyo3(signature = (kind, text, name, base_dir, live="{}"))]
fn run<'py>(
    py: Python<'py>,
    kind: &str,
    text: &str,
    name: &str,
    base_dir: &str,
    live: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let (def, mut live) = py
        .detach(|| -> substep::Result<_> {
            let mut def = definition(kind, text, name, base_dir)?;
            let config_name = def.source.clone();
            let live = Live::start(&live_options(live)?, &mut def, &config_name, false)?;
            Ok((def, live))
        })
        .map_err(|e| to_py(&e))?;
    let mut collector = Collector {
        table: HistoryTable::default(),
        last_check: Instant::now(),
        interrupted: None,
    };
    let cancel = AtomicBool::new(false);
    let summary = py
        .detach(|| -> substep::Result<_> {
            let mut run = Run::new(&def)?;
            run.set_stability(live.stability_settings.clone())?;
            let mut watched = LiveObserver {
                inner: &mut collector,
                live: &mut live,
                quiet: true,
            };
            Ok(run.execute(&mut watched, &cancel))
        })
        .map_err(|e| to_py(&e))?;
    let final_state = serde_json::json!({
        "completed": summary.completed, "reason": summary.reason, "stopped_by": summary.stopped_by,
        "steps_done": summary.steps_done, "steps": summary.steps,
    });
    py.detach(|| live.finish(final_state, &[], false));
    if let Some(e) = collector.interrupted {
        return Err(e);
    }
    run_tables(py, &summary, collector.table)
}

/// The monitor's and the indicator's options from Python (`monitor`, `monitor_public`,
/// `monitor_token`, `monitor_linger`, `stability`, `pace`; a JSON object made by the Python layer).
fn live_options(json: &str) -> substep::Result<LiveOptions> {
    let v: serde_json::Value =
        serde_json::from_str(json).map_err(|e| substep::Error::invalid("monitor options", e.to_string()))?;
    let text = |k: &str| v.get(k).and_then(|x| x.as_str()).map(str::to_string);
    let number = |k: &str| v.get(k).and_then(serde_json::Value::as_f64);
    let stability = match text("stability").as_deref() {
        None => None,
        Some("warn") => Some(StabilityChoice::Warn),
        Some("stop") => Some(StabilityChoice::Stop),
        Some("off") => Some(StabilityChoice::Off),
        Some(other) => {
            return Err(substep::Error::invalid(
                "stability",
                format!("unknown action {other:?} (warn, stop or off)"),
            ));
        }
    };
    let defaults = LiveOptions::default();
    let linger = number("monitor_linger").unwrap_or(defaults.monitor_linger);
    if !(linger.is_finite() && linger >= 0.0) {
        return Err(substep::Error::invalid(
            "monitor_linger",
            format!("{linger} is not a number of seconds ≥ 0"),
        ));
    }
    let pace = number("pace");
    if let Some(p) = pace
        && !(p.is_finite() && p > 0.0)
    {
        return Err(substep::Error::invalid("pace", format!("{p} is not a factor > 0")));
    }
    Ok(LiveOptions {
        monitor: text("monitor"),
        monitor_public: v
            .get("monitor_public")
            .and_then(serde_json::Value::as_bool)
            .unwrap_or(false),
        monitor_token: text("monitor_token"),
        monitor_linger: linger,
        stability,
        pace,
        keyword_names: true,
    })
}

/// The output folder's observer and the in-memory tables, fed in turn.
struct FolderAndTables<'a> {
    folder: &'a mut RunFolder,
    tables: &'a mut Collector,
}

impl SubstepObserver for FolderAndTables<'_> {
    fn substep(&mut self, step: usize, j: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.folder.substep(step, j, command, force, displacement);
        self.tables.substep(step, j, command, force, displacement);
    }
    fn phase_lag(&mut self, tracking_error: &[f64], correction: &[f64]) {
        self.folder.phase_lag(tracking_error, correction);
        self.tables.phase_lag(tracking_error, correction);
    }
    fn lab(&mut self, held: bool, strays: u64) {
        self.folder.lab(held, strays);
        self.tables.lab(held, strays);
    }
    fn ramp(&mut self, step: usize, j: usize, s: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.folder.ramp(step, j, s, command, force, displacement);
        self.tables.ramp(step, j, s, command, force, displacement);
    }
}

impl RunObserver for FolderAndTables<'_> {
    fn start(&mut self, layout: &Layout) {
        self.folder.start(layout);
        self.tables.start(layout);
    }
    fn step(&mut self, row: &StepRow<'_>) -> ControlFlow<()> {
        match self.folder.step(row) {
            ControlFlow::Break(()) => ControlFlow::Break(()),
            ControlFlow::Continue(()) => self.tables.step(row),
        }
    }
}

/// The figure options of a Python run: `plots` (None: the config's `[output] plots`) and
/// `plot_format` (None: the config's `[output.plots] format`, else PNG).
fn folder_options(
    def: &TestDefinition,
    plots: Option<bool>,
    plot_format: Option<&str>,
) -> substep::Result<FolderOptions> {
    let plot_format = plot_format
        .map(|name| {
            substep::figure::PlotFormat::from_name(name)
                .map(|f| (f, "plot_format"))
                .ok_or_else(|| {
                    substep::Error::invalid("plot_format", format!("unknown format {name:?} (png, svg or pdf)"))
                })
        })
        .transpose()?;
    FolderOptions::resolve(def, plots.unwrap_or(def.output.plots), plot_format)
}

fn run_tables<'py>(
    py: Python<'py>,
    summary: &substep::run::RunSummary,
    table: HistoryTable,
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    out.set_item("summary", summary.to_json())?;
    out.set_item(
        "error",
        summary.failure.as_ref().map(|e| to_py(e).value(py).to_string()),
    )?;
    out.set_item(
        "error_kind",
        summary.failure.as_ref().map(|e| match e {
            substep::Error::Diverged { .. } | substep::Error::Stopped { .. } => "run",
            _ => "config",
        }),
    )?;
    let HistoryTable {
        history,
        substeps,
        response,
        ..
    } = table;
    out.set_item("history", table_pair(py, history)?)?;
    out.set_item("substeps", substeps.map(|t| table_pair(py, t)).transpose()?)?;
    out.set_item("response", response.map(|t| table_pair(py, t)).transpose()?)?;
    Ok(out)
}

/// [`run`] into the output folder `out_dir` (what `substep run CONFIG --out DIR` writes:
/// [`substep::output::RunFolder`], then `results.h5` / `results.mat` when the config's
/// `[output] format` (or `format`) asks for it). The dict also has `outputs` (the files
/// written).
#[pyfunction]
#[pyo3(signature = (kind, text, name, base_dir, out_dir, plots=None, plot_format=None, format=None, live="{}"))]
// The config's four parts and the CLI's four output flags: a struct would only rename them.
#[allow(clippy::too_many_arguments)]
fn run_folder<'py>(
    py: Python<'py>,
    kind: &str,
    text: &str,
    name: &str,
    base_dir: &str,
    out_dir: &str,
    plots: Option<bool>,
    plot_format: Option<&str>,
    format: Option<&str>,
    live: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let dir = Path::new(out_dir);
    let (def, options, container, mut live) = py
        .detach(|| -> substep::Result<_> {
            let mut def = definition(kind, text, name, base_dir)?;
            let options = folder_options(&def, plots, plot_format)?;
            let container = match format {
                Some(f) => Format::parse("format", f)?,
                None => def.output.format,
            };
            // As the CLI: the indicator's settings and the monitor page (when asked for).
            let config_name = def.source.clone();
            let live = Live::start(&live_options(live)?, &mut def, &config_name, false)?;
            Ok((def, options, container, live))
        })
        .map_err(|e| to_py(&e))?;
    let mut collector = Collector {
        table: HistoryTable::default(),
        last_check: Instant::now(),
        interrupted: None,
    };
    let cancel = AtomicBool::new(false);
    let result = py.detach(|| -> substep::Result<_> {
        let mut run = Run::new(&def)?;
        run.set_stability(live.stability_settings.clone())?;
        let layout = run.layout().clone();
        let mut folder = RunFolder::create(&def, &layout, dir, options)?;
        let mut both = FolderAndTables {
            folder: &mut folder,
            tables: &mut collector,
        };
        let mut watched = LiveObserver {
            inner: &mut both,
            live: &mut live,
            quiet: true,
        };
        let mut summary = run.execute(&mut watched, &cancel);
        let finished = folder.finish(&def, run.input_motion(), &mut summary);
        let finished = substep::output::files::no_summary_left_running(&dir.join("summary.json"), finished);
        let mut outputs = finished?;
        if substep::output::container::ran(summary.failure.as_ref())
            && let Some(path) = substep::output::container::write(dir, container, config_text(kind, text))?
        {
            outputs.push(path);
        }
        Ok((summary, outputs))
    });
    let (summary, outputs) = match result {
        Ok((summary, outputs)) => {
            let final_state = serde_json::json!({
                "completed": summary.completed, "reason": summary.reason, "stopped_by": summary.stopped_by,
                "steps_done": summary.steps_done, "steps": summary.steps,
            });
            // The page shows the final state for `monitor_linger` seconds.
            py.detach(|| live.finish(final_state, &outputs, false));
            (summary, outputs)
        }
        Err(e) => {
            py.detach(|| {
                live.finish(
                    serde_json::json!({ "completed": false, "reason": e.to_string() }),
                    &[],
                    true,
                )
            });
            return Err(to_py(&e));
        }
    };
    if let Some(e) = collector.interrupted.take() {
        return Err(e);
    }
    let out = run_tables(py, &summary, collector.table)?;
    out.set_item(
        "outputs",
        outputs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
    )?;
    Ok(out)
}

/// A real-time run into `out_dir` ([`substep::session::realtime::run_realtime`], what
/// `substep run CONFIG --realtime --out DIR` does). `options` is a JSON object: `max_missed`,
/// `late_policy`, `lock_memory`, `fifo_priority` and the monitor's options. Returns a dict with
/// `summary` (the text of `summary.json`), `outputs`, `error` and `error_kind`; the tables are
/// read from the folder by the Python layer.
#[pyfunction]
#[pyo3(signature = (kind, text, name, base_dir, out_dir=None, options="{}"))]
fn run_realtime<'py>(
    py: Python<'py>,
    kind: &str,
    text: &str,
    name: &str,
    base_dir: &str,
    out_dir: Option<&str>,
    options: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let outcome = py
        .detach(|| -> substep::Result<_> {
            let def = definition(kind, text, name, base_dir)?;
            // As the CLI: `[output] dir`, else `results`.
            let out_dir = out_dir
                .map(std::path::PathBuf::from)
                .or_else(|| def.output.dir.clone())
                .unwrap_or_else(|| std::path::PathBuf::from("results"));
            let v: serde_json::Value = serde_json::from_str(options)
                .map_err(|e| substep::Error::invalid("real-time options", e.to_string()))?;
            let fifo_priority =
                match v.get("fifo_priority").and_then(serde_json::Value::as_i64) {
                    None => None,
                    Some(p) => Some(i32::try_from(p).map_err(|_| {
                        substep::Error::invalid("fifo_priority", format!("{p} is not a priority 1..99"))
                    })?),
                };
            let options = RealtimeRunOptions {
                max_missed: v.get("max_missed").and_then(serde_json::Value::as_f64),
                late_policy: v.get("late_policy").and_then(|x| x.as_str()).map(str::to_string),
                lock_memory: v
                    .get("lock_memory")
                    .and_then(serde_json::Value::as_bool)
                    .unwrap_or(false),
                fifo_priority,
                live: live_options(options)?,
                keyword_names: true,
            };
            let source = def.source.clone();
            let outcome = substep::session::realtime::run_realtime(&def, &out_dir, &source, &options)?;
            let RealtimeOutcome {
                summary,
                outputs,
                failure,
                not_real_time,
                live,
                final_state,
                ..
            } = outcome;
            live.finish(final_state, &outputs, false);
            Ok((summary, outputs, failure, not_real_time, out_dir))
        })
        .map_err(|e| to_py(&e))?;
    let (summary, outputs, failure, not_real_time, out_dir) = outcome;
    let out = PyDict::new(py);
    out.set_item("out_dir", out_dir.display().to_string())?;
    out.set_item("summary", serde_json::to_string(&summary).unwrap_or_default())?;
    out.set_item(
        "outputs",
        outputs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
    )?;
    let (error, kind) = match (&failure, &not_real_time) {
        (Some(e), _) => (Some(to_py(e).value(py).to_string()), Some("run")),
        (None, Some(reason)) => (
            Some(reason.split_whitespace().collect::<Vec<_>>().join(" ")),
            Some("run"),
        ),
        (None, None) => (None, None),
    };
    out.set_item("error", error)?;
    out.set_item("error_kind", kind)?;
    Ok(out)
}

/// The test definition's text as a run read it (for the container's copy).
fn config_text(kind: &str, text: &str) -> String {
    match kind {
        "path" => {
            substep::io::limits::read_text(Path::new(text), substep::io::limits::CONFIG_MAX_BYTES).unwrap_or_default()
        }
        _ => text.to_string(),
    }
}

/// Write a table (`names`, a rows × columns array) as CSV in the format of `substep run`'s files
/// (`step`, `substep` and `ramp` columns as integers).
#[pyfunction]
fn write_csv(py: Python<'_>, path: &str, names: Vec<String>, rows: PyReadonlyArray2<'_, f64>) -> PyResult<()> {
    let a = rows.as_array();
    if a.ncols() != names.len() {
        return Err(ConfigError::new_err(format!(
            "{path}: {} column names for {} columns",
            names.len(),
            a.ncols()
        )));
    }
    let table = Table::from_columns(names, a.columns().into_iter().map(|c| c.to_vec()).collect());
    py.detach(|| {
        let file = std::fs::File::create(path)?;
        let mut w = std::io::BufWriter::new(file);
        table.write_csv(&mut w)?;
        std::io::Write::flush(&mut w)
    })
    .map_err(|e| pyo3::exceptions::PyOSError::new_err(format!("cannot write {path}: {e}")))
}

#[pymodule]
fn _substep(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("ConfigError", m.py().get_type::<ConfigError>())?;
    m.add("RunError", m.py().get_type::<RunError>())?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(run_folder, m)?)?;
    m.add_function(wrap_pyfunction!(run_realtime, m)?)?;
    m.add_function(wrap_pyfunction!(write_csv, m)?)?;
    m.add_function(wrap_pyfunction!(analyze::stability, m)?)?;
    m.add_function(wrap_pyfunction!(analyze::accuracy, m)?)?;
    m.add_function(wrap_pyfunction!(analyze::transfer_function, m)?)?;
    m.add_function(wrap_pyfunction!(analyze::plan, m)?)?;
    m.add_function(wrap_pyfunction!(analyze::verify, m)?)?;
    m.add_function(wrap_pyfunction!(benchmark::rths, m)?)?;
    m.add_function(wrap_pyfunction!(benchmark::rths_compare, m)?)?;
    m.add_function(wrap_pyfunction!(benchmark::marths, m)?)?;
    m.add_function(wrap_pyfunction!(study::study_plan, m)?)?;
    m.add_function(wrap_pyfunction!(study::study_run, m)?)?;
    m.add_function(wrap_pyfunction!(study::write_container, m)?)?;
    Ok(())
}
