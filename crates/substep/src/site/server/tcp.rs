//! The TCP side of the `SSTP` server: the accept loop (a second client is told `busy` at once),
//! one connection's handshake and session.

use super::options::*;
use super::session::*;
use crate::error::{Error, Result};
use crate::site::auth::{MAC_LEN, NONCE_LEN, SessionKeys, TAG_LEN, nonce};
use crate::site::protocol::{
    AUTH_FAILED, HEADER_LEN, Header, Hello, MAX_REASON, Message, MessageType, as_auth_failure, decode_frame,
    hello_payload_len, open_sealed,
};
use crate::site::transport::{LinkError, POLL, read_frame, read_full, write_all};
use crate::substructure::ExperimentalSubstructure;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

/// Busy answers in flight at once; a client beyond that is dropped unanswered.
pub(super) const MAX_BUSY_REPLIES: usize = 64;
/// How long a client arriving at a busy site waits for the slot before it is told "busy".
pub(super) const BUSY_GRACE: Duration = Duration::from_millis(100);

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
pub(super) fn accept_loop(
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
pub(super) fn tell_busy(mut stream: TcpStream) {
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
pub(super) fn discard(stream: &mut TcpStream, n: usize, deadline: Instant) {
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
/// Serve one TCP connection; returns whether a session was opened.
pub(super) fn serve_tcp_connection(
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
    // `keys`: the session's, once the handshake is complete (the handshake itself is sent
    // unsealed).
    let mut send = |stream: &mut TcpStream, msg: &Message, seq: u32, keys: Option<&SessionKeys>| {
        msg.encode_session(seq, &mut tx, keys);
        write_all(stream, &tx, io)
    };
    let handshake = handshake_tcp(&mut stream, &mut frame, options, stop).and_then(|(hello, accept_seq, proof)| {
        let session =
            Hosted::open(hello, factory, &options.limits, false).map_err(|r| Refusal::reject(r, accept_seq))?;
        Ok((session, accept_seq, proof))
    });
    let (mut session, accept_seq, proof) = match handshake {
        Ok(x) => x,
        Err(refusal) => {
            if let Some(seq) = refusal.reply {
                let _ = send(
                    &mut stream,
                    &Message::Reject {
                        reason: refusal.log.clone(),
                    },
                    seq,
                    None,
                );
            }
            options.log(&format!("site: {peer} rejected: {}", refusal.log));
            report.rejected += 1;
            return false;
        }
    };
    let (mac, keys) = match proof {
        Some((mac, keys)) => (Some(mac), Some(keys)),
        None => (None, None),
    };
    let keys = keys.as_ref();
    let accept = Message::Accept {
        n_coupling: session.hello.n_coupling,
        mac,
    };
    if let Err(e) = send(&mut stream, &accept, accept_seq, None) {
        options.log(&format!("site: {peer}: cannot send Accept: {e}"));
        report.errors += 1;
        return false;
    }
    report.sessions += 1;
    options.log(&format!(
        "site: {peer} connected ({}{})",
        session.describe(),
        if keys.is_some() {
            ", authenticated"
        } else {
            ", messages not authenticated: no secret"
        }
    ));
    let limits = session.limits();
    let max_request = limits.max_request_payload() + if keys.is_some() { TAG_LEN } else { 0 };
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
            keys.is_some(),
        ) {
            Ok(h) => h,
            Err(LinkError::Closed { got: 0 }) => break "client disconnected".to_string(),
            Err(LinkError::Stopped) => break "server stopped; connection dropped".to_string(),
            Err(LinkError::TimedOut { got: 0 }) => {
                let reason = format!(
                    "idle for more than {:.3} s",
                    options.idle_timeout.unwrap_or_default().as_secs_f64()
                );
                let _ = send(&mut stream, &Message::Error { reason: reason.clone() }, expect, keys);
                report.errors += 1;
                break reason;
            }
            Err(LinkError::Protocol(e)) => {
                // In an authenticated session a frame refused from its header (e.g. a length
                // beyond the limit) is a changed or forged one like any other.
                let e = if keys.is_some() { as_auth_failure(e) } else { e };
                let _ = send(&mut stream, &Message::Error { reason: e.to_string() }, expect, keys);
                report.errors += 1;
                if keys.is_some() {
                    break e.to_string(); // names the failed authentication
                }
                break format!("bad frame: {e}");
            }
            Err(e) => {
                report.errors += 1;
                break e.to_string();
            }
        };
        // Authenticated: the tag first (until it checks, not even the sequence number is the
        // client's); a bad one ends the session, answered with `expect` so that the client
        // waiting for that reply reads the reason.
        let (header, payload) = match keys {
            None => (header, &frame[HEADER_LEN..]),
            Some(k) => match open_sealed(&frame, &header, k) {
                Ok(x) => x,
                Err(e) => {
                    let reason = e.to_string();
                    let _ = send(&mut stream, &Message::Error { reason: reason.clone() }, expect, keys);
                    report.errors += 1;
                    break reason;
                }
            },
        };
        if header.seq != expect {
            let reason = match keys {
                None => format!(
                    "site protocol: {}: sequence number {}, expected {expect}",
                    header.kind.name(),
                    header.seq
                ),
                Some(_) => format!(
                    "{AUTH_FAILED}: {} #{} arrived where #{expect} was expected (a replayed or reordered message)",
                    header.kind.name(),
                    header.seq
                ),
            };
            let reply_seq = if keys.is_some() { expect } else { header.seq };
            let _ = send(&mut stream, &Message::Error { reason: reason.clone() }, reply_seq, keys);
            report.errors += 1;
            break reason;
        }
        let msg = match Message::decode(&header, payload, Some(&limits)) {
            Ok(m) => m,
            Err(e) => {
                let _ = send(&mut stream, &Message::Error { reason: e.to_string() }, header.seq, keys);
                report.errors += 1;
                break format!("bad frame: {e}");
            }
        };
        let (reply, close) = match session.handle(msg) {
            Outcome::Reply(m) => (m, None),
            Outcome::Close(m, why) => (m, Some(why)),
        };
        if let Err(e) = send(&mut stream, &reply, header.seq, keys) {
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
    let summary = session.summary();
    let (substeps, steps) = (session.substeps, session.steps);
    let ramp = session.ramp_to_rest();
    report.substeps += substeps;
    report.steps += steps;
    options.log(&format!("site: {peer} session ended after {summary}: {end}{ramp}"));
    true
}

/// The TCP handshake up to (not including) building the site: the Hello, checked against the
/// limits, and with a secret the challenge–response, all within `handshake_timeout`. Returns
/// the Hello, the sequence number of the `Accept`, and with a secret the site's proof and the
/// session keys.
pub(super) fn handshake_tcp(
    stream: &mut TcpStream,
    frame: &mut Vec<u8>,
    options: &ServeOptions,
    stop: Option<&AtomicBool>,
) -> std::result::Result<(Hello, u32, Option<Proof>), Refusal> {
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
        false,
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
        false,
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
    let proof = check_auth(secret, &site_nonce, &hello_payload, &header, msg)?;
    Ok((hello, 1, Some(proof)))
}
