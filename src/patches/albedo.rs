//! A textured object's albedo per patch, as radiosity exchanges light:
//! the material read over each patch, not its mean over the whole
//! texture. A globe's oceans and a bottle's label send the floor their
//! own colours: with one mean per surface, the light an object bounced
//! onto the floor beside it had the colour of its whole texture (on
//! `materials` `globe_floor` the floor in the globe's half shadow took
//! 0.75 of the truth's change in red and 1.05 in blue). Read once per
//! mesh in the object's frame ([`super::ObjectMeshes`]): it moves with it.

use glam::DVec3;

use super::Patches;
use crate::geometry::Triangle;
use crate::materials::{SurfaceMaterial, brdf};
use crate::scene::ObjectSurface;

/// The surface's material if it has a texture the albedo reads (base
/// colour or metallic-roughness) and a texture coordinate per triangle.
pub(crate) fn textured(surface: &ObjectSurface) -> Option<&SurfaceMaterial> {
    surface.material.as_ref().filter(|m| {
        let t = &m.material;
        m.attributes.uvs.len() == surface.triangles.len()
            && (t.base_texture.is_some() || t.metallic_roughness_texture.is_some())
    })
}

/// Each patch's albedo in `block`, the mesh of `triangles` as surface 0:
/// the material at the patch centre's texture coordinate, filtered over
/// the patch's extent in the texture (the mip level of its size), through
/// [`brdf::table_albedo`] (None where its triangle is not known).
pub(crate) fn block_albedo(
    block: &Patches,
    triangles: &[Triangle],
    material: &SurfaceMaterial,
) -> Vec<Option<glam::Vec3>> {
    use rayon::prelude::*;
    let mut of_root: crate::util::FastMap<u32, [u32; 2]> = crate::util::fast_map();
    for t in 0..triangles.len() as u32 {
        if let Some(r) = block.root_of(0, t) {
            of_root.entry(r).and_modify(|e| e[1] = t).or_insert([t, t]);
        }
    }
    (0..block.patch_count())
        .into_par_iter()
        .map(|k| {
            let el = block.patch(k);
            let pair = of_root.get(&el.root)?;
            // Single precision, as the texture it comes from.
            patch_albedo(el.centre, el.area, pair, triangles, material).map(|a| a.as_vec3())
        })
        .collect()
}

/// The albedo at `centre` of a patch of `area` on the root covering
/// triangles `pair` (a quad's two, or one twice).
fn patch_albedo(
    centre: DVec3,
    area: f64,
    pair: &[u32; 2],
    triangles: &[Triangle],
    material: &SurfaceMaterial,
) -> Option<DVec3> {
    let corners = |t: u32| triangles[t as usize].map(|p| p.as_dvec3());
    // Of the root's triangles, the one the centre lies in (the least
    // outside, for a point on their shared diagonal).
    let (t, w) = pair
        .iter()
        .map(|&t| {
            let [a, b, c] = corners(t);
            (t, crate::geometry::barycentric(a, b, c, centre))
        })
        .max_by(|x, y| min3(x.1).total_cmp(&min3(y.1)))?;
    let uv = material.attributes.uvs[t as usize];
    let at = uv[0].as_dvec2() * w[0] + uv[1].as_dvec2() * w[1] + uv[2].as_dvec2() * w[2];
    // The patch's extent in the texture: its area scaled as its triangle
    // maps area to texture area.
    let [a, b, c] = corners(t);
    let surface = 0.5 * (b - a).cross(c - a).length();
    let (p, q) = ((uv[1] - uv[0]).as_dvec2(), (uv[2] - uv[0]).as_dvec2());
    let texture = 0.5 * (p.x * q.y - p.y * q.x).abs();
    let footprint = if surface > 0.0 {
        (area * texture / surface).sqrt()
    } else {
        0.0
    };
    let lobes = material.material.lobes_at(at.as_vec2(), footprint as f32);
    let albedo = brdf::table_albedo(&lobes);
    albedo.is_finite().then_some(albedo)
}

/// Each patch's albedo in `block`, meshed coarser than `triangles`
/// ([`super::proxy`]): the area-weighted mean of the albedo at the
/// centre of every triangle under its root (`members`), each read over
/// its own triangle's extent.
pub(crate) fn coarse_block_albedo(
    block: &Patches,
    triangles: &[Triangle],
    members: &crate::util::FastMap<u32, Vec<u32>>,
    material: &SurfaceMaterial,
) -> Vec<Option<glam::Vec3>> {
    use rayon::prelude::*;
    (0..block.patch_count())
        .into_par_iter()
        .map(|k| {
            let (mut sum, mut area) = (DVec3::ZERO, 0.0);
            for &t in members.get(&block.patch(k).root)? {
                let [a, b, c] = triangles[t as usize].map(|p| p.as_dvec3());
                let at = 0.5 * (b - a).cross(c - a).length();
                if let Some(albedo) =
                    patch_albedo((a + b + c) / 3.0, at, &[t, t], triangles, material)
                {
                    sum += albedo * at;
                    area += at;
                }
            }
            (area > 0.0).then(|| (sum / area).as_vec3())
        })
        .collect()
}

fn min3(w: [f64; 3]) -> f64 {
    w[0].min(w[1]).min(w[2])
}
