//! Unit tests of the config reader (parsing and validation messages).

use super::compensation::DEFAULT_RAMP_STEPS;
use super::*;
use crate::compensate::{PhaseLagSpec, Ramp};
use crate::substructure::ErrorForceSpec;
use nalgebra::DVector;

const BASE: &str = r#"
[structure]
mass = [[1000.0, 0.0, 0.0], [0.0, 1000.0, 0.0], [0.0, 0.0, 1000.0]]
stiffness = [[2e6, -1e6, 0.0], [-1e6, 2e6, -1e6], [0.0, -1e6, 1e6]]

[structure.rayleigh]
zeta = 0.05

[ground_motion]
generator = "harmonic"
amplitude = 1.0
frequency = 2.0
duration = 1.0

[integrator]
scheme = "newmark"
dt = 0.01

[substructure]
coupling_dofs = [3, 1]
substeps = 4

[[substructure.specimen]]
kind = "linear_sdof"
dof = 3
mass = 50.0
stiffness = 2000.0
damping = 60.0

[[substructure.specimen]]
kind = "linear_sdof"
dof = 1
stiffness = 1.0e5

[substructure.actuator]
kind = "second_order"
frequency = 50.0
zeta = 0.7

[substructure.sensors]
force_noise = 1.0
seed = 3
"#;

fn parse(text: &str) -> Result<TestDefinition> {
    TestDefinition::from_toml(text, "cfg.toml", Path::new("/nonexistent-dir"))
}

fn err(text: &str) -> String {
    match parse(text) {
        Ok(_) => panic!("config was accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

/// BASE with `from` replaced by `to` (which must occur).
fn edit(from: &str, to: &str) -> String {
    assert!(BASE.contains(from), "{from}");
    BASE.replacen(from, to, 1)
}

#[test]
fn base_config_is_valid_and_zero_based() {
    let d = parse(BASE).unwrap();
    assert_eq!(d.source, "cfg.toml");
    assert_eq!(d.model.n_dofs(), 3);
    assert!(
        d.model.as_dense().unwrap().damping[(0, 0)] > 0.0,
        "Rayleigh damping applied"
    );
    assert_eq!(d.integrator.steps, 100);
    assert_eq!(d.ground_motion.accel.len(), 101);
    let s = d.substructure.unwrap();
    assert_eq!(s.coupling_dofs, vec![2, 0]);
    assert_eq!(s.specimens[0].dofs(), vec![2]);
    assert_eq!(s.inner_steps, 10, "default for a non-ideal actuator");
    assert_eq!((s.beta, s.gamma), (0.25, 0.5));
    assert_eq!(s.force_sensors.len(), 2);
    assert_eq!(s.force_sensors[0].noise_std, 1.0);
    let seeds = [
        s.force_sensors[0].seed,
        s.force_sensors[1].seed,
        s.displacement_sensors[0].seed,
        s.displacement_sensors[1].seed,
    ];
    for i in 0..4 {
        for j in 0..i {
            assert_ne!(seeds[i], seeds[j], "per-channel seeds differ");
        }
    }
    assert_eq!(s.error_force, ErrorForceSpec::None);
    assert_eq!(
        d.output,
        OutputSettings {
            dir: None,
            plots: true,
            plot_options: PlotOptions::default(),
            format: Default::default(),
        }
    );
}

#[test]
fn builders_and_defaults() {
    let d = parse(
        "[structure.tmd]\n[ground_motion]\ngenerator = \"sine_sweep\"\namplitude = 1\nf0 = 0.2\nf1 = 3\n\
         [integrator]\nscheme = \"exact\"\ndt = 0.01\nduration = 2.0\n",
    )
    .unwrap();
    assert_eq!(d.model.n_dofs(), 2);
    assert_eq!(d.integrator.scheme, Scheme::Exact);
    assert_eq!(d.integrator.steps, 200, "generator duration from integrator.duration");
    let d = parse(
        "[structure.shear_building]\nstories = 5\nstory_mass = 1e4\nfirst_period = 0.5\n[structure.modal]\n\
         zeta = [0.02, 0.03, 0.04, 0.05, 0.06]\n[ground_motion]\ngenerator = \"kanai_tajimi\"\nduration = 1\n\
         pga = 2\n[integrator]\nscheme = \"hht\"\nalpha = -0.1\ndt = 0.02\n[output]\ndir = \"out\"\nplots = false\n",
    )
    .unwrap();
    assert_eq!(d.model.n_dofs(), 5);
    assert_eq!(d.integrator.scheme, Scheme::Hht { alpha: -0.1 });
    assert!((d.ground_motion.accel.iter().fold(0.0f64, |m, a| m.max(a.abs())) - 2.0).abs() < 1e-12);
    assert_eq!(d.output.dir, Some(PathBuf::from("out")));
    assert!(!d.output.plots);
}

#[test]
fn ideal_actuator_defaults_to_one_inner_step() {
    let text = edit(
        "kind = \"second_order\"\nfrequency = 50.0\nzeta = 0.7",
        "kind = \"ideal\"",
    );
    assert_eq!(parse(&text).unwrap().substructure.unwrap().inner_steps, 1);
    let text = edit(
        "kind = \"second_order\"\nfrequency = 50.0\nzeta = 0.7",
        "kind = \"ideal\"\ndelay = 0.002",
    );
    assert_eq!(parse(&text).unwrap().substructure.unwrap().inner_steps, 10);
}

#[test]
fn malformed_toml_names_file_and_line() {
    let e = err(&edit("substeps = 4", "substeps = [4"));
    assert!(e.starts_with("cfg.toml: line 23: "), "{e}");
    assert!(!e.contains('\n'));
}

#[test]
fn unknown_keys_are_named() {
    let e = err(&edit("substeps = 4", "substeps = 4\nsubstepz = 5"));
    assert!(e.starts_with("cfg.toml: line 22: unknown field `substepz`"), "{e}");
    let e = err(&edit("stiffness = 1.0e5", "stiffness = 1.0e5\nmas = 3.0"));
    assert!(e.contains("unknown field `mas`"), "{e}");
    let e = err(&format!("{BASE}\n[outptu]\ndir = \"x\"\n"));
    assert!(e.contains("unknown field `outptu`"), "{e}");
}

#[test]
fn unknown_scheme_and_kinds() {
    let e = err(&edit("scheme = \"newmark\"", "scheme = \"leapfrog\""));
    assert!(
        e.starts_with("cfg.toml: integrator.scheme: unknown scheme 'leapfrog'"),
        "{e}"
    );
    let e = err(&edit(
        "kind = \"linear_sdof\"\ndof = 1",
        "kind = \"hydraulic_damper\"\ndof = 1",
    ));
    assert!(
        e.contains("unknown variant `hydraulic_damper`, expected one of") && e.contains("`linear_sdof`"),
        "{e}"
    );
    let e = err(&edit("kind = \"second_order\"", "kind = \"third_order\""));
    assert!(e.contains("unknown variant `third_order`"), "{e}");
    let e = err(&edit("generator = \"harmonic\"", "generator = \"chirp\""));
    assert_eq!(
        e,
        "cfg.toml: ground_motion.generator: unknown generator 'chirp' (expected harmonic, sine_sweep or kanai_tajimi)"
    );
}

#[test]
fn matrix_errors() {
    let e = err(&edit(
        "stiffness = [[2e6, -1e6, 0.0], [-1e6, 2e6, -1e6], [0.0, -1e6, 1e6]]",
        "stiffness = [[2e6, -1e6], [-1e6, 2e6]]",
    ));
    assert_eq!(
        e,
        "cfg.toml: structure.stiffness: is 2x2 but the model has 3 DOFs (the mass matrix is 3x3)"
    );
    let e = err(&edit("[-1e6, 2e6, -1e6], [0.0", "[-1e6, 2e6, -1e6], [5.0"));
    assert!(
        e.starts_with("cfg.toml: structure.stiffness: is not symmetric: entry (3, 1)"),
        "{e}"
    );
    let e = err(&edit("[0.0, 0.0, 1000.0]]", "[0.0, 0.0, -1000.0]]"));
    assert_eq!(e, "cfg.toml: structure.mass: is not positive definite");
    let e = err(&edit("[0.0, 0.0, 1000.0]]", "[0.0, 1000.0]]"));
    assert_eq!(e, "cfg.toml: structure.mass: row 3 has 2 entries but row 1 has 3");
    let e = err(&edit("[0.0, 0.0, 1000.0]]", "[0.0, 0.0, nan]]"));
    assert_eq!(e, "cfg.toml: structure.mass: entry (3, 3) is not finite (NaN)");
}

#[test]
fn missing_files_are_named() {
    let e = err(&edit(
        "mass = [[1000.0, 0.0, 0.0], [0.0, 1000.0, 0.0], [0.0, 0.0, 1000.0]]",
        "mass = \"M.mtx\"",
    ));
    assert!(
        e.starts_with("cfg.toml: structure.mass: /nonexistent-dir/M.mtx: cannot read file"),
        "{e}"
    );
    let e = err(&edit(
        "generator = \"harmonic\"\namplitude = 1.0\nfrequency = 2.0\nduration = 1.0",
        "file = \"records/ag.csv\"",
    ));
    assert!(
        e.starts_with("cfg.toml: ground_motion.file: /nonexistent-dir/records/ag.csv: cannot read file"),
        "{e}"
    );
}

#[test]
fn nan_in_a_record_names_file_and_line() {
    let dir = std::env::temp_dir().join(format!("substep-config-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("ag.csv"), "t,ag\n0,0\n0.01,0.5\n0.02,NaN\n0.03,0\n").unwrap();
    let text = edit(
        "generator = \"harmonic\"\namplitude = 1.0\nfrequency = 2.0\nduration = 1.0",
        "file = \"ag.csv\"",
    );
    let e = TestDefinition::from_toml(&text, "cfg.toml", &dir)
        .unwrap_err()
        .to_string();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(e.starts_with("cfg.toml: ground_motion.file: "), "{e}");
    assert!(e.ends_with("ag.csv: line 4: value is not finite (NaN)"), "{e}");
}

#[test]
fn time_step_and_substeps() {
    let e = err(&edit("dt = 0.01", "dt = 0.0"));
    assert_eq!(e, "cfg.toml: integrator.dt: must be a finite number > 0, got 0");
    let e = err(&edit("dt = 0.01", "dt = -0.01"));
    assert_eq!(e, "cfg.toml: integrator.dt: must be a finite number > 0, got -0.01");
    let e = err(&edit("substeps = 4", "substeps = 0"));
    assert_eq!(e, "cfg.toml: substructure.substeps: must be at least 1");
    let e = err(&edit("substeps = 4", "substeps = 4\ninner_steps = 0"));
    assert_eq!(e, "cfg.toml: substructure.inner_steps: must be at least 1");
}

#[test]
fn coupling_dof_checks() {
    let e = err(&edit("coupling_dofs = [3, 1]", "coupling_dofs = [3, 7]"));
    assert_eq!(
        e,
        "cfg.toml: substructure.coupling_dofs: DOF 7 is out of range (the model has DOFs 1..=3)"
    );
    let e = err(&edit("coupling_dofs = [3, 1]", "coupling_dofs = [3, 0]"));
    assert_eq!(
        e,
        "cfg.toml: substructure.coupling_dofs: DOF 0 is out of range (the model has DOFs 1..=3)"
    );
    let e = err(&edit("coupling_dofs = [3, 1]", "coupling_dofs = [3, 1, 3]"));
    assert_eq!(e, "cfg.toml: substructure.coupling_dofs: DOF 3 is listed twice");
    let e = err(&edit("coupling_dofs = [3, 1]", "coupling_dofs = [3, 1, 2]"));
    assert_eq!(
        e,
        "cfg.toml: substructure.coupling_dofs: DOF 2 has no specimen attached"
    );
    let e = err(&edit("dof = 1\n", "dof = 2\n"));
    assert_eq!(
        e,
        "cfg.toml: substructure.specimen[2].dof: DOF 2 is not one of substructure.coupling_dofs"
    );
}

#[test]
fn specimen_values() {
    let e = err(&edit("mass = 50.0", "mass = -50.0"));
    assert_eq!(
        e,
        "cfg.toml: substructure.specimen[1].mass: must be a finite number > 0, got -50"
    );
    let e = err(&edit("damping = 60.0", "damping = -60.0"));
    assert_eq!(
        e,
        "cfg.toml: substructure.specimen[1].damping: must be a finite number >= 0, got -60"
    );
    let mdof = "kind = \"linear_mdof\"\ndofs = [3]\nmass = [[0.0, 0.0], [0.0, 50.0]]\n\
                stiffness = [[2000.0, -2000.0], [-2000.0, 2000.0]]\ndamping = [[60.0, -60.0], [-60.0, 60.0]]";
    let ok = edit(
        "kind = \"linear_sdof\"\ndof = 3\nmass = 50.0\nstiffness = 2000.0\ndamping = 60.0",
        mdof,
    );
    assert!(parse(&ok).is_ok());
    let bad = ok.replace("[0.0, 50.0]]", "[0.0, -50.0]]");
    let e = err(&bad);
    assert!(e.starts_with("cfg.toml: substructure.specimen[1].mass: "), "{e}");
    let bad = ok.replace(
        "[[0.0, 0.0], [0.0, 50.0]]",
        "[[0.0, 0.0, 0.0], [0.0, 50.0, 0.0], [0.0, 0.0, 1.0]]",
    );
    let e = err(&bad);
    assert!(e.starts_with("cfg.toml: substructure.specimen[1].mass: is 3x3;"), "{e}");
}

#[test]
fn actuator_and_sensor_values() {
    let e = err(&edit("zeta = 0.7", "zeta = 0.0"));
    assert!(
        e.starts_with("cfg.toml: substructure.actuator.zeta: must be > 0"),
        "{e}"
    );
    let e = err(&edit("zeta = 0.7", "zeta = -0.2"));
    assert!(
        e.starts_with("cfg.toml: substructure.actuator.zeta: must be > 0"),
        "{e}"
    );
    let e = err(&edit("frequency = 50.0\n", ""));
    assert!(e.contains("missing field `frequency`"), "{e}");
    let e = err(&edit("force_noise = 1.0", "force_noise = -1.0"));
    assert_eq!(
        e,
        "cfg.toml: substructure.sensors.force_noise: must be a finite number >= 0, got -1"
    );
    let e = err(&edit("force_noise = 1.0", "adc_bits = 12"));
    assert!(
        e.starts_with("cfg.toml: substructure.sensors.adc_bits: needs force_range"),
        "{e}"
    );
}

#[test]
fn scheme_must_suit_the_substructure() {
    let e = err(&edit("scheme = \"newmark\"", "scheme = \"central_difference\""));
    assert!(
        e.starts_with("cfg.toml: integrator.scheme: the substructure algorithm needs an implicit Newmark scheme"),
        "{e}"
    );
    let e = err(&edit("scheme = \"newmark\"", "scheme = \"newmark\"\nbeta = 0.0"));
    assert!(e.starts_with("cfg.toml: integrator.scheme: "), "{e}");
    let e = err(&edit("scheme = \"newmark\"", "scheme = \"fox_goodwin\"\nbeta = 0.3"));
    assert!(
        e.starts_with("cfg.toml: integrator.beta: only used with scheme = \"newmark\""),
        "{e}"
    );
    let e = err(&edit("scheme = \"newmark\"", "scheme = \"hht\"\nalpha = -0.5"));
    assert!(
        e.starts_with("cfg.toml: integrator.alpha: Hilber's alpha must lie in [-1/3, 0]"),
        "{e}"
    );
}

#[test]
fn ground_motion_keys() {
    let e = err(&edit("frequency = 2.0", "frequency = 2.0\nf0 = 1.0"));
    assert!(
        e.starts_with("cfg.toml: ground_motion.f0: not used by generator = \"harmonic\""),
        "{e}"
    );
    let e = err(&edit("frequency = 2.0\n", ""));
    assert_eq!(
        e,
        "cfg.toml: ground_motion.frequency: required for generator = \"harmonic\""
    );
    let e = err(&edit("frequency = 2.0", "frequency = 80.0"));
    assert!(
        e.starts_with("cfg.toml: ground_motion.frequency: must be below the Nyquist"),
        "{e}"
    );
}

// --- error_force.kind = "arx" and [substructure.phase_lag] ---

fn with_tables(extra: &str) -> String {
    format!("{BASE}\n{extra}")
}

#[test]
fn error_force_arx_keys() {
    let def = parse(&with_tables("[substructure.error_force]\nkind = \"arx\"\n")).unwrap();
    assert_eq!(def.substructure.unwrap().error_force, ErrorForceSpec::ARX_DEFAULT);
    let def = parse(&with_tables(
        "[substructure.error_force]\nkind = \"arx\"\norder = 12\nforgetting_factor = 0.995\np0 = 10.0\n",
    ))
    .unwrap();
    assert_eq!(
        def.substructure.unwrap().error_force,
        ErrorForceSpec::Arx {
            order: 12,
            lambda: 0.995,
            p0: 10.0
        }
    );
    for (extra, key) in [
        ("order = 1", "substructure.error_force.order: must be in 2..=12, got 1"),
        (
            "order = 13",
            "substructure.error_force.order: must be in 2..=12, got 13",
        ),
        (
            "forgetting_factor = 0.0",
            "substructure.error_force.forgetting_factor: must be in (0, 1]",
        ),
        (
            "forgetting_factor = 1.5",
            "substructure.error_force.forgetting_factor: must be in (0, 1]",
        ),
        ("p0 = -1.0", "substructure.error_force.p0"),
    ] {
        let e = err(&with_tables(&format!(
            "[substructure.error_force]\nkind = \"arx\"\n{extra}\n"
        )));
        assert!(e.starts_with(&format!("cfg.toml: {key}")), "{e}");
    }
    let e = err(&with_tables("[substructure.error_force]\nkind = \"arx\"\np = 1.0\n"));
    assert!(e.contains("unknown field `p`"), "{e}");
}

#[test]
fn phase_lag_kinds_and_defaults() {
    let delayed = |extra: &str| {
        with_tables(&format!("[substructure.phase_lag]\n{extra}\n")).replacen(
            "zeta = 0.7",
            "zeta = 0.7\ndelay = 0.005",
            1,
        )
    };
    // Δτ = 2.5 ms, delay 5 ms: default lead 2 sub-steps; the ARX compensator's k_lag is the
    // actuator's low-frequency lag, delay + 2ζ/ω (50 Hz, ζ = 0.7: 4.456 ms), 3.78 → 4 sub-steps.
    let def = parse(&delayed("kind = \"polynomial\"")).unwrap();
    let pl = def.substructure.as_ref().unwrap().phase_lag.unwrap();
    assert_eq!(
        pl.spec,
        PhaseLagSpec::Polynomial {
            order: 3,
            lead: 2.0,
            spacing: 1,
            guard_factor: 10.0
        }
    );
    assert_eq!(pl.ramp, Ramp::new(0, DEFAULT_RAMP_STEPS * 4));
    let def = parse(&delayed(
        "kind = \"arx\"\nn_u = 3\nramp_start = 10\nramp_steps = 20\nfade_out = [90, 5]",
    ))
    .unwrap();
    let pl = def.substructure.as_ref().unwrap().phase_lag.unwrap();
    match pl.spec {
        PhaseLagSpec::Arx(a) => {
            assert_eq!((a.k_lag, a.n_u, a.lambda), (4, 3, 0.99));
            let lag = 0.005 + 2.0 * 0.7 / (2.0 * std::f64::consts::PI * 50.0);
            assert!((a.lead - lag / 0.0025).abs() < 1e-12, "{}", a.lead);
            // Velocities over one step (k_sub = 4), smoothed over half of it, the step's ripple,
            // the supervisor's bound 4 k_lag + 2 span.
            assert_eq!((a.span, a.smoothing, a.period, a.max_lead), (4, 2.0, 4, Some(24.0)));
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(pl.ramp, Ramp::new(40, 80).with_fade_out(360, 20));
    let def = parse(&delayed("kind = \"inverse_fir\"\nlead = 0.01\ntaps = 6")).unwrap();
    match def.substructure.as_ref().unwrap().phase_lag.unwrap().spec {
        PhaseLagSpec::InverseFir(f) => assert_eq!((f.lead, f.taps, f.order), (4.0, 6, 2)),
        other => panic!("{other:?}"),
    }
    let def = parse(&delayed("kind = \"none\"")).unwrap();
    assert!(def.substructure.as_ref().unwrap().phase_lag.is_none());
    // The test is built with the compensated site.
    let def = parse(&delayed("kind = \"arx\"")).unwrap();
    let s = def.substructure.as_ref().unwrap();
    let test = s.build_test(&def.model, 0.01, &DVector::zeros(3)).unwrap();
    assert!(test.site.phase_lag().is_some());
}

#[test]
fn phase_lag_bad_values_name_the_key() {
    let p = "cfg.toml: substructure.phase_lag.";
    for (extra, expect) in [
        (
            "kind = \"polynomial\"\norder = 4",
            "order: polynomial extrapolation supports orders 1 to 3",
        ),
        ("kind = \"polynomial\"\nlead = -0.01", "lead: "),
        (
            "kind = \"polynomial\"\nlead = 0.01\nlead_substeps = 4.0",
            "lead_substeps: give either",
        ),
        (
            "kind = \"polynomial\"\nk_lag = 4",
            "k_lag: is not used with kind = \"polynomial\"",
        ),
        ("kind = \"arx\"\nn_u = 13", "n_u: must be in 1..=12"),
        (
            "kind = \"arx\"\nforgetting_factor = 1.5",
            "forgetting_factor: must be in (0, 1]",
        ),
        ("kind = \"arx\"\nk_lag = 0", "k_lag: must be at least 1"),
        (
            "kind = \"arx\"\nk_lag = 100000",
            "k_lag: k_lag and span larger than the history",
        ),
        ("kind = \"arx\"\nspan = 0", "span: must be at least 1 sub-step"),
        (
            "kind = \"arx\"\nsmoothing = -1.0",
            "smoothing: must be in 0..=16384 sub-steps",
        ),
        (
            "kind = \"arx\"\nmax_lead = 0.0",
            "max_lead: must be a finite number > 0",
        ),
        (
            "kind = \"arx\"\nsupervisor = false\nmax_lead = 10.0",
            "max_lead: is not used with supervisor = false",
        ),
        (
            "kind = \"polynomial\"\nspan = 4",
            "span: is not used with kind = \"polynomial\"",
        ),
        ("kind = \"arx\"\norder = 2", "order: is not used with kind = \"arx\""),
        (
            "kind = \"arx\"\nguard_factor = 0.0",
            "guard_factor: must be a finite number > 0",
        ),
        ("kind = \"inverse_fir\"\ntaps = 0", "taps: must be in 1..=64"),
        (
            "kind = \"inverse_fir\"\nforgetting_factor = 0.0",
            "forgetting_factor: must be in (0, 1]",
        ),
        (
            "kind = \"arx\"\nramp_steps = 10\nfade_out = [5, 3]",
            "fade_out: begins at sub-step 20",
        ),
        ("kind = \"none\"\nn_u = 3", "n_u: is not used with kind = \"none\""),
        ("kind = \"smith\"", "kind: unknown kind 'smith'"),
    ] {
        let e = err(&with_tables(&format!("[substructure.phase_lag]\n{extra}\n")));
        assert!(e.starts_with(&format!("{p}{expect}")), "{extra}: {e}");
    }
}

#[test]
fn a_delay_longer_than_the_test_is_refused() {
    // The base test lasts 1 s; a 511 s delay (a typo of 5.11 ms) would leave the specimen at rest.
    let text = edit("zeta = 0.7", "zeta = 0.7\ndelay = 511.0");
    let e = err(&text);
    assert!(
        e.starts_with("cfg.toml: substructure.actuator.delay: 511 s is longer than the test (1 s)"),
        "{e}"
    );
    // Up to the test's length it is accepted (the specimen moves at the end).
    assert!(parse(&edit("zeta = 0.7", "zeta = 0.7\ndelay = 0.5")).is_ok());
}

/// A config given as a map (a Python dict) names the key path of a reader error, not a line of
/// the TOML text written from the map (issue 29).
#[test]
fn generated_toml_errors_name_the_key_path() {
    let value: toml::Value = toml::from_str(BASE).unwrap();
    let gen_err = |edit: &dyn Fn(&mut toml::Table)| {
        let mut v = value.clone();
        edit(v.as_table_mut().unwrap());
        let text = toml::to_string(&v).unwrap();
        match TestDefinition::from_generated_toml(&text, "<dict>", Path::new("/nonexistent-dir")) {
            Ok(_) => panic!("accepted:\n{text}"),
            Err(e) => e.to_string(),
        }
    };
    let e = gen_err(&|t| {
        t["integrator"]
            .as_table_mut()
            .unwrap()
            .insert("dtt".into(), 0.01.into());
    });
    assert!(e.starts_with("<dict>: integrator.dtt: unknown field `dtt`"), "{e}");
    let e = gen_err(&|t| {
        t["integrator"]
            .as_table_mut()
            .unwrap()
            .insert("dt".into(), "fast".into());
    });
    assert!(e.starts_with("<dict>: integrator.dt: "), "{e}");
    let e = gen_err(&|t| {
        let specimens = t["substructure"].as_table_mut().unwrap()["specimen"]
            .as_array_mut()
            .unwrap();
        specimens[1]
            .as_table_mut()
            .unwrap()
            .insert("stifness".into(), 1.0.into());
    });
    assert!(e.starts_with("<dict>: substructure.specimen[1].stifness: "), "{e}");
    // Validation errors already name their keys; they are unchanged.
    let e = gen_err(&|t| {
        t["integrator"]
            .as_table_mut()
            .unwrap()
            .insert("dt".into(), (-1.0).into());
    });
    assert!(e.starts_with("<dict>: integrator.dt: "), "{e}");
    assert!(!e.contains("line "), "{e}");
}

/// `[integrator] scheme = "cr" | "kr_alpha"` with `rho_inf`: defaults, ranges, misuse.
#[test]
fn explicit_model_based_schemes_in_the_config() {
    let base = "[structure.shear_building]\nstories = 3\nstory_mass = 1e5\nfirst_period = 0.5\n\
                [ground_motion]\ngenerator = \"sine_sweep\"\namplitude = 1\nf0 = 0.2\nf1 = 3\nduration = 1\n";
    let d = parse(&format!("{base}[integrator]\nscheme = \"kr_alpha\"\ndt = 0.01\n")).unwrap();
    assert_eq!(d.integrator.scheme, Scheme::KrAlpha { rho_inf: 0.5 });
    let d = parse(&format!(
        "{base}[integrator]\nscheme = \"kr_alpha\"\nrho_inf = 0.8\ndt = 0.01\n"
    ))
    .unwrap();
    assert_eq!(d.integrator.scheme, Scheme::KrAlpha { rho_inf: 0.8 });
    let d = parse(&format!("{base}[integrator]\nscheme = \"cr\"\ndt = 0.01\n")).unwrap();
    assert_eq!(d.integrator.scheme, Scheme::Cr);
    for (integrator, key, words) in [
        ("scheme = \"kr_alpha\"\nrho_inf = 1.5", "integrator.rho_inf", "[0, 1]"),
        ("scheme = \"kr_alpha\"\nrho_inf = -0.1", "integrator.rho_inf", "[0, 1]"),
        ("scheme = \"cr\"\nrho_inf = 0.5", "integrator.rho_inf", "only used with"),
        (
            "scheme = \"average_acceleration\"\nrho_inf = 0.5",
            "integrator.rho_inf",
            "only used with",
        ),
        (
            "scheme = \"kr_alpha\"\nalpha = -0.1",
            "integrator.alpha",
            "only used with",
        ),
        ("scheme = \"cr\"\nbeta = 0.25", "integrator.beta", "only used with"),
    ] {
        let msg = err(&format!("{base}[integrator]\n{integrator}\ndt = 0.01\n"));
        assert!(msg.contains(key) && msg.contains(words), "{integrator}: {msg}");
    }
    // A substructure test with CR is driven by the explicit scheme itself (issue 38).
    let d = parse(&format!(
        "{base}[integrator]\nscheme = \"cr\"\ndt = 0.01\n[substructure]\ncoupling_dofs = [3]\nsubsteps = 2\n\
         [[substructure.specimen]]\nkind = \"linear_sdof\"\ndof = 3\nstiffness = 1e6\n"
    ))
    .unwrap();
    assert_eq!(d.substructure.unwrap().explicit, Some(Scheme::Cr));
    // alpha_os cannot.
    let msg = err(&format!(
        "{base}[integrator]\nscheme = \"alpha_os\"\ndt = 0.01\n[substructure]\ncoupling_dofs = [3]\nsubsteps = 2\n\
         [[substructure.specimen]]\nkind = \"linear_sdof\"\ndof = 3\nstiffness = 1e6\n"
    ));
    assert!(msg.contains("integrator.scheme") && msg.contains("'alpha_os'"), "{msg}");
}
