//! Ground motions: readers, generators, resampling.
//!
//! # Conventions
//!
//! * Units are SI: time in s, ground acceleration `a_g` in m/s². Records given in g (PEER
//!   `.AT2`) are converted with the standard gravity [`G`] = 9.80665 m/s².
//! * A [`Record`] is sampled uniformly: sample `i` is the value at `t = i·dt`, so sample 0 is
//!   `t = 0` and the record lasts `(len − 1)·dt`.
//! * Between samples the record is interpolated linearly. Before `t = 0` and after the end of
//!   the record the ground is at rest: [`Record::value_at`] and [`Record::resample`] return
//!   `0.0` there (a record that does not end at zero thus jumps to zero after its end).
//! * All sample counts are `floor(duration/dt + 1e-9) + 1` (the last sample is at or just before
//!   `duration`); resampled and generated records are limited to [`MAX_SAMPLES`].
//!
//! # Inputs and errors
//!
//! Only the `read_*` functions touch the file system; each has a `parse_*` twin that takes the
//! file content and a name used in messages. Every bad input gives a one-line
//! [`Error`](crate::error::Error) naming the file (and line) or the parameter, e.g.
//! `ag.csv: line 17: cannot parse 'abc' as a number`.
//!
//! Generators ([`harmonic`], [`sine_sweep`], [`kanai_tajimi`]) are deterministic: the stochastic
//! one is seeded explicitly.

mod generators;
mod readers;
mod record;
pub mod spectrum;

pub use generators::{Envelope, KanaiTajimi, harmonic, kanai_tajimi, sine_sweep};
pub use readers::{
    parse_at2, parse_single_column, parse_two_column, read_at2, read_record, read_record_with, read_single_column,
    read_two_column,
};
pub use record::Record;

/// Standard gravity in m/s², used to convert records given in g.
pub const G: f64 = 9.80665;

/// Largest number of samples of a resampled or generated record, so that a wrong `dt` or
/// duration gives an error instead of exhausting memory.
pub const MAX_SAMPLES: usize = 100_000_000;
