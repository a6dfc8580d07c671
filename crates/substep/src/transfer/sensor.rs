//! Sensors: additive Gaussian noise (seeded), optional first-order low-pass filter, optional
//! A/D quantisation over a symmetric range — applied in that order, like an analog sensor
//! followed by an anti-alias filter and a converter.

use crate::error::{Error, Result, require_non_negative, require_positive};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorSpec {
    /// Standard deviation of the additive noise, in the measured unit (N or m).
    pub noise_std: f64,
    /// Cut-off frequency of a first-order low-pass filter \[Hz\].
    pub lowpass_hz: Option<f64>,
    /// A/D converter: number of bits over `[-range, range]`.
    pub adc_bits: Option<u32>,
    pub adc_range: f64,
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
        }
        Ok(())
    }
    pub fn build(&self, what: &str) -> Result<Sensor> {
        self.validate(what)?;
        Ok(Sensor {
            spec: *self,
            rng: ChaCha8Rng::seed_from_u64(self.seed),
            filtered: None,
        })
    }
}

#[derive(Debug, Clone)]
pub struct Sensor {
    spec: SensorSpec,
    rng: ChaCha8Rng,
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
            let z: f64 = StandardNormal.sample(&mut self.rng);
            x += self.spec.noise_std * z;
        }
        if let Some(fc) = self.spec.lowpass_hz {
            // Exact discretisation of τ ẏ + y = x with x held over the interval.
            let alpha = 1.0 - (-2.0 * std::f64::consts::PI * fc * dt).exp();
            let y = self.filtered.unwrap_or(0.0);
            x = y + alpha * (x - y);
            self.filtered = Some(x);
        }
        if let Some(bits) = self.spec.adc_bits {
            let r = self.spec.adc_range;
            let q = 2.0 * r / (2f64).powi(bits as i32);
            x = ((x.clamp(-r, r) / q).round() * q).clamp(-r, r);
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
        self.spec.noise_std == 0.0 && self.spec.adc_bits.is_none()
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

/// One force and one displacement sensor per coupling DOF from base specs, each with its own
/// seed derived from the base spec's seed by [`channel_seed`].
pub fn channel_sensors(
    force: &SensorSpec,
    displacement: &SensorSpec,
    n_c: usize,
) -> (Vec<SensorSpec>, Vec<SensorSpec>) {
    let with = |s: &SensorSpec, ch: u64| SensorSpec {
        seed: channel_seed(s.seed, ch),
        ..*s
    };
    (
        (0..n_c as u64).map(|i| with(force, 2 * i)).collect(),
        (0..n_c as u64).map(|i| with(displacement, 2 * i + 1)).collect(),
    )
}
