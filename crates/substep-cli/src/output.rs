//! Output files of `substep run`: `history.csv` and `substeps.csv` (written row by row through
//! a `BufWriter`), the statistics that go into `summary.json`, and a decimating recorder that
//! keeps the series for the plots bounded in memory.

use serde::Serialize;
use std::fmt::Write as _;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;
use substep::substructure::{StepRecord, SubstepObserver};

/// A number for CSV: shortest round-trip form, exponent notation for very small or large values.
pub fn num(out: &mut String, x: f64) {
    let a = x.abs();
    if x == 0.0 {
        out.push('0'); // also for -0.0
    } else if (1e-4..1e7).contains(&a) || !x.is_finite() {
        let _ = write!(out, "{x}");
    } else {
        let _ = write!(out, "{x:e}");
    }
}

fn header_group(out: &mut String, prefix: &str, n: usize) {
    for k in 1..=n {
        let _ = write!(out, ",{prefix}{k}");
    }
}

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
    /// Columns `t, u1..un, v1..vn, a1..an`, then for substructured runs (`n_c > 0`)
    /// `fc, fe, fu, dm` per coupling DOF, the groups named in `extra` (each one column per
    /// coupling DOF; their values are passed to [`row`](Self::row)) and, with a reference,
    /// `uref1..urefn`.
    pub fn create(path: &Path, n: usize, n_c: usize, extra: &[&str], reference: bool) -> io::Result<Self> {
        let mut w = BufWriter::new(File::create(path)?);
        let mut line = String::from("t");
        for p in ["u", "v", "a"] {
            header_group(&mut line, p, n);
        }
        for p in ["fc", "fe", "fu", "dm"] {
            header_group(&mut line, p, n_c);
        }
        for p in extra {
            header_group(&mut line, p, n_c);
        }
        if reference {
            header_group(&mut line, "uref", n);
        }
        line.push('\n');
        w.write_all(line.as_bytes())?;
        Ok(Self { w, line })
    }

    pub fn row(
        &mut self,
        t: f64,
        kin: &substep::integrate::Kinematics,
        coupling: Option<&StepRecord>,
        extra: &[f64],
        reference: Option<&[f64]>,
    ) -> io::Result<()> {
        let line = &mut self.line;
        line.clear();
        // Rounded to 1 ns: `i·Δt` without float noise (19.99, not 19.990000000000002).
        num(line, crate::engineering::substep_time(t));
        row_group(line, kin.u.as_slice());
        row_group(line, kin.v.as_slice());
        row_group(line, kin.a.as_slice());
        if let Some(c) = coupling {
            row_group(line, c.coupling_force);
            row_group(line, c.error_force);
            row_group(line, c.compensation_force);
            row_group(line, c.measured_displacement);
        }
        row_group(line, extra);
        if let Some(r) = reference {
            row_group(line, r);
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
/// [`SubstepObserver::phase_lag`]). Write errors are kept and reported by
/// [`SubstepWriter::finish`] (the observer interface cannot return them).
pub struct SubstepWriter {
    w: BufWriter<File>,
    line: String,
    dt: f64,
    dtau: f64,
    error: Option<io::Error>,
    /// Tracking error and correction of the current sub-step (phase-lag runs).
    phase_lag: Option<(Vec<f64>, Vec<f64>)>,
}

impl SubstepWriter {
    pub fn create(path: &Path, n_c: usize, dt: f64, substeps: usize, phase_lag: bool) -> io::Result<Self> {
        let mut w = BufWriter::new(File::create(path)?);
        let mut line = String::from("step,substep,t");
        for p in ["cmd", "fm", "dm"] {
            header_group(&mut line, p, n_c);
        }
        if phase_lag {
            for p in ["te", "du"] {
                header_group(&mut line, p, n_c);
            }
        }
        line.push('\n');
        w.write_all(line.as_bytes())?;
        Ok(Self {
            w,
            line,
            dt,
            dtau: dt / substeps as f64,
            error: None,
            phase_lag: phase_lag.then(|| (vec![0.0; n_c], vec![0.0; n_c])),
        })
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
    fn phase_lag(&mut self, tracking_error: &[f64], correction: &[f64]) {
        if let Some((te, du)) = &mut self.phase_lag {
            te.copy_from_slice(tracking_error);
            du.copy_from_slice(correction);
        }
    }
    fn substep(&mut self, step: usize, j: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        if self.error.is_some() {
            return;
        }
        let line = &mut self.line;
        line.clear();
        let _ = write!(line, "{step},{j},");
        num(
            line,
            crate::engineering::substep_time((step - 1) as f64 * self.dt + j as f64 * self.dtau),
        );
        row_group(line, command);
        row_group(line, force);
        row_group(line, displacement);
        if let Some((te, du)) = &self.phase_lag {
            row_group(line, te);
            row_group(line, du);
        }
        line.push('\n');
        if let Err(e) = self.w.write_all(line.as_bytes()) {
            self.error = Some(e);
        }
    }
}

/// A peak `max |x|` and the time it occurred.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Peak {
    pub max_abs: f64,
    pub t: f64,
}

/// Peaks of one vector quantity, per component.
#[derive(Debug, Clone)]
pub struct PeakTracker(pub Vec<Peak>);

impl PeakTracker {
    pub fn new(n: usize) -> Self {
        Self(vec![Peak::default(); n])
    }
    pub fn update(&mut self, x: &[f64], t: f64) {
        for (p, &v) in self.0.iter_mut().zip(x) {
            if v.abs() > p.max_abs {
                *p = Peak { max_abs: v.abs(), t };
            }
        }
    }
    /// Index and value of the largest peak.
    pub fn largest(&self) -> (usize, Peak) {
        self.0
            .iter()
            .copied()
            .enumerate()
            .fold((0, Peak::default()), |best, (k, p)| {
                if p.max_abs > best.1.max_abs { (k, p) } else { best }
            })
    }
}

/// Errors of a quantity against its reference, per component.
#[derive(Debug, Clone)]
pub struct ErrorTracker {
    sum_sq: Vec<f64>,
    max_err: Vec<f64>,
    max_ref: Vec<f64>,
    count: usize,
}

/// RMS and peak error normalised by the reference peak.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ErrorStats {
    pub rms_error: f64,
    pub peak_error: f64,
    pub reference_peak: f64,
}

impl ErrorTracker {
    pub fn new(n: usize) -> Self {
        Self {
            sum_sq: vec![0.0; n],
            max_err: vec![0.0; n],
            max_ref: vec![0.0; n],
            count: 0,
        }
    }
    pub fn update(&mut self, x: &[f64], reference: &[f64]) {
        for k in 0..self.sum_sq.len() {
            let e = x[k] - reference[k];
            self.sum_sq[k] += e * e;
            self.max_err[k] = self.max_err[k].max(e.abs());
            self.max_ref[k] = self.max_ref[k].max(reference[k].abs());
        }
        self.count += 1;
    }
    /// Normalised errors of component `k` (NaN if the reference is identically zero).
    pub fn stats(&self, k: usize) -> ErrorStats {
        let peak = self.max_ref[k];
        let norm = if peak > 0.0 { peak } else { f64::NAN };
        ErrorStats {
            rms_error: (self.sum_sq[k] / self.count.max(1) as f64).sqrt() / norm,
            peak_error: self.max_err[k] / norm,
            reference_peak: peak,
        }
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

#[cfg(test)]
mod tests {
    use super::*;

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
    fn number_format_round_trips() {
        for x in [0.0, 1.5, -2.25e-9, 3.0e12, 0.1 + 0.2] {
            let mut s = String::new();
            num(&mut s, x);
            assert_eq!(s.parse::<f64>().unwrap(), x, "{s}");
        }
    }
}
