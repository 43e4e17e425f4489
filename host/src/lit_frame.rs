//! A lit frame of a scene in memory on any backend: per sample generate → trace → shade →
//! occlusion trace, then a denoiser and the ratio estimator's composite
//! `emitted + U · den(S_N)/den(U_N)`. This is what `raywave render` runs; an engine that builds its
//! own [`Scene`] ([`Scene::new`]) calls [`render_lit`] and gets the image in memory.

use crate::backend::{aperture_refusal, check_image_size_common, check_shade_streams, Backend, StageReport};
use crate::denoise::{check_radius, frame_params, is_guide_surface, rgb, DenoiseInput, DenoiseMethod};
use crate::error::{Error, Result};
use crate::frame::{check_samples_per_pixel, generate_params_with, sampler_params};
use crate::lit_sample::{CameraStreams, LitSampleRequest};
use crate::scene::{Scene, MAX_COORDINATE};
use crate::shading::{resolve, ShadeAccumulator, ShadeData};
use crate::stream::{check_one_hit_per_ray, first_not_ascending, HitStream, RayStream};
use glam::Vec3;
use raywave_kernels::shade::stage::Surface;
use raywave_shared::sampling::sampler_kind;
use raywave_shared::{DenoiseParams, GenerateParams, SamplerParams};

/// The largest thin-lens aperture radius and focus distance accepted, in scene units, as for
/// the scene's coordinates ([`MAX_COORDINATE`]): ray origins on the lens stay in the range the
/// trace and shade stages handle (an aperture of 10²⁰ rendered black).
pub const MAX_LENS_DISTANCE: f32 = MAX_COORDINATE;

/// How a lit frame is sampled and filtered.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LitFrameSettings {
    /// Image width in pixels (≥ 1, within the backend's limits: [`Backend::check_image_size`]).
    pub width: u32,
    /// Image height in pixels (≥ 1, within the backend's limits).
    pub height: u32,
    /// Samples per pixel: camera rays, and one shadow ray each ([`check_samples_per_pixel`]).
    pub samples_per_pixel: u32,
    /// The sampler (one of [`sampler_kind`]; the blue-noise `ZSOBOL` by default).
    pub sampler_kind: u32,
    /// Seed of the sampler and of the noise estimate's line angles.
    pub seed: u32,
    /// Thin-lens aperture radius in scene units, in `[0, MAX_LENS_DISTANCE]` (0: a pinhole) and
    /// at most [`MAX_APERTURE_TO_FOCUS`](crate::backend::MAX_APERTURE_TO_FOCUS) times the focus distance.
    pub lens_radius: f32,
    /// Distance of the plane in focus, in `(0, MAX_LENS_DISTANCE]`; `None` focuses on the
    /// camera's look-at point.
    pub focus_distance: Option<f32>,
    /// The denoiser of the shadow ratio ([`DenoiseMethod::Tv`] by default;
    /// [`DenoiseMethod::None`] composites the raw `U · S_N/U_N`).
    pub denoise: DenoiseMethod,
    /// The filter radius R in pixels (`1..=MAX_RADIUS`); `None` follows the image size
    /// ([`DenoiseParams::default_radius`]).
    pub denoise_radius: Option<u32>,
}

impl LitFrameSettings {
    /// A `width × height` frame of `samples_per_pixel` samples: the blue-noise sampler with seed 0,
    /// a pinhole camera, the TV denoiser with the radius that follows the image.
    pub fn new(width: u32, height: u32, samples_per_pixel: u32) -> Self {
        Self {
            width,
            height,
            samples_per_pixel,
            sampler_kind: sampler_kind::ZSOBOL,
            seed: 0,
            lens_radius: 0.0,
            focus_distance: None,
            denoise: DenoiseMethod::Tv,
            denoise_radius: None,
        }
    }

    /// Checks the settings that need neither the backend nor the image size: the sampler kind,
    /// the lens (its ratio of aperture to focus where the focus distance is set; see
    /// [`Self::check_lens`] for the camera's) and the filter radius. Errors name the setting as
    /// `raywave render` spells its option (`sampler`, `aperture`, `focus`, `denoise-radius`).
    pub fn check(&self) -> Result<()> {
        let invalid = |name, reason: String| Err(Error::InvalidParameter { name, reason });
        if self.sampler_kind >= sampler_kind::COUNT {
            return invalid("sampler", format!("kind {} is not one of 0..{}", self.sampler_kind, sampler_kind::COUNT));
        }
        check_radius("denoise-radius", self.denoise_radius)?;
        if !(0.0..=MAX_LENS_DISTANCE).contains(&self.lens_radius) {
            return invalid("aperture", format!("{} is outside [0, {MAX_LENS_DISTANCE:e}]", self.lens_radius));
        }
        if let Some(focus) = self.focus_distance {
            if !(focus > 0.0 && focus <= MAX_LENS_DISTANCE) {
                return invalid("focus", format!("{focus} is outside (0, {MAX_LENS_DISTANCE:e}]"));
            }
            return check_aperture(self.lens_radius, focus, "");
        }
        Ok(())
    }

    /// Checks the aperture against the focus distance this frame uses on `scene`: the one set, or
    /// the camera's look-at distance (at most [`MAX_APERTURE_TO_FOCUS`](crate::backend::MAX_APERTURE_TO_FOCUS) times it; an error naming
    /// `aperture`). [`shade_samples`] calls it before any work; a job can call it as soon as the
    /// scene has loaded.
    pub fn check_lens(&self, scene: &Scene) -> Result<()> {
        let camera_focus = if self.focus_distance.is_none() {
            " (the camera's look-at distance: set the focus distance, --focus, or narrow the aperture)"
        } else {
            ""
        };
        check_aperture(self.lens_radius, self.generate_params(scene, 0).focus_distance, camera_focus)
    }

    /// [`Self::check`], then the image size against the rules every backend shares (at least one
    /// pixel, a side of at most [`crate::backend::MAX_IMAGE_SIDE`]) and the samples per pixel for
    /// that size: all of [`Self::check_on`] but a backend's own pixel limit, so that a job can
    /// refuse them before it loads a scene or opens a backend.
    pub fn check_size(&self) -> Result<()> {
        self.check()?;
        check_image_size_common(self.width, self.height, u64::MAX, "every backend")?;
        check_samples_per_pixel("spp", self.sampler_kind, self.width, self.height, self.samples_per_pixel)
    }

    /// Checks every setting for a frame on `backend`: [`Self::check`], then the image size
    /// against the backend's limits ([`Backend::check_image_size`]), then the samples per pixel
    /// for that size ([`check_samples_per_pixel`], named `spp`).
    pub fn check_on(&self, backend: &dyn Backend) -> Result<()> {
        self.check()?;
        backend.check_image_size(self.width, self.height)?;
        check_samples_per_pixel("spp", self.sampler_kind, self.width, self.height, self.samples_per_pixel)
    }

    /// Checks that a lit frame of this size fits the host's memory on `backend`: its
    /// [`Backend::lit_frame_bytes_per_pixel`] times the pixels within
    /// [`crate::memory::available_bytes`], else an [`Error::ImageSize`] giving both — a render
    /// too large for the machine is refused before it starts, where the out-of-memory killer had
    /// ended it midway. It passes where either is unknown; the scene's own memory (its BVH) is not
    /// counted.
    pub fn check_memory(&self, backend: &dyn Backend) -> Result<()> {
        let (per_pixel, available) = (backend.lit_frame_bytes_per_pixel(), crate::memory::available_bytes());
        check_memory_fits(self.width, self.height, per_pixel, available, &backend.name())
    }

    /// The sampler of this frame's samples.
    pub fn sampler(&self) -> SamplerParams {
        sampler_params(self.sampler_kind, self.seed, self.width, self.height, self.samples_per_pixel)
    }

    /// The generate stage's parameters for sample `sample_index` of `scene`'s camera, with this
    /// frame's lens: `tmax` lengthened by twice the aperture's radius (a ray from the lens's rim
    /// starts up to one radius farther from the scene than the camera; twice keeps a margin when
    /// the radius dwarfs the scene, where `f32` would round one away): an aperture wider than the
    /// scene had cut rays short, a darkened image with nothing counted.
    pub fn generate_params(&self, scene: &Scene, sample_index: u32) -> GenerateParams {
        let mut params = generate_params_with(scene, self.width, self.height, sample_index, self.sampler());
        params.tmax += 2.0 * self.lens_radius;
        params.lens_radius = self.lens_radius;
        params.focus_distance = self.focus_distance.unwrap_or(params.focus_distance);
        params
    }

    /// The denoiser's parameters for a frame of `samples` samples per pixel.
    pub fn denoise_params(&self, samples: u32) -> DenoiseParams {
        DenoiseParams {
            seed: self.seed,
            samples_per_pixel: samples,
            ..frame_params(self.width, self.height, self.denoise_radius)
        }
    }
}

/// Host memory, bytes per pixel, that a lit frame holds on every backend at its denoise step:
/// the sums of its samples ([`ShadeAccumulator`]: four `f64` RGB sums), the G-buffer
/// ([`Surface`]), the denoiser's inputs ([`DenoiseInput`]: six `Vec4` images) and the colour it
/// returns (a `Vec4`) — 256 bytes. A lower bound, counted, not measured: staging copies, the
/// images written and their encodings come on top (the CPU backend, which holds all of it and its
/// streams, measured 360). What a Vulkan GPU's frame is held to
/// ([`Backend::lit_frame_bytes_per_pixel`]).
pub const HOST_LIT_FRAME_BYTES_PER_PIXEL: u64 = (4 * std::mem::size_of::<glam::DVec3>()
    + std::mem::size_of::<Surface>()
    + 7 * std::mem::size_of::<glam::Vec4>()) as u64;
const _: () = assert!(HOST_LIT_FRAME_BYTES_PER_PIXEL == 256, "the figure its doc gives");
const _: () = assert!(
    HOST_LIT_FRAME_BYTES_PER_PIXEL < crate::cpu::LIT_FRAME_BYTES_PER_PIXEL,
    "a lower bound of what the CPU backend's measured peak holds too"
);

/// [`LitFrameSettings::check_memory`]'s rule: a `width × height` lit frame at `per_pixel` bytes
/// fits within `available` bytes (either `None`: unknown, so it passes).
fn check_memory_fits(
    width: u32,
    height: u32,
    per_pixel: Option<u64>,
    available: Option<u64>,
    backend: &str,
) -> Result<()> {
    let (Some(per_pixel), Some(available)) = (per_pixel, available) else { return Ok(()) };
    let needed = u64::from(width) * u64::from(height) * per_pixel;
    if needed <= available {
        return Ok(());
    }
    let gb = |bytes: u64| bytes as f64 / 1e9;
    let reason = format!(
        "a lit frame needs about {:.1} GB of memory ({per_pixel} bytes per pixel), more than the {:.1} GB \
         available",
        gb(needed),
        gb(available)
    );
    Err(Error::ImageSize { width, height, backend: backend.to_owned(), reason })
}

/// The shading samples of a frame, before any filter.
#[derive(Clone, Debug)]
pub struct LitSamples {
    /// Per-pixel sums of `U`, `U_N`, `S_N` and the emitted radiance over the samples.
    pub accumulator: ShadeAccumulator,
    /// The denoiser's G-buffer: per pixel, the surface hit by the first of its camera rays that
    /// hit one the denoiser sees (so a silhouette pixel whose first jittered ray missed is
    /// filtered as the later rays that hit it saw it); none where no ray did.
    pub surfaces: Vec<Surface>,
    /// Each stage's report, summed over the samples ([`StageReport::add_to`]) in execution order.
    pub timings: Vec<StageReport>,
    /// Camera rays that hit geometry, over all samples.
    pub hits: usize,
    /// Bytes of the SoA streams one sample used ([`crate::lit_sample::LitSample::stream_bytes`]):
    /// rays, hits, the shade stream, occlusion results and, on a backend whose shadow rays pass
    /// through the host, their copy.
    pub stream_bytes: u64,
}

impl LitSamples {
    /// The denoiser's inputs: the G-buffer and the accumulated estimates.
    pub fn denoise_input(&self) -> DenoiseInput {
        DenoiseInput::new(&self.surfaces, &self.accumulator)
    }
}

/// The aperture `lens_radius` against the focus distance `focus` ([`aperture_refusal`]): an
/// error naming `aperture`, its reason followed by `note` (where the focus distance came from).
fn check_aperture(lens_radius: f32, focus: f32, note: &str) -> Result<()> {
    match aperture_refusal(lens_radius, focus) {
        Some(reason) => Err(Error::InvalidParameter { name: "aperture", reason: format!("{reason}{note}") }),
        None => Ok(()),
    }
}

/// Runs `settings.samples_per_pixel` samples of `scene` on `backend`, each generate → trace →
/// shade → occlusion trace, and accumulates them. `backend` must have loaded `scene`
/// ([`Backend::load_scene`]) and `data` must be `scene`'s ([`ShadeData::new`]); the settings, the
/// image size, the lens on `scene`'s camera ([`LitFrameSettings::check_lens`]), `data`'s scene
/// ([`ShadeData::check_scene`]) and `data` ([`ShadeData::check`]) are checked first, so a bad
/// value is a typed error before any work.
///
/// The denoiser's G-buffer ([`LitSamples::surfaces`]) is resolved from the first sample's camera
/// streams; its gaps, pixels whose first ray hit no surface, take the surface of the first later
/// sample whose ray hit one there ([`CameraStreams::HitsAmong`]: only those records come back).
/// Without that, a silhouette pixel whose first jittered ray missed was never filtered.
pub fn shade_samples(
    backend: &mut dyn Backend,
    scene: &Scene,
    data: &ShadeData,
    settings: &LitFrameSettings,
) -> Result<LitSamples> {
    settings.check_on(backend)?;
    settings.check_lens(scene)?;
    data.check_scene(Some(scene.identity()))?;
    data.check()?;
    let (width, height) = (settings.width, settings.height);
    let mut samples = LitSamples {
        accumulator: ShadeAccumulator::new(width as usize * height as usize),
        surfaces: Vec::new(),
        timings: Vec::new(),
        hits: 0,
        stream_bytes: 0,
    };
    // The G-buffer's gaps: pixels with no surface yet, ascending.
    let mut gaps: Vec<u32> = Vec::new();
    for sample_index in 0..settings.samples_per_pixel {
        let generate = settings.generate_params(scene, sample_index);
        let shade = data.params(settings.sampler(), width, height, sample_index);
        let camera = match sample_index {
            0 => CameraStreams::All,
            _ if gaps.is_empty() => CameraStreams::None,
            _ => CameraStreams::HitsAmong(&gaps),
        };
        let request = LitSampleRequest { generate: &generate, shade: &shade, data, camera };
        let sample = backend.lit_sample(&request)?;
        samples.accumulator.add_sample(&sample)?;
        if camera != CameraStreams::None {
            // The streams are checked again here (`data` was checked above): the resolve step
            // would panic on fewer hits than rays, and a backend an engine wrote may return other
            // streams than the ones it shaded.
            let Some((rays, hits)) = &sample.camera else {
                let reason = format!("the backend's lit sample {sample_index} returned no camera streams");
                return Err(Error::InvalidParameter { name: "lit_sample", reason });
            };
            if sample_index == 0 {
                check_shade_streams(&shade, data, rays, hits)?;
                samples.surfaces = resolve(data, rays, hits);
                gaps = (0..samples.surfaces.len() as u32)
                    .filter(|&i| !is_guide_surface(&samples.surfaces[i as usize]))
                    .collect();
            } else {
                check_gap_streams(rays, hits, &gaps)?;
                fill_gaps(&mut samples.surfaces, &mut gaps, data, rays, hits);
            }
        }
        for report in sample.camera_timings.iter().chain(&sample.pass_timings) {
            StageReport::add_to(&mut samples.timings, report);
        }
        samples.hits += sample.hits;
        samples.stream_bytes = sample.stream_bytes;
    }
    Ok(samples)
}

/// Checks the camera streams a lit sample returned for the G-buffer's `gaps`
/// ([`CameraStreams::HitsAmong`]): one hit per ray, each ray's pixel one of `gaps`, ascending.
/// An error naming `lit_sample` otherwise (a backend an engine wrote may return other records).
fn check_gap_streams(rays: &RayStream, hits: &HitStream, gaps: &[u32]) -> Result<()> {
    check_one_hit_per_ray(rays, hits, "lit_sample")?;
    let reason = if let Some(k) = first_not_ascending(&rays.pixel) {
        Some(format!("camera rays' pixels [{k}] and [{}] are not ascending", k + 1))
    } else {
        let unlisted = rays.pixel.iter().find(|pixel| gaps.binary_search(pixel).is_err());
        unlisted.map(|pixel| format!("a camera ray of pixel {pixel}, which was not asked for"))
    };
    reason.map_or(Ok(()), |reason| Err(Error::InvalidParameter { name: "lit_sample", reason }))
}

/// Fills the G-buffer's `gaps` from a later sample's camera records of some of them (checked by
/// [`check_gap_streams`]): each pixel whose record resolves to a surface the denoiser sees takes
/// it and leaves `gaps`.
fn fill_gaps(surfaces: &mut [Surface], gaps: &mut Vec<u32>, data: &ShadeData, rays: &RayStream, hits: &HitStream) {
    let mut filled = false;
    for (&pixel, surface) in rays.pixel.iter().zip(resolve(data, rays, hits)) {
        if is_guide_surface(&surface) {
            surfaces[pixel as usize] = surface;
            filled = true;
        }
    }
    if filled {
        gaps.retain(|&pixel| !is_guide_surface(&surfaces[pixel as usize]));
    }
}

/// A lit frame: the image and the samples behind it.
#[derive(Clone, Debug)]
pub struct LitFrame {
    /// Linear RGB radiance per pixel, rows from the top: `emitted + U · den(S_N)/den(U_N)`
    /// (falling back to `U` where `den(U_N) ≈ 0`), every value finite.
    pub color: Vec<Vec3>,
    /// The accumulated estimates; their `timings` also hold the denoiser's passes, after the
    /// stages.
    pub samples: LitSamples,
}

/// Renders a lit frame of `scene` on `backend`: [`shade_samples`], then `settings.denoise` and
/// the composite, all on `backend`. The same preconditions and checks as [`shade_samples`].
///
/// ```
/// use raywave_host::denoise::DenoiseMethod;
/// use raywave_host::lit_frame::{render_lit, LitFrameSettings};
/// use raywave_host::scene::{Camera, Material, Mesh};
/// use raywave_host::shading::ShadeData;
/// use raywave_host::{open_backend, BackendOptions, DeviceChoice, Scene};
/// use glam::Vec3;
///
/// // An engine's own geometry: a floor, a block standing on it and a square lamp above,
/// // facing down (counter-clockwise seen from below); emissive parallelograms are quad lights.
/// let quad = |name: &str, corners: [Vec3; 4], material| Mesh {
///     name: name.into(),
///     positions: corners.to_vec(),
///     triangles: vec![[0, 1, 2], [0, 2, 3]],
///     material,
/// };
/// let floor = quad(
///     "floor",
///     [Vec3::new(-2.0, 0.0, -2.0), Vec3::new(-2.0, 0.0, 2.0), Vec3::new(2.0, 0.0, 2.0), Vec3::new(2.0, 0.0, -2.0)],
///     Material::diffuse(Vec3::splat(0.7)),
/// );
/// let block = quad(
///     "block",
///     [Vec3::new(-0.3, 0.5, -0.3), Vec3::new(-0.3, 0.5, 0.3), Vec3::new(0.3, 0.5, 0.3), Vec3::new(0.3, 0.5, -0.3)],
///     Material { roughness: 0.3, ..Material::diffuse(Vec3::new(0.8, 0.2, 0.2)) },
/// );
/// let lamp = quad(
///     "lamp",
///     [Vec3::new(-0.2, 2.0, -0.2), Vec3::new(0.2, 2.0, -0.2), Vec3::new(0.2, 2.0, 0.2), Vec3::new(-0.2, 2.0, 0.2)],
///     Material { emission: Vec3::splat(20.0), ..Material::diffuse(Vec3::ZERO) },
/// );
/// let camera = Camera {
///     position: Vec3::new(0.0, 3.0, 4.0),
///     look_at: Vec3::ZERO,
///     up: Vec3::Y,
///     vertical_fov_degrees: 45.0,
///     mirrored: false,
/// };
/// let scene = Scene::new("engine scene", vec![floor, block, lamp], camera)?;
/// assert_eq!(scene.lights().len(), 1);
///
/// let mut backend = open_backend(DeviceChoice::Cpu, &BackendOptions::default())?;
/// backend.load_scene(&scene)?;
/// let data = ShadeData::new(&scene)?;
/// let settings = LitFrameSettings { denoise: DenoiseMethod::Tv, ..LitFrameSettings::new(48, 32, 2) };
/// let frame = render_lit(backend.as_mut(), &scene, &data, &settings)?;
/// assert_eq!(frame.color.len(), 48 * 32);
/// assert!(frame.color.iter().all(|c| c.is_finite()));
/// // The floor under the block, at the image's centre, lies in the block's shadow.
/// let lit_floor = frame.color[28 * 48 + 4];
/// let shadowed_floor = frame.color[16 * 48 + 24];
/// assert!(shadowed_floor.length() < 0.5 * lit_floor.length());
/// # Ok::<(), raywave_host::Error>(())
/// ```
pub fn render_lit(
    backend: &mut dyn Backend,
    scene: &Scene,
    data: &ShadeData,
    settings: &LitFrameSettings,
) -> Result<LitFrame> {
    let samples = shade_samples(backend, scene, data, settings)?;
    denoise_samples(backend, settings, samples)
}

/// The second half of [`render_lit`]: `settings.denoise` and the composite of `samples` (what
/// [`shade_samples`] returned for the same `settings`) on `backend`, the denoiser's pass times
/// appended to theirs. Apart, so that a one-off frame can free what its samples kept
/// ([`Backend::release_kept_memory`]) before the denoiser allocates its own. It takes the samples,
/// and an error (the device out of memory, a value the denoiser refuses) drops them: a caller
/// that would rather try another backend or method than sample again calls
/// [`Backend::denoise`] itself with [`LitFrameSettings::denoise_params`] and
/// [`LitSamples::denoise_input`], which borrow them.
pub fn denoise_samples(
    backend: &mut dyn Backend,
    settings: &LitFrameSettings,
    mut samples: LitSamples,
) -> Result<LitFrame> {
    let params = settings.denoise_params(samples.accumulator.samples());
    let (color, reports) = backend.denoise(settings.denoise, &params, &samples.denoise_input())?;
    samples.timings.extend(reports);
    Ok(LitFrame { color: rgb(&color), samples })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::{FrameOutput, MAX_APERTURE_TO_FOCUS};
    use crate::cpu::CpuBackend;
    use crate::lit_sample::LitSample;
    use crate::stream::{HitStream, RayStream, ShadeStream};
    use glam::{UVec2, Vec4};
    use raywave_shared::{SamplerProbeParams, ShadeParams, WarpParams};

    fn rejected_setting(settings: LitFrameSettings) -> &'static str {
        match settings.check_on(&CpuBackend::new()) {
            Err(Error::InvalidParameter { name, .. }) => name,
            other => panic!("expected a typed error, got {other:?}"),
        }
    }

    /// Rays from a lens wider than the Cornell box (radius 3, the box ~1.4 from the camera) reach
    /// everything they would without a `tmax`: with `tmax` twice the camera's distance alone,
    /// rays from the rim stopped short of the back wall.
    #[test]
    fn a_wide_aperture_does_not_cut_rays_short() {
        let scene = Scene::load("builtin:cornell").unwrap();
        let settings = LitFrameSettings { lens_radius: 3.0, ..LitFrameSettings::new(48, 32, 4) };
        let cpu_scene = crate::cpu::CpuScene::build(&scene).unwrap();
        for sample in 0..4 {
            let rays = crate::cpu::generate(&settings.generate_params(&scene, sample)).unwrap();
            let mut unbounded = rays.clone();
            unbounded.direction.iter_mut().for_each(|d| d.w = 1.0e6);
            let [hits, all] = [&rays, &unbounded].map(|r| crate::cpu::trace(&cpu_scene, r).unwrap().hit_count());
            assert!(all > rays.len() / 2 && hits == all, "sample {sample}: {hits} of {all} hits within tmax");
        }
    }

    /// A lit frame is held to the host's memory: at the CPU's 2²⁶-pixel limit it needs 25.5 GB,
    /// refused with both sizes said where less is available; where the footprint or the memory
    /// is unknown, or the frame fits (to the byte), it passes. A frame of a few pixels fits this
    /// machine.
    #[test]
    fn a_lit_frame_is_held_to_the_memory_available() {
        let per_pixel = Some(crate::cpu::LIT_FRAME_BYTES_PER_PIXEL);
        match check_memory_fits(8192, 8192, per_pixel, Some(16 << 30), "cpu (2 threads)") {
            Err(Error::ImageSize { width: 8192, height: 8192, backend, reason }) => {
                assert_eq!(backend, "cpu (2 threads)");
                let expected = "a lit frame needs about 25.5 GB of memory (380 bytes per pixel), more than the 17.2 GB";
                assert!(reason.contains(expected), "{reason}");
            }
            other => panic!("{other:?}"),
        }
        assert!(check_memory_fits(8192, 8192, None, Some(16 << 30), "gpu").is_ok());
        // A GPU's frame is held to the host buffers it keeps (below the CPU's measured peak,
        // which holds them too: a constant assertion beside them): 16384² of them need 68.7 GB,
        // more than a 32 GiB host has.
        let gpu = Some(HOST_LIT_FRAME_BYTES_PER_PIXEL);
        assert!(check_memory_fits(16384, 16384, gpu, Some(32 << 30), "vulkan:0 NVIDIA H200").is_err());
        assert!(check_memory_fits(8192, 8192, gpu, Some(32 << 30), "vulkan:0 NVIDIA H200").is_ok());
        assert!(check_memory_fits(8192, 8192, per_pixel, None, "cpu").is_ok());
        assert!(check_memory_fits(100, 10, Some(380), Some(380_000), "cpu").is_ok());
        assert!(check_memory_fits(100, 10, Some(380), Some(379_999), "cpu").is_err());
        LitFrameSettings::new(64, 32, 4).check_memory(&CpuBackend::new()).unwrap();
    }

    #[test]
    fn each_bad_setting_is_named() {
        let good = LitFrameSettings::new(64, 32, 4);
        good.check_on(&CpuBackend::new()).unwrap();
        let empty = LitFrameSettings::new(0, 32, 4).check_on(&CpuBackend::new());
        assert!(matches!(empty, Err(Error::ImageSize { width: 0, .. })), "{empty:?}");
        // Without a backend: the sides every backend shares and the sampler's index.
        assert!(matches!(LitFrameSettings::new(0, 32, 4).check_size(), Err(Error::ImageSize { width: 0, .. })));
        assert!(matches!(LitFrameSettings::new(65537, 1, 1).check_size(), Err(Error::ImageSize { .. })));
        let overflow = LitFrameSettings::new(65536, 1, 2).check_size();
        assert!(matches!(overflow, Err(Error::InvalidParameter { name: "spp", .. })), "{overflow:?}");
        good.check_size().unwrap();
        assert_eq!(rejected_setting(LitFrameSettings { samples_per_pixel: 0, ..good }), "spp");
        assert_eq!(rejected_setting(LitFrameSettings::new(4096, 4096, 1024)), "spp");
        assert_eq!(rejected_setting(LitFrameSettings::new(65536, 1, 2)), "spp");
        // A longer side is the backend's to refuse, for every sampler, before the samples.
        let too_wide = LitFrameSettings::new(65537, 1, 1).check_on(&CpuBackend::new());
        assert!(matches!(too_wide, Err(Error::ImageSize { width: 65537, .. })), "{too_wide:?}");
        // Only the blue-noise sampler's Morton index limits the samples: the others index any.
        for sampler_kind in [sampler_kind::SOBOL, sampler_kind::INDEPENDENT] {
            let settings = LitFrameSettings { sampler_kind, ..LitFrameSettings::new(65537, 1, 1) };
            assert!(matches!(settings.check_on(&CpuBackend::new()), Err(Error::ImageSize { .. })));
            for (width, height, spp) in [(4096, 4096, 1024), (65536, 1, 2)] {
                let settings = LitFrameSettings { sampler_kind, ..LitFrameSettings::new(width, height, spp) };
                settings.check_on(&CpuBackend::new()).unwrap();
            }
        }
        assert_eq!(rejected_setting(LitFrameSettings { sampler_kind: sampler_kind::COUNT, ..good }), "sampler");
        assert_eq!(rejected_setting(LitFrameSettings { denoise_radius: Some(0), ..good }), "denoise-radius");
        for lens_radius in [-1.0, f32::NAN, 2.0 * MAX_LENS_DISTANCE] {
            assert_eq!(rejected_setting(LitFrameSettings { lens_radius, ..good }), "aperture");
        }
        for focus in [0.0, f32::INFINITY, f32::NAN] {
            assert_eq!(rejected_setting(LitFrameSettings { focus_distance: Some(focus), ..good }), "focus");
        }
        // An aperture wider than `MAX_APERTURE_TO_FOCUS` focus distances (2 here), within the
        // absolute limit: refused where the focus distance is set.
        let focused = LitFrameSettings { focus_distance: Some(2.0), ..good };
        LitFrameSettings { lens_radius: 2.0 * MAX_APERTURE_TO_FOCUS, ..focused }.check().unwrap();
        assert_eq!(
            rejected_setting(LitFrameSettings { lens_radius: 2.1 * MAX_APERTURE_TO_FOCUS, ..focused }),
            "aperture"
        );
    }

    /// The Cornell box, its shade data, and a CPU backend that has loaded it.
    fn cornell_on_the_cpu() -> (Scene, ShadeData, CpuBackend) {
        let scene = Scene::load("builtin:cornell").unwrap();
        let data = ShadeData::new(&scene).unwrap();
        let mut cpu = CpuBackend::new();
        cpu.load_scene(&scene).unwrap();
        (scene, data, cpu)
    }

    /// Focused on the camera's look-at point (0.8 away in the Cornell box), an aperture of
    /// `MAX_APERTURE_TO_FOCUS` look-at distances renders and a wider one is refused, naming the
    /// aperture, before any stage runs: `raywave render --aperture 1e6` had rendered a frame whose
    /// rays missed their focal points by scene-sized amounts.
    #[test]
    fn an_aperture_too_wide_for_the_cameras_focus_is_refused_before_any_work() {
        let (scene, data, mut cpu) = cornell_on_the_cpu();
        let look_at = crate::frame::generate_params(&scene, 4, 4, 0).focus_distance;
        let settings = |lens_radius| LitFrameSettings { lens_radius, ..LitFrameSettings::new(4, 4, 1) };
        settings(1e6).check().unwrap();
        assert!(shade_samples(&mut cpu, &scene, &data, &settings(MAX_APERTURE_TO_FOCUS * look_at)).is_ok());
        match shade_samples(&mut cpu, &scene, &data, &settings(1.01 * MAX_APERTURE_TO_FOCUS * look_at)) {
            Err(Error::InvalidParameter { name: "aperture", reason }) => {
                assert!(reason.contains("the camera's look-at distance"), "{reason}")
            }
            other => panic!("expected the aperture refused, got {other:?}"),
        }
    }

    #[test]
    fn a_backend_without_the_scene_is_an_error_not_a_panic() {
        let scene = Scene::load("builtin:cornell").unwrap();
        let data = ShadeData::new(&scene).unwrap();
        let mut cpu = CpuBackend::new();
        assert!(render_lit(&mut cpu, &scene, &data, &LitFrameSettings::new(8, 8, 1)).is_err());
    }

    #[test]
    fn reports_add_up_by_stage_in_first_seen_order() {
        let mut totals = Vec::new();
        for report in [
            StageReport::once("trace", 1.0, 2),
            StageReport::clean("shade", 0.5),
            StageReport { dispatches: 3, ..StageReport::once("trace", 0.25, 1) },
        ] {
            StageReport::add_to(&mut totals, &report);
        }
        assert_eq!(
            totals,
            [StageReport { dispatches: 4, ..StageReport::once("trace", 1.25, 3) }, StageReport::clean("shade", 0.5)]
        );
    }

    #[test]
    fn samples_count_hits_resolve_the_g_buffer_and_draw_their_own_points() {
        let (scene, data, mut cpu) = cornell_on_the_cpu();
        let settings = LitFrameSettings::new(16, 12, 3);
        let samples = shade_samples(&mut cpu, &scene, &data, &settings).unwrap();
        assert_eq!(samples.accumulator.samples(), 3);
        assert_eq!(samples.surfaces.len(), 16 * 12);
        // Where the first sample's ray hit a surface, the G-buffer holds it (gaps are filled from
        // later samples: `tests/parity_lit_sample.rs`, on every backend).
        let first = cpu.render(&settings.generate_params(&scene, 0)).unwrap();
        let first_surfaces = resolve(&data, &first.rays, &first.hits);
        let kept = samples.surfaces.iter().zip(&first_surfaces).filter(|(_, first)| is_guide_surface(first));
        assert!(kept.clone().count() > 16 * 12 / 2 && kept.into_iter().all(|(s, first)| s == first));
        assert!(samples.hits > 0 && samples.hits <= 3 * 16 * 12);
        let stages: Vec<_> = samples.timings.iter().map(|t| t.stage).collect();
        assert_eq!(stages, ["generate", "trace", "shade", "occlusion"]);
        assert!(samples.timings.iter().all(|t| t.dispatches == 3 && t.sanitized == 0));

        // Each sample draws its own camera rays and shadow rays: the sums are those of passes
        // rendered and shaded with their own sample indices, which a pass that repeated another's
        // index in generate or in shade would not match.
        let mut expected = ShadeAccumulator::new(16 * 12);
        let (mut hits, mut stream_bytes) = (0, 0);
        for index in 0..3 {
            let rendered = cpu.render(&settings.generate_params(&scene, index)).unwrap();
            let params = data.params(settings.sampler(), 16, 12, index);
            let (_, pass_bytes) =
                expected.shade_pass(&mut cpu, &params, &data, &rendered.rays, &rendered.hits).unwrap();
            hits += rendered.hits.hit_count();
            stream_bytes = rendered.rays.bytes() + rendered.hits.bytes() + pass_bytes;
        }
        // The counts `raywave render` reports: every sample's hits, and one sample's streams
        // (rays, hits, the shade stream, shadow rays, occlusion).
        assert_eq!((samples.hits, samples.stream_bytes), (hits, stream_bytes));
        let frame = &samples.accumulator;
        assert_eq!((frame.analytic(), frame.unshadowed()), (expected.analytic(), expected.unshadowed()));
        assert_eq!(frame.shadowed(), expected.shadowed());
        // And the passes differ: the same index three times would give every sum three equal terms.
        let mut repeated = ShadeAccumulator::new(16 * 12);
        let params = data.params(settings.sampler(), 16, 12, 0);
        repeated.shade_pass(&mut cpu, &params, &data, &first.rays, &first.hits).unwrap();
        assert_ne!(frame.unshadowed(), repeated.unshadowed());
    }

    /// The settings reach the stages' parameters: the lens (aperture and the focus distance,
    /// which otherwise is the camera's look-at distance) and the seed, which draws the samples
    /// and the noise estimate's line angles.
    #[test]
    fn the_lens_and_the_seed_reach_the_stages() {
        let scene = Scene::load("builtin:cornell").unwrap();
        let pinhole = LitFrameSettings::new(16, 12, 2);
        let look_at = crate::frame::generate_params(&scene, 16, 12, 0).focus_distance;
        assert_eq!(pinhole.generate_params(&scene, 1).focus_distance, look_at);
        let lens = LitFrameSettings { lens_radius: 0.05, focus_distance: Some(2.5), seed: 7, ..pinhole };
        let params = lens.generate_params(&scene, 1);
        assert_ne!(look_at, 2.5);
        assert_eq!((params.lens_radius, params.focus_distance, params.sampler.seed), (0.05, 2.5, 7));
        assert_eq!((lens.denoise_params(2).seed, lens.denoise_params(2).samples_per_pixel), (7, 2));
    }

    /// How an engine's backend [`Faulty`] gets its streams wrong.
    #[derive(Clone, Copy, Debug)]
    enum Fault {
        /// Its frames hold one hit fewer than they generated rays.
        ShortHits,
        /// Its lit samples' camera streams hold one hit fewer than rays (the sample itself sound).
        ShortCameraHits,
        /// Its first lit sample returns no camera streams.
        NoCameraStreams,
        /// Its lit samples return every camera record where those of the G-buffer's gaps that
        /// hit were asked for.
        WholeFrameForGaps,
    }

    /// An engine's backend with a [`Fault`]: the CPU backend otherwise.
    struct Faulty(CpuBackend, Fault);

    /// The hit stream one record shorter.
    fn drop_last_hit(hits: &mut HitStream) {
        let kept = hits.len() - 1;
        hits.t.truncate(kept);
        hits.primitive.truncate(kept);
        hits.instance.truncate(kept);
        hits.barycentrics.truncate(kept);
    }

    impl Backend for Faulty {
        fn name(&self) -> String {
            format!("{:?}", self.1)
        }
        fn check_image_size(&self, width: u32, height: u32) -> Result<()> {
            self.0.check_image_size(width, height)
        }
        fn lit_frame_bytes_per_pixel(&self) -> Option<u64> {
            self.0.lit_frame_bytes_per_pixel()
        }
        fn set_sustain_seconds(&mut self, seconds: f64) -> Result<()> {
            self.0.set_sustain_seconds(seconds)
        }
        fn load_scene(&mut self, scene: &Scene) -> Result<()> {
            self.0.load_scene(scene)
        }
        fn generate(&mut self, params: &GenerateParams) -> Result<(RayStream, StageReport)> {
            self.0.generate(params)
        }
        fn trace(&mut self, rays: &RayStream) -> Result<(HitStream, StageReport)> {
            self.0.trace(rays)
        }
        fn trace_occlusion(&mut self, rays: &RayStream) -> Result<(Vec<u32>, StageReport)> {
            self.0.trace_occlusion(rays)
        }
        fn shade(
            &mut self,
            params: &ShadeParams,
            data: &ShadeData,
            rays: &RayStream,
            hits: &HitStream,
        ) -> Result<(ShadeStream, StageReport)> {
            self.0.shade(params, data, rays, hits)
        }
        fn denoise(
            &mut self,
            method: DenoiseMethod,
            params: &DenoiseParams,
            input: &DenoiseInput,
        ) -> Result<(Vec<Vec4>, Vec<StageReport>)> {
            self.0.denoise(method, params, input)
        }
        fn copy_probe(&mut self, params: &DenoiseParams, image: &[Vec4]) -> Result<(Vec<Vec4>, StageReport)> {
            self.0.copy_probe(params, image)
        }
        fn render(&mut self, params: &GenerateParams) -> Result<FrameOutput> {
            let mut frame = self.0.render(params)?;
            if let Fault::ShortHits = self.1 {
                drop_last_hit(&mut frame.hits);
            }
            Ok(frame)
        }
        fn lit_sample(&mut self, request: &LitSampleRequest<'_>) -> Result<LitSample> {
            let whole = LitSampleRequest { camera: CameraStreams::All, ..*request };
            let asked_gaps = matches!(request.camera, CameraStreams::HitsAmong(_));
            let faulty_request =
                if asked_gaps && matches!(self.1, Fault::WholeFrameForGaps) { &whole } else { request };
            let mut sample = crate::lit_sample::compose(self, faulty_request)?;
            match self.1 {
                Fault::ShortHits | Fault::WholeFrameForGaps => {}
                Fault::ShortCameraHits => sample.camera.iter_mut().for_each(|(_, hits)| drop_last_hit(hits)),
                Fault::NoCameraStreams => sample.camera = None,
            }
            Ok(sample)
        }
        fn sampler_probe(&mut self, params: &SamplerProbeParams) -> Result<Vec<UVec2>> {
            self.0.sampler_probe(params)
        }
        fn warp_probe(&mut self, params: &WarpParams) -> Result<Vec<Vec4>> {
            self.0.warp_probe(params)
        }
    }

    /// A backend an engine wrote that returns fewer hits than rays, a lit sample without the
    /// camera streams the G-buffer is resolved from, or records of pixels that were not asked
    /// for, gets a typed error from `shade_samples` naming the stage: the streams are checked
    /// before the G-buffer's resolve step, which indexes the hits by ray, reads them (the shade
    /// pass checks a frame's; `shade_samples` the camera streams a lit sample returns, which
    /// need not be the ones it shaded).
    #[test]
    fn a_backend_returning_too_few_hits_is_an_error_not_a_panic() {
        let faults = [
            (Fault::ShortHits, "shade", "64 rays but 63 hits", "builtin:cornell"),
            (Fault::ShortCameraHits, "shade", "64 rays but 63 hits", "builtin:cornell"),
            (Fault::NoCameraStreams, "lit_sample", "returned no camera streams", "builtin:cornell"),
            // The spheres stand against the sky: the first sample leaves gaps.
            (Fault::WholeFrameForGaps, "lit_sample", "which was not asked for", "builtin:spheres"),
        ];
        for (fault, stage, why, scene) in faults {
            let scene = Scene::load(scene).unwrap();
            let data = ShadeData::new(&scene).unwrap();
            let mut faulty = Faulty(CpuBackend::new(), fault);
            faulty.load_scene(&scene).unwrap();
            match shade_samples(&mut faulty, &scene, &data, &LitFrameSettings::new(8, 8, 2)) {
                Err(Error::InvalidParameter { name, reason }) => {
                    assert_eq!(name, stage, "{fault:?}: {reason}");
                    assert!(reason.contains(why), "{fault:?}: {reason}");
                }
                other => panic!("{fault:?}: {:?}", other.map(|_| "accepted")),
            }
        }
    }
}
