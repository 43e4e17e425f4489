//! A lit sample with its streams kept on the device (`Backend::lit_sample` on Vulkan: camera
//! rays, hits, the shade stream and the shadow rays never leave it) must be the sample composed
//! from the backend's own stage calls (`lit_sample::compose`, every stream through the host) bit
//! for bit: the same kernels on the same inputs. On every device and trace method, for the Cornell
//! box with and without the quadrature residual and for the light grid (the light BVH), at three
//! sample indices, with all the camera streams, none, and those of listed pixels that hit (the
//! G-buffer's gaps, gathered out of the device's streams); the same stage order, hit count and
//! sanitized counts (0 on these scenes); and the same refusals, before any work, for what the
//! composed stages refuse.
#![cfg(feature = "vulkan")]

mod common;

use common::vulkan;
use raywave::denoise::is_guide_surface;
use raywave::frame::{generate_params_with, sampler_params};
use raywave::kernels::shade::stage::Surface;
use raywave::lit_frame::{shade_samples, LitFrameSettings};
use raywave::lit_sample::{compose, CameraStreams, LitSample, LitSampleRequest};
use raywave::shading::{resolve, ShadeData};
use raywave::shared::sampling::sampler_kind;
use raywave::shared::stream::NO_HIT;
use raywave::shared::{GenerateParams, ShadeParams};
use raywave::stream::{HitStream, RayStream};
use raywave::{Backend, Scene};

const WIDTH: u32 = 40;
const HEIGHT: u32 = 30;

/// The camera and shade parameters of sample `sample_index` (of 8) of `scene` at this test's size.
fn params(scene: &Scene, data: &ShadeData, sample_index: u32) -> (GenerateParams, ShadeParams) {
    let sampler = sampler_params(sampler_kind::ZSOBOL, 7, WIDTH, HEIGHT, 8);
    let generate = generate_params_with(scene, WIDTH, HEIGHT, sample_index, sampler);
    (generate, data.params(sampler, WIDTH, HEIGHT, sample_index))
}

/// Fails unless two lit samples agree in everything but the seconds and the stream bytes (the
/// composed sample counts the host's copy of the shadow rays too), naming the field.
fn assert_same(case: &str, a: &LitSample, b: &LitSample) {
    assert!(a.analytic == b.analytic, "{case}: analytic");
    assert!(a.unshadowed == b.unshadowed, "{case}: unshadowed");
    assert!(a.emitted == b.emitted, "{case}: emitted");
    assert!(a.occluded == b.occluded, "{case}: occluded");
    assert!(a.camera == b.camera, "{case}: camera streams");
    assert_eq!(a.hits, b.hits, "{case}: hits");
    let reports = |s: &LitSample| -> Vec<_> {
        s.camera_timings.iter().chain(&s.pass_timings).map(|r| (r.stage, r.sanitized, r.dispatches)).collect()
    };
    assert_eq!(reports(a), reports(b), "{case}: stages");
}

#[test]
fn device_resident_lit_samples_are_the_composed_stages_bit_for_bit() {
    let scenes = [("builtin:cornell", false), ("builtin:cornell", true), ("builtin:cornell-light-grid", false)];
    for mut backend in vulkan::every_device("device_resident_lit_samples") {
        let name = backend.name();
        for (scene_name, analytic_residual) in scenes {
            let scene = Scene::load(scene_name).expect("built-in scene");
            let mut data = ShadeData::new(&scene).expect("shade data");
            data.analytic_residual = analytic_residual;
            backend.load_scene(&scene).expect("scene loads");
            // Runs of consecutive pixels and single ones, gathered in one copy region each.
            let listed: Vec<u32> = (0..WIDTH * HEIGHT).filter(|i| i % 7 < 3 || i % 50 == 11).collect();
            let streams = [CameraStreams::All, CameraStreams::None, CameraStreams::HitsAmong(&listed)];
            for (sample_index, camera) in (0..).zip(streams) {
                let case = format!("{name}, {scene_name} residual {analytic_residual}, sample {sample_index}");
                let (generate, shade) = params(&scene, &data, sample_index);
                let request = LitSampleRequest { generate: &generate, shade: &shade, data: &data, camera };
                let resident = backend.lit_sample(&request).expect("device-resident lit sample");
                let composed = compose(&mut backend, &request).expect("composed lit sample");
                assert_same(&case, &resident, &composed);
                // A sample that shades nothing, or traces every shadow ray blocked, would agree too.
                let lit = resident.occluded.iter().filter(|&&blocked| blocked == 0).count();
                assert!(resident.hits > WIDTH as usize * HEIGHT as usize / 2, "{case}: {} hits", resident.hits);
                assert!(lit > 0 && lit < resident.occluded.len(), "{case}: {lit} unblocked shadow rays");
                assert!(resident.unshadowed.iter().any(|u| u.x > 0.0), "{case}: no U_N");
                // The records' pixels: every one, or the listed ones that the sample's camera
                // rays, traced on their own, hit (some of them: the box's edges leave misses).
                let pixels_of = |camera: &Option<(RayStream, HitStream)>| {
                    camera.as_ref().map(|(rays, hits)| (rays.pixel.clone(), hits.len()))
                };
                let expected = match camera {
                    CameraStreams::None => None,
                    CameraStreams::All => Some(((0..WIDTH * HEIGHT).collect(), (WIDTH * HEIGHT) as usize)),
                    CameraStreams::HitsAmong(pixels) => {
                        let frame = backend.render(&generate).expect("camera rays traced");
                        let hit: Vec<u32> =
                            pixels.iter().copied().filter(|&i| frame.hits.primitive[i as usize] != NO_HIT).collect();
                        assert!(!hit.is_empty() && hit.len() < pixels.len(), "{case}: {} listed hits", hit.len());
                        Some((hit.clone(), hit.len()))
                    }
                };
                assert_eq!(pixels_of(&resident.camera), expected, "{case}");
                let pixels = u64::from(WIDTH * HEIGHT);
                assert_eq!((resident.stream_bytes, composed.stream_bytes), (140 * pixels, 176 * pixels), "{case}");
            }
        }
        vulkan::assert_clean(backend);
    }
}

/// The G-buffer a frame's samples leave (`shade_samples`): per pixel, the surface of the first
/// sample whose camera ray hit one the denoiser sees, else the first sample's miss. On the CPU
/// and on every Vulkan device and trace method (where the gaps' records are gathered out of the
/// device's streams), each against the samples' frames rendered and resolved on that backend on
/// their own. Both scenes leave gaps (the spheres stand against the sky, the box against the
/// dark) that later samples fill, and pixels that none does.
#[test]
fn g_buffer_gaps_take_the_first_later_surface_on_every_backend() {
    let mut cpu = raywave::open_backend(raywave::DeviceChoice::Cpu, &Default::default()).expect("CPU backend");
    assert_g_buffer_gaps_filled(cpu.as_mut());
    for mut backend in vulkan::every_device("g_buffer_gaps") {
        assert_g_buffer_gaps_filled(&mut backend);
        vulkan::assert_clean(backend);
    }
}

/// Fails unless `backend`'s lit frames leave the G-buffer that
/// [`g_buffer_gaps_take_the_first_later_surface_on_every_backend`] describes.
fn assert_g_buffer_gaps_filled(backend: &mut dyn Backend) {
    for scene_name in ["builtin:spheres", "builtin:cornell"] {
        let case = format!("{}, {scene_name}", backend.name());
        let scene = Scene::load(scene_name).expect("built-in scene");
        let data = ShadeData::new(&scene).expect("shade data");
        let settings = LitFrameSettings::new(WIDTH, HEIGHT, 6);
        backend.load_scene(&scene).expect("scene loads");
        let samples = shade_samples(backend, &scene, &data, &settings).expect("samples");
        let resolved: Vec<Vec<Surface>> = (0..settings.samples_per_pixel)
            .map(|k| {
                let frame = backend.render(&settings.generate_params(&scene, k)).expect("frame");
                resolve(&data, &frame.rays, &frame.hits)
            })
            .collect();
        let mut filled_later = 0;
        for (pixel, surface) in samples.surfaces.iter().enumerate() {
            let first = resolved.iter().position(|surfaces| is_guide_surface(&surfaces[pixel]));
            assert!(*surface == resolved[first.unwrap_or(0)][pixel], "{case}: pixel {pixel}");
            filled_later += usize::from(first.is_some_and(|k| k > 0));
        }
        let none = samples.surfaces.iter().filter(|s| !is_guide_surface(s)).count();
        assert!(filled_later > 0 && none > 0, "{case}: {filled_later} pixels filled later, {none} without a surface");
    }
}

#[test]
fn device_resident_lit_samples_refuse_what_the_composed_stages_refuse() {
    let scene = common::cornell();
    let other = Scene::load("builtin:cornell-two-lights").expect("built-in scene");
    let data = ShadeData::new(&scene).expect("shade data");
    let other_data = ShadeData::new(&other).expect("shade data");
    for mut backend in vulkan::each_device("device_resident_lit_sample_refusals") {
        let name = backend.name();
        let (generate, shade) = params(&scene, &data, 0);
        let request = LitSampleRequest { generate: &generate, shade: &shade, data: &data, camera: CameraStreams::None };
        let refusal = |backend: &mut raywave::vulkan::VulkanBackend, request: &LitSampleRequest<'_>| {
            let message = |result: raywave::Result<LitSample>, how: &str| match result {
                Ok(_) => panic!("{how}: accepted"),
                Err(e) => e.to_string(),
            };
            (message(backend.lit_sample(request), "on the device"), message(compose(backend, request), "composed"))
        };
        let (resident, composed) = refusal(&mut backend, &request);
        assert_eq!(resident, composed, "{name}: no scene loaded");
        assert!(resident.contains("loaded scene"), "{name}: {resident}");
        backend.load_scene(&scene).expect("scene loads");
        let wrong_count = ShadeParams { count: shade.count - 1, ..shade };
        let extra_light = ShadeParams { light_count: data.lights.len() as u32 + 1, ..shade };
        let other_sample = ShadeParams { sample_index: 1, ..shade };
        let (flat, flat_shade) = (GenerateParams { width: 0, ..generate }, ShadeParams { width: 0, ..shade });
        let wider = ShadeParams { width: WIDTH + 1, ..shade };
        let gaps = |pixels: &'static [u32]| LitSampleRequest { camera: CameraStreams::HitsAmong(pixels), ..request };
        // Each refusal, and the words that say why: the two paths could agree on another reason.
        let cases = [
            ("another scene's data", LitSampleRequest { data: &other_data, ..request }, "ShadeData::new"),
            ("a count one short", LitSampleRequest { shade: &wrong_count, ..request }, "params.count"),
            ("a light past the data's", LitSampleRequest { shade: &extra_light, ..request }, "params.light_count"),
            ("another sample's shading", LitSampleRequest { shade: &other_sample, ..request }, "sample_index"),
            ("another image's shading", LitSampleRequest { shade: &wider, ..request }, "shade.width"),
            ("an image 0 wide", LitSampleRequest { generate: &flat, shade: &flat_shade, ..request }, "at least 1"),
            ("a listed pixel past the image", gaps(&[5, WIDTH * HEIGHT]), "past the image's end"),
            ("listed pixels out of order", gaps(&[5, 9, 9]), "strictly ascending"),
        ];
        for (what, case, why) in cases {
            let (resident, composed) = refusal(&mut backend, &case);
            assert_eq!(resident, composed, "{name}: {what}");
            assert!(resident.contains(why), "{name}: {what}: {resident}");
        }
        vulkan::assert_clean(backend);
    }
}
