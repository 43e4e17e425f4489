//! What every raywave pipeline shares, compute or ray tracing: descriptor set 0 laid out from the
//! shared binding numbers, a push-constant range, and a timestamped run that repeats its work in
//! benchmark mode ([`super::ContextOptions::sustain_seconds`]), recorded into a submission that
//! [`super::batch::Batch`] makes.

use super::buffer::{global_barrier, GpuBuffer};
use super::context::{vk_error, Core, MAX_SUSTAINED_DISPATCHES};
use super::driver_lock;
use crate::backend::StageReport;
use crate::error::{Error, Result};
use ash::vk;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

/// What one run of a pass measured ([`Pass::timing`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Timing {
    /// Seconds per dispatch: the run's time over `dispatches`.
    pub seconds: f64,
    /// How many times the work ran back to back in the run.
    pub dispatches: u32,
}

impl Timing {
    /// The report of `stage` run with this timing, `sanitized` invocations replaced.
    pub fn report(self, stage: &'static str, sanitized: u64) -> StageReport {
        StageReport { stage, seconds: self.seconds, dispatches: self.dispatches, sanitized }
    }
}

/// How many dispatches keep a device busy for `sustain_seconds` when one takes `seconds` (1 when
/// that is not known yet, NaN): at least 1, at most [`MAX_SUSTAINED_DISPATCHES`].
fn sustained_dispatches(sustain_seconds: f64, seconds: f64) -> u32 {
    if seconds > 0.0 {
        (sustain_seconds / seconds).ceil().clamp(1.0, f64::from(MAX_SUSTAINED_DISPATCHES)) as u32
    } else {
        1
    }
}

/// Ticks from timestamp `start` to `end` of a counter of `valid_bits` bits, which wraps at
/// `2^valid_bits` (the bits above are undefined): the difference modulo that, so that a wrap
/// between the two stamps still gives the short time between them.
fn elapsed_ticks(start: u64, end: u64, valid_bits: u32) -> u64 {
    let ticks = end.wrapping_sub(start);
    if valid_bits < u64::BITS {
        ticks & ((1 << valid_bits) - 1)
    } else {
        ticks
    }
}

/// A resource bound to one binding of a pass's descriptor set.
#[derive(Clone, Copy)]
pub(crate) enum Resource<'a> {
    /// A storage buffer.
    Buffer(&'a GpuBuffer),
    /// A top-level acceleration structure.
    AccelerationStructure(vk::AccelerationStructureKHR),
}

/// A run of a pass, prepared ([`Pass::prepare`]) and not yet recorded: it holds one of the pass's
/// slots, whose descriptor set is written, until [`Pass::release`].
pub(crate) struct PreparedRun {
    /// The slot's index in the pass, its descriptor set and its two timestamp queries.
    slot: usize,
    descriptor_set: vk::DescriptorSet,
    query_pool: vk::QueryPool,
    /// How many times the work repeats back to back (benchmark mode), at least 1.
    dispatches: u32,
    /// Invocations of one repetition (at least 1), for the time per invocation.
    size: f64,
    /// The sanitized counters among the resources, zeroed before the last repetition.
    counters: Vec<vk::Buffer>,
    /// The push constants.
    push: Vec<u8>,
}

/// What one run of a pass needs of its own while it waits in a batch: a descriptor set (a second
/// run of the pass binds other buffers) and a pair of timestamp queries (it is timed on its own).
struct Slot {
    descriptor_pool: vk::DescriptorPool,
    descriptor_set: vk::DescriptorSet,
    query_pool: vk::QueryPool,
    /// Whether a prepared run holds the slot ([`Pass::prepare`], [`Pass::release`]).
    claimed: bool,
}

/// Destroys the objects of `slot` (null handles are ignored); its set goes with its pool.
fn destroy_slot(core: &Core, slot: &Slot) {
    // SAFETY: the device is idle after every submission and no run holds a destroyed slot: it is
    // destroyed with its pass, or by `Pass::new_slot` on an error, before it was ever published.
    unsafe {
        core.device.destroy_query_pool(slot.query_pool, None);
        core.device.destroy_descriptor_pool(slot.descriptor_pool, None);
    }
}

/// A pipeline with its layout and its slots (descriptor sets and timestamp queries, one per run
/// that a live batch holds); destroyed on drop.
pub(crate) struct Pass {
    pub core: Arc<Core>,
    /// Entry point(s), for error messages.
    pub name: &'static str,
    bind_point: vk::PipelineBindPoint,
    stages: vk::ShaderStageFlags,
    set_layout: vk::DescriptorSetLayout,
    pub pipeline_layout: vk::PipelineLayout,
    /// Set by the pipeline kind after creation; null until then.
    pub pipeline: vk::Pipeline,
    /// The descriptors of one set, to size each slot's pool.
    pool_sizes: Vec<vk::DescriptorPoolSize>,
    /// One per run that live batches held at once, at most: made when every slot is claimed,
    /// reused once released.
    slots: Mutex<Vec<Slot>>,
    bindings: Vec<(u32, vk::DescriptorType)>,
    /// Bytes of push constants the layout declares, which every run must push.
    push_constant_bytes: u32,
    /// Benchmark mode: the last run's seconds per dispatch per invocation (`f64` bits; NaN
    /// before the first), from which the next run, whatever its size, takes how many dispatches
    /// it repeats — so that a large call after a small one does not run for minutes.
    seconds_per_invocation: AtomicU64,
}

impl Drop for Pass {
    fn drop(&mut self) {
        if self.core.is_wedged() {
            // Leaked: a submission may still use the pipeline and its slots (`Core::wedge`).
            return;
        }
        let _driver = driver_lock::device_use();
        // SAFETY: the device is idle after every submission; these objects are owned by `self`
        // (null handles are ignored by the destroy calls).
        unsafe {
            let d = &self.core.device;
            let slots = self.slots.get_mut().unwrap_or_else(PoisonError::into_inner);
            for slot in slots.drain(..) {
                destroy_slot(&self.core, &slot);
            }
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.pipeline_layout, None);
            d.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

impl Pass {
    /// Creates the layout objects for descriptor set 0 = `bindings`, visible to `stages`, and
    /// `push_constant_bytes` of push constants. The caller then creates `pipeline`.
    pub fn new(
        core: &Arc<Core>,
        name: &'static str,
        bind_point: vk::PipelineBindPoint,
        stages: vk::ShaderStageFlags,
        bindings: &[(u32, vk::DescriptorType)],
        push_constant_bytes: u32,
    ) -> Result<Self> {
        let d = &core.device;
        let mut pool_sizes: Vec<vk::DescriptorPoolSize> = Vec::new();
        for &(_, ty) in bindings {
            match pool_sizes.iter_mut().find(|s| s.ty == ty) {
                Some(s) => s.descriptor_count += 1,
                None => pool_sizes.push(vk::DescriptorPoolSize { ty, descriptor_count: 1 }),
            }
        }
        // Every object is stored in `pass` as soon as it exists, so Drop cleans up on error.
        let mut pass = Self {
            core: core.clone(),
            name,
            bind_point,
            stages,
            set_layout: vk::DescriptorSetLayout::null(),
            pipeline_layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
            pool_sizes,
            slots: Mutex::new(Vec::new()),
            bindings: bindings.to_vec(),
            push_constant_bytes,
            seconds_per_invocation: AtomicU64::new(f64::NAN.to_bits()),
        };
        let layout_bindings: Vec<_> = bindings
            .iter()
            .map(|&(binding, ty)| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(binding)
                    .descriptor_type(ty)
                    .descriptor_count(1)
                    .stage_flags(stages)
            })
            .collect();
        // SAFETY: all create infos borrow locals that outlive the calls; created objects are
        // recorded in `pass` and destroyed by its Drop.
        unsafe {
            pass.set_layout = d
                .create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&layout_bindings),
                    None,
                )
                .map_err(vk_error("vkCreateDescriptorSetLayout"))?;
            let set_layouts = [pass.set_layout];
            let push_ranges = [vk::PushConstantRange::default().stage_flags(stages).size(push_constant_bytes)];
            pass.pipeline_layout = d
                .create_pipeline_layout(
                    &vk::PipelineLayoutCreateInfo::default()
                        .set_layouts(&set_layouts)
                        .push_constant_ranges(&push_ranges),
                    None,
                )
                .map_err(vk_error("vkCreatePipelineLayout"))?;
        }
        Ok(pass)
    }

    /// A new slot, claimed: a pool of one descriptor set laid out as the pass's set 0, the set,
    /// and a pool of two timestamp queries. On an error what was made is destroyed.
    fn new_slot(&self) -> Result<Slot> {
        let d = &self.core.device;
        let mut slot = Slot {
            descriptor_pool: vk::DescriptorPool::null(),
            descriptor_set: vk::DescriptorSet::null(),
            query_pool: vk::QueryPool::null(),
            claimed: true,
        };
        let set_layouts = [self.set_layout];
        // SAFETY: the create infos borrow locals that outlive the calls; what is created is
        // recorded in `slot`, destroyed here on an error and by the pass's Drop otherwise.
        let made = unsafe {
            (|| -> Result<()> {
                slot.descriptor_pool = d
                    .create_descriptor_pool(
                        &vk::DescriptorPoolCreateInfo::default().max_sets(1).pool_sizes(&self.pool_sizes),
                        None,
                    )
                    .map_err(vk_error("vkCreateDescriptorPool"))?;
                slot.descriptor_set = d
                    .allocate_descriptor_sets(
                        &vk::DescriptorSetAllocateInfo::default()
                            .descriptor_pool(slot.descriptor_pool)
                            .set_layouts(&set_layouts),
                    )
                    .map_err(vk_error("vkAllocateDescriptorSets"))?[0];
                slot.query_pool = d
                    .create_query_pool(
                        &vk::QueryPoolCreateInfo::default().query_type(vk::QueryType::TIMESTAMP).query_count(2),
                        None,
                    )
                    .map_err(vk_error("vkCreateQueryPool"))?;
                Ok(())
            })()
        };
        match made {
            Ok(()) => Ok(slot),
            Err(error) => {
                destroy_slot(&self.core, &slot);
                Err(error)
            }
        }
    }

    /// Claims a free slot for a run, making one where every slot is claimed: its index, its
    /// descriptor set and its query pool.
    fn claim(&self) -> Result<(usize, vk::DescriptorSet, vk::QueryPool)> {
        let mut slots = self.slots.lock().unwrap_or_else(PoisonError::into_inner);
        let index = match slots.iter().position(|slot| !slot.claimed) {
            Some(index) => index,
            None => {
                slots.push(self.new_slot()?);
                slots.len() - 1
            }
        };
        let slot = &mut slots[index];
        slot.claimed = true;
        Ok((index, slot.descriptor_set, slot.query_pool))
    }

    /// Releases the slot of `run`, a run of this pass, once its batch is done with it or
    /// dropped; taken by value, so that no run is released twice.
    pub fn release(&self, run: PreparedRun) {
        let mut slots = self.slots.lock().unwrap_or_else(PoisonError::into_inner);
        slots[run.slot].claimed = false;
    }

    /// How many slots the pass has made: the most runs of it that live batches held at once.
    #[cfg(test)]
    pub fn slot_count(&self) -> usize {
        self.slots.lock().unwrap_or_else(PoisonError::into_inner).len()
    }

    /// A shader module from the embedded SPIR-V of `entry`, for a compute entry point with
    /// workgroups of `local_size_x` invocations where given ([`super::spirv::words`]); the caller
    /// destroys it.
    pub fn shader_module(&self, entry: &str, local_size_x: Option<u32>) -> Result<vk::ShaderModule> {
        let code = super::spirv::words(entry, local_size_x)?;
        // SAFETY: `code` is a valid SPIR-V word stream that outlives the call.
        unsafe { self.core.device.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&code), None) }
            .map_err(vk_error("vkCreateShaderModule"))
    }

    /// Prepares a run of this pass over `resources` (one per binding, in creation order; every
    /// buffer device-local, so no kernel reads or writes host memory across the bus) with push
    /// constants `push` and `invocations` invocations: checks the resources, writes them to the
    /// descriptor set, and chooses how many times the work repeats — once, or in benchmark mode
    /// as many times as the last run's time per invocation says keep the device busy for
    /// [`Core::sustain_seconds`]. The run holds a slot of its own (descriptor set, timestamps)
    /// until the caller releases it ([`Self::release`]), so that runs of one pass can wait in
    /// one batch or several side by side. In benchmark mode a batch prepares all its runs before
    /// any is timed, so each takes its count from the pass's last timed run — a frame's earlier
    /// run of the same pass (TV's bilateral x before y) no longer informs a later one, and the
    /// first frame runs each once (a benchmark's warm-up frames set the counts).
    pub fn prepare(&self, resources: &[Resource<'_>], push: &[u8], invocations: u32) -> Result<PreparedRun> {
        if resources.len() != self.bindings.len() {
            return Err(Error::InvalidParameter {
                name: "resources",
                reason: format!("{} takes {} bindings", self.name, self.bindings.len()),
            });
        }
        // A resource of another kind than its binding's would write a descriptor without its
        // data, and pushed constants of another size leave the kernel reading undefined ones.
        let kind = |resource: &Resource<'_>| match resource {
            Resource::Buffer(_) => vk::DescriptorType::STORAGE_BUFFER,
            Resource::AccelerationStructure(_) => vk::DescriptorType::ACCELERATION_STRUCTURE_KHR,
        };
        if let Some((_, &(binding, ty))) = resources.iter().zip(&self.bindings).find(|(r, &(_, ty))| kind(r) != ty) {
            return Err(Error::InvalidParameter {
                name: "resources",
                reason: format!("{}: binding {binding} takes a {ty:?}, not the resource given", self.name),
            });
        }
        if push.len() != self.push_constant_bytes as usize {
            return Err(Error::InvalidParameter {
                name: "push",
                reason: format!(
                    "{}: {} bytes of push constants for a layout of {}",
                    self.name,
                    push.len(),
                    self.push_constant_bytes
                ),
            });
        }
        if let Some(k) = resources.iter().position(|r| matches!(r, Resource::Buffer(b) if !b.device_local)) {
            return Err(Error::InvalidParameter {
                name: "resources",
                reason: format!("{}: the buffer at binding {} is not device-local", self.name, self.bindings[k].0),
            });
        }
        let d = &self.core.device;
        // Nothing after the claim fails, so no error leaves a slot claimed.
        let (slot, descriptor_set, query_pool) = self.claim()?;
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
                let write =
                    vk::WriteDescriptorSet::default().dst_set(descriptor_set).dst_binding(binding).descriptor_type(ty);
                match resource {
                    Resource::Buffer(_) => write.buffer_info(buffer_info),
                    Resource::AccelerationStructure(_) => write.descriptor_count(1).push_next(accel_write),
                }
            })
            .collect();
        // SAFETY: the set is not in use (every submission is waited for, and the slot is this
        // run's alone, recorded after this write) and the writes reference live resources.
        unsafe { d.update_descriptor_sets(&writes, &[]) };
        let size = f64::from(invocations.max(1));
        let sustain_seconds = self.core.sustain_seconds();
        let dispatches = if sustain_seconds > 0.0 {
            let per_invocation = f64::from_bits(self.seconds_per_invocation.load(Ordering::Relaxed));
            sustained_dispatches(sustain_seconds, per_invocation * size)
        } else {
            1
        };
        let counters = resources
            .iter()
            .filter_map(|r| match r {
                Resource::Buffer(b) if b.is_counter => Some(b.buffer),
                _ => None,
            })
            .collect();
        Ok(PreparedRun { slot, descriptor_set, query_pool, dispatches, size, counters, push: push.to_vec() })
    }

    /// Records `run` into `cmd`: binds the pipeline and set, pushes the constants and records
    /// `work` (the run's dispatch) `run.dispatches` times, separated by barriers, with every
    /// counter among the resources zeroed before the last — between two timestamps where the
    /// device writes them ([`super::DeviceInfo::timestamps`]), which take in the zeroing only
    /// where it falls between repetitions (benchmark mode), as before batches.
    pub fn record(&self, cmd: vk::CommandBuffer, run: &PreparedRun, work: &dyn Fn(vk::CommandBuffer)) {
        let d = &self.core.device;
        let all = vk::PipelineStageFlags::ALL_COMMANDS;
        let zero_counters = || {
            for &counter in &run.counters {
                // SAFETY: `cmd` is recording; a live device-local counter (TRANSFER_DST usage) of
                // 4 bytes.
                unsafe { d.cmd_fill_buffer(cmd, counter, 0, vk::WHOLE_SIZE, 0) };
            }
            global_barrier(&self.core, cmd, all, all);
        };
        if run.dispatches == 1 && !run.counters.is_empty() {
            // Outside the timestamps: the time is the dispatch's alone.
            zero_counters();
        }
        // SAFETY: `cmd` is recording; pipeline, layout, set and query pool are live; the queue
        // family has timestamp valid bits wherever `timestamps`.
        unsafe {
            if self.core.info.timestamps {
                d.cmd_reset_query_pool(cmd, run.query_pool, 0, 2);
                d.cmd_write_timestamp(cmd, vk::PipelineStageFlags::TOP_OF_PIPE, run.query_pool, 0);
            }
            d.cmd_bind_pipeline(cmd, self.bind_point, self.pipeline);
            d.cmd_bind_descriptor_sets(cmd, self.bind_point, self.pipeline_layout, 0, &[run.descriptor_set], &[]);
            d.cmd_push_constants(cmd, self.pipeline_layout, self.stages, 0, &run.push);
        }
        for repetition in 0..run.dispatches {
            if repetition > 0 {
                // Each repetition writes what the last wrote: in order, as a frame's passes.
                global_barrier(&self.core, cmd, all, all);
            }
            if repetition > 0 && repetition + 1 == run.dispatches && !run.counters.is_empty() {
                // The counters count the last repetition alone, exactly one run's count.
                zero_counters();
            }
            work(cmd);
        }
        if self.core.info.timestamps {
            // SAFETY: as above.
            unsafe { d.cmd_write_timestamp(cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, run.query_pool, 1) };
        }
    }

    /// The time per dispatch of `run`, once its submission has completed: from the GPU
    /// timestamps where the device has them, else `host_seconds`, the host clock around a
    /// submission that held this run alone. Benchmark mode sizes the next run from it.
    pub fn timing(&self, run: &PreparedRun, host_seconds: f64) -> Result<Timing> {
        let seconds = if self.core.info.timestamps { self.gpu_seconds(run.query_pool)? } else { host_seconds };
        let timing = Timing { seconds: seconds / f64::from(run.dispatches), dispatches: run.dispatches };
        self.seconds_per_invocation.store((timing.seconds / run.size).to_bits(), Ordering::Relaxed);
        Ok(timing)
    }

    /// The time between the two timestamps in `query_pool` of the completed submission, in
    /// seconds (only where the device writes them, [`super::DeviceInfo::timestamps`]).
    fn gpu_seconds(&self, query_pool: vk::QueryPool) -> Result<f64> {
        let d = &self.core.device;
        let mut stamps = [0u64; 2];
        // SAFETY: both queries were written by the completed submission.
        unsafe {
            d.get_query_pool_results(
                query_pool,
                0,
                &mut stamps,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .map_err(vk_error("vkGetQueryPoolResults"))?;
        let ticks = elapsed_ticks(stamps[0], stamps[1], self.core.info.timestamp_valid_bits);
        Ok(ticks as f64 * f64::from(self.core.limits.timestamp_period) * 1e-9)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sustained_dispatches_fill_the_busy_time_within_their_bounds() {
        assert_eq!(sustained_dispatches(0.01, 0.001), 10);
        assert_eq!(sustained_dispatches(0.01, 0.003), 4);
        assert_eq!(sustained_dispatches(0.01, 0.02), 1);
        assert_eq!(sustained_dispatches(0.01, 1e-9), MAX_SUSTAINED_DISPATCHES);
        assert_eq!(sustained_dispatches(0.01, 0.0), 1);
        assert_eq!(sustained_dispatches(0.01, f64::NAN), 1);
    }

    /// A run is refused, by a typed error naming what is wrong, for a resource of another kind
    /// than its binding's or push constants of another size than the layout's, and prepared
    /// when both match. Every Vulkan device; without one it fails under CI and is skipped loudly
    /// elsewhere.
    #[test]
    fn a_run_of_mismatched_resources_or_push_constants_is_refused() {
        for (name, core) in super::super::validated_cores_for_test("pass preparation") {
            let storage = vk::DescriptorType::STORAGE_BUFFER;
            let stages = vk::ShaderStageFlags::COMPUTE;
            let pass =
                Pass::new(&core, "test", vk::PipelineBindPoint::COMPUTE, stages, &[(0, storage), (1, storage)], 16)
                    .unwrap();
            let buffer = GpuBuffer::storage::<u32>(&core, 4, "test").unwrap();
            let buffers = [Resource::Buffer(&buffer), Resource::Buffer(&buffer)];
            let refusal = |resources: &[Resource<'_>], push: &[u8]| match pass.prepare(resources, push, 1) {
                Err(Error::InvalidParameter { name, reason }) => format!("{name}: {reason}"),
                Err(other) => panic!("{}: {other}", name),
                Ok(run) => {
                    pass.release(run);
                    String::new()
                }
            };
            let accel = Resource::AccelerationStructure(vk::AccelerationStructureKHR::null());
            let mixed = refusal(&[buffers[0], accel], &[0; 16]);
            assert!(mixed.contains("resources: test: binding 1 takes a STORAGE_BUFFER"), "{}: {mixed}", name);
            for push in [&[0u8; 0][..], &[0; 8], &[0; 20]] {
                let message = refusal(&buffers, push);
                let expected = format!("push: test: {} bytes of push constants for a layout of 16", push.len());
                assert_eq!(message, expected, "{}", name);
            }
            assert_eq!(refusal(&buffers, &[0; 16]), "", "{}: matching resources and constants", name);
            let messages = core.validation_log().messages();
            assert!(messages.is_empty(), "{}: {messages:?}", name);
        }
    }

    #[test]
    fn elapsed_ticks_survive_a_wrap_of_a_narrow_counter() {
        assert_eq!(elapsed_ticks(10, 25, 64), 15);
        assert_eq!(elapsed_ticks(u64::MAX - 4, 10, 64), 15, "a 64-bit counter wraps at 2^64");
        assert_eq!(elapsed_ticks((1 << 36) - 5, 10, 36), 15, "not 2^64 − 2^36 + 15 ticks");
        assert_eq!(elapsed_ticks(10, 25, 36), 15);
        // Bits above the valid ones are undefined and ignored.
        assert_eq!(elapsed_ticks(0xFF00_0000_0000_0010, 0x0A00_0000_0000_0025, 36), 0x15);
    }
}
