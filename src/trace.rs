//! Ray tracing by Intel Embree 3 (Debian's `libembree-dev`), bound here by
//! hand: Debian ships Embree 3.13, so `embree4-rs` cannot link. This is the
//! only module of arlux with `unsafe`; moving to Embree 4 changes only it.
//!
//! [`Geometry`] is one committed Embree scene of triangle surfaces, each
//! surface carrying arlux's surface id. [`Tracer`] keeps the real geometry
//! and the virtual objects in two separate scenes, so that "blocked by a
//! virtual object" can be asked alone ([`Layer::Virtual`]) and moving an
//! object rebuilds only the small virtual scene. Queries take `&self` and are
//! safe from any number of rayon threads (Embree's committed scenes are
//! thread-safe for queries).

use std::cell::Cell;
use std::ffi::{CStr, c_char, c_void};
use std::ptr::{NonNull, null, null_mut};
use std::sync::{Mutex, OnceLock};

use glam::Vec3;

use crate::geometry::Triangle;

#[allow(non_camel_case_types)]
mod ffi;
pub mod timing;

/// A failure inside Embree (out of memory, unsupported CPU, bad geometry).
#[derive(Debug, Clone, thiserror::Error)]
#[error("Embree: {0}")]
pub struct TraceError(pub String);

/// The process-wide Embree device. Embree devices are thread-safe; one is
/// enough, and creating it spawns Embree's build threads once.
struct Device(ffi::RTCDevice);
// SAFETY: Embree devices may be used from any thread.
unsafe impl Send for Device {}
unsafe impl Sync for Device {}

static DEVICE: OnceLock<Result<Device, TraceError>> = OnceLock::new();
static LAST_ERROR: Mutex<String> = Mutex::new(String::new());

unsafe extern "C" fn record_error(_user: *mut c_void, code: u32, message: *const c_char) {
    let text = if message.is_null() {
        String::new()
    } else {
        // SAFETY: Embree passes a NUL-terminated string valid for this call.
        unsafe { CStr::from_ptr(message) }
            .to_string_lossy()
            .into_owned()
    };
    if let Ok(mut last) = LAST_ERROR.lock() {
        *last = format!("error {code}: {text}");
    }
}

fn device() -> Result<ffi::RTCDevice, TraceError> {
    let d = DEVICE.get_or_init(|| {
        // SAFETY: a null config asks for defaults; the result is checked.
        let d = unsafe { ffi::rtcNewDevice(null()) };
        if d.is_null() {
            return Err(TraceError(
                "could not create a device (is this CPU supported?)".into(),
            ));
        }
        // SAFETY: `record_error` matches RTCErrorFunction and needs no user data.
        unsafe { ffi::rtcSetDeviceErrorFunction(d, Some(record_error), null_mut()) };
        Ok(Device(d))
    });
    d.as_ref().map(|d| d.0).map_err(Clone::clone)
}

fn check_device(what: &str) -> Result<(), TraceError> {
    let d = device()?;
    // SAFETY: the device is valid for the whole process.
    let code = unsafe { ffi::rtcGetDeviceError(d) };
    if code == 0 {
        return Ok(());
    }
    let detail = LAST_ERROR.lock().map(|s| s.clone()).unwrap_or_default();
    Err(TraceError(format!("{what} failed ({detail})")))
}

thread_local! {
    static FLUSH_DENORMALS_SET: Cell<bool> = const { Cell::new(false) };
}

/// Sets flush-to-zero and denormals-are-zero on the calling thread once:
/// Embree asks for it, and denormals make its traversal slow.
fn ensure_flush_denormals() {
    FLUSH_DENORMALS_SET.with(|set| {
        if !set.get() {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: only the FTZ and DAZ bits of MXCSR are changed.
            #[allow(deprecated)]
            unsafe {
                use std::arch::x86_64::{_mm_getcsr, _mm_setcsr};
                _mm_setcsr(_mm_getcsr() | 0x8040);
            }
            set.set(true);
        }
    });
}

/// A ray segment for the tracer: points `origin + t·direction` for t in
/// (tnear, tfar). `direction` need not be unit; `t` is in its units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceRay {
    pub origin: Vec3,
    pub direction: Vec3,
    pub tnear: f32,
    pub tfar: f32,
}

impl TraceRay {
    /// A ray from `origin` along `direction`, unbounded.
    pub fn new(origin: Vec3, direction: Vec3) -> Self {
        TraceRay {
            origin,
            direction,
            tnear: 0.0,
            tfar: f32::INFINITY,
        }
    }

    /// The open segment from `a` to `b`, shortened by `eps` (a fraction of
    /// its length) at both ends so that the surfaces at the ends do not count.
    pub fn segment(a: Vec3, b: Vec3, eps: f32) -> Self {
        TraceRay {
            origin: a,
            direction: b - a,
            tnear: eps,
            tfar: 1.0 - eps,
        }
    }
}

/// The closest surface a ray hits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// arlux's surface id (as given when the geometry was built).
    pub surface: u32,
    /// Index of the triangle within its surface.
    pub triangle: u32,
    /// Barycentric coordinates: point = (1-u-v)·p0 + u·p1 + v·p2.
    pub u: f32,
    pub v: f32,
    /// Ray parameter of the hit.
    pub t: f32,
    /// Unit geometric normal, turned to face the ray's origin (surfaces are two-sided).
    pub normal: Vec3,
    /// Whether the surface belongs to the virtual layer.
    pub is_virtual: bool,
}

/// One lane of Embree's hit record, as either ray layout stores it.
struct RawHit {
    geom_id: u32,
    inst_id: u32,
    prim_id: u32,
    u: f32,
    v: f32,
    t: f32,
    ng: Vec3,
}

/// Triangles of one surface, with the id the tracer reports for it.
pub struct SurfaceTriangles<'a> {
    pub surface: u32,
    pub triangles: &'a [Triangle],
    /// Where the surface is cut away (an alpha mask): rays pass there.
    pub mask: Option<Mask>,
}

/// Whether a surface is present at barycentric (u, v) of its triangle
/// (Embree's: the point is (1 − u − v)·a + u·b + v·c).
pub type Mask = std::sync::Arc<dyn Fn(u32, f32, f32) -> bool + Send + Sync>;

/// Embree's filter for a masked surface: hits where its mask says the
/// surface is cut away are rejected, so rays continue past them. A mask
/// that panics keeps the hit (unwinding must not cross into Embree).
unsafe extern "C" fn mask_filter(args: *const ffi::RTCFilterFunctionNArguments) {
    // SAFETY: Embree passes valid arguments: `valid` and `hit` hold N
    // lanes, and the user pointer is the `Mask` this geometry was given,
    // kept alive by its `Geometry`.
    unsafe {
        let args = &*args;
        let mask = &*(args.geometry_user_ptr as *const Mask);
        let n = args.n as usize;
        let hit = args.hit as *const f32;
        for i in 0..n {
            let valid = args.valid.add(i);
            if *valid == 0 {
                continue;
            }
            let (u, v) = (*hit.add(3 * n + i), *hit.add(4 * n + i));
            let prim = *(hit as *const u32).add(5 * n + i);
            let present =
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| mask(prim, u, v)))
                    .unwrap_or(true);
            if !present {
                *valid = 0;
            }
        }
    }
}

/// One committed Embree scene.
pub struct Geometry {
    scene: NonNull<c_void>,
    /// The masks its filters read, boxed: Embree holds their addresses,
    /// which must not move when the list grows.
    #[allow(clippy::vec_box)]
    masks: Vec<Box<Mask>>,
    /// arlux surface id of each Embree geometry id.
    surface_of_geometry: Vec<u32>,
    /// A scene of objects' instances: each instance's object, by its
    /// Embree geometry id ([`instances`]).
    instances: Vec<Option<instances::Instanced>>,
    triangles: usize,
    is_virtual: bool,
}

// SAFETY: a committed Embree scene is immutable and safe to query from any
// thread; arlux never modifies it after commit.
unsafe impl Send for Geometry {}
unsafe impl Sync for Geometry {}

impl Drop for Geometry {
    fn drop(&mut self) {
        // SAFETY: the scene was created by rtcNewScene and is released once.
        unsafe { ffi::rtcReleaseScene(self.scene.as_ptr()) };
    }
}

impl Geometry {
    /// Builds and commits a scene from surfaces' triangles.
    pub fn build(surfaces: &[SurfaceTriangles], is_virtual: bool) -> Result<Geometry, TraceError> {
        Geometry::build_with(surfaces, &[], is_virtual)
    }

    /// Builds and commits a scene from surfaces' triangles and instances
    /// of objects' own scenes ([`instances`]).
    fn build_with(
        surfaces: &[SurfaceTriangles],
        objects: &[(std::sync::Arc<Geometry>, &ObjectInstance)],
        is_virtual: bool,
    ) -> Result<Geometry, TraceError> {
        let device = device()?;
        // SAFETY: the device is valid; the result is checked.
        let scene = NonNull::new(unsafe { ffi::rtcNewScene(device) })
            .ok_or_else(|| TraceError("could not create a scene".into()))?;
        let mut g = Geometry {
            scene,
            masks: Vec::new(),
            surface_of_geometry: Vec::new(),
            instances: Vec::new(),
            triangles: 0,
            is_virtual,
        };
        // SAFETY: the scene is valid and not yet committed.
        unsafe {
            ffi::rtcSetSceneBuildQuality(scene.as_ptr(), ffi::RTC_BUILD_QUALITY_MEDIUM);
            ffi::rtcSetSceneFlags(scene.as_ptr(), ffi::RTC_SCENE_FLAG_ROBUST);
        }
        for s in surfaces.iter().filter(|s| !s.triangles.is_empty()) {
            let n = s.triangles.len();
            // SAFETY: buffers are allocated by Embree with the sizes given and
            // filled within those sizes before the geometry is committed.
            let geom_id = unsafe {
                let geom = ffi::rtcNewGeometry(device, ffi::RTC_GEOMETRY_TYPE_TRIANGLE);
                if geom.is_null() {
                    check_device("creating a triangle mesh")?;
                    return Err(TraceError("could not create a triangle mesh".into()));
                }
                let vb = ffi::rtcSetNewGeometryBuffer(
                    geom,
                    ffi::RTC_BUFFER_TYPE_VERTEX,
                    0,
                    ffi::RTC_FORMAT_FLOAT3,
                    12,
                    3 * n,
                ) as *mut [f32; 3];
                let ib = ffi::rtcSetNewGeometryBuffer(
                    geom,
                    ffi::RTC_BUFFER_TYPE_INDEX,
                    0,
                    ffi::RTC_FORMAT_UINT3,
                    12,
                    n,
                ) as *mut [u32; 3];
                if vb.is_null() || ib.is_null() {
                    ffi::rtcReleaseGeometry(geom);
                    check_device("allocating mesh buffers")?;
                    return Err(TraceError("could not allocate mesh buffers".into()));
                }
                let verts = std::slice::from_raw_parts_mut(vb, 3 * n);
                let idx = std::slice::from_raw_parts_mut(ib, n);
                for (i, t) in s.triangles.iter().enumerate() {
                    for k in 0..3 {
                        verts[3 * i + k] = t[k].to_array();
                    }
                    let base = 3 * i as u32;
                    idx[i] = [base, base + 1, base + 2];
                }
                if let Some(mask) = &s.mask {
                    let boxed = Box::new(mask.clone());
                    let user = &*boxed as *const Mask as *mut c_void;
                    ffi::rtcSetGeometryUserData(geom, user);
                    ffi::rtcSetGeometryIntersectFilterFunction(geom, Some(mask_filter));
                    ffi::rtcSetGeometryOccludedFilterFunction(geom, Some(mask_filter));
                    g.masks.push(boxed);
                }
                ffi::rtcCommitGeometry(geom);
                let id = ffi::rtcAttachGeometry(scene.as_ptr(), geom);
                ffi::rtcReleaseGeometry(geom);
                id
            };
            let slot = geom_id as usize;
            if g.surface_of_geometry.len() <= slot {
                g.surface_of_geometry.resize(slot + 1, u32::MAX);
            }
            g.surface_of_geometry[slot] = s.surface;
            g.triangles += n;
        }
        for (object, o) in objects {
            g.attach_instance(device, object, o)?;
        }
        // SAFETY: all geometries are attached and committed.
        unsafe { ffi::rtcCommitScene(scene.as_ptr()) };
        check_device("building the acceleration structure")?;
        Ok(g)
    }

    pub fn triangle_count(&self) -> usize {
        self.triangles
    }

    // Embree's hit record, read out of either ray layout; the normal turned
    // to face the ray.
    fn hit_from(&self, h: RawHit, dir: Vec3) -> Option<Hit> {
        if h.geom_id == ffi::RTC_INVALID_GEOMETRY_ID {
            return None;
        }
        // Embree gives an instance's normal in the object's own frame.
        let (surface, ng) = match self
            .instances
            .get(h.inst_id as usize)
            .and_then(Option::as_ref)
        {
            Some(i) => i.surface_and_normal(h.geom_id, h.ng),
            None => (self.surface_of_geometry[h.geom_id as usize], h.ng),
        };
        let n = ng.normalize_or_zero();
        let normal = if n.dot(dir) > 0.0 { -n } else { n };
        Some(Hit {
            surface,
            triangle: h.prim_id,
            u: h.u,
            v: h.v,
            t: h.t,
            normal,
            is_virtual: self.is_virtual,
        })
    }

    /// The closest hit along the ray, if any.
    pub fn intersect(&self, ray: &TraceRay) -> Option<Hit> {
        let _timed = timing::start(timing::Kind::Intersect1, 1);
        ensure_flush_denormals();
        let mut rh = ffi::RTCRayHit {
            ray: ffi::RTCRay {
                org: ray.origin.to_array(),
                tnear: ray.tnear,
                dir: ray.direction.to_array(),
                tfar: ray.tfar,
                mask: u32::MAX,
                ..Default::default()
            },
            hit: ffi::RTCHit {
                geom_id: ffi::RTC_INVALID_GEOMETRY_ID,
                inst_id: [ffi::RTC_INVALID_GEOMETRY_ID],
                ..Default::default()
            },
        };
        let mut ctx = ffi::RTCIntersectContext::new();
        // SAFETY: the scene is committed; ray and context are valid for the call.
        unsafe { ffi::rtcIntersect1(self.scene.as_ptr(), &mut ctx, &mut rh) };
        let h = rh.hit;
        let raw = RawHit {
            geom_id: h.geom_id,
            inst_id: h.inst_id[0],
            prim_id: h.prim_id,
            u: h.u,
            v: h.v,
            t: rh.ray.tfar,
            ng: Vec3::from_array(h.ng),
        };
        self.hit_from(raw, ray.direction)
    }

    /// Whether anything lies on the ray between tnear and tfar.
    pub fn occluded(&self, ray: &TraceRay) -> bool {
        let _timed = timing::start(timing::Kind::Occluded1, 1);
        ensure_flush_denormals();
        let mut r = ffi::RTCRay {
            org: ray.origin.to_array(),
            tnear: ray.tnear,
            dir: ray.direction.to_array(),
            tfar: ray.tfar,
            mask: u32::MAX,
            ..Default::default()
        };
        let mut ctx = ffi::RTCIntersectContext::new();
        // SAFETY: the scene is committed; ray and context are valid for the call.
        unsafe { ffi::rtcOccluded1(self.scene.as_ptr(), &mut ctx, &mut r) };
        r.tfar == f32::NEG_INFINITY
    }

    /// Fills the N-wide packet `p` from up to N rays, in place, and
    /// `valid` with its mask: lanes past the rays get an empty ray, as a
    /// fresh packet would have. Built where it is used: building it
    /// elsewhere and moving it in (1 kB per packet, tens of thousands of
    /// packets per update) cost as much as the rest of the setup.
    fn fill_packet<const N: usize>(
        p: &mut ffi::RTCRayN<N>,
        valid: &mut [i32; N],
        rays: &[TraceRay],
    ) {
        debug_assert!(rays.len() <= N);
        for (i, lane) in valid.iter_mut().enumerate() {
            let r = rays.get(i).unwrap_or(&EMPTY_LANE);
            p.org_x[i] = r.origin.x;
            p.org_y[i] = r.origin.y;
            p.org_z[i] = r.origin.z;
            p.tnear[i] = r.tnear;
            p.dir_x[i] = r.direction.x;
            p.dir_y[i] = r.direction.y;
            p.dir_z[i] = r.direction.z;
            p.tfar[i] = r.tfar;
            *lane = if i < rays.len() { -1 } else { 0 };
        }
    }

    /// Closest hits of many rays, traced in packets of 16 (write one result per ray).
    pub fn intersect_batch(&self, rays: &[TraceRay], out: &mut [Option<Hit>]) {
        let _timed = timing::start(timing::Kind::IntersectPacket, rays.len());
        assert_eq!(rays.len(), out.len());
        ensure_flush_denormals();
        let mut ctx = ffi::RTCIntersectContext::new();
        let mut rh = ffi::RTCRayHit16 {
            ray: ffi::RTCRayN::EMPTY,
            hit: EMPTY_HIT16,
        };
        let mut valid = [0i32; 16];
        for (chunk, res) in rays.chunks(16).zip(out.chunks_mut(16)) {
            Self::fill_packet(&mut rh.ray, &mut valid, chunk);
            // Embree writes only the lanes that hit something.
            rh.hit.geom_id = [ffi::RTC_INVALID_GEOMETRY_ID; 16];
            rh.hit.inst_id = [[ffi::RTC_INVALID_GEOMETRY_ID; 16]];
            // SAFETY: the packet is 64-byte aligned as Embree requires; the
            // scene is committed; inactive lanes are masked off.
            unsafe { ffi::rtcIntersect16(valid.as_ptr(), self.scene.as_ptr(), &mut ctx, &mut rh) };
            let h = &rh.hit;
            for (i, o) in res.iter_mut().enumerate() {
                let raw = RawHit {
                    geom_id: h.geom_id[i],
                    inst_id: h.inst_id[0][i],
                    prim_id: h.prim_id[i],
                    u: h.u[i],
                    v: h.v[i],
                    t: rh.ray.tfar[i],
                    ng: Vec3::new(h.ng_x[i], h.ng_y[i], h.ng_z[i]),
                };
                *o = self.hit_from(raw, chunk[i].direction);
            }
        }
    }

    /// Occlusion of many rays, traced in packets of 16 (four or fewer in
    /// one packet of 4: a light term's first rays, a short visibility test).
    pub fn occluded_batch(&self, rays: &[TraceRay], out: &mut [bool]) {
        let _timed = timing::start(timing::Kind::OccludedPacket, rays.len());
        assert_eq!(rays.len(), out.len());
        ensure_flush_denormals();
        let mut ctx = ffi::RTCIntersectContext::new();
        if rays.len() <= 4 {
            let mut packet = ffi::RTCRayN::<4>::EMPTY;
            let mut valid = [0i32; 4];
            Self::fill_packet(&mut packet, &mut valid, rays);
            // SAFETY: the packet is aligned as Embree requires; the scene
            // is committed; inactive lanes are masked off.
            unsafe {
                ffi::rtcOccluded4(valid.as_ptr(), self.scene.as_ptr(), &mut ctx, &mut packet)
            };
            for (i, o) in out.iter_mut().enumerate() {
                *o = packet.tfar[i] == f32::NEG_INFINITY;
            }
            return;
        }
        let mut packet = ffi::RTCRayN::<16>::EMPTY;
        let mut valid = [0i32; 16];
        for (chunk, res) in rays.chunks(16).zip(out.chunks_mut(16)) {
            Self::fill_packet(&mut packet, &mut valid, chunk);
            // SAFETY: as in `intersect_batch`.
            unsafe {
                ffi::rtcOccluded16(valid.as_ptr(), self.scene.as_ptr(), &mut ctx, &mut packet)
            };
            for (i, o) in res.iter_mut().enumerate() {
                *o = packet.tfar[i] == f32::NEG_INFINITY;
            }
        }
    }
}

/// An inactive lane of a packet.
const EMPTY_LANE: TraceRay = TraceRay {
    origin: Vec3::ZERO,
    direction: Vec3::Z,
    tnear: 0.0,
    tfar: 0.0,
};

const EMPTY_HIT16: ffi::RTCHit16 = ffi::RTCHit16 {
    ng_x: [0.0; 16],
    ng_y: [0.0; 16],
    ng_z: [0.0; 16],
    u: [0.0; 16],
    v: [0.0; 16],
    prim_id: [0; 16],
    geom_id: [ffi::RTC_INVALID_GEOMETRY_ID; 16],
    inst_id: [[ffi::RTC_INVALID_GEOMETRY_ID; 16]],
};

/// Which geometry a query sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layer {
    Real,
    Virtual,
    All,
}

/// The real scene and, when there are virtual objects, the virtual one.
pub struct Tracer {
    pub real: Geometry,
    pub virtual_objects: Option<Geometry>,
    /// The objects' own scenes the virtual one instances, kept for the next
    /// pose ([`Tracer::build_with_objects`]).
    object_scenes: instances::ObjectScenes,
}

impl Tracer {
    /// Builds the real scene, and the virtual one only if it has triangles
    /// (a scene without virtual objects builds no virtual geometry).
    pub fn build(
        real: &[SurfaceTriangles],
        virtual_objects: &[SurfaceTriangles],
    ) -> Result<Tracer, TraceError> {
        let real = Geometry::build(real, false)?;
        let has_virtual = virtual_objects.iter().any(|s| !s.triangles.is_empty());
        let virtual_objects = if has_virtual {
            Some(Geometry::build(virtual_objects, true)?)
        } else {
            None
        };
        Ok(Tracer {
            real,
            virtual_objects,
            object_scenes: Default::default(),
        })
    }

    /// Builds the real scene, and the virtual one from the surfaces of
    /// `world` (in the world's frame) and instances of `objects`' own
    /// scenes (none built when there are no triangles): objects of one
    /// mesh share its scene, and a move keeps it.
    pub fn build_with_objects(
        real: &[SurfaceTriangles],
        world: &[SurfaceTriangles],
        objects: &[ObjectInstance],
    ) -> Result<Tracer, TraceError> {
        let mut tracer = Tracer::build(real, &[])?;
        tracer.place_objects(world, objects)?;
        Ok(tracer)
    }

    /// Places the virtual objects again (after a move), as
    /// [`Tracer::build_with_objects`] does: the real scene is kept, and so
    /// is each instanced object's own scene that is still shown.
    pub(crate) fn place_objects(
        &mut self,
        world: &[SurfaceTriangles],
        objects: &[ObjectInstance],
    ) -> Result<(), TraceError> {
        self.virtual_objects = self.object_scenes.place(world, objects)?;
        Ok(())
    }

    /// The closest hit in the given layer.
    pub fn intersect(&self, ray: &TraceRay, layer: Layer) -> Option<Hit> {
        let real = if layer != Layer::Virtual {
            self.real.intersect(ray)
        } else {
            None
        };
        if layer == Layer::Real {
            return real;
        }
        let Some(v) = &self.virtual_objects else {
            return real;
        };
        let mut shortened = *ray;
        if let Some(h) = &real {
            shortened.tfar = h.t;
        }
        v.intersect(&shortened).or(real)
    }

    /// Whether anything in the given layer blocks the ray segment.
    pub fn occluded(&self, ray: &TraceRay, layer: Layer) -> bool {
        let virt = || {
            self.virtual_objects
                .as_ref()
                .is_some_and(|v| v.occluded(ray))
        };
        match layer {
            Layer::Real => self.real.occluded(ray),
            Layer::Virtual => virt(),
            Layer::All => virt() || self.real.occluded(ray),
        }
    }

    /// Closest hits of many rays in the given layer, in packets of 16.
    pub fn intersect_batch(&self, rays: &[TraceRay], layer: Layer, out: &mut [Option<Hit>]) {
        let virt = self
            .virtual_objects
            .as_ref()
            .filter(|_| layer != Layer::Real);
        match (layer, virt) {
            (Layer::Virtual, None) => out.iter_mut().for_each(|o| *o = None),
            (Layer::Virtual, Some(v)) => v.intersect_batch(rays, out),
            (_, None) => self.real.intersect_batch(rays, out),
            (_, Some(_)) => {
                self.real.intersect_batch(rays, out);
                let before: Vec<f32> = rays
                    .iter()
                    .zip(out.iter())
                    .map(|(r, h)| h.map_or(r.tfar, |h| h.t))
                    .collect();
                self.put_virtual_in_front(rays, &before, out);
            }
        }
    }

    /// Replaces each of `hits` (a [`Layer::Real`] query's) by the closest
    /// virtual hit nearer than `before` (that hit's distance, or the ray's
    /// end), where there is one: the second half of a [`Layer::All`] query,
    /// for a caller that kept the first.
    pub(crate) fn put_virtual_in_front(
        &self,
        rays: &[TraceRay],
        before: &[f32],
        hits: &mut [Option<Hit>],
    ) {
        let mut near = vec![None; rays.len()];
        self.intersect_virtual_before(rays, before, &mut near);
        for (h, n) in hits.iter_mut().zip(near) {
            if n.is_some() {
                *h = n;
            }
        }
    }

    /// The closest virtual hit of each ray nearer than `before` (its real
    /// hit's distance, or its own end): the second half of a
    /// [`Layer::All`] query, for a caller that kept the first.
    pub(crate) fn intersect_virtual_before(
        &self,
        rays: &[TraceRay],
        before: &[f32],
        out: &mut [Option<Hit>],
    ) {
        assert_eq!(rays.len(), before.len());
        let Some(v) = &self.virtual_objects else {
            out.iter_mut().for_each(|o| *o = None);
            return;
        };
        let shortened: Vec<TraceRay> = rays
            .iter()
            .zip(before)
            .map(|(r, &t)| TraceRay { tfar: t, ..*r })
            .collect();
        v.intersect_batch(&shortened, out);
    }

    /// Occlusion of many rays in the given layer, in packets of 16.
    pub fn occluded_batch(&self, rays: &[TraceRay], layer: Layer, out: &mut [bool]) {
        let virt = self.virtual_objects.as_ref();
        match layer {
            Layer::Real => self.real.occluded_batch(rays, out),
            Layer::Virtual => match virt {
                Some(v) => v.occluded_batch(rays, out),
                None => out.iter_mut().for_each(|o| *o = false),
            },
            Layer::All => {
                self.real.occluded_batch(rays, out);
                if let Some(v) = virt {
                    let mut blocked = vec![false; rays.len()];
                    v.occluded_batch(rays, &mut blocked);
                    out.iter_mut().zip(blocked).for_each(|(o, b)| *o |= b);
                }
            }
        }
    }
}

mod instances;
pub use instances::ObjectInstance;

#[cfg(test)]
mod tests;
