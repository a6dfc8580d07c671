//! The monitor's HTTP request parser (`substep run --monitor`) on any bytes a client can send:
//! complete, still arriving, or refused with 400/413; never a body over `MAX_BODY`, never more
//! than a head and a body left waiting.
#![no_main]
use libfuzzer_sys::fuzz_target;
use substep::monitor::http::{MAX_BODY, MAX_HEAD, Parsed, parse_request};

fuzz_target!(|data: &[u8]| {
    match parse_request(data) {
        Parsed::Complete(r) => assert!(r.body.len() <= MAX_BODY && r.path.starts_with('/')),
        Parsed::Incomplete => assert!(data.len() <= MAX_HEAD + 4 + MAX_BODY),
        Parsed::Refused(code, _) => assert!(code == 400 || code == 413),
    }
});
