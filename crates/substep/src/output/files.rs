//! Output files of `substep run`: `history.csv` and `substeps.csv` (written row by row through
//! a `BufWriter`; the rows and the summary's statistics come from [`crate::run`]), and a
//! decimating recorder that keeps the series for the plots bounded in memory.
//!
//! The output directory: [`prepare_dir`] creates it and removes the files an earlier run wrote
//! there ([`OWNED_OUTPUTS`], nothing else), so no file in it can be mistaken for this run's;
//! small files (`summary.json`, `realtime.json`, plots) are replaced atomically
//! ([`write_atomic`]), so a run killed at any moment leaves either the old or the new file.

use crate::run::StepRow;
use crate::substructure::SubstepObserver;
use std::fmt::Write as _;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;

/// Every file `substep run` (offline or `--realtime`) writes into its output directory. A run
/// removes these (and their temporary files) before it writes anything; other files in the
/// directory are never touched.
pub const OWNED_OUTPUTS: &[&str] = &[
    "history.csv",
    "substeps.csv",
    "summary.json",
    "realtime.json",
    "realtime.txt",
    "response.csv",
    "ground_motion.csv",
    "fourier.csv",
    "spectrum.csv",
    "results.h5",
    "results.mat",
];

/// The figures `substep run` draws (file stems, the names `[output.plots] figures` accepts), each
/// in any of [`FIGURE_EXTENSIONS`]; a run removes all of them as it does [`OWNED_OUTPUTS`].
pub use crate::io::config::PLOT_FIGURES as OWNED_FIGURES;

/// The extensions of the plot formats (`--plot-format`).
pub const FIGURE_EXTENSIONS: &[&str] = &["png", "svg", "pdf"];

/// Every file name a run owns in its output directory.
fn owned_names() -> impl Iterator<Item = String> {
    OWNED_OUTPUTS.iter().map(|s| s.to_string()).chain(
        OWNED_FIGURES
            .iter()
            .flat_map(|f| FIGURE_EXTENSIONS.iter().map(move |e| format!("{f}.{e}"))),
    )
}

pub use crate::atomic_file::{replace_atomic, temp_path, write_atomic};

/// Create the output directory `dir` and remove what an earlier run left in it (the files of
/// [`OWNED_OUTPUTS`], [`OWNED_FIGURES`] and their temporary files). Errors are bad input (exit code 2): the
/// directory cannot be created, a name is taken by something that is not a file, or a stale
/// output cannot be removed.
pub fn prepare_dir(dir: &Path) -> crate::Result<()> {
    let name = dir.display().to_string();
    std::fs::create_dir_all(dir)
        .map_err(|e| crate::Error::file(&name, format!("cannot create the output directory: {e}")))?;
    for owned in owned_names() {
        let path = dir.join(owned);
        for p in [temp_path(&path), path] {
            let Ok(meta) = std::fs::symlink_metadata(&p) else {
                continue;
            };
            let shown = p.display().to_string();
            if meta.is_dir() {
                return Err(crate::Error::file(
                    shown,
                    "is a directory, but substep writes a file of that name here (choose another --out)",
                ));
            }
            std::fs::remove_file(&p)
                .map_err(|e| crate::Error::file(shown, format!("cannot remove this output of an earlier run: {e}")))?;
        }
    }
    Ok(())
}

/// A number for CSV: shortest round-trip form, exponent notation for very small or large values.
pub use crate::run::push_number as num;

fn row_group(out: &mut String, values: &[f64]) {
    for &x in values {
        out.push(',');
        num(out, x);
    }
}

/// `history.csv`: one row per step from `t = 0`.
pub struct HistoryWriter {
    w: BufWriter<File>,
    line: String,
}

impl HistoryWriter {
    /// A file with the header `columns` ([`crate::run::Layout::history_columns`]).
    pub fn create(path: &Path, columns: &[String]) -> io::Result<Self> {
        let mut w = BufWriter::new(File::create(path)?);
        let mut line = columns.join(",");
        line.push('\n');
        w.write_all(line.as_bytes())?;
        Ok(Self { w, line })
    }

    pub fn row(&mut self, row: &StepRow<'_>) -> io::Result<()> {
        let line = &mut self.line;
        line.clear();
        for (i, x) in row.history_values().enumerate() {
            if i > 0 {
                line.push(',');
            }
            num(line, x);
        }
        line.push('\n');
        self.w.write_all(line.as_bytes())
    }

    /// Push buffered rows to the file (crash safety: the run loop calls this every ~0.5 s).
    pub fn flush(&mut self) -> io::Result<()> {
        self.w.flush()
    }

    pub fn finish(mut self) -> io::Result<()> {
        self.w.flush()
    }
}

/// `substeps.csv`: `step, substep, t, cmd.., fm.., dm..` for every sub-step, with phase-lag
/// compensation also `te.., du..` (tracking error and correction, from
/// [`SubstepObserver::phase_lag`]), against a lab target `held, strays` (from
/// [`SubstepObserver::lab`]), with safety limits a last column `ramp`: 0 for the
/// algorithm's sub-steps, `s = 1, 2, ...` for the ramp to the safe position after a stop
/// ([`SubstepObserver::ramp`]; `te`, `du` are NaN there). Write errors are kept and reported
/// by [`SubstepWriter::finish`] (the observer interface cannot return them).
pub struct SubstepWriter {
    w: BufWriter<File>,
    line: String,
    dt: f64,
    dtau: f64,
    error: Option<io::Error>,
    /// Tracking error and correction of the current sub-step (phase-lag runs).
    phase_lag: Option<(Vec<f64>, Vec<f64>)>,
    /// `held`, `strays` of the current sub-step (lab-target runs).
    lab: Option<(bool, u64)>,
    /// The `ramp` column is written (runs with safety limits).
    ramp_column: bool,
    ramp_rows: usize,
}

impl SubstepWriter {
    /// A file with the header [`crate::run::Layout::substep_columns`] (an error for a monolithic layout).
    pub fn create(path: &Path, layout: &crate::run::Layout) -> io::Result<Self> {
        let (Some(columns), Some(substeps)) = (layout.substep_columns(), layout.substeps) else {
            return Err(io::Error::other("a monolithic run has no sub-step rows"));
        };
        let mut w = BufWriter::new(File::create(path)?);
        let mut line = columns.join(",");
        line.push('\n');
        w.write_all(line.as_bytes())?;
        let n_c = layout.coupling_dofs.len();
        Ok(Self {
            w,
            line,
            dt: layout.dt,
            dtau: layout.dt / substeps as f64,
            error: None,
            phase_lag: layout.phase_lag.then(|| (vec![0.0; n_c], vec![0.0; n_c])),
            lab: layout.lab.then_some((false, 0)),
            ramp_column: layout.ramp_column,
            ramp_rows: 0,
        })
    }

    /// Ramp sub-steps written after a safety stop.
    pub fn ramp_rows(&self) -> usize {
        self.ramp_rows
    }

    /// One row; `ramp`: 0 for an algorithm sub-step, else the ramp sub-step.
    fn write_row(&mut self, step: usize, j: usize, ramp: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        if self.error.is_some() {
            return;
        }
        let line = &mut self.line;
        line.clear();
        let _ = write!(line, "{step},{j},");
        num(
            line,
            crate::run::round_time(step.saturating_sub(1) as f64 * self.dt + j as f64 * self.dtau),
        );
        row_group(line, command);
        row_group(line, force);
        row_group(line, displacement);
        if let Some((te, du)) = &self.phase_lag {
            if ramp == 0 {
                row_group(line, te);
                row_group(line, du);
            } else {
                for _ in 0..te.len() + du.len() {
                    line.push_str(",NaN");
                }
            }
        }
        if let Some((held, strays)) = self.lab {
            if ramp == 0 {
                let _ = write!(line, ",{},{strays}", u8::from(held));
            } else {
                line.push_str(",NaN,NaN");
            }
        }
        if self.ramp_column {
            let _ = write!(line, ",{ramp}");
        }
        line.push('\n');
        if let Err(e) = self.w.write_all(line.as_bytes()) {
            self.error = Some(e);
        }
    }

    pub fn flush(&mut self) -> io::Result<()> {
        match self.error.take() {
            Some(e) => Err(e),
            None => self.w.flush(),
        }
    }

    pub fn finish(mut self) -> io::Result<()> {
        match self.error.take() {
            Some(e) => Err(e),
            None => self.w.flush(),
        }
    }
}

impl SubstepObserver for SubstepWriter {
    fn lab(&mut self, held: bool, strays: u64) {
        if let Some(l) = &mut self.lab {
            *l = (held, strays);
        }
    }
    fn phase_lag(&mut self, tracking_error: &[f64], correction: &[f64]) {
        if let Some((te, du)) = &mut self.phase_lag {
            te.copy_from_slice(tracking_error);
            du.copy_from_slice(correction);
        }
    }
    fn substep(&mut self, step: usize, j: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.write_row(step, j, 0, command, force, displacement);
    }
    fn ramp(&mut self, step: usize, j: usize, s: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.ramp_rows += 1;
        self.write_row(step, j, s, command, force, displacement);
    }
}

/// Rows of numbers recorded with a growing stride so that at most `cap` rows are kept: when
/// the table is full, every second row is dropped and the stride doubles.
pub struct Decimated {
    pub width: usize,
    pub data: Vec<f64>,
    cap: usize,
    stride: usize,
    seen: usize,
}

impl Decimated {
    pub fn new(width: usize, cap: usize) -> Self {
        Self {
            width,
            data: Vec::with_capacity(width * cap),
            cap: cap.max(2),
            stride: 1,
            seen: 0,
        }
    }
    pub fn push(&mut self, row: &[f64]) {
        debug_assert_eq!(row.len(), self.width);
        if self.seen.is_multiple_of(self.stride) {
            if self.rows() == self.cap {
                let w = self.width;
                let kept: Vec<f64> = self.data.chunks(w).step_by(2).flatten().copied().collect();
                self.data = kept;
                self.stride *= 2;
            }
            if self.seen.is_multiple_of(self.stride) {
                self.data.extend_from_slice(row);
            }
        }
        self.seen += 1;
    }
    pub fn rows(&self) -> usize {
        self.data.len() / self.width.max(1)
    }
    /// Column `c` as a vector.
    pub fn column(&self, c: usize) -> Vec<f64> {
        self.data.chunks(self.width).map(|r| r[c]).collect()
    }
}

/// After a run that ended with `result`: a `summary.json` that still says "running" (an error
/// — a write error, a full disk — ended the run before its summary was written) is replaced by
/// one that says it failed and why, or removed when even that cannot be written. A summary never
/// keeps saying "running" once the process has ended on its own (only a killed run leaves it).
pub fn no_summary_left_running<T, E: std::fmt::Display>(path: &Path, result: Result<T, E>) -> Result<T, E> {
    let Err(e) = &result else {
        return result;
    };
    let Ok(text) = crate::io::limits::read_text(path, 1024.0 * 1024.0) else {
        return result;
    };
    let Ok(mut v) = serde_json::from_str::<serde_json::Value>(&text) else {
        return result;
    };
    let running = v["status"].as_str().is_some_and(|s| s.starts_with("running"));
    if !running {
        return result;
    }
    let reason = format!("{e:#}").split_whitespace().collect::<Vec<_>>().join(" ");
    if let Some(obj) = v.as_object_mut() {
        obj.insert("completed".into(), false.into());
        obj.insert(
            "status".into(),
            "failed: the run ended with an error before its summary was written".into(),
        );
        obj.insert("reason".into(), reason.into());
    }
    let json = serde_json::to_string_pretty(&v).unwrap_or_default() + "\n";
    if write_atomic(path, json.as_bytes()).is_err() {
        let _ = std::fs::remove_file(path);
    }
    result
}

/// A write error naming the file.
pub fn cannot_write(path: &Path, e: impl std::fmt::Display) -> crate::Error {
    crate::Error::write(path, e)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run that ended with an error while its summary said "running" leaves a summary that
    /// says it failed and why; a finished summary and a successful run are left alone.
    #[test]
    fn a_failed_run_never_leaves_a_running_summary() {
        let dir = std::env::temp_dir().join(format!("substep-running-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("summary.json");
        let running =
            "{\"config\": \"c.toml\", \"completed\": false, \"status\": \"running (a run that was killed ...)\"}\n";
        std::fs::write(&path, running).unwrap();
        let r = no_summary_left_running(&path, Err::<(), _>("cannot write history.csv: No space left on device"));
        assert!(r.is_err());
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        assert_eq!(v["completed"], false);
        assert_eq!(v["config"], "c.toml");
        assert!(v["status"].as_str().unwrap().starts_with("failed"), "{v}");
        assert_eq!(v["reason"], "cannot write history.csv: No space left on device");
        // success, or a summary already final: untouched
        std::fs::write(&path, running).unwrap();
        no_summary_left_running(&path, Ok::<(), String>(())).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), running);
        let done = "{\"completed\": false, \"reason\": \"diverged\"}\n";
        std::fs::write(&path, done).unwrap();
        let _ = no_summary_left_running(&path, Err::<(), _>("diverged"));
        assert_eq!(std::fs::read_to_string(&path).unwrap(), done);
        // when the replacement cannot be written, the lying summary goes: a directory in the
        // way of the temporary file stands in for a full disk
        std::fs::write(&path, running).unwrap();
        std::fs::create_dir_all(temp_path(&path)).unwrap();
        let _ = no_summary_left_running(&path, Err::<(), _>("disk full"));
        assert!(!path.exists(), "a summary that cannot be corrected is removed");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn decimation_keeps_a_regular_grid() {
        let mut d = Decimated::new(1, 8);
        for i in 0..100 {
            d.push(&[i as f64]);
        }
        let c = d.column(0);
        assert!(c.len() <= 8);
        let step = c[1] - c[0];
        assert!(c.windows(2).all(|w| w[1] - w[0] == step), "{c:?}");
        assert_eq!(c[0], 0.0);
    }

    #[test]
    fn an_interrupted_replacement_leaves_the_old_file() {
        let dir = std::env::temp_dir().join(format!("substep-atomic-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("summary.json");
        write_atomic(&path, b"{\"completed\": true}\n").unwrap();
        // The writer dies half-way (as a killed process or a full disk would leave it).
        let err = replace_atomic(&path, |tmp| {
            std::fs::write(tmp, b"{\"compl")?;
            Err(io::Error::other("disk full"))
        })
        .unwrap_err();
        assert_eq!(err.to_string(), "disk full");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "{\"completed\": true}\n");
        assert!(!temp_path(&path).exists());
        // Until the rename, readers see the old file; then the new one.
        replace_atomic(&path, |tmp| {
            std::fs::write(tmp, b"{\"completed\": false}\n")?;
            assert_eq!(std::fs::read_to_string(&path)?, "{\"completed\": true}\n");
            Ok(())
        })
        .unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "{\"completed\": false}\n");
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["summary.json"]);
        assert_eq!(temp_path(Path::new("out/a.png")), Path::new("out/.a.tmp.png"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn number_format_round_trips() {
        for x in [0.0, 1.5, -2.25e-9, 3.0e12, 0.1 + 0.2] {
            let mut s = String::new();
            num(&mut s, x);
            assert_eq!(s.parse::<f64>().unwrap(), x, "{s}");
        }
    }
}
