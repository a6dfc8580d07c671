//! Lab targets: substep as the host of a lab's real-time controller (docs/lab.md).
//!
//! * [`frames`]: the byte layouts — OpenFresco's ECSpeedgoat and ECGenericTCP frames and
//!   substep's own lab I/O (`substep_udp`), pure functions;
//! * [`channels`]: which target signal is which command or measurement, with calibration;
//! * [`target`]: [`LabTarget`], one bounded exchange per sub-step as an
//!   [`ExperimentalSubstructure`](crate::substructure::ExperimentalSubstructure), with the hold
//!   policy and the link statistics;
//! * [`emulator`]: [`Emulator`], a target that serves any of the protocols with the virtual lab
//!   behind it and injects faults.
//!
//! Next to [`crate::site`] (remote sites speaking substep's SSTP or OpenFresco's element
//! protocol), this is the lab side of OpenFresco's layering: the experimental control.

pub mod channels;
pub mod emulator;
pub mod frames;
mod link;
pub mod target;

pub use channels::{ChannelMap, CommandChannel, MeasuredChannel, Quantity};
pub use emulator::{Emulator, EmulatorReport, EmulatorSpec, Faults};
pub use link::LinkTransport;
pub use target::{LabProtocol, LabStats, LabTarget, LabTargetSpec};
