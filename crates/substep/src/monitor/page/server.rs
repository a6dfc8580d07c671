//! The monitor's HTTP server: one thread reads every connection's request non-blocking, so the
//! operator's stop cannot be locked out by clients that are slow on purpose.
//!
//! * **Requests** are read by the `monitor-http` thread from non-blocking sockets into a buffer of
//!   at most `MAX_HEAD + MAX_BODY` bytes each ([`crate::monitor::http::parse_request`] after
//!   every read). A request has [`REQUEST_DEADLINE`] from its connection to its last byte (head
//!   and body together), whatever its pace; then it is answered 408 and closed.
//! * **Admission never refuses a new connection**: at most [`MAX_PENDING`] requests are being
//!   read at once and [`MAX_PENDING_PER_ADDRESS`] per client address; a new connection beyond
//!   either evicts the oldest one being read (of that address, or overall). A control request
//!   arrives in one segment and is read within one poll interval, so 16 (or 1000) dribbling
//!   connections cannot keep `POST /control` out: they only evict each other.
//! * **Answers** to `/`, `/info`, `/state` and `POST /control` are made on the same thread (no
//!   I/O but the socket; the stop is applied before its answer is written) and written
//!   non-blocking; what the socket does not take at once is finished within
//!   [`REPLY_DEADLINE`] or dropped ([`MAX_OUTGOING`] at most).
//! * **Event streams** and **output downloads** get a thread each, at most [`MAX_STREAMS`]
//!   (and [`MAX_STREAMS_PER_ADDRESS`]) and [`MAX_DOWNLOADS`], with blocking writes that time
//!   out after [`WRITE_TIMEOUT`]: a client that stops reading is dropped once the kernel's send
//!   buffer is full and the timeout has passed. An event carries at most [`FRAMES_PER_EVENT`]
//!   frames, so a stream's own memory stays at one bounded message.
//!
//! Why not hyper/axum: the guarantees above (eviction of slow requests in favour of new ones,
//! per-address caps, the control answer never behind a stream) are not defaults there either and
//! would be written as middleware all the same, while tokio + axum add about 35 s to a clean
//! build (measured for this project, research notes), +19 % of the 3 min `cargo run --release`
//! from a clean clone. Five endpoints on loopback do not need a framework.

use super::shared::{NO_HOLD, PAGE, Shared, frame_json, status_json};
use crate::monitor::http::{MAX_BODY, MAX_HEAD, Parsed, parse_request};
use crate::monitor::{StopRequest, token_matches};
use serde_json::{Value, json};
use std::io::{Read, Write};
use std::net::{IpAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// Time a request has from its connection to its last byte.
pub const REQUEST_DEADLINE: Duration = Duration::from_secs(2);
/// Requests being read at once, overall and per client address.
pub const MAX_PENDING: usize = 64;
pub const MAX_PENDING_PER_ADDRESS: usize = 32;
/// Answers still being written by the request thread, and the time each has.
pub const MAX_OUTGOING: usize = 64;
pub const REPLY_DEADLINE: Duration = Duration::from_secs(2);
/// Event streams at once, overall and per client address; downloads of outputs at once.
pub const MAX_STREAMS: usize = 8;
pub const MAX_STREAMS_PER_ADDRESS: usize = 4;
pub const MAX_DOWNLOADS: usize = 4;
/// A stream or download write that makes no progress for this long drops the client.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(2);
/// Frames in one server-sent event (the window's history goes out in several).
pub const FRAMES_PER_EVENT: usize = 250;
/// Interval of the event stream (20 Hz).
const TICK: Duration = Duration::from_millis(50);
/// Poll interval of the request thread while requests are being read or answered, and idle.
const POLL_BUSY: Duration = Duration::from_millis(5);
const POLL_IDLE: Duration = Duration::from_millis(20);

struct Pending {
    stream: TcpStream,
    peer: IpAddr,
    since: Instant,
    buf: Vec<u8>,
}

struct Outgoing {
    stream: TcpStream,
    data: Vec<u8>,
    written: usize,
    deadline: Instant,
}

/// An owned copy of a complete request (taken off the connection's buffer).
struct Request {
    method: String,
    path: String,
    body: Vec<u8>,
}

pub(super) fn accept_loop(listener: TcpListener, shared: &Arc<Shared>) {
    let mut pending: Vec<Pending> = Vec::with_capacity(MAX_PENDING);
    let mut outgoing: Vec<Outgoing> = Vec::with_capacity(MAX_OUTGOING);
    let mut chunk = [0u8; 4096];
    while !shared.quit.load(Ordering::Acquire) {
        let mut progress = false;
        // Take every waiting connection (a full table evicts, never refuses).
        while let Ok((stream, peer)) = listener.accept() {
            progress = true;
            if stream.set_nonblocking(true).is_err() {
                continue;
            }
            let _ = stream.set_nodelay(true);
            admit(&mut pending, stream, peer.ip());
        }
        let now = Instant::now();
        let mut i = 0;
        while i < pending.len() {
            let p = &mut pending[i];
            let mut closed = false;
            loop {
                let room = MAX_HEAD + MAX_BODY + 4 - p.buf.len();
                if room == 0 {
                    break;
                }
                let want = room.min(chunk.len());
                match p.stream.read(&mut chunk[..want]) {
                    Ok(0) => {
                        closed = true;
                        break;
                    }
                    Ok(n) => {
                        progress = true;
                        p.buf.extend_from_slice(&chunk[..n]);
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(_) => break,
                }
            }
            let decision = match parse_request(&p.buf) {
                Parsed::Complete(r) => Some(Ok(Request {
                    method: r.method.to_string(),
                    path: r.path.to_string(),
                    body: r.body.to_vec(),
                })),
                Parsed::Refused(code, why) => Some(Err((code, why))),
                Parsed::Incomplete if closed => {
                    pending.swap_remove(i);
                    continue;
                }
                Parsed::Incomplete if now.duration_since(p.since) > REQUEST_DEADLINE => Some(Err((
                    408,
                    "request not complete within its deadline (2 s from the connection)",
                ))),
                Parsed::Incomplete => None,
            };
            match decision {
                None => i += 1,
                Some(outcome) => {
                    let p = pending.swap_remove(i);
                    match outcome {
                        Ok(req) => dispatch(req, p.stream, p.peer, shared, &mut outgoing),
                        Err((code, why)) => queue(
                            &mut outgoing,
                            p.stream,
                            response(code, "text/plain", format!("{why}\n").as_bytes()),
                        ),
                    }
                }
            }
        }
        let now = Instant::now();
        outgoing.retain_mut(|o| {
            loop {
                match o.stream.write(&o.data[o.written..]) {
                    Ok(0) => return false,
                    Ok(n) => {
                        o.written += n;
                        if o.written == o.data.len() {
                            return false;
                        }
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return now < o.deadline,
                    Err(_) => return false,
                }
            }
        });
        if !progress {
            let busy = !pending.is_empty() || !outgoing.is_empty();
            std::thread::sleep(if busy { POLL_BUSY } else { POLL_IDLE });
        }
    }
}

/// Add a connection to the requests being read, evicting the oldest one of its address (or the
/// oldest overall) when a cap is reached.
fn admit(pending: &mut Vec<Pending>, stream: TcpStream, peer: IpAddr) {
    let oldest = |pending: &[Pending], same: Option<IpAddr>| {
        pending
            .iter()
            .enumerate()
            .filter(|(_, p)| same.is_none_or(|ip| p.peer == ip))
            .min_by_key(|(_, p)| p.since)
            .map(|(k, _)| k)
    };
    if pending.iter().filter(|p| p.peer == peer).count() >= MAX_PENDING_PER_ADDRESS {
        if let Some(k) = oldest(pending, Some(peer)) {
            pending.swap_remove(k);
        }
    } else if pending.len() >= MAX_PENDING
        && let Some(k) = oldest(pending, None)
    {
        pending.swap_remove(k);
    }
    pending.push(Pending {
        stream,
        peer,
        since: Instant::now(),
        buf: Vec::new(),
    });
}

fn response(code: u16, kind: &str, body: &[u8]) -> Vec<u8> {
    let reason = match code {
        200 => "OK",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        409 => "Conflict",
        413 => "Payload Too Large",
        _ => "Service Unavailable",
    };
    let mut out = format!(
        "HTTP/1.1 {code} {reason}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    )
    .into_bytes();
    out.extend_from_slice(body);
    out
}

fn json_body(code: u16, v: &Value) -> Vec<u8> {
    response(code, "application/json", (v.to_string() + "\n").as_bytes())
}

/// Write an answer now as far as the socket takes it; the rest is finished by the loop.
fn queue(outgoing: &mut Vec<Outgoing>, mut stream: TcpStream, data: Vec<u8>) {
    let mut written = 0;
    while written < data.len() {
        match stream.write(&data[written..]) {
            Ok(0) => return,
            Ok(n) => written += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
            Err(_) => return,
        }
    }
    if written == data.len() {
        return;
    }
    if outgoing.len() >= MAX_OUTGOING {
        outgoing.remove(0);
    }
    outgoing.push(Outgoing {
        stream,
        data,
        written,
        deadline: Instant::now() + REPLY_DEADLINE,
    });
}

fn dispatch(req: Request, stream: TcpStream, peer: IpAddr, shared: &Arc<Shared>, outgoing: &mut Vec<Outgoing>) {
    let answer = match (req.method.as_str(), req.path.as_str()) {
        ("GET", "/") | ("GET", "/index.html") => response(200, "text/html; charset=utf-8", PAGE.as_bytes()),
        ("GET", "/info") => json_body(
            200,
            &json!({ "info": shared.info, "window": shared.window, "hold_allowed": shared.hold_allowed,
                "hold_note": (!shared.hold_allowed).then_some(NO_HOLD) }),
        ),
        ("GET", "/state") => {
            let v = shared
                .state
                .lock()
                .map(|s| status_json(shared, &s))
                .unwrap_or(Value::Null);
            json_body(200, &v)
        }
        ("POST", "/control") => {
            let (code, v) = control(shared, &req.body);
            json_body(code, &v)
        }
        ("GET", "/events") => match StreamSlot::take(shared, peer) {
            Some(slot) => {
                let s = shared.clone();
                let _ = std::thread::Builder::new()
                    .name("monitor-events".into())
                    .spawn(move || {
                        let _slot = slot;
                        let _ = events(stream, &s);
                    });
                return;
            }
            None => response(
                503,
                "text/plain",
                b"too many event streams (at most 8, 4 per address)\n",
            ),
        },
        ("GET", p) if p.starts_with("/out/") => {
            if shared.downloads.fetch_add(1, Ordering::AcqRel) >= MAX_DOWNLOADS {
                shared.downloads.fetch_sub(1, Ordering::AcqRel);
                response(503, "text/plain", b"too many downloads at once (at most 4)\n")
            } else {
                let s = shared.clone();
                let name = p[5..].to_string();
                let spawned = std::thread::Builder::new()
                    .name("monitor-download".into())
                    .spawn(move || {
                        let _ = output_file(stream, &s, &name);
                        s.downloads.fetch_sub(1, Ordering::AcqRel);
                    });
                if spawned.is_err() {
                    shared.downloads.fetch_sub(1, Ordering::AcqRel);
                }
                return;
            }
        }
        ("GET", _) => response(404, "text/plain", b"not found\n"),
        _ => response(405, "text/plain", b"method not allowed\n"),
    };
    queue(outgoing, stream, answer);
}

/// A place among the event streams, given back when the stream ends.
struct StreamSlot {
    shared: Arc<Shared>,
    peer: IpAddr,
}

impl StreamSlot {
    fn take(shared: &Arc<Shared>, peer: IpAddr) -> Option<Self> {
        let mut streams = shared.streams.lock().ok()?;
        if streams.len() >= MAX_STREAMS || streams.iter().filter(|&&p| p == peer).count() >= MAX_STREAMS_PER_ADDRESS {
            return None;
        }
        streams.push(peer);
        Some(Self {
            shared: shared.clone(),
            peer,
        })
    }
}

impl Drop for StreamSlot {
    fn drop(&mut self) {
        if let Ok(mut streams) = self.shared.streams.lock()
            && let Some(k) = streams.iter().position(|&p| p == self.peer)
        {
            streams.swap_remove(k);
        }
    }
}

fn blocking(stream: &TcpStream) -> std::io::Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_write_timeout(Some(WRITE_TIMEOUT))
}

fn events(mut stream: TcpStream, shared: &Shared) -> std::io::Result<()> {
    blocking(&stream)?;
    stream.write_all(
        b"HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
    )?;
    let mut last = 0u64;
    let mut sent_final = false;
    while !shared.quit.load(Ordering::Acquire) {
        let (msg, more) = {
            let Ok(s) = shared.state.lock() else { break };
            let mut frames = Vec::new();
            let from = last;
            for (q, f) in s.history.iter().filter(|(q, _)| *q > from).take(FRAMES_PER_EVENT) {
                frames.push(frame_json(f));
                last = *q;
            }
            let more = s.history.back().is_some_and(|(q, _)| *q > last);
            let fin = s.finished.is_some() && !more;
            let m = json!({ "frames": frames, "status": status_json(shared, &s) });
            if fin && sent_final {
                (None, false)
            } else {
                sent_final = fin;
                (Some(m.to_string()), more)
            }
        };
        match msg {
            Some(m) => {
                stream.write_all(b"data: ")?;
                stream.write_all(m.as_bytes())?;
                stream.write_all(b"\n\n")?;
            }
            // Keep the connection alive while the page shows the final state.
            None => stream.write_all(b": idle\n\n")?,
        }
        if !more {
            std::thread::sleep(TICK);
        }
    }
    Ok(())
}

/// Apply a control request; the status and the JSON answer.
fn control(shared: &Shared, body: &[u8]) -> (u16, Value) {
    let Ok(v) = serde_json::from_slice::<Value>(body) else {
        return (
            400,
            json!({ "error": "body must be JSON {\"token\": ..., \"action\": ...}" }),
        );
    };
    let token = v["token"].as_str().unwrap_or("");
    if !token_matches(token, &shared.token) {
        return (
            403,
            json!({ "error": "refused: the controls need the token printed when the run started" }),
        );
    }
    let c = &shared.controls;
    let finished = shared.state.lock().map(|s| s.finished.is_some()).unwrap_or(true);
    if finished {
        return (409, json!({ "error": "the run has already ended" }));
    }
    match v["action"].as_str().unwrap_or("") {
        "stop" => c.request_stop(StopRequest::Operator),
        "hold" if shared.hold_allowed => c.set_hold(true),
        "hold" => return (409, json!({ "error": NO_HOLD })),
        "resume" => c.set_hold(false),
        "ack" => c.acknowledge(),
        other => {
            return (
                400,
                json!({ "error": format!("unknown action '{other}' (stop, hold, resume, ack)") }),
            );
        }
    }
    (200, json!({ "ok": true }))
}

fn output_file(mut stream: TcpStream, shared: &Shared, name: &str) -> std::io::Result<()> {
    blocking(&stream)?;
    let path = shared.state.lock().ok().and_then(|s| {
        s.outputs
            .iter()
            .find(|p| p.file_name().is_some_and(|n| n.to_string_lossy() == name))
            .cloned()
    });
    let Some(path) = path else {
        return stream.write_all(&response(404, "text/plain", b"no such output of this run\n"));
    };
    let kind = match path.extension().and_then(|e| e.to_str()) {
        Some("json") => "application/json",
        Some("csv") | Some("txt") => "text/plain; charset=utf-8",
        Some("png") => "image/png",
        Some("svg") => "image/svg+xml",
        Some("pdf") => "application/pdf",
        _ => "application/octet-stream",
    };
    let mut f = std::fs::File::open(&path)?;
    let len = f.metadata()?.len();
    write!(
        stream,
        "HTTP/1.1 200 OK\r\nContent-Type: {kind}\r\nContent-Length: {len}\r\nConnection: close\r\n\r\n"
    )?;
    std::io::copy(&mut f, &mut stream)?;
    stream.flush()
}
