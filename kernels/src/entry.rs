//! The SPIR-V entry points — `#[spirv(compute)]` kernels and the ray-tracing pipeline's
//! ray-generation, miss and closest-hit shaders: thin wrappers that turn an invocation id into a
//! stream index, call the stage function and store its result. Binding numbers repeat
//! [`raywave_shared::bindings`] (attributes need literals); `threads(64)` is
//! [`raywave_shared::bindings::WORKGROUP_SIZE`].
//!
//! Every entry point declares `SignedZeroInfNanPreserve` for 32-bit floats: without it Vulkan lets
//! a driver assume that no float operand or result is NaN or ±Inf (Vulkan specification,
//! "Precision and Operation of SPIR-V Instructions") and so fold the kernels' `is_finite` and
//! `!(x > 0.0)` guards, and with them DESIGN rule 5 — no NaN or Inf leaves a stage, and what was
//! replaced is counted — which the CPU's IEEE arithmetic keeps. It needs the device property
//! `shaderSignedZeroInfNanPreserveFloat32`, which raywave's Vulkan backend requires.

use glam::{UVec3, Vec4};
use raywave_shared::bindings::{stream_index, WORKGROUP_SIZE};
use raywave_shared::GenerateParams;
use spirv_std::spirv;

/// The value of an invocation's result, counting the invocation in its stage's counter if it
/// replaced a non-finite value (DESIGN rule 5, [`crate::sanitized`]): element 0 of a one-`u32`
/// storage buffer the host zeroes and reads back.
fn counted<T>(result: crate::sanitized::Sanitized<T>, counter: &mut [u32]) -> T {
    use spirv_std::memory::{Scope, Semantics};
    if !result.replaced {
        return result.value;
    }
    // SAFETY: an atomic increment of a storage-buffer `u32` the host bound for this purpose;
    // relaxed (no ordering needed: the host reads it after the dispatch completes). Queue-family
    // scope covers every invocation of the dispatch; device scope would need the
    // `VulkanMemoryModelDeviceScope` capability under the Vulkan memory model rust-gpu emits.
    unsafe {
        spirv_std::arch::atomic_i_increment::<u32, { Scope::QueueFamily as u32 }, { Semantics::NONE.bits() }>(
            &mut counter[0],
        );
    }
    result.value
}

/// Writes `hit` into the four hit-stream fields at index `i`.
fn store_hit(
    i: usize,
    hit: crate::trace::Hit,
    hit_t: &mut [f32],
    hit_primitive: &mut [u32],
    hit_instance: &mut [u32],
    hit_barycentrics: &mut [glam::Vec2],
) {
    hit_t[i] = hit.t;
    hit_primitive[i] = hit.primitive;
    hit_instance[i] = hit.instance;
    hit_barycentrics[i] = hit.barycentrics;
}

/// Entry point of the generate stage.
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
pub fn generate(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &GenerateParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] ray_origin: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] ray_direction: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] ray_pixel: &mut [u32],
) {
    let i = stream_index(global_id);
    if i < params.ray_count() {
        let ray = crate::generate::generate_ray(i, params);
        ray_origin[i as usize] = ray.origin;
        ray_direction[i as usize] = ray.direction;
        ray_pixel[i as usize] = ray.pixel;
    }
}

/// Entry point of the sampler probe: raw sampler bits, compared bit-exact with the CPU.
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
pub fn sampler_probe(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::SamplerProbeParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] bits: &mut [glam::UVec2],
) {
    let i = stream_index(global_id);
    if i < params.sample_count() {
        bits[i as usize] = crate::sampling::probe::sampler_probe(i, params);
    }
}

/// Entry point of the warp probe: warped directions and their pdfs.
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
pub fn warp_probe(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::WarpParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] samples: &mut [Vec4],
) {
    let i = stream_index(global_id);
    if i < params.count {
        samples[i as usize] = crate::sampling::probe::warp_probe(i, params);
    }
}

/// Entry point of the trace stage with software CWBVH traversal: needs no ray-tracing extension.
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
#[allow(clippy::too_many_arguments)]
pub fn trace_cwbvh(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::TraceParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] nodes: &[raywave_shared::bvh::CwBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] ray_origin: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] ray_direction: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] hit_t: &mut [f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] hit_primitive: &mut [u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] hit_instance: &mut [u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] hit_barycentrics: &mut [glam::Vec2],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 7)] vertices: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] ids: &[glam::UVec2],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 9)] replaced: &mut [u32],
) {
    let i = stream_index(global_id) as usize;
    if i < params.ray_count as usize {
        let scene = crate::trace::cwbvh::CwBvhScene { nodes, vertices, ids };
        let hit = crate::trace::trace_closest(ray_origin[i], ray_direction[i], &scene);
        store_hit(i, counted(hit, replaced), hit_t, hit_primitive, hit_instance, hit_barycentrics);
    }
}

/// Entry point of the trace stage with `VK_KHR_ray_query`; only in the SPIR-V build with the
/// `ray-query` feature (and the `RayQueryKHR` capability), so other modules never declare it.
#[cfg(all(target_arch = "spirv", feature = "ray-query"))]
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
#[allow(clippy::too_many_arguments)]
pub fn trace_ray_query(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::TraceParams,
    #[spirv(descriptor_set = 0, binding = 0)] tlas: &spirv_std::ray_tracing::AccelerationStructure,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] ray_origin: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] ray_direction: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] hit_t: &mut [f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] hit_primitive: &mut [u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] hit_instance: &mut [u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] hit_barycentrics: &mut [glam::Vec2],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 9)] replaced: &mut [u32],
) {
    let i = stream_index(global_id) as usize;
    if i < params.ray_count as usize {
        let scene = crate::trace::ray_query::RayQueryScene { tlas };
        let hit = crate::trace::trace_closest(ray_origin[i], ray_direction[i], &scene);
        store_hit(i, counted(hit, replaced), hit_t, hit_primitive, hit_instance, hit_barycentrics);
    }
}

/// Ray generation shader of the trace stage for `VK_KHR_ray_tracing_pipeline` (GPUs without ray
/// query): one launch per ray over a 2-D launch grid, the same stream bindings as
/// `trace_ray_query`, the closest hit found by the fixed-function traversal.
#[cfg(all(target_arch = "spirv", feature = "ray-tracing"))]
#[spirv(ray_generation(signed_zero_inf_nan_preserve = 32))]
#[allow(clippy::too_many_arguments)]
pub fn trace_raygen(
    #[spirv(launch_id)] launch_id: UVec3,
    #[spirv(launch_size)] launch_size: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::TraceParams,
    #[spirv(descriptor_set = 0, binding = 0)] tlas: &spirv_std::ray_tracing::AccelerationStructure,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] ray_origin: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] ray_direction: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] hit_t: &mut [f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] hit_primitive: &mut [u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] hit_instance: &mut [u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] hit_barycentrics: &mut [glam::Vec2],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 9)] replaced: &mut [u32],
    #[spirv(ray_payload)] payload: &mut crate::trace::Hit,
) {
    use crate::trace::{trace_closest_with, Hit};
    let i = (launch_id.y * launch_size.x + launch_id.x) as usize;
    if i < params.ray_count as usize {
        let hit = trace_closest_with(ray_origin[i], ray_direction[i], move |ray| {
            *payload = Hit::MISS;
            // SAFETY: `tlas` is a valid acceleration structure bound by the host, the ray is
            // traceable (`trace_closest_with` calls this only then), and `payload` lives in the
            // ray-payload storage class.
            unsafe {
                tlas.trace_ray(
                    spirv_std::ray_tracing::RayFlags::OPAQUE,
                    0xff,
                    0,
                    0,
                    0,
                    ray.origin,
                    ray.tmin,
                    ray.direction,
                    ray.tmax,
                    payload,
                );
            }
            *payload
        });
        store_hit(i, counted(hit, replaced), hit_t, hit_primitive, hit_instance, hit_barycentrics);
    }
}

/// Miss shader of the ray-tracing-pipeline trace: the ray hit nothing.
#[cfg(all(target_arch = "spirv", feature = "ray-tracing"))]
#[spirv(miss(signed_zero_inf_nan_preserve = 32))]
pub fn trace_miss(#[spirv(incoming_ray_payload)] payload: &mut crate::trace::Hit) {
    *payload = crate::trace::Hit::MISS;
}

/// Closest-hit shader of the ray-tracing-pipeline trace: records t, ids and barycentrics.
#[cfg(all(target_arch = "spirv", feature = "ray-tracing"))]
#[spirv(closest_hit(signed_zero_inf_nan_preserve = 32))]
pub fn trace_closest_hit(
    #[spirv(incoming_ray_payload)] payload: &mut crate::trace::Hit,
    #[spirv(hit_attribute)] barycentrics: &mut glam::Vec2,
    #[spirv(ray_tmax)] t: f32,
    #[spirv(primitive_id)] primitive: u32,
    #[spirv(instance_id)] instance: u32,
) {
    *payload = crate::trace::Hit { t, primitive, instance, barycentrics: *barycentrics };
}

/// Entry point of the occlusion (any-hit) trace with software CWBVH traversal: 1 per blocked ray.
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
#[allow(clippy::too_many_arguments)]
pub fn occlusion_cwbvh(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::TraceParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] nodes: &[raywave_shared::bvh::CwBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] ray_origin: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] ray_direction: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] occluded: &mut [u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 7)] vertices: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] ids: &[glam::UVec2],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 9)] replaced: &mut [u32],
) {
    let i = stream_index(global_id) as usize;
    if i < params.ray_count as usize {
        let scene = crate::trace::cwbvh::CwBvhScene { nodes, vertices, ids };
        let blocked = crate::trace::trace_occluded(ray_origin[i], ray_direction[i], &scene);
        occluded[i] = u32::from(counted(blocked, replaced));
    }
}

/// Entry point of the occlusion (any-hit) trace with `VK_KHR_ray_query`.
#[cfg(all(target_arch = "spirv", feature = "ray-query"))]
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
pub fn occlusion_ray_query(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::TraceParams,
    #[spirv(descriptor_set = 0, binding = 0)] tlas: &spirv_std::ray_tracing::AccelerationStructure,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] ray_origin: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] ray_direction: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] occluded: &mut [u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 9)] replaced: &mut [u32],
) {
    let i = stream_index(global_id) as usize;
    if i < params.ray_count as usize {
        let scene = crate::trace::ray_query::RayQueryScene { tlas };
        let blocked = crate::trace::trace_occluded(ray_origin[i], ray_direction[i], &scene);
        occluded[i] = u32::from(counted(blocked, replaced));
    }
}

/// Ray generation shader of the occlusion trace for `VK_KHR_ray_tracing_pipeline`: the payload
/// starts at 1 (blocked), the traversal stops at the first hit without a closest-hit shader, and
/// [`occlusion_miss`] clears it.
#[cfg(all(target_arch = "spirv", feature = "ray-tracing"))]
#[spirv(ray_generation(signed_zero_inf_nan_preserve = 32))]
#[allow(clippy::too_many_arguments)]
pub fn occlusion_raygen(
    #[spirv(launch_id)] launch_id: UVec3,
    #[spirv(launch_size)] launch_size: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::TraceParams,
    #[spirv(descriptor_set = 0, binding = 0)] tlas: &spirv_std::ray_tracing::AccelerationStructure,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] ray_origin: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] ray_direction: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] occluded: &mut [u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 9)] replaced: &mut [u32],
    #[spirv(ray_payload)] payload: &mut u32,
) {
    use spirv_std::ray_tracing::RayFlags;
    let i = (launch_id.y * launch_size.x + launch_id.x) as usize;
    if i < params.ray_count as usize {
        let blocked = crate::trace::trace_occluded_with(ray_origin[i], ray_direction[i], move |ray| {
            // Blocked unless the miss shader clears it.
            *payload = 1;
            let flags = RayFlags::OPAQUE | RayFlags::TERMINATE_ON_FIRST_HIT | RayFlags::SKIP_CLOSEST_HIT_SHADER;
            // SAFETY: as in `trace_raygen`.
            unsafe {
                tlas.trace_ray(flags, 0xff, 0, 0, 0, ray.origin, ray.tmin, ray.direction, ray.tmax, payload);
            }
            *payload != 0
        });
        occluded[i] = u32::from(counted(blocked, replaced));
    }
}

/// Miss shader of the occlusion trace: the ray reached its end unblocked.
#[cfg(all(target_arch = "spirv", feature = "ray-tracing"))]
#[spirv(miss(signed_zero_inf_nan_preserve = 32))]
pub fn occlusion_miss(#[spirv(incoming_ray_payload)] payload: &mut u32) {
    *payload = 0;
}

/// Entry point of the shade stage: resolves each camera ray's hit into a surface and shades one
/// sample of it (see `crate::shade::stage`). Bindings: the ray directions, the hit stream, the
/// scene's triangles and materials, the lights and their BVH, the LTC table, then the outputs.
/// Specialization constant 0 ([`raywave_shared::bindings::shade::RESIDUAL_CODE_SPEC_ID`]): 0
/// builds the stage without the residual towards GGX.
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
#[allow(clippy::too_many_arguments)]
pub fn shade(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::ShadeParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] ray_direction: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] hit_t: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] hit_primitive: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] hit_instance: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] hit_barycentrics: &[glam::Vec2],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] triangles: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] first_triangle: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 7)] materials: &[raywave_shared::MaterialParams],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 8)] lights: &[raywave_shared::Light],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 9)] light_nodes: &[raywave_shared::LightBvhNode],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 10)] light_trails: &[u32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 11)] ltc: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 12)] analytic: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 13)] unshadowed: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 14)] emitted: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 15)] shadow_origin: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 16)] shadow_direction: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 17)] replaced: &mut [u32],
    #[spirv(spec_constant(id = 0, default = 1))] residual_code: u32,
) {
    let i = stream_index(global_id);
    if i < params.count {
        // Specialized to 0 (`RESIDUAL_CODE_SPEC_ID`), the residual's flag is a constant 0 and the
        // driver drops its code.
        let residual = if residual_code != 0 { params.analytic_residual } else { 0 };
        let params = &raywave_shared::ShadeParams { analytic_residual: residual, ..*params };
        let k = i as usize;
        let direction = glam::Vec4Swizzles::xyz(ray_direction[k]);
        let surface = crate::shade::stage::resolve_surface(
            direction,
            hit_t[k],
            hit_instance[k],
            hit_primitive[k],
            hit_barycentrics[k],
            triangles,
            first_triangle,
        );
        let scene = crate::shade::stage::ShadeScene {
            materials,
            lights: crate::sampling::light_select::LightSet {
                lights,
                nodes: light_nodes,
                trails: light_trails,
                light_count: params.light_count,
                node_count: params.light_node_count,
            },
            ltc,
        };
        let width = if params.width > 0 { params.width } else { 1 };
        let pixel = glam::UVec2::new(i % width, i / width);
        let s = counted(crate::shade::stage::shade_sample(params, pixel, direction, &surface, &scene), replaced);
        analytic[k] = s.analytic;
        unshadowed[k] = s.unshadowed;
        emitted[k] = s.emitted;
        shadow_origin[k] = s.shadow_origin;
        shadow_direction[k] = s.shadow_direction;
    }
}

/// Entry point of the copy probe (one invocation per pixel): pixel `i`'s `Vec4` copied to
/// another buffer, nothing else — the least a per-pixel pass over `Vec4` images can move, and so
/// the memory roof `raywave bench denoise` measures the passes' bandwidth against.
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
pub fn copy_probe(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::DenoiseParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] source: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] copy: &mut [Vec4],
) {
    let i = stream_index(global_id);
    if params.pixel(i).is_some() {
        copy[i as usize] = source[i as usize];
    }
}

/// Entry point of the denoisers' ratio pass: `S_N/U_N` per pixel (one invocation per pixel).
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
pub fn denoise_ratio(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::DenoiseParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] shadowed: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] unshadowed: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] ratio: &mut [Vec4],
) {
    let i = stream_index(global_id);
    if params.pixel(i).is_some() {
        let k = i as usize;
        ratio[k] = crate::denoise::noise::ratio_pixel(shadowed[k], unshadowed[k]);
    }
}

/// Entry point of the denoiser's raw noise estimate (one invocation per pixel).
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
pub fn denoise_noise(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::DenoiseParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] ratio: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] noise: &mut [f32],
) {
    let i = stream_index(global_id);
    if let Some(pixel) = params.pixel(i) {
        noise[i as usize] = crate::denoise::noise::noise_estimate(params, pixel, ratio);
    }
}

/// Entry point of the noise estimate's 3×3 blur (one invocation per pixel).
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
pub fn denoise_noise_blur(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::DenoiseParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] raw: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] blurred: &mut [f32],
) {
    let i = stream_index(global_id);
    if let Some(pixel) = params.pixel(i) {
        blurred[i as usize] = crate::denoise::noise::blurred_noise(params, pixel, raw);
    }
}

/// A line segment of the bilateral pass in workgroup memory: `TILE_LEN` taps, the centre of
/// invocation `local` at `local + MAX_RADIUS`.
struct TileLine<'a> {
    shadowed: &'a [Vec4; TILE],
    unshadowed: &'a [Vec4; TILE],
    position: &'a [Vec4; TILE],
    normal: &'a [Vec4; TILE],
    center: i32,
}

/// Workgroup tile length as an array length.
const TILE: usize = raywave_shared::denoise::TILE_LEN as usize;

impl crate::denoise::bilateral::FilterLine for TileLine<'_> {
    fn tap(&self, offset: i32) -> crate::denoise::bilateral::FilterTap {
        let k = (self.center + offset) as usize;
        crate::denoise::bilateral::FilterTap {
            shadowed: self.shadowed[k],
            unshadowed: self.unshadowed[k],
            guide: crate::denoise::Guide { position: self.position[k], normal: self.normal[k] },
        }
    }
}

/// Entry point of one 1-D pass of the joint bilateral filter along `params.axis`. Each
/// workgroup filters a `WORKGROUP_SIZE`-pixel segment of one line (the host dispatches
/// [`raywave_shared::DenoiseParams::bilateral_invocations`]): it first loads the segment and
/// `MAX_RADIUS` pixels on each side into workgroup memory, one global read per pixel, then every
/// invocation filters its pixel from the tile with the CPU's `bilateral_pass`.
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
#[allow(clippy::too_many_arguments)]
pub fn denoise_bilateral(
    #[spirv(workgroup_id)] group: UVec3,
    #[spirv(num_workgroups)] num_workgroups: UVec3,
    #[spirv(local_invocation_index)] local: u32,
    #[spirv(push_constant)] params: &raywave_shared::DenoiseParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] position: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] normal: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] noise: &[f32],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] shadowed: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] unshadowed: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] shadowed_out: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 6)] unshadowed_out: &mut [Vec4],
    #[spirv(workgroup)] tile_shadowed: &mut [Vec4; TILE],
    #[spirv(workgroup)] tile_unshadowed: &mut [Vec4; TILE],
    #[spirv(workgroup)] tile_position: &mut [Vec4; TILE],
    #[spirv(workgroup)] tile_normal: &mut [Vec4; TILE],
) {
    use crate::denoise::bilateral::{FilterLine, ImageLine};
    use raywave_shared::denoise::{MAX_RADIUS, TILE_LEN};
    let segments = params.segments_per_line();
    let group_index = group.y * num_workgroups.x + group.x;
    let (line, segment) = (group_index / segments.max(1), group_index % segments.max(1));
    let (length, lines) = params.lines();
    let start = (segment * WORKGROUP_SIZE) as i32;
    let source = ImageLine {
        shadowed,
        unshadowed,
        position,
        normal,
        center: crate::denoise::bilateral::line_pixel(params, line, 0),
        params,
    };
    // Every invocation of a workgroup takes the same branch: `line` is per workgroup.
    if line < lines {
        let mut k = local;
        while k < TILE_LEN {
            let tap = source.tap(start - MAX_RADIUS as i32 + k as i32);
            let slot = k as usize;
            tile_shadowed[slot] = tap.shadowed;
            tile_unshadowed[slot] = tap.unshadowed;
            tile_position[slot] = tap.guide.position;
            tile_normal[slot] = tap.guide.normal;
            k += WORKGROUP_SIZE;
        }
    }
    spirv_std::arch::workgroup_memory_barrier_with_group_sync();
    let along = start + local as i32;
    if line < lines && (along as u32) < length {
        let tile = TileLine {
            shadowed: tile_shadowed,
            unshadowed: tile_unshadowed,
            position: tile_position,
            normal: tile_normal,
            center: (local + MAX_RADIUS) as i32,
        };
        let pixel = crate::denoise::bilateral::line_pixel(params, line, along);
        let i = (pixel.y as u32 * params.width + pixel.x as u32) as usize;
        let (s, u) = crate::denoise::bilateral::bilateral_pass(&tile, noise[i], params);
        shadowed_out[i] = s;
        unshadowed_out[i] = u;
    }
}

/// Entry point of the denoiser's composite `emitted + U · den(S_N)/den(U_N)` (one invocation per
/// pixel).
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
#[allow(clippy::too_many_arguments)]
pub fn denoise_composite(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::DenoiseParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] analytic: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] emitted: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] shadowed: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] unshadowed: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] color: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 5)] replaced: &mut [u32],
) {
    use glam::Vec4Swizzles;
    let i = stream_index(global_id);
    if params.pixel(i).is_some() {
        let k = i as usize;
        let c =
            crate::shade::stage::composite(analytic[k].xyz(), unshadowed[k].xyz(), shadowed[k].xyz(), emitted[k].xyz());
        color[k] = counted(c, replaced).extend(1.0);
    }
}

/// Entry point of the SVGF baseline's spatial variance of the ratio (one invocation per pixel).
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
pub fn svgf_variance(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::DenoiseParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] ratio: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] position: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] normal: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] with_variance: &mut [Vec4],
) {
    let i = stream_index(global_id);
    if let Some(pixel) = params.pixel(i) {
        with_variance[i as usize] = crate::denoise::svgf::ratio_and_variance(params, pixel, ratio, position, normal);
    }
}

/// Entry point of one SVGF à-trous iteration with spacing `params.step` (one invocation per
/// pixel).
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
pub fn svgf_atrous(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::DenoiseParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] ratio: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] position: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] normal: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] filtered: &mut [Vec4],
) {
    let i = stream_index(global_id);
    if let Some(pixel) = params.pixel(i) {
        filtered[i as usize] = crate::denoise::svgf::atrous_step(params, pixel, ratio, position, normal);
    }
}

/// Entry point of the SVGF baseline's composite `emitted + U · den(ratio)` (one invocation per
/// pixel).
#[spirv(compute(threads(64), signed_zero_inf_nan_preserve = 32))]
#[allow(clippy::too_many_arguments)]
pub fn svgf_composite(
    #[spirv(global_invocation_id)] global_id: UVec3,
    #[spirv(push_constant)] params: &raywave_shared::DenoiseParams,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] analytic: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 1)] emitted: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 2)] ratio: &[Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 3)] color: &mut [Vec4],
    #[spirv(storage_buffer, descriptor_set = 0, binding = 4)] replaced: &mut [u32],
) {
    use glam::Vec4Swizzles;
    let i = stream_index(global_id);
    if params.pixel(i).is_some() {
        let k = i as usize;
        let c = crate::shade::stage::apply_visibility(analytic[k].xyz(), ratio[k].xyz(), emitted[k].xyz());
        color[k] = counted(c, replaced).extend(1.0);
    }
}
