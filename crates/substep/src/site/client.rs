//! Clients of a remote `SSTP` site.
//!
//! * [`RemoteSite`] — per-sub-step mode; implements [`ExperimentalSubstructure`], so a
//!   [`crate::substructure::SubstructureTest`] runs against it unchanged.
//! * [`RemoteStepSite`] — per-step mode; [`run_remote_step`] runs one step of a
//!   [`SubstepController`] against it and [`RemoteStepTest`] is the per-step counterpart of
//!   `SubstructureTest`.
//!
//! Every error names the site's address. A failed request leaves the connection unusable
//! (its state is unknown); later requests fail at once with the original reason.
//!
//! With a secret every message after the handshake is sealed and every reply's tag and
//! sequence number are checked ([`super::auth`], [`super::protocol`]): a bad reply is an error
//! starting with `message authentication failed` (over UDP a datagram that fails its tag is
//! dropped and the request waits on, see the protocol docs).

use super::auth::{Role, Secret, SessionKeys, TAG_LEN, nonce};
use super::protocol::{
    AUTH_FAILED, HEADER_LEN, Header, Hello, MAX_DATAGRAM, Message, Mode, Session, StepReply, StepRequest, open_sealed,
};
use super::transport::{LinkError, read_frame, write_all};
use crate::error::{Error, Result};
use crate::model::ModelRef;
use crate::substructure::{ExperimentalSubstructure, StepRecord, SubstepController, SubstepObserver};
use nalgebra::DVector;
use std::io;
use std::net::{SocketAddr, TcpStream, ToSocketAddrs, UdpSocket};
use std::time::{Duration, Instant};

/// Which transport carries the protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    /// One TCP connection (`TCP_NODELAY`).
    Tcp,
    /// One datagram per message; lost replies are recovered by re-sending the request with the
    /// same sequence number.
    Udp,
}

impl Transport {
    pub fn name(self) -> &'static str {
        match self {
            Transport::Tcp => "tcp",
            Transport::Udp => "udp",
        }
    }
}

/// Client settings.
#[derive(Debug, Clone)]
pub struct ClientOptions {
    /// Time allowed for each reply (for each attempt over UDP).
    pub timeout: Duration,
    /// Time allowed to open a TCP connection.
    pub connect_timeout: Duration,
    /// UDP: requests re-sent after a timeout (total wait ≤ `(udp_retries + 1) × timeout`).
    pub udp_retries: u32,
    /// The site's shared secret: prove it to the site, and require the site to prove it back
    /// (a site without the secret is refused). `None`: a site that asks for it is refused.
    pub secret: Option<Secret>,
}

impl Default for ClientOptions {
    fn default() -> Self {
        Self {
            timeout: Duration::from_secs(2),
            connect_timeout: Duration::from_secs(2),
            udp_retries: 3,
            secret: None,
        }
    }
}

enum Link {
    Tcp(TcpStream),
    Udp(UdpSocket),
}

/// A connection to an `SSTP` site after a successful handshake.
pub struct SiteClient {
    link: Link,
    peer: SocketAddr,
    transport: Transport,
    hello: Hello,
    limits: Session,
    seq: u32,
    options: ClientOptions,
    tx: Vec<u8>,
    rx: Vec<u8>,
    broken: Option<String>,
    closed: bool,
    /// The session keys once an authenticated handshake is complete: every later message is
    /// sealed and every reply checked.
    keys: Option<SessionKeys>,
}

fn resolve(addr: impl ToSocketAddrs) -> Result<SocketAddr> {
    let mut it = addr
        .to_socket_addrs()
        .map_err(|e| Error::invalid("site address", format!("cannot resolve: {e}")))?;
    it.next()
        .ok_or_else(|| Error::invalid("site address", "resolves to no address"))
}

impl SiteClient {
    /// Connect and perform the handshake.
    pub fn connect(
        addr: impl ToSocketAddrs,
        transport: Transport,
        hello: Hello,
        options: &ClientOptions,
    ) -> Result<Self> {
        let peer = resolve(addr)?;
        let name = format!("site {}://{peer}", transport.name());
        hello.validate()?;
        let limits = hello.session();
        let link = match transport {
            Transport::Tcp => {
                let stream = TcpStream::connect_timeout(&peer, options.connect_timeout.max(Duration::from_millis(1)))
                    .map_err(|e| Error::invalid(&name, format!("cannot connect: {e}")))?;
                stream
                    .set_nodelay(true)
                    .map_err(|e| Error::invalid(&name, format!("cannot set TCP_NODELAY: {e}")))?;
                Link::Tcp(stream)
            }
            Transport::Udp => {
                if HEADER_LEN + limits.max_payload() > MAX_DATAGRAM {
                    return Err(Error::invalid(
                        &name,
                        format!(
                            "n_c = {} with k_sub = {} needs messages larger than one UDP datagram; use TCP",
                            hello.n_coupling, hello.substeps
                        ),
                    ));
                }
                let local: SocketAddr = match peer {
                    SocketAddr::V4(a) if a.ip().is_loopback() => "127.0.0.1:0".parse().expect("valid"),
                    SocketAddr::V4(_) => "0.0.0.0:0".parse().expect("valid"),
                    SocketAddr::V6(a) if a.ip().is_loopback() => "[::1]:0".parse().expect("valid"),
                    SocketAddr::V6(_) => "[::]:0".parse().expect("valid"),
                };
                let socket = UdpSocket::bind(local).map_err(|e| Error::invalid(&name, format!("cannot bind: {e}")))?;
                socket
                    .connect(peer)
                    .map_err(|e| Error::invalid(&name, format!("cannot connect: {e}")))?;
                Link::Udp(socket)
            }
        };
        let mut client = SiteClient {
            link,
            peer,
            transport,
            limits,
            hello: hello.clone(),
            seq: 0,
            options: options.clone(),
            tx: Vec::new(),
            rx: Vec::new(),
            broken: None,
            closed: false,
            keys: None,
        };
        match client.handshake() {
            Ok(()) => Ok(client),
            Err(e) => {
                client.closed = true;
                Err(e)
            }
        }
    }

    /// `Hello`, and with a challenge the `Auth` exchange ([`super::auth`]).
    fn handshake(&mut self) -> Result<()> {
        let hello = Message::Hello(self.hello.clone());
        let mut frame = Vec::new();
        hello.encode(0, &mut frame);
        let hello_payload = &frame[HEADER_LEN..];
        let n_c = self.hello.n_coupling;
        let (reply, proof) = match self.request(&hello)? {
            Message::Challenge { nonce: site_nonce } => {
                let Some(secret) = self.options.secret.clone() else {
                    return Err(self.err(format!(
                        "the site requires authentication: configure its secret (substructure.remote.secret_file or the environment variable {})",
                        super::auth::SECRET_ENV
                    )));
                };
                let client_nonce = nonce()?;
                let mac = secret.mac(Role::Client, &site_nonce, &client_nonce, hello_payload);
                let reply = self.request(&Message::Auth {
                    nonce: client_nonce,
                    mac,
                })?;
                (reply, Some((secret, site_nonce, client_nonce)))
            }
            other => (other, None),
        };
        match reply {
            Message::Accept { n_coupling, mac } => {
                if n_coupling != n_c {
                    return Err(self.err(format!(
                        "the site accepted with {n_coupling} coupling DOFs, the controller has {n_c}"
                    )));
                }
                match (&self.options.secret, proof, mac) {
                    (None, None, _) => Ok(()),
                    (Some(_), None, _) => Err(self.err(
                        "the site did not ask for authentication although a secret is configured: it is not the site that holds the secret (refused)",
                    )),
                    (_, Some((secret, site_nonce, client_nonce)), Some(mac)) => {
                        if secret.verify(Role::Site, &site_nonce, &client_nonce, hello_payload, &mac) {
                            self.keys =
                                Some(secret.session_keys(Role::Client, &site_nonce, &client_nonce, hello_payload));
                            Ok(())
                        } else {
                            Err(self.err("the site's proof of the secret is wrong (refused): it holds a different secret"))
                        }
                    }
                    (_, Some(_), None) => Err(self.err("the site accepted without proving the secret (refused)")),
                }
            }
            Message::Reject { reason } => Err(self.err(format!("the site rejected the connection: {reason}"))),
            other => Err(self.err(format!("unexpected {} reply to the handshake", other.kind().name()))),
        }
    }

    /// The site's address.
    pub fn peer(&self) -> SocketAddr {
        self.peer
    }
    pub fn transport(&self) -> Transport {
        self.transport
    }
    pub fn hello(&self) -> &Hello {
        &self.hello
    }
    pub fn options(&self) -> &ClientOptions {
        &self.options
    }
    /// Whether the session's messages are authenticated (a secret was configured and the
    /// handshake proved it on both sides).
    pub fn authenticated(&self) -> bool {
        self.keys.is_some()
    }

    fn err(&self, reason: impl Into<String>) -> Error {
        Error::invalid(format!("site {}://{}", self.transport.name(), self.peer), reason)
    }

    /// Send one request and wait for its reply. An `Error` reply from the site becomes `Err`.
    pub fn request(&mut self, msg: &Message) -> Result<Message> {
        if let Some(reason) = &self.broken {
            return Err(self.err(format!("connection unusable after an earlier failure: {reason}")));
        }
        let seq = self.seq;
        msg.encode_session(seq, &mut self.tx, self.keys.as_ref());
        let what = format!("{} #{seq}", msg.kind().name());
        let keys = self.keys.as_ref();
        let result = match &mut self.link {
            Link::Tcp(stream) => request_tcp(
                stream,
                &self.tx,
                &mut self.rx,
                seq,
                &self.limits,
                self.options.timeout,
                keys,
            ),
            Link::Udp(socket) => request_udp(
                socket,
                &self.tx,
                &mut self.rx,
                seq,
                &self.limits,
                self.options.timeout,
                self.options.udp_retries,
                keys,
            ),
        };
        let result = result.map_err(|e| e.describe(&what)).and_then(|m| match m {
            Message::Error { reason } => Err(format!("the site reported an error (reply to {what}): {reason}")),
            m => Ok(m),
        });
        match result {
            Ok(m) => {
                self.seq = self.seq.wrapping_add(1);
                Ok(m)
            }
            Err(reason) => {
                self.broken = Some(reason.clone());
                Err(self.err(reason))
            }
        }
    }

    /// Round-trip a heartbeat; returns the round-trip time.
    pub fn ping(&mut self) -> Result<Duration> {
        let t0 = Instant::now();
        match self.request(&Message::Heartbeat)? {
            Message::Heartbeat => Ok(t0.elapsed()),
            other => Err(self.fail(format!("unexpected {} reply to Heartbeat", other.kind().name()))),
        }
    }

    /// End the session: send `Stop` and wait for the site's acknowledgement.
    pub fn stop(&mut self, reason: &str) -> Result<()> {
        if self.closed {
            return Ok(());
        }
        self.closed = true;
        match self.request(&Message::Stop {
            reason: reason.to_string(),
        })? {
            Message::Stop { .. } => Ok(()),
            other => Err(self.err(format!("unexpected {} reply to Stop", other.kind().name()))),
        }
    }

    /// Mark the connection unusable and return the error.
    fn fail(&mut self, reason: String) -> Error {
        self.broken = Some(reason.clone());
        self.err(reason)
    }
}

impl Drop for SiteClient {
    fn drop(&mut self) {
        if self.closed || self.broken.is_some() {
            return;
        }
        // Best effort: tell the site we are done, without waiting for the acknowledgement.
        Message::Stop {
            reason: "client closed".into(),
        }
        .encode_session(self.seq, &mut self.tx, self.keys.as_ref());
        match &mut self.link {
            Link::Tcp(s) => {
                let _ = write_all(s, &self.tx, Duration::from_millis(100));
            }
            Link::Udp(s) => {
                let _ = s.send(&self.tx);
            }
        }
    }
}

/// A request failed; `describe` words it for the request `what`.
enum RequestError {
    Link(LinkError),
    BadReply(Error),
    Timeout {
        timeout: Duration,
        attempts: u32,
    },
    Unreachable(io::Error),
    /// A reply failed authentication (its error starts with [`AUTH_FAILED`]).
    Auth(Error),
    /// UDP: no reply, and the site said (authentically) that it dropped `count` of the
    /// request's datagrams as unauthenticated, the last time with `reason`.
    DroppedBySite {
        attempts: u32,
        count: u32,
        reason: String,
    },
}

impl RequestError {
    fn describe(&self, what: &str) -> String {
        match self {
            RequestError::Link(LinkError::TimedOut { got }) | RequestError::Link(LinkError::Closed { got })
                if *got > 0 =>
            {
                let cause = if matches!(self, RequestError::Link(LinkError::TimedOut { .. })) {
                    "timed out"
                } else {
                    "connection closed"
                };
                format!("incomplete reply to {what} ({got} bytes, then {cause})")
            }
            RequestError::Link(LinkError::Closed { .. }) => {
                format!("the site closed the connection (no reply to {what}); the site is gone")
            }
            RequestError::Link(LinkError::TimedOut { .. }) => format!("no reply to {what} (timeout)"),
            RequestError::Link(LinkError::Protocol(e)) | RequestError::BadReply(e) => {
                format!("bad reply to {what}: {e}")
            }
            RequestError::Link(e) => format!("connection error during {what}: {e}"),
            RequestError::Timeout { timeout, attempts } => format!(
                "no reply to {what} within {:.3} s (timeout){}",
                timeout.as_secs_f64(),
                if *attempts > 1 {
                    format!(", {attempts} attempts")
                } else {
                    String::new()
                }
            ),
            RequestError::Unreachable(e) => format!("the site is unreachable during {what} ({e}); the site is gone"),
            RequestError::Auth(e) => format!("{e} (reply to {what})"),
            RequestError::DroppedBySite {
                attempts,
                count,
                reason,
            } => format!(
                "{AUTH_FAILED}: the site dropped {what} as unauthenticated ({count} of {attempts} attempts; the site says: {reason}): something on the way changes the messages"
            ),
        }
    }
}

fn request_tcp(
    stream: &mut TcpStream,
    tx: &[u8],
    rx: &mut Vec<u8>,
    seq: u32,
    limits: &Session,
    timeout: Duration,
    keys: Option<&SessionKeys>,
) -> std::result::Result<Message, RequestError> {
    let deadline = Instant::now().checked_add(timeout).unwrap_or_else(Instant::now);
    write_all(stream, tx, timeout).map_err(RequestError::Link)?;
    let header = match read_frame(
        stream,
        rx,
        Some(deadline),
        Duration::ZERO,
        limits.max_payload() + if keys.is_some() { TAG_LEN } else { 0 },
        "the largest reply of this session",
        None,
        keys.is_some(),
    ) {
        Ok(h) => h,
        Err(LinkError::TimedOut { got: 0 }) => return Err(RequestError::Timeout { timeout, attempts: 1 }),
        Err(LinkError::Protocol(e)) if keys.is_some() => {
            return Err(RequestError::Auth(super::protocol::as_auth_failure(e)));
        }
        Err(e) => return Err(RequestError::Link(e)),
    };
    let Some(keys) = keys else {
        check_seq(&header, seq, false)?;
        return Message::decode(&header, &rx[HEADER_LEN..], Some(limits)).map_err(RequestError::BadReply);
    };
    // The tag first: until it checks, nothing in the frame (its number included) is the site's.
    let (header, payload) = open_sealed(rx, &header, keys).map_err(RequestError::Auth)?;
    check_seq(&header, seq, true)?;
    Message::decode(&header, payload, Some(limits)).map_err(RequestError::BadReply)
}

/// The reply's sequence number must be the request's. In an authenticated session another
/// number on an authentic reply is a replayed or reordered message.
fn check_seq(header: &Header, seq: u32, authenticated: bool) -> std::result::Result<(), RequestError> {
    if header.seq == seq {
        Ok(())
    } else if authenticated {
        Err(RequestError::Auth(Error::invalid(
            AUTH_FAILED,
            format!(
                "the reply {} carries sequence number {}, expected {seq} (a replayed or reordered message)",
                header.kind.name(),
                header.seq
            ),
        )))
    } else {
        Err(RequestError::BadReply(Error::invalid(
            "site protocol: header.seq",
            format!("reply carries sequence number {}, expected {seq}", header.seq),
        )))
    }
}

#[allow(clippy::too_many_arguments)]
fn request_udp(
    socket: &UdpSocket,
    tx: &[u8],
    rx: &mut Vec<u8>,
    seq: u32,
    limits: &Session,
    timeout: Duration,
    retries: u32,
    keys: Option<&SessionKeys>,
) -> std::result::Result<Message, RequestError> {
    rx.resize(MAX_DATAGRAM + 1, 0);
    let attempts = retries + 1;
    // The site's authentic notices that it dropped this request's datagrams (see below).
    let mut dropped_by_site: u32 = 0;
    let mut dropped_reason = String::new();
    for _ in 0..attempts {
        match socket.send(tx) {
            Ok(_) => {}
            Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => return Err(RequestError::Unreachable(e)),
            Err(e) => return Err(RequestError::Link(LinkError::Io(e))),
        }
        let deadline = Instant::now().checked_add(timeout).unwrap_or_else(Instant::now);
        loop {
            let now = Instant::now();
            if now >= deadline {
                break;
            }
            socket
                .set_read_timeout(Some((deadline - now).max(Duration::from_micros(100))))
                .map_err(|e| RequestError::Link(LinkError::Io(e)))?;
            let n = match socket.recv(rx) {
                Ok(n) => n,
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
                    ) =>
                {
                    continue;
                }
                Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => return Err(RequestError::Unreachable(e)),
                Err(e) => return Err(RequestError::Link(LinkError::Io(e))),
            };
            let frame = &rx[..n];
            let Some(keys) = keys else {
                let header = Header::parse(frame).map_err(RequestError::BadReply)?;
                if header.seq != seq && seq.wrapping_sub(header.seq) < (1 << 31) {
                    continue; // a duplicate reply to an earlier request
                }
                check_seq(&header, seq, false)?;
                return super::protocol::decode_frame(frame, Some(limits))
                    .map(|(_, m)| m)
                    .map_err(RequestError::BadReply);
            };
            // Authenticated: a datagram that fails its tag is not the site's (anyone can send
            // one with the site's address as its source): drop it and wait on, so a forged
            // datagram cannot end the session.
            let Ok((header, payload)) = Header::parse_session(frame, true).and_then(|h| open_sealed(frame, &h, keys))
            else {
                continue;
            };
            if header.seq != seq && seq.wrapping_sub(header.seq) < (1 << 31) {
                continue; // a duplicate reply to an earlier request
            }
            check_seq(&header, seq, true)?;
            match Message::decode(&header, payload, Some(limits)).map_err(RequestError::BadReply)? {
                Message::Dropped { reason } => {
                    // Not fatal (a forged request with this number gets the same notice); it
                    // explains a timeout if every attempt is dropped.
                    dropped_by_site += 1;
                    dropped_reason = reason;
                }
                m => return Ok(m),
            }
        }
    }
    if dropped_by_site > 0 {
        return Err(RequestError::DroppedBySite {
            attempts,
            count: dropped_by_site,
            reason: dropped_reason,
        });
    }
    Err(RequestError::Timeout { timeout, attempts })
}

/// A remote site in per-sub-step mode, usable wherever an [`ExperimentalSubstructure`] is.
pub struct RemoteSite {
    client: SiteClient,
}

impl RemoteSite {
    /// Connect with a per-sub-step handshake.
    pub fn connect(
        addr: impl ToSocketAddrs,
        transport: Transport,
        hello: Hello,
        options: &ClientOptions,
    ) -> Result<Self> {
        if hello.mode != Mode::PerSubstep {
            return Err(Error::invalid("site.mode", "RemoteSite needs the per-substep mode"));
        }
        Ok(Self {
            client: SiteClient::connect(addr, transport, hello, options)?,
        })
    }

    /// Connect with the handshake of `controller` (per sub-step).
    pub fn for_controller(
        addr: impl ToSocketAddrs,
        transport: Transport,
        controller: &SubstepController,
        options: &ClientOptions,
    ) -> Result<Self> {
        Self::connect(
            addr,
            transport,
            Hello::from_controller(controller, Mode::PerSubstep),
            options,
        )
    }

    pub fn client(&mut self) -> &mut SiteClient {
        &mut self.client
    }
    pub fn peer(&self) -> SocketAddr {
        self.client.peer()
    }
}

impl ExperimentalSubstructure for RemoteSite {
    fn n_coupling(&self) -> usize {
        self.client.hello.n_coupling
    }

    fn substep(
        &mut self,
        command: &[f64],
        ag: (f64, f64),
        dtau: f64,
        force: &mut [f64],
        displacement: &mut [f64],
    ) -> Result<()> {
        if let Some(i) = command.iter().position(|c| !c.is_finite()) {
            return Err(Error::numerical(
                format!("command to site {}", self.client.peer),
                format!("coupling DOF {} is not finite ({})", i + 1, command[i]),
            ));
        }
        let msg = Message::Substep {
            command: command.to_vec(),
            ag,
            dtau,
        };
        match self.client.request(&msg)? {
            Message::Measured {
                force: f,
                displacement: d,
            } => {
                force.copy_from_slice(&f);
                displacement.copy_from_slice(&d);
                Ok(())
            }
            other => Err(self
                .client
                .fail(format!("unexpected {} reply to Substep", other.kind().name()))),
        }
    }

    fn is_linear(&self) -> Result<()> {
        Err(Error::invalid(
            format!("site {}", self.client.peer),
            "a remote site's linearity is unknown; the amplification-matrix analysis needs a local model",
        ))
    }
    fn state_len(&self) -> usize {
        0
    }
    fn write_state(&self, _out: &mut [f64]) {}
    fn read_state(&mut self, _state: &[f64]) {}
}

/// A remote site in per-step mode: the site runs the `k_sub` sub-steps of each step.
pub struct RemoteStepSite {
    client: SiteClient,
    reply: StepReply,
}

impl RemoteStepSite {
    /// Connect with a per-step handshake (which carries `G_cc`, `k_sub` and `Δτ`).
    pub fn connect(
        addr: impl ToSocketAddrs,
        transport: Transport,
        hello: Hello,
        options: &ClientOptions,
    ) -> Result<Self> {
        if hello.mode != Mode::PerStep {
            return Err(Error::invalid("site.mode", "RemoteStepSite needs the per-step mode"));
        }
        let reply = StepReply::zeros(&hello.session());
        Ok(Self {
            client: SiteClient::connect(addr, transport, hello, options)?,
            reply,
        })
    }

    /// Connect with the handshake of `controller` (per step).
    pub fn for_controller(
        addr: impl ToSocketAddrs,
        transport: Transport,
        controller: &SubstepController,
        options: &ClientOptions,
    ) -> Result<Self> {
        Self::connect(
            addr,
            transport,
            Hello::from_controller(controller, Mode::PerStep),
            options,
        )
    }

    pub fn client(&mut self) -> &mut SiteClient {
        &mut self.client
    }
    pub fn peer(&self) -> SocketAddr {
        self.client.peer()
    }
    pub fn n_coupling(&self) -> usize {
        self.client.hello.n_coupling
    }

    /// Run one step at the site from the controller's predictor data (after `begin_step`).
    pub fn step(
        &mut self,
        predictor_c_prev: &[f64],
        predictor_c: &[f64],
        force_prev: &[f64],
        ag: (f64, f64),
    ) -> Result<&StepReply> {
        for (name, v) in [
            ("predictor_c_prev", predictor_c_prev),
            ("predictor_c", predictor_c),
            ("force_prev", force_prev),
        ] {
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(Error::numerical(
                    format!("step request to site {}", self.client.peer),
                    format!("{name}[{i}] is not finite ({})", v[i]),
                ));
            }
        }
        let msg = Message::Step(StepRequest {
            predictor_c_prev: predictor_c_prev.to_vec(),
            predictor_c: predictor_c.to_vec(),
            force_prev: force_prev.to_vec(),
            ag,
        });
        match self.client.request(&msg)? {
            Message::StepResult(r) => {
                self.reply = r;
                Ok(&self.reply)
            }
            other => Err(self
                .client
                .fail(format!("unexpected {} reply to Step", other.kind().name()))),
        }
    }
}

/// One step `i → i+1` of `controller` with the sub-steps executed at `site`: `begin_step`, one
/// `Step` round trip, then `next_command` / `feedback` for each returned sub-step (the site's
/// commands are checked bit for bit against the controller's), `finish_step`. `step` (the
/// number of the step being computed, 1-based) is passed to the observer. On `Err` the
/// controller's state is still that of the last completed step.
pub fn run_remote_step(
    controller: &mut SubstepController,
    site: &mut RemoteStepSite,
    load_next: &DVector<f64>,
    ag: (f64, f64),
    step: usize,
    observer: &mut impl SubstepObserver,
) -> Result<()> {
    if controller.estimation_stats().is_some() {
        // The estimation replaces the last sub-step's command; a per-step site runs the plain ramp.
        return Err(Error::invalid(
            "substructure.error_force",
            "error_force.kind = \"arx\" changes the last sub-step's command, which a per-step site \
             computes itself; use a per-sub-step site",
        ));
    }
    controller.begin_step(load_next);
    let n = controller.n_coupling();
    let k = controller.substeps();
    let peer = site.peer();
    let reply = site.step(
        controller.predictor_c_prev(),
        controller.predictor_c(),
        controller.coupling_force(),
        ag,
    )?;
    for j in 0..k {
        let row = j * n..(j + 1) * n;
        let command = controller.next_command();
        if let Some(i) = (0..n).find(|&i| command[i].to_bits() != reply.commands[row.start + i].to_bits()) {
            return Err(Error::numerical(
                format!("site {peer}"),
                format!(
                    "sub-step {} of step {step}: the site commanded {:e} on coupling DOF {} where the controller computes {:e} \
                     (the site does not run the same sub-step ramp)",
                    j + 1,
                    reply.commands[row.start + i],
                    i + 1,
                    command[i]
                ),
            ));
        }
        observer.substep(
            step,
            j + 1,
            controller.command(),
            &reply.forces[row.clone()],
            &reply.displacements[row.clone()],
        );
        controller.feedback(&reply.forces[row]);
    }
    controller.finish_step();
    Ok(())
}

/// The per-step counterpart of [`crate::substructure::SubstructureTest`]: controller + remote
/// per-step site + ground-motion load `−M ι a_g`.
pub struct RemoteStepTest {
    pub controller: SubstepController,
    pub site: RemoteStepSite,
    mass_influence: DVector<f64>,
    load: DVector<f64>,
    step: usize,
    measured_displacement: Vec<f64>,
}

impl RemoteStepTest {
    /// The site must have been connected with this controller's handshake.
    pub fn new<'a>(
        model: impl Into<ModelRef<'a>>,
        controller: SubstepController,
        site: RemoteStepSite,
    ) -> Result<Self> {
        let model = model.into();
        let expected = Hello::from_controller(&controller, Mode::PerStep);
        let h = site.client.hello();
        let same = h.n_coupling == expected.n_coupling
            && h.substeps == expected.substeps
            && h.dtau.to_bits() == expected.dtau.to_bits()
            && h.gain_cc
                .iter()
                .zip(&expected.gain_cc)
                .all(|(a, b)| a.to_bits() == b.to_bits());
        if !same {
            return Err(Error::invalid(
                format!("site {}", site.peer()),
                "the site was connected with a handshake that does not match the controller (n_c, k_sub, Δτ or G_cc)",
            ));
        }
        let n_c = controller.n_coupling();
        Ok(Self {
            controller,
            site,
            mass_influence: model.effective_mass_vector(),
            load: DVector::zeros(model.n_dofs()),
            step: 0,
            measured_displacement: vec![0.0; n_c],
        })
    }

    /// Advance from `t_i` (ground acceleration `ag_i`) to `t_{i+1}` (`ag_next`).
    pub fn step(&mut self, ag_i: f64, ag_next: f64, observer: &mut impl SubstepObserver) -> Result<()> {
        self.load.copy_from(&self.mass_influence);
        self.load.scale_mut(-ag_next);
        let step = self.step + 1;
        run_remote_step(
            &mut self.controller,
            &mut self.site,
            &self.load,
            (ag_i, ag_next),
            step,
            observer,
        )
        .map_err(|e| Error::Stopped {
            step,
            time: step as f64 * self.controller.dt(),
            reason: format!("experimental side failed: {e}"),
        })?;
        let n = self.controller.n_coupling();
        let k = self.controller.substeps();
        self.measured_displacement
            .copy_from_slice(&self.site.reply.displacements[(k - 1) * n..k * n]);
        self.step += 1;
        if !self.controller.state().is_finite() {
            return Err(Error::Diverged {
                step: self.step,
                time: self.step as f64 * self.controller.dt(),
                reason: "the response is no longer finite (NaN or overflow)".into(),
            });
        }
        Ok(())
    }

    pub fn steps_done(&self) -> usize {
        self.step
    }

    pub fn record(&self) -> StepRecord<'_> {
        StepRecord::of(&self.controller, self.step, &self.measured_displacement)
    }
}
