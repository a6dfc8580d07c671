//! `[substructure.actuator]` (docs/config.md, section `[substructure.actuator]`): actuator
//! dynamics, delay, servo-hydraulic plant.

use crate::error::{Error, Result};
use crate::transfer::lti::{StateSpace, TransferFunction};
use crate::transfer::servo::{Derivative, HydraulicActuator};
use crate::transfer::{ActuatorSpec, Dynamics, ServoSpec};
use nalgebra::{DMatrix, DVector};
use serde::Deserialize;

#[derive(Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub(crate) enum RawActuator {
    Ideal {
        #[serde(default)]
        delay: f64,
    },
    Delay {
        delay: f64,
    },
    FirstOrder {
        time_constant: f64,
        #[serde(default)]
        delay: f64,
    },
    SecondOrder {
        frequency: f64,
        zeta: f64,
        #[serde(default)]
        delay: f64,
    },
    /// `num / den` in descending powers of s.
    TransferFunction {
        num: Vec<f64>,
        den: Vec<f64>,
        #[serde(default)]
        delay: f64,
    },
    StateSpace {
        a: Vec<Vec<f64>>,
        b: Vec<f64>,
        c: Vec<f64>,
        #[serde(default)]
        d: f64,
        #[serde(default)]
        delay: f64,
    },
    /// Defaults: the benchmark's nominal plant ([`ServoSpec::benchmark`]).
    ServoHydraulic {
        g: Option<f64>,
        a1_beta0: Option<f64>,
        beta1: Option<f64>,
        beta2: Option<f64>,
        a2: Option<f64>,
        a3: Option<f64>,
        /// `"finite_difference"` (default, the benchmark's block) or `"exact"`.
        csi_derivative: Option<String>,
        #[serde(default)]
        delay: f64,
    },
    /// A servo-hydraulic actuator from physical parameters ([`HydraulicActuator`]).
    Hydraulic {
        piston_area: f64,
        oil_stiffness: Option<f64>,
        bulk_modulus: Option<f64>,
        oil_volume: Option<f64>,
        #[serde(default)]
        leakage: f64,
        valve_flow: f64,
        valve_frequency: f64,
        #[serde(default = "default_valve_damping")]
        valve_damping: f64,
        kp: f64,
        #[serde(default = "one")]
        command_gain: f64,
        #[serde(default)]
        delay: f64,
    },
}

fn default_valve_damping() -> f64 {
    0.7
}

fn one() -> f64 {
    1.0
}

impl RawActuator {
    /// Errors name keys as `actuator.KEY` (the caller prefixes the section).
    pub(crate) fn spec(&self) -> Result<ActuatorSpec> {
        Ok(match self {
            RawActuator::Ideal { delay } | RawActuator::Delay { delay } => ActuatorSpec {
                dynamics: Dynamics::Ideal,
                delay: *delay,
            },
            RawActuator::FirstOrder { time_constant, delay } => ActuatorSpec {
                dynamics: Dynamics::FirstOrder {
                    time_constant: *time_constant,
                },
                delay: *delay,
            },
            RawActuator::SecondOrder { frequency, zeta, delay } => ActuatorSpec {
                dynamics: Dynamics::SecondOrder {
                    frequency_hz: *frequency,
                    zeta: *zeta,
                },
                delay: *delay,
            },
            RawActuator::TransferFunction { num, den, delay } => {
                if den.iter().all(|&v| v == 0.0) {
                    return Err(Error::invalid("actuator.den", "is zero (no transfer function)"));
                }
                let tf = TransferFunction::new("actuator", num, den)?;
                ActuatorSpec {
                    dynamics: Dynamics::Lti(tf.to_state_space()),
                    delay: *delay,
                }
            }
            RawActuator::StateSpace { a, b, c, d, delay } => {
                let n = a.len();
                if n == 0 {
                    return Err(Error::invalid("actuator.a", "is empty"));
                }
                if let Some(r) = a.iter().position(|row| row.len() != n) {
                    return Err(Error::invalid(
                        "actuator.a",
                        format!(
                            "must be square: row {} has {} entries, A has {n} rows",
                            r + 1,
                            a[r].len()
                        ),
                    ));
                }
                for (key, v) in [("b", b), ("c", c)] {
                    if v.len() != n {
                        return Err(Error::invalid(
                            format!("actuator.{key}"),
                            format!("has {} entries, A is {n}x{n}", v.len()),
                        ));
                    }
                }
                let am = DMatrix::from_fn(n, n, |i, j| a[i][j]);
                let ss = StateSpace::new(
                    "actuator",
                    am,
                    DVector::from_column_slice(b),
                    DVector::from_column_slice(c),
                    *d,
                )?;
                ActuatorSpec {
                    dynamics: Dynamics::Lti(ss),
                    delay: *delay,
                }
            }
            RawActuator::ServoHydraulic {
                g,
                a1_beta0,
                beta1,
                beta2,
                a2,
                a3,
                csi_derivative,
                delay,
            } => {
                let base = ServoSpec::benchmark();
                let derivative = match csi_derivative.as_deref().unwrap_or("finite_difference") {
                    "finite_difference" => Derivative::FiniteDifference,
                    "exact" => Derivative::Exact,
                    other => {
                        return Err(Error::invalid(
                            "actuator.csi_derivative",
                            format!("unknown '{other}' (expected finite_difference or exact)"),
                        ));
                    }
                };
                ActuatorSpec {
                    dynamics: Dynamics::ServoHydraulic(ServoSpec {
                        g: g.unwrap_or(base.g),
                        a1_beta0: a1_beta0.unwrap_or(base.a1_beta0),
                        beta1: beta1.unwrap_or(base.beta1),
                        beta2: beta2.unwrap_or(base.beta2),
                        a2: a2.unwrap_or(base.a2),
                        a3: a3.unwrap_or(base.a3),
                        derivative,
                    }),
                    delay: *delay,
                }
            }
            RawActuator::Hydraulic {
                piston_area,
                oil_stiffness,
                bulk_modulus,
                oil_volume,
                leakage,
                valve_flow,
                valve_frequency,
                valve_damping,
                kp,
                command_gain,
                delay,
            } => {
                let oil_stiffness = match (oil_stiffness, bulk_modulus, oil_volume) {
                    (Some(k), None, None) => *k,
                    (None, Some(b), Some(v)) => {
                        crate::error::require_positive("actuator.bulk_modulus", *b)?;
                        crate::error::require_positive("actuator.oil_volume", *v)?;
                        HydraulicActuator::oil_stiffness(*b, *piston_area, *v)
                    }
                    _ => {
                        return Err(Error::invalid(
                            "actuator.oil_stiffness",
                            "give either oil_stiffness [N/m] or both bulk_modulus [Pa] and oil_volume [m^3] \
                             (k_oil = 4 bulk_modulus piston_area^2 / oil_volume)",
                        ));
                    }
                };
                let h = HydraulicActuator {
                    piston_area: *piston_area,
                    oil_stiffness,
                    leakage: *leakage,
                    valve_flow: *valve_flow,
                    valve_frequency_hz: *valve_frequency,
                    valve_damping: *valve_damping,
                    kp: *kp,
                    command_gain: *command_gain,
                };
                h.validate()?;
                ActuatorSpec {
                    dynamics: Dynamics::ServoHydraulic(ServoSpec::from_physical(&h)),
                    delay: *delay,
                }
            }
        })
    }
}
