//! The benchmark's TOML settings file (`substep benchmark rths --config FILE.toml`): the
//! controller and the sub-step algorithm. Every key is optional; unknown keys are errors.
//!
//! ```toml
//! [controller]
//! kind = "arx"                  # none | sample | arx | polynomial | inverse_fir | ats | amb (--controller wins)
//! converters = true             # the benchmark's A/D and D/A (±3.8, q = 2^-18)
//! # feedforward = { num = [...], den = [...] }  # the shaping filter of kind none | sample only
//! feedback = { num = [2.0, 95.0], den = [1.0, 0.0] }   # continuous TFs in s, Tustin at 1/4096 s
//! no_feedforward = false        # drop the preset's feedforward (sample: G_T)
//! no_feedback = false           # drop the preset's feedback (sample: G_C)
//! ramp_start = 0                # compensator ramp h_k: 0 before, linear over ramp_in samples
//! ramp_in = 1024
//!
//! [controller.arx]              # crate::compensate::ArxPhaseLagSpec, at the controller rate
//! k_lag = 96                    # samples
//! n_u = 4
//! forgetting_factor = 0.999
//! p0 = 100.0
//! p_max = 100.0
//! scalar_covariance = false
//! guard_factor = 10.0
//! regressor = "velocity"        # full | correction_velocity | velocity_error | velocity
//! pairing = "delayed"           # current | delayed
//! span = 96                     # samples per velocity difference and between lags (k_lag)
//! smoothing = 48.0              # low-pass time constant of each of two stages [samples] (span/2)
//! max_lead = 480.0              # supervisor bound on the correction's lead [samples] (4 k_lag + 2 span)
//! supervisor = true             # false: no supervisor
//!
//! [controller.polynomial]
//! order = 2
//! lead = 97.0                   # samples
//! spacing = 49                  # samples between the interpolation nodes
//! guard_factor = 10.0
//!
//! [controller.inverse_fir]
//! lead = 97.0
//! taps = 4
//! order = 2
//! forgetting_factor = 0.995
//! p0 = 100.0
//!
//! [controller.ats]              # compensate::AtsSpec, in samples
//! initial_lead = 97.0           # a₁ at the start (a₂ = a₁²/2, a₀ = 1)
//! window = 4096                 # samples in the least-squares window (1 s)
//! subsample = 16                # one regression row every 16 samples
//! span = 32                     # samples per difference of the derivatives
//! smoothing = 48.5              # low-pass time constant of each of two stages [samples]
//! threshold = 1e-4              # adaptation starts above this |x_m| [m]
//! guard_factor = 10.0
//!
//! [controller.amb]              # compensate::AmbSpec, in samples
//! inverse_series = [0.9925, 101.9, 1789.0, 26497.0]   # g₀…g₃ of 1/G(σ) (default: the nominal plant's)
//! span = 34                     # samples per difference
//! smoothing = 34.0              # low-pass time constant of each of two stages [samples]
//! threshold = 1e-4              # adaptation starts above this |x_m| [m]
//! forgetting_factor = 0.99988   # RLS, per row
//! subsample = 1                 # one RLS row every sample
//! deviation = 0.5               # each coefficient within ±50 % of the model's
//! adapted_terms = 2             # adapt c₀ and c₁ (gain and lead); c₂, c₃ stay the model's
//! p0 = 0.01                     # initial covariance of each ratio to the model
//! instruments = true            # instrumental variables (the delayed target), not plain RLS
//! guard_factor = 10.0
//!
//! [plant]
//! kind = "servo"                # or "ideal": x = desired exactly (the loop's own error)
//! derivative = "finite_difference"   # or "exact"
//!
//! [noise]
//! enabled = true
//! seed = 1144108930
//!
//! [substep]                     # --algorithm substep
//! dt = 0.0009765625             # whole number of 1/4096 s samples
//! k_sub = 4
//! beta = 0.25
//! gamma = 0.5
//! error_force = { kind = "pid", p = 1.0, i = 0.0, d = 0.0 }   # or { kind = "none" },
//!                               # { kind = "arx", order = 4, forgetting_factor = 0.98, p0 = 100.0 }
//! ```

use super::controller::{ControllerKind, ControllerSpec};
use super::run::SubstepSpec;
use crate::compensate::{ArxPhaseLagSpec, ErrorPairing, PhaseLagSpec, Ramp, Regressor};
use crate::error::{Error, Result};
use crate::substructure::ErrorForceSpec;
use crate::transfer::lti::TransferFunction;
use crate::transfer::noise::BENCHMARK_SEED;
use crate::transfer::servo::Derivative;
use serde::Deserialize;

/// The top-level keys (for docs and messages).
pub const CONFIG_KEYS: &[&str] = &["controller", "plant", "noise", "substep"];

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    controller: Option<RawController>,
    plant: Option<RawPlant>,
    noise: Option<RawNoise>,
    substep: Option<RawSubstep>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTf {
    num: Vec<f64>,
    den: Vec<f64>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawController {
    kind: Option<String>,
    converters: Option<bool>,
    feedforward: Option<RawTf>,
    feedback: Option<RawTf>,
    no_feedforward: Option<bool>,
    no_feedback: Option<bool>,
    ramp_start: Option<usize>,
    ramp_in: Option<usize>,
    arx: Option<RawArx>,
    polynomial: Option<RawPolynomial>,
    inverse_fir: Option<RawInverseFir>,
    ats: Option<RawAts>,
    amb: Option<RawAmb>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAmb {
    inverse_series: Option<[f64; 4]>,
    span: Option<usize>,
    smoothing: Option<f64>,
    threshold: Option<f64>,
    forgetting_factor: Option<f64>,
    subsample: Option<usize>,
    deviation: Option<f64>,
    adapted_terms: Option<usize>,
    p0: Option<f64>,
    instruments: Option<bool>,
    guard_factor: Option<f64>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAts {
    initial_lead: Option<f64>,
    window: Option<usize>,
    subsample: Option<usize>,
    span: Option<usize>,
    smoothing: Option<f64>,
    threshold: Option<f64>,
    guard_factor: Option<f64>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawArx {
    k_lag: Option<usize>,
    n_u: Option<usize>,
    forgetting_factor: Option<f64>,
    p0: Option<f64>,
    p_max: Option<f64>,
    scalar_covariance: Option<bool>,
    guard_factor: Option<f64>,
    regressor: Option<String>,
    pairing: Option<String>,
    span: Option<usize>,
    smoothing: Option<f64>,
    max_lead: Option<f64>,
    supervisor: Option<bool>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPolynomial {
    order: Option<usize>,
    lead: Option<f64>,
    spacing: Option<usize>,
    guard_factor: Option<f64>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInverseFir {
    lead: Option<f64>,
    taps: Option<usize>,
    order: Option<usize>,
    forgetting_factor: Option<f64>,
    p0: Option<f64>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlant {
    kind: Option<String>,
    derivative: Option<String>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawNoise {
    enabled: Option<bool>,
    seed: Option<u32>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSubstep {
    dt: Option<f64>,
    k_sub: Option<usize>,
    beta: Option<f64>,
    gamma: Option<f64>,
    error_force: Option<RawErrorForce>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawErrorForce {
    kind: String,
    p: Option<f64>,
    i: Option<f64>,
    d: Option<f64>,
    order: Option<usize>,
    forgetting_factor: Option<f64>,
    p0: Option<f64>,
}

/// Parsed settings (see the module docs).
#[derive(Debug, Clone, Default)]
pub struct BenchmarkConfig {
    raw: Raw,
}

fn toml_error(e: &toml::de::Error, text: &str, name: &str) -> Error {
    let message = e.message().split_whitespace().collect::<Vec<_>>().join(" ");
    match e.span() {
        Some(span) => {
            let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
            Error::file(name, format!("line {line}: {message}"))
        }
        None => Error::file(name, message),
    }
}

impl BenchmarkConfig {
    /// Parse `text` (`name` names the file in errors) and check every value.
    pub fn parse(text: &str, name: &str) -> Result<Self> {
        let raw: Raw = toml::from_str(text).map_err(|e| toml_error(&e, text, name))?;
        let cfg = Self { raw };
        let in_file = |e: Error| match e {
            Error::InvalidInput { what, reason } => Error::file(name, format!("{what}: {reason}")),
            other => other,
        };
        cfg.controller(None).map_err(in_file)?;
        cfg.substep().map_err(in_file)?;
        cfg.derivative().map_err(in_file)?;
        cfg.ideal_plant().map_err(in_file)?;
        cfg.noise().map_err(in_file)?;
        Ok(cfg)
    }

    /// The controller kind named in the file, if any.
    pub fn kind(&self) -> Result<Option<ControllerKind>> {
        match self.raw.controller.as_ref().and_then(|c| c.kind.as_deref()) {
            Some(k) => ControllerKind::parse(k)
                .map(Some)
                .map_err(|e| Error::invalid("controller.kind", e.to_string().replace("controller: ", ""))),
            None => Ok(None),
        }
    }

    /// The controller: `kind` (else the file's kind, else `sample`) with the file's settings
    /// over the kind's preset. Checks that it builds (Tustin stability included).
    pub fn controller(&self, kind: Option<ControllerKind>) -> Result<ControllerSpec> {
        let kind = match kind {
            Some(k) => k,
            None => self.kind()?.unwrap_or(ControllerKind::Sample),
        };
        let mut spec = ControllerSpec::preset(kind);
        let Some(c) = &self.raw.controller else {
            return Ok(spec);
        };
        if let Some(v) = c.converters {
            spec.converters = v;
        }
        if c.no_feedforward == Some(true) {
            spec.feedforward = None;
        }
        if c.no_feedback == Some(true) {
            spec.feedback = None;
        }
        if let Some(tf) = &c.feedforward {
            spec.feedforward = Some(TransferFunction::new("controller.feedforward", &tf.num, &tf.den)?);
        }
        if let Some(tf) = &c.feedback {
            spec.feedback = Some(TransferFunction::new("controller.feedback", &tf.num, &tf.den)?);
        }
        if c.ramp_start.is_some() || c.ramp_in.is_some() {
            spec.ramp = Ramp::new(
                c.ramp_start.unwrap_or(spec.ramp.start),
                c.ramp_in.unwrap_or(spec.ramp.ramp_in),
            );
        }
        match (&mut spec.phase_lag, kind) {
            (Some(PhaseLagSpec::Arx(a)), ControllerKind::Arx) => {
                if let Some(r) = &c.arx {
                    if let Some(k) = r.k_lag {
                        // The defaults that follow k_lag: the span, smoothing and lead bound.
                        *a = ArxPhaseLagSpec { k_lag: k, ..*a }.with_span(k);
                    }
                    if let Some(s) = r.span {
                        *a = a.with_span(s);
                    }
                    a.smoothing = r.smoothing.unwrap_or(a.smoothing);
                    a.max_lead = r.max_lead.map(Some).unwrap_or(a.max_lead);
                    if r.supervisor == Some(false) {
                        a.max_lead = None;
                    }
                    a.n_u = r.n_u.unwrap_or(a.n_u);
                    a.lambda = r.forgetting_factor.unwrap_or(a.lambda);
                    a.p0 = r.p0.unwrap_or(a.p0);
                    a.p_max = r.p_max.or(a.p_max);
                    a.scalar_covariance = r.scalar_covariance.unwrap_or(a.scalar_covariance);
                    a.guard_factor = r.guard_factor.unwrap_or(a.guard_factor);
                    if let Some(s) = &r.regressor {
                        a.regressor = match s.as_str() {
                            "full" => Regressor::Full,
                            "correction_velocity" => Regressor::CorrectionVelocity,
                            "velocity_error" => Regressor::VelocityError,
                            "velocity" => Regressor::Velocity,
                            _ => {
                                return Err(Error::invalid(
                                    "controller.arx.regressor",
                                    format!("unknown `{s}` (full, correction_velocity, velocity_error, velocity)"),
                                ));
                            }
                        };
                    }
                    if let Some(s) = &r.pairing {
                        a.pairing = match s.as_str() {
                            "current" => ErrorPairing::Current,
                            "delayed" => ErrorPairing::Delayed,
                            _ => {
                                return Err(Error::invalid(
                                    "controller.arx.pairing",
                                    format!("unknown `{s}` (current, delayed)"),
                                ));
                            }
                        };
                    }
                }
            }
            (
                Some(PhaseLagSpec::Polynomial {
                    order,
                    lead,
                    spacing,
                    guard_factor,
                }),
                ControllerKind::Polynomial,
            ) => {
                if let Some(r) = &c.polynomial {
                    *order = r.order.unwrap_or(*order);
                    *lead = r.lead.unwrap_or(*lead);
                    *spacing = r.spacing.unwrap_or(*spacing);
                    *guard_factor = r.guard_factor.unwrap_or(*guard_factor);
                }
            }
            (Some(PhaseLagSpec::Ats(s)), ControllerKind::Ats) => {
                if let Some(r) = &c.ats {
                    if let Some(l) = r.initial_lead {
                        // Bounds and rate limits follow the expected delay.
                        *s = crate::compensate::AtsSpec {
                            window: s.window,
                            subsample: s.subsample,
                            span: s.span,
                            smoothing: s.smoothing,
                            threshold: s.threshold,
                            guard_factor: s.guard_factor,
                            ..crate::compensate::AtsSpec::new(l)
                        };
                    }
                    s.window = r.window.unwrap_or(s.window);
                    s.subsample = r.subsample.unwrap_or(s.subsample);
                    s.span = r.span.unwrap_or(s.span);
                    s.smoothing = r.smoothing.unwrap_or(s.smoothing);
                    s.threshold = r.threshold.unwrap_or(s.threshold);
                    s.guard_factor = r.guard_factor.unwrap_or(s.guard_factor);
                }
            }
            (Some(PhaseLagSpec::Amb(s)), ControllerKind::Amb) => {
                if let Some(r) = &c.amb {
                    s.series = r.inverse_series.unwrap_or(s.series);
                    s.span = r.span.unwrap_or(s.span);
                    s.smoothing = r.smoothing.unwrap_or(s.smoothing);
                    s.threshold = r.threshold.unwrap_or(s.threshold);
                    s.lambda = r.forgetting_factor.unwrap_or(s.lambda);
                    s.subsample = r.subsample.unwrap_or(s.subsample);
                    s.deviation = r.deviation.unwrap_or(s.deviation);
                    s.adapted_terms = r.adapted_terms.unwrap_or(s.adapted_terms);
                    s.p0 = r.p0.unwrap_or(s.p0);
                    s.instruments = r.instruments.unwrap_or(s.instruments);
                    s.guard_factor = r.guard_factor.unwrap_or(s.guard_factor);
                }
            }
            (Some(PhaseLagSpec::InverseFir(s)), ControllerKind::InverseFir) => {
                if let Some(r) = &c.inverse_fir {
                    s.lead = r.lead.unwrap_or(s.lead);
                    s.taps = r.taps.unwrap_or(s.taps);
                    s.order = r.order.unwrap_or(s.order);
                    s.lambda = r.forgetting_factor.unwrap_or(s.lambda);
                    s.p0 = r.p0.unwrap_or(s.p0);
                }
            }
            _ => {}
        }
        spec.build(super::controller::SAMPLE_TIME).map_err(|e| match e {
            Error::InvalidInput { what, reason } if what.starts_with("phase_lag.") => Error::invalid(
                format!("controller.{}.{}", kind.name(), &what["phase_lag.".len()..]),
                reason,
            ),
            other => other,
        })?;
        Ok(spec)
    }

    /// The sub-step settings (defaults: [`SubstepSpec::default`]).
    pub fn substep(&self) -> Result<SubstepSpec> {
        let mut s = SubstepSpec::default();
        if let Some(r) = &self.raw.substep {
            s.dt = r.dt.unwrap_or(s.dt);
            s.k_sub = r.k_sub.unwrap_or(s.k_sub);
            s.beta = r.beta.unwrap_or(s.beta);
            s.gamma = r.gamma.unwrap_or(s.gamma);
            if let Some(e) = &r.error_force {
                s.error_force = match e.kind.as_str() {
                    "none" => ErrorForceSpec::None,
                    "pid" => ErrorForceSpec::Pid {
                        p: e.p.unwrap_or(1.0),
                        i: e.i.unwrap_or(0.0),
                        d: e.d.unwrap_or(0.0),
                    },
                    "arx" => {
                        let ErrorForceSpec::Arx { order, lambda, p0 } = ErrorForceSpec::ARX_DEFAULT else {
                            unreachable!()
                        };
                        ErrorForceSpec::Arx {
                            order: e.order.unwrap_or(order),
                            lambda: e.forgetting_factor.unwrap_or(lambda),
                            p0: e.p0.unwrap_or(p0),
                        }
                    }
                    k => {
                        return Err(Error::invalid(
                            "substep.error_force.kind",
                            format!("unknown `{k}` (none, pid, arx)"),
                        ));
                    }
                };
            }
        }
        s.samples_per_step()?;
        Ok(s)
    }

    /// `true` for `[plant] kind = "ideal"` (x = desired; no plant, the controller is unused).
    pub fn ideal_plant(&self) -> Result<bool> {
        match self.raw.plant.as_ref().and_then(|p| p.kind.as_deref()) {
            None | Some("servo") => Ok(false),
            Some("ideal") => Ok(true),
            Some(s) => Err(Error::invalid("plant.kind", format!("unknown `{s}` (servo, ideal)"))),
        }
    }

    pub fn derivative(&self) -> Result<Derivative> {
        match self.raw.plant.as_ref().and_then(|p| p.derivative.as_deref()) {
            None | Some("finite_difference") => Ok(Derivative::FiniteDifference),
            Some("exact") => Ok(Derivative::Exact),
            Some(s) => Err(Error::invalid(
                "plant.derivative",
                format!("unknown `{s}` (finite_difference, exact)"),
            )),
        }
    }

    /// `(enabled, seed)`.
    pub fn noise(&self) -> Result<(bool, u32)> {
        let n = self.raw.noise.clone().unwrap_or_default();
        let seed = n.seed.unwrap_or(BENCHMARK_SEED);
        crate::transfer::noise::MinStdPolar::new(seed)?;
        Ok((n.enabled.unwrap_or(true), seed))
    }
}
