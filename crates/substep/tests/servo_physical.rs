//! The servo-hydraulic actuator from physical parameters (`kind = "hydraulic"`,
//! examples/servo_physical.toml): its closed loop with the specimen, as the lab integrates it,
//! against the analytic transfer function written from the physics in this file (valve,
//! continuity with the oil column and leakage, piston and specimen), at frequencies from 1 Hz to
//! past the loop's bandwidth; and parameter sets whose loop is unstable are refused before the
//! run, naming the pole.

use nalgebra::Complex;
use std::path::Path;
use substep::io::TestDefinition;
use substep::specimen::SpecimenSpec;

const EXAMPLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/servo_physical.toml");

/// The physical parameters as the example writes them (read back from its text, so that this
/// test computes from what a user reads, not from the library's conversion).
struct Physical {
    area: f64,
    k_oil: f64,
    leakage: f64,
    flow: f64,
    f_valve: f64,
    zeta_valve: f64,
    kp: f64,
    mass: f64,
    damping: f64,
    stiffness: f64,
}

fn physical(text: &str) -> Physical {
    let v: toml::Value = toml::from_str(text).unwrap();
    let a = &v["substructure"]["actuator"];
    assert_eq!(a["kind"].as_str(), Some("hydraulic"));
    let f = |t: &toml::Value, k: &str| t[k].as_float().unwrap_or_else(|| panic!("{k}"));
    let s = &v["substructure"]["specimen"][0];
    let area = f(a, "piston_area");
    Physical {
        area,
        k_oil: 4.0 * f(a, "bulk_modulus") * area * area / f(a, "oil_volume"),
        leakage: f(a, "leakage"),
        flow: f(a, "valve_flow"),
        f_valve: f(a, "valve_frequency"),
        zeta_valve: f(a, "valve_damping"),
        kp: f(a, "kp"),
        mass: f(s, "mass"),
        damping: f(s, "damping"),
        stiffness: f(s, "stiffness"),
    }
}

/// `x/u` at `s = iω` from the physical equations:
/// piston + specimen `F = (m s² + c s + k) X`; continuity `q = A s X + (A/k_oil) s F + (C_l/A) F`;
/// valve `q = Q_r V(s) i`, `V = ω_v² / (s² + 2ζ_v ω_v s + ω_v²)`; controller `i = k_p (U − X)`.
fn analytic(p: &Physical, omega: f64) -> Complex<f64> {
    let s = Complex::new(0.0, omega);
    let wv = 2.0 * std::f64::consts::PI * p.f_valve;
    let valve = wv * wv / (s * s + 2.0 * p.zeta_valve * wv * s + wv * wv);
    let specimen = p.mass * s * s + p.damping * s + p.stiffness;
    let chamber = p.area * s + (p.area / p.k_oil * s + p.leakage / p.area) * specimen;
    let drive = p.flow * valve * p.kp;
    drive / (chamber + drive)
}

#[test]
fn closed_loop_equals_the_analytic_transfer_function() {
    let text = std::fs::read_to_string(EXAMPLE).unwrap();
    let p = physical(&text);
    let def = TestDefinition::from_toml(&text, "servo_physical.toml", Path::new(EXAMPLE).parent().unwrap()).unwrap();
    let sub = def.substructure.as_ref().unwrap();
    let plant = match &sub.specimens[..] {
        [s @ SpecimenSpec::LumpedSdof { .. }] => s.lumped_mck().unwrap(),
        other => panic!("{other:?}"),
    };
    assert_eq!(plant, [p.mass, p.damping, p.stiffness]);
    let h = 1.0 / 16384.0;
    for f in [1.0, 5.0, 20.0, 60.0, 150.0] {
        let mut act = sub.actuator.build_with_plant(h, Some(plant)).unwrap();
        let omega = 2.0 * std::f64::consts::PI * f;
        // 1 s of settling (the slowest closed-loop pole decays in a few ms), then a whole
        // number of periods fitted by least squares to a sin + b cos.
        let settle = (1.0 / h) as usize;
        let periods = (f * 0.5).ceil();
        let n_fit = (periods / f / h).round() as usize;
        let (mut ss, mut sc, mut cc, mut ys, mut yc) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for k in 1..=settle + n_fit {
            let t = k as f64 * h;
            let x = act.advance(1e-3 * (omega * t).sin(), h);
            if k > settle {
                let (sn, cs) = (omega * t).sin_cos();
                ss += sn * sn;
                sc += sn * cs;
                cc += cs * cs;
                ys += x * sn;
                yc += x * cs;
            }
        }
        let det = ss * cc - sc * sc;
        let a = (ys * cc - yc * sc) / det;
        let b = (yc * ss - ys * sc) / det;
        // x = a sin + b cos = Im(G e^{iωt}) for a unit sine: G = a + i b (per 1 mm).
        let measured = Complex::new(a, b) / 1e-3;
        let expected = analytic(&p, omega);
        let error = (measured - expected).norm() / expected.norm();
        println!(
            "{f:>6} Hz: |G| {:.6} (analytic {:.6}), phase {:.3}° ({:.3}°), relative error {error:.2e}",
            measured.norm(),
            expected.norm(),
            measured.arg().to_degrees(),
            expected.arg().to_degrees()
        );
        // The lab's command is linear between the samples: a sine sampled at h and joined by
        // straight lines differs from the sine by about (ωh)²/12 in amplitude, the rest is RK4.
        let tolerance = (omega * h).powi(2) / 6.0 + 1e-5;
        assert!(
            error < tolerance,
            "{f} Hz: {measured} vs {expected} ({error:.2e} > {tolerance:.2e})"
        );
    }
    // The loop really lags and rolls off (not an identity): 2 ms of lag at low frequency,
    // about half the command at 150 Hz.
    let lag = -analytic(&p, 2.0 * std::f64::consts::PI).arg() / (2.0 * std::f64::consts::PI);
    assert!((1.5e-3..3e-3).contains(&lag), "{lag}");
    assert!(analytic(&p, 2.0 * std::f64::consts::PI * 150.0).norm() < 0.55);
}

#[test]
fn unstable_parameter_sets_are_refused_before_the_run() {
    let text = std::fs::read_to_string(EXAMPLE).unwrap();
    let dir = Path::new(EXAMPLE).parent().unwrap();
    let build = |text: &str| -> Result<(), String> {
        let def = TestDefinition::from_toml(text, "cfg.toml", dir).map_err(|e| e.to_string())?;
        let sub = def.substructure.as_ref().unwrap();
        let load0 = nalgebra::DVector::zeros(def.model.n_dofs());
        sub.build_test(&def.model, def.integrator.dt, &load0)
            .map(|_| ())
            .map_err(|e| e.to_string())
    };
    build(&text).unwrap();
    // A loop gain 4x the example's: the valve's lag makes the loop oscillate.
    let hot = text.replace("kp = 2500.0 ", "kp = 10000.0 ");
    assert_ne!(hot, text);
    let e = build(&hot).unwrap_err();
    assert!(
        e.contains("the servo loop with the specimen at its DOF (m = 29.13 kg")
            && e.contains("is unstable: closed-loop pole"),
        "{e}"
    );
    // And the analytic loop agrees that it is unstable: its characteristic polynomial has a
    // root in the right half-plane (a growing response at the pole the message names).
    let pole = e
        .split("closed-loop pole ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|re| re.parse::<f64>().ok())
        .unwrap();
    assert!(pole > 0.0, "{e}");
    // Bad physical input: one line naming the key.
    let e = build(&text.replace("piston_area = 0.00476 ", "piston_area = 0.0 ")).unwrap_err();
    assert!(
        e.starts_with("cfg.toml: substructure.actuator.piston_area: must be"),
        "{e}"
    );
    let e = build(&text.replace("bulk_modulus = 1.0e9 ", "oil_stiffness = 6e7\nbulk_modulus = 1.0e9 ")).unwrap_err();
    assert!(
        e.starts_with("cfg.toml: substructure.actuator.oil_stiffness: give either oil_stiffness"),
        "{e}"
    );
}

/// The benchmark's servo-valve with a heavy specimen (2 t instead of 29 kg) went to 10²² m and
/// "completed": now it is refused with the pole.
#[test]
fn the_benchmark_servo_with_a_heavy_specimen_is_refused() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/servo_hydraulic.toml");
    let text = std::fs::read_to_string(path)
        .unwrap()
        .replace("mass = 29.13 ", "mass = 2000.0 ");
    let def = TestDefinition::from_toml(&text, "cfg.toml", Path::new(path).parent().unwrap()).unwrap();
    let sub = def.substructure.as_ref().unwrap();
    let load0 = nalgebra::DVector::zeros(def.model.n_dofs());
    let e = sub
        .build_test(&def.model, def.integrator.dt, &load0)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("(m = 2000 kg") && e.contains("is unstable"), "{e}");
}
