//! MatrixMarket (`.mtx`) reader for real matrices, into a dense matrix
//! ([`read_matrix_market`]) or a sparse square CSC matrix ([`read_matrix_market_sparse`], no
//! dense `n × n` array: for large models).
//!
//! Supported: `%%MatrixMarket matrix coordinate|array real|integer|double general|symmetric|skew-symmetric`
//! (keywords in any case). `coordinate` lists `i j value` with 1-based indices; `array` lists all
//! values column by column (for `symmetric` only the lower triangle, for `skew-symmetric` only
//! the strict lower triangle). A symmetric coordinate file may list an off-diagonal pair in
//! either triangle, but only once; duplicate entries are an error. Lines starting with `%` are
//! comments. `pattern` and `complex` files are refused.
//!
//! Every error names the file and, where it has one, the line: `K.mtx: line 7: row index 4 is
//! out of range 1..=3`.

use crate::error::{Error, Result};
use crate::limits::{CHAIN_BYTES_PER_DOF, Limits, MTX_BYTES_PER_ENTRY, bytes, read_text_checked};
use crate::sparse::CscMatrix;
use nalgebra::DMatrix;
use std::io::{BufWriter, Write};
use std::path::Path;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Layout {
    Coordinate,
    Array,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Symmetry {
    General,
    Symmetric,
    SkewSymmetric,
}

/// Read a `.mtx` file into a dense matrix; the path as given names the file in messages.
pub fn read_matrix_market(path: impl AsRef<Path>) -> Result<DMatrix<f64>> {
    read_matrix_market_with(path, &Limits::default())
}

/// [`read_matrix_market`] within `limits` (file size, and the memory the size line asks for).
pub fn read_matrix_market_with(path: impl AsRef<Path>, limits: &Limits) -> Result<DMatrix<f64>> {
    let path = path.as_ref();
    let text = read_text_checked(path, limits.max_file_bytes, &check_banner)?;
    parse_dense(&text, &path.display().to_string(), limits)
}

/// Parse the text of a `.mtx` file; `name` names it in messages.
pub fn parse_matrix_market(text: &str, name: &str) -> Result<DMatrix<f64>> {
    parse_dense(text, name, &Limits::default())
}

fn parse_dense(text: &str, name: &str, limits: &Limits) -> Result<DMatrix<f64>> {
    let mut dense = Dense {
        max_memory: limits.max_memory,
        m: DMatrix::zeros(0, 0),
        set: Vec::new(),
    };
    parse_into(text, name, &mut dense)?;
    Ok(dense.m)
}

/// Read a `.mtx` file into a sparse square matrix; the path as given names the file in
/// messages.
pub fn read_matrix_market_sparse(path: impl AsRef<Path>) -> Result<CscMatrix> {
    read_matrix_market_sparse_with(path, &Limits::default())
}

/// [`read_matrix_market_sparse`] within `limits` (file size, and the memory the size line
/// asks for).
pub fn read_matrix_market_sparse_with(path: impl AsRef<Path>, limits: &Limits) -> Result<CscMatrix> {
    let path = path.as_ref();
    let text = read_text_checked(path, limits.max_file_bytes, &check_banner)?;
    parse_sparse(&text, &path.display().to_string(), limits)
}

/// Parse the text of a `.mtx` file into a sparse square matrix (stored entries only; explicit
/// zeros are dropped); `name` names it in messages.
pub fn parse_matrix_market_sparse(text: &str, name: &str) -> Result<CscMatrix> {
    parse_sparse(text, name, &Limits::default())
}

fn parse_sparse(text: &str, name: &str, limits: &Limits) -> Result<CscMatrix> {
    let mut sparse = Sparse {
        max_memory: limits.max_memory,
        ..Sparse::default()
    };
    parse_into(text, name, &mut sparse)?;
    sparse.finish(name)
}

/// Where parsed entries go.
trait Target {
    /// The size line was read (`entries`: the declared entries of a coordinate file, `None`
    /// for an array); refuse sizes the target cannot hold before anything is allocated.
    fn start(&mut self, rows: usize, cols: usize, entries: Option<usize>) -> std::result::Result<(), String>;
    /// Entry `(r, c) = v` from file line `line`; `Err(())` if it was already set.
    fn put(&mut self, r: usize, c: usize, v: f64, line: usize) -> std::result::Result<(), ()>;
    /// Whether the file is symmetric or skew-symmetric (for messages).
    fn symmetry(&mut self, _symmetric: bool) {}
}

struct Dense {
    max_memory: f64,
    m: DMatrix<f64>,
    set: Vec<bool>,
}

/// The refusal of a size line whose matrix would not fit in `limits.max_memory`.
fn too_large(rows: usize, cols: usize, how: &str, estimate: f64, max_memory: f64) -> String {
    format!(
        "matrix size {rows}x{cols} {how} needs about {} of memory (estimate), more than \
         limits.max_memory = {}; set [limits] max_memory (bytes) to allow it",
        bytes(estimate),
        bytes(max_memory)
    )
}

impl Target for Dense {
    fn start(&mut self, rows: usize, cols: usize, _entries: Option<usize>) -> std::result::Result<(), String> {
        // A value and a "set" flag per entry, checked before allocating.
        let estimate = 9.0 * rows as f64 * cols as f64;
        if estimate > self.max_memory || rows.checked_mul(cols).is_none() {
            return Err(too_large(rows, cols, "as a dense matrix", estimate, self.max_memory));
        }
        self.m = DMatrix::zeros(rows, cols);
        self.set = vec![false; rows * cols];
        Ok(())
    }
    fn put(&mut self, r: usize, c: usize, v: f64, _line: usize) -> std::result::Result<(), ()> {
        let rows = self.m.nrows();
        if std::mem::replace(&mut self.set[r + c * rows], true) {
            return Err(());
        }
        self.m[(r, c)] = v;
        Ok(())
    }
}

/// Triplets with their file lines; duplicates are found by sorting at the end.
#[derive(Default)]
struct Sparse {
    max_memory: f64,
    n: usize,
    symmetric_file: bool,
    entries: Vec<(usize, usize, f64, usize)>,
}

impl Target for Sparse {
    fn start(&mut self, rows: usize, cols: usize, entries: Option<usize>) -> std::result::Result<(), String> {
        if rows != cols {
            return Err(format!(
                "matrix size {rows}x{cols} is not square (a model matrix must be)"
            ));
        }
        // The model built from it: per DOF vectors and factor, per entry triplets, CSC and fill
        // (an array's values are bounded by the file size, which is checked before reading).
        let estimate = rows as f64 * CHAIN_BYTES_PER_DOF + entries.unwrap_or(0) as f64 * MTX_BYTES_PER_ENTRY;
        if estimate > self.max_memory {
            return Err(too_large(rows, cols, "as a sparse model", estimate, self.max_memory));
        }
        self.n = rows;
        Ok(())
    }
    fn put(&mut self, r: usize, c: usize, v: f64, line: usize) -> std::result::Result<(), ()> {
        self.entries.push((r, c, v, line));
        Ok(())
    }
    fn symmetry(&mut self, symmetric: bool) {
        self.symmetric_file = symmetric;
    }
}

impl Sparse {
    fn finish(mut self, name: &str) -> Result<CscMatrix> {
        self.entries.sort_unstable_by_key(|&(r, c, _, line)| (c, r, line));
        // The first line (in file order) that repeats an entry, as the dense reader reports it.
        let duplicate = self
            .entries
            .windows(2)
            .filter(|w| (w[0].0, w[0].1) == (w[1].0, w[1].1))
            .map(|w| w[1])
            .min_by_key(|&(r, c, _, line)| (line, c, r));
        if let Some((r, c, _, line)) = duplicate {
            let note = if self.symmetric_file {
                " (a symmetric file lists each off-diagonal pair once)"
            } else {
                ""
            };
            return Err(Error::file(
                name,
                format!("line {line}: entry ({}, {}) is given twice{note}", r + 1, c + 1),
            ));
        }
        let triplets: Vec<(usize, usize, f64)> = self
            .entries
            .iter()
            .filter(|e| e.2 != 0.0)
            .map(|&(r, c, v, _)| (r, c, v))
            .collect();
        Ok(CscMatrix::from_triplets(self.n, &triplets))
    }
}

fn parse_into<T: Target + ?Sized>(text: &str, name: &str, target: &mut T) -> Result<()> {
    let fail = |line: usize, reason: String| Error::file(name, format!("line {line}: {reason}"));
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_start_matches('\u{feff}')));

    let (_, header) = lines
        .next()
        .ok_or_else(|| Error::file(name, "empty file (expected a '%%MatrixMarket' header)"))?;
    let (layout, symmetry) = parse_header(header).map_err(|r| fail(1, r))?;
    target.symmetry(symmetry != Symmetry::General);

    // Size line: the first line that is neither a comment nor blank.
    let mut data = lines.filter(|(_, l)| {
        let t = l.trim();
        !t.is_empty() && !t.starts_with('%')
    });
    let (size_line, size) = data
        .next()
        .ok_or_else(|| Error::file(name, "no size line after the header"))?;
    let dims: Vec<&str> = size.split_whitespace().collect();
    let expected_fields = if layout == Layout::Coordinate { 3 } else { 2 };
    let what = if layout == Layout::Coordinate {
        "rows, columns, entries"
    } else {
        "rows, columns"
    };
    if dims.len() != expected_fields {
        return Err(fail(
            size_line,
            format!(
                "size line must hold {expected_fields} integers ({what}), found '{}'",
                size.trim()
            ),
        ));
    }
    let parse_count = |s: &str| -> Result<usize> {
        s.parse::<usize>()
            .map_err(|_| fail(size_line, format!("cannot parse '{s}' as a non-negative integer")))
    };
    let rows = parse_count(dims[0])?;
    let cols = parse_count(dims[1])?;
    if rows == 0 || cols == 0 {
        return Err(fail(size_line, format!("matrix size {rows}x{cols} is empty")));
    }
    if symmetry != Symmetry::General && rows != cols {
        return Err(fail(
            size_line,
            format!("a symmetric matrix must be square, the size line says {rows}x{cols}"),
        ));
    }
    let declared = if layout == Layout::Coordinate {
        Some(parse_count(dims[2])?)
    } else {
        None
    };
    target.start(rows, cols, declared).map_err(|r| fail(size_line, r))?;

    let value = |line: usize, s: &str| -> Result<f64> {
        let v: f64 = s
            .parse()
            .map_err(|_| fail(line, format!("cannot parse '{s}' as a number")))?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(fail(line, format!("value is not finite ({s})")))
        }
    };

    match layout {
        Layout::Coordinate => {
            let nnz = declared.unwrap_or(0);
            let max_nnz = stored_count(symmetry, rows, cols);
            if nnz > max_nnz {
                return Err(fail(
                    size_line,
                    format!("{nnz} entries declared but a {rows}x{cols} matrix of this kind holds at most {max_nnz}"),
                ));
            }
            let mut count = 0;
            for (line, l) in data {
                let f: Vec<&str> = l.split_whitespace().collect();
                if f.len() != 3 {
                    return Err(fail(
                        line,
                        format!("expected 3 fields (row, column, value), found {}", f.len()),
                    ));
                }
                if count == nnz {
                    return Err(fail(
                        line,
                        format!("more entries than the {nnz} declared in the size line (line {size_line})"),
                    ));
                }
                let index = |s: &str, what: &str, n: usize| -> Result<usize> {
                    match s.parse::<usize>() {
                        Ok(i) if (1..=n).contains(&i) => Ok(i - 1),
                        Ok(i) => Err(fail(line, format!("{what} index {i} is out of range 1..={n}"))),
                        Err(_) => Err(fail(line, format!("cannot parse '{s}' as a {what} index"))),
                    }
                };
                let i = index(f[0], "row", rows)?;
                let j = index(f[1], "column", cols)?;
                let v = value(line, f[2])?;
                if symmetry == Symmetry::SkewSymmetric && i == j {
                    return Err(fail(
                        line,
                        format!("diagonal entry ({}, {}) in a skew-symmetric file", i + 1, j + 1),
                    ));
                }
                let mut put = |r: usize, c: usize, v: f64| -> Result<()> {
                    if target.put(r, c, v, line).is_err() {
                        let note = if symmetry == Symmetry::General {
                            ""
                        } else {
                            " (a symmetric file lists each off-diagonal pair once)"
                        };
                        return Err(fail(line, format!("entry ({}, {}) is given twice{note}", r + 1, c + 1)));
                    }
                    Ok(())
                };
                put(i, j, v)?;
                if i != j {
                    match symmetry {
                        Symmetry::General => {}
                        Symmetry::Symmetric => put(j, i, v)?,
                        Symmetry::SkewSymmetric => put(j, i, -v)?,
                    }
                }
                count += 1;
            }
            if count != nnz {
                return Err(Error::file(
                    name,
                    format!("the size line (line {size_line}) declares {nnz} entries but {count} were found"),
                ));
            }
        }
        Layout::Array => {
            // Positions in storage order (column-major, lower triangle for symmetric kinds),
            // walked one by one: the size line alone must not allocate.
            let total = stored_count(symmetry, rows, cols);
            let first_row = |j: usize| match symmetry {
                Symmetry::General => 0,
                Symmetry::Symmetric => j,
                Symmetry::SkewSymmetric => j + 1,
            };
            let (mut i, mut j) = (first_row(0), 0);
            let mut count = 0;
            for (line, l) in data {
                for field in l.split_whitespace() {
                    if count >= total {
                        return Err(fail(
                            line,
                            format!("more values than the {total} a {rows}x{cols} array holds"),
                        ));
                    }
                    while i >= rows {
                        j += 1;
                        i = first_row(j);
                    }
                    let v = value(line, field)?;
                    // Array positions are distinct, so `put` cannot report a duplicate here.
                    let _ = target.put(i, j, v, line);
                    match symmetry {
                        Symmetry::General => {}
                        Symmetry::Symmetric if i != j => {
                            let _ = target.put(j, i, v, line);
                        }
                        Symmetry::Symmetric => {}
                        Symmetry::SkewSymmetric => {
                            let _ = target.put(j, i, -v, line);
                        }
                    }
                    count += 1;
                    i += 1;
                }
            }
            if count != total {
                return Err(Error::file(
                    name,
                    format!("a {rows}x{cols} array needs {total} values but {count} were found"),
                ));
            }
        }
    }
    Ok(())
}

/// How many entries a file of this symmetry stores for a `rows × cols` matrix (saturating).
fn stored_count(symmetry: Symmetry, rows: usize, cols: usize) -> usize {
    match symmetry {
        Symmetry::General => rows.saturating_mul(cols),
        Symmetry::Symmetric => rows.saturating_mul(rows.saturating_add(1)) / 2,
        Symmetry::SkewSymmetric => rows.saturating_mul(rows.saturating_sub(1)) / 2,
    }
}

/// The head check of the readers: the first line must be a MatrixMarket banner, so a file of
/// another kind is refused after its first 64 KiB, not after reading all of it.
fn check_banner(head: &[u8]) -> std::result::Result<(), String> {
    let first = head.split(|&b| b == b'\n').next().unwrap_or(&[]);
    let first = String::from_utf8_lossy(first);
    let first = first.trim_start_matches('\u{feff}');
    if !first.trim_start().to_ascii_lowercase().starts_with("%%matrixmarket") {
        // The parser's own message for a wrong first line (quoting at most 80 characters).
        let shown: String = first.chars().take(80).collect();
        return parse_header(&shown).map(|_| ()).map_err(|r| format!("line 1: {r}"));
    }
    Ok(())
}

fn parse_header(header: &str) -> std::result::Result<(Layout, Symmetry), String> {
    let words: Vec<String> = header.split_whitespace().map(str::to_ascii_lowercase).collect();
    let expected = "expected '%%MatrixMarket matrix coordinate|array real|integer general|symmetric|skew-symmetric'";
    if words.first().map(String::as_str) != Some("%%matrixmarket") {
        return Err(format!(
            "not a MatrixMarket file: {expected}, found '{}'",
            header.trim()
        ));
    }
    if words.len() != 5 {
        return Err(format!("bad header '{}': {expected}", header.trim()));
    }
    if words[1] != "matrix" {
        return Err(format!("object '{}' is not supported (only 'matrix')", words[1]));
    }
    let layout = match words[2].as_str() {
        "coordinate" => Layout::Coordinate,
        "array" => Layout::Array,
        other => return Err(format!("format '{other}' is not supported (coordinate or array)")),
    };
    match words[3].as_str() {
        "real" | "integer" | "double" => {}
        other => {
            return Err(format!(
                "field '{other}' is not supported (real or integer; pattern and complex matrices cannot be used)"
            ));
        }
    }
    let symmetry = match words[4].as_str() {
        "general" => Symmetry::General,
        "symmetric" => Symmetry::Symmetric,
        "skew-symmetric" => Symmetry::SkewSymmetric,
        other => {
            return Err(format!(
                "symmetry '{other}' is not supported (general, symmetric or skew-symmetric)"
            ));
        }
    };
    Ok((layout, symmetry))
}

/// Write the symmetric `a` as `%%MatrixMarket matrix coordinate real symmetric` (its lower
/// triangle, 1-based, values with 17 significant digits so that they read back bit for bit);
/// `comment` lines go after the header.
pub fn write_matrix_market_symmetric(
    out: &mut impl std::io::Write,
    a: &CscMatrix,
    comment: &str,
) -> std::io::Result<()> {
    let (cp, ri, vals) = a.lower_triangle();
    writeln!(out, "%%MatrixMarket matrix coordinate real symmetric")?;
    for line in comment.lines() {
        writeln!(out, "% {line}")?;
    }
    writeln!(out, "{} {} {}", a.n(), a.n(), vals.len())?;
    for j in 0..a.n() {
        for k in cp[j]..cp[j + 1] {
            writeln!(out, "{} {} {:.16e}", ri[k] + 1, j + 1, vals[k])?;
        }
    }
    Ok(())
}

/// Write the vector `v` as `%%MatrixMarket matrix array real general` (`n × 1`).
pub fn write_matrix_market_vector(out: &mut impl std::io::Write, v: &[f64], comment: &str) -> std::io::Result<()> {
    writeln!(out, "%%MatrixMarket matrix array real general")?;
    for line in comment.lines() {
        writeln!(out, "% {line}")?;
    }
    writeln!(out, "{} 1", v.len())?;
    for x in v {
        writeln!(out, "{x:.16e}")?;
    }
    Ok(())
}

/// Write `model` and its coupling DOFs (0-based) into `dir` (each file atomically): `M.mtx`,
/// `C.mtx`, `K.mtx` (symmetric coordinate), `influence.mtx` (`n × 1` array) and `coupling.txt`
/// (1-based, one per line), so that another tool runs on exactly these matrices (`substep model
/// export`, `substep bench --compare`). `what` goes into each file's comment.
pub fn export_model(model: &crate::model::SparseModel, coupling: &[usize], dir: &Path, what: &str) -> Result<()> {
    std::fs::create_dir_all(dir)
        .map_err(|e| Error::file(dir.display().to_string(), format!("cannot create the directory: {e}")))?;
    let write = |name: &str, f: &dyn Fn(&mut BufWriter<std::fs::File>) -> std::io::Result<()>| -> Result<()> {
        let path = dir.join(name);
        crate::atomic_file::replace_atomic(&path, |tmp| {
            let mut w = BufWriter::new(std::fs::File::create(tmp)?);
            f(&mut w)?;
            w.flush()
        })
        .map_err(|e| Error::write(&path, e))
    };
    for (name, m, label) in [
        ("M.mtx", &model.mass, "mass M [kg]"),
        ("C.mtx", &model.damping, "damping C [N s/m]"),
        ("K.mtx", &model.stiffness, "stiffness K [N/m]"),
    ] {
        write(name, &|w| {
            write_matrix_market_symmetric(w, m, &format!("{label}, {what}"))
        })?;
    }
    write("influence.mtx", &|w| {
        write_matrix_market_vector(w, model.influence.as_slice(), &format!("influence vector, {what}"))
    })?;
    write("coupling.txt", &|w| {
        coupling.iter().try_for_each(|d| writeln!(w, "{}", d + 1))
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dmatrix;

    fn parse(text: &str) -> Result<DMatrix<f64>> {
        parse_matrix_market(text, "K.mtx")
    }
    fn err(text: &str) -> String {
        parse(text).unwrap_err().to_string()
    }

    #[test]
    fn coordinate_general_and_integer() {
        let m = parse("%%MatrixMarket matrix coordinate real general\n% comment\n2 3 3\n1 1 1.5\n2 3 -2e3\n1 2 4\n")
            .unwrap();
        assert_eq!(m, dmatrix![1.5, 4.0, 0.0; 0.0, 0.0, -2000.0]);
        let m = parse("%%MatrixMarket matrix coordinate integer general\n1 1 1\n1 1 7\n").unwrap();
        assert_eq!(m, dmatrix![7.0]);
    }

    #[test]
    fn coordinate_symmetric_mirrors_either_triangle() {
        let lower = parse("%%MatrixMarket matrix coordinate real symmetric\n2 2 3\n1 1 2\n2 1 -1\n2 2 1\n").unwrap();
        let upper = parse("%%MatrixMarket matrix coordinate real symmetric\n2 2 3\n1 1 2\n1 2 -1\n2 2 1\n").unwrap();
        assert_eq!(lower, dmatrix![2.0, -1.0; -1.0, 1.0]);
        assert_eq!(lower, upper);
        let skew = parse("%%MatrixMarket matrix coordinate real skew-symmetric\n2 2 1\n2 1 3\n").unwrap();
        assert_eq!(skew, dmatrix![0.0, -3.0; 3.0, 0.0]);
    }

    #[test]
    fn array_general_and_symmetric() {
        let m = parse("%%MatrixMarket matrix array real general\n2 2\n1\n2\n3\n4\n").unwrap();
        assert_eq!(m, dmatrix![1.0, 3.0; 2.0, 4.0]);
        let s = parse("%%MatrixMarket matrix array real symmetric\n2 2\n4 -1\n3\n").unwrap();
        assert_eq!(s, dmatrix![4.0, -1.0; -1.0, 3.0]);
    }

    #[test]
    fn sparse_reader_matches_dense_and_finds_duplicates() {
        for text in [
            "%%MatrixMarket matrix coordinate real symmetric\n3 3 4\n1 1 2\n2 1 -1\n2 2 2\n3 3 0.5\n",
            "%%MatrixMarket matrix array real symmetric\n2 2\n4 -1\n3\n",
            "%%MatrixMarket matrix coordinate real general\n2 2 3\n1 1 1\n2 2 1\n1 2 0\n",
        ] {
            let d = parse(text).unwrap();
            let s = parse_matrix_market_sparse(text, "K.mtx").unwrap();
            assert_eq!(s.to_dense(), d);
        }
        let e = parse_matrix_market_sparse(
            "%%MatrixMarket matrix coordinate real symmetric\n2 2 3\n2 1 1\n1 1 1\n1 2 1\n",
            "K.mtx",
        )
        .unwrap_err()
        .to_string();
        assert_eq!(
            e,
            "K.mtx: line 5: entry (2, 1) is given twice (a symmetric file lists each off-diagonal pair once)"
        );
        let e = parse_matrix_market_sparse("%%MatrixMarket matrix coordinate real general\n2 3 0\n", "K.mtx")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "K.mtx: line 2: matrix size 2x3 is not square (a model matrix must be)"
        );
        // No dense n x n storage: a 200 000-DOF diagonal reads fine.
        let mut big = String::from("%%MatrixMarket matrix coordinate real general\n200000 200000 200000\n");
        for i in 1..=200_000 {
            big.push_str(&format!("{i} {i} 1\n"));
        }
        assert_eq!(parse_matrix_market_sparse(&big, "M.mtx").unwrap().nnz(), 200_000);
    }

    #[test]
    fn errors_name_file_and_line() {
        assert_eq!(
            err("%%MatrixMarket matrix coordinate complex general\n1 1 1\n1 1 1 0\n"),
            "K.mtx: line 1: field 'complex' is not supported (real or integer; pattern and complex matrices cannot be used)"
        );
        assert!(err("1 2 3\n").starts_with("K.mtx: line 1: not a MatrixMarket file"));
        assert_eq!(
            err("%%MatrixMarket matrix coordinate real general\n3 3 2\n1 1 1\n4 1 2\n"),
            "K.mtx: line 4: row index 4 is out of range 1..=3"
        );
        assert_eq!(
            err("%%MatrixMarket matrix coordinate real general\n2 2 3\n1 1 1\n2 2 1\n"),
            "K.mtx: the size line (line 2) declares 3 entries but 2 were found"
        );
        assert_eq!(
            err("%%MatrixMarket matrix coordinate real general\n2 2 1\n1 1 1\n2 2 1\n"),
            "K.mtx: line 4: more entries than the 1 declared in the size line (line 2)"
        );
        assert_eq!(
            err("%%MatrixMarket matrix coordinate real general\n2 2 1\n\n1 1 nan\n"),
            "K.mtx: line 4: value is not finite (nan)"
        );
        assert_eq!(
            err("%%MatrixMarket matrix array real general\n2 2\n1 2 3\n"),
            "K.mtx: a 2x2 array needs 4 values but 3 were found"
        );
        assert_eq!(
            err("%%MatrixMarket matrix coordinate real symmetric\n2 2 2\n2 1 1\n1 2 1\n"),
            "K.mtx: line 4: entry (1, 2) is given twice (a symmetric file lists each off-diagonal pair once)"
        );
        assert_eq!(
            err("%%MatrixMarket matrix coordinate real general\n2 2 2\n1 1 1\n1 1 2\n"),
            "K.mtx: line 4: entry (1, 1) is given twice"
        );
        assert_eq!(
            err("%%MatrixMarket matrix coordinate real general\n2 x 1\n"),
            "K.mtx: line 2: cannot parse 'x' as a non-negative integer"
        );
        assert!(
            read_matrix_market("/nonexistent/M.mtx")
                .unwrap_err()
                .to_string()
                .starts_with("/nonexistent/M.mtx: cannot read file")
        );
    }
}
