//! `[substructure.remote]` (docs/config.md, section `[substructure.remote]`): a remote
//! experimental site (substep or OpenFresco protocol).

use crate::error::{Error, Result};
use crate::site::{ClientOptions, Mode, Secret, Transport};
use serde::Deserialize;
use std::path::Path;
use std::time::Duration;

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

/// `[substructure.remote]`: drive a site served by `substep site serve` (or an OpenFresco site).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRemote {
    pub(crate) address: String,
    pub(crate) protocol: Option<String>,
    pub(crate) transport: Option<String>,
    pub(crate) mode: Option<String>,
    pub(crate) timeout: Option<f64>,
    pub(crate) secret_file: Option<String>,
}

impl RawRemote {
    pub(crate) fn build(&self, base: &Path) -> Result<RemoteDefinition> {
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
