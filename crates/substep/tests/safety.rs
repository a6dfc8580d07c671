//! Safety limits: a violation stops the test with a message naming DOF, quantity, value and
//! limit, and the actuators are ramped to the safe position linearly (never a jump).

use nalgebra::DVector;
use std::sync::{Arc, Mutex};
use substep::Error;
use substep::model::sdof;
use substep::specimen::SpecimenSpec;
use substep::substructure::{
    ErrorForceSpec, ExperimentalSubstructure, LimitedSite, SafetyLimits, SubstepController, SubstepSettings,
    SubstructureTest,
};
use substep::transfer::{ActuatorSpec, SensorSpec, VirtualLab};

/// Passes everything through and records the commands it was given.
struct Recording {
    inner: VirtualLab,
    commands: Arc<Mutex<Vec<f64>>>,
}

impl ExperimentalSubstructure for Recording {
    fn n_coupling(&self) -> usize {
        1
    }
    fn substep(&mut self, c: &[f64], ag: (f64, f64), dtau: f64, f: &mut [f64], d: &mut [f64]) -> substep::Result<()> {
        self.commands.lock().unwrap().push(c[0]);
        self.inner.substep(c, ag, dtau, f, d)
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
    fn read_state(&mut self, s: &[f64]) {
        self.inner.read_state(s)
    }
}

fn test_with(limits: SafetyLimits) -> (SubstructureTest, Arc<Mutex<Vec<f64>>>) {
    let model = sdof(1000.0, 600.0, 4e4).unwrap();
    let dt = 0.01;
    let k = 4;
    let settings = SubstepSettings {
        dt,
        beta: 0.25,
        gamma: 0.5,
        substeps: k,
        coupling_dofs: vec![0],
        error_force: ErrorForceSpec::None,
    };
    let ctrl = SubstepController::new(&model, &settings, &DVector::zeros(1)).unwrap();
    let spec = SpecimenSpec::LinearSdof {
        dof: 0,
        mass: None,
        stiffness: 5e3,
        damping: 0.0,
    };
    let lab = VirtualLab::from_specs(
        &[0],
        &[spec],
        &[ActuatorSpec::ideal()],
        &[SensorSpec::ideal()],
        &[SensorSpec::ideal()],
        dt / k as f64,
        1,
    )
    .unwrap();
    let commands = Arc::new(Mutex::new(Vec::new()));
    let rec = Recording {
        inner: lab,
        commands: commands.clone(),
    };
    let site = LimitedSite::new(Box::new(rec), limits).unwrap();
    (SubstructureTest::new(&model, ctrl, Box::new(site)).unwrap(), commands)
}

#[test]
fn displacement_limit_stops_and_ramps_down_linearly() {
    let limits = SafetyLimits {
        displacement: Some(vec![0.02]),
        velocity: None,
        force: None,
        ramp_time: 0.1,
        stability: None,
    };
    let (mut test, commands) = test_with(limits);
    // 1 Hz (near resonance) ground motion of growing response
    let ag = |i: usize| 2.0 * (2.0 * std::f64::consts::PI * i as f64 * 0.01).sin();
    let mut stopped = None;
    for i in 0..2000 {
        if let Err(e) = test.step(ag(i), ag(i + 1), &mut ()) {
            stopped = Some((i + 1, e));
            break;
        }
    }
    let (step, err) = stopped.expect("the limit must be hit");
    let msg = err.to_string();
    assert!(matches!(err, Error::Stopped { step: s, .. } if s == step), "{msg}");
    assert!(
        msg.contains("measured displacement") && msg.contains("coupling DOF 1") && msg.contains("limit 2e-2 m"),
        "{msg}"
    );
    let c = commands.lock().unwrap();
    // 0.1 s ramp of 2.5 ms sub-steps = 40 commands after the violating one, ending at 0
    let ramp = &c[c.len() - 40..];
    let start = c[c.len() - 41];
    assert!(start.abs() > 0.02, "the violating command {start}");
    assert_eq!(*ramp.last().unwrap(), 0.0);
    for (s, &v) in ramp.iter().enumerate() {
        let expected = start * (1.0 - (s + 1) as f64 / 40.0);
        assert!((v - expected).abs() < 1e-15, "ramp step {s}: {v} vs {expected}");
    }
    // the steps before the stop are intact and further steps are refused
    assert_eq!(test.steps_done(), step - 1);
    assert!(test.step(0.0, 0.0, &mut ()).is_err());
}

#[test]
fn velocity_limit_refuses_the_command() {
    let limits = SafetyLimits {
        displacement: None,
        velocity: Some(vec![1e-3]),
        force: None,
        ramp_time: 0.05,
        stability: None,
    };
    let (mut test, commands) = test_with(limits);
    let err = (0..100)
        .find_map(|i| test.step(if i == 0 { 0.0 } else { 3.0 }, 3.0, &mut ()).err())
        .unwrap();
    let msg = err.to_string();
    assert!(
        msg.contains("command velocity") && msg.contains("(command not sent)"),
        "{msg}"
    );
    // the refused command never reached the site: every recorded command moved ≤ 1e-3 m/s · Δτ
    let c = commands.lock().unwrap();
    let dtau = 0.0025;
    let mut prev = 0.0;
    for &v in c.iter() {
        assert!((v - prev).abs() <= 1e-3 * dtau * (1.0 + 1e-12), "{prev} -> {v}");
        prev = v;
    }
}

#[test]
fn limits_are_validated() {
    let bad = SafetyLimits {
        displacement: Some(vec![0.1, 0.1]),
        velocity: None,
        force: None,
        ramp_time: 1.0,
        stability: None,
    };
    assert!(
        bad.validate(1)
            .unwrap_err()
            .to_string()
            .contains("substructure.limits.displacement")
    );
    let bad = SafetyLimits {
        ramp_time: 0.0,
        ..SafetyLimits::default()
    };
    assert!(
        bad.validate(1)
            .unwrap_err()
            .to_string()
            .contains("substructure.limits.ramp_time")
    );
}

/// Every sub-step the observer sees: (step, j, ramp s (0 = algorithm), command).
#[derive(Default)]
struct Rows(Vec<(usize, usize, usize, f64)>);

impl substep::substructure::SubstepObserver for Rows {
    fn substep(&mut self, step: usize, j: usize, c: &[f64], _f: &[f64], _d: &[f64]) {
        self.0.push((step, j, 0, c[0]));
    }
    fn ramp(&mut self, step: usize, j: usize, s: usize, c: &[f64], _f: &[f64], _d: &[f64]) {
        self.0.push((step, j, s, c[0]));
    }
}

#[test]
fn the_ramp_down_reaches_the_observer() {
    let limits = SafetyLimits {
        displacement: Some(vec![0.02]),
        velocity: None,
        force: None,
        ramp_time: 0.1,
        stability: None,
    };
    let (mut test, commands) = test_with(limits);
    let ag = |i: usize| 2.0 * (2.0 * std::f64::consts::PI * i as f64 * 0.01).sin();
    let mut rows = Rows::default();
    let step = (0..2000)
        .find_map(|i| test.step(ag(i), ag(i + 1), &mut rows).err().map(|_| i + 1))
        .expect("the limit must be hit");
    let sent = commands.lock().unwrap();
    // every command the site received is one observed row, in order: the algorithm's sub-steps
    // (the tripping one included, its command was sent and measured), then the 40 ramp sub-steps
    assert_eq!(rows.0.len(), sent.len());
    for (r, &c) in rows.0.iter().zip(sent.iter()) {
        assert_eq!(r.3, c);
    }
    let ramp: Vec<_> = rows.0.iter().filter(|r| r.2 > 0).collect();
    assert_eq!(ramp.len(), 40);
    let tripped = rows.0[rows.0.len() - 41];
    assert_eq!((tripped.0, tripped.2), (step, 0));
    assert!(tripped.3.abs() > 0.02, "{tripped:?}");
    for (s, r) in ramp.iter().enumerate() {
        // same step, sub-step numbers and time run on after the tripping sub-step
        assert_eq!((r.0, r.1, r.2), (step, tripped.1 + s + 1, s + 1));
    }
    assert_eq!(ramp[39].3, 0.0);
    // the log is handed over once: a refused later step adds no rows
    let before = rows.0.len();
    assert!(test.step(0.0, 0.0, &mut rows).is_err());
    assert_eq!(rows.0.len(), before);
}

#[test]
fn a_refused_command_is_not_recorded_but_the_ramp_is() {
    let limits = SafetyLimits {
        displacement: None,
        velocity: Some(vec![1e-3]),
        force: None,
        ramp_time: 0.05,
        stability: None,
    };
    let (mut test, commands) = test_with(limits);
    let mut rows = Rows::default();
    let step = (0..100)
        .find_map(|i| {
            test.step(if i == 0 { 0.0 } else { 3.0 }, 3.0, &mut rows)
                .err()
                .map(|_| i + 1)
        })
        .unwrap();
    let sent = commands.lock().unwrap();
    assert_eq!(rows.0.len(), sent.len(), "only commands that were sent are recorded");
    let ramp: Vec<_> = rows.0.iter().filter(|r| r.2 > 0).collect();
    assert_eq!(ramp.len(), 20); // 0.05 s of 2.5 ms sub-steps
    // numbering continues after the last executed sub-step of the step (the refused one was not)
    let first_j = match rows.0.iter().rev().find(|r| r.2 == 0) {
        Some(r) if r.0 == step => r.1 + 1,
        _ => 1,
    };
    assert_eq!((ramp[0].0, ramp[0].1), (step, first_j));
}

#[test]
fn the_ramp_is_bounded() {
    let long = SafetyLimits {
        ramp_time: 1e6,
        ..SafetyLimits::default()
    };
    let msg = long.validate(1).unwrap_err().to_string();
    assert_eq!(
        msg,
        "substructure.limits.ramp_time: 1000000 s is longer than the maximum of 60 s"
    );
    let ok = SafetyLimits {
        ramp_time: substep::substructure::MAX_RAMP_TIME,
        ..SafetyLimits::default()
    };
    ok.validate(1).unwrap();
    // 60 s in 1 ms sub-steps = 60 000 ramp sub-steps: allowed; in 0.1 ms: 600 000, refused
    ok.validate_for(1, 1e-3).unwrap();
    let msg = ok.validate_for(1, 1e-4).unwrap_err().to_string();
    assert!(
        msg.starts_with("substructure.limits.ramp_time: 60 s needs 600000 ramp sub-steps of 1e-4 s; at most 100000"),
        "{msg}"
    );
}
