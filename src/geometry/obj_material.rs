//! An OBJ's `.mtl` materials as glTF metallic-roughness materials, and its
//! per-triangle normals (`vn`) and texture coordinates (`vt`).
//!
//! `Kd` is the base colour, `map_Kd` its texture (sRGB), `Pm` the metallic
//! factor and `Pr` the roughness (the PBR extension of the MTL format);
//! without `Pr`, a Phong exponent `Ns` gives the GGX α = √(2 / (Ns + 2))
//! (Walter et al. 2007), roughness √α. A material with none of `Ks` > 0,
//! `Pr`, `Pm` or `map_Kd` stays diffuse (the surface's `Kd` as before).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{Vec2, Vec3};

use crate::error::{Error, Result};
use crate::materials::{Attributes, Material, Texture};

/// The file's materials, converted as surfaces ask for them.
pub(super) struct ObjMaterials<'a> {
    dir: PathBuf,
    materials: &'a [tobj::Material],
    done: HashMap<usize, Option<Arc<Material>>>,
    unsupported: Vec<String>,
}

impl<'a> ObjMaterials<'a> {
    pub(super) fn new(dir: &Path, materials: &'a [tobj::Material]) -> Self {
        ObjMaterials {
            dir: dir.to_path_buf(),
            materials,
            done: HashMap::new(),
            unsupported: Vec::new(),
        }
    }

    /// Material `id` when it has more than a diffuse colour.
    pub(super) fn get(&mut self, id: usize) -> Result<Option<Arc<Material>>> {
        if let Some(m) = self.done.get(&id) {
            return Ok(m.clone());
        }
        let Some(mat) = self.materials.get(id) else {
            return Ok(None);
        };
        let m = self.convert(mat)?.map(Arc::new);
        self.done.insert(id, m.clone());
        Ok(m)
    }

    fn convert(&mut self, mat: &tobj::Material) -> Result<Option<Material>> {
        let param = |k: &str| -> Option<f32> {
            mat.unknown_param
                .get(k)
                .and_then(|v| v.split_whitespace().next()?.parse().ok())
        };
        let (pr, pm) = (param("Pr"), param("Pm"));
        let specular = mat.specular.is_some_and(|k| k.iter().any(|&c| c > 0.0));
        if !specular && pr.is_none() && pm.is_none() && mat.diffuse_texture.is_none() {
            return Ok(None);
        }
        let roughness = pr.unwrap_or_else(|| match mat.shininess {
            Some(ns) if specular => (2.0 / (ns.max(0.0) + 2.0)).sqrt().sqrt(),
            _ => 1.0,
        });
        let base = mat.diffuse.map_or(Vec3::splat(0.8), Vec3::from_array);
        let mut m = Material::plain(&mat.name, base, pm.unwrap_or(0.0), roughness);
        if let Some(file) = &mat.diffuse_texture {
            m.base_texture = Some(Arc::new(self.image(file)?));
        }
        if let Some(ke) = mat.emissive {
            m.emissive = Vec3::from_array(ke).max(Vec3::ZERO);
        }
        for (has, what) in [
            (mat.normal_texture.is_some(), "map_Bump/norm"),
            (mat.specular_texture.is_some(), "map_Ks"),
            (mat.dissolve.is_some_and(|d| d < 1.0), "d (transparency)"),
        ] {
            let name = format!("{}: {what}", mat.name);
            if has && !self.unsupported.contains(&name) {
                self.unsupported.push(name);
            }
        }
        Ok(Some(m))
    }

    /// An image file beside the OBJ as an sRGB texture.
    fn image(&self, file: &str) -> Result<Texture> {
        let path = self.dir.join(file);
        let img = image::open(&path)
            .map_err(|e| Error::file(&path, format!("cannot read the texture: {e}")))?
            .to_rgba8();
        let (w, h) = img.dimensions();
        Texture::from_u8(w, h, 4, img.as_raw(), true)
            .ok_or_else(|| Error::file(&path, "an empty texture"))
    }

    pub(super) fn unsupported(self) -> Vec<String> {
        self.unsupported
    }
}

/// Appends face `k`'s normals and texture coordinates (OBJ's `vt` has v
/// up, glTF's v down: v is flipped here), when the file has them.
pub(super) fn push_attributes(m: &tobj::Mesh, k: usize, out: &mut Attributes) {
    let at = |idx: &[u32], i: usize| idx.get(3 * k + i).map(|&j| j as usize);
    if !m.normals.is_empty() && m.normal_indices.len() == m.indices.len() {
        let n = |i| {
            at(&m.normal_indices, i)
                .and_then(|j| m.normals.get(3 * j..3 * j + 3))
                .map_or(Vec3::ZERO, |c| {
                    Vec3::new(c[0], c[1], c[2]).normalize_or_zero()
                })
        };
        out.normals.push([n(0), n(1), n(2)]);
    }
    if !m.texcoords.is_empty() && m.texcoord_indices.len() == m.indices.len() {
        let t = |i| {
            at(&m.texcoord_indices, i)
                .and_then(|j| m.texcoords.get(2 * j..2 * j + 2))
                .map_or(Vec2::ZERO, |c| Vec2::new(c[0], 1.0 - c[1]))
        };
        out.uvs.push([t(0), t(1), t(2)]);
    }
}
