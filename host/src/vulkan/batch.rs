//! One submission of several passes and of the copies that read their results back. A lit
//! sample's generate, trace, shade and occlusion passes, their sanitized counters and its
//! readbacks make one command buffer and one wait: each of them had been its own submission,
//! fifteen a sample (21 with the camera streams), every one a round trip to the device and the
//! driver's threads.

use super::buffer::{global_barrier, submit_and_wait, GpuBuffer};
use super::context::Core;
use super::pass::{Pass, PreparedRun, Resource, Timing};
use crate::error::{Error, Result};
use ash::vk;
use bytemuck::Pod;
use gpu_allocator::MemoryLocation;
use std::marker::PhantomData;
use std::sync::Arc;
use std::time::Instant;

/// Work gathered for one submission: runs of passes, in order, each after a barrier that makes
/// the last one's writes visible, then copies of device buffers into host-visible staging
/// buffers, one per read (no larger than the buffer read, as before batches). The buffers its
/// runs bind and its reads copy are borrowed for `'a`, past [`Self::submit`]'s wait; an
/// acceleration structure is bound by handle, which the caller keeps alive (`add_trace` borrows
/// its scene). Each pass it runs is claimed until the batch is dropped ([`Pass::claim`]).
pub(crate) struct Batch<'a> {
    core: Arc<Core>,
    runs: Vec<Run<'a>>,
    reads: Vec<Read<'a>>,
}

/// A pass's prepared run and the commands of its work.
struct Run<'a> {
    pass: &'a Pass,
    prepared: PreparedRun,
    work: Box<dyn Fn(vk::CommandBuffer) + 'a>,
}

/// A copy of the first `bytes` of `buffer` into `staging`.
struct Read<'a> {
    buffer: &'a GpuBuffer,
    staging: GpuBuffer,
    bytes: u64,
}

/// A run in a [`Batch`], to find its timing in [`Done`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct RunId(usize);

/// A read in a [`Batch`] of elements of `T`, to find them in [`Done`]: its staging buffer's
/// index, or none for a read of nothing.
pub(crate) struct ReadId<T> {
    staging: Option<usize>,
    bytes: usize,
    _element: PhantomData<T>,
}

/// What a submitted [`Batch`] measured and read back.
pub(crate) struct Done {
    timings: Vec<Timing>,
    staging: Vec<GpuBuffer>,
}

impl<'a> Batch<'a> {
    /// An empty batch for `core`'s device.
    pub fn new(core: &Arc<Core>) -> Self {
        Self { core: core.clone(), runs: Vec::new(), reads: Vec::new() }
    }

    /// Adds a run of `pass` over `resources` with push constants `push` and `invocations`
    /// invocations, whose commands `work` records ([`Pass::prepare`], [`Pass::record`]); refused
    /// for a pass that this or another live batch already runs, whose one descriptor set the
    /// second run would overwrite before the first ran.
    pub fn add(
        &mut self,
        pass: &'a Pass,
        resources: &[Resource<'a>],
        push: &[u8],
        invocations: u32,
        work: impl Fn(vk::CommandBuffer) + 'a,
    ) -> Result<RunId> {
        pass.claim()?;
        let prepared = match pass.prepare(resources, push, invocations) {
            Ok(prepared) => prepared,
            Err(error) => {
                pass.release();
                return Err(error);
            }
        };
        self.runs.push(Run { pass, prepared, work: Box::new(work) });
        Ok(RunId(self.runs.len() - 1))
    }

    /// Adds a copy of the first `count` elements of device buffer `buffer`, made after every run,
    /// and allocates its staging buffer; a read past the buffer's end is refused.
    pub fn read<T: Pod>(&mut self, buffer: &'a GpuBuffer, count: usize) -> Result<ReadId<T>> {
        let bytes = count
            .checked_mul(std::mem::size_of::<T>())
            .filter(|&bytes| bytes as u64 <= buffer.size)
            .ok_or_else(|| Error::InvalidParameter {
                name: "count",
                reason: format!("read of {count} elements past the end of a buffer of {} bytes", buffer.size),
            })?;
        if bytes == 0 {
            // Vulkan refuses empty copy regions.
            return Ok(ReadId { staging: None, bytes, _element: PhantomData });
        }
        let staging = GpuBuffer::new(
            &self.core,
            bytes as u64,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
            "readback staging",
        )?;
        self.reads.push(Read { buffer, staging, bytes: bytes as u64 });
        Ok(ReadId { staging: Some(self.reads.len() - 1), bytes, _element: PhantomData })
    }

    /// Records the reads' copies.
    fn record_reads(&self, cmd: vk::CommandBuffer) {
        for read in &self.reads {
            let region = [vk::BufferCopy::default().size(read.bytes)];
            // SAFETY: `cmd` is recording; the source holds `bytes` (checked in `read`), the
            // staging buffer was made of that size; both have transfer usage.
            unsafe { self.core.device.cmd_copy_buffer(cmd, read.buffer.buffer, read.staging.buffer, &region) };
        }
    }

    /// Submits the batch and waits. Where the device writes timestamps the runs and the copies
    /// make one submission, and each run's time comes from its own pair of timestamps. Where it
    /// does not, and in benchmark mode ([`Core::sustain_seconds`]: a run then keeps the device
    /// busy on its own, and four in one command buffer could outlast a driver's watchdog), each
    /// run is its own submission — timed by the host clock around it where there are no
    /// timestamps — and the copies one more, as every pass was before batches.
    pub fn submit(self) -> Result<Done> {
        self.submit_in(true)
    }

    /// [`Self::submit`], split into one submission per run and one for the copies also where one
    /// submission could hold them all, unless `together`.
    pub(super) fn submit_in(mut self, together: bool) -> Result<Done> {
        let together = together && self.core.info.timestamps && self.core.sustain_seconds() == 0.0;
        let all = vk::PipelineStageFlags::ALL_COMMANDS;
        let groups: Vec<&[Run]> = if together { vec![&self.runs[..]] } else { self.runs.chunks(1).collect() };
        let mut timings = Vec::with_capacity(self.runs.len());
        for group in groups {
            let copies = together && !self.reads.is_empty();
            if group.is_empty() && !copies {
                continue;
            }
            let start = Instant::now();
            submit_and_wait(&self.core, |cmd| {
                for (k, run) in group.iter().enumerate() {
                    if k > 0 {
                        // Each run reads what the ones before it wrote.
                        global_barrier(&self.core, cmd, all, all);
                    }
                    run.pass.record(cmd, &run.prepared, &*run.work);
                }
                if copies {
                    if !group.is_empty() {
                        global_barrier(&self.core, cmd, all, all);
                    }
                    self.record_reads(cmd);
                }
            })?;
            let host_seconds = start.elapsed().as_secs_f64();
            for run in group {
                timings.push(run.pass.timing(&run.prepared, host_seconds)?);
            }
        }
        if !together && !self.reads.is_empty() {
            submit_and_wait(&self.core, |cmd| self.record_reads(cmd))?;
        }
        let staging = std::mem::take(&mut self.reads).into_iter().map(|read| read.staging).collect();
        Ok(Done { timings, staging })
    }
}

impl Drop for Batch<'_> {
    /// Releases the passes the batch claimed, submitted or not.
    fn drop(&mut self) {
        for run in &self.runs {
            run.pass.release();
        }
    }
}

/// Submits a batch of the one run `add` puts in it and waits: that run's timing.
pub(crate) fn run_alone<'a>(core: &Arc<Core>, add: impl FnOnce(&mut Batch<'a>) -> Result<RunId>) -> Result<Timing> {
    let mut batch = Batch::new(core);
    let run = add(&mut batch)?;
    Ok(batch.submit()?.timing(run))
}

impl Done {
    /// The timing of run `run`.
    pub fn timing(&self, run: RunId) -> Timing {
        self.timings[run.0]
    }

    /// The elements read by `read`.
    pub fn read<T: Pod>(&self, read: &ReadId<T>) -> Result<Vec<T>> {
        match read.staging {
            Some(index) => self.staging[index].read_mapped(read.bytes),
            None => Ok(Vec::new()),
        }
    }

    /// The value of a sanitized counter ([`GpuBuffer::counter`]) read by `read`.
    pub fn count(&self, read: &ReadId<u32>) -> Result<u64> {
        Ok(self.read(read)?.first().copied().map(u64::from).unwrap_or(0))
    }
}
