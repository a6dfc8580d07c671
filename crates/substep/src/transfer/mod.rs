//! Transfer systems (docs/theory.md §7): what happens between the command `d^{(j)}` computed by the
//! sub-step controller and the force measured on the specimen — actuator dynamics, delays,
//! sensors with noise, quantisation and filtering — and the [`VirtualLab`] that composes them
//! with virtual specimens.
//!
//! Convention: the command to an actuator is a continuous signal, linear between the
//! sub-step commands (an ideal actuator therefore moves the specimen linearly over a sub-step).
//! Delays and dynamics act on that signal on an inner grid of `inner_steps` intervals per
//! sub-step: the dynamics are integrated exactly (first-order hold) for an input that is linear
//! over each inner interval. A fractional delay moves the corners of the command signal off
//! that grid, which costs an `O(h²)` interpolation error (bounded; see `tests/transfer.rs`).
//! Displacement-sensor filter states and noise generators are not part of the saved state: the
//! sub-step algorithm reads only forces, but a phase-lag compensator that reads the measured
//! displacement (ARX, inverse FIR) does see them, so a frozen-compensator analysis of a lab with
//! a displacement low-pass omits that state (docs/theory.md §6.7).
//!
//! Lab-grade building blocks (used by the RTHS benchmark, [`crate::benchmark::rths`]): continuous
//! LTI systems from transfer functions or state space ([`lti`]), Tustin-discretised controllers
//! ([`discrete`]), the servo-hydraulic actuator with control–structure interaction ([`servo`]),
//! noise given as power or σ with the benchmark's generator ([`noise`]) and A/D–D/A converters
//! ([`converter`]). [`ControlledSite`] puts a Tustin-discretised tracking controller in front
//! of a site.

mod actuator;
mod controlled;
pub mod converter;
mod delay_ramp;
pub mod discrete;
pub mod kinematics;
mod lab;
pub mod lti;
pub mod mimo;
pub mod noise;
mod sensor;
pub mod servo;

pub use actuator::{Actuator, ActuatorSpec, DELAY_MAX_SAMPLES, DelayLine, Dynamics, ServoSpec};
pub use controlled::ControlledSite;
pub use delay_ramp::{DelayRamp, DelayRampSite, MAX_RAMP_DELAY};
pub use lab::{AttachedSpecimen, LabOptions, VirtualLab};
pub use sensor::{NoiseGenerator, Sensor, SensorSpec, channel_seed, channel_seed_for, channel_sensors};
