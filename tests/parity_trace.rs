//! Parity of the trace stage: the CPU executor (obvhs CWBVH + watertight test) and every Vulkan
//! device (ray query against a BLAS/TLAS) report the same closest hits on the same rays.
//!
//! Tolerance: the same (instance, primitive) for ≥ 99.99 % of rays (rays grazing a shared edge may
//! legitimately pick either triangle), t within 1e-5 relative, barycentrics within 1e-4 absolute
//! on rays that agree on the primitive (drivers compute them with their own, non-watertight
//! arithmetic; 1e-4 is a hundredth of a texel of a 1k texture).
#![cfg(feature = "vulkan")]

mod common;

use common::{close, cornell, vulkan};
use raywave::cpu::{self, CpuScene};
use raywave::frame::generate_params;
use raywave::shared::stream::NO_HIT;
use raywave::{Backend, HitStream, RayStream, Scene};

const MIN_AGREEMENT: f64 = 0.9999;
const T_REL_TOLERANCE: f32 = 1e-5;
const BARYCENTRIC_TOLERANCE: f32 = 1e-4;

/// Compares two hit streams and returns the fraction of rays that agree on the hit primitive.
fn compare(expected: &HitStream, actual: &HitStream) -> f64 {
    assert_eq!(expected.len(), actual.len());
    let mut same = 0usize;
    for i in 0..expected.len() {
        let same_hit = expected.primitive[i] == actual.primitive[i] && expected.instance[i] == actual.instance[i];
        if !same_hit {
            continue;
        }
        same += 1;
        assert!(actual.t[i].is_finite() && actual.barycentrics[i].is_finite(), "ray {i}: non-finite output");
        if expected.primitive[i] != NO_HIT {
            assert!(
                close(expected.t[i], actual.t[i], T_REL_TOLERANCE, 0.0),
                "ray {i}: t {} vs {}",
                expected.t[i],
                actual.t[i]
            );
            let db = (expected.barycentrics[i] - actual.barycentrics[i]).abs().max_element();
            assert!(
                db <= BARYCENTRIC_TOLERANCE,
                "ray {i}: barycentrics {} vs {}",
                expected.barycentrics[i],
                actual.barycentrics[i]
            );
        }
    }
    same as f64 / expected.len() as f64
}

/// Camera rays plus, for variety, rays from inside the box in hashed directions.
fn test_rays(scene: &Scene) -> RayStream {
    let mut rays = cpu::generate(&generate_params(scene, 320, 320, 0, 3));
    let centre = glam::Vec3::new(0.278, 0.274, 0.28);
    for i in 0..rays.len() / 2 {
        let h = raywave::kernels::hash::pcg3d(glam::UVec3::new(i as u32, 11, 5));
        let u = glam::Vec3::new(h.x as f32, h.y as f32, h.z as f32) / u32::MAX as f32 * 2.0 - 1.0;
        let dir = if u.length_squared() > 1e-6 { u.normalize() } else { glam::Vec3::Y };
        rays.origin[i] = centre.extend(0.0);
        rays.direction[i] = dir.extend(10.0);
    }
    rays
}

#[test]
fn trace_matches_cpu_on_every_vulkan_device() {
    let scene = cornell();
    let cpu_scene = CpuScene::build(&scene).expect("BVH builds");
    let rays = test_rays(&scene);
    assert!(rays.len() >= 100_000);
    let expected = cpu::trace(&cpu_scene, &rays);
    let hit_fraction = expected.primitive.iter().filter(|&&p| p != NO_HIT).count() as f64 / rays.len() as f64;
    // The box is open towards the camera (no front wall), so about a tenth of the rays escape.
    assert!(hit_fraction > 0.85, "the test rays must mostly hit the box ({hit_fraction})");
    for mut device in vulkan::every_device("trace parity") {
        device.load_scene(&scene).expect("acceleration structures build");
        let (hits, _) = device.trace(&rays).expect("trace runs");
        let agreement = compare(&expected, &hits);
        assert!(agreement >= MIN_AGREEMENT, "{}: only {:.5} of rays agree", device.info().name, agreement);
        eprintln!("{}: {:.6} of {} rays agree with the CPU", device.info().name, agreement, rays.len());
        vulkan::assert_clean(&device);
    }
}

#[test]
fn whole_frame_matches_cpu_on_every_vulkan_device() {
    let scene = cornell();
    let params = generate_params(&scene, 257, 193, 0, 9);
    let mut cpu_backend = raywave::cpu::CpuBackend::new();
    cpu_backend.load_scene(&scene).unwrap();
    let expected = cpu_backend.render(&params).unwrap();
    for mut device in vulkan::every_device("frame parity") {
        device.load_scene(&scene).unwrap();
        let frame = device.render(&params).unwrap();
        assert_eq!(frame.rays.pixel, expected.rays.pixel);
        assert!(compare(&expected.hits, &frame.hits) >= MIN_AGREEMENT);
        assert_eq!(frame.timings.iter().map(|t| t.stage).collect::<Vec<_>>(), ["generate", "trace"]);
        vulkan::assert_clean(&device);
    }
}

#[test]
fn untraceable_rays_miss_on_every_backend() {
    let scene = cornell();
    let mut rays = RayStream::zeroed(4);
    let ok_dir = glam::Vec4::new(0.0, 0.0, 1.0, 10.0);
    rays.origin = vec![
        glam::Vec4::new(f32::NAN, 0.3, 0.3, 0.0),
        glam::Vec4::new(0.3, 0.3, 0.3, 0.0),
        glam::Vec4::new(0.3, 0.3, 0.3, 5.0),
        glam::Vec4::new(0.3, 0.3, 0.3, 0.0),
    ];
    rays.direction =
        vec![ok_dir, glam::Vec4::new(0.0, 0.0, 0.0, 10.0), ok_dir, glam::Vec4::new(0.0, 0.0, 1.0, f32::INFINITY)];
    let expected = cpu::trace(&CpuScene::build(&scene).unwrap(), &rays);
    assert!(expected.primitive.iter().all(|&p| p == NO_HIT));
    for mut device in vulkan::every_device("untraceable rays") {
        device.load_scene(&scene).unwrap();
        let (hits, _) = device.trace(&rays).unwrap();
        assert_eq!(hits, expected);
        vulkan::assert_clean(&device);
    }
}
