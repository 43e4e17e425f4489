//! `raywave report error-vs-time`: the headline result of seed 000 — error (relMSE against a
//! converged reference) against milliseconds for the stochastic estimator and the ratio
//! estimator, each raw and denoised, at 1 … `max_spp` samples per pixel.
//!
//! Methods: `stochastic` (`S_N`), `stochastic+tv` (the TV filter applied to `S_N`, see
//! [`DenoiseInput::stochastic`]), `ratio` (`U · S_N/U_N`), `ratio+tv` (seed 000's TV-guided joint
//! bilateral filter) and `ratio+svgf` (the variance-guided à-trous baseline). As in
//! `report shade`, the visible surfaces are a fixed G-buffer; the reference is the ratio
//! estimate at `reference_spp` samples. The time of a method is what the chosen backend spent
//! on its frame: the G-buffer's camera rays, the shade and occlusion passes, and the denoiser's
//! passes (GPU timestamps on Vulkan, wall clock on the CPU), averaged over the repetitions.

use super::shade::{accumulate, GBuffer};
use crate::denoise::{rgb, DenoiseInput, DenoiseMethod};
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
pub type ErrorVsTimeOptions = super::SceneReportOptions;

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
    /// Milliseconds of backend time for the frame, mean over the repetitions.
    pub ms: f64,
}

impl ErrorVsTimeLine {
    /// The JSON line.
    pub fn json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }

    /// A table row.
    pub fn row(&self) -> String {
        format!(
            "{:<28} {:>3} spp  {:<14} relMSE {:.6}  {:>9.2} ms",
            self.scene, self.spp, self.method, self.relmse, self.ms
        )
    }
}

/// Relative MSE, `½·mean((x − y)² / (y² + ε))` over pixels and RGB channels, ε =
/// [`RELMSE_EPSILON`] (Gharbi et al. 2019; `../shared/reference/sampling-denoise.md` §3.4).
pub fn relmse(image: &[Vec3], reference: &[Vec3]) -> f64 {
    let sum: f64 = image
        .iter()
        .zip(reference)
        .map(|(x, y)| {
            let (x, y) = (x.as_dvec3(), y.as_dvec3());
            let d = x - y;
            (d * d / (y * y + RELMSE_EPSILON)).element_sum()
        })
        .sum();
    0.5 * sum / (3 * reference.len().max(1)) as f64
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
    /// Image side in pixels.
    pub resolution: u32,
}

impl PreparedScene {
    /// Loads `scene` into `backend` and traces its G-buffer.
    pub fn new(backend: &mut dyn Backend, scene: &Scene, resolution: u32) -> Result<Self> {
        backend.load_scene(scene)?;
        let data = ShadeData::new(scene)?;
        let gbuffer = GBuffer::new(backend, scene, resolution)?;
        let surfaces = gbuffer.surfaces(&data);
        Ok(Self { data, gbuffer, surfaces, resolution })
    }

    /// The converged image: the ratio estimate at `spp` samples per pixel (seed fixed apart from
    /// every measured run's).
    pub fn reference(&self, backend: &mut dyn Backend, spp: u32) -> Result<Vec<Vec3>> {
        Ok(accumulate(backend, &self.gbuffer, &self.data, self.resolution, spp, 0xfeed)?.0.ratio_image())
    }

    /// One frame at `spp` samples with sampler seed `seed`: every method's image and its
    /// milliseconds, in [`METHODS`] order.
    pub fn frame(&self, backend: &mut dyn Backend, spp: u32, seed: u32) -> Result<Vec<(Vec<Vec3>, f64)>> {
        let (run, shade_seconds) = accumulate(backend, &self.gbuffer, &self.data, self.resolution, spp, seed)?;
        let base_ms = 1e3 * (self.gbuffer.seconds + shade_seconds);
        let input = DenoiseInput::new(&self.surfaces, &run);
        let params = DenoiseParams { seed, ..DenoiseParams::new(self.resolution, self.resolution) };
        let mut denoised = |method, input: &DenoiseInput| -> Result<(Vec<Vec3>, f64)> {
            let (color, timings) = backend.denoise(method, &params, input)?;
            Ok((rgb(&color), base_ms + 1e3 * timings.iter().map(|t| t.seconds).sum::<f64>()))
        };
        let stochastic_tv = denoised(DenoiseMethod::Tv, &input.stochastic())?;
        let ratio_tv = denoised(DenoiseMethod::Tv, &input)?;
        let ratio_svgf = denoised(DenoiseMethod::Svgf, &input)?;
        Ok(vec![(run.stochastic_image(), base_ms), stochastic_tv, (run.ratio_image(), base_ms), ratio_tv, ratio_svgf])
    }
}

/// Runs the report, handing each line to `emit` as soon as it is measured; returns every line.
pub fn report_error_vs_time(
    backend: &mut dyn Backend,
    options: &ErrorVsTimeOptions,
    mut emit: impl FnMut(&ErrorVsTimeLine),
) -> Result<Vec<ErrorVsTimeLine>> {
    options.check("report error-vs-time")?;
    let mut lines = Vec::new();
    for name in &options.scenes {
        let scene = Scene::load(name)?;
        let prepared = PreparedScene::new(backend, &scene, options.resolution)?;
        let reference = prepared.reference(backend, options.reference_spp)?;
        for spp in options.spp_steps() {
            let mut sums = [(0.0, 0.0); METHODS.len()];
            for rep in 0..options.reps {
                for (sum, (image, ms)) in sums.iter_mut().zip(prepared.frame(backend, spp, rep)?) {
                    sum.0 += relmse(&image, &reference);
                    sum.1 += ms;
                }
            }
            for (method, (relmse, ms)) in METHODS.into_iter().zip(sums) {
                let reps = f64::from(options.reps);
                let line = ErrorVsTimeLine { scene: name.clone(), spp, method, relmse: relmse / reps, ms: ms / reps };
                emit(&line);
                lines.push(line);
            }
        }
    }
    Ok(lines)
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
    let mut scenes: Vec<&str> = lines.iter().map(|l| l.scene.as_str()).collect();
    scenes.dedup();
    let (width, panel_height) = (960u32, 560u32);
    let height = panel_height * scenes.len().max(1) as u32;
    let mut pixels = vec![255u8; (width * height * 3) as usize];
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
            let mut chart = ChartBuilder::on(panel)
                .caption(format!("{scene} — {title}"), ("sans-serif", 20))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(range(&ms).log_scale(), range(&err).log_scale())
                .map_err(|e| plot_error(&e))?;
            chart
                .configure_mesh()
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
    output.finish_png(&image)
}
