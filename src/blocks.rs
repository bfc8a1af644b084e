//! [`BlockHierarchy`] (Grosch §3.2): pixel blocks over the image — single
//! pixels, then 2×2 blocks of them, and so on up to the whole picture — each
//! with the bounding box of its pixels' surface points. A block's shaft to a
//! light (the convex hull of its box and the light's shape) holds every
//! pixel shaft below it, so one shaft test that excludes a moved object's
//! old and new bounds skips the whole block.

use glam::{DVec3, Vec3};

use crate::light::LightSource;
use crate::pda::PixelDataArray;
use crate::shaft::{ObjectBounds, Shaft};

/// One level of the hierarchy: its width and height in blocks, and each block's box.
type Level = (u32, u32, Vec<(Vec3, Vec3)>);

/// Boxes per level, level 0 = pixels; an empty block has lo > hi.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockHierarchy {
    pub width: u32,
    pub height: u32,
    /// (width, height, boxes) per level; level 0's boxes are `points`.
    levels: Vec<Level>,
    /// Level 0: each pixel's surface point (infinite: none), 12 bytes a
    /// pixel where a box of a point took 24.
    points: Vec<Vec3>,
    /// Per level, the number of blocks on the levels below it (a block's
    /// place in [`BlockShafts`]).
    first: Vec<u32>,
}

/// Shafts of a hierarchy's blocks to one light, built when a traversal
/// first tests them and kept: they depend on the room's points and the
/// light alone, and an object moving through a motion meets the same
/// blocks pose after pose (building them was most of a traversal's work).
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct BlockShafts {
    /// Per block kept (numbered level by level), its shaft's place in
    /// `shafts`: a map, as at most [`MOST_KEPT`] are kept (a table of
    /// every block took 5 bytes a pixel per light).
    slot: std::collections::HashMap<u32, u32>,
    shafts: Vec<Shaft>,
    /// Shafts kept at most ([`MOST_KEPT`]).
    most: usize,
}

/// Shafts kept per light at most (about 8 MB of planes): a motion over
/// the whole image would otherwise keep one per block; beyond it, a
/// block's shaft is built for each test again.
const MOST_KEPT: usize = 1 << 14;

/// What a traversal tests blocks against: the light's corners and box, and the objects' bounds.
#[derive(Clone, Copy)]
struct Against<'a> {
    corners: &'a [DVec3],
    light_box: (DVec3, DVec3),
    objects: &'a [ObjectBounds],
}

impl BlockShafts {
    /// `test` of the shaft of block `index`, the kept one or one `build`
    /// makes (kept while there is room).
    fn test(
        &mut self,
        index: u32,
        build: impl FnOnce() -> Shaft,
        test: impl FnOnce(&Shaft) -> bool,
    ) -> bool {
        if let Some(&at) = self.slot.get(&index) {
            return test(&self.shafts[at as usize]);
        }
        let shaft = build();
        let answer = test(&shaft);
        if self.shafts.len() < self.most {
            self.slot.insert(index, self.shafts.len() as u32);
            self.shafts.push(shaft);
        }
        answer
    }

    pub fn memory_bytes(&self) -> usize {
        self.slot.capacity() * 12
            + self
                .shafts
                .iter()
                .map(|s| {
                    std::mem::size_of::<Shaft>()
                        + s.plane_count() * std::mem::size_of::<(DVec3, f64)>()
                })
                .sum::<usize>()
    }
}

/// What a traversal did.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Traversal {
    /// Pixels whose shaft to the light may meet the bounds.
    pub pixels: Vec<u32>,
    pub shaft_tests: u64,
    /// Blocks skipped by one test: (level, x, y).
    pub skipped: Vec<(u8, u32, u32)>,
}

const EMPTY: (Vec3, Vec3) = (Vec3::INFINITY, Vec3::NEG_INFINITY);

/// A pixel's box: its point, or [`EMPTY`].
fn point_box(p: Vec3) -> (Vec3, Vec3) {
    if p.x.is_finite() { (p, p) } else { EMPTY }
}

impl BlockHierarchy {
    /// Built over the real surface points of the Pixel Data Array.
    pub fn build(pda: &PixelDataArray) -> BlockHierarchy {
        let points = pda
            .real_index
            .iter()
            .map(|&k| (k != u32::MAX).then(|| pda.real.points[k as usize].position));
        BlockHierarchy::of_points(pda.width, pda.height, points)
    }

    /// Over a `w` × `h` image's surface points, row by row (None: no point).
    fn of_points(w: u32, h: u32, points: impl Iterator<Item = Option<Vec3>>) -> BlockHierarchy {
        let points: Vec<Vec3> = points.map(|p| p.unwrap_or(Vec3::INFINITY)).collect();
        let mut levels = vec![(w, h, Vec::new())];
        while {
            let (lw, lh, _) = levels.last().unwrap();
            *lw > 1 || *lh > 1
        } {
            let at = levels.len() - 1;
            let (lw, lh, boxes) = levels.last().unwrap();
            let (nw, nh) = (lw.div_ceil(2), lh.div_ceil(2));
            let mut next = vec![EMPTY; (nw * nh) as usize];
            for y in 0..*lh {
                for x in 0..*lw {
                    let i = (y * lw + x) as usize;
                    let (lo, hi) = if at == 0 {
                        point_box(points[i])
                    } else {
                        boxes[i]
                    };
                    let n = &mut next[((y / 2) * nw + x / 2) as usize];
                    *n = (n.0.min(lo), n.1.max(hi));
                }
            }
            levels.push((nw, nh, next));
        }
        let first = levels
            .iter()
            .scan(0, |below, (lw, lh, _)| {
                Some(std::mem::replace(below, *below + lw * lh))
            })
            .collect();
        BlockHierarchy {
            width: w,
            height: h,
            levels,
            points,
            first,
        }
    }

    pub fn memory_bytes(&self) -> usize {
        self.points.len() * std::mem::size_of::<Vec3>()
            + (self.levels.iter())
                .map(|(_, _, b)| b.len() * std::mem::size_of::<(Vec3, Vec3)>())
                .sum::<usize>()
    }

    /// An empty store of shafts to one light, for [`BlockHierarchy::traverse`].
    pub(crate) fn no_shafts(&self) -> BlockShafts {
        BlockShafts {
            slot: Default::default(),
            shafts: Vec::new(),
            most: MOST_KEPT,
        }
    }

    /// The pixels whose shaft to `light` may meet any of the `objects`
    /// (a moved object's old and new bounds), found top-down; the blocks'
    /// shafts are taken from `shafts` (this light's, from
    /// [`BlockHierarchy::no_shafts`]), those missing built and kept there.
    pub(crate) fn traverse(
        &self,
        light: &LightSource,
        objects: &[ObjectBounds],
        shafts: &mut BlockShafts,
    ) -> Traversal {
        let mut out = Traversal::default();
        if objects.is_empty() {
            return out;
        }
        let light_points = light.corners();
        let light_box = crate::geometry::bounds(light_points.iter().copied());
        let top = self.levels.len() - 1;
        let against = Against {
            corners: &light_points,
            light_box,
            objects,
        };
        self.visit(top, 0, 0, &against, shafts, &mut out);
        out
    }

    fn visit(
        &self,
        level: usize,
        x: u32,
        y: u32,
        against: &Against,
        shafts: &mut BlockShafts,
        out: &mut Traversal,
    ) {
        let (lw, lh, boxes) = &self.levels[level];
        if x >= *lw || y >= *lh {
            return;
        }
        let (lo, hi) = if level == 0 {
            point_box(self.points[(y * lw + x) as usize])
        } else {
            boxes[(y * lw + x) as usize]
        };
        if lo.x > hi.x {
            return;
        }
        out.shaft_tests += 1;
        let (lo, hi) = (lo.as_dvec3(), hi.as_dvec3());
        let Against {
            corners,
            light_box,
            objects,
        } = *against;
        let index = self.first[level] + y * lw + x;
        let may_meet = if level == 0 && corners.len() == 1 {
            // A pixel: exactly the test the Pixel Data Array makes.
            objects.iter().any(|o| o.meets_segment(lo, corners[0]))
        } else {
            // A pixel's pyramid to the light's shape, as the Pixel Data
            // Array tests it; a block's Haines & Wallace shaft from its box
            // to the light's, which holds every pixel shaft below it.
            let build = || {
                if level == 0 {
                    Shaft::pyramid(lo, corners)
                } else {
                    Shaft::between_boxes((lo, hi), light_box)
                }
            };
            shafts.test(index, build, |shaft| {
                objects.iter().any(|o| !o.outside(shaft))
            })
        };
        if !may_meet {
            out.skipped.push((level as u8, x, y));
            return;
        }
        if level == 0 {
            out.pixels.push(y * self.width + x);
            return;
        }
        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            self.visit(level - 1, 2 * x + dx, 2 * y + dy, against, shafts, out);
        }
    }

    /// The image rectangle a block of `level` at (x, y) covers.
    pub fn block_pixels(&self, level: u8, x: u32, y: u32) -> (u32, u32, u32, u32) {
        let s = 1u32 << level;
        (
            x * s,
            y * s,
            ((x + 1) * s).min(self.width),
            ((y + 1) * s).min(self.height),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::{test_panel, test_spot};

    /// Over a floor of points (with gaps) under a panel and a spot, moving
    /// a box about: a traversal reaches the same pixels whether each
    /// block's shaft is built for the test, kept from the traversals
    /// before, or kept up to a cap with the rest built again.
    #[test]
    fn kept_shafts_reach_the_pixels_fresh_ones_reach() {
        let (w, h) = (37u32, 23u32);
        let points = (0..w * h).map(|i| {
            (i % 11 != 3).then(|| Vec3::new((i % w) as f32 * 0.05, 0.0, (i / w) as f32 * 0.05))
        });
        let blocks = BlockHierarchy::of_points(w, h, points);
        let (panel, spot) = (
            test_panel(DVec3::new(0.9, 2.0, 0.5)),
            test_spot(DVec3::new(0.2, 1.5, 1.0)),
        );
        for light in [&panel, &spot] {
            let (mut kept, mut capped) = (blocks.no_shafts(), blocks.no_shafts());
            capped.most = 5;
            let mut reached = 0;
            for step in 0..6 {
                let lo = DVec3::new(0.2 + 0.25 * step as f64, 0.0, 0.3);
                let object = ObjectBounds::around(&[lo, lo + DVec3::new(0.2, 0.3, 0.2)]);
                let fresh = blocks.traverse(light, &[object], &mut blocks.no_shafts());
                assert_eq!(
                    blocks.traverse(light, &[object], &mut kept).pixels,
                    fresh.pixels,
                    "{} at step {step}",
                    light.name
                );
                assert_eq!(
                    blocks.traverse(light, &[object], &mut capped).pixels,
                    fresh.pixels,
                    "{} at step {step}, capped",
                    light.name
                );
                reached += fresh.pixels.len();
            }
            assert!(
                reached > 0 && capped.shafts.len() == 5 && kept.shafts.len() > 5,
                "{}: {reached} pixels, {} kept",
                light.name,
                kept.shafts.len()
            );
        }
    }
}
