//! Objects added from a folder of meshes (`arlux serve --assets DIR`): the
//! session appends a `[[virtual]]` table for the file to its scene's text
//! and reads the scene back, so that the object renders (and saves) as the
//! scene file with that table would; then it stands the object where a
//! click sees a floor or a table, as a placement does.

use std::path::{Path, PathBuf};

use super::{Edit, Interactive, ObjectEdit, Outcome, Refusal};
use crate::error::{Error, Result};
use crate::scene::{Scene, Showing};
use crate::util::stages::StageTimes;

/// The mesh files an asset folder offers (as [`crate::geometry::load_mesh`] reads them).
pub const MESH_EXTENSIONS: [&str; 4] = ["obj", "gltf", "glb", "ply"];

/// The clay colour of an added mesh that names none (an OBJ without
/// materials, a PLY): a mid grey.
const CLAY_RGB: [f64; 3] = [0.7, 0.7, 0.7];

/// The meshes directly in `dir` (not in its sub-folders), by file name, sorted.
pub fn list_assets(dir: &Path) -> Result<Vec<(String, PathBuf)>> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, &e))?;
    let mut assets = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| Error::io(dir, &e))?.path();
        let ext = (path.extension())
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
        if let (true, Some(name)) = (
            path.is_file() && MESH_EXTENSIONS.contains(&ext.as_str()),
            name,
        ) {
            assets.push((name, path));
        }
    }
    assets.sort();
    Ok(assets)
}

impl Interactive {
    /// Adds the mesh `file` as a new virtual object, named after the file
    /// (made unique among the scene's objects and lights), and stands it
    /// where image point (x, y) sees a floor-like surface. One undo step
    /// hides it again. Refused, changing nothing, when the mesh does not
    /// load or cannot stand there.
    pub fn add_object(
        &mut self,
        file: &Path,
        at: (f64, f64),
        times: &mut StageTimes,
    ) -> std::result::Result<(Outcome, String), Refusal> {
        let name = self.free_name(file);
        let scene = self.scene_with(file, &name)?;
        let object = scene.objects.len() - 1;
        let old = std::mem::replace(&mut self.base, scene);
        self.objects.push(ObjectEdit::default());
        self.others = None;
        let edit = Edit::Place {
            object,
            x: at.0,
            y: at.1,
        };
        match self.step(edit, false, times) {
            Ok(outcome) => Ok((outcome, name)),
            Err(r) => {
                self.base = old;
                self.objects.pop();
                self.others = None;
                Err(r)
            }
        }
    }

    /// The session's scene with a disabled `[[virtual]]` of `file` named
    /// `name` appended to its text, read back (with a clay colour if the
    /// mesh names none).
    fn scene_with(&self, file: &Path, name: &str) -> std::result::Result<Scene, Refusal> {
        let refused = |e: Error| Refusal::new("asset", e.to_string());
        let mesh = mesh_key(file, self.base.dir());
        let text_with = |rgb: Option<[f64; 3]>| {
            let mut t = toml::Table::new();
            t.insert("name".into(), name.into());
            t.insert("mesh".into(), mesh.clone().into());
            if let Some(rgb) = rgb {
                t.insert(
                    "rgb".into(),
                    rgb.iter()
                        .map(|&c| toml::Value::from(c))
                        .collect::<Vec<_>>()
                        .into(),
                );
            }
            t.insert("enabled".into(), false.into());
            let mut doc = toml::Table::new();
            doc.insert("virtual".into(), toml::Value::Array(vec![t.into()]));
            let table = toml::to_string(&doc).expect("a table of strings and numbers");
            format!(
                "{}\n\n# Added by arlux serve.\n{table}",
                self.base.source.trim_end()
            )
        };
        let read = |text: String| Scene::from_text(&self.base.file, text, Showing::Everything);
        match read(text_with(None)) {
            Ok(scene) => Ok(scene),
            // A mesh without materials takes a clay colour, as `rgb` would give it.
            Err(e)
                if matches!(&e.location, crate::error::Location::Key(k) if k.ends_with(".rgb"))
                    && e.message.starts_with("missing") =>
            {
                read(text_with(Some(CLAY_RGB))).map_err(refused)
            }
            Err(e) => Err(refused(e)),
        }
    }

    /// The file's stem as an object name no object or light of the scene has.
    fn free_name(&self, file: &Path) -> String {
        let stem: String = (file.file_stem())
            .map(|s| s.to_string_lossy())
            .unwrap_or_default()
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .take(48)
            .collect();
        let stem = if stem.is_empty() {
            "object".to_string()
        } else {
            stem
        };
        let taken = |n: &str| {
            self.base.objects.iter().any(|o| o.name == n)
                || self.base.lights.iter().any(|l| l.name == n)
        };
        (1..)
            .map(|k| {
                if k == 1 {
                    stem.clone()
                } else {
                    format!("{stem}-{k}")
                }
            })
            .find(|n| !taken(n))
            .expect("some number is free")
    }
}

/// How the scene's text names `file`: relative to the scene's folder when
/// inside it (the saved file then moves with its folder), else absolute.
fn mesh_key(file: &Path, scene_dir: &Path) -> String {
    let file = file.canonicalize().unwrap_or_else(|_| file.to_path_buf());
    let dir = scene_dir
        .canonicalize()
        .unwrap_or_else(|_| scene_dir.to_path_buf());
    match file.strip_prefix(&dir) {
        Ok(rel) => rel.display().to_string(),
        Err(_) => file.display().to_string(),
    }
}
