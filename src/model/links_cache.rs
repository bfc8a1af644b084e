//! The room's hierarchical links kept in `.arlux-cache/` next to the scene:
//! they depend on the real surfaces, their mesh and ε only, not on the
//! lights or the variant, so a second render of the same room (another
//! light change, another object) reads them instead of refining again
//! (about 10 s on `lounge`'s light changes).
//!
//! A flat binary file rather than a serde format: 12 bytes per link and
//! millions of links, read and checked in one pass.

use std::path::{Path, PathBuf};

use crate::patches::Patches;
use crate::radiosity::Link;
use crate::scene::Scene;
use crate::util::cache::{ContentHash, build_id};

const FORMAT: &[u8; 8] = b"ARLXLNK1";

/// Link entries kept per scene folder, the most recently used: a room
/// edited again and again would otherwise leave one per version (52 MB
/// each for `lounge`'s light changes).
const KEPT: usize = 4;

/// The cache entry of the links between `patches` (a mesh of `scene`'s
/// real surfaces) refined to `epsilon`: named after the surfaces (what
/// blocks light) and every element's corners, normal, sidedness and
/// children (what is linked, and the indices the links hold).
pub(super) fn entry(scene: &Scene, patches: &Patches, epsilon: f64) -> PathBuf {
    let mut hash = ContentHash::default();
    hash.feed(FORMAT);
    hash.feed(&epsilon.to_le_bytes());
    for (id, s) in scene.surfaces.iter().enumerate() {
        hash.feed(&(id as u64).to_le_bytes());
        hash.feed(&(s.triangles.len() as u64).to_le_bytes());
        for v in s.triangles.iter().flatten() {
            for c in v.to_array() {
                hash.feed(&c.to_le_bytes());
            }
        }
    }
    for e in &patches.elements {
        let corners = e.shape.corners();
        for x in corners.iter().chain([&e.normal]) {
            for c in x.to_array() {
                hash.feed(&c.to_le_bytes());
            }
        }
        let [c0, c1] = e.children.unwrap_or([u32::MAX; 2]);
        hash.feed(&[corners.len() as u8, e.one_sided as u8]);
        hash.feed(&c0.to_le_bytes());
        hash.feed(&c1.to_le_bytes());
    }
    hash.entry(scene.dir(), "links", "bin")
}

/// The links stored at `path`, if this build wrote it whole and every link
/// joins elements of `patches` with a finite, non-negative factor. Read in
/// blocks: the file's bytes are never held beside the links.
pub(super) fn read(path: &Path, patches: &Patches) -> Option<Vec<Link>> {
    use std::io::Read;
    let mut file = std::fs::File::open(path).ok()?;
    let mut head = [0u8; 24];
    file.read_exact(&mut head).ok()?;
    let number = |i: usize| u64::from_le_bytes(head[i..i + 8].try_into().unwrap());
    let count = usize::try_from(number(16)).ok()?;
    let size = file.metadata().ok()?.len();
    if &head[..8] != FORMAT
        || Some(number(8)) != build_id()
        || Some(size) != (count as u64).checked_mul(12).map(|b| b + 24)
    {
        return None;
    }
    let n = patches.elements.len() as u32;
    let word = |c: &[u8], i: usize| u32::from_le_bytes(c[4 * i..4 * i + 4].try_into().unwrap());
    let mut links = Vec::with_capacity(count);
    let mut block = vec![0u8; 12 * 8192];
    while links.len() < count {
        let take = 12 * (count - links.len()).min(8192);
        file.read_exact(&mut block[..take]).ok()?;
        for c in block[..take].chunks_exact(12) {
            let link = Link {
                receiver: word(c, 0),
                source: word(c, 1),
                form_factor: f32::from_bits(word(c, 2)),
            };
            let valid = link.receiver < n
                && link.source < n
                && link.form_factor.is_finite()
                && link.form_factor >= 0.0;
            links.push(valid.then_some(link)?);
        }
    }
    // Marked as used, so that pruning keeps it.
    let _ = file.set_modified(std::time::SystemTime::now());
    Some(links)
}

/// Stores `links` at `path` (atomically, written as it is encoded; a cache
/// that cannot be written is no error), then prunes the folder.
pub(super) fn write(path: &Path, links: impl ExactSizeIterator<Item = Link>) {
    let Some(build) = build_id() else {
        return;
    };
    let Some(dir) = path.parent().filter(|d| std::fs::create_dir_all(d).is_ok()) else {
        return;
    };
    let written = crate::image_io::write_atomic_with(path, |f| {
        f.write_all(FORMAT)?;
        f.write_all(&build.to_le_bytes())?;
        f.write_all(&(links.len() as u64).to_le_bytes())?;
        for l in links {
            f.write_all(&l.receiver.to_le_bytes())?;
            f.write_all(&l.source.to_le_bytes())?;
            f.write_all(&l.form_factor.to_bits().to_le_bytes())?;
        }
        Ok(())
    });
    if written.is_ok() {
        crate::util::cache::prune(dir, "links", "bin", KEPT);
    }
}
