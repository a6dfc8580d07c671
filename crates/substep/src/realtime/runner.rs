//! [`RealtimeRunner`]: the threads, the schedule and the late-step policy (see the module docs).

use super::controllers::RealtimeController;
use super::os::{self, RtSetting};
use super::overlap::CouplingLoop;
use super::ring::{Consumer, Producer, SpscRing};
use super::stop::{PacedRamp, StopHandle};
use super::{LatePolicy, RealtimeOptions, RealtimeReport, StepRecordOwned};
use crate::error::{Error, Result};
use crate::latency::LatencyHistogram;
use crate::model::ModelRef;
use crate::substructure::{
    ExperimentalSubstructure, StepRecord, StopLog, SubstepController, SubstructureTest, stopped_at,
};
use nalgebra::DVector;
use std::fmt;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::thread::{self, Thread};
use std::time::{Duration, Instant};

/// A failed run: the error (site failure, divergence) and the report up to it. The records up
/// to the failure have been handed to the sink.
#[derive(Debug)]
pub struct RealtimeFailure {
    pub error: Error,
    pub report: RealtimeReport,
    /// Where the experimental side stopped: step (as [`Error::Stopped`] reports it) and
    /// sub-step `j` (1-based; 0 = a hold sub-step before the step's first).
    pub stopped_at: Option<(usize, usize)>,
    /// What a safety stop did (tripping sub-step and ramp), for `substeps.csv`: replay it with
    /// [`StopLog::replay`] at `stopped_at`.
    pub stop_log: Option<StopLog>,
    /// A lab target's link statistics up to the failure (the test itself is not returned).
    pub lab: Option<crate::substructure::LabStats>,
}

impl fmt::Display for RealtimeFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "real-time run stopped after {} steps: {}",
            self.report.steps, self.error
        )
    }
}

impl std::error::Error for RealtimeFailure {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&self.error)
    }
}

/// What [`RealtimeRunner::run`] returns: the report and the test, or the failure (error and
/// report).
pub type RealtimeResult<C = SubstepController> =
    std::result::Result<(RealtimeReport, SubstructureTest<C>), Box<RealtimeFailure>>;

/// Runs a [`SubstructureTest`] in real time (see the module docs of [`crate::realtime`]): the
/// sub-step algorithm's by default, or a CR / KR-α test
/// ([`crate::substructure::ExplicitController`]).
pub struct RealtimeRunner<C: RealtimeController = SubstepController> {
    test: SubstructureTest<C>,
    overlap: C::Overlap,
    mass_influence: DVector<f64>,
    ground_accel: Vec<f64>,
    options: RealtimeOptions,
    stop: StopHandle,
}

impl<C: RealtimeController> RealtimeRunner<C> {
    /// `model` is the numerical substructure the test's controller was built from (for the
    /// ground-motion load `−M ι a_g`); `ground_accel[i]` is `a_g` at `t_i = i Δt` from the
    /// test's current state on, so the run has `ground_accel.len() − 1` steps.
    pub fn new<'a>(
        model: impl Into<ModelRef<'a>>,
        test: SubstructureTest<C>,
        ground_accel: Vec<f64>,
        options: RealtimeOptions,
    ) -> Result<Self> {
        let model = model.into();
        let n = model.n_dofs();
        let mut test = test;
        test.controller.check_realtime(model)?;
        if ground_accel.len() < 2 {
            return Err(Error::invalid(
                "realtime.ground_accel",
                "needs at least two samples (one step)",
            ));
        }
        if let Some(i) = ground_accel.iter().position(|a| !a.is_finite()) {
            return Err(Error::invalid(
                "realtime.ground_accel",
                format!("sample {i} is not finite"),
            ));
        }
        if let Some(dofs) = &options.record_dofs
            && let Some(&d) = dofs.iter().find(|&&d| d >= n)
        {
            return Err(Error::invalid(
                "realtime.record_dofs",
                format!("DOF {} is out of range (the model has DOFs 1..={n})", d + 1),
            ));
        }
        if options.ring_capacity == 0 {
            return Err(Error::invalid("realtime.ring_capacity", "must be at least 1"));
        }
        for (what, priority) in [
            ("realtime.fifo_priority", options.fifo_priority),
            ("realtime.numerical_fifo_priority", options.numerical_fifo_priority),
        ] {
            if let Some(p) = priority
                && !(1..=99).contains(&p)
            {
                return Err(Error::invalid(what, format!("must be in 1..=99, got {p}")));
            }
        }
        let dt = test.controller.dt();
        if dt < 1e-6 * test.controller.substeps() as f64 {
            return Err(Error::invalid(
                "realtime",
                "the sub-step length is below 1 µs; it cannot be paced in real time",
            ));
        }
        let overlap = test.controller.overlap()?;
        Ok(Self {
            test,
            overlap,
            mass_influence: model.effective_mass_vector(),
            ground_accel,
            options,
            stop: StopHandle::new(),
        })
    }

    /// The handle that asks this run for the controlled stop from another thread (take it
    /// before [`run`](Self::run); the sink may use it too, e.g. for the stability indicator).
    pub fn stop_handle(&self) -> StopHandle {
        self.stop.clone()
    }

    /// Use `handle` (made before the runner, e.g. by the monitor) for the controlled stop.
    pub fn with_stop_handle(mut self, handle: StopHandle) -> Self {
        self.stop = handle;
        self
    }

    /// Run all steps in real time, handing step records to `sink` (on the calling thread, in
    /// step order). Returns the report and the test in its final state (the controller and the
    /// experimental side have advanced; `SubstructureTest::steps_done` and `record` are not
    /// updated by this runner). On failure the run stops, the records so far are flushed to the
    /// sink, and the error comes with the report.
    pub fn run<F>(mut self, mut sink: F) -> RealtimeResult<C>
    where
        F: FnMut(&StepRecordOwned) + Send,
    {
        let opts = &self.options;
        let ag = &self.ground_accel[..];
        let n_steps = ag.len() - 1;
        let offset = self.test.steps_done();
        let ctrl = &self.test.controller;
        let (n, n_c, k, dt) = (ctrl.state().u.len(), ctrl.n_coupling(), ctrl.substeps(), ctrl.dt());
        let dofs: Vec<usize> = opts.record_dofs.clone().unwrap_or_else(|| (0..n).collect());
        let hist = || LatencyHistogram::new(opts.histogram_bin, opts.histogram_bins);

        // Rings: records to the writer, and the two mailboxes between the loop threads.
        let mut records = SpscRing::new(opts.ring_capacity, || StepRecordOwned::with_sizes(&dofs, n_c));
        let mut to_rt = SpscRing::new(2, || PredictorMsg {
            step: 0,
            w_c: vec![0.0; n_c],
        });
        let mut to_numerical = SpscRing::new(2, || EndMsg {
            step: 0,
            before: vec![0.0; n_c],
            last: vec![0.0; n_c],
            command: vec![0.0; n_c],
            displacement: vec![0.0; n_c],
            true_before: vec![0.0; n_c],
            true_last: vec![0.0; n_c],
            true_seen: false,
            holds: 0,
        });
        // A nonlinear substructure's pipeline: f^{(k−1)} and d^{(k)} of each step, as soon as
        // sub-step k − 1 has been measured.
        let mut to_numerical_mid = SpscRing::new(2, || MidMsg {
            step: 0,
            posted: Instant::now(),
            before: vec![0.0; n_c],
            command: vec![0.0; n_c],
        });
        let nonlinear = self.test.controller.uses_pipeline();
        let (mut record_tx, mut record_rx) = records.split();
        let (w_tx, w_rx) = to_rt.split();
        let (end_tx, end_rx) = to_numerical.split();
        let (mid_tx, mid_rx) = to_numerical_mid.split();

        if opts.record_every > 0 {
            let initial = self.test.record();
            let command = self.test.controller.command().to_vec();
            let ideal = self.test.controller.ideal_error_force();
            record_tx.push_or_drop(|slot| slot.fill(&initial, &command, ideal, 0));
        }

        // Step 0's predictor the plain way; the overlap starts with step 1.
        let mut load = DVector::zeros(n);
        load.copy_from(&self.mass_influence);
        load.scale_mut(-ag[1]);
        self.test.controller.begin_step(&load);
        let overlap = self.overlap;
        let coupling = self.test.controller.coupling_loop(&overlap);
        // Where the noise-free bookkeeping stands (a run that continues a test).
        let true_last0 = self.test.controller.true_force_last().to_vec();

        let memory_lock = if opts.lock_memory {
            os::lock_memory()
        } else {
            RtSetting::NotRequested
        };
        let started = Instant::now();
        let shared = Shared::new(started);
        let t0 = started
            + opts
                .start_delay
                .unwrap_or_else(|| Duration::from_secs_f64(dt).max(Duration::from_millis(1)));
        let mut records_written = 0u64;

        let numerical = Numerical {
            controller: &mut self.test.controller,
            overlap,
            w_c: vec![0.0; n_c],
            mass_influence: &self.mass_influence,
            load,
            ag,
            n_steps,
            offset,
            before: vec![0.0; n_c],
            displacement: vec![0.0; n_c],
            command: vec![0.0; n_c],
            w_tx,
            end_rx,
            mid_rx,
            nonlinear,
            pipeline: hist(),
            record_tx,
            record_every: opts.record_every,
            delays: &opts.numerical_delay,
            fifo_priority: opts.numerical_fifo_priority,
            shared: &shared,
            hist: hist(),
        };
        let site: &mut dyn ExperimentalSubstructure = &mut *self.test.site;
        // A controlled stop ramps on the real-time thread's clock, one ramp sub-step per Δτ.
        let paced = site.pace_ramp(Some(Box::new(PacedRamp::new(opts.spin_window))));
        let stop = &self.stop;
        let (numerical_out, rt_out) = thread::scope(|s| {
            let numerical = thread::Builder::new()
                .name("substep-numerical".into())
                .spawn_scoped(s, move || numerical.run())
                .expect("spawn the numerical thread");
            let rt = RealTime {
                site,
                coupling,
                ag,
                n_steps,
                offset,
                dt,
                k,
                t0,
                w_rx,
                end_tx,
                mid_tx,
                nonlinear,
                worker: numerical.thread().clone(),
                shared: &shared,
                stop,
                opts,
                force: vec![0.0; n_c],
                displacement: vec![0.0; n_c],
                true_before: vec![0.0; n_c],
                true_last: true_last0,
                true_seen: false,
                stats: RtStats {
                    wake: hist(),
                    completion: hist(),
                    steps: 0,
                    substeps: 0,
                    holds: 0,
                    missed: 0,
                    late_steps: 0,
                    rebased: 0,
                    worst: Duration::ZERO,
                    worst_at: (0, 0),
                    fifo: RtSetting::NotRequested,
                    stopped_at: None,
                },
            };
            let rt = thread::Builder::new()
                .name("substep-realtime".into())
                .spawn_scoped(s, move || rt.run())
                .expect("spawn the real-time thread");
            // The writer: this thread.
            loop {
                let done = shared.numerical_done.load(Ordering::Acquire);
                let mut any = false;
                while record_rx.try_pop_with(|r| sink(r)).is_some() {
                    records_written += 1;
                    any = true;
                }
                if done {
                    break;
                }
                if !any {
                    thread::sleep(Duration::from_millis(2));
                }
            }
            (join(numerical.join()), join(rt.join()))
        });
        if memory_lock == RtSetting::Applied {
            os::unlock_memory();
        }
        if paced {
            // The returned test runs offline again.
            self.test.site.pace_ramp(None);
        }
        let (numerical_hist, pipeline, numerical_fifo, numerical_result) = numerical_out;
        let (stats, rt_result) = rt_out;
        let wall_time = started.elapsed();
        let report = RealtimeReport {
            dt,
            k_sub: k,
            steps: stats.steps,
            substeps: stats.substeps,
            hold_substeps: stats.holds,
            missed: stats.missed,
            late_steps: stats.late_steps,
            rebased: stats.rebased,
            latency_p50: stats.wake.percentile(0.5),
            latency_p99: stats.wake.percentile(0.99),
            latency_max: stats.wake.max(),
            latency_max_at: stats.worst_at,
            histogram: stats.wake,
            completion: stats.completion,
            numerical: numerical_hist,
            pipeline,
            records_written,
            records_dropped: records.overflows(),
            memory_lock,
            fifo: stats.fifo,
            numerical_fifo,
            wall_time,
        };
        let error = match shared.first_error.load(Ordering::Acquire) {
            FROM_RT => rt_result.err(),
            FROM_NUMERICAL => numerical_result.err(),
            _ => None,
        };
        match error {
            Some(error) => Err(Box::new(RealtimeFailure {
                error,
                report,
                stopped_at: stats.stopped_at,
                stop_log: self.test.site.take_stop_log(),
                lab: self.test.site.lab_stats().cloned(),
            })),
            None => Ok((report, self.test)),
        }
    }
}

fn join<T>(r: thread::Result<T>) -> T {
    r.unwrap_or_else(|e| std::panic::resume_unwind(e))
}

const FROM_RT: u8 = 1;
const FROM_NUMERICAL: u8 = 2;

struct Shared {
    /// A thread failed; the other stops.
    stop: AtomicBool,
    /// Which thread failed first (`FROM_*`).
    first_error: AtomicU8,
    rt_done: AtomicBool,
    numerical_done: AtomicBool,
    /// When the current step's last sub-step is due, in ns after `epoch` (set by the real-time
    /// thread at each step's start): the numerical thread of a nonlinear substructure sleeps
    /// until just before it and then polls, instead of waiting to be woken (a futex wake-up
    /// takes up to milliseconds on a busy machine; the pipeline has one sub-step).
    epoch: Instant,
    last_substep_due: AtomicU64,
}

impl Shared {
    fn new(epoch: Instant) -> Self {
        Self {
            stop: AtomicBool::new(false),
            first_error: AtomicU8::new(0),
            rt_done: AtomicBool::new(false),
            numerical_done: AtomicBool::new(false),
            epoch,
            last_substep_due: AtomicU64::new(0),
        }
    }

    fn set_last_substep_due(&self, at: Instant) {
        let ns = at.saturating_duration_since(self.epoch).as_nanos() as u64;
        self.last_substep_due.store(ns, Ordering::Release);
    }

    /// Wait for the next message of a nonlinear substructure's pipeline: sleep until `window`
    /// before the last sub-step is due, then poll; after it, poll with short parks.
    fn pace_until_last_substep(&self, window: Duration) {
        let due = self.epoch + Duration::from_nanos(self.last_substep_due.load(Ordering::Acquire));
        let now = Instant::now();
        if due > now + window {
            thread::park_timeout((due - now - window).min(Duration::from_millis(5)));
        } else if now < due + window {
            std::hint::spin_loop();
        } else {
            thread::park_timeout(Duration::from_micros(100));
        }
    }

    fn fail(&self, who: u8) {
        let _ = self
            .first_error
            .compare_exchange(0, who, Ordering::AcqRel, Ordering::Acquire);
        self.stop.store(true, Ordering::Release);
    }
}

/// Sets a flag when dropped (also while unwinding), so that no thread waits for a dead one.
struct SetOnDrop<'a>(&'a AtomicBool, Option<Thread>);

impl Drop for SetOnDrop<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
        if let Some(t) = &self.1 {
            t.unpark();
        }
    }
}

/// Numerical → real-time: coupling rows of `W` for step `step`.
struct PredictorMsg {
    step: usize,
    w_c: Vec<f64>,
}

/// How long before the last sub-step is due the numerical thread of a nonlinear substructure
/// starts polling for `f^{(k−1)}` (covers the sleep's overshoot).
const PIPELINE_POLL_WINDOW: Duration = Duration::from_micros(200);

/// Real-time → numerical (nonlinear substructure): `f^{(k−1)}` and `d^{(k)}` of step `step`,
/// posted when sub-step `k` starts.
struct MidMsg {
    step: usize,
    posted: Instant,
    before: Vec<f64>,
    command: Vec<f64>,
}

/// Real-time → numerical: the end of step `step`.
struct EndMsg {
    step: usize,
    before: Vec<f64>,
    last: Vec<f64>,
    command: Vec<f64>,
    displacement: Vec<f64>,
    /// Noise-free forces of the last two sub-steps, if the site reported them.
    true_before: Vec<f64>,
    true_last: Vec<f64>,
    true_seen: bool,
    holds: usize,
}

fn diverged(step: usize, dt: f64) -> Error {
    Error::Diverged {
        step,
        time: step as f64 * dt,
        reason: "the response is no longer finite (NaN or overflow)".into(),
    }
}

// ----------------------------------------------------------------------------------------------
// Numerical thread

struct Numerical<'a, C: RealtimeController> {
    controller: &'a mut C,
    overlap: C::Overlap,
    /// The known part of the next coupling target, posted to the real-time thread.
    w_c: Vec<f64>,
    mass_influence: &'a DVector<f64>,
    load: DVector<f64>,
    ag: &'a [f64],
    n_steps: usize,
    offset: usize,
    before: Vec<f64>,
    displacement: Vec<f64>,
    command: Vec<f64>,
    w_tx: Producer<'a, PredictorMsg>,
    end_rx: Consumer<'a, EndMsg>,
    mid_rx: Consumer<'a, MidMsg>,
    /// Hysteretic springs: the one-sub-step pipeline (docs/realtime.md).
    nonlinear: bool,
    /// From `f^{(k−1)}` posted to the next predictor's coupling rows posted (nonlinear only).
    pipeline: LatencyHistogram,
    record_tx: Producer<'a, StepRecordOwned>,
    record_every: usize,
    delays: &'a [(usize, Duration)],
    fifo_priority: Option<i32>,
    shared: &'a Shared,
    hist: LatencyHistogram,
}

impl<C: RealtimeController> Numerical<'_, C> {
    fn run(mut self) -> (LatencyHistogram, LatencyHistogram, RtSetting, Result<()>) {
        let shared = self.shared;
        let _done = SetOnDrop(&shared.numerical_done, None);
        let fifo = self.fifo_priority.map_or(RtSetting::NotRequested, os::set_fifo);
        let result = self.steps();
        if result.is_err() {
            self.shared.fail(FROM_NUMERICAL);
        }
        (self.hist, self.pipeline, fifo, result)
    }

    /// Nonlinear substructure, step `n`: once `f^{(k−1)}` and `d^{(k)}` are in, the state of the
    /// step's end, the springs at the next predictor, the next predictor's coupling rows to the
    /// real-time thread (within the last sub-step), then the rest of `W`. Returns the time it
    /// took, or `None` if the run ended.
    fn pipeline_step(&mut self, n: usize) -> Option<Duration> {
        let more = n + 1 < self.n_steps;
        let (controller, shared) = (&mut *self.controller, self.shared);
        let posted = loop {
            let finished = shared.stop.load(Ordering::Acquire) || shared.rt_done.load(Ordering::Acquire);
            let got = self.mid_rx.try_pop_with(|m| {
                debug_assert_eq!(m.step, n);
                controller.pipeline_close(&m.before, &m.command, more);
                m.posted
            });
            if let Some(p) = got {
                break p;
            }
            if finished {
                return None;
            }
            shared.pace_until_last_substep(PIPELINE_POLL_WINDOW);
        };
        let start = Instant::now();
        if more {
            let w_c = self.controller.pipeline_coupling(&mut self.overlap);
            let sent = self.w_tx.try_push_with(|msg| {
                msg.step = n + 1;
                msg.w_c.copy_from_slice(w_c);
            });
            debug_assert!(sent, "predictor mailbox full (protocol violated)");
            self.pipeline.record(posted.elapsed());
            self.controller.pipeline_subtract(&mut self.overlap);
        }
        Some(start.elapsed())
    }

    fn steps(&mut self) -> Result<()> {
        if self.n_steps > 1 {
            self.precompute_and_post(1);
        }
        for n in 0..self.n_steps {
            let mut busy = Duration::ZERO;
            if self.nonlinear {
                match self.pipeline_step(n) {
                    Some(d) => busy = d,
                    None => return Ok(()),
                }
            }
            let nonlinear = self.nonlinear;
            // Wait for the last forces of step n.
            let holds = loop {
                // Read the flags before popping: a message pushed before they were set is seen.
                let finished = self.shared.stop.load(Ordering::Acquire) || self.shared.rt_done.load(Ordering::Acquire);
                let got = self.end_rx.try_pop_with(|m| {
                    debug_assert_eq!(m.step, n);
                    self.controller.take_end(
                        &m.before,
                        &m.last,
                        &m.command,
                        m.true_seen.then_some((&m.true_before[..], &m.true_last[..])),
                    );
                    self.before.copy_from_slice(&m.before);
                    self.command.copy_from_slice(&m.command);
                    self.displacement.copy_from_slice(&m.displacement);
                    m.holds
                });
                if let Some(h) = got {
                    break h;
                }
                if finished {
                    return Ok(());
                }
                thread::park_timeout(Duration::from_millis(5));
            };
            let received = Instant::now();
            if !nonlinear {
                self.controller.finish_step();
            }
            let step = self.offset + n + 1;
            if !self.controller.state().is_finite() {
                return Err(diverged(step, self.controller.dt()));
            }
            if self.record_every > 0 && step.is_multiple_of(self.record_every) {
                let c = &*self.controller;
                let s = c.state();
                let record = StepRecord {
                    step,
                    time: step as f64 * c.dt(),
                    u: s.u.as_slice(),
                    v: s.v.as_slice(),
                    a: s.a.as_slice(),
                    coupling_force: c.coupling_force(),
                    error_force: c.error_force(),
                    compensation_force: c.compensation_force(),
                    measured_displacement: &self.displacement,
                };
                let command = &self.command;
                let ideal = c.ideal_error_force();
                self.record_tx
                    .push_or_drop(|slot| slot.fill(&record, command, ideal, holds));
            }
            if n + 1 < self.n_steps {
                // f_l at the end of the next step (the sub-step algorithm's W has it already)
                self.load.copy_from(self.mass_influence);
                self.load.scale_mut(-self.ag[n + 2]);
                self.controller.begin_next(&mut self.overlap, &self.before, &self.load);
            }
            if n + 2 < self.n_steps {
                self.precompute_and_post(n + 2);
            }
            self.hist.record(received.elapsed() + busy);
        }
        Ok(())
    }

    /// `W` of step `m` (whose predictor needs `f_l` at `t_{m+1}`), coupling rows to the
    /// real-time thread (a nonlinear substructure's go with the springs' share, in
    /// [`Numerical::pipeline_step`]). The controller is inside step `m − 1`.
    fn precompute_and_post(&mut self, m: usize) {
        if let Some(&(_, d)) = self.delays.iter().find(|(s, _)| *s == m) {
            thread::sleep(d);
        }
        self.load.copy_from(self.mass_influence);
        self.load.scale_mut(-self.ag[m + 1]);
        if !self.controller.precompute(&mut self.overlap, &self.load, &mut self.w_c) {
            return;
        }
        let w_c = &self.w_c;
        let posted = self.w_tx.try_push_with(|msg| {
            msg.step = m;
            msg.w_c.copy_from_slice(w_c);
        });
        debug_assert!(posted, "predictor mailbox full (protocol violated)");
    }
}

// ----------------------------------------------------------------------------------------------
// Real-time thread

struct RtStats {
    wake: LatencyHistogram,
    completion: LatencyHistogram,
    steps: usize,
    substeps: usize,
    holds: usize,
    missed: usize,
    late_steps: usize,
    rebased: usize,
    /// The latest wake-up of an algorithm sub-step and where it was (step, sub-step).
    worst: Duration,
    worst_at: (usize, usize),
    fifo: RtSetting,
    /// Step and sub-step where the experimental side failed or stopped.
    stopped_at: Option<(usize, usize)>,
}

struct RealTime<'a> {
    site: &'a mut dyn ExperimentalSubstructure,
    coupling: CouplingLoop,
    ag: &'a [f64],
    n_steps: usize,
    offset: usize,
    dt: f64,
    k: usize,
    /// Origin of the schedule (moves when re-based).
    t0: Instant,
    w_rx: Consumer<'a, PredictorMsg>,
    end_tx: Producer<'a, EndMsg>,
    mid_tx: Producer<'a, MidMsg>,
    /// Post `f^{(k−1)}`, `d^{(k)}` when the last sub-step starts (hysteretic springs).
    nonlinear: bool,
    worker: Thread,
    shared: &'a Shared,
    stop: &'a StopHandle,
    opts: &'a RealtimeOptions,
    force: Vec<f64>,
    displacement: Vec<f64>,
    /// Noise-free forces of the last two algorithm sub-steps (as the controller keeps them
    /// offline through `feedback_true`), for the ideal error force.
    true_before: Vec<f64>,
    true_last: Vec<f64>,
    true_seen: bool,
    stats: RtStats,
}

/// Why the sub-step loop stopped early without an error of its own.
enum Halt {
    Stopped,
    Failed(Error),
}

impl From<Error> for Halt {
    fn from(e: Error) -> Self {
        Halt::Failed(e)
    }
}

impl RealTime<'_> {
    fn run(mut self) -> (RtStats, Result<()>) {
        let shared = self.shared;
        let _done = SetOnDrop(&shared.rt_done, Some(self.worker.clone()));
        if let Some(p) = self.opts.fifo_priority {
            self.stats.fifo = os::set_fifo(p);
        }
        if self.opts.lock_memory {
            prefault_stack();
        }
        let result = match self.steps() {
            Ok(()) | Err(Halt::Stopped) => Ok(()),
            Err(Halt::Failed(e)) => {
                self.shared.fail(FROM_RT);
                self.worker.unpark();
                Err(e)
            }
        };
        (self.stats, result)
    }

    /// Offset [ns] from the step start of slot `j` (0-based) of the algorithm's sub-steps when
    /// `holds` hold slots came first: `holds Δτ + j (k − holds) Δτ / k`.
    fn slot_offset(&self, dt_ns: u128, holds: usize, j: usize) -> u64 {
        let k = self.k as u128;
        (holds as u128 * dt_ns / k + j as u128 * (k - holds as u128) * dt_ns / (k * k)) as u64
    }

    fn steps(&mut self) -> std::result::Result<(), Halt> {
        let sleeper = spin_sleep::SpinSleeper::new(self.opts.spin_window.as_nanos().min(999_999_999) as u32);
        let dt_ns = (self.dt * 1e9).round() as u128;
        let max_lag = self.opts.max_lag.unwrap_or(Duration::from_nanos(dt_ns as u64));
        let k = self.k;
        let dtau = self.dt / k as f64;
        for n in 0..self.n_steps {
            let step_start = Duration::from_nanos((n as u128 * dt_ns) as u64);
            let (ag_i, ag_next) = (self.ag[n], self.ag[n + 1]);
            // The one poll per step of an external stop (an atomic load).
            let stop = self.stop;
            if let Some(reason) = stop.requested() {
                return Err(self.external_stop(&sleeper, n, step_start, reason));
            }
            let mut holds = 0;
            if n > 0 {
                if !self.coupling.has_next() {
                    sleeper.sleep_until(self.t0 + step_start);
                    if !self.take_predictor() && self.nonlinear {
                        // The springs' share arrives one pipeline latency (tens of µs) after the
                        // last sub-step began; a real-time thread that woke late for that
                        // sub-step (catching up) gets here first. Half a sub-step of grace
                        // before the late policy, whose hold sub-step would change the test.
                        let grace = Instant::now() + Duration::from_nanos((dt_ns / (2 * k as u128)) as u64);
                        while !self.coupling.has_next() && Instant::now() < grace {
                            std::hint::spin_loop();
                            self.take_predictor();
                        }
                    }
                    if !self.coupling.has_next() {
                        self.stats.late_steps += 1;
                        holds = self.late_step(&sleeper, n, step_start, dt_ns, (ag_i, ag_i))?;
                    }
                }
                self.coupling.begin_next();
            }
            if self.nonlinear {
                let last = Duration::from_nanos(self.slot_offset(dt_ns, holds, k - 1));
                self.shared.set_last_substep_due(self.t0 + step_start + last);
            }
            let dtau_slot = if holds == 0 {
                dtau
            } else {
                (k - holds) as f64 * dtau / k as f64
            };
            for j in 1..=k {
                if self.shared.stop.load(Ordering::Acquire) {
                    return Err(Halt::Stopped);
                }
                let mut start = self.t0 + step_start + Duration::from_nanos(self.slot_offset(dt_ns, holds, j - 1));
                sleeper.sleep_until(start);
                let wake = Instant::now();
                let late = wake.saturating_duration_since(start);
                self.stats.wake.record(late);
                if late > self.stats.worst {
                    self.stats.worst = late;
                    self.stats.worst_at = (self.offset + n, j);
                }
                if late > max_lag {
                    self.t0 += late;
                    start += late;
                    self.stats.rebased += 1;
                }
                let end = self.t0 + step_start + Duration::from_nanos(self.slot_offset(dt_ns, holds, j));
                let ag = crate::substructure::substep_ground_acceleration(ag_i, ag_next, j, k);
                self.coupling.next_command();
                let command = self.coupling.command();
                if j == k && self.nonlinear {
                    let (before, posted) = (self.coupling.force_last(), Instant::now());
                    // Never full by the protocol (one message per step, read before the step's end).
                    let sent = self.mid_tx.try_push_with(|m| {
                        m.step = n;
                        m.posted = posted;
                        m.before.copy_from_slice(before);
                        m.command.copy_from_slice(command);
                    });
                    debug_assert!(sent, "pipeline mailbox full (protocol violated)");
                    self.worker.unpark();
                }
                if let Err(e) = self
                    .site
                    .substep(command, ag, dtau_slot, &mut self.force, &mut self.displacement)
                {
                    return Err(self.site_failed(n, j, e));
                }
                self.coupling.feedback(&self.force);
                match self.site.true_force() {
                    Some(f) => {
                        std::mem::swap(&mut self.true_before, &mut self.true_last);
                        self.true_last.copy_from_slice(f);
                        self.true_seen = true;
                    }
                    None => self.true_seen = false,
                }
                self.stats.substeps += 1;
                if j == k {
                    self.end_step(n, holds)?;
                }
                let done = Instant::now();
                self.stats.completion.record(done.saturating_duration_since(start));
                if done > end {
                    self.stats.missed += 1;
                }
            }
            self.stats.steps += 1;
        }
        Ok(())
    }

    /// After the last sub-step of step `n`: compensation, the forces to the numerical thread,
    /// and the next predictor if it is there.
    fn end_step(&mut self, n: usize, holds: usize) -> std::result::Result<(), Halt> {
        if self.force.iter().any(|f| !f.is_finite()) {
            return Err(diverged(self.offset + n + 1, self.dt).into());
        }
        self.coupling.end_step();
        let c = &self.coupling;
        let d = &self.displacement;
        let (tb, tl, seen) = (&self.true_before, &self.true_last, self.true_seen);
        let msg = |m: &mut EndMsg| {
            m.step = n;
            m.before.copy_from_slice(c.force_before());
            m.last.copy_from_slice(c.force_last());
            m.command.copy_from_slice(c.command());
            m.displacement.copy_from_slice(d);
            m.true_before.copy_from_slice(tb);
            m.true_last.copy_from_slice(tl);
            m.true_seen = seen;
            m.holds = holds;
        };
        // Never full by the protocol (at most two steps in flight); wait rather than lose it.
        while !self.end_tx.try_push_with(msg) {
            if self.shared.stop.load(Ordering::Acquire) {
                return Err(Halt::Stopped);
            }
            thread::sleep(Duration::from_micros(20));
        }
        self.worker.unpark();
        if n + 1 < self.n_steps {
            self.take_predictor();
        }
        Ok(())
    }

    /// The experimental side failed in sub-step `j` of step `n` (of this run): a controlled
    /// stop at the step the offline driver would report.
    fn site_failed(&mut self, n: usize, j: usize, e: Error) -> Halt {
        let step = self.offset + n + 1;
        self.stats.stopped_at = Some((step, j));
        Halt::Failed(stopped_at(step, self.dt, e))
    }

    /// The controlled stop asked for through the [`StopHandle`], before step `n` (of this run):
    /// at the step's first slot the site ramps to the safe position (paced by the
    /// [`PacedRamp`]), as the offline driver does after [`ExperimentalSubstructure::request_stop`]
    /// between two steps.
    fn external_stop(
        &mut self,
        sleeper: &spin_sleep::SpinSleeper,
        n: usize,
        step_start: Duration,
        reason: &str,
    ) -> Halt {
        sleeper.sleep_until(self.t0 + step_start);
        let step = self.offset + n + 1;
        let time = step as f64 * self.dt;
        self.stats.stopped_at = Some((step, 1));
        if !self.site.request_stop(reason) {
            return Halt::Failed(Error::Stopped {
                step,
                time,
                reason: format!("{reason} (between steps: this run has no ramp to the safe position)"),
            });
        }
        let dtau = self.dt / self.k as f64;
        let ag = self.ag[n];
        let command = self.coupling.command();
        match self
            .site
            .substep(command, (ag, ag), dtau, &mut self.force, &mut self.displacement)
        {
            Err(e) => self.site_failed(n, 1, e),
            // A side that said it would ramp but ran the sub-step: stop here all the same.
            Ok(()) => Halt::Failed(Error::Stopped {
                step,
                time,
                reason: format!("{reason} (the experimental side did not ramp to the safe position)"),
            }),
        }
    }

    /// Take the next step's `W_c` if posted.
    fn take_predictor(&mut self) -> bool {
        let c = &mut self.coupling;
        self.w_rx.try_pop_with(|m| c.take_predictor(&m.w_c)).is_some()
    }

    /// The late-step policy for the step starting at `step_start`; returns the number of hold
    /// sub-steps sent.
    fn late_step(
        &mut self,
        sleeper: &spin_sleep::SpinSleeper,
        n: usize,
        step_start: Duration,
        dt_ns: u128,
        ag_hold: (f64, f64),
    ) -> std::result::Result<usize, Halt> {
        let dtau = self.dt / self.k as f64;
        let mut holds = 0;
        if self.opts.late_policy == LatePolicy::HoldExtrapolate {
            while holds + 1 < self.k {
                if self.shared.stop.load(Ordering::Acquire) {
                    return Err(Halt::Stopped);
                }
                let start =
                    self.t0 + step_start + Duration::from_nanos((holds as u128 * dt_ns / self.k as u128) as u64);
                let end = start + Duration::from_nanos((dt_ns / self.k as u128) as u64);
                self.stats.wake.record(Instant::now().saturating_duration_since(start));
                let command = self.coupling.hold_command(holds);
                if let Err(e) = self
                    .site
                    .substep(command, ag_hold, dtau, &mut self.force, &mut self.displacement)
                {
                    return Err(self.site_failed(n, 0, e));
                }
                holds += 1;
                self.stats.holds += 1;
                let done = Instant::now();
                self.stats.completion.record(done.saturating_duration_since(start));
                if done > end {
                    self.stats.missed += 1;
                }
                sleeper.sleep_until(end);
                if self.take_predictor() {
                    return Ok(holds);
                }
            }
        }
        // Wait for the predictor, then re-base so that the step starts now.
        while !self.take_predictor() {
            if self.shared.stop.load(Ordering::Acquire) {
                return Err(Halt::Stopped);
            }
            thread::sleep(Duration::from_micros(20));
        }
        let due = self.t0 + step_start + Duration::from_nanos(self.slot_offset(dt_ns, holds, 0));
        let now = Instant::now();
        if now > due {
            self.t0 += now - due;
        }
        self.stats.rebased += 1;
        Ok(holds)
    }
}

/// Touch some stack so that its pages are resident (and locked) before the loop.
fn prefault_stack() {
    let mut buf = [0u8; 64 * 1024];
    std::hint::black_box(&mut buf);
}
