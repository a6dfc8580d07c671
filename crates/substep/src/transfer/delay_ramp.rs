//! `[substructure.delay_ramp]`: a transfer system that degrades during the run — an extra pure
//! delay on the commands that grows linearly from 0 at `start` to `delay` at `end` (and stays).
//! A fault injection for virtual tests: it makes a stable test go unstable part-way, which is
//! what the stability indicator (docs/theory.md §15) must catch.

use crate::error::{Error, Result};
use crate::substructure::{ExperimentalSubstructure, StopLog};

/// The ramp: extra delay `delay` \[s\] reached at `end` \[s\], starting at `start` \[s\] of
/// test time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DelayRamp {
    pub start: f64,
    pub end: f64,
    pub delay: f64,
}

/// Longest extra delay \[s\].
pub const MAX_RAMP_DELAY: f64 = 1.0;

impl DelayRamp {
    pub fn validate(&self, dtau: f64) -> Result<()> {
        let what = "substructure.delay_ramp";
        if !(self.start.is_finite() && self.start >= 0.0) {
            return Err(Error::invalid(
                format!("{what}.start"),
                format!("must be a time >= 0 s, got {}", self.start),
            ));
        }
        if !(self.end.is_finite() && self.end > self.start) {
            return Err(Error::invalid(
                format!("{what}.end"),
                format!("must be later than start = {} s, got {}", self.start, self.end),
            ));
        }
        if !(self.delay.is_finite() && self.delay >= 0.0 && self.delay <= MAX_RAMP_DELAY) {
            return Err(Error::invalid(
                format!("{what}.delay"),
                format!("must be in [0, {MAX_RAMP_DELAY}] s, got {}", self.delay),
            ));
        }
        if self.delay / dtau > 1e6 {
            return Err(Error::invalid(
                format!("{what}.delay"),
                format!("{} s is more than 10⁶ sub-steps of {dtau:e} s", self.delay),
            ));
        }
        Ok(())
    }

    /// Extra delay at test time `t` \[s\].
    pub fn at(&self, t: f64) -> f64 {
        self.delay * ((t - self.start) / (self.end - self.start)).clamp(0.0, 1.0)
    }
}

/// Wraps the experimental side (next to the actuators) and delays its commands by
/// [`DelayRamp::at`] of the current time, with linear interpolation between sub-steps.
pub struct DelayRampSite {
    inner: Box<dyn ExperimentalSubstructure>,
    ramp: DelayRamp,
    t: f64,
    /// Ring of past sub-step ends: time and one command per coupling DOF.
    times: Vec<f64>,
    values: Vec<f64>,
    head: usize,
    delayed: Vec<f64>,
}

impl DelayRampSite {
    /// `dtau`: the nominal sub-step length (sizes the history; re-spaced sub-steps down to
    /// half of it are covered).
    pub fn new(inner: Box<dyn ExperimentalSubstructure>, ramp: DelayRamp, dtau: f64) -> Result<Self> {
        ramp.validate(dtau)?;
        let n = inner.n_coupling();
        let cap = 2 * ((ramp.delay / dtau).ceil() as usize + 2);
        Ok(Self {
            inner,
            ramp,
            t: 0.0,
            // The signal was 0 since t = −∞.
            times: (0..cap).map(|k| (k as f64 - (cap - 1) as f64) * dtau).collect(),
            values: vec![0.0; cap * n],
            head: cap - 1,
            delayed: vec![0.0; n],
        })
    }

    fn value_at(&mut self, t: f64) {
        let (cap, n) = (self.times.len(), self.delayed.len());
        let mut newer = self.head;
        for _ in 1..cap {
            let older = (newer + cap - 1) % cap;
            if self.times[older] <= t {
                let (t0, t1) = (self.times[older], self.times[newer]);
                let r = if t1 > t0 { (t - t0) / (t1 - t0) } else { 1.0 };
                for k in 0..n {
                    let (a, b) = (self.values[older * n + k], self.values[newer * n + k]);
                    self.delayed[k] = a + r * (b - a);
                }
                return;
            }
            newer = older;
        }
        self.delayed.copy_from_slice(&self.values[newer * n..(newer + 1) * n]);
    }
}

impl ExperimentalSubstructure for DelayRampSite {
    fn n_coupling(&self) -> usize {
        self.inner.n_coupling()
    }
    fn substep(
        &mut self,
        command: &[f64],
        ag: (f64, f64),
        dtau: f64,
        force: &mut [f64],
        displacement: &mut [f64],
    ) -> Result<()> {
        let n = self.delayed.len();
        self.t += dtau;
        self.head = (self.head + 1) % self.times.len();
        self.times[self.head] = self.t;
        self.values[self.head * n..(self.head + 1) * n].copy_from_slice(command);
        let t = self.t - self.ramp.at(self.t);
        self.value_at(t);
        self.inner.substep(&self.delayed, ag, dtau, force, displacement)
    }
    fn is_linear(&self) -> Result<()> {
        Err(Error::invalid(
            "substructure.delay_ramp",
            "a delay that changes during the run is not a time-invariant map",
        ))
    }
    fn state_len(&self) -> usize {
        self.inner.state_len()
    }
    fn write_state(&self, out: &mut [f64]) {
        self.inner.write_state(out)
    }
    fn read_state(&mut self, state: &[f64]) {
        self.inner.read_state(state)
    }
    fn true_force(&self) -> Option<&[f64]> {
        self.inner.true_force()
    }
    fn true_displacement(&self) -> Option<&[f64]> {
        self.inner.true_displacement()
    }
    fn phase_lag(&self) -> Option<&dyn crate::substructure::PhaseLagReport> {
        self.inner.phase_lag()
    }
    fn take_stop_log(&mut self) -> Option<StopLog> {
        self.inner.take_stop_log()
    }
    fn request_stop(&mut self, reason: &str) -> bool {
        self.inner.request_stop(reason)
    }
    fn lab_stats(&self) -> Option<&crate::substructure::LabStats> {
        self.inner.lab_stats()
    }
    fn pace_ramp(&mut self, clock: Option<Box<dyn crate::substructure::RampClock>>) -> bool {
        self.inner.pace_ramp(clock)
    }
}
