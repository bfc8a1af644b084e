//! Form factors between elements: the exact point-to-polygon factor
//! integrated over the receiver, and the visibility between them by shafts
//! and rays.

use super::transport::*;
use crate::light::{offset_origin, segment};
use crate::patches::{Element, Patches};
use crate::shaft::Shaft;
use crate::trace::{Layer, TraceRay, Tracer};
use glam::DVec3;

/// Visibility sampling: rays from `r`×`r` receiver points to `m`×`m`
/// source points. Elements above the leaves always get 2×2, so that a
/// partial occlusion shows as such and makes refinement go deeper.
pub(super) fn visibility_sampling(p: &Element, q: &Element) -> (usize, usize) {
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
pub(super) fn coplanar(p: &Element, q: &Element) -> bool {
    let scale = p.size.max(q.size);
    p.normal.dot(q.normal).abs() > 1.0 - 1e-9
        && (q.centre - p.centre).dot(p.normal).abs() < 1e-9 * scale.max(1e-9)
}

/// Whether a one-sided element has the other wholly behind its plane: then
/// [`point_factor`] is zero for every point of every sub-element pair (the
/// receiver sees nothing behind it, the source sends nothing backwards), so
/// the pair needs neither an occluder search nor a link.
pub(super) fn faces_away(p: &Element, q: &Element) -> bool {
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
pub(super) fn straddles(p: &Element, q: &Element) -> bool {
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
pub(super) fn point_factor(x: DVec3, p: &Element, q: &Element, polygon: &[DVec3]) -> f64 {
    if q.one_sided && (x - q.centre).dot(q.normal) <= 0.0 {
        return 0.0;
    }
    crate::light::polygon_form_factor_sided(x, p.normal, polygon, !p.one_sided)
}

/// The unoccluded form factor from receiver `p` to source `q`: the exact
/// point-to-polygon factor integrated over p by Gauss quadrature.
pub(crate) fn unoccluded_form_factor(p: &Element, q: &Element) -> f64 {
    if coplanar(p, q) {
        return 0.0;
    }
    // A receiver partly behind a one-sided source gathers from the part in
    // front only: a step across p that its quadrature points place badly.
    // Integrated over q instead (A_p·F_pq = A_q·F_qp), each point of q
    // clips p to q's front exactly.
    if straddles(p, q) && !straddles(q, p) && p.area > 0.0 {
        return quadrature_factor(q, p) * q.area / p.area;
    }
    quadrature_factor(p, q)
}

/// Quadrature points a receiver's shape has at most ([`FF_ORDER`]²).
const QUADRATURE_POINTS: usize = 16;
const _: () = assert!(FF_ORDER * FF_ORDER <= QUADRATURE_POINTS);

/// [`point_factor`] from `p` to `q` at the quadrature points of `p`,
/// weighted and summed in their order: the points' factors taken at once
/// ([`crate::light::polygon_form_factors_sided`]), the same sum bit for bit.
fn quadrature_factor(p: &Element, q: &Element) -> f64 {
    let polygon = q.shape.corners();
    let (mut xs, mut ws, mut count) = (
        [DVec3::ZERO; QUADRATURE_POINTS],
        [0.0; QUADRATURE_POINTS],
        0,
    );
    (p.shape).for_each_quadrature_point(FF_ORDER, |x, w| {
        (xs[count], ws[count]) = (x, w);
        count += 1;
    });
    let mut factors = [0.0; QUADRATURE_POINTS];
    let (xs, factors) = (&xs[..count], &mut factors[..count]);
    point_factors(xs, p, q, &polygon, factors);
    let mut f = 0.0;
    for (w, factor) in ws.iter().zip(factors) {
        f += w * *factor;
    }
    f
}

/// [`point_factor`] at each of `xs` into `out`, taken at once
/// ([`crate::light::polygon_form_factors_sided`]): the same numbers bit
/// for bit.
pub(super) fn point_factors(
    xs: &[DVec3],
    p: &Element,
    q: &Element,
    polygon: &[DVec3],
    out: &mut [f64],
) {
    crate::light::polygon_form_factors_sided(xs, p.normal, polygon, !p.one_sided, out);
    for (x, f) in xs.iter().zip(out) {
        if q.one_sided && (*x - q.centre).dot(q.normal) <= 0.0 {
            *f = 0.0;
        }
    }
}

/// The shaft `ShaftTest` tests roots against, built when first needed:
/// the hull of the two elements. Most pairs' roots lie outside the pair's
/// box or behind a plane and need none. Haines & Wallace's shaft between
/// the two boxes, tested first, was built for 6.5 million pairs of
/// lounge's finer mesh and spared the hull 3.5% of them (without it, and
/// with the root pairs refined pair by pair, the links refined 8% faster;
/// the two were measured together).
#[derive(Debug, Default)]
pub struct PairShafts {
    pub(super) hull: std::sync::OnceLock<Shaft>,
}

/// Tests root elements against the shaft between two elements.
pub(super) struct ShaftTest<'a> {
    pub(super) patches: &'a Patches,
    pub(super) layer: Layer,
    pub(super) p: &'a Element,
    pub(super) q: &'a Element,
    pub(super) lo: DVec3,
    pub(super) hi: DVec3,
    pub(super) slack: f64,
    pub(super) shafts: &'a PairShafts,
    /// p's plane and q's, each with its normal turned to the side light
    /// crosses it on: a one-sided element's front, or the side the other
    /// element lies wholly on. A root wholly behind either cannot meet a
    /// segment that carries light between the two.
    pub(super) planes: [Option<(DVec3, DVec3)>; 2],
    pub(super) plane_slack: f64,
    /// Whether a root the box and planes keep is tested against the hull too.
    pub(super) hull: bool,
}

impl<'a> ShaftTest<'a> {
    pub(super) fn new(
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
            hull: true,
        }
    }

    /// Whether root `r` may block light between p and q: it is in the
    /// layer, coplanar with neither, behind neither's plane (a solid's own
    /// faces, for one), and the shaft does not exclude it.
    pub(super) fn may_block(&self, r: u32) -> bool {
        let root = &self.patches.elements[r as usize];
        // Cheapest first: most roots lie outside the pair's box.
        let (rlo, rhi) = root.bounds;
        if self.outside_box(rlo, rhi) {
            return false;
        }
        let in_layer = match self.layer {
            Layer::All => true,
            layer => self.patches.is_virtual_element(r) == (layer == Layer::Virtual),
        };
        if !in_layer || coplanar(root, self.p) || coplanar(root, self.q) {
            return false;
        }
        // A triangle's corners are read where they lie: copied into a
        // `Corners` first, the copy stalled on its own stores (13% of this
        // test's time on lounge's finer mesh, whose roots are triangles).
        match &root.shape {
            crate::patches::Shape::Tri(corners) => self.may_hold(corners),
            shape => self.may_hold(&shape.corners()),
        }
    }

    /// Whether the box [lo, hi] lies outside the pair's box (boxes that
    /// only touch cannot hold an occluder between p and q).
    fn outside_box(&self, lo: DVec3, hi: DVec3) -> bool {
        (lo - self.slack).cmpge(self.hi).any() || (hi + self.slack).cmple(self.lo).any()
    }

    /// Whether the convex hull of `corners` may meet a segment carrying
    /// light between p and q: behind neither's plane, and not excluded by
    /// the hull.
    fn may_hold(&self, corners: &[DVec3]) -> bool {
        let behind =
            |&(o, n): &(DVec3, DVec3)| corners.iter().all(|c| (*c - o).dot(n) <= self.plane_slack);
        if self.planes.iter().flatten().any(behind) {
            return false;
        }
        if !self.hull {
            return true;
        }
        let (p, q) = (self.p, self.q);
        let hull = (self.shafts.hull)
            .get_or_init(|| Shaft::between_polygons(&p.shape.corners(), &q.shape.corners()));
        !hull.excludes(corners)
    }
}

/// The root elements among `candidates` that may block light between `p`
/// and `q` (see `ShaftTest`). Empty means certainly visible. A child
/// pair's shaft lies inside its parents', so their occluders are a subset.
pub(crate) fn occluders_between(
    patches: &Patches,
    layer: Layer,
    p: &Element,
    q: &Element,
    candidates: &[u32],
) -> Vec<u32> {
    occluders_between_using(patches, layer, p, q, candidates, &PairShafts::default())
}

/// [`occluders_between`] with the pair's shafts kept in `shafts`.
pub(super) fn occluders_between_using(
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
pub(crate) fn may_be_occluded(
    patches: &Patches,
    layer: Layer,
    p: &Element,
    q: &Element,
    candidates: &[u32],
) -> bool {
    may_be_occluded_using(
        patches,
        layer,
        p,
        q,
        candidates,
        &PairShafts::default(),
        true,
    )
}

/// [`may_be_occluded`] with the pair's shafts kept in `shafts`.
pub(super) fn may_be_occluded_using(
    patches: &Patches,
    layer: Layer,
    p: &Element,
    q: &Element,
    candidates: &[u32],
    shafts: &PairShafts,
    hull: bool,
) -> bool {
    let test = ShaftTest {
        hull,
        ..ShaftTest::new(patches, layer, p, q, shafts)
    };
    candidates.iter().any(|&r| test.may_block(r))
}

/// The fraction of rays between points of `p` and points of `q` that no
/// geometry of `layer` blocks.
pub fn visibility(p: &Element, q: &Element, tracer: &Tracer, layer: Layer) -> f64 {
    let (rays, count) = visibility_rays(p, q);
    let rays = &rays[..count];
    let mut blocked = [false; MAX_VISIBILITY_RAYS];
    let blocked = &mut blocked[..count];
    tracer.occluded_batch(rays, layer, blocked);
    blocked.iter().filter(|b| !**b).count() as f64 / count as f64
}

/// The most rays [`visibility_rays`] gives: 2×2 points each way (a
/// triangle's order 2 is 4 points too).
const MAX_VISIBILITY_RAYS: usize = 16;

/// The rays [`visibility`] traces between `p` and `q`, and their count:
/// held on the stack, as millions of pairs are traced.
pub(super) fn visibility_rays(
    p: &Element,
    q: &Element,
) -> ([TraceRay; MAX_VISIBILITY_RAYS], usize) {
    let (r, m) = visibility_sampling(p, q);
    let mut targets = [DVec3::ZERO; 4];
    let mut t = 0;
    q.shape.for_each_quadrature_point(m, |x, _| {
        targets[t] = x;
        t += 1;
    });
    let mut rays = [segment(DVec3::ZERO, DVec3::X); MAX_VISIBILITY_RAYS];
    let mut count = 0;
    p.shape.for_each_quadrature_point(r, |x, _| {
        for &y in &targets[..t] {
            rays[count] = segment(offset_origin(x, p.normal, y), y);
            count += 1;
        }
    });
    (rays, count)
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
