//! Readers of ground-motion files: two-column `t, a_g` text, single-column `a_g` text with a given
//! `dt`, and PEER NGA `.AT2`.
//!
//! Text formats: fields are separated by commas, semicolons, spaces or tabs; everything after a
//! `#` is a comment; blank lines are skipped. Lines at the top whose first field is not a number
//! are taken as header lines and skipped; after the first data line a field that is not a
//! number is an error. Numbers may use a Fortran `D` exponent (`1.5D-03`). Decimal commas are
//! not supported.

use super::G;
use super::record::{Record, from_located_samples};
use crate::error::{Error, Result, require_positive};
use crate::limits::Limits;
use std::path::Path;

/// Read a whole record file as text within `limits` (a regular file of at most
/// `max_file_bytes`, at most `max_record_values` numbers, counted before it is kept); the path
/// as given names the file in messages.
fn read_text(path: &Path, limits: &Limits) -> Result<(String, String)> {
    let text = crate::limits::read_record_text(path, limits)?;
    Ok((path.display().to_string(), text))
}

/// The limits of the readers without a config (`[limits]` of a config: [`read_record_with`]).
fn default_limits() -> Limits {
    Limits::default()
}

/// The fields of one line, without a `#` comment (and without a byte-order mark).
fn fields(line: &str) -> impl Iterator<Item = &str> {
    let line = line.split('#').next().unwrap_or("");
    line.trim_start_matches('\u{feff}')
        .split(|c: char| c == ',' || c == ';' || c.is_whitespace())
        .filter(|f| !f.is_empty())
}

/// A number in Rust or Fortran notation (`1.5e-3`, `.15E-02`, `1.5D-03`).
fn parse_number(field: &str) -> Option<f64> {
    field.parse().ok().or_else(|| {
        if field.contains(['d', 'D']) {
            field.replace(['d', 'D'], "e").parse().ok()
        } else {
            None
        }
    })
}

/// Parse a data field of line `line_no`, which must be a finite number.
fn data_value(field: &str, name: &str, line_no: usize, what: &str) -> Result<f64> {
    let v = parse_number(field)
        .ok_or_else(|| Error::file(name, format!("line {line_no}: cannot parse '{field}' as a number")))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Error::file(name, format!("line {line_no}: {what} is not finite ({v})")))
    }
}

/// Read a two-column `t, a_g` file (s, m/s²); see [`parse_two_column`].
pub fn read_two_column(path: impl AsRef<Path>) -> Result<Record> {
    let (name, text) = read_text(path.as_ref(), &default_limits())?;
    parse_two_column(&text, &name)
}

/// Parse two-column `t, a_g` text (s, m/s²); `name` names it in messages.
///
/// Every data line holds exactly two numbers. Times must be finite, `>= 0` and strictly
/// increasing; the samples become a [`Record`] as described at [`Record::from_samples`]
/// (uniform spacing kept, otherwise resampled to the smallest spacing; a first time above 0
/// is preceded by `a_g = 0` at `t = 0`).
pub fn parse_two_column(text: &str, name: &str) -> Result<Record> {
    let (mut times, mut values, mut line_nos) = (Vec::new(), Vec::new(), Vec::new());
    for (idx, line) in text.lines().enumerate() {
        let line_no = idx + 1;
        let mut it = fields(line);
        let Some(first) = it.next() else { continue };
        if times.is_empty() && parse_number(first).is_none() {
            continue; // header line
        }
        let t = parse_number(first)
            .ok_or_else(|| Error::file(name, format!("line {line_no}: cannot parse '{first}' as a number")))?;
        let Some(second) = it.next() else {
            return Err(Error::file(
                name,
                format!("line {line_no}: expected 2 values (t, a_g), found 1"),
            ));
        };
        let extra = it.count();
        if extra > 0 {
            return Err(Error::file(
                name,
                format!("line {line_no}: expected 2 values (t, a_g), found {}", 2 + extra),
            ));
        }
        let a = parse_number(second)
            .ok_or_else(|| Error::file(name, format!("line {line_no}: cannot parse '{second}' as a number")))?;
        times.push(t);
        values.push(a);
        line_nos.push(line_no);
    }
    from_located_samples(&times, &values, name, |k| format!("line {}", line_nos[k]), Error::file)
}

/// Read a file of `a_g` values (m/s²) sampled at `dt` (s); see [`parse_single_column`].
pub fn read_single_column(path: impl AsRef<Path>, dt: f64) -> Result<Record> {
    let path = path.as_ref();
    require_positive(&format!("{}: dt", path.display()), dt)?;
    let (name, text) = read_text(path, &default_limits())?;
    parse_single_column(&text, dt, &name)
}

/// Parse `a_g` values (m/s²) sampled at `dt` (s), the first at `t = 0`; `name` names the text in
/// messages. A line may hold several values; they are read row by row.
pub fn parse_single_column(text: &str, dt: f64, name: &str) -> Result<Record> {
    require_positive(&format!("{name}: dt"), dt)?;
    let mut accel = Vec::new();
    for (idx, line) in text.lines().enumerate() {
        let line_no = idx + 1;
        let mut it = fields(line).peekable();
        let Some(first) = it.peek() else { continue };
        if accel.is_empty() && parse_number(first).is_none() {
            continue; // header line
        }
        for field in it {
            accel.push(data_value(field, name, line_no, "value")?);
        }
    }
    if accel.is_empty() {
        return Err(Error::file(name, "no data"));
    }
    Ok(Record { dt, accel })
}

/// Read a PEER NGA `.AT2` acceleration file (values in g, converted to m/s²); see
/// [`parse_at2`].
pub fn read_at2(path: impl AsRef<Path>) -> Result<Record> {
    let (name, text) = read_text(path.as_ref(), &default_limits())?;
    parse_at2(&text, &name)
}

/// Parse the text of a PEER NGA `.AT2` file; `name` names it in messages.
///
/// Four header lines; line 3 names the quantity (a velocity or displacement file is refused),
/// line 4 gives the number of points and the time step, as `NPTS= 3000, DT= .0100 SEC` (any
/// case and spacing, `=` or `:`) or in the old form `3000  .0100  NPTS, DT`. The data that
/// follow are in g and are converted with [`G`]; their number must equal NPTS.
pub fn parse_at2(text: &str, name: &str) -> Result<Record> {
    let mut lines = text.lines();
    let mut header = [""; 4];
    for (i, slot) in header.iter_mut().enumerate() {
        *slot = lines.next().ok_or_else(|| {
            Error::file(
                name,
                format!("expected 4 header lines (PEER NGA format), the file has only {i} lines"),
            )
        })?;
    }
    let quantity = header[2].to_ascii_uppercase();
    if quantity.contains("VELOCITY") || quantity.contains("DISPLACEMENT") {
        return Err(Error::file(
            name,
            format!("line 3: not an acceleration record ('{}')", header[2].trim()),
        ));
    }
    let (npts, dt) = at2_npts_dt(header[3]).ok_or_else(|| {
        Error::file(
            name,
            format!("line 4: cannot find NPTS and DT in '{}'", header[3].trim()),
        )
    })?;
    if !(npts.is_finite() && npts >= 1.0 && npts.fract() == 0.0) {
        return Err(Error::file(
            name,
            format!("line 4: NPTS must be a whole number >= 1, got {npts}"),
        ));
    }
    if !(dt.is_finite() && dt > 0.0) {
        return Err(Error::file(
            name,
            format!("line 4: DT must be a finite number > 0, got {dt}"),
        ));
    }

    let mut accel = Vec::new();
    for (idx, line) in lines.enumerate() {
        let line_no = idx + 5;
        for field in fields(line) {
            accel.push(G * data_value(field, name, line_no, "value")?);
        }
    }
    if accel.len() as f64 != npts {
        return Err(Error::file(
            name,
            format!("header says NPTS = {npts} but {} values were found", accel.len()),
        ));
    }
    Ok(Record { dt, accel })
}

/// `(NPTS, DT)` from line 4 of an AT2 file, if both can be found.
fn at2_npts_dt(line: &str) -> Option<(f64, f64)> {
    let up = line.to_ascii_uppercase();
    if let (Some(n), Some(dt)) = (keyed_number(&up, "NPTS"), keyed_number(&up, "DT")) {
        return Some((n, dt));
    }
    // Old format: "  3000   .0100   NPTS, DT".
    if up.contains('=') {
        return None;
    }
    let mut it = fields(&up);
    let n = parse_number(it.next()?)?;
    let dt = parse_number(it.next()?)?;
    Some((n, dt))
}

/// The number after the first `key=` (or `key:`) in `s`, spaces allowed around the sign.
fn keyed_number(s: &str, key: &str) -> Option<f64> {
    s.match_indices(key).find_map(|(pos, _)| {
        let rest = s[pos + key.len()..].trim_start();
        let rest = rest.strip_prefix(['=', ':'])?.trim_start();
        let end = rest
            .find(|c: char| !(c.is_ascii_digit() || matches!(c, '.' | '+' | '-' | 'E')))
            .unwrap_or(rest.len());
        parse_number(&rest[..end])
    })
}

/// Read a ground-motion file, choosing the format by extension: `.at2` (any case) is PEER NGA
/// AT2 (a given `dt` must then agree with the header's DT); otherwise a single column sampled
/// at `dt` if `dt` is given, else two columns `t, a_g`.
pub fn read_record(path: impl AsRef<Path>, dt: Option<f64>) -> Result<Record> {
    read_record_with(path, dt, &default_limits())
}

/// [`read_record`] within a config's `limits` (`[limits] max_file_bytes`, `max_record_values`).
pub fn read_record_with(path: impl AsRef<Path>, dt: Option<f64>, limits: &Limits) -> Result<Record> {
    let path = path.as_ref();
    let name = path.display().to_string();
    let is_at2 = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("at2"));
    if is_at2 {
        let (_, text) = read_text(path, limits)?;
        let record = parse_at2(&text, &name)?;
        match dt {
            Some(dt) if dt.is_nan() || (dt - record.dt).abs() > 1e-9 * record.dt => Err(Error::file(
                path.display().to_string(),
                format!("dt = {dt} s was given but the AT2 header says DT = {} s", record.dt),
            )),
            _ => Ok(record),
        }
    } else if let Some(dt) = dt {
        require_positive(&format!("{name}: dt"), dt)?;
        let (_, text) = read_text(path, limits)?;
        parse_single_column(&text, dt, &name)
    } else {
        let (_, text) = read_text(path, limits)?;
        parse_two_column(&text, &name)
    }
}
