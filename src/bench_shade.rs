//! `raywave bench shade`: shading throughput — resolving each camera ray's hit, the analytic `U`
//! of every light and one MIS shadow-ray sample — on the CPU and on the best Vulkan device, there
//! in each shade workgroup size asked for ([`crate::WorkgroupSizes::shade`], occupancy tuning).
//!
//! The camera rays and their hits (one sample per pixel) are made once on the CPU; each backend
//! then shades them untimed until its times stop falling and timed `repeats` times, the median
//! reported (as every `raywave bench` measures). The Vulkan backend runs in benchmark mode (its shade
//! dispatch repeated to keep the GPU busy, `crate::BackendOptions::sustain_seconds`), timed by
//! GPU timestamps around the dispatch, without the uploads and readbacks around it.

use crate::bench::{check_rays_per_side, check_repeats, measure, CPU_SETTLE_SECONDS};
use crate::frame::{generate_params, sampler_params};
use crate::shading::ShadeData;
use crate::shared::sampling::sampler_kind;
use crate::{Backend, Result, Scene};

/// What to measure.
#[derive(Clone, Debug)]
pub struct ShadeBenchOptions {
    /// `builtin:NAME` or a scene file.
    pub scene: String,
    /// Camera rays per side (≥ 1, within the CPU backend's image size): `resolution²` samples.
    pub resolution: u32,
    /// Timed repetitions per measurement (≥ 1); the median is reported.
    pub repeats: u32,
    /// Also measure the best Vulkan device, if there is one.
    pub vulkan: bool,
    /// The Vulkan device's shade workgroup sizes ([`crate::WorkgroupSizes::shade`]) and warm-up.
    pub vulkan_options: crate::bench_device::VulkanBenchOptions,
}

/// One measurement, printed as one JSON line.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ShadeMeasurement {
    /// Always `shade`.
    pub stage: &'static str,
    /// The backend's name.
    #[serde(rename = "impl")]
    pub implementation: String,
    /// The scene shaded.
    pub scene: String,
    /// Samples (camera rays) shaded per repetition.
    pub samples: usize,
    /// Lights whose `U` each sample computes.
    pub lights: usize,
    /// Median seconds per repetition (Vulkan: GPU timestamps of the dispatch).
    pub seconds: f64,
    /// Millions of samples per second.
    pub msamples_per_s: f64,
    /// Vulkan: shade dispatches back to back in each timed submission (benchmark mode, the last
    /// repetition's), `seconds` their mean; 1 on the CPU.
    pub dispatches: u32,
    /// Seconds of untimed runs before the measurement, until the times had stopped falling.
    pub warm_up_seconds: f64,
    /// Vulkan: invocations per shade workgroup; absent on the CPU.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub workgroup_size: Option<u32>,
}

impl crate::output_line::OutputLine for ShadeMeasurement {
    fn json(&self) -> String {
        crate::output_line::json_object(self)
    }
    fn row(&self) -> String {
        let workgroup = crate::bench_device::workgroup_note(self.workgroup_size);
        format!(
            "{:<48} {:>8} samples {:>3} lights {:>9.4} s {:>8.2} Msamples/s  ×{}{workgroup}",
            self.implementation, self.samples, self.lights, self.seconds, self.msamples_per_s, self.dispatches
        )
    }
}

/// Runs the benchmark, handing each line to `emit` as soon as it is measured.
pub fn bench_shade(options: &ShadeBenchOptions, mut emit: impl FnMut(&ShadeMeasurement)) -> Result<()> {
    check_repeats(options.repeats)?;
    let (side, mut cpu) = (options.resolution, crate::cpu::CpuBackend::new());
    check_rays_per_side(side)?;
    #[cfg_attr(not(feature = "vulkan"), allow(unused_variables))]
    let vulkan_device = options.vulkan_options.device(options.vulkan, crate::StreamStage::Shade, [side, side])?;
    let scene = Scene::load(&options.scene)?;
    let data = ShadeData::new(&scene)?;
    cpu.load_scene(&scene)?;
    let (rays, _) = cpu.generate(&generate_params(&scene, side, side, 1))?;
    let (hits, _) = cpu.trace(&rays)?;
    let params = data.params(sampler_params(sampler_kind::ZSOBOL, 1, side, side, 1), side, side, 0);
    let mut shade_on = |backend: &mut dyn Backend, settle: f64, workgroup_size: Option<u32>| -> Result<()> {
        let measured =
            measure(settle, options.repeats, 1, || Ok(vec![backend.shade(&params, &data, &rays, &hits)?.1]))?;
        let (seconds, dispatches) = (measured.stages[0].seconds, measured.stages[0].dispatches);
        emit(&ShadeMeasurement {
            stage: "shade",
            implementation: backend.name(),
            scene: options.scene.clone(),
            samples: rays.len(),
            lights: data.lights.len(),
            seconds,
            msamples_per_s: crate::bench::per_second(rays.len() as f64, seconds) / 1e6,
            dispatches,
            warm_up_seconds: measured.warm_up_seconds,
            workgroup_size,
        });
        Ok(())
    };
    shade_on(&mut cpu, CPU_SETTLE_SECONDS, None)?;
    #[cfg(feature = "vulkan")]
    if let Some(device) = vulkan_device {
        for &size in &device.sizes {
            let mut backend = device.open(size, None, Default::default())?;
            let runs = backend.workgroup_sizes().shade;
            shade_on(&mut backend, device.settle_seconds, Some(runs))?;
        }
    }
    Ok(())
}
