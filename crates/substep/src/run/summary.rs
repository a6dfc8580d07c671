//! The summary of a run (`summary.json`): parameters, peaks, errors against the reference,
//! tracking metrics, compensation statistics and the engineering blocks. Field order is the
//! file's; the descriptive blocks (substructure, estimation, phase lag) are JSON values whose
//! keys serialise sorted.

use super::engineering::{EngineeringSummary, InputMotionSummary};
use super::simulation::Simulation;
use super::stats::{ErrorStats, Peak};
use crate::compensate::{PhaseLagDefinition, PhaseLagSpec};
use crate::io::SubstructureDefinition;
use crate::specimen::SpecimenSpec;
use crate::substructure::ErrorForceSpec;
use crate::transfer::Dynamics;
use serde::Serialize;
use serde_json::{Value, json};

#[derive(Debug, Clone, Serialize)]
pub struct DofPeaks {
    pub dof: usize,
    pub u: Peak,
    pub v: Peak,
    pub a: Peak,
}

#[derive(Debug, Clone, Serialize)]
pub struct CouplingPeaks {
    pub dof: usize,
    pub force: Peak,
    pub error_force: Peak,
}

#[derive(Debug, Clone, Serialize)]
pub struct DofError {
    pub dof: usize,
    #[serde(flatten)]
    pub displacement: ErrorStats,
    /// J-style `std(u − u_ref) / std(u_ref)` (the benchmark's J4/J6 normalisation).
    pub nrms_error: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct CouplingError {
    pub dof: usize,
    pub displacement: ErrorStats,
    /// J-style `std(u − u_ref) / std(u_ref)` of the coupling DOF's displacement.
    pub displacement_nrms_error: f64,
    pub force: ErrorStats,
}

/// How well the measured displacement of a coupling DOF follows the command `d^{(j)}`, over
/// all sub-steps (the benchmark's J1–J3 for any test).
#[derive(Debug, Clone, Serialize)]
pub struct TrackingSummary {
    pub dof: usize,
    /// Cross-correlation lag of the measured displacement behind the command \[s\]; null when
    /// the command does not move. Equal to `max_delay_s` means "at least that".
    pub delay_s: Option<f64>,
    pub max_delay_s: f64,
    /// `std(x_m − d) / std(d)`.
    pub nrms_error: f64,
    /// `max|x_m − d| / max|d|`.
    pub peak_error: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct ReferenceSummary {
    /// `exact` (first-order hold) or `newmark`.
    pub scheme: &'static str,
    pub n_dofs: usize,
    /// Largest normalised peak error over the numerical DOFs' displacements.
    pub max_displacement_error: f64,
    /// Largest normalised peak error over the coupling forces.
    pub max_force_error: f64,
    pub dofs: Vec<DofError>,
    pub coupling: Vec<CouplingError>,
    /// With the exact reference: the split of the displacement error into the time step's
    /// share and the test's (see [`SameIntegratorSummary`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub same_integrator: Option<SameIntegratorSummary>,
}

/// The assembled structure integrated with the test's own scheme (its `β`, `γ` and `Δt`:
/// [`Reference::same_integrator`](crate::run::Reference::same_integrator)) beside the exact
/// reference. Both errors are the largest over the numerical DOFs of the peak displacement
/// error relative to that DOF's peak, like
/// [`ReferenceSummary::max_displacement_error`].
#[derive(Debug, Clone, Serialize)]
pub struct SameIntegratorSummary {
    /// The test against that solution: what the substructuring, the sub-stepping and the
    /// transfer system add to the time integration.
    pub max_displacement_error: f64,
    /// That solution against the exact one: the error of the time step alone, which no
    /// compensation can remove (a smaller `Δt` does).
    pub integration_error: f64,
}

/// The summary of a run, serialised as `summary.json`. `wall_time_s` and `us_per_step` are
/// timings (they differ between reruns); every other number is bit-identical between reruns.
#[derive(Debug, Serialize)]
pub struct RunSummary {
    pub config: String,
    pub scheme: String,
    pub dt: f64,
    pub steps: usize,
    pub duration: f64,
    pub n_dofs: usize,
    pub ground_motion: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub substructure: Option<Value>,
    pub completed: bool,
    /// The run diverged: a non-finite or runaway response, or an error against the reference
    /// beyond [`super::DIVERGED_ERROR`] (then `completed` is false and `reason` says which).
    pub diverged: bool,
    pub steps_done: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stopped_at_step: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// `operator` (a front end's [`super::RunObserver::stop_request`]) or `stability` (the
    /// indicator's `stability = "stop"`), when the run ended by that controlled stop.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stopped_by: Option<&'static str>,
    /// Sub-steps of the ramp to the safe position after a safety stop (in `substeps.csv`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ramp_substeps: Option<usize>,
    /// Wall time of the stepping loop including recording \[s\].
    pub wall_time_s: f64,
    /// Compute time of the simulation steps alone per step \[µs\].
    pub us_per_step: f64,
    pub peaks: Vec<DofPeaks>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coupling_peaks: Option<Vec<CouplingPeaks>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tracking: Option<Vec<TrackingSummary>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference: Option<ReferenceSummary>,
    /// Error-force compensation by estimation: how the steps were closed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub estimation: Option<Value>,
    /// Phase-lag compensation: kind and guard trips.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub phase_lag: Option<Value>,
    /// A lab target's link (`[substructure.lab]`, docs/lab.md): exchanges, sub-steps held,
    /// late / duplicated / unexpected / malformed replies, and the round trip p50 / p99 / max
    /// \[µs\] (timings: they differ between reruns).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lab: Option<Value>,
    /// The on-line stability indicator: thresholds, worst values, alarms (docs/monitor.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stability: Option<crate::monitor::StabilitySummary>,
    /// Warnings of the run (e.g. a phase-lag compensator disabled by its guard).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// PGA and response-spectrum peak of the input.
    pub input_motion: InputMotionSummary,
    /// Energy balance, base shear, drifts, absolute accelerations (dense models up to 200 DOFs).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub engineering: Option<EngineeringSummary>,
    /// `[structure.reduction]`: the reduced model, its error estimate and the check against the
    /// full model (`seconds` and `full_run_seconds` are timings).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reduction: Option<super::reduction::ReductionSummary>,
    /// The files a front end wrote (paths as it names them; empty when nothing was written).
    pub outputs: Vec<String>,
    /// Why the run did not complete (the error behind `stopped_at_step` and `reason`).
    #[serde(skip)]
    pub failure: Option<crate::Error>,
}

impl RunSummary {
    /// `summary.json`'s text: pretty-printed JSON and a final newline.
    pub fn to_json(&self) -> String {
        // Serialising plain numbers, strings and maps with string keys cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default() + "\n"
    }
}

pub(super) fn substructure_json(s: &SubstructureDefinition) -> Value {
    let a = &s.actuator;
    let mut actuator = match &a.dynamics {
        Dynamics::Ideal => json!({ "kind": "ideal", "delay": a.delay }),
        Dynamics::FirstOrder { time_constant } => {
            json!({ "kind": "first_order", "time_constant": time_constant, "delay": a.delay })
        }
        Dynamics::SecondOrder { frequency_hz, zeta } => {
            json!({ "kind": "second_order", "frequency": frequency_hz, "zeta": zeta, "delay": a.delay })
        }
        Dynamics::Lti(ss) => json!({
            "kind": "lti",
            "a": ss.a.row_iter().map(|r| r.iter().copied().collect::<Vec<f64>>()).collect::<Vec<_>>(),
            "b": ss.b.as_slice(),
            "c": ss.c.as_slice(),
            "d": ss.d,
            "delay": a.delay,
        }),
        Dynamics::ServoHydraulic(p) => json!({
            "kind": "servo_hydraulic",
            "g": p.g,
            "a1_beta0": p.a1_beta0,
            "beta1": p.beta1,
            "beta2": p.beta2,
            "a2": p.a2,
            "a3": p.a3,
            "csi_derivative": match p.derivative {
                crate::transfer::servo::Derivative::Exact => "exact",
                crate::transfer::servo::Derivative::FiniteDifference => "finite_difference",
            },
            "delay": a.delay,
        }),
    };
    if let Some(c) = &s.lab.command_converter {
        actuator["da_converter"] = json!({ "range": c.range(), "quantum": c.quantum() });
    }
    let error_force = match s.error_force {
        ErrorForceSpec::None => json!({ "kind": "none" }),
        ErrorForceSpec::Pid { p, i, d } => json!({ "kind": "pid", "p": p, "i": i, "d": d }),
        ErrorForceSpec::PidResidual { p } => json!({ "kind": "pid_residual", "p": p }),
        ErrorForceSpec::Arx { order, lambda, p0 } => {
            json!({ "kind": "arx", "order": order, "forgetting_factor": lambda, "p0": p0 })
        }
    };
    let specimens: Vec<Value> = s
        .specimens
        .iter()
        .map(|sp| {
            let dofs: Vec<usize> = sp.dofs().iter().map(|d| d + 1).collect();
            match sp {
                SpecimenSpec::LinearSdof {
                    mass,
                    stiffness,
                    damping,
                    ..
                } => {
                    json!({ "kind": sp.kind(), "dofs": dofs, "mass": mass, "stiffness": stiffness, "damping": damping })
                }
                SpecimenSpec::LumpedSdof {
                    mass,
                    stiffness,
                    damping,
                    ..
                } => {
                    json!({ "kind": sp.kind(), "dofs": dofs, "mass": mass, "stiffness": stiffness, "damping": damping })
                }
                _ => json!({ "kind": sp.kind(), "dofs": dofs }),
            }
        })
        .collect();
    let f = &s.force_sensors[0];
    let d = &s.displacement_sensors[0];
    json!({
        "coupling_dofs": s.coupling_dofs.iter().map(|c| c + 1).collect::<Vec<_>>(),
        "substeps": s.substeps,
        "inner_steps": s.inner_steps,
        "specimens": specimens,
        "actuator": actuator,
        "sensors": {
            "force_noise": f.noise_std, "displacement_noise": d.noise_std,
            "adc_bits": f.adc_bits.or(d.adc_bits), "lowpass_hz": f.lowpass_hz,
            "force_quantum": f.converter().map(|c| c.quantum()),
            "displacement_quantum": d.converter().map(|c| c.quantum()),
            "generator": match f.generator {
                crate::transfer::NoiseGenerator::ChaCha => "chacha",
                crate::transfer::NoiseGenerator::Benchmark => "benchmark",
            },
        },
        "force": if s.lab.force_from_motion { "from_motion" } else { "model" },
        "controller": s.controller.as_ref().map(|c| json!({
            "num": c.num(), "den": c.den(),
            "feedforward": s.controller_feedforward.as_ref().map(|f| json!({ "num": f.num(), "den": f.den() })),
        })),
        "error_force": error_force,
        "phase_lag": s.phase_lag.as_ref().map(phase_lag_json),
    })
}

// --- Phase-lag compensation, estimation and ideal error force: records and summary ---

pub(super) fn phase_lag_json(p: &PhaseLagDefinition) -> Value {
    let ramp = json!({
        "start_substep": p.ramp.start, "ramp_substeps": p.ramp.ramp_in,
        "fade_out": p.ramp.fade_out.map(|(b, l)| [b, l]),
    });
    match p.spec {
        PhaseLagSpec::Polynomial {
            order,
            lead,
            spacing,
            guard_factor,
        } => {
            json!({ "kind": "polynomial", "order": order, "lead_substeps": lead, "spacing_substeps": spacing, "guard_factor": guard_factor, "ramp": ramp })
        }
        PhaseLagSpec::Arx(a) => json!({
            "kind": "arx", "n_u": a.n_u, "k_lag": a.k_lag, "forgetting_factor": a.lambda,
            "guard_factor": a.guard_factor, "ramp": ramp,
        }),
        PhaseLagSpec::InverseFir(f) => json!({
            "kind": "inverse_fir", "lead_substeps": f.lead, "taps": f.taps, "order": f.order,
            "forgetting_factor": f.lambda, "ramp": ramp,
        }),
        PhaseLagSpec::Ats(a) => json!({
            "kind": "ats", "initial_lead_substeps": a.initial_lead, "window_substeps": a.window,
            "subsample": a.subsample, "smoothing_substeps": a.smoothing, "threshold": a.threshold,
            "guard_factor": a.guard_factor, "ramp": ramp,
        }),
        PhaseLagSpec::Amb(a) => json!({
            "kind": "amb", "inverse_series": a.series, "model_coefficients": a.model(), "span_substeps": a.span,
            "smoothing_substeps": a.smoothing, "threshold": a.threshold, "forgetting_factor": a.lambda,
            "subsample": a.subsample, "deviation": a.deviation, "adapted_terms": a.adapted_terms, "p0": a.p0, "instruments": a.instruments,
            "guard_factor": a.guard_factor, "ramp": ramp,
        }),
    }
}

/// Estimation counts and phase-lag trips of a finished (or stopped) run, and the warnings.
/// `(estimation, phase_lag, warnings)` of the summary.
/// The `lab` block of a run against a lab target; a warning when sub-steps were held.
pub(super) fn lab_summary(sim: &Simulation, warnings: &mut Vec<String>) -> Option<Value> {
    let s = sim.site()?.lab_stats()?;
    if s.held > 0 {
        warnings.push(format!(
            "lab target: {} sub-step(s) held the last measurement (no reply in time; at most {} in a row)",
            s.held, s.max_held_in_a_row
        ));
    }
    Some(s.json())
}

pub(super) fn compensation_summary(sim: &Simulation) -> (Option<Value>, Option<Value>, Vec<String>) {
    let mut warnings = Vec::new();
    let (Some(site), Some(coupling)) = (sim.site(), sim.coupling_dofs()) else {
        return (None, None, warnings);
    };
    let estimation = sim
        .substructure_test()
        .and_then(|t| t.controller.estimation_stats())
        .map(|s| {
            if s.guard_fallbacks() > 0 {
                warnings.push(format!(
                    "error-force estimation fell back to the plain algorithm in {} step(s) after its warm-up \
                 ({} ill-conditioned, {} implausible predictions)",
                    s.guard_fallbacks(),
                    s.ill_conditioned,
                    s.implausible
                ));
            }
            json!({
                "steps": s.steps, "estimated": s.estimated, "fallbacks": s.fallbacks(),
                "warm_up": s.warm_up, "ill_conditioned": s.ill_conditioned, "implausible": s.implausible,
            })
        });
    let phase_lag = site.phase_lag().map(|p| {
        let trips: Vec<Value> = p
            .trips()
            .into_iter()
            .map(|(i, t)| {
                let dof = coupling[i] + 1;
                warnings.push(format!(
                    "phase-lag compensator of coupling DOF {dof} disabled by its guard: {t}"
                ));
                json!({ "dof": dof, "reason": t.to_string() })
            })
            .collect();
        json!({ "kinds": p.kinds(), "disabled": trips })
    });
    (estimation, phase_lag, warnings)
}
