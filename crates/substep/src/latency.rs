//! Allocation-free latency histogram with fixed-width bins.

use std::fmt;
use std::time::Duration;

/// Counts of latencies in bins of fixed width `[i·w, (i+1)·w)`, one bin for everything beyond
/// the range, and the exact maximum. Recording does not allocate (the bins are created and
/// touched up front).
#[derive(Debug, Clone, PartialEq)]
pub struct LatencyHistogram {
    bin_ns: u64,
    counts: Vec<u64>,
    above: u64,
    count: u64,
    max_ns: u64,
    sum_ns: u128,
}

impl LatencyHistogram {
    /// `bins` bins of width `bin` (at least 1 ns and 1 bin).
    pub fn new(bin: Duration, bins: usize) -> Self {
        let mut counts = vec![0u64; bins.max(1)];
        // Touch every page now (volatile: the zero-filled allocation would let plain stores of
        // zero be optimised away), so that recording causes no page faults.
        for c in counts.iter_mut().step_by(512) {
            // SAFETY: `c` is a valid, exclusive reference.
            unsafe { std::ptr::write_volatile(c, 0) };
        }
        Self {
            bin_ns: (bin.as_nanos() as u64).max(1),
            counts,
            above: 0,
            count: 0,
            max_ns: 0,
            sum_ns: 0,
        }
    }

    pub fn record(&mut self, latency: Duration) {
        self.record_ns(latency.as_nanos().min(u64::MAX as u128) as u64);
    }

    pub fn record_ns(&mut self, ns: u64) {
        match self.counts.get_mut((ns / self.bin_ns) as usize) {
            Some(c) => *c += 1,
            None => self.above += 1,
        }
        self.count += 1;
        self.max_ns = self.max_ns.max(ns);
        self.sum_ns += ns as u128;
    }

    pub fn count(&self) -> u64 {
        self.count
    }
    pub fn bin_width(&self) -> Duration {
        Duration::from_nanos(self.bin_ns)
    }
    /// Upper end of the binned range; larger values only count in [`LatencyHistogram::above_range`].
    pub fn range(&self) -> Duration {
        Duration::from_nanos(self.bin_ns * self.counts.len() as u64)
    }
    pub fn above_range(&self) -> u64 {
        self.above
    }
    pub fn max(&self) -> Duration {
        Duration::from_nanos(self.max_ns)
    }
    pub fn mean(&self) -> Duration {
        if self.count == 0 {
            Duration::ZERO
        } else {
            Duration::from_nanos((self.sum_ns / self.count as u128) as u64)
        }
    }

    /// An upper bound of the `q`-quantile (`0 < q ≤ 1`): the upper edge of the bin that holds it,
    /// but not more than the maximum. Zero for an empty histogram.
    pub fn percentile(&self, q: f64) -> Duration {
        if self.count == 0 {
            return Duration::ZERO;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (i, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return Duration::from_nanos(((i as u64 + 1) * self.bin_ns).min(self.max_ns));
            }
        }
        self.max()
    }

    /// Non-empty bins as `(from, to, count)`; the out-of-range bin, if any, last as
    /// `(range, max, count)`.
    pub fn bins(&self) -> impl Iterator<Item = (Duration, Duration, u64)> + '_ {
        let w = self.bin_ns;
        self.counts
            .iter()
            .enumerate()
            .filter(|(_, c)| **c > 0)
            .map(move |(i, &c)| {
                (
                    Duration::from_nanos(i as u64 * w),
                    Duration::from_nanos((i as u64 + 1) * w),
                    c,
                )
            })
            .chain((self.above > 0).then(|| (self.range(), self.max(), self.above)))
    }

    /// The histogram re-binned to `width` (a multiple of the bin width; rounded up to one),
    /// non-empty bins only, for printing.
    pub fn coarse(&self, width: Duration) -> Vec<(Duration, Duration, u64)> {
        let factor = ((width.as_nanos() as u64) / self.bin_ns).max(1);
        let mut out: Vec<(Duration, Duration, u64)> = Vec::new();
        for (from, _, c) in self.bins() {
            if from >= self.range() {
                out.push((self.range(), self.max(), c));
                continue;
            }
            let i = from.as_nanos() as u64 / self.bin_ns / factor;
            let lo = Duration::from_nanos(i * factor * self.bin_ns);
            match out.last_mut() {
                Some(last) if last.0 == lo => last.2 += c,
                _ => out.push((lo, Duration::from_nanos((i + 1) * factor * self.bin_ns), c)),
            }
        }
        out
    }
}

/// `p50 / p99 / max` of a histogram (percentiles are bin upper edges, see
/// [`LatencyHistogram::percentile`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LatencySummary {
    pub p50: Duration,
    pub p99: Duration,
    pub max: Duration,
    pub mean: Duration,
    pub count: u64,
}

impl From<&LatencyHistogram> for LatencySummary {
    fn from(h: &LatencyHistogram) -> Self {
        Self {
            p50: h.percentile(0.5),
            p99: h.percentile(0.99),
            max: h.max(),
            mean: h.mean(),
            count: h.count(),
        }
    }
}

impl fmt::Display for LatencySummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let us = |d: Duration| d.as_secs_f64() * 1e6;
        write!(
            f,
            "p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs, mean {:.1} µs (n = {})",
            us(self.p50),
            us(self.p99),
            us(self.max),
            us(self.mean),
            self.count
        )
    }
}
