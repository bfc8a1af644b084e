//! The virtual objects' patches' reflectances as radiosity exchanges
//! light: a textured object's per patch, read with its mesh
//! ([`crate::patches::ObjectMeshes`]), else its surface's.

use glam::DVec3;

use crate::patches::Patches;
use crate::scene::Scene;

/// Each patch's reflectance from patch `from` on (the objects').
pub fn object_reflectances(scene: &Scene, patches: &Patches, from: usize) -> Vec<DVec3> {
    let rgb = scene.virtual_surface_rgb();
    (from..patches.patch_count())
        .map(|k| {
            let surface = patches.patch(k).surface;
            (patches
                .albedo
                .get(k)
                .copied()
                .flatten()
                .map(|a| a.as_dvec3()))
            .unwrap_or_else(|| rgb.get(&surface).copied().unwrap_or(DVec3::ZERO))
        })
        .collect()
}
