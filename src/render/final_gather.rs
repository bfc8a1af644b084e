//! Final gathering at the virtual objects' vertices: their indirect light
//! gathered from the photograph and the radiosity, shared between nearby
//! vertices that face alike.

use super::*;

/// What final gathering reads.
pub(super) struct Gather<'a> {
    pub(super) camera: &'a crate::camera::Camera,
    pub(super) tracer: &'a crate::trace::Tracer,
    /// The room's patches and then the objects'.
    pub(super) patches: &'a Patches,
    /// Vertices from this one on are the objects'.
    pub(super) real_vertices: usize,
    pub(super) photo: &'a Image,
    /// Radiosity per patch with the changes, and in the photo's model.
    pub(super) radiosity_with: &'a [DVec3],
    pub(super) radiosity_without: &'a [DVec3],
    /// Rays per vertex.
    pub(super) rays: u32,
    /// How far apart vertices may be and still share one gather (see
    /// [`shared_gathers`]): a quarter of the objects' patch size (2.5 cm: a tenth gathered at
    /// 1.9 times as many of the stool's vertices for the same skill on
    /// every object variant; half lost 0.6% on the vase).
    pub(super) share_within: f64,
    /// Object surfaces (sorted ids) whose pixels read no light of their
    /// vertices: metals, shaded per pixel with no diffuse part.
    pub(super) bounce_only: &'a [u32],
}

/// The largest angle between two vertices' normals that still share a
/// gather: the facets of a finely tessellated curved surface meet at a
/// point with normals a few degrees apart and gather nearly the same
/// light, where a coarse one's (the 20 × 40 ball's 9°, a 16-sided leg's
/// 22.5°) keep their own.
pub(super) const SHARE_ANGLE_DEG: f64 = 5.0;

/// Which vertices gather their own light and which share others' gathers.
/// Taken in order, a vertex gathers unless an earlier gathering vertex of
/// the same side lies within `within` and [`SHARE_ANGLE_DEG`] of it; one
/// that does not gather takes every such vertex's light, weighted as in
/// Ward's irradiance caching (1 / (distance / within + √(1 − n·n'))).
/// The light gathered grows with the object's area and curvature, not
/// with its triangles: a subdivided ball gathers at about as many points
/// as a coarse one. Serial and in vertex order, so that the choice is the
/// same whatever the thread count. Returns, per vertex, the gathering
/// vertices it takes and their weights (none: it gathers itself).
pub(super) fn shared_gathers(
    patches: &Patches,
    vertices: &[(u32, DVec3, u32)],
    within: f64,
) -> Shares {
    if within <= 0.0 {
        return Shares {
            start: vec![0; vertices.len() + 1],
            taken: Vec::new(),
        };
    }
    use rayon::prelude::*;
    let cos_max = SHARE_ANGLE_DEG.to_radians().cos();
    // The weight vertex `i` gives gathering vertex `j` (None: too far or
    // facing too differently to share).
    let weight = |i: usize, j: u32| {
        let ((v, n, side), (w, m, other_side)) = (vertices[i], vertices[j as usize]);
        // The side and the normals first: most candidates near a crease
        // or a thin part's far face fail them, and need no distance.
        let cos = n.dot(m);
        let alike = other_side == side && cos >= cos_max;
        if !alike {
            return None;
        }
        let d = (patches.vertices[w as usize] - patches.vertices[v as usize]).length();
        (d <= within).then(|| 1.0 / (d / within + (1.0 - cos).max(0.0).sqrt()).max(1e-9))
    };
    // Which vertices gather, in order (serial: each choice reads the ones
    // before). Each gathering vertex is listed in the 27 cells around its
    // own, so a vertex finds every candidate within `within` in its own
    // cell's list: one lookup per vertex (an 80k-triangle object has 160k
    // vertices and under 2k gathers). The lists are a grid's, not a map of
    // small lists: beside a still 2 m table (31,753 vertices, 7,624
    // gathers) the sharing took 14–22 ms a step with the map, 4.5–6.8 ms
    // with the grid.
    let at = |i: usize| patches.vertices[vertices[i].0 as usize];
    let mut near = crate::util::near_lists::NearLists::new((0..vertices.len()).map(at), within);
    let mut gathers = vec![false; vertices.len()];
    for (i, gathering) in gathers.iter_mut().enumerate() {
        if near.near(at(i)).any(|j| weight(i, j).is_some()) {
            continue;
        }
        *gathering = true;
        near.add_near(at(i), i as u32);
    }
    // Then, side by side in runs of vertices, what each other vertex
    // takes: the gathering vertices before it within reach (those after
    // it gathered knowing it did not), in order. Held in one list, not a
    // list per vertex: an 80k-triangle object's 160k vertices each took
    // a small allocation.
    // Per run: each vertex's count, and their entries.
    type Run = (Vec<u32>, Vec<(u32, f64)>);
    let runs: Vec<Run> = (0..vertices.len().div_ceil(SHARE_RUN))
        .into_par_iter()
        .map(|r| {
            let run = r * SHARE_RUN..vertices.len().min((r + 1) * SHARE_RUN);
            let (mut counts, mut taken) = (Vec::with_capacity(run.len()), Vec::new());
            for i in run {
                let before = taken.len();
                if !gathers[i] {
                    taken.extend(
                        near.near(at(i))
                            .take_while(|&j| (j as usize) < i)
                            .filter_map(|j| weight(i, j).map(|w| (j, w))),
                    );
                }
                counts.push((taken.len() - before) as u32);
            }
            (counts, taken)
        })
        .collect();
    let mut start = Vec::with_capacity(vertices.len() + 1);
    start.push(0u32);
    let mut taken = Vec::with_capacity(runs.iter().map(|r| r.1.len()).sum());
    for (counts, run) in runs {
        for c in counts {
            start.push(start[start.len() - 1] + c);
        }
        taken.extend(run);
    }
    Shares { start, taken }
}

/// Vertices per run that [`shared_gathers`] lists side by side.
const SHARE_RUN: usize = 4096;

/// Per vertex, the gathering vertices it takes light from and their
/// weights (by their place among the vertices gathered for); none for a
/// vertex that gathers itself.
pub(super) struct Shares {
    /// Vertex `i`'s entries are `taken[start[i]..start[i + 1]]`.
    start: Vec<u32>,
    taken: Vec<(u32, f64)>,
}

impl Shares {
    /// What vertex `i` takes (empty: it gathers).
    pub(super) fn of(&self, i: usize) -> &[(u32, f64)] {
        &self.taken[self.start[i] as usize..self.start[i + 1] as usize]
    }

    pub(super) fn len(&self) -> usize {
        self.start.len() - 1
    }
}

/// A vertex's light from the gathers it shares (see [`shared_gathers`]):
/// the weighted mean, and for the bounces between objects the nearest
/// one's rays (`rank`: a gathering vertex's place among the gathers).
fn shared_light<'a>(
    vertex: u32,
    taken: &[(u32, f64)],
    of: &impl Fn(u32) -> &'a Gathered,
    rank: &impl Fn(u32) -> u32,
) -> Gathered {
    let total: f64 = taken.iter().map(|t| t.1).sum();
    let mean = |f: &dyn Fn(&Gathered) -> DVec3| -> DVec3 {
        taken.iter().map(|&(j, w)| f(of(j)) * w).sum::<DVec3>() / total
    };
    let nearest = taken
        .iter()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .expect("a shared gather")
        .0;
    Gathered {
        vertex,
        irradiance: mean(&|g| g.irradiance),
        from_room: mean(&|g| g.from_room),
        objects_of: rank(nearest),
    }
}

/// Indirect irradiance at the virtual objects' vertices gathered from the
/// photograph (final gathering, Grosch §4 after Loscos): `rays` cosine-
/// distributed rays per vertex; where one meets a real surface the camera
/// sees, the light leaving it is the photo's pixel there, times the change
/// the objects make to that patch's radiosity (with / without); elsewhere
/// the radiosity solution's B/π. Returns (vertex, irradiance) pairs.
pub(super) fn final_gather(g: &Gather, directions: &mut GatherDirections) -> Gathers {
    use rayon::prelude::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    let vertices = gather_vertices(g);
    let shares = shared_gathers(g.patches, &vertices, g.share_within);
    // The gathering vertices, by their place in `vertices` (ascending).
    let gathering: Vec<usize> = (0..vertices.len())
        .filter(|&i| shares.of(i).is_empty())
        .collect();
    let clear_of_object = object_clearance(g.patches, gathering.len());
    if directions.kept {
        let own: Vec<(u32, DVec3, u32)> = gathering.iter().map(|&i| vertices[i]).collect();
        directions.keep(&own);
    }
    // Each gathering vertex's rays of the last pose, taken rather than
    // copied (beside a still 2 m table, 4,649 kept vertices copied up to 27 MB an
    // update); the map is filled again below.
    let mut last = std::mem::take(&mut directions.traced);
    let with_old: Vec<(usize, Option<Traced>)> = (gathering.iter())
        .map(|&i| {
            let (v, n, side) = vertices[i];
            let old = (directions.since.as_ref())
                .and_then(|_| last.remove(&GatherDirections::key(v, n, side)));
            (i, old)
        })
        .collect();
    drop(last);
    let keeping = directions.kept;
    let kept = &*directions;
    let (reused, partly) = (AtomicUsize::new(0), AtomicUsize::new(0));
    // The gathers, and beside them (kept by a session) their rays: one
    // pointer per gathering vertex where no session keeps them. Held for
    // the gathering vertices alone: an 80k-triangle object has 160k
    // vertices and under 2k gathers.
    type Own = ((Gathered, Met), Option<Box<Traced>>);
    type Kept = Vec<Option<Box<Traced>>>;
    let (own, traced): (Vec<(Gathered, Met)>, Kept) = (with_old.into_par_iter())
        .enumerate()
        .map(|(rank, (i, old))| -> Own {
            let (v, n, side) = vertices[i];
            let p = g.patches.vertices[v as usize];
            let layer = if clear_of_object(p, n) {
                Layer::Real
            } else {
                Layer::All
            };
            let dirs = kept.of(v, n, side);
            // Faces are one-sided here (solids face out, open surfaces face the camera).
            let origin = crate::light::offset_origin(p, n, p + n);
            let again = (kept.since.as_ref())
                .zip(old)
                .and_then(|(since, old)| old.kept(origin, layer, &dirs, since));
            let traced = match again {
                Some((traced, redo)) if redo.is_empty() => {
                    reused.fetch_add(1, Ordering::Relaxed);
                    traced
                }
                Some((mut traced, redo)) => {
                    // The rays a moved object may cross traced again, the rest kept.
                    partly.fetch_add(1, Ordering::Relaxed);
                    let some: Vec<DVec3> = redo.iter().map(|&i| dirs[i]).collect();
                    traced.replace(&redo, trace_at(g, origin, &some, layer));
                    traced
                }
                None => trace_at(g, origin, &dirs, layer),
            };
            let (gathered, met) = sum_at(g, v, &traced);
            let gathered = Gathered {
                objects_of: rank as u32,
                ..gathered
            };
            ((gathered, met), keeping.then(|| Box::new(traced)))
        })
        .unzip();
    (directions.reused, directions.partly) = (reused.into_inner(), partly.into_inner());
    for (t, &i) in traced.into_iter().zip(&gathering) {
        if let Some(t) = t {
            let (v, n, side) = vertices[i];
            directions
                .traced
                .insert(GatherDirections::key(v, n, side), *t);
        }
    }
    // Every vertex's light, allocated once at its size: a gathering
    // vertex's own, the others' shared.
    let rank = |j: u32| -> u32 {
        let k = gathering
            .binary_search(&(j as usize))
            .expect("a gathering vertex");
        k as u32
    };
    let of = |j: u32| -> &Gathered { &own[rank(j) as usize].0 };
    let each: Vec<Gathered> = (0..shares.len())
        .into_par_iter()
        .map(|i| match shares.of(i) {
            [] => own[rank(i as u32) as usize].0,
            taken => shared_light(vertices[i].0, taken, &of, &rank),
        })
        .collect();
    let met = own.into_iter().map(|(_, m)| m).collect();
    Gathers { each, met }
}

/// Each virtual vertex with the normal of the plane it lies in and its
/// strata per side.
fn gather_vertices(g: &Gather) -> Vec<(u32, DVec3, u32)> {
    let patches = g.patches;
    // By vertex from the first of the objects' (dense: an object has as
    // many vertices as corners of its patches); the first patch's normal.
    let first = g.real_vertices;
    let mut normal_of: Vec<Option<(DVec3, u32)>> =
        vec![None; patches.vertices.len().saturating_sub(first)];
    for (k, ids) in patches.patch_vertices.iter().enumerate() {
        for &v in ids
            .iter()
            .filter(|&&v| v != u32::MAX && v as usize >= first)
        {
            let n = &mut normal_of[v as usize - first];
            if n.is_none() {
                let patch = patches.patch(k);
                *n = Some((patch.normal, patch.surface));
            }
        }
    }
    // A vertex on a face turned from the camera shows in no pixel: its
    // light reaches the image only through what it sends the room, a small
    // part of the room's own indirect light, and a quarter of the rays
    // estimate it well enough (the box's hidden faces: half its vertices).
    // So does a metal's vertex, whose pixels have no diffuse part to read
    // it (the chrome ball's update 62 -> 56 ms, its skills within 1e-5).
    let side = (g.rays as f64).sqrt().ceil() as u32;
    let hidden_side = side.div_ceil(2);
    // Normals rounded to 2^-16: a moved object's are recomputed from its
    // moved single-precision corners and differ by ~1e-7 from pose to pose,
    // and the directions (kept per vertex and normal) would never be found
    // again. The rounding turns the hemisphere by at most ~1e-5 rad.
    let steady = |n: DVec3| ((n * 65536.0).round() / 65536.0).normalize();
    normal_of
        .into_iter()
        .enumerate()
        .filter_map(|(i, n)| Some(((i + first) as u32, n?)))
        .map(|(v, (n, surface))| {
            let faces_camera = n.dot(g.camera.position - patches.vertices[v as usize]) > 0.0;
            let shown = faces_camera && g.bounce_only.binary_search(&surface).is_err();
            (v, steady(n), if shown { side } else { hidden_side })
        })
        .collect()
}

/// Whether a vertex's rays may skip the objects: a ray leaving a face that
/// its whole solid lies behind cannot meet that solid (it starts in front
/// of the plane and moves away), so with no other object such a vertex
/// traces the room alone.
fn object_clearance(patches: &Patches, vertices: usize) -> impl Fn(DVec3, DVec3) -> bool + Sync {
    let object_roots: Vec<&crate::patches::Element> = patches
        .roots
        .iter()
        .filter(|&&r| patches.is_virtual_element(r))
        .map(|&r| &patches.elements[r as usize])
        .collect();
    let one_object = object_roots
        .windows(2)
        .all(|w| w[0].surface == w[1].surface);
    let count: usize = object_roots.iter().map(|e| e.shape.corners().len()).sum();
    let test = one_object && vertices * count <= CLEAR_TEST_LIMIT;
    // The corners only where they are tested (an 80k-triangle object's
    // would hold 6 MB for nothing).
    let corners: Vec<DVec3> = match test {
        true => (object_roots.iter())
            .flat_map(|e| e.shape.corners().to_vec())
            .collect(),
        false => Vec::new(),
    };
    move |p: DVec3, n: DVec3| test && crate::gather::clear_of_solid(&corners, p, n)
}

/// What a virtual vertex gathered: the irradiance from the room (and,
/// at first, from the objects as the first solve left them), and whose
/// rays its bounces between objects read.
#[derive(Debug, Default, Clone, Copy)]
pub(super) struct Gathered {
    pub(super) vertex: u32,
    /// Whose rays this vertex's bounces read: its own, or for a vertex
    /// that shares gathers the nearest one's (by its place in
    /// [`Gathers::met`]).
    pub(super) objects_of: u32,
    pub(super) irradiance: DVec3,
    /// The room's part of `irradiance`.
    pub(super) from_room: DVec3,
}

/// A gathering vertex's rays as the bounces between objects read them:
/// the object patches they met, one entry per ray that met one, of `rays`.
#[derive(Debug, Default)]
pub(super) struct Met {
    pub(super) objects: Vec<u32>,
    pub(super) rays: u32,
}

/// Every virtual vertex's light (in the order of their vertices), and per
/// gathering vertex, in order, what its rays met.
#[derive(Debug, Default)]
pub(super) struct Gathers {
    pub(super) each: Vec<Gathered>,
    pub(super) met: Vec<Met>,
}

/// A gathering vertex's rays as traced: where each landed, and the
/// photo's radiance there where the landing point is real and the camera
/// sees it (a session keeps them for the next pose).
#[derive(Debug, Clone)]
pub(super) struct Traced {
    origin: DVec3,
    layer: Layer,
    landed: Vec<Option<Landed>>,
    /// Per ray: pixels of the photo, single precision as it holds them.
    seen: Vec<Option<glam::Vec3>>,
}

/// Where a gather ray landed: the point (single precision: kept for the
/// test against the objects that move, which allows a millimetre), its
/// patch, and the object surface it lies on (`u32::MAX`: the room).
#[derive(Debug, Clone, Copy)]
struct Landed {
    at: glam::Vec3,
    patch: u32,
    object: u32,
}

impl Landed {
    fn on_object(&self) -> bool {
        self.object != u32::MAX
    }
}

/// How far a ray that met nothing is checked against the objects that moved.
const FAR: f64 = 1e4;

impl Traced {
    /// These rays at this pose, where they are as they were: the vertex is
    /// where it was and traces the same layer; the rays that see the
    /// objects are kept where no object that moved (`since`) comes near
    /// them, the patches met on still objects renumbered as this pose
    /// numbers them. Returns them with the rays to trace again (by their
    /// place in `dirs`): a ray kept lands where a fresh one would, and the
    /// photo's radiances, read through the room alone, stand. None where
    /// no ray can be kept.
    fn kept(
        mut self,
        origin: DVec3,
        layer: Layer,
        dirs: &[DVec3],
        since: &crate::radiosity::StillSurfaces,
    ) -> Option<(Traced, Vec<usize>)> {
        // The directions are the vertex's own (its number, normal and
        // strata, the key it was kept under).
        if self.origin != origin || self.layer != layer || self.landed.len() != dirs.len() {
            return None;
        }
        if layer == Layer::Real {
            return Some((self, Vec::new()));
        }
        let redo: Vec<usize> = (self.landed.iter().zip(dirs).enumerate())
            .filter(|(_, (l, d))| {
                let end = l.map_or(origin + **d * FAR, |l| l.at.as_dvec3());
                !since.clear_of_movers(origin, end)
            })
            .map(|(i, _)| i)
            .collect();
        // Every ray near a mover: nothing to keep (a fresh trace, no copy).
        if !redo.is_empty() && redo.len() == dirs.len() {
            return None;
        }
        for (i, l) in self.landed.iter_mut().enumerate() {
            match l {
                Some(l) if l.on_object() && redo.binary_search(&i).is_err() => {
                    let shift = since.patch_shift(l.object)?;
                    l.patch = u32::try_from(l.patch as i64 + shift).ok()?;
                }
                _ => {}
            }
        }
        Some((self, redo))
    }

    /// Puts `fresh`, the rays at places `at` traced again, in their places.
    fn replace(&mut self, at: &[usize], fresh: Traced) {
        for ((&i, l), s) in at.iter().zip(fresh.landed).zip(fresh.seen) {
            self.landed[i] = l;
            self.seen[i] = s;
        }
    }
}

/// Traces the rays along `dirs` from `origin` through `layer`.
fn trace_at(g: &Gather, origin: DVec3, dirs: &[DVec3], layer: Layer) -> Traced {
    use crate::trace::TraceRay;
    let traced: Vec<TraceRay> = dirs
        .iter()
        .map(|d| TraceRay::new(origin.as_vec3(), d.as_vec3()))
        .collect();
    let mut hits = vec![None; traced.len()];
    g.tracer.intersect_batch(&traced, layer, &mut hits);
    // Where each ray lands and on which patch; the real points' photo radiance in one batch.
    let points: Vec<Option<(DVec3, Landed)>> = dirs
        .iter()
        .zip(&hits)
        .map(|(d, hit)| {
            let hit = hit.as_ref()?;
            let y = origin + *d * hit.t as f64;
            let at = g.patches.locate(hit.surface, hit.triangle, y)?;
            let object = if hit.is_virtual {
                hit.surface
            } else {
                u32::MAX
            };
            let landed = Landed {
                at: y.as_vec3(),
                patch: at.patch,
                object,
            };
            Some((y, landed))
        })
        .collect();
    let real: Vec<(usize, DVec3)> = (points.iter().enumerate())
        .filter_map(|(i, p)| p.filter(|(_, l)| !l.on_object()).map(|(y, _)| (i, y)))
        .collect();
    let real_points: Vec<DVec3> = real.iter().map(|r| r.1).collect();
    let mut seen = vec![None; dirs.len()];
    let radiances = crate::gather::photo_radiances(g.camera, g.tracer, g.photo, &real_points);
    for (&(i, _), r) in real.iter().zip(radiances) {
        seen[i] = r.map(|r| r.as_vec3());
    }
    let landed = points.into_iter().map(|p| p.map(|(_, l)| l)).collect();
    Traced {
        origin,
        layer,
        landed,
        seen,
    }
}

/// The irradiance vertex `v`'s rays `traced` gather from the radiosity,
/// and what they met of the objects.
fn sum_at(g: &Gather, v: u32, traced: &Traced) -> (Gathered, Met) {
    let pi = std::f64::consts::PI;
    let (mut sum, mut objects) = (DVec3::ZERO, DVec3::ZERO);
    let mut objects_met = Vec::new();
    for (l, seen) in traced.landed.iter().zip(&traced.seen) {
        let Some(l) = l else { continue };
        let k = l.patch as usize;
        let model = g.radiosity_with[k] / pi;
        if l.on_object() {
            objects += model;
            objects_met.push(k as u32);
            continue;
        }
        // Seen by the camera? Then the photo knows its radiance.
        sum += match seen.map(|r| r.as_dvec3()) {
            Some(radiance) => {
                let ratio = (g.radiosity_with[k] / g.radiosity_without[k].max(DVec3::splat(1e-12)))
                    .min(DVec3::splat(4.0));
                radiance * ratio
            }
            None => model,
        };
    }
    let rays = traced.landed.len();
    let per_ray = pi / rays as f64;
    let gathered = Gathered {
        vertex: v,
        irradiance: (sum + objects) * per_ray,
        from_room: sum * per_ray,
        objects_of: u32::MAX,
    };
    let met = Met {
        objects: objects_met,
        rays: rays as u32,
    };
    (gathered, met)
}
