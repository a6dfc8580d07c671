//! What a wrapped experimental substructure reports to the run loop, and the settings of the
//! stability indicator that the safety wrapper carries: plain types that the layers above
//! (`compensate`, `lab`, `monitor`) fill in and the run loop reads, defined here so that the
//! trait [`super::ExperimentalSubstructure`] does not reach up into those layers.

use crate::error::{Error, Result, require_positive};
use crate::latency::LatencyHistogram;
use std::time::Duration;

/// What a phase-lag compensated site reports per sub-step (for records and summaries); see
/// [`crate::substructure::ExperimentalSubstructure::phase_lag`].
pub trait PhaseLagReport {
    /// `d − y` of the last sub-step per coupling DOF (target minus measured displacement).
    fn tracking_error(&self) -> &[f64];
    /// `Δu` of the last sub-step per coupling DOF (before the ramp).
    fn correction(&self) -> &[f64];
    /// The command sent in the last sub-step, `d + h Δu`.
    fn command_sent(&self) -> &[f64];
    /// `h` of the last sub-step.
    fn ramp_value(&self) -> f64;
    /// The compensator kind per coupling DOF.
    fn kinds(&self) -> Vec<&'static str>;
    /// Per coupling DOF (0-based): why its guard disabled it, if it did. Allocates.
    fn trips(&self) -> Vec<(usize, GuardTrip)>;
}

/// Why a [`Guard`](crate::compensate::Guard) disabled a compensator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GuardTrip {
    /// The target or the measured displacement was not finite.
    NonFiniteInput,
    /// The computed correction was not finite.
    NonFiniteCorrection,
    /// `|h Δu|` exceeded the bound.
    Bound { correction: f64, bound: f64 },
    /// The supervisor of an identified compensator saw its correction amount to a lead of
    /// `lead` sub-steps, more than `bound`: the compensated loop was going unstable.
    Unstable { lead: f64, bound: f64 },
}

impl std::fmt::Display for GuardTrip {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            GuardTrip::NonFiniteInput => write!(f, "non-finite target or measured displacement"),
            GuardTrip::NonFiniteCorrection => write!(f, "non-finite correction"),
            GuardTrip::Bound { correction, bound } => {
                write!(f, "correction {correction:.3e} exceeded the bound {bound:.3e}")
            }
            GuardTrip::Unstable { lead, bound } => write!(
                f,
                "the correction amounted to a lead of {lead:.1} sub-steps, more than the {bound:.1} \
                 a delay can need: the compensated loop was going unstable, so the compensator \
                 backed off"
            ),
        }
    }
}

/// What happened on the link (for `summary.json`).
#[derive(Debug, Clone, PartialEq)]
pub struct LabStats {
    pub protocol: &'static str,
    pub transport: &'static str,
    /// Sub-steps exchanged (answered or held).
    pub exchanges: u64,
    /// Sub-steps whose reply did not come in time: the last measurement was held.
    pub held: u64,
    pub max_held_in_a_row: u64,
    /// Replies that came after their sub-step was held (discarded).
    pub late: u64,
    /// Replies to a sub-step already answered (discarded).
    pub duplicated: u64,
    /// Replies that fit no request (a sequence number ahead of the one sent; discarded).
    pub unexpected: u64,
    /// Frames of the wrong size (discarded).
    pub malformed: u64,
    /// Stale frames skipped before a command (speedgoat over UDP).
    pub stale: u64,
    /// substep_udp: commands sent a second time when half the budget passed without a reply.
    pub resent: u64,
    /// Round trip of the answered exchanges.
    pub rtt: LatencyHistogram,
    /// The last exchange: held, and the stray replies it discarded (for `substeps.csv`).
    pub last_held: bool,
    pub last_strays: u64,
}

impl LabStats {
    pub(crate) fn strays(&self) -> u64 {
        self.late + self.duplicated + self.unexpected + self.malformed + self.stale
    }

    /// The `lab` block of `summary.json` (round trips in µs).
    pub fn json(&self) -> serde_json::Value {
        let us = |d: Duration| d.as_secs_f64() * 1e6;
        serde_json::json!({
            "protocol": self.protocol, "transport": self.transport, "exchanges": self.exchanges,
            "held": self.held, "max_held_in_a_row": self.max_held_in_a_row, "late": self.late,
            "duplicated": self.duplicated, "unexpected": self.unexpected, "malformed": self.malformed,
            "stale": self.stale, "resent": self.resent,
            "rtt_us": { "p50": us(self.rtt.percentile(0.5)), "p99": us(self.rtt.percentile(0.99)), "max": us(self.rtt.max()) },
        })
    }

    /// One line for a printed summary, from the `lab` block of [`LabStats::json`] (what a
    /// front end has of a finished run).
    pub fn summary_line(lab: &serde_json::Value) -> String {
        let us = |k: &str| lab["rtt_us"][k].as_f64().unwrap_or(f64::NAN);
        format!(
            "lab target ({} over {}): {} exchanges, {} held, {} late, {} duplicated; round trip p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs",
            lab["protocol"].as_str().unwrap_or("?"),
            lab["transport"].as_str().unwrap_or("?"),
            lab["exchanges"],
            lab["held"],
            lab["late"],
            lab["duplicated"],
            us("p50"),
            us("p99"),
            us("max")
        )
    }
}

/// What crossing a threshold does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StabilityAction {
    /// Warn (console, monitor page, `summary.json`) and go on.
    #[default]
    Warn,
    /// Start the controlled ramp-down of the safety limits.
    Stop,
}

impl StabilityAction {
    pub fn name(self) -> &'static str {
        match self {
            StabilityAction::Warn => "warn",
            StabilityAction::Stop => "stop",
        }
    }
}

/// `[substructure.limits] stability` and its thresholds.
#[derive(Debug, Clone, PartialEq)]
pub struct StabilitySettings {
    pub action: StabilityAction,
    /// Alarm when the energy ratio `η` exceeds this (1 = no damping left).
    pub energy_threshold: f64,
    /// Alarm when the model view's margin `1 − ρ` falls below this.
    pub margin_threshold: f64,
    /// Sliding window of the energy view and memory of the identification \[s\].
    pub window: f64,
    /// Steps between two evaluations of the model view.
    pub refresh: usize,
    /// Consecutive evaluations beyond a threshold before the alarm (noise immunity).
    pub persistence: usize,
}

impl Default for StabilitySettings {
    fn default() -> Self {
        Self {
            action: StabilityAction::Warn,
            energy_threshold: 0.8,
            margin_threshold: -1e-3,
            window: 2.0,
            refresh: 10,
            persistence: 3,
        }
    }
}

impl StabilitySettings {
    pub fn validate(&self) -> Result<()> {
        require_positive("substructure.limits.stability_energy", self.energy_threshold)?;
        if !(self.margin_threshold.is_finite() && self.margin_threshold < 1.0) {
            return Err(Error::invalid(
                "substructure.limits.stability_margin",
                format!("must be a finite number below 1, got {}", self.margin_threshold),
            ));
        }
        require_positive("substructure.limits.stability_window", self.window)?;
        if self.window > 600.0 {
            return Err(Error::invalid(
                "substructure.limits.stability_window",
                format!("{} s is longer than the maximum of 600 s", self.window),
            ));
        }
        if self.refresh == 0 {
            return Err(Error::invalid(
                "substructure.limits.stability_refresh",
                "must be at least 1 step",
            ));
        }
        Ok(())
    }
}
