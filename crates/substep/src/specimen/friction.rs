//! Friction damper on one coupling DOF: Coulomb friction with slip force `F_s`, plus an optional
//! linear viscous part `c`.
//!
//! Two models (forces on the structure, sign of docs/theory.md §1.2):
//!
//! * `stick_slip` (default in configs): an elasto-plastic spring — elastic pre-slip stiffness `k`,
//!   slip at `|q| = F_s`. With the slip displacement `u_p`, `q = k (u − u_p)`, `|q| ≤ F_s`, and
//!   `f = −q − c u̇`. The update is the exact return mapping at the end of the interval (the model
//!   is rate independent and the displacement is monotone within an interval, so this is exact):
//!   `q_tr = k (u₁ − u_p)`; if `|q_tr| > F_s` then `u_p ← u₁ − F_s sgn(q_tr) / k`, `q = F_s sgn(q_tr)`.
//!   Under a cycle of amplitude `U > F_s/k` the loop is a parallelogram dissipating
//!   `4 F_s (U − F_s/k)`.
//! * `smooth`: `f = −F_s tanh(u̇ / v_ref) − c u̇`, stateless, with `u̇` the interval's (constant)
//!   velocity.

use super::{Motion, Specimen};
use crate::error::{Result, require_non_negative, require_positive};

/// Which friction law.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrictionModel {
    /// Elasto-plastic (stick–slip) with pre-slip stiffness `stiffness` [N/m].
    StickSlip { stiffness: f64 },
    /// `F_s tanh(u̇ / v_ref)` with reference velocity `v_ref` [m/s].
    Smooth { v_ref: f64 },
}

impl FrictionModel {
    /// Name as in configs (`stick_slip`, `smooth`).
    pub fn name(&self) -> &'static str {
        match self {
            FrictionModel::StickSlip { .. } => "stick_slip",
            FrictionModel::Smooth { .. } => "smooth",
        }
    }
}

pub struct Friction {
    slip_force: f64,
    model: FrictionModel,
    damping: f64,
    /// Committed / trial slip displacement `u_p` [m] (stick–slip only).
    u_p: f64,
    u_p_trial: f64,
}

impl Friction {
    /// `slip_force` `F_s ≥ 0` \[N\], `damping` `c ≥ 0` [N s/m].
    pub fn new(slip_force: f64, model: FrictionModel, damping: f64) -> Result<Self> {
        require_non_negative("specimen.slip_force", slip_force)?;
        match model {
            FrictionModel::StickSlip { stiffness } => {
                require_positive("specimen.stiffness", stiffness)?;
            }
            FrictionModel::Smooth { v_ref } => {
                require_positive("specimen.v_ref", v_ref)?;
            }
        }
        require_non_negative("specimen.damping", damping)?;
        Ok(Self {
            slip_force,
            model,
            damping,
            u_p: 0.0,
            u_p_trial: 0.0,
        })
    }

    pub fn model(&self) -> FrictionModel {
        self.model
    }

    pub fn slip_force(&self) -> f64 {
        self.slip_force
    }

    /// Committed slip displacement `u_p` \[m\] (0 for the smooth model).
    pub fn slip(&self) -> f64 {
        self.u_p
    }
}

impl Specimen for Friction {
    fn kind(&self) -> &'static str {
        "friction"
    }
    fn n_dofs(&self) -> usize {
        1
    }
    fn advance(&mut self, m: &Motion, force: &mut [f64]) {
        let u0 = m.d_start.first().copied().unwrap_or(0.0);
        let u1 = m.d_end.first().copied().unwrap_or(0.0);
        let v = if m.dt > 0.0 { (u1 - u0) / m.dt } else { 0.0 };
        let fs = self.slip_force;
        let q = match self.model {
            FrictionModel::StickSlip { stiffness } => {
                let q_tr = stiffness * (u1 - self.u_p);
                if q_tr.abs() > fs {
                    let q = fs.copysign(q_tr);
                    self.u_p_trial = u1 - q / stiffness;
                    q
                } else {
                    self.u_p_trial = self.u_p;
                    q_tr
                }
            }
            FrictionModel::Smooth { v_ref } => fs * (v / v_ref).tanh(),
        };
        if let Some(out) = force.first_mut() {
            *out = -q - self.damping * v;
        }
    }
    fn commit(&mut self) {
        self.u_p = self.u_p_trial;
    }
    fn is_linear(&self) -> bool {
        false
    }
    fn state_len(&self) -> usize {
        match self.model {
            FrictionModel::StickSlip { .. } => 1,
            FrictionModel::Smooth { .. } => 0,
        }
    }
    fn write_state(&self, out: &mut [f64]) {
        if let FrictionModel::StickSlip { .. } = self.model {
            out[0] = self.u_p;
        }
    }
    fn read_state(&mut self, state: &[f64]) {
        if let FrictionModel::StickSlip { .. } = self.model {
            self.u_p = state[0];
            self.u_p_trial = state[0];
        }
    }
}
