//! One lit sample of a frame as a backend runs it — generate → trace → shade → occlusion trace —
//! with what comes back to the host cut to what the accumulator adds up ([`LitSample`]).
//!
//! Composed from a backend's stage calls ([`compose`]), the streams stay on the device only from
//! generate to trace: the camera rays and their hits, the shade stream and the occlusion results
//! pass through the host between the calls; on Vulkan that is 208 bytes a pixel per sample (140
//! read back, 68 uploaded again), in one blocking submission per call (render, shade, occlusion
//! trace). [`crate::Backend::lit_sample`] lets a backend keep the streams
//! on its device from the camera rays to the occlusion results instead, as the Vulkan backend
//! does; it must give the composed sample's values bit for bit (the same kernels on the same
//! inputs), which `tests/parity_lit_sample.rs` checks.

use crate::backend::{Backend, StageReport};
use crate::error::{Error, Result};
use crate::shading::{shadow_rays, ShadeData};
use crate::stream::{check_one_hit_per_ray, first_not_ascending, hits_among, HitStream, RayStream, ShadeStream};
use glam::Vec4;
use raywave_shared::{GenerateParams, ShadeParams};

/// What one lit sample is asked for.
#[derive(Clone, Copy, Debug)]
pub struct LitSampleRequest<'a> {
    /// The camera rays: the generate stage's parameters (dense, one ray per pixel).
    pub generate: &'a GenerateParams,
    /// The shade stage's parameters, for the same image and sample index as `generate`.
    pub shade: &'a ShadeParams,
    /// The loaded scene's shade data ([`ShadeData::new`]).
    pub data: &'a ShadeData,
    /// Which camera rays and hits to return as well ([`LitSample::camera`]): the denoiser's
    /// G-buffer is resolved from the first sample's, and its gaps filled from later samples'.
    pub camera: CameraStreams<'a>,
}

/// The camera streams a lit sample returns besides what the accumulator adds up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraStreams<'a> {
    /// None.
    None,
    /// Every camera ray and its hit, ray `i` for pixel `i`: the G-buffer's first resolve.
    All,
    /// The camera rays and hits of the pixels listed (strictly ascending, each an index of the
    /// image) whose ray hit something (its primitive not `NO_HIT`), in the list's order, with
    /// `rays.pixel` naming each one's pixel: the G-buffer's gaps that a later sample fills. What
    /// comes back is as many records as hit there (on Vulkan, copied out of the device's streams
    /// in a submission of their own once the sample's hits are known, whose time no report
    /// holds), not the frame's.
    HitsAmong(&'a [u32]),
}

impl LitSampleRequest<'_> {
    /// Checks that `shade` is for `generate`'s image and sample: the same width, sample index
    /// and sampler (the ray and hit counts are the shade stage's own check). A mismatch had been
    /// shaded as asked — samples drawn for other pixels or another sample of the sequence —
    /// without a word. An error naming `lit_sample` and the field otherwise.
    pub fn check(&self) -> Result<()> {
        let (generate, shade) = (self.generate, self.shade);
        let reason = if shade.width != generate.width {
            Some(format!("shade.width = {} but generate.width = {}", shade.width, generate.width))
        } else if shade.sample_index != generate.sample_index {
            Some(format!(
                "shade.sample_index = {} but generate.sample_index = {}",
                shade.sample_index, generate.sample_index
            ))
        } else if shade.sampler != generate.sampler {
            Some(format!("shade.sampler = {:?} but generate.sampler = {:?}", shade.sampler, generate.sampler))
        } else if let CameraStreams::HitsAmong(pixels) = self.camera {
            listed_pixels_problem(pixels, u64::from(generate.width) * u64::from(generate.height))
        } else {
            None
        };
        reason.map_or(Ok(()), |reason| Err(Error::InvalidParameter { name: "lit_sample", reason }))
    }
}

/// Why `pixels` is no list [`CameraStreams::HitsAmong`] takes for an image of `count` pixels:
/// an entry out of order, repeated or past the image's end.
fn listed_pixels_problem(pixels: &[u32], count: u64) -> Option<String> {
    if let Some(k) = first_not_ascending(pixels) {
        let (a, b) = (pixels[k], pixels[k + 1]);
        return Some(format!("camera pixels [{k}] = {a} and [{}] = {b}: the list must be strictly ascending", k + 1));
    }
    match pixels.last() {
        Some(&last) if u64::from(last) >= count => {
            Some(format!("camera pixel {last} is past the image's end ({count} pixels)"))
        }
        _ => None,
    }
}

/// One lit sample's results, one record per pixel (ray `i` is pixel `i`): the shade stage's
/// outputs that the accumulator sums and the occlusion of each shadow ray; the camera streams as
/// [`CameraStreams`] asked. (Not `PartialEq`: two runs differ in their reports' seconds.)
#[derive(Clone, Debug)]
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
    /// The camera rays and their hits that [`LitSampleRequest::camera`] asked for; `None` where
    /// it asked for none.
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
pub(crate) fn shade_and_occlude<B: Backend + ?Sized>(
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

/// The lit sample of `request` ([`LitSampleRequest::check`]) from `backend`'s stage calls —
/// [`Backend::render`], then the shade stage and the occlusion trace of its shadow rays — every
/// stream but the camera rays passing through the host: what [`Backend::lit_sample`] does unless
/// a backend keeps the streams on its device.
pub fn compose<B: Backend + ?Sized>(backend: &mut B, request: &LitSampleRequest<'_>) -> Result<LitSample> {
    request.check()?;
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
        camera: match request.camera {
            CameraStreams::None => None,
            CameraStreams::All => Some((frame.rays, frame.hits)),
            CameraStreams::HitsAmong(pixels) => {
                // Selected from every field of both streams: a backend's frame with fields of
                // other lengths is refused, not indexed past an end.
                check_one_hit_per_ray(&frame.rays, &frame.hits, "lit_sample")?;
                let hit = hits_among(pixels, &frame.hits.primitive);
                Some((frame.rays.select(&hit), frame.hits.select(&hit)))
            }
        },
        camera_timings: frame.timings,
        pass_timings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu::CpuBackend;
    use crate::frame::{generate_params_with, sampler_params};
    use crate::scene::Scene;
    use raywave_shared::sampling::sampler_kind;
    use raywave_shared::stream::NO_HIT;
    use raywave_shared::SamplerParams;

    /// `scene` on a CPU backend, its shade data, and the sampler, camera and shade parameters of
    /// sample 1 (of 4) of a `width × height` image.
    fn sample_one(
        scene: &str,
        width: u32,
        height: u32,
    ) -> (CpuBackend, ShadeData, SamplerParams, GenerateParams, ShadeParams) {
        let scene = Scene::load(scene).unwrap();
        let data = ShadeData::new(&scene).unwrap();
        let mut cpu = CpuBackend::new();
        cpu.load_scene(&scene).unwrap();
        let sampler = sampler_params(sampler_kind::ZSOBOL, 3, width, height, 4);
        let generate = generate_params_with(&scene, width, height, 1, sampler);
        let shade = data.params(sampler, width, height, 1);
        (cpu, data, sampler, generate, shade)
    }

    /// Shading for another image, sample or sampler than the camera rays' is refused before any
    /// work, naming the field; the matching request is shaded.
    #[test]
    fn a_request_shades_the_camera_rays_own_image_and_sample() {
        let (mut cpu, data, sampler, generate, shade) = sample_one("builtin:cornell", 16, 12);
        let request = LitSampleRequest { generate: &generate, shade: &shade, data: &data, camera: CameraStreams::None };
        assert_eq!(compose(&mut cpu, &request).unwrap().analytic.len(), 16 * 12);
        let mismatches = [
            (ShadeParams { width: 12, count: 16 * 12, ..shade }, "shade.width = 12"),
            (ShadeParams { sample_index: 2, ..shade }, "shade.sample_index = 2"),
            (ShadeParams { sampler: SamplerParams { seed: 4, ..sampler }, ..shade }, "shade.sampler"),
        ];
        let listed = |pixels: &'static [u32]| LitSampleRequest { camera: CameraStreams::HitsAmong(pixels), ..request };
        let requests = mismatches.iter().map(|(shade, what)| (LitSampleRequest { shade, ..request }, *what)).chain([
            (listed(&[4, 3]), "[0] = 4 and [1] = 3: the list must be strictly ascending"),
            (listed(&[1, 1]), "strictly ascending"),
            (listed(&[0, 16 * 12]), "camera pixel 192 is past the image's end (192 pixels)"),
        ]);
        for (request, what) in requests {
            match compose(&mut cpu, &request) {
                Err(Error::InvalidParameter { name: "lit_sample", reason }) => {
                    assert!(reason.contains(what), "{reason}")
                }
                other => panic!("{what}: {:?}", other.map(|_| "accepted")),
            }
        }
    }

    /// The camera streams asked for: none, the whole frame's, or the records of the listed
    /// pixels that hit, in the list's order, each naming its pixel — those of the whole frame at
    /// those pixels.
    #[test]
    fn a_sample_returns_the_camera_records_asked_for() {
        let (mut cpu, data, _, generate, shade) = sample_one("builtin:spheres", 32, 24);
        let request = |camera| LitSampleRequest { generate: &generate, shade: &shade, data: &data, camera };
        assert_eq!(compose(&mut cpu, &request(CameraStreams::None)).unwrap().camera, None);
        let (rays, hits) = compose(&mut cpu, &request(CameraStreams::All)).unwrap().camera.unwrap();
        assert_eq!((rays.len(), hits.len()), (32 * 24, 32 * 24));
        let listed: Vec<u32> = (0..32 * 24).step_by(5).collect();
        let hit: Vec<u32> = listed.iter().copied().filter(|&i| hits.primitive[i as usize] != NO_HIT).collect();
        assert!(
            !hit.is_empty() && hit.len() < listed.len(),
            "the list holds hits and misses: {} of {}",
            hit.len(),
            listed.len()
        );
        let (some_rays, some_hits) =
            compose(&mut cpu, &request(CameraStreams::HitsAmong(&listed))).unwrap().camera.unwrap();
        assert_eq!(some_rays.pixel, hit);
        assert_eq!((some_rays, some_hits), (rays.select(&hit), hits.select(&hit)));
    }
}
