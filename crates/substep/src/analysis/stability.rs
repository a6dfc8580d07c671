//! Stability maps: `ρ` over a grid of `Ω` and one other parameter, for several `k_sub`.

use super::{AnalysisCase, Parameter};
use crate::error::{Error, Result};
use rayon::prelude::*;

/// One grid point of a map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapPoint {
    pub k_sub: usize,
    pub omega_dt: f64,
    pub value: f64,
    pub rho: f64,
}

/// Grids larger than this are refused (each point costs ~10–100 µs and 32 bytes).
pub const MAX_GRID_POINTS: usize = 20_000_000;

/// An inclusive linear grid `a:b:n`.
pub fn linear_grid(what: &str, a: f64, b: f64, n: usize) -> Result<Vec<f64>> {
    if !(a.is_finite() && b.is_finite()) {
        return Err(Error::invalid(what, "range bounds must be finite"));
    }
    if n == 0 {
        return Err(Error::invalid(what, "the grid is empty (n = 0)"));
    }
    if n > 1 && b <= a {
        return Err(Error::invalid(
            what,
            format!("range {a}:{b} is empty or inverted (need start < end)"),
        ));
    }
    if n == 1 {
        return Ok(vec![a]);
    }
    Ok((0..n).map(|i| a + (b - a) * i as f64 / (n - 1) as f64).collect())
}

/// Compute `ρ` on the grid `k_subs × values × omegas` in parallel. `progress` is called with
/// the number of points finished so far (from worker threads). Points whose probe fails (e.g.
/// an invalid parameter such as `Ω = 0`) get `ρ = NaN`.
pub fn stability_map(
    base: &AnalysisCase,
    k_subs: &[usize],
    omegas: &[f64],
    param: Parameter,
    values: &[f64],
    progress: &(dyn Fn(usize) + Sync),
) -> Result<Vec<MapPoint>> {
    let total = k_subs.len() * omegas.len() * values.len();
    if total == 0 {
        return Err(Error::invalid("stability map", "the grid is empty"));
    }
    if total > MAX_GRID_POINTS {
        return Err(Error::invalid(
            "stability map",
            format!(
                "{total} grid points is too many (limit {MAX_GRID_POINTS}); it would need ~{:.1} GB and ~{:.0} CPU-minutes",
                total as f64 * 32.0 / 1e9,
                total as f64 * 30e-6 / 60.0
            ),
        ));
    }
    if k_subs.contains(&0) {
        return Err(Error::invalid("k_sub", "must be at least 1"));
    }
    let done = std::sync::atomic::AtomicUsize::new(0);
    let rows: Vec<(usize, f64)> = k_subs
        .iter()
        .flat_map(|&k| values.iter().map(move |&v| (k, v)))
        .collect();
    let points = rows
        .par_iter()
        .flat_map_iter(|&(k, v)| {
            let case = AnalysisCase {
                k_sub: k,
                ..base.with(param, v)
            };
            let row: Vec<MapPoint> = omegas
                .iter()
                .map(|&w| {
                    let c = AnalysisCase { omega_dt: w, ..case };
                    let rho = c.spectral_radius().unwrap_or(f64::NAN);
                    MapPoint {
                        k_sub: k,
                        omega_dt: w,
                        value: v,
                        rho,
                    }
                })
                .collect();
            progress(done.fetch_add(omegas.len(), std::sync::atomic::Ordering::Relaxed) + omegas.len());
            row
        })
        .collect();
    Ok(points)
}

/// The stability limit along one row (points ordered by `Ω`): the first `Ω` where `ρ` crosses
/// `1 + tol`, linearly interpolated; `None` if the whole row is stable; `Some(first Ω)` if it
/// starts unstable.
pub fn critical_omega(row: &[(f64, f64)], tol: f64) -> Option<f64> {
    let limit = 1.0 + tol;
    let mut prev: Option<(f64, f64)> = None;
    for &(w, rho) in row {
        let unstable = !rho.is_finite() || rho > limit;
        if unstable {
            return Some(match prev {
                Some((w0, r0)) if rho.is_finite() => w0 + (limit - r0) / (rho - r0) * (w - w0),
                Some((w0, _)) => w0,
                None => w,
            });
        }
        prev = Some((w, rho));
    }
    None
}
