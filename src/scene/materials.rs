//! Which material a virtual surface is shaded with: its file's (glTF, or an
//! OBJ material with more than `Kd`), with the scene's `rgb`, `metallic`
//! and `roughness` over it; none (diffuse clay of one colour, as before
//! materials) for a surface whose file gives only a colour and whose scene
//! entry sets neither `metallic` nor `roughness`.

use std::sync::Arc;

use glam::DVec3;

use crate::geometry::MeshSurface;
use crate::materials::{Material, SurfaceMaterial};

/// The `[[virtual]]` keys that override a material's factors.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Overrides {
    pub metallic: Option<f64>,
    pub roughness: Option<f64>,
    /// A scale on the emitted light (0: none).
    pub emission: Option<f64>,
}

/// Surface `s`'s material with the scene's keys over it, or None for clay.
pub(super) fn surface_material(
    s: &MeshSurface,
    rgb: Option<DVec3>,
    looks: Overrides,
    attributes: impl FnOnce() -> Arc<crate::materials::Attributes>,
) -> Result<Option<SurfaceMaterial>, String> {
    let untouched = rgb.is_none()
        && looks.metallic.is_none()
        && looks.roughness.is_none()
        && looks.emission.is_none_or(|e| e == 1.0);
    let mut material = match (&s.material, looks.metallic.or(looks.roughness)) {
        // The file's own material, shared: objects made from one file then
        // share one mesh of patches (`patches::ObjectMeshes` matches
        // materials by pointer; a copy per object meshed each again).
        (Some(m), _) if untouched => {
            return Ok(Some(SurfaceMaterial {
                material: Arc::clone(m),
                attributes: attributes(),
            }));
        }
        (Some(m), _) => (**m).clone(),
        (None, Some(_)) => {
            let base = rgb
                .or(s.material_rgb.map(|c| c.as_dvec3()))
                .ok_or_else(|| {
                    format!(
                        "missing: surface '{}' has no material colour, and metallic or roughness needs one",
                        s.name
                    )
                })?;
            Material::plain(&s.name, base.as_vec3(), 0.0, 1.0)
        }
        (None, None) => return Ok(None),
    };
    if let Some(rgb) = rgb {
        material.base_colour = rgb.as_vec3().extend(material.base_colour.w);
        material.base_texture = None;
    }
    if let Some(m) = looks.metallic {
        material.metallic = m as f32;
        material.metallic_roughness_texture = None;
    }
    if let Some(r) = looks.roughness {
        material.roughness = r as f32;
        material.metallic_roughness_texture = None;
    }
    if let Some(e) = looks.emission {
        material.emissive *= e as f32;
        if e == 0.0 {
            material.emissive_texture = None;
        }
    }
    Ok(Some(SurfaceMaterial {
        material: Arc::new(material),
        attributes: attributes(),
    }))
}
