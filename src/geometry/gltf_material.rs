//! A glTF file's materials (metallic-roughness core) with their textures,
//! decoded by the `gltf` crate's image import, and what the file asks that
//! arlux cannot honour (material extensions, a second texture set, …).

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use glam::{Vec3, Vec4};

use crate::error::{Error, Result};
use crate::materials::{Material, Texture};

/// Materials converted as primitives ask for them, textures decoded once.
pub(super) struct GltfMaterials<'a> {
    path: &'a Path,
    doc: &'a gltf::Document,
    buffers: &'a [gltf::buffer::Data],
    images: Option<Vec<gltf::image::Data>>,
    textures: HashMap<(usize, bool), Arc<Texture>>,
    done: HashMap<Option<usize>, Arc<Material>>,
    unsupported: Vec<String>,
}

impl<'a> GltfMaterials<'a> {
    pub(super) fn new(
        path: &'a Path,
        doc: &'a gltf::Document,
        buffers: &'a [gltf::buffer::Data],
    ) -> Self {
        let mut unsupported: Vec<String> = doc
            .extensions_used()
            .filter(|e| e.starts_with("KHR_materials_") || *e == "KHR_texture_transform")
            .map(|e| format!("extension {e}"))
            .collect();
        unsupported.dedup();
        GltfMaterials {
            path,
            doc,
            buffers,
            images: None,
            textures: HashMap::new(),
            done: HashMap::new(),
            unsupported,
        }
    }

    /// The material of a primitive (glTF's default material when it names none).
    pub(super) fn get(&mut self, m: gltf::Material) -> Result<Arc<Material>> {
        if let Some(done) = self.done.get(&m.index()) {
            return Ok(done.clone());
        }
        let pbr = m.pbr_metallic_roughness();
        let name = m.name().map_or_else(
            || format!("material{}", m.index().unwrap_or(0)),
            str::to_string,
        );
        let mut out = Material::plain(
            &name,
            Vec3::ONE,
            pbr.metallic_factor(),
            pbr.roughness_factor(),
        );
        out.base_colour = Vec4::from_array(pbr.base_color_factor()).clamp(Vec4::ZERO, Vec4::ONE);
        out.base_texture = self.texture(&name, pbr.base_color_texture(), true)?;
        out.metallic_roughness_texture =
            self.texture(&name, pbr.metallic_roughness_texture(), false)?;
        if let Some(n) = m.normal_texture() {
            self.texture_set(&name, n.tex_coord(), "normalTexture");
            let t = self.decoded(n.texture(), false)?;
            out.normal_texture = t.map(|t| (t, n.scale()));
        }
        out.emissive = Vec3::from_array(m.emissive_factor()).max(Vec3::ZERO);
        out.emissive_texture = self.texture(&name, m.emissive_texture(), true)?;
        match m.alpha_mode() {
            gltf::material::AlphaMode::Mask => {
                out.alpha_cutoff = Some(m.alpha_cutoff().unwrap_or(0.5))
            }
            gltf::material::AlphaMode::Blend => {
                self.note(format!("{name}: alphaMode BLEND (drawn opaque)"))
            }
            gltf::material::AlphaMode::Opaque => {}
        }
        if m.occlusion_texture().is_some() {
            self.note(format!(
                "{name}: occlusionTexture (light is traced, not baked)"
            ));
        }
        out.double_sided = m.double_sided();
        let out = Arc::new(out);
        self.done.insert(m.index(), out.clone());
        Ok(out)
    }

    fn texture(
        &mut self,
        material: &str,
        info: Option<gltf::texture::Info>,
        srgb: bool,
    ) -> Result<Option<Arc<Texture>>> {
        let Some(info) = info else { return Ok(None) };
        self.texture_set(material, info.tex_coord(), "a texture");
        self.decoded(info.texture(), srgb)
    }

    fn texture_set(&mut self, material: &str, set: u32, what: &str) {
        if set != 0 {
            self.note(format!(
                "{material}: {what} on TEXCOORD_{set} (read on TEXCOORD_0)"
            ));
        }
    }

    fn decoded(&mut self, t: gltf::Texture, srgb: bool) -> Result<Option<Arc<Texture>>> {
        use gltf::texture::WrappingMode;
        let s = t.sampler();
        if s.wrap_s() != WrappingMode::Repeat || s.wrap_t() != WrappingMode::Repeat {
            self.note(format!(
                "texture {}: a wrapping mode other than REPEAT (sampled repeating)",
                t.index()
            ));
        }
        let source = t.source().index();
        if let Some(done) = self.textures.get(&(source, srgb)) {
            return Ok(Some(done.clone()));
        }
        if self.images.is_none() {
            let base = self.path.parent().unwrap_or(Path::new("."));
            self.images =
                Some(decode_images(self.doc, base, self.buffers).map_err(|e| {
                    Error::file(self.path, format!("cannot decode its images: {e}"))
                })?);
        }
        let Some(img) = self.images.as_ref().and_then(|i| i.get(source)) else {
            return Ok(None);
        };
        use gltf::image::Format;
        let channels = match img.format {
            Format::R8 => 1,
            Format::R8G8 => 2,
            Format::R8G8B8 => 3,
            Format::R8G8B8A8 => 4,
            other => {
                self.note(format!(
                    "image {source}: {other:?} texels (only 8-bit are read)"
                ));
                return Ok(None);
            }
        };
        let texture = Texture::from_u8(img.width, img.height, channels, &img.pixels, srgb)
            .ok_or_else(|| Error::file(self.path, format!("image {source} is empty or short")))?;
        let texture = Arc::new(texture);
        self.textures.insert((source, srgb), texture.clone());
        Ok(Some(texture))
    }

    pub(super) fn note(&mut self, what: String) {
        if !self.unsupported.contains(&what) {
            self.unsupported.push(what);
        }
    }

    pub(super) fn unsupported(self) -> Vec<String> {
        self.unsupported
    }
}

/// Every image of the document decoded, as `gltf::import_images` decodes
/// them, but side by side (it decodes one after another: an export's three
/// or four 2k-4k textures took most of the file's load); the first failing
/// image's error, in the document's order.
fn decode_images(
    doc: &gltf::Document,
    base: &Path,
    buffers: &[gltf::buffer::Data],
) -> std::result::Result<Vec<gltf::image::Data>, gltf::Error> {
    use rayon::prelude::*;
    let images: Vec<gltf::Image> = doc.images().collect();
    (images.par_iter())
        .map(|i| gltf::image::Data::from_source(i.source(), Some(base), buffers))
        .collect::<Vec<_>>()
        .into_iter()
        .collect()
}
