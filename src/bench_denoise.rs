//! `raywave bench denoise`: seconds per denoise pass and the bytes each must move per second, for
//! one frame (1920×1080 by default) of a built-in scene, on the CPU and on a Vulkan device.
//!
//! The frame's inputs (`U`, `U_N`, `S_N` at `spp` samples and the G-buffer) are shaded once on the
//! CPU; then each backend runs each denoiser untimed until its times stop falling (the bench's
//! warm-up)
//! and timed `repeats` times, and the median per pass is reported. The Vulkan backend is opened in
//! benchmark mode: each pass's timed submission repeats its dispatch to keep the GPU busy for
//! 50 ms, so that it holds its clocks (`crate::BackendOptions::sustain_seconds`).
//! "Bytes" counts every buffer a pass reads or writes once ([`crate::denoise::DenoisePass::bytes_per_pixel`]) —
//! the traffic of an ideal cache — so `gb_per_s` is the effective bandwidth, and on a GPU with a
//! known peak (`--peak-gbps`, or the datasheet value of an NVIDIA H100 or H200 model,
//! [`known_peak_gbps`]) its fraction.
//! On every backend it is also set against that backend's copy probe ([`Backend::copy_probe`]):
//! a pass that only reads and writes one `Vec4` per pixel of the same frame, the bandwidth a
//! memory-bound pass can reach there.

use crate::bench::{measure, Measured, CPU_SETTLE_SECONDS};
use crate::denoise::{check_radius, frame_params, DenoiseInput, DenoiseMethod};
use crate::lit_frame::{shade_samples, LitFrameSettings};
use crate::shading::ShadeData;
use crate::shared::DenoiseParams;
use crate::{Backend, Result, Scene};
use glam::Vec4;

/// What to measure.
#[derive(Clone, Debug)]
pub struct DenoiseBenchOptions {
    /// `builtin:NAME` or a scene file.
    pub scene: String,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Samples per pixel of the shaded input (the TV filter narrows as `1/√N`), checked by
    /// [`crate::frame::check_samples_per_pixel`].
    pub spp: u32,
    /// Timed repetitions per denoiser (≥ 1); the median per pass is reported.
    pub repeats: u32,
    /// Also measure the best Vulkan device, if there is one.
    pub vulkan: bool,
    /// Peak memory bandwidth of the Vulkan device in GB/s (finite, > 0), if known to the caller.
    pub peak_gbps: Option<f64>,
    /// The filter radius R in pixels (`1..=MAX_RADIUS`); `None` follows the frame size
    /// ([`DenoiseParams::default_radius`]: 6 at 1080p). The noise lines and the bilateral
    /// passes tap `2R + 1` pixels each and SVGF's à-trous iterations follow R, so their time
    /// does too (their bytes, counted once per buffer, do not).
    pub denoise_radius: Option<u32>,
    /// The Vulkan device's workgroup sizes of the per-pixel passes
    /// ([`crate::WorkgroupSizes::denoise`]; the bilateral passes keep 64) and warm-up.
    pub vulkan_options: crate::bench_device::VulkanBenchOptions,
}

/// One pass (or a whole denoiser, `pass = "total"`) on one backend, printed as one JSON line.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DenoiseMeasurement {
    /// Always `denoise`.
    pub stage: &'static str,
    /// The backend's name.
    #[serde(rename = "impl")]
    pub implementation: String,
    /// `tv` or `svgf`.
    pub method: &'static str,
    /// The pass's name, or `total`.
    pub pass: &'static str,
    /// Pixels per frame.
    pub pixels: u64,
    /// The filter radius R in pixels.
    pub radius: u32,
    /// Median seconds (GPU timestamps on Vulkan, wall clock on the CPU); on the `total` line the
    /// median of each timed run's summed passes.
    pub seconds: f64,
    /// How many times the pass ran back to back in each timed submission (the last
    /// repetition's), `seconds` being their mean: 1 on the CPU, more on Vulkan
    /// (benchmark mode, 50 ms a submission); absent on the `total` line.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dispatches: Option<u32>,
    /// Seconds of the untimed warm-up of this denoiser before it was timed (until its times had
    /// not fallen for `--settle-seconds`, default 5 s, on Vulkan; 0.5 s on the CPU): long where
    /// the device had to raise its clocks first.
    pub warm_up_seconds: f64,
    /// Bytes the pass must move.
    pub bytes: u64,
    /// Effective bandwidth `bytes / seconds`, in GB/s (10⁹ bytes).
    pub gb_per_s: f64,
    /// `gb_per_s` as a fraction of the device's peak memory bandwidth, where known.
    pub bandwidth_fraction: Option<f64>,
    /// The backend's copy bandwidth in GB/s: its copy probe on the frame's pixels, median of
    /// `repeats` runs, each pixel's 16 bytes read once and written once.
    pub copy_gb_per_s: f64,
    /// `gb_per_s / copy_gb_per_s`: near 1, the pass is as fast as its bytes allow here; far
    /// below, it is bound by arithmetic or by latency.
    pub copy_fraction: f64,
    /// Vulkan: invocations per workgroup of the per-pixel passes (the bilateral passes run 64);
    /// absent on the CPU.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub workgroup_size: Option<u32>,
}

impl crate::output_line::OutputLine for DenoiseMeasurement {
    fn json(&self) -> String {
        crate::output_line::json_object(self)
    }

    fn row(&self) -> String {
        let fraction = self.bandwidth_fraction.map_or(String::new(), |f| format!("  {:.1} % of peak", 100.0 * f));
        let dispatches = self.dispatches.map_or(String::new(), |d| format!("  ×{d}"));
        let workgroup = crate::bench_device::workgroup_note(self.workgroup_size);
        format!(
            "{:<40} {:<5} R={:<3} {:<20} {:>9.3} ms  {:>7.2} GB/s  {:>5.1} % of copy{fraction}{dispatches}{workgroup}",
            self.implementation,
            self.method,
            self.radius,
            self.pass,
            1e3 * self.seconds,
            self.gb_per_s,
            100.0 * self.copy_fraction
        )
    }
}

/// Datasheet peak memory bandwidth (GB/s) of a GPU by its exact Vulkan device name
/// (`deviceName`, as `raywave devices` lists it; the names NVIDIA's driver gives), for the
/// models whose name fixes it (NVIDIA H100 and H200 datasheets): H100 SXM5 80 GB HBM3 3 350,
/// H100 PCIe 2 000, H100 NVL 3 900, H200 SXM and H200 NVL 4 800. Any other name is `None`
/// (`--peak-gbps` gives it): GH200, whose bandwidth differs between its memory versions (96 GB
/// HBM3 4 000, 144 GB HBM3e 4 900), H800, H20, and names this list does not know — a partial
/// match gave the H100 NVL the SXM5's 3 350 and every GH200 the H200's 4 800.
pub fn known_peak_gbps(device_name: &str) -> Option<f64> {
    match device_name {
        "NVIDIA H100 80GB HBM3" => Some(3350.0),
        "NVIDIA H100 PCIe" => Some(2000.0),
        "NVIDIA H100 NVL" => Some(3900.0),
        "NVIDIA H200" | "NVIDIA H200 NVL" => Some(4800.0),
        _ => None,
    }
}

/// Shades the benchmark frame's inputs on the CPU (`options.scene` at `options.width` ×
/// `options.height`, `options.spp` samples): what `raywave bench denoise` and the criterion
/// bench's `denoise` group filter.
pub fn frame_input(options: &DenoiseBenchOptions) -> Result<DenoiseInput> {
    let scene = Scene::load(&options.scene)?;
    let mut cpu = crate::cpu::CpuBackend::new();
    let settings = LitFrameSettings::new(options.width, options.height, options.spp);
    settings.check_on(&cpu)?;
    cpu.load_scene(&scene)?;
    let data = ShadeData::new(&scene)?;
    Ok(shade_samples(&mut cpu, &scene, &data, &settings)?.denoise_input())
}

/// `backend`'s copy bandwidth in GB/s on `image` (one `Vec4` per pixel of `params`' frame): the
/// median time of `repeats` copy probes after a warm-up of `settle_seconds` ([`measure`]), each pixel read
/// once and written once.
fn copy_bandwidth(
    backend: &mut dyn Backend,
    params: &DenoiseParams,
    image: &[Vec4],
    repeats: u32,
    settle_seconds: f64,
) -> Result<f64> {
    let measured = measure(settle_seconds, repeats, 1, || Ok(vec![backend.copy_probe(params, image)?.1]))?;
    let bytes = 2.0 * std::mem::size_of::<Vec4>() as f64 * f64::from(params.pixels());
    Ok(crate::bench::per_second(bytes, measured.stages[0].seconds) / 1e9)
}

/// How [`bench_backend`] measures a backend: the device's peak bandwidth if known, the warm-up's
/// settling time ([`measure`]) and, on Vulkan, the per-pixel passes' workgroup size.
#[derive(Clone, Copy)]
struct Measuring {
    peak_gbps: Option<f64>,
    settle_seconds: f64,
    workgroup_size: Option<u32>,
}

/// Measures `backend` as `measured_as` says, handing each line to `emit`.
fn bench_backend(
    backend: &mut dyn Backend,
    input: &DenoiseInput,
    options: &DenoiseBenchOptions,
    measured_as: &Measuring,
    emit: &mut impl FnMut(&DenoiseMeasurement),
) -> Result<()> {
    let Measuring { peak_gbps, settle_seconds, workgroup_size } = *measured_as;
    let params = DenoiseParams {
        samples_per_pixel: options.spp,
        ..frame_params(options.width, options.height, options.denoise_radius)
    };
    let pixels = u64::from(params.pixels());
    let copy_gb_per_s = copy_bandwidth(backend, &params, &input.shadowed, options.repeats, settle_seconds)?;
    for method in [DenoiseMethod::Tv, DenoiseMethod::Svgf] {
        let passes = method.passes(&params);
        let Measured { stages, total_seconds, warm_up_seconds } =
            measure(settle_seconds, options.repeats, passes.len(), || {
                backend.denoise(method, &params, input).map(|(_, r)| r)
            })?;
        let line = |pass: &'static str, seconds: f64, dispatches: Option<u32>, bytes: u64| {
            let gb_per_s = crate::bench::per_second(bytes as f64, seconds) / 1e9;
            DenoiseMeasurement {
                stage: "denoise",
                implementation: backend.name(),
                method: method.name(),
                pass,
                pixels,
                radius: params.radius,
                seconds,
                dispatches,
                warm_up_seconds,
                bytes,
                gb_per_s,
                bandwidth_fraction: peak_gbps.map(|peak| gb_per_s / peak),
                copy_gb_per_s,
                copy_fraction: gb_per_s / copy_gb_per_s,
                workgroup_size,
            }
        };
        let mut total_bytes = 0;
        for (pass, stage) in passes.iter().zip(stages) {
            let bytes = pass.bytes_per_pixel() * pixels;
            total_bytes += bytes;
            emit(&line(pass.name(), stage.seconds, Some(stage.dispatches), bytes));
        }
        emit(&line("total", total_seconds, None, total_bytes));
    }
    Ok(())
}

/// Runs the benchmark, handing each line to `emit` as soon as it is measured.
pub fn bench_denoise(options: &DenoiseBenchOptions, mut emit: impl FnMut(&DenoiseMeasurement)) -> Result<()> {
    crate::bench::check_repeats(options.repeats)?;
    if options.peak_gbps.is_some_and(|peak| !(peak.is_finite() && peak > 0.0)) {
        return Err(crate::Error::InvalidParameter { name: "peak-gbps", reason: "must be finite and > 0".into() });
    }
    check_radius("denoise-radius", options.denoise_radius)?;
    // The frame's size and samples before any device is enumerated or scene loaded.
    LitFrameSettings::new(options.width, options.height, options.spp).check_on(&crate::cpu::CpuBackend::new())?;
    let image = [options.width, options.height];
    let vulkan_device = options.vulkan_options.device(options.vulkan, crate::StreamStage::Denoise, image)?;
    if vulkan_device.is_none() && options.peak_gbps.is_some() {
        let reason = "no Vulkan device is measured, so nothing uses it (the CPU rows have no peak)".into();
        return Err(crate::Error::InvalidParameter { name: "peak-gbps", reason });
    }
    let input = frame_input(options)?;
    let mut cpu = crate::cpu::CpuBackend::new();
    let on_the_cpu = Measuring { peak_gbps: None, settle_seconds: CPU_SETTLE_SECONDS, workgroup_size: None };
    bench_backend(&mut cpu, &input, options, &on_the_cpu, &mut emit)?;
    #[cfg(feature = "vulkan")]
    if let Some(device) = vulkan_device {
        for &size in &device.sizes {
            let mut vulkan = device.open(size, None, Default::default())?;
            let measuring = Measuring {
                peak_gbps: options.peak_gbps.or_else(|| known_peak_gbps(&device.info.name)),
                settle_seconds: device.settle_seconds,
                workgroup_size: Some(vulkan.workgroup_sizes().denoise),
            };
            bench_backend(&mut vulkan, &input, options, &measuring, &mut emit)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_datasheet_peak_is_known_for_exact_model_names_only() {
        assert_eq!(known_peak_gbps("NVIDIA H100 80GB HBM3"), Some(3350.0));
        assert_eq!(known_peak_gbps("NVIDIA H100 PCIe"), Some(2000.0));
        assert_eq!(known_peak_gbps("NVIDIA H100 NVL"), Some(3900.0));
        assert_eq!(known_peak_gbps("NVIDIA H200"), Some(4800.0));
        assert_eq!(known_peak_gbps("NVIDIA H200 NVL"), Some(4800.0));
        for unknown in [
            "NVIDIA GH200 480GB",
            "NVIDIA GH200 144G HBM3e",
            "NVIDIA H800",
            "NVIDIA H100",
            "vulkan:0 NVIDIA H100 80GB HBM3 (trace: rtpipe)",
            "llvmpipe (LLVM 15.0.6, 256 bits)",
            "",
        ] {
            assert_eq!(known_peak_gbps(unknown), None, "{unknown}");
        }
    }
}
