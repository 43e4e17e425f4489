//! Parity of the sampling module: the sampler's integer outputs are bit-identical on the CPU and
//! on every Vulkan device, for every sampler kind, and the warps agree within a documented
//! tolerance and pass the same statistical checks on each device.
#![cfg(feature = "vulkan")]

mod common;

use common::vulkan;
use common::warp_cases::within_pdf_spread;
use glam::Vec3;
use raywave::cpu::CpuBackend;
use raywave::shared::sampling::{sampler_kind, SamplerParams};
use raywave::shared::SamplerProbeParams;
use raywave::Backend;

/// Whether `points` (raw 32-bit fractions, `2^m` of them) form a (0,m,2)-net: every elementary
/// interval of area `2^-m` holds exactly one point.
fn is_net(points: &[glam::UVec2]) -> bool {
    let m = points.len().trailing_zeros();
    (0..=m).all(|row_bits| {
        let col_bits = m - row_bits;
        let mut seen = vec![false; points.len()];
        points.iter().all(|p| {
            let x = if col_bits == 0 { 0 } else { p.x >> (32 - col_bits) };
            let y = if row_bits == 0 { 0 } else { p.y >> (32 - row_bits) };
            let cell = ((y << col_bits) | x) as usize;
            !std::mem::replace(&mut seen[cell], true)
        })
    })
}

/// Asserts elementary-interval stratification of the first `2^k` samples of each pixel, for
/// both Sobol' samplers, as computed by `backend`.
fn assert_stratified(backend: &mut dyn Backend) {
    for kind in [sampler_kind::ZSOBOL, sampler_kind::SOBOL] {
        for spp_log2 in [0u32, 1, 4, 7, 10] {
            let params = SamplerProbeParams {
                sampler: SamplerParams { kind, seed: 99, spp_log2, resolution_log2: 3 },
                width: 8,
                height: 4,
                dimension: 2,
                padding: 0,
            };
            let bits = backend.sampler_probe(&params).expect("probe runs");
            assert_eq!(bits.len() as u32, params.sample_count(), "{}: kind {kind} 2^{spp_log2} spp", backend.name());
            for (pixel, samples) in bits.chunks(1 << spp_log2).enumerate() {
                assert!(is_net(samples), "{}: kind {kind} 2^{spp_log2} spp pixel {pixel} not a net", backend.name());
            }
        }
    }
}

#[test]
fn every_pixels_sobol_samples_are_stratified_on_every_device() {
    assert_stratified(&mut CpuBackend::new());
    for mut device in vulkan::each_device("sampler stratification") {
        assert_stratified(&mut device);
        vulkan::assert_clean(device);
    }
}

#[test]
fn sampler_bits_are_identical_on_every_vulkan_device() {
    let mut cpu = CpuBackend::new();
    let mut devices = vulkan::each_device("sampler parity");
    // Odd image sizes, 1…256 samples per pixel, low and high slots, extreme seeds.
    let shapes =
        [(37u32, 23u32, 0u32, 0u32, 1u32), (16, 16, 4, 3, 0xffff_ffff), (5, 3, 8, 31, 12345), (64, 64, 1, 7, 2)];
    for (width, height, spp_log2, dimension, seed) in shapes {
        for kind in 0..sampler_kind::COUNT {
            let resolution_log2 = width.max(height).next_power_of_two().trailing_zeros();
            let params = SamplerProbeParams {
                sampler: SamplerParams { kind, seed, spp_log2, resolution_log2 },
                width,
                height,
                dimension,
                padding: 0,
            };
            let expected = cpu.sampler_probe(&params).expect("cpu probe");
            assert_eq!(expected.len() as u32, params.sample_count());
            for device in &mut devices {
                let bits = device.sampler_probe(&params).expect("device probe");
                assert_eq!(bits.len(), expected.len(), "kind {kind}, {params:?} on {}", device.name());
                let mismatches = bits.iter().zip(&expected).filter(|(a, b)| a != b).count();
                assert_eq!(mismatches, 0, "kind {kind}, {params:?}: {mismatches} samples differ on {}", device.name());
                vulkan::assert_no_messages_yet(device);
            }
        }
    }
    devices.into_iter().for_each(vulkan::assert_clean);
}

/// Documented tolerance of the warp parity: the warps' trigonometry is the kernels' own
/// (`raywave_kernels::trig`), but a device rounds `+ − × ÷ √` its own way (an NVIDIA driver
/// contracts `a·b + c` into one fused multiply-add), so directions agree within 2·10⁻³
/// (components of a unit vector) or a twentieth of the spread of the case's directions, whichever
/// is smaller (a cone 10⁻³ rad wide spans 2·10⁻³: there any direction in it would have passed),
/// and pdfs within 1 % relative — or, where the pdf is
/// ill-conditioned in `f32`, within what the CPU's own pdf gives for directions a few ulps from
/// its sample (`warp_cases::within_pdf_spread`) — for all but 10⁻³ of the samples, which may sit on a pdf
/// discontinuity (the rim of a cone, the edge of a quad) and legitimately flip sides.
const WARP_DIRECTION_TOLERANCE: f32 = 2.0e-3;
const WARP_PDF_REL_TOLERANCE: f32 = 1.0e-2;
const WARP_OUTLIER_FRACTION: f64 = 1.0e-3;

#[test]
fn every_warp_passes_its_statistical_check_on_every_vulkan_device() {
    let mut devices = vulkan::each_device("warp parity");
    for (name, params) in common::warp_cases::warp_cases() {
        let expected = common::warp_cases::cpu_samples(&params);
        let (lowest, highest) = expected
            .iter()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), s| (lo.min(s.truncate()), hi.max(s.truncate())));
        let tolerance = WARP_DIRECTION_TOLERANCE.min(0.05 * (highest - lowest).max_element());
        for device in &mut devices {
            let samples = device.warp_probe(&params).expect("warp probe runs");
            assert_eq!(samples.len(), expected.len());
            let outliers: Vec<usize> = (0..samples.len())
                .filter(|&i| {
                    let (g, c) = (samples[i], expected[i]);
                    let direction_off = (g.truncate() - c.truncate()).abs().max_element() > tolerance;
                    let pdf_off = (g.w - c.w).abs() > WARP_PDF_REL_TOLERANCE * c.w.abs().max(1e-6)
                        && !within_pdf_spread(&params, c.truncate(), c.w, g.w, WARP_PDF_REL_TOLERANCE, 0.0);
                    direction_off || pdf_off || !g.is_finite()
                })
                .collect();
            let examples: Vec<String> =
                outliers.iter().take(6).map(|&i| format!("  {i}: {} vs {}", samples[i], expected[i])).collect();
            common::assert_within_budget(
                outliers.len(),
                samples.len(),
                WARP_OUTLIER_FRACTION,
                &format!("{name} on {}: samples differing from the CPU (device vs CPU)", device.name()),
                &examples,
            );
            if let Err(report) = common::warp_cases::check_warp(&name, &params, &samples) {
                panic!("{name} on {}:\n{report}", device.name());
            }
            vulkan::assert_no_messages_yet(device);
        }
    }
    devices.into_iter().for_each(vulkan::assert_clean);
}
