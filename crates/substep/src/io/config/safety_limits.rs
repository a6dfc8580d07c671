//! `[substructure.limits]` (docs/config.md, section `[substructure.limits]`): safety limits with
//! a controlled stop.

use super::common::OneOrMany;
use crate::error::{Error, Result};
use crate::substructure::{SafetyLimits, StabilityAction, StabilitySettings};
use serde::Deserialize;

/// `[substructure.limits]`: one value for all coupling DOFs or one per DOF.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLimits {
    pub(crate) displacement: Option<OneOrMany>,
    pub(crate) velocity: Option<OneOrMany>,
    pub(crate) force: Option<OneOrMany>,
    pub(crate) ramp_time: Option<f64>,
    /// `"warn"` or `"stop"`: run the on-line stability indicator.
    pub(crate) stability: Option<String>,
    /// Thresholds: energy ratio η, model margin 1 − ρ; window [s]; refresh [steps].
    pub(crate) stability_energy: Option<f64>,
    pub(crate) stability_margin: Option<f64>,
    pub(crate) stability_window: Option<f64>,
    pub(crate) stability_refresh: Option<usize>,
}

impl RawLimits {
    /// `stability = "off"`: no indicator (it runs by default, docs/config.md).
    pub(crate) fn stability_off(&self) -> bool {
        self.stability.as_deref() == Some("off")
    }

    fn stability(&self) -> Result<Option<StabilitySettings>> {
        let Some(action) = self.stability.as_ref().filter(|a| a.as_str() != "off") else {
            if self.stability_energy.is_some()
                || self.stability_margin.is_some()
                || self.stability_window.is_some()
                || self.stability_refresh.is_some()
            {
                return Err(Error::invalid(
                    "substructure.limits.stability",
                    if self.stability_off() {
                        "the stability_* thresholds are not used with stability = \"off\""
                    } else {
                        "the stability_* thresholds need stability = \"warn\" or \"stop\""
                    },
                ));
            }
            return Ok(None);
        };
        let action = match action.as_str() {
            "warn" => StabilityAction::Warn,
            "stop" => StabilityAction::Stop,
            other => {
                return Err(Error::invalid(
                    "substructure.limits.stability",
                    format!("unknown action '{other}' (expected \"warn\", \"stop\" or \"off\")"),
                ));
            }
        };
        let d = StabilitySettings::default();
        let s = StabilitySettings {
            action,
            energy_threshold: self.stability_energy.unwrap_or(d.energy_threshold),
            margin_threshold: self.stability_margin.unwrap_or(d.margin_threshold),
            window: self.stability_window.unwrap_or(d.window),
            refresh: self.stability_refresh.unwrap_or(d.refresh),
            ..d
        };
        s.validate()?;
        Ok(Some(s))
    }

    /// `dtau`: the sub-step length (the ramp after a stop runs in sub-steps of it).
    pub(crate) fn build(&self, n_c: usize, dtau: f64) -> Result<SafetyLimits> {
        let expand = |key: &str, v: &Option<OneOrMany>| -> Result<Option<Vec<f64>>> {
            match v {
                None => Ok(None),
                Some(OneOrMany(x)) if x.len() == 1 => Ok(Some(vec![x[0]; n_c])),
                Some(OneOrMany(x)) if x.len() == n_c => Ok(Some(x.clone())),
                Some(OneOrMany(x)) => Err(Error::invalid(
                    format!("substructure.limits.{key}"),
                    format!(
                        "has {} entries; give one value or one per coupling DOF ({n_c})",
                        x.len()
                    ),
                )),
            }
        };
        let limits = SafetyLimits {
            displacement: expand("displacement", &self.displacement)?,
            velocity: expand("velocity", &self.velocity)?,
            force: expand("force", &self.force)?,
            ramp_time: self.ramp_time.unwrap_or(1.0),
            stability: self.stability()?,
        };
        limits.validate_for(n_c, dtau)?;
        Ok(limits)
    }
}
