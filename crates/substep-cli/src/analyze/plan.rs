//! `substep analyze plan CONFIG`: the scan of [`substep::analysis::plan::plan`] as a table and
//! `plan.csv`.

use super::*;

#[derive(Debug, Args)]
pub struct PlanArgs {
    /// Test definition (TOML) with a [substructure] of linear specimens
    pub config: PathBuf,
    /// Time steps Δt [s] to scan, comma-separated (default: the config's Δt × 2, 1, 1/2)
    #[arg(long)]
    pub dt: Option<String>,
    /// Sub-steps per step to scan (default: 1, 2, 4, 8 and the config's)
    #[arg(long)]
    pub k_sub: Option<String>,
    /// Actuator delays [s] to scan (default: the config's)
    #[arg(long)]
    pub delay: Option<String>,
    /// Accepted peak error (amplitude or period) as a fraction
    #[arg(long, default_value_t = 0.02)]
    pub tolerance: f64,
    /// Required stability margin 1 − ρ
    #[arg(long, default_value_t = 1e-3)]
    pub margin: f64,
    /// Share of Δt the computation may take on this PC (the rest: I/O, actuator control)
    #[arg(long, default_value_t = 0.5)]
    pub budget: f64,
    /// Output directory of plan.csv
    #[arg(long, default_value = "analysis")]
    pub out: PathBuf,
    /// Print nothing (plan.csv is still written)
    #[arg(long, short)]
    pub quiet: bool,
}

pub(super) fn plan(a: &PlanArgs) -> Result<()> {
    use substep::analysis::plan::{PlanSettings, plan as scan};
    let def = TestDefinition::from_file(&a.config)?;
    let Some(sub) = &def.substructure else {
        bad!(
            a.config.display().to_string(),
            "plan needs a [substructure] section (a monolithic run has nothing to plan)"
        );
    };
    let dts = match &a.dt {
        Some(s) => parse_f64_list("--dt", s)?,
        None => vec![2.0 * def.integrator.dt, def.integrator.dt, 0.5 * def.integrator.dt],
    };
    if let Some(bad) = dts.iter().find(|&&v| v <= 0.0) {
        bad!("--dt", "{bad} is not > 0");
    }
    let mut k_subs = match &a.k_sub {
        Some(s) => parse_usize_list("--k-sub", s)?,
        None => vec![1, 2, 4, 8, sub.substeps],
    };
    k_subs.sort_unstable();
    k_subs.dedup();
    let delays = match &a.delay {
        Some(s) => parse_f64_list("--delay", s)?,
        None => vec![sub.actuator.delay],
    };
    if let Some(bad) = delays.iter().find(|&&v| v < 0.0) {
        bad!("--delay", "{bad} is not ≥ 0");
    }
    for (flag, v) in [
        ("--tolerance", a.tolerance),
        ("--margin", a.margin),
        ("--budget", a.budget),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            bad!(flag, "must be a number ≥ 0, got {v}");
        }
    }
    // The amplification-matrix analysis is dense (refused for large sparse models).
    let model = def.model.dense("substep analyze plan")?;
    let started = std::time::Instant::now();
    let settings = PlanSettings {
        dts,
        k_subs,
        delays,
        tolerance: a.tolerance,
        min_margin: a.margin,
        budget: a.budget,
        cost_steps: 200,
    };
    let result = scan(sub, &model, &settings)?;
    let elapsed = started.elapsed().as_secs_f64();
    create_out(&a.out)?;
    let mut csv = String::from(
        "dt,k_sub,delay,rho,margin,class,error,error_dt,error_substep,error_delay,dominant,us_per_step,budget_share,peak,freq_hz,freq_hz_exact,amplitude_error,period_error\n",
    );
    let output = sub.coupling_dofs[0];
    let mut table = format!(
        "plan for {} (response of coupling DOF {} to a_g vs the exact assembled system; errors are relative, amplitude h/h_exact − 1, period f_exact/f − 1):\n  {:>8} {:>5} {:>9} {:>9} {:>10} {:>9} {:>8} {:>14} {:>9} {:>8}  peaks: f [Hz] (amplitude error, period error)\n",
        a.config.display(),
        output + 1,
        "dt [s]",
        "k_sub",
        "delay [s]",
        "rho",
        "1 - rho",
        "class",
        "error",
        "dominant",
        "µs/step",
        "budget",
    );
    for p in &result.points {
        let cls = Stability::classify(p.rho, 1e-9).name();
        let dom = match p.dominant() {
            substep::analysis::plan::ErrorSource::TimeStep => "dt",
            substep::analysis::plan::ErrorSource::SubStepping => "sub-step",
            substep::analysis::plan::ErrorSource::Delay => "delay",
        };
        let head = format!(
            "{},{},{},{},{},{cls},{},{},{},{},{dom},{:.3},{:.5}",
            p.dt,
            p.k_sub,
            p.delay,
            p.rho,
            p.margin(),
            p.error,
            p.error_dt,
            p.error_substep,
            p.error_delay,
            p.cost * 1e6,
            p.utilisation()
        );
        let mut peak_text = String::new();
        for (i, pk) in p.peaks.iter().enumerate() {
            let _ = write!(
                peak_text,
                "  {:.3} ({:+.2} %, {:+.2} %)",
                pk.freq_hz,
                100.0 * pk.amplitude_error,
                100.0 * pk.period_error
            );
            let _ = writeln!(
                csv,
                "{head},{},{},{},{},{}",
                i + 1,
                pk.freq_hz,
                pk.freq_hz_exact,
                pk.amplitude_error,
                pk.period_error
            );
        }
        if p.peaks.is_empty() {
            let _ = writeln!(csv, "{head},,,,,");
        }
        let _ = writeln!(
            table,
            "  {:>8} {:>5} {:>9} {:>9.6} {:>10.2e} {cls:>9} {:>6.2} % {dom:>14} {:>9.1} {:>6.1} %{peak_text}",
            p.dt,
            p.k_sub,
            p.delay,
            p.rho,
            p.margin(),
            100.0 * p.error,
            p.cost * 1e6,
            100.0 * p.utilisation()
        );
    }
    if let Some(note) = &result.phase_lag_note {
        let _ = writeln!(table, "{note}");
    }
    if def.hysteresis.is_some() {
        let _ = writeln!(
            table,
            "note: the numerical substructure yields; the plan uses its initial stiffness (softening keeps a \
             stable test stable, hardening beyond it does not: analyze stability --vary stiffness_ratio=0:2:41)"
        );
    }
    let _ = writeln!(
        table,
        "criteria: peak error ≤ {:.2} %, 1 − ρ ≥ {:.0e}, computation ≤ {:.0} % of dt (measured on this PC)",
        100.0 * a.tolerance,
        a.margin,
        100.0 * a.budget
    );
    for (i, line) in result.advice.iter().enumerate() {
        let _ = writeln!(table, "{}{line}", if i == 0 { "recommendation: " } else { "  " });
    }
    let _ = writeln!(
        table,
        "scanned {} settings in {elapsed:.2} s; table in {}",
        result.points.len(),
        a.out.join("plan.csv").display()
    );
    write_file(&a.out.join("plan.csv"), &csv)?;
    if !a.quiet {
        print!("{table}");
    }
    Ok(())
}
