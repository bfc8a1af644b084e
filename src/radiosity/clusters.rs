//! Clusters of the virtual objects' root elements: a hierarchy of boxes
//! (Smits, Arvo & Greenberg 1994; Sillion 1995) that a shaft test descends
//! instead of testing every root (a 2,000-triangle chair has 2,000 roots),
//! and through which the objects send the room their light.
//!
//! Written here rather than taken from a spatial-index crate (rstar, bvh):
//! each node carries what radiosity needs of its roots (the box for shaft
//! tests; the light it sends, see [`ClusterLinks`]), and queries are shaft
//! tests, not rays or points. Embree still does every ray.

use glam::{DVec3, Vec3};

use super::form_factor::ShaftTest;
use super::transport::{Link, Refiner, refine};
use crate::light::{offset_origin, segment};
use crate::patches::Patches;
use crate::trace::{Layer, TraceRay};

/// Roots per leaf cluster: below this a box test costs about as much as
/// testing the roots themselves.
const LEAF_ROOTS: usize = 4;

/// Clusters a pair passes down to its children as possible occluders
/// ([`RootClusters::frontier`]).
const FRONTIER: usize = 16;

/// A node: its box, its roots' total area and area-weighted centre, and
/// either two child nodes or a range of `roots`.
#[derive(Debug, Clone, PartialEq)]
pub struct Cluster {
    pub lo: DVec3,
    pub hi: DVec3,
    pub area: f64,
    pub centroid: DVec3,
    /// `roots[start..end]`: every root under this node.
    pub roots: (u32, u32),
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
        let (area, moment) = self.roots[start..end]
            .iter()
            .fold((0.0, DVec3::ZERO), |(a, m), r| {
                let e = &patches.elements[*r as usize];
                (a + e.area, m + e.centre * e.area)
            });
        let index = self.nodes.len() as u32;
        self.nodes.push(Cluster {
            lo,
            hi,
            area,
            centroid: if area > 0.0 {
                moment / area
            } else {
                (lo + hi) / 2.0
            },
            roots: (start as u32, end as u32),
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

    /// The clusters among `from` (and their descendants) that may hold a
    /// root blocking `test`'s pair: opened while there are fewer than
    /// [`FRONTIER`], a leaf kept only when one of its roots may block. A
    /// child pair's shaft lies inside its parent's, so it starts from its
    /// parent's frontier: a chair wholly inside a wall-to-floor shaft is
    /// tested as a few boxes, not as its thousands of roots, at each level.
    pub(super) fn frontier(&self, test: &ShaftTest, from: &[u32]) -> Vec<u32> {
        let mut out = Vec::new();
        let mut stack: Vec<u32> = from.iter().rev().copied().collect();
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if !test.may_block_box(node.lo, node.hi) {
                continue;
            }
            match node.kind {
                ClusterKind::Leaf(s, e) => {
                    if self.roots[s as usize..e as usize]
                        .iter()
                        .any(|&r| test.may_block(r))
                    {
                        out.push(n);
                    }
                }
                ClusterKind::Inner([l, r]) if out.len() + stack.len() < FRONTIER => {
                    stack.extend([r, l])
                }
                ClusterKind::Inner(_) => out.push(n),
            }
        }
        out
    }

    /// Whether any root may block `test`'s pair.
    pub(super) fn any_may_block(&self, test: &ShaftTest) -> bool {
        let mut stack = if self.nodes.is_empty() {
            vec![]
        } else {
            vec![0u32]
        };
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if !test.may_block_box(node.lo, node.hi) {
                continue;
            }
            match node.kind {
                ClusterKind::Inner([l, r]) => stack.extend([r, l]),
                ClusterKind::Leaf(s, e) => {
                    if self.roots[s as usize..e as usize]
                        .iter()
                        .any(|&r| test.may_block(r))
                    {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// A room element's link to a cluster of the objects: it gathers
/// `geometry × I(direction)`, I the cluster's radiant intensity towards it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClusterLink {
    pub receiver: u32,
    pub node: u32,
    /// The receiver's mean of cosθ/d² × the fraction of rays the room lets
    /// through, towards the cluster's centre.
    pub geometry: f32,
    /// From the cluster's centre to the receiver's.
    pub direction: Vec3,
}

/// The light the virtual objects send the room through their clusters
/// (Sillion 1995): each cluster sends like a point with the radiant
/// intensity of its roots, I(ω) = Σ A·B/π·max(0, n·ω). A cluster keeps its
/// roots' area per bin of normal directions (a cube map of 6 × 4 × 4 cells,
/// about 15° across) with the bin's mean normal; I is summed over the
/// bins. Exact for boxy furniture (one normal per face) and within a few
/// per cent for a tessellated sphere; spherical harmonics of order 2 are
/// 37–50% off along a cube's axes (its anisotropy is of order 4).
/// Self-shadowing inside a cluster is left out (it sends a little too much
/// towards a concave side); where that matters, near the object, the
/// oracle opens the cluster.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ClusterLinks {
    pub tree: RootClusters,
    pub links: Vec<ClusterLink>,
    /// Per node, its non-empty bins (bin, mean normal) in `bins[ranges[n]..ranges[n + 1]]`.
    bins: Vec<(u8, Vec3)>,
    ranges: Vec<u32>,
}

/// Normal bins per cube face side (see [`ClusterLinks`]).
const BIN_SIDE: usize = 4;
const BINS: usize = 6 * BIN_SIDE * BIN_SIDE;

/// The cube-map cell of unit direction `n`.
pub(super) fn normal_bin(n: DVec3) -> usize {
    let a = n.abs();
    let (face, u, v, m) = if a.x >= a.y && a.x >= a.z {
        (usize::from(n.x < 0.0), n.y, n.z, a.x)
    } else if a.y >= a.z {
        (2 + usize::from(n.y < 0.0), n.x, n.z, a.y)
    } else {
        (4 + usize::from(n.z < 0.0), n.x, n.y, a.z)
    };
    let cell =
        |t: f64| (((t / m.max(1e-300) + 1.0) / 2.0 * BIN_SIDE as f64) as usize).min(BIN_SIDE - 1);
    face * BIN_SIDE * BIN_SIDE + cell(u) * BIN_SIDE + cell(v)
}

/// The sides a root sends from: its normal, and for a two-sided root its reverse.
fn sides(e: &crate::patches::Element) -> impl Iterator<Item = DVec3> {
    std::iter::once(e.normal).chain((!e.one_sided).then_some(-e.normal))
}

impl ClusterLinks {
    /// The links of `links` to the clusters of `tree`, with each node's bins.
    pub fn new(patches: &Patches, tree: RootClusters, links: Vec<ClusterLink>) -> ClusterLinks {
        let mut bins = Vec::new();
        let mut ranges = vec![0u32];
        for node in &tree.nodes {
            let (s, e) = node.roots;
            let mut area = [(0.0f64, DVec3::ZERO); BINS];
            for &r in &tree.roots[s as usize..e as usize] {
                let el = &patches.elements[r as usize];
                for n in sides(el) {
                    let b = &mut area[normal_bin(n)];
                    b.0 += el.area;
                    b.1 += n * el.area;
                }
            }
            bins.extend(
                area.iter()
                    .enumerate()
                    .filter(|(_, a)| a.0 > 0.0)
                    .map(|(k, a)| (k as u8, a.1.normalize_or_zero().as_vec3())),
            );
            ranges.push(bins.len() as u32);
        }
        ClusterLinks {
            tree,
            links,
            bins,
            ranges,
        }
    }

    /// Each node's power (Σ A·B/π, one channel) per bin, from the elements'
    /// radiosities `node_b` (pulled: a root's is its patches' mean).
    pub(super) fn powers(&self, patches: &Patches, node_b: &[f64]) -> Vec<[f64; BINS]> {
        let nodes = &self.tree.nodes;
        let mut power = vec![[0.0; BINS]; nodes.len()];
        // Children follow their parent: from the last node back, children first.
        for n in (0..nodes.len()).rev() {
            match nodes[n].kind {
                ClusterKind::Inner([a, b]) => {
                    power[n] = std::array::from_fn(|i| power[a as usize][i] + power[b as usize][i]);
                }
                ClusterKind::Leaf(s, e) => {
                    for &r in &self.tree.roots[s as usize..e as usize] {
                        let el = &patches.elements[r as usize];
                        let w = node_b[r as usize] * el.area / std::f64::consts::PI;
                        for side in sides(el) {
                            power[n][normal_bin(side)] += w;
                        }
                    }
                }
            }
        }
        power
    }

    /// The radiant intensity of `node` towards unit `w`, given its powers.
    pub(super) fn intensity(&self, node: u32, power: &[f64; BINS], w: DVec3) -> f64 {
        let (a, b) = (self.ranges[node as usize], self.ranges[node as usize + 1]);
        self.bins[a as usize..b as usize]
            .iter()
            .map(|(k, n)| power[*k as usize] * n.as_dvec3().dot(w).max(0.0))
            .sum()
    }

    /// Adds to `node_h` (per element) the irradiance each linked room
    /// element gathers from the clusters, given radiosities `node_b`.
    pub(super) fn gather_into(&self, patches: &Patches, node_b: &[f64], node_h: &mut [f64]) {
        if self.links.is_empty() {
            return;
        }
        let power = self.powers(patches, node_b);
        for l in &self.links {
            let i = self.intensity(l.node, &power[l.node as usize], l.direction.as_dvec3());
            node_h[l.receiver as usize] += l.geometry as f64 * i;
        }
    }

    pub fn memory_bytes(&self) -> usize {
        self.links.len() * std::mem::size_of::<ClusterLink>()
            + self.tree.nodes.len() * std::mem::size_of::<Cluster>()
            + self.tree.roots.len() * 4
            + self.bins.len() * std::mem::size_of::<(u8, Vec3)>()
            + self.ranges.len() * 4
    }
}

/// What element `p` (the room's, or an object's gathering from the
/// objects) gathers from cluster `node` of `with.objects`:
/// one [`ClusterLink`] where the cluster is far enough that the factor's
/// spread over the pair, F × (((d + r) / (d − r))² − 1) with r the two
/// radii, is within ε (F bounded by the cluster's area / 2πd²: no view
/// of a closed object shows more than half its surface) and the pair's
/// distance is at least twice r; otherwise the larger of the two is opened,
/// down to the roots, which [`refine`] links as elements.
pub(super) fn refine_cluster(
    with: &Refiner,
    p: u32,
    node: u32,
    room_roots: &[u32],
    out: &mut Vec<Link>,
    cluster_links: &mut Vec<ClusterLink>,
) {
    let tree = with.objects.expect("clusters to refine against");
    let (ep, c) = (
        &with.patches.elements[p as usize],
        &tree.nodes[node as usize],
    );
    let corners = crate::geometry::box_corners(c.lo, c.hi);
    if ep.one_sided
        && corners
            .iter()
            .all(|x| (*x - ep.centre).dot(ep.normal) <= 0.0)
    {
        return;
    }
    let cluster_radius = (c.hi - c.lo).length() / 2.0;
    let receiver_radius = (ep.bounds.1 - ep.bounds.0).length() / 2.0;
    let r = cluster_radius + receiver_radius;
    let d = (c.centroid - ep.centre).length();
    let far = d > 2.0 * r && {
        let f = c.area / (2.0 * std::f64::consts::PI * d * d);
        f * (((d + r) / (d - r)).powi(2) - 1.0) <= with.epsilon
    };
    if far {
        if let Some(link) = cluster_link(with, p, c.centroid) {
            cluster_links.push(ClusterLink { node, ..link });
        }
        return;
    }
    match c.kind {
        ClusterKind::Leaf(s, e) => {
            // An object's element gathering from the objects: never from
            // its own root (a flat element sends itself nothing).
            let own = with.patches.elements[p as usize].root;
            for &root in (tree.roots[s as usize..e as usize].iter()).filter(|&&r| r != own) {
                refine(with, p, root, room_roots, out);
            }
        }
        ClusterKind::Inner(children)
            if ep.children.is_none() || cluster_radius >= receiver_radius =>
        {
            for child in children {
                refine_cluster(with, p, child, room_roots, out, cluster_links);
            }
        }
        ClusterKind::Inner(_) => {
            for child in ep.children.expect("not a leaf") {
                refine_cluster(with, child, node, room_roots, out, cluster_links);
            }
        }
    }
}

/// The link from room element `p` to a cluster centred at `target` (its
/// node left 0): cosθ/d² averaged over p's 2×2 points, each times whether
/// the room lets its ray to the target through. None when nothing arrives.
fn cluster_link(with: &Refiner, p: u32, target: DVec3) -> Option<ClusterLink> {
    let ep = &with.patches.elements[p as usize];
    let points = ep.shape.quadrature(2);
    let rays: Vec<TraceRay> = points
        .iter()
        .map(|(x, _)| segment(offset_origin(*x, ep.normal, target), target))
        .collect();
    let mut blocked = vec![false; rays.len()];
    with.tracer.occluded_batch(&rays, Layer::Real, &mut blocked);
    let geometry: f64 = points
        .iter()
        .zip(&blocked)
        .filter(|(_, b)| !**b)
        .map(|((x, w), _)| {
            let v = target - *x;
            let d2 = v.length_squared().max(1e-300);
            let cos = ep.normal.dot(v) / d2.sqrt();
            let cos = if ep.one_sided {
                cos.max(0.0)
            } else {
                cos.abs()
            };
            w * cos / d2
        })
        .sum();
    (geometry > 0.0).then(|| ClusterLink {
        receiver: p,
        node: 0,
        geometry: geometry as f32,
        direction: (ep.centre - target).normalize_or_zero().as_vec3(),
    })
}
