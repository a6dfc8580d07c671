//! Any bytes as an SSTP frame, before and within a session: never a panic, and whatever
//! decodes re-encodes to the same frame.
#![no_main]

use libfuzzer_sys::fuzz_target;
use substep::site::protocol::{Header, Session, decode_frame};

fuzz_target!(|data: &[u8]| {
    let (frame, params) = data.split_at(data.len().saturating_sub(2));
    let session = Session {
        n_coupling: 1 + params.first().map_or(0, |b| (b % 8) as usize),
        substeps: 1 + params.get(1).map_or(0, |b| (b % 16) as usize),
    };
    for s in [None, Some(&session)] {
        if let Ok((h, m)) = decode_frame(frame, s) {
            let mut again = Vec::new();
            m.encode(h.seq, &mut again);
            assert_eq!(again, frame);
            assert_eq!(Header::parse(&again).unwrap(), h);
        }
    }
});
