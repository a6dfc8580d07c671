//! Live monitoring of a run: the on-line stability indicator (docs/theory.md §15), the frames
//! a run hands to a monitor (the web page of `substep run --monitor`, docs/monitor.md) and the
//! operator's commands coming back.
//!
//! * [`StabilityMonitor`]: the energy view ([`energy`]) and the model view ([`model_view`]) of
//!   the indicator, fed once per step, with the thresholds and the action of
//!   `[substructure.limits] stability`.
//! * [`Frame`]: a fixed-size snapshot of one step (no heap data), pushed by the stepping
//!   thread into a lock-free SPSC ring ([`frame_ring`]); a full ring drops the frame, never
//!   the step.
//! * [`Controls`]: stop, hold and acknowledge as atomics, set by the monitor's thread and
//!   checked by the stepping loop between steps (no lock on either side).
//! * [`page`]: the HTTP server of the live page (std only, bounded, slow clients cannot stall
//!   it); the run loop's side of page and indicator is `crate::session::live`.

pub mod energy;
pub mod http;
mod indicator;
pub mod model_view;
pub mod page;

pub use indicator::{
    Alarm, AlarmSummary, IdentifiedSummary, IndicatorView, StabilityAction, StabilityMonitor, StabilitySettings,
    StabilitySummary,
};

use crate::realtime::{OwnedConsumer, OwnedProducer, owned_ring};
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};

/// Coupling DOFs a frame carries (the first ones of a test).
pub const FRAME_DOFS: usize = 4;

/// One step as the monitor shows it. Units SI; NaN where a value does not exist (no reference,
/// no model view yet, no real-time statistics).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    pub step: u64,
    pub time: f64,
    /// Coupling DOFs filled in (≤ [`FRAME_DOFS`]).
    pub n_c: usize,
    pub command: [f64; FRAME_DOFS],
    pub measured: [f64; FRAME_DOFS],
    pub force: [f64; FRAME_DOFS],
    pub error_force: [f64; FRAME_DOFS],
    /// Displacement of the coupling DOF in the test and in the reference solution.
    pub test_u: [f64; FRAME_DOFS],
    pub reference_u: [f64; FRAME_DOFS],
    pub eta: f64,
    pub margin: f64,
    pub stiffness: [f64; FRAME_DOFS],
    pub damping: [f64; FRAME_DOFS],
    pub lag: [f64; FRAME_DOFS],
    /// Real-time runs: steps that started late so far, hold sub-steps so far.
    pub late_steps: u64,
    pub hold_substeps: u64,
    /// The stability indicator has raised its alarm.
    pub alarm: bool,
}

impl Default for Frame {
    fn default() -> Self {
        let nan = [f64::NAN; FRAME_DOFS];
        Self {
            step: 0,
            time: 0.0,
            n_c: 0,
            command: nan,
            measured: nan,
            force: nan,
            error_force: nan,
            test_u: nan,
            reference_u: nan,
            eta: f64::NAN,
            margin: f64::NAN,
            stiffness: nan,
            damping: nan,
            lag: nan,
            late_steps: 0,
            hold_substeps: 0,
            alarm: false,
        }
    }
}

impl Frame {
    /// Copy the indicator's current values into the frame.
    pub fn set_indicator(&mut self, m: &StabilityMonitor) {
        self.eta = m.eta();
        self.margin = m.margin();
        self.alarm = m.alarm().is_some();
        let id = m.identification();
        copy_into(&mut self.stiffness, id.stiffness());
        copy_into(&mut self.damping, id.damping());
        copy_into(&mut self.lag, id.lag());
    }
}

/// Copy the first [`FRAME_DOFS`] values of `src` into `dst`.
pub fn copy_into(dst: &mut [f64; FRAME_DOFS], src: &[f64]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = *s;
    }
}

/// The ring from the stepping thread to the monitor: `capacity` preallocated frames.
pub fn frame_ring(capacity: usize) -> (OwnedProducer<Frame>, OwnedConsumer<Frame>) {
    owned_ring(capacity.max(1), Frame::default)
}

/// Who asked for the stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopRequest {
    /// The operator, on the monitor page, with the token.
    Operator,
    /// The stability indicator (`stability = "stop"`).
    Stability,
}

/// Operator commands from the monitor to the stepping loop.
#[derive(Debug, Default)]
pub struct Controls {
    /// 0: none, 1: operator stop, 2: stability stop.
    stop: AtomicU8,
    hold: AtomicBool,
    acks: AtomicU64,
}

impl Controls {
    pub fn request_stop(&self, who: StopRequest) {
        let code = match who {
            StopRequest::Operator => 1,
            StopRequest::Stability => 2,
        };
        // The first request wins (who stopped the test is recorded once).
        let _ = self.stop.compare_exchange(0, code, Ordering::AcqRel, Ordering::Acquire);
    }
    pub fn stop_requested(&self) -> Option<StopRequest> {
        match self.stop.load(Ordering::Acquire) {
            1 => Some(StopRequest::Operator),
            2 => Some(StopRequest::Stability),
            _ => None,
        }
    }
    pub fn set_hold(&self, hold: bool) {
        self.hold.store(hold, Ordering::Release);
    }
    pub fn held(&self) -> bool {
        self.hold.load(Ordering::Acquire)
    }
    /// Acknowledge the current warnings (counts acknowledgements).
    pub fn acknowledge(&self) {
        self.acks.fetch_add(1, Ordering::AcqRel);
    }
    pub fn acknowledgements(&self) -> u64 {
        self.acks.load(Ordering::Acquire)
    }
}

/// A fresh random token of 32 hex digits (128 bits from the OS).
pub fn new_token() -> crate::Result<String> {
    let mut b = [0u8; 16];
    getrandom::fill(&mut b).map_err(|e| crate::Error::numerical("monitor token", format!("no OS randomness: {e}")))?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// `a == b` in time independent of where they differ.
pub fn token_matches(given: &str, expected: &str) -> bool {
    let (a, b) = (given.as_bytes(), expected.as_bytes());
    if a.len() != b.len() || b.is_empty() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}
