//! What the integration tests share: the example scenes in `scenes/`, their
//! photos and reference images. Tests read nothing outside the repository.

#![allow(dead_code)] // each test binary uses its own part of this module

use std::path::{Path, PathBuf};

use arlux::image_io::{Image, read_image};
use arlux::scene::Scene;

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
