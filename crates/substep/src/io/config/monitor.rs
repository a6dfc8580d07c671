//! `[monitor]` (docs/config.md, section `[monitor]`): the defaults of `substep run --monitor`,
//! the control token and the address of the live page (docs/monitor.md).

use crate::error::{Error, Result};
use serde::Deserialize;

/// Shortest control token accepted (a config's or `--monitor-token`'s).
pub const MIN_TOKEN_CHARS: usize = 16;
/// Longest control token accepted (a request body is at most 4 KiB).
pub const MAX_TOKEN_CHARS: usize = 256;

/// `[monitor]`: used when the run has a monitor (`--monitor`); a config with this table does
/// not start one by itself.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MonitorSettings {
    /// The token the page's controls need (instead of a random one printed at start).
    pub token: Option<String>,
    /// Address of the page when `--monitor` names none (`host:port`).
    pub address: Option<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMonitor {
    pub(crate) token: Option<String>,
    pub(crate) address: Option<String>,
}

impl RawMonitor {
    pub(crate) fn build(self) -> Result<MonitorSettings> {
        if let Some(t) = &self.token {
            check_token("monitor.token", t)?;
        }
        if let Some(a) = &self.address
            && a.parse::<std::net::SocketAddr>().is_err()
        {
            return Err(Error::invalid(
                "monitor.address",
                format!(
                    "'{}' is not an address host:port (e.g. \"127.0.0.1:8080\")",
                    a.escape_debug()
                ),
            ));
        }
        Ok(MonitorSettings {
            token: self.token,
            address: self.address,
        })
    }
}

/// A control token: [`MIN_TOKEN_CHARS`] to [`MAX_TOKEN_CHARS`] visible ASCII characters (no
/// spaces); `what` names it in the message.
pub fn check_token(what: &str, token: &str) -> Result<()> {
    if token.is_empty() {
        return Err(Error::invalid(what, "is empty"));
    }
    if let Some(c) = token.chars().find(|c| !c.is_ascii_graphic()) {
        return Err(Error::invalid(
            what,
            format!("must be printable ASCII without spaces; it contains {:?}", c),
        ));
    }
    if token.len() < MIN_TOKEN_CHARS {
        return Err(Error::invalid(
            what,
            format!(
                "is {} characters; a control token needs at least {MIN_TOKEN_CHARS}",
                token.len()
            ),
        ));
    }
    if token.len() > MAX_TOKEN_CHARS {
        return Err(Error::invalid(
            what,
            format!("is {} characters; at most {MAX_TOKEN_CHARS}", token.len()),
        ));
    }
    Ok(())
}
