//! `[substructure]` (docs/config.md, section `[substructure]`): coupling DOFs, sub-steps, the
//! lab options and `[substructure.controller]`; builds the experimental substructure from the
//! specimen, actuator, sensor, compensation, remote and limits tables (their own files).

use super::actuator::RawActuator;
use super::common::{dof_index, prefixed};
use super::compensation::{RawErrorForce, RawPhaseLag};
use super::remote::{RawRemote, RemoteDefinition, RemoteProtocol};
use super::safety_limits::RawLimits;
use super::sensors::RawSensors;
use super::specimens::RawSpecimen;
use crate::compensate::PhaseLagDefinition;
use crate::error::{Error, Result};
use crate::integrate::Scheme;
use crate::limits::Limits;
use crate::model::{Model, ModelRef};
use crate::site::openfresco::OpenFrescoSite;
use crate::site::{Mode, RemoteSite, RemoteStepSite, RemoteStepTest};
use crate::specimen::SpecimenSpec;
use crate::substructure::{
    ErrorForceSpec, ExperimentalSubstructure, ExplicitController, LimitedSite, SafetyLimits, SubstepController,
    SubstepSettings, SubstructureTest,
};
use crate::substructure::{StabilityAction, StabilitySettings};
use crate::transfer::lti::TransferFunction;
use crate::transfer::{
    ActuatorSpec, ControlledSite, DelayRamp, DelayRampSite, Dynamics, LabOptions, SensorSpec, VirtualLab,
};
use nalgebra::DVector;
use serde::Deserialize;
use std::path::Path;

#[derive(Debug, Clone)]
pub struct SubstructureDefinition {
    /// Coupling DOFs of the numerical model, 0-based, distinct, in config order.
    pub coupling_dofs: Vec<usize>,
    /// Sub-steps per step `k_sub`.
    pub substeps: usize,
    /// Inner intervals per sub-step on which actuators and specimens are advanced.
    pub inner_steps: usize,
    /// Specimens attached to model DOFs (0-based).
    pub specimens: Vec<SpecimenSpec>,
    /// One actuator of this kind per coupling DOF.
    pub actuator: ActuatorSpec,
    /// One force and one displacement sensor per coupling DOF.
    pub force_sensors: Vec<SensorSpec>,
    pub displacement_sensors: Vec<SensorSpec>,
    pub error_force: ErrorForceSpec,
    /// Newmark β, γ of the integrator (average acceleration ¼, ½ for an explicit scheme: the
    /// β, γ of its converged Newton reference).
    pub beta: f64,
    pub gamma: f64,
    /// `Some(Scheme::Cr | Scheme::KrAlpha)`: the model-based explicit scheme drives the test
    /// ([`ExplicitController`], docs/theory.md §2.9) instead of the sub-step algorithm.
    pub explicit: Option<Scheme>,
    /// Phase-lag compensation of the actuators (`[substructure.phase_lag]`), if any.
    pub phase_lag: Option<PhaseLagDefinition>,
    /// A remote site instead of the virtual lab (the specimens, if any, then only feed the
    /// reference solution).
    pub remote: Option<RemoteDefinition>,
    /// A lab's real-time target instead of the virtual lab (`[substructure.lab]`); the
    /// specimens, actuator and sensors then describe what `substep lab emulate` runs and feed
    /// the reference.
    pub lab_target: Option<crate::lab::LabTargetSpec>,
    /// Safety limits with a controlled stop.
    pub limits: Option<SafetyLimits>,
    /// `[substructure.limits] stability = "off"`: no on-line stability indicator (see
    /// [`Self::stability_settings`]).
    pub stability_off: bool,
    /// `[substructure.delay_ramp]`: a growing extra command delay (virtual tests), if any.
    pub delay_ramp: Option<DelayRamp>,
    /// D/A converter on the commands and how the lab builds the force (`[substructure] force`).
    pub lab: LabOptions,
    /// Tracking controller `C(s)` (`[substructure.controller]`), Tustin-discretised at the
    /// sub-step length, between the (compensated) command and the actuator
    /// ([`ControlledSite`]).
    pub controller: Option<TransferFunction>,
    /// Its feedforward filter `F(s)` (`feedforward_num`, `feedforward_den`), if any.
    pub controller_feedforward: Option<TransferFunction>,
}

impl SubstructureDefinition {
    /// The on-line stability indicator of this test (docs/theory.md §15): the config's
    /// `[substructure.limits] stability`; without it the indicator still runs, with the default
    /// thresholds, to warn, or to stop (the controlled ramp-down) where safety limits are set;
    /// `None` for `stability = "off"`.
    pub fn stability_settings(&self) -> Option<StabilitySettings> {
        if self.stability_off {
            return None;
        }
        match &self.limits {
            None => Some(StabilitySettings::default()),
            Some(l) => Some(l.stability.clone().unwrap_or(StabilitySettings {
                action: StabilityAction::Stop,
                ..StabilitySettings::default()
            })),
        }
    }

    /// The experimental side for `controller`: the virtual lab or the remote site (per
    /// sub-step), wrapped in the safety limits when given.
    pub fn build_site(&self, controller: &SubstepController, dt: f64) -> Result<Box<dyn ExperimentalSubstructure>> {
        self.site_for(Some(controller), dt)
    }

    /// As [`build_site`](Self::build_site); `controller` is needed only by a per-sub-step
    /// `substep` site (it is told the controller's gains), which an explicit scheme refuses
    /// in the config.
    fn site_for(&self, controller: Option<&SubstepController>, dt: f64) -> Result<Box<dyn ExperimentalSubstructure>> {
        let n_c = self.coupling_dofs.len();
        let site: Box<dyn ExperimentalSubstructure> = match &self.remote {
            None if self.lab_target.is_some() => {
                let target = self.lab_target.as_ref().expect("checked");
                Box::new(crate::lab::LabTarget::connect(target, n_c)?)
            }
            None => Box::new(self.virtual_lab(dt)?),
            Some(r) => match (r.protocol, r.mode) {
                (RemoteProtocol::Substep, Mode::PerSubstep) => {
                    let controller = controller.ok_or_else(|| {
                        Error::invalid(
                            "substructure.remote.protocol",
                            "a substep site is told the sub-step algorithm's gains; with cr or kr_alpha use \
                             protocol = \"openfresco\"",
                        )
                    })?;
                    Box::new(RemoteSite::for_controller(
                        r.address.as_str(),
                        r.transport,
                        controller,
                        &r.client_options(),
                    )?)
                }
                (RemoteProtocol::OpenFresco, _) => {
                    Box::new(OpenFrescoSite::connect(r.address.as_str(), n_c, &r.client_options())?)
                }
                (RemoteProtocol::Substep, Mode::PerStep) => {
                    return Err(Error::invalid(
                        "substructure.remote.mode",
                        "per_step runs through build_remote_step_test (the site executes the sub-steps)",
                    ));
                }
            },
        };
        // A degrading transfer system (fault injection) belongs to the actuators themselves.
        let site: Box<dyn ExperimentalSubstructure> = match &self.delay_ramp {
            Some(r) => Box::new(DelayRampSite::new(site, *r, dt / self.substeps as f64)?),
            None => site,
        };
        // The limits sit next to the actuators: they check the command actually sent (after the
        // tracking controller and the phase-lag compensator), and their ramp to the safe
        // position bypasses both.
        let site: Box<dyn ExperimentalSubstructure> = match &self.limits {
            Some(l) => Box::new(LimitedSite::new(site, l.clone())?),
            None => site,
        };
        let site: Box<dyn ExperimentalSubstructure> = match &self.controller {
            None => site,
            Some(c) => Box::new(ControlledSite::new(
                site,
                "substructure.controller",
                c,
                self.controller_feedforward.as_ref(),
                dt / self.substeps as f64,
            )?),
        };
        let site: Box<dyn ExperimentalSubstructure> = match &self.phase_lag {
            None => site,
            Some(p) => Box::new(p.wrap(site).map_err(|e| prefixed(e, "substructure."))?),
        };
        Ok(site)
    }

    /// The virtual lab of this test (actuators, specimens, sensors) at time step `dt`.
    pub fn virtual_lab(&self, dt: f64) -> Result<VirtualLab> {
        let n_c = self.coupling_dofs.len();
        VirtualLab::from_specs_with(
            &self.coupling_dofs,
            &self.specimens,
            &vec![self.actuator.clone(); n_c],
            &self.force_sensors,
            &self.displacement_sensors,
            dt / self.substeps as f64,
            self.inner_steps,
            &self.lab,
        )
        .map_err(|e| prefixed(e, "substructure."))
    }

    /// A per-step remote test (`mode = "per_step"`): the site runs the sub-steps of each step.
    pub fn build_remote_step_test<'a>(
        &self,
        model: impl Into<ModelRef<'a>>,
        dt: f64,
        load0: &DVector<f64>,
    ) -> Result<RemoteStepTest> {
        let model = model.into();
        let r = self
            .remote
            .as_ref()
            .ok_or_else(|| Error::invalid("substructure.remote", "is required for a per-step remote test"))?;
        self.refuse_explicit()?;
        let controller = SubstepController::new(model, &self.settings(dt), load0)?;
        let site = RemoteStepSite::for_controller(r.address.as_str(), r.transport, &controller, &r.client_options())?;
        RemoteStepTest::new(model, controller, site)
    }

    /// The substructure test of this definition (controller + virtual lab) for `model` at
    /// rest, time step `dt` and initial load `load0`.
    pub fn build_test<'a>(
        &self,
        model: impl Into<ModelRef<'a>>,
        dt: f64,
        load0: &DVector<f64>,
    ) -> Result<SubstructureTest> {
        let model = model.into();
        self.refuse_explicit()?;
        let controller = SubstepController::new(model, &self.settings(dt), load0)?;
        let site = self.build_site(&controller, dt)?;
        SubstructureTest::new(model, controller, site)
    }

    /// The test of this definition with a model-based explicit scheme
    /// ([`Self::explicit`]): [`ExplicitController`] and the experimental side, for the dense
    /// `model` at rest with the numerical substructure's `springs` and initial load `load0`.
    pub fn build_explicit_test(
        &self,
        model: &crate::model::StructuralModel,
        dt: f64,
        springs: Option<crate::model::Springs>,
        load0: &DVector<f64>,
    ) -> Result<SubstructureTest<ExplicitController>> {
        let controller = self.explicit_controller(model, dt, springs, load0)?;
        let site = self.site_for(None, dt)?;
        SubstructureTest::new(model, controller, site)
    }

    /// The [`ExplicitController`] of [`Self::build_explicit_test`] alone (e.g. a throwaway one
    /// for the real-time budget probe).
    pub fn explicit_controller(
        &self,
        model: &crate::model::StructuralModel,
        dt: f64,
        springs: Option<crate::model::Springs>,
        load0: &DVector<f64>,
    ) -> Result<ExplicitController> {
        let scheme = match self.explicit {
            Some(Scheme::Cr) => crate::integrate::KrAlpha::cr(model, dt, springs, load0)?,
            Some(Scheme::KrAlpha { rho_inf }) => {
                crate::integrate::KrAlpha::with_rho_inf(model, dt, rho_inf, springs, load0)?
            }
            _ => {
                return Err(Error::invalid(
                    "integrator.scheme",
                    "an explicit substructure test needs scheme = \"cr\" or \"kr_alpha\"",
                ));
            }
        };
        ExplicitController::new(scheme, &self.coupling_dofs, self.substeps)
    }

    /// A cr / kr_alpha definition has no sub-step controller ([`Self::build_explicit_test`]).
    fn refuse_explicit(&self) -> Result<()> {
        match self.explicit {
            Some(_) => Err(Error::invalid(
                "integrator.scheme",
                "a cr or kr_alpha test runs through build_explicit_test, not the sub-step controller",
            )),
            None => Ok(()),
        }
    }

    /// Settings of the sub-step controller for time step `dt`.
    pub fn settings(&self, dt: f64) -> SubstepSettings {
        SubstepSettings {
            dt,
            beta: self.beta,
            gamma: self.gamma,
            substeps: self.substeps,
            coupling_dofs: self.coupling_dofs.clone(),
            error_force: self.error_force,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSubstructure {
    pub(crate) coupling_dofs: Vec<usize>,
    pub(crate) substeps: usize,
    pub(crate) inner_steps: Option<usize>,
    #[serde(default)]
    pub(crate) specimen: Vec<RawSpecimen>,
    pub(crate) actuator: Option<RawActuator>,
    pub(crate) sensors: Option<RawSensors>,
    pub(crate) error_force: Option<RawErrorForce>,
    pub(crate) phase_lag: Option<RawPhaseLag>,
    pub(crate) remote: Option<RawRemote>,
    pub(crate) lab: Option<super::lab_target::RawLabTarget>,
    pub(crate) limits: Option<RawLimits>,
    pub(crate) delay_ramp: Option<RawDelayRamp>,
    /// `"model"` (default) or `"from_motion"`.
    pub(crate) force: Option<String>,
    pub(crate) controller: Option<RawController>,
}

/// `[substructure.delay_ramp]`: an extra command delay growing from 0 at `start` to `delay` at
/// `end` (fault injection for virtual tests).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawDelayRamp {
    pub(crate) start: f64,
    pub(crate) end: f64,
    pub(crate) delay: f64,
}

/// `[substructure.controller]`: the tracking controller `C(s) = num/den` (descending powers of s).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawController {
    pub(crate) num: Vec<f64>,
    pub(crate) den: Vec<f64>,
    /// Feedforward `F(s)` on the command before the feedback.
    pub(crate) feedforward_num: Option<Vec<f64>>,
    pub(crate) feedforward_den: Option<Vec<f64>>,
}

impl RawSubstructure {
    pub(crate) fn build(
        &self,
        model: &Model,
        scheme_name: &str,
        scheme: Scheme,
        dt: f64,
        base: &Path,
        limits: &Limits,
    ) -> Result<SubstructureDefinition> {
        let p = "substructure.";
        let (beta, gamma, explicit) = match scheme {
            Scheme::Newmark { beta, gamma } if beta > 0.0 => (beta, gamma, None),
            // the model-based explicit schemes command the step's displacement directly
            Scheme::Cr | Scheme::KrAlpha { .. } => (0.25, 0.5, Some(scheme)),
            _ => {
                return Err(Error::invalid(
                    "integrator.scheme",
                    format!(
                        "the substructure algorithm needs an implicit Newmark scheme (beta > 0), cr or \
                         kr_alpha; '{scheme_name}' cannot be used with [substructure]"
                    ),
                ));
            }
        };
        let n = model.n_dofs();
        let key = format!("{p}coupling_dofs");
        if self.coupling_dofs.is_empty() {
            return Err(Error::invalid(key, "must list at least one DOF"));
        }
        let mut coupling = Vec::with_capacity(self.coupling_dofs.len());
        for &d in &self.coupling_dofs {
            let i = dof_index(&key, d, n)?;
            if coupling.contains(&i) {
                return Err(Error::invalid(key, format!("DOF {d} is listed twice")));
            }
            coupling.push(i);
        }
        if self.substeps == 0 {
            return Err(Error::invalid(format!("{p}substeps"), "must be at least 1"));
        }
        let remote = self.remote.as_ref().map(|r| r.build(base)).transpose()?;
        let lab_target = self.lab.as_ref().map(|l| l.build(&self.coupling_dofs)).transpose()?;
        if remote.is_some() && lab_target.is_some() {
            return Err(Error::invalid(
                format!("{p}lab"),
                "give either [substructure.remote] (a site) or [substructure.lab] (a lab target), not both",
            ));
        }
        if self.specimen.is_empty() && remote.is_none() && lab_target.is_none() {
            return Err(Error::invalid(
                format!("{p}specimen"),
                "no specimen given (add a [[substructure.specimen]] table)",
            ));
        }
        let mut specimens = Vec::with_capacity(self.specimen.len());
        let mut attached = vec![false; coupling.len()];
        for (k, raw) in self.specimen.iter().enumerate() {
            let what = format!("{p}specimen[{}]", k + 1);
            let spec = raw.to_spec_with(n, &what, base, limits)?;
            for dof in spec.dofs() {
                let Some(i) = coupling.iter().position(|&c| c == dof) else {
                    let key = if matches!(spec, SpecimenSpec::LinearSdof { .. }) {
                        "dof"
                    } else {
                        "dofs"
                    };
                    return Err(Error::invalid(
                        format!("{what}.{key}"),
                        format!("DOF {} is not one of substructure.coupling_dofs", dof + 1),
                    ));
                };
                attached[i] = true;
            }
            // Build once to check the specimen's own consistency (mass on attached DOFs, stability).
            spec.build().map_err(|e| match e {
                Error::InvalidInput { what: w, reason } | Error::Numerical { what: w, reason } => {
                    let rest = w.trim_start_matches("specimen");
                    Error::invalid(
                        format!(
                            "{what}{}",
                            if rest.starts_with('.') || rest.is_empty() {
                                rest.to_string()
                            } else {
                                format!(".{rest}")
                            }
                        ),
                        reason,
                    )
                }
                other => other,
            })?;
            specimens.push(spec);
        }
        if let Some(i) = attached.iter().position(|a| !a).filter(|_| remote.is_none()) {
            return Err(Error::invalid(
                key,
                format!("DOF {} has no specimen attached", coupling[i] + 1),
            ));
        }
        let actuator = match &self.actuator {
            Some(a) => a.spec().map_err(|e| prefixed(e, p))?,
            None => ActuatorSpec::ideal(),
        };
        actuator.validate().map_err(|e| prefixed(e, p))?;
        if actuator.needs_plant() {
            // The plant contains the specimen: one lumped_sdof alone at every coupling DOF.
            for &c in &coupling {
                let at: Vec<&SpecimenSpec> = specimens.iter().filter(|s| s.dofs().contains(&c)).collect();
                let ok = matches!(at.as_slice(), [SpecimenSpec::LumpedSdof { .. }]);
                if !ok && remote.is_none() {
                    return Err(Error::invalid(
                        format!("{p}actuator.kind"),
                        format!(
                            "a servo_hydraulic or hydraulic actuator needs exactly one lumped_sdof specimen at coupling DOF {} (its mass, damping and stiffness are part of the plant)",
                            c + 1
                        ),
                    ));
                }
            }
        }
        let force_from_motion = match self.force.as_deref().unwrap_or("model") {
            "model" => false,
            "from_motion" => {
                for &c in &coupling {
                    let at: Vec<&SpecimenSpec> = specimens.iter().filter(|s| s.dofs().contains(&c)).collect();
                    if !matches!(at.as_slice(), [s] if s.lumped_mck().is_some()) {
                        return Err(Error::invalid(
                            format!("{p}force"),
                            format!(
                                "from_motion needs exactly one lumped_sdof (or massless linear_sdof) specimen at coupling DOF {}",
                                c + 1
                            ),
                        ));
                    }
                }
                true
            }
            other => {
                return Err(Error::invalid(
                    format!("{p}force"),
                    format!("unknown '{other}' (expected model or from_motion)"),
                ));
            }
        };
        for spec in &specimens {
            if let SpecimenSpec::LumpedSdof { dof, .. } = spec
                && model.influence()[*dof] != 1.0
            {
                return Err(Error::invalid(
                    format!("{p}specimen"),
                    format!(
                        "a lumped_sdof specimen carries the earthquake load m·a_g and needs influence 1 at DOF {}",
                        dof + 1
                    ),
                ));
            }
        }
        // Refuse a bad or unstable controller now, with the sub-step length of the run.
        let controller_tf = |key: &str, num: &[f64], den: &[f64]| -> Result<TransferFunction> {
            if den.iter().all(|&v| v == 0.0) {
                return Err(Error::invalid(format!("{key}.den"), "is zero (no transfer function)"));
            }
            let tf = TransferFunction::new(key, num, den)?;
            crate::transfer::discrete::DiscreteFilter::tustin(key, &tf, dt / self.substeps as f64)?;
            Ok(tf)
        };
        let (controller, controller_feedforward) = match &self.controller {
            None => (None, None),
            Some(c) => {
                let key = format!("{p}controller");
                let fb = controller_tf(&key, &c.num, &c.den)?;
                let ff = match (&c.feedforward_num, &c.feedforward_den) {
                    (Some(num), Some(den)) => Some(controller_tf(&format!("{key}.feedforward"), num, den)?),
                    (None, None) => None,
                    (Some(_), None) => {
                        return Err(Error::invalid(
                            format!("{key}.feedforward_den"),
                            "is missing (feedforward_num is given)",
                        ));
                    }
                    (None, Some(_)) => {
                        return Err(Error::invalid(
                            format!("{key}.feedforward_num"),
                            "is missing (feedforward_den is given)",
                        ));
                    }
                };
                (Some(fb), ff)
            }
        };
        let inner_steps = match self.inner_steps {
            Some(0) => return Err(Error::invalid(format!("{p}inner_steps"), "must be at least 1")),
            Some(k) => k,
            None if actuator.dynamics == Dynamics::Ideal && actuator.delay == 0.0 => 1,
            None => 10,
        };
        let command_converter = match &self.sensors {
            Some(s) => s.command_converter()?,
            None => None,
        };
        if remote.is_some() {
            // These belong to the virtual lab, which a remote site replaces.
            let local = [
                ("force", force_from_motion),
                ("sensors.command_range", command_converter.is_some()),
            ];
            if let Some((key, _)) = local.iter().find(|(_, on)| *on) {
                return Err(Error::invalid(
                    format!("{p}{key}"),
                    "belongs to the virtual lab and is not used with [substructure.remote] (configure the site)",
                ));
            }
        }
        let (force_sensors, displacement_sensors) = match &self.sensors {
            Some(s) => s.specs(coupling.len())?,
            None => (
                vec![SensorSpec::ideal(); coupling.len()],
                vec![SensorSpec::ideal(); coupling.len()],
            ),
        };
        let error_force = self
            .error_force
            .as_ref()
            .map_or(ErrorForceSpec::None, RawErrorForce::spec);
        error_force.validate()?;
        if explicit.is_some() {
            if self.error_force.is_some() && error_force != ErrorForceSpec::None {
                return Err(Error::invalid(
                    format!("{p}error_force"),
                    format!(
                        "error-force compensation belongs to the sub-step algorithm; '{scheme_name}' commands the \
                         step's displacement directly and has none (remove [substructure.error_force])"
                    ),
                ));
            }
            if let Some(r) = &remote
                && r.protocol == RemoteProtocol::Substep
            {
                return Err(Error::invalid(
                    format!("{p}remote.protocol"),
                    format!(
                        "a substep site runs the sub-step algorithm's ramp; with '{scheme_name}' use protocol = \
                         \"openfresco\" (the site is sent each step's target)"
                    ),
                ));
            }
        }
        let phase_lag = match &self.phase_lag {
            Some(raw) => raw.build(dt, self.substeps, &actuator)?,
            None => None,
        };
        Ok(SubstructureDefinition {
            substeps: self.substeps,
            inner_steps,
            specimens,
            actuator,
            force_sensors,
            displacement_sensors,
            error_force,
            beta,
            gamma,
            explicit,
            limits: self
                .limits
                .as_ref()
                .map(|l| l.build(coupling.len(), dt / self.substeps as f64))
                .transpose()?,
            stability_off: self.limits.as_ref().is_some_and(RawLimits::stability_off),
            coupling_dofs: coupling,
            remote,
            lab_target,
            phase_lag,
            lab: LabOptions {
                command_converter,
                force_from_motion,
            },
            controller,
            controller_feedforward,
            delay_ramp: match &self.delay_ramp {
                None => None,
                Some(r) => {
                    let ramp = DelayRamp {
                        start: r.start,
                        end: r.end,
                        delay: r.delay,
                    };
                    ramp.validate(dt / self.substeps as f64)?;
                    Some(ramp)
                }
            },
        })
    }
}
