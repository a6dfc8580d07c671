//! The MATLAB level-5 MAT-file writer behind [`write_container`](super::write_container)
//! (`--format mat`): pure Rust, no system library, read by MATLAB's `load` and SciPy's
//! `scipy.io.loadmat`.
//!
//! The format (MathWorks, "MAT-File Format", level 5): a 128-byte header (116 bytes of text,
//! 8 bytes of subsystem offset, version `0x0100`, endian marker `IM`), then data elements, each an
//! 8-byte tag (`u32` type, `u32` byte count) and its data padded to a multiple of 8 bytes. A
//! variable is an `miMATRIX` element holding, in order: array flags (`miUINT32` ×2: the class),
//! dimensions (`miINT32`), name (`miINT8`) and the data; a struct holds the field-name length,
//! the field names (each null-padded to that length) and one `miMATRIX` per field with an
//! empty name. Everything is little-endian and uncompressed.
//!
//! Layout written (the same as the v7.3 file): every table is a 1×1 struct of N×1 double
//! columns (`history.u1`), `units` a struct of structs of char (`units.history.u1 = 'm'`),
//! `summary` (the JSON summary) and `config` (the test definition) char row vectors (UTF-8
//! data, `miUTF8`).
//!
//! A table is streamed: its rows are counted first, then the file region of every column is
//! known and each block of [`BLOCK_ROWS`] rows is written in place, so memory does not grow
//! with the length of the run. An element's byte count is a `u32` and MATLAB reads at most
//! 2³¹ − 1 bytes per variable in this format: a larger table is refused with a message that
//! points to `mat73` (MATLAB v7.3).

use super::table::{BLOCK_ROWS, CsvTable, Metadata, column_unit, created_on, matlab_name, split_header};
use crate::error::{Error, Result};
use std::io::{BufReader, BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

const MI_INT8: u32 = 1;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_DOUBLE: u32 = 9;
const MI_MATRIX: u32 = 14;
const MI_UTF8: u32 = 16;
const MX_STRUCT: u32 = 2;
const MX_CHAR: u32 = 4;
const MX_DOUBLE: u32 = 6;
/// The largest variable MATLAB reads from a level-5 file (bytes).
pub const MAX_VARIABLE_BYTES: u64 = (1 << 31) - 1;

/// A small value encoded in memory (units, summary, config).
enum Value {
    Char(String),
    Struct(Vec<(String, Value)>),
}

pub(super) fn write_file(tmp: &Path, tables: &[(&str, PathBuf)], meta: &Metadata, shown: &str) -> Result<()> {
    let io = |e: std::io::Error| Error::Output {
        path: shown.to_string(),
        reason: e.to_string(),
    };
    let file = std::fs::File::create(tmp).map_err(io)?;
    let mut out = BufWriter::new(file);
    out.write_all(&header(&created_on())).map_err(io)?;
    let mut units = Vec::with_capacity(tables.len());
    for (name, csv) in tables {
        let columns = write_table(&mut out, name, csv, shown)?;
        let fields = columns
            .iter()
            .map(|c| {
                (
                    matlab_name(split_header(c).0),
                    Value::Char(column_unit(name, c).to_string()),
                )
            })
            .collect();
        units.push((matlab_name(name), Value::Struct(fields)));
    }
    let mut small = Vec::new();
    for (name, value) in [
        ("units", Value::Struct(units)),
        ("summary", Value::Char(meta.summary_json.clone())),
        ("config", Value::Char(meta.config.clone())),
    ] {
        small.clear();
        encode(&mut small, name, &value);
        if small.len() as u64 > MAX_VARIABLE_BYTES {
            return Err(Error::file(
                shown,
                format!("`{name}` is larger than a level-5 MAT-file holds; use --format mat73 (MATLAB v7.3)"),
            ));
        }
        out.write_all(&small).map_err(io)?;
    }
    let file = out.into_inner().map_err(|e| io(e.into_error()))?;
    file.sync_all().map_err(io)
}

/// The 128-byte file header.
fn header(created: &str) -> [u8; 128] {
    let text = format!("MATLAB 5.0 MAT-file, Platform: GLNXA64, Created on: {created} by substep");
    let mut h = [b' '; 128];
    let n = text.len().min(116);
    h[..n].copy_from_slice(&text.as_bytes()[..n]);
    h[116..124].fill(0);
    h[124..126].copy_from_slice(&0x0100u16.to_le_bytes());
    h[126..128].copy_from_slice(b"IM");
    h
}

const fn pad8(n: usize) -> usize {
    n.div_ceil(8) * 8
}

fn tag(out: &mut Vec<u8>, ty: u32, bytes: usize) {
    out.extend_from_slice(&ty.to_le_bytes());
    out.extend_from_slice(&(bytes as u32).to_le_bytes());
}

fn padded(out: &mut Vec<u8>, ty: u32, data: &[u8]) {
    tag(out, ty, data.len());
    out.extend_from_slice(data);
    out.resize(out.len() + pad8(data.len()) - data.len(), 0);
}

/// Array flags, dimensions and name: the start of every `miMATRIX` body.
fn matrix_head(out: &mut Vec<u8>, class: u32, dims: [u32; 2], name: &str) {
    tag(out, MI_UINT32, 8);
    out.extend_from_slice(&class.to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes());
    tag(out, MI_INT32, 8);
    out.extend_from_slice(&dims[0].to_le_bytes());
    out.extend_from_slice(&dims[1].to_le_bytes());
    padded(out, MI_INT8, name.as_bytes());
}

/// Field-name length (small element) and the names, each null-padded to that length.
fn field_names<'a>(out: &mut Vec<u8>, names: impl Iterator<Item = &'a str> + Clone) {
    let len = names.clone().map(str::len).max().unwrap_or(0) + 1;
    out.extend_from_slice(&((4u32 << 16) | MI_INT32).to_le_bytes());
    out.extend_from_slice(&(len as u32).to_le_bytes());
    let mut data = Vec::new();
    for n in names {
        data.extend_from_slice(n.as_bytes());
        data.resize(data.len() + len - n.len(), 0);
    }
    padded(out, MI_INT8, &data);
}

/// One `miMATRIX` element for `value`, named `name` (empty inside a struct).
fn encode(out: &mut Vec<u8>, name: &str, value: &Value) {
    let start = out.len();
    tag(out, MI_MATRIX, 0);
    match value {
        Value::Char(text) => {
            // UTF-8 data with one MATLAB char per character, as SciPy writes text (SciPy reads
            // miUINT16 text through an 8-bit codec); characters outside the BMP, two MATLAB
            // chars each, become U+FFFD so that the count matches for every reader.
            let text: String = text
                .chars()
                .map(|c| {
                    if u32::from(c) > 0xFFFF {
                        char::REPLACEMENT_CHARACTER
                    } else {
                        c
                    }
                })
                .collect();
            let n = text.chars().count() as u32;
            matrix_head(out, MX_CHAR, [u32::from(n > 0), n], name);
            padded(out, MI_UTF8, text.as_bytes());
        }
        Value::Struct(fields) => {
            matrix_head(out, MX_STRUCT, [1, 1], name);
            field_names(out, fields.iter().map(|(n, _)| n.as_str()));
            for (_, v) in fields {
                encode(out, "", v);
            }
        }
    }
    let body = (out.len() - start - 8) as u32;
    out[start + 4..start + 8].copy_from_slice(&body.to_le_bytes());
}

/// Bytes of one N×1 double field after its `miMATRIX` tag: head (flags 16, dims 16, empty
/// name 8) and the data tag.
const FIELD_HEAD: u64 = 16 + 16 + 8 + 8;

/// Write the table `csv` as the struct `name`; returns its column names.
fn write_table<W: Write + Seek>(out: &mut W, name: &str, csv: &Path, shown: &str) -> Result<Vec<String>> {
    let csv_name = csv.display().to_string();
    let open = || -> Result<CsvTable<BufReader<std::fs::File>>> {
        let f = std::fs::File::open(csv).map_err(|e| Error::file(&csv_name, format!("cannot open: {e}")))?;
        CsvTable::new(csv_name.clone(), BufReader::new(f))
    };
    // Pass 1: the number of rows (and every row parsed, so pass 2 cannot fail half-way).
    let mut table = open()?;
    let columns = table.columns().to_vec();
    let fields: Vec<String> = unique_names(&columns);
    let mut block: Vec<Vec<f64>> = (0..columns.len()).map(|_| Vec::with_capacity(BLOCK_ROWS)).collect();
    let mut rows: u64 = 0;
    loop {
        block.iter_mut().for_each(Vec::clear);
        let n = table.read_block(&mut block, BLOCK_ROWS)?;
        if n == 0 {
            break;
        }
        rows += n as u64;
    }
    let field_bytes = 8 + FIELD_HEAD + rows * 8;
    let mut head = Vec::new();
    tag(&mut head, MI_MATRIX, 0);
    matrix_head(&mut head, MX_STRUCT, [1, 1], &matlab_name(name));
    field_names(&mut head, fields.iter().map(String::as_str));
    let total = head.len() as u64 + field_bytes * fields.len() as u64;
    if total > MAX_VARIABLE_BYTES || rows > u64::from(u32::MAX) {
        return Err(Error::file(
            shown,
            format!(
                "table `{name}` ({rows} rows × {} columns, {:.1} GB) is larger than a level-5 MAT-file \
                 variable (2 GB); use --format mat73 (MATLAB v7.3) or hdf5",
                columns.len(),
                total as f64 / 1e9
            ),
        ));
    }
    head[4..8].copy_from_slice(&((total - 8) as u32).to_le_bytes());
    let io = |e: std::io::Error| Error::Output {
        path: shown.to_string(),
        reason: e.to_string(),
    };
    let base = out.stream_position().map_err(io)?;
    out.write_all(&head).map_err(io)?;
    let data_at = |k: usize| base + head.len() as u64 + field_bytes * k as u64 + 8 + FIELD_HEAD;
    let mut field = Vec::with_capacity((8 + FIELD_HEAD) as usize);
    for k in 0..fields.len() {
        field.clear();
        tag(&mut field, MI_MATRIX, (field_bytes - 8) as usize);
        matrix_head(&mut field, MX_DOUBLE, [rows as u32, 1], "");
        tag(&mut field, MI_DOUBLE, (rows * 8) as usize);
        out.seek(SeekFrom::Start(data_at(k) - 8 - FIELD_HEAD)).map_err(io)?;
        out.write_all(&field).map_err(io)?;
    }
    // Pass 2: the numbers, a block of rows at a time, into each column's region.
    let mut table = open()?;
    let mut done: u64 = 0;
    let mut bytes = Vec::with_capacity(BLOCK_ROWS * 8);
    loop {
        block.iter_mut().for_each(Vec::clear);
        let n = table.read_block(&mut block, BLOCK_ROWS)?;
        if n == 0 {
            break;
        }
        if done + n as u64 > rows {
            return Err(Error::file(&csv_name, "changed while it was being converted"));
        }
        for (k, col) in block.iter().enumerate() {
            bytes.clear();
            bytes.extend(col.iter().flat_map(|x| x.to_le_bytes()));
            out.seek(SeekFrom::Start(data_at(k) + done * 8)).map_err(io)?;
            out.write_all(&bytes).map_err(io)?;
        }
        done += n as u64;
    }
    if done != rows {
        return Err(Error::file(&csv_name, "changed while it was being converted"));
    }
    out.seek(SeekFrom::Start(base + total)).map_err(io)?;
    Ok(columns)
}

/// MATLAB field names for the columns, made unique (`u_1` twice becomes `u_1`, `u_1_2`).
fn unique_names(columns: &[String]) -> Vec<String> {
    let mut seen = std::collections::BTreeSet::new();
    columns
        .iter()
        .map(|c| {
            let base = matlab_name(split_header(c).0);
            let mut name = base.clone();
            let mut i = 2;
            while !seen.insert(name.clone()) {
                let suffix = format!("_{i}");
                name = format!("{}{suffix}", &base[..base.len().min(63 - suffix.len())]);
                i += 1;
            }
            name
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_layout() {
        let h = header("Thu Jan  1 00:00:00 1970");
        assert!(h.starts_with(b"MATLAB 5.0 MAT-file, Platform: GLNXA64, Created on: Thu Jan  1 00:00:00 1970"));
        assert_eq!(&h[116..124], &[0; 8]);
        assert_eq!(&h[124..128], &[0x00, 0x01, b'I', b'M']);
    }

    /// A char variable byte for byte as the format specifies it.
    #[test]
    fn char_element_bytes() {
        let mut out = Vec::new();
        encode(&mut out, "ab", &Value::Char("hi".into()));
        let words: Vec<u32> = out
            .chunks(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        assert_eq!(
            words,
            [
                14,
                64, // miMATRIX, 64 bytes
                6,
                8,
                4,
                0, // flags: mxCHAR
                5,
                8,
                1,
                2, // dims 1×2
                1,
                2,
                u32::from_le_bytes(*b"ab\0\0"),
                0, // name "ab", padded
                16,
                2,
                u32::from_le_bytes(*b"hi\0\0"),
                0, // miUTF8 "hi", padded
            ]
        );
    }

    #[test]
    fn duplicate_field_names_are_made_unique() {
        let cols: Vec<String> = ["u-1", "u_1", "t"].iter().map(|s| s.to_string()).collect();
        assert_eq!(unique_names(&cols), ["u_1", "u_1_2", "t"]);
    }
}
