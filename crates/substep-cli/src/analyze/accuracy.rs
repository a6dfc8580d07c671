//! `substep analyze accuracy`: peak errors over a grid (`accuracy.csv`, error and
//! transfer-function plots) from [`substep::analysis::accuracy`].

use super::*;

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
    /// Optional series parameter name=a:b:n (zeta_s, zeta, eta_f, eta_m, eta_p, stiffness_ratio); adds a column
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

pub(super) fn accuracy(a: &AccuracyArgs) -> Result<()> {
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

pub(super) fn accuracy_plots(
    a: &AccuracyArgs,
    base: &AnalysisCase,
    rows: &[AccuracyRow],
    grid: &AccuracyGrid,
) -> Result<()> {
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
            "frequency ratio ω_exc/ω [–]",
            "h = |u₁| ω²/|a_g| [–]",
            &curves,
        )?;
    }
    Ok(())
}
