//! `substep analyze`: stability maps, accuracy (peak errors), verification runs and a test
//! planner (docs/theory.md §9). See docs/analysis.md for the contract and a reading of the results.

use crate::plots::{Curve, line_chart, rho_heatmap};
use anyhow::{Context, Result, bail};

/// A bad command-line value: a `substep::Error` so that the exit code is 2 (bad input).
macro_rules! bad {
    ($flag:expr, $($arg:tt)*) => {
        return Err(substep::Error::invalid($flag, format!($($arg)*)).into())
    };
}
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use substep::analysis::accuracy::{AccuracyGrid, AccuracyRow, accuracy_rows, transfer_functions};
use substep::analysis::stability::{linear_grid, stability_study};
use substep::analysis::verification::{VerifySettings, verify_analysis};
use substep::analysis::{AnalysisCase, FrozenPhaseLag, Parameter, Stability};
use substep::io::config::TestDefinition;
use substep::substructure::ErrorForceSpec;

#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    #[command(subcommand)]
    pub command: AnalyzeCommand,
    /// Figure format: png, svg or pdf
    #[arg(long, global = true, value_enum, value_name = "FORMAT", default_value = "png")]
    pub plot_format: crate::plots::PlotFormat,
}

#[derive(Debug, Subcommand)]
pub enum AnalyzeCommand {
    /// Spectral radius over a grid of Ω and one other parameter, per k_sub (CSV + heat maps)
    Stability(StabilityArgs),
    /// Peaks of the transfer function: amplitude and period errors against the exact system
    Accuracy(AccuracyArgs),
    /// Time-domain runs that check the frequency-domain peaks and the stability predictions
    Verify(VerifyArgs),
    /// For your own test definition: scan Δt, k_sub and actuator delay, recommend settings
    Plan(PlanArgs),
}

/// The analysis model of docs/theory.md §9.3 (dimensionless: m = 1, ω = 1).
#[derive(Debug, Clone, Args)]
pub struct CaseArgs {
    /// Base case: `typical` (η_m 5 %, ζ 5 %, ζ_s 10 %, η_f 1) or `large_mass_ratio` (η_m 50 %, ζ = ζ_s = 5 %)
    #[arg(long, default_value = "typical")]
    pub case: String,
    /// Mass ratio η_m = m_s/m
    #[arg(long)]
    pub eta_m: Option<f64>,
    /// Frequency ratio η_f = ω_s/ω
    #[arg(long)]
    pub eta_f: Option<f64>,
    /// Damping ratio ζ of the numerical substructure
    #[arg(long)]
    pub zeta: Option<f64>,
    /// Damping ratio ζ_s of the specimen
    #[arg(long)]
    pub zeta_s: Option<f64>,
    /// Error-force compensation: `none`, `pid:P`, `pid:P:I:D`
    #[arg(long, default_value = "none")]
    pub error_force: String,
}

impl CaseArgs {
    fn case(&self) -> Result<AnalysisCase> {
        let mut c = match self.case.as_str() {
            "typical" => AnalysisCase::typical_tmd(),
            "large_mass_ratio" => AnalysisCase::large_mass_ratio(),
            other => bad!(
                "--case",
                "unknown case '{other}' (expected typical or large_mass_ratio)"
            ),
        };
        if let Some(v) = self.eta_m {
            c.eta_m = v;
        }
        if let Some(v) = self.eta_f {
            c.eta_f = v;
        }
        if let Some(v) = self.zeta {
            c.zeta = v;
        }
        if let Some(v) = self.zeta_s {
            c.zeta_s = v;
        }
        c.error_force = parse_error_force(&self.error_force)?;
        c.validate()?;
        Ok(c)
    }
}

fn parse_error_force(s: &str) -> Result<ErrorForceSpec> {
    if s == "none" {
        return Ok(ErrorForceSpec::None);
    }
    let parts: Vec<&str> = s.split(':').collect();
    if parts[0] != "pid" || !(parts.len() == 2 || parts.len() == 4) {
        bad!("--error-force", "expected none, pid:P or pid:P:I:D, got '{s}'");
    }
    let num = |t: &str| -> Result<f64> {
        match t.parse::<f64>().ok().filter(|v| v.is_finite()) {
            Some(v) => Ok(v),
            None => bad!("--error-force", "'{t}' is not a number"),
        }
    };
    let p = num(parts[1])?;
    let (i, d) = if parts.len() == 4 {
        (num(parts[2])?, num(parts[3])?)
    } else {
        (0.0, 0.0)
    };
    Ok(ErrorForceSpec::Pid { p, i, d })
}

fn parse_f64_list(flag: &str, s: &str) -> Result<Vec<f64>> {
    let Some(v) = s
        .split(',')
        .map(|t| t.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
        .collect::<Option<Vec<f64>>>()
    else {
        bad!(flag, "expected a comma-separated list of numbers, got '{s}'");
    };
    if v.is_empty() {
        bad!(flag, "the list is empty");
    }
    Ok(v)
}

fn parse_usize_list(flag: &str, s: &str) -> Result<Vec<usize>> {
    match s
        .split(',')
        .map(|t| t.trim().parse::<usize>().ok().filter(|&k| k >= 1))
        .collect::<Option<Vec<usize>>>()
    {
        Some(v) => Ok(v),
        None => bad!(flag, "expected a comma-separated list of integers >= 1, got '{s}'"),
    }
}

/// `a:b:n`, an inclusive linear grid.
fn parse_grid(flag: &str, s: &str) -> Result<Vec<f64>> {
    let parts: Vec<&str> = s.split(':').collect();
    if parts.len() != 3 {
        bad!(flag, "expected a grid a:b:n, got '{s}'");
    }
    let (Ok(a), Ok(b), Ok(n)) = (
        parts[0].trim().parse::<f64>(),
        parts[1].trim().parse::<f64>(),
        parts[2].trim().parse::<usize>(),
    ) else {
        bad!(flag, "expected numbers a:b and a count n in '{s}'");
    };
    Ok(linear_grid(flag, a, b, n)?)
}

/// `name=a:b:n`.
fn parse_vary(s: &str) -> Result<(Parameter, Vec<f64>)> {
    let Some((name, grid)) = s.split_once('=') else {
        bad!("--vary", "expected name=a:b:n, got '{s}'");
    };
    let p = match Parameter::from_name(name.trim()) {
        Ok(p) => p,
        Err(e) => bad!("--vary", "{e}"),
    };
    if matches!(p, Parameter::Omega | Parameter::EtaT) {
        bad!(
            "--vary",
            "'{name}' is the x axis already; vary zeta_s, zeta, eta_f, eta_m or eta_p"
        );
    }
    Ok((p, parse_grid("--vary", grid)?))
}

fn progress(total: usize, quiet: bool, what: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(total as u64);
    if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta})") {
        pb.set_style(style.progress_chars("=> "));
    }
    pb.set_message(what.to_string());
    pb
}

fn create_out(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create output directory {}", dir.display()))
}

fn write_file(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

#[derive(Debug, Args)]
pub struct StabilityArgs {
    #[command(flatten)]
    pub case: CaseArgs,
    /// Phase-lag ratio η_p = τ/Δt (pure actuator delay)
    #[arg(long, default_value_t = 0.0)]
    pub eta_p: f64,
    /// Phase-lag compensation with frozen parameters: `none` or `polynomial:ORDER` (ORDER 1..=3,
    /// lead η_p·k_sub sub-steps)
    #[arg(long, default_value = "none")]
    pub phase_lag: String,
    /// Sub-steps per step, a list
    #[arg(long, default_value = "1,2,3,4,5")]
    pub k_sub: String,
    /// Ω = ωΔt grid a:b:n (inclusive)
    #[arg(long, default_value = "0.015708:3.141593:200")]
    pub omega: String,
    /// The y axis: name=a:b:n with name one of zeta_s, zeta, eta_f, eta_m, eta_p
    #[arg(long, default_value = "zeta_s=0:0.5:200")]
    pub vary: String,
    /// Band around ρ = 1 taken as limited stability
    #[arg(long, default_value_t = 1e-9)]
    pub tol: f64,
    /// Output directory of the CSV files and figures
    #[arg(long, default_value = "analysis")]
    pub out: PathBuf,
    /// No progress bar and no summary on stdout (files are still written)
    #[arg(long, short)]
    pub quiet: bool,
    /// Write the CSV files only, no figures
    #[arg(long)]
    pub no_plots: bool,
}

fn stability(a: &StabilityArgs) -> Result<()> {
    let mut base = a.case.case()?;
    base.eta_p = a.eta_p;
    base.phase_lag = parse_phase_lag(&a.phase_lag)?;
    base.validate()?;
    let k_subs = parse_usize_list("--k-sub", &a.k_sub)?;
    let omegas = parse_grid("--omega", &a.omega)?;
    if omegas[0] <= 0.0 {
        bad!("--omega", "Ω = ωΔt must be > 0 (got a grid starting at {})", omegas[0]);
    }
    let (param, values) = parse_vary(&a.vary)?;
    let total = k_subs.len() * omegas.len() * values.len();
    let pb = progress(total, a.quiet, "stability map");
    let t0 = std::time::Instant::now();
    let study = stability_study(&base, &k_subs, &omegas, param, &values, a.tol, &|done| {
        pb.set_position(done as u64)
    })?;
    pb.finish_and_clear();
    let secs = t0.elapsed().as_secs_f64();
    create_out(&a.out)?;
    let name = param.name();
    let mut csv = format!("k_sub,Omega,{name},rho\n");
    for p in &study.points {
        let _ = writeln!(csv, "{},{},{},{}", p.k_sub, p.omega_dt, p.value, p.rho);
    }
    write_file(&a.out.join("stability.csv"), &csv)?;
    let mut limits = format!("k_sub,{name},Omega_cr\n");
    let mut summary = String::new();
    for map in &study.maps {
        let k = map.k_sub;
        for (v, w) in values.iter().zip(&map.critical) {
            let _ = writeln!(limits, "{k},{v},{}", w.map_or("none".into(), |w| w.to_string()));
        }
        let _ = writeln!(
            summary,
            "  k_sub = {k}: {:.1} % of the grid stable or limited",
            100.0 * map.stable_share
        );
        if !a.no_plots {
            let rows: Vec<Vec<f64>> = map.rho.row_iter().map(|r| r.iter().copied().collect()).collect();
            rho_heatmap(
                &a.out.join(format!("stability_k{k}.png")),
                &format!(
                    "spectral radius, k_sub = {k}, η_p = {}, {}",
                    a.eta_p,
                    describe_case(&base, param)
                ),
                "Ω = ωΔt",
                param.symbol(),
                &omegas,
                &values,
                &rows,
            )?;
        }
    }
    write_file(&a.out.join("stability_limit.csv"), &limits)?;
    if !a.quiet {
        println!(
            "stability map: {total} points in {secs:.2} s ({:.0} points/s) -> {}",
            total as f64 / secs,
            a.out.join("stability.csv").display()
        );
        print!("{summary}");
    }
    Ok(())
}

/// `none` or `polynomial:ORDER`.
fn parse_phase_lag(s: &str) -> Result<Option<FrozenPhaseLag>> {
    if s == "none" {
        return Ok(None);
    }
    match s.split_once(':') {
        Some(("polynomial", o)) => match o.trim().parse::<usize>() {
            Ok(order) if (1..=3).contains(&order) => Ok(Some(FrozenPhaseLag::Polynomial { order })),
            _ => bad!("--phase-lag", "the polynomial order must be 1, 2 or 3, got '{o}'"),
        },
        _ => bad!("--phase-lag", "expected none or polynomial:ORDER, got '{s}'"),
    }
}

fn describe_case(c: &AnalysisCase, varied: Parameter) -> String {
    let mut parts = Vec::new();
    for (p, v) in [
        (Parameter::EtaM, c.eta_m),
        (Parameter::EtaF, c.eta_f),
        (Parameter::Zeta, c.zeta),
        (Parameter::ZetaS, c.zeta_s),
    ] {
        if p != varied {
            parts.push(format!("{} = {v}", p.symbol()));
        }
    }
    if c.error_force != ErrorForceSpec::None {
        parts.push("PID".into());
    }
    if let Some(FrozenPhaseLag::Polynomial { order }) = c.phase_lag {
        parts.push(format!("polynomial p = {order} (frozen)"));
    }
    parts.join(", ")
}

#[derive(Debug, Args)]
pub struct AccuracyArgs {
    #[command(flatten)]
    pub case: CaseArgs,
    /// Phase-lag ratios η_p = τ/Δt, a list
    #[arg(long, default_value = "0")]
    pub eta_p: String,
    /// Sub-steps per step, a list
    #[arg(long, default_value = "1,2,5")]
    pub k_sub: String,
    /// Dimensionless time steps η_T = Δt/T, a list
    #[arg(long, default_value = "0.005,0.01,0.02,0.03,0.05,0.075,0.1,0.125,0.15,0.2")]
    pub eta_t: String,
    /// Optional series parameter name=a:b:n (zeta_s, zeta, eta_f, eta_m, eta_p); adds a column
    #[arg(long)]
    pub vary: Option<String>,
    /// Output directory of the CSV files and figures
    #[arg(long, default_value = "analysis")]
    pub out: PathBuf,
    /// No progress bar and no summary on stdout (files are still written)
    #[arg(long, short)]
    pub quiet: bool,
    /// Write the CSV files only, no figures
    #[arg(long)]
    pub no_plots: bool,
}

fn accuracy(a: &AccuracyArgs) -> Result<()> {
    let base = a.case.case()?;
    let k_subs = parse_usize_list("--k-sub", &a.k_sub)?;
    let eta_ts = parse_f64_list("--eta-t", &a.eta_t)?;
    if let Some(bad) = eta_ts.iter().find(|&&v| !(v > 0.0 && v < 0.5)) {
        bad!(
            "--eta-t",
            "{bad} is outside (0, 0.5) (η_T = Δt/T; the discrete response needs Δt < T/2)"
        );
    }
    let eta_ps = parse_f64_list("--eta-p", &a.eta_p)?;
    if let Some(bad) = eta_ps.iter().find(|&&v| v < 0.0) {
        bad!("--eta-p", "{bad} is negative");
    }
    let vary = a.vary.as_deref().map(parse_vary).transpose()?;
    let grid = AccuracyGrid {
        k_subs,
        eta_ps,
        eta_ts,
        vary,
    };
    let n_values = grid.vary.as_ref().map_or(1, |(_, v)| v.len());
    let total = grid.k_subs.len() * grid.eta_ps.len() * n_values * grid.eta_ts.len();
    let pb = progress(total, a.quiet, "accuracy");
    let rows = accuracy_rows(&base, &grid, &|done| pb.set_position(done as u64))?;
    pb.finish_and_clear();
    create_out(&a.out)?;
    let extra = grid
        .vary
        .as_ref()
        .map(|(p, _)| format!("{},", p.name()))
        .unwrap_or_default();
    let mut csv =
        format!("k_sub,eta_T,eta_p,{extra}peak,freq_ratio,h,freq_ratio_exact,h_exact,amplitude_error,period_error\n");
    for r in &rows {
        for e in &r.peaks {
            let v = r.value.map(|x| format!("{x},")).unwrap_or_default();
            let _ = writeln!(
                csv,
                "{},{},{},{v}{},{},{},{},{},{},{}",
                r.k_sub,
                r.eta_t,
                r.eta_p,
                e.peak,
                e.sub.freq_ratio,
                e.sub.h,
                e.exact.freq_ratio,
                e.exact.h,
                e.amplitude_error,
                e.period_error
            );
        }
    }
    write_file(&a.out.join("accuracy.csv"), &csv)?;
    if !a.no_plots {
        accuracy_plots(a, &base, &rows, &grid)?;
    }
    if !a.quiet {
        println!(
            "accuracy: {} parameter points -> {}",
            rows.len(),
            a.out.join("accuracy.csv").display()
        );
        for r in rows.iter().take(12) {
            for e in &r.peaks {
                println!(
                    "  k_sub {} η_T {} η_p {}{} peak {}: amplitude error {:+.3} %, period error {:+.3} %",
                    r.k_sub,
                    r.eta_t,
                    r.eta_p,
                    r.value.map(|v| format!(" value {v}")).unwrap_or_default(),
                    e.peak,
                    100.0 * e.amplitude_error,
                    100.0 * e.period_error
                );
            }
        }
    }
    Ok(())
}

fn accuracy_plots(a: &AccuracyArgs, base: &AnalysisCase, rows: &[AccuracyRow], grid: &AccuracyGrid) -> Result<()> {
    let vary = grid.vary.as_ref().map(|(p, _)| *p);
    let (k_subs, eta_ts, eta_ps) = (&grid.k_subs, &grid.eta_ts, &grid.eta_ps);
    // error against the series parameter (η_T unless --vary), one curve per k_sub and peak,
    // for the first η_p
    let x_name = vary.map_or("η_T = Δt/T", |p| p.symbol());
    for (file, label, pick) in [
        ("amplitude_error.png", "amplitude error [%]", 0usize),
        ("period_error.png", "period error [%]", 1usize),
    ] {
        let mut curves = Vec::new();
        for &k in k_subs {
            for peak in 1..=2 {
                let mut pts: Vec<(f64, f64)> = rows
                    .iter()
                    .filter(|r| r.k_sub == k && r.eta_p == eta_ps[0])
                    .filter(|r| vary.is_none() || r.eta_t == eta_ts[0])
                    .filter_map(|r| {
                        let e = r.peaks.iter().find(|e| e.peak == peak)?;
                        let x = r.value.unwrap_or(r.eta_t);
                        Some((x, 100.0 * if pick == 0 { e.amplitude_error } else { e.period_error }))
                    })
                    .collect();
                pts.sort_by(|p, q| p.0.total_cmp(&q.0));
                if !pts.is_empty() {
                    curves.push(Curve {
                        label: format!("k_sub = {k}, peak {peak}"),
                        x: pts.iter().map(|p| p.0).collect(),
                        y: pts.iter().map(|p| p.1).collect(),
                    });
                }
            }
        }
        line_chart(
            &a.out.join(file),
            &if vary == Some(Parameter::EtaP) {
                format!("{label} vs {x_name} (η_T = {})", eta_ts[0])
            } else {
                format!("{label} vs {x_name} (η_p = {})", eta_ps[0])
            },
            x_name,
            label,
            &curves,
        )?;
    }
    // transfer functions: |h| vs r for each η_T (first η_p), one plot per k_sub, with the exact curve
    let r_grid: Vec<f64> = (0..=600).map(|i| 0.5 + i as f64 / 600.0).collect();
    for &k in k_subs {
        let (h, exact) = transfer_functions(base, k, eta_ps[0], eta_ts, &r_grid)?;
        let mut curves: Vec<Curve> = eta_ts
            .iter()
            .zip(h)
            .map(|(et, y)| Curve {
                label: format!("η_T = {et}"),
                x: r_grid.clone(),
                y,
            })
            .collect();
        curves.push(Curve {
            label: "exact".into(),
            x: r_grid.clone(),
            y: exact,
        });
        line_chart(
            &a.out.join(format!("transfer_function_k{k}.png")),
            &format!(
                "dynamic amplification of the primary DOF, k_sub = {k}, η_p = {}",
                eta_ps[0]
            ),
            "frequency ratio ω_exc/ω",
            "h = |u₁| ω²/|a_g|",
            &curves,
        )?;
    }
    Ok(())
}

#[derive(Debug, Args)]
pub struct VerifyArgs {
    /// Output directory of verify.md and verify.csv
    #[arg(long, default_value = "analysis")]
    pub out: PathBuf,
    /// Print nothing (the files are still written)
    #[arg(long, short)]
    pub quiet: bool,
}

/// docs/theory.md §9.6: sine-sweep peaks vs the frequency-domain peaks; check points inside, on and
/// outside the stability boundary run in the time domain; a PID-stabilised point
/// ([`verify_analysis`]); this writes `verify.md` and `verify.csv`.
fn verify(a: &VerifyArgs) -> Result<()> {
    create_out(&a.out)?;
    let settings = VerifySettings::default();
    let v = verify_analysis(&settings)?;
    let mut md =
        String::from("# Verification of the analysis in the time domain\n\nGenerated by `substep analyze verify`.\n\n");
    let mut csv = String::from("check,case,k_sub,Omega,eta_p,quantity,frequency_domain,time_domain,agrees\n");

    md.push_str("## Stepped-sine sweeps against the discrete frequency response\n\n");
    let _ = writeln!(
        md,
        "Each time-domain point is a steady-state harmonic run (Fourier coefficient over whole periods after the transient). Sweep resolution Δr = {}.\n",
        settings.sweep_step
    );
    md.push_str("| case | k_sub | Ω | η_p | peak | r (freq. domain) | h (freq. domain) | r (sweep) | h (sweep) | r exact | h exact | agrees |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for s in &v.sweeps {
        let (name, c) = (&s.name, &s.case);
        for p in &s.peaks {
            let (f, t, e) = (p.frequency_domain, p.sweep, p.exact);
            let _ = writeln!(
                md,
                "| {name} | {} | {:.4} | {} | {} | {:.4} | {:.4} | {:.3} | {:.4} | {:.4} | {:.4} | {} |",
                c.k_sub,
                c.omega_dt,
                c.eta_p,
                p.peak,
                f.freq_ratio,
                f.h,
                t.freq_ratio,
                t.h,
                e.freq_ratio,
                e.h,
                yes(p.agrees)
            );
            let _ = writeln!(
                csv,
                "sweep_peak,{name},{},{},{},peak{}_r,{},{},{}",
                c.k_sub, c.omega_dt, c.eta_p, p.peak, f.freq_ratio, t.freq_ratio, p.agrees
            );
        }
    }

    md.push_str("\n## Check points inside, on and outside the stability boundary\n\n");
    let _ = writeln!(
        md,
        "Ω_cr is found by bisection on ρ(Ω) = 1. Each point runs {n} steps of free vibration after a ground-acceleration pulse; the time-domain growth per step is (peak of the last quarter / peak of the second quarter)^(1/{half}). Classes: stable (< 1 − {b:e}), limited (within ±{b:e}), unstable (> 1 + {b:e}) for the growth; the same bands for ρ.\n",
        n = settings.boundary_steps,
        half = 2 * (settings.boundary_steps / 4),
        b = settings.band
    );
    md.push_str("| case | k_sub | where | Ω | ρ | predicted | time-domain growth | observed | agrees |\n|---|---|---|---|---|---|---|---|---|\n");
    for b in &v.boundaries {
        let (name, c) = (&b.name, &b.case);
        if b.omega_cr.is_none() {
            let _ = writeln!(md, "| {name} | {} | no boundary in Ω ∈ (0, π] | | | | | | |", c.k_sub);
            continue;
        }
        for g in &b.checks {
            let (label, w, rho, growth) = (&g.label, g.omega_dt, g.rho, g.growth);
            let (pred, obs) = (g.predicted.name(), g.observed.name());
            let _ = writeln!(
                md,
                "| {name} | {} | {label} | {w:.4} | {rho:.6} | {pred} | {growth:.6} | {obs} | {} |",
                c.k_sub,
                yes(g.agrees)
            );
            let _ = writeln!(
                csv,
                "boundary_{label},{name},{},{w},{},growth,{rho},{growth},{}",
                c.k_sub, c.eta_p, g.agrees
            );
        }
    }

    md.push_str("\n## Error-force compensation moves an unstable point into the stable region\n\n");
    md.push_str("| case | k_sub | Ω | compensation | ρ | predicted | time-domain growth | observed | agrees |\n|---|---|---|---|---|---|---|---|---|\n");
    let c = &settings.compensated;
    for g in &v.compensation {
        let (label, rho, growth) = (&g.label, g.rho, g.growth);
        let (pred, obs) = (g.predicted.name(), g.observed.name());
        let _ = writeln!(
            md,
            "| large mass ratio, ζ = {}, ζ_s = {} % | {} | {} | {label} | {rho:.6} | {pred} | {growth:.4e} | {obs} | {} |",
            c.zeta,
            100.0 * c.zeta_s,
            c.k_sub,
            c.omega_dt,
            yes(g.agrees)
        );
        let _ = writeln!(
            csv,
            "pid,{label},{},{},{},growth,{rho},{growth},{}",
            c.k_sub, c.omega_dt, c.eta_p, g.agrees
        );
    }
    let _ = writeln!(md, "\nAll checks agree: **{}**", yes(v.all_agree));
    write_file(&a.out.join("verify.md"), &md)?;
    write_file(&a.out.join("verify.csv"), &csv)?;
    if !a.quiet {
        print!("{md}");
    }
    if !v.all_agree {
        bail!(
            "verification: some time-domain checks disagree with the analysis (see {})",
            a.out.join("verify.md").display()
        );
    }
    Ok(())
}

fn yes(ok: bool) -> &'static str {
    if ok { "yes" } else { "NO" }
}

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

fn plan(a: &PlanArgs) -> Result<()> {
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

pub fn analyze(args: &AnalyzeArgs) -> Result<()> {
    crate::plots::set_format(args.plot_format);
    match &args.command {
        AnalyzeCommand::Stability(a) => stability(a),
        AnalyzeCommand::Accuracy(a) => accuracy(a),
        AnalyzeCommand::Verify(a) => verify(a),
        AnalyzeCommand::Plan(a) => plan(a),
    }
}
