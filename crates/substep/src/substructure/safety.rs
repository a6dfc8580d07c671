//! Safety limits and the controlled stop.
//!
//! [`LimitedSite`] wraps any experimental side. Before a command is sent it checks the command
//! velocity; after each sub-step it checks the measured displacement and force of every
//! coupling DOF. On a violation — or when the wrapped site fails — it ramps the actuators
//! linearly from the last command to the safe position (0, where the test started) over
//! `ramp_time`, sub-step by sub-step (never a jump), and returns [`Error::Stopped`] with a
//! message naming the DOF, the quantity, the value and the limit.

use super::ExperimentalSubstructure;
use crate::error::{Error, Result, require_positive};

/// Limits per coupling DOF (`None`: not checked). Units: m, m/s, N, s.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SafetyLimits {
    pub displacement: Option<Vec<f64>>,
    pub velocity: Option<Vec<f64>>,
    pub force: Option<Vec<f64>>,
    /// Duration of the ramp to the safe position after a stop \[s\].
    pub ramp_time: f64,
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
        Ok(())
    }
}

pub struct LimitedSite {
    inner: Box<dyn ExperimentalSubstructure>,
    limits: SafetyLimits,
    last_command: Vec<f64>,
    ramp_command: Vec<f64>,
    scratch_force: Vec<f64>,
    scratch_disp: Vec<f64>,
    stopped: bool,
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
        })
    }

    /// Ramp from the last command to 0 over `ramp_time` in sub-steps of `dtau`, ground
    /// acceleration 0; returns what went wrong during the ramp, if anything.
    fn ramp_to_safe(&mut self, dtau: f64) -> Option<String> {
        let steps = (self.limits.ramp_time / dtau).ceil().max(1.0) as usize;
        for s in 1..=steps {
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
        }
        None
    }

    fn stop(&mut self, dtau: f64, reason: String) -> Error {
        self.stopped = true;
        let ramp = match self.ramp_to_safe(dtau) {
            None => format!("actuators ramped to 0 over {} s", self.limits.ramp_time),
            Some(e) => e,
        };
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
        if let Some(v) = &self.limits.velocity {
            for (i, (&c, &l)) in command.iter().zip(&self.last_command).enumerate() {
                let vel = (c - l) / dtau;
                if vel.is_nan() || vel.abs() > v[i] {
                    let reason = format!(
                        "safety stop: command velocity {vel:.4e} m/s on coupling DOF {} exceeds the limit {:e} m/s (command not sent)",
                        i + 1,
                        v[i]
                    );
                    return Err(self.stop(dtau, reason));
                }
            }
        }
        if let Err(e) = self.inner.substep(command, ag, dtau, force, displacement) {
            // The site may be gone; try to bring it to the safe position anyway.
            return Err(self.stop(dtau, format!("experimental side failed: {e}")));
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
            return Err(self.stop(dtau, reason));
        }
        Ok(())
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
