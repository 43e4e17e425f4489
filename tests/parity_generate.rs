//! Parity of the generate stage: the CPU executor and every Vulkan device produce the same ray
//! stream. Tolerance: pixel indices identical; every float within 2e-6 relative to the magnitude
//! of the vector it belongs to (origins and tmin/tmax are copies, directions are normalised on
//! each device with its own `sqrt` and division, which Vulkan allows to differ by a few ulp).
#![cfg(feature = "vulkan")]

mod common;

use common::{cornell, vulkan};
use glam::Vec3;
use raywave::cpu;
use raywave::frame::{generate_params_with, sampler_params};
use raywave::shared::sampling::sampler_kind;
use raywave::Backend;

#[test]
fn generate_matches_cpu_on_every_vulkan_device() {
    let scene = cornell();
    let mut devices = vulkan::each_device("generate parity");
    // Odd sizes leave a partial workgroup and a partial dispatch row; every sampler, with and
    // without a thin lens.
    let cases = [(333, 211, 0, 1, 0.0), (64, 1, 5, 77, 0.05), (1, 1, 0, 0, 0.0), (40, 30, 3, 5, 0.02)];
    for ((width, height, sample, seed, lens_radius), kind) in
        cases.into_iter().flat_map(|c| (0..sampler_kind::COUNT).map(move |k| (c, k)))
    {
        let sampler = sampler_params(kind, seed, width, height, 8);
        let mut params = generate_params_with(&scene, width, height, sample, sampler);
        params.lens_radius = lens_radius;
        let expected = cpu::generate(&params).expect("generate");
        for device in &mut devices {
            let (rays, timing) = device.generate(&params).expect("generate runs");
            assert_eq!((timing.stage, timing.sanitized), ("generate", 0), "{timing:?}");
            assert!(timing.seconds.is_finite(), "{timing:?}");
            common::assert_rays_match(&expected, &rays, &device.name());
            vulkan::assert_no_messages_yet(device);
        }
    }
    devices.into_iter().for_each(vulkan::assert_clean);
}

/// The hard cameras: a field of view of 0.01° and of 179° (image-plane axes 8.7·10⁻⁵ and 115 long),
/// images 4096 × 2 and 2 × 4096 wide open, views exactly along an axis, a camera 10⁶ from the
/// origin, and a thin lens at that distance, along and across its view. The rays must match as
/// on the Cornell camera.
#[test]
fn generate_matches_cpu_for_extreme_cameras_on_every_vulkan_device() {
    let scene = cornell();
    let mut devices = vulkan::each_device("generate parity, extreme cameras");
    let half_tan = |fov_degrees: f32| (fov_degrees.to_radians() * 0.5).tan();
    // (width, height, origin, forward, right axis, up axis, vertical fov°, lens radius)
    let cases = [
        (17, 13, Vec3::ZERO, Vec3::NEG_Z, Vec3::X, Vec3::Y, 0.01, 0.0),
        (17, 13, Vec3::new(0.5, 0.5, 3.0), Vec3::NEG_Z, Vec3::X, Vec3::Y, 179.0, 0.0),
        (4096, 2, Vec3::ZERO, Vec3::X, Vec3::NEG_Z, Vec3::Y, 90.0, 0.0),
        (2, 4096, Vec3::ZERO, Vec3::NEG_Y, Vec3::X, Vec3::Z, 170.0, 0.0),
        (
            23,
            19,
            Vec3::new(1e6, -1e6, 1e6),
            Vec3::new(-1.0, 1.0, -1.0).normalize(),
            Vec3::new(1.0, 1.0, 0.0).normalize(),
            Vec3::new(-1.0, 1.0, 2.0).normalize(),
            40.0,
            0.0,
        ),
        (23, 19, Vec3::new(1e6, 0.0, 0.0), Vec3::NEG_X, Vec3::Z, Vec3::Y, 40.0, 0.25),
        // The far coordinate across the view, where the lens and focal points had rounded to the
        // camera's grid (a GPU fusing one multiply-add had then aimed a ray pixels off).
        (23, 19, Vec3::new(1e5, 0.0, 0.0), Vec3::NEG_Z, Vec3::X, Vec3::Y, 40.0, 1e-3),
    ];
    for (width, height, origin, forward, right, up, fov, lens_radius) in cases {
        let sampler = sampler_params(sampler_kind::ZSOBOL, 9, width, height, 4);
        let mut params = generate_params_with(&scene, width, height, 3, sampler);
        let tan_y = half_tan(fov);
        params.origin = origin.extend(0.0);
        params.forward = forward.extend(0.0);
        params.right = (right * tan_y * width as f32 / height as f32).extend(0.0);
        params.up = (up * tan_y).extend(0.0);
        params.tmax = 4e6;
        params.lens_radius = lens_radius;
        params.focus_distance = 10.0;
        let expected = cpu::generate(&params).expect("generate");
        assert_eq!(expected.len() as u32, width * height);
        for ray in 0..expected.len() {
            let direction = expected.direction[ray];
            let cosine = direction.truncate().dot(forward);
            assert!(direction.is_finite() && cosine > 0.0, "fov {fov}°: ray {ray} {direction} is not in front");
        }
        for device in &mut devices {
            let (rays, _) = device.generate(&params).expect("generate runs");
            common::assert_rays_match(
                &expected,
                &rays,
                &format!("{} (fov {fov}°, {width}×{height}, at {origin})", device.name()),
            );
            vulkan::assert_no_messages_yet(device);
        }
    }
    devices.into_iter().for_each(vulkan::assert_clean);
}
