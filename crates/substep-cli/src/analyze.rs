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
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use substep::analysis::frequency::{DiscreteResponse, Peak, exact_amplification, find_peaks, peak_errors};
use substep::analysis::stability::{MapPoint, critical_omega, linear_grid, stability_map};
use substep::analysis::verify::{free_vibration_growth, stepped_sine_sweep};
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
    let points = stability_map(&base, &k_subs, &omegas, param, &values, &|done| {
        pb.set_position(done as u64)
    })?;
    pb.finish_and_clear();
    let secs = t0.elapsed().as_secs_f64();
    create_out(&a.out)?;
    let name = param.name();
    let mut csv = format!("k_sub,Omega,{name},rho\n");
    for p in &points {
        let _ = writeln!(csv, "{},{},{},{}", p.k_sub, p.omega_dt, p.value, p.rho);
    }
    write_file(&a.out.join("stability.csv"), &csv)?;
    let mut limits = format!("k_sub,{name},Omega_cr\n");
    let mut summary = String::new();
    for &k in &k_subs {
        let rows: Vec<Vec<f64>> = values
            .iter()
            .map(|&v| rows_of(&points, k, v).iter().map(|p| p.1).collect())
            .collect();
        let mut crit = Vec::new();
        for (iv, &v) in values.iter().enumerate() {
            let row: Vec<(f64, f64)> = omegas.iter().copied().zip(rows[iv].iter().copied()).collect();
            let w = critical_omega(&row, a.tol);
            let _ = writeln!(limits, "{k},{v},{}", w.map_or("none".into(), |w| w.to_string()));
            crit.push(w);
        }
        let stable_share = points
            .iter()
            .filter(|p| p.k_sub == k && Stability::classify(p.rho, a.tol) != Stability::Unstable)
            .count() as f64
            / (omegas.len() * values.len()) as f64;
        let _ = writeln!(
            summary,
            "  k_sub = {k}: {:.1} % of the grid stable or limited",
            100.0 * stable_share
        );
        if !a.no_plots {
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

/// `(Ω, ρ)` of one row of a map, ordered by Ω.
fn rows_of(points: &[MapPoint], k: usize, v: f64) -> Vec<(f64, f64)> {
    points
        .iter()
        .filter(|p| p.k_sub == k && p.value == v)
        .map(|p| (p.omega_dt, p.rho))
        .collect()
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

struct AccuracyRow {
    k_sub: usize,
    eta_t: f64,
    eta_p: f64,
    value: Option<f64>,
    peaks: Vec<substep::analysis::frequency::PeakError>,
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
    let values: Vec<Option<f64>> = match &vary {
        Some((_, v)) => v.iter().map(|&x| Some(x)).collect(),
        None => vec![None],
    };
    let mut jobs = Vec::new();
    for &k in &k_subs {
        for &ep in &eta_ps {
            for &v in &values {
                for &et in &eta_ts {
                    jobs.push((k, ep, v, et));
                }
            }
        }
    }
    let pb = progress(jobs.len(), a.quiet, "accuracy");
    let rows = jobs
        .par_iter()
        .map(|&(k, ep, v, et)| {
            let mut c = AnalysisCase {
                k_sub: k,
                eta_p: ep,
                ..base
            }
            .with(Parameter::EtaT, et);
            if let (Some((p, _)), Some(x)) = (&vary, v) {
                c = c.with(*p, x);
            }
            let peaks = peak_errors(&c)?;
            pb.inc(1);
            Ok(AccuracyRow {
                k_sub: k,
                eta_t: et,
                eta_p: ep,
                value: v,
                peaks,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    pb.finish_and_clear();
    create_out(&a.out)?;
    let extra = vary.as_ref().map(|(p, _)| format!("{},", p.name())).unwrap_or_default();
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
        accuracy_plots(a, &base, &rows, vary.map(|(p, _)| p), &k_subs, &eta_ts, &eta_ps)?;
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

fn accuracy_plots(
    a: &AccuracyArgs,
    base: &AnalysisCase,
    rows: &[AccuracyRow],
    vary: Option<Parameter>,
    k_subs: &[usize],
    eta_ts: &[f64],
    eta_ps: &[f64],
) -> Result<()> {
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
        let mut curves = Vec::new();
        for &et in eta_ts {
            let c = AnalysisCase {
                k_sub: k,
                eta_p: eta_ps[0],
                ..*base
            }
            .with(Parameter::EtaT, et);
            let resp = DiscreteResponse::new(&c)?;
            curves.push(Curve {
                label: format!("η_T = {et}"),
                x: r_grid.clone(),
                y: r_grid.iter().map(|&r| resp.amplification(r)).collect(),
            });
        }
        curves.push(Curve {
            label: "exact".into(),
            x: r_grid.clone(),
            y: r_grid
                .iter()
                .map(|&r| exact_amplification(base, r).unwrap_or(f64::NAN))
                .collect(),
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
/// outside the stability boundary run in the time domain; a PID-stabilised point.
fn verify(a: &VerifyArgs) -> Result<()> {
    create_out(&a.out)?;
    let mut md =
        String::from("# Verification of the analysis in the time domain\n\nGenerated by `substep analyze verify`.\n\n");
    let mut csv = String::from("check,case,k_sub,Omega,eta_p,quantity,frequency_domain,time_domain,agrees\n");
    let mut all_ok = true;

    md.push_str("## Stepped-sine sweeps against the discrete frequency response\n\n");
    md.push_str("Each time-domain point is a steady-state harmonic run (Fourier coefficient over whole periods after the transient). Sweep resolution Δr = 0.005.\n\n");
    md.push_str("| case | k_sub | Ω | η_p | peak | r (freq. domain) | h (freq. domain) | r (sweep) | h (sweep) | r exact | h exact | agrees |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    let sweep_cases = [
        (
            "typical",
            AnalysisCase {
                k_sub: 1,
                ..AnalysisCase::typical_tmd()
            }
            .with(Parameter::EtaT, 0.02),
        ),
        (
            "typical",
            AnalysisCase {
                k_sub: 4,
                ..AnalysisCase::typical_tmd()
            }
            .with(Parameter::EtaT, 0.02),
        ),
        (
            "typical",
            AnalysisCase {
                k_sub: 2,
                eta_p: 0.5,
                ..AnalysisCase::typical_tmd()
            }
            .with(Parameter::EtaT, 0.02),
        ),
        (
            "large_mass_ratio",
            AnalysisCase {
                k_sub: 2,
                ..AnalysisCase::large_mass_ratio()
            }
            .with(Parameter::EtaT, 0.02),
        ),
    ];
    let step = 0.005;
    for (name, c) in sweep_cases {
        let resp = DiscreteResponse::new(&c)?;
        let fd = find_peaks(|r| resp.amplification(r), 0.05, 3.0, 1500);
        let exact = find_peaks(|r| exact_amplification(&c, r).unwrap_or(f64::NAN), 0.05, 3.0, 1500);
        let settle = (60.0 / c.omega_dt).ceil() as usize * 10;
        let td: Vec<Peak> = fd
            .par_iter()
            .map(|p| {
                let ratios: Vec<f64> = (-16..=16).map(|i| p.freq_ratio + step * i as f64).collect();
                let (_, peaks) = stepped_sine_sweep(&c, &ratios, settle, settle / 3)?;
                // the largest local maximum of this window is the sweep's peak
                Ok(peaks.into_iter().max_by(|x, y| x.h.total_cmp(&y.h)).unwrap_or(Peak {
                    freq_ratio: f64::NAN,
                    h: f64::NAN,
                }))
            })
            .collect::<Result<Vec<_>>>()?;
        for (i, (f, t)) in fd.iter().zip(&td).enumerate() {
            let ok = (t.freq_ratio - f.freq_ratio).abs() <= step + 1e-12 && (t.h - f.h).abs() <= 2e-3 * f.h;
            all_ok &= ok;
            let e = exact.get(i).copied().unwrap_or(Peak {
                freq_ratio: f64::NAN,
                h: f64::NAN,
            });
            let _ = writeln!(
                md,
                "| {name} | {} | {:.4} | {} | {} | {:.4} | {:.4} | {:.3} | {:.4} | {:.4} | {:.4} | {} |",
                c.k_sub,
                c.omega_dt,
                c.eta_p,
                i + 1,
                f.freq_ratio,
                f.h,
                t.freq_ratio,
                t.h,
                e.freq_ratio,
                e.h,
                yes(ok)
            );
            let _ = writeln!(
                csv,
                "sweep_peak,{name},{},{},{},peak{}_r,{},{},{ok}",
                c.k_sub,
                c.omega_dt,
                c.eta_p,
                i + 1,
                f.freq_ratio,
                t.freq_ratio
            );
        }
    }

    md.push_str("\n## Check points inside, on and outside the stability boundary\n\n");
    md.push_str("Ω_cr is found by bisection on ρ(Ω) = 1. Each point runs 4000 steps of free vibration after a ground-acceleration pulse; the time-domain growth per step is (peak of the last quarter / peak of the second quarter)^(1/2000). Classes: stable (< 1 − 1e-3), limited (within ±1e-3), unstable (> 1 + 1e-3) for the growth; the same bands for ρ.\n\n");
    md.push_str("| case | k_sub | where | Ω | ρ | predicted | time-domain growth | observed | agrees |\n|---|---|---|---|---|---|---|---|---|\n");
    let boundary_cases = [
        (
            "typical, ζ_s = 2 %",
            AnalysisCase {
                k_sub: 1,
                zeta_s: 0.02,
                ..AnalysisCase::typical_tmd()
            },
        ),
        (
            "large_mass_ratio",
            AnalysisCase {
                k_sub: 1,
                ..AnalysisCase::large_mass_ratio()
            },
        ),
        (
            "large_mass_ratio",
            AnalysisCase {
                k_sub: 2,
                ..AnalysisCase::large_mass_ratio()
            },
        ),
        (
            "typical, ζ_s = 2 %, η_p = 1",
            AnalysisCase {
                k_sub: 2,
                zeta_s: 0.02,
                eta_p: 1.0,
                ..AnalysisCase::typical_tmd()
            },
        ),
    ];
    let band = 1e-3;
    for (name, c) in boundary_cases {
        let Some(w_cr) = boundary(&c)? else {
            let _ = writeln!(md, "| {name} | {} | no boundary in Ω ∈ (0, π] | | | | | | |", c.k_sub);
            continue;
        };
        for (label, w) in [("inside", 0.7 * w_cr), ("on", w_cr), ("outside", 1.3 * w_cr)] {
            let case = AnalysisCase { omega_dt: w, ..c };
            let rho = case.spectral_radius()?;
            let growth = free_vibration_growth(&case, 4000)?;
            let (pred, obs) = (class(rho, band), class(growth, band));
            let ok = pred == obs;
            all_ok &= ok;
            let _ = writeln!(
                md,
                "| {name} | {} | {label} | {w:.4} | {rho:.6} | {pred} | {growth:.6} | {obs} | {} |",
                c.k_sub,
                yes(ok)
            );
            let _ = writeln!(
                csv,
                "boundary_{label},{name},{},{w},{},growth,{rho},{growth},{ok}",
                c.k_sub, c.eta_p
            );
        }
    }

    md.push_str("\n## Error-force compensation moves an unstable point into the stable region\n\n");
    md.push_str("| case | k_sub | Ω | compensation | ρ | predicted | time-domain growth | observed | agrees |\n|---|---|---|---|---|---|---|---|---|\n");
    let pid_case = AnalysisCase {
        zeta: 0.0,
        zeta_s: 0.1,
        omega_dt: 0.628,
        k_sub: 1,
        ..AnalysisCase::large_mass_ratio()
    };
    for (label, ef) in [
        ("none", ErrorForceSpec::None),
        ("PID P = 1", ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 }),
    ] {
        let case = AnalysisCase {
            error_force: ef,
            ..pid_case
        };
        let rho = case.spectral_radius()?;
        let growth = free_vibration_growth(&case, 2000)?;
        let (pred, obs) = (class(rho, band), class(growth, band));
        let ok = pred == obs;
        all_ok &= ok;
        let _ = writeln!(
            md,
            "| large mass ratio, ζ = 0, ζ_s = 10 % | 1 | 0.628 | {label} | {rho:.6} | {pred} | {growth:.4e} | {obs} | {} |",
            yes(ok)
        );
        let _ = writeln!(csv, "pid,{label},1,0.628,0,growth,{rho},{growth},{ok}");
    }
    let _ = writeln!(md, "\nAll checks agree: **{}**", yes(all_ok));
    write_file(&a.out.join("verify.md"), &md)?;
    write_file(&a.out.join("verify.csv"), &csv)?;
    if !a.quiet {
        print!("{md}");
    }
    if !all_ok {
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

fn class(rho: f64, band: f64) -> &'static str {
    Stability::classify(rho, band).name()
}

/// The smallest Ω in (0, π] with ρ = 1 (scan, then bisection), if any.
fn boundary(c: &AnalysisCase) -> Result<Option<f64>> {
    let rho = |w: f64| AnalysisCase { omega_dt: w, ..*c }.spectral_radius();
    let grid: Vec<f64> = (1..=100).map(|i| std::f64::consts::PI * i as f64 / 100.0).collect();
    let mut prev = (grid[0], rho(grid[0])?);
    if prev.1 > 1.0 {
        return Ok(None);
    }
    for &w in &grid[1..] {
        let r = rho(w)?;
        if r > 1.0 {
            let (mut lo, mut hi) = (prev.0, w);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if rho(mid)? > 1.0 { hi = mid } else { lo = mid }
            }
            return Ok(Some(0.5 * (lo + hi)));
        }
        prev = (w, r);
    }
    Ok(None)
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
