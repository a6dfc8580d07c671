//! `[substructure.limits]` (docs/config.md, section `[substructure.limits]`): safety limits with
//! a controlled stop.

use super::OneOrMany;
use crate::error::{Error, Result};
use crate::substructure::SafetyLimits;
use serde::Deserialize;

/// `[substructure.limits]`: one value for all coupling DOFs or one per DOF.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLimits {
    pub(crate) displacement: Option<OneOrMany>,
    pub(crate) velocity: Option<OneOrMany>,
    pub(crate) force: Option<OneOrMany>,
    pub(crate) ramp_time: Option<f64>,
}

impl RawLimits {
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
        };
        limits.validate_for(n_c, dtau)?;
        Ok(limits)
    }
}
