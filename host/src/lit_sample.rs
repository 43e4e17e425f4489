//! One lit sample of a frame as a backend runs it — generate → trace → shade → occlusion trace —
//! with what comes back to the host cut to what the accumulator adds up ([`LitSample`]).
//!
//! Composed from a backend's stage calls ([`compose`]), every stream passes through the host
//! between stages; on Vulkan that was about 240 bytes a pixel down and up again per sample and a
//! blocking submission per buffer. [`crate::Backend::lit_sample`] lets a backend keep the streams
//! on its device from the camera rays to the occlusion results instead, as the Vulkan backend
//! does; it must give the composed sample's values bit for bit (the same kernels on the same
//! inputs), which `tests/parity_lit_sample.rs` checks.

use crate::backend::{Backend, StageReport};
use crate::error::Result;
use crate::shading::{shadow_rays, ShadeData};
use crate::stream::{HitStream, RayStream, ShadeStream};
use glam::Vec4;
use raywave_shared::{GenerateParams, ShadeParams};

/// What one lit sample is asked for.
#[derive(Clone, Copy)]
pub struct LitSampleRequest<'a> {
    /// The camera rays: the generate stage's parameters (dense, one ray per pixel).
    pub generate: &'a GenerateParams,
    /// The shade stage's parameters, for the same image and sample index as `generate`.
    pub shade: &'a ShadeParams,
    /// The loaded scene's shade data ([`ShadeData::new`]).
    pub data: &'a ShadeData,
    /// Whether to return the camera rays and their hits as well ([`LitSample::camera`]): the
    /// denoiser's G-buffer is resolved from the first sample's.
    pub keep_camera_streams: bool,
}

/// One lit sample's results, one record per pixel (ray `i` is pixel `i`): the shade stage's
/// outputs that the accumulator sums and the occlusion of each shadow ray.
#[derive(Clone, Debug, PartialEq)]
pub struct LitSample {
    /// Analytic unshadowed radiance `U` (rgb; w = 0).
    pub analytic: Vec<Vec4>,
    /// This sample's contribution to `U_N` (rgb; w = 0).
    pub unshadowed: Vec<Vec4>,
    /// Radiance emitted by the surface towards the camera (rgb; w = 0).
    pub emitted: Vec<Vec4>,
    /// 1 where the pixel's shadow ray was blocked, 0 where not (or where there was none).
    pub occluded: Vec<u32>,
    /// Camera rays that hit geometry.
    pub hits: usize,
    /// The camera rays and their hits, when [`LitSampleRequest::keep_camera_streams`] asked.
    pub camera: Option<(RayStream, HitStream)>,
    /// The camera stages' reports, `generate` and `trace`, in execution order.
    pub camera_timings: Vec<StageReport>,
    /// The pass's reports, `shade` and `occlusion`.
    pub pass_timings: [StageReport; 2],
    /// Bytes of the SoA streams the sample used on the backend: camera rays, hits, the shade
    /// stream, occlusion results, and, where the shadow rays pass through the host, their copy.
    pub stream_bytes: u64,
}

/// A shade pass over camera rays and their hits on `backend`: the shade stream, the occlusion of
/// its shadow rays, both stages' reports and the bytes of the streams the pass used (shade stream,
/// shadow rays, occlusion results). The pass [`compose`] and
/// [`crate::shading::ShadeAccumulator::shade_pass`] run.
pub fn shade_and_occlude<B: Backend + ?Sized>(
    backend: &mut B,
    params: &ShadeParams,
    data: &ShadeData,
    rays: &RayStream,
    hits: &HitStream,
) -> Result<(ShadeStream, Vec<u32>, [StageReport; 2], u64)> {
    let (shades, shade_time) = backend.shade(params, data, rays, hits)?;
    let shadow_rays = shadow_rays(&shades);
    let (occluded, occlusion_time) = backend.trace_occlusion(&shadow_rays)?;
    let bytes = shades.bytes() + std::mem::size_of_val(occluded.as_slice()) as u64 + shadow_rays.bytes();
    Ok((shades, occluded, [shade_time, occlusion_time], bytes))
}

/// The lit sample of `request` from `backend`'s stage calls — [`Backend::render`], then
/// [`shade_and_occlude`] — every stream passing through the host: what
/// [`Backend::lit_sample`] does unless a backend keeps the streams on its device.
pub fn compose<B: Backend + ?Sized>(backend: &mut B, request: &LitSampleRequest<'_>) -> Result<LitSample> {
    let frame = backend.render(request.generate)?;
    let (shades, occluded, pass_timings, pass_bytes) =
        shade_and_occlude(backend, request.shade, request.data, &frame.rays, &frame.hits)?;
    Ok(LitSample {
        analytic: shades.analytic,
        unshadowed: shades.unshadowed,
        emitted: shades.emitted,
        occluded,
        hits: frame.hits.hit_count(),
        stream_bytes: frame.rays.bytes() + frame.hits.bytes() + pass_bytes,
        camera: request.keep_camera_streams.then_some((frame.rays, frame.hits)),
        camera_timings: frame.timings,
        pass_timings,
    })
}
