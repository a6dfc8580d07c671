//! Test definitions in TOML (the keys are documented in `docs/config.md`).
//!
//! [`TestDefinition::from_file`] / [`TestDefinition::from_toml`] read a config into a validated
//! [`TestDefinition`]: the numerical model, the ground acceleration at the step times, the
//! integrator, the optional substructure part and the output settings. Parsing happens in two
//! stages: serde reads the text into `Raw*` structs that mirror the file (unknown keys are
//! errors), then `build` checks values and relations between keys and produces library types.
//!
//! Messages are one line. Syntax and type errors name the file and line
//! (`test.toml: line 7: unknown field `foo`, expected ...`); validation errors name the file and
//! the key path (`test.toml: substructure.coupling_dofs: DOF 7 is out of range (the model has
//! DOFs 1..=3)`). DOF numbers in configs are 1-based; the definition holds them 0-based.
//!
//! Relative file paths (matrices, records) are resolved against the config file's directory.
//! The output directory is left as given (relative to the working directory of the run).
//!
//! To add a specimen kind: add a variant to `RawSpecimen` (its keys are the variant's fields)
//! and one arm to `RawSpecimen::to_spec`.

use super::limits::{self, Limits, RunShape};
use super::matrix_market::{read_matrix_market_sparse_with, read_matrix_market_with};
use crate::compensate::{ArxPhaseLagSpec, InverseFirSpec, PhaseLagDefinition, PhaseLagSpec, Ramp};
use crate::error::{Error, Result, require_non_negative, require_positive};
use crate::excitation::{self, Envelope, KanaiTajimi, Record};
use crate::integrate::{Scheme, check_hilber_alpha};
use crate::model::{
    DENSE_MAX_DOFS, DampingSpec, Frame2d, Model, ModelRef, Section, ShearBuilding, SparseModel, Storage,
    StructuralModel, TmdSystem, frame_2d, sdof, shear_building_sparse, tmd_two_dof,
};
use crate::site::openfresco::OpenFrescoSite;
use crate::site::{ClientOptions, Mode, RemoteSite, RemoteStepSite, RemoteStepTest, Secret, Transport};
use crate::sparse::CscMatrix;
use crate::specimen::{BoucWenParams, FrictionModel, Pinching, SpecimenSpec};
use crate::substructure::{
    ErrorForceSpec, ExperimentalSubstructure, LimitedSite, SafetyLimits, SubstepController, SubstepSettings,
    SubstructureTest,
};
use crate::transfer::converter::Converter;
use crate::transfer::lti::{StateSpace, TransferFunction};
use crate::transfer::noise::BENCHMARK_SEED;
use crate::transfer::servo::Derivative;
use crate::transfer::{
    ActuatorSpec, ControlledSite, Dynamics, LabOptions, NoiseGenerator, SensorSpec, ServoSpec, VirtualLab,
    channel_seed_for,
};
use nalgebra::{DMatrix, DVector};
use serde::Deserialize;
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A validated test definition.
#[derive(Debug, Clone)]
pub struct TestDefinition {
    /// Where the definition came from (the config path, or a name for embedded text).
    pub source: String,
    /// The numerical substructure (with a `[substructure]`, the specimens are not in it), in
    /// dense or sparse storage (`[structure] storage`).
    pub model: Model,
    pub ground_motion: GroundMotion,
    pub integrator: IntegratorDefinition,
    pub substructure: Option<SubstructureDefinition>,
    pub output: OutputSettings,
}

/// Ground acceleration at the step times.
#[derive(Debug, Clone)]
pub struct GroundMotion {
    /// `a_g(t_i)`, `t_i = i·dt`, `i = 0..=steps` [m/s²].
    pub accel: Vec<f64>,
    /// Short human description (source, scale).
    pub description: String,
}

#[derive(Debug, Clone)]
pub struct IntegratorDefinition {
    /// The scheme name as given in the config (e.g. `average_acceleration`).
    pub name: String,
    pub scheme: Scheme,
    /// Time step \[s\].
    pub dt: f64,
    /// Number of steps; the run covers `t = 0 ..= steps·dt`.
    pub steps: usize,
}

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
    /// Newmark β, γ of the integrator.
    pub beta: f64,
    pub gamma: f64,
    /// Phase-lag compensation of the actuators (`[substructure.phase_lag]`), if any.
    pub phase_lag: Option<PhaseLagDefinition>,
    /// A remote site instead of the virtual lab (the specimens, if any, then only feed the
    /// reference solution).
    pub remote: Option<RemoteDefinition>,
    /// Safety limits with a controlled stop.
    pub limits: Option<SafetyLimits>,
    /// D/A converter on the commands and how the lab builds the force (`[substructure] force`).
    pub lab: LabOptions,
    /// Tracking controller `C(s)` (`[substructure.controller]`), Tustin-discretised at the
    /// sub-step length, between the (compensated) command and the actuator
    /// ([`ControlledSite`]).
    pub controller: Option<TransferFunction>,
    /// Its feedforward filter `F(s)` (`feedforward_num`, `feedforward_den`), if any.
    pub controller_feedforward: Option<TransferFunction>,
}

/// Protocol of a remote site.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RemoteProtocol {
    /// The project's own protocol (`substep site serve` with `protocol = "substep"`).
    Substep,
    /// OpenFresco's generic TCP protocol (e.g. an `ECGenericTCP`-style site, or
    /// `substep site serve` with `protocol = "openfresco"`).
    OpenFresco,
}

#[derive(Debug, Clone, PartialEq)]
pub struct RemoteDefinition {
    pub address: String,
    pub protocol: RemoteProtocol,
    pub transport: Transport,
    pub mode: Mode,
    /// Reply timeout \[s\] (checked: at most `MAX_DURATION_SECS`).
    pub timeout: f64,
    /// The site's shared secret (`secret_file`, else `SUBSTEP_SITE_SECRET`).
    pub secret: Option<Secret>,
}

impl RemoteDefinition {
    pub fn client_options(&self) -> ClientOptions {
        // `timeout` was checked by `require_duration` when the config was read.
        let t = Duration::from_secs_f64(self.timeout.clamp(1e-6, crate::error::MAX_DURATION_SECS));
        ClientOptions {
            timeout: t,
            connect_timeout: t,
            secret: self.secret.clone(),
            ..ClientOptions::default()
        }
    }
}

impl SubstructureDefinition {
    /// The experimental side for `controller`: the virtual lab or the remote site (per
    /// sub-step), wrapped in the safety limits when given.
    pub fn build_site(&self, controller: &SubstepController, dt: f64) -> Result<Box<dyn ExperimentalSubstructure>> {
        let n_c = self.coupling_dofs.len();
        let site: Box<dyn ExperimentalSubstructure> = match &self.remote {
            None => Box::new(
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
                .map_err(|e| prefixed(e, "substructure."))?,
            ),
            Some(r) => match (r.protocol, r.mode) {
                (RemoteProtocol::Substep, Mode::PerSubstep) => Box::new(RemoteSite::for_controller(
                    r.address.as_str(),
                    r.transport,
                    controller,
                    &r.client_options(),
                )?),
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
        let controller = SubstepController::new(model, &self.settings(dt), load0)?;
        let site = self.build_site(&controller, dt)?;
        SubstructureTest::new(model, controller, site)
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

#[derive(Debug, Clone, PartialEq)]
pub struct OutputSettings {
    /// Output directory from `[output] dir`, if given.
    pub dir: Option<PathBuf>,
    /// Whether to draw figures.
    pub plots: bool,
    /// `[output.plots]`: format, time window and which figures.
    pub plot_options: PlotOptions,
}

/// Figure names accepted by `[output.plots] figures` (the file names without extension).
pub const PLOT_FIGURES: &[&str] = &[
    "displacement",
    "acceleration",
    "coupling_force",
    "error_force",
    "hysteresis",
    "reference",
    "compensation_force",
    "tracking_error",
    "energy",
    "base_shear",
    "storeys",
    "ground_motion",
    "response_spectrum",
];

/// The `[output.plots]` table (all optional).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PlotOptions {
    /// `png`, `svg` or `pdf`.
    pub format: Option<String>,
    /// Time window `[t0, t1]` \[s\] of the hysteresis plot and the zoom panel.
    pub window: Option<(f64, f64)>,
    /// Only these figures (names from [`PLOT_FIGURES`]); all when `None`.
    pub figures: Option<Vec<String>>,
}

impl PlotOptions {
    /// Whether figure `name` is to be drawn.
    pub fn wants(&self, name: &str) -> bool {
        self.figures.as_ref().is_none_or(|f| f.iter().any(|n| n == name))
    }
}

impl TestDefinition {
    /// Read and validate a config file; relative paths in it resolve against its directory.
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let name = path.display().to_string();
        let text = limits::read_text(path, limits::CONFIG_MAX_BYTES)?;
        let base = path.parent().unwrap_or(Path::new(""));
        Self::from_toml(&text, &name, base)
    }

    /// Parse and validate config text; `name` names it in messages and becomes
    /// [`TestDefinition::source`], `base_dir` resolves relative paths.
    pub fn from_toml(text: &str, name: &str, base_dir: &Path) -> Result<Self> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| toml_error(&e, text, name))?;
        raw.build(name, base_dir).map_err(|e| match e {
            Error::InvalidInput { what, reason } => Error::invalid(format!("{name}: {what}"), reason),
            Error::Numerical { what, reason } => Error::numerical(format!("{name}: {what}"), reason),
            other => other,
        })
    }

    /// Step time `t_i = i·dt` \[s\].
    pub fn time(&self, step: usize) -> f64 {
        step as f64 * self.integrator.dt
    }
}

/// `FILE: line L: message` from a toml error (its message may span lines; they are joined).
pub(super) fn toml_error(e: &toml::de::Error, text: &str, name: &str) -> Error {
    let message = plain_types(&e.message().split_whitespace().collect::<Vec<_>>().join(" "));
    match e.span() {
        Some(span) => {
            let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
            Error::file(name, format!("line {line}: {message}"))
        }
        None => Error::file(name, message),
    }
}

/// Prefix the key path of an input error (`mass` → `structure.sdof.mass`).
pub(super) fn prefixed(e: Error, prefix: &str) -> Error {
    match e {
        Error::InvalidInput { what, reason } if !what.starts_with(prefix) => {
            Error::invalid(format!("{prefix}{what}"), reason)
        }
        other => other,
    }
}

// ---------------------------------------------------------------------------------------------
// Raw structs: the file as written.

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    structure: RawStructure,
    ground_motion: RawGroundMotion,
    integrator: RawIntegrator,
    substructure: Option<RawSubstructure>,
    #[serde(default)]
    output: RawOutput,
    limits: Option<RawRunLimits>,
}

/// `[limits]`: what one run may ask of the machine (docs/limits.md).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRunLimits {
    max_memory: Option<f64>,
    max_run_time: Option<f64>,
    max_output_bytes: Option<f64>,
    max_file_bytes: Option<f64>,
}

impl RawRunLimits {
    fn build(&self) -> Result<Limits> {
        let d = Limits::default();
        Ok(Limits {
            max_memory: limits::limit_value("max_memory", self.max_memory, d.max_memory)?,
            max_run_time: limits::limit_value("max_run_time", self.max_run_time, d.max_run_time)?,
            max_output_bytes: limits::limit_value("max_output_bytes", self.max_output_bytes, d.max_output_bytes)?,
            max_file_bytes: limits::limit_value("max_file_bytes", self.max_file_bytes, d.max_file_bytes)?,
        })
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStructure {
    mass: Option<MatrixInput>,
    stiffness: Option<MatrixInput>,
    damping: Option<MatrixInput>,
    influence: Option<Vec<f64>>,
    rayleigh: Option<RawRayleigh>,
    modal: Option<RawModal>,
    shear_building: Option<RawShearBuilding>,
    sdof: Option<RawSdof>,
    tmd: Option<RawTmd>,
    frame: Option<RawFrame>,
    storage: Option<String>,
}

/// `[structure.frame]`; every key has the default of [`Frame2d::default`].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct RawFrame {
    bays: usize,
    stories: usize,
    bay_width: f64,
    story_height: f64,
    elastic_modulus: f64,
    column_area: f64,
    column_inertia: f64,
    beam_area: f64,
    beam_inertia: f64,
    density: f64,
    floor_mass_per_bay: f64,
    rigid_diaphragm: bool,
}

impl Default for RawFrame {
    fn default() -> Self {
        let f = Frame2d::default();
        Self {
            bays: f.bays,
            stories: f.stories,
            bay_width: f.bay_width,
            story_height: f.story_height,
            elastic_modulus: f.elastic_modulus,
            column_area: f.column.area,
            column_inertia: f.column.inertia,
            beam_area: f.beam.area,
            beam_inertia: f.beam.inertia,
            density: f.density,
            floor_mass_per_bay: f.floor_mass_per_bay,
            rigid_diaphragm: f.rigid_diaphragm,
        }
    }
}

impl RawFrame {
    fn to_frame(&self) -> Frame2d {
        Frame2d {
            bays: self.bays,
            stories: self.stories,
            bay_width: self.bay_width,
            story_height: self.story_height,
            elastic_modulus: self.elastic_modulus,
            column: Section {
                area: self.column_area,
                inertia: self.column_inertia,
            },
            beam: Section {
                area: self.beam_area,
                inertia: self.beam_inertia,
            },
            density: self.density,
            floor_mass_per_bay: self.floor_mass_per_bay,
            rigid_diaphragm: self.rigid_diaphragm,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRayleigh {
    alpha: Option<f64>,
    beta: Option<f64>,
    zeta: Option<f64>,
    modes: Option<Vec<usize>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModal {
    zeta: OneOrMany,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawShearBuilding {
    stories: usize,
    story_mass: f64,
    first_period: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSdof {
    mass: f64,
    stiffness: f64,
    #[serde(default)]
    damping: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct RawTmd {
    mass: f64,
    frequency: f64,
    zeta: f64,
    eta_m: f64,
    eta_f: f64,
    zeta_s: f64,
}

impl Default for RawTmd {
    fn default() -> Self {
        let t = TmdSystem::typical();
        Self {
            mass: t.mass,
            frequency: t.frequency,
            zeta: t.zeta,
            eta_m: t.eta_m,
            eta_f: t.eta_f,
            zeta_s: t.zeta_s,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGroundMotion {
    file: Option<String>,
    dt: Option<f64>,
    scale: Option<f64>,
    units: Option<String>,
    generator: Option<String>,
    amplitude: Option<f64>,
    frequency: Option<f64>,
    f0: Option<f64>,
    f1: Option<f64>,
    duration: Option<f64>,
    seed: Option<u64>,
    pga: Option<f64>,
    omega_g: Option<f64>,
    zeta_g: Option<f64>,
    rise: Option<f64>,
    hold: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawIntegrator {
    #[serde(default = "default_scheme")]
    scheme: String,
    beta: Option<f64>,
    gamma: Option<f64>,
    alpha: Option<f64>,
    dt: f64,
    duration: Option<f64>,
}

fn default_scheme() -> String {
    "newmark".into()
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSubstructure {
    coupling_dofs: Vec<usize>,
    substeps: usize,
    inner_steps: Option<usize>,
    #[serde(default)]
    specimen: Vec<RawSpecimen>,
    actuator: Option<RawActuator>,
    sensors: Option<RawSensors>,
    error_force: Option<RawErrorForce>,
    phase_lag: Option<RawPhaseLag>,
    remote: Option<RawRemote>,
    limits: Option<RawLimits>,
    /// `"model"` (default) or `"from_motion"`.
    force: Option<String>,
    controller: Option<RawController>,
}

/// `[substructure.controller]`: the tracking controller `C(s) = num/den` (descending powers of s).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawController {
    num: Vec<f64>,
    den: Vec<f64>,
    /// Feedforward `F(s)` on the command before the feedback.
    feedforward_num: Option<Vec<f64>>,
    feedforward_den: Option<Vec<f64>>,
}

/// `[substructure.remote]`: drive a site served by `substep site serve` (or an OpenFresco site).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRemote {
    address: String,
    protocol: Option<String>,
    transport: Option<String>,
    mode: Option<String>,
    timeout: Option<f64>,
    secret_file: Option<String>,
}

/// `[substructure.limits]`: one value for all coupling DOFs or one per DOF.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLimits {
    displacement: Option<OneOrMany>,
    velocity: Option<OneOrMany>,
    force: Option<OneOrMany>,
    ramp_time: Option<f64>,
}

/// One `[[substructure.specimen]]`; `kind` selects the variant.
#[derive(Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub(super) enum RawSpecimen {
    LinearSdof {
        dof: usize,
        mass: Option<f64>,
        stiffness: f64,
        #[serde(default)]
        damping: f64,
    },
    LinearMdof {
        dofs: Vec<usize>,
        mass: Option<MatrixInput>,
        stiffness: MatrixInput,
        damping: Option<MatrixInput>,
        influence: Option<Vec<f64>>,
    },
    /// Bouc–Wen hysteretic spring; optional keys default as in `BoucWenParams::new`.
    BoucWen {
        dof: usize,
        stiffness: f64,
        alpha: f64,
        yield_displacement: f64,
        a: Option<f64>,
        beta: Option<f64>,
        gamma: Option<f64>,
        n: Option<f64>,
        #[serde(default)]
        damping: f64,
        #[serde(default)]
        delta_a: f64,
        #[serde(default)]
        delta_nu: f64,
        #[serde(default)]
        delta_eta: f64,
        /// Baber–Noori pinching strength `ζ_s` (shape parameters at their defaults).
        pinching: Option<f64>,
    },
    /// Friction damper: `model = "stick_slip"` (default, needs `stiffness`) or `"smooth"` (`v_ref`).
    Friction {
        dof: usize,
        slip_force: f64,
        model: Option<String>,
        stiffness: Option<f64>,
        v_ref: Option<f64>,
        #[serde(default)]
        damping: f64,
    },
    /// Replay of a measured force record [N]: `file` (two columns t, f) or `values` + `dt`.
    Replay {
        dof: usize,
        file: Option<String>,
        values: Option<Vec<f64>>,
        dt: Option<f64>,
        #[serde(default = "one")]
        scale: f64,
    },
    /// Mass, dashpot and spring at the coupling DOF itself.
    LumpedSdof {
        dof: usize,
        mass: f64,
        #[serde(default)]
        damping: f64,
        #[serde(default)]
        stiffness: f64,
    },
}

#[derive(Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub(super) enum RawActuator {
    Ideal {
        #[serde(default)]
        delay: f64,
    },
    Delay {
        delay: f64,
    },
    FirstOrder {
        time_constant: f64,
        #[serde(default)]
        delay: f64,
    },
    SecondOrder {
        frequency: f64,
        zeta: f64,
        #[serde(default)]
        delay: f64,
    },
    /// `num / den` in descending powers of s.
    TransferFunction {
        num: Vec<f64>,
        den: Vec<f64>,
        #[serde(default)]
        delay: f64,
    },
    StateSpace {
        a: Vec<Vec<f64>>,
        b: Vec<f64>,
        c: Vec<f64>,
        #[serde(default)]
        d: f64,
        #[serde(default)]
        delay: f64,
    },
    /// Defaults: the benchmark's nominal plant ([`ServoSpec::benchmark`]).
    ServoHydraulic {
        g: Option<f64>,
        a1_beta0: Option<f64>,
        beta1: Option<f64>,
        beta2: Option<f64>,
        a2: Option<f64>,
        a3: Option<f64>,
        /// `"finite_difference"` (default, the benchmark's block) or `"exact"`.
        csi_derivative: Option<String>,
        #[serde(default)]
        delay: f64,
    },
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSensors {
    #[serde(default)]
    force_noise: f64,
    #[serde(default)]
    displacement_noise: f64,
    adc_bits: Option<u32>,
    force_range: Option<f64>,
    displacement_range: Option<f64>,
    /// A/D step instead of `adc_bits` [N], [m].
    force_quantum: Option<f64>,
    displacement_quantum: Option<f64>,
    lowpass_hz: Option<f64>,
    /// Band-limited white-noise power [N² s], [m² s] at `noise_sample_time` [s]: σ² = P / T_s.
    force_noise_power: Option<f64>,
    displacement_noise_power: Option<f64>,
    noise_sample_time: Option<f64>,
    /// The same noise sequence on every channel.
    #[serde(default)]
    shared_noise: bool,
    /// `"chacha"` (default) or `"benchmark"`.
    generator: Option<String>,
    /// D/A converter on the actuator commands [m].
    command_range: Option<f64>,
    command_quantum: Option<f64>,
    command_bits: Option<u32>,
    seed: Option<u64>,
}

fn one() -> f64 {
    1.0
}

#[derive(Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
enum RawErrorForce {
    None {},
    Pid {
        #[serde(default = "one")]
        p: f64,
        #[serde(default)]
        i: f64,
        #[serde(default)]
        d: f64,
    },
    PidResidual {
        #[serde(default = "one")]
        p: f64,
    },
    Arx {
        #[serde(default = "default_arx_order")]
        order: usize,
        #[serde(default = "default_arx_lambda")]
        forgetting_factor: f64,
        #[serde(default = "default_arx_p0")]
        p0: f64,
    },
}

fn default_arx_order() -> usize {
    4
}
fn default_arx_lambda() -> f64 {
    0.98
}
fn default_arx_p0() -> f64 {
    100.0
}

/// `[substructure.phase_lag]`; which keys apply depends on `kind` (checked in `build`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPhaseLag {
    kind: String,
    order: Option<usize>,
    lead: Option<f64>,
    lead_substeps: Option<f64>,
    k_lag: Option<usize>,
    n_u: Option<usize>,
    forgetting_factor: Option<f64>,
    taps: Option<usize>,
    guard_factor: Option<f64>,
    ramp_start: Option<usize>,
    ramp_steps: Option<usize>,
    fade_out: Option<[usize; 2]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOutput {
    dir: Option<String>,
    #[serde(default)]
    plots: RawPlots,
}

/// `[output] plots = true | false`, or the table `[output.plots]`.
#[derive(Debug)]
enum RawPlots {
    Enabled(bool),
    Table(RawPlotTable),
}

impl Default for RawPlots {
    fn default() -> Self {
        RawPlots::Enabled(true)
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlotTable {
    enabled: Option<bool>,
    format: Option<String>,
    window: Option<[f64; 2]>,
    figures: Option<Vec<String>>,
}

impl<'de> Deserialize<'de> for RawPlots {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = RawPlots;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("true, false or a table [output.plots] with enabled, format, window, figures")
            }
            fn visit_bool<E: serde::de::Error>(self, v: bool) -> std::result::Result<RawPlots, E> {
                Ok(RawPlots::Enabled(v))
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> std::result::Result<RawPlots, A::Error> {
                RawPlotTable::deserialize(serde::de::value::MapAccessDeserializer::new(map)).map(RawPlots::Table)
            }
        }
        d.deserialize_any(V)
    }
}

impl RawPlots {
    fn build(&self) -> Result<(bool, PlotOptions)> {
        let t = match self {
            RawPlots::Enabled(b) => return Ok((*b, PlotOptions::default())),
            RawPlots::Table(t) => t,
        };
        if let Some(f) = &t.format
            && !["png", "svg", "pdf"].contains(&f.as_str())
        {
            return Err(Error::invalid(
                "output.plots.format",
                format!("unknown format '{f}' (expected \"png\", \"svg\" or \"pdf\")"),
            ));
        }
        if let Some([a, b]) = t.window
            && !(a.is_finite() && b.is_finite() && a >= 0.0 && b > a)
        {
            return Err(Error::invalid(
                "output.plots.window",
                format!("must be [t0, t1] with 0 ≤ t0 < t1 [s], got [{a}, {b}]"),
            ));
        }
        if let Some(figs) = &t.figures
            && let Some(bad) = figs.iter().find(|f| !PLOT_FIGURES.contains(&f.as_str()))
        {
            return Err(Error::invalid(
                "output.plots.figures",
                format!("unknown figure '{bad}' (expected some of {})", PLOT_FIGURES.join(", ")),
            ));
        }
        Ok((
            t.enabled.unwrap_or(true),
            PlotOptions {
                format: t.format.clone(),
                window: t.window.map(|[a, b]| (a, b)),
                figures: t.figures.clone(),
            },
        ))
    }
}

impl Default for RawOutput {
    fn default() -> Self {
        Self {
            dir: None,
            plots: RawPlots::default(),
        }
    }
}

/// A matrix in a config: an array of rows, a number (1×1), or a path to a `.mtx` file.
#[derive(Debug, Clone)]
pub(super) enum MatrixInput {
    Rows(Vec<Vec<f64>>),
    File(String),
}

impl<'de> Deserialize<'de> for MatrixInput {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = MatrixInput;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a matrix: an array of rows (arrays of numbers), a number, or the path of a .mtx file")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> std::result::Result<MatrixInput, E> {
                Ok(MatrixInput::File(v.to_string()))
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> std::result::Result<MatrixInput, E> {
                Ok(MatrixInput::Rows(vec![vec![v]]))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> std::result::Result<MatrixInput, E> {
                self.visit_f64(v as f64)
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> std::result::Result<MatrixInput, E> {
                self.visit_f64(v as f64)
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<MatrixInput, A::Error> {
                let mut rows = Vec::new();
                while let Some(row) = seq.next_element::<Vec<f64>>()? {
                    rows.push(row);
                }
                Ok(MatrixInput::Rows(rows))
            }
        }
        d.deserialize_any(V)
    }
}

/// One number for all, or one per item.
#[derive(Debug, Clone)]
struct OneOrMany(Vec<f64>);

impl<'de> Deserialize<'de> for OneOrMany {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = OneOrMany;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number or an array of numbers")
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> std::result::Result<OneOrMany, E> {
                Ok(OneOrMany(vec![v]))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> std::result::Result<OneOrMany, E> {
                Ok(OneOrMany(vec![v as f64]))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> std::result::Result<OneOrMany, E> {
                Ok(OneOrMany(vec![v as f64]))
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<OneOrMany, A::Error> {
                let mut v = Vec::new();
                while let Some(x) = seq.next_element::<f64>()? {
                    v.push(x);
                }
                Ok(OneOrMany(v))
            }
        }
        d.deserialize_any(V)
    }
}

/// A matrix from its config form; `what` is the key path.
pub(super) fn matrix(input: &MatrixInput, what: &str, base: &Path) -> Result<DMatrix<f64>> {
    matrix_with(input, what, base, &Limits::default())
}

/// [`matrix`] with a `.mtx` file read within `limits`.
fn matrix_with(input: &MatrixInput, what: &str, base: &Path, limits: &Limits) -> Result<DMatrix<f64>> {
    match input {
        MatrixInput::File(path) => {
            let resolved = base.join(path);
            read_matrix_market_with(&resolved, limits).map_err(|e| Error::invalid(what, e.to_string()))
        }
        MatrixInput::Rows(rows) => {
            let n_rows = rows.len();
            let n_cols = rows.first().map_or(0, Vec::len);
            if n_rows == 0 || n_cols == 0 {
                return Err(Error::invalid(what, "matrix is empty"));
            }
            for (i, row) in rows.iter().enumerate() {
                if row.len() != n_cols {
                    return Err(Error::invalid(
                        what,
                        format!("row {} has {} entries but row 1 has {n_cols}", i + 1, row.len()),
                    ));
                }
                if let Some(j) = row.iter().position(|x| !x.is_finite()) {
                    return Err(Error::invalid(
                        what,
                        format!("entry ({}, {}) is not finite ({})", i + 1, j + 1, row[j]),
                    ));
                }
            }
            Ok(DMatrix::from_fn(n_rows, n_cols, |i, j| rows[i][j]))
        }
    }
}

/// A model matrix in sparse form: `.mtx` files are read without a dense array; inline rows must
/// be square.
fn sparse_matrix(input: &MatrixInput, what: &str, base: &Path, limits: &Limits) -> Result<CscMatrix> {
    match input {
        MatrixInput::File(path) => {
            let resolved = base.join(path);
            read_matrix_market_sparse_with(&resolved, limits).map_err(|e| Error::invalid(what, e.to_string()))
        }
        MatrixInput::Rows(_) => {
            let m = matrix_with(input, what, base, limits)?;
            if m.nrows() != m.ncols() {
                return Err(Error::invalid(
                    what,
                    format!("is {}x{}, a model matrix must be square", m.nrows(), m.ncols()),
                ));
            }
            Ok(CscMatrix::from_dense(&m))
        }
    }
}

/// 1-based DOF number → 0-based index, with a range check.
fn dof_index(what: &str, dof: usize, n: usize) -> Result<usize> {
    if (1..=n).contains(&dof) {
        Ok(dof - 1)
    } else {
        Err(Error::invalid(
            what,
            format!("DOF {dof} is out of range (the model has DOFs 1..={n})"),
        ))
    }
}

/// Error if any of the named optional keys is present (`why` explains).
fn forbid(prefix: &str, keys: &[(&str, bool)], why: &str) -> Result<()> {
    match keys.iter().find(|(_, present)| *present) {
        Some((key, _)) => Err(Error::invalid(format!("{prefix}{key}"), why.to_string())),
        None => Ok(()),
    }
}

// ---------------------------------------------------------------------------------------------
// Building: raw → validated.

impl RawConfig {
    fn build(self, name: &str, base: &Path) -> Result<TestDefinition> {
        let limits = self
            .limits
            .as_ref()
            .map_or(Ok(Limits::default()), RawRunLimits::build)?;
        let (name_s, scheme, dt, duration) = self.integrator.build()?;
        // Only the implicit Newmark schemes (and the sub-step controller) run on sparse storage.
        let sparse_capable = matches!(scheme, Scheme::Newmark { beta, .. } if beta > 0.0);
        // Limits first, from the config alone: nothing big is built, read or run before this.
        let shape = self.structure.shape(sparse_capable, &limits)?;
        if let Some(length) = self.ground_motion.length_hint(duration) {
            check_samples(&limits, length, dt)?;
            if let Some(m) = shape {
                self.check_run(&limits, m, (length / dt).floor(), dt)?;
            }
        }
        let ground_motion = self.ground_motion.build(dt, duration, base, &limits)?;
        let steps = ground_motion.accel.len() - 1;
        if steps == 0 {
            return Err(Error::invalid(
                "integrator.duration",
                format!("the run must last at least one step (dt = {dt} s)"),
            ));
        }
        if let Some(m) = shape {
            self.check_run(&limits, m, steps as f64, dt)?;
        }
        let model = self.structure.build(base, sparse_capable, &limits)?;
        if shape.is_none() {
            self.check_run(&limits, ModelShape::of(&model), steps as f64, dt)?;
        }
        let substructure = match self.substructure {
            None => None,
            Some(s) => Some(s.build(&model, &name_s, scheme, dt, base, &limits)?),
        };
        check_exact_range(&self.structure, &model, substructure.as_ref(), scheme, dt)?;
        Ok(TestDefinition {
            source: name.to_string(),
            model,
            ground_motion,
            integrator: IntegratorDefinition {
                name: name_s,
                scheme,
                dt,
                steps,
            },
            substructure,
            output: {
                let (plots, plot_options) = self.output.plots.build()?;
                OutputSettings {
                    dir: self.output.dir.map(PathBuf::from),
                    plots,
                    plot_options,
                }
            },
        })
    }
}

impl RawStructure {
    /// The model in the storage `[structure] storage` asks for; `sparse_capable` is false when
    /// the integrator needs dense matrices (then `auto` keeps models dense).
    fn build(&self, base: &Path, sparse_capable: bool, limits: &Limits) -> Result<Model> {
        let matrices = self.mass.is_some() || self.stiffness.is_some();
        let forms = [
            ("mass + stiffness", matrices),
            ("[structure.shear_building]", self.shear_building.is_some()),
            ("[structure.sdof]", self.sdof.is_some()),
            ("[structure.tmd]", self.tmd.is_some()),
            ("[structure.frame]", self.frame.is_some()),
        ];
        let given: Vec<&str> = forms.iter().filter(|f| f.1).map(|f| f.0).collect();
        match given.len() {
            0 => {
                return Err(Error::invalid(
                    "structure",
                    "no model given: set mass and stiffness, or one of [structure.shear_building], \
                     [structure.frame], [structure.sdof], [structure.tmd]",
                ));
            }
            1 => {}
            _ => {
                return Err(Error::invalid(
                    "structure",
                    format!("give only one model form, found {}", given.join(" and ")),
                ));
            }
        }
        let storage = match &self.storage {
            Some(s) => Storage::from_name(s)?,
            None => Storage::Auto,
        };
        let damping_options = [
            ("damping", self.damping.is_some()),
            ("rayleigh", self.rayleigh.is_some()),
            ("modal", self.modal.is_some()),
        ];
        let damping_given: Vec<&str> = damping_options.iter().filter(|f| f.1).map(|f| f.0).collect();
        if damping_given.len() > 1 {
            return Err(Error::invalid(
                format!("structure.{}", damping_given[1]),
                format!("cannot be combined with structure.{}", damping_given[0]),
            ));
        }
        let influence = self.influence.clone().map(DVector::from_vec);

        let model: Model = if let Some(s) = &self.sdof {
            forbid(
                "structure.",
                &damping_options,
                "not allowed with [structure.sdof] (give its damping there)",
            )?;
            let m = sdof(s.mass, s.damping, s.stiffness).map_err(|e| prefixed(e, "structure.sdof."))?;
            StructuralModel::new(m.mass, m.damping, m.stiffness, influence)?.into()
        } else if let Some(t) = &self.tmd {
            forbid(
                "structure.",
                &damping_options,
                "not allowed with [structure.tmd] (it sets damping by zeta and zeta_s)",
            )?;
            let p = TmdSystem {
                mass: t.mass,
                frequency: t.frequency,
                zeta: t.zeta,
                eta_m: t.eta_m,
                eta_f: t.eta_f,
                zeta_s: t.zeta_s,
            };
            let m = tmd_two_dof(&p).map_err(|e| prefixed(e, "structure."))?;
            StructuralModel::new(m.mass, m.damping, m.stiffness, influence)?.into()
        } else if let Some(b) = &self.shear_building {
            let m = shear_building_sparse(&ShearBuilding {
                stories: b.stories,
                story_mass: b.story_mass,
                first_period: b.first_period,
            })?;
            let damping = match &self.damping {
                Some(c) => sparse_matrix(c, "structure.damping", base, limits)?,
                None => m.damping,
            };
            SparseModel::new(m.mass, damping, m.stiffness, influence)?.into()
        } else if let Some(f) = &self.frame {
            let m = frame_2d(&f.to_frame())?;
            let damping = match &self.damping {
                Some(c) => sparse_matrix(c, "structure.damping", base, limits)?,
                None => m.damping,
            };
            SparseModel::new(m.mass, damping, m.stiffness, influence.or(Some(m.influence)))?.into()
        } else {
            let (mass, stiffness) = match (&self.mass, &self.stiffness) {
                (Some(m), Some(k)) => (m, k),
                (Some(_), None) => {
                    return Err(Error::invalid(
                        "structure.stiffness",
                        "missing (structure.mass is given)",
                    ));
                }
                _ => {
                    return Err(Error::invalid(
                        "structure.mass",
                        "missing (structure.stiffness is given)",
                    ));
                }
            };
            let inputs = [Some(mass), Some(stiffness), self.damping.as_ref()];
            if inputs.iter().flatten().any(|m| matches!(m, MatrixInput::File(_))) {
                // MatrixMarket files are read sparse (they may be large).
                let mass = sparse_matrix(mass, "structure.mass", base, limits)?;
                let stiffness = sparse_matrix(stiffness, "structure.stiffness", base, limits)?;
                let damping = match &self.damping {
                    Some(c) => sparse_matrix(c, "structure.damping", base, limits)?,
                    None => CscMatrix::zeros(mass.n()),
                };
                SparseModel::new(mass, damping, stiffness, influence)?.into()
            } else {
                let mass = matrix_with(mass, "structure.mass", base, limits)?;
                let stiffness = matrix_with(stiffness, "structure.stiffness", base, limits)?;
                let damping = match &self.damping {
                    Some(c) => matrix_with(c, "structure.damping", base, limits)?,
                    None => DMatrix::zeros(mass.nrows(), mass.ncols()),
                };
                StructuralModel::new(mass, damping, stiffness, influence)?.into()
            }
        };

        let spec = if let Some(r) = &self.rayleigh {
            Some(r.spec()?)
        } else {
            self.modal
                .as_ref()
                .map(|m| DampingSpec::Modal { zeta: m.zeta.0.clone() })
        };
        let model = resolve_storage(model, storage, sparse_capable, self.modal.is_some())?;
        match spec {
            Some(spec) => model.with_damping(&spec),
            None => Ok(model),
        }
    }
}

/// Put `model` in the storage asked for. `auto` picks sparse for large sparse models, but dense
/// when the integrator or modal damping needs dense matrices (up to [`DENSE_MAX_DOFS`]).
fn resolve_storage(model: Model, storage: Storage, sparse_capable: bool, modal: bool) -> Result<Model> {
    let n = model.n_dofs();
    check_storage(n, storage, sparse_capable, modal)?;
    match storage {
        Storage::Auto if modal || !sparse_capable => model.with_storage(Storage::Dense),
        storage => model.with_storage(storage),
    }
}

/// Whether storage `storage` can hold an `n`-DOF model for this scheme and damping (cheap: it
/// runs before the model is built).
fn check_storage(n: usize, storage: Storage, sparse_capable: bool, modal: bool) -> Result<()> {
    let needs_dense = if modal {
        Some("modal damping ([structure.modal])")
    } else if !sparse_capable {
        Some("the integrator scheme")
    } else {
        None
    };
    match (storage, needs_dense) {
        (Storage::Sparse, Some(why)) => Err(Error::invalid(
            "structure.storage",
            format!(
                "\"sparse\" cannot be used with {why}, which needs dense matrices: use \
                 [structure.rayleigh] and an implicit Newmark scheme, or storage = \"dense\""
            ),
        )),
        (Storage::Auto, Some(why)) if n > DENSE_MAX_DOFS => Err(Error::invalid(
            "structure",
            format!(
                "{why} needs dense matrices, but the model has {n} DOFs (dense storage is limited to \
                 {DENSE_MAX_DOFS} DOFs here): use [structure.rayleigh] and an implicit Newmark scheme"
            ),
        )),
        _ => Ok(()),
    }
}

/// Size of the numerical model, known before it is built (or from the built model).
#[derive(Debug, Clone, Copy)]
struct ModelShape {
    n: f64,
    bytes: f64,
    step_seconds: f64,
}

impl ModelShape {
    fn of(model: &Model) -> Self {
        let n = model.n_dofs() as f64;
        match model {
            Model::Dense(_) => Self::dense(n),
            Model::Sparse(m) => {
                let nnz = (m.mass.nnz() + m.damping.nnz() + m.stiffness.nnz()) as f64;
                Self {
                    n,
                    bytes: n * limits::CHAIN_BYTES_PER_DOF + nnz * limits::MTX_BYTES_PER_ENTRY,
                    step_seconds: RunShape::sparse_step_seconds(nnz),
                }
            }
        }
    }
    fn dense(n: f64) -> Self {
        Self {
            n,
            bytes: limits::dense_model_bytes(n),
            step_seconds: RunShape::dense_step_seconds(n),
        }
    }
}

impl RawStructure {
    /// The model's size from the config alone, refused when over `limits` or when its storage
    /// contradicts the scheme or the damping; `None` for MatrixMarket files (their size line is
    /// checked as they are read).
    fn shape(&self, sparse_capable: bool, limits: &Limits) -> Result<Option<ModelShape>> {
        let storage = match &self.storage {
            Some(s) => Storage::from_name(s)?,
            None => Storage::Auto,
        };
        let (n, sparse, key, asked) = if let Some(b) = &self.shear_building {
            let n = b.stories as f64;
            let sparse = ModelShape {
                n,
                bytes: n * limits::CHAIN_BYTES_PER_DOF,
                step_seconds: RunShape::chain_step_seconds(n),
            };
            let asked = format!("a shear building of {} stories", b.stories);
            (n, sparse, "structure.shear_building.stories", asked)
        } else if let Some(f) = &self.frame {
            let lines = f.bays as f64 + 1.0;
            let per_floor = if f.rigid_diaphragm {
                1.0 + 2.0 * lines
            } else {
                3.0 * lines
            };
            let n = f.stories as f64 * per_floor;
            let sparse = ModelShape {
                n,
                bytes: n * limits::FRAME_BYTES_PER_DOF,
                step_seconds: RunShape::frame_step_seconds(n, lines),
            };
            let asked = format!(
                "a frame of {} bays and {} stories ({} DOFs)",
                f.bays,
                f.stories,
                limits::number(n)
            );
            (n, sparse, "structure.frame", asked)
        } else {
            let n = if self.sdof.is_some() {
                1
            } else if self.tmd.is_some() {
                2
            } else if let Some(MatrixInput::Rows(rows)) = &self.mass {
                rows.len()
            } else {
                return Ok(None);
            };
            return Ok(Some(ModelShape::dense(n as f64)));
        };
        let modal = self.modal.is_some();
        check_storage(n.min(usize::MAX as f64) as usize, storage, sparse_capable, modal)?;
        let shape = if modal || !sparse_capable || storage == Storage::Dense {
            ModelShape::dense(n)
        } else {
            sparse
        };
        limits.check_memory(key, &asked, shape.bytes)?;
        Ok(Some(shape))
    }
}

/// Largest rate `max(|K_ii|, |C_ii|) / M_ii · Δt` (the diagonal of `A·Δt` of `ż = A z`) that an
/// exact integration accepts: the matrix exponential is computed up to `‖A·Δt‖₁ =`
/// [`crate::linalg::EXPM_MAX_NORM`], and the off-diagonal terms add to the diagonal's.
const EXACT_MAX_RATE: f64 = 1e11;

impl RawStructure {
    /// Config key of the model's stiffness or damping (`what` = "stiffness" / "damping").
    fn key(&self, what: &str) -> String {
        if self.sdof.is_some() {
            format!("structure.sdof.{what}")
        } else if self.tmd.is_some() {
            "structure.tmd".into()
        } else if self.shear_building.is_some() {
            "structure.shear_building".into()
        } else if self.frame.is_some() {
            "structure.frame".into()
        } else if what == "damping" && self.rayleigh.is_some() {
            "structure.rayleigh".into()
        } else if what == "damping" && self.modal.is_some() {
            "structure.modal".into()
        } else {
            format!("structure.{what}")
        }
    }
}

/// Refuse what the matrix exponentials cannot integrate in f64 (e.g. a stiffness of 1e60 N/m
/// on 50 kg, or a mass of 1e-300 kg): every DOF of the exact scheme or of the exact reference at
/// `dt`, specimen internal DOFs and actuator dynamics at the inner step, with the key of the
/// term that dominates.
fn check_exact_range(
    raw: &RawStructure,
    model: &Model,
    sub: Option<&SubstructureDefinition>,
    scheme: Scheme,
    dt: f64,
) -> Result<()> {
    struct Dof {
        m: f64,
        k: f64,
        c: f64,
        /// Specimen (index) whose stiffness / damping dominates, `None` for the structure.
        k_owner: Option<usize>,
        c_owner: Option<usize>,
        /// Integrated at the inner step only (a specimen's internal DOF).
        internal: bool,
    }
    let n = model.n_dofs();
    let diagonals = match model {
        Model::Dense(m) => (m.mass.diagonal(), m.stiffness.diagonal(), m.damping.diagonal()),
        Model::Sparse(m) => (
            DVector::from_vec(m.mass.diagonal()),
            DVector::from_vec(m.stiffness.diagonal()),
            DVector::from_vec(m.damping.diagonal()),
        ),
    };
    let mut dofs: Vec<Dof> = (0..n)
        .map(|i| Dof {
            m: diagonals.0[i],
            k: diagonals.1[i],
            c: diagonals.2[i],
            k_owner: None,
            c_owner: None,
            internal: false,
        })
        .collect();
    let mut all_linear = true;
    let mut dt_inner = dt;
    if let Some(s) = sub {
        dt_inner = dt / s.substeps as f64 / s.inner_steps as f64;
        for (idx, spec) in s.specimens.iter().enumerate() {
            let Some(lm) = spec.linear_matrices() else {
                all_linear = false;
                continue;
            };
            for (a, row) in (0..lm.stiffness.nrows()).map(|a| (a, lm.dofs.get(a).copied())) {
                let (k, c, m) = (lm.stiffness[(a, a)], lm.damping[(a, a)], lm.mass[(a, a)]);
                match row {
                    Some(g) if g < n => {
                        let d = &mut dofs[g];
                        if k.abs() > d.k.abs() {
                            d.k_owner = Some(idx);
                        }
                        if c.abs() > d.c.abs() {
                            d.c_owner = Some(idx);
                        }
                        d.k += k;
                        d.c += c;
                        d.m += m;
                    }
                    _ => dofs.push(Dof {
                        m,
                        k,
                        c,
                        k_owner: Some(idx),
                        c_owner: Some(idx),
                        internal: true,
                    }),
                }
            }
        }
        let (key, rate) = match &s.actuator.dynamics {
            // Continuous LTI and servo-hydraulic actuators are checked for stability and
            // integrability where the lab builds them (transfer/lti.rs, transfer/servo.rs).
            Dynamics::Ideal | Dynamics::Lti(_) | Dynamics::ServoHydraulic(_) => ("", 0.0),
            Dynamics::FirstOrder { time_constant } => ("time_constant", dt_inner / time_constant),
            Dynamics::SecondOrder { frequency_hz, zeta } => {
                let w = 2.0 * std::f64::consts::PI * frequency_hz;
                ("frequency", (w * w).max(2.0 * zeta * w) * dt_inner)
            }
        };
        if !(rate <= EXACT_MAX_RATE) {
            return Err(Error::invalid(
                format!("substructure.actuator.{key}"),
                format!(
                    "gives a rate of {rate:.3e} per inner step of {dt_inner:.3e} s (at most {EXACT_MAX_RATE:.0e}): \
                     outside what f64 can integrate; check the units"
                ),
            ));
        }
    }
    let exact = scheme == Scheme::Exact
        || sub.is_some_and(|s| {
            !s.specimens.is_empty() && all_linear && dofs.len() <= super::run::EXACT_REFERENCE_MAX_DOFS
        });
    for (i, d) in dofs.iter().enumerate() {
        let h = if d.internal { dt_inner } else { dt };
        if !(d.internal || exact) || d.m <= 0.0 {
            continue; // no exponential at this DOF; a mass that is not positive is refused elsewhere
        }
        let (rate_k, rate_c) = (d.k.abs() / d.m * h, d.c.abs() / d.m * h);
        if rate_k <= EXACT_MAX_RATE && rate_c <= EXACT_MAX_RATE {
            continue;
        }
        let (what, value, owner) = if !(rate_c > rate_k) {
            ("stiffness", d.k, d.k_owner)
        } else {
            ("damping", d.c, d.c_owner)
        };
        let key = match owner {
            Some(idx) => format!("substructure.specimen[{}].{what}", idx + 1),
            None => raw.key(what),
        };
        let place = if d.internal {
            format!("an internal specimen DOF at the inner step {h:.3e} s")
        } else {
            format!("DOF {} at dt = {h} s", i + 1)
        };
        return Err(Error::invalid(
            key,
            format!(
                "{what} {value:.3e} against a mass of {:.3e} kg at {place} gives a rate {what}/mass·dt = \
                 {:.3e}, more than {EXACT_MAX_RATE:.0e}: outside what f64 can integrate exactly (matrix \
                 exponential); check the units of mass, {what} and dt",
                d.m,
                rate_k.max(rate_c)
            ),
        ));
    }
    Ok(())
}

/// Refuse an excitation whose samples at `dt` would not fit, before they are generated.
fn check_samples(limits: &Limits, length: f64, dt: f64) -> Result<()> {
    let steps = (length / dt).floor();
    let shape = RunShape {
        steps,
        ..RunShape::default()
    };
    limits.check_memory(
        "integrator.dt",
        &format!(
            "a {} s excitation at dt = {} s ({} steps)",
            limits::number(length),
            limits::number(dt),
            limits::number(steps)
        ),
        shape.excitation_bytes(),
    )
}

impl RawConfig {
    /// Memory, computing time and output of the run (model `m`, `steps` steps of `dt`), checked
    /// against `limits` before anything of that size exists.
    fn check_run(&self, limits: &Limits, m: ModelShape, steps: f64, dt: f64) -> Result<()> {
        let mut shape = RunShape {
            n_dofs: m.n,
            model_bytes: m.bytes,
            step_seconds: m.step_seconds,
            steps,
            ..RunShape::default()
        };
        limits.check_memory(
            "integrator.dt",
            &format!(
                "a {} s excitation at dt = {} s ({} steps)",
                limits::number(steps * dt),
                limits::number(dt),
                limits::number(steps)
            ),
            shape.excitation_bytes(),
        )?;
        let mut asked = format!("{} steps of a {}-DOF model", limits::number(steps), limits::number(m.n));
        if let Some(s) = &self.substructure {
            if s.substeps == 0 || s.coupling_dofs.is_empty() {
                return Ok(()); // refused with its own message when the substructure is built
            }
            let actuator = match s.actuator.as_ref().map(RawActuator::spec) {
                None => ActuatorSpec::ideal(),
                Some(Ok(a)) => a,
                Some(Err(_)) => return Ok(()), // refused with its own message when the lab is built
            };
            let inner = match s.inner_steps {
                Some(k) => k.max(1),
                None if actuator.dynamics == Dynamics::Ideal && actuator.delay == 0.0 => 1,
                None => 10,
            };
            shape.n_coupling = s.coupling_dofs.len() as f64;
            shape.substeps = s.substeps as f64;
            shape.inner_steps = inner as f64;
            let dt_inner = dt / shape.substeps / shape.inner_steps;
            if actuator.delay.is_finite() && actuator.delay > 0.0 {
                shape.delay_samples = crate::transfer::DelayLine::samples(actuator.delay, dt_inner);
            }
            if s.phase_lag.as_ref().is_some_and(|p| p.kind != "none") {
                shape.extra_substep_columns = 2.0;
            }
            limits.check_memory(
                "substructure.actuator.delay",
                &format!(
                    "a delay of {} s sampled every {dt_inner:.3e} s (dt / substeps / inner_steps: {:.3e} samples \
                     per actuator)",
                    limits::number(actuator.delay),
                    shape.delay_samples
                ),
                shape.delay_bytes(),
            )?;
            asked = format!(
                "{asked} with {} sub-steps of {inner} inner steps on {} coupling DOF(s)",
                s.substeps,
                s.coupling_dofs.len()
            );
        }
        limits.check_memory("limits", &format!("the whole run ({asked})"), shape.memory())?;
        let total = shape.run_time();
        let inner = RunShape {
            step_seconds: 0.0,
            ..shape
        }
        .run_time();
        let key = if steps * m.step_seconds >= 0.5 * total || self.substructure.is_none() {
            "integrator.dt"
        } else if shape.inner_steps > shape.substeps && inner >= 0.5 * total {
            "substructure.inner_steps"
        } else {
            "substructure.substeps"
        };
        limits.check_run_time(key, &asked, total)?;
        let key = if shape.substeps_bytes() > shape.history_bytes() {
            "substructure.substeps"
        } else {
            "integrator.dt"
        };
        limits.check_output(key, &asked, shape.output_bytes())
    }
}

impl RawRayleigh {
    fn spec(&self) -> Result<DampingSpec> {
        match (self.alpha, self.beta, self.zeta) {
            (None, None, Some(zeta)) => {
                let modes = match self.modes.as_deref() {
                    None => (1, 2),
                    Some([i, j]) => (*i, *j),
                    Some(other) => {
                        return Err(Error::invalid(
                            "structure.rayleigh.modes",
                            format!("must list two mode numbers, got {}", other.len()),
                        ));
                    }
                };
                Ok(DampingSpec::RayleighRatio { zeta, modes })
            }
            (alpha, beta, None) if alpha.is_some() || beta.is_some() => {
                if self.modes.is_some() {
                    return Err(Error::invalid(
                        "structure.rayleigh.modes",
                        "only used with zeta (not with alpha, beta)",
                    ));
                }
                Ok(DampingSpec::Rayleigh {
                    alpha: alpha.unwrap_or(0.0),
                    beta: beta.unwrap_or(0.0),
                })
            }
            (_, _, Some(_)) => Err(Error::invalid(
                "structure.rayleigh",
                "give either alpha and beta, or zeta (with modes), not both",
            )),
            _ => Err(Error::invalid(
                "structure.rayleigh",
                "give alpha and beta, or zeta (with modes = [i, j], default [1, 2])",
            )),
        }
    }
}

impl RawIntegrator {
    /// `(name, scheme, dt, duration)`.
    fn build(&self) -> Result<(String, Scheme, f64, Option<f64>)> {
        let dt = require_positive("integrator.dt", self.dt)?;
        if let Some(d) = self.duration {
            require_positive("integrator.duration", d)?;
        }
        let name = self.scheme.as_str();
        let is_newmark = name == "newmark";
        let is_alpha = matches!(name, "hht" | "alpha_os");
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
        let beta = self.beta.unwrap_or(0.25);
        let gamma = self.gamma.unwrap_or(0.5);
        if is_newmark {
            require_non_negative("integrator.beta", beta)?;
            require_non_negative("integrator.gamma", gamma)?;
        }
        let scheme = Scheme::from_name(name, beta, gamma, self.alpha.unwrap_or(-0.1))?;
        if let Scheme::Hht { alpha } | Scheme::AlphaOs { alpha } = scheme {
            check_hilber_alpha(alpha)?;
        }
        Ok((name.to_string(), scheme, dt, self.duration))
    }
}

impl RawGroundMotion {
    fn build(&self, dt: f64, duration: Option<f64>, base: &Path, limits: &Limits) -> Result<GroundMotion> {
        let g = "ground_motion.";
        let scale = self.scale.unwrap_or(1.0);
        if !scale.is_finite() {
            return Err(Error::invalid(
                "ground_motion.scale",
                format!("must be finite, got {scale}"),
            ));
        }
        // Units of the file's (or generator's) values; `.AT2` records are in g by definition and
        // converted by their reader.
        let is_at2 = self
            .file
            .as_deref()
            .is_some_and(|f| Path::new(f).extension().is_some_and(|e| e.eq_ignore_ascii_case("at2")));
        let units = match (self.units.as_deref(), is_at2) {
            (None | Some("m/s2"), false) => 1.0,
            (Some("g"), false) => excitation::G,
            (Some("cm/s2"), false) => 0.01,
            (None | Some("g"), true) => 1.0,
            (Some(u @ ("m/s2" | "cm/s2")), true) => {
                return Err(Error::invalid(
                    "ground_motion.units",
                    format!("a PEER .AT2 record is in g (converted on reading), not {u}"),
                ));
            }
            (Some(other), _) => {
                return Err(Error::invalid(
                    "ground_motion.units",
                    format!("unknown units '{other}' (expected \"m/s2\", \"g\" or \"cm/s2\")"),
                ));
            }
        };
        let generator_keys = [
            ("amplitude", self.amplitude.is_some()),
            ("frequency", self.frequency.is_some()),
            ("f0", self.f0.is_some()),
            ("f1", self.f1.is_some()),
            ("duration", self.duration.is_some()),
            ("seed", self.seed.is_some()),
            ("pga", self.pga.is_some()),
            ("omega_g", self.omega_g.is_some()),
            ("zeta_g", self.zeta_g.is_some()),
            ("rise", self.rise.is_some()),
            ("hold", self.hold.is_some()),
        ];
        let (record, description) = match (&self.file, &self.generator) {
            (Some(_), Some(_)) => {
                return Err(Error::invalid(
                    "ground_motion",
                    "give either file or generator, not both",
                ));
            }
            (None, None) => {
                return Err(Error::invalid(
                    "ground_motion",
                    "give a record file (file = \"ag.csv\") or a generator (generator = \"sine_sweep\")",
                ));
            }
            (Some(file), None) => {
                forbid(g, &generator_keys, "only used with generator = ...")?;
                let path = base.join(file);
                let record = excitation::read_record_with(&path, self.dt, limits.max_file_bytes)
                    .map_err(|e| Error::invalid("ground_motion.file", e.to_string()))?;
                (record, format!("record {}", path.display()))
            }
            (None, Some(kind)) => {
                if self.dt.is_some() {
                    return Err(Error::invalid(
                        "ground_motion.dt",
                        "only used with a single-column file (generators sample at integrator.dt)",
                    ));
                }
                let length = match (self.duration, duration) {
                    (Some(d), _) | (None, Some(d)) => d,
                    (None, None) => {
                        return Err(Error::invalid(
                            "ground_motion.duration",
                            "required for a generator (or set integrator.duration)",
                        ));
                    }
                };
                check_samples(limits, length, dt)?;
                self.generate(kind, length, dt, &generator_keys)?
            }
        };
        let description = match self.units.as_deref() {
            Some(u) if !is_at2 && u != "m/s2" => format!("{description}, in {u}"),
            _ => description,
        };
        let description = if scale == 1.0 {
            description
        } else {
            format!("{description}, scaled by {scale}")
        };
        check_samples(limits, duration.unwrap_or(record.duration()), dt)?;
        let accel = record
            .scaled(scale * units)?
            .resample(dt, duration)
            .map_err(|e| prefixed(e, "ground_motion: "))?;
        Ok(GroundMotion { accel, description })
    }

    /// Length of the excitation [s] if it is known without reading a file.
    fn length_hint(&self, duration: Option<f64>) -> Option<f64> {
        match (&self.file, &self.generator) {
            (None, Some(_)) => self.duration.or(duration),
            (Some(_), None) => duration,
            _ => None,
        }
    }

    fn generate(&self, kind: &str, duration: f64, dt: f64, keys: &[(&str, bool)]) -> Result<(Record, String)> {
        let g = "ground_motion.";
        let allowed: &[&str] = match kind {
            "harmonic" => &["amplitude", "frequency", "duration"],
            "sine_sweep" => &["amplitude", "f0", "f1", "duration"],
            "kanai_tajimi" => &["pga", "omega_g", "zeta_g", "seed", "rise", "hold", "duration"],
            other => {
                return Err(Error::invalid(
                    "ground_motion.generator",
                    format!("unknown generator '{other}' (expected harmonic, sine_sweep or kanai_tajimi)"),
                ));
            }
        };
        let extra: Vec<(&str, bool)> = keys.iter().filter(|(k, _)| !allowed.contains(k)).copied().collect();
        forbid(
            g,
            &extra,
            &format!("not used by generator = \"{kind}\" (it uses {})", allowed.join(", ")),
        )?;
        let need = |key: &str, v: Option<f64>| {
            v.ok_or_else(|| Error::invalid(format!("{g}{key}"), format!("required for generator = \"{kind}\"")))
        };
        let gen_err = |e: Error| match e {
            Error::InvalidInput { what, reason } => {
                let key = what.rsplit('.').next().unwrap_or(&what).to_string();
                let key = match key.as_str() {
                    "frequency_hz" => "frequency".to_string(),
                    "f0_hz" => "f0".to_string(),
                    "f1_hz" => "f1".to_string(),
                    "pga_target" => "pga".to_string(),
                    "envelope" => "rise".to_string(),
                    _ => key,
                };
                Error::invalid(format!("{g}{key}"), reason)
            }
            other => other,
        };
        match kind {
            "harmonic" => {
                let a = need("amplitude", self.amplitude)?;
                let f = need("frequency", self.frequency)?;
                let r = excitation::harmonic(a, f, duration, dt).map_err(gen_err)?;
                Ok((r, format!("harmonic {f} Hz, {a} m/s², {duration} s")))
            }
            "sine_sweep" => {
                let a = need("amplitude", self.amplitude)?;
                let f0 = need("f0", self.f0)?;
                let f1 = need("f1", self.f1)?;
                let r = excitation::sine_sweep(a, f0, f1, duration, dt).map_err(gen_err)?;
                Ok((r, format!("linear sine sweep {f0}–{f1} Hz, {a} m/s², {duration} s")))
            }
            _ => {
                let envelope = match (self.rise, self.hold) {
                    (None, None) => Envelope::None,
                    (Some(rise), Some(hold)) => Envelope::Trapezoid { rise, hold },
                    (Some(_), None) => return Err(Error::invalid("ground_motion.hold", "required with rise")),
                    (None, Some(_)) => return Err(Error::invalid("ground_motion.rise", "required with hold")),
                };
                let params = KanaiTajimi {
                    pga_target: self.pga,
                    omega_g: self.omega_g.unwrap_or(15.6),
                    zeta_g: self.zeta_g.unwrap_or(0.6),
                    duration,
                    dt,
                    seed: self.seed.unwrap_or(1),
                    envelope,
                };
                let r = excitation::kanai_tajimi(params).map_err(gen_err)?;
                let pga = r.pga();
                Ok((
                    r,
                    format!(
                        "Kanai-Tajimi noise (omega_g {} rad/s, zeta_g {}, seed {}), PGA {pga:.3} m/s², {duration} s",
                        params.omega_g, params.zeta_g, params.seed
                    ),
                ))
            }
        }
    }
}

/// serde's Rust type names in a message replaced by what a user types ("expected usize" →
/// "expected a whole number ≥ 0").
pub(super) fn plain_types(message: &str) -> String {
    let mut m = message.to_string();
    for (rust, plain) in [
        ("expected usize", "expected a whole number ≥ 0"),
        ("expected u64", "expected a whole number ≥ 0"),
        ("expected u32", "expected a whole number ≥ 0 (at most 4294967295)"),
        ("expected u16", "expected a whole number 0…65535"),
        ("expected u8", "expected a whole number 0…255"),
        ("expected i64", "expected a whole number"),
        ("expected i32", "expected a whole number"),
        ("expected f64", "expected a number"),
        ("expected f32", "expected a number"),
        ("expected a sequence", "expected an array [..]"),
        ("expected a map", "expected a table"),
        ("floating point", "the number"),
        ("invalid type: integer", "invalid value: the whole number"),
        ("invalid type:", "wrong type:"),
    ] {
        m = m.replace(rust, plain);
    }
    m
}

/// `specimen.<key>` from a specimen constructor becomes `<what>.<key>`.
fn rekey(e: Error, what: &str) -> Error {
    match e {
        Error::InvalidInput { what: key, reason } | Error::Numerical { what: key, reason } => {
            let rest = key.strip_prefix("specimen").unwrap_or(&key);
            Error::invalid(format!("{what}{rest}"), reason)
        }
        other => other,
    }
}

impl RawSpecimen {
    /// The library's description; `n` is the number of model DOFs, `what` the key prefix.
    pub(super) fn to_spec(&self, n: usize, what: &str, base: &Path) -> Result<SpecimenSpec> {
        self.to_spec_with(n, what, base, &Limits::default())
    }

    /// [`RawSpecimen::to_spec`] with files read within `limits`.
    fn to_spec_with(&self, n: usize, what: &str, base: &Path, limits: &Limits) -> Result<SpecimenSpec> {
        match self {
            RawSpecimen::BoucWen {
                dof,
                stiffness,
                alpha,
                yield_displacement,
                a,
                beta,
                gamma,
                n: sharpness,
                damping,
                delta_a,
                delta_nu,
                delta_eta,
                pinching,
            } => {
                let mut p = BoucWenParams::new(*stiffness, *alpha, *yield_displacement);
                p.a = a.unwrap_or(p.a);
                p.beta = beta.unwrap_or(p.beta);
                p.gamma = gamma.unwrap_or(p.gamma);
                p.n = sharpness.unwrap_or(p.n);
                p.damping = *damping;
                p.delta_a = *delta_a;
                p.delta_nu = *delta_nu;
                p.delta_eta = *delta_eta;
                p.pinching = pinching.map(Pinching::new);
                let spec = SpecimenSpec::BoucWen {
                    dof: dof_index(&format!("{what}.dof"), *dof, n)?,
                    params: p,
                };
                spec.build().map_err(|e| rekey(e, what))?;
                Ok(spec)
            }
            RawSpecimen::Friction {
                dof,
                slip_force,
                model,
                stiffness,
                v_ref,
                damping,
            } => {
                let model = match model.as_deref().unwrap_or("stick_slip") {
                    "stick_slip" => FrictionModel::StickSlip {
                        stiffness: stiffness.ok_or_else(|| {
                            Error::invalid(
                                format!("{what}.stiffness"),
                                "is required for model = \"stick_slip\" (pre-slip stiffness, N/m)",
                            )
                        })?,
                    },
                    "smooth" => FrictionModel::Smooth {
                        v_ref: v_ref.ok_or_else(|| {
                            Error::invalid(
                                format!("{what}.v_ref"),
                                "is required for model = \"smooth\" (reference velocity, m/s)",
                            )
                        })?,
                    },
                    other => {
                        return Err(Error::invalid(
                            format!("{what}.model"),
                            format!("unknown friction model '{other}' (expected stick_slip or smooth)"),
                        ));
                    }
                };
                let spec = SpecimenSpec::Friction {
                    dof: dof_index(&format!("{what}.dof"), *dof, n)?,
                    slip_force: *slip_force,
                    model,
                    damping: *damping,
                };
                spec.build().map_err(|e| rekey(e, what))?;
                Ok(spec)
            }
            RawSpecimen::Replay {
                dof,
                file,
                values,
                dt,
                scale,
            } => {
                let (dt, values) = match (file, values) {
                    (Some(f), None) => {
                        let path = base.join(f);
                        let rec = excitation::read_record_with(&path, *dt, limits.max_file_bytes)
                            .map_err(|e| Error::invalid(format!("{what}.file"), e.to_string()))?;
                        (rec.dt, rec.accel)
                    }
                    (None, Some(v)) => {
                        let dt = dt.ok_or_else(|| Error::invalid(format!("{what}.dt"), "is required with values"))?;
                        (dt, v.clone())
                    }
                    _ => {
                        return Err(Error::invalid(
                            what.to_string(),
                            "give either file or values (with dt) for a replay",
                        ));
                    }
                };
                if !scale.is_finite() {
                    return Err(Error::invalid(format!("{what}.scale"), "must be finite"));
                }
                let spec = SpecimenSpec::Replay {
                    dof: dof_index(&format!("{what}.dof"), *dof, n)?,
                    dt,
                    values: values.iter().map(|v| v * scale).collect(),
                };
                spec.build().map_err(|e| rekey(e, what))?;
                Ok(spec)
            }
            RawSpecimen::LumpedSdof {
                dof,
                mass,
                damping,
                stiffness,
            } => {
                require_positive(&format!("{what}.mass"), *mass)?;
                require_non_negative(&format!("{what}.stiffness"), *stiffness)?;
                require_non_negative(&format!("{what}.damping"), *damping)?;
                Ok(SpecimenSpec::LumpedSdof {
                    dof: dof_index(&format!("{what}.dof"), *dof, n)?,
                    mass: *mass,
                    damping: *damping,
                    stiffness: *stiffness,
                })
            }
            RawSpecimen::LinearSdof {
                dof,
                mass,
                stiffness,
                damping,
            } => {
                if let Some(m) = mass {
                    require_positive(&format!("{what}.mass"), *m)?;
                }
                require_non_negative(&format!("{what}.stiffness"), *stiffness)?;
                require_non_negative(&format!("{what}.damping"), *damping)?;
                Ok(SpecimenSpec::LinearSdof {
                    dof: dof_index(&format!("{what}.dof"), *dof, n)?,
                    mass: *mass,
                    stiffness: *stiffness,
                    damping: *damping,
                })
            }
            RawSpecimen::LinearMdof {
                dofs,
                mass,
                stiffness,
                damping,
                influence,
            } => {
                let key = format!("{what}.dofs");
                if dofs.is_empty() {
                    return Err(Error::invalid(key, "must list at least one DOF"));
                }
                let mut idx = Vec::with_capacity(dofs.len());
                for &d in dofs {
                    let i = dof_index(&key, d, n)?;
                    if idx.contains(&i) {
                        return Err(Error::invalid(key, format!("DOF {d} is listed twice")));
                    }
                    idx.push(i);
                }
                let k = matrix_with(stiffness, &format!("{what}.stiffness"), base, limits)?;
                let size = k.nrows();
                let m = match mass {
                    Some(m) => matrix_with(m, &format!("{what}.mass"), base, limits)?,
                    None => DMatrix::zeros(size, size),
                };
                let c = match damping {
                    Some(c) => matrix_with(c, &format!("{what}.damping"), base, limits)?,
                    None => DMatrix::zeros(size, size),
                };
                for (key, mat) in [("stiffness", &k), ("mass", &m), ("damping", &c)] {
                    if mat.nrows() != mat.ncols() || mat.nrows() < dofs.len() || mat.nrows() != size {
                        return Err(Error::invalid(
                            format!("{what}.{key}"),
                            format!(
                                "is {}x{}; it must be square over the {} attached DOFs followed by the internal \
                                 DOFs, and all specimen matrices must have one size (stiffness is {size}x{size})",
                                mat.nrows(),
                                mat.ncols(),
                                dofs.len()
                            ),
                        ));
                    }
                }
                if let Some(inf) = influence
                    && inf.len() != size
                {
                    return Err(Error::invalid(
                        format!("{what}.influence"),
                        format!("has {} entries, the specimen has {size} DOFs", inf.len()),
                    ));
                }
                Ok(SpecimenSpec::LinearMdof {
                    dofs: idx,
                    mass: m,
                    damping: c,
                    stiffness: k,
                    influence: influence.clone().map(DVector::from_vec),
                })
            }
        }
    }
}

impl RawActuator {
    /// Errors name keys as `actuator.KEY` (the caller prefixes the section).
    pub(super) fn spec(&self) -> Result<ActuatorSpec> {
        Ok(match self {
            RawActuator::Ideal { delay } | RawActuator::Delay { delay } => ActuatorSpec {
                dynamics: Dynamics::Ideal,
                delay: *delay,
            },
            RawActuator::FirstOrder { time_constant, delay } => ActuatorSpec {
                dynamics: Dynamics::FirstOrder {
                    time_constant: *time_constant,
                },
                delay: *delay,
            },
            RawActuator::SecondOrder { frequency, zeta, delay } => ActuatorSpec {
                dynamics: Dynamics::SecondOrder {
                    frequency_hz: *frequency,
                    zeta: *zeta,
                },
                delay: *delay,
            },
            RawActuator::TransferFunction { num, den, delay } => {
                if den.iter().all(|&v| v == 0.0) {
                    return Err(Error::invalid("actuator.den", "is zero (no transfer function)"));
                }
                let tf = TransferFunction::new("actuator", num, den)?;
                ActuatorSpec {
                    dynamics: Dynamics::Lti(tf.to_state_space()),
                    delay: *delay,
                }
            }
            RawActuator::StateSpace { a, b, c, d, delay } => {
                let n = a.len();
                if n == 0 {
                    return Err(Error::invalid("actuator.a", "is empty"));
                }
                if let Some(r) = a.iter().position(|row| row.len() != n) {
                    return Err(Error::invalid(
                        "actuator.a",
                        format!(
                            "must be square: row {} has {} entries, A has {n} rows",
                            r + 1,
                            a[r].len()
                        ),
                    ));
                }
                for (key, v) in [("b", b), ("c", c)] {
                    if v.len() != n {
                        return Err(Error::invalid(
                            format!("actuator.{key}"),
                            format!("has {} entries, A is {n}x{n}", v.len()),
                        ));
                    }
                }
                let am = DMatrix::from_fn(n, n, |i, j| a[i][j]);
                let ss = StateSpace::new(
                    "actuator",
                    am,
                    DVector::from_column_slice(b),
                    DVector::from_column_slice(c),
                    *d,
                )?;
                ActuatorSpec {
                    dynamics: Dynamics::Lti(ss),
                    delay: *delay,
                }
            }
            RawActuator::ServoHydraulic {
                g,
                a1_beta0,
                beta1,
                beta2,
                a2,
                a3,
                csi_derivative,
                delay,
            } => {
                let base = ServoSpec::benchmark();
                let derivative = match csi_derivative.as_deref().unwrap_or("finite_difference") {
                    "finite_difference" => Derivative::FiniteDifference,
                    "exact" => Derivative::Exact,
                    other => {
                        return Err(Error::invalid(
                            "actuator.csi_derivative",
                            format!("unknown '{other}' (expected finite_difference or exact)"),
                        ));
                    }
                };
                ActuatorSpec {
                    dynamics: Dynamics::ServoHydraulic(ServoSpec {
                        g: g.unwrap_or(base.g),
                        a1_beta0: a1_beta0.unwrap_or(base.a1_beta0),
                        beta1: beta1.unwrap_or(base.beta1),
                        beta2: beta2.unwrap_or(base.beta2),
                        a2: a2.unwrap_or(base.a2),
                        a3: a3.unwrap_or(base.a3),
                        derivative,
                    }),
                    delay: *delay,
                }
            }
        })
    }
}

impl RawSensors {
    /// The base force and displacement sensor (seed = the configured seed), from which
    /// [`crate::transfer::channel_sensors`] derives one per coupling DOF exactly as
    /// [`RawSensors::specs`] does.
    pub(super) fn base_specs(&self) -> Result<(SensorSpec, SensorSpec)> {
        let (f, d) = self.specs(1)?;
        Ok((
            SensorSpec {
                seed: self.seed(),
                ..f[0]
            },
            SensorSpec {
                seed: self.seed(),
                ..d[0]
            },
        ))
    }

    fn generator(&self) -> Result<NoiseGenerator> {
        match self.generator.as_deref().unwrap_or("chacha") {
            "chacha" => Ok(NoiseGenerator::ChaCha),
            "benchmark" => Ok(NoiseGenerator::Benchmark),
            other => Err(Error::invalid(
                "substructure.sensors.generator",
                format!("unknown generator '{other}' (expected chacha or benchmark)"),
            )),
        }
    }

    /// Whether the channels share one noise sequence.
    pub(super) fn shared_noise(&self) -> bool {
        self.shared_noise
    }

    /// The configured seed; by default 1, or the benchmark's start state for its generator.
    fn seed(&self) -> u64 {
        match (self.seed, self.generator.as_deref()) {
            (Some(s), _) => s,
            (None, Some("benchmark")) => u64::from(BENCHMARK_SEED),
            (None, _) => 1,
        }
    }

    /// The D/A converter on the commands, if configured.
    pub(super) fn command_converter(&self) -> Result<Option<Converter>> {
        let p = "substructure.sensors.";
        let Some(r) = self.command_range else {
            forbid(
                p,
                &[
                    ("command_quantum", self.command_quantum.is_some()),
                    ("command_bits", self.command_bits.is_some()),
                ],
                "needs command_range (the D/A converter's range)",
            )?;
            return Ok(None);
        };
        require_positive(&format!("{p}command_range"), r)?;
        let q = match (self.command_quantum, self.command_bits) {
            (Some(_), Some(_)) => {
                return Err(Error::invalid(
                    format!("{p}command_bits"),
                    "give either command_quantum or command_bits, not both",
                ));
            }
            (Some(q), None) => require_positive(&format!("{p}command_quantum"), q)?,
            (None, Some(bits)) if (2..=32).contains(&bits) => 2.0 * r / (2f64).powi(bits as i32),
            (None, Some(bits)) => {
                return Err(Error::invalid(
                    format!("{p}command_bits"),
                    format!("must be in 2..=32, got {bits}"),
                ));
            }
            (None, None) => {
                return Err(Error::invalid(
                    format!("{p}command_range"),
                    "needs command_quantum or command_bits (the D/A converter's step)",
                ));
            }
        };
        Ok(Some(Converter::new(r, q)?))
    }

    /// `(force sensors, displacement sensors)`, one per coupling DOF.
    pub(super) fn specs(&self, n_c: usize) -> Result<(Vec<SensorSpec>, Vec<SensorSpec>)> {
        let p = "substructure.sensors.";
        require_non_negative(&format!("{p}force_noise"), self.force_noise)?;
        require_non_negative(&format!("{p}displacement_noise"), self.displacement_noise)?;
        let generator = self.generator()?;
        // σ from a band-limited white-noise power: σ² = P / T_s.
        let sigma = |sigma: f64, key: &str, power: Option<f64>| -> Result<f64> {
            let Some(pw) = power else { return Ok(sigma) };
            if sigma != 0.0 {
                return Err(Error::invalid(
                    format!("{p}{key}_power"),
                    format!("give either {key} (σ) or {key}_power, not both"),
                ));
            }
            require_non_negative(&format!("{p}{key}_power"), pw)?;
            let ts = self.noise_sample_time.ok_or_else(|| {
                Error::invalid(
                    format!("{p}{key}_power"),
                    "needs noise_sample_time (the sample time of the band-limited white noise, σ² = P / T_s)",
                )
            })?;
            require_positive(&format!("{p}noise_sample_time"), ts)?;
            Ok((pw / ts).sqrt())
        };
        let force_sigma = sigma(self.force_noise, "force_noise", self.force_noise_power)?;
        let disp_sigma = sigma(
            self.displacement_noise,
            "displacement_noise",
            self.displacement_noise_power,
        )?;
        if self.noise_sample_time.is_some()
            && self.force_noise_power.is_none()
            && self.displacement_noise_power.is_none()
        {
            return Err(Error::invalid(
                format!("{p}noise_sample_time"),
                "only used with force_noise_power or displacement_noise_power",
            ));
        }
        if let Some(s) = self.seed
            && generator == NoiseGenerator::Benchmark
            && !(1..=2_147_483_646).contains(&s)
        {
            return Err(Error::invalid(
                format!("{p}seed"),
                format!("the benchmark generator needs a seed in 1..=2147483646, got {s}"),
            ));
        }
        let seed = self.seed();
        // Per-channel seeds, kept in the benchmark generator's range for that generator.
        let channel = |ch: u64| -> u64 {
            if self.shared_noise {
                return seed;
            }
            channel_seed_for(generator, seed, ch)
        };
        for (key, q, range) in [
            ("force_quantum", self.force_quantum, self.force_range),
            (
                "displacement_quantum",
                self.displacement_quantum,
                self.displacement_range,
            ),
        ] {
            if let Some(q) = q {
                require_positive(&format!("{p}{key}"), q)?;
                if self.adc_bits.is_some() {
                    return Err(Error::invalid(
                        format!("{p}{key}"),
                        "give either adc_bits or a quantum, not both",
                    ));
                }
                if range.is_none() {
                    return Err(Error::invalid(
                        format!("{p}{key}"),
                        format!("needs {} (the converter's range)", key.replace("quantum", "range")),
                    ));
                }
            }
        }
        let any_quantum = self.force_quantum.is_some() || self.displacement_quantum.is_some();
        if let Some(f) = self.lowpass_hz {
            require_positive(&format!("{p}lowpass_hz"), f)?;
        }
        match self.adc_bits {
            Some(bits) => {
                if !(2..=32).contains(&bits) {
                    return Err(Error::invalid(
                        format!("{p}adc_bits"),
                        format!("must be in 2..=32, got {bits}"),
                    ));
                }
                if self.force_range.is_none() && self.displacement_range.is_none() {
                    return Err(Error::invalid(
                        format!("{p}adc_bits"),
                        "needs force_range and/or displacement_range (the converter's range)",
                    ));
                }
            }
            None if any_quantum => {}
            None => forbid(
                p,
                &[
                    ("force_range", self.force_range.is_some()),
                    ("displacement_range", self.displacement_range.is_some()),
                ],
                "only used with adc_bits, force_quantum or displacement_quantum",
            )?,
        }
        let sensor = |noise: f64, range: Option<f64>, quantum: Option<f64>, key: &str, ch: u64| -> Result<SensorSpec> {
            if let Some(r) = range {
                require_positive(&format!("{p}{key}"), r)?;
                if self.adc_bits.is_none() && quantum.is_none() {
                    return Err(Error::invalid(
                        format!("{p}{key}"),
                        format!(
                            "needs adc_bits or {} (the converter's step)",
                            key.replace("range", "quantum")
                        ),
                    ));
                }
            }
            Ok(SensorSpec {
                noise_std: noise,
                lowpass_hz: self.lowpass_hz,
                adc_bits: range.and(self.adc_bits),
                adc_range: range.unwrap_or(0.0),
                adc_quantum: range.and(quantum),
                generator,
                seed: channel(ch),
            })
        };
        let mut force = Vec::with_capacity(n_c);
        let mut disp = Vec::with_capacity(n_c);
        for i in 0..n_c as u64 {
            force.push(sensor(
                force_sigma,
                self.force_range,
                self.force_quantum,
                "force_range",
                2 * i,
            )?);
            disp.push(sensor(
                disp_sigma,
                self.displacement_range,
                self.displacement_quantum,
                "displacement_range",
                2 * i + 1,
            )?);
        }
        Ok((force, disp))
    }
}

impl RawErrorForce {
    fn spec(&self) -> ErrorForceSpec {
        match *self {
            RawErrorForce::None {} => ErrorForceSpec::None,
            RawErrorForce::Pid { p, i, d } => ErrorForceSpec::Pid { p, i, d },
            RawErrorForce::PidResidual { p } => ErrorForceSpec::PidResidual { p },
            RawErrorForce::Arx {
                order,
                forgetting_factor,
                p0,
            } => ErrorForceSpec::Arx {
                order,
                lambda: forgetting_factor,
                p0,
            },
        }
    }
}

/// Default ramp-in of the phase-lag compensation [steps].
const DEFAULT_RAMP_STEPS: usize = 100;

impl RawPhaseLag {
    /// `None` for `kind = "none"`. `dt` time step, `k_sub` sub-steps, `delay` the actuator's pure
    /// delay [s] (the default lead and `k_lag`).
    fn build(&self, dt: f64, k_sub: usize, delay: f64) -> Result<Option<PhaseLagDefinition>> {
        let p = "substructure.phase_lag.";
        let dtau = dt / k_sub as f64;
        let keys = |names: &[&'static str]| -> Vec<(&'static str, bool)> {
            names
                .iter()
                .map(|&n| {
                    let present = match n {
                        "order" => self.order.is_some(),
                        "lead" => self.lead.is_some(),
                        "lead_substeps" => self.lead_substeps.is_some(),
                        "k_lag" => self.k_lag.is_some(),
                        "n_u" => self.n_u.is_some(),
                        "forgetting_factor" => self.forgetting_factor.is_some(),
                        "taps" => self.taps.is_some(),
                        "guard_factor" => self.guard_factor.is_some(),
                        "ramp_start" => self.ramp_start.is_some(),
                        "ramp_steps" => self.ramp_steps.is_some(),
                        "fade_out" => self.fade_out.is_some(),
                        _ => false,
                    };
                    (n, present)
                })
                .collect()
        };
        let kind = self.kind.as_str();
        let unused = format!("is not used with kind = \"{kind}\"");
        // The lead in sub-steps: `lead` [s] or `lead_substeps`, default the actuator delay.
        let lead = || -> Result<f64> {
            match (self.lead, self.lead_substeps) {
                (Some(_), Some(_)) => Err(Error::invalid(
                    format!("{p}lead_substeps"),
                    "give either lead [s] or lead_substeps, not both",
                )),
                (Some(l), None) => {
                    require_non_negative(&format!("{p}lead"), l)?;
                    Ok(l / dtau)
                }
                (None, Some(l)) => {
                    require_non_negative(&format!("{p}lead_substeps"), l)?;
                    Ok(l)
                }
                (None, None) => Ok(delay / dtau),
            }
        };
        let guard_factor = self.guard_factor.unwrap_or(10.0);
        let spec = match kind {
            "none" => {
                forbid(
                    p,
                    &keys(&[
                        "order",
                        "lead",
                        "lead_substeps",
                        "k_lag",
                        "n_u",
                        "forgetting_factor",
                        "taps",
                        "guard_factor",
                        "ramp_start",
                        "ramp_steps",
                        "fade_out",
                    ]),
                    &unused,
                )?;
                return Ok(None);
            }
            "polynomial" => {
                forbid(p, &keys(&["k_lag", "n_u", "forgetting_factor", "taps"]), &unused)?;
                PhaseLagSpec::Polynomial {
                    order: self.order.unwrap_or(3),
                    lead: lead()?,
                    guard_factor,
                }
            }
            "arx" => {
                forbid(p, &keys(&["order", "lead", "lead_substeps", "taps"]), &unused)?;
                let k_lag = self.k_lag.unwrap_or_else(|| ((delay / dtau).round() as usize).max(1));
                let mut spec = ArxPhaseLagSpec::new(k_lag);
                if let Some(n) = self.n_u {
                    spec.n_u = n;
                }
                if let Some(l) = self.forgetting_factor {
                    spec.lambda = l;
                }
                spec.guard_factor = guard_factor;
                PhaseLagSpec::Arx(spec)
            }
            "inverse_fir" => {
                forbid(p, &keys(&["k_lag", "n_u", "guard_factor"]), &unused)?;
                let mut spec = InverseFirSpec::new(lead()?);
                if let Some(o) = self.order {
                    spec.order = o;
                }
                if let Some(t) = self.taps {
                    spec.taps = t;
                }
                if let Some(l) = self.forgetting_factor {
                    spec.lambda = l;
                }
                PhaseLagSpec::InverseFir(spec)
            }
            other => {
                return Err(Error::invalid(
                    format!("{p}kind"),
                    format!("unknown kind '{other}' (expected none, polynomial, arx or inverse_fir)"),
                ));
            }
        };
        let mut ramp = Ramp::new(
            self.ramp_start.unwrap_or(0).saturating_mul(k_sub),
            self.ramp_steps.unwrap_or(DEFAULT_RAMP_STEPS).saturating_mul(k_sub),
        );
        if let Some([begin, steps]) = self.fade_out {
            ramp = ramp.with_fade_out(begin.saturating_mul(k_sub), steps.saturating_mul(k_sub));
        }
        let def = PhaseLagDefinition { spec, ramp };
        def.validate().map_err(|e| prefixed(e, "substructure."))?;
        Ok(Some(def))
    }
}

impl RawSubstructure {
    fn build(
        &self,
        model: &Model,
        scheme_name: &str,
        scheme: Scheme,
        dt: f64,
        base: &Path,
        limits: &Limits,
    ) -> Result<SubstructureDefinition> {
        let p = "substructure.";
        let (beta, gamma) = match scheme {
            Scheme::Newmark { beta, gamma } if beta > 0.0 => (beta, gamma),
            _ => {
                return Err(Error::invalid(
                    "integrator.scheme",
                    format!(
                        "the substructure algorithm needs an implicit Newmark scheme (beta > 0); \
                         '{scheme_name}' cannot be used with [substructure]"
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
        if self.specimen.is_empty() && remote.is_none() {
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
                            "servo_hydraulic needs exactly one lumped_sdof specimen at coupling DOF {} (its mass, damping and stiffness are part of the plant)",
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
        let phase_lag = match &self.phase_lag {
            Some(raw) => raw.build(dt, self.substeps, actuator.delay)?,
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
            limits: self
                .limits
                .as_ref()
                .map(|l| l.build(coupling.len(), dt / self.substeps as f64))
                .transpose()?,
            coupling_dofs: coupling,
            remote,
            phase_lag,
            lab: LabOptions {
                command_converter,
                force_from_motion,
            },
            controller,
            controller_feedforward,
        })
    }
}

impl RawRemote {
    fn build(&self, base: &Path) -> Result<RemoteDefinition> {
        let p = "substructure.remote.";
        if self.address.parse::<std::net::SocketAddr>().is_err() && !self.address.contains(':') {
            return Err(Error::invalid(
                format!("{p}address"),
                format!("'{}' is not host:port", self.address),
            ));
        }
        let protocol = match self.protocol.as_deref().unwrap_or("substep") {
            "substep" => RemoteProtocol::Substep,
            "openfresco" => RemoteProtocol::OpenFresco,
            other => {
                return Err(Error::invalid(
                    format!("{p}protocol"),
                    format!("unknown protocol '{other}' (expected substep or openfresco)"),
                ));
            }
        };
        let transport = match self.transport.as_deref().unwrap_or("tcp") {
            "tcp" => Transport::Tcp,
            "udp" => Transport::Udp,
            other => {
                return Err(Error::invalid(
                    format!("{p}transport"),
                    format!("unknown transport '{other}' (expected tcp or udp)"),
                ));
            }
        };
        let mode = match self.mode.as_deref().unwrap_or("per_substep") {
            "per_substep" => Mode::PerSubstep,
            "per_step" => Mode::PerStep,
            other => {
                return Err(Error::invalid(
                    format!("{p}mode"),
                    format!("unknown mode '{other}' (expected per_substep or per_step)"),
                ));
            }
        };
        if protocol == RemoteProtocol::OpenFresco && (transport != Transport::Tcp || mode != Mode::PerSubstep) {
            return Err(Error::invalid(
                p.trim_end_matches('.'),
                "the openfresco protocol runs over tcp, per sub-step",
            ));
        }
        let timeout = self.timeout.unwrap_or(2.0);
        crate::error::require_duration(&format!("{p}timeout"), timeout)?;
        let secret = match (&self.secret_file, protocol) {
            (Some(_), RemoteProtocol::OpenFresco) => {
                return Err(Error::invalid(
                    format!("{p}secret_file"),
                    "the openfresco protocol has no authentication (use the substep protocol for an authenticated site)",
                ));
            }
            (Some(f), RemoteProtocol::Substep) => Some(Secret::from_file(&base.join(f), &format!("{p}secret_file"))?),
            (None, RemoteProtocol::Substep) => Secret::from_env()?,
            (None, RemoteProtocol::OpenFresco) => None,
        };
        Ok(RemoteDefinition {
            address: self.address.clone(),
            protocol,
            transport,
            mode,
            timeout,
            secret,
        })
    }
}

impl RawLimits {
    /// `dtau`: the sub-step length (the ramp after a stop runs in sub-steps of it).
    fn build(&self, n_c: usize, dtau: f64) -> Result<SafetyLimits> {
        let expand = |key: &str, v: &Option<OneOrMany>| -> Result<Option<Vec<f64>>> {
            match v {
                None => Ok(None),
                Some(OneOrMany(x)) if x.len() == 1 => Ok(Some(vec![x[0]; n_c])),
                Some(OneOrMany(x)) if x.len() == n_c => Ok(Some(x.clone())),
                Some(OneOrMany(x)) => Err(Error::invalid(
                    format!("substructure.limits.{key}"),
                    format!(
                        "has {} entries; give one value or one per coupling DOF ({n_c})",
                        x.len()
                    ),
                )),
            }
        };
        let limits = SafetyLimits {
            displacement: expand("displacement", &self.displacement)?,
            velocity: expand("velocity", &self.velocity)?,
            force: expand("force", &self.force)?,
            ramp_time: self.ramp_time.unwrap_or(1.0),
        };
        limits.validate_for(n_c, dtau)?;
        Ok(limits)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BASE: &str = r#"
[structure]
mass = [[1000.0, 0.0, 0.0], [0.0, 1000.0, 0.0], [0.0, 0.0, 1000.0]]
stiffness = [[2e6, -1e6, 0.0], [-1e6, 2e6, -1e6], [0.0, -1e6, 1e6]]

[structure.rayleigh]
zeta = 0.05

[ground_motion]
generator = "harmonic"
amplitude = 1.0
frequency = 2.0
duration = 1.0

[integrator]
scheme = "newmark"
dt = 0.01

[substructure]
coupling_dofs = [3, 1]
substeps = 4

[[substructure.specimen]]
kind = "linear_sdof"
dof = 3
mass = 50.0
stiffness = 2000.0
damping = 60.0

[[substructure.specimen]]
kind = "linear_sdof"
dof = 1
stiffness = 1.0e5

[substructure.actuator]
kind = "second_order"
frequency = 50.0
zeta = 0.7

[substructure.sensors]
force_noise = 1.0
seed = 3
"#;

    fn parse(text: &str) -> Result<TestDefinition> {
        TestDefinition::from_toml(text, "cfg.toml", Path::new("/nonexistent-dir"))
    }

    fn err(text: &str) -> String {
        match parse(text) {
            Ok(_) => panic!("config was accepted:\n{text}"),
            Err(e) => e.to_string(),
        }
    }

    /// BASE with `from` replaced by `to` (which must occur).
    fn edit(from: &str, to: &str) -> String {
        assert!(BASE.contains(from), "{from}");
        BASE.replacen(from, to, 1)
    }

    #[test]
    fn base_config_is_valid_and_zero_based() {
        let d = parse(BASE).unwrap();
        assert_eq!(d.source, "cfg.toml");
        assert_eq!(d.model.n_dofs(), 3);
        assert!(
            d.model.as_dense().unwrap().damping[(0, 0)] > 0.0,
            "Rayleigh damping applied"
        );
        assert_eq!(d.integrator.steps, 100);
        assert_eq!(d.ground_motion.accel.len(), 101);
        let s = d.substructure.unwrap();
        assert_eq!(s.coupling_dofs, vec![2, 0]);
        assert_eq!(s.specimens[0].dofs(), vec![2]);
        assert_eq!(s.inner_steps, 10, "default for a non-ideal actuator");
        assert_eq!((s.beta, s.gamma), (0.25, 0.5));
        assert_eq!(s.force_sensors.len(), 2);
        assert_eq!(s.force_sensors[0].noise_std, 1.0);
        let seeds = [
            s.force_sensors[0].seed,
            s.force_sensors[1].seed,
            s.displacement_sensors[0].seed,
            s.displacement_sensors[1].seed,
        ];
        for i in 0..4 {
            for j in 0..i {
                assert_ne!(seeds[i], seeds[j], "per-channel seeds differ");
            }
        }
        assert_eq!(s.error_force, ErrorForceSpec::None);
        assert_eq!(
            d.output,
            OutputSettings {
                dir: None,
                plots: true,
                plot_options: PlotOptions::default()
            }
        );
    }

    #[test]
    fn builders_and_defaults() {
        let d = parse(
            "[structure.tmd]\n[ground_motion]\ngenerator = \"sine_sweep\"\namplitude = 1\nf0 = 0.2\nf1 = 3\n\
             [integrator]\nscheme = \"exact\"\ndt = 0.01\nduration = 2.0\n",
        )
        .unwrap();
        assert_eq!(d.model.n_dofs(), 2);
        assert_eq!(d.integrator.scheme, Scheme::Exact);
        assert_eq!(d.integrator.steps, 200, "generator duration from integrator.duration");
        let d = parse(
            "[structure.shear_building]\nstories = 5\nstory_mass = 1e4\nfirst_period = 0.5\n[structure.modal]\n\
             zeta = [0.02, 0.03, 0.04, 0.05, 0.06]\n[ground_motion]\ngenerator = \"kanai_tajimi\"\nduration = 1\n\
             pga = 2\n[integrator]\nscheme = \"hht\"\nalpha = -0.1\ndt = 0.02\n[output]\ndir = \"out\"\nplots = false\n",
        )
        .unwrap();
        assert_eq!(d.model.n_dofs(), 5);
        assert_eq!(d.integrator.scheme, Scheme::Hht { alpha: -0.1 });
        assert!((d.ground_motion.accel.iter().fold(0.0f64, |m, a| m.max(a.abs())) - 2.0).abs() < 1e-12);
        assert_eq!(d.output.dir, Some(PathBuf::from("out")));
        assert!(!d.output.plots);
    }

    #[test]
    fn ideal_actuator_defaults_to_one_inner_step() {
        let text = edit(
            "kind = \"second_order\"\nfrequency = 50.0\nzeta = 0.7",
            "kind = \"ideal\"",
        );
        assert_eq!(parse(&text).unwrap().substructure.unwrap().inner_steps, 1);
        let text = edit(
            "kind = \"second_order\"\nfrequency = 50.0\nzeta = 0.7",
            "kind = \"ideal\"\ndelay = 0.002",
        );
        assert_eq!(parse(&text).unwrap().substructure.unwrap().inner_steps, 10);
    }

    #[test]
    fn malformed_toml_names_file_and_line() {
        let e = err(&edit("substeps = 4", "substeps = [4"));
        assert!(e.starts_with("cfg.toml: line 23: "), "{e}");
        assert!(!e.contains('\n'));
    }

    #[test]
    fn unknown_keys_are_named() {
        let e = err(&edit("substeps = 4", "substeps = 4\nsubstepz = 5"));
        assert!(e.starts_with("cfg.toml: line 22: unknown field `substepz`"), "{e}");
        let e = err(&edit("stiffness = 1.0e5", "stiffness = 1.0e5\nmas = 3.0"));
        assert!(e.contains("unknown field `mas`"), "{e}");
        let e = err(&format!("{BASE}\n[outptu]\ndir = \"x\"\n"));
        assert!(e.contains("unknown field `outptu`"), "{e}");
    }

    #[test]
    fn unknown_scheme_and_kinds() {
        let e = err(&edit("scheme = \"newmark\"", "scheme = \"leapfrog\""));
        assert!(
            e.starts_with("cfg.toml: integrator.scheme: unknown scheme 'leapfrog'"),
            "{e}"
        );
        let e = err(&edit(
            "kind = \"linear_sdof\"\ndof = 1",
            "kind = \"hydraulic_damper\"\ndof = 1",
        ));
        assert!(
            e.contains("unknown variant `hydraulic_damper`, expected one of") && e.contains("`linear_sdof`"),
            "{e}"
        );
        let e = err(&edit("kind = \"second_order\"", "kind = \"third_order\""));
        assert!(e.contains("unknown variant `third_order`"), "{e}");
        let e = err(&edit("generator = \"harmonic\"", "generator = \"chirp\""));
        assert_eq!(
            e,
            "cfg.toml: ground_motion.generator: unknown generator 'chirp' (expected harmonic, sine_sweep or kanai_tajimi)"
        );
    }

    #[test]
    fn matrix_errors() {
        let e = err(&edit(
            "stiffness = [[2e6, -1e6, 0.0], [-1e6, 2e6, -1e6], [0.0, -1e6, 1e6]]",
            "stiffness = [[2e6, -1e6], [-1e6, 2e6]]",
        ));
        assert_eq!(
            e,
            "cfg.toml: structure.stiffness: is 2x2 but the model has 3 DOFs (the mass matrix is 3x3)"
        );
        let e = err(&edit("[-1e6, 2e6, -1e6], [0.0", "[-1e6, 2e6, -1e6], [5.0"));
        assert!(
            e.starts_with("cfg.toml: structure.stiffness: is not symmetric: entry (3, 1)"),
            "{e}"
        );
        let e = err(&edit("[0.0, 0.0, 1000.0]]", "[0.0, 0.0, -1000.0]]"));
        assert_eq!(e, "cfg.toml: structure.mass: is not positive definite");
        let e = err(&edit("[0.0, 0.0, 1000.0]]", "[0.0, 1000.0]]"));
        assert_eq!(e, "cfg.toml: structure.mass: row 3 has 2 entries but row 1 has 3");
        let e = err(&edit("[0.0, 0.0, 1000.0]]", "[0.0, 0.0, nan]]"));
        assert_eq!(e, "cfg.toml: structure.mass: entry (3, 3) is not finite (NaN)");
    }

    #[test]
    fn missing_files_are_named() {
        let e = err(&edit(
            "mass = [[1000.0, 0.0, 0.0], [0.0, 1000.0, 0.0], [0.0, 0.0, 1000.0]]",
            "mass = \"M.mtx\"",
        ));
        assert!(
            e.starts_with("cfg.toml: structure.mass: /nonexistent-dir/M.mtx: cannot read file"),
            "{e}"
        );
        let e = err(&edit(
            "generator = \"harmonic\"\namplitude = 1.0\nfrequency = 2.0\nduration = 1.0",
            "file = \"records/ag.csv\"",
        ));
        assert!(
            e.starts_with("cfg.toml: ground_motion.file: /nonexistent-dir/records/ag.csv: cannot read file"),
            "{e}"
        );
    }

    #[test]
    fn nan_in_a_record_names_file_and_line() {
        let dir = std::env::temp_dir().join(format!("substep-config-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("ag.csv"), "t,ag\n0,0\n0.01,0.5\n0.02,NaN\n0.03,0\n").unwrap();
        let text = edit(
            "generator = \"harmonic\"\namplitude = 1.0\nfrequency = 2.0\nduration = 1.0",
            "file = \"ag.csv\"",
        );
        let e = TestDefinition::from_toml(&text, "cfg.toml", &dir)
            .unwrap_err()
            .to_string();
        let _ = std::fs::remove_dir_all(&dir);
        assert!(e.starts_with("cfg.toml: ground_motion.file: "), "{e}");
        assert!(e.ends_with("ag.csv: line 4: value is not finite (NaN)"), "{e}");
    }

    #[test]
    fn time_step_and_substeps() {
        let e = err(&edit("dt = 0.01", "dt = 0.0"));
        assert_eq!(e, "cfg.toml: integrator.dt: must be a finite number > 0, got 0");
        let e = err(&edit("dt = 0.01", "dt = -0.01"));
        assert_eq!(e, "cfg.toml: integrator.dt: must be a finite number > 0, got -0.01");
        let e = err(&edit("substeps = 4", "substeps = 0"));
        assert_eq!(e, "cfg.toml: substructure.substeps: must be at least 1");
        let e = err(&edit("substeps = 4", "substeps = 4\ninner_steps = 0"));
        assert_eq!(e, "cfg.toml: substructure.inner_steps: must be at least 1");
    }

    #[test]
    fn coupling_dof_checks() {
        let e = err(&edit("coupling_dofs = [3, 1]", "coupling_dofs = [3, 7]"));
        assert_eq!(
            e,
            "cfg.toml: substructure.coupling_dofs: DOF 7 is out of range (the model has DOFs 1..=3)"
        );
        let e = err(&edit("coupling_dofs = [3, 1]", "coupling_dofs = [3, 0]"));
        assert_eq!(
            e,
            "cfg.toml: substructure.coupling_dofs: DOF 0 is out of range (the model has DOFs 1..=3)"
        );
        let e = err(&edit("coupling_dofs = [3, 1]", "coupling_dofs = [3, 1, 3]"));
        assert_eq!(e, "cfg.toml: substructure.coupling_dofs: DOF 3 is listed twice");
        let e = err(&edit("coupling_dofs = [3, 1]", "coupling_dofs = [3, 1, 2]"));
        assert_eq!(
            e,
            "cfg.toml: substructure.coupling_dofs: DOF 2 has no specimen attached"
        );
        let e = err(&edit("dof = 1\n", "dof = 2\n"));
        assert_eq!(
            e,
            "cfg.toml: substructure.specimen[2].dof: DOF 2 is not one of substructure.coupling_dofs"
        );
    }

    #[test]
    fn specimen_values() {
        let e = err(&edit("mass = 50.0", "mass = -50.0"));
        assert_eq!(
            e,
            "cfg.toml: substructure.specimen[1].mass: must be a finite number > 0, got -50"
        );
        let e = err(&edit("damping = 60.0", "damping = -60.0"));
        assert_eq!(
            e,
            "cfg.toml: substructure.specimen[1].damping: must be a finite number >= 0, got -60"
        );
        let mdof = "kind = \"linear_mdof\"\ndofs = [3]\nmass = [[0.0, 0.0], [0.0, 50.0]]\n\
                    stiffness = [[2000.0, -2000.0], [-2000.0, 2000.0]]\ndamping = [[60.0, -60.0], [-60.0, 60.0]]";
        let ok = edit(
            "kind = \"linear_sdof\"\ndof = 3\nmass = 50.0\nstiffness = 2000.0\ndamping = 60.0",
            mdof,
        );
        assert!(parse(&ok).is_ok());
        let bad = ok.replace("[0.0, 50.0]]", "[0.0, -50.0]]");
        let e = err(&bad);
        assert!(e.starts_with("cfg.toml: substructure.specimen[1].mass: "), "{e}");
        let bad = ok.replace(
            "[[0.0, 0.0], [0.0, 50.0]]",
            "[[0.0, 0.0, 0.0], [0.0, 50.0, 0.0], [0.0, 0.0, 1.0]]",
        );
        let e = err(&bad);
        assert!(e.starts_with("cfg.toml: substructure.specimen[1].mass: is 3x3;"), "{e}");
    }

    #[test]
    fn actuator_and_sensor_values() {
        let e = err(&edit("zeta = 0.7", "zeta = 0.0"));
        assert!(
            e.starts_with("cfg.toml: substructure.actuator.zeta: must be > 0"),
            "{e}"
        );
        let e = err(&edit("zeta = 0.7", "zeta = -0.2"));
        assert!(
            e.starts_with("cfg.toml: substructure.actuator.zeta: must be > 0"),
            "{e}"
        );
        let e = err(&edit("frequency = 50.0\n", ""));
        assert!(e.contains("missing field `frequency`"), "{e}");
        let e = err(&edit("force_noise = 1.0", "force_noise = -1.0"));
        assert_eq!(
            e,
            "cfg.toml: substructure.sensors.force_noise: must be a finite number >= 0, got -1"
        );
        let e = err(&edit("force_noise = 1.0", "adc_bits = 12"));
        assert!(
            e.starts_with("cfg.toml: substructure.sensors.adc_bits: needs force_range"),
            "{e}"
        );
    }

    #[test]
    fn scheme_must_suit_the_substructure() {
        let e = err(&edit("scheme = \"newmark\"", "scheme = \"central_difference\""));
        assert!(
            e.starts_with("cfg.toml: integrator.scheme: the substructure algorithm needs an implicit Newmark scheme"),
            "{e}"
        );
        let e = err(&edit("scheme = \"newmark\"", "scheme = \"newmark\"\nbeta = 0.0"));
        assert!(e.starts_with("cfg.toml: integrator.scheme: "), "{e}");
        let e = err(&edit("scheme = \"newmark\"", "scheme = \"fox_goodwin\"\nbeta = 0.3"));
        assert!(
            e.starts_with("cfg.toml: integrator.beta: only used with scheme = \"newmark\""),
            "{e}"
        );
        let e = err(&edit("scheme = \"newmark\"", "scheme = \"hht\"\nalpha = -0.5"));
        assert!(
            e.starts_with("cfg.toml: integrator.alpha: Hilber's alpha must lie in [-1/3, 0]"),
            "{e}"
        );
    }

    #[test]
    fn ground_motion_keys() {
        let e = err(&edit("frequency = 2.0", "frequency = 2.0\nf0 = 1.0"));
        assert!(
            e.starts_with("cfg.toml: ground_motion.f0: not used by generator = \"harmonic\""),
            "{e}"
        );
        let e = err(&edit("frequency = 2.0\n", ""));
        assert_eq!(
            e,
            "cfg.toml: ground_motion.frequency: required for generator = \"harmonic\""
        );
        let e = err(&edit("frequency = 2.0", "frequency = 80.0"));
        assert!(
            e.starts_with("cfg.toml: ground_motion.frequency: must be below the Nyquist"),
            "{e}"
        );
    }

    // --- error_force.kind = "arx" and [substructure.phase_lag] ---

    fn with_tables(extra: &str) -> String {
        format!("{BASE}\n{extra}")
    }

    #[test]
    fn error_force_arx_keys() {
        let def = parse(&with_tables("[substructure.error_force]\nkind = \"arx\"\n")).unwrap();
        assert_eq!(def.substructure.unwrap().error_force, ErrorForceSpec::ARX_DEFAULT);
        let def = parse(&with_tables(
            "[substructure.error_force]\nkind = \"arx\"\norder = 12\nforgetting_factor = 0.995\np0 = 10.0\n",
        ))
        .unwrap();
        assert_eq!(
            def.substructure.unwrap().error_force,
            ErrorForceSpec::Arx {
                order: 12,
                lambda: 0.995,
                p0: 10.0
            }
        );
        for (extra, key) in [
            ("order = 1", "substructure.error_force.order: must be in 2..=12, got 1"),
            (
                "order = 13",
                "substructure.error_force.order: must be in 2..=12, got 13",
            ),
            (
                "forgetting_factor = 0.0",
                "substructure.error_force.forgetting_factor: must be in (0, 1]",
            ),
            (
                "forgetting_factor = 1.5",
                "substructure.error_force.forgetting_factor: must be in (0, 1]",
            ),
            ("p0 = -1.0", "substructure.error_force.p0"),
        ] {
            let e = err(&with_tables(&format!(
                "[substructure.error_force]\nkind = \"arx\"\n{extra}\n"
            )));
            assert!(e.starts_with(&format!("cfg.toml: {key}")), "{e}");
        }
        let e = err(&with_tables("[substructure.error_force]\nkind = \"arx\"\np = 1.0\n"));
        assert!(e.contains("unknown field `p`"), "{e}");
    }

    #[test]
    fn phase_lag_kinds_and_defaults() {
        let delayed = |extra: &str| {
            with_tables(&format!("[substructure.phase_lag]\n{extra}\n")).replacen(
                "zeta = 0.7",
                "zeta = 0.7\ndelay = 0.005",
                1,
            )
        };
        // Δτ = 2.5 ms, delay 5 ms: default lead 2 sub-steps, default k_lag 2.
        let def = parse(&delayed("kind = \"polynomial\"")).unwrap();
        let pl = def.substructure.as_ref().unwrap().phase_lag.unwrap();
        assert_eq!(
            pl.spec,
            PhaseLagSpec::Polynomial {
                order: 3,
                lead: 2.0,
                guard_factor: 10.0
            }
        );
        assert_eq!(pl.ramp, Ramp::new(0, DEFAULT_RAMP_STEPS * 4));
        let def = parse(&delayed(
            "kind = \"arx\"\nn_u = 3\nramp_start = 10\nramp_steps = 20\nfade_out = [90, 5]",
        ))
        .unwrap();
        let pl = def.substructure.as_ref().unwrap().phase_lag.unwrap();
        match pl.spec {
            PhaseLagSpec::Arx(a) => assert_eq!((a.k_lag, a.n_u, a.lambda), (2, 3, 0.99)),
            other => panic!("{other:?}"),
        }
        assert_eq!(pl.ramp, Ramp::new(40, 80).with_fade_out(360, 20));
        let def = parse(&delayed("kind = \"inverse_fir\"\nlead = 0.01\ntaps = 6")).unwrap();
        match def.substructure.as_ref().unwrap().phase_lag.unwrap().spec {
            PhaseLagSpec::InverseFir(f) => assert_eq!((f.lead, f.taps, f.order), (4.0, 6, 2)),
            other => panic!("{other:?}"),
        }
        let def = parse(&delayed("kind = \"none\"")).unwrap();
        assert!(def.substructure.as_ref().unwrap().phase_lag.is_none());
        // The test is built with the compensated site.
        let def = parse(&delayed("kind = \"arx\"")).unwrap();
        let s = def.substructure.as_ref().unwrap();
        let test = s.build_test(&def.model, 0.01, &DVector::zeros(3)).unwrap();
        assert!(test.site.phase_lag().is_some());
    }

    #[test]
    fn phase_lag_bad_values_name_the_key() {
        let p = "cfg.toml: substructure.phase_lag.";
        for (extra, expect) in [
            (
                "kind = \"polynomial\"\norder = 4",
                "order: polynomial extrapolation supports orders 1 to 3",
            ),
            ("kind = \"polynomial\"\nlead = -0.01", "lead: "),
            (
                "kind = \"polynomial\"\nlead = 0.01\nlead_substeps = 4.0",
                "lead_substeps: give either",
            ),
            (
                "kind = \"polynomial\"\nk_lag = 4",
                "k_lag: is not used with kind = \"polynomial\"",
            ),
            ("kind = \"arx\"\nn_u = 13", "n_u: must be in 1..=12"),
            (
                "kind = \"arx\"\nforgetting_factor = 1.5",
                "forgetting_factor: must be in (0, 1]",
            ),
            ("kind = \"arx\"\nk_lag = 0", "k_lag: must be at least 1"),
            ("kind = \"arx\"\nk_lag = 100000", "k_lag: k_lag larger than the history"),
            ("kind = \"arx\"\norder = 2", "order: is not used with kind = \"arx\""),
            (
                "kind = \"arx\"\nguard_factor = 0.0",
                "guard_factor: must be a finite number > 0",
            ),
            ("kind = \"inverse_fir\"\ntaps = 0", "taps: must be in 1..=64"),
            (
                "kind = \"inverse_fir\"\nforgetting_factor = 0.0",
                "forgetting_factor: must be in (0, 1]",
            ),
            (
                "kind = \"arx\"\nramp_steps = 10\nfade_out = [5, 3]",
                "fade_out: begins at sub-step 20",
            ),
            ("kind = \"none\"\nn_u = 3", "n_u: is not used with kind = \"none\""),
            ("kind = \"smith\"", "kind: unknown kind 'smith'"),
        ] {
            let e = err(&with_tables(&format!("[substructure.phase_lag]\n{extra}\n")));
            assert!(e.starts_with(&format!("{p}{expect}")), "{extra}: {e}");
        }
    }
}
