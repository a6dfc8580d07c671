//! Studies. Parameter studies (this module): every variant of a base test definition, run in
//! parallel, one row of metrics per run (docs/theory.md §14, docs/config.md "Study files").
//! Study drivers: a fixed set-up run over a set of methods or parameters, returning typed
//! results (numbers and series); a report module writes their files, front ends print:
//!
//! * [`vst`]: the virtual substructure test study (every compensation method against the exact
//!   reference, docs/vst.md; its files: [`vst::report`]).
//!
//! Parameter studies in detail:
//! A [`Study`] is the base config (parsed TOML), a grid of dotted-key overrides (the cartesian
//! product, first key slowest), optionally `n` seeded random samples per grid point
//! ([`sampling`]) and optionally a list of noise seeds per variant. Run `i` is defined by `i`
//! alone, so any subset of runs (a batch on a cluster node) gives the same rows as the whole
//! study. Each run is independent and deterministic: rows do not depend on the thread count.
//!
//! A run that cannot start (an override key the config does not know, a value it refuses) or
//! that stops (diverges, hits a safety limit) gives a row with `completed = false` and the
//! reason; the other runs go on.

pub mod metrics;
pub mod overrides;
pub mod sampling;
pub mod vst;

use crate::error::{Error, Result};
use crate::io::TestDefinition;
use rayon::prelude::*;
use sampling::{Distribution, Sampled};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use toml::Value;

pub use metrics::Metric;

/// The largest study accepted (rows are kept in memory; a study this large is a cluster job).
pub const MAX_RUNS: usize = 1_000_000;

/// The config key a study's `seeds` set by default (the sensor noise of a virtual test).
pub const DEFAULT_SEED_KEY: &str = "substructure.sensors.seed";

/// A parameter study, validated.
#[derive(Debug, Clone)]
pub struct Study {
    base: Value,
    base_name: String,
    base_dir: PathBuf,
    grid: Vec<(String, Vec<Value>)>,
    samples: Vec<Sampled>,
    n_samples: usize,
    sample_seed: u64,
    seeds: Vec<u64>,
    seed_key: String,
    metrics: Vec<Metric>,
}

/// One run of a study: its index and the values it sets.
#[derive(Debug, Clone, PartialEq)]
pub struct Variant {
    pub index: usize,
    /// `(key, value)` in column order ([`Study::parameters`]).
    pub values: Vec<(String, Value)>,
}

/// The result row of one run.
#[derive(Debug, Clone)]
pub struct Row {
    pub index: usize,
    /// Values of [`Study::parameters`], in that order.
    pub values: Vec<Value>,
    pub completed: bool,
    /// Why the run did not complete (empty when it did).
    pub error: String,
    /// Values of [`Study::metrics`] (NaN where the run has no such quantity).
    pub metrics: Vec<f64>,
    /// The run's summary (when the runner gave one).
    pub summary: Option<serde_json::Value>,
}

/// What a study runs for each variant: the defined test in, its summary (`summary.json`'s
/// content, with `completed` and `reason`) out; an error when the test cannot start.
pub type Runner = dyn Fn(&TestDefinition) -> Result<serde_json::Value> + Sync;

/// Most threads a study runs on (`--threads`, Python's `threads`): a bound on what a typo can
/// spawn.
pub const MAX_THREADS: usize = 256;

/// Records nothing: a study keeps only the summary of each run.
pub(crate) struct SummaryOnly;

impl crate::substructure::SubstepObserver for SummaryOnly {}

impl crate::run::RunObserver for SummaryOnly {
    fn step(&mut self, _row: &crate::run::StepRow<'_>) -> std::ops::ControlFlow<()> {
        std::ops::ControlFlow::Continue(())
    }
}

/// The runner of a study: [`crate::run::execute`], keeping only the summary.
pub fn summary_runner(def: &TestDefinition) -> Result<serde_json::Value> {
    let summary = crate::run::execute(def, &mut SummaryOnly, &std::sync::atomic::AtomicBool::new(false))?;
    serde_json::to_value(&summary).map_err(|e| Error::invalid("summary", e.to_string()))
}

// --- the study file -------------------------------------------------------------------------

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStudy {
    base: Option<String>,
    #[serde(default)]
    grid: toml::Table,
    samples: Option<RawSamples>,
    #[serde(default)]
    seeds: Vec<u64>,
    seed_key: Option<String>,
    #[serde(default)]
    metrics: Vec<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSamples {
    n: usize,
    #[serde(default)]
    seed: u64,
    params: toml::Table,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDistribution {
    dist: String,
    low: Option<f64>,
    high: Option<f64>,
    mean: Option<f64>,
    std: Option<f64>,
    #[serde(default)]
    relative: bool,
}

/// Metrics of a study that names none.
pub const DEFAULT_METRICS: &[&str] = &[
    "max_displacement_error",
    "rms_displacement_error",
    "max_force_error",
    "tracking_delay",
    "tracking_nrms",
    "peak_displacement",
];

impl Study {
    /// Read a study file (TOML): `base` (the test definition, relative to the study file),
    /// `[grid]`, `[samples]`, `seeds`, `seed_key`, `metrics` (docs/config.md "Study files").
    pub fn from_file(path: &Path) -> Result<Self> {
        let name = path.display().to_string();
        let text = crate::limits::read_text(path, crate::limits::CONFIG_MAX_BYTES)?;
        let dir = path.parent().unwrap_or(Path::new(""));
        let raw: RawStudy = toml::from_str(&text).map_err(|e| toml_error(&e, &text, &name))?;
        let base_rel = raw
            .base
            .clone()
            .ok_or_else(|| Error::invalid(format!("{name}: base"), "missing: the test definition to vary"))?;
        let base_path = dir.join(&base_rel);
        let base_text = crate::limits::read_text(&base_path, crate::limits::CONFIG_MAX_BYTES)?;
        let base_name = base_path.display().to_string();
        let base: Value = toml::from_str(&base_text).map_err(|e| toml_error(&e, &base_text, &base_name))?;
        Self::build(
            raw,
            base,
            base_name,
            base_path.parent().unwrap_or(Path::new("")).to_path_buf(),
            &name,
        )
    }

    /// A study of the test definition `base_text` (TOML, named `base_name`, relative paths
    /// against `base_dir`) with the settings of `spec`: a JSON object with the keys of a study
    /// file except `base` (what the Python package passes).
    pub fn from_json(base_text: &str, base_name: &str, base_dir: &Path, spec: &str) -> Result<Self> {
        let raw: RawStudy = serde_json::from_str(spec).map_err(|e| Error::invalid("study", e.to_string()))?;
        let base: Value = toml::from_str(base_text).map_err(|e| Error::file(base_name, flat(e.message())))?;
        Self::build(raw, base, base_name.to_string(), base_dir.to_path_buf(), "study")
    }

    fn build(raw: RawStudy, base: Value, base_name: String, base_dir: PathBuf, name: &str) -> Result<Self> {
        let key = |k: &str| format!("{name}: {k}");
        let mut grid = Vec::new();
        for (k, v) in raw.grid {
            let values = match v {
                Value::Array(a) if !a.is_empty() => a,
                Value::Array(_) => return Err(Error::invalid(key(&format!("grid.{k}")), "needs at least one value")),
                one => vec![one],
            };
            grid.push((k, values));
        }
        let (samples, n_samples, sample_seed) = match raw.samples {
            None => (Vec::new(), 1, 0),
            Some(s) => {
                if s.n == 0 || s.params.is_empty() {
                    return Err(Error::invalid(
                        key("samples"),
                        "needs n >= 1 and at least one entry in samples.params",
                    ));
                }
                let mut params = Vec::new();
                for (k, v) in s.params {
                    let what = key(&format!("samples.params.{k}"));
                    let d: RawDistribution = v
                        .try_into()
                        .map_err(|e: toml::de::Error| Error::invalid(&what, flat(e.message())))?;
                    let distribution = distribution(&d, &what)?;
                    if d.relative {
                        match overrides::get(&base, &k) {
                            Some(Value::Float(_) | Value::Integer(_)) => {}
                            _ => {
                                return Err(Error::invalid(
                                    &what,
                                    format!("relative = true needs a number at `{k}` in the base config"),
                                ));
                            }
                        }
                    }
                    params.push(Sampled {
                        key: k,
                        distribution,
                        relative: d.relative,
                    });
                }
                (params, s.n, s.seed)
            }
        };
        let seed_key = raw.seed_key.unwrap_or_else(|| DEFAULT_SEED_KEY.to_string());
        let names: Vec<&str> = grid
            .iter()
            .map(|(k, _)| k.as_str())
            .chain(samples.iter().map(|s| s.key.as_str()))
            .chain((!raw.seeds.is_empty()).then_some(seed_key.as_str()))
            .collect();
        for (i, k) in names.iter().enumerate() {
            if names[..i].contains(k) {
                return Err(Error::invalid(
                    key(k),
                    "varied twice (grid, samples and seeds set distinct keys)",
                ));
            }
        }
        let metric_names: Vec<String> = if raw.metrics.is_empty() {
            DEFAULT_METRICS.iter().map(|s| s.to_string()).collect()
        } else {
            raw.metrics
        };
        let metrics = metric_names
            .iter()
            .map(|m| Metric::parse(m).map_err(|e| Error::invalid(key("metrics"), e)))
            .collect::<Result<Vec<_>>>()?;
        let study = Self {
            base,
            base_name,
            base_dir,
            grid,
            samples,
            n_samples,
            sample_seed,
            seeds: raw.seeds,
            seed_key,
            metrics,
        };
        let n = study
            .grid_points()
            .checked_mul(study.n_samples)
            .and_then(|x| x.checked_mul(study.seeds.len().max(1)));
        match n {
            Some(n) if n <= MAX_RUNS => {}
            _ => return Err(Error::invalid(name, format!("more than {MAX_RUNS} runs"))),
        }
        // The base must be a test definition by itself: a bad key, or a record or matrix it
        // names that cannot be read, is one refusal here instead of one failed run per variant.
        let text = toml::to_string(&study.base).map_err(|e| Error::invalid(&study.base_name, e.to_string()))?;
        TestDefinition::from_toml(&text, &study.base_name, &study.base_dir)?;
        Ok(study)
    }

    fn grid_points(&self) -> usize {
        self.grid.iter().map(|(_, v)| v.len()).product()
    }

    /// Number of runs: grid points × samples × seeds.
    pub fn len(&self) -> usize {
        self.grid_points() * self.n_samples * self.seeds.len().max(1)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The varied keys, in column order: grid keys, sampled keys, then the seed key.
    pub fn parameters(&self) -> Vec<String> {
        let mut p: Vec<String> = self.grid.iter().map(|(k, _)| k.clone()).collect();
        p.extend(self.samples.iter().map(|s| s.key.clone()));
        if !self.seeds.is_empty() {
            p.push(self.seed_key.clone());
        }
        p
    }

    pub fn metrics(&self) -> &[Metric] {
        &self.metrics
    }

    /// The values run `index` sets (`index < len()`): grid point, sample and seed from the
    /// index (seed fastest, grid's first key slowest).
    pub fn variant(&self, index: usize) -> Result<Variant> {
        if index >= self.len() {
            return Err(Error::invalid(
                "study",
                format!("run {index} does not exist (the study has {})", self.len()),
            ));
        }
        let n_seeds = self.seeds.len().max(1);
        let seed_i = index % n_seeds;
        let sample_i = (index / n_seeds) % self.n_samples;
        let mut grid_i = index / n_seeds / self.n_samples;
        let mut grid_values = vec![Value::Boolean(false); self.grid.len()];
        for (slot, (_, values)) in grid_values.iter_mut().zip(&self.grid).rev() {
            *slot = values[grid_i % values.len()].clone();
            grid_i /= values.len();
        }
        let mut values: Vec<(String, Value)> = self.grid.iter().map(|(k, _)| k.clone()).zip(grid_values).collect();
        if !self.samples.is_empty() {
            let drawn = sampling::sample(self.sample_seed, sample_i, &self.samples);
            for (p, x) in self.samples.iter().zip(drawn) {
                let x = if p.relative {
                    x * overrides::get(&self.base, &p.key).and_then(as_f64).unwrap_or(f64::NAN)
                } else {
                    x
                };
                values.push((p.key.clone(), Value::Float(x)));
            }
        }
        if !self.seeds.is_empty() {
            values.push((self.seed_key.clone(), Value::Integer(self.seeds[seed_i] as i64)));
        }
        Ok(Variant { index, values })
    }

    /// The test definition of a variant. Errors name the run and its overrides.
    pub fn definition(&self, v: &Variant) -> Result<TestDefinition> {
        let label = || label(v);
        let mut config = self.base.clone();
        for (k, x) in &v.values {
            overrides::set(&mut config, k, x.clone())
                .map_err(|e| Error::invalid(format!("run {} {}", v.index, label()), e.to_string()))?;
        }
        let text = toml::to_string(&config).map_err(|e| Error::invalid(format!("run {}", v.index), e.to_string()))?;
        let name = format!("{} (run {})", self.base_name, v.index);
        TestDefinition::from_toml(&text, &name, &self.base_dir)
            .map_err(|e| Error::invalid(format!("run {} {}", v.index, label()), e.to_string()))
    }

    /// Run the variants `indices` with `runner`, on `threads` threads (0: all cores), calling
    /// `done` after each run; rows in the order of `indices`. No run's failure stops the others.
    pub fn run(
        &self,
        indices: &[usize],
        threads: usize,
        runner: &Runner,
        done: &(dyn Fn() + Sync),
    ) -> Result<Vec<Row>> {
        if let Some(&bad) = indices.iter().find(|&&i| i >= self.len()) {
            return Err(Error::invalid(
                "study",
                format!("run {bad} does not exist (the study has {})", self.len()),
            ));
        }
        if threads > MAX_THREADS {
            return Err(Error::invalid(
                "threads",
                format!(
                    "at most {MAX_THREADS} (the runs are computation: more threads than cores do not help), got {threads}"
                ),
            ));
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| Error::invalid("study threads", e.to_string()))?;
        Ok(pool.install(|| {
            indices
                .par_iter()
                .map(|&i| {
                    let row = self.run_one(i, runner);
                    done();
                    row
                })
                .collect()
        }))
    }

    /// Every run of the study ([`run`](Self::run) over `0..len()`).
    pub fn run_all(&self, threads: usize, runner: &Runner, done: &(dyn Fn() + Sync)) -> Result<Vec<Row>> {
        let all: Vec<usize> = (0..self.len()).collect();
        self.run(&all, threads, runner, done)
    }

    fn run_one(&self, index: usize, runner: &Runner) -> Row {
        let failed = |values: Vec<Value>, error: String| Row {
            index,
            values,
            completed: false,
            error,
            metrics: vec![f64::NAN; self.metrics.len()],
            summary: None,
        };
        let v = match self.variant(index) {
            Ok(v) => v,
            Err(e) => return failed(Vec::new(), e.to_string()),
        };
        let values: Vec<Value> = v.values.iter().map(|(_, x)| x.clone()).collect();
        let def = match self.definition(&v) {
            Ok(d) => d,
            Err(e) => return failed(values, e.to_string()),
        };
        // A panic is a bug, but it must not lose the other runs' rows.
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| runner(&def)));
        let summary = match outcome {
            Ok(Ok(s)) => s,
            Ok(Err(e)) => return failed(values, format!("run {index} {}: {e}", label(&v))),
            Err(p) => {
                let msg = p
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| p.downcast_ref::<String>().cloned())
                    .unwrap_or_default();
                return failed(
                    values,
                    format!("run {index} {}: internal error (panic): {msg}", label(&v)),
                );
            }
        };
        let completed = summary
            .get("completed")
            .and_then(serde_json::Value::as_bool)
            .unwrap_or(false);
        let error = if completed {
            String::new()
        } else {
            let reason = summary
                .get("reason")
                .and_then(serde_json::Value::as_str)
                .unwrap_or("did not complete");
            format!("run {index} {}: {reason}", label(&v))
        };
        Row {
            index,
            values,
            completed,
            error,
            // A run that diverged or stopped has no meaningful metrics (docs/config.md): NaN.
            metrics: self
                .metrics
                .iter()
                .map(|m| if completed { m.value(&summary) } else { f64::NAN })
                .collect(),
            summary: Some(summary),
        }
    }
}

/// `[key = value, ...]` of a variant, for messages.
fn label(v: &Variant) -> String {
    let parts: Vec<String> = v.values.iter().map(|(k, x)| format!("{k} = {}", show(x))).collect();
    format!("[{}]", parts.join(", "))
}

/// A value as the study CSV and messages show it.
pub fn show(x: &Value) -> String {
    match x {
        Value::String(s) => s.clone(),
        Value::Float(f) => format!("{f}"),
        other => other.to_string(),
    }
}

fn as_f64(v: &Value) -> Option<f64> {
    match v {
        Value::Float(f) => Some(*f),
        Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

/// `FILE: line L: message` of a TOML syntax or schema error.
fn toml_error(e: &toml::de::Error, text: &str, name: &str) -> Error {
    match e.span() {
        Some(span) => {
            let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
            Error::file(name, format!("line {line}: {}", flat(e.message())))
        }
        None => Error::file(name, flat(e.message())),
    }
}

fn flat(message: &str) -> String {
    message.split_whitespace().collect::<Vec<_>>().join(" ")
}

fn distribution(d: &RawDistribution, what: &str) -> Result<Distribution> {
    let need = |x: Option<f64>, k: &str| x.ok_or_else(|| Error::invalid(what, format!("{} needs `{k}`", d.dist)));
    let dist = match d.dist.as_str() {
        "uniform" => Distribution::Uniform {
            low: need(d.low, "low")?,
            high: need(d.high, "high")?,
        },
        "log_uniform" => Distribution::LogUniform {
            low: need(d.low, "low")?,
            high: need(d.high, "high")?,
        },
        "normal" => Distribution::Normal {
            mean: need(d.mean, "mean")?,
            std: need(d.std, "std")?,
        },
        other => {
            return Err(Error::invalid(
                what,
                format!("unknown distribution `{other}` (expected uniform, normal or log_uniform)"),
            ));
        }
    };
    dist.validate(what)?;
    Ok(dist)
}

/// The study as CSV: `run`, the parameters, `completed`, the metrics, `error`.
pub fn to_csv(study: &Study, rows: &[Row]) -> String {
    let quote = |s: &str| {
        if s.contains([',', '"', '\n']) {
            format!("\"{}\"", s.replace('"', "\"\""))
        } else {
            s.to_string()
        }
    };
    let mut out = String::from("run");
    for p in study.parameters() {
        out.push(',');
        out.push_str(&quote(&p));
    }
    out.push_str(",completed");
    for m in study.metrics() {
        out.push(',');
        out.push_str(&quote(m.name()));
    }
    out.push_str(",error\n");
    for r in rows {
        out.push_str(&r.index.to_string());
        for v in &r.values {
            out.push(',');
            out.push_str(&quote(&show(v)));
        }
        out.push_str(if r.completed { ",true" } else { ",false" });
        for m in &r.metrics {
            out.push(',');
            // Shortest round-trip form, in exponent notation when large or small (`{}` would
            // write 10³⁰⁰ with 301 digits).
            out.push_str(&format!("{m:?}"));
        }
        out.push(',');
        out.push_str(&quote(&r.error.split_whitespace().collect::<Vec<_>>().join(" ")));
        out.push('\n');
    }
    out
}
