//! Experimental substructures (specimens).
//!
//! A specimen is attached to one or more coupling DOFs. The transfer system moves those DOFs
//! along a piecewise-linear trajectory; over each piece the specimen advances from its
//! committed state and reports the force it exerts **on the numerical substructure** (the sign
//! a load cell is wired to give, docs/theory.md §1.2). `commit` accepts the trial state. Displacements are
//! relative to the ground; the ground acceleration is given as well, for specimens with mass.

mod assemble;
mod bouc_wen;
mod friction;
mod linear;
mod lumped;
mod replay;
mod spec;

pub use assemble::{assemble_monolithic_model, assemble_monolithic_sparse};
pub use bouc_wen::{BoucWen, BoucWenParams, Pinching};
pub use friction::{Friction, FrictionModel};
pub use linear::LinearSpecimen;
pub use lumped::LumpedSdof;
pub use replay::Replay;
pub use spec::{LinearMatrices, SpecimenSpec, assemble_monolithic};

/// The motion imposed on a specimen over one interval: coupling displacements move linearly
/// from `d_start` to `d_end` \[m\] while the ground acceleration moves linearly from `ag_start`
/// to `ag_end` [m/s²], over `dt` \[s\].
#[derive(Debug, Clone, Copy)]
pub struct Motion<'a> {
    pub d_start: &'a [f64],
    pub d_end: &'a [f64],
    pub ag_start: f64,
    pub ag_end: f64,
    pub dt: f64,
}

/// A specimen: virtual (simulated) or a driver for hardware.
pub trait Specimen: Send {
    /// Short name of the kind, as in configs (`linear_sdof`, `bouc_wen`, ...).
    fn kind(&self) -> &'static str;
    /// Number of coupling DOFs the specimen is attached to.
    fn n_dofs(&self) -> usize;
    /// Advance from the committed state through `motion`; write the force on the structure at
    /// the end of the interval (one entry per attached DOF) into `force` \[N\].
    fn advance(&mut self, motion: &Motion, force: &mut [f64]);
    /// Accept the trial state computed by the last `advance`.
    fn commit(&mut self);
    /// Whether the force is a linear function of state and motion (required by the
    /// amplification-matrix analysis).
    fn is_linear(&self) -> bool;
    /// Length of the internal state vector (for checkpoints and the linear analysis).
    fn state_len(&self) -> usize;
    /// Committed internal state into `out` (`out.len() == state_len()`).
    fn write_state(&self, out: &mut [f64]);
    /// Set the committed internal state.
    fn read_state(&mut self, state: &[f64]);
}
