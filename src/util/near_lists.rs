//! Items found by place: a uniform grid over the box of a set of points,
//! each cell listing, in the order they were added, the items added near
//! it. Written here rather than taken from a crate: the spatial-index
//! crates (kiddo, rstar) descend a tree per radius query and give what
//! they find in their tree's order, where final gathering's choice of
//! vertices adds items one by one between queries and sums what it finds
//! in the order the items came (so the sums are the same bit for bit
//! however the index is laid out).

use glam::DVec3;

/// Cells a grid may hold at most (4 bytes each, twice): past this the
/// cells grow, which keeps every answer and lengthens the lists.
const MOST_CELLS: usize = 1 << 18;

const NONE: u32 = u32::MAX;

/// A grid whose cells list items in the order they were added.
pub struct NearLists {
    origin: DVec3,
    size: f64,
    dims: [usize; 3],
    /// Per cell, its first and last entry in `entries` (NONE: empty).
    first: Vec<u32>,
    last: Vec<u32>,
    /// (item, next entry of the same cell).
    entries: Vec<(u32, u32)>,
}

impl NearLists {
    /// A grid over the box of `points` whose cells are at least `within`
    /// wide: an item added near a point ([`NearLists::add_near`]) is listed
    /// at every point within `within` of it.
    pub fn new(points: impl Iterator<Item = DVec3>, within: f64) -> NearLists {
        let (lo, hi) = points.fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p), hi.max(p))
        });
        let (lo, hi) = match lo.cmple(hi).all() {
            true => (lo, hi),
            false => (DVec3::ZERO, DVec3::ZERO),
        };
        let extent = hi - lo;
        let volume = extent.max(DVec3::splat(within)).element_product();
        let mut size = within.max((volume / MOST_CELLS as f64).cbrt()).max(1e-9);
        // A cell of margin on every side: the 27 cells around any point of
        // the box are in the grid.
        let dims_at = |size: f64| {
            (extent / size)
                .floor()
                .as_uvec3()
                .to_array()
                .map(|d| d as usize + 3)
        };
        // A flat or thin box has fewer cells than its volume says, and more
        // of margin: grown until the grid holds no more than it may.
        while dims_at(size).iter().product::<usize>() > MOST_CELLS {
            size *= 2.0;
        }
        let dims = dims_at(size);
        let cells = dims[0] * dims[1] * dims[2];
        NearLists {
            origin: lo - DVec3::splat(size),
            size,
            dims,
            first: vec![NONE; cells],
            last: vec![NONE; cells],
            entries: Vec::new(),
        }
    }

    /// The cell holding `p`, clamped into the grid.
    fn cell(&self, p: DVec3) -> [usize; 3] {
        let c = ((p - self.origin) / self.size).floor();
        let clamp = |x: f64, d: usize| (x.max(0.0) as usize).min(d - 1);
        [
            clamp(c.x, self.dims[0]),
            clamp(c.y, self.dims[1]),
            clamp(c.z, self.dims[2]),
        ]
    }

    fn index(&self, [x, y, z]: [usize; 3]) -> usize {
        (z * self.dims[1] + y) * self.dims[0] + x
    }

    /// Lists `item` in the 27 cells around the one holding `p`.
    pub fn add_near(&mut self, p: DVec3, item: u32) {
        let [cx, cy, cz] = self.cell(p);
        for z in cz.saturating_sub(1)..(cz + 2).min(self.dims[2]) {
            for y in cy.saturating_sub(1)..(cy + 2).min(self.dims[1]) {
                for x in cx.saturating_sub(1)..(cx + 2).min(self.dims[0]) {
                    let k = self.index([x, y, z]);
                    let e = self.entries.len() as u32;
                    self.entries.push((item, NONE));
                    match self.last[k] {
                        NONE => self.first[k] = e,
                        l => self.entries[l as usize].1 = e,
                    }
                    self.last[k] = e;
                }
            }
        }
    }

    /// The items added near `p`'s cell, in the order they were added:
    /// among them every item added within `within` of `p`.
    pub fn near(&self, p: DVec3) -> impl Iterator<Item = u32> + '_ {
        let mut e = self.first[self.index(self.cell(p))];
        std::iter::from_fn(move || {
            let (item, next) = *self.entries.get(e as usize)?;
            e = next;
            Some(item)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_item_within_reach_is_listed_in_the_order_added() {
        let mut state = 7u64;
        let mut next = || {
            state = crate::util::rng::hash2(state, 1);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let points: Vec<DVec3> = (0..2000)
            .map(|_| DVec3::new(next() * 2.0, next() * 0.1, next() * 0.7 - 0.3))
            .collect();
        // A box 2 × 0.1 × 0.7 m, and a flat one 100 m wide (its cells grow
        // to keep the grid within bounds).
        let flat: Vec<DVec3> = (points.iter())
            .map(|p| DVec3::new(p.x * 50.0, 0.0, p.z * 140.0))
            .collect();
        for (points, within) in [
            (&points, 0.01),
            (&points, 0.05),
            (&points, 0.3),
            (&points, 5.0),
            (&flat, 0.01),
        ] {
            let mut lists = NearLists::new(points.iter().copied(), within);
            assert!(lists.first.len() <= MOST_CELLS, "{}", lists.first.len());
            let added: Vec<usize> = (0..points.len()).step_by(3).collect();
            for &i in &added {
                lists.add_near(points[i], i as u32);
            }
            for p in points.iter() {
                let listed: Vec<u32> = lists.near(*p).collect();
                assert!(listed.windows(2).all(|w| w[0] < w[1]));
                for &i in &added {
                    if (points[i] - *p).length() <= within {
                        assert!(listed.contains(&(i as u32)), "{within}: {i} missing");
                    }
                }
            }
        }
    }
}
