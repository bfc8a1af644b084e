//! `arlux radiosity`: Re-render the photo from the model alone (reflectances estimated from the photo × (direct + indirect light)), with a mesh view; reports patches, links, iterations, residual and time per stage.

use std::path::PathBuf;

use anyhow::Result;

use arlux::compare::compare;
use arlux::image_io::{self};
use arlux::surface_ids::SurfaceIds;

use crate::common::*;
use crate::timing::*;

/// Arguments of `arlux radiosity`.
#[derive(clap::Args)]
pub struct Args {
    pub scene: PathBuf,
    /// Output EXR: the model's radiance, with layers direct, indirect
    /// (irradiance) and reflectance.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Mesh view PNG (2·width × height: patch colours | render with patch outlines).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Largest patch edge in metres.
    #[arg(long, default_value_t = 0.25)]
    pub patch_size: f64,
    /// Full patch-to-patch matrix instead of hierarchical radiosity.
    #[arg(long)]
    pub full: bool,
    /// Refinement threshold of hierarchical radiosity.
    #[arg(long, default_value_t = arlux::radiosity::DEFAULT_LINK_EPSILON)]
    pub epsilon: f64,
    /// 2^level shadow rays per point towards area lights.
    #[arg(long, default_value_t = 4)]
    pub light_level: usize,
    /// Refine the room's links again rather than read them from
    /// `.arlux-cache/` next to the scene (nor keep them there).
    #[arg(long)]
    pub no_cache: bool,
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args) -> Result<()> {
    let path = args.scene.as_path();
    let output = args.output.as_path();
    let mesh = args.mesh.as_deref();
    let patch_size = args.patch_size;
    let full = args.full;
    let epsilon = args.epsilon;
    let light_level = args.light_level;
    let as_json = args.json;
    use arlux::model::{Model, ModelSettings, ModelView, StageTimes, TransportMethod};
    let settings = ModelSettings {
        patch_size,
        transport: if full {
            TransportMethod::Full
        } else {
            TransportMethod::Hierarchical { epsilon }
        },
        light_level,
        cache_links: !args.no_cache,
        ..ModelSettings::default()
    };
    settings.validate()?;
    let mut times = StageTimes::default();
    let scene = times.time("load", || load(path, None))?;
    let tracer = times.time("tracer", || arlux::scene_tracer::build_tracer(&scene))?;
    let photo = photo_in_units(&scene, &tracer, &settings, &mut times)?;
    // A light to reconstruct is recovered first, as `render` does.
    let scene = match arlux::gonio::light_to_reconstruct(&scene)? {
        Some(_) => times.time("goniometric", || {
            arlux::inputs::reconstruct_cached(&scene, &photo, &tracer)
        })?,
        None => scene,
    };
    // The model reads the photo with its lamps filled from around them,
    // as a render does, and is compared with that photo.
    let supersample = arlux::pda::PdaSettings::default().supersample;
    let (photo, _) = arlux::inputs::lamps_in_view(&scene, photo, &tracer, supersample, &mut times)?;
    let model = Model::build(&scene, &photo, &tracer, &settings, &mut times)?;
    let view = times.time("render view", || {
        ModelView::render(&scene, &tracer, &model, light_level)
    });
    let error = times.time("compare", || compare(&view.radiance, &photo, None));
    times.time("write", || -> Result<()> {
        let (w, h) = (scene.camera.width, scene.camera.height);
        image_io::write_exr(
            output,
            w,
            h,
            &[
                image_io::ExrLayer::Rgb("", &view.radiance),
                image_io::ExrLayer::Rgb("direct", &view.direct),
                image_io::ExrLayer::Rgb("indirect", &view.indirect),
                image_io::ExrLayer::Rgb("reflectance", &view.reflectance),
            ],
        )?;
        if let Some(mesh) = mesh {
            let ids = SurfaceIds {
                width: w,
                height: h,
                ids: view.patch_ids.clone(),
            };
            image_io::write_png_rgb8(mesh, 2 * w, h, ids.registration_picture(&view.radiance))?;
        }
        Ok(())
    })?;
    let est = &model.estimate;
    keep(&times);
    let report = RadiosityReport {
        patches: model.patches.patch_count(),
        elements: model.patches.elements.len(),
        transport: if full { "full" } else { "hierarchical" },
        links: model.transport.link_count(),
        transport_bytes: model.transport.memory_bytes(),
        estimate_iterations: est.iterations,
        estimate_change: est.change,
        clamped_patches: est.clamped,
        unseen_patches: est.unseen,
        solver_iterations: est.solution.iterations,
        solver_residual: est.solution.residual,
        shadow_rays: view.rays,
        comparison: error,
        stages: stages_json(&times),
        seconds: times.total().as_secs_f64(),
    };
    print_report(&report, as_json)
}

/// `arlux radiosity`'s report.
#[derive(serde::Serialize)]
struct RadiosityReport {
    patches: usize,
    elements: usize,
    transport: &'static str,
    links: usize,
    transport_bytes: usize,
    estimate_iterations: usize,
    estimate_change: f64,
    clamped_patches: usize,
    unseen_patches: usize,
    solver_iterations: usize,
    solver_residual: f64,
    shadow_rays: u64,
    comparison: arlux::compare::Comparison,
    stages: serde_json::Value,
    seconds: f64,
}

impl Report for RadiosityReport {
    const COMMAND: &'static str = "radiosity";

    fn text(&self) -> Vec<String> {
        let error = &self.comparison;
        vec![
            format!(
                "{} patches ({} elements), {} transport with {} form factors ({:.1} MB)",
                self.patches,
                self.elements,
                self.transport,
                self.links,
                self.transport_bytes as f64 / 1e6
            ),
            format!(
                "reflectances: {} fixed-point iterations (last change {:.1e}), {} patches clamped to [0, {}], {} unseen patches took their surface's mean",
                self.estimate_iterations,
                self.estimate_change,
                self.clamped_patches,
                arlux::estimate::MAX_REFLECTANCE,
                self.unseen_patches
            ),
            format!(
                "radiosity: GMRES {} iterations, residual {:.1e}",
                self.solver_iterations, self.solver_residual
            ),
            format!(
                "model against the photo: RMSE {:.5}, relative {:.3}, PSNR {}",
                error.rmse,
                error.relative_rmse.unwrap_or(f64::NAN),
                error
                    .psnr_srgb_db
                    .map_or("inf".into(), |p| format!("{p:.2} dB"))
            ),
        ]
    }
}
