//! `substep analyze stability`: spectral-radius maps (`stability.csv`, `stability_limit.csv`,
//! heat maps) from [`substep::analysis::stability::stability_study`].

use super::*;

#[derive(Debug, Args)]
pub struct StabilityArgs {
    #[command(flatten)]
    pub case: CaseArgs,
    /// Phase-lag ratio η_p = τ/Δt (pure actuator delay)
    #[arg(long, default_value_t = 0.0)]
    pub eta_p: f64,
    /// Phase-lag compensation with frozen parameters: `none`, `polynomial:ORDER` (ORDER 1..=3,
    /// lead η_p·k_sub sub-steps) or `arx` (the identified compensator at its defaults, frozen at
    /// the parameters it converges to in front of the delayed actuator)
    #[arg(long, default_value = "none")]
    pub phase_lag: String,
    /// The algorithm of the test: `substep` (the sub-step algorithm, Newmark average
    /// acceleration), `cr` or `kr_alpha[:RHO]` (explicit, K₀ = the numerical stiffness;
    /// docs/theory.md §2.9)
    #[arg(long, default_value = "substep")]
    pub scheme: String,
    /// Sub-steps per step, a list
    #[arg(long, default_value = "1,2,3,4,5")]
    pub k_sub: String,
    /// Ω = ωΔt grid a:b:n (inclusive)
    #[arg(long, default_value = "0.015708:3.141593:200")]
    pub omega: String,
    /// The y axis: name=a:b:n with name one of zeta_s, zeta, eta_f, eta_m, eta_p, stiffness_ratio
    /// (k_t/k₀ of a yielded or hardened numerical substructure under the operator splitting)
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

pub(super) fn stability(a: &StabilityArgs) -> Result<()> {
    let mut base = a.case.case()?;
    base.eta_p = a.eta_p;
    base.phase_lag = parse_phase_lag(&a.phase_lag)?;
    base.scheme = AnalysisScheme::from_name("--scheme", &a.scheme)?;
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

/// `none`, `polynomial:ORDER` or `arx`.
pub(super) fn parse_phase_lag(s: &str) -> Result<Option<FrozenPhaseLag>> {
    if s == "none" {
        return Ok(None);
    }
    if s == "arx" {
        return Ok(Some(FrozenPhaseLag::Arx));
    }
    match s.split_once(':') {
        Some(("polynomial", o)) => match o.trim().parse::<usize>() {
            Ok(order) if (1..=3).contains(&order) => Ok(Some(FrozenPhaseLag::Polynomial { order })),
            _ => bad!("--phase-lag", "the polynomial order must be 1, 2 or 3, got '{o}'"),
        },
        _ => bad!("--phase-lag", "expected none, polynomial:ORDER or arx, got '{s}'"),
    }
}

pub(super) fn describe_case(c: &AnalysisCase, varied: Parameter) -> String {
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
    if c.scheme != AnalysisScheme::SubStep {
        parts.push(c.scheme.label());
    }
    match c.phase_lag {
        Some(FrozenPhaseLag::Polynomial { order }) => parts.push(format!("polynomial p = {order} (frozen)")),
        Some(FrozenPhaseLag::Arx) => parts.push("ARX (frozen at its converged parameters)".into()),
        None => {}
    }
    parts.join(", ")
}
