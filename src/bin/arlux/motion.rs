//! `arlux motion`: Render a motion: the first pose in full, then an incremental update per pose, writing DIR/NAME_000.exr, NAME_001.exr, ...

use std::path::PathBuf;

use anyhow::{Context, Result};
use serde_json::json;

use arlux::compare::compare;
use arlux::image_io::{self, Image};

use crate::common::*;
use crate::timing::*;

/// Arguments of `arlux motion`.
#[derive(clap::Args)]
pub struct Args {
    pub scene: PathBuf,
    #[arg(long)]
    pub motion: String,
    /// Output folder (created if missing).
    #[arg(short, long, default_value = ".")]
    pub output: PathBuf,
    /// PNG of the blocks the last update skipped with one shaft test (first active light).
    #[arg(long)]
    pub debug_blocks: Option<PathBuf>,
    /// Only these poses, `A..B` (B excluded): the first in full, the rest
    /// by updates. Each frame equals the whole run's bit for bit, so a
    /// motion splits over machines.
    #[arg(long, conflicts_with = "shard")]
    pub frames: Option<String>,
    /// The i-th of n contiguous shares of the poses (`i/n`, 0-based), or
    /// `auto/n` to read i from SLURM_ARRAY_TASK_ID or JOB_COMPLETION_INDEX
    /// (a Slurm array or a Kubernetes Indexed Job).
    #[arg(long)]
    pub shard: Option<String>,
    /// Write each frame's RGBA alone, without the compositing and light
    /// layers `render` writes (a tenth to a fifth less work per update).
    #[arg(long)]
    pub image_only: bool,
    /// The render flags, as `render` takes them (every frame).
    #[command(flatten)]
    pub flags: crate::flags::RenderFlags,
    #[arg(long)]
    pub json: bool,
}

/// `arlux motion`'s report.
#[derive(serde::Serialize)]
struct MotionReport<'a> {
    motion: &'a str,
    /// Every pose's time, summed.
    seconds: f64,
    poses: Vec<PoseReport>,
    pda_bytes: usize,
    /// The pixel-block hierarchy after the first pose, and at the end (it
    /// keeps the shafts its traversals built).
    block_bytes: usize,
    block_bytes_end: usize,
    /// The room's radiosity without the objects, kept for every pose, and
    /// the objects' change to it at the last pose.
    room_solution_bytes: usize,
    change_bytes: usize,
}

/// One pose: the full render (the first) or an update.
#[derive(serde::Serialize)]
struct PoseReport {
    pose: usize,
    seconds: f64,
    full_render: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    speedup: Option<f64>,
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    update: Option<UpdateReport>,
    comparison: Option<arlux::compare::Comparison>,
    #[serde(skip_serializing_if = "Option::is_none")]
    stages: Option<serde_json::Value>,
}

/// What an update recomputed.
#[derive(serde::Serialize)]
struct UpdateReport {
    pixels_recomputed: usize,
    pixels_retraced: u64,
    shaft_tests: u64,
    rays: u64,
}

impl PoseReport {
    fn text(&self, pda_bytes: usize, block_bytes: usize) -> String {
        let error = self.comparison.map_or(String::new(), |e| {
            format!("; RMSE against its reference {:.5}", e.rmse)
        });
        match (&self.update, self.speedup) {
            (Some(u), Some(speedup)) => format!(
                "pose {}: update {:.1} ms ({speedup:.1}x faster than the full render); {} pixels recomputed, {} re-traced, {} shaft tests, {} rays{error}",
                self.pose,
                self.seconds * 1e3,
                u.pixels_recomputed,
                u.pixels_retraced,
                u.shaft_tests,
                u.rays,
            ),
            _ => format!(
                "pose {}: full render {:.1} ms; pixel data {:.1} MB, pixel blocks {:.1} MB{error}",
                self.pose,
                self.seconds * 1e3,
                pda_bytes as f64 / 1e6,
                block_bytes as f64 / 1e6,
            ),
        }
    }
}

/// A job array sized for a longer motion: this shard has no pose to render.
fn nothing_to_render(args: &Args, name: &str, total: usize) -> Result<()> {
    eprintln!(
        "note: --shard {}: no pose falls to this shard ({total} in all): nothing rendered",
        args.shard.as_deref().unwrap_or(""),
    );
    let report = MotionReport {
        motion: name,
        seconds: 0.0,
        poses: Vec::new(),
        pda_bytes: 0,
        block_bytes: 0,
        block_bytes_end: 0,
        room_solution_bytes: 0,
        change_bytes: 0,
    };
    print_report(&report, args.json)
}

/// The poses' references and placements, checked before any frame.
fn check_poses(
    base: &arlux::scene::Scene,
    name: &str,
    motion: &arlux::scene::Motion,
    poses: std::ops::Range<usize>,
) -> Result<()> {
    stage("check inputs", || -> Result<()> {
        for pose in poses.clone() {
            if let Some(r) = motion.references.get(pose) {
                base.check_reference(&format!("motion '{name}'.references[{pose}]"), r)?;
            }
        }
        Ok(())
    })?;
    let crossings = stage("placement checks", || {
        arlux::placement::motion_warnings(base, name, poses)
    })?;
    for w in &crossings {
        warn(base, w)?;
    }
    Ok(())
}

pub fn run(args: &Args) -> Result<()> {
    let name = args.motion.as_str();
    let dir = args.output.as_path();
    use arlux::model::StageTimes;
    use arlux::renderer::Renderer;
    // The settings checked before any work.
    let mut options = arlux::settings::RenderOptions::default();
    args.flags.apply(&mut options);
    let method = options.resolve()?;
    let base = stage("load", || {
        load_showing(&args.scene, arlux::scene::Showing::Motion(name))
    })?;
    let motion = base.motion(name)?.clone();
    let poses = pose_range(args, motion.translations.len())?;
    if poses.is_empty() {
        return nothing_to_render(args, name, motion.translations.len());
    }
    check_poses(&base, name, &motion, poses.clone())?;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: could not create the folder", dir.display()))?;
    let write = |pose: usize, c: &arlux::composite::Composite, photo: &Image| -> Result<()> {
        let file = dir.join(format!("{name}_{pose:03}.exr"));
        let meta = frame_meta(&base, json!({ "motion": name, "pose": pose }));
        write_frame(&file, c, photo, &meta)
    };
    let error_at = |pose: usize, img: &Image| -> Result<Option<arlux::compare::Comparison>> {
        match motion.references.get(pose) {
            Some(r) => {
                let truth = base.fit_size(image_io::read_image(r)?, "motion.references", r)?;
                Ok(Some(compare(img, &truth, None)))
            }
            None => Ok(None),
        }
    };
    let bar = crate::progress::progress_bar(poses.len() as u64, "poses");
    let first = base.with_motion_pose(name, poses.start)?;
    let photo = stage("read photo", || read_photo(&first))?;
    let mut times = StageTimes::default();
    // Each shard of a farm starts with a full render of its first pose:
    // all but the first read the room's links.
    let mut session = Renderer::start(&first, &photo, &method, &mut times)?;
    session.prepare_updates(&mut times);
    if args.image_only {
        session.image_only();
    }
    keep(&times);
    let full_seconds = full_render_seconds(&times);
    stage("write", || write(poses.start, session.composite(), &photo))?;
    bar.inc(1);
    let memory = session.memory_bytes();
    let (pda_bytes, block_bytes) = (memory.pixel_data, memory.pixel_blocks);
    let first = PoseReport {
        pose: poses.start,
        seconds: full_seconds,
        full_render: true,
        speedup: None,
        update: None,
        comparison: stage("compare", || {
            error_at(poses.start, &session.composite().image)
        })?,
        stages: None,
    };
    if !args.json {
        say!("{}", first.text(pda_bytes, block_bytes));
    }
    let mut rows = vec![first];
    let mut last_skipped = Vec::new();
    for pose in poses.start + 1..poses.end {
        let scene = base.with_motion_pose(name, pose)?;
        let mut times = StageTimes::default();
        let stats = session.update(&scene, &mut times)?;
        keep(&times);
        let seconds = times.total().as_secs_f64();
        stage("write", || write(pose, session.composite(), &photo))?;
        // The texture path renders every pose in full.
        let row = PoseReport {
            pose,
            seconds,
            full_render: stats.is_none(),
            speedup: stats.as_ref().map(|_| full_seconds / seconds),
            update: stats.as_ref().map(|stats| UpdateReport {
                pixels_recomputed: stats.pixels_recomputed,
                pixels_retraced: stats.pixels_retraced,
                shaft_tests: stats.shaft_tests,
                rays: stats.rays,
            }),
            comparison: stage("compare", || error_at(pose, &session.composite().image))?,
            stages: Some(stages_json(&times)),
        };
        if !args.json {
            bar.suspend(|| -> Result<()> {
                say!("{}", row.text(pda_bytes, block_bytes));
                Ok(())
            })?;
        }
        rows.push(row);
        last_skipped = stats.map(|s| s.skipped_blocks).unwrap_or_default();
        bar.inc(1);
    }
    bar.finish_and_clear();
    if let (Some(png), Some(blocks)) = (&args.debug_blocks, session.blocks()) {
        write_skipped_blocks(png, blocks, &photo, &last_skipped)?;
    }
    let report = MotionReport {
        motion: name,
        seconds: rows.iter().map(|r| r.seconds).sum(),
        poses: rows,
        pda_bytes,
        block_bytes,
        block_bytes_end: session.memory_bytes().pixel_blocks,
        room_solution_bytes: memory.room_solution,
        change_bytes: session.memory_bytes().change,
    };
    // The poses' lines were printed as they came: the text adds the end.
    print_report(&report, args.json)
}

impl Report for MotionReport<'_> {
    const COMMAND: &'static str = "motion";

    fn text(&self) -> Vec<String> {
        vec![format!(
            "pixel blocks at the end: {:.1} MB; room solution kept {:.2} MB, the objects' change {:.2} MB",
            self.block_bytes_end as f64 / 1e6,
            self.room_solution_bytes as f64 / 1e6,
            self.change_bytes as f64 / 1e6
        )]
    }
}

/// What re-rendering a pose costs: the full render less the photo's
/// calibration and a light's reconstruction, done once per scene.
fn full_render_seconds(times: &arlux::model::StageTimes) -> f64 {
    let once: f64 = times
        .0
        .iter()
        .filter(|(n, _)| matches!(*n, "bracket scale" | "goniometric"))
        .map(|(_, d)| d.as_secs_f64())
        .sum();
    times.total().as_secs_f64() - once
}

/// The poses to render: all, `--frames A..B`, or a `--shard`'s share.
fn pose_range(args: &Args, count: usize) -> Result<std::ops::Range<usize>> {
    if let Some(frames) = &args.frames {
        let bad = || anyhow::anyhow!("--frames {frames}: give A..B with A < B <= {count}");
        let (a, b) = frames.split_once("..").ok_or_else(bad)?;
        let (a, b): (usize, usize) = (
            a.trim().parse().map_err(|_| bad())?,
            b.trim().parse().map_err(|_| bad())?,
        );
        if a >= b || b > count {
            return Err(bad());
        }
        return Ok(a..b);
    }
    let Some(shard) = &args.shard else {
        return Ok(0..count);
    };
    Ok(crate::common::shard_range(shard, count)?.0)
}

/// The photo, dimmed, under the blocks the last update skipped with one
/// shaft test, coloured by level (Grosch Fig. 6).
fn write_skipped_blocks(
    png: &std::path::Path,
    blocks: &arlux::blocks::BlockHierarchy,
    photo: &Image,
    last_skipped: &[Vec<(u8, u32, u32)>],
) -> Result<()> {
    let (w, h) = (blocks.width, blocks.height);
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
    Ok(())
}
