//! Helpers the commands share: loading a scene, the photo, formatting.

use std::path::Path;

use anyhow::{Context, Result};
use serde_json::json;

use arlux::image_io::{self, Image};
use arlux::scene::{Photo, Scene, Showing};

/// The version of every `--json` report's layout (`docs/json.md`): raised
/// when a field changes meaning or goes away.
pub(crate) const SCHEMA: u32 = 1;

/// Prints a command's `--json` report: the object `report` with the
/// schema's version and the command's name in front (`docs/json.md`).
pub(crate) fn emit(command: &str, report: serde_json::Value) -> Result<()> {
    let mut out = serde_json::Map::new();
    out.insert("schema".into(), json!(SCHEMA));
    out.insert("command".into(), json!(command));
    if let serde_json::Value::Object(fields) = report {
        out.extend(fields);
    }
    say!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}

/// A command's report: one value, printed as `--json` (`docs/json.md`) or
/// as text for a reader.
pub(crate) trait Report: serde::Serialize {
    /// The command's name in the JSON.
    const COMMAND: &'static str;
    /// The report as lines for a reader.
    fn text(&self) -> Vec<String>;
}

/// Prints `report`: its JSON with `--json`, else its text.
pub(crate) fn print_report<R: Report>(report: &R, as_json: bool) -> Result<()> {
    if as_json {
        return emit(R::COMMAND, serde_json::to_value(report)?);
    }
    for line in report.text() {
        say!("{line}");
    }
    Ok(())
}

pub(crate) fn load(path: &Path, variant: Option<&str>) -> Result<Scene> {
    let scene = load_showing(path, variant.map_or(Showing::Base, Showing::Variant))?;
    Ok(match variant {
        Some(v) => scene.with_variant(v)?,
        None => scene,
    })
}

/// The scene with the meshes of what `showing` shows read (the others'
/// files checked, not read), its warnings said.
pub(crate) fn load_showing(path: &Path, showing: Showing) -> Result<Scene> {
    let scene = Scene::load_showing(path, showing)?;
    crate::outputs::refuse_inputs(&scene.input_files())?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    Ok(scene)
}

/// The scene's photo, saying how many negative pixels it had (clamped to 0).
pub(crate) fn read_photo(scene: &Scene) -> Result<Image> {
    let (img, negative) = scene.read_photo()?;
    if negative > 0 {
        eprintln!(
            "warning: {}: {negative} pixels of the photo are negative; they are taken as 0",
            scene.file.display()
        );
    }
    Ok(img)
}

/// Writes a frame as the EXR a compositor expects: the final `RGBA`;
/// `object.RGBA`, the virtual objects premultiplied by their coverage;
/// `shadow.RGB`, the photo's factor where real surfaces show, so that
/// photo × shadow + object is the frame; `change.RGB` = frame − photo; the
/// `photo`; the irradiance layers `direct` and `indirect`. A composite made
/// without its layers writes `RGBA` alone.
pub(crate) fn write_frame(
    path: &Path,
    c: &arlux::composite::Composite,
    photo: &Image,
    meta: &image_io::ExrMeta,
) -> Result<()> {
    let (w, h) = (c.image.width, c.image.height);
    let files = arlux::output::FrameFiles {
        exr: path.to_path_buf(),
        // Only a composite with its layers writes them (a motion's later poses do not).
        layers: c.direct.pixels.len() == c.image.pixels.len(),
        ..Default::default()
    };
    let mut writer = arlux::output::FrameWriter::start(&files, w, h, meta)?;
    writer.band(c, (0, h), photo)?;
    writer.finish()?;
    Ok(())
}

/// The EXR attributes of a frame: the camera's matrices, and in the text
/// attribute `arlux` the version and what was rendered (`what`, JSON).
pub(crate) fn frame_meta(scene: &Scene, what: serde_json::Value) -> image_io::ExrMeta {
    let mut text = json!({ "version": env!("CARGO_PKG_VERSION"), "scene": scene.name });
    let d = scene.camera.distortion;
    if !d.is_none() {
        // worldToNDC is the pinhole part; the lens bends it as OpenCV's model says.
        text["lens"] = json!({ "k1": d.k1, "k2": d.k2, "p1": d.p1, "p2": d.p2, "k3": d.k3 });
    }
    if let (Some(t), serde_json::Value::Object(w)) = (text.as_object_mut(), what) {
        t.extend(w);
    }
    image_io::ExrMeta {
        arlux: Some(text.to_string()),
        ..image_io::ExrMeta::default()
    }
    .with_camera(&scene.camera)
}

pub(crate) fn rel(scene: &Scene, p: &Path) -> String {
    p.strip_prefix(scene.dir())
        .unwrap_or(p)
        .display()
        .to_string()
}

pub(crate) fn fmt3(v: glam::DVec3) -> String {
    format!("[{}, {}, {}]", v.x, v.y, v.z)
}

/// Range figures of the photo, per channel and over all.
pub(crate) fn photo_range(img: &Image) -> serde_json::Value {
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

/// The photo to draw outlines on: the HDR photo, or for brackets the
/// exposure nearest EV 0 (decoded from sRGB; only for looking at).
pub(crate) fn display_photo(scene: &Scene) -> Result<Image> {
    match &scene.photo {
        Photo::Image(_) => read_photo(scene),
        Photo::Brackets(bs) => {
            let b = bs
                .iter()
                .min_by(|a, b| a.ev.abs().total_cmp(&b.ev.abs()))
                .context("no brackets")?;
            let img = image_io::read_image(&b.image)?;
            Ok(scene.fit_size(img, "photo.brackets", &b.image)?)
        }
    }
}

/// The photo in the scene's units ([`arlux::inputs::photo_in_units`], with
/// the model `settings` the command uses); a photo left relative is a
/// warning (an error with `--strict`): these commands give absolute figures.
pub(crate) fn photo_in_units(
    scene: &Scene,
    tracer: &arlux::trace::Tracer,
    settings: &arlux::model::ModelSettings,
    times: &mut arlux::model::StageTimes,
) -> Result<Image> {
    let photo = times.time("read photo", || read_photo(scene))?;
    let (photo, relative) = arlux::inputs::photo_in_units(scene, &photo, tracer, settings, times);
    if let Some(why) = relative {
        warn(scene, &why)?;
    }
    Ok(photo)
}

/// The skill figures on one line.
pub(crate) fn skill_line(s: &arlux::compare::Skill) -> String {
    match s.skill {
        Some(k) => format!(
            "skill {k:.3} over the {} pixels the change touches (RMSE {:.5} there; the unchanged photo's {:.5})",
            s.changed_pixels, s.rmse_changed, s.rmse_photo_changed
        ),
        None => "skill: n/a (the reference does not differ from the photo)".to_string(),
    }
}

static STRICT: std::sync::OnceLock<bool> = std::sync::OnceLock::new();

/// `--strict`: warnings about likely wrong inputs become errors.
pub(crate) fn set_strict(strict: bool) {
    let _ = STRICT.set(strict);
}

/// Reports a likely wrong input on stderr, or refuses it under `--strict`.
pub(crate) fn warn(scene: &Scene, message: &str) -> Result<()> {
    if STRICT.get().copied().unwrap_or(false) {
        anyhow::bail!("{}: {message} (--strict)", scene.file.display());
    }
    eprintln!("warning: {}: {message}", scene.file.display());
    Ok(())
}

/// A shard `i/n` (0-based i), or `auto/n` with i read from the job array's
/// index: SLURM_ARRAY_TASK_ID (Slurm) or JOB_COMPLETION_INDEX (Kubernetes
/// Indexed Jobs).
pub(crate) fn shard(text: &str) -> Result<(usize, usize)> {
    let bad = |why: String| anyhow::anyhow!("--shard {text}: {why}");
    let (i, n) = text
        .split_once('/')
        .ok_or_else(|| bad("give i/n or auto/n".into()))?;
    let n: usize = n
        .trim()
        .parse()
        .ok()
        .filter(|n| *n > 0)
        .ok_or_else(|| bad("n must be a positive whole number".into()))?;
    let i = if i.trim() == "auto" {
        let set: Vec<(&str, String)> = ["SLURM_ARRAY_TASK_ID", "JOB_COMPLETION_INDEX"]
            .iter()
            .filter_map(|v| std::env::var(v).ok().map(|x| (*v, x)))
            .collect();
        if let [(a, x), (b, y)] = &set[..]
            && x.trim() != y.trim()
        {
            return Err(bad(format!(
                "auto: {a}={x} and {b}={y} disagree: unset the one that is not this task's"
            )));
        }
        let (var, value) = set.into_iter().next().ok_or_else(|| {
            bad("auto: neither SLURM_ARRAY_TASK_ID nor JOB_COMPLETION_INDEX is set".into())
        })?;
        value
            .trim()
            .parse::<usize>()
            .map_err(|_| bad(format!("{var}={value} is not a whole number")))?
    } else {
        i.trim()
            .parse::<usize>()
            .map_err(|_| bad("i must be a whole number".into()))?
    };
    if i >= n {
        return Err(bad(format!("i must be below n ({i} >= {n})")));
    }
    Ok((i, n))
}

/// Shard `text`'s contiguous share of `count` items (the first shares one
/// longer when n does not divide count), with i and n; empty when there
/// are fewer items than shards and this is one of the shards beyond them.
pub(crate) fn shard_range(
    text: &str,
    count: usize,
) -> Result<(std::ops::Range<usize>, usize, usize)> {
    let (i, n) = shard(text)?;
    let (base, extra) = (count / n, count % n);
    let start = i * base + i.min(extra);
    let end = start + base + usize::from(i < extra);
    Ok((start..end, i, n))
}
