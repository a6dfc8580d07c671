//! Lab-grade transfer systems in the virtual lab (issue 10, items 1–3): the transfer-function,
//! state-space and servo-hydraulic actuator kinds against closed forms, the force built from
//! motion, noise given as power, the benchmark generator and shared channels, converters'
//! rounding, and the Tustin tracking controller — each built the way `substep run` builds it.

use nalgebra::{Complex, dmatrix, dvector};
use std::f64::consts::PI;
use substep::io::TestDefinition;
use substep::specimen::SpecimenSpec;
use substep::substructure::ExperimentalSubstructure;
use substep::transfer::converter::Converter;
use substep::transfer::lti::{StateSpace, TransferFunction};
use substep::transfer::noise::{BENCHMARK_SEED, MinStdPolar};
use substep::transfer::servo::Derivative;
use substep::transfer::{ActuatorSpec, Dynamics, LabOptions, SensorSpec, ServoSpec, VirtualLab};

fn tf(num: &[f64], den: &[f64]) -> ActuatorSpec {
    ActuatorSpec {
        dynamics: Dynamics::Lti(TransferFunction::new("actuator", num, den).unwrap().to_state_space()),
        delay: 0.0,
    }
}

/// A lab with one actuator on coupling DOF 0 and `specimen` there.
fn lab(actuator: ActuatorSpec, specimen: SpecimenSpec, dtau: f64, inner: usize, options: &LabOptions) -> VirtualLab {
    VirtualLab::from_specs_with(
        &[0],
        &[specimen],
        &[actuator],
        &[SensorSpec::ideal()],
        &[SensorSpec::ideal()],
        dtau,
        inner,
        options,
    )
    .unwrap()
}

fn spring() -> SpecimenSpec {
    SpecimenSpec::LinearSdof {
        dof: 0,
        mass: None,
        stiffness: 1000.0,
        damping: 0.0,
    }
}

/// The benchmark's specimen at the actuator's DOF.
fn benchmark_specimen() -> SpecimenSpec {
    SpecimenSpec::LumpedSdof {
        dof: 0,
        mass: 29.13,
        damping: 114.2208671,
        stiffness: 1.19e6,
    }
}

/// Commands `cmd(t_j)` at `t_j = j dtau`; returns the true displacements at `t_j`.
fn drive(lab: &mut VirtualLab, dtau: f64, n: usize, cmd: impl Fn(f64) -> f64) -> Vec<f64> {
    let (mut f, mut d) = ([0.0], [0.0]);
    (1..=n)
        .map(|j| {
            lab.substep(&[cmd(j as f64 * dtau)], (0.0, 0.0), dtau, &mut f, &mut d)
                .unwrap();
            lab.true_displacement().unwrap()[0]
        })
        .collect()
}

/// Gain and phase [rad] of `y` against `sin(ω t)` over whole periods at the end of the record
/// (least squares on sin/cos).
fn gain_phase(y: &[f64], dtau: f64, w: f64, periods: usize) -> (f64, f64) {
    let per = (2.0 * PI / w / dtau).round() as usize;
    let n = per * periods;
    let (mut s, mut c) = (0.0, 0.0);
    for (j, &v) in y.iter().enumerate().skip(y.len() - n) {
        let t = (j + 1) as f64 * dtau;
        s += v * (w * t).sin();
        c += v * (w * t).cos();
    }
    let (a, b) = (2.0 * s / n as f64, 2.0 * c / n as f64);
    ((a * a + b * b).sqrt(), b.atan2(a))
}

// ---------------------------------------------------------------------------------------------
// actuator kinds

#[test]
fn first_order_transfer_function_step_response_is_one_minus_exp() {
    // G(s) = 1 / (τ s + 1); a unit step (reached within the first sub-step, then held).
    let (tau, dtau) = (0.01, 1e-4);
    let mut l = lab(tf(&[1.0], &[tau, 1.0]), spring(), dtau, 2, &LabOptions::default());
    let y = drive(&mut l, dtau, 500, |_| 1.0);
    // The command ramps 0 → 1 over [0, Δτ]: exact response of the ramp-then-hold input.
    let exact = |t: f64| {
        let ramp = |t: f64| t - tau * (1.0 - (-t / tau).exp());
        (ramp(t) - ramp(t - dtau)) / dtau
    };
    let mut worst = 0.0f64;
    for (j, &v) in y.iter().enumerate() {
        let t = (j + 1) as f64 * dtau;
        worst = worst.max((v - exact(t)).abs());
    }
    assert!(worst < 1e-12, "FOH of the TF actuator vs closed form: {worst:e}");
    // And the plain step response 1 − e^{−t/τ} after the ramp (offset Δτ/2 to first order).
    let t = 0.03;
    let v = y[(t / dtau).round() as usize - 1];
    assert!((v - (1.0 - (-(t - dtau / 2.0) / tau).exp())).abs() < 1e-5, "{v}");
}

#[test]
fn transfer_function_actuator_equals_second_order_kind() {
    let (f, zeta, dtau) = (40.0, 0.6, 2.5e-4);
    let w = 2.0 * PI * f;
    let second = ActuatorSpec {
        dynamics: Dynamics::SecondOrder { frequency_hz: f, zeta },
        delay: 1.3e-3,
    };
    let mut as_tf = tf(&[w * w], &[1.0, 2.0 * zeta * w, w * w]);
    as_tf.delay = 1.3e-3;
    let cmd = |t: f64| 0.01 * (2.0 * PI * 3.0 * t).sin() + 0.004 * (2.0 * PI * 17.0 * t).cos();
    let mut a = lab(second, spring(), dtau, 4, &LabOptions::default());
    let mut b = lab(as_tf, spring(), dtau, 4, &LabOptions::default());
    let ya = drive(&mut a, dtau, 2000, cmd);
    let yb = drive(&mut b, dtau, 2000, cmd);
    let peak = ya.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let worst = ya.iter().zip(&yb).fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
    assert!(
        worst < 1e-12 * peak.max(1.0),
        "TF vs second_order: {worst:e} (peak {peak})"
    );
}

#[test]
fn state_space_actuator_with_feedthrough_matches_its_transfer_function() {
    // (s + 30) / (s + 60) = 1 − 30/(s + 60): state space A = −60, B = 1, C = −30, D = 1.
    let dtau = 1e-3;
    let ss = ActuatorSpec {
        dynamics: Dynamics::Lti(
            StateSpace::new("actuator", dmatrix![-60.0], dvector![1.0], dvector![-30.0], 1.0).unwrap(),
        ),
        delay: 0.0,
    };
    let mut a = lab(ss, spring(), dtau, 1, &LabOptions::default());
    let y = drive(&mut a, dtau, 4000, |t| (2.0 * PI * 5.0 * t).sin());
    let (g, ph) = gain_phase(&y, dtau, 2.0 * PI * 5.0, 10);
    let h = TransferFunction::new("t", &[1.0, 30.0], &[1.0, 60.0])
        .unwrap()
        .frequency_response(5.0);
    // The FOH of a sampled ramp adds no phase; the remaining error is the sampling of the sine.
    assert!((g - h.norm()).abs() < 2e-4, "gain {g} vs {}", h.norm());
    assert!((ph - h.arg()).abs() < 2e-3, "phase {ph} vs {}", h.arg());
}

#[test]
fn servo_hydraulic_plant_with_the_specimen_matches_its_closed_form() {
    // G_p(s) of transfer/servo.rs with the specimen's m, c, k; exact CSI derivative.
    let dtau = 1.0 / 4096.0;
    let servo = ServoSpec {
        derivative: Derivative::Exact,
        ..ServoSpec::benchmark()
    };
    let spec = ActuatorSpec {
        dynamics: Dynamics::ServoHydraulic(servo),
        delay: 0.0,
    };
    let gp = servo.params([29.13, 114.2208671, 1.19e6]).closed_form().unwrap();
    // Steady state: a held unit command.
    let mut l = lab(spec.clone(), benchmark_specimen(), dtau, 4, &LabOptions::default());
    let y = drive(&mut l, dtau, 8 * 4096, |_| 1e-3);
    let ss = y[y.len() - 1] / 1e-3;
    assert!(
        (ss - gp.dc_gain()).abs() < 1e-9,
        "static gain {ss} vs G_p(0) = {}",
        gp.dc_gain()
    );
    // Frequency response at 2, 8 and 32 Hz (whole periods of samples).
    for f in [2.0, 8.0, 32.0] {
        let mut l = lab(spec.clone(), benchmark_specimen(), dtau, 4, &LabOptions::default());
        let w = 2.0 * PI * f;
        let y = drive(&mut l, dtau, 4 * 4096, |t| 1e-3 * (w * t).sin());
        // The last second.
        let (g, ph) = gain_phase(&y, dtau, w, f as usize);
        // The lab's command is the linear interpolation of the samples: its fundamental carries
        // sinc²(ωΔτ/2) of the amplitude (the triangle kernel's transform).
        let x = w * dtau / 2.0;
        let h: Complex<f64> = gp.frequency_response(f) * 1e-3 * (x.sin() / x).powi(2);
        assert!(
            (g - h.norm()).abs() < 2e-5 * h.norm(),
            "{f} Hz: gain {g} vs {}",
            h.norm()
        );
        assert!((ph - h.arg()).abs() < 2e-5, "{f} Hz: phase {ph} vs {}", h.arg());
    }
    // The specimen is part of the plant: a softer specimen changes the actuator's motion.
    let soft = SpecimenSpec::LumpedSdof {
        dof: 0,
        mass: 29.13,
        damping: 114.2208671,
        stiffness: 1.19e5,
    };
    let mut l = lab(spec, soft, dtau, 4, &LabOptions::default());
    let w = 2.0 * PI * 32.0;
    let y = drive(&mut l, dtau, 3 * 4096, |t| 1e-3 * (w * t).sin());
    let (g, _) = gain_phase(&y, dtau, w, 32);
    let h_soft = servo
        .params([29.13, 114.2208671, 1.19e5])
        .closed_form()
        .unwrap()
        .frequency_response(32.0);
    let x = w * dtau / 2.0;
    let expected = 1e-3 * h_soft.norm() * (x.sin() / x).powi(2);
    assert!(
        (g - expected).abs() < 2e-5 * expected,
        "soft specimen: {g} vs {expected}"
    );
    assert!((h_soft.norm() - gp.frequency_response(32.0).norm()).abs() > 0.01);
}

#[test]
fn force_from_motion_is_the_backward_difference_load_cell() {
    // Ideal actuator: the achieved motion is the command, so the force is known exactly:
    // f_j = −(k x_j + c D1_j + m D2_j + m a_g).
    let (m, c, k, dtau) = (29.13, 114.2208671, 1.19e6, 1.0 / 4096.0);
    let options = LabOptions {
        force_from_motion: true,
        ..LabOptions::default()
    };
    let mut l = lab(ActuatorSpec::ideal(), benchmark_specimen(), dtau, 3, &options);
    let x = |t: f64| 1e-3 * (2.0 * PI * 7.0 * t).sin() + 2e-4 * t;
    let (mut f, mut d) = ([0.0], [0.0]);
    let (mut x1, mut v1) = (0.0, 0.0);
    for j in 1..=2000 {
        let t = j as f64 * dtau;
        let ag = 0.3 * (5.0 * t).cos();
        l.substep(&[x(t)], (0.0, ag), dtau, &mut f, &mut d).unwrap();
        let xj = x(t);
        let (d1, d2) = if j == 1 {
            (0.0, 0.0)
        } else {
            ((xj - x1) / dtau, ((xj - x1) / dtau - v1) / dtau)
        };
        let expected = -(k * xj + c * d1 + m * d2 + m * ag);
        assert!(
            (f[0] - expected).abs() < 1e-9 * expected.abs().max(1.0),
            "j = {j}: {} vs {expected}",
            f[0]
        );
        // The model's force (the lumped specimen at the inner rate) differs: that is the option.
        if j > 10 {
            assert!((l.true_force()[0] - f[0]).abs() > 0.0);
        }
        x1 = xj;
        v1 = if j == 1 { 0.0 } else { d1 };
    }
}

// ---------------------------------------------------------------------------------------------
// sensors and converters, through the config parser

const BASE: &str = r#"
[structure.sdof]
mass = 1000.0
stiffness = 1.0e6
[ground_motion]
generator = "sine_sweep"
amplitude = 1.0
f0 = 0.5
f1 = 2.0
duration = 0.1
[integrator]
scheme = "average_acceleration"
dt = 0.0009765625
[substructure]
coupling_dofs = [1]
substeps = 4
[[substructure.specimen]]
kind = "linear_sdof"
dof = 1
stiffness = 1000.0
"#;

fn parse(extra: &str) -> substep::Result<TestDefinition> {
    TestDefinition::from_toml(&format!("{BASE}{extra}"), "cfg.toml", std::path::Path::new(""))
}

fn noise_draws(spec: &SensorSpec, n: usize) -> Vec<f64> {
    let mut s = spec.build("sensor").unwrap();
    (0..n).map(|_| s.measure(0.0, 1e-3)).collect()
}

#[test]
fn noise_power_gives_sigma_squared_equal_power_over_sample_time() {
    let (p, ts): (f64, f64) = (6.25e-14, 1.0 / 4096.0);
    let by_power = parse(&format!(
        "[substructure.sensors]\ndisplacement_noise_power = {p:e}\nnoise_sample_time = {ts:e}\nseed = 7\n"
    ))
    .unwrap();
    let by_sigma = parse(&format!(
        "[substructure.sensors]\ndisplacement_noise = {:e}\nseed = 7\n",
        (p / ts).sqrt()
    ))
    .unwrap();
    let a = &by_power.substructure.as_ref().unwrap().displacement_sensors[0];
    let b = &by_sigma.substructure.as_ref().unwrap().displacement_sensors[0];
    assert_eq!(a.noise_std, (p / ts).sqrt());
    assert!(
        (a.noise_std - 1.6e-5).abs() < 1e-20,
        "the benchmark's σ_x = 1.6e−5 m: {}",
        a.noise_std
    );
    assert_eq!(noise_draws(a, 100), noise_draws(b, 100));
}

#[test]
fn benchmark_generator_reproduces_the_benchmark_sequence_and_shares_channels() {
    let def = parse(
        "[substructure.sensors]\ngenerator = \"benchmark\"\nshared_noise = true\nforce_noise = 2.0\ndisplacement_noise = 1.0\n",
    )
    .unwrap();
    let s = def.substructure.as_ref().unwrap();
    let (f, d) = (&s.force_sensors[0], &s.displacement_sensors[0]);
    assert_eq!(f.seed, u64::from(BENCHMARK_SEED));
    assert_eq!(d.seed, u64::from(BENCHMARK_SEED));
    let fd = noise_draws(f, 1000);
    let dd = noise_draws(d, 1000);
    // Shared: the force channel is the displacement channel's sequence times σ_f/σ_x, bit for bit.
    for (x, y) in fd.iter().zip(&dd) {
        assert_eq!(*x, 2.0 * y);
    }
    // The benchmark's first 1000 standard normals (shipped with the RTHS tests).
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/rths_noise_first1000.csv"
    ))
    .unwrap();
    let published: Vec<f64> = text.lines().skip(1).map(|l| l.trim().parse().unwrap()).collect();
    assert_eq!(published.len(), 1000);
    for (k, (x, p)) in dd.iter().zip(&published).enumerate() {
        assert!((x - p).abs() < 1e-15, "draw {k}: {x} vs {p}");
    }
    // Without sharing, channels differ (and stay in the generator's seed range).
    let def = parse("[substructure.sensors]\ngenerator = \"benchmark\"\nforce_noise = 1.0\ndisplacement_noise = 1.0\n")
        .unwrap();
    let s = def.substructure.as_ref().unwrap();
    assert_ne!(
        noise_draws(&s.force_sensors[0], 10),
        noise_draws(&s.displacement_sensors[0], 10)
    );
    let mut g = MinStdPolar::benchmark();
    assert_eq!(g.normal(), published[0]);
}

#[test]
fn converters_round_half_away_from_zero_and_saturate() {
    let q = 0.25;
    let def = parse(&format!(
        "[substructure.sensors]\ndisplacement_range = 1.0\ndisplacement_quantum = {q}\ncommand_range = 0.5\ncommand_quantum = {q}\n"
    ))
    .unwrap();
    let s = def.substructure.as_ref().unwrap();
    let mut sensor = s.displacement_sensors[0].build("sensor").unwrap();
    // ±half quanta round away from zero; just inside stays.
    for (x, y) in [
        (0.125, 0.25),
        (-0.125, -0.25),
        (0.375, 0.5),
        (-0.375, -0.5),
        (0.1249999, 0.0),
        (-0.1249999, 0.0),
        (0.9, 1.0),
        (3.0, 1.0),
        (-3.0, -1.0),
    ] {
        assert_eq!(sensor.measure(x, 1e-3), y, "A/D of {x}");
    }
    // The D/A on the commands: quantise, then saturate at ±0.5.
    let c = s.lab.command_converter.unwrap();
    assert_eq!(c, Converter::new(0.5, q).unwrap());
    assert_eq!(c.da(0.125), 0.25);
    assert_eq!(c.da(-0.125), -0.25);
    assert_eq!(c.da(0.7), 0.5);
    // Through the lab: an ideal actuator reaches the converted command.
    let mut l = VirtualLab::from_specs_with(
        &s.coupling_dofs,
        &s.specimens,
        &[ActuatorSpec::ideal()],
        &s.force_sensors,
        &s.displacement_sensors,
        1e-3,
        1,
        &s.lab,
    )
    .unwrap();
    let (mut f, mut d) = ([0.0], [0.0]);
    l.substep(&[0.125], (0.0, 0.0), 1e-3, &mut f, &mut d).unwrap();
    assert_eq!(l.true_displacement().unwrap()[0], 0.25);
    // adc_bits keeps its meaning: q = 2 r / 2^bits.
    let def = parse("[substructure.sensors]\nadc_bits = 3\nforce_range = 4.0\n").unwrap();
    let mut s = def.substructure.as_ref().unwrap().force_sensors[0].build("s").unwrap();
    assert_eq!(s.measure(0.5, 1e-3), 1.0);
    assert_eq!(s.measure(-0.4999, 1e-3), 0.0);
}

#[test]
fn tracking_controller_is_tustin_of_the_configured_tf() {
    // C(s) = 2 + 95/s at Δτ = dt/4: Tustin gives y_k = y_{k−1} + (2 + 95Δτ/2) e_k − (2 − 95Δτ/2) e_{k−1}.
    let def = parse("[substructure.controller]\nnum = [2.0, 95.0]\nden = [1.0, 0.0]\n").unwrap();
    let s = def.substructure.as_ref().unwrap();
    let c = s.controller.as_ref().unwrap();
    assert_eq!(c.num(), &[2.0, 95.0]);
    let dtau = 0.0009765625 / 4.0;
    let mut f = substep::transfer::discrete::DiscreteFilter::tustin("c", c, dtau).unwrap();
    let (b0, b1) = (2.0 + 95.0 * dtau / 2.0, -(2.0 - 95.0 * dtau / 2.0));
    let (mut y, mut e_prev) = (0.0, 0.0);
    for k in 0..50 {
        let e = (k as f64 * 0.37).sin();
        y += b0 * e + b1 * e_prev;
        e_prev = e;
        let got = f.step(e);
        assert!((got - y).abs() < 1e-12, "{k}: {got} vs {y}");
    }
}

#[test]
fn bad_transfer_inputs_name_the_key() {
    let err = |extra: &str| parse(extra).unwrap_err().to_string();
    for (extra, expect) in [
        (
            "[substructure.controller]\nnum = [1.0]\nden = [0.0, 0.0]\n",
            "cfg.toml: substructure.controller.den: is zero",
        ),
        (
            "[substructure.controller]\nnum = [1.0, 0.0, 0.0]\nden = [1.0, 1.0]\n",
            "cfg.toml: substructure.controller: improper transfer function",
        ),
        (
            "[substructure.controller]\nnum = [1.0]\nden = [1.0, -10.0]\n",
            "cfg.toml: substructure.controller: discretised controller is unstable",
        ),
        (
            "[substructure.actuator]\nkind = \"transfer_function\"\nnum = [1.0]\nden = [1.0, -5.0]\n",
            "cfg.toml: substructure.actuator: the actuator dynamics are not asymptotically stable",
        ),
        (
            "[substructure.actuator]\nkind = \"transfer_function\"\nnum = [1.0]\nden = [0.0]\n",
            "cfg.toml: substructure.actuator.den: is zero",
        ),
        (
            "[substructure.actuator]\nkind = \"state_space\"\na = [[-1.0, 0.0]]\nb = [1.0]\nc = [1.0]\n",
            "cfg.toml: substructure.actuator.a: must be square",
        ),
        (
            "[substructure.actuator]\nkind = \"servo_hydraulic\"\n",
            "cfg.toml: substructure.actuator.kind: a servo_hydraulic or hydraulic actuator needs exactly one lumped_sdof specimen at coupling DOF 1",
        ),
        (
            "[substructure.sensors]\ndisplacement_noise_power = 1e-12\n",
            "cfg.toml: substructure.sensors.displacement_noise_power: needs noise_sample_time",
        ),
        (
            "[substructure.sensors]\ngenerator = \"benchmark\"\nseed = 0\n",
            "cfg.toml: substructure.sensors.seed: the benchmark generator needs a seed in 1..=2147483646",
        ),
        (
            "[substructure.sensors]\ncommand_range = 1.0\n",
            "cfg.toml: substructure.sensors.command_range: needs command_quantum or command_bits",
        ),
        (
            "[substructure.sensors]\ndisplacement_quantum = 0.1\n",
            "cfg.toml: substructure.sensors.displacement_quantum: needs displacement_range",
        ),
    ] {
        let e = err(extra);
        assert!(e.starts_with(expect), "{extra}: got '{e}'");
        assert!(!e.contains('\n'), "one line: {e}");
    }
    // `force` sits in [substructure]: a massless linear_sdof is a valid from_motion specimen.
    let with_force = |v: &str| {
        TestDefinition::from_toml(
            &BASE.replace("substeps = 4\n", &format!("substeps = 4\nforce = \"{v}\"\n")),
            "cfg.toml",
            std::path::Path::new(""),
        )
    };
    assert!(
        with_force("from_motion")
            .unwrap()
            .substructure
            .unwrap()
            .lab
            .force_from_motion
    );
    let e = with_force("loadcell").unwrap_err().to_string();
    assert!(e.starts_with("cfg.toml: substructure.force: unknown 'loadcell'"), "{e}");
    // The lab's options are refused with a remote site (which replaces the lab).
    let remote = TestDefinition::from_toml(
        &format!(
            "{}[substructure.remote]\naddress = \"127.0.0.1:9\"\n",
            BASE.replace("substeps = 4\n", "substeps = 4\nforce = \"from_motion\"\n")
        ),
        "cfg.toml",
        std::path::Path::new(""),
    );
    let e = remote.map(|_| ()).unwrap_err().to_string();
    assert!(
        e.starts_with("cfg.toml: substructure.force: belongs to the virtual lab"),
        "{e}"
    );
}

#[test]
fn benchmark_channel_seeds_are_the_same_locally_and_on_a_site() {
    // A site derives its channels from the base spec with `channel_sensors`; a local run from
    // the config: both give the same per-channel seeds, so a remote run reproduces a local one.
    let def = parse("[substructure.sensors]\ngenerator = \"benchmark\"\nforce_noise = 1.0\ndisplacement_noise = 1.0\n")
        .unwrap();
    let s = def.substructure.as_ref().unwrap();
    let base = SensorSpec {
        noise_std: 1.0,
        generator: substep::transfer::NoiseGenerator::Benchmark,
        seed: u64::from(BENCHMARK_SEED),
        ..SensorSpec::ideal()
    };
    let (f, d) = substep::transfer::channel_sensors(&base, &base, 1);
    assert_eq!(f[0], s.force_sensors[0]);
    assert_eq!(d[0], s.displacement_sensors[0]);
    assert!((1..=2_147_483_646).contains(&f[0].seed) && f[0].seed != d[0].seed);
    // What a site cannot do is refused there, with the key.
    let site = |sensors: &str| {
        substep::io::site_config::SiteDefinition::from_toml(
            &format!(
                "[site]\nprotocol = \"substep\"\nlisten = \"127.0.0.1:8090\"\n[[specimen]]\nkind = \"linear_sdof\"\ndof = 1\nstiffness = 10.0\n[sensors]\n{sensors}"
            ),
            "site.toml",
            std::path::Path::new(""),
        )
        .map(|_| ())
        .map_err(|e| e.to_string())
    };
    site("generator = \"benchmark\"\nforce_noise = 1.0\n").unwrap();
    let e = site("shared_noise = true\n").unwrap_err();
    assert!(
        e.starts_with("site.toml: sensors.shared_noise: is not supported by a site"),
        "{e}"
    );
    let e = site("command_range = 1.0\ncommand_bits = 16\n").unwrap_err();
    assert!(e.starts_with("site.toml: sensors.command_range:"), "{e}");
}

#[test]
fn state_round_trip_of_the_new_kinds_and_the_controller() {
    // Save the state, go on, restore, go on again: bit-identical (checkpoints and the linear
    // analysis rely on it).
    let dtau = 1.0 / 4096.0;
    let kinds = [
        ActuatorSpec {
            dynamics: Dynamics::ServoHydraulic(ServoSpec::benchmark()),
            delay: 5e-4,
        },
        tf(&[1.0, 30.0], &[1.0, 60.0]),
        tf(&[142122.3], &[1.0, 527.8, 142122.3]),
    ];
    let pi = TransferFunction::new("c", &[2.0, 95.0], &[1.0, 0.0]).unwrap();
    let lead = TransferFunction::new("f", &[50.8, 8570.4], &[1.0, 8570.4]).unwrap();
    for spec in kinds {
        let inner = lab(spec.clone(), benchmark_specimen(), dtau, 3, &LabOptions::default());
        let mut site = substep::transfer::ControlledSite::new(Box::new(inner), "c", &pi, Some(&lead), dtau).unwrap();
        let cmd = |j: usize| 1e-3 * (j as f64 * 0.01).sin();
        let (mut f, mut d) = ([0.0], [0.0]);
        for j in 0..300 {
            site.substep(&[cmd(j)], (0.0, 0.0), dtau, &mut f, &mut d).unwrap();
        }
        let mut state = vec![0.0; site.state_len()];
        site.write_state(&mut state);
        let run = |site: &mut substep::transfer::ControlledSite| -> Vec<f64> {
            let (mut f, mut d) = ([0.0], [0.0]);
            (300..400)
                .flat_map(|j| {
                    site.substep(&[cmd(j)], (0.0, 0.0), dtau, &mut f, &mut d).unwrap();
                    [f[0], d[0]]
                })
                .collect()
        };
        let first = run(&mut site);
        site.read_state(&state);
        let second = run(&mut site);
        assert_eq!(first, second, "{:?}", spec.dynamics);
        assert!(first.iter().any(|v| *v != 0.0));
    }
}
