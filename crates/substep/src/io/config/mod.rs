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
//! One file per section of the test definition, each next to the docs/config.md section it
//! implements: `structure.rs` (`[structure]`), `ground_motion.rs`, `integrator.rs`,
//! `substructure.rs` (`[substructure]`, `[substructure.controller]`), `specimens.rs`
//! (`[[substructure.specimen]]`), `actuator.rs`, `sensors.rs`, `compensation.rs`
//! (`[substructure.error_force]`, `[substructure.phase_lag]`), `remote.rs`, `safety_limits.rs`
//! (`[substructure.limits]`), `output.rs` (`[output]`); this file holds [`TestDefinition`], the
//! top-level `RawConfig` with the run-size checks of `[limits]`, and the helpers every section
//! uses (matrices, DOF numbers, message prefixes).
//!
//! To add a specimen kind: add a variant to `RawSpecimen` (`specimens.rs`; its keys are the
//! variant's fields) and one arm to `RawSpecimen::to_spec`.

mod actuator;
mod common;
mod compensation;
mod emulator;
mod ground_motion;
mod integrator;
mod lab_target;
mod monitor;
mod output;
mod realtime;
mod reduction;
mod remote;
mod safety_limits;
mod sensors;
mod specimens;
mod structure;
mod substructure;
#[cfg(test)]
mod tests;

use crate::error::{Error, Result};
use crate::integrate::Scheme;
use crate::limits::{self, Limits, RunShape};
use crate::model::{Hysteresis, Model};
use crate::transfer::{ActuatorSpec, Dynamics};
pub(crate) use actuator::RawActuator;
pub(crate) use common::*;
pub use emulator::{Emulated, emulator_from_file, emulator_from_toml};
pub use ground_motion::GroundMotion;
use ground_motion::RawGroundMotion;
pub use integrator::IntegratorDefinition;
use integrator::RawIntegrator;
use monitor::RawMonitor;
pub use monitor::{MAX_TOKEN_CHARS, MIN_TOKEN_CHARS, MonitorSettings, check_token};
use output::{Format, RawOutput};
pub use output::{OutputSettings, PLOT_FIGURES, PlotOptions};
use realtime::RawRealtime;
pub use realtime::{DEFAULT_MAX_MISSED, RealtimeSettings, check_max_missed, parse_late_policy, too_many_missed};
pub use remote::{RemoteDefinition, RemoteProtocol};
pub(crate) use sensors::RawSensors;
use serde::Deserialize;
pub(crate) use specimens::RawSpecimen;
use std::path::{Path, PathBuf};
pub use structure::EXACT_REFERENCE_MAX_DOFS;
use structure::{ModelShape, RawStructure, check_exact_range};
use substructure::RawSubstructure;
pub use substructure::SubstructureDefinition;

/// A validated test definition.
#[derive(Debug, Clone)]
pub struct TestDefinition {
    /// Where the definition came from (the config path, or a name for embedded text).
    pub source: String,
    /// The numerical substructure (with a `[substructure]`, the specimens are not in it), in
    /// dense or sparse storage (`[structure] storage`).
    pub model: Model,
    /// The hysteretic springs of a nonlinear numerical substructure (`[structure.storeys.hysteresis]`);
    /// `None` for a linear one. `model` holds the initial stiffness.
    pub hysteresis: Option<Hysteresis>,
    /// A constant load applied statically before the excitation (`[structure.frame] gravity`)
    /// \[N\]; the run then starts from its static solution. Monolithic runs only.
    pub static_load: Option<nalgebra::DVector<f64>>,
    pub ground_motion: GroundMotion,
    pub integrator: IntegratorDefinition,
    pub substructure: Option<SubstructureDefinition>,
    pub output: OutputSettings,
    /// `[monitor]`: token and address of the live page (used with `--monitor`).
    pub monitor: MonitorSettings,
    /// `[realtime]`: the share of missed deadlines a `--realtime` run accepts.
    pub realtime: RealtimeSettings,
    /// `[structure.reduction]`: `model` is the reduced numerical substructure (its first DOFs
    /// are the kept ones, [`crate::model::Reduction::kept`]), and the test on the full model
    /// for the check.
    pub reduction: Option<ReducedStructure>,
}

/// A test on a reduced numerical substructure: the reduction and, for the check against the full
/// model after an offline run, the same test on the full model.
#[derive(Debug, Clone)]
pub struct ReducedStructure {
    pub reduction: crate::model::Reduction,
    /// The test on the full model (`None` when the check is off or the specimen is in a lab or
    /// at a remote site, which a second run must not drive).
    pub full: Option<Box<TestDefinition>>,
    /// Why there is no check (`None`: there is one).
    pub no_check: Option<String>,
    /// Seconds the eigen-solve and the projection took.
    pub seconds: f64,
}

impl TestDefinition {
    /// DOFs of the model that are displacements \[m\]: all of them, or a reduced model's kept
    /// ones (the rest are modal coordinates).
    pub fn physical_dofs(&self) -> usize {
        self.reduction
            .as_ref()
            .map_or(self.model.n_dofs(), |r| r.reduction.kept.len())
    }

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

    /// As [`from_toml`](Self::from_toml) for TOML text generated from a nested map (a Python
    /// dict, JSON): an error of the TOML reader names the key path in the map
    /// (`<dict>: structure.sdof.mas: unknown field ...`) instead of a line of text the user never
    /// saw.
    pub fn from_generated_toml(text: &str, name: &str, base_dir: &Path) -> Result<Self> {
        Self::from_toml(text, name, base_dir).map_err(|e| match e {
            Error::File { path, reason } if path == name => match reason
                .strip_prefix("line ")
                .and_then(|r| r.split_once(": "))
                .and_then(|(n, rest)| Some((n.parse::<usize>().ok()?, rest)))
            {
                Some((line, rest)) => {
                    // A tagged table (a specimen) is reported at its array; the unknown key's
                    // own line is the first one below that defines it.
                    let line = rest
                        .strip_prefix("unknown field `")
                        .and_then(|r| r.split_once('`'))
                        .and_then(|(key, _)| {
                            text.lines()
                                .enumerate()
                                .skip(line.saturating_sub(1))
                                .find_map(|(i, l)| {
                                    let (k, _) = l.split_once('=')?;
                                    (k.trim().trim_matches('"') == key).then_some(i + 1)
                                })
                        })
                        .unwrap_or(line);
                    Error::invalid(format!("{name}: {}", key_path_at(text, line)), rest)
                }
                None => Error::File { path, reason },
            },
            other => other,
        })
    }

    /// Step time `t_i = i·dt` \[s\].
    pub fn time(&self, step: usize) -> f64 {
        step as f64 * self.integrator.dt
    }
}

/// The dotted key path of line `line` (1-based) of TOML text written by `toml::to_string`:
/// the table header above it (`[a.b]`; the n-th `[[a.b]]` as `a.b[n]`, 0-based) and the key on
/// the line (`key = ...`).
fn key_path_at(text: &str, line: usize) -> String {
    let mut table = String::new();
    let mut counts = std::collections::BTreeMap::<String, usize>::new();
    for (i, l) in text.lines().enumerate().take(line) {
        let t = l.trim();
        if let Some(h) = t.strip_prefix("[[").and_then(|h| h.strip_suffix("]]")) {
            let h = h.trim().to_string();
            let n = counts.entry(h.clone()).and_modify(|n| *n += 1).or_insert(0);
            table = format!("{h}[{n}]");
        } else if let Some(h) = t.strip_prefix('[').and_then(|h| h.strip_suffix(']')) {
            // a sub-table of an array element stays under that element
            let h = h.trim();
            table = match counts
                .keys()
                .filter(|k| h.starts_with(&format!("{k}.")))
                .max_by_key(|k| k.len())
            {
                Some(k) => format!("{k}[{}]{}", counts[k], &h[k.len()..]),
                None => h.to_string(),
            };
        } else if i + 1 == line
            && let Some((key, _)) = t.split_once('=')
        {
            let key = key.trim().trim_matches('"');
            return if table.is_empty() {
                key.to_string()
            } else {
                format!("{table}.{key}")
            };
        }
    }
    if table.is_empty() {
        "(top level)".to_string()
    } else {
        table
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawConfig {
    pub(crate) structure: RawStructure,
    pub(crate) ground_motion: RawGroundMotion,
    pub(crate) integrator: RawIntegrator,
    pub(crate) substructure: Option<RawSubstructure>,
    #[serde(default)]
    pub(crate) output: RawOutput,
    pub(crate) limits: Option<RawRunLimits>,
    #[serde(default)]
    pub(crate) monitor: RawMonitor,
    #[serde(default)]
    pub(crate) realtime: RawRealtime,
}

/// `[limits]`: what one run may ask of the machine (docs/limits.md).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRunLimits {
    pub(crate) max_memory: Option<f64>,
    pub(crate) max_run_time: Option<f64>,
    pub(crate) max_output_bytes: Option<f64>,
    pub(crate) max_file_bytes: Option<f64>,
    pub(crate) max_record_values: Option<f64>,
}

impl RawRunLimits {
    pub(crate) fn build(&self) -> Result<Limits> {
        let d = Limits::default();
        Ok(Limits {
            max_memory: limits::limit_value("max_memory", self.max_memory, d.max_memory)?,
            max_run_time: limits::limit_value("max_run_time", self.max_run_time, d.max_run_time)?,
            max_output_bytes: limits::limit_value("max_output_bytes", self.max_output_bytes, d.max_output_bytes)?,
            max_file_bytes: limits::limit_value("max_file_bytes", self.max_file_bytes, d.max_file_bytes)?,
            max_record_values: limits::limit_value("max_record_values", self.max_record_values, d.max_record_values)?,
        })
    }
}

impl RawConfig {
    pub(crate) fn build(mut self, name: &str, base: &Path) -> Result<TestDefinition> {
        let limits = self
            .limits
            .as_ref()
            .map_or(Ok(Limits::default()), RawRunLimits::build)?;
        let (name_s, scheme, dt, duration) = self.integrator.build()?;
        let newton = self.integrator.newton()?;
        // Only the implicit Newmark schemes (and the sub-step controller) run on sparse storage.
        let sparse_capable = matches!(scheme, Scheme::Newmark { beta, .. } if beta > 0.0);
        // Limits first, from the config alone: nothing big is built, read or run before this.
        let shape = self.structure.shape(sparse_capable, &limits)?;
        // A reduced run steps and writes the reduced model (building the full one is checked
        // above); its memory stays the full model's.
        let shape = match (shape, &self.structure.reduction) {
            (Some(m), Some(r)) => {
                let n_coupling = self.substructure.as_ref().map_or(0, |s| s.coupling_dofs.len());
                let n = r.reduced_dofs_bound(n_coupling, m.n);
                Some(ModelShape {
                    n,
                    bytes: m.bytes,
                    step_seconds: RunShape::dense_step_seconds(n),
                })
            }
            (shape, _) => shape,
        };
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
        let hysteresis = self.structure.hysteresis()?;
        if hysteresis.is_some() {
            self.integrator.check_nonlinear(scheme)?;
        }
        let static_load = self.structure.static_load(&model)?;
        if static_load.is_some() {
            if !matches!(scheme, Scheme::Newmark { beta, .. } if beta > 0.0) {
                return Err(Error::invalid(
                    "structure.frame.gravity",
                    "needs an implicit Newmark scheme (the static gravity state is found by Newton–Raphson)",
                ));
            }
            if self.substructure.is_some() {
                return Err(Error::invalid(
                    "structure.frame.gravity",
                    "is for monolithic runs: the sub-step algorithm starts at rest",
                ));
            }
        }
        if shape.is_none() {
            self.check_run(&limits, ModelShape::of(&model), steps as f64, dt)?;
        }
        let mut substructure = match &self.substructure {
            None => None,
            Some(s) => Some(s.build(&model, &name_s, scheme, dt, base, &limits)?),
        };
        let mut model = model;
        // The reduced model replaces the full one; the full one stays for the check.
        let mut full_parts = None;
        let mut reduced_structure = None;
        if let Some(r) = &self.structure.reduction {
            if hysteresis.is_some() {
                return Err(Error::invalid(
                    "structure.reduction",
                    "reduces linear structures only: this one has hysteretic springs",
                ));
            }
            if static_load.is_some() {
                return Err(Error::invalid(
                    "structure.reduction",
                    "cannot be combined with structure.frame.gravity",
                ));
            }
            let coupling: Vec<usize> = self
                .substructure
                .as_ref()
                .map_or_else(Vec::new, |s| s.coupling_dofs.clone());
            let spec = r.spec(model.n_dofs(), &coupling)?;
            let start = std::time::Instant::now();
            let reduction = crate::model::Reduction::compute(&model, &spec, limits.max_memory)?;
            let seconds = start.elapsed().as_secs_f64();
            let reduced: Model = reduction.model(reduction.modes)?.into();
            let in_lab = substructure
                .as_ref()
                .is_some_and(|s| s.lab_target.is_some() || s.remote.is_some());
            let no_check = if !r.check() {
                Some("structure.reduction.check = false".to_string())
            } else if in_lab {
                Some(
                    "the specimen is in a lab or at a remote site: run the definition as a virtual test to check"
                        .into(),
                )
            } else {
                None
            };
            let full_sub = substructure.take();
            if let Some(raw) = self.substructure.as_mut() {
                reduction::renumber(raw, &reduction.kept);
                substructure = Some(raw.build(&reduced, &name_s, scheme, dt, base, &limits)?);
            }
            let full_model = std::mem::replace(&mut model, reduced);
            if no_check.is_none() {
                full_parts = Some((full_model, full_sub));
            }
            reduced_structure = Some(ReducedStructure {
                reduction,
                full: None,
                no_check,
                seconds,
            });
        }
        check_exact_range(&self.structure, &model, substructure.as_ref(), scheme, dt)?;
        if let Some(sub) = &substructure {
            // A delay longer than the test leaves the specimen at rest for the whole run (and
            // its delay line costs memory and time for nothing): a typo, refused.
            let duration = steps as f64 * dt;
            if sub.actuator.delay > duration {
                return Err(Error::invalid(
                    "substructure.actuator.delay",
                    format!(
                        "{} s is longer than the test ({} s): the specimen would never move",
                        sub.actuator.delay, duration
                    ),
                ));
            }
        }
        let mut def = TestDefinition {
            source: name.to_string(),
            model,
            hysteresis,
            static_load,
            ground_motion,
            integrator: IntegratorDefinition {
                name: name_s,
                scheme,
                dt,
                steps,
                newton,
            },
            substructure,
            output: {
                let (plots, plot_options) = self.output.plots.build()?;
                OutputSettings {
                    dir: self.output.dir.map(PathBuf::from),
                    plots,
                    plot_options,
                    format: match &self.output.format {
                        None => Format::Csv,
                        Some(f) => Format::parse("output.format", f)?,
                    },
                }
            },
            monitor: self.monitor.build()?,
            realtime: self.realtime.build()?,
            reduction: None,
        };
        if let Some(r) = reduced_structure.as_mut()
            && let Some((model, substructure)) = full_parts
        {
            r.full = Some(Box::new(TestDefinition {
                model,
                substructure,
                ..def.clone()
            }));
        }
        def.reduction = reduced_structure;
        Ok(def)
    }
}

impl RawConfig {
    /// Memory, computing time and output of the run (model `m`, `steps` steps of `dt`), checked
    /// against `limits` before anything of that size exists.
    pub(crate) fn check_run(&self, limits: &Limits, m: ModelShape, steps: f64, dt: f64) -> Result<()> {
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
