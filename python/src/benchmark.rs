//! `substep.benchmark.rths`: the virtual RTHS benchmark (Silva et al. 2020, docs/benchmark.md),
//! the library's study ([`StudyOptions`]) as `substep benchmark rths --json` runs it: nominal
//! and perturbed plants, `k_sub` series, a record of the user's.

use crate::to_py;
use pyo3::prelude::*;
use substep::benchmark::rths::StudyOptions;

fn read(path: Option<&str>) -> substep::Result<Option<(String, String)>> {
    path.map(|p| {
        std::fs::read_to_string(p)
            .map(|t| (p.to_string(), t))
            .map_err(|e| substep::Error::file(p, format!("cannot read: {e}")))
    })
    .transpose()
}

/// The study's JSON text (the object of `substep benchmark rths --json`); Python parses it.
#[pyfunction]
#[pyo3(signature = (case, intensity, controller, config, algorithm, record, perturbed, seed, k_sub))]
#[allow(clippy::too_many_arguments)] // the keyword arguments of `substep.benchmark.rths`
pub fn rths(
    py: Python<'_>,
    case: Option<u8>,
    intensity: f64,
    controller: Option<&str>,
    config: Option<&str>,
    algorithm: &str,
    record: Option<&str>,
    perturbed: Option<usize>,
    seed: u64,
    k_sub: Vec<usize>,
) -> PyResult<String> {
    let record = read(record).map_err(|e| to_py(&e))?;
    let config = read(config).map_err(|e| to_py(&e))?;
    let options = StudyOptions {
        case,
        record: record.as_ref().map(|(n, t)| (n.as_str(), t.as_str())),
        intensity,
        controller,
        config: config.as_ref().map(|(n, t)| (n.as_str(), t.as_str())),
        algorithm,
        perturbed,
        seed,
        k_sub: &k_sub,
    };
    let setup = options.setup(|name| name.to_string()).map_err(|e| to_py(&e))?;
    let rows = py.detach(|| setup.run()).map_err(|e| to_py(&e))?;
    serde_json::to_string(&setup.json(&rows)).map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))
}

/// `substep benchmark rths --compare --json` for the same options: the controllers side by side
/// (`substep.benchmark.compare`); Python parses the JSON text.
#[pyfunction]
#[pyo3(signature = (case, intensity, record, perturbed, seed))]
pub fn rths_compare(
    py: Python<'_>,
    case: Option<u8>,
    intensity: f64,
    record: Option<&str>,
    perturbed: usize,
    seed: u64,
) -> PyResult<String> {
    let record = read(record).map_err(|e| to_py(&e))?;
    let options = StudyOptions {
        case,
        record: record.as_ref().map(|(n, t)| (n.as_str(), t.as_str())),
        intensity,
        controller: None,
        config: None,
        algorithm: "benchmark",
        perturbed: (perturbed > 0).then_some(perturbed),
        seed,
        k_sub: &[],
    };
    let setup = options.setup(|name| name.to_string()).map_err(|e| to_py(&e))?;
    let rows = py.detach(|| setup.compare()).map_err(|e| to_py(&e))?;
    serde_json::to_string(&setup.comparison_json(&rows))
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))
}

/// `substep benchmark marths --json` for the same options (`substep.benchmark.marths`): the
/// library's [`MarthsOptions`], files read here; Python parses the JSON text. A run that diverged
/// raises `RunError` with the CLI's message.
#[pyfunction]
#[pyo3(signature = (record, intensity, controller, trials, seed, noise, ideal, algorithm, partition_density, config))]
#[allow(clippy::too_many_arguments)] // the keyword arguments of `substep.benchmark.marths`
pub fn marths(
    py: Python<'_>,
    record: &str,
    intensity: f64,
    controller: &str,
    trials: usize,
    seed: u64,
    noise: bool,
    ideal: bool,
    algorithm: &str,
    partition_density: Option<f64>,
    config: Option<&str>,
) -> PyResult<String> {
    use substep::benchmark::marths::{MarthsOptions, RecordChoice, names_a_record_file, reference, run_with};
    let record_file = if names_a_record_file(record) {
        read(Some(record)).map_err(|e| to_py(&e))?
    } else {
        None
    };
    let config = read(config).map_err(|e| to_py(&e))?;
    let options = MarthsOptions {
        record: match &record_file {
            Some((name, text)) => RecordChoice::File { name, text },
            None => RecordChoice::Shipped(record),
        },
        intensity,
        controller,
        trials,
        seed,
        noise,
        ideal,
        algorithm,
        partition_density,
        config: config.as_ref().map(|(n, t)| (n.as_str(), t.as_str())),
    };
    let input = options.input(|name| name.to_string()).map_err(|e| to_py(&e))?;
    let t0 = std::time::Instant::now();
    let study = py
        .detach(|| reference(&input).and_then(|r| run_with(&input, &r, trials, seed)))
        .map_err(|e| to_py(&e))?;
    if let Some(e) = study.divergence() {
        return Err(to_py(&e));
    }
    let json = options.json(&input, &study, t0.elapsed().as_secs_f64());
    serde_json::to_string(&json).map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))
}
