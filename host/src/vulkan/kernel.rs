//! Compute pipelines built from the embedded SPIR-V: one per entry point, dispatched as a 2-D grid
//! of 1-D workgroups of the size the pipeline was built with.

use super::batch::{Batch, RunId};
use super::context::{vk_error, Core};
use super::pass::{Pass, Resource};
use crate::error::{Error, Result};
use ash::vk;
use raywave_shared::bindings::STREAM_ROW;
use std::sync::Arc;

/// A compute pipeline for one entry point.
pub(crate) struct ComputeKernel {
    pass: Pass,
    /// Invocations per workgroup.
    workgroup_size: u32,
}

impl ComputeKernel {
    /// Builds the pipeline of SPIR-V entry point `entry` with descriptor set 0 laid out as
    /// `bindings`, `push_constant_bytes` of push constants and workgroups of `workgroup_size`
    /// invocations (a size other than the compiled `WORKGROUP_SIZE` only for stages indexed by
    /// `raywave_shared::bindings::stream_index`, already checked against the device by [`super::context::open`]).
    pub fn new(
        core: &Arc<Core>,
        entry: &'static str,
        bindings: &[(u32, vk::DescriptorType)],
        push_constant_bytes: u32,
        workgroup_size: u32,
    ) -> Result<Self> {
        Self::specialized(core, entry, bindings, push_constant_bytes, workgroup_size, &[])
    }

    /// [`Self::new`] with the `u32` specialization constants `constants` (id, value) set.
    pub fn specialized(
        core: &Arc<Core>,
        entry: &'static str,
        bindings: &[(u32, vk::DescriptorType)],
        push_constant_bytes: u32,
        workgroup_size: u32,
        constants: &[(u32, u32)],
    ) -> Result<Self> {
        // Before anything is created, so that this error leaks nothing.
        let name = std::ffi::CString::new(entry).map_err(|_| Error::InvalidParameter {
            name: "entry",
            reason: format!("entry point name {entry:?} holds a NUL byte"),
        })?;
        let entries: Vec<vk::SpecializationMapEntry> = (0u32..)
            .zip(constants)
            .map(|(k, &(id, _))| vk::SpecializationMapEntry::default().constant_id(id).offset(4 * k).size(4))
            .collect();
        let values: Vec<u32> = constants.iter().map(|&(_, value)| value).collect();
        let specialization =
            vk::SpecializationInfo::default().map_entries(&entries).data(bytemuck::cast_slice(&values));
        let stages = vk::ShaderStageFlags::COMPUTE;
        let mut pass = Pass::new(core, entry, vk::PipelineBindPoint::COMPUTE, stages, bindings, push_constant_bytes)?;
        let module = pass.shader_module(entry, Some(workgroup_size))?;
        let mut stage = vk::PipelineShaderStageCreateInfo::default().stage(stages).module(module).name(&name);
        if !constants.is_empty() {
            stage = stage.specialization_info(&specialization);
        }
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
        Ok(Self { pass, workgroup_size })
    }

    /// Adds to `batch` a run over `resources` (one per binding, in creation order) with push
    /// constants `push` and `invocations` invocations ([`Batch::add`]: repeated in benchmark
    /// mode).
    pub fn add_to<'a>(
        &'a self,
        batch: &mut Batch<'a>,
        resources: &[Resource<'a>],
        push: &[u8],
        invocations: u32,
    ) -> Result<RunId> {
        let (groups_x, groups_y) =
            dispatch_grid(&self.pass.core.limits, invocations, self.workgroup_size).ok_or_else(|| {
                Error::InvalidParameter {
                    name: "invocations",
                    reason: format!("{invocations} exceed the device's dispatch limits"),
                }
            })?;
        let device = &self.pass.core.device;
        batch.add(&self.pass, resources, push, invocations, move |cmd| {
            if groups_x > 0 {
                // SAFETY: `cmd` is recording with this pass's pipeline and set bound.
                unsafe { device.cmd_dispatch(cmd, groups_x, groups_y, 1) };
            }
        })
    }

    /// How many runs of the kernel live batches have held at once, at most ([`Pass::prepare`]).
    #[cfg(test)]
    pub fn slot_count(&self) -> usize {
        self.pass.slot_count()
    }
}

/// Workgroup grid `(x, y)` covering `invocations` in workgroups of `workgroup_size`: one row
/// where `maxComputeWorkGroupCount[0]` workgroups suffice, else rows of exactly [`STREAM_ROW`]
/// invocations (`raywave_shared::bindings::stream_index`); `None` if that needs more rows than the y limit or more
/// workgroups per row than the x limit.
pub(crate) fn dispatch_grid(
    limits: &vk::PhysicalDeviceLimits,
    invocations: u32,
    workgroup_size: u32,
) -> Option<(u32, u32)> {
    let groups = invocations.div_ceil(workgroup_size);
    let [max_x, max_y, _] = limits.max_compute_work_group_count;
    if groups <= max_x {
        return Some(if groups == 0 { (0, 0) } else { (groups, 1) });
    }
    let y = invocations.div_ceil(STREAM_ROW);
    (stream_rows_fit(workgroup_size, max_x) && y <= max_y).then_some((STREAM_ROW / workgroup_size, y))
}

/// Whether a row of [`STREAM_ROW`] invocations is a whole number of workgroups of
/// `workgroup_size`, at least one and at most `max_x` (`maxComputeWorkGroupCount[0]`): a
/// workgroup wider than the row would make a row of 0 workgroups, a grid that runs nothing.
pub(crate) fn stream_rows_fit(workgroup_size: u32, max_x: u32) -> bool {
    STREAM_ROW.checked_div(workgroup_size).is_some_and(|row| (1..=max_x).contains(&row))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_spills_into_rows_of_stream_row_invocations_only_past_the_x_limit() {
        let limits = vk::PhysicalDeviceLimits { max_compute_work_group_count: [65_535, 3, 1], ..Default::default() };
        assert_eq!(dispatch_grid(&limits, 0, 64), Some((0, 0)));
        assert_eq!(dispatch_grid(&limits, 1, 64), Some((1, 1)));
        // One row holds 65 535 workgroups of 64, more than `STREAM_ROW` invocations.
        assert_eq!(dispatch_grid(&limits, 64 * 65_535, 64), Some((65_535, 1)));
        assert_eq!(dispatch_grid(&limits, 32 * 65_535 + 1, 32), Some((STREAM_ROW / 32, 2)));
        assert_eq!(dispatch_grid(&limits, 64 * 65_535 + 1, 64), None, "four rows");
        assert_eq!(dispatch_grid(&limits, 3 * STREAM_ROW, 16), None, "2^16 workgroups of 16 per row");
        let wide = vk::PhysicalDeviceLimits { max_compute_work_group_count: [u32::MAX, 65_535, 65_535], ..limits };
        assert_eq!(dispatch_grid(&wide, u32::MAX, 1), Some((u32::MAX, 1)));
        // A workgroup wider than a row has no rows: none of 0 workgroups that would run nothing.
        let narrow = vk::PhysicalDeviceLimits { max_compute_work_group_count: [1, 65_535, 1], ..limits };
        assert_eq!(dispatch_grid(&narrow, 3 * STREAM_ROW, 2 * STREAM_ROW), None);
        assert!(!stream_rows_fit(2 * STREAM_ROW, u32::MAX) && !stream_rows_fit(0, u32::MAX));
        assert!(stream_rows_fit(STREAM_ROW, 1) && !stream_rows_fit(STREAM_ROW / 2, 1));
    }

    #[test]
    fn every_invocation_of_a_multi_row_grid_has_its_own_stream_index() {
        // The rows cover the stream exactly once: index y · STREAM_ROW + x over the grid.
        let limits = vk::PhysicalDeviceLimits { max_compute_work_group_count: [4096, 65_535, 1], ..Default::default() };
        for size in [256, 512, 1024] {
            let invocations = 4096 * size + 1;
            let (x, y) = dispatch_grid(&limits, invocations, size).expect("fits");
            assert_eq!(x * size, STREAM_ROW, "rows of STREAM_ROW invocations");
            assert!((y - 1) * STREAM_ROW < invocations && invocations <= y * STREAM_ROW, "{invocations}: {y} rows");
            assert!(y > 1, "{invocations} invocations of {size}: one row");
        }
    }
}
