//! Adaptive compensators at their converged parameters, for the linear analysis
//! (docs/theory.md §6.7).
//!
//! An identified phase-lag compensator is a linear filter only while its parameters are
//! frozen, and what it does to the stability of a test depends on the parameters it reaches,
//! not on those it starts from. [`converged_parameters`] runs the compensator in open loop in
//! front of the test's actuator model (delay and dynamics, on the lab's inner grid, ideal
//! sensors), commanded with a multi-sine at the frequencies the structure responds at: the
//! parameters it has identified at the end are what it converges to for this actuator. The
//! analysis then freezes the compensator at them ([`crate::compensate::CompensatedSite::set_parameters`]).
//!
//! The command is `d(t) = Σ_m sin(2π f_m t + φ_m) / f_m`, `φ_m = m·2.4 rad`, over 30 periods of the
//! lowest frequency (at most 300 000 sub-steps), tapered in over the first 10 %. No sub-step
//! ripple and no structure: the identification meets the actuator alone.

use crate::compensate::PhaseLagDefinition;
use crate::error::Result;
use crate::transfer::{ActuatorSpec, Dynamics};
use std::f64::consts::PI;

/// Longest convergence run \[sub-steps\].
const MAX_SUBSTEPS: usize = 300_000;

/// The parameters the compensator of `def` converges to in front of `actuator` (sub-steps of
/// `dtau` seconds, `inner_steps` actuator intervals each) under a multi-sine at `freqs_hz`;
/// `None` when the compensator does not adapt (polynomial) or the actuator's plant contains the
/// specimen (servo-hydraulic), where the analysis keeps the starting parameters.
pub fn converged_parameters(
    def: &PhaseLagDefinition,
    actuator: &ActuatorSpec,
    dtau: f64,
    inner_steps: usize,
    freqs_hz: &[f64],
) -> Result<Option<Vec<f64>>> {
    let mut comp = def.spec.build()?;
    let freqs: Vec<f64> = freqs_hz.iter().copied().filter(|f| f.is_finite() && *f > 0.0).collect();
    if !comp.is_adaptive()
        || comp.parameters().is_empty()
        || freqs.is_empty()
        || matches!(actuator.dynamics, Dynamics::ServoHydraulic(_))
    {
        return Ok(None);
    }
    let inner = inner_steps.max(1);
    let h = dtau / inner as f64;
    let mut act = actuator.build(h)?;
    let f_lo = freqs.iter().copied().fold(f64::INFINITY, f64::min);
    let n = ((30.0 / f_lo / dtau).ceil() as usize).clamp(1, MAX_SUBSTEPS);
    let taper = (n / 10).max(1);
    let (mut measured, mut command_prev) = (0.0, 0.0);
    for j in 0..n {
        let t = (j + 1) as f64 * dtau;
        let w = ((j + 1) as f64 / taper as f64).min(1.0);
        let target: f64 = w * freqs
            .iter()
            .enumerate()
            .map(|(m, f)| (2.0 * PI * f * t + 2.4 * m as f64).sin() / f)
            .sum::<f64>();
        let command = target + comp.correction(target, measured, 1.0);
        for s in 0..inner {
            let r = (s + 1) as f64 / inner as f64;
            measured = act.advance(command_prev + r * (command - command_prev), h);
        }
        command_prev = command;
    }
    Ok(Some(comp.parameters().to_vec()))
}
