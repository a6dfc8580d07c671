//! A real-time run of a test definition into its output folder (`substep run --realtime`,
//! Python's `substep.run(config, realtime=True)`; see `docs/realtime.md`): the runner
//! ([`crate::realtime`]) against the wall clock, the reference beside it on the writer thread,
//! `history.csv` (as offline, without reference columns when the model is too large),
//! `realtime.json` (deadline report and latency histograms), `realtime.txt` and `summary.json`;
//! after a safety stop also `substeps.csv` with the tripping sub-step and the ramp to the safe
//! position (the real-time thread records no sub-steps otherwise: it does no I/O). A stop from
//! the monitor page or the stability indicator reaches the real-time thread through the
//! runner's [`StopHandle`] (set on the writer thread, polled once per step by the real-time
//! thread).

use super::live::{Live, LiveOptions};
use crate::io::config::TestDefinition;
use crate::output::files::{SubstepWriter, cannot_write, num, prepare_dir, write_atomic};
use crate::realtime::{LatencyHistogram, RealtimeOptions, RealtimeReport, RealtimeRunner, RtSetting, StopHandle};
use crate::run::SameIntegratorSummary;
use crate::{Error, Result};
use std::io::Write;
use std::path::{Path, PathBuf};

/// A front end's choices for a real-time run (the CLI's `--max-missed`, `--late-policy`,
/// `--lock-memory`, `--fifo-priority` and the monitor's flags).
#[derive(Debug, Clone, Default)]
pub struct RealtimeRunOptions {
    /// Overrides `[realtime] max_missed` (the share of missed deadlines that fails the run).
    pub max_missed: Option<f64>,
    /// Overrides `[realtime] late_policy` (`hold`, `skip`, ...).
    pub late_policy: Option<String>,
    pub lock_memory: bool,
    pub fifo_priority: Option<i32>,
    pub live: LiveOptions,
    /// Name the options in messages as Python's keywords (`max_missed`) instead of the CLI's
    /// flags (`--max-missed`).
    pub keyword_names: bool,
}

impl RealtimeRunOptions {
    fn name(&self, flag: &'static str, keyword: &'static str) -> &'static str {
        if self.keyword_names { keyword } else { flag }
    }
}

/// A finished real-time run: what the front end prints, and the monitor to close.
pub struct RealtimeOutcome {
    /// `summary.json` as written.
    pub summary: serde_json::Value,
    pub report: RealtimeReport,
    /// The report with the latency histogram (`realtime.txt`).
    pub report_text: String,
    pub report_path: PathBuf,
    /// The files written (`summary.json` last; `realtime.txt` is [`report_path`](Self::report_path)).
    pub outputs: Vec<PathBuf>,
    /// Why the run failed (diverged, stopped), if it did.
    pub failure: Option<Error>,
    /// Why a run without failure was still not the real-time test it was meant to be (too many
    /// missed deadlines).
    pub not_real_time: Option<String>,
    /// Sub-step deadlines, missed share and the share allowed.
    pub slots: usize,
    pub missed_share: f64,
    pub max_missed: f64,
    /// Peak |u| and peak |f_c|: (value, DOF index or coupling index, t).
    pub peak_u: (f64, usize, f64),
    pub peak_f: (f64, usize, f64),
    /// The assembled structure's DOFs when it was too large for a reference beside the test.
    pub no_reference: Option<usize>,
    /// (scheme, DOFs, largest displacement error, largest force error) against the reference.
    pub reference_errors: Option<(&'static str, usize, f64, f64)>,
    pub time_step_share: Option<SameIntegratorSummary>,
    pub lab: Option<crate::substructure::LabStats>,
    pub ramp_substeps: Option<usize>,
    /// The monitor and indicator of the run: the front end prints, then calls
    /// [`Live::finish`] with [`final_state`](Self::final_state) (the page may linger).
    pub live: Live,
    pub final_state: serde_json::Value,
}

fn histogram_json(h: &LatencyHistogram) -> serde_json::Value {
    let bins: Vec<serde_json::Value> = h
        .coarse(std::time::Duration::from_micros(10))
        .into_iter()
        .filter(|b| b.2 > 0)
        .map(|(lo, hi, n)| serde_json::json!([lo.as_secs_f64() * 1e6, hi.as_secs_f64() * 1e6, n]))
        .collect();
    serde_json::json!({
        "count": h.count(),
        "p50_us": h.percentile(0.5).as_secs_f64() * 1e6,
        "p99_us": h.percentile(0.99).as_secs_f64() * 1e6,
        "max_us": h.max().as_secs_f64() * 1e6,
        "above_range": h.above_range(),
        "bins_us_lo_hi_count": bins,
    })
}

fn setting(s: &RtSetting) -> String {
    s.to_string()
}

fn report_json(r: &RealtimeReport) -> serde_json::Value {
    serde_json::json!({
        "dt": r.dt, "k_sub": r.k_sub, "steps": r.steps, "substeps": r.substeps,
        "hold_substeps": r.hold_substeps, "missed_deadlines": r.missed, "late_steps": r.late_steps,
        "rebased": r.rebased, "records_written": r.records_written, "records_dropped": r.records_dropped,
        "memory_lock": setting(&r.memory_lock), "fifo": setting(&r.fifo), "numerical_fifo": setting(&r.numerical_fifo),
        "wall_time_s": r.wall_time.as_secs_f64(),
        "wake_up_latency": histogram_json(&r.histogram),
        "completion_latency": histogram_json(&r.completion),
        "numerical_step": histogram_json(&r.numerical),
        // Nonlinear numerical substructures only (count 0 otherwise): f^(k-1) posted -> W_c posted.
        "springs_pipeline": histogram_json(&r.pipeline),
    })
}

/// The sub-step algorithm's runner or a CR / KR-α test's.
enum AnyRunner {
    Substep(Box<RealtimeRunner>),
    Explicit(Box<RealtimeRunner<crate::substructure::ExplicitController>>),
}

/// Run `def` in real time into `out_dir` (`config_name`: how the summary names the test
/// definition). Bad input (no substructure, an unusable option, a model that cannot keep the
/// wall clock on this machine) is refused before anything is written; a run that diverged,
/// stopped or missed too many deadlines comes back with `failure` or `not_real_time` set.
pub fn run_realtime(
    def: &TestDefinition,
    out_dir: &Path,
    config_name: &str,
    args: &RealtimeRunOptions,
) -> Result<RealtimeOutcome> {
    let Some(_) = &def.substructure else {
        return Err(Error::invalid(
            args.name("--realtime", "realtime=True"),
            "needs a [substructure] (a monolithic run has no real-time part)",
        ));
    };
    let mut def = def.clone();
    let mut live = Live::start(&args.live, &mut def, config_name, true)?;
    let def = &def;
    let physical_dofs = def.physical_dofs();
    let sub = def.substructure.as_ref().expect("checked above");
    let accel = def.ground_motion.accel.clone();
    let load0 = -def.model.effective_mass_vector() * accel[0];
    let max_missed = match args.max_missed {
        Some(x) => crate::io::config::check_max_missed(args.name("--max-missed", "max_missed"), x)?,
        None => def.realtime.max_missed,
    };
    let late_policy = match &args.late_policy {
        Some(name) => crate::io::config::parse_late_policy(args.name("--late-policy", "late_policy"), name)?,
        None => def.realtime.late_policy,
    };
    // Can this model keep the wall clock on this machine? Measured on a throwaway controller
    // before any site or lab target is connected (docs/realtime.md, budget).
    // Hysteretic springs run in the runner's one-sub-step pipeline (docs/realtime.md).
    let springs = || def.hysteresis.as_ref().map(|h| h.build(def.model.n_dofs())).transpose();
    let mass_influence = def.model.effective_mass_vector();
    let options = RealtimeOptions {
        lock_memory: args.lock_memory,
        fifo_priority: args.fifo_priority,
        late_policy,
        ..RealtimeOptions::default()
    };
    let stop = StopHandle::new();
    let runner = if sub.explicit.is_some() {
        // CR / KR-α (docs/theory.md §2.9): the whole step runs on the numerical thread.
        let model = def.model.dense("a cr or kr_alpha substructure test")?;
        let probe = sub.explicit_controller(&model, def.integrator.dt, springs()?, &load0)?;
        crate::realtime::budget::probe_steps(probe, &mass_influence, &accel)
            .check(args.name("--realtime", "realtime=True"))?;
        let test = sub.build_explicit_test(&model, def.integrator.dt, springs()?, &load0)?;
        AnyRunner::Explicit(Box::new(
            RealtimeRunner::new(&def.model, test, accel.clone(), options)?.with_stop_handle(stop.clone()),
        ))
    } else {
        let mut probe =
            crate::substructure::SubstepController::new(&def.model, &sub.settings(def.integrator.dt), &load0)?;
        if let Some(s) = springs()? {
            probe.set_springs(s);
        }
        crate::realtime::budget::probe(probe, &mass_influence, &accel)
            .check(args.name("--realtime", "realtime=True"))?;
        let mut test = sub.build_test(&def.model, def.integrator.dt, &load0)?;
        if let Some(s) = springs()? {
            test.controller.set_springs(s);
        }
        AnyRunner::Substep(Box::new(
            RealtimeRunner::new(&def.model, test, accel.clone(), options)?.with_stop_handle(stop.clone()),
        ))
    };
    // The monolithic reference runs on this (the writer's) thread, as offline, up to
    // REALTIME_REFERENCE_MAX_DOFS DOFs (a step well under a millisecond). A larger model's
    // reference would be a second full integration next to the real-time thread on the same
    // cores; those runs record no reference and say so (run offline for it).
    let (mut reference, no_reference) = match crate::run::Reference::new(def)? {
        Some(r) if r.n_dofs() > crate::run::REALTIME_REFERENCE_MAX_DOFS => (None, Some(r.n_dofs())),
        r => (r, None),
    };
    // Beside the exact reference, as offline, the same model with the test's own integrator
    // (`reference.same_integrator`: the time step's share of the error).
    let mut same_integrator = reference
        .as_ref()
        .and_then(|r| crate::run::SameIntegrator::beside(def, r));
    let mut reference_step = 0usize;
    // Errors against it, as offline: per DOF, peak |test − reference| over the peak |reference|.
    let n_c = sub.coupling_dofs.len();
    let mut err_u = crate::run::ErrorTracker::new(def.model.n_dofs());
    let mut err_f = crate::run::ErrorTracker::new(n_c);
    // Everything above is validation; no output of an earlier run survives into this one.
    prepare_dir(out_dir)?;
    let summary_path = out_dir.join("summary.json");
    let running = serde_json::json!({
        "config": config_name,
        "mode": "realtime",
        "completed": false,
        "status": "running (a run that was killed leaves this summary; history.csv holds the steps flushed so far)",
    });
    write_json(&summary_path, &running)?;
    let history_path = out_dir.join("history.csv");
    let file = std::fs::File::create(&history_path).map_err(|e| cannot_write(&history_path, e))?;
    let mut w = std::io::BufWriter::new(file);
    // The columns of an offline run's history: the ideal error force (local sites), the
    // reference's and the indicator's when they run; no phase-lag columns (the real-time
    // records do not carry them).
    let indicator_columns = live.indicator().is_some();
    // As offline: a remote site or a lab target reports no noise-free force, so no `fei`; nor
    // does a CR / KR-α test keep an ideal error force.
    let ideal_column = sub.remote.is_none() && sub.lab_target.is_none() && sub.explicit.is_none();
    let layout = crate::run::Layout {
        n_dofs: def.model.n_dofs(),
        coupling_dofs: sub.coupling_dofs.clone(),
        extra_groups: if ideal_column { vec!["fei"] } else { Vec::new() },
        reference: reference.is_some(),
        indicator: indicator_columns,
        dt: def.integrator.dt,
        substeps: Some(sub.substeps),
        // What the stop's substeps.csv below holds: the ramp, no phase-lag columns.
        phase_lag: false,
        lab: false,
        ramp_column: true,
        response_columns: None,
    };
    let header = layout.history_columns().join(",");
    writeln!(w, "{header}").map_err(|e| cannot_write(&history_path, e))?;
    let mut line = String::new();
    let mut write_error = None;
    let mut last_flush = std::time::Instant::now();
    // Response peaks for the printed summary: (|x|, index, t) of u and of f_c.
    let mut peak_u = (0.0_f64, 0usize, 0.0_f64);
    let mut peak_f = (0.0_f64, 0usize, 0.0_f64);
    let coupling = sub.coupling_dofs.clone();
    let mut warnings: Vec<String> = Vec::new();
    let mut runaway: Option<String> = None;
    // A nonlinear reference whose Newton iteration fails ends the test (as offline), with the
    // controlled ramp-down.
    let mut reference_failure: Option<crate::Error> = None;
    let sink = |r: &crate::realtime::StepRecordOwned| {
        let ag = accel.get(r.step).copied().unwrap_or(0.0);
        if let Some(w) = live.record_realtime(r, ag, &coupling) {
            warnings.push(w);
        }
        if let Some(reason) = live.take_stop() {
            stop.request(reason);
        }
        // A runaway response stops the test with the controlled ramp-down (as offline).
        if runaway.is_none()
            && let Some((k, x)) = crate::run::runaway_dof(r.u.as_slice(), physical_dofs)
        {
            let reason = format!(
                "diverged: runaway response: |u| = {} m on DOF {} exceeded {} m at step {}",
                crate::format::sig(x.abs(), 4),
                k + 1,
                crate::run::RUNAWAY_DISPLACEMENT,
                r.step
            );
            stop.request(reason.clone());
            runaway = Some(reason);
        }
        for (k, &x) in r.u.iter().take(physical_dofs).enumerate() {
            if x.abs() > peak_u.0 {
                peak_u = (x.abs(), k, r.time);
            }
        }
        for (k, &x) in r.coupling_force.iter().enumerate() {
            if x.abs() > peak_f.0 {
                peak_f = (x.abs(), k, r.time);
            }
        }
        line.clear();
        num(&mut line, r.time);
        for group in [
            &r.u,
            &r.v,
            &r.a,
            &r.coupling_force,
            &r.error_force,
            &r.compensation_force,
            &r.measured_displacement,
        ] {
            for &x in group.iter() {
                line.push(',');
                num(&mut line, x);
            }
        }
        if ideal_column {
            for &x in &r.ideal_error_force {
                line.push(',');
                num(&mut line, x);
            }
        }
        if let Some(reference) = reference.as_mut() {
            // Records can be sparser than the steps (dropped when the writer falls behind).
            while reference_step < r.step {
                reference_step += 1;
                let ag = accel.get(reference_step).copied().unwrap_or(0.0);
                if reference_failure.is_none()
                    && let Err(e) = reference.step(ag)
                {
                    let failed =
                        crate::run::reference_failed(reference_step, reference_step as f64 * def.integrator.dt, &e);
                    stop.request(failed.to_string());
                    reference_failure = Some(failed);
                }
                if same_integrator.as_mut().is_some_and(|s| !s.step(ag)) {
                    same_integrator = None;
                }
            }
            for &x in reference.u() {
                line.push(',');
                num(&mut line, x);
            }
            // The records hold every DOF (no `record_dofs` here), as the reference does.
            err_u.update(&r.u, reference.u());
            err_f.update(&r.coupling_force, reference.coupling_force());
            if let Some(same) = same_integrator.as_mut() {
                same.record(&r.u, reference.u());
            }
        }
        if indicator_columns && let Some(m) = live.indicator() {
            for x in m.history_values() {
                line.push(',');
                num(&mut line, x);
            }
        }
        line.push('\n');
        if let Err(e) = w.write_all(line.as_bytes()) {
            write_error.get_or_insert(e);
        }
        if last_flush.elapsed().as_millis() > 500 {
            let _ = w.flush();
            last_flush = std::time::Instant::now();
        }
    };
    // A lab target's link statistics: with the test, or with the failure.
    let result = match runner {
        AnyRunner::Substep(runner) => runner
            .run(sink)
            .map(|(report, test)| (report, test.site.lab_stats().cloned())),
        AnyRunner::Explicit(runner) => runner
            .run(sink)
            .map(|(report, test)| (report, test.site.lab_stats().cloned())),
    };
    w.flush().map_err(|e| cannot_write(&history_path, e))?;
    if let Some(e) = write_error {
        return Err(cannot_write(&history_path, e));
    }
    let (report, failure, stop, lab) = match result {
        Ok((report, lab)) => (report, None, None, lab),
        Err(f) => {
            let f = *f;
            (f.report, Some(f.error), f.stopped_at.zip(f.stop_log), f.lab)
        }
    };
    let realtime_path = out_dir.join("realtime.json");
    let mut outputs = vec![history_path.clone(), realtime_path.clone()];
    let mut ramp_substeps = None;
    if let Some(((step, j), log)) = &stop {
        let path = out_dir.join("substeps.csv");
        let mut w = SubstepWriter::create(&path, &layout).map_err(|e| cannot_write(&path, e))?;
        log.replay(*step, *j, &mut w);
        ramp_substeps = Some(w.ramp_rows());
        w.finish().map_err(|e| cannot_write(&path, e))?;
        outputs.push(path);
    }
    outputs.push(summary_path.clone());
    let rt = report_json(&report);
    write_json(&realtime_path, &rt)?;
    // The largest errors against the reference (the offline summary's keys; its per-DOF
    // details are in the offline run's summary).
    let reference_errors = reference
        .as_ref()
        .map(|r| (r.scheme(), r.n_dofs(), err_u.max_peak_error(), err_f.max_peak_error()));
    let time_step_share = same_integrator.as_ref().map(crate::run::SameIntegrator::summary);
    // As offline: an error against the reference beyond 100 % is a diverged run; a failed
    // reference is the run's failure (the stop it asked for names it too).
    let mut failure = match (reference_failure, failure) {
        (Some(e), Some(crate::Error::Stopped { .. }) | None) => Some(e),
        (_, f) => f,
    };
    let overall = err_u.overall_peak_error();
    if failure.is_none() && overall > crate::run::DIVERGED_ERROR {
        failure = Some(crate::Error::Diverged {
            step: report.steps,
            time: report.steps as f64 * def.integrator.dt,
            reason: format!(
                "the largest displacement error against the reference reached {} of the reference's largest \
                 displacement (more than {} %): the test diverged from the structure it simulates",
                crate::format::percent(overall),
                100.0 * crate::run::DIVERGED_ERROR
            ),
        });
    }
    // A run that missed more deadlines than the lab accepts was not the real-time test it was
    // meant to be (the actuator held or jumped on every missed slot): a failure, not "completed".
    let slots = report.substeps + report.hold_substeps;
    let missed_share = if slots > 0 {
        report.missed as f64 / slots as f64
    } else {
        0.0
    };
    let not_real_time = crate::io::config::too_many_missed(report.missed, slots, max_missed);
    let mut not_real_time_reason = None;
    if failure.is_none() && not_real_time {
        not_real_time_reason = Some(format!(
            "not real time: {} of {} sub-step deadlines missed ({}), more than the {} allowed \
             ([realtime] max_missed, --max-missed); the actuator held or jumped on every missed \
             sub-step, so this was a slower test than the one defined (docs/realtime.md){}",
            report.missed,
            slots,
            crate::format::percent(missed_share),
            crate::format::percent(max_missed),
            // Without SCHED_FIFO a woken sub-step thread can wait a scheduler slice behind
            // another thread: the usual cause on a lab PC, and the fix is one flag.
            if report.fifo == crate::realtime::RtSetting::Applied {
                ""
            } else {
                "; the sub-step thread ran without SCHED_FIFO: try --fifo-priority 80 --lock-memory \
                 (root or CAP_SYS_NICE / CAP_IPC_LOCK), which removes the scheduler's wake-up delays"
            }
        ));
    }
    let diverged = matches!(failure, Some(crate::Error::Diverged { .. })) || (runaway.is_some() && failure.is_some());
    let (stopped_at_step, reason) = match &failure {
        Some(crate::Error::Diverged { step, reason, .. } | crate::Error::Stopped { step, reason, .. }) => {
            (Some(*step), Some(reason.clone()))
        }
        Some(e) => (Some(report.steps + 1), Some(e.to_string())),
        None => (None, not_real_time_reason.clone()),
    };
    let completed = failure.is_none() && not_real_time_reason.is_none();
    // As offline: only the monitor's own stops (operator, stability indicator) are named.
    let stopped_by = match &failure {
        Some(crate::Error::Stopped { .. }) => live.stopped_by,
        _ => None,
    };
    let mut summary = serde_json::json!({
        "config": config_name,
        "mode": "realtime",
        "dt": def.integrator.dt,
        "steps": def.integrator.steps,
        "completed": completed,
        "diverged": diverged,
        "real_time": !not_real_time,
        "steps_done": report.steps,
        "stopped_at_step": stopped_at_step,
        "reason": reason,
        "ramp_substeps": ramp_substeps,
        "missed_deadlines": report.missed,
        "deadlines": slots,
        "missed_share": missed_share,
        "max_missed": max_missed,
        "late_steps": report.late_steps,
        "wake_up_latency_p99_us": report.latency_p99.as_secs_f64() * 1e6,
        "warnings": warnings,
        "stability": live.summary(),
        "outputs": outputs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
    });
    if let (Some(s), Some(obj)) = (stopped_by, summary.as_object_mut()) {
        obj.insert("stopped_by".into(), s.into());
    }
    if let (Some(l), Some(obj)) = (&lab, summary.as_object_mut()) {
        obj.insert("lab".into(), l.json());
    }
    if let (Some((scheme, n_dofs, u, f)), Some(obj)) = (reference_errors, summary.as_object_mut()) {
        let mut r = serde_json::json!({ "scheme": scheme, "n_dofs": n_dofs,
            "max_displacement_error": u, "max_force_error": f });
        if let (Some(split), Some(o)) = (&time_step_share, r.as_object_mut()) {
            o.insert("same_integrator".into(), serde_json::json!(split));
        }
        obj.insert("reference".into(), r);
    }
    write_json(&summary_path, &summary)?;
    // The full report with the latency histogram goes to a file; the front end prints the statistics.
    let report_text = report.to_string();
    let report_path = out_dir.join("realtime.txt");
    write_atomic(&report_path, report_text.as_bytes()).map_err(|e| cannot_write(&report_path, e))?;
    let final_state = serde_json::json!({ "completed": completed, "reason": summary["reason"], "stopped_by": stopped_by,
        "steps_done": report.steps,
        "missed_deadlines": report.missed, "late_steps": report.late_steps });
    Ok(RealtimeOutcome {
        summary,
        report,
        report_text,
        report_path,
        outputs,
        failure,
        not_real_time: not_real_time_reason,
        slots,
        missed_share,
        max_missed,
        peak_u,
        peak_f,
        no_reference,
        reference_errors,
        time_step_share,
        lab,
        ramp_substeps,
        live,
        final_state,
    })
}

fn write_json(path: &Path, v: &serde_json::Value) -> Result<()> {
    let text = serde_json::to_string_pretty(v).map_err(|e| cannot_write(path, e))? + "\n";
    write_atomic(path, text.as_bytes()).map_err(|e| cannot_write(path, e))
}
