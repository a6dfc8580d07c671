//! `substep.benchmark.rths`: the virtual RTHS benchmark (Silva et al. 2020, docs/benchmark.md),
//! `substep::benchmark::rths::run_study` as `substep benchmark rths --json` runs it (the
//! nominal plant; perturbed plants and k_sub series stay with the CLI).

use crate::to_py;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::sync::Arc;
use substep::benchmark::rths::{
    Algorithm, BenchmarkConfig, Case, ControllerKind, GroundRecord, RthsInput, Transfer, run_study,
};
use substep::transfer::servo::ServoParams;

fn setup(
    case: Option<u8>,
    intensity: f64,
    controller: Option<&str>,
    config: Option<&str>,
    algorithm: &str,
) -> substep::Result<(Vec<Case>, RthsInput, ControllerKind)> {
    let cases = match case {
        Some(c) => {
            vec![Case::new(c).map_err(|e| substep::Error::invalid("case", e.to_string().replace("case: ", "")))?]
        }
        None => Case::all().to_vec(),
    };
    if !(intensity.is_finite() && intensity >= 0.0) {
        return Err(substep::Error::invalid(
            "intensity",
            format!("must be a finite number >= 0, got {intensity}"),
        ));
    }
    let config = match config {
        Some(path) => {
            let text =
                std::fs::read_to_string(path).map_err(|e| substep::Error::file(path, format!("cannot read: {e}")))?;
            BenchmarkConfig::parse(&text, path)?
        }
        None => BenchmarkConfig::default(),
    };
    let kind = match controller {
        Some(k) => Some(
            ControllerKind::parse(k)
                .map_err(|e| substep::Error::invalid("controller", e.to_string().replace("controller: ", "")))?,
        ),
        None => config.kind()?,
    };
    let controller = config.controller(kind)?;
    let kind = controller.kind;
    let (noise, noise_seed) = config.noise()?;
    let algorithm = match algorithm {
        "benchmark" => Algorithm::Benchmark,
        "substep" => Algorithm::Substep(config.substep()?),
        other => {
            return Err(substep::Error::invalid(
                "algorithm",
                format!("unknown `{other}` (benchmark, substep)"),
            ));
        }
    };
    let base = RthsInput {
        case: cases[0],
        record: Arc::new(GroundRecord::elcentro()),
        intensity,
        controller,
        transfer: if config.ideal_plant()? {
            Transfer::Ideal
        } else {
            Transfer::Plant {
                params: ServoParams::benchmark(),
                derivative: config.derivative()?,
            }
        },
        noise,
        noise_seed,
        algorithm,
        keep_history: false,
    };
    Ok((cases, base, kind))
}

/// The benchmark's cases: a list of dicts `case, J1..J9, max_force, stable, capacity_exceeded`
/// (`diverged_at`, `guard_trip` when they apply), as in `substep benchmark rths --json`.
#[pyfunction]
#[pyo3(signature = (case, intensity, controller, config, algorithm))]
pub fn rths<'py>(
    py: Python<'py>,
    case: Option<u8>,
    intensity: f64,
    controller: Option<&str>,
    config: Option<&str>,
    algorithm: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let (cases, base, kind) = setup(case, intensity, controller, config, algorithm).map_err(|e| to_py(&e))?;
    let rows = py
        .detach(|| run_study(&base, &cases, &[None], None, 1))
        .map_err(|e| to_py(&e))?;
    let list = PyList::empty(py);
    for r in rows.iter().map(|row| &row.nominal) {
        let d = PyDict::new(py);
        d.set_item("case", r.case)?;
        for i in 0..9 {
            d.set_item(format!("J{}", i + 1), r.criteria.as_ref().map(|c| c.j[i]))?;
        }
        d.set_item("max_force", r.max_force)?;
        d.set_item("stable", r.stable)?;
        d.set_item("capacity_exceeded", r.capacity_exceeded)?;
        if let Some(t) = r.diverged_at {
            d.set_item("diverged_at", t)?;
        }
        if let Some(g) = &r.guard_trip {
            d.set_item("guard_trip", g)?;
        }
        list.append(d)?;
    }
    let out = PyDict::new(py);
    out.set_item("benchmark", "rths")?;
    out.set_item("controller", kind.name())?;
    out.set_item("record", &base.record.name)?;
    out.set_item("intensity", base.intensity)?;
    out.set_item("algorithm", algorithm)?;
    out.set_item("cases", list)?;
    Ok(out)
}
