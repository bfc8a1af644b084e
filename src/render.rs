//! [`render`]: the augmented photo of a scene, stage by stage — the model of
//! the photographed room (estimation), radiosity with the changes (virtual
//! objects taking part, lights at their new scales), the Pixel Data Array,
//! and the differential composite. Stages a scene does not need are left
//! out and listed: no change returns the photo; no virtual object builds no
//! virtual geometry and reuses the room's light transport.

use std::collections::HashMap;

use glam::DVec3;

use crate::composite::{Composite, CompositeInput, CompositeMode, composite};
use crate::error::Result;
use crate::image_io::Image;
use crate::model::{Model, ModelSettings, StageTimes, TransportMethod};

use crate::patches::Patches;
use crate::pda::{PdaInput, PdaSettings, PixelDataArray, VirtualBounds};
use crate::radiosity::{Transport, direct_irradiance, solve_from, total_direct};
use crate::scene::Scene;
use crate::trace::Layer;

/// Render settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    pub model: ModelSettings,
    /// Largest patch edge on virtual objects (their indirect light shows directly).
    pub virtual_patch_size: f64,
    pub pda: PdaSettings,
    pub mode: CompositeMode,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            model: ModelSettings::default(),
            virtual_patch_size: 0.1,
            pda: PdaSettings::default(),
            mode: CompositeMode::Ratio,
        }
    }
}

/// What a render produced and what it did.
pub struct RenderOutput {
    pub composite: Composite,
    /// Stages that ran are in the timings; these were left out, with why.
    pub left_out: Vec<String>,
    pub pda_bytes: usize,
    pub pda_pixels: usize,
    pub rays: u64,
    pub patches: usize,
    pub links: usize,
}

/// Renders `scene` (an effective scene: a variant or motion pose of the
/// loaded one) over `photo`.
pub fn render(scene: &Scene, photo: &Image, settings: &RenderSettings, times: &mut StageTimes) -> Result<RenderOutput> {
    let n = photo.pixels.len();
    if !scene.changes_the_photo() {
        let composite = Composite {
            image: photo.clone(),
            direct: Image::new(photo.width, photo.height),
            indirect: Image::new(photo.width, photo.height),
            change: Image::new(photo.width, photo.height),
            alpha: vec![0.0; n],
            copied: n,
            ratio_fallbacks: 0,
            clamped: 0,
        };
        let left_out = vec!["everything: the scene shows the photo's state (no virtual object, lights as photographed)".to_string()];
        return Ok(RenderOutput { composite, left_out, pda_bytes: 0, pda_pixels: n, rays: 0, patches: 0, links: 0 });
    }
    let mut left_out = Vec::new();
    let tracer = times.time("tracer", || scene.build_tracer())?;
    let model = Model::build(scene, photo, &tracer, &settings.model, times)?;
    let lights = &model.lights;
    let scales_without: Vec<f64> = lights.iter().map(|l| l.photo_scale()).collect();
    let scales_with: Vec<f64> = lights.iter().map(|l| l.scale).collect();
    let has_virtual = tracer.virtual_objects.is_some();

    // Radiosity with the changes: the virtual objects' patches join the
    // room's, with their own reflectance, and shadow the exchanges.
    let own: Option<(Patches, Vec<Vec<DVec3>>, Transport)> = if has_virtual {
        let patches = times.time("virtual mesh", || Patches::of_scene_with(scene, true, settings.model.patch_size, settings.virtual_patch_size));
        let direct = times.time("direct light with objects", || direct_irradiance(&patches, lights, &tracer, Layer::All, settings.model.light_level));
        let epsilon = match settings.model.transport {
            TransportMethod::Full => crate::radiosity::DEFAULT_LINK_EPSILON,
            TransportMethod::Hierarchical { epsilon } => epsilon,
        };
        let transport = times.time("form factors with objects", || model.transport.with_objects(&patches, &tracer, epsilon));
        Some((patches, direct, transport))
    } else {
        left_out.push("virtual geometry and new form factors: no virtual object (the room's transport is reused)".to_string());
        None
    };
    let (patches, direct_per_light, transport) = match &own {
        Some((p, d, t)) => (p, d, t),
        None => (&model.patches, &model.direct_per_light, &model.transport),
    };
    let virtual_rgb: HashMap<u32, DVec3> = scene.virtual_surface_rgb();
    let real_count = model.patches.patch_count();
    let reflectance: Vec<DVec3> = (0..patches.patch_count())
        .map(|k| if k < real_count { model.estimate.reflectance[k] } else { virtual_rgb[&patches.patch(k).surface] })
        .collect();
    let with = times.time("solve with changes", || {
        let e = total_direct(&scales_with, direct_per_light);
        let b: Vec<DVec3> = reflectance.iter().zip(&e).map(|(r, e)| *r * *e).collect();
        let mut guess = model.estimate.solution.radiosity.clone();
        guess.resize(patches.patch_count(), DVec3::ZERO);
        solve_from(patches, transport, &reflectance, &b, Some(&guess), settings.model.estimate.solve_tolerance, 500)
    });
    let indirect_without = model.patches.vertex_values(&model.estimate.solution.indirect_irradiance);
    let indirect_with = patches.vertex_values(&with.indirect_irradiance);

    let bounds = VirtualBounds::of(&scene.virtual_world_surfaces());
    let active: Vec<bool> = scales_with.iter().zip(&scales_without).map(|(a, b)| *a > 0.0 || *b > 0.0).collect();
    if !has_virtual {
        left_out.push("rays against virtual geometry and edge supersampling: no virtual object".to_string());
    }
    let pda = times.time("pixel data array", || {
        PixelDataArray::build(&PdaInput {
            camera: &scene.camera,
            tracer: &tracer,
            patches,
            lights,
            active: &active,
            bounds: &bounds,
            settings: settings.pda,
        })
    });
    let result = times.time("composite", || {
        composite(&CompositeInput {
            pda: &pda,
            photo,
            lights,
            scales_without: &scales_without,
            scales_with: &scales_with,
            indirect_without: &indirect_without,
            indirect_with: &indirect_with,
            reflectance: &reflectance,
            patch_vertices: &patches.patch_vertices,
            mode: settings.mode,
        })
    });
    Ok(RenderOutput {
        composite: result,
        left_out,
        pda_bytes: pda.memory_bytes(),
        pda_pixels: n,
        rays: pda.rays,
        patches: patches.patch_count(),
        links: transport.link_count(),
    })
}

