//! `SITE.toml` for `substep site serve`: which protocol to serve, where, and the experimental
//! substructure the site hosts (documented in `docs/config.md`, section "Site").
//!
//! ```toml
//! [site]
//! protocol = "substep"        # substep | openfresco
//! listen = "127.0.0.1:8090"
//! transport = "tcp"           # substep protocol: tcp | udp
//! inner_steps = 10            # as [substructure] inner_steps
//! idle_timeout = 30.0         # s; drop a silent client
//!
//! [[specimen]]                # same kinds as [[substructure.specimen]]; dof = model DOF of the client
//! kind = "linear_sdof"        # openfresco: also kind = "linear_element" (stiffness, damping, mass
//! dof = 2                     # matrices over the element DOFs the client declares)
//! mass = 50.0
//! stiffness = 1973.92
//! damping = 62.83
//!
//! [actuator]                  # optional, as [substructure.actuator]
//! [sensors]                   # optional, as [substructure.sensors]
//! ```

use super::config::{MatrixInput, RawActuator, RawSensors, RawSpecimen, matrix, toml_error};
use crate::error::{Error, Result, require_positive};
use crate::site::openfresco::ElementSpec;
use crate::site::{Transport, VirtualLabSpec};
use crate::transfer::{ActuatorSpec, Dynamics, SensorSpec};
use serde::Deserialize;
use std::path::Path;
use std::time::Duration;

/// What `substep site serve` hosts.
#[derive(Debug, Clone)]
pub enum SiteDefinition {
    /// The project's protocol: a virtual lab built for each client's coupling DOFs.
    Substep {
        listen: String,
        transport: Transport,
        idle_timeout: Option<Duration>,
        lab: VirtualLabSpec,
    },
    /// OpenFresco's generic TCP protocol: one element.
    OpenFresco {
        listen: String,
        idle_timeout: Option<Duration>,
        element: ElementSpec,
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSite {
    site: RawSiteSection,
    #[serde(default)]
    specimen: Vec<toml::Value>,
    actuator: Option<RawActuator>,
    sensors: Option<RawSensors>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSiteSection {
    protocol: String,
    listen: String,
    transport: Option<String>,
    inner_steps: Option<usize>,
    idle_timeout: Option<f64>,
    /// Time step assumed for velocities of a specimen hosted for OpenFresco clients [s].
    dt: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLinearElement {
    #[allow(dead_code)]
    kind: String,
    stiffness: MatrixInput,
    damping: Option<MatrixInput>,
    mass: Option<MatrixInput>,
    #[serde(default)]
    damping_to_client: bool,
}

/// DOF numbers in a site file are not bounded by a model; this only rejects 0.
const MAX_DOF: usize = 1 << 20;

impl SiteDefinition {
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(&name, format!("cannot read file: {e}")))?;
        let base = path.parent().unwrap_or(Path::new("."));
        Self::from_toml(&text, &name, base)
    }

    pub fn from_toml(text: &str, name: &str, base: &Path) -> Result<Self> {
        let raw: RawSite = toml::from_str(text).map_err(|e| toml_error(&e, text, name))?;
        raw.build(base).map_err(|e| match e {
            Error::InvalidInput { what, reason } => Error::invalid(format!("{name}: {what}"), reason),
            other => other,
        })
    }

    pub fn listen(&self) -> &str {
        match self {
            SiteDefinition::Substep { listen, .. } | SiteDefinition::OpenFresco { listen, .. } => listen,
        }
    }
}

impl RawSite {
    fn build(self, base: &Path) -> Result<SiteDefinition> {
        let s = &self.site;
        let idle_timeout = s
            .idle_timeout
            .map(|t| require_positive("site.idle_timeout", t))
            .transpose()?
            .map(Duration::from_secs_f64);
        if self.specimen.is_empty() {
            return Err(Error::invalid(
                "specimen",
                "no specimen given (add a [[specimen]] table)",
            ));
        }
        let kind_of = |v: &toml::Value| v.get("kind").and_then(|k| k.as_str()).unwrap_or("").to_string();
        match s.protocol.as_str() {
            "substep" => {
                let transport = match s.transport.as_deref().unwrap_or("tcp") {
                    "tcp" => Transport::Tcp,
                    "udp" => Transport::Udp,
                    other => {
                        return Err(Error::invalid(
                            "site.transport",
                            format!("unknown transport '{other}' (expected tcp or udp)"),
                        ));
                    }
                };
                let mut specimens = Vec::new();
                for (k, v) in self.specimen.iter().enumerate() {
                    let what = format!("specimen[{}]", k + 1);
                    if kind_of(v) == "linear_element" {
                        return Err(Error::invalid(
                            format!("{what}.kind"),
                            "linear_element is served with protocol = \"openfresco\"",
                        ));
                    }
                    let raw: RawSpecimen = v
                        .clone()
                        .try_into()
                        .map_err(|e: toml::de::Error| Error::invalid(&what, e.message().to_string()))?;
                    specimens.push(raw.to_spec(MAX_DOF, &what, base)?);
                }
                let actuator = match &self.actuator {
                    Some(a) => a.spec()?,
                    None => ActuatorSpec::ideal(),
                };
                actuator.validate()?;
                if let Some(r) = &self.sensors {
                    // A site derives its channels' seeds itself and has no D/A stage yet.
                    if r.shared_noise() {
                        return Err(Error::invalid(
                            "sensors.shared_noise",
                            "is not supported by a site (each channel gets its own sequence)",
                        ));
                    }
                    if !matches!(r.command_converter(), Ok(None)) {
                        return Err(Error::invalid(
                            "sensors.command_range",
                            "the D/A converter on the commands is not supported by a site",
                        ));
                    }
                }
                let (force_sensor, displacement_sensor) = match &self.sensors {
                    Some(r) => r.base_specs().map_err(|e| match e {
                        Error::InvalidInput { what, reason } => {
                            Error::invalid(what.replace("substructure.sensors", "sensors"), reason)
                        }
                        other => other,
                    })?,
                    None => (SensorSpec::ideal(), SensorSpec::ideal()),
                };
                let inner_steps = match s.inner_steps {
                    Some(0) => return Err(Error::invalid("site.inner_steps", "must be at least 1")),
                    Some(k) => k,
                    None if actuator.dynamics == Dynamics::Ideal && actuator.delay == 0.0 => 1,
                    None => 10,
                };
                Ok(SiteDefinition::Substep {
                    listen: s.listen.clone(),
                    transport,
                    idle_timeout,
                    lab: VirtualLabSpec {
                        specimens,
                        actuator,
                        force_sensor,
                        displacement_sensor,
                        inner_steps,
                    },
                })
            }
            "openfresco" => {
                if self.specimen.len() != 1 {
                    return Err(Error::invalid(
                        "specimen",
                        "an OpenFresco site hosts exactly one element ([[specimen]] table)",
                    ));
                }
                for (key, given) in [
                    ("site.transport", s.transport.is_some()),
                    ("actuator", self.actuator.is_some()),
                    ("sensors", self.sensors.is_some()),
                ] {
                    if given {
                        return Err(Error::invalid(key, "is not used with protocol = \"openfresco\""));
                    }
                }
                let v = &self.specimen[0];
                let element = if kind_of(v) == "linear_element" {
                    let raw: RawLinearElement = v
                        .clone()
                        .try_into()
                        .map_err(|e: toml::de::Error| Error::invalid("specimen[1]", e.message().to_string()))?;
                    ElementSpec::LinearElement {
                        stiffness: matrix(&raw.stiffness, "specimen[1].stiffness", base)?,
                        damping: raw
                            .damping
                            .as_ref()
                            .map(|m| matrix(m, "specimen[1].damping", base))
                            .transpose()?,
                        mass: raw
                            .mass
                            .as_ref()
                            .map(|m| matrix(m, "specimen[1].mass", base))
                            .transpose()?,
                        damping_to_client: raw.damping_to_client,
                    }
                } else {
                    let raw: RawSpecimen = v
                        .clone()
                        .try_into()
                        .map_err(|e: toml::de::Error| Error::invalid("specimen[1]", e.message().to_string()))?;
                    let dt = require_positive("site.dt", s.dt.unwrap_or(0.01))?;
                    ElementSpec::Specimen {
                        spec: raw.to_spec(MAX_DOF, "specimen[1]", base)?,
                        default_dt: dt,
                    }
                };
                element.build()?; // validate now, not at the first connection
                Ok(SiteDefinition::OpenFresco {
                    listen: s.listen.clone(),
                    idle_timeout,
                    element,
                })
            }
            other => Err(Error::invalid(
                "site.protocol",
                format!("unknown protocol '{other}' (expected substep or openfresco)"),
            )),
        }
    }
}
