//! `substep vst`: the virtual substructure test (VST) study of the dissertation's chapter 9.
//!
//! A 3-storey shear frame (3 × 1000 kg, first mode 1 Hz, 2 % modal damping) is the numerical
//! substructure; a TMD-like linear specimen (150 kg, tuned to 0.95 Hz, 10 % damping) on the top
//! floor is the experimental substructure, behind a servo-hydraulic actuator (second order,
//! 40 Hz, ζ = 0.7, plus a pure delay, 10 ms by default) with 1 % force noise (standard deviation
//! 1 % of the peak coupling force of the exact reference). Ground motion: a sine sweep.
//! `Δt = 0.01 s`, `k_sub = 4` (`Δτ = 2.5 ms`).
//!
//! Every method runs on the same set-up and noise sequence and is compared with the exact
//! solution of the assembled model (`assemble_monolithic` + `Scheme::Exact`, through
//! [`substep::io::Reference`]). The study writes `vst.md` (the table, generated here), `vst.csv`
//! and the plots.

use crate::plots::{Curve, line_chart};
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use substep::analysis::spectral::{averaged_amplitude_spectrum, band_coherence};
use substep::compensate::{ArxPhaseLagSpec, InverseFirSpec, PhaseLagDefinition, PhaseLagSpec, Ramp};
use substep::excitation::sine_sweep;
use substep::integrate::Scheme;
use substep::io::config::{GroundMotion, IntegratorDefinition, OutputSettings, SubstructureDefinition, TestDefinition};
use substep::io::{Reference, Simulation};
use substep::model::{DampingSpec, ShearBuilding, StructuralModel, shear_building};
use substep::monitor::{StabilityMonitor, StabilitySettings};
use substep::specimen::SpecimenSpec;
use substep::substructure::{ErrorForceSpec, SubstepObserver};
use substep::transfer::{ActuatorSpec, Dynamics, SensorSpec};

#[derive(Debug, Clone, clap::Args)]
pub struct VstArgs {
    /// Output directory
    #[arg(long, value_name = "DIR", default_value = "vst")]
    pub out: PathBuf,
    /// A shortened study (12 s instead of 60 s of ground motion)
    #[arg(long)]
    pub quick: bool,
    /// Pure delay of the actuator [s]
    #[arg(long, default_value_t = 0.010)]
    pub delay: f64,
    /// No PNG plots
    #[arg(long)]
    pub no_plots: bool,
    /// No progress output
    #[arg(long, short)]
    pub quiet: bool,
}

/// The set-up of the study.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VstSettings {
    /// Length of the sine sweep [s].
    pub duration: f64,
    /// Sweep range [Hz] and amplitude [m/s²].
    pub f0: f64,
    pub f1: f64,
    pub amplitude: f64,
    /// Pure delay of the actuator [s].
    pub delay: f64,
    /// Force noise as a fraction of the reference's peak coupling force.
    pub noise_ratio: f64,
    pub dt: f64,
    pub k_sub: usize,
    /// Phase-lag ramp-in [steps] (from t = 0).
    pub ramp_steps: usize,
    /// Statistics of tracking and error force from this time on [s] (after ramp-in and warm-up).
    pub settle: f64,
}

impl VstSettings {
    pub fn full(delay: f64) -> Self {
        Self {
            duration: 60.0,
            f0: 0.3,
            f1: 5.0,
            amplitude: 1.0,
            delay,
            noise_ratio: 0.01,
            dt: 0.01,
            k_sub: 4,
            ramp_steps: 100,
            settle: 2.0,
        }
    }
    pub fn quick(delay: f64) -> Self {
        Self {
            duration: 12.0,
            ..Self::full(delay)
        }
    }
    fn dtau(&self) -> f64 {
        self.dt / self.k_sub as f64
    }
    /// The actuator delay in sub-steps.
    fn delay_substeps(&self) -> f64 {
        self.delay / self.dtau()
    }
}

/// Actuator: second order 40 Hz, ζ = 0.7, plus the delay.
const ACTUATOR_HZ: f64 = 40.0;
const ACTUATOR_ZETA: f64 = 0.7;
/// Specimen: 150 kg TMD tuned to 0.95 Hz with 10 % damping.
const TMD_MASS: f64 = 150.0;
const TMD_HZ: f64 = 0.95;
const TMD_ZETA: f64 = 0.10;
/// Order of the error-force estimation in the main runs.
const MAIN_ORDER: usize = 4;
/// The orders of the n_u series.
pub const ORDERS: [usize; 6] = [2, 3, 4, 5, 8, 12];
/// Top floor (0-based), the coupling DOF.
const TOP: usize = 2;

/// Which compensation a run uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Method {
    pub key: &'static str,
    pub name: &'static str,
    pub error_force: ErrorForceSpec,
    pub phase_lag: Option<PhaseLagSpec>,
    /// Part of the n_u series (second table) rather than the main comparison.
    pub series: bool,
}

fn arx_ef(order: usize) -> ErrorForceSpec {
    ErrorForceSpec::Arx {
        order,
        lambda: 0.98,
        p0: 100.0,
    }
}

/// The methods of the study.
pub fn methods(s: &VstSettings) -> Vec<Method> {
    let lead = s.delay_substeps();
    let total_lag = (s.delay + 2.0 * ACTUATOR_ZETA / (2.0 * std::f64::consts::PI * ACTUATOR_HZ)) / s.dtau();
    let arx_pl = PhaseLagSpec::Arx(ArxPhaseLagSpec::new((lead.round() as usize).max(1)));
    let pid = ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 };
    let poly = |order, lead| PhaseLagSpec::Polynomial {
        order,
        lead,
        guard_factor: 10.0,
    };
    let m = |key, name, error_force, phase_lag| Method {
        key,
        name,
        error_force,
        phase_lag,
        series: false,
    };
    let mut v = vec![
        m("none", "(a) no compensation", ErrorForceSpec::None, None),
        m(
            "ef_arx",
            "(b) error force: estimation (ARX, n_u = 4)",
            arx_ef(MAIN_ORDER),
            None,
        ),
        m(
            "pl_arx",
            "(c) phase lag: identification (ARX)",
            ErrorForceSpec::None,
            Some(arx_pl),
        ),
        m("both", "(d) both: (b) + (c)", arx_ef(MAIN_ORDER), Some(arx_pl)),
        m("pid", "error force: PID P = 1", pid, None),
        m(
            "poly_delay",
            "phase lag: polynomial p = 3, lead = delay",
            ErrorForceSpec::None,
            Some(poly(3, lead)),
        ),
        m(
            "poly_lag",
            "phase lag: polynomial p = 2, lead = delay + 2ζ/ω_a",
            ErrorForceSpec::None,
            Some(poly(2, total_lag)),
        ),
        m(
            "inverse_fir",
            "phase lag: inverse FIR",
            ErrorForceSpec::None,
            Some(PhaseLagSpec::InverseFir(InverseFirSpec::new(lead))),
        ),
        m("pid_pl_arx", "PID P = 1 + (c)", pid, Some(arx_pl)),
    ];
    const SERIES_KEYS: [&str; 6] = ["ef_arx_2", "ef_arx_3", "ef_arx_4", "ef_arx_5", "ef_arx_8", "ef_arx_12"];
    const SERIES_NAMES: [&str; 6] = [
        "estimation n_u = 2",
        "estimation n_u = 3",
        "estimation n_u = 4",
        "estimation n_u = 5",
        "estimation n_u = 8",
        "estimation n_u = 12",
    ];
    for (k, &n) in ORDERS.iter().enumerate() {
        v.push(Method {
            key: SERIES_KEYS[k],
            name: SERIES_NAMES[k],
            error_force: arx_ef(n),
            phase_lag: None,
            series: true,
        });
    }
    v
}

/// The numerical substructure: 3 floors × 1000 kg, first period 1 s, 2 % modal damping.
fn structure() -> Result<StructuralModel> {
    let b = ShearBuilding {
        stories: 3,
        story_mass: 1000.0,
        first_period: 1.0,
    };
    Ok(shear_building(&b)?.with_damping(&DampingSpec::Modal { zeta: vec![0.02] })?)
}

fn specimen() -> SpecimenSpec {
    let w = 2.0 * std::f64::consts::PI * TMD_HZ;
    SpecimenSpec::LinearSdof {
        dof: TOP,
        mass: Some(TMD_MASS),
        stiffness: TMD_MASS * w * w,
        damping: 2.0 * TMD_ZETA * TMD_MASS * w,
    }
}

/// The test definition of one run (force noise `sigma` [N]).
fn definition(s: &VstSettings, sigma: f64, method: &Method) -> Result<TestDefinition> {
    let record = sine_sweep(s.amplitude, s.f0, s.f1, s.duration, s.dt)?;
    let steps = record.accel.len() - 1;
    let (beta, gamma) = (0.25, 0.5);
    let substructure = SubstructureDefinition {
        coupling_dofs: vec![TOP],
        substeps: s.k_sub,
        inner_steps: 10,
        specimens: vec![specimen()],
        actuator: ActuatorSpec {
            dynamics: Dynamics::SecondOrder {
                frequency_hz: ACTUATOR_HZ,
                zeta: ACTUATOR_ZETA,
            },
            delay: s.delay,
        },
        force_sensors: vec![SensorSpec {
            noise_std: sigma,
            seed: 11,
            ..SensorSpec::ideal()
        }],
        displacement_sensors: vec![SensorSpec::ideal()],
        error_force: method.error_force,
        beta,
        gamma,
        phase_lag: method.phase_lag.map(|spec| PhaseLagDefinition {
            spec,
            ramp: Ramp::new(0, s.ramp_steps * s.k_sub),
        }),
        remote: None,
        limits: None,
        lab: Default::default(),
        controller: None,
        controller_feedforward: None,
        delay_ramp: None,
    };
    Ok(TestDefinition {
        source: format!("vst: {}", method.name),
        model: structure()?.into(),
        ground_motion: GroundMotion {
            accel: record.accel,
            description: format!(
                "linear sine sweep {}–{} Hz, {} m/s², {} s",
                s.f0, s.f1, s.amplitude, s.duration
            ),
        },
        integrator: IntegratorDefinition {
            name: "average_acceleration".into(),
            scheme: Scheme::Newmark { beta, gamma },
            dt: s.dt,
            steps,
        },
        substructure: Some(substructure),
        output: OutputSettings {
            dir: None,
            plots: false,
            plot_options: Default::default(),
        },
    })
}

/// Per-step series of a run (or of the reference).
#[derive(Debug, Clone, Default)]
pub struct Series {
    pub t: Vec<f64>,
    /// Top-floor displacement [m].
    pub u: Vec<f64>,
    /// Noise-free coupling force at the step's end [N].
    pub f_true: Vec<f64>,
    /// Measured coupling force [N].
    pub f_meas: Vec<f64>,
    /// Measured coupling displacement [m].
    pub d_meas: Vec<f64>,
    /// Error force e, compensation force f_u and the ideal value of e [N].
    pub e: Vec<f64>,
    pub fu: Vec<f64>,
    pub ideal: Vec<f64>,
    /// The force the step was closed with (`f^(k−1)` or the estimate `f̂^(k)`) [N].
    pub closing: Vec<f64>,
    /// Tracking error of the last sub-step [m].
    pub tracking: Vec<f64>,
}

/// Error statistics of one run against the reference.
#[derive(Debug, Clone)]
pub struct RunResult {
    pub method: Method,
    pub completed: bool,
    /// Normalised by the reference peaks: RMS and peak error of the top-floor displacement and
    /// of the (noise-free) coupling force; the same for the measured force.
    pub disp_rms: f64,
    pub disp_peak: f64,
    pub force_rms: f64,
    pub force_peak: f64,
    pub force_meas_rms: f64,
    /// RMS of `d_target − y_true` over all sub-steps after `settle` [m].
    pub tracking_rms: f64,
    /// RMS of the error force `e` and of its ideal value after `settle` [N].
    pub e_rms: f64,
    pub ideal_rms: f64,
    /// RMS of the true equilibrium error `f°^(k) − f_close` after `settle` [N]: how far the force
    /// the step was closed with is from the true force at the step's end.
    pub equilibrium_rms: f64,
    /// RMS of `e − ideal` [N] and the coherence of `e` and its ideal value over the sweep's band
    /// (with P = 1 and the estimation `e` is the compensation force `f_u`).
    pub diff_rms: f64,
    pub coherence: f64,
    /// Estimation: steps closed with the estimate / steps.
    pub estimated: Option<(u64, u64)>,
    /// Guard warnings.
    pub warnings: Vec<String>,
    /// The on-line stability indicator's alarm, if it raised one (docs/monitor.md).
    pub stability_alarm: Option<String>,
    /// Largest energy ratio η of the indicator over the run.
    pub max_eta: f64,
    pub series: Series,
}

/// The whole study.
pub struct Study {
    pub settings: VstSettings,
    /// Force noise [N] and the reference peaks.
    pub sigma: f64,
    pub ref_peak_u: f64,
    pub ref_peak_f: f64,
    pub reference: Series,
    pub runs: Vec<RunResult>,
}

impl Study {
    pub fn run(&self, key: &str) -> &RunResult {
        self.runs
            .iter()
            .find(|r| r.method.key == key)
            .unwrap_or_else(|| panic!("no run {key}"))
    }
}

/// Sub-step tracking statistics.
struct Tracking {
    dt: f64,
    from: f64,
    sum: f64,
    count: usize,
    last: f64,
    last_command: f64,
}

impl SubstepObserver for Tracking {
    fn substep(&mut self, step: usize, _j: usize, command: &[f64], _force: &[f64], displacement: &[f64]) {
        // The displacement sensor is ideal: measured = achieved (y_true).
        let e = command[0] - displacement[0];
        self.last = e;
        self.last_command = command[0];
        if step as f64 * self.dt > self.from {
            self.sum += e * e;
            self.count += 1;
        }
    }
}

/// The exact reference: peaks and series.
fn reference_run(s: &VstSettings) -> Result<Series> {
    let def = definition(s, 0.0, &methods(s)[0])?;
    let mut r = Reference::new(&def)?.context("the VST specimen is linear, a reference exists")?;
    let mut out = Series::default();
    let n = def.ground_motion.accel.len();
    out.t.push(0.0);
    out.u.push(0.0);
    out.f_true.push(0.0);
    out.d_meas.push(0.0);
    for i in 1..n {
        r.step(def.ground_motion.accel[i]);
        out.t.push(i as f64 * s.dt);
        out.u.push(r.u()[TOP]);
        out.f_true.push(r.coupling_force()[0]);
        out.d_meas.push(r.u()[TOP]);
    }
    Ok(out)
}

fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

fn one_run(s: &VstSettings, sigma: f64, method: &Method, reference: &Series) -> Result<RunResult> {
    let def = definition(s, sigma, method)?;
    let mut sim = Simulation::new(&def)?;
    let mut track = Tracking {
        dt: s.dt,
        from: s.settle,
        sum: 0.0,
        count: 0,
        last: 0.0,
        last_command: 0.0,
    };
    // The on-line stability indicator watches every run (it must stay quiet on all of them).
    let mut stability = StabilityMonitor::new(
        def.substructure.as_ref().expect("substructured"),
        &def.model,
        s.dt,
        StabilitySettings::default(),
    )?;
    let mut max_eta = f64::NAN;
    let mut ser = Series::default();
    let push = |ser: &mut Series, sim: &Simulation, te: f64| {
        let test = sim.substructure_test().expect("substructured");
        let c = &test.controller;
        ser.t.push(sim.time());
        ser.u.push(c.state().u[TOP]);
        ser.f_true.push(test.site.true_force().map_or(f64::NAN, |f| f[0]));
        ser.f_meas.push(c.coupling_force()[0]);
        ser.d_meas
            .push(sim.coupling().map_or(0.0, |r| r.measured_displacement[0]));
        ser.e.push(c.error_force()[0]);
        ser.fu.push(c.compensation_force()[0]);
        ser.ideal.push(c.ideal_error_force().map_or(0.0, |v| v[0]));
        ser.closing.push(c.closing_force()[0]);
        ser.tracking.push(te);
    };
    push(&mut ser, &sim, 0.0);
    let mut completed = true;
    while sim.steps_done() < sim.steps_total() {
        if sim.step(&mut track).is_err() {
            completed = false;
            break;
        }
        push(&mut ser, &sim, track.last);
        if let Some(rec) = sim.coupling() {
            let i = sim.steps_done();
            let st = sim.state();
            stability.push(
                i,
                st.u.as_slice(),
                st.v.as_slice(),
                def.ground_motion.accel[i],
                rec.coupling_force,
                &[track.last_command],
                rec.measured_displacement,
            );
            if stability.eta().is_finite() {
                max_eta = if max_eta.is_nan() {
                    stability.eta()
                } else {
                    max_eta.max(stability.eta())
                };
            }
        }
    }
    let n = ser.t.len();
    let err = |x: &[f64], r: &[f64]| -> (f64, f64) {
        let peak = r[..n].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let d: Vec<f64> = x.iter().zip(r).map(|(a, b)| a - b).collect();
        let max = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        (rms(&d) / peak, max / peak)
    };
    let (disp_rms, disp_peak) = err(&ser.u, &reference.u);
    let (force_rms, force_peak) = err(&ser.f_true, &reference.f_true);
    let (force_meas_rms, _) = err(&ser.f_meas, &reference.f_true);
    let from = ((s.settle / s.dt).ceil() as usize).min(n);
    let (fu, ideal) = (&ser.e[from..], &ser.ideal[from..]);
    let diff: Vec<f64> = fu.iter().zip(ideal).map(|(a, b)| a - b).collect();
    let test = sim.substructure_test().expect("substructured");
    let mut warnings = Vec::new();
    if let Some(p) = test.site.phase_lag() {
        for (i, t) in p.trips() {
            warnings.push(format!("{}: phase-lag compensator {} disabled: {t}", method.key, i + 1));
        }
    }
    let has_compensation = method.error_force != ErrorForceSpec::None;
    Ok(RunResult {
        method: *method,
        completed,
        disp_rms,
        disp_peak,
        force_rms,
        force_peak,
        force_meas_rms,
        tracking_rms: (track.sum / track.count.max(1) as f64).sqrt(),
        e_rms: rms(&ser.e[from..]),
        equilibrium_rms: rms(&ser.f_true[from..]
            .iter()
            .zip(&ser.closing[from..])
            .map(|(t, c)| t - c)
            .collect::<Vec<_>>()),
        ideal_rms: rms(ideal),
        diff_rms: if has_compensation { rms(&diff) } else { f64::NAN },
        coherence: if has_compensation {
            band_coherence(fu, ideal, s.dt, 512, s.f0, s.f1)
        } else {
            f64::NAN
        },
        estimated: test.controller.estimation_stats().map(|st| (st.estimated, st.steps)),
        warnings,
        stability_alarm: stability.alarm().map(|a| a.message()),
        max_eta,
        series: ser,
    })
}

/// Run the study: the reference, then every method (in parallel).
pub fn run_study(s: &VstSettings) -> Result<Study> {
    use rayon::prelude::*;
    let reference = reference_run(s)?;
    let ref_peak_u = reference.u.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let ref_peak_f = reference.f_true.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let sigma = s.noise_ratio * ref_peak_f;
    let runs = methods(s)
        .par_iter()
        .map(|m| one_run(s, sigma, m, &reference))
        .collect::<Result<Vec<_>>>()?;
    Ok(Study {
        settings: *s,
        sigma,
        ref_peak_u,
        ref_peak_f,
        reference,
        runs,
    })
}

// ---------------------------------------------------------------------------------------------
// Outputs: the table (Markdown + CSV), the acceptance checks, the plots.

fn pct(x: f64) -> String {
    if x.is_finite() {
        format!("{:.2}", 100.0 * x)
    } else {
        "–".into()
    }
}
fn num(x: f64, digits: usize) -> String {
    if x.is_finite() {
        format!("{x:.digits$}")
    } else {
        "–".into()
    }
}

/// The acceptance checks of the issue, computed from the study: `(statement, holds)`.
pub fn acceptance(st: &Study) -> Vec<(String, bool)> {
    let mut out = Vec::new();
    let (none, pl, both, pid) = (st.run("none"), st.run("pl_arx"), st.run("both"), st.run("pid"));
    let (poly, poly_lag) = (st.run("poly_delay"), st.run("poly_lag"));
    let red = none.tracking_rms / pl.tracking_rms;
    out.push((
        format!(
            "phase-lag identification reduces the RMS tracking error after ramp-in {red:.1}× against no compensation ({:.1} µm → {:.2} µm; required ≥ 5×)",
            1e6 * none.tracking_rms,
            1e6 * pl.tracking_rms
        ),
        red >= 5.0,
    ));
    out.push((
        format!(
            "it beats polynomial extrapolation with the lead = the actuator delay (the config default): {:.2} µm vs {:.2} µm ({:.1}×)",
            1e6 * pl.tracking_rms,
            1e6 * poly.tracking_rms,
            poly.tracking_rms / pl.tracking_rms
        ),
        pl.tracking_rms < poly.tracking_rms,
    ));
    out.push((
        format!(
            "it beats polynomial extrapolation with the lead tuned to delay + 2ζ/ω_a in tracking: {:.2} µm vs {:.2} µm",
            1e6 * pl.tracking_rms,
            1e6 * poly_lag.tracking_rms
        ),
        pl.tracking_rms < poly_lag.tracking_rms,
    ));
    out.push((
        format!(
            "… and in the coupling force (RMS error {} % vs {} %)",
            pct(pl.force_rms),
            pct(poly_lag.force_rms)
        ),
        pl.force_rms < poly_lag.force_rms,
    ));
    for r in st.runs.iter().filter(|r| r.method.series) {
        out.push((
            format!(
                "{}: residual error force RMS {:.2} N < PID P = 1 {:.2} N (true equilibrium error {:.2} N vs {:.2} N); RMS(e − e°) = {:.2} σ (PID {:.2} σ), coherence with e° {:.2} (PID {:.2})",
                r.method.name,
                r.e_rms,
                pid.e_rms,
                r.equilibrium_rms,
                pid.equilibrium_rms,
                r.diff_rms / st.sigma,
                pid.diff_rms / st.sigma,
                r.coherence,
                pid.coherence
            ),
            r.e_rms < pid.e_rms,
        ));
    }
    let singles: Vec<&RunResult> = st
        .runs
        .iter()
        .filter(|r| !r.method.series && !matches!(r.method.key, "both" | "pid_pl_arx"))
        .collect();
    let best = singles
        .iter()
        .min_by(|a, b| a.force_rms.total_cmp(&b.force_rms))
        .expect("runs");
    let best_peak = singles
        .iter()
        .min_by(|a, b| a.force_peak.total_cmp(&b.force_peak))
        .expect("runs");
    out.push((
        format!(
            "with both compensations the coupling force matches the reference better than every single method: RMS error {} % vs best single {} ({} %)",
            pct(both.force_rms),
            best.method.key,
            pct(best.force_rms)
        ),
        both.force_rms < best.force_rms,
    ));
    out.push((
        format!(
            "… and in the peak error: {} % vs best single {} ({} %)",
            pct(both.force_peak),
            best_peak.method.key,
            pct(best_peak.force_peak)
        ),
        both.force_peak < best_peak.force_peak,
    ));
    let alarms: Vec<&str> = st
        .runs
        .iter()
        .filter(|r| r.stability_alarm.is_some())
        .map(|r| r.method.key)
        .collect();
    let max_eta = st
        .runs
        .iter()
        .map(|r| r.max_eta)
        .filter(|e| e.is_finite())
        .fold(0.0f64, f64::max);
    out.push((
        format!(
            "the on-line stability indicator raises no alarm on any method (largest energy ratio η = {max_eta:.2}; alarms: {})",
            if alarms.is_empty() { "none".to_string() } else { alarms.join(", ") }
        ),
        alarms.is_empty(),
    ));
    out
}

/// `vst.md`: set-up, the tables and the acceptance checks.
pub fn markdown(st: &Study) -> String {
    let s = &st.settings;
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# VST study (generated by `substep vst{}`)\n",
        if s.duration < 60.0 { " --quick" } else { "" }
    );
    let _ = writeln!(
        md,
        "Numerical substructure: 3-storey shear frame, 3 × 1000 kg, first mode 1 Hz, 2 % modal damping. \
         Specimen on the top floor: TMD {TMD_MASS} kg tuned to {TMD_HZ} Hz, ζ_s = {TMD_ZETA}. \
         Actuator: second order {ACTUATOR_HZ} Hz, ζ = {ACTUATOR_ZETA}, pure delay {} ms. \
         Δt = {} s, k_sub = {} (Δτ = {} ms), 10 inner steps. Ground motion: sine sweep {}–{} Hz, {} m/s², {} s. \
         Force noise σ = {:.2} N ({} % of the reference peak coupling force {:.1} N); ideal displacement sensor. \
         Reference: the assembled model integrated exactly (peak top-floor displacement {:.4} m). Phase-lag ramp-in over the first {} steps; \
         tracking and error-force statistics from t = {} s.\n",
        1e3 * s.delay,
        s.dt,
        s.k_sub,
        1e3 * s.dtau(),
        s.f0,
        s.f1,
        s.amplitude,
        s.duration,
        st.sigma,
        100.0 * s.noise_ratio,
        st.ref_peak_f,
        st.ref_peak_u,
        s.ramp_steps,
        s.settle
    );
    md.push_str(
        "Columns: errors of the top-floor displacement `u` and of the noise-free coupling force `f` against the reference, \
         normalised by the reference peaks (RMS over the run and peak); `f meas.`: the same for the measured force (includes the noise); \
         tracking: RMS of `d − y` (target command minus achieved displacement) over all sub-steps; \
         `e`: error force (for P = 1 and the estimation also the compensation force), `e°` its ideal (noise-free) value; \
         coherence of `e` and `e°` over the sweep band (Welch, 5.12 s segments); \
         `f° − f_close`: the true equilibrium error of a step, the noise-free force at its end minus the force it was closed with \
         (`f^(k−1)` measured, or the estimate `f̂^(k)`).\n\n",
    );
    md.push_str("| run | u RMS % | u peak % | f RMS % | f peak % | f meas. RMS % | tracking RMS [µm] | tracking vs (a) | e RMS [N] | e° RMS [N] | RMS(e − e°)/σ | coherence | f° − f_close RMS [N] | estimated steps |\n");
    md.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    let none_track = st.run("none").tracking_rms;
    for r in st.runs.iter().filter(|r| !r.method.series) {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {}× | {} | {} | {} | {} | {} | {} |",
            r.method.name,
            pct(r.disp_rms),
            pct(r.disp_peak),
            pct(r.force_rms),
            pct(r.force_peak),
            pct(r.force_meas_rms),
            num(1e6 * r.tracking_rms, 2),
            num(none_track / r.tracking_rms, 1),
            num(r.e_rms, 2),
            num(r.ideal_rms, 2),
            num(r.diff_rms / st.sigma, 2),
            num(r.coherence, 2),
            num(r.equilibrium_rms, 2),
            r.estimated.map_or("–".into(), |(a, b)| format!("{a}/{b}")),
        );
    }
    md.push_str("\n## Error-force estimation: orders n_u (no phase-lag compensation)\n\n");
    md.push_str("| run | e RMS [N] | e RMS vs PID P = 1 | e° RMS [N] | RMS(e − e°)/σ | coherence | f° − f_close RMS [N] | estimated steps | f RMS % |\n|---|---|---|---|---|---|---|---|---|\n");
    let pid = st.run("pid");
    for r in std::iter::once(pid).chain(st.runs.iter().filter(|r| r.method.series)) {
        let _ = writeln!(
            md,
            "| {} | {} | {} % | {} | {} | {} | {} | {} | {} |",
            r.method.name,
            num(r.e_rms, 2),
            num(100.0 * r.e_rms / pid.e_rms, 0),
            num(r.ideal_rms, 2),
            num(r.diff_rms / st.sigma, 2),
            num(r.coherence, 2),
            num(r.equilibrium_rms, 2),
            r.estimated.map_or("–".into(), |(a, b)| format!("{a}/{b}")),
            pct(r.force_rms),
        );
    }
    md.push_str("\n## Acceptance checks (computed by the tool)\n\n");
    for (text, ok) in acceptance(st) {
        let _ = writeln!(md, "* {} — {}", if ok { "holds" } else { "**does not hold**" }, text);
    }
    let warnings: Vec<&String> = st.runs.iter().flat_map(|r| &r.warnings).collect();
    if !warnings.is_empty() {
        md.push_str("\n## Warnings\n\n");
        for w in warnings {
            let _ = writeln!(md, "* {w}");
        }
    }
    md
}

/// `vst.csv`: one row per run.
pub fn csv(st: &Study) -> String {
    let mut out = String::from(
        "key,name,completed,u_rms,u_peak,f_rms,f_peak,f_meas_rms,tracking_rms_m,e_rms_n,ideal_rms_n,diff_rms_n,coherence,equilibrium_rms_n,estimated,steps\n",
    );
    for r in &st.runs {
        let (e, n) = r
            .estimated
            .map_or((String::new(), String::new()), |(a, b)| (a.to_string(), b.to_string()));
        let _ = writeln!(
            out,
            "{},\"{}\",{},{},{},{},{},{},{},{},{},{},{},{},{e},{n}",
            r.method.key,
            r.method.name,
            r.completed,
            r.disp_rms,
            r.disp_peak,
            r.force_rms,
            r.force_peak,
            r.force_meas_rms,
            r.tracking_rms,
            r.e_rms,
            r.ideal_rms,
            r.diff_rms,
            r.coherence,
            r.equilibrium_rms
        );
    }
    out
}

fn window(t: &[f64], y: &[f64], t0: f64, t1: f64) -> (Vec<f64>, Vec<f64>) {
    t.iter()
        .zip(y)
        .filter(|(t, _)| **t >= t0 && **t <= t1)
        .map(|(a, b)| (*a, *b))
        .unzip()
}

/// The plots; returns the files written.
pub fn plots(st: &Study, dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    let r = &st.reference;
    let s = &st.settings;
    let curve = |label: &str, x: &[f64], y: &[f64]| Curve {
        label: label.into(),
        x: x.to_vec(),
        y: y.to_vec(),
    };
    let runs = ["none", "ef_arx", "pl_arx", "both"];
    let mut chart = |file: &str, title: &str, xl: &str, yl: &str, curves: Vec<Curve>| -> Result<()> {
        let path = dir.join(file);
        line_chart(&path, title, xl, yl, &curves)?;
        files.push(path);
        Ok(())
    };
    // Time histories against the reference, in a window around the first-mode resonance.
    let (t0, t1) = if s.duration >= 60.0 { (6.0, 14.0) } else { (2.0, 6.0) };
    let mut c = vec![{
        let (x, y) = window(&r.t, &r.u, t0, t1);
        curve("reference (exact)", &x, &y)
    }];
    for key in ["none", "both"] {
        let run = st.run(key);
        let (x, y) = window(&run.series.t, &run.series.u, t0, t1);
        c.push(curve(run.method.name, &x, &y));
    }
    chart(
        "vst_displacement.png",
        "Top-floor displacement against the reference",
        "time t [s]",
        "u_3 [m]",
        c,
    )?;
    let mut c = vec![{
        let (x, y) = window(&r.t, &r.f_true, t0, t1);
        curve("reference (exact)", &x, &y)
    }];
    for key in ["none", "both"] {
        let run = st.run(key);
        let (x, y) = window(&run.series.t, &run.series.f_true, t0, t1);
        c.push(curve(run.method.name, &x, &y));
    }
    chart(
        "vst_force.png",
        "Coupling force (noise-free) against the reference",
        "time t [s]",
        "f_c [N]",
        c,
    )?;
    // Errors over the whole run.
    let c = runs
        .iter()
        .chain(["poly_delay"].iter())
        .map(|key| {
            let run = st.run(key);
            let e: Vec<f64> = run.series.f_true.iter().zip(&r.f_true).map(|(a, b)| a - b).collect();
            curve(run.method.name, &run.series.t, &e)
        })
        .collect();
    chart(
        "vst_force_error.png",
        "Coupling-force error against the reference",
        "time t [s]",
        "f_c − f_ref [N]",
        c,
    )?;
    // Hysteresis loops.
    let mut c = vec![{
        let (_, x) = window(&r.t, &r.d_meas, t0, t1);
        let (_, y) = window(&r.t, &r.f_true, t0, t1);
        curve("reference (exact)", &x, &y)
    }];
    for key in ["none", "both"] {
        let run = st.run(key);
        let (_, x) = window(&run.series.t, &run.series.d_meas, t0, t1);
        let (_, y) = window(&run.series.t, &run.series.f_true, t0, t1);
        c.push(curve(run.method.name, &x, &y));
    }
    chart(
        "vst_hysteresis.png",
        "Coupling force vs coupling displacement",
        "displacement [m]",
        "f_c [N]",
        c,
    )?;
    // Tracking error.
    let c = ["none", "poly_delay", "inverse_fir", "pl_arx"]
        .iter()
        .map(|key| {
            let run = st.run(key);
            curve(run.method.name, &run.series.t, &run.series.tracking)
        })
        .collect();
    chart(
        "vst_tracking.png",
        "Actuator tracking error d − y (last sub-step of each step)",
        "time t [s]",
        "tracking error [m]",
        c,
    )?;
    // Compensation force of the estimation vs its ideal value vs the noise.
    let b = st.run("ef_arx");
    let noise: Vec<f64> = b
        .series
        .f_meas
        .iter()
        .zip(&b.series.f_true)
        .map(|(m, t)| m - t)
        .collect();
    let (w0, w1) = (t0, t0 + 2.0);
    let c = vec![
        {
            let (x, y) = window(&b.series.t, &b.series.fu, w0, w1);
            curve("f_u (estimation, n_u = 4)", &x, &y)
        },
        {
            let (x, y) = window(&b.series.t, &b.series.ideal, w0, w1);
            curve("ideal value (noise-free)", &x, &y)
        },
        {
            let (x, y) = window(&b.series.t, &noise, w0, w1);
            curve("force noise", &x, &y)
        },
    ];
    chart(
        "vst_compensation.png",
        "Compensation force of the estimation, its ideal value and the noise",
        "time t [s]",
        "force [N]",
        c,
    )?;
    let from = ((s.settle / s.dt).ceil() as usize).min(b.series.t.len());
    let pid = st.run("pid");
    let spec = |y: &[f64]| averaged_amplitude_spectrum(&y[from..], s.dt, 512, 10.0);
    let mut c = Vec::new();
    for (label, y) in [
        ("f_u (estimation, n_u = 4)", &b.series.fu),
        ("ideal value of f_u (estimation)", &b.series.ideal),
        ("force noise", &noise),
        ("f_u (PID P = 1)", &pid.series.fu),
    ] {
        let (f, a) = spec(y);
        c.push(curve(label, &f, &a));
    }
    chart(
        "vst_compensation_spectrum.png",
        "Amplitude spectra (Welch, 5.12 s segments): compensation force, its ideal value, the noise",
        "frequency [Hz]",
        "amplitude [N]",
        c,
    )?;
    Ok(files)
}

pub fn vst(args: &VstArgs) -> Result<()> {
    if !(args.delay.is_finite() && args.delay >= 0.0 && args.delay <= 0.1) {
        return Err(substep::Error::invalid("--delay", format!("must be in [0, 0.1] s, got {}", args.delay)).into());
    }
    let settings = if args.quick {
        VstSettings::quick(args.delay)
    } else {
        VstSettings::full(args.delay)
    };
    if !args.quiet {
        println!(
            "substep vst: {} runs of {} s each (3-storey frame, TMD specimen, actuator delay {} ms, 1 % force noise) …",
            methods(&settings).len(),
            settings.duration,
            1e3 * settings.delay
        );
    }
    let t0 = std::time::Instant::now();
    let study = run_study(&settings)?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let write = |name: &str, text: &str| -> Result<PathBuf> {
        let path = args.out.join(name);
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
        Ok(path)
    };
    let md = markdown(&study);
    let mut files = vec![write("vst.md", &md)?, write("vst.csv", &csv(&study))?];
    if !args.no_plots {
        files.extend(plots(&study, &args.out)?);
    }
    if !args.quiet {
        println!("{md}");
        println!(
            "done in {:.1} s; wrote {}",
            t0.elapsed().as_secs_f64(),
            files
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The acceptance lines on the shortened study (12 s sweep, 10 ms delay, 1 % noise).
    #[test]
    fn quick_study_meets_the_acceptance_lines() {
        let st = run_study(&VstSettings::quick(0.010)).unwrap();
        println!("{}", markdown(&st));
        assert!(st.runs.iter().all(|r| r.completed && r.warnings.is_empty()));
        // The on-line stability indicator raises no alarm on any method of the study.
        for r in &st.runs {
            println!("{}: stability indicator max η = {:.3}", r.method.key, r.max_eta);
            assert!(r.stability_alarm.is_none(), "{}: {:?}", r.method.key, r.stability_alarm);
        }
        let (none, pl, both, pid) = (st.run("none"), st.run("pl_arx"), st.run("both"), st.run("pid"));
        // 1. Phase-lag identification: ≥ 5× less tracking error than none after ramp-in, and
        //    better than polynomial extrapolation with the lead = the delay (the default). Against
        //    a polynomial whose lead is tuned to the actuator's total lag it tracks worse but gives
        //    the smaller coupling-force error (see docs/vst.md).
        assert!(none.tracking_rms > 5.0 * pl.tracking_rms);
        assert!(pl.tracking_rms < st.run("poly_delay").tracking_rms);
        assert!(pl.force_rms < st.run("poly_lag").force_rms);
        // 2. Error-force estimation: lower residual error force than PID P = 1, and closer to its
        //    ideal value, for every order.
        for r in st.runs.iter().filter(|r| r.method.series) {
            assert!(
                r.e_rms < 0.9 * pid.e_rms,
                "{}: {} vs {}",
                r.method.name,
                r.e_rms,
                pid.e_rms
            );
            assert!(r.diff_rms < pid.diff_rms, "{}", r.method.name);
            assert!(r.diff_rms < 1.2 * st.sigma, "{}", r.method.name);
            // The force the step is closed with is closer to the true force than f^(k−1).
            assert!(r.equilibrium_rms < 0.8 * pid.equilibrium_rms, "{}", r.method.name);
            let (est, steps) = r.estimated.unwrap();
            assert!(est as f64 > 0.9 * steps as f64, "{}", r.method.name);
        }
        // 3. Both compensations: the coupling force matches the reference better than every
        //    single method, in RMS and in peak error.
        for r in st
            .runs
            .iter()
            .filter(|r| !r.method.series && !matches!(r.method.key, "both" | "pid_pl_arx"))
        {
            assert!(both.force_rms < r.force_rms, "{}", r.method.key);
            assert!(both.force_peak < r.force_peak, "{}", r.method.key);
        }
        let checks = acceptance(&st);
        assert_eq!(checks.iter().filter(|(_, ok)| !ok).count(), 1, "{checks:?}");
    }

    #[test]
    fn methods_are_distinct_and_complete() {
        let m = methods(&VstSettings::quick(0.010));
        let mut keys: Vec<&str> = m.iter().map(|m| m.key).collect();
        keys.sort();
        keys.dedup();
        assert_eq!(keys.len(), m.len());
        for key in ["none", "ef_arx", "pl_arx", "both", "pid", "poly_delay", "inverse_fir"] {
            assert!(keys.contains(&key), "{key}");
        }
        assert_eq!(m.iter().filter(|m| m.series).count(), ORDERS.len());
    }
}
