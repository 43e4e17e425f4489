//! How a stage's work is dispatched must change nothing but its timing, on every device and
//! trace method, for every stage — generate, trace, occlusion, shade, both denoisers, the copy,
//! sampler and warp probes: the same result bit for bit and the same sanitized counts (non-zero
//! where the input has non-finite values, so that a counter counting twice would show).
//!
//! - **Benchmark mode** (`ContextOptions::sustain_seconds`, what `raywave bench` opens its Vulkan
//!   backend with): once a kernel has run, each of its timed submissions repeats the dispatch to
//!   keep the GPU busy, so that the GPU holds its clocks; it reports how many dispatches it
//!   timed: 1 without benchmark mode, more than 1 with it. The sampler and warp probes return no
//!   report, so for them only the result is compared: that they repeated is not checked here
//!   (they run through the same `Pass` as the copy probe, whose count is).
//! - **Workgroup sizes** (`ContextOptions::workgroup_sizes`, for occupancy tuning): the 1-D
//!   stream stages run in workgroups of another power of two, including streams spread over
//!   several rows of the dispatch grid.
#![cfg(feature = "vulkan")]

mod common;

use common::{cornell, vulkan};
use glam::Vec4;
use raywave::cpu::CpuBackend;
use raywave::denoise::{DenoiseInput, DenoiseMethod};
use raywave::frame::{generate_params_with, sampler_params};
use raywave::report::error_vs_time::{report_error_vs_time, ErrorVsTimeOptions, MethodFrames, PreparedScene};
use raywave::report::SceneReportOptions;
use raywave::shading::{resolve, ShadeAccumulator, ShadeData};
use raywave::shared::sampling::sampler_kind;
use raywave::shared::{DenoiseParams, GenerateParams, SamplerParams, SamplerProbeParams, WarpParams};
use raywave::stream::{HitStream, RayStream};
use raywave::vulkan::{ContextOptions, VulkanBackend, MAX_SUSTAINED_DISPATCHES};
use raywave::{open_backend, Backend, BackendOptions, DeviceChoice, Scene, StageReport, StreamStage, WorkgroupSizes};
use std::fmt::Debug;

/// The busy time benchmark mode stretches each submission to here: 50 ms, far above what any
/// stage takes on this test's 32×24 frame (lavapipe: a few ms at most), so that every repeated
/// submission holds more than one dispatch.
const SUSTAIN_SECONDS: f64 = 0.05;

const WIDTH: u32 = 32;
const HEIGHT: u32 = 24;

/// Runs one stage on two backends and checks what must agree.
trait Comparison {
    /// Runs `stage` on `reference` and on `other` and checks that both return the same result and
    /// sanitized counts, `what` naming the stage.
    fn check<T: PartialEq + Debug>(
        &mut self,
        what: &str,
        reference: &mut VulkanBackend,
        other: &mut VulkanBackend,
        stage: impl FnMut(&mut VulkanBackend) -> (T, Vec<StageReport>),
    );
}

fn sanitized(reports: &[StageReport]) -> Vec<(&'static str, u64)> {
    reports.iter().map(|r| (r.stage, r.sanitized)).collect()
}

/// Benchmark mode: `other` sustains its submissions, `reference` dispatches once.
struct Sustained;

impl Comparison for Sustained {
    /// Runs `stage` on `single` once and three times on `sustained` (each run sets how many
    /// dispatches the next repeats): `single` times one dispatch, `sustained`'s last run more.
    fn check<T: PartialEq + Debug>(
        &mut self,
        what: &str,
        single: &mut VulkanBackend,
        sustained: &mut VulkanBackend,
        mut stage: impl FnMut(&mut VulkanBackend) -> (T, Vec<StageReport>),
    ) {
        let who = format!("{} {what}", single.name());
        let (expected, single_reports) = stage(single);
        // The first run in benchmark mode dispatches once and may include a lazy pipeline compile
        // (lavapipe), the second is sized by it, the third by a warm run.
        let (first, _) = stage(sustained);
        let (second, _) = stage(sustained);
        let (repeated, repeated_reports) = stage(sustained);
        assert!(first == expected, "{who}: the first run in benchmark mode differs");
        assert!(second == expected && repeated == expected, "{who}: the repeated dispatches' result differs");
        assert_eq!(sanitized(&repeated_reports), sanitized(&single_reports), "{who}: sanitized counts");
        for report in &single_reports {
            assert_eq!(report.dispatches, 1, "{who}: {} without benchmark mode", report.stage);
        }
        for report in &repeated_reports {
            assert!(
                (2..=MAX_SUSTAINED_DISPATCHES).contains(&report.dispatches),
                "{who}: {} repeated {} times after a {} s dispatch",
                report.stage,
                report.dispatches,
                report.seconds
            );
            assert!(
                report.seconds.is_finite() && report.seconds >= 0.0,
                "{who}: {} took {} s",
                report.stage,
                report.seconds
            );
        }
    }
}

/// Another workgroup size: `other` runs the stream stages in workgroups of its own size.
struct Resized;

impl Comparison for Resized {
    fn check<T: PartialEq + Debug>(
        &mut self,
        what: &str,
        preferred: &mut VulkanBackend,
        resized: &mut VulkanBackend,
        mut stage: impl FnMut(&mut VulkanBackend) -> (T, Vec<StageReport>),
    ) {
        let who = format!("{} {what} in workgroups of {:?}", resized.name(), resized.workgroup_sizes());
        let (expected, expected_reports) = stage(preferred);
        let (result, reports) = stage(resized);
        assert!(result == expected, "{who}: the result differs from workgroups of {:?}", preferred.workgroup_sizes());
        assert_eq!(sanitized(&reports), sanitized(&expected_reports), "{who}: sanitized counts");
    }
}

/// The inputs of every stage on the test frame, each with values a stage must sanitize.
struct Inputs {
    scene: Scene,
    data: ShadeData,
    generate: GenerateParams,
    rays: RayStream,
    /// `rays` and two rays that cannot be traced.
    traced: RayStream,
    /// The hits of `rays`, some broken.
    hits: HitStream,
    shade: raywave::shared::ShadeParams,
    denoise_params: DenoiseParams,
    denoise_input: DenoiseInput,
    image: Vec<Vec4>,
    probe: SamplerProbeParams,
    warp: WarpParams,
}

impl Inputs {
    fn new() -> Self {
        let scene = cornell();
        let data = ShadeData::new(&scene).expect("shade data");
        let (sampler, generate) = camera(&scene);
        let mut cpu = CpuBackend::new();
        cpu.load_scene(&scene).expect("cpu scene");
        let (rays, _) = cpu.generate(&generate).expect("cpu generate");
        let (mut hits, _) = cpu.trace(&rays).expect("cpu trace");
        let shade = data.params(sampler, WIDTH, HEIGHT, 0);
        // Denoiser input: the frame shaded on the CPU, with colours that overflow `f32` in a few
        // pixels, which the composites replace and count.
        let mut accumulator = ShadeAccumulator::new(rays.len());
        accumulator.shade_pass(&mut cpu, &shade, &data, &rays, &hits).expect("cpu shade pass");
        let mut denoise_input = DenoiseInput::new(&resolve(&data, &rays, &hits), &accumulator);
        let huge = Vec4::new(0.6 * f32::MAX, 1.0, 1.0, 0.0);
        for i in (0..denoise_input.len()).step_by(97) {
            (denoise_input.analytic[i], denoise_input.emitted[i]) = (huge, huge);
        }
        let traced = with_untraceable_rays(rays.clone());
        // Broken hit records, which shade counts as sanitized.
        for i in (5..hits.len()).step_by(29) {
            hits.t[i] = f32::NAN;
        }
        let (_, mut warp) = common::warp_cases::warp_cases().swap_remove(1);
        warp.count = 4096;
        Inputs {
            scene,
            data,
            generate,
            rays,
            traced,
            hits,
            shade,
            denoise_params: DenoiseParams::new(WIDTH, HEIGHT),
            denoise_input,
            image: (0..WIDTH * HEIGHT).map(|i| Vec4::new(i as f32, -0.5, 1e-30, 3e38)).collect(),
            probe: SamplerProbeParams {
                sampler: SamplerParams { kind: sampler_kind::ZSOBOL, seed: 5, spp_log2: 2, resolution_log2: 5 },
                width: WIDTH,
                height: HEIGHT,
                dimension: 3,
                padding: 0,
            },
            warp,
        }
    }

    /// Runs every stage on `a` and `b` (the scene already loaded) through `comparison`.
    fn compare_every_stage(&self, comparison: &mut impl Comparison, a: &mut VulkanBackend, b: &mut VulkanBackend) {
        comparison.check("generate", a, b, |d| {
            let (rays, report) = d.generate(&self.generate).expect("generate");
            (rays, vec![report])
        });
        comparison.check("trace", a, b, |d| {
            let (hits, report) = d.trace(&self.traced).expect("trace");
            assert_eq!(report.sanitized, 2, "{} trace", d.name());
            (hits, vec![report])
        });
        comparison.check("occlusion", a, b, |d| {
            let (occluded, report) = d.trace_occlusion(&self.traced).expect("occlusion");
            assert_eq!(report.sanitized, 2, "{} occlusion", d.name());
            (occluded, vec![report])
        });
        comparison.check("shade", a, b, |d| {
            let (shades, report) = d.shade(&self.shade, &self.data, &self.rays, &self.hits).expect("shade");
            assert!(report.sanitized > 0, "{} shade counted no broken hit record", d.name());
            (shades, vec![report])
        });
        for method in [DenoiseMethod::Tv, DenoiseMethod::Svgf] {
            comparison.check(method.name(), a, b, |d| {
                let (color, reports) = d.denoise(method, &self.denoise_params, &self.denoise_input).expect("denoise");
                assert!(StageReport::total_sanitized(&reports) > 0, "{} {method:?} counted no overflow", d.name());
                (color, reports)
            });
        }
        comparison.check("copy probe", a, b, |d| {
            let (copy, report) = d.copy_probe(&self.denoise_params, &self.image).expect("copy probe");
            (copy, vec![report])
        });
        comparison.check("sampler probe", a, b, |d| (d.sampler_probe(&self.probe).expect("sampler probe"), vec![]));
        comparison.check("warp probe", a, b, |d| (d.warp_probe(&self.warp).expect("warp probe"), vec![]));
    }
}

/// The test frame's sampler and the generate parameters of its first sample.
fn camera(scene: &Scene) -> (SamplerParams, GenerateParams) {
    let sampler = sampler_params(sampler_kind::ZSOBOL, 3, WIDTH, HEIGHT, 4);
    (sampler, generate_params_with(scene, WIDTH, HEIGHT, 0, sampler))
}

/// Rays that cannot be traced, appended to `rays`: a NaN origin and an infinite tmax, which
/// every trace counts as sanitized.
fn with_untraceable_rays(mut rays: RayStream) -> RayStream {
    rays.origin.extend([Vec4::new(f32::NAN, 0.3, 0.3, 0.0), Vec4::new(0.3, 0.3, 0.3, 0.0)]);
    rays.direction.extend([Vec4::new(0.0, 0.0, 1.0, 10.0), Vec4::new(0.0, 0.0, 1.0, f32::INFINITY)]);
    rays.pixel.extend([0, 1]);
    rays
}

#[test]
fn repeated_dispatches_return_what_one_dispatch_returns_on_every_stage_and_device() {
    let inputs = Inputs::new();
    let singles = vulkan::every_device("benchmark mode");
    let options = ContextOptions { sustain_seconds: SUSTAIN_SECONDS, ..Default::default() };
    let sustained = vulkan::every_device_with("benchmark mode", &options);
    assert_eq!(singles.len(), sustained.len());
    for (mut single, mut sustained) in singles.into_iter().zip(sustained) {
        for backend in [&mut single, &mut sustained] {
            backend.load_scene(&inputs.scene).expect("scene loads");
        }
        inputs.compare_every_stage(&mut Sustained, &mut single, &mut sustained);
        vulkan::assert_clean(single);
        vulkan::assert_clean(sustained);
    }
}

/// Benchmark mode sizes a submission by the time per invocation of the kernel's last one: a large
/// call right after a one-ray call repeats `⌈sustain / (N × the ray's time)⌉` times, a few
/// (a dispatch's fixed cost makes one ray's time per invocation large). Sized by the time per
/// dispatch alone it would repeat as often as the one-ray call did — here 1024 times, minutes
/// for a large enough stream.
#[test]
fn a_large_call_after_a_one_ray_call_is_sized_by_the_time_per_ray() {
    let scene = cornell();
    let rays = CpuBackend::new().generate(&camera(&scene).1).expect("rays").0;
    let mut one_ray = RayStream::zeroed(1);
    (one_ray.origin[0], one_ray.direction[0]) = (rays.origin[0], rays.direction[0]);
    let options = ContextOptions { sustain_seconds: SUSTAIN_SECONDS, ..Default::default() };
    for mut device in vulkan::every_device_with("benchmark mode sizing", &options) {
        device.load_scene(&scene).expect("scene loads");
        let name = device.name();
        let mut trace = |rays: &RayStream| device.trace(rays).expect("trace").1;
        trace(&rays);
        let one = trace(&one_ray);
        let after = trace(&rays);
        let expected = (SUSTAIN_SECONDS / (one.seconds * rays.len() as f64)).ceil();
        let expected = expected.clamp(1.0, f64::from(MAX_SUSTAINED_DISPATCHES)) as u32;
        assert_eq!(after.dispatches, expected, "{name}: {} rays after one ray ({one:?}): {after:?}", rays.len());
        assert!(one.seconds > 0.0 && one.dispatches > 1, "{name}: the one-ray trace: {one:?}");
        vulkan::assert_clean(device);
    }
}

/// Benchmark mode's busy time must be finite and within 0..=1 s: anything else is a typed error
/// when the device is opened, not a submission that runs for ever.
#[test]
fn an_unusable_sustain_time_is_refused_when_the_device_opens() {
    let Some(device) = first_device("sustain time check") else { return };
    for sustain_seconds in [-0.001, 1.5, f64::NAN, f64::INFINITY] {
        let options = ContextOptions { sustain_seconds, ..Default::default() };
        match VulkanBackend::open(device.index, &options, None) {
            Err(raywave::Error::InvalidParameter { name: "sustain_seconds", .. }) => {}
            other => panic!("sustain_seconds = {sustain_seconds}: {:?}", other.map(|b| b.name())),
        }
    }
}

/// Benchmark mode switched per call (`Backend::set_sustain_seconds`, what `report
/// error-vs-time --settle-seconds` does after a reference): on from the next stage, off again,
/// the same results either way; an unusable time refused without changing the mode.
#[test]
fn benchmark_mode_switches_on_and_off_between_calls() {
    let scene = cornell();
    let rays = CpuBackend::new().generate(&camera(&scene).1).expect("rays").0;
    for mut device in vulkan::every_device("benchmark mode switch") {
        device.load_scene(&scene).expect("scene loads");
        let name = device.name();
        let trace = |device: &mut VulkanBackend| device.trace(&rays).expect("trace");
        let (single, first) = trace(&mut device);
        assert_eq!(first.dispatches, 1, "{name}: opened without benchmark mode");
        device.set_sustain_seconds(SUSTAIN_SECONDS).expect("a usable time");
        let (sustained, on) = trace(&mut device);
        assert!(on.dispatches > 1 && sustained == single, "{name}: benchmark mode on: {on:?}");
        for unusable in [-1.0, 1.5, f64::NAN] {
            match device.set_sustain_seconds(unusable) {
                Err(raywave::Error::InvalidParameter { name: "sustain_seconds", .. }) => {}
                other => panic!("{name}: sustain_seconds = {unusable}: {other:?}"),
            }
        }
        assert!(trace(&mut device).1.dispatches > 1, "{name}: a refused time leaves benchmark mode on");
        device.set_sustain_seconds(0.0).expect("off");
        let (again, off) = trace(&mut device);
        assert!(off.dispatches == 1 && again == single, "{name}: benchmark mode off: {off:?}");
        vulkan::assert_clean(device);
    }
}

/// `report error-vs-time --settle-seconds`: the warm-up ([`PreparedScene::settle`]) leaves the
/// backend in benchmark mode with the same images, and the report turns it off after each
/// scene, so that the next reference runs every pass once.
#[test]
fn the_error_vs_time_warm_up_measures_in_benchmark_mode_and_the_report_ends_it() {
    let scene = cornell();
    let rays = CpuBackend::new().generate(&camera(&scene).1).expect("rays").0;
    for mut device in vulkan::every_device("error-vs-time warm-up") {
        let name = device.name();
        let mut prepared = PreparedScene::new(&mut device, &scene, 16).expect("prepared");
        let images = |frame: MethodFrames| frame.images.into_iter().map(|(image, _)| image).collect::<Vec<_>>();
        let once = images(prepared.frame(&mut device, 2, 7).expect("frame"));
        assert!(prepared.settle(&mut device, &scene, 0.05).expect("settles") >= 0.05, "{name}");
        assert!(device.trace(&rays).expect("trace").1.dispatches > 1, "{name}: benchmark mode after the warm-up");
        assert!(images(prepared.frame(&mut device, 2, 7).expect("frame")) == once, "{name}: the same images");
        let report = SceneReportOptions {
            scenes: vec!["builtin:cornell".into()],
            resolution: 16,
            reference_spp: 4,
            max_spp: 1,
            reps: 1,
        };
        let options = ErrorVsTimeOptions { report, denoise_radius: None, settle_seconds: Some(0.05) };
        let lines = report_error_vs_time(&mut device, &options, |_| {}).expect("report");
        assert!(!lines.is_empty(), "{name}: the report measured nothing");
        assert!(lines.iter().all(|l| l.warm_up_seconds.is_some_and(|w| w >= 0.05)), "{name}: {lines:?}");
        assert_eq!(device.trace(&rays).expect("trace").1.dispatches, 1, "{name}: benchmark mode after the report");
        vulkan::assert_clean(device);
    }
}

/// The first Vulkan device; none (after a loud SKIP, or a failure under CI) if there is none.
fn first_device(test: &str) -> Option<raywave::vulkan::DeviceInfo> {
    let device = raywave::vulkan::enumerate_devices().ok().and_then(|d| d.into_iter().next());
    if device.is_none() {
        common::skip_or_fail(test, "no Vulkan device");
    }
    device
}

/// Workgroup sizes to compare with the preferred ones (shade 256, the others 64): the smallest
/// every device runs, 128, which every device runs, and the largest all of them run (lavapipe:
/// 1024; `DeviceInfo::workgroup_sizes`).
fn workgroup_sizes(test: &str) -> Vec<u32> {
    let devices = raywave::vulkan::enumerate_devices().unwrap_or_default();
    let largest = devices.iter().filter_map(|d| d.workgroup_sizes.last().copied()).min();
    let Some(largest) = largest else {
        common::skip_or_fail(test, "no Vulkan device");
        return vec![];
    };
    let mut sizes = vec![32, 128, largest];
    sizes.dedup();
    sizes
}

#[test]
fn every_stage_returns_the_same_in_workgroups_of_another_size_on_every_device() {
    let inputs = Inputs::new();
    let mut preferred = vulkan::every_device("workgroup size");
    for size in workgroup_sizes("workgroup size") {
        let options = ContextOptions { workgroup_sizes: Some(WorkgroupSizes::all(size)), ..Default::default() };
        let resized = vulkan::every_device_with("workgroup size", &options);
        assert_eq!(preferred.len(), resized.len());
        for (preferred, mut resized) in preferred.iter_mut().zip(resized) {
            assert_eq!(resized.workgroup_sizes(), WorkgroupSizes::all(size));
            for backend in [&mut *preferred, &mut resized] {
                backend.load_scene(&inputs.scene).expect("scene loads");
            }
            inputs.compare_every_stage(&mut Resized, preferred, &mut resized);
            vulkan::assert_clean(resized);
        }
    }
    preferred.into_iter().for_each(vulkan::assert_clean);
}

/// A stream too long for one row of 65 535 workgroups of 32 — the x limit lavapipe and many
/// devices have — is spread over rows of `STREAM_ROW` invocations; generate and the copy probe
/// over a 2048×1040 frame (2.13 M invocations) must still write every element once, as in
/// one row of 33 280 workgroups of 64.
#[test]
fn a_stream_spread_over_several_grid_rows_is_covered_exactly_once() {
    const WIDE: (u32, u32) = (2048, 1040);
    let scene = cornell();
    let generate =
        generate_params_with(&scene, WIDE.0, WIDE.1, 0, sampler_params(sampler_kind::ZSOBOL, 3, WIDE.0, WIDE.1, 1));
    let params = DenoiseParams::new(WIDE.0, WIDE.1);
    let image: Vec<Vec4> =
        (0..WIDE.0 * WIDE.1).map(|i| Vec4::new(i as f32, 1.0 / (i as f32 + 1.0), -3.0, 0.5)).collect();
    let options = ContextOptions { workgroup_sizes: Some(WorkgroupSizes::all(32)), ..Default::default() };
    let narrow = vulkan::each_device_with("grid rows", &options);
    for (mut preferred, mut narrow) in vulkan::each_device("grid rows").into_iter().zip(narrow) {
        let mut compare = Resized;
        compare.check("generate", &mut preferred, &mut narrow, |d| {
            let (rays, report) = d.generate(&generate).expect("generate");
            (rays, vec![report])
        });
        compare.check("copy probe", &mut preferred, &mut narrow, |d| {
            let (copy, report) = d.copy_probe(&params, &image).expect("copy probe");
            assert_eq!(copy, image, "{} copy probe", d.name());
            (copy, vec![report])
        });
        vulkan::assert_clean(preferred);
        vulkan::assert_clean(narrow);
    }
}

/// A workgroup size that is not a power of two, or that the device does not run, is a typed
/// error naming the stage when the device is opened; sizes it runs are what the backend reports,
/// stage by stage, and without sizes it runs the preferred ones.
#[test]
fn an_unusable_workgroup_size_is_refused_when_the_device_opens() {
    let Some(device) = first_device("workgroup size check") else { return };
    let largest = *device.workgroup_sizes.last().expect("the device runs 64");
    for (stage, size) in StreamStage::ALL.into_iter().zip([0, 3, 96, 2 * largest]) {
        let workgroup_sizes = WorkgroupSizes::COMPILED.with(stage, size);
        let options = ContextOptions { workgroup_sizes: Some(workgroup_sizes), ..Default::default() };
        let name = stage.field_name();
        match VulkanBackend::open(device.index, &options, None) {
            Err(raywave::Error::InvalidParameter { name: refused, .. }) if refused == name => {}
            other => panic!("{name} = {size}: {:?}", other.map(|b| b.name())),
        }
        // `--device auto` must not fall back to the CPU and drop the sizes asked for (sizes no
        // device runs: `auto` may pick another device than this one).
        if !size.is_power_of_two() {
            let options = BackendOptions { workgroup_sizes: Some(workgroup_sizes), ..Default::default() };
            match open_backend(DeviceChoice::Auto, &options) {
                Err(raywave::Error::InvalidParameter { name: refused, .. }) if refused == name => {}
                other => panic!("auto, {name} = {size}: {:?}", other.map(|b| b.name().to_owned())),
            }
        }
    }
    let mixed = WorkgroupSizes { generate: 32, trace: 128, shade: largest, denoise: 256.min(largest) };
    let validated = ContextOptions { validation: true, ..Default::default() };
    let options = ContextOptions { workgroup_sizes: Some(mixed), ..validated.clone() };
    let opened = VulkanBackend::open(device.index, &options, None).expect("every size runs");
    assert_eq!(opened.workgroup_sizes(), mixed);
    let preferred = VulkanBackend::open(device.index, &validated, None).expect("opens");
    assert_eq!(preferred.workgroup_sizes(), WorkgroupSizes::preferred_on(&device.workgroup_sizes));
    if largest >= 256 {
        assert_eq!(preferred.workgroup_sizes(), WorkgroupSizes::PREFERRED);
        assert_eq!(preferred.workgroup_sizes().shade, 256);
    }
    vulkan::assert_clean(opened);
    vulkan::assert_clean(preferred);
}
