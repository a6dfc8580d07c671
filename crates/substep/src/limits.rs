//! What one run may ask of the machine: memory, computing time, output volume and input file
//! size (`[limits]` in a test definition, documented in `docs/limits.md`).
//!
//! Every size and duration derived from input is estimated from the config alone and checked
//! here *before* anything is allocated, read or run, so that a typo such as `stories = 1e9`
//! is refused in microseconds with one line that says what was asked, the estimate and the key
//! to raise, instead of exhausting the machine. The estimates are deliberately simple cost
//! models (calibrated on the development VM, see `docs/limits.md`); they err on the high side.
//!
//! Input files are read through [`read_text`]: only regular files (a device such as
//! `/dev/zero` or a FIFO would never end or never start), opened non-blocking, and at most
//! `max_file_bytes` of them.

use crate::error::{Error, Result};
use std::io::Read;
use std::path::Path;

const GIB: f64 = 1024.0 * 1024.0 * 1024.0;
const MIB: f64 = 1024.0 * 1024.0;

/// Limits of one run; [`Limits::default`] is what a config without `[limits]` gets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Estimated memory of the model, the excitation and the buffers [bytes].
    pub max_memory: f64,
    /// Estimated computing time of the whole run \[s\].
    pub max_run_time: f64,
    /// Estimated size of `history.csv` plus `substeps.csv` [bytes].
    pub max_output_bytes: f64,
    /// Size of any one input file (config, `.mtx`, record) [bytes].
    pub max_file_bytes: f64,
    /// Numbers in one record file (ground motion, replayed forces; a time and a value each
    /// count), counted while the file is scanned, before it is read into memory.
    pub max_record_values: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_memory: 4.0 * GIB,
            max_run_time: 3600.0,
            max_output_bytes: 4.0 * GIB,
            max_file_bytes: 256.0 * MIB,
            max_record_values: 2.0e7,
        }
    }
}

/// Largest test-definition file: its `[limits]` are inside it, so this one is fixed. Inline
/// matrices of a few hundred DOFs take well under a MiB; large models belong in `.mtx` files.
pub const CONFIG_MAX_BYTES: f64 = 16.0 * MIB;

/// `1.5 GiB`, `320 MiB`, `12 KiB`, `800 B`; exponent form beyond PiB (absurd requests).
pub fn bytes(b: f64) -> String {
    let units = [
        ("PiB", GIB * 1024.0 * 1024.0),
        ("TiB", GIB * 1024.0),
        ("GiB", GIB),
        ("MiB", MIB),
        ("KiB", 1024.0),
    ];
    if !b.is_finite() {
        return "an unbounded amount".into();
    }
    if b >= 1024.0 * units[0].1 {
        return format!("{b:.2e} B");
    }
    for (name, size) in units {
        if b >= size {
            return format!("{:.1} {name}", b / size);
        }
    }
    format!("{b:.0} B")
}

/// A count or a value of a message: plain up to 10¹⁵ (`2000`, `0.01`), exponent form beyond
/// or for tiny values (`1.000e300`), so an absurd request does not print 300 digits.
pub fn number(x: f64) -> String {
    if x == 0.0 || (x.abs() >= 1e-4 && x.abs() < 1e15) || !x.is_finite() {
        format!("{x}")
    } else {
        format!("{x:.3e}")
    }
}

/// `42 s`, `2.5 h`, `3.1 days`, `1.2e9 years`.
pub fn duration(s: f64) -> String {
    const DAY: f64 = 86_400.0;
    const YEAR: f64 = 365.25 * DAY;
    if !s.is_finite() {
        return format!("{s} s");
    }
    if s < 120.0 {
        format!("{s:.2} s")
    } else if s < 2.0 * 3600.0 {
        format!("{:.1} min", s / 60.0)
    } else if s < 2.0 * DAY {
        format!("{:.1} h", s / 3600.0)
    } else if s < YEAR {
        format!("{:.1} days", s / DAY)
    } else {
        format!("{:.2e} years", s / YEAR)
    }
}

impl Limits {
    /// Refuse `estimate` bytes of memory for `asked` (what the config asked for, in words).
    pub fn check_memory(&self, what: &str, asked: &str, estimate: f64) -> Result<()> {
        if estimate.is_finite() && estimate <= self.max_memory {
            return Ok(());
        }
        Err(Error::invalid(
            what,
            format!(
                "{asked} needs about {} of memory (estimate), more than limits.max_memory = {}; \
                 set [limits] max_memory (bytes) to allow it",
                bytes(estimate),
                bytes(self.max_memory)
            ),
        ))
    }

    /// Refuse `estimate` seconds of computation for `asked`.
    pub fn check_run_time(&self, what: &str, asked: &str, estimate: f64) -> Result<()> {
        if estimate.is_finite() && estimate <= self.max_run_time {
            return Ok(());
        }
        Err(Error::invalid(
            what,
            format!(
                "{asked} needs about {} of computation (estimate), more than limits.max_run_time = {}; \
                 set [limits] max_run_time (s) to allow it",
                duration(estimate),
                duration(self.max_run_time)
            ),
        ))
    }

    /// Refuse `estimate` bytes of output files for `asked`.
    pub fn check_output(&self, what: &str, asked: &str, estimate: f64) -> Result<()> {
        if estimate.is_finite() && estimate <= self.max_output_bytes {
            return Ok(());
        }
        Err(Error::invalid(
            what,
            format!(
                "{asked} writes about {} of history.csv and substeps.csv (estimate), more than \
                 limits.max_output_bytes = {}; set [limits] max_output_bytes (bytes) to allow it",
                bytes(estimate),
                bytes(self.max_output_bytes)
            ),
        ))
    }
}

/// Memory of a model in dense storage: `M`, `C`, `K`, the effective stiffness and its factor,
/// the gain columns and the modal / exact-reference work arrays, about twelve `n × n` arrays.
pub fn dense_model_bytes(n: f64) -> f64 {
    12.0 * 8.0 * n * n
}

/// Memory per DOF of sparse models after assembly and factorisation, measured with
/// `/usr/bin/time -v` (docs/limits.md) and rounded up: a chain (shear building) takes about
/// 0.8 KiB per DOF, a frame 2.1–2.6 KiB per DOF (fill of the factor).
pub const CHAIN_BYTES_PER_DOF: f64 = 1200.0;
pub const FRAME_BYTES_PER_DOF: f64 = 4000.0;
/// Memory per stored entry of a MatrixMarket model (triplets with file lines while reading,
/// CSC, the effective stiffness and a factor with fill), plus [`CHAIN_BYTES_PER_DOF`] per DOF.
pub const MTX_BYTES_PER_ENTRY: f64 = 200.0;

/// The shape of a run, from which its memory, time and output are estimated.
#[derive(Debug, Clone, Copy, Default)]
pub struct RunShape {
    /// DOFs of the numerical model.
    pub n_dofs: f64,
    /// Estimated memory of the numerical model [bytes].
    pub model_bytes: f64,
    /// Estimated time of one step of the numerical model \[s\].
    pub step_seconds: f64,
    pub steps: f64,
    /// Coupling DOFs (0 for a monolithic run).
    pub n_coupling: f64,
    pub substeps: f64,
    pub inner_steps: f64,
    /// Samples of one actuator delay line (0 without delay).
    pub delay_samples: f64,
    /// Extra `substeps.csv` columns per coupling DOF (phase-lag compensation: 2).
    pub extra_substep_columns: f64,
}

/// Bytes of one number in the CSV outputs, at most (shortest round-trip form, sign, exponent
/// and separator).
const CSV_BYTES_PER_VALUE: f64 = 24.0;

impl RunShape {
    /// Time of one dense step: about 1.2–3.9 ns per `n²` (docs/performance.md: 1.1–1.3 ms at
    /// n = 1000), doubled for the reference run alongside.
    pub fn dense_step_seconds(n: f64) -> f64 {
        2.0 * 2e-9 * n * n
    }
    /// Time of one sparse step of a chain: 7 ns per DOF measured, 20 ns taken (with reference).
    pub fn chain_step_seconds(n: f64) -> f64 {
        20e-9 * n
    }
    /// Time of one sparse frame step: measured 37–212 ns per DOF growing like the square root
    /// of the column lines (fill); 40 ns × √lines per DOF taken (with reference).
    pub fn frame_step_seconds(n: f64, lines: f64) -> f64 {
        40e-9 * n * lines.max(1.0).sqrt()
    }
    /// Time of one sparse step from the stored entries of `K` (MatrixMarket models).
    pub fn sparse_step_seconds(nnz: f64) -> f64 {
        40e-9 * nnz
    }

    /// Memory of the sampled ground motion (record, resampled copy, the simulation's copy).
    pub fn excitation_bytes(&self) -> f64 {
        3.0 * 8.0 * (self.steps + 1.0)
    }
    /// Memory of the actuator delay lines (times and values, one line per coupling DOF, and
    /// one more set for a per-step remote site or the reference).
    pub fn delay_bytes(&self) -> f64 {
        2.0 * 2.0 * 8.0 * self.delay_samples * self.n_coupling
    }
    pub fn memory(&self) -> f64 {
        self.model_bytes + self.excitation_bytes() + self.delay_bytes()
    }
    /// Computation: the steps, plus per sub-step the controller (0.3 µs + 0.1 µs·n_c²) and per
    /// inner step and coupling DOF the actuator, specimen and sensors (0.2 µs, measured 0.2)
    /// and the delay-line look-up (1 ns per sample of history).
    pub fn run_time(&self) -> f64 {
        let inner = self.inner_steps * self.n_coupling * (200e-9 + 1e-9 * self.delay_samples);
        let substep = 300e-9 + 100e-9 * self.n_coupling * self.n_coupling + inner;
        self.steps * (self.step_seconds + self.substeps * substep)
    }
    /// `history.csv` (t, u, v, a, the reference, and up to 7 groups per coupling DOF) plus
    /// `substeps.csv` (step, j, t and 3 groups per coupling DOF, 2 more with phase lag).
    pub fn history_bytes(&self) -> f64 {
        (self.steps + 1.0) * CSV_BYTES_PER_VALUE * (1.0 + 4.0 * self.n_dofs + 7.0 * self.n_coupling)
    }
    pub fn substeps_bytes(&self) -> f64 {
        let cols = 3.0 + (3.0 + self.extra_substep_columns) * self.n_coupling;
        self.steps * self.substeps * CSV_BYTES_PER_VALUE * cols * f64::from(self.n_coupling > 0.0)
    }
    pub fn output_bytes(&self) -> f64 {
        self.history_bytes() + self.substeps_bytes()
    }
}

/// Read an input file as UTF-8 text: a regular file of at most `max_bytes`, opened so that a
/// FIFO swapped in after the check cannot block. Errors name the file (as given) and the reason.
pub fn read_text(path: &Path, max_bytes: f64) -> Result<String> {
    read_text_checked(path, max_bytes, &|_| Ok(()))
}

/// Bytes handed to the head check of [`read_text_checked`].
pub const HEAD_BYTES: usize = 64 * 1024;

/// [`read_text`], but the first [`HEAD_BYTES`] (or the whole file, if shorter) go to
/// `check_head` before the rest is read: a 200 MB file that is plainly not of its kind (no
/// MatrixMarket banner) is refused after 64 KiB instead of after reading all of it. The head
/// may end inside a line or a UTF-8 character.
pub fn read_text_checked(
    path: &Path,
    max_bytes: f64,
    check_head: &dyn Fn(&[u8]) -> std::result::Result<(), String>,
) -> Result<String> {
    let name = path.display().to_string();
    let fail = |reason: String| Error::file(&name, reason);
    let (file, len) = open_regular(path, max_bytes).map_err(fail)?;
    let cap = max_bytes.clamp(0.0, u64::MAX as f64) as u64;
    let mut raw = Vec::with_capacity(len.min(cap).min(HEAD_BYTES as u64) as usize);
    let mut limited = file.take(cap.saturating_add(1));
    (&mut limited)
        .take(HEAD_BYTES as u64)
        .read_to_end(&mut raw)
        .map_err(|e| fail(format!("cannot read file: {e}")))?;
    check_head(&raw).map_err(fail)?;
    raw.reserve((len.min(cap) as usize).saturating_sub(raw.len()));
    limited
        .read_to_end(&mut raw)
        .map_err(|e| fail(format!("cannot read file: {e}")))?;
    if raw.len() as u64 > cap {
        return Err(fail(format!(
            "grew beyond limits.max_file_bytes = {} while it was read",
            bytes(max_bytes)
        )));
    }
    String::from_utf8(raw).map_err(|e| {
        fail(format!(
            "is not UTF-8 text (invalid byte at offset {})",
            e.utf8_error().valid_up_to()
        ))
    })
}

/// Read a record file (ground motion, replayed forces) as text within `limits`: the file is
/// first scanned in 64 KiB pieces, keeping nothing, and its numbers (fields between commas,
/// semicolons and white space) are counted; more than `limits.max_record_values` are refused
/// before anything is kept, so a 10⁸-row record costs a scan of its first 2·10⁷ fields, not its
/// size in memory. Then it is read as by [`read_text`].
pub fn read_record_text(path: &Path, limits: &Limits) -> Result<String> {
    let name = path.display().to_string();
    let fail = |reason: String| Error::file(&name, reason);
    let (file, _) = open_regular(path, limits.max_file_bytes).map_err(fail)?;
    let cap = limits.max_file_bytes.clamp(0.0, u64::MAX as f64) as u64;
    let max_values = limits.max_record_values.clamp(0.0, u64::MAX as f64) as u64;
    let mut reader = file.take(cap.saturating_add(1));
    let mut buf = vec![0u8; HEAD_BYTES];
    let (mut values, mut in_field) = (0u64, false);
    loop {
        let n = match reader.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(fail(format!("cannot read file: {e}"))),
        };
        for &b in &buf[..n] {
            let separator = matches!(b, b',' | b';' | b' ' | b'\t' | b'\n' | b'\r');
            values += u64::from(!separator && !in_field);
            in_field = !separator;
        }
        if values > max_values {
            return Err(fail(format!(
                "holds more than limits.max_record_values = {} numbers (a time and a value each \
                 count); set [limits] max_record_values to allow it",
                number(limits.max_record_values)
            )));
        }
    }
    read_text(path, limits.max_file_bytes)
}

/// Open `path` if it is a regular file of at most `max_bytes` (checked on the path and again on
/// the open handle); the handle and the file's length.
fn open_regular(path: &Path, max_bytes: f64) -> std::result::Result<(std::fs::File, u64), String> {
    let meta = std::fs::metadata(path).map_err(|e| format!("cannot read file: {e}"))?;
    check_regular(&meta, max_bytes)?;
    let file = open_nonblocking(path).map_err(|e| format!("cannot read file: {e}"))?;
    // The path may have been replaced between the two looks: check what was opened.
    let meta = file.metadata().map_err(|e| format!("cannot read file: {e}"))?;
    check_regular(&meta, max_bytes)?;
    Ok((file, meta.len()))
}

fn check_regular(meta: &std::fs::Metadata, max_bytes: f64) -> std::result::Result<(), String> {
    let kind = meta.file_type();
    if kind.is_dir() {
        return Err("is a directory, not a file".into());
    }
    if !kind.is_file() {
        return Err("is not a regular file (a device, FIFO or socket is never read as input)".into());
    }
    if meta.len() as f64 > max_bytes {
        // A configuration file's limit is fixed (its [limits] are inside it).
        if max_bytes == CONFIG_MAX_BYTES {
            return Err(format!(
                "is {}, more than the {} a configuration file may have (large models belong in \
                 .mtx files, records in their own files)",
                bytes(meta.len() as f64),
                bytes(max_bytes)
            ));
        }
        return Err(format!(
            "is {}, more than limits.max_file_bytes = {}; set [limits] max_file_bytes (bytes) to allow it",
            bytes(meta.len() as f64),
            bytes(max_bytes)
        ));
    }
    Ok(())
}

#[cfg(unix)]
fn open_nonblocking(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
}

#[cfg(not(unix))]
fn open_nonblocking(path: &Path) -> std::io::Result<std::fs::File> {
    std::fs::File::open(path)
}

/// Value of a `[limits]` key: a finite number > 0.
pub(crate) fn limit_value(key: &str, v: Option<f64>, default: f64) -> Result<f64> {
    match v {
        None => Ok(default),
        Some(x) if x.is_finite() && x > 0.0 => Ok(x),
        Some(x) => Err(Error::invalid(
            format!("limits.{key}"),
            format!("must be a finite number > 0, got {x}"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_durations_read_well() {
        assert_eq!(bytes(800.0), "800 B");
        assert_eq!(bytes(1536.0), "1.5 KiB");
        assert_eq!(bytes(7.0 * GIB), "7.0 GiB");
        assert_eq!(duration(30.0), "30.00 s");
        assert_eq!(duration(3.0 * 86_400.0), "3.0 days");
    }

    #[test]
    fn refusals_name_the_key_and_the_estimate() {
        let l = Limits::default();
        assert!(l.check_memory("x", "y", 1e9).is_ok());
        let e = l
            .check_memory("structure.frame", "a 3000x3000 frame", 16.0 * GIB)
            .unwrap_err();
        let m = e.to_string();
        assert!(
            m.starts_with("structure.frame: a 3000x3000 frame needs about 16.0 GiB"),
            "{m}"
        );
        assert!(m.contains("limits.max_memory = 4.0 GiB"), "{m}");
        assert!(l.check_run_time("k", "x", f64::NAN).is_err());
        assert!(l.check_output("k", "x", f64::INFINITY).is_err());
    }
}
