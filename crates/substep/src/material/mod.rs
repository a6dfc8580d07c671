//! Hysteretic uniaxial materials, shared by the nonlinear numerical models (storey springs,
//! hinges) and the specimens.
//!
//! A material maps a deformation `δ` (a storey drift in m, a hinge rotation in rad) to a force
//! `F(δ)` (N, or N·m for a rotation) along a path: the **committed** state is the state at the
//! end of the last accepted step; [`Material::set_trial`] moves from it to a trial deformation
//! (the path between them is taken as monotone, i.e. linear in time) and may be called any
//! number of times (Newton iterations, sub-steps) before [`Material::commit`] accepts the last
//! trial or [`Material::revert`] drops it. The tangent `dF/dδ` of the trial state is available
//! for Newton–Raphson.
//!
//! Laws (docs/theory.md §14.1):
//!
//! * [`Elastic`]: `F = k δ`.
//! * [`Bilinear`]: kinematic hardening between the bounds `F = b k δ ± (1 − b) F_y`
//!   (OpenSees `Steel01` without isotropic hardening): the elastic trial
//!   `F_tr = F_n + k (δ − δ_n)` clamped into `[b k δ − (1 − b) F_y, b k δ + (1 − b) F_y]`;
//!   tangent `k` inside, `b k` on a bound.
//! * elastic–perfectly plastic: [`Bilinear`] with `b = 0` (OpenSees `ElasticPP`).
//! * [`BoucWenMaterial`]: Bouc–Wen, `F = α k δ + (1 − α) k z` with the hysteretic displacement
//!   `z` (Baber–Wen degradation and Baber–Noori pinching optional), integrated accurately along
//!   the straight path of each trial move; the spring of the `bouc_wen` specimen
//!   ([`crate::specimen::BoucWen`]). Parameters [`BoucWenParams`], [`Pinching`].
//!
//! A new law is one implementation of [`Material`] plus one arm of [`MaterialSpec`]. The
//! trial/commit calls never allocate.

mod bouc_wen;

pub use bouc_wen::{BoucWenMaterial, BoucWenParams, Pinching};

use crate::error::{Error, Result, require_positive};

/// A rate-independent uniaxial force–deformation law with committed and trial states.
pub trait Material: Send {
    /// Short name as in configs (`elastic`, `bilinear`, ...).
    fn kind(&self) -> &'static str;
    /// Move from the committed state to the trial deformation `deformation`.
    fn set_trial(&mut self, deformation: f64);
    /// Force of the trial state.
    fn force(&self) -> f64;
    /// Tangent `dF/dδ` of the trial state.
    fn tangent(&self) -> f64;
    /// Tangent at zero deformation of the virgin material (the initial stiffness).
    fn initial_tangent(&self) -> f64;
    /// Accept the trial state.
    fn commit(&mut self);
    /// Drop the trial state (back to the committed one).
    fn revert(&mut self);
    /// A fresh copy in the virgin state.
    fn fresh(&self) -> Box<dyn Material>;
    /// Length of the committed state vector (checkpoints).
    fn state_len(&self) -> usize;
    fn write_state(&self, out: &mut [f64]);
    fn read_state(&mut self, state: &[f64]);
}

/// `F = k δ`.
#[derive(Debug, Clone)]
pub struct Elastic {
    stiffness: f64,
    trial: f64,
    /// Committed deformation (for `revert`; not part of the state vector, the force does not
    /// depend on the history).
    committed: f64,
}

impl Elastic {
    pub fn new(stiffness: f64) -> Result<Self> {
        require_positive("material.stiffness", stiffness)?;
        Ok(Self {
            stiffness,
            trial: 0.0,
            committed: 0.0,
        })
    }
}

impl Elastic {
    /// As [`Elastic::new`], also for a zero stiffness (a fully yielded state).
    pub fn new_or_zero(stiffness: f64) -> Result<Self> {
        crate::error::require_non_negative("material.stiffness", stiffness)?;
        Ok(Self {
            stiffness,
            trial: 0.0,
            committed: 0.0,
        })
    }
}

impl Material for Elastic {
    fn kind(&self) -> &'static str {
        "elastic"
    }
    fn set_trial(&mut self, deformation: f64) {
        self.trial = deformation;
    }
    fn force(&self) -> f64 {
        self.stiffness * self.trial
    }
    fn tangent(&self) -> f64 {
        self.stiffness
    }
    fn initial_tangent(&self) -> f64 {
        self.stiffness
    }
    fn commit(&mut self) {
        self.committed = self.trial;
    }
    fn revert(&mut self) {
        self.trial = self.committed;
    }
    fn fresh(&self) -> Box<dyn Material> {
        Box::new(Self::new_or_zero(self.stiffness).expect("validated"))
    }
    fn state_len(&self) -> usize {
        0
    }
    fn write_state(&self, _: &mut [f64]) {}
    fn read_state(&mut self, _: &[f64]) {}
}

/// Bilinear kinematic hardening (`b = 0`: elastic–perfectly plastic).
#[derive(Debug, Clone)]
pub struct Bilinear {
    stiffness: f64,
    yield_force: f64,
    hardening: f64,
    /// Committed deformation and force.
    deformation: f64,
    committed_force: f64,
    /// Trial deformation, force and tangent.
    trial_deformation: f64,
    trial_force: f64,
    trial_tangent: f64,
}

impl Bilinear {
    /// Initial stiffness `k` \[N/m\], yield force `F_y` \[N\], hardening ratio `b ∈ [0, 1)`.
    pub fn new(stiffness: f64, yield_force: f64, hardening: f64) -> Result<Self> {
        require_positive("material.stiffness", stiffness)?;
        require_positive("material.yield_force", yield_force)?;
        check_hardening("material.hardening", hardening)?;
        Ok(Self {
            stiffness,
            yield_force,
            hardening,
            deformation: 0.0,
            committed_force: 0.0,
            trial_deformation: 0.0,
            trial_force: 0.0,
            trial_tangent: stiffness,
        })
    }
    pub fn yield_force(&self) -> f64 {
        self.yield_force
    }
    pub fn hardening(&self) -> f64 {
        self.hardening
    }
}

/// A hardening ratio must lie in `[0, 1)`.
pub fn check_hardening(what: &str, hardening: f64) -> Result<()> {
    if !(hardening.is_finite() && (0.0..1.0).contains(&hardening)) {
        return Err(Error::invalid(
            what,
            format!("must lie in [0, 1) (post-yield over initial stiffness), got {hardening}"),
        ));
    }
    Ok(())
}

impl Material for Bilinear {
    fn kind(&self) -> &'static str {
        if self.hardening == 0.0 {
            "elastic_plastic"
        } else {
            "bilinear"
        }
    }
    fn set_trial(&mut self, deformation: f64) {
        let (k, b) = (self.stiffness, self.hardening);
        let elastic = self.committed_force + k * (deformation - self.deformation);
        let half_width = (1.0 - b) * self.yield_force;
        let centre = b * k * deformation;
        self.trial_deformation = deformation;
        if elastic > centre + half_width {
            self.trial_force = centre + half_width;
            self.trial_tangent = b * k;
        } else if elastic < centre - half_width {
            self.trial_force = centre - half_width;
            self.trial_tangent = b * k;
        } else {
            self.trial_force = elastic;
            self.trial_tangent = k;
        }
    }
    fn force(&self) -> f64 {
        self.trial_force
    }
    fn tangent(&self) -> f64 {
        self.trial_tangent
    }
    fn initial_tangent(&self) -> f64 {
        self.stiffness
    }
    fn commit(&mut self) {
        self.deformation = self.trial_deformation;
        self.committed_force = self.trial_force;
    }
    fn revert(&mut self) {
        self.trial_deformation = self.deformation;
        self.trial_force = self.committed_force;
        self.trial_tangent = self.stiffness;
    }
    fn fresh(&self) -> Box<dyn Material> {
        Box::new(Self::new(self.stiffness, self.yield_force, self.hardening).expect("validated"))
    }
    fn state_len(&self) -> usize {
        2
    }
    fn write_state(&self, out: &mut [f64]) {
        out[0] = self.deformation;
        out[1] = self.committed_force;
    }
    fn read_state(&mut self, state: &[f64]) {
        self.deformation = state[0];
        self.committed_force = state[1];
        self.revert();
    }
}

/// A hysteresis law by name and parameters, without its initial stiffness (which comes from
/// the element it sits in, e.g. a storey's `stiffness`).
#[derive(Debug, Clone, PartialEq)]
pub enum MaterialSpec {
    Elastic,
    /// Bilinear kinematic hardening; `hardening = 0` is elastic–perfectly plastic.
    Bilinear {
        yield_force: f64,
        hardening: f64,
    },
    /// Bouc–Wen; `build` replaces `stiffness` by the element's stiffness and keeps
    /// `yield_displacement` (and the shape, degradation and pinching parameters). `damping` must
    /// be 0: a material is the spring alone.
    BoucWen(Box<BoucWenParams>),
    /// Linear with `ratio` times the element's stiffness: a spring frozen in a yielded
    /// (`ratio < 1`) or hardened (`> 1`) state, for the stability analysis of the splitting
    /// (its deviation force is `(ratio − 1) k δ`).
    Scaled {
        ratio: f64,
    },
}

impl MaterialSpec {
    pub fn kind(&self) -> &'static str {
        match self {
            MaterialSpec::Elastic => "elastic",
            MaterialSpec::Bilinear { hardening, .. } if *hardening == 0.0 => "elastic_plastic",
            MaterialSpec::Bilinear { .. } => "bilinear",
            MaterialSpec::Scaled { .. } => "elastic",
            MaterialSpec::BoucWen(_) => "bouc_wen",
        }
    }

    /// The material with initial stiffness `stiffness`; `what` names the config item in errors.
    pub fn build(&self, stiffness: f64, what: &str) -> Result<Box<dyn Material>> {
        let named = |e: Error| match e {
            Error::InvalidInput { what: w, reason } => {
                let key = w
                    .strip_prefix("material.")
                    .or_else(|| w.strip_prefix("specimen."))
                    .unwrap_or(&w);
                Error::invalid(format!("{what}.{key}"), reason)
            }
            other => other,
        };
        Ok(match self {
            MaterialSpec::Elastic => Box::new(Elastic::new(stiffness).map_err(named)?),
            MaterialSpec::Scaled { ratio } => {
                crate::error::require_non_negative(&format!("{what}.ratio"), *ratio)?;
                Box::new(Elastic::new_or_zero(stiffness * ratio).map_err(named)?)
            }
            MaterialSpec::Bilinear { yield_force, hardening } => {
                Box::new(Bilinear::new(stiffness, *yield_force, *hardening).map_err(named)?)
            }
            MaterialSpec::BoucWen(params) => {
                if params.damping != 0.0 {
                    return Err(Error::invalid(
                        format!("{what}.damping"),
                        format!(
                            "must be 0 for a material (the Bouc–Wen material is the spring alone), got {}",
                            params.damping
                        ),
                    ));
                }
                let params = BoucWenParams { stiffness, ..**params };
                Box::new(BoucWenMaterial::new(&params).map_err(named)?)
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_follows_the_kinematic_bounds_through_a_cycle() {
        // k = 100, F_y = 10 (δ_y = 0.1), b = 0.1: hardening slope 10.
        let mut m = Bilinear::new(100.0, 10.0, 0.1).unwrap();
        let mut at = |d: f64| {
            m.set_trial(d);
            m.commit();
            (m.force(), m.tangent())
        };
        assert_eq!(at(0.05), (5.0, 100.0));
        // loading past yield: F = 10 + 10 (0.3 − 0.1) = 12
        let (f, t) = at(0.3);
        assert!((f - 12.0).abs() < 1e-12 && t == 10.0);
        // unloading elastically by 2 F_y (20): from 12 down to −8 at δ = 0.1
        let (f, t) = at(0.1);
        assert!((f + 8.0).abs() < 1e-12 && t == 100.0, "{f}");
        // further: lower bound b k δ − (1 − b) F_y = 10 δ − 9; at δ = −0.2: −11
        let (f, t) = at(-0.2);
        assert!((f + 11.0).abs() < 1e-12 && t == 10.0, "{f}");
    }

    #[test]
    fn trial_states_do_not_move_the_committed_one() {
        let mut m = Bilinear::new(100.0, 10.0, 0.0).unwrap();
        m.set_trial(1.0);
        assert_eq!(m.force(), 10.0);
        m.revert();
        m.set_trial(0.01);
        assert!((m.force() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn bad_parameters_are_named() {
        let e = MaterialSpec::Bilinear {
            yield_force: -1.0,
            hardening: 0.0,
        }
        .build(1.0, "structure.storeys.hysteresis")
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("structure.storeys.hysteresis.yield_force"), "{e}");
        let e = MaterialSpec::Bilinear {
            yield_force: 1.0,
            hardening: 1.0,
        }
        .build(1.0, "x")
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("x.hardening") && e.contains("[0, 1)"), "{e}");
    }
}
