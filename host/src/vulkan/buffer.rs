//! Buffers and one-shot command submission.

use super::batch::Batch;
use super::context::{vk_error, Core};
use super::driver_lock;
use super::recycle::{BufferKind, Parked};
use crate::error::{Error, Result};
use ash::vk;
use bytemuck::Pod;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::AllocationError;
use gpu_allocator::MemoryLocation;
use std::sync::atomic::Ordering;
use std::sync::Arc;

/// A Vulkan buffer with its memory; freed on drop, or kept for reuse if it is transient
/// ([`Self::transient`]).
pub(crate) struct GpuBuffer {
    core: Arc<Core>,
    pub buffer: vk::Buffer,
    allocation: Option<Allocation>,
    /// Device address, or 0 when the buffer was created without `SHADER_DEVICE_ADDRESS`.
    pub address: u64,
    /// Whether the memory was asked for as device-local ([`MemoryLocation::GpuOnly`]): the host
    /// reaches it only through a staging buffer ([`Self::with_data`], [`Batch::read`]).
    pub device_local: bool,
    /// Size in bytes.
    pub size: u64,
    /// Whether this is a stage's sanitized counter ([`Self::counter`]), which every run that
    /// binds it zeroes before its last repetition.
    pub is_counter: bool,
    /// The kind of a transient buffer ([`Self::transient`]), which goes back to the device's
    /// [`super::recycle::Recycler`] when dropped; none for one freed on drop.
    transient: Option<BufferKind>,
}

impl Drop for GpuBuffer {
    fn drop(&mut self) {
        if self.core.is_wedged() {
            // Leaked with its memory: a submission may still use it (`Core::wedge`).
            return;
        }
        let _driver = driver_lock::device_use();
        let Some(allocation) = self.allocation.take() else {
            // Its memory was never bound (creation failed): only the buffer is left.
            // SAFETY: no command ever used a buffer without memory.
            unsafe { self.core.device.destroy_buffer(self.buffer, None) };
            return;
        };
        let parked = Parked { buffer: self.buffer, allocation };
        match self.transient {
            // Kept for the next call that asks for one of its kind, handing back what it pushes
            // out.
            Some(kind) => {
                let submitted = self.core.submissions.load(Ordering::Relaxed);
                for freed in self.core.recycler.keep(kind, parked, submitted) {
                    free_parked(&self.core, freed);
                }
            }
            None => free_parked(&self.core, parked),
        }
    }
}

/// The device address of `buffer` (memory bound), or 0 where `usage` has no
/// `SHADER_DEVICE_ADDRESS`.
fn device_address(core: &Core, buffer: vk::Buffer, usage: vk::BufferUsageFlags) -> u64 {
    if !usage.contains(vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS) {
        return 0;
    }
    // SAFETY: the buffer was created with SHADER_DEVICE_ADDRESS and has memory bound.
    unsafe { core.device.get_buffer_device_address(&vk::BufferDeviceAddressInfo::default().buffer(buffer)) }
}

/// Destroys a buffer no command uses, then frees its memory. The caller holds the driver lock
/// ([`driver_lock::device_use`] or, at teardown, `device_lifetime`).
pub(crate) fn free_parked(core: &Core, parked: Parked) {
    // SAFETY: the device is idle after every submission, so no command uses the buffer.
    unsafe { core.device.destroy_buffer(parked.buffer, None) };
    // Then its memory; a panic elsewhere while the allocator was locked leaves it usable.
    let mut allocator = core.allocator.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let _ = allocator.free(parked.allocation);
}

/// The usage a device-local buffer has besides its own: the copies from and to staging buffers
/// that the host fills and reads it through.
const STAGED: vk::BufferUsageFlags = vk::BufferUsageFlags::from_raw(
    vk::BufferUsageFlags::TRANSFER_SRC.as_raw() | vk::BufferUsageFlags::TRANSFER_DST.as_raw(),
);

/// Least alignment, in bytes, of a buffer that has a device address: the largest a device address
/// input needs (an acceleration structure's instance array, 16 bytes; vertex and index data 4).
const DEVICE_ADDRESS_ALIGNMENT: u64 = 16;

/// Why a buffer could not be made, and whether for want of memory, which freeing the buffers kept
/// for reuse may mend.
struct Unmade {
    error: Error,
    out_of_memory: bool,
}

/// The [`Unmade`] of Vulkan call `call` failing with a result.
fn vk_unmade(call: &'static str) -> impl Fn(vk::Result) -> Unmade {
    move |result| Unmade {
        error: vk_error(call)(result),
        out_of_memory: matches!(result, vk::Result::ERROR_OUT_OF_DEVICE_MEMORY | vk::Result::ERROR_OUT_OF_HOST_MEMORY),
    }
}

/// Runs `attempt`; where it fails for want of memory and `free_kept` freed something (returns
/// whether it did), runs it once more.
fn retried_after_freeing<T>(
    mut attempt: impl FnMut() -> std::result::Result<T, Unmade>,
    free_kept: impl FnOnce() -> bool,
) -> Result<T> {
    match attempt() {
        Ok(made) => Ok(made),
        Err(Unmade { out_of_memory: true, error }) => {
            if free_kept() {
                attempt().map_err(|unmade| unmade.error)
            } else {
                Err(error)
            }
        }
        Err(unmade) => Err(unmade.error),
    }
}

impl GpuBuffer {
    /// Creates a buffer of `size` bytes (at least 4, since Vulkan forbids empty buffers) that is
    /// freed on drop; one with a device address starts on a 16-byte boundary. Where it cannot be
    /// made for want of memory while the device keeps transient buffers for reuse
    /// ([`super::recycle::Recycler`]), those are freed and it is tried once more.
    pub fn new(
        core: &Arc<Core>,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
        name: &str,
    ) -> Result<Self> {
        // Kept buffers are at least 4 bytes each, so none was freed exactly when no byte was.
        let free_kept = || core.free_kept_buffers() > 0;
        retried_after_freeing(|| Self::create(core, size, usage, location, name), free_kept)
    }

    /// A buffer of `size` bytes (at least 4) with no memory bound yet, freed on drop.
    fn unbound(core: &Arc<Core>, buffer: vk::Buffer, size: u64, location: MemoryLocation) -> Self {
        let device_local = location == MemoryLocation::GpuOnly;
        Self {
            core: core.clone(),
            buffer,
            allocation: None,
            address: 0,
            device_local,
            size,
            is_counter: false,
            transient: None,
        }
    }

    /// [`Self::new`], tried once.
    fn create(
        core: &Arc<Core>,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
        name: &str,
    ) -> std::result::Result<Self, Unmade> {
        let size = size.max(4);
        let wants_address = usage.contains(vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS);
        let info = vk::BufferCreateInfo::default().size(size).usage(usage).sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid create info; the buffer is destroyed in Drop.
        let buffer = unsafe { core.device.create_buffer(&info, None) }.map_err(vk_unmade("vkCreateBuffer"))?;
        // Constructed now so any failure below frees the buffer through Drop.
        let mut this = Self::unbound(core, buffer, size, location);
        // SAFETY: `buffer` is a live buffer of this device.
        let mut requirements = unsafe { core.device.get_buffer_memory_requirements(buffer) };
        if wants_address {
            // Device addresses feed acceleration-structure builds, whose instance data must be
            // 16-byte aligned (VUID-vkCmdBuildAccelerationStructuresKHR-pInfos-03715; vertex and
            // index data need only their component size, 03711/03712); the buffer's own memory
            // alignment is not bound to be that large.
            requirements.alignment = requirements.alignment.max(DEVICE_ADDRESS_ALIGNMENT);
        }
        let poisoned = || Unmade {
            error: Error::Vulkan { call: "gpu_allocator", result: "allocator lock poisoned".into() },
            out_of_memory: false,
        };
        let allocation = core
            .allocator
            .lock()
            .map_err(|_| poisoned())?
            .allocate(&AllocationCreateDesc {
                name,
                requirements,
                location,
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            })
            .map_err(|e| Unmade {
                out_of_memory: matches!(e, AllocationError::OutOfMemory),
                error: Error::Vulkan { call: "gpu_allocator::allocate", result: e.to_string() },
            })?;
        // Stored before binding, so a failed bind frees the allocation through Drop too.
        let allocation = this.allocation.insert(allocation);
        // SAFETY: the allocation satisfies `requirements` and is not bound elsewhere.
        unsafe { core.device.bind_buffer_memory(buffer, allocation.memory(), allocation.offset()) }
            .map_err(vk_unmade("vkBindBufferMemory"))?;
        this.address = device_address(core, buffer, usage);
        Ok(this)
    }

    /// A buffer of `size` bytes ([`Self::new`]) for one call: one the device kept for reuse
    /// where it has one of exactly this size, usage and location
    /// ([`super::recycle::Recycler::take`]), holding what its last user left (and the debug
    /// `name` of its first, in the allocator's reports), else a new one; either way kept for
    /// reuse when dropped.
    pub fn transient(
        core: &Arc<Core>,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
        name: &str,
    ) -> Result<Self> {
        let kind = BufferKind { size: size.max(4), usage, location };
        let mut this = match core.recycler.take(kind) {
            Some(Parked { buffer, allocation }) => {
                let mut this = Self::unbound(core, buffer, kind.size, location);
                this.allocation = Some(allocation);
                this.address = device_address(core, buffer, usage);
                this
            }
            None => {
                let this = Self::new(core, size, usage, location, name)?;
                core.recycler.created(kind);
                this
            }
        };
        this.transient = Some(kind);
        Ok(this)
    }

    /// Creates a device-local buffer of `size` bytes for `usage`, which the host fills and reads
    /// through staging copies. Every buffer a kernel binds is one: on a discrete GPU host-visible
    /// memory is system memory (gpu-allocator's `GpuToCpu`) or a small BAR window (`CpuToGpu`,
    /// falling back to system memory when it is full), which a kernel reaches over PCIe — tens
    /// of GB/s against the several TB/s of an H100's or H200's HBM. On a device whose memory is
    /// all host-visible (lavapipe, integrated GPUs) the staging copies cost a `memcpy` each.
    pub fn device_local(core: &Arc<Core>, size: u64, usage: vk::BufferUsageFlags, name: &str) -> Result<Self> {
        Self::new(core, size, usage | STAGED, MemoryLocation::GpuOnly, name)
    }

    /// Creates a device-local buffer ([`Self::device_local`]) holding `data`.
    pub fn with_data<T: Pod>(core: &Arc<Core>, data: &[T], usage: vk::BufferUsageFlags, name: &str) -> Result<Self> {
        let buffer = Self::device_local(core, std::mem::size_of_val(data) as u64, usage, name)?;
        buffer.upload(data)?;
        Ok(buffer)
    }

    /// A device-local storage buffer (as [`Self::device_local`]) for `len` elements of `T`, for
    /// one call ([`Self::transient`]: possibly reused, holding its last user's data): what every
    /// stream, image, counter and probe a kernel reads or writes is held in. Not checked against
    /// the storage-buffer range: the backend checks every stream against its `max_rays` first,
    /// which keeps a stream of the widest element, `Vec4`, within it, and every probe on its own.
    pub fn storage<T: Pod>(core: &Arc<Core>, len: u32, name: &str) -> Result<Self> {
        let bytes = u64::from(len) * std::mem::size_of::<T>() as u64;
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER | STAGED;
        Self::transient(core, bytes, usage, MemoryLocation::GpuOnly, name)
    }

    /// A device-local storage buffer ([`Self::device_local`]) holding `data`, freed on drop: the
    /// scene data a backend keeps.
    pub fn storage_with<T: Pod>(core: &Arc<Core>, data: &[T], name: &str) -> Result<Self> {
        Self::with_data(core, data, vk::BufferUsageFlags::STORAGE_BUFFER, name)
    }

    /// Copies `data` to the start of this device-local buffer through a host-visible staging
    /// buffer, in a submission of its own ([`Batch::upload`]; none for empty `data`), and waits.
    pub fn upload<T: Pod>(&self, data: &[T]) -> Result<()> {
        let mut batch = Batch::new(&self.core);
        batch.upload(self, data)?;
        batch.submit().map(drop)
    }

    /// A host-visible staging buffer holding `bytes` (at least one), which a copy uploads into
    /// this buffer: transient ([`Self::transient`]) where this one is — a call's own data —
    /// else freed when dropped, as scene data is uploaded once and may be large.
    pub(crate) fn staging_for(&self, bytes: &[u8]) -> Result<Self> {
        let (core, size, usage, location) =
            (&self.core, bytes.len() as u64, vk::BufferUsageFlags::TRANSFER_SRC, MemoryLocation::CpuToGpu);
        let mut staging = if self.transient.is_some() {
            Self::transient(core, size, usage, location, "upload staging")?
        } else {
            Self::new(core, size, usage, location, "upload staging")?
        };
        staging.mapped_mut()?[..bytes.len()].copy_from_slice(bytes);
        Ok(staging)
    }

    /// A stage's sanitized counter: one `u32` that its entry points increment atomically (the
    /// `REPLACED` bindings of `raywave_shared::bindings`), zeroed on the device by every run
    /// that binds it before its last repetition ([`super::pass::Pass::record`]); a batch reads
    /// it once the run has completed ([`Batch::read`], [`super::batch::Done::count`]).
    pub fn counter(core: &Arc<Core>, name: &str) -> Result<Self> {
        let mut counter = Self::storage::<u32>(core, 1, name)?;
        counter.is_counter = true;
        Ok(counter)
    }

    /// The mapping of a host-visible (staging) buffer. A device-local buffer is refused even where
    /// its memory happens to be host-visible (lavapipe, integrated GPUs), so that a path which
    /// would fail on a discrete GPU fails in CI too.
    fn mapped_mut(&mut self) -> Result<&mut [u8]> {
        if self.device_local {
            return Err(not_host_visible());
        }
        self.allocation.as_mut().and_then(|a| a.mapped_slice_mut()).ok_or_else(not_host_visible)
    }

    /// Copies the first `count` elements out of this device-local buffer through a host-visible
    /// staging buffer, in a submission of its own, for tests ([`Batch::read`] reads in a batch).
    #[cfg(test)]
    pub fn read<T: Pod>(&self, count: usize) -> Result<Vec<T>> {
        let mut batch = Batch::new(&self.core);
        let read = batch.read(self, count)?;
        batch.submit()?.read(&read)
    }

    /// The first `len` bytes of a host-visible (staging) buffer's mapping, as elements of `T`;
    /// refused for a device-local buffer, as [`Self::mapped_mut`].
    pub(crate) fn read_mapped<T: Pod>(&self, len: usize) -> Result<Vec<T>> {
        if self.device_local {
            return Err(not_host_visible());
        }
        let bytes = self.allocation.as_ref().and_then(|a| a.mapped_slice()).ok_or_else(not_host_visible)?;
        let bytes = bytes.get(..len).ok_or_else(|| Error::InvalidParameter {
            name: "count",
            reason: format!("read of {len} bytes past {}", bytes.len()),
        })?;
        Ok(bytemuck::pod_collect_to_vec(bytes))
    }
}

/// Checks that `what`, a storage buffer of `bytes` bytes, fits the device's
/// `maxStorageBufferRange`: every kernel binds its buffers whole ([`super::pass::Pass::prepare`]),
/// and a binding past that range is invalid — the kernel would not see all of the buffer. A
/// buffer over it is [`Error::InvalidParameter`] naming `parameter`, `what` and both sizes.
pub(crate) fn check_storage_range(
    limits: &vk::PhysicalDeviceLimits,
    bytes: u64,
    parameter: &'static str,
    what: &str,
) -> Result<()> {
    let range = limits.max_storage_buffer_range;
    if bytes > u64::from(range) {
        return Err(Error::InvalidParameter {
            name: parameter,
            reason: format!("{what}: {bytes} bytes exceed the device's storage-buffer range of {range} bytes"),
        });
    }
    Ok(())
}

/// The error of mapping a buffer the host may not reach directly.
fn not_host_visible() -> Error {
    Error::Vulkan { call: "vkMapMemory", result: "buffer memory is not host-visible".into() }
}

/// Records commands with `record`, submits them and waits for completion. If the wait fails (a
/// lost device, out of memory), the submission may still be pending: the device is idled, and if
/// that fails too, other than by losing the device, it is wedged ([`Core::wedge`]) — the fence,
/// the pool and every buffer the commands use are leaked rather than freed under the GPU — and
/// this and every later call fail with the error [`wedged_error`].
pub(crate) fn submit_and_wait(core: &Core, record: impl FnOnce(vk::CommandBuffer)) -> Result<()> {
    if core.is_wedged() {
        return Err(wedged_error());
    }
    let device = &core.device;
    // SAFETY: the pool, command buffer and fence are created, used and destroyed within this call,
    // and the wait (or an idle device, or a wedged one's leak) guarantees the GPU is done with
    // them before destruction.
    unsafe {
        let pool = device
            .create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(core.queue_family)
                    .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                None,
            )
            .map_err(vk_error("vkCreateCommandPool"))?;
        let result = (|| {
            let cmd = device
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(pool)
                        .level(vk::CommandBufferLevel::PRIMARY)
                        .command_buffer_count(1),
                )
                .map_err(vk_error("vkAllocateCommandBuffers"))?[0];
            device
                .begin_command_buffer(
                    cmd,
                    &vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )
                .map_err(vk_error("vkBeginCommandBuffer"))?;
            // Make every earlier submission's writes visible to this one's shaders and builds.
            global_barrier(core, cmd, vk::PipelineStageFlags::ALL_COMMANDS, vk::PipelineStageFlags::ALL_COMMANDS);
            record(cmd);
            // And this one's writes visible to the host for readback.
            global_barrier(core, cmd, vk::PipelineStageFlags::ALL_COMMANDS, vk::PipelineStageFlags::HOST);
            device.end_command_buffer(cmd).map_err(vk_error("vkEndCommandBuffer"))?;
            let fence =
                device.create_fence(&vk::FenceCreateInfo::default(), None).map_err(vk_error("vkCreateFence"))?;
            let cmds = [cmd];
            let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
            let waited = match device.queue_submit(core.queue, &submit, fence) {
                Err(e) => Err(vk_error("vkQueueSubmit")(e)),
                Ok(()) => {
                    core.submissions.fetch_add(1, Ordering::Relaxed);
                    let waited = device.wait_for_fences(&[fence], true, u64::MAX).map_err(vk_error("vkWaitForFences"));
                    if waited.is_err() && !idled(device.device_wait_idle()) {
                        core.wedge();
                    }
                    // The wait's own error is the one reported.
                    waited
                }
            };
            if !core.is_wedged() {
                device.destroy_fence(fence, None);
            }
            waited
        })();
        if !core.is_wedged() {
            device.destroy_command_pool(pool, None);
        }
        result
    }
}

/// Whether `vkDeviceWaitIdle`'s `result` leaves no submission running: success, or a lost
/// device, which counts every submission complete (Vulkan specification, "Lost Device").
fn idled(result: ash::prelude::VkResult<()>) -> bool {
    matches!(result, Ok(()) | Err(vk::Result::ERROR_DEVICE_LOST))
}

/// The error of a call on a wedged device ([`Core::wedge`]).
pub(crate) fn wedged_error() -> Error {
    Error::Vulkan {
        call: "vkQueueSubmit",
        result: "not submitted: an earlier submission could be neither waited for nor the device idled, so the \
                 GPU may still be using this backend's objects (they are leaked, not freed); open a new backend"
            .into(),
    }
}

/// A full memory barrier between `src` and `dst` stages covering all reads and writes.
pub(crate) fn global_barrier(
    core: &Core,
    cmd: vk::CommandBuffer,
    src: vk::PipelineStageFlags,
    dst: vk::PipelineStageFlags,
) {
    let barrier = [vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
        .dst_access_mask(vk::AccessFlags::MEMORY_READ | vk::AccessFlags::MEMORY_WRITE)];
    // SAFETY: `cmd` is in the recording state.
    unsafe { core.device.cmd_pipeline_barrier(cmd, src, dst, vk::DependencyFlags::empty(), &barrier, &[], &[]) };
}

/// Fills every buffer `core` keeps for reuse with ones (all bits set: NaN as `f32`, `u32::MAX`),
/// so that a call taking one reads them wherever it reads what it did not write first; for the
/// tests that check no stale contents reach a result ([`super::recycle`]).
#[cfg(test)]
pub(crate) fn fill_kept_with_ones(core: &Core) {
    let mut device_local = Vec::new();
    core.recycler.for_each_kept(|kind, parked| match kind.location {
        MemoryLocation::GpuOnly => device_local.push(parked.buffer),
        _ => parked.allocation.mapped_slice_mut().expect("staging memory is mapped").fill(0xff),
    });
    submit_and_wait(core, |cmd| {
        for &buffer in &device_local {
            // SAFETY: `cmd` is recording; kept device-local buffers have transfer-destination
            // usage (`STAGED`), and none is dropped while they are kept.
            unsafe { core.device.cmd_fill_buffer(cmd, buffer, 0, vk::WHOLE_SIZE, u32::MAX) };
        }
    })
    .unwrap();
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Validation includes synchronization validation: a copy that reads a buffer a fill just
    /// wrote, with no barrier between, is reported (a serial device such as lavapipe runs it
    /// right, so only the layer can see it), and the same two commands with the barrier are not.
    /// Every Vulkan device; without one it fails under CI and is skipped loudly elsewhere.
    #[test]
    fn validation_reports_a_missing_barrier() {
        for (name, core) in super::super::validated_cores_for_test("synchronization validation") {
            let source = GpuBuffer::storage::<u32>(&core, 64, "source").unwrap();
            let destination = GpuBuffer::storage::<u32>(&core, 64, "destination").unwrap();
            let fill_then_copy = |barrier: bool| {
                submit_and_wait(&core, |cmd| {
                    let region = [vk::BufferCopy::default().size(256)];
                    // SAFETY: `cmd` is recording; both buffers are live, hold 256 bytes and have
                    // transfer usage.
                    unsafe { core.device.cmd_fill_buffer(cmd, source.buffer, 0, vk::WHOLE_SIZE, 7) };
                    if barrier {
                        let all = vk::PipelineStageFlags::ALL_COMMANDS;
                        global_barrier(&core, cmd, all, all);
                    }
                    // SAFETY: as above.
                    unsafe { core.device.cmd_copy_buffer(cmd, source.buffer, destination.buffer, &region) };
                })
                .unwrap();
                core.validation_log().messages()
            };
            assert!(fill_then_copy(true).is_empty(), "{}: with the barrier", name);
            let messages = fill_then_copy(false);
            assert!(messages.iter().any(|m| m.contains("SYNC-HAZARD")), "{}: {messages:?}", name);
            assert_eq!(destination.read::<u32>(64).unwrap(), [7; 64], "{}", name);
        }
    }

    /// `vkDeviceWaitIdle` leaves nothing running when it succeeds or finds the device lost; any
    /// other error (out of memory) may leave a submission pending, which wedges the device.
    #[test]
    fn only_success_or_a_lost_device_leaves_the_device_idle() {
        assert!(idled(Ok(())));
        assert!(idled(Err(vk::Result::ERROR_DEVICE_LOST)));
        assert!(!idled(Err(vk::Result::ERROR_OUT_OF_HOST_MEMORY)));
        assert!(!idled(Err(vk::Result::ERROR_OUT_OF_DEVICE_MEMORY)));
    }

    /// A wedged device (`Core::wedge`) submits nothing more — a call fails with the typed error
    /// before recording — and dropping a buffer and the device after it, which leaks them, is
    /// quiet under validation (that nothing is destroyed, no test here can see). Every Vulkan
    /// device; without one it fails under CI and is skipped loudly elsewhere.
    #[test]
    fn a_wedged_device_submits_nothing_and_drops_quietly() {
        for (name, core) in super::super::validated_cores_for_test("wedged device") {
            let buffer = GpuBuffer::storage::<u32>(&core, 64, "in use").unwrap();
            submit_and_wait(&core, |_| {}).unwrap();
            let submitted = core.submissions.load(Ordering::Relaxed);
            core.wedge();
            let refused = submit_and_wait(&core, |_| panic!("recorded on a wedged device")).expect_err("wedged");
            assert_eq!(refused.to_string(), wedged_error().to_string(), "{}", name);
            assert_eq!(core.submissions.load(Ordering::Relaxed), submitted, "{}", name);
            let log = core.validation_log();
            drop(buffer);
            drop(core);
            assert_eq!(log.messages(), Vec::<String>::new(), "{}", name);
        }
    }

    /// A buffer that cannot be made for want of memory is tried once more after the kept buffers
    /// are freed, and only then and only if some were; any other failure, or a second one, is
    /// the error returned.
    #[test]
    fn a_buffer_is_tried_again_only_after_freeing_kept_buffers_for_want_of_memory() {
        let unmade =
            |out_of_memory| Unmade { error: Error::Vulkan { call: "test", result: "no".into() }, out_of_memory };
        let run = |failures: Vec<bool>, kept: bool| {
            let (mut attempts, mut frees) = (failures.into_iter(), 0);
            let made = retried_after_freeing(
                || attempts.next().map_or(Ok(()), |out_of_memory| Err(unmade(out_of_memory))),
                || {
                    frees += 1;
                    kept
                },
            );
            (made.is_ok(), attempts.len(), frees)
        };
        // (made, attempts left unused, frees)
        assert_eq!(run(vec![], true), (true, 0, 0), "made at once");
        assert_eq!(run(vec![true], true), (true, 0, 1), "made after freeing");
        assert_eq!(run(vec![true, true], true), (false, 0, 1), "out of memory twice");
        assert_eq!(run(vec![true, true], false), (false, 1, 1), "nothing kept: no second try");
        assert_eq!(run(vec![false, true], true), (false, 1, 0), "not for want of memory: no freeing");
    }

    #[test]
    fn a_storage_buffer_past_the_device_range_is_refused_by_name() {
        let limits = vk::PhysicalDeviceLimits { max_storage_buffer_range: 1 << 27, ..Default::default() };
        assert!(check_storage_range(&limits, 1 << 27, "scene", "cwbvh vertices").is_ok());
        match check_storage_range(&limits, (1 << 27) + 1, "scene", "cwbvh vertices") {
            Err(Error::InvalidParameter { name: "scene", reason }) => assert_eq!(
                reason,
                "cwbvh vertices: 134217729 bytes exceed the device's storage-buffer range of 134217728 bytes"
            ),
            other => panic!("expected a scene parameter error, got {other:?}"),
        }
        let widest = vk::PhysicalDeviceLimits { max_storage_buffer_range: u32::MAX, ..limits };
        assert!(check_storage_range(&widest, u64::from(u32::MAX), "warp probe", "warp probe").is_ok());
        assert!(check_storage_range(&widest, 1 << 32, "warp probe", "warp probe").is_err());
    }
}
