//! The HDF5 / MATLAB v7.3 writer behind [`write_container`](super::write_container).
//!
//! MATLAB v7.3 files are HDF5 files with a 512-byte user block whose first 128 bytes are the
//! MATLAB text header; MATLAB stores arrays column-major, so an `m×n` MATLAB array is an HDF5
//! dataset of dims `(n, m)`: a column vector of N samples is written as `(1, N)`. Every
//! variable carries `MATLAB_class`; a struct is a group with `MATLAB_class = "struct"` and
//! `MATLAB_fields` (the field names as variable-length arrays of single characters), the
//! convention MATLAB itself writes and `hdf5storage` / `mat73` read.

use super::{BLOCK_ROWS, CsvTable, Metadata, column_unit, created_on, matlab_name, split_header};
use crate::error::{Error, Result};
use hdf5::types::{FixedAscii, VarLenArray, VarLenUnicode};
use hdf5::{Extent, File, Location};
use std::io::{BufReader, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Samples per chunk of a column dataset (64 KiB of `f64`).
const CHUNK: usize = 8192;
/// Deflate level: 4 compresses histories about as well as 9, at a fraction of the time.
const DEFLATE: u8 = 4;
/// The user block MATLAB v7.3 files start with.
const USER_BLOCK: u64 = 512;

fn h5err(what: &str) -> impl Fn(hdf5::Error) -> Error + '_ {
    move |e| Error::file(what, format!("HDF5: {e}"))
}

pub(super) fn write_file(
    tmp: &Path,
    mat: bool,
    tables: &[(&str, PathBuf)],
    meta: &Metadata,
    shown: &str,
) -> Result<()> {
    let err = h5err(shown);
    {
        let file = File::with_options()
            .with_fcpl(|p| {
                // No modification times in the objects: a rerun writes the same bytes.
                p.obj_track_times(false).userblock(if mat { USER_BLOCK } else { 0 })
            })
            .create(tmp)
            .map_err(&err)?;
        for (name, csv) in tables {
            let csv_name = csv.display().to_string();
            let f = std::fs::File::open(csv).map_err(|e| Error::file(&csv_name, format!("cannot open: {e}")))?;
            let mut table = CsvTable::new(csv_name, BufReader::new(f))?;
            if mat {
                mat_table(&file, name, &mut table).map_err(&err)?;
            } else {
                h5_table(&file, name, &mut table).map_err(&err)?;
            }
        }
        if mat {
            mat_char(&file, "summary", &meta.summary_json).map_err(&err)?;
            mat_char(&file, "config", &meta.config).map_err(&err)?;
        } else {
            str_attr(&file, "summary", &meta.summary_json).map_err(&err)?;
            str_attr(&file, "config", &meta.config).map_err(&err)?;
            str_attr(&file, "creator", &format!("substep {}", env!("CARGO_PKG_VERSION"))).map_err(&err)?;
        }
        file.close().map_err(&err)?;
    }
    if mat {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .open(tmp)
            .map_err(|e| Error::file(shown, format!("cannot write the MATLAB header: {e}")))?;
        f.seek(SeekFrom::Start(0))
            .and_then(|_| f.write_all(&matlab_header(created_on())))
            .and_then(|()| f.sync_all())
            .map_err(|e| Error::file(shown, format!("cannot write the MATLAB header: {e}")))?;
    }
    Ok(())
}

type H5 = hdf5::Result<()>;

fn str_attr(loc: &Location, name: &str, value: &str) -> H5 {
    let v: VarLenUnicode = value
        .parse()
        .map_err(|e| hdf5::Error::from(format!("attribute {name}: {e}")))?;
    loc.new_attr::<VarLenUnicode>().create(name)?.write_scalar(&v)
}

fn str_list_attr(loc: &Location, name: &str, values: &[String]) -> H5 {
    let v: Vec<VarLenUnicode> = values
        .iter()
        .map(|s| s.parse())
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| hdf5::Error::from(format!("attribute {name}: {e}")))?;
    loc.new_attr::<VarLenUnicode>().shape(v.len()).create(name)?.write(&v)
}

/// An HDF5 table: a group with one resizable, chunked, compressed 1-D dataset per column.
fn h5_table<R: std::io::BufRead>(file: &File, name: &str, table: &mut CsvTable<R>) -> H5 {
    let group = file
        .create_group_builder()
        .with_gcpl(|p| p.link_creation_order(hdf5::plist::group_create::LinkCreationOrder::Indexed))
        .create(name)?;
    let names: Vec<String> = table.columns().iter().map(|c| split_header(c).0.to_owned()).collect();
    str_list_attr(&group, "columns", &names)?;
    let mut datasets = Vec::with_capacity(table.columns().len());
    for (c, n) in table.columns().iter().zip(&names) {
        let ds = group
            .new_dataset::<f64>()
            .chunk(CHUNK)
            .deflate(DEFLATE)
            .shape(Extent::resizable(0))
            .create(n.as_str())?;
        str_attr(&ds, "units", column_unit(name, c))?;
        datasets.push(ds);
    }
    stream(table, |col, start, data| {
        let ds = &datasets[col];
        ds.resize(start + data.len())?;
        ds.write_slice(data, start..start + data.len())
    })
}

/// A MATLAB struct of column vectors (dims `(1, N)` in HDF5).
fn mat_table<R: std::io::BufRead>(file: &File, name: &str, table: &mut CsvTable<R>) -> H5 {
    let group = file.create_group(&matlab_name(name))?;
    let fields: Vec<String> = table.columns().iter().map(|c| matlab_name(split_header(c).0)).collect();
    fixed_attr::<6>(&group, "MATLAB_class", "struct")?;
    let names: Vec<VarLenArray<FixedAscii<1>>> = fields
        .iter()
        .map(|f| {
            let chars: Vec<FixedAscii<1>> = f
                .bytes()
                .map(|b| FixedAscii::from_ascii(&[b]).expect("matlab_name is ASCII"))
                .collect();
            VarLenArray::from_slice(&chars)
        })
        .collect();
    group
        .new_attr::<VarLenArray<FixedAscii<1>>>()
        .shape(names.len())
        .create("MATLAB_fields")?
        .write(&names)?;
    let mut datasets = Vec::with_capacity(fields.len());
    for f in &fields {
        let ds = group
            .new_dataset::<f64>()
            .chunk((1, CHUNK))
            .deflate(DEFLATE)
            .shape((1, Extent::resizable(0)))
            .create(f.as_str())?;
        fixed_attr::<6>(&ds, "MATLAB_class", "double")?;
        datasets.push(ds);
    }
    stream(table, |col, start, data| {
        let ds = &datasets[col];
        ds.resize((1, start + data.len()))?;
        ds.write_slice(data, (0, start..start + data.len()))
    })
}

/// Feed the table in blocks of [`BLOCK_ROWS`] rows to `write(column, first_row, values)`.
fn stream<R: std::io::BufRead>(table: &mut CsvTable<R>, mut write: impl FnMut(usize, usize, &[f64]) -> H5) -> H5 {
    let mut block: Vec<Vec<f64>> = (0..table.columns().len())
        .map(|_| Vec::with_capacity(BLOCK_ROWS))
        .collect();
    let mut start = 0;
    loop {
        block.iter_mut().for_each(Vec::clear);
        let rows = table
            .read_block(&mut block, BLOCK_ROWS)
            .map_err(|e| hdf5::Error::from(e.to_string()))?;
        if rows == 0 {
            return Ok(());
        }
        for (k, col) in block.iter().enumerate() {
            write(k, start, col)?;
        }
        start += rows;
    }
}

/// A fixed-length ASCII string attribute of exactly `N` characters (MATLAB reads its class
/// names from such attributes).
fn fixed_attr<const N: usize>(loc: &Location, name: &str, value: &str) -> H5 {
    let v = FixedAscii::<N>::from_ascii(value).map_err(|e| hdf5::Error::from(format!("{name}: {e}")))?;
    loc.new_attr::<FixedAscii<N>>().create(name)?.write_scalar(&v)
}

/// A MATLAB char row vector: UTF-16 code units, dims `(len, 1)` in HDF5.
fn mat_char(file: &File, name: &str, text: &str) -> H5 {
    let units: Vec<u16> = text.encode_utf16().collect();
    if units.is_empty() {
        return Ok(()); // MATLAB's empty arrays need their own encoding; nothing to store
    }
    let ds = file
        .new_dataset::<u16>()
        .chunk((units.len().min(CHUNK), 1))
        .deflate(DEFLATE)
        .shape((units.len(), 1))
        .create(name)?;
    ds.write_raw(&units)?;
    fixed_attr::<4>(&ds, "MATLAB_class", "char")?;
    ds.new_attr::<i32>().create("MATLAB_int_decode")?.write_scalar(&2)
}

/// The 128 bytes MATLAB v7.3 files begin with: the text header padded with spaces to 116
/// bytes, 8 bytes of subsystem offset (spaces: none), version 0x0200 and the endian marker
/// "IM" (little-endian writer); the rest of the 512-byte user block is zeros.
fn matlab_header(created: String) -> Vec<u8> {
    let text = format!("MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: {created} HDF5 schema 1.00 .");
    let mut h = vec![0u8; USER_BLOCK as usize];
    let n = text.len().min(116);
    h[..n].copy_from_slice(&text.as_bytes()[..n]);
    h[n..124].fill(b' ');
    h[124..128].copy_from_slice(&[0x00, 0x02, b'I', b'M']);
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matlab_header_layout() {
        let h = matlab_header(crate::io::results::asctime(0));
        assert_eq!(h.len(), 512);
        assert!(h.starts_with(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Thu Jan  1 00:00:00 1970"));
        assert_eq!(&h[116..124], b"        ");
        assert_eq!(&h[124..128], &[0, 2, b'I', b'M']);
        assert!(h[128..].iter().all(|&b| b == 0));
    }
}
