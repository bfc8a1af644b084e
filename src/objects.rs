//! The virtual objects' bounds as the visibility tests need them: where a
//! shadow ray or a radiosity link may meet an object, and which rays need
//! not trace an object's own solid or the room.

use glam::{DVec3, Vec3};

use crate::light::LightSource;
use crate::shaft::{ObjectBounds, Shaft};
use crate::trace::Hit;

/// What moved since a session kept what its rays met: an update's objects
/// where they were and where they are (`radiosity::StillSurfaces`).
pub trait Movers: Sync {
    /// Whether no moved object comes near any segment from a point within
    /// `slack` of `a` to a point within `radius` of `c`.
    fn clear_towards(&self, a: DVec3, c: DVec3, radius: f64, slack: f64) -> bool;
    /// Whether virtual surface `surface` stood still, its patches numbered
    /// as before.
    fn unmoved(&self, surface: u32) -> bool;
    /// Whether any virtual surface stood still (else nothing can be kept).
    fn any_unmoved(&self) -> bool;
}

/// What the oracle needs about the virtual objects: each surface's bounds
/// ([`ObjectBounds`]: its world box and its box turned about the vertical)
/// and id, and, for a solid, per triangle whether the solid lies wholly
/// behind the triangle's plane (a box's faces; any face on a convex hull).
/// Light reaching a point of such a face from in front of it crosses
/// nothing of its own solid, and light from behind it is inside the solid:
/// the point need not trace its own solid (on the desk's box, a fifth of
/// an update's rays).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VirtualBounds {
    pub objects: Vec<ObjectBounds>,
    surfaces: Vec<u32>,
    /// Per surface, per triangle: the unit normal of the side of its plane
    /// clear of the solid, or zero (not a solid, or the solid is on both sides).
    clear_side: Vec<Vec<Vec3>>,
    /// Per surface, the mean of its corners when every face is clear of
    /// the solid (a convex solid, which holds that point inside).
    convex_centre: Vec<Option<DVec3>>,
    /// Per surface, per light: whether no real surface can block light
    /// between them ([`VirtualBounds::with_room`]; empty until asked).
    pub(crate) room_clear: Vec<Vec<bool>>,
}

/// Triangles × corners above which a solid's faces are not tested for
/// being clear of it (each update tests them: the quadratic cost would
/// exceed the rays it saves); its points trace it as any other object.
pub(crate) const CLEAR_TEST_LIMIT: usize = 1 << 22;

impl VirtualBounds {
    pub fn of(triangles: &[(u32, Vec<crate::geometry::Triangle>)]) -> VirtualBounds {
        let mut out = VirtualBounds::default();
        for (surface, t) in triangles.iter().filter(|(_, t)| !t.is_empty()) {
            let points: Vec<DVec3> = t.iter().flatten().map(|p| p.as_dvec3()).collect();
            let object = ObjectBounds::around(&points);
            let sides = clear_sides(t, (object.aabb.1 - object.aabb.0).length());
            let convex = sides.iter().all(|c| *c != Vec3::ZERO);
            out.convex_centre
                .push(convex.then(|| points.iter().sum::<DVec3>() / points.len() as f64));
            out.clear_side.push(sides);
            out.objects.push(object);
            out.surfaces.push(*surface);
        }
        out
    }

    /// These bounds knowing, per object and light, whether no real surface
    /// (`room`: the polygons of the real roots) can block light travelling
    /// between them; then the object's points trace no ray through the
    /// room (the desk's box, at most poses: every one of its pixels is
    /// lit through the room). A polygon cannot when the object and the
    /// light lie on one side of its plane (the floor the object stands on,
    /// which a ray may touch only where it starts), or when the convex hull
    /// of the two excludes it, the object's box grown by twice the most a
    /// ray's origin is lifted off its surface ([`crate::light::origin_lift`]):
    /// rays start inside it. (A ray from a point within the lift of the
    /// floor, on a face tilted down, may start under it and, traced, meet
    /// it; this takes such a point as lit.)
    pub fn with_room(mut self, room: &[Vec<DVec3>], lights: &[LightSource]) -> VirtualBounds {
        self.room_clear = self
            .objects
            .iter()
            .map(|o| {
                let corners = o.upright.corners();
                let pad = 2.0
                    * crate::light::origin_lift(DVec3::splat(
                        corners
                            .iter()
                            .map(|c| c.abs().max_element())
                            .fold(0.0, f64::max),
                    ));
                let grown = o.upright.padded(pad).corners();
                lights
                    .iter()
                    .map(|light| clear_of_room(&corners, &grown, light, room))
                    .collect()
            })
            .collect();
        self
    }

    /// Whether light `l` (`light`) reaches point `x` of `surface`, whose
    /// unit normal `n` faces out of its solid, blocked by nothing but that
    /// solid, so that which of its rays are blocked is known without
    /// tracing ([`own_blocks`]): the solid is convex (every face clear of
    /// it; then n faces out where the solid's centre lies behind x), the
    /// room cannot block it ([`VirtualBounds::with_room`]), and no other
    /// object's box meets the box around it and the light.
    pub fn only_own_blocks(
        &self,
        surface: u32,
        x: DVec3,
        n: DVec3,
        l: usize,
        light: &LightSource,
    ) -> bool {
        let Some(k) = self.surfaces.iter().position(|&s| s == surface) else {
            return false;
        };
        let Some(centre) = self.convex_centre[k] else {
            return false;
        };
        let (llo, lhi) = light.bounds();
        let (lo, hi) = (
            self.objects[k].aabb.0.min(llo),
            self.objects[k].aabb.1.max(lhi),
        );
        let apart = |(j, o): (usize, &ObjectBounds)| {
            j == k || o.aabb.0.cmpgt(hi).any() || o.aabb.1.cmplt(lo).any()
        };
        (x - centre).dot(n) > 0.0
            && self.room_clear_of(k, l)
            && self.objects.iter().enumerate().all(apart)
    }

    /// Whether the room cannot block light between a point of `surface` (on
    /// an object when `is_virtual`) and light `l`.
    pub(crate) fn room_clear(&self, is_virtual: bool, surface: u32, l: usize) -> bool {
        is_virtual
            && self
                .surfaces
                .iter()
                .position(|&s| s == surface)
                .is_some_and(|k| self.room_clear_of(k, l))
    }

    /// Whether the room cannot block light between object `k` and light `l`
    /// (no when not asked: [`VirtualBounds::with_room`]).
    pub(crate) fn room_clear_of(&self, k: usize, l: usize) -> bool {
        self.room_clear
            .get(k)
            .and_then(|c| c.get(l))
            .copied()
            .unwrap_or(false)
    }

    /// The index of the solid a point of `surface` lies on, when its face
    /// is clear of it (`clear_of_own`).
    pub(crate) fn own_clear(&self, clear_of_own: bool, surface: u32) -> Option<usize> {
        clear_of_own
            .then(|| self.surfaces.iter().position(|&s| s == surface))
            .flatten()
    }

    /// Whether `hit`'s point, facing `hit.normal`, lies on a face clear of its own solid.
    pub(crate) fn is_clear_of_own(&self, hit: &Hit) -> bool {
        let Some(k) = self.surfaces.iter().position(|&s| s == hit.surface) else {
            return false;
        };
        self.clear_side[k]
            .get(hit.triangle as usize)
            .is_some_and(|n| n.dot(hit.normal) > 0.0)
    }

    /// Each virtual surface's id and bounds.
    pub fn surface_bounds(&self) -> impl Iterator<Item = (u32, &ObjectBounds)> {
        self.surfaces.iter().copied().zip(&self.objects)
    }

    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }

    /// Whether light travelling from `x` to the light's emitter may pass a
    /// virtual object, other than the surface of box `own` (clear of x).
    pub(crate) fn may_shadow(&self, x: DVec3, light: &LightSource, own: Option<usize>) -> bool {
        let others = || {
            self.objects
                .iter()
                .enumerate()
                .filter(move |(k, _)| Some(*k) != own)
                .map(|(_, o)| o)
        };
        match light.rect_corners() {
            None => others().any(|o| o.meets_segment(x, light.position)),
            Some(quad) => {
                // A box apart from the one around x and the light meets no
                // ray between them: no pyramid needed (most points, most boxes).
                let (slo, shi) = quad
                    .iter()
                    .fold((x, x), |(lo, hi), c| (lo.min(*c), hi.max(*c)));
                let near =
                    |o: &&ObjectBounds| !(o.aabb.0.cmpgt(shi).any() || o.aabb.1.cmplt(slo).any());
                if !others().any(|o| near(&o)) {
                    return false;
                }
                let shaft = Shaft::pyramid(x, &quad);
                others().filter(near).any(|o| !o.outside(&shaft))
            }
        }
    }
}

/// Whether the solid that a point x (normal n, facing out) lies on blocks
/// its ray to point y of a light centred at `centre`, for a face clear of
/// the solid: where y lies behind the face — and everywhere when the
/// centre does, as the rays then leave from the solid's side of the face
/// ([`crate::light::offset_origin`]).
pub fn own_blocks(x: DVec3, n: DVec3, centre: DVec3, y: DVec3) -> bool {
    (centre - x).dot(n) < 0.0 || (y - x).dot(n) < 0.0
}

/// Whether no polygon of `room` can block a segment from a point of the
/// box with corners `object` (`grown`: grown by the rays' lift) to a point
/// of the light (see [`VirtualBounds::with_room`]).
pub(crate) fn clear_of_room(
    object: &[DVec3; 8],
    grown: &[DVec3; 8],
    light: &LightSource,
    room: &[Vec<DVec3>],
) -> bool {
    let emitter = match light.rect_corners() {
        Some(quad) => quad.to_vec(),
        None => vec![light.position],
    };
    let ends: Vec<DVec3> = object.iter().chain(&emitter).copied().collect();
    let (lo, hi) = crate::geometry::bounds(grown.iter().chain(&emitter).copied());
    let slack = 1e-9 * lo.abs().max(hi.abs()).max_element().max(1.0);
    let mut hull: Option<Shaft> = None;
    room.iter().all(|polygon| {
        let (plo, phi) = crate::geometry::bounds(polygon.iter().copied());
        if plo.cmpgt(hi).any() || phi.cmplt(lo).any() {
            return true;
        }
        // Newell's normal: any polygon the mesh keeps as a root.
        let n = polygon
            .iter()
            .zip(polygon.iter().cycle().skip(1))
            .fold(DVec3::ZERO, |n, (a, b)| n + a.cross(*b));
        if n != DVec3::ZERO {
            let d = |e: &DVec3| (*e - polygon[0]).dot(n) / n.length();
            if ends.iter().all(|e| d(e) >= -slack) || ends.iter().all(|e| d(e) <= slack) {
                return true;
            }
        }
        hull.get_or_insert_with(|| {
            Shaft::hull(&grown.iter().chain(&emitter).copied().collect::<Vec<_>>())
        })
        .excludes(polygon)
    })
}

/// Per triangle of one surface, when it is a solid (closed), the unit
/// normal of the side of the triangle's plane that holds none of the
/// solid's corners (within `size` × 1e-5: the corners are single
/// precision), or zero.
pub(crate) fn clear_sides(triangles: &[crate::geometry::Triangle], size: f64) -> Vec<Vec3> {
    if triangles.len() * 3 * triangles.len() > CLEAR_TEST_LIMIT
        || !crate::geometry::is_closed(triangles)
    {
        return vec![Vec3::ZERO; triangles.len()];
    }
    let tolerance = 1e-5 * size;
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|p| p.as_dvec3());
            let n = (b - a).cross(c - a).normalize_or_zero();
            let (mut front, mut back) = (false, false);
            for p in triangles.iter().flatten() {
                let d = (p.as_dvec3() - a).dot(n);
                front |= d > tolerance;
                back |= d < -tolerance;
            }
            match (front, back) {
                _ if n == DVec3::ZERO => Vec3::ZERO,
                (false, true) => n.as_vec3(),
                (true, false) => -n.as_vec3(),
                _ => Vec3::ZERO,
            }
        })
        .collect()
}
