//! The `substep` site protocol (`SSTP`, version 1; version 2 frames in authenticated sessions).
//!
//! Every message is one frame: a 16-byte header and a payload, all little-endian.
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `b"SSTP"` |
//! | 4 | 2 | protocol version (u16, = [`VERSION`], or [`VERSION_AUTHENTICATED`] see below) |
//! | 6 | 2 | message type (u16, [`MessageType`]) |
//! | 8 | 4 | sequence number (u32) |
//! | 12 | 4 | payload length in bytes (u32, ≤ [`MAX_PAYLOAD`]; with the tag in version 2) |
//!
//! Payloads (`n` = `n_c`, `k` = `k_sub` of the handshake; `f64` IEEE-754, `u32`; strings are a
//! u32 byte count and UTF-8 bytes):
//!
//! | type | code | payload |
//! |---|---|---|
//! | `Hello` | 1 | `u32 version, u32 n, u32 k, u32 mode (0 per sub-step, 1 per step), f64 Δt, f64 Δτ, f64 G_cc[n·n] (column-major), u32 coupling_dof[n] (0-based model DOFs)` |
//! | `Accept` | 2 | `u32 n` (the site's coupling DOFs) [, `u8 MAC_s[32]` after an `Auth`] |
//! | `Reject` | 3 | string reason |
//! | `Substep` | 4 | `f64 command[n], f64 ag_start, f64 ag_end, f64 Δτ` |
//! | `Measured` | 5 | `f64 force[n], f64 displacement[n]` |
//! | `Step` | 6 | `f64 x̂_c_prev[n], f64 x̂_c[n], f64 f0[n], f64 ag(t_i), f64 ag(t_i+1)` |
//! | `StepResult` | 7 | `f64 command[k·n], f64 force[k·n], f64 displacement[k·n]` (sub-step-major) |
//! | `Heartbeat` | 8 | empty |
//! | `Stop` | 9 | string reason |
//! | `Error` | 10 | string reason |
//! | `Challenge` | 11 | `u8 nonce[32]` (a site with a secret answers `Hello` with it) |
//! | `Auth` | 12 | `u8 nonce[32], u8 MAC_c[32]` (the client's proof, see [`super::auth`]) |
//! | `Dropped` | 13 | string reason; version 2 only: a UDP site's notice that a datagram with this sequence number failed authentication and was not executed |
//!
//! **Authenticated sessions.** Without a secret every frame is version 1 and carries no MAC.
//! With a secret, the handshake (`Hello`, `Challenge`, `Auth`, `Accept`/`Reject`) is version 1
//! as above, and every later frame in both directions is a *version 2* frame: the header with
//! version [`VERSION_AUTHENTICATED`], the payload as above, then a [`TAG_LEN`]-byte tag; the
//! header's length counts payload and tag. The tag is HMAC-SHA256 under the sender's session
//! key over the header and the payload, truncated ([`super::auth::SessionKeys`]), so the type,
//! the sequence number, the length and every payload byte are authenticated. A receiver checks
//! the tag before anything else, then the sequence number. A frame of the other version is
//! refused in either kind of session (so a MAC cannot be stripped, and a peer that does not
//! authenticate its messages is detected at its first message).
//!
//! Sequence numbers: the client numbers its requests 0, 1, 2, … (`Hello` is 0); every reply
//! carries the number of the request it answers. With authentication the handshake is
//! `Hello #0 → Challenge #0`, `Auth #1 → Accept #1`, and the session's requests start at 2. Over UDP a request that times out is sent
//! again with the same number; the server answers a repeated number with its cached reply
//! (the site is not moved twice) and the client ignores replies to older numbers. In an
//! authenticated session only an *authentic* repeat (its tag checks) gets the cached reply.
//!
//! What a bad message does in an authenticated session (tag mismatch, version 1 frame, or an
//! authentic frame with an unexpected sequence number, i.e. a replay or reordering): over TCP
//! it ends the session at once, and the site answers an authenticated `Error` that starts
//! with `message authentication failed:`; a client that receives a bad reply stops with the
//! same words. Over UDP a datagram that fails its tag is dropped and not executed, and the
//! session goes on (anyone who can send to the site's port could otherwise end a session with
//! one forged datagram); the site logs it and answers an authenticated `Dropped` notice, which
//! the client only remembers: if its request then gets no reply (every attempt was changed on
//! the way), it stops with `message authentication failed: the site dropped …`. An authentic
//! UDP datagram with an unexpected (newer) number ends the session as it does without a secret.
//!
//! Decoding validates everything and never panics: magic, version, type, length limits,
//! payload length against the handshake's `n_c`/`k_sub`, finite numbers, UTF-8 strings.
//! Errors are [`Error::InvalidInput`] whose `what` names the offending field.

use super::auth::{MAC_LEN, NONCE_LEN, SessionKeys, TAG_LEN};
use crate::error::{Error, Result};

pub const MAGIC: [u8; 4] = *b"SSTP";
pub const VERSION: u16 = 1;
/// The header version of the frames of an authenticated session after the handshake: they
/// end with a [`TAG_LEN`]-byte tag.
pub const VERSION_AUTHENTICATED: u16 = 2;
pub const HEADER_LEN: usize = 16;
/// Largest payload accepted on any transport, in bytes.
pub const MAX_PAYLOAD: usize = 1 << 24;
/// Largest UDP datagram (header + payload), in bytes.
pub const MAX_DATAGRAM: usize = 65_507;
/// Limits checked in the handshake.
pub const MAX_COUPLING: usize = 1024;
pub const MAX_SUBSTEPS: usize = 1 << 20;
/// Longest reason string, in bytes.
pub const MAX_REASON: usize = 4096;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u16)]
pub enum MessageType {
    Hello = 1,
    Accept = 2,
    Reject = 3,
    Substep = 4,
    Measured = 5,
    Step = 6,
    StepResult = 7,
    Heartbeat = 8,
    Stop = 9,
    Error = 10,
    Challenge = 11,
    Auth = 12,
    Dropped = 13,
}

impl MessageType {
    pub fn from_code(code: u16) -> Option<Self> {
        use MessageType::*;
        Some(match code {
            1 => Hello,
            2 => Accept,
            3 => Reject,
            4 => Substep,
            5 => Measured,
            6 => Step,
            7 => StepResult,
            8 => Heartbeat,
            9 => Stop,
            10 => Error,
            11 => Challenge,
            12 => Auth,
            13 => Dropped,
            _ => return None,
        })
    }
    pub fn code(self) -> u16 {
        self as u16
    }
    pub fn name(self) -> &'static str {
        use MessageType::*;
        match self {
            Hello => "Hello",
            Accept => "Accept",
            Reject => "Reject",
            Substep => "Substep",
            Measured => "Measured",
            Step => "Step",
            StepResult => "StepResult",
            Heartbeat => "Heartbeat",
            Stop => "Stop",
            Error => "Error",
            Challenge => "Challenge",
            Auth => "Auth",
            Dropped => "Dropped",
        }
    }
}

fn perr(what: impl AsRef<str>, reason: impl Into<String>) -> Error {
    Error::invalid(format!("site protocol: {}", what.as_ref()), reason)
}

/// The words every authentication failure of a session message starts with.
pub const AUTH_FAILED: &str = "message authentication failed";

fn auth_err(reason: impl Into<String>) -> Error {
    Error::invalid(AUTH_FAILED, reason)
}

/// `e` as an authentication failure (starting with [`AUTH_FAILED`]), for errors of frames of
/// an authenticated session.
pub fn as_auth_failure(e: Error) -> Error {
    let text = e.to_string();
    if text.starts_with(AUTH_FAILED) {
        e
    } else {
        auth_err(text)
    }
}

/// A frame header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    pub version: u16,
    pub kind: MessageType,
    pub seq: u32,
    /// Payload length, in bytes.
    pub len: u32,
}

impl Header {
    pub fn write(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&self.version.to_le_bytes());
        out.extend_from_slice(&self.kind.code().to_le_bytes());
        out.extend_from_slice(&self.seq.to_le_bytes());
        out.extend_from_slice(&self.len.to_le_bytes());
    }

    /// Parse and validate the first [`HEADER_LEN`] bytes of `bytes` (a version 1 frame).
    pub fn parse(bytes: &[u8]) -> Result<Header> {
        Self::parse_version(bytes, false)
    }

    /// Parse the header of a frame of a session: an authenticated session's frames must be
    /// version 2 ([`VERSION_AUTHENTICATED`], the tag still to be checked with [`open_sealed`]),
    /// the others version 1 ([`Header::parse`]).
    pub fn parse_session(bytes: &[u8], authenticated: bool) -> Result<Header> {
        Self::parse_version(bytes, authenticated)
    }

    fn parse_version(bytes: &[u8], authenticated: bool) -> Result<Header> {
        let header = Self::parse_fields(bytes, authenticated);
        if authenticated {
            // In an authenticated session a frame that does not even parse was changed or
            // forged just the same.
            header.map_err(as_auth_failure)
        } else {
            header
        }
    }

    fn parse_fields(bytes: &[u8], authenticated: bool) -> Result<Header> {
        if bytes.len() < HEADER_LEN {
            return Err(perr("header", format!("{} bytes, need {HEADER_LEN}", bytes.len())));
        }
        if bytes[0..4] != MAGIC {
            return Err(perr(
                "header.magic",
                format!(
                    "is {:02x?}, expected \"SSTP\" (not a substep site protocol frame)",
                    &bytes[0..4]
                ),
            ));
        }
        let version = u16::from_le_bytes([bytes[4], bytes[5]]);
        let code = u16::from_le_bytes([bytes[6], bytes[7]]);
        let seq = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
        if authenticated && version != VERSION_AUTHENTICATED {
            let kind = MessageType::from_code(code).map_or_else(|| format!("type {code}"), |k| k.name().to_string());
            return Err(auth_err(format!(
                "{kind} #{seq} is a version {version} frame without a MAC, but this session is authenticated (version {VERSION_AUTHENTICATED} frames)"
            )));
        }
        if !authenticated && version != VERSION {
            return Err(perr(
                "header.version",
                format!("is {version}, this program speaks version {VERSION}"),
            ));
        }
        let kind = MessageType::from_code(code)
            .filter(|k| authenticated || *k != MessageType::Dropped)
            .ok_or_else(|| perr("header.type", format!("{code} is not a known message type (1..=12)")))?;
        let len = u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]);
        let max = if authenticated {
            MAX_PAYLOAD + TAG_LEN
        } else {
            MAX_PAYLOAD
        };
        if len as usize > max {
            return Err(perr("header.length", format!("{len} bytes exceeds the limit of {max}")));
        }
        Ok(Header {
            version,
            kind,
            seq,
            len,
        })
    }
}

/// How the work of a step is split between controller and site.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// One `Substep` → `Measured` round trip per sub-step.
    PerSubstep,
    /// One `Step` → `StepResult` round trip per step; the site runs the sub-step loop.
    PerStep,
}

impl Mode {
    fn code(self) -> u32 {
        match self {
            Mode::PerSubstep => 0,
            Mode::PerStep => 1,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Mode::PerSubstep => "per-substep",
            Mode::PerStep => "per-step",
        }
    }
}

/// The client's handshake.
#[derive(Debug, Clone, PartialEq)]
pub struct Hello {
    pub n_coupling: usize,
    pub substeps: usize,
    pub mode: Mode,
    /// Time step Δt and sub-step length Δτ, in seconds.
    pub dt: f64,
    pub dtau: f64,
    /// `G_cc`, `n_c × n_c`, column-major [m/N] (used by the site in per-step mode).
    pub gain_cc: Vec<f64>,
    /// The model DOF (0-based) of each coupling DOF, in the controller's order: the site
    /// attaches its specimens by these (see [`super::VirtualLabSpec`]).
    pub coupling_dofs: Vec<usize>,
}

impl Hello {
    /// The handshake for `controller` (Δτ = Δt / k_sub, computed as the test runner does).
    pub fn from_controller(controller: &crate::substructure::SubstepController, mode: Mode) -> Self {
        let k = controller.substeps();
        Hello {
            n_coupling: controller.n_coupling(),
            substeps: k,
            mode,
            dt: controller.dt(),
            dtau: controller.dt() / k as f64,
            gain_cc: controller.gain_cc().as_slice().to_vec(),
            coupling_dofs: controller.coupling_dofs().to_vec(),
        }
    }

    /// Validate ranges and sizes (also done by [`Message::decode`]).
    pub fn validate(&self) -> Result<()> {
        if self.n_coupling == 0 || self.n_coupling > MAX_COUPLING {
            return Err(perr(
                "Hello.n_coupling",
                format!("is {}, must be 1..={MAX_COUPLING}", self.n_coupling),
            ));
        }
        if self.substeps == 0 || self.substeps > MAX_SUBSTEPS {
            return Err(perr(
                "Hello.substeps",
                format!("is {}, must be 1..={MAX_SUBSTEPS}", self.substeps),
            ));
        }
        for (name, v) in [("Hello.dt", self.dt), ("Hello.dtau", self.dtau)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(perr(name, format!("must be a finite number > 0, got {v}")));
            }
        }
        if self.gain_cc.len() != self.n_coupling * self.n_coupling {
            return Err(perr(
                "Hello.gain_cc",
                format!(
                    "has {} entries, expected {} (n_c × n_c)",
                    self.gain_cc.len(),
                    self.n_coupling * self.n_coupling
                ),
            ));
        }
        if let Some(i) = self.gain_cc.iter().position(|g| !g.is_finite()) {
            return Err(perr(format!("Hello.gain_cc[{i}]"), "is not finite"));
        }
        if self.coupling_dofs.len() != self.n_coupling {
            return Err(perr(
                "Hello.coupling_dofs",
                format!(
                    "has {} entries, expected n_c = {}",
                    self.coupling_dofs.len(),
                    self.n_coupling
                ),
            ));
        }
        for (i, &d) in self.coupling_dofs.iter().enumerate() {
            if d > u32::MAX as usize {
                return Err(perr(
                    format!("Hello.coupling_dofs[{i}]"),
                    format!("{d} does not fit a u32"),
                ));
            }
            if self.coupling_dofs[..i].contains(&d) {
                return Err(perr(
                    format!("Hello.coupling_dofs[{i}]"),
                    format!("model DOF {d} is listed twice"),
                ));
            }
        }
        if self.session().step_result_len() > MAX_PAYLOAD {
            return Err(perr(
                "Hello",
                format!(
                    "a StepResult for n_c = {} and k_sub = {} would exceed {MAX_PAYLOAD} bytes",
                    self.n_coupling, self.substeps
                ),
            ));
        }
        Ok(())
    }

    pub fn session(&self) -> Session {
        Session {
            n_coupling: self.n_coupling,
            substeps: self.substeps,
        }
    }
}

/// Payload length of a `Hello` for `n` coupling DOFs, in bytes.
pub fn hello_payload_len(n: usize) -> usize {
    32 + 8 * n * n + 4 * n
}

/// What the decoder needs to know from the handshake.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Session {
    pub n_coupling: usize,
    pub substeps: usize,
}

impl Session {
    /// Payload length of a `StepResult`, in bytes.
    pub fn step_result_len(&self) -> usize {
        3 * self.n_coupling * self.substeps * 8
    }
    /// Largest payload of a request of this session (what a site reads), in bytes.
    pub fn max_request_payload(&self) -> usize {
        let n = self.n_coupling;
        hello_payload_len(n)
            .max(8 * (3 * n + 2))
            .max(8 * (n + 3))
            .max(4 + MAX_REASON)
            .max(NONCE_LEN + MAC_LEN)
    }
    /// Largest payload of any message of this session, in bytes (for UDP limits).
    pub fn max_payload(&self) -> usize {
        let n = self.n_coupling;
        (16 + 8 * (2 + n * n) + 4 * n)
            .max(self.step_result_len())
            .max(8 * (3 * n + 2))
            .max(4 + MAX_REASON)
    }
}

/// Per-step request: the controller's predictor data after `begin_step`.
#[derive(Debug, Clone, PartialEq)]
pub struct StepRequest {
    /// `x̂_c^{(i)}`, `x̂_c`, `f^{(0)} = f_c,i`.
    pub predictor_c_prev: Vec<f64>,
    pub predictor_c: Vec<f64>,
    pub force_prev: Vec<f64>,
    /// `a_g(t_i)`, `a_g(t_{i+1})`.
    pub ag: (f64, f64),
}

/// Per-step reply: every sub-step's command, force and displacement (row `j` = sub-step
/// `j + 1`, `k × n_c` each, sub-step-major).
#[derive(Debug, Clone, PartialEq)]
pub struct StepReply {
    pub commands: Vec<f64>,
    pub forces: Vec<f64>,
    pub displacements: Vec<f64>,
}

impl StepReply {
    pub fn zeros(session: &Session) -> Self {
        let l = session.n_coupling * session.substeps;
        StepReply {
            commands: vec![0.0; l],
            forces: vec![0.0; l],
            displacements: vec![0.0; l],
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    Hello(Hello),
    Accept {
        n_coupling: usize,
        /// The site's proof after an `Auth` (see [`super::auth`]).
        mac: Option<[u8; MAC_LEN]>,
    },
    Reject {
        reason: String,
    },
    Substep {
        command: Vec<f64>,
        ag: (f64, f64),
        dtau: f64,
    },
    Measured {
        force: Vec<f64>,
        displacement: Vec<f64>,
    },
    Step(StepRequest),
    StepResult(StepReply),
    Heartbeat,
    Stop {
        reason: String,
    },
    Error {
        reason: String,
    },
    Challenge {
        nonce: [u8; NONCE_LEN],
    },
    Auth {
        nonce: [u8; NONCE_LEN],
        mac: [u8; MAC_LEN],
    },
    /// Only sealed (version 2): see the module docs.
    Dropped {
        reason: String,
    },
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}
fn put_f64s(out: &mut Vec<u8>, v: &[f64]) {
    for x in v {
        out.extend_from_slice(&x.to_le_bytes());
    }
}
fn put_str(out: &mut Vec<u8>, s: &str) {
    // Truncate on a char boundary so the receiver's limit holds.
    let mut end = s.len().min(MAX_REASON);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    put_u32(out, end as u32);
    out.extend_from_slice(&s.as_bytes()[..end]);
}

impl Message {
    pub fn kind(&self) -> MessageType {
        match self {
            Message::Hello(_) => MessageType::Hello,
            Message::Accept { .. } => MessageType::Accept,
            Message::Reject { .. } => MessageType::Reject,
            Message::Substep { .. } => MessageType::Substep,
            Message::Measured { .. } => MessageType::Measured,
            Message::Step(_) => MessageType::Step,
            Message::StepResult(_) => MessageType::StepResult,
            Message::Heartbeat => MessageType::Heartbeat,
            Message::Stop { .. } => MessageType::Stop,
            Message::Error { .. } => MessageType::Error,
            Message::Challenge { .. } => MessageType::Challenge,
            Message::Auth { .. } => MessageType::Auth,
            Message::Dropped { .. } => MessageType::Dropped,
        }
    }

    /// Encode as one frame with sequence number `seq` into `out` (cleared first).
    pub fn encode(&self, seq: u32, out: &mut Vec<u8>) {
        out.clear();
        Header {
            version: VERSION,
            kind: self.kind(),
            seq,
            len: 0,
        }
        .write(out);
        match self {
            Message::Hello(h) => {
                put_u32(out, VERSION as u32);
                put_u32(out, h.n_coupling as u32);
                put_u32(out, h.substeps as u32);
                put_u32(out, h.mode.code());
                put_f64s(out, &[h.dt, h.dtau]);
                put_f64s(out, &h.gain_cc);
                for &d in &h.coupling_dofs {
                    put_u32(out, d as u32);
                }
            }
            Message::Accept { n_coupling, mac } => {
                put_u32(out, *n_coupling as u32);
                if let Some(m) = mac {
                    out.extend_from_slice(m);
                }
            }
            Message::Challenge { nonce } => out.extend_from_slice(nonce),
            Message::Auth { nonce, mac } => {
                out.extend_from_slice(nonce);
                out.extend_from_slice(mac);
            }
            Message::Reject { reason }
            | Message::Stop { reason }
            | Message::Error { reason }
            | Message::Dropped { reason } => put_str(out, reason),
            Message::Substep { command, ag, dtau } => {
                put_f64s(out, command);
                put_f64s(out, &[ag.0, ag.1, *dtau]);
            }
            Message::Measured { force, displacement } => {
                put_f64s(out, force);
                put_f64s(out, displacement);
            }
            Message::Step(s) => {
                put_f64s(out, &s.predictor_c_prev);
                put_f64s(out, &s.predictor_c);
                put_f64s(out, &s.force_prev);
                put_f64s(out, &[s.ag.0, s.ag.1]);
            }
            Message::StepResult(r) => {
                put_f64s(out, &r.commands);
                put_f64s(out, &r.forces);
                put_f64s(out, &r.displacements);
            }
            Message::Heartbeat => {}
        }
        let len = (out.len() - HEADER_LEN) as u32;
        out[12..16].copy_from_slice(&len.to_le_bytes());
    }

    /// Encode as one frame of an authenticated session (version 2, with the tag under
    /// `keys`) into `out` (cleared first); `keys = None` is [`Message::encode`].
    pub fn encode_session(&self, seq: u32, out: &mut Vec<u8>, keys: Option<&SessionKeys>) {
        self.encode(seq, out);
        if let Some(keys) = keys {
            seal(out, keys);
        }
    }

    /// Decode a payload. Messages that depend on the handshake (`Substep`, `Measured`, `Step`,
    /// `StepResult`) need `session`.
    pub fn decode(header: &Header, payload: &[u8], session: Option<&Session>) -> Result<Message> {
        let kind = header.kind;
        let name = kind.name();
        if payload.len() != header.len as usize {
            return Err(perr(
                format!("{name} payload"),
                format!("{} bytes, but the header announces {}", payload.len(), header.len),
            ));
        }
        let need_session =
            || session.ok_or_else(|| perr(name, "received before the handshake (Hello/Accept) completed"));
        let expect_len = |expected: usize, detail: String| {
            if payload.len() == expected {
                Ok(())
            } else {
                Err(perr(
                    format!("{name} payload"),
                    format!("is {} bytes, expected {expected} ({detail})", payload.len()),
                ))
            }
        };
        let mut r = Reader { buf: payload, pos: 0 };
        let msg = match kind {
            MessageType::Hello => {
                if payload.len() < 32 {
                    return Err(perr(
                        "Hello payload",
                        format!("is {} bytes, at least 32 needed", payload.len()),
                    ));
                }
                let version = r.u32();
                if version != VERSION as u32 {
                    return Err(perr(
                        "Hello.version",
                        format!("is {version}, this program speaks version {VERSION}"),
                    ));
                }
                let n = r.u32() as usize;
                let k = r.u32() as usize;
                let mode = match r.u32() {
                    0 => Mode::PerSubstep,
                    1 => Mode::PerStep,
                    m => {
                        return Err(perr(
                            "Hello.mode",
                            format!("is {m}, expected 0 (per sub-step) or 1 (per step)"),
                        ));
                    }
                };
                if n == 0 || n > MAX_COUPLING {
                    return Err(perr("Hello.n_coupling", format!("is {n}, must be 1..={MAX_COUPLING}")));
                }
                expect_len(32 + 8 * n * n + 4 * n, format!("n_c = {n}"))?;
                let dt = r.f64("Hello.dt")?;
                let dtau = r.f64("Hello.dtau")?;
                let gain_cc = r.f64s("Hello.gain_cc", n * n)?;
                let coupling_dofs = (0..n).map(|_| r.u32() as usize).collect();
                let h = Hello {
                    n_coupling: n,
                    substeps: k,
                    mode,
                    dt,
                    dtau,
                    gain_cc,
                    coupling_dofs,
                };
                h.validate()?;
                Message::Hello(h)
            }
            MessageType::Accept => {
                if payload.len() != 4 && payload.len() != 4 + MAC_LEN {
                    expect_len(4, format!("one u32, or one u32 and a {MAC_LEN}-byte MAC"))?;
                }
                let n = r.u32() as usize;
                if n == 0 || n > MAX_COUPLING {
                    return Err(perr("Accept.n_coupling", format!("is {n}, must be 1..={MAX_COUPLING}")));
                }
                let mac = if payload.len() == 4 + MAC_LEN {
                    Some(r.bytes::<MAC_LEN>())
                } else {
                    None
                };
                Message::Accept { n_coupling: n, mac }
            }
            MessageType::Challenge => {
                expect_len(NONCE_LEN, "a nonce".into())?;
                Message::Challenge {
                    nonce: r.bytes::<NONCE_LEN>(),
                }
            }
            MessageType::Auth => {
                expect_len(NONCE_LEN + MAC_LEN, "a nonce and a MAC".into())?;
                Message::Auth {
                    nonce: r.bytes::<NONCE_LEN>(),
                    mac: r.bytes::<MAC_LEN>(),
                }
            }
            MessageType::Reject => Message::Reject {
                reason: r.string(name)?,
            },
            MessageType::Stop => Message::Stop {
                reason: r.string(name)?,
            },
            MessageType::Error => Message::Error {
                reason: r.string(name)?,
            },
            MessageType::Dropped => Message::Dropped {
                reason: r.string(name)?,
            },
            MessageType::Heartbeat => {
                expect_len(0, "empty".into())?;
                Message::Heartbeat
            }
            MessageType::Substep => {
                let n = need_session()?.n_coupling;
                expect_len(8 * (n + 3), format!("n_c = {n}"))?;
                let command = r.f64s("Substep.command", n)?;
                let ag = (r.f64("Substep.ag_start")?, r.f64("Substep.ag_end")?);
                let dtau = r.f64("Substep.dtau")?;
                if dtau <= 0.0 {
                    return Err(perr("Substep.dtau", format!("must be > 0, got {dtau}")));
                }
                Message::Substep { command, ag, dtau }
            }
            MessageType::Measured => {
                let n = need_session()?.n_coupling;
                expect_len(16 * n, format!("n_c = {n}"))?;
                Message::Measured {
                    force: r.f64s("Measured.force", n)?,
                    displacement: r.f64s("Measured.displacement", n)?,
                }
            }
            MessageType::Step => {
                let n = need_session()?.n_coupling;
                expect_len(8 * (3 * n + 2), format!("n_c = {n}"))?;
                Message::Step(StepRequest {
                    predictor_c_prev: r.f64s("Step.predictor_c_prev", n)?,
                    predictor_c: r.f64s("Step.predictor_c", n)?,
                    force_prev: r.f64s("Step.force_prev", n)?,
                    ag: (r.f64("Step.ag_start")?, r.f64("Step.ag_end")?),
                })
            }
            MessageType::StepResult => {
                let s = need_session()?;
                let l = s.n_coupling * s.substeps;
                expect_len(24 * l, format!("n_c = {}, k_sub = {}", s.n_coupling, s.substeps))?;
                Message::StepResult(StepReply {
                    commands: r.f64s("StepResult.commands", l)?,
                    forces: r.f64s("StepResult.forces", l)?,
                    displacements: r.f64s("StepResult.displacements", l)?,
                })
            }
        };
        if r.pos != payload.len() {
            return Err(perr(
                format!("{name} payload"),
                format!("{} trailing bytes", payload.len() - r.pos),
            ));
        }
        Ok(msg)
    }
}

/// Parse a whole frame (header + payload, nothing more).
pub fn decode_frame(frame: &[u8], session: Option<&Session>) -> Result<(Header, Message)> {
    let header = Header::parse(frame)?;
    let payload = &frame[HEADER_LEN..];
    if payload.len() != header.len as usize {
        return Err(perr(
            "header.length",
            format!(
                "announces {} payload bytes but the frame carries {}",
                header.len,
                payload.len()
            ),
        ));
    }
    let msg = Message::decode(&header, payload, session)?;
    Ok((header, msg))
}

/// Turn the version 1 frame in `frame` into a version 2 frame of an authenticated session:
/// version [`VERSION_AUTHENTICATED`], the length counting the tag, and the tag appended.
pub fn seal(frame: &mut Vec<u8>, keys: &SessionKeys) {
    frame[4..6].copy_from_slice(&VERSION_AUTHENTICATED.to_le_bytes());
    let len = (frame.len() - HEADER_LEN + TAG_LEN) as u32;
    frame[12..16].copy_from_slice(&len.to_le_bytes());
    let tag = keys.tag(frame);
    frame.extend_from_slice(&tag);
}

/// Check the tag of a whole frame of an authenticated session (header, payload and tag, as
/// received; the header already parsed with [`Header::parse_session`]); returns the header
/// with the payload's length (without the tag) and the payload, ready for [`Message::decode`].
/// Every error starts with [`AUTH_FAILED`] and names the message as its header claims it.
pub fn open_sealed<'a>(frame: &'a [u8], header: &Header, keys: &SessionKeys) -> Result<(Header, &'a [u8])> {
    // Named only on the error paths: the good path allocates nothing.
    let what = || format!("{} #{}", header.kind.name(), header.seq);
    let len = header.len as usize;
    if frame.len() != HEADER_LEN + len {
        return Err(auth_err(format!(
            "{}: the header announces {len} bytes after it, the frame carries {}",
            what(),
            frame.len().saturating_sub(HEADER_LEN)
        )));
    }
    if len < TAG_LEN {
        return Err(auth_err(format!(
            "{}: {len} bytes after the header, too short for the {TAG_LEN}-byte tag",
            what()
        )));
    }
    let (message, tag) = frame.split_at(frame.len() - TAG_LEN);
    if !keys.verify(message, tag) {
        return Err(auth_err(format!(
            "{}: the tag does not match (the message was changed on the way, forged, or sealed with another key)",
            what()
        )));
    }
    let header = Header {
        len: (len - TAG_LEN) as u32,
        ..*header
    };
    Ok((header, &message[HEADER_LEN..]))
}

/// Bounds-checked little-endian reader. Lengths are checked before reading numbers, but every
/// access is still checked so that no input can panic.
struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let end = self.pos.checked_add(N)?;
        let bytes: [u8; N] = self.buf.get(self.pos..end)?.try_into().ok()?;
        self.pos = end;
        Some(bytes)
    }
    /// `N` bytes; the caller has checked the payload length (zeros otherwise).
    fn bytes<const N: usize>(&mut self) -> [u8; N] {
        self.take::<N>().unwrap_or([0; N])
    }
    fn u32(&mut self) -> u32 {
        self.take::<4>().map(u32::from_le_bytes).unwrap_or(u32::MAX)
    }
    fn f64(&mut self, what: &str) -> Result<f64> {
        let v = self
            .take::<8>()
            .map(f64::from_le_bytes)
            .ok_or_else(|| perr(what, "payload too short"))?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(perr(what, format!("is not finite ({v})")))
        }
    }
    fn f64s(&mut self, what: &str, n: usize) -> Result<Vec<f64>> {
        let mut v = Vec::with_capacity(n.min(self.buf.len() / 8));
        for i in 0..n {
            let x = self
                .take::<8>()
                .map(f64::from_le_bytes)
                .ok_or_else(|| perr(what, "payload too short"))?;
            if !x.is_finite() {
                return Err(perr(format!("{what}[{i}]"), format!("is not finite ({x})")));
            }
            v.push(x);
        }
        Ok(v)
    }
    fn string(&mut self, name: &str) -> Result<String> {
        let len = self
            .take::<4>()
            .map(u32::from_le_bytes)
            .ok_or_else(|| perr(format!("{name}.reason"), "payload too short for the length"))?
            as usize;
        if len > MAX_REASON {
            return Err(perr(
                format!("{name}.reason"),
                format!("length {len} exceeds {MAX_REASON}"),
            ));
        }
        if self.buf.len() - self.pos != len {
            return Err(perr(
                format!("{name}.reason"),
                format!("announces {len} bytes but {} follow", self.buf.len() - self.pos),
            ));
        }
        let bytes = &self.buf[self.pos..];
        self.pos = self.buf.len();
        String::from_utf8(bytes.to_vec()).map_err(|_| perr(format!("{name}.reason"), "is not valid UTF-8"))
    }
}

#[cfg(test)]
mod tests {
    //! The MAC framing of authenticated sessions: any change of a sealed frame is detected,
    //! a frame is valid only in its direction and its session, and a replay or reordering
    //! is an authentic frame whose sequence number the receiver refuses (tested at the session
    //! level in `tests/site_hardening.rs`).
    use super::*;
    use crate::site::auth::{Role, Secret};

    const SITE_NONCE: [u8; NONCE_LEN] = [7; NONCE_LEN];
    const CLIENT_NONCE: [u8; NONCE_LEN] = [9; NONCE_LEN];
    const SESSION: Session = Session {
        n_coupling: 2,
        substeps: 4,
    };

    fn keys(role: Role, site_nonce: &[u8; NONCE_LEN]) -> SessionKeys {
        Secret::new(b"a shared secret of the lab, 32 b", "test")
            .unwrap()
            .session_keys(role, site_nonce, &CLIENT_NONCE, b"the Hello payload")
    }

    fn substep(seq: u32, keys: &SessionKeys) -> Vec<u8> {
        let mut frame = Vec::new();
        Message::Substep {
            command: vec![1e-3, -2e-3],
            ag: (0.5, 0.25),
            dtau: 0.0025,
        }
        .encode_session(seq, &mut frame, Some(keys));
        frame
    }

    /// What the site makes of a frame from the client.
    fn open(frame: &[u8], keys: &SessionKeys) -> Result<(Header, Message)> {
        let header = Header::parse_session(frame, true)?;
        let (header, payload) = open_sealed(frame, &header, keys)?;
        Ok((header, Message::decode(&header, payload, Some(&SESSION))?))
    }

    fn assert_refused(frame: &[u8], keys: &SessionKeys, what: &str) {
        match open(frame, keys) {
            Err(e) => assert!(e.to_string().starts_with(AUTH_FAILED), "{what}: {e}"),
            Ok(m) => panic!("{what}: accepted {m:?}"),
        }
    }

    #[test]
    fn a_sealed_frame_opens_to_the_same_message() {
        let (client, site) = (keys(Role::Client, &SITE_NONCE), keys(Role::Site, &SITE_NONCE));
        let frame = substep(5, &client);
        let mut plain = Vec::new();
        Message::Substep {
            command: vec![1e-3, -2e-3],
            ag: (0.5, 0.25),
            dtau: 0.0025,
        }
        .encode(5, &mut plain);
        // version 2, the length counts the tag, the rest is the version 1 frame
        assert_eq!(frame.len(), plain.len() + TAG_LEN);
        assert_eq!(u16::from_le_bytes([frame[4], frame[5]]), VERSION_AUTHENTICATED);
        assert_eq!(frame[HEADER_LEN..plain.len()], plain[HEADER_LEN..]);
        let (header, msg) = open(&frame, &site).unwrap();
        assert_eq!(
            (header.kind, header.seq, header.len as usize),
            (MessageType::Substep, 5, plain.len() - HEADER_LEN)
        );
        assert_eq!(decode_frame(&plain, Some(&SESSION)).unwrap().1, msg);
        // and the other direction
        let mut reply = Vec::new();
        Message::Measured {
            force: vec![3.0, 4.0],
            displacement: vec![1e-3, -2e-3],
        }
        .encode_session(5, &mut reply, Some(&site));
        let header = Header::parse_session(&reply, true).unwrap();
        assert!(open_sealed(&reply, &header, &client).is_ok());
        // without keys, encode_session is the version 1 encoding byte for byte
        let mut unsealed = Vec::new();
        Message::Heartbeat.encode_session(3, &mut unsealed, None);
        let mut v1 = Vec::new();
        Message::Heartbeat.encode(3, &mut v1);
        assert_eq!(unsealed, v1);
    }

    #[test]
    fn every_changed_bit_of_a_sealed_frame_is_detected() {
        let (client, site) = (keys(Role::Client, &SITE_NONCE), keys(Role::Site, &SITE_NONCE));
        let frame = substep(2, &client);
        // magic, version, type, sequence number, length, payload and tag: every bit
        for bit in 0..8 * frame.len() {
            let mut bad = frame.clone();
            bad[bit / 8] ^= 1 << (bit % 8);
            assert_refused(&bad, &site, &format!("bit {bit}"));
        }
    }

    #[test]
    fn a_changed_type_sequence_number_payload_or_tag_is_refused_with_a_reason() {
        let (client, site) = (keys(Role::Client, &SITE_NONCE), keys(Role::Site, &SITE_NONCE));
        let frame = substep(2, &client);
        let reason = |f: &[u8]| open(f, &site).unwrap_err().to_string();
        // type: a Substep passed off as a Step (the payload would not even fit) or Heartbeat
        let mut bad = frame.clone();
        bad[6..8].copy_from_slice(&MessageType::Heartbeat.code().to_le_bytes());
        assert!(
            reason(&bad).contains("Heartbeat #2: the tag does not match"),
            "{}",
            reason(&bad)
        );
        // sequence number
        let mut bad = frame.clone();
        bad[8..12].copy_from_slice(&3u32.to_le_bytes());
        assert!(
            reason(&bad).contains("Substep #3: the tag does not match"),
            "{}",
            reason(&bad)
        );
        // payload: the command × 1000 (the attack of the issue)
        let mut bad = frame.clone();
        let command = f64::from_le_bytes(bad[HEADER_LEN..HEADER_LEN + 8].try_into().unwrap());
        bad[HEADER_LEN..HEADER_LEN + 8].copy_from_slice(&(command * 1000.0).to_le_bytes());
        assert!(reason(&bad).contains("the tag does not match"), "{}", reason(&bad));
        // tag
        let mut bad = frame.clone();
        let last = bad.len() - 1;
        bad[last] ^= 0x80;
        assert!(reason(&bad).contains("the tag does not match"), "{}", reason(&bad));
        // the tag stripped: a version 1 frame in an authenticated session
        let mut plain = Vec::new();
        Message::Heartbeat.encode(2, &mut plain);
        assert_eq!(
            reason(&plain),
            "message authentication failed: Heartbeat #2 is a version 1 frame without a MAC, but this session is authenticated (version 2 frames)"
        );
        // the tag stripped but the header made version 2: too short, or a tag over other bytes
        let mut bad = plain.clone();
        bad[4..6].copy_from_slice(&VERSION_AUTHENTICATED.to_le_bytes());
        assert!(
            reason(&bad).contains("too short for the 16-byte tag"),
            "{}",
            reason(&bad)
        );
        // truncated and extended frames
        assert!(open(&frame[..frame.len() - 1], &site).is_err());
        let mut longer = frame.clone();
        longer.push(0);
        assert!(reason(&longer).contains("the frame carries"), "{}", reason(&longer));
        // and a version 2 frame outside an authenticated session is refused as before
        assert!(
            Header::parse(&frame)
                .unwrap_err()
                .to_string()
                .contains("header.version: is 2")
        );
        let mut dropped = Vec::new();
        Message::Dropped { reason: "x".into() }.encode(0, &mut dropped);
        assert!(
            Header::parse(&dropped)
                .unwrap_err()
                .to_string()
                .contains("13 is not a known message type")
        );
    }

    #[test]
    fn a_frame_is_valid_only_in_its_direction_and_its_session() {
        let (client, site) = (keys(Role::Client, &SITE_NONCE), keys(Role::Site, &SITE_NONCE));
        // reflected: the client's own frame sent back to it as if it were the site's
        let frame = substep(2, &client);
        assert_refused(&frame, &client, "reflected to the client");
        // the site's reply fed to the site
        let mut reply = Vec::new();
        Message::Heartbeat.encode_session(2, &mut reply, Some(&site));
        assert_refused(&reply, &site, "reflected to the site");
        // another session (another site nonce): the keys differ
        let other_site = keys(Role::Site, &[8; NONCE_LEN]);
        assert_refused(&frame, &other_site, "from another session");
    }

    #[test]
    fn a_replayed_or_reordered_frame_is_authentic_but_carries_its_old_number() {
        // The tag covers the sequence number, so a replay or reordering cannot renumber a
        // frame: the receiver sees the old number and refuses it (tests/site_hardening.rs).
        let (client, site) = (keys(Role::Client, &SITE_NONCE), keys(Role::Site, &SITE_NONCE));
        let (first, second) = (substep(2, &client), substep(3, &client));
        assert_eq!(open(&first, &site).unwrap().0.seq, 2);
        assert_eq!(open(&second, &site).unwrap().0.seq, 3);
        // renumbering the replay to the expected number breaks its tag
        let mut renumbered = first.clone();
        renumbered[8..12].copy_from_slice(&4u32.to_le_bytes());
        assert_refused(&renumbered, &site, "renumbered replay");
        // splicing the payload of one frame under the header of another
        let mut spliced = second.clone();
        spliced[HEADER_LEN..].copy_from_slice(&first[HEADER_LEN..]);
        assert_refused(&spliced, &site, "spliced");
    }
}
