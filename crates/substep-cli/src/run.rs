//! `substep run`: load a test definition and run it into its output folder
//! ([`substep::output`]: the tables, figures and `summary.json`, the same files Python's
//! `substep.run(config, out_dir=...)` writes), with the progress bar, the live monitor and the
//! printed summary around it; `--realtime` hands over to [`crate::realtime`].

use crate::{DEFAULT_CONFIG, DEFAULT_CONFIG_NAME, RunArgs};
use anyhow::Result;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use substep::format::percent;
use substep::io::TestDefinition;
use substep::io::results::Format;
use substep::model::ReductionMethod;
use substep::output::{FolderOptions, RunFolder};
use substep::run::{Run, RunSummary, largest};
use substep::session::live::{Live, LiveObserver, LiveOptions, StabilityChoice};

/// The summary's line on the error against the reference (offline and real-time runs).
pub(crate) fn print_reference_error(scheme: &str, max_displacement_error: f64, max_force_error: f64) {
    let what = match scheme {
        "exact" => "exact solution",
        "newmark_newton" => "monolithic Newmark + Newton solution (nonlinear)",
        _ => "monolithic Newmark solution",
    };
    println!(
        "  max error vs {what}: {} (displacement), {} (coupling force)",
        percent(max_displacement_error),
        percent(max_force_error)
    );
    println!("    (largest |test − reference| over the run and all DOFs, relative to that DOF's peak |reference|)");
}

/// The summary's line on the time step's share of the error (against the exact reference, or
/// the converged Newton one of a nonlinear structure, `reference`).
pub(crate) fn print_time_step_share(scheme: &str, reference: &str, split: &substep::run::SameIntegratorSummary) {
    let against = if reference == "exact" { "exact" } else { "Newton" };
    println!(
        "    the time step alone: {} (the assembled structure integrated with this test's {scheme} scheme and Δt \
         vs {against}); the substructure test vs that solution: {}",
        percent(split.integration_error),
        percent(split.max_displacement_error)
    );
}

/// The peaks of the summary on stdout.
fn print_peaks(s: &RunSummary) {
    // A reduced model's DOFs past the kept ones are modal coordinates, not displacements.
    let kept = s.reduction.as_ref().map(|r| r.kept_dofs.as_slice());
    let peaks = &s.peaks[..kept.map_or(s.peaks.len(), |k| k.len().min(s.peaks.len()))];
    let show = |name: &str, unit: &str, (k, peak): (usize, substep::run::Peak)| {
        let full = kept.map_or_else(String::new, |kept| format!(", DOF {} of the full model", kept[k]));
        println!(
            "  peak {name} = {} {unit} (DOF {}{full}, t = {:.3} s)",
            fixed(peak.max_abs),
            k + 1,
            peak.t
        );
    };
    if !peaks.is_empty() {
        show("relative displacement |u|", "m", largest(peaks.iter().map(|p| p.u)));
        show("relative velocity |u̇|", "m/s", largest(peaks.iter().map(|p| p.v)));
        show("relative acceleration |ü|", "m/s²", largest(peaks.iter().map(|p| p.a)));
    }
    if let Some(r) = &s.reduction {
        let check = match (&r.check, &r.no_check) {
            (Some(c), _) => format!(
                "; measured against the full model: {} ({:.2} s)",
                substep::format::sig(c.max_error, 3),
                c.full_run_seconds
            ),
            (None, Some(why)) => format!("; not checked against the full model: {why}"),
            (None, None) => String::new(),
        };
        println!(
            "  reduction error (peak |u − u_full| of a kept DOF over its peak): estimated {}{}{check}",
            substep::format::sig(r.error_estimate, 3),
            if r.estimate_unreliable {
                " (unreliable: the estimate's basis was cut short)"
            } else {
                ""
            }
        );
    }
    if let Some(c) = s.coupling_peaks.as_ref().filter(|c| !c.is_empty()) {
        let (k, p) = largest(c.iter().map(|p| p.force));
        let (ke, pe) = largest(c.iter().map(|p| p.error_force));
        println!(
            "  peak coupling force |f_c| = {} N (DOF {}, t = {:.3} s), peak |error force| = {} N (DOF {})",
            fixed(p.max_abs),
            c[k].dof,
            p.t,
            fixed(pe.max_abs),
            c[ke].dof
        );
    }
}

/// A number in fixed-point notation with about four significant digits (no exponent for
/// the magnitudes of a test: 1e-6 … 1e9).
fn fixed(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 || !a.is_finite() {
        return format!("{x}");
    }
    if !(1e-6..1e9).contains(&a) {
        return format!("{x:.3e}");
    }
    let digits = (3.0 - a.log10().floor()).clamp(0.0, 9.0) as usize;
    format!("{x:.digits$}")
}

fn print_header(args: &RunArgs, def: &TestDefinition) {
    match &args.config {
        None => println!(
            "substep run: no config given, running the embedded default example (examples/default.toml):\n  \
             the typical TMD system as a virtual substructure test"
        ),
        Some(p) => println!("substep run: {}", p.display()),
    }
    let kind = match &def.substructure {
        None => format!("monolithic, scheme {}", def.integrator.name),
        Some(s) => format!(
            "substructured, scheme {}, coupling DOF(s) {:?}, k_sub = {}",
            def.integrator.name,
            s.coupling_dofs.iter().map(|c| c + 1).collect::<Vec<_>>(),
            s.substeps
        ),
    };
    println!(
        "  model: {} DOF(s), {} storage, {kind}",
        def.model.n_dofs(),
        def.model.storage_name()
    );
    if let Some(red) = &def.reduction {
        let r = &red.reduction;
        println!(
            "  reduced from {} DOFs by {} in {:.2} s: u1..u{} are DOFs {:?} of the full model, then {} {} (up to \
             {:.3} Hz){}",
            r.n_full,
            match r.method {
                ReductionMethod::CraigBampton => "Craig–Bampton",
                ReductionMethod::Ritz => "load-dependent Ritz vectors",
            },
            red.seconds,
            r.kept.len(),
            r.kept.iter().map(|d| d + 1).collect::<Vec<_>>(),
            r.modes,
            match r.method {
                ReductionMethod::CraigBampton => "fixed-interface modes",
                ReductionMethod::Ritz => "Ritz vectors",
            },
            r.basis_top_hz[0],
            if r.residual {
                " and the static correction of the ground load"
            } else {
                ""
            }
        );
    }
    if let Some(t) = def.substructure.as_ref().and_then(|s| s.lab_target.as_ref()) {
        println!(
            "  experimental side: lab target at {} ({} over {}, exchange timeout {} ms, up to {} held sub-steps in a row)",
            t.address,
            t.protocol.name(),
            t.transport.name(),
            t.timeout.as_secs_f64() * 1e3,
            t.hold_limit
        );
    }
    let steps = def.integrator.steps;
    println!(
        "  ground motion: {}; dt = {} s, {steps} steps ({} s)",
        def.ground_motion.description,
        def.integrator.dt,
        def.time(steps)
    );
}

/// A progress bar that appears once a run has taken more than a second (on a terminal, unless
/// `--quiet`).
struct Progress {
    bar: ProgressBar,
    started: Instant,
    enabled: bool,
    shown: bool,
}

impl Progress {
    fn new(steps: usize, enabled: bool) -> Self {
        let bar = ProgressBar::with_draw_target(Some(steps as u64), ProgressDrawTarget::hidden());
        bar.set_style(
            ProgressStyle::with_template("{spinner} {elapsed_precise} [{wide_bar}] {pos}/{len} steps, ETA {eta}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        Self {
            bar,
            started: Instant::now(),
            enabled,
            shown: false,
        }
    }
    fn update(&mut self, step: usize) {
        if !step.is_multiple_of(64) {
            return;
        }
        if self.enabled && !self.shown && self.started.elapsed() > Duration::from_secs(1) {
            self.bar.set_draw_target(ProgressDrawTarget::stderr());
            self.shown = true;
        }
        self.bar.set_position(step as u64);
    }
}

pub fn run(args: &RunArgs) -> Result<()> {
    let def = match &args.config {
        None => TestDefinition::from_toml(DEFAULT_CONFIG, DEFAULT_CONFIG_NAME, Path::new("."))?,
        Some(p) => TestDefinition::from_file(p)?,
    };
    let out_dir = args
        .out
        .clone()
        .or_else(|| def.output.dir.clone())
        .unwrap_or_else(|| PathBuf::from("results"));
    let container = match args.format.as_deref() {
        Some(name) => Format::parse("--format", name)?,
        None => def.output.format,
    };
    let result = run_definition(args, def, out_dir.clone());
    let result = substep::output::files::no_summary_left_running(&out_dir.join("summary.json"), result);
    if container == Format::Csv {
        return result;
    }
    // After a run that got as far as writing its outputs (completed, diverged or stopped; not
    // refused input, which leaves an earlier run's files in place), gather them; the run's own
    // error stays the result, a container that cannot be written is a runtime failure.
    let ran = match &result {
        Ok(()) => true,
        Err(e) => e
            .downcast_ref::<substep::Error>()
            .is_some_and(|e| substep::output::container::ran(Some(e))),
    };
    if !ran {
        return result;
    }
    let config = match &args.config {
        None => DEFAULT_CONFIG.to_string(),
        Some(p) => substep::io::limits::read_text(p, substep::io::limits::CONFIG_MAX_BYTES).unwrap_or_default(),
    };
    let written = substep::output::container::write(&out_dir, container, config);
    match (result, written) {
        (Err(e), _) => Err(e),
        (Ok(()), Err(e)) => Err(e.into()),
        (Ok(()), Ok(path)) => {
            if let Some(path) = path
                && !args.quiet
            {
                println!("  {} written (CSV tables and summary)", path.display());
            }
            Ok(())
        }
    }
}

/// The monitor's and the indicator's flags.
pub(crate) fn live_options(args: &RunArgs) -> LiveOptions {
    LiveOptions {
        monitor: args.monitor.clone(),
        monitor_public: args.monitor_public,
        monitor_token: args.monitor_token.clone(),
        monitor_linger: args.monitor_linger,
        stability: args.stability.map(|s| match s {
            crate::StabilityArg::Warn => StabilityChoice::Warn,
            crate::StabilityArg::Stop => StabilityChoice::Stop,
            crate::StabilityArg::Off => StabilityChoice::Off,
        }),
        pace: args.pace,
        keyword_names: false,
    }
}

fn run_definition(args: &RunArgs, mut def: TestDefinition, out_dir: PathBuf) -> Result<()> {
    let options = FolderOptions::resolve(
        &def,
        def.output.plots && !args.no_plots,
        args.plot_format.map(|f| (f.library(), "--plot-format")),
    )?;
    crate::plots::set_library_format(options.plot_format);
    if args.realtime {
        let name = args
            .config
            .as_ref()
            .map_or(DEFAULT_CONFIG_NAME.to_string(), |p| p.display().to_string());
        return crate::realtime::run_realtime(args, &def, out_dir, name);
    }
    let config_name = def.source.clone();
    let mut live = Live::start(&live_options(args), &mut def, &config_name, false)?;
    let def = def;
    let mut run = Run::new(&def)?;
    run.set_stability(live.stability_settings.clone())?;
    let layout = run.layout().clone();
    let steps = def.integrator.steps;
    if !args.quiet {
        print_header(args, &def);
    }

    // Everything above is validation; from here on outputs are written.
    let mut progress = Progress::new(steps, !args.quiet);
    let bar = progress.bar.clone();
    let mut folder =
        RunFolder::create(&def, &layout, &out_dir, options)?.with_progress(Box::new(move |step| progress.update(step)));
    let mut watched = LiveObserver {
        inner: &mut folder,
        live: &mut live,
        quiet: args.quiet,
    };
    let mut summary = run.execute(&mut watched, &AtomicBool::new(false));
    bar.finish_and_clear();
    let outputs = folder.finish(&def, run.input_motion(), &mut summary)?;
    let done = summary.steps_done;
    let final_state = serde_json::json!({
        "completed": summary.completed, "reason": summary.reason, "stopped_by": summary.stopped_by,
        "steps_done": summary.steps_done, "steps": summary.steps,
    });

    let failure = summary.failure.take();
    if !args.quiet {
        match &failure {
            None => println!(
                "  completed {done} steps in {:.3} s wall time ({:.2} µs per step of computation)",
                summary.wall_time_s, summary.us_per_step
            ),
            Some(e) => println!("  STOPPED after {done} of {steps} steps: {e}"),
        }
        print_details(&def, &summary);
        let names: Vec<String> = outputs
            .iter()
            .map(|p| {
                p.file_name()
                    .map_or_else(String::new, |f| f.to_string_lossy().into_owned())
            })
            .collect();
        println!("  outputs in {}: {}", out_dir.display(), names.join(", "));
    }
    live.finish(final_state, &outputs, args.quiet);
    match failure {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

/// The summary's lines after the first: peaks, estimation, lab, warnings, the stability
/// indicator, the error against the reference and the engineering quantities.
fn print_details(def: &TestDefinition, summary: &RunSummary) {
    if let Some(ramp_substeps) = summary.ramp_substeps {
        println!("  the {ramp_substeps} sub-steps of the ramp to the safe position are in substeps.csv (column ramp)");
    }
    print_peaks(summary);
    if let Some(e) = &summary.estimation {
        println!(
            "  error-force estimation: {} of {} steps closed with the estimate",
            e["estimated"], e["steps"]
        );
    }
    if let Some(l) = &summary.lab {
        println!("  {}", substep::lab::LabStats::summary_line(l));
    }
    for w in &summary.warnings {
        println!("  warning: {w}");
    }
    if let Some(st) = &summary.stability
        && st.alarm_count == 0
    {
        let show = |x: f64, f: &dyn Fn(f64) -> String| if x.is_finite() { f(x) } else { "–".to_string() };
        println!(
            "  stability indicator ({}): no alarm; largest energy ratio η {}, smallest model margin 1 − ρ {}",
            st.action,
            show(st.max_eta, &|x| format!("{x:.3}")),
            show(st.min_margin, &|x| format!("{x:.2e}"))
        );
    }
    if let Some(r) = &summary.reference {
        print_reference_error(r.scheme, r.max_displacement_error, r.max_force_error);
        if let Some(s) = &r.same_integrator {
            print_time_step_share(&summary.scheme, r.scheme, s);
        }
    } else if let Some(why) = substep::run::Reference::unavailable(def) {
        println!("  no reference solution: {why}");
    }
    if let Some(e) = &summary.engineering {
        for line in substep::output::response::lines(e) {
            println!("{line}");
        }
    }
}
