//! Mass, dashpot and spring lumped at one coupling DOF (the RTHS benchmark's experimental
//! substructure): the load cell between actuator and specimen carries `m ẍ + c ẋ + k x`.
//!
//! The specimen only sees the imposed motion, so its force is built from it by backward
//! differences over the intervals it is moved through, like a lab builds it from measured
//! motion: `v = (x₁ − x₀)/h` (the velocity of the interval), `a = (v − v_prev)/h` (`v_prev` of
//! the previous interval, 0 from rest). The mass also carries its share of the earthquake load,
//! `m a_g`, which the numerical model's load vector does not contain (so the test equals the
//! monolithic model with `m` added at the DOF and influence 1 there):
//! `f = −(k x₁ + c v + m (a + a_g,1))` on the structure.

use super::{Motion, Specimen};
use crate::error::{Result, require_non_negative, require_positive};

#[derive(Debug, Clone)]
pub struct LumpedSdof {
    mass: f64,
    damping: f64,
    stiffness: f64,
    v_prev: f64,
    v_trial: f64,
}

impl LumpedSdof {
    pub fn new(mass: f64, damping: f64, stiffness: f64) -> Result<Self> {
        require_positive("specimen.mass", mass)?;
        require_non_negative("specimen.damping", damping)?;
        require_non_negative("specimen.stiffness", stiffness)?;
        Ok(Self {
            mass,
            damping,
            stiffness,
            v_prev: 0.0,
            v_trial: 0.0,
        })
    }
}

impl Specimen for LumpedSdof {
    fn kind(&self) -> &'static str {
        "lumped_sdof"
    }
    fn n_dofs(&self) -> usize {
        1
    }
    fn advance(&mut self, m: &Motion, force: &mut [f64]) {
        let v = (m.d_end[0] - m.d_start[0]) / m.dt;
        let a = (v - self.v_prev) / m.dt;
        self.v_trial = v;
        force[0] = -(self.stiffness * m.d_end[0] + self.damping * v + self.mass * (a + m.ag_end));
    }
    fn commit(&mut self) {
        self.v_prev = self.v_trial;
    }
    fn is_linear(&self) -> bool {
        true
    }
    fn state_len(&self) -> usize {
        1
    }
    fn write_state(&self, out: &mut [f64]) {
        out[0] = self.v_prev;
    }
    fn read_state(&mut self, state: &[f64]) {
        self.v_prev = state[0];
        self.v_trial = state[0];
    }
}
