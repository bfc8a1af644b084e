//! The room's automatic patch size kept in `.arlux-cache/`: choosing it
//! meshes, links, measures and solves the room once at the coarse size to
//! estimate its reflectances ([`super::interreflection_scale`]), a whole
//! model built only to be thrown away (60–70 ms of a warm 0.55 s render
//! of `lounge`). The choice depends on the room's surfaces, its lights as
//! photographed, the known reflectances, the camera, the photo's pixels,
//! the model's settings and this build, all named in the entry: a changed
//! input is a new entry, never a stale size.

use std::path::{Path, PathBuf};

use crate::image_io::Image;
use crate::model::ModelSettings;
use crate::scene::Scene;
use crate::util::cache::{ContentHash, build_id};

const FORMAT: &[u8; 8] = b"ARLXSIZ1";

/// Entries kept per scene folder, the most recently used.
const KEPT: usize = 8;

/// The entry of the size chosen for `scene` photographed as `photo`
/// (None: this build cannot name its entries).
pub(super) fn entry(scene: &Scene, photo: &Image, settings: &ModelSettings) -> Option<PathBuf> {
    let mut hash = ContentHash::default();
    hash.feed(FORMAT);
    hash.feed(&build_id()?.to_le_bytes());
    hash.feed(format!("{settings:?}").as_bytes());
    for s in &scene.surfaces {
        hash.feed(&(s.triangles.len() as u64).to_le_bytes());
        for c in s.triangles.iter().flatten().flat_map(|v| v.to_array()) {
            hash.feed(&c.to_le_bytes());
        }
    }
    hash.feed(format!("{:?}", scene.lights).as_bytes());
    hash.feed(format!("{:?}", scene.reflectances).as_bytes());
    hash.feed(format!("{:?}", scene.camera).as_bytes());
    hash.feed(&photo.width.to_le_bytes());
    hash.feed(&photo.height.to_le_bytes());
    for c in photo.pixels.iter().flat_map(|p| p.to_array()) {
        hash.feed(&c.to_le_bytes());
    }
    Some(hash.entry(scene.dir(), "room-size", "txt"))
}

/// The size stored at `path`, if it is a finite positive number.
pub(super) fn read(path: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(path).ok()?;
    let size: f64 = text.trim().parse().ok()?;
    // Marked as used, so that pruning keeps it.
    let _ = std::fs::File::open(path).and_then(|f| f.set_modified(std::time::SystemTime::now()));
    (size.is_finite() && size > 0.0).then_some(size)
}

/// Stores `size` at `path` (atomically; a cache that cannot be written is
/// no error), then prunes the folder. Written as Rust prints an f64, which
/// reads back to the same bits.
pub(super) fn write(path: &Path, size: f64) {
    let Some(dir) = path.parent().filter(|d| std::fs::create_dir_all(d).is_ok()) else {
        return;
    };
    let written = crate::image_io::write_atomic_with(path, |f| writeln!(f, "{size:?}"));
    if written.is_ok() {
        crate::util::cache::prune(dir, "room-size", "txt", KEPT);
    }
}
