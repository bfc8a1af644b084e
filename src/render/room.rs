//! The room's preparation for a session: its mesh size and model, the
//! photo's grain, the ratio's floor.

use super::*;

mod size_cache;

/// The photo smoothed within its own grain, what a brightening multiplies
/// (see [`crate::composite::grain`]).
pub(super) fn photo_without_grain(photo: &Image, lamps: Option<&LampPixels>) -> Image {
    let noise = crate::composite::grain::relative_noise(photo);
    let mut base = crate::composite::grain::smoothed(photo, noise);
    // A lamp's pixels hold a fill, not a photographed surface: smoothing it
    // across a lamp's hot spot only biases what the lamp's scale multiplies.
    for i in lamps.iter().flat_map(|l| l.pixel_indices()) {
        base.pixels[i] = photo.pixels[i];
    }
    base
}

/// The irradiance under which a composite's ratio is not trusted: a
/// thousandth of the mean "without" irradiance over the pixels that see
/// the room, from the model's patches, each weighted by the pixels that
/// see it (the same number for the whole frame, a crop and a band).
pub(super) fn ratio_floor(model: &Model, scales_without: &[f64]) -> DVec3 {
    let (mut sum, mut count) = (DVec3::ZERO, 0.0);
    for (p, &n) in model.photo.pixels.iter().enumerate() {
        if n > 0 {
            let direct: DVec3 = (model.direct_per_light.iter().zip(scales_without))
                .map(|(d, s)| d[p] * *s)
                .sum();
            sum += (direct + model.estimate.solution.indirect_irradiance[p]) * n as f64;
            count += n as f64;
        }
    }
    sum / count.max(1.0) * 1e-3
}

/// The room's largest patch edge: the user's, or from what the scene changes.
pub(super) fn room_patch_size(scene: &Scene, patch_size: PatchSize) -> f64 {
    match patch_size {
        PatchSize::Metres(m) => m,
        PatchSize::Auto if lights_change(&scene.lights) => fine_patch_size(scene),
        PatchSize::Auto => room_diagonal(scene) / 6.0,
    }
}

/// The photo's model; with an automatic patch size and no light change,
/// built finer where the room's interreflection asks for it (the size
/// found from a coarse model first, kept in the scene's cache).
pub(super) fn photo_model(
    scene: &Scene,
    photo: &Image,
    tracer: &crate::trace::Tracer,
    settings: &mut RenderSettings,
    times: &mut StageTimes,
) -> Result<Model> {
    if settings.patch_size != PatchSize::Auto || lights_change(&scene.lights) {
        return Model::build(scene, photo, tracer, &settings.model, times);
    }
    let coarse = settings.model.patch_size;
    let entry = (settings.model.cache_links)
        .then(|| size_cache::entry(scene, photo, &settings.model))
        .flatten();
    let size = match entry.as_deref().and_then(size_cache::read) {
        Some(size) => size,
        None => {
            let model = Model::build(scene, photo, tracer, &settings.model, times)?;
            let finer = coarse * interreflection_scale(&model);
            let size = if finer < 0.9 * coarse {
                finer.max(fine_patch_size(scene))
            } else {
                coarse
            };
            if let Some(entry) = &entry {
                size_cache::write(entry, size);
            }
            if size == coarse {
                return Ok(model);
            }
            size
        }
    };
    settings.model.patch_size = size;
    Model::build(scene, photo, tracer, &settings.model, times)
}

/// Whether a scene's lights switch, scale or add a light.
pub(crate) fn lights_change(lights: &[crate::scene::Light]) -> bool {
    lights
        .iter()
        .any(|l| l.scale != if l.real { 1.0 } else { 0.0 })
}

/// How much finer than the coarse room an object's change of the indirect
/// light needs the room's mesh, from the room's area-weighted mean
/// reflectance ρ̄ as estimated: (1 − ρ̄)/0.5, between ¼ and 1. The coarse
/// mesh holds where most of an object's change is the first bounce (rooms
/// of ρ̄ up to one half); the interreflections spread the change through
/// the room with a gain of 1/(1 − ρ̄), twice as much at ρ̄ = 0.75, five
/// times at 0.9, and the mesh refines in proportion (measured on
/// `whitebox`, ρ̄ ≈ 0.8: skill 0.62–0.79 with the coarse mesh, 0.69–0.86
/// at a quarter of its size).
pub(super) fn interreflection_scale(model: &Model) -> f64 {
    let (mut sum, mut area) = (0.0, 0.0);
    for (k, rho) in model.estimate.reflectance.iter().enumerate() {
        let a = model.patches.patch(k).area;
        sum += a * rho.element_sum() / 3.0;
        area += a;
    }
    let mean = if area > 0.0 { sum / area } else { 0.0 };
    ((1.0 - mean) / 0.5).clamp(0.25, 1.0)
}

/// The virtual surface ids of the objects shown at the same pose in `old`
/// and `new` (an update's objects that stood still).
pub(super) fn unmoved_surfaces(old: &Scene, new: &Scene) -> Vec<u32> {
    let mut id = new.surfaces.len() as u32;
    let mut out = Vec::new();
    for (a, b) in old.objects.iter().zip(&new.objects) {
        let n = b.surfaces.len() as u32;
        let same = a.name == b.name && a.surfaces.len() == b.surfaces.len();
        if same && a.enabled && b.enabled && a.pose == b.pose {
            out.extend(id..id + n);
        }
        id += n;
    }
    out
}
