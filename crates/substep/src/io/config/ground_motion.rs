//! `[ground_motion]` (docs/config.md, section `[ground_motion]`): records, generators, scaling,
//! the ground acceleration at the step times.

use super::common::{check_samples, forbid, prefixed};
use crate::error::{Error, Result};
use crate::excitation::{self, Envelope, KanaiTajimi, Record};
use crate::limits::Limits;
use serde::Deserialize;
use std::path::Path;

/// Ground acceleration at the step times.
#[derive(Debug, Clone)]
pub struct GroundMotion {
    /// `a_g(t_i)`, `t_i = i·dt`, `i = 0..=steps` [m/s²].
    pub accel: Vec<f64>,
    /// Short human description (source, scale).
    pub description: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawGroundMotion {
    pub(crate) file: Option<String>,
    pub(crate) dt: Option<f64>,
    pub(crate) scale: Option<f64>,
    pub(crate) units: Option<String>,
    pub(crate) generator: Option<String>,
    pub(crate) amplitude: Option<f64>,
    pub(crate) frequency: Option<f64>,
    pub(crate) f0: Option<f64>,
    pub(crate) f1: Option<f64>,
    pub(crate) duration: Option<f64>,
    pub(crate) seed: Option<u64>,
    pub(crate) pga: Option<f64>,
    pub(crate) omega_g: Option<f64>,
    pub(crate) zeta_g: Option<f64>,
    pub(crate) rise: Option<f64>,
    pub(crate) hold: Option<f64>,
}

impl RawGroundMotion {
    pub(crate) fn build(&self, dt: f64, duration: Option<f64>, base: &Path, limits: &Limits) -> Result<GroundMotion> {
        let g = "ground_motion.";
        let scale = self.scale.unwrap_or(1.0);
        if !scale.is_finite() {
            return Err(Error::invalid(
                "ground_motion.scale",
                format!("must be finite, got {scale}"),
            ));
        }
        // Units of the file's (or generator's) values; `.AT2` records are in g by definition and
        // converted by their reader.
        let is_at2 = self
            .file
            .as_deref()
            .is_some_and(|f| Path::new(f).extension().is_some_and(|e| e.eq_ignore_ascii_case("at2")));
        let units = match (self.units.as_deref(), is_at2) {
            (None | Some("m/s2"), false) => 1.0,
            (Some("g"), false) => excitation::G,
            (Some("cm/s2"), false) => 0.01,
            (None | Some("g"), true) => 1.0,
            (Some(u @ ("m/s2" | "cm/s2")), true) => {
                return Err(Error::invalid(
                    "ground_motion.units",
                    format!("a PEER .AT2 record is in g (converted on reading), not {u}"),
                ));
            }
            (Some(other), _) => {
                return Err(Error::invalid(
                    "ground_motion.units",
                    format!("unknown units '{other}' (expected \"m/s2\", \"g\" or \"cm/s2\")"),
                ));
            }
        };
        let generator_keys = [
            ("amplitude", self.amplitude.is_some()),
            ("frequency", self.frequency.is_some()),
            ("f0", self.f0.is_some()),
            ("f1", self.f1.is_some()),
            ("duration", self.duration.is_some()),
            ("seed", self.seed.is_some()),
            ("pga", self.pga.is_some()),
            ("omega_g", self.omega_g.is_some()),
            ("zeta_g", self.zeta_g.is_some()),
            ("rise", self.rise.is_some()),
            ("hold", self.hold.is_some()),
        ];
        let (record, description) = match (&self.file, &self.generator) {
            (Some(_), Some(_)) => {
                return Err(Error::invalid(
                    "ground_motion",
                    "give either file or generator, not both",
                ));
            }
            (None, None) => {
                return Err(Error::invalid(
                    "ground_motion",
                    "give a record file (file = \"ag.csv\") or a generator (generator = \"sine_sweep\")",
                ));
            }
            (Some(file), None) => {
                forbid(g, &generator_keys, "only used with generator = ...")?;
                let path = base.join(file);
                let record = excitation::read_record_with(&path, self.dt, limits)
                    .map_err(|e| Error::invalid("ground_motion.file", e.to_string()))?;
                (record, format!("record {}", path.display()))
            }
            (None, Some(kind)) => {
                if self.dt.is_some() {
                    return Err(Error::invalid(
                        "ground_motion.dt",
                        "only used with a single-column file (generators sample at integrator.dt)",
                    ));
                }
                let length = match (self.duration, duration) {
                    (Some(d), _) | (None, Some(d)) => d,
                    (None, None) => {
                        return Err(Error::invalid(
                            "ground_motion.duration",
                            "required for a generator (or set integrator.duration)",
                        ));
                    }
                };
                check_samples(limits, length, dt)?;
                self.generate(kind, length, dt, &generator_keys)?
            }
        };
        let description = match self.units.as_deref() {
            Some(u) if !is_at2 && u != "m/s2" => format!("{description}, in {u}"),
            _ => description,
        };
        let description = if scale == 1.0 {
            description
        } else {
            format!("{description}, scaled by {scale}")
        };
        check_samples(limits, duration.unwrap_or(record.duration()), dt)?;
        let accel = record
            .scaled(scale * units)?
            .resample(dt, duration)
            .map_err(|e| prefixed(e, "ground_motion: "))?;
        Ok(GroundMotion { accel, description })
    }

    /// Length of the excitation [s] if it is known without reading a file.
    pub(crate) fn length_hint(&self, duration: Option<f64>) -> Option<f64> {
        match (&self.file, &self.generator) {
            (None, Some(_)) => self.duration.or(duration),
            (Some(_), None) => duration,
            _ => None,
        }
    }

    pub(crate) fn generate(
        &self,
        kind: &str,
        duration: f64,
        dt: f64,
        keys: &[(&str, bool)],
    ) -> Result<(Record, String)> {
        let g = "ground_motion.";
        let allowed: &[&str] = match kind {
            "harmonic" => &["amplitude", "frequency", "duration"],
            "sine_sweep" => &["amplitude", "f0", "f1", "duration"],
            "kanai_tajimi" => &["pga", "omega_g", "zeta_g", "seed", "rise", "hold", "duration"],
            other => {
                return Err(Error::invalid(
                    "ground_motion.generator",
                    format!("unknown generator '{other}' (expected harmonic, sine_sweep or kanai_tajimi)"),
                ));
            }
        };
        let extra: Vec<(&str, bool)> = keys.iter().filter(|(k, _)| !allowed.contains(k)).copied().collect();
        forbid(
            g,
            &extra,
            &format!("not used by generator = \"{kind}\" (it uses {})", allowed.join(", ")),
        )?;
        let need = |key: &str, v: Option<f64>| {
            v.ok_or_else(|| Error::invalid(format!("{g}{key}"), format!("required for generator = \"{kind}\"")))
        };
        let gen_err = |e: Error| match e {
            Error::InvalidInput { what, reason } => {
                let key = what.rsplit('.').next().unwrap_or(&what).to_string();
                let key = match key.as_str() {
                    "frequency_hz" => "frequency".to_string(),
                    "f0_hz" => "f0".to_string(),
                    "f1_hz" => "f1".to_string(),
                    "pga_target" => "pga".to_string(),
                    "envelope" => "rise".to_string(),
                    _ => key,
                };
                Error::invalid(format!("{g}{key}"), reason)
            }
            other => other,
        };
        match kind {
            "harmonic" => {
                let a = need("amplitude", self.amplitude)?;
                let f = need("frequency", self.frequency)?;
                let r = excitation::harmonic(a, f, duration, dt).map_err(gen_err)?;
                Ok((r, format!("harmonic {f} Hz, {a} m/s², {duration} s")))
            }
            "sine_sweep" => {
                let a = need("amplitude", self.amplitude)?;
                let f0 = need("f0", self.f0)?;
                let f1 = need("f1", self.f1)?;
                let r = excitation::sine_sweep(a, f0, f1, duration, dt).map_err(gen_err)?;
                Ok((r, format!("linear sine sweep {f0}–{f1} Hz, {a} m/s², {duration} s")))
            }
            _ => {
                let envelope = match (self.rise, self.hold) {
                    (None, None) => Envelope::None,
                    (Some(rise), Some(hold)) => Envelope::Trapezoid { rise, hold },
                    (Some(_), None) => return Err(Error::invalid("ground_motion.hold", "required with rise")),
                    (None, Some(_)) => return Err(Error::invalid("ground_motion.rise", "required with hold")),
                };
                let params = KanaiTajimi {
                    pga_target: self.pga,
                    omega_g: self.omega_g.unwrap_or(15.6),
                    zeta_g: self.zeta_g.unwrap_or(0.6),
                    duration,
                    dt,
                    seed: self.seed.unwrap_or(1),
                    envelope,
                };
                let r = excitation::kanai_tajimi(params).map_err(gen_err)?;
                let pga = r.pga();
                Ok((
                    r,
                    format!(
                        "Kanai-Tajimi noise (omega_g {} rad/s, zeta_g {}, seed {}), PGA {pga:.3} m/s², {duration} s",
                        params.omega_g, params.zeta_g, params.seed
                    ),
                ))
            }
        }
    }
}
