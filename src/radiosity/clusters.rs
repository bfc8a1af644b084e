//! Clusters of the virtual objects' root elements: a hierarchy of boxes
//! (Smits, Arvo & Greenberg 1994; Sillion 1995) that a shaft test descends
//! instead of testing every root. A 2,000-triangle chair has 2,000 roots;
//! every room link an object may shadow, and every pair it links, asked
//! each of them, and those tests were most of an update.
//!
//! Written here rather than taken from a spatial-index crate (rstar, bvh):
//! each node carries what radiosity needs of its roots (the box for shaft
//! tests; the light it sends, see [`ClusterLight`]), and queries are shaft
//! tests, not rays or points. Embree still does every ray.

use glam::DVec3;

use super::form_factor::ShaftTest;
use crate::patches::Patches;

/// Roots per leaf cluster: below this a box test costs about as much as
/// testing the roots themselves.
const LEAF_ROOTS: usize = 4;

/// A node: its box, and either two child nodes or a range of `roots`.
#[derive(Debug, Clone, PartialEq)]
pub struct Cluster {
    pub lo: DVec3,
    pub hi: DVec3,
    pub kind: ClusterKind,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ClusterKind {
    Inner([u32; 2]),
    /// `roots[start..end]`.
    Leaf(u32, u32),
}

/// The cluster hierarchy over some root elements; node 0 holds them all.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RootClusters {
    pub nodes: Vec<Cluster>,
    /// The roots, ordered so that each leaf's are contiguous.
    pub roots: Vec<u32>,
}

impl RootClusters {
    /// Clusters `roots` (elements of `patches`) by splitting their centres
    /// at the median of the longest axis, recursively.
    pub fn build(patches: &Patches, roots: &[u32]) -> RootClusters {
        let mut out = RootClusters {
            nodes: Vec::with_capacity(2 * roots.len() / LEAF_ROOTS + 1),
            roots: roots.to_vec(),
        };
        if !roots.is_empty() {
            out.split(patches, 0, roots.len());
        }
        out
    }

    /// Makes the node over `roots[start..end]`, returning its index.
    fn split(&mut self, patches: &Patches, start: usize, end: usize) -> u32 {
        let bounds = |r: &u32| patches.elements[*r as usize].bounds;
        let (lo, hi) = self.roots[start..end].iter().map(bounds).fold(
            (DVec3::INFINITY, DVec3::NEG_INFINITY),
            |(lo, hi), (a, b)| (lo.min(a), hi.max(b)),
        );
        let index = self.nodes.len() as u32;
        self.nodes.push(Cluster {
            lo,
            hi,
            kind: ClusterKind::Leaf(start as u32, end as u32),
        });
        if end - start > LEAF_ROOTS {
            let centre = |r: &u32| patches.elements[*r as usize].centre;
            let (clo, chi) = self.roots[start..end]
                .iter()
                .map(centre)
                .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), c| {
                    (lo.min(c), hi.max(c))
                });
            let axis = (chi - clo).max_position();
            let mid = (start + end) / 2;
            self.roots[start..end].select_nth_unstable_by(mid - start, |a, b| {
                centre(a)[axis].total_cmp(&centre(b)[axis])
            });
            let left = self.split(patches, start, mid);
            let right = self.split(patches, mid, end);
            self.nodes[index as usize].kind = ClusterKind::Inner([left, right]);
        }
        index
    }

    /// Whether any root may block `test`'s pair.
    pub(super) fn any_may_block(&self, test: &ShaftTest) -> bool {
        let mut found = false;
        self.visit(test, &mut |_| {
            found = true;
            false
        });
        found
    }

    /// The roots that may block `test`'s pair, appended to `out`.
    pub(super) fn may_block_into(&self, test: &ShaftTest, out: &mut Vec<u32>) {
        self.visit(test, &mut |r| {
            out.push(r);
            true
        });
    }

    /// Calls `found` for each root that may block `test`'s pair, in the
    /// roots' original order within each leaf, while it returns true.
    fn visit(&self, test: &ShaftTest, found: &mut dyn FnMut(u32) -> bool) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = vec![0u32];
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if !test.may_block_box(node.lo, node.hi) {
                continue;
            }
            match node.kind {
                // Right pushed first: leaves are met left to right.
                ClusterKind::Inner([l, r]) => stack.extend([r, l]),
                ClusterKind::Leaf(s, e) => {
                    for &root in &self.roots[s as usize..e as usize] {
                        if test.may_block(root) && !found(root) {
                            return;
                        }
                    }
                }
            }
        }
    }
}
