//! Materials of virtual objects: glTF 2.0 metallic-roughness (base colour,
//! metallic, roughness, their textures, a normal texture, emission, alpha
//! MASK, double-sidedness) and the per-vertex attributes shading needs
//! (smooth normals, texture coordinates, tangents). [`brdf`] holds the BRDF;
//! [`texture`] the textures. The mesh readers fill these; the object
//! shader ([`crate::object_shading`]) evaluates them per pixel.

use std::sync::Arc;

use glam::{DVec3, Vec2, Vec3, Vec4};

pub mod brdf;
pub mod texture;

pub use brdf::Lobes;
pub use texture::Texture;

/// The lobes of a base colour, metallic and roughness, each clamped to [0, 1].
fn lobes_of(base: Vec4, metallic: f32, roughness: f32) -> Lobes {
    Lobes {
        base: base.truncate().as_dvec3().clamp(DVec3::ZERO, DVec3::ONE),
        metallic: metallic.clamp(0.0, 1.0) as f64,
        roughness: roughness.clamp(0.0, 1.0) as f64,
    }
}

/// A glTF 2.0 metallic-roughness material (factors times textures).
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    pub name: String,
    /// Linear RGBA base colour factor.
    pub base_colour: Vec4,
    /// sRGB-decoded base colour texture (alpha linear).
    pub base_texture: Option<Arc<Texture>>,
    pub metallic: f32,
    pub roughness: f32,
    /// glTF's metallicRoughnessTexture: roughness in G, metallic in B (linear).
    pub metallic_roughness_texture: Option<Arc<Texture>>,
    /// Tangent-space normal texture and its scale.
    pub normal_texture: Option<(Arc<Texture>, f32)>,
    /// Linear emitted radiance factor, and its sRGB texture.
    pub emissive: Vec3,
    pub emissive_texture: Option<Arc<Texture>>,
    /// alphaMode MASK: texels whose alpha is below this are holes.
    pub alpha_cutoff: Option<f32>,
    pub double_sided: bool,
}

impl Material {
    /// A material of one colour, no textures.
    pub fn plain(name: &str, base: Vec3, metallic: f32, roughness: f32) -> Material {
        Material {
            name: name.to_string(),
            base_colour: base.extend(1.0),
            base_texture: None,
            metallic: metallic.clamp(0.0, 1.0),
            roughness: roughness.clamp(0.0, 1.0),
            metallic_roughness_texture: None,
            normal_texture: None,
            emissive: Vec3::ZERO,
            emissive_texture: None,
            alpha_cutoff: None,
            double_sided: false,
        }
    }

    /// The material at texture coordinate `uv`, over a pixel footprint
    /// `footprint` wide in texture coordinates (selects the mip level).
    pub fn at(&self, uv: Vec2, footprint: f32) -> PointMaterial {
        let texels = |t: &Texture| footprint * ((t.size().0 as f32) * (t.size().1 as f32)).sqrt();
        let (base, metallic, roughness) = self.factors_at(uv, footprint);
        let emissive = match &self.emissive_texture {
            Some(t) => self.emissive * t.sample(uv, texels(t)).truncate(),
            None => self.emissive,
        };
        let normal = self.normal_texture.as_ref().map(|(t, scale)| {
            let s = t.sample(uv, texels(t));
            let n = Vec3::new(
                (2.0 * s.x - 1.0) * scale,
                (2.0 * s.y - 1.0) * scale,
                2.0 * s.z - 1.0,
            );
            n.normalize_or(Vec3::Z)
        });
        PointMaterial {
            lobes: lobes_of(base, metallic, roughness),
            emissive: emissive.as_dvec3().max(DVec3::ZERO),
            opaque: self.alpha_cutoff.is_none_or(|c| base.w >= c),
            tangent_normal: normal,
        }
    }

    /// The lobes alone at `uv` over `footprint` (as [`Material::at`], the
    /// normal and emission textures left unread).
    pub fn lobes_at(&self, uv: Vec2, footprint: f32) -> Lobes {
        let (base, metallic, roughness) = self.factors_at(uv, footprint);
        lobes_of(base, metallic, roughness)
    }

    /// Base colour (with alpha), metallic and roughness at `uv` over
    /// `footprint` wide in texture coordinates, factors times textures.
    fn factors_at(&self, uv: Vec2, footprint: f32) -> (Vec4, f32, f32) {
        // Texels across the footprint: texture coordinates span √(W·H) texels on average.
        let texels = |t: &Texture| footprint * ((t.size().0 as f32) * (t.size().1 as f32)).sqrt();
        let base = match &self.base_texture {
            Some(t) => self.base_colour * t.sample(uv, texels(t)),
            None => self.base_colour,
        };
        let (mut metallic, mut roughness) = (self.metallic, self.roughness);
        if let Some(t) = &self.metallic_roughness_texture {
            let s = t.sample(uv, texels(t));
            roughness *= s.y;
            metallic *= s.z;
        }
        (base, metallic, roughness)
    }

    /// The mean colour and albedo a diffuse exchange of light sees: the base
    /// colour's mean over its texture, through [`brdf::hemispherical_albedo`].
    pub fn mean_albedo(&self) -> DVec3 {
        let base = match &self.base_texture {
            Some(t) => self.base_colour * t.mean(),
            None => self.base_colour,
        };
        let (mut metallic, mut roughness) = (self.metallic, self.roughness);
        if let Some(t) = &self.metallic_roughness_texture {
            let m = t.mean();
            roughness *= m.y;
            metallic *= m.z;
        }
        brdf::hemispherical_albedo(&Lobes {
            base: base.truncate().as_dvec3().clamp(DVec3::ZERO, DVec3::ONE),
            metallic: metallic.clamp(0.0, 1.0) as f64,
            roughness: roughness.clamp(0.0, 1.0) as f64,
        })
        .clamp(DVec3::ZERO, DVec3::ONE)
    }

    /// The mean emitted radiance: the emission factor times its texture's mean.
    pub fn mean_emission(&self) -> DVec3 {
        let e = match &self.emissive_texture {
            Some(t) => self.emissive * t.mean().truncate(),
            None => self.emissive,
        };
        e.as_dvec3().max(DVec3::ZERO)
    }

    /// The brightest radiance it emits anywhere (its factor times its
    /// texture's brightest texel).
    pub fn peak_emission(&self) -> DVec3 {
        let e = match &self.emissive_texture {
            Some(t) => self.emissive * t.max().truncate(),
            None => self.emissive,
        };
        e.as_dvec3().max(DVec3::ZERO)
    }

    /// One line for `arlux info`.
    pub fn describe(&self) -> String {
        let c = self.base_colour;
        // With a texture the factors only scale it: saying "metallic 1.00"
        // alone misreads a textured material.
        let (m, r) = (self.metallic, self.roughness);
        let factors = match self.metallic_roughness_texture {
            Some(_) => format!("metallic and roughness from texture (× {m:.2}, × {r:.2})"),
            None => format!("metallic {m:.2}, roughness {r:.2}"),
        };
        let mut s = format!(
            "'{}': base [{:.3}, {:.3}, {:.3}], {factors}",
            self.name, c.x, c.y, c.z
        );
        for (has, what) in [
            (self.base_texture.is_some(), "base colour texture"),
            (
                self.metallic_roughness_texture.is_some(),
                "metallic-roughness texture",
            ),
            (self.normal_texture.is_some(), "normal texture"),
            (self.emissive != Vec3::ZERO, "emission"),
            (self.alpha_cutoff.is_some(), "alpha mask"),
            (self.double_sided, "double-sided"),
        ] {
            if has {
                s.push_str(", ");
                s.push_str(what);
            }
        }
        s
    }
}

/// A material evaluated at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointMaterial {
    pub lobes: Lobes,
    pub emissive: DVec3,
    /// False where an alpha MASK cuts the surface away.
    pub opaque: bool,
    /// The normal texture's normal in tangent space (z along the surface normal).
    pub tangent_normal: Option<Vec3>,
}

/// Per-triangle shading attributes of a surface, aligned with its
/// triangles; an empty list means the file has none (flat normals, no
/// texture coordinates, tangents from MikkTSpace where a normal texture needs them).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Attributes {
    pub normals: Vec<[Vec3; 3]>,
    pub uvs: Vec<[Vec2; 3]>,
    /// xyz the tangent, w the bitangent's sign (glTF's TANGENT).
    pub tangents: Vec<[Vec4; 3]>,
}

impl Attributes {
    /// Whether the lists hold one entry per triangle of `count` (or none).
    pub fn fits(&self, count: usize) -> bool {
        [self.normals.len(), self.uvs.len(), self.tangents.len()]
            .iter()
            .all(|&n| n == 0 || n == count)
    }

    /// Appends `more` (for triangles appended to a surface that now has
    /// `count` of them): a list one part has and the other lacks is
    /// dropped for the whole surface (flat, untextured), never misaligned.
    pub fn append(&mut self, more: Attributes, count: usize) {
        fn join<T>(a: &mut Vec<T>, b: Vec<T>, count: usize) {
            a.extend(b);
            if a.len() != count {
                a.clear();
            }
        }
        join(&mut self.normals, more.normals, count);
        join(&mut self.uvs, more.uvs, count);
        join(&mut self.tangents, more.tangents, count);
    }

    /// These attributes with MikkTSpace tangents for `triangles` (what
    /// normal textures are baked against, and what glTF asks for when a
    /// file has none), where there are texture coordinates and no tangents.
    /// MikkTSpace reads v up (Blender's convention), glTF's flipped.
    pub fn with_mikktspace(mut self, triangles: &[[Vec3; 3]]) -> Attributes {
        if !self.tangents.is_empty() || self.uvs.len() != triangles.len() || triangles.is_empty() {
            return self;
        }
        let mut mesh = Mikk {
            triangles,
            attributes: &self,
            tangents: vec![[Vec4::ZERO; 3]; triangles.len()],
        };
        if bevy_mikktspace::generate_tangents(&mut mesh).is_ok() {
            self.tangents = mesh.tangents;
        }
        self
    }
}

/// A surface as `bevy_mikktspace` reads it.
struct Mikk<'a> {
    triangles: &'a [[Vec3; 3]],
    attributes: &'a Attributes,
    tangents: Vec<[Vec4; 3]>,
}

impl bevy_mikktspace::Geometry for Mikk<'_> {
    fn num_faces(&self) -> usize {
        self.triangles.len()
    }

    fn num_vertices_of_face(&self, _face: usize) -> usize {
        3
    }

    fn position(&self, face: usize, vert: usize) -> [f32; 3] {
        self.triangles[face][vert].to_array()
    }

    fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
        match self.attributes.normals.get(face) {
            Some(n) => n[vert].to_array(),
            None => {
                let [a, b, c] = self.triangles[face];
                (b - a).cross(c - a).normalize_or_zero().to_array()
            }
        }
    }

    fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
        let uv = self.attributes.uvs[face][vert];
        [uv.x, 1.0 - uv.y]
    }

    fn set_tangent(
        &mut self,
        tangent: Option<bevy_mikktspace::TangentSpace>,
        face: usize,
        vert: usize,
    ) {
        // A corner MikkTSpace leaves without one (a degenerate face) keeps
        // zero: the shader then falls back to the face's own tangent.
        if let Some(t) = tangent {
            self.tangents[face][vert] = Vec4::from_array(t.tangent_encoded());
        }
    }
}

/// A virtual surface's material and attributes, as the object shader reads them.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceMaterial {
    pub material: Arc<Material>,
    pub attributes: Arc<Attributes>,
}

#[cfg(test)]
mod tests;
