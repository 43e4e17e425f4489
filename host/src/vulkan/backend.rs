//! The Vulkan backend: the generate, trace and shade stages as compute dispatches over
//! device-resident SoA streams.

use super::accel::{build_scene, check_limits, SceneAccel};
use super::batch::{Batch, Done, ReadId, RunId};
use super::buffer::{check_storage_range, GpuBuffer};
use super::context::{open, ContextOptions, Core, DeviceInfo};
use super::denoise::DenoiseKernels;
use super::driver_lock;
use super::kernel::{dispatch_grid, ComputeKernel};
use super::pass::Resource;
use super::rt_pipeline::{RtPipelineKernel, CLOSEST_HIT_SHADERS, OCCLUSION_SHADERS};
use crate::backend::{
    check_generate_params, check_image_size_common, check_shade_inputs, check_shade_params, copy_probe_len,
    sampler_probe_len, warp_probe_len, Backend, FrameOutput, StageReport,
};
use crate::cpu::CpuScene;
use crate::denoise::{DenoiseInput, DenoiseMethod};
use crate::device::TraceMethod;
use crate::error::{Error, Result};
use crate::lit_sample::{CameraStreams, LitSample, LitSampleRequest};
use crate::scene::{Scene, SceneIdentity};
use crate::shading::{ShadeData, ShadeDataIdentity};
use crate::stream::{count_hits, hits_among, HitStream, RayStream, ShadeStream, SHADE_STREAM_BYTES_PER_RAY};
use crate::workgroup::WorkgroupSizes;
use ash::vk;
use bytemuck::Pod;
use glam::{UVec2, Vec2, Vec4};
use raywave_shared::stream::{HIT_STREAM_BYTES_PER_RAY, RAY_STREAM_BYTES_PER_RAY};
use raywave_shared::{
    bindings, DenoiseParams, GenerateParams, SamplerProbeParams, ShadeParams, TraceParams, WarpParams,
};
use std::sync::Arc;

/// What a trace kernel reads of a ray stream on the device: its origins and directions.
struct DevicePaths {
    origin: GpuBuffer,
    direction: GpuBuffer,
    len: u32,
}

/// The ray stream on the device (what generate writes): the paths and each ray's pixel.
struct DeviceRays {
    paths: DevicePaths,
    pixel: GpuBuffer,
}

/// The hit stream on the device.
struct DeviceHits {
    t: GpuBuffer,
    primitive: GpuBuffer,
    instance: GpuBuffer,
    barycentrics: GpuBuffer,
    len: u32,
}

/// The records of a device stream that a read copies back.
#[derive(Clone, Copy, Debug)]
enum Records<'i> {
    /// The whole stream.
    All,
    /// The records at these indices, in their order ([`Batch::gather`]).
    At(&'i [u32]),
}

impl Records<'_> {
    /// Adds to `batch` the read of these records of `buffer`, a field of a stream of `len`.
    fn read_in<'a, T: Pod>(self, batch: &mut Batch<'a>, buffer: &'a GpuBuffer, len: u32) -> Result<ReadId<T>> {
        match self {
            Self::All => batch.read(buffer, len as usize),
            Self::At(indices) => batch.gather(buffer, indices),
        }
    }
}

/// The records at `indices` of the camera streams `rays` and `hits`, copied out of the device in
/// a submission of their own (none where there are none).
fn gather_camera_records(
    core: &Arc<Core>,
    rays: &DeviceRays,
    hits: &DeviceHits,
    indices: &[u32],
) -> Result<(RayStream, HitStream)> {
    let mut batch = Batch::new(core);
    let ray_reads = rays.read_records_in(&mut batch, Records::At(indices))?;
    let hit_reads = hits.read_records_in(&mut batch, Records::At(indices))?;
    let done = batch.submit()?;
    Ok((ray_reads.stream(&done)?, hit_reads.stream(&done)?))
}

/// A device buffer for the `count` samples of `T` of probe `name` (at least one: a binding
/// cannot be empty), refused where the device could not bind it whole ([`check_storage_range`]):
/// a probe is bounded by its sample count, not by [`VulkanBackend::max_rays`].
fn probe_buffer<T: Pod>(core: &Arc<Core>, count: u32, name: &'static str) -> Result<GpuBuffer> {
    let len = count.max(1);
    check_storage_range(&core.limits, u64::from(len) * std::mem::size_of::<T>() as u64, name, name)?;
    GpuBuffer::storage::<T>(core, len, name)
}

/// Runs probe `kernel` with push constants `push` over `count` samples, which it writes to
/// `samples`, and reads them back, in one batch.
fn probe<T: Pod>(
    core: &Arc<Core>,
    kernel: &ComputeKernel,
    samples: &GpuBuffer,
    push: &[u8],
    count: u32,
) -> Result<Vec<T>> {
    let mut batch = Batch::new(core);
    kernel.add_to(&mut batch, &[Resource::Buffer(samples)], push, count)?;
    let read = batch.read(samples, count as usize)?;
    batch.submit()?.read(&read)
}

impl DevicePaths {
    /// Room for `len` rays, checked against the device ([`VulkanBackend::check_stream`]).
    fn new(core: &Arc<Core>, len: u32) -> Result<Self> {
        Ok(Self {
            origin: GpuBuffer::storage::<Vec4>(core, len, "ray origin")?,
            direction: GpuBuffer::storage::<Vec4>(core, len, "ray direction")?,
            len,
        })
    }

    /// Adds to `batch` the uploads of the origins and directions of `rays`, the stream of `len`
    /// rays these buffers were made for.
    fn upload_in<'a>(&'a self, batch: &mut Batch<'a>, rays: &RayStream) -> Result<()> {
        batch.upload(&self.origin, &rays.origin)?;
        batch.upload(&self.direction, &rays.direction)
    }
}

impl DeviceRays {
    fn new(core: &Arc<Core>, len: u32) -> Result<Self> {
        Ok(Self { paths: DevicePaths::new(core, len)?, pixel: GpuBuffer::storage::<u32>(core, len, "ray pixel")? })
    }

    /// Adds the reads of the whole stream to `batch`.
    fn read_in<'a>(&'a self, batch: &mut Batch<'a>) -> Result<RayReads> {
        self.read_records_in(batch, Records::All)
    }

    /// Adds the reads of the stream's `records` to `batch`.
    fn read_records_in<'a>(&'a self, batch: &mut Batch<'a>, records: Records<'_>) -> Result<RayReads> {
        let (paths, len) = (&self.paths, self.paths.len);
        Ok(RayReads {
            origin: records.read_in(batch, &paths.origin, len)?,
            direction: records.read_in(batch, &paths.direction, len)?,
            pixel: records.read_in(batch, &self.pixel, len)?,
        })
    }
}

/// A ray stream's reads in a batch ([`DeviceRays::read_in`]).
struct RayReads {
    origin: ReadId<Vec4>,
    direction: ReadId<Vec4>,
    pixel: ReadId<u32>,
}

impl RayReads {
    /// The stream, once the batch has completed.
    fn stream(&self, done: &Done) -> Result<RayStream> {
        Ok(RayStream {
            origin: done.read(&self.origin)?,
            direction: done.read(&self.direction)?,
            pixel: done.read(&self.pixel)?,
        })
    }
}

impl DeviceHits {
    fn new(core: &Arc<Core>, len: u32) -> Result<Self> {
        Ok(Self {
            t: GpuBuffer::storage::<f32>(core, len, "hit t")?,
            primitive: GpuBuffer::storage::<u32>(core, len, "hit primitive")?,
            instance: GpuBuffer::storage::<u32>(core, len, "hit instance")?,
            barycentrics: GpuBuffer::storage::<Vec2>(core, len, "hit barycentrics")?,
            len,
        })
    }

    /// Adds to `batch` the uploads of `hits`, the stream of `len` hits these buffers were made
    /// for.
    fn upload_in<'a>(&'a self, batch: &mut Batch<'a>, hits: &HitStream) -> Result<()> {
        batch.upload(&self.t, &hits.t)?;
        batch.upload(&self.primitive, &hits.primitive)?;
        batch.upload(&self.instance, &hits.instance)?;
        batch.upload(&self.barycentrics, &hits.barycentrics)
    }

    /// The closest-hit trace's outputs, in the order of [`HIT_OUTPUTS`].
    fn outputs(&self) -> [&GpuBuffer; 4] {
        [&self.t, &self.primitive, &self.instance, &self.barycentrics]
    }

    /// Adds the reads of the whole stream to `batch`.
    fn read_in<'a>(&'a self, batch: &mut Batch<'a>) -> Result<HitReads> {
        self.read_records_in(batch, Records::All)
    }

    /// Adds the reads of the stream's `records` to `batch`.
    fn read_records_in<'a>(&'a self, batch: &mut Batch<'a>, records: Records<'_>) -> Result<HitReads> {
        let len = self.len;
        Ok(HitReads {
            t: records.read_in(batch, &self.t, len)?,
            primitive: records.read_in(batch, &self.primitive, len)?,
            instance: records.read_in(batch, &self.instance, len)?,
            barycentrics: records.read_in(batch, &self.barycentrics, len)?,
        })
    }
}

/// A hit stream's reads in a batch ([`DeviceHits::read_in`]).
struct HitReads {
    t: ReadId<f32>,
    primitive: ReadId<u32>,
    instance: ReadId<u32>,
    barycentrics: ReadId<Vec2>,
}

impl HitReads {
    /// The stream, once the batch has completed.
    fn stream(&self, done: &Done) -> Result<HitStream> {
        Ok(HitStream {
            t: done.read(&self.t)?,
            primitive: done.read(&self.primitive)?,
            instance: done.read(&self.instance)?,
            barycentrics: done.read(&self.barycentrics)?,
        })
    }
}

/// The shade stream on the device: the shade stage's five outputs, the last two the shadow rays
/// the occlusion trace reads.
struct DeviceShades {
    analytic: GpuBuffer,
    unshadowed: GpuBuffer,
    emitted: GpuBuffer,
    shadow: DevicePaths,
}

impl DeviceShades {
    fn new(core: &Arc<Core>, len: u32) -> Result<Self> {
        Ok(Self {
            analytic: GpuBuffer::storage::<Vec4>(core, len, "shade analytic")?,
            unshadowed: GpuBuffer::storage::<Vec4>(core, len, "shade unshadowed")?,
            emitted: GpuBuffer::storage::<Vec4>(core, len, "shade emitted")?,
            shadow: DevicePaths {
                origin: GpuBuffer::storage::<Vec4>(core, len, "shadow ray origin")?,
                direction: GpuBuffer::storage::<Vec4>(core, len, "shadow ray direction")?,
                len,
            },
        })
    }

    /// Adds the reads of the whole stream to `batch`.
    fn read_in<'a>(&'a self, batch: &mut Batch<'a>) -> Result<ShadeReads> {
        let n = self.shadow.len as usize;
        Ok(ShadeReads {
            analytic: batch.read(&self.analytic, n)?,
            unshadowed: batch.read(&self.unshadowed, n)?,
            emitted: batch.read(&self.emitted, n)?,
            shadow_origin: batch.read(&self.shadow.origin, n)?,
            shadow_direction: batch.read(&self.shadow.direction, n)?,
        })
    }
}

/// A shade stream's reads in a batch ([`DeviceShades::read_in`]).
struct ShadeReads {
    analytic: ReadId<Vec4>,
    unshadowed: ReadId<Vec4>,
    emitted: ReadId<Vec4>,
    shadow_origin: ReadId<Vec4>,
    shadow_direction: ReadId<Vec4>,
}

impl ShadeReads {
    /// The stream, once the batch has completed.
    fn stream(&self, done: &Done) -> Result<ShadeStream> {
        Ok(ShadeStream {
            analytic: done.read(&self.analytic)?,
            unshadowed: done.read(&self.unshadowed)?,
            emitted: done.read(&self.emitted)?,
            shadow_origin: done.read(&self.shadow_origin)?,
            shadow_direction: done.read(&self.shadow_direction)?,
        })
    }
}

/// The scene data of the shade stage on the device, uploaded once per [`ShadeData`] value (the
/// 192 KiB LTC table, the triangles, …) and reused while the same value comes back.
struct DeviceShadeData {
    /// Which [`ShadeData`] these buffers hold.
    identity: ShadeDataIdentity,
    triangles: GpuBuffer,
    first_triangle: GpuBuffer,
    materials: GpuBuffer,
    lights: GpuBuffer,
    light_nodes: GpuBuffer,
    light_trails: GpuBuffer,
    ltc: GpuBuffer,
}

impl DeviceShadeData {
    fn upload(core: &Arc<Core>, data: &ShadeData) -> Result<Self> {
        Ok(Self {
            identity: data.identity(),
            triangles: input_buffer(core, &data.triangles, "shade triangles")?,
            first_triangle: input_buffer(core, &data.first_triangle, "shade first triangle")?,
            materials: input_buffer(core, &data.materials, "shade materials")?,
            lights: input_buffer(core, &data.lights, "shade lights")?,
            light_nodes: input_buffer(core, &data.light_nodes, "shade light nodes")?,
            light_trails: input_buffer(core, &data.light_trails, "shade light trails")?,
            ltc: input_buffer(core, &data.ltc, "shade ltc table")?,
        })
    }
}

/// A read-only storage buffer holding scene data `data` (the shade stage's, the software
/// trace's), or one zeroed element when `data` is empty (a binding cannot be empty; the stage's
/// parameters carry the valid counts). Fails, naming the buffer, when it exceeds the device's
/// storage-buffer range, which a binding could not cover ([`check_storage_range`]).
fn input_buffer<T: Pod>(core: &Arc<Core>, data: &[T], name: &str) -> Result<GpuBuffer> {
    let dummy = [T::zeroed()];
    let data = if data.is_empty() { &dummy[..] } else { data };
    check_storage_range(&core.limits, std::mem::size_of_val(data) as u64, "scene", name)?;
    GpuBuffer::storage_with(core, data, name)
}

/// The scene as the chosen trace method reads it on the device.
enum DeviceScene {
    /// CWBVH nodes and triangles for the software traversal kernel (boxed: three buffers
    /// outweigh the other variant).
    Software(Box<SoftwareScene>),
    /// BLAS/TLAS for ray query and the ray-tracing pipeline.
    Accelerated(SceneAccel),
}

/// The buffers the software traversal kernel reads: CWBVH nodes, triangle vertices and ids.
struct SoftwareScene {
    nodes: GpuBuffer,
    vertices: GpuBuffer,
    ids: GpuBuffer,
}

/// The trace stage's pipeline: a compute kernel (software traversal, ray query) or a
/// ray-tracing pipeline.
enum TraceKernel {
    Compute(ComputeKernel),
    /// Boxed: it holds the ray-tracing pipeline's function table.
    RtPipeline(Box<RtPipelineKernel>),
}

/// A Vulkan device running raywave's stages. Several threads may each open, use and drop their own
/// at the same time: opening and dropping one wait until no other thread is inside a backend call,
/// because NVIDIA's driver deadlocks when a device is created or destroyed during another thread's
/// driver calls (measured; see `vulkan/driver_lock.rs`).
pub struct VulkanBackend {
    generate: ComputeKernel,
    sampler_probe: ComputeKernel,
    warp_probe: ComputeKernel,
    trace: TraceKernel,
    occlusion: TraceKernel,
    shade_kernels: ShadeKernels,
    denoise_kernels: DenoiseKernels,
    trace_method: TraceMethod,
    /// [`ContextOptions::software_bvh`]: the preset [`TraceMethod::Software`] builds.
    software_bvh: crate::cpu::BvhQuality,
    /// The loaded scene on the device, and the scene's identity, which shade data must match.
    scene: Option<(DeviceScene, SceneIdentity)>,
    /// The shade stage's scene data, cached across `shade` calls.
    shade_data: Option<DeviceShadeData>,
    core: Arc<Core>,
}

/// Descriptor layout of a trace kernel for `method` writing `outputs` (binding numbers from
/// `raywave_shared`): the scene at binding 0, the rays, the outputs, for software traversal the
/// triangle buffers, and the sanitized counter. [`add_trace`] binds resources in this order.
fn trace_bindings(method: TraceMethod, outputs: &[u32]) -> Vec<(u32, vk::DescriptorType)> {
    let storage = vk::DescriptorType::STORAGE_BUFFER;
    let scene = match method {
        TraceMethod::Software => (bindings::trace::NODES, storage),
        TraceMethod::RayQuery | TraceMethod::RtPipeline => {
            (bindings::trace::TLAS, vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
        }
    };
    let mut layout = vec![scene, (bindings::trace::RAY_ORIGIN, storage), (bindings::trace::RAY_DIRECTION, storage)];
    layout.extend(outputs.iter().map(|&binding| (binding, storage)));
    if method == TraceMethod::Software {
        layout.push((bindings::trace::TRIANGLE_VERTICES, storage));
        layout.push((bindings::trace::TRIANGLE_IDS, storage));
    }
    layout.push((bindings::trace::REPLACED, storage));
    layout
}

/// Memory a lit frame holds at its peak on a Vulkan device in host memory, bytes per pixel
/// ([`Backend::lit_frame_bytes_per_pixel`]): measured 543–563 on lavapipe (the peak resident
/// memory of `raywave render --device vulkan --spp 1 --exr --stochastic` grows by that much per
/// pixel from 512² to 1024², 1024² to 2048² and 2048² to 2800², 2026-12-01, a release build; 4 spp
/// alike; the debug build's 582 from 512² to 1024²), rounded up by 5 %.
pub const SOFTWARE_DEVICE_LIT_FRAME_BYTES_PER_PIXEL: u64 = 600;

/// [`Backend::lit_frame_bytes_per_pixel`] for a device of `device_type` (`VkPhysicalDeviceType`
/// without its prefix): on one in host memory (`CPU`, as lavapipe is), streams and device buffers
/// included, [`SOFTWARE_DEVICE_LIT_FRAME_BYTES_PER_PIXEL`]; on a GPU, not measured, the host
/// buffers every backend's lit frame holds at its denoise step
/// ([`crate::lit_frame::HOST_LIT_FRAME_BYTES_PER_PIXEL`]), a lower bound — so that a frame
/// that cannot fit the host is refused there too, where none had been.
fn lit_frame_bytes_per_pixel_on(device_type: &str) -> u64 {
    if device_type == "CPU" {
        SOFTWARE_DEVICE_LIT_FRAME_BYTES_PER_PIXEL
    } else {
        crate::lit_frame::HOST_LIT_FRAME_BYTES_PER_PIXEL
    }
}

/// Output bindings of the closest-hit trace.
const HIT_OUTPUTS: [u32; 4] = [
    bindings::trace::HIT_T,
    bindings::trace::HIT_PRIMITIVE,
    bindings::trace::HIT_INSTANCE,
    bindings::trace::HIT_BARYCENTRICS,
];

/// Output binding of the occlusion trace.
const OCCLUSION_OUTPUTS: [u32; 1] = [bindings::occlusion::OCCLUDED];

/// Bindings of the shade stage, in the order [`add_shade`] binds its resources.
const SHADE_BINDINGS: [u32; 18] = [
    bindings::shade::RAY_DIRECTION,
    bindings::shade::HIT_T,
    bindings::shade::HIT_PRIMITIVE,
    bindings::shade::HIT_INSTANCE,
    bindings::shade::HIT_BARYCENTRICS,
    bindings::shade::TRIANGLES,
    bindings::shade::FIRST_TRIANGLE,
    bindings::shade::MATERIALS,
    bindings::shade::LIGHTS,
    bindings::shade::LIGHT_NODES,
    bindings::shade::LIGHT_TRAILS,
    bindings::shade::LTC,
    bindings::shade::ANALYTIC,
    bindings::shade::UNSHADOWED,
    bindings::shade::EMITTED,
    bindings::shade::SHADOW_ORIGIN,
    bindings::shade::SHADOW_DIRECTION,
    bindings::shade::REPLACED,
];

/// The shade stage's pipelines, both of `entry::shade`: without the residual towards GGX (its
/// specialization constant [`bindings::shade::RESIDUAL_CODE_SPEC_ID`] 0), which passes without
/// `ShadeParams::analytic_residual` run, and with it, built at the first pass that asks for it.
/// The residual is two fifths of the kernel's code: specialized away, the driver does not
/// compile it (README, Shading: lavapipe's compile time) and may need fewer registers.
struct ShadeKernels {
    without_residual: ComputeKernel,
    with_residual: Option<ComputeKernel>,
}

impl ShadeKernels {
    fn new(core: &Arc<Core>) -> Result<Self> {
        Ok(Self { without_residual: Self::build(core, false)?, with_residual: None })
    }

    /// The pipeline with (`residual`) or without the residual's code.
    fn build(core: &Arc<Core>, residual: bool) -> Result<ComputeKernel> {
        let storage = vk::DescriptorType::STORAGE_BUFFER;
        let layout: Vec<_> = SHADE_BINDINGS.iter().map(|&binding| (binding, storage)).collect();
        ComputeKernel::specialized(
            core,
            "entry::shade",
            &layout,
            std::mem::size_of::<ShadeParams>() as u32,
            core.workgroup_sizes.shade,
            &[(bindings::shade::RESIDUAL_CODE_SPEC_ID, u32::from(residual))],
        )
    }

    /// The pipeline for a pass with `params`.
    fn for_params(&mut self, core: &Arc<Core>, params: &ShadeParams) -> Result<&ComputeKernel> {
        if params.analytic_residual == 0 {
            return Ok(&self.without_residual);
        }
        Ok(match &mut self.with_residual {
            Some(kernel) => kernel,
            none => none.insert(Self::build(core, true)?),
        })
    }
}

impl VulkanBackend {
    /// Opens Vulkan device `index` and builds its pipelines (but the shade stage's with the
    /// residual towards GGX, built at the first pass that asks for it: `ShadeKernels`). `trace`
    /// picks the trace method; `None` takes ray query where the device has it, else the
    /// ray-tracing pipeline, else software traversal. A method the device lacks is
    /// [`Error::MissingFeatures`].
    pub fn open(index: usize, options: &ContextOptions, trace: Option<TraceMethod>) -> Result<Self> {
        let core = open(index, options)?;
        // Declared after `core`, so released before a failed open drops it.
        let _driver = driver_lock::device_use();
        let missing = |method: TraceMethod| core.info.missing_for(method);
        let trace_method = trace.unwrap_or_else(|| {
            [TraceMethod::RayQuery, TraceMethod::RtPipeline]
                .into_iter()
                .find(|&m| missing(m).is_empty())
                .unwrap_or(TraceMethod::Software)
        });
        if !missing(trace_method).is_empty() {
            return Err(Error::MissingFeatures {
                device: core.info.name.clone(),
                stage: format!("trace ({})", trace_method.name()),
                missing: missing(trace_method),
            });
        }
        let storage = vk::DescriptorType::STORAGE_BUFFER;
        let generate = ComputeKernel::new(
            &core,
            "entry::generate",
            &[
                (bindings::generate::RAY_ORIGIN, storage),
                (bindings::generate::RAY_DIRECTION, storage),
                (bindings::generate::RAY_PIXEL, storage),
            ],
            std::mem::size_of::<GenerateParams>() as u32,
            core.workgroup_sizes.generate,
        )?;
        let probe_layout = [(bindings::probe::SAMPLES, storage)];
        let sampler_probe = ComputeKernel::new(
            &core,
            "entry::sampler_probe",
            &probe_layout,
            std::mem::size_of::<SamplerProbeParams>() as u32,
            core.workgroup_sizes.generate,
        )?;
        let warp_push = std::mem::size_of::<WarpParams>() as u32;
        let warp_probe =
            ComputeKernel::new(&core, "entry::warp_probe", &probe_layout, warp_push, core.workgroup_sizes.generate)?;
        let shade_kernels = ShadeKernels::new(&core)?;
        let push = std::mem::size_of::<TraceParams>() as u32;
        let hit_layout = trace_bindings(trace_method, &HIT_OUTPUTS);
        let occlusion_layout = trace_bindings(trace_method, &OCCLUSION_OUTPUTS);
        let compute = |entry, layout: &[(u32, vk::DescriptorType)]| -> Result<TraceKernel> {
            Ok(TraceKernel::Compute(ComputeKernel::new(&core, entry, layout, push, core.workgroup_sizes.trace)?))
        };
        let rt = |shaders, layout: &[(u32, vk::DescriptorType)]| -> Result<TraceKernel> {
            Ok(TraceKernel::RtPipeline(Box::new(RtPipelineKernel::new(&core, shaders, layout, push)?)))
        };
        let (trace, occlusion) = match trace_method {
            TraceMethod::Software => {
                (compute("entry::trace_cwbvh", &hit_layout)?, compute("entry::occlusion_cwbvh", &occlusion_layout)?)
            }
            TraceMethod::RayQuery => (
                compute("entry::trace_ray_query", &hit_layout)?,
                compute("entry::occlusion_ray_query", &occlusion_layout)?,
            ),
            TraceMethod::RtPipeline => {
                (rt(&CLOSEST_HIT_SHADERS, &hit_layout)?, rt(&OCCLUSION_SHADERS, &occlusion_layout)?)
            }
        };
        Ok(Self {
            generate,
            sampler_probe,
            warp_probe,
            trace,
            occlusion,
            shade_kernels,
            denoise_kernels: DenoiseKernels::new(&core)?,
            trace_method,
            software_bvh: options.software_bvh,
            scene: None,
            shade_data: None,
            core,
        })
    }

    /// The obvhs preset of the CWBVH that software traversal builds for each scene it loads
    /// ([`ContextOptions::software_bvh`]).
    pub fn software_bvh(&self) -> crate::cpu::BvhQuality {
        self.software_bvh
    }

    /// The device's name and features.
    pub fn info(&self) -> &DeviceInfo {
        &self.core.info
    }

    /// The trace method this backend runs.
    pub fn trace_method(&self) -> TraceMethod {
        self.trace_method
    }

    /// Invocations per workgroup of each 1-D stream stage ([`ContextOptions::workgroup_sizes`]).
    pub fn workgroup_sizes(&self) -> WorkgroupSizes {
        self.core.workgroup_sizes
    }

    /// Validation-layer messages of warning or error severity received so far (empty unless
    /// opened with validation, and empty when all is well). [`Backend::validation_log`] outlives
    /// the backend: read after dropping it, it holds the messages of its teardown too.
    pub fn validation_messages(&self) -> Vec<String> {
        self.core.validation_log().messages()
    }

    /// Largest stream this device can hold in one storage buffer and cover with one dispatch.
    fn max_rays(&self) -> u64 {
        self.core.info.max_stream_len(self.core.workgroup_sizes.smallest())
    }

    /// The generate stage's checks on this device: the image size, then the camera's parameters.
    fn check_generate(&self, params: &GenerateParams) -> Result<()> {
        self.check_image_size(params.width, params.height)?;
        check_generate_params(params)
    }

    /// The scene the trace kernels read, if one is loaded.
    fn loaded_scene(&self) -> Result<&DeviceScene> {
        loaded(&self.scene).map(|(scene, _)| scene)
    }

    /// The length of a stream of `len` elements of input `name` (rays, hits, an image's pixels)
    /// if it fits one storage buffer and one dispatch (in workgroups of the smallest stage size:
    /// if those fit, every stage's do), else a typed error naming the input and the limit.
    fn check_stream(&self, len: usize, name: &'static str) -> Result<u32> {
        let workgroup = self.core.workgroup_sizes.smallest();
        let fits = |len: &u32| {
            dispatch_grid(&self.core.limits, *len, workgroup).is_some() && u64::from(*len) <= self.max_rays()
        };
        u32::try_from(len).ok().filter(fits).ok_or_else(|| Error::InvalidParameter {
            name,
            reason: format!("{len} elements exceed the device's {} per stream", self.max_rays()),
        })
    }
}

/// The loaded scene and its identity, or an error naming the stage that needs it. A function of
/// the backend's `scene` field, not a method, so that the scene may be borrowed beside the shade
/// data (`lit_sample`).
fn loaded(scene: &Option<(DeviceScene, SceneIdentity)>) -> Result<(&DeviceScene, &SceneIdentity)> {
    scene
        .as_ref()
        .map(|(scene, identity)| (scene, identity))
        .ok_or(Error::InvalidParameter { name: "scene", reason: "trace needs a loaded scene".into() })
}

/// The shade data in `loaded` — `data`'s, uploaded unless the buffers already hold it; the old
/// buffers are freed before the new ones are allocated. A function of the backend's fields, not
/// a method, so that the data it returns borrows `loaded` alone.
fn load_shade_data<'a>(
    core: &Arc<Core>,
    loaded: &'a mut Option<DeviceShadeData>,
    data: &ShadeData,
) -> Result<&'a DeviceShadeData> {
    let current = match loaded.take() {
        Some(current) if current.identity == data.identity() => current,
        old => {
            drop(old);
            DeviceShadeData::upload(core, data)?
        }
    };
    Ok(loaded.insert(current))
}

/// A stage's run in a batch, and the read of its sanitized counter where it has one.
struct StageRun {
    stage: &'static str,
    run: RunId,
    sanitized: Option<ReadId<u32>>,
}

impl StageRun {
    /// The stage's report, once its batch has completed.
    fn report(&self, done: &Done) -> Result<StageReport> {
        let sanitized = match &self.sanitized {
            Some(read) => done.count(read)?,
            None => 0,
        };
        Ok(done.timing(self.run).report(self.stage, sanitized))
    }
}

/// Adds the generate stage over `params` (checked by the caller, [`VulkanBackend::check_generate`])
/// to `batch`, writing `rays`.
fn add_generate<'a>(
    batch: &mut Batch<'a>,
    kernel: &'a ComputeKernel,
    params: &GenerateParams,
    rays: &'a DeviceRays,
) -> Result<StageRun> {
    let resources = [&rays.paths.origin, &rays.paths.direction, &rays.pixel].map(Resource::Buffer);
    let run = kernel.add_to(batch, &resources, bytemuck::bytes_of(params), rays.paths.len)?;
    Ok(StageRun { stage: "generate", run, sanitized: None })
}

/// Adds trace `kernel` over `rays` (checked against the device, [`VulkanBackend::check_stream`])
/// in `scene` to `batch`, with `outputs` bound after the rays (layout of [`trace_bindings`]) and
/// its sanitized count in `counter`; it reports as `stage`.
fn add_trace<'a>(
    batch: &mut Batch<'a>,
    stage: &'static str,
    kernel: &'a TraceKernel,
    scene: &'a DeviceScene,
    rays: &'a DevicePaths,
    outputs: &[&'a GpuBuffer],
    counter: &'a GpuBuffer,
) -> Result<StageRun> {
    let (scene_resource, triangles) = match scene {
        DeviceScene::Accelerated(accel) => (Resource::AccelerationStructure(accel.tlas.handle), vec![]),
        DeviceScene::Software(software) => (
            Resource::Buffer(&software.nodes),
            vec![Resource::Buffer(&software.vertices), Resource::Buffer(&software.ids)],
        ),
    };
    let resources: Vec<Resource> = [scene_resource, Resource::Buffer(&rays.origin), Resource::Buffer(&rays.direction)]
        .into_iter()
        .chain(outputs.iter().map(|b| Resource::Buffer(b)))
        .chain(triangles)
        .chain([Resource::Buffer(counter)])
        .collect();
    let params = TraceParams { ray_count: rays.len, padding: [0; 3] };
    let push = bytemuck::bytes_of(&params);
    let run = match kernel {
        TraceKernel::Compute(kernel) => kernel.add_to(batch, &resources, push, rays.len),
        TraceKernel::RtPipeline(kernel) => kernel.add_to(batch, &resources, push, rays.len),
    }?;
    Ok(StageRun { stage, run, sanitized: Some(batch.read(counter, 1)?) })
}

/// Adds the shade stage `kernel` over `hits.len` camera rays whose directions `direction` holds,
/// against the shade data `scene` on the device, to `batch`: it writes `out`, and its sanitized
/// count to `counter`.
#[allow(clippy::too_many_arguments)]
fn add_shade<'a>(
    batch: &mut Batch<'a>,
    kernel: &'a ComputeKernel,
    scene: &'a DeviceShadeData,
    params: &ShadeParams,
    direction: &'a GpuBuffer,
    hits: &'a DeviceHits,
    out: &'a DeviceShades,
    counter: &'a GpuBuffer,
) -> Result<StageRun> {
    let resources = [
        direction,
        &hits.t,
        &hits.primitive,
        &hits.instance,
        &hits.barycentrics,
        &scene.triangles,
        &scene.first_triangle,
        &scene.materials,
        &scene.lights,
        &scene.light_nodes,
        &scene.light_trails,
        &scene.ltc,
        &out.analytic,
        &out.unshadowed,
        &out.emitted,
        &out.shadow.origin,
        &out.shadow.direction,
        counter,
    ]
    .map(Resource::Buffer);
    let run = kernel.add_to(batch, &resources, bytemuck::bytes_of(params), hits.len)?;
    Ok(StageRun { stage: "shade", run, sanitized: Some(batch.read(counter, 1)?) })
}

/// The shade stage `kernel` over the camera rays `rays` and their `hits`, `len` of each (checked
/// against the device, [`VulkanBackend::check_stream`]), against the shade data `scene` on the
/// device: the uploads of the rays' directions and the hits, the pass and the read of its
/// stream in one batch. A function of the backend's fields, not a method, so that `scene` may
/// borrow the backend's shade data.
fn shade_on_device(
    core: &Arc<Core>,
    kernel: &ComputeKernel,
    scene: &DeviceShadeData,
    params: &ShadeParams,
    (rays, hits, len): (&RayStream, &HitStream, u32),
) -> Result<(ShadeStream, StageReport)> {
    let direction = GpuBuffer::storage::<Vec4>(core, len, "ray direction")?;
    let device_hits = DeviceHits::new(core, len)?;
    let out = DeviceShades::new(core, len)?;
    let counter = GpuBuffer::counter(core, "shade")?;
    let mut batch = Batch::new(core);
    batch.upload(&direction, &rays.direction)?;
    device_hits.upload_in(&mut batch, hits)?;
    let (direction, hits) = (&direction, &device_hits);
    let shade = add_shade(&mut batch, kernel, scene, params, direction, hits, &out, &counter)?;
    let reads = out.read_in(&mut batch)?;
    let done = batch.submit()?;
    Ok((reads.stream(&done)?, shade.report(&done)?))
}

impl Backend for VulkanBackend {
    fn name(&self) -> String {
        format!("vulkan:{} {} (trace: {})", self.core.info.index, self.core.info.name, self.trace_method.name())
    }

    fn check_image_size(&self, width: u32, height: u32) -> Result<()> {
        check_image_size_common(width, height, self.max_rays(), &self.name())
    }

    /// Measured on a device in host memory (`CPU`, as lavapipe is), streams and device buffers
    /// included: [`SOFTWARE_DEVICE_LIT_FRAME_BYTES_PER_PIXEL`]; on a GPU, not measured, a lower
    /// bound: [`crate::lit_frame::HOST_LIT_FRAME_BYTES_PER_PIXEL`].
    fn lit_frame_bytes_per_pixel(&self) -> Option<u64> {
        Some(lit_frame_bytes_per_pixel_on(&self.core.info.device_type))
    }

    fn set_sustain_seconds(&mut self, seconds: f64) -> Result<()> {
        self.core.set_sustain_seconds(seconds)
    }

    fn load_scene(&mut self, scene: &Scene) -> Result<()> {
        // Everything that can refuse the scene on the host runs first, so that a refused scene
        // leaves the loaded one in place (as on the CPU backend), and outside the driver lock
        // (`driver_lock::debug_assert_unheld`: the software BVH's build may take seconds). Then
        // the old scene's device memory is freed before the new one's is allocated: a failure
        // from here on (device memory) leaves no scene loaded.
        let software = match self.trace_method {
            TraceMethod::RayQuery | TraceMethod::RtPipeline => {
                check_limits(scene, &self.core.accel_limits, &self.core.info.name)?;
                None
            }
            TraceMethod::Software => {
                let cpu = CpuScene::build_with(scene, self.software_bvh)?;
                for (bytes, what) in [
                    (std::mem::size_of_val(cpu.nodes()), "cwbvh nodes"),
                    (std::mem::size_of_val(cpu.vertices()), "cwbvh vertices"),
                    (std::mem::size_of_val(cpu.ids()), "cwbvh triangle ids"),
                ] {
                    // `input_buffer` checks each again, as it does every input it uploads.
                    check_storage_range(&self.core.limits, bytes as u64, "scene", what)?;
                }
                Some(cpu)
            }
        };
        let _driver = driver_lock::device_use();
        self.scene = None;
        let device_scene = match software {
            None => DeviceScene::Accelerated(build_scene(&self.core, scene)?),
            Some(cpu) => DeviceScene::Software(Box::new(SoftwareScene {
                nodes: input_buffer(&self.core, cpu.nodes(), "cwbvh nodes")?,
                vertices: input_buffer(&self.core, cpu.vertices(), "cwbvh vertices")?,
                ids: input_buffer(&self.core, cpu.ids(), "cwbvh triangle ids")?,
            })),
        };
        self.scene = Some((device_scene, scene.identity().clone()));
        Ok(())
    }

    fn generate(&mut self, params: &GenerateParams) -> Result<(RayStream, StageReport)> {
        let _driver = driver_lock::device_use();
        self.check_generate(params)?;
        let rays = DeviceRays::new(&self.core, params.ray_count())?;
        let mut batch = Batch::new(&self.core);
        let generate = add_generate(&mut batch, &self.generate, params, &rays)?;
        let reads = rays.read_in(&mut batch)?;
        let done = batch.submit()?;
        Ok((reads.stream(&done)?, generate.report(&done)?))
    }

    fn trace(&mut self, rays: &RayStream) -> Result<(HitStream, StageReport)> {
        let _driver = driver_lock::device_use();
        rays.check("trace")?;
        let scene = self.loaded_scene()?;
        let paths = DevicePaths::new(&self.core, self.check_stream(rays.len(), "rays")?)?;
        let hits = DeviceHits::new(&self.core, paths.len)?;
        let counter = GpuBuffer::counter(&self.core, "trace")?;
        let mut batch = Batch::new(&self.core);
        paths.upload_in(&mut batch, rays)?;
        let trace = add_trace(&mut batch, "trace", &self.trace, scene, &paths, &hits.outputs(), &counter)?;
        let reads = hits.read_in(&mut batch)?;
        let done = batch.submit()?;
        Ok((reads.stream(&done)?, trace.report(&done)?))
    }

    fn trace_occlusion(&mut self, rays: &RayStream) -> Result<(Vec<u32>, StageReport)> {
        let _driver = driver_lock::device_use();
        rays.check("trace_occlusion")?;
        let scene = self.loaded_scene()?;
        let paths = DevicePaths::new(&self.core, self.check_stream(rays.len(), "rays")?)?;
        let occluded = GpuBuffer::storage::<u32>(&self.core, paths.len, "occluded")?;
        let counter = GpuBuffer::counter(&self.core, "occlusion")?;
        let mut batch = Batch::new(&self.core);
        paths.upload_in(&mut batch, rays)?;
        let occlusion = add_trace(&mut batch, "occlusion", &self.occlusion, scene, &paths, &[&occluded], &counter)?;
        let read = batch.read(&occluded, rays.len())?;
        let done = batch.submit()?;
        Ok((done.read(&read)?, occlusion.report(&done)?))
    }

    fn shade(
        &mut self,
        params: &ShadeParams,
        data: &ShadeData,
        rays: &RayStream,
        hits: &HitStream,
    ) -> Result<(ShadeStream, StageReport)> {
        // The checks before the driver lock: the dense-stream check is a rayon scan
        // (`driver_lock::debug_assert_unheld`).
        let loaded = self.scene.as_ref().map(|(_, identity)| identity);
        check_shade_inputs(params, data, loaded, rays, hits)?;
        let len = self.check_stream(hits.len(), "hits")?;
        let _driver = driver_lock::device_use();
        let core = &self.core;
        let kernel = self.shade_kernels.for_params(core, params)?;
        let scene = load_shade_data(core, &mut self.shade_data, data)?;
        shade_on_device(core, kernel, scene, params, (rays, hits, len))
    }

    /// The lit sample with every stream on the device, from the camera rays to the occlusion
    /// results, in one submission where the device writes timestamps (`vulkan/batch.rs`): what
    /// comes back is the three accumulated shade fields, the occlusion results and the hits'
    /// primitives (to count the hits), 56 bytes a pixel, and the camera streams when asked (the
    /// composed stages move 208): all of them in the same submission, or, for the listed pixels
    /// that hit ([`CameraStreams::HitsAmong`]), their records only, 56 bytes each, gathered in a
    /// second one once the hits' primitives show which those are. The checks of the composed
    /// stages, in their order and before any work: the request, the scene loaded, the camera, the
    /// shade data and parameters for the dense stream generate writes.
    fn lit_sample(&mut self, request: &LitSampleRequest<'_>) -> Result<LitSample> {
        let _driver = driver_lock::device_use();
        request.check()?;
        let (scene, identity) = loaded(&self.scene)?;
        self.check_generate(request.generate)?;
        request.data.check_scene(Some(identity))?;
        request.data.check()?;
        check_shade_params(request.shade, request.data, request.generate.ray_count() as usize)?;
        // The shade pipeline the pass needs, built (the residual's, at its first pass) before
        // any work, so that a failure to build it leaves none done.
        let core = &self.core;
        let kernel = self.shade_kernels.for_params(core, request.shade)?;
        let data = load_shade_data(core, &mut self.shade_data, request.data)?;
        let len = request.generate.ray_count();
        let rays = DeviceRays::new(core, len)?;
        let hits = DeviceHits::new(core, len)?;
        let shades = DeviceShades::new(core, len)?;
        let occluded = GpuBuffer::storage::<u32>(core, len, "occluded")?;
        let counters = [
            GpuBuffer::counter(core, "trace")?,
            GpuBuffer::counter(core, "shade")?,
            GpuBuffer::counter(core, "occlusion")?,
        ];
        let mut batch = Batch::new(core);
        let generate = add_generate(&mut batch, &self.generate, request.generate, &rays)?;
        // check_generate checked the image against max_rays: the stream fits every pass.
        let trace = add_trace(&mut batch, "trace", &self.trace, scene, &rays.paths, &hits.outputs(), &counters[0])?;
        let direction = &rays.paths.direction;
        let shade = add_shade(&mut batch, kernel, data, request.shade, direction, &hits, &shades, &counters[1])?;
        let occlusion =
            add_trace(&mut batch, "occlusion", &self.occlusion, scene, &shades.shadow, &[&occluded], &counters[2])?;
        let n = len as usize;
        let analytic = batch.read(&shades.analytic, n)?;
        let unshadowed = batch.read(&shades.unshadowed, n)?;
        let emitted = batch.read(&shades.emitted, n)?;
        let occlusion_read = batch.read(&occluded, n)?;
        // The hits' primitives, to count the hits (read twice where the camera streams are).
        let primitive = batch.read::<u32>(&hits.primitive, n)?;
        let camera_reads = match request.camera {
            CameraStreams::All => Some((rays.read_in(&mut batch)?, hits.read_in(&mut batch)?)),
            CameraStreams::None | CameraStreams::HitsAmong(_) => None,
        };
        let done = batch.submit()?;
        let primitives = done.read(&primitive)?;
        let camera = match (&camera_reads, request.camera) {
            (Some((rays, hits)), _) => Some((rays.stream(&done)?, hits.stream(&done)?)),
            // Which listed pixels hit is known now: their records are copied out in a second,
            // small submission while the streams are still on the device.
            (None, CameraStreams::HitsAmong(pixels)) => {
                Some(gather_camera_records(core, &rays, &hits, &hits_among(pixels, &primitives))?)
            }
            (None, _) => None,
        };
        let pixels = u64::from(len);
        Ok(LitSample {
            analytic: done.read(&analytic)?,
            unshadowed: done.read(&unshadowed)?,
            emitted: done.read(&emitted)?,
            occluded: done.read(&occlusion_read)?,
            hits: count_hits(&primitives),
            camera,
            camera_timings: vec![generate.report(&done)?, trace.report(&done)?],
            pass_timings: [shade.report(&done)?, occlusion.report(&done)?],
            // Camera rays, hits, the shade stream (with the shadow rays) and occlusion results.
            stream_bytes: pixels
                * u64::from(
                    RAY_STREAM_BYTES_PER_RAY + HIT_STREAM_BYTES_PER_RAY + SHADE_STREAM_BYTES_PER_RAY + u32::BITS / 8,
                ),
        })
    }

    fn render(&mut self, params: &GenerateParams) -> Result<FrameOutput> {
        let _driver = driver_lock::device_use();
        let scene = self.loaded_scene()?;
        self.check_generate(params)?;
        let len = params.ray_count();
        let rays = DeviceRays::new(&self.core, len)?;
        let hits = DeviceHits::new(&self.core, len)?;
        let counter = GpuBuffer::counter(&self.core, "trace")?;
        let mut batch = Batch::new(&self.core);
        let generate = add_generate(&mut batch, &self.generate, params, &rays)?;
        // check_generate checked the image against max_rays: the stream fits every pass.
        let trace = add_trace(&mut batch, "trace", &self.trace, scene, &rays.paths, &hits.outputs(), &counter)?;
        let (ray_reads, hit_reads) = (rays.read_in(&mut batch)?, hits.read_in(&mut batch)?);
        let done = batch.submit()?;
        Ok(FrameOutput {
            rays: ray_reads.stream(&done)?,
            hits: hit_reads.stream(&done)?,
            timings: vec![generate.report(&done)?, trace.report(&done)?],
        })
    }

    fn denoise(
        &mut self,
        method: DenoiseMethod,
        params: &DenoiseParams,
        input: &DenoiseInput,
    ) -> Result<(Vec<Vec4>, Vec<StageReport>)> {
        // The inputs' scan before the driver lock (`driver_lock::debug_assert_unheld`).
        input.check(params)?;
        self.check_stream(input.len(), "denoise")?;
        let _driver = driver_lock::device_use();
        self.denoise_kernels.run(&self.core, method, params, input)
    }

    fn copy_probe(&mut self, params: &DenoiseParams, image: &[Vec4]) -> Result<(Vec<Vec4>, StageReport)> {
        let _driver = driver_lock::device_use();
        self.check_stream(copy_probe_len(params, image)? as usize, "copy probe")?;
        self.denoise_kernels.copy_probe(&self.core, params, image)
    }

    fn sampler_probe(&mut self, params: &SamplerProbeParams) -> Result<Vec<UVec2>> {
        let _driver = driver_lock::device_use();
        let count = sampler_probe_len(params)?;
        let samples = probe_buffer::<UVec2>(&self.core, count, "sampler probe")?;
        probe(&self.core, &self.sampler_probe, &samples, bytemuck::bytes_of(params), count)
    }

    fn warp_probe(&mut self, params: &WarpParams) -> Result<Vec<Vec4>> {
        let _driver = driver_lock::device_use();
        let count = warp_probe_len(params)?;
        let samples = probe_buffer::<Vec4>(&self.core, count, "warp probe")?;
        probe(&self.core, &self.warp_probe, &samples, bytemuck::bytes_of(params), count)
    }

    fn release_kept_memory(&mut self) -> u64 {
        self.core.free_kept_buffers()
    }

    fn validation_log(&self) -> Option<crate::backend::ValidationLog> {
        Some(self.core.validation_log())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu::BvhQuality;

    /// A device in host memory is held to its measured footprint, any other (a GPU, which CI has
    /// not) to the host buffers every lit frame keeps; none passes unchecked.
    #[test]
    fn a_lit_frame_on_any_vulkan_device_is_held_to_host_memory() {
        assert_eq!(lit_frame_bytes_per_pixel_on("CPU"), SOFTWARE_DEVICE_LIT_FRAME_BYTES_PER_PIXEL);
        for gpu in ["DISCRETE_GPU", "INTEGRATED_GPU", "VIRTUAL_GPU", "OTHER"] {
            assert_eq!(lit_frame_bytes_per_pixel_on(gpu), crate::lit_frame::HOST_LIT_FRAME_BYTES_PER_PIXEL, "{gpu}");
        }
    }

    /// Specialized without the residual ([`ShadeKernels`]), the shade pipeline reads
    /// `analytic_residual` as 0: asked for the residual, it shades as the pass without it, bit
    /// for bit, while the backend's pass with the residual differs (a glossy Cornell box, whose
    /// `U_S` the residual changes). So the constant reaches the kernel and the backend picks the
    /// pipeline by the flag. Every Vulkan device; without one it fails under CI and is skipped
    /// loudly elsewhere.
    #[test]
    fn the_shade_pipeline_specialized_without_the_residual_ignores_its_flag() {
        let devices = super::super::devices_for_test("shade specialization");
        let scene = Scene::load("builtin:cornell").unwrap();
        let mut data = ShadeData::new(&scene).unwrap();
        for material in &mut data.materials {
            material.base_color_roughness.w = 0.3;
            material.emission_metallic.w = 1.0;
        }
        let generate = crate::frame::generate_params(&scene, 24, 16, 1);
        let without = data.params(generate.sampler, 24, 16, 0);
        let with = ShadeParams { analytic_residual: 1, ..without };
        for device in &devices {
            let options = ContextOptions { validation: true, ..Default::default() };
            let mut backend = VulkanBackend::open(device.index, &options, None).unwrap();
            backend.load_scene(&scene).unwrap();
            let frame = backend.render(&generate).unwrap();
            let (plain, _) = backend.shade(&without, &data, &frame.rays, &frame.hits).unwrap();
            let (residual, _) = backend.shade(&with, &data, &frame.rays, &frame.hits).unwrap();
            let core = &backend.core;
            let on_device = load_shade_data(core, &mut backend.shade_data, &data).unwrap();
            let kernel = &backend.shade_kernels.without_residual;
            let streams = (&frame.rays, &frame.hits, frame.hits.len() as u32);
            let (forced, _) = shade_on_device(core, kernel, on_device, &with, streams).unwrap();
            assert!(forced.analytic == plain.analytic && forced.unshadowed == plain.unshadowed, "{}", device.name);
            assert!(residual.analytic != plain.analytic, "{}: the residual changes U", device.name);
            let messages = backend.validation_messages();
            assert!(messages.is_empty(), "{}: {messages:?}", device.name);
        }
    }

    /// Software traversal uploads the tree of the preset it was opened with
    /// ([`ContextOptions::software_bvh`]): node for node the CPU's tree of that preset (the
    /// Vulkan backend had always built the default, under `bench trace --bvh slow` too). Needs a
    /// Vulkan device; without one it fails under CI (`CI=true` or `1`, as the integration tests
    /// read it) and is skipped loudly elsewhere.
    #[test]
    fn software_traversal_uploads_the_preset_it_was_opened_with() {
        let devices = super::super::enumerate_devices();
        let Some(device) = devices.as_ref().ok().and_then(|devices| devices.first()) else {
            assert!(!crate::in_ci(), "CI=true requires a Vulkan device: {devices:?}");
            eprintln!("\n*** SKIP software BVH preset: no Vulkan device ({devices:?}) ***\n");
            return;
        };
        let scene = Scene::load("builtin:spheres").unwrap();
        let nodes_of = |quality| CpuScene::build_with(&scene, quality).unwrap().nodes().to_vec();
        assert_ne!(nodes_of(BvhQuality::Fast).len(), nodes_of(BvhQuality::Slow).len(), "the presets differ");
        for quality in [BvhQuality::Fast, BvhQuality::Slow] {
            let options = ContextOptions { software_bvh: quality, validation: true, ..Default::default() };
            let mut backend = VulkanBackend::open(device.index, &options, Some(TraceMethod::Software)).unwrap();
            assert_eq!(backend.software_bvh(), quality);
            backend.load_scene(&scene).unwrap();
            let Some((DeviceScene::Software(software), _)) = &backend.scene else { panic!("a software scene") };
            let nodes = &software.nodes;
            let expected = nodes_of(quality);
            let uploaded: Vec<raywave_shared::bvh::CwBvhNode> = nodes.read(expected.len()).unwrap();
            assert!(uploaded == expected, "{quality:?}: the uploaded nodes are not the preset's tree");
            let messages = backend.validation_messages();
            assert!(messages.is_empty(), "{}: {messages:?}", device.name);
        }
    }

    /// A lit sample is one submission where the device writes timestamps — the four passes,
    /// their counters and the readbacks in one command buffer — and one per pass plus one for
    /// the copies where it does not ([`Batch::submit`]); it had been fifteen. Counted from the
    /// second sample, after the first has uploaded the shade data. Listed pixels' camera records
    /// take one submission more where some of them hit; none where none is listed, or none of
    /// those listed hit (no records come back then). Every Vulkan device; without one it fails
    /// under CI and is skipped loudly elsewhere.
    #[test]
    fn a_lit_sample_is_one_submission_where_the_device_writes_timestamps() {
        let devices = super::super::devices_for_test("lit sample submissions");
        let scene = Scene::load("builtin:cornell").unwrap();
        let data = ShadeData::new(&scene).unwrap();
        for device in &devices {
            let options = ContextOptions { validation: true, ..Default::default() };
            let mut backend = VulkanBackend::open(device.index, &options, None).unwrap();
            backend.load_scene(&scene).unwrap();
            let mut submissions = Vec::new();
            // Pixels the fifth sample's rays miss (the box's edges leave some).
            let fifth = backend.render(&crate::frame::generate_params(&scene, 24, 16, 4)).unwrap();
            let misses: Vec<u32> =
                (0..24 * 16).filter(|&i| fifth.hits.primitive[i as usize] == raywave_shared::stream::NO_HIT).collect();
            assert!(!misses.is_empty(), "{}", device.name);
            let cameras = [
                CameraStreams::All,
                CameraStreams::None,
                CameraStreams::HitsAmong(&[3, 4, 5, 200]),
                CameraStreams::HitsAmong(&[]),
                CameraStreams::HitsAmong(&misses),
            ];
            let mut records = Vec::new();
            for (seed, camera) in (0..).zip(cameras) {
                let generate = crate::frame::generate_params(&scene, 24, 16, seed);
                let shade = data.params(generate.sampler, 24, 16, generate.sample_index);
                let request = LitSampleRequest { generate: &generate, shade: &shade, data: &data, camera };
                let before = backend.core.submissions.load(std::sync::atomic::Ordering::Relaxed);
                let sample = backend.lit_sample(&request).unwrap();
                submissions.push(backend.core.submissions.load(std::sync::atomic::Ordering::Relaxed) - before);
                records.push(sample.camera.map(|(rays, hits)| (rays.len(), hits.len())));
                assert!(sample.hits > 0 && sample.occluded.len() == 24 * 16, "{}", device.name);
            }
            let (one, all) = (if backend.core.info.timestamps { 1 } else { 5 }, 24 * 16);
            assert_eq!(submissions[1..], [one, one + 1, one, one], "{}: submissions of each sample", device.name);
            let gathered = records[2].map_or(0, |(rays, _)| rays);
            assert!((1..=4).contains(&gathered), "{}: {records:?}", device.name);
            let expected = [Some((all, all)), None, Some((gathered, gathered)), Some((0, 0)), Some((0, 0))];
            assert_eq!(records, expected, "{}: camera records", device.name);
            let messages = backend.validation_messages();
            assert!(messages.is_empty(), "{}: {messages:?}", device.name);
        }
    }

    /// Transient buffers are kept and reused ([`super::super::recycle::Recycler`]): after a lit
    /// sample, one of the same size creates no buffer — it takes every one the sample before it
    /// left — and, with every kept buffer filled with ones first, it reads back, bit for bit,
    /// what the same sample reads on a backend that had run nothing, camera streams included: no
    /// stale contents reach a result. No buffer is in use after a sample, the kept bytes stay
    /// within their bound, and the backend's teardown, which frees the kept buffers, leaves the
    /// validation layers nothing to report. Every Vulkan device; without one it fails under CI
    /// and is skipped loudly elsewhere.
    #[test]
    fn a_lit_sample_reuses_the_buffers_of_the_one_before_and_reads_none_of_their_contents() {
        use super::super::recycle::KEPT_PEAKS;
        let devices = super::super::devices_for_test("lit sample buffer reuse");
        let scene = Scene::load("builtin:cornell").unwrap();
        let data = ShadeData::new(&scene).unwrap();
        let (width, height) = (24, 16);
        let sample = |backend: &mut VulkanBackend, seed| {
            let generate = crate::frame::generate_params(&scene, width, height, seed);
            let shade = data.params(generate.sampler, width, height, generate.sample_index);
            let request =
                LitSampleRequest { generate: &generate, shade: &shade, data: &data, camera: CameraStreams::All };
            let sample = backend.lit_sample(&request).unwrap();
            let (rays, hits) = sample.camera.unwrap();
            // Compared as bits, so that any NaN compares too.
            fn bits<T: Pod>(values: &[T]) -> Vec<u8> {
                bytemuck::cast_slice(values).to_vec()
            }
            vec![
                bits(&sample.analytic),
                bits(&sample.unshadowed),
                bits(&sample.emitted),
                bits(&sample.occluded),
                bits(&rays.origin),
                bits(&rays.direction),
                bits(&rays.pixel),
                bits(&hits.t),
                bits(&hits.primitive),
                bits(&hits.instance),
                bits(&hits.barycentrics),
            ]
        };
        for device in &devices {
            let options = ContextOptions { validation: true, ..Default::default() };
            let open = || {
                let mut backend = VulkanBackend::open(device.index, &options, None).unwrap();
                backend.load_scene(&scene).unwrap();
                backend
            };
            let mut backend = open();
            sample(&mut backend, 0);
            let first = backend.core.recycler.counts();
            assert!(first.created > 0 && first.kept > 0, "{}: {first:?}", device.name);
            super::super::buffer::fill_kept_with_ones(&backend.core);
            let second = sample(&mut backend, 1);
            let after = backend.core.recycler.counts();
            assert_eq!(after.created, first.created, "{}: the second sample created buffers", device.name);
            assert!(after.reused > first.reused && after.live_bytes == 0, "{}: {after:?}", device.name);
            assert!(after.kept_bytes <= KEPT_PEAKS * after.peak_live_bytes, "{}: {after:?}", device.name);
            let fresh = sample(&mut open(), 1);
            assert!(second == fresh, "{}: a reused buffer's contents reached the second sample", device.name);
            let log = backend.core.validation_log();
            drop(backend);
            let messages = log.messages();
            assert!(messages.is_empty(), "{}: {messages:?}", device.name);
        }
    }

    /// `release_kept_memory` frees what the calls before kept — the allocator's bytes fall by at
    /// least the bytes it returns — and the next sample makes every buffer afresh, as the first
    /// did, with the same values. Validation on, teardown included. Every Vulkan device; without
    /// one it fails under CI and is skipped loudly elsewhere.
    #[test]
    fn released_kept_memory_is_freed_and_the_next_sample_makes_its_buffers_afresh() {
        let devices = super::super::devices_for_test("releasing kept buffers");
        let scene = Scene::load("builtin:cornell").unwrap();
        let data = ShadeData::new(&scene).unwrap();
        let (width, height) = (24, 16);
        let generate = crate::frame::generate_params(&scene, width, height, 0);
        let shade = data.params(generate.sampler, width, height, generate.sample_index);
        let request = LitSampleRequest { generate: &generate, shade: &shade, data: &data, camera: CameraStreams::None };
        for device in &devices {
            let options = ContextOptions { validation: true, ..Default::default() };
            let mut backend = VulkanBackend::open(device.index, &options, None).unwrap();
            backend.load_scene(&scene).unwrap();
            let allocated = |backend: &VulkanBackend| {
                backend.core.allocator.lock().unwrap().generate_report().total_allocated_bytes
            };
            let first = backend.lit_sample(&request).unwrap();
            let kept = backend.core.recycler.counts();
            let before = allocated(&backend);
            let released = backend.release_kept_memory();
            assert!(released > 0 && released == kept.kept_bytes, "{}: {released} of {kept:?}", device.name);
            let after = allocated(&backend);
            assert!(after + released <= before, "{}: {before} → {after} bytes, {released} released", device.name);
            let empty = backend.core.recycler.counts();
            assert_eq!((empty.kept, empty.kept_bytes), (0, 0), "{}", device.name);
            assert_eq!(backend.release_kept_memory(), 0, "{}: nothing left to release", device.name);
            let second = backend.lit_sample(&request).unwrap();
            let made = backend.core.recycler.counts();
            assert_eq!(made.created, 2 * kept.created, "{}: {made:?} after {kept:?}", device.name);
            assert_eq!(made.reused, kept.reused, "{}: {made:?} after {kept:?}", device.name);
            assert!(
                second.analytic == first.analytic && second.occluded == first.occluded,
                "{}: the same sample again differs",
                device.name
            );
            let log = backend.core.validation_log();
            drop(backend);
            let messages = log.messages();
            assert!(messages.is_empty(), "{}: {messages:?}", device.name);
        }
    }

    /// A realtime loop — frames of a lit sample with camera streams, one without and a denoise,
    /// TV or SVGF — creates buffers in its first frame only: every later frame takes all it
    /// needs from those kept ([`super::super::recycle::KEPT_PEAKS`] leaves room for the sample's
    /// and the denoise's distinct buffers), with no buffer in use between frames. Every Vulkan
    /// device; without one it fails under CI and is skipped loudly elsewhere.
    #[test]
    fn a_frame_loop_creates_buffers_in_its_first_frame_only() {
        use crate::lit_frame::{render_lit, LitFrameSettings};
        let devices = super::super::devices_for_test("frame loop buffer reuse");
        let scene = Scene::load("builtin:cornell").unwrap();
        let data = ShadeData::new(&scene).unwrap();
        for device in &devices {
            for denoise in [crate::denoise::DenoiseMethod::Tv, crate::denoise::DenoiseMethod::Svgf] {
                let options = ContextOptions { validation: true, ..Default::default() };
                let mut backend = VulkanBackend::open(device.index, &options, None).unwrap();
                backend.load_scene(&scene).unwrap();
                let mut created = Vec::new();
                for seed in 0..4 {
                    let settings = LitFrameSettings { seed, denoise, ..LitFrameSettings::new(40, 24, 2) };
                    render_lit(&mut backend, &scene, &data, &settings).unwrap();
                    let counts = backend.core.recycler.counts();
                    assert_eq!(counts.live_bytes, 0, "{} {denoise:?}: {counts:?}", device.name);
                    created.push(counts.created);
                }
                assert!(created.iter().all(|&c| c == created[0]), "{} {denoise:?}: {created:?}", device.name);
                let messages = backend.validation_messages();
                assert!(messages.is_empty(), "{}: {messages:?}", device.name);
            }
        }
    }

    /// A batch submitted as one submission for the uploads, one per run and one for the reads (the
    /// path of a device without timestamps and of benchmark mode, which CI's lavapipe does not
    /// take by itself) reads back what one submission does, bit for bit, with the same reports —
    /// the sanitized counts 0 though the batch uploaded `u32::MAX` to the counter before the
    /// trace zeroed it; a gather reads the records it names; an upload, a read or a gather past a
    /// buffer's end is refused, and a second upload to one buffer (the uploads run without
    /// barriers between them). Every Vulkan device; without one it fails under CI and is skipped
    /// loudly elsewhere.
    #[test]
    fn a_batch_split_into_a_submission_per_run_reads_what_one_submission_reads() {
        let devices = super::super::devices_for_test("batch submissions");
        let scene = Scene::load("builtin:cornell").unwrap();
        let params = crate::frame::generate_params(&scene, 24, 16, 3);
        const PICKED: [u32; 7] = [1, 2, 3, 7, 40, 41, 24 * 16 - 1];
        for device in &devices {
            let options = ContextOptions { validation: true, ..Default::default() };
            let mut backend = VulkanBackend::open(device.index, &options, None).unwrap();
            backend.load_scene(&scene).unwrap();
            let (core, scene_on_device) = (&backend.core, backend.loaded_scene().unwrap());
            let rays = DeviceRays::new(core, params.ray_count()).unwrap();
            let frame = |together: bool| {
                let hits = DeviceHits::new(core, params.ray_count()).unwrap();
                let counter = GpuBuffer::counter(core, "trace").unwrap();
                let mut batch = Batch::new(core);
                let past_the_end = batch.upload(&counter, &[0u32; 2]);
                assert!(
                    matches!(past_the_end, Err(Error::InvalidParameter { name: "data", reason }) if reason.contains("past the end"))
                );
                batch.upload(&counter, &[u32::MAX]).unwrap();
                let again = batch.upload(&counter, &[0u32]);
                assert!(
                    matches!(again, Err(Error::InvalidParameter { name: "data", reason }) if reason.contains("second upload"))
                );
                let generate = add_generate(&mut batch, &backend.generate, &params, &rays).unwrap();
                let outputs = hits.outputs();
                let trace =
                    add_trace(&mut batch, "trace", &backend.trace, scene_on_device, &rays.paths, &outputs, &counter)
                        .unwrap();
                let past_the_end = batch.read::<u32>(&counter, 2);
                assert!(matches!(past_the_end, Err(Error::InvalidParameter { name: "count", .. })));
                let gathered_past_the_end = batch.gather::<u32>(&counter, &[0, 1]);
                assert!(matches!(gathered_past_the_end, Err(Error::InvalidParameter { name: "indices", .. })));
                let (ray_reads, hit_reads) = (rays.read_in(&mut batch).unwrap(), hits.read_in(&mut batch).unwrap());
                let picked = Records::At(&PICKED);
                let (picked_rays, picked_hits) = (
                    rays.read_records_in(&mut batch, picked).unwrap(),
                    hits.read_records_in(&mut batch, picked).unwrap(),
                );
                let before = core.submissions.load(std::sync::atomic::Ordering::Relaxed);
                let done = batch.submit_in(together).unwrap();
                let submissions = core.submissions.load(std::sync::atomic::Ordering::Relaxed) - before;
                let reports = [generate.report(&done).unwrap(), trace.report(&done).unwrap()];
                let streams = (ray_reads.stream(&done).unwrap(), hit_reads.stream(&done).unwrap());
                let gathered = (picked_rays.stream(&done).unwrap(), picked_hits.stream(&done).unwrap());
                (streams.0, streams.1, reports, submissions, gathered)
            };
            let (rays_read, hits, reports, submissions, gathered) = frame(true);
            let (split_rays, split_hits, split_reports, split_submissions, _) = frame(false);
            // A gather reads the records at the indices given, in their order: runs and single
            // records, the last one the stream's.
            assert!(gathered == (rays_read.select(&PICKED), hits.select(&PICKED)), "{}: gathered", device.name);
            let together = if core.info.timestamps { 1 } else { 4 };
            assert_eq!((submissions, split_submissions), (together, 4), "{}", device.name);
            assert!(
                rays_read == split_rays && hits == split_hits,
                "{}: the split batch read other streams",
                device.name
            );
            assert!(hits.hit_count() > 0, "{}: the camera sees the box", device.name);
            for (one, split) in reports.iter().zip(&split_reports) {
                assert_eq!(
                    (one.stage, one.dispatches, one.sanitized, split.sanitized),
                    (split.stage, split.dispatches, 0, 0)
                );
                assert!(one.seconds > 0.0 && split.seconds > 0.0, "{}: {one:?} {split:?}", device.name);
            }
            let messages = backend.validation_messages();
            assert!(messages.is_empty(), "{}: {messages:?}", device.name);
        }
    }
}
