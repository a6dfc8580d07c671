//! `[realtime]` (docs/config.md, section `[realtime]`): what `substep run --realtime` accepts
//! as real time.

use crate::error::{Error, Result};
pub use crate::realtime::LatePolicy;
use serde::Deserialize;

/// The share of sub-step slots that may miss their deadline before a real-time run counts as
/// failed, unless `[realtime] max_missed` or `--max-missed` says otherwise: 1 %.
pub const DEFAULT_MAX_MISSED: f64 = 0.01;

/// `[realtime]`: used by `substep run --realtime`; an offline run ignores it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RealtimeSettings {
    /// Largest share (0–1) of sub-step slots, holds included, whose work may end after the next
    /// slot's deadline; above it the run failed (exit 1, `"completed": false`).
    pub max_missed: f64,
    /// What the real-time thread does when the next step's predictor is late: hold the
    /// actuator (`"hold"`, the default: the test keeps the wall clock) or wait for it and
    /// re-base the schedule (`"wait"`: the run equals the offline run; for virtual labs and
    /// quasi-static specimens, docs/realtime.md).
    pub late_policy: LatePolicy,
}

impl Default for RealtimeSettings {
    fn default() -> Self {
        Self {
            max_missed: DEFAULT_MAX_MISSED,
            late_policy: LatePolicy::HoldExtrapolate,
        }
    }
}

/// A late policy by its name in `[realtime] late_policy` / `--late-policy`; `what` names the
/// setting in the message.
pub fn parse_late_policy(what: &str, name: &str) -> Result<LatePolicy> {
    match name {
        "hold" => Ok(LatePolicy::HoldExtrapolate),
        "wait" => Ok(LatePolicy::Wait),
        other => Err(Error::invalid(
            what,
            format!("must be \"hold\" (keep the wall clock) or \"wait\" (exact, re-based schedule), got {other:?}"),
        )),
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRealtime {
    pub(crate) max_missed: Option<f64>,
    pub(crate) late_policy: Option<String>,
}

impl RawRealtime {
    pub(crate) fn build(self) -> Result<RealtimeSettings> {
        let mut s = RealtimeSettings::default();
        if let Some(x) = self.max_missed {
            s.max_missed = check_max_missed("realtime.max_missed", x)?;
        }
        if let Some(name) = &self.late_policy {
            s.late_policy = parse_late_policy("realtime.late_policy", name)?;
        }
        Ok(s)
    }
}

/// A missed-deadline share: finite, in `[0, 1]`; `what` names it in the message.
pub fn check_max_missed(what: &str, x: f64) -> Result<f64> {
    if !(0.0..=1.0).contains(&x) {
        return Err(Error::invalid(
            what,
            format!(
                "must be a share of the sub-step deadlines between 0 and 1 (0.01 = 1 %), got {}",
                crate::format::sig(x, 6)
            ),
        ));
    }
    Ok(x)
}

/// Whether `missed` of `slots` deadlines is more than the share `max_missed` allows.
pub fn too_many_missed(missed: usize, slots: usize, max_missed: f64) -> bool {
    slots > 0 && missed as f64 > max_missed * slots as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shares_and_limits() {
        assert!(!too_many_missed(100, 10_000, 0.01));
        assert!(too_many_missed(101, 10_000, 0.01));
        assert!(too_many_missed(1, 10_000, 0.0));
        assert!(!too_many_missed(0, 10_000, 0.0));
        assert!(!too_many_missed(10_000, 10_000, 1.0));
        assert!(!too_many_missed(0, 0, 0.0));
        assert_eq!(parse_late_policy("x", "wait").unwrap(), LatePolicy::Wait);
        assert_eq!(parse_late_policy("x", "hold").unwrap(), LatePolicy::HoldExtrapolate);
        let e = parse_late_policy("realtime.late_policy", "later")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("realtime.late_policy: must be \"hold\""), "{e}");
        assert_eq!(check_max_missed("x", 0.05).unwrap(), 0.05);
        for bad in [-0.1, 1.5, f64::NAN, f64::INFINITY] {
            let e = check_max_missed("realtime.max_missed", bad).unwrap_err().to_string();
            assert!(e.starts_with("realtime.max_missed: must be a share"), "{e}");
        }
    }
}
