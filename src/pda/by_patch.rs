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
    /// The real points by patch (made on the first call, over the patches
    /// the points lie on: a patch beyond them holds none).
    pub fn real_by_patch(&self) -> &RealByPatch {
        self.by_patch.0.get_or_init(|| {
            let patch_of = |k: u32| self.real.points[k as usize].location.patch as usize;
            let held = || {
                self.real_index
                    .iter()
                    .enumerate()
                    .filter(|(_, k)| **k != NONE)
            };
            let patch_count = held().map(|(_, &k)| patch_of(k) + 1).max().unwrap_or(0);
            let mut start = vec![0u32; patch_count + 1];
            for (_, &k) in held() {
                start[patch_of(k) + 1] += 1;
            }
            for k in 0..patch_count {
                start[k + 1] += start[k];
            }
            let mut next = start.clone();
            let mut entries = vec![(0, 0); start[patch_count] as usize];
            for (i, &k) in held() {
                let at = &mut next[patch_of(k)];
                entries[*at as usize] = (i as u32, k);
                *at += 1;
            }
            RealByPatch { start, entries }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pda::{PatchPoint, SurfacePoint};
    use glam::Vec3;

    #[test]
    fn each_patch_lists_its_real_points_in_pixel_order() {
        // Pixels 0..8: no real point at 2 and 5; patches 3, 0, -, 3, 1, -, 0, 3.
        let patches = [
            Some(3),
            Some(0),
            None,
            Some(3),
            Some(1),
            None,
            Some(0),
            Some(3),
        ];
        let mut pda = PixelDataArray::default();
        for p in patches {
            match p {
                Some(patch) => {
                    pda.real_index.push(pda.real.points.len() as u32);
                    pda.real.points.push(SurfacePoint {
                        position: Vec3::ZERO,
                        normal: Vec3::Z,
                        surface: 0,
                        is_virtual: false,
                        pixel_terms: false,
                        clear_of_own: false,
                        location: PatchPoint {
                            patch,
                            weights: [1.0, 0.0, 0.0, 0.0],
                        },
                    });
                }
                None => pda.real_index.push(NONE),
            }
        }
        let unmade = pda.clone();
        let by = pda.real_by_patch();
        // (pixel, point): points are numbered in pixel order, skipping 2 and 5.
        assert_eq!(by.of(0), &[(1, 1), (6, 4)]);
        assert_eq!(by.of(1), &[(4, 3)]);
        assert_eq!(by.of(2), &[]);
        assert_eq!(by.of(3), &[(0, 0), (3, 2), (7, 5)]);
        assert_eq!(by.of(4), &[]);
        // Derived: equality ignores whether it was made.
        assert_eq!(pda, unmade);
    }
}
