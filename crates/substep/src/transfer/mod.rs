//! Transfer systems (spec §5): what happens between the command `d^{(j)}` computed by the
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
//! Displacement-sensor filter states and noise generators are not part of the saved state
//! (they never feed back into the algorithm).

mod actuator;
mod lab;
mod sensor;

pub use actuator::{Actuator, ActuatorSpec, DELAY_MAX_SAMPLES, DelayLine, Dynamics};
pub use lab::{AttachedSpecimen, VirtualLab};
pub use sensor::{Sensor, SensorSpec, channel_seed, channel_sensors};
