//! J-style accuracy metrics of a substructure test, accumulated on line (one pass, bounded
//! memory), so any `substep run` can be compared with the figures of the RTHS benchmark.
//!
//! For a signal `x` and its reference `r` sampled at `N` instants (sample standard deviations,
//! the `N − 1` normalisations cancel in the ratios):
//!
//! * normalised RMS error `NRMS = std(x − r) / std(r)`;
//! * normalised peak error `peak = max|x − r| / max|r|`;
//! * tracking delay: the Pearson correlation `ρ(j)` of the measured `x[j..N]` with the desired
//!   `d[0..N−j]` for lags `j = 0 … L`; the delay is `j* h` with `j*` the **first** lag of
//!   maximum correlation (the benchmark's J1 rule), `h` the sample time.
//!
//! [`ErrorAccumulator`] uses Welford's update (no cancellation for signals with an offset).
//! [`DelayAccumulator`] keeps, per lag, `Σ x_k d_{k−j}`, the first `L` samples of `x` and the
//! last `L` of `d`: the per-lag sums of `x`, `x²` over `k ≥ j` and of `d`, `d²` over
//! `k < N − j` follow from the totals, so memory is `O(L)` and each sample costs `O(L)`.
//! Both signals are shifted by the first desired sample (Pearson's `ρ` is shift-invariant) to
//! keep the sums well conditioned. `tests/tracking_metrics.rs` checks both against a direct
//! two-pass implementation.

use crate::substructure::SubstepObserver;

/// Streaming `std(x − r) / std(r)` and `max|x − r| / max|r|` of one channel.
#[derive(Debug, Clone, Default)]
pub struct ErrorAccumulator {
    count: usize,
    mean_e: f64,
    m2_e: f64,
    mean_r: f64,
    m2_r: f64,
    max_e: f64,
    max_r: f64,
}

impl ErrorAccumulator {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn push(&mut self, x: f64, reference: f64) {
        let e = x - reference;
        self.count += 1;
        let n = self.count as f64;
        let de = e - self.mean_e;
        self.mean_e += de / n;
        self.m2_e += de * (e - self.mean_e);
        let dr = reference - self.mean_r;
        self.mean_r += dr / n;
        self.m2_r += dr * (reference - self.mean_r);
        // NaN-safe maxima: a NaN sample poisons the result instead of vanishing.
        self.max_e = if e.abs() >= self.max_e || e.is_nan() {
            e.abs()
        } else {
            self.max_e
        };
        self.max_r = if reference.abs() >= self.max_r || reference.is_nan() {
            reference.abs()
        } else {
            self.max_r
        };
    }

    pub fn count(&self) -> usize {
        self.count
    }

    /// `std(x − r) / std(r)`; NaN when the reference does not vary (fewer than 2 samples or
    /// constant).
    pub fn nrms(&self) -> f64 {
        if self.count < 2 || self.m2_r <= 0.0 {
            return f64::NAN;
        }
        (self.m2_e / self.m2_r).sqrt()
    }

    /// `max|x − r| / max|r|`; NaN when the reference is identically zero.
    pub fn peak(&self) -> f64 {
        if self.max_r > 0.0 {
            self.max_e / self.max_r
        } else {
            f64::NAN
        }
    }
}

/// Streaming cross-correlation delay estimate between a desired and a measured signal.
#[derive(Debug, Clone)]
pub struct DelayAccumulator {
    max_lag: usize,
    count: usize,
    shift: f64,
    /// `Σ_{k ≥ j} x_k d_{k−j}` per lag `j`.
    cross: Vec<f64>,
    /// The last `max_lag + 1` desired samples (ring, newest at `head`).
    recent_d: Vec<f64>,
    head: usize,
    /// The first `max_lag` measured samples.
    first_x: Vec<f64>,
    sum_x: f64,
    sum_xx: f64,
    sum_d: f64,
    sum_dd: f64,
}

impl DelayAccumulator {
    /// Lags `0 ..= max_lag` samples.
    pub fn new(max_lag: usize) -> Self {
        Self {
            max_lag,
            count: 0,
            shift: 0.0,
            cross: vec![0.0; max_lag + 1],
            recent_d: vec![0.0; max_lag + 1],
            head: 0,
            first_x: Vec::with_capacity(max_lag),
            sum_x: 0.0,
            sum_xx: 0.0,
            sum_d: 0.0,
            sum_dd: 0.0,
        }
    }

    pub fn max_lag(&self) -> usize {
        self.max_lag
    }

    /// One sample: `desired` (the command) and `measured` at the same instant.
    pub fn push(&mut self, desired: f64, measured: f64) {
        if self.count == 0 {
            self.shift = desired;
        }
        let d = desired - self.shift;
        let x = measured - self.shift;
        let len = self.recent_d.len();
        self.head = (self.head + 1) % len;
        self.recent_d[self.head] = d;
        // cross[j] += x · d_{k−j}: lags 0..=head read the ring backwards from head, the rest
        // wrap around to its end (two straight loops, no index arithmetic per lag).
        let lags = self.max_lag.min(self.count);
        let first = lags.min(self.head);
        for (c, &d) in self.cross[..=first]
            .iter_mut()
            .zip(self.recent_d[..=self.head].iter().rev())
        {
            *c += x * d;
        }
        if lags > self.head {
            let rest = lags - self.head;
            for (c, &d) in self.cross[self.head + 1..=lags]
                .iter_mut()
                .zip(self.recent_d[len - rest..].iter().rev())
            {
                *c += x * d;
            }
        }
        if self.first_x.len() < self.max_lag {
            self.first_x.push(x);
        }
        self.sum_x += x;
        self.sum_xx += x * x;
        self.sum_d += d;
        self.sum_dd += d * d;
        self.count += 1;
    }

    /// Pearson correlation at lag `j` (NaN if a signal does not vary over the overlap or there
    /// are fewer than 2 overlapping samples).
    pub fn correlation(&self, j: usize) -> f64 {
        if j > self.max_lag || self.count < j + 2 {
            return f64::NAN;
        }
        let n = (self.count - j) as f64;
        let (mut sx, mut sxx) = (self.sum_x, self.sum_xx);
        for &x in &self.first_x[..j] {
            sx -= x;
            sxx -= x * x;
        }
        let (mut sd, mut sdd) = (self.sum_d, self.sum_dd);
        let len = self.recent_d.len();
        for i in 0..j {
            let d = self.recent_d[(self.head + len - i) % len];
            sd -= d;
            sdd -= d * d;
        }
        let cov = n * self.cross[j] - sx * sd;
        let var = (n * sxx - sx * sx) * (n * sdd - sd * sd);
        if var > 0.0 { cov / var.sqrt() } else { f64::NAN }
    }

    /// The first lag of maximum correlation, in samples (`None` before two samples or when no
    /// lag has a defined correlation).
    pub fn best_lag(&self) -> Option<usize> {
        let mut best: Option<(usize, f64)> = None;
        for j in 0..=self.max_lag {
            let r = self.correlation(j);
            if r.is_nan() {
                continue;
            }
            if best.is_none_or(|(_, b)| r > b) {
                best = Some((j, r));
            }
        }
        best.map(|(j, _)| j)
    }
}

/// The tracking metrics of every coupling DOF of a substructure test, fed sub-step by
/// sub-step (command `d^{(j)}` against the measured displacement).
#[derive(Debug, Clone)]
pub struct TrackingMetrics {
    substep_length: f64,
    delay: Vec<DelayAccumulator>,
    error: Vec<ErrorAccumulator>,
}

/// Tracking metrics of one coupling DOF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tracking {
    /// Cross-correlation delay of the measured displacement behind the command \[s\] (`None`
    /// when undefined, e.g. no motion).
    pub delay: Option<f64>,
    /// Upper end of the lag range searched \[s\]: a delay equal to it means "at least".
    pub max_delay: f64,
    /// `std(x_m − d) / std(d)`.
    pub nrms: f64,
    /// `max|x_m − d| / max|d|`.
    pub peak: f64,
}

impl TrackingMetrics {
    /// Longest delay searched, whatever the sub-step length \[s\].
    pub const MAX_DELAY: f64 = 0.1;
    /// Cap on the lags kept per coupling DOF (bounds memory and the cost per sub-step).
    pub const MAX_LAGS: usize = 1000;

    /// For `n_coupling` DOFs and sub-step length `substep_length` \[s\] (> 0).
    pub fn new(n_coupling: usize, substep_length: f64) -> Self {
        let lags = if substep_length > 0.0 {
            ((Self::MAX_DELAY / substep_length).ceil() as usize).clamp(1, Self::MAX_LAGS)
        } else {
            1
        };
        Self {
            substep_length,
            delay: vec![DelayAccumulator::new(lags); n_coupling],
            error: vec![ErrorAccumulator::new(); n_coupling],
        }
    }

    pub fn push(&mut self, command: &[f64], measured: &[f64]) {
        for (k, (&d, &x)) in command.iter().zip(measured).enumerate() {
            self.delay[k].push(d, x);
            self.error[k].push(x, d);
        }
    }

    pub fn result(&self, k: usize) -> Tracking {
        let delay = &self.delay[k];
        Tracking {
            delay: delay.best_lag().map(|j| j as f64 * self.substep_length),
            max_delay: delay.max_lag() as f64 * self.substep_length,
            nrms: self.error[k].nrms(),
            peak: self.error[k].peak(),
        }
    }

    pub fn n_coupling(&self) -> usize {
        self.error.len()
    }
}

impl SubstepObserver for TrackingMetrics {
    fn substep(&mut self, _step: usize, _j: usize, command: &[f64], _force: &[f64], displacement: &[f64]) {
        self.push(command, displacement);
    }
}
