//! `substep benchmark rths`: its `--config` TOML and its `--record` CSV reader on any text.
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;
use substep::benchmark::rths::{BenchmarkConfig, GroundRecord};

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    common::check(BenchmarkConfig::parse(&text, "fuzz.toml"));
    common::check(GroundRecord::parse_csv("fuzz.csv", &text));
});
