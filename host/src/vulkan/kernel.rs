//! Compute pipelines built from the embedded SPIR-V: one per entry point, dispatched as a 2-D grid
//! of 1-D workgroups.

use super::context::{vk_error, Core};
use super::pass::{Pass, Resource, Timing};
use crate::error::{Error, Result};
use ash::vk;
use raywave_shared::bindings::WORKGROUP_SIZE;
use std::sync::Arc;

/// A compute pipeline for one entry point.
pub(crate) struct ComputeKernel {
    pass: Pass,
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
        let stages = vk::ShaderStageFlags::COMPUTE;
        let mut pass = Pass::new(core, entry, vk::PipelineBindPoint::COMPUTE, stages, bindings, push_constant_bytes)?;
        let module = pass.shader_module(entry)?;
        let name = std::ffi::CString::new(entry)
            .map_err(|_| Error::InvalidParameter { name: "entry", reason: entry.into() })?;
        let stage = vk::PipelineShaderStageCreateInfo::default().stage(stages).module(module).name(&name);
        // SAFETY: the create info borrows live locals; the module is destroyed after creation.
        let created = unsafe {
            let created = core.device.create_compute_pipelines(
                vk::PipelineCache::null(),
                &[vk::ComputePipelineCreateInfo::default().stage(stage).layout(pass.pipeline_layout)],
                None,
            );
            core.device.destroy_shader_module(module, None);
            created
        };
        pass.pipeline = created.map_err(|(_, e)| vk_error("vkCreateComputePipelines")(e))?[0];
        Ok(Self { pass })
    }

    /// Binds `resources` (one per binding, in creation order), pushes `push`, runs `invocations`
    /// invocations and waits ([`Pass::run`]: repeated in benchmark mode); returns the time per
    /// dispatch.
    pub fn dispatch(&self, resources: &[Resource<'_>], push: &[u8], invocations: u32) -> Result<Timing> {
        let (groups_x, groups_y) =
            dispatch_grid(&self.pass.core.limits, invocations).ok_or_else(|| Error::InvalidParameter {
                name: "invocations",
                reason: format!("{invocations} exceed the device's dispatch limits"),
            })?;
        let device = &self.pass.core.device;
        self.pass.run(resources, push, invocations, |cmd| {
            if groups_x > 0 {
                // SAFETY: `cmd` is recording with this pass's pipeline and set bound.
                unsafe { device.cmd_dispatch(cmd, groups_x, groups_y, 1) };
            }
        })
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
