//! Replay of a measured force record on one coupling DOF, regardless of the motion.
//!
//! The record holds the force on the structure (sign of docs/theory.md §1.2, as the load cell gives it) at
//! `t_j = j Δt_rec`, `j = 0 … N−1`, `t = 0` at the start of the test. Each instance keeps its own
//! elapsed time `t` (its state); `advance` reports the record at `t + dt`, linearly interpolated
//! between samples, and `0` after the last sample (`t > (N−1) Δt_rec`). The specimen never reads
//! the displacements.

use super::{Motion, Specimen};
use crate::error::{Error, Result, require_positive};
use std::sync::Arc;

pub struct Replay {
    dt: f64,
    values: Arc<[f64]>,
    t: f64,
    t_trial: f64,
}

impl Replay {
    /// `dt` the record's sampling interval \[s\] (`> 0`), `values` the forces \[N\] (non-empty,
    /// finite).
    pub fn new(dt: f64, values: impl Into<Arc<[f64]>>) -> Result<Self> {
        require_positive("specimen.dt", dt)?;
        let values = values.into();
        if values.is_empty() {
            return Err(Error::invalid("specimen.values", "the force record is empty"));
        }
        if let Some(j) = values.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(
                "specimen.values",
                format!("sample {j} is not finite ({})", values[j]),
            ));
        }
        Ok(Self {
            dt,
            values,
            t: 0.0,
            t_trial: 0.0,
        })
    }

    /// Committed elapsed time \[s\].
    pub fn time(&self) -> f64 {
        self.t
    }

    /// Duration of the record, `(N−1) Δt_rec` \[s\].
    pub fn duration(&self) -> f64 {
        (self.values.len() - 1) as f64 * self.dt
    }

    /// The record at time `t` (linear interpolation, 0 after the end; the first sample before
    /// `t = 0`).
    pub fn value_at(&self, t: f64) -> f64 {
        let v = &self.values;
        let last = v.len() - 1;
        let pos = t / self.dt;
        if !pos.is_finite() {
            return 0.0;
        }
        if pos <= 0.0 {
            return v[0];
        }
        // A relative tolerance so that round-off in the accumulated time cannot drop the last
        // sample.
        if pos >= last as f64 {
            return if pos <= last as f64 * (1.0 + 1e-12) + 1e-9 {
                v[last]
            } else {
                0.0
            };
        }
        let j = (pos.floor() as usize).min(last - 1);
        let r = pos - j as f64;
        v[j] + r * (v[j + 1] - v[j])
    }
}

impl Specimen for Replay {
    fn kind(&self) -> &'static str {
        "replay"
    }
    fn n_dofs(&self) -> usize {
        1
    }
    fn advance(&mut self, m: &Motion, force: &mut [f64]) {
        let dt = if m.dt.is_finite() && m.dt > 0.0 { m.dt } else { 0.0 };
        self.t_trial = self.t + dt;
        if let Some(out) = force.first_mut() {
            *out = self.value_at(self.t_trial);
        }
    }
    fn commit(&mut self) {
        self.t = self.t_trial;
    }
    fn is_linear(&self) -> bool {
        false
    }
    fn state_len(&self) -> usize {
        1
    }
    fn write_state(&self, out: &mut [f64]) {
        out[0] = self.t;
    }
    fn read_state(&mut self, state: &[f64]) {
        self.t = state[0];
        self.t_trial = state[0];
    }
}
