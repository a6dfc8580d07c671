//! The target file of `substep lab emulate` (docs/lab.md): the emulator's settings and the
//! virtual lab of the test definition it names.

use super::TestDefinition;
use super::common::toml_error;
use super::lab_target::resolve;
use crate::error::{Error, Result};
use crate::lab::{EmulatorSpec, Faults};
use serde::Deserialize;
use std::path::Path;
use std::time::Duration;

/// The target file of `substep lab emulate`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEmulator {
    test: String,
    bind: Option<String>,
    idle: Option<f64>,
    faults: Option<RawFaults>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFaults {
    loss: Option<f64>,
    duplicate: Option<f64>,
    reorder: Option<f64>,
    stall: Option<[f64; 2]>,
    die_at: Option<f64>,
    seed: Option<u64>,
}

/// Read a `substep lab emulate` target file: the emulator's spec and the virtual lab of its
/// test definition (which must have a `[substructure.lab]`: protocol, transport, channels and,
/// unless `bind` is given, the address to serve).
pub fn emulator_from_file(path: &Path) -> Result<Emulated> {
    let name = path.display().to_string();
    let text = crate::limits::read_text(path, crate::limits::CONFIG_MAX_BYTES)?;
    emulator_from_toml(&text, &name, path.parent().unwrap_or(Path::new("")))
}

/// The emulator and its virtual lab.
pub type Emulated = (EmulatorSpec, Box<dyn crate::substructure::ExperimentalSubstructure>);

/// As [`emulator_from_file`] from the file's text; `name` names it in errors, `base` is the
/// directory `test` is relative to.
pub fn emulator_from_toml(text: &str, name: &str, base: &Path) -> Result<Emulated> {
    let name = name.to_string();
    let raw: RawEmulator = toml::from_str(text).map_err(|e| toml_error(&e, text, &name))?;
    let def = TestDefinition::from_file(base.join(&raw.test))?;
    let sub = def
        .substructure
        .as_ref()
        .ok_or_else(|| Error::invalid(format!("{name}: test"), "the test has no [substructure]"))?;
    let target = sub.lab_target.as_ref().ok_or_else(|| {
        Error::invalid(
            format!("{name}: test"),
            "the test has no [substructure.lab] (its protocol, transport and channels are the target's)",
        )
    })?;
    let bind = match &raw.bind {
        Some(b) => resolve(&format!("{name}: bind"), b)?,
        None => target.address,
    };
    let f = raw.faults.as_ref();
    let faults = Faults {
        loss: f.and_then(|f| f.loss).unwrap_or(0.0),
        duplicate: f.and_then(|f| f.duplicate).unwrap_or(0.0),
        reorder: f.and_then(|f| f.reorder).unwrap_or(0.0),
        stall: f.and_then(|f| f.stall).map(|[a, d]| (a, d)),
        die_at: f.and_then(|f| f.die_at),
        seed: f.and_then(|f| f.seed).unwrap_or(1),
    };
    faults.validate(&format!("{name}: faults"))?;
    let idle = raw.idle.unwrap_or(30.0);
    if !(idle.is_finite() && idle > 0.0 && idle <= 3600.0) {
        return Err(Error::invalid(
            format!("{name}: idle"),
            format!("must be 0 to 3600 s, got {idle}"),
        ));
    }
    let dt = def.integrator.dt;
    let lab = sub.virtual_lab(dt)?;
    let spec = EmulatorSpec {
        protocol: target.protocol,
        transport: target.transport,
        bind,
        map: target.map.clone(),
        dt,
        k_sub: sub.substeps,
        accel: def.ground_motion.accel.clone(),
        faults,
        idle: Duration::from_secs_f64(idle),
    };
    Ok((spec, Box::new(lab)))
}
