//! `raywave report shade`: the ratio estimator against the fully stochastic one (seed 000).
//!
//! As in the talk, the visible surfaces are fixed (one camera ray per pixel, as a rasterized
//! G-buffer would give) and only the light samples are stochastic. For each built-in scene: a
//! reference (the ratio estimate at `reference_spp`, whose `S_N/U_N` has converged; equal to `U`
//! exactly where nothing is in shadow), then for 1, 2, 4, … 64 samples per pixel the RMSE of the
//! ratio estimate `U · S_N / U_N` and of the stochastic `S_N` against it — over all pixels, over
//! shadowed pixels (reference `S/U` below 0.995 in luminance) and over unshadowed ones — averaged
//! over `reps` independent seeds. Emitters seen directly add the same radiance to every sample
//! of a fixed surface, so they cancel in the error.

use crate::frame::{generate_params_with, sampler_params};
use crate::kernels::sampling::light_select::luminance;
use crate::shading::{ShadeAccumulator, ShadeData};
use crate::shared::sampling::sampler_kind;
use crate::{Backend, Result, Scene};
use glam::Vec3;

/// What to measure.
pub type ShadeReportOptions = super::SceneReportOptions;

/// One measurement, printed as one JSON line.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ShadeLine {
    /// Scene name.
    pub scene: String,
    /// Samples per pixel.
    pub spp: u32,
    /// `ratio` or `stochastic`.
    pub estimator: &'static str,
    /// `all`, `shadow` or `lit`.
    pub region: &'static str,
    /// Root-mean-square error against the reference (linear radiance, mean over RGB), averaged
    /// over the repetitions.
    pub rmse: f64,
    /// Pixels in the region.
    pub pixels: usize,
}

impl ShadeLine {
    /// The JSON line.
    pub fn json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }

    /// A table row.
    pub fn row(&self) -> String {
        format!(
            "{:<28} {:>3} spp  {:<10} {:<6} RMSE {:.5}  ({} px)",
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
}

impl GBuffer {
    /// Traces the camera rays of a `resolution²` image.
    pub fn new(backend: &mut dyn Backend, scene: &Scene, resolution: u32) -> Result<Self> {
        let sampler = sampler_params(sampler_kind::ZSOBOL, 0, resolution, resolution, 1);
        let frame = backend.render(&generate_params_with(scene, resolution, resolution, 0, sampler))?;
        let seconds = frame.timings.iter().map(|t| t.seconds).sum();
        Ok(Self { rays: frame.rays, hits: frame.hits, seconds })
    }

    /// The surface each pixel's camera ray hit (the denoiser's G-buffer).
    pub fn surfaces(&self, data: &ShadeData) -> Vec<crate::kernels::shade::stage::Surface> {
        crate::shading::resolve(data, &self.rays, &self.hits)
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
    let sum: f64 = pixels
        .iter()
        .map(|&i| {
            let d = (image[i] - reference[i]).as_dvec3();
            d.length_squared() / 3.0
        })
        .sum();
    sum / pixels.len().max(1) as f64
}

/// Runs the report, handing each line to `emit` as soon as it is measured.
pub fn report_shade(
    backend: &mut dyn Backend,
    options: &ShadeReportOptions,
    mut emit: impl FnMut(&ShadeLine),
) -> Result<()> {
    options.check("report shade")?;
    for (name, scene) in options.scenes.iter().zip(options.load_scenes()?) {
        backend.load_scene(&scene)?;
        let data = ShadeData::new(&scene)?;
        let gbuffer = GBuffer::new(backend, &scene, options.resolution)?;
        let (reference_run, _) =
            accumulate(backend, &gbuffer, &data, options.resolution, options.reference_spp, 0xfeed)?;
        let reference = reference_run.ratio_image();
        let analytic = reference_run.analytic();
        let all: Vec<usize> = (0..reference.len()).collect();
        let lit_reference = |i: &usize| luminance(analytic[*i]) > 0.0;
        let shadow: Vec<usize> = all
            .iter()
            .copied()
            .filter(|i| lit_reference(i) && luminance(reference[*i]) < 0.995 * luminance(analytic[*i]))
            .collect();
        let lit: Vec<usize> = all
            .iter()
            .copied()
            .filter(|i| lit_reference(i) && luminance(reference[*i]) >= 0.995 * luminance(analytic[*i]))
            .collect();
        for spp in options.spp_steps() {
            let mut sums = [[0.0f64; 3]; 2];
            for rep in 0..options.reps {
                let (run, _) = accumulate(backend, &gbuffer, &data, options.resolution, spp, rep)?;
                let (ratio, stochastic) = (run.ratio_image(), run.stochastic_image());
                for (e, image) in [&ratio, &stochastic].into_iter().enumerate() {
                    for (r, pixels) in [&all, &shadow, &lit].into_iter().enumerate() {
                        sums[e][r] += mse(image, &reference, pixels).sqrt();
                    }
                }
            }
            for (e, estimator) in ["ratio", "stochastic"].into_iter().enumerate() {
                for (r, (region, pixels)) in [("all", &all), ("shadow", &shadow), ("lit", &lit)].into_iter().enumerate()
                {
                    emit(&ShadeLine {
                        scene: name.clone(),
                        spp,
                        estimator,
                        region,
                        rmse: sums[e][r] / f64::from(options.reps),
                        pixels: pixels.len(),
                    });
                }
            }
        }
    }
    Ok(())
}
