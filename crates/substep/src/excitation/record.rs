//! The uniformly sampled ground-acceleration record and its interpolation.

use super::MAX_SAMPLES;
use crate::error::{Error, Result, require_non_negative, require_positive};

/// Tolerance (in units of samples) within which a time is considered to lie on the record, so
/// that `t = duration` computed with rounding errors still gives the last sample.
const INDEX_TOL: f64 = 1e-9;

/// Relative tolerance on the spacing of given sample times under which they count as uniform.
const UNIFORM_TOL: f64 = 1e-6;

/// Ground acceleration sampled uniformly from `t = 0`: `accel[i]` is `a_g(i·dt)` in m/s².
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Sampling interval in s.
    pub dt: f64,
    /// Ground acceleration in m/s², sample 0 at `t = 0`.
    pub accel: Vec<f64>,
}

/// Builds the error of one input source: [`Error::file`] for readers, [`Error::invalid`] for
/// in-memory data.
pub(crate) type MakeError = fn(String, String) -> Error;

impl Record {
    /// A checked record: `dt` finite and > 0, at least one sample, all samples finite.
    pub fn new(dt: f64, accel: Vec<f64>) -> Result<Self> {
        let record = Self { dt, accel };
        record.validate("record")?;
        Ok(record)
    }

    /// Check the invariants of [`Record::new`] (the fields are public, so a record may have been
    /// built by hand); `what` names the record in the message.
    pub fn validate(&self, what: &str) -> Result<()> {
        require_positive(&format!("{what}.dt"), self.dt)?;
        if self.accel.is_empty() {
            return Err(Error::invalid(what, "no data"));
        }
        if let Some((i, a)) = self.accel.iter().enumerate().find(|(_, a)| !a.is_finite()) {
            return Err(Error::invalid(what, format!("sample {i}: value is not finite ({a})")));
        }
        Ok(())
    }

    /// Duration `(len − 1)·dt` in s (0 for a record with fewer than two samples).
    pub fn duration(&self) -> f64 {
        self.accel.len().saturating_sub(1) as f64 * self.dt
    }

    /// Peak ground acceleration `max |a_g|` in m/s² (0 for an empty record).
    pub fn pga(&self) -> f64 {
        self.accel.iter().fold(0.0, |m, a| m.max(a.abs()))
    }

    /// The record with every sample multiplied by `factor` (which must be finite).
    pub fn scaled(&self, factor: f64) -> Result<Record> {
        if !factor.is_finite() {
            return Err(Error::invalid(
                "scale factor",
                format!("must be a finite number, got {factor}"),
            ));
        }
        Ok(Record {
            dt: self.dt,
            accel: self.accel.iter().map(|a| a * factor).collect(),
        })
    }

    /// `a_g(t)` by linear interpolation between samples; `0.0` before `t = 0` and after the end
    /// of the record (the ground is at rest there), NaN for a NaN `t`.
    pub fn value_at(&self, t: f64) -> f64 {
        let n = self.accel.len();
        if t.is_nan() {
            return f64::NAN;
        }
        if n == 0 {
            return 0.0;
        }
        let last = (n - 1) as f64;
        let s = t / self.dt;
        if s < -INDEX_TOL || s > last + INDEX_TOL {
            return 0.0;
        }
        if n == 1 {
            return self.accel[0];
        }
        let s = s.clamp(0.0, last);
        let i = (s.floor() as usize).min(n - 2);
        let frac = s - i as f64;
        let (a0, a1) = (self.accel[i], self.accel[i + 1]);
        a0 + frac * (a1 - a0)
    }

    /// Values at `t_i = i·dt_new`, `i = 0..=floor(duration/dt_new + 1e-9)`, by linear
    /// interpolation ([`Record::value_at`]). `duration` defaults to the record's duration; where
    /// it reaches beyond the end of the record the values are `0.0`.
    pub fn resample(&self, dt_new: f64, duration: Option<f64>) -> Result<Vec<f64>> {
        self.validate("record")?;
        require_positive("resample.dt", dt_new)?;
        let duration = match duration {
            Some(d) => require_non_negative("resample.duration", d)?,
            None => self.duration(),
        };
        let n = sample_count("resample", duration, dt_new)?;
        Ok((0..n).map(|i| self.value_at(i as f64 * dt_new)).collect())
    }

    /// A record from samples `(times[k], values[k])`, e.g. a two-column file.
    ///
    /// Times must be finite, `>= 0` and strictly increasing; values finite. If the first time is
    /// above 0, the record still starts at `t = 0`, with `a_g` rising linearly from `(0, 0)` to the
    /// first sample. If the spacing is uniform (relative tolerance 1e-6) the samples are kept as
    /// they are; otherwise the data are resampled by linear interpolation to the smallest
    /// spacing, up to the last given time. `name` names the data in messages, which refer to
    /// samples by their 0-based index.
    pub fn from_samples(times: &[f64], values: &[f64], name: &str) -> Result<Record> {
        if times.len() != values.len() {
            return Err(Error::invalid(
                name,
                format!("{} times but {} values", times.len(), values.len()),
            ));
        }
        from_located_samples(times, values, name, |k| format!("sample {k}"), Error::invalid)
    }
}

/// Number of samples `floor(duration/dt + 1e-9) + 1` of a uniform grid, limited to
/// [`MAX_SAMPLES`]. Arguments must already be validated (`dt > 0`, `duration >= 0`).
pub(crate) fn sample_count(what: &str, duration: f64, dt: f64) -> Result<usize> {
    let steps = (duration / dt + INDEX_TOL).floor();
    if !steps.is_finite() || steps >= MAX_SAMPLES as f64 {
        return Err(Error::invalid(
            what,
            format!("a duration of {duration} s at dt = {dt} s needs more than {MAX_SAMPLES} samples"),
        ));
    }
    Ok(steps as usize + 1)
}

/// [`Record::from_samples`] with `loc(k)` naming sample `k` in messages (e.g. `line 9`) and
/// `err` building the error. `times` and `values` have equal length.
pub(crate) fn from_located_samples(
    times: &[f64],
    values: &[f64],
    name: &str,
    loc: impl Fn(usize) -> String,
    err: MakeError,
) -> Result<Record> {
    let fail = |reason: String| Err(err(name.to_string(), reason));
    if times.is_empty() {
        return fail("no data".into());
    }
    for (k, (&t, &a)) in times.iter().zip(values).enumerate() {
        if !t.is_finite() {
            return fail(format!("{}: time is not finite ({t})", loc(k)));
        }
        if !a.is_finite() {
            return fail(format!("{}: value is not finite ({a})", loc(k)));
        }
        if k == 0 && t < 0.0 {
            return fail(format!(
                "{}: time must be >= 0 (the record starts at t = 0), got {t}",
                loc(k)
            ));
        }
        if k > 0 && t <= times[k - 1] {
            let prev = times[k - 1];
            return fail(format!("times are not increasing at {} (t = {t} after {prev})", loc(k)));
        }
    }

    // Samples of the record from t = 0: a first time that is zero up to the uniformity
    // tolerance counts as 0, a later one gets a (0, 0) sample in front.
    let t0 = times[0];
    let first_gap = times.get(1).map_or(0.0, |t1| t1 - t0);
    let (ts, vs): (Vec<f64>, Vec<f64>) = if t0 <= UNIFORM_TOL * first_gap {
        let mut ts = times.to_vec();
        ts[0] = 0.0;
        (ts, values.to_vec())
    } else {
        (
            std::iter::once(0.0).chain(times.iter().copied()).collect(),
            std::iter::once(0.0).chain(values.iter().copied()).collect(),
        )
    };
    let m = ts.len();
    if m < 2 {
        return fail("at least two samples are needed to determine the time step".into());
    }

    let t_end = ts[m - 1];
    let mean = t_end / (m - 1) as f64;
    let (mut h_min, mut uniform) = (f64::INFINITY, true);
    for w in ts.windows(2) {
        let h = w[1] - w[0];
        h_min = h_min.min(h);
        uniform &= (h - mean).abs() <= UNIFORM_TOL * mean;
    }
    if uniform {
        return Ok(Record { dt: mean, accel: vs });
    }

    // Non-uniform: linear interpolation onto the smallest spacing.
    let n = sample_count(name, t_end, h_min).map_err(|_| {
        err(
            name.to_string(),
            format!(
                "times are not uniform and resampling to the smallest spacing {h_min} s over \
             {t_end} s would need more than {MAX_SAMPLES} samples"
            ),
        )
    })?;
    let mut accel = Vec::with_capacity(n);
    let mut j = 0;
    for i in 0..n {
        let t = i as f64 * h_min;
        while j + 2 < m && ts[j + 1] <= t {
            j += 1;
        }
        let frac = ((t - ts[j]) / (ts[j + 1] - ts[j])).clamp(0.0, 1.0);
        accel.push(vs[j] + frac * (vs[j + 1] - vs[j]));
    }
    Ok(Record { dt: h_min, accel })
}
