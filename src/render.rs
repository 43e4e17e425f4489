//! The `raywave render` job: scene → generate → trace on a chosen backend → image file.

use crate::{open_backend, BackendOptions, DeviceChoice, Result, Scene, StageTiming};
use raywave_host::frame::{generate_params_with, sampler_params};
use raywave_host::visualize::{normal_depth_image, PendingOutput};
use std::path::PathBuf;

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
    /// Seed of the sampler.
    pub seed: u32,
    /// Sampler kind (`raywave_shared::sampling::sampler_kind`).
    pub sampler: u32,
    /// Thin-lens aperture radius in scene units (0: pinhole).
    pub lens_radius: f32,
    /// Distance of the plane in focus; `None` focuses on the camera's look-at point.
    pub focus_distance: Option<f32>,
    /// Output PNG path.
    pub out: PathBuf,
    /// Backend options (validation layers).
    pub backend: BackendOptions,
}

/// What a render did.
#[derive(Clone, Debug)]
pub struct RenderReport {
    /// The backend that ran the stages.
    pub backend: String,
    /// Triangles in the scene.
    pub triangles: usize,
    /// Zero-area triangles dropped while loading the scene.
    pub dropped_degenerate: usize,
    /// Per-stage times.
    pub timings: Vec<StageTiming>,
    /// Rays that hit geometry.
    pub hits: usize,
    /// Bytes of SoA streams the frame used per pixel (ray stream + hit stream).
    pub stream_bytes_per_pixel: u64,
}

/// Renders the normal/depth view of `options.scene` into `options.out`. Every input is checked
/// before work starts and the output file appears only when complete.
pub fn render(options: &RenderOptions) -> Result<RenderReport> {
    let scene = Scene::load(&options.scene)?;
    let output = PendingOutput::create(&options.out)?;
    let mut backend = open_backend(options.device, &options.backend)?;
    backend.check_image_size(options.width, options.height)?;
    backend.load_scene(&scene)?;
    let lens_ok = options.lens_radius.is_finite() && options.lens_radius >= 0.0;
    if !lens_ok {
        return Err(crate::Error::InvalidParameter { name: "aperture", reason: "must be finite and ≥ 0".into() });
    }
    let sampler = sampler_params(options.sampler, options.seed, options.width, options.height, 1);
    let mut params = generate_params_with(&scene, options.width, options.height, 0, sampler);
    params.lens_radius = options.lens_radius;
    if let Some(focus) = options.focus_distance {
        if !(focus.is_finite() && focus > 0.0) {
            return Err(crate::Error::InvalidParameter { name: "focus", reason: "must be finite and > 0".into() });
        }
        params.focus_distance = focus;
    }
    let frame = backend.render(&params)?;
    let image = normal_depth_image(&scene, &frame.rays, &frame.hits, options.width, options.height);
    output.finish_png(&image)?;
    Ok(RenderReport {
        backend: backend.name(),
        triangles: scene.triangle_count(),
        dropped_degenerate: scene.dropped_degenerate(),
        hits: frame.hits.primitive.iter().filter(|&&p| p != crate::shared::stream::NO_HIT).count(),
        stream_bytes_per_pixel: (frame.rays.bytes() + frame.hits.bytes()) / u64::from(options.width * options.height),
        timings: frame.timings,
    })
}
