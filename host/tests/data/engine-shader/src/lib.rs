//! An engine's compute shader that uses a raywave kernel function (the fixture of
//! `host/tests/engine_shader.rs`).
#![no_std]

use glam::UVec3;
use spirv_std::spirv;

/// The engine's one entry point: the sine of each invocation's index, by raywave's `sin_cos`.
#[spirv(compute(threads(64)))]
pub fn engine_main(
    #[spirv(global_invocation_id)] id: UVec3,
    #[spirv(storage_buffer, descriptor_set = 0, binding = 0)] out: &mut [f32],
) {
    out[id.x as usize] = raywave_kernels::trig::sin_cos(id.x as f32).0;
}
