//! docs/config.md documents every key the parser accepts: the key list of each table is taken
//! from the parser itself (an unknown key makes serde list the accepted ones), and each key must
//! appear as `key` in the doc section of that table.

use std::path::Path;
use substep::io::TestDefinition;

/// `(table header as written in a config, kind, heading text of its doc section)`.
const TABLES: &[(&str, Option<&str>, &str)] = &[
    ("[structure]", None, "## `[structure]`"),
    ("[structure.shear_building]", None, "### `[structure.shear_building]`"),
    ("[structure.frame]", None, "### `[structure.frame]`"),
    ("[structure.sdof]", None, "### `[structure.sdof]`"),
    ("[structure.tmd]", None, "### `[structure.tmd]`"),
    ("[structure.rayleigh]", None, "### Damping options"),
    ("[structure.modal]", None, "### Damping options"),
    ("[ground_motion]", None, "## `[ground_motion]`"),
    ("[realtime]", None, "### `[realtime]`"),
    ("[integrator]", None, "## `[integrator]`"),
    ("[substructure]", None, "## `[substructure]`"),
    (
        "[[substructure.specimen]]",
        Some("linear_sdof"),
        "### `[[substructure.specimen]]`",
    ),
    (
        "[[substructure.specimen]]",
        Some("linear_mdof"),
        "### `[[substructure.specimen]]`",
    ),
    (
        "[[substructure.specimen]]",
        Some("bouc_wen"),
        "### `[[substructure.specimen]]`",
    ),
    (
        "[[substructure.specimen]]",
        Some("friction"),
        "### `[[substructure.specimen]]`",
    ),
    (
        "[[substructure.specimen]]",
        Some("replay"),
        "### `[[substructure.specimen]]`",
    ),
    (
        "[substructure.actuator]",
        Some("ideal"),
        "### `[substructure.actuator]`",
    ),
    (
        "[substructure.actuator]",
        Some("delay"),
        "### `[substructure.actuator]`",
    ),
    (
        "[substructure.actuator]",
        Some("first_order"),
        "### `[substructure.actuator]`",
    ),
    (
        "[substructure.actuator]",
        Some("second_order"),
        "### `[substructure.actuator]`",
    ),
    (
        "[substructure.actuator]",
        Some("servo_hydraulic"),
        "### `[substructure.actuator]`",
    ),
    (
        "[substructure.actuator]",
        Some("hydraulic"),
        "### `[substructure.actuator]`",
    ),
    ("[substructure.sensors]", None, "### `[substructure.sensors]`"),
    ("[substructure.delay_ramp]", None, "### `[substructure.delay_ramp]`"),
    (
        "[substructure.error_force]",
        Some("none"),
        "### `[substructure.error_force]`",
    ),
    (
        "[substructure.error_force]",
        Some("pid"),
        "### `[substructure.error_force]`",
    ),
    (
        "[substructure.error_force]",
        Some("arx"),
        "### `[substructure.error_force]`",
    ),
    ("[substructure.phase_lag]", None, "### `[substructure.phase_lag]`"),
    ("[substructure.remote]", None, "### `[substructure.remote]`"),
    ("[substructure.limits]", None, "### `[substructure.limits]`"),
    ("[monitor]", None, "## `[monitor]`"),
    ("[output]", None, "## `[output]`"),
    ("[output.plots]", None, "## `[output]`"),
];

/// The keys the parser accepts in one table, from its unknown-field message.
fn accepted_keys(header: &str, kind: Option<&str>) -> Vec<String> {
    let kind_line = kind.map_or(String::new(), |k| format!("kind = \"{k}\"\n"));
    let text = format!("{header}\n{kind_line}zzz_not_a_key = 1\n");
    let err = match TestDefinition::from_toml(&text, "probe.toml", Path::new(".")) {
        Ok(_) => panic!("{header}: the probe key was accepted"),
        Err(e) => e.to_string(),
    };
    assert!(
        err.contains("unknown field `zzz_not_a_key`"),
        "{header} {kind:?}: {err}"
    );
    if err.contains("there are no fields") {
        return kind.map(|_| vec!["kind".to_string()]).unwrap_or_default();
    }
    let list = err
        .split_once("expected ")
        .map(|(_, rest)| rest.trim_start_matches("one of "))
        .unwrap_or_else(|| panic!("{header}: no key list in {err}"));
    let mut keys: Vec<String> = list
        .split('`')
        .enumerate()
        .filter(|(i, _)| i % 2 == 1)
        .map(|(_, k)| k.to_string())
        .collect();
    if kind.is_some() {
        keys.push("kind".into());
    }
    keys
}

/// The doc text from `heading` to the next heading of the same or a higher level.
fn section<'a>(doc: &'a str, heading: &str) -> &'a str {
    let start = doc
        .find(heading)
        .unwrap_or_else(|| panic!("docs/config.md has no section {heading}"));
    let level = heading.chars().take_while(|&c| c == '#').count();
    let rest = &doc[start + heading.len()..];
    let mut end = rest.len();
    let mut offset = 0;
    for line in rest.split_inclusive('\n') {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if hashes > 0 && hashes <= level && line[hashes..].starts_with(' ') && offset > 0 {
            end = offset;
            break;
        }
        offset += line.len();
    }
    &rest[..end]
}

#[test]
fn every_key_the_parser_accepts_is_documented() {
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/config.md")).unwrap();
    let mut missing = Vec::new();
    let mut total = 0;
    for &(header, kind, heading) in TABLES {
        let text = section(&doc, heading);
        let table = header.trim_matches(|c| c == '[' || c == ']');
        for key in accepted_keys(header, kind) {
            total += 1;
            // A sub-table is documented by its own section, `kind` by the kind column.
            let sub_table =
                doc.contains(&format!("`[{table}.{key}]`")) || doc.contains(&format!("`[[{table}.{key}]]`"));
            let kind_column = key == "kind" && (text.contains("| kind |") || text.contains("`kind`"));
            if !text.contains(&format!("`{key}`")) && !sub_table && !kind_column {
                missing.push(format!("{header} {}: `{key}`", kind.unwrap_or("")));
            }
        }
    }
    assert!(total > 100, "only {total} keys found: the probe is not working");
    assert!(
        missing.is_empty(),
        "keys accepted by the parser but not in docs/config.md:\n{}",
        missing.join("\n")
    );
}

#[test]
fn the_example_site_file_is_valid_and_every_example_config_parses() {
    let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples"));
    let site = substep::io::site_config::SiteDefinition::from_file(dir.join("sites/tmd_site.toml"))
        .expect("examples/sites/tmd_site.toml");
    assert_eq!(site.listen(), "127.0.0.1:8090");
    for name in [
        "default.toml",
        "tmd_substructure.toml",
        "two_specimens.toml",
        "shear_building_10.toml",
    ] {
        TestDefinition::from_file(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    }
}

#[test]
fn type_errors_read_without_rust_type_names() {
    let base = "[structure.sdof]\nmass = 1.0\nstiffness = 1.0\n[ground_motion]\ngenerator = \"harmonic\"\namplitude = 1.0\nfrequency = 1.0\nduration = 1.0\n[integrator]\ndt = 0.01\n[substructure]\ncoupling_dofs = [1]\nsubsteps = SUB\n[[substructure.specimen]]\nkind = \"linear_sdof\"\ndof = 1\nstiffness = 1.0\n";
    for (value, want) in [
        ("2.5", "expected a whole number ≥ 0"),
        ("-1", "expected a whole number ≥ 0"),
        ("\"four\"", "expected a whole number ≥ 0"),
    ] {
        let e = TestDefinition::from_toml(&base.replace("SUB", value), "t.toml", Path::new("."))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("t.toml: line 13: ") && e.contains(want), "{value}: {e}");
        assert!(!e.contains("usize"), "{e}");
    }
    let e = TestDefinition::from_toml(
        &base.replace("SUB", "4").replace("mass = 1.0", "mass = \"heavy\""),
        "t.toml",
        Path::new("."),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("expected a number") && !e.contains("f64"), "{e}");
}
