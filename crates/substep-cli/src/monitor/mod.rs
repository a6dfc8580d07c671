//! `substep run --monitor`: a small HTTP server (std only, one thread per connection, bounded
//! requests) that serves the live page (`page.html`, embedded), the frames of the run as
//! server-sent events and the operator's controls (see docs/monitor.md).
//!
//! The stepping thread only pushes [`Frame`]s into a lock-free ring ([`frame_ring`]; a full
//! ring drops the frame) and reads [`Controls`] atomics; everything else (draining the ring,
//! keeping the last window, JSON, sockets) runs on the monitor's own threads.

pub mod live;

use anyhow::{Context, Result, bail};
use serde_json::{Value, json};
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;
use substep::monitor::{Controls, Frame, StopRequest, frame_ring, token_matches};
use substep::realtime::{OwnedConsumer, OwnedProducer};

const PAGE: &str = include_str!("page.html");
/// Longest request head and body accepted (bytes).
const MAX_HEAD: usize = 8192;
const MAX_BODY: usize = 4096;
/// Connections served at once; more are answered 503 and closed.
const MAX_CONNECTIONS: usize = 16;
/// Frames kept for the page (the last window, decimated in run time).
const HISTORY_FRAMES: usize = 2000;
/// Why a real-time run has no hold (the page shows it on the disabled button; a POST gets it).
const NO_HOLD: &str = "hold is not available in real-time runs: the specimen is rate-dependent and the \
                       schedule is the test, so it cannot pause between steps (use the controlled stop)";
/// Interval of the event stream (20 Hz).
const TICK: Duration = Duration::from_millis(50);

pub struct MonitorOptions {
    pub addr: SocketAddr,
    pub public: bool,
    pub token: String,
    /// Window of the traces on the page \[s of run time\].
    pub window: f64,
    /// Whether the test can hold between steps (offline runs).
    pub hold_allowed: bool,
    pub info: Value,
}

struct State {
    history: VecDeque<(u64, Frame)>,
    seq: u64,
    last_kept: f64,
    latest: Option<Frame>,
    warnings: Vec<String>,
    finished: Option<Value>,
    outputs: Vec<PathBuf>,
}

struct Shared {
    state: Mutex<State>,
    quit: AtomicBool,
    active: AtomicUsize,
    token: String,
    window: f64,
    hold_allowed: bool,
    info: Value,
    controls: Arc<Controls>,
    dropped: std::sync::atomic::AtomicU64,
}

/// The running monitor: the producer end for the stepping loop, the controls, the threads.
pub struct Monitor {
    producer: OwnedProducer<Frame>,
    pub controls: Arc<Controls>,
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
    pub url: String,
}

impl Monitor {
    pub fn start(opts: MonitorOptions) -> Result<Self> {
        if !opts.addr.ip().is_loopback() && !opts.public {
            bail!(substep::Error::invalid(
                "--monitor",
                format!(
                    "{} is not a loopback address; listening on other interfaces needs --monitor-public (controls stay behind the token)",
                    opts.addr
                )
            ));
        }
        let listener = TcpListener::bind(opts.addr)
            .map_err(|e| substep::Error::invalid("--monitor", format!("cannot listen on {}: {e}", opts.addr)))?;
        listener.set_nonblocking(true).context("monitor socket")?;
        let addr = listener.local_addr().context("monitor socket")?;
        let (producer, consumer) = frame_ring(4096);
        let controls = Arc::new(Controls::default());
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                history: VecDeque::with_capacity(HISTORY_FRAMES),
                seq: 0,
                last_kept: f64::NEG_INFINITY,
                latest: None,
                warnings: Vec::new(),
                finished: None,
                outputs: Vec::new(),
            }),
            quit: AtomicBool::new(false),
            active: AtomicUsize::new(0),
            token: opts.token,
            window: opts.window,
            hold_allowed: opts.hold_allowed,
            info: opts.info,
            controls: controls.clone(),
            dropped: Default::default(),
        });
        let s1 = shared.clone();
        let drain = std::thread::Builder::new()
            .name("monitor-drain".into())
            .spawn(move || drain_loop(consumer, &s1))
            .context("monitor thread")?;
        let s2 = shared.clone();
        let accept = std::thread::Builder::new()
            .name("monitor-http".into())
            .spawn(move || accept_loop(listener, &s2))
            .context("monitor thread")?;
        Ok(Self {
            producer,
            controls,
            shared,
            threads: vec![drain, accept],
            url: format!("http://{addr}/"),
        })
    }

    /// Fill the next frame in place (never blocks: a full ring drops the frame).
    pub fn push(&mut self, fill: impl FnOnce(&mut Frame)) {
        self.producer.push_or_drop(fill);
    }

    /// A warning for the page (off the step path: called when a warning is raised).
    pub fn warn(&self, message: &str) {
        if let Ok(mut s) = self.shared.state.lock()
            && s.warnings.len() < 100
        {
            s.warnings.push(message.to_string());
        }
    }

    /// The run ended: the page shows `result` and links to `outputs`; the server stays up for
    /// `linger`, then stops.
    pub fn finish(mut self, result: Value, outputs: &[PathBuf], linger: Duration) {
        // Let the drain thread take the last frames and the pages receive them first.
        std::thread::sleep(TICK * 3);
        if let Ok(mut s) = self.shared.state.lock() {
            s.finished = Some(result);
            s.outputs = outputs.to_vec();
        }
        std::thread::sleep(linger);
        self.shared.quit.store(true, Ordering::Release);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

fn drain_loop(mut rx: OwnedConsumer<Frame>, shared: &Shared) {
    loop {
        let quit = shared.quit.load(Ordering::Acquire);
        if let Ok(mut s) = shared.state.lock() {
            let step_back = shared.window / (HISTORY_FRAMES as f64 / 2.0);
            while let Some(f) = rx.try_pop_with(|f| *f) {
                s.latest = Some(f);
                if f.time >= s.last_kept + step_back || f.time < s.last_kept {
                    s.seq += 1;
                    let seq = s.seq;
                    if s.history.len() == HISTORY_FRAMES {
                        s.history.pop_front();
                    }
                    s.history.push_back((seq, f));
                    s.last_kept = f.time;
                }
            }
            shared.dropped.store(rx.overflows(), Ordering::Relaxed);
        }
        if quit {
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn accept_loop(listener: TcpListener, shared: &Arc<Shared>) {
    while !shared.quit.load(Ordering::Acquire) {
        match listener.accept() {
            Ok((stream, _)) => {
                let _ = stream.set_nonblocking(false);
                if shared.active.load(Ordering::Acquire) >= MAX_CONNECTIONS {
                    let mut stream = stream;
                    let _ = respond(&mut stream, 503, "text/plain", b"too many monitor connections\n");
                    continue;
                }
                shared.active.fetch_add(1, Ordering::AcqRel);
                let s = shared.clone();
                let spawned = std::thread::Builder::new().name("monitor-conn".into()).spawn(move || {
                    let _ = serve(stream, &s);
                    s.active.fetch_sub(1, Ordering::AcqRel);
                });
                if spawned.is_err() {
                    shared.active.fetch_sub(1, Ordering::AcqRel);
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => std::thread::sleep(Duration::from_millis(20)),
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

fn respond(stream: &mut TcpStream, code: u16, kind: &str, body: &[u8]) -> std::io::Result<()> {
    let reason = match code {
        200 => "OK",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        409 => "Conflict",
        413 => "Payload Too Large",
        _ => "Service Unavailable",
    };
    write!(
        stream,
        "HTTP/1.1 {code} {reason}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    stream.write_all(body)?;
    stream.flush()
}

fn json_response(stream: &mut TcpStream, code: u16, v: &Value) -> std::io::Result<()> {
    respond(stream, code, "application/json", (v.to_string() + "\n").as_bytes())
}

struct Request {
    method: String,
    path: String,
    body: Vec<u8>,
}

/// Read one request: a head of at most [`MAX_HEAD`] bytes, a body of at most [`MAX_BODY`].
fn read_request(stream: &TcpStream) -> std::result::Result<Request, (u16, &'static str)> {
    let mut r = BufReader::new(stream.take((MAX_HEAD + MAX_BODY) as u64));
    let mut head = 0usize;
    let mut line = String::new();
    let bad = (400, "malformed request");
    r.read_line(&mut line).map_err(|_| bad)?;
    head += line.len();
    let mut parts = line.split_whitespace();
    let method = parts.next().ok_or(bad)?.to_string();
    let path = parts.next().ok_or(bad)?.to_string();
    let mut length = 0usize;
    loop {
        line.clear();
        let n = r.read_line(&mut line).map_err(|_| bad)?;
        head += n;
        if head > MAX_HEAD {
            return Err((413, "request head too long"));
        }
        if n == 0 || line == "\r\n" || line == "\n" {
            break;
        }
        if let Some((k, v)) = line.split_once(':')
            && k.trim().eq_ignore_ascii_case("content-length")
        {
            length = v.trim().parse().map_err(|_| bad)?;
        }
    }
    if length > MAX_BODY {
        return Err((413, "request body too long"));
    }
    let mut body = vec![0u8; length];
    r.read_exact(&mut body).map_err(|_| bad)?;
    Ok(Request { method, path, body })
}

fn frame_json(f: &Frame) -> Value {
    let n = f.n_c;
    let v = |a: &[f64; substep::monitor::FRAME_DOFS]| json!(a[..n].to_vec());
    json!({
        "step": f.step, "t": f.time, "cmd": v(&f.command), "meas": v(&f.measured),
        "fc": v(&f.force), "fe": v(&f.error_force), "u": v(&f.test_u), "uref": v(&f.reference_u),
        "eta": f.eta, "margin": f.margin, "k": v(&f.stiffness), "c": v(&f.damping), "lag": v(&f.lag),
        "late": f.late_steps, "holds": f.hold_substeps, "alarm": f.alarm,
    })
}

fn status_json(shared: &Shared, s: &State) -> Value {
    let c = &shared.controls;
    json!({
        "latest": s.latest.as_ref().map(frame_json),
        "warnings": s.warnings,
        "acknowledged": c.acknowledgements(),
        "held": c.held(),
        "stop": c.stop_requested().map(|r| match r { StopRequest::Operator => "operator", StopRequest::Stability => "stability" }),
        "finished": s.finished,
        "outputs": s.outputs.iter().filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned())).collect::<Vec<_>>(),
        "frames_dropped": shared.dropped.load(Ordering::Relaxed),
    })
}

fn serve(mut stream: TcpStream, shared: &Shared) -> std::io::Result<()> {
    stream.set_read_timeout(Some(Duration::from_secs(5)))?;
    stream.set_write_timeout(Some(Duration::from_secs(5)))?;
    let req = match read_request(&stream) {
        Ok(r) => r,
        Err((code, why)) => return respond(&mut stream, code, "text/plain", why.as_bytes()),
    };
    let path = req.path.split('?').next().unwrap_or("");
    match (req.method.as_str(), path) {
        ("GET", "/") | ("GET", "/index.html") => respond(&mut stream, 200, "text/html; charset=utf-8", PAGE.as_bytes()),
        ("GET", "/info") => json_response(
            &mut stream,
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
            json_response(&mut stream, 200, &v)
        }
        ("GET", "/events") => events(stream, shared),
        ("POST", "/control") => control(&mut stream, shared, &req.body),
        ("GET", p) if p.starts_with("/out/") => output_file(&mut stream, shared, &p[5..]),
        ("GET", _) => respond(&mut stream, 404, "text/plain", b"not found\n"),
        _ => respond(&mut stream, 405, "text/plain", b"method not allowed\n"),
    }
}

fn events(mut stream: TcpStream, shared: &Shared) -> std::io::Result<()> {
    stream.write_all(
        b"HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
    )?;
    let mut last = 0u64;
    let mut sent_final = false;
    while !shared.quit.load(Ordering::Acquire) {
        let msg = {
            let Ok(s) = shared.state.lock() else { break };
            let frames: Vec<Value> = s
                .history
                .iter()
                .filter(|(q, _)| *q > last)
                .map(|(_, f)| frame_json(f))
                .collect();
            if let Some((q, _)) = s.history.back() {
                last = *q;
            }
            let fin = s.finished.is_some();
            let m = json!({ "frames": frames, "status": status_json(shared, &s) });
            if fin && sent_final {
                None
            } else {
                sent_final = fin;
                Some(m)
            }
        };
        if let Some(m) = msg {
            stream.write_all(format!("data: {m}\n\n").as_bytes())?;
            stream.flush()?;
        } else {
            // Keep the connection alive while the page shows the final state.
            stream.write_all(b": idle\n\n")?;
        }
        std::thread::sleep(TICK);
    }
    Ok(())
}

fn control(stream: &mut TcpStream, shared: &Shared, body: &[u8]) -> std::io::Result<()> {
    let Ok(v) = serde_json::from_slice::<Value>(body) else {
        return json_response(
            stream,
            400,
            &json!({ "error": "body must be JSON {\"token\": ..., \"action\": ...}" }),
        );
    };
    let token = v["token"].as_str().unwrap_or("");
    if !token_matches(token, &shared.token) {
        return json_response(
            stream,
            403,
            &json!({ "error": "refused: the controls need the token printed when the run started" }),
        );
    }
    let c = &shared.controls;
    let finished = shared.state.lock().map(|s| s.finished.is_some()).unwrap_or(true);
    if finished {
        return json_response(stream, 409, &json!({ "error": "the run has already ended" }));
    }
    match v["action"].as_str().unwrap_or("") {
        "stop" => c.request_stop(StopRequest::Operator),
        "hold" if shared.hold_allowed => c.set_hold(true),
        "hold" => return json_response(stream, 409, &json!({ "error": NO_HOLD })),
        "resume" => c.set_hold(false),
        "ack" => c.acknowledge(),
        other => {
            return json_response(
                stream,
                400,
                &json!({ "error": format!("unknown action '{other}' (stop, hold, resume, ack)") }),
            );
        }
    }
    json_response(stream, 200, &json!({ "ok": true }))
}

fn output_file(stream: &mut TcpStream, shared: &Shared, name: &str) -> std::io::Result<()> {
    let path = shared.state.lock().ok().and_then(|s| {
        s.outputs
            .iter()
            .find(|p| p.file_name().is_some_and(|n| n.to_string_lossy() == name))
            .cloned()
    });
    let Some(path) = path else {
        return respond(stream, 404, "text/plain", b"no such output of this run\n");
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
    std::io::copy(&mut f, stream)?;
    stream.flush()
}
