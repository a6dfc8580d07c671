//! What a front end asks of the benchmark study (the flags of `substep benchmark rths`, the
//! arguments of `substep.benchmark.rths`), checked and turned into a [`StudySetup`]; and the
//! study's results as the JSON object both front ends give. Files are read by the front end:
//! here they arrive as `(name, text)`.

use super::{
    Algorithm, BenchmarkConfig, Case, ControllerKind, GroundRecord, MAX_PERTURBED, RthsInput, RthsResult, RthsRow,
    SubstepSpec, Transfer, perturbed_stats, run_study,
};
use crate::error::{Error, Result};
use crate::transfer::servo::ServoParams;
use serde_json::{Map, Value, json};
use std::sync::Arc;

/// The options of one study. Errors name an option by its front end's spelling:
/// [`StudyOptions::setup`] takes the spelling of each (`"k_sub"` → `--k-sub` for the CLI).
#[derive(Debug, Clone)]
pub struct StudyOptions<'a> {
    /// Reference structure 1..4 (`None`: all four).
    pub case: Option<u8>,
    /// A two-column `t, a_g` CSV as `(name, text)` (`None`: the shipped El Centro record).
    pub record: Option<(&'a str, &'a str)>,
    /// Scale of the record (`eq_intensity`).
    pub intensity: f64,
    /// Tracking controller (`None`: the config's, else `sample`).
    pub controller: Option<&'a str>,
    /// A settings file (TOML, docs/benchmark.md) as `(name, text)`.
    pub config: Option<(&'a str, &'a str)>,
    /// `benchmark` (the original loop) or `substep`.
    pub algorithm: &'a str,
    /// Perturbed plants per case.
    pub perturbed: Option<usize>,
    /// Seed of the plant perturbations.
    pub seed: u64,
    /// With `substep`: the `k_sub` values to run (empty: the config's).
    pub k_sub: &'a [usize],
}

/// A checked study: the cases × `k_sub` rows to run from `base`.
#[derive(Debug, Clone)]
pub struct StudySetup {
    pub cases: Vec<Case>,
    pub base: RthsInput,
    pub k_subs: Vec<Option<usize>>,
    pub kind: ControllerKind,
    pub perturbed: Option<usize>,
    pub seed: u64,
}

impl StudyOptions<'_> {
    /// Check every option; `name` spells an option (given as `case`, `intensity`, `controller`,
    /// `algorithm`, `k_sub`, `perturbed`) in the front end's errors.
    pub fn setup(&self, name: impl Fn(&str) -> String) -> Result<StudySetup> {
        let cases = match self.case {
            Some(c) => {
                vec![Case::new(c).map_err(|e| Error::invalid(name("case"), e.to_string().replace("case: ", "")))?]
            }
            None => Case::all().to_vec(),
        };
        if !(self.intensity.is_finite() && self.intensity >= 0.0) {
            return Err(Error::invalid(
                name("intensity"),
                format!("must be a finite number >= 0, got {}", self.intensity),
            ));
        }
        let record = match self.record {
            Some((n, text)) => GroundRecord::parse_csv(n, text)?,
            None => GroundRecord::elcentro(),
        };
        let config = match self.config {
            Some((n, text)) => BenchmarkConfig::parse(text, n)?,
            None => BenchmarkConfig::default(),
        };
        let kind = match self.controller {
            Some(k) => Some(
                ControllerKind::parse(k)
                    .map_err(|e| Error::invalid(name("controller"), e.to_string().replace("controller: ", "")))?,
            ),
            None => config.kind()?,
        };
        let controller = config.controller(kind)?;
        let kind = controller.kind;
        if kind == ControllerKind::InverseFir {
            return Err(Error::invalid(name("controller"), super::INVERSE_FIR_REFUSED));
        }
        let (noise, noise_seed) = config.noise()?;
        let algorithm = match self.algorithm {
            "benchmark" => Algorithm::Benchmark,
            "substep" => Algorithm::Substep(config.substep()?),
            other => {
                return Err(Error::invalid(
                    name("algorithm"),
                    format!("unknown `{other}` (benchmark, substep)"),
                ));
            }
        };
        let k_subs = if self.k_sub.is_empty() {
            vec![None]
        } else {
            let Algorithm::Substep(spec) = &algorithm else {
                return Err(Error::invalid(
                    name("k_sub"),
                    format!(
                        "applies to the sub-step algorithm only; set {} to substep",
                        name("algorithm")
                    ),
                ));
            };
            for &k in self.k_sub {
                SubstepSpec {
                    k_sub: k,
                    ..spec.clone()
                }
                .samples_per_step()
                .map_err(|e| Error::invalid(name("k_sub"), e.to_string()))?;
            }
            self.k_sub.iter().map(|&k| Some(k)).collect()
        };
        if let Some(n) = self.perturbed
            && !(1..=MAX_PERTURBED).contains(&n)
        {
            return Err(Error::invalid(
                name("perturbed"),
                format!("must be in 1..={MAX_PERTURBED}, got {n}"),
            ));
        }
        let base = RthsInput {
            case: cases[0],
            record: Arc::new(record),
            intensity: self.intensity,
            controller,
            transfer: if config.ideal_plant()? {
                Transfer::Ideal
            } else {
                Transfer::Plant {
                    params: ServoParams::benchmark(),
                    derivative: config.derivative()?,
                }
            },
            noise,
            noise_seed,
            algorithm,
            keep_history: false,
        };
        Ok(StudySetup {
            cases,
            base,
            k_subs,
            kind,
            perturbed: self.perturbed,
            seed: self.seed,
        })
    }
}

impl StudySetup {
    /// Every row ([`run_study`]).
    pub fn run(&self) -> Result<Vec<RthsRow>> {
        run_study(&self.base, &self.cases, &self.k_subs, self.perturbed, self.seed)
    }

    /// The object of `substep benchmark rths --json`: the settings, one object per row in
    /// `cases` (`case`, `k_sub`, `J1`..`J9` (null if diverged), `max_force`, `stable`,
    /// `capacity_exceeded`, `diverged_at`/`guard_trip` when they apply, `perturbed` with the
    /// statistics and every run), and with a single row its fields at the top level too.
    pub fn json(&self, rows: &[RthsRow]) -> Value {
        let mut obj = Map::new();
        obj.insert("benchmark".into(), json!("rths"));
        obj.insert("controller".into(), json!(self.kind.name()));
        obj.insert("record".into(), json!(self.base.record.name));
        obj.insert("intensity".into(), json!(self.base.intensity));
        obj.insert(
            "algorithm".into(),
            json!(match self.base.algorithm {
                Algorithm::Benchmark => "benchmark",
                Algorithm::Substep(_) => "substep",
            }),
        );
        if let Algorithm::Substep(sp) = &self.base.algorithm {
            obj.insert("dt".into(), json!(sp.dt));
            obj.insert("error_force".into(), json!(sp.error_force.kind()));
        }
        if self.perturbed.is_some() {
            obj.insert("seed".into(), json!(self.seed));
        }
        let cases: Vec<Value> = rows.iter().map(row_json).collect();
        if let [Value::Object(only)] = cases.as_slice() {
            for (k, v) in only {
                obj.insert(k.clone(), v.clone());
            }
        }
        obj.insert("cases".into(), Value::Array(cases));
        Value::Object(obj)
    }
}

fn j_json(r: &RthsResult, obj: &mut Map<String, Value>) {
    for i in 0..9 {
        obj.insert(format!("J{}", i + 1), r.criteria.map_or(Value::Null, |c| json!(c.j[i])));
    }
    // Unrounded, for comparisons with the traces (`--out`) or another implementation.
    obj.insert("J_raw".into(), r.criteria.map_or(Value::Null, |c| json!(c.raw)));
    obj.insert("max_force".into(), json!(r.max_force));
    obj.insert("stable".into(), json!(r.stable));
    obj.insert("capacity_exceeded".into(), json!(r.capacity_exceeded));
    if let Some(t) = r.diverged_at {
        obj.insert("diverged_at".into(), json!(t));
    }
    if let Some(g) = &r.guard_trip {
        obj.insert("guard_trip".into(), json!(g));
    }
    let warnings = r.warnings();
    if !warnings.is_empty() {
        obj.insert("warnings".into(), json!(warnings));
    }
}

fn num_or_null(v: f64) -> Value {
    if v.is_finite() {
        json!((v * 100.0).round() / 100.0)
    } else {
        Value::Null
    }
}

fn row_json(row: &RthsRow) -> Value {
    let mut obj = Map::new();
    obj.insert("case".into(), json!(row.case));
    if let Some(k) = row.k_sub {
        obj.insert("k_sub".into(), json!(k));
    }
    j_json(&row.nominal, &mut obj);
    if !row.perturbed.is_empty() {
        let runs: Vec<Value> = row
            .perturbed
            .iter()
            .enumerate()
            .map(|(i, (p, r))| {
                let mut o = Map::new();
                o.insert("run".into(), json!(i));
                o.insert("k_e".into(), json!(p.k_e));
                o.insert("beta1".into(), json!(p.beta1));
                o.insert("beta2".into(), json!(p.beta2));
                o.insert("a3".into(), json!(p.a3));
                j_json(r, &mut o);
                Value::Object(o)
            })
            .collect();
        let st = perturbed_stats(&row.perturbed);
        let named = |v: &[f64; 9]| -> Value {
            Value::Object((0..9).map(|i| (format!("J{}", i + 1), num_or_null(v[i]))).collect())
        };
        obj.insert(
            "perturbed".into(),
            json!({
                "n": row.perturbed.len(),
                "stable": st.stable,
                "under_capacity": st.under_capacity,
                "mean": named(&st.mean),
                "max": named(&st.max),
                "max_force": st.max_force,
                "runs": runs,
            }),
        );
    }
    Value::Object(obj)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1 s, 2 Hz sine (the benchmark's El Centro record is 50 s).
    fn sine() -> String {
        (0..=200)
            .map(|i| {
                let t = i as f64 * 0.005;
                format!("{t},{}\n", (2.0 * std::f64::consts::PI * 2.0 * t).sin())
            })
            .collect()
    }

    fn options<'a>(record: &'a str, k_sub: &'a [usize]) -> StudyOptions<'a> {
        StudyOptions {
            case: Some(1),
            record: Some(("sine", record)),
            intensity: 0.4,
            controller: None,
            config: None,
            algorithm: "benchmark",
            perturbed: Some(3),
            seed: 5,
            k_sub,
        }
    }

    #[test]
    fn the_json_holds_every_perturbed_run_and_their_statistics() {
        let rec = sine();
        let setup = options(&rec, &[]).setup(|n| n.to_string()).unwrap();
        let rows = setup.run().unwrap();
        let v = setup.json(&rows);
        assert_eq!(v["seed"], 5);
        assert_eq!(v["record"], "sine");
        assert_eq!(v["cases"].as_array().unwrap().len(), 1);
        // One row: its fields at the top level too.
        assert_eq!(v["J4"], v["cases"][0]["J4"]);
        let p = &v["cases"][0]["perturbed"];
        let runs = p["runs"].as_array().unwrap();
        assert_eq!((p["n"].as_u64(), runs.len()), (Some(3), 3));
        let stable: Vec<f64> = runs
            .iter()
            .filter(|r| r["stable"] == true)
            .map(|r| r["J4"].as_f64().unwrap())
            .collect();
        assert_eq!(p["stable"].as_u64(), Some(stable.len() as u64));
        assert!(!stable.is_empty());
        let mean = stable.iter().sum::<f64>() / stable.len() as f64;
        assert!((p["mean"]["J4"].as_f64().unwrap() - mean).abs() <= 0.005, "{p}");
        // The plants are the perturbed ones of this seed, not the nominal.
        let k_e: Vec<f64> = runs.iter().map(|r| r["k_e"].as_f64().unwrap()).collect();
        assert!(k_e.iter().all(|&k| k != ServoParams::benchmark().k_e), "{k_e:?}");
    }

    #[test]
    fn errors_name_the_option_as_the_front_end_spells_it() {
        let rec = sine();
        let cli = |n: &str| format!("--{}", n.replace('_', "-"));
        let err = |o: StudyOptions| o.setup(cli).unwrap_err().to_string();
        assert_eq!(
            err(options(&rec, &[4])),
            "--k-sub: applies to the sub-step algorithm only; set --algorithm to substep"
        );
        assert_eq!(
            err(StudyOptions {
                perturbed: Some(0),
                ..options(&rec, &[])
            }),
            "--perturbed: must be in 1..=10000, got 0"
        );
        assert_eq!(
            err(StudyOptions {
                algorithm: "fast",
                ..options(&rec, &[])
            }),
            "--algorithm: unknown `fast` (benchmark, substep)"
        );
        assert!(
            err(StudyOptions {
                case: Some(9),
                ..options(&rec, &[])
            })
            .starts_with("--case: unknown case 9")
        );
        assert!(
            err(StudyOptions {
                record: Some(("bad.csv", "t,a\n0,x\n")),
                ..options(&rec, &[])
            })
            .starts_with("bad.csv")
        );
    }
}
