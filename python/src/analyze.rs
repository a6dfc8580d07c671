//! `substep.analyze`: the stability map and the accuracy table of the sub-step algorithm
//! (docs/analysis.md), the library functions `substep analyze stability|accuracy` call, with
//! the CLI's defaults. The parameters arrive as Python values instead of flag strings; the
//! small parsers here only translate them (messages name the keyword argument).

use crate::to_py;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use substep::analysis::accuracy::{AccuracyGrid, accuracy_rows, transfer_functions};
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

/// `none`, `polynomial:ORDER` or `arx`.
fn parse_phase_lag(s: &str) -> PyResult<Option<FrozenPhaseLag>> {
    if s == "none" {
        return Ok(None);
    }
    if s == "arx" {
        return Ok(Some(FrozenPhaseLag::Arx));
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
            format!("expected none, polynomial:ORDER or arx, got '{s}'"),
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
    let grid = AccuracyGrid {
        k_subs,
        eta_ps: eta_p,
        eta_ts: eta_t,
        vary,
    };
    let rows = py
        .detach(|| accuracy_rows(&base, &grid, &|_| {}))
        .map_err(|e| to_py(&e))?;
    let vary = grid.vary;
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
    for r in &rows {
        for e in &r.peaks {
            let row = [
                r.k_sub as f64,
                r.eta_t,
                r.eta_p,
                r.value.unwrap_or(f64::NAN),
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

/// `|h(r)|` of the algorithm and of the exact system; see `substep.analyze.transfer_function`.
#[pyfunction]
#[pyo3(signature = (case_name, eta_m, eta_f, zeta, zeta_s, error_force, eta_p, k_sub, eta_t, r))]
#[allow(clippy::too_many_arguments)]
pub fn transfer_function<'py>(
    py: Python<'py>,
    case_name: &str,
    eta_m: Option<f64>,
    eta_f: Option<f64>,
    zeta: Option<f64>,
    zeta_s: Option<f64>,
    error_force: &str,
    eta_p: f64,
    k_sub: usize,
    eta_t: f64,
    r: Vec<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let base = case(case_name, eta_m, eta_f, zeta, zeta_s, error_force)?;
    k_subs(&[k_sub])?;
    if !(eta_t > 0.0 && eta_t < 0.5) {
        return Err(bad(
            "eta_t",
            format!("{eta_t} is outside (0, 0.5) (η_T = Δt/T; the discrete response needs Δt < T/2)"),
        ));
    }
    if !(eta_p >= 0.0 && eta_p.is_finite()) {
        return Err(bad("eta_p", format!("{eta_p} is negative or not finite")));
    }
    if let Some(x) = r.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
        return Err(bad("r", format!("frequency ratios must be finite and > 0, got {x}")));
    }
    let (curves, h_exact) = py
        .detach(|| transfer_functions(&base, k_sub, eta_p, &[eta_t], &r))
        .map_err(|e| to_py(&e))?;
    let out = PyDict::new(py);
    out.set_item("r", r)?;
    out.set_item("h", curves.into_iter().next().unwrap_or_default())?;
    out.set_item("h_exact", h_exact)?;
    Ok(out)
}

/// The test planner for a test definition; see `substep.analyze.plan`.
#[pyfunction]
#[pyo3(signature = (kind, text, name, base_dir, dt, k_sub, delay, tolerance, margin, budget))]
#[allow(clippy::too_many_arguments)]
pub fn plan<'py>(
    py: Python<'py>,
    kind: &str,
    text: &str,
    name: &str,
    base_dir: &str,
    dt: Option<Vec<f64>>,
    k_sub: Option<Vec<usize>>,
    delay: Option<Vec<f64>>,
    tolerance: f64,
    margin: f64,
    budget: f64,
) -> PyResult<Bound<'py, PyDict>> {
    use substep::analysis::plan::{ErrorSource, PlanSettings, plan as scan};
    let def = py
        .detach(|| crate::definition(kind, text, name, base_dir))
        .map_err(|e| to_py(&e))?;
    let Some(sub) = &def.substructure else {
        return Err(bad(
            &def.source,
            "plan needs a [substructure] section (a monolithic run has nothing to plan)".into(),
        ));
    };
    let dts = dt.unwrap_or_else(|| vec![2.0 * def.integrator.dt, def.integrator.dt, 0.5 * def.integrator.dt]);
    if let Some(b) = dts.iter().find(|&&v| !(v > 0.0 && v.is_finite())) {
        return Err(bad("dt", format!("{b} is not > 0")));
    }
    let mut k_subs = match k_sub {
        Some(k) => self::k_subs(&k)?,
        None => vec![1, 2, 4, 8, sub.substeps],
    };
    k_subs.sort_unstable();
    k_subs.dedup();
    let delays = delay.unwrap_or_else(|| vec![sub.actuator.delay]);
    if let Some(b) = delays.iter().find(|&&v| !(v >= 0.0 && v.is_finite())) {
        return Err(bad("delay", format!("{b} is not ≥ 0")));
    }
    for (what, v) in [("tolerance", tolerance), ("margin", margin), ("budget", budget)] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(bad(what, format!("must be a number ≥ 0, got {v}")));
        }
    }
    let model = def.model.dense("substep analyze plan").map_err(|e| to_py(&e))?;
    let settings = PlanSettings {
        dts,
        k_subs,
        delays,
        tolerance,
        min_margin: margin,
        budget,
        cost_steps: 200,
    };
    let result = py.detach(|| scan(sub, &model, &settings)).map_err(|e| to_py(&e))?;
    // The columns of plan.csv, one row per peak of each scanned point.
    let mut num: Vec<(&str, Vec<f64>)> = [
        "dt",
        "k_sub",
        "delay",
        "rho",
        "margin",
        "error",
        "error_dt",
        "error_substep",
        "error_delay",
        "us_per_step",
        "budget_share",
        "peak",
        "freq_hz",
        "freq_hz_exact",
        "amplitude_error",
        "period_error",
    ]
    .into_iter()
    .map(|n| (n, Vec::new()))
    .collect();
    let (mut class, mut dominant) = (Vec::new(), Vec::new());
    for p in &result.points {
        let cls = substep::analysis::Stability::classify(p.rho, 1e-9).name();
        let dom = match p.dominant() {
            ErrorSource::TimeStep => "dt",
            ErrorSource::SubStepping => "sub-step",
            ErrorSource::Delay => "delay",
        };
        let head = [
            p.dt,
            p.k_sub as f64,
            p.delay,
            p.rho,
            p.margin(),
            p.error,
            p.error_dt,
            p.error_substep,
            p.error_delay,
            p.cost * 1e6,
            p.utilisation(),
        ];
        let peaks: Vec<[f64; 5]> = if p.peaks.is_empty() {
            vec![[f64::NAN; 5]]
        } else {
            p.peaks
                .iter()
                .enumerate()
                .map(|(i, pk)| {
                    [
                        (i + 1) as f64,
                        pk.freq_hz,
                        pk.freq_hz_exact,
                        pk.amplitude_error,
                        pk.period_error,
                    ]
                })
                .collect()
        };
        for pk in peaks {
            for (c, x) in num.iter_mut().zip(head.iter().chain(&pk)) {
                c.1.push(*x);
            }
            class.push(cls);
            dominant.push(dom);
        }
    }
    let out = PyDict::new(py);
    for (i, (name, c)) in num.into_iter().enumerate() {
        out.set_item(name, c)?;
        if i == 4 {
            out.set_item("class", class.clone())?;
        }
        if i == 8 {
            out.set_item("dominant", dominant.clone())?;
        }
    }
    out.set_item("phase_lag_note", result.phase_lag_note.clone())?;
    let recommended = result.recommended.map(|i| &result.points[i]).map(|p| {
        let d = PyDict::new(py);
        d.set_item("dt", p.dt)?;
        d.set_item("k_sub", p.k_sub)?;
        d.set_item("delay", p.delay)?;
        Ok::<_, PyErr>(d)
    });
    out.set_item("recommended", recommended.transpose()?)?;
    Ok(out)
}

/// The time-domain verification of the analysis (`substep analyze verify`, docs/theory.md §9.6)
/// with its default checks; see `substep.analyze.verify`.
#[pyfunction]
pub fn verify<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
    use substep::analysis::verification::{VerifySettings, verify_analysis};
    let settings = VerifySettings::default();
    let v = py.detach(|| verify_analysis(&settings)).map_err(|e| to_py(&e))?;
    let rows = v.rows(&settings);
    let out = PyDict::new(py);
    out.set_item("check", rows.iter().map(|r| r.check.clone()).collect::<Vec<_>>())?;
    out.set_item("case", rows.iter().map(|r| r.case.clone()).collect::<Vec<_>>())?;
    out.set_item("k_sub", rows.iter().map(|r| r.k_sub).collect::<Vec<_>>())?;
    out.set_item("Omega", rows.iter().map(|r| r.omega_dt).collect::<Vec<_>>())?;
    out.set_item("eta_p", rows.iter().map(|r| r.eta_p).collect::<Vec<_>>())?;
    out.set_item("quantity", rows.iter().map(|r| r.quantity.clone()).collect::<Vec<_>>())?;
    out.set_item(
        "frequency_domain",
        rows.iter().map(|r| r.frequency_domain).collect::<Vec<_>>(),
    )?;
    out.set_item("time_domain", rows.iter().map(|r| r.time_domain).collect::<Vec<_>>())?;
    out.set_item("agrees", rows.iter().map(|r| r.agrees).collect::<Vec<_>>())?;
    out.set_item("all_agree", v.all_agree)?;
    Ok(out)
}
