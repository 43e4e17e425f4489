//! The trace stage through `VK_KHR_ray_tracing_pipeline`, for GPUs that expose ray-tracing
//! pipelines but not ray query (e.g. NVIDIA's data-center parts): a raygen shader reads the ray
//! stream, one miss and one triangle hit group fill the payload, the shader binding table holds
//! the three group handles.

use super::batch::{Batch, RunId};
use super::buffer::GpuBuffer;
use super::context::{vk_error, Core};
use super::pass::{Pass, Resource};
use crate::error::{Error, Result};
use ash::vk;
use std::sync::Arc;

/// The shaders of one ray-tracing pipeline: groups are raygen, miss and a triangle hit group
/// (whose closest-hit shader may be absent, as for occlusion rays).
pub(crate) struct RtShaders {
    pub raygen: &'static std::ffi::CStr,
    pub miss: &'static std::ffi::CStr,
    pub closest_hit: Option<&'static std::ffi::CStr>,
}

/// The closest-hit trace: records the hit in the payload.
pub(crate) const CLOSEST_HIT_SHADERS: RtShaders = RtShaders {
    raygen: c"entry::trace_raygen",
    miss: c"entry::trace_miss",
    closest_hit: Some(c"entry::trace_closest_hit"),
};

/// The occlusion trace: stops at the first hit, only the miss shader runs.
pub(crate) const OCCLUSION_SHADERS: RtShaders =
    RtShaders { raygen: c"entry::occlusion_raygen", miss: c"entry::occlusion_miss", closest_hit: None };

/// Widest launch row: rays are laid out as rows of this many launches (a 2-D launch).
const LAUNCH_WIDTH: u32 = 4096;

/// A ray-tracing pipeline with its shader binding table.
pub(crate) struct RtPipelineKernel {
    pass: Pass,
    /// The device's `VK_KHR_ray_tracing_pipeline` functions, which record the launch.
    loader: ash::khr::ray_tracing_pipeline::Device,
    _sbt: GpuBuffer,
    raygen: vk::StridedDeviceAddressRegionKHR,
    miss: vk::StridedDeviceAddressRegionKHR,
    hit: vk::StridedDeviceAddressRegionKHR,
}

impl RtPipelineKernel {
    /// Builds the pipeline (descriptor set 0 = `bindings`, `push_constant_bytes` of push
    /// constants, both visible to the raygen shader) and its shader binding table.
    pub fn new(
        core: &Arc<Core>,
        shaders: &RtShaders,
        bindings: &[(u32, vk::DescriptorType)],
        push_constant_bytes: u32,
    ) -> Result<Self> {
        let loader = core.ray_tracing_pipeline.as_ref().ok_or_else(|| Error::MissingFeatures {
            device: core.info.name.clone(),
            stage: "trace (rtpipe)".into(),
            missing: core.info.missing_for_rt_pipeline(),
        })?;
        let stages = vk::ShaderStageFlags::RAYGEN_KHR;
        let name = if shaders.closest_hit.is_some() { "trace_raygen" } else { "occlusion_raygen" };
        let mut pass =
            Pass::new(core, name, vk::PipelineBindPoint::RAY_TRACING_KHR, stages, bindings, push_constant_bytes)?;
        let mut entries =
            vec![(vk::ShaderStageFlags::RAYGEN_KHR, shaders.raygen), (vk::ShaderStageFlags::MISS_KHR, shaders.miss)];
        if let Some(closest_hit) = shaders.closest_hit {
            entries.push((vk::ShaderStageFlags::CLOSEST_HIT_KHR, closest_hit));
        }
        let mut modules = Vec::new();
        for (_, entry) in &entries {
            // The names are ASCII literals, so `to_string_lossy` is exact.
            match pass.shader_module(&entry.to_string_lossy(), None) {
                Ok(m) => modules.push(m),
                Err(e) => {
                    destroy_modules(core, &modules);
                    return Err(e);
                }
            }
        }
        let stage_infos: Vec<_> = entries
            .iter()
            .zip(&modules)
            .map(|(&(kind, name), &module)| {
                vk::PipelineShaderStageCreateInfo::default().stage(kind).module(module).name(name)
            })
            .collect();
        let general = |shader: u32| {
            vk::RayTracingShaderGroupCreateInfoKHR::default()
                .ty(vk::RayTracingShaderGroupTypeKHR::GENERAL)
                .general_shader(shader)
                .closest_hit_shader(vk::SHADER_UNUSED_KHR)
                .any_hit_shader(vk::SHADER_UNUSED_KHR)
                .intersection_shader(vk::SHADER_UNUSED_KHR)
        };
        let groups = [
            general(0),
            general(1),
            vk::RayTracingShaderGroupCreateInfoKHR::default()
                .ty(vk::RayTracingShaderGroupTypeKHR::TRIANGLES_HIT_GROUP)
                .general_shader(vk::SHADER_UNUSED_KHR)
                .closest_hit_shader(if shaders.closest_hit.is_some() { 2 } else { vk::SHADER_UNUSED_KHR })
                .any_hit_shader(vk::SHADER_UNUSED_KHR)
                .intersection_shader(vk::SHADER_UNUSED_KHR),
        ];
        let info = vk::RayTracingPipelineCreateInfoKHR::default()
            .stages(&stage_infos)
            .groups(&groups)
            .max_pipeline_ray_recursion_depth(1)
            .layout(pass.pipeline_layout);
        // SAFETY: the create info borrows live locals; the modules are destroyed after creation.
        let created = unsafe {
            loader.create_ray_tracing_pipelines(
                vk::DeferredOperationKHR::null(),
                vk::PipelineCache::null(),
                &[info],
                None,
            )
        };
        destroy_modules(core, &modules);
        pass.pipeline = created.map_err(|(_, e)| vk_error("vkCreateRayTracingPipelinesKHR")(e))?[0];

        // Shader binding table: one record per group, each region starting on the base alignment.
        let props = core.rt_properties;
        let handle_size = props.handle_size as usize;
        // SAFETY: the pipeline has 3 groups; the data size is 3 handles.
        let handles = unsafe { loader.get_ray_tracing_shader_group_handles(pass.pipeline, 0, 3, 3 * handle_size) }
            .map_err(vk_error("vkGetRayTracingShaderGroupHandlesKHR"))?;
        let stride = u64::from(props.handle_size.next_multiple_of(props.handle_alignment.max(1)));
        let region = stride.next_multiple_of(u64::from(props.base_alignment.max(1)));
        let alignment = u64::from(props.base_alignment.max(1));
        // Device-local like every buffer the device reads per ray (see `GpuBuffer::device_local`).
        let size = 3 * region + alignment;
        let sbt = GpuBuffer::device_local(
            core,
            size,
            vk::BufferUsageFlags::SHADER_BINDING_TABLE_KHR | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            "shader binding table",
        )?;
        let base = sbt.address.next_multiple_of(alignment);
        let mut table = vec![0u8; size as usize];
        for group in 0..3usize {
            let at = (base - sbt.address + group as u64 * region) as usize;
            table[at..at + handle_size].copy_from_slice(&handles[group * handle_size..(group + 1) * handle_size]);
        }
        sbt.upload(&table)?;
        let record = |group: u64, size: u64| {
            vk::StridedDeviceAddressRegionKHR::default().device_address(base + group * region).stride(stride).size(size)
        };
        let (raygen, miss, hit) = (record(0, stride), record(1, stride), record(2, stride));
        Ok(Self { loader: loader.clone(), raygen, miss, hit, _sbt: sbt, pass })
    }

    /// Adds to `batch` a trace of `rays` rays (raygen launch `min(rays, LAUNCH_WIDTH)` wide) over
    /// `resources` with push constants `push` ([`Batch::add`]: repeated in benchmark mode).
    pub fn add_to<'a>(
        &'a self,
        batch: &mut Batch<'a>,
        resources: &[Resource<'a>],
        push: &[u8],
        rays: u32,
    ) -> Result<RunId> {
        let core = &self.pass.core;
        // The launch is a whole number of LAUNCH_WIDTH-wide rows: its invocations, not the rays,
        // must fit the limit (VUID-vkCmdTraceRaysKHR-width-03641).
        let (width, height) = (rays.min(LAUNCH_WIDTH), rays.div_ceil(LAUNCH_WIDTH));
        let invocations = u64::from(width) * u64::from(height);
        if invocations > u64::from(core.rt_properties.max_dispatch_invocations) {
            return Err(Error::InvalidParameter {
                name: "rays",
                reason: format!(
                    "{rays} rays launch {invocations} invocations ({height} rows of {width}), more than \
                     maxRayDispatchInvocationCount {}",
                    core.rt_properties.max_dispatch_invocations
                ),
            });
        }
        let (loader, callable) = (&self.loader, vk::StridedDeviceAddressRegionKHR::default());
        batch.add(&self.pass, resources, push, rays, move |cmd| {
            if rays > 0 {
                // SAFETY: `cmd` is recording with this pass's pipeline and set bound; the SBT
                // regions point into the live table buffer.
                unsafe { loader.cmd_trace_rays(cmd, &self.raygen, &self.miss, &self.hit, &callable, width, height, 1) };
            }
        })
    }
}

fn destroy_modules(core: &Core, modules: &[vk::ShaderModule]) {
    for &m in modules {
        // SAFETY: the modules are no longer referenced by any pipeline creation in flight.
        unsafe { core.device.destroy_shader_module(m, None) };
    }
}
