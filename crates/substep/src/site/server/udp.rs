//! The UDP side of the `SSTP` server: one client at a time, handshakes with authentication
//! waiting in a bounded table, datagrams answered in order.
//!
//! In an authenticated session a datagram from the client's address that is not an authentic
//! session frame (its tag fails, or it is not a version 2 frame, or not a frame at all) is
//! dropped without being executed, logged, and answered with an authenticated `Dropped`
//! notice; the session goes on. A UDP source address is easily forged, so ending the session
//! here would let anyone end it with one datagram; the client stops by itself if its own
//! requests never get through (see [`super::super::protocol`]).

use super::options::*;
use super::session::*;
use crate::error::Result;
use crate::site::auth::{NONCE_LEN, SessionKeys, nonce};
use crate::site::protocol::{
    AUTH_FAILED, HEADER_LEN, Header, Hello, Message, MessageType, VERSION_AUTHENTICATED, decode_frame, open_sealed,
};
use crate::substructure::ExperimentalSubstructure;
use std::net::{SocketAddr, UdpSocket};
use std::time::Instant;

pub(super) struct UdpSession {
    pub(super) peer: SocketAddr,
    pub(super) session: Hosted,
    pub(super) last_seq: u32,
    pub(super) last_reply: Vec<u8>,
    pub(super) last_seen: Instant,
    /// The session keys of an authenticated session.
    pub(super) keys: Option<SessionKeys>,
    /// Datagrams from the client's address dropped because they failed authentication.
    pub(super) dropped: u64,
}

/// A UDP handshake waiting for the client's `Auth`.
pub(super) struct Pending {
    pub(super) peer: SocketAddr,
    pub(super) hello: Hello,
    pub(super) hello_payload: Vec<u8>,
    pub(super) site_nonce: [u8; NONCE_LEN],
    pub(super) challenge: Vec<u8>,
    pub(super) since: Instant,
}

/// Handshakes waiting for `Auth` at once (the oldest is dropped beyond that).
pub(super) const MAX_PENDING: usize = 8;

pub(super) struct UdpServer {
    pub(super) socket: UdpSocket,
    pub(super) session: Option<UdpSession>,
    /// The last reply of a session that ended (peer, sequence number, frame), re-sent when the
    /// final request is repeated.
    pub(super) closed: Option<(SocketAddr, u32, Vec<u8>)>,
    pub(super) pending: Vec<Pending>,
    pub(super) report: ServeReport,
    pub(super) tx: Vec<u8>,
}

impl UdpServer {
    pub(super) fn send(&mut self, to: SocketAddr, msg: &Message, seq: u32) {
        msg.encode(seq, &mut self.tx);
        let _ = self.socket.send_to(&self.tx, to);
    }
    pub(super) fn send_error(&mut self, to: SocketAddr, seq: u32, reason: &str) {
        self.send(
            to,
            &Message::Error {
                reason: reason.to_string(),
            },
            seq,
        );
    }
    /// An `Error` to the peer of the current session (sealed if the session is authenticated).
    pub(super) fn send_session_error(&mut self, seq: u32, reason: &str) {
        if let Some(s) = &self.session {
            Message::Error {
                reason: reason.to_string(),
            }
            .encode_session(seq, &mut self.tx, s.keys.as_ref());
            let _ = self.socket.send_to(&self.tx, s.peer);
        }
    }
    pub(super) fn refuse(&mut self, from: SocketAddr, options: &ServeOptions, refusal: Refusal) {
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

    pub(super) fn end_session(&mut self, options: &ServeOptions, why: &str) {
        if let Some(mut s) = self.session.take() {
            self.report.substeps += s.session.substeps;
            self.report.steps += s.session.steps;
            let summary = s.session.summary();
            let ramp = s.session.ramp_to_rest();
            let dropped = if s.dropped > 0 {
                format!(" ({} unauthenticated datagrams dropped)", s.dropped)
            } else {
                String::new()
            };
            options.log(&format!(
                "site: {} session ended after {summary}{dropped}: {why}{ramp}",
                s.peer
            ));
            self.closed = Some((s.peer, s.last_seq, s.last_reply));
        }
    }

    /// Handle one datagram; returns whether a session ended.
    pub(super) fn datagram(
        &mut self,
        frame: &[u8],
        from: SocketAddr,
        factory: &mut impl FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>>,
        options: &ServeOptions,
    ) -> bool {
        let in_session = self.session.as_ref().is_some_and(|s| s.peer == from);
        let authenticated_session = in_session && self.session.as_ref().is_some_and(|s| s.keys.is_some());
        if authenticated_session {
            // Only the handshake (a new one, or a repeated Auth whose Accept was lost) is
            // unsealed; everything else must be an authentic session frame.
            let handshake = Header::parse(frame)
                .is_ok_and(|h| matches!(h.kind, MessageType::Hello | MessageType::Auth) && h.seq <= 1);
            if !handshake {
                return self.sealed_datagram(frame, from, options);
            }
        }
        // With a secret, a session frame (version 2) from outside the session is still read
        // as one: a repeat of an ended session's last request gets its cached reply, others
        // "no session with this address".
        let sealed = options.secret.is_some() && frame.get(4..6) == Some(&VERSION_AUTHENTICATED.to_le_bytes()[..]);
        let header = match Header::parse_session(frame, sealed) {
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
                return self.execute(msg, header.seq, options);
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
                Ok(proof) => (p.hello, 1, Some(proof)),
                Err(r) => {
                    self.refuse(from, options, r);
                    return false;
                }
            }
        };
        if in_session {
            self.end_session(options, "client sent a new handshake");
        }
        let (mac, keys) = match mac {
            Some((mac, keys)) => (Some(mac), Some(keys)),
            None => (None, None),
        };
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
                    if keys.is_some() {
                        ", authenticated"
                    } else {
                        ", messages not authenticated: no secret"
                    }
                ));
                self.report.sessions += 1;
                self.closed = None;
                self.session = Some(UdpSession {
                    peer: from,
                    session,
                    last_seq: accept_seq,
                    last_reply,
                    last_seen: Instant::now(),
                    keys,
                    dropped: 0,
                });
            }
            Err(reason) => self.refuse(from, options, Refusal::reject(reason, accept_seq)),
        }
        false
    }

    /// Execute the decoded request `seq` of the current session and answer it (the reply is
    /// cached for a repeat of `seq`); returns whether the session ended.
    fn execute(&mut self, msg: Message, seq: u32, options: &ServeOptions) -> bool {
        let Some(s) = self.session.as_mut() else {
            return false;
        };
        let (reply, close) = match s.session.handle(msg) {
            Outcome::Reply(m) => (m, None),
            Outcome::Close(m, why) => (m, Some(why)),
        };
        reply.encode_session(seq, &mut s.last_reply, s.keys.as_ref());
        s.last_seq = seq;
        let _ = self.socket.send_to(&s.last_reply, s.peer);
        if let Some(why) = close {
            if reply.kind() == MessageType::Error {
                self.report.errors += 1;
            }
            self.end_session(options, &why);
            return true;
        }
        false
    }

    /// A datagram from the peer of an authenticated session that is not a handshake frame:
    /// executed only if its tag checks (then as in [`UdpServer::datagram`]: a repeat of the
    /// last number gets the cached reply, older numbers are ignored, a newer one than expected
    /// ends the session); otherwise dropped (see the module docs). Returns whether the
    /// session ended.
    fn sealed_datagram(&mut self, frame: &[u8], from: SocketAddr, options: &ServeOptions) -> bool {
        let Some(s) = self.session.as_mut() else {
            return false;
        };
        let Some(keys) = s.keys.as_ref() else {
            return false;
        };
        let opened = Header::parse_session(frame, true).and_then(|h| open_sealed(frame, &h, keys));
        let (header, payload) = match opened {
            Ok(x) => x,
            Err(e) => {
                s.dropped += 1;
                self.report.dropped += 1;
                // The number the datagram claims (unauthenticated): the notice is for the
                // client's request of that number, if it is waiting for one.
                let claimed = frame
                    .get(8..12)
                    .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
                let reason = format!("{e}; the datagram was dropped, not executed (the session goes on)");
                // Log the first ones, then every power of two: a flood must not flood the log.
                if s.dropped <= 10 || s.dropped.is_power_of_two() {
                    options.log(&format!(
                        "site: {from}: {reason} [{} dropped in this session]",
                        s.dropped
                    ));
                }
                Message::Dropped { reason }.encode_session(claimed, &mut self.tx, Some(keys));
                let _ = self.socket.send_to(&self.tx, from);
                return false;
            }
        };
        // Authentic: the client's.
        s.last_seen = Instant::now();
        if header.seq == s.last_seq {
            // A retry: the reply was lost. Re-send it; do not move the site again.
            let _ = self.socket.send_to(&s.last_reply, from);
            return false;
        }
        let expect = s.last_seq.wrapping_add(1);
        if header.seq != expect {
            if s.last_seq.wrapping_sub(header.seq) < (1 << 31) {
                return false; // an old duplicate (or a replay of one): nothing to do
            }
            let reason = format!(
                "{AUTH_FAILED}: {} #{} arrived where #{expect} was expected (messages out of order)",
                header.kind.name(),
                header.seq
            );
            self.send_session_error(header.seq, &reason);
            self.report.errors += 1;
            self.end_session(options, &reason);
            return true;
        }
        let limits = s.session.limits();
        match Message::decode(&header, payload, Some(&limits)) {
            Ok(msg) => self.execute(msg, header.seq, options),
            Err(e) => {
                let reason = e.to_string();
                self.send_session_error(header.seq, &reason);
                self.report.errors += 1;
                self.end_session(options, &format!("bad datagram: {reason}"));
                true
            }
        }
    }
}
