//! A scene handed to the tracer: its real surfaces and its enabled virtual
//! objects as Embree geometry. Kept apart from [`crate::scene`], which is
//! plain data loaded from files, and from [`crate::trace`], which knows
//! triangles, not scenes.

use crate::error::{Error, Result};
use crate::geometry::Triangle;
use crate::scene::{Scene, VirtualObject};
use crate::trace::{Mask, ObjectInstance, SurfaceTriangles, Tracer};

/// The real surfaces as tracer input, each with its id.
pub(crate) fn real_triangle_sets(scene: &Scene) -> Vec<SurfaceTriangles<'_>> {
    scene
        .surfaces
        .iter()
        .enumerate()
        .map(|(i, s)| SurfaceTriangles {
            surface: i as u32,
            triangles: &s.triangles,
            mask: None,
        })
        .collect()
}

/// Objects of at least this many triangles are traced as instances of
/// their own scene ([`ObjectInstance`]), the others as world triangles.
/// An instance's rays cross two hierarchies (the desk box's update spent
/// 2% more in its ray stages), while a world object's hierarchy is built
/// anew on every move, about 0.3 µs a triangle (an 80,000-triangle
/// object's 19-24 ms; the 2,000-triangle stool's 0.5 ms).
pub const INSTANCE_TRIANGLES: usize = 8192;

/// Builds the tracer: the real surfaces, and the enabled virtual objects
/// (none built when there are none).
pub fn build_tracer(scene: &Scene) -> Result<Tracer> {
    let small: Vec<(u32, Vec<Triangle>)> = (scene.virtual_surfaces())
        .filter(|(_, o, _)| o.enabled && !instanced(o))
        .map(|(id, o, i)| (id, o.world_triangles(i)))
        .collect();
    Tracer::build_with_objects(
        &real_triangle_sets(scene),
        &world_triangle_sets(scene, &small),
        &object_instances(scene),
    )
    .map_err(|e| Error::file(&scene.file, e.to_string()))
}

/// Whether `o` is traced as an instance ([`INSTANCE_TRIANGLES`]).
fn instanced(o: &VirtualObject) -> bool {
    o.surfaces.iter().map(|s| s.triangles.len()).sum::<usize>() >= INSTANCE_TRIANGLES
}

/// The surfaces of `virt` (world triangles by surface id, as
/// [`Scene::virtual_world_surfaces`] gives them) whose objects are not
/// instanced, as tracer input, each with its material's alpha mask when it
/// has one.
pub(crate) fn world_triangle_sets<'a>(
    scene: &Scene,
    virt: &'a [(u32, Vec<Triangle>)],
) -> Vec<SurfaceTriangles<'a>> {
    let masks = alpha_masks(scene);
    let of_instances: std::collections::HashSet<u32> = (scene.virtual_surfaces())
        .filter(|(_, o, _)| instanced(o))
        .map(|(id, _, _)| id)
        .collect();
    (virt.iter())
        .filter(|(id, _)| !of_instances.contains(id))
        .map(|(id, t)| SurfaceTriangles {
            surface: *id,
            triangles: t,
            mask: masks.get(id).cloned(),
        })
        .collect()
}

/// The enabled objects traced as instances, as tracer input: their
/// surfaces in their own frames, each with its material's alpha mask when
/// it has one, and their poses.
pub(crate) fn object_instances(scene: &Scene) -> Vec<ObjectInstance<'_>> {
    let masks = alpha_masks(scene);
    let mut out = Vec::new();
    for (first, o, _) in scene.virtual_surfaces().filter(|&(_, _, i)| i == 0) {
        if !o.enabled || !instanced(o) {
            continue;
        }
        let surfaces = (o.surfaces.iter().enumerate())
            .map(|(k, s)| SurfaceTriangles {
                surface: k as u32,
                triangles: &s.triangles,
                mask: masks.get(&(first + k as u32)).cloned(),
            })
            .collect();
        out.push(ObjectInstance {
            surfaces,
            first_surface: first,
            rotation: o.pose.rotation,
            scale: o.pose.scale,
            translate: o.pose.translate,
        });
    }
    out
}

/// Per virtual surface id, the tracer's mask of a material with alphaMode
/// MASK: present where the base colour's alpha at the point's texture
/// coordinate reaches the cutoff.
fn alpha_masks(scene: &Scene) -> std::collections::HashMap<u32, Mask> {
    let mut out = std::collections::HashMap::new();
    for (id, o, i) in scene.virtual_surfaces() {
        let material = o.surfaces[i].material.as_ref();
        let Some(m) = material.filter(|m| m.material.alpha_cutoff.is_some()) else {
            continue;
        };
        let (material, attributes) = (m.material.clone(), m.attributes.clone());
        let mask: Mask = std::sync::Arc::new(move |k: u32, u: f32, v: f32| {
            let uv = attributes
                .uvs
                .get(k as usize)
                .map_or(glam::Vec2::ZERO, |t| {
                    t[0] * (1.0 - u - v) + t[1] * u + t[2] * v
                });
            material.at(uv, 0.0).opaque
        });
        out.insert(id, mask);
    }
    out
}
