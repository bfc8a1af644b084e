//! Virtual objects as a change to a room's solved radiosity: what each
//! room patch sees of the objects, traced from the patch towards them.
//!
//! A room patch that sees an object along a direction stops receiving the
//! radiance of the room behind it (which the room's unchanged links still
//! carry: the object sends it back as negative light, George, Sillion &
//! Greenberg 1990; antiradiance, Dachsbacher et al. 2007) and receives the
//! object's own radiance instead. Both are read along the same rays: one
//! ray against the room and objects finds the object, one against the room
//! alone finds what it hides. The rays depend on the patches and objects
//! only, so a pose traces them once and the change is a sum over them for
//! any radiosity; a patch that cannot see an object traces nothing.

use super::still::StillSurfaces;
use super::transport::*;
use super::*;
use crate::light::offset_origin;
use crate::objects::VirtualBounds;
use crate::patches::{Element, Patches};
use crate::trace::{Hit, Layer, TraceRay, Tracer};
use glam::DVec3;
use rayon::prelude::*;

/// Rays from a patch towards one object when it sees it over its whole
/// hemisphere; fewer in proportion to the cone's solid angle.
const MAX_RAYS: u32 = 1024;

/// Fewest rays, for a patch that sees an object as a small cone.
const MIN_RAYS: u32 = 4;

/// Half-angle of the widest cone sampled as a cone (72°): wider, a
/// patch's rays cover its hemisphere, cosine-distributed.
const CONE_MAX: f64 = 1.2566;

/// One ray from a room patch that met an object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Seen {
    /// Solid angle × cosine at the receiver, over the rays in its cone: the
    /// irradiance this ray stands for per unit radiance.
    pub(super) weight: f32,
    /// The ray's number in its bundle (what an update that keeps the
    /// bundle's other rays re-traces it by).
    pub(super) ray: u32,
    /// The object patch the ray met.
    pub(super) object: u32,
    /// The room patch behind it (`u32::MAX`: the ray leaves the room).
    pub(super) behind: u32,
}

/// What the room's patches see of the virtual objects.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ObjectView {
    /// Per room patch that sees an object: (patch, range in `seen`).
    ranges: Vec<(u32, u32, u32)>,
    seen: Vec<Seen>,
    /// Per room patch and target surface traced: (surface, range in
    /// `seen`), patch `k`'s from `bundle_start[k]` (what an update keeps,
    /// see [`StillSurfaces`]).
    bundles: Vec<(u32, u32, u32)>,
    bundle_start: Vec<u32>,
    /// Rays traced.
    pub rays: u64,
    /// Bundles kept from the last pose rather than traced.
    pub kept: u64,
}

/// A sphere around one virtual surface and the surface's id.
#[derive(Debug, Clone, Copy)]
pub(super) struct Target {
    pub(super) surface: u32,
    pub(super) centre: DVec3,
    pub(super) radius: f64,
    pub(super) lo: DVec3,
    pub(super) hi: DVec3,
}

/// A target per virtual surface of `objects`.
pub(super) fn targets(objects: &VirtualBounds) -> Vec<Target> {
    objects
        .surface_bounds()
        .map(|(surface, b)| {
            let (lo, hi) = b.aabb;
            Target {
                surface,
                centre: 0.5 * (lo + hi),
                radius: 0.5 * (hi - lo).length(),
                lo,
                hi,
            }
        })
        .collect()
}

impl ObjectView {
    /// Traces, from each of the first `room_count` patches of `patches`
    /// (the room's, followed by the objects'), rays towards each virtual
    /// surface of `objects` that lies in front of it.
    pub fn trace(
        patches: &Patches,
        room_count: usize,
        tracer: &Tracer,
        objects: &VirtualBounds,
    ) -> ObjectView {
        ObjectView::trace_keeping(patches, room_count, tracer, objects, None)
    }

    /// [`ObjectView::trace`], keeping from `last` (the view of the pose
    /// before) the bundles `still` says a fresh trace would give again.
    pub fn trace_keeping(
        patches: &Patches,
        room_count: usize,
        tracer: &Tracer,
        objects: &VirtualBounds,
        last: Option<(&ObjectView, &StillSurfaces)>,
    ) -> ObjectView {
        let targets = targets(objects);
        if targets.is_empty() {
            return ObjectView::default();
        }
        // Per patch: its rays' hits, rays traced, bundles, bundles kept.
        type PatchView = (Vec<Seen>, u64, Vec<(u32, u32, u32)>, u64);
        let per_patch: Vec<PatchView> = (0..room_count)
            .into_par_iter()
            .map(|k| {
                let (mut seen, mut rays, mut bundles, mut kept_here) =
                    (Vec::new(), 0, Vec::new(), 0);
                let el = patches.patch(k);
                let h = (el.shape.corners().iter())
                    .map(|c| (*c - el.centre).length())
                    .fold(0.0, f64::max);
                for t in &targets {
                    let a = seen.len() as u32;
                    // The bundle the pose before traced towards a surface that stood still.
                    let old = last.and_then(|(view, still)| {
                        let range = still.is_still(t.surface).then(|| view.bundle(k, t.surface));
                        Some((&view.seen[range.flatten()?], still))
                    });
                    match old {
                        Some((old, still))
                            if still.keeps(el.centre, h, t)
                                || still.cone_clear(
                                    el.centre,
                                    h,
                                    cone_towards(el.centre, h, t),
                                    t,
                                ) =>
                        {
                            seen.extend(old.iter().map(|s| still.renumbered(t.surface, *s)));
                            kept_here += 1;
                        }
                        _ => {
                            if let Some(bundle) = view_rays(patches, k, t) {
                                rays += trace_bundle(patches, &bundle, t, tracer, old, &mut seen);
                                kept_here += old.is_some() as u64;
                            }
                        }
                    }
                    bundles.push((t.surface, a, seen.len() as u32));
                }
                (seen, rays, bundles, kept_here)
            })
            .collect();
        let mut view = ObjectView {
            bundle_start: Vec::with_capacity(room_count + 1),
            ..ObjectView::default()
        };
        for (k, (seen, rays, bundles, kept)) in per_patch.into_iter().enumerate() {
            view.rays += rays;
            view.kept += kept;
            let a = view.seen.len() as u32;
            view.bundle_start.push(view.bundles.len() as u32);
            view.bundles
                .extend(bundles.into_iter().map(|(s, x, y)| (s, x + a, y + a)));
            if seen.is_empty() {
                continue;
            }
            view.seen.extend(seen);
            view.ranges.push((k as u32, a, view.seen.len() as u32));
        }
        view.bundle_start.push(view.bundles.len() as u32);
        view
    }

    /// Patch `k`'s bundle towards `surface`, as a range in `seen`.
    fn bundle(&self, k: usize, surface: u32) -> Option<std::ops::Range<usize>> {
        let (a, b) = (*self.bundle_start.get(k)?, *self.bundle_start.get(k + 1)?);
        (self.bundles[a as usize..b as usize].iter())
            .find(|(s, _, _)| *s == surface)
            .map(|&(_, x, y)| x as usize..y as usize)
    }

    /// Room patches that see an object.
    pub fn patch_count(&self) -> usize {
        self.ranges.len()
    }

    pub fn memory_bytes(&self) -> usize {
        (self.ranges.len() + self.bundles.len()) * std::mem::size_of::<(u32, u32, u32)>()
            + self.bundle_start.len() * 4
            + self.seen.len() * std::mem::size_of::<Seen>()
    }

    /// Each room patch that sees an object, with what its rays met.
    pub(super) fn receivers(&self) -> impl Iterator<Item = (u32, &[Seen])> {
        (self.ranges.iter()).map(|&(k, a, b)| (k, &self.seen[a as usize..b as usize]))
    }

    /// The change to each room patch's irradiance (`room_count` values):
    /// the objects' radiance (`radiosity`, per patch of the room and the
    /// objects, /π) where a patch sees them, less the room's radiance
    /// behind them (`room`, per room patch) that the room's links carry.
    pub fn irradiance_change(
        &self,
        room_count: usize,
        radiosity: &[DVec3],
        room: &[DVec3],
    ) -> Vec<DVec3> {
        let mut out = vec![DVec3::ZERO; room_count];
        for &(k, a, b) in &self.ranges {
            let sum: DVec3 = self.seen[a as usize..b as usize]
                .iter()
                .map(|s| {
                    let behind = room.get(s.behind as usize).copied().unwrap_or(DVec3::ZERO);
                    (radiosity[s.object as usize] - behind) * f64::from(s.weight)
                })
                .sum();
            out[k as usize] = sum / std::f64::consts::PI;
        }
        out
    }

    /// Subtracts from `out` (per room patch) the irradiance the objects
    /// hide of room radiosity `x`: the objects' shadow on the room's own
    /// links, applied to any radiosity (the change's bounces).
    fn hide_from(&self, x: &[DVec3], out: &mut [DVec3]) {
        for &(k, a, b) in &self.ranges {
            let hidden: DVec3 = (self.seen[a as usize..b as usize].iter())
                .filter_map(|s| Some(*x.get(s.behind as usize)? * f64::from(s.weight)))
                .sum();
            out[k as usize] -= hidden / std::f64::consts::PI;
        }
    }
}

/// Solves for the change ΔB the objects make to a room's radiosity:
/// ΔB = b + ρ ⊙ (T(ΔB) − G(ΔB)), with T the room's `transport` and G what
/// the objects hide (`view`), from `guess` (or zero) to relative residual
/// `tolerance`. The change's bounces pass the objects as the room's light
/// does: where the change is bright (the wall an object lights), the room
/// behind the object does not see it. Its `indirect_irradiance` is
/// T(ΔB) − G(ΔB).
pub fn solve_change(
    patches: &Patches,
    transport: &Transport,
    reflectance: &[DVec3],
    b: &[DVec3],
    guess: Option<&[DVec3]>,
    view: &ObjectView,
    tolerance: f64,
) -> Solution {
    let gather = |x: &[DVec3], out: &mut [DVec3]| {
        transport.gather_channels(patches, x, out);
        view.hide_from(x, out);
    };
    let apply = |x: &[DVec3], out: &mut [DVec3]| {
        gather(x, out);
        for ((o, x), r) in out.iter_mut().zip(x).zip(reflectance) {
            *o = *x - *r * *o;
        }
    };
    let (change, stats) = super::solve::gmres_rgb(apply, b, guess, tolerance, 500, 40);
    let (iterations, residual) = super::solve::largest(&stats);
    let mut indirect = vec![DVec3::ZERO; b.len()];
    gather(&change, &mut indirect);
    Solution {
        radiosity: change,
        indirect_irradiance: indirect,
        iterations,
        residual,
    }
}

/// The side of element `el` that receives light from target `t` (its
/// normal, or the opposite for a two-sided element), None where `t` lies
/// wholly behind a one-sided element or in its plane.
pub(super) fn receiving_side(el: &Element, t: &Target) -> Option<DVec3> {
    let corners = crate::geometry::box_corners(t.lo, t.hi);
    let side = |c: &DVec3| (*c - el.centre).dot(el.normal);
    let front = corners.iter().any(|c| side(c) > 0.0);
    let back = corners.iter().any(|c| side(c) < 0.0);
    match (front, back) {
        (false, false) => None,
        (false, true) if el.one_sided => None,
        (false, true) => Some(-el.normal),
        (true, false) => Some(el.normal),
        (true, true) if el.one_sided => Some(el.normal),
        (true, true) if side(&t.centre) >= 0.0 => Some(el.normal),
        (true, true) => Some(-el.normal),
    }
}

/// The cone of directions that holds target `t` seen from anywhere within
/// `h` of `from` (the axis turns by at most asin(h / d) over that disc, and
/// the sphere spans asin(r / (d - h)) about it): its unit axis, and the
/// cosine of its half-angle, None where a hemisphere is needed instead.
pub(super) fn cone_towards(from: DVec3, h: f64, t: &Target) -> (DVec3, Option<f64>) {
    let axis = t.centre - from;
    let d = axis.length();
    let spread = if d > h + t.radius {
        (h / d).asin() + (t.radius / (d - h)).asin()
    } else {
        std::f64::consts::FRAC_PI_2
    };
    (
        axis / d.max(1e-300),
        (spread < CONE_MAX).then(|| spread.cos()),
    )
}

/// A receiver's `count` rays towards a cone (`cone`: its axis and the
/// cosine of its half-angle) or over the hemisphere about `n`, the frame
/// about the axis made once for the bundle: an update makes every ray of
/// a kept bundle to test it against what moved, and a frame made per ray
/// was a good part of that (beside a still 2 m table, what the room sees
/// of the objects took 66–73 ms a step then, 57–60 ms since).
#[derive(Clone, Copy)]
pub(super) struct Towards {
    n: DVec3,
    axis: DVec3,
    frame: (DVec3, DVec3),
    cone: Option<f64>,
    count: u32,
}

impl Towards {
    pub(super) fn new(n: DVec3, (axis, cone): (DVec3, Option<f64>), count: u32) -> Towards {
        let axis = if cone.is_some() { axis } else { n };
        Towards {
            n,
            axis,
            frame: frame(axis),
            cone,
            count,
        }
    }

    /// The ray at Sobol parameters (`u1`, `u2`): its direction and the
    /// irradiance it stands for per unit radiance.
    pub(super) fn at(&self, u1: f64, u2: f64) -> (DVec3, f64) {
        match self.cone {
            Some(cos_max) => {
                let solid = std::f64::consts::TAU * (1.0 - cos_max);
                let d = cone_direction_in(self.frame, self.axis, cos_max, u1, u2);
                // Cone rays weigh Ω / count × cos.
                (d, solid / self.count as f64 * d.dot(self.n).max(0.0))
            }
            // Cosine-distributed rays weigh π / count.
            None => (
                cosine_direction_in(self.frame, self.axis, u1, u2),
                std::f64::consts::PI / self.count as f64,
            ),
        }
    }
}

/// Rays for a cone (or the hemisphere, None) of `max` over the whole
/// hemisphere: fewer in proportion to its solid angle, a power of two.
pub(super) fn rays_for(cone: Option<f64>, max: u32) -> u32 {
    let share = cone.map_or(1.0, |c| 1.0 - c);
    ((max as f64 * share).ceil() as u32)
        .clamp(MIN_RAYS, max)
        .next_power_of_two()
}

/// Patch `k`'s bundle of rays towards target `t` and the side they leave
/// from; None when `t` is behind it.
fn view_rays(patches: &Patches, k: usize, t: &Target) -> Option<Bundle> {
    let el = patches.patch(k);
    let n = receiving_side(el, t)?;
    // One cone from the patch's centre for all its rays (a patch that close
    // gathers over its hemisphere instead): one axis keeps the
    // stratification of their directions.
    let h = (el.shape.corners().iter())
        .map(|c| (*c - el.centre).length())
        .fold(0.0, f64::max);
    let cone = cone_towards(el.centre, h, t);
    let count = rays_for(cone.1, MAX_RAYS);
    let seed = crate::util::rng::hash2(k as u64, t.surface as u64) as u32;
    let towards = Towards::new(n, cone, count);
    let rays = (0..count)
        .map(|i| {
            let [s, v, u1, u2] = sobol_burley::sample_4d(i, 0, seed).map(f64::from);
            let (d, w) = towards.at(u1, u2);
            (point_on(el, s, v), d, w)
        })
        .collect();
    Some(Bundle { n, rays })
}

/// A receiver's rays towards one target: (origin, direction, weight) each,
/// leaving from the side `n` faces.
pub(super) struct Bundle {
    pub(super) n: DVec3,
    pub(super) rays: Vec<(DVec3, DVec3, f64)>,
}

/// Traces `bundle` towards target `t`, keeping in `seen` the rays that meet
/// it first; returns the rays traced. With `last` (the bundle's hits the
/// pose before, and what moved since), only the rays a surface that moved
/// may have crossed are traced again and the others' hits kept: `seen`
/// gets what a fresh trace gives.
pub(super) fn trace_bundle(
    patches: &Patches,
    bundle: &Bundle,
    t: &Target,
    tracer: &Tracer,
    last: Option<(&[Seen], &StillSurfaces)>,
    seen: &mut Vec<Seen>,
) -> u64 {
    let indexed = |i: usize| {
        let (x, d, w) = bundle.rays[i];
        (i as u32, x, d, w)
    };
    let Some((old, still)) = last else {
        let all: Vec<_> = (0..bundle.rays.len()).map(indexed).collect();
        return trace_seen(patches, &all, bundle.n, t, tracer, seen);
    };
    let crossed: Vec<_> = (0..bundle.rays.len())
        .filter(|&i| still.crosses(bundle.rays[i].0, bundle.rays[i].1, t))
        .map(indexed)
        .collect();
    let mut fresh = Vec::new();
    let traced = trace_seen(patches, &crossed, bundle.n, t, tracer, &mut fresh);
    // Both in ray order: the kept hits of the rays not traced, and the new ones.
    let retraced = |s: &Seen| crossed.binary_search_by_key(&s.ray, |r| r.0).is_ok();
    let mut kept = old.iter().filter(|s| !retraced(s)).peekable();
    let mut fresh = fresh.into_iter().peekable();
    loop {
        let take_kept = match (kept.peek(), fresh.peek()) {
            (Some(a), Some(b)) => a.ray < b.ray,
            (Some(_), None) => true,
            (None, Some(_)) => false,
            (None, None) => break,
        };
        let next = match take_kept {
            true => kept.next().map(|s| still.renumbered(t.surface, *s)),
            false => fresh.next(),
        };
        seen.extend(next);
    }
    traced
}

/// Traces `rays` (number, origin, direction, weight) from a receiver facing `n`,
/// keeping in `seen` those that meet target `t` first, with the room patch
/// each hides; returns the rays traced.
fn trace_seen(
    patches: &Patches,
    rays: &[(u32, DVec3, DVec3, f64)],
    n: DVec3,
    t: &Target,
    tracer: &Tracer,
    seen: &mut Vec<Seen>,
) -> u64 {
    let traced: Vec<TraceRay> = (rays.iter())
        .map(|(_, x, d, _)| TraceRay::new(offset_origin(*x, n, *x + n).as_vec3(), d.as_vec3()))
        .collect();
    let (met, count) = meet_target(tracer, &traced, t.surface, |i| rays[i].2.dot(n) > 0.0);
    for (i, h, b) in met {
        let (o, d) = (traced[i].origin.as_dvec3(), rays[i].2);
        let Some(object) = patches.locate(h.surface, h.triangle, o + d * h.t as f64) else {
            continue;
        };
        let behind = b
            .and_then(|b| patches.locate(b.surface, b.triangle, o + d * b.t as f64))
            .map_or(u32::MAX, |l| l.patch);
        seen.push(Seen {
            weight: rays[i].3 as f32,
            ray: rays[i].0,
            object: object.patch,
            behind,
        });
    }
    count
}

/// The rays among `rays` (those `wanted` says) that meet virtual surface
/// `surface` before any other object and any room surface: each ray's
/// number, its hit on the surface and the room's first hit along it (what
/// the surface hides there); and the queries made. The objects are traced
/// first (their own small BVH), the room only along the rays whose first
/// object is `surface`: one room query says both whether the room hides
/// the surface (nearer) and what it hides (farther). The same answers as
/// a query of both layers followed by one of the room, without crossing
/// the room where a ray misses.
pub(super) fn meet_target(
    tracer: &Tracer,
    rays: &[TraceRay],
    surface: u32,
    wanted: impl Fn(usize) -> bool,
) -> (Vec<(usize, Hit, Option<Hit>)>, u64) {
    let mut hits = vec![None; rays.len()];
    tracer.intersect_batch(rays, Layer::Virtual, &mut hits);
    let aimed: Vec<usize> = (0..rays.len())
        .filter(|&i| hits[i].as_ref().is_some_and(|h| h.surface == surface) && wanted(i))
        .collect();
    let count = (rays.len() + aimed.len()) as u64;
    if aimed.is_empty() {
        return (Vec::new(), count);
    }
    let room_rays: Vec<TraceRay> = aimed.iter().map(|&i| rays[i]).collect();
    let mut room = vec![None; room_rays.len()];
    tracer.intersect_batch(&room_rays, Layer::Real, &mut room);
    let met = (aimed.into_iter().zip(room))
        .filter_map(|(i, b)| {
            let h = hits[i].take().expect("an aimed ray met the surface");
            // A room surface nearer hides it; at the same distance the
            // object is taken, as a query of both layers has it.
            match b {
                Some(b) if b.t < h.t => None,
                _ => Some((i, h, b)),
            }
        })
        .collect();
    (met, count)
}

/// The point at parameters (`s`, `t`) ∈ \[0, 1)² of the element (a
/// triangle folded into its parallelogram).
fn point_on(el: &Element, s: f64, t: f64) -> DVec3 {
    match el.shape {
        crate::patches::Shape::Quad { origin, u, v } => origin + u * s + v * t,
        crate::patches::Shape::Tri([a, b, c]) => {
            let (s, t) = if s + t > 1.0 {
                (1.0 - s, 1.0 - t)
            } else {
                (s, t)
            };
            a + (b - a) * s + (c - a) * t
        }
    }
}

/// Two unit vectors completing unit `axis` to a frame.
fn frame(axis: DVec3) -> (DVec3, DVec3) {
    let t = if axis.x.abs() < 0.9 {
        DVec3::X.cross(axis).normalize()
    } else {
        DVec3::Y.cross(axis).normalize()
    };
    (t, axis.cross(t))
}

/// The direction at (`u1`, `u2`) ∈ \[0, 1)² of the uniform distribution over
/// the cone of half-angle acos(`cos_max`) about unit `axis`.
fn cone_direction_in((t, b): (DVec3, DVec3), axis: DVec3, cos_max: f64, u1: f64, u2: f64) -> DVec3 {
    let cos = 1.0 - u1 * (1.0 - cos_max);
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = std::f64::consts::TAU * u2;
    t * (sin * phi.cos()) + b * (sin * phi.sin()) + axis * cos
}

/// The direction at (`u1`, `u2`) of the cosine distribution about unit `n`.
pub fn cosine_direction(n: DVec3, u1: f64, u2: f64) -> DVec3 {
    cosine_direction_in(frame(n), n, u1, u2)
}

/// [`cosine_direction`] in the frame `(t, b)` made about `n`.
fn cosine_direction_in((t, b): (DVec3, DVec3), n: DVec3, u1: f64, u2: f64) -> DVec3 {
    let (r, phi) = (u1.sqrt(), std::f64::consts::TAU * u2);
    t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt()
}
