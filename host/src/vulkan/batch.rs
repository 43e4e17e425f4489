//! One submission of several passes, of the copies that upload their inputs and of the copies
//! that read their results back. A lit sample's generate, trace, shade and occlusion passes,
//! their sanitized counters and its readbacks make one command buffer and one wait: each of them
//! had been its own submission, fifteen a sample (21 with the camera streams), every one a round
//! trip to the device and the driver's threads. A frame's denoise is one too, where it had been
//! one per pass and per input (fourteen for TV).

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

/// Work gathered for one submission: copies of host data into device buffers, through
/// host-visible staging buffers written when they are added; runs of passes, in order; then
/// copies of device buffers into host-visible staging buffers, one per read (no larger than the
/// buffer read, as before batches; a gather's as large as the buffer it gathers from). Each
/// step comes after a barrier that makes the writes before it visible, this submission's and
/// earlier ones'. The buffers it uploads to, its runs bind and its reads copy are borrowed for
/// `'a`, past [`Self::submit`]'s wait; an acceleration structure is bound by handle, which the
/// caller keeps alive (`add_trace` borrows its scene). Each run holds a slot of its pass
/// (descriptor set, timestamps) until the batch is dropped ([`Pass::prepare`]), so a pass may
/// run several times in one batch.
pub(crate) struct Batch<'a> {
    core: Arc<Core>,
    /// Copies from their staging buffers, written by the host, into their device buffers.
    uploads: Vec<Staged<'a>>,
    runs: Vec<Run<'a>>,
    /// Copies from their device buffers into their staging buffers, which the host reads.
    reads: Vec<Staged<'a>>,
}

/// A device buffer and the host-visible staging buffer that `regions` copy from (an upload) or
/// into (a read): the buffer's first bytes, or the elements a gather picks.
struct Staged<'a> {
    buffer: &'a GpuBuffer,
    staging: GpuBuffer,
    regions: Vec<vk::BufferCopy>,
}

/// A pass's prepared run and the commands of its work.
struct Run<'a> {
    pass: &'a Pass,
    prepared: PreparedRun,
    work: Box<dyn Fn(vk::CommandBuffer) + 'a>,
}

/// One step of a submission, after a barrier where it is not the first.
enum Step<'r, 'a> {
    Uploads,
    Run(&'r Run<'a>),
    Reads,
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
        Self { core: core.clone(), uploads: Vec::new(), runs: Vec::new(), reads: Vec::new() }
    }

    /// Adds a copy of `data` into the start of device buffer `buffer`, made before every run:
    /// `data` is written now into a host-visible staging buffer of its size, held until the
    /// batch is dropped — a batch's uploads occupy host-visible memory all at once (a 1080p
    /// denoise's six inputs, 200 MB), where one upload at a time had held one. An upload past the
    /// buffer's end is refused, and a second upload to the same buffer (the copies run without
    /// barriers between them, so the two would race); an empty one adds nothing (Vulkan refuses
    /// empty copy regions).
    pub fn upload<T: Pod>(&mut self, buffer: &'a GpuBuffer, data: &[T]) -> Result<()> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let refused = |reason: String| Err(Error::InvalidParameter { name: "data", reason });
        if bytes.len() as u64 > buffer.size {
            return refused(format!(
                "upload of {} bytes past the end of a buffer of {} bytes",
                bytes.len(),
                buffer.size
            ));
        }
        if self.uploads.iter().any(|upload| upload.buffer.buffer == buffer.buffer) {
            return refused("a second upload to one buffer in a batch".to_owned());
        }
        if !bytes.is_empty() {
            let staging = buffer.staging_for(bytes)?;
            let regions = vec![vk::BufferCopy::default().size(bytes.len() as u64)];
            self.uploads.push(Staged { buffer, staging, regions });
        }
        Ok(())
    }

    /// Adds a run of `pass` over `resources` with push constants `push` and `invocations`
    /// invocations, whose commands `work` records ([`Pass::prepare`], [`Pass::record`]), in a
    /// slot of the pass that the batch holds until it is dropped.
    pub fn add(
        &mut self,
        pass: &'a Pass,
        resources: &[Resource<'a>],
        push: &[u8],
        invocations: u32,
        work: impl Fn(vk::CommandBuffer) + 'a,
    ) -> Result<RunId> {
        let prepared = pass.prepare(resources, push, invocations)?;
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
        self.read_regions(buffer, bytes, bytes as u64, vec![vk::BufferCopy::default().size(bytes as u64)])
    }

    /// Adds a copy of the elements of device buffer `buffer` at `indices`, in their order, made
    /// after every run: a gather, one copy region per run of consecutive indices, into the start
    /// of a staging buffer. That is as large as `buffer`, so that it is the one a whole read of
    /// `buffer` leaves for reuse ([`super::recycle`]): gathers of ever-changing lengths (a
    /// G-buffer's gaps, sample by sample) create none in a frame loop. An index past the
    /// buffer's end is refused.
    pub fn gather<T: Pod>(&mut self, buffer: &'a GpuBuffer, indices: &[u32]) -> Result<ReadId<T>> {
        let size = std::mem::size_of::<T>() as u64;
        if let Some(&index) = indices.iter().find(|&&i| (u64::from(i) + 1) * size > buffer.size) {
            return Err(Error::InvalidParameter {
                name: "indices",
                reason: format!("gather of element {index} past the end of a buffer of {} bytes", buffer.size),
            });
        }
        let bytes = indices.len() as u64 * size;
        // As large as the buffer, or as the gather where it repeats elements.
        self.read_regions(buffer, bytes as usize, buffer.size.max(bytes), gather_regions(indices, size))
    }

    /// Adds a read of `bytes` bytes of `buffer` that `regions` copy into the start of a staging
    /// buffer of `staging_size` bytes; a read of nothing adds no copy (Vulkan refuses empty copy
    /// regions).
    fn read_regions<T: Pod>(
        &mut self,
        buffer: &'a GpuBuffer,
        bytes: usize,
        staging_size: u64,
        regions: Vec<vk::BufferCopy>,
    ) -> Result<ReadId<T>> {
        if bytes == 0 {
            return Ok(ReadId { staging: None, bytes, _element: PhantomData });
        }
        let staging = GpuBuffer::transient(
            &self.core,
            staging_size,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
            "readback staging",
        )?;
        self.reads.push(Staged { buffer, staging, regions });
        Ok(ReadId { staging: Some(self.reads.len() - 1), bytes, _element: PhantomData })
    }

    /// Records `steps` into `cmd`, each after a barrier.
    fn record(&self, cmd: vk::CommandBuffer, steps: &[Step<'_, 'a>]) {
        let all = vk::PipelineStageFlags::ALL_COMMANDS;
        let copy = |source: &GpuBuffer, destination: &GpuBuffer, regions: &[vk::BufferCopy]| {
            // SAFETY: `cmd` is recording; both buffers hold every region (checked in `upload`,
            // `read` and `gather`, which made each staging buffer at least the size of what its
            // regions copy), none empty, and have transfer usage.
            unsafe { self.core.device.cmd_copy_buffer(cmd, source.buffer, destination.buffer, regions) };
        };
        for step in steps {
            // Each step reads what the ones before it wrote: in this submission, or in an
            // earlier one (a queue submission orders only the host's writes before it, not the
            // device's; a split batch's runs and a gather read what earlier submissions wrote).
            global_barrier(&self.core, cmd, all, all);
            match step {
                Step::Uploads => self.uploads.iter().for_each(|up| copy(&up.staging, up.buffer, &up.regions)),
                Step::Run(run) => run.pass.record(cmd, &run.prepared, &*run.work),
                Step::Reads => self.reads.iter().for_each(|read| copy(read.buffer, &read.staging, &read.regions)),
            }
        }
    }

    /// Records `steps` into a submission of their own and waits, unless there are none: the
    /// host clock's seconds around it.
    fn submit_steps(&self, steps: &[Step<'_, 'a>]) -> Result<f64> {
        if steps.is_empty() {
            return Ok(0.0);
        }
        let start = Instant::now();
        submit_and_wait(&self.core, |cmd| self.record(cmd, steps))?;
        Ok(start.elapsed().as_secs_f64())
    }

    /// Submits the batch and waits. Where the device writes timestamps the uploads, the runs and
    /// the reads make one submission, and each run's time comes from its own pair of timestamps.
    /// Where it does not, and in benchmark mode ([`Core::sustain_seconds`]: a run then keeps the
    /// device busy on its own, and four in one command buffer could outlast a driver's watchdog),
    /// the uploads are one submission, each run is its own — timed by the host clock around it
    /// where there are no timestamps — and the reads one more, as every pass was before batches.
    pub fn submit(self) -> Result<Done> {
        self.submit_in(true)
    }

    /// [`Self::submit`], split into one submission for the uploads, one per run and one for the
    /// reads also where one submission could hold them all, unless `together`.
    pub(super) fn submit_in(mut self, together: bool) -> Result<Done> {
        let together = together && self.core.info.timestamps && self.core.sustain_seconds() == 0.0;
        let uploads = (!self.uploads.is_empty()).then_some(Step::Uploads);
        let reads = (!self.reads.is_empty()).then_some(Step::Reads);
        let mut timings = Vec::with_capacity(self.runs.len());
        if together {
            let steps: Vec<Step> = uploads.into_iter().chain(self.runs.iter().map(Step::Run)).chain(reads).collect();
            let host_seconds = self.submit_steps(&steps)?;
            for run in &self.runs {
                timings.push(run.pass.timing(&run.prepared, host_seconds)?);
            }
        } else {
            self.submit_steps(&Vec::from_iter(uploads))?;
            for run in &self.runs {
                let host_seconds = self.submit_steps(&[Step::Run(run)])?;
                timings.push(run.pass.timing(&run.prepared, host_seconds)?);
            }
            self.submit_steps(&Vec::from_iter(reads))?;
        }
        let staging = std::mem::take(&mut self.reads).into_iter().map(|read| read.staging).collect();
        Ok(Done { timings, staging })
    }
}

/// The copy regions of a gather of the elements at `indices`, each `size` bytes, into the start
/// of a staging buffer in their order: one region per run of consecutive indices.
fn gather_regions(indices: &[u32], size: u64) -> Vec<vk::BufferCopy> {
    let mut regions: Vec<vk::BufferCopy> = Vec::new();
    for (k, &index) in indices.iter().enumerate() {
        let source = u64::from(index) * size;
        match regions.last_mut() {
            Some(run) if run.src_offset + run.size == source => run.size += size,
            _ => regions.push(vk::BufferCopy::default().src_offset(source).dst_offset(k as u64 * size).size(size)),
        }
    }
    regions
}

impl Drop for Batch<'_> {
    /// Releases the slots of the batch's runs, submitted or not.
    fn drop(&mut self) {
        for run in self.runs.drain(..) {
            run.pass.release(run.prepared);
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A gather copies each run of consecutive indices in one region, to where its first element
    /// falls in the list; a repeated or descending index starts a run of its own.
    #[test]
    fn a_gather_copies_each_run_of_indices_in_one_region() {
        let regions: Vec<_> = gather_regions(&[1, 2, 3, 7, 40, 41, 383, 383, 5], 8)
            .iter()
            .map(|r| (r.src_offset, r.dst_offset, r.size))
            .collect();
        assert_eq!(regions, [(8, 0, 24), (56, 24, 8), (320, 32, 16), (3064, 48, 8), (3064, 56, 8), (40, 64, 8)]);
        assert!(gather_regions(&[], 8).is_empty());
    }
}
