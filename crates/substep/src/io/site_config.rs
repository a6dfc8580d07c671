//! `SITE.toml` for `substep site serve`: which protocol to serve, where, and the experimental
//! substructure the site hosts (documented in `docs/config.md`, section "Site").
//!
//! ```toml
//! [site]
//! protocol = "substep"        # substep | openfresco
//! listen = "127.0.0.1:8090"   # the default; another interface needs a secret (or an allow-list)
//! transport = "tcp"           # substep protocol: tcp | udp
//! inner_steps = 10            # as [substructure] inner_steps
//! idle_timeout = 10.0         # s; drop a silent client (default 10)
//! secret_file = "site.key"    # substep protocol: only clients proving this secret (or $SUBSTEP_SITE_SECRET)
//! allow = ["127.0.0.1"]       # client addresses allowed to connect (default: any)
//! max_substeps = 1000         # limits of what one client may ask (docs/security.md)
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
use crate::error::{Error, Result, require_duration, require_positive};
use crate::site::openfresco::ElementSpec;
use crate::site::{Secret, SiteLimits, Transport, VirtualLabSpec};
use crate::transfer::{ActuatorSpec, Dynamics, SensorSpec};
use serde::Deserialize;
use std::net::IpAddr;
use std::path::Path;
use std::time::Duration;

/// Address a site listens on when `[site] listen` is not given: this machine only.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:8090";

/// How a site serves, whatever it hosts: timeouts, limits, who may connect.
#[derive(Debug, Clone)]
pub struct ServerSettings {
    pub listen: String,
    /// `[site] idle_timeout` (default 10 s).
    pub idle_timeout: Duration,
    /// `[site] handshake_timeout` (default 2 s).
    pub handshake_timeout: Duration,
    pub limits: SiteLimits,
    /// `[site] secret_file`, else the environment variable `SUBSTEP_SITE_SECRET`.
    pub secret: Option<Secret>,
    /// `[site] allow`.
    pub allow: Option<Vec<IpAddr>>,
}

/// What `substep site serve` hosts.
#[derive(Debug, Clone)]
pub enum SiteDefinition {
    /// The project's protocol: a virtual lab built for each client's coupling DOFs.
    Substep {
        server: ServerSettings,
        transport: Transport,
        lab: VirtualLabSpec,
    },
    /// OpenFresco's generic TCP protocol: one element.
    OpenFresco {
        server: ServerSettings,
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
    listen: Option<String>,
    transport: Option<String>,
    inner_steps: Option<usize>,
    idle_timeout: Option<f64>,
    handshake_timeout: Option<f64>,
    secret_file: Option<String>,
    allow: Option<Vec<String>>,
    max_coupling: Option<usize>,
    max_substeps: Option<usize>,
    min_dtau: Option<f64>,
    max_dt: Option<f64>,
    /// [MB]
    max_session_memory: Option<f64>,
    max_request_work: Option<f64>,
    /// [s]
    ramp_time: Option<f64>,
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
        // Bounded, regular files only (as a test definition): `/dev/zero` or a FIFO is refused.
        let text = crate::limits::read_text(path, crate::limits::CONFIG_MAX_BYTES)?;
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
        &self.server().listen
    }

    pub fn server(&self) -> &ServerSettings {
        match self {
            SiteDefinition::Substep { server, .. } | SiteDefinition::OpenFresco { server, .. } => server,
        }
    }
}

impl RawSiteSection {
    fn server(&self, base: &Path) -> Result<ServerSettings> {
        let idle_timeout = require_duration("site.idle_timeout", self.idle_timeout.unwrap_or(10.0))?;
        let handshake_timeout = require_duration("site.handshake_timeout", self.handshake_timeout.unwrap_or(2.0))?;
        let d = SiteLimits::default();
        let count = |key: &str, v: Option<usize>, default: usize| -> Result<usize> {
            match v {
                Some(0) => Err(Error::invalid(format!("site.{key}"), "must be at least 1")),
                Some(x) => Ok(x),
                None => Ok(default),
            }
        };
        let max_session_bytes = match self.max_session_memory {
            None => d.max_session_bytes,
            Some(mb) => {
                if !(mb.is_finite() && mb > 0.0 && mb <= 1e6) {
                    return Err(Error::invalid(
                        "site.max_session_memory",
                        format!("must be a number of MB in (0, 1e6], got {mb}"),
                    ));
                }
                (mb * 1e6) as usize
            }
        };
        let max_request_work = match self.max_request_work {
            None => d.max_request_work,
            Some(w) => {
                if !(w.is_finite() && (1.0..=1e15).contains(&w)) {
                    return Err(Error::invalid(
                        "site.max_request_work",
                        format!("must be a number in [1, 1e15], got {w}"),
                    ));
                }
                w as u64
            }
        };
        let limits = SiteLimits {
            max_coupling: count("max_coupling", self.max_coupling, d.max_coupling)?,
            max_substeps: count("max_substeps", self.max_substeps, d.max_substeps)?,
            min_dtau: require_positive("site.min_dtau", self.min_dtau.unwrap_or(d.min_dtau))?,
            max_dt: require_positive("site.max_dt", self.max_dt.unwrap_or(d.max_dt))?,
            max_session_bytes,
            max_request_work,
            ramp_time: self.ramp_time.unwrap_or(d.ramp_time),
        };
        limits
            .validate()
            .map_err(|(key, reason)| Error::invalid(format!("site.{key}"), reason))?;
        let secret = match &self.secret_file {
            _ if self.protocol == "openfresco" => {
                if self.secret_file.is_some() {
                    return Err(Error::invalid(
                        "site.secret_file",
                        "the openfresco protocol has no authentication; restrict it with site.allow and run it on a lab network only",
                    ));
                }
                None
            }
            Some(f) => Some(Secret::from_file(&base.join(f), "site.secret_file")?),
            None => Secret::from_env()?,
        };
        let allow = self
            .allow
            .as_ref()
            .map(|list| {
                list.iter()
                    .enumerate()
                    .map(|(i, a)| {
                        a.trim().parse::<IpAddr>().map_err(|_| {
                            Error::invalid(
                                format!("site.allow[{}]", i + 1),
                                format!("'{a}' is not an IP address (e.g. \"192.168.1.20\")"),
                            )
                        })
                    })
                    .collect::<Result<Vec<_>>>()
            })
            .transpose()?;
        let listen = self.listen.clone().unwrap_or_else(|| DEFAULT_LISTEN.to_string());
        Ok(ServerSettings {
            listen,
            idle_timeout,
            handshake_timeout,
            limits,
            secret,
            allow,
        })
    }
}

impl RawSite {
    fn build(self, base: &Path) -> Result<SiteDefinition> {
        let s = &self.site;
        let server = s.server(base)?;
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
                    server,
                    transport,
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
                Ok(SiteDefinition::OpenFresco { server, element })
            }
            other => Err(Error::invalid(
                "site.protocol",
                format!("unknown protocol '{other}' (expected substep or openfresco)"),
            )),
        }
    }
}
