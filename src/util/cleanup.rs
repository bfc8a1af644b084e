//! The temporary files a run is writing, so that a signal that ends the
//! run removes them instead of leaving `.NAME.XXXXXX.tmp` beside an output.
//! Writers register a temporary file while it exists; the binary's signal
//! thread calls [`remove_all`] before it exits.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

static TEMPORARY: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn files() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    TEMPORARY.lock().unwrap_or_else(|e| e.into_inner())
}

/// Marks `path` as a temporary file of this run.
pub fn register(path: &Path) {
    files().push(path.to_path_buf());
}

/// `path` is gone (renamed over its output, or removed).
pub fn unregister(path: &Path) {
    files().retain(|p| p != path);
}

/// Removes every temporary file of this run still there.
pub fn remove_all() {
    for p in files().drain(..) {
        let _ = std::fs::remove_file(p);
    }
}
