//! Compute pipelines built from the embedded SPIR-V: one per entry point, with a descriptor set
//! laid out from the shared binding numbers, push constants, and GPU timestamps per dispatch.

use super::buffer::{submit_and_wait, GpuBuffer};
use super::context::{vk_error, Core};
use crate::error::{Error, Result};
use ash::vk;
use raywave_shared::bindings::WORKGROUP_SIZE;
use std::sync::Arc;
use std::time::Instant;

/// A resource bound to one binding of a kernel's descriptor set.
pub(crate) enum Resource<'a> {
    /// A storage buffer.
    Buffer(&'a GpuBuffer),
    /// A top-level acceleration structure.
    AccelerationStructure(vk::AccelerationStructureKHR),
}

/// A compute pipeline and the objects it needs to dispatch; destroyed on drop.
pub(crate) struct ComputeKernel {
    core: Arc<Core>,
    entry: &'static str,
    set_layout: vk::DescriptorSetLayout,
    pipeline_layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
    descriptor_pool: vk::DescriptorPool,
    descriptor_set: vk::DescriptorSet,
    query_pool: vk::QueryPool,
    bindings: Vec<(u32, vk::DescriptorType)>,
}

impl Drop for ComputeKernel {
    fn drop(&mut self) {
        // SAFETY: the device is idle after every submission; these objects are owned by `self`.
        unsafe {
            let d = &self.core.device;
            d.destroy_query_pool(self.query_pool, None);
            d.destroy_descriptor_pool(self.descriptor_pool, None);
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.pipeline_layout, None);
            d.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

impl ComputeKernel {
    /// Builds the pipeline of SPIR-V entry point `entry` with descriptor set 0 laid out as
    /// `bindings` and `push_constant_bytes` of push constants.
    pub fn new(
        core: &Arc<Core>,
        entry: &'static str,
        bindings: &[(u32, vk::DescriptorType)],
        push_constant_bytes: u32,
    ) -> Result<Self> {
        let spirv = super::spirv::module(entry)?;
        let code = ash::util::read_spv(&mut std::io::Cursor::new(spirv))
            .map_err(|e| Error::Vulkan { call: "read_spv", result: format!("{entry}: {e}") })?;
        let d = &core.device;
        // Every object below is stored in `kernel` as soon as it exists, so Drop cleans up on error.
        let mut kernel = Self {
            core: core.clone(),
            entry,
            set_layout: vk::DescriptorSetLayout::null(),
            pipeline_layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            descriptor_pool: vk::DescriptorPool::null(),
            descriptor_set: vk::DescriptorSet::null(),
            query_pool: vk::QueryPool::null(),
            bindings: bindings.to_vec(),
        };
        let layout_bindings: Vec<_> = bindings
            .iter()
            .map(|&(binding, ty)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(binding)
                    .descriptor_type(ty)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        // SAFETY: all create infos borrow locals that outlive the calls; created objects are
        // recorded in `kernel` and destroyed by its Drop.
        unsafe {
            kernel.set_layout = d
                .create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&layout_bindings),
                    None,
                )
                .map_err(vk_error("vkCreateDescriptorSetLayout"))?;
            let set_layouts = [kernel.set_layout];
            let push_ranges =
                [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::COMPUTE).size(push_constant_bytes)];
            kernel.pipeline_layout = d
                .create_pipeline_layout(
                    &vk::PipelineLayoutCreateInfo::default()
                        .set_layouts(&set_layouts)
                        .push_constant_ranges(&push_ranges),
                    None,
                )
                .map_err(vk_error("vkCreatePipelineLayout"))?;
            let module = d
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&code), None)
                .map_err(vk_error("vkCreateShaderModule"))?;
            let name = std::ffi::CString::new(entry)
                .map_err(|_| Error::InvalidParameter { name: "entry", reason: entry.into() })?;
            let stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(module)
                .name(&name);
            let created = d.create_compute_pipelines(
                vk::PipelineCache::null(),
                &[vk::ComputePipelineCreateInfo::default().stage(stage).layout(kernel.pipeline_layout)],
                None,
            );
            d.destroy_shader_module(module, None);
            kernel.pipeline = created.map_err(|(_, e)| vk_error("vkCreateComputePipelines")(e))?[0];

            let mut pool_sizes: Vec<vk::DescriptorPoolSize> = Vec::new();
            for &(_, ty) in bindings {
                match pool_sizes.iter_mut().find(|s| s.ty == ty) {
                    Some(s) => s.descriptor_count += 1,
                    None => pool_sizes.push(vk::DescriptorPoolSize { ty, descriptor_count: 1 }),
                }
            }
            kernel.descriptor_pool = d
                .create_descriptor_pool(
                    &vk::DescriptorPoolCreateInfo::default().max_sets(1).pool_sizes(&pool_sizes),
                    None,
                )
                .map_err(vk_error("vkCreateDescriptorPool"))?;
            kernel.descriptor_set = d
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default()
                        .descriptor_pool(kernel.descriptor_pool)
                        .set_layouts(&set_layouts),
                )
                .map_err(vk_error("vkAllocateDescriptorSets"))?[0];
            kernel.query_pool = d
                .create_query_pool(
                    &vk::QueryPoolCreateInfo::default().query_type(vk::QueryType::TIMESTAMP).query_count(2),
                    None,
                )
                .map_err(vk_error("vkCreateQueryPool"))?;
        }
        Ok(kernel)
    }

    /// Binds `resources` (one per binding, in the order given at creation), pushes `push`, runs
    /// `invocations` invocations and waits. Returns the dispatch's duration in seconds, from GPU
    /// timestamps where the device has them, else from the host clock around the submission.
    pub fn dispatch(&self, resources: &[Resource<'_>], push: &[u8], invocations: u32) -> Result<f64> {
        if resources.len() != self.bindings.len() {
            return Err(Error::InvalidParameter {
                name: "resources",
                reason: format!("{} takes {} bindings", self.entry, self.bindings.len()),
            });
        }
        let (groups_x, groups_y) =
            dispatch_grid(&self.core.limits, invocations).ok_or_else(|| Error::InvalidParameter {
                name: "invocations",
                reason: format!("{invocations} exceed the device's dispatch limits"),
            })?;
        let d = &self.core.device;
        let buffer_infos: Vec<[vk::DescriptorBufferInfo; 1]> = resources
            .iter()
            .map(|r| match r {
                Resource::Buffer(b) => [vk::DescriptorBufferInfo::default().buffer(b.buffer).range(vk::WHOLE_SIZE)],
                Resource::AccelerationStructure(_) => [vk::DescriptorBufferInfo::default()],
            })
            .collect();
        let accels: Vec<[vk::AccelerationStructureKHR; 1]> = resources
            .iter()
            .map(|r| match r {
                Resource::AccelerationStructure(a) => [*a],
                Resource::Buffer(_) => [vk::AccelerationStructureKHR::null()],
            })
            .collect();
        let mut accel_writes: Vec<vk::WriteDescriptorSetAccelerationStructureKHR> = accels
            .iter()
            .map(|a| vk::WriteDescriptorSetAccelerationStructureKHR::default().acceleration_structures(a))
            .collect();
        let writes: Vec<vk::WriteDescriptorSet> = resources
            .iter()
            .zip(&self.bindings)
            .zip(buffer_infos.iter().zip(accel_writes.iter_mut()))
            .map(|((resource, &(binding, ty)), (buffer_info, accel_write))| {
                let write = vk::WriteDescriptorSet::default()
                    .dst_set(self.descriptor_set)
                    .dst_binding(binding)
                    .descriptor_type(ty);
                match resource {
                    Resource::Buffer(_) => write.buffer_info(buffer_info),
                    Resource::AccelerationStructure(_) => write.descriptor_count(1).push_next(accel_write),
                }
            })
            .collect();
        // SAFETY: the set is not in use (every dispatch waits for completion) and the writes
        // reference live resources.
        unsafe { d.update_descriptor_sets(&writes, &[]) };
        let start = Instant::now();
        submit_and_wait(&self.core, |cmd| {
            // SAFETY: `cmd` is recording; pipeline, layout, set and query pool are live.
            unsafe {
                d.cmd_reset_query_pool(cmd, self.query_pool, 0, 2);
                d.cmd_write_timestamp(cmd, vk::PipelineStageFlags::TOP_OF_PIPE, self.query_pool, 0);
                d.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.pipeline);
                d.cmd_bind_descriptor_sets(
                    cmd,
                    vk::PipelineBindPoint::COMPUTE,
                    self.pipeline_layout,
                    0,
                    &[self.descriptor_set],
                    &[],
                );
                d.cmd_push_constants(cmd, self.pipeline_layout, vk::ShaderStageFlags::COMPUTE, 0, push);
                if groups_x > 0 {
                    d.cmd_dispatch(cmd, groups_x, groups_y, 1);
                }
                d.cmd_write_timestamp(cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, self.query_pool, 1);
            }
        })?;
        let host_seconds = start.elapsed().as_secs_f64();
        if !self.core.info.timestamps {
            return Ok(host_seconds);
        }
        let mut stamps = [0u64; 2];
        // SAFETY: both queries were written by the completed submission.
        unsafe {
            d.get_query_pool_results(
                self.query_pool,
                0,
                &mut stamps,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .map_err(vk_error("vkGetQueryPoolResults"))?;
        let ticks = stamps[1].wrapping_sub(stamps[0]);
        Ok(ticks as f64 * f64::from(self.core.limits.timestamp_period) * 1e-9)
    }
}

/// Workgroup grid `(x, y)` covering `invocations` with rows of at most
/// `maxComputeWorkGroupCount[0]` workgroups, or `None` if even that exceeds the y limit.
pub(crate) fn dispatch_grid(limits: &vk::PhysicalDeviceLimits, invocations: u32) -> Option<(u32, u32)> {
    let groups = invocations.div_ceil(WORKGROUP_SIZE);
    if groups == 0 {
        return Some((0, 0));
    }
    let x = groups.min(limits.max_compute_work_group_count[0]);
    let y = groups.div_ceil(x);
    (y <= limits.max_compute_work_group_count[1]).then_some((x, y))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_spills_into_y_only_past_the_x_limit() {
        let limits = vk::PhysicalDeviceLimits { max_compute_work_group_count: [100, 10, 1], ..Default::default() };
        assert_eq!(dispatch_grid(&limits, 0), Some((0, 0)));
        assert_eq!(dispatch_grid(&limits, 1), Some((1, 1)));
        assert_eq!(dispatch_grid(&limits, 64 * 100), Some((100, 1)));
        assert_eq!(dispatch_grid(&limits, 64 * 100 + 1), Some((100, 2)));
        assert_eq!(dispatch_grid(&limits, 64 * 1000), Some((100, 10)));
        assert_eq!(dispatch_grid(&limits, 64 * 1000 + 1), None);
    }
}
