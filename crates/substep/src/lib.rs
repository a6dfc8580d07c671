//! # substep
//!
//! Real-time substructure testing (hybrid simulation) with Dorka's sub-step control:
//! Newmark-type implicit integration of a linear numerical substructure, the sub-step
//! controller that drives the coupling DOFs of an experimental substructure, error-force and
//! phase-lag compensation, and the accuracy/stability analysis of the whole algorithm.
//!
//! Large numerical substructures use sparse storage ([`model::SparseModel`], [`sparse`]):
//! banded or sparse Cholesky of the effective stiffness, factorised once, allocation-free steps.
//!
//! Equations and sign conventions are those of `docs/theory.md` (layers:
//! `docs/architecture.md`); units are SI throughout.
//! The numerical core does no I/O; readers for ground-motion files live in [`excitation`],
//! MatrixMarket and TOML test definitions (and the runner for a defined test) in [`io`]. What a
//! run leaves on disk (its output folder, figures) is made by [`output`] and [`figure`], so
//! every front end writes the same files.

pub mod atomic_file;
pub mod error;
pub mod excitation;
pub mod figure;
pub mod format;
pub mod integrate;
pub mod io;
pub mod model;
pub mod monitor;
pub mod output;
pub mod realtime;
pub mod run;
pub mod session;

pub use error::{Error, Result};
pub mod analysis;
pub mod bench;
pub mod benchmark;
pub mod compensate;
pub mod ident;
pub mod lab;
pub mod latency;
pub mod limits;
pub mod linalg;
pub mod material;
pub mod site;
pub mod sparse;
pub mod specimen;
pub mod study;
pub mod substructure;
pub mod transfer;
