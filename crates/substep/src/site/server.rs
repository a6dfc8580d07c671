//! The site server: hosts an experimental substructure for remote controllers over the `SSTP`
//! protocol ([`super::protocol`]), on TCP or UDP.
//!
//! One client is served at a time (a lab has one rig); the substructure is built per connection
//! by the factory from the client's handshake. In per-step mode the server runs the sub-step
//! loop itself with [`super::CommandRamp`], i.e. with the same floating-point operations as the
//! controller.

use super::protocol::{
    HEADER_LEN, Header, Hello, MAX_DATAGRAM, Message, MessageType, Mode, Session, StepReply, decode_frame,
};
use super::transport::{LinkError, POLL, read_frame, write_all};
use super::{CommandRamp, LogFn, SiteFactory, substep_ground_acceleration};
use crate::error::{Error, Result};
use crate::specimen::SpecimenSpec;
use crate::substructure::ExperimentalSubstructure;
use crate::transfer::{ActuatorSpec, SensorSpec, VirtualLab, channel_sensors};
use std::net::{SocketAddr, TcpListener, TcpStream, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Server settings.
#[derive(Clone)]
pub struct ServeOptions {
    /// Return after the first client's session ends (instead of serving forever).
    pub once: bool,
    /// A client silent for longer than this is dropped (`None`: wait forever). Set it for UDP:
    /// a UDP client that vanishes without `Stop` otherwise keeps its session (and the site)
    /// busy for good.
    pub idle_timeout: Option<Duration>,
    /// Time allowed for the handshake, for the rest of a frame once its header arrived, and
    /// for each write.
    pub io_timeout: Duration,
    /// One-line log messages (connections, rejections, errors).
    pub log: Option<LogFn>,
    /// Raising this flag stops the server within ~25 ms (the current client is dropped).
    pub stop: Option<Arc<AtomicBool>>,
}

impl Default for ServeOptions {
    fn default() -> Self {
        Self {
            once: false,
            idle_timeout: None,
            io_timeout: Duration::from_secs(5),
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
            .field("io_timeout", &self.io_timeout)
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

/// The `SSTP` site server.
pub struct SiteServer;

impl SiteServer {
    /// Serve clients on `listener` (TCP) one at a time until a `once` session ends or the stop
    /// flag is raised. Connection-level errors are logged and end that connection only.
    pub fn serve(
        listener: TcpListener,
        mut factory: impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>>,
        options: &ServeOptions,
    ) -> Result<ServeReport> {
        let local = listener
            .local_addr()
            .map_err(|e| Error::invalid("site server", e.to_string()))?;
        listener
            .set_nonblocking(true)
            .map_err(|e| Error::invalid(format!("site server {local}"), e.to_string()))?;
        options.log(&format!("site: listening on tcp://{local}"));
        let mut report = ServeReport::default();
        loop {
            if options.stopped() {
                options.log(&format!("site: tcp://{local} stopped"));
                return Ok(report);
            }
            match listener.accept() {
                Ok((stream, peer)) => {
                    let opened = serve_tcp_connection(stream, peer, &mut factory, options, &mut report);
                    if options.once && opened {
                        return Ok(report);
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => std::thread::sleep(POLL / 5),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionAborted => {
                    options.log(&format!("site: accept on {local}: {e}"));
                }
                Err(e) => {
                    return Err(Error::invalid(
                        format!("site server {local}"),
                        format!("accept failed: {e}"),
                    ));
                }
            }
        }
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
                if options.once {
                    return Ok(udp.report);
                }
            }
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
    reply: StepReply,
    substeps: u64,
    steps: u64,
}

enum Outcome {
    Reply(Message),
    /// Reply, then end the session with the given log reason.
    Close(Message, String),
}

impl Hosted {
    fn open(
        hello: Hello,
        factory: &mut impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>>,
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

    fn run_substep(&mut self, command: &[f64], ag: (f64, f64), dtau: f64) -> std::result::Result<(), String> {
        self.site
            .substep(command, ag, dtau, &mut self.force, &mut self.disp)
            .map_err(|e| format!("the site failed at sub-step {}: {e}", self.substeps + 1))?;
        self.substeps += 1;
        if let Some(i) = self.force.iter().position(|f| !f.is_finite()) {
            return Err(format!(
                "the site measured a non-finite force on coupling DOF {}",
                i + 1
            ));
        }
        if let Some(i) = self.disp.iter().position(|f| !f.is_finite()) {
            return Err(format!(
                "the site measured a non-finite displacement on coupling DOF {}",
                i + 1
            ));
        }
        Ok(())
    }

    fn handle(&mut self, msg: Message) -> Outcome {
        let mode = self.hello.mode;
        match msg {
            Message::Substep { command, ag, dtau } if mode == Mode::PerSubstep => {
                match self.run_substep(&command, ag, dtau) {
                    Ok(()) => Outcome::Reply(Message::Measured {
                        force: self.force.clone(),
                        displacement: self.disp.clone(),
                    }),
                    Err(reason) => Outcome::Close(Message::Error { reason: reason.clone() }, reason),
                }
            }
            Message::Step(req) if mode == Mode::PerStep => {
                let (n, k) = (self.hello.n_coupling, self.hello.substeps);
                let dtau = self.hello.dtau;
                self.ramp
                    .begin(&req.predictor_c_prev, &req.predictor_c, &req.force_prev);
                for j in 1..=k {
                    let command = self.ramp.next_command().to_vec();
                    let ag = substep_ground_acceleration(req.ag.0, req.ag.1, j, k);
                    if let Err(reason) = self.run_substep(&command, ag, dtau) {
                        return Outcome::Close(Message::Error { reason: reason.clone() }, reason);
                    }
                    self.ramp.feedback(&self.force);
                    let row = (j - 1) * n..j * n;
                    self.reply.commands[row.clone()].copy_from_slice(&command);
                    self.reply.forces[row.clone()].copy_from_slice(&self.force);
                    self.reply.displacements[row].copy_from_slice(&self.disp);
                }
                self.steps += 1;
                Outcome::Reply(Message::StepResult(self.reply.clone()))
            }
            Message::Substep { .. } | Message::Step(_) => {
                let reason = format!("{} message in a {} session", msg.kind().name(), mode.name());
                Outcome::Close(Message::Error { reason: reason.clone() }, reason)
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
            Message::Hello(_) => {
                let reason = "handshake repeated within a session".to_string();
                Outcome::Close(Message::Error { reason: reason.clone() }, reason)
            }
            other => {
                let reason = format!("unexpected {} message from a client", other.kind().name());
                Outcome::Close(Message::Error { reason: reason.clone() }, reason)
            }
        }
    }

    fn summary(&self) -> String {
        format!("{} sub-steps, {} steps", self.substeps, self.steps)
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
    // Handshake.
    let hello = match read_frame(&mut stream, &mut frame, Some(Instant::now() + io), io, stop)
        .and_then(|_| decode_frame(&frame, None).map_err(LinkError::Protocol))
    {
        Ok((h, Message::Hello(hello))) if h.seq == 0 => hello,
        Ok((h, msg)) => {
            let reason = format!(
                "expected Hello with sequence number 0, got {} #{}",
                msg.kind().name(),
                h.seq
            );
            let _ = send(&mut stream, &Message::Reject { reason: reason.clone() }, h.seq);
            options.log(&format!("site: {peer} rejected: {reason}"));
            report.rejected += 1;
            return false;
        }
        Err(e) => {
            if let LinkError::Protocol(err) = &e {
                let _ = send(
                    &mut stream,
                    &Message::Reject {
                        reason: err.to_string(),
                    },
                    0,
                );
            }
            options.log(&format!("site: {peer} rejected: handshake failed: {e}"));
            report.rejected += 1;
            return false;
        }
    };
    let mut session = match Hosted::open(hello, factory, false) {
        Ok(s) => s,
        Err(reason) => {
            let _ = send(&mut stream, &Message::Reject { reason: reason.clone() }, 0);
            options.log(&format!("site: {peer} rejected: {reason}"));
            report.rejected += 1;
            return false;
        }
    };
    let accept = Message::Accept {
        n_coupling: session.hello.n_coupling,
    };
    if let Err(e) = send(&mut stream, &accept, 0) {
        options.log(&format!("site: {peer}: cannot send Accept: {e}"));
        report.errors += 1;
        return false;
    }
    report.sessions += 1;
    options.log(&format!("site: {peer} connected ({})", session.describe()));
    let limits = session.limits();
    let mut expect: u32 = 1;
    let end = loop {
        let idle = options.idle_timeout.map(|t| Instant::now() + t);
        let header = match read_frame(&mut stream, &mut frame, idle, io, stop) {
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
                "site protocol: {}: sequence number {} , expected {expect}",
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

struct UdpSession {
    peer: SocketAddr,
    session: Hosted,
    last_seq: u32,
    last_reply: Vec<u8>,
    last_seen: Instant,
}

struct UdpServer {
    socket: UdpSocket,
    session: Option<UdpSession>,
    /// The last reply of a session that ended (peer, sequence number, frame), re-sent when the
    /// final request is repeated.
    closed: Option<(SocketAddr, u32, Vec<u8>)>,
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
        if in_session {
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
        // Not in a session with this peer.
        if header.kind != MessageType::Hello {
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
        if let Some(s) = &self.session {
            let reason = format!("the site is busy with another client ({})", s.peer);
            self.send(from, &Message::Reject { reason: reason.clone() }, header.seq);
            options.log(&format!("site: {from} rejected: {reason}"));
            self.report.rejected += 1;
            return false;
        }
        let hello = match decode_frame(frame, None) {
            Ok((h, Message::Hello(hello))) if h.seq == 0 => hello,
            Ok((h, _)) => {
                let reason = format!("Hello must have sequence number 0, got {}", h.seq);
                self.send(from, &Message::Reject { reason: reason.clone() }, h.seq);
                options.log(&format!("site: {from} rejected: {reason}"));
                self.report.rejected += 1;
                return false;
            }
            Err(e) => {
                let reason = e.to_string();
                self.send(from, &Message::Reject { reason: reason.clone() }, header.seq);
                options.log(&format!("site: {from} rejected: {reason}"));
                self.report.rejected += 1;
                return false;
            }
        };
        match Hosted::open(hello, factory, true) {
            Ok(session) => {
                let mut last_reply = Vec::new();
                Message::Accept {
                    n_coupling: session.hello.n_coupling,
                }
                .encode(0, &mut last_reply);
                let _ = self.socket.send_to(&last_reply, from);
                options.log(&format!("site: {from} connected over UDP ({})", session.describe()));
                self.report.sessions += 1;
                self.closed = None;
                self.session = Some(UdpSession {
                    peer: from,
                    session,
                    last_seq: 0,
                    last_reply,
                    last_seen: Instant::now(),
                });
            }
            Err(reason) => {
                self.send(from, &Message::Reject { reason: reason.clone() }, 0);
                options.log(&format!("site: {from} rejected: {reason}"));
                self.report.rejected += 1;
            }
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

    /// A factory for [`SiteServer::serve`].
    pub fn factory(self) -> impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>> + Send + 'static {
        move |hello: &Hello| Ok(Box::new(self.build(hello)?) as Box<dyn ExperimentalSubstructure>)
    }
}
