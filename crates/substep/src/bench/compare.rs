//! Comparisons with other tools: before anything is timed, the tools must compute the same
//! response of the same model.

use crate::error::{Error, Result};

/// `max_i |theirs_i − ours_i| / max_i |ours_i|` over a response history.
pub fn max_rel_difference(ours: &[f64], theirs: &[f64]) -> f64 {
    let scale = ours.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(f64::MIN_POSITIVE);
    if ours.len() != theirs.len() {
        return f64::INFINITY;
    }
    ours.iter()
        .zip(theirs)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, |m: f64, d| if d.is_nan() { f64::INFINITY } else { m.max(d) })
        / scale
}

/// Whether `tool`'s response agrees with ours to `tolerance` (relative to our peak); the
/// difference if it does, an error naming the tool and the difference if it does not.
pub fn check_agreement(tool: &str, ours: &[f64], theirs: &[f64], tolerance: f64) -> Result<f64> {
    if ours.len() != theirs.len() {
        return Err(Error::invalid(
            tool,
            format!(
                "reported {} response values for {} steps: not the same run",
                theirs.len(),
                ours.len()
            ),
        ));
    }
    let d = max_rel_difference(ours, theirs);
    if d <= tolerance {
        Ok(d)
    } else {
        Err(Error::invalid(
            tool,
            format!(
                "its response differs from substep's by {d:.3e} (relative, tolerance {tolerance:.0e}): a different model, not timed"
            ),
        ))
    }
}
