//! A scene handed to the tracer: its real surfaces and its enabled virtual
//! objects as Embree geometry. Kept apart from [`crate::scene`], which is
//! plain data loaded from files, and from [`crate::trace`], which knows
//! triangles, not scenes.

use crate::error::{Error, Result};
use crate::scene::Scene;
use crate::trace::{SurfaceTriangles, Tracer};

/// The real surfaces as tracer input, each with its id.
pub(crate) fn real_triangle_sets(scene: &Scene) -> Vec<SurfaceTriangles<'_>> {
    scene
        .surfaces
        .iter()
        .enumerate()
        .map(|(i, s)| SurfaceTriangles {
            surface: i as u32,
            triangles: &s.triangles,
        })
        .collect()
}

/// Builds the tracer: the real surfaces, and the enabled virtual objects
/// (none built when there are none).
pub fn build_tracer(scene: &Scene) -> Result<Tracer> {
    let virt = scene.virtual_world_surfaces();
    let sets: Vec<SurfaceTriangles> = virt
        .iter()
        .map(|(id, t)| SurfaceTriangles {
            surface: *id,
            triangles: t,
        })
        .collect();
    Tracer::build(&real_triangle_sets(scene), &sets)
        .map_err(|e| Error::file(&scene.file, e.to_string()))
}
