//! Statistics of timing samples and the clocks and counters the benchmarks read.

use serde::{Deserialize, Serialize};

/// Quantile `q ∈ [0, 1]` of sorted samples (nearest rank); 0 for no samples.
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let i = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[i]
}

/// Median (mean of the two middle values for an even count); 0 for no samples.
pub fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let m = s.len() / 2;
    match s.len() {
        0 => 0.0,
        n if n % 2 == 1 => s[m],
        _ => 0.5 * (s[m - 1] + s[m]),
    }
}

/// Median, minimum and maximum of a few figures (one per batch or run).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Spread {
    pub median: f64,
    pub min: f64,
    pub max: f64,
    pub count: usize,
}

impl Spread {
    pub fn of(v: &[f64]) -> Self {
        Self {
            median: median(v),
            min: v.iter().copied().fold(f64::INFINITY, f64::min),
            max: v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            count: v.len(),
        }
    }
}

/// CPU time of the calling thread \[s\] (what a step costs on its core, whatever else the
/// machine runs); 0 where the clock is not available.
pub fn thread_cpu_seconds() -> f64 {
    #[cfg(unix)]
    {
        let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: `ts` is a valid timespec to write to.
        if unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) } == 0 {
            return ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9;
        }
    }
    0.0
}

/// Peak resident set size (VmHWM) of this process \[bytes\], 0 where `/proc` is not available.
pub fn peak_rss_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1).and_then(|v| v.parse::<u64>().ok()))
        })
        .map_or(0, |kb| kb * 1024)
}

/// Reset the peak RSS to the current RSS (Linux `clear_refs` 5), so that the next
/// [`peak_rss_bytes`] is the peak of what runs in between. `false` where not supported.
pub fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// Streaming read bandwidth of one core \[GB/s\]: the best of 5 sums over a 256 MiB buffer
/// (eight partial sums, so the adds are not the limit) in the same kind of memory as the
/// sparse factor (2 MiB-aligned, advised to huge pages: with 4 KiB pages the TLB misses make
/// the probe slower than the solve it is meant to bound). The best, not the median: the floor
/// is a lower bound on a solve's time.
pub fn read_bandwidth_gbs() -> f64 {
    let buf = crate::sparse::HugeBuf::from_slice(&vec![1.0f64; 32 << 20]);
    let mut best = 0.0f64;
    for _ in 0..5 {
        let t = std::time::Instant::now();
        let mut acc = [0.0f64; 8];
        for c in buf.chunks_exact(8) {
            for k in 0..8 {
                acc[k] += c[k];
            }
        }
        let e = t.elapsed().as_secs_f64();
        std::hint::black_box(acc);
        best = best.max(buf.len() as f64 * 8.0 / e / 1e9);
    }
    best
}
