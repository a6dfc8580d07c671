//! Small files replaced atomically (`summary.json`, `realtime.json`, figures): written to a
//! hidden temporary file beside the target, synced, renamed over it. A run killed at any moment
//! leaves either the old or the new file, never half of one.

use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// The temporary file [`write_atomic`] writes before renaming it to `path`: hidden, in the
/// same directory (a rename within one file system is atomic), same extension (the PNG
/// encoder picks the format from it).
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let tmp = match name.rsplit_once('.') {
        Some((stem, ext)) => format!(".{stem}.tmp.{ext}"),
        None => format!(".{name}.tmp"),
    };
    path.with_file_name(tmp)
}

/// Replace `path` atomically by what `write` puts into the file at the given temporary path:
/// written, synced to disk, then renamed over `path` (and the directory synced). On any error
/// the temporary file is removed and `path` is unchanged.
pub fn replace_atomic(path: &Path, write: impl FnOnce(&Path) -> io::Result<()>) -> io::Result<()> {
    let tmp = temp_path(path);
    let result = write(&tmp).and_then(|()| {
        File::open(&tmp)?.sync_all()?;
        std::fs::rename(&tmp, path)
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
        return result;
    }
    // The rename is durable once the directory is synced; not every file system allows it.
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
        && let Ok(d) = File::open(dir)
    {
        let _ = d.sync_all();
    }
    Ok(())
}

/// [`replace_atomic`] with the given bytes.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    replace_atomic(path, |tmp| {
        let mut f = File::create(tmp)?;
        f.write_all(bytes)?;
        f.flush()
    })
}
