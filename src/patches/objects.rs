//! The virtual objects' patches, meshed once in each object's own frame
//! and moved with it. An object's elements, their splits and welded
//! vertices depend on its triangles and its scale only: a move turns and
//! shifts them (a pass over its elements), where meshing them again (the
//! closed-solid tests, the quads' pairing, the splits, the weld) cost an
//! 80k-triangle prop 170 ms a pose. Meshed in the object's frame, the same
//! object also gets the same patches wherever it stands (meshed in the
//! world, rounding in the weld and the pairing moved a few patches), and
//! objects made from one mesh at one scale are meshed once.

use std::sync::Arc;

use glam::DVec3;

use super::{Element, Patches, Shape, SurfaceInput};
use crate::geometry::Triangle;
use crate::materials::SurfaceMaterial;
use crate::scene::{ObjectSurface, Pose, Scene};

/// Objects' meshes in their own frames, kept between poses by a session
/// (`keep`), else only for the objects of one scene (instances of one
/// mesh meshed once).
#[derive(Debug, Clone, Default)]
pub struct ObjectMeshes {
    keep: bool,
    /// The surfaces of an object of this many triangles or more are meshed
    /// on their coarse meshes where they have one ([`super::proxy`]; None:
    /// every surface on its own triangles).
    coarse_from: Option<usize>,
    meshed: Vec<Meshed>,
}

#[derive(Debug, Clone)]
struct Meshed {
    /// The surface's triangles in its object's frame, unscaled (the
    /// scene's own array).
    triangles: Arc<[Triangle]>,
    scale: f64,
    size: f64,
    /// Meshed on its coarse mesh when it has one.
    coarse: bool,
    /// The textured material its patches' albedo was read from.
    material: Option<SurfaceMaterial>,
    /// Surface 0 of this mesh, its coordinates scaled, not turned or moved.
    block: Patches,
    used: bool,
}

impl ObjectMeshes {
    /// `keep`: keep the meshes for the next scene (a session's next pose).
    pub fn new(keep: bool) -> ObjectMeshes {
        ObjectMeshes {
            keep,
            coarse_from: None,
            meshed: Vec::new(),
        }
    }

    /// [`ObjectMeshes::new`], meshing the surfaces of an object of `from`
    /// triangles or more on their coarse meshes (`patches::proxy`: their
    /// triangles clustered on cells a quarter of the patch size; None: on
    /// their own triangles).
    pub fn coarse_from(self, from: Option<usize>) -> ObjectMeshes {
        ObjectMeshes {
            coarse_from: from,
            ..self
        }
    }

    /// How many distinct meshes are held (objects from one file, at one
    /// scale and with one material, share one).
    pub fn mesh_count(&self) -> usize {
        self.meshed.len()
    }

    /// The index of the mesh of `triangles` at `scale` with leaves no
    /// larger than `size`, each patch's albedo read from `material` when
    /// it is textured, meshed now if it is not kept; on its coarse mesh
    /// when its object holds `object_triangles` ≥ the `coarse_from` asked
    /// (a real asset's many materials each hold a part of its triangles).
    fn mesh(
        &mut self,
        surface: &ObjectSurface,
        scale: f64,
        size: f64,
        object_triangles: usize,
    ) -> usize {
        let triangles = &surface.triangles[..];
        let coarse = self.coarse_from.is_some_and(|n| object_triangles >= n);
        let material = super::albedo::textured(surface).cloned();
        let same = |a: &Option<SurfaceMaterial>, b: &Option<SurfaceMaterial>| match (a, b) {
            (Some(a), Some(b)) => {
                Arc::ptr_eq(&a.material, &b.material) && Arc::ptr_eq(&a.attributes, &b.attributes)
            }
            (None, None) => true,
            _ => false,
        };
        let found = self.meshed.iter().position(|m| {
            m.scale == scale
                && m.size == size
                && m.coarse == coarse
                && same(&m.material, &material)
                && (Arc::ptr_eq(&m.triangles, &surface.triangles) || m.triangles[..] == *triangles)
        });
        let k = found.unwrap_or_else(|| {
            let scaled: Vec<Triangle> = triangles
                .iter()
                .map(|t| t.map(|p| (p.as_dvec3() * scale).as_vec3()))
                .collect();
            let proxy = coarse
                .then(|| super::proxy::coarse_block(&scaled, size))
                .flatten();
            let block = match (proxy, &material) {
                (Some((mut block, members)), m) => {
                    if let Some(m) = m {
                        block.albedo =
                            super::albedo::coarse_block_albedo(&block, &scaled, &members, m);
                    }
                    block
                }
                (None, m) => {
                    let input = SurfaceInput {
                        surface: 0,
                        triangles: &scaled,
                        is_virtual: true,
                    };
                    let mut block = Patches::build(&[input], size);
                    if let Some(m) = m {
                        block.albedo = super::albedo::block_albedo(&block, &scaled, m);
                    }
                    block
                }
            };
            self.meshed.push(Meshed {
                triangles: surface.triangles.clone(),
                scale,
                size,
                coarse,
                material,
                block,
                used: false,
            });
            self.meshed.len() - 1
        });
        self.meshed[k].used = true;
        k
    }
}

impl Patches {
    /// Meshes the scene's enabled objects after what this mesh holds, each
    /// surface under the id the tracer knows it by, with leaves no larger
    /// than `size` metres.
    pub(crate) fn append_objects(&mut self, scene: &Scene, size: f64, meshes: &mut ObjectMeshes) {
        let mut id = scene.surfaces.len() as u32;
        let mut placed = Vec::new();
        for o in &scene.objects {
            let count = o.surfaces.iter().map(|s| s.triangles.len()).sum();
            for s in &o.surfaces {
                if o.enabled {
                    placed.push((meshes.mesh(s, o.pose.scale, size, count), id, &o.pose));
                }
                id += 1;
            }
        }
        // Room for them all at once: grown object by object, each
        // reallocation held the old and the new arrays (three 80k-triangle
        // objects' elements alone are 70 MB).
        let blocks = || placed.iter().map(|&(k, ..)| &meshes.meshed[k].block);
        self.elements
            .reserve(blocks().map(|b| b.elements.len()).sum());
        self.vertices
            .reserve(blocks().map(|b| b.vertices.len()).sum());
        self.patches
            .reserve(blocks().map(|b| b.patches.len()).sum());
        self.patch_vertices
            .reserve(blocks().map(|b| b.patch_vertices.len()).sum());
        self.albedo.reserve(blocks().map(|b| b.albedo.len()).sum());
        for &(k, id, pose) in &placed {
            self.place(&meshes.meshed[k].block, id, pose);
        }
        if meshes.keep {
            // What the scene no longer shows is dropped.
            meshes.meshed.retain(|m| m.used);
            meshes.meshed.iter_mut().for_each(|m| m.used = false);
        } else {
            meshes.meshed.clear();
        }
    }

    /// Appends `block`'s surface 0 as surface `surface`, turned and moved
    /// by `pose` (its scale is the block's own already).
    fn place(&mut self, block: &Patches, surface: u32, pose: &Pose) {
        use rayon::prelude::*;
        let (e0, p0, v0) = (
            self.elements.len() as u32,
            self.patches.len() as u32,
            self.vertices.len() as u32,
        );
        let (r, t) = (pose.rotation, pose.translate);
        let at = |x: DVec3| t + r * x;
        let moved = |shape: Shape| match shape {
            Shape::Tri(c) => Shape::Tri(c.map(at)),
            Shape::Quad { origin, u, v } => Shape::Quad {
                origin: at(origin),
                u: r * u,
                v: r * v,
            },
        };
        self.elements
            .par_extend(block.elements.par_iter().map(|el| {
                let shape = moved(el.shape);
                Element {
                    shape,
                    bounds: shape.bounds(),
                    size: el.size,
                    area: el.area,
                    centre: at(el.centre),
                    normal: r * el.normal,
                    surface,
                    one_sided: el.one_sided,
                    root: el.root + e0,
                    parent: el.parent.map(|p| p + e0),
                    children: el.children.map(|c| c.map(|c| c + e0)),
                    patch: el.patch.map(|p| p + p0),
                    region: el.region,
                }
            }));
        self.roots.extend(block.roots.iter().map(|&e| e + e0));
        self.patches.extend(block.patches.iter().map(|&e| e + e0));
        (self.vertices).par_extend(block.vertices.par_iter().map(|&v| at(v)));
        self.albedo.extend_from_slice(&block.albedo);
        (self.surface_samples).extend(
            block
                .surface_samples
                .iter()
                .map(|(&k, &shape)| (k + p0, moved(shape))),
        );
        self.patch_vertices.extend(
            block
                .patch_vertices
                .iter()
                .map(|ids| ids.map(|v| if v == u32::MAX { v } else { v + v0 })),
        );
        self.surface_is_virtual.insert(surface, true);
        let s = surface as usize;
        if self.root_of_triangle.len() <= s {
            self.root_of_triangle.resize(s + 1, Vec::new());
        }
        self.root_of_triangle[s] = block.root_of_triangle.first().map_or(Vec::new(), |of| {
            of.iter()
                .map(|&e| if e == u32::MAX { e } else { e + e0 })
                .collect()
        });
    }
}
