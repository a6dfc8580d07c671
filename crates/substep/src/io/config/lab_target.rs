//! `[substructure.lab]` (docs/config.md): a lab's real-time target as the experimental side
//! (the target file of `substep lab emulate` is `emulator.rs`).

use crate::error::{Error, Result};
use crate::lab::{ChannelMap, CommandChannel, LabProtocol, LabTargetSpec, LinkTransport, MeasuredChannel, Quantity};
use serde::Deserialize;
use std::net::{SocketAddr, ToSocketAddrs};
use std::time::Duration;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLabTarget {
    pub(crate) protocol: String,
    pub(crate) transport: Option<String>,
    pub(crate) address: String,
    pub(crate) local_address: Option<String>,
    #[serde(default)]
    pub(crate) allow_remote: bool,
    pub(crate) timeout: Option<f64>,
    pub(crate) hold_limit: Option<usize>,
    pub(crate) signals: Option<usize>,
    #[serde(default)]
    pub(crate) command: Vec<RawCommandChannel>,
    #[serde(default)]
    pub(crate) measured: Vec<RawMeasuredChannel>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawCommandChannel {
    pub(crate) dof: usize,
    pub(crate) gain: Option<f64>,
    pub(crate) offset: Option<f64>,
    pub(crate) saturation: Option<[f64; 2]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMeasuredChannel {
    pub(crate) signal: usize,
    pub(crate) quantity: String,
    pub(crate) dof: usize,
    pub(crate) gain: Option<f64>,
    pub(crate) offset: Option<f64>,
}

pub(crate) fn resolve(key: &str, text: &str) -> Result<SocketAddr> {
    text.to_socket_addrs()
        .map_err(|e| Error::invalid(key, format!("'{text}' is not host:port ({e})")))?
        .next()
        .ok_or_else(|| Error::invalid(key, format!("'{text}' resolves to no address")))
}

/// A 1-based index from the config, as 0-based; `what` names it.
fn one_based(key: &str, v: usize) -> Result<usize> {
    v.checked_sub(1)
        .ok_or_else(|| Error::invalid(key, "counts from 1, got 0"))
}

impl RawLabTarget {
    /// For a test with `coupling` coupling DOFs (config numbers: `coupling_numbers`, the DOF
    /// numbers of `coupling_dofs`, which the channel tables use).
    pub(crate) fn build(&self, coupling_numbers: &[usize]) -> Result<LabTargetSpec> {
        let p = "substructure.lab.";
        let protocol = match self.protocol.as_str() {
            "speedgoat" => LabProtocol::Speedgoat,
            "generic_tcp" => LabProtocol::GenericTcp,
            "substep_udp" => LabProtocol::SubstepUdp,
            other => {
                return Err(Error::invalid(
                    format!("{p}protocol"),
                    format!("unknown protocol '{other}' (expected speedgoat, generic_tcp or substep_udp)"),
                ));
            }
        };
        let default_transport = match protocol {
            LabProtocol::GenericTcp => "tcp",
            _ => "udp",
        };
        let transport = match self.transport.as_deref().unwrap_or(default_transport) {
            "udp" => LinkTransport::Udp,
            "tcp" => LinkTransport::Tcp,
            other => {
                return Err(Error::invalid(
                    format!("{p}transport"),
                    format!("unknown transport '{other}' (expected udp or tcp)"),
                ));
            }
        };
        match (protocol, transport) {
            (LabProtocol::GenericTcp, LinkTransport::Udp) => {
                return Err(Error::invalid(format!("{p}transport"), "generic_tcp runs over tcp"));
            }
            (LabProtocol::SubstepUdp, LinkTransport::Tcp) => {
                return Err(Error::invalid(format!("{p}transport"), "substep_udp runs over udp"));
            }
            _ => {}
        }
        let address = resolve(&format!("{p}address"), &self.address)?;
        if !address.ip().is_loopback() && !self.allow_remote {
            return Err(Error::invalid(
                format!("{p}address"),
                format!(
                    "{address} is not a loopback address: a test that moves real actuators over the network needs \
                     allow_remote = true in [substructure.lab]"
                ),
            ));
        }
        let local = self
            .local_address
            .as_deref()
            .map(|a| resolve(&format!("{p}local_address"), a))
            .transpose()?;
        if local.is_some() && transport != LinkTransport::Udp {
            return Err(Error::invalid(
                format!("{p}local_address"),
                "is for udp (the port the target sends to)",
            ));
        }
        let timeout = self.timeout.unwrap_or(0.1);
        if !(timeout.is_finite() && timeout > 0.0 && timeout <= 60.0) {
            return Err(Error::invalid(
                format!("{p}timeout"),
                format!("must be a time > 0 and at most 60 s, got {timeout}"),
            ));
        }
        let hold_limit = self.hold_limit.unwrap_or(3);
        if hold_limit > 1000 {
            return Err(Error::invalid(
                format!("{p}hold_limit"),
                format!("must be 0 to 1000 sub-steps, got {hold_limit}"),
            ));
        }
        let n_c = coupling_numbers.len();
        let dof = |key: &str, number: usize| -> Result<usize> {
            coupling_numbers.iter().position(|&d| d == number).ok_or_else(|| {
                Error::invalid(
                    key,
                    format!("DOF {number} is not a coupling DOF (coupling_dofs = {coupling_numbers:?})"),
                )
            })
        };
        let mut map = ChannelMap::default_for(n_c);
        if !self.command.is_empty() {
            map.commands = self
                .command
                .iter()
                .enumerate()
                .map(|(k, c)| {
                    let key = format!("{p}command[{}]", k + 1);
                    let [min, max] = c.saturation.unwrap_or([f64::NEG_INFINITY, f64::INFINITY]);
                    Ok(CommandChannel {
                        dof: dof(&format!("{key}.dof"), c.dof)?,
                        gain: c.gain.unwrap_or(1.0),
                        offset: c.offset.unwrap_or(0.0),
                        min,
                        max,
                    })
                })
                .collect::<Result<_>>()?;
        }
        if !self.measured.is_empty() {
            map.measured = self
                .measured
                .iter()
                .enumerate()
                .map(|(k, m)| {
                    let key = format!("{p}measured[{}]", k + 1);
                    let quantity = match m.quantity.as_str() {
                        "displacement" => Quantity::Displacement,
                        "force" => Quantity::Force,
                        other => {
                            return Err(Error::invalid(
                                format!("{key}.quantity"),
                                format!("unknown quantity '{other}' (expected displacement or force)"),
                            ));
                        }
                    };
                    Ok(MeasuredChannel {
                        signal: one_based(&format!("{key}.signal"), m.signal)?,
                        quantity,
                        dof: dof(&format!("{key}.dof"), m.dof)?,
                        gain: m.gain.unwrap_or(1.0),
                        offset: m.offset.unwrap_or(0.0),
                    })
                })
                .collect::<Result<_>>()?;
        }
        map.n_signals = self.signals.unwrap_or_else(|| {
            map.measured
                .iter()
                .map(|m| m.signal + 1)
                .max()
                .unwrap_or(0)
                .max(2 * n_c)
        });
        map.validate(n_c, "substructure.lab")?;
        if protocol == LabProtocol::GenericTcp {
            // The DAQ vector is displacements | forces (OpenFresco's order): the displacement
            // channels must come first.
            let n_disp = map
                .measured
                .iter()
                .filter(|m| m.quantity == Quantity::Displacement)
                .count();
            if let Some(m) = map
                .measured
                .iter()
                .find(|m| (m.quantity == Quantity::Displacement) != (m.signal < n_disp))
            {
                return Err(Error::invalid(
                    format!("{p}measured"),
                    format!(
                        "generic_tcp sends the displacements first, then the forces: signal {} is out of that order",
                        m.signal + 1
                    ),
                ));
            }
        }
        let spec = LabTargetSpec {
            protocol,
            transport,
            address,
            local,
            map,
            timeout: Duration::from_secs_f64(timeout),
            hold_limit,
        };
        spec.check_frames()?;
        Ok(spec)
    }
}
