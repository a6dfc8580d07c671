//! Sites that survive any peer, and authenticated sites (issue 11): hostile handshakes are
//! refused against the site's limits before anything is built, silent and second clients
//! cannot hold the site, no non-finite value goes on the wire, durations from input are bounded,
//! and a site with a secret serves only clients that prove it (HMAC-SHA256, replay-safe,
//! mutual). Loopback only; every wait is bounded by a timeout.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, UdpSocket};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use substep::error::require_duration;
use substep::site::auth::{Role, Secret, SessionKeys};
use substep::site::openfresco::{ElementSpec, OpenFrescoServer, Sizes, action};
use substep::site::protocol::{HEADER_LEN, Header, MessageType, Session, decode_frame, open_sealed};
use substep::site::{
    ClientOptions, Hello, Message, Mode, RemoteSite, RemoteStepSite, ServeOptions, SiteClient, SiteLimits, SiteServer,
    Transport, VirtualLabSpec,
};
use substep::specimen::SpecimenSpec;
use substep::substructure::ExperimentalSubstructure;
use substep::transfer::{ActuatorSpec, Dynamics};

/// Spring stiffness of the hosted specimen [N/m]: with ideal actuators and sensors the force on
/// the structure is exactly `−K d`.
const K: f64 = 2.5e4;

fn spring(dof: usize) -> SpecimenSpec {
    SpecimenSpec::LinearSdof {
        dof,
        mass: None,
        stiffness: K,
        damping: 0.0,
    }
}

/// A lab like a real one: a 1.5 ms delay (the buffer a tiny Δτ used to blow up) and ten inner
/// steps per sub-step.
fn delayed_lab() -> VirtualLabSpec {
    VirtualLabSpec {
        actuator: ActuatorSpec {
            dynamics: Dynamics::FirstOrder { time_constant: 0.002 },
            delay: 0.0015,
        },
        inner_steps: 10,
        ..VirtualLabSpec::ideal(vec![spring(0), spring(1)])
    }
}

fn hello(n: usize, k: usize, dt: f64, mode: Mode) -> Hello {
    let mut gain = vec![0.0; n * n];
    for i in 0..n {
        gain[i * n + i] = 1e-6;
    }
    Hello {
        n_coupling: n,
        substeps: k,
        mode,
        dt,
        dtau: dt / k as f64,
        gain_cc: gain,
        coupling_dofs: (0..n).collect(),
    }
}

type Log = Arc<Mutex<Vec<String>>>;

fn options() -> (ServeOptions, Log) {
    let log: Log = Arc::default();
    let sink = log.clone();
    let options = ServeOptions {
        idle_timeout: Some(Duration::from_secs(5)),
        log: Some(Arc::new(move |line: &str| sink.lock().unwrap().push(line.to_string()))),
        ..ServeOptions::default()
    };
    (options, log)
}

fn client_options() -> ClientOptions {
    ClientOptions {
        timeout: Duration::from_secs(3),
        connect_timeout: Duration::from_secs(2),
        udp_retries: 1,
        secret: None,
    }
}

/// A factory that counts how often something was built (what reaches the actuators).
fn counting(
    lab: VirtualLabSpec,
    built: Arc<AtomicUsize>,
) -> impl FnMut(&Hello) -> substep::Result<Box<dyn ExperimentalSubstructure>> + Send + 'static {
    let mut inner = lab.factory();
    move |h: &Hello| {
        built.fetch_add(1, Ordering::SeqCst);
        inner(h)
    }
}

fn spawn(transport: Transport, options: &ServeOptions, built: &Arc<AtomicUsize>) -> substep::site::ServerHandle {
    let factory = counting(delayed_lab(), built.clone());
    match transport {
        Transport::Tcp => SiteServer::spawn(TcpListener::bind("127.0.0.1:0").unwrap(), factory, options).unwrap(),
        Transport::Udp => SiteServer::spawn_udp(UdpSocket::bind("127.0.0.1:0").unwrap(), factory, options).unwrap(),
    }
}

fn refusal(addr: SocketAddr, transport: Transport, hello: Hello, options: &ClientOptions) -> String {
    // the previous client's session may still be closing: "busy" is retried (bounded)
    for _ in 0..100 {
        let t0 = Instant::now();
        let err = SiteClient::connect(addr, transport, hello.clone(), options)
            .err()
            .expect("must be refused")
            .to_string();
        assert!(
            t0.elapsed() < options.timeout,
            "refused at once, not by a timeout: {err}"
        );
        if !err.contains("busy") {
            return err;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("the site stayed busy");
}

/// The first refusal, "busy" included.
fn first_refusal(addr: SocketAddr, transport: Transport, hello: Hello, options: &ClientOptions) -> String {
    let t0 = Instant::now();
    let err = SiteClient::connect(addr, transport, hello, options)
        .err()
        .expect("must be refused")
        .to_string();
    assert!(
        t0.elapsed() < options.timeout,
        "refused at once, not by a timeout: {err}"
    );
    err
}

/// Retry `connect` while the site is busy with the previous client (bounded).
fn unless_busy<T>(mut connect: impl FnMut() -> substep::Result<T>) -> T {
    for _ in 0..100 {
        match connect() {
            Ok(s) => return s,
            Err(e) if e.to_string().contains("busy") => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => panic!("{e}"),
        }
    }
    panic!("the site stayed busy");
}

fn connect_site(addr: SocketAddr, transport: Transport, hello: Hello, options: &ClientOptions) -> RemoteSite {
    unless_busy(|| RemoteSite::connect(addr, transport, hello.clone(), options))
}

/// One per-sub-step round trip; the force must be −K d on each coupling DOF.
fn check_spring(site: &mut RemoteSite, d: &[f64]) {
    let n = d.len();
    let (mut f, mut dm) = (vec![0.0; n], vec![0.0; n]);
    site.substep(d, (0.0, 0.0), 0.0025, &mut f, &mut dm).unwrap();
    for i in 0..n {
        assert_eq!(f[i], -K * d[i], "force on coupling DOF {}", i + 1);
    }
}

#[test]
fn hostile_hellos_are_refused_by_the_site_limits_before_anything_is_built() {
    for transport in [Transport::Tcp, Transport::Udp] {
        let built = Arc::new(AtomicUsize::new(0));
        let (opts, _log) = options();
        let server = spawn(transport, &opts, &built);
        let addr = server.local_addr();
        let per_step = hello(2, 4, 0.01, Mode::PerStep);
        let mut cases: Vec<(Hello, &str)> = vec![
            // the reproduced aborts: Δτ = 1e-12 s (160 GB delay buffer) and 1e-10 s (1.6 GB)
            (
                Hello {
                    dtau: 1e-12,
                    ..per_step.clone()
                },
                "site.min_dtau",
            ),
            (
                Hello {
                    dtau: 1e-10,
                    ..per_step.clone()
                },
                "site.min_dtau",
            ),
            // k = 32 000 per step (29 s of CPU per Step before; the UDP client itself refuses a
            // StepResult that large, so just over the limit there)
            (
                hello(
                    2,
                    if transport == Transport::Tcp { 32_000 } else { 1001 },
                    0.01,
                    Mode::PerStep,
                ),
                "site.max_substeps",
            ),
            (hello(65, 4, 0.01, Mode::PerSubstep), "site.max_coupling"),
            (hello(2, 4, 1e6, Mode::PerSubstep), "site.max_dt"),
            (
                Hello {
                    dtau: 0.5,
                    ..per_step.clone()
                },
                "longer than the time step",
            ),
        ];
        if transport == Transport::Tcp {
            // larger than any Hello the site reads: refused from the frame header
            cases.push((hello(100, 4, 0.01, Mode::PerSubstep), "site.max_coupling"));
        }
        for (h, key) in cases {
            let err = refusal(addr, transport, h, &client_options());
            assert!(
                err.contains("rejected the connection") && err.contains(key),
                "{key}: {err}"
            );
        }
        assert_eq!(
            built.load(Ordering::SeqCst),
            0,
            "nothing was built for a refused handshake"
        );
        // within the generic limits, but the delay history and its per-Step search would cost
        // too much: k = 1000 at Δτ = 1e-5 s with 10 inner steps → 3004 samples searched 10⁴
        // times per coupling DOF and Step
        let err = refusal(addr, transport, hello(2, 1000, 0.01, Mode::PerStep), &client_options());
        assert!(err.contains("site.max_request_work"), "{err}");
        // a legitimate client is served afterwards, with the right forces
        let mut site = connect_site(addr, transport, hello(2, 4, 0.01, Mode::PerSubstep), &client_options());
        let mut check = |d: &[f64]| {
            let (mut f, mut dm) = (vec![0.0; 2], vec![0.0; 2]);
            site.substep(d, (0.0, 0.0), 0.0025, &mut f, &mut dm).unwrap();
            f
        };
        // delayed, lagging actuator: just finite and opposite in sign to the motion
        let f = check(&[1e-3, -2e-3]);
        assert!(f[0] < 0.0 && f[1] > 0.0, "{f:?}");
        drop(site);
        server.stop().unwrap();
    }
}

#[test]
fn the_delay_history_is_sized_by_the_limits() {
    // A long delay with a short sub-step: the history alone would take 640 MB.
    let lab = VirtualLabSpec {
        actuator: ActuatorSpec {
            dynamics: Dynamics::Ideal,
            delay: 1.0,
        },
        ..delayed_lab()
    };
    let h = Hello {
        dtau: 1e-6,
        ..hello(2, 4, 0.01, Mode::PerSubstep)
    };
    let cost = lab.cost(&h);
    // 2 (⌈1 s · 10 / 1e-6 s⌉ + 2) samples × 16 bytes × 2 actuators
    assert_eq!(cost.bytes, 2 * 2 * (10_000_000 + 2) * 16 + 2 * 1024);
    let err = SiteLimits::default().check_cost(&h, cost).unwrap_err();
    assert!(
        err.contains("640.0 MB") && err.contains("site.max_session_memory"),
        "{err}"
    );
    let mut factory = lab.factory();
    let err = factory(&h).err().unwrap().to_string();
    assert!(err.contains("site.max_session_memory"), "{err}");
    // the real-world handshake costs next to nothing
    let ok = hello(2, 4, 0.01, Mode::PerStep);
    assert!(SiteLimits::default().check_cost(&ok, delayed_lab().cost(&ok)).is_ok());
}

#[test]
fn silent_clients_cannot_hold_the_site() {
    let built = Arc::new(AtomicUsize::new(0));
    let (mut opts, log) = options();
    opts.idle_timeout = Some(Duration::from_millis(300));
    opts.handshake_timeout = Duration::from_millis(300);
    let server = spawn(Transport::Tcp, &opts, &built);
    let addr = server.local_addr();
    // connects and says nothing: dropped after the handshake timeout
    let mut mute = TcpStream::connect(addr).unwrap();
    mute.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
    let mut buf = [0u8; 16];
    assert_eq!(
        mute.read(&mut buf).unwrap_or(0),
        0,
        "the site closes a connection without a Hello"
    );
    // completes the handshake, then goes silent: dropped after the idle timeout with an Error
    let h = hello(2, 4, 0.01, Mode::PerSubstep);
    let mut silent = unless_busy(|| SiteClient::connect(addr, Transport::Tcp, h.clone(), &client_options()));
    std::thread::sleep(Duration::from_millis(600));
    let err = silent.ping().unwrap_err().to_string();
    assert!(err.contains("idle for more than 0.300 s"), "{err}");
    // and the site serves the next client
    let mut site = connect_site(addr, Transport::Tcp, h, &client_options());
    let (mut f, mut dm) = (vec![0.0; 2], vec![0.0; 2]);
    site.substep(&[0.0, 0.0], (0.0, 0.0), 0.0025, &mut f, &mut dm).unwrap();
    assert_eq!(f, vec![0.0, 0.0]);
    drop(site);
    server.stop().unwrap();
    let log = log.lock().unwrap();
    assert!(
        log.iter().any(|l| l.contains("no complete Hello within 0.300 s")),
        "{log:?}"
    );
    assert!(log.iter().any(|l| l.contains("idle for more than 0.300 s")), "{log:?}");
}

#[test]
fn a_busy_site_answers_busy_at_once() {
    for transport in [Transport::Tcp, Transport::Udp] {
        let built = Arc::new(AtomicUsize::new(0));
        let (opts, _log) = options();
        let server = spawn(transport, &opts, &built);
        let addr = server.local_addr();
        let h = hello(2, 4, 0.01, Mode::PerSubstep);
        let first = connect_site(addr, transport, h.clone(), &client_options());
        let err = first_refusal(addr, transport, h.clone(), &client_options());
        assert!(
            err.contains("the site is busy with another client"),
            "{transport:?}: {err}"
        );
        drop(first);
        // once the first client has left, the next one is served (bounded retries: the Stop
        // of the dropped client may still be in flight)
        let mut second = connect_site(addr, transport, h.clone(), &client_options());
        let (mut f, mut dm) = (vec![0.0; 2], vec![0.0; 2]);
        second
            .substep(&[0.0, 0.0], (0.0, 0.0), 0.0025, &mut f, &mut dm)
            .unwrap();
        drop(second);
        server.stop().unwrap();
    }
}

#[test]
fn no_non_finite_value_goes_on_the_wire() {
    let built = Arc::new(AtomicUsize::new(0));
    let (opts, _log) = options();
    let ideal = VirtualLabSpec::ideal(vec![spring(0), spring(1)]);
    let server = SiteServer::spawn(
        TcpListener::bind("127.0.0.1:0").unwrap(),
        counting(ideal, built.clone()),
        &opts,
    )
    .unwrap();
    let addr = server.local_addr();
    // per sub-step: K · 1e308 overflows; the site replies an Error instead of −inf
    let mut site = connect_site(
        addr,
        Transport::Tcp,
        hello(2, 4, 0.01, Mode::PerSubstep),
        &client_options(),
    );
    check_spring(&mut site, &[1e-3, -4e-3]);
    let (mut f, mut dm) = (vec![0.0; 2], vec![0.0; 2]);
    let err = site
        .substep(&[1e308, 0.0], (0.0, 0.0), 0.0025, &mut f, &mut dm)
        .unwrap_err()
        .to_string();
    assert!(err.contains("non-finite force on coupling DOF 1"), "{err}");
    drop(site);
    // a Substep whose Δτ is outside the session's range
    let mut site = connect_site(
        addr,
        Transport::Tcp,
        hello(2, 4, 0.01, Mode::PerSubstep),
        &client_options(),
    );
    let err = site
        .substep(&[0.0, 0.0], (0.0, 0.0), 1e300, &mut f, &mut dm)
        .unwrap_err()
        .to_string();
    assert!(err.contains("Substep.dtau = 1e300 s is outside"), "{err}");
    drop(site);
    // per step: the ramp of huge (finite) predictors overflows, or the force does
    let mut step = unless_busy(|| {
        RemoteStepSite::connect(
            addr,
            Transport::Tcp,
            hello(2, 4, 0.01, Mode::PerStep),
            &client_options(),
        )
    });
    let err = step
        .step(&[-1.7e308, 0.0], &[1.7e308, 0.0], &[1.7e308, 0.0], (0.0, 0.0))
        .unwrap_err()
        .to_string();
    assert!(err.contains("not finite") || err.contains("non-finite"), "{err}");
    drop(step);
    server.stop().unwrap();

    // OpenFresco: a trial displacement of 1e308 or a trial time of 1e308 is refused (the
    // connection is closed: the protocol has no error reply), never answered with NaN
    for (slot, value) in [(1usize, 1e308), (2, 1e308)] {
        let (opts, log) = options();
        let element = ElementSpec::Specimen {
            spec: spring(0),
            default_dt: 0.01,
        };
        let server = OpenFrescoServer::spawn(
            TcpListener::bind("127.0.0.1:0").unwrap(),
            move |_| element.build(),
            &opts,
        )
        .unwrap();
        let mut s = TcpStream::connect(server.local_addr()).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
        let sizes = Sizes::substep_client(1);
        s.write_all(&sizes.encode()).unwrap();
        let send = |s: &mut TcpStream, v: &[f64]| {
            let mut m = vec![0.0; sizes.data_size];
            m[..v.len()].copy_from_slice(v);
            let bytes: Vec<u8> = m.iter().flat_map(|x| x.to_le_bytes()).collect();
            s.write_all(&bytes)
        };
        // trial: [3, disp, time]
        let mut trial = vec![action::SET_TRIAL_RESPONSE as f64, 1e-3, 0.01];
        trial[slot] = value;
        send(&mut s, &trial).unwrap();
        let _ = send(&mut s, &[action::GET_DAQ_RESPONSE as f64]);
        let mut reply = vec![0u8; 8 * sizes.data_size];
        let got = s.read(&mut reply).unwrap_or(0);
        assert_eq!(got, 0, "no reply: the connection is closed");
        server.stop().unwrap();
        let log = log.lock().unwrap();
        let why = if slot == 1 {
            "gives a non-finite force"
        } else {
            "more than site.max_dt"
        };
        assert!(log.iter().any(|l| l.contains(why)), "{log:?}");
    }
}

#[test]
fn durations_from_input_are_bounded() {
    for (v, msg) in [
        (1e20, "at most 1e6 s"),
        (1e19, "at most 1e6 s"),
        (f64::INFINITY, "finite"),
        (f64::NAN, "finite"),
        (0.0, "> 0"),
        (-1.0, "> 0"),
    ] {
        let err = require_duration("site.idle_timeout", v).unwrap_err().to_string();
        assert!(
            err.starts_with("site.idle_timeout: ") && err.contains(msg),
            "{v}: {err}"
        );
    }
    assert_eq!(require_duration("x", 1e6).unwrap(), Duration::from_secs(1_000_000));
    let site = |extra: &str| {
        format!(
            "[site]\nprotocol = \"substep\"\n{extra}\n[[specimen]]\nkind = \"linear_sdof\"\ndof = 1\nstiffness = 1.0\n"
        )
    };
    for (extra, key) in [
        ("idle_timeout = 1e20", "site.idle_timeout"),
        ("idle_timeout = 1e19", "site.idle_timeout"),
        ("handshake_timeout = 1e300", "site.handshake_timeout"),
        ("max_substeps = 0", "site.max_substeps"),
        ("max_coupling = 5000", "site.max_coupling"),
        ("min_dtau = -1.0", "site.min_dtau"),
        ("max_session_memory = 1e300", "site.max_session_memory"),
        ("allow = [\"localhost\"]", "site.allow[1]"),
        ("secret_file = \"missing.key\"", "site.secret_file"),
    ] {
        let err =
            substep::io::site_config::SiteDefinition::from_toml(&site(extra), "site.toml", std::path::Path::new("."))
                .unwrap_err()
                .to_string();
        assert!(err.starts_with("site.toml: ") && err.contains(key), "{extra}: {err}");
    }
    // listen defaults to this machine only
    let def =
        substep::io::site_config::SiteDefinition::from_toml(&site(""), "site.toml", std::path::Path::new(".")).unwrap();
    assert_eq!(def.listen(), "127.0.0.1:8090");
    assert_eq!(def.server().idle_timeout, Duration::from_secs(10));
}

// ---------------------------------------------------------------------------------------------
// Authentication

fn secret(s: &str) -> Secret {
    Secret::new(s.as_bytes(), "test secret").unwrap()
}

fn with_secret(s: Option<&Secret>) -> ClientOptions {
    ClientOptions {
        secret: s.cloned(),
        ..client_options()
    }
}

#[test]
fn a_site_with_a_secret_serves_only_clients_that_prove_it() {
    let right = secret("correct horse battery staple 42");
    let wrong = secret("correct horse battery staple 43");
    for transport in [Transport::Tcp, Transport::Udp] {
        let built = Arc::new(AtomicUsize::new(0));
        let (mut opts, log) = options();
        opts.secret = Some(right.clone());
        let server = spawn(transport, &opts, &built);
        let addr = server.local_addr();
        let h = hello(2, 4, 0.01, Mode::PerSubstep);
        let err = refusal(addr, transport, h.clone(), &with_secret(None));
        assert!(err.contains("the site requires authentication"), "{err}");
        let err = refusal(addr, transport, h.clone(), &with_secret(Some(&wrong)));
        assert!(err.contains("authentication failed: wrong proof"), "{err}");
        assert_eq!(
            built.load(Ordering::SeqCst),
            0,
            "{transport:?}: nothing reached the actuators"
        );
        let mut site = connect_site(addr, transport, h.clone(), &with_secret(Some(&right)));
        assert_eq!(built.load(Ordering::SeqCst), 1);
        let (mut f, mut dm) = (vec![0.0; 2], vec![0.0; 2]);
        site.substep(&[2e-3, -1e-3], (0.0, 0.0), 0.0025, &mut f, &mut dm)
            .unwrap();
        assert!(f[0] < 0.0 && f[1] > 0.0, "{f:?}");
        drop(site);
        server.stop().unwrap();
        let log = log.lock().unwrap();
        assert!(
            log.iter()
                .any(|l| l.contains("connected") && l.contains("authenticated")),
            "{log:?}"
        );
        assert_eq!(
            log.iter().filter(|l| l.contains("authentication failed")).count(),
            1,
            "{log:?}"
        );
    }
}

#[test]
fn a_client_with_a_secret_refuses_a_site_without_it() {
    let built = Arc::new(AtomicUsize::new(0));
    let (opts, _log) = options();
    let server = spawn(Transport::Tcp, &opts, &built);
    let s = secret("0123456789abcdef0123456789abcdef");
    let err = refusal(
        server.local_addr(),
        Transport::Tcp,
        hello(2, 4, 0.01, Mode::PerSubstep),
        &with_secret(Some(&s)),
    );
    assert!(err.contains("did not ask for authentication"), "{err}");
    // an impostor that asks for the proof but cannot give its own
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let impostor = std::thread::spawn(move || {
        let (mut c, _) = listener.accept().unwrap();
        c.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
        let _hello = read_frame(&mut c);
        let mut out = Vec::new();
        Message::Challenge { nonce: [9; 32] }.encode(0, &mut out);
        c.write_all(&out).unwrap();
        let _auth = read_frame(&mut c);
        Message::Accept {
            n_coupling: 2,
            mac: Some([0; 32]),
        }
        .encode(1, &mut out);
        c.write_all(&out).unwrap();
    });
    let err = refusal(
        addr,
        Transport::Tcp,
        hello(2, 4, 0.01, Mode::PerSubstep),
        &with_secret(Some(&s)),
    );
    assert!(err.contains("the site's proof of the secret is wrong"), "{err}");
    impostor.join().unwrap();
    server.stop().unwrap();
}

fn read_frame(s: &mut TcpStream) -> Vec<u8> {
    let mut head = [0u8; HEADER_LEN];
    s.read_exact(&mut head).unwrap();
    // version 1 or 2 (sealed): the length is where it is in both
    let len = u32::from_le_bytes(head[12..16].try_into().unwrap()) as usize;
    let mut frame = head.to_vec();
    frame.resize(HEADER_LEN + len, 0);
    s.read_exact(&mut frame[HEADER_LEN..]).unwrap();
    frame
}

#[test]
fn a_recorded_handshake_cannot_be_replayed() {
    let key = secret("a lab secret of sufficient length");
    let built = Arc::new(AtomicUsize::new(0));
    let (mut opts, log) = options();
    opts.secret = Some(key.clone());
    let server = spawn(Transport::Tcp, &opts, &built);
    let addr = server.local_addr();
    let h = hello(2, 4, 0.01, Mode::PerSubstep);
    let session = Session {
        n_coupling: 2,
        substeps: 4,
    };
    // a genuine handshake, recorded byte for byte
    let mut hello_frame = Vec::new();
    Message::Hello(h.clone()).encode(0, &mut hello_frame);
    let mut c = TcpStream::connect(addr).unwrap();
    c.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
    c.write_all(&hello_frame).unwrap();
    let Message::Challenge { nonce: site_nonce } = decode_frame(&read_frame(&mut c), None).unwrap().1 else {
        panic!("expected a Challenge");
    };
    let client_nonce = [5u8; 32];
    let mac = key.mac(Role::Client, &site_nonce, &client_nonce, &hello_frame[HEADER_LEN..]);
    let mut auth_frame = Vec::new();
    Message::Auth {
        nonce: client_nonce,
        mac,
    }
    .encode(1, &mut auth_frame);
    c.write_all(&auth_frame).unwrap();
    let Message::Accept {
        mac: Some(site_mac), ..
    } = decode_frame(&read_frame(&mut c), Some(&session)).unwrap().1
    else {
        panic!("expected an Accept with the site's proof");
    };
    assert!(key.verify(
        Role::Site,
        &site_nonce,
        &client_nonce,
        &hello_frame[HEADER_LEN..],
        &site_mac
    ));
    drop(c);
    assert_eq!(built.load(Ordering::SeqCst), 1);
    // the same bytes again: the site's nonce is new, so the old proof fails
    let mut replay = None;
    for _ in 0..50 {
        let mut r = TcpStream::connect(addr).unwrap();
        r.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
        r.write_all(&hello_frame).unwrap();
        match decode_frame(&read_frame(&mut r), None).unwrap().1 {
            Message::Challenge { nonce } => {
                assert_ne!(nonce, site_nonce, "a fresh nonce per session");
                r.write_all(&auth_frame).unwrap();
                replay = Some(decode_frame(&read_frame(&mut r), Some(&session)).unwrap().1);
                break;
            }
            // the recorded session may still be closing
            Message::Reject { reason } if reason.contains("busy") => std::thread::sleep(Duration::from_millis(20)),
            other => panic!("{other:?}"),
        }
    }
    match replay.expect("the site answered the replay") {
        Message::Reject { reason } => assert!(reason.contains("authentication failed"), "{reason}"),
        other => panic!("a replayed handshake was accepted: {other:?}"),
    }
    // a proof for other session parameters does not carry over either: the Hello is in the MAC
    let mut r = TcpStream::connect(addr).unwrap();
    r.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
    let mut other_frame = Vec::new();
    Message::Hello(Hello {
        substeps: 8,
        dtau: 0.01 / 8.0,
        ..h.clone()
    })
    .encode(0, &mut other_frame);
    r.write_all(&other_frame).unwrap();
    let Message::Challenge { nonce } = decode_frame(&read_frame(&mut r), None).unwrap().1 else {
        panic!("expected a Challenge");
    };
    let mac = key.mac(Role::Client, &nonce, &client_nonce, &hello_frame[HEADER_LEN..]);
    let mut f = Vec::new();
    Message::Auth {
        nonce: client_nonce,
        mac,
    }
    .encode(1, &mut f);
    r.write_all(&f).unwrap();
    match decode_frame(&read_frame(&mut r), None).unwrap().1 {
        Message::Reject { reason } => assert!(reason.contains("authentication failed"), "{reason}"),
        other => panic!("{other:?}"),
    }
    server.stop().unwrap();
    assert_eq!(built.load(Ordering::SeqCst), 1, "the replays built nothing");
    let log = log.lock().unwrap();
    assert_eq!(
        log.iter().filter(|l| l.contains("authentication failed")).count(),
        2,
        "{log:?}"
    );
}

#[test]
fn the_allow_list_drops_other_addresses_unanswered() {
    let built = Arc::new(AtomicUsize::new(0));
    let (mut opts, log) = options();
    opts.allow = Some(vec!["192.0.2.1".parse().unwrap()]);
    let server = spawn(Transport::Tcp, &opts, &built);
    let err = SiteClient::connect(
        server.local_addr(),
        Transport::Tcp,
        hello(2, 4, 0.01, Mode::PerSubstep),
        &client_options(),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("closed the connection"), "{err}");
    server.stop().unwrap();
    assert_eq!(built.load(Ordering::SeqCst), 0);
    assert!(
        log.lock()
            .unwrap()
            .iter()
            .any(|l| l.contains("refused: address not in site.allow"))
    );
}

#[test]
fn secrets_are_checked() {
    let err = Secret::new(b"short\n", "site.secret_file (k)").unwrap_err().to_string();
    assert!(
        err.starts_with("site.secret_file (k): ") && err.contains("5 bytes, at least 16"),
        "{err}"
    );
    // surrounding whitespace (a file's newline) is not part of the secret
    let a = secret("0123456789abcdef0123");
    let b = Secret::new(b"  0123456789abcdef0123\n", "b").unwrap();
    let (n1, n2) = ([1u8; 32], [2u8; 32]);
    assert_eq!(
        a.mac(Role::Client, &n1, &n2, b"hello"),
        b.mac(Role::Client, &n1, &n2, b"hello")
    );
    // HMAC-SHA256 of the documented message, as computed independently by Python's hmac:
    // hmac.new(key, b"SSTP-1 auth" + b"C" + n1 + n2 + struct.pack("<Q", 5) + b"hello", sha256)
    let m = a.mac(Role::Client, &n1, &n2, b"hello");
    let hex: String = m.iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(hex, "8dffe925c1d999936df7338f3783eec7cc74f419ffb22482699f577ffbfb3b08");
    // the two roles' proofs differ (no reflection), and every input is bound
    assert_ne!(m, a.mac(Role::Site, &n1, &n2, b"hello"));
    assert_ne!(m, a.mac(Role::Client, &n2, &n1, b"hello"));
    assert_ne!(m, a.mac(Role::Client, &n1, &n2, b"hellO"));
    assert!(a.verify(Role::Client, &n1, &n2, b"hello", &m));
    let mut bad = m;
    bad[31] ^= 1;
    assert!(!a.verify(Role::Client, &n1, &n2, b"hello", &bad));
    assert_eq!(format!("{a:?}"), "Secret(20 bytes)", "never printed");
}

// ---------------------------------------------------------------------------------------------
// Authenticated session messages (issue 25): every message after the handshake carries a tag.

/// Every command that reached the hosted specimen (what would move the actuators).
type Commands = Arc<Mutex<Vec<Vec<f64>>>>;

/// The hosted substructure, recording the commands it executes.
struct Recording {
    inner: Box<dyn ExperimentalSubstructure>,
    commands: Commands,
}

impl ExperimentalSubstructure for Recording {
    fn n_coupling(&self) -> usize {
        self.inner.n_coupling()
    }
    fn substep(
        &mut self,
        command: &[f64],
        ag: (f64, f64),
        dtau: f64,
        force: &mut [f64],
        displacement: &mut [f64],
    ) -> substep::Result<()> {
        self.commands.lock().unwrap().push(command.to_vec());
        self.inner.substep(command, ag, dtau, force, displacement)
    }
    fn is_linear(&self) -> substep::Result<()> {
        self.inner.is_linear()
    }
    fn state_len(&self) -> usize {
        self.inner.state_len()
    }
    fn write_state(&self, out: &mut [f64]) {
        self.inner.write_state(out)
    }
    fn read_state(&mut self, state: &[f64]) {
        self.inner.read_state(state)
    }
}

/// A site of two ideal springs (`f = −K d` exactly) that records the commands it executes.
fn recording_site(transport: Transport, options: &ServeOptions) -> (substep::site::ServerHandle, Commands) {
    let commands: Commands = Arc::default();
    let record = commands.clone();
    let mut lab = VirtualLabSpec::ideal(vec![spring(0), spring(1)]).factory();
    let factory = move |h: &Hello| -> substep::Result<Box<dyn ExperimentalSubstructure>> {
        Ok(Box::new(Recording {
            inner: lab(h)?,
            commands: record.clone(),
        }))
    };
    let server = match transport {
        Transport::Tcp => SiteServer::spawn(TcpListener::bind("127.0.0.1:0").unwrap(), factory, options).unwrap(),
        Transport::Udp => SiteServer::spawn_udp(UdpSocket::bind("127.0.0.1:0").unwrap(), factory, options).unwrap(),
    };
    (server, commands)
}

/// Whether a frame (header and payload) is a message of the session, not of the handshake.
fn is_session_message(frame: &[u8]) -> bool {
    let kind = u16::from_le_bytes([frame[6], frame[7]]);
    !matches!(
        MessageType::from_code(kind),
        Some(MessageType::Hello | MessageType::Auth)
    )
}

/// Flip the lowest bit of the first payload byte (the lowest bit of the first command of a
/// `Substep`: a change a site without authentication executes as a plausible command).
fn flip_one_bit(frame: &mut [u8]) {
    if frame.len() > HEADER_LEN {
        frame[HEADER_LEN] ^= 1;
    }
}

/// A TCP proxy in front of `site` that passes the handshake and flips one bit of every later
/// client → site message; site → client bytes pass unchanged. Serves one connection.
fn tampering_tcp_proxy(site: SocketAddr) -> SocketAddr {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    std::thread::spawn(move || {
        let Ok((mut client, _)) = listener.accept() else {
            return;
        };
        let mut upstream = TcpStream::connect(site).unwrap();
        let (mut from_site, mut to_client) = (upstream.try_clone().unwrap(), client.try_clone().unwrap());
        std::thread::spawn(move || {
            let _ = std::io::copy(&mut from_site, &mut to_client);
            let _ = to_client.shutdown(std::net::Shutdown::Both);
        });
        client.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        loop {
            let mut frame = vec![0u8; HEADER_LEN];
            if client.read_exact(&mut frame).is_err() {
                break;
            }
            let len = u32::from_le_bytes(frame[12..16].try_into().unwrap()) as usize;
            frame.resize(HEADER_LEN + len, 0);
            if client.read_exact(&mut frame[HEADER_LEN..]).is_err() {
                break;
            }
            if is_session_message(&frame) {
                flip_one_bit(&mut frame);
            }
            if upstream.write_all(&frame).is_err() {
                break;
            }
        }
        let _ = upstream.shutdown(std::net::Shutdown::Both);
    });
    addr
}

/// The UDP counterpart of [`tampering_tcp_proxy`]; runs for at most 20 s.
fn tampering_udp_proxy(site: SocketAddr) -> SocketAddr {
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket.set_read_timeout(Some(Duration::from_millis(10))).unwrap();
    let addr = socket.local_addr().unwrap();
    std::thread::spawn(move || {
        let start = Instant::now();
        let mut buf = vec![0u8; 70_000];
        let mut client = None;
        while start.elapsed() < Duration::from_secs(20) {
            let Ok((n, from)) = socket.recv_from(&mut buf) else {
                continue;
            };
            if from == site {
                if let Some(c) = client {
                    let _ = socket.send_to(&buf[..n], c);
                }
            } else {
                client = Some(from);
                if n >= HEADER_LEN && is_session_message(&buf[..n]) {
                    flip_one_bit(&mut buf[..n]);
                }
                let _ = socket.send_to(&buf[..n], site);
            }
        }
    });
    addr
}

#[test]
fn a_tampering_proxy_ends_the_session_and_nothing_tampered_reaches_the_actuators() {
    let key = secret("the lab's secret, 32 bytes long!");
    for transport in [Transport::Tcp, Transport::Udp] {
        let (mut opts, log) = options();
        opts.secret = Some(key.clone());
        let (server, commands) = recording_site(transport, &opts);
        let proxy = match transport {
            Transport::Tcp => tampering_tcp_proxy(server.local_addr()),
            Transport::Udp => tampering_udp_proxy(server.local_addr()),
        };
        let client = ClientOptions {
            timeout: Duration::from_millis(300),
            ..with_secret(Some(&key))
        };
        let mut site = RemoteSite::connect(proxy, transport, hello(2, 4, 0.01, Mode::PerSubstep), &client).unwrap();
        assert!(site.client().authenticated());
        let (mut f, mut d) = ([0.0; 2], [0.0; 2]);
        let err = site
            .substep(&[1e-3, -1e-3], (0.0, 0.0), 0.0025, &mut f, &mut d)
            .unwrap_err()
            .to_string();
        println!("{transport:?} client: {err}");
        assert!(err.contains(&proxy.to_string()), "the error names the site: {err}");
        assert!(err.contains("message authentication failed"), "{err}");
        match transport {
            // the site ended the session and said why, in an authenticated Error
            Transport::Tcp => assert!(
                err.contains("the site reported an error (reply to Substep #2): message authentication failed: Substep #2: the tag does not match"),
                "{err}"
            ),
            // the site dropped both attempts and said so in authenticated notices
            Transport::Udp => assert!(
                err.contains("message authentication failed: the site dropped Substep #2 as unauthenticated (2 of 2 attempts"),
                "{err}"
            ),
        }
        // the connection is unusable from now on (the run's ramp-down finds it so at once)
        let again = site
            .substep(&[0.0, 0.0], (0.0, 0.0), 0.0025, &mut f, &mut d)
            .unwrap_err()
            .to_string();
        assert!(
            again.contains("connection unusable after an earlier failure"),
            "{again}"
        );
        drop(site);
        std::thread::sleep(Duration::from_millis(100));
        let report = server.stop().unwrap();
        let log = log.lock().unwrap();
        println!("{transport:?} site: {log:#?}");
        assert!(
            commands.lock().unwrap().is_empty(),
            "{transport:?}: a tampered command was executed"
        );
        assert_eq!(report.substeps, 0);
        let peer_says = |needle: &str| {
            log.iter()
                .any(|l| l.starts_with("site: 127.0.0.1:") && l.contains(needle))
        };
        match transport {
            Transport::Tcp => {
                assert!(
                    peer_says(
                        "session ended after 0 sub-steps, 0 steps: message authentication failed: Substep #2: the tag does not match"
                    ),
                    "{log:?}"
                );
                assert_eq!(report.errors, 1);
            }
            Transport::Udp => {
                assert!(
                    peer_says(
                        "message authentication failed: Substep #2: the tag does not match (the message was changed on the way, forged, or sealed with another key); the datagram was dropped, not executed (the session goes on) [1 dropped in this session]"
                    ),
                    "{log:?}"
                );
                assert_eq!(report.dropped, 2);
            }
        }
    }
    // the attack without a secret: the changed command is executed, as before (what the secret
    // is for)
    let (opts, _log) = options();
    let (server, commands) = recording_site(Transport::Tcp, &opts);
    let proxy = tampering_tcp_proxy(server.local_addr());
    let mut site = RemoteSite::connect(
        proxy,
        Transport::Tcp,
        hello(2, 4, 0.01, Mode::PerSubstep),
        &client_options(),
    )
    .unwrap();
    assert!(!site.client().authenticated());
    let (mut f, mut d) = ([0.0; 2], [0.0; 2]);
    site.substep(&[1e-3, -1e-3], (0.0, 0.0), 0.0025, &mut f, &mut d)
        .unwrap();
    drop(site);
    server.stop().unwrap();
    let executed = commands.lock().unwrap()[0].clone();
    assert_ne!(
        executed[0].to_bits(),
        1e-3f64.to_bits(),
        "without a secret the change goes through"
    );
    assert_eq!(executed[0].to_bits(), 1e-3f64.to_bits() ^ 1);
}

/// A hand-made client: the handshake of [`substep::site::auth`] and sealed frames.
fn raw_handshake(
    key: &Secret,
    h: &Hello,
    mut send: impl FnMut(&[u8]),
    mut recv: impl FnMut() -> Vec<u8>,
) -> SessionKeys {
    let mut hello_frame = Vec::new();
    Message::Hello(h.clone()).encode(0, &mut hello_frame);
    send(&hello_frame);
    let Message::Challenge { nonce: site_nonce } = decode_frame(&recv(), None).unwrap().1 else {
        panic!("expected a Challenge");
    };
    let client_nonce = [3u8; 32];
    let payload = &hello_frame[HEADER_LEN..];
    let mut auth = Vec::new();
    Message::Auth {
        nonce: client_nonce,
        mac: key.mac(Role::Client, &site_nonce, &client_nonce, payload),
    }
    .encode(1, &mut auth);
    send(&auth);
    let session = Session {
        n_coupling: h.n_coupling,
        substeps: h.substeps,
    };
    let Message::Accept { mac: Some(_), .. } = decode_frame(&recv(), Some(&session)).unwrap().1 else {
        panic!("expected an Accept");
    };
    key.session_keys(Role::Client, &site_nonce, &client_nonce, payload)
}

fn sealed_substep(seq: u32, command: [f64; 2], keys: &SessionKeys) -> Vec<u8> {
    let mut frame = Vec::new();
    Message::Substep {
        command: command.to_vec(),
        ag: (0.0, 0.0),
        dtau: 0.0025,
    }
    .encode_session(seq, &mut frame, Some(keys));
    frame
}

/// Open a sealed reply from the site (panics if it is not authentic).
fn open_reply(frame: &[u8], keys: &SessionKeys) -> (u32, Message) {
    let header = Header::parse_session(frame, true).unwrap();
    let (header, payload) = open_sealed(frame, &header, keys).unwrap();
    let session = Session {
        n_coupling: 2,
        substeps: 4,
    };
    (header.seq, Message::decode(&header, payload, Some(&session)).unwrap())
}

/// Makes the frame sent after a good `Substep #2` (the session keys, that frame).
type BadFrame = Box<dyn Fn(&SessionKeys, &[u8]) -> Vec<u8>>;

#[test]
fn replayed_reordered_and_changed_messages_end_a_tcp_session() {
    let key = secret("the lab's secret, 32 bytes long!");
    let (mut opts, log) = options();
    opts.secret = Some(key.clone());
    let (server, commands) = recording_site(Transport::Tcp, &opts);
    let h = hello(2, 4, 0.01, Mode::PerSubstep);
    let connect = || {
        let c = TcpStream::connect(server.local_addr()).unwrap();
        c.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
        let keys = {
            let mut w = c.try_clone().unwrap();
            let mut r = c.try_clone().unwrap();
            raw_handshake(&key, &h, |b| w.write_all(b).unwrap(), || read_frame(&mut r))
        };
        (c, keys)
    };
    // (frames to send after a good Substep #2, the reason the site gives)
    let cases: [(&str, BadFrame, &str); 3] = [
        (
            "replay",
            Box::new(|_, first| first.to_vec()),
            "message authentication failed: Substep #2 arrived where #3 was expected (a replayed or reordered message)",
        ),
        (
            "reorder",
            Box::new(|k, _| sealed_substep(4, [2e-3, 0.0], k)),
            "message authentication failed: Substep #4 arrived where #3 was expected (a replayed or reordered message)",
        ),
        (
            "changed sequence number",
            Box::new(|k, _| {
                let mut f = sealed_substep(4, [2e-3, 0.0], k);
                f[8..12].copy_from_slice(&3u32.to_le_bytes());
                f
            }),
            "message authentication failed: Substep #3: the tag does not match",
        ),
    ];
    for (what, bad, reason) in cases {
        let (mut c, keys) = connect();
        let first = sealed_substep(2, [1e-3, -1e-3], &keys);
        c.write_all(&first).unwrap();
        let (seq, reply) = open_reply(&read_frame(&mut c), &keys);
        assert_eq!(seq, 2);
        let Message::Measured { force, .. } = reply else {
            panic!("{what}: {reply:?}");
        };
        assert_eq!(force, vec![-K * 1e-3, K * 1e-3]);
        let executed = commands.lock().unwrap().len();
        c.write_all(&bad(&keys, &first)).unwrap();
        // the site answers an authenticated Error for the request the client is at, and closes
        let (seq, reply) = open_reply(&read_frame(&mut c), &keys);
        assert_eq!(seq, 3, "{what}");
        match reply {
            Message::Error { reason: r } => assert!(r.starts_with(reason), "{what}: {r}"),
            other => panic!("{what}: {other:?}"),
        }
        let mut rest = Vec::new();
        assert_eq!(
            c.read_to_end(&mut rest).unwrap(),
            0,
            "{what}: the site closed the connection"
        );
        // the busy slot frees once the session ended (and the site's ramp to rest is done)
        std::thread::sleep(Duration::from_millis(50));
        // Nothing the client sent after the bad frame was executed: what follows the last
        // authentic command is the site's own ramp to rest (1 s of 2.5 ms sub-steps), that
        // command scaled down to 0.
        let after = commands.lock().unwrap().clone();
        let last = &after[executed - 1];
        assert_eq!(after.len(), executed + 400, "{what}: the ramp to rest");
        for (s, c) in after[executed..].iter().enumerate() {
            let left = 1.0 - (s + 1) as f64 / 400.0;
            assert!(
                (c[0] - left * last[0]).abs() < 1e-15 && (c[1] - left * last[1]).abs() < 1e-15,
                "{what}: ramp sub-step {s}: {c:?}"
            );
        }
        assert_eq!(after.last().unwrap(), &vec![0.0, 0.0], "{what}: at rest");
    }
    server.stop().unwrap();
    // the site's log names the peer and the reason of each
    let log = log.lock().unwrap();
    let ended: Vec<&String> = log
        .iter()
        .filter(|l| {
            l.starts_with("site: 127.0.0.1:")
                && l.contains("session ended after 1 sub-steps, 0 steps: message authentication failed: ")
        })
        .collect();
    assert_eq!(ended.len(), 3, "{log:?}");
    assert!(ended[2].contains("Substep #3: the tag does not match"), "{ended:?}");
    assert!(
        ended.iter().all(|l| l
            .ends_with("; the site ramped its actuators to rest from |command| ≤ 1.000e-3 m over 400 sub-steps (1 s)")),
        "{ended:?}"
    );
}

/// A UDP socket bound with `SO_REUSEPORT` (a second one can share its address and port).
fn reuse_port_socket(addr: Option<SocketAddr>) -> UdpSocket {
    use std::os::fd::FromRawFd;
    // SAFETY: plain socket calls on a descriptor this function owns until it hands it to
    // `UdpSocket`; the option value and the address point to live locals of the given sizes.
    unsafe {
        let fd = libc::socket(libc::AF_INET, libc::SOCK_DGRAM, 0);
        assert!(fd >= 0);
        let one: libc::c_int = 1;
        let len = std::mem::size_of::<libc::c_int>() as libc::socklen_t;
        assert_eq!(
            libc::setsockopt(
                fd,
                libc::SOL_SOCKET,
                libc::SO_REUSEPORT,
                (&one as *const libc::c_int).cast(),
                len
            ),
            0
        );
        let port = addr.map_or(0, |a| a.port());
        let sin = libc::sockaddr_in {
            sin_family: libc::AF_INET as libc::sa_family_t,
            sin_port: port.to_be(),
            sin_addr: libc::in_addr {
                s_addr: u32::from_ne_bytes([127, 0, 0, 1]),
            },
            sin_zero: [0; 8],
        };
        let size = std::mem::size_of::<libc::sockaddr_in>() as libc::socklen_t;
        assert_eq!(libc::bind(fd, (&sin as *const libc::sockaddr_in).cast(), size), 0);
        UdpSocket::from_raw_fd(fd)
    }
}

#[test]
fn a_spoofed_udp_datagram_is_dropped_and_the_session_goes_on() {
    let key = secret("the lab's secret, 32 bytes long!");
    let (mut opts, log) = options();
    opts.secret = Some(key.clone());
    let (server, commands) = recording_site(Transport::Udp, &opts);
    let site = server.local_addr();
    let client = reuse_port_socket(None);
    client.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
    let recv = |s: &UdpSocket| {
        let mut buf = vec![0u8; 70_000];
        let (n, from) = s.recv_from(&mut buf).unwrap();
        assert_eq!(from, site);
        buf.truncate(n);
        buf
    };
    let keys = raw_handshake(
        &key,
        &hello(2, 4, 0.01, Mode::PerSubstep),
        |b| {
            client.send_to(b, site).unwrap();
        },
        || recv(&client),
    );
    let executed = || commands.lock().unwrap().clone();
    let good = sealed_substep(2, [1e-3, -1e-3], &keys);
    client.send_to(&good, site).unwrap();
    assert!(matches!(
        open_reply(&recv(&client), &keys),
        (2, Message::Measured { .. })
    ));
    assert_eq!(executed(), vec![vec![1e-3, -1e-3]]);

    // 1. the right source, a wrong tag: the client's Substep #3 with the command × 1000
    let mut forged = sealed_substep(3, [1e-3, -1e-3], &keys);
    forged[HEADER_LEN..HEADER_LEN + 8].copy_from_slice(&1.0f64.to_le_bytes());
    client.send_to(&forged, site).unwrap();
    // … answered with an authenticated notice, not executed
    match open_reply(&recv(&client), &keys) {
        (3, Message::Dropped { reason }) => assert!(
            reason.starts_with("message authentication failed: Substep #3: the tag does not match"),
            "{reason}"
        ),
        other => panic!("{other:?}"),
    }
    // 2. another socket sending from the client's own address and port, with a forged tag
    let spoofer = reuse_port_socket(Some(client.local_addr().unwrap()));
    assert_eq!(spoofer.local_addr().unwrap(), client.local_addr().unwrap());
    let mut forged = sealed_substep(3, [1.0, -1.0], &keys);
    let last = forged.len() - 1;
    forged[last] ^= 0x55;
    spoofer.send_to(&forged, site).unwrap();
    // and an unauthenticated (version 1) Substep, and garbage
    let mut plain = Vec::new();
    Message::Substep {
        command: vec![1.0, -1.0],
        ag: (0.0, 0.0),
        dtau: 0.0025,
    }
    .encode(3, &mut plain);
    spoofer.send_to(&plain, site).unwrap();
    spoofer.send_to(b"SSTP garbage", site).unwrap();
    // 3. a replay of the authentic #2 from another address: no session with that address
    let elsewhere = UdpSocket::bind("127.0.0.1:0").unwrap();
    elsewhere.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
    elsewhere.send_to(&good, site).unwrap();
    let mut buf = [0u8; 4096];
    let n = elsewhere.recv(&mut buf).unwrap();
    match decode_frame(&buf[..n], None).unwrap().1 {
        Message::Error { reason } => assert!(reason.contains("no session with this address"), "{reason}"),
        other => panic!("{other:?}"),
    }
    // (replies to the shared address may go to either socket while both exist)
    std::thread::sleep(Duration::from_millis(50));
    drop(spoofer);
    // 4. a replay of the authentic #2 from the client's address: the last number the site
    // executed (the forged #3s were not), so it is answered from the cache and not executed
    // again (the notices of the drops may arrive first, here or at the spoofer's socket)
    client.send_to(&good, site).unwrap();
    loop {
        match open_reply(&recv(&client), &keys) {
            (2, Message::Measured { .. }) => break,
            (_, Message::Dropped { .. }) => {}
            other => panic!("{other:?}"),
        }
    }
    assert_eq!(executed().len(), 1, "no spoofed or replayed datagram was executed");

    // the session goes on: the genuine #3 is executed with the genuine command (the notices of
    // the drops may arrive first)
    client.send_to(&sealed_substep(3, [2e-3, 0.0], &keys), site).unwrap();
    let force = loop {
        match open_reply(&recv(&client), &keys) {
            (3, Message::Measured { force, .. }) => break force,
            (_, Message::Dropped { .. }) => {}
            other => panic!("{other:?}"),
        }
    };
    assert_eq!(force, vec![-K * 2e-3, 0.0]);
    // an authentic repeat of #3 (its reply lost) gets the cached reply, not a second move
    client.send_to(&sealed_substep(3, [2e-3, 0.0], &keys), site).unwrap();
    assert!(matches!(
        open_reply(&recv(&client), &keys),
        (3, Message::Measured { .. })
    ));
    assert_eq!(executed(), vec![vec![1e-3, -1e-3], vec![2e-3, 0.0]]);
    let report = server.stop().unwrap();
    assert_eq!(
        report.dropped, 4,
        "the forged tag, the two forged from the other socket, and the garbage"
    );
    // the session was never ended
    assert_eq!(report.errors, 0);
    assert_eq!(report.sessions, 1);
    let log = log.lock().unwrap();
    assert!(!log.iter().any(|l| l.contains("session ended")), "{log:?}");
    assert_eq!(
        log.iter().filter(|l| l.contains("the datagram was dropped")).count(),
        4,
        "{log:?}"
    );
}
