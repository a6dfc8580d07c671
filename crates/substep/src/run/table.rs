//! The in-memory recorder of a run ([`HistoryTable`]: the columns of `history.csv` and
//! `substeps.csv`, for front ends that hand arrays to their users), and the number format of
//! the CSV files.

use super::{Layout, RunObserver, StepRow};
use crate::format::round_time;
use crate::substructure::SubstepObserver;
use std::fmt::Write as _;
use std::io::{self, Write};
use std::ops::ControlFlow;

/// Append a number in the CSV files' format: shortest round-trip form, exponent notation for
/// very small or large values, `0` for ±0.
pub fn push_number(out: &mut String, x: f64) {
    let a = x.abs();
    if x == 0.0 {
        out.push('0'); // also for -0.0
    } else if (1e-4..1e7).contains(&a) || !x.is_finite() {
        let _ = write!(out, "{x}");
    } else {
        let _ = write!(out, "{x:e}");
    }
}

/// Named columns of numbers, all of one length.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Table {
    pub names: Vec<String>,
    pub columns: Vec<Vec<f64>>,
    /// Columns written as integers in CSV (the step and sub-step counters).
    pub integer: Vec<bool>,
}

impl Table {
    fn new(names: Vec<String>) -> Self {
        let integer = names
            .iter()
            .map(|n| matches!(n.as_str(), "step" | "substep" | "ramp"))
            .collect();
        Self {
            columns: vec![Vec::new(); names.len()],
            names,
            integer,
        }
    }

    /// A table of the given columns (one per name, all of one length); `step`, `substep` and
    /// `ramp` are the integer columns.
    pub fn from_columns(names: Vec<String>, columns: Vec<Vec<f64>>) -> Self {
        let mut t = Self::new(names);
        t.columns = columns;
        t
    }

    pub fn rows(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }

    /// The column called `name`.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        let k = self.names.iter().position(|n| n == name)?;
        Some(&self.columns[k])
    }

    fn push(&mut self, values: impl Iterator<Item = f64>) {
        for (c, x) in self.columns.iter_mut().zip(values) {
            c.push(x);
        }
    }

    /// The table as CSV, in the format of the files `substep run` writes (header line, then
    /// one line per row).
    pub fn write_csv(&self, w: &mut impl Write) -> io::Result<()> {
        let mut line = self.names.join(",");
        line.push('\n');
        w.write_all(line.as_bytes())?;
        for r in 0..self.rows() {
            line.clear();
            for (k, c) in self.columns.iter().enumerate() {
                if k > 0 {
                    line.push(',');
                }
                if self.integer[k] {
                    let _ = write!(line, "{}", c[r] as u64);
                } else {
                    push_number(&mut line, c[r]);
                }
            }
            line.push('\n');
            w.write_all(line.as_bytes())?;
        }
        Ok(())
    }
}

/// A [`RunObserver`] that keeps every row in memory: `history` has the columns of
/// `history.csv`, `substeps` those of `substeps.csv` (substructured runs), `response` those of
/// `response.csv` (when the engineering quantities are recorded). Memory grows with the run
/// (8 bytes per value); the CLI streams to files instead.
#[derive(Debug, Clone, Default)]
pub struct HistoryTable {
    pub history: Table,
    pub substeps: Option<Table>,
    pub response: Option<Table>,
    dt: f64,
    dtau: f64,
    /// Tracking error and correction of the current sub-step (phase-lag runs).
    phase_lag: Option<(Vec<f64>, Vec<f64>)>,
    /// `held`, `strays` of the current sub-step (lab-target runs).
    lab: Option<(bool, u64)>,
    ramp_column: bool,
}

impl HistoryTable {
    /// An empty table for `layout` (as [`RunObserver::start`] makes it).
    pub fn new(layout: &Layout) -> Self {
        let mut t = Self::default();
        t.start(layout);
        t
    }

    fn substep_row(
        &mut self,
        step: usize,
        j: usize,
        ramp: usize,
        command: &[f64],
        force: &[f64],
        displacement: &[f64],
    ) {
        let Some(table) = &mut self.substeps else { return };
        let t = round_time(step.saturating_sub(1) as f64 * self.dt + j as f64 * self.dtau);
        let head = [step as f64, j as f64, t];
        let plain = command.iter().chain(force).chain(displacement).copied();
        let lag = self
            .phase_lag
            .iter()
            .flat_map(|(te, du)| te.iter().chain(du).map(move |&x| if ramp == 0 { x } else { f64::NAN }));
        // As substeps.csv: the lab's columns are NaN on the ramp's rows.
        let lab = self.lab.into_iter().flat_map(|(held, strays)| {
            if ramp == 0 {
                [f64::from(u8::from(held)), strays as f64]
            } else {
                [f64::NAN; 2]
            }
        });
        let ramp_col = self.ramp_column.then_some(ramp as f64);
        table.push(head.into_iter().chain(plain).chain(lag).chain(lab).chain(ramp_col));
    }
}

impl SubstepObserver for HistoryTable {
    fn phase_lag(&mut self, tracking_error: &[f64], correction: &[f64]) {
        if let Some((te, du)) = &mut self.phase_lag {
            te.copy_from_slice(tracking_error);
            du.copy_from_slice(correction);
        }
    }
    fn lab(&mut self, held: bool, strays: u64) {
        if let Some(l) = &mut self.lab {
            *l = (held, strays);
        }
    }
    fn substep(&mut self, step: usize, j: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.substep_row(step, j, 0, command, force, displacement);
    }
    fn ramp(&mut self, step: usize, j: usize, s: usize, command: &[f64], force: &[f64], displacement: &[f64]) {
        self.substep_row(step, j, s, command, force, displacement);
    }
}

impl RunObserver for HistoryTable {
    fn start(&mut self, layout: &Layout) {
        let n_c = layout.coupling_dofs.len();
        self.history = Table::new(layout.history_columns());
        self.substeps = layout.substep_columns().map(Table::new);
        self.response = layout.response_columns.clone().map(Table::new);
        self.dt = layout.dt;
        self.dtau = layout.dt / layout.substeps.unwrap_or(1) as f64;
        self.phase_lag = layout.phase_lag.then(|| (vec![0.0; n_c], vec![0.0; n_c]));
        self.lab = layout.lab.then_some((false, 0));
        self.ramp_column = layout.ramp_column;
    }

    fn step(&mut self, row: &StepRow<'_>) -> ControlFlow<()> {
        self.history.push(row.history_values());
        if let (Some(table), Some(e)) = (&mut self.response, &row.engineering) {
            table.push(e.values());
        }
        ControlFlow::Continue(())
    }
}
