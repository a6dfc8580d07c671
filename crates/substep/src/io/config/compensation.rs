//! `[substructure.error_force]` and `[substructure.phase_lag]` (docs/config.md, sections of the
//! same names): the compensation methods.

use super::common::{forbid, one, prefixed};
use crate::compensate::{AmbSpec, ArxPhaseLagSpec, AtsSpec, InverseFirSpec, PhaseLagDefinition, PhaseLagSpec, Ramp};
use crate::error::{Error, Result, require_non_negative};
use crate::substructure::ErrorForceSpec;
use serde::Deserialize;

#[derive(Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub(crate) enum RawErrorForce {
    None {},
    Pid {
        #[serde(default = "one")]
        p: f64,
        #[serde(default)]
        i: f64,
        #[serde(default)]
        d: f64,
    },
    PidResidual {
        #[serde(default = "one")]
        p: f64,
    },
    Arx {
        #[serde(default = "default_arx_order")]
        order: usize,
        #[serde(default = "default_arx_lambda")]
        forgetting_factor: f64,
        #[serde(default = "default_arx_p0")]
        p0: f64,
    },
}

pub(crate) fn default_arx_order() -> usize {
    4
}
pub(crate) fn default_arx_lambda() -> f64 {
    0.98
}
pub(crate) fn default_arx_p0() -> f64 {
    100.0
}

/// `[substructure.phase_lag]`; which keys apply depends on `kind` (checked in `build`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawPhaseLag {
    pub(crate) kind: String,
    pub(crate) order: Option<usize>,
    pub(crate) lead: Option<f64>,
    pub(crate) lead_substeps: Option<f64>,
    pub(crate) k_lag: Option<usize>,
    pub(crate) n_u: Option<usize>,
    pub(crate) forgetting_factor: Option<f64>,
    pub(crate) taps: Option<usize>,
    pub(crate) guard_factor: Option<f64>,
    pub(crate) span: Option<usize>,
    pub(crate) smoothing: Option<f64>,
    pub(crate) max_lead: Option<f64>,
    pub(crate) supervisor: Option<bool>,
    pub(crate) window: Option<f64>,
    pub(crate) threshold: Option<f64>,
    pub(crate) spacing: Option<usize>,
    pub(crate) inverse_series: Option<[f64; 4]>,
    pub(crate) deviation: Option<f64>,
    pub(crate) adapted_terms: Option<usize>,
    pub(crate) ramp_start: Option<usize>,
    pub(crate) ramp_steps: Option<usize>,
    pub(crate) fade_out: Option<[usize; 2]>,
}

impl RawErrorForce {
    pub(crate) fn spec(&self) -> ErrorForceSpec {
        match *self {
            RawErrorForce::None {} => ErrorForceSpec::None,
            RawErrorForce::Pid { p, i, d } => ErrorForceSpec::Pid { p, i, d },
            RawErrorForce::PidResidual { p } => ErrorForceSpec::PidResidual { p },
            RawErrorForce::Arx {
                order,
                forgetting_factor,
                p0,
            } => ErrorForceSpec::Arx {
                order,
                lambda: forgetting_factor,
                p0,
            },
        }
    }
}

/// The keys of `kind = "arx"` alone (refused with the other kinds).
const ARX_ONLY: &[&str] = &["span", "smoothing", "max_lead", "supervisor"];
/// The keys of `kind = "ats"` alone.
const ATS_ONLY: &[&str] = &["window", "threshold"];
/// The keys of `kind = "amb"` alone.
const AMB_ONLY: &[&str] = &["inverse_series", "deviation", "adapted_terms"];

/// Default ramp-in of the phase-lag compensation [steps].
pub(crate) const DEFAULT_RAMP_STEPS: usize = 100;

impl RawPhaseLag {
    /// `None` for `kind = "none"`. `dt` time step, `k_sub` sub-steps; of the `actuator`: the pure
    /// delay \[s\] (the default lead), the low-frequency lag \[s\] (delay plus dynamics: the
    /// default `k_lag`) and the series of its inverse (the default model of `amb`).
    pub(crate) fn build(
        &self,
        dt: f64,
        k_sub: usize,
        actuator: &crate::transfer::ActuatorSpec,
    ) -> Result<Option<PhaseLagDefinition>> {
        let (delay, lag) = (actuator.delay, actuator.low_frequency_lag());
        let p = "substructure.phase_lag.";
        let dtau = dt / k_sub as f64;
        let keys = |names: &[&'static str]| -> Vec<(&'static str, bool)> {
            names
                .iter()
                .map(|&n| {
                    let present = match n {
                        "order" => self.order.is_some(),
                        "lead" => self.lead.is_some(),
                        "lead_substeps" => self.lead_substeps.is_some(),
                        "k_lag" => self.k_lag.is_some(),
                        "n_u" => self.n_u.is_some(),
                        "forgetting_factor" => self.forgetting_factor.is_some(),
                        "taps" => self.taps.is_some(),
                        "guard_factor" => self.guard_factor.is_some(),
                        "span" => self.span.is_some(),
                        "smoothing" => self.smoothing.is_some(),
                        "max_lead" => self.max_lead.is_some(),
                        "supervisor" => self.supervisor.is_some(),
                        "window" => self.window.is_some(),
                        "threshold" => self.threshold.is_some(),
                        "spacing" => self.spacing.is_some(),
                        "inverse_series" => self.inverse_series.is_some(),
                        "deviation" => self.deviation.is_some(),
                        "adapted_terms" => self.adapted_terms.is_some(),
                        "ramp_start" => self.ramp_start.is_some(),
                        "ramp_steps" => self.ramp_steps.is_some(),
                        "fade_out" => self.fade_out.is_some(),
                        _ => false,
                    };
                    (n, present)
                })
                .collect()
        };
        let kind = self.kind.as_str();
        let unused = format!("is not used with kind = \"{kind}\"");
        // The lead in sub-steps: `lead` [s] or `lead_substeps`, default the actuator delay.
        let lead = || -> Result<f64> {
            match (self.lead, self.lead_substeps) {
                (Some(_), Some(_)) => Err(Error::invalid(
                    format!("{p}lead_substeps"),
                    "give either lead [s] or lead_substeps, not both",
                )),
                (Some(l), None) => {
                    require_non_negative(&format!("{p}lead"), l)?;
                    Ok(l / dtau)
                }
                (None, Some(l)) => {
                    require_non_negative(&format!("{p}lead_substeps"), l)?;
                    Ok(l)
                }
                (None, None) => Ok(delay / dtau),
            }
        };
        let guard_factor = self.guard_factor.unwrap_or(10.0);
        let spec = match kind {
            "none" => {
                forbid(
                    p,
                    &keys(&[
                        "order",
                        "lead",
                        "lead_substeps",
                        "k_lag",
                        "n_u",
                        "forgetting_factor",
                        "taps",
                        "guard_factor",
                        "span",
                        "smoothing",
                        "max_lead",
                        "supervisor",
                        "window",
                        "threshold",
                        "spacing",
                        "inverse_series",
                        "deviation",
                        "adapted_terms",
                        "ramp_start",
                        "ramp_steps",
                        "fade_out",
                    ]),
                    &unused,
                )?;
                return Ok(None);
            }
            "polynomial" => {
                forbid(p, &keys(&["k_lag", "n_u", "forgetting_factor", "taps"]), &unused)?;
                forbid(p, &keys(ARX_ONLY), &unused)?;
                forbid(p, &keys(ATS_ONLY), &unused)?;
                forbid(p, &keys(AMB_ONLY), &unused)?;
                PhaseLagSpec::Polynomial {
                    order: self.order.unwrap_or(3),
                    lead: lead()?,
                    spacing: self.spacing.unwrap_or(1),
                    guard_factor,
                }
            }
            "arx" => {
                forbid(
                    p,
                    &keys(&["order", "lead", "lead_substeps", "taps", "spacing"]),
                    &unused,
                )?;
                forbid(p, &keys(ATS_ONLY), &unused)?;
                forbid(p, &keys(AMB_ONLY), &unused)?;
                // The actuator's lag in sub-steps, or the k_lag given.
                let lag = self.k_lag.map_or(lag / dtau, |k| k as f64);
                let mut spec = ArxPhaseLagSpec::for_substeps(lag, k_sub);
                if let Some(k) = self.k_lag {
                    // As given (0 is refused by the validation, not rounded up).
                    spec.k_lag = k;
                }
                if let Some(s) = self.span {
                    spec = spec.with_span(s);
                }
                if let Some(t) = self.smoothing {
                    spec.smoothing = t;
                }
                if let Some(l) = self.max_lead {
                    spec.max_lead = Some(l);
                }
                if self.supervisor == Some(false) {
                    if self.max_lead.is_some() {
                        return Err(Error::invalid(
                            format!("{p}max_lead"),
                            "is not used with supervisor = false",
                        ));
                    }
                    spec.max_lead = None;
                }
                if let Some(n) = self.n_u {
                    spec.n_u = n;
                }
                if let Some(l) = self.forgetting_factor {
                    spec.lambda = l;
                }
                spec.guard_factor = guard_factor;
                PhaseLagSpec::Arx(spec)
            }
            "inverse_fir" => {
                forbid(p, &keys(&["k_lag", "n_u", "guard_factor", "spacing"]), &unused)?;
                forbid(p, &keys(ARX_ONLY), &unused)?;
                forbid(p, &keys(ATS_ONLY), &unused)?;
                forbid(p, &keys(AMB_ONLY), &unused)?;
                let mut spec = InverseFirSpec::new(lead()?);
                if let Some(o) = self.order {
                    spec.order = o;
                }
                if let Some(t) = self.taps {
                    spec.taps = t;
                }
                if let Some(l) = self.forgetting_factor {
                    spec.lambda = l;
                }
                PhaseLagSpec::InverseFir(spec)
            }
            "ats" => {
                forbid(
                    p,
                    &keys(&["order", "k_lag", "n_u", "forgetting_factor", "taps", "spacing"]),
                    &unused,
                )?;
                forbid(p, &keys(&["span", "max_lead", "supervisor"]), &unused)?;
                forbid(p, &keys(AMB_ONLY), &unused)?;
                // The initial a₁: `lead`/`lead_substeps` if given, else the actuator's
                // low-frequency lag (delay plus dynamics), what the actuator's inverse starts from.
                let initial = if self.lead.is_some() || self.lead_substeps.is_some() {
                    lead()?
                } else {
                    lag / dtau
                };
                let mut spec = AtsSpec::new(initial);
                // A 1 s window (Chae et al. 2013), about 250 rows of it.
                let window_s = self.window.unwrap_or(1.0);
                if !(window_s.is_finite() && window_s > 0.0 && window_s / dtau <= (1u64 << 22) as f64) {
                    return Err(Error::invalid(
                        format!("{p}window"),
                        format!("must be a finite time > 0 s of at most 4194304 sub-steps, got {window_s}"),
                    ));
                }
                spec.window = (window_s / dtau).round() as usize;
                spec.subsample = (spec.window / 250).max(1);
                if let Some(t) = self.threshold {
                    spec.threshold = t;
                }
                if let Some(t) = self.smoothing {
                    spec.smoothing = t;
                }
                spec.guard_factor = guard_factor;
                PhaseLagSpec::Ats(spec)
            }
            "amb" => {
                forbid(
                    p,
                    &keys(&[
                        "order",
                        "k_lag",
                        "n_u",
                        "taps",
                        "spacing",
                        "max_lead",
                        "supervisor",
                        "window",
                    ]),
                    &unused,
                )?;
                // The model: `inverse_series` [sⁱ] if given, else a pure delay of `lead` if
                // given, else the actuator's (delay and dynamics).
                let given_lead = self.lead.is_some() || self.lead_substeps.is_some();
                if given_lead && self.inverse_series.is_some() {
                    return Err(Error::invalid(
                        format!("{p}inverse_series"),
                        "give either the model's inverse_series or a lead (a pure-delay model), not both",
                    ));
                }
                let seconds = match self.inverse_series {
                    Some(g) => g,
                    None if given_lead => {
                        let t = lead()? * dtau;
                        [1.0, t, t * t / 2.0, t * t * t / 6.0]
                    }
                    None => actuator.inverse_series(),
                };
                let series: [f64; 4] = std::array::from_fn(|i| seconds[i] / dtau.powi(i as i32));
                let mut spec = AmbSpec::pure_delay(series[1]);
                spec.series = series;
                // A memory of about 2 s.
                spec.lambda = 1.0 - dtau / 2.0;
                if let Some(s) = self.span {
                    spec.span = s;
                }
                spec.smoothing = self.smoothing.unwrap_or(spec.span as f64);
                if let Some(t) = self.threshold {
                    spec.threshold = t;
                }
                if let Some(l) = self.forgetting_factor {
                    spec.lambda = l;
                }
                if let Some(d) = self.deviation {
                    spec.deviation = d;
                }
                if let Some(n) = self.adapted_terms {
                    spec.adapted_terms = n;
                }
                spec.guard_factor = guard_factor;
                PhaseLagSpec::Amb(spec)
            }
            other => {
                return Err(Error::invalid(
                    format!("{p}kind"),
                    format!("unknown kind '{other}' (expected none, polynomial, arx, inverse_fir, ats or amb)"),
                ));
            }
        };
        let mut ramp = Ramp::new(
            self.ramp_start.unwrap_or(0).saturating_mul(k_sub),
            self.ramp_steps.unwrap_or(DEFAULT_RAMP_STEPS).saturating_mul(k_sub),
        );
        if let Some([begin, steps]) = self.fade_out {
            ramp = ramp.with_fade_out(begin.saturating_mul(k_sub), steps.saturating_mul(k_sub));
        }
        let def = PhaseLagDefinition { spec, ramp };
        def.validate().map_err(|e| prefixed(e, "substructure."))?;
        Ok(Some(def))
    }
}
