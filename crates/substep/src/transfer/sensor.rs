//! Sensors: additive Gaussian noise (seeded), optional first-order low-pass filter, optional
//! A/D converter (saturation at `±range`, then quantisation with rounding half away from zero,
//! [`Converter::ad`]) — applied in that order, like an analog sensor followed by an anti-alias
//! filter and a converter.
//!
//! The noise comes from a ChaCha8 generator (the default) or from the RTHS benchmark's
//! Park–Miller/polar generator ([`MinStdPolar`]), which reproduces the benchmark's sequence.
//! Sensors built with the same generator and seed draw bit-identical sequences (shared noise).

use super::converter::Converter;
use super::noise::MinStdPolar;
use crate::error::{Error, Result, require_non_negative, require_positive};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Which generator draws a sensor's standard-normal noise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NoiseGenerator {
    /// ChaCha8 seeded with `seed`, normals by `rand_distr::StandardNormal`.
    #[default]
    ChaCha,
    /// [`MinStdPolar`] started from `seed` (which must be in `1 ..= 2³¹ − 2`).
    Benchmark,
}

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorSpec {
    /// Standard deviation of the additive noise, in the measured unit (N or m).
    pub noise_std: f64,
    /// Cut-off frequency of a first-order low-pass filter \[Hz\].
    pub lowpass_hz: Option<f64>,
    /// A/D converter: number of bits over `[-range, range]`.
    pub adc_bits: Option<u32>,
    pub adc_range: f64,
    /// A/D converter step instead of `adc_bits` (with `adc_range`).
    pub adc_quantum: Option<f64>,
    pub generator: NoiseGenerator,
    pub seed: u64,
}

impl SensorSpec {
    pub fn ideal() -> Self {
        Self::default()
    }
    pub fn validate(&self, what: &str) -> Result<()> {
        require_non_negative(&format!("{what}.noise"), self.noise_std)?;
        if let Some(f) = self.lowpass_hz {
            require_positive(&format!("{what}.lowpass_hz"), f)?;
        }
        if let Some(bits) = self.adc_bits {
            if !(2..=32).contains(&bits) {
                return Err(Error::invalid(
                    format!("{what}.adc_bits"),
                    format!("must be in 2..=32, got {bits}"),
                ));
            }
            require_positive(&format!("{what}.adc_range"), self.adc_range)?;
            if self.adc_quantum.is_some() {
                return Err(Error::invalid(
                    format!("{what}.adc_quantum"),
                    "give either adc_bits or a quantum, not both",
                ));
            }
        }
        if let Some(q) = self.adc_quantum {
            require_positive(&format!("{what}.adc_quantum"), q)?;
            require_positive(&format!("{what}.adc_range"), self.adc_range)?;
        }
        Ok(())
    }

    /// The A/D converter, if any.
    pub fn converter(&self) -> Option<Converter> {
        let q = match (self.adc_bits, self.adc_quantum) {
            (Some(bits), _) => 2.0 * self.adc_range / (2f64).powi(bits as i32),
            (None, Some(q)) => q,
            (None, None) => return None,
        };
        Converter::new(self.adc_range, q).ok()
    }

    pub fn build(&self, what: &str) -> Result<Sensor> {
        self.validate(what)?;
        let rng = match self.generator {
            NoiseGenerator::ChaCha => Rng::ChaCha(Box::new(ChaCha8Rng::seed_from_u64(self.seed))),
            NoiseGenerator::Benchmark => {
                let seed = u32::try_from(self.seed).unwrap_or(0);
                Rng::Benchmark(MinStdPolar::new(seed).map_err(|e| match e {
                    Error::InvalidInput { reason, .. } => Error::invalid(format!("{what}.seed"), reason),
                    other => other,
                })?)
            }
        };
        Ok(Sensor {
            spec: *self,
            rng,
            converter: self.converter(),
            filtered: None,
        })
    }
}

#[derive(Debug, Clone)]
enum Rng {
    ChaCha(Box<ChaCha8Rng>),
    Benchmark(MinStdPolar),
}

impl Rng {
    #[inline]
    fn normal(&mut self) -> f64 {
        match self {
            Rng::ChaCha(r) => StandardNormal.sample(r.as_mut()),
            Rng::Benchmark(g) => g.normal(),
        }
    }
}

#[derive(Debug, Clone)]
pub struct Sensor {
    spec: SensorSpec,
    rng: Rng,
    converter: Option<Converter>,
    filtered: Option<f64>,
}

impl Sensor {
    pub fn spec(&self) -> &SensorSpec {
        &self.spec
    }

    /// Measure `true_value`; `dt` is the time since the previous measurement (for the filter).
    pub fn measure(&mut self, true_value: f64, dt: f64) -> f64 {
        let mut x = true_value;
        if self.spec.noise_std > 0.0 {
            x += self.spec.noise_std * self.rng.normal();
        }
        if let Some(fc) = self.spec.lowpass_hz {
            // Exact discretisation of τ ẏ + y = x with x held over the interval.
            let alpha = 1.0 - (-2.0 * std::f64::consts::PI * fc * dt).exp();
            let y = self.filtered.unwrap_or(0.0);
            x = y + alpha * (x - y);
            self.filtered = Some(x);
        }
        if let Some(c) = &self.converter {
            // With bits, `range/q` is a power of two, so the quantised value never exceeds the range.
            x = c.ad(x);
        }
        x
    }

    /// Filter state (the only state that matters for a noise-free linear analysis).
    pub fn filter_state(&self) -> f64 {
        self.filtered.unwrap_or(0.0)
    }
    pub fn set_filter_state(&mut self, y: f64) {
        if self.spec.lowpass_hz.is_some() {
            self.filtered = Some(y);
        }
    }
    /// Whether the sensor is a linear map (no noise, no quantisation).
    pub fn is_linear(&self) -> bool {
        self.spec.noise_std == 0.0 && self.converter.is_none()
    }
}

/// Seed of sensor channel `channel` derived from a base seed (splitmix64), so that every sensor
/// of a lab gets its own reproducible noise: force sensor of coupling DOF `i` uses channel
/// `2i`, its displacement sensor `2i + 1`.
pub fn channel_seed(seed: u64, channel: u64) -> u64 {
    let mut z = seed
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(channel.wrapping_add(1).wrapping_mul(0xBF58_476D_1CE4_E5B9));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// [`channel_seed`] kept in the generator's seed range (`1 ..= 2³¹ − 2` for the benchmark's).
pub fn channel_seed_for(generator: NoiseGenerator, seed: u64, channel: u64) -> u64 {
    let s = channel_seed(seed, channel);
    match generator {
        NoiseGenerator::ChaCha => s,
        NoiseGenerator::Benchmark => s % 2_147_483_646 + 1,
    }
}

/// One force and one displacement sensor per coupling DOF from base specs, each with its own
/// seed derived from the base spec's seed by [`channel_seed_for`].
pub fn channel_sensors(
    force: &SensorSpec,
    displacement: &SensorSpec,
    n_c: usize,
) -> (Vec<SensorSpec>, Vec<SensorSpec>) {
    let with = |s: &SensorSpec, ch: u64| SensorSpec {
        seed: channel_seed_for(s.generator, s.seed, ch),
        ..*s
    };
    (
        (0..n_c as u64).map(|i| with(force, 2 * i)).collect(),
        (0..n_c as u64).map(|i| with(displacement, 2 * i + 1)).collect(),
    )
}
