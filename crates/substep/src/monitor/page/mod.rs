//! The live monitor page (`substep run --monitor`, Python's `substep.run(..., monitor=ADDR)`): a small HTTP server (std only; requests read by one thread that
//! slow clients cannot stall, everything bounded: `server`) that serves the live page
//! (`page.html`, embedded), the frames of the run as server-sent events and the operator's
//! controls (see docs/monitor.md).
//!
//! The stepping thread only pushes [`Frame`]s into a lock-free ring ([`frame_ring`]; a full
//! ring drops the frame) and reads [`Controls`] atomics; everything else (draining the ring,
//! keeping the last window, JSON, sockets) runs on the monitor's own threads.

mod server;
mod shared;

use crate::monitor::{Controls, Frame, frame_ring};
use crate::realtime::{OwnedConsumer, OwnedProducer};
use crate::{Error, Result};
use serde_json::Value;
use shared::{Shared, State};
use std::collections::VecDeque;
use std::net::{SocketAddr, TcpListener};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// Frames kept for the page (the last window, decimated in run time).
const HISTORY_FRAMES: usize = 2000;
/// Interval of the event stream (20 Hz).
const TICK: Duration = Duration::from_millis(50);

pub struct MonitorOptions {
    pub addr: SocketAddr,
    pub public: bool,
    /// How messages name the address option and the one that allows a public address (the
    /// CLI's `--monitor`, `--monitor-public`; Python's keywords).
    pub option: &'static str,
    pub public_option: &'static str,
    pub token: String,
    /// Window of the traces on the page \[s of run time\].
    pub window: f64,
    /// Whether the test can hold between steps (offline runs).
    pub hold_allowed: bool,
    pub info: Value,
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
            return Err(Error::invalid(
                opts.option,
                format!(
                    "{} is not a loopback address; listening on other interfaces needs {} (controls stay behind the token)",
                    opts.addr, opts.public_option
                ),
            ));
        }
        let listener = TcpListener::bind(opts.addr)
            .map_err(|e| Error::invalid(opts.option, format!("cannot listen on {}: {e}", opts.addr)))?;
        listener
            .set_nonblocking(true)
            .map_err(|e| Error::invalid(opts.option, format!("monitor socket: {e}")))?;
        let addr = listener
            .local_addr()
            .map_err(|e| Error::invalid(opts.option, format!("monitor socket: {e}")))?;
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
            streams: Mutex::new(Vec::new()),
            downloads: AtomicUsize::new(0),
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
            .map_err(|e| Error::invalid(opts.option, format!("cannot start the monitor thread: {e}")))?;
        let s2 = shared.clone();
        let accept = std::thread::Builder::new()
            .name("monitor-http".into())
            .spawn(move || server::accept_loop(listener, &s2))
            .map_err(|e| Error::invalid(opts.option, format!("cannot start the monitor thread: {e}")))?;
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
