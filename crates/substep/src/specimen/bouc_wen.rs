//! Bouc–Wen hysteretic spring on one coupling DOF, with optional Baber–Wen degradation and
//! Baber–Noori pinching, plus a linear dashpot.
//!
//! Force on the structure (sign of docs/theory.md §1.2: a spring to ground pulls back):
//!
//! ```text
//! f = −(α k u + (1 − α) k z) − c u̇
//! ```
//!
//! The spring is the material [`BoucWenMaterial`], moved along each interval's straight path
//! from its committed state; the equations, the parameters and the integration of `z` are
//! documented in `material/bouc_wen.rs` ([`crate::material::BoucWenMaterial`]). `c` is
//! [`BoucWenParams::damping`], `u̇` the interval's mean velocity `(u₁ − u₀) / dt`.

use super::{Motion, Specimen};
use crate::error::Result;
use crate::material::{BoucWenMaterial, Material};

pub use crate::material::{BoucWenParams, Pinching};

pub struct BoucWen {
    spring: BoucWenMaterial,
    damping: f64,
}

impl BoucWen {
    pub fn new(params: &BoucWenParams) -> Result<Self> {
        Ok(Self {
            spring: BoucWenMaterial::new(params)?,
            damping: params.damping,
        })
    }

    pub fn params(&self) -> &BoucWenParams {
        self.spring.params()
    }

    /// The hysteretic spring.
    pub fn material(&self) -> &BoucWenMaterial {
        &self.spring
    }

    /// Committed hysteretic displacement `z` \[m\].
    pub fn z(&self) -> f64 {
        self.spring.z()
    }

    /// Committed normalised hysteretic energy `ε = ∫ z du / u_y²`.
    pub fn normalised_energy(&self) -> f64 {
        self.spring.normalised_energy()
    }

    /// Committed hysteretic energy `E_h = (1 − α) k u_y² ε` \[J\] (excludes the viscous part).
    pub fn hysteretic_energy(&self) -> f64 {
        self.spring.hysteretic_energy()
    }
}

impl Specimen for BoucWen {
    fn kind(&self) -> &'static str {
        "bouc_wen"
    }
    fn n_dofs(&self) -> usize {
        1
    }
    fn advance(&mut self, m: &Motion, force: &mut [f64]) {
        let u0 = m.d_start.first().copied().unwrap_or(0.0);
        let u1 = m.d_end.first().copied().unwrap_or(0.0);
        let du = u1 - u0;
        self.spring.set_trial_path(u0, u1);
        let v = if m.dt > 0.0 && du.is_finite() { du / m.dt } else { 0.0 };
        let f = -self.spring.force() - self.damping * v;
        if let Some(out) = force.first_mut() {
            *out = f;
        }
    }
    fn commit(&mut self) {
        self.spring.commit();
    }
    fn is_linear(&self) -> bool {
        false
    }
    /// `[z, ε]`.
    fn state_len(&self) -> usize {
        2
    }
    fn write_state(&self, out: &mut [f64]) {
        out[0] = self.spring.z();
        out[1] = self.spring.normalised_energy();
    }
    fn read_state(&mut self, state: &[f64]) {
        // The material's deformation and direction do not matter here (each interval passes
        // its start); keep them and set z and ε.
        let mut s = [0.0; 4];
        self.spring.write_state(&mut s);
        (s[1], s[2]) = (state[0], state[1]);
        self.spring.read_state(&s);
    }
}
