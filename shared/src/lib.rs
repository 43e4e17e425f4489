//! The contract between the raywave host and its kernels.
//!
//! Everything that crosses the host/GPU boundary is defined here exactly once: push-constant
//! parameter blocks (`#[repr(C)]`, [`bytemuck::Pod`], with compile-time size and alignment checks),
//! the element types of the SoA streams, and the descriptor binding numbers. The kernels use these
//! types unchanged on the CPU and in SPIR-V; the host uses them to fill buffers.
#![no_std]

// The structs here share the std430 layout of the kernels' buffers and push constants, which
// needs glam's 16-byte-aligned `Vec4` (its SIMD and SPIR-V layout; each struct's own size and
// alignment checks are in its module). glam's `scalar-math` feature, if any crate in a build
// enables it, aligns `Vec4` to 4 bytes: refused first, here, with a message that names it,
// which the structs' own checks, failing after it, do not.
const _: () = assert!(
    core::mem::align_of::<glam::Vec4>() == 16,
    "raywave needs glam's 16-byte-aligned Vec4 for the layout it shares with its shaders; \
     glam's `scalar-math` feature (enabled by some crate in this build) is not supported"
);

pub mod bindings;
pub mod bvh;
pub mod denoise;
pub mod generate;
pub mod light;
pub mod ltc_table;
pub mod sampling;
pub mod shade;
pub mod stream;
pub mod trace;

pub use denoise::DenoiseParams;
pub use generate::GenerateParams;
pub use light::Light;
pub use light::{LightBounds, LightBvhNode};
pub use sampling::{SamplerParams, SamplerProbeParams, WarpParams};
pub use shade::{MaterialParams, ShadeParams};
pub use trace::TraceParams;
