//! The real-time runner: the sub-step loop paced by a monotonic clock, with the numerical step
//! work of the next step overlapped with the sub-steps of the current one, as on a PC +
//! real-time-controller pair.
//!
//! # Threads
//!
//! * **Real-time thread** (optionally SCHED_FIFO): runs the sub-steps. Sub-step `j` of step `n`
//!   is due at the absolute deadline `t0 + n Δt + (j−1) Δτ`, `Δτ = Δt/k_sub` (integer
//!   nanoseconds, no drift); the thread sleeps until then with `spin_sleep` (native sleep, then
//!   a short spin of [`RealtimeOptions::spin_window`]; never a 100 % spin, which SCHED_FIFO
//!   throttling punishes), computes the command `d^{(j)}`, calls
//!   [`ExperimentalSubstructure::substep`] and takes the measured force. It only does
//!   coupling-sized work (`n_c`-vectors and `n_c × n_c` matrices); it does not allocate, lock or
//!   do I/O.
//! * **Numerical thread**: owns the [`SubstepController`] with all n-sized state. During the
//!   sub-steps of step `i → i+1` it computes the expensive part of the next predictor (below);
//!   when the real-time thread posts the step's last two forces it closes the step
//!   (`finish_step`, the unchanged offline code) and assembles the next predictor.
//! * **Writer** (the thread that called [`RealtimeRunner::run`]): drains step records from a
//!   lock-free SPSC ring ([`SpscRing`]) and hands them to the caller's sink (e.g. a CSV writer).
//!   A full ring drops the record and counts it ([`RealtimeReport::records_dropped`]).
//!
//! The two loop threads talk through two more SPSC rings of capacity 2 (the protocol never
//! has more than two messages in flight): numerical → real-time: the coupling rows of `W`
//! (below); real-time → numerical: `f^{(k−1)}`, `f^{(k)}`, `d^{(k)}` and the measured
//! displacement at the end of each step. The real-time thread never waits for the numerical
//! one except under [`LatePolicy::Wait`].
//!
//! # Overlap
//!
//! With `G = K̂⁻¹ Sᵀ` (n × n_c), the step closes with `u_{i+1} = x̂_{i+1} + G f^{(k−1)}` and
//! Newmark's `a_{i+1} = a0 (u_{i+1} − u_i) − a2 v_i − a3 a_i`, `v_{i+1} = v_i + a6 a_i + a7
//! a_{i+1}`. Write `ū = x̂_{i+1}`, `ā`, `v̄` for these kinematics with `f^{(k−1)} = 0`; then
//! `u_{i+1} = ū + g`, `a_{i+1} = ā + a0 g`, `v_{i+1} = v̄ + a7 a0 g` with `g = G f^{(k−1)}`, and
//! the next predictor `x̂_{i+2} = K̂⁻¹ (F̂_{i+1} + f_l,i+2 + Sᵀ f_u,i+1)` splits into
//!
//! ```text
//! x̂_{i+2} = W + H f^{(k−1)} + G f_u,i+1
//! W = K̂⁻¹ (F̂(ū, v̄, ā) + f_l,i+2)                 n×n work, known when step i+1 begins
//! H = K̂⁻¹ (α M + β′ C) G,  α = a0 (1 + a2 a7 + a3),  β′ = a1 + a0 (a4 a7 + a5)   (once)
//! ```
//!
//! `f_u,i+1` is whatever the compensator makes of the error force `f^{(k)} − f^{(k−1)}` (any
//! compensator, linear or not: it only enters through `G f_u`). So between the last sub-step of
//! a step and the first of the next, the real-time thread needs only
//! `x̂_c = W_c + H_cc f^{(k−1)} + G_cc f_u` (n_c × n_c work); the numerical thread computes `W`
//! for the following step during the `k` sub-steps (a whole `Δt`). The state update itself is
//! the controller's own `finish_step`, and the commands repeat `next_command` operation for
//! operation, so the run equals the offline [`SubstructureTest`] run up to the round-off of the
//! split predictor (about `1e-15` relative per step; the tests require `1e-12` over the run; on
//! stiff models the Newmark acceleration amplifies round-off in `u` by `a0 = 4/Δt²`, see
//! `docs/realtime.md`).
//!
//! # Nonlinear numerical substructures: the one-sub-step pipeline
//!
//! Hysteretic springs add `−K̂⁻¹ d(ũ_{i+2})` to the next predictor, with `ũ_{i+2}` the Newmark
//! displacement predictor of the step's end state, which depends on `f^{(k−1)}`. The
//! real-time thread posts `f^{(k−1)}` and `d^{(k)}` when the last sub-step begins; the numerical
//! thread closes the step's kinematics, evaluates the springs and posts `W_c − G_{:,c}ᵀ d`
//! within that sub-step; `f^{(k)}` then closes the step's forces as offline. The numbers are
//! the offline algorithm's (docs/realtime.md, docs/theory.md §14.4). [`budget::probe`] measures
//! before a test whether the step and the springs fit their budgets.
//!
//! # Deadlines and the late-step policy
//!
//! Every sub-step slot records its wake-up lateness (actual wake-up − deadline) and its
//! completion time (end of the work − deadline) in allocation-free histograms; a slot whose
//! work ends after the next slot's deadline is a **missed deadline**. A real-time thread that
//! falls behind (slow experimental side) keeps the absolute schedule and starts the overdue
//! sub-steps at once (catch-up; the algorithm is unchanged, so results still equal the offline
//! run); if it is more than [`RealtimeOptions::max_lag`] behind, the schedule is re-based to the
//! current time (counted in [`RealtimeReport::rebased`]).
//!
//! If the next step's predictor is not ready when its first sub-step is due (numerical thread
//! late; counted in [`RealtimeReport::late_steps`]), [`LatePolicy::HoldExtrapolate`] (default)
//! does what lab controllers do: it sends one **hold sub-step** of the normal length `Δτ` whose
//! command extrapolates the previous ramp by one sub-step, `d^{(k)} + (x̂_c − x̂_c^{prev})/k`
//! (later hold sub-steps repeat that command), with the ground acceleration held at
//! `a_g(t_{i+1})`; its measured force is discarded (the algorithm state is unchanged). When the
//! predictor has arrived after `h` hold sub-steps, the `k` sub-steps of the step are
//! **re-spaced** over the remaining `(k − h) Δτ`, sub-step length `(k − h) Δτ / k` (also passed
//! to the experimental side), so the step ends on its deadline. After `k − 1` hold sub-steps it
//! waits for the predictor and re-bases the schedule. Hold sub-steps make the experimental side
//! see extra time, so results then differ from the offline run. [`LatePolicy::Wait`] instead
//! waits for the predictor and re-bases the schedule: no hold sub-steps, results always equal
//! the offline run (for virtual labs and tests).
//!
//! # Controlled stop from outside
//!
//! [`RealtimeRunner::stop_handle`] gives a [`StopHandle`] that any thread (the monitor page's
//! server, the stability indicator on the writer thread) uses to ask for the controlled stop.
//! The real-time thread polls it once per step, before the step's first sub-step (one atomic
//! load). At that step's first slot it hands the reason to the experimental side's safety ramp
//! ([`ExperimentalSubstructure::request_stop`]); the ramp from the last command to the safe
//! position runs on the real-time thread, paced one ramp sub-step per `Δτ` (the runner gives
//! every [`LimitedSite`] its clock with [`ExperimentalSubstructure::pace_ramp`], so a tripped
//! limit ramps on the same schedule), and the run ends with [`crate::Error::Stopped`] at the step
//! the offline driver reports, the records up to the stop flushed and the ramp in
//! [`RealtimeFailure::stop_log`].
//!
//! Records (per step: time, `u`, `v`, `a` of the chosen DOFs, coupling, error and compensation
//! force, last command, measured displacement) go through the SPSC ring to the writer; the
//! initial state is recorded first.
//!
//! [`ExperimentalSubstructure::substep`]: crate::substructure::ExperimentalSubstructure::substep
//! [`ExperimentalSubstructure::request_stop`]: crate::substructure::ExperimentalSubstructure::request_stop
//! [`ExperimentalSubstructure::pace_ramp`]: crate::substructure::ExperimentalSubstructure::pace_ramp
//! [`LimitedSite`]: crate::substructure::LimitedSite
//! [`SubstepController`]: crate::substructure::SubstepController

mod bench;
pub mod budget;
mod controllers;

mod os;
mod overlap;
mod ring;
mod runner;
mod stop;

pub use crate::latency::{LatencyHistogram, LatencySummary};
pub use bench::{BenchOverlap, bench_overlap, bench_overlap_with};
pub use controllers::{ExplicitOverlap, RealtimeController};
pub use os::RtSetting;
pub use overlap::{CouplingLoop, OverlapPredictor};
pub use ring::{Consumer, OwnedConsumer, OwnedProducer, Producer, SpscRing, owned_ring};
pub use runner::{RealtimeFailure, RealtimeResult, RealtimeRunner};
pub use stop::StopHandle;

use crate::substructure::StepRecord;
#[allow(unused_imports)] // doc links
use crate::substructure::SubstructureTest;
use std::fmt;
use std::time::Duration;

/// What to do when the next step's predictor is not ready in time (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LatePolicy {
    /// Hold sub-steps extrapolating the previous ramp, then re-space the step's sub-steps.
    #[default]
    HoldExtrapolate,
    /// Wait for the predictor and re-base the schedule (exact; for virtual labs).
    Wait,
}

#[derive(Debug, Clone, PartialEq)]
pub struct RealtimeOptions {
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)` for the run (undone afterwards).
    pub lock_memory: bool,
    /// SCHED_FIFO priority (1–99) for the real-time thread.
    pub fifo_priority: Option<i32>,
    /// SCHED_FIFO priority for the numerical thread (below the real-time thread's; it computes
    /// for part of each step and then waits, so it cannot starve the machine).
    pub numerical_fifo_priority: Option<i32>,
    /// Record every `record_every`-th step (and the initial state); 0 records nothing.
    pub record_every: usize,
    /// DOFs (0-based) whose `u`, `v`, `a` are recorded; `None` = all.
    pub record_dofs: Option<Vec<usize>>,
    /// Slots of the record ring.
    pub ring_capacity: usize,
    pub late_policy: LatePolicy,
    /// Final part of each sleep that is spun instead of slept (`spin_sleep`'s native accuracy).
    pub spin_window: Duration,
    /// Latency histogram bins: width and count.
    pub histogram_bin: Duration,
    pub histogram_bins: usize,
    /// Time from the start of `run` to the first deadline; `None` = one step (at least 1 ms).
    pub start_delay: Option<Duration>,
    /// Lag behind the schedule after which it is re-based; `None` = one step.
    pub max_lag: Option<Duration>,
    /// Fault injection (tests, demonstrations): `(m, d)` makes the numerical thread sleep `d`
    /// before it computes the predictor of step `m` (0-based within the run).
    pub numerical_delay: Vec<(usize, Duration)>,
}

impl Default for RealtimeOptions {
    fn default() -> Self {
        Self {
            lock_memory: false,
            fifo_priority: None,
            numerical_fifo_priority: None,
            record_every: 1,
            record_dofs: None,
            ring_capacity: 256,
            late_policy: LatePolicy::default(),
            spin_window: Duration::from_micros(125),
            histogram_bin: Duration::from_micros(1),
            histogram_bins: 20_000,
            start_delay: None,
            max_lag: None,
            numerical_delay: Vec::new(),
        }
    }
}

/// One recorded step, owned (the ring's slots are reused; the sink gets a reference).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StepRecordOwned {
    /// Step number (as [`SubstructureTest::steps_done`] counts) and time `step · Δt` (s).
    pub step: usize,
    pub time: f64,
    /// The recorded DOFs (0-based; same in every record) and their `u` (m), `v` (m/s), `a` (m/s²).
    pub dofs: Vec<usize>,
    pub u: Vec<f64>,
    pub v: Vec<f64>,
    pub a: Vec<f64>,
    /// Per coupling DOF (N): measured force `f_c = f^{(k)}`, error force, compensation force.
    pub coupling_force: Vec<f64>,
    pub error_force: Vec<f64>,
    pub compensation_force: Vec<f64>,
    /// Last command `d^{(k)}` and measured displacement at the end of the step (m).
    pub command: Vec<f64>,
    pub measured_displacement: Vec<f64>,
    /// Ideal error force per coupling DOF (N, as an offline run's `fei`): 0 at step 0, NaN
    /// where the site reports no noise-free force (a remote site).
    pub ideal_error_force: Vec<f64>,
    /// Hold sub-steps inserted before this step's sub-steps (late policy).
    pub holds: usize,
}

impl StepRecordOwned {
    fn with_sizes(dofs: &[usize], n_c: usize) -> Self {
        let m = dofs.len();
        Self {
            dofs: dofs.to_vec(),
            u: vec![0.0; m],
            v: vec![0.0; m],
            a: vec![0.0; m],
            coupling_force: vec![0.0; n_c],
            error_force: vec![0.0; n_c],
            compensation_force: vec![0.0; n_c],
            command: vec![0.0; n_c],
            measured_displacement: vec![0.0; n_c],
            ideal_error_force: vec![0.0; n_c],
            ..Self::default()
        }
    }

    /// Copy from a borrowed record (no allocation); `ideal`: the controller's ideal error force
    /// (`None`: 0 at step 0, else NaN, as an offline history has it).
    fn fill(&mut self, r: &StepRecord<'_>, command: &[f64], ideal: Option<&[f64]>, holds: usize) {
        self.step = r.step;
        self.time = r.time;
        for (k, &d) in self.dofs.iter().enumerate() {
            self.u[k] = r.u[d];
            self.v[k] = r.v[d];
            self.a[k] = r.a[d];
        }
        self.coupling_force.copy_from_slice(r.coupling_force);
        self.error_force.copy_from_slice(r.error_force);
        self.compensation_force.copy_from_slice(r.compensation_force);
        self.command.copy_from_slice(command);
        self.measured_displacement.copy_from_slice(r.measured_displacement);
        match ideal {
            Some(f) if r.step > 0 => self.ideal_error_force.copy_from_slice(f),
            _ => self.ideal_error_force.fill(if r.step == 0 { 0.0 } else { f64::NAN }),
        }
        self.holds = holds;
    }
}

/// What a real-time run did.
#[derive(Debug, Clone, PartialEq)]
pub struct RealtimeReport {
    pub dt: f64,
    pub k_sub: usize,
    /// Steps completed and sub-steps of the algorithm executed (`steps · k_sub`).
    pub steps: usize,
    pub substeps: usize,
    /// Extra hold sub-steps sent by the late-step policy.
    pub hold_substeps: usize,
    /// Sub-step slots (holds included) whose work ended after the next slot's deadline.
    pub missed: usize,
    /// Steps whose predictor was not ready when their first sub-step was due.
    pub late_steps: usize,
    /// Times the schedule was re-based (lag beyond `max_lag`, or waiting for a late predictor).
    pub rebased: usize,
    /// Wake-up lateness per slot: p50 / p99 / max (percentiles: upper bin edges).
    pub latency_p50: Duration,
    pub latency_p99: Duration,
    pub latency_max: Duration,
    /// Where the latest wake-up of an algorithm sub-step happened: (step, sub-step `j`, 1-based),
    /// the step counted from the run's first step (`0` = `t_0 → t_1`) plus the test's
    /// `steps_done` at the start.
    pub latency_max_at: (usize, usize),
    /// Wake-up lateness per slot (actual wake-up − deadline).
    pub histogram: LatencyHistogram,
    /// Completion per slot (end of command + measurement + step-boundary work − deadline).
    pub completion: LatencyHistogram,
    /// Numerical thread per step: from the step's last forces to the next `W` posted.
    pub numerical: LatencyHistogram,
    /// A nonlinear substructure's one-sub-step pipeline: from `f^{(k−1)}` posted (the last
    /// sub-step begins) to the next predictor's coupling rows posted; it has to stay below one
    /// sub-step `Δτ`. Empty for a linear substructure.
    pub pipeline: LatencyHistogram,
    pub records_written: u64,
    pub records_dropped: u64,
    pub memory_lock: RtSetting,
    pub fifo: RtSetting,
    pub numerical_fifo: RtSetting,
    pub wall_time: Duration,
}

impl RealtimeReport {
    pub fn wake_summary(&self) -> LatencySummary {
        (&self.histogram).into()
    }
    pub fn completion_summary(&self) -> LatencySummary {
        (&self.completion).into()
    }
    pub fn numerical_summary(&self) -> LatencySummary {
        (&self.numerical).into()
    }
    pub fn pipeline_summary(&self) -> LatencySummary {
        (&self.pipeline).into()
    }
}

impl fmt::Display for RealtimeReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "real-time run: {} steps of {} ms, k_sub = {} ({} sub-steps of {:.1} µs), wall time {:.3} s",
            self.steps,
            self.dt * 1e3,
            self.k_sub,
            self.substeps,
            self.dt / self.k_sub as f64 * 1e6,
            self.wall_time.as_secs_f64()
        )?;
        writeln!(
            f,
            "missed deadlines: {}, late steps: {}, hold sub-steps: {}, re-based: {}",
            self.missed, self.late_steps, self.hold_substeps, self.rebased
        )?;
        writeln!(
            f,
            "wake-up lateness: {} (latest sub-step: step {} j = {})",
            self.wake_summary(),
            self.latency_max_at.0,
            self.latency_max_at.1
        )?;
        writeln!(f, "completion:       {}", self.completion_summary())?;
        writeln!(f, "numerical step:   {}", self.numerical_summary())?;
        if self.pipeline.count() > 0 {
            writeln!(
                f,
                "springs pipeline: {} (budget: one sub-step)",
                self.pipeline_summary()
            )?;
        }
        writeln!(
            f,
            "records: {} written, {} dropped; mlockall: {}; SCHED_FIFO: {} (numerical thread: {})",
            self.records_written, self.records_dropped, self.memory_lock, self.fifo, self.numerical_fifo
        )?;
        writeln!(f, "wake-up lateness histogram (µs: count):")?;
        let width = if self.histogram.max() > Duration::from_micros(200) {
            Duration::from_micros(10)
        } else {
            self.histogram.bin_width()
        };
        for (lo, hi, c) in self.histogram.coarse(width) {
            writeln!(
                f,
                "  [{:>8.1}, {:>8.1}): {c}",
                lo.as_secs_f64() * 1e6,
                hi.as_secs_f64() * 1e6
            )?;
        }
        Ok(())
    }
}
