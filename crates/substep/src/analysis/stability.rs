//! Stability maps: `ρ` over a grid of `Ω` and one other parameter, for several `k_sub`.

use super::{AnalysisCase, Parameter, Stability};
use crate::error::{Error, Result};
use nalgebra::DMatrix;
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

/// The map of one `k_sub` with its stability limits.
#[derive(Debug, Clone, PartialEq)]
pub struct KSubMap {
    pub k_sub: usize,
    /// `ρ[(iv, iw)]` at `(values[iv], omegas[iw])`.
    pub rho: DMatrix<f64>,
    /// Per value (row): the critical `Ω` of [`critical_omega`], `None` if the row is stable.
    pub critical: Vec<Option<f64>>,
    /// Share of the grid that is stable or limited (`Stability::classify` with the study's
    /// tolerance).
    pub stable_share: f64,
}

/// A stability map over `k_subs × values × omegas` with its limits ([`stability_study`]).
#[derive(Debug, Clone, PartialEq)]
pub struct StabilityStudy {
    /// The y axis: the varied parameter and its values.
    pub param: Parameter,
    pub values: Vec<f64>,
    /// The x axis, `Ω = ωΔt`.
    pub omegas: Vec<f64>,
    /// Band around `ρ = 1` taken as limited stability.
    pub tol: f64,
    /// Every grid point, ordered by `k_sub`, then value, then `Ω` (as [`stability_map`]).
    pub points: Vec<MapPoint>,
    /// One map per `k_sub`, in the order given.
    pub maps: Vec<KSubMap>,
}

/// [`stability_map`] on the grid, then per `k_sub` the `ρ` matrix, the critical `Ω` of each row
/// (band `tol`) and the stable share. `progress` as for [`stability_map`].
///
/// ```
/// use substep::analysis::stability::{linear_grid, stability_study};
/// use substep::analysis::{AnalysisCase, Parameter};
/// let omegas = linear_grid("Omega", 0.1, 3.0, 8).unwrap();
/// let values = linear_grid("zeta_s", 0.0, 0.5, 3).unwrap();
/// let s = stability_study(&AnalysisCase::typical_tmd(), &[1, 2], &omegas, Parameter::ZetaS, &values, 1e-9, &|_| {})
///     .unwrap();
/// assert_eq!(s.maps.len(), 2);
/// assert_eq!(s.maps[0].rho.shape(), (3, 8));
/// assert!(s.maps.iter().all(|m| (0.0..=1.0).contains(&m.stable_share)));
/// ```
pub fn stability_study(
    base: &AnalysisCase,
    k_subs: &[usize],
    omegas: &[f64],
    param: Parameter,
    values: &[f64],
    tol: f64,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<StabilityStudy> {
    let points = stability_map(base, k_subs, omegas, param, values, progress)?;
    let (nv, nw) = (values.len(), omegas.len());
    let maps = k_subs
        .iter()
        .enumerate()
        .map(|(ik, &k)| {
            // `stability_map` keeps the order k_sub, value, Ω.
            let block = &points[ik * nv * nw..(ik + 1) * nv * nw];
            let rho = DMatrix::from_fn(nv, nw, |iv, iw| block[iv * nw + iw].rho);
            let critical = (0..nv)
                .map(|iv| {
                    let row: Vec<(f64, f64)> = omegas.iter().copied().zip(rho.row(iv).iter().copied()).collect();
                    critical_omega(&row, tol)
                })
                .collect();
            let stable = block
                .iter()
                .filter(|p| Stability::classify(p.rho, tol) != Stability::Unstable)
                .count();
            KSubMap {
                k_sub: k,
                rho,
                critical,
                stable_share: stable as f64 / (nw * nv) as f64,
            }
        })
        .collect();
    Ok(StabilityStudy {
        param,
        values: values.to_vec(),
        omegas: omegas.to_vec(),
        tol,
        points,
        maps,
    })
}
