//! Remote sites on loopback: the `SSTP` protocol (per sub-step and per step, TCP and UDP) must
//! reproduce a local run bit for bit; faults end a test with a clear error and keep the data
//! recorded so far; the OpenFresco server answers a genericClient like OpenSees expects and
//! (when openseespy is installed) an OpenSees model with a `genericClient` element hosted here
//! matches the same model with a native element.
//!
//! Over 800 lines on purpose: every file under `tests/` is its own test binary that links the
//! whole library, so related checks share one binary to keep the CI build short; the sections
//! below are independent and can be read one at a time.

use nalgebra::{DMatrix, DVector, dmatrix};
use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use substep::model::{StructuralModel, TmdSystem};
use substep::site::openfresco::{ElementSpec, OpenFrescoServer, OpenFrescoSite, Sizes, SubstructureElement, action};
use substep::site::protocol::{HEADER_LEN, Header, MAX_PAYLOAD, Session, decode_frame};
use substep::site::{
    ClientOptions, Hello, Message, Mode, RemoteSite, RemoteStepSite, RemoteStepTest, ServeOptions, SiteClient,
    SiteServer, StepReply, StepRequest, Transport, VirtualLabSpec,
};
use substep::specimen::SpecimenSpec;
use substep::substructure::{
    ErrorForceSpec, ExperimentalSubstructure, SubstepController, SubstepSettings, SubstructureTest,
};
use substep::transfer::{ActuatorSpec, Dynamics, SensorSpec, VirtualLab};

// ---------------------------------------------------------------------------------------------
// The test problem: a 2-DOF shear frame, a TMD on the top floor and a spring + dashpot on the
// first floor (two coupling DOFs, so G_cc is a full 2×2 matrix), actuators with first-order
// dynamics and a delay (the lab has state), P = 1 error-force compensation.

const DT: f64 = 0.01;
const K_SUB: usize = 4;
const STEPS: usize = 300;

fn frame() -> StructuralModel {
    let p = TmdSystem::typical();
    let (k, c) = p.primary();
    let m = p.mass;
    StructuralModel::new(
        dmatrix![m, 0.0; 0.0, m],
        dmatrix![2.0 * c, -c; -c, c],
        dmatrix![2.0 * k, -k; -k, k],
        None,
    )
    .unwrap()
}

fn specimens() -> Vec<SpecimenSpec> {
    let p = TmdSystem::typical();
    let (ms, ks, cs) = p.absorber();
    vec![
        SpecimenSpec::LinearSdof {
            dof: 1,
            mass: Some(ms),
            stiffness: ks,
            damping: cs,
        },
        SpecimenSpec::LinearSdof {
            dof: 0,
            mass: None,
            stiffness: 0.3 * ks,
            damping: 0.5 * cs,
        },
    ]
}

const COUPLING: [usize; 2] = [1, 0];

fn actuator() -> ActuatorSpec {
    ActuatorSpec {
        dynamics: Dynamics::FirstOrder { time_constant: 0.002 },
        delay: 0.0015,
    }
}

fn lab(dtau: f64) -> VirtualLab {
    let n = COUPLING.len();
    VirtualLab::from_specs(
        &COUPLING,
        &specimens(),
        &vec![actuator(); n],
        &vec![SensorSpec::ideal(); n],
        &vec![SensorSpec::ideal(); n],
        dtau,
        2,
    )
    .unwrap()
}

/// The server's lab: built from the client's handshake (coupling DOFs, Δτ).
fn lab_spec() -> VirtualLabSpec {
    VirtualLabSpec {
        specimens: specimens(),
        actuator: actuator(),
        force_sensor: SensorSpec::ideal(),
        displacement_sensor: SensorSpec::ideal(),
        inner_steps: 2,
    }
}

fn lab_factory(h: &Hello) -> substep::Result<Box<dyn ExperimentalSubstructure>> {
    Ok(Box::new(lab_spec().build(h)?))
}

fn controller(model: &StructuralModel, ag0: f64) -> SubstepController {
    let settings = SubstepSettings {
        dt: DT,
        beta: 0.25,
        gamma: 0.5,
        substeps: K_SUB,
        coupling_dofs: COUPLING.to_vec(),
        error_force: ErrorForceSpec::Pid { p: 1.0, i: 0.0, d: 0.0 },
    };
    SubstepController::new(model, &settings, &(-model.effective_mass_vector() * ag0)).unwrap()
}

fn ground_motion(steps: usize) -> Vec<f64> {
    (0..=steps)
        .map(|i| {
            let t = i as f64 * DT;
            2.0 * (2.0 * std::f64::consts::PI * (0.5 * t + 0.4 * t * t)).sin() * (-0.2 * t).exp()
        })
        .collect()
}

/// Bits of `[u; v; a]` after each step.
type History = Vec<Vec<u64>>;

fn bits(u: &[f64], v: &[f64], a: &[f64]) -> Vec<u64> {
    u.iter().chain(v).chain(a).map(|x| x.to_bits()).collect()
}

/// Run `test` for all steps (or until the first error), recording the state after each step.
fn run_substructure(test: &mut SubstructureTest, ag: &[f64]) -> (History, Option<substep::Error>) {
    let mut h = Vec::new();
    for i in 0..ag.len() - 1 {
        if let Err(e) = test.step(ag[i], ag[i + 1], &mut ()) {
            return (h, Some(e));
        }
        let r = test.record();
        h.push(bits(r.u, r.v, r.a));
    }
    (h, None)
}

fn local_history(ag: &[f64]) -> History {
    let model = frame();
    let ctrl = controller(&model, ag[0]);
    let dtau = DT / K_SUB as f64;
    let mut test = SubstructureTest::new(&model, ctrl, Box::new(lab(dtau))).unwrap();
    let (h, err) = run_substructure(&mut test, ag);
    assert!(err.is_none(), "{err:?}");
    h
}

fn client_options(timeout_ms: u64) -> ClientOptions {
    ClientOptions {
        timeout: Duration::from_millis(timeout_ms),
        connect_timeout: Duration::from_secs(2),
        udp_retries: 3,
        secret: None,
    }
}

fn tcp_listener() -> TcpListener {
    TcpListener::bind("127.0.0.1:0").unwrap()
}

fn udp_socket() -> UdpSocket {
    UdpSocket::bind("127.0.0.1:0").unwrap()
}

type Log = Arc<Mutex<Vec<String>>>;

fn serve_options(once: bool) -> (ServeOptions, Log) {
    let log: Log = Arc::default();
    let sink = log.clone();
    let options = ServeOptions {
        once,
        idle_timeout: Some(Duration::from_secs(10)),
        io_timeout: Duration::from_secs(2),
        log: Some(Arc::new(move |line: &str| sink.lock().unwrap().push(line.to_string()))),
        ..ServeOptions::default()
    };
    (options, log)
}

fn remote_substep_history(transport: Transport, addr: SocketAddr, ag: &[f64]) -> History {
    let model = frame();
    let ctrl = controller(&model, ag[0]);
    let site = RemoteSite::for_controller(addr, transport, &ctrl, &client_options(2000)).unwrap();
    let mut test = SubstructureTest::new(&model, ctrl, Box::new(site)).unwrap();
    let (h, err) = run_substructure(&mut test, ag);
    assert!(err.is_none(), "{err:?}");
    h
}

fn remote_step_history(transport: Transport, addr: SocketAddr, ag: &[f64], options: &ClientOptions) -> History {
    let model = frame();
    let ctrl = controller(&model, ag[0]);
    let site = RemoteStepSite::for_controller(addr, transport, &ctrl, options).unwrap();
    let mut test = RemoteStepTest::new(&model, ctrl, site).unwrap();
    let mut h = Vec::new();
    for i in 0..ag.len() - 1 {
        test.step(ag[i], ag[i + 1], &mut ()).unwrap();
        let r = test.record();
        h.push(bits(r.u, r.v, r.a));
    }
    h
}

fn assert_same(remote: &History, local: &History, what: &str) {
    assert_eq!(remote.len(), local.len(), "{what}: number of steps");
    for (i, (r, l)) in remote.iter().zip(local).enumerate() {
        assert_eq!(r, l, "{what}: state after step {} differs from the local run", i + 1);
    }
}

// ---------------------------------------------------------------------------------------------
// Bit-for-bit agreement with the local run.

#[test]
fn per_substep_tcp_matches_local_bit_for_bit() {
    let ag = ground_motion(STEPS);
    let local = local_history(&ag);
    let (options, log) = serve_options(true);
    let server = SiteServer::spawn(tcp_listener(), lab_factory, &options).unwrap();
    let remote = remote_substep_history(Transport::Tcp, server.local_addr(), &ag);
    let report = server.join().unwrap();
    assert_same(&remote, &local, "per-substep over TCP");
    assert_eq!(report.sessions, 1);
    assert_eq!(report.substeps, (STEPS * K_SUB) as u64);
    assert_eq!(report.errors, 0);
    let log = log.lock().unwrap();
    assert!(
        log.iter().any(|l| l.contains("connected") && l.contains("per-substep")),
        "{log:?}"
    );
    assert!(
        log.iter().any(|l| l.contains("session ended after 1200 sub-steps")),
        "{log:?}"
    );
    // the response is not trivial
    let u_max = local.iter().map(|s| f64::from_bits(s[0]).abs()).fold(0.0, f64::max);
    assert!(u_max > 1e-3, "u_max = {u_max}");
}

#[test]
fn per_step_tcp_matches_local_bit_for_bit() {
    let ag = ground_motion(STEPS);
    let local = local_history(&ag);
    let (options, log) = serve_options(true);
    let server = SiteServer::spawn(tcp_listener(), lab_factory, &options).unwrap();
    let remote = remote_step_history(Transport::Tcp, server.local_addr(), &ag, &client_options(2000));
    let report = server.join().unwrap();
    assert_same(&remote, &local, "per-step over TCP");
    assert_eq!((report.steps, report.substeps), (STEPS as u64, (STEPS * K_SUB) as u64));
    assert!(log.lock().unwrap().iter().any(|l| l.contains("per-step")));
}

#[test]
fn per_substep_udp_matches_local_bit_for_bit() {
    let ag = ground_motion(STEPS);
    let local = local_history(&ag);
    let (options, _log) = serve_options(true);
    let server = SiteServer::spawn_udp(udp_socket(), lab_factory, &options).unwrap();
    let remote = remote_substep_history(Transport::Udp, server.local_addr(), &ag);
    let report = server.join().unwrap();
    assert_same(&remote, &local, "per-substep over UDP");
    assert_eq!(report.substeps, (STEPS * K_SUB) as u64);
}

#[test]
fn per_step_udp_matches_local_bit_for_bit() {
    let ag = ground_motion(STEPS);
    let local = local_history(&ag);
    let (options, _log) = serve_options(true);
    let server = SiteServer::spawn_udp(udp_socket(), lab_factory, &options).unwrap();
    let remote = remote_step_history(Transport::Udp, server.local_addr(), &ag, &client_options(2000));
    let report = server.join().unwrap();
    assert_same(&remote, &local, "per-step over UDP");
    assert_eq!(report.steps, STEPS as u64);
}

/// A UDP proxy between client and server that drops every `drop_every`-th reply and sends
/// every `dup_every`-th request twice. Runs until `stop` is raised (or 20 s pass).
fn lossy_udp_proxy(
    server: SocketAddr,
    drop_every: usize,
    dup_every: usize,
) -> (SocketAddr, Arc<AtomicBool>, JoinHandle<(usize, usize)>) {
    let socket = udp_socket();
    socket.set_read_timeout(Some(Duration::from_millis(10))).unwrap();
    let addr = socket.local_addr().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let t = std::thread::spawn(move || {
        let start = Instant::now();
        let mut buf = vec![0u8; 70_000];
        let mut client = None;
        let (mut replies, mut requests, mut dropped, mut duplicated) = (0, 0, 0, 0);
        while !flag.load(Ordering::Relaxed) && start.elapsed() < Duration::from_secs(20) {
            let Ok((n, from)) = socket.recv_from(&mut buf) else {
                continue;
            };
            if from == server {
                replies += 1;
                if replies % drop_every == 0 {
                    dropped += 1;
                    continue;
                }
                if let Some(c) = client {
                    let _ = socket.send_to(&buf[..n], c);
                }
            } else {
                client = Some(from);
                requests += 1;
                let _ = socket.send_to(&buf[..n], server);
                if requests % dup_every == 0 {
                    duplicated += 1;
                    let _ = socket.send_to(&buf[..n], server);
                }
            }
        }
        (dropped, duplicated)
    });
    (addr, stop, t)
}

#[test]
fn udp_lost_replies_are_retried_and_duplicates_ignored() {
    lossy_udp_runs(None);
}

/// With a secret the retransmit rule holds for authentic repeats: the site answers a repeated
/// sealed request with its cached reply and executes every sub-step once.
#[test]
fn authenticated_udp_lost_replies_are_retried_and_duplicates_ignored() {
    lossy_udp_runs(Some(
        substep::site::Secret::new(b"0123456789abcdef0123456789abcdef", "test").unwrap(),
    ));
}

fn lossy_udp_runs(secret: Option<substep::site::Secret>) {
    let steps = 60;
    let ag = ground_motion(steps);
    let local = local_history(&ag);
    let (mut options, log) = serve_options(true);
    options.secret = secret.clone();
    let server = SiteServer::spawn_udp(udp_socket(), lab_factory, &options).unwrap();
    let (proxy, stop, proxy_thread) = lossy_udp_proxy(server.local_addr(), 10, 5);
    let opts = ClientOptions {
        timeout: Duration::from_millis(50),
        connect_timeout: Duration::from_secs(1),
        udp_retries: 8,
        secret: secret.clone(),
    };
    let t0 = Instant::now();
    // per sub-step: ~250 requests, every 10th reply lost, every 5th request duplicated
    let model = frame();
    let ctrl = controller(&model, ag[0]);
    let site = RemoteSite::for_controller(proxy, Transport::Udp, &ctrl, &opts).unwrap();
    let mut test = SubstructureTest::new(&model, ctrl, Box::new(site)).unwrap();
    let (remote, err) = run_substructure(&mut test, &ag);
    assert!(err.is_none(), "{err:?}");
    drop(test);
    // per step, through a second proxy that loses even more
    let server2 = SiteServer::spawn_udp(udp_socket(), lab_factory, &options).unwrap();
    let (proxy2, stop2, proxy_thread2) = lossy_udp_proxy(server2.local_addr(), 6, 3);
    let remote_step = remote_step_history(Transport::Udp, proxy2, &ag, &opts);
    println!("lossy UDP runs took {:?}", t0.elapsed());
    // the site executed every sub-step exactly once despite the duplicates and retries (the
    // clients' final Stop passes through the proxies: join the servers first)
    let report = server.join().unwrap();
    let report2 = server2.join().unwrap();
    println!("{}", log.lock().unwrap().join("\n"));
    assert_eq!(report.substeps, (steps * K_SUB) as u64);
    assert_eq!(report2.substeps, (steps * K_SUB) as u64);
    stop.store(true, Ordering::Relaxed);
    stop2.store(true, Ordering::Relaxed);
    let (dropped, duplicated) = proxy_thread.join().unwrap();
    let (dropped2, duplicated2) = proxy_thread2.join().unwrap();
    println!("dropped {dropped}/{dropped2} replies, duplicated {duplicated}/{duplicated2} requests");
    assert!(dropped > 10 && duplicated > 10 && dropped2 > 5 && duplicated2 > 5);
    assert_same(&remote, &local, "per-substep over lossy UDP");
    assert_same(&remote_step, &local, "per-step over lossy UDP");
    let log = log.lock().unwrap();
    let sessions: Vec<&String> = log.iter().filter(|l| l.contains("connected over UDP")).collect();
    assert_eq!(sessions.len(), 2, "{log:?}");
    let note = if secret.is_some() {
        ", authenticated)"
    } else {
        ", messages not authenticated: no secret)"
    };
    assert!(sessions.iter().all(|l| l.ends_with(note)), "{sessions:?}");
    assert_eq!(report.dropped + report2.dropped, 0, "no datagram failed authentication");
}

// ---------------------------------------------------------------------------------------------
// Handshake, heartbeat, server behaviour.

#[test]
fn handshake_is_rejected_with_a_reason() {
    let (options, log) = serve_options(false);
    let server = SiteServer::spawn(tcp_listener(), lab_factory, &options).unwrap();
    let addr = server.local_addr();
    let reject = |hello: &Hello, transport: Transport, addr: SocketAddr| -> String {
        let err = SiteClient::connect(addr, transport, hello.clone(), &client_options(1000))
            .err()
            .expect("must be rejected")
            .to_string();
        println!("{err}");
        assert!(err.contains(&addr.to_string()), "{err}");
        err
    };
    // the client couples only at model DOF 2, but the site has a specimen on DOF 1 too
    let hello = Hello {
        n_coupling: 1,
        substeps: 2,
        mode: Mode::PerSubstep,
        dt: 0.01,
        dtau: 0.005,
        gain_cc: vec![1e-6],
        coupling_dofs: vec![1],
    };
    let err = reject(&hello, Transport::Tcp, addr);
    assert!(
        err.contains("rejected the connection") && err.contains("specimen[2].dof"),
        "{err}"
    );
    // the client couples at model DOF 3 where the site has no specimen
    let two = Hello {
        n_coupling: 2,
        gain_cc: vec![1e-6, 0.0, 0.0, 1e-6],
        coupling_dofs: vec![0, 2],
        ..hello.clone()
    };
    let err = reject(&two, Transport::Tcp, addr);
    assert!(err.contains("model DOF 3 where this site has no specimen"), "{err}");
    // a factory that ignores the handshake: the coupling DOF counts are checked
    let fixed = SiteServer::spawn(
        tcp_listener(),
        |_: &Hello| -> substep::Result<Box<dyn ExperimentalSubstructure>> { Ok(Box::new(lab(0.001))) },
        &options,
    )
    .unwrap();
    let err = reject(&hello, Transport::Tcp, fixed.local_addr());
    assert!(
        err.contains("the site has 2 coupling DOFs, the client asked for 1"),
        "{err}"
    );
    // a factory error is passed on as the reason
    let failing = SiteServer::spawn(
        tcp_listener(),
        |_: &Hello| -> substep::Result<Box<dyn ExperimentalSubstructure>> {
            Err(substep::Error::invalid("specimen.stiffness", "must be >= 0"))
        },
        &options,
    )
    .unwrap();
    let err = reject(&hello, Transport::Tcp, failing.local_addr());
    assert!(err.contains("specimen.stiffness: must be >= 0"), "{err}");
    // UDP cannot carry a StepResult of 3000 × 2 × 3 f64 (refused before anything is sent)
    let big = Hello {
        substeps: 3000,
        mode: Mode::PerStep,
        ..two
    };
    let err = reject(&big, Transport::Udp, addr);
    assert!(err.contains("UDP"), "{err}");
    drop(server);
    let rejected = log.lock().unwrap().iter().filter(|l| l.contains("rejected")).count();
    assert_eq!(rejected, 4);
}

#[test]
fn heartbeat_and_stop() {
    let (options, log) = serve_options(true);
    let server = SiteServer::spawn(tcp_listener(), lab_factory, &options).unwrap();
    let model = frame();
    let ctrl = controller(&model, 0.0);
    let hello = Hello::from_controller(&ctrl, Mode::PerSubstep);
    let mut client = SiteClient::connect(server.local_addr(), Transport::Tcp, hello, &client_options(1000)).unwrap();
    for _ in 0..5 {
        let rtt = client.ping().unwrap();
        assert!(rtt < Duration::from_millis(500));
    }
    client.stop("test done").unwrap();
    let report = server.join().unwrap();
    assert_eq!(report.sessions, 1);
    assert!(
        log.lock()
            .unwrap()
            .iter()
            .any(|l| l.contains("client stopped (test done)"))
    );
}

// ---------------------------------------------------------------------------------------------
// Protocol: round trip, named errors, fuzzing.

fn sample_messages() -> (Session, Vec<Message>) {
    let s = Session {
        n_coupling: 2,
        substeps: 3,
    };
    let reply = StepReply {
        commands: (0..6).map(|i| i as f64 * 0.1).collect(),
        forces: (0..6).map(|i| -(i as f64)).collect(),
        displacements: (0..6).map(|i| i as f64 * 1e-3).collect(),
    };
    let msgs = vec![
        Message::Hello(Hello {
            n_coupling: 2,
            substeps: 3,
            mode: Mode::PerStep,
            dt: 0.01,
            dtau: 0.01 / 3.0,
            gain_cc: vec![1e-6, 2e-7, 2e-7, 3e-6],
            coupling_dofs: vec![4, 0],
        }),
        Message::Accept {
            n_coupling: 2,
            mac: None,
        },
        Message::Reject {
            reason: "busy — Grüße".into(),
        },
        Message::Substep {
            command: vec![1e-3, -2e-3],
            ag: (0.5, -0.25),
            dtau: 0.0025,
        },
        Message::Measured {
            force: vec![-12.5, 3.0],
            displacement: vec![1e-3, -2e-3],
        },
        Message::Step(StepRequest {
            predictor_c_prev: vec![1.0, 2.0],
            predictor_c: vec![3.0, 4.0],
            force_prev: vec![5.0, 6.0],
            ag: (0.1, 0.2),
        }),
        Message::StepResult(reply),
        Message::Heartbeat,
        Message::Stop { reason: "done".into() },
        Message::Error { reason: String::new() },
        Message::Accept {
            n_coupling: 2,
            mac: Some([7; 32]),
        },
        Message::Challenge { nonce: [3; 32] },
        Message::Auth {
            nonce: [1; 32],
            mac: [2; 32],
        },
    ];
    (s, msgs)
}

#[test]
fn protocol_round_trip() {
    let (s, msgs) = sample_messages();
    let mut buf = Vec::new();
    for (seq, m) in msgs.iter().enumerate() {
        m.encode(seq as u32 * 1000, &mut buf);
        assert_eq!(&buf[..4], b"SSTP");
        let (h, back) = decode_frame(&buf, Some(&s)).unwrap();
        assert_eq!(h.seq, seq as u32 * 1000);
        assert_eq!(h.len as usize, buf.len() - HEADER_LEN);
        assert_eq!(&back, m);
    }
}

fn decode_err(frame: &[u8], s: Option<&Session>) -> String {
    decode_frame(frame, s).expect_err("must be rejected").to_string()
}

#[test]
fn protocol_errors_name_the_field() {
    let (s, msgs) = sample_messages();
    let mut f = Vec::new();
    msgs[4].encode(7, &mut f); // Measured, n_c = 2
    let good = f.clone();

    f[0..4].copy_from_slice(b"HTTP");
    assert!(decode_err(&f, Some(&s)).contains("header.magic"));

    f = good.clone();
    f[4] = 9;
    assert!(decode_err(&f, Some(&s)).contains("header.version"));

    f = good.clone();
    f[6] = 77;
    assert!(decode_err(&f, Some(&s)).contains("header.type"));

    f = good.clone();
    f[12..16].copy_from_slice(&((MAX_PAYLOAD + 1) as u32).to_le_bytes());
    assert!(decode_err(&f, Some(&s)).contains("header.length"));

    f = good.clone();
    f.truncate(f.len() - 3);
    assert!(decode_err(&f, Some(&s)).contains("header.length"));

    // a Measured for n_c = 2 in a session with n_c = 1
    let one = Session {
        n_coupling: 1,
        substeps: 3,
    };
    let e = decode_err(&good, Some(&one));
    assert!(e.contains("Measured payload") && e.contains("expected 16"), "{e}");

    // before the handshake
    assert!(decode_err(&good, None).contains("before the handshake"));

    // NaN in force[1]
    f = good.clone();
    f[HEADER_LEN + 8..HEADER_LEN + 16].copy_from_slice(&f64::NAN.to_le_bytes());
    let e = decode_err(&f, Some(&s));
    assert!(e.contains("Measured.force[1]") && e.contains("not finite"), "{e}");

    // infinity in the Hello's gain, a zero time step, an unknown mode
    let mut h = Vec::new();
    msgs[0].encode(0, &mut h);
    let mut g = h.clone();
    g[HEADER_LEN + 32 + 8..HEADER_LEN + 32 + 16].copy_from_slice(&f64::INFINITY.to_le_bytes());
    assert!(decode_err(&g, None).contains("Hello.gain_cc[1]"));
    g = h.clone();
    g[HEADER_LEN + 16..HEADER_LEN + 24].copy_from_slice(&0.0f64.to_le_bytes());
    assert!(decode_err(&g, None).contains("Hello.dt"));
    g = h.clone();
    g[HEADER_LEN + 12] = 5;
    assert!(decode_err(&g, None).contains("Hello.mode"));
    g = h.clone();
    g[HEADER_LEN + 8..HEADER_LEN + 12].copy_from_slice(&0u32.to_le_bytes());
    assert!(decode_err(&g, None).contains("Hello.substeps"));

    // a reason string that is not UTF-8, or whose length is wrong
    let mut r = Vec::new();
    msgs[8].encode(1, &mut r);
    let mut b = r.clone();
    b[HEADER_LEN + 4] = 0xff;
    assert!(decode_err(&b, None).contains("UTF-8"));
    b = r.clone();
    b[HEADER_LEN] = 9;
    assert!(decode_err(&b, None).contains("Stop.reason"));
}

#[test]
fn protocol_fuzz_never_panics() {
    let (s, msgs) = sample_messages();
    let mut rng = ChaCha8Rng::seed_from_u64(0x5157_9a11);
    let mut encoded: Vec<Vec<u8>> = Vec::new();
    for (i, m) in msgs.iter().enumerate() {
        let mut b = Vec::new();
        m.encode(i as u32, &mut b);
        encoded.push(b);
    }
    let (mut ok, mut rejected) = (0, 0);
    let mut frame = Vec::new();
    for round in 0..30_000 {
        frame.clear();
        match round % 3 {
            // pure garbage, sometimes with a valid magic and version
            0 => {
                let len = rng.random_range(0..200);
                frame.resize(len, 0);
                rng.fill_bytes(&mut frame);
                if len >= 6 && rng.random_bool(0.5) {
                    frame[..4].copy_from_slice(b"SSTP");
                    frame[4..6].copy_from_slice(&1u16.to_le_bytes());
                }
            }
            // a valid frame with a few bytes flipped
            1 => {
                frame.extend_from_slice(&encoded[rng.random_range(0..encoded.len())]);
                for _ in 0..rng.random_range(1..4) {
                    let i = rng.random_range(0..frame.len());
                    frame[i] ^= 1 << rng.random_range(0..8);
                }
            }
            // a valid frame truncated or extended
            _ => {
                frame.extend_from_slice(&encoded[rng.random_range(0..encoded.len())]);
                if rng.random_bool(0.5) {
                    let cut = rng.random_range(0..frame.len());
                    frame.truncate(cut);
                } else {
                    for _ in 0..rng.random_range(1..16) {
                        frame.push(rng.random());
                    }
                }
            }
        }
        let session = if rng.random_bool(0.8) { Some(&s) } else { None };
        match decode_frame(&frame, session) {
            Ok((h, m)) => {
                ok += 1;
                // whatever decodes re-encodes to the same bytes
                let mut again = Vec::new();
                m.encode(h.seq, &mut again);
                assert_eq!(again, frame, "round {round}: {m:?}");
            }
            Err(e) => {
                rejected += 1;
                assert!(e.to_string().starts_with("site protocol: "), "{e}");
            }
        }
    }
    println!("fuzz: {ok} decoded, {rejected} rejected");
    assert!(rejected > 20_000 && ok > 100, "{ok} / {rejected}");
}

// ---------------------------------------------------------------------------------------------
// Faults: the site goes away, stalls, or answers garbage. The test's step returns Err naming
// the address; everything recorded before the failure equals the local run.

#[test]
fn site_disappears_mid_test() {
    for transport in [Transport::Tcp, Transport::Udp] {
        let ag = ground_motion(40);
        let local = local_history(&ag);
        let (options, _log) = serve_options(false);
        let server = match transport {
            Transport::Tcp => SiteServer::spawn(tcp_listener(), lab_factory, &options).unwrap(),
            Transport::Udp => SiteServer::spawn_udp(udp_socket(), lab_factory, &options).unwrap(),
        };
        let addr = server.local_addr();
        let model = frame();
        let ctrl = controller(&model, ag[0]);
        let opts = ClientOptions {
            timeout: Duration::from_millis(300),
            connect_timeout: Duration::from_secs(1),
            udp_retries: 2,
            secret: None,
        };
        let site = RemoteSite::for_controller(addr, transport, &ctrl, &opts).unwrap();
        let mut test = SubstructureTest::new(&model, ctrl, Box::new(site)).unwrap();
        let mut recorded = Vec::new();
        for i in 0..20 {
            test.step(ag[i], ag[i + 1], &mut ()).unwrap();
            let r = test.record();
            recorded.push(bits(r.u, r.v, r.a));
        }
        server.stop().unwrap(); // the site process goes away
        let t0 = Instant::now();
        let err = test.step(ag[20], ag[21], &mut ()).expect_err("must fail").to_string();
        let took = t0.elapsed();
        println!("{transport:?}: {err} ({took:?})");
        assert!(err.contains(&addr.to_string()), "{err}");
        assert!(err.contains("the site is gone") || err.contains("timeout"), "{err}");
        assert!(took < Duration::from_millis(300 * 3 + 500), "{took:?}");
        // the data up to the failure is intact, and the state is still that of step 20
        assert_eq!(test.steps_done(), 20);
        let r = test.record();
        assert_eq!(bits(r.u, r.v, r.a), local[19]);
        assert_same(&recorded, &local[..20].to_vec(), "before the failure");
        // the connection stays failed
        let again = test.step(ag[20], ag[21], &mut ()).err().unwrap().to_string();
        assert!(again.contains("unusable after an earlier failure"), "{again}");
    }
}

/// What a scripted site does after answering `good` requests correctly.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Fault {
    Stall,
    WrongMagic,
    WrongLength,
    NanForce,
    WrongSequence,
    WrongType,
    Close,
}

fn read_raw_frame(stream: &mut TcpStream) -> Option<Vec<u8>> {
    let mut f = vec![0u8; HEADER_LEN];
    stream.read_exact(&mut f).ok()?;
    let h = Header::parse(&f).ok()?;
    f.resize(HEADER_LEN + h.len as usize, 0);
    stream.read_exact(&mut f[HEADER_LEN..]).ok()?;
    Some(f)
}

/// A hand-written per-sub-step site (one connection) that misbehaves after `good` sub-steps.
fn scripted_site(fault: Fault, good: usize) -> (SocketAddr, JoinHandle<()>) {
    let listener = tcp_listener();
    let addr = listener.local_addr().unwrap();
    let t = std::thread::spawn(move || {
        let (mut stream, _) = listener.accept().unwrap();
        stream.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let hello = match decode_frame(&read_raw_frame(&mut stream).unwrap(), None).unwrap() {
            (_, Message::Hello(h)) => h,
            other => panic!("{other:?}"),
        };
        let s = hello.session();
        let mut lab = lab(hello.dtau);
        let mut out = Vec::new();
        Message::Accept {
            n_coupling: hello.n_coupling,
            mac: None,
        }
        .encode(0, &mut out);
        stream.write_all(&out).unwrap();
        let n = hello.n_coupling;
        let (mut force, mut disp) = (vec![0.0; n], vec![0.0; n]);
        for count in 0.. {
            let Some(frame) = read_raw_frame(&mut stream) else {
                return;
            };
            let (h, msg) = decode_frame(&frame, Some(&s)).unwrap();
            let Message::Substep { command, ag, dtau } = msg else {
                return;
            };
            lab.substep(&command, ag, dtau, &mut force, &mut disp).unwrap();
            let reply = Message::Measured {
                force: force.clone(),
                displacement: disp.clone(),
            };
            if count < good {
                reply.encode(h.seq, &mut out);
                stream.write_all(&out).unwrap();
                continue;
            }
            match fault {
                Fault::Stall => {
                    // stop answering; wait (bounded) until the client gives up
                    let mut b = [0u8; 64];
                    let until = Instant::now() + Duration::from_secs(5);
                    while Instant::now() < until {
                        match stream.read(&mut b) {
                            Ok(0) => break,
                            Ok(_) => {}
                            Err(_) => {}
                        }
                    }
                }
                Fault::Close => {}
                _ => {
                    reply.encode(h.seq, &mut out);
                    match fault {
                        Fault::WrongMagic => out[..4].copy_from_slice(b"SSTQ"),
                        Fault::WrongLength => {
                            // a Measured with one value too many
                            Message::Measured {
                                force: vec![1.0; n + 1],
                                displacement: vec![0.0; n],
                            }
                            .encode(h.seq, &mut out)
                        }
                        Fault::NanForce => {
                            out[HEADER_LEN..HEADER_LEN + 8].copy_from_slice(&f64::NAN.to_le_bytes());
                        }
                        Fault::WrongSequence => out[8..12].copy_from_slice(&(h.seq + 5).to_le_bytes()),
                        Fault::WrongType => Message::Heartbeat.encode(h.seq, &mut out),
                        Fault::Stall | Fault::Close => unreachable!(),
                    }
                    let _ = stream.write_all(&out);
                    // keep the connection open until the client leaves (bounded)
                    let mut b = [0u8; 64];
                    let _ = stream.read(&mut b);
                }
            }
            return;
        }
    });
    (addr, t)
}

#[test]
fn faulty_sites_give_clear_errors_and_keep_the_data() {
    let ag = ground_motion(20);
    let local = local_history(&ag);
    let good_steps = 7;
    let timeout = Duration::from_millis(250);
    for (fault, expect) in [
        (Fault::Stall, "within 0.250 s (timeout)"),
        (Fault::Close, "the site is gone"),
        (Fault::WrongMagic, "header.magic"),
        (Fault::WrongLength, "Measured payload"),
        (Fault::NanForce, "Measured.force[0]"),
        (Fault::WrongSequence, "header.seq"),
        (Fault::WrongType, "unexpected Heartbeat reply to Substep"),
    ] {
        // the fault hits in the middle of step 8
        let (addr, site_thread) = scripted_site(fault, good_steps * K_SUB + 2);
        let model = frame();
        let ctrl = controller(&model, ag[0]);
        let opts = ClientOptions {
            timeout,
            ..ClientOptions::default()
        };
        let site = RemoteSite::for_controller(addr, Transport::Tcp, &ctrl, &opts).unwrap();
        let mut test = SubstructureTest::new(&model, ctrl, Box::new(site)).unwrap();
        let t0 = Instant::now();
        let (recorded, err) = run_substructure(&mut test, &ag);
        let took = t0.elapsed();
        let err = err.expect("must fail").to_string();
        println!("{fault:?}: {err}");
        assert!(err.contains(&addr.to_string()), "{fault:?}: {err}");
        assert!(err.contains(expect), "{fault:?}: expected '{expect}' in: {err}");
        assert_eq!(recorded.len(), good_steps, "{fault:?}");
        assert_same(&recorded, &local[..good_steps].to_vec(), "before the fault");
        assert_eq!(test.steps_done(), good_steps);
        if fault == Fault::Stall {
            // fails within the timeout (plus scheduling slack), not much later
            assert!(took < Duration::from_secs(2), "{took:?}");
        }
        drop(test);
        site_thread.join().unwrap();
    }
}

#[test]
fn per_step_site_with_another_ramp_is_detected() {
    // a server whose per-step ramp uses another G_cc: the command check catches it
    let ag = ground_motion(10);
    let (options, _log) = serve_options(true);
    let server = SiteServer::spawn(tcp_listener(), lab_factory, &options).unwrap();
    let model = frame();
    let ctrl = controller(&model, ag[0]);
    let mut hello = Hello::from_controller(&ctrl, Mode::PerStep);
    hello.gain_cc[1] *= 1.0 + 1e-12;
    let site = RemoteStepSite::connect(server.local_addr(), Transport::Tcp, hello, &client_options(1000)).unwrap();
    let err = RemoteStepTest::new(&model, ctrl, site).err().unwrap().to_string();
    assert!(err.contains("does not match the controller"), "{err}");
    drop(server);

    // driving a per-step site by hand with a wrong predictor: the reply still decodes, and
    // run_remote_step compares the commands bit for bit
    let server = SiteServer::spawn(tcp_listener(), lab_factory, &options).unwrap();
    let mut ctrl = controller(&model, ag[0]);
    let mut hello = Hello::from_controller(&ctrl, Mode::PerStep);
    hello.gain_cc[0] *= 2.0;
    let mut site = RemoteStepSite::connect(server.local_addr(), Transport::Tcp, hello, &client_options(1000)).unwrap();
    let mut steps_ok = 0;
    let mut err = None;
    for i in 1..5 {
        let load = -model.effective_mass_vector() * ag[i];
        match substep::site::run_remote_step(&mut ctrl, &mut site, &load, (ag[i - 1], ag[i]), i, &mut ()) {
            Ok(()) => steps_ok += 1,
            Err(e) => {
                err = Some(e.to_string());
                break;
            }
        }
    }
    let err = err.expect("G_cc mismatch must be detected");
    assert!(err.contains("does not run the same sub-step ramp"), "{err}");
    // the first step starts from rest with zero force: G_cc does not matter yet
    assert!(steps_ok <= 1, "{steps_ok}");
}

// ---------------------------------------------------------------------------------------------
// OpenFresco.

/// A client that talks like OpenSees' genericClient.
struct GenericClientEmulator {
    stream: TcpStream,
    data_size: usize,
}

impl GenericClientEmulator {
    fn connect(addr: SocketAddr, sizes: &Sizes) -> Self {
        let mut stream = TcpStream::connect(addr).unwrap();
        stream.set_nodelay(true).unwrap();
        stream.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        stream.write_all(&sizes.encode()).unwrap();
        Self {
            stream,
            data_size: sizes.data_size,
        }
    }
    fn send(&mut self, code: i32, values: &[f64]) {
        let mut v = vec![0.0; self.data_size];
        v[0] = code as f64;
        v[1..1 + values.len()].copy_from_slice(values);
        let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.stream.write_all(&bytes).unwrap();
    }
    fn ask(&mut self, code: i32) -> Vec<f64> {
        self.send(code, &[]);
        let mut b = vec![0u8; 8 * self.data_size];
        self.stream.read_exact(&mut b).unwrap();
        b.chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }
}

#[test]
fn openfresco_server_answers_the_generic_client_sequence() {
    let k = dmatrix![3.0e4, -1.0e4; -2.0e4, 4.0e4]; // not symmetric: checks the column-major order
    let c = dmatrix![30.0, -10.0; -10.0, 20.0];
    let m = dmatrix![0.0, 0.0; 0.0, 5.0];
    for damping_to_client in [false, true] {
        let spec = ElementSpec::LinearElement {
            stiffness: k.clone(),
            damping: Some(c.clone()),
            mass: Some(m.clone()),
            damping_to_client,
        };
        let (options, log) = serve_options(true);
        let server = OpenFrescoServer::spawn(tcp_listener(), move |_: &Sizes| spec.build(), &options).unwrap();
        let sizes = Sizes::generic_client(2, 256);
        assert_eq!(sizes.encode().len(), 44);
        assert_eq!(sizes.data_size, 256);
        let mut gc = GenericClientEmulator::connect(server.local_addr(), &sizes);
        // start: zero trial, mass
        gc.send(action::SET_TRIAL_RESPONSE, &[0.0; 7]);
        let mass = gc.ask(action::GET_MASS);
        assert_eq!(&mass[..4], m.as_slice());
        assert!(mass[4..].iter().all(|&x| x == 0.0));
        let dt = 0.02;
        let mut u_prev = [0.0, 0.0];
        for step in 1..=25 {
            let t = step as f64 * dt;
            let u = [1e-3 * (3.0 * t).sin(), -2e-3 * (5.0 * t).cos() + 2e-3];
            let v = [3e-3 * (3.0 * t).cos(), 1e-2 * (5.0 * t).sin()];
            let a = [-9e-3 * (3.0 * t).sin(), 5e-2 * (5.0 * t).cos()];
            // trial: disp, vel, accel, time
            gc.send(action::SET_TRIAL_RESPONSE, &[u[0], u[1], v[0], v[1], a[0], a[1], t]);
            let kt = gc.ask(action::GET_TANGENT_STIFF);
            assert_eq!(&kt[..4], &[3.0e4, -2.0e4, -1.0e4, 4.0e4]);
            let damp = gc.ask(action::GET_DAMP);
            let expect_damp: &[f64] = if damping_to_client { c.as_slice() } else { &[0.0; 4] };
            assert_eq!(&damp[..4], expect_damp);
            let p = gc.ask(action::GET_FORCE);
            let uu = DVector::from_row_slice(&u);
            let vv = DVector::from_row_slice(&v);
            let expect = if damping_to_client {
                &k * &uu
            } else {
                &k * &uu + &c * &vv
            };
            for i in 0..2 {
                assert!(
                    (p[i] - expect[i]).abs() <= 1e-12 * expect.amax(),
                    "step {step}: p = {:?}, expected {expect}",
                    &p[..2]
                );
            }
            assert!(p[2..].iter().all(|&x| x == 0.0));
            let _ = gc.ask(action::GET_DAMP);
            // getDisp / getVel / getAccel / getTime echo the trial
            assert_eq!(&gc.ask(action::GET_DISP)[..2], &u);
            assert_eq!(&gc.ask(action::GET_VEL)[..2], &v);
            assert_eq!(&gc.ask(action::GET_ACCEL)[..2], &a);
            assert_eq!(gc.ask(action::GET_TIME)[0], t);
            // getDaqResponse: only the force block (daq sizes [0, 0, 0, n, 0])
            assert_eq!(&gc.ask(action::GET_DAQ_RESPONSE)[..3], &[p[0], p[1], 0.0]);
            gc.send(action::COMMIT_STATE, &[]);
            u_prev = u;
        }
        let _ = u_prev;
        assert_eq!(&gc.ask(action::GET_INITIAL_STIFF)[..4], &[3.0e4, -2.0e4, -1.0e4, 4.0e4]);
        // ignored actions, then disconnect
        gc.send(action::OPEN, &[]);
        gc.send(action::SETUP, &[]);
        gc.send(action::EXECUTE, &[]);
        gc.send(action::DISCONNECT, &[]);
        let report = server.join().unwrap();
        assert_eq!(
            (report.sessions, report.substeps, report.steps, report.errors),
            (1, 26, 25, 0)
        );
        let log = log.lock().unwrap();
        assert!(
            log.iter()
                .any(|l| l.contains("connected (2 DOFs, data_size 256, hosting linear_element)")),
            "{log:?}"
        );
        assert!(log.iter().any(|l| l.contains("(action 99)")), "{log:?}");
    }
}

#[test]
fn openfresco_server_hosts_a_specimen_spring() {
    // linear_sdof with mass = None on a 1-DOF element: p = k u + c u̇ (u̇ over the time step)
    let (k, c) = (2.0e4, 150.0);
    let spec = ElementSpec::Specimen {
        spec: SpecimenSpec::LinearSdof {
            dof: 0,
            mass: None,
            stiffness: k,
            damping: c,
        },
        default_dt: 0.01,
    };
    let (options, _log) = serve_options(true);
    let server = OpenFrescoServer::spawn(tcp_listener(), move |_: &Sizes| spec.build(), &options).unwrap();
    let sizes = Sizes::generic_client(1, 256);
    let mut gc = GenericClientEmulator::connect(server.local_addr(), &sizes);
    gc.send(action::SET_TRIAL_RESPONSE, &[0.0, 0.0, 0.0, 0.0]);
    assert_eq!(gc.ask(action::GET_FORCE)[0], 0.0);
    assert_eq!(gc.ask(action::GET_TANGENT_STIFF)[0], k);
    assert_eq!(gc.ask(action::GET_DAMP)[0], 0.0);
    let dt = 0.01;
    let mut u_prev = 0.0;
    for step in 1..=10 {
        let t = step as f64 * dt;
        let u = 1e-3 * (7.0 * t).sin();
        // a Newton-like repeated trial: first a wrong guess, then the final value; the
        // repeated trial must start from the committed state again
        gc.send(action::SET_TRIAL_RESPONSE, &[0.5 * u, 0.0, 0.0, t]);
        let _ = gc.ask(action::GET_FORCE);
        gc.send(action::SET_TRIAL_RESPONSE, &[u, 0.0, 0.0, t]);
        let p = gc.ask(action::GET_FORCE)[0];
        let expect = k * u + c * (u - u_prev) / dt;
        assert!(
            (p - expect).abs() <= 1e-9 * expect.abs().max(1.0),
            "step {step}: {p} vs {expect}"
        );
        gc.send(action::COMMIT_STATE, &[]);
        u_prev = u;
    }
    gc.send(action::DISCONNECT, &[]);
    server.join().unwrap();
}

#[test]
fn openfresco_server_rejects_bad_sizes_and_actions() {
    let (options, log) = serve_options(false);
    let spec = ElementSpec::LinearElement {
        stiffness: dmatrix![1.0, 0.0; 0.0, 1.0],
        damping: None,
        mass: None,
        damping_to_client: false,
    };
    let server = OpenFrescoServer::spawn(tcp_listener(), move |_: &Sizes| spec.build(), &options).unwrap();
    let addr = server.local_addr();
    let raw_sizes = |v: [i32; 11]| -> Vec<u8> { v.iter().flat_map(|x| x.to_le_bytes()).collect() };
    let expect_closed = |bytes: &[u8], extra: Option<Vec<u8>>| {
        let mut s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
        s.write_all(bytes).unwrap();
        if let Some(e) = extra {
            let _ = s.write_all(&e);
        }
        let mut b = [0u8; 8];
        // the server closes the connection: read returns 0 (or a reset)
        assert!(matches!(s.read(&mut b), Ok(0) | Err(_)));
    };
    // data_size too small for a 2x2 matrix and the request
    expect_closed(&raw_sizes([2, 2, 2, 0, 1, 0, 0, 0, 2, 0, 3]), None);
    // negative size
    expect_closed(&raw_sizes([2, -1, 2, 0, 1, 0, 0, 0, 2, 0, 256]), None);
    // 3 DOFs for a 2-DOF element
    expect_closed(&raw_sizes([3, 3, 3, 0, 1, 0, 0, 0, 3, 0, 256]), None);
    // unknown action code, NaN action
    let ok = raw_sizes([2, 2, 2, 0, 1, 0, 0, 0, 2, 0, 256]);
    let msg = |code: f64| -> Vec<u8> {
        let mut v = vec![0.0; 256];
        v[0] = code;
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    };
    expect_closed(&ok, Some(msg(42.0)));
    expect_closed(&ok, Some(msg(f64::NAN)));
    // a trial with a NaN displacement
    let mut bad = msg(3.0);
    bad[8..16].copy_from_slice(&f64::NAN.to_le_bytes());
    expect_closed(&ok, Some(bad));
    drop(server);
    let log = log.lock().unwrap();
    for needle in [
        "sizes.data_size",
        "sizes.ctrl_vel",
        "3 element DOFs",
        "unknown action code 42",
        "not an action code",
        "not finite",
    ] {
        assert!(log.iter().any(|l| l.contains(needle)), "'{needle}' not in {log:#?}");
    }
}

/// `SubstructureTest` driving an OpenFresco site (our own server) through [`OpenFrescoSite`].
fn openfresco_history(spec: SpecimenSpec, ag: &[f64]) -> (History, History) {
    let p = TmdSystem::typical();
    let (kp, cp) = p.primary();
    let model = substep::model::sdof(p.mass, cp, kp).unwrap();
    let settings = SubstepSettings {
        dt: DT,
        beta: 0.25,
        gamma: 0.5,
        substeps: K_SUB,
        coupling_dofs: vec![0],
        error_force: ErrorForceSpec::None,
    };
    let load0 = -model.effective_mass_vector() * ag[0];
    let dtau = DT / K_SUB as f64;
    let local_lab = VirtualLab::from_specs(
        &[0],
        std::slice::from_ref(&spec),
        &[ActuatorSpec::ideal()],
        &[SensorSpec::ideal()],
        &[SensorSpec::ideal()],
        dtau,
        1,
    )
    .unwrap();
    let ctrl = SubstepController::new(&model, &settings, &load0).unwrap();
    let mut local = SubstructureTest::new(&model, ctrl, Box::new(local_lab)).unwrap();
    let (local_h, err) = run_substructure(&mut local, ag);
    assert!(err.is_none());

    let (options, _log) = serve_options(true);
    let element = ElementSpec::Specimen { spec, default_dt: dtau };
    let server = OpenFrescoServer::spawn(tcp_listener(), move |_: &Sizes| element.build(), &options).unwrap();
    let site = OpenFrescoSite::connect(server.local_addr(), 1, &client_options(2000)).unwrap();
    let ctrl = SubstepController::new(&model, &settings, &load0).unwrap();
    let mut remote = SubstructureTest::new(&model, ctrl, Box::new(site)).unwrap();
    let (remote_h, err) = run_substructure(&mut remote, ag);
    assert!(err.is_none(), "{err:?}");
    drop(remote);
    let report = server.join().unwrap();
    assert_eq!(report.substeps, ((ag.len() - 1) * K_SUB) as u64);
    assert_eq!(report.steps, ((ag.len() - 1) * K_SUB) as u64);
    (remote_h, local_h)
}

#[test]
fn openfresco_client_drives_a_substructure_test() {
    let ag = ground_motion(200);
    // an undamped spring does not depend on the sub-step length: bit for bit
    let (remote, local) = openfresco_history(
        SpecimenSpec::LinearSdof {
            dof: 0,
            mass: None,
            stiffness: 5000.0,
            damping: 0.0,
        },
        &ag,
    );
    assert_same(&remote, &local, "OpenFresco client, spring");
    // with a dashpot the server's time increment t_j − t_{j−1} differs from Δτ by rounding
    let (remote, local) = openfresco_history(
        SpecimenSpec::LinearSdof {
            dof: 0,
            mass: None,
            stiffness: 5000.0,
            damping: 300.0,
        },
        &ag,
    );
    let u = |h: &History| -> Vec<f64> { h.iter().map(|s| f64::from_bits(s[0])).collect() };
    let (ur, ul) = (u(&remote), u(&local));
    let scale = ul.iter().map(|x| x.abs()).fold(0.0, f64::max);
    let diff = ur.iter().zip(&ul).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    println!(
        "OpenFresco client, spring + dashpot: max |Δu| / max |u| = {:.2e}",
        diff / scale
    );
    assert!(diff <= 1e-9 * scale, "{diff} vs {scale}");
}

#[test]
fn openfresco_client_reports_a_vanished_site() {
    let (options, _log) = serve_options(false);
    let element = ElementSpec::LinearElement {
        stiffness: dmatrix![1000.0],
        damping: None,
        mass: None,
        damping_to_client: false,
    };
    let server = OpenFrescoServer::spawn(tcp_listener(), move |_: &Sizes| element.build(), &options).unwrap();
    let addr = server.local_addr();
    let mut site = OpenFrescoSite::connect(addr, 1, &client_options(300)).unwrap();
    let (mut f, mut d) = ([0.0], [0.0]);
    site.substep(&[1e-3], (0.0, 0.0), 0.001, &mut f, &mut d).unwrap();
    assert_eq!(f[0], -1.0); // f_c = −p = −k u
    assert_eq!(d[0], 1e-3);
    server.stop().unwrap();
    let t0 = Instant::now();
    let err = site
        .substep(&[2e-3], (0.0, 0.0), 0.001, &mut f, &mut d)
        .err()
        .unwrap()
        .to_string();
    println!("{err}");
    assert!(
        err.contains(&addr.to_string()) && err.contains("closed the connection"),
        "{err}"
    );
    assert!(t0.elapsed() < Duration::from_secs(1));
}

// ---------------------------------------------------------------------------------------------
// OpenSees interoperability (needs openseespy).

/// `$SUBSTEP_PYTHON` (scripts/test points it at the virtual environment with openseespy), else
/// `python3`.
fn python() -> String {
    std::env::var("SUBSTEP_PYTHON").unwrap_or_else(|_| "python3".into())
}

fn openseespy_available() -> bool {
    std::process::Command::new(python())
        .args(["-c", "import openseespy.opensees"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

#[test]
fn opensees_generic_client_matches_native_element() {
    if !openseespy_available() {
        println!(
            "SKIPPED: openseespy is not installed (pip install openseespy); the OpenSees interoperability test did not run"
        );
        return;
    }
    let (k, c, m) = (4.0e4, 120.0, 100.0);
    let (options, log) = serve_options(true);
    // 2-node element, DOF 1 at each node: a spring k between them (linear_element)
    let two_node = ElementSpec::LinearElement {
        stiffness: dmatrix![k, -k; -k, k],
        damping: None,
        mass: None,
        damping_to_client: false,
    };
    let s1 = OpenFrescoServer::spawn(tcp_listener(), move |_: &Sizes| two_node.build(), &options).unwrap();
    // 1-node element: the linear_sdof specimen (spring to ground)
    let sdof = ElementSpec::Specimen {
        spec: SpecimenSpec::LinearSdof {
            dof: 0,
            mass: None,
            stiffness: k,
            damping: 0.0,
        },
        default_dt: 0.01,
    };
    let s2 = OpenFrescoServer::spawn(tcp_listener(), move |_: &Sizes| sdof.build(), &options).unwrap();
    // 2-node spring + dashpot, damping reported to the client (exact with algorithm Linear)
    let damped = ElementSpec::LinearElement {
        stiffness: dmatrix![k, -k; -k, k],
        damping: Some(dmatrix![c, -c; -c, c]),
        mass: None,
        damping_to_client: true,
    };
    let s3 = OpenFrescoServer::spawn(tcp_listener(), move |_: &Sizes| damped.build(), &options).unwrap();

    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/opensees/genericclient_spring.py");
    let tmp = std::env::temp_dir();
    let tag = format!("substep-site-opensees-{}", std::process::id());
    let out_path = tmp.join(format!("{tag}.out"));
    let err_path = tmp.join(format!("{tag}.err"));
    let mut child = std::process::Command::new(python())
        .arg(script)
        .args(["--k", &k.to_string(), "--c", &c.to_string(), "--m", &m.to_string()])
        .args(["--dt", "0.01", "--steps", "500"])
        .args(["--port-element", &s1.local_addr().port().to_string()])
        .args(["--port-sdof", &s2.local_addr().port().to_string()])
        .args(["--port-damped", &s3.local_addr().port().to_string()])
        .stdout(std::fs::File::create(&out_path).unwrap())
        .stderr(std::fs::File::create(&err_path).unwrap())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break Some(s);
        }
        if t0.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let out = std::fs::read_to_string(&out_path).unwrap_or_default();
    let err = std::fs::read_to_string(&err_path).unwrap_or_default();
    let _ = std::fs::remove_file(&out_path);
    let _ = std::fs::remove_file(&err_path);
    let server_log = log.lock().unwrap().join("\n");
    match status {
        None => panic!("the openseespy script did not finish within 60 s\n{err}\nserver log:\n{server_log}"),
        Some(s) if !s.success() => panic!("the openseespy script failed: {s}\n{err}\nserver log:\n{server_log}"),
        Some(_) => {}
    }
    let series = |name: &str| -> Vec<f64> {
        let line = out
            .lines()
            .find(|l| l.split_whitespace().next() == Some(name))
            .unwrap_or_else(|| panic!("no '{name}' in the script's output:\n{out}\n{err}"));
        line.split_whitespace().skip(1).map(|x| x.parse().unwrap()).collect()
    };
    let compare = |a: &[f64], b: &[f64], what: &str| -> f64 {
        assert_eq!(a.len(), b.len(), "{what}");
        assert_eq!(a.len(), 500, "{what}");
        let scale = b.iter().map(|x| x.abs()).fold(0.0, f64::max);
        assert!(scale > 1e-4, "{what}: the response is trivial ({scale})");
        let diff = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        let rel = diff / scale;
        println!("{what}: max |Δu| / max |u| = {rel:.3e} (max |u| = {scale:.4e} m)");
        assert!(rel <= 1e-9, "{what}: relative difference {rel:e}");
        rel
    };
    compare(
        &series("generic_element"),
        &series("native"),
        "genericClient linear_element vs zeroLength",
    );
    compare(
        &series("generic_sdof"),
        &series("native"),
        "genericClient linear_sdof vs zeroLength",
    );
    compare(
        &series("generic_damped"),
        &series("native_damped"),
        "genericClient damped linear_element vs zeroLength (Elastic + Viscous)",
    );
    let reports = [s1.join().unwrap(), s2.join().unwrap(), s3.join().unwrap()];
    for r in &reports {
        assert_eq!(r.sessions, 1, "{r:?}");
        assert_eq!(r.errors, 0, "{r:?}");
        assert!(r.steps >= 500, "{r:?}");
    }
    println!("{}", log.lock().unwrap().join("\n"));
}

#[test]
fn substructure_element_restores_state_between_trials() {
    // a TMD specimen: repeated trials of the same step give the same force
    let p = TmdSystem::typical();
    let (ms, ks, cs) = p.absorber();
    let mut el = SubstructureElement::from_specimen(
        &SpecimenSpec::LinearSdof {
            dof: 0,
            mass: Some(ms),
            stiffness: ks,
            damping: cs,
        },
        0.01,
    )
    .unwrap();
    use substep::site::openfresco::ElementSite;
    let mut forces = Vec::new();
    for step in 1..=20 {
        let t = step as f64 * 0.01;
        let u = [2e-3 * (4.0 * t).sin()];
        el.set_trial(&[0.3 * u[0]], None, None, Some(t)).unwrap();
        el.set_trial(&u, None, None, Some(t)).unwrap();
        let f1 = el.force()[0];
        el.set_trial(&u, None, None, Some(t)).unwrap();
        assert_eq!(el.force()[0].to_bits(), f1.to_bits(), "step {step}");
        el.commit().unwrap();
        forces.push(f1);
    }
    // the TMD's internal state carries over: forces are not just k u
    let mut k_times = DMatrix::zeros(1, 1);
    el.tangent_stiffness(k_times.as_mut_slice());
    assert_eq!(k_times[(0, 0)], ks);
    assert!(forces.iter().any(|f| f.abs() > 0.0));
}
