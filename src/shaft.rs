//! [`Shaft`]: the convex hull of two point sets (Haines & Wallace shaft
//! culling), as a set of planes. A conservative test says when a convex
//! occluder certainly lies outside it: then nothing it contains can block
//! light between the two ends.

use glam::DVec3;

use crate::geometry::{UprightBox, bounds, segment_meets_box};

/// A convex volume given by outward planes n·x ≤ d.
#[derive(Debug, Clone, PartialEq)]
pub struct Shaft {
    planes: Vec<(DVec3, f64)>,
    tolerance: f64,
}

impl Shaft {
    /// The convex hull of the given points (at most a few dozen: every
    /// plane through three of them that has all on one side is a face).
    pub(crate) fn hull(points: &[DVec3]) -> Shaft {
        // Repeated points add no face (a pixel's box is one point eight times).
        let mut unique: Vec<DVec3> = Vec::with_capacity(points.len());
        for p in points {
            if !unique.iter().any(|q| q == p) {
                unique.push(*p);
            }
        }
        let points = &unique[..];
        let scale = points
            .iter()
            .map(|p| p.abs().max_element())
            .fold(1.0, f64::max);
        let extent = points
            .iter()
            .map(|p| (*p - points[0]).length())
            .fold(0.0, f64::max)
            .max(1e-12);
        let tolerance = 1e-9 * scale.max(extent);
        let mut planes: Vec<(DVec3, f64)> = Vec::new();
        let n = points.len();
        for i in 0..n {
            for j in i + 1..n {
                for k in j + 1..n {
                    add_face(
                        &mut planes,
                        points,
                        [points[i], points[j], points[k]],
                        extent,
                        tolerance,
                    );
                }
            }
        }
        Shaft { planes, tolerance }
    }

    /// The convex hull of two planar convex polygons (an element pair's
    /// shaft), the same as [`Shaft::hull`] of their corners but searched
    /// among fewer planes: a face of the hull meets each polygon in a
    /// face of it, so it is a polygon's own plane or holds an edge of one
    /// and a corner of the other.
    pub(crate) fn between_polygons(p: &[DVec3], q: &[DVec3]) -> Shaft {
        // Element corners (at most four each) on the stack: the links'
        // refinement builds millions of these shafts (6.3 million on
        // lounge's finer mesh), and a heap list each was a tenth of them.
        let mut buf = [DVec3::ZERO; 8];
        let on_heap: Vec<DVec3>;
        let points: &[DVec3] = if p.len() + q.len() <= buf.len() {
            buf[..p.len()].copy_from_slice(p);
            buf[p.len()..p.len() + q.len()].copy_from_slice(q);
            &buf[..p.len() + q.len()]
        } else {
            on_heap = p.iter().chain(q).copied().collect();
            &on_heap
        };
        let scale = points
            .iter()
            .map(|x| x.abs().max_element())
            .fold(1.0, f64::max);
        let extent = points
            .iter()
            .map(|x| (*x - points[0]).length())
            .fold(0.0, f64::max)
            .max(1e-12);
        let tolerance = 1e-9 * scale.max(extent);
        let mut planes: Vec<(DVec3, f64)> = Vec::with_capacity(16);
        for poly in [p, q] {
            if poly.len() >= 3 {
                add_face(
                    &mut planes,
                    points,
                    [poly[0], poly[1], poly[2]],
                    extent,
                    tolerance,
                );
            }
        }
        for (a, b) in [(p, q), (q, p)] {
            for i in 0..a.len() {
                let (e0, e1) = (a[i], a[(i + 1) % a.len()]);
                for &v in b {
                    add_face(&mut planes, points, [e0, e1, v], extent, tolerance);
                }
            }
        }
        // Coplanar polygons have a flat hull: the general search handles it.
        if planes.len() < 4 {
            return Shaft::hull(points);
        }
        Shaft { planes, tolerance }
    }

    /// The pyramid from `apex` to a planar convex polygon `base` (a pixel's
    /// shaft to a rect light): its faces written down instead of searched
    /// for. Falls back to [`Shaft::hull`] when the apex lies in the base's plane.
    pub(crate) fn pyramid(apex: DVec3, base: &[DVec3]) -> Shaft {
        let n = base.len();
        let normal = (base[1] - base[0]).cross(base[2] - base[0]);
        let extent = base
            .iter()
            .map(|p| (*p - apex).length())
            .fold(0.0, f64::max)
            .max(1e-12);
        let height = (apex - base[0]).dot(normal) / normal.length().max(1e-300);
        if normal.length() < 1e-12 * extent * extent || height.abs() < 1e-9 * extent {
            let mut all = base.to_vec();
            all.push(apex);
            return Shaft::hull(&all);
        }
        let scale = base
            .iter()
            .chain(std::iter::once(&apex))
            .map(|p| p.abs().max_element())
            .fold(1.0, f64::max);
        let tolerance = 1e-9 * scale.max(extent);
        let centre = (base.iter().copied().sum::<DVec3>() + apex) / (n + 1) as f64;
        let outward = |m: DVec3, on: DVec3| -> (DVec3, f64) {
            let m = m.normalize();
            let m = if m.dot(centre - on) > 0.0 { -m } else { m };
            (m, m.dot(on))
        };
        let mut planes = Vec::with_capacity(n + 1);
        planes.push(outward(normal, base[0]));
        for i in 0..n {
            let (a, b) = (base[i], base[(i + 1) % n]);
            planes.push(outward((a - apex).cross(b - apex), apex));
        }
        Shaft { planes, tolerance }
    }

    /// Haines & Wallace's shaft between two boxes: the box around both,
    /// cut by a plane through each pair of parallel edges where one box
    /// bounds the union on one face and the other box on an adjacent face.
    /// It holds the convex hull of the two boxes; built in constant time.
    pub(crate) fn between_boxes(a: (DVec3, DVec3), b: (DVec3, DVec3)) -> Shaft {
        let (lo, hi) = (a.0.min(b.0), a.1.max(b.1));
        let mid = 0.25 * (a.0 + a.1 + b.0 + b.1);
        let scale = lo.abs().max(hi.abs()).max_element().max(1.0);
        let tolerance = 1e-9 * scale;
        let mut planes: Vec<(DVec3, f64)> = Vec::with_capacity(14);
        for k in 0..3 {
            let mut n = DVec3::ZERO;
            n[k] = 1.0;
            planes.push((n, hi[k]));
            planes.push((-n, -lo[k]));
        }
        // side 0: the min face, side 1: the max face of an axis.
        let extent = |bx: (DVec3, DVec3), axis: usize, side: usize| {
            if side == 0 { bx.0[axis] } else { bx.1[axis] }
        };
        let owner = |axis: usize, side: usize| -> bool {
            // true: box a reaches that face of the union (ties go to a).
            if side == 0 {
                a.0[axis] <= b.0[axis]
            } else {
                a.1[axis] >= b.1[axis]
            }
        };
        for i in 0..3 {
            for j in i + 1..3 {
                for si in 0..2 {
                    for sj in 0..2 {
                        if owner(i, si) == owner(j, sj) {
                            continue;
                        }
                        // The edge of each box at (face i side si, face j side sj), as a
                        // point in the (i, j) plane; the plane holds both edges.
                        let (pa, pb) = (
                            (extent(a, i, si), extent(a, j, sj)),
                            (extent(b, i, si), extent(b, j, sj)),
                        );
                        let (di, dj) = (pb.0 - pa.0, pb.1 - pa.1);
                        let mut n = DVec3::ZERO;
                        n[i] = dj;
                        n[j] = -di;
                        let len = n.length();
                        if len < 1e-300 {
                            continue;
                        }
                        let n = n / len;
                        let mut on = DVec3::ZERO;
                        on[i] = pa.0;
                        on[j] = pa.1;
                        // Outward: the midpoint of the boxes' centres lies in
                        // their hull, so it must stay inside; a plane through
                        // it cannot be oriented safely and is left out.
                        let side = n.dot(mid - on);
                        if side.abs() <= tolerance {
                            continue;
                        }
                        let n = if side > 0.0 { -n } else { n };
                        planes.push((n, n.dot(on)));
                    }
                }
            }
        }
        Shaft { planes, tolerance }
    }

    /// Whether the convex hull of `points` certainly lies outside the shaft
    /// (or only touches its boundary): all of them on or beyond one plane.
    /// May answer false for a hull that misses the shaft (conservative).
    pub(crate) fn excludes(&self, points: &[DVec3]) -> bool {
        self.planes
            .iter()
            .any(|(n, d)| points.iter().all(|p| n.dot(*p) - d >= -self.tolerance))
    }

    pub(crate) fn plane_count(&self) -> usize {
        self.planes.len()
    }
}

/// Where a virtual object may be: its world-aligned box and its box
/// turned about the vertical ([`UprightBox`], the tighter for a turned
/// object). Both hold it: a segment misses it when it misses either (the
/// world box first, the cheaper test); shafts test the turned box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectBounds {
    pub aabb: (DVec3, DVec3),
    pub upright: UprightBox,
    /// The turned box's corners.
    corners: [DVec3; 8],
}

impl ObjectBounds {
    pub fn around(points: &[DVec3]) -> ObjectBounds {
        let upright = UprightBox::around(points);
        ObjectBounds {
            aabb: bounds(points.iter().copied()),
            upright,
            corners: upright.corners(),
        }
    }

    /// Whether the segment a→b may meet the object.
    pub(crate) fn meets_segment(&self, a: DVec3, b: DVec3) -> bool {
        segment_meets_box(a, b, self.aabb.0, self.aabb.1) && self.upright.meets_segment(a, b)
    }

    /// Whether the object certainly lies outside `shaft`.
    pub fn outside(&self, shaft: &Shaft) -> bool {
        shaft.excludes(&self.corners)
    }
}

/// Adds the plane through `abc` to `planes` (outward, once) when every
/// point lies on one side of it, within `tolerance`: a face of their hull.
fn add_face(
    planes: &mut Vec<(DVec3, f64)>,
    points: &[DVec3],
    [a, b, c]: [DVec3; 3],
    extent: f64,
    tolerance: f64,
) {
    let normal = (b - a).cross(c - a);
    let len = normal.length();
    if len < 1e-12 * extent * extent {
        return;
    }
    // Most candidates are not faces: they are rejected on the normal as
    // it comes, the tolerance scaled to its length, and only a face's is
    // normalised.
    let scaled = tolerance * len;
    let (mut above, mut below) = (false, false);
    for p in points {
        let s = normal.dot(*p - a);
        above |= s > scaled;
        below |= s < -scaled;
        // Points on both sides: not a face, whatever the rest say.
        if above && below {
            return;
        }
    }
    let normal = normal / len;
    let d = normal.dot(a);
    let plane = if above { (-normal, -d) } else { (normal, d) };
    if !planes
        .iter()
        .any(|(m, e)| (*m - plane.0).length_squared() < 1e-18 && (e - plane.1).abs() <= tolerance)
    {
        planes.push(plane);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(y: f64) -> Vec<DVec3> {
        vec![
            DVec3::new(0.0, y, 0.0),
            DVec3::new(1.0, y, 0.0),
            DVec3::new(1.0, y, 1.0),
            DVec3::new(0.0, y, 1.0),
        ]
    }

    #[test]
    fn a_shaft_between_parallel_squares_is_their_box() {
        let mut pts = square(0.0);
        pts.extend(square(2.0));
        let s = Shaft::hull(&pts);
        assert_eq!(s.plane_count(), 6);
        let blocker = vec![
            DVec3::new(0.4, 1.0, 0.4),
            DVec3::new(0.6, 1.0, 0.4),
            DVec3::new(0.5, 1.0, 0.6),
        ];
        assert!(!s.excludes(&blocker));
        let aside: Vec<DVec3> = blocker
            .iter()
            .map(|p| *p + DVec3::new(2.0, 0.0, 0.0))
            .collect();
        assert!(s.excludes(&aside));
        // A wall in the plane x = 1 only touches the shaft: it cannot block.
        let wall = vec![
            DVec3::new(1.0, -1.0, -1.0),
            DVec3::new(1.0, 3.0, -1.0),
            DVec3::new(1.0, 3.0, 3.0),
        ];
        assert!(s.excludes(&wall));
    }

    #[test]
    fn a_box_shaft_cuts_away_the_corners_of_the_box_around_both() {
        let a = (DVec3::new(0.0, 0.0, 0.0), DVec3::new(1.0, 0.1, 1.0));
        let b = (DVec3::new(2.0, 3.0, 0.2), DVec3::new(2.5, 3.05, 0.7));
        let shaft = Shaft::between_boxes(a, b);
        // The union box's corner far from both boxes lies outside the hull.
        assert!(shaft.excludes(&[DVec3::new(0.05, 2.9, 0.5)]));
        assert!(shaft.excludes(&[DVec3::new(2.45, 0.2, 0.5)]));
        // The segment between the boxes' centres lies inside.
        for t in [0.0, 0.3, 0.7, 1.0] {
            let p = DVec3::new(0.5, 0.05, 0.5).lerp(DVec3::new(2.25, 3.025, 0.45), t);
            assert!(!shaft.excludes(&[p]), "{p}");
        }
    }

    #[test]
    fn a_pyramid_agrees_with_the_general_hull() {
        let base = square(2.0);
        let apex = DVec3::new(0.3, 0.0, 0.6);
        let (p, mut all) = (Shaft::pyramid(apex, &base), base.clone());
        all.push(apex);
        let h = Shaft::hull(&all);
        assert_eq!(p.plane_count(), 5);
        let mut state = 3u64;
        for _ in 0..2000 {
            let c = DVec3::new(
                crate::util::rng::unit_random(&mut state) * 3.0 - 1.0,
                crate::util::rng::unit_random(&mut state) * 3.0 - 0.5,
                crate::util::rng::unit_random(&mut state) * 3.0 - 1.0,
            );
            let tri = [
                c,
                c + DVec3::new(0.1, 0.0, 0.0),
                c + DVec3::new(0.0, 0.1, 0.05),
            ];
            assert_eq!(p.excludes(&tri), h.excludes(&tri), "{c}");
        }
    }

    #[test]
    fn a_shaft_between_perpendicular_squares_is_a_prism() {
        let floor = square(0.0);
        let wall = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ];
        let mut pts = floor.clone();
        pts.extend(wall);
        let s = Shaft::hull(&pts);
        // The hull is the triangular prism under the diagonal plane y + z = 1.
        assert!(!s.excludes(&[DVec3::new(0.5, 0.2, 0.2)]));
        assert!(s.excludes(&[DVec3::new(0.5, 0.8, 0.8)]));
    }
}

#[cfg(test)]
mod random_tests {
    use super::*;

    /// The polygon-pair hull excludes exactly what the general hull does.
    #[test]
    fn polygon_shafts_equal_the_general_hull() {
        let mut state = 7u64;
        let mut r = || crate::util::rng::unit_random(&mut state);
        let polygon = |r: &mut dyn FnMut() -> f64| -> Vec<DVec3> {
            let origin = DVec3::new(r() * 4.0 - 2.0, r() * 3.0, r() * 4.0 - 2.0);
            let u = DVec3::new(r() - 0.5, r() - 0.5, r() - 0.5);
            let v = DVec3::new(r() - 0.5, r() - 0.5, r() - 0.5);
            if r() < 0.5 {
                vec![origin, origin + u, origin + u + v, origin + v]
            } else {
                vec![origin, origin + u, origin + v]
            }
        };
        for case in 0..2000 {
            let p = polygon(&mut r);
            let mut q = polygon(&mut r);
            if case % 10 == 0 {
                // Parallel to p, as a floor and a ceiling are.
                let lift = DVec3::new(0.1, 1.5, -0.2);
                q = p.iter().map(|x| *x * 0.7 + lift).collect();
            }
            let all: Vec<DVec3> = p.iter().chain(&q).copied().collect();
            let (general, fast) = (Shaft::hull(&all), Shaft::between_polygons(&p, &q));
            let centre = all.iter().copied().sum::<DVec3>() / all.len() as f64;
            for _ in 0..50 {
                // Near the hull's boundary: a point of it pushed in or out.
                let weights: Vec<f64> = all.iter().map(|_| r().powi(4)).collect();
                let x = all
                    .iter()
                    .zip(&weights)
                    .map(|(p, w)| *p * *w)
                    .sum::<DVec3>()
                    / weights.iter().sum::<f64>();
                let probe = vec![centre + (x - centre) * (0.7 + 0.6 * r())];
                assert_eq!(
                    general.excludes(&probe),
                    fast.excludes(&probe),
                    "case {case}"
                );
            }
        }
    }

    /// Conservative: no point of the true hull of the two boxes (a random
    /// convex combination of their corners) is ever excluded. (The face
    /// test of `Shaft::hull` is weaker for slivers, so the two tests are
    /// not nested; both are conservative against the true hull.)
    #[test]
    fn box_shafts_never_exclude_a_point_of_the_true_hull() {
        let mut state = 99u64;
        let mut r = || crate::util::rng::unit_random(&mut state);
        for _ in 0..3000 {
            let mut bx = || {
                let lo = DVec3::new(r() * 4.0 - 2.0, r() * 3.0, r() * 4.0 - 2.0);
                let mut size = DVec3::new(r(), r(), r());
                let flat = (r() * 4.0) as usize;
                if flat < 3 {
                    size[flat] = 0.0;
                }
                (lo, lo + size)
            };
            let (a, b) = (bx(), bx());
            let shaft = Shaft::between_boxes(a, b);
            let mut pts: Vec<DVec3> = Vec::new();
            for bb in [a, b] {
                pts.extend((0..8).map(|i| {
                    DVec3::new(
                        if i & 1 == 0 { bb.0.x } else { bb.1.x },
                        if i & 2 == 0 { bb.0.y } else { bb.1.y },
                        if i & 4 == 0 { bb.0.z } else { bb.1.z },
                    )
                }));
            }
            for _ in 0..40 {
                let w: Vec<f64> = (0..pts.len()).map(|_| r().powi(4)).collect();
                let total: f64 = w.iter().sum();
                let p = pts.iter().zip(&w).map(|(p, w)| *p * *w).sum::<DVec3>() / total;
                assert!(
                    !shaft.excludes(&[p]),
                    "a {a:?} b {b:?} excludes its own hull's point {p}"
                );
            }
        }
    }
}
