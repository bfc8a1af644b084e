//! [`Model`]: the illumination model of a real scene, built in stages —
//! patches, direct light per light, light transport, reflectances estimated
//! from the photo and the radiosity solution — and [`ModelView`], the photo
//! re-rendered from the model alone, per pixel: ρ × (direct + indirect) / π,
//! with direct light traced per pixel and indirect light interpolated from
//! the solution's vertex values.

use std::collections::HashMap;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::error::Result;
use crate::estimate::{Estimate, EstimateSettings, PhotoPatches, estimate_reflectances};
use crate::image_io::Image;
use crate::light::LightSource;
use crate::patches::Patches;
use crate::radiosity::{DEFAULT_LINK_EPSILON, Transport, direct_irradiance, total_direct};
use crate::scene::Scene;
use crate::surface_ids::row_hits;
use crate::trace::{Layer, Tracer};
use crate::util::rng::hash2;

/// How light transport is computed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TransportMethod {
    /// Every patch against every other (the oracle; small scenes).
    Full,
    /// Hierarchical radiosity with this refinement threshold.
    Hierarchical { epsilon: f64 },
}

/// Settings of the model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelSettings {
    /// Largest patch edge, metres.
    pub patch_size: f64,
    pub transport: TransportMethod,
    /// 2^level shadow rays per point towards rect lights.
    pub light_level: usize,
    pub estimate: EstimateSettings,
    /// Keep the room's hierarchical links in `.arlux-cache/` next to the
    /// scene and read them from there when the room's surfaces, their mesh
    /// and ε are the same, and this build wrote them (and so the room's
    /// automatic patch size, when everything it was found from is the same).
    pub cache_links: bool,
}

impl Default for ModelSettings {
    fn default() -> Self {
        ModelSettings {
            patch_size: 0.25,
            transport: TransportMethod::Hierarchical {
                epsilon: DEFAULT_LINK_EPSILON,
            },
            light_level: 4,
            estimate: EstimateSettings::default(),
            cache_links: false,
        }
    }
}

/// Kept here too for the front ends that time the model's stages.
pub use crate::util::stages::StageTimes;

/// The illumination model of a scene's real part.
pub struct Model {
    pub patches: Patches,
    pub lights: Vec<LightSource>,
    /// Direct irradiance per light and patch, before each light's scale.
    pub direct_per_light: Vec<Vec<DVec3>>,
    pub transport: Transport,
    pub photo: PhotoPatches,
    pub estimate: Estimate,
}

/// Patches above which a mesh is refused before it is built: the
/// hierarchical links and the form factors grow faster than the patches,
/// and at this count they would take gigabytes and hours.
pub(crate) const MAX_PATCHES: f64 = 500_000.0;

/// Refuses a patch size that would mesh the real surfaces into more than
/// [`MAX_PATCHES`] patches (each surface splits into halves until no edge
/// exceeds the size, so a patch covers at least half of size²).
pub(crate) fn check_patch_count(scene: &Scene, patch_size: f64) -> Result<()> {
    let area: f64 = scene
        .surfaces
        .iter()
        .flat_map(|s| &s.triangles)
        .map(|t| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length() as f64)
        .sum();
    let estimate = area / (0.5 * patch_size * patch_size);
    if estimate > MAX_PATCHES {
        return Err(crate::Error::file(
            &scene.file,
            format!(
                "a patch size of {patch_size} m would mesh the room's {area:.0} m² into up to {estimate:.0} patches (at most {MAX_PATCHES} are built: links and form factors would take gigabytes); give a larger --patch-size, at least {:.3} m",
                (2.0 * area / MAX_PATCHES).sqrt()
            ),
        ));
    }
    Ok(())
}

/// The light transport between the room's patches, as `settings` ask.
fn room_transport(
    scene: &Scene,
    patches: &Patches,
    tracer: &Tracer,
    settings: &ModelSettings,
    times: &mut StageTimes,
) -> Transport {
    match settings.transport {
        TransportMethod::Full => times.time("form factors", || {
            Transport::full(patches, tracer, Layer::Real)
        }),
        TransportMethod::Hierarchical { epsilon } => {
            room_links(scene, patches, tracer, epsilon, settings.cache_links, times)
        }
    }
}

/// Hierarchical radiosity between the room's `patches`; with `cache`,
/// read from `.arlux-cache/` when it holds this mesh's links (the stage is
/// then "links from the cache") and written there when refined.
pub(crate) fn room_links(
    scene: &Scene,
    patches: &Patches,
    tracer: &Tracer,
    epsilon: f64,
    cache: bool,
    times: &mut StageTimes,
) -> Transport {
    if !cache {
        return times.time("form factors", || {
            Transport::hierarchical(patches, tracer, Layer::Real, epsilon)
        });
    }
    crate::util::stages::started("form factors");
    let t0 = Instant::now();
    let entry = links_cache::entry(scene, patches, epsilon);
    let (stage, transport) = match links_cache::read(&entry, patches) {
        Some(links) => (
            "links from the cache",
            Transport::hierarchical_from_links(links),
        ),
        None => {
            let transport = Transport::hierarchical(patches, tracer, Layer::Real, epsilon);
            links_cache::write(&entry, transport.links());
            ("form factors", transport)
        }
    };
    times.0.push((stage, t0.elapsed()));
    transport
}

impl Model {
    /// Builds the model of `scene`'s real surfaces under its lights as the
    /// photo shows them (real lights at scale 1, virtual lights off).
    pub fn build(
        scene: &Scene,
        photo: &Image,
        tracer: &Tracer,
        settings: &ModelSettings,
        times: &mut StageTimes,
    ) -> Result<Model> {
        let lights = LightSource::all(scene)?;
        check_patch_count(scene, settings.patch_size)?;
        let patches = times.time("mesh", || {
            Patches::of_scene(scene, false, settings.patch_size)
        });
        let direct_per_light = times.time("direct light", || {
            direct_irradiance(&patches, &lights, tracer, Layer::Real, settings.light_level)
        });
        let transport = room_transport(scene, &patches, tracer, settings, times);
        let photo = times.time("photo per patch", || {
            PhotoPatches::measure(&scene.camera, tracer, &patches, photo)
        });
        let known: HashMap<u32, DVec3> = scene
            .reflectances
            .iter()
            .map(|k| (k.surface as u32, k.rgb))
            .collect();
        // The photo shows the real lights as they are and no virtual light.
        let scales: Vec<f64> = lights.iter().map(|l| l.photo_scale()).collect();
        let direct = total_direct(patches.patch_count(), &scales, &direct_per_light);
        let estimate = times.time("estimate + solve", || {
            estimate_reflectances(
                &patches,
                &transport,
                &direct,
                &photo,
                &known,
                settings.estimate,
            )
        });
        Ok(Model {
            patches,
            lights,
            direct_per_light,
            transport,
            photo,
            estimate,
        })
    }
}

/// The model seen from the camera.
pub struct ModelView {
    /// Radiance ρ·(E + H)/π: the photo as the model explains it.
    pub radiance: Image,
    /// Direct irradiance E per pixel (the lights as photographed).
    pub direct: Image,
    /// Indirect irradiance H per pixel, interpolated.
    pub indirect: Image,
    pub reflectance: Image,
    /// Patch seen at each pixel (-1: none).
    pub patch_ids: Vec<i32>,
    /// Shadow rays traced.
    pub rays: u64,
}

impl ModelView {
    /// Renders the model per pixel centre with `2^level` shadow rays per rect light.
    pub fn render(scene: &Scene, tracer: &Tracer, model: &Model, level: usize) -> ModelView {
        let cam = &scene.camera;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let vertex_indirect = model
            .patches
            .vertex_values(&model.estimate.solution.indirect_irradiance);
        let pi = std::f64::consts::PI;
        // Per pixel: radiance, direct, indirect, reflectance, surface id, rays.
        type Sample = (DVec3, DVec3, DVec3, DVec3, i32, u64);
        let rows: Vec<Vec<Sample>> = (0..h)
            .into_par_iter()
            .map(|row| {
                row_hits(cam, tracer, Layer::Real, row as u32)
                    .iter()
                    .enumerate()
                    .map(|(col, hit)| {
                        let none = (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO, DVec3::ZERO, -1, 0);
                        let Some(hit) = hit else { return none };
                        let ray = cam.pixel_ray(col as u32, row as u32);
                        let x = ray.origin + ray.direction * hit.t as f64;
                        let Some(at) = model.patches.locate(hit.surface, hit.triangle, x) else {
                            return none;
                        };
                        let n = hit.normal.as_dvec3();
                        let seed = hash2((row * w + col) as u64, 0x0D1_EC7);
                        let mut e = DVec3::ZERO;
                        let mut count = 0u64;
                        for (li, light) in model
                            .lights
                            .iter()
                            .enumerate()
                            .filter(|(_, l)| l.photo_scale() > 0.0)
                        {
                            let d = light.direct(
                                tracer,
                                Layer::Real,
                                x,
                                n,
                                level,
                                hash2(seed, li as u64),
                            );
                            e += d.unoccluded * d.visibility * light.photo_scale();
                            count += d.rays as u64;
                        }
                        let indirect = model.patches.interpolate(&vertex_indirect, &at);
                        let rho = model.estimate.reflectance[at.patch as usize];
                        (
                            rho * (e + indirect) / pi,
                            e,
                            indirect,
                            rho,
                            at.patch as i32,
                            count,
                        )
                    })
                    .collect()
            })
            .collect();
        let mut view = ModelView {
            radiance: Image::new(cam.width, cam.height),
            direct: Image::new(cam.width, cam.height),
            indirect: Image::new(cam.width, cam.height),
            reflectance: Image::new(cam.width, cam.height),
            patch_ids: Vec::with_capacity(w * h),
            rays: 0,
        };
        for (i, (l, e, ind, rho, id, rays)) in rows.into_iter().flatten().enumerate() {
            view.radiance.pixels[i] = l.as_vec3();
            view.direct.pixels[i] = e.as_vec3();
            view.indirect.pixels[i] = ind.as_vec3();
            view.reflectance.pixels[i] = rho.as_vec3();
            view.patch_ids.push(id);
            view.rays += rays;
        }
        view
    }
}

/// The factor that puts a photo merged from brackets into the scene's
/// radiometric units: reflectances are estimated with the known ones
/// treated as unknown, and the photo is scaled until their estimates match
/// the known values (a few rounds: the indirect term makes it not quite
/// linear). `None` when no reflectance is known (radiance stays relative).
pub fn bracket_scale(
    scene: &Scene,
    photo: &Image,
    tracer: &Tracer,
    settings: &ModelSettings,
) -> Option<f64> {
    if scene.reflectances.is_empty() {
        return None;
    }
    let lights = LightSource::all(scene).ok()?;
    let patches = Patches::of_scene(scene, false, settings.patch_size);
    let per_light = direct_irradiance(&patches, &lights, tracer, Layer::Real, settings.light_level);
    let scales: Vec<f64> = lights.iter().map(|l| l.photo_scale()).collect();
    let direct = total_direct(patches.patch_count(), &scales, &per_light);
    let transport = room_transport(
        scene,
        &patches,
        tracer,
        settings,
        &mut StageTimes::default(),
    );
    let measured = PhotoPatches::measure(&scene.camera, tracer, &patches, photo);
    let known: HashMap<u32, DVec3> = scene
        .reflectances
        .iter()
        .map(|k| (k.surface as u32, k.rgb))
        .collect();
    // ln(known / estimated) at a given scale, averaged over known surfaces.
    let mismatch = |scale: f64| -> Option<f64> {
        let scaled = PhotoPatches {
            radiance: measured.radiance.iter().map(|r| *r * scale).collect(),
            pixels: measured.pixels.clone(),
            image_mean: measured.image_mean * scale,
        };
        let est = estimate_reflectances(
            &patches,
            &transport,
            &direct,
            &scaled,
            &HashMap::new(),
            settings.estimate,
        );
        let logs: Vec<f64> = known
            .iter()
            .filter_map(|(s, rgb)| {
                let got = crate::estimate::surface_mean(&patches, &est.reflectance, *s)?;
                (got.element_sum() > 0.0).then(|| (rgb.element_sum() / got.element_sum()).ln())
            })
            .collect();
        (!logs.is_empty()).then(|| logs.iter().sum::<f64>() / logs.len() as f64)
    };
    // Start from direct light alone: it overestimates reflectance, so the
    // first guess cannot push estimates into the clamp.
    let (mut lit, mut shown) = (0.0, 0.0);
    for (k, d) in direct.iter().enumerate().take(patches.patch_count()) {
        if measured.pixels[k] > 0 && known.contains_key(&patches.patch(k).surface) {
            let a = patches.patch(k).area;
            lit += d.element_sum() * a;
            shown += measured.radiance[k].element_sum() * std::f64::consts::PI * a;
        }
    }
    let rho_known = known.values().map(|r| r.element_sum() / 3.0).sum::<f64>() / known.len() as f64;
    if shown <= 0.0 || lit <= 0.0 {
        return None;
    }
    // Secant steps on ln(scale) until the known reflectances are met.
    let mut x0 = (rho_known * lit / shown).ln();
    let mut y0 = mismatch(x0.exp())?;
    let mut x1 = x0 + y0;
    for _ in 0..20 {
        let y1 = mismatch(x1.exp())?;
        if y1.abs() < 1e-5 || (y1 - y0).abs() < 1e-12 {
            break;
        }
        let x2 = x1 - y1 * (x1 - x0) / (y1 - y0);
        (x0, y0, x1) = (x1, y1, x2);
    }
    let scale = x1.exp();
    scale.is_finite().then_some(scale)
}

mod links_cache;
