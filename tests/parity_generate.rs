//! Parity of the generate stage: the CPU executor and every Vulkan device produce the same ray
//! stream. Tolerance: pixel indices identical; every float within 2e-6 relative to the magnitude
//! of the vector it belongs to (origins and tmin/tmax are copies, directions are normalised on
//! each device with its own `sqrt` and division, which Vulkan allows to differ by a few ulp).
#![cfg(feature = "vulkan")]

mod common;

use common::{close, cornell, vulkan};
use glam::Vec4Swizzles;
use raywave::cpu;
use raywave::frame::{generate_params_with, sampler_params};
use raywave::shared::sampling::sampler_kind;
use raywave::Backend;

/// Documented float tolerance of the generate stage, relative.
const REL_TOLERANCE: f32 = 2e-6;

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
            assert!(timing.seconds >= 0.0);
            assert_eq!(rays.len(), expected.len());
            assert_eq!(rays.pixel, expected.pixel, "pixel indices must be identical");
            for i in 0..rays.len() {
                let (o, e) = (rays.origin[i], expected.origin[i]);
                let (d, f) = (rays.direction[i], expected.direction[i]);
                let o_scale = e.xyz().length();
                for k in 0..4 {
                    assert!(close(o[k], e[k], REL_TOLERANCE, o_scale), "ray {i} origin {o} vs {e}");
                    assert!(
                        close(d[k], f[k], REL_TOLERANCE, if k < 3 { 1.0 } else { f.w.abs() }),
                        "ray {i} direction {d} vs {f}"
                    );
                }
            }
            vulkan::assert_clean(device);
        }
    }
}
