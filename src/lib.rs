//! raywave: data-oriented wavefront ray-tracing kernels that run the same math on the CPU and on
//! Vulkan devices (SPIR-V built with rust-gpu).
//!
//! This facade re-exports the three layers — [`shared`] (the host/kernel contract), [`kernels`]
//! (the stages as plain `no_std` functions) and the host (scenes, CPU executor, Vulkan backend) —
//! and adds [`render`], the whole-frame job behind `raywave render`, [`bench`](mod@bench),
//! [`bench_shade`] and [`bench_denoise`], the benchmarks behind `raywave bench trace|shade|denoise`,
//! and [`report`], the accuracy reports behind `raywave report`.

pub mod bench;
pub mod bench_denoise;
pub mod bench_device;
pub mod bench_shade;
#[cfg(feature = "embree")]
pub mod embree;
pub mod output_line;
pub mod render;
pub mod report;

// The host re-exports `shared`, `kernels` and `glam` too.
pub use raywave_host::*;
