//! The `arlux` command line: parses arguments and calls the library.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use serde_json::json;

use arlux::compare::{Comparison, compare, read_mask};
use arlux::image_io::{self, Image};
use arlux::scene::{Intensity, LightPosition, LightShape, Photo, Scene};
use arlux::surface_ids::{SurfaceIds, id_colour};
use arlux::trace::Layer;

/// Prints a line to stdout, failing (not panicking) when the reader has
/// gone: `main` turns a broken pipe into a quiet exit.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($arg)*)?;
    }};
}

#[derive(Parser)]
#[command(
    name = "arlux",
    version,
    about = "Per-pixel differential rendering of virtual objects and lights into photographs"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Report wall time per stage (load, tracer, estimation, radiosity,
    /// pixel data array, composite, write, ...) and peak memory, on stderr.
    #[arg(long, global = true)]
    timings: bool,
}

/// Stages timed anywhere in this run, in order, for `--timings`.
static STAGES: std::sync::Mutex<Vec<(String, std::time::Duration)>> =
    std::sync::Mutex::new(Vec::new());

/// Runs `f` as the stage `name` of this run.
fn stage<T>(name: &str, f: impl FnOnce() -> T) -> T {
    let t0 = std::time::Instant::now();
    let out = f();
    STAGES
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push((name.to_string(), t0.elapsed()));
    out
}

/// Marks a stage that ran side by side within another: listed, not summed.
const SIDE_BY_SIDE: &str = "  | ";

/// Adds a library call's stage times to this run's.
fn keep(times: &arlux::model::StageTimes) {
    let mut stages = STAGES.lock().unwrap_or_else(|e| e.into_inner());
    stages.extend(times.0.iter().map(|(n, d)| (n.to_string(), *d)));
    stages.extend(
        times
            .1
            .iter()
            .map(|(n, d)| (format!("{SIDE_BY_SIDE}{n}"), *d)),
    );
}

/// Peak resident memory of this process (Linux: VmHWM), bytes.
fn peak_memory() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The `--timings` report: every stage, what no stage covers, and peak memory.
fn report_timings(wall: std::time::Duration) {
    let stages = STAGES.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let mut merged: Vec<(String, f64)> = Vec::new();
    for (name, d) in stages {
        match merged.iter_mut().find(|(n, _)| *n == name) {
            Some(m) => m.1 += d.as_secs_f64(),
            None => merged.push((name, d.as_secs_f64())),
        }
    }
    let sum: f64 = merged
        .iter()
        .filter(|m| !m.0.starts_with(SIDE_BY_SIDE))
        .map(|m| m.1)
        .sum();
    let wall = wall.as_secs_f64();
    eprintln!("timings:");
    for (name, secs) in &merged {
        eprintln!("  {name:<32} {:>10.1} ms", secs * 1e3);
    }
    eprintln!(
        "  {:<32} {:>10.1} ms",
        "(outside stages)",
        (wall - sum).max(0.0) * 1e3
    );
    eprintln!(
        "  {:<32} {:>10.1} ms  (stages: {:.1}% of it)",
        "wall",
        wall * 1e3,
        100.0 * sum / wall.max(1e-12)
    );
    match peak_memory() {
        Some(b) => eprintln!("  peak memory {:.1} MB", b as f64 / 1e6),
        None => eprintln!("  peak memory: not known on this system"),
    }
}

#[derive(Subcommand)]
enum Command {
    /// Describe a scene: surfaces, triangles, lights, objects, variants, motions, the photo's range.
    Info {
        scene: PathBuf,
        /// Apply this variant first.
        #[arg(long)]
        variant: Option<String>,
        /// Print a JSON report instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Colour each pixel by the surface it sees, beside the photo with the
    /// surfaces' outlines: how to check that the model registers with the photo.
    Ids {
        scene: PathBuf,
        /// Output PNG (2·width × height: surface colours | photo with outlines).
        #[arg(short, long)]
        output: PathBuf,
        /// Also write the ids as an EXR (channel Y: surface index, -1 for none).
        #[arg(long)]
        exr: Option<PathBuf>,
        /// Include the enabled virtual objects (of the variant, if given).
        #[arg(long)]
        with_virtual: bool,
        #[arg(long)]
        variant: Option<String>,
    },
    /// The augmented photo of a variant: virtual objects inserted, lights
    /// changed or added, by per-pixel differential rendering (or, with
    /// --method texture, shadow-free textures × B/D).
    Render {
        scene: PathBuf,
        #[arg(long)]
        variant: Option<String>,
        /// Output EXR, with layers direct, indirect (irradiance), change and A (virtual coverage).
        #[arg(short, long)]
        output: PathBuf,
        /// Also an 8-bit sRGB PNG.
        #[arg(long)]
        png: Option<PathBuf>,
        /// Also each layer as its own EXR in this folder.
        #[arg(long)]
        aov: Option<PathBuf>,
        /// Rendering method: pda (per-pixel differential rendering, Grosch)
        /// or texture (shadow-free textures × B/D, Loscos).
        #[arg(long, default_value = "pda", value_parser = ["pda", "texture"])]
        method: String,
        /// How real pixels take the change: ratio (photo × L_with/L_without) or additive.
        #[arg(long, default_value = "ratio", value_parser = ["ratio", "additive"])]
        composite: String,
        /// The room's largest patch edge, metres (default: from what the
        /// scene changes: the room's diagonal / 24 for light changes, / 6 for
        /// added objects only).
        #[arg(long)]
        patch_size: Option<f64>,
        /// Largest patch edge on virtual objects, metres.
        #[arg(long, default_value_t = 0.1)]
        virtual_patch_size: f64,
        /// Every patch against every other (the form-factor oracle) instead
        /// of hierarchical radiosity; pixel path only.
        #[arg(long)]
        full: bool,
        /// Hierarchical radiosity's link threshold (both methods).
        #[arg(long, default_value_t = arlux::radiosity::DEFAULT_LINK_EPSILON)]
        epsilon: f64,
        /// 2^level shadow rays per rect light everywhere, 2^penumbra_level in penumbra.
        #[arg(long, default_value_t = 2)]
        min_level: usize,
        #[arg(long, default_value_t = 4)]
        penumbra_level: usize,
        /// n×n sub-pixels where real and virtual surfaces meet.
        #[arg(long, default_value_t = 4)]
        supersample: u32,
        /// Texture path: CIELAB distance under which two leaves have similar colour (default 10).
        #[arg(long)]
        colour_threshold: Option<f64>,
        /// Texture path: visibility difference (0..0.5) under which two leaves see a light alike (default 0.2).
        #[arg(long)]
        visibility_threshold: Option<f64>,
        /// Texture path: CIELAB distance under which a frontier leaf may be a reference (default 10).
        #[arg(long)]
        reference_colour_threshold: Option<f64>,
        /// Texture path: the smallest leaf, in pixel footprints (default 3).
        #[arg(long)]
        min_leaf_pixels: Option<f64>,
        #[arg(long)]
        json: bool,
    },
    /// Render a motion: the first pose in full, then an incremental update
    /// per pose, writing DIR/NAME_000.exr, NAME_001.exr, ...
    Motion {
        scene: PathBuf,
        #[arg(long)]
        motion: String,
        /// Output folder (created if missing).
        #[arg(short, long, default_value = ".")]
        output: PathBuf,
        /// PNG of the blocks the last update skipped with one shaft test (first active light).
        #[arg(long)]
        debug_blocks: Option<PathBuf>,
        #[arg(long)]
        json: bool,
    },
    /// Merge 8-bit exposure brackets into an HDR radiance map (Debevec &
    /// Malik): the camera response per channel, then a weighted merge.
    /// Radiance is relative (the base exposure time is unknown).
    Hdr {
        /// An exposure as IMAGE:EV, e.g. brackets/ev-2.png:-2 (at least two).
        #[arg(long = "bracket", required = true)]
        brackets: Vec<String>,
        #[arg(short, long)]
        output: PathBuf,
        /// Also write the recovered response as CSV (code, then ln exposure per channel).
        #[arg(long)]
        response: Option<PathBuf>,
    },
    /// Re-render the photo from the model alone (reflectances estimated from
    /// the photo × (direct + indirect light)), with a mesh view; reports
    /// patches, links, iterations, residual and time per stage.
    Radiosity {
        scene: PathBuf,
        /// Output EXR: the model's radiance, with layers direct, indirect
        /// (irradiance) and reflectance.
        #[arg(short, long)]
        output: PathBuf,
        /// Mesh view PNG (2·width × height: patch colours | render with patch outlines).
        #[arg(long)]
        mesh: Option<PathBuf>,
        /// Largest patch edge in metres.
        #[arg(long, default_value_t = 0.25)]
        patch_size: f64,
        /// Full patch-to-patch matrix instead of hierarchical radiosity.
        #[arg(long)]
        full: bool,
        /// Refinement threshold of hierarchical radiosity.
        #[arg(long, default_value_t = arlux::radiosity::DEFAULT_LINK_EPSILON)]
        epsilon: f64,
        /// 2^level shadow rays per point towards area lights.
        #[arg(long, default_value_t = 4)]
        light_level: usize,
        #[arg(long)]
        json: bool,
    },
    /// Recover the goniometric of the scene's light marked
    /// intensity = "reconstruct" from the photo (Grosch §2.3), with the
    /// reflectances it needs on the way; writes it as an IES LM-63 file.
    Gonio {
        scene: PathBuf,
        /// Output IES file (candela relative to the printed rgb).
        #[arg(short, long)]
        output: PathBuf,
        /// Also a polar plot PNG of the recovered distribution.
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Spacing of the table's vertical angles, degrees.
        #[arg(long, default_value_t = 1.0)]
        vertical_step: f64,
        /// Spacing of its horizontal angles, degrees.
        #[arg(long, default_value_t = 2.5)]
        horizontal_step: f64,
        #[arg(long)]
        json: bool,
    },
    /// Error against run time: render a variant (or a motion) over a grid
    /// of quality settings, measure each against its reference, and write
    /// DIR/sweep.csv and DIR/sweep.png (error against time, Pareto front marked).
    Sweep {
        scene: PathBuf,
        #[arg(long, conflicts_with = "motion", required_unless_present = "motion")]
        variant: Option<String>,
        /// Sweep a motion instead: full first pose, updates after; time and mean error over the poses.
        #[arg(long)]
        motion: Option<String>,
        #[arg(short, long)]
        output: PathBuf,
        /// Six settings from cheapest to dearest, for a smoke check.
        #[arg(long)]
        quick: bool,
        /// Runs per setting; the fastest counts (default 3, 1 with --quick).
        #[arg(long)]
        repeats: Option<usize>,
        #[arg(long)]
        json: bool,
    },
    /// Error of an image against a reference: RMSE and relative RMSE in
    /// linear radiance, PSNR of the sRGB-encoded images, and their means.
    Compare {
        image: PathBuf,
        reference: PathBuf,
        /// Compare only where this PNG is white (grey > 0.5).
        #[arg(long)]
        mask: Option<PathBuf>,
        #[arg(long)]
        json: bool,
    },
}

fn main() -> ExitCode {
    let start = std::time::Instant::now();
    let cli = stage("arguments", Cli::parse);
    let timings = cli.timings;
    let result = run(cli);
    if timings {
        report_timings(start.elapsed());
    }
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // A closed pipe (`arlux info | head`) is not a failure.
            if e.chain().any(|c| {
                c.downcast_ref::<std::io::Error>()
                    .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            }) {
                return ExitCode::SUCCESS;
            }
            eprintln!("error: {e}");
            for cause in e.chain().skip(1) {
                eprintln!("  caused by: {cause}");
            }
            ExitCode::from(2)
        }
    }
}

/// The files a command will write (folders it creates itself are not here).
fn output_files(command: &Command) -> Vec<&Path> {
    let mut out: Vec<&Path> = Vec::new();
    match command {
        Command::Ids { output, exr, .. } => out.extend(
            [Some(output.as_path()), exr.as_deref()]
                .into_iter()
                .flatten(),
        ),
        Command::Render { output, png, .. } => out.extend(
            [Some(output.as_path()), png.as_deref()]
                .into_iter()
                .flatten(),
        ),
        Command::Hdr {
            output, response, ..
        } => out.extend(
            [Some(output.as_path()), response.as_deref()]
                .into_iter()
                .flatten(),
        ),
        Command::Radiosity { output, mesh, .. } => out.extend(
            [Some(output.as_path()), mesh.as_deref()]
                .into_iter()
                .flatten(),
        ),
        Command::Gonio { output, plot, .. } => out.extend(
            [Some(output.as_path()), plot.as_deref()]
                .into_iter()
                .flatten(),
        ),
        Command::Motion { debug_blocks, .. } => out.extend(debug_blocks.as_deref()),
        Command::Info { .. } | Command::Compare { .. } | Command::Sweep { .. } => {}
    }
    out
}

fn run(cli: Cli) -> Result<()> {
    // Refuse an output whose folder is missing before any work, not after it.
    for file in output_files(&cli.command) {
        let dir = file
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        if !dir.is_dir() {
            bail!(arlux::Error::file(
                file,
                format!("cannot write: the folder {} does not exist", dir.display())
            ));
        }
    }
    match cli.command {
        Command::Info {
            scene,
            variant,
            json,
        } => info(&scene, variant.as_deref(), json),
        Command::Ids {
            scene,
            output,
            exr,
            with_virtual,
            variant,
        } => ids(
            &scene,
            &output,
            exr.as_deref(),
            with_virtual,
            variant.as_deref(),
        ),
        Command::Compare {
            image,
            reference,
            mask,
            json,
        } => compare_cmd(&image, &reference, mask.as_deref(), json),
        Command::Render {
            scene,
            variant,
            output,
            png,
            aov,
            method,
            composite,
            patch_size,
            virtual_patch_size,
            full,
            epsilon,
            min_level,
            penumbra_level,
            supersample,
            colour_threshold,
            visibility_threshold,
            reference_colour_threshold,
            min_leaf_pixels,
            json,
        } => {
            let mut settings = render_settings(
                patch_size.unwrap_or(0.25),
                full,
                epsilon,
                min_level,
                penumbra_level,
                supersample,
                &composite,
            )?;
            if let Some(m) = patch_size {
                settings.patch_size = arlux::render::PatchSize::Metres(m);
            }
            if !(virtual_patch_size > 0.0 && virtual_patch_size.is_finite()) {
                bail!(
                    "--virtual-patch-size must be a positive number of metres, not {virtual_patch_size}"
                );
            }
            settings.virtual_patch_size = virtual_patch_size;
            let texture_flags = [
                ("--colour-threshold", colour_threshold, 0.0, f64::INFINITY),
                ("--visibility-threshold", visibility_threshold, 0.0, 0.5),
                (
                    "--reference-colour-threshold",
                    reference_colour_threshold,
                    0.0,
                    f64::INFINITY,
                ),
                ("--min-leaf-pixels", min_leaf_pixels, 0.0, f64::INFINITY),
            ];
            if method == "texture" {
                let d = arlux::render::RenderSettings::default();
                let pda_only = [
                    ("--full", full),
                    ("--composite", composite != "ratio"),
                    ("--min-level", min_level != d.pda.min_level),
                    ("--penumbra-level", penumbra_level != d.pda.penumbra_level),
                    ("--supersample", supersample != d.pda.supersample),
                ];
                if let Some((flag, _)) = pda_only.iter().find(|(_, given)| *given) {
                    bail!(
                        "{flag} applies to --method pda (the texture path casts its shadow rays per leaf and displays T×B/D)"
                    );
                }
            }
            for (flag, value, lo, hi) in texture_flags {
                let Some(v) = value else { continue };
                if method != "texture" {
                    bail!("{flag} applies to --method texture");
                }
                if !(v.is_finite() && v > lo && v < hi) {
                    bail!("{flag} must be a number in ({lo}, {hi}), not {v}");
                }
            }
            let method = match method.as_str() {
                "texture" => {
                    let d = arlux::relight::TextureSettings::default();
                    Method::Texture(arlux::relight::TextureSettings {
                        patch_size,
                        link_epsilon: epsilon,
                        colour_threshold: colour_threshold.unwrap_or(d.colour_threshold),
                        visibility_threshold: visibility_threshold
                            .unwrap_or(d.visibility_threshold),
                        reference_colour_threshold: reference_colour_threshold
                            .unwrap_or(d.reference_colour_threshold),
                        min_leaf_pixels: min_leaf_pixels.unwrap_or(d.min_leaf_pixels),
                        ..d
                    })
                }
                _ => Method::Pda(settings),
            };
            render_cmd(
                &scene,
                variant.as_deref(),
                &output,
                png.as_deref(),
                aov.as_deref(),
                &method,
                json,
            )
        }
        Command::Hdr {
            brackets,
            output,
            response,
        } => hdr_cmd(&brackets, &output, response.as_deref()),
        Command::Motion {
            scene,
            motion,
            output,
            debug_blocks,
            json,
        } => motion_cmd(&scene, &motion, &output, debug_blocks.as_deref(), json),
        Command::Sweep {
            scene,
            variant,
            motion,
            output,
            quick,
            repeats,
            json,
        } => sweep_cmd(
            &scene,
            variant.as_deref(),
            motion.as_deref(),
            &output,
            quick,
            repeats.unwrap_or(if quick { 1 } else { 3 }),
            json,
        ),
        Command::Gonio {
            scene,
            output,
            plot,
            vertical_step,
            horizontal_step,
            json,
        } => gonio_cmd(
            &scene,
            &output,
            plot.as_deref(),
            vertical_step,
            horizontal_step,
            json,
        ),
        Command::Radiosity {
            scene,
            output,
            mesh,
            patch_size,
            full,
            epsilon,
            light_level,
            json,
        } => radiosity_cmd(
            &scene,
            &output,
            mesh.as_deref(),
            patch_size,
            full,
            epsilon,
            light_level,
            json,
        ),
    }
}

fn load(path: &Path, variant: Option<&str>) -> Result<Scene> {
    let scene = Scene::load(path)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    Ok(match variant {
        Some(v) => scene.with_variant(v)?,
        None => scene,
    })
}

fn rel(scene: &Scene, p: &Path) -> String {
    p.strip_prefix(scene.dir())
        .unwrap_or(p)
        .display()
        .to_string()
}

fn fmt3(v: glam::DVec3) -> String {
    format!("[{}, {}, {}]", v.x, v.y, v.z)
}

/// Range figures of the photo, per channel and over all.
fn photo_range(img: &Image) -> serde_json::Value {
    let mut min = [f32::INFINITY; 3];
    let mut max = [f32::NEG_INFINITY; 3];
    let mut min_positive = f32::INFINITY;
    for p in &img.pixels {
        for c in 0..3 {
            min[c] = min[c].min(p[c]);
            max[c] = max[c].max(p[c]);
            if p[c] > 0.0 {
                min_positive = min_positive.min(p[c]);
            }
        }
    }
    let peak = max.iter().copied().fold(0.0f32, f32::max);
    json!({
        "width": img.width, "height": img.height,
        "min": min, "max": max, "mean": img.mean(),
        "dynamic_range": if min_positive.is_finite() { Some(peak / min_positive) } else { None },
    })
}

fn info(path: &Path, variant: Option<&str>, as_json: bool) -> Result<()> {
    let scene = stage("load", || load(path, variant))?;
    let names = scene.surface_names();
    let photo = match &scene.photo {
        Photo::Image(p) => {
            let img = stage("read photo", || scene.load_photo())?;
            json!({ "image": rel(&scene, p), "range": stage("photo range", || photo_range(&img)) })
        }
        Photo::Brackets(bs) => json!({
            "brackets": bs.iter().map(|b| json!({ "image": rel(&scene, &b.image), "ev": b.ev })).collect::<Vec<_>>(),
        }),
    };
    stage("report", || info_report(&scene, &names, photo, as_json))
}

fn info_report(
    scene: &Scene,
    names: &[String],
    photo: serde_json::Value,
    as_json: bool,
) -> Result<()> {
    let surfaces: Vec<_> = scene
        .surfaces
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let known = scene.reflectances.iter().find(|k| k.surface == i).map(|k| k.rgb.to_array());
            json!({ "id": i, "name": s.name, "triangles": s.triangles.len(), "mesh": rel(scene, &s.mesh), "known_reflectance": known })
        })
        .collect();
    let lights: Vec<_> = scene
        .lights
        .iter()
        .map(|l| {
            let position = match &l.position {
                LightPosition::Known(p) => fmt3(*p),
                LightPosition::FromShadows(c) => {
                    format!("from {} shadow lines and {} shadow planes", c.lines.len(), c.planes.len())
                }
            };
            let shape = match l.shape {
                LightShape::Point => "point".to_string(),
                LightShape::Rect { u, v } => format!("rect {:.3} x {:.3} m", u.length(), v.length()),
            };
            let intensity = match &l.intensity {
                Intensity::Uniform(rgb) => format!("uniform {}", fmt3(*rgb)),
                Intensity::Lambertian { rgb, .. } => format!("lambertian {}", fmt3(*rgb)),
                Intensity::Spot { rgb, beam_deg, cutoff_deg, .. } => {
                    format!("spot {} beam {beam_deg}° cutoff {cutoff_deg}°", fmt3(*rgb))
                }
                Intensity::Ies { file, rgb, .. } => format!("ies {} x {}", rel(scene, file), fmt3(*rgb)),
                Intensity::Reconstruct => "reconstruct from the photo".to_string(),
            };
            json!({ "name": l.name, "real": l.real, "scale": l.scale, "position": position, "shape": shape, "intensity": intensity })
        })
        .collect();
    let objects: Vec<_> = scene
        .objects
        .iter()
        .map(|o| {
            json!({
                "name": o.name, "mesh": rel(scene, &o.mesh), "enabled": o.enabled,
                "triangles": o.surfaces.iter().map(|s| s.triangles.len()).sum::<usize>(),
                "surfaces": o.surfaces.iter().map(|s| json!({ "name": s.name, "rgb": s.rgb.to_array() })).collect::<Vec<_>>(),
                "translate": o.pose.translate.to_array(), "rotate_y_deg": o.pose.rotate_y_deg, "scale": o.pose.scale,
            })
        })
        .collect();
    let variants: Vec<_> = scene
        .variants
        .iter()
        .map(|v| {
            json!({
                "name": v.name,
                "lights": v.lights.iter().map(|(l, s)| json!({ "light": scene.lights[*l].name, "scale": s })).collect::<Vec<_>>(),
                "objects": v.objects.iter().map(|(o, _)| scene.objects[*o].name.clone()).collect::<Vec<_>>(),
                "hide": v.hide_objects.iter().map(|o| scene.objects[*o].name.clone())
                    .chain(v.hide_lights.iter().map(|l| scene.lights[*l].name.clone())).collect::<Vec<_>>(),
                "reference": v.reference.as_ref().map(|r| rel(scene, r)),
            })
        })
        .collect();
    let motions: Vec<_> = scene
        .motions
        .iter()
        .map(|m| {
            json!({ "name": m.name, "object": scene.objects[m.object].name, "poses": m.translations.len(), "references": m.references.len() })
        })
        .collect();
    let c = &scene.camera;
    let report = json!({
        "name": scene.name, "file": scene.file.display().to_string(),
        "camera": { "width": c.width, "height": c.height, "position": c.position.to_array(), "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy },
        "photo": photo, "surfaces": surfaces, "triangles": scene.triangle_count(), "lights": lights,
        "virtual_objects": objects, "variants": variants, "motions": motions, "warnings": scene.warnings,
        "all_surface_names": names,
    });
    let mut out = std::io::stdout().lock();
    if as_json {
        writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
        return Ok(());
    }
    writeln!(out, "scene '{}' ({})", scene.name, scene.file.display())?;
    writeln!(
        out,
        "camera: {}x{} px, fx {:.2} fy {:.2}, principal point ({:.1}, {:.1})",
        c.width, c.height, c.fx, c.fy, c.cx, c.cy
    )?;
    match &report["photo"]["range"] {
        serde_json::Value::Null => writeln!(out, "photo: {}", report["photo"])?,
        r => writeln!(
            out,
            "photo: {} {}x{}, min {} max {} mean {:.5}, dynamic range {}:1",
            report["photo"]["image"].as_str().unwrap_or(""),
            r["width"],
            r["height"],
            r["min"],
            r["max"],
            r["mean"].as_f64().unwrap_or(0.0),
            r["dynamic_range"]
                .as_f64()
                .map_or("n/a".into(), |d| format!("{d:.0}")),
        )?,
    }
    writeln!(
        out,
        "real surfaces: {} ({} triangles)",
        scene.surfaces.len(),
        scene.triangle_count()
    )?;
    for s in &surfaces {
        let known = s["known_reflectance"]
            .as_array()
            .map(|k| {
                format!(
                    "  known reflectance {}",
                    serde_json::Value::Array(k.clone())
                )
            })
            .unwrap_or_default();
        writeln!(
            out,
            "  {:>3} {:<16} {:>6} triangles  {}{}",
            s["id"],
            s["name"].as_str().unwrap_or(""),
            s["triangles"],
            s["mesh"].as_str().unwrap_or(""),
            known
        )?;
    }
    writeln!(out, "lights: {}", lights.len())?;
    for l in &lights {
        writeln!(
            out,
            "  {:<12} {:<7} scale {:<4} at {}  {}  {}",
            l["name"].as_str().unwrap_or(""),
            if l["real"].as_bool().unwrap_or(true) {
                "real"
            } else {
                "virtual"
            },
            l["scale"],
            l["position"].as_str().unwrap_or(""),
            l["shape"].as_str().unwrap_or(""),
            l["intensity"].as_str().unwrap_or("")
        )?;
    }
    writeln!(out, "virtual objects: {}", objects.len())?;
    for o in &objects {
        writeln!(
            out,
            "  {:<12} {} triangles, {}, at {} rotated {}°",
            o["name"].as_str().unwrap_or(""),
            o["triangles"],
            if o["enabled"].as_bool().unwrap_or(false) {
                "enabled"
            } else {
                "disabled"
            },
            o["translate"],
            o["rotate_y_deg"]
        )?;
    }
    writeln!(out, "variants: {}", variants.len())?;
    for v in &variants {
        writeln!(
            out,
            "  {:<20} reference {}",
            v["name"].as_str().unwrap_or(""),
            v["reference"].as_str().unwrap_or("none")
        )?;
    }
    writeln!(out, "motions: {}", motions.len())?;
    for m in &motions {
        writeln!(
            out,
            "  {:<20} moves {} through {} poses ({} references)",
            m["name"].as_str().unwrap_or(""),
            m["object"].as_str().unwrap_or(""),
            m["poses"],
            m["references"]
        )?;
    }
    Ok(())
}

/// The photo to draw outlines on: the HDR photo, or for brackets the
/// exposure nearest EV 0 (decoded from sRGB; only for looking at).
fn display_photo(scene: &Scene) -> Result<Image> {
    match &scene.photo {
        Photo::Image(_) => Ok(scene.load_photo()?),
        Photo::Brackets(bs) => {
            let b = bs
                .iter()
                .min_by(|a, b| a.ev.abs().total_cmp(&b.ev.abs()))
                .context("no brackets")?;
            let img = image_io::read_image(&b.image)?;
            scene.check_size(&img, "photo.brackets")?;
            Ok(img)
        }
    }
}

fn ids(
    path: &Path,
    output: &Path,
    exr: Option<&Path>,
    with_virtual: bool,
    variant: Option<&str>,
) -> Result<()> {
    let scene = stage("load", || load(path, variant))?;
    let photo = stage("read photo", || display_photo(&scene))?;
    let tracer = stage("tracer", || scene.build_tracer())?;
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
    say!(
        "{} of {} pixels see a surface; wrote {}",
        ids.covered(),
        ids.ids.len(),
        output.display()
    );
    for (i, name) in names.iter().enumerate() {
        let n = ids.ids.iter().filter(|&&s| s == i as i32).count();
        if n > 0 {
            let [r, g, b] = id_colour(i as i32);
            say!(
                "  {i:>3} {name:<20} #{r:02x}{g:02x}{b:02x}  {:5.1}% of the image",
                100.0 * n as f64 / total
            );
        }
    }
    Ok(())
}

fn compare_cmd(image: &Path, reference: &Path, mask: Option<&Path>, as_json: bool) -> Result<()> {
    let (a, b) = stage("load", || -> Result<(Image, Image)> {
        Ok((
            image_io::read_image(image)?,
            image_io::read_image(reference)?,
        ))
    })?;
    if (a.width, a.height) != (b.width, b.height) {
        bail!(arlux::Error::file(
            image,
            format!(
                "is {}x{} but {} is {}x{}",
                a.width,
                a.height,
                reference.display(),
                b.width,
                b.height
            )
        ));
    }
    let mask = mask.map(|m| read_mask(m, a.width, a.height)).transpose()?;
    let c: Comparison = stage("compare", || compare(&a, &b, mask.as_deref()));
    if as_json {
        say!("{}", serde_json::to_string_pretty(&c)?);
    } else {
        say!("pixels         {}", c.pixels);
        say!("rmse           {:.6}", c.rmse);
        say!(
            "relative rmse  {}",
            c.relative_rmse
                .map_or("n/a (black reference)".into(), |r| format!("{:.4}", r))
        );
        say!(
            "psnr (sRGB)    {}",
            c.psnr_srgb_db
                .map_or("inf (identical)".into(), |p| format!("{p:.2} dB"))
        );
        say!("mean           {:.6}", c.mean);
        say!("mean reference {:.6}", c.mean_reference);
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
/// The photo in the scene's units: merged brackets scaled by the known reflectances.
fn photo_in_units(
    scene: &Scene,
    tracer: &arlux::trace::Tracer,
    times: &mut arlux::model::StageTimes,
) -> Result<Image> {
    let mut photo = times.time("read photo", || scene.load_photo())?;
    if scene.photo_is_relative() {
        let base = arlux::model::ModelSettings::default();
        match times.time("bracket scale", || {
            arlux::render::bracket_scale_cached(
                scene,
                &photo,
                tracer,
                &base,
                arlux::render::fine_patch_size(scene),
            )
        }) {
            Some(s) => photo.pixels.iter_mut().for_each(|p| *p *= s as f32),
            None => eprintln!(
                "warning: the photo comes from brackets and no reflectance is known: radiance is relative"
            ),
        }
    }
    Ok(photo)
}

fn sweep_cmd(
    path: &Path,
    variant: Option<&str>,
    motion: Option<&str>,
    dir: &Path,
    quick: bool,
    repeats: usize,
    as_json: bool,
) -> Result<()> {
    if repeats == 0 {
        bail!("--repeats must be at least 1");
    }
    use arlux::sweep::{Target, grid, plot, run, to_csv};
    let scene = stage("load", || load(path, None))?;
    let (target, label) = match (variant, motion) {
        (_, Some(m)) => (Target::Motion { name: m }, format!("motion {m}")),
        (Some(v), None) => (Target::Variant { name: v }, format!("variant {v}")),
        (None, None) => bail!("give --variant or --motion"),
    };
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: could not create the folder", dir.display()))?;
    let settings = grid(quick, matches!(target, Target::Variant { .. }));
    let bar = indicatif::ProgressBar::new(settings.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} settings, {elapsed} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let rows = stage("renders", || {
        run(&scene, &target, &settings, repeats, |_, row| {
            bar.set_message(format!("last: {:.2} s, RMSE {:.5}", row.seconds, row.rmse));
            bar.inc(1);
        })
    })?;
    bar.finish_and_clear();
    let reference = match &target {
        Target::Variant { name } => scene
            .variant(name)?
            .reference
            .as_ref()
            .map_or(String::new(), |r| rel(&scene, r)),
        Target::Motion { name } => format!(
            "{} references of motion {name}",
            scene.motion(name)?.references.len()
        ),
    };
    let csv = dir.join("sweep.csv");
    let png = dir.join("sweep.png");
    stage("write", || -> Result<()> {
        image_io::write_atomic(&csv, to_csv(&rows, &reference).as_bytes())?;
        plot(
            &rows,
            &format!(
                "{}: {label}, error against time ({} settings)",
                scene.name,
                rows.len()
            ),
            &png,
        )?;
        Ok(())
    })?;
    let mut front: Vec<&arlux::sweep::SweepRow> = rows.iter().filter(|r| r.pareto).collect();
    front.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
    let describe = |r: &arlux::sweep::SweepRow| {
        let s = &r.settings;
        let method = match s.method {
            arlux::sweep::SweepMethod::Pda => json!("pda"),
            arlux::sweep::SweepMethod::Texture { min_leaf_pixels } => {
                json!({ "texture": { "min_leaf_pixels": min_leaf_pixels } })
            }
        };
        json!({
            "method": method,
            "shadow_rays": [1u32 << s.min_level, 1u32 << s.penumbra_level], "supersample": s.supersample,
            "patch_size": s.patch_size, "virtual_patch_size": matches!(s.method, arlux::sweep::SweepMethod::Pda).then_some(s.virtual_patch_size),
            "epsilon": s.epsilon, "seconds": r.seconds, "rmse": r.rmse,
            "relative_rmse": r.relative_rmse, "pareto": r.pareto,
        })
    };
    if as_json {
        say!(
            "{}",
            serde_json::to_string_pretty(&json!({
                "target": label, "settings": rows.len(), "csv": csv.display().to_string(), "plot": png.display().to_string(),
                "rows": rows.iter().map(describe).collect::<Vec<_>>(),
            }))?
        );
        return Ok(());
    }
    say!(
        "{} settings of {label}; wrote {} and {}",
        rows.len(),
        csv.display(),
        png.display()
    );
    say!("Pareto front (faster and closer than nothing else):");
    say!(
        "  {:>7} {:>11} {:>10} {:>10} {:>8} {:>8} {:>9} {:>10}",
        "method",
        "shadow rays",
        "supersamp.",
        "patch",
        "objects",
        "epsilon",
        "seconds",
        "RMSE"
    );
    for r in front {
        let s = &r.settings;
        let (method, rays, supersample) = match s.method {
            arlux::sweep::SweepMethod::Pda => (
                "pda",
                format!("{}-{}", 1u32 << s.min_level, 1u32 << s.penumbra_level),
                s.supersample.to_string(),
            ),
            arlux::sweep::SweepMethod::Texture { min_leaf_pixels } => (
                "texture",
                format!("leaf {min_leaf_pixels} px"),
                "-".to_string(),
            ),
        };
        let objects = match s.method {
            arlux::sweep::SweepMethod::Pda => format!("{} m", s.virtual_patch_size),
            arlux::sweep::SweepMethod::Texture { .. } => "-".to_string(),
        };
        say!(
            "  {:>7} {:>11} {:>10} {:>10} {:>8} {:>8} {:>9.3} {:>10.6}",
            method,
            rays,
            supersample,
            s.patch_size
                .map_or("auto".to_string(), |m| format!("{m} m")),
            objects,
            s.epsilon,
            r.seconds,
            r.rmse
        );
    }
    Ok(())
}

fn gonio_cmd(
    path: &Path,
    output: &Path,
    plot: Option<&Path>,
    vertical_step: f64,
    horizontal_step: f64,
    as_json: bool,
) -> Result<()> {
    use arlux::gonio::{GonioSettings, ReflectanceSource, reconstruct};
    for (name, v, max) in [
        ("--vertical-step", vertical_step, 90.0),
        ("--horizontal-step", horizontal_step, 90.0),
    ] {
        if !(v > 0.0 && v <= max) {
            bail!("{name} must be in (0, {max}] degrees, not {v}");
        }
    }
    let mut times = arlux::model::StageTimes::default();
    let scene = times.time("load", || load(path, None))?;
    if arlux::gonio::light_to_reconstruct(&scene)?.is_none() {
        bail!(
            "{}: no light has intensity = \"reconstruct\"",
            path.display()
        );
    }
    let tracer = times.time("tracer", || scene.build_tracer())?;
    let photo = photo_in_units(&scene, &tracer, &mut times)?;
    let settings = GonioSettings {
        vertical_step_deg: vertical_step,
        horizontal_step_deg: horizontal_step,
        ..GonioSettings::default()
    };
    let rec = times.time("reconstruct", || {
        reconstruct(&scene, &photo, &tracer, &settings)
    })?;
    times.time("write", || -> Result<()> {
        image_io::write_atomic(output, rec.profile.to_lm63().as_bytes())?;
        if let Some(plot) = plot {
            let (w, h, rgb) = arlux::gonio::polar_plot(&rec);
            image_io::write_png_rgb8(plot, w, h, rgb)?;
        }
        Ok(())
    })?;
    let light = &scene.lights[rec.light];
    let (peak, peak_dir) = arlux::gonio::peak(&rec);
    let surfaces: Vec<_> = rec
        .reflectances
        .iter()
        .map(|r| {
            let (source, step, angle) = match r.source {
                ReflectanceSource::Known => ("known", None, None),
                ReflectanceSource::Propagated { step, angle_deg, .. } => ("EQ2", Some(step), Some(angle_deg)),
                ReflectanceSource::Unreached => ("unreached", None, None),
            };
            json!({ "surface": r.name, "rgb": r.rgb.map(|c| c.to_array()), "source": source, "step": step, "angle_deg": angle })
        })
        .collect();
    keep(&times);
    let report = json!({
        "light": light.name,
        "position": rec.position.to_array(),
        "rgb": rec.colour.to_array(),
        "peak_candela": peak,
        "peak_direction": peak_dir.to_array(),
        "coverage": rec.coverage,
        "colour_residual": rec.colour_residual,
        "rounds": rec.rounds,
        "last_change": rec.change,
        "samples": rec.samples,
        "patches": rec.patches,
        "reconstruction_seconds": rec.seconds,
        "paper_seconds": 97.9,
        "reflectances": surfaces,
        "output": output.display().to_string(),
        "stages": stages_json(&times),
        "total_seconds": times.total().as_secs_f64(),
    });
    if as_json {
        say!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    say!(
        "light '{}' at {}: reconstructed from {} pixels ({} patches for the indirect light), {} rounds (last change {:.1e} of the peak)",
        light.name,
        fmt3(rec.position),
        rec.samples,
        rec.patches,
        rec.rounds,
        rec.change
    );
    say!(
        "peak {:.3} × rgb {} towards {}; {:.1}% of the sphere is known from the photo (the rest is 0 and marked unknown)",
        peak,
        fmt3(rec.colour),
        fmt3(peak_dir),
        100.0 * rec.coverage
    );
    for r in &rec.reflectances {
        let rgb = r.rgb.map_or("-".to_string(), |c| {
            format!("[{:.3}, {:.3}, {:.3}]", c.x, c.y, c.z)
        });
        match r.source {
            ReflectanceSource::Known => say!("  {:<14} {rgb}  known", r.name),
            ReflectanceSource::Propagated {
                step,
                angle_deg,
                samples,
            } => {
                say!(
                    "  {:<14} {rgb}  EQ2 step {step}, from directions within {angle_deg:.2}° ({samples} pixels)",
                    r.name
                )
            }
            ReflectanceSource::Unreached => say!(
                "  {:<14} -  not lit by this light where the photo sees it",
                r.name
            ),
        }
    }
    say!(
        "reconstruction {:.2} s (Grosch et al.: 97.9 s for 282 patches); total {:.2} s",
        rec.seconds,
        times.total().as_secs_f64()
    );
    say!(
        "wrote {}; use it as: intensity = {{ ies = \"{}\", rgb = [{:.4}, {:.4}, {:.4}], direction = [0.0, -1.0, 0.0], reference = [1.0, 0.0, 0.0] }}",
        output.display(),
        output.display(),
        rec.colour.x,
        rec.colour.y,
        rec.colour.z
    );
    Ok(())
}

// One argument per command-line flag.
#[allow(clippy::too_many_arguments)]
fn radiosity_cmd(
    path: &Path,
    output: &Path,
    mesh: Option<&Path>,
    patch_size: f64,
    full: bool,
    epsilon: f64,
    light_level: usize,
    as_json: bool,
) -> Result<()> {
    use arlux::model::{Model, ModelSettings, ModelView, StageTimes, TransportMethod};
    if !(patch_size > 0.0 && patch_size.is_finite()) {
        bail!("--patch-size must be a positive number of metres, not {patch_size}");
    }
    if !(epsilon > 0.0 && epsilon.is_finite()) {
        bail!("--epsilon must be positive, not {epsilon}");
    }
    if light_level > arlux::light::MAX_GRID_LEVEL {
        bail!(
            "--light-level must be at most {}",
            arlux::light::MAX_GRID_LEVEL
        );
    }
    let mut times = StageTimes::default();
    let scene = times.time("load", || load(path, None))?;
    let tracer = times.time("tracer", || scene.build_tracer())?;
    let photo = photo_in_units(&scene, &tracer, &mut times)?;
    // A light to reconstruct is recovered first, as `render` does.
    let scene = match arlux::gonio::light_to_reconstruct(&scene)? {
        Some(_) => times.time("goniometric", || {
            arlux::render::reconstruct_cached(&scene, &photo, &tracer)
        })?,
        None => scene,
    };
    let settings = ModelSettings {
        patch_size,
        transport: if full {
            TransportMethod::Full
        } else {
            TransportMethod::Hierarchical { epsilon }
        },
        light_level,
        ..ModelSettings::default()
    };
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
    let report = json!({
        "patches": model.patches.patch_count(),
        "elements": model.patches.elements.len(),
        "transport": if full { "full" } else { "hierarchical" },
        "links": model.transport.link_count(),
        "transport_bytes": model.transport.memory_bytes(),
        "estimate_iterations": est.iterations,
        "estimate_change": est.change,
        "clamped_patches": est.clamped,
        "unseen_patches": est.unseen,
        "solver_iterations": est.solution.iterations,
        "solver_residual": est.solution.residual,
        "shadow_rays": view.rays,
        "error_against_photo": error,
        "stages": stages_json(&times),
        "total_seconds": times.total().as_secs_f64(),
    });
    if as_json {
        say!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    say!(
        "{} patches ({} elements), {} transport with {} form factors ({:.1} MB)",
        model.patches.patch_count(),
        model.patches.elements.len(),
        if full { "full" } else { "hierarchical" },
        model.transport.link_count(),
        model.transport.memory_bytes() as f64 / 1e6
    );
    say!(
        "reflectances: {} fixed-point iterations (last change {:.1e}), {} patches clamped to [0, {}], {} unseen patches took their surface's mean",
        est.iterations,
        est.change,
        est.clamped,
        arlux::estimate::MAX_REFLECTANCE,
        est.unseen
    );
    say!(
        "radiosity: GMRES {} iterations, residual {:.1e}",
        est.solution.iterations,
        est.solution.residual
    );
    say!(
        "model against the photo: RMSE {:.5}, relative {:.3}, PSNR {}",
        error.rmse,
        error.relative_rmse.unwrap_or(f64::NAN),
        error
            .psnr_srgb_db
            .map_or("inf".into(), |p| format!("{p:.2} dB"))
    );
    print_stages(&times)?;
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn render_settings(
    patch_size: f64,
    full: bool,
    epsilon: f64,
    min_level: usize,
    penumbra_level: usize,
    supersample: u32,
    composite: &str,
) -> Result<arlux::render::RenderSettings> {
    use arlux::model::{ModelSettings, TransportMethod};
    use arlux::render::RenderSettings;
    if !(patch_size > 0.0 && patch_size.is_finite()) {
        bail!("--patch-size must be a positive number of metres, not {patch_size}");
    }
    if !(epsilon > 0.0 && epsilon.is_finite()) {
        bail!("--epsilon must be positive, not {epsilon}");
    }
    let max = arlux::light::MAX_GRID_LEVEL;
    if min_level > max || penumbra_level > max || penumbra_level < min_level {
        bail!("--min-level and --penumbra-level must satisfy min-level <= penumbra-level <= {max}");
    }
    if !(1..=16).contains(&supersample) {
        bail!("--supersample must lie in 1..=16, not {supersample}");
    }
    let defaults = RenderSettings::default();
    Ok(RenderSettings {
        model: ModelSettings {
            patch_size,
            transport: if full {
                TransportMethod::Full
            } else {
                TransportMethod::Hierarchical { epsilon }
            },
            ..ModelSettings::default()
        },
        pda: arlux::pda::PdaSettings {
            min_level,
            penumbra_level,
            supersample,
        },
        mode: if composite == "additive" {
            arlux::composite::CompositeMode::Additive
        } else {
            arlux::composite::CompositeMode::Ratio
        },
        ..defaults
    })
}

/// How `render` renders.
enum Method {
    Pda(arlux::render::RenderSettings),
    Texture(arlux::relight::TextureSettings),
}

fn render_cmd(
    path: &Path,
    variant: Option<&str>,
    output: &Path,
    png: Option<&Path>,
    aov: Option<&Path>,
    method: &Method,
    as_json: bool,
) -> Result<()> {
    use arlux::model::StageTimes;
    let mut times = StageTimes::default();
    let base = times.time("load", || load(path, None))?;
    let scene = match variant {
        Some(v) => base.with_variant(v)?,
        None => base.clone(),
    };
    let reference = variant
        .and_then(|v| base.variant(v).ok())
        .and_then(|v| v.reference.clone());
    let photo = times.time("read photo", || scene.load_photo())?;
    let out = match method {
        Method::Pda(settings) => arlux::render::render(&scene, &photo, settings, &mut times)?,
        Method::Texture(settings) => {
            arlux::relight::render_texture(&scene, &photo, settings, &mut times)?
        }
    };
    let c = &out.composite;
    times.time("write", || -> Result<()> {
        let (w, h) = (photo.width, photo.height);
        let layers = [
            image_io::ExrLayer::Rgb("", &c.image),
            image_io::ExrLayer::Rgb("direct", &c.direct),
            image_io::ExrLayer::Rgb("indirect", &c.indirect),
            image_io::ExrLayer::Rgb("change", &c.change),
            image_io::ExrLayer::Channel("A", &c.alpha),
        ];
        image_io::write_exr(output, w, h, &layers)?;
        if let Some(png) = png {
            image_io::write_png(png, &c.image, 0.0)?;
        }
        if let Some(dir) = aov {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("{}: could not create the folder", dir.display()))?;
            for (name, img) in [
                ("direct", &c.direct),
                ("indirect", &c.indirect),
                ("change", &c.change),
            ] {
                image_io::write_exr(
                    &dir.join(format!("{name}.exr")),
                    w,
                    h,
                    &[image_io::ExrLayer::Rgb("", img)],
                )?;
            }
            image_io::write_exr(
                &dir.join("alpha.exr"),
                w,
                h,
                &[image_io::ExrLayer::Channel("Y", &c.alpha)],
            )?;
            if let Some((_, unoccluded, _)) = &out.texture {
                image_io::write_exr(
                    &dir.join("unoccluded_texture.exr"),
                    w,
                    h,
                    &[image_io::ExrLayer::Rgb("", unoccluded)],
                )?;
            }
        }
        Ok(())
    })?;
    let error = times.time("compare", || -> Result<Option<Comparison>> {
        match &reference {
            Some(r) => {
                let truth = image_io::read_image(r)?;
                scene.check_size(&truth, "variant.reference")?;
                Ok(Some(compare(&c.image, &truth, None)))
            }
            None => Ok(None),
        }
    })?;
    keep(&times);
    let report = json!({
        "variant": variant,
        "pixels": out.pda_pixels,
        "copied_from_photo": c.copied,
        "ratio_fallbacks": c.ratio_fallbacks,
        "clamped": c.clamped,
        "patches": out.patches,
        "patch_size_m": out.patch_size,
        "links": out.links,
        "method": if out.texture.is_some() { "texture" } else { "pda" },
        "rays": out.texture.is_none().then_some(out.rays),
        "pda_bytes": out.pda_bytes,
        "pda_bytes_per_pixel": out.pda_bytes as f64 / out.pda_pixels.max(1) as f64,
        "texture": out.texture.as_ref().map(|(s, _, change)| json!({
            "refinement_rounds": s.rounds, "splits": s.splits, "splits_undone": s.undone, "leaves": s.leaves,
            "occluded_leaves": s.occluded, "corrected_from_frontier": s.by_frontier,
            "corrected_from_user_reference": s.by_user_reference, "uncorrected": s.uncorrected,
            "texels": s.texels, "texture_bytes": s.texture_bytes, "light_change_seconds": change.as_secs_f64(),
        })),
        "error_against_reference": error,
        "left_out": out.left_out,
        "stages": stages_json(&times),
        "total_seconds": times.total().as_secs_f64(),
    });
    if as_json {
        say!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    match &out.texture {
        None => say!(
            "{} pixels, {} copied from the photo unchanged; {} patches ({:.2} m), {} form factors; {} rays; pixel data {:.1} MB ({:.0} bytes per pixel)",
            out.pda_pixels,
            c.copied,
            out.patches,
            out.patch_size,
            out.links,
            out.rays,
            out.pda_bytes as f64 / 1e6,
            out.pda_bytes as f64 / out.pda_pixels.max(1) as f64
        ),
        Some((s, _, change)) => {
            say!(
                "texture path: {} leaves from {:.2} m patches after {} refinement rounds ({} splits, {} undone: no visibility change); {} form factors",
                out.patches,
                out.patch_size,
                s.rounds,
                s.splits,
                s.undone,
                out.links
            );
            say!(
                "{} seen leaves in some real shadow: {} corrected from a frontier leaf, {} from the user's [[texture_reference]], {} left as Step 1 made them",
                s.occluded,
                s.by_frontier,
                s.by_user_reference,
                s.uncorrected
            );
            say!(
                "textures {:.1} MB ({} texels); the light change alone (radiosity step + display): {:.3} s (Loscos: 0.8 s)",
                s.texture_bytes as f64 / 1e6,
                s.texels,
                change.as_secs_f64()
            );
        }
    }
    if c.ratio_fallbacks > 0 || c.clamped > 0 {
        match out.texture {
            None => say!(
                "{} samples fell back from the ratio to the additive form (dark before), {} were clamped at zero",
                c.ratio_fallbacks,
                c.clamped
            ),
            Some(_) => say!(
                "{} pixels show the radiosity B/π: the photo saw them unlit (D ≈ 0)",
                c.ratio_fallbacks
            ),
        }
    }
    if let Some(e) = error {
        say!(
            "against the reference: RMSE {:.5}, relative {:.4}, PSNR {}, mean {:.5} (reference {:.5})",
            e.rmse,
            e.relative_rmse.unwrap_or(f64::NAN),
            e.psnr_srgb_db
                .map_or("inf".into(), |p| format!("{p:.2} dB")),
            e.mean,
            e.mean_reference
        );
    }
    for l in &out.left_out {
        say!("left out: {l}");
    }
    print_stages(&times)?;
    Ok(())
}

fn hdr_cmd(brackets: &[String], output: &Path, response_csv: Option<&Path>) -> Result<()> {
    use arlux::hdr::{Exposure, merge, recover_response};
    let mut exposures = Vec::new();
    for b in brackets {
        let Some((path, ev)) = b.rsplit_once(':') else {
            bail!("--bracket {b}: give IMAGE:EV, e.g. ev-2.png:-2");
        };
        let ev: f64 = ev
            .trim()
            .parse()
            .map_err(|_| anyhow::anyhow!("--bracket {b}: '{ev}' is not an EV number"))?;
        if !ev.is_finite() {
            bail!("--bracket {b}: the EV must be finite");
        }
        exposures.push(stage("load", || Exposure::read(Path::new(path), ev))?);
    }
    let response = stage("response", || recover_response(&exposures, 64, 20.0))?;
    let merged = stage("merge", || merge(&exposures, &response))?;
    stage("write", || -> Result<()> {
        image_io::write_exr(
            output,
            merged.image.width,
            merged.image.height,
            &[image_io::ExrLayer::Rgb("", &merged.image)],
        )?;
        if let Some(csv) = response_csv {
            let mut text = String::from("code,ln_exposure_r,ln_exposure_g,ln_exposure_b\n");
            for (z, ((r, g), b)) in response[0]
                .iter()
                .zip(&response[1])
                .zip(&response[2])
                .enumerate()
            {
                text.push_str(&format!("{z},{r},{g},{b}\n"));
            }
            image_io::write_atomic(csv, text.as_bytes())?;
        }
        Ok(())
    })?;
    say!(
        "merged {} exposures into {} ({}x{}); {} pixels saturated in every exposure, {} black in every exposure; radiance is relative (g(128) = 0, t0 = 1)",
        exposures.len(),
        output.display(),
        merged.image.width,
        merged.image.height,
        merged.saturated.iter().filter(|s| **s).count(),
        merged.black.iter().filter(|s| **s).count()
    );
    Ok(())
}

fn motion_cmd(
    path: &Path,
    name: &str,
    dir: &Path,
    debug_blocks: Option<&Path>,
    as_json: bool,
) -> Result<()> {
    use arlux::model::StageTimes;
    use arlux::render::{RenderSettings, Session};
    let base = stage("load", || load(path, None))?;
    let motion = base.motion(name)?.clone();
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: could not create the folder", dir.display()))?;
    let settings = RenderSettings::default();
    let write = |pose: usize, img: &Image| -> Result<()> {
        let file = dir.join(format!("{name}_{pose:03}.exr"));
        image_io::write_exr(
            &file,
            img.width,
            img.height,
            &[image_io::ExrLayer::Rgb("", img)],
        )?;
        Ok(())
    };
    let error_at = |pose: usize, img: &Image| -> Result<Option<arlux::compare::Comparison>> {
        match motion.references.get(pose) {
            Some(r) => {
                let truth = image_io::read_image(r)?;
                base.check_size(&truth, "motion.references")?;
                Ok(Some(compare(img, &truth, None)))
            }
            None => Ok(None),
        }
    };
    let first = base.with_motion_pose(name, 0)?;
    let photo = stage("read photo", || first.load_photo())?;
    let mut times = StageTimes::default();
    let mut session = Session::start(&first, &photo, &settings, &mut times)?;
    session.prepare_updates(&mut times);
    // Each pose writes its image only.
    session.image_only();
    keep(&times);
    // Speed-ups compare with what re-rendering a pose costs: the photo's
    // calibration and a light's reconstruction are done once per scene.
    let once: f64 = times
        .0
        .iter()
        .filter(|(n, _)| matches!(*n, "bracket scale" | "goniometric"))
        .map(|(_, d)| d.as_secs_f64())
        .sum();
    let full_seconds = times.total().as_secs_f64() - once;
    stage("write", || write(0, &session.composite.image))?;
    let (pda_bytes, block_bytes) = session.memory_bytes();
    let mut rows = vec![json!({
        "pose": 0, "seconds": full_seconds, "full_render": true,
        "error_against_reference": stage("compare", || error_at(0, &session.composite.image))?,
    })];
    if !as_json {
        say!(
            "pose 0: full render {:.1} ms; pixel data {:.1} MB, pixel blocks {:.1} MB{}",
            full_seconds * 1e3,
            pda_bytes as f64 / 1e6,
            block_bytes as f64 / 1e6,
            rows[0]["error_against_reference"]["rmse"]
                .as_f64()
                .map_or(String::new(), |e| format!(
                    "; RMSE against its reference {e:.5}"
                ))
        );
    }
    let mut last_skipped = Vec::new();
    for pose in 1..motion.translations.len() {
        let scene = base.with_motion_pose(name, pose)?;
        let mut times = StageTimes::default();
        let stats = session.update(&scene, &mut times)?;
        keep(&times);
        let seconds = times.total().as_secs_f64();
        stage("write", || write(pose, &session.composite.image))?;
        let error = stage("compare", || error_at(pose, &session.composite.image))?;
        if !as_json {
            say!(
                "pose {pose}: update {:.1} ms ({:.1}x faster than the full render); {} pixels recomputed, {} re-traced, {} shaft tests, {} rays{}",
                seconds * 1e3,
                full_seconds / seconds,
                stats.pixels_recomputed,
                stats.pixels_retraced,
                stats.shaft_tests,
                stats.rays,
                error.map_or(String::new(), |e| format!(
                    "; RMSE against its reference {:.5}",
                    e.rmse
                ))
            );
        }
        rows.push(json!({
            "pose": pose, "seconds": seconds, "full_render": false, "speedup": full_seconds / seconds,
            "pixels_recomputed": stats.pixels_recomputed, "pixels_retraced": stats.pixels_retraced,
            "shaft_tests": stats.shaft_tests, "rays": stats.rays, "error_against_reference": error,
            "stages": stages_json(&times),
        }));
        last_skipped = stats.skipped_blocks;
    }
    if let (Some(png), Some(blocks)) = (debug_blocks, session.blocks()) {
        let (w, h) = (blocks.width, blocks.height);
        // The photo, dimmed, under the skipped blocks coloured by level (Grosch Fig. 6).
        let mut bytes: Vec<u8> = photo
            .pixels
            .iter()
            .flat_map(|p| {
                (*p * (0.09 / photo.mean().max(1e-12) as f32))
                    .to_array()
                    .map(|c| (image_io::linear_to_srgb(c) * 255.0) as u8)
            })
            .collect();
        if let Some(skipped) = last_skipped.iter().find(|s| !s.is_empty()) {
            for &(level, bx, by) in skipped {
                let (x0, y0, x1, y1) = blocks.block_pixels(level, bx, by);
                let colour =
                    arlux::surface_ids::id_colour(level as i32 + 3 * (bx as i32 + by as i32) % 2);
                for y in y0..y1 {
                    for x in x0..x1 {
                        let i = ((y * w + x) * 3) as usize;
                        let edge = x == x0 || y == y0;
                        for c in 0..3 {
                            bytes[i + c] = if edge {
                                0
                            } else {
                                ((bytes[i + c] as u16 + colour[c] as u16) / 2) as u8
                            };
                        }
                    }
                }
            }
        }
        image_io::write_png_rgb8(png, w, h, bytes)?;
    }
    // The hierarchy keeps the shafts its traversals built: what it holds at the end.
    let block_bytes_end = session.memory_bytes().1;
    if as_json {
        say!(
            "{}",
            serde_json::to_string_pretty(
                &json!({ "motion": name, "poses": rows, "pda_bytes": pda_bytes, "block_bytes": block_bytes, "block_bytes_end": block_bytes_end })
            )?
        );
    } else {
        say!(
            "pixel blocks at the end: {:.1} MB",
            block_bytes_end as f64 / 1e6
        );
    }
    Ok(())
}

fn stages_json(times: &arlux::model::StageTimes) -> serde_json::Value {
    let side_by_side = times
        .1
        .iter()
        .map(|(n, d)| json!({ "stage": n, "seconds": d.as_secs_f64(), "side_by_side": true }));
    times
        .0
        .iter()
        .map(|(n, d)| json!({ "stage": n, "seconds": d.as_secs_f64() }))
        .chain(side_by_side)
        .collect()
}

fn print_stages(times: &arlux::model::StageTimes) -> Result<()> {
    say!("time per stage:");
    for (name, d) in &times.0 {
        say!("  {name:<26} {:>9.1} ms", d.as_secs_f64() * 1e3);
    }
    for (name, d) in &times.1 {
        say!(
            "  {:<26} {:>9.1} ms",
            format!("{SIDE_BY_SIDE}{name}"),
            d.as_secs_f64() * 1e3
        );
    }
    say!(
        "  {:<26} {:>9.1} ms",
        "total",
        times.total().as_secs_f64() * 1e3
    );
    Ok(())
}
