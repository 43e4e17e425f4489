//! What every execution backend offers: the stages over host streams, and a whole frame that
//! keeps the streams on the backend between stages.

use crate::denoise::{DenoiseInput, DenoiseMethod};
use crate::error::Result;
use crate::lit_sample::{LitSample, LitSampleRequest};
use crate::scene::{Scene, SceneIdentity};
use crate::shading::ShadeData;
use crate::stream::{check_one_hit_per_ray, HitStream, RayStream, ShadeStream};
use glam::{UVec2, Vec4};
use rayon::prelude::*;
use raywave_shared::sampling::{sampler_kind, warp_kind};
use raywave_shared::{DenoiseParams, GenerateParams, SamplerParams, SamplerProbeParams, ShadeParams, WarpParams};
use std::sync::{Arc, Mutex};

/// What one run of a stage (or denoise pass) on a backend reports: its time, and how many of its
/// invocations had to replace a non-finite value (DESIGN rule 5).
#[derive(Clone, Debug, PartialEq)]
pub struct StageReport {
    /// Stage name (`generate`, `trace`, …).
    pub stage: &'static str,
    /// Seconds per dispatch: on Vulkan the stage's run's time over `dispatches`, from the GPU
    /// timestamps around it where the device writes them (`DeviceInfo::timestamps`), else from
    /// the host clock around its submission, which then holds that run alone; the wall clock of
    /// the parallel loop on the CPU.
    pub seconds: f64,
    /// How many times the stage's kernel ran back to back in its run: 1, except on
    /// a Vulkan backend opened for benchmarking (`ContextOptions::sustain_seconds`), where the
    /// repetitions keep the GPU busy enough to hold its clocks; always 1 on the CPU.
    pub dispatches: u32,
    /// Invocations that replaced a non-finite value — read (a NaN ray, a NaN hit record) or
    /// computed (an overflowing sum) — so that nothing non-finite left the stage: rays or hits
    /// for trace and occlusion, samples for shade, pixels for the composites; always 0 for the
    /// stages and passes that cannot meet one (generate's parameters are checked, the denoiser's
    /// inputs too). Sound input gives 0, which the tests assert; the same input gives the same
    /// count on every backend.
    pub sanitized: u64,
}

impl StageReport {
    /// A report of one run of `stage` that took `seconds` and sanitized `sanitized` invocations.
    pub fn once(stage: &'static str, seconds: f64, sanitized: u64) -> Self {
        Self { stage, seconds, dispatches: 1, sanitized }
    }

    /// A report of one run of `stage` that took `seconds` and sanitized nothing.
    pub fn clean(stage: &'static str, seconds: f64) -> Self {
        Self::once(stage, seconds, 0)
    }

    /// The sanitized counts of `reports` (a frame's stages, a denoiser's passes), summed.
    pub fn total_sanitized(reports: &[StageReport]) -> u64 {
        reports.iter().map(|r| r.sanitized).sum()
    }

    /// Adds `report` to its stage's entry of `totals` — seconds, sanitized values and timed
    /// dispatches — appending the entry the first time its stage appears: a frame's reports
    /// summed over its samples, in execution order.
    pub fn add_to(totals: &mut Vec<StageReport>, report: &StageReport) {
        match totals.iter_mut().find(|t| t.stage == report.stage) {
            Some(total) => {
                total.seconds += report.seconds;
                total.sanitized += report.sanitized;
                total.dispatches += report.dispatches;
            }
            None => totals.push(report.clone()),
        }
    }
}

/// The result of one frame: the streams the last stage produced and the time of each stage.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameOutput {
    /// The generated rays (read back for visualisation and tests).
    pub rays: RayStream,
    /// The closest hit of each ray.
    pub hits: HitStream,
    /// Per-stage timings in execution order.
    pub timings: Vec<StageReport>,
}

/// Checks benchmark mode's busy time per timed submission ([`Backend::set_sustain_seconds`]):
/// within 0..=1 s, on every backend, whether or not it uses it.
pub(crate) fn check_sustain_seconds(seconds: f64) -> Result<f64> {
    if (0.0..=1.0).contains(&seconds) {
        Ok(seconds)
    } else {
        Err(crate::error::Error::InvalidParameter {
            name: "sustain_seconds",
            reason: format!("{seconds} is not within 0..=1 s"),
        })
    }
}

/// The validation messages of warning or error severity one Vulkan backend received, in arrival
/// order, shared with it: still readable after the backend is dropped, when the messages its
/// teardown raised (objects left alive at `vkDestroyDevice`, say) have arrived too.
#[derive(Clone, Debug, Default)]
pub struct ValidationLog(pub(crate) Arc<Mutex<Vec<String>>>);

impl ValidationLog {
    /// The messages received so far.
    pub fn messages(&self) -> Vec<String> {
        self.0.lock().map(|m| m.clone()).unwrap_or_default()
    }
}

/// An execution backend: the CPU executor or a Vulkan device.
///
/// `Send`, so that an engine can move a backend (the `Box<dyn Backend>` of
/// [`crate::open_backend`]) to its render thread; a backend is used by one thread at a time
/// (its methods take `&mut self`).
pub trait Backend: Send {
    /// Human-readable name, e.g. `cpu (2 threads)` or `vulkan:0 llvmpipe (…)`.
    fn name(&self) -> String;

    /// Checks that a `width × height` image fits this backend's limits.
    fn check_image_size(&self, width: u32, height: u32) -> Result<()>;

    /// Host memory, bytes per pixel, that a lit frame ([`crate::lit_frame`]: its sample passes
    /// one at a time, their sums, the G-buffer, the denoiser and the images written) holds at its
    /// peak on this backend, as measured — on a Vulkan GPU, whose streams live in device memory,
    /// not measured: at least [`crate::lit_frame::HOST_LIT_FRAME_BYTES_PER_PIXEL`]; `None` where
    /// not known at all. [`crate::lit_frame::LitFrameSettings::check_memory`] holds an image to
    /// it.
    fn lit_frame_bytes_per_pixel(&self) -> Option<u64>;

    /// Benchmark mode from the next stage on, as `BackendOptions::sustain_seconds` sets it at
    /// open: each timed Vulkan submission repeats its dispatch to keep the GPU busy about
    /// `seconds` (0..=1; 0 runs every stage once), so that a measurement can be sustained while
    /// the work around it (a many-sample reference image) runs once. The CPU backend checks it
    /// and otherwise ignores it.
    fn set_sustain_seconds(&mut self, seconds: f64) -> Result<()>;

    /// Builds the acceleration structures for `scene` and records its [`Scene::identity`]; later
    /// `trace` calls run against it, and `shade` takes only [`ShadeData`] built from it (or a
    /// clone of it). A scene refused here leaves the loaded one in place (on Vulkan, a failure to
    /// allocate its device memory leaves none loaded).
    fn load_scene(&mut self, scene: &Scene) -> Result<()>;

    /// Runs the generate stage.
    fn generate(&mut self, params: &GenerateParams) -> Result<(RayStream, StageReport)>;

    /// Runs the trace stage on `rays` against the loaded scene.
    fn trace(&mut self, rays: &RayStream) -> Result<(HitStream, StageReport)>;

    /// Runs the occlusion variant of the trace stage on `rays`: 1 per ray blocked within its
    /// interval, 0 otherwise (shadow rays).
    fn trace_occlusion(&mut self, rays: &RayStream) -> Result<(Vec<u32>, StageReport)>;

    /// Runs the shade stage: resolves each camera ray's hit (`rays[i]`, `hits[i]`, pixel `i` of a
    /// `params.width`-wide image) into a surface of `data`'s scene and shades one sample of it.
    /// The streams are dense, one ray per pixel in pixel order as the generate stage writes them:
    /// `rays.pixel[i]` must be `i` (a compacted stream, misses dropped, is refused naming the
    /// first ray out of place — its samples would have been drawn for the wrong pixels), and
    /// `params.count` must equal the number of rays and of hits. With a scene loaded, `data` must
    /// be built from it ([`ShadeData::check_scene`]: [`crate::Error::SceneMismatch`] otherwise);
    /// without one (hits from an engine's own trace) any scene's data is taken. Every check is
    /// [`check_shade_inputs`]'s. Backends that keep `data` on a device upload it once and reuse
    /// it while the same `data` is passed (see [`ShadeData::identity`]).
    fn shade(
        &mut self,
        params: &ShadeParams,
        data: &ShadeData,
        rays: &RayStream,
        hits: &HitStream,
    ) -> Result<(ShadeStream, StageReport)>;

    /// Runs denoiser `method` on `input` (a `params.width × params.height` image): every pass
    /// on this backend. Returns the colour image (rgb; w = 1) and each pass's time.
    fn denoise(
        &mut self,
        method: DenoiseMethod,
        params: &DenoiseParams,
        input: &DenoiseInput,
    ) -> Result<(Vec<Vec4>, Vec<StageReport>)>;

    /// Runs the copy probe: `image` (one `Vec4` per pixel of `params`' image, checked by
    /// [`copy_probe_len`]) read and written to another buffer by a per-pixel pass that does
    /// nothing else, run as the denoise passes are (`raywave_kernels::entry::copy_probe` on
    /// Vulkan, the same parallel loop over pixels on the CPU). Returns the copy (bit-identical)
    /// and its time: the least a per-pixel pass over `Vec4` images can take on this backend, the
    /// memory roof `raywave bench denoise` compares each pass's bandwidth with.
    fn copy_probe(&mut self, params: &DenoiseParams, image: &[Vec4]) -> Result<(Vec<Vec4>, StageReport)>;

    /// Runs generate → trace as one frame, keeping the ray stream on the backend in between.
    fn render(&mut self, params: &GenerateParams) -> Result<FrameOutput>;

    /// Runs one lit sample — generate → trace → shade → occlusion trace — and returns what the
    /// accumulator adds up ([`LitSample`]), with the checks and errors of those stage calls. By
    /// default it is [`crate::lit_sample::compose`] of them, every stream passing through the
    /// host; a backend may keep the streams on its device in between (the Vulkan backend does),
    /// giving the same values bit for bit.
    fn lit_sample(&mut self, request: &LitSampleRequest<'_>) -> Result<LitSample> {
        crate::lit_sample::compose(self, request)
    }

    /// Runs the sampler probe: the raw bits of every sample `params` covers, in invocation order
    /// (bit-identical on every backend).
    fn sampler_probe(&mut self, params: &SamplerProbeParams) -> Result<Vec<UVec2>>;

    /// Runs the warp probe: `params.count` warped directions (xyz) with their pdfs (w).
    fn warp_probe(&mut self, params: &WarpParams) -> Result<Vec<Vec4>>;

    /// Frees the working memory this backend keeps between calls for the next one to take again,
    /// and returns its bytes. On Vulkan that is the streams, images, counters and staging buffers
    /// of the calls before (README, Architecture: kept within twice the most in use at once, and
    /// until later calls age them out), device memory that an engine's frame loop reuses every
    /// frame but a one-off frame no longer needs once its samples are in, or that an engine
    /// pausing its ray tracing wants back without closing the backend and its loaded scene. The
    /// next call makes what it needs afresh. The CPU backend keeps nothing: 0.
    fn release_kept_memory(&mut self) -> u64 {
        0
    }

    /// The log of this backend's validation-layer messages, which outlives it
    /// ([`crate::device::close_backend`] reads it after the drop). `None` for a backend without
    /// validation layers (the CPU); a Vulkan backend's log stays empty unless it was opened with
    /// validation.
    fn validation_log(&self) -> Option<ValidationLog> {
        None
    }
}

/// Largest probe (samples of the sampler or warp probe) any backend runs: 2²⁴ samples.
pub const MAX_PROBE_SAMPLES: u64 = 1 << 24;

/// Number of samples the sampler probe `params` covers, checked against [`MAX_PROBE_SAMPLES`] and
/// the sampler's own index space.
pub fn sampler_probe_len(params: &SamplerProbeParams) -> Result<u32> {
    let pixels = u64::from(params.width) * u64::from(params.height);
    let spp_log2 = params.sampler.spp_log2;
    let samples_per_pixel = (spp_log2 < 32).then(|| 1u64 << spp_log2);
    let count = samples_per_pixel.and_then(|spp| pixels.checked_mul(spp)).filter(|&count| count <= MAX_PROBE_SAMPLES);
    check_sampler("sampler probe", &params.sampler, params.width, params.height, 1)?;
    match count {
        // At most MAX_PROBE_SAMPLES = 2²⁴: a u32.
        Some(count) => Ok(count as u32),
        None => Err(crate::error::Error::InvalidParameter {
            name: "sampler probe",
            reason: format!(
                "{}×{} pixels at 2^{} samples exceed {MAX_PROBE_SAMPLES} samples",
                params.width, params.height, params.sampler.spp_log2
            ),
        }),
    }
}

/// Checks that `sampler` is of a known kind ([`sampler_kind`]: the kernels draw any other as
/// `ZSOBOL`) and gives samples `0..sample_count` of every pixel of a `width × height` image their
/// own points ([`SamplerParams::indexes`]); `name` names the stage in the error.
fn check_sampler(
    name: &'static str,
    sampler: &SamplerParams,
    width: u32,
    height: u32,
    sample_count: u32,
) -> Result<()> {
    if sampler.kind >= sampler_kind::COUNT {
        return Err(crate::error::Error::InvalidParameter {
            name,
            reason: format!("sampler kind {} is not one of 0..{}", sampler.kind, sampler_kind::COUNT),
        });
    }
    if sampler.indexes(width, height, sample_count) {
        return Ok(());
    }
    Err(crate::error::Error::InvalidParameter {
        name,
        reason: format!(
            "the ZSOBOL sampler's space (a 2^{} square, 2^{} samples a pixel) repeats points for {sample_count} \
             samples of a {width}×{height} image (see SamplerParams::indexes)",
            sampler.resolution_log2, sampler.spp_log2
        ),
    })
}

/// Number of samples the warp probe `params` covers (sample `i` of pixel (0, 0)), checked against
/// [`MAX_PROBE_SAMPLES`] and the sampler's index space, and its warp kind against
/// [`warp_kind::COUNT`] (an unknown kind had returned zeros with `Ok`).
pub fn warp_probe_len(params: &WarpParams) -> Result<u32> {
    if params.kind >= warp_kind::COUNT {
        return Err(crate::error::Error::InvalidParameter {
            name: "warp probe",
            reason: format!("warp kind {} is not one of 0..{}", params.kind, warp_kind::COUNT),
        });
    }
    check_sampler("warp probe", &params.sampler, 1, 1, params.count)?;
    if u64::from(params.count) <= MAX_PROBE_SAMPLES {
        Ok(params.count)
    } else {
        Err(crate::error::Error::InvalidParameter {
            name: "warp probe",
            reason: format!("{} samples exceed {MAX_PROBE_SAMPLES}", params.count),
        })
    }
}

/// Number of pixels of the copy probe's `image`: `params`' image, not empty, one entry each.
pub fn copy_probe_len(params: &DenoiseParams, image: &[Vec4]) -> Result<u32> {
    let pixels = u64::from(params.width) * u64::from(params.height);
    match u32::try_from(pixels) {
        Ok(pixels) if pixels > 0 && image.len() as u64 == u64::from(pixels) => Ok(pixels),
        _ => Err(crate::error::Error::InvalidParameter {
            name: "copy probe",
            reason: format!("{}×{} pixels but an image of {} entries", params.width, params.height, image.len()),
        }),
    }
}

/// Checks the inputs of the shade stage every backend shares, for an engine's own [`Backend`]
/// too: `data` built from `loaded`, the scene the backend has loaded, if any
/// ([`ShadeData::check_scene`]), the data itself ([`ShadeData::check`]), streams whose fields
/// agree in length, one hit per ray, [`check_shade_params`] — `params.count` rays, a width ≥ 1,
/// light and node counts within the data's buffers (a count past its buffer was clamped to it by
/// the kernels — on the CPU to the slice, on Vulkan to the buffer, which holds one zeroed element
/// where the slice is empty — so the backends would have shaded different light sets), and a
/// sampler of a known kind that gives the sample its own point in every pixel
/// ([`SamplerParams::indexes`]) —, then dense rays (`rays.pixel[i] = i`: the stage shades
/// invocation `i` as pixel `(i mod width, i div width)` and ignores the field). Errors name the
/// stage (`shade`) and the field at fault.
pub fn check_shade_inputs(
    params: &ShadeParams,
    data: &ShadeData,
    loaded: Option<&SceneIdentity>,
    rays: &RayStream,
    hits: &HitStream,
) -> Result<()> {
    data.check_scene(loaded)?;
    data.check()?;
    check_shade_streams(params, data, rays, hits)
}

/// The checks of [`check_shade_inputs`] after the data's own: the streams, one hit per ray,
/// [`check_shade_params`] (cheap, and the more basic fault), then dense rays. For callers that
/// have checked `data` already (a lit frame checks the camera streams a backend returned before
/// resolving its G-buffer).
pub(crate) fn check_shade_streams(
    params: &ShadeParams,
    data: &ShadeData,
    rays: &RayStream,
    hits: &HitStream,
) -> Result<()> {
    check_one_hit_per_ray(rays, hits, "shade")?;
    check_shade_params(params, data, hits.len())?;
    #[cfg(feature = "vulkan")]
    crate::vulkan::driver_lock::debug_assert_unheld("the shade stage's dense-stream check (rayon)");
    match rays.pixel.par_iter().enumerate().position_first(|(i, &pixel)| pixel as usize != i) {
        Some(i) => Err(shade_error(format!(
            "rays.pixel[{i}] = {}: the stage takes dense streams, ray i for pixel i as generate writes them \
             (a compacted stream would shade its samples for the wrong pixels)",
            rays.pixel[i]
        ))),
        None => Ok(()),
    }
}

/// The shade stage's refusal of its inputs, for `reason`.
fn shade_error(reason: String) -> crate::error::Error {
    crate::error::Error::InvalidParameter { name: "shade", reason }
}

/// The checks of [`check_shade_inputs`] that need no streams, for a dense pass of `count` camera
/// rays — as the generate stage writes them, one per pixel in pixel order, which a backend that
/// keeps them on its device ([`Backend::lit_sample`]) takes as they are: `params.count` equal to
/// `count`, a width of at least 1, light and node counts within the data's buffers and the
/// sampler. `data` itself is checked by the caller ([`ShadeData::check_scene`],
/// [`ShadeData::check`]). Errors name the stage (`shade`) and the field at fault.
pub fn check_shade_params(params: &ShadeParams, data: &ShadeData, count: usize) -> Result<()> {
    let reason = if params.count as usize != count {
        Some(format!("params.count = {} but {count} rays", params.count))
    } else if params.width == 0 {
        Some("params.width must be at least 1".to_owned())
    } else if params.light_count as usize > data.lights.len() {
        Some(format!("params.light_count = {} but the data has {} lights", params.light_count, data.lights.len()))
    } else if params.light_node_count != 0 && params.light_node_count as usize != data.light_nodes.len() {
        // Part of a tree cuts off the lights beyond it: never drawn, though `U` counts them.
        Some(format!(
            "params.light_node_count = {} but the data has {} light BVH nodes (all or none)",
            params.light_node_count,
            data.light_nodes.len()
        ))
    } else {
        None
    };
    match reason {
        Some(reason) => Err(shade_error(reason)),
        // Invocation i shades pixel (i mod width, i div width).
        None => {
            let height = params.count.div_ceil(params.width);
            check_sampler("shade", &params.sampler, params.width, height, params.sample_index.saturating_add(1))
        }
    }
}

/// Largest length of the generate stage's `right` and `up` axes (the tangents of half the field
/// of view, times the aspect ratio for `right`): with a unit `forward` orthogonal to them, a
/// pixel's pinhole direction `forward + x·right + y·up` then has a squared length in
/// [1, (1 + 2·10¹⁸)²], which `f32` holds, so it normalizes to a finite unit vector.
pub const MAX_IMAGE_PLANE_AXIS: f32 = 1e18;

/// Least squared length of the generate stage's `right` and `up` axes: a normal float (lengths
/// from ~1.1·10⁻¹⁹), so that they normalize — the thin lens does — and can be judged orthogonal
/// to `forward`.
pub const MIN_IMAGE_PLANE_AXIS_SQUARED: f32 = f32::MIN_POSITIVE;

/// Largest thin-lens aperture radius as a multiple of the focus distance. A ray from the lens's
/// rim is aimed at its point on the focal plane along a direction rounded to `f32`, so it misses
/// that point by about 1.2·10⁻⁷ of the focus distance per unit of this ratio (measured:
/// `thin_lens_rays_meet_their_focal_point_up_to_the_aperture_limit`; the generate stage takes
/// the lens and focal points relative to the camera, so far from the origin too, where only the
/// ray's start rounds to the camera position's `f32` grid). Under the old limit alone
/// (an aperture of 10⁸ scene units), `raywave render --aperture 1e6 … 1e8` on the Cornell box
/// (focus 0.8) missed by scene-sized amounts: the share of camera rays that hit drifted from 73 %
/// to 32 %, and the CPU and lavapipe's ray query disagreed on 13 % of the rays at 10⁷, nothing
/// counted. At 10³ the miss is 1.2·10⁻⁴ of the focus distance — a pixel of the focal plane at
/// 8192 pixels across a 53° view — and the f-number `f/2R`, 5·10⁻⁴, is beyond any lens.
pub const MAX_APERTURE_TO_FOCUS: f32 = 1e3;

/// Why a thin lens of aperture radius `lens_radius` focused at `focus_distance` is refused — it
/// is wider than [`MAX_APERTURE_TO_FOCUS`] focus distances —, or `None` (a pinhole always
/// passes; non-finite values are other checks' to refuse).
pub fn aperture_refusal(lens_radius: f32, focus_distance: f32) -> Option<String> {
    let widest = MAX_APERTURE_TO_FOCUS * focus_distance;
    (lens_radius > 0.0 && (lens_radius > widest || widest.is_nan())).then(|| {
        format!(
            "{lens_radius} exceeds {MAX_APERTURE_TO_FOCUS:e} × the focus distance {focus_distance}: rays from the \
             lens's rim would miss their points on the plane in focus by the f32 rounding of their directions"
        )
    })
}

/// Relative tolerance of the camera basis' documented shape ([`GenerateParams`]): `|forward|`
/// within this of 1, `right`, `up` orthogonal to it within this fraction of their length, and
/// to each other within this cosine — far above the rounding of a basis built from normalized
/// cross products (~10⁻⁷).
const CAMERA_BASIS_TOLERANCE: f32 = 1e-3;

/// Checks generate-stage parameters beyond the image size (which each backend checks against its
/// own limit): a finite camera basis of the shape [`GenerateParams`]' fields document — a unit
/// `forward`, `right` and `up` orthogonal to it and to each other, long enough to normalize
/// (squared length a normal float, ~10⁻¹⁹), within [`MAX_IMAGE_PLANE_AXIS`] (a zeroed basis gave
/// NaN ray directions, a 10⁻³⁰ one infinite ones, a 10¹⁹ one zero ones, and a slanted image
/// plane, `right` and `up` 1000 long at 0.06° from each other, a zero direction at its corner) —,
/// `0 ≤ tmin < tmax` finite, a finite non-negative aperture with a positive finite focus distance
/// when it is open, at most [`MAX_APERTURE_TO_FOCUS`] times it, and a thin lens within
/// `f32::MAX / 4` of the origin, and a sampler of a known
/// kind that gives the sample its own point ([`SamplerParams::indexes`]). Every backend's
/// `generate` and `render` call it, beside its own image-size check; an engine's own [`Backend`]
/// can too. Errors name the stage (`generate`).
pub fn check_generate_params(params: &GenerateParams) -> Result<()> {
    let basis = [params.origin, params.forward, params.right, params.up];
    let (forward, right, up) = (params.forward.truncate(), params.right.truncate(), params.up.truncate());
    // Long enough to normalize (the thin lens does) and to be judged, at most the bound, and
    // orthogonal to `forward`.
    let usable = |axis: glam::Vec3| {
        axis.length_squared() >= MIN_IMAGE_PLANE_AXIS_SQUARED
            && axis.length() <= MAX_IMAGE_PLANE_AXIS
            && axis.dot(forward).abs() <= CAMERA_BASIS_TOLERANCE * axis.length()
    };
    // The thin lens's points (origin, aperture, focal point) in f64, so that the check itself
    // cannot overflow.
    let lens_reach = f64::from(params.origin.truncate().abs().max_element())
        + f64::from(params.lens_radius)
        + f64::from(params.focus_distance) * (1.0 + f64::from(right.length()) + f64::from(up.length()));
    let reason = if !basis.iter().all(|v| v.is_finite()) {
        Some("the camera's origin, forward, right and up must be finite".to_owned())
    } else if (forward.length() - 1.0).abs() > CAMERA_BASIS_TOLERANCE {
        Some(format!("the camera's forward axis must be a unit vector (length {})", forward.length()))
    } else if !(usable(right) && usable(up)) || right.normalize().dot(up.normalize()).abs() > CAMERA_BASIS_TOLERANCE {
        Some(format!(
            "the camera's right and up axes must be orthogonal to forward and to each other, and between 1e-19 \
             and {MAX_IMAGE_PLANE_AXIS:e} long (right {right}, up {up})"
        ))
    } else if !(params.tmin >= 0.0 && params.tmax > params.tmin && params.tmax.is_finite()) {
        Some(format!("needs 0 ≤ tmin < tmax, both finite (tmin {}, tmax {})", params.tmin, params.tmax))
    } else if !(params.lens_radius.is_finite() && params.lens_radius >= 0.0) {
        Some(format!("lens_radius {} must be finite and ≥ 0", params.lens_radius))
    } else if params.lens_radius > 0.0 && !(params.focus_distance.is_finite() && params.focus_distance > 0.0) {
        Some(format!("focus_distance {} must be finite and > 0 with an aperture", params.focus_distance))
    } else if let Some(reason) = aperture_refusal(params.lens_radius, params.focus_distance) {
        Some(format!("lens_radius {reason}"))
    } else if params.lens_radius > 0.0 && lens_reach > f64::from(f32::MAX) / 4.0 {
        Some(format!(
            "the thin lens reaches {lens_reach:e} from the origin (camera origin, aperture {}, focal plane at {}), \
             beyond f32::MAX / 4, where its points' differences overflow",
            params.lens_radius, params.focus_distance
        ))
    } else {
        None
    };
    match reason {
        Some(reason) => Err(crate::error::Error::InvalidParameter { name: "generate", reason }),
        None => check_sampler(
            "generate",
            &params.sampler,
            params.width,
            params.height,
            params.sample_index.saturating_add(1),
        ),
    }
}

/// Longest image side every backend accepts, in pixels. The generate stage places a ray at
/// `(x + jitter) / width` in `f32`, whose 24-bit significand keeps sub-pixel steps of 2⁻⁸ pixel
/// up to this side but only whole pixels from 2²³ on, and rounds neighbouring pixels onto one
/// ray from 2²⁴ on; the blue-noise sampler's Morton index covers no longer side either.
pub const MAX_IMAGE_SIDE: u32 = 1 << 16;

/// Checks the size rules every backend shares: both sides within `1..=`[`MAX_IMAGE_SIDE`] and
/// the pixel count within `max_pixels`.
pub(crate) fn check_image_size_common(width: u32, height: u32, max_pixels: u64, backend: &str) -> Result<()> {
    let reason = if width == 0 || height == 0 {
        Some("width and height must be at least 1".to_owned())
    } else if width.max(height) > MAX_IMAGE_SIDE {
        Some(format!(
            "a side of {} pixels exceeds {MAX_IMAGE_SIDE}, beyond which f32 sub-pixel positions lose precision",
            width.max(height)
        ))
    } else if u64::from(width) * u64::from(height) > max_pixels {
        Some(format!("{} pixels exceed the limit of {max_pixels}", u64::from(width) * u64::from(height)))
    } else {
        None
    };
    match reason {
        Some(reason) => Err(crate::Error::ImageSize { width, height, backend: backend.to_owned(), reason }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use raywave_shared::sampling::sampler_kind;

    /// A ZSobol sampler probe over `width × height` pixels, its square covering the image.
    fn sampler_probe(width: u32, height: u32, spp_log2: u32) -> SamplerProbeParams {
        let resolution_log2 = width.max(height).checked_next_power_of_two().map_or(32, u32::trailing_zeros);
        let sampler = SamplerParams { kind: sampler_kind::ZSOBOL, seed: 0, spp_log2, resolution_log2 };
        SamplerProbeParams { sampler, width, height, dimension: 0, padding: 0 }
    }

    /// Sides up to [`MAX_IMAGE_SIDE`] pass; a longer one is refused naming it, whatever the
    /// pixel count allows (a 2²⁴-pixel-wide line's neighbours had shared one ray).
    #[test]
    fn image_sides_are_limited_to_keep_sub_pixel_precision() {
        assert!(check_image_size_common(MAX_IMAGE_SIDE, 1, u64::MAX, "any").is_ok());
        assert!(check_image_size_common(1, MAX_IMAGE_SIDE, u64::MAX, "any").is_ok());
        for (width, height) in [(MAX_IMAGE_SIDE + 1, 1), (1, 1 << 24), (u32::MAX, u32::MAX)] {
            let err = check_image_size_common(width, height, u64::MAX, "any").expect_err("refused");
            let side = format!("a side of {} pixels exceeds 65536", width.max(height));
            assert!(matches!(err, crate::Error::ImageSize { .. }) && err.to_string().contains(&side), "{err}");
        }
    }

    #[test]
    fn a_sampler_probe_counts_its_samples_or_refuses_them() {
        // The Sobol' sampler, which has no Morton space to refuse first: the counts themselves.
        let sobol = |width, height, spp_log2| {
            let mut probe = sampler_probe(width, height, spp_log2);
            probe.sampler.kind = sampler_kind::SOBOL;
            probe
        };
        assert_eq!(sampler_probe_len(&sobol(4, 4, 2)).ok(), Some(64));
        assert_eq!(sampler_probe_len(&sobol(1 << 12, 1 << 12, 0)).ok(), Some(1 << 24));
        // Too many, including counts a shift would wrap: 2^64 (to 0) and 2^64 + 2^24 (to 2^24).
        let refused =
            [(1 << 12, 1 << 12, 1), (1 << 20, 1 << 20, 24), (257, 4_278_255_361, 24), (1, 1, 32), (1, 1, u32::MAX)];
        for (width, height, spp_log2) in refused {
            assert!(sampler_probe_len(&sobol(width, height, spp_log2)).is_err(), "{width}×{height}, 2^{spp_log2}");
        }
    }

    /// A warp probe of an unknown kind is refused naming the kind; it had returned zeros with
    /// `Ok` (the kernels draw nothing for it).
    #[test]
    fn a_warp_probe_of_an_unknown_kind_is_refused() {
        let warp = |kind: u32| WarpParams {
            kind,
            count: 4,
            padding: [0; 2],
            sampler: SamplerParams { kind: sampler_kind::SOBOL, seed: 0, spp_log2: 2, resolution_log2: 0 },
            a: Vec4::ZERO,
            b: Vec4::ZERO,
            c: Vec4::ZERO,
        };
        assert_eq!(warp_probe_len(&warp(warp_kind::COUNT - 1)).ok(), Some(4));
        for kind in [warp_kind::COUNT, u32::MAX] {
            match warp_probe_len(&warp(kind)) {
                Err(crate::error::Error::InvalidParameter { name: "warp probe", reason }) => {
                    assert!(reason.contains(&format!("warp kind {kind} is not one of 0..10")), "{reason}")
                }
                other => panic!("expected warp kind {kind} refused, got {other:?}"),
            }
        }
    }

    /// ZSobol points repeat where its sample space does not cover the image or the sample: every
    /// stage that draws from it refuses such parameters.
    #[test]
    fn a_zsobol_space_that_would_repeat_points_is_refused() {
        let mut probe = sampler_probe(5, 3, 2);
        assert!(sampler_probe_len(&probe).is_ok());
        probe.sampler.resolution_log2 = 2;
        assert!(sampler_probe_len(&probe).is_err(), "a 4-pixel square under a 5-pixel side");
        probe.sampler.kind = sampler_kind::SOBOL;
        assert!(sampler_probe_len(&probe).is_ok(), "other samplers have no such space");
        probe.sampler = SamplerParams { kind: sampler_kind::ZSOBOL, seed: 0, spp_log2: 1, resolution_log2: u32::MAX };
        assert!(sampler_probe_len(&probe).is_err(), "a field that would wrap u32 arithmetic");

        let warp = |count: u32, spp_log2: u32| WarpParams {
            kind: 0,
            count,
            padding: [0; 2],
            sampler: SamplerParams { kind: sampler_kind::ZSOBOL, seed: 0, spp_log2, resolution_log2: 0 },
            a: Vec4::ZERO,
            b: Vec4::ZERO,
            c: Vec4::ZERO,
        };
        assert_eq!(warp_probe_len(&warp(16, 4)).ok(), Some(16));
        assert!(warp_probe_len(&warp(17, 4)).is_err(), "sample 16 of 2^4 repeats sample 0's point");

        let scene = crate::Scene::load("builtin:cornell").unwrap();
        let mut generate = crate::frame::generate_params(&scene, 9, 7, 1);
        assert!(check_generate_params(&generate).is_ok());
        generate.sample_index = 1;
        assert!(check_generate_params(&generate).is_err(), "sample 1 of a one-sample frame");
        generate.sampler.spp_log2 = 1;
        assert!(check_generate_params(&generate).is_ok());
        generate.sampler.resolution_log2 = 3;
        generate.width = 9;
        assert!(check_generate_params(&generate).is_err(), "an 8-pixel square under a 9-pixel side");
    }

    /// A sampler kind outside [`sampler_kind`], which the kernels draw as `ZSOBOL` — whose space
    /// `indexes` had not judged for such a kind, so sample 5 of a one-sample frame repeated
    /// sample 0's points — is refused by every stage that draws from it.
    #[test]
    fn an_unknown_sampler_kind_is_refused() {
        let scene = crate::Scene::load("builtin:cornell").unwrap();
        let mut generate = crate::frame::generate_params(&scene, 8, 8, 0);
        generate.sampler.kind = sampler_kind::COUNT;
        assert!(!generate.sampler.indexes(8, 8, 6), "drawn as ZSOBOL, judged as ZSOBOL");
        let err = check_generate_params(&generate).expect_err("refused");
        assert!(err.to_string().contains("sampler kind 3"), "{err}");
        let mut probe = sampler_probe(8, 8, 0);
        probe.sampler.kind = 7;
        assert!(sampler_probe_len(&probe).is_err());
    }

    /// The measurement behind [`MAX_APERTURE_TO_FOCUS`]: every ray of the Cornell box's camera
    /// (focus 0.8) at 32², 4 samples, crosses the focal plane (found in f64) where its pinhole ray
    /// does, within 1.2·10⁻⁷ of the focus distance per unit of the ratio of aperture to focus:
    /// 1.9·10⁻⁷ at 1, 1.2·10⁻⁴ at the limit of 10³, 0.13 at 10⁶ and 1.1 at 10⁷ (inside the old
    /// limit of 10⁸ scene units). The limit is accepted, a radius above it refused.
    #[test]
    fn thin_lens_rays_meet_their_focal_point_up_to_the_aperture_limit() {
        let scene = crate::Scene::load("builtin:cornell").unwrap();
        let pinhole = crate::frame::generate_params(&scene, 32, 32, 0);
        let focus = pinhole.focus_distance;
        let worst_miss = |ratio: f32| {
            let lens = GenerateParams { lens_radius: ratio * focus, ..pinhole };
            let mut worst: f64 = 0.0;
            for sample_index in 0..4 {
                for i in 0..lens.ray_count() {
                    let ray = raywave_kernels::generate::generate_ray(i, &GenerateParams { sample_index, ..lens });
                    let aim = raywave_kernels::generate::generate_ray(i, &GenerateParams { sample_index, ..pinhole });
                    let f64s = |v: Vec4| glam::DVec3::new(v.x.into(), v.y.into(), v.z.into());
                    let forward = f64s(pinhole.forward).normalize();
                    let camera = f64s(pinhole.origin);
                    // The focal plane `(x − camera)·forward = focus`, and where each ray meets it.
                    let meet = |origin: glam::DVec3, direction: glam::DVec3| {
                        origin
                            + direction * ((f64::from(focus) - (origin - camera).dot(forward)) / direction.dot(forward))
                    };
                    let target = meet(f64s(aim.origin), f64s(aim.direction));
                    let crossing = meet(f64s(ray.origin), f64s(ray.direction));
                    worst = worst.max(crossing.distance(target) / f64::from(focus));
                }
            }
            worst
        };
        for ratio in [1.0, 10.0, 100.0, MAX_APERTURE_TO_FOCUS] {
            let miss = worst_miss(ratio);
            // Plus 1: at small ratios the pinhole ray's own rounding is most of the miss.
            let bound = 2e-7 * (1.0 + f64::from(ratio));
            assert!(miss < bound, "ratio {ratio}: rays miss by {miss:e} of the focus distance");
        }
        assert!(worst_miss(1e6) > 0.1, "beyond the limit, where it was accepted before");
        let at_limit = GenerateParams { lens_radius: MAX_APERTURE_TO_FOCUS * focus, ..pinhole };
        assert!(check_generate_params(&at_limit).is_ok());
        let over = GenerateParams { lens_radius: at_limit.lens_radius * 1.01, ..pinhole };
        let err = check_generate_params(&over).expect_err("refused").to_string();
        assert!(err.contains("lens_radius") && err.contains("focus distance"), "{err}");
    }

    /// The camera basis must have the shape `GenerateParams` documents: a 10⁻³⁰-long basis made
    /// 77 % of the rays' directions infinite and a 2·10¹⁹-long `forward` made them all zero, both
    /// uncounted, before the check; a basis built from normalized cross products passes.
    #[test]
    fn a_camera_basis_of_another_shape_is_refused() {
        let scene = crate::Scene::load("builtin:cornell").unwrap();
        let good = crate::frame::generate_params(&scene, 8, 8, 0);
        assert!(check_generate_params(&good).is_ok());
        let v = |x, y, z| Vec4::new(x, y, z, 0.0);
        let tiny =
            GenerateParams { forward: v(1e-30, 0.0, 0.0), right: v(0.0, 3e-23, 0.0), up: v(0.0, 0.0, 3e-23), ..good };
        let long = GenerateParams { forward: v(0.0, 0.0, 2e19), right: v(1.0, 0.0, 0.0), up: v(0.0, 1.0, 0.0), ..good };
        let slanted = GenerateParams { right: good.right + good.forward * 0.01 * good.right.length(), ..good };
        let wide = GenerateParams { right: good.right * 1e19, ..good };
        let flat = GenerateParams { up: good.right, ..good };
        // Axes 1000 long, each orthogonal to `forward` within the tolerance, but not to each
        // other: the image plane's corner ray had been zero, a NaN direction.
        let sheared =
            GenerateParams { forward: v(0.0, 0.0, 1.0), right: v(1000.0, 0.0, 0.0), up: v(1000.0, 0.0, 1.0), ..good };
        // At right angles within the basis' rounding, as built, it passes.
        let square = GenerateParams { up: good.up + good.right * 1e-6, ..good };
        assert!(check_generate_params(&square).is_ok());
        // Too short to normalize, which the thin lens does: its origins became infinite.
        let lens = GenerateParams { lens_radius: 0.01, focus_distance: 1.0, ..good };
        let thin = GenerateParams {
            right: good.right * (1e-23 / good.right.length()),
            up: good.up * (1e-16 / good.up.length()),
            ..lens
        };
        // A focal plane whose point `pinhole · focus_distance` overflows.
        let far = GenerateParams { right: good.right * 1e17, focus_distance: 1e22, ..lens };
        assert!(check_generate_params(&lens).is_ok());
        let cases = [
            ("tiny", tiny),
            ("long", long),
            ("slanted", slanted),
            ("wide", wide),
            ("flat", flat),
            ("sheared", sheared),
            ("thin", thin),
            ("far", far),
        ];
        for (name, params) in cases {
            assert!(check_generate_params(&params).is_err(), "{name}");
        }
    }

    /// An opened backend, boxed as `open_backend` returns it, moves to another thread (an
    /// engine's render thread) and runs there: `Backend` is `Send`, which `thread::spawn` checks
    /// at compile time.
    #[test]
    fn a_boxed_backend_moves_to_another_thread() {
        let mut backend = crate::open_backend(crate::DeviceChoice::Cpu, &Default::default()).unwrap();
        let scene = crate::Scene::load("builtin:cornell").unwrap();
        backend.load_scene(&scene).unwrap();
        let params = crate::frame::generate_params(&scene, 4, 3, 0);
        let frame = std::thread::spawn(move || backend.render(&params)).join().expect("the render thread");
        assert_eq!(frame.unwrap().hits.len(), 12);
    }

    #[test]
    fn a_copy_probe_takes_one_entry_per_pixel() {
        let params = DenoiseParams::new(3, 2);
        assert_eq!(copy_probe_len(&params, &[Vec4::ZERO; 6]).ok(), Some(6));
        assert!(copy_probe_len(&params, &[Vec4::ZERO; 5]).is_err());
        assert!(copy_probe_len(&DenoiseParams::new(0, 2), &[]).is_err(), "an empty image");
    }
}
