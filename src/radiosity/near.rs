//! The objects' change to the room's indirect light near them, held finer
//! than the room's patches.
//!
//! [`ObjectView`] gives each room patch the mean of what it sees of the
//! objects less what they hide; the room's vertices interpolate those
//! means. Within an object's size of it, the change varies over a few
//! centimetres (a bright face lights the floor in front of it, the floor
//! beside its base sees less of the room) while a room patch may be most
//! of a metre across: the mean spreads a narrow glow over the patch and its
//! neighbours. Each room patch that close holds a grid of points at the
//! objects' patch size where the same change is traced at the point, and
//! a pixel on it reads the difference from the interpolated means,
//! tapered to nothing at twice an object's radius from it, where the
//! patch means take over unchanged.
//!
//! A composite reads the field only at the plain real pixels' points (a
//! pixel that shows an object reads the object's light), so a grid traces
//! only the points whose cells hold one of them ([`ReadPoints`]): the floor
//! under an object, and what the camera does not see of a patch, cost
//! nothing. Each point's rays are its own (seeded by patch, point and
//! target), so the points read hold the same values bit for bit whichever
//! others are traced.

use super::change::{
    Bundle, Towards, cone_towards, rays_for, receiving_side, targets, trace_bundle,
};
use super::change::{Seen, Target};
use super::still::StillSurfaces;
use crate::objects::VirtualBounds;
use crate::patches::Patches;
use crate::patches::Shape;
use crate::trace::Tracer;
use glam::DVec2;
use glam::DVec3;
use glam::Vec3;
use rayon::prelude::*;

/// Rays from a grid point towards an object that fills its hemisphere
/// (128 lost 1.3% of skill on `whitebox` `cube_far` and doubled the error
/// against a brute-force trace; on the desk's box 64 scored as 256 does).
const MAX_POINT_RAYS: u32 = 256;

/// Most grid cells along a patch's side.
const MAX_CELLS: u32 = 32;

/// A grid's cell, at least this fraction of the patch's distance from
/// the nearest object's sphere (the objects' patch size nearer).
const DISTANCE_CELL: f64 = 0.5;

/// A room patch's grid of points.
#[derive(Debug, Clone, PartialEq)]
struct Grid {
    patch: u32,
    /// Cells along each side: (cells + 1)² points.
    cells: u32,
    /// Per point: its taper in \[0, 1\] and its range in `seen`.
    points: Vec<(f64, u32, u32)>,
    /// Per point traced, per target: (surface, range in `seen`); point
    /// `i`'s from `bundle_start[i]` (what an update keeps, see
    /// [`StillSurfaces`]).
    bundles: Vec<(u32, u32, u32)>,
    bundle_start: Vec<u32>,
}

impl Grid {
    /// Point `i`'s bundle towards `surface`, as a range in the view's `seen`.
    fn bundle(&self, i: usize, surface: u32) -> Option<std::ops::Range<usize>> {
        let (a, b) = (*self.bundle_start.get(i)?, *self.bundle_start.get(i + 1)?);
        (self.bundles[a as usize..b as usize].iter())
            .find(|(s, _, _)| *s == surface)
            .map(|&(_, x, y)| x as usize..y as usize)
    }
}

/// What the grid points of the room's patches near the objects see of them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NearView {
    grids: Vec<Grid>,
    seen: Vec<Seen>,
    /// Rays traced.
    pub rays: u64,
    /// Bundles kept from the last pose rather than traced.
    pub kept: u64,
}

/// The change at the grid points, less the patch means' interpolation.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NearField {
    /// Per room patch, its grid in `grids` (u32::MAX: none).
    index: Vec<u32>,
    grids: Vec<(Shape, u32, Vec<DVec3>)>,
}

/// The points of the room's patches at which the field is read: per
/// patch, the points of the pixels that show it and no object.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReadPoints {
    /// Per room patch, its points' range in `points` (None: every point
    /// of every patch is read).
    start: Option<Vec<u32>>,
    points: Vec<Vec3>,
    patch_count: usize,
}

impl ReadPoints {
    /// Every point of each of `patch_count` room patches.
    pub fn everywhere(patch_count: usize) -> ReadPoints {
        ReadPoints {
            start: None,
            points: Vec::new(),
            patch_count,
        }
    }

    /// The points `points` yields (room patch, point), over `patch_count`
    /// patches. `points` is called twice and must yield the same both times
    /// (a count per patch, then the points in place: no list of pairs).
    pub fn of<I: Iterator<Item = (u32, Vec3)>>(
        patch_count: usize,
        points: impl Fn() -> I,
    ) -> ReadPoints {
        let mut start = vec![0u32; patch_count + 1];
        for (k, _) in points() {
            if let Some(c) = start.get_mut(k as usize + 1) {
                *c += 1;
            }
        }
        for k in 0..patch_count {
            start[k + 1] += start[k];
        }
        let mut next = start.clone();
        let mut held = vec![Vec3::ZERO; start[patch_count] as usize];
        for (k, x) in points() {
            if let Some(at) = next
                .get_mut(k as usize)
                .filter(|_| (k as usize) < patch_count)
            {
                held[*at as usize] = x;
                *at += 1;
            }
        }
        ReadPoints {
            start: Some(start),
            points: held,
            patch_count,
        }
    }

    /// Patch `k`'s points (None: all of them).
    fn on(&self, k: usize) -> Option<&[Vec3]> {
        let start = self.start.as_ref()?;
        Some(&self.points[start[k] as usize..start[k + 1] as usize])
    }

    /// Whether any point of patch `k` is read.
    fn any(&self, k: usize) -> bool {
        self.on(k).is_none_or(|p| !p.is_empty())
    }
}

impl NearView {
    /// Grids on the room's patches (the first of `patches`) where `read`
    /// holds a point, that lie within twice an object's radius of its
    /// bounding sphere, points `cell` apart (no finer than the patch, at
    /// most 32 cells a side); traced at the points whose cells hold one
    /// of `read`'s.
    pub fn trace(
        patches: &Patches,
        read: &ReadPoints,
        tracer: &Tracer,
        objects: &VirtualBounds,
        cell: f64,
    ) -> NearView {
        NearView::trace_keeping(patches, read, tracer, (objects, cell), None)
    }

    /// [`NearView::trace`] (`objects` and `cell` as there), keeping from
    /// `last` (the view of the pose before) the bundles `still` says a
    /// fresh trace would give again.
    pub fn trace_keeping(
        patches: &Patches,
        read: &ReadPoints,
        tracer: &Tracer,
        (objects, cell): (&VirtualBounds, f64),
        last: Option<(&NearView, &StillSurfaces)>,
    ) -> NearView {
        let targets = targets(objects);
        let near = Near {
            patches,
            targets: &targets,
            tracer,
            cell,
        };
        let mut last_grid = vec![u32::MAX; read.patch_count];
        for (g, grid) in last.iter().flat_map(|(v, _)| v.grids.iter().enumerate()) {
            if let Some(slot) = last_grid.get_mut(grid.patch as usize) {
                *slot = g as u32;
            }
        }
        let grids: Vec<(Grid, Vec<Seen>, (u64, u64))> = (0..read.patch_count)
            .into_par_iter()
            .filter(|&k| read.any(k))
            .filter_map(|k| {
                let kept = last.and_then(|(view, still)| {
                    let grid = view.grids.get(last_grid[k] as usize)?;
                    Some(Kept { view, grid, still })
                });
                grid_of(&near, k, read.on(k), kept)
            })
            .collect();
        let mut view = NearView::default();
        for (mut grid, seen, (rays, kept)) in grids {
            let base = view.seen.len() as u32;
            for p in &mut grid.points {
                (p.1, p.2) = (p.1 + base, p.2 + base);
            }
            for b in &mut grid.bundles {
                (b.1, b.2) = (b.1 + base, b.2 + base);
            }
            view.seen.extend(seen);
            view.grids.push(grid);
            view.rays += rays;
            view.kept += kept;
        }
        view
    }

    /// Which of the first `room_count` of `patches` may hold a grid near
    /// `objects` (no other patch's points are read).
    pub fn patches_near(
        patches: &Patches,
        room_count: usize,
        objects: &VirtualBounds,
    ) -> Vec<bool> {
        let targets = targets(objects);
        (0..room_count)
            .map(|k| targets.iter().any(|t| reaches(patches.patch(k), t)))
            .collect()
    }

    pub fn memory_bytes(&self) -> usize {
        self.grids
            .iter()
            .map(|g| {
                g.points.len() * std::mem::size_of::<(f64, u32, u32)>()
                    + g.bundles.len() * std::mem::size_of::<(u32, u32, u32)>()
                    + g.bundle_start.len() * 4
            })
            .sum::<usize>()
            + self.seen.len() * std::mem::size_of::<Seen>()
    }

    /// The field for radiosity `radiosity` (room and objects), the room's
    /// radiosity without them `room`, and `coarse`, the patch means'
    /// change ([`ObjectView::irradiance_change`](super::ObjectView::irradiance_change)) as vertex values of the
    /// room's patches.
    pub fn field(
        &self,
        patches: &Patches,
        radiosity: &[DVec3],
        room: &[DVec3],
        coarse: &[DVec3],
    ) -> NearField {
        let mut index = vec![u32::MAX; room.len()];
        let grids = (self.grids.iter().enumerate())
            .map(|(g, grid)| {
                index[grid.patch as usize] = g as u32;
                let k = grid.patch as usize;
                let el = patches.patch(k);
                // A triangle's fourth vertex is unused (and may be none).
                let corners = (patches.patch_vertices[k])
                    .map(|v| coarse.get(v as usize).copied().unwrap_or(DVec3::ZERO));
                let n = grid.cells;
                let values = (grid.points.iter().enumerate())
                    .map(|(i, &(taper, a, b))| {
                        if taper == 0.0 {
                            return DVec3::ZERO;
                        }
                        let st = grid_params(i as u32, n, &el.shape);
                        let point: DVec3 = (self.seen[a as usize..b as usize].iter())
                            .map(|s| {
                                let behind = room.get(s.behind as usize).copied();
                                (radiosity[s.object as usize] - behind.unwrap_or(DVec3::ZERO))
                                    * f64::from(s.weight)
                            })
                            .sum::<DVec3>()
                            / std::f64::consts::PI;
                        (point - interpolate_corners(&el.shape, &corners, st)) * taper
                    })
                    .collect();
                (el.shape, n, values)
            })
            .collect();
        NearField { index, grids }
    }
}

impl NearField {
    /// The correction to the interpolated indirect irradiance at point `x`
    /// of room patch `patch`; None where the patch holds no grid.
    pub fn at(&self, patch: u32, x: DVec3) -> Option<DVec3> {
        let g = *self.index.get(patch as usize)?;
        let (shape, n, values) = self.grids.get(g as usize)?;
        let ((i, j), (fs, ft)) = cell_at(shape, *n, x)?;
        let at = |i: u32, j: u32| values[(j * (n + 1) + i) as usize];
        Some(
            (at(i, j) * (1.0 - fs) + at(i + 1, j) * fs) * (1.0 - ft)
                + (at(i, j + 1) * (1.0 - fs) + at(i + 1, j + 1) * fs) * ft,
        )
    }

    /// A field of `room_count` patches whose grids (one cell, zero
    /// everywhere) lie on `patches`: for tests of who reads it.
    #[cfg(test)]
    pub(crate) fn zero_on(room_count: usize, patches: &[usize]) -> NearField {
        let mut index = vec![u32::MAX; room_count];
        let square = Shape::Quad {
            origin: DVec3::ZERO,
            u: DVec3::X,
            v: DVec3::Y,
        };
        let grids = (patches.iter().enumerate())
            .map(|(g, &k)| {
                index[k] = g as u32;
                (square, 1, vec![DVec3::ZERO; 4])
            })
            .collect();
        NearField { index, grids }
    }

    /// The room patches that hold a grid.
    pub fn patches(&self) -> impl Iterator<Item = usize> + '_ {
        (self.index.iter().enumerate())
            .filter(|(_, g)| **g != u32::MAX)
            .map(|(k, _)| k)
    }

    /// How many room patches hold a grid.
    pub fn patch_count(&self) -> usize {
        self.grids.len()
    }

    pub fn memory_bytes(&self) -> usize {
        self.index.len() * 4
            + (self.grids.iter())
                .map(|g| g.2.len() * std::mem::size_of::<DVec3>())
                .sum::<usize>()
    }
}

/// The cell of a grid of `n` cells a side over `shape` that holds point
/// `x` (its lower corner's column and row) and where in it; None where a
/// sliver patch's parameters are not finite (no correction there). One
/// function for the reading and for which points are traced.
fn cell_at(shape: &Shape, n: u32, x: DVec3) -> Option<((u32, u32), (f64, f64))> {
    let st = Some(shape.params(x)).filter(|st| st.is_finite())?;
    let st = st.clamp(DVec2::ZERO, DVec2::ONE) * n as f64;
    let (i, j) = (
        (st.x.floor() as u32).min(n - 1),
        (st.y.floor() as u32).min(n - 1),
    );
    Some(((i, j), (st.x - i as f64, st.y - j as f64)))
}

/// Which of the (n + 1)² points of a grid of `n` cells a side over `shape`
/// are read at `read`'s points: the corners of the cells that hold one.
fn read_corners(shape: &Shape, n: u32, read: &[Vec3]) -> Vec<bool> {
    let mut used = vec![false; ((n + 1) * (n + 1)) as usize];
    for x in read {
        if let Some(((i, j), _)) = cell_at(shape, n, x.as_dvec3()) {
            for (a, b) in [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)] {
                used[(b * (n + 1) + a) as usize] = true;
            }
        }
    }
    used
}

/// How far patch `el`'s nearest point may be from target `t`'s sphere.
fn gap(el: &crate::patches::Element, t: &Target) -> f64 {
    let h = (el.shape.corners().iter())
        .map(|c| (*c - el.centre).length())
        .fold(0.0, f64::max);
    ((t.centre - el.centre).length() - h - t.radius).max(0.0)
}

/// Whether target `t` is near enough patch `el` for a grid there.
fn reaches(el: &crate::patches::Element, t: &Target) -> bool {
    gap(el, t) < 2.0 * t.radius
}

/// Point `i`'s parameters on a grid of `n` cells a side over `shape`
/// (a triangle's points beyond its hypotenuse moved onto it).
fn grid_params(i: u32, n: u32, shape: &Shape) -> DVec2 {
    let st = DVec2::new((i % (n + 1)) as f64, (i / (n + 1)) as f64) / n as f64;
    match shape {
        Shape::Tri(_) if st.x + st.y > 1.0 => st / (st.x + st.y),
        _ => st,
    }
}

/// The point of `shape` at parameters `st`.
fn shape_point(shape: &Shape, st: DVec2) -> DVec3 {
    match *shape {
        Shape::Quad { origin, u, v } => origin + u * st.x + v * st.y,
        Shape::Tri([a, b, c]) => a + (b - a) * st.x + (c - a) * st.y,
    }
}

/// Vertex values at a patch's corners interpolated at `st`, as the room's
/// pixels interpolate them (bilinear on a quad, barycentric on a triangle).
fn interpolate_corners(shape: &Shape, c: &[DVec3; 4], st: DVec2) -> DVec3 {
    let (s, t) = (st.x, st.y);
    match shape {
        Shape::Quad { .. } => {
            c[0] * ((1.0 - s) * (1.0 - t))
                + c[1] * (s * (1.0 - t))
                + c[2] * (s * t)
                + c[3] * ((1.0 - s) * t)
        }
        Shape::Tri(_) => c[0] * (1.0 - s - t) + c[1] * s + c[2] * t,
    }
}

/// How much of the point correction is kept at `x`: all within one radius
/// of a target's sphere, none beyond two (smoothly between).
pub(super) fn taper(x: DVec3, targets: &[Target]) -> f64 {
    (targets.iter())
        .map(|t| {
            let d = ((x - t.centre).length() - t.radius).max(0.0) / t.radius.max(1e-9);
            let u = (d - 1.0).clamp(0.0, 1.0);
            1.0 - u * u * (3.0 - 2.0 * u)
        })
        .fold(0.0, f64::max)
}

/// The last pose's grid on a patch, what a new trace of it may keep.
#[derive(Clone, Copy)]
struct Kept<'a> {
    view: &'a NearView,
    grid: &'a Grid,
    still: &'a StillSurfaces,
}

/// What every patch's grid reads: the patches, the objects' targets, the
/// tracer and the finest cell.
struct Near<'a> {
    patches: &'a Patches,
    targets: &'a [Target],
    tracer: &'a Tracer,
    cell: f64,
}

/// Patch `k`'s grid, its rays' hits and the rays traced; None where no
/// target is near enough or the patch is no larger than a cell. Traced at
/// the points whose cells hold one of `read` (None: at every point); the
/// others hold nothing (taper 0). Bundles `kept` says are unchanged are
/// copied rather than traced.
fn grid_of(
    near_input: &Near,
    k: usize,
    read: Option<&[Vec3]>,
    kept: Option<Kept>,
) -> Option<(Grid, Vec<Seen>, (u64, u64))> {
    let Near {
        patches,
        targets,
        tracer,
        cell,
    } = *near_input;
    let el = patches.patch(k);
    let near = |t: &Target| reaches(el, t);
    if !targets.iter().any(near) {
        return None;
    }
    let side = match el.shape {
        Shape::Quad { u, v, .. } => u.length().max(v.length()),
        Shape::Tri([a, b, c]) => (b - a).length().max((c - a).length()),
    };
    // The change varies over distances like the patch's from the object:
    // farther patches take coarser cells.
    let from = (targets.iter().filter(|t| near(t)))
        .map(|t| gap(el, t))
        .fold(f64::INFINITY, f64::min);
    let cell = cell.max(DISTANCE_CELL * from);
    let cells = ((side / cell).ceil() as u32).min(MAX_CELLS);
    if cells < 2 {
        return None;
    }
    let used = read.map(|read| read_corners(&el.shape, cells, read));
    // The last grid on this patch, when it has the same points.
    let kept = kept.filter(|kept| kept.grid.cells == cells);
    let (mut seen, mut bundles, mut bundle_start) = (Vec::new(), Vec::new(), Vec::new());
    let (mut rays, mut kept_here) = (0, 0);
    let points = (0..(cells + 1) * (cells + 1))
        .map(|i| {
            let x = shape_point(&el.shape, grid_params(i, cells, &el.shape));
            let w = match used.as_ref().is_none_or(|u| u[i as usize]) {
                true => taper(x, targets),
                false => 0.0,
            };
            let a = seen.len() as u32;
            bundle_start.push(bundles.len() as u32);
            if w > 0.0 {
                for t in targets {
                    let b = seen.len() as u32;
                    // The bundle the pose before traced towards a surface that stood still.
                    let old = kept.and_then(|kept| {
                        let range = (kept.still.is_still(t.surface))
                            .then(|| kept.grid.bundle(i as usize, t.surface));
                        Some((&kept.view.seen[range.flatten()?], kept.still))
                    });
                    match old {
                        Some((old, still))
                            if still.keeps(x, 0.0, t)
                                || still.cone_clear(x, 0.0, cone_towards(x, 0.0, t), t) =>
                        {
                            seen.extend(old.iter().map(|s| still.renumbered(t.surface, *s)));
                            kept_here += 1;
                        }
                        _ => {
                            if let Some(bundle) = point_rays(patches, (k, i), x, t) {
                                rays += trace_bundle(patches, &bundle, t, tracer, old, &mut seen);
                                kept_here += old.is_some() as u64;
                            }
                        }
                    }
                    bundles.push((t.surface, b, seen.len() as u32));
                }
            }
            (w, a, seen.len() as u32)
        })
        .collect();
    bundle_start.push(bundles.len() as u32);
    Some((
        Grid {
            patch: k as u32,
            cells,
            points,
            bundles,
            bundle_start,
        },
        seen,
        (rays, kept_here),
    ))
}

/// The bundle of rays from point `x` (grid point `i` of room patch `k`)
/// towards target `t`; None when `t` is behind the patch.
fn point_rays(patches: &Patches, (k, i): (usize, u32), x: DVec3, t: &Target) -> Option<Bundle> {
    let n = receiving_side(patches.patch(k), t)?;
    let cone = cone_towards(x, 0.0, t);
    let count = rays_for(cone.1, MAX_POINT_RAYS);
    let seed = crate::util::rng::hash2(
        crate::util::rng::hash2(k as u64, i as u64),
        t.surface as u64,
    ) as u32;
    let towards = Towards::new(n, cone, count);
    let rays = (0..count)
        .map(|r| {
            let [u1, u2, _, _] = sobol_burley::sample_4d(r, 0, seed).map(f64::from);
            let (d, w) = towards.at(u1, u2);
            (x, d, w)
        })
        .collect();
    Some(Bundle { n, rays })
}
