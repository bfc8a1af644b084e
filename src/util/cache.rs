//! The caches arlux keeps next to a scene (`.arlux-cache/`): a merged HDR
//! photo, a recovered goniometric, a brackets' scale, the room's links.
//! Each entry is named after a hash of everything it was made from, so a
//! changed input is a new entry and a stale one is never read. A cache is
//! a convenience: failing to write one is not an error.

use std::path::{Path, PathBuf};

/// FNV-1a over bytes: names cache files after what they were made from.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ContentHash(u64);

impl Default for ContentHash {
    fn default() -> Self {
        ContentHash(0xcbf2_9ce4_8422_2325)
    }
}

impl ContentHash {
    pub fn feed(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 = (self.0 ^ *b as u64).wrapping_mul(0x0100_0000_01b3);
        }
    }

    pub fn value(&self) -> u64 {
        self.0
    }
}

impl ContentHash {
    /// The cache entry `kind-<hash>.ext` in `.arlux-cache/` next to a scene.
    pub fn entry(&self, scene_dir: &Path, kind: &str, ext: &str) -> PathBuf {
        scene_dir
            .join(".arlux-cache")
            .join(format!("{kind}-{:016x}.{ext}", self.value()))
    }
}

/// The running program: its version, size and time of build. Another
/// build may compute differently, and what it made must never be read as
/// this one's: where the program's file cannot be read, nothing is kept or
/// read.
pub(crate) fn build_id() -> Option<u64> {
    let exe = std::env::current_exe().ok()?.metadata().ok()?;
    let built = exe
        .modified()
        .ok()?
        .duration_since(std::time::UNIX_EPOCH)
        .ok()?;
    let mut hash = ContentHash::default();
    hash.feed(env!("CARGO_PKG_VERSION").as_bytes());
    hash.feed(&exe.len().to_le_bytes());
    hash.feed(&built.as_nanos().to_le_bytes());
    Some(hash.value())
}

/// Removes all but the `kept` most recently used `kind-*.ext` entries in `dir`.
pub(crate) fn prune(dir: &Path, kind: &str, ext: &str, kept: usize) {
    let Ok(listing) = std::fs::read_dir(dir) else {
        return;
    };
    let (prefix, suffix) = (format!("{kind}-"), format!(".{ext}"));
    let mut entries: Vec<(std::time::SystemTime, PathBuf)> = listing
        .flatten()
        .filter(|e| {
            let name = e.file_name();
            let name = name.to_string_lossy();
            name.starts_with(&prefix) && name.ends_with(&suffix)
        })
        .filter_map(|e| Some((e.metadata().ok()?.modified().ok()?, e.path())))
        .collect();
    entries.sort_by_key(|e| std::cmp::Reverse(e.0));
    for (_, old) in entries.into_iter().skip(kept) {
        let _ = std::fs::remove_file(old);
    }
}
