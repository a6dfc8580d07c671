//! The MatrixMarket reader, dense and sparse, on any text (corpus: `examples/*.mtx`).
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    common::check(substep::io::parse_matrix_market(&text, "fuzz.mtx"));
    common::check(substep::io::parse_matrix_market_sparse(&text, "fuzz.mtx"));
});
