//! `arlux ids`: Colour each pixel by the surface it sees, beside the photo with the surfaces' outlines: how to check that the model registers with the photo.

use std::path::PathBuf;

use anyhow::{Result, bail};

use arlux::image_io::{self};
use arlux::surface_ids::{SurfaceIds, id_colour};
use arlux::trace::Layer;

use crate::common::*;
use crate::timing::*;

/// Arguments of `arlux ids`.
#[derive(clap::Args)]
pub struct Args {
    pub scene: PathBuf,
    /// Output PNG (2·width × height: surface colours | photo with outlines).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also write the ids as an EXR (channel Y: surface index, -1 for none).
    #[arg(long)]
    pub exr: Option<PathBuf>,
    /// Include the enabled virtual objects (of the variant, if given).
    #[arg(long)]
    pub with_virtual: bool,
    #[arg(long)]
    pub variant: Option<String>,
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args) -> Result<()> {
    let path = args.scene.as_path();
    let output = args.output.as_path();
    let exr = args.exr.as_deref();
    let with_virtual = args.with_virtual;
    let variant = args.variant.as_deref();
    let scene = stage("load", || load(path, variant))?;
    let photo = stage("read photo", || display_photo(&scene))?;
    let tracer = stage("tracer", || arlux::scene_tracer::build_tracer(&scene))?;
    let layer = if with_virtual {
        Layer::All
    } else {
        Layer::Real
    };
    let ids = stage("trace ids", || {
        SurfaceIds::at_pixel_centres(&scene.camera, &tracer, layer)
    });
    if ids.covered() == 0 {
        bail!(arlux::Error::key(
            &scene.file,
            "camera",
            "the camera sees no surface: check position, look_at and the field of view"
        ));
    }
    stage("write", || -> Result<()> {
        let picture = ids.registration_picture(&photo);
        image_io::write_png_rgb8(output, 2 * scene.camera.width, scene.camera.height, picture)?;
        if let Some(exr) = exr {
            let values: Vec<f32> = ids.ids.iter().map(|&i| i as f32).collect();
            image_io::write_exr(
                exr,
                scene.camera.width,
                scene.camera.height,
                &[image_io::ExrLayer::Channel("Y", &values)],
            )?;
        }
        Ok(())
    })?;
    let names = scene.surface_names();
    let total = ids.ids.len() as f64;
    let seen: Vec<(usize, &String, usize)> = names
        .iter()
        .enumerate()
        .map(|(i, name)| (i, name, ids.ids.iter().filter(|&&s| s == i as i32).count()))
        .filter(|(_, _, n)| *n > 0)
        .collect();
    let report = IdsReport {
        pixels: ids.ids.len(),
        covered: ids.covered(),
        output: output.display().to_string(),
        surfaces: seen
            .iter()
            .map(|(i, name, n)| {
                let [r, g, b] = id_colour(*i as i32);
                SurfaceReport {
                    id: *i,
                    name: name.to_string(),
                    colour: format!("#{r:02x}{g:02x}{b:02x}"),
                    pixels: *n,
                    fraction: *n as f64 / total,
                }
            })
            .collect(),
    };
    print_report(&report, args.json)
}

/// `arlux ids`'s report.
#[derive(serde::Serialize)]
struct IdsReport {
    pixels: usize,
    /// Pixels that see a surface.
    covered: usize,
    output: String,
    surfaces: Vec<SurfaceReport>,
}

/// A surface the camera sees, in its colour of the picture.
#[derive(serde::Serialize)]
struct SurfaceReport {
    id: usize,
    name: String,
    colour: String,
    pixels: usize,
    fraction: f64,
}

impl Report for IdsReport {
    const COMMAND: &'static str = "ids";

    fn text(&self) -> Vec<String> {
        let mut lines = vec![format!(
            "{} of {} pixels see a surface; wrote {}",
            self.covered, self.pixels, self.output
        )];
        lines.extend(self.surfaces.iter().map(|s| {
            format!(
                "  {:>3} {:<20} {}  {:5.1}% of the image",
                s.id,
                s.name,
                s.colour,
                100.0 * s.fraction
            )
        }));
        lines
    }
}
