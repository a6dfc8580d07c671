//! The real `substep site serve` binary under abuse (issue 11): random bytes, truncated frames,
//! absurd sizes, NaN/inf, hostile handshake parameters, 50 concurrent clients, silent clients
//! and mid-frame disconnects. Its peak memory (VmHWM) stays within a fixed bound, and afterwards
//! it serves a valid client correctly, within that client's timeout. Loopback only, bounded.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use substep::site::protocol::HEADER_LEN;
use substep::site::{ClientOptions, Hello, Message, Mode, RemoteSite, RemoteStepSite, Transport, VirtualLabSpec};
use substep::specimen::SpecimenSpec;
use substep::substructure::ExperimentalSubstructure;
use substep::transfer::{ActuatorSpec, Dynamics, SensorSpec};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-abuse-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The site: two springs behind first-order actuators with a 1.5 ms delay and ten inner steps
/// (the delay history is what a tiny Δτ used to blow up).
const SITE: &str = r#"
[site]
protocol = "substep"
listen = "127.0.0.1:0"
idle_timeout = 1.0
handshake_timeout = 0.5

[[specimen]]
kind = "linear_sdof"
dof = 1
stiffness = 8000.0
damping = 100.0

[[specimen]]
kind = "linear_sdof"
dof = 2
mass = 60.0
stiffness = 3000.0
damping = 40.0

[actuator]
kind = "first_order"
time_constant = 0.002
delay = 0.0015
"#;

/// The same lab as a library value: the reference for the forces the site must return.
fn lab() -> VirtualLabSpec {
    VirtualLabSpec {
        specimens: vec![
            SpecimenSpec::LinearSdof {
                dof: 0,
                mass: None,
                stiffness: 8000.0,
                damping: 100.0,
            },
            SpecimenSpec::LinearSdof {
                dof: 1,
                mass: Some(60.0),
                stiffness: 3000.0,
                damping: 40.0,
            },
        ],
        actuator: ActuatorSpec {
            dynamics: Dynamics::FirstOrder { time_constant: 0.002 },
            delay: 0.0015,
        },
        force_sensor: SensorSpec::ideal(),
        displacement_sensor: SensorSpec::ideal(),
        inner_steps: 10,
    }
}

struct Site {
    child: Child,
    addr: SocketAddr,
    log: Arc<Mutex<Vec<String>>>,
}

impl Drop for Site {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Start the site; its stdout (one line per connection) is drained by a thread so that the
/// log can never block it.
fn serve(dir: &Path, toml: &str, env: &[(&str, &str)]) -> Site {
    std::fs::write(dir.join("site.toml"), toml).unwrap();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_substep"));
    cmd.args(["site", "serve", "site.toml"])
        .current_dir(dir)
        .env_remove("SUBSTEP_SITE_SECRET")
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let mut child = cmd.spawn().unwrap();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    out.read_line(&mut line).unwrap();
    assert!(line.contains("listening on tcp://127.0.0.1:"), "{line}");
    let addr = line.trim().rsplit("tcp://").next().unwrap().parse().unwrap();
    let log: Arc<Mutex<Vec<String>>> = Arc::default();
    let sink = log.clone();
    std::thread::spawn(move || {
        for l in out.lines() {
            let Ok(l) = l else { break };
            sink.lock().unwrap().push(l);
        }
    });
    Site { child, addr, log }
}

/// Peak and current resident memory of a process [kB] (`VmHWM`, `VmRSS`).
fn memory_kb(pid: u32) -> (u64, u64) {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let field = |name: &str| -> u64 {
        let line = status.lines().find(|l| l.starts_with(name)).unwrap();
        line.split_whitespace().nth(1).unwrap().parse().unwrap()
    };
    (field("VmHWM:"), field("VmRSS:"))
}

fn hello(k: usize, dtau: f64, mode: Mode) -> Hello {
    Hello {
        n_coupling: 2,
        substeps: k,
        mode,
        dt: 0.01,
        dtau,
        gain_cc: vec![1e-5, 0.0, 0.0, 2e-5],
        coupling_dofs: vec![0, 1],
    }
}

fn frame(msg: &Message, seq: u32) -> Vec<u8> {
    let mut f = Vec::new();
    msg.encode(seq, &mut f);
    f
}

/// Connect, send `bytes`, optionally read what comes back, and hang up (all bounded).
fn poke(addr: SocketAddr, bytes: &[u8], read: bool) -> Vec<u8> {
    let Ok(mut s) = TcpStream::connect_timeout(&addr, Duration::from_secs(1)) else {
        return Vec::new();
    };
    let _ = s.set_read_timeout(Some(Duration::from_millis(700)));
    let _ = s.set_write_timeout(Some(Duration::from_millis(700)));
    let _ = s.write_all(bytes);
    let mut got = Vec::new();
    if read {
        let mut buf = [0u8; 8192];
        while got.len() < 1 << 16 {
            match s.read(&mut buf) {
                Ok(0) | Err(_) => break,
                Ok(n) => got.extend_from_slice(&buf[..n]),
            }
        }
    }
    got
}

/// A client's handshake and, if accepted, one raw request.
fn session_then(addr: SocketAddr, h: &Hello, request: &[u8]) -> Vec<u8> {
    let mut bytes = frame(&Message::Hello(h.clone()), 0);
    bytes.extend_from_slice(request);
    poke(addr, &bytes, true)
}

fn lcg(state: &mut u64) -> u64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    *state >> 33
}

#[test]
fn a_site_under_abuse_stays_small_and_then_serves_a_valid_client() {
    let dir = temp_dir("abuse");
    let site = serve(&dir, SITE, &[]);
    let addr = site.addr;
    let t0 = Instant::now();
    let mut rng = 0x5eed_u64;

    // random bytes, and random bytes behind a valid magic
    for i in 0..40 {
        let len = (lcg(&mut rng) % 400) as usize;
        let mut b: Vec<u8> = (0..len).map(|_| lcg(&mut rng) as u8).collect();
        if i % 2 == 0 && b.len() >= 4 {
            b[..4].copy_from_slice(b"SSTP");
        }
        poke(addr, &b, i % 4 == 0);
    }
    // truncated frames and mid-frame disconnects
    let good = frame(&Message::Hello(hello(4, 0.0025, Mode::PerStep)), 0);
    for cut in [1, 8, HEADER_LEN, HEADER_LEN + 5, good.len() - 1] {
        poke(addr, &good[..cut], false);
    }
    // absurd sizes: the largest payload the header allows, u32::MAX, a 1024-DOF Hello
    for len in [1u32 << 24, u32::MAX, 1 << 23] {
        let mut f = good[..HEADER_LEN].to_vec();
        f[12..16].copy_from_slice(&len.to_le_bytes());
        f.extend(std::iter::repeat_n(0u8, 4096));
        let reply = poke(addr, &f, true);
        assert!(reply.is_empty() || reply.starts_with(b"SSTP"), "only protocol replies");
    }
    let huge = Hello {
        n_coupling: 1024,
        substeps: 1,
        mode: Mode::PerSubstep,
        dt: 0.01,
        dtau: 0.01,
        gain_cc: vec![0.0; 1024 * 1024],
        coupling_dofs: (0..1024).collect(),
    };
    poke(addr, &frame(&Message::Hello(huge), 0), true);
    // NaN / inf: in the handshake, and in a request after a valid handshake
    let nan_hello = frame(&Message::Hello(hello(4, f64::NAN, Mode::PerSubstep)), 0);
    poke(addr, &nan_hello, true);
    let nan_step = frame(
        &Message::Substep {
            command: vec![f64::NAN, f64::INFINITY],
            ag: (0.0, f64::NEG_INFINITY),
            dtau: 0.0025,
        },
        1,
    );
    let reply = session_then(addr, &hello(4, 0.0025, Mode::PerSubstep), &nan_step);
    let text = String::from_utf8_lossy(&reply);
    assert!(text.contains("not finite"), "the site refuses NaN: {text}");
    // hostile handshake parameters: the reproduced aborts and CPU hogs
    for h in [
        hello(4, 1e-12, Mode::PerStep),
        hello(4, 1e-10, Mode::PerStep),
        hello(32_000, 0.01 / 32_000.0, Mode::PerStep),
        // the largest k the protocol itself allows (n_c = 1)
        Hello {
            n_coupling: 1,
            gain_cc: vec![1e-5],
            coupling_dofs: vec![0],
            ..hello(699_050, 0.01 / 699_050.0, Mode::PerStep)
        },
    ] {
        let reply = poke(addr, &frame(&Message::Hello(h), 0), true);
        let text = String::from_utf8_lossy(&reply);
        assert!(
            text.contains("site.min_dtau") || text.contains("site.max_substeps"),
            "{text}"
        );
    }
    // 50 concurrent clients (one gets the session, the others are told at once that the site
    // is busy) and 10 silent ones, all at the same time
    let mut threads = Vec::new();
    for i in 0..60 {
        let bytes = if i < 50 { good.clone() } else { Vec::new() };
        threads.push(std::thread::spawn(move || {
            let r = poke(addr, &bytes, true);
            String::from_utf8_lossy(&r).into_owned()
        }));
    }
    let replies: Vec<String> = threads.into_iter().map(|t| t.join().unwrap()).collect();
    let busy = replies.iter().filter(|r| r.contains("busy")).count();
    assert!(busy >= 20, "most concurrent clients are told the site is busy: {busy}");
    assert!(t0.elapsed() < Duration::from_secs(60), "the abuse itself is bounded");

    let (hwm, rss) = memory_kb(site.child.id());
    println!("site under abuse: VmHWM {hwm} kB, VmRSS {rss} kB");
    assert!(hwm < 100_000, "peak memory {hwm} kB");

    // a valid per-step client is served within its timeout (retrying while an abuser's
    // session or busy answer is still in flight), and its forces are exactly those of the
    // same lab run locally
    let options = ClientOptions {
        timeout: Duration::from_secs(2),
        ..ClientOptions::default()
    };
    let h = hello(4, 0.0025, Mode::PerStep);
    let started = Instant::now();
    let mut remote = loop {
        match RemoteStepSite::connect(addr, Transport::Tcp, h.clone(), &options) {
            Ok(s) => break s,
            Err(e) if e.to_string().contains("busy") && started.elapsed() < Duration::from_secs(10) => {
                std::thread::sleep(Duration::from_millis(50));
            }
            Err(e) => panic!("{e}"),
        }
    };
    let mut local = lab().build(&h).unwrap();
    let mut ramp = substep::site::CommandRamp::new(2, 4, &h.gain_cc);
    let (mut f, mut d) = ([0.0; 2], [0.0; 2]);
    let (mut prev, mut force) = ([0.0; 2], [0.0; 2]);
    for step in 1..=20 {
        let t = step as f64 * 0.01;
        let next = [1e-3 * (7.0 * t).sin(), -2e-3 * (5.0 * t).sin()];
        let reply = remote.step(&prev, &next, &force, (0.0, 0.0)).unwrap().clone();
        ramp.begin(&prev, &next, &force);
        for j in 0..4 {
            let cmd = ramp.next_command().to_vec();
            local.substep(&cmd, (0.0, 0.0), 0.0025, &mut f, &mut d).unwrap();
            ramp.feedback(&f);
            for i in 0..2 {
                assert_eq!(reply.commands[2 * j + i].to_bits(), cmd[i].to_bits());
                assert_eq!(
                    reply.forces[2 * j + i].to_bits(),
                    f[i].to_bits(),
                    "step {step} sub-step {} DOF {}",
                    j + 1,
                    i + 1
                );
            }
        }
        assert!(f.iter().any(|x| x.abs() > 0.0));
        prev = next;
        force = f;
    }
    drop(remote);
    let log = site.log.lock().unwrap();
    assert!(log.iter().any(|l| l.contains("rejected")), "the log names the refusals");
    assert!(log.iter().all(|l| !l.contains('\u{0}')));
}

#[test]
fn an_authenticated_site_serves_only_the_right_secret() {
    let dir = temp_dir("auth");
    std::fs::write(dir.join("site.key"), "6c61622d7365637265742d31323334353637383930\n").unwrap();
    let toml = SITE.replace(
        "handshake_timeout = 0.5",
        "handshake_timeout = 0.5\nsecret_file = \"site.key\"",
    );
    let site = serve(&dir, &toml, &[]);
    let h = hello(4, 0.0025, Mode::PerSubstep);
    let options = |secret: Option<&str>| ClientOptions {
        timeout: Duration::from_secs(2),
        secret: secret.map(|s| substep::site::Secret::new(s.as_bytes(), "test").unwrap()),
        ..ClientOptions::default()
    };
    let err = RemoteSite::connect(site.addr, Transport::Tcp, h.clone(), &options(None))
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("requires authentication"), "{err}");
    let err = RemoteSite::connect(
        site.addr,
        Transport::Tcp,
        h.clone(),
        &options(Some("6c61622d7365637265742d31323334353637383931")),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("authentication failed"), "{err}");
    let mut ok = RemoteSite::connect(
        site.addr,
        Transport::Tcp,
        h,
        &options(Some("6c61622d7365637265742d31323334353637383930")),
    )
    .unwrap();
    let (mut f, mut d) = (vec![0.0; 2], vec![0.0; 2]);
    ok.substep(&[1e-3, 1e-3], (0.0, 0.0), 0.0025, &mut f, &mut d).unwrap();
    drop(ok);
    std::thread::sleep(Duration::from_millis(100));
    let log = site.log.lock().unwrap();
    assert!(log.iter().any(|l| l.contains("authentication failed")), "{log:?}");
    assert!(log.iter().any(|l| l.contains("authenticated")), "{log:?}");
    // the substep session of the wrong secret built nothing: only one session was opened
    assert_eq!(log.iter().filter(|l| l.contains(" connected ")).count(), 1, "{log:?}");
}

#[test]
fn a_site_reachable_from_other_machines_without_a_secret_warns() {
    let dir = temp_dir("warn");
    for (toml, expect) in [
        (SITE.replace("127.0.0.1:0", "0.0.0.0:0"), "the site has no secret"),
        (
            "[site]\nprotocol = \"openfresco\"\nlisten = \"0.0.0.0:0\"\n[[specimen]]\nkind = \"linear_sdof\"\ndof = 1\nstiffness = 1.0\n".to_string(),
            "site] allow",
        ),
    ] {
        std::fs::write(dir.join("site.toml"), &toml).unwrap();
        let mut child = Command::new(env!("CARGO_BIN_EXE_substep"))
            .args(["site", "serve", "site.toml", "--once"])
            .current_dir(&dir)
            .env_remove("SUBSTEP_SITE_SECRET")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stderr.take().unwrap()).read_line(&mut line).unwrap();
        let _ = child.kill();
        let _ = child.wait();
        assert!(line.starts_with("warning: ") && line.contains(expect), "{line}");
    }
    // on loopback (the default) there is nothing to warn about
    std::fs::write(dir.join("site.toml"), SITE.replace("listen = \"127.0.0.1:0\"\n", "")).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_substep"))
        .args(["site", "serve", "site.toml", "--once", "--listen", "127.0.0.1:0"])
        .current_dir(&dir)
        .env_remove("SUBSTEP_SITE_SECRET")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let _ = child.kill();
    let out = child.wait_with_output().unwrap();
    assert!(line.contains("listening on tcp://127.0.0.1:"), "{line}");
    assert!(out.stderr.is_empty(), "{}", String::from_utf8_lossy(&out.stderr));
}
