//! The Vulkan instance and device: loading, validation-message capture, device enumeration with
//! ray-tracing feature detection, and device creation.

use super::driver_lock;
use super::kernel::stream_rows_fit;
use super::recycle::Recycler;
use crate::backend::{check_sustain_seconds, ValidationLog};
use crate::device::TraceMethod;
use crate::error::{Error, Result};
use crate::workgroup::WorkgroupSizes;
use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use raywave_shared::bindings::MOST_STORAGE_BUFFERS;
use raywave_shared::bindings::STREAM_ROW;
use std::ffi::{c_void, CStr};
use std::io::Write;
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

/// Name of the Khronos validation layer.
const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// Converts a failed Vulkan call into [`Error::Vulkan`].
pub(crate) fn vk_error(call: &'static str) -> impl Fn(vk::Result) -> Error {
    move |result| Error::Vulkan { call, result: format!("{result:?}") }
}

/// What one Vulkan device offers raywave.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeviceInfo {
    /// Index in `vkEnumeratePhysicalDevices` order, as used by `--device vulkan:N`.
    pub index: usize,
    /// `deviceName`.
    pub name: String,
    /// Device type (discrete GPU, integrated GPU, CPU, …).
    pub device_type: String,
    /// Supported Vulkan version, `major.minor.patch`.
    pub api_version: String,
    /// `VK_KHR_ray_query` with its `rayQuery` feature.
    pub ray_query: bool,
    /// `VK_KHR_acceleration_structure` with its `accelerationStructure` feature.
    pub acceleration_structure: bool,
    /// `VK_KHR_ray_tracing_pipeline` with its `rayTracingPipeline` feature.
    pub ray_tracing_pipeline: bool,
    /// The Vulkan 1.2 `bufferDeviceAddress` feature.
    pub buffer_device_address: bool,
    /// The Vulkan 1.2 `vulkanMemoryModel` feature: every rust-gpu module uses the Vulkan memory
    /// model, so no kernel runs without it.
    pub vulkan_memory_model: bool,
    /// The Vulkan 1.2 property `shaderSignedZeroInfNanPreserveFloat32`: every raywave kernel
    /// declares the `SignedZeroInfNanPreserve` execution mode for 32-bit floats, without which a
    /// driver may assume that no value is NaN or ±Inf and drop the kernels' checks for them
    /// (`raywave_kernels::entry`), so no kernel runs without it.
    pub signed_zero_inf_nan_preserve: bool,
    /// Whether raywave's compute queue writes GPU timestamps: `timestampComputeAndGraphics` and a
    /// `timestampValidBits` above 0. Without them every pass is timed by the host clock, since
    /// writing a timestamp on a queue without valid bits is invalid usage.
    pub timestamps: bool,
    /// `timestampValidBits` of the compute queue family raywave runs on (0: no timestamps): the
    /// counter wraps at `2^bits`, so an elapsed time is taken modulo that.
    pub timestamp_valid_bits: u32,
    /// The storage buffers one compute pass may bind on this device: the least of
    /// `maxPerStageDescriptorStorageBuffers`, `maxDescriptorSetStorageBuffers` and
    /// `maxPerStageResources` (raywave's passes bind up to [`MOST_STORAGE_BUFFERS`]).
    pub storage_buffers_per_pass: u32,
    /// The workgroup sizes this device runs the 1-D stream stages with
    /// ([`ContextOptions::workgroup_sizes`]), ascending: the powers of two within
    /// `maxComputeWorkGroupSize[0]` and `maxComputeWorkGroupInvocations` whose rows of
    /// [`STREAM_ROW`] invocations are whole workgroups that fit `maxComputeWorkGroupCount[0]`.
    pub workgroup_sizes: Vec<u32>,
    /// `maxStorageBufferRange`, bytes: a stream of `Vec4`s holds at most a sixteenth of it
    /// elements ([`Self::max_stream_len`]).
    pub max_storage_buffer_range: u32,
    /// `maxComputeWorkGroupCount`: with the workgroup size, how many invocations one dispatch
    /// covers ([`Self::max_stream_len`]).
    pub max_compute_work_group_count: [u32; 3],
}

impl DeviceInfo {
    /// The longest stream (rays, hits, an image's pixels) this device holds in one storage buffer
    /// of `Vec4`s and covers with one dispatch in workgroups of `smallest_workgroup` invocations —
    /// the smallest size a backend runs its stages in: where those fit, every stage's do. One row
    /// of workgroups, or rows of [`STREAM_ROW`] invocations where such a row's workgroups fit
    /// `maxComputeWorkGroupCount[0]` (`kernel::dispatch_grid`'s two grids).
    pub fn max_stream_len(&self, smallest_workgroup: u32) -> u64 {
        let by_buffer = u64::from(self.max_storage_buffer_range) / std::mem::size_of::<glam::Vec4>() as u64;
        let [max_x, max_y, _] = self.max_compute_work_group_count;
        let one_row = u64::from(max_x) * u64::from(smallest_workgroup);
        let rows_fit = stream_rows_fit(smallest_workgroup, max_x);
        let rows = if rows_fit { u64::from(max_y) * u64::from(STREAM_ROW) } else { 0 };
        by_buffer.min(one_row.max(rows)).min(u64::from(u32::MAX))
    }

    /// Checks a `width` × `height` image (one stream element a pixel) against this device with its
    /// stages in `workgroup_sizes`: the size rules every backend shares and
    /// [`Self::max_stream_len`], as a backend opened on it would
    /// ([`crate::Backend::check_image_size`]) — so that a bench refuses a size the device cannot
    /// take before it measures anything (it had measured the CPU for minutes first).
    pub fn check_image_size(&self, width: u32, height: u32, workgroup_sizes: &WorkgroupSizes) -> Result<()> {
        let max_pixels = self.max_stream_len(workgroup_sizes.smallest());
        crate::backend::check_image_size_common(
            width,
            height,
            max_pixels,
            &format!("vulkan:{} {}", self.index, self.name),
        )
    }

    /// What every kernel needs and this device lacks (empty when raywave runs on it): Vulkan 1.2
    /// with `vulkanMemoryModel` (every rust-gpu module uses it) and
    /// `shaderSignedZeroInfNanPreserveFloat32` (every kernel keeps IEEE Inf and NaN), and room
    /// for [`MOST_STORAGE_BUFFERS`] storage buffers in one pass.
    pub fn missing_for_kernels(&self) -> Vec<String> {
        let mut missing = Vec::new();
        if !self.vulkan_memory_model {
            missing.push("Vulkan 1.2 with vulkanMemoryModel".to_owned());
        }
        if !self.signed_zero_inf_nan_preserve {
            missing.push("shaderSignedZeroInfNanPreserveFloat32 (IEEE Inf and NaN in 32-bit float shaders)".to_owned());
        }
        if self.storage_buffers_per_pass < MOST_STORAGE_BUFFERS {
            missing.push(format!(
                "{MOST_STORAGE_BUFFERS} storage buffers a pass (maxPerStageDescriptorStorageBuffers, \
                 maxDescriptorSetStorageBuffers, maxPerStageResources: {})",
                self.storage_buffers_per_pass
            ));
        }
        missing
    }

    /// What the ray-query trace stage needs and this device lacks (empty when it can run).
    pub fn missing_for_ray_query(&self) -> Vec<String> {
        let mut missing = Vec::new();
        let mut need = |ok: bool, what: &str| {
            if !ok {
                missing.push(what.to_owned());
            }
        };
        need(self.acceleration_structure, "VK_KHR_acceleration_structure (accelerationStructure)");
        need(self.ray_query, "VK_KHR_ray_query (rayQuery)");
        need(self.buffer_device_address, "bufferDeviceAddress");
        missing
    }

    /// What the ray-tracing-pipeline trace stage needs and this device lacks (empty when it can run).
    pub fn missing_for_rt_pipeline(&self) -> Vec<String> {
        let mut missing = self.missing_for_ray_query();
        missing.retain(|m| !m.starts_with("VK_KHR_ray_query"));
        if !self.ray_tracing_pipeline {
            missing.push("VK_KHR_ray_tracing_pipeline (rayTracingPipeline)".to_owned());
        }
        missing
    }

    /// What trace method `method` needs and this device lacks (empty when it can run; software
    /// traversal runs everywhere).
    pub fn missing_for(&self, method: TraceMethod) -> Vec<String> {
        match method {
            TraceMethod::Software => Vec::new(),
            TraceMethod::RayQuery => self.missing_for_ray_query(),
            TraceMethod::RtPipeline => self.missing_for_rt_pipeline(),
        }
    }

    /// The trace methods this device runs, in the order the benchmarks measure them: software
    /// traversal, then ray query and the ray-tracing pipeline where it has what they need — so
    /// that every bench picks its methods alike (an NVIDIA H100 or H200: `sw` and `rtpipe`;
    /// lavapipe: all three).
    pub fn trace_methods(&self) -> Vec<TraceMethod> {
        [TraceMethod::Software, TraceMethod::RayQuery, TraceMethod::RtPipeline]
            .into_iter()
            .filter(|&method| self.missing_for(method).is_empty())
            .collect()
    }
}

/// Shader-binding-table sizes of `VK_KHR_ray_tracing_pipeline`, bytes.
#[derive(Copy, Clone, Debug, Default)]
pub(crate) struct RtPipelineProperties {
    pub handle_size: u32,
    pub handle_alignment: u32,
    pub base_alignment: u32,
    pub max_dispatch_invocations: u32,
}

/// How to open a Vulkan device.
#[derive(Clone, Debug, Default)]
pub struct ContextOptions {
    /// Enable `VK_LAYER_KHRONOS_validation`, with its synchronization validation where the layer
    /// offers it (`VK_EXT_validation_features`), and capture its warnings and errors. Fails with
    /// [`Error::VulkanUnavailable`] if the layer is not installed.
    pub validation: bool,
    /// Benchmark mode, in seconds (finite, `0..=1`; 0, the default, is off): after a kernel's
    /// first run, each of its timed submissions repeats the dispatch back to back — up to
    /// [`MAX_SUSTAINED_DISPATCHES`] times, as many as the kernel's last time per invocation says
    /// keep the device busy for about this long — and reports the mean per dispatch
    /// ([`crate::StageReport::dispatches`]). A GPU lowers its clocks under sparse work: on an
    /// NVIDIA H200 the single dispatches of `raywave bench denoise`, each submitted alone
    /// between uploads, ran at the idle 345 MHz instead of the 1980 MHz boost, 2.5–5.5× slower,
    /// whenever they missed the few seconds of boost that opening the device gives (README).
    /// Results do not change: no kernel reads what it writes, and a stage's sanitized counter is
    /// zeroed before the last repetition.
    pub sustain_seconds: f64,
    /// Invocations per workgroup of each 1-D stream stage, for occupancy tuning: each a power of
    /// two among [`DeviceInfo::workgroup_sizes`], else a typed error at open naming the field;
    /// `None` (the default): the preferred sizes, [`WorkgroupSizes::PREFERRED`], as far as
    /// the device runs them ([`WorkgroupSizes::preferred_on`]).
    pub workgroup_sizes: Option<WorkgroupSizes>,
    /// The obvhs preset of the CWBVH that the software trace method builds for each scene it
    /// loads (the other methods build the driver's acceleration structures): the default, or
    /// the one `raywave bench trace --bvh` measures on the CPU, so both traverse the same tree.
    pub software_bvh: crate::cpu::BvhQuality,
}

/// What `VK_KHR_acceleration_structure` allows on a device
/// (`VkPhysicalDeviceAccelerationStructurePropertiesKHR`).
#[derive(Copy, Clone, Debug, Default)]
pub(crate) struct AccelerationLimits {
    /// `minAccelerationStructureScratchOffsetAlignment`, bytes (at least 1).
    pub scratch_alignment: u64,
    /// `maxInstanceCount`: instances in a top-level structure (Vulkan guarantees 2²⁴ − 1).
    pub max_instances: u64,
    /// `maxPrimitiveCount`: triangles in a bottom-level structure (Vulkan guarantees 2²⁹ − 1).
    pub max_triangles: u64,
}

/// Most dispatches one timed submission repeats in benchmark mode
/// ([`ContextOptions::sustain_seconds`]).
pub const MAX_SUSTAINED_DISPATCHES: u32 = 1024;

/// Instance-level state shared by every object created from it; destroyed last.
pub(crate) struct Core {
    _entry: ash::Entry,
    pub instance: ash::Instance,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    /// Validation messages of warning or error severity, in arrival order.
    messages: ValidationLog,
    pub device: ash::Device,
    pub queue: vk::Queue,
    pub queue_family: u32,
    pub allocator: ManuallyDrop<Mutex<Allocator>>,
    pub acceleration_structure: Option<ash::khr::acceleration_structure::Device>,
    pub ray_tracing_pipeline: Option<ash::khr::ray_tracing_pipeline::Device>,
    pub rt_properties: RtPipelineProperties,
    pub info: DeviceInfo,
    pub limits: vk::PhysicalDeviceLimits,
    /// The acceleration-structure limits builds must keep to (without the extension: counts 0,
    /// scratch alignment 1).
    pub accel_limits: AccelerationLimits,
    /// [`ContextOptions::sustain_seconds`], as `f64` bits: [`Core::sustain_seconds`], changed
    /// by [`Core::set_sustain_seconds`].
    sustain_seconds: AtomicU64,
    /// Invocations per workgroup of the 1-D stream stages ([`ContextOptions::workgroup_sizes`]
    /// or the preferred ones, checked against the device).
    pub workgroup_sizes: WorkgroupSizes,
    /// Command buffers submitted to the queue so far ([`super::buffer::submit_and_wait`]): the
    /// clock that ages kept transient buffers out ([`Recycler`]), and what the tests count to
    /// check that a batch is one submission.
    pub submissions: AtomicU64,
    /// Transient buffers kept for the next call that needs one of their kind.
    pub recycler: Recycler,
    /// Set when a wait for a submission failed and the device then could not be idled either (an
    /// error other than a lost device, after which every submission counts as done): the GPU may
    /// still be using any object of the device, so from then on none is destroyed — each is
    /// leaked, the device with them — and nothing more is submitted
    /// ([`super::buffer::submit_and_wait`]).
    wedged: AtomicBool,
}

impl Drop for Core {
    fn drop(&mut self) {
        if self.is_wedged() {
            // Leaked: the GPU may still be using the device's objects (`wedged`). So is the
            // debug messenger, whose callback writes into the log: it must outlive it.
            std::mem::forget(self.messages.clone());
            return;
        }
        let _lifetime = driver_lock::device_lifetime();
        // SAFETY: every object created from this device holds an `Arc<Core>`, so none is alive now.
        unsafe {
            let _ = self.device.device_wait_idle();
            for parked in self.recycler.drain().0 {
                super::buffer::free_parked(self, parked);
            }
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
            if let Some((utils, messenger)) = self.debug.take() {
                utils.destroy_debug_utils_messenger(messenger, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

impl Core {
    /// Whether the device is wedged ([`Core::wedge`]): nothing of it may be destroyed any more.
    pub fn is_wedged(&self) -> bool {
        self.wedged.load(Ordering::Acquire)
    }

    /// Marks the device wedged: a submission may still be running that the driver could neither
    /// wait for nor idle the device behind, so every object it might use — any of the device's —
    /// is leaked from now on instead of destroyed, and no more work is submitted.
    pub fn wedge(&self) {
        self.wedged.store(true, Ordering::Release);
    }

    /// The validation log ([`ValidationLog`]), shared.
    pub fn validation_log(&self) -> ValidationLog {
        self.messages.clone()
    }

    /// Frees every transient buffer kept for reuse ([`Recycler`]) and returns their bytes. No
    /// command uses a kept buffer, so this may run between any two calls.
    pub fn free_kept_buffers(&self) -> u64 {
        let (kept, bytes) = self.recycler.drain();
        let _driver = driver_lock::device_use();
        kept.into_iter().for_each(|parked| super::buffer::free_parked(self, parked));
        bytes
    }
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user_data: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the loader passes a valid callback-data pointer; `user_data` is the
    // `Mutex<Vec<String>>` owned by the `Core` that registered this messenger and outlives it.
    let (text, sink) = unsafe {
        let text = (*data).message_as_c_str().map(|m| m.to_string_lossy().into_owned()).unwrap_or_default();
        (text, &*(user_data as *const Mutex<Vec<String>>))
    };
    let line = format!("[vulkan {severity:?}] {text}");
    // Not `eprintln!`, which panics when stderr is gone (a closed pipe), and a panic out of an
    // `extern "system"` callback aborts the process; the message is kept in `sink` regardless.
    let _ = writeln!(std::io::stderr().lock(), "{line}");
    if let Ok(mut messages) = sink.lock() {
        messages.push(line);
    }
    vk::FALSE
}

/// The Vulkan loader, loaded once for the process and never unloaded, with the drivers it found
/// kept loaded too ([`keep_drivers_loaded`]). The caller holds [`driver_lock::device_lifetime`].
fn load_entry() -> Result<ash::Entry> {
    // A loader that failed to load stays failed: a missing libvulkan does not come back.
    static LOADER: OnceLock<std::result::Result<ash::Entry, String>> = OnceLock::new();
    let entry = LOADER
        // SAFETY: loading the system Vulkan loader library; no Vulkan call is in flight.
        .get_or_init(|| unsafe { ash::Entry::load() }.map_err(|e| e.to_string()))
        .clone()
        .map_err(|e| Error::VulkanUnavailable { reason: format!("cannot load the Vulkan loader: {e}") })?;
    keep_drivers_loaded(&entry);
    Ok(entry)
}

/// Creates, once, an instance that is never destroyed, so that the loader never unloads the
/// drivers' libraries; tried again on the next call until it succeeds (a driver the loader could
/// not start this time is not held). It enables no layer of its own (layers the environment
/// forces, `VK_INSTANCE_LAYERS` or implicit ones, still load, harmlessly). Why: the loader
/// unloads a driver's library when the last instance using it is destroyed, and NVIDIA's driver
/// (580.159.04 on an H100, measured) can still have a thread of its own running in that library
/// then: `trace_robustness`, whose test threads open and close backends in turn, died in 2 of 5
/// runs with a segmentation fault at an instruction address no longer mapped, in a thread named
/// after one of the tests. An engine that opens and closes backends would meet the same. While no
/// instance can be created this does nothing; opening a device then reports why. The caller holds
/// [`driver_lock::device_lifetime`].
fn keep_drivers_loaded(entry: &ash::Entry) {
    static KEPT: AtomicBool = AtomicBool::new(false);
    if !KEPT.load(Ordering::Acquire) {
        // `ash::Instance` has no destructor: dropping the handle leaves the instance alive.
        let kept = create_instance(entry, false, false, None).is_ok();
        KEPT.store(kept, Ordering::Release);
    }
}

/// Creates the instance; with `validation` the validation layer, with its synchronization
/// validation where `sync_validation` says the layer offers it (`VK_EXT_validation_features`),
/// and the debug-utils messenger of `messenger_info`.
fn create_instance(
    entry: &ash::Entry,
    validation: bool,
    sync_validation: bool,
    messenger_info: Option<&mut vk::DebugUtilsMessengerCreateInfoEXT>,
) -> Result<ash::Instance> {
    let app = vk::ApplicationInfo::default()
        .application_name(c"raywave")
        .engine_name(c"raywave")
        .api_version(vk::API_VERSION_1_2);
    let layers = if validation { vec![VALIDATION_LAYER.as_ptr()] } else { vec![] };
    let mut extensions = if validation { vec![ash::ext::debug_utils::NAME.as_ptr()] } else { vec![] };
    if sync_validation {
        extensions.push(ash::ext::validation_features::NAME.as_ptr());
    }
    // With validation, synchronization validation too: a missing barrier between passes that a
    // serial device such as lavapipe forgives is an error the tests see.
    let enabled = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
    let mut features = vk::ValidationFeaturesEXT::default().enabled_validation_features(&enabled);
    let mut info = vk::InstanceCreateInfo::default()
        .application_info(&app)
        .enabled_layer_names(&layers)
        .enabled_extension_names(&extensions);
    if let Some(m) = messenger_info {
        info = info.push_next(m);
    }
    if sync_validation {
        info = info.push_next(&mut features);
    }
    // SAFETY: all pointers in `info` borrow locals that outlive the call.
    unsafe { entry.create_instance(&info, None) }.map_err(|e| match e {
        vk::Result::ERROR_INCOMPATIBLE_DRIVER => {
            Error::VulkanUnavailable { reason: "no Vulkan 1.2 driver is installed".into() }
        }
        other => vk_error("vkCreateInstance")(other),
    })
}

fn physical_devices(instance: &ash::Instance) -> Result<Vec<vk::PhysicalDevice>> {
    // SAFETY: `instance` is a live instance.
    unsafe { instance.enumerate_physical_devices() }.map_err(vk_error("vkEnumeratePhysicalDevices"))
}

fn has_extension(available: &[vk::ExtensionProperties], name: &CStr) -> bool {
    available.iter().any(|e| e.extension_name_as_c_str() == Ok(name))
}

/// Reads the properties and ray-tracing features of one physical device.
fn describe(instance: &ash::Instance, physical: vk::PhysicalDevice, index: usize) -> Result<DeviceInfo> {
    // SAFETY: `physical` was enumerated from `instance`; the feature chain borrows locals.
    unsafe {
        let props = instance.get_physical_device_properties(physical);
        let exts = instance
            .enumerate_device_extension_properties(physical)
            .map_err(vk_error("vkEnumerateDeviceExtensionProperties"))?;
        let has_as = has_extension(&exts, ash::khr::acceleration_structure::NAME)
            && has_extension(&exts, ash::khr::deferred_host_operations::NAME);
        let has_rq = has_extension(&exts, ash::khr::ray_query::NAME);
        let has_rtp = has_extension(&exts, ash::khr::ray_tracing_pipeline::NAME);
        let api_1_2 = props.api_version >= vk::API_VERSION_1_2;
        let mut v12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut as_features = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default();
        let mut rq_features = vk::PhysicalDeviceRayQueryFeaturesKHR::default();
        let mut rtp_features = vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default();
        let mut features = vk::PhysicalDeviceFeatures2::default();
        if api_1_2 {
            features = features.push_next(&mut v12);
        }
        if has_as {
            features = features.push_next(&mut as_features);
        }
        if has_rq {
            features = features.push_next(&mut rq_features);
        }
        if has_rtp {
            features = features.push_next(&mut rtp_features);
        }
        instance.get_physical_device_features2(physical, &mut features);
        let mut v12_properties = vk::PhysicalDeviceVulkan12Properties::default();
        if api_1_2 {
            let mut properties = vk::PhysicalDeviceProperties2::default().push_next(&mut v12_properties);
            instance.get_physical_device_properties2(physical, &mut properties);
        }
        let timestamp_valid_bits = compute_queue_family(instance, physical).map_or(0, |(_, f)| f.timestamp_valid_bits);
        let v = props.api_version;
        Ok(DeviceInfo {
            index,
            name: props.device_name_as_c_str().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
            device_type: format!("{:?}", props.device_type),
            api_version: format!(
                "{}.{}.{}",
                vk::api_version_major(v),
                vk::api_version_minor(v),
                vk::api_version_patch(v)
            ),
            ray_query: has_rq && rq_features.ray_query == vk::TRUE,
            acceleration_structure: has_as && as_features.acceleration_structure == vk::TRUE,
            ray_tracing_pipeline: has_rtp && rtp_features.ray_tracing_pipeline == vk::TRUE,
            buffer_device_address: api_1_2 && v12.buffer_device_address == vk::TRUE,
            vulkan_memory_model: api_1_2 && v12.vulkan_memory_model == vk::TRUE,
            signed_zero_inf_nan_preserve: api_1_2
                && v12_properties.shader_signed_zero_inf_nan_preserve_float32 == vk::TRUE,
            timestamps: props.limits.timestamp_compute_and_graphics == vk::TRUE && timestamp_valid_bits > 0,
            timestamp_valid_bits,
            storage_buffers_per_pass: props
                .limits
                .max_per_stage_descriptor_storage_buffers
                .min(props.limits.max_descriptor_set_storage_buffers)
                .min(props.limits.max_per_stage_resources),
            workgroup_sizes: stream_workgroup_sizes(&props.limits),
            max_storage_buffer_range: props.limits.max_storage_buffer_range,
            max_compute_work_group_count: props.limits.max_compute_work_group_count,
        })
    }
}

/// The queue family raywave runs on — the first with compute — with its index, or `None` when
/// the device has no compute queue.
fn compute_queue_family(
    instance: &ash::Instance,
    physical: vk::PhysicalDevice,
) -> Option<(u32, vk::QueueFamilyProperties)> {
    // SAFETY: `physical` was enumerated from `instance`.
    let families = unsafe { instance.get_physical_device_queue_family_properties(physical) };
    (0u32..).zip(families).find(|(_, family)| family.queue_flags.contains(vk::QueueFlags::COMPUTE))
}

/// Lists every Vulkan device with the features raywave cares about. An absent Vulkan loader or
/// driver is an [`Error::VulkanUnavailable`].
pub fn enumerate_devices() -> Result<Vec<DeviceInfo>> {
    let _lifetime = driver_lock::device_lifetime();
    let entry = load_entry()?;
    let instance = create_instance(&entry, false, false, None)?;
    let result = physical_devices(&instance)
        .and_then(|devices| devices.iter().enumerate().map(|(i, &pd)| describe(&instance, pd, i)).collect());
    // SAFETY: nothing was created from this instance.
    unsafe { instance.destroy_instance(None) };
    result
}

/// Opens Vulkan device `index` (as listed by [`enumerate_devices`]).
pub(crate) fn open(index: usize, options: &ContextOptions) -> Result<Arc<Core>> {
    check_sustain_seconds(options.sustain_seconds)?;
    let _lifetime = driver_lock::device_lifetime();
    let entry = load_entry()?;
    if options.validation {
        // SAFETY: plain query on a loaded entry.
        let layers = unsafe { entry.enumerate_instance_layer_properties() }
            .map_err(vk_error("vkEnumerateInstanceLayerProperties"))?;
        if !layers.iter().any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER)) {
            return Err(Error::VulkanUnavailable {
                reason: "validation requested but VK_LAYER_KHRONOS_validation is not installed".into(),
            });
        }
    }
    // Synchronization validation where the layer offers it: an older layer without
    // `VK_EXT_validation_features` still validates the rest, as before raywave asked for it (not
    // a failed `vkCreateInstance`); CI's layer has it, which
    // `buffer::tests::validation_reports_a_missing_barrier` checks.
    let sync_validation = options.validation && {
        // SAFETY: plain query on a loaded entry for an installed layer.
        let extensions = unsafe { entry.enumerate_instance_extension_properties(Some(VALIDATION_LAYER)) }
            .map_err(vk_error("vkEnumerateInstanceExtensionProperties"))?;
        has_extension(&extensions, ash::ext::validation_features::NAME)
    };
    let messages = ValidationLog::default();
    let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(vk::DebugUtilsMessageSeverityFlagsEXT::WARNING | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR)
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(debug_callback))
        .user_data(Arc::as_ptr(&messages.0) as *mut c_void);
    let instance = create_instance(
        &entry,
        options.validation,
        sync_validation,
        options.validation.then_some(&mut messenger_info),
    )?;
    // From here on, every failure path destroys what was created before it.
    let debug = if options.validation {
        let utils = ash::ext::debug_utils::Instance::new(&entry, &instance);
        // SAFETY: `messenger_info` is valid and its user data outlives the messenger (owned by Core).
        match unsafe { utils.create_debug_utils_messenger(&messenger_info, None) } {
            Ok(m) => Some((utils, m)),
            Err(e) => {
                // SAFETY: nothing else was created from the instance.
                unsafe { instance.destroy_instance(None) };
                return Err(vk_error("vkCreateDebugUtilsMessengerEXT")(e));
            }
        }
    } else {
        None
    };
    let destroy_instance =
        |instance: &ash::Instance, debug: &Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>| {
            // SAFETY: no device was created (or it was destroyed) from this instance.
            unsafe {
                if let Some((utils, m)) = debug {
                    utils.destroy_debug_utils_messenger(*m, None);
                }
                instance.destroy_instance(None);
            }
        };
    let physical = match physical_devices(&instance) {
        Ok(list) if index < list.len() => list[index],
        Ok(list) => {
            destroy_instance(&instance, &debug);
            return Err(Error::DeviceChoice {
                requested: format!("vulkan:{index}"),
                reason: match list.len() {
                    0 => "there is no Vulkan device".to_owned(),
                    1 => "there is one Vulkan device, vulkan:0".to_owned(),
                    n => format!("there are {n} Vulkan devices, vulkan:0 to vulkan:{}", n - 1),
                },
            });
        }
        Err(e) => {
            destroy_instance(&instance, &debug);
            return Err(e);
        }
    };
    // SAFETY: plain query of a physical device of this instance.
    let device_limits = unsafe { instance.get_physical_device_properties(physical).limits };
    let runnable = stream_workgroup_sizes(&device_limits);
    let workgroup_sizes = options.workgroup_sizes.unwrap_or_else(|| WorkgroupSizes::preferred_on(&runnable));
    if let Err(e) = workgroup_sizes.check(&runnable) {
        destroy_instance(&instance, &debug);
        return Err(e);
    }
    match create_device(&instance, physical, index) {
        Ok((device, queue_family, info, limits, accel_limits, rt_properties)) => {
            // SAFETY: queue family `queue_family` with one queue was requested at device creation.
            let queue = unsafe { device.get_device_queue(queue_family, 0) };
            let allocator = Allocator::new(&AllocatorCreateDesc {
                instance: instance.clone(),
                device: device.clone(),
                physical_device: physical,
                debug_settings: Default::default(),
                buffer_device_address: info.buffer_device_address,
                allocation_sizes: Default::default(),
            });
            let allocator = match allocator {
                Ok(a) => a,
                Err(e) => {
                    // SAFETY: nothing was created from the device.
                    unsafe { device.destroy_device(None) };
                    destroy_instance(&instance, &debug);
                    return Err(Error::Vulkan { call: "gpu_allocator::Allocator::new", result: e.to_string() });
                }
            };
            let acceleration_structure =
                info.acceleration_structure.then(|| ash::khr::acceleration_structure::Device::new(&instance, &device));
            let ray_tracing_pipeline = info
                .missing_for_rt_pipeline()
                .is_empty()
                .then(|| ash::khr::ray_tracing_pipeline::Device::new(&instance, &device));
            Ok(Arc::new(Core {
                _entry: entry,
                instance,
                debug,
                messages,
                device,
                queue,
                queue_family,
                allocator: ManuallyDrop::new(Mutex::new(allocator)),
                acceleration_structure,
                ray_tracing_pipeline,
                rt_properties,
                info,
                limits,
                accel_limits,
                sustain_seconds: AtomicU64::new(options.sustain_seconds.to_bits()),
                workgroup_sizes,
                submissions: AtomicU64::new(0),
                recycler: Recycler::default(),
                wedged: AtomicBool::new(false),
            }))
        }
        Err(e) => {
            destroy_instance(&instance, &debug);
            Err(e)
        }
    }
}

impl Core {
    /// Benchmark mode's busy time per timed submission, in seconds (0: off;
    /// [`ContextOptions::sustain_seconds`]).
    pub fn sustain_seconds(&self) -> f64 {
        f64::from_bits(self.sustain_seconds.load(Ordering::Relaxed))
    }

    /// Turns benchmark mode on (`seconds` > 0) or off (0) for the passes run from now on;
    /// `seconds` outside `0..=1` is [`Error::InvalidParameter`].
    pub fn set_sustain_seconds(&self, seconds: f64) -> Result<()> {
        self.sustain_seconds.store(check_sustain_seconds(seconds)?.to_bits(), Ordering::Relaxed);
        Ok(())
    }
}

/// The powers of two a device with `limits` runs the 1-D stream stages in
/// ([`DeviceInfo::workgroup_sizes`]).
fn stream_workgroup_sizes(limits: &vk::PhysicalDeviceLimits) -> Vec<u32> {
    let most = limits.max_compute_work_group_size[0].min(limits.max_compute_work_group_invocations);
    (0..u32::BITS)
        .map(|k| 1 << k)
        .filter(|&size| size <= most && stream_rows_fit(size, limits.max_compute_work_group_count[0]))
        .collect()
}

type CreatedDevice = (ash::Device, u32, DeviceInfo, vk::PhysicalDeviceLimits, AccelerationLimits, RtPipelineProperties);

fn create_device(instance: &ash::Instance, physical: vk::PhysicalDevice, index: usize) -> Result<CreatedDevice> {
    let info = describe(instance, physical, index)?;
    let missing = info.missing_for_kernels();
    if !missing.is_empty() {
        return Err(Error::MissingFeatures { device: info.name.clone(), stage: "any kernel".into(), missing });
    }
    // SAFETY: `physical` belongs to `instance`; all create-info pointers borrow locals.
    unsafe {
        let (queue_family, _) = compute_queue_family(instance, physical).ok_or_else(|| Error::MissingFeatures {
            device: info.name.clone(),
            stage: "compute".into(),
            missing: vec!["a compute queue".into()],
        })?;
        let priorities = [1.0];
        let queues =
            [vk::DeviceQueueCreateInfo::default().queue_family_index(queue_family).queue_priorities(&priorities)];
        let mut extensions = vec![];
        if info.acceleration_structure {
            extensions.push(ash::khr::acceleration_structure::NAME.as_ptr());
            extensions.push(ash::khr::deferred_host_operations::NAME.as_ptr());
        }
        // Like the ray-tracing pipeline, only with what it requires (VK_KHR_acceleration_structure:
        // VUID-vkCreateDevice-ppEnabledExtensionNames-01387).
        let ray_query = info.missing_for_ray_query().is_empty();
        if ray_query {
            extensions.push(ash::khr::ray_query::NAME.as_ptr());
        }
        let rt_pipeline = info.missing_for_rt_pipeline().is_empty();
        if rt_pipeline {
            extensions.push(ash::khr::ray_tracing_pipeline::NAME.as_ptr());
        }
        let mut v12 = vk::PhysicalDeviceVulkan12Features::default()
            .buffer_device_address(info.buffer_device_address)
            .vulkan_memory_model(true);
        let mut as_features =
            vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default().acceleration_structure(true);
        let mut rq_features = vk::PhysicalDeviceRayQueryFeaturesKHR::default().ray_query(true);
        let mut rtp_features = vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default().ray_tracing_pipeline(true);
        let mut create = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queues)
            .enabled_extension_names(&extensions)
            .push_next(&mut v12);
        if info.acceleration_structure {
            create = create.push_next(&mut as_features);
        }
        if ray_query {
            create = create.push_next(&mut rq_features);
        }
        if rt_pipeline {
            create = create.push_next(&mut rtp_features);
        }
        let device = instance.create_device(physical, &create, None).map_err(vk_error("vkCreateDevice"))?;
        let limits = instance.get_physical_device_properties(physical).limits;
        let mut as_props = vk::PhysicalDeviceAccelerationStructurePropertiesKHR::default();
        if info.acceleration_structure {
            let mut props2 = vk::PhysicalDeviceProperties2::default().push_next(&mut as_props);
            instance.get_physical_device_properties2(physical, &mut props2);
        }
        let accel_limits = AccelerationLimits {
            scratch_alignment: u64::from(as_props.min_acceleration_structure_scratch_offset_alignment.max(1)),
            max_instances: as_props.max_instance_count,
            max_triangles: as_props.max_primitive_count,
        };
        let mut rt_properties = RtPipelineProperties::default();
        if rt_pipeline {
            let mut rtp_props = vk::PhysicalDeviceRayTracingPipelinePropertiesKHR::default();
            let mut props2 = vk::PhysicalDeviceProperties2::default().push_next(&mut rtp_props);
            instance.get_physical_device_properties2(physical, &mut props2);
            rt_properties = RtPipelineProperties {
                handle_size: rtp_props.shader_group_handle_size,
                handle_alignment: rtp_props.shader_group_handle_alignment,
                base_alignment: rtp_props.shader_group_base_alignment,
                max_dispatch_invocations: rtp_props.max_ray_dispatch_invocation_count,
            };
        }
        Ok((device, queue_family, info, limits, accel_limits, rt_properties))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_device_runs_the_powers_of_two_within_its_limits_in_rows_of_stream_row() {
        let limits = vk::PhysicalDeviceLimits {
            max_compute_work_group_size: [1024, 1024, 64],
            max_compute_work_group_invocations: 512,
            max_compute_work_group_count: [65_535, 65_535, 65_535],
            ..Default::default()
        };
        // 1024 exceeds the invocations per workgroup; 16 would make rows of 65 536 workgroups.
        assert_eq!(stream_workgroup_sizes(&limits), [32, 64, 128, 256, 512]);
        let wide = vk::PhysicalDeviceLimits { max_compute_work_group_count: [u32::MAX; 3], ..limits };
        assert_eq!(stream_workgroup_sizes(&wide), [1, 2, 4, 8, 16, 32, 64, 128, 256, 512]);
        let narrow = vk::PhysicalDeviceLimits { max_compute_work_group_size: [128, 128, 64], ..limits };
        assert_eq!(stream_workgroup_sizes(&narrow), [32, 64, 128]);
        // A workgroup wider than a row of `STREAM_ROW` would make rows of no workgroups.
        let huge = vk::PhysicalDeviceLimits {
            max_compute_work_group_size: [u32::MAX; 3],
            max_compute_work_group_invocations: u32::MAX,
            ..wide
        };
        assert_eq!(stream_workgroup_sizes(&huge).last(), Some(&STREAM_ROW));
    }

    /// A device as lavapipe describes itself: every feature, generous limits.
    fn lavapipe() -> DeviceInfo {
        DeviceInfo {
            index: 0,
            name: "llvmpipe".into(),
            device_type: "CPU".into(),
            api_version: "1.4.0".into(),
            ray_query: true,
            acceleration_structure: true,
            ray_tracing_pipeline: true,
            buffer_device_address: true,
            vulkan_memory_model: true,
            signed_zero_inf_nan_preserve: true,
            timestamps: true,
            timestamp_valid_bits: 64,
            storage_buffers_per_pass: 1 << 20,
            workgroup_sizes: vec![32, 64, 128, 256, 512, 1024],
            max_storage_buffer_range: 1 << 27,
            max_compute_work_group_count: [65535; 3],
        }
    }

    #[test]
    fn a_device_runs_software_traversal_and_the_hardware_methods_it_has_what_they_need_for() {
        let lavapipe = lavapipe();
        let all = [TraceMethod::Software, TraceMethod::RayQuery, TraceMethod::RtPipeline];
        assert_eq!(lavapipe.trace_methods(), all);
        // An NVIDIA H100 or H200: no ray query.
        let data_center = DeviceInfo { ray_query: false, ..lavapipe.clone() };
        assert_eq!(data_center.trace_methods(), [TraceMethod::Software, TraceMethod::RtPipeline]);
        assert_eq!(data_center.missing_for(TraceMethod::RayQuery), ["VK_KHR_ray_query (rayQuery)"]);
        let compute_only = DeviceInfo { acceleration_structure: false, ..lavapipe };
        assert_eq!(compute_only.trace_methods(), [TraceMethod::Software]);
        assert!(compute_only.missing_for(TraceMethod::Software).is_empty());
    }

    #[test]
    fn a_device_needs_the_memory_model_ieee_floats_and_room_for_the_shade_passes_buffers() {
        let base = DeviceInfo {
            name: "a GPU".into(),
            device_type: "DISCRETE_GPU".into(),
            storage_buffers_per_pass: MOST_STORAGE_BUFFERS,
            ..lavapipe()
        };
        assert!(base.missing_for_kernels().is_empty());
        // Vulkan's guaranteed minimum, 4 storage buffers a stage: the shade pass binds 18.
        let small = DeviceInfo { storage_buffers_per_pass: 4, ..base.clone() };
        let missing = small.missing_for_kernels();
        assert!(missing.len() == 1 && missing[0].contains("18 storage buffers a pass") && missing[0].contains(": 4)"));
        let old = DeviceInfo { vulkan_memory_model: false, ..small };
        assert_eq!(old.missing_for_kernels().len(), 2);
        // A driver that may assume no float is NaN or Inf.
        let lax = DeviceInfo { signed_zero_inf_nan_preserve: false, ..base.clone() };
        assert_eq!(lax.missing_for_kernels().len(), 1);
        assert!(lax.missing_for_kernels()[0].contains("shaderSignedZeroInfNanPreserveFloat32"));
        // `auto` passes over such devices.
        let devices = [DeviceInfo { index: 0, ..old }, DeviceInfo { index: 1, device_type: "CPU".into(), ..base }];
        assert_eq!(crate::device::best_vulkan_device(&devices).unwrap(), 1);
    }

    /// With a trace method or workgroup sizes asked for, `auto` takes the best device that has
    /// them: lavapipe beside an H100, which has no ray query, for `rayquery`; lavapipe beside a
    /// GPU that runs workgroups up to 512 for 1024; the GPU otherwise, and where no device has
    /// what is asked (the backend then says what it lacks).
    #[test]
    fn a_trace_method_or_workgroup_sizes_pick_the_best_device_that_has_them() {
        use crate::device::{best_vulkan_device_for as best_for, BackendOptions};
        let best = |devices: &[DeviceInfo], trace| best_for(devices, &BackendOptions { trace, ..Default::default() });
        let gpu = DeviceInfo { index: 0, device_type: "DISCRETE_GPU".into(), ray_query: false, ..lavapipe() };
        let devices = [gpu.clone(), DeviceInfo { index: 1, ..lavapipe() }];
        assert_eq!(best(&devices, Some(TraceMethod::RayQuery)).unwrap(), 1);
        assert_eq!(best(&devices, Some(TraceMethod::RtPipeline)).unwrap(), 0);
        assert_eq!(best(&devices, None).unwrap(), 0);
        assert_eq!(best(std::slice::from_ref(&gpu), Some(TraceMethod::RayQuery)).unwrap(), 0);
        // A device with ray query that cannot run the kernels does not hide one that can: that
        // one opens (and its backend then says it lacks ray query).
        let unable = DeviceInfo { index: 1, storage_buffers_per_pass: 4, ..lavapipe() };
        assert_eq!(best(&[gpu.clone(), unable], Some(TraceMethod::RayQuery)).unwrap(), 0);
        // Workgroup sizes: lavapipe runs 1024, this GPU up to 512; 512 both.
        let narrow = DeviceInfo { workgroup_sizes: vec![32, 64, 128, 256, 512], ..gpu.clone() };
        assert!(devices[1].workgroup_sizes.contains(&1024), "{:?}", devices[1].workgroup_sizes);
        let devices = [narrow.clone(), devices[1].clone()];
        let sized = |size| BackendOptions { workgroup_sizes: Some(WorkgroupSizes::all(size)), ..Default::default() };
        assert_eq!(best_for(&devices, &sized(1024)).unwrap(), 1);
        assert_eq!(best_for(&devices, &sized(512)).unwrap(), 0);
        assert_eq!(best_for(std::slice::from_ref(&narrow), &sized(1024)).unwrap(), 0);
    }

    /// A stream is bounded by one storage buffer of `Vec4`s and by one dispatch grid, and an image
    /// is checked against that before a backend opens: lavapipe's 2²⁷-byte buffers hold 2896²
    /// pixels, not 2897².
    #[test]
    fn a_stream_fits_one_buffer_and_one_dispatch() {
        let lavapipe = lavapipe();
        assert_eq!(lavapipe.max_stream_len(32), 1 << 23);
        let sizes = WorkgroupSizes::preferred_on(&lavapipe.workgroup_sizes);
        assert!(lavapipe.check_image_size(2896, 2896, &sizes).is_ok());
        let refused = lavapipe.check_image_size(2897, 2897, &sizes);
        assert!(
            matches!(&refused, Err(Error::ImageSize { backend, .. }) if backend == "vulkan:0 llvmpipe"),
            "{refused:?}"
        );
        // 65 535 workgroups in x and two rows: one row of 32-wide workgroups covers 2 097 120
        // invocations, two rows of `STREAM_ROW` (32 768 workgroups each) 2²¹.
        let grid = |max_compute_work_group_count| DeviceInfo {
            max_storage_buffer_range: u32::MAX,
            max_compute_work_group_count,
            ..lavapipe.clone()
        };
        assert_eq!(grid([65_535, 2, 1]).max_stream_len(32), 2 * u64::from(STREAM_ROW));
        assert_eq!(grid([65_535, 2, 1]).max_stream_len(1024), 65_535 * 1024);
        // 1024 in x: a row of `STREAM_ROW` does not fit, so one row of workgroups is all.
        assert_eq!(grid([1024, 4, 1]).max_stream_len(32), 1024 * 32);
        assert_eq!(grid([1024, 4, 1]).max_stream_len(0), 0);
        let wide = grid([u32::MAX, 1, 1]);
        assert_eq!(wide.max_stream_len(1), u64::from(u32::MAX) / 16);
        assert!(wide.check_image_size(0, 1, &sizes).is_err());
    }
}
