//! The denoise passes on the CPU: each pass is the kernel function over every pixel (rayon),
//! exactly what the Vulkan entry points run per invocation.

use super::count;
use crate::backend::StageReport;
use crate::denoise::{DenoiseInput, DenoiseMethod, DenoisePass};
use glam::{IVec2, Vec4};
use rayon::prelude::*;
use raywave_kernels::denoise::bilateral::{bilateral_pass, ImageLine};
use raywave_kernels::denoise::{noise, svgf};
use raywave_kernels::shade::stage::{apply_visibility, composite};
use raywave_shared::denoise::axis;
use raywave_shared::DenoiseParams;
use std::sync::atomic::AtomicU64;
use std::time::Instant;

/// The buffers a denoiser threads through its passes.
struct Working {
    noise_raw: Vec<f32>,
    noise: Vec<f32>,
    shadowed: Vec<Vec4>,
    unshadowed: Vec<Vec4>,
    /// What a bilateral pass writes (then swapped with `shadowed` and `unshadowed`): allocated
    /// before the timed passes, as the Vulkan backend's buffers are; empty for SVGF.
    filtered_shadowed: Vec<Vec4>,
    filtered_unshadowed: Vec<Vec4>,
    ratio: Vec<Vec4>,
    color: Vec<Vec4>,
}

/// The pixel at row-major index `i` of an image of `params`' width.
fn pixel_at(params: &DenoiseParams, i: u32) -> IVec2 {
    IVec2::new((i % params.width) as i32, (i / params.width) as i32)
}

/// Evaluates `f` at every pixel of the image in parallel.
fn per_pixel<T: Send>(params: &DenoiseParams, f: impl Fn(IVec2) -> T + Sync) -> Vec<T> {
    (0..params.pixels()).into_par_iter().map(|i| f(pixel_at(params, i))).collect()
}

/// The index of `pixel` in a row-major image of `params`' width.
fn pixel_index(params: &DenoiseParams, pixel: IVec2) -> usize {
    (pixel.y as u32 * params.width + pixel.x as u32) as usize
}

/// Runs `pass` on the CPU; returns how many invocations replaced a non-finite value (only the
/// composites, the denoiser's boundary, can).
fn run_pass(pass: DenoisePass, params: &DenoiseParams, input: &DenoiseInput, w: &mut Working) -> u64 {
    let sanitized = AtomicU64::new(0);
    let index = |p: IVec2| pixel_index(params, p);
    match pass {
        DenoisePass::Ratio => {
            w.ratio = w.shadowed.par_iter().zip(&w.unshadowed).map(|(&s, &u)| noise::ratio_pixel(s, u)).collect();
        }
        DenoisePass::Noise => w.noise_raw = per_pixel(params, |p| noise::noise_estimate(params, p, &w.ratio)),
        DenoisePass::NoiseBlur => w.noise = per_pixel(params, |p| noise::blurred_noise(params, p, &w.noise_raw)),
        DenoisePass::BilateralX | DenoisePass::BilateralY => {
            let along = if pass == DenoisePass::BilateralX { axis::X } else { axis::Y };
            let params = DenoiseParams { axis: along, ..*params };
            let (shadowed, unshadowed, noise) = (&w.shadowed, &w.unshadowed, &w.noise);
            let filtered = w.filtered_shadowed.par_iter_mut().zip(&mut w.filtered_unshadowed);
            filtered.enumerate().for_each(|(i, (s, u))| {
                let (position, normal) = (&input.position, &input.normal);
                let center = pixel_at(&params, i as u32);
                let line = ImageLine { shadowed, unshadowed, position, normal, center, params: &params };
                (*s, *u) = bilateral_pass(&line, noise[i], &params);
            });
            std::mem::swap(&mut w.shadowed, &mut w.filtered_shadowed);
            std::mem::swap(&mut w.unshadowed, &mut w.filtered_unshadowed);
        }
        DenoisePass::Composite => {
            w.color = per_pixel(params, |p| {
                let i = index(p);
                let c = composite(
                    input.analytic[i].truncate(),
                    w.unshadowed[i].truncate(),
                    w.shadowed[i].truncate(),
                    input.emitted[i].truncate(),
                );
                count(c, &sanitized).extend(1.0)
            });
        }
        DenoisePass::SvgfVariance => {
            w.ratio =
                per_pixel(params, |p| svgf::ratio_and_variance(params, p, &w.ratio, &input.position, &input.normal));
        }
        DenoisePass::SvgfAtrous { step } => {
            let params = DenoiseParams { step, ..*params };
            w.ratio = per_pixel(&params, |p| svgf::atrous_step(&params, p, &w.ratio, &input.position, &input.normal));
        }
        DenoisePass::SvgfComposite => {
            w.color = per_pixel(params, |p| {
                let i = index(p);
                let c =
                    apply_visibility(input.analytic[i].truncate(), w.ratio[i].truncate(), input.emitted[i].truncate());
                count(c, &sanitized).extend(1.0)
            });
        }
    }
    sanitized.into_inner()
}

/// The copy probe on the CPU ([`crate::Backend::copy_probe`]; `image` already checked against
/// `params`): the loop every pass runs, copying each pixel.
pub fn copy_probe(params: &DenoiseParams, image: &[Vec4]) -> (Vec<Vec4>, StageReport) {
    let start = Instant::now();
    let copy = per_pixel(params, |p| image[pixel_index(params, p)]);
    (copy, StageReport::clean("copy probe", start.elapsed().as_secs_f64()))
}

/// Runs `method` on `input` (already checked against `params`): the colour image (rgb, w = 1)
/// and each pass's wall-clock time.
pub fn denoise(method: DenoiseMethod, params: &DenoiseParams, input: &DenoiseInput) -> (Vec<Vec4>, Vec<StageReport>) {
    let passes = method.passes(params);
    let bilateral = passes.iter().any(|&pass| matches!(pass, DenoisePass::BilateralX | DenoisePass::BilateralY));
    let filtered = || vec![Vec4::ZERO; if bilateral { input.len() } else { 0 }];
    let mut working = Working {
        noise_raw: Vec::new(),
        noise: Vec::new(),
        shadowed: input.shadowed.clone(),
        unshadowed: input.unshadowed.clone(),
        filtered_shadowed: filtered(),
        filtered_unshadowed: filtered(),
        ratio: Vec::new(),
        color: Vec::new(),
    };
    let timings = passes
        .into_iter()
        .map(|pass| {
            let start = Instant::now();
            let sanitized = run_pass(pass, params, input, &mut working);
            StageReport::once(pass.name(), start.elapsed().as_secs_f64(), sanitized)
        })
        .collect();
    (working.color, timings)
}
