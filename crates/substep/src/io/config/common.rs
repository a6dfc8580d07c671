//! Helpers shared by the sections of the test definition (`mod.rs` and every section file):
//! TOML error messages, key-path prefixes, numbers or arrays, matrices inline or from a file,
//! DOF numbers. Below every other file of `io/config`, so that no two of them import each other.

use crate::error::{Error, Result};
use crate::io::matrix_market::{read_matrix_market_sparse_with, read_matrix_market_with};
use crate::limits::{self, Limits, RunShape};
use crate::sparse::CscMatrix;
use nalgebra::DMatrix;
use serde::Deserialize;
use std::fmt;
use std::path::Path;

/// `FILE: line L: message` from a toml error (its message may span lines; they are joined).
pub(crate) fn toml_error(e: &toml::de::Error, text: &str, name: &str) -> Error {
    let message = plain_types(&e.message().split_whitespace().collect::<Vec<_>>().join(" "));
    match e.span() {
        Some(span) => {
            let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
            Error::file(name, format!("line {line}: {message}"))
        }
        None => Error::file(name, message),
    }
}

/// Prefix the key path of an input error (`mass` → `structure.sdof.mass`).
pub(crate) fn prefixed(e: Error, prefix: &str) -> Error {
    match e {
        Error::InvalidInput { what, reason } if !what.starts_with(prefix) => {
            Error::invalid(format!("{prefix}{what}"), reason)
        }
        other => other,
    }
}

pub(crate) fn one() -> f64 {
    1.0
}

/// A matrix in a config: an array of rows, a number (1×1), or a path to a `.mtx` file.
#[derive(Debug, Clone)]
pub(crate) enum MatrixInput {
    Rows(Vec<Vec<f64>>),
    File(String),
}

impl<'de> Deserialize<'de> for MatrixInput {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = MatrixInput;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a matrix: an array of rows (arrays of numbers), a number, or the path of a .mtx file")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> std::result::Result<MatrixInput, E> {
                Ok(MatrixInput::File(v.to_string()))
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> std::result::Result<MatrixInput, E> {
                Ok(MatrixInput::Rows(vec![vec![v]]))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> std::result::Result<MatrixInput, E> {
                self.visit_f64(v as f64)
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> std::result::Result<MatrixInput, E> {
                self.visit_f64(v as f64)
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<MatrixInput, A::Error> {
                let mut rows = Vec::new();
                while let Some(row) = seq.next_element::<Vec<f64>>()? {
                    rows.push(row);
                }
                Ok(MatrixInput::Rows(rows))
            }
        }
        d.deserialize_any(V)
    }
}

/// One number for all, or one per item.
#[derive(Debug, Clone)]
pub(crate) struct OneOrMany(pub(crate) Vec<f64>);

impl<'de> Deserialize<'de> for OneOrMany {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = OneOrMany;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number or an array of numbers")
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> std::result::Result<OneOrMany, E> {
                Ok(OneOrMany(vec![v]))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> std::result::Result<OneOrMany, E> {
                Ok(OneOrMany(vec![v as f64]))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> std::result::Result<OneOrMany, E> {
                Ok(OneOrMany(vec![v as f64]))
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<OneOrMany, A::Error> {
                let mut v = Vec::new();
                while let Some(x) = seq.next_element::<f64>()? {
                    v.push(x);
                }
                Ok(OneOrMany(v))
            }
        }
        d.deserialize_any(V)
    }
}

/// A matrix from its config form; `what` is the key path.
pub(crate) fn matrix(input: &MatrixInput, what: &str, base: &Path) -> Result<DMatrix<f64>> {
    matrix_with(input, what, base, &Limits::default())
}

/// [`matrix`] with a `.mtx` file read within `limits`.
pub(crate) fn matrix_with(input: &MatrixInput, what: &str, base: &Path, limits: &Limits) -> Result<DMatrix<f64>> {
    match input {
        MatrixInput::File(path) => {
            let resolved = base.join(path);
            read_matrix_market_with(&resolved, limits).map_err(|e| Error::invalid(what, e.to_string()))
        }
        MatrixInput::Rows(rows) => {
            let n_rows = rows.len();
            let n_cols = rows.first().map_or(0, Vec::len);
            if n_rows == 0 || n_cols == 0 {
                return Err(Error::invalid(what, "matrix is empty"));
            }
            for (i, row) in rows.iter().enumerate() {
                if row.len() != n_cols {
                    return Err(Error::invalid(
                        what,
                        format!("row {} has {} entries but row 1 has {n_cols}", i + 1, row.len()),
                    ));
                }
                if let Some(j) = row.iter().position(|x| !x.is_finite()) {
                    return Err(Error::invalid(
                        what,
                        format!("entry ({}, {}) is not finite ({})", i + 1, j + 1, row[j]),
                    ));
                }
            }
            Ok(DMatrix::from_fn(n_rows, n_cols, |i, j| rows[i][j]))
        }
    }
}

/// A model matrix in sparse form: `.mtx` files are read without a dense array; inline rows must
/// be square.
pub(crate) fn sparse_matrix(input: &MatrixInput, what: &str, base: &Path, limits: &Limits) -> Result<CscMatrix> {
    match input {
        MatrixInput::File(path) => {
            let resolved = base.join(path);
            read_matrix_market_sparse_with(&resolved, limits).map_err(|e| Error::invalid(what, e.to_string()))
        }
        MatrixInput::Rows(_) => {
            let m = matrix_with(input, what, base, limits)?;
            if m.nrows() != m.ncols() {
                return Err(Error::invalid(
                    what,
                    format!("is {}x{}, a model matrix must be square", m.nrows(), m.ncols()),
                ));
            }
            Ok(CscMatrix::from_dense(&m))
        }
    }
}

/// 1-based DOF number → 0-based index, with a range check.
pub(crate) fn dof_index(what: &str, dof: usize, n: usize) -> Result<usize> {
    if (1..=n).contains(&dof) {
        Ok(dof - 1)
    } else {
        Err(Error::invalid(
            what,
            format!("DOF {dof} is out of range (the model has DOFs 1..={n})"),
        ))
    }
}

/// Error if any of the named optional keys is present (`why` explains).
pub(crate) fn forbid(prefix: &str, keys: &[(&str, bool)], why: &str) -> Result<()> {
    match keys.iter().find(|(_, present)| *present) {
        Some((key, _)) => Err(Error::invalid(format!("{prefix}{key}"), why.to_string())),
        None => Ok(()),
    }
}

/// Refuse an excitation whose samples at `dt` would not fit, before they are generated.
pub(crate) fn check_samples(limits: &Limits, length: f64, dt: f64) -> Result<()> {
    let steps = (length / dt).floor();
    let shape = RunShape {
        steps,
        ..RunShape::default()
    };
    limits.check_memory(
        "integrator.dt",
        &format!(
            "a {} s excitation at dt = {} s ({} steps)",
            limits::number(length),
            limits::number(dt),
            limits::number(steps)
        ),
        shape.excitation_bytes(),
    )
}

/// serde's Rust type names in a message replaced by what a user types ("expected usize" →
/// "expected a whole number ≥ 0").
pub(crate) fn plain_types(message: &str) -> String {
    let mut m = message.to_string();
    for (rust, plain) in [
        ("expected usize", "expected a whole number ≥ 0"),
        ("expected u64", "expected a whole number ≥ 0"),
        ("expected u32", "expected a whole number ≥ 0 (at most 4294967295)"),
        ("expected u16", "expected a whole number 0…65535"),
        ("expected u8", "expected a whole number 0…255"),
        ("expected i64", "expected a whole number"),
        ("expected i32", "expected a whole number"),
        ("expected f64", "expected a number"),
        ("expected f32", "expected a number"),
        ("expected a sequence", "expected an array [..]"),
        ("expected a map", "expected a table"),
        ("floating point", "the number"),
        ("invalid type: integer", "invalid value: the whole number"),
        ("invalid type:", "wrong type:"),
    ] {
        m = m.replace(rust, plain);
    }
    m
}

/// `specimen.<key>` from a specimen constructor becomes `<what>.<key>`.
pub(crate) fn rekey(e: Error, what: &str) -> Error {
    match e {
        Error::InvalidInput { what: key, reason } | Error::Numerical { what: key, reason } => {
            let rest = key.strip_prefix("specimen").unwrap_or(&key);
            Error::invalid(format!("{what}{rest}"), reason)
        }
        other => other,
    }
}
