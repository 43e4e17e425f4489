//! The contract between the raywave host and its kernels.
//!
//! Everything that crosses the host/GPU boundary is defined here exactly once: push-constant
//! parameter blocks (`#[repr(C)]`, [`bytemuck::Pod`], with compile-time size and alignment checks),
//! the element types of the SoA streams, and the descriptor binding numbers. The kernels use these
//! types unchanged on the CPU and in SPIR-V; the host uses them to fill buffers.
#![no_std]

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
