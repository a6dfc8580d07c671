//! The HDF5 / MATLAB v7.3 writer behind [`write_container`](super::write_container), in pure
//! Rust (`hdf5-pure`): no system library, in every build.
//!
//! MATLAB v7.3 files are HDF5 files with a 512-byte user block whose first 128 bytes are the
//! MATLAB text header; MATLAB stores arrays column-major, so an `m×n` MATLAB array is an HDF5
//! dataset of dims `(n, m)`: a column vector of N samples is written as `(1, N)`. Every
//! variable carries `MATLAB_class`; a struct is a group with `MATLAB_class = "struct"` and
//! `MATLAB_fields`, the convention MATLAB itself writes and `hdf5storage` / `mat73` read
//! (`hdf5_pure::mat` writes that layout).
//!
//! Memory does not grow with the run: `.h5` columns are created with the first block of
//! [`BLOCK_ROWS`] rows and extended a block at a time (chunked, unlimited, deflate); a `.mat`'s
//! columns are first copied column-block-wise into a scratch file beside the output, then
//! streamed from it into MATLAB's contiguous layout (uncompressed: MATLAB's `load` reads the
//! HDF5 1.8 format, and compressed storage needs 1.10).

use super::table::{BLOCK_ROWS, CsvTable, Metadata, column_unit, created_on, matlab_name, split_header};
use crate::error::{Error, Result};
use hdf5_pure::mat::{Block, Compression, DataProducer, MatBuilder, MatError, Options};
use hdf5_pure::{AttrValue, FileAccessProperties, FileBuilder, MaxExtent, MemoryStrategy, SyncPolicy};
use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Deflate level: 4 compresses histories about as well as 9, at a fraction of the time.
const DEFLATE: u32 = 4;
/// The user block MATLAB v7.3 files start with.
const USER_BLOCK: usize = 512;

fn open_table(csv: &Path) -> Result<CsvTable<BufReader<File>>> {
    let csv_name = csv.display().to_string();
    let f = File::open(csv).map_err(|e| Error::file(&csv_name, format!("cannot open: {e}")))?;
    CsvTable::new(csv_name, BufReader::new(f))
}

fn empty_block(columns: usize) -> Vec<Vec<f64>> {
    (0..columns).map(|_| Vec::with_capacity(BLOCK_ROWS)).collect()
}

fn read_next(table: &mut CsvTable<BufReader<File>>, block: &mut [Vec<f64>]) -> Result<usize> {
    block.iter_mut().for_each(Vec::clear);
    table.read_block(block, BLOCK_ROWS)
}

/// A group per table with one chunked (one block per chunk), deflate-compressed 1-D dataset
/// per column (`units` attribute) and the column order in `columns`; the summary and config as
/// root attributes.
pub(super) fn write_h5(tmp: &Path, tables: &[(&str, PathBuf)], meta: &Metadata, shown: &str) -> Result<()> {
    let h5 = |e: hdf5_pure::Error| Error::file(shown, format!("HDF5: {e}"));
    let mut file = FileBuilder::new();
    let mut open = Vec::with_capacity(tables.len());
    for (name, csv) in tables {
        let mut table = open_table(csv)?;
        let headers = table.columns().to_vec();
        let mut block = empty_block(headers.len());
        read_next(&mut table, &mut block)?;
        let mut group = file.create_group(name);
        let names: Vec<String> = headers.iter().map(|c| split_header(c).0.to_owned()).collect();
        group.set_attr("columns", AttrValue::VarLenStringArray(names.clone()));
        for ((header, n), data) in headers.iter().zip(&names).zip(&block) {
            group
                .create_dataset(n)
                .with_f64_data(data)
                .with_maxshape(&[MaxExtent::Unlimited])
                .with_chunks(&[BLOCK_ROWS as u64])
                .with_deflate(DEFLATE)
                .set_attr("units", AttrValue::VarLenString(column_unit(name, header).to_owned()));
        }
        file.add_group(group.finish());
        open.push((*name, names, table, block));
    }
    file.set_attr("summary", AttrValue::VarLenString(meta.summary_json.clone()));
    file.set_attr("config", AttrValue::VarLenString(meta.config.clone()));
    file.set_attr(
        "creator",
        AttrValue::VarLenString(format!("substep {}", env!("CARGO_PKG_VERSION"))),
    );
    file.write(tmp).map_err(h5)?;
    // The rest of every table, a block at a time; durability once at close (the file is a
    // temporary until renamed into place, so a crash mid-way loses nothing of the run's).
    let access = FileAccessProperties::new()
        .with_memory_strategy(MemoryStrategy::Bounded)
        .with_sync_policy(SyncPolicy::OnClose);
    let file = hdf5_pure::File::open_rw_with_options(tmp, access).map_err(h5)?;
    for (name, names, table, block) in &mut open {
        let mut datasets = Vec::with_capacity(names.len());
        for n in names.iter() {
            datasets.push(file.dataset(&format!("{name}/{n}")).map_err(h5)?);
        }
        while read_next(table, block)? > 0 {
            for (ds, data) in datasets.iter_mut().zip(block.iter()) {
                ds.append(data).map_err(h5)?;
            }
        }
    }
    file.close().map_err(h5)
}

/// One table copied into the scratch file: blocks of [`BLOCK_ROWS`] rows back to back, each
/// block column-major, so a column is read back as one run per block.
struct ScratchTable {
    name: String,
    headers: Vec<String>,
    rows: usize,
    /// Byte offset of the table's first block in the scratch file.
    start: u64,
}

/// The scratch file of a `.mat` write, removed when dropped.
struct Scratch {
    path: PathBuf,
    file: Arc<File>,
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// One column of a scratch table, handed to the MAT writer a block at a time.
struct ColumnProducer {
    file: Arc<File>,
    start: u64,
    rows: usize,
    columns: usize,
    column: usize,
}

impl DataProducer for ColumnProducer {
    fn block_bytes(&self, block: Block, out: &mut Vec<u8>) -> std::result::Result<(), MatError> {
        let (mut row, end) = (
            block.first_element as usize,
            (block.first_element + block.elements) as usize,
        );
        while row < end {
            let k = row / BLOCK_ROWS;
            let block_rows = BLOCK_ROWS.min(self.rows - k * BLOCK_ROWS);
            let in_block = row - k * BLOCK_ROWS;
            let n = (block_rows - in_block).min(end - row);
            let offset = self.start + 8 * (k * BLOCK_ROWS * self.columns + self.column * block_rows + in_block) as u64;
            let at = out.len();
            out.resize(at + 8 * n, 0);
            self.file.read_exact_at(&mut out[at..], offset)?;
            row += n;
        }
        Ok(())
    }
}

/// A MATLAB struct of column vectors per table, `summary` and `config` as char variables.
pub(super) fn write_mat(tmp: &Path, tables: &[(&str, PathBuf)], meta: &Metadata, shown: &str) -> Result<()> {
    let io = |e: std::io::Error| Error::Output {
        path: shown.to_string(),
        reason: e.to_string(),
    };
    let path = tmp.with_extension("columns.tmp");
    let scratch_file = File::options()
        .read(true)
        .write(true)
        .create(true)
        .truncate(true)
        .open(&path)
        .map_err(io)?;
    let scratch = Scratch {
        path,
        file: Arc::new(scratch_file),
    };
    let mut copied = Vec::with_capacity(tables.len());
    {
        let mut out = BufWriter::new(&*scratch.file);
        let mut at = 0u64;
        for (name, csv) in tables {
            let mut table = open_table(csv)?;
            let headers = table.columns().to_vec();
            let mut block = empty_block(headers.len());
            let (start, mut rows) = (at, 0);
            loop {
                let n = read_next(&mut table, &mut block)?;
                if n == 0 {
                    break;
                }
                for value in block.iter().flatten() {
                    out.write_all(&value.to_le_bytes()).map_err(io)?;
                }
                rows += n;
                at += 8 * (n * headers.len()) as u64;
            }
            copied.push(ScratchTable {
                name: (*name).to_owned(),
                headers,
                rows,
                start,
            });
        }
        out.flush().map_err(io)?;
    }
    let mut options = Options::default();
    options.compression = Compression::None;
    let mut mat = MatBuilder::new(options);
    let to_error = |e: MatError| Error::file(shown, format!("MATLAB v7.3: {e}"));
    for table in &copied {
        mat.struct_(&matlab_name(&table.name), |s| {
            for (column, header) in table.headers.iter().enumerate() {
                let producer = ColumnProducer {
                    file: Arc::clone(&scratch.file),
                    start: table.start,
                    rows: table.rows,
                    columns: table.headers.len(),
                    column,
                };
                let field = matlab_name(split_header(header).0);
                s.builder()
                    .write_blocks::<f64>(&field, &[table.rows, 1], Box::new(producer))?;
            }
            Ok(())
        })
        .map_err(to_error)?;
    }
    if !meta.summary_json.is_empty() {
        mat.write_char("summary", &meta.summary_json).map_err(to_error)?;
    }
    if !meta.config.is_empty() {
        mat.write_char("config", &meta.config).map_err(to_error)?;
    }
    let out = File::create(tmp).map_err(io)?;
    mat.finish_to(BufWriter::new(&out)).map_err(to_error)?;
    out.write_all_at(&matlab_header(created_on()), 0).map_err(io)?;
    out.sync_all().map_err(io)?;
    drop(scratch);
    Ok(())
}

/// The 128 bytes MATLAB v7.3 files begin with: the text header padded with spaces to 116
/// bytes, 8 bytes of subsystem offset (spaces: none), version 0x0200 and the endian marker
/// "IM" (little-endian writer); the rest of the 512-byte user block is zeros.
fn matlab_header(created: String) -> Vec<u8> {
    let text = format!("MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: {created} HDF5 schema 1.00 .");
    let mut h = vec![0u8; USER_BLOCK];
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
        let h = matlab_header(super::super::table::asctime(0));
        assert_eq!(h.len(), 512);
        assert!(h.starts_with(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Thu Jan  1 00:00:00 1970"));
        assert_eq!(&h[116..124], b"        ");
        assert_eq!(&h[124..128], &[0, 2, b'I', b'M']);
        assert!(h[128..].iter().all(|&b| b == 0));
    }
}
