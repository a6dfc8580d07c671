//! The run loop's side of the monitor and of the stability indicator: a few calls per step
//! from `substep run` (offline) — read the indicator of the run (`crate::run` computes it),
//! push a frame, obey the controls, pace. Real-time runs feed their own indicator here, from
//! the writer thread.

use crate::Result;
use crate::io::TestDefinition;
use crate::monitor::page::{Monitor, MonitorOptions};
use crate::monitor::{StabilityAction, StabilityMonitor, StabilitySettings, StopRequest, copy_into};
use crate::run::{Layout, RunObserver, StepRow};
use crate::substructure::{SafetyLimits, SubstepObserver};
use serde_json::{Value, json};
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Ramp time used for operator and stability stops when the config sets no limits \[s\].
pub const DEFAULT_STOP_RAMP: f64 = 1.0;
/// Address of the page when neither `--monitor ADDR` nor `[monitor] address` gives one.
pub const DEFAULT_ADDRESS: &str = "127.0.0.1:8080";

/// `--stability`: the indicator's action whatever the config says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StabilityChoice {
    Warn,
    Stop,
    Off,
}

/// A front end's choices for the monitor and the indicator (the CLI's `--monitor`,
/// `--monitor-public`, `--monitor-token`, `--monitor-linger`, `--stability`, `--pace`).
#[derive(Debug, Clone, PartialEq)]
pub struct LiveOptions {
    /// Serve the live page at this address (`""`: `[monitor] address`, else
    /// [`DEFAULT_ADDRESS`]); `None`: no page.
    pub monitor: Option<String>,
    /// Allow an address that is not loopback (the controls still need the token).
    pub monitor_public: bool,
    /// The controls' token (default: `[monitor] token`, else a random one, printed at start).
    pub monitor_token: Option<String>,
    /// Seconds the page keeps showing the final state after the run.
    pub monitor_linger: f64,
    /// Overrides `[substructure.limits] stability` (`None`: the config's; offline the indicator
    /// runs by default).
    pub stability: Option<StabilityChoice>,
    /// Pace an offline run at this multiple of real time (for watching it).
    pub pace: Option<f64>,
    /// Name the options in messages as Python's keywords (`monitor_token`) instead of the
    /// CLI's flags (`--monitor-token`).
    pub keyword_names: bool,
}

impl LiveOptions {
    fn name(&self, flag: &'static str, keyword: &'static str) -> &'static str {
        if self.keyword_names { keyword } else { flag }
    }
}

impl Default for LiveOptions {
    fn default() -> Self {
        Self {
            monitor: None,
            monitor_public: false,
            monitor_token: None,
            monitor_linger: 30.0,
            stability: None,
            pace: None,
            keyword_names: false,
        }
    }
}

/// The last command of each coupling DOF (the step's last sub-step).
#[derive(Debug, Default)]
pub struct LastCommand(pub Vec<f64>);

impl SubstepObserver for LastCommand {
    fn substep(&mut self, _step: usize, _j: usize, command: &[f64], _force: &[f64], _displacement: &[f64]) {
        self.0.copy_from_slice(command);
    }
}

/// A front end's observer with the monitor around it: every row and sub-step reach `inner`
/// unchanged; the last command, the indicator's alarm, the frames and the operator's stop are
/// taken on the way.
pub struct LiveObserver<'a, O> {
    pub inner: &'a mut O,
    pub live: &'a mut Live,
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
    fn lab(&mut self, held: bool, strays: u64) {
        self.inner.lab(held, strays);
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
        // The run's summary gets the alarm (the library raises it); here it is shown at once.
        let quiet = self.quiet;
        self.live.tick(row, &mut |w| {
            if !quiet {
                println!("  warning: {w}");
            }
        });
        self.inner.step(row)
    }
    fn stop_request(&mut self) -> Option<String> {
        self.live.take_stop()
    }
}

pub struct Live {
    monitor: Option<Monitor>,
    /// The indicator's settings for the run (`--stability`, `--monitor` or the config); an
    /// offline run hands them to [`crate::run::Run::set_stability`].
    pub stability_settings: Option<StabilitySettings>,
    /// Real-time runs: the indicator fed from the writer thread.
    stability: Option<StabilityMonitor>,
    pub last: LastCommand,
    stop_sent: bool,
    pending: Option<String>,
    coupling: Vec<usize>,
    pub stopped_by: Option<&'static str>,
    pace: Option<(Instant, f64)>,
    /// Offline: the run's alarm has been shown.
    alarm_shown: bool,
    linger: Duration,
    late_steps: u64,
    hold_substeps: u64,
}

impl Live {
    /// Start the monitor (`--monitor`) and the indicator (`--monitor`, or
    /// `[substructure.limits] stability`). A test without limits gets a ramp-only
    /// [`SafetyLimits`] so that a stop from the page or the indicator can ramp.
    pub fn start(args: &LiveOptions, def: &mut TestDefinition, config: &str, realtime: bool) -> Result<Self> {
        let n_c = def.substructure.as_ref().map_or(0, |s| s.coupling_dofs.len());
        // Offline the indicator runs by default (`SubstructureDefinition::stability_settings`); a
        // real-time run gets it only when asked for (its writer thread shares the cores with
        // the real-time threads).
        let from_config = def.substructure.as_ref().and_then(|s| {
            if realtime {
                s.limits.as_ref().and_then(|l| l.stability.clone())
            } else {
                s.stability_settings()
            }
        });
        // The command-line action overrides the config's (keeping its thresholds).
        let off = args.stability == Some(StabilityChoice::Off);
        let configured = match (args.stability, from_config) {
            (None, c) => c,
            (Some(StabilityChoice::Off), _) => None,
            (Some(a), c) => Some(StabilitySettings {
                action: match a {
                    StabilityChoice::Stop => StabilityAction::Stop,
                    _ => StabilityAction::Warn,
                },
                ..c.unwrap_or_default()
            }),
        };
        let settings = match (&configured, &args.monitor) {
            _ if off => None,
            (Some(s), _) => Some(s.clone()),
            // Offline, the page shows the indicator by default; a real-time run gets it only
            // when asked for (its writer thread shares the cores with the real-time threads).
            (None, Some(_)) if n_c > 0 && !realtime => Some(StabilitySettings::default()),
            _ => None,
        };
        // A real-time run always can ramp down: a response that runs away stops with the ramp.
        let wants_ramp =
            realtime || args.monitor.is_some() || settings.as_ref().is_some_and(|s| s.action == StabilityAction::Stop);
        if let Some(sub) = &mut def.substructure
            && wants_ramp
            && sub.limits.is_none()
        {
            sub.limits = Some(SafetyLimits {
                ramp_time: DEFAULT_STOP_RAMP,
                ..SafetyLimits::default()
            });
        }
        let settings = settings.filter(|_| {
            def.substructure
                .as_ref()
                .is_some_and(|s| s.remote.is_none() || !realtime)
        });
        let stability = match (&def.substructure, &settings) {
            (Some(sub), Some(s)) if realtime => {
                Some(StabilityMonitor::new(sub, &def.model, def.integrator.dt, s.clone())?)
            }
            (Some(sub), Some(s)) => {
                // Validated here, before the monitor starts; the run builds its own.
                StabilityMonitor::new(sub, &def.model, def.integrator.dt, s.clone())?;
                None
            }
            _ => None,
        };
        let monitor = match &args.monitor {
            None => None,
            Some(addr) => {
                let (addr, what) = match (addr.as_str(), &def.monitor.address) {
                    ("", Some(a)) => (a.as_str(), "monitor.address"),
                    ("", None) => (DEFAULT_ADDRESS, args.name("--monitor", "monitor")),
                    (a, _) => (a, args.name("--monitor", "monitor")),
                };
                let addr = addr
                    .parse()
                    .map_err(|e| crate::Error::invalid(what, format!("'{addr}' is not an address host:port ({e})")))?;
                // The command line's token overrides the config's; without either a random one.
                let (token, shown) = match (&args.monitor_token, &def.monitor.token) {
                    (Some(t), _) => {
                        let option = args.name("--monitor-token", "monitor_token");
                        crate::io::check_token(option, t)?;
                        (t.clone(), format!("the token given with {option}"))
                    }
                    (None, Some(t)) => (t.clone(), format!("the token of [monitor] token in {config}")),
                    (None, None) => {
                        let t = crate::monitor::new_token()?;
                        (t.clone(), format!("the token {t}"))
                    }
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
                let st = settings.as_ref();
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
                    option: args.name("--monitor", "monitor"),
                    public_option: args.name("--monitor-public", "monitor_public=True"),
                    token: token.clone(),
                    window: 10.0,
                    hold_allowed: !realtime,
                    info,
                })?;
                // The operator needs both at start; printed even with --quiet.
                println!("monitor: {} (controls need {shown})", m.url);
                use std::io::Write;
                let _ = std::io::stdout().flush();
                Some(m)
            }
        };
        let pace = args.pace.map(|p| (Instant::now(), p));
        Ok(Self {
            monitor,
            stability_settings: settings,
            stability,
            last: LastCommand(vec![0.0; n_c]),
            stop_sent: false,
            pending: None,
            coupling: def
                .substructure
                .as_ref()
                .map_or_else(Vec::new, |s| s.coupling_dofs.clone()),
            stopped_by: None,
            pace,
            alarm_shown: false,
            linger: Duration::from_secs_f64(args.monitor_linger.max(0.0)),
            late_steps: 0,
            hold_substeps: 0,
        })
    }

    /// The row of step `row.step` (the run API's [`StepRow`]): show a new alarm of the run's
    /// indicator, push a frame, then obey the controls and the pace. An operator's stop is kept
    /// for [`RunObserver::stop_request`]; the alarm's message goes to `warn`.
    pub fn tick(&mut self, row: &StepRow<'_>, warn: &mut dyn FnMut(String)) {
        let i = row.step;
        if let Some(a) = row.indicator.and_then(|st| st.alarm())
            && !self.alarm_shown
        {
            self.alarm_shown = true;
            let msg = a.message();
            if let Some(m) = &self.monitor {
                m.warn(&msg);
            }
            warn(msg);
            if row
                .indicator
                .is_some_and(|st| st.settings().action == StabilityAction::Stop)
            {
                // The run stops itself (the library's indicator); the page's stop is moot.
                self.stop_sent = true;
                self.stopped_by = Some("stability");
            }
        }
        let t = row.t;
        if let Some(m) = &mut self.monitor {
            if let Some(rec) = &row.coupling {
                let st = row.indicator;
                let last = &self.last.0;
                let coupling = &self.coupling;
                m.push(|f| {
                    f.step = i as u64;
                    f.time = t;
                    f.n_c = coupling.len().min(crate::monitor::FRAME_DOFS);
                    copy_into(&mut f.command, last);
                    copy_into(&mut f.measured, rec.measured_displacement);
                    copy_into(&mut f.force, rec.coupling_force);
                    copy_into(&mut f.error_force, rec.error_force);
                    for (k, &c) in coupling.iter().take(crate::monitor::FRAME_DOFS).enumerate() {
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
        r: &crate::realtime::StepRecordOwned,
        ag: f64,
        coupling: &[usize],
    ) -> Option<String> {
        let mut msg = None;
        if let Some(st) = &mut self.stability
            && r.u.len() == r.v.len()
            && let Some(a) = st.push(
                r.step,
                &r.u,
                &r.v,
                ag,
                &r.coupling_force,
                &r.command,
                &r.measured_displacement,
            )
        {
            let m = a.message();
            if st.settings().action == StabilityAction::Stop && !self.stop_sent {
                self.stopped_by = Some("stability");
                self.stop_sent = true;
                self.pending = Some(format!("stability stop: {m}"));
            }
            msg = Some(m);
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
                f.n_c = coupling.len().min(crate::monitor::FRAME_DOFS);
                copy_into(&mut f.command, &r.command);
                copy_into(&mut f.measured, &r.measured_displacement);
                copy_into(&mut f.force, &r.coupling_force);
                copy_into(&mut f.error_force, &r.error_force);
                for (k, &c) in coupling.iter().take(crate::monitor::FRAME_DOFS).enumerate() {
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

    /// The stability indicator of the run, when it runs (a real-time run's `history.csv` ends
    /// with its columns, as an offline run's).
    pub fn indicator(&self) -> Option<&StabilityMonitor> {
        self.stability.as_ref()
    }

    /// `summary.json`'s `stability` object of a real-time run (offline runs: the library's
    /// summary has it).
    pub fn summary(&self) -> Option<Value> {
        self.stability
            .as_ref()
            .and_then(|st| serde_json::to_value(st.summary()).ok())
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
