use super::*;

pub(crate) type RTCDevice = *mut c_void;
pub(crate) type RTCScene = *mut c_void;
pub(crate) type RTCGeometry = *mut c_void;
pub(crate) type RTCErrorFunction = Option<unsafe extern "C" fn(*mut c_void, u32, *const c_char)>;

pub(crate) const RTC_GEOMETRY_TYPE_TRIANGLE: u32 = 0;
pub(crate) const RTC_GEOMETRY_TYPE_INSTANCE: u32 = 121;
pub(crate) const RTC_BUFFER_TYPE_INDEX: u32 = 0;
pub(crate) const RTC_BUFFER_TYPE_VERTEX: u32 = 1;
pub(crate) const RTC_FORMAT_UINT3: u32 = 0x5003;
pub(crate) const RTC_FORMAT_FLOAT3: u32 = 0x9003;
pub(crate) const RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR: u32 = 0x9234;
pub(crate) const RTC_BUILD_QUALITY_MEDIUM: u32 = 1;
pub(crate) const RTC_SCENE_FLAG_ROBUST: u32 = 1 << 2;
pub(crate) const RTC_INVALID_GEOMETRY_ID: u32 = u32::MAX;

#[repr(C, align(16))]
#[derive(Clone, Copy, Default)]
pub(crate) struct RTCRay {
    pub org: [f32; 3],
    pub tnear: f32,
    pub dir: [f32; 3],
    pub time: f32,
    pub tfar: f32,
    pub mask: u32,
    pub id: u32,
    pub flags: u32,
}

#[repr(C, align(16))]
#[derive(Clone, Copy, Default)]
pub(crate) struct RTCHit {
    pub ng: [f32; 3],
    pub u: f32,
    pub v: f32,
    pub prim_id: u32,
    pub geom_id: u32,
    pub inst_id: [u32; 1],
}

#[repr(C)]
#[derive(Clone, Copy, Default)]
pub(crate) struct RTCRayHit {
    pub ray: RTCRay,
    pub hit: RTCHit,
}

/// `RTCRay4`, `RTCRay16` (N = 4, 16): the rays of a packet, field by
/// field. Embree asks 16-byte alignment of the first and 64 of the
/// second; both get 64.
#[repr(C, align(64))]
#[derive(Clone, Copy)]
pub(crate) struct RTCRayN<const N: usize> {
    pub org_x: [f32; N],
    pub org_y: [f32; N],
    pub org_z: [f32; N],
    pub tnear: [f32; N],
    pub dir_x: [f32; N],
    pub dir_y: [f32; N],
    pub dir_z: [f32; N],
    pub time: [f32; N],
    pub tfar: [f32; N],
    pub mask: [u32; N],
    pub id: [u32; N],
    pub flags: [u32; N],
}

impl<const N: usize> RTCRayN<N> {
    /// Every lane an inactive ray.
    pub(crate) const EMPTY: Self = RTCRayN {
        org_x: [0.0; N],
        org_y: [0.0; N],
        org_z: [0.0; N],
        tnear: [0.0; N],
        dir_x: [0.0; N],
        dir_y: [0.0; N],
        dir_z: [1.0; N],
        time: [0.0; N],
        tfar: [0.0; N],
        mask: [u32::MAX; N],
        id: [0; N],
        flags: [0; N],
    };
}

#[repr(C, align(64))]
#[derive(Clone, Copy)]
pub(crate) struct RTCHit16 {
    pub ng_x: [f32; 16],
    pub ng_y: [f32; 16],
    pub ng_z: [f32; 16],
    pub u: [f32; 16],
    pub v: [f32; 16],
    pub prim_id: [u32; 16],
    pub geom_id: [u32; 16],
    pub inst_id: [[u32; 16]; 1],
}

#[repr(C)]
#[derive(Clone, Copy)]
pub(crate) struct RTCRayHit16 {
    pub ray: RTCRayN<16>,
    pub hit: RTCHit16,
}

/// `rtcInitIntersectContext` is an inline function in the header; this is it.
#[repr(C)]
pub(crate) struct RTCIntersectContext {
    pub flags: u32,
    pub filter: *const c_void,
    pub inst_id: [u32; 1],
}

impl RTCIntersectContext {
    pub fn new() -> Self {
        RTCIntersectContext {
            flags: 0,
            filter: null(),
            inst_id: [RTC_INVALID_GEOMETRY_ID],
        }
    }
}

// Layouts as the C headers define them (checked with offsetof, see
// docs in the engineering notes).
const _: () = assert!(std::mem::size_of::<RTCRay>() == 48);
const _: () = assert!(std::mem::size_of::<RTCHit>() == 32);
const _: () = assert!(std::mem::size_of::<RTCRayHit>() == 80);
const _: () = assert!(std::mem::offset_of!(RTCRayHit, hit) == 48);
const _: () = assert!(std::mem::size_of::<RTCIntersectContext>() == 24);
const _: () = assert!(std::mem::offset_of!(RTCIntersectContext, inst_id) == 16);
const _: () = assert!(std::mem::size_of::<RTCRayN<16>>() == 768);
const _: () = assert!(std::mem::size_of::<RTCRayN<4>>() == 192);
const _: () = assert!(std::mem::size_of::<RTCHit16>() == 512);

/// Embree's arguments to a geometry's filter function (rtcore_common.h).
#[repr(C)]
pub(crate) struct RTCFilterFunctionNArguments {
    pub valid: *mut i32,
    pub geometry_user_ptr: *mut c_void,
    pub context: *mut c_void,
    pub ray: *mut c_void,
    /// `RTCHitN`: N normals' x, y, z, then N u, N v, N primID, … (4 bytes each).
    pub hit: *mut c_void,
    pub n: u32,
}

pub(crate) type RTCFilterFunctionN =
    Option<unsafe extern "C" fn(*const RTCFilterFunctionNArguments)>;

#[link(name = "embree3")]
unsafe extern "C" {
    pub(crate) fn rtcNewDevice(config: *const c_char) -> RTCDevice;
    pub(crate) fn rtcGetDeviceError(device: RTCDevice) -> u32;
    pub(crate) fn rtcSetDeviceErrorFunction(
        device: RTCDevice,
        f: RTCErrorFunction,
        user: *mut c_void,
    );
    pub(crate) fn rtcNewScene(device: RTCDevice) -> RTCScene;
    pub(crate) fn rtcReleaseScene(scene: RTCScene);
    pub(crate) fn rtcSetSceneBuildQuality(scene: RTCScene, quality: u32);
    pub(crate) fn rtcSetSceneFlags(scene: RTCScene, flags: u32);
    pub(crate) fn rtcCommitScene(scene: RTCScene);
    pub(crate) fn rtcNewGeometry(device: RTCDevice, kind: u32) -> RTCGeometry;
    pub(crate) fn rtcSetNewGeometryBuffer(
        geometry: RTCGeometry,
        kind: u32,
        slot: u32,
        format: u32,
        byte_stride: usize,
        count: usize,
    ) -> *mut c_void;
    pub(crate) fn rtcCommitGeometry(geometry: RTCGeometry);
    pub(crate) fn rtcSetGeometryUserData(geometry: RTCGeometry, ptr: *mut c_void);
    pub(crate) fn rtcSetGeometryIntersectFilterFunction(
        geometry: RTCGeometry,
        filter: RTCFilterFunctionN,
    );
    pub(crate) fn rtcSetGeometryOccludedFilterFunction(
        geometry: RTCGeometry,
        filter: RTCFilterFunctionN,
    );
    pub(crate) fn rtcSetGeometryInstancedScene(geometry: RTCGeometry, scene: RTCScene);
    pub(crate) fn rtcSetGeometryTransform(
        geometry: RTCGeometry,
        time_step: u32,
        format: u32,
        xfm: *const c_void,
    );
    pub(crate) fn rtcAttachGeometry(scene: RTCScene, geometry: RTCGeometry) -> u32;
    pub(crate) fn rtcReleaseGeometry(geometry: RTCGeometry);
    pub(crate) fn rtcIntersect1(
        scene: RTCScene,
        ctx: *mut RTCIntersectContext,
        rayhit: *mut RTCRayHit,
    );
    pub(crate) fn rtcOccluded1(scene: RTCScene, ctx: *mut RTCIntersectContext, ray: *mut RTCRay);
    pub(crate) fn rtcIntersect16(
        valid: *const i32,
        scene: RTCScene,
        ctx: *mut RTCIntersectContext,
        rayhit: *mut RTCRayHit16,
    );
    pub(crate) fn rtcOccluded16(
        valid: *const i32,
        scene: RTCScene,
        ctx: *mut RTCIntersectContext,
        ray: *mut RTCRayN<16>,
    );
    pub(crate) fn rtcOccluded4(
        valid: *const i32,
        scene: RTCScene,
        ctx: *mut RTCIntersectContext,
        ray: *mut RTCRayN<4>,
    );
}
