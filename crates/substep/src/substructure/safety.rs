//! Safety limits and the controlled stop.
//!
//! [`LimitedSite`] wraps any experimental side. Before a command is sent it checks the command
//! velocity; after each sub-step it checks the measured displacement and force of every
//! coupling DOF. On a violation — or when the wrapped site fails — it ramps the actuators
//! linearly from the last command to the safe position (0, where the test started) over
//! `ramp_time`, sub-step by sub-step (never a jump), and returns [`Error::Stopped`] with a
//! message naming the DOF, the quantity, the value and the limit.
//!
//! The stop is recorded in a [`StopLog`] (the tripping sub-step, if it was measured, and every
//! ramp sub-step) that the driver takes with [`ExperimentalSubstructure::take_stop_log`] and
//! hands to its [`SubstepObserver`] ([`StopLog::replay`]), so the ramp is in `substeps.csv`.
//! Offline the ramp runs as fast as the side does; a real-time runner paces it with a
//! [`RampClock`] ([`ExperimentalSubstructure::pace_ramp`]), one ramp sub-step per `Δτ`.
//! The ramp is bounded: `ramp_time` ≤ [`MAX_RAMP_TIME`] and at most [`MAX_RAMP_SUBSTEPS`]
//! sub-steps, so a stop always ends and its log has a fixed maximum size.

use super::{ExperimentalSubstructure, SubstepObserver};
use crate::error::{Error, Result, require_positive};

/// Longest ramp to the safe position \[s\]. A lab ramps actuators down in seconds; a longer
/// value is a typo (`1e6`) that would keep the stop running for days.
pub const MAX_RAMP_TIME: f64 = 60.0;
/// Most sub-steps of one ramp (`ceil(ramp_time / Δτ)`): bounds the time and the memory of a
/// stop (the [`StopLog`] holds `3 n_c` numbers per ramp sub-step).
pub const MAX_RAMP_SUBSTEPS: usize = 100_000;

/// Limits per coupling DOF (`None`: not checked). Units: m, m/s, N, s.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SafetyLimits {
    pub displacement: Option<Vec<f64>>,
    pub velocity: Option<Vec<f64>>,
    pub force: Option<Vec<f64>>,
    /// Duration of the ramp to the safe position after a stop \[s\].
    pub ramp_time: f64,
    /// `stability = "warn" | "stop"` and the thresholds of the on-line stability indicator
    /// ([`crate::monitor`]); the driver runs the indicator and, for "stop", asks for the ramp.
    pub stability: Option<crate::substructure::StabilitySettings>,
}

impl SafetyLimits {
    pub fn validate(&self, n_c: usize) -> Result<()> {
        for (key, v) in [
            ("displacement", &self.displacement),
            ("velocity", &self.velocity),
            ("force", &self.force),
        ] {
            if let Some(v) = v {
                let what = format!("substructure.limits.{key}");
                if v.len() != n_c {
                    return Err(Error::invalid(
                        what,
                        format!("has {} entries for {n_c} coupling DOFs", v.len()),
                    ));
                }
                for &x in v {
                    require_positive(&what, x)?;
                }
            }
        }
        require_positive("substructure.limits.ramp_time", self.ramp_time)?;
        if self.ramp_time > MAX_RAMP_TIME {
            return Err(Error::invalid(
                "substructure.limits.ramp_time",
                format!("{} s is longer than the maximum of {MAX_RAMP_TIME} s", self.ramp_time),
            ));
        }
        Ok(())
    }

    /// [`validate`](Self::validate), and the ramp fits in [`MAX_RAMP_SUBSTEPS`] sub-steps of
    /// length `dtau` \[s\].
    pub fn validate_for(&self, n_c: usize, dtau: f64) -> Result<()> {
        self.validate(n_c)?;
        let substeps = ramp_substeps(self.ramp_time, dtau);
        if substeps > MAX_RAMP_SUBSTEPS as f64 {
            return Err(Error::invalid(
                "substructure.limits.ramp_time",
                format!(
                    "{} s needs {substeps:.0} ramp sub-steps of {dtau:e} s; at most {MAX_RAMP_SUBSTEPS} are allowed \
                     (shorten ramp_time or lengthen the sub-steps)",
                    self.ramp_time
                ),
            ));
        }
        Ok(())
    }
}

/// Sub-steps of a ramp of `ramp_time` in sub-steps of `dtau` (at least one).
fn ramp_substeps(ramp_time: f64, dtau: f64) -> f64 {
    (ramp_time / dtau).ceil().max(1.0)
}

/// What the experimental side did in a controlled stop, for the records.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StopLog {
    n_c: usize,
    /// The first row is the sub-step that tripped a limit (command sent and measured).
    tripped: bool,
    /// Rows of `3 n_c` numbers: command, measured force, measured displacement.
    rows: Vec<f64>,
}

type Row<'a> = (&'a [f64], &'a [f64], &'a [f64]);

impl StopLog {
    fn row(&self, r: usize) -> Row<'_> {
        let n = self.n_c;
        let x = &self.rows[3 * n * r..3 * n * (r + 1)];
        (&x[..n], &x[n..2 * n], &x[2 * n..])
    }
    fn push(&mut self, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.rows.extend_from_slice(command);
        self.rows.extend_from_slice(force);
        self.rows.extend_from_slice(displacement);
    }
    fn rows(&self) -> usize {
        self.rows.len() / (3 * self.n_c).max(1)
    }
    /// The sub-step whose measurement tripped a limit: command, force, displacement (`None`
    /// when the command was refused or the site failed: nothing was measured).
    pub fn tripped(&self) -> Option<Row<'_>> {
        (self.tripped && self.rows() > 0).then(|| self.row(0))
    }
    /// The ramp sub-steps to the safe position, in order: command, force, displacement.
    pub fn ramp(&self) -> impl Iterator<Item = Row<'_>> {
        (usize::from(self.tripped)..self.rows()).map(|r| self.row(r))
    }
    pub fn ramp_len(&self) -> usize {
        self.rows() - usize::from(self.tripped && self.rows() > 0)
    }
    /// Hand the stop to `observer`: the tripping sub-step as sub-step `j` of `step` (the
    /// sub-step that failed), then ramp sub-step `s = 1, 2, ...` as sub-step `j_last + s` of the
    /// same step (`j_last`: the last sub-step that was executed), so time runs on.
    pub fn replay(&self, step: usize, j: usize, observer: &mut (impl SubstepObserver + ?Sized)) {
        let mut last = j.saturating_sub(1);
        if let Some((c, f, d)) = self.tripped() {
            observer.substep(step, j, c, f, d);
            last = j;
        }
        for (s, (c, f, d)) in self.ramp().enumerate() {
            observer.ramp(step, last + s + 1, s + 1, c, f, d);
        }
    }
}

/// Paces the ramp of a controlled stop (a real-time runner's clock; the numerical core keeps no
/// clock of its own).
pub trait RampClock: Send {
    /// Called before ramp sub-step `s` (1-based) of length `dtau` \[s\] is sent: wait until it
    /// is due (`s = 1` starts the ramp's schedule).
    fn before_ramp_substep(&mut self, s: usize, dtau: f64);
}

pub struct LimitedSite {
    inner: Box<dyn ExperimentalSubstructure>,
    limits: SafetyLimits,
    last_command: Vec<f64>,
    ramp_command: Vec<f64>,
    scratch_force: Vec<f64>,
    scratch_disp: Vec<f64>,
    stopped: bool,
    log: Option<StopLog>,
    /// A stop asked for from outside ([`ExperimentalSubstructure::request_stop`]).
    requested: Option<String>,
    clock: Option<Box<dyn RampClock>>,
}

impl LimitedSite {
    pub fn new(inner: Box<dyn ExperimentalSubstructure>, limits: SafetyLimits) -> Result<Self> {
        let n = inner.n_coupling();
        limits.validate(n)?;
        Ok(Self {
            inner,
            limits,
            last_command: vec![0.0; n],
            ramp_command: vec![0.0; n],
            scratch_force: vec![0.0; n],
            scratch_disp: vec![0.0; n],
            stopped: false,
            log: None,
            requested: None,
            clock: None,
        })
    }

    /// Ramp from the last command to 0 over `ramp_time` in sub-steps of `dtau` (at most
    /// [`MAX_RAMP_SUBSTEPS`]), ground acceleration 0, into `log`; returns what went wrong during
    /// the ramp, if anything.
    fn ramp_to_safe(&mut self, dtau: f64, log: &mut StopLog) -> Option<String> {
        let steps = ramp_substeps(self.limits.ramp_time, dtau).min(MAX_RAMP_SUBSTEPS as f64) as usize;
        // Allocated once, on the stop path (never in a running test's sub-steps).
        log.rows.reserve_exact(3 * self.inner.n_coupling() * steps);
        for s in 1..=steps {
            if let Some(clock) = &mut self.clock {
                clock.before_ramp_substep(s, dtau);
            }
            let r = 1.0 - s as f64 / steps as f64;
            for (c, &l) in self.ramp_command.iter_mut().zip(&self.last_command) {
                *c = r * l;
            }
            if let Err(e) = self.inner.substep(
                &self.ramp_command,
                (0.0, 0.0),
                dtau,
                &mut self.scratch_force,
                &mut self.scratch_disp,
            ) {
                return Some(format!("the ramp to the safe position failed at {s}/{steps}: {e}"));
            }
            log.push(&self.ramp_command, &self.scratch_force, &self.scratch_disp);
        }
        None
    }

    /// The controlled stop. `measured`: the command, force and displacement of the sub-step
    /// that tripped a limit, if it was executed.
    fn stop(&mut self, dtau: f64, reason: String, measured: Option<Row<'_>>) -> Error {
        self.stopped = true;
        let mut log = StopLog {
            n_c: self.inner.n_coupling(),
            tripped: measured.is_some(),
            rows: Vec::new(),
        };
        if let Some((c, f, d)) = measured {
            log.push(c, f, d);
        }
        let ramp = match self.ramp_to_safe(dtau, &mut log) {
            None => format!("actuators ramped to 0 over {} s", self.limits.ramp_time),
            Some(e) => e,
        };
        self.log = Some(log);
        Error::Stopped {
            step: 0,
            time: 0.0,
            reason: format!("{reason}; {ramp}"),
        }
    }
}

fn violation(values: &[f64], limits: &Option<Vec<f64>>) -> Option<(usize, f64, f64)> {
    let l = limits.as_ref()?;
    values
        .iter()
        .zip(l)
        .enumerate()
        .find(|(_, (v, l))| v.is_nan() || v.abs() > **l)
        .map(|(i, (v, l))| (i, *v, *l))
}

impl ExperimentalSubstructure for LimitedSite {
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
        if self.stopped {
            return Err(Error::Stopped {
                step: 0,
                time: 0.0,
                reason: "the test was stopped earlier".into(),
            });
        }
        if let Some(reason) = self.requested.take() {
            return Err(self.stop(dtau, reason, None));
        }
        if let Some(v) = &self.limits.velocity {
            for (i, (&c, &l)) in command.iter().zip(&self.last_command).enumerate() {
                let vel = (c - l) / dtau;
                if vel.is_nan() || vel.abs() > v[i] {
                    let reason = format!(
                        "safety stop: command velocity {vel:.4e} m/s on coupling DOF {} exceeds the limit {:e} m/s (command not sent)",
                        i + 1,
                        v[i]
                    );
                    return Err(self.stop(dtau, reason, None));
                }
            }
        }
        if let Err(e) = self.inner.substep(command, ag, dtau, force, displacement) {
            // The site may be gone; try to bring it to the safe position anyway.
            return Err(self.stop(dtau, format!("experimental side failed: {e}"), None));
        }
        self.last_command.copy_from_slice(command);
        let found = violation(displacement, &self.limits.displacement)
            .map(|v| ("displacement", "m", v))
            .or_else(|| violation(force, &self.limits.force).map(|v| ("force", "N", v)));
        if let Some((what, unit, (i, v, l))) = found {
            let reason = format!(
                "safety stop: measured {what} {v:.4e} {unit} on coupling DOF {} exceeds the limit {l:e} {unit}",
                i + 1
            );
            return Err(self.stop(dtau, reason, Some((command, &*force, &*displacement))));
        }
        Ok(())
    }

    fn take_stop_log(&mut self) -> Option<StopLog> {
        self.log.take()
    }
    fn request_stop(&mut self, reason: &str) -> bool {
        if !self.stopped && self.requested.is_none() {
            self.requested = Some(reason.to_string());
        }
        true
    }
    fn lab_stats(&self) -> Option<&crate::substructure::LabStats> {
        self.inner.lab_stats()
    }
    fn pace_ramp(&mut self, clock: Option<Box<dyn RampClock>>) -> bool {
        self.clock = clock;
        true
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

    fn is_linear(&self) -> Result<()> {
        self.inner.is_linear()
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
}
