//! One submission of several passes and of the copies that read their results back. A lit
//! sample's generate, trace, shade and occlusion passes, their sanitized counters and its
//! readbacks make one command buffer and one wait: each of them had been its own submission,
//! fifteen a sample, every one a round trip to the device and the driver's threads.

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
/// the last one's writes visible, then copies of device buffers into one host-visible staging
/// buffer. Borrows every resource it records until [`Self::submit`] has waited for the device.
pub(crate) struct Batch<'a> {
    core: Arc<Core>,
    runs: Vec<Run<'a>>,
    reads: Vec<Read<'a>>,
    /// Bytes of staging the reads take.
    staging_bytes: u64,
}

/// A pass's prepared run and the commands of its work.
struct Run<'a> {
    pass: &'a Pass,
    prepared: PreparedRun,
    /// What the run binds, borrowed until the submission completes.
    _resources: Vec<Resource<'a>>,
    work: Box<dyn Fn(vk::CommandBuffer) + 'a>,
}

/// A copy of the first `bytes` of `buffer` to `offset` in the staging buffer.
struct Read<'a> {
    buffer: &'a GpuBuffer,
    offset: u64,
    bytes: u64,
}

/// A run in a [`Batch`], to find its timing in [`Done`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct RunId(usize);

/// A read in a [`Batch`] of elements of `T`, to find them in [`Done`].
pub(crate) struct ReadId<T> {
    offset: u64,
    bytes: usize,
    _element: PhantomData<T>,
}

/// What a submitted [`Batch`] measured and read back.
pub(crate) struct Done {
    timings: Vec<Timing>,
    staging: Option<GpuBuffer>,
}

impl<'a> Batch<'a> {
    /// An empty batch for `core`'s device.
    pub fn new(core: &Arc<Core>) -> Self {
        Self { core: core.clone(), runs: Vec::new(), reads: Vec::new(), staging_bytes: 0 }
    }

    /// Adds a run of `pass` over `resources` with push constants `push` and `invocations`
    /// invocations, whose commands `work` records ([`Pass::prepare`], [`Pass::record`]); refused
    /// for a pass the batch already runs, whose one descriptor set the second run would
    /// overwrite before the first ran.
    pub fn add(
        &mut self,
        pass: &'a Pass,
        resources: &[Resource<'a>],
        push: &[u8],
        invocations: u32,
        work: impl Fn(vk::CommandBuffer) + 'a,
    ) -> Result<RunId> {
        if self.runs.iter().any(|run| std::ptr::eq(run.pass, pass)) {
            return Err(Error::InvalidParameter {
                name: "batch",
                reason: format!("{} runs twice in one submission", pass.name),
            });
        }
        let prepared = pass.prepare(resources, push, invocations)?;
        self.runs.push(Run { pass, prepared, _resources: resources.to_vec(), work: Box::new(work) });
        Ok(RunId(self.runs.len() - 1))
    }

    /// Adds a copy of the first `count` elements of device buffer `buffer`, made after every run;
    /// a read past its end is refused.
    pub fn read<T: Pod>(&mut self, buffer: &'a GpuBuffer, count: usize) -> Result<ReadId<T>> {
        let bytes = count
            .checked_mul(std::mem::size_of::<T>())
            .filter(|&bytes| bytes as u64 <= buffer.size)
            .ok_or_else(|| Error::InvalidParameter {
                name: "count",
                reason: format!("read of {count} elements past the end of a buffer of {} bytes", buffer.size),
            })?;
        let offset = self.staging_bytes;
        if bytes > 0 {
            // Vulkan refuses empty copy regions.
            self.reads.push(Read { buffer, offset, bytes: bytes as u64 });
            self.staging_bytes += bytes as u64;
        }
        Ok(ReadId { offset, bytes, _element: PhantomData })
    }

    /// Records the reads' copies into `staging`.
    fn record_reads(&self, cmd: vk::CommandBuffer, staging: &GpuBuffer) {
        for read in &self.reads {
            let region = [vk::BufferCopy::default().dst_offset(read.offset).size(read.bytes)];
            // SAFETY: `cmd` is recording; the source holds `bytes` (checked in `read`) and the
            // staging buffer `offset + bytes` (sized from the reads); both have transfer usage.
            unsafe { self.core.device.cmd_copy_buffer(cmd, read.buffer.buffer, staging.buffer, &region) };
        }
    }

    /// Submits the batch and waits. Where the device writes timestamps the runs and the copies
    /// make one submission, and each run's time comes from its own pair of timestamps; where it
    /// does not, each run is its own submission, timed by the host clock around it, and the
    /// copies one more — as every pass was before batches.
    pub fn submit(self) -> Result<Done> {
        let together = self.core.info.timestamps;
        self.submit_in(together)
    }

    /// [`Self::submit`] as one submission (`together`), or as one per run and one for the copies.
    pub(super) fn submit_in(self, together: bool) -> Result<Done> {
        let staging = match self.staging_bytes {
            0 => None,
            bytes => Some(GpuBuffer::new(
                &self.core,
                bytes,
                vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuToCpu,
                "readback staging",
            )?),
        };
        let all = vk::PipelineStageFlags::ALL_COMMANDS;
        let groups: Vec<&[Run]> = if together { vec![&self.runs[..]] } else { self.runs.chunks(1).collect() };
        let mut timings = Vec::with_capacity(self.runs.len());
        for group in groups {
            let copies = staging.as_ref().filter(|_| together);
            if group.is_empty() && copies.is_none() {
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
                if let Some(staging) = copies {
                    if !group.is_empty() {
                        global_barrier(&self.core, cmd, all, all);
                    }
                    self.record_reads(cmd, staging);
                }
            })?;
            let host_seconds = start.elapsed().as_secs_f64();
            for run in group {
                timings.push(run.pass.timing(&run.prepared, host_seconds)?);
            }
        }
        if let Some(staging) = staging.as_ref().filter(|_| !together) {
            submit_and_wait(&self.core, |cmd| self.record_reads(cmd, staging))?;
        }
        Ok(Done { timings, staging })
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
        match &self.staging {
            Some(staging) => staging.read_mapped(read.offset, read.bytes),
            None => Ok(Vec::new()),
        }
    }

    /// The value of a sanitized counter ([`GpuBuffer::counter`]) read by `read`.
    pub fn count(&self, read: &ReadId<u32>) -> Result<u64> {
        Ok(self.read(read)?.first().copied().map(u64::from).unwrap_or(0))
    }
}
