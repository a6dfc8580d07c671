//! The benchmark study of `substep benchmark rths`: several cases (and `k_sub` values), each
//! nominal and optionally with perturbed plants, in parallel; the statistics of the perturbed
//! runs; whether the published table applies.

use super::{Algorithm, Case, ControllerKind, RthsInput, RthsResult, Transfer, run, run_perturbed};
use crate::error::{Error, Result};
use crate::transfer::servo::ServoParams;
use rayon::prelude::*;

/// Most perturbed runs per case.
pub const MAX_PERTURBED: usize = 10_000;

/// One row of results: a case (and `k_sub`), its nominal run and the perturbed runs.
#[derive(Debug, Clone)]
pub struct RthsRow {
    pub case: u8,
    /// The `k_sub` of this row (`None`: the input's own).
    pub k_sub: Option<usize>,
    pub nominal: RthsResult,
    /// Perturbed plants and their runs, in run order.
    pub perturbed: Vec<(ServoParams, RthsResult)>,
}

/// Statistics of perturbed runs: mean and max of each J over the stable runs (NaN if none).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PerturbedStats {
    pub mean: [f64; 9],
    pub max: [f64; 9],
    /// Stable runs, and stable runs that stay under the force capacity.
    pub stable: usize,
    pub under_capacity: usize,
    /// Largest `max |F|` over all runs \[N\] (0 without runs).
    pub max_force: f64,
}

/// [`PerturbedStats`] of `runs`.
pub fn perturbed_stats(runs: &[(ServoParams, RthsResult)]) -> PerturbedStats {
    let ok: Vec<[f64; 9]> = runs
        .iter()
        .filter(|(_, r)| r.stable)
        .filter_map(|(_, r)| r.criteria.map(|c| c.j))
        .collect();
    let mut mean = [f64::NAN; 9];
    let mut max = [f64::NAN; 9];
    if !ok.is_empty() {
        for i in 0..9 {
            mean[i] = ok.iter().map(|j| j[i]).sum::<f64>() / ok.len() as f64;
            max[i] = ok.iter().map(|j| j[i]).fold(f64::MIN, f64::max);
        }
    }
    PerturbedStats {
        mean,
        max,
        stable: runs.iter().filter(|(_, r)| r.stable).count(),
        under_capacity: runs.iter().filter(|(_, r)| r.stable && !r.capacity_exceeded).count(),
        max_force: runs.iter().map(|(_, r)| r.max_force).fold(0.0, f64::max),
    }
}

impl RthsInput {
    /// This input with `k_sub` sub-steps (only for [`Algorithm::Substep`]; otherwise, or with
    /// `None`, unchanged).
    pub fn with_k_sub(&self, k_sub: Option<usize>) -> Self {
        let mut input = self.clone();
        if let (Some(k), Algorithm::Substep(spec)) = (k_sub, &mut input.algorithm) {
            spec.k_sub = k;
        }
        input
    }

    /// The published table (`PUBLISHED_SAMPLE`) applies: the sample controller on the nominal
    /// benchmark (shipped El Centro at 0.4, the benchmark loop, the servo plant).
    pub fn is_published_setting(&self) -> bool {
        self.controller.kind == ControllerKind::Sample
            && self.record.name == "elcentro"
            && (self.intensity - 0.4).abs() < 1e-12
            && matches!(self.algorithm, Algorithm::Benchmark)
            && matches!(self.transfer, Transfer::Plant { .. })
    }
}

/// Run `base` for every case × `k_sub` (in parallel, rows in that order), each nominal and, with
/// `perturbed = Some(n)`, with `n` perturbed plants of seed `seed` ([`run_perturbed`]).
///
/// ```
/// use std::sync::Arc;
/// use substep::benchmark::rths::{Case, ControllerKind, ControllerSpec, GroundRecord, RthsInput, run_study};
/// // A 1 s, 2 Hz sine keeps the example fast (the benchmark's record is El Centro, 50 s).
/// let csv: String = (0..=200).map(|i| {
///     let t = i as f64 * 0.005;
///     format!("{t},{}\n", (2.0 * std::f64::consts::PI * 2.0 * t).sin())
/// }).collect();
/// let mut base = RthsInput::nominal(Case::new(1).unwrap(), ControllerSpec::preset(ControllerKind::Sample));
/// base.record = Arc::new(GroundRecord::parse_csv("sine", &csv).unwrap());
/// let rows = run_study(&base, &[Case::new(1).unwrap(), Case::new(2).unwrap()], &[None], Some(2), 1).unwrap();
/// assert_eq!(rows.len(), 2);
/// assert!(rows.iter().all(|r| r.nominal.stable && r.perturbed.len() == 2));
/// assert!(!base.is_published_setting()); // not the shipped record
/// ```
pub fn run_study(
    base: &RthsInput,
    cases: &[Case],
    k_subs: &[Option<usize>],
    perturbed: Option<usize>,
    seed: u64,
) -> Result<Vec<RthsRow>> {
    if let Some(n) = perturbed
        && !(1..=MAX_PERTURBED).contains(&n)
    {
        return Err(Error::invalid(
            "perturbed runs",
            format!("must be in 1..={MAX_PERTURBED}, got {n}"),
        ));
    }
    let jobs: Vec<(Case, Option<usize>)> = cases
        .iter()
        .flat_map(|c| k_subs.iter().map(move |k| (*c, *k)))
        .collect();
    jobs.par_iter()
        .map(|&(case, k_sub)| -> Result<RthsRow> {
            let mut input = base.with_k_sub(k_sub);
            input.case = case;
            let nominal = run(&input)?;
            let perturbed = match perturbed {
                Some(n) => run_perturbed(&input, n, seed)?,
                None => Vec::new(),
            };
            Ok(RthsRow {
                case: case.number,
                k_sub,
                nominal,
                perturbed,
            })
        })
        .collect()
}
