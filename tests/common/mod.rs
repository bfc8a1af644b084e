//! What the integration tests share: the example scenes in `scenes/`, their
//! photos and reference images. Tests read nothing outside the repository.

#![allow(dead_code)] // each test binary uses its own part of this module

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use arlux::image_io::{Image, read_image};
use arlux::scene::Scene;

pub mod asset;
pub mod serve;

/// The folder of the example scene `name` (`desk`, `lounge`, `whitebox`).
pub fn scene_dir(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name)
}

/// An example scene's manifest `file` (e.g. `scene.toml`), loaded.
pub fn load(name: &str, file: &str) -> Scene {
    Scene::load(scene_dir(name).join(file)).unwrap()
}

/// `scenes/desk/scene.toml`, loaded.
pub fn desk() -> Scene {
    load("desk", "scene.toml")
}

/// An image of an example scene, by its path inside the scene's folder.
pub fn image(name: &str, file: &str) -> Image {
    read_image(&scene_dir(name).join(file)).unwrap()
}

pub const DESK: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/desk");

/// A writable copy of the desk (scene.toml, geometry, photo) in a temporary folder.
pub struct Desk {
    pub dir: tempfile::TempDir,
}

/// A writable copy of `files` of the scene folder `src` (its `geometry`
/// folder made) in a temporary folder, the truths linked.
pub fn writable_copy(src: &Path, files: &[&str]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("geometry")).unwrap();
    for f in files {
        std::fs::copy(src.join(f), dir.path().join(f)).unwrap();
    }
    std::os::unix::fs::symlink(src.join("truth"), dir.path().join("truth")).unwrap();
    dir
}

impl Desk {
    pub fn new() -> Desk {
        let files = [
            "scene.toml",
            "photo.exr",
            "geometry/room.obj",
            "geometry/furniture.obj",
            "geometry/box.obj",
        ];
        Desk {
            dir: writable_copy(Path::new(DESK), &files),
        }
    }

    pub fn path(&self, rel: &str) -> PathBuf {
        self.dir.path().join(rel)
    }

    pub fn edit(&self, rel: &str, old: &str, new: &str) {
        let text = std::fs::read_to_string(self.path(rel)).unwrap();
        assert!(text.contains(old), "{rel} has no '{old}'");
        std::fs::write(self.path(rel), text.replacen(old, new, 1)).unwrap();
    }

    pub fn scene(&self) -> String {
        self.path("scene.toml").display().to_string()
    }
}

pub fn arlux(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_arlux"))
        .args(args)
        .output()
        .unwrap()
}

/// Runs arlux and asserts that it succeeded (its stderr in the message).
#[allow(dead_code)]
pub fn arlux_ok(args: &[&str]) -> Output {
    let run = arlux(args);
    assert_eq!(
        run.status.code(),
        Some(0),
        "{args:?}: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    run
}

/// Runs arlux, asserts status 2 with every `expected` text in the
/// message and no panic; returns the message.
#[allow(dead_code)]
pub fn arlux_refused(args: &[&str], expected: &[&str]) -> String {
    let run = arlux(args);
    let stderr = String::from_utf8_lossy(&run.stderr).into_owned();
    assert_eq!(run.status.code(), Some(2), "{args:?}: {stderr}");
    for e in expected {
        assert!(stderr.contains(e), "expected '{e}' in: {stderr}");
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
    stderr
}

/// Runs arlux (with `--json` among `args`), asserts that it succeeded and
/// returns its report.
#[allow(dead_code)]
pub fn arlux_json(args: &[&str]) -> serde_json::Value {
    serde_json::from_slice(&arlux_ok(args).stdout).unwrap()
}

/// Renders the desk copy's `box_floor_a` to `out` with `--json`; its report.
#[allow(dead_code)]
pub fn render_box_floor_a(desk: &Desk, out: &Path) -> serde_json::Value {
    let out = out.to_str().unwrap();
    let run = arlux_ok(&[
        "render",
        &desk.scene(),
        "--variant",
        "box_floor_a",
        "-o",
        out,
        "--json",
    ]);
    serde_json::from_slice(&run.stdout).unwrap()
}

/// `scene`'s image rendered with `settings` on a pool of `threads` threads.
pub fn image_on_threads(
    scene: &Scene,
    photo: &Image,
    settings: &arlux::render::RenderSettings,
    threads: usize,
) -> Image {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        arlux::render::render(
            scene,
            photo,
            settings,
            &mut arlux::model::StageTimes::default(),
        )
        .unwrap()
        .composite
        .image
    })
}

/// `scene` rendered with the default settings over its photo, and the photo.
pub fn render_default(scene: &Scene) -> (arlux::render::RenderOutput, Image) {
    let photo = scene.load_photo().unwrap();
    let out = arlux::render::render(
        scene,
        &photo,
        &arlux::render::RenderSettings::default(),
        &mut arlux::model::StageTimes::default(),
    )
    .unwrap();
    (out, photo)
}

/// A variant rendered with the defaults (every pixel checked finite and not
/// negative), its truth and the photo.
pub fn rendered(base: &Scene, variant: &str) -> (Image, Image, Image) {
    let scene = base.with_variant(variant).unwrap();
    let photo = scene.load_photo().unwrap();
    let out = arlux::render::render(
        &scene,
        &photo,
        &arlux::render::RenderSettings::default(),
        &mut arlux::model::StageTimes::default(),
    )
    .unwrap();
    let reference = base.variant(variant).unwrap().reference.clone().unwrap();
    let truth = arlux::image_io::read_image(&reference).unwrap();
    assert_layers_sound(variant, &out.composite);
    (out.composite.image, truth, photo)
}

/// How many pixels of two images differ in any bit.
pub fn differing(a: &Image, b: &Image) -> usize {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .filter(|(x, y)| x.to_array().map(f32::to_bits) != y.to_array().map(f32::to_bits))
        .count()
}

/// The largest difference between two images relative to the second's
/// value (a floor of 1e-3 of its mean for the darkest pixels).
pub fn relative_difference(a: &Image, b: &Image) -> f64 {
    let values = |i: &Image| {
        i.pixels
            .iter()
            .flat_map(|p| p.to_array())
            .collect::<Vec<f32>>()
    };
    relative_difference_of(&values(a), &values(b))
}

/// [`relative_difference`] of two images' values as flat lists (what
/// `serve`'s `/api/linear` returns).
pub fn relative_difference_of(a: &[f32], b: &[f32]) -> f64 {
    let mean = b.iter().map(|v| *v as f64).sum::<f64>() / b.len().max(1) as f64;
    (a.iter().zip(b))
        .map(|(x, y)| (*x as f64 - *y as f64).abs() / (*y as f64).abs().max(1e-3 * mean))
        .fold(0.0, f64::max)
}

/// Every layer a compositor reads is finite and not negative (but
/// `change`, image − photo, which is signed), coverage lies in [0, 1].
pub fn assert_layers_sound(label: &str, c: &arlux::composite::Composite) {
    for (name, layer) in [
        ("image", &c.image),
        ("direct", &c.direct),
        ("indirect", &c.indirect),
        ("object", &c.object),
    ] {
        let bad = (layer.pixels.iter())
            .filter(|p| !(p.is_finite() && p.min_element() >= 0.0))
            .count();
        assert_eq!(
            bad, 0,
            "{label}: {bad} pixels of '{name}' negative or not finite"
        );
    }
    assert!(
        c.change.pixels.iter().all(|p| p.is_finite()),
        "{label}: change"
    );
    assert!(
        c.alpha.iter().all(|a| (0.0..=1.0).contains(a)),
        "{label}: alpha"
    );
    assert!(
        c.noise.iter().all(|n| n.is_finite() && *n >= 0.0),
        "{label}: noise"
    );
}

/// The names of a report's stages.
#[allow(dead_code)]
pub fn stage_names(report: &serde_json::Value) -> Vec<String> {
    report["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["stage"].as_str().unwrap().to_string())
        .collect()
}
