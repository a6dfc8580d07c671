//! `TestDefinition::from_toml` on any text (corpus: `examples/*.toml`).
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    common::check(substep::io::TestDefinition::from_toml(
        &text,
        "fuzz.toml",
        &common::examples(),
    ));
});
