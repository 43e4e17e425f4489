//! The denoise passes on the CPU: each pass is the kernel function over every pixel (rayon),
//! exactly what the Vulkan entry points run per invocation.

use super::count;
use crate::backend::StageReport;
use crate::denoise::{DenoiseInput, DenoiseMethod, DenoisePass, WorkingBuffers};
use glam::{IVec2, Vec4};
use rayon::prelude::*;
use raywave_kernels::denoise::bilateral::{bilateral_pass, ImageLine};
use raywave_kernels::denoise::{noise, svgf};
use raywave_kernels::shade::stage::{apply_visibility, composite};
use raywave_shared::denoise::axis;
use raywave_shared::DenoiseParams;
use std::sync::atomic::AtomicU64;
use std::time::Instant;

/// The buffers a denoiser threads through its passes, each allocated and written (at the image's
/// size, or empty where no pass of the method writes it) before the timed passes, as the Vulkan
/// backend's buffers are; a pass writes into its output buffer and, where it reads its own kind
/// of input, swaps the two.
struct Working {
    noise_raw: Vec<f32>,
    noise: Vec<f32>,
    shadowed: Vec<Vec4>,
    unshadowed: Vec<Vec4>,
    /// What a bilateral pass writes (then swapped with `shadowed` and `unshadowed`).
    filtered_shadowed: Vec<Vec4>,
    filtered_unshadowed: Vec<Vec4>,
    ratio: Vec<Vec4>,
    /// What an SVGF pass writes (then swapped with `ratio`).
    filtered_ratio: Vec<Vec4>,
    color: Vec<Vec4>,
}

impl Working {
    /// The buffers `passes` write, for `input`.
    fn for_passes(passes: &[DenoisePass], input: &DenoiseInput) -> Self {
        let needs = WorkingBuffers::for_passes(passes);
        let sized = |needed: bool| if needed { input.len() } else { 0 };
        Self {
            noise_raw: written_zeros(sized(needs.noise)),
            noise: written_zeros(sized(needs.noise)),
            shadowed: input.shadowed.clone(),
            unshadowed: input.unshadowed.clone(),
            filtered_shadowed: written_zeros(sized(needs.filtered)),
            filtered_unshadowed: written_zeros(sized(needs.filtered)),
            ratio: written_zeros(sized(needs.ratio)),
            filtered_ratio: written_zeros(sized(needs.filtered_ratio)),
            color: written_zeros(input.len()),
        }
    }
}

/// `len` zeros, every one written: unlike `vec![0.0; len]`, whose zeroed allocation maps its
/// pages only when a pass first writes them, so that no pass's time includes those page faults.
fn written_zeros<T: Clone + Default>(len: usize) -> Vec<T> {
    let mut zeros = Vec::with_capacity(len);
    zeros.resize(len, T::default());
    zeros
}

/// Writes `f(pixel)` into `out[i]` for every pixel `i` of the image in parallel, as every
/// invocation of a per-pixel entry point does (`out` holds one value per pixel).
fn per_pixel_into<T: Send>(params: &DenoiseParams, out: &mut [T], f: impl Fn(IVec2) -> T + Sync) {
    out.par_iter_mut().zip(0..params.pixels()).for_each(|(value, i)| {
        if let Some(pixel) = params.pixel(i) {
            *value = f(pixel);
        }
    });
}

/// Writes `f(i)` into `out[i]` for every index of `out` in parallel: a per-pixel pass that
/// reads only its own pixel.
fn per_index_into<T: Send>(out: &mut [T], f: impl Fn(usize) -> T + Sync) {
    out.par_iter_mut().enumerate().for_each(|(i, value)| *value = f(i));
}

/// Runs `pass` on the CPU; returns how many invocations replaced a non-finite value (only the
/// composites, the denoiser's boundary, can).
fn run_pass(pass: DenoisePass, params: &DenoiseParams, input: &DenoiseInput, w: &mut Working) -> u64 {
    let sanitized = AtomicU64::new(0);
    let (position, normal) = (&input.position, &input.normal);
    match pass {
        DenoisePass::Ratio => {
            let (shadowed, unshadowed) = (&w.shadowed, &w.unshadowed);
            per_index_into(&mut w.ratio, |i| noise::ratio_pixel(shadowed[i], unshadowed[i]));
        }
        DenoisePass::Noise => {
            let ratio = &w.ratio;
            per_pixel_into(params, &mut w.noise_raw, |p| noise::noise_estimate(params, p, ratio));
        }
        DenoisePass::NoiseBlur => {
            let raw = &w.noise_raw;
            per_pixel_into(params, &mut w.noise, |p| noise::blurred_noise(params, p, raw));
        }
        DenoisePass::BilateralX | DenoisePass::BilateralY => {
            let along = if pass == DenoisePass::BilateralX { axis::X } else { axis::Y };
            let params = DenoiseParams { axis: along, ..*params };
            let (shadowed, unshadowed, noise) = (&w.shadowed, &w.unshadowed, &w.noise);
            let filtered = w.filtered_shadowed.par_iter_mut().zip(&mut w.filtered_unshadowed);
            filtered.zip(0..params.pixels()).for_each(|((s, u), i)| {
                if let Some(center) = params.pixel(i) {
                    let line = ImageLine { shadowed, unshadowed, position, normal, center, params: &params };
                    (*s, *u) = bilateral_pass(&line, noise[i as usize], &params);
                }
            });
            std::mem::swap(&mut w.shadowed, &mut w.filtered_shadowed);
            std::mem::swap(&mut w.unshadowed, &mut w.filtered_unshadowed);
        }
        DenoisePass::Composite => {
            let (shadowed, unshadowed) = (&w.shadowed, &w.unshadowed);
            per_index_into(&mut w.color, |i| {
                let (analytic, emitted) = (input.analytic[i].truncate(), input.emitted[i].truncate());
                let c = composite(analytic, unshadowed[i].truncate(), shadowed[i].truncate(), emitted);
                count(c, &sanitized).extend(1.0)
            });
        }
        DenoisePass::SvgfVariance => {
            let ratio = &w.ratio;
            per_pixel_into(params, &mut w.filtered_ratio, |p| {
                svgf::ratio_and_variance(params, p, ratio, position, normal)
            });
            std::mem::swap(&mut w.ratio, &mut w.filtered_ratio);
        }
        DenoisePass::SvgfAtrous { step } => {
            let params = DenoiseParams { step, ..*params };
            let ratio = &w.ratio;
            per_pixel_into(&params, &mut w.filtered_ratio, |p| svgf::atrous_step(&params, p, ratio, position, normal));
            std::mem::swap(&mut w.ratio, &mut w.filtered_ratio);
        }
        DenoisePass::SvgfComposite => {
            let ratio = &w.ratio;
            per_index_into(&mut w.color, |i| {
                let (analytic, emitted) = (input.analytic[i].truncate(), input.emitted[i].truncate());
                let c = apply_visibility(analytic, ratio[i].truncate(), emitted);
                count(c, &sanitized).extend(1.0)
            });
        }
    }
    sanitized.into_inner()
}

/// The copy probe on the CPU ([`crate::Backend::copy_probe`]; `image` already checked against
/// `params`): the loop every pass runs, copying each pixel into a buffer allocated beforehand.
pub fn copy_probe(params: &DenoiseParams, image: &[Vec4]) -> (Vec<Vec4>, StageReport) {
    let mut copy = written_zeros(params.pixels() as usize);
    let start = Instant::now();
    per_index_into(&mut copy, |i| image[i]);
    (copy, StageReport::clean("copy probe", start.elapsed().as_secs_f64()))
}

/// Runs `method` on `input` (already checked against `params`): the colour image (rgb, w = 1)
/// and each pass's wall-clock time.
pub fn denoise(method: DenoiseMethod, params: &DenoiseParams, input: &DenoiseInput) -> (Vec<Vec4>, Vec<StageReport>) {
    run_passes(method.passes(params), params, input)
}

/// Runs `passes` in order on `input`: the colour image and each pass's wall-clock time.
fn run_passes(passes: Vec<DenoisePass>, params: &DenoiseParams, input: &DenoiseInput) -> (Vec<Vec4>, Vec<StageReport>) {
    let mut working = Working::for_passes(&passes, input);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::denoise::TV_PASSES;
    use raywave_kernels::hash::CounterRng;

    /// A composite that overflows `f32` (`E + U · S_N/U_N` with `U` and `E` of 3·10³⁸, inputs the
    /// check accepts) is replaced and counted in the composite pass's report, as the Vulkan
    /// entry point's counter counts it: the report is how a caller learns that a pixel was lost.
    #[test]
    fn an_overflowing_composite_is_replaced_and_counted() {
        let params = DenoiseParams::new(2, 1);
        let radiance = |v: f32| vec![Vec4::new(v, v, v, 0.0); 2];
        let mut input = DenoiseInput {
            position: vec![Vec4::ZERO; 2],
            normal: vec![Vec4::ZERO; 2],
            analytic: radiance(1.0),
            emitted: radiance(0.0),
            shadowed: radiance(0.5),
            unshadowed: radiance(0.5),
        };
        input.analytic[1].x = 3e38;
        input.emitted[1].x = 3e38;
        input.check(&params).unwrap();
        let (color, reports) = denoise(DenoiseMethod::None, &params, &input);
        assert!(color.iter().all(|c| c.is_finite()), "{color:?}");
        assert_eq!(color[0], Vec4::ONE, "the sound pixel: U · S_N/U_N");
        assert_eq!(reports.iter().map(|r| (r.stage, r.sanitized)).collect::<Vec<_>>(), [("denoise composite", 1)]);
    }

    /// Where [`DenoiseParams::tv_filter_is_identity`] lets the TV method skip to its composite,
    /// its full passes give that image bit for bit: coin-flip visibility over a tilted plane,
    /// U_N varying and sometimes 0, a few pixels without a surface, at N = 4R² samples. One
    /// sample fewer, they filter.
    #[test]
    fn the_tv_passes_leave_the_image_as_it_is_where_the_method_skips_them() {
        const WIDTH: u32 = 23;
        const HEIGHT: u32 = 17;
        let mut rng = CounterRng::new(11);
        let mut input = DenoiseInput::default();
        for i in 0..WIDTH * HEIGHT {
            let (x, y) = ((i % WIDTH) as f32, (i / WIDTH) as f32);
            let surface = i % 29 != 0;
            let point = glam::Vec3::new(x - 11.0, y - 8.0, -20.0 - 0.3 * x);
            let analytic = glam::Vec3::new(0.8, 0.6, 0.3) * (0.5 + rng.next_f32());
            let unshadowed = if rng.next_f32() < 0.1 { glam::Vec3::ZERO } else { analytic * (0.5 + rng.next_f32()) };
            let visible = rng.next_f32() < 0.5;
            input.position.push(if surface { point.extend(point.length()) } else { Vec4::ZERO });
            input.normal.push(if surface { glam::Vec3::Z.extend(analytic.y) } else { Vec4::ZERO });
            input.analytic.push(analytic.extend(0.0));
            input.unshadowed.push(unshadowed.extend(0.0));
            input.shadowed.push(if visible { unshadowed.extend(0.0) } else { Vec4::ZERO });
            input.emitted.push(Vec4::new(0.0, 0.1 * (i % 3) as f32, 0.0, 0.0));
        }
        let mut params = DenoiseParams { seed: 3, ..DenoiseParams::with_radius(WIDTH, HEIGHT, 4) };
        params.samples_per_pixel = 4 * params.radius * params.radius;
        assert!(params.tv_filter_is_identity());
        assert_eq!(DenoiseMethod::Tv.passes(&params), [DenoisePass::Composite]);
        let (skipped, _) = denoise(DenoiseMethod::Tv, &params, &input);
        let (full, reports) = run_passes(TV_PASSES.to_vec(), &params, &input);
        assert_eq!(full, skipped, "the full passes at N = 4R²");
        assert!(reports.iter().all(|r| r.sanitized == 0));
        params.samples_per_pixel -= 1;
        let (filtered, _) = run_passes(TV_PASSES.to_vec(), &params, &input);
        assert_ne!(filtered, skipped, "at N = 4R² − 1 the filter works");
    }

    /// The bilateral passes take each pixel's width from the blurred noise estimate, not the raw
    /// one (the denoise review's gap): over a plane facing the camera, lit everywhere but at
    /// scattered shadowed pixels (one in 50), a pixel passes through both passes untouched exactly
    /// where the *blurred* estimate makes its Gaussian ≤ ½ pixel, and among the pixels whose own
    /// noise lines see no shadow (raw width ≤ ½) but whose neighbours' do, many are filtered.
    /// Reading the raw estimate instead filters pixels of the first kind and leaves those of the
    /// second untouched (it fails at a pixel of the first kind).
    #[test]
    fn the_bilateral_passes_filter_with_the_blurred_noise_estimate() {
        const WIDTH: u32 = 64;
        const HEIGHT: u32 = 48;
        let mut rng = CounterRng::new(5);
        let mut input = DenoiseInput::default();
        for i in 0..WIDTH * HEIGHT {
            let point = glam::Vec3::new((i % WIDTH) as f32, (i / WIDTH) as f32, -50.0);
            let lit = Vec4::new(0.5, 0.4, 0.3, 0.0);
            input.position.push(point.extend(50.0));
            input.normal.push(glam::Vec3::Z.extend(0.4));
            input.analytic.push(lit);
            input.unshadowed.push(lit);
            input.shadowed.push(if rng.next_f32() < 0.02 { Vec4::ZERO } else { lit });
            input.emitted.push(Vec4::ZERO);
        }
        let params = DenoiseParams { seed: 9, ..DenoiseParams::with_radius(WIDTH, HEIGHT, 4) };
        input.check(&params).unwrap();
        let (unfiltered, _) = denoise(DenoiseMethod::None, &params, &input);
        let (filtered, _) = denoise(DenoiseMethod::Tv, &params, &input);

        let ratio: Vec<Vec4> =
            input.shadowed.iter().zip(&input.unshadowed).map(|(&s, &u)| noise::ratio_pixel(s, u)).collect();
        let pixels: Vec<IVec2> = (0..params.pixels()).map(|i| params.pixel(i).unwrap()).collect();
        let raw: Vec<f32> = pixels.iter().map(|&p| noise::noise_estimate(&params, p, &ratio)).collect();
        let blurred: Vec<f32> = pixels.iter().map(|&p| noise::blurred_noise(&params, p, &raw)).collect();
        let filters = |noise: f32| {
            raywave_kernels::denoise::bilateral::gaussian_radius(noise, params.radius, params.samples_per_pixel) > 0.5
        };
        let (mut quiet, mut spread_to, mut spread_and_changed) = (0, 0, 0);
        for i in 0..pixels.len() {
            if !filters(blurred[i]) {
                assert_eq!(filtered[i], unfiltered[i], "pixel {}: blurred noise {}", pixels[i], blurred[i]);
                quiet += usize::from(filters(raw[i]));
            } else if !filters(raw[i]) {
                spread_to += 1;
                spread_and_changed += usize::from(filtered[i] != unfiltered[i]);
            }
        }
        assert!(quiet >= 10, "only {quiet} pixels with loud raw but quiet blurred noise");
        assert!(spread_to >= 100, "only {spread_to} pixels with quiet raw but loud blurred noise");
        assert!(spread_and_changed * 2 >= spread_to, "{spread_and_changed} of {spread_to} filtered");
    }
}
