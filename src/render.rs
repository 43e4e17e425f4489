//! The `raywave render` job: scene → per sample (generate → trace → shade → occlusion trace), all
//! on the chosen backend → TV-denoise of `S_N`, `U_N` and the ratio estimator's composite
//! `U · den(S_N)/den(U_N)` (or another denoiser, or none) → image files.

use crate::bench::{check_settle_seconds, warm_up, SUSTAIN_SECONDS};
use crate::{
    close_backend, open_backend_telling_fallback, Backend, BackendOptions, DeviceChoice, Result, Scene, StageReport,
};
use glam::Vec3;
use image::{ImageFormat, RgbImage};
use raywave_host::denoise::DenoiseMethod;
use raywave_host::lit_frame::{denoise_samples, shade_samples, LitFrameSettings};
use raywave_host::scene::Unrendered;
use raywave_host::shading::{ShadeAccumulator, ShadeData};
use raywave_host::visualize::{normal_depth_image, output_destination, persist_all, srgb_image, PendingOutput};
use std::path::PathBuf;

/// What the image shows.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum RenderView {
    /// Direct lighting from the scene's quad lights with soft shadows: the emitted radiance plus
    /// `U · S_N / U_N`, the ratio denoised (`--denoise`).
    Lit,
    /// The geometry: face-forward normals darkened with depth (one sample per pixel).
    Normals,
}

impl std::str::FromStr for RenderView {
    type Err = crate::Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "lit" => Ok(Self::Lit),
            "normals" => Ok(Self::Normals),
            other => Err(crate::Error::InvalidParameter {
                name: "view",
                reason: format!("unknown view `{other}` (expected lit or normals)"),
            }),
        }
    }
}

/// What to render and where.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// `builtin:NAME` or a scene file path.
    pub scene: String,
    /// Which backend runs the stages.
    pub device: DeviceChoice,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Samples (camera rays, and one shadow ray each) per pixel, ≥ 1.
    pub spp: u32,
    /// Seed of the sampler.
    pub seed: u32,
    /// Sampler kind (`raywave_shared::sampling::sampler_kind`).
    pub sampler: u32,
    /// Thin-lens aperture radius in scene units (0: pinhole).
    pub lens_radius: f32,
    /// Distance of the plane in focus; `None` focuses on the camera's look-at point.
    pub focus_distance: Option<f32>,
    /// What the image shows.
    pub view: RenderView,
    /// Output PNG path (sRGB, clamped).
    pub out: PathBuf,
    /// Also write the HDR image (linear RGB, 32-bit float OpenEXR) here.
    pub exr: Option<PathBuf>,
    /// Also write the fully stochastic image (emitted radiance + `S_N`, no ratio) as PNG here,
    /// for comparison.
    pub stochastic: Option<PathBuf>,
    /// The denoiser of the shadow ratio ([`DenoiseMethod::Tv`] by default;
    /// [`DenoiseMethod::None`] composites the raw `U · S_N/U_N`).
    pub denoise: DenoiseMethod,
    /// The filter radius R in pixels (`1..=MAX_RADIUS`; the TV filter's widest Gaussian, and the
    /// SVGF baseline's footprint); `None` follows the image size
    /// ([`raywave_shared::DenoiseParams::default_radius`]: 6 from a 441-pixel side up, 2 at 128²).
    pub denoise_radius: Option<u32>,
    /// Whether `U`'s specular term takes the quadrature residual towards GGX
    /// ([`ShadeData::analytic_residual`]).
    pub analytic_residual: bool,
    /// Backend options (validation layers).
    pub backend: BackendOptions,
    /// Steady-state stage times: render untimed frames until their summed stage times have not
    /// fallen for this many seconds (`0..=30`, else a typed error), in benchmark mode
    /// ([`BackendOptions::sustain_seconds`] at least the benches' 50 ms), then report one more.
    /// `None`: one frame, whose single dispatches a GPU may run at idle clocks — on an NVIDIA
    /// H100 two of three one-frame renders measured every stage about 5× slower than the steady
    /// state (README, "On an NVIDIA H100"). The image is the same either way.
    pub settle_seconds: Option<f64>,
}

/// What a render did.
#[derive(Clone, Debug)]
pub struct RenderReport {
    /// The backend that ran the stages.
    pub backend: String,
    /// Why `--device auto` ran on the CPU: the error Vulkan could not be opened with (`None`
    /// where it did not fall back).
    pub vulkan_fallback: Option<String>,
    /// Triangles in the scene.
    pub triangles: usize,
    /// Zero-area triangles dropped while loading the scene.
    pub dropped_degenerate: usize,
    /// Quad lights the shade stage samples.
    pub lights: usize,
    /// Emissive meshes that are not one planar parallelogram: they glow where seen but light
    /// nothing ([`Scene::unsupported_emitters`]).
    pub unsupported_emitters: usize,
    /// What the scene's file asked for that raywave does not render: textures, see-through and
    /// unlit materials, skins and morph targets, orthographic cameras, punctual lights, GPU
    /// instancing ([`Scene::unrendered`]).
    pub unrendered: Unrendered,
    /// Samples per pixel traced: `spp` for the lit view, 1 for the normals view.
    pub samples_per_pixel: u32,
    /// Per-stage times, sanitized counts and timed dispatches, summed over the samples (in
    /// benchmark mode, [`RenderOptions::settle_seconds`], each time is the mean of its
    /// dispatches).
    pub timings: Vec<StageReport>,
    /// Camera rays that hit geometry (over all samples).
    pub hits: usize,
    /// Bytes of SoA streams one sample pass uses per pixel (rays, hits, the shade stream, shadow
    /// rays, occlusion).
    pub stream_bytes_per_pixel: u64,
    /// Seconds of untimed warm-up frames before the timed one ([`RenderOptions::settle_seconds`];
    /// `None`: the one frame was timed).
    pub warm_up_seconds: Option<f64>,
    /// The most resident memory the process held, bytes, its files written
    /// ([`raywave_host::memory::peak_resident_bytes`]; `None` where it cannot be read): what
    /// [`LitFrameSettings::check_memory`] estimates, the process's own on top.
    pub peak_resident_bytes: Option<u64>,
}

impl RenderOptions {
    /// The frame these options describe: the lit view's samples per pixel, or one sample for the
    /// normals view.
    fn frame_settings(&self) -> LitFrameSettings {
        LitFrameSettings {
            samples_per_pixel: if self.view == RenderView::Lit { self.spp } else { 1 },
            sampler_kind: self.sampler,
            seed: self.seed,
            lens_radius: self.lens_radius,
            focus_distance: self.focus_distance,
            denoise: self.denoise,
            denoise_radius: self.denoise_radius,
            ..LitFrameSettings::new(self.width, self.height, self.spp)
        }
    }
}

/// Checks the options that need neither the scene nor the backend: the samples per pixel in
/// range, the backend options the device choice allows ([`BackendOptions::check_for`]: no
/// validation or hardware trace on the CPU), the frame's settings, the image size and the
/// samples for it as far as no backend is needed ([`LitFrameSettings::check_size`]: lens values
/// and filter radius in range too), outputs that the view writes, no option that another makes
/// the render ignore (but `--spp`, which has a default: the normals view traces one sample, as
/// README says; `--denoise-radius` where the TV filter is the identity at `--spp`,
/// [`crate::shared::DenoiseParams::tv_filter_is_identity`], included), and no file named twice.
fn check_options(options: &RenderOptions) -> Result<()> {
    let invalid = |name, reason: String| Err(crate::Error::InvalidParameter { name, reason });
    let settings = options.frame_settings();
    crate::frame::check_sample_count("spp", options.spp)?;
    options.backend.check_for(options.device)?;
    // Before the scene loads and the backend opens (its own pixel limit is checked once it is
    // open).
    settings.check_size()?;
    if options.view == RenderView::Normals {
        for (name, given) in [("exr", options.exr.is_some()), ("stochastic", options.stochastic.is_some())] {
            if given {
                return invalid(name, "the normals view writes only --out; drop it or use --view lit".into());
            }
        }
        // Options of the lit view's shading and denoising, which the normals view would ignore
        // (`--denoise` only where it differs from its default).
        let lit_only = [
            ("denoise", options.denoise != DenoiseMethod::Tv),
            ("denoise-radius", options.denoise_radius.is_some()),
            ("analytic-residual", options.analytic_residual),
        ];
        if let Some((name, _)) = lit_only.into_iter().find(|&(_, given)| given) {
            return invalid(name, "the normals view is neither shaded nor denoised; drop it or use --view lit".into());
        }
    }
    // Options that another option's value would make the render ignore.
    if options.focus_distance.is_some() && options.lens_radius == 0.0 {
        return invalid("focus", "a pinhole camera (no --aperture) has everything in focus; give --aperture R".into());
    }
    if options.denoise == DenoiseMethod::None && options.denoise_radius.is_some() {
        return invalid("denoise-radius", "--denoise none filters nothing; drop it or choose a filter".into());
    }
    let denoise = settings.denoise_params(settings.samples_per_pixel);
    if options.denoise == DenoiseMethod::Tv && options.denoise_radius.is_some() && denoise.tv_filter_is_identity() {
        let (spp, radius) = (settings.samples_per_pixel, denoise.radius);
        return invalid(
            "denoise-radius",
            format!(
                "the TV filter at --spp {spp} ≥ 4R² = {} leaves every pixel as it is (its widest Gaussian, R/√spp, \
                 is at most ½ pixel); drop it, or give R > √spp / 2",
                4 * radius * radius
            ),
        );
    }
    let named =
        [("out", Some(&options.out)), ("exr", options.exr.as_ref()), ("stochastic", options.stochastic.as_ref())];
    let same_file = |a: &PathBuf, b: &PathBuf| output_destination(a) == output_destination(b);
    for (k, (name, path)) in named.iter().enumerate() {
        let Some(path) = path else { continue };
        if let Some((other, _)) = named[..k].iter().find(|(_, p)| p.is_some_and(|p| same_file(p, path))) {
            return invalid(name, format!("{} is also --{other}'s file; each output needs its own", path.display()));
        }
    }
    Ok(())
}

/// Renders `options.scene` into `options.out` (and the optional EXR and stochastic images).
/// Every input is checked before work starts, and the output files appear together, each
/// complete, or not at all: a render with validation layers
/// ([`BackendOptions::validation`]) that reported anything, teardown included, is an
/// [`crate::Error::Validation`] and writes nothing.
pub fn render(options: &RenderOptions) -> Result<RenderReport> {
    check_options(options)?;
    let settle_seconds = options.settle_seconds.map(check_settle_seconds).transpose()?;
    let output = PendingOutput::create(&options.out, ImageFormat::Png)?;
    let exr = options.exr.as_deref().map(|path| PendingOutput::create(path, ImageFormat::OpenExr)).transpose()?;
    let stochastic =
        options.stochastic.as_deref().map(|path| PendingOutput::create(path, ImageFormat::Png)).transpose()?;
    let scene = Scene::load(&options.scene)?;
    // The lens against the camera's focus distance, in either view, before any work.
    options.frame_settings().check_lens(&scene)?;
    // Before the backend opens and builds its acceleration structures: the light BVH may refuse
    // the scene.
    let data = if options.view == RenderView::Lit {
        let mut data = ShadeData::new(&scene)?;
        data.analytic_residual = options.analytic_residual;
        Some(data)
    } else {
        None
    };
    let mut backend_options = options.backend.clone();
    if settle_seconds.is_some() {
        backend_options.sustain_seconds = backend_options.sustain_seconds.max(SUSTAIN_SECONDS);
    }
    let (mut backend, vulkan_fallback) = open_backend_telling_fallback(options.device, &backend_options)?;
    // The view's frame: its size on this backend, and its samples (one for the normals view,
    // whatever `--spp` says) for its sampler.
    let settings = options.frame_settings();
    settings.check_on(backend.as_ref())?;
    if options.view == RenderView::Lit {
        settings.check_memory(backend.as_ref())?;
    }
    backend.load_scene(&scene)?;
    let frame = Frame { scene: &scene, settings: &settings, data: data.as_ref(), one_off: settle_seconds.is_none() };
    let (rendered, warm_up_seconds) = match settle_seconds {
        None => (frame.render(backend.as_mut())?, None),
        Some(settle) => {
            let warm_up_seconds = warm_up(settle, || Ok(frame.render(backend.as_mut())?.seconds()))?;
            (frame.render(backend.as_mut())?, Some(warm_up_seconds))
        }
    };
    let backend_name = backend.name();
    close_backend(backend)?;
    let report = RenderReport {
        backend: backend_name,
        vulkan_fallback: vulkan_fallback.map(|error| error.to_string()),
        triangles: scene.triangle_count(),
        dropped_degenerate: scene.dropped_degenerate(),
        lights: scene.lights().len(),
        unsupported_emitters: scene.unsupported_emitters(),
        unrendered: scene.unrendered(),
        samples_per_pixel: settings.samples_per_pixel,
        hits: rendered.hits,
        stream_bytes_per_pixel: rendered.stream_bytes / (u64::from(options.width) * u64::from(options.height)),
        timings: rendered.timings,
        warm_up_seconds,
        peak_resident_bytes: None,
    };
    let (width, height) = (options.width, options.height);
    match rendered.image {
        FrameImage::Normals(image) => output.finish_image(&image)?,
        FrameImage::Lit { color, accumulator } => {
            let mut written = vec![output.write_image(&srgb_image(&color, width, height))?];
            if let Some(exr) = exr {
                written.push(exr.write_linear_rgb(&color, width, height)?);
            }
            if let Some(stochastic) = stochastic {
                written.push(stochastic.write_image(&srgb_image(&accumulator.stochastic_image(), width, height))?);
            }
            persist_all(written)?;
        }
    }
    Ok(RenderReport { peak_resident_bytes: raywave_host::memory::peak_resident_bytes(), ..report })
}

/// One frame of a render: everything but the backend, which each run borrows.
struct Frame<'a> {
    scene: &'a Scene,
    settings: &'a LitFrameSettings,
    /// The shading inputs of the lit view (`None`: the normals view).
    data: Option<&'a ShadeData>,
    /// Whether this is the only frame (no [`RenderOptions::settle_seconds`]): its samples' kept
    /// buffers are freed before the denoiser allocates its own, for a lower peak (a 1080p render
    /// on lavapipe: README, Architecture), where settling frames keep them as a frame loop does.
    one_off: bool,
}

/// What one frame produced.
struct RenderedFrame {
    /// Per-stage times and sanitized counts, summed over the samples.
    timings: Vec<StageReport>,
    /// Camera rays that hit geometry, over all samples.
    hits: usize,
    /// Bytes of SoA streams one sample pass used.
    stream_bytes: u64,
    image: FrameImage,
}

impl RenderedFrame {
    /// The frame's summed stage seconds, which the warm-up watches fall.
    fn seconds(&self) -> f64 {
        self.timings.iter().map(|t| t.seconds).sum()
    }
}

/// The image of a frame, by view.
enum FrameImage {
    /// The normals view, one sample per pixel.
    Normals(RgbImage),
    /// The lit view: the denoised colour (linear RGB) and the accumulated estimates behind it.
    Lit { color: Vec<Vec3>, accumulator: ShadeAccumulator },
}

impl Frame<'_> {
    /// Renders the frame on `backend`: the lit view as `render_lit` does it ([`shade_samples`]:
    /// per sample generate → trace → shade → occlusion; then [`denoise_samples`]), the normals
    /// view from one sample's hits.
    fn render(&self, backend: &mut dyn Backend) -> Result<RenderedFrame> {
        let (width, height) = (self.settings.width, self.settings.height);
        let Some(data) = self.data else {
            let frame = backend.render(&self.settings.generate_params(self.scene, 0))?;
            let hits = frame.hits.hit_count();
            let image = normal_depth_image(self.scene, &frame.rays, &frame.hits, width, height);
            let stream_bytes = frame.rays.bytes() + frame.hits.bytes();
            return Ok(RenderedFrame { timings: frame.timings, hits, stream_bytes, image: FrameImage::Normals(image) });
        };
        let samples = shade_samples(backend, self.scene, data, self.settings)?;
        if self.one_off {
            backend.release_kept_memory();
        }
        let lit = denoise_samples(backend, self.settings, samples)?;
        let samples = lit.samples;
        Ok(RenderedFrame {
            timings: samples.timings,
            hits: samples.hits,
            stream_bytes: samples.stream_bytes,
            image: FrameImage::Lit { color: lit.color, accumulator: samples.accumulator },
        })
    }
}
