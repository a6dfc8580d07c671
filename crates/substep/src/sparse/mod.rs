//! Sparse linear algebra for large numerical substructures: square CSC matrices
//! ([`CscMatrix`]), a once-factorised symmetric positive definite solver with allocation-free
//! solves ([`SymmetricFactor`]: banded Cholesky or faer's sparse Cholesky with AMD ordering),
//! and the lowest natural frequencies by subspace iteration ([`lowest_frequencies`]).

mod csc;
mod factor;
mod modes;

pub use csc::CscMatrix;
pub use factor::{FactorKind, SymmetricFactor};
pub use modes::lowest_frequencies;
