//! The texture path's objects with materials: their pixels shaded by their
//! BRDF ([`crate::object_shading`]) after the display of a light change.

use super::*;
use crate::object_shading::{ObjectMaterials, ObjectShading, ShadingSettings};
use crate::pda::{PatchPoint, SurfacePoint};
use crate::trace::TraceRay;

impl TexturePath {
    /// Replaces the pixels of `out` that show an object with a material by
    /// that object's shading under `scales`, with the room's indirect
    /// irradiance per patch `indirect`. The room a reflection sees is the
    /// photo changed by the direct light's with ÷ without (this path keeps
    /// one indirect solution, the changed one).
    pub(super) fn shade_objects(
        &self,
        out: &mut Composite,
        scene: &Scene,
        tracer: &Tracer,
        scales: &[f64],
        indirect: &[DVec3],
    ) {
        let materials = ObjectMaterials::of(scene);
        if materials.is_empty() {
            return;
        }
        let h = self.patches.vertex_values(indirect);
        let without: Vec<f64> = self.lights.iter().map(|l| l.photo_scale()).collect();
        let shading = ObjectShading {
            materials: &materials,
            tracer,
            camera: &scene.camera,
            photo: &self.photo,
            lights: &self.lights,
            scales_with: scales,
            scales_without: &without,
            patches: &self.patches,
            indirect_with: &h,
            indirect_without: &h,
            reflectance: &self.reflectance,
            settings: ShadingSettings::default(),
            brightness: crate::object_shading::mean_luminance(&self.photo),
        };
        let w = self.photo.width.max(1);
        let shaded: Vec<(usize, Vec3)> = self
            .pixels
            .par_iter()
            .enumerate()
            .filter_map(|(i, px)| {
                let Some(PixelPoint::Virtual { at }) = px else {
                    return None;
                };
                let ray = scene.camera.pixel_ray(i as u32 % w, i as u32 / w);
                let trace = TraceRay::new(ray.origin.as_vec3(), ray.direction.as_vec3());
                let hit = tracer
                    .intersect(&trace, Layer::All)
                    .filter(|h| h.is_virtual)?;
                let p = SurfacePoint {
                    position: (ray.origin + ray.direction * hit.t as f64).as_vec3(),
                    normal: hit.normal,
                    surface: hit.surface,
                    is_virtual: true,
                    pixel_terms: false,
                    clear_of_own: false,
                    location: PatchPoint {
                        patch: at.patch,
                        weights: at.weights.map(|(_, w)| w as f32),
                    },
                };
                shading.radiance(&p, 1.0).map(|v| (i, v.as_vec3()))
            })
            .collect();
        let layers = out.object.pixels.len() == out.image.pixels.len();
        for (i, v) in shaded {
            out.image.pixels[i] = v;
            if layers {
                out.object.pixels[i] = v * out.alpha[i];
                out.change.pixels[i] = v - self.photo.pixels[i];
            }
        }
    }
}
