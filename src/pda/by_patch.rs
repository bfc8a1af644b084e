//! The real points of a Pixel Data Array by room patch, found once: the
//! grid near the objects asks an update for the points on the patches
//! near them, where a pass over every pixel cost the desk's update more
//! than any other line (6% of it).

use std::sync::OnceLock;

use super::{NONE, PixelDataArray};

/// Per room patch, its real points (pixel held, point), in pixel order.
#[derive(Debug, Clone, Default)]
pub struct RealByPatch {
    start: Vec<u32>,
    entries: Vec<(u32, u32)>,
}

impl RealByPatch {
    /// Patch `k`'s real points: (pixel held, index into `real`).
    pub fn of(&self, k: usize) -> &[(u32, u32)] {
        match (self.start.get(k), self.start.get(k + 1)) {
            (Some(&a), Some(&b)) => &self.entries[a as usize..b as usize],
            _ => &[],
        }
    }

    fn memory_bytes(&self) -> usize {
        (self.start.len() + 2 * self.entries.len()) * 4
    }
}

/// A [`RealByPatch`] made when first asked for. The real points do not
/// change while the array lives (an update re-traces the objects' pixels
/// and recomputes the real points' light, not the points), so it holds
/// for the array's life; equality ignores it (it is derived).
#[derive(Debug, Clone, Default)]
pub(super) struct ByPatchCache(OnceLock<RealByPatch>);

impl PartialEq for ByPatchCache {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl ByPatchCache {
    pub(super) fn memory_bytes(&self) -> usize {
        self.0.get().map_or(0, RealByPatch::memory_bytes)
    }
}

impl PixelDataArray {
    /// The real points by patch, over `patch_count` room patches (made on
    /// the first call; a point on a patch beyond is left out).
    pub fn real_by_patch(&self, patch_count: usize) -> &RealByPatch {
        self.by_patch.0.get_or_init(|| {
            let mut start = vec![0u32; patch_count + 1];
            let patch_of = |k: u32| self.real.points[k as usize].location.patch as usize;
            for &k in self.real_index.iter().filter(|&&k| k != NONE) {
                if let Some(c) = start.get_mut(patch_of(k) + 1) {
                    *c += 1;
                }
            }
            for k in 0..patch_count {
                start[k + 1] += start[k];
            }
            let mut next = start.clone();
            let mut entries = vec![(0, 0); start[patch_count] as usize];
            for (i, &k) in self.real_index.iter().enumerate() {
                if k == NONE || patch_of(k) >= patch_count {
                    continue;
                }
                let at = &mut next[patch_of(k)];
                entries[*at as usize] = (i as u32, k);
                *at += 1;
            }
            RealByPatch { start, entries }
        })
    }
}
