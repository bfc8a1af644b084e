//! Direct irradiance per patch from each light, through the room or the
//! room and the objects.

use super::still::StillSurfaces;
use crate::light::LightSource;
use crate::objects::VirtualBounds;
use crate::patches::Patches;
use crate::shaft::Shaft;
use crate::trace::{Layer, Tracer};
use glam::DVec3;
use rayon::prelude::*;

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

/// What [`direct_irradiance_with_objects`] reads.
pub struct DirectWithObjects<'a> {
    pub patches: &'a Patches,
    pub lights: &'a [LightSource],
    pub tracer: &'a Tracer,
    /// Shadow rays per point to a rect light: 2^level.
    pub level: usize,
    /// The room's own values per light (through real geometry, for the first patches).
    pub room: &'a [Vec<DVec3>],
    pub objects: &'a VirtualBounds,
}

/// [`direct_irradiance`] through real and virtual geometry: the room's own
/// values are taken wherever the shaft from a patch to the light excludes
/// every one of the objects — no ray can meet an object there, so the
/// numbers are the same — and only the rest are traced. An object's patch
/// whose light only its own solid can block
/// ([`VirtualBounds::only_own_blocks`]) knows its rays without tracing.
/// `kept`: what moved since the pose before and its values for the same
/// lights; a patch of the room or of a still object (numbered as before)
/// whose shaft to a light no moved box enters, where it was or is, takes
/// the value it had: its rays, seeded by its number, meet what they met.
pub fn direct_irradiance_with_objects(
    input: &DirectWithObjects,
    kept: Option<(&StillSurfaces, &[Vec<DVec3>])>,
) -> Vec<Vec<DVec3>> {
    let (patches, room, objects) = (input.patches, input.room, input.objects);
    let (tracer, level) = (input.tracer, input.level);
    let share = face_clusters(patches, room.first().map_or(0, |r| r.len()));
    (input.lights.iter())
        .zip(room)
        .enumerate()
        .map(|(l, (light, room))| {
            let light_box = light.bounds();
            let own: Vec<DVec3> = (0..patches.patch_count())
                .into_par_iter()
                .map(|k| {
                    if share[k] != k as u32 {
                        return DVec3::ZERO;
                    }
                    let el = patches.patch(k);
                    // The value it had, if no moved box enters its shaft.
                    // (Its shaft given, or made only when it may be kept.)
                    let before = |shaft: Option<&Shaft>| {
                        let (still, last) = kept?;
                        let last = last.get(l).filter(|v| v.len() == patches.patch_count())?;
                        let same = k < room.len() || still.patch_shift(el.surface) == Some(0);
                        if !same {
                            return None;
                        }
                        let made;
                        let shaft = match shaft {
                            Some(s) => s,
                            None => {
                                made = Shaft::between_boxes(el.bounds, light_box);
                                &made
                            }
                        };
                        still.clear_of_shaft(shaft).then_some(last[k])
                    };
                    if k < room.len() {
                        let shaft = Shaft::between_boxes(el.bounds, light_box);
                        if objects.objects.iter().all(|o| o.outside(&shaft)) {
                            return room[k];
                        }
                        if let Some(v) = before(Some(&shaft)) {
                            return v;
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
                    if let Some(v) = (k >= room.len()).then(|| before(None)).flatten() {
                        return v;
                    }
                    patch_direct(patches, k, light, tracer, Layer::All, level)
                })
                .collect();
            share.iter().map(|&s| own[s as usize]).collect()
        })
        .collect()
}

/// Edge of the cells that gather a finely tessellated object's patches
/// into face clusters (2.5 cm: a quarter of the objects' patch size).
const FACE_CLUSTER_CELL: f64 = 0.025;

/// Per patch, the patch whose direct light it takes: itself, or for an
/// object's patch (from `first` on) the one nearest the area-weighted
/// centre of its face cluster — the object's patches of one surface whose
/// centres share a [`FACE_CLUSTER_CELL`] and whose normals share a
/// cube-map cell (~22° across; Willmott, Heckbert & Garland 1999 cluster faces
/// of similar normal). A subdivided ball then traces about what the coarse
/// one does (its 24,768 patches were most of an update's direct light),
/// and an object meshed no finer than the cell keeps its own patches.
fn face_clusters(patches: &Patches, first: usize) -> Vec<u32> {
    let mut share: Vec<u32> = (0..patches.patch_count() as u32).collect();
    let mut groups: crate::util::FastMap<(u32, [i64; 3], usize), Vec<u32>> =
        crate::util::fast_map();
    for k in first..patches.patch_count() {
        let el = patches.patch(k);
        let cell = (el.centre / FACE_CLUSTER_CELL)
            .floor()
            .as_i64vec3()
            .to_array();
        let key = (el.surface, cell, crate::geometry::normal_bin(el.normal));
        groups.entry(key).or_default().push(k as u32);
    }
    for members in groups.values().filter(|m| m.len() > 1) {
        let area: f64 = members
            .iter()
            .map(|&k| patches.patch(k as usize).area)
            .sum();
        let centre = members
            .iter()
            .map(|&k| patches.patch(k as usize).centre * patches.patch(k as usize).area)
            .sum::<DVec3>()
            / area.max(1e-300);
        // On the surface (a mean of a curved surface's points lies inside
        // its solid, where shadow rays would start): the nearest member,
        // the lowest index among equals so that the choice is fixed.
        let nearest = members
            .iter()
            .copied()
            .min_by(|&a, &b| {
                let d = |k: u32| (patches.patch(k as usize).centre - centre).length_squared();
                d(a).total_cmp(&d(b)).then(a.cmp(&b))
            })
            .expect("a cluster has members");
        for &k in members {
            share[k as usize] = nearest;
        }
    }
    share
}

/// Patch k's direct irradiance from `light`: the mean over 2×2 points, or
/// over a split of the patch near the light ([`direct_split`]).
pub(super) fn patch_direct(
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
pub(super) fn direct_split(el: &crate::patches::Element, light: &LightSource) -> usize {
    let (lo, hi) = light.bounds();
    let nearest = el.centre.clamp(lo, hi);
    let gap = ((el.centre - nearest).length() - 0.5 * el.size).max(0.0);
    if gap >= el.size {
        return 1;
    }
    ((el.size / gap.max(el.size / 16.0)).ceil() as usize).clamp(2, 16)
}

/// [`patch_direct`], with `direct(point, normal, seed)` giving each point's
/// direct light (see [`LightSource::direct_by`]). A virtual object's patch
/// away from the light takes its centre alone: its direct light only
/// reaches the image through the light the object sends the room (its
/// pixels take theirs per pixel), which sums many such patches, and a
/// tessellated object has thousands (the stool's 2,000 patches × 2×2
/// points × 16 rays per rect light were most of an update's direct light).
pub(super) fn patch_direct_by(
    patches: &Patches,
    k: usize,
    light: &LightSource,
    direct: impl Fn(DVec3, DVec3, u64) -> crate::light::DirectLight,
) -> DVec3 {
    let el = patches.patch(k);
    let split = direct_split(el, light);
    let shape = patches.sample_shape(k);
    let points = match split == 1 && patches.is_virtual_element(patches.patches[k]) {
        true => shape.quadrature(1),
        false => shape.split_quadrature(split),
    };
    points
        .iter()
        .enumerate()
        .map(|(i, (x, w))| {
            let seed = crate::util::rng::hash2(k as u64, i as u64);
            let d = direct(*x, el.normal, seed);
            d.unoccluded * d.visibility * *w
        })
        .sum()
}

/// Total direct irradiance of `n` patches: Σ scale × per-light irradiance
/// (the count is given: with every light off there is no list to take it from).
pub fn total_direct(n: usize, scales: &[f64], per_light: &[Vec<DVec3>]) -> Vec<DVec3> {
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
