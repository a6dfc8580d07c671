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
//! Files: this one (options, report, handle, [`SiteServer`]), `tcp.rs` (accept loop, one
//! connection), `udp.rs`, `session.rs` (a session and the handshake checks, shared by both
//! transports), `lab_spec.rs` ([`VirtualLabSpec`]).

use super::auth::{MAC_LEN, NONCE_LEN, Role, Secret, SessionKeys, TAG_LEN, nonce};
use super::limits::{MAX_SITE_RAMP_SUBSTEPS, SessionCost, SiteLimits};
use super::protocol::{
    AUTH_FAILED, HEADER_LEN, Header, Hello, MAX_DATAGRAM, MAX_REASON, Message, MessageType, Mode, Session, StepReply,
    VERSION_AUTHENTICATED, as_auth_failure, decode_frame, hello_payload_len, open_sealed,
};
use super::transport::{LinkError, POLL, read_frame, read_full, write_all};
use super::{CommandRamp, LogFn, SiteFactory, substep_ground_acceleration};
use crate::error::{Error, Result};
use crate::specimen::SpecimenSpec;
use crate::substructure::ExperimentalSubstructure;
use crate::transfer::{ActuatorSpec, SensorSpec, VirtualLab, channel_sensors};
use std::net::{IpAddr, SocketAddr, TcpListener, TcpStream, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

mod lab_spec;
mod session;
mod tcp;
mod udp;

pub use lab_spec::VirtualLabSpec;
use session::*;
pub(crate) use tcp::serve_tcp_sessions;
use tcp::*;
use udp::*;

/// Server settings.
#[derive(Clone)]
pub struct ServeOptions {
    /// Return after the first client's session ends (instead of serving forever).
    pub once: bool,
    /// A client silent for longer than this is dropped (`None`: wait forever — not for a site
    /// reachable by others: a silent client holds the one-client site). Default 10 s.
    pub idle_timeout: Option<Duration>,
    /// Time allowed for the whole handshake (Hello, and Auth with a secret). Default 2 s.
    pub handshake_timeout: Duration,
    /// Time allowed for the rest of a frame once its header arrived, and for each write.
    pub io_timeout: Duration,
    /// What one client may ask of the site (checked before anything is built).
    pub limits: SiteLimits,
    /// With a secret, only clients that prove they know it get a session ([`super::auth`]).
    pub secret: Option<Secret>,
    /// Client addresses allowed to connect (`None`: any). Others are dropped unanswered.
    pub allow: Option<Vec<IpAddr>>,
    /// One-line log messages (connections, rejections, errors).
    pub log: Option<LogFn>,
    /// Raising this flag stops the server within ~25 ms (the current client is dropped).
    pub stop: Option<Arc<AtomicBool>>,
}

impl Default for ServeOptions {
    fn default() -> Self {
        Self {
            once: false,
            idle_timeout: Some(Duration::from_secs(10)),
            handshake_timeout: Duration::from_secs(2),
            io_timeout: Duration::from_secs(5),
            limits: SiteLimits::default(),
            secret: None,
            allow: None,
            log: None,
            stop: None,
        }
    }
}

impl std::fmt::Debug for ServeOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ServeOptions")
            .field("once", &self.once)
            .field("idle_timeout", &self.idle_timeout)
            .field("handshake_timeout", &self.handshake_timeout)
            .field("io_timeout", &self.io_timeout)
            .field("limits", &self.limits)
            .field("secret", &self.secret)
            .field("allow", &self.allow)
            .field("log", &self.log.is_some())
            .finish()
    }
}

impl ServeOptions {
    pub(crate) fn log(&self, line: &str) {
        if let Some(log) = &self.log {
            log(line);
        }
    }
    pub(crate) fn stopped(&self) -> bool {
        self.stop.as_ref().is_some_and(|s| s.load(Ordering::Relaxed))
    }
    /// Whether `peer` passes the allow-list.
    pub fn allows(&self, peer: &SocketAddr) -> bool {
        let ip = match peer.ip() {
            IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(IpAddr::V6(v6), IpAddr::V4),
            v4 => v4,
        };
        self.allow.as_ref().is_none_or(|list| list.contains(&ip))
    }
    /// `now + d`, or no deadline if that does not fit an `Instant`.
    pub(crate) fn deadline(d: Option<Duration>) -> Option<Instant> {
        d.and_then(|d| Instant::now().checked_add(d))
    }
}

/// What a server did before it returned.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ServeReport {
    /// Sessions opened (accepted handshakes).
    pub sessions: usize,
    /// Connections or handshakes rejected, and sessions ended by an error.
    pub rejected: usize,
    pub errors: usize,
    /// Sub-steps executed by the hosted substructures (both modes), and per-step requests.
    pub substeps: u64,
    pub steps: u64,
    /// UDP datagrams from a session's client address dropped because they failed
    /// authentication (not executed).
    pub dropped: u64,
}

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

/// What a connection handler tells the accept loop.
pub(crate) struct Flow {
    /// A session was opened (for `once`).
    pub opened: bool,
    /// The client asked the server to shut down.
    pub shutdown: bool,
}

enum Incoming {
    Conn(TcpStream, SocketAddr),
    Failed(Error),
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
