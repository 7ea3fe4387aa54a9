//! Outputs (files, or folders of them) written under a temporary name beside
//! the final one and renamed into place only when complete, so a failed or aborted run never leaves a
//! partial file under the name the user asked for (and never replaces an older
//! complete one with it).

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

use crate::exit::Failure;

/// Temporary files being written, for an abort to remove.
static OPEN: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn open() -> MutexGuard<'static, Vec<PathBuf>> {
    // A panic while holding the lock leaves the set as it was; it is still right.
    OPEN.lock().unwrap_or_else(|e| e.into_inner())
}

/// One output being written. Dropped without [`Partial::commit`], it removes its temporary file.
pub struct Partial {
    temp: PathBuf,
    dest: PathBuf,
}

impl Partial {
    /// `dir/.name.<pid>.part` for `dir/name`: beside the final file, so the rename
    /// stays on one file system, hidden, and distinct per process.
    pub fn new(dest: &Path) -> Partial {
        let name = dest.file_name().unwrap_or_default().to_string_lossy();
        let temp = dest.with_file_name(format!(".{name}.{}.part", std::process::id()));
        open().push(temp.clone());
        Partial {
            temp,
            dest: dest.to_path_buf(),
        }
    }

    /// Where the pipeline writes.
    pub fn temp(&self) -> &Path {
        &self.temp
    }

    /// The final name.
    pub fn dest(&self) -> &Path {
        &self.dest
    }

    /// Moves the finished file to its final name.
    pub fn commit(self) -> Result<(), Failure> {
        std::fs::rename(&self.temp, &self.dest).map_err(|e| {
            Failure::new(format!(
                "cannot move the finished {} to {}: {e}",
                self.temp.display(),
                self.dest.display()
            ))
        })
    }
}

impl Drop for Partial {
    fn drop(&mut self) {
        // After a commit the file is gone from here; removing it again is harmless.
        remove(&self.temp);
        open().retain(|t| *t != self.temp);
    }
}

/// Removes every temporary file (or folder) still being written (Ctrl-C pressed twice).
pub fn remove_all() {
    for temp in open().iter() {
        remove(temp);
    }
}

fn remove(temp: &Path) {
    if temp.is_dir() {
        let _ = std::fs::remove_dir_all(temp);
    } else {
        let _ = std::fs::remove_file(temp);
    }
}
