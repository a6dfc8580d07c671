//! The site server: hosts an experimental substructure for remote controllers over the `SSTP`
//! protocol ([`super::protocol`]), on TCP or UDP.
//!
//! One client is served at a time (a lab has one rig): a second one is answered `busy` at once.
//! The handshake is checked against the site's [`SiteLimits`] and, with a secret, authenticated
//! ([`super::auth`]) before the substructure is built per connection by the factory; silent
//! clients are dropped after `handshake_timeout` / `idle_timeout`, and no reply carries a
//! non-finite number (`docs/security.md`). In per-step mode the server runs the sub-step
//! loop itself with [`super::CommandRamp`], i.e. with the same floating-point operations as the
//! controller.
//!
//! Files: this one (handle, [`SiteServer`]), `options.rs` (settings, report), `tcp.rs` (accept
//! loop, one connection), `udp.rs`, `session.rs` (a session and the handshake checks, shared by
//! both transports), `lab_spec.rs` ([`VirtualLabSpec`]). The transports import from their
//! siblings, never from this file.

use super::SiteFactory;
use super::limits::{SessionCost, SiteLimits};
use super::protocol::{Hello, MAX_DATAGRAM};
use super::transport::POLL;
use crate::error::{Error, Result};
use crate::specimen::SpecimenSpec;
use crate::substructure::ExperimentalSubstructure;
use crate::transfer::{ActuatorSpec, SensorSpec, VirtualLab, channel_sensors};
use std::net::{SocketAddr, TcpListener, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;

mod lab_spec;
mod options;
mod session;
mod tcp;
mod udp;

pub use lab_spec::VirtualLabSpec;
pub(crate) use options::Flow;
pub use options::{ServeOptions, ServeReport};
pub(crate) use tcp::serve_tcp_sessions;
use tcp::*;
use udp::*;

/// A server running in its own thread. Dropping the handle stops the server.
pub struct ServerHandle {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Result<ServeReport>>>,
}

impl ServerHandle {
    pub(crate) fn start(
        addr: SocketAddr,
        options: &ServeOptions,
        run: impl FnOnce(ServeOptions) -> Result<ServeReport> + Send + 'static,
    ) -> Result<Self> {
        let mut options = options.clone();
        let stop = options.stop.clone().unwrap_or_default();
        options.stop = Some(stop.clone());
        let thread = std::thread::Builder::new()
            .name(format!("site-server-{addr}"))
            .spawn(move || run(options))
            .map_err(|e| Error::invalid("site server", format!("cannot start the server thread: {e}")))?;
        Ok(Self {
            addr,
            stop,
            thread: Some(thread),
        })
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }
    /// Whether the server has returned (e.g. a `once` server after its client left).
    pub fn is_finished(&self) -> bool {
        self.thread.as_ref().is_none_or(|t| t.is_finished())
    }
    /// Stop the server (dropping the current client, as if the site went away) and wait for it.
    pub fn stop(mut self) -> Result<ServeReport> {
        self.stop.store(true, Ordering::Relaxed);
        self.join_inner()
    }
    /// Wait until the server returns by itself.
    pub fn join(mut self) -> Result<ServeReport> {
        self.join_inner()
    }
    fn join_inner(&mut self) -> Result<ServeReport> {
        match self.thread.take() {
            Some(t) => t
                .join()
                .unwrap_or_else(|_| Err(Error::invalid("site server", "the server thread panicked"))),
            None => Ok(ServeReport::default()),
        }
    }
}

impl Drop for ServerHandle {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.join_inner();
    }
}

/// The `SSTP` site server.
pub struct SiteServer;

impl SiteServer {
    /// Serve clients on `listener` (TCP) one at a time until a `once` session ends or the stop
    /// flag is raised. Connection-level errors are logged and end that connection only; a
    /// client arriving while another is served is rejected at once (`busy`).
    pub fn serve(
        listener: TcpListener,
        mut factory: impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>>,
        options: &ServeOptions,
    ) -> Result<ServeReport> {
        options
            .limits
            .validate()
            .map_err(|(k, r)| Error::invalid(format!("site.{k}"), r))?;
        serve_tcp_sessions(listener, options, "site", tell_busy, |stream, peer, report| Flow {
            opened: serve_tcp_connection(stream, peer, &mut factory, options, report),
            shutdown: false,
        })
    }

    /// [`SiteServer::serve`] in a new thread.
    pub fn spawn(
        listener: TcpListener,
        factory: impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>> + Send + 'static,
        options: &ServeOptions,
    ) -> Result<ServerHandle> {
        let addr = listener
            .local_addr()
            .map_err(|e| Error::invalid("site server", e.to_string()))?;
        ServerHandle::start(addr, options, move |o| Self::serve(listener, factory, &o))
    }

    /// Serve over UDP: one datagram per message, one client session at a time. A request
    /// repeated with the same sequence number gets the cached reply (the site is not moved
    /// twice); a `Hello` from another address while a session is active is rejected.
    pub fn serve_udp(
        socket: UdpSocket,
        mut factory: impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>>,
        options: &ServeOptions,
    ) -> Result<ServeReport> {
        options
            .limits
            .validate()
            .map_err(|(k, r)| Error::invalid(format!("site.{k}"), r))?;
        let local = socket
            .local_addr()
            .map_err(|e| Error::invalid("site server", e.to_string()))?;
        socket
            .set_read_timeout(Some(POLL))
            .map_err(|e| Error::invalid(format!("site server udp://{local}"), e.to_string()))?;
        options.log(&format!("site: listening on udp://{local}"));
        let mut udp = UdpServer {
            socket,
            session: None,
            closed: None,
            pending: Vec::new(),
            report: ServeReport::default(),
            tx: Vec::new(),
        };
        let mut buf = vec![0u8; MAX_DATAGRAM + 1];
        loop {
            if options.stopped() {
                options.log(&format!("site: udp://{local} stopped"));
                return Ok(udp.report);
            }
            if let (Some(s), Some(limit)) = (&udp.session, options.idle_timeout)
                && s.last_seen.elapsed() > limit
            {
                udp.send_session_error(0, "session ended: idle timeout");
                udp.end_session(options, &format!("idle for more than {:.3} s", limit.as_secs_f64()));
                udp.report.errors += 1;
                if options.once {
                    return Ok(udp.report);
                }
            }
            udp.pending.retain(|p| p.since.elapsed() <= options.handshake_timeout);
            let (n, from) = match udp.socket.recv_from(&mut buf) {
                Ok(x) => x,
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock
                            | std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::Interrupted
                            | std::io::ErrorKind::ConnectionReset
                            | std::io::ErrorKind::ConnectionRefused
                    ) =>
                {
                    continue;
                }
                Err(e) => {
                    return Err(Error::invalid(
                        format!("site server udp://{local}"),
                        format!("receive failed: {e}"),
                    ));
                }
            };
            if !options.allows(&from) {
                udp.report.rejected += 1;
                continue;
            }
            let ended = udp.datagram(&buf[..n], from, &mut factory, options);
            if ended && options.once {
                return Ok(udp.report);
            }
        }
    }

    /// [`SiteServer::serve_udp`] in a new thread.
    pub fn spawn_udp(
        socket: UdpSocket,
        factory: impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>> + Send + 'static,
        options: &ServeOptions,
    ) -> Result<ServerHandle> {
        let addr = socket
            .local_addr()
            .map_err(|e| Error::invalid("site server", e.to_string()))?;
        ServerHandle::start(addr, options, move |o| Self::serve_udp(socket, factory, &o))
    }

    /// Box a factory closure (for APIs that store it).
    pub fn boxed_factory(
        factory: impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>> + Send + 'static,
    ) -> SiteFactory {
        Box::new(factory)
    }
}
