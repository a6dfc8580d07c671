//! Remote experimental sites: the experimental substructure runs in another process or on
//! another machine (the lab PC next to the actuators) and the controller talks to it over the
//! network.
//!
//! * [`protocol`]: the project's own framed, versioned, little-endian protocol (`SSTP`), with a
//!   handshake and two modes: **per sub-step** (one round trip per sub-step; the controller stays
//!   where it is) and **per step** (the site executes the `k_sub` sub-steps of a step itself —
//!   the distributed sub-step scheme — and returns every sub-step's command, force and
//!   displacement, one round trip per step).
//! * [`server`]: [`SiteServer`] hosts any [`ExperimentalSubstructure`] over TCP or UDP, built
//!   per connection by a factory from the client's handshake — e.g. [`VirtualLabSpec`], a
//!   [`crate::transfer::VirtualLab`] whose specimens are attached to the client's coupling DOFs.
//! * [`client`]: [`RemoteSite`] (per sub-step) implements [`ExperimentalSubstructure`] so a
//!   [`crate::substructure::SubstructureTest`] can run against a remote site unchanged;
//!   [`RemoteStepSite`] / [`RemoteStepTest`] drive the per-step mode.
//! * [`openfresco`]: the OpenFresco/OpenSees `genericClient` protocol, both as a server (so an
//!   OpenSees model can use a `substep` site as an element) and as a client (so `substep` can
//!   drive an OpenFresco-style site).
//!
//! Everything uses `std::net` and threads; no async runtime. See `docs/openfresco.md`.

pub mod client;
pub mod openfresco;
pub mod protocol;
pub mod server;
mod transport;

pub use client::{ClientOptions, RemoteSite, RemoteStepSite, RemoteStepTest, SiteClient, Transport, run_remote_step};
pub use protocol::{Hello, Message, MessageType, Mode, StepReply, StepRequest};
pub use server::{ServeOptions, ServeReport, ServerHandle, SiteServer, VirtualLabSpec};

use crate::error::Result;
use crate::substructure::ExperimentalSubstructure;
use nalgebra::{DMatrix, DVector};
use std::sync::Arc;

/// A one-line log sink (connection opened/closed, errors). Called from the server thread.
pub type LogFn = Arc<dyn Fn(&str) + Send + Sync>;

/// Builds the experimental substructure for one connection from the client's handshake
/// (which gives `n_c`, `k_sub`, `Δt` and `Δτ`, e.g. for [`crate::transfer::VirtualLab::from_specs`]).
/// An `Err` rejects the connection with the error's message.
pub type SiteFactory = Box<dyn FnMut(&Hello) -> Result<Box<dyn ExperimentalSubstructure>> + Send>;

/// The command ramp of the sub-step algorithm (docs/theory.md §3.4; per-step sites: §3.11),
/// computed with exactly the same floating-point operations as
/// [`crate::substructure::SubstepController::next_command`], so a site that runs the sub-steps
/// itself reproduces the controller's commands bit for bit:
/// `d^{(j)} = (1 − r_j) x̂_c^{(i)} + r_j x̂_c + G_cc f^{(j−1)}`, `r_j = j/k` (`j` 1-based).
pub struct CommandRamp {
    k_sub: usize,
    gain_cc: DMatrix<f64>,
    predictor_c_prev: DVector<f64>,
    predictor_c: DVector<f64>,
    force_last: DVector<f64>,
    command: DVector<f64>,
    substep: usize,
}

impl CommandRamp {
    /// `gain_cc` column-major `n_c × n_c`.
    pub fn new(n_c: usize, k_sub: usize, gain_cc: &[f64]) -> Self {
        Self {
            k_sub,
            gain_cc: DMatrix::from_column_slice(n_c, n_c, gain_cc),
            predictor_c_prev: DVector::zeros(n_c),
            predictor_c: DVector::zeros(n_c),
            force_last: DVector::zeros(n_c),
            command: DVector::zeros(n_c),
            substep: 0,
        }
    }

    /// Start a step with the previous and current predictor (coupling parts) and `f^{(0)}`.
    pub fn begin(&mut self, predictor_c_prev: &[f64], predictor_c: &[f64], force_prev: &[f64]) {
        self.predictor_c_prev.copy_from_slice(predictor_c_prev);
        self.predictor_c.copy_from_slice(predictor_c);
        self.force_last.copy_from_slice(force_prev);
        self.substep = 0;
    }

    /// The command of the next sub-step.
    pub fn next_command(&mut self) -> &[f64] {
        let r = (self.substep + 1) as f64 / self.k_sub as f64;
        self.command.copy_from(&self.predictor_c_prev);
        self.command.scale_mut(1.0 - r);
        self.command.axpy(r, &self.predictor_c, 1.0);
        self.command.gemv(1.0, &self.gain_cc, &self.force_last, 1.0);
        self.command.as_slice()
    }

    /// The force measured at the end of the sub-step.
    pub fn feedback(&mut self, force: &[f64]) {
        self.force_last.copy_from_slice(force);
        self.substep += 1;
    }
}

pub use crate::substructure::substep_ground_acceleration;
