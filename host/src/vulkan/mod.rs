//! The Vulkan backend (feature `vulkan`): an ash context with validation capture, buffers through
//! gpu-allocator, BLAS/TLAS builds, compute pipelines from the embedded SPIR-V, and dispatch with
//! GPU timestamps.

mod accel;
mod backend;
mod batch;
mod buffer;
mod context;
mod denoise;
pub(crate) mod driver_lock;
mod kernel;
mod pass;
mod recycle;
mod rt_pipeline;
pub mod spirv;

pub use crate::backend::ValidationLog;
pub use backend::{VulkanBackend, SOFTWARE_DEVICE_LIT_FRAME_BYTES_PER_PIXEL};
pub use context::{enumerate_devices, ContextOptions, DeviceInfo, MAX_SUSTAINED_DISPATCHES};

/// The Vulkan devices a test runs on: every one there is. With none, under CI (`CI=true` or `1`)
/// the test fails; elsewhere it is told to skip (an empty list) with a loud line naming `what`.
#[cfg(test)]
pub(crate) fn devices_for_test(what: &str) -> Vec<DeviceInfo> {
    let devices = enumerate_devices().unwrap_or_default();
    if devices.is_empty() {
        assert!(!crate::in_ci(), "CI=true requires a Vulkan device");
        eprintln!("\n*** SKIP {what}: no Vulkan device ***\n");
    }
    devices
}

/// A context with validation on for each device of [`devices_for_test`] (named by `what`), with
/// the device's name: what the crate's own low-level tests run on.
#[cfg(test)]
pub(crate) fn validated_cores_for_test(what: &str) -> Vec<(String, std::sync::Arc<context::Core>)> {
    let options = ContextOptions { validation: true, ..Default::default() };
    devices_for_test(what)
        .into_iter()
        .map(|device| (device.name, context::open(device.index, &options).expect("a Vulkan context")))
        .collect()
}
