//! The on-line J-style metrics (`analysis::tracking`) against a direct two-pass implementation
//! and against signals with a known delay.

use substep::analysis::tracking::{DelayAccumulator, ErrorAccumulator, TrackingMetrics};

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

fn std(x: &[f64]) -> f64 {
    let m = mean(x);
    (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (x.len() - 1) as f64).sqrt()
}

fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let (ma, mb) = (mean(a), mean(b));
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}

/// A deterministic, irregular test signal with an offset (so cancellation would show).
fn signal(n: usize, offset: f64) -> Vec<f64> {
    let mut s = 12345u64;
    (0..n)
        .map(|k| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let noise = ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.1;
            let t = k as f64 * 1e-3;
            offset
                + (2.0 * std::f64::consts::PI * 1.3 * t).sin()
                + 0.4 * (2.0 * std::f64::consts::PI * 4.1 * t).cos()
                + noise
        })
        .collect()
}

#[test]
fn error_accumulator_equals_two_pass_ratios() {
    let r = signal(5000, 0.7);
    let x: Vec<f64> = r
        .iter()
        .enumerate()
        .map(|(k, v)| 1.05 * v + 0.01 * (k as f64 * 0.37).sin())
        .collect();
    let mut acc = ErrorAccumulator::new();
    for (&xi, &ri) in x.iter().zip(&r) {
        acc.push(xi, ri);
    }
    let e: Vec<f64> = x.iter().zip(&r).map(|(a, b)| a - b).collect();
    let nrms = std(&e) / std(&r);
    let peak = e.iter().fold(0.0f64, |m, v| m.max(v.abs())) / r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!((acc.nrms() - nrms).abs() < 1e-12 * nrms, "{} vs {}", acc.nrms(), nrms);
    assert_eq!(acc.peak(), peak);
    assert!(nrms > 0.03 && nrms < 0.2, "the test signal has a real error: {nrms}");
}

#[test]
fn error_accumulator_is_nan_for_a_constant_reference() {
    let mut acc = ErrorAccumulator::new();
    for _ in 0..10 {
        acc.push(1.0, 0.0);
    }
    assert!(acc.nrms().is_nan());
    assert!(acc.peak().is_nan());
}

#[test]
fn correlation_per_lag_equals_direct_pearson() {
    let d = signal(3000, 2.5);
    // Measured: the desired signal 7 samples late, scaled, with a different offset.
    let lag = 7;
    let x: Vec<f64> = (0..d.len())
        .map(|k| if k >= lag { 0.9 * d[k - lag] - 0.3 } else { -0.3 })
        .collect();
    let mut acc = DelayAccumulator::new(20);
    for (&di, &xi) in d.iter().zip(&x) {
        acc.push(di, xi);
    }
    let n = d.len();
    for j in 0..=20 {
        let direct = pearson(&x[j..n], &d[..n - j]);
        let online = acc.correlation(j);
        assert!((online - direct).abs() < 1e-9, "lag {j}: {online} vs {direct}");
    }
    assert_eq!(acc.best_lag(), Some(lag));
}

#[test]
fn delay_of_a_delayed_sine_is_found_and_the_first_maximum_wins() {
    // A pure delay of 12.5 ms sampled at 1 ms lies between lags 12 and 13; a 10 ms delay is
    // exactly lag 10.
    let h = 1e-3;
    let n = 4000;
    let d: Vec<f64> = (0..n)
        .map(|k| (2.0 * std::f64::consts::PI * 2.0 * k as f64 * h).sin())
        .collect();
    let delayed = |tau: f64| -> Vec<f64> {
        (0..n)
            .map(|k| {
                let t = k as f64 * h - tau;
                if t < 0.0 {
                    0.0
                } else {
                    (2.0 * std::f64::consts::PI * 2.0 * t).sin()
                }
            })
            .collect()
    };
    let mut m = TrackingMetrics::new(2, h);
    let x10 = delayed(0.010);
    let x125 = delayed(0.0125);
    for k in 0..n {
        m.push(&[d[k], d[k]], &[x10[k], x125[k]]);
    }
    let r10 = m.result(0);
    assert!((r10.delay.unwrap() - 0.010).abs() < 1e-12, "{:?}", r10.delay);
    let r125 = m.result(1).delay.unwrap();
    assert!((r125 - 0.012).abs() < 1e-12 || (r125 - 0.013).abs() < 1e-12, "{r125}");
    // Tracking error of a 10 ms delay at 2 Hz: |1 − e^{−iωτ}| = 2 sin(ωτ/2) of the amplitude.
    let expected = 2.0 * (std::f64::consts::PI * 2.0 * 0.010).sin();
    assert!((r10.nrms - expected).abs() < 0.01, "{} vs {expected}", r10.nrms);
    assert!((r10.max_delay - 0.1).abs() < 1e-12);

    // Identical signals: lag 0 is the first maximum.
    let mut same = DelayAccumulator::new(5);
    for &v in &d {
        same.push(v, v);
    }
    assert_eq!(same.best_lag(), Some(0));
}

#[test]
fn delay_is_undefined_without_motion() {
    let mut m = TrackingMetrics::new(1, 1e-3);
    for _ in 0..100 {
        m.push(&[0.0], &[0.0]);
    }
    let r = m.result(0);
    assert_eq!(r.delay, None);
    assert!(r.nrms.is_nan());
}
