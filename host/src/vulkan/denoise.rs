//! The denoise passes on a Vulkan device: one compute pipeline per pass entry point, the
//! intermediate images kept on the device between passes.

use super::batch::Batch;
use super::buffer::GpuBuffer;
use super::context::Core;
use super::kernel::ComputeKernel;
use super::pass::Resource;
use crate::backend::StageReport;
use crate::denoise::{bilateral_invocations, DenoiseInput, DenoiseMethod, DenoisePass, WorkingBuffers};
use crate::error::{Error, Result};
use ash::vk;
use glam::Vec4;
use raywave_shared::bindings::denoise as counts;
use raywave_shared::bindings::WORKGROUP_SIZE;
use raywave_shared::denoise::axis;
use raywave_shared::DenoiseParams;
use std::sync::Arc;

/// The pipelines of every denoise pass.
pub(crate) struct DenoiseKernels {
    ratio: ComputeKernel,
    noise: ComputeKernel,
    noise_blur: ComputeKernel,
    bilateral: ComputeKernel,
    composite: ComputeKernel,
    svgf_variance: ComputeKernel,
    svgf_atrous: ComputeKernel,
    svgf_composite: ComputeKernel,
    copy_probe: ComputeKernel,
}

impl DenoiseKernels {
    /// Builds the pipelines.
    pub fn new(core: &Arc<Core>) -> Result<Self> {
        let push = std::mem::size_of::<DenoiseParams>() as u32;
        let kernel_sized = |entry, count: u32, workgroup_size| {
            let layout: Vec<_> = (0..count).map(|b| (b, vk::DescriptorType::STORAGE_BUFFER)).collect();
            ComputeKernel::new(core, entry, &layout, push, workgroup_size)
        };
        let kernel = |entry, count| kernel_sized(entry, count, core.workgroup_sizes.denoise);
        Ok(Self {
            ratio: kernel("entry::denoise_ratio", counts::RATIO)?,
            noise: kernel("entry::denoise_noise", counts::NOISE)?,
            noise_blur: kernel("entry::denoise_noise_blur", counts::NOISE_BLUR)?,
            // Its workgroup-memory tile is sized for the compiled workgroup size (`TILE_LEN`).
            bilateral: kernel_sized("entry::denoise_bilateral", counts::BILATERAL, WORKGROUP_SIZE)?,
            composite: kernel("entry::denoise_composite", counts::COMPOSITE)?,
            svgf_variance: kernel("entry::svgf_variance", counts::SVGF_VARIANCE)?,
            svgf_atrous: kernel("entry::svgf_atrous", counts::SVGF_ATROUS)?,
            svgf_composite: kernel("entry::svgf_composite", counts::SVGF_COMPOSITE)?,
            copy_probe: kernel("entry::copy_probe", counts::COPY_PROBE)?,
        })
    }

    /// Runs the copy probe on `source` (already checked against `params`) and reads the copy
    /// back, the upload, the dispatch and the read in one batch; the time is the dispatch's
    /// ([`super::pass::Pass::timing`]: GPU timestamps where the device has them).
    pub fn copy_probe(
        &self,
        core: &Arc<Core>,
        params: &DenoiseParams,
        source: &[Vec4],
    ) -> Result<(Vec<Vec4>, StageReport)> {
        let pixels = params.pixels();
        let on_device = GpuBuffer::storage::<Vec4>(core, pixels, "copy probe source")?;
        let copy = GpuBuffer::storage::<Vec4>(core, pixels, "copy probe copy")?;
        let mut batch = Batch::new(core);
        batch.upload(&on_device, source)?;
        let run = self.copy_probe.add_to(
            &mut batch,
            &[Resource::Buffer(&on_device), Resource::Buffer(&copy)],
            bytemuck::bytes_of(params),
            pixels,
        )?;
        let read = batch.read(&copy, pixels as usize)?;
        let done = batch.submit()?;
        Ok((done.read(&read)?, done.timing(run).report("copy probe", 0)))
    }

    /// Runs `method` on `input` (already checked against `params`) in one batch
    /// ([`Batch::submit`]: one submission where the device writes timestamps): uploads the
    /// inputs its passes read into buffers it allocates with the working buffers they write
    /// ([`WorkingBuffers`]), runs every pass, and reads back the colour and the composite's
    /// sanitized count. Timings are the passes' ([`super::pass::Pass::timing`]: GPU timestamps
    /// where the device has them).
    pub fn run(
        &self,
        core: &Arc<Core>,
        method: DenoiseMethod,
        params: &DenoiseParams,
        input: &DenoiseInput,
    ) -> Result<(Vec<Vec4>, Vec<StageReport>)> {
        let pixels = params.pixels();
        let passes = method.passes(params);
        // Only what the passes use is allocated at the image's size; any other buffer is an
        // empty one (`GpuBuffer::new`'s least size, 4 bytes) that no pass binds.
        let needs = WorkingBuffers::for_passes(&passes);
        let sized = |needed: bool| if needed { pixels } else { 0 };
        let image = |len, name| GpuBuffer::storage::<Vec4>(core, len, name);
        let position = image(sized(needs.guides_read()), "denoise position")?;
        let normal = image(sized(needs.guides_read()), "denoise normal")?;
        let analytic = image(pixels, "denoise analytic")?;
        let emitted = image(pixels, "denoise emitted")?;
        // Ping-pong pairs: [current] holds the S_N / U_N / ratio so far, the other receives the
        // next.
        let shadowed = [image(pixels, "S_N")?, image(sized(needs.filtered), "S_N filtered")?];
        let unshadowed = [image(pixels, "U_N")?, image(sized(needs.filtered), "U_N filtered")?];
        let ratio = [image(sized(needs.ratio), "ratio")?, image(sized(needs.filtered_ratio), "ratio filtered")?];
        let (mut filtered, mut ratio_current) = (0, 0);
        let noise_raw = GpuBuffer::storage::<f32>(core, sized(needs.noise), "noise raw")?;
        let noise = GpuBuffer::storage::<f32>(core, sized(needs.noise), "noise")?;
        let color = image(pixels, "denoised colour")?;
        // Only the composites, the denoiser's boundary, count (their last binding).
        let counter = GpuBuffer::counter(core, "denoise")?;
        let mut batch = Batch::new(core);
        if needs.guides_read() {
            batch.upload(&position, &input.position)?;
            batch.upload(&normal, &input.normal)?;
        }
        batch.upload(&analytic, &input.analytic)?;
        batch.upload(&emitted, &input.emitted)?;
        batch.upload(&shadowed[0], &input.shadowed)?;
        batch.upload(&unshadowed[0], &input.unshadowed)?;
        let mut runs = Vec::with_capacity(passes.len());
        for &pass in &passes {
            let b = Resource::Buffer;
            let run = match pass {
                DenoisePass::Ratio => self.ratio.add_to(
                    &mut batch,
                    &[b(&shadowed[0]), b(&unshadowed[0]), b(&ratio[0])],
                    bytemuck::bytes_of(params),
                    pixels,
                )?,
                DenoisePass::Noise => {
                    self.noise.add_to(&mut batch, &[b(&ratio[0]), b(&noise_raw)], bytemuck::bytes_of(params), pixels)?
                }
                DenoisePass::NoiseBlur => self.noise_blur.add_to(
                    &mut batch,
                    &[b(&noise_raw), b(&noise)],
                    bytemuck::bytes_of(params),
                    pixels,
                )?,
                DenoisePass::BilateralX | DenoisePass::BilateralY => {
                    let along = if pass == DenoisePass::BilateralX { axis::X } else { axis::Y };
                    let params = DenoiseParams { axis: along, ..*params };
                    // Already checked by `DenoiseInput::check`: a count past 32 bits would wrap.
                    let invocations = bilateral_invocations(&params)
                        .map_err(|reason| Error::InvalidParameter { name: "denoise", reason })?;
                    let (from, to) = (filtered, 1 - filtered);
                    filtered = to;
                    self.bilateral.add_to(
                        &mut batch,
                        &[
                            b(&position),
                            b(&normal),
                            b(&noise),
                            b(&shadowed[from]),
                            b(&unshadowed[from]),
                            b(&shadowed[to]),
                            b(&unshadowed[to]),
                        ],
                        bytemuck::bytes_of(&params),
                        invocations,
                    )?
                }
                DenoisePass::Composite => self.composite.add_to(
                    &mut batch,
                    &[
                        b(&analytic),
                        b(&emitted),
                        b(&shadowed[filtered]),
                        b(&unshadowed[filtered]),
                        b(&color),
                        b(&counter),
                    ],
                    bytemuck::bytes_of(params),
                    pixels,
                )?,
                DenoisePass::SvgfVariance | DenoisePass::SvgfAtrous { .. } => {
                    let (kernel, params) = match pass {
                        DenoisePass::SvgfAtrous { step } => (&self.svgf_atrous, DenoiseParams { step, ..*params }),
                        _ => (&self.svgf_variance, *params),
                    };
                    let (from, to) = (ratio_current, 1 - ratio_current);
                    ratio_current = to;
                    kernel.add_to(
                        &mut batch,
                        &[b(&ratio[from]), b(&position), b(&normal), b(&ratio[to])],
                        bytemuck::bytes_of(&params),
                        pixels,
                    )?
                }
                DenoisePass::SvgfComposite => self.svgf_composite.add_to(
                    &mut batch,
                    &[b(&analytic), b(&emitted), b(&ratio[ratio_current]), b(&color), b(&counter)],
                    bytemuck::bytes_of(params),
                    pixels,
                )?,
            };
            runs.push((pass, run));
        }
        let count = batch.read::<u32>(&counter, 1)?;
        let colour = batch.read::<Vec4>(&color, pixels as usize)?;
        let done = batch.submit()?;
        // Each method has one composite, its last pass: the counter is that pass's count.
        let sanitized = done.count(&count)?;
        let timings = runs
            .into_iter()
            .map(|(pass, run)| done.timing(run).report(pass.name(), if pass.is_composite() { sanitized } else { 0 }))
            .collect();
        Ok((done.read(&colour)?, timings))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::denoise::TV_PASSES;
    use crate::vulkan::context::open;
    use crate::vulkan::ContextOptions;

    /// An image of `pixels` colours that differ from pixel to pixel and from image `k` to image.
    fn image(k: u32, pixels: u32) -> Vec<Vec4> {
        (0..pixels).map(|i| Vec4::new(k as f32, i as f32, 0.5 + (i % 7) as f32, 1.0)).collect()
    }

    /// A frame's denoise input for `params`, with a shadowed quarter of image `k`'s unshadowed
    /// light, and guides and emission that differ with `k` too.
    fn frame(k: u32, params: &DenoiseParams) -> DenoiseInput {
        let pixels = params.pixels();
        let input = DenoiseInput {
            position: (0..pixels).map(|i| Vec4::new(i as f32, k as f32, 1.0, 1.0 + ((i + k) % 3) as f32)).collect(),
            normal: vec![Vec4::new(0.0, 0.0, 1.0, 0.5); pixels as usize],
            analytic: image(k + 7, pixels),
            emitted: image(k, pixels).iter().map(|c| *c * 0.01).collect(),
            shadowed: image(k, pixels).iter().map(|c| *c * 0.25).collect(),
            unshadowed: image(k, pixels),
        };
        input.check(params).unwrap();
        input
    }

    /// `input` denoised by `method` on `core` with kernels of their own: the colour as bits (so
    /// that any NaN compares too), the passes' reports and the submissions it made.
    fn denoised(
        core: &Arc<Core>,
        method: DenoiseMethod,
        params: &DenoiseParams,
        input: &DenoiseInput,
    ) -> (Vec<u32>, Vec<StageReport>, u64) {
        let kernels = DenoiseKernels::new(core).unwrap();
        let before = core.submissions.load(std::sync::atomic::Ordering::Relaxed);
        let (colour, reports) = kernels.run(core, method, params, input).unwrap();
        let submissions = core.submissions.load(std::sync::atomic::Ordering::Relaxed) - before;
        (bytemuck::cast_slice::<Vec4, u32>(&colour).to_vec(), reports, submissions)
    }

    /// A denoise takes the buffers the frame before it left ([`super::super::recycle::Recycler`]):
    /// the second frame of a size creates none, and, with every kept buffer filled with ones
    /// first, its colour is, bit for bit, what a device that had denoised nothing makes of the
    /// same input — every pass of TV and SVGF writes what the next reads, so no stale contents
    /// reach the image; no buffer is in use after a frame. Every Vulkan device; without one it
    /// fails under CI and is skipped loudly elsewhere.
    #[test]
    fn a_second_frame_reuses_the_first_ones_buffers_and_reads_none_of_their_contents() {
        let devices = super::super::devices_for_test("denoise buffer reuse");
        let params = DenoiseParams::new(24, 16);
        let options = ContextOptions { validation: true, ..Default::default() };
        for device in &devices {
            for method in [DenoiseMethod::Tv, DenoiseMethod::Svgf] {
                let denoise = |core: &Arc<Core>, k| denoised(core, method, &params, &frame(k, &params)).0;
                let core = open(device.index, &options).unwrap();
                denoise(&core, 1);
                let first = core.recycler.counts();
                super::super::buffer::fill_kept_with_ones(&core);
                let second = denoise(&core, 2);
                let after = core.recycler.counts();
                assert!(after.created == first.created && after.reused > first.reused, "{} {method:?}", device.name);
                assert_eq!(after.live_bytes, 0, "{} {method:?}: {after:?}", device.name);
                let fresh = denoise(&open(device.index, &options).unwrap(), 2);
                assert!(second == fresh, "{} {method:?}: a reused buffer's contents reached the image", device.name);
                let messages = core.validation_log().messages();
                assert!(messages.is_empty(), "{}: {messages:?}", device.name);
            }
        }
    }

    /// Where the device writes no timestamps (CI's lavapipe does, so here they are switched off
    /// on a second device handle), a denoise is a submission for the uploads, one per pass and
    /// one for the reads, each pass timed by the host clock around its own submission: every
    /// pass's time is positive, and the colour is, bit for bit, the one-submission frame's. The
    /// only run of that path in CI. Every Vulkan device; without one it fails under CI and is
    /// skipped loudly elsewhere.
    #[test]
    fn without_timestamps_each_pass_is_timed_by_the_host_clock() {
        let devices = super::super::devices_for_test("host-clock timing");
        let params = DenoiseParams::new(24, 16);
        let input = frame(2, &params);
        let options = ContextOptions { validation: true, ..Default::default() };
        for device in &devices {
            let timed = open(device.index, &options).unwrap();
            let mut untimed = open(device.index, &options).unwrap();
            Arc::get_mut(&mut untimed).expect("nothing shares a device just opened").info.timestamps = false;
            for method in [DenoiseMethod::Tv, DenoiseMethod::Svgf] {
                let denoise = |core: &Arc<Core>| denoised(core, method, &params, &input);
                let (colour, _, _) = denoise(&timed);
                let (untimed_colour, reports, submissions) = denoise(&untimed);
                assert!(untimed_colour == colour, "{} {method:?}: the split frame's colour", device.name);
                assert_eq!(submissions, method.passes(&params).len() as u64 + 2, "{} {method:?}", device.name);
                let seconds: Vec<f64> = reports.iter().map(|report| report.seconds).collect();
                assert!(seconds.iter().all(|s| *s > 0.0 && s.is_finite()), "{} {method:?}: {seconds:?}", device.name);
            }
            for core in [&timed, &untimed] {
                let messages = core.validation_log().messages();
                assert!(messages.is_empty(), "{}: {messages:?}", device.name);
            }
        }
    }

    /// Runs of one pass wait side by side — two in one batch, a third in another live batch —
    /// each on a descriptor set and timestamps of its own (the pass's slots,
    /// [`super::super::pass::Pass::prepare`]): each copy probe copies its own image, though the
    /// second batch is submitted first and split into a submission per step (the path of a device
    /// without timestamps), and the large copy takes longer than the small one beside it, which
    /// shared timestamps would have given one time. The slots are reused once the batches are
    /// gone, and neither a batch dropped unsubmitted nor a refused run keeps one. Every Vulkan
    /// device; without one it fails under CI and is skipped loudly elsewhere.
    #[test]
    fn runs_of_one_pass_side_by_side_bind_their_own_buffers() {
        let devices = super::super::devices_for_test("pass slots");
        // Run 1 copies 8192 times as many pixels as runs 0 and 2.
        let sizes = [DenoiseParams::new(16, 8), DenoiseParams::new(1024, 1024), DenoiseParams::new(16, 8)];
        for device in &devices {
            let core = open(device.index, &ContextOptions { validation: true, ..Default::default() }).unwrap();
            let kernels = DenoiseKernels::new(&core).unwrap();
            let buffers = |name| -> Vec<GpuBuffer> {
                sizes.iter().map(|p| GpuBuffer::storage::<Vec4>(&core, p.pixels(), name).unwrap()).collect()
            };
            let (sources, copies) = (buffers("source"), buffers("copy"));
            let (mut first, mut second) = (Batch::new(&core), Batch::new(&core));
            let mut added = Vec::new();
            for (k, params) in sizes.iter().enumerate() {
                let batch = if k < 2 { &mut first } else { &mut second };
                let pixels = params.pixels();
                batch.upload(&sources[k], &image(k as u32, pixels)).unwrap();
                let resources = [Resource::Buffer(&sources[k]), Resource::Buffer(&copies[k])];
                let run = kernels.copy_probe.add_to(batch, &resources, bytemuck::bytes_of(params), pixels).unwrap();
                added.push((run, batch.read::<Vec4>(&copies[k], pixels as usize).unwrap()));
            }
            assert_eq!(kernels.copy_probe.slot_count(), 3, "{}", device.name);
            let second = second.submit_in(false).unwrap();
            let first = first.submit().unwrap();
            let mut seconds = Vec::new();
            for (k, (run, read)) in added.iter().enumerate() {
                let done = if k < 2 { &first } else { &second };
                assert!(done.read(read).unwrap() == image(k as u32, sizes[k].pixels()), "{}: copy {k}", device.name);
                seconds.push(done.timing(*run).seconds);
            }
            assert!(seconds[1] > seconds[0] && seconds[2] > 0.0, "{}: {seconds:?}", device.name);
            drop((first, second));
            let params = sizes[0];
            let mut unsubmitted = Batch::new(&core);
            let resources = [Resource::Buffer(&sources[0]), Resource::Buffer(&copies[0])];
            kernels.copy_probe.add_to(&mut unsubmitted, &resources, bytemuck::bytes_of(&params), 1).unwrap();
            drop(unsubmitted);
            let refused = kernels.copy_probe.add_to(&mut Batch::new(&core), &resources[..1], &[], 1);
            assert!(matches!(refused, Err(Error::InvalidParameter { name: "resources", .. })));
            let (_, report) = kernels.copy_probe(&core, &params, &image(7, params.pixels())).unwrap();
            assert_eq!((report.stage, kernels.copy_probe.slot_count()), ("copy probe", 3), "{}", device.name);
            let messages = core.validation_log().messages();
            assert!(messages.is_empty(), "{}: {messages:?}", device.name);
        }
    }

    /// A denoise is one submission where the device writes timestamps — its uploads, every pass
    /// and its reads — and one for the uploads, one per pass and one for the reads where it does
    /// not; it had been a submission per input, per pass and per read (fourteen for TV). The
    /// kernels that run more than once a frame (TV's bilateral, SVGF's à-trous) hold a slot per
    /// run, made by the first frame and reused by the next. Every Vulkan device; without one it
    /// fails under CI and is skipped loudly elsewhere.
    #[test]
    fn a_denoise_is_one_submission_where_the_device_writes_timestamps() {
        let devices = super::super::devices_for_test("denoise submissions");
        let params = DenoiseParams::new(24, 16);
        let pixels = params.pixels();
        let input = frame(2, &params);
        for device in &devices {
            let core = open(device.index, &ContextOptions { validation: true, ..Default::default() }).unwrap();
            let kernels = DenoiseKernels::new(&core).unwrap();
            for method in [DenoiseMethod::Tv, DenoiseMethod::Svgf] {
                let passes = method.passes(&params);
                let mut submissions = Vec::new();
                for _frame in 0..2 {
                    let before = core.submissions.load(std::sync::atomic::Ordering::Relaxed);
                    let (color, reports) = kernels.run(&core, method, &params, &input).unwrap();
                    submissions.push(core.submissions.load(std::sync::atomic::Ordering::Relaxed) - before);
                    assert!(color.len() == pixels as usize && color.iter().all(|c| c.is_finite()));
                    let names: Vec<_> = reports.iter().map(|r| r.stage).collect();
                    assert_eq!(names, passes.iter().map(|p| p.name()).collect::<Vec<_>>(), "{}", device.name);
                }
                let expected = if core.info.timestamps { 1 } else { passes.len() as u64 + 2 };
                assert_eq!(submissions, [expected; 2], "{} {method:?}", device.name);
            }
            let bilateral = TV_PASSES.iter().filter(|p| matches!(p, DenoisePass::BilateralX | DenoisePass::BilateralY));
            let svgf = DenoiseMethod::Svgf.passes(&params);
            let atrous = svgf.iter().filter(|p| matches!(p, DenoisePass::SvgfAtrous { .. }));
            assert_eq!(
                (kernels.bilateral.slot_count(), kernels.svgf_atrous.slot_count(), kernels.composite.slot_count()),
                (bilateral.count(), atrous.count(), 1),
                "{}: a slot per run in a frame, reused by the next",
                device.name
            );
            let messages = core.validation_log().messages();
            assert!(messages.is_empty(), "{}: {messages:?}", device.name);
        }
    }
}
