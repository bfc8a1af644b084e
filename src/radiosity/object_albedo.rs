//! The virtual objects' patches' reflectances as radiosity exchanges light:
//! a textured material's albedo over each patch, not its mean over the
//! whole texture. A globe's oceans and a bottle's label send the floor
//! their own colours: with one mean per surface, the light an object
//! bounces onto the floor beside it had the colour of its whole texture
//! (on `materials` `globe_floor` the floor in the globe's half shadow took
//! 0.81 of the truth's change in red and 1.11 in blue).

use glam::DVec3;

use crate::materials::{SurfaceMaterial, brdf};
use crate::patches::Patches;
use crate::scene::{Pose, Scene};

/// Each patch's reflectance from patch `from` on (the objects'): for a
/// surface whose material has a base-colour or metallic-roughness texture,
/// the material at the patch centre's texture coordinate, filtered over
/// the patch's extent in the texture (the mip level of its size), through
/// [`brdf::table_albedo`]; else the surface's reflectance.
pub fn object_reflectances(scene: &Scene, patches: &Patches, from: usize) -> Vec<DVec3> {
    use rayon::prelude::*;
    let rgb = scene.virtual_surface_rgb();
    let textured = textured_surfaces(scene, patches);
    (from..patches.patch_count())
        .into_par_iter()
        .map(|k| {
            let surface = patches.patch(k).surface;
            textured
                .get(&surface)
                .and_then(|t| t.albedo(patches, k))
                .unwrap_or_else(|| rgb.get(&surface).copied().unwrap_or(DVec3::ZERO))
        })
        .collect()
}

/// A shown surface with a textured material, and which of its triangles
/// each root element covers.
struct Textured<'a> {
    material: &'a SurfaceMaterial,
    triangles: &'a [crate::geometry::Triangle],
    pose: &'a Pose,
    /// Per root element: its first triangle and, for a quad, its second.
    of_root: crate::util::FastMap<u32, [u32; 2]>,
}

fn textured_surfaces<'a>(
    scene: &'a Scene,
    patches: &Patches,
) -> crate::util::FastMap<u32, Textured<'a>> {
    let mut out = crate::util::fast_map();
    let mut id = scene.surfaces.len() as u32;
    for o in &scene.objects {
        for s in &o.surfaces {
            // Texture coordinates per triangle, and a texture to read.
            let textured = s.material.as_ref().filter(|m| {
                let t = &m.material;
                m.attributes.uvs.len() == s.triangles.len()
                    && (t.base_texture.is_some() || t.metallic_roughness_texture.is_some())
            });
            if let (true, Some(material)) = (o.enabled, textured) {
                let mut of_root: crate::util::FastMap<u32, [u32; 2]> = crate::util::fast_map();
                for t in 0..s.triangles.len() as u32 {
                    if let Some(r) = patches.root_of(id, t) {
                        of_root.entry(r).and_modify(|e| e[1] = t).or_insert([t, t]);
                    }
                }
                let surface = Textured {
                    material,
                    triangles: &s.triangles,
                    pose: &o.pose,
                    of_root,
                };
                out.insert(id, surface);
            }
            id += 1;
        }
    }
    out
}

impl Textured<'_> {
    /// Patch `k`'s albedo (None: its triangle is not known).
    fn albedo(&self, patches: &Patches, k: usize) -> Option<DVec3> {
        let el = patches.patch(k);
        let pair = self.of_root.get(&el.root)?;
        let pose = self.pose;
        // The centre in the object's frame, where its triangles are.
        let local = pose.rotation.transpose() * (el.centre - pose.translate) / pose.scale;
        // Of the root's triangles, the one the centre lies in (the least
        // outside, for a point on their shared diagonal).
        let (t, w) = pair
            .iter()
            .map(|&t| {
                let [a, b, c] = self.triangles[t as usize].map(|p| p.as_dvec3());
                (t, crate::geometry::barycentric(a, b, c, local))
            })
            .max_by(|x, y| min3(x.1).total_cmp(&min3(y.1)))?;
        let uv = self.material.attributes.uvs[t as usize];
        let at = uv[0].as_dvec2() * w[0] + uv[1].as_dvec2() * w[1] + uv[2].as_dvec2() * w[2];
        // The patch's extent in the texture: its area scaled as its
        // triangle maps world area to texture area.
        let [a, b, c] = self.triangles[t as usize].map(|p| p.as_dvec3() * pose.scale);
        let world = 0.5 * (b - a).cross(c - a).length();
        let (p, q) = ((uv[1] - uv[0]).as_dvec2(), (uv[2] - uv[0]).as_dvec2());
        let texture = 0.5 * (p.x * q.y - p.y * q.x).abs();
        let footprint = if world > 0.0 {
            (el.area * texture / world).sqrt()
        } else {
            0.0
        };
        let point = self.material.material.at(at.as_vec2(), footprint as f32);
        let albedo = brdf::table_albedo(&point.lobes);
        albedo.is_finite().then_some(albedo)
    }
}

fn min3(w: [f64; 3]) -> f64 {
    w[0].min(w[1]).min(w[2])
}
