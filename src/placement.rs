//! Likely placement mistakes, said with numbers before a render: an object
//! the camera cannot see, one sunk into a real surface or passing through
//! another object, one glowing brighter than anything in the photo. The
//! render goes on (the user may mean it); `--strict` makes them errors.
//! `arlux serve` refuses the first two kinds of place outright
//! ([`crate::interactive`]), with the same test ([`cut_into`]).

use glam::DVec3;

use crate::camera::Camera;
use crate::image_io::Image;
use crate::scene::{Pose, Scene, VirtualObject};
use crate::trace::{Layer, TraceRay, Tracer};

/// How deep an object may sink into a surface, as a fraction of its box's
/// diagonal: one standing on a rough model's floor (vertices a few
/// centimetres off) touches it unevenly; one pushed into a wall goes deeper.
pub const TOUCH: f64 = 0.05;
/// Points of an object checked against what it may cut into, at most.
const CHECKED_POINTS: usize = 1024;
/// Camera rays per object when looking for a pixel of it, at most, before
/// every pixel of its box on screen is tried.
const SEEN_RAYS: usize = 65_536;

/// The object's vertices placed by `pose`, in world space.
pub fn object_points<'a>(
    object: &'a VirtualObject,
    pose: &'a Pose,
) -> impl Iterator<Item = DVec3> + 'a {
    (object.surfaces.iter())
        .flat_map(|s| s.triangles.iter().flatten())
        .map(move |&p| pose.apply(p).as_dvec3())
}

/// A surface `layer` of `tracer` holds (other than `own`, the object's
/// own surface ids) that the object cuts into: one crossed by a segment
/// from the centre of its box to one of its vertices or face centres more
/// than [`TOUCH`] of its size before the segment's end. With the deepest
/// such point's depth under that surface (along its normal), metres.
pub fn cut_into(
    tracer: &Tracer,
    layer: Layer,
    object: &VirtualObject,
    own: &[u32],
) -> Option<(u32, f64)> {
    let points: Vec<DVec3> = object_points(object, &object.pose).collect();
    let (lo, hi) = crate::geometry::bounds(points.iter().copied());
    let centre = 0.5 * (lo + hi);
    let depth = TOUCH * (hi - lo).length();
    let centroids = (object.surfaces.iter())
        .flat_map(|s| s.triangles.iter())
        .map(|t| object.pose.apply((t[0] + t[1] + t[2]) / 3.0).as_dvec3());
    let all: Vec<DVec3> = points.iter().copied().chain(centroids).collect();
    let step = all.len().div_ceil(CHECKED_POINTS).max(1);
    let mut deepest: Option<(u32, f64)> = None;
    for p in all.iter().step_by(step) {
        let length = (*p - centre).length();
        if length <= depth {
            continue;
        }
        let end = (1.0 - depth / length) as f32;
        let mut from = 0.0f32;
        // The object's own surfaces may lie across a segment of a concave
        // shape: passed over, up to a few times.
        for _ in 0..8 {
            let ray = TraceRay {
                origin: centre.as_vec3(),
                direction: (*p - centre).as_vec3(),
                tnear: from,
                tfar: end,
            };
            let Some(hit) = tracer.intersect(&ray, layer) else {
                break;
            };
            if !own.contains(&hit.surface) {
                let along = (1.0 - hit.t as f64) * length;
                let depth = along * (*p - centre).normalize().dot(hit.normal.as_dvec3()).abs();
                if deepest.is_none_or(|(_, d)| depth > d) {
                    deepest = Some((hit.surface, depth));
                }
                break;
            }
            from = hit.t + 1e-5;
        }
    }
    deepest
}

/// The enabled objects other than one, as geometry to check that one
/// against: built once and kept while they stay where they are (a drag
/// moves one object; the others' tracer is reused for every step).
pub struct Others {
    /// The object left out, and every other object's pose and whether shown.
    key: (usize, Vec<Option<(Pose, bool)>>),
    tracer: Option<Tracer>,
}

impl Others {
    /// The other object `object` passes through deeper than [`TOUCH`] of
    /// its size, by name, with the depth (metres); `kept` holds the others'
    /// geometry from the last call and is rebuilt when they changed.
    pub fn passed_through(
        kept: &mut Option<Others>,
        scene: &Scene,
        object: usize,
    ) -> crate::error::Result<Option<(String, f64)>> {
        // The moving object's own pose is not part of the key.
        let key = (
            object,
            (scene.objects.iter().enumerate())
                .map(|(i, o)| (i != object).then_some((o.pose, o.enabled)))
                .collect::<Vec<_>>(),
        );
        let ids = surface_ids(scene);
        if kept.as_ref().is_none_or(|k| k.key != key) {
            let others: Vec<(u32, Vec<crate::geometry::Triangle>)> = scene
                .virtual_world_surfaces()
                .into_iter()
                .filter(|(id, _)| !ids[object].contains(id))
                .collect();
            let sets: Vec<crate::trace::SurfaceTriangles> = (others.iter())
                .map(|(id, t)| crate::trace::SurfaceTriangles {
                    surface: *id,
                    triangles: t,
                    mask: None,
                })
                .collect();
            let tracer = match sets.is_empty() {
                true => None,
                false => Some(
                    Tracer::build(&[], &sets)
                        .map_err(|e| crate::error::Error::file(&scene.file, e.to_string()))?,
                ),
            };
            *kept = Some(Others { key, tracer });
        }
        let Some(tracer) = kept.as_ref().and_then(|k| k.tracer.as_ref()) else {
            return Ok(None);
        };
        let hit = cut_into(tracer, Layer::Virtual, &scene.objects[object], &ids[object]);
        Ok(hit.map(|(surface, depth)| {
            let other = object_of(&ids, surface).map_or("another object".to_string(), |o| {
                scene.objects[o].name.clone()
            });
            (other, depth)
        }))
    }
}

/// Where along motion `name` (its poses `poses`) the moving object passes
/// through the room or another object deeper than [`TOUCH`] of its size:
/// one sentence per kind, naming the first such pose and how many there
/// are. Checked before a motion renders (no pose is rendered for it).
pub fn motion_warnings(
    base: &Scene,
    name: &str,
    poses: std::ops::Range<usize>,
) -> crate::error::Result<Vec<String>> {
    let object = base.motion(name)?.object;
    let room = Tracer::build(&crate::scene_tracer::real_triangle_sets(base), &[])
        .map_err(|e| crate::error::Error::file(&base.file, e.to_string()))?;
    let mut others = None;
    // (what it passes through, the first pose, the deepest, how many poses)
    let mut found: Vec<(String, usize, f64, usize)> = Vec::new();
    for pose in poses {
        let scene = base.with_motion_pose(name, pose)?;
        let o = &scene.objects[object];
        let mut hits = Vec::new();
        if let Some((surface, depth)) = cut_into(&room, Layer::Real, o, &[]) {
            hits.push((
                format!("the room's '{}'", scene.surfaces[surface as usize].name),
                depth,
            ));
        }
        if let Some((other, depth)) = Others::passed_through(&mut others, &scene, object)? {
            hits.push((format!("'{other}'"), depth));
        }
        for (what, depth) in hits {
            match found.iter_mut().find(|f| f.0 == what) {
                Some(f) => {
                    f.2 = f.2.max(depth);
                    f.3 += 1;
                }
                None => found.push((what, pose, depth, 1)),
            }
        }
    }
    let moving = &base.objects[object].name;
    Ok(found
        .into_iter()
        .map(|(what, first, depth, count)| {
            format!(
                "motion '{name}': '{moving}' passes through {what} at {count} pose(s) from pose {first} (up to {:.1} cm deep; more than {:.0}% of its size is not a touch)",
                100.0 * depth,
                100.0 * TOUCH
            )
        })
        .collect())
}

/// Each object's virtual surface ids, in the scene's numbering (after the
/// real surfaces, over every object, enabled or not).
fn surface_ids(scene: &Scene) -> Vec<Vec<u32>> {
    let mut id = scene.surfaces.len() as u32;
    (scene.objects.iter())
        .map(|o| {
            let ids = (id..id + o.surfaces.len() as u32).collect();
            id += o.surfaces.len() as u32;
            ids
        })
        .collect()
}

/// What is likely wrong with where the enabled objects are, one sentence
/// each with its numbers. `tracer` holds the room and the enabled objects
/// (as [`crate::scene_tracer::build_tracer`] builds it).
pub fn warnings(scene: &Scene, photo: &Image, tracer: &Tracer) -> Vec<String> {
    let ids = surface_ids(scene);
    let name_of = |surface: u32| -> String {
        match scene.surfaces.get(surface as usize) {
            Some(s) => format!("the room's '{}'", s.name),
            None => object_of(&ids, surface).map_or("an object".to_string(), |o| {
                format!("'{}'", scene.objects[o].name)
            }),
        }
    };
    let peak_photo = (photo.pixels.iter())
        .map(|p| p.max_element())
        .fold(0.0f32, f32::max) as f64;
    let mut out = Vec::new();
    for (o, object) in scene.objects.iter().enumerate() {
        if !object.enabled || object.surfaces.is_empty() {
            continue;
        }
        let size = {
            let (lo, hi) = crate::geometry::bounds(object_points(object, &object.pose));
            (hi - lo).length()
        };
        for layer in [Layer::Real, Layer::Virtual] {
            if layer == Layer::Virtual && tracer.virtual_objects.is_none() {
                continue;
            }
            if let Some((surface, depth)) = cut_into(tracer, layer, object, &ids[o]) {
                out.push(format!(
                    "'{}' passes through {} ({:.1} cm deep, {:.0}% of its {:.2} m size; more than {:.0}% is not a touch): move it or check its scale and origin",
                    object.name,
                    name_of(surface),
                    100.0 * depth,
                    100.0 * depth / size,
                    size,
                    100.0 * TOUCH
                ));
            }
        }
        if pixels_seen(&scene.camera, tracer, object, &ids[o]) == 0 {
            out.push(format!(
                "the camera sees no pixel of '{}' (out of the frame, or hidden behind the room or another object): it changes the image only through its shadows and light",
                object.name
            ));
        }
        let glow = (object.surfaces.iter())
            .filter_map(|s| s.material.as_ref())
            .map(|m| m.material.peak_emission().max_element())
            .fold(0.0, f64::max);
        if glow > peak_photo && peak_photo > 0.0 {
            out.push(format!(
                "'{}' emits radiance up to {glow:.3}, {:.1}x the photo's brightest pixel ({peak_photo:.3}): it will outshine the real lamps (scale it with the object's `emission` key, 0 turns it off)",
                object.name,
                glow / peak_photo
            ));
        }
    }
    out
}

/// The image rectangle (x0, y0, x1, y1, pixel coordinates, not clipped to
/// the frame) that the object's box covers as placed; None when a corner of
/// the box lies at or behind the camera.
pub fn screen_rect(camera: &Camera, object: &VirtualObject) -> Option<[f64; 4]> {
    let (lo, hi) = crate::geometry::bounds(object_points(object, &object.pose));
    let mut rect = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for c in crate::geometry::box_corners(lo, hi) {
        let (x, y, _) = camera.project(c)?;
        rect = [
            rect[0].min(x),
            rect[1].min(y),
            rect[2].max(x),
            rect[3].max(y),
        ];
    }
    Some(rect)
}

/// Which object surface id `surface` belongs to, by the objects' `ids`.
fn object_of(ids: &[Vec<u32>], surface: u32) -> Option<usize> {
    ids.iter().position(|o| o.contains(&surface))
}

/// How many pixel centres (of a sample of them, at most [`SEEN_RAYS`],
/// within the object's box on screen) see `object` first; 0 only when
/// every pixel of its box was tried.
fn pixels_seen(camera: &Camera, tracer: &Tracer, object: &VirtualObject, own: &[u32]) -> usize {
    let (w, h) = (camera.width as i64, camera.height as i64);
    // The box's rectangle on screen (the whole frame when a corner is
    // behind the camera).
    let rect = match screen_rect(camera, object) {
        Some([x0, y0, x1, y1]) => (
            x0.floor() as i64,
            y0.floor() as i64,
            x1.ceil() as i64,
            y1.ceil() as i64,
        ),
        None => (0, 0, w - 1, h - 1),
    };
    let (x0, y0) = (rect.0.max(0), rect.1.max(0));
    let (x1, y1) = (rect.2.min(w - 1), rect.3.min(h - 1));
    if x1 < x0 || y1 < y0 {
        return 0;
    }
    let area = ((x1 - x0 + 1) * (y1 - y0 + 1)) as usize;
    let coarse = ((area as f64 / SEEN_RAYS as f64).sqrt().ceil() as i64).max(1);
    let count = |step: i64| -> usize {
        use rayon::prelude::*;
        let rows: Vec<i64> = (y0..=y1).step_by(step as usize).collect();
        rows.par_iter()
            .map(|&y| {
                (x0..=x1)
                    .step_by(step as usize)
                    .filter(|&x| {
                        let ray = camera.ray(x as f64 + 0.5, y as f64 + 0.5);
                        let ray = TraceRay::new(ray.origin.as_vec3(), ray.direction.as_vec3());
                        (tracer.intersect(&ray, Layer::All))
                            .is_some_and(|hit| own.contains(&hit.surface))
                    })
                    .count()
            })
            .sum()
    };
    match count(coarse) {
        0 if coarse > 1 => count(1),
        n => n,
    }
}
