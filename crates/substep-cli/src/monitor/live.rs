//! The run loop's side of the monitor and of the stability indicator: a few calls per step
//! from `substep run` (offline) — feed the indicator, push a frame, obey the controls, pace.

use super::{Monitor, MonitorOptions};
use crate::RunArgs;
use anyhow::Result;
use serde_json::{Value, json};
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use substep::io::TestDefinition;
use substep::monitor::{StabilityAction, StabilityMonitor, StabilitySettings, StopRequest, copy_into};
use substep::run::{Layout, RunObserver, StepRow};
use substep::substructure::{SafetyLimits, SubstepObserver};

/// Ramp time used for operator and stability stops when the config sets no limits \[s\].
pub const DEFAULT_STOP_RAMP: f64 = 1.0;

/// The last command of each coupling DOF (the step's last sub-step).
#[derive(Debug, Default)]
pub struct LastCommand(pub Vec<f64>);

impl SubstepObserver for LastCommand {
    fn substep(&mut self, _step: usize, _j: usize, command: &[f64], _force: &[f64], _displacement: &[f64]) {
        self.0.copy_from_slice(command);
    }
}

/// A front end's observer with the monitor around it: every row and sub-step reach `inner`
/// unchanged; the last command, the indicator, the frames and the stop request are taken on
/// the way.
pub struct LiveObserver<'a, O> {
    pub inner: &'a mut O,
    pub live: &'a mut Live,
    pub warnings: Vec<String>,
    pub quiet: bool,
}

impl<O: SubstepObserver> SubstepObserver for LiveObserver<'_, O> {
    fn substep(&mut self, step: usize, j: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.live.last.substep(step, j, command, force, displacement);
        self.inner.substep(step, j, command, force, displacement);
    }
    fn phase_lag(&mut self, tracking_error: &[f64], correction: &[f64]) {
        self.inner.phase_lag(tracking_error, correction);
    }
    #[allow(clippy::too_many_arguments)]
    fn ramp(&mut self, step: usize, j: usize, s: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.inner.ramp(step, j, s, command, force, displacement);
    }
}

impl<O: RunObserver> RunObserver for LiveObserver<'_, O> {
    fn start(&mut self, layout: &Layout) {
        self.inner.start(layout);
    }
    fn step(&mut self, row: &StepRow<'_>) -> ControlFlow<()> {
        let quiet = self.quiet;
        let warnings = &mut self.warnings;
        self.live.tick(row, &mut |w| {
            if !quiet {
                println!("  warning: {w}");
            }
            warnings.push(w);
        });
        self.inner.step(row)
    }
    fn stop_request(&mut self) -> Option<String> {
        self.live.take_stop()
    }
}

pub struct Live {
    monitor: Option<Monitor>,
    stability: Option<StabilityMonitor>,
    action: StabilityAction,
    pub last: LastCommand,
    stop_sent: bool,
    pending: Option<String>,
    coupling: Vec<usize>,
    pub stopped_by: Option<&'static str>,
    pace: Option<(Instant, f64)>,
    max_eta: f64,
    min_margin: f64,
    linger: Duration,
    late_steps: u64,
    hold_substeps: u64,
}

impl Live {
    /// Start the monitor (`--monitor`) and the indicator (`--monitor`, or
    /// `[substructure.limits] stability`). A test without limits gets a ramp-only
    /// [`SafetyLimits`] so that a stop from the page or the indicator can ramp.
    pub fn start(args: &RunArgs, def: &mut TestDefinition, config: &str, realtime: bool) -> Result<Self> {
        let n_c = def.substructure.as_ref().map_or(0, |s| s.coupling_dofs.len());
        let from_config = def
            .substructure
            .as_ref()
            .and_then(|s| s.limits.as_ref())
            .and_then(|l| l.stability.clone());
        // The command-line action overrides the config's (keeping its thresholds).
        let configured = match (args.stability, from_config) {
            (None, c) => c,
            (Some(a), c) => Some(StabilitySettings {
                action: match a {
                    crate::StabilityArg::Warn => StabilityAction::Warn,
                    crate::StabilityArg::Stop => StabilityAction::Stop,
                },
                ..c.unwrap_or_default()
            }),
        };
        let settings = match (&configured, &args.monitor) {
            (Some(s), _) => Some(s.clone()),
            // Offline, the page shows the indicator by default; a real-time run gets it only
            // when asked for (its writer thread shares the cores with the real-time threads).
            (None, Some(_)) if n_c > 0 && !realtime => Some(StabilitySettings::default()),
            _ => None,
        };
        let wants_ramp = args.monitor.is_some() || settings.as_ref().is_some_and(|s| s.action == StabilityAction::Stop);
        if let Some(sub) = &mut def.substructure
            && wants_ramp
            && sub.limits.is_none()
        {
            sub.limits = Some(SafetyLimits {
                ramp_time: DEFAULT_STOP_RAMP,
                ..SafetyLimits::default()
            });
        }
        let stability = match (&def.substructure, settings) {
            (Some(sub), Some(s)) if sub.remote.is_none() || !realtime => {
                Some(StabilityMonitor::new(sub, &def.model, def.integrator.dt, s)?)
            }
            _ => None,
        };
        let action = stability
            .as_ref()
            .map_or(StabilityAction::Warn, |s| s.settings().action);
        let monitor = match &args.monitor {
            None => None,
            Some(addr) => {
                let addr = addr.parse().map_err(|e| {
                    substep::Error::invalid("--monitor", format!("'{addr}' is not an address host:port ({e})"))
                })?;
                let token = match &args.monitor_token {
                    Some(t) if t.len() >= 8 => t.clone(),
                    Some(_) => {
                        return Err(substep::Error::invalid("--monitor-token", "must be at least 8 characters").into());
                    }
                    None => substep::monitor::new_token()?,
                };
                let limits = def.substructure.as_ref().and_then(|s| s.limits.as_ref()).map(|l| {
                    let mut parts = Vec::new();
                    if let Some(d) = &l.displacement {
                        parts.push(format!("displacement {d:?} m"));
                    }
                    if let Some(v) = &l.velocity {
                        parts.push(format!("velocity {v:?} m/s"));
                    }
                    if let Some(f) = &l.force {
                        parts.push(format!("force {f:?} N"));
                    }
                    parts.push(format!("ramp {} s", l.ramp_time));
                    parts.join(", ")
                });
                let st = stability.as_ref().map(|s| s.settings().clone());
                let info = json!({
                    "config": config, "dt": def.integrator.dt, "steps": def.integrator.steps, "n_c": n_c,
                    "realtime": realtime, "limits": limits,
                    "energy_threshold": st.as_ref().map(|s| s.energy_threshold),
                    "margin_threshold": st.as_ref().map(|s| s.margin_threshold),
                    "action": st.as_ref().map(|s| s.action.name()),
                });
                let m = Monitor::start(MonitorOptions {
                    addr,
                    public: args.monitor_public,
                    token: token.clone(),
                    window: 10.0,
                    hold_allowed: !realtime,
                    info,
                })?;
                // The operator needs both at start; printed even with --quiet.
                println!("monitor: {} (controls need the token {token})", m.url);
                use std::io::Write;
                let _ = std::io::stdout().flush();
                Some(m)
            }
        };
        let pace = args.pace.map(|p| (Instant::now(), p));
        Ok(Self {
            monitor,
            stability,
            action,
            last: LastCommand(vec![0.0; n_c]),
            stop_sent: false,
            pending: None,
            coupling: def
                .substructure
                .as_ref()
                .map_or_else(Vec::new, |s| s.coupling_dofs.clone()),
            stopped_by: None,
            pace,
            max_eta: f64::NAN,
            min_margin: f64::NAN,
            linger: Duration::from_secs_f64(args.monitor_linger.max(0.0)),
            late_steps: 0,
            hold_substeps: 0,
        })
    }

    /// The row of step `row.step` (the run API's [`StepRow`]): feed the indicator, push a
    /// frame, then obey the controls and the pace. A stop to ask for is kept for
    /// [`RunObserver::stop_request`]; warnings go to `warn`.
    pub fn tick(&mut self, row: &StepRow<'_>, warn: &mut dyn FnMut(String)) {
        let i = row.step;
        let mut alarm = None;
        if let (Some(st), Some(rec)) = (&mut self.stability, &row.coupling) {
            alarm = st.push(
                i,
                row.u,
                row.v,
                0.0,
                rec.coupling_force,
                &self.last.0,
                rec.measured_displacement,
            );
            self.max_eta = nan_max(self.max_eta, st.eta());
            self.min_margin = -nan_max(-self.min_margin, -st.margin());
        }
        if let Some(a) = alarm {
            let msg = a.message();
            if let Some(m) = &self.monitor {
                m.warn(&msg);
            }
            warn(msg.clone());
            if self.action == StabilityAction::Stop && !self.stop_sent {
                self.stopped_by = Some("stability");
                self.stop_sent = true;
                self.pending = Some(format!("stability stop: {msg}"));
            }
        }
        let t = row.t;
        if let Some(m) = &mut self.monitor {
            if let Some(rec) = &row.coupling {
                let st = &self.stability;
                let last = &self.last.0;
                let coupling = &self.coupling;
                m.push(|f| {
                    f.step = i as u64;
                    f.time = t;
                    f.n_c = coupling.len().min(substep::monitor::FRAME_DOFS);
                    copy_into(&mut f.command, last);
                    copy_into(&mut f.measured, rec.measured_displacement);
                    copy_into(&mut f.force, rec.coupling_force);
                    copy_into(&mut f.error_force, rec.error_force);
                    for (k, &c) in coupling.iter().take(substep::monitor::FRAME_DOFS).enumerate() {
                        f.test_u[k] = row.u[c];
                        f.reference_u[k] = row.reference.map_or(f64::NAN, |r| r[c]);
                    }
                    if let Some(st) = st {
                        f.set_indicator(st);
                    }
                });
            }
            self.page_stop();
        }
        // Hold between steps until resumed or stopped.
        let mut held = false;
        while let Some(m) = &self.monitor
            && m.controls.held()
            && m.controls.stop_requested().is_none()
        {
            held = true;
            std::thread::sleep(Duration::from_millis(20));
        }
        // A stop pressed while held stops before the next step.
        self.page_stop();
        if held && let Some((t0, p)) = &mut self.pace {
            // Resume the pace from here, not by racing to catch up.
            *t0 = Instant::now() - Duration::from_secs_f64(t / *p);
        }
        self.pace(t);
    }

    /// A stop pressed on the page (or set by the indicator in the controls), once.
    fn page_stop(&mut self) {
        if let Some(m) = &self.monitor
            && let Some(who) = m.controls.stop_requested()
            && !self.stop_sent
        {
            self.stop_sent = true;
            self.pending = Some(match who {
                StopRequest::Operator => {
                    self.stopped_by = Some("operator");
                    "operator stop from the monitor page (token holder)".to_string()
                }
                StopRequest::Stability => {
                    self.stopped_by = Some("stability");
                    "stability stop".to_string()
                }
            });
        }
    }

    /// The stop to hand to the run loop, once.
    pub fn take_stop(&mut self) -> Option<String> {
        self.pending.take()
    }

    fn pace(&self, t: f64) {
        if let Some((t0, p)) = self.pace
            && p > 0.0
        {
            let due = t0 + Duration::from_secs_f64(t / p);
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
        }
    }

    /// A real-time run's step record (on the writer thread, never the real-time one): feed the
    /// indicator and push a frame. Returns the alarm message if this record raised it. A stop
    /// (page, or the indicator with `stability = "stop"`) is kept for [`take_stop`](Self::take_stop),
    /// which the caller hands to the runner's stop handle.
    pub fn record_realtime(
        &mut self,
        r: &substep::realtime::StepRecordOwned,
        ag: f64,
        coupling: &[usize],
    ) -> Option<String> {
        let mut msg = None;
        if let Some(st) = &mut self.stability
            && r.u.len() == r.v.len()
        {
            if let Some(a) = st.push(
                r.step,
                &r.u,
                &r.v,
                ag,
                &r.coupling_force,
                &r.command,
                &r.measured_displacement,
            ) {
                let m = a.message();
                if self.action == StabilityAction::Stop && !self.stop_sent {
                    self.stopped_by = Some("stability");
                    self.stop_sent = true;
                    self.pending = Some(format!("stability stop: {m}"));
                }
                msg = Some(m);
            }
            self.max_eta = nan_max(self.max_eta, st.eta());
            self.min_margin = -nan_max(-self.min_margin, -st.margin());
        }
        if r.holds > 0 {
            self.late_steps += 1;
            self.hold_substeps += r.holds as u64;
        }
        if let Some(m) = &mut self.monitor {
            if let Some(w) = &msg {
                m.warn(w);
            }
            let (st, late, holds) = (&self.stability, self.late_steps, self.hold_substeps);
            m.push(|f| {
                f.step = r.step as u64;
                f.time = r.time;
                f.n_c = coupling.len().min(substep::monitor::FRAME_DOFS);
                copy_into(&mut f.command, &r.command);
                copy_into(&mut f.measured, &r.measured_displacement);
                copy_into(&mut f.force, &r.coupling_force);
                copy_into(&mut f.error_force, &r.error_force);
                for (k, &c) in coupling.iter().take(substep::monitor::FRAME_DOFS).enumerate() {
                    f.test_u[k] = r.dofs.iter().position(|&d| d == c).map_or(f64::NAN, |i| r.u[i]);
                }
                f.late_steps = late;
                f.hold_substeps = holds;
                if let Some(st) = st {
                    f.set_indicator(st);
                }
            });
            self.page_stop();
        }
        msg
    }

    /// `summary.json`'s `stability` object.
    pub fn summary(&self) -> Option<Value> {
        let st = self.stability.as_ref()?;
        let s = st.settings();
        Some(json!({
            "action": s.action.name(),
            "energy_threshold": s.energy_threshold,
            "margin_threshold": s.margin_threshold,
            "window_s": s.window,
            "max_eta": finite(self.max_eta),
            "min_margin": finite(self.min_margin),
            "final_eta": finite(st.eta()),
            "final_margin": finite(st.margin()),
            "added_energy_j": st.energy().total_added(),
            "identified": {
                "stiffness": st.identification().stiffness().iter().map(|&v| finite(v)).collect::<Vec<_>>(),
                "damping": st.identification().damping().iter().map(|&v| finite(v)).collect::<Vec<_>>(),
                "lag_s": st.identification().lag().iter().map(|&v| finite(v)).collect::<Vec<_>>(),
            },
            "model_view": st.model_view_note().map_or(Value::from("on"), |n| Value::from(format!("off: {n}"))),
            "alarm": st.alarm().map(|a| json!({
                "view": a.view.name(), "step": a.step, "time": a.time, "value": a.value,
                "threshold": a.threshold, "message": a.message(),
            })),
        }))
    }

    /// The run ended: hand the result to the page and keep serving it for `--monitor-linger`.
    pub fn finish(self, result: Value, outputs: &[PathBuf], quiet: bool) {
        if let Some(m) = self.monitor {
            if !quiet && !self.linger.is_zero() {
                println!(
                    "monitor: the page shows the final state for {:.0} s more ({})",
                    self.linger.as_secs_f64(),
                    m.url
                );
            }
            m.finish(result, outputs, self.linger);
        }
    }
}

fn finite(x: f64) -> Value {
    if x.is_finite() { json!(x) } else { Value::Null }
}

fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() {
        b
    } else if b.is_nan() {
        a
    } else {
        a.max(b)
    }
}
