//! Ground motions: readers, generators, resampling.
