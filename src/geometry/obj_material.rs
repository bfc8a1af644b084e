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
            .map_err(|e| Error::file(&path, format!("cannot read the texture: {e}")))?;
        let (w, h) = (img.width(), img.height());
        // In 8 bits with the channels the file has (a texture holds no
        // more): grey, grey and alpha, RGB or RGBA, read as RGBA alike.
        let colour = img.color();
        let (channels, texels) = match (colour.has_color(), colour.has_alpha()) {
            (false, false) => (1, img.into_luma8().into_raw()),
            (false, true) => (2, img.into_luma_alpha8().into_raw()),
            (true, false) => (3, img.into_rgb8().into_raw()),
            (true, true) => (4, img.into_rgba8().into_raw()),
        };
        Texture::from_u8(w, h, channels, &texels, true)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_texture_keeps_the_file_s_channels_and_reads_as_its_rgba_would() {
        // Each layout saved as a PNG, read by `map_Kd`, against the same
        // image expanded to RGBA first (as textures were read before).
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (5, 3);
        let code = |x: u32, y: u32, k: u32| ((37 * x + 91 * y + 53 * k) % 256) as u8;
        let images: Vec<(&str, image::DynamicImage)> = vec![
            (
                "grey.png",
                image::GrayImage::from_fn(w, h, |x, y| image::Luma([code(x, y, 0)])).into(),
            ),
            (
                "grey_alpha.png",
                image::GrayAlphaImage::from_fn(w, h, |x, y| {
                    image::LumaA([code(x, y, 0), code(x, y, 1)])
                })
                .into(),
            ),
            (
                "rgb.png",
                image::RgbImage::from_fn(w, h, |x, y| {
                    image::Rgb([code(x, y, 0), code(x, y, 1), code(x, y, 2)])
                })
                .into(),
            ),
            (
                "rgba.png",
                image::RgbaImage::from_fn(w, h, |x, y| {
                    image::Rgba([code(x, y, 0), code(x, y, 1), code(x, y, 2), code(x, y, 3)])
                })
                .into(),
            ),
        ];
        let reader = ObjMaterials::new(dir.path(), &[]);
        for (channels, (file, img)) in (1..=4).zip(images) {
            img.save(dir.path().join(file)).unwrap();
            let texture = reader.image(file).unwrap();
            let rgba = img.to_rgba8();
            let expanded = Texture::from_u8(w, h, 4, rgba.as_raw(), true).unwrap();
            assert_eq!(texture.texels(), expanded.texels(), "{file}");
            // A byte a channel the file has on the full level.
            let full = (w * h) as usize * channels;
            assert!(texture.memory_bytes() < expanded.memory_bytes() || channels == 4);
            assert!(texture.memory_bytes() >= full, "{file}");
        }
    }
}
