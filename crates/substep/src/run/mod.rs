//! Running a [`TestDefinition`] to the end and recording it: the step loop with the monolithic
//! reference alongside, the per-step rows a front end stores ([`StepRow`]: what `history.csv`
//! and `response.csv` hold), every sub-step (through [`SubstepObserver`]), and the summary
//! ([`RunSummary`], serialised as `summary.json`: peaks, errors against the reference, tracking
//! metrics, compensation statistics, energy balance).
//!
//! Front ends differ only in their [`RunObserver`]: the CLI streams rows to CSV files (so a
//! 10⁵-DOF run never holds its history in memory), [`HistoryTable`] collects them in memory
//! (the Python package). The loop does no I/O itself; the observer decides, and can stop a run
//! between steps, as can the `cancel` flag (e.g. set by a Ctrl-C handler).
//!
//! ```no_run
//! use std::sync::atomic::AtomicBool;
//! use substep::io::TestDefinition;
//! use substep::run::{HistoryTable, execute};
//! let def = TestDefinition::from_file("examples/default.toml")?;
//! let mut table = HistoryTable::default();
//! let summary = execute(&def, &mut table, &AtomicBool::new(false))?;
//! println!("{} steps, u1 at the end = {}", summary.steps_done, table.history.column("u1").unwrap().last().unwrap());
//! # Ok::<(), substep::Error>(())
//! ```

mod engineering;
pub mod reduction;
mod simulation;
mod stats;
mod summary;
mod table;

pub use crate::format::round_time;
pub use crate::io::config::EXACT_REFERENCE_MAX_DOFS;
pub use engineering::{
    EnergySummary, EngineeringRecorder, EngineeringRow, EngineeringSummary, InputMotion, InputMotionSummary,
    MAX_DOFS as ENGINEERING_MAX_DOFS, PeakAt, SPECTRUM_ZETA, SpectrumPeak, StoreyPeak,
};
pub use simulation::{Reference, Simulation};
pub use stats::{ErrorStats, ErrorTracker, Peak, PeakTracker, largest};
pub use summary::{
    CouplingError, CouplingPeaks, DofError, DofPeaks, ReferenceSummary, RunSummary, SameIntegratorSummary,
    TrackingSummary,
};
pub use table::{HistoryTable, Table, push_number};

use crate::analysis::tracking::{ErrorAccumulator, TrackingMetrics};
use crate::error::{Error, Result};
use crate::io::{SubstructureDefinition, TestDefinition};
use crate::monitor::{StabilityAction, StabilityMonitor, StabilitySettings};
use crate::substructure::{StepRecord, SubstepObserver};
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The largest model whose monolithic reference a real-time run integrates beside the test (on
/// the writer thread, sharing the cores with the numerical thread): a step of a 10³-DOF frame's
/// reference, Newton included, costs well under a millisecond, a 10⁴-DOF one's is a second full
/// integration as costly as the test's own. Larger real-time runs record no reference; the
/// offline run of the same definition has it.
pub const REALTIME_REFERENCE_MAX_DOFS: usize = 1000;

/// The run's failure when its monolithic reference fails at `step` (a Newton iteration that
/// does not converge): a stop at that step, not bad input.
pub fn reference_failed(step: usize, time: f64, e: &Error) -> Error {
    Error::Stopped {
        step,
        time,
        reason: format!("the reference solution failed: {e}"),
    }
}

/// What a run records: the columns of its history, sub-step and engineering rows.
#[derive(Debug, Clone)]
pub struct Layout {
    pub n_dofs: usize,
    /// Coupling DOFs (0-based; empty for a monolithic run).
    pub coupling_dofs: Vec<usize>,
    /// Extra history groups, one column per coupling DOF each: `fei` (ideal error force), `te`,
    /// `du` (tracking error and correction of the last sub-step, with phase-lag compensation).
    pub extra_groups: Vec<&'static str>,
    /// The history has the reference's displacements `uref1..urefn`.
    pub reference: bool,
    /// The stability indicator runs: the history ends with `eta`, `margin` and, per coupling
    /// DOF, `k_id`, `c_id`, `lag_id` (docs/monitor.md).
    pub indicator: bool,
    pub dt: f64,
    /// `k_sub` of a substructured run, `None` for a monolithic one (no sub-step rows).
    pub substeps: Option<usize>,
    /// Sub-step rows carry `te`, `du` (phase-lag compensation).
    pub phase_lag: bool,
    /// Sub-step rows carry `held`, `strays` (a lab target's exchange, docs/lab.md).
    pub lab: bool,
    /// Sub-step rows end with a `ramp` column (runs with safety limits).
    pub ramp_column: bool,
    /// Columns of the engineering rows (`response.csv`), when they are recorded.
    pub response_columns: Option<Vec<String>>,
}

fn group(names: &mut Vec<String>, prefix: &str, n: usize) {
    names.extend((1..=n).map(|k| format!("{prefix}{k}")));
}

impl Layout {
    /// The columns of `history.csv`: `t, u1..un, v1..vn, a1..an`, for substructured runs `fc,
    /// fe, fu, dm` and the extra groups per coupling DOF, with a reference `uref1..urefn`, with
    /// the stability indicator `eta, margin, k_id1.., c_id1.., lag_id1..`.
    pub fn history_columns(&self) -> Vec<String> {
        let n_c = self.coupling_dofs.len();
        let mut c = vec!["t".to_string()];
        for p in ["u", "v", "a"] {
            group(&mut c, p, self.n_dofs);
        }
        for p in ["fc", "fe", "fu", "dm"] {
            group(&mut c, p, n_c);
        }
        for p in &self.extra_groups {
            group(&mut c, p, n_c);
        }
        if self.reference {
            group(&mut c, "uref", self.n_dofs);
        }
        if self.indicator {
            c.extend(StabilityMonitor::history_columns(n_c));
        }
        c
    }

    /// The columns of `substeps.csv` (`None` for a monolithic run): `step, substep, t, cmd..,
    /// fm.., dm..`, with phase-lag compensation `te.., du..`, against a lab target `held,
    /// strays`, with safety limits `ramp`.
    pub fn substep_columns(&self) -> Option<Vec<String>> {
        self.substeps?;
        let n_c = self.coupling_dofs.len();
        let mut c: Vec<String> = ["step", "substep", "t"].iter().map(|s| s.to_string()).collect();
        for p in ["cmd", "fm", "dm"] {
            group(&mut c, p, n_c);
        }
        if self.phase_lag {
            for p in ["te", "du"] {
                group(&mut c, p, n_c);
            }
        }
        if self.lab {
            c.push("held".into());
            c.push("strays".into());
        }
        if self.ramp_column {
            c.push("ramp".into());
        }
        Some(c)
    }
}

/// The state after one step (step 0: the initial state), borrowed from the run.
pub struct StepRow<'a> {
    pub step: usize,
    /// `step · Δt` \[s\] (not rounded).
    pub t: f64,
    pub u: &'a [f64],
    pub v: &'a [f64],
    pub a: &'a [f64],
    /// Coupling data of a substructured run.
    pub coupling: Option<StepRecord<'a>>,
    /// The extra groups of [`Layout::extra_groups`], group-major.
    pub extra: &'a [f64],
    /// Displacements of the reference, when there is one.
    pub reference: Option<&'a [f64]>,
    /// The engineering row, when it is recorded.
    pub engineering: Option<EngineeringRow<'a>>,
    /// The stability indicator after this step's data, when it runs.
    pub indicator: Option<&'a StabilityMonitor>,
}

impl StepRow<'_> {
    /// The values in the order of [`Layout::history_columns`] (time rounded by [`round_time`]).
    pub fn history_values(&self) -> impl Iterator<Item = f64> + '_ {
        let c = self.coupling.as_ref();
        std::iter::once(round_time(self.t))
            .chain(self.u.iter().copied())
            .chain(self.v.iter().copied())
            .chain(self.a.iter().copied())
            .chain(c.into_iter().flat_map(|c| {
                c.coupling_force
                    .iter()
                    .chain(c.error_force)
                    .chain(c.compensation_force)
                    .chain(c.measured_displacement)
                    .copied()
            }))
            .chain(self.extra.iter().copied())
            .chain(self.reference.into_iter().flatten().copied())
            .chain(self.indicator.into_iter().flat_map(StabilityMonitor::history_values))
    }
}

/// What a front end does with a run: it sees every step's row (from step 0) and, as a
/// [`SubstepObserver`], every sub-step. Returning `ControlFlow::Break` from [`step`](Self::step)
/// stops the run before the next step (the summary then says it was cancelled).
pub trait RunObserver: SubstepObserver {
    /// Before the first row: the columns of the run.
    fn start(&mut self, _layout: &Layout) {}
    fn step(&mut self, row: &StepRow<'_>) -> ControlFlow<()>;
    /// A controlled stop the front end asks for after [`step`](Self::step) (an operator on the
    /// monitor page): the loop hands `reason` to the test's safety ramp
    /// ([`Simulation::request_stop`]), so the next step ramps the actuators to the safe position
    /// and the run ends `Stopped` with `reason` and `stopped_by: "operator"`. The stability
    /// indicator's stop (`stability = "stop"`) is the loop's own. Only the first stop counts.
    /// Default: never.
    fn stop_request(&mut self) -> Option<String> {
        None
    }
}

/// Two sub-step observers fed in turn (the front end's and the tracking metrics).
struct Both<'a, A: ?Sized, B>(&'a mut A, &'a mut B);

impl<A: SubstepObserver + ?Sized, B: SubstepObserver> SubstepObserver for Both<'_, A, B> {
    fn substep(&mut self, step: usize, j: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.0.substep(step, j, command, force, displacement);
        self.1.substep(step, j, command, force, displacement);
    }
    fn phase_lag(&mut self, tracking_error: &[f64], correction: &[f64]) {
        self.0.phase_lag(tracking_error, correction);
        self.1.phase_lag(tracking_error, correction);
    }
    fn lab(&mut self, held: bool, strays: u64) {
        self.0.lab(held, strays);
        self.1.lab(held, strays);
    }
    #[allow(clippy::too_many_arguments)]
    fn ramp(&mut self, step: usize, j: usize, s: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.0.ramp(step, j, s, command, force, displacement);
        self.1.ramp(step, j, s, command, force, displacement);
    }
}

/// What the loop itself gathers from the sub-steps: the tracking metrics, the ramp sub-steps
/// after a safety stop and the last command (the stability indicator's).
struct SubstepMetrics {
    tracking: TrackingMetrics,
    ramp: usize,
    command: Vec<f64>,
}

impl SubstepObserver for SubstepMetrics {
    fn substep(&mut self, step: usize, j: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.tracking.substep(step, j, command, force, displacement);
        if command.len() == self.command.len() {
            self.command.copy_from_slice(command);
        }
    }
    fn ramp(&mut self, _step: usize, _j: usize, _s: usize, _command: &[f64], _force: &[f64], _displacement: &[f64]) {
        self.ramp += 1;
    }
}

/// Extra history groups: `fei` (ideal error force) for every virtual (local) substructured run
/// — a remote site or a lab target reports no noise-free force —, `te`, `du` (tracking error
/// and correction of the last sub-step) with phase-lag compensation. The ideal error force is
/// the sub-step algorithm's: a cr / kr_alpha test has none.
fn extra_groups(def: &TestDefinition) -> Vec<&'static str> {
    match &def.substructure {
        None => Vec::new(),
        Some(s) if (s.remote.is_some() || s.lab_target.is_some() || s.explicit.is_some()) && s.phase_lag.is_some() => {
            vec!["te", "du"]
        }
        Some(s) if s.remote.is_some() || s.lab_target.is_some() || s.explicit.is_some() => Vec::new(),
        Some(s) if s.phase_lag.is_some() => vec!["fei", "te", "du"],
        Some(_) => vec!["fei"],
    }
}

/// Fill the extra columns (group-major, one value per coupling DOF) for the current step.
fn extra_values(sim: &Simulation, groups: &[&str], out: &mut [f64]) {
    let (Some(site), Some(coupling)) = (sim.site(), sim.coupling_dofs()) else {
        return;
    };
    let n_c = coupling.len();
    for (g, name) in groups.iter().enumerate() {
        let cols = &mut out[g * n_c..(g + 1) * n_c];
        let src = match *name {
            "fei" if sim.steps_done() > 0 => sim.substructure_test().and_then(|t| t.controller.ideal_error_force()),
            "te" => site.phase_lag().map(|p| p.tracking_error()),
            "du" => site.phase_lag().map(|p| p.correction()),
            _ => None,
        };
        match src {
            Some(v) => cols.copy_from_slice(v),
            None => cols
                .iter_mut()
                .for_each(|c| *c = if sim.steps_done() == 0 { 0.0 } else { f64::NAN }),
        }
    }
}

/// The assembled structure integrated with the test's own scheme beside the exact reference
/// ([`Reference::same_integrator`]), and the two errors of [`SameIntegratorSummary`]: the test
/// against it, it against the exact solution. Stepped between the test's steps (offline in the
/// run loop, in a real-time run on the writer thread); allocates nothing after
/// [`SameIntegrator::beside`].
pub struct SameIntegrator {
    reference: Reference,
    test_error: ErrorTracker,
    integration_error: ErrorTracker,
}

impl SameIntegrator {
    /// Beside `exact` when it is the exact reference; `None` otherwise, and when the
    /// same-integrator reference cannot be built — an extra, never a reason to refuse a test.
    pub fn beside(def: &TestDefinition, exact: &Reference) -> Option<Self> {
        // A cr / kr_alpha test also splits its error against the converged Newton reference of
        // a nonlinear structure: its own scheme on the assembled model is explicit, no Newton.
        let explicit = def.substructure.as_ref().is_some_and(|s| s.explicit.is_some());
        if exact.scheme() != "exact" && !explicit {
            return None;
        }
        let reference = Reference::same_integrator(def).ok().flatten()?;
        let n = def.model.n_dofs();
        Some(Self {
            reference,
            test_error: ErrorTracker::new(n),
            integration_error: ErrorTracker::new(n),
        })
    }

    /// Advance with the ground acceleration at the end of the step; `false` if the step failed
    /// (a linear Newmark step does not; the caller then drops the split).
    pub fn step(&mut self, ag_next: f64) -> bool {
        self.reference.step(ag_next).is_ok()
    }

    /// The test's displacements `u` and the exact reference's `exact_u` at the current step.
    pub fn record(&mut self, u: &[f64], exact_u: &[f64]) {
        self.test_error.update(u, self.reference.u());
        self.integration_error.update(self.reference.u(), exact_u);
    }

    pub fn summary(&self) -> SameIntegratorSummary {
        SameIntegratorSummary {
            max_displacement_error: self.test_error.max_peak_error(),
            integration_error: self.integration_error.max_peak_error(),
        }
    }
}

/// Peaks and errors against the reference, gathered between steps for the summary.
struct SummaryRecorder {
    coupling: Vec<usize>,
    /// Measured coupling force of the current step.
    force: Vec<f64>,
    peak_u: PeakTracker,
    peak_v: PeakTracker,
    peak_a: PeakTracker,
    peak_fc: PeakTracker,
    peak_fe: PeakTracker,
    err_u: ErrorTracker,
    err_f: ErrorTracker,
    nrms_u: Vec<ErrorAccumulator>,
}

impl SummaryRecorder {
    fn new(n: usize, coupling: &[usize]) -> Self {
        let n_c = coupling.len();
        Self {
            coupling: coupling.to_vec(),
            force: vec![0.0; n_c],
            peak_u: PeakTracker::new(n),
            peak_v: PeakTracker::new(n),
            peak_a: PeakTracker::new(n),
            peak_fc: PeakTracker::new(n_c),
            peak_fe: PeakTracker::new(n_c),
            err_u: ErrorTracker::new(n),
            err_f: ErrorTracker::new(n_c),
            nrms_u: vec![ErrorAccumulator::new(); n],
        }
    }

    fn record(&mut self, sim: &Simulation, reference: Option<&Reference>) {
        let t = sim.time();
        let s = sim.state();
        self.peak_u.update(s.u.as_slice(), t);
        self.peak_v.update(s.v.as_slice(), t);
        self.peak_a.update(s.a.as_slice(), t);
        if let Some(rec) = sim.coupling() {
            self.peak_fc.update(rec.coupling_force, t);
            self.peak_fe.update(rec.error_force, t);
            self.force.copy_from_slice(rec.coupling_force);
        }
        if let Some(r) = reference {
            self.err_u.update(s.u.as_slice(), r.u());
            for (acc, (&u, &u_ref)) in self.nrms_u.iter_mut().zip(s.u.iter().zip(r.u())) {
                acc.push(u, u_ref);
            }
            self.err_f.update(&self.force, r.coupling_force());
        }
    }

    fn reference_summary(&self, r: &Reference, same_integrator: Option<&SameIntegrator>) -> ReferenceSummary {
        let dofs: Vec<DofError> = (0..self.peak_u.0.len())
            .map(|k| DofError {
                dof: k + 1,
                displacement: self.err_u.stats(k),
                nrms_error: self.nrms_u[k].nrms(),
            })
            .collect();
        let coupling: Vec<CouplingError> = self
            .coupling
            .iter()
            .enumerate()
            .map(|(k, &c)| CouplingError {
                dof: c + 1,
                displacement: self.err_u.stats(c),
                displacement_nrms_error: self.nrms_u[c].nrms(),
                force: self.err_f.stats(k),
            })
            .collect();
        let max = |it: &mut dyn Iterator<Item = f64>| it.filter(|x| x.is_finite()).fold(0.0, f64::max);
        ReferenceSummary {
            scheme: r.scheme(),
            n_dofs: r.n_dofs(),
            max_displacement_error: max(&mut dofs.iter().map(|d| d.displacement.peak_error)),
            max_force_error: max(&mut coupling.iter().map(|c| c.force.peak_error)),
            dofs,
            coupling,
            same_integrator: same_integrator.map(SameIntegrator::summary),
        }
    }
}

/// A run whose largest displacement error against its reference (over the run and the DOFs)
/// exceeds this share of the reference's largest displacement (100 %) has diverged from the
/// structure it simulates ([`ErrorTracker::overall_peak_error`]; docs/config.md, "Exit codes").
pub const DIVERGED_ERROR: f64 = 1.0;

/// A displacement beyond this \[m\] is a runaway response whatever the structure (no test moves a
/// kilometre): the run ends as diverged at once (after the controlled ramp-down where it has one).
pub const RUNAWAY_DISPLACEMENT: f64 = 1.0e3;

/// `value` is beyond `bound` or not a number (a NaN error or response counts as beyond).
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn exceeds(value: f64, bound: f64) -> bool {
    !(value <= bound)
}

/// The first DOF of `u` (and its value) that is a runaway response: beyond
/// [`RUNAWAY_DISPLACEMENT`] among the first `physical` DOFs, not finite anywhere. A reduced
/// model's DOFs past its kept ones are mass-normalised modal coordinates, not metres
/// (`√(kg)·m`: a 6·10⁸ kg building moving 0.1 m has coordinates of 2 400).
pub fn runaway_dof(u: &[f64], physical: usize) -> Option<(usize, f64)> {
    u.iter()
        .enumerate()
        .find(|&(k, v)| {
            if k < physical {
                exceeds(v.abs(), RUNAWAY_DISPLACEMENT)
            } else {
                !v.is_finite()
            }
        })
        .map(|(k, &v)| (k, v))
}

/// Why `u` is a runaway response, if it is (`physical` as in [`runaway_dof`]).
fn runaway(u: &[f64], physical: usize) -> Option<String> {
    let (k, v) = runaway_dof(u, physical)?;
    Some(format!(
        "runaway response: |u| = {} m on DOF {} exceeded {RUNAWAY_DISPLACEMENT} m at the step before",
        crate::format::sig(v.abs(), 4),
        k + 1
    ))
}

/// A validated run, ready to execute: the simulation, its reference and the engineering
/// recorder are built (all input errors are reported here, before a front end writes anything).
pub struct Run<'d> {
    def: &'d TestDefinition,
    sim: Simulation,
    reference: Option<Reference>,
    /// Beside an exact reference: the same structure with the test's own integrator.
    same_integrator: Option<SameIntegrator>,
    engineering: Option<EngineeringRecorder>,
    /// Computed after the loop (a long record's Fourier amplitude takes a while; a remote site
    /// should not wait for it between connecting and the first step).
    input_motion: Option<InputMotion>,
    /// The on-line stability indicator (`[substructure.limits] stability`, or
    /// [`Self::set_stability`]).
    stability: Option<StabilityMonitor>,
    layout: Layout,
    /// `[structure.reduction]`: its estimate (computed in [`Run::new`]) and, filled during the
    /// run, the kept DOFs' displacements for the check against the full model.
    reduction: Option<(reduction::ReductionSummary, Vec<Vec<f64>>)>,
}

/// The indicator of `settings` for the test `def` (`None` without a substructure).
fn stability_monitor(def: &TestDefinition, settings: Option<StabilitySettings>) -> Result<Option<StabilityMonitor>> {
    match (&def.substructure, settings) {
        (Some(sub), Some(s)) => Ok(Some(StabilityMonitor::new(sub, &def.model, def.integrator.dt, s)?)),
        _ => Ok(None),
    }
}

impl<'d> Run<'d> {
    pub fn new(def: &'d TestDefinition) -> Result<Self> {
        let sim = Simulation::new(def)?;
        let reference = Reference::new(def)?;
        let same_integrator = reference.as_ref().and_then(|r| SameIntegrator::beside(def, r));
        let engineering = EngineeringRecorder::new(def);
        let sub = def.substructure.as_ref();
        let stability = stability_monitor(def, sub.and_then(SubstructureDefinition::stability_settings))?;
        let layout = Layout {
            n_dofs: def.model.n_dofs(),
            coupling_dofs: sub.map_or_else(Vec::new, |s| s.coupling_dofs.clone()),
            extra_groups: extra_groups(def),
            reference: reference.is_some(),
            indicator: stability.is_some(),
            dt: def.integrator.dt,
            substeps: sub.map(|s| s.substeps),
            phase_lag: sub.is_some_and(|s| s.phase_lag.is_some()),
            lab: sub.is_some_and(|s| s.lab_target.is_some()),
            ramp_column: sub.is_some_and(|s| s.limits.is_some()),
            response_columns: engineering.as_ref().map(EngineeringRecorder::columns),
        };
        let reduction = reduction::estimate(def)?.map(|r| {
            let kept = vec![Vec::with_capacity(def.integrator.steps + 1); r.kept_dofs.len()];
            (r, kept)
        });
        Ok(Self {
            def,
            sim,
            reference,
            same_integrator,
            engineering,
            input_motion: None,
            stability,
            layout,
            reduction,
        })
    }

    /// Run the stability indicator with `settings` whatever the config says (`None`: not at
    /// all), e.g. for a front end's `--stability`. A test without a substructure has none.
    pub fn set_stability(&mut self, settings: Option<StabilitySettings>) -> Result<()> {
        self.stability = stability_monitor(self.def, settings)?;
        self.layout.indicator = self.stability.is_some();
        Ok(())
    }

    /// The stability indicator, when it runs.
    pub fn stability(&self) -> Option<&StabilityMonitor> {
        self.stability.as_ref()
    }

    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// The input motion's Fourier amplitude and response spectrum (after [`Self::execute`]).
    pub fn input_motion(&self) -> Option<&InputMotion> {
        self.input_motion.as_ref()
    }

    /// Step the test to its end (or until it diverges, stops, the observer breaks or `cancel`
    /// is set), feeding `observer`. A run that did not complete says why in the summary
    /// (`completed`, `stopped_at_step`, `reason`) and in [`RunSummary::failure`]. A run executes
    /// once; calling it again steps nothing.
    pub fn execute<O: RunObserver + ?Sized>(&mut self, observer: &mut O, cancel: &AtomicBool) -> RunSummary {
        let Run {
            def,
            sim,
            reference,
            same_integrator,
            engineering,
            input_motion,
            stability,
            layout,
            reduction,
        } = self;
        let def: &TestDefinition = def;
        observer.start(layout);
        let n = layout.n_dofs;
        let steps = def.integrator.steps;
        let coupling = &layout.coupling_dofs;
        let groups = &layout.extra_groups;
        let mut extra = vec![0.0; groups.len() * coupling.len()];
        let mut recorder = SummaryRecorder::new(n, coupling);
        let substep_length = def
            .substructure
            .as_ref()
            .map_or(def.integrator.dt, |s| def.integrator.dt / s.substeps as f64);
        let mut metrics = SubstepMetrics {
            tracking: TrackingMetrics::new(coupling.len(), substep_length),
            ramp: 0,
            command: vec![0.0; coupling.len()],
        };
        let mut indicator_warnings = Vec::new();
        // The first stop asked for (indicator or observer) and who asked.
        let mut stop_sent = false;
        let mut stopped_by: Option<&'static str> = None;
        let mut pending_stop: Option<String> = None;
        let mut diverging = false;
        let started = Instant::now();
        let mut compute = Duration::ZERO;
        let mut failure: Option<Error> = None;
        let mut cancelled = false;
        loop {
            let i = sim.steps_done();
            extra_values(sim, groups, &mut extra);
            if let Some(e) = engineering
                && let Err(err) = e.record(sim)
            {
                failure = Some(err);
                break;
            }
            let s = sim.state();
            if let (Some(st), Some(rec)) = (stability.as_mut(), sim.coupling())
                && let Some(alarm) = st.push(
                    i,
                    s.u.as_slice(),
                    s.v.as_slice(),
                    sim.ground_acceleration(i),
                    rec.coupling_force,
                    &metrics.command,
                    rec.measured_displacement,
                )
            {
                let msg = alarm.message();
                if st.settings().action == StabilityAction::Stop && !stop_sent {
                    stop_sent = true;
                    stopped_by = Some("stability");
                    pending_stop = Some(format!("stability stop: {msg}"));
                }
                indicator_warnings.push(msg);
            }
            let flow = observer.step(&StepRow {
                step: i,
                t: sim.time(),
                u: s.u.as_slice(),
                v: s.v.as_slice(),
                a: s.a.as_slice(),
                coupling: sim.coupling(),
                extra: &extra,
                reference: reference.as_ref().map(|r| r.u()),
                engineering: engineering.as_ref().map(|e| e.row(sim.time())),
                indicator: stability.as_ref(),
            });
            recorder.record(sim, reference.as_ref());
            if let Some((_, kept)) = reduction.as_mut() {
                for (k, h) in kept.iter_mut().enumerate() {
                    h.push(s.u[k]);
                }
            }
            if let (Some(same), Some(r)) = (same_integrator.as_mut(), reference.as_ref()) {
                same.record(s.u.as_slice(), r.u());
            }
            if !diverging && let Some(reason) = runaway(s.u.as_slice(), def.physical_dofs()) {
                // A runaway response: ramp the actuators down where the run can, else end here.
                diverging = true;
                if stop_sent || !sim.request_stop(&format!("diverged: {reason}")) {
                    // Step i is recorded; the run ends before step i + 1 (as a non-finite step).
                    failure = Some(Error::Diverged {
                        step: i + 1,
                        time: def.time(i + 1),
                        reason,
                    });
                    break;
                }
                stop_sent = true;
                stopped_by = Some("divergence");
            }
            let asked = observer.stop_request();
            if let Some(reason) = asked
                && !stop_sent
            {
                stop_sent = true;
                stopped_by = Some("operator");
                pending_stop = Some(reason);
            }
            if let Some(reason) = pending_stop.take()
                && !sim.request_stop(&reason)
            {
                failure = Some(Error::Stopped {
                    step: i + 1,
                    time: def.time(i + 1),
                    reason: format!("{reason} (between steps: this run has no ramp to the safe position)"),
                });
                break;
            }
            if i == steps {
                break;
            }
            if flow.is_break() || cancel.load(Ordering::Relaxed) {
                cancelled = true;
                failure = Some(Error::Stopped {
                    step: i + 1,
                    time: def.time(i + 1),
                    reason: "cancelled before this step (interrupted by the caller)".into(),
                });
                break;
            }
            let t0 = Instant::now();
            let result = sim.step(&mut Both(observer, &mut metrics));
            compute += t0.elapsed();
            if let Err(e) = result {
                failure = Some(e);
                break;
            }
            if let Some(r) = reference
                && let Err(e) = r.step(sim.ground_acceleration(i + 1))
            {
                // The test itself may be fine, but it has nothing to be judged against from
                // here: the run ends (exit 1), naming the step and the reference.
                failure = Some(reference_failed(i + 1, def.time(i + 1), &e));
                break;
            }
            if let Some(same) = same_integrator.as_mut()
                && !same.step(sim.ground_acceleration(i + 1))
            {
                *same_integrator = None;
            }
        }
        let wall = started.elapsed().as_secs_f64();
        // A cancelled run returns at once: the input motion's spectrum of a long record takes
        // seconds, which an interrupted caller should not wait for.
        let motion = if cancelled {
            Ok(None)
        } else {
            InputMotion::new(def).map(Some)
        };
        let motion_summary = match motion {
            Ok(Some(m)) => {
                let s = m.summary.clone();
                *input_motion = Some(m);
                s
            }
            other => {
                if let Err(e) = other {
                    failure.get_or_insert(e);
                }
                InputMotionSummary {
                    pga_g: f64::NAN,
                    pga_m_s2: f64::NAN,
                    spectrum_damping: SPECTRUM_ZETA,
                    spectrum_peak: None,
                }
            }
        };
        let done = sim.steps_done();
        let reference_summary = reference
            .as_ref()
            .map(|r| recorder.reference_summary(r, same_integrator.as_ref()));
        let overall = recorder.err_u.overall_peak_error();
        // NaN (a reference at rest throughout): nothing to judge against; a runaway is caught above.
        if failure.is_none() && overall > DIVERGED_ERROR {
            failure = Some(Error::Diverged {
                step: done,
                time: def.time(done),
                reason: format!(
                    "the largest displacement error against the reference reached {} of the reference's \
                     largest displacement (more than {} %): the test diverged from the structure it simulates",
                    crate::format::percent(overall),
                    100.0 * DIVERGED_ERROR
                ),
            });
        }
        let diverged = matches!(failure, Some(Error::Diverged { .. })) || stopped_by == Some("divergence");
        let (stopped_at_step, reason) = match &failure {
            Some(Error::Diverged { step, reason, .. } | Error::Stopped { step, reason, .. }) => {
                (Some(*step), Some(reason.clone()))
            }
            Some(e) => (Some(done + 1), Some(e.to_string())),
            None => (None, None),
        };
        let (estimation, phase_lag, mut warnings) = summary::compensation_summary(sim);
        let lab = summary::lab_summary(sim, &mut warnings);
        warnings.extend(indicator_warnings);
        let sub = def.substructure.as_ref();
        let reduction_summary = reduction.take().map(|(mut r, kept)| {
            if failure.is_none() && !cancelled && kept.first().is_some_and(|h| h.len() == steps + 1) {
                match reduction::check(def, &kept) {
                    Ok(c) => r.check = c,
                    Err(e) => warnings.push(format!("the check of the reduction against the full model failed: {e}")),
                }
            }
            if let Some(c) = &r.check
                && c.max_error > r.error_estimate.max(reduction::CHECK_FLOOR)
            {
                warnings.push(format!(
                    "the reduced model's error against the full model ({}) exceeds its estimate ({})",
                    crate::format::sig(c.max_error, 3),
                    crate::format::sig(r.error_estimate, 3)
                ));
            }
            r
        });
        RunSummary {
            config: def.source.clone(),
            scheme: def.integrator.name.clone(),
            dt: def.integrator.dt,
            steps,
            duration: def.time(steps),
            n_dofs: n,
            ground_motion: def.ground_motion.description.clone(),
            substructure: sub.map(summary::substructure_json),
            completed: failure.is_none(),
            diverged,
            steps_done: done,
            stopped_at_step,
            reason,
            // Named only when the run did end by that stop (not by a later divergence).
            stopped_by: stopped_by.filter(|_| matches!(failure, Some(Error::Stopped { .. }))),
            ramp_substeps: (metrics.ramp > 0).then_some(metrics.ramp),
            wall_time_s: wall,
            us_per_step: compute.as_secs_f64() * 1e6 / done.max(1) as f64,
            peaks: (0..n)
                .map(|k| DofPeaks {
                    dof: k + 1,
                    u: recorder.peak_u.0[k],
                    v: recorder.peak_v.0[k],
                    a: recorder.peak_a.0[k],
                })
                .collect(),
            coupling_peaks: sub.map(|_| {
                coupling
                    .iter()
                    .enumerate()
                    .map(|(k, &c)| CouplingPeaks {
                        dof: c + 1,
                        force: recorder.peak_fc.0[k],
                        error_force: recorder.peak_fe.0[k],
                    })
                    .collect()
            }),
            tracking: sub.map(|_| {
                coupling
                    .iter()
                    .enumerate()
                    .map(|(k, &c)| {
                        let t = metrics.tracking.result(k);
                        TrackingSummary {
                            dof: c + 1,
                            delay_s: t.delay,
                            max_delay_s: t.max_delay,
                            nrms_error: t.nrms,
                            peak_error: t.peak,
                        }
                    })
                    .collect()
            }),
            reference: reference_summary,
            estimation,
            phase_lag,
            lab,
            stability: stability.as_ref().map(StabilityMonitor::summary),
            warnings,
            input_motion: motion_summary,
            engineering: engineering.as_ref().map(EngineeringRecorder::summary),
            reduction: reduction_summary,
            outputs: Vec::new(),
            failure,
        }
    }
}

/// Validate `def` and run it to the end, feeding `observer` (see [`Run::execute`]). `Err` only
/// for input errors, before the first step; a run that diverged or stopped returns its summary.
pub fn execute<O: RunObserver + ?Sized>(
    def: &TestDefinition,
    observer: &mut O,
    cancel: &AtomicBool,
) -> Result<RunSummary> {
    Ok(Run::new(def)?.execute(observer, cancel))
}
