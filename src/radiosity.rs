//! Radiosity over [`Patches`]: B = ρ·(E + Σ F·B), with E the direct
//! irradiance from the lights and F the form factors between elements.
//!
//! Form factors ([`element_form_factor`]) integrate the exact point-to-polygon
//! form factor over the receiver with one Gauss rule for all pairs, so they
//! stay finite for touching elements and the factors out of a receiver in a
//! closed room sum to one (a receiver lying across a one-sided source's
//! plane is integrated over the source instead: a step across it would
//! otherwise fall between its Gauss points); visibility is the fraction of
//! Embree rays between the two elements that pass.
//!
//! [`Transport`] is either the full patch-to-patch matrix (small scenes, and
//! the test oracle) or hierarchical radiosity (Hanrahan et al. 1991, Loscos
//! §2.3): links between elements at the level an oracle deems accurate,
//! gathered at each level, irradiance pushed down and radiosity pulled up.
//! [`solve`] solves (I − ρT)B = b by restarted GMRES: the plain gather
//! iteration ([`solve_by_iteration`]) needs ~ln(tol)/ln(ρ) sweeps, hundreds
//! at ρ = 0.99, where GMRES needs a handful.

use glam::DVec3;
use rayon::prelude::*;

use crate::light::{LightSource, offset_origin, segment};
use crate::objects::VirtualBounds;
use crate::patches::{Element, Patches};
use crate::shaft::Shaft;
use crate::trace::{Layer, TraceRay, Tracer};

/// Default refinement threshold of hierarchical radiosity: on the desk at
/// 0.5 m patches it keeps every patch within 0.4% of the full matrix with
/// 80% of its form factors (1.5% at 0.003, 0.3% at 0.001; see
/// tests/radiosity_desk.rs).
pub const DEFAULT_LINK_EPSILON: f64 = 0.002;

/// A partly hidden pair is refined while its unoccluded form factor exceeds
/// this fraction of ε; below it, rays at that level estimate visibility.
/// Measured on the desk (0.25 m): 1 (refine only above ε) keeps 287k links
/// but the hierarchical solution drifts 5% from the full matrix; 0.1 stays
/// within 1% with 359k links; refining every hidden pair to the leaves
/// needs 387k links and twice the time.
pub const VISIBILITY_REFINE_FRACTION: f64 = 0.1;

/// Below this many links a gather runs on one thread: waking the others
/// costs more than the few microseconds of work (a solve applies it
/// dozens of times).
const SERIAL_GATHER_LINKS: usize = 1 << 16;

/// Receiver quadrature order of the unoccluded form factor. It is the same
/// for every pair, so that the factors out of one receiver sum to the exact
/// fraction of its hemisphere the sources cover (one in a closed room):
/// per-pair orders would each err a little and the errors add up, which a
/// reflectance of 0.99 amplifies a hundredfold.
const FF_ORDER: usize = 3;

/// Visibility sampling: rays from `r`×`r` receiver points to `m`×`m`
/// source points. Elements above the leaves always get 2×2, so that a
/// partial occlusion shows as such and makes refinement go deeper.
fn visibility_sampling(p: &Element, q: &Element) -> (usize, usize) {
    let d = (q.centre - p.centre).length().max(1e-12);
    let r = if d > 3.0 * p.size && p.children.is_none() {
        1
    } else {
        2
    };
    let m = if d > 3.0 * q.size && q.children.is_none() {
        1
    } else {
        2
    };
    (r, m)
}

/// Whether two elements lie in one plane (they exchange no light).
fn coplanar(p: &Element, q: &Element) -> bool {
    let scale = p.size.max(q.size);
    p.normal.dot(q.normal).abs() > 1.0 - 1e-9
        && (q.centre - p.centre).dot(p.normal).abs() < 1e-9 * scale.max(1e-9)
}

/// Whether a one-sided element has the other wholly behind its plane: then
/// [`point_factor`] is zero for every point of every sub-element pair (the
/// receiver sees nothing behind it, the source sends nothing backwards), so
/// the pair needs neither an occluder search nor a link.
fn faces_away(p: &Element, q: &Element) -> bool {
    let behind = |e: &Element, other: &Element| {
        e.one_sided
            && other
                .shape
                .corners()
                .iter()
                .all(|c| (*c - e.centre).dot(e.normal) <= 0.0)
    };
    behind(p, q) || behind(q, p)
}

/// Whether receiver `p` lies partly in front of one-sided source `q` and
/// partly behind it: its points then gather from q or not at all, a step
/// that the few points of [`factor_spread`] and the quadrature of
/// [`unoccluded_form_factor`] can miss (a table top beside a leg's face sees
/// it from a strip as wide as the leg is from the table's edge).
fn straddles(p: &Element, q: &Element) -> bool {
    if !q.one_sided {
        return false;
    }
    let slack = 1e-9 * p.size.max(q.size).max(1e-9);
    let (mut front, mut behind) = (false, false);
    for c in p.shape.corners().iter() {
        let d = (*c - q.centre).dot(q.normal);
        front |= d > slack;
        behind |= d < -slack;
    }
    front && behind
}

/// The exact unoccluded form factor from point `x` of receiver `p` to the
/// polygon of source `q`, minding one-sided elements: a solid's face
/// receives only from outside and sends only outwards.
fn point_factor(x: DVec3, p: &Element, q: &Element, polygon: &[DVec3]) -> f64 {
    if q.one_sided && (x - q.centre).dot(q.normal) <= 0.0 {
        return 0.0;
    }
    crate::light::polygon_form_factor_sided(x, p.normal, polygon, !p.one_sided)
}

/// The unoccluded form factor from receiver `p` to source `q`: the exact
/// point-to-polygon factor integrated over p by Gauss quadrature.
pub fn unoccluded_form_factor(p: &Element, q: &Element) -> f64 {
    if coplanar(p, q) {
        return 0.0;
    }
    // A receiver partly behind a one-sided source gathers from the part in
    // front only: a step across p that its quadrature points place badly.
    // Integrated over q instead (A_p·F_pq = A_q·F_qp), each point of q
    // clips p to q's front exactly.
    if straddles(p, q) && !straddles(q, p) && p.area > 0.0 {
        let polygon = p.shape.corners();
        let f: f64 = q
            .shape
            .quadrature(FF_ORDER)
            .into_iter()
            .map(|(y, w)| w * point_factor(y, q, p, &polygon))
            .sum();
        return f * q.area / p.area;
    }
    let polygon = q.shape.corners();
    p.shape
        .quadrature(FF_ORDER)
        .into_iter()
        .map(|(x, w)| w * point_factor(x, p, q, &polygon))
        .sum()
}

/// The two shafts `ShaftTest` tests roots against, built when first
/// needed: Haines & Wallace's shaft between the two elements' boxes (cheap,
/// and holding the exact hull, so what it excludes the hull excludes too),
/// then the hull. Most pairs' roots never pass the box test and need neither.
/// A room's pair keeps them across updates ([`RoomLinkFacts`]).
#[derive(Debug, Default)]
pub struct PairShafts {
    coarse: std::sync::OnceLock<Shaft>,
    hull: std::sync::OnceLock<Shaft>,
}

/// Tests root elements against the shaft between two elements.
struct ShaftTest<'a> {
    patches: &'a Patches,
    layer: Layer,
    p: &'a Element,
    q: &'a Element,
    lo: DVec3,
    hi: DVec3,
    slack: f64,
    shafts: &'a PairShafts,
    /// p's plane and q's, each with its normal turned to the side light
    /// crosses it on: a one-sided element's front, or the side the other
    /// element lies wholly on. A root wholly behind either cannot meet a
    /// segment that carries light between the two.
    planes: [Option<(DVec3, DVec3)>; 2],
    plane_slack: f64,
}

impl<'a> ShaftTest<'a> {
    fn new(
        patches: &'a Patches,
        layer: Layer,
        p: &'a Element,
        q: &'a Element,
        shafts: &'a PairShafts,
    ) -> Self {
        let ((plo, phi), (qlo, qhi)) = (p.bounds, q.bounds);
        let (lo, hi) = (plo.min(qlo), phi.max(qhi));
        let slack = 1e-9 * (hi - lo).max_element().max(1.0);
        let facing = |e: &Element, other: &Element| -> Option<(DVec3, DVec3)> {
            if e.one_sided {
                return Some((e.centre, e.normal));
            }
            let d = other
                .shape
                .corners()
                .iter()
                .map(|c| (*c - e.centre).dot(e.normal))
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| {
                    (lo.min(d), hi.max(d))
                });
            if d.0 > slack {
                Some((e.centre, e.normal))
            } else if d.1 < -slack {
                Some((e.centre, -e.normal))
            } else {
                None
            }
        };
        let planes = [facing(p, q), facing(q, p)];
        // Single-precision vertices leave a solid's corners ~1e-7 of the
        // coordinates off its neighbouring faces' planes; rays start 1e-5 off.
        let plane_slack = 1e-6 * (hi - lo).max_element().max(1.0);
        ShaftTest {
            patches,
            layer,
            p,
            q,
            lo,
            hi,
            slack,
            shafts,
            planes,
            plane_slack,
        }
    }

    /// Whether root `r` may block light between p and q: it is in the
    /// layer, coplanar with neither, behind neither's plane (a solid's own
    /// faces, for one), and the shaft does not exclude it.
    fn may_block(&self, r: u32) -> bool {
        let root = &self.patches.elements[r as usize];
        // Cheapest first: most roots lie outside the pair's box. Boxes that
        // only touch cannot hold an occluder between p and q.
        let (rlo, rhi) = root.bounds;
        if (rlo - self.slack).cmpge(self.hi).any() || (rhi + self.slack).cmple(self.lo).any() {
            return false;
        }
        let in_layer = match self.layer {
            Layer::All => true,
            layer => self.patches.is_virtual_element(r) == (layer == Layer::Virtual),
        };
        if !in_layer || coplanar(root, self.p) || coplanar(root, self.q) {
            return false;
        }
        let corners = root.shape.corners();
        let behind =
            |&(o, n): &(DVec3, DVec3)| corners.iter().all(|c| (*c - o).dot(n) <= self.plane_slack);
        if self.planes.iter().flatten().any(behind) {
            return false;
        }
        let (p, q) = (self.p, self.q);
        if self
            .shafts
            .coarse
            .get_or_init(|| Shaft::between_boxes(p.bounds, q.bounds))
            .excludes(&corners)
        {
            return false;
        }
        !self
            .shafts
            .hull
            .get_or_init(|| Shaft::between_polygons(&p.shape.corners(), &q.shape.corners()))
            .excludes(&corners)
    }
}

/// The root elements among `candidates` that may block light between `p`
/// and `q` (see `ShaftTest`). Empty means certainly visible. A child
/// pair's shaft lies inside its parents', so their occluders are a subset.
pub fn occluders_between(
    patches: &Patches,
    layer: Layer,
    p: &Element,
    q: &Element,
    candidates: &[u32],
) -> Vec<u32> {
    occluders_between_using(patches, layer, p, q, candidates, &PairShafts::default())
}

/// [`occluders_between`] with the pair's shafts kept in `shafts`.
fn occluders_between_using(
    patches: &Patches,
    layer: Layer,
    p: &Element,
    q: &Element,
    candidates: &[u32],
    shafts: &PairShafts,
) -> Vec<u32> {
    if candidates.is_empty() {
        return Vec::new();
    }
    let test = ShaftTest::new(patches, layer, p, q, shafts);
    // Sized at once: grown from empty, a list of a few dozen moved twice.
    let mut found = Vec::with_capacity(candidates.len());
    found.extend(candidates.iter().copied().filter(|&r| test.may_block(r)));
    found
}

/// Whether any of `candidates` may block light between `p` and `q`.
pub fn may_be_occluded(
    patches: &Patches,
    layer: Layer,
    p: &Element,
    q: &Element,
    candidates: &[u32],
) -> bool {
    may_be_occluded_using(patches, layer, p, q, candidates, &PairShafts::default())
}

/// [`may_be_occluded`] with the pair's shafts kept in `shafts`.
fn may_be_occluded_using(
    patches: &Patches,
    layer: Layer,
    p: &Element,
    q: &Element,
    candidates: &[u32],
    shafts: &PairShafts,
) -> bool {
    let test = ShaftTest::new(patches, layer, p, q, shafts);
    candidates.iter().any(|&r| test.may_block(r))
}

/// The fraction of rays between points of `p` and points of `q` that no
/// geometry of `layer` blocks.
pub fn visibility(p: &Element, q: &Element, tracer: &Tracer, layer: Layer) -> f64 {
    let rays = visibility_rays(p, q);
    let mut blocked = vec![false; rays.len()];
    tracer.occluded_batch(&rays, layer, &mut blocked);
    blocked.iter().filter(|b| !**b).count() as f64 / rays.len() as f64
}

/// The rays [`visibility`] traces between `p` and `q`.
fn visibility_rays(p: &Element, q: &Element) -> Vec<TraceRay> {
    let (r, m) = visibility_sampling(p, q);
    let targets: Vec<DVec3> = q.shape.quadrature(m).into_iter().map(|(x, _)| x).collect();
    let origins = p.shape.quadrature(r);
    let mut rays = Vec::with_capacity(origins.len() * targets.len());
    rays.extend(origins.into_iter().flat_map(|(x, _)| {
        targets
            .iter()
            .map(move |&t| segment(offset_origin(x, p.normal, t), t))
    }));
    rays
}

/// Which of a pair's `rays` ([`visibility_rays`]) the room's geometry
/// blocks, bit k for ray k (None: more rays than bits). Traced even where
/// no room root may block the pair: [`visibility`] traces the room too
/// once an object may, and its rays can meet what the shafts leave out (a
/// neighbouring surface at their very start).
fn room_blocked(rays: &[TraceRay], tracer: &Tracer) -> Option<u64> {
    if rays.len() > 64 {
        return None;
    }
    let mut blocked = vec![false; rays.len()];
    tracer.occluded_batch(rays, Layer::Real, &mut blocked);
    Some(
        blocked
            .iter()
            .enumerate()
            .fold(0, |m, (k, b)| m | (*b as u64) << k),
    )
}

/// [`visibility`] through all geometry of a pair's `rays`, `room` giving
/// which the room blocks (see [`room_blocked`]): they are traced through the
/// objects alone, as [`Layer::All`] traces them after the room (all of
/// them, in the same packets: Embree may decide a grazing ray differently
/// in a packet with fewer rays), so the same fraction results.
fn visibility_with_room(rays: &[TraceRay], tracer: &Tracer, room: u64) -> f64 {
    let mut blocked = vec![false; rays.len()];
    tracer.occluded_batch(rays, Layer::Virtual, &mut blocked);
    blocked
        .iter()
        .enumerate()
        .filter(|(k, b)| room >> k & 1 == 0 && !**b)
        .count() as f64
        / rays.len() as f64
}

/// The form factor from receiver element `p` to source element `q` (what
/// p gathers: H_p = Σ F_pq·B_q; A_p·F_pq = A_q·F_qp): unoccluded factor
/// times visibility. `None` for the tracer means unoccluded.
pub fn element_form_factor(p: &Element, q: &Element, tracer: Option<(&Tracer, Layer)>) -> f64 {
    let f = unoccluded_form_factor(p, q);
    match tracer {
        Some((tracer, layer)) if f > 0.0 => f * visibility(p, q, tracer, layer),
        _ => f,
    }
}

/// A hierarchical link: `receiver` gathers `form_factor × B(source)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Link {
    pub receiver: u32,
    pub source: u32,
    pub form_factor: f32,
}

/// How light moves between patches.
#[derive(Debug, Clone, PartialEq)]
pub enum Transport {
    /// Row-major patch × patch form factors.
    Full { n: usize, form_factors: Vec<f32> },
    /// Links between elements of the hierarchy, sorted by receiver, and
    /// each receiver's range of them.
    Hierarchical {
        links: Vec<Link>,
        ranges: Vec<(u32, u32, u32)>,
    },
}

impl Transport {
    /// Every patch against every other: N² form factors.
    pub fn full(patches: &Patches, tracer: &Tracer, layer: Layer) -> Transport {
        let n = patches.patch_count();
        // Possible occluders between each pair of roots, narrowed per patch pair.
        let roots = &patches.roots;
        let root_index: std::collections::HashMap<u32, usize> =
            roots.iter().enumerate().map(|(i, r)| (*r, i)).collect();
        let between: Vec<Vec<u32>> = (0..roots.len() * roots.len())
            .into_par_iter()
            .map(|k| {
                let (a, b) = (
                    &patches.elements[roots[k / roots.len()] as usize],
                    &patches.elements[roots[k % roots.len()] as usize],
                );
                occluders_between(patches, layer, a, b, roots)
            })
            .collect();
        let mut ff = vec![0f32; n * n];
        ff.par_chunks_mut(n.max(1))
            .enumerate()
            .for_each(|(i, row)| {
                let p = patches.patch(i);
                let ri = root_index[&p.root];
                for (j, f) in row.iter_mut().enumerate() {
                    if i != j {
                        let q = patches.patch(j);
                        let u = unoccluded_form_factor(p, q);
                        if u > 0.0 {
                            let candidates = &between[ri * roots.len() + root_index[&q.root]];
                            let occluded = may_be_occluded(patches, layer, p, q, candidates);
                            let v = if occluded {
                                visibility(p, q, tracer, layer)
                            } else {
                                1.0
                            };
                            *f = (u * v) as f32;
                        }
                    }
                }
            });
        Transport::Full {
            n,
            form_factors: ff,
        }
    }

    /// Hierarchical radiosity: starting from every pair of root elements,
    /// refined (see `refine`) until one form factor represents each
    /// exchange to within `epsilon`.
    pub fn hierarchical(
        patches: &Patches,
        tracer: &Tracer,
        layer: Layer,
        epsilon: f64,
    ) -> Transport {
        let links: Vec<Link> = patches
            .roots
            .par_iter()
            .flat_map_iter(|&p| {
                let mut out = Vec::new();
                let with = Refiner {
                    patches,
                    tracer,
                    layer,
                    epsilon,
                    trace_first: false,
                };
                for &q in &patches.roots {
                    if p != q {
                        refine(&with, p, q, &patches.roots, &mut out);
                    }
                }
                out
            })
            .collect();
        Transport::hierarchical_from_links(links)
    }

    /// This transport (of a room's patches) with virtual objects added:
    /// `patches` holds the room's elements first, unchanged, then the
    /// objects'. Hierarchical links whose shaft cannot meet an object are
    /// kept; the others are refined again with the objects as occluders;
    /// the objects' elements are linked with everything. A full matrix is
    /// rebuilt.
    ///
    /// With `objects_receive` false the objects get no links of their own to
    /// gather through (the caller supplies their light, e.g. by final
    /// gathering from the photo); they still send light and shadow the room.
    pub fn with_objects(
        &self,
        patches: &Patches,
        tracer: &Tracer,
        epsilon: f64,
        objects_receive: bool,
    ) -> Transport {
        self.with_objects_using(patches, tracer, epsilon, objects_receive, None)
    }

    /// [`Transport::with_objects`], keeping in `facts` (made for this
    /// transport by [`RoomLinkFacts::new`]) what it learns about the room's
    /// links for the next placement of the objects: the same links result.
    pub fn with_objects_using(
        &self,
        patches: &Patches,
        tracer: &Tracer,
        epsilon: f64,
        objects_receive: bool,
        facts: Option<&RoomLinkFacts>,
    ) -> Transport {
        let Transport::Hierarchical {
            links: room_links, ..
        } = self
        else {
            return Transport::full(patches, tracer, Layer::All);
        };
        let is_virtual = |r: &u32| patches.is_virtual_element(*r);
        let object_roots: Vec<u32> = patches.roots.iter().copied().filter(is_virtual).collect();
        let all_roots = &patches.roots;
        // The objects' joint box first: most room links' boxes miss it.
        let (olo, ohi) = object_roots
            .iter()
            .map(|&r| patches.elements[r as usize].bounds)
            .fold(
                (DVec3::INFINITY, DVec3::NEG_INFINITY),
                |(lo, hi), (a, b)| (lo.min(a), hi.max(b)),
            );
        let object_box = crate::geometry::box_corners(olo, ohi);
        // The candidates are the objects' own roots: no layer to look up per root.
        let near_objects = |i: usize| {
            let l = &room_links[i];
            let (a, b) = (
                &patches.elements[l.receiver as usize],
                &patches.elements[l.source as usize],
            );
            let ((alo, ahi), (blo, bhi)) = (a.bounds, b.bounds);
            let (lo, hi) = (alo.min(blo), ahi.max(bhi));
            if olo.cmpgt(hi).any() || ohi.cmplt(lo).any() {
                return false;
            }
            match facts.and_then(|f| f.shafts.get(i)) {
                // A shaft that leaves out the objects' whole box leaves out each of their roots.
                Some(shafts) => {
                    !shafts
                        .coarse
                        .get_or_init(|| Shaft::between_boxes(a.bounds, b.bounds))
                        .excludes(&object_box)
                        && may_be_occluded_using(patches, Layer::All, a, b, &object_roots, shafts)
                }
                None => may_be_occluded(patches, Layer::All, a, b, &object_roots),
            }
        };
        let near: Vec<bool> = (0..room_links.len())
            .into_par_iter()
            .map(near_objects)
            .collect();
        let mut links: Vec<Link> = room_links
            .iter()
            .zip(&near)
            .filter(|(_, n)| !**n)
            .map(|(l, _)| *l)
            .collect();
        let room_roots: Vec<u32> = all_roots
            .iter()
            .copied()
            .filter(|r| !is_virtual(r))
            .collect();
        // One task per room link the objects may shadow and per (object
        // root, root) pair, so that both cores share the few large ones.
        enum Task {
            Room(usize),
            Object(u32, u32),
        }
        let tasks: Vec<Task> = (0..room_links.len())
            .filter(|&i| near[i])
            .map(Task::Room)
            .chain(object_roots.iter().flat_map(|&v| {
                all_roots
                    .iter()
                    .filter(move |&&r| r != v)
                    .map(move |&r| Task::Object(v, r))
            }))
            .collect();
        let with = Refiner {
            patches,
            tracer,
            layer: Layer::All,
            epsilon,
            trace_first: true,
        };
        let new: Vec<Link> = tasks
            .par_iter()
            .with_max_len(4)
            .flat_map_iter(|task| {
                let mut out = Vec::new();
                match *task {
                    Task::Room(i) => {
                        let l = room_links[i];
                        let (ep, eq) = (
                            &patches.elements[l.receiver as usize],
                            &patches.elements[l.source as usize],
                        );
                        match facts.and_then(|f| Some((f.facts.get(i)?, f.shafts.get(i)?))) {
                            Some((cell, shafts)) => {
                                let known = cell.get_or_init(|| {
                                    PairFacts::of(patches, tracer, ep, eq, &room_roots, shafts)
                                });
                                refine_from(
                                    &with,
                                    l.receiver,
                                    l.source,
                                    all_roots,
                                    Some((known, &object_roots, shafts)),
                                    &mut out,
                                );
                            }
                            None => refine(&with, l.receiver, l.source, all_roots, &mut out),
                        }
                    }
                    Task::Object(v, r) => {
                        if objects_receive {
                            refine(&with, v, r, all_roots, &mut out);
                        }
                        if !is_virtual(&r) {
                            refine(&with, r, v, all_roots, &mut out);
                        }
                    }
                }
                out
            })
            .collect();
        links.extend(new);
        Transport::hierarchical_from_links(links)
    }

    fn hierarchical_from_links(mut links: Vec<Link>) -> Transport {
        links.sort_by_key(|l| (l.receiver, l.source));
        let mut ranges: Vec<(u32, u32, u32)> = Vec::new();
        for (i, l) in links.iter().enumerate() {
            match ranges.last_mut() {
                Some(r) if r.0 == l.receiver => r.2 = i as u32 + 1,
                _ => ranges.push((l.receiver, i as u32, i as u32 + 1)),
            }
        }
        Transport::Hierarchical { links, ranges }
    }

    /// Number of form factors stored (links, or the matrix's non-zeros).
    pub fn link_count(&self) -> usize {
        match self {
            Transport::Full { form_factors, .. } => {
                form_factors.iter().filter(|f| **f != 0.0).count()
            }
            Transport::Hierarchical { links, .. } => links.len(),
        }
    }

    pub fn memory_bytes(&self) -> usize {
        match self {
            Transport::Full { form_factors, .. } => form_factors.len() * 4,
            Transport::Hierarchical { links, ranges } => {
                links.len() * std::mem::size_of::<Link>()
                    + ranges.len() * std::mem::size_of::<(u32, u32, u32)>()
            }
        }
    }

    /// Irradiance each patch gathers from patch radiosities `b` (one channel).
    pub fn gather(&self, patches: &Patches, b: &[f64], out: &mut [f64]) {
        match self {
            Transport::Full { n, form_factors } => {
                out.par_iter_mut().enumerate().for_each(|(i, o)| {
                    let row = &form_factors[i * n..(i + 1) * n];
                    *o = row.iter().zip(b).map(|(f, b)| *f as f64 * b).sum();
                });
            }
            Transport::Hierarchical { links, ranges } => {
                let elements = &patches.elements;
                // Pull: an element's radiosity is the area-weighted mean of its
                // children's (children follow their parent in the arena).
                let mut node_b = vec![0.0; elements.len()];
                for (k, &e) in patches.patches.iter().enumerate() {
                    node_b[e as usize] = b[k];
                }
                for e in (0..elements.len()).rev() {
                    if let Some([c0, c1]) = elements[e].children {
                        let (a0, a1) = (elements[c0 as usize].area, elements[c1 as usize].area);
                        node_b[e] =
                            (node_b[c0 as usize] * a0 + node_b[c1 as usize] * a1) / (a0 + a1);
                    }
                }
                let gather_range = |&(_, a, b): &(u32, u32, u32)| -> f64 {
                    links[a as usize..b as usize]
                        .iter()
                        .map(|l| l.form_factor as f64 * node_b[l.source as usize])
                        .sum()
                };
                let gathered: Vec<f64> = if links.len() < SERIAL_GATHER_LINKS {
                    ranges.iter().map(gather_range).collect()
                } else {
                    ranges.par_iter().map(gather_range).collect()
                };
                let mut node_h = vec![0.0; elements.len()];
                for (&(receiver, _, _), h) in ranges.iter().zip(gathered) {
                    node_h[receiver as usize] = h;
                }
                // Push: what an element gathers reaches every point of its children.
                for e in 0..elements.len() {
                    if let Some(parent) = elements[e].parent {
                        node_h[e] += node_h[parent as usize];
                    }
                }
                for (k, &e) in patches.patches.iter().enumerate() {
                    out[k] = node_h[e as usize];
                }
            }
        }
    }

    /// Irradiance per patch from RGB radiosities.
    pub fn gather_rgb(&self, patches: &Patches, b: &[DVec3]) -> Vec<DVec3> {
        let n = b.len();
        let mut out = vec![DVec3::ZERO; n];
        let mut channel = vec![0.0; n];
        let mut h = vec![0.0; n];
        for c in 0..3 {
            for (x, v) in channel.iter_mut().zip(b) {
                *x = v[c];
            }
            self.gather(patches, &channel, &mut h);
            for (o, v) in out.iter_mut().zip(&h) {
                o[c] = *v;
            }
        }
        out
    }
}

/// The exact unoccluded point-to-polygon factor towards `q` at the centre
/// and (slightly inset) corners of `p`: their spread bounds how much the
/// irradiance p gathers from q varies across p.
fn factor_spread(p: &Element, q: &Element) -> (f64, f64) {
    let polygon = q.shape.corners();
    let mut lo = f64::INFINITY;
    let mut hi: f64 = 0.0;
    let mut mean = 0.0;
    let corners = p.shape.corners();
    for x in corners
        .iter()
        .map(|c| p.centre + (*c - p.centre) * 0.9)
        .chain(std::iter::once(p.centre))
    {
        let f = point_factor(x, p, q, &polygon);
        lo = lo.min(f);
        hi = hi.max(f);
        mean += f;
    }
    (hi - lo, mean / (corners.len() + 1) as f64)
}

/// How unevenly `p` sees the points of `q`: the relative spread of the
/// point-to-point kernel cosθ_p·cosθ_q/r² from p's centre over q's corners
/// and centre. Averaging q's radiosity over q errs by about F × this × the
/// relative variation of that radiosity.
fn source_spread(p: &Element, q: &Element) -> f64 {
    let corners = q.shape.corners();
    let (mut lo, mut hi, mut sum) = (f64::INFINITY, 0.0f64, 0.0);
    for y in corners
        .iter()
        .map(|c| q.centre + (*c - q.centre) * 0.9)
        .chain(std::iter::once(q.centre))
    {
        let r = y - p.centre;
        let d2 = r.length_squared().max(1e-300);
        let k = (p.normal.dot(r) * q.normal.dot(r)).abs() / (d2 * d2);
        lo = lo.min(k);
        hi = hi.max(k);
        sum += k;
    }
    let mean = sum / (corners.len() + 1) as f64;
    if mean > 0.0 { (hi - lo) / mean } else { 0.0 }
}

/// Links receiver `p` to source `q` where one form factor represents the
/// exchange to within `epsilon`. The receiver is subdivided while the
/// factor varies across it by more than epsilon, or while it lies across
/// the plane of a one-sided source ([`straddles`]): its points would gather
/// different amounts. The source while F × its [`source_spread`] exceeds
/// epsilon (its radiosity would be averaged with the wrong weights); the
/// larger of the two while they are partly hidden from each other.
fn refine(with: &Refiner, p: u32, q: u32, candidates: &[u32], out: &mut Vec<Link>) {
    refine_from(with, p, q, candidates, None, out);
}

/// What [`refine`] works with: the elements, the geometry that may block
/// them (`layer`), ε, and how a partly hidden pair above ε's fraction is
/// settled: split at once, or (`trace_first`) traced first and split only
/// where its rays disagree. Tracing first saves the split wherever the
/// rays all pass or all stop — a conservative shaft holds many roots that
/// block nothing — at the risk of missing a small occluder all of the
/// pair's rays pass by. The room's links are built once per scene and
/// split at once; the objects' are rebuilt at every move and traced first.
#[derive(Clone, Copy)]
struct Refiner<'a> {
    patches: &'a Patches,
    tracer: &'a Tracer,
    layer: Layer,
    epsilon: f64,
    trace_first: bool,
}

/// What refinement learns about a pair of the room's elements before any
/// object matters: its factors and the room's roots that may block it.
/// Kept per room link, an update that re-refines a link its objects may
/// shadow starts from these instead of computing them again.
#[derive(Debug, Clone, PartialEq)]
pub struct PairFacts {
    spread: f64,
    mean: f64,
    source_spread: f64,
    form_factor: f64,
    occluders: Vec<u32>,
    /// Which of the pair's visibility rays the room blocks ([`room_blocked`]).
    room_blocked: Option<u64>,
    /// The pair's visibility rays ([`visibility_rays`]), kept with what
    /// the room does to them (an update traces them again through the objects).
    rays: Vec<TraceRay>,
}

impl PairFacts {
    fn of(
        patches: &Patches,
        tracer: &Tracer,
        p: &Element,
        q: &Element,
        room_roots: &[u32],
        shafts: &PairShafts,
    ) -> PairFacts {
        let (spread, mean) = factor_spread(p, q);
        let occluders = occluders_between_using(patches, Layer::All, p, q, room_roots, shafts);
        let rays = visibility_rays(p, q);
        PairFacts {
            spread,
            mean,
            source_spread: source_spread(p, q),
            form_factor: unoccluded_form_factor(p, q),
            room_blocked: room_blocked(&rays, tracer),
            rays,
            occluders,
        }
    }
}

/// [`PairFacts`] and [`PairShafts`] per link of a room's transport, found
/// when first needed (every update asks each link whether the objects may
/// shadow it: the shafts are room geometry, the same each time).
#[derive(Debug, Default)]
pub struct RoomLinkFacts {
    facts: Vec<std::sync::OnceLock<PairFacts>>,
    shafts: Vec<PairShafts>,
}

impl RoomLinkFacts {
    pub fn new(transport: &Transport) -> RoomLinkFacts {
        let n = transport.link_count();
        RoomLinkFacts {
            facts: (0..n).map(|_| std::sync::OnceLock::new()).collect(),
            shafts: (0..n).map(|_| PairShafts::default()).collect(),
        }
    }
}

/// [`refine`], with the pair's room facts already known (`known`: the
/// facts, the other candidates — the objects' roots — and the pair's kept
/// shafts) at this first level.
fn refine_from(
    with: &Refiner,
    p: u32,
    q: u32,
    candidates: &[u32],
    known: Option<(&PairFacts, &[u32], &PairShafts)>,
    out: &mut Vec<Link>,
) {
    let Refiner {
        patches,
        tracer,
        layer,
        epsilon,
        trace_first,
    } = *with;
    let (ep, eq) = (&patches.elements[p as usize], &patches.elements[q as usize]);
    if coplanar(ep, eq) || faces_away(ep, eq) {
        return;
    }
    let occluders = match known {
        Some((facts, others, shafts)) => facts
            .occluders
            .iter()
            .copied()
            .chain(occluders_between_using(
                patches, layer, ep, eq, others, shafts,
            ))
            .collect(),
        None => occluders_between(patches, layer, ep, eq, candidates),
    };
    let facts = known.map(|k| k.0);
    let (p_leaf, q_leaf) = (ep.children.is_none(), eq.children.is_none());
    // Two leaves split neither way: their factors' spread decides nothing.
    let (spread, mean) = if p_leaf && q_leaf {
        (0.0, 0.0)
    } else {
        facts.map_or_else(|| factor_spread(ep, eq), |f| (f.spread, f.mean))
    };
    let split_receiver = if (spread > epsilon || straddles(ep, eq)) && !p_leaf {
        Some(true)
    } else if !q_leaf
        && mean * facts.map_or_else(|| source_spread(ep, eq), |f| f.source_spread) > epsilon
    {
        Some(false)
    } else {
        let f = facts.map_or_else(|| unoccluded_form_factor(ep, eq), |f| f.form_factor);
        if f <= 0.0 {
            return;
        }
        // Where the shaft between the two holds no possible occluder they
        // see each other whole. Otherwise rays estimate the visible part:
        // trusted where the exchange is small (its error is at most F), and
        // refined where it is not (Hanrahan's BFV refinement, exact shafts)
        // — with `trace_first`, only where the rays disagree (see [`Refiner`]).
        let occluded = !occluders.is_empty();
        let splits = occluded && f > epsilon * VISIBILITY_REFINE_FRACTION && !(p_leaf && q_leaf);
        // A room pair's rays through the room were traced before: only the objects are left.
        // Where no object may block, the rays skip the objects: one could
        // meet them only from the part of the receiver behind a one-sided
        // source's plane, light the form factor already leaves out (lost
        // twice, were it counted here).
        let traced = || match facts.and_then(|f| Some((f.room_blocked?, &f.rays))) {
            Some((room, rays)) if layer == Layer::All => visibility_with_room(rays, tracer, room),
            _ if layer == Layer::All
                && !occluders.iter().any(|&r| patches.is_virtual_element(r)) =>
            {
                visibility(ep, eq, tracer, Layer::Real)
            }
            _ => visibility(ep, eq, tracer, layer),
        };
        let visible = match (occluded, splits && !trace_first) {
            (false, _) => Some(1.0),
            (true, true) => None,
            (true, false) => Some(traced()),
        };
        match visible {
            Some(v) if !(splits && v > 0.0 && v < 1.0) => {
                if v > 0.0 {
                    out.push(Link {
                        receiver: p,
                        source: q,
                        form_factor: (f * v) as f32,
                    });
                }
                None
            }
            _ => Some(!p_leaf && (q_leaf || ep.area >= eq.area)),
        }
    };
    match split_receiver {
        Some(true) => ep
            .children
            .unwrap()
            .iter()
            .for_each(|&c| refine(with, c, q, &occluders, out)),
        Some(false) => eq
            .children
            .unwrap()
            .iter()
            .for_each(|&c| refine(with, p, c, &occluders, out)),
        None => {}
    }
}

/// Direct irradiance per patch from each light (before the light's scale):
/// the mean over 2×2 points of unoccluded irradiance × visibility, with
/// `2^level` shadow rays per point to rect lights. Indexed `[light][patch]`.
pub fn direct_irradiance(
    patches: &Patches,
    lights: &[LightSource],
    tracer: &Tracer,
    layer: Layer,
    level: usize,
) -> Vec<Vec<DVec3>> {
    lights
        .iter()
        .map(|light| {
            (0..patches.patch_count())
                .into_par_iter()
                .map(|k| patch_direct(patches, k, light, tracer, layer, level))
                .collect()
        })
        .collect()
}

/// [`direct_irradiance`] through real and virtual geometry, where `room`
/// holds the room's own values (through real geometry, for the first
/// patches): those are taken wherever the shaft from a patch to the
/// light excludes every one of the objects — no ray can meet an object
/// there, so the numbers are the same — and only the rest are traced.
/// An object's patch whose light only its own solid can block
/// ([`VirtualBounds::only_own_blocks`]) knows its rays without tracing.
pub fn direct_irradiance_with_objects(
    patches: &Patches,
    lights: &[LightSource],
    tracer: &Tracer,
    level: usize,
    room: &[Vec<DVec3>],
    objects: &VirtualBounds,
) -> Vec<Vec<DVec3>> {
    lights
        .iter()
        .zip(room)
        .enumerate()
        .map(|(l, (light, room))| {
            let light_box = light.bounds();
            (0..patches.patch_count())
                .into_par_iter()
                .map(|k| {
                    let el = patches.patch(k);
                    if k < room.len() {
                        let shaft = Shaft::between_boxes(el.bounds, light_box);
                        if objects.objects.iter().all(|o| o.outside(&shaft)) {
                            return room[k];
                        }
                    } else if objects.only_own_blocks(el.surface, el.centre, el.normal, l, light) {
                        return patch_direct_by(patches, k, light, |x, n, seed| {
                            light.direct_by(x, n, level, seed, |targets, _, blocked| {
                                for (b, t) in blocked.iter_mut().zip(targets) {
                                    *b = crate::objects::own_blocks(x, n, light.position, *t);
                                }
                            })
                        });
                    }
                    patch_direct(patches, k, light, tracer, Layer::All, level)
                })
                .collect()
        })
        .collect()
}

/// Patch k's direct irradiance from `light`: the mean over 2×2 points, or
/// over a split of the patch near the light ([`direct_split`]).
fn patch_direct(
    patches: &Patches,
    k: usize,
    light: &LightSource,
    tracer: &Tracer,
    layer: Layer,
    level: usize,
) -> DVec3 {
    patch_direct_by(patches, k, light, |x, n, seed| {
        light.direct(tracer, layer, x, n, level, seed)
    })
}

/// Parts per side a patch is split into to integrate a light's direct
/// irradiance over it: 1 (2×2 points) when the light is further from the
/// patch than the patch is wide; closer, the irradiance peaks within the
/// patch (1/d² under a lamp a few centimetres away holds much of the
/// light the patch receives) and 2×2 points would catch or miss the peak
/// by chance, so the patch is split until each part is about as wide as
/// the gap to the light (at most 16 per side).
fn direct_split(el: &crate::patches::Element, light: &LightSource) -> usize {
    let (lo, hi) = light.bounds();
    let nearest = el.centre.clamp(lo, hi);
    let gap = ((el.centre - nearest).length() - 0.5 * el.size).max(0.0);
    if gap >= el.size {
        return 1;
    }
    ((el.size / gap.max(el.size / 16.0)).ceil() as usize).clamp(2, 16)
}

/// [`patch_direct`], with `direct(point, normal, seed)` giving each point's
/// direct light (see [`LightSource::direct_by`]).
fn patch_direct_by(
    patches: &Patches,
    k: usize,
    light: &LightSource,
    direct: impl Fn(DVec3, DVec3, u64) -> crate::light::DirectLight,
) -> DVec3 {
    let el = patches.patch(k);
    el.shape
        .split_quadrature(direct_split(el, light))
        .iter()
        .enumerate()
        .map(|(i, (x, w))| {
            let seed = crate::util::rng::hash2(k as u64, i as u64);
            let d = direct(*x, el.normal, seed);
            d.unoccluded * d.visibility * *w
        })
        .sum()
}

/// Total direct irradiance per patch: Σ scale × per-light irradiance.
pub fn total_direct(scales: &[f64], per_light: &[Vec<DVec3>]) -> Vec<DVec3> {
    let n = per_light.first().map_or(0, |v| v.len());
    let mut e = vec![DVec3::ZERO; n];
    for (&scale, values) in scales.iter().zip(per_light) {
        if scale > 0.0 {
            for (e, v) in e.iter_mut().zip(values) {
                *e += *v * scale;
            }
        }
    }
    e
}

/// A solved system.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Radiosity per patch.
    pub radiosity: Vec<DVec3>,
    /// Irradiance each patch gathers from the others (the indirect light).
    pub indirect_irradiance: Vec<DVec3>,
    /// Operator applications (the largest over the three channels).
    pub iterations: usize,
    /// Final relative residual ‖b − (I − ρT)B‖ / ‖b‖ (largest channel).
    pub residual: f64,
}

/// Solves B = b + ρ ⊙ T(B) per channel by restarted GMRES, to relative
/// residual `tolerance`. For lights, b = ρ ⊙ E_direct.
pub fn solve(
    patches: &Patches,
    transport: &Transport,
    reflectance: &[DVec3],
    b: &[DVec3],
    tolerance: f64,
    max_iterations: usize,
) -> Solution {
    solve_from(
        patches,
        transport,
        reflectance,
        b,
        None,
        tolerance,
        max_iterations,
    )
}

/// [`solve`] starting from a guess (a previous solution of a nearby system).
pub fn solve_from(
    patches: &Patches,
    transport: &Transport,
    reflectance: &[DVec3],
    b: &[DVec3],
    guess: Option<&[DVec3]>,
    tolerance: f64,
    max_iterations: usize,
) -> Solution {
    let n = b.len();
    let mut radiosity = vec![DVec3::ZERO; n];
    let (mut iterations, mut residual) = (0, 0.0f64);
    for c in 0..3 {
        let rho: Vec<f64> = reflectance.iter().map(|r| r[c]).collect();
        let rhs: Vec<f64> = b.iter().map(|v| v[c]).collect();
        let apply = |x: &[f64], out: &mut [f64]| {
            transport.gather(patches, x, out);
            for ((o, x), r) in out.iter_mut().zip(x).zip(&rho) {
                *o = x - r * *o;
            }
        };
        let x0: Vec<f64> = match guess {
            Some(g) => g.iter().map(|v| v[c]).collect(),
            None => vec![0.0; n],
        };
        let (x, it, res) = gmres(apply, &rhs, x0, tolerance, max_iterations, 40);
        iterations = iterations.max(it);
        residual = residual.max(res);
        for (r, v) in radiosity.iter_mut().zip(x) {
            r[c] = v;
        }
    }
    finish(patches, transport, radiosity, iterations, residual)
}

/// The plain gather iteration B ← b + ρ ⊙ T(B) from B = b, until the
/// change is below `tolerance` (relative): the baseline GMRES is measured against.
pub fn solve_by_iteration(
    patches: &Patches,
    transport: &Transport,
    reflectance: &[DVec3],
    b: &[DVec3],
    tolerance: f64,
    max_iterations: usize,
) -> Solution {
    let mut x = b.to_vec();
    let norm = b
        .iter()
        .map(|v| v.length_squared())
        .sum::<f64>()
        .sqrt()
        .max(1e-300);
    let mut iterations = 0;
    let mut change = f64::INFINITY;
    while iterations < max_iterations && change > tolerance {
        let h = transport.gather_rgb(patches, &x);
        let next: Vec<DVec3> = b
            .iter()
            .zip(&h)
            .zip(reflectance)
            .map(|((b, h), r)| *b + *r * *h)
            .collect();
        change = next
            .iter()
            .zip(&x)
            .map(|(a, b)| (*a - *b).length_squared())
            .sum::<f64>()
            .sqrt()
            / norm;
        x = next;
        iterations += 1;
    }
    finish(patches, transport, x, iterations, change)
}

fn finish(
    patches: &Patches,
    transport: &Transport,
    radiosity: Vec<DVec3>,
    iterations: usize,
    residual: f64,
) -> Solution {
    let indirect_irradiance = transport.gather_rgb(patches, &radiosity);
    Solution {
        radiosity,
        indirect_irradiance,
        iterations,
        residual,
    }
}

/// Restarted GMRES for A x = b from the guess `x0`. Returns (x, operator
/// applications, relative residual).
fn gmres(
    apply: impl Fn(&[f64], &mut [f64]),
    b: &[f64],
    x0: Vec<f64>,
    tolerance: f64,
    max_iterations: usize,
    restart: usize,
) -> (Vec<f64>, usize, f64) {
    let n = b.len();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let bnorm = dot(b, b).sqrt();
    let mut x = x0;
    if bnorm == 0.0 || n == 0 {
        return (vec![0.0; n], 0, 0.0);
    }
    let mut iterations = 0;
    let mut ax = vec![0.0; n];
    loop {
        apply(&x, &mut ax);
        let r: Vec<f64> = b.iter().zip(&ax).map(|(b, a)| b - a).collect();
        let beta = dot(&r, &r).sqrt();
        if beta / bnorm <= tolerance || iterations >= max_iterations {
            return (x, iterations, beta / bnorm);
        }
        let mut v: Vec<Vec<f64>> = vec![r.iter().map(|r| r / beta).collect()];
        let mut h = vec![vec![0.0; restart]; restart + 1];
        let (mut cs, mut sn) = (vec![0.0; restart], vec![0.0; restart]);
        let mut g = vec![0.0; restart + 1];
        g[0] = beta;
        let mut k = 0;
        while k < restart && iterations < max_iterations {
            let mut w = vec![0.0; n];
            apply(&v[k], &mut w);
            iterations += 1;
            for (i, vi) in v.iter().enumerate() {
                h[i][k] = dot(&w, vi);
                for (wj, vj) in w.iter_mut().zip(vi) {
                    *wj -= h[i][k] * vj;
                }
            }
            h[k + 1][k] = dot(&w, &w).sqrt();
            for i in 0..k {
                let t = cs[i] * h[i][k] + sn[i] * h[i + 1][k];
                h[i + 1][k] = -sn[i] * h[i][k] + cs[i] * h[i + 1][k];
                h[i][k] = t;
            }
            let denom = h[k][k].hypot(h[k + 1][k]);
            (cs[k], sn[k]) = if denom == 0.0 {
                (1.0, 0.0)
            } else {
                (h[k][k] / denom, h[k + 1][k] / denom)
            };
            h[k][k] = denom;
            h[k + 1][k] = 0.0;
            g[k + 1] = -sn[k] * g[k];
            g[k] *= cs[k];
            let norm_w = dot(&w, &w).sqrt();
            k += 1;
            if g[k].abs() / bnorm <= tolerance || norm_w == 0.0 {
                break;
            }
            v.push(w.iter().map(|x| x / norm_w).collect());
        }
        // Back-substitution of the k×k triangle, then x += V y.
        let mut y = vec![0.0; k];
        for i in (0..k).rev() {
            let s: f64 = (i + 1..k).map(|j| h[i][j] * y[j]).sum();
            y[i] = if h[i][i] != 0.0 {
                (g[i] - s) / h[i][i]
            } else {
                0.0
            };
        }
        for (i, yi) in y.iter().enumerate() {
            for (xj, vj) in x.iter_mut().zip(&v[i]) {
                *xj += yi * vj;
            }
        }
    }
}

#[cfg(test)]
mod tests;
