//! The Vulkan backend (feature `vulkan`): an ash context with validation capture, buffers through
//! gpu-allocator, BLAS/TLAS builds, compute pipelines from the embedded SPIR-V, and dispatch with
//! GPU timestamps.

mod accel;
mod backend;
mod batch;
mod buffer;
mod context;
mod denoise;
mod driver_lock;
mod kernel;
mod pass;
mod rt_pipeline;
pub mod spirv;

pub use crate::backend::ValidationLog;
pub use backend::VulkanBackend;
pub use context::{enumerate_devices, ContextOptions, DeviceInfo, MAX_SUSTAINED_DISPATCHES};
