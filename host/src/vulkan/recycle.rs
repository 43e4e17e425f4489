//! Transient buffers kept for reuse: the streams, images, counters and staging buffers that a
//! lit sample, a denoise or a single stage allocates for one call and drops at its end.
//!
//! Why: a 1080p lit sample on Vulkan holds sixteen device buffers and eight staging buffers
//! (thirty-one with the camera streams of a frame's first sample, or with a later sample's
//! gather of the G-buffer's gaps, whose staging buffers are the same), a denoise up to fourteen and
//! eight, and every call had created and freed them all. gpu-allocator suballocates 256 MB device
//! blocks (64 MB host blocks) and frees a block as soon as it is empty unless it is the memory
//! type's last, so at 1080p (33 MB a `Vec4` image) each call allocated and freed whole blocks
//! through `vkAllocateMemory`; on lavapipe that memory is fresh pages the kernel faults in and
//! zeroes every call. Kept buffers are taken again by the next call that asks for exactly the
//! same size, usage and memory location ([`BufferKind`]) — the next sample, the next frame, and
//! a denoise's images that a lit sample's streams of the same size left.
//!
//! What it holds: each released buffer until the first release more than
//! [`KEPT_FOR_SUBMISSIONS`] submissions later, and at most [`KEPT_PEAKS`] times the bytes the
//! transient buffers alive at once have ever reached, the oldest given up first — room for the
//! distinct buffers of two kinds of call that alternate, while calls of ever-changing lengths (an
//! engine's single-stage calls on streams it compacts) cannot pile up. Where a buffer cannot be
//! made for want of memory, every kept buffer of its device is freed and it is tried once more
//! ([`super::buffer::GpuBuffer::new`]; each device keeps its own, so a second backend on the same
//! GPU frees only its own). The last call's buffers stay until a later release ages them out or
//! the backend closes, as an engine's render targets stay between frames. A reused buffer holds
//! what its last user left: every stage writes the elements it reads back, and the sanitized
//! counters are zeroed on the device by each run (tests fill kept buffers with ones before the
//! calls that take them to check it).

use ash::vk;
use gpu_allocator::vulkan::Allocation;
use gpu_allocator::MemoryLocation;
use std::sync::{Mutex, MutexGuard, PoisonError};

/// How many submissions a released buffer is kept for without being taken again (it goes at the
/// first release after them). A lit sample and a denoise are one submission each where the
/// device writes timestamps, and split (benchmark mode, or no timestamps: uploads, each pass,
/// reads) five and up to nine (SVGF with four à-trous steps), so a frame's buffers outlive the
/// next frame's calls; buffers of a size no longer asked for (a resized viewport, a bench's
/// previous size) go.
pub(crate) const KEPT_FOR_SUBMISSIONS: u64 = 16;

/// The kept bytes' bound, in multiples of the most bytes of transient buffers ever in use at
/// once. Two: a realtime loop alternates lit samples and a denoise, whose distinct buffers come
/// to 1.4–1.5 times that peak (`a_frame_loop_creates_buffers_in_its_first_frame_only`, 40×24
/// pixels, 2 spp: 396 bytes a pixel kept against a peak of 280 with TV, 380 against 256 with
/// SVGF); with one, 26 of a TV frame's 40 buffers were freed and made again every frame.
pub(crate) const KEPT_PEAKS: u64 = 2;

/// What a kept buffer may be reused for: a buffer of exactly this size (bytes), usage and memory
/// location. Exact, because a kernel binds its buffers whole and may read their length.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) struct BufferKind {
    pub size: u64,
    pub usage: vk::BufferUsageFlags,
    pub location: MemoryLocation,
}

/// A buffer and its bound memory that no command and no [`super::buffer::GpuBuffer`] uses.
pub(crate) struct Parked {
    pub buffer: vk::Buffer,
    pub allocation: Allocation,
}

/// A parked buffer with its kind and the submission count when it was released.
struct Kept {
    kind: BufferKind,
    parked: Parked,
    released_at: u64,
}

/// The kept buffers of one device ([`super::context::Core`]) and the accounting that bounds them.
#[derive(Default)]
pub(crate) struct Recycler {
    state: Mutex<State>,
}

/// What a [`Recycler`] guards.
#[derive(Default)]
struct State {
    /// The kept buffers, oldest release first.
    kept: Vec<Kept>,
    /// Their bytes.
    kept_bytes: u64,
    /// Bytes of the transient buffers in use now, and the most there have been at once.
    live_bytes: u64,
    peak_live_bytes: u64,
    /// Transient buffers created, and taken from the kept ones, since the device opened.
    #[cfg(test)]
    created: u64,
    #[cfg(test)]
    reused: u64,
}

impl State {
    /// Counts a buffer of `kind` in use.
    fn count_live(&mut self, kind: BufferKind) {
        self.live_bytes += kind.size;
        self.peak_live_bytes = self.peak_live_bytes.max(self.live_bytes);
    }

    /// Removes and returns the oldest kept buffer.
    fn give_up_oldest(&mut self) -> Option<Parked> {
        if self.kept.is_empty() {
            return None;
        }
        let oldest = self.kept.remove(0);
        self.kept_bytes -= oldest.kind.size;
        Some(oldest.parked)
    }
}

/// What a [`Recycler`] holds and has done, for tests.
#[cfg(test)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct RecyclerCounts {
    /// Transient buffers created and taken again since the device opened.
    pub created: u64,
    pub reused: u64,
    /// Buffers kept now, and their bytes.
    pub kept: usize,
    pub kept_bytes: u64,
    /// Bytes of transient buffers in use now, and the most at once.
    pub live_bytes: u64,
    pub peak_live_bytes: u64,
}

impl Recycler {
    fn state(&self) -> MutexGuard<'_, State> {
        // Every update leaves the state consistent before anything that could panic.
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// A kept buffer of `kind` to use again (the most recently released), counted in use; none
    /// when no kept buffer is of that kind.
    pub fn take(&self, kind: BufferKind) -> Option<Parked> {
        let mut state = self.state();
        let index = state.kept.iter().rposition(|kept| kept.kind == kind)?;
        let kept = state.kept.remove(index);
        state.kept_bytes -= kind.size;
        state.count_live(kind);
        #[cfg(test)]
        {
            state.reused += 1;
        }
        Some(kept.parked)
    }

    /// Counts a transient buffer of `kind` just created in use.
    pub fn created(&self, kind: BufferKind) {
        let mut state = self.state();
        state.count_live(kind);
        #[cfg(test)]
        {
            state.created += 1;
        }
    }

    /// Takes back a transient buffer of `kind` that is no longer used, released when `submitted`
    /// submissions had been made; returns the buffers the caller must free: those released more
    /// than [`KEPT_FOR_SUBMISSIONS`] submissions before, and the oldest ones the byte bound
    /// ([`KEPT_PEAKS`]) pushes out (`parked` itself always fits: it was counted in use, so in the
    /// peak).
    pub fn keep(&self, kind: BufferKind, parked: Parked, submitted: u64) -> Vec<Parked> {
        let mut state = self.state();
        debug_assert!(state.live_bytes >= kind.size, "a transient buffer released but never counted in use");
        state.live_bytes = state.live_bytes.saturating_sub(kind.size);
        let mut freed = Vec::new();
        while state.kept.first().is_some_and(|kept| kept.released_at + KEPT_FOR_SUBMISSIONS < submitted) {
            freed.extend(state.give_up_oldest());
        }
        let bound = KEPT_PEAKS * state.peak_live_bytes;
        while state.kept_bytes + kind.size > bound {
            match state.give_up_oldest() {
                Some(oldest) => freed.push(oldest),
                None => break,
            }
        }
        state.kept_bytes += kind.size;
        state.kept.push(Kept { kind, parked, released_at: submitted });
        freed
    }

    /// Every kept buffer, for the caller to free, and their bytes: when an allocation failed,
    /// when the engine releases them ([`crate::Backend::release_kept_memory`]), and at teardown.
    pub fn drain(&self) -> (Vec<Parked>, u64) {
        let mut state = self.state();
        let bytes = std::mem::take(&mut state.kept_bytes);
        (state.kept.drain(..).map(|kept| kept.parked).collect(), bytes)
    }

    /// What it holds and has done.
    #[cfg(test)]
    pub fn counts(&self) -> RecyclerCounts {
        let state = self.state();
        RecyclerCounts {
            created: state.created,
            reused: state.reused,
            kept: state.kept.len(),
            kept_bytes: state.kept_bytes,
            live_bytes: state.live_bytes,
            peak_live_bytes: state.peak_live_bytes,
        }
    }

    /// Calls `visit` on every kept buffer with its kind (tests fill them with ones).
    #[cfg(test)]
    pub fn for_each_kept(&self, mut visit: impl FnMut(BufferKind, &mut Parked)) {
        let mut state = self.state();
        for kept in &mut state.kept {
            visit(kept.kind, &mut kept.parked);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kind(size: u64) -> BufferKind {
        BufferKind { size, usage: vk::BufferUsageFlags::STORAGE_BUFFER, location: MemoryLocation::GpuOnly }
    }

    /// A parked buffer told apart by its handle (no device: the recycler never calls one).
    fn parked(handle: u64) -> Parked {
        use ash::vk::Handle;
        Parked { buffer: vk::Buffer::from_raw(handle), allocation: Allocation::default() }
    }

    fn handles(freed: &[Parked]) -> Vec<u64> {
        use ash::vk::Handle;
        freed.iter().map(|p| p.buffer.as_raw()).collect()
    }

    #[test]
    fn a_buffer_is_taken_again_only_for_its_exact_kind() {
        let recycler = Recycler::default();
        recycler.created(kind(64));
        assert!(handles(&recycler.keep(kind(64), parked(1), 0)).is_empty());
        assert!(recycler.take(kind(60)).is_none(), "another size");
        let staging = BufferKind { location: MemoryLocation::CpuToGpu, ..kind(64) };
        assert!(recycler.take(staging).is_none(), "another location");
        let upload = BufferKind { usage: vk::BufferUsageFlags::TRANSFER_SRC, ..kind(64) };
        assert!(recycler.take(upload).is_none(), "another usage");
        assert_eq!(handles(&recycler.take(kind(64)).into_iter().collect::<Vec<_>>()), [1]);
        assert!(recycler.take(kind(64)).is_none(), "taken once");
        let counts = recycler.counts();
        assert_eq!((counts.created, counts.reused, counts.kept, counts.live_bytes), (1, 1, 0, 64));
    }

    #[test]
    fn kept_buffers_age_out_after_the_kept_submissions() {
        let recycler = Recycler::default();
        for size in [64, 128] {
            recycler.created(kind(size));
        }
        recycler.keep(kind(64), parked(1), 10);
        // Released at 10, still kept by a release at 10 + KEPT_FOR_SUBMISSIONS …
        assert!(recycler.keep(kind(128), parked(2), 10 + KEPT_FOR_SUBMISSIONS).is_empty());
        // … and given up by the first release after that.
        let taken = recycler.take(kind(128)).unwrap();
        let freed = recycler.keep(kind(128), taken, 11 + KEPT_FOR_SUBMISSIONS);
        assert_eq!(handles(&freed), [1]);
        assert_eq!((recycler.counts().kept, recycler.counts().kept_bytes), (1, 128));
        let (drained, bytes) = recycler.drain();
        assert_eq!((handles(&drained), bytes), (vec![2], 128));
        assert_eq!((recycler.counts().kept, recycler.counts().kept_bytes), (0, 0));
    }

    #[test]
    fn kept_bytes_stay_within_twice_the_most_ever_in_use_at_once() {
        let recycler = Recycler::default();
        // At most 300 bytes in use at once (100 + 200): 600 may be kept.
        recycler.created(kind(100));
        recycler.created(kind(200));
        recycler.keep(kind(100), parked(1), 0);
        recycler.keep(kind(200), parked(2), 0);
        // Calls of other lengths, one buffer at a time: each release pushes out the oldest
        // until the kept bytes fit 600.
        let release = |size, handle| {
            recycler.created(kind(size));
            handles(&recycler.keep(kind(size), parked(handle), handle))
        };
        assert!(release(150, 3).is_empty(), "450 kept");
        assert!(release(120, 4).is_empty(), "570 kept");
        assert_eq!(release(90, 5), [1], "660 less the oldest 100");
        assert_eq!(release(250, 6), [2, 3], "810 less 200 and 150");
        let counts = recycler.counts();
        assert_eq!((counts.kept_bytes, counts.live_bytes, counts.peak_live_bytes), (460, 0, 300));
        let (drained, bytes) = recycler.drain();
        assert_eq!((handles(&drained), bytes), (vec![4, 5, 6], 460));
    }
}
