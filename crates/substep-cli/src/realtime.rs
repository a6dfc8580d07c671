//! `substep run --realtime`: the library's real-time run ([`substep::session::realtime`],
//! docs/realtime.md) with the CLI's flags, and its printed summary.

use crate::RunArgs;
use anyhow::Result;
use std::path::PathBuf;
use substep::io::config::TestDefinition;
use substep::session::realtime::{RealtimeRunOptions, run_realtime as run};

pub fn run_realtime(args: &RunArgs, def: &TestDefinition, out_dir: PathBuf, config_name: String) -> Result<()> {
    let options = RealtimeRunOptions {
        max_missed: args.max_missed,
        late_policy: args.late_policy.clone(),
        lock_memory: args.lock_memory,
        fifo_priority: args.fifo_priority,
        live: crate::run::live_options(args),
        keyword_names: false,
    };
    let outcome = run(def, &out_dir, &config_name, &options)?;
    let report = &outcome.report;
    if !args.quiet {
        for l in outcome
            .report_text
            .lines()
            .take_while(|l| !l.starts_with("wake-up lateness histogram"))
        {
            println!("  {l}");
        }
        println!(
            "  deadlines: {} of {} sub-step slots missed ({}; at most {} allowed): {}",
            report.missed,
            outcome.slots,
            substep::format::percent(outcome.missed_share),
            substep::format::percent(outcome.max_missed),
            if outcome.summary["real_time"] == true {
                "real time"
            } else {
                "NOT real time"
            }
        );
        let (peak_u, peak_f) = (outcome.peak_u, outcome.peak_f);
        let coupling = def.substructure.as_ref().map_or(&[][..], |s| &s.coupling_dofs[..]);
        println!(
            "  peak relative displacement |u| = {} m (DOF {}, t = {:.3} s); peak coupling force |f_c| = {} N (DOF {}, t = {:.3} s)",
            substep::format::sig(peak_u.0, 7),
            peak_u.1 + 1,
            peak_u.2,
            substep::format::sig(peak_f.0, 7),
            coupling.get(peak_f.1).map_or(0, |d| d + 1),
            peak_f.2
        );
        if let Some(n) = outcome.no_reference {
            println!(
                "  no reference in real time: the assembled structure has {n} DOFs, more than the {} a real-time \
                 run integrates beside the test; the offline run (without --realtime) reports its error",
                substep::run::REALTIME_REFERENCE_MAX_DOFS
            );
        }
        if let Some((scheme, _, u, f)) = outcome.reference_errors {
            crate::run::print_reference_error(scheme, u, f);
            if let Some(split) = &outcome.time_step_share {
                crate::run::print_time_step_share(&def.integrator.name, scheme, split);
            }
        }
        if let Some(l) = &outcome.lab {
            println!("  {}", substep::lab::LabStats::summary_line(&l.json()));
        }
        if let Some(n) = outcome.ramp_substeps.filter(|&n| n > 0) {
            println!("  the {n} sub-steps of the ramp to the safe position are in substeps.csv (column ramp)");
        }
        let names: Vec<String> = outcome
            .outputs
            .iter()
            .chain(std::iter::once(&outcome.report_path))
            .filter_map(|p| p.file_name().map(|f| f.to_string_lossy().into_owned()))
            .collect();
        println!(
            "  outputs in {}: {} (realtime.txt has the latency histogram)",
            out_dir.display(),
            names.join(", ")
        );
    }
    let substep::session::realtime::RealtimeOutcome {
        live,
        final_state,
        outputs,
        failure,
        not_real_time,
        ..
    } = outcome;
    live.finish(final_state, &outputs, args.quiet);
    match (failure, not_real_time) {
        (Some(e), _) => Err(e.into()),
        (None, Some(reason)) => Err(anyhow::anyhow!("{reason}")),
        (None, None) => Ok(()),
    }
}
