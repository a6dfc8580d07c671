//! The ground-motion record readers on any text: two columns, AT2, single column (its `dt` from
//! the first byte, so bad time steps are reached too). Corpus: `examples/ag_sweep.csv`.
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;
use substep::excitation::{parse_at2, parse_single_column, parse_two_column};

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    common::check(parse_two_column(&text, "fuzz.csv"));
    common::check(parse_at2(&text, "fuzz.AT2"));
    let dt = match data.first() {
        Some(0) => 0.0,
        Some(&b) => f64::from(b) * 1e-3,
        None => 0.01,
    };
    common::check(parse_single_column(&text, dt, "fuzz.txt"));
});
