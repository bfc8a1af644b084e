//! `arlux render`: The augmented photo of a variant: virtual objects inserted, lights changed or added, by per-pixel differential rendering (or, with --method texture, shadow-free textures × B/D).

use std::path::PathBuf;

use anyhow::{Context, Result};
use serde_json::json;

use arlux::compare::{BandComparison, Comparison, Skill};
use arlux::composite::Composite;
use arlux::image_io::{self, ExrMeta, PixelRect};
use arlux::model::StageTimes;
use arlux::output::{AOV_LAYERS, FrameFiles, FrameWriter, RenderOutput};

use arlux::settings::{Method, RenderOptions};

use crate::common::*;
use crate::timing::*;

/// Arguments of `arlux render`.
#[derive(clap::Args)]
pub struct Args {
    pub scene: PathBuf,
    #[arg(long)]
    pub variant: Option<String>,
    /// Output EXR, with layers direct, indirect (irradiance), change and A (virtual coverage).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also an 8-bit sRGB PNG.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// The PNG's exposure, in stops: its pixels are radiance × 2^EV (the
    /// EXR keeps radiance).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub exposure: f32,
    /// Also each layer as its own EXR in this folder.
    #[arg(long)]
    pub aov: Option<PathBuf>,
    /// Render only this window of the frame, as fractions of its width and
    /// height (pbrt's crop window): columns ⌈w·X0⌉..⌈w·X1⌉, rows likewise.
    /// The EXR holds the window as its data window within the whole frame,
    /// each pixel bit-identical to the whole render's; `arlux merge`
    /// assembles tiles.
    #[arg(long, num_args = 4, value_names = ["X0", "X1", "Y0", "Y1"], allow_negative_numbers = true)]
    pub crop: Option<Vec<f64>>,
    /// The memory a render may hold, as bytes with a suffix (`4G`, `800M`):
    /// the pixel path renders and writes the image in bands of rows that
    /// fit (default: half the memory available, at most 1.5G); the texture
    /// path composites the whole frame, and refuses before linking its
    /// objects when their links (estimated from a sample) would not fit.
    #[arg(long)]
    pub memory: Option<String>,
    #[command(flatten)]
    pub flags: crate::flags::RenderFlags,
    /// Seconds the render may take: as many rounds as fit (at most
    /// --samples when given); the report says how many ran.
    #[arg(long)]
    pub time: Option<f64>,
    #[arg(long)]
    pub json: bool,
}

impl Args {
    fn options(&self) -> RenderOptions {
        let mut options = RenderOptions {
            crop: self.crop.as_ref().map(|c| arlux::image_io::CropWindow {
                x0: c[0],
                x1: c[1],
                y0: c[2],
                y1: c[3],
            }),
            time: self.time,
            ..RenderOptions::default()
        };
        self.flags.apply(&mut options);
        options
    }
}

pub fn run(args: &Args) -> Result<()> {
    let budget = match &args.memory {
        Some(m) => {
            arlux::render::parse_memory(m).map_err(|e| anyhow::anyhow!("--memory {m}: {e}"))?
        }
        None => arlux::render::default_memory(),
    };
    let options = RenderOptions {
        memory: Some(budget),
        ..args.options()
    };
    let method = options.resolve()?;
    if !(args.exposure.is_finite() && args.exposure.abs() <= 64.0) {
        anyhow::bail!("--exposure {}: give stops within ±64", args.exposure);
    }
    let mut times = StageTimes::default();
    let variant = args.variant.as_deref();
    let showing = variant.map_or(arlux::scene::Showing::Base, arlux::scene::Showing::Variant);
    let base = times.time("load", || load_showing(&args.scene, showing))?;
    let scene = match variant {
        Some(v) => base.with_variant(v)?,
        None => base.clone(),
    };
    let reference = variant
        .and_then(|v| base.variant(v).ok())
        .and_then(|v| v.reference.clone());
    // The reference's header now (a bad one refused before any work), its
    // rows as the bands are written.
    let truth = match (variant, &reference) {
        (Some(v), Some(r)) => Some(times.time("check inputs", || {
            base.reference_rows(&format!("variant '{v}'.reference"), r)
        })?),
        _ => None,
    };
    let window = options.crop_pixels(scene.camera.width, scene.camera.height)?;
    let photo = times.time("read photo", || read_photo(&scene))?;
    let meta = ExrMeta {
        window,
        ..frame_meta(&scene, json!({ "variant": variant, "settings": options }))
    };
    let (w, h) = (scene.camera.width, scene.camera.height);
    let rows = arlux::render::band_rows(w, h, budget);
    // The reference is compared band by band as the bands are written (a
    // 24 MP frame and its truth are never held whole), on the window's pixels.
    let window_photo = match window {
        Some(r) if reference.is_some() => std::borrow::Cow::Owned(photo.crop(r)),
        _ => std::borrow::Cow::Borrowed(&photo),
    };
    let mut against = match truth {
        Some(truth) => Some(Against::open(truth, &scene, window, &window_photo)?),
        None => None,
    };
    let out = crate::outputs::Batch::run(|batch| {
        let files = frame_files(args, batch)?;
        let mut writer = FrameWriter::start(&files, w, h, &meta)?;
        let mut written = |writer: &mut FrameWriter, band: &Composite, rows| -> arlux::Result<()> {
            writer.band(band, rows, &photo)?;
            match &mut against {
                Some(a) => writer.image_rows(band, rows, &photo, |piece| a.push(piece)),
                None => Ok(()),
            }
        };
        let out = match &method {
            Method::Pda(settings) => {
                let mut sink = |band: &Composite, rows| written(&mut writer, band, rows);
                arlux::render::render_bands(&scene, &photo, settings, rows, &mut times, &mut sink)?
            }
            Method::Texture(settings) => {
                let mut out = arlux::relight::render_texture(&scene, &photo, settings, &mut times)?;
                // Its composite counts the whole frame; a tile counts its own.
                if let Some(r) = window {
                    out.composite.copied = out.composite.unchanged_in(r, &photo);
                }
                let rows = (0, h);
                times.time("write bands", || written(&mut writer, &out.composite, rows))?;
                if let (Some(dir), Some((_, unoccluded, _))) = (&args.aov, &out.texture) {
                    let layer = [image_io::ExrLayer::Rgb("", unoccluded)];
                    let path = batch.stage(&dir.join("unoccluded_texture.exr"));
                    image_io::write_exr_with(&path, w, h, &layer, &meta)?;
                }
                out
            }
        };
        // Under --strict a warning is an error: nothing is committed.
        for w in &out.warnings {
            warn(&scene, w)?;
        }
        times.time("write", || writer.finish())?;
        Ok(out)
    })?;
    let error = times.time("compare", || against.map(Against::finish));
    keep(&times);
    if let (Some(limit), Some(r)) = (args.time, &out.residual) {
        let took = times.total().as_secs_f64();
        if took > 1.25 * limit {
            // Not a warning (the image is right, only late), so not fatal
            // under --strict: where the change lies in few of many bands,
            // the first band that samples any pixel sets the rounds for all
            // by its share of the rows.
            eprintln!(
                "note: --time {limit}: the render took {took:.1} s ({} rounds, fixed in the first band with pixels to sample); fewer bands (a larger --memory) or --samples N bound it better",
                r.rounds
            );
        }
    }
    let bands = (out.texture.is_none()).then(|| Bands {
        rows,
        count: window
            .unwrap_or(PixelRect::full(w, h))
            .height()
            .div_ceil(rows) as usize,
        memory_budget: budget,
    });
    let report = RenderReport::new(variant, &out, error, &times, window, bands);
    print_report(&report, args.json)
}

/// A variant's reference compared with the render band by band.
struct Against<'a> {
    truth: image_io::RowReader,
    /// The window's rows and columns of the truth's rows.
    window: PixelRect,
    bands: BandComparison<'a>,
}

impl<'a> Against<'a> {
    /// The reference's rows `truth` (at the camera's size) against a
    /// render of `window` (the frame when none) whose photo's part is `photo`.
    fn open(
        mut truth: image_io::RowReader,
        scene: &arlux::scene::Scene,
        window: Option<PixelRect>,
        photo: &'a image_io::Image,
    ) -> Result<Against<'a>> {
        let (w, h) = (scene.camera.width, scene.camera.height);
        let window = window.unwrap_or(PixelRect::full(w, h));
        // The rows above a tile are read and left.
        truth.rows(window.y0)?;
        Ok(Against {
            truth,
            window,
            bands: BandComparison::new(photo),
        })
    }

    /// The window's next image rows, against as many of the truth's.
    fn push(&mut self, image: &[glam::Vec3]) -> arlux::Result<()> {
        let w = (self.window.width() as usize).max(1);
        let full = self.truth.rows((image.len() / w) as u32)?;
        let (x0, x1) = (self.window.x0 as usize, self.window.x1 as usize);
        if x1 - x0 == self.truth.width as usize {
            self.bands.push(image, &full);
        } else {
            let truth: Vec<glam::Vec3> = (full.chunks(self.truth.width as usize))
                .flat_map(|row| row[x0..x1].iter().copied())
                .collect();
            self.bands.push(image, &truth);
        }
        Ok(())
    }

    fn finish(self) -> (Comparison, Skill) {
        self.bands.finish()
    }
}

/// Where each output of `args` goes for now (staged in `batch`).
fn frame_files(args: &Args, batch: &mut crate::outputs::Batch) -> Result<FrameFiles> {
    let mut aov = Vec::new();
    if let Some(dir) = &args.aov {
        batch
            .folder(dir)
            .with_context(|| format!("{}: could not create the folder", dir.display()))?;
        // The noise layer only where rounds of samples run to estimate it.
        let sampled = args.flags.samples > 0 || args.time.is_some();
        for (name, layer) in AOV_LAYERS {
            if layer != arlux::output::FrameLayer::Noise || sampled {
                aov.push((layer, batch.stage(&dir.join(format!("{name}.exr")))));
            }
        }
    }
    Ok(FrameFiles {
        exr: batch.stage(&args.output),
        png: args.png.as_ref().map(|p| (batch.stage(p), args.exposure)),
        aov,
        layers: true,
    })
}

/// How the image was cut into bands.
#[derive(serde::Serialize)]
struct Bands {
    rows: u32,
    count: usize,
    memory_budget: u64,
}

/// `arlux render`'s report.
#[derive(serde::Serialize)]
struct RenderReport<'a> {
    variant: Option<&'a str>,
    crop: Option<Crop>,
    pixels: usize,
    copied_from_photo: usize,
    /// The pixel path renders and writes in bands of rows.
    bands: Option<Bands>,
    /// The process's peak resident memory so far (Linux), bytes.
    peak_memory_bytes: Option<u64>,
    ratio_fallbacks: usize,
    clamped: usize,
    patches: usize,
    patch_size_m: f64,
    links: usize,
    elements: usize,
    links_bytes: usize,
    room_solution_bytes: usize,
    change_bytes: usize,
    method: &'static str,
    /// Shadow and sub-pixel rays (the pixel path's).
    rays: Option<u64>,
    pda_bytes: usize,
    pda_bytes_per_pixel: f64,
    texture: Option<TextureReport>,
    /// What `--samples` / `--time` ran (null: no rounds).
    samples: Option<arlux::residual::ResidualStats>,
    comparison: Option<Comparison>,
    skill: Option<Skill>,
    left_out: &'a [String],
    stages: serde_json::Value,
    seconds: f64,
}

/// A crop window, pixels [x0, x1) × [y0, y1).
#[derive(serde::Serialize)]
struct Crop {
    x0: u32,
    x1: u32,
    y0: u32,
    y1: u32,
}

/// What the texture path did.
#[derive(serde::Serialize)]
struct TextureReport {
    refinement_rounds: usize,
    splits: usize,
    splits_undone: usize,
    leaves: usize,
    occluded_leaves: usize,
    corrected_from_frontier: usize,
    corrected_from_user_reference: usize,
    uncorrected: usize,
    texels: usize,
    texture_bytes: usize,
    light_change_seconds: f64,
    /// Linking the objects as estimated before it started (null: no objects).
    object_links_estimate: Option<arlux::radiosity::ObjectLinkEstimate>,
    /// Groups of the objects' leaves that gathered their light by rays.
    object_gather_groups: usize,
}

impl<'a> RenderReport<'a> {
    fn new(
        variant: Option<&'a str>,
        out: &'a RenderOutput,
        error: Option<(Comparison, Skill)>,
        times: &StageTimes,
        window: Option<PixelRect>,
        bands: Option<Bands>,
    ) -> Self {
        let c = &out.composite;
        // A tile counts its own pixels (the composite counts those only).
        let pixels = window.map_or(out.pda_pixels, |r| r.pixel_count());
        RenderReport {
            variant,
            crop: window.map(|r| Crop {
                x0: r.x0,
                x1: r.x1,
                y0: r.y0,
                y1: r.y1,
            }),
            pixels,
            copied_from_photo: c.copied,
            bands,
            peak_memory_bytes: crate::timing::peak_memory(),
            ratio_fallbacks: c.ratio_fallbacks,
            clamped: c.clamped,
            patches: out.patches,
            patch_size_m: out.patch_size,
            links: out.links,
            elements: out.elements,
            links_bytes: out.links_bytes,
            room_solution_bytes: out.room_solution_bytes,
            change_bytes: out.change_bytes,
            method: if out.texture.is_some() {
                "texture"
            } else {
                "pda"
            },
            rays: out.texture.is_none().then_some(out.rays),
            pda_bytes: out.pda_bytes,
            pda_bytes_per_pixel: out.pda_bytes as f64 / out.pda_pixels.max(1) as f64,
            texture: out.texture.as_ref().map(|(s, _, change)| TextureReport {
                refinement_rounds: s.rounds,
                splits: s.splits,
                splits_undone: s.undone,
                leaves: s.leaves,
                occluded_leaves: s.occluded,
                corrected_from_frontier: s.by_frontier,
                corrected_from_user_reference: s.by_user_reference,
                uncorrected: s.uncorrected,
                texels: s.texels,
                texture_bytes: s.texture_bytes,
                light_change_seconds: change.as_secs_f64(),
                object_links_estimate: s.object_links_estimate,
                object_gather_groups: s.object_gather_groups,
            }),
            samples: out.residual,
            comparison: error.map(|e| e.0),
            skill: error.map(|e| e.1),
            left_out: &out.left_out,
            stages: stages_json(times),
            seconds: times.total().as_secs_f64(),
        }
    }
}

impl Report for RenderReport<'_> {
    const COMMAND: &'static str = "render";

    fn text(&self) -> Vec<String> {
        let mut lines = Vec::new();
        match &self.texture {
            None => lines.push(format!(
                "{} pixels, {} copied from the photo unchanged; {} patches ({:.2} m), {} form factors ({:.1} MB, {:.0} per element); room solution {:.2} MB kept, objects' change {:.2} MB; {} rays; pixel data {:.1} MB ({:.0} bytes per pixel)",
                self.pixels,
                self.copied_from_photo,
                self.patches,
                self.patch_size_m,
                self.links,
                self.links_bytes as f64 / 1e6,
                self.links as f64 / self.elements.max(1) as f64,
                self.room_solution_bytes as f64 / 1e6,
                self.change_bytes as f64 / 1e6,
                self.rays.unwrap_or(0),
                self.pda_bytes as f64 / 1e6,
                self.pda_bytes_per_pixel
            )),
            Some(s) => lines.extend([
                format!(
                    "texture path: {} leaves from {:.2} m patches after {} refinement rounds ({} splits, {} undone: no visibility change); {} form factors ({:.1} MB)",
                    self.patches,
                    self.patch_size_m,
                    s.refinement_rounds,
                    s.splits,
                    s.splits_undone,
                    self.links,
                    self.links_bytes as f64 / 1e6
                ),
                format!(
                    "{} seen leaves in some real shadow: {} corrected from a frontier leaf, {} from the user's [[texture_reference]], {} left as Step 1 made them",
                    s.occluded_leaves,
                    s.corrected_from_frontier,
                    s.corrected_from_user_reference,
                    s.uncorrected
                ),
                format!(
                    "textures {:.1} MB ({} texels); the light change alone (radiosity step + display): {:.3} s (Loscos: 0.8 s)",
                    s.texture_bytes as f64 / 1e6,
                    s.texels,
                    s.light_change_seconds
                ),
            ]),
        }
        if let Some(r) = &self.samples {
            lines.push(format!(
                "per-pixel rounds: {} (--samples {} reproduces them), {} rays in {:.2} s over {} pixels ({} objects', {} near them, {} on shadow edges, {} on outlines); estimated remaining noise {:.2e} RMS ({:.2}% of their mean)",
                r.rounds,
                r.rounds,
                r.rays,
                r.seconds,
                r.pixels(),
                r.object_pixels,
                r.room_pixels,
                r.shadow_pixels,
                r.edge_pixels,
                r.noise_rms,
                100.0 * r.noise_relative
            ));
        }
        if self.ratio_fallbacks > 0 || self.clamped > 0 {
            lines.push(match self.texture {
                None => format!(
                    "{} samples fell back from the ratio to the additive form (dark before), {} were clamped at zero",
                    self.ratio_fallbacks, self.clamped
                ),
                Some(_) => format!(
                    "{} pixels show the radiosity B/π: the photo saw them unlit (D ≈ 0)",
                    self.ratio_fallbacks
                ),
            });
        }
        if let (Some(e), Some(s)) = (&self.comparison, &self.skill) {
            lines.push(format!(
                "against the reference: RMSE {:.5}, relative {:.4}, PSNR {}, mean {:.5} (reference {:.5})",
                e.rmse,
                e.relative_rmse.unwrap_or(f64::NAN),
                e.psnr_srgb_db
                    .map_or("inf".into(), |p| format!("{p:.2} dB")),
                e.mean,
                e.mean_reference
            ));
            lines.push(skill_line(s));
        }
        lines.extend(self.left_out.iter().map(|l| format!("left out: {l}")));
        lines
    }
}
