//! Parameter studies and result containers for the Python package (`substep.study`,
//! `Result.save("x.h5" | "x.mat")`): thin over `substep::study` and `substep::io::results`.
//!
//! A study is sent as (base config, JSON spec); `study_run` runs the given run indices on the
//! library's rayon pool with the GIL released. A Dask task calls it with one batch of indices
//! and one thread: run `i` is defined by `i` alone, so the rows equal the local ones.

use crate::{ConfigError, to_py};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::{Path, PathBuf};
use substep::io::results::{Format, Metadata, write_container as write};
use substep::study::{Study, show, summary_runner};

/// The study of `spec` (JSON) over the base config given as (kind, text, name, base_dir), as
/// the run API's `definition` takes it: `path`, `toml` or `json` (a dict).
fn study(kind: &str, text: &str, name: &str, base_dir: &str, spec: &str) -> substep::Result<Study> {
    let (toml_text, name, dir): (String, String, PathBuf) = match kind {
        "path" => {
            let path = Path::new(text);
            let t = substep::io::limits::read_text(path, substep::io::limits::CONFIG_MAX_BYTES)?;
            (
                t,
                text.to_string(),
                path.parent().unwrap_or(Path::new("")).to_path_buf(),
            )
        }
        "toml" => (text.to_string(), name.to_string(), PathBuf::from(base_dir)),
        "json" => {
            let json: serde_json::Value = serde_json::from_str(text)
                .map_err(|e| substep::Error::invalid(name, format!("not a JSON-compatible dict: {e}")))?;
            let value = toml::Value::try_from(json).map_err(|e| {
                substep::Error::invalid(name, format!("cannot be written as TOML (None is not a value): {e}"))
            })?;
            let t = toml::to_string(&value)
                .map_err(|e| substep::Error::invalid(name, format!("cannot be written as TOML: {e}")))?;
            (t, name.to_string(), PathBuf::from(base_dir))
        }
        other => return Err(substep::Error::invalid("base", format!("unknown kind {other:?}"))),
    };
    Study::from_json(&toml_text, &name, &dir, spec)
}

/// `(runs, parameter names, metric names)` of a study (validates it).
#[pyfunction]
#[pyo3(signature = (kind, text, name, base_dir, spec))]
pub fn study_plan(
    py: Python<'_>,
    kind: &str,
    text: &str,
    name: &str,
    base_dir: &str,
    spec: &str,
) -> PyResult<(usize, Vec<String>, Vec<String>)> {
    let s = py
        .detach(|| study(kind, text, name, base_dir, spec))
        .map_err(|e| to_py(&e))?;
    Ok((
        s.len(),
        s.parameters(),
        s.metrics().iter().map(|m| m.name().to_string()).collect(),
    ))
}

/// Rows of the runs `indices` (all when None) on `threads` threads (0: all cores): a list of
/// dicts `run`, `values` (list), `completed`, `error` (str, empty when completed), `metrics`
/// (list of float), `summary` (the JSON text, when `keep_summary`).
#[pyfunction]
#[pyo3(signature = (kind, text, name, base_dir, spec, indices=None, threads=0, keep_summary=false))]
#[allow(clippy::too_many_arguments)]
pub fn study_run<'py>(
    py: Python<'py>,
    kind: &str,
    text: &str,
    name: &str,
    base_dir: &str,
    spec: &str,
    indices: Option<Vec<usize>>,
    threads: usize,
    keep_summary: bool,
) -> PyResult<Bound<'py, PyList>> {
    let rows = py
        .detach(|| {
            let s = study(kind, text, name, base_dir, spec)?;
            let all: Vec<usize>;
            let which = match &indices {
                Some(i) => i.as_slice(),
                None => {
                    all = (0..s.len()).collect();
                    &all
                }
            };
            s.run(which, threads, &summary_runner, &|| {})
        })
        .map_err(|e| to_py(&e))?;
    let out = PyList::empty(py);
    for r in rows {
        let d = PyDict::new(py);
        d.set_item("run", r.index)?;
        let values = PyList::empty(py);
        for v in &r.values {
            match v {
                toml::Value::Float(f) => values.append(*f)?,
                toml::Value::Integer(i) => values.append(*i)?,
                toml::Value::Boolean(b) => values.append(*b)?,
                other => values.append(show(other))?,
            }
        }
        d.set_item("values", values)?;
        d.set_item("completed", r.completed)?;
        d.set_item("error", &r.error)?;
        d.set_item("metrics", &r.metrics)?;
        if keep_summary {
            d.set_item("summary", r.summary.map(|s| s.to_string()))?;
        }
        out.append(d)?;
    }
    Ok(out)
}

/// Gather the CSV tables and the summary in `dir` into `results.h5` (`format = "hdf5"`) or
/// `results.mat` (`"mat"`) there; the path written.
#[pyfunction]
pub fn write_container(py: Python<'_>, dir: &str, format: &str, summary_json: &str, config: &str) -> PyResult<String> {
    let f = Format::parse("format", format).map_err(|e| to_py(&e))?;
    if f == Format::Csv {
        return Err(ConfigError::new_err(
            "format: csv has no container (save to a directory)",
        ));
    }
    let meta = Metadata {
        summary_json: summary_json.to_string(),
        config: config.to_string(),
    };
    let path = py
        .detach(|| write(Path::new(dir), f, &meta))
        .map_err(|e| pyo3::exceptions::PyOSError::new_err(e.to_string()))?;
    Ok(path.map(|p| p.display().to_string()).unwrap_or_default())
}
