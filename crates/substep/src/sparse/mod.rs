//! Sparse linear algebra for large numerical substructures: square CSC matrices
//! ([`CscMatrix`]), a once-factorised symmetric positive definite solver with allocation-free
//! solves ([`SymmetricFactor`]: banded Cholesky, or faer's supernodal Cholesky under an AMD or
//! nested-dissection ordering with our streaming solve); the lowest natural frequencies of a sparse
//! model use these factors (`model::lowest_frequencies`, shift-invert Lanczos).

mod csc;
mod factor;
mod ordering;
mod supernodal;
mod symmetric;

pub use csc::CscMatrix;
pub use factor::{FactorKind, SparseOrdering, SymmetricFactor};
pub(crate) use supernodal::HugeBuf;
pub use symmetric::SymmetricProduct;
