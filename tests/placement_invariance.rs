//! The frame does not depend on where the scene is or how large it is: the Cornell box (0.56 m
//! across) moved with its camera by `k · (1, −0.5, 0.7)` m, or scaled about the origin with it
//! (radiance depends on directions only), must render what it renders as built — generate, trace,
//! shade, the shadow rays' occlusion and both denoisers, on the CPU and every Vulkan device ×
//! trace method — up to the rounding of its coordinates.
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
//! of each other), the largest relMSE of the five methods' images against the box as built, and
//! the largest change of their means: moved 10 m 3.3·10⁻⁶ (5·10⁻⁵), 100 m 5.4·10⁻⁵ (2.8·10⁻⁴),
//! 1 km 3.7·10⁻⁴ (1.7·10⁻³) — rays that pass within the offset of an edge (256 ulps: 2 mm at
//! 100 m, 1.6 cm at 1 km) change sides, so the error grows with the distance; scaled 10⁻³
//! (0.56 mm across, where the offset is its absolute floor 2⁻¹⁶ m, 3 % of the box) 5.8·10⁻⁴
//! (1.2·10⁻³), 10⁻² 5.6·10⁻⁵ (1.3·10⁻⁴), 10³ 5.0·10⁻⁵ (9.8·10⁻⁴). The bounds below sit 3–10×
//! above those. At 10 km the offset is 25 cm and the light (0.1 mm below the ceiling) shares the ceiling's float values: the
//! scene no longer exists in `f32` there, so that is not tested.

mod common;

use glam::Vec3;
use raywave::cpu::CpuBackend;
use raywave::report::error_vs_time::{relmse, PreparedScene, METHODS};
use raywave::{Backend, Scene};

const RESOLUTION: u32 = 64;
const SPP: u32 = 4;
const SEED: u32 = 7;

/// One placement of the box: every point `p` (its vertices, the camera's eye and target) becomes
/// `scale · p + offset`; the largest relMSE any method's image may have against the box as built,
/// and the largest relative change of any image's mean.
struct Placement {
    scale: f32,
    offset: Vec3,
    max_relmse: f64,
    max_mean_change: f64,
}

/// A move by `k · (1, −0.5, 0.7)` m: far from the origin in every axis, on both sides of it.
const fn moved(k: f32, max_relmse: f64, max_mean_change: f64) -> Placement {
    Placement { scale: 1.0, offset: Vec3::new(k, -0.5 * k, 0.7 * k), max_relmse, max_mean_change }
}

/// A uniform scale about the origin.
const fn scaled(scale: f32, max_relmse: f64, max_mean_change: f64) -> Placement {
    Placement { scale, offset: Vec3::ZERO, max_relmse, max_mean_change }
}

const PLACEMENTS: [Placement; 6] = [
    moved(10.0, 3e-5, 5e-4),
    moved(100.0, 3e-4, 2e-3),
    moved(1000.0, 2e-3, 5e-3),
    scaled(1e-3, 3e-3, 5e-3),
    scaled(1e-2, 3e-4, 1e-3),
    scaled(1e3, 3e-4, 5e-3),
];

impl Placement {
    /// `base` placed.
    fn apply(&self, base: &Scene) -> Scene {
        let place = |p: Vec3| self.scale * p + self.offset;
        let meshes = base
            .meshes()
            .iter()
            .cloned()
            .map(|mut mesh| {
                mesh.positions.iter_mut().for_each(|p| *p = place(*p));
                mesh
            })
            .collect();
        let mut camera = *base.camera();
        camera.position = place(camera.position);
        camera.look_at = place(camera.look_at);
        Scene::new("placed cornell", meshes, camera).expect("the placed scene is valid")
    }
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

/// Asserts that `backend` renders every placed box like the box as built.
fn assert_placement_invariant(backend: &mut dyn Backend) {
    let base = common::cornell();
    let as_built = images(backend, &base);
    for placement in &PLACEMENTS {
        let placed = images(backend, &placement.apply(&base));
        for ((method, image), reference) in METHODS.iter().zip(&placed).zip(&as_built) {
            let what = format!("{}, scale {} offset {}, {method}", backend.name(), placement.scale, placement.offset);
            assert!(image.iter().all(|c| c.is_finite()), "{what}: a pixel is not finite");
            let error = relmse(image, reference);
            let change = (mean(image) / mean(reference) - 1.0).abs();
            eprintln!("{what}: relMSE {error:.2e}, mean {change:+.1e}");
            assert!(error <= placement.max_relmse, "{what}: relMSE {error} against the box as built");
            assert!(change <= placement.max_mean_change, "{what}: the mean changed by {change}");
        }
    }
}

#[test]
fn a_moved_or_scaled_frame_matches_the_frame_as_built_on_the_cpu() {
    assert_placement_invariant(&mut CpuBackend::new());
}

#[cfg(feature = "vulkan")]
#[test]
fn a_moved_or_scaled_frame_matches_the_frame_as_built_on_every_vulkan_device() {
    for mut device in common::vulkan::every_device("a_moved_or_scaled_frame_matches_the_frame_as_built") {
        assert_placement_invariant(&mut device);
        common::vulkan::assert_clean(&device);
    }
}
