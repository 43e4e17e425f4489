//! `raywave report sampling`: seed 002's variance table, reproduced on built-in scenes.
//!
//! Each case renders the Cornell box image with two estimators at the talk's sample count, `reps`
//! times with independent seeds, and compares the per-pixel variance across repetitions, averaged
//! over the image. Every sample is a whole path segment as the talk's renderer took it: a camera
//! ray jittered in its pixel by the generate stage, traced, then one shadow (or occlusion) ray from
//! the hit, all drawn from the estimator's sampler (slots of `kernels::sampling::dims`):
//!
//! | case | worse | better | spp | published |
//! |---|---|---|---|---|
//! | `ao_cosine_vs_uniform` | uniform hemisphere | cosine-weighted | 4 | 1.74 |
//! | `sphere_cone_vs_area` | whole-sphere area sampling | subtended cone | 4 | 2.90 |
//! | `light_importance_vs_uniform` | uniform light choice | importance (power·cos/d²) | 4 | 2.46 |
//! | `sobol_vs_random` | independent random | Owen-scrambled Sobol' | 16 | ≈2.6 |
//!
//! The published ratios are from Pharr 2018 (seed 002). Every worse estimator draws independent
//! samples, so its variance falls exactly as 1/N and the rays it needs for the better one's error
//! are `spp · ratio`.

use super::scenes::{self, ShadingPoint};
use super::variance::{variance_ratio_interval, GroupedMoments};
use crate::kernels::sampling::{dims, light_select, sampler, warp};
use crate::shared::sampling::sampler_kind;
use crate::shared::Light;
use crate::{Backend, RayStream, Result, Scene};
use glam::{UVec2, Vec2, Vec3, Vec4};
use rayon::prelude::*;

/// What to measure.
#[derive(Clone, Debug)]
pub struct SamplingReportOptions {
    /// Image side in pixels: `resolution²` shading points (a power of two keeps the Morton order
    /// of the blue-noise sampler aligned).
    pub resolution: u32,
    /// Independent repetitions per estimator (≥ 2).
    pub reps: u32,
}

/// How a shadow ray's direction is chosen.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum Strategy {
    /// Ambient occlusion within `AO_RADIUS`, uniform hemisphere directions.
    AoUniform,
    /// Ambient occlusion within `AO_RADIUS`, cosine-weighted directions.
    AoCosine,
    /// Direct light from the sphere lights: choose a light (uniformly or by importance), then a
    /// point on its whole surface by area, or a direction in its subtended cone.
    SphereLights {
        /// Sample the subtended cone (else the whole sphere by area).
        cone: bool,
        /// Choose the light by importance (else uniformly).
        importance: bool,
    },
    /// Direct light from one quad light, sampled uniformly by area.
    QuadArea,
}

/// One estimator: a strategy fed by a sampler.
#[derive(Copy, Clone, Debug)]
pub struct Estimator {
    /// Short name for the table.
    pub label: &'static str,
    /// Direction choice.
    pub strategy: Strategy,
    /// One of [`sampler_kind`].
    pub sampler: u32,
}

/// One row of seed 002's table.
#[derive(Copy, Clone, Debug)]
pub struct Case {
    /// JSON name.
    pub name: &'static str,
    /// The variance ratio the talk reports.
    pub published: f64,
    /// Samples (rays) per pixel per estimate.
    pub spp: u32,
    /// The estimator expected to have the larger variance.
    pub worse: Estimator,
    /// The estimator expected to have the smaller variance.
    pub better: Estimator,
}

/// Ambient-occlusion radius in metres (the Cornell box is 0.55 m wide).
pub const AO_RADIUS: f32 = 0.1;

/// The four cases, in the talk's order.
pub fn cases() -> [Case; 4] {
    let independent = sampler_kind::INDEPENDENT;
    let sphere = |cone, importance| Strategy::SphereLights { cone, importance };
    [
        Case {
            name: "ao_cosine_vs_uniform",
            published: 1.74,
            spp: 4,
            worse: Estimator { label: "uniform", strategy: Strategy::AoUniform, sampler: independent },
            better: Estimator { label: "cosine", strategy: Strategy::AoCosine, sampler: independent },
        },
        Case {
            name: "sphere_cone_vs_area",
            published: 2.90,
            spp: 4,
            worse: Estimator { label: "whole sphere", strategy: sphere(false, false), sampler: independent },
            better: Estimator { label: "cone", strategy: sphere(true, false), sampler: independent },
        },
        Case {
            name: "light_importance_vs_uniform",
            published: 2.46,
            spp: 4,
            worse: Estimator { label: "uniform light", strategy: sphere(true, false), sampler: independent },
            better: Estimator { label: "importance", strategy: sphere(true, true), sampler: independent },
        },
        Case {
            name: "sobol_vs_random",
            published: 2.6,
            spp: 16,
            worse: Estimator { label: "random", strategy: Strategy::QuadArea, sampler: independent },
            better: Estimator { label: "owen-sobol", strategy: Strategy::QuadArea, sampler: sampler_kind::SOBOL },
        },
    ]
}

/// The measured result of one case.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CaseResult {
    /// Case name.
    pub case: &'static str,
    /// Image variance of the worse estimator over that of the better one.
    pub variance_ratio: f64,
    /// Its 95 % confidence interval (`variance::variance_ratio_interval`, a jackknife over groups
    /// of repetitions); `null` where it cannot be formed: fewer than three repetitions, or an
    /// image variance of 0 with a group of them left out.
    pub variance_ratio_low: Option<f64>,
    /// The interval's upper end.
    pub variance_ratio_high: Option<f64>,
    /// The talk's ratio.
    pub published: f64,
    /// Independent repetitions per estimator.
    pub reps: u32,
    /// Samples per pixel per estimate.
    pub spp: u32,
    /// Mean per-pixel variance of the worse estimator.
    pub variance_worse: f64,
    /// Mean per-pixel variance of the better estimator.
    pub variance_better: f64,
    /// Rays per pixel the worse estimator needs for the better one's variance (`spp · ratio`,
    /// exact in expectation because the worse estimator's samples are independent).
    pub rays_for_equal_error: f64,
    /// Pixels in the image (the variance is averaged over all of them).
    pub pixels: usize,
}

impl CaseResult {
    /// The JSON line.
    pub fn json(&self) -> String {
        crate::output_line::json_object(self)
    }

    /// A human-readable table row.
    pub fn row(&self, case: &Case) -> String {
        format!(
            "{:<28} {:>14} vs {:<12} {:>3} spp  ratio {:>6.2} {} (published {:.2}, ours/published {:.2})  \
             {:>5.1} rays for equal error  [{} reps, {} px]",
            self.case,
            case.worse.label,
            case.better.label,
            self.spp,
            self.variance_ratio,
            match (self.variance_ratio_low, self.variance_ratio_high) {
                (Some(low), Some(high)) => format!("(95 %: {low:.2}–{high:.2})"),
                _ => "(no interval: fewer than three repetitions, or a variance of 0)".to_string(),
            },
            self.published,
            self.variance_ratio / self.published,
            self.rays_for_equal_error,
            self.reps,
            self.pixels
        )
    }
}

/// The lights of a strategy's scene.
fn lights_for(strategy: Strategy) -> Vec<Light> {
    match strategy {
        Strategy::AoUniform | Strategy::AoCosine => Vec::new(),
        Strategy::SphereLights { .. } => scenes::two_sphere_lights(),
        Strategy::QuadArea => vec![scenes::skinny_quad_light()],
    }
}

/// One shadow ray of an estimator: direction, length, and the weight its visibility is
/// multiplied by (0 when the sample cannot contribute; the ray is then not traced).
#[derive(Copy, Clone, Debug, Default)]
pub struct ShadowSample {
    /// Unit direction.
    pub direction: Vec3,
    /// Ray length (to the light sample, or the AO radius).
    pub tmax: f32,
    /// Contribution if unoccluded.
    pub weight: f32,
}

/// The contribution of a light sample to a diffuse point: `L · (ρ/π) · cos θ / (pdf · pmf)`, zero
/// if the sample is behind the point or on the light's back side.
fn light_contribution(point: &ShadingPoint, light: &Light, s: &warp::LightSample, pmf: f32) -> ShadowSample {
    let cos_surface = point.normal.dot(s.direction);
    let facing_light = s.normal.dot(-s.direction) > 0.0;
    if s.pdf <= 0.0 || pmf <= 0.0 || cos_surface <= 0.0 || !facing_light {
        return ShadowSample::default();
    }
    let radiance = light_select::luminance(light.radiance.truncate());
    let weight = radiance * point.albedo / core::f32::consts::PI * cos_surface / (s.pdf * pmf);
    ShadowSample { direction: s.direction, tmax: s.distance * (1.0 - 1e-4), weight }
}

/// The shadow ray of `strategy` at `point` from light-selection number `u_select` and the 2-D
/// number `u`.
pub fn shadow_sample(
    strategy: Strategy,
    point: &ShadingPoint,
    lights: &[Light],
    u_select: f32,
    u: Vec2,
) -> ShadowSample {
    match strategy {
        Strategy::AoUniform | Strategy::AoCosine => {
            let (local, weight) = if strategy == Strategy::AoUniform {
                let d = warp::sample_uniform_hemisphere(u);
                (d, 2.0 * d.z)
            } else {
                (warp::sample_cosine_hemisphere(u), 1.0)
            };
            if local.z <= 0.0 {
                return ShadowSample::default();
            }
            ShadowSample { direction: warp::local_to_world(point.normal, local), tmax: AO_RADIUS, weight }
        }
        Strategy::SphereLights { cone, importance } => {
            let choice = if importance {
                light_select::select_importance(lights, point.origin, point.normal, u_select)
            } else {
                light_select::select_uniform(lights.len() as u32, u_select)
            };
            let Some(light) = lights.get(choice.index as usize) else {
                return ShadowSample::default();
            };
            let (centre, radius) = (light.position.truncate(), light.position.w);
            let s = if cone {
                warp::sample_sphere_light_cone(point.origin, centre, radius, u)
            } else {
                warp::sample_sphere_light_area(point.origin, centre, radius, u)
            };
            light_contribution(point, light, &s, choice.pmf)
        }
        Strategy::QuadArea => {
            let light = &lights[0];
            let (corner, eu, ev) = (light.position.truncate(), light.edge_u.truncate(), light.edge_v.truncate());
            let s = warp::sample_quad_area(point.origin, corner, eu, ev, u);
            light_contribution(point, light, &s, 1.0)
        }
    }
}

/// The image of `estimator` with `spp` samples per pixel (row-major `resolution²` pixels, 0 where
/// every camera ray misses) for repetition seed `seed`, on `backend` holding `scene`, and how
/// many values went non-finite on the way: those the stages sanitized, and samples whose weight
/// is not finite, which add nothing (a NaN weight had failed `weight > 0`, so its ray came back
/// unblocked and made the pixel NaN).
pub fn estimate_image(
    backend: &mut dyn Backend,
    scene: &Scene,
    estimator: &Estimator,
    spp: u32,
    seed: u32,
    resolution: u32,
) -> Result<(Vec<f32>, u64)> {
    let lights = lights_for(estimator.strategy);
    let sampler_params = crate::frame::sampler_params(estimator.sampler, seed, resolution, resolution, spp);
    let mut image = vec![0.0f32; (resolution * resolution) as usize];
    let mut sanitized = 0;
    for sample_index in 0..spp {
        let params = crate::frame::generate_params_with(scene, resolution, resolution, sample_index, sampler_params);
        let (camera_rays, generated) = backend.generate(&params)?;
        let (points, traced) = scenes::shading_points(scene, backend, &camera_rays)?;
        sanitized += generated.sanitized + traced;
        let samples: Vec<ShadowSample> = points
            .par_iter()
            .map(|point| {
                let pixel = UVec2::new(point.pixel % resolution, point.pixel / resolution);
                let u_select = sampler::sample_1d(&sampler_params, pixel, sample_index, dims::SHADE_LIGHT_SELECT);
                let u = sampler::sample_2d(&sampler_params, pixel, sample_index, dims::SHADE_DIRECTION);
                shadow_sample(estimator.strategy, point, &lights, u_select, u)
            })
            .collect();
        let mut rays = RayStream::zeroed(samples.len());
        for (i, (point, s)) in points.iter().zip(&samples).enumerate() {
            rays.origin[i] = point.origin.extend(0.0);
            // Samples that cannot contribute get an empty interval; their visibility is unused.
            let traced = s.weight.is_finite() && s.weight > 0.0;
            rays.direction[i] = if traced { s.direction.extend(s.tmax) } else { Vec4::new(0.0, 0.0, 1.0, 0.0) };
            rays.pixel[i] = point.pixel;
        }
        let (occluded, occlusion) = backend.trace_occlusion(&rays)?;
        sanitized += occlusion.sanitized;
        for ((point, s), &blocked) in points.iter().zip(&samples).zip(&occluded) {
            if !s.weight.is_finite() {
                sanitized += 1;
            } else if blocked == 0 {
                image[point.pixel as usize] += s.weight / spp as f32;
            }
        }
    }
    Ok((image, sanitized))
}

/// Runs `estimator` for `reps` repetitions (seeds `seed_base + r`) and returns its moments, the
/// repetitions dealt into the jackknife's groups, and the values that went non-finite
/// ([`estimate_image`]).
pub fn moments(
    backend: &mut dyn Backend,
    scene: &Scene,
    estimator: &Estimator,
    spp: u32,
    options: &SamplingReportOptions,
    seed_base: u32,
) -> Result<(GroupedMoments, u64)> {
    let mut moments = GroupedMoments::new((options.resolution * options.resolution) as usize, options.reps);
    let mut sanitized = 0;
    for rep in 0..options.reps {
        let (image, replaced) = estimate_image(backend, scene, estimator, spp, seed_base + rep, options.resolution)?;
        moments.add(rep, &image);
        sanitized += replaced;
    }
    Ok((moments, sanitized))
}

/// One measured case with the better estimator's per-pixel mean (a converged reference for the
/// spectrum: `reps · spp` samples per pixel).
pub struct CaseMeasurement {
    /// The table row.
    pub result: CaseResult,
    /// Per-pixel mean of the better estimator over all repetitions.
    pub reference: Vec<f64>,
    /// Values that went non-finite in either estimator's images ([`estimate_image`]).
    pub sanitized: u64,
}

/// `worse / better`, the variance ratio of case `name` measured on `resolution²` pixels; an
/// error where the better estimator's variance is not positive: the ratio would be infinite (a
/// JSON `null`), or meaningless where the worse variance is 0 too.
fn variance_ratio(name: &str, worse: f64, better: f64, resolution: u32) -> Result<f64> {
    if better.is_nan() || better <= 0.0 {
        let reason = format!(
            "case {name}: the better estimator's variance is {better} at {resolution}² pixels, so no variance \
             ratio can be measured; take a larger resolution"
        );
        return Err(crate::Error::InvalidParameter { name: "resolution", reason });
    }
    Ok(worse / better)
}

/// Measures one case on `backend`, whose loaded scene must be `scene`.
pub fn measure_case(
    backend: &mut dyn Backend,
    scene: &Scene,
    case: &Case,
    options: &SamplingReportOptions,
) -> Result<CaseMeasurement> {
    let (worse_moments, worse_sanitized) = moments(backend, scene, &case.worse, case.spp, options, 0)?;
    let (better_moments, better_sanitized) = moments(backend, scene, &case.better, case.spp, options, 1 << 20)?;
    let (worse_pooled, better_pooled) = (worse_moments.pooled(), better_moments.pooled());
    let (worse, better) = (worse_pooled.mean_variance(), better_pooled.mean_variance());
    let ratio = variance_ratio(case.name, worse, better, options.resolution)?;
    let interval = variance_ratio_interval(&worse_moments, &better_moments);
    let result = CaseResult {
        case: case.name,
        variance_ratio: ratio,
        variance_ratio_low: interval.map(|(low, _)| low),
        variance_ratio_high: interval.map(|(_, high)| high),
        published: case.published,
        reps: options.reps,
        spp: case.spp,
        variance_worse: worse,
        variance_better: better,
        rays_for_equal_error: f64::from(case.spp) * ratio,
        pixels: (options.resolution * options.resolution) as usize,
    };
    Ok(CaseMeasurement {
        result,
        reference: better_pooled.mean().to_vec(),
        sanitized: worse_sanitized + better_sanitized,
    })
}

/// The screen-space error spectrum of one sampler.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SpectrumResult {
    /// Always `error_spectrum`.
    pub case: &'static str,
    /// `zsobol`, `sobol` or `random`.
    pub sampler: &'static str,
    /// Error images averaged.
    pub images: u32,
    /// Mean normalised power of rings 1 ..= max(1, resolution/8), up to about ⅛ cycle per pixel
    /// (white noise ≈ 1, blue noise ≪ 1).
    pub low_frequency_power: f64,
    /// Normalised radially averaged power, ring 0 ..= resolution/2 (cycles per image).
    pub radial_power: Vec<f64>,
}

impl crate::output_line::OutputLine for SpectrumResult {
    fn json(&self) -> String {
        crate::output_line::json_object(self)
    }

    /// The low-frequency power and the spectrum in eight bands of rings 1 ..= resolution/2 (fewer
    /// below 16 rings: one ring each) — ring 0, the mean, is ≈ 0 once the error's mean is removed,
    /// and had pulled the first band low.
    fn row(&self) -> String {
        let rings = self.radial_power.get(1..).unwrap_or_default();
        let bands: Vec<String> = (0..8)
            .map(|b| &rings[b * rings.len() / 8..(b + 1) * rings.len() / 8])
            .filter(|band| !band.is_empty())
            .map(|band| format!("{:.2}", band.iter().sum::<f64>() / band.len() as f64))
            .collect();
        format!(
            "error spectrum {:<7} low-frequency power {:.3}  radial bands low→high [{}]  ({} images)",
            self.sampler,
            self.low_frequency_power,
            bands.join(" "),
            self.images
        )
    }
}

/// Error images averaged per sampler in the spectrum.
pub const SPECTRUM_IMAGES: u32 = 32;

/// The radially averaged power spectrum of the 1-spp error image (estimate − `reference`) of the
/// `case.better` strategy under each sampler kind, over [`SPECTRUM_IMAGES`] seeds, and the values
/// that went non-finite in those images ([`estimate_image`]).
pub fn error_spectra(
    backend: &mut dyn Backend,
    scene: &Scene,
    case: &Case,
    measured: &CaseMeasurement,
    resolution: u32,
) -> Result<(Vec<SpectrumResult>, u64)> {
    let mut results = Vec::new();
    let mut sanitized = 0;
    for kind in 0..sampler_kind::COUNT {
        let estimator = Estimator { sampler: kind, ..case.better };
        let mut spectrum = super::spectrum::PowerSpectrum::new(resolution as usize);
        for seed in 0..SPECTRUM_IMAGES {
            let (estimate, replaced) = estimate_image(backend, scene, &estimator, 1, seed, resolution)?;
            sanitized += replaced;
            let error: Vec<f64> = estimate
                .iter()
                .zip(&measured.reference)
                .map(|(&value, &reference)| f64::from(value) - reference)
                .collect();
            spectrum.add(&error);
        }
        results.push(SpectrumResult {
            case: "error_spectrum",
            sampler: crate::frame::SAMPLER_NAMES[kind as usize],
            images: SPECTRUM_IMAGES,
            low_frequency_power: spectrum.low_frequency_power(),
            radial_power: spectrum.radial_average(),
        });
    }
    Ok((results, sanitized))
}

/// One printed line of the report.
pub enum ReportLine<'a> {
    /// A row of the variance table.
    Case(&'a Case, &'a CaseResult),
    /// An error spectrum.
    Spectrum(&'a SpectrumResult),
}

/// Runs the whole report on `backend` (the Cornell box is loaded into it) and hands each line to
/// `emit` as soon as it is measured.
pub fn report_sampling(
    backend: &mut dyn Backend,
    options: &SamplingReportOptions,
    mut emit: impl FnMut(ReportLine<'_>),
) -> Result<()> {
    validate(options)?;
    let scene = Scene::load("builtin:cornell")?;
    backend.load_scene(&scene)?;
    for case in cases() {
        let measured = measure_case(backend, &scene, &case, options)?;
        super::warn_if_sanitized(&format!("{} ({})", scene.name(), case.name), case.spp, measured.sanitized);
        emit(ReportLine::Case(&case, &measured.result));
        if case.name == "sobol_vs_random" {
            let (spectra, sanitized) = error_spectra(backend, &scene, &case, &measured, options.resolution)?;
            super::warn_if_sanitized(&format!("{} (error spectrum)", scene.name()), 1, sanitized);
            for spectrum in spectra {
                emit(ReportLine::Spectrum(&spectrum));
            }
        }
    }
    Ok(())
}

/// Checks the options.
pub fn validate(options: &SamplingReportOptions) -> Result<()> {
    super::check_reps(options.reps, 2, ": a variance needs two repetitions")?;
    super::check_resolution(options.resolution)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output_line::OutputLine;

    /// White noise at 64² (33 rings, ring 0 the removed mean) prints eight bands of 1: the
    /// bands had been chunks of 5 rings (seven bands), the first reading 0.80 with ring 0 in it.
    #[test]
    fn spectrum_rows_show_eight_bands_without_the_mean() {
        let white = |rings: usize| SpectrumResult {
            case: "error_spectrum",
            sampler: "random",
            images: 1,
            low_frequency_power: 1.0,
            radial_power: std::iter::once(0.0).chain(std::iter::repeat_n(1.0, rings - 1)).collect(),
        };
        for rings in [33, 17, 9, 513] {
            let row = white(rings).row();
            assert!(row.contains("[1.00 1.00 1.00 1.00 1.00 1.00 1.00 1.00]"), "{rings} rings: {row}");
        }
        // At 4² (3 rings), one band per ring beyond the mean's.
        assert!(white(3).row().contains("[1.00 1.00]"), "{}", white(3).row());
    }

    #[test]
    fn a_variance_ratio_needs_a_positive_better_variance() {
        assert_eq!(variance_ratio("case", 3.0, 1.5, 64).unwrap(), 2.0);
        for better in [0.0, f64::NAN] {
            let err = variance_ratio("ao", 4.0, better, 4).unwrap_err().to_string();
            assert!(err.contains("resolution: case ao: the better estimator's variance is"), "{err}");
        }
    }
}
