//! `[substructure.sensors]` (docs/config.md, section `[substructure.sensors]`): load cells and
//! displacement sensors, noise, filters, converters.

use super::common::forbid;
use crate::error::{Error, Result, require_non_negative, require_positive};
use crate::transfer::converter::Converter;
use crate::transfer::noise::BENCHMARK_SEED;
use crate::transfer::{NoiseGenerator, SensorSpec, channel_seed_for};
use serde::Deserialize;

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSensors {
    #[serde(default)]
    pub(crate) force_noise: f64,
    #[serde(default)]
    pub(crate) displacement_noise: f64,
    pub(crate) adc_bits: Option<u32>,
    pub(crate) force_range: Option<f64>,
    pub(crate) displacement_range: Option<f64>,
    /// A/D step instead of `adc_bits` [N], [m].
    pub(crate) force_quantum: Option<f64>,
    pub(crate) displacement_quantum: Option<f64>,
    pub(crate) lowpass_hz: Option<f64>,
    /// Band-limited white-noise power [N² s], [m² s] at `noise_sample_time` [s]: σ² = P / T_s.
    pub(crate) force_noise_power: Option<f64>,
    pub(crate) displacement_noise_power: Option<f64>,
    pub(crate) noise_sample_time: Option<f64>,
    /// The same noise sequence on every channel.
    #[serde(default)]
    pub(crate) shared_noise: bool,
    /// `"chacha"` (default) or `"benchmark"`.
    pub(crate) generator: Option<String>,
    /// D/A converter on the actuator commands [m].
    pub(crate) command_range: Option<f64>,
    pub(crate) command_quantum: Option<f64>,
    pub(crate) command_bits: Option<u32>,
    pub(crate) seed: Option<u64>,
}

impl RawSensors {
    /// The base force and displacement sensor (seed = the configured seed), from which
    /// [`crate::transfer::channel_sensors`] derives one per coupling DOF exactly as
    /// [`RawSensors::specs`] does.
    pub(crate) fn base_specs(&self) -> Result<(SensorSpec, SensorSpec)> {
        let (f, d) = self.specs(1)?;
        Ok((
            SensorSpec {
                seed: self.seed(),
                ..f[0]
            },
            SensorSpec {
                seed: self.seed(),
                ..d[0]
            },
        ))
    }

    pub(crate) fn generator(&self) -> Result<NoiseGenerator> {
        match self.generator.as_deref().unwrap_or("chacha") {
            "chacha" => Ok(NoiseGenerator::ChaCha),
            "benchmark" => Ok(NoiseGenerator::Benchmark),
            other => Err(Error::invalid(
                "substructure.sensors.generator",
                format!("unknown generator '{other}' (expected chacha or benchmark)"),
            )),
        }
    }

    /// Whether the channels share one noise sequence.
    pub(crate) fn shared_noise(&self) -> bool {
        self.shared_noise
    }

    /// The configured seed; by default 1, or the benchmark's start state for its generator.
    pub(crate) fn seed(&self) -> u64 {
        match (self.seed, self.generator.as_deref()) {
            (Some(s), _) => s,
            (None, Some("benchmark")) => u64::from(BENCHMARK_SEED),
            (None, _) => 1,
        }
    }

    /// The D/A converter on the commands, if configured.
    pub(crate) fn command_converter(&self) -> Result<Option<Converter>> {
        let p = "substructure.sensors.";
        let Some(r) = self.command_range else {
            forbid(
                p,
                &[
                    ("command_quantum", self.command_quantum.is_some()),
                    ("command_bits", self.command_bits.is_some()),
                ],
                "needs command_range (the D/A converter's range)",
            )?;
            return Ok(None);
        };
        require_positive(&format!("{p}command_range"), r)?;
        let q = match (self.command_quantum, self.command_bits) {
            (Some(_), Some(_)) => {
                return Err(Error::invalid(
                    format!("{p}command_bits"),
                    "give either command_quantum or command_bits, not both",
                ));
            }
            (Some(q), None) => require_positive(&format!("{p}command_quantum"), q)?,
            (None, Some(bits)) if (2..=32).contains(&bits) => 2.0 * r / (2f64).powi(bits as i32),
            (None, Some(bits)) => {
                return Err(Error::invalid(
                    format!("{p}command_bits"),
                    format!("must be in 2..=32, got {bits}"),
                ));
            }
            (None, None) => {
                return Err(Error::invalid(
                    format!("{p}command_range"),
                    "needs command_quantum or command_bits (the D/A converter's step)",
                ));
            }
        };
        Ok(Some(Converter::new(r, q)?))
    }

    /// `(force sensors, displacement sensors)`, one per coupling DOF.
    pub(crate) fn specs(&self, n_c: usize) -> Result<(Vec<SensorSpec>, Vec<SensorSpec>)> {
        let p = "substructure.sensors.";
        require_non_negative(&format!("{p}force_noise"), self.force_noise)?;
        require_non_negative(&format!("{p}displacement_noise"), self.displacement_noise)?;
        let generator = self.generator()?;
        // σ from a band-limited white-noise power: σ² = P / T_s.
        let sigma = |sigma: f64, key: &str, power: Option<f64>| -> Result<f64> {
            let Some(pw) = power else { return Ok(sigma) };
            if sigma != 0.0 {
                return Err(Error::invalid(
                    format!("{p}{key}_power"),
                    format!("give either {key} (σ) or {key}_power, not both"),
                ));
            }
            require_non_negative(&format!("{p}{key}_power"), pw)?;
            let ts = self.noise_sample_time.ok_or_else(|| {
                Error::invalid(
                    format!("{p}{key}_power"),
                    "needs noise_sample_time (the sample time of the band-limited white noise, σ² = P / T_s)",
                )
            })?;
            require_positive(&format!("{p}noise_sample_time"), ts)?;
            Ok((pw / ts).sqrt())
        };
        let force_sigma = sigma(self.force_noise, "force_noise", self.force_noise_power)?;
        let disp_sigma = sigma(
            self.displacement_noise,
            "displacement_noise",
            self.displacement_noise_power,
        )?;
        if self.noise_sample_time.is_some()
            && self.force_noise_power.is_none()
            && self.displacement_noise_power.is_none()
        {
            return Err(Error::invalid(
                format!("{p}noise_sample_time"),
                "only used with force_noise_power or displacement_noise_power",
            ));
        }
        if let Some(s) = self.seed
            && generator == NoiseGenerator::Benchmark
            && !(1..=2_147_483_646).contains(&s)
        {
            return Err(Error::invalid(
                format!("{p}seed"),
                format!("the benchmark generator needs a seed in 1..=2147483646, got {s}"),
            ));
        }
        let seed = self.seed();
        // Per-channel seeds, kept in the benchmark generator's range for that generator.
        let channel = |ch: u64| -> u64 {
            if self.shared_noise {
                return seed;
            }
            channel_seed_for(generator, seed, ch)
        };
        for (key, q, range) in [
            ("force_quantum", self.force_quantum, self.force_range),
            (
                "displacement_quantum",
                self.displacement_quantum,
                self.displacement_range,
            ),
        ] {
            if let Some(q) = q {
                require_positive(&format!("{p}{key}"), q)?;
                if self.adc_bits.is_some() {
                    return Err(Error::invalid(
                        format!("{p}{key}"),
                        "give either adc_bits or a quantum, not both",
                    ));
                }
                if range.is_none() {
                    return Err(Error::invalid(
                        format!("{p}{key}"),
                        format!("needs {} (the converter's range)", key.replace("quantum", "range")),
                    ));
                }
            }
        }
        let any_quantum = self.force_quantum.is_some() || self.displacement_quantum.is_some();
        if let Some(f) = self.lowpass_hz {
            require_positive(&format!("{p}lowpass_hz"), f)?;
        }
        match self.adc_bits {
            Some(bits) => {
                if !(2..=32).contains(&bits) {
                    return Err(Error::invalid(
                        format!("{p}adc_bits"),
                        format!("must be in 2..=32, got {bits}"),
                    ));
                }
                if self.force_range.is_none() && self.displacement_range.is_none() {
                    return Err(Error::invalid(
                        format!("{p}adc_bits"),
                        "needs force_range and/or displacement_range (the converter's range)",
                    ));
                }
            }
            None if any_quantum => {}
            None => forbid(
                p,
                &[
                    ("force_range", self.force_range.is_some()),
                    ("displacement_range", self.displacement_range.is_some()),
                ],
                "only used with adc_bits, force_quantum or displacement_quantum",
            )?,
        }
        let sensor = |noise: f64, range: Option<f64>, quantum: Option<f64>, key: &str, ch: u64| -> Result<SensorSpec> {
            if let Some(r) = range {
                require_positive(&format!("{p}{key}"), r)?;
                if self.adc_bits.is_none() && quantum.is_none() {
                    return Err(Error::invalid(
                        format!("{p}{key}"),
                        format!(
                            "needs adc_bits or {} (the converter's step)",
                            key.replace("range", "quantum")
                        ),
                    ));
                }
            }
            Ok(SensorSpec {
                noise_std: noise,
                lowpass_hz: self.lowpass_hz,
                adc_bits: range.and(self.adc_bits),
                adc_range: range.unwrap_or(0.0),
                adc_quantum: range.and(quantum),
                generator,
                seed: channel(ch),
            })
        };
        let mut force = Vec::with_capacity(n_c);
        let mut disp = Vec::with_capacity(n_c);
        for i in 0..n_c as u64 {
            force.push(sensor(
                force_sigma,
                self.force_range,
                self.force_quantum,
                "force_range",
                2 * i,
            )?);
            disp.push(sensor(
                disp_sigma,
                self.displacement_range,
                self.displacement_quantum,
                "displacement_range",
                2 * i + 1,
            )?);
        }
        Ok((force, disp))
    }
}
