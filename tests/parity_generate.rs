//! Parity of the generate stage: the CPU executor and every Vulkan device produce the same ray
//! stream. Tolerance: pixel indices identical; every float within 2e-6 relative to the magnitude
//! of the vector it belongs to (origins and tmin/tmax are copies, directions are normalised on
//! each device with its own `sqrt` and division, which Vulkan allows to differ by a few ulp).
#![cfg(feature = "vulkan")]

mod common;

use common::{cornell, vulkan};
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
