//! What the page's threads share: the run's recent frames, warnings and final state behind one
//! mutex (never taken by the stepping thread), the controls, and the JSON the page reads.

use crate::monitor::{Controls, Frame, StopRequest};
use serde_json::{Value, json};
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

pub(super) const PAGE: &str = include_str!("page.html");
/// Why a real-time run has no hold (the page shows it on the disabled button; a POST gets it).
pub(super) const NO_HOLD: &str = "hold is not available in real-time runs: the specimen is rate-dependent and the \
                       schedule is the test, so it cannot pause between steps (use the controlled stop)";
pub(super) struct State {
    pub(super) history: VecDeque<(u64, Frame)>,
    pub(super) seq: u64,
    pub(super) last_kept: f64,
    pub(super) latest: Option<Frame>,
    pub(super) warnings: Vec<String>,
    pub(super) finished: Option<Value>,
    pub(super) outputs: Vec<PathBuf>,
}

pub(super) struct Shared {
    pub(super) state: Mutex<State>,
    pub(super) quit: AtomicBool,
    /// Client addresses of the event streams being served.
    pub(super) streams: Mutex<Vec<std::net::IpAddr>>,
    /// Output downloads being served.
    pub(super) downloads: AtomicUsize,
    pub(super) token: String,
    pub(super) window: f64,
    pub(super) hold_allowed: bool,
    pub(super) info: Value,
    pub(super) controls: Arc<Controls>,
    pub(super) dropped: std::sync::atomic::AtomicU64,
}

pub(super) fn frame_json(f: &Frame) -> Value {
    let n = f.n_c;
    let v = |a: &[f64; crate::monitor::FRAME_DOFS]| json!(a[..n].to_vec());
    json!({
        "step": f.step, "t": f.time, "cmd": v(&f.command), "meas": v(&f.measured),
        "fc": v(&f.force), "fe": v(&f.error_force), "u": v(&f.test_u), "uref": v(&f.reference_u),
        "eta": f.eta, "margin": f.margin, "k": v(&f.stiffness), "c": v(&f.damping), "lag": v(&f.lag),
        "late": f.late_steps, "holds": f.hold_substeps, "alarm": f.alarm,
    })
}

pub(super) fn status_json(shared: &Shared, s: &State) -> Value {
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
