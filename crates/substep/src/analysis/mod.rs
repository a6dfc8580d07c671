//! Accuracy and stability analysis of the complete sub-step algorithm (docs/theory.md §9).
//!
//! The one-step map `X_{i+1} = 𝔸 X_i + 𝔹₀ a_g,i + 𝔹₁ a_g,i+1` is probed from the library's own
//! step function ([`amplification::StepMap::probe`]), so the analysis and the simulation cannot
//! disagree. On top of it: spectral radius and stability class, stability maps over parameter
//! grids, and the discrete frequency response with amplitude and period errors.

pub mod accuracy;
pub mod amplification;
pub mod converged;
pub mod energy;
pub mod frequency;
pub mod metrics;
pub mod plan;
pub mod spectral;
pub mod stability;
pub mod storey;
pub mod tmd_case;
pub mod tracking;
pub mod verification;
pub mod verify;

pub use amplification::{FrequencyResponse, Stability, StepMap};
pub use tmd_case::{AnalysisCase, AnalysisScheme, FrozenPhaseLag, Parameter};
