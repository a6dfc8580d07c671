//! Study drivers: a fixed set-up run over a set of methods or parameters, returning typed
//! results (numbers and series, no files). Front ends print, plot and write them.
//!
//! * [`vst`]: the virtual substructure test study (every compensation method against the exact
//!   reference, docs/vst.md).

pub mod vst;
