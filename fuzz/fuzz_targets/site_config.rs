//! `SiteDefinition::from_toml` on any text.
#![no_main]
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    common::check(substep::io::site_config::SiteDefinition::from_toml(
        &text,
        "site.toml",
        &common::examples(),
    ));
});
