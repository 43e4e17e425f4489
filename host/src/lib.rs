//! raywave's host: scenes, the CPU executor, the Vulkan backend and what runs a frame.
//!
//! Nothing here re-implements kernel math: the CPU backend calls `raywave-kernels` directly and
//! the Vulkan backend runs the same functions compiled to SPIR-V.

pub mod backend;
pub mod cpu;
pub mod denoise;
pub mod device;
pub mod error;
pub mod frame;
pub mod lights;
pub mod lit_frame;
pub mod lit_sample;
pub mod ltc_fit;
pub mod memory;
pub mod scene;
pub mod shading;
pub mod stats;
pub mod stream;
pub mod visualize;
#[cfg(feature = "vulkan")]
pub mod vulkan;
pub mod workgroup;

/// The glam version the host's and the kernels' signatures use (0.34, the one spirv-std 0.11
/// builds against), so an engine can name `Vec3` and friends without pinning it itself.
pub use glam;
/// The kernels, as plain `no_std` functions: what the backends run, and what an engine's own
/// code (CPU or rust-gpu) can call.
pub use raywave_kernels as kernels;
/// The host/kernel contract: the parameter structs, the lights and the binding numbers.
pub use raywave_shared as shared;

pub use backend::{Backend, FrameOutput, StageReport, ValidationLog};
pub use device::{
    close_backend, open_backend, open_backend_telling_fallback, BackendOptions, DeviceChoice, TraceMethod,
};
pub use error::{Error, Result};
pub use scene::Scene;
pub use stream::{HitStream, RayStream};
pub use workgroup::{StreamStage, WorkgroupSizes};

/// Whether the tests run under CI (`CI=true` or `1`, as the integration tests read it): there a
/// test that cannot run on this machine fails instead of skipping.
#[cfg(test)]
pub(crate) fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true" || v == "1")
}
