//! `substep.analyze`: the stability map and the accuracy table of the sub-step algorithm
//! (docs/analysis.md), the library functions `substep analyze stability|accuracy` call, with
//! the CLI's defaults. The parameters arrive as Python values instead of flag strings; the
//! small parsers here only translate them (messages name the keyword argument).

use crate::to_py;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use substep::analysis::frequency::peak_errors;
use substep::analysis::stability::{linear_grid, stability_map};
use substep::analysis::{AnalysisCase, FrozenPhaseLag, Parameter};
use substep::substructure::ErrorForceSpec;

fn bad(what: &str, reason: String) -> PyErr {
    to_py(&substep::Error::invalid(what, reason))
}

/// The analysis case of docs/theory.md §9.3: `typical` or `large_mass_ratio`, with overrides.
fn case(
    name: &str,
    eta_m: Option<f64>,
    eta_f: Option<f64>,
    zeta: Option<f64>,
    zeta_s: Option<f64>,
    error_force: &str,
) -> PyResult<AnalysisCase> {
    let mut c = match name {
        "typical" => AnalysisCase::typical_tmd(),
        "large_mass_ratio" => AnalysisCase::large_mass_ratio(),
        other => {
            return Err(bad(
                "case",
                format!("unknown case '{other}' (expected typical or large_mass_ratio)"),
            ));
        }
    };
    for (slot, v) in [
        (&mut c.eta_m, eta_m),
        (&mut c.eta_f, eta_f),
        (&mut c.zeta, zeta),
        (&mut c.zeta_s, zeta_s),
    ] {
        if let Some(v) = v {
            *slot = v;
        }
    }
    c.error_force = parse_error_force(error_force)?;
    c.validate().map_err(|e| to_py(&e))?;
    Ok(c)
}

/// `none`, `pid:P` or `pid:P:I:D`.
fn parse_error_force(s: &str) -> PyResult<ErrorForceSpec> {
    if s == "none" {
        return Ok(ErrorForceSpec::None);
    }
    let parts: Vec<&str> = s.split(':').collect();
    if parts[0] != "pid" || !(parts.len() == 2 || parts.len() == 4) {
        return Err(bad(
            "error_force",
            format!("expected none, pid:P or pid:P:I:D, got '{s}'"),
        ));
    }
    let num = |t: &str| -> PyResult<f64> {
        t.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| bad("error_force", format!("'{t}' is not a number")))
    };
    let p = num(parts[1])?;
    let (i, d) = if parts.len() == 4 {
        (num(parts[2])?, num(parts[3])?)
    } else {
        (0.0, 0.0)
    };
    Ok(ErrorForceSpec::Pid { p, i, d })
}

/// `none` or `polynomial:ORDER`.
fn parse_phase_lag(s: &str) -> PyResult<Option<FrozenPhaseLag>> {
    if s == "none" {
        return Ok(None);
    }
    match s.split_once(':') {
        Some(("polynomial", o)) => match o.trim().parse::<usize>() {
            Ok(order) if (1..=3).contains(&order) => Ok(Some(FrozenPhaseLag::Polynomial { order })),
            _ => Err(bad(
                "phase_lag",
                format!("the polynomial order must be 1, 2 or 3, got '{o}'"),
            )),
        },
        _ => Err(bad(
            "phase_lag",
            format!("expected none or polynomial:ORDER, got '{s}'"),
        )),
    }
}

/// The varied parameter of a map (not the x axis).
fn parameter(what: &str, name: &str) -> PyResult<Parameter> {
    let p = Parameter::from_name(name).map_err(|e| bad(what, e.to_string()))?;
    if matches!(p, Parameter::Omega | Parameter::EtaT) {
        return Err(bad(
            what,
            format!("'{name}' is the x axis already; vary zeta_s, zeta, eta_f, eta_m or eta_p"),
        ));
    }
    Ok(p)
}

fn k_subs(k: &[usize]) -> PyResult<Vec<usize>> {
    if k.is_empty() || k.contains(&0) {
        return Err(bad("k_sub", format!("expected a list of integers >= 1, got {k:?}")));
    }
    Ok(k.to_vec())
}

/// Spectral radius over a grid; see `substep.analyze.stability`.
#[pyfunction]
#[pyo3(signature = (case_name, eta_m, eta_f, zeta, zeta_s, error_force, eta_p, phase_lag, k_sub, omega, vary_name, vary))]
#[allow(clippy::too_many_arguments)]
pub fn stability<'py>(
    py: Python<'py>,
    case_name: &str,
    eta_m: Option<f64>,
    eta_f: Option<f64>,
    zeta: Option<f64>,
    zeta_s: Option<f64>,
    error_force: &str,
    eta_p: f64,
    phase_lag: &str,
    k_sub: Vec<usize>,
    omega: (f64, f64, usize),
    vary_name: &str,
    vary: (f64, f64, usize),
) -> PyResult<Bound<'py, PyDict>> {
    let mut base = case(case_name, eta_m, eta_f, zeta, zeta_s, error_force)?;
    base.eta_p = eta_p;
    base.phase_lag = parse_phase_lag(phase_lag)?;
    base.validate().map_err(|e| to_py(&e))?;
    let k_subs = k_subs(&k_sub)?;
    let omegas = linear_grid("omega", omega.0, omega.1, omega.2).map_err(|e| to_py(&e))?;
    if omegas[0] <= 0.0 {
        return Err(bad(
            "omega",
            format!("Ω = ωΔt must be > 0 (got a grid starting at {})", omegas[0]),
        ));
    }
    let param = parameter("vary", vary_name)?;
    let values = linear_grid("vary", vary.0, vary.1, vary.2).map_err(|e| to_py(&e))?;
    let points = py
        .detach(|| stability_map(&base, &k_subs, &omegas, param, &values, &|_| {}))
        .map_err(|e| to_py(&e))?;
    let out = PyDict::new(py);
    out.set_item("k_sub", points.iter().map(|p| p.k_sub).collect::<Vec<_>>())?;
    out.set_item("Omega", points.iter().map(|p| p.omega_dt).collect::<Vec<_>>())?;
    out.set_item(param.name(), points.iter().map(|p| p.value).collect::<Vec<_>>())?;
    out.set_item("rho", points.iter().map(|p| p.rho).collect::<Vec<_>>())?;
    Ok(out)
}

/// Peak amplitude and period errors; see `substep.analyze.accuracy`.
#[pyfunction]
#[pyo3(signature = (case_name, eta_m, eta_f, zeta, zeta_s, error_force, eta_p, k_sub, eta_t, vary_name, vary))]
#[allow(clippy::too_many_arguments)]
pub fn accuracy<'py>(
    py: Python<'py>,
    case_name: &str,
    eta_m: Option<f64>,
    eta_f: Option<f64>,
    zeta: Option<f64>,
    zeta_s: Option<f64>,
    error_force: &str,
    eta_p: Vec<f64>,
    k_sub: Vec<usize>,
    eta_t: Vec<f64>,
    vary_name: Option<&str>,
    vary: Option<(f64, f64, usize)>,
) -> PyResult<Bound<'py, PyDict>> {
    let base = case(case_name, eta_m, eta_f, zeta, zeta_s, error_force)?;
    let k_subs = k_subs(&k_sub)?;
    if eta_t.is_empty() {
        return Err(bad("eta_t", "the list is empty".into()));
    }
    if let Some(b) = eta_t.iter().find(|&&v| !(v > 0.0 && v < 0.5)) {
        return Err(bad(
            "eta_t",
            format!("{b} is outside (0, 0.5) (η_T = Δt/T; the discrete response needs Δt < T/2)"),
        ));
    }
    if eta_p.is_empty() {
        return Err(bad("eta_p", "the list is empty".into()));
    }
    if let Some(b) = eta_p.iter().find(|&&v| !(v >= 0.0 && v.is_finite())) {
        return Err(bad("eta_p", format!("{b} is negative or not finite")));
    }
    let vary = match (vary_name, vary) {
        (Some(name), Some(g)) => Some((
            parameter("vary", name)?,
            linear_grid("vary", g.0, g.1, g.2).map_err(|e| to_py(&e))?,
        )),
        (None, None) => None,
        _ => return Err(bad("vary", "give both the name and the grid".into())),
    };
    let values: Vec<Option<f64>> = match &vary {
        Some((_, v)) => v.iter().map(|&x| Some(x)).collect(),
        None => vec![None],
    };
    // The CLI's job order: k_sub, η_p, the varied value, η_T.
    let mut jobs = Vec::new();
    for &k in &k_subs {
        for &ep in &eta_p {
            for &v in &values {
                for &et in &eta_t {
                    jobs.push((k, ep, v, et));
                }
            }
        }
    }
    let rows = py
        .detach(|| {
            jobs.iter()
                .map(|&(k, ep, v, et)| {
                    let mut c = AnalysisCase {
                        k_sub: k,
                        eta_p: ep,
                        ..base
                    }
                    .with(Parameter::EtaT, et);
                    if let (Some((p, _)), Some(x)) = (&vary, v) {
                        c = c.with(*p, x);
                    }
                    peak_errors(&c).map(|peaks| (k, ep, v, et, peaks))
                })
                .collect::<substep::Result<Vec<_>>>()
        })
        .map_err(|e| to_py(&e))?;
    let mut cols: Vec<(&str, Vec<f64>)> = [
        "k_sub",
        "eta_T",
        "eta_p",
        "value",
        "peak",
        "freq_ratio",
        "h",
        "freq_ratio_exact",
        "h_exact",
        "amplitude_error",
        "period_error",
    ]
    .into_iter()
    .map(|n| (n, Vec::new()))
    .collect();
    for (k, ep, v, et, peaks) in &rows {
        for e in peaks {
            let row = [
                *k as f64,
                *et,
                *ep,
                v.unwrap_or(f64::NAN),
                e.peak as f64,
                e.sub.freq_ratio,
                e.sub.h,
                e.exact.freq_ratio,
                e.exact.h,
                e.amplitude_error,
                e.period_error,
            ];
            for (c, x) in cols.iter_mut().zip(row) {
                c.1.push(x);
            }
        }
    }
    let out = PyDict::new(py);
    for (name, c) in cols {
        let name = match (name, &vary) {
            ("value", Some((p, _))) => p.name(),
            ("value", None) => continue,
            (n, _) => n,
        };
        out.set_item(name, c)?;
    }
    Ok(out)
}
