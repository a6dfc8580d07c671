//! The test planner: which `Δt`, `k_sub` and compensation for *this* test, within *this* PC's
//! real-time budget.
//!
//! For every scanned setting `(Δt, k_sub, τ)` the complete algorithm of the test definition
//! (controller, actuator model with delay `τ`, specimens, error-force compensation, phase-lag
//! compensation) is probed into its one-step map ([`StepMap`]); noise and quantisation are
//! switched off (they do not change the linear map). Phase-lag compensation is analysed
//! **frozen**: a polynomial or inverse-FIR compensator with the lead of the scanned delay
//! (`lead = τ/Δτ` sub-steps, the config's default), an ARX compensator with `k_lag = round(τ/Δτ)`,
//! each at its starting parameters and fully ramped in (`h = 1`), i.e. the compensator as a fixed
//! linear filter. The results per setting:
//!
//! * the spectral radius `ρ` and the stability margin `1 − ρ`;
//! * the peaks of the discrete frequency response of the first coupling DOF to `a_g`, against the
//!   peaks of the continuous assembled system: amplitude error `h/h_exact − 1` and period error
//!   `f_exact/f − 1`; the setting's error is the largest of their magnitudes;
//! * a split of that error into its sources, by evaluating two more models at the same `Δt`:
//!   monolithic Newmark of the assembled system (**Δt**: integration error alone), and the
//!   sub-step algorithm with an ideal actuator without delay (its difference to Newmark is the
//!   **sub-stepping** error); what the actuator adds on top of that (delay and dynamics, net of
//!   phase-lag compensation) is the **delay** error. Each source's size is the largest change it
//!   makes to any peak's amplitude or period error;
//! * the measured computing cost per step (the test stepped `cost_steps` times on this PC) and
//!   its share of the real-time budget `Δt`.
//!
//! What is shared between grid points is computed once: the exact peaks (per model), the
//! Newmark peaks (per `Δt`) and the delay-free algorithm (per `(Δt, k_sub)`). Frequency
//! responses use [`FrequencyResponse`] (one Hessenberg reduction per map, `O(n²)` per frequency).
//!
//! The recommendation: among the settings with `ρ ≤ 1 − min_margin` whose cost fits the budget
//! (`cost ≤ budget · Δt`), those with an error `≤ tolerance`; of these the one with the smallest
//! share of the budget (the cheapest that is accurate enough), ties broken by the larger margin.
//! If none is accurate enough, the most accurate feasible one, and the advice names the dominant
//! error source and its remedy.

use super::converged::converged_parameters;
use super::frequency::{Peak, continuous_response, find_peaks};
use super::{FrequencyResponse, StepMap};
use crate::compensate::{AmbSpec, ArxPhaseLagSpec, AtsSpec, PhaseLagDefinition, PhaseLagSpec, Ramp};
use crate::error::{Error, Result};
use crate::io::SubstructureDefinition;
use crate::model::StructuralModel;
use crate::specimen::assemble_monolithic;
use crate::substructure::ErrorForceSpec;
use crate::transfer::{ActuatorSpec, SensorSpec};
use nalgebra::{Complex, DMatrix, DVector};
use rayon::prelude::*;
use std::f64::consts::PI;
use std::time::Instant;

/// Samples of the frequency grid on which peaks are searched (then refined).
const PEAK_SAMPLES: usize = 300;

/// What the planner scans and how it weighs the results.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanSettings {
    pub dts: Vec<f64>,
    pub k_subs: Vec<usize>,
    pub delays: Vec<f64>,
    /// Accepted peak error (amplitude or period), e.g. 0.02.
    pub tolerance: f64,
    /// Required stability margin `1 − ρ`.
    pub min_margin: f64,
    /// Share of `Δt` the computation may use (the rest is I/O and the actuator controller).
    pub budget: f64,
    /// Steps timed per setting for the cost (0: no timing, cost 0).
    pub cost_steps: usize,
}

/// Which part of the algorithm causes an error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorSource {
    TimeStep,
    SubStepping,
    Delay,
}

impl ErrorSource {
    pub fn name(self) -> &'static str {
        match self {
            ErrorSource::TimeStep => "time step Δt",
            ErrorSource::SubStepping => "sub-stepping",
            ErrorSource::Delay => "actuator delay/lag",
        }
    }
}

/// One peak of the algorithm's response against the exact one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeakComparison {
    pub freq_hz: f64,
    pub freq_hz_exact: f64,
    pub amplitude_error: f64,
    pub period_error: f64,
}

/// One scanned setting.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanPoint {
    pub dt: f64,
    pub k_sub: usize,
    pub delay: f64,
    pub rho: f64,
    pub peaks: Vec<PeakComparison>,
    /// Largest `|amplitude error|` or `|period error|` over the peaks (NaN without peaks).
    pub error: f64,
    /// Error split: Δt, sub-stepping, delay (see the module docs).
    pub error_dt: f64,
    pub error_substep: f64,
    pub error_delay: f64,
    /// Measured computing time per step \[s\].
    pub cost: f64,
}

impl PlanPoint {
    pub fn margin(&self) -> f64 {
        1.0 - self.rho
    }
    /// Cost per step over `Δt`.
    pub fn utilisation(&self) -> f64 {
        self.cost / self.dt
    }
    pub fn dominant(&self) -> ErrorSource {
        let mut best = (ErrorSource::TimeStep, self.error_dt);
        for (s, e) in [
            (ErrorSource::SubStepping, self.error_substep),
            (ErrorSource::Delay, self.error_delay),
        ] {
            if e > best.1 {
                best = (s, e);
            }
        }
        best.0
    }
}

/// The scanned settings and the recommendation.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    pub points: Vec<PlanPoint>,
    /// Index into `points`.
    pub recommended: Option<usize>,
    /// Whether the recommended point meets the tolerance.
    pub meets_tolerance: bool,
    /// Sentences of advice, most important first.
    pub advice: Vec<String>,
    /// How phase-lag compensation was analysed (`None` without one).
    pub phase_lag_note: Option<String>,
    /// When no scanned setting is usable with the configured phase-lag compensation: the
    /// recommended setting with `[substructure.phase_lag] kind = "arx"` at its defaults (the
    /// robust identification of docs/theory.md §6.4), if that has one.
    pub alternative: Option<PlanPoint>,
}

/// Peaks `(rad/s, |H|)` of `h(ω)` on `[w_lo, w_hi]`.
fn peaks_of(h: impl Fn(f64) -> f64, w_lo: f64, w_hi: f64) -> Vec<Peak> {
    find_peaks(h, w_lo, w_hi, PEAK_SAMPLES)
}

/// The peak of `h` near each exact peak: the largest of 48 samples in `[0.8 ω_e, 1.25 ω_e]`
/// (within the band and between the midpoints to the neighbouring exact peaks), refined by golden-section search to `10⁻⁹ ω`. Falls back to the search
/// over the whole band when a maximum sits on a window edge (a badly distorted response).
fn peaks_near(h: impl Fn(f64) -> f64, exact: &[Peak], w_lo: f64, w_hi: f64) -> Vec<Peak> {
    const N: usize = 48;
    let mut out = Vec::with_capacity(exact.len());
    for (k, e) in exact.iter().enumerate() {
        let below = if k > 0 {
            0.5 * (exact[k - 1].freq_ratio + e.freq_ratio)
        } else {
            w_lo
        };
        let above = exact.get(k + 1).map_or(w_hi, |n| 0.5 * (n.freq_ratio + e.freq_ratio));
        let (a, b) = (
            (0.8 * e.freq_ratio).max(w_lo).max(below),
            (1.25 * e.freq_ratio).min(w_hi).min(above),
        );
        let step = (b - a) / (N - 1) as f64;
        let (mut best, mut hb) = (0, f64::NEG_INFINITY);
        for i in 0..N {
            let v = h(a + i as f64 * step);
            if v > hb {
                (best, hb) = (i, v);
            }
        }
        if best == 0 || best == N - 1 || !hb.is_finite() {
            return peaks_of(h, w_lo, w_hi);
        }
        let (mut lo, mut hi) = (a + (best - 1) as f64 * step, a + (best + 1) as f64 * step);
        let g = (5f64.sqrt() - 1.0) / 2.0;
        let (mut c, mut d) = (hi - g * (hi - lo), lo + g * (hi - lo));
        let (mut fc, mut fd) = (h(c), h(d));
        while hi - lo > 1e-9 * hi {
            if fc > fd {
                hi = d;
                (d, fd) = (c, fc);
                c = hi - g * (hi - lo);
                fc = h(c);
            } else {
                lo = c;
                (c, fc) = (d, fd);
                d = lo + g * (hi - lo);
                fd = h(d);
            }
        }
        let w = 0.5 * (lo + hi);
        out.push(Peak { freq_ratio: w, h: h(w) });
    }
    out
}

/// Signed `(amplitude, period)` errors of `alg` against `exact`, peak by peak.
fn errors(alg: &[Peak], exact: &[Peak]) -> Vec<(f64, f64)> {
    alg.iter()
        .zip(exact)
        .map(|(s, e)| (s.h / e.h - 1.0, e.freq_ratio / s.freq_ratio - 1.0))
        .collect()
}

fn largest(e: &[(f64, f64)]) -> f64 {
    if e.is_empty() {
        return f64::NAN;
    }
    e.iter().map(|(a, p)| a.abs().max(p.abs())).fold(0.0, f64::max)
}

/// Largest change between two error lists, peak by peak.
fn change(a: &[(f64, f64)], b: &[(f64, f64)]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x.0 - y.0).abs().max((x.1 - y.1).abs()))
        .fold(0.0, f64::max)
}

/// Newmark(β, γ) response of `output` to `a_g = e^{iωt}` sampled at `Δt`, from the three-point
/// recurrence `[z A₂ + A₁ + z⁻¹ A₀] U = Δt² (β z + w₁ + w₂ z⁻¹) F`, `F = −M ι`.
fn newmark_response(m: &StructuralModel, beta: f64, gamma: f64, dt: f64, output: usize, w: f64) -> Complex<f64> {
    let n = m.n_dofs();
    let z = Complex::new((w * dt).cos(), (w * dt).sin());
    let zi = z.inv();
    let dt2 = dt * dt;
    let (w1, w2) = (0.5 - 2.0 * beta + gamma, 0.5 + beta - gamma);
    let lhs = DMatrix::from_fn(n, n, |i, j| {
        let (mm, cc, kk) = (m.mass[(i, j)], m.damping[(i, j)], m.stiffness[(i, j)]);
        let a2 = mm + gamma * dt * cc + beta * dt2 * kk;
        let a1 = -2.0 * mm + (1.0 - 2.0 * gamma) * dt * cc + w1 * dt2 * kk;
        let a0 = mm - (1.0 - gamma) * dt * cc + w2 * dt2 * kk;
        z * a2 + Complex::new(a1, 0.0) + zi * a0
    });
    let load = (z * beta + Complex::new(w1, 0.0) + zi * w2) * dt2;
    let mi = m.effective_mass_vector();
    let rhs = DVector::from_fn(n, |i, _| load * -mi[i]);
    lhs.lu()
        .solve(&rhs)
        .map_or(Complex::new(f64::NAN, f64::NAN), |u| u[output])
}

/// The phase-lag compensation of `def` re-derived for the scanned `dt`, `k_sub` and `delay`,
/// fully ramped in: the lead of polynomial and inverse-FIR compensation is the delay in
/// sub-steps; an ARX compensator gets the config's defaults for the setting (`k_lag` and its
/// lead from the actuator's low-frequency lag `lag` (delay plus dynamics), velocities over a
/// step; the form of project version 1 keeps its own); AMB's model is the actuator's inverse
/// `series` (\[sⁱ\], [`crate::transfer::ActuatorSpec::inverse_series`]) at the setting.
fn phase_lag_for(
    def: &PhaseLagDefinition,
    dt: f64,
    k_sub: usize,
    delay: f64,
    lag: f64,
    series: [f64; 4],
) -> PhaseLagDefinition {
    let dtau = dt / k_sub as f64;
    let lead = delay / dtau;
    let spec = match def.spec {
        PhaseLagSpec::Polynomial {
            order,
            spacing,
            guard_factor,
            ..
        } => PhaseLagSpec::Polynomial {
            order,
            lead,
            spacing,
            guard_factor,
        },
        PhaseLagSpec::Arx(s) => {
            let k_lag = ((lag / dtau).round() as usize).max(1);
            let v1 = !s.from_current && s.smoothing == 0.0;
            PhaseLagSpec::Arx(if v1 {
                ArxPhaseLagSpec {
                    k_lag,
                    span: k_lag,
                    lead: k_lag as f64,
                    ..s
                }
            } else {
                let d = ArxPhaseLagSpec::for_substeps(lag / dtau, k_sub);
                ArxPhaseLagSpec {
                    k_lag: d.k_lag,
                    lead: d.lead,
                    period: d.period,
                    ..s
                }
                .with_span(k_sub)
            })
        }
        PhaseLagSpec::InverseFir(mut s) => {
            s.lead = lead;
            PhaseLagSpec::InverseFir(s)
        }
        // Its defaults for the setting's lag (bounds and rate limits scale with it); the
        // analysis sees it at its starting coefficients a₁ = L, a₂ = L²/2, which a delay of L
        // sub-steps converges close to (a₂ → L²/2 + L/2).
        PhaseLagSpec::Ats(s) => PhaseLagSpec::Ats(AtsSpec {
            window: s.window,
            subsample: s.subsample,
            span: s.span,
            smoothing: s.smoothing,
            threshold: s.threshold,
            guard_factor: s.guard_factor,
            ..AtsSpec::new(lag / dtau)
        }),
        // The model, its span, low-pass and memory re-derived for the setting (as the config
        // derives them); the band, adapted terms and threshold as configured.
        PhaseLagSpec::Amb(s) => {
            let series: [f64; 4] = std::array::from_fn(|i| series[i] / dtau.powi(i as i32));
            let d = AmbSpec::pure_delay(series[1]);
            PhaseLagSpec::Amb(AmbSpec {
                series,
                span: d.span,
                smoothing: d.span as f64,
                lambda: 1.0 - dtau / 2.0,
                ..s
            })
        }
    };
    PhaseLagDefinition {
        spec,
        ramp: Ramp::full(),
    }
}

/// The step map of `sub` at one setting (ideal sensors, frozen phase-lag compensation at
/// `parameters`, or its starting ones).
fn probe(
    sub: &SubstructureDefinition,
    model: &StructuralModel,
    dt: f64,
    parameters: Option<&[f64]>,
) -> Result<(StepMap, f64, usize)> {
    let mut test = sub.build_frozen_test_at(model, dt, parameters)?;
    let map = StepMap::probe(&mut test)?;
    let rho = map.spectral_radius();
    Ok((map, rho, test.state_len()))
}

/// Measured seconds per step of the (frozen, noise-free) test under a harmonic input.
fn cost(sub: &SubstructureDefinition, model: &StructuralModel, dt: f64, steps: usize, w: f64) -> Result<f64> {
    if steps == 0 {
        return Ok(0.0);
    }
    let mut test = sub.build_frozen_test(model, dt)?;
    let ag = |i: usize| 0.01 * (w * dt * i as f64).sin();
    let t0 = Instant::now();
    for i in 0..steps {
        // A diverging setting may stop early; its cost so far is what counts.
        if test.step(ag(i), ag(i + 1), &mut ()).is_err() {
            return Ok(t0.elapsed().as_secs_f64() / (i + 1) as f64);
        }
    }
    Ok(t0.elapsed().as_secs_f64() / steps as f64)
}

impl SubstructureDefinition {
    /// This definition as a linear, time-invariant test for the analysis: ideal sensors (noise
    /// and quantisation do not change the linear map), phase-lag compensation (if any) frozen
    /// and fully ramped in, no safety limits, the virtual lab even if a remote site is set.
    pub fn build_frozen_test(&self, model: &StructuralModel, dt: f64) -> Result<crate::substructure::SubstructureTest> {
        self.build_frozen_test_at(model, dt, None)
    }

    /// As [`Self::build_frozen_test`], with the phase-lag compensators frozen at `parameters`
    /// (e.g. [`super::converged::converged_parameters`]) instead of their starting ones.
    pub fn build_frozen_test_at(
        &self,
        model: &StructuralModel,
        dt: f64,
        parameters: Option<&[f64]>,
    ) -> Result<crate::substructure::SubstructureTest> {
        use crate::compensate::CompensatedSite;
        use crate::substructure::{ExperimentalSubstructure, SubstepController, SubstructureTest};
        use crate::transfer::VirtualLab;
        if self.explicit.is_some() {
            return Err(Error::invalid(
                "integrator.scheme",
                "this analysis scans the sub-step algorithm; a cr or kr_alpha test is analysed by \
                 substep::analysis::StepMap on its own test (docs/theory.md §2.9)",
            ));
        }
        let n_c = self.coupling_dofs.len();
        let controller = SubstepController::new(model, &self.settings(dt), &DVector::zeros(model.n_dofs()))?;
        let lab = VirtualLab::from_specs(
            &self.coupling_dofs,
            &self.specimens,
            &vec![self.actuator.clone(); n_c],
            &vec![SensorSpec::ideal(); n_c],
            &vec![SensorSpec::ideal(); n_c],
            dt / self.substeps as f64,
            self.inner_steps,
        )?;
        let site: Box<dyn ExperimentalSubstructure> = match &self.phase_lag {
            None => Box::new(lab),
            Some(p) => {
                let mut site: CompensatedSite = p.wrap(Box::new(lab))?;
                if let Some(theta) = parameters {
                    site.set_parameters(theta);
                }
                site.set_frozen(true);
                Box::new(site)
            }
        };
        SubstructureTest::new(model, controller, site)
    }
}

/// Scan `settings` for `sub` on `model` (see the module docs). `model` must be dense.
pub fn plan(sub: &SubstructureDefinition, model: &StructuralModel, settings: &PlanSettings) -> Result<Plan> {
    if settings.dts.is_empty() || settings.k_subs.is_empty() || settings.delays.is_empty() {
        return Err(Error::invalid(
            "plan",
            "nothing to scan (empty Δt, k_sub or delay list)",
        ));
    }
    let assembled = assemble_monolithic(model, &sub.specimens)?;
    let modes = assembled.modes()?;
    let flexible: Vec<f64> = modes.omega.iter().copied().filter(|&w| w > 0.0).collect();
    let w1 = *flexible
        .first()
        .ok_or_else(|| Error::invalid("plan", "the assembled model has no flexible mode"))?;
    let w_top = flexible.iter().copied().take(3).fold(w1, f64::max);
    // What an adaptive compensator converges on: the structure's first modes.
    let mode_hz: Vec<f64> = flexible.iter().take(3).map(|w| w / (2.0 * PI)).collect();
    let output = sub.coupling_dofs[0];
    let band = |dt: f64| (0.3 * w1, (1.5 * w_top).min(0.95 * PI / dt));
    let exact_h = |w: f64| continuous_response(&assembled, output, w).norm();

    // Shared per Δt: exact peaks in the Δt's band and monolithic Newmark.
    struct PerDt {
        exact: Vec<Peak>,
        newmark: Vec<(f64, f64)>,
    }
    let per_dt: Vec<PerDt> = settings
        .dts
        .par_iter()
        .map(|&dt| {
            let (lo, hi) = band(dt);
            let exact = peaks_of(exact_h, lo, hi);
            let nm = peaks_near(
                |w| newmark_response(&assembled, sub.beta, sub.gamma, dt, output, w).norm(),
                &exact,
                lo,
                hi,
            );
            PerDt {
                newmark: errors(&nm, &exact),
                exact,
            }
        })
        .collect();

    // Shared per (Δt, k_sub): the delay-free algorithm (ideal actuator, no compensation).
    let mut pairs = Vec::new();
    for (i, &dt) in settings.dts.iter().enumerate() {
        for &k in &settings.k_subs {
            pairs.push((i, dt, k));
        }
    }
    let ideal: Vec<Vec<(f64, f64)>> = pairs
        .par_iter()
        .map(|&(i, dt, k)| -> Result<Vec<(f64, f64)>> {
            let mut s = sub.clone();
            s.substeps = k;
            s.actuator = ActuatorSpec::ideal();
            s.phase_lag = None;
            let mut test = s.build_frozen_test(model, dt)?;
            let map = StepMap::probe(&mut test)?;
            let fr = FrequencyResponse::new(&map, output)?;
            let (lo, hi) = band(dt);
            Ok(errors(
                &peaks_near(|w| fr.at(w * dt).norm(), &per_dt[i].exact, lo, hi),
                &per_dt[i].exact,
            ))
        })
        .collect::<Result<_>>()?;

    let mut jobs = Vec::new();
    for (p, &(i, dt, k)) in pairs.iter().enumerate() {
        for &d in &settings.delays {
            jobs.push((p, i, dt, k, d));
        }
    }
    let points: Vec<PlanPoint> = jobs
        .par_iter()
        .map(|&(p, i, dt, k, delay)| -> Result<PlanPoint> {
            let mut s = sub.clone();
            s.substeps = k;
            s.actuator.delay = delay;
            let lag = s.actuator.low_frequency_lag();
            let series = s.actuator.inverse_series();
            s.phase_lag = sub
                .phase_lag
                .as_ref()
                .map(|pl| phase_lag_for(pl, dt, k, delay, lag, series));
            let theta = match &s.phase_lag {
                Some(pl) => converged_parameters(pl, &s.actuator, dt / k as f64, s.inner_steps, &mode_hz)?,
                None => None,
            };
            let (map, rho, _) = probe(&s, model, dt, theta.as_deref())?;
            let fr = FrequencyResponse::new(&map, output)?;
            let (lo, hi) = band(dt);
            let exact = &per_dt[i].exact;
            let alg = peaks_near(|w| fr.at(w * dt).norm(), exact, lo, hi);
            let e = errors(&alg, exact);
            let peaks = alg
                .iter()
                .zip(exact)
                .zip(&e)
                .map(|((a, x), &(amp, per))| PeakComparison {
                    freq_hz: a.freq_ratio / (2.0 * PI),
                    freq_hz_exact: x.freq_ratio / (2.0 * PI),
                    amplitude_error: amp,
                    period_error: per,
                })
                .collect();
            let nm = &per_dt[i].newmark;
            Ok(PlanPoint {
                dt,
                k_sub: k,
                delay,
                rho,
                peaks,
                error: largest(&e),
                error_dt: largest(nm),
                error_substep: change(&ideal[p], nm),
                error_delay: change(&e, &ideal[p]),
                cost: 0.0,
            })
        })
        .collect::<Result<_>>()?;
    // Timing runs one after another, so that parallel work does not inflate them.
    let mut points = points;
    for pt in &mut points {
        let mut s = sub.clone();
        s.substeps = pt.k_sub;
        s.actuator.delay = pt.delay;
        let lag = s.actuator.low_frequency_lag();
        s.phase_lag = sub
            .phase_lag
            .as_ref()
            .map(|pl| phase_lag_for(pl, pt.dt, pt.k_sub, pt.delay, lag, s.actuator.inverse_series()));
        pt.cost = cost(&s, model, pt.dt, settings.cost_steps, w1)?;
    }
    let mut result = recommend(sub, model, settings, points);
    // Nothing usable with the configured compensator: is the default ARX compensation?
    let default_arx = PhaseLagSpec::Arx(ArxPhaseLagSpec::for_substeps(1.0, 1));
    // The configured compensator is the default one if both re-derive to the same at a setting.
    let same = |a: &PhaseLagDefinition, b: PhaseLagSpec| {
        let b = PhaseLagDefinition { spec: b, ramp: a.ramp };
        let series = [1.0, 0.01, 5e-5, 1.7e-7];
        phase_lag_for(a, 0.01, 2, 0.01, 0.01, series).spec == phase_lag_for(&b, 0.01, 2, 0.01, 0.01, series).spec
    };
    if result.recommended.is_none()
        && let Some(pl) = &sub.phase_lag
        && !same(pl, default_arx)
    {
        let mut alt = sub.clone();
        alt.phase_lag = Some(PhaseLagDefinition {
            spec: default_arx,
            ramp: pl.ramp,
        });
        let other = plan(&alt, model, settings)?;
        if let Some(i) = other.recommended {
            let p = other.points[i].clone();
            result.advice.push(format!(
                "with [substructure.phase_lag] kind = \"arx\" at its defaults (the robust identification) instead: \
                 dt = {} s, k_sub = {} is stable (1 − ρ = {:.2e}) with a peak error of {}",
                p.dt,
                p.k_sub,
                p.margin(),
                percent(p.error)
            ));
            result.alternative = Some(p);
        }
    }
    Ok(result)
}

fn percent(x: f64) -> String {
    format!("{:.2} %", 100.0 * x)
}

fn recommend(
    sub: &SubstructureDefinition,
    model: &StructuralModel,
    settings: &PlanSettings,
    points: Vec<PlanPoint>,
) -> Plan {
    let stable = |p: &PlanPoint| p.rho.is_finite() && p.margin() >= settings.min_margin;
    let fits = |p: &PlanPoint| p.cost <= settings.budget * p.dt;
    let feasible: Vec<usize> = (0..points.len())
        .filter(|&i| stable(&points[i]) && fits(&points[i]))
        .collect();
    let accurate: Vec<usize> = feasible
        .iter()
        .copied()
        .filter(|&i| points[i].error <= settings.tolerance)
        .collect();
    let by = |a: &usize, b: &usize| {
        let (p, q) = (&points[*a], &points[*b]);
        p.utilisation()
            .total_cmp(&q.utilisation())
            .then(q.margin().total_cmp(&p.margin()))
    };
    let (recommended, meets) = if let Some(&i) = accurate.iter().min_by(|a, b| by(a, b)) {
        (Some(i), true)
    } else {
        let best = feasible
            .iter()
            .copied()
            .min_by(|&a, &b| points[a].error.total_cmp(&points[b].error));
        (best, false)
    };
    let mut advice = Vec::new();
    let has_pl = sub.phase_lag.is_some();
    let has_ef = !matches!(sub.error_force, ErrorForceSpec::None);
    match recommended {
        Some(i) => {
            let p = &points[i];
            advice.push(format!(
                "dt = {} s, k_sub = {} (delay {} s): {} peak error {}, margin 1 − ρ = {:.2e}, {:.1} µs per step = {:.1} % of the real-time budget dt",
                p.dt,
                p.k_sub,
                p.delay,
                if meets { "within the tolerance," } else { "NOT within the tolerance, the most accurate feasible setting:" },
                percent(p.error),
                p.margin(),
                p.cost * 1e6,
                100.0 * p.utilisation()
            ));
        }
        None => {
            let unstable = points.iter().filter(|p| !stable(p)).count();
            let slow = points.iter().filter(|p| !fits(p)).count();
            advice.push(format!(
                "none of the {} scanned settings is usable: {unstable} unstable or with a margin below {:.0e}, {slow} over the real-time budget ({:.0} % of dt)",
                points.len(),
                settings.min_margin,
                100.0 * settings.budget
            ));
        }
    }
    // The dominant error and its remedy, at the recommended setting or else the most accurate one.
    let focus = recommended.or_else(|| {
        (0..points.len())
            .filter(|&i| points[i].error.is_finite())
            .min_by(|&a, &b| points[a].error.total_cmp(&points[b].error))
    });
    if let Some(i) = focus {
        let p = &points[i];
        let d = p.dominant();
        advice.push(format!(
            "dominant error: {} ({} of the peak errors; Δt {}, sub-stepping {}, delay {})",
            d.name(),
            percent(match d {
                ErrorSource::TimeStep => p.error_dt,
                ErrorSource::SubStepping => p.error_substep,
                ErrorSource::Delay => p.error_delay,
            }),
            percent(p.error_dt),
            percent(p.error_substep),
            percent(p.error_delay)
        ));
        let remedy = match d {
            ErrorSource::Delay if !has_pl => {
                let what_if = what_if_polynomial(sub, model, p);
                format!(
                    "remedy: phase-lag compensation, [substructure.phase_lag] kind = \"polynomial\" (lead = the actuator delay){what_if}"
                )
            }
            ErrorSource::Delay if matches!(sub.phase_lag.as_ref().map(|pl| pl.spec), Some(PhaseLagSpec::Arx(_))) => {
                format!(
                    "remedy: the ARX compensation at the parameters it converges to still leaves {}; a smaller dt (the \
                 lead it must predict shrinks with the step) or a faster actuator",
                    percent(p.error_delay)
                )
            }
            ErrorSource::Delay => format!(
                "remedy: the frozen {} compensation still leaves {}; check the lead against the measured delay (summary.json tracking.delay_s) or try kind = \"arx\"",
                sub.phase_lag.as_ref().map_or("", |pl| pl.spec.kind()),
                percent(p.error_delay)
            ),
            ErrorSource::SubStepping => {
                // More sub-steps only where the table shows the error falling with k_sub.
                let better = points
                    .iter()
                    .filter(|q| q.dt == p.dt && q.delay == p.delay && q.k_sub > p.k_sub && stable(q))
                    .min_by(|a, b| a.error.total_cmp(&b.error))
                    .filter(|q| q.error < p.error);
                match better {
                    Some(q) => format!(
                        "remedy: more sub-steps at this dt: k_sub = {} gives a peak error of {}",
                        q.k_sub,
                        percent(q.error)
                    ),
                    None if has_ef => {
                        "remedy: not more sub-steps (at this dt the error does not fall with k_sub in the table): a smaller dt"
                            .to_string()
                    }
                    None => "remedy: not more sub-steps (at this dt the error does not fall with k_sub in the table): \
                             a smaller dt, or error-force compensation ([substructure.error_force] kind = \"pid\", p = 1)"
                        .to_string(),
                }
            }
            ErrorSource::TimeStep => {
                "remedy: a smaller dt (the Newmark integration error itself dominates)".to_string()
            }
        };
        advice.push(remedy);
    }
    if points.iter().all(|p| !stable(p)) && !has_ef {
        advice.push(
            "every setting is unstable: error-force compensation ([substructure.error_force] kind = \"pid\", p = 1) or phase-lag compensation usually restores stability".into(),
        );
    }
    let phase_lag_note = sub.phase_lag.as_ref().map(|pl| match pl.spec {
        PhaseLagSpec::Arx(_) | PhaseLagSpec::InverseFir(_) | PhaseLagSpec::Ats(_) | PhaseLagSpec::Amb(_)
            if !matches!(sub.actuator.dynamics, crate::transfer::Dynamics::ServoHydraulic(_)) =>
        {
            format!(
                "phase-lag compensation ({}) analysed frozen at the parameters it converges to in front of this actuator \
                 (identified on line under a multi-sine at the first modes; {}), fully ramped in",
                pl.spec.kind(),
                if matches!(pl.spec, PhaseLagSpec::Amb(_)) {
                    "starting from the actuator's model at the scanned delay"
                } else {
                    "lead / k_lag = the scanned delay in sub-steps"
                }
            )
        }
        _ => format!(
            "phase-lag compensation ({}) analysed frozen: lead / k_lag = the scanned delay in sub-steps, starting parameters, fully ramped in",
            pl.spec.kind()
        ),
    });
    Plan {
        points,
        recommended,
        meets_tolerance: meets,
        advice,
        phase_lag_note,
        alternative: None,
    }
}

/// ", which here gives …" for the recommended point with a frozen order-3 polynomial compensator.
fn what_if_polynomial(sub: &SubstructureDefinition, model: &StructuralModel, p: &PlanPoint) -> String {
    let mut s = sub.clone();
    s.substeps = p.k_sub;
    s.actuator.delay = p.delay;
    let base = PhaseLagDefinition {
        spec: PhaseLagSpec::Polynomial {
            order: 3,
            lead: 0.0,
            spacing: 1,
            guard_factor: 10.0,
        },
        ramp: Ramp::full(),
    };
    s.phase_lag = Some(phase_lag_for(
        &base,
        p.dt,
        p.k_sub,
        p.delay,
        p.delay,
        s.actuator.inverse_series(),
    ));
    let single = PlanSettings {
        dts: vec![p.dt],
        k_subs: vec![p.k_sub],
        delays: vec![p.delay],
        tolerance: 0.0,
        min_margin: 0.0,
        budget: f64::INFINITY,
        cost_steps: 0,
    };
    match plan(&s, model, &single) {
        Ok(q) => {
            let r = &q.points[0];
            format!(
                "; analysed frozen at this setting it gives a peak error of {} (was {}), 1 − ρ = {:.2e}",
                percent(r.error),
                percent(p.error),
                r.margin()
            )
        }
        Err(_) => String::new(),
    }
}
