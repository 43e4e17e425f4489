//! Embree 3 as a reference tracer for benchmarks (feature `embree`, links Debian's
//! `libembree3`). A minimal FFI over the C API: one triangle geometry per mesh, so Embree's
//! (geomID, primID) are raywave's (instance, primitive).

use crate::kernels::trace::{Hit, Ray};
use crate::{Error, Result, Scene};
use glam::Vec2;
use std::ffi::c_void;
use std::time::{Duration, Instant};

/// `RTC_INVALID_GEOMETRY_ID`.
const INVALID_ID: u32 = u32::MAX;
const GEOMETRY_TYPE_TRIANGLE: u32 = 0;
const BUFFER_TYPE_INDEX: u32 = 0;
const BUFFER_TYPE_VERTEX: u32 = 1;
const FORMAT_UINT3: u32 = 0x5003;
const FORMAT_FLOAT3: u32 = 0x9003;
const BUILD_QUALITY_HIGH: u32 = 2;
/// `RTC_ERROR_NONE`.
const ERROR_NONE: u32 = 0;

/// `struct RTCRay` (rtcore_ray.h).
#[repr(C, align(16))]
#[derive(Copy, Clone, Default)]
struct RtcRay {
    org: [f32; 3],
    tnear: f32,
    dir: [f32; 3],
    time: f32,
    tfar: f32,
    mask: u32,
    id: u32,
    flags: u32,
}

/// `struct RTCHit` with `RTC_MAX_INSTANCE_LEVEL_COUNT == 1` (Debian's build).
#[repr(C, align(16))]
#[derive(Copy, Clone, Default)]
struct RtcHit {
    ng: [f32; 3],
    u: f32,
    v: f32,
    prim_id: u32,
    geom_id: u32,
    inst_id: [u32; 1],
}

/// `struct RTCRayHit`.
#[repr(C)]
#[derive(Copy, Clone, Default)]
struct RtcRayHit {
    ray: RtcRay,
    hit: RtcHit,
}

/// `struct RTCIntersectContext` with one instance level and no minimum width (Debian's build).
#[repr(C)]
struct RtcIntersectContext {
    flags: u32,
    filter: *const c_void,
    inst_id: [u32; 1],
}

const _: () = assert!(std::mem::size_of::<RtcRay>() == 48 && std::mem::size_of::<RtcHit>() == 32);
const _: () = assert!(std::mem::size_of::<RtcRayHit>() == 80);
const _: () = assert!(std::mem::size_of::<RtcIntersectContext>() == 24);

#[link(name = "embree3")]
unsafe extern "C" {
    fn rtcNewDevice(config: *const std::ffi::c_char) -> *mut c_void;
    fn rtcReleaseDevice(device: *mut c_void);
    fn rtcGetDeviceError(device: *mut c_void) -> u32;
    fn rtcNewScene(device: *mut c_void) -> *mut c_void;
    fn rtcSetSceneBuildQuality(scene: *mut c_void, quality: u32);
    fn rtcReleaseScene(scene: *mut c_void);
    fn rtcNewGeometry(device: *mut c_void, kind: u32) -> *mut c_void;
    fn rtcSetNewGeometryBuffer(
        geometry: *mut c_void,
        kind: u32,
        slot: u32,
        format: u32,
        byte_stride: usize,
        count: usize,
    ) -> *mut c_void;
    fn rtcCommitGeometry(geometry: *mut c_void);
    fn rtcAttachGeometry(scene: *mut c_void, geometry: *mut c_void) -> u32;
    fn rtcReleaseGeometry(geometry: *mut c_void);
    fn rtcCommitScene(scene: *mut c_void);
    fn rtcIntersect1(scene: *mut c_void, context: *mut RtcIntersectContext, rayhit: *mut RtcRayHit);
    fn rtcOccluded1(scene: *mut c_void, context: *mut RtcIntersectContext, ray: *mut RtcRay);
}

/// A committed Embree scene (high build quality), safe to query from many threads.
pub struct EmbreeScene {
    device: *mut c_void,
    scene: *mut c_void,
    build_time: Duration,
}

// SAFETY: Embree scenes are immutable after rtcCommitScene and documented as thread-safe for
// rtcIntersect1/rtcOccluded1 from any number of threads.
unsafe impl Send for EmbreeScene {}
// SAFETY: as above.
unsafe impl Sync for EmbreeScene {}

impl Drop for EmbreeScene {
    fn drop(&mut self) {
        // SAFETY: both handles were created by `build` and are released exactly once.
        unsafe {
            rtcReleaseScene(self.scene);
            rtcReleaseDevice(self.device);
        }
    }
}

/// The first error Embree recorded on `device` since the last call (`rtcGetDeviceError`, which
/// clears it) as the module's typed error, naming the call it was found after: Embree's commits
/// return nothing, and a failed one (out of memory, say) leaves a scene every ray misses.
///
/// # Safety
/// `device` is a live Embree device.
unsafe fn check_device(device: *mut c_void, after: &str) -> Result<()> {
    // SAFETY: the caller's.
    let code = unsafe { rtcGetDeviceError(device) };
    if code == ERROR_NONE {
        return Ok(());
    }
    // `enum RTCError` (rtcore_device.h).
    let what = match code {
        2 => "invalid argument",
        3 => "invalid operation",
        4 => "out of memory",
        5 => "unsupported CPU",
        6 => "cancelled",
        _ => "unknown error",
    };
    Err(Error::InvalidParameter { name: "embree", reason: format!("{after}: {what} (RTCError {code})") })
}

fn context() -> RtcIntersectContext {
    // rtcInitIntersectContext: incoherent flag (0), no filter, invalid instance id.
    RtcIntersectContext { flags: 0, filter: std::ptr::null(), inst_id: [INVALID_ID] }
}

fn rtc_ray(ray: &Ray) -> RtcRay {
    RtcRay {
        org: ray.origin.to_array(),
        tnear: ray.tmin,
        dir: ray.direction.to_array(),
        tfar: ray.tmax,
        mask: u32::MAX,
        ..RtcRay::default()
    }
}

impl EmbreeScene {
    /// Builds the scene: one committed triangle geometry per mesh, attached in mesh order.
    pub fn build(scene: &Scene) -> Result<Self> {
        let unavailable = |what: &str| Error::InvalidParameter { name: "embree", reason: what.to_owned() };
        // SAFETY: plain Embree API calls; every buffer is written within the size Embree allocated.
        unsafe {
            let device = rtcNewDevice(std::ptr::null());
            if device.is_null() {
                return Err(unavailable("rtcNewDevice failed"));
            }
            // Timed from here: the device's start-up (its thread pool) is not part of a build,
            // as obvhs's build time has none.
            let start = Instant::now();
            let handle = rtcNewScene(device);
            let mut this = Self { device, scene: handle, build_time: Duration::ZERO };
            rtcSetSceneBuildQuality(handle, BUILD_QUALITY_HIGH);
            for (index, mesh) in scene.meshes().iter().enumerate() {
                let geometry = rtcNewGeometry(device, GEOMETRY_TYPE_TRIANGLE);
                let vertices =
                    rtcSetNewGeometryBuffer(geometry, BUFFER_TYPE_VERTEX, 0, FORMAT_FLOAT3, 12, mesh.positions.len())
                        as *mut [f32; 3];
                let indices =
                    rtcSetNewGeometryBuffer(geometry, BUFFER_TYPE_INDEX, 0, FORMAT_UINT3, 12, mesh.triangles.len())
                        as *mut [u32; 3];
                if vertices.is_null() || indices.is_null() {
                    rtcReleaseGeometry(geometry);
                    return Err(unavailable("rtcSetNewGeometryBuffer failed"));
                }
                for (i, p) in mesh.positions.iter().enumerate() {
                    *vertices.add(i) = p.to_array();
                }
                for (i, t) in mesh.triangles.iter().enumerate() {
                    *indices.add(i) = *t;
                }
                rtcCommitGeometry(geometry);
                let id = rtcAttachGeometry(handle, geometry);
                rtcReleaseGeometry(geometry);
                check_device(device, &format!("rtcCommitGeometry of mesh {index}"))?;
                if id != index as u32 {
                    return Err(unavailable("geometry ids are not dense"));
                }
            }
            rtcCommitScene(handle);
            check_device(device, "rtcCommitScene")?;
            this.build_time = start.elapsed();
            Ok(this)
        }
    }

    /// Wall-clock time of the build: geometry upload and the committed BVH, without the Embree
    /// device's creation.
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Closest hit with `rtcIntersect1`; barycentrics in Embree's (u, v) = weights of vertices 1, 2.
    pub fn closest_hit(&self, ray: &Ray) -> Hit {
        let mut rayhit = RtcRayHit {
            ray: rtc_ray(ray),
            hit: RtcHit { geom_id: INVALID_ID, inst_id: [INVALID_ID], ..RtcHit::default() },
        };
        let mut context = context();
        // SAFETY: `self.scene` is committed; the structs match Embree's layout (asserted above).
        unsafe { rtcIntersect1(self.scene, &mut context, &mut rayhit) };
        if rayhit.hit.geom_id == INVALID_ID {
            return Hit::MISS;
        }
        Hit {
            t: rayhit.ray.tfar,
            primitive: rayhit.hit.prim_id,
            instance: rayhit.hit.geom_id,
            barycentrics: Vec2::new(rayhit.hit.u, rayhit.hit.v),
        }
    }

    /// Occlusion with `rtcOccluded1` (Embree sets `tfar` to −∞ when blocked).
    pub fn occluded(&self, ray: &Ray) -> bool {
        let mut rtc = rtc_ray(ray);
        let mut context = context();
        // SAFETY: as in `closest_hit`.
        unsafe { rtcOccluded1(self.scene, &mut context, &mut rtc) };
        rtc.tfar == f32::NEG_INFINITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An error Embree records (here a build quality it does not know) is the module's typed error
    /// naming the call it followed, and is read once: the check after it passes. `build` runs this
    /// check after every `rtcCommitGeometry` and after `rtcCommitScene`, whose failures (out of
    /// memory) a test cannot bring about.
    #[test]
    fn a_device_error_is_a_typed_error_naming_the_call() {
        // SAFETY: plain Embree API calls on a device and scene released at the end.
        unsafe {
            let device = rtcNewDevice(std::ptr::null());
            assert!(!device.is_null());
            let scene = rtcNewScene(device);
            assert!(check_device(device, "rtcNewScene").is_ok());
            rtcSetSceneBuildQuality(scene, 99);
            let error = check_device(device, "rtcSetSceneBuildQuality").unwrap_err();
            assert!(
                matches!(&error, Error::InvalidParameter { name: "embree", reason }
                    if reason.starts_with("rtcSetSceneBuildQuality: ")),
                "{error}"
            );
            assert!(check_device(device, "rtcSetSceneBuildQuality").is_ok(), "read twice");
            rtcReleaseScene(scene);
            rtcReleaseDevice(device);
        }
    }
}
