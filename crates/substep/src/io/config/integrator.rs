//! `[integrator]` (docs/config.md, section `[integrator]`): scheme, time step, duration.

use super::common::forbid;
use crate::error::{Error, Result, require_non_negative, require_positive};
use crate::integrate::{NewtonSettings, Scheme, check_hilber_alpha, check_rho_inf};

/// KR-α's `ρ∞` when the config gives none (Kolay & Ricles' recommended range is 0.5–1).
pub const DEFAULT_RHO_INF: f64 = 0.5;
use serde::Deserialize;

#[derive(Debug, Clone)]
pub struct IntegratorDefinition {
    /// The scheme name as given in the config (e.g. `average_acceleration`).
    pub name: String,
    pub scheme: Scheme,
    /// Time step \[s\].
    pub dt: f64,
    /// Number of steps; the run covers `t = 0 ..= steps·dt`.
    pub steps: usize,
    /// Newton–Raphson of the implicit Newmark schemes on a nonlinear model.
    pub newton: NewtonSettings,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawIntegrator {
    #[serde(default = "default_scheme")]
    pub(crate) scheme: String,
    pub(crate) beta: Option<f64>,
    pub(crate) gamma: Option<f64>,
    pub(crate) alpha: Option<f64>,
    /// KR-α's spectral radius at infinite frequency.
    pub(crate) rho_inf: Option<f64>,
    pub(crate) dt: f64,
    pub(crate) duration: Option<f64>,
    pub(crate) tolerance: Option<f64>,
    pub(crate) max_iterations: Option<usize>,
}

pub(crate) fn default_scheme() -> String {
    "newmark".into()
}

impl RawIntegrator {
    /// `[integrator] tolerance` and `max_iterations`.
    pub(crate) fn newton(&self) -> Result<NewtonSettings> {
        let mut n = NewtonSettings::default();
        if let Some(t) = self.tolerance {
            if !(t.is_finite() && t > 0.0 && t < 1.0) {
                return Err(Error::invalid(
                    "integrator.tolerance",
                    format!(
                        "must lie in (0, 1) (the Newton tolerance on the displacement increment, relative), got {t}"
                    ),
                ));
            }
            n.tolerance = t;
        }
        if let Some(m) = self.max_iterations {
            if !(1..=1000).contains(&m) {
                return Err(Error::invalid(
                    "integrator.max_iterations",
                    format!("must lie in 1..=1000 (Newton iterations per step), got {m}"),
                ));
            }
            n.max_iterations = m;
        }
        Ok(n)
    }

    /// Refuse a scheme that cannot integrate a nonlinear model.
    pub(crate) fn check_nonlinear(&self, scheme: Scheme) -> Result<()> {
        match scheme {
            Scheme::Newmark { beta, .. } if beta > 0.0 => Ok(()),
            Scheme::AlphaOs { .. } | Scheme::AlphaOsTp { .. } | Scheme::Cr | Scheme::KrAlpha { .. } => Ok(()),
            _ => Err(Error::invalid(
                "integrator.scheme",
                format!(
                    "\"{}\" cannot integrate a nonlinear model ([structure.storeys.hysteresis]): use an implicit \
                     Newmark scheme (e.g. average_acceleration, solved by Newton–Raphson), alpha_os, cr or kr_alpha",
                    self.scheme
                ),
            )),
        }
    }

    /// `(name, scheme, dt, duration)`.
    pub(crate) fn build(&self) -> Result<(String, Scheme, f64, Option<f64>)> {
        let dt = require_positive("integrator.dt", self.dt)?;
        if let Some(d) = self.duration {
            require_positive("integrator.duration", d)?;
        }
        let name = self.scheme.as_str();
        let is_newmark = name == "newmark";
        let is_alpha = matches!(name, "hht" | "alpha_os" | "alpha_os_tp");
        if !is_newmark {
            forbid(
                "integrator.",
                &[("beta", self.beta.is_some()), ("gamma", self.gamma.is_some())],
                &format!("only used with scheme = \"newmark\" (scheme \"{name}\" fixes its own parameters)"),
            )?;
        }
        if !is_alpha && self.alpha.is_some() {
            return Err(Error::invalid(
                "integrator.alpha",
                format!("only used with scheme = \"hht\" or \"alpha_os\", not \"{name}\""),
            ));
        }
        if name != "kr_alpha" && self.rho_inf.is_some() {
            return Err(Error::invalid(
                "integrator.rho_inf",
                format!("only used with scheme = \"kr_alpha\", not \"{name}\""),
            ));
        }
        let beta = self.beta.unwrap_or(0.25);
        let gamma = self.gamma.unwrap_or(0.5);
        if is_newmark {
            require_non_negative("integrator.beta", beta)?;
            require_non_negative("integrator.gamma", gamma)?;
        }
        let scheme = Scheme::from_name(
            name,
            beta,
            gamma,
            self.alpha.unwrap_or(-0.1),
            self.rho_inf.unwrap_or(DEFAULT_RHO_INF),
        )?;
        if let Scheme::KrAlpha { rho_inf } = scheme {
            check_rho_inf(rho_inf)?;
        }
        if let Scheme::Hht { alpha } | Scheme::AlphaOs { alpha } | Scheme::AlphaOsTp { alpha } = scheme {
            check_hilber_alpha(alpha)?;
        }
        Ok((name.to_string(), scheme, dt, self.duration))
    }
}
