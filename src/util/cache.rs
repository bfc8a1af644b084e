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
