//! What every render needs before it starts, whichever the method: the
//! photo in absolute units and a light to reconstruct recovered, each
//! through a cache next to the scene; and the room's patch sizes.

use crate::error::Result;
use crate::image_io::Image;
use crate::lamps::LampPixels;
use crate::model::ModelSettings;
use crate::scene::Scene;
use crate::trace::Tracer;
use crate::util::stages::StageTimes;

/// What every method needs before it starts: the photo in absolute units
/// (merged brackets are radiance up to a factor, fixed from the known
/// reflectances) and a light to reconstruct recovered from it (Grosch
/// §2.3). Returns the scene with the recovered light, if there was one.
pub(crate) fn resolve_inputs(
    scene: &Scene,
    photo: &Image,
    tracer: &crate::trace::Tracer,
    settings: &ModelSettings,
    times: &mut StageTimes,
    left_out: &mut Vec<String>,
) -> Result<(Option<Scene>, Image)> {
    let (photo, relative) = photo_in_units(scene, photo, tracer, settings, times);
    left_out.extend(relative.map(|why| format!("absolute scale: {why}")));
    let resolved = match crate::gonio::light_to_reconstruct(scene)? {
        Some(_) => Some(times.time("goniometric", || reconstruct_cached(scene, &photo, tracer))?),
        None => None,
    };
    Ok((resolved, photo))
}

/// The photo in the scene's units: merged brackets (radiance up to a
/// factor) scaled by the factor the known reflectances fix, through a
/// cache next to the scene; an HDR photo as it is. With brackets and no
/// known reflectance the photo stays relative, and the second value says
/// so (every command that needs absolute radiance says it its own way).
pub fn photo_in_units(
    scene: &Scene,
    photo: &Image,
    tracer: &Tracer,
    settings: &ModelSettings,
    times: &mut StageTimes,
) -> (Image, Option<String>) {
    if !scene.photo_is_relative() {
        return (photo.clone(), None);
    }
    let scale = times.time("bracket scale", || {
        bracket_scale_cached(scene, photo, tracer, settings, fine_patch_size(scene))
    });
    match scale {
        Some(s) => (
            Image {
                pixels: photo.pixels.iter().map(|p| *p * s as f32).collect(),
                ..photo.clone()
            },
            None,
        ),
        None => (
            photo.clone(),
            Some("the photo comes from brackets and no reflectance is known, so radiance is relative".into()),
        ),
    }
}

/// The diagonal of the real geometry's bounding box.
pub(crate) fn room_diagonal(scene: &Scene) -> f64 {
    let (lo, hi) = scene.real_bounds();
    (hi - lo).length()
}

/// The patch size at which the room's radiosity is accurate per patch.
pub fn fine_patch_size(scene: &Scene) -> f64 {
    room_diagonal(scene) / 24.0
}

/// `scene` with its light to reconstruct recovered from `photo`
/// ([`crate::gonio::reconstruct`]), through a cache next to the scene keyed
/// by the scene file, its meshes, the photo's files and the settings.
pub fn reconstruct_cached(
    scene: &Scene,
    photo: &Image,
    tracer: &crate::trace::Tracer,
) -> Result<Scene> {
    let settings = crate::gonio::GonioSettings::default();
    let mut files: Vec<std::path::PathBuf> = vec![scene.file.clone()];
    files.extend(scene.surfaces.iter().map(|s| s.mesh.clone()));
    match &scene.photo {
        crate::scene::Photo::Image(p) => files.push(p.clone()),
        crate::scene::Photo::Brackets(b) => files.extend(b.iter().map(|b| b.image.clone())),
    }
    files.dedup();
    let mut hash = crate::util::cache::ContentHash::default();
    let readable = files
        .iter()
        .all(|f| std::fs::read(f).map(|bytes| hash.feed(&bytes)).is_ok());
    hash.feed(format!("{settings:?} {}", crate::gonio::ALGORITHM_VERSION).as_bytes());
    let cache = hash.entry(scene.dir(), "gonio", "ies");
    if readable
        && let Some((light, profile, colour)) = std::fs::read_to_string(&cache)
            .ok()
            .and_then(|t| crate::gonio::from_cache_text(&t, &cache))
            .filter(|(l, _, _)| *l < scene.lights.len())
    {
        return Ok(crate::gonio::apply_profile(scene, light, &profile, colour));
    }
    let rec = crate::gonio::reconstruct(scene, photo, tracer, &settings)?;
    if readable
        && cache
            .parent()
            .is_some_and(|d| std::fs::create_dir_all(d).is_ok())
    {
        let _ = crate::image_io::write_atomic(&cache, rec.to_cache_text().as_bytes());
    }
    Ok(rec.apply(scene))
}

/// Bumped when [`crate::model::bracket_scale`] changes what it returns, so
/// that caches written by an older arlux are not read.
pub(crate) const BRACKET_SCALE_VERSION: u32 = 3;

/// [`crate::model::bracket_scale`] on a fine mesh (the factor rests on a
/// few surfaces' estimates, which coarse patches bias), cached next to the
/// scene under a hash of the scene file, its meshes and the brackets.
pub fn bracket_scale_cached(
    scene: &Scene,
    photo: &Image,
    tracer: &crate::trace::Tracer,
    settings: &ModelSettings,
    patch_size: f64,
) -> Option<f64> {
    let mut hash = crate::util::cache::ContentHash::default();
    let mut feed = |bytes: &[u8]| hash.feed(bytes);
    let mut files: Vec<std::path::PathBuf> = vec![scene.file.clone()];
    files.extend(scene.surfaces.iter().map(|s| s.mesh.clone()));
    if let crate::scene::Photo::Brackets(b) = &scene.photo {
        files.extend(b.iter().map(|b| b.image.clone()));
    }
    files.dedup();
    for f in &files {
        feed(&std::fs::read(f).ok()?);
    }
    feed(&patch_size.to_le_bytes());
    // A change to how the factor is found, or to its settings, is a new entry.
    feed(format!("{BRACKET_SCALE_VERSION} {settings:?}").as_bytes());
    let cache = hash.entry(scene.dir(), "scale", "txt");
    if let Some(s) = std::fs::read_to_string(&cache)
        .ok()
        .and_then(|t| t.trim().parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s > 0.0)
    {
        return Some(s);
    }
    let fine = ModelSettings {
        patch_size,
        ..*settings
    };
    let scale = crate::model::bracket_scale(scene, photo, tracer, &fine)?;
    if std::fs::create_dir_all(cache.parent()?).is_ok() {
        let _ = crate::image_io::write_atomic(&cache, format!("{scale}\n").as_bytes());
    }
    Some(scale)
}

/// The pixels that see a lamp, with the photo the stages read (those
/// pixels filled from around them), and the lamps with the photo as shot;
/// the photo unchanged when no lamp is in view. `supersample` is the edge
/// supersampling: a lamp is sampled [`crate::lamps::LAMP_SUPERSAMPLE_FACTOR`]
/// times as finely per side.
pub fn lamps_in_view(
    scene: &Scene,
    photo: Image,
    tracer: &Tracer,
    supersample: u32,
    times: &mut StageTimes,
) -> Result<(Image, Option<(LampPixels, Image)>)> {
    let lights = crate::light::LightSource::all(scene)?;
    let found = times.time("lamps in view", || {
        LampPixels::find(
            &scene.camera,
            &lights,
            tracer,
            supersample * crate::lamps::LAMP_SUPERSAMPLE_FACTOR,
        )
        .map(|l| (l.photo_without_lamps(&photo), l))
    });
    Ok(match found {
        Some((filled, lamps)) => (filled, Some((lamps, photo))),
        None => (photo, None),
    })
}

/// Share of pixels above which a photo counts as clipped.
pub(crate) const CLIPPED_SHARE: f64 = 0.01;
/// Share of the seen area above which pinned reflectances say the lights
/// do not fit the photo.
pub(crate) const PINNED_SHARE: f64 = 0.03;

/// Warnings about the photo and what the estimate made of it: a photo whose
/// brightest value is shared by more than [`CLIPPED_SHARE`] of its pixels
/// (a sensor or an 8-bit encoding clipped it: radiance there is unknown),
/// and reflectances pinned at the clamp on more than [`PINNED_SHARE`] of
/// the seen area (the lights are too weak for the photo).
pub(crate) fn input_warnings(
    photo: &Image,
    estimate: Option<&crate::estimate::Estimate>,
) -> Vec<String> {
    let mut out = Vec::new();
    let peak = photo
        .pixels
        .iter()
        .map(|p| p.max_element())
        .fold(0.0f32, f32::max);
    if peak > 0.0 {
        let at_peak = photo
            .pixels
            .iter()
            .filter(|p| p.max_element() >= peak * (1.0 - 1e-6))
            .count();
        let share = at_peak as f64 / photo.pixels.len().max(1) as f64;
        if share > CLIPPED_SHARE {
            out.push(format!(
                "{:.1}% of the photo's pixels sit at its brightest value {peak}: the photo is clipped there, and their radiance is unknown (use an HDR photo or brackets)",
                100.0 * share
            ));
        }
    }
    if let Some(estimate) = estimate.filter(|e| e.pinned_share > PINNED_SHARE) {
        out.push(format!(
            "the reflectances estimated on {:.0}% of the seen area are pinned at the clamp: the lights given are too weak for the photo by at least {:.1}x (or the photo is that much too bright)",
            100.0 * estimate.pinned_share,
            estimate.pinned_factor
        ));
    }
    out
}

/// Below this share of the image seen by the model, a render is likely
/// wrong (a camera that looks past the room, a model that misses most of
/// the photo): the rest is the photo, unchanged.
const MIN_COVERAGE: f64 = 0.5;

/// A warning when the model covers less than [`MIN_COVERAGE`] of the
/// image's `pixels` (the crop window's, when one is given).
pub(crate) fn coverage_warning(covered: usize, pixels: usize) -> Option<String> {
    let covered = covered as f64 / pixels.max(1) as f64;
    (covered < MIN_COVERAGE).then(|| {
        format!(
            "the model covers {:.1}% of the image: the rest is the photo, unchanged (check the camera's position, look_at and field of view against `arlux ids`)",
            100.0 * covered
        )
    })
}
