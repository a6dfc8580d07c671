//! `[structure.reduction]`: the numerical substructure reduced by Craig–Bampton before the test
//! (`model::Reduction`, docs/config.md "Model reduction", theory §12).

use super::specimens::RawSpecimen;
use super::substructure::RawSubstructure;
use crate::error::{Error, Result};
use crate::model::{ModeCount, ReductionMethod, ReductionSpec};
use serde::Deserialize;

/// `[structure.reduction]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawReduction {
    /// `"craig_bampton"` (the default) or `"ritz"`.
    pub(crate) method: Option<String>,
    pub(crate) modes: Option<usize>,
    /// Hz.
    pub(crate) frequency_max: Option<f64>,
    /// Physical DOFs kept besides the coupling DOFs (1-based, full model).
    #[serde(default)]
    pub(crate) keep: Vec<usize>,
    /// After an offline virtual test, run the full model too and put the error in the summary.
    pub(crate) check: Option<bool>,
}

impl RawReduction {
    /// The spec for a model of `n` DOFs whose coupling DOFs (1-based, checked) are `coupling`.
    pub(crate) fn spec(&self, n: usize, coupling: &[usize]) -> Result<ReductionSpec> {
        let method = match self.method.as_deref() {
            None | Some("craig_bampton") => ReductionMethod::CraigBampton,
            Some("ritz") => ReductionMethod::Ritz,
            Some(other) => {
                return Err(Error::invalid(
                    "structure.reduction.method",
                    format!("unknown method '{other}' (expected craig_bampton or ritz)"),
                ));
            }
        };
        let modes = match (self.modes, self.frequency_max) {
            (Some(m), None) => ModeCount::Modes(m),
            (None, Some(f)) => ModeCount::FrequencyMax(f),
            (Some(_), Some(_)) => {
                return Err(Error::invalid(
                    "structure.reduction.frequency_max",
                    "cannot be combined with structure.reduction.modes: give one",
                ));
            }
            (None, None) => {
                return Err(Error::invalid(
                    "structure.reduction",
                    "give modes (a number of fixed-interface modes or Ritz vectors) or frequency_max (Hz)",
                ));
            }
        };
        let mut kept = Vec::with_capacity(self.keep.len() + coupling.len());
        for &d in &self.keep {
            if d == 0 || d > n {
                return Err(Error::invalid(
                    "structure.reduction.keep",
                    format!("DOF {d} is out of range (the model has DOFs 1..={n})"),
                ));
            }
            kept.push(d - 1);
        }
        kept.extend(coupling.iter().filter(|&&d| d >= 1 && d <= n).map(|d| d - 1));
        kept.sort_unstable();
        kept.dedup();
        Ok(ReductionSpec { method, modes, kept })
    }

    /// At most this many DOFs in the reduced model of a full one of `n_full` (before it is
    /// computed: `frequency_max` counts as the cap on modes).
    pub(crate) fn reduced_dofs_bound(&self, n_coupling: usize, n_full: f64) -> f64 {
        let modes = self.modes.unwrap_or(crate::model::MAX_MODES);
        ((self.keep.len() + n_coupling + modes + 1) as f64).min(n_full)
    }

    pub(crate) fn check(&self) -> bool {
        self.check.unwrap_or(true)
    }
}

/// Renumber the DOFs a substructure names (1-based, full model) to the reduced model's (the
/// kept DOFs come first, in order).
pub(crate) fn renumber(sub: &mut RawSubstructure, kept: &[usize]) {
    let map = |d: &mut usize| {
        if let Some(k) = kept.iter().position(|&x| x + 1 == *d) {
            *d = k + 1;
        }
    };
    sub.coupling_dofs.iter_mut().for_each(map);
    for s in &mut sub.specimen {
        match s {
            RawSpecimen::LinearMdof { dofs, .. } => dofs.iter_mut().for_each(map),
            RawSpecimen::LinearSdof { dof, .. }
            | RawSpecimen::BoucWen { dof, .. }
            | RawSpecimen::Friction { dof, .. }
            | RawSpecimen::Replay { dof, .. }
            | RawSpecimen::LumpedSdof { dof, .. } => map(dof),
        }
    }
}
