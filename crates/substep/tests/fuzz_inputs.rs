//! Property test of the test-definition reader: the shipped example configs with their numbers
//! mutated to extremes (0, -0, 1e-300, 1e300, 1e308, nan, inf, huge integers, ...) must either
//! load and step, or be refused with a one-line error naming the config — never panic or hang.
//!
//! Seeded (ChaCha8, one seed per case) so a failure reproduces; `SUBSTEP_FUZZ_CASES` sets the
//! number of cases (default 2000, a few seconds in release). Every case runs in its own thread
//! with a deadline, so a hang fails the test instead of blocking it.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;
use substep::excitation::{parse_single_column, parse_two_column};
use substep::io::{TestDefinition, parse_matrix_market, parse_matrix_market_sparse};
use substep::run::{Reference, Simulation};

const EXTREMES: &[&str] = &[
    "0",
    "-0.0",
    "1e-300",
    "-1e-300",
    "1e300",
    "1e308",
    "-1e308",
    "nan",
    "inf",
    "-inf",
    "-1",
    "1e9",
    "1000000000",
    "4294967296",
    "9223372036854775807",
    "18446744073709551615",
    "1e-12",
    "2",
];

/// Keys the shipped examples do not use, in two more configs of the same kind. (`ramp_time` of
/// `[substructure.limits]` is left out: its bound is separate work, and a huge one ramps down
/// for ever after a safety stop.)
const EXTRA_CONFIGS: &[(&str, &str)] = &[
    (
        "frame.toml",
        r#"[structure.frame]
bays = 2
stories = 3
bay_width = 6.0
story_height = 3.5
floor_mass_per_bay = 2000.0

[structure.rayleigh]
zeta = 0.03
modes = [1, 3]

[ground_motion]
generator = "sine_sweep"
amplitude = 0.5
f0 = 0.5
f1 = 4.0
duration = 2.0

[integrator]
dt = 0.01

[substructure]
coupling_dofs = [1, 4]
substeps = 3

[[substructure.specimen]]
kind = "bouc_wen"
dof = 1
stiffness = 1.0e6
alpha = 0.1
yield_displacement = 0.01
n = 2.0
pinching = 0.5

[[substructure.specimen]]
kind = "friction"
dof = 4
slip_force = 1000.0
stiffness = 1.0e6

[substructure.actuator]
kind = "first_order"
time_constant = 0.005
delay = 0.002

[substructure.error_force]
kind = "arx"
order = 4
forgetting_factor = 0.98
p0 = 100.0

[substructure.limits]
displacement = 0.5
force = [1e6, 1e6]
"#,
    ),
    (
        "tmd_lag.toml",
        r#"[structure.tmd]
mass = 1000.0
frequency = 1.0
zeta = 0.05
eta_m = 0.05
eta_f = 1.0
zeta_s = 0.1

[ground_motion]
generator = "kanai_tajimi"
pga = 1.5
omega_g = 15.6
zeta_g = 0.6
duration = 2.0
seed = 7

[integrator]
scheme = "newmark"
beta = 0.25
gamma = 0.5
dt = 0.01

[substructure]
coupling_dofs = [2]
substeps = 5
inner_steps = 4

[[substructure.specimen]]
kind = "replay"
dof = 2
values = [0.0, 10.0, 20.0, 10.0]
dt = 0.5
scale = 2.0

[substructure.actuator]
kind = "second_order"
frequency = 40.0
zeta = 0.7
delay = 0.003

[substructure.sensors]
force_noise = 1.0
displacement_noise = 1e-6
adc_bits = 16
force_range = 1e4
displacement_range = 0.1
lowpass_hz = 200.0
seed = 5

[substructure.phase_lag]
kind = "polynomial"
order = 3
lead = 0.003
ramp_start = 2
ramp_steps = 10
fade_out = [150, 20]
"#,
    ),
];

/// Tight limits appended to every case: the estimates are what is exercised, and a case that
/// passes them stays small on a shared machine.
const LIMITS: &str = "\n[limits]\nmax_memory = 2e8\nmax_run_time = 5\nmax_output_bytes = 1e8\n";

/// Steps run of a case that loads.
const STEPS: usize = 5;

fn examples_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples")
}

/// Byte ranges of the numeric literals in values (after `=`, inside arrays), not in keys,
/// strings or comments.
fn numbers(text: &str) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut offset = 0;
    for line in text.split_inclusive('\n') {
        let code = line.split('#').next().unwrap_or("");
        if let Some(eq) = code.find('=')
            && !code.trim_start().starts_with('[')
        {
            let bytes = code.as_bytes();
            let mut i = eq + 1;
            let mut in_string = false;
            while i < bytes.len() {
                let c = bytes[i];
                if c == b'"' {
                    in_string = !in_string;
                }
                let starts = !in_string
                    && (c.is_ascii_digit() || c == b'-' || c == b'+')
                    && (i == 0 || matches!(bytes[i - 1], b' ' | b'=' | b'[' | b','));
                if starts {
                    let j = (i + 1..bytes.len())
                        .find(|&j| !(bytes[j].is_ascii_alphanumeric() || matches!(bytes[j], b'.' | b'-' | b'+' | b'_')))
                        .unwrap_or(bytes.len());
                    out.push((offset + i, offset + j));
                    i = j;
                    continue;
                }
                i += 1;
            }
        }
        offset += line.len();
    }
    out
}

/// The config with 1 to 3 of its numbers replaced by extremes.
fn mutate(text: &str, rng: &mut ChaCha8Rng) -> String {
    let spots = numbers(text);
    let mut picks: Vec<(usize, usize, &str)> = (0..rng.random_range(1..=3))
        .map(|_| {
            let (a, b) = spots[rng.random_range(0..spots.len())];
            (a, b, EXTREMES[rng.random_range(0..EXTREMES.len())])
        })
        .collect();
    picks.sort_by_key(|p| std::cmp::Reverse(p.0));
    picks.dedup_by_key(|p| p.0);
    let mut out = text.to_string();
    for (a, b, v) in picks {
        out.replace_range(a..b, v);
    }
    out
}

/// What a case did: `Ok(None)` loaded and stepped, `Ok(Some(msg))` a refusal or a stop.
fn run_case(text: String, name: String, base: PathBuf) -> Result<Option<String>, String> {
    let outcome = std::panic::catch_unwind(move || -> Option<String> {
        let def = match TestDefinition::from_toml(&text, &name, &base) {
            Ok(d) => d,
            Err(e) => return Some(format!("config: {e}")),
        };
        let mut sim = match Simulation::new(&def) {
            Ok(s) => s,
            Err(e) => return Some(format!("setup: {e}")),
        };
        let mut reference = match Reference::new(&def) {
            Ok(r) => r,
            Err(e) => return Some(format!("setup: {e}")),
        };
        for _ in 0..STEPS.min(sim.steps_total()) {
            let i = sim.steps_done();
            if let Err(e) = sim.step(&mut ()) {
                return Some(e.to_string());
            }
            if let Some(r) = &mut reference
                && let Err(e) = r.step(sim.ground_acceleration(i + 1))
            {
                return Some(e.to_string());
            }
        }
        None
    });
    outcome.map_err(|p| {
        p.downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_default()
    })
}

#[test]
fn mutated_example_configs_never_panic_or_hang() {
    let cases: usize = std::env::var("SUBSTEP_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2000);
    let dir = examples_dir();
    let mut configs: Vec<(String, String)> = std::fs::read_dir(&dir)
        .expect("examples dir")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        // Its 1000-DOF modal analysis takes seconds per case; shear_building_10 has its keys.
        .filter(|p| !p.ends_with("realtime_1000.toml"))
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read_to_string(&p).expect("example"))
        })
        .collect();
    configs.sort();
    assert!(configs.len() >= 5, "the shipped examples are found");
    configs.extend(EXTRA_CONFIGS.iter().map(|(n, t)| (n.to_string(), t.to_string())));
    let (mut refused, mut loaded) = (0, 0);
    for case in 0..cases {
        let mut rng = ChaCha8Rng::seed_from_u64(0x5eed_0000 + case as u64);
        let (name, text) = &configs[case % configs.len()];
        let mutated = mutate(text, &mut rng) + LIMITS;
        let (tx, rx) = mpsc::channel();
        let (t, n, b) = (mutated.clone(), name.clone(), dir.clone());
        std::thread::spawn(move || {
            let _ = tx.send(run_case(t, n, b));
        });
        let started = std::time::Instant::now();
        let result = rx
            .recv_timeout(Duration::from_secs(30))
            .unwrap_or_else(|_| panic!("case {case} ({name}) did not finish within 30 s:\n{mutated}"));
        if std::env::var("SUBSTEP_FUZZ_SLOW").is_ok() && started.elapsed() > Duration::from_millis(300) {
            eprintln!("slow case {case} ({name}) {:?}:\n{mutated}", started.elapsed());
        }
        match result {
            Err(panic) => panic!("case {case} ({name}) panicked: {panic}\n{mutated}"),
            Ok(None) => loaded += 1,
            Ok(Some(msg)) => {
                refused += 1;
                assert!(
                    !msg.is_empty() && !msg.contains('\n'),
                    "case {case} ({name}): not a one-line message: {msg:?}\n{mutated}"
                );
                // A refused config names itself (and the key or the file it read), also when
                // the refusal comes from building the integrator or the reference.
                if let Some(config) = msg.strip_prefix("config: ").or_else(|| msg.strip_prefix("setup: ")) {
                    assert!(
                        config.starts_with(name.as_str()),
                        "case {case} ({name}): the message does not name the config: {msg}\n{mutated}"
                    );
                }
            }
        }
    }
    eprintln!("{cases} cases: {loaded} loaded and stepped, {refused} refused or stopped");
    // The generator must exercise both outcomes, or it tests nothing.
    assert!(
        cases < 20 || (refused > 0 && loaded > 0),
        "refused {refused}, loaded {loaded}"
    );
}

/// Numeric tokens of a data file (any whitespace- or comma-separated field that parses).
fn data_numbers(text: &str) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let bytes = text.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        let sep = |c: u8| c.is_ascii_whitespace() || c == b',';
        if sep(bytes[i]) {
            i += 1;
            continue;
        }
        let j = (i..bytes.len()).find(|&j| sep(bytes[j])).unwrap_or(bytes.len());
        if text[i..j].parse::<f64>().is_ok() {
            out.push((i, j));
        }
        i = j;
    }
    out
}

/// The shipped `.mtx` files and record, with numbers (size lines included) mutated to
/// extremes, lines dropped or repeated: the readers must refuse or accept, never panic, and
/// name the file.
#[test]
fn mutated_matrix_market_files_and_records_never_panic() {
    let cases: usize = std::env::var("SUBSTEP_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2000);
    let dir = examples_dir();
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).expect("example file");
    // The first 200 rows of the record keep a case cheap.
    let record: String = read("ag_sweep.csv").split_inclusive('\n').take(200).collect();
    let files = [
        ("three_story_K.mtx", read("three_story_K.mtx")),
        ("three_story_M.mtx", read("three_story_M.mtx")),
        ("ag_sweep.csv", record),
    ];
    let mut refused = 0;
    for case in 0..cases {
        let mut rng = ChaCha8Rng::seed_from_u64(0xf11e_0000 + case as u64);
        let (name, text) = &files[case % files.len()];
        let spots = data_numbers(text);
        let mut mutated = text.clone();
        let mut picks: Vec<(usize, usize)> = (0..rng.random_range(1..=3))
            .map(|_| spots[rng.random_range(0..spots.len())])
            .collect();
        picks.sort_by_key(|p| std::cmp::Reverse(p.0));
        picks.dedup();
        for (a, b) in picks {
            mutated.replace_range(a..b, EXTREMES[rng.random_range(0..EXTREMES.len())]);
        }
        if rng.random_bool(0.2) {
            let mut lines: Vec<&str> = mutated.lines().collect();
            let k = rng.random_range(0..lines.len());
            if rng.random_bool(0.5) {
                lines.remove(k);
            } else {
                lines.insert(k, lines[k]);
            }
            mutated = lines.join("\n");
        }
        let text = mutated.clone();
        let outcome = std::panic::catch_unwind(|| -> Vec<String> {
            let errors = if name.ends_with(".mtx") {
                vec![
                    parse_matrix_market(&text, name).err(),
                    parse_matrix_market_sparse(&text, name).err(),
                ]
            } else {
                vec![
                    parse_two_column(&text, name).err(),
                    parse_single_column(&text, 0.005, name).err(),
                ]
            };
            errors.into_iter().flatten().map(|e| e.to_string()).collect()
        });
        let messages = outcome.unwrap_or_else(|_| panic!("case {case} ({name}) panicked:\n{mutated}"));
        for m in messages {
            refused += 1;
            assert!(
                m.starts_with(*name) && !m.contains('\n'),
                "case {case} ({name}): {m:?}\n{mutated}"
            );
        }
    }
    assert!(
        cases < 20 || refused > 0,
        "no case was refused: the mutations test nothing"
    );
}

#[test]
fn numbers_are_found_in_values_only() {
    let text = "[a]\nx = 1.5 # 7\nname = \"f2.csv\"\nv = [1, -2e3, 3]\n[b.c2]\n";
    let found: Vec<&str> = numbers(text).iter().map(|&(a, b)| &text[a..b]).collect();
    assert_eq!(found, vec!["1.5", "1", "-2e3", "3"]);
}
