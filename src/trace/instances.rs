//! Virtual objects as Embree instances: a large object's surfaces are
//! built once in its own frame, and the virtual scene places them by their
//! poses beside the small objects' world triangles. A move rebuilds only
//! that scene, and objects from one mesh share one acceleration structure
//! (an 80,000-triangle object's took 19-24 ms to build on every move, and
//! each copy of it held its own triangles and hierarchy).

use std::hash::{BuildHasher, Hasher};
use std::sync::Arc;

use glam::{Mat3, Vec3};

use super::*;

/// A virtual object as the tracer takes it: its surfaces in its own frame
/// (each `surface` its index among them) and where it stands.
pub struct ObjectInstance<'a> {
    pub surfaces: Vec<SurfaceTriangles<'a>>,
    /// The scene's id of its first surface; the others follow in order.
    pub first_surface: u32,
    /// World point = translate + rotation · (scale · object point).
    pub rotation: glam::DMat3,
    pub scale: f64,
    pub translate: glam::DVec3,
}

impl ObjectInstance<'_> {
    /// Embree's 3×4 column-major transform: the scaled rotation's columns,
    /// then the translation.
    fn transform(&self) -> [f32; 12] {
        let m = self.rotation * self.scale;
        let mut out = [0.0; 12];
        for (k, c) in [m.x_axis, m.y_axis, m.z_axis, self.translate]
            .into_iter()
            .enumerate()
        {
            out[3 * k..3 * k + 3].copy_from_slice(&c.as_vec3().to_array());
        }
        out
    }

    /// What tells one object's surfaces from another's: their triangles
    /// (two independent 64-bit hashes of their bits) and, where a surface
    /// is masked, the mask itself (a mask is a material's, which the
    /// triangles do not tell).
    fn key(&self) -> Key {
        let seeded = |seed: u64| {
            let mut h = foldhash::fast::FixedState::with_seed(seed).build_hasher();
            for s in &self.surfaces {
                h.write_usize(s.triangles.len());
                h.write(triangle_bytes(s.triangles));
                h.write_usize(
                    s.mask
                        .as_ref()
                        .map_or(0, |m| Arc::as_ptr(m) as *const () as usize),
                );
            }
            h.finish()
        };
        Key {
            hashes: [seeded(0x9E37_79B9), seeded(0xC2B2_AE3D)],
            triangles: self.surfaces.iter().map(|s| s.triangles.len()).sum(),
        }
    }
}

/// The bytes of `triangles` (nine f32 each, no padding), to hash.
fn triangle_bytes(triangles: &[Triangle]) -> &[u8] {
    const _: () = assert!(std::mem::size_of::<Triangle>() == 36);
    // SAFETY: a triangle is three `Vec3`s of three f32s each, 36 bytes with
    // no padding (asserted above); any bytes are valid u8s, and the slice
    // borrows `triangles` for its lifetime.
    unsafe {
        std::slice::from_raw_parts(
            triangles.as_ptr() as *const u8,
            std::mem::size_of_val(triangles),
        )
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Key {
    hashes: [u64; 2],
    triangles: usize,
}

/// An instance in a scene of instances: its object's scene, the id of the
/// object's first surface, and its rotation.
pub(super) struct Instanced {
    object: Arc<Geometry>,
    first_surface: u32,
    rotation: Mat3,
}

impl Instanced {
    /// The scene's surface id of the object's geometry `geom_id`, and
    /// normal `ng` of the object's frame turned into the world's.
    pub(super) fn surface_and_normal(&self, geom_id: u32, ng: Vec3) -> (u32, Vec3) {
        let local = self.object.surface_of_geometry[geom_id as usize];
        (self.first_surface + local, self.rotation * ng)
    }
}

/// The objects' own scenes, kept from one placing to the next.
#[derive(Default)]
pub(super) struct ObjectScenes {
    pub(super) kept: Vec<(Key, Arc<Geometry>)>,
}

impl ObjectScenes {
    /// The virtual scene: the surfaces of `world` as they are and
    /// `objects`' instances (None: no triangles), each object's own scene
    /// reused when one of the same surfaces is kept; those no object uses
    /// any more are dropped.
    pub(super) fn place(
        &mut self,
        world: &[SurfaceTriangles],
        objects: &[ObjectInstance],
    ) -> Result<Option<Geometry>, TraceError> {
        let shown: Vec<&ObjectInstance> = (objects.iter())
            .filter(|o| o.surfaces.iter().any(|s| !s.triangles.is_empty()))
            .collect();
        let mut kept = Vec::with_capacity(shown.len());
        let mut placed = Vec::with_capacity(shown.len());
        for o in shown {
            let key = o.key();
            let found = (kept.iter().chain(&self.kept)).find(|(k, _)| *k == key);
            let object = match found {
                Some((_, g)) => Arc::clone(g),
                None => Arc::new(Geometry::build(&o.surfaces, true)?),
            };
            if !kept.iter().any(|(k, _)| *k == key) {
                kept.push((key, Arc::clone(&object)));
            }
            placed.push((object, o));
        }
        self.kept = kept;
        if placed.is_empty() && world.iter().all(|s| s.triangles.is_empty()) {
            return Ok(None);
        }
        Geometry::build_with(world, &placed, true).map(Some)
    }
}

impl Geometry {
    /// Attaches an instance of `object`'s scene placed as `o` to this
    /// scene, not yet committed.
    pub(super) fn attach_instance(
        &mut self,
        device: ffi::RTCDevice,
        object: &Arc<Geometry>,
        o: &ObjectInstance,
    ) -> Result<(), TraceError> {
        let transform = o.transform();
        // SAFETY: the instanced scene is committed and outlives the
        // instance (`self` holds it); Embree copies the transform.
        let id = unsafe {
            let geom = ffi::rtcNewGeometry(device, ffi::RTC_GEOMETRY_TYPE_INSTANCE);
            if geom.is_null() {
                check_device("creating an instance")?;
                return Err(TraceError("could not create an instance".into()));
            }
            ffi::rtcSetGeometryInstancedScene(geom, object.scene.as_ptr());
            ffi::rtcSetGeometryTransform(
                geom,
                0,
                ffi::RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR,
                transform.as_ptr() as *const c_void,
            );
            ffi::rtcCommitGeometry(geom);
            let id = ffi::rtcAttachGeometry(self.scene.as_ptr(), geom);
            ffi::rtcReleaseGeometry(geom);
            id as usize
        };
        check_device("placing an instance")?;
        if self.instances.len() <= id {
            self.instances.resize_with(id + 1, || None);
        }
        self.instances[id] = Some(Instanced {
            object: Arc::clone(object),
            first_surface: o.first_surface,
            rotation: o.rotation.as_mat3(),
        });
        self.triangles += object.triangles;
        Ok(())
    }
}
