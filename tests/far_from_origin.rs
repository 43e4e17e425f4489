//! The whole frame far from the origin, on the CPU and every Vulkan device × trace method: the
//! Cornell box (0.56 m across) moved with its camera by `k · (1, −0.5, 0.7)` m must render what it
//! renders at the origin — generate, trace, shade, the shadow rays' occlusion and both denoisers —
//! up to the rounding of its coordinates, which grows with `k`.
//!
//! What this caught: a shadow ray stopped `10⁻⁴` of its length short of the point it was sent to on
//! the light, a margin that shrinks with the cosine between the ray and the light's plane while the
//! light's own rounding (an ulp of its coordinates, over that cosine along the ray) grows with the
//! distance from the origin. At 10 m, rays from the walls to the ceiling light at grazing angles met
//! the light's own triangles: twice the shadow rays blocked (1179 against 570 of 9216 at 96², one
//! sample), the image 6 % darker (relMSE 1.2·10⁻² against the frame at the origin). Even at the
//! origin 3 of those 9216 rays met the light. The stop is now the light's plane lifted towards the
//! ray by the same ulp-scaled offset the ray's origin gets (`kernels::offset::ray_stop_before`).
//!
//! Measured (64², 4 spp, seed 7; the CPU and lavapipe's `sw`, `rayquery` and `rtpipe` within 2 %
//! of each other), the largest relMSE of the five methods' images against the frame at the origin,
//! and the largest change of their means: at 10 m 3.3·10⁻⁶ (5·10⁻⁵), at 100 m 5.4·10⁻⁵
//! (2.8·10⁻⁴), at 1 km 3.7·10⁻⁴ (1.7·10⁻³) — rays that pass within the offset of an edge (256
//! ulps: 2 mm at 100 m, 1.6 cm at 1 km) change sides, so the error grows with the distance. The
//! bounds below sit 3–10× above those. At 10 km the offset is 25 cm and the light (0.1 mm below the
//! ceiling) shares the ceiling's float values: the scene no longer exists in `f32` there, so that
//! is not tested.

mod common;

use glam::Vec3;
use raywave::cpu::CpuBackend;
use raywave::report::error_vs_time::{relmse, PreparedScene, METHODS};
use raywave::{Backend, Scene};

const RESOLUTION: u32 = 64;
const SPP: u32 = 4;
const SEED: u32 = 7;

/// Distance scale `k` of the move (metres), the largest relMSE any method's image may have
/// against the frame at the origin, and the largest relative change of any image's mean.
const CASES: [(f32, f64, f64); 3] = [(10.0, 3e-5, 5e-4), (100.0, 3e-4, 2e-3), (1000.0, 2e-3, 5e-3)];

/// The Cornell box with its camera moved by `offset`.
fn moved(base: &Scene, offset: Vec3) -> Scene {
    let meshes = base
        .meshes()
        .iter()
        .cloned()
        .map(|mut mesh| {
            mesh.positions.iter_mut().for_each(|p| *p += offset);
            mesh
        })
        .collect();
    let mut camera = *base.camera();
    camera.position += offset;
    camera.look_at += offset;
    Scene::new("moved cornell", meshes, camera).expect("the moved scene is valid")
}

/// Every method's image of `scene` ([`METHODS`] order) on `backend`.
fn images(backend: &mut dyn Backend, scene: &Scene) -> Vec<Vec<Vec3>> {
    let prepared = PreparedScene::new(backend, scene, RESOLUTION).expect("G-buffer");
    let frame = prepared.frame(backend, SPP, SEED).expect("frame");
    frame.into_iter().map(|(image, _)| image).collect()
}

fn mean(image: &[Vec3]) -> f64 {
    image.iter().map(|c| f64::from(c.x + c.y + c.z)).sum::<f64>() / image.len() as f64
}

/// Asserts that `backend` renders the moved boxes like the one at the origin.
fn assert_same_far_away(backend: &mut dyn Backend) {
    let base = common::cornell();
    let at_origin = images(backend, &base);
    for (scale, max_relmse, max_mean_change) in CASES {
        let far = images(backend, &moved(&base, scale * Vec3::new(1.0, -0.5, 0.7)));
        for ((method, image), reference) in METHODS.iter().zip(&far).zip(&at_origin) {
            let what = format!("{} at {scale} m, {method}", backend.name());
            assert!(image.iter().all(|c| c.is_finite()), "{what}: a pixel is not finite");
            let error = relmse(image, reference);
            let change = (mean(image) / mean(reference) - 1.0).abs();
            eprintln!("{what}: relMSE {error:.2e}, mean {change:+.1e}");
            assert!(error <= max_relmse, "{what}: relMSE {error} against the box at the origin");
            assert!(change <= max_mean_change, "{what}: the mean changed by {change}");
        }
    }
}

#[test]
fn a_frame_far_from_the_origin_matches_it_at_the_origin_on_the_cpu() {
    assert_same_far_away(&mut CpuBackend::new());
}

#[cfg(feature = "vulkan")]
#[test]
fn a_frame_far_from_the_origin_matches_it_at_the_origin_on_every_vulkan_device() {
    for mut device in common::vulkan::every_device("a_frame_far_from_the_origin_matches_it_at_the_origin") {
        assert_same_far_away(&mut device);
        common::vulkan::assert_clean(&device);
    }
}
