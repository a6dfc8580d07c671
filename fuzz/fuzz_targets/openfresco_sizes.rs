//! Any bytes as the OpenFresco sizes message: never a panic; valid sizes round-trip.
#![no_main]

use libfuzzer_sys::fuzz_target;
use substep::site::openfresco::Sizes;

fuzz_target!(|data: &[u8]| {
    if let Ok(s) = Sizes::decode(data) {
        assert_eq!(&s.encode()[..], data);
        assert!(s.validate().is_ok());
    }
});
