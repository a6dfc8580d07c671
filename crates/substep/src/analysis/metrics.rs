//! Tracking and accuracy metrics in the style of the RTHS benchmark's J criteria (Silva et al.
//! 2020), for any pair of sampled signals.
//!
//! * [`tracking_delay`]`(desired, measured, h, max_lag) -> Result<f64>` \[s\]: the lag `I·h`,
//!   `I ∈ 0..=max_lag`, of the first maximum of the Pearson correlation
//!   `r(j) = corr(measured[j..N], desired[0..N−j])`.
//! * [`nrms_error`]`(x, r) -> Result<f64>`: `std(x − r) / std(r)` (population std; the ratio
//!   does not depend on the normalisation).
//! * [`peak_error`]`(x, r) -> Result<f64>`: `max|x − r| / max|r|`.
//! * [`round_percent`]`(ratio)`: the benchmark's `round(10000·ratio)/100` [%], and
//!   [`round_delay_ms`]`(seconds)`: `round(10000·s)/10` \[ms\]; both round half away from zero.
//!
//! Errors (never panics): different lengths, fewer than 2 samples, a reference with zero spread
//! (or zero peak), or `max_lag ≥ N − 1`.

use crate::error::{Error, Result};

fn check(x: &[f64], r: &[f64]) -> Result<()> {
    if x.len() != r.len() {
        return Err(Error::invalid(
            "metrics",
            format!("signals have different lengths ({} and {})", x.len(), r.len()),
        ));
    }
    if x.len() < 2 {
        return Err(Error::invalid("metrics", "need at least 2 samples"));
    }
    Ok(())
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// Population standard deviation.
pub fn std_dev(x: &[f64]) -> f64 {
    let m = mean(x);
    (x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / x.len() as f64).sqrt()
}

/// `std(x − r) / std(r)`.
// NaN-safe checks: `!(x > 0.0)` also refuses NaN, which `x <= 0.0` would let through.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn nrms_error(x: &[f64], r: &[f64]) -> Result<f64> {
    check(x, r)?;
    let sr = std_dev(r);
    if !(sr > 0.0) {
        return Err(Error::invalid("metrics", "reference has zero spread"));
    }
    let n = x.len() as f64;
    let md = x.iter().zip(r).map(|(a, b)| a - b).sum::<f64>() / n;
    let sd = (x.iter().zip(r).map(|(a, b)| (a - b - md) * (a - b - md)).sum::<f64>() / n).sqrt();
    Ok(sd / sr)
}

/// `max|x − r| / max|r|`.
// NaN-safe checks: `!(x > 0.0)` also refuses NaN, which `x <= 0.0` would let through.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn peak_error(x: &[f64], r: &[f64]) -> Result<f64> {
    check(x, r)?;
    let pr = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if !(pr > 0.0) {
        return Err(Error::invalid("metrics", "reference has zero peak"));
    }
    Ok(x.iter().zip(r).fold(0.0f64, |m, (a, b)| m.max((a - b).abs())) / pr)
}

/// Pearson correlation of two equally long slices (0 if either has zero spread).
pub fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let (ma, mb) = (mean(a), mean(b));
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (dx, dy) = (x - ma, y - mb);
        sab += dx * dy;
        saa += dx * dx;
        sbb += dy * dy;
    }
    if saa > 0.0 && sbb > 0.0 {
        sab / (saa * sbb).sqrt()
    } else {
        0.0
    }
}

/// Lag \[s\] of the first maximum of the cross-correlation (module docs).
pub fn tracking_delay(desired: &[f64], measured: &[f64], h: f64, max_lag: usize) -> Result<f64> {
    check(desired, measured)?;
    crate::error::require_positive("metrics.h", h)?;
    let n = desired.len();
    if max_lag + 1 >= n {
        return Err(Error::invalid(
            "metrics.max_lag",
            format!("{max_lag} samples leaves fewer than 2 samples of {n}"),
        ));
    }
    let mut best = (0usize, f64::NEG_INFINITY);
    for j in 0..=max_lag {
        let r = pearson(&measured[j..], &desired[..n - j]);
        if r > best.1 {
            best = (j, r);
        }
    }
    Ok(best.0 as f64 * h)
}

/// `round(10000·ratio)/100` [%].
pub fn round_percent(ratio: f64) -> f64 {
    (10000.0 * ratio).round() / 100.0
}

/// `round(10000·seconds)/10` \[ms\] (0.1 ms steps).
pub fn round_delay_ms(seconds: f64) -> f64 {
    (10000.0 * seconds).round() / 10.0
}
