//! The denoise passes on a Vulkan device: one compute pipeline per pass entry point, the
//! intermediate images kept on the device between passes.

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
    /// back; the time is the dispatch's ([`super::pass::Pass::timing`]: GPU timestamps where the
    /// device has them).
    pub fn copy_probe(
        &self,
        core: &Arc<Core>,
        params: &DenoiseParams,
        source: &[Vec4],
    ) -> Result<(Vec<Vec4>, StageReport)> {
        let pixels = params.pixels();
        let source = GpuBuffer::storage_with(core, source, "copy probe source")?;
        let copy = GpuBuffer::storage::<Vec4>(core, pixels, "copy probe copy")?;
        let timing = self.copy_probe.dispatch(
            &[Resource::Buffer(&source), Resource::Buffer(&copy)],
            bytemuck::bytes_of(params),
            pixels,
        )?;
        Ok((copy.read(pixels as usize)?, timing.report("copy probe", 0)))
    }

    /// Runs `method` on `input` (already checked against `params`): uploads the inputs its passes
    /// read, allocates the working buffers they write ([`WorkingBuffers`]), runs every pass on the
    /// device and reads the colour back. Timings are the passes'
    /// ([`super::pass::Pass::timing`]: GPU timestamps where the device has them).
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
        let guide = |data: &[Vec4], name| {
            if needs.guides_read() {
                GpuBuffer::storage_with(core, data, name)
            } else {
                GpuBuffer::storage::<Vec4>(core, 0, name)
            }
        };
        let position = guide(&input.position, "denoise position")?;
        let normal = guide(&input.normal, "denoise normal")?;
        let analytic = GpuBuffer::storage_with(core, &input.analytic, "denoise analytic")?;
        let emitted = GpuBuffer::storage_with(core, &input.emitted, "denoise emitted")?;
        // Ping-pong pairs: [0] holds the current S_N / U_N / ratio, [1] receives the next.
        let mut shadowed = [
            GpuBuffer::storage_with(core, &input.shadowed, "S_N")?,
            GpuBuffer::storage::<Vec4>(core, sized(needs.filtered), "S_N filtered")?,
        ];
        let mut unshadowed = [
            GpuBuffer::storage_with(core, &input.unshadowed, "U_N")?,
            GpuBuffer::storage::<Vec4>(core, sized(needs.filtered), "U_N filtered")?,
        ];
        let mut ratio = [
            GpuBuffer::storage::<Vec4>(core, sized(needs.ratio), "ratio")?,
            GpuBuffer::storage::<Vec4>(core, sized(needs.filtered_ratio), "ratio filtered")?,
        ];
        let noise_raw = GpuBuffer::storage::<f32>(core, sized(needs.noise), "noise raw")?;
        let noise = GpuBuffer::storage::<f32>(core, sized(needs.noise), "noise")?;
        let color = GpuBuffer::storage::<Vec4>(core, pixels, "denoised colour")?;
        // Only the composites, the denoiser's boundary, count (their last binding).
        let counter = GpuBuffer::counter(core, "denoise")?;
        let mut timings = Vec::new();
        for pass in passes {
            let b = Resource::Buffer;
            let timing = match pass {
                DenoisePass::Ratio => self.ratio.dispatch(
                    &[b(&shadowed[0]), b(&unshadowed[0]), b(&ratio[0])],
                    bytemuck::bytes_of(params),
                    pixels,
                )?,
                DenoisePass::Noise => {
                    self.noise.dispatch(&[b(&ratio[0]), b(&noise_raw)], bytemuck::bytes_of(params), pixels)?
                }
                DenoisePass::NoiseBlur => {
                    self.noise_blur.dispatch(&[b(&noise_raw), b(&noise)], bytemuck::bytes_of(params), pixels)?
                }
                DenoisePass::BilateralX | DenoisePass::BilateralY => {
                    let along = if pass == DenoisePass::BilateralX { axis::X } else { axis::Y };
                    let params = DenoiseParams { axis: along, ..*params };
                    // Already checked by `DenoiseInput::check`: a count past 32 bits would wrap.
                    let invocations = bilateral_invocations(&params)
                        .map_err(|reason| Error::InvalidParameter { name: "denoise", reason })?;
                    let timing = self.bilateral.dispatch(
                        &[
                            b(&position),
                            b(&normal),
                            b(&noise),
                            b(&shadowed[0]),
                            b(&unshadowed[0]),
                            b(&shadowed[1]),
                            b(&unshadowed[1]),
                        ],
                        bytemuck::bytes_of(&params),
                        invocations,
                    )?;
                    shadowed.swap(0, 1);
                    unshadowed.swap(0, 1);
                    timing
                }
                DenoisePass::Composite => self.composite.dispatch(
                    &[b(&analytic), b(&emitted), b(&shadowed[0]), b(&unshadowed[0]), b(&color), b(&counter)],
                    bytemuck::bytes_of(params),
                    pixels,
                )?,
                DenoisePass::SvgfVariance => {
                    let timing = self.svgf_variance.dispatch(
                        &[b(&ratio[0]), b(&position), b(&normal), b(&ratio[1])],
                        bytemuck::bytes_of(params),
                        pixels,
                    )?;
                    ratio.swap(0, 1);
                    timing
                }
                DenoisePass::SvgfAtrous { step } => {
                    let params = DenoiseParams { step, ..*params };
                    let timing = self.svgf_atrous.dispatch(
                        &[b(&ratio[0]), b(&position), b(&normal), b(&ratio[1])],
                        bytemuck::bytes_of(&params),
                        pixels,
                    )?;
                    ratio.swap(0, 1);
                    timing
                }
                DenoisePass::SvgfComposite => self.svgf_composite.dispatch(
                    &[b(&analytic), b(&emitted), b(&ratio[0]), b(&color), b(&counter)],
                    bytemuck::bytes_of(params),
                    pixels,
                )?,
            };
            // Each method has one composite, its last pass: the counter is that pass's count.
            let sanitized = if pass.is_composite() { counter.read_count()? } else { 0 };
            timings.push(timing.report(pass.name(), sanitized));
        }
        Ok((color.read(pixels as usize)?, timings))
    }
}
