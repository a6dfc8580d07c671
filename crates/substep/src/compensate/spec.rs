//! Descriptions of phase-lag compensation (for test definitions): which compensator, with which
//! parameters, and the ramp; built into a [`CompensatedSite`] around an experimental side.

use super::{
    AmbSpec, ArxPhaseLagSpec, AtsSpec, CompensatedSite, Guard, InverseFirSpec, PhaseLagCompensator, Polynomial, Ramp,
};
use crate::error::Result;
use crate::substructure::ExperimentalSubstructure;

/// One compensator kind with its parameters; one compensator per coupling DOF is built from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PhaseLagSpec {
    /// [`Polynomial`] extrapolation of order `order` (1..=3), `lead` sub-steps ahead, nodes
    /// `spacing` sub-steps apart, guard factor `guard_factor`.
    Polynomial {
        order: usize,
        lead: f64,
        spacing: usize,
        guard_factor: f64,
    },
    /// [`super::ArxPhaseLag`].
    Arx(ArxPhaseLagSpec),
    /// [`super::InverseFir`].
    InverseFir(InverseFirSpec),
    /// [`super::Ats`].
    Ats(AtsSpec),
    /// [`super::Amb`].
    Amb(AmbSpec),
}

impl PhaseLagSpec {
    /// `polynomial`, `arx`, `inverse_fir`, `ats` or `amb` (the config's `kind`).
    pub fn kind(&self) -> &'static str {
        match self {
            PhaseLagSpec::Polynomial { .. } => "polynomial",
            PhaseLagSpec::Arx(_) => "arx",
            PhaseLagSpec::InverseFir(_) => "inverse_fir",
            PhaseLagSpec::Ats(_) => "ats",
            PhaseLagSpec::Amb(_) => "amb",
        }
    }

    /// One compensator. Errors name `phase_lag.<key>`.
    pub fn build(&self) -> Result<Box<dyn PhaseLagCompensator>> {
        Ok(match *self {
            PhaseLagSpec::Polynomial {
                order,
                lead,
                spacing,
                guard_factor,
            } => Box::new(
                Polynomial::new(order, lead)?
                    .with_spacing(spacing)?
                    .with_guard(Guard::new(guard_factor, 1e-6)?),
            ),
            PhaseLagSpec::Arx(spec) => Box::new(spec.build()?),
            PhaseLagSpec::InverseFir(spec) => Box::new(spec.build()?),
            PhaseLagSpec::Ats(spec) => Box::new(spec.build()?),
            PhaseLagSpec::Amb(spec) => Box::new(spec.build()?),
        })
    }

    pub fn validate(&self) -> Result<()> {
        self.build().map(|_| ())
    }
}

/// Phase-lag compensation of every coupling DOF: the compensator and the ramp `h` (in sub-steps).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseLagDefinition {
    pub spec: PhaseLagSpec,
    pub ramp: Ramp,
}

impl PhaseLagDefinition {
    pub fn validate(&self) -> Result<()> {
        self.spec.validate()?;
        self.ramp.validate()
    }

    /// Wrap `inner` in a [`CompensatedSite`] with one compensator per coupling DOF.
    pub fn wrap(&self, inner: Box<dyn ExperimentalSubstructure>) -> Result<CompensatedSite> {
        let compensators = (0..inner.n_coupling())
            .map(|_| self.spec.build())
            .collect::<Result<Vec<_>>>()?;
        CompensatedSite::new(inner, compensators, self.ramp)
    }
}
