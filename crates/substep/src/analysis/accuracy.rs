//! Accuracy over a parameter grid (docs/theory.md §9.5): the amplitude and period errors of the
//! transfer-function peaks ([`super::frequency::peak_errors`]) for every `k_sub × η_p × value ×
//! η_T`, and the transfer functions themselves for plotting.

use super::frequency::{DiscreteResponse, PeakError, exact_amplification, peak_errors};
use super::{AnalysisCase, Parameter};
use crate::error::Result;
use rayon::prelude::*;

/// The grid of an accuracy study.
#[derive(Debug, Clone, PartialEq)]
pub struct AccuracyGrid {
    pub k_subs: Vec<usize>,
    /// Phase-lag ratios `η_p = τ/Δt`.
    pub eta_ps: Vec<f64>,
    /// Dimensionless time steps `η_T = Δt/T`.
    pub eta_ts: Vec<f64>,
    /// An optional series parameter and its values (one more grid axis).
    pub vary: Option<(Parameter, Vec<f64>)>,
}

/// The peaks of one grid point.
#[derive(Debug, Clone, PartialEq)]
pub struct AccuracyRow {
    pub k_sub: usize,
    pub eta_t: f64,
    pub eta_p: f64,
    /// The value of the series parameter, if the grid varies one.
    pub value: Option<f64>,
    pub peaks: Vec<PeakError>,
}

/// [`peak_errors`] on every point of `grid` (in parallel), ordered by `k_sub`, `η_p`, value,
/// `η_T`. `progress` is called with the number of points finished so far (from worker threads).
///
/// ```
/// use substep::analysis::AnalysisCase;
/// use substep::analysis::accuracy::{AccuracyGrid, accuracy_rows};
/// let grid = AccuracyGrid { k_subs: vec![1, 4], eta_ps: vec![0.0], eta_ts: vec![0.02], vary: None };
/// let rows = accuracy_rows(&AnalysisCase::typical_tmd(), &grid, &|_| {}).unwrap();
/// assert_eq!(rows.len(), 2);
/// // Sub-stepping reduces the amplitude error of the first peak.
/// let err = |r: &substep::analysis::accuracy::AccuracyRow| r.peaks[0].amplitude_error.abs();
/// assert!(err(&rows[1]) < err(&rows[0]));
/// ```
pub fn accuracy_rows(
    base: &AnalysisCase,
    grid: &AccuracyGrid,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Vec<AccuracyRow>> {
    let values: Vec<Option<f64>> = match &grid.vary {
        Some((_, v)) => v.iter().map(|&x| Some(x)).collect(),
        None => vec![None],
    };
    let mut jobs = Vec::new();
    for &k in &grid.k_subs {
        for &ep in &grid.eta_ps {
            for &v in &values {
                for &et in &grid.eta_ts {
                    jobs.push((k, ep, v, et));
                }
            }
        }
    }
    let done = std::sync::atomic::AtomicUsize::new(0);
    jobs.par_iter()
        .map(|&(k, ep, v, et)| {
            let mut c = AnalysisCase {
                k_sub: k,
                eta_p: ep,
                ..*base
            }
            .with(Parameter::EtaT, et);
            if let (Some((p, _)), Some(x)) = (&grid.vary, v) {
                c = c.with(*p, x);
            }
            let peaks = peak_errors(&c)?;
            progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1);
            Ok(AccuracyRow {
                k_sub: k,
                eta_t: et,
                eta_p: ep,
                value: v,
                peaks,
            })
        })
        .collect()
}

/// Transfer functions `h(r)` at the frequency ratios `r`: one curve per `η_T` of `eta_ts`
/// (`k_sub`, `η_p` as given), and the exact 2-DOF curve of `base` last (NaN where it cannot be
/// evaluated).
pub fn transfer_functions(
    base: &AnalysisCase,
    k_sub: usize,
    eta_p: f64,
    eta_ts: &[f64],
    r: &[f64],
) -> Result<(Vec<Vec<f64>>, Vec<f64>)> {
    let curves = eta_ts
        .iter()
        .map(|&et| {
            let c = AnalysisCase { k_sub, eta_p, ..*base }.with(Parameter::EtaT, et);
            let resp = DiscreteResponse::new(&c)?;
            Ok(r.iter().map(|&x| resp.amplification(x)).collect())
        })
        .collect::<Result<Vec<Vec<f64>>>>()?;
    let exact = r
        .iter()
        .map(|&x| exact_amplification(base, x).unwrap_or(f64::NAN))
        .collect();
    Ok((curves, exact))
}
