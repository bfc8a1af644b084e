//! What an update keeps of the last pose's rays towards the objects: a
//! receiver's bundle of rays towards a surface that did not move (its
//! object neither moved nor was shown or hidden) meets that surface as
//! before unless a surface that moved was, or is, in the way. Every ray
//! of such a bundle that met the surface ran, from a point of the
//! receiver's sphere to a point of the surface's, inside the capsule of the
//! larger radius around the segment between their centres; a moved
//! surface whose sphere (where it was, or where it is) clears that capsule
//! cannot have changed any of them. The bundles kept are the ones a fresh
//! trace would give (the same rays, seeded alike, meeting the same
//! triangles), so an update's image stays a full render's, bit for bit.

use glam::DVec3;

use super::change::{Seen, Target, targets};
use crate::objects::VirtualBounds;
use crate::patches::Patches;

/// Which surfaces' bundles an update may keep, and what moved.
#[derive(Debug, Clone, Default)]
pub struct StillSurfaces {
    /// By surface id: None, or how far its patches' numbers moved (the
    /// objects before it in the list may have more or fewer patches now).
    shift: Vec<Option<i64>>,
    /// The spheres of the surfaces that moved, where they were and where they are.
    movers: Vec<(DVec3, f64)>,
    /// Their boxes, in the same order.
    boxes: Vec<(DVec3, DVec3)>,
}

/// Beyond a receiver's own reach, what a ray's origin may be lifted off it.
const ORIGIN_SLACK: f64 = 1e-3;

impl StillSurfaces {
    /// Between the objects' bounds and patches of the last pose (`old`)
    /// and this one's, with `unmoved` the surfaces whose objects stood
    /// still (shown in both): a surface is still when its box is where it
    /// was and its patches are the same elements as before, in one run.
    pub fn between(
        old: (&VirtualBounds, &Patches),
        new: (&VirtualBounds, &Patches),
        unmoved: &[u32],
    ) -> StillSurfaces {
        let (old_targets, new_targets) = (targets(old.0), targets(new.0));
        let (old_runs, new_runs) = (patch_runs(old.1), patch_runs(new.1));
        let find = |ts: &[Target], s: u32| ts.iter().find(|t| t.surface == s).copied();
        let mut out = StillSurfaces::default();
        for &s in unmoved {
            let (Some(a), Some(b)) = (find(&old_targets, s), find(&new_targets, s)) else {
                continue;
            };
            let (Some(&(p, n)), Some(&(q, m))) = (old_runs.get(&s), new_runs.get(&s)) else {
                continue;
            };
            let same_patches = n == m
                && (0..n).all(|i| {
                    let (x, y) = (old.1.patch(p + i), new.1.patch(q + i));
                    x.shape == y.shape && x.surface == y.surface
                });
            if a.lo != b.lo || a.hi != b.hi || !same_patches {
                continue;
            }
            if out.shift.len() <= s as usize {
                out.shift.resize(s as usize + 1, None);
            }
            out.shift[s as usize] = Some(q as i64 - p as i64);
        }
        for t in old_targets.iter().chain(&new_targets) {
            if !out.is_still(t.surface) {
                out.movers.push((t.centre, t.radius));
                out.boxes.push((t.lo, t.hi));
            }
        }
        out
    }

    /// `seen`, a hit on still surface `surface` the pose before, as this pose numbers it.
    pub(super) fn renumbered(&self, surface: u32, mut seen: Seen) -> Seen {
        let shift = self.shift[surface as usize].expect("a still surface");
        seen.object = (seen.object as i64 + shift) as u32;
        seen
    }

    /// Whether no surface that moved, where it was or where it is, comes
    /// near the segment from `a` to `b` (its sphere first, then its box).
    pub fn clear_of_movers(&self, a: DVec3, b: DVec3) -> bool {
        let slack = DVec3::splat(ORIGIN_SLACK);
        (self.movers.iter().zip(&self.boxes)).all(|(&(c, r), &(lo, hi))| {
            distance_to_segment(c, a, b) > r + ORIGIN_SLACK
                || !crate::geometry::segment_meets_box(a, b, lo - slack, hi + slack)
        })
    }

    /// Whether no surface that moved, where it was or where it is, comes
    /// near any segment from a point within `slack` of `a` to a point
    /// within `radius` of `c` (its sphere against the cone from `a` to
    /// `c`'s ball, `slack` further). Its box is tested too: the cone lies
    /// within `radius` + `slack` of the segment a–c, which then misses the
    /// box grown by as much.
    pub fn clear_of_movers_towards(&self, a: DVec3, c: DVec3, radius: f64, slack: f64) -> bool {
        (self.movers.iter().zip(&self.boxes)).all(|(&(m, r), &(lo, hi))| {
            let pad = DVec3::splat(radius + slack + ORIGIN_SLACK);
            distance_to_cone(m, a, c, radius) > r + slack + ORIGIN_SLACK
                || !crate::geometry::segment_meets_box(a, c, lo - pad, hi + pad)
        })
    }

    /// Whether every surface that moved, where it was and where it is,
    /// lies outside `shaft` (its box).
    pub fn clear_of_shaft(&self, shaft: &crate::shaft::Shaft) -> bool {
        (self.boxes.iter()).all(|&(lo, hi)| shaft.excludes(&crate::geometry::box_corners(lo, hi)))
    }

    /// How far still surface `surface`'s patch numbers moved (None: it
    /// moved, or was shown or hidden).
    pub fn patch_shift(&self, surface: u32) -> Option<i64> {
        self.shift.get(surface as usize).copied().flatten()
    }

    pub fn is_still(&self, surface: u32) -> bool {
        self.shift
            .get(surface as usize)
            .is_some_and(|s| s.is_some())
    }

    /// Whether the bundle from a receiver within `reach` of `from` towards
    /// target `t` is as it was.
    pub(super) fn keeps(&self, from: DVec3, reach: f64, t: &Target) -> bool {
        if !self.is_still(t.surface) {
            return false;
        }
        let radius = (reach + ORIGIN_SLACK).max(t.radius);
        self.movers
            .iter()
            .all(|&(c, r)| distance_to_segment(c, from, t.centre) > r + radius)
    }

    /// Whether no surface that moved, where it was or where it is, comes
    /// within the rays of a bundle from a receiver within `reach` of
    /// `from` inside `cone` (its axis and the cosine of its half-angle;
    /// None: the hemisphere) as far as target `t`'s far side.
    pub(super) fn cone_clear(
        &self,
        from: DVec3,
        reach: f64,
        (axis, cone): (DVec3, Option<f64>),
        t: &Target,
    ) -> bool {
        let far = (t.centre - from).length() + t.radius + reach;
        self.movers.iter().all(|&(c, r)| {
            let r = r + reach + ORIGIN_SLACK;
            let v = c - from;
            let d = v.length();
            if d <= r {
                return false;
            }
            if d - r > far {
                return true;
            }
            let Some(cos_max) = cone else {
                return false;
            };
            // The sphere lies outside the cone when the angle to its centre
            // less its angular radius exceeds the cone's half-angle.
            let phi = (v.dot(axis) / d).clamp(-1.0, 1.0).acos();
            phi - (r / d).asin() > cos_max.clamp(-1.0, 1.0).acos()
        })
    }

    /// Whether a surface that moved comes, where it was or where it is,
    /// near the ray from `origin` along `d` as far as target `t`'s far side.
    pub(super) fn crosses(&self, origin: DVec3, d: DVec3, t: &Target) -> bool {
        let length = d.length();
        if length == 0.0 {
            return false;
        }
        let reach = (t.centre - origin).length() + t.radius;
        let end = origin + d * (reach / length);
        (self.movers.iter()).any(|&(c, r)| distance_to_segment(c, origin, end) <= r + ORIGIN_SLACK)
    }
}

/// An update's moved objects, for what a session keeps of its rays.
impl crate::objects::Movers for StillSurfaces {
    fn clear_towards(&self, a: DVec3, c: DVec3, radius: f64, slack: f64) -> bool {
        self.clear_of_movers_towards(a, c, radius, slack)
    }

    fn unmoved(&self, surface: u32) -> bool {
        self.is_still(surface) && self.patch_shift(surface) == Some(0)
    }

    fn any_unmoved(&self) -> bool {
        self.shift.contains(&Some(0))
    }
}

/// Per virtual surface, its patches' first number and count, where they
/// are one run (a surface meshed as any other is).
fn patch_runs(patches: &Patches) -> std::collections::HashMap<u32, (usize, usize)> {
    let mut runs: std::collections::HashMap<u32, (usize, usize)> = Default::default();
    let mut broken = Vec::new();
    for k in 0..patches.patch_count() {
        let s = patches.patch(k).surface;
        if !patches.is_virtual_surface(s) {
            continue;
        }
        let run = runs.entry(s).or_insert((k, 0));
        if run.0 + run.1 != k {
            broken.push(s);
        }
        run.1 += 1;
    }
    for s in broken {
        runs.remove(&s);
    }
    runs
}

/// A lower bound of the distance from `p` to the cone of segments from
/// `a` to the ball of `radius` around `b`: the least over the axis's
/// points at fraction s of |p − (a + s(b − a))| − s·radius (each point of
/// the cone at s lies within s·radius of the axis), a convex function of
/// s, whose least is where its slope is zero, or at an end.
fn distance_to_cone(p: DVec3, a: DVec3, b: DVec3, radius: f64) -> f64 {
    let axis = b - a;
    let length = axis.length();
    if radius <= 0.0 || length <= radius {
        return distance_to_segment(p, a, b) - radius;
    }
    let u = axis / length;
    let along = (p - a).dot(u);
    let across = ((p - a) - u * along).length();
    // Zero slope: (s·L − along) / |…| = radius / L.
    let k = radius / length;
    let s = ((along + across * k / (1.0 - k * k).sqrt()) / length).clamp(0.0, 1.0);
    (p - (a + axis * s)).length() - s * radius
}

/// The distance from `p` to the segment from `a` to `b`.
fn distance_to_segment(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let d = b - a;
    let s = match d.length_squared() {
        l if l > 0.0 => ((p - a).dot(d) / l).clamp(0.0, 1.0),
        _ => 0.0,
    };
    (a + d * s - p).length()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_moved_sphere_is_clear_of_a_cone_only_outside_it_or_beyond_the_target() {
        let target = Target {
            surface: 7,
            centre: DVec3::new(0.0, 0.0, 2.0),
            radius: 0.5,
            lo: DVec3::splat(-0.5) + DVec3::new(0.0, 0.0, 2.0),
            hi: DVec3::splat(0.5) + DVec3::new(0.0, 0.0, 2.0),
        };
        let moved = |c: DVec3, r: f64| StillSurfaces {
            shift: vec![None; 8],
            movers: vec![(c, r)],
            boxes: vec![(c - DVec3::splat(r), c + DVec3::splat(r))],
        };
        let cone = (DVec3::Z, Some(0.25f64.asin().cos()));
        let clear = |s: &StillSurfaces, cone| s.cone_clear(DVec3::ZERO, 0.0, cone, &target);
        // On the axis, between the receiver and the target.
        assert!(!clear(&moved(DVec3::new(0.0, 0.0, 1.0), 0.1), cone));
        // Beside the cone (45° off its 14.5° half-angle), and behind the receiver.
        assert!(clear(&moved(DVec3::new(1.0, 0.0, 1.0), 0.1), cone));
        assert!(clear(&moved(DVec3::new(0.0, 0.0, -1.0), 0.1), cone));
        // Just touching the cone's edge from outside: not clear.
        assert!(!clear(&moved(DVec3::new(0.5, 0.0, 1.0), 0.3), cone));
        // Beyond the target's far side, and anywhere near over a hemisphere.
        assert!(clear(&moved(DVec3::new(0.0, 0.0, 3.0), 0.2), cone));
        assert!(!clear(
            &moved(DVec3::new(1.0, 0.0, 1.0), 0.1),
            (DVec3::Z, None)
        ));
    }

    #[test]
    fn the_distance_to_a_cone_bounds_every_segment_in_it() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let v = |rng: &mut rand::rngs::StdRng, s: f64| {
            DVec3::new(rng.random(), rng.random(), rng.random()) * s - DVec3::splat(0.5 * s)
        };
        for _ in 0..2000 {
            let (a, b, p) = (v(&mut rng, 4.0), v(&mut rng, 4.0), v(&mut rng, 4.0));
            let radius = rng.random::<f64>() * 0.8;
            let bound = distance_to_cone(p, a, b, radius);
            // Segments to points of the ball's surface and inside it.
            for _ in 0..40 {
                let w = v(&mut rng, 2.0).normalize_or_zero() * radius * rng.random::<f64>();
                let d = distance_to_segment(p, a, b + w);
                assert!(bound <= d + 1e-12, "bound {bound} above a segment's {d}");
            }
        }
        // Along the axis the cone narrows to its apex.
        let (a, b) = (DVec3::ZERO, DVec3::new(4.0, 0.0, 0.0));
        let near_apex = distance_to_cone(DVec3::new(0.5, 0.5, 0.0), a, b, 1.0);
        assert!(near_apex > 0.3 && near_apex < 0.4, "{near_apex}");
    }

    #[test]
    fn the_distance_to_a_segment_is_to_its_nearest_point() {
        let (a, b) = (DVec3::ZERO, DVec3::new(2.0, 0.0, 0.0));
        assert_eq!(distance_to_segment(DVec3::new(1.0, 3.0, 0.0), a, b), 3.0);
        assert_eq!(distance_to_segment(DVec3::new(-3.0, 4.0, 0.0), a, b), 5.0);
        assert_eq!(distance_to_segment(DVec3::new(5.0, 0.0, 4.0), a, b), 5.0);
        assert_eq!(
            distance_to_segment(DVec3::new(1.0, 1.0, 0.0), a, a),
            2f64.sqrt()
        );
    }
}
