//! Round-trip time of a remote site on loopback (TCP): per-sub-step and per-step requests
//! against an in-process `SiteServer` hosting two springs, with and without a secret.
//!
//! `cargo run --release -p substep --example site_roundtrip [N]` (N requests per case,
//! default 20000). Prints mean, p50 and p99 in µs. Used for docs/performance.md. With
//! `SITE_ROUNDTRIP_SECRET` set, the session is authenticated: every message carries a MAC.

use std::net::TcpListener;
use std::time::{Duration, Instant};
use substep::site::{
    ClientOptions, Hello, Mode, RemoteSite, RemoteStepSite, ServeOptions, SiteServer, Transport, VirtualLabSpec,
};
use substep::specimen::SpecimenSpec;
use substep::substructure::ExperimentalSubstructure;

fn lab() -> VirtualLabSpec {
    VirtualLabSpec::ideal(
        (0..2)
            .map(|dof| SpecimenSpec::LinearSdof {
                dof,
                mass: None,
                stiffness: 1e4,
                damping: 10.0,
            })
            .collect(),
    )
}

fn hello(mode: Mode) -> Hello {
    Hello {
        n_coupling: 2,
        substeps: 4,
        mode,
        dt: 0.01,
        dtau: 0.0025,
        gain_cc: vec![1e-6, 0.0, 0.0, 1e-6],
        coupling_dofs: vec![0, 1],
    }
}

fn stats(name: &str, mut t: Vec<f64>) {
    t.sort_by(f64::total_cmp);
    let mean = t.iter().sum::<f64>() / t.len() as f64;
    let p = |q: f64| t[((t.len() - 1) as f64 * q) as usize];
    println!(
        "{name:<34} mean {mean:7.1} µs   p50 {:7.1} µs   p99 {:7.1} µs",
        p(0.5),
        p(0.99)
    );
}

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(20_000);
    let secret = std::env::var("SITE_ROUNDTRIP_SECRET").ok();
    let secret = secret.map(|s| substep::site::Secret::new(s.as_bytes(), "SITE_ROUNDTRIP_SECRET").unwrap());
    let options = ServeOptions {
        secret: secret.clone(),
        ..ServeOptions::default()
    };
    let server = SiteServer::spawn(TcpListener::bind("127.0.0.1:0").unwrap(), lab().factory(), &options).unwrap();
    let addr = server.local_addr();
    let client = ClientOptions {
        secret,
        ..ClientOptions::default()
    };
    let label = if options.secret.is_some() {
        "authenticated"
    } else {
        "no secret"
    };

    let mut site = RemoteSite::connect(addr, Transport::Tcp, hello(Mode::PerSubstep), &client).unwrap();
    let (mut f, mut d) = ([0.0; 2], [0.0; 2]);
    let mut times = Vec::with_capacity(n);
    for i in 0..n + 1000 {
        let x = 1e-3 * (i as f64 * 0.01).sin();
        let t0 = Instant::now();
        site.substep(&[x, -x], (0.0, 0.0), 0.0025, &mut f, &mut d).unwrap();
        if i >= 1000 {
            times.push(t0.elapsed().as_secs_f64() * 1e6);
        }
    }
    stats(&format!("per sub-step, {label}"), times);
    drop(site);
    std::thread::sleep(Duration::from_millis(50));

    let mut step = RemoteStepSite::connect(addr, Transport::Tcp, hello(Mode::PerStep), &client).unwrap();
    let mut times = Vec::with_capacity(n);
    for i in 0..n + 1000 {
        let x = 1e-3 * (i as f64 * 0.01).sin();
        let t0 = Instant::now();
        step.step(&[0.0, 0.0], &[x, -x], &[0.0, 0.0], (0.0, 0.0)).unwrap();
        if i >= 1000 {
            times.push(t0.elapsed().as_secs_f64() * 1e6);
        }
    }
    stats(&format!("per step (k_sub = 4), {label}"), times);
    drop(step);
    server.stop().unwrap();
}
