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

use super::auth::{MAC_LEN, NONCE_LEN, Role, Secret, nonce};
use super::limits::{SessionCost, SiteLimits};
use super::protocol::{
    HEADER_LEN, Header, Hello, MAX_DATAGRAM, MAX_REASON, Message, MessageType, Mode, Session, StepReply, decode_frame,
    hello_payload_len,
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

/// Busy answers in flight at once; a client beyond that is dropped unanswered.
const MAX_BUSY_REPLIES: usize = 64;
/// How long a client arriving at a busy site waits for the slot before it is told "busy".
const BUSY_GRACE: Duration = Duration::from_millis(100);

/// Accept TCP connections and serve them one at a time until a `once` session ends, a client
/// asks for shutdown or the stop flag is raised. The accept loop runs in its own thread so a
/// second client is answered at once by `busy` (in a short-lived thread) instead of waiting
/// in the backlog; addresses not on the allow-list are dropped unanswered.
pub(crate) fn serve_tcp_sessions(
    listener: TcpListener,
    options: &ServeOptions,
    tag: &'static str,
    busy: fn(TcpStream),
    mut serve_one: impl FnMut(TcpStream, SocketAddr, &mut ServeReport) -> Flow,
) -> Result<ServeReport> {
    let local = listener
        .local_addr()
        .map_err(|e| Error::invalid(format!("{tag} server"), e.to_string()))?;
    listener
        .set_nonblocking(true)
        .map_err(|e| Error::invalid(format!("{tag} server {local}"), e.to_string()))?;
    options.log(&format!("{tag}: listening on tcp://{local}"));
    let occupied = Arc::new(AtomicBool::new(false));
    let done = Arc::new(AtomicBool::new(false));
    let refused = Arc::new(AtomicUsize::new(0));
    let (tx, rx) = mpsc::sync_channel::<Incoming>(1);
    let acceptor = {
        let (occupied, done, refused, options) = (occupied.clone(), done.clone(), refused.clone(), options.clone());
        std::thread::Builder::new()
            .name(format!("{tag}-accept-{local}"))
            .spawn(move || accept_loop(listener, &options, tag, busy, &occupied, &done, &refused, &tx))
            .map_err(|e| Error::invalid(format!("{tag} server"), format!("cannot start the accept thread: {e}")))?
    };
    let mut report = ServeReport::default();
    let result = loop {
        if options.stopped() {
            options.log(&format!("{tag}: tcp://{local} stopped"));
            break Ok(());
        }
        match rx.recv_timeout(POLL) {
            Ok(Incoming::Conn(stream, peer)) => {
                let flow = serve_one(stream, peer, &mut report);
                if flow.shutdown || (options.once && flow.opened) {
                    // still occupied: a client arriving now is told "busy", not dropped
                    break Ok(());
                }
                occupied.store(false, Ordering::SeqCst);
            }
            Ok(Incoming::Failed(e)) => break Err(e),
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) if options.stopped() => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                break Err(Error::invalid(
                    format!("{tag} server {local}"),
                    "the accept thread ended",
                ));
            }
        }
    };
    done.store(true, Ordering::SeqCst);
    let _ = acceptor.join();
    report.rejected += refused.load(Ordering::SeqCst);
    result.map(|()| report)
}

#[allow(clippy::too_many_arguments)]
fn accept_loop(
    listener: TcpListener,
    options: &ServeOptions,
    tag: &str,
    busy: fn(TcpStream),
    occupied: &Arc<AtomicBool>,
    done: &Arc<AtomicBool>,
    refused: &Arc<AtomicUsize>,
    tx: &mpsc::SyncSender<Incoming>,
) {
    let replies = Arc::new(AtomicUsize::new(0));
    let local = listener.local_addr().map(|a| a.to_string()).unwrap_or_default();
    while !done.load(Ordering::SeqCst) && !options.stopped() {
        match listener.accept() {
            Ok((stream, peer)) => {
                if !options.allows(&peer) {
                    refused.fetch_add(1, Ordering::SeqCst);
                    options.log(&format!("{tag}: {peer} refused: address not in site.allow"));
                    continue;
                }
                if occupied.swap(true, Ordering::SeqCst) {
                    // Busy. A client that reconnects right after its session ended may arrive
                    // a moment before the slot is free: give it a short grace, then "busy".
                    if replies.fetch_add(1, Ordering::SeqCst) >= MAX_BUSY_REPLIES {
                        replies.fetch_sub(1, Ordering::SeqCst);
                        refused.fetch_add(1, Ordering::SeqCst);
                        options.log(&format!(
                            "{tag}: {peer} dropped: the site is busy and answering too many others"
                        ));
                        continue;
                    }
                    let (in_flight, occupied, refused, done, tx, options) = (
                        replies.clone(),
                        occupied.clone(),
                        refused.clone(),
                        done.clone(),
                        tx.clone(),
                        options.clone(),
                    );
                    let tag = tag.to_string();
                    let spawned = std::thread::Builder::new()
                        .name(format!("{tag}-busy"))
                        .stack_size(128 << 10)
                        .spawn(move || {
                            let until = Instant::now() + BUSY_GRACE;
                            let mut stream = Some(stream);
                            while Instant::now() < until && !done.load(Ordering::SeqCst) {
                                if occupied
                                    .compare_exchange(false, true, Ordering::SeqCst, Ordering::SeqCst)
                                    .is_ok()
                                {
                                    let s = stream.take().expect("still here");
                                    let _ = tx.send(Incoming::Conn(s, peer));
                                    break;
                                }
                                std::thread::sleep(Duration::from_millis(5));
                            }
                            if let Some(s) = stream {
                                refused.fetch_add(1, Ordering::SeqCst);
                                options.log(&format!("{tag}: {peer} rejected: the site is busy with another client"));
                                busy(s);
                            }
                            in_flight.fetch_sub(1, Ordering::SeqCst);
                        });
                    if spawned.is_err() {
                        replies.fetch_sub(1, Ordering::SeqCst);
                    }
                    continue;
                }
                if tx.send(Incoming::Conn(stream, peer)).is_err() {
                    return;
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => std::thread::sleep(POLL / 5),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::ConnectionAborted | std::io::ErrorKind::ConnectionReset
                ) =>
            {
                options.log(&format!("{tag}: accept on {local}: {e}"));
            }
            // Out of descriptors or memory (e.g. a flood of connections): wait, do not exit.
            Err(e)
                if matches!(
                    e.raw_os_error(),
                    Some(libc::EMFILE | libc::ENFILE | libc::ENOBUFS | libc::ENOMEM)
                ) =>
            {
                options.log(&format!("{tag}: accept on {local}: {e}; retrying"));
                std::thread::sleep(POLL * 4);
            }
            Err(e) => {
                let _ = tx.send(Incoming::Failed(Error::invalid(
                    format!("{tag} server {local}"),
                    format!("accept failed: {e}"),
                )));
                return;
            }
        }
    }
}

/// What a busy `SSTP` site tells a second client: read its Hello (briefly, bounded), answer
/// `Reject`, and let the client read that before the connection closes.
fn tell_busy(mut stream: TcpStream) {
    const WAIT: Duration = Duration::from_millis(300);
    let _ = stream.set_nonblocking(false);
    let _ = stream.set_nodelay(true);
    let deadline = Instant::now() + WAIT;
    let mut head = [0u8; HEADER_LEN];
    let mut seq = 0;
    if read_full(&mut stream, &mut head, Some(deadline), None).is_ok()
        && let Ok(h) = Header::parse(&head)
    {
        seq = h.seq;
        discard(&mut stream, (h.len as usize).min(1 << 16), deadline);
    }
    let mut tx = Vec::new();
    Message::Reject {
        reason: "the site is busy with another client".into(),
    }
    .encode(seq, &mut tx);
    let _ = write_all(&mut stream, &tx, WAIT);
    let _ = stream.shutdown(std::net::Shutdown::Write);
    discard(&mut stream, 1 << 16, Instant::now() + WAIT);
}

/// Read and drop up to `n` bytes before `deadline`.
fn discard(stream: &mut TcpStream, n: usize, deadline: Instant) {
    let mut buf = [0u8; 4096];
    let mut left = n;
    while left > 0 {
        let now = Instant::now();
        if now >= deadline || stream.set_read_timeout(Some(deadline - now)).is_err() {
            return;
        }
        match std::io::Read::read(stream, &mut buf[..left.min(4096)]) {
            Ok(0) | Err(_) => return,
            Ok(k) => left -= k,
        }
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
                let peer = s.peer;
                udp.end_session(options, &format!("idle for more than {:.3} s", limit.as_secs_f64()));
                udp.send_error(peer, 0, "session ended: idle timeout");
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

/// One client session: the hosted substructure and the per-step machinery.
struct Hosted {
    hello: Hello,
    site: Box<dyn ExperimentalSubstructure>,
    ramp: CommandRamp,
    force: Vec<f64>,
    disp: Vec<f64>,
    command: Vec<f64>,
    reply: StepReply,
    min_dtau: f64,
    substeps: u64,
    steps: u64,
}

enum Outcome {
    Reply(Message),
    /// Reply, then end the session with the given log reason.
    Close(Message, String),
}

impl Outcome {
    fn error(reason: String) -> Self {
        Outcome::Close(Message::Error { reason: reason.clone() }, reason)
    }
}

impl Hosted {
    /// Build the session for an accepted (and, with a secret, authenticated) handshake that
    /// passed [`SiteLimits::check_hello`].
    fn open(
        hello: Hello,
        factory: &mut impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>>,
        limits: &SiteLimits,
        udp: bool,
    ) -> std::result::Result<Self, String> {
        let s = hello.session();
        if udp && HEADER_LEN + s.max_payload() > MAX_DATAGRAM {
            return Err(format!(
                "n_c = {} with k_sub = {} needs messages larger than one UDP datagram ({MAX_DATAGRAM} bytes); use TCP",
                hello.n_coupling, hello.substeps
            ));
        }
        let site = factory(&hello).map_err(|e| format!("cannot build the site: {e}"))?;
        if site.n_coupling() != hello.n_coupling {
            return Err(format!(
                "the site has {} coupling DOFs, the client asked for {}",
                site.n_coupling(),
                hello.n_coupling
            ));
        }
        let n = hello.n_coupling;
        Ok(Self {
            ramp: CommandRamp::new(n, hello.substeps, &hello.gain_cc),
            reply: StepReply::zeros(&s),
            site,
            force: vec![0.0; n],
            disp: vec![0.0; n],
            command: vec![0.0; n],
            min_dtau: limits.min_dtau,
            hello,
            substeps: 0,
            steps: 0,
        })
    }

    fn limits(&self) -> Session {
        self.hello.session()
    }

    fn describe(&self) -> String {
        format!(
            "n_c = {}, k_sub = {}, dt = {} s, {}",
            self.hello.n_coupling,
            self.hello.substeps,
            self.hello.dt,
            self.hello.mode.name()
        )
    }

    /// One sub-step with `self.command`.
    fn run_substep(&mut self, ag: (f64, f64), dtau: f64) -> std::result::Result<(), String> {
        self.site
            .substep(&self.command, ag, dtau, &mut self.force, &mut self.disp)
            .map_err(|e| format!("the site failed at sub-step {}: {e}", self.substeps + 1))?;
        self.substeps += 1;
        // Never a non-finite value on the wire: refuse instead.
        if let Some(i) = self.force.iter().position(|f| !f.is_finite()) {
            return Err(format!(
                "the site measured a non-finite force on coupling DOF {} (command {:e} m)",
                i + 1,
                self.command[i]
            ));
        }
        if let Some(i) = self.disp.iter().position(|f| !f.is_finite()) {
            return Err(format!(
                "the site measured a non-finite displacement on coupling DOF {} (command {:e} m)",
                i + 1,
                self.command[i]
            ));
        }
        Ok(())
    }

    fn handle(&mut self, msg: Message) -> Outcome {
        let mode = self.hello.mode;
        match msg {
            Message::Substep { command, ag, dtau } if mode == Mode::PerSubstep => {
                // The sub-step length sizes nothing here, but bounds the work of the specimen
                // and actuator models (and keeps their matrix exponentials in range).
                if !(dtau >= self.min_dtau && dtau <= self.hello.dt) {
                    return Outcome::error(format!(
                        "site protocol: Substep.dtau = {dtau:e} s is outside {:e} s (site.min_dtau) ..= {:e} s (the session's dt)",
                        self.min_dtau, self.hello.dt
                    ));
                }
                self.command.copy_from_slice(&command);
                match self.run_substep(ag, dtau) {
                    Ok(()) => Outcome::Reply(Message::Measured {
                        force: self.force.clone(),
                        displacement: self.disp.clone(),
                    }),
                    Err(reason) => Outcome::error(reason),
                }
            }
            Message::Step(req) if mode == Mode::PerStep => {
                let (n, k) = (self.hello.n_coupling, self.hello.substeps);
                let dtau = self.hello.dtau;
                self.ramp
                    .begin(&req.predictor_c_prev, &req.predictor_c, &req.force_prev);
                for j in 1..=k {
                    self.command.copy_from_slice(self.ramp.next_command());
                    if let Some(i) = self.command.iter().position(|c| !c.is_finite()) {
                        return Outcome::error(format!(
                            "sub-step {j}: the command on coupling DOF {} is not finite (the Step request's values are too large)",
                            i + 1
                        ));
                    }
                    let ag = substep_ground_acceleration(req.ag.0, req.ag.1, j, k);
                    if let Err(reason) = self.run_substep(ag, dtau) {
                        return Outcome::error(reason);
                    }
                    self.ramp.feedback(&self.force);
                    let row = (j - 1) * n..j * n;
                    self.reply.commands[row.clone()].copy_from_slice(&self.command);
                    self.reply.forces[row.clone()].copy_from_slice(&self.force);
                    self.reply.displacements[row].copy_from_slice(&self.disp);
                }
                self.steps += 1;
                Outcome::Reply(Message::StepResult(self.reply.clone()))
            }
            Message::Substep { .. } | Message::Step(_) => {
                Outcome::error(format!("{} message in a {} session", msg.kind().name(), mode.name()))
            }
            Message::Heartbeat => Outcome::Reply(Message::Heartbeat),
            Message::Stop { reason } => Outcome::Close(
                Message::Stop {
                    reason: "stop acknowledged".into(),
                },
                format!("client stopped ({reason})"),
            ),
            Message::Error { reason } => Outcome::Close(
                Message::Stop {
                    reason: "error acknowledged".into(),
                },
                format!("client reported an error: {reason}"),
            ),
            Message::Hello(_) => Outcome::error("handshake repeated within a session".to_string()),
            other => Outcome::error(format!("unexpected {} message from a client", other.kind().name())),
        }
    }

    fn summary(&self) -> String {
        format!("{} sub-steps, {} steps", self.substeps, self.steps)
    }
}

/// Why a handshake did not lead to a session.
struct Refusal {
    /// Sequence number of the `Reject` (with `log` as its reason) to send, if any.
    reply: Option<u32>,
    log: String,
}

impl Refusal {
    fn reject(reason: String, seq: u32) -> Self {
        Refusal {
            reply: Some(seq),
            log: reason,
        }
    }
}

/// Check a decoded Hello (sequence number, limits).
fn admit_hello(header: &Header, msg: Message, limits: &SiteLimits) -> std::result::Result<Hello, Refusal> {
    match msg {
        Message::Hello(hello) if header.seq == 0 => {
            limits.check_hello(&hello).map_err(|r| Refusal::reject(r, 0))?;
            Ok(hello)
        }
        other => Err(Refusal::reject(
            format!(
                "expected Hello with sequence number 0, got {} #{}",
                other.kind().name(),
                header.seq
            ),
            header.seq,
        )),
    }
}

/// Check the client's `Auth` against the challenge; on success the site's proof for `Accept`.
fn check_auth(
    secret: &Secret,
    site_nonce: &[u8; NONCE_LEN],
    hello_payload: &[u8],
    header: &Header,
    msg: Message,
) -> std::result::Result<[u8; MAC_LEN], Refusal> {
    match msg {
        Message::Auth { nonce, mac } if header.seq == 1 => {
            if secret.verify(Role::Client, site_nonce, &nonce, hello_payload, &mac) {
                Ok(secret.mac(Role::Site, site_nonce, &nonce, hello_payload))
            } else {
                Err(Refusal::reject(
                    "authentication failed: wrong proof (a different secret, or a replayed handshake)".into(),
                    1,
                ))
            }
        }
        other => Err(Refusal::reject(
            format!(
                "authentication required: expected Auth #1 after the Challenge, got {} #{} (configure the site's secret on the client)",
                other.kind().name(),
                header.seq
            ),
            header.seq,
        )),
    }
}

/// Serve one TCP connection; returns whether a session was opened.
fn serve_tcp_connection(
    mut stream: TcpStream,
    peer: SocketAddr,
    factory: &mut impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>>,
    options: &ServeOptions,
    report: &mut ServeReport,
) -> bool {
    let io = options.io_timeout;
    let stop = options.stop.as_deref();
    let _ = stream.set_nonblocking(false);
    let _ = stream.set_nodelay(true);
    let mut frame = Vec::new();
    let mut tx = Vec::new();
    let mut send = |stream: &mut TcpStream, msg: &Message, seq: u32| {
        msg.encode(seq, &mut tx);
        write_all(stream, &tx, io)
    };
    let handshake = handshake_tcp(&mut stream, &mut frame, options, stop).and_then(|(hello, accept_seq, mac)| {
        let session =
            Hosted::open(hello, factory, &options.limits, false).map_err(|r| Refusal::reject(r, accept_seq))?;
        Ok((session, accept_seq, mac))
    });
    let (mut session, accept_seq, mac) = match handshake {
        Ok(x) => x,
        Err(refusal) => {
            if let Some(seq) = refusal.reply {
                let _ = send(
                    &mut stream,
                    &Message::Reject {
                        reason: refusal.log.clone(),
                    },
                    seq,
                );
            }
            options.log(&format!("site: {peer} rejected: {}", refusal.log));
            report.rejected += 1;
            return false;
        }
    };
    let accept = Message::Accept {
        n_coupling: session.hello.n_coupling,
        mac,
    };
    if let Err(e) = send(&mut stream, &accept, accept_seq) {
        options.log(&format!("site: {peer}: cannot send Accept: {e}"));
        report.errors += 1;
        return false;
    }
    report.sessions += 1;
    options.log(&format!(
        "site: {peer} connected ({}{})",
        session.describe(),
        if mac.is_some() { ", authenticated" } else { "" }
    ));
    let limits = session.limits();
    let max_request = limits.max_request_payload();
    let mut expect: u32 = accept_seq + 1;
    let end = loop {
        let idle = ServeOptions::deadline(options.idle_timeout);
        let header = match read_frame(
            &mut stream,
            &mut frame,
            idle,
            io,
            max_request,
            "the largest request of this session",
            stop,
        ) {
            Ok(h) => h,
            Err(LinkError::Closed { got: 0 }) => break "client disconnected".to_string(),
            Err(LinkError::Stopped) => break "server stopped; connection dropped".to_string(),
            Err(LinkError::TimedOut { got: 0 }) => {
                let reason = format!(
                    "idle for more than {:.3} s",
                    options.idle_timeout.unwrap_or_default().as_secs_f64()
                );
                let _ = send(&mut stream, &Message::Error { reason: reason.clone() }, expect);
                report.errors += 1;
                break reason;
            }
            Err(LinkError::Protocol(e)) => {
                let _ = send(&mut stream, &Message::Error { reason: e.to_string() }, expect);
                report.errors += 1;
                break format!("bad frame: {e}");
            }
            Err(e) => {
                report.errors += 1;
                break e.to_string();
            }
        };
        if header.seq != expect {
            let reason = format!(
                "site protocol: {}: sequence number {}, expected {expect}",
                header.kind.name(),
                header.seq
            );
            let _ = send(&mut stream, &Message::Error { reason: reason.clone() }, header.seq);
            report.errors += 1;
            break reason;
        }
        let msg = match Message::decode(&header, &frame[HEADER_LEN..], Some(&limits)) {
            Ok(m) => m,
            Err(e) => {
                let _ = send(&mut stream, &Message::Error { reason: e.to_string() }, header.seq);
                report.errors += 1;
                break format!("bad frame: {e}");
            }
        };
        let (reply, close) = match session.handle(msg) {
            Outcome::Reply(m) => (m, None),
            Outcome::Close(m, why) => (m, Some(why)),
        };
        if let Err(e) = send(&mut stream, &reply, header.seq) {
            report.errors += 1;
            break format!("cannot send {}: {e}", reply.kind().name());
        }
        if let Some(why) = close {
            if reply.kind() == MessageType::Error {
                report.errors += 1;
            }
            break why;
        }
        expect = expect.wrapping_add(1);
    };
    report.substeps += session.substeps;
    report.steps += session.steps;
    options.log(&format!(
        "site: {peer} session ended after {}: {end}",
        session.summary()
    ));
    true
}

/// The TCP handshake up to (not including) building the site: the Hello, checked against the
/// limits, and with a secret the challenge–response, all within `handshake_timeout`. Returns
/// the Hello, the sequence number of the `Accept` and the site's proof.
fn handshake_tcp(
    stream: &mut TcpStream,
    frame: &mut Vec<u8>,
    options: &ServeOptions,
    stop: Option<&AtomicBool>,
) -> std::result::Result<(Hello, u32, Option<[u8; MAC_LEN]>), Refusal> {
    let deadline = ServeOptions::deadline(Some(options.handshake_timeout));
    let link_refusal = |e: LinkError, what: &str| match e {
        LinkError::Protocol(err) => Refusal::reject(err.to_string(), 0),
        LinkError::TimedOut { .. } => Refusal {
            reply: None,
            log: format!(
                "handshake failed: no complete {what} within {:.3} s (handshake timeout)",
                options.handshake_timeout.as_secs_f64()
            ),
        },
        e => Refusal {
            reply: None,
            log: format!("handshake failed: {e}"),
        },
    };
    let max_hello = hello_payload_len(options.limits.max_coupling);
    let header = read_frame(
        stream,
        frame,
        deadline,
        Duration::ZERO,
        max_hello,
        "a Hello for at most site.max_coupling coupling DOFs",
        stop,
    )
    .map_err(|e| link_refusal(e, "Hello"))?;
    let msg = decode_frame(frame, None)
        .map_err(|e| Refusal::reject(e.to_string(), header.seq))?
        .1;
    let hello = admit_hello(&header, msg, &options.limits)?;
    let Some(secret) = &options.secret else {
        return Ok((hello, 0, None));
    };
    let hello_payload = frame[HEADER_LEN..].to_vec();
    let site_nonce = nonce().map_err(|e| Refusal::reject(e.to_string(), 0))?;
    let mut tx = Vec::new();
    Message::Challenge { nonce: site_nonce }.encode(0, &mut tx);
    write_all(stream, &tx, options.io_timeout).map_err(|e| Refusal {
        reply: None,
        log: format!("cannot send the Challenge: {e}"),
    })?;
    let header = read_frame(
        stream,
        frame,
        deadline,
        Duration::ZERO,
        NONCE_LEN + MAC_LEN + MAX_REASON,
        "an Auth",
        stop,
    )
    .map_err(|e| match e {
        LinkError::Closed { got: 0 } => Refusal {
            reply: None,
            log: "authentication required: the client left after the Challenge (it has no secret configured?)".into(),
        },
        e => link_refusal(e, "Auth"),
    })?;
    let msg = decode_frame(frame, None)
        .map_err(|e| Refusal::reject(e.to_string(), header.seq))?
        .1;
    let mac = check_auth(secret, &site_nonce, &hello_payload, &header, msg)?;
    Ok((hello, 1, Some(mac)))
}

struct UdpSession {
    peer: SocketAddr,
    session: Hosted,
    last_seq: u32,
    last_reply: Vec<u8>,
    last_seen: Instant,
}

/// A UDP handshake waiting for the client's `Auth`.
struct Pending {
    peer: SocketAddr,
    hello: Hello,
    hello_payload: Vec<u8>,
    site_nonce: [u8; NONCE_LEN],
    challenge: Vec<u8>,
    since: Instant,
}

/// Handshakes waiting for `Auth` at once (the oldest is dropped beyond that).
const MAX_PENDING: usize = 8;

struct UdpServer {
    socket: UdpSocket,
    session: Option<UdpSession>,
    /// The last reply of a session that ended (peer, sequence number, frame), re-sent when the
    /// final request is repeated.
    closed: Option<(SocketAddr, u32, Vec<u8>)>,
    pending: Vec<Pending>,
    report: ServeReport,
    tx: Vec<u8>,
}

impl UdpServer {
    fn send(&mut self, to: SocketAddr, msg: &Message, seq: u32) {
        msg.encode(seq, &mut self.tx);
        let _ = self.socket.send_to(&self.tx, to);
    }
    fn send_error(&mut self, to: SocketAddr, seq: u32, reason: &str) {
        self.send(
            to,
            &Message::Error {
                reason: reason.to_string(),
            },
            seq,
        );
    }
    fn refuse(&mut self, from: SocketAddr, options: &ServeOptions, refusal: Refusal) {
        if let Some(seq) = refusal.reply {
            self.send(
                from,
                &Message::Reject {
                    reason: refusal.log.clone(),
                },
                seq,
            );
        }
        options.log(&format!("site: {from} rejected: {}", refusal.log));
        self.report.rejected += 1;
    }

    fn end_session(&mut self, options: &ServeOptions, why: &str) {
        if let Some(s) = self.session.take() {
            self.report.substeps += s.session.substeps;
            self.report.steps += s.session.steps;
            options.log(&format!(
                "site: {} session ended after {}: {why}",
                s.peer,
                s.session.summary()
            ));
            self.closed = Some((s.peer, s.last_seq, s.last_reply));
        }
    }

    /// Handle one datagram; returns whether a session ended.
    fn datagram(
        &mut self,
        frame: &[u8],
        from: SocketAddr,
        factory: &mut impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>>,
        options: &ServeOptions,
    ) -> bool {
        let in_session = self.session.as_ref().is_some_and(|s| s.peer == from);
        let header = match Header::parse(frame) {
            Ok(h) => h,
            Err(e) => {
                self.send_error(from, 0, &e.to_string());
                self.report.errors += 1;
                if in_session {
                    self.end_session(options, &format!("bad datagram: {e}"));
                    return true;
                }
                options.log(&format!("site: bad datagram from {from}: {e}"));
                return false;
            }
        };
        let handshake = matches!(header.kind, MessageType::Hello | MessageType::Auth) && header.seq <= 1;
        if let Some(s) = self.session.as_mut().filter(|s| s.peer == from)
            && header.kind == MessageType::Auth
            && header.seq == s.last_seq
        {
            // The Accept was lost: the same one again.
            s.last_seen = Instant::now();
            let _ = self.socket.send_to(&s.last_reply, from);
            return false;
        }
        if in_session && !(handshake && options.secret.is_some()) {
            let s = self.session.as_mut().expect("checked above");
            s.last_seen = Instant::now();
            if header.seq == s.last_seq && header.kind != MessageType::Hello {
                // A retry: the reply was lost. Re-send it; do not move the site again.
                let _ = self.socket.send_to(&s.last_reply, from);
                return false;
            }
            if header.kind == MessageType::Hello && header.seq == 0 {
                if s.last_seq == 0 {
                    let _ = self.socket.send_to(&s.last_reply, from);
                    return false;
                }
                // The client restarted: end the old session, open a new one below.
                self.end_session(options, "client sent a new handshake");
            } else {
                let expect = s.last_seq.wrapping_add(1);
                if header.seq != expect {
                    if s.last_seq.wrapping_sub(header.seq) < (1 << 31) {
                        return false; // an old duplicate
                    }
                    let reason = format!(
                        "site protocol: {}: sequence number {}, expected {expect}",
                        header.kind.name(),
                        header.seq
                    );
                    self.send_error(from, header.seq, &reason);
                    self.report.errors += 1;
                    self.end_session(options, &reason);
                    return true;
                }
                let limits = s.session.limits();
                let msg = match decode_frame(frame, Some(&limits)) {
                    Ok((_, m)) => m,
                    Err(e) => {
                        let reason = e.to_string();
                        self.send_error(from, header.seq, &reason);
                        self.report.errors += 1;
                        self.end_session(options, &format!("bad datagram: {reason}"));
                        return true;
                    }
                };
                let (reply, close) = match s.session.handle(msg) {
                    Outcome::Reply(m) => (m, None),
                    Outcome::Close(m, why) => (m, Some(why)),
                };
                reply.encode(header.seq, &mut s.last_reply);
                s.last_seq = header.seq;
                let _ = self.socket.send_to(&s.last_reply, from);
                if let Some(why) = close {
                    if reply.kind() == MessageType::Error {
                        self.report.errors += 1;
                    }
                    self.end_session(options, &why);
                    return true;
                }
                return false;
            }
        }
        // Not in a session with this peer (or, with a secret, a new handshake from it: the old
        // session stays until the new one is authenticated).
        if !handshake {
            if let Some((peer, seq, bytes)) = &self.closed
                && *peer == from
                && *seq == header.seq
            {
                let _ = self.socket.send_to(bytes, from);
                return false;
            }
            self.send_error(
                from,
                header.seq,
                "no session with this address (send Hello first, or the session has ended)",
            );
            return false;
        }
        if let Some(s) = &self.session
            && s.peer != from
        {
            let reason = "the site is busy with another client".to_string();
            self.refuse(from, options, Refusal::reject(reason, header.seq));
            return false;
        }
        let decoded = match decode_frame(frame, None) {
            Ok((_, m)) => m,
            Err(e) => {
                self.refuse(from, options, Refusal::reject(e.to_string(), header.seq));
                return false;
            }
        };
        let (hello, accept_seq, mac) = if header.kind == MessageType::Hello {
            let payload = &frame[HEADER_LEN..];
            if let Some(p) = self
                .pending
                .iter()
                .find(|p| p.peer == from && p.hello_payload == payload)
            {
                // The Challenge was lost: the same one again.
                let _ = self.socket.send_to(&p.challenge, from);
                return false;
            }
            let hello = match admit_hello(&header, decoded, &options.limits) {
                Ok(h) => h,
                Err(r) => {
                    self.refuse(from, options, r);
                    return false;
                }
            };
            if options.secret.is_some() {
                let site_nonce = match nonce() {
                    Ok(n) => n,
                    Err(e) => {
                        self.refuse(from, options, Refusal::reject(e.to_string(), 0));
                        return false;
                    }
                };
                let mut challenge = Vec::new();
                Message::Challenge { nonce: site_nonce }.encode(0, &mut challenge);
                let _ = self.socket.send_to(&challenge, from);
                self.pending.retain(|p| p.peer != from);
                if self.pending.len() >= MAX_PENDING {
                    self.pending.remove(0);
                }
                self.pending.push(Pending {
                    peer: from,
                    hello,
                    hello_payload: payload.to_vec(),
                    site_nonce,
                    challenge,
                    since: Instant::now(),
                });
                return false;
            }
            (hello, 0, None)
        } else {
            let Some(secret) = options.secret.clone() else {
                let reason = "unexpected Auth: this site has no secret".to_string();
                self.refuse(from, options, Refusal::reject(reason, header.seq));
                return false;
            };
            let Some(i) = self.pending.iter().position(|p| p.peer == from) else {
                let reason = "Auth without a pending handshake (send Hello first)".to_string();
                self.refuse(from, options, Refusal::reject(reason, header.seq));
                return false;
            };
            let p = self.pending.remove(i);
            match check_auth(&secret, &p.site_nonce, &p.hello_payload, &header, decoded) {
                Ok(mac) => (p.hello, 1, Some(mac)),
                Err(r) => {
                    self.refuse(from, options, r);
                    return false;
                }
            }
        };
        if in_session {
            self.end_session(options, "client sent a new handshake");
        }
        match Hosted::open(hello, factory, &options.limits, true) {
            Ok(session) => {
                let mut last_reply = Vec::new();
                Message::Accept {
                    n_coupling: session.hello.n_coupling,
                    mac,
                }
                .encode(accept_seq, &mut last_reply);
                let _ = self.socket.send_to(&last_reply, from);
                options.log(&format!(
                    "site: {from} connected over UDP ({}{})",
                    session.describe(),
                    if mac.is_some() { ", authenticated" } else { "" }
                ));
                self.report.sessions += 1;
                self.closed = None;
                self.session = Some(UdpSession {
                    peer: from,
                    session,
                    last_seq: accept_seq,
                    last_reply,
                    last_seen: Instant::now(),
                });
            }
            Err(reason) => self.refuse(from, options, Refusal::reject(reason, accept_seq)),
        }
        false
    }
}

/// A virtual lab to host: specimens attached to model DOFs, and the actuator and sensors used
/// for every coupling DOF. Built per connection from the client's handshake: the actuator
/// order follows the client's coupling DOFs and the sub-step length is the client's `Δτ`.
#[derive(Debug, Clone, PartialEq)]
pub struct VirtualLabSpec {
    pub specimens: Vec<SpecimenSpec>,
    pub actuator: ActuatorSpec,
    /// Base sensor specs; each channel gets its own seed (see [`channel_sensors`]).
    pub force_sensor: SensorSpec,
    pub displacement_sensor: SensorSpec,
    /// Inner intervals per sub-step (≥ 1).
    pub inner_steps: usize,
}

impl VirtualLabSpec {
    /// Specimens behind ideal actuators and sensors.
    pub fn ideal(specimens: Vec<SpecimenSpec>) -> Self {
        Self {
            specimens,
            actuator: ActuatorSpec::ideal(),
            force_sensor: SensorSpec::ideal(),
            displacement_sensor: SensorSpec::ideal(),
            inner_steps: 1,
        }
    }

    /// The lab for a client. Every coupling DOF of the client must carry a specimen and every
    /// specimen must sit on a coupling DOF of the client.
    pub fn build(&self, hello: &Hello) -> Result<VirtualLab> {
        let mut at: Vec<usize> = self.specimens.iter().flat_map(|s| s.dofs()).collect();
        at.sort_unstable();
        at.dedup();
        if let Some(d) = hello.coupling_dofs.iter().find(|d| !at.contains(d)) {
            let list: Vec<String> = at.iter().map(|d| (d + 1).to_string()).collect();
            return Err(Error::invalid(
                "site",
                format!(
                    "the client couples at model DOF {} where this site has no specimen (specimens at DOFs {})",
                    d + 1,
                    list.join(", ")
                ),
            ));
        }
        let n = hello.n_coupling;
        // per-channel seeds as in a local run's config (`[substructure.sensors] seed`)
        let (force, displacement) = channel_sensors(&self.force_sensor, &self.displacement_sensor, n);
        VirtualLab::from_specs(
            &hello.coupling_dofs,
            &self.specimens,
            &vec![self.actuator.clone(); n],
            &force,
            &displacement,
            hello.dtau,
            self.inner_steps,
        )
    }

    /// What hosting this lab for `hello` costs: the actuators' delay histories (sized from
    /// the delay and the inner-step length `Δτ / inner_steps`) and the work of one sub-step
    /// (every inner step searches each delay history). Computed in floating point, so absurd
    /// handshakes give huge numbers instead of overflowing.
    pub fn cost(&self, hello: &Hello) -> SessionCost {
        let n = hello.n_coupling as f64;
        let inner = self.inner_steps.max(1) as f64;
        let history = if self.actuator.delay > 0.0 {
            // as `DelayLine::new`: 2 (⌈delay / dt_inner⌉ + 2) samples of (time, value)
            2.0 * ((self.actuator.delay * inner / hello.dtau).ceil() + 2.0)
        } else {
            0.0
        };
        let dofs: usize = self.specimens.iter().map(|s| s.dofs().len()).sum();
        let specimen_work = (dofs * dofs) as f64 + 16.0;
        let to_u = |x: f64| if x.is_finite() && x < 1e18 { x as u64 } else { u64::MAX };
        SessionCost {
            bytes: to_u(n * history * 16.0 + n * 1024.0).min(usize::MAX as u64) as usize,
            work_per_substep: to_u(inner * (n * (history + 8.0) + specimen_work)),
        }
    }

    /// A factory for [`SiteServer::serve`] with the default [`SiteLimits`].
    pub fn factory(self) -> impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>> + Send + 'static {
        self.factory_with(SiteLimits::default())
    }

    /// A factory that refuses a handshake whose [`VirtualLabSpec::cost`] exceeds `limits`
    /// before building anything.
    pub fn factory_with(
        self,
        limits: SiteLimits,
    ) -> impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>> + Send + 'static {
        move |hello: &Hello| {
            limits
                .check_cost(hello, self.cost(hello))
                .map_err(|reason| Error::invalid("site limits", reason))?;
            Ok(Box::new(self.build(hello)?) as Box<dyn ExperimentalSubstructure>)
        }
    }
}
