//! Intel Embree 3 as a peer in the benchmark (cargo feature `embree`): a small
//! hand-written binding to `libembree3` (Debian `libembree-dev` 3.13) with just
//! what one triangle mesh and single-ray queries need. The struct layouts mirror
//! `/usr/include/embree3/rtcore_ray.h` and `rtcore_common.h` as built with
//! `RTC_MAX_INSTANCE_LEVEL_COUNT 1` and `RTC_MIN_WIDTH 0` (rtcore_config.h);
//! the tests check sizes and offsets against the values the C compiler gives.

use std::ffi::c_void;
use std::ptr;

use glam::Vec3;

use crate::consts::{PRIM_INVALID, PRIM_MISS};
use crate::error::{Error, Result};
use crate::geom::{Hit, Ray};
use crate::kdtree::build::is_non_finite;

/// `RTCRay` (48 bytes, 16-aligned).
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, Default)]
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

/// `RTCHit` (32 bytes, 16-aligned).
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, Default)]
struct RtcHit {
    ng: [f32; 3],
    u: f32,
    v: f32,
    prim_id: u32,
    geom_id: u32,
    inst_id: [u32; 1],
}

/// `RTCRayHit` (80 bytes).
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, Default)]
struct RtcRayHit {
    ray: RtcRay,
    hit: RtcHit,
}

/// `RTCIntersectContext` (24 bytes): flags, filter callback, instance stack.
#[repr(C)]
struct RtcIntersectContext {
    flags: u32,
    filter: Option<unsafe extern "C" fn(*const c_void)>,
    inst_id: [u32; 1],
}

impl RtcIntersectContext {
    /// What the header's inline `rtcInitIntersectContext` does.
    fn new() -> Self {
        RtcIntersectContext {
            flags: RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT,
            filter: None,
            inst_id: [RTC_INVALID_GEOMETRY_ID],
        }
    }
}

type RtcDevice = *mut c_void;
type RtcScene = *mut c_void;
type RtcGeometry = *mut c_void;

const RTC_INVALID_GEOMETRY_ID: u32 = u32::MAX;
const RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT: u32 = 0;
const RTC_GEOMETRY_TYPE_TRIANGLE: u32 = 0;
const RTC_BUFFER_TYPE_INDEX: u32 = 0;
const RTC_BUFFER_TYPE_VERTEX: u32 = 1;
const RTC_FORMAT_UINT3: u32 = 0x5003;
const RTC_FORMAT_FLOAT3: u32 = 0x9003;
const RTC_SCENE_FLAG_ROBUST: u32 = 1 << 2;
const RTC_BUILD_QUALITY_HIGH: u32 = 2;

#[link(name = "embree3")]
extern "C" {
    fn rtcNewDevice(config: *const std::ffi::c_char) -> RtcDevice;
    fn rtcReleaseDevice(device: RtcDevice);
    fn rtcGetDeviceError(device: RtcDevice) -> u32;
    fn rtcNewScene(device: RtcDevice) -> RtcScene;
    fn rtcReleaseScene(scene: RtcScene);
    fn rtcSetSceneFlags(scene: RtcScene, flags: u32);
    fn rtcSetSceneBuildQuality(scene: RtcScene, quality: u32);
    fn rtcNewGeometry(device: RtcDevice, kind: u32) -> RtcGeometry;
    fn rtcReleaseGeometry(geometry: RtcGeometry);
    fn rtcSetNewGeometryBuffer(
        geometry: RtcGeometry,
        kind: u32,
        slot: u32,
        format: u32,
        byte_stride: usize,
        item_count: usize,
    ) -> *mut c_void;
    fn rtcCommitGeometry(geometry: RtcGeometry);
    fn rtcAttachGeometry(scene: RtcScene, geometry: RtcGeometry) -> u32;
    fn rtcCommitScene(scene: RtcScene);
    fn rtcIntersect1(scene: RtcScene, context: *mut RtcIntersectContext, rayhit: *mut RtcRayHit);
    fn rtcOccluded1(scene: RtcScene, context: *mut RtcIntersectContext, ray: *mut RtcRay);
}

/// One triangle mesh in an Embree device and scene, committed and ready for
/// queries from any number of threads.
pub struct EmbreeScene {
    device: RtcDevice,
    scene: RtcScene,
    triangle_count: usize,
}

// SAFETY: Embree allows queries on a committed scene from several threads at once
// (rtcIntersect1/rtcOccluded1 only read it); it is released once, in `drop`.
unsafe impl Send for EmbreeScene {}
// SAFETY: as above: `&EmbreeScene` only runs read-only queries.
unsafe impl Sync for EmbreeScene {}

impl EmbreeScene {
    /// Builds Embree's BVH over `triangles` (geometry and primitive ids follow
    /// the triangle index). `robust`: `RTC_SCENE_FLAG_ROBUST`, Embree's
    /// watertight mode (slower). Triangles with non-finite vertices become
    /// degenerate ones, which Embree never reports.
    pub fn new(triangles: &[[Vec3; 3]], robust: bool) -> Result<EmbreeScene> {
        let fail = |what: &str, code: u32| Error::InvalidInput(format!("Embree: {what} failed (RTCError {code})"));
        // SAFETY: plain C calls; every pointer returned is checked before use, the
        // buffers are written within the item counts they were made with, and the
        // geometry is released after the scene took its reference.
        unsafe {
            let device = rtcNewDevice(ptr::null());
            if device.is_null() {
                return Err(fail("rtcNewDevice", rtcGetDeviceError(ptr::null_mut())));
            }
            let scene = rtcNewScene(device);
            let this = EmbreeScene { device, scene, triangle_count: triangles.len() };
            if scene.is_null() {
                return Err(fail("rtcNewScene", rtcGetDeviceError(device)));
            }
            if robust {
                rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
            }
            rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
            let geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
            if geometry.is_null() {
                return Err(fail("rtcNewGeometry", rtcGetDeviceError(device)));
            }
            let n = triangles.len();
            let vertices =
                rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, 3 * n) as *mut f32;
            let indices =
                rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, n) as *mut u32;
            if vertices.is_null() || indices.is_null() {
                rtcReleaseGeometry(geometry);
                return Err(fail("rtcSetNewGeometryBuffer", rtcGetDeviceError(device)));
            }
            let vertices = std::slice::from_raw_parts_mut(vertices, 9 * n);
            let indices = std::slice::from_raw_parts_mut(indices, 3 * n);
            for (i, tri) in triangles.iter().enumerate() {
                let tri = if is_non_finite(tri) { [Vec3::ZERO; 3] } else { *tri };
                for (k, v) in tri.iter().enumerate() {
                    vertices[9 * i + 3 * k..9 * i + 3 * k + 3].copy_from_slice(&v.to_array());
                    indices[3 * i + k] = (3 * i + k) as u32;
                }
            }
            rtcCommitGeometry(geometry);
            rtcAttachGeometry(scene, geometry);
            rtcReleaseGeometry(geometry);
            rtcCommitScene(scene);
            match rtcGetDeviceError(device) {
                0 => Ok(this),
                code => Err(fail("building the scene", code)),
            }
        }
    }

    fn embree_ray(ray: &Ray) -> RtcRay {
        RtcRay {
            org: ray.origin,
            tnear: ray.tmin.max(0.0),
            dir: ray.traced_dir().to_array(),
            tfar: ray.tmax,
            mask: u32::MAX,
            ..RtcRay::default()
        }
    }

    /// The closest hit of `ray` (`rtcIntersect1`), as a kdtrace [`Hit`].
    pub fn intersect(&self, ray: &Ray) -> Hit {
        if !ray.is_valid() {
            return Hit { t: f32::NAN, prim_id: PRIM_INVALID, u: 0.0, v: 0.0 };
        }
        let mut rayhit = RtcRayHit {
            ray: Self::embree_ray(ray),
            hit: RtcHit { geom_id: RTC_INVALID_GEOMETRY_ID, ..RtcHit::default() },
        };
        let mut context = RtcIntersectContext::new();
        // SAFETY: a committed scene; both structs are valid for the call.
        unsafe { rtcIntersect1(self.scene, &mut context, &mut rayhit) };
        if rayhit.hit.geom_id == RTC_INVALID_GEOMETRY_ID {
            return Hit::MISS;
        }
        Hit { t: rayhit.ray.tfar, prim_id: rayhit.hit.prim_id, u: rayhit.hit.u, v: rayhit.hit.v }
    }

    /// True when something occludes `ray` in `[tmin, tmax]` (`rtcOccluded1`).
    pub fn occluded(&self, ray: &Ray) -> bool {
        if !ray.is_valid() {
            return false;
        }
        let mut r = Self::embree_ray(ray);
        let mut context = RtcIntersectContext::new();
        // SAFETY: a committed scene; both structs are valid for the call.
        unsafe { rtcOccluded1(self.scene, &mut context, &mut r) };
        r.tfar == f32::NEG_INFINITY
    }

    /// An any-hit answer to judge against the exact reference: the closest hit
    /// when `rtcOccluded1` says occluded (a real occluder to check), a miss when
    /// it says free, and an out-of-range triangle (a false hit) when the two
    /// queries disagree on an occluded ray.
    pub fn any_hit_answer(&self, ray: &Ray) -> Hit {
        if !ray.is_valid() {
            return Hit { t: f32::NAN, prim_id: PRIM_INVALID, u: 0.0, v: 0.0 };
        }
        if !self.occluded(ray) {
            return Hit::MISS;
        }
        match self.intersect(ray) {
            hit if hit.prim_id != PRIM_MISS => hit,
            _ => Hit { t: ray.tmin, prim_id: self.triangle_count as u32, u: 0.0, v: 0.0 },
        }
    }
}

impl Drop for EmbreeScene {
    fn drop(&mut self) {
        // SAFETY: created in `new`, released once; null handles are skipped.
        unsafe {
            if !self.scene.is_null() {
                rtcReleaseScene(self.scene);
            }
            rtcReleaseDevice(self.device);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{align_of, offset_of, size_of};

    #[test]
    fn layouts_match_the_c_headers() {
        // Values printed by gcc for embree3/rtcore.h 3.13.5.
        assert_eq!((size_of::<RtcRay>(), align_of::<RtcRay>()), (48, 16));
        assert_eq!(offset_of!(RtcRay, tfar), 32);
        assert_eq!((size_of::<RtcHit>(), offset_of!(RtcHit, prim_id)), (32, 20));
        assert_eq!((size_of::<RtcRayHit>(), offset_of!(RtcRayHit, hit)), (80, 48));
        assert_eq!(size_of::<RtcIntersectContext>(), 24);
        assert_eq!((offset_of!(RtcIntersectContext, filter), offset_of!(RtcIntersectContext, inst_id)), (8, 16));
    }

    #[test]
    fn hits_and_occlusion_of_one_triangle() {
        let tris = vec![[Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)]];
        for robust in [false, true] {
            let scene = EmbreeScene::new(&tris, robust).expect("an Embree scene");
            let down = Ray::new(Vec3::new(0.25, 0.25, 2.0), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY);
            let hit = scene.intersect(&down);
            assert_eq!(hit.prim_id, 0);
            assert!((hit.t - 2.0).abs() < 1e-6 && (hit.u - 0.25).abs() < 1e-6 && (hit.v - 0.25).abs() < 1e-6);
            assert!(scene.occluded(&down));
            let short = Ray { tmax: 1.0, ..down };
            assert!(!scene.occluded(&short));
            assert_eq!(scene.intersect(&short), Hit::MISS);
            let beside = Ray::new(Vec3::new(2.0, 2.0, 2.0), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY);
            assert_eq!(scene.any_hit_answer(&beside), Hit::MISS);
        }
    }
}
