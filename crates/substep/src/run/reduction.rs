//! The error of a reduced numerical substructure (`[structure.reduction]`): the estimate
//! computed before the test, and the check against the full model after an offline run.
//!
//! **Estimate.** The bases of the reduction are nested: the test's `N` modes and the estimate's
//! basis with every mode up to `2 ω_{N+1}` (`model::Reduction`). The test's assembled model
//! (numerical substructure and specimen models, the test's Newmark scheme and `Δt`; the numerical
//! substructure alone when a specimen has no model) is integrated through the record with both.
//! With the static correction in both bases, a dropped mode `j` contributes only its dynamic
//! amplification `(ω/ω_j)² / (1 − (ω/ω_j)²)` of its static part, so the error of the enriched
//! basis is about a quarter of the test's (`ω_j` doubled) and `q = ½` bounds the ratio with a
//! margin: `|e_N| ≤ d + |e_rich| ≤ d + ½ |e_N|`, i.e. `|e_N| ≤ 2 d`, where `d = |u_N − u_rich|`
//! (peak over time of each kept DOF relative to its peak in the enriched run; the largest over
//! the kept DOFs). When the enrichment stops short of `2 ω_{N+1}` (the cap on modes), the factor
//! is 10 and the estimate says it is unreliable.
//!
//! **Check.** After an offline virtual test, the same test runs on the full model; the error is
//! the peak over time of `|u_reduced − u_full|` of each kept DOF relative to its full-model peak.

use crate::error::Result;
use crate::io::TestDefinition;
use crate::model::Model;
use serde::Serialize;

/// The error of the enriched basis over the test's at most (module docs).
pub const RATIO: f64 = 0.5;
/// Below this error (relative to the peak) the reduced and the full run differ by their own
/// arithmetic, not by the truncation, and a measured error above the estimate is no warning
/// (measured: 3e-7 against an estimate of 4e-8 with 200 of a 1 740-DOF frame's modes).
pub const CHECK_FLOOR: f64 = 1e-6;
/// The ratio assumed when the enrichment is cut short.
pub const RATIO_CUT_SHORT: f64 = 0.9;

/// What `summary.json` says of a reduction.
#[derive(Debug, Clone, Serialize)]
pub struct ReductionSummary {
    pub method: &'static str,
    pub full_dofs: usize,
    pub reduced_dofs: usize,
    /// The full model's DOF (1-based) of each of the reduced model's first DOFs (`u1`, `u2`, …).
    pub kept_dofs: Vec<usize>,
    pub modes: usize,
    pub static_correction: bool,
    /// The highest kept and the lowest dropped fixed-interface frequency \[Hz\] (Ritz vectors:
    /// the basis's largest Ritz frequency, and none).
    pub highest_kept_hz: f64,
    pub lowest_dropped_hz: Option<f64>,
    /// The estimated error: peak displacement error of a kept DOF relative to its peak.
    pub error_estimate: f64,
    /// Modes of the estimate's enriched basis and its highest frequency \[Hz\].
    pub estimate_modes: usize,
    pub estimate_highest_hz: f64,
    /// The enrichment stopped short of twice the first dropped frequency: the estimate is a
    /// guess.
    pub estimate_unreliable: bool,
    pub seconds: f64,
    /// The measured error against the full model, per kept DOF (after an offline virtual test).
    pub check: Option<ReductionCheck>,
    /// Why there is no check.
    pub no_check: Option<String>,
}

#[derive(Debug, Clone, Serialize)]
pub struct ReductionCheck {
    /// The largest over the kept DOFs.
    pub max_error: f64,
    pub dofs: Vec<KeptError>,
    pub full_run_seconds: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct KeptError {
    /// 1-based, full model.
    pub dof: usize,
    /// Peak |u_reduced − u_full| over the full model's peak of this DOF.
    pub error: f64,
    pub peak: f64,
}

/// Displacements of the first `nb` DOFs at every step of the test's assembled model on `model`.
fn kept_history(def: &TestDefinition, model: Model, nb: usize) -> Result<Vec<Vec<f64>>> {
    let mut def = TestDefinition {
        model,
        reduction: None,
        ..def.clone()
    };
    let ag = def.ground_motion.accel.clone();
    let mut out = vec![Vec::with_capacity(ag.len()); nb];
    let push = |u: &[f64], out: &mut Vec<Vec<f64>>| {
        for (k, o) in out.iter_mut().enumerate() {
            o.push(u[k]);
        }
    };
    if let Some(mut r) = super::simulation::Reference::same_integrator(&def)? {
        push(r.u(), &mut out);
        for &a in &ag[1..] {
            r.step(a)?;
            push(r.u(), &mut out);
        }
        return Ok(out);
    }
    def.substructure = None;
    let mut sim = super::simulation::Simulation::new(&def)?;
    push(sim.state().u.as_slice(), &mut out);
    for _ in 1..ag.len() {
        sim.step(&mut ())?;
        push(sim.state().u.as_slice(), &mut out);
    }
    Ok(out)
}

/// Peak over time of `|a − b|` relative to the peak of `reference`, per DOF.
fn relative_peaks(a: &[Vec<f64>], b: &[Vec<f64>], reference: &[Vec<f64>]) -> Vec<(f64, f64)> {
    a.iter()
        .zip(b)
        .zip(reference)
        .map(|((a, b), r)| {
            let peak = r.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
            let err = a.iter().zip(b).fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()));
            (if peak > 0.0 { err / peak } else { 0.0 }, peak)
        })
        .collect()
}

/// The estimate of the module docs, before the test.
pub fn estimate(def: &TestDefinition) -> Result<Option<ReductionSummary>> {
    let Some(red) = &def.reduction else { return Ok(None) };
    let r = &red.reduction;
    let nb = r.kept.len();
    let n = r.modes;
    let rich = r.computed_modes();
    let cut_short = r.enrichment_cut_short;
    let error_estimate = if nb == 0 || rich == n {
        0.0 // every mode of the structure is in the basis: the reduction is exact
    } else {
        let test = kept_history(def, r.model(n)?.into(), nb)?;
        let fine = kept_history(def, r.model(rich)?.into(), nb)?;
        let d = relative_peaks(&test, &fine, &fine)
            .iter()
            .fold(0.0_f64, |m, e| m.max(e.0));
        let q = if cut_short { RATIO_CUT_SHORT } else { RATIO };
        d / (1.0 - q)
    };
    Ok(Some(ReductionSummary {
        method: r.method.name(),
        full_dofs: r.n_full,
        reduced_dofs: r.size(n),
        kept_dofs: r.kept.iter().map(|d| d + 1).collect(),
        modes: n,
        static_correction: r.residual,
        highest_kept_hz: r.basis_top_hz[0],
        lowest_dropped_hz: r.frequencies_hz.get(n).copied(),
        error_estimate,
        estimate_modes: rich,
        estimate_highest_hz: r.basis_top_hz[1],
        estimate_unreliable: cut_short,
        seconds: red.seconds,
        check: None,
        no_check: red.no_check.clone(),
    }))
}

/// Run the test on the full model and compare its kept DOFs with `reduced` (the reduced run's
/// first DOFs at every step). `None` when the definition has no check.
pub fn check(def: &TestDefinition, reduced: &[Vec<f64>]) -> Result<Option<ReductionCheck>> {
    let Some(red) = &def.reduction else { return Ok(None) };
    let Some(full) = &red.full else { return Ok(None) };
    let start = std::time::Instant::now();
    let kept = &red.reduction.kept;
    let mut sim = super::simulation::Simulation::new(full)?;
    let mut out = vec![Vec::with_capacity(full.integrator.steps + 1); kept.len()];
    let push = |u: &[f64], out: &mut Vec<Vec<f64>>| {
        for (o, &d) in out.iter_mut().zip(kept) {
            o.push(u[d]);
        }
    };
    push(sim.state().u.as_slice(), &mut out);
    while sim.steps_done() < sim.steps_total() {
        sim.step(&mut ())?;
        push(sim.state().u.as_slice(), &mut out);
    }
    let per = relative_peaks(reduced, &out, &out);
    let dofs: Vec<KeptError> = per
        .iter()
        .zip(kept)
        .map(|(&(error, peak), &d)| KeptError {
            dof: d + 1,
            error,
            peak,
        })
        .collect();
    Ok(Some(ReductionCheck {
        max_error: dofs.iter().fold(0.0, |m, e| m.max(e.error)),
        dofs,
        full_run_seconds: start.elapsed().as_secs_f64(),
    }))
}
