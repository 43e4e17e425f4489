//! Descriptor binding numbers and workgroup sizes, shared by the host's descriptor layouts and the
//! kernels' entry points.
//!
//! All stages use descriptor set 0 and one storage buffer per stream field. SPIR-V entry-point
//! attributes need literal numbers, so the kernels repeat these values in their
//! `#[spirv(binding = N)]` attributes; the Vulkan validation layers (on in every test) reject a
//! pipeline whose layout disagrees with its shader, and the parity tests catch two swapped buffers.

/// Threads per workgroup every 1-D compute stage is compiled with (`threads(64)` in the kernels'
/// entry points). 64 fills a wave on AMD and two warps on NVIDIA. The host may run the stream
/// stages with another power of two (`ContextOptions::workgroup_sizes`); the bilateral denoise
/// pass, whose workgroup-memory tile is sized by it ([`crate::denoise::TILE_LEN`]), always runs
/// with this one.
pub const WORKGROUP_SIZE: u32 = 64;

/// Invocations per row of a stream stage's dispatch grid when the stream needs more than one
/// row: 2^20, a multiple of every power-of-two workgroup size up to 1024 whose rows of
/// `STREAM_ROW / size` workgroups stay within the 65 535 every Vulkan device allows in x for
/// sizes from 32 up. Kernels index streams as `y · STREAM_ROW + x` ([`stream_index`]).
pub const STREAM_ROW: u32 = 1 << 20;

/// The stream index of an invocation in a 2-D grid of 1-D workgroups: row `y` starts at
/// `y · STREAM_ROW`. The host spreads a stream over more than one row only when it needs more
/// workgroups than `maxComputeWorkGroupCount[0]` (at least 65 535), and then sends rows of exactly
/// [`STREAM_ROW`] invocations, so the index does not depend on the workgroup size the host picked
/// ([`WORKGROUP_SIZE`] or another). Every stream stage's entry point starts from it.
pub fn stream_index(global_id: glam::UVec3) -> u32 {
    global_id.y * STREAM_ROW + global_id.x
}

/// Bindings of the generate stage (set 0).
pub mod generate {
    /// Output: ray origins (`Vec4`, w = tmin).
    pub const RAY_ORIGIN: u32 = 0;
    /// Output: ray directions (`Vec4`, w = tmax).
    pub const RAY_DIRECTION: u32 = 1;
    /// Output: pixel index of each ray (`u32`).
    pub const RAY_PIXEL: u32 = 2;
}

/// Bindings of the occlusion variant of the trace stage (set 0): the scene and ray bindings of
/// [`trace`], and one `u32` per ray (1 = blocked) in place of the hit stream.
pub mod occlusion {
    /// Output: 1 where the ray is blocked within its interval, 0 where it is not (`u32`).
    pub const OCCLUDED: u32 = 3;
}

/// Bindings of the trace stage (set 0). Binding 0 holds the scene: the TLAS for ray query, the
/// CWBVH nodes for software traversal; the streams are the same for every trace backend.
pub mod trace {
    /// Input, ray query: the top-level acceleration structure.
    pub const TLAS: u32 = 0;
    /// Input, software traversal: CWBVH nodes (`CwBvhNode`).
    pub const NODES: u32 = 0;
    /// Input: ray origins (`Vec4`, w = tmin).
    pub const RAY_ORIGIN: u32 = 1;
    /// Input: ray directions (`Vec4`, w = tmax).
    pub const RAY_DIRECTION: u32 = 2;
    /// Output: hit distance (`f32`).
    pub const HIT_T: u32 = 3;
    /// Output: primitive index within the instance's mesh (`u32`).
    pub const HIT_PRIMITIVE: u32 = 4;
    /// Output: instance index (`u32`).
    pub const HIT_INSTANCE: u32 = 5;
    /// Output: barycentrics of vertices 1 and 2 (`Vec2`).
    pub const HIT_BARYCENTRICS: u32 = 6;
    /// Input, software traversal: triangle vertices in BVH order (`Vec4`, three per triangle).
    pub const TRIANGLE_VERTICES: u32 = 7;
    /// Input, software traversal: (instance, primitive) per triangle in BVH order (`UVec2`).
    pub const TRIANGLE_IDS: u32 = 8;
    /// Output, closest-hit and occlusion traces: the count of rays or hits the stage replaced
    /// because they were not finite (one `u32`, zeroed by the host, atomically incremented;
    /// DESIGN rule 5).
    pub const REPLACED: u32 = 9;
}

/// Bindings of the sampling probes (set 0), which expose the sampler and the warps as streams for
/// the CPU–SPIR-V parity tests.
pub mod probe {
    /// Output: the sampler probe's raw bits (`UVec2`) or the warp probe's samples (`Vec4`, xyz
    /// direction, w pdf).
    pub const SAMPLES: u32 = 0;
}

/// Bindings of the shade stage (set 0), in order: inputs, then outputs.
pub mod shade {
    /// Input: camera-ray directions (`Vec4`).
    pub const RAY_DIRECTION: u32 = 0;
    /// Input: hit distance (`f32`).
    pub const HIT_T: u32 = 1;
    /// Input: hit primitive (`u32`).
    pub const HIT_PRIMITIVE: u32 = 2;
    /// Input: hit instance (`u32`).
    pub const HIT_INSTANCE: u32 = 3;
    /// Input: hit barycentrics (`Vec2`).
    pub const HIT_BARYCENTRICS: u32 = 4;
    /// Input: triangle vertices by (instance, primitive), three `Vec4` per triangle.
    pub const TRIANGLES: u32 = 5;
    /// Input: first triangle of each instance (`u32`).
    pub const FIRST_TRIANGLE: u32 = 6;
    /// Input: material per instance (`MaterialParams`).
    pub const MATERIALS: u32 = 7;
    /// Input: quad lights (`Light`).
    pub const LIGHTS: u32 = 8;
    /// Input: light BVH nodes (`LightBvhNode`).
    pub const LIGHT_NODES: u32 = 9;
    /// Input: light trails in the BVH (`u32`).
    pub const LIGHT_TRAILS: u32 = 10;
    /// Input: the packed LTC table (`Vec4`).
    pub const LTC: u32 = 11;
    /// Output: analytic unshadowed radiance `U` (`Vec4`).
    pub const ANALYTIC: u32 = 12;
    /// Output: this sample's `U_N` contribution (`Vec4`).
    pub const UNSHADOWED: u32 = 13;
    /// Output: emitted radiance (`Vec4`).
    pub const EMITTED: u32 = 14;
    /// Output: shadow-ray origins (`Vec4`, w = tmin).
    pub const SHADOW_ORIGIN: u32 = 15;
    /// Output: shadow-ray directions (`Vec4`, w = tmax; 0 = no ray).
    pub const SHADOW_DIRECTION: u32 = 16;
    /// Output: the count of samples in which the stage replaced a non-finite value (one `u32`, as
    /// [`super::trace::REPLACED`]).
    pub const REPLACED: u32 = 17;
    /// Specialization constant (`u32`, default 1): 0 compiles the stage without the residual
    /// towards GGX (`ShadeParams::analytic_residual` then reads as 0), 1 with it. The residual's
    /// slope-space quadrature and thin-strip lines are two fifths of the kernel's code; a pipeline
    /// specialized to 0 leaves them to the driver's dead-code elimination, so passes without the
    /// residual do not compile them (the README's Shading section measures lavapipe's compile
    /// time) and may need fewer registers. A pipeline built with 0 ignores the flag: an engine
    /// that sets it for some passes needs a pipeline of each.
    pub const RESIDUAL_CODE_SPEC_ID: u32 = 0;
}

/// The most storage buffers one pass binds — the shade stage's, [`shade::REPLACED`] + 1 — which a
/// device's `maxPerStageDescriptorStorageBuffers`, `maxDescriptorSetStorageBuffers` and
/// `maxPerStageResources` must allow (Vulkan guarantees only 4, 24 and 128).
pub const MOST_STORAGE_BUFFERS: u32 = shade::REPLACED + 1;

/// Bindings of the denoise passes (set 0): every pass binds storage buffers `0..n` in the order
/// its entry point (`raywave_kernels::entry::denoise_*`, `svgf_*`) lists; these are the counts.
/// The two composites, the denoisers' last passes, end with the count of colours they replaced
/// because they were not finite (one `u32`, as [`trace::REPLACED`]).
pub mod denoise {
    /// `denoise_ratio`: `S_N`, `U_N` in; ratio (`Vec4`) out.
    pub const RATIO: u32 = 3;
    /// `denoise_noise`: ratio in; raw noise (`f32`) out.
    pub const NOISE: u32 = 2;
    /// `denoise_noise_blur`: raw noise in; blurred noise out.
    pub const NOISE_BLUR: u32 = 2;
    /// `denoise_bilateral`: position, normal, noise, `S_N`, `U_N` in; filtered `S_N`, `U_N` out.
    pub const BILATERAL: u32 = 7;
    /// `denoise_composite`: `U`, emitted, `S_N`, `U_N` in; colour and replaced count out.
    pub const COMPOSITE: u32 = 6;
    /// `svgf_variance`: ratio, position, normal in; ratio and variance out.
    pub const SVGF_VARIANCE: u32 = 4;
    /// `svgf_atrous`: ratio and variance, position, normal in; filtered ratio and variance out.
    pub const SVGF_ATROUS: u32 = 4;
    /// `svgf_composite`: `U`, emitted, ratio in; colour and replaced count out.
    pub const SVGF_COMPOSITE: u32 = 5;
    /// `copy_probe` (the bandwidth roof, not a pass of any denoiser): an image in; its copy out.
    pub const COPY_PROBE: u32 = 2;
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::UVec3;

    #[test]
    fn stream_index_is_row_major_over_rows_of_stream_row_invocations() {
        assert_eq!(stream_index(UVec3::new(5, 0, 0)), 5);
        // A single-row dispatch may run past `STREAM_ROW` in x.
        assert_eq!(stream_index(UVec3::new(STREAM_ROW + 3, 0, 0)), STREAM_ROW + 3);
        assert_eq!(stream_index(UVec3::new(0, 1, 0)), STREAM_ROW);
        assert_eq!(stream_index(UVec3::new(7, 2, 0)), 2 * STREAM_ROW + 7);
    }
}
