//! The controlled stop of a real-time run asked for from outside (an operator on the monitor
//! page, the stability indicator on the writer thread), and the clock that paces the ramp to
//! the safe position on the real-time thread.

use crate::substructure::RampClock;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

/// Ask a running [`RealtimeRunner`](super::RealtimeRunner) for the controlled stop, from any
/// thread. The real-time thread polls it once per step (`OnceLock::get`, one atomic load: no
/// lock, no allocation, no system call); at the next step boundary it hands the reason to the safety
/// ramp of the experimental side ([`ExperimentalSubstructure::request_stop`]), and the run ends
/// with [`Error::Stopped`] and that reason, as after a tripped limit.
///
/// [`ExperimentalSubstructure::request_stop`]: crate::substructure::ExperimentalSubstructure::request_stop
/// [`Error::Stopped`]: crate::Error::Stopped
#[derive(Debug, Clone, Default)]
pub struct StopHandle(Arc<OnceLock<String>>);

impl StopHandle {
    pub fn new() -> Self {
        Self::default()
    }

    /// Ask for the stop. The first reason is kept (who stopped the run is recorded once);
    /// returns whether this call was the first.
    pub fn request(&self, reason: impl Into<String>) -> bool {
        self.0.set(reason.into()).is_ok()
    }

    /// The reason, once a stop has been asked for.
    pub fn requested(&self) -> Option<&str> {
        self.0.get().map(String::as_str)
    }
}

/// Paces a ramp in real time: ramp sub-step `s` starts `(s − 1) Δτ` after the first (which
/// starts at once), with the runner's sleep (native sleep, then a short spin).
pub(super) struct PacedRamp {
    sleeper: spin_sleep::SpinSleeper,
    origin: Option<Instant>,
}

impl PacedRamp {
    pub(super) fn new(spin_window: Duration) -> Self {
        Self {
            sleeper: spin_sleep::SpinSleeper::new(spin_window.as_nanos().min(999_999_999) as u32),
            origin: None,
        }
    }
}

impl RampClock for PacedRamp {
    fn before_ramp_substep(&mut self, s: usize, dtau: f64) {
        match self.origin {
            Some(origin) if s > 1 => self
                .sleeper
                .sleep_until(origin + Duration::from_secs_f64(dtau * (s - 1) as f64)),
            _ => self.origin = Some(Instant::now()),
        }
    }
}
