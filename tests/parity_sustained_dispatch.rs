//! Benchmark mode (`ContextOptions::sustain_seconds`, what `raywave bench` opens its Vulkan
//! backend with): once a kernel has run, each of its timed submissions repeats the dispatch to
//! keep the GPU busy, so that the GPU holds its clocks. Repeating must change nothing but the
//! timing: on every device and trace method, every stage — generate, trace, occlusion, shade,
//! both denoisers, the copy, sampler and warp probes — returns exactly what a backend that
//! dispatches once returns, bit for bit, with the same sanitized counts (non-zero where the input
//! has non-finite values, so that a counter counting every repetition would show), and reports
//! how many dispatches it timed: 1 without benchmark mode, more than 1 with it.
#![cfg(feature = "vulkan")]

mod common;

use common::{cornell, vulkan};
use glam::Vec4;
use raywave::cpu::CpuBackend;
use raywave::denoise::{DenoiseInput, DenoiseMethod};
use raywave::frame::{generate_params_with, sampler_params};
use raywave::shading::{resolve, ShadeAccumulator, ShadeData};
use raywave::shared::sampling::sampler_kind;
use raywave::shared::{DenoiseParams, GenerateParams, SamplerParams, SamplerProbeParams};
use raywave::stream::RayStream;
use raywave::vulkan::{VulkanBackend, MAX_SUSTAINED_DISPATCHES};
use raywave::{Backend, Scene, StageReport};
use std::fmt::Debug;

/// The busy time benchmark mode stretches each submission to here: 50 ms, far above what any
/// stage takes on this test's 32×24 frame (lavapipe: a few ms at most), so that every repeated
/// submission holds more than one dispatch.
const SUSTAIN_SECONDS: f64 = 0.05;

const WIDTH: u32 = 32;
const HEIGHT: u32 = 24;

/// Runs `stage` on `single` (one dispatch per submission) and three times on `sustained` (each
/// run sets how many dispatches the next repeats) and checks that all return the same result
/// and sanitized counts, `single` timing one dispatch and `sustained`'s last run more.
fn check_stage<T: PartialEq + Debug>(
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
    let sanitized = |reports: &[StageReport]| reports.iter().map(|r| (r.stage, r.sanitized)).collect::<Vec<_>>();
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
    let denoise_params = DenoiseParams::new(WIDTH, HEIGHT);
    let traced = with_untraceable_rays(rays.clone());
    // Broken hit records, which shade counts as sanitized.
    for i in (5..hits.len()).step_by(29) {
        hits.t[i] = f32::NAN;
    }
    let image: Vec<Vec4> = (0..WIDTH * HEIGHT).map(|i| Vec4::new(i as f32, -0.5, 1e-30, 3e38)).collect();
    let probe = SamplerProbeParams {
        sampler: SamplerParams { kind: sampler_kind::ZSOBOL, seed: 5, spp_log2: 2, resolution_log2: 5 },
        width: WIDTH,
        height: HEIGHT,
        dimension: 3,
        padding: 0,
    };
    let (_, mut warp) = common::warp_cases::warp_cases().swap_remove(1);
    warp.count = 4096;

    let singles = vulkan::every_device("benchmark mode");
    let sustained = vulkan::every_device_sustained("benchmark mode", SUSTAIN_SECONDS);
    assert_eq!(singles.len(), sustained.len());
    for (mut single, mut sustained) in singles.into_iter().zip(sustained) {
        for backend in [&mut single, &mut sustained] {
            backend.load_scene(&scene).expect("scene loads");
        }
        let (a, b) = (&mut single, &mut sustained);
        check_stage("generate", a, b, |d| {
            let (rays, report) = d.generate(&generate).expect("generate");
            (rays, vec![report])
        });
        check_stage("trace", a, b, |d| {
            let (hits, report) = d.trace(&traced).expect("trace");
            assert_eq!(report.sanitized, 2, "{} trace", d.name());
            (hits, vec![report])
        });
        check_stage("occlusion", a, b, |d| {
            let (occluded, report) = d.trace_occlusion(&traced).expect("occlusion");
            assert_eq!(report.sanitized, 2, "{} occlusion", d.name());
            (occluded, vec![report])
        });
        check_stage("shade", a, b, |d| {
            let (shades, report) = d.shade(&shade, &data, &rays, &hits).expect("shade");
            assert!(report.sanitized > 0, "{} shade counted no broken hit record", d.name());
            (shades, vec![report])
        });
        for method in [DenoiseMethod::Tv, DenoiseMethod::Svgf] {
            check_stage(method.name(), a, b, |d| {
                let (color, reports) = d.denoise(method, &denoise_params, &denoise_input).expect("denoise");
                assert!(StageReport::total_sanitized(&reports) > 0, "{} {method:?} counted no overflow", d.name());
                (color, reports)
            });
        }
        check_stage("copy probe", a, b, |d| {
            let (copy, report) = d.copy_probe(&denoise_params, &image).expect("copy probe");
            (copy, vec![report])
        });
        check_stage("sampler probe", a, b, |d| (d.sampler_probe(&probe).expect("sampler probe"), vec![]));
        check_stage("warp probe", a, b, |d| (d.warp_probe(&warp).expect("warp probe"), vec![]));
        vulkan::assert_clean(&single);
        vulkan::assert_clean(&sustained);
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
    for mut device in vulkan::every_device_sustained("benchmark mode sizing", SUSTAIN_SECONDS) {
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
    }
}

/// Benchmark mode's busy time must be finite and within 0..=1 s: anything else is a typed error
/// when the device is opened, not a submission that runs for ever.
#[test]
fn an_unusable_sustain_time_is_refused_when_the_device_opens() {
    use raywave::vulkan::{enumerate_devices, ContextOptions};
    let Some(device) = enumerate_devices().ok().and_then(|d| d.into_iter().next()) else {
        common::skip_or_fail("sustain time check", "no Vulkan device");
        return;
    };
    for sustain_seconds in [-0.001, 1.5, f64::NAN, f64::INFINITY] {
        let options = ContextOptions { sustain_seconds, ..Default::default() };
        match VulkanBackend::open(device.index, &options, None) {
            Err(raywave::Error::InvalidParameter { name: "sustain_seconds", .. }) => {}
            other => panic!("sustain_seconds = {sustain_seconds}: {:?}", other.map(|b| b.name())),
        }
    }
}
