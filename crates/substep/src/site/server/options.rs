//! The server's settings, its report, and what a connection handler tells the accept loop:
//! shared by [`super::SiteServer`] and the transports (`tcp.rs`, `udp.rs`), below all of them.

use super::super::LogFn;
use super::super::auth::Secret;
use super::super::limits::SiteLimits;
use crate::error::Error;
use std::net::{IpAddr, SocketAddr, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

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
    /// With a secret, only clients that prove they know it get a session ([`crate::site::auth`]).
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

/// What a connection handler tells the accept loop.
pub(crate) struct Flow {
    /// A session was opened (for `once`).
    pub opened: bool,
    /// The client asked the server to shut down.
    pub shutdown: bool,
}

pub(crate) enum Incoming {
    Conn(TcpStream, SocketAddr),
    Failed(Error),
}
