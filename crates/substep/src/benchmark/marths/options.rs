//! The front ends' options of a maRTHS study (`substep benchmark marths`, `substep.benchmark.marths`)
//! and the JSON object they print: one place for both, files read by the caller.

use super::config::MarthsConfig;
use super::data::Record;
use super::run::{Algorithm, ControllerKind, Criteria, MarthsInput, SubstepSpec, Transfer, round1};
use super::study::Study;
use crate::benchmark::rths::GroundRecord;
use crate::error::{Error, Result};
use serde_json::{Value, json};
use std::sync::Arc;

/// What a front end was given. `record`: a shipped record's name, or `(name, CSV text)`;
/// `config`: `(name, TOML text)`.
#[derive(Debug, Clone)]
pub struct MarthsOptions<'a> {
    pub record: RecordChoice<'a>,
    pub intensity: f64,
    pub controller: &'a str,
    pub trials: usize,
    pub seed: u64,
    pub noise: bool,
    pub ideal: bool,
    pub algorithm: &'a str,
    pub partition_density: Option<f64>,
    pub config: Option<(&'a str, &'a str)>,
}

/// A shipped record by name or a file's text.
#[derive(Debug, Clone, Copy)]
pub enum RecordChoice<'a> {
    Shipped(&'a str),
    File { name: &'a str, text: &'a str },
}

impl Default for MarthsOptions<'_> {
    /// The command's defaults: El Centro × 0.4, RoDeAC, the nominal plant with noise (seed 123),
    /// the toolset's loop.
    fn default() -> Self {
        Self {
            record: RecordChoice::Shipped("elcentro"),
            intensity: 0.4,
            controller: "rodeac",
            trials: 0,
            seed: 123,
            noise: true,
            ideal: false,
            algorithm: "benchmark",
            partition_density: None,
            config: None,
        }
    }
}

/// The shipped record of this name.
pub fn shipped_record(name: &str) -> Option<Record> {
    Record::all().into_iter().find(|r| r.name() == name)
}

/// Whether `--record NAME` names a file for the front end to read: not a shipped record, and a
/// path that exists or has an extension (anything else is refused by [`MarthsOptions::input`]
/// with the list of records).
pub fn names_a_record_file(name: &str) -> bool {
    let path = std::path::Path::new(name);
    shipped_record(name).is_none() && (path.exists() || path.extension().is_some())
}

impl MarthsOptions<'_> {
    /// The input these options describe (checked; `what(name)` spells an option as the front
    /// end does, e.g. `--trials`).
    pub fn input(&self, what: impl Fn(&str) -> String) -> Result<MarthsInput> {
        let record = match self.record {
            RecordChoice::Shipped(name) => shipped_record(name)
                .ok_or_else(|| {
                    Error::invalid(
                        what("record"),
                        format!("unknown record `{name}` (elcentro, kobe, morgan, or a t,a_g CSV file in m/s²)"),
                    )
                })?
                .load(),
            RecordChoice::File { name, text } => GroundRecord::parse_csv(name, text)?,
        };
        let mut input = MarthsInput::new(Arc::new(record));
        input.intensity = self.intensity;
        if let Some(rho) = self.partition_density {
            input.partition_density = rho;
        }
        input.controller = ControllerKind::parse(self.controller)?;
        input.algorithm = match self.algorithm {
            "benchmark" => Algorithm::Benchmark,
            "substep" => Algorithm::Substep(SubstepSpec::default()),
            other => {
                return Err(Error::invalid(
                    what("algorithm"),
                    format!("unknown algorithm `{other}` (benchmark, substep)"),
                ));
            }
        };
        if self.ideal {
            if self.trials > 0 {
                return Err(Error::invalid(
                    what("trials"),
                    "uncertain plants need the plant, not the ideal transfer system",
                ));
            }
            input.transfer = Transfer::Ideal;
        } else if let Transfer::Plant { noise_seed, .. } = &mut input.transfer {
            *noise_seed = self.noise.then_some(self.seed);
        }
        if let Some((name, text)) = self.config {
            let c = MarthsConfig::from_toml(text, name)?;
            if c.plant.is_some() && self.trials > 0 {
                return Err(Error::invalid(
                    what("trials"),
                    "the uncertain plants perturb the toolset's plant: with [plant] in the config use 0 trials",
                ));
            }
            c.apply(&mut input);
        }
        Ok(input)
    }

    /// The object of `substep benchmark marths --json` (see docs/benchmark.md).
    pub fn json(&self, input: &MarthsInput, study: &Study, wall_time_s: f64) -> Value {
        let mut obj = serde_json::Map::new();
        obj.insert("benchmark".into(), json!("maRTHS"));
        obj.insert("record".into(), json!(input.record.name));
        obj.insert("intensity".into(), json!(input.intensity));
        obj.insert("controller".into(), json!(input.controller.name()));
        obj.insert("algorithm".into(), json!(self.algorithm));
        obj.insert("ideal".into(), json!(self.ideal));
        obj.insert("noise".into(), json!(self.noise && !self.ideal));
        obj.insert("seed".into(), json!(self.seed));
        obj.insert("trials".into(), json!(self.trials));
        obj.insert("partition_density".into(), json!(input.partition_density));
        if let Some(c) = study.reported() {
            for (name, v) in c.map(round1).lists() {
                obj.insert(name.into(), json!(v));
            }
            obj.insert("J_raw".into(), criteria_json(&c));
        }
        obj.insert(
            "nominal".into(),
            study.nominal.criteria.as_ref().map_or(Value::Null, criteria_json),
        );
        obj.insert(
            "per_trial".into(),
            json!(
                study
                    .trials
                    .iter()
                    .map(|(_, r)| r.criteria.as_ref().map_or(Value::Null, criteria_json))
                    .collect::<Vec<_>>()
            ),
        );
        obj.insert("realizable".into(), json!(study.realizable()));
        obj.insert(
            "peak_volts".into(),
            json!({
                "nominal": study.nominal.peak_volts,
                "trials": study.trials.iter().map(|(_, r)| r.peak_volts).collect::<Vec<_>>(),
            }),
        );
        let diverged = study.diverged_runs();
        obj.insert("stable".into(), json!(diverged == 0));
        obj.insert("diverged_runs".into(), json!(diverged));
        if let Some(r) = study.first_diverged() {
            obj.insert("stop_reason".into(), json!(r.stop_reason));
        }
        obj.insert("wall_time_s".into(), json!(wall_time_s));
        Value::Object(obj)
    }
}

/// `{"J1": [...], …, "J10": [...]}`.
pub fn criteria_json(c: &Criteria) -> Value {
    let mut m = serde_json::Map::new();
    for (name, v) in c.lists() {
        m.insert(name.into(), json!(v));
    }
    Value::Object(m)
}
