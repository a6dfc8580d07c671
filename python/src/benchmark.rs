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
    serde_json::to_string(&setup.comparison_json(&rows)).map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))
}
