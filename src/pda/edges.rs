//! Where real and virtual surfaces mix within a pixel: the candidate
//! pixels along the objects' outlines and their sub-pixel samples.

use super::*;

/// The sub-pixel samples of a pixel whose n×n sub-pixels mix real and
/// virtual surfaces, with their light terms appended to `terms`; `None`
/// where they do not mix. `real`: the pixel's own real point when its
/// centre sees it, whose light terms the real sub-pixels on its plane take
/// (no rays of their own; their terms here are left empty). Returns rays cast.
pub(super) fn edge_samples(
    input: &PdaInput,
    col: u32,
    row: u32,
    seed: u64,
    real: Option<&SurfacePoint>,
    terms: &mut Vec<LightTerm>,
) -> (Option<Vec<SurfacePoint>>, u64) {
    let n = input.settings.supersample;
    if n <= 1 {
        return (None, 0);
    }
    let (mixed, visible, mut rays) = sub_pixels_mix(input, col, row, n);
    if !mixed {
        return (None, rays);
    }
    let (subs, traced) = sub_points(input, col, row, n, &visible);
    rays += traced;
    let mut kept: Vec<SurfacePoint> = Vec::new();
    let lights = input.lights.len();
    // Each kept sub-pixel holds `lights` terms from here on.
    let base = terms.len();
    for (k, s) in subs.into_iter().enumerate() {
        // A sub-pixel that sees nothing counts as the photo's background.
        if let Some(mut p) = s {
            p.pixel_terms = !p.is_virtual
                && real.is_some_and(|r| {
                    r.surface == p.surface && r.normal.dot(p.normal) > SAME_PLANE_COS
                });
            // Sub-pixels on one plane share the light of the first of them:
            // within a pixel's footprint it differs by less than the shadow
            // rays' own noise, and each would cost a full set of rays.
            let first = kept.iter().position(|q| {
                !q.pixel_terms && q.surface == p.surface && q.normal.dot(p.normal) > SAME_PLANE_COS
            });
            match first {
                _ if p.pixel_terms => {
                    terms.extend(std::iter::repeat_n(LightTerm::default(), lights))
                }
                Some(j) => terms.extend_from_within(base + j * lights..base + (j + 1) * lights),
                None => rays += input.terms(&p, hash2(seed, 100 + k as u64), terms, None),
            }
            kept.push(p);
        }
    }
    (Some(kept), rays)
}

/// Whether some of a pixel's n×n sub-pixels see a virtual object and some
/// do not, or all see objects but on different planes. The sub-rays meet the objects alone first (a few triangles);
/// only those that hit one ask the room whether a real surface is nearer,
/// with an occlusion query that stops at the object. Most pixels near an
/// object's image are decided by the first step, or need only short rays.
/// Returns the answer, each sub-ray's object hit where no real surface
/// hides it (what [`sub_points`] takes as found), and the rays cast.
pub(super) fn sub_pixels_mix(
    input: &PdaInput,
    col: u32,
    row: u32,
    n: u32,
) -> (bool, Vec<Option<Hit>>, u64) {
    // A packet's worth at a time: the arrays stay small whatever n is.
    const PACKET: usize = 16;
    let count = (n * n) as usize;
    let cam = input.camera;
    let (mut seen, mut rays_cast) = (0, 0u64);
    let mut visible = vec![None; count];
    for start in (0..count).step_by(PACKET) {
        let len = PACKET.min(count - start);
        let mut rays = [TraceRay::new(glam::Vec3::ZERO, glam::Vec3::Z); PACKET];
        for (k, ray) in (start..start + len).zip(rays.iter_mut()) {
            *ray = sub_ray(cam, col, row, n, k as u32).0;
        }
        let mut hits = [None; PACKET];
        input
            .tracer
            .intersect_batch(&rays[..len], Layer::Virtual, &mut hits[..len]);
        rays_cast += len as u64;
        // Of the sub-rays meeting an object, those a real surface hides before it.
        let mut short = [TraceRay::new(glam::Vec3::ZERO, glam::Vec3::Z); PACKET];
        let mut at = [0usize; PACKET];
        let mut m = 0;
        for (k, (ray, hit)) in rays[..len].iter().zip(&hits[..len]).enumerate() {
            if let Some(h) = hit {
                short[m] = TraceRay { tfar: h.t, ..*ray };
                at[m] = k;
                m += 1;
            }
        }
        if m > 0 {
            let mut hidden = [false; PACKET];
            input
                .tracer
                .occluded_batch(&short[..m], Layer::Real, &mut hidden[..m]);
            rays_cast += m as u64;
            for (&k, hidden) in at[..m].iter().zip(&hidden[..m]) {
                if !hidden {
                    visible[start + k] = hits[k];
                    seen += 1;
                }
            }
        }
    }
    // A pixel wholly on the objects mixes where its sub-pixels see
    // different planes: a small curved object's facets, each lit its own
    // way, over a pixel's area as the camera averages them. Not where
    // every one is shaded per pixel by its material, whose samples spread
    // over the pixel each at its own point: as sub-pixels, a finely
    // tessellated object's pixels drew four times a whole pixel's samples
    // (nearly every pixel of an 80k-triangle prop or a 4k-triangle ball).
    let facets = match visible.first() {
        Some(Some(f)) if seen == count => {
            let planes = (visible.iter().flatten())
                .any(|h| h.surface != f.surface || h.normal.dot(f.normal) < SAME_PLANE_COS);
            planes && !(visible.iter().flatten()).all(|h| input.shades_per_pixel(h.surface))
        }
        _ => false,
    };
    (seen > 0 && seen < count || facets, visible, rays_cast)
}

/// Sub-ray k of a pixel's n×n (row by row), for the tracer and in double precision.
pub(super) fn sub_ray(
    cam: &Camera,
    col: u32,
    row: u32,
    n: u32,
    k: u32,
) -> (TraceRay, DVec3, DVec3) {
    let (i, j) = (k % n, k / n);
    let r = cam.ray(
        col as f64 + (i as f64 + 0.5) / n as f64,
        row as f64 + (j as f64 + 0.5) / n as f64,
    );
    (
        TraceRay::new(r.origin.as_vec3(), r.direction.as_vec3()),
        r.origin,
        r.direction,
    )
}

/// The pixels whose sub-pixels may mix real and virtual surfaces, as a
/// mask over the image, or `None` when every pixel near an object's image
/// must be tested. With no real surface between the camera and an object's
/// box, which of a pixel's sub-rays meet the object changes only across
/// the projected edges of the object's polygons: a pixel no edge comes
/// near sees the object through all its sub-pixels or through none. Real
/// geometry in front of the box (or cutting into it) draws boundaries of
/// its own, so then every pixel is tested, as is an object reaching behind
/// the camera.
pub(super) fn edge_candidates(input: &PdaInput) -> Option<Vec<bool>> {
    let cam = input.camera;
    let patches = input.patches;
    let is_virtual = |r: &u32| patches.is_virtual_element(*r);
    for (lo, hi) in input.bounds.objects.iter().map(|o| &o.aabb) {
        let mut ends = vec![cam.position];
        ends.extend(box_corners(*lo, *hi));
        let hull = Shaft::hull(&ends);
        let (hlo, hhi) = (lo.min(cam.position), hi.max(cam.position));
        let in_front = patches.roots.iter().filter(|r| !is_virtual(r)).any(|&r| {
            let shape = &patches.elements[r as usize].shape;
            let (rlo, rhi) = shape.bounds();
            !(rlo.cmpgt(hhi).any() || rhi.cmplt(hlo).any() || hull.excludes(&shape.corners()))
        });
        if in_front {
            return None;
        }
    }
    let (w, h) = (cam.width, cam.height);
    let mut marks = vec![false; (w * h) as usize];
    // Within this many pixels of an edge a sub-ray may fall either side
    // once the tracer's single precision has rounded it.
    const MARGIN: f64 = 0.01;
    let roots: Vec<&crate::patches::Element> = patches
        .roots
        .iter()
        .filter(|r| is_virtual(r))
        .map(|&r| &patches.elements[r as usize])
        .collect();
    let table = edge_table(Some(cam), &roots);
    for root in &roots {
        let corners = root.shape.corners();
        for k in 0..corners.len() {
            let (a, b) = (corners[k], corners[(k + 1) % corners.len()]);
            let path = cam.project_path(a, b)?;
            let held = &table[&edge_key(a, b)];
            // A crease between surfaces shaded per pixel mixes nothing
            // ([`sub_pixels_mix`]).
            let per_pixel =
                input.shades_per_pixel(held.first.0) && input.shades_per_pixel(held.last);
            if !held.interior() || (held.crease && !per_pixel) {
                for piece in path.windows(2) {
                    mark_segment(&mut marks, w, h, piece[0], piece[1], MARGIN);
                }
            }
        }
    }
    Some(marks)
}

/// An edge by its two ends' bits, in either order.
pub(super) type EdgeKey = [[u64; 3]; 2];

pub(super) fn edge_key(a: DVec3, b: DVec3) -> EdgeKey {
    let bits = |v: DVec3| v.to_array().map(f64::to_bits);
    let (a, b) = (bits(a), bits(b));
    if a <= b { [a, b] } else { [b, a] }
}

/// What one pass over the objects' polygons learns of each edge: how many
/// polygons hold it (whole: the same ends, bit for bit), which sides of
/// it in the image they lie on, and whether it is a crease.
#[derive(Debug, Clone, Copy)]
pub(super) struct EdgeHeld {
    count: u32,
    left: bool,
    right: bool,
    /// Held by polygons of two surfaces or on different planes: a pixel
    /// across it sees two facets whose light differs, and its sub-pixels
    /// are shaded apart ([`sub_pixels_mix`]).
    pub(super) crease: bool,
    /// The first polygon's surface and normal, which the others' are
    /// compared with.
    first: (u32, DVec3),
    /// The last polygon's surface: with the first, both of an interior edge's.
    last: u32,
}

impl EdgeHeld {
    /// Whether the edge is no silhouette: whole (the same ends, bit for
    /// bit) in exactly two polygons that lie on either side of it in the
    /// image. A convex polygon lies wholly on one side of each of its
    /// edges, so a sub-pixel on either side of such an edge sees one of
    /// the two (or something nearer), and no pixel along it mixes objects
    /// and room but where it meets an outline edge, which marks those.
    /// Decided in the image, not by the polygons' normals: a fold of an
    /// open surface can hide one side behind the other whichever way its
    /// normals turn. A polygon seen edge-on, or behind the camera, is on
    /// neither side; edges matched only in part count as outline.
    pub(super) fn interior(&self) -> bool {
        self.count == 2 && self.left && self.right
    }
}

/// Every edge of the objects' polygons `roots` and what holds it, seen
/// from `cam` (without one, no polygon is on either side). One table for
/// both questions an edge is asked, each edge's polygons summed as they
/// come: an 80k-triangle object held a list of its polygons per edge, and
/// three such objects' lists were the peak of a render's memory.
pub(super) fn edge_table(
    cam: Option<&Camera>,
    roots: &[&crate::patches::Element],
) -> HashMap<EdgeKey, EdgeHeld> {
    // A closed mesh's polygons share each edge by two.
    let mut table: HashMap<EdgeKey, EdgeHeld> = HashMap::with_capacity(roots.len() * 3 / 2);
    let flat = |p: Option<(f64, f64, f64)>| p.map(|(x, y, _)| glam::DVec2::new(x, y));
    let project = |p: DVec3| cam.and_then(|cam| flat(cam.project(p)));
    for e in roots {
        let centre = project(e.centre);
        let normal = e.shape.normal();
        let corners = e.shape.corners();
        for k in 0..corners.len() {
            let key = edge_key(corners[k], corners[(k + 1) % corners.len()]);
            let [a, b] = key.map(|v| project(DVec3::from_array(v.map(f64::from_bits))));
            let side = match (a, b, centre) {
                (Some(a), Some(b), Some(c)) => {
                    let cross = (b - a).perp_dot(c - a);
                    // Within rounding of the line: edge-on.
                    let size = (b - a).length() * (c - a).length();
                    if cross.abs() <= 1e-9 * size {
                        0
                    } else {
                        cross.signum() as i32
                    }
                }
                _ => 0,
            };
            let held = table.entry(key).or_insert(EdgeHeld {
                count: 0,
                left: false,
                right: false,
                crease: false,
                first: (e.surface, normal),
                last: e.surface,
            });
            held.count += 1;
            held.last = e.surface;
            held.left |= side < 0;
            held.right |= side > 0;
            let (surface, first) = held.first;
            held.crease |=
                e.surface != surface || normal.dot(first).abs() < f64::from(SAME_PLANE_COS);
        }
    }
    table
}

/// The objects' polygon edges that are no silhouette for `cam`
/// ([`EdgeHeld::interior`]).
#[cfg(test)]
pub(super) fn interior_edges(
    cam: &Camera,
    roots: &[&crate::patches::Element],
) -> std::collections::HashSet<EdgeKey> {
    (edge_table(Some(cam), roots).into_iter())
        .filter(|(_, held)| held.interior())
        .map(|(edge, _)| edge)
        .collect()
}

/// The objects' polygon edges that are creases ([`EdgeHeld::crease`]).
#[cfg(test)]
pub(super) fn crease_edges(
    roots: &[&crate::patches::Element],
) -> std::collections::HashSet<EdgeKey> {
    (edge_table(None, roots).into_iter())
        .filter(|(_, held)| held.crease)
        .map(|(edge, _)| edge)
        .collect()
}

/// Marks every pixel whose square comes within `margin` of segment a–b.
pub(super) fn mark_segment(
    marks: &mut [bool],
    w: u32,
    h: u32,
    a: (f64, f64),
    b: (f64, f64),
    margin: f64,
) {
    let (y_lo, y_hi) = (a.1.min(b.1) - margin, a.1.max(b.1) + margin);
    let first = y_lo.floor().max(0.0);
    let last = y_hi.floor().min(h as f64 - 1.0);
    if first > last {
        return;
    }
    let at = |t: f64| (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
    for row in first as u32..=last as u32 {
        // The part of the segment within the row's band, margin included.
        let (band_lo, band_hi) = (row as f64 - margin, row as f64 + 1.0 + margin);
        let (t0, t1) = if b.1 == a.1 {
            (0.0, 1.0)
        } else {
            let (ta, tb) = ((band_lo - a.1) / (b.1 - a.1), (band_hi - a.1) / (b.1 - a.1));
            (ta.min(tb).max(0.0), ta.max(tb).min(1.0))
        };
        if t0 > t1 {
            continue;
        }
        let (x0, x1) = (at(t0).0, at(t1).0);
        let (x_lo, x_hi) = (x0.min(x1) - margin, x0.max(x1) + margin);
        if x_hi < 0.0 || x_lo > w as f64 - 1e-9 {
            continue;
        }
        let c0 = x_lo.floor().max(0.0) as u32;
        let c1 = (x_hi.floor().max(0.0) as u32).min(w - 1);
        for col in c0..=c1 {
            marks[(row * w + col) as usize] = true;
        }
    }
}

/// The n×n sub-pixel surface points of a pixel (None where a ray leaves
/// the scene), given the object each sub-ray sees ([`sub_pixels_mix`]):
/// only the others are traced, through the room. Returns the points and
/// the rays cast.
pub(super) fn sub_points(
    input: &PdaInput,
    col: u32,
    row: u32,
    n: u32,
    visible: &[Option<Hit>],
) -> (Vec<Option<SurfacePoint>>, u64) {
    let cam = input.camera;
    let rays: Vec<(TraceRay, DVec3, DVec3)> =
        (0..n * n).map(|k| sub_ray(cam, col, row, n, k)).collect();
    let rest: Vec<usize> = (0..rays.len()).filter(|&k| visible[k].is_none()).collect();
    let traced: Vec<TraceRay> = rest.iter().map(|&k| rays[k].0).collect();
    let mut hits = visible.to_vec();
    let mut real = vec![None; traced.len()];
    input
        .tracer
        .intersect_batch(&traced, Layer::Real, &mut real);
    for (&k, h) in rest.iter().zip(real) {
        hits[k] = h;
    }
    let points = hits
        .iter()
        .zip(&rays)
        .map(|(h, r)| h.as_ref().and_then(|h| input.point(h, r.1, r.2)))
        .collect();
    (points, traced.len() as u64)
}

/// A pixel rectangle, inclusive.
#[derive(Debug, Clone, Copy)]
pub(super) struct PixelBox {
    pub(super) x0: u32,
    pub(super) y0: u32,
    pub(super) x1: u32,
    pub(super) y1: u32,
}

impl PixelBox {
    pub(super) fn contains(&self, x: u32, y: u32) -> bool {
        x >= self.x0 && x <= self.x1 && y >= self.y0 && y <= self.y1
    }
}

/// The image boxes of the virtual objects' bounds, one pixel wider; a box
/// reaching behind the camera covers the whole image.
pub(super) fn screen_boxes(cam: &Camera, bounds: &VirtualBounds) -> Vec<PixelBox> {
    bounds
        .objects
        .iter()
        .map(|o| {
            let (lo, hi) = &o.aabb;
            let projected = cam.project_hull(&box_corners(*lo, *hi));
            let full = PixelBox {
                x0: 0,
                y0: 0,
                x1: cam.width - 1,
                y1: cam.height - 1,
            };
            let Some(pts) = projected else { return full };
            let (mut x0, mut y0, mut x1, mut y1) = (
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            );
            for (x, y) in pts {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x);
                y1 = y1.max(y);
            }
            let clamp = |v: f64, max: u32| (v.floor().max(0.0) as u32).min(max);
            PixelBox {
                x0: clamp(x0 - 1.0, cam.width - 1),
                y0: clamp(y0 - 1.0, cam.height - 1),
                x1: clamp(x1 + 1.0, cam.width - 1),
                y1: clamp(y1 + 1.0, cam.height - 1),
            }
        })
        .collect()
}
