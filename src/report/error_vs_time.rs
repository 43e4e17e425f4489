//! `raywave report error-vs-time`: the headline result of seed 000 — error (relMSE against a
//! converged reference, and FLIP beside it) against milliseconds for the stochastic estimator and
//! the ratio estimator, each raw and denoised, at 1 … `max_spp` samples per pixel.
//!
//! Methods: `stochastic` (`S_N`), `stochastic+tv` (the TV filter applied to `S_N`, see
//! [`DenoiseInput::stochastic`]), `ratio` (`U · S_N/U_N`), `ratio+tv` (seed 000's TV-guided joint
//! bilateral filter) and `ratio+svgf` (the variance-guided à-trous baseline). As in
//! `report shade`, the visible surfaces are a fixed G-buffer; the reference is the ratio
//! estimate at `reference_spp` samples. The time of a method is what the chosen backend spent
//! on its frame: the G-buffer's camera rays, the shade and occlusion passes, and the passes that
//! make its image from the accumulated estimates — the composite alone for the raw methods
//! ([`DenoiseMethod::None`]), a filter and the composite for the others (GPU timestamps on
//! Vulkan, wall clock on the CPU; not the host's work between them, nor uploads and readbacks)
//! — averaged over the repetitions; with `settle_seconds`, in benchmark mode after a warm-up,
//! the reference image still rendered once per pass ([`PreparedScene::settle`]); without it, after
//! one untimed frame of every method, so that no method is charged a pass's first run
//! ([`PreparedScene::run_every_pass_once`]). The G-buffer's time, added to every frame's, is
//! that of one trace made after the untimed frames.
//!
//! Every method is charged the same shade passes, which evaluate the analytic `U` for every
//! light on every pass although the stochastic methods read only the chosen light's form
//! factors (its sampling probabilities) and, for `stochastic+tv`'s edge stops, `U`'s luminance;
//! on a scene of one or two lights that is most of the work, on the 20-light grid it is not. The time axis compares
//! the estimators at equal work, not what leaving `U` out would save a purely stochastic
//! renderer. The stochastic methods go through the composite with `U = U_N` = the mean of `S_N`
//! ([`DenoiseInput::stochastic`]), so a pixel above 10⁴ times that mean is clipped there, and
//! `stochastic+tv`'s edge stops keep the luminance of `U` as a guide. Each relMSE is split into
//! the parts made in shadowed and in unshadowed pixels ([`ShadowRegions`]), which shows where a
//! method's error is.

use super::flip::mean_flip;
use super::shade::{accumulate, GBuffer, ShadowRegions};
use super::{sum_from_zero, Repeated};
use crate::bench::{check_settle_seconds, warm_up, SUSTAIN_SECONDS};
use crate::denoise::{check_radius, frame_params, rgb, DenoiseInput, DenoiseMethod};
use crate::shading::ShadeData;
use crate::shared::DenoiseParams;
use crate::visualize::PendingOutput;
use crate::{Backend, Result, Scene};
use glam::Vec3;

/// The methods compared, in plot order.
pub const METHODS: [&str; 5] = ["stochastic", "stochastic+tv", "ratio", "ratio+tv", "ratio+svgf"];

/// The ε of relMSE's denominator, 0.01 (Gharbi et al. 2019, sbmc `RelativeMSE`).
pub const RELMSE_EPSILON: f64 = 0.01;

/// What to measure.
#[derive(Clone, Debug)]
pub struct ErrorVsTimeOptions {
    /// Scenes, image side, sample counts and repetitions.
    pub report: super::SceneReportOptions,
    /// The filters' radius R in pixels (`1..=MAX_RADIUS`; the TV filter's widest Gaussian, SVGF's
    /// footprint); `None` follows the image size ([`DenoiseParams::default_radius`]: 2 at 128²).
    pub denoise_radius: Option<u32>,
    /// Steady-state milliseconds: measure in benchmark mode after 1-spp frames have run untimed
    /// until their times have not fallen for this many seconds (`0..=30`), per scene
    /// ([`PreparedScene::settle`]); `None`: each stage of a frame runs once, as a GPU may run it
    /// at idle clocks (README, "On an NVIDIA H100": ~5× slower), after one untimed frame of every
    /// method ([`PreparedScene::run_every_pass_once`]). Errors are the same either way.
    pub settle_seconds: Option<f64>,
}

impl ErrorVsTimeOptions {
    /// Checks the options before any measurement ([`super::SceneReportOptions::check`], the
    /// radius and the settling time).
    pub fn check(&self) -> Result<()> {
        self.report.check()?;
        check_radius("denoise-radius", self.denoise_radius)?;
        self.settle_seconds.map(check_settle_seconds).transpose()?;
        Ok(())
    }

    /// The radius the filters run with.
    pub fn radius(&self) -> u32 {
        let side = self.report.resolution;
        frame_params(side, side, self.denoise_radius).radius
    }
}

/// One measurement, printed as one JSON line.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ErrorVsTimeLine {
    /// Scene name.
    pub scene: String,
    /// Samples per pixel.
    pub spp: u32,
    /// One of [`METHODS`].
    pub method: &'static str,
    /// Relative MSE against the reference ([`relmse`]), mean over the repetitions.
    pub relmse: f64,
    /// The standard error of `relmse` over the repetitions ([`super::Repeated::standard_error`]:
    /// ±t times it is a 95 % confidence interval, t = 3.18 for 4 repetitions, 1.96 for many);
    /// absent for one repetition.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub relmse_stderr: Option<f64>,
    /// The part of `relmse` made in shadowed pixels (penumbrae and umbrae, [`ShadowRegions`]).
    pub relmse_shadow: f64,
    /// The part of `relmse` made in unshadowed pixels; with `relmse_shadow` and the part in
    /// pixels without direct light it adds up to `relmse`.
    pub relmse_lit: f64,
    /// Mean FLIP against the reference ([`mean_flip`]), mean over the repetitions.
    pub flip: f64,
    /// Milliseconds of backend time for the frame, mean over the repetitions.
    pub ms: f64,
    /// The backend that measured `ms` ([`Backend::name`]): under `--device auto`, the one chosen.
    pub backend: String,
    /// Seconds of the scene's warm-up before steady-state measurements
    /// ([`ErrorVsTimeOptions::settle_seconds`]); absent where each stage ran once.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub warm_up_seconds: Option<f64>,
}

impl crate::output_line::OutputLine for ErrorVsTimeLine {
    fn json(&self) -> String {
        crate::output_line::json_object(self)
    }

    fn row(&self) -> String {
        let stderr = self.relmse_stderr.map_or(String::new(), |e| format!(" ± {e:.6}"));
        format!(
            "{:<28} {:>3} spp  {:<14} relMSE {:.6}{stderr} (shadow {:.6}, lit {:.6})  FLIP {:.4}  {:>9.2} ms",
            self.scene, self.spp, self.method, self.relmse, self.relmse_shadow, self.relmse_lit, self.flip, self.ms
        )
    }
}

/// Relative MSE, `½·mean((x − y)² / (y² + ε))` over pixels and RGB channels, ε =
/// [`RELMSE_EPSILON`] (Gharbi et al. 2019; `../shared/reference/sampling-denoise.md` §3.4).
/// Panics if the images differ in length (the mean would be over the wrong count).
pub fn relmse(image: &[Vec3], reference: &[Vec3]) -> f64 {
    relmse_over(image, reference, 0..reference.len())
}

/// The part of [`relmse`] made in `pixels`: their terms over the whole image's count, so the
/// parts of disjoint sets of pixels add up to the image's relMSE. Panics if the images differ in
/// length or an index is out of range.
pub fn relmse_part(image: &[Vec3], reference: &[Vec3], pixels: &[usize]) -> f64 {
    relmse_over(image, reference, pixels.iter().copied())
}

/// The terms of [`relmse`] at `pixels`, over the whole image's count.
fn relmse_over(image: &[Vec3], reference: &[Vec3], pixels: impl Iterator<Item = usize>) -> f64 {
    assert_eq!(image.len(), reference.len(), "relMSE: image and reference differ in size");
    let sum = sum_from_zero(pixels.map(|i| relative_squared_error(image[i], reference[i])));
    0.5 * sum / (3 * reference.len().max(1)) as f64
}

/// One pixel's term of [`relmse`]: `Σ_rgb (x − y)² / (y² + ε)`, in f64.
fn relative_squared_error(x: Vec3, y: Vec3) -> f64 {
    let (x, y) = (x.as_dvec3(), y.as_dvec3());
    let d = x - y;
    (d * d / (y * y + RELMSE_EPSILON)).element_sum()
}

/// A scene prepared for the measurements: its shade data, fixed G-buffer, surfaces and the
/// converged reference image.
pub struct PreparedScene {
    /// The shade stage's scene data.
    pub data: ShadeData,
    /// The camera rays' hits.
    pub gbuffer: GBuffer,
    /// The surface per pixel (the denoiser's G-buffer).
    pub surfaces: Vec<crate::kernels::shade::stage::Surface>,
    /// The analytic unshadowed radiance `U` per pixel (the same in every frame: the surfaces
    /// are fixed), which tells shadowed pixels from unshadowed ones in the reference.
    pub analytic: Vec<Vec3>,
    /// The radiance the surfaces emit per pixel (fixed too), which the reference includes.
    pub emitted: Vec<Vec3>,
    /// Image side in pixels.
    pub resolution: u32,
    /// The filters' radius R in pixels: [`DenoiseParams::default_radius`] for the image side
    /// unless set.
    pub denoise_radius: u32,
}

/// One frame of every method ([`PreparedScene::frame`]).
pub struct MethodFrames {
    /// Each method's image and its milliseconds, in [`METHODS`] order.
    pub images: Vec<(Vec<Vec3>, f64)>,
    /// Values the frame's stages sanitized — the shade passes, the denoisers' composites
    /// ([`crate::StageReport::sanitized`]); 0 on sound input. The G-buffer's, which every frame
    /// shares, are [`GBuffer::sanitized`].
    pub sanitized: u64,
}

impl PreparedScene {
    /// Loads `scene` into `backend`, traces its G-buffer and shades it once for the analytic and
    /// emitted radiance.
    pub fn new(backend: &mut dyn Backend, scene: &Scene, resolution: u32) -> Result<Self> {
        backend.load_scene(scene)?;
        let data = ShadeData::new(scene)?;
        let gbuffer = GBuffer::new(backend, scene, resolution)?;
        let surfaces = gbuffer.surfaces(&data);
        let (once, _) = accumulate(backend, &gbuffer, &data, resolution, 1, 0)?;
        let (analytic, emitted) = (once.analytic(), once.emitted());
        let denoise_radius = DenoiseParams::default_radius(resolution, resolution);
        Ok(Self { data, gbuffer, surfaces, analytic, emitted, resolution, denoise_radius })
    }

    /// The pixels of `reference` split by how much of their direct light reaches them
    /// ([`ShadowRegions`]).
    pub fn shadow_regions(&self, reference: &[Vec3]) -> ShadowRegions {
        ShadowRegions::new(&self.analytic, &self.emitted, reference)
    }

    /// The converged image: the ratio estimate at `spp` samples per pixel (seed
    /// [`super::REFERENCE_SEED`], apart from every measured run's), and the values the
    /// G-buffer's trace and its stages sanitized or its composite replaced.
    pub fn reference(&self, backend: &mut dyn Backend, spp: u32) -> Result<(Vec<Vec3>, u64)> {
        let (run, _) = accumulate(backend, &self.gbuffer, &self.data, self.resolution, spp, super::REFERENCE_SEED)?;
        let (image, replaced) = run.ratio_image();
        Ok((image, self.gbuffer.sanitized + run.sanitized() + replaced))
    }

    /// Renders one 1-spp frame of every method untimed, then traces the G-buffer again — the
    /// same rays and hits — so that no method's time includes a pass's first run on the backend
    /// (lavapipe compiles a pipeline at its first dispatch; the reference, composited on the
    /// host, runs neither the composite nor the filters): each stage of a measured frame still
    /// runs once, as a GPU may run it at idle clocks, but none runs for the first time.
    pub fn run_every_pass_once(&mut self, backend: &mut dyn Backend, scene: &Scene) -> Result<()> {
        self.frame(backend, 1, 0)?;
        self.gbuffer = GBuffer::new(backend, scene, self.resolution)?;
        Ok(())
    }

    /// Switches `backend` to benchmark mode (50 ms of back-to-back dispatches per timed
    /// submission) and renders 1-spp frames untimed until their times have not fallen for
    /// `settle_seconds`, then traces the G-buffer again — the same rays and hits — so that
    /// its time, part of every method's, is a steady-state one too. Returns the warm-up's
    /// seconds. Turn benchmark mode off again (`set_sustain_seconds(0.0)`) before work that
    /// should run once, such as a reference of thousands of passes.
    pub fn settle(&mut self, backend: &mut dyn Backend, scene: &Scene, settle_seconds: f64) -> Result<f64> {
        backend.set_sustain_seconds(SUSTAIN_SECONDS)?;
        let frame_seconds = |frame: MethodFrames| 1e-3 * frame.images.iter().map(|(_, ms)| ms).sum::<f64>();
        let warm_up_seconds = warm_up(settle_seconds, || Ok(frame_seconds(self.frame(backend, 1, 0)?)))?;
        self.gbuffer = GBuffer::new(backend, scene, self.resolution)?;
        Ok(warm_up_seconds)
    }

    /// One frame at `spp` samples with sampler seed `seed`: every method's image and its
    /// milliseconds, in [`METHODS`] order, and what its stages sanitized.
    pub fn frame(&self, backend: &mut dyn Backend, spp: u32, seed: u32) -> Result<MethodFrames> {
        let (run, shade_seconds) = accumulate(backend, &self.gbuffer, &self.data, self.resolution, spp, seed)?;
        let mut sanitized = run.sanitized();
        let base_ms = 1e3 * (self.gbuffer.seconds + shade_seconds);
        let input = DenoiseInput::new(&self.surfaces, &run);
        let params = DenoiseParams {
            seed,
            samples_per_pixel: run.samples(),
            ..DenoiseParams::with_radius(self.resolution, self.resolution, self.denoise_radius)
        };
        let mut denoised = |method, input: &DenoiseInput| -> Result<(Vec<Vec3>, f64)> {
            let (color, timings) = backend.denoise(method, &params, input)?;
            sanitized += crate::StageReport::total_sanitized(&timings);
            Ok((rgb(&color), base_ms + 1e3 * timings.iter().map(|t| t.seconds).sum::<f64>()))
        };
        let stochastic = input.stochastic();
        let images = vec![
            denoised(DenoiseMethod::None, &stochastic)?,
            denoised(DenoiseMethod::Tv, &stochastic)?,
            denoised(DenoiseMethod::None, &input)?,
            denoised(DenoiseMethod::Tv, &input)?,
            denoised(DenoiseMethod::Svgf, &input)?,
        ];
        Ok(MethodFrames { images, sanitized })
    }

    /// Every method's error against `reference` and time at `spp` samples, in [`METHODS`]
    /// order: the means over one [`frame`](Self::frame) per seed of `seeds` (at least one); and
    /// the values the G-buffer's trace and those frames' stages sanitized
    /// ([`MethodFrames::sanitized`], summed; the G-buffer's once, as every frame shares it).
    pub fn errors(
        &self,
        backend: &mut dyn Backend,
        reference: &[Vec3],
        spp: u32,
        seeds: &[u32],
    ) -> Result<([MethodError; METHODS.len()], u64)> {
        if seeds.is_empty() {
            let reason = "no seeds: a mean needs at least one frame".to_owned();
            return Err(crate::Error::InvalidParameter { name: "reps", reason });
        }
        let regions = self.shadow_regions(reference);
        let mut runs = [MethodRuns::default(); METHODS.len()];
        let mut sanitized = self.gbuffer.sanitized;
        for &seed in seeds {
            let frame = self.frame(backend, spp, seed)?;
            sanitized += frame.sanitized;
            for (runs, (image, ms)) in runs.iter_mut().zip(frame.images) {
                runs.relmse.add(relmse(&image, reference));
                runs.relmse_shadow.add(relmse_part(&image, reference, &regions.shadow));
                runs.relmse_lit.add(relmse_part(&image, reference, &regions.lit));
                runs.flip.add(mean_flip(&image, reference, self.resolution, self.resolution));
                runs.ms.add(ms);
            }
        }
        let errors = runs.map(|runs| MethodError {
            relmse: runs.relmse.mean(),
            relmse_stderr: runs.relmse.standard_error(),
            relmse_shadow: runs.relmse_shadow.mean(),
            relmse_lit: runs.relmse_lit.mean(),
            flip: runs.flip.mean(),
            ms: runs.ms.mean(),
        });
        Ok((errors, sanitized))
    }
}

/// One method's measurements over the frames of [`PreparedScene::errors`], each quantity's mean
/// (and `relmse`'s standard error) taken at the end.
#[derive(Copy, Clone, Default)]
struct MethodRuns {
    relmse: Repeated,
    relmse_shadow: Repeated,
    relmse_lit: Repeated,
    flip: Repeated,
    ms: Repeated,
}

/// One method's error and time, averaged over frames (see [`PreparedScene::errors`]).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct MethodError {
    /// Relative MSE against the reference ([`relmse`]).
    pub relmse: f64,
    /// The standard error of `relmse` over the frames ([`Repeated::standard_error`]); `None`
    /// for one frame.
    pub relmse_stderr: Option<f64>,
    /// The part of `relmse` made in shadowed pixels ([`relmse_part`], [`ShadowRegions`]).
    pub relmse_shadow: f64,
    /// The part of `relmse` made in unshadowed pixels.
    pub relmse_lit: f64,
    /// Mean FLIP against the reference ([`mean_flip`]).
    pub flip: f64,
    /// Milliseconds of backend time for the frame.
    pub ms: f64,
}

/// Runs the report, handing each line to `emit` as soon as it is measured; returns every line.
pub fn report_error_vs_time(
    backend: &mut dyn Backend,
    options: &ErrorVsTimeOptions,
    mut emit: impl FnMut(&ErrorVsTimeLine),
) -> Result<Vec<ErrorVsTimeLine>> {
    options.check()?;
    let report = &options.report;
    let mut lines = Vec::new();
    let backend_name = backend.name();
    for (name, scene) in report.scenes.iter().zip(report.load_scenes()?) {
        let mut prepared = PreparedScene {
            denoise_radius: options.radius(),
            ..PreparedScene::new(backend, &scene, report.resolution)?
        };
        let (reference, sanitized) = prepared.reference(backend, report.reference_spp)?;
        super::warn_if_sanitized(name, report.reference_spp, sanitized);
        let warm_up_seconds = match options.settle_seconds {
            Some(settle) => Some(prepared.settle(backend, &scene, settle)?),
            None => {
                prepared.run_every_pass_once(backend, &scene)?;
                None
            }
        };
        let seeds: Vec<u32> = (0..report.reps).collect();
        for spp in report.spp_steps() {
            let (errors, sanitized) = prepared.errors(backend, &reference, spp, &seeds)?;
            super::warn_if_sanitized(name, spp, sanitized);
            for (method, error) in METHODS.into_iter().zip(errors) {
                let MethodError { relmse, relmse_stderr, relmse_shadow, relmse_lit, flip, ms } = error;
                let scene = name.clone();
                let line = ErrorVsTimeLine {
                    scene,
                    spp,
                    method,
                    relmse,
                    relmse_stderr,
                    relmse_shadow,
                    relmse_lit,
                    flip,
                    ms,
                    backend: backend_name.clone(),
                    warm_up_seconds,
                };
                emit(&line);
                lines.push(line);
            }
        }
        if warm_up_seconds.is_some() {
            // The next scene's reference runs once per pass again.
            backend.set_sustain_seconds(0.0)?;
        }
    }
    Ok(lines)
}

/// Milliseconds `method` needs on `scene` to reach relMSE `error` along its measured curve
/// (points in `lines` order, 1 … max spp): the first point at or below `error`, interpolated
/// linearly in log–log from the point before it; `None` if no point gets there.
pub fn time_to_reach(lines: &[ErrorVsTimeLine], scene: &str, method: &str, error: f64) -> Option<f64> {
    let curve = lines.iter().filter(|l| l.scene == scene && l.method == method);
    let mut previous: Option<&ErrorVsTimeLine> = None;
    for point in curve {
        if point.relmse <= error {
            return Some(match previous {
                Some(above)
                    if point.relmse < error
                        && above.relmse > 0.0
                        && point.relmse > 0.0
                        && above.ms > 0.0
                        && point.ms > 0.0 =>
                {
                    let along = (error.ln() - above.relmse.ln()) / (point.relmse.ln() - above.relmse.ln());
                    (above.ms.ln() + along * (point.ms.ln() - above.ms.ln())).exp()
                }
                _ => point.ms,
            });
        }
        previous = Some(point);
    }
    None
}

/// The fastest method to one error level on one scene.
#[derive(Clone, Debug, PartialEq)]
pub struct FastestLine {
    /// Scene name.
    pub scene: String,
    /// The relMSE to reach.
    pub relmse: f64,
    /// The method that gets there first, and its milliseconds ([`time_to_reach`]).
    pub fastest: (&'static str, f64),
    /// The next fastest method and its milliseconds, if another one gets there.
    pub runner_up: Option<(&'static str, f64)>,
}

impl FastestLine {
    /// A table row.
    pub fn row(&self) -> String {
        let runner_up = match self.runner_up {
            Some((method, ms)) => format!("  (next: {method} {ms:.1} ms)"),
            None => "  (no other method gets there)".to_owned(),
        };
        format!(
            "{:<28} relMSE ≤ {:.1e}  fastest {:<14} {:>9.1} ms{runner_up}",
            self.scene, self.relmse, self.fastest.0, self.fastest.1
        )
    }
}

/// The error levels of [`fastest_by_error`] within a decade, descending: four per decade, as
/// 10^(k/4) rounded to two digits.
const LEVELS_PER_DECADE: [f64; 4] = [5.6, 3.2, 1.8, 1.0];

/// The scenes of `lines`, in report order.
fn scenes(lines: &[ErrorVsTimeLine]) -> Vec<&str> {
    let mut scenes: Vec<&str> = lines.iter().map(|l| l.scene.as_str()).collect();
    scenes.dedup();
    scenes
}

/// For each scene in `lines`, the fastest method at error levels four per decade (1, 1.8, 3.2,
/// 5.6 × 10ᵏ) from the worst first point of any curve down to the best error any method reaches
/// — the plot's headline read off as a table.
pub fn fastest_by_error(lines: &[ErrorVsTimeLine]) -> Vec<FastestLine> {
    let mut table = Vec::new();
    for scene in scenes(lines) {
        let ours = || lines.iter().filter(move |l| l.scene == scene && l.relmse > 0.0);
        let worst = ours().filter(|l| l.spp == 1).map(|l| l.relmse).fold(f64::MIN, f64::max);
        let best = ours().map(|l| l.relmse).fold(f64::MAX, f64::min);
        if !(worst.is_finite() && best.is_finite() && best <= worst) {
            continue;
        }
        let decades = (best.log10().floor() as i32..=worst.log10().floor() as i32).rev();
        let levels = decades.flat_map(|k| LEVELS_PER_DECADE.map(|m| m * 10f64.powi(k)));
        for relmse in levels.filter(|&e| e <= worst * (1.0 + 1e-9) && e >= best * (1.0 - 1e-9)) {
            let mut times: Vec<(&'static str, f64)> =
                METHODS.iter().filter_map(|&m| time_to_reach(lines, scene, m, relmse).map(|ms| (m, ms))).collect();
            times.sort_by(|a, b| a.1.total_cmp(&b.1));
            if let Some(&fastest) = times.first() {
                table.push(FastestLine { scene: scene.to_owned(), relmse, fastest, runner_up: times.get(1).copied() });
            }
        }
    }
    table
}

/// The font of the plot's text: DejaVu Sans Mono (Bitstream Vera licence,
/// `assets/fonts/LICENSE-DejaVu.txt`), embedded so plotting needs no system font library.
const FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSansMono.ttf");

/// Draws `lines` as a PNG into `output`: one log–log panel (milliseconds → relMSE) per scene,
/// one curve per method through its 1 … max spp points. The file appears only when complete.
pub fn plot(lines: &[ErrorVsTimeLine], title: &str, output: PendingOutput) -> Result<()> {
    use plotters::prelude::*;
    let plot_error = |e: &dyn std::fmt::Display| crate::Error::InvalidParameter { name: "plot", reason: e.to_string() };
    // Registering twice (a second plot in one process) replaces the same font.
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT).map_err(|_| plot_error(&"bad font"))?;
    let scenes = scenes(lines);
    let (width, panel_height) = (960u32, 560u32);
    let height = panel_height * scenes.len().max(1) as u32;
    let mut pixels = vec![255u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area();
        let panels = root.split_evenly((scenes.len().max(1), 1));
        let colors = [
            RGBColor(150, 150, 150),
            RGBColor(80, 80, 200),
            RGBColor(230, 150, 30),
            RGBColor(200, 30, 30),
            RGBColor(30, 150, 60),
        ];
        for (panel, scene) in panels.iter().zip(&scenes) {
            let ours: Vec<&ErrorVsTimeLine> = lines.iter().filter(|l| l.scene == *scene).collect();
            let (ms, err): (Vec<f64>, Vec<f64>) = ours.iter().map(|l| (l.ms, l.relmse.max(1e-9))).unzip();
            let range = |v: &[f64]| {
                let (lo, hi) = v.iter().fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
                (lo / 1.5)..(hi * 1.5)
            };
            let time_range = range(&ms);
            let time_ticks = log_ticks(&time_range, &[1.0, 2.0, 5.0]);
            let mut chart = ChartBuilder::on(panel)
                .caption(format!("{scene} — {title}"), ("sans-serif", 20))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(time_range.log_scale().with_key_points(time_ticks), range(&err).log_scale())
                .map_err(|e| plot_error(&e))?;
            chart
                .configure_mesh()
                // "1000", not plotters' "1000.0", which the panel's edge cut.
                .x_label_formatter(&|ms| format!("{ms}"))
                .x_desc("time per frame (ms)")
                .y_desc("relMSE")
                .label_style(("sans-serif", 14))
                .draw()
                .map_err(|e| plot_error(&e))?;
            for (method, color) in METHODS.iter().zip(colors) {
                let points: Vec<(f64, f64)> =
                    ours.iter().filter(|l| l.method == *method).map(|l| (l.ms, l.relmse.max(1e-9))).collect();
                chart
                    .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))
                    .map_err(|e| plot_error(&e))?
                    .label(*method)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2)));
                chart
                    .draw_series(points.into_iter().map(|p| Circle::new(p, 3, color.filled())))
                    .map_err(|e| plot_error(&e))?;
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 14))
                .draw()
                .map_err(|e| plot_error(&e))?;
        }
        root.present().map_err(|e| plot_error(&e))?;
    }
    let image = image::RgbImage::from_raw(width, height, pixels).ok_or_else(|| plot_error(&"plot buffer size"))?;
    output.finish_image(&image)
}

/// The ticks of a log axis over `range`: each of `leading` (digits in 1..10) times each power of
/// ten, within the range. The time axis takes 1, 2 and 5: plotters' own ticks put a label at
/// every integer from 60 to 100 ms, which ran together.
fn log_ticks(range: &std::ops::Range<f64>, leading: &[f64]) -> Vec<f64> {
    let (first, last) = (range.start.log10().floor() as i32, range.end.log10().ceil() as i32);
    (first..=last)
        .flat_map(|decade| leading.iter().map(move |digit| digit * 10f64.powi(decade)))
        .filter(|tick| range.contains(tick))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_time_axis_ticks_at_one_two_five_steps() {
        assert_eq!(log_ticks(&(9.0..120.0), &[1.0, 2.0, 5.0]), [10.0, 20.0, 50.0, 100.0]);
        assert_eq!(log_ticks(&(0.15..0.6), &[1.0, 2.0, 5.0]), [0.2, 0.5]);
    }

    fn line(method: &'static str, spp: u32, relmse: f64, ms: f64) -> ErrorVsTimeLine {
        ErrorVsTimeLine {
            scene: "s".to_owned(),
            spp,
            method,
            relmse,
            relmse_stderr: None,
            relmse_shadow: 0.0,
            relmse_lit: 0.0,
            flip: 0.0,
            ms,
            backend: "cpu".to_owned(),
            warm_up_seconds: None,
        }
    }

    #[test]
    fn the_parts_of_relmse_add_up_over_a_partition_of_the_pixels() {
        let reference = [Vec3::ZERO, Vec3::ONE, Vec3::splat(0.5), Vec3::new(2.0, 0.0, 1.0)];
        let image = [Vec3::splat(0.1), Vec3::splat(1.5), Vec3::splat(0.5), Vec3::ZERO];
        let whole = relmse(&image, &reference);
        let parts = [relmse_part(&image, &reference, &[0, 3]), relmse_part(&image, &reference, &[1, 2])];
        assert!(whole > 0.0 && (parts[0] + parts[1] - whole).abs() < 1e-15 * whole, "{parts:?} vs {whole}");
        // Pixel 0 alone: ½ · 3 · 0.1² / (0 + ε) over 3 channels × 4 pixels (0.1 as f32: 3·10⁻⁸ relative).
        let pixel_0 = relmse_part(&image, &reference, &[0]);
        assert!((pixel_0 - 0.5 * 3.0 / 12.0).abs() < 1e-6, "{pixel_0}");
        assert_eq!(relmse_part(&image, &reference, &[2]), 0.0, "an exact pixel adds nothing");
    }

    #[test]
    fn time_to_reach_interpolates_in_log_log_and_gives_up_below_the_curve() {
        let lines = [line("ratio", 1, 1e-2, 10.0), line("ratio", 2, 1e-4, 1000.0)];
        let at = |e| time_to_reach(&lines, "s", "ratio", e);
        assert_eq!(at(1e-1), Some(10.0), "the first point is already below");
        assert!((at(1e-3).unwrap() - 100.0).abs() < 1e-9, "halfway in log–log");
        assert_eq!(at(1e-4), Some(1000.0), "exactly on a point");
        assert_eq!(at(1e-5), None);
        assert_eq!(time_to_reach(&lines, "other", "ratio", 1.0), None);
    }

    #[test]
    fn the_fastest_method_is_read_off_every_error_level() {
        let lines = [
            line("ratio", 1, 1e-2, 10.0),
            line("ratio+tv", 1, 1e-3, 12.0),
            line("ratio", 2, 1e-4, 100.0),
            line("ratio+tv", 2, 1e-4, 200.0),
        ];
        let table = fastest_by_error(&lines);
        let levels: Vec<f64> = table.iter().map(|l| l.relmse).collect();
        assert_eq!(levels.first(), Some(&1e-2));
        assert_eq!(levels.last(), Some(&1e-4));
        assert_eq!(levels.len(), 9, "four levels per decade, both ends included: {levels:?}");
        assert_eq!(table[0].fastest.0, "ratio", "1e-2: ratio's first frame is cheaper");
        let at_1e3 = table.iter().find(|l| (l.relmse - 1e-3).abs() < 1e-12).unwrap();
        assert_eq!(at_1e3.fastest, ("ratio+tv", 12.0));
        assert_eq!(at_1e3.runner_up.unwrap().0, "ratio");
        let last = table.last().unwrap().fastest;
        assert!(last.0 == "ratio" && (last.1 - 100.0).abs() < 1e-9, "{last:?}");
        assert!(table.iter().all(|l| l.scene == "s") && table.iter().all(|l| l.row().contains("fastest")));
    }
}
