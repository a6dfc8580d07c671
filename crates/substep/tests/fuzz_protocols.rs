//! Seeded fuzz / property harness for both wire protocols (SSTP and OpenFresco), decoder and
//! live peers, server side and client side: arbitrary bytes never panic, never hang (every wait
//! has a timeout) and never allocate beyond a bound (a counting global allocator measures it),
//! and encode → decode is the identity on random valid messages.
//!
//! `SUBSTEP_FUZZ_CASES` sets the number of cases of the decoder tests (default: a few seconds
//! in release; the tests with live peers run a hundredth of it), `SUBSTEP_FUZZ_SEED` the seed.
//! See docs/security.md for longer runs.

use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;
use substep::site::openfresco::{ElementSpec, OpenFrescoServer, OpenFrescoSite, SIZES_LEN, Sizes, action};
use substep::site::protocol::{HEADER_LEN, Header, MAX_REASON, Session, decode_frame};
use substep::site::{
    ClientOptions, Hello, Message, Mode, RemoteSite, ServeOptions, SiteClient, SiteServer, StepReply, StepRequest,
    Transport, VirtualLabSpec,
};
use substep::specimen::SpecimenSpec;
use substep::substructure::ExperimentalSubstructure;

// --- allocation accounting ------------------------------------------------------------------

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// Largest single allocation made by this thread since the last reset.
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

fn note(size: usize) {
    let live = LIVE.fetch_add(size, Ordering::Relaxed) + size;
    PEAK.fetch_max(live, Ordering::Relaxed);
    let _ = LARGEST.try_with(|l| l.set(l.get().max(size)));
}

// SAFETY: forwards to the system allocator unchanged; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        note(new_size);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

fn largest_reset() {
    LARGEST.with(|l| l.set(0));
}
fn largest() -> usize {
    LARGEST.with(|l| l.get())
}

// --- harness --------------------------------------------------------------------------------

fn cases(default: usize) -> usize {
    std::env::var("SUBSTEP_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
        .map_or(default, |n| n.max(1))
}

/// Cases for the tests with live peers (each a connection with timeouts): a hundredth of
/// `SUBSTEP_FUZZ_CASES`.
fn live_cases(default: usize) -> usize {
    std::env::var("SUBSTEP_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
        .map_or(default, |n| (n / 100).max(1))
}

fn rng(salt: u64) -> ChaCha8Rng {
    let seed = std::env::var("SUBSTEP_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
        .unwrap_or(20_261_201);
    ChaCha8Rng::seed_from_u64(seed ^ salt.wrapping_mul(0x9e37_79b9_7f4a_7c15))
}

fn finite(r: &mut ChaCha8Rng) -> f64 {
    match r.random_range(0..4) {
        0 => 0.0,
        1 => r.random_range(-1.0..1.0),
        2 => r.random_range(-1e6..1e6),
        _ => {
            // any bit pattern that is a finite number (subnormals, ±1e308 included)
            let x = f64::from_bits(r.next_u64());
            if x.is_finite() { x } else { f64::MAX }
        }
    }
}

fn finite_vec(r: &mut ChaCha8Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| finite(r)).collect()
}

fn text(r: &mut ChaCha8Rng) -> String {
    let n = r.random_range(0..40);
    (0..n)
        .map(|_| ['a', 'ß', '→', ' ', '9', '語'][r.random_range(0..6)])
        .collect()
}

/// A random valid message of a session with `n` coupling DOFs and `k` sub-steps.
fn random_message(r: &mut ChaCha8Rng, n: usize, k: usize) -> Message {
    let mut bytes32 = || {
        let mut b = [0u8; 32];
        r.fill_bytes(&mut b);
        b
    };
    let (a, b) = (bytes32(), bytes32());
    match r.random_range(0..12) {
        0 => {
            let mut dofs: Vec<usize> = (0..3 * n).collect();
            for i in (1..dofs.len()).rev() {
                dofs.swap(i, r.random_range(0..=i));
            }
            let dt = r.random_range(1e-4..1.0);
            Message::Hello(Hello {
                n_coupling: n,
                substeps: k,
                mode: if r.random() { Mode::PerStep } else { Mode::PerSubstep },
                dt,
                dtau: dt / k as f64,
                gain_cc: finite_vec(r, n * n),
                coupling_dofs: dofs[..n].to_vec(),
            })
        }
        1 => Message::Accept {
            n_coupling: n,
            mac: if r.random() { Some(a) } else { None },
        },
        2 => Message::Reject { reason: text(r) },
        3 => Message::Substep {
            command: finite_vec(r, n),
            ag: (finite(r), finite(r)),
            dtau: r.random_range(1e-6..1.0),
        },
        4 => Message::Measured {
            force: finite_vec(r, n),
            displacement: finite_vec(r, n),
        },
        5 => Message::Step(StepRequest {
            predictor_c_prev: finite_vec(r, n),
            predictor_c: finite_vec(r, n),
            force_prev: finite_vec(r, n),
            ag: (finite(r), finite(r)),
        }),
        6 => Message::StepResult(StepReply {
            commands: finite_vec(r, n * k),
            forces: finite_vec(r, n * k),
            displacements: finite_vec(r, n * k),
        }),
        7 => Message::Heartbeat,
        8 => Message::Stop { reason: text(r) },
        9 => Message::Error { reason: text(r) },
        10 => Message::Challenge { nonce: a },
        _ => Message::Auth { nonce: a, mac: b },
    }
}

/// Damage a frame the ways a hostile peer or a bad link would.
fn mutate(r: &mut ChaCha8Rng, frame: &mut Vec<u8>) {
    for _ in 0..r.random_range(1..4) {
        match r.random_range(0..7) {
            0 if !frame.is_empty() => {
                let i = r.random_range(0..frame.len());
                frame[i] ^= 1 << r.random_range(0..8);
            }
            1 => frame.truncate(r.random_range(0..=frame.len())),
            2 if frame.len() >= HEADER_LEN => {
                // an absurd or slightly wrong length
                let len: u32 = match r.random_range(0..3) {
                    0 => u32::MAX,
                    1 => r.random(),
                    _ => (frame.len() - HEADER_LEN) as u32 ^ 8,
                };
                frame[12..16].copy_from_slice(&len.to_le_bytes());
            }
            3 if frame.len() >= HEADER_LEN => {
                let code: u16 = r.random_range(0..16);
                frame[6..8].copy_from_slice(&code.to_le_bytes());
            }
            4 if frame.len() >= HEADER_LEN + 8 => {
                // NaN, inf or a huge count where a number is
                let i = r.random_range(HEADER_LEN..frame.len() - 7);
                let v = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e308][r.random_range(0..4)];
                frame[i..i + 8].copy_from_slice(&v.to_le_bytes());
            }
            5 if frame.len() >= HEADER_LEN + 4 => {
                let i = r.random_range(HEADER_LEN..frame.len() - 3);
                frame[i..i + 4].copy_from_slice(&u32::MAX.to_le_bytes());
            }
            _ => {
                let extra = r.random_range(0..16);
                frame.extend((0..extra).map(|_| r.random::<u8>()));
            }
        }
    }
}

// --- SSTP decoder ---------------------------------------------------------------------------

#[test]
fn sstp_encode_decode_round_trip() {
    let mut r = rng(1);
    let mut buf = Vec::new();
    for _ in 0..cases(20_000) {
        let (n, k) = (r.random_range(1..=6), r.random_range(1..=8));
        let session = Session {
            n_coupling: n,
            substeps: k,
        };
        let msg = random_message(&mut r, n, k);
        let seq = r.random();
        msg.encode(seq, &mut buf);
        let (h, back) = decode_frame(&buf, Some(&session)).unwrap_or_else(|e| panic!("{msg:?}: {e}"));
        assert_eq!(h.seq, seq);
        assert_eq!(h.len as usize + HEADER_LEN, buf.len());
        // strings are carried as UTF-8 truncated at MAX_REASON; everything else exactly
        assert_eq!(back, msg);
    }
}

#[test]
fn sstp_decode_of_arbitrary_bytes_never_panics_nor_over_allocates() {
    let mut r = rng(2);
    let mut frame = Vec::new();
    let mut refused = 0usize;
    for case in 0..cases(40_000) {
        let (n, k) = (r.random_range(1..=6), r.random_range(1..=8));
        let session = Session {
            n_coupling: n,
            substeps: k,
        };
        if case % 4 == 0 {
            frame.clear();
            let len = r.random_range(0..300);
            frame.extend((0..len).map(|_| r.random::<u8>()));
            if r.random() && frame.len() >= 4 {
                frame[..4].copy_from_slice(b"SSTP");
            }
        } else {
            random_message(&mut r, n, k).encode(r.random(), &mut frame);
            mutate(&mut r, &mut frame);
        }
        for s in [None, Some(&session)] {
            largest_reset();
            let result = decode_frame(&frame, s);
            // a decoder allocates at most what it returns (the frame's own numbers and one
            // reason string), never what a length field claims
            assert!(
                largest() <= frame.len() + MAX_REASON + 64,
                "case {case}: {} bytes allocated for a {}-byte frame",
                largest(),
                frame.len()
            );
            match result {
                Ok((_, m)) => {
                    // whatever decodes is valid: finite numbers, re-encodes to the same frame
                    let mut again = Vec::new();
                    let h = Header::parse(&frame).unwrap();
                    m.encode(h.seq, &mut again);
                    assert_eq!(again, frame, "case {case}: {m:?}");
                }
                Err(e) => {
                    let e = e.to_string();
                    assert!(e.starts_with("site protocol: ") && !e.contains('\n'), "{e}");
                    refused += 1;
                }
            }
        }
    }
    assert!(refused > 0);
}

// --- OpenFresco sizes -----------------------------------------------------------------------

#[test]
fn openfresco_sizes_decode_never_panics_and_round_trips() {
    let mut r = rng(3);
    for _ in 0..cases(20_000) {
        let mut raw = [0u8; 4 * SIZES_LEN];
        if r.random() {
            r.fill_bytes(&mut raw);
        } else {
            let n = r.random_range(1..=40);
            raw = Sizes::generic_client(n, r.random_range(0..600)).encode();
            let i = r.random_range(0..SIZES_LEN);
            let v: i32 = [0, -1, i32::MAX, n as i32 + 1, 1][r.random_range(0..5)];
            raw[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
        }
        largest_reset();
        if let Ok(s) = Sizes::decode(&raw) {
            assert_eq!(s.encode(), raw);
            assert!(s.data_size <= substep::site::openfresco::MAX_DATA_SIZE);
        }
        assert!(largest() <= 256, "{} bytes allocated decoding 44 bytes", largest());
        let cut = r.random_range(0..raw.len());
        assert!(Sizes::decode(&raw[..cut]).is_err());
    }
}

// --- live peers -----------------------------------------------------------------------------

fn spring_lab() -> VirtualLabSpec {
    VirtualLabSpec::ideal(vec![
        SpecimenSpec::LinearSdof {
            dof: 0,
            mass: None,
            stiffness: 1e4,
            damping: 0.0,
        },
        SpecimenSpec::LinearSdof {
            dof: 1,
            mass: None,
            stiffness: 2e4,
            damping: 0.0,
        },
    ])
}

fn hello2() -> Hello {
    Hello {
        n_coupling: 2,
        substeps: 4,
        mode: Mode::PerSubstep,
        dt: 0.01,
        dtau: 0.0025,
        gain_cc: vec![1e-6, 0.0, 0.0, 1e-6],
        coupling_dofs: vec![0, 1],
    }
}

fn quick_options() -> ServeOptions {
    ServeOptions {
        idle_timeout: Some(Duration::from_millis(100)),
        handshake_timeout: Duration::from_millis(100),
        io_timeout: Duration::from_millis(100),
        ..ServeOptions::default()
    }
}

/// Send one hostile byte stream, then read whatever comes back (bounded).
fn hostile_session(addr: SocketAddr, r: &mut ChaCha8Rng, valid_prefix: Option<&[u8]>) {
    let Ok(mut s) = TcpStream::connect(addr) else { return };
    let _ = s.set_read_timeout(Some(Duration::from_millis(300)));
    let _ = s.set_write_timeout(Some(Duration::from_millis(300)));
    if let Some(p) = valid_prefix {
        let _ = s.write_all(p);
        let mut reply = [0u8; 256];
        let _ = s.read(&mut reply);
    }
    let mut junk = Vec::new();
    if r.random() {
        random_message(r, 2, 4).encode(r.random_range(0..4), &mut junk);
        mutate(r, &mut junk);
    } else {
        let len = r.random_range(0..200);
        junk.extend((0..len).map(|_| r.random::<u8>()));
    }
    let _ = s.write_all(&junk);
    match r.random_range(0..10) {
        // hang up mid-frame at once
        0..=3 => return,
        // go silent: the site's timeouts end it
        4 => {}
        // half-close: the site sees the end of the stream after the junk
        _ => {
            let _ = s.shutdown(std::net::Shutdown::Write);
        }
    }
    let mut sink = [0u8; 4096];
    for _ in 0..4 {
        match s.read(&mut sink) {
            Ok(0) | Err(_) => break,
            Ok(_) => {}
        }
    }
}

#[test]
fn sstp_server_survives_arbitrary_bytes() {
    let built = Arc::new(AtomicUsize::new(0));
    let counter = built.clone();
    let mut inner = spring_lab().factory();
    let factory = move |h: &Hello| -> substep::Result<Box<dyn ExperimentalSubstructure>> {
        counter.fetch_add(1, Ordering::SeqCst);
        inner(h)
    };
    let server = SiteServer::spawn(TcpListener::bind("127.0.0.1:0").unwrap(), factory, &quick_options()).unwrap();
    let addr = server.local_addr();
    let mut r = rng(4);
    let mut hello = Vec::new();
    Message::Hello(hello2()).encode(0, &mut hello);
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    for case in 0..live_cases(200) {
        // a third of the cases get past the handshake first (server side of a session)
        hostile_session(addr, &mut r, (case % 3 == 0).then_some(&hello[..]));
    }
    let growth = PEAK.load(Ordering::Relaxed).saturating_sub(base);
    assert!(growth < 16 << 20, "the server's heap grew by {growth} bytes under fuzz");
    // and still serves a valid client: force = −K d
    let opts = ClientOptions {
        timeout: Duration::from_secs(2),
        ..ClientOptions::default()
    };
    let mut site = None;
    for _ in 0..100 {
        match RemoteSite::connect(addr, Transport::Tcp, hello2(), &opts) {
            Ok(s) => {
                site = Some(s);
                break;
            }
            Err(e) if e.to_string().contains("busy") => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => panic!("{e}"),
        }
    }
    let mut site = site.expect("served");
    let (mut f, mut d) = (vec![0.0; 2], vec![0.0; 2]);
    site.substep(&[1e-3, 2e-3], (0.0, 0.0), 0.0025, &mut f, &mut d).unwrap();
    assert_eq!(f, vec![-10.0, -40.0]);
    drop(site);
    server.stop().unwrap();
    assert!(built.load(Ordering::SeqCst) >= 1);
}

#[test]
fn openfresco_server_survives_arbitrary_bytes() {
    let element = ElementSpec::Specimen {
        spec: SpecimenSpec::LinearSdof {
            dof: 0,
            mass: None,
            stiffness: 1e4,
            damping: 0.0,
        },
        default_dt: 0.01,
    };
    let server = OpenFrescoServer::spawn(
        TcpListener::bind("127.0.0.1:0").unwrap(),
        move |_| element.build(),
        &quick_options(),
    )
    .unwrap();
    let addr = server.local_addr();
    let mut r = rng(5);
    let base = LIVE.load(Ordering::Relaxed);
    for _ in 0..live_cases(200) {
        let Ok(mut s) = TcpStream::connect(addr) else { continue };
        let _ = s.set_read_timeout(Some(Duration::from_millis(300)));
        let _ = s.set_write_timeout(Some(Duration::from_millis(300)));
        let sizes = Sizes::substep_client(1);
        let mut out: Vec<u8> = if r.random() {
            sizes.encode().to_vec()
        } else {
            let mut raw = sizes.encode();
            let i = r.random_range(0..SIZES_LEN);
            raw[4 * i..4 * i + 4].copy_from_slice(&r.random::<i32>().to_le_bytes());
            raw.to_vec()
        };
        // messages: random action codes and values (NaN, inf, 1e308 included)
        for _ in 0..r.random_range(0..4) {
            let mut m = vec![0.0; sizes.data_size];
            m[0] = [3.0, 6.0, 5.0, 7.0, 12.0, 99.0, 1e300, f64::NAN, -1.0][r.random_range(0..9)];
            for x in m.iter_mut().skip(1).take(3) {
                *x = [1e-3, 1e308, f64::NAN, f64::INFINITY, 0.02][r.random_range(0..5)];
            }
            out.extend(m.iter().flat_map(|x| x.to_le_bytes()));
        }
        out.truncate(r.random_range(0..=out.len()));
        let _ = s.write_all(&out);
        if r.random_range(0..10) > 0 {
            let _ = s.shutdown(std::net::Shutdown::Write);
        }
        let mut reply = vec![0u8; 8 * sizes.data_size];
        let mut got = 0;
        while got < reply.len() {
            match s.read(&mut reply[got..]) {
                Ok(0) | Err(_) => break,
                Ok(k) => got += k,
            }
        }
        // a reply that arrived whole is finite
        if got == reply.len() {
            assert!(
                reply
                    .chunks_exact(8)
                    .all(|c| f64::from_le_bytes(c.try_into().unwrap()).is_finite())
            );
        }
    }
    let growth = PEAK.load(Ordering::Relaxed).saturating_sub(base);
    assert!(growth < 64 << 20, "heap grew by {growth} bytes");
    // a valid client afterwards: p = k u, so f_c = −p = −10 N at 1 mm
    let mut site = None;
    for _ in 0..100 {
        if let Ok(s) = OpenFrescoSite::connect(addr, 1, &ClientOptions::default()) {
            site = Some(s);
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut site = site.expect("connected");
    let (mut f, mut d) = ([0.0], [0.0]);
    let mut ok = false;
    for _ in 0..100 {
        // the previous fuzz client may still hold the server for its timeout
        match site.substep(&[1e-3], (0.0, 0.0), 0.01, &mut f, &mut d) {
            Ok(()) => {
                ok = true;
                break;
            }
            Err(_) => {
                std::thread::sleep(Duration::from_millis(20));
                site = OpenFrescoSite::connect(addr, 1, &ClientOptions::default()).unwrap();
            }
        }
    }
    assert!(ok);
    assert!((f[0] + 10.0).abs() < 1e-9, "{f:?}");
    drop(site);
    server.stop().unwrap();
    let _ = action::DISCONNECT;
}

/// A fake site that answers every request with hostile bytes.
fn hostile_site(seed: u64, replies: usize) -> (SocketAddr, std::thread::JoinHandle<()>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let t = std::thread::spawn(move || {
        let mut r = rng(seed);
        for _ in 0..replies {
            let Ok((mut c, _)) = listener.accept() else { return };
            let _ = c.set_read_timeout(Some(Duration::from_millis(500)));
            let mut buf = [0u8; 1024];
            let _ = c.read(&mut buf);
            let mut reply = Vec::new();
            if r.random_range(0..3) == 0 {
                // a valid Accept, then garbage for the first request
                Message::Accept {
                    n_coupling: 2,
                    mac: None,
                }
                .encode(0, &mut reply);
                let _ = c.write_all(&reply);
                let _ = c.read(&mut buf);
                reply.clear();
            }
            random_message(&mut r, 2, 4).encode(r.random_range(0..3), &mut reply);
            mutate(&mut r, &mut reply);
            let _ = c.write_all(&reply);
            // sometimes stall, sometimes hang up
            if r.random() {
                std::thread::sleep(Duration::from_millis(r.random_range(0..50)));
            }
        }
    });
    (addr, t)
}

#[test]
fn sstp_client_survives_a_hostile_site() {
    let n = live_cases(150);
    let (addr, site) = hostile_site(6, n);
    let opts = ClientOptions {
        timeout: Duration::from_millis(150),
        connect_timeout: Duration::from_secs(1),
        ..ClientOptions::default()
    };
    let bound = HEADER_LEN + hello2().session().max_payload() + 4096;
    for _ in 0..n {
        largest_reset();
        match SiteClient::connect(addr, Transport::Tcp, hello2(), &opts) {
            Ok(mut c) => {
                let e = c
                    .request(&Message::Substep {
                        command: vec![0.0, 0.0],
                        ag: (0.0, 0.0),
                        dtau: 0.0025,
                    })
                    .map(|m| {
                        // whatever was accepted is a decoded, finite message
                        if let Message::Measured { force, displacement } = m {
                            assert!(force.iter().chain(&displacement).all(|x| x.is_finite()));
                        }
                    });
                let _ = e;
            }
            Err(e) => {
                let e = e.to_string();
                assert!(e.contains(&addr.to_string()) && !e.contains('\n'), "{e}");
            }
        }
        assert!(
            largest() <= bound,
            "the client allocated {} bytes (bound {bound})",
            largest()
        );
    }
    site.join().unwrap();
}

#[test]
fn sstp_udp_server_survives_arbitrary_datagrams() {
    use std::net::UdpSocket;
    let server = SiteServer::spawn_udp(
        UdpSocket::bind("127.0.0.1:0").unwrap(),
        spring_lab().factory(),
        &quick_options(),
    )
    .unwrap();
    let addr = server.local_addr();
    let mut r = rng(7);
    let base = LIVE.load(Ordering::Relaxed);
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_nonblocking(true).unwrap();
    let mut hello = Vec::new();
    Message::Hello(hello2()).encode(0, &mut hello);
    let mut buf = vec![0u8; 65_536];
    for case in 0..live_cases(2_000) {
        let mut d = Vec::new();
        match case % 4 {
            // a valid handshake now and then, so that requests hit a live session too
            0 => d.extend_from_slice(&hello),
            1 => {
                let len = r.random_range(0..300);
                d.extend((0..len).map(|_| r.random::<u8>()));
            }
            _ => {
                random_message(&mut r, 2, 4).encode(r.random_range(0..4), &mut d);
                mutate(&mut r, &mut d);
            }
        }
        let _ = sock.send_to(&d, addr);
        if case % 64 == 0 {
            std::thread::sleep(Duration::from_millis(1)); // let the server keep up
        }
        // replies that have arrived (if any) are protocol frames
        while let Ok((n, _)) = sock.recv_from(&mut buf) {
            assert!(n >= 4 && &buf[..4] == b"SSTP", "{:?}", &buf[..n.min(16)]);
        }
    }
    let growth = PEAK.load(Ordering::Relaxed).saturating_sub(base);
    assert!(growth < 64 << 20, "heap grew by {growth} bytes");
    // a valid UDP client is served afterwards (the fuzz socket's session, if any, is another
    // address: wait for its idle timeout on "busy")
    let opts = ClientOptions {
        timeout: Duration::from_millis(300),
        ..ClientOptions::default()
    };
    let mut site = None;
    for _ in 0..100 {
        match RemoteSite::connect(addr, Transport::Udp, hello2(), &opts) {
            Ok(s) => {
                site = Some(s);
                break;
            }
            Err(e) if e.to_string().contains("busy") => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => panic!("{e}"),
        }
    }
    let mut site = site.expect("served");
    let (mut f, mut d) = (vec![0.0; 2], vec![0.0; 2]);
    site.substep(&[1e-3, 2e-3], (0.0, 0.0), 0.0025, &mut f, &mut d).unwrap();
    assert_eq!(f, vec![-10.0, -40.0]);
    drop(site);
    server.stop().unwrap();
}
