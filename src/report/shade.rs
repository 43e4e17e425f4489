//! `raywave report shade`: the ratio estimator against the fully stochastic one (seed 000).
//!
//! As in the talk, the visible surfaces are fixed (one camera ray per pixel, as a rasterized
//! G-buffer would give) and only the light samples are stochastic. For each built-in scene: a
//! reference (the ratio estimate at `reference_spp`, whose `S_N/U_N` has converged; equal to `U`
//! exactly where nothing is in shadow), then for 1, 2, 4, … 64 samples per pixel the RMSE of the
//! ratio estimate `U · S_N / U_N` and of the stochastic `S_N` against it — over all pixels, over
//! shadowed pixels (reference `S/U` below 0.995 in luminance) and over unshadowed ones — the root
//! of the squared error's mean over those pixels and `reps` independent seeds — and, once per scene, the error of any unbiased estimate made
//! of `U` times one binary visibility sample (the `visibility-floor` lines), which is what the
//! 1-spp ratio estimate is up to its small bias. Emitters seen directly add the same radiance to
//! every sample of a fixed surface, so they cancel in the error.

use super::error_vs_time::PreparedScene;
use super::{sum_from_zero, Repeated};
use crate::frame::{generate_params_with, sampler_params};
use crate::kernels::sampling::light_select::luminance;
use crate::shading::{ShadeAccumulator, ShadeData};
use crate::shared::sampling::sampler_kind;
use crate::{Backend, Result, Scene};
use glam::{DVec3, Vec3};

/// What to measure.
pub type ShadeReportOptions = super::SceneReportOptions;

/// One measurement, printed as one JSON line.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ShadeLine {
    /// Scene name.
    pub scene: String,
    /// Samples per pixel.
    pub spp: u32,
    /// `ratio`, `stochastic`, or `visibility-floor` (1 spp only: the error of any unbiased
    /// estimate that multiplies `U` by one binary visibility sample; see [`visibility_floor`]).
    pub estimator: &'static str,
    /// `all`, `shadow` or `lit`.
    pub region: &'static str,
    /// Root-mean-square error against the reference (linear radiance, mean over RGB): the square
    /// root of the squared error's mean over every pixel of the region and every repetition, the
    /// statistic the `visibility-floor` (computed from the reference alone) bounds.
    pub rmse: f64,
    /// The standard error of `rmse` over the repetitions, by the delta method: the standard error
    /// of the repetitions' mean squared error ([`Repeated::standard_error`]) over `2·rmse`. ±t
    /// times it is a 95 % confidence interval, t = 3.18 for 4 repetitions, 1.96 for many; absent
    /// for one repetition and for the `visibility-floor`, which is no mean of repetitions. It
    /// covers the repetitions' spread only, not the reference's error they share: in the ratio
    /// estimate's `lit` region, where that is almost all of the error (the reference's rarely
    /// blocked samples), every repetition can have the same error and the standard error be 0.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rmse_stderr: Option<f64>,
    /// Pixels in the region.
    pub pixels: usize,
}

impl crate::output_line::OutputLine for ShadeLine {
    fn json(&self) -> String {
        crate::output_line::json_object(self)
    }

    fn row(&self) -> String {
        let stderr = self.rmse_stderr.map_or(String::new(), |e| format!(" ± {e:.5}"));
        format!(
            "{:<28} {:>3} spp  {:<10} {:<6} RMSE {:.5}{stderr}  ({} px)",
            self.scene, self.spp, self.estimator, self.region, self.rmse, self.pixels
        )
    }
}

/// The visible surfaces of `scene` (loaded into `backend`): one camera ray per pixel, at a fixed
/// sub-pixel position, traced once — the G-buffer the shade samples are drawn on.
pub struct GBuffer {
    rays: crate::RayStream,
    hits: crate::HitStream,
    /// Seconds the backend took to generate and trace the camera rays.
    pub seconds: f64,
    /// Rays or hits the trace sanitized ([`crate::StageReport::sanitized`]).
    pub sanitized: u64,
}

impl GBuffer {
    /// Traces the camera rays of a `resolution²` image.
    pub fn new(backend: &mut dyn Backend, scene: &Scene, resolution: u32) -> Result<Self> {
        let sampler = sampler_params(sampler_kind::ZSOBOL, 0, resolution, resolution, 1);
        let frame = backend.render(&generate_params_with(scene, resolution, resolution, 0, sampler))?;
        let seconds = frame.timings.iter().map(|t| t.seconds).sum();
        let sanitized = crate::StageReport::total_sanitized(&frame.timings);
        Ok(Self { rays: frame.rays, hits: frame.hits, seconds, sanitized })
    }

    /// The surface each pixel's camera ray hit (the denoiser's G-buffer).
    pub fn surfaces(&self, data: &ShadeData) -> Vec<crate::kernels::shade::stage::Surface> {
        crate::shading::resolve(data, &self.rays, &self.hits)
    }
}

/// The share of a pixel's analytic `U` (in luminance) its converged image must show to count as
/// unshadowed: 99.5 %, so that the reference's own residual noise does not count as shadow.
pub const LIT_FRACTION: f32 = 0.995;

/// The pixels of an image split by how much of their direct light reaches them in the
/// converged image: the error of a shadow estimator is made in the first set.
pub struct ShadowRegions {
    /// Pixels in penumbra or umbra: the converged image shows less than [`LIT_FRACTION`] of `U`.
    pub shadow: Vec<usize>,
    /// Unshadowed pixels: the converged image shows at least [`LIT_FRACTION`] of `U`.
    pub lit: Vec<usize>,
}

impl ShadowRegions {
    /// Splits the pixels of `reference` (converged, `emitted` radiance included, which is taken
    /// out first, as [`visibility_floor`] does: an emitter's own light is no direct light
    /// reaching it) by their analytic unshadowed `analytic`; pixels without direct light
    /// (`U` = 0) are in neither set.
    pub fn new(analytic: &[Vec3], emitted: &[Vec3], reference: &[Vec3]) -> Self {
        let (mut shadow, mut lit) = (Vec::new(), Vec::new());
        for (i, ((&u, &emitted), &converged)) in analytic.iter().zip(emitted).zip(reference).enumerate() {
            let u = luminance(u);
            if u > 0.0 {
                if luminance(converged - emitted) < LIT_FRACTION * u {
                    shadow.push(i);
                } else {
                    lit.push(i);
                }
            }
        }
        Self { shadow, lit }
    }
}

/// Runs `spp` shade passes on `gbuffer` (shade and occlusion on `backend`) with `seed` and
/// returns the accumulated `U`, `U_N`, `S_N` and the seconds the passes took on the backend.
pub fn accumulate(
    backend: &mut dyn Backend,
    gbuffer: &GBuffer,
    data: &ShadeData,
    resolution: u32,
    spp: u32,
    seed: u32,
) -> Result<(ShadeAccumulator, f64)> {
    let sampler = sampler_params(sampler_kind::ZSOBOL, seed, resolution, resolution, spp);
    let mut accumulator = ShadeAccumulator::new((resolution * resolution) as usize);
    let mut seconds = 0.0;
    for sample_index in 0..spp {
        let params = data.params(sampler, resolution, resolution, sample_index);
        let (timings, _) = accumulator.shade_pass(backend, &params, data, &gbuffer.rays, &gbuffer.hits)?;
        seconds += timings.iter().map(|t| t.seconds).sum::<f64>();
    }
    Ok((accumulator, seconds))
}

/// Mean squared error over `pixels` (mean over RGB).
fn mse(image: &[Vec3], reference: &[Vec3], pixels: &[usize]) -> f64 {
    let sum = sum_from_zero(pixels.iter().map(|&i| {
        let d = (image[i] - reference[i]).as_dvec3();
        d.length_squared() / 3.0
    }));
    sum / pixels.len().max(1) as f64
}

/// The RMSE over `pixels` (mean over RGB) that an **unbiased** estimate made of the analytic `U`
/// times **one binary visibility sample** per pixel leaves: with the reference's shadow ratio
/// `v = (reference − emitted) / U` per channel, a 0/1 sample of mean `v` has the variance
/// `v(1 − v)`, so the pixel's squared error is `U² · v(1 − v)` — whatever the sampling that draws
/// it. At 1 spp the ratio estimate is such a product (`S_N / U_N` is the one shadow ray's
/// visibility, 0 or 1), but its mean `q`, the chance that the one sample is visible (and 1 where
/// `U_N` = 0 falls back to `U`), is not `v`: the estimator is consistent, not unbiased. Its
/// squared error is `U² · (q(1 − q) + (q − v)²) = U² · (v(1 − v) + (q − v)(1 − 2v))`, whose
/// bias term may take either sign — negative where `q` errs towards the nearer of 0 and 1,
/// positive in an umbra that the fallback lights — so the floor is what the ratio estimate would
/// leave were it unbiased, not a bound on it; on the Cornell box at 32² it measured 1.07 × the
/// floor (`tests/report_shade.rs` holds it within 0.9–1.2 ×). The bound is exact where every channel sees the same visible
/// fraction (one light, lobes of one colour); under lights of different colours, or where a
/// coloured diffuse lobe and a white specular one weigh a partly hidden light differently, `v`
/// differs between channels and one scalar sample cannot have every channel's mean. Stratified
/// samples (ZSobol) beat `floor/√N` at `N` > 1, so only the 1-spp floor is reported.
pub fn visibility_floor(analytic: &[Vec3], reference: &[Vec3], emitted: &[Vec3], pixels: &[usize]) -> f64 {
    let sum = sum_from_zero(pixels.iter().map(|&i| {
        let u = analytic[i].as_dvec3();
        let shadowed = (reference[i] - emitted[i]).as_dvec3();
        let v = (shadowed / u).clamp(DVec3::ZERO, DVec3::ONE);
        let v = DVec3::select(u.cmpgt(DVec3::ZERO), v, DVec3::ONE);
        (u * u * v * (DVec3::ONE - v)).element_sum() / 3.0
    }));
    (sum / pixels.len().max(1) as f64).sqrt()
}

/// The standard error of `√mean` of `squared_error`'s repetitions by the delta method,
/// `se(mean) / (2·√mean)`; 0 where every repetition's error was 0, `None` for one repetition.
fn rmse_standard_error(squared_error: &Repeated) -> Option<f64> {
    let rmse = squared_error.mean().sqrt();
    squared_error.standard_error().map(|se| if rmse > 0.0 { se / (2.0 * rmse) } else { 0.0 })
}

/// Runs the report, handing each line to `emit` as soon as it is measured.
pub fn report_shade(
    backend: &mut dyn Backend,
    options: &ShadeReportOptions,
    mut emit: impl FnMut(&ShadeLine),
) -> Result<()> {
    options.check()?;
    for (name, scene) in options.scenes.iter().zip(options.load_scenes()?) {
        let prepared = PreparedScene::new(backend, &scene, options.resolution)?;
        let (reference, sanitized) = prepared.reference(backend, options.reference_spp)?;
        super::warn_if_sanitized(name, options.reference_spp, sanitized);
        let PreparedScene { data, gbuffer, analytic, emitted, .. } = &prepared;
        let all: Vec<usize> = (0..reference.len()).collect();
        let ShadowRegions { shadow, lit } = prepared.shadow_regions(&reference);
        for (region, pixels) in [("all", &all), ("shadow", &shadow), ("lit", &lit)] {
            emit(&ShadeLine {
                scene: name.clone(),
                spp: 1,
                estimator: "visibility-floor",
                region,
                rmse: visibility_floor(analytic, &reference, emitted, pixels),
                rmse_stderr: None,
                pixels: pixels.len(),
            });
        }
        for spp in options.spp_steps() {
            let mut squared_error = [[Repeated::default(); 3]; 2];
            let mut sanitized = gbuffer.sanitized;
            for rep in 0..options.reps {
                let (run, _) = accumulate(backend, gbuffer, data, options.resolution, spp, rep)?;
                sanitized += run.sanitized();
                let ((ratio, replaced), stochastic) = (run.ratio_image(), run.stochastic_image());
                sanitized += replaced;
                for (e, image) in [&ratio, &stochastic].into_iter().enumerate() {
                    for (r, pixels) in [&all, &shadow, &lit].into_iter().enumerate() {
                        squared_error[e][r].add(mse(image, &reference, pixels));
                    }
                }
            }
            super::warn_if_sanitized(name, spp, sanitized);
            for (e, estimator) in ["ratio", "stochastic"].into_iter().enumerate() {
                for (r, (region, pixels)) in [("all", &all), ("shadow", &shadow), ("lit", &lit)].into_iter().enumerate()
                {
                    emit(&ShadeLine {
                        scene: name.clone(),
                        spp,
                        estimator,
                        region,
                        rmse: squared_error[e][r].mean().sqrt(),
                        rmse_stderr: rmse_standard_error(&squared_error[e][r]),
                        pixels: pixels.len(),
                    });
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rmse_standard_error_is_the_mean_squared_errors_over_twice_the_rmse() {
        let mut squared_error = Repeated::default();
        squared_error.add(4.0);
        assert_eq!(rmse_standard_error(&squared_error), None);
        squared_error.add(12.0);
        // Mean 8, sample variance 32, standard error √(32/2) = 4; √8 = 2√2.
        let expected = 4.0 / (2.0 * 8.0f64.sqrt());
        assert!((rmse_standard_error(&squared_error).unwrap() - expected).abs() < 1e-12);
        let mut exact = Repeated::default();
        exact.add(0.0);
        exact.add(0.0);
        assert_eq!(rmse_standard_error(&exact), Some(0.0));
    }

    #[test]
    fn visibility_floor_is_the_binary_sample_variance_times_u_squared() {
        // Pixel 0: half in shadow under U = 2 in every channel → U²·¼ = 1. Pixel 1: lit (v = 1),
        // pixel 2: umbra (v = 0), pixel 3: U = 0 (nothing to estimate) — no error for any of them.
        // Pixel 4: v = (0.1, 0.5, 0.9) under U = 1 over an emitter of 5 that cancels.
        let analytic = [Vec3::splat(2.0), Vec3::splat(3.0), Vec3::splat(3.0), Vec3::ZERO, Vec3::ONE];
        let emitted = [Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::splat(5.0)];
        let reference = [Vec3::ONE, Vec3::splat(3.0), Vec3::ZERO, Vec3::ONE, Vec3::new(5.1, 5.5, 5.9)];
        let floor = |pixels: &[usize]| visibility_floor(&analytic, &reference, &emitted, pixels);
        assert!((floor(&[0]) - 1.0).abs() < 1e-12);
        assert_eq!(floor(&[1, 2, 3]), 0.0);
        assert!((floor(&[0, 1]) - 0.5f64.sqrt()).abs() < 1e-12, "a mean over the pixels");
        let expected = ((0.09 + 0.25 + 0.09) / 3.0f64).sqrt();
        assert!((floor(&[4]) - expected).abs() < 1e-6, "{} vs {expected}", floor(&[4]));
        // +0: `Iterator::sum` of no f64 is −0, printed as an RMSE of -0.0.
        assert!(floor(&[]) == 0.0 && floor(&[]).is_sign_positive());
        let empty = mse(&analytic, &reference, &[]);
        assert!(empty == 0.0 && empty.is_sign_positive());
    }
}
