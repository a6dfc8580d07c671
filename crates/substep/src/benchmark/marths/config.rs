//! `substep benchmark marths --config FILE.toml`: another plant, another coupler, the ARX
//! compensator's and the sub-step algorithm's settings (docs/benchmark.md, "maRTHS").
//!
//! ```toml
//! [plant]                 # replaces the toolset's 2×2 plant (commands [mm] → strokes [mm])
//! # row i = actuator i's stroke, column j = command j; zeros and poles [rad/s] as [re, im]
//! h = [[{ zeros = [[-754.0, 0.0]], poles = [[-100.0, 0.0], [-300.0, 0.0]], gain = 40.0 }, { … }],
//!      [{ … }, { … }]]
//! # or a state space: a (n×n), b (n×2), c (2×n), d (2×2, default 0)
//!
//! [coupler]               # two horizontal actuators pinned to the coupler
//! attachments = [[0.295394465, -25.4633], [0.295394465, 25.4633]]   # [radius m, angle °] each
//! inverse = "toolset"     # or "exact" (symmetric couplers; others always invert by Newton)
//!
//! [controller.arx]        # the ARX compensator per actuator
//! k_lag = 16
//! span = 8
//! n_u = 5
//! forgetting_factor = 0.999
//! max_lead = 120.0
//!
//! [substep]               # --algorithm substep
//! samples_per_step = 2
//! k_sub = 2
//! p = 1.0                 # error-force compensation
//! ```

use super::run::{Algorithm, ControllerKind, MarthsInput, SubstepSpec, Transfer, arx_default};
use crate::error::{Error, Result};
use crate::substructure::ErrorForceSpec;
use crate::transfer::kinematics::{Attachment, Coupler};
use crate::transfer::lti::TransferFunction;
use crate::transfer::mimo::{MimoStateSpace, TransferMatrix};
use nalgebra::Complex;
use nalgebra::DMatrix;
use serde::Deserialize;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    plant: Option<RawPlant>,
    coupler: Option<RawCoupler>,
    controller: Option<RawController>,
    substep: Option<RawSubstep>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlant {
    h: Option<Vec<Vec<RawChannel>>>,
    a: Option<Vec<Vec<f64>>>,
    b: Option<Vec<Vec<f64>>>,
    c: Option<Vec<Vec<f64>>>,
    d: Option<Vec<Vec<f64>>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawChannel {
    #[serde(default)]
    zeros: Vec<[f64; 2]>,
    poles: Vec<[f64; 2]>,
    gain: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCoupler {
    attachments: Vec<[f64; 2]>,
    inverse: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawController {
    arx: Option<RawArx>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawArx {
    k_lag: Option<usize>,
    span: Option<usize>,
    n_u: Option<usize>,
    forgetting_factor: Option<f64>,
    max_lead: Option<f64>,
    smoothing: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSubstep {
    samples_per_step: Option<usize>,
    k_sub: Option<usize>,
    p: Option<f64>,
}

/// A parsed `--config` file.
#[derive(Debug, Clone, Default)]
pub struct MarthsConfig {
    pub plant: Option<MimoStateSpace>,
    pub coupler: Option<Coupler>,
    pub arx: Option<crate::compensate::ArxPhaseLagSpec>,
    pub substep: Option<SubstepSpec>,
}

fn complex(roots: &[[f64; 2]]) -> Vec<Complex<f64>> {
    roots.iter().map(|r| Complex::new(r[0], r[1])).collect()
}

impl MarthsConfig {
    /// Parse the TOML text; `name` names the file in errors.
    pub fn from_toml(text: &str, name: &str) -> Result<Self> {
        let raw: Raw = toml::from_str(text).map_err(|e| Error::file(name, e.message().to_string()))?;
        let mut c = Self::default();
        if let Some(p) = raw.plant {
            c.plant = Some(plant(p)?);
        }
        if let Some(k) = raw.coupler {
            if k.attachments.len() != 2 {
                return Err(Error::invalid(
                    "coupler.attachments",
                    format!(
                        "needs two [radius m, angle °] pairs (two actuators), got {}",
                        k.attachments.len()
                    ),
                ));
            }
            let a = |i: usize| Attachment {
                radius: k.attachments[i][0],
                angle: k.attachments[i][1].to_radians(),
            };
            let coupler = Coupler::new([a(0), a(1)])?;
            c.coupler = Some(match k.inverse.as_deref() {
                None | Some("toolset") => coupler.clone().toolset_inverse().unwrap_or(coupler),
                Some("exact") => coupler,
                Some(other) => {
                    return Err(Error::invalid(
                        "coupler.inverse",
                        format!("unknown inverse `{other}` (toolset, exact)"),
                    ));
                }
            });
        }
        if let Some(arx) = raw.controller.and_then(|c| c.arx) {
            let mut spec = arx_default();
            // `with_span` resets the lead bound and the smoothing; the preset's bound stays.
            let preset_lead = spec.max_lead;
            if let Some(k) = arx.k_lag {
                spec.k_lag = k;
                spec.lead = k as f64;
            }
            spec = spec.with_span(arx.span.unwrap_or(spec.span));
            spec.max_lead = preset_lead;
            if let Some(n) = arx.n_u {
                spec.n_u = n;
            }
            if let Some(l) = arx.forgetting_factor {
                spec.lambda = l;
            }
            if let Some(l) = arx.max_lead {
                spec.max_lead = Some(l);
            }
            if let Some(t) = arx.smoothing {
                spec.smoothing = t;
            }
            spec.validate().map_err(|e| prefixed(e, "controller.arx."))?;
            c.arx = Some(spec);
        }
        if let Some(s) = raw.substep {
            let d = SubstepSpec::default();
            c.substep = Some(SubstepSpec {
                samples_per_step: s.samples_per_step.unwrap_or(d.samples_per_step),
                k_sub: s.k_sub.unwrap_or(d.k_sub),
                error_force: match s.p {
                    Some(p) => ErrorForceSpec::Pid { p, i: 0.0, d: 0.0 },
                    None => d.error_force,
                },
            });
        }
        Ok(c)
    }

    /// Apply to `input` (the plant keeps the input's noise setting).
    pub fn apply(&self, input: &mut MarthsInput) {
        if let Some(p) = &self.plant
            && let Transfer::Plant { plant, .. } = &mut input.transfer
        {
            *plant = p.clone();
        }
        if let Some(c) = &self.coupler {
            input.coupler = c.clone();
        }
        if let (Some(spec), ControllerKind::Arx(s)) = (&self.arx, &mut input.controller) {
            *s = *spec;
        }
        if let (Some(spec), Algorithm::Substep(s)) = (&self.substep, &mut input.algorithm) {
            *s = spec.clone();
        }
    }
}

/// The plant of `[plant]`: the 2×2 matrix `h` of zeros, poles and gains, or a state space
/// `a` (n×n), `b` (n×2), `c` (2×n), `d` (2×2, default 0).
fn plant(p: RawPlant) -> Result<MimoStateSpace> {
    match (p.h, p.a, p.b, p.c) {
        (Some(h), None, None, None) => {
            let rows = h.len();
            if rows != 2 || h.iter().any(|r| r.len() != 2) {
                return Err(Error::invalid(
                    "plant.h",
                    format!(
                        "must be a 2×2 matrix (two actuators, two commands), got {rows} row(s) of {}",
                        h.iter().map(|r| r.len().to_string()).collect::<Vec<_>>().join(", ")
                    ),
                ));
            }
            let mut entries = Vec::with_capacity(4);
            for (i, row) in h.iter().enumerate() {
                for (j, ch) in row.iter().enumerate() {
                    entries.push(TransferFunction::from_zpk(
                        &format!("plant.h[{}][{}]", i + 1, j + 1),
                        &complex(&ch.zeros),
                        &complex(&ch.poles),
                        ch.gain,
                    )?);
                }
            }
            Ok(TransferMatrix::new("plant.h", 2, 2, entries)?.to_state_space())
        }
        (None, Some(a), Some(b), Some(c)) => {
            let matrix = |name: &str, rows: Vec<Vec<f64>>| -> Result<DMatrix<f64>> {
                let n = rows.len();
                let m = rows.first().map_or(0, Vec::len);
                if n == 0 || m == 0 || rows.iter().any(|r| r.len() != m) {
                    return Err(Error::invalid(
                        format!("plant.{name}"),
                        "must be a non-empty matrix with rows of equal length",
                    ));
                }
                if n * m > 1 << 20 {
                    return Err(Error::invalid(format!("plant.{name}"), format!("{n}×{m} is too large")));
                }
                Ok(DMatrix::from_fn(n, m, |i, j| rows[i][j]))
            };
            let (a, b, c) = (matrix("a", a)?, matrix("b", b)?, matrix("c", c)?);
            let d = match p.d {
                Some(d) => matrix("d", d)?,
                None => DMatrix::zeros(c.nrows(), b.ncols()),
            };
            let ss = MimoStateSpace::new("plant", a, b, c, d)?;
            if ss.outputs() != 2 || ss.inputs() != 2 {
                return Err(Error::invalid(
                    "plant",
                    format!(
                        "must be 2×2 (two actuators, two commands), got {} outputs × {} inputs",
                        ss.outputs(),
                        ss.inputs()
                    ),
                ));
            }
            Ok(ss)
        }
        _ => Err(Error::invalid(
            "plant",
            "give either `h` (the 2×2 matrix of zeros, poles and gains) or the state space `a`, `b`, `c` (and `d`)",
        )),
    }
}

fn prefixed(e: Error, prefix: &str) -> Error {
    match e {
        Error::InvalidInput { what, reason } => {
            let what = what.strip_prefix("phase_lag.").unwrap_or(&what).to_string();
            Error::invalid(format!("{prefix}{what}"), reason)
        }
        other => other,
    }
}
