//! The safety limits sit next to the actuators: with phase-lag compensation the velocity limit
//! checks the command actually sent (`d + h Δu`), not the target `d`, and the wrapped lab's
//! ideal force and phase-lag report stay visible through the limits.

use std::path::Path;
use substep::io::TestDefinition;
use substep::run::Simulation;
use substep::substructure::SubstepObserver;

const DELAY_SUBSTEPS: usize = 10; // 10 ms at Δτ = 1 ms

fn config(limits: &str) -> String {
    let record = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/ag_sweep.csv");
    format!(
        "[structure.sdof]\nmass = 1000.0\nstiffness = 39478.417604357426\ndamping = 628.3185307179587\n\
         [ground_motion]\nfile = {:?}\n\
         [integrator]\nscheme = \"average_acceleration\"\ndt = 0.01\n\
         [substructure]\ncoupling_dofs = [1]\nsubsteps = 10\n\
         [[substructure.specimen]]\nkind = \"linear_sdof\"\ndof = 1\nmass = 50.0\nstiffness = 1973.9208802178716\ndamping = 62.83185307179586\n\
         [substructure.actuator]\nkind = \"ideal\"\ndelay = 0.01\n\
         [substructure.error_force]\nkind = \"none\"\n\
         [substructure.phase_lag]\nkind = \"polynomial\"\norder = 3\nlead = 0.03\nguard_factor = 1000\nramp_steps = 1\n\
         {limits}",
        record.display().to_string()
    )
}

#[derive(Default)]
struct Record {
    target: Vec<f64>,
    measured: Vec<f64>,
    phase_lag_reports: usize,
}

impl SubstepObserver for Record {
    fn substep(&mut self, _step: usize, _j: usize, command: &[f64], _force: &[f64], displacement: &[f64]) {
        self.target.push(command[0]);
        self.measured.push(displacement[0]);
    }
    fn phase_lag(&mut self, _tracking_error: &[f64], _correction: &[f64]) {
        self.phase_lag_reports += 1;
    }
}

fn max_rate(x: &[f64], dtau: f64) -> f64 {
    x.windows(2).map(|w| ((w[1] - w[0]) / dtau).abs()).fold(0.0, f64::max)
}

#[test]
fn velocity_limit_checks_the_compensated_command() {
    let dtau = 1e-3;
    // Without limits: the ideal actuator reproduces the sent command DELAY_SUBSTEPS later,
    // exactly at sub-step ends, so the sent command is the measured displacement shifted back.
    let def = TestDefinition::from_toml(&config(""), "free.toml", Path::new(".")).unwrap();
    let mut sim = Simulation::new(&def).unwrap();
    let mut rec = Record::default();
    for _ in 0..1500 {
        sim.step(&mut rec).unwrap();
    }
    let sent = &rec.measured[DELAY_SUBSTEPS..];
    let target_rate = max_rate(&rec.target, dtau);
    let sent_rate = max_rate(sent, dtau);
    assert!(
        sent_rate > 1.1 * target_rate,
        "the over-long lead makes the sent command faster: {sent_rate} vs {target_rate}"
    );
    assert_eq!(rec.phase_lag_reports, rec.target.len(), "the phase-lag report is seen");

    // A limit between the two: the target never exceeds it, the sent command does.
    let limit = 0.5 * (target_rate + sent_rate);
    let limits = format!("[substructure.limits]\nvelocity = [{limit}]\nramp_time = 0.05\n");
    let def = TestDefinition::from_toml(&config(&limits), "limited.toml", Path::new(".")).unwrap();
    let mut sim = Simulation::new(&def).unwrap();
    let mut rec = Record::default();
    let mut stop = None;
    for _ in 0..1500 {
        if let Err(e) = sim.step(&mut rec) {
            stop = Some(e.to_string());
            break;
        }
    }
    let stop = stop.expect("the compensated command trips the velocity limit");
    assert!(
        stop.contains("command velocity") && stop.contains("command not sent"),
        "{stop}"
    );
    assert_eq!(
        rec.phase_lag_reports,
        rec.target.len(),
        "the limits do not hide the compensator"
    );
}
