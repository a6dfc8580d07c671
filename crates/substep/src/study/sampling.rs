//! Seeded random parameters of a Monte-Carlo study (docs/theory.md §14.2).
//!
//! One seed per study; sample `i` draws its parameters, in the order they are declared, from
//! a ChaCha8 generator seeded with the study seed on stream `i`. A run's parameters therefore
//! depend only on (seed, i): the same whether the study runs serially, on threads or in
//! batches on a cluster, and a longer study extends a shorter one with the same seed.

use crate::error::{Error, Result};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution as _, Normal, Uniform};

/// A parameter distribution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Distribution {
    /// Uniform on `[low, high)`.
    Uniform { low: f64, high: f64 },
    /// Normal with the given mean and standard deviation.
    Normal { mean: f64, std: f64 },
    /// `exp(U(ln low, ln high))`: uniform in the logarithm (`0 < low < high`).
    LogUniform { low: f64, high: f64 },
}

/// A sampled parameter: its distribution and whether the sample multiplies the base value
/// (`relative`, e.g. a stiffness ±10 % as `uniform(0.9, 1.1)`) or replaces it.
#[derive(Debug, Clone, PartialEq)]
pub struct Sampled {
    pub key: String,
    pub distribution: Distribution,
    pub relative: bool,
}

impl Distribution {
    /// Checks the parameters; `what` names the parameter in errors.
    pub fn validate(&self, what: &str) -> Result<()> {
        let ok = match *self {
            Self::Uniform { low, high } => low.is_finite() && high.is_finite() && low < high,
            Self::Normal { mean, std } => mean.is_finite() && std.is_finite() && std >= 0.0,
            Self::LogUniform { low, high } => low.is_finite() && high.is_finite() && 0.0 < low && low < high,
        };
        if ok {
            Ok(())
        } else {
            Err(Error::invalid(
                what,
                match self {
                    Self::Uniform { .. } => "uniform needs finite low < high",
                    Self::Normal { .. } => "normal needs a finite mean and std >= 0",
                    Self::LogUniform { .. } => "log_uniform needs 0 < low < high",
                },
            ))
        }
    }

    fn draw(&self, rng: &mut ChaCha8Rng) -> f64 {
        match *self {
            // `validate` has run: the constructors cannot fail here.
            Self::Uniform { low, high } => Uniform::new(low, high).map_or(low, |u| u.sample(rng)),
            Self::Normal { mean, std } => Normal::new(mean, std).map_or(mean, |n| n.sample(rng)),
            Self::LogUniform { low, high } => Uniform::new(low.ln(), high.ln()).map_or(low, |u| u.sample(rng).exp()),
        }
    }
}

/// The parameters of sample `index` of a study seeded with `seed`, one per entry of `params`.
pub fn sample(seed: u64, index: usize, params: &[Sampled]) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(index as u64);
    params.iter().map(|p| p.distribution.draw(&mut rng)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(d: Distribution) -> Sampled {
        Sampled {
            key: "k".into(),
            distribution: d,
            relative: false,
        }
    }

    #[test]
    fn samples_depend_only_on_seed_and_index() {
        let params = [
            p(Distribution::Uniform {
                low: 0.005,
                high: 0.015,
            }),
            p(Distribution::Normal { mean: 1.0, std: 0.1 }),
        ];
        let a = sample(7, 3, &params);
        assert_eq!(a, sample(7, 3, &params));
        assert_ne!(a, sample(7, 4, &params));
        assert_ne!(a, sample(8, 3, &params));
        assert!((0.005..0.015).contains(&a[0]));
    }

    /// Moments of 20 000 draws against the distributions' closed forms (5 standard errors).
    #[test]
    fn moments_match_the_distributions() {
        let n = 20_000;
        let moments = |d: Distribution| {
            let x: Vec<f64> = (0..n).map(|i| sample(11, i, &[p(d)])[0]).collect();
            let m = x.iter().sum::<f64>() / n as f64;
            let v = x.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1) as f64;
            (m, v, x)
        };
        let (m, v, x) = moments(Distribution::Uniform { low: 2.0, high: 4.0 });
        let var = 4.0 / 12.0;
        assert!((m - 3.0).abs() < 5.0 * (var / n as f64).sqrt(), "{m}");
        assert!((v - var).abs() < 0.02 * var * 5.0, "{v}");
        assert!(x.iter().all(|x| (2.0..4.0).contains(x)));
        let (m, v, _) = moments(Distribution::Normal { mean: -1.0, std: 0.5 });
        assert!((m + 1.0).abs() < 5.0 * 0.5 / (n as f64).sqrt(), "{m}");
        assert!((v - 0.25).abs() < 5.0 * 0.25 * (2.0 / n as f64).sqrt(), "{v}");
        // log-uniform on [1, e^2]: ln x ~ U(0, 2), so E[x] = (e^2 − 1) / 2.
        let (m, _, x) = moments(Distribution::LogUniform {
            low: 1.0,
            high: 2f64.exp(),
        });
        let mean = (2f64.exp() - 1.0) / 2.0;
        let var = ((4f64.exp() - 1.0) / 4.0) - mean * mean;
        assert!((m - mean).abs() < 5.0 * (var / n as f64).sqrt(), "{m}");
        let logs_mean = x.iter().map(|x| x.ln()).sum::<f64>() / n as f64;
        assert!((logs_mean - 1.0).abs() < 5.0 * (4.0 / 12.0 / n as f64).sqrt());
    }

    #[test]
    fn bad_parameters_are_named() {
        let e = Distribution::Uniform { low: 1.0, high: 1.0 }
            .validate("samples.x")
            .unwrap_err();
        assert_eq!(e.to_string(), "samples.x: uniform needs finite low < high");
        assert!(Distribution::LogUniform { low: 0.0, high: 1.0 }.validate("x").is_err());
        assert!(Distribution::Normal { mean: 0.0, std: -1.0 }.validate("x").is_err());
    }
}
