//! Everything a run leaves on disk, made here so that every front end (the `substep` command,
//! the Python package) writes the same files byte for byte:
//!
//! * [`folder`]: the output folder of a run ([`RunFolder`], [`run_in_folder`]): `history.csv`,
//!   `substeps.csv`, `response.csv`, the ground-motion tables, the figures and `summary.json`;
//! * [`files`]: the row writers, the decimated series of the figures, atomic replacement and the
//!   list of files a run owns in its folder;
//! * [`response`]: the engineering outputs (`response.csv`, `ground_motion.csv`, `fourier.csv`,
//!   `spectrum.csv`) and their figures;
//! * [`container`]: `results.h5` / `results.mat` gathered from the tables after the run.
//!
//! The figures themselves are drawn by [`crate::figure`].

pub mod container;
pub mod files;
pub mod folder;
pub mod response;

pub use folder::{FolderOptions, FolderRun, RunFolder, run_in_folder};
