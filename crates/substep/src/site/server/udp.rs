//! The UDP side of the `SSTP` server: one client at a time, handshakes with authentication
//! waiting in a bounded table, datagrams answered in order.

use super::*;

pub(super) struct UdpSession {
    pub(super) peer: SocketAddr,
    pub(super) session: Hosted,
    pub(super) last_seq: u32,
    pub(super) last_reply: Vec<u8>,
    pub(super) last_seen: Instant,
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
    pub(super) fn datagram(
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
