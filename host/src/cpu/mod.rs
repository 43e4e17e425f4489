//! The CPU executor: runs the kernel functions of `raywave-kernels` in parallel (rayon) over the
//! same invocation range a Vulkan dispatch covers.

mod bvh;
mod denoise;

pub use bvh::{BvhQuality, CpuScene, TraversalIsa};

use crate::backend::{
    check_generate_params, check_image_size_common, check_shade_inputs, check_sustain_seconds, copy_probe_len,
    sampler_probe_len, warp_probe_len, Backend, FrameOutput, StageReport,
};
use crate::denoise::{DenoiseInput, DenoiseMethod};
use crate::error::{Error, Result};
use crate::scene::{Scene, SceneIdentity};
use crate::shading::{self, ShadeData};
use crate::stream::{HitStream, RayStream, ShadeStream};
use glam::{UVec2, Vec4};
use rayon::prelude::*;
use raywave_kernels::sampling::probe;
use raywave_kernels::sanitized::Sanitized;
use raywave_kernels::{
    generate::generate_ray,
    trace::{trace_closest, trace_occluded},
};
use raywave_shared::{DenoiseParams, GenerateParams, SamplerProbeParams, ShadeParams, WarpParams};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Largest image the CPU backend accepts: 2²⁶ pixels (≈ 3.8 GB of ray and hit streams; a lit
/// frame, [`LIT_FRAME_BYTES_PER_PIXEL`], takes 25 GB of memory there).
pub const MAX_PIXELS: u64 = 1 << 26;

/// Host memory a lit frame holds at its peak on the CPU backend, bytes per pixel
/// ([`Backend::lit_frame_bytes_per_pixel`]): measured 360 (the peak resident memory of `raywave
/// render --device cpu --spp 1 --exr --stochastic` grows by that much per pixel from 1024² to
/// 2048² and from 2048² to 4096², 2026-12-01, 2 threads; 1 and 4 spp alike, SVGF less), rounded
/// up by 5 %. The normals view takes about 59.
pub const LIT_FRAME_BYTES_PER_PIXEL: u64 = 380;

/// The CPU backend.
#[derive(Default)]
pub struct CpuBackend {
    /// The loaded scene's BVH, and the scene's identity, which shade data must match.
    scene: Option<(CpuScene, SceneIdentity)>,
}

impl CpuBackend {
    /// A CPU backend with no scene loaded.
    pub fn new() -> Self {
        Self::default()
    }

    /// The loaded scene, or an error naming the stage that needs it.
    fn scene(&self) -> Result<&CpuScene> {
        self.scene
            .as_ref()
            .map(|(scene, _)| scene)
            .ok_or(Error::InvalidParameter { name: "scene", reason: "trace needs a loaded scene".into() })
    }
}

/// Runs the generate stage over `0..params.ray_count()`, after the checks of the CPU backend's
/// [`Backend::generate`]: the image size within its limits ([`MAX_PIXELS`]; a size whose pixel
/// count wraps `ray_count`'s `u32` had given an empty stream) and the camera's parameters.
pub fn generate(params: &GenerateParams) -> Result<RayStream> {
    check_generate(params)?;
    Ok(generate_checked(params))
}

/// [`generate`]'s checks: the CPU backend's image size, then the camera's parameters.
fn check_generate(params: &GenerateParams) -> Result<()> {
    CpuBackend::new().check_image_size(params.width, params.height)?;
    check_generate_params(params)
}

/// The generate stage over `params` that [`check_generate`] has accepted.
fn generate_checked(params: &GenerateParams) -> RayStream {
    let mut rays = RayStream::zeroed(params.ray_count() as usize);
    (&mut rays.origin, &mut rays.direction, &mut rays.pixel).into_par_iter().enumerate().for_each(
        |(i, (origin, direction, pixel))| {
            let ray = generate_ray(i as u32, params);
            (*origin, *direction, *pixel) = (ray.origin, ray.direction, ray.pixel);
        },
    );
    rays
}

/// Runs the trace stage over every ray of `rays`: the hit stream and how many rays or hits were
/// not finite and became misses ([`StageReport::sanitized`]). Fields of different lengths are an
/// error naming them, as [`Backend::trace`] makes it (a short direction field had given zeroed
/// records — hits on mesh 0's triangle 0 — for the rays past its end).
pub fn trace_counted(scene: &CpuScene, rays: &RayStream) -> Result<(HitStream, u64)> {
    rays.check("trace")?;
    Ok(trace_checked(scene, rays))
}

/// The hit stream of [`trace_counted`] alone.
pub fn trace(scene: &CpuScene, rays: &RayStream) -> Result<HitStream> {
    Ok(trace_counted(scene, rays)?.0)
}

/// [`trace_counted`] over a ray stream whose fields have been checked.
fn trace_checked(scene: &CpuScene, rays: &RayStream) -> (HitStream, u64) {
    let mut hits = HitStream::zeroed(rays.len());
    let sanitized = AtomicU64::new(0);
    (&mut hits.t, &mut hits.primitive, &mut hits.instance, &mut hits.barycentrics)
        .into_par_iter()
        .zip((&rays.origin, &rays.direction).into_par_iter())
        .for_each(|((t, primitive, instance, barycentrics), (origin, direction))| {
            let hit = count(trace_closest(*origin, *direction, scene), &sanitized);
            (*t, *primitive, *instance, *barycentrics) = (hit.t, hit.primitive, hit.instance, hit.barycentrics);
        });
    (hits, sanitized.into_inner())
}

/// Runs the occlusion variant of the trace stage (shadow rays) over every ray of `rays`: 1 where
/// the ray is blocked within its interval, 0 where it is not; and how many rays were not finite
/// (reported unblocked). Fields of different lengths are an error naming them.
pub fn trace_occlusion_counted(scene: &CpuScene, rays: &RayStream) -> Result<(Vec<u32>, u64)> {
    rays.check("trace_occlusion")?;
    Ok(occlusion_checked(scene, rays))
}

/// The occlusion results of [`trace_occlusion_counted`] alone.
pub fn trace_occlusion(scene: &CpuScene, rays: &RayStream) -> Result<Vec<u32>> {
    Ok(trace_occlusion_counted(scene, rays)?.0)
}

/// [`trace_occlusion_counted`] over a ray stream whose fields have been checked.
fn occlusion_checked(scene: &CpuScene, rays: &RayStream) -> (Vec<u32>, u64) {
    let sanitized = AtomicU64::new(0);
    let occluded = (&rays.origin, &rays.direction)
        .into_par_iter()
        .map(|(origin, direction)| u32::from(count(trace_occluded(*origin, *direction, scene), &sanitized)))
        .collect();
    (occluded, sanitized.into_inner())
}

/// The value of an invocation's result, adding it to `sanitized` if it replaced a non-finite value
/// (what the SPIR-V entry points' atomic counter does on a device).
pub(crate) fn count<T>(result: Sanitized<T>, sanitized: &AtomicU64) -> T {
    if result.replaced {
        sanitized.fetch_add(1, Ordering::Relaxed);
    }
    result.value
}

/// Runs `f`, which returns a value and its sanitized count, and reports both with its time.
fn timed<T>(stage: &'static str, f: impl FnOnce() -> (T, u64)) -> (T, StageReport) {
    let start = Instant::now();
    let (value, sanitized) = f();
    (value, StageReport::once(stage, start.elapsed().as_secs_f64(), sanitized))
}

impl Backend for CpuBackend {
    fn name(&self) -> String {
        format!("cpu ({} threads)", rayon::current_num_threads())
    }

    fn check_image_size(&self, width: u32, height: u32) -> Result<()> {
        check_image_size_common(width, height, MAX_PIXELS, &self.name())
    }

    fn lit_frame_bytes_per_pixel(&self) -> Option<u64> {
        Some(LIT_FRAME_BYTES_PER_PIXEL)
    }

    /// Every CPU stage runs once, timed by the wall clock: nothing to sustain (the value is
    /// checked as on every backend).
    fn set_sustain_seconds(&mut self, seconds: f64) -> Result<()> {
        check_sustain_seconds(seconds).map(|_| ())
    }

    fn load_scene(&mut self, scene: &Scene) -> Result<()> {
        self.scene = Some((CpuScene::build(scene)?, scene.identity().clone()));
        Ok(())
    }

    fn generate(&mut self, params: &GenerateParams) -> Result<(RayStream, StageReport)> {
        check_generate(params)?;
        Ok(timed("generate", || (generate_checked(params), 0)))
    }

    fn trace(&mut self, rays: &RayStream) -> Result<(HitStream, StageReport)> {
        rays.check("trace")?;
        let scene = self.scene()?;
        Ok(timed("trace", || trace_checked(scene, rays)))
    }

    fn trace_occlusion(&mut self, rays: &RayStream) -> Result<(Vec<u32>, StageReport)> {
        rays.check("trace_occlusion")?;
        let scene = self.scene()?;
        Ok(timed("occlusion", || occlusion_checked(scene, rays)))
    }

    fn shade(
        &mut self,
        params: &ShadeParams,
        data: &ShadeData,
        rays: &RayStream,
        hits: &HitStream,
    ) -> Result<(ShadeStream, StageReport)> {
        let loaded = self.scene.as_ref().map(|(_, identity)| identity);
        check_shade_inputs(params, data, loaded, rays, hits)?;
        Ok(timed("shade", || {
            let surfaces = shading::resolve(data, rays, hits);
            shading::shade(params, data, rays, &surfaces)
        }))
    }

    fn render(&mut self, params: &GenerateParams) -> Result<FrameOutput> {
        // Before the camera rays, as the Vulkan backend checks it: no work for a frame that
        // cannot be traced.
        self.scene()?;
        let (rays, generate_time) = self.generate(params)?;
        let (hits, trace_time) = self.trace(&rays)?;
        Ok(FrameOutput { rays, hits, timings: vec![generate_time, trace_time] })
    }

    fn denoise(
        &mut self,
        method: DenoiseMethod,
        params: &DenoiseParams,
        input: &DenoiseInput,
    ) -> Result<(Vec<Vec4>, Vec<StageReport>)> {
        input.check(params)?;
        Ok(denoise::denoise(method, params, input))
    }

    fn copy_probe(&mut self, params: &DenoiseParams, image: &[Vec4]) -> Result<(Vec<Vec4>, StageReport)> {
        copy_probe_len(params, image)?;
        Ok(denoise::copy_probe(params, image))
    }

    fn sampler_probe(&mut self, params: &SamplerProbeParams) -> Result<Vec<UVec2>> {
        let count = sampler_probe_len(params)?;
        Ok((0..count).into_par_iter().map(|i| probe::sampler_probe(i, params)).collect())
    }

    fn warp_probe(&mut self, params: &WarpParams) -> Result<Vec<Vec4>> {
        let count = warp_probe_len(params)?;
        Ok((0..count).into_par_iter().map(|i| probe::warp_probe(i, params)).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Vec3, Vec4};
    use raywave_shared::stream::NO_HIT;

    /// Mesh indices of the built-in Cornell box (see `scene::cornell::meshes`).
    const FLOOR: u32 = 0;
    const TALL_BLOCK: u32 = 6;
    const LIGHT: u32 = 7;

    fn trace_one(origin: Vec3, direction: Vec3) -> (f32, u32) {
        let scene = Scene::load("builtin:cornell").unwrap();
        let mut rays = RayStream::zeroed(1);
        rays.origin[0] = origin.extend(0.0);
        rays.direction[0] = direction.extend(10.0);
        let hits = trace(&CpuScene::build(&scene).unwrap(), &rays).unwrap();
        (hits.t[0], hits.instance[0])
    }

    /// The free `generate` checks what the backend checks: a 65536² image, whose pixel count
    /// wraps `ray_count`'s `u32` to 0, had returned an empty stream; a longer side than
    /// [`crate::backend::MAX_IMAGE_SIDE`] is refused whatever the pixel count; a camera without
    /// an image plane is refused.
    #[test]
    fn the_free_generate_refuses_what_the_backend_refuses() {
        let scene = Scene::load("builtin:cornell").unwrap();
        for (width, height, reason) in [(1 << 16, 1 << 16, "exceed the limit"), (1 << 17, 1, "a side of 131072")] {
            let params = crate::frame::generate_params(&scene, width, height, 0);
            let err = generate(&params).expect_err("refused");
            assert!(matches!(err, Error::ImageSize { .. }) && err.to_string().contains(reason), "{err}");
        }
        let mut flat = crate::frame::generate_params(&scene, 4, 4, 0);
        flat.up = Vec4::ZERO;
        assert!(matches!(generate(&flat), Err(Error::InvalidParameter { name: "generate", .. })));
        assert_eq!(generate(&crate::frame::generate_params(&scene, 4, 3, 0)).expect("generates").len(), 12);
    }

    /// A short direction traces what a unit one does, also for geometry 10⁻¹⁷ of the distance
    /// across: a 10⁻⁹-wide triangle 10⁸ away, hit near its node's edge. The box test had floored
    /// the zero components of `(0, 0, 10⁻¹²)` at 10⁻³⁰, 10⁻¹⁸ of the direction, and culled the
    /// node; it now scales every direction to a largest component in [1, 2) first.
    #[test]
    fn a_short_direction_hits_tiny_geometry_far_away() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("tiny.obj");
        std::fs::write(&path, "v 0 0 0\nv 1e-9 0 0\nv 0 1e-9 0\nf 1 2 3\n").unwrap();
        let cpu_scene = CpuScene::build(&Scene::load(path.to_str().unwrap()).unwrap()).unwrap();
        let origin = Vec4::new(0.99e-9, 0.005e-9, -1e8, 0.0);
        for length in [1.0, raywave_kernels::trace::MIN_DIRECTION] {
            let hit = trace_closest(origin, Vec4::new(0.0, 0.0, length, 2e8 / length), &cpu_scene).value;
            assert_eq!(hit.primitive, 0, "direction length {length}: {hit:?}");
            assert!((hit.t * length / 1e8 - 1.0).abs() < 1e-6, "direction length {length}: {hit:?}");
        }
    }

    #[test]
    fn camera_axis_hits_the_tall_block_front_face() {
        // At x = 278 mm the tall block's front edge runs from (265, 296) to (423, 247) mm, so the
        // camera axis meets it at z = 296 − 49·13/158 mm; the camera is at z = −800 mm.
        let (t, instance) = trace_one(Vec3::new(0.278, 0.273, -0.8), Vec3::Z);
        assert_eq!(instance, TALL_BLOCK);
        let expected = 0.8 + (0.296 - 0.049 * 13.0 / 158.0);
        assert!((t - expected).abs() < 1e-6, "t = {t}, expected {expected}");
    }

    #[test]
    fn vertical_rays_hit_floor_and_light() {
        let (t, instance) = trace_one(Vec3::new(0.278, 0.5, 0.28), Vec3::NEG_Y);
        assert_eq!((instance, (t - 0.5).abs() < 1e-6), (FLOOR, true), "t = {t}");
        let (t, instance) = trace_one(Vec3::new(0.278, 0.3, 0.28), Vec3::Y);
        assert_eq!((instance, (t - 0.2487).abs() < 1e-6), (LIGHT, true), "t = {t}");
    }

    #[test]
    fn rays_out_of_the_open_front_miss() {
        let (t, instance) = trace_one(Vec3::new(0.278, 0.273, 0.2), Vec3::NEG_Z);
        assert_eq!((t, instance), (0.0, NO_HIT));
    }

    #[test]
    fn stages_cover_the_whole_image_and_keep_outputs_finite() {
        let scene = Scene::load("builtin:cornell").unwrap();
        let mut backend = CpuBackend::new();
        backend.load_scene(&scene).unwrap();
        let params = crate::frame::generate_params(&scene, 33, 17, 4);
        let frame = backend.render(&params).unwrap();
        assert_eq!(frame.rays.pixel, (0..33 * 17).collect::<Vec<u32>>());
        assert!(frame.hits.t.iter().all(|t| t.is_finite()));
        assert!(frame.hits.barycentrics.iter().all(|b| b.is_finite()));
        assert!(frame.rays.direction.iter().all(|d: &Vec4| d.is_finite()));
        // Finite as computed, not as replaced (each stage replaces a non-finite value and counts it).
        assert!(frame.timings.iter().all(|report| report.sanitized == 0), "{:?}", frame.timings);
    }

    #[test]
    fn trace_without_a_scene_is_an_error() {
        assert!(CpuBackend::new().trace(&RayStream::zeroed(1)).is_err());
    }

    /// What a linking engine can get wrong through the public API — streams whose fields differ in
    /// length, a zeroed camera, shade data edited after construction, an accumulator of another
    /// size — is a typed error naming the stage or field. Before, trace zipped to the shortest
    /// field (extra records read as hits on triangle 0), generate returned NaN directions, a NaN
    /// metalness left the shade stage as NaN `U`, and an emptied LTC table panicked.
    #[test]
    fn malformed_streams_parameters_and_shade_data_are_errors() {
        use crate::error::Error;
        use crate::shading::{ShadeAccumulator, ShadeData};
        let name_of = |err: Error| match err {
            Error::InvalidParameter { name, .. } => name,
            other => panic!("expected an invalid parameter, got {other}"),
        };
        let scene = Scene::load("builtin:cornell").unwrap();
        let mut cpu = CpuBackend::new();
        cpu.load_scene(&scene).unwrap();
        let mut rays = RayStream::zeroed(4);
        rays.pixel.push(4);
        assert_eq!(name_of(cpu.trace(&rays).unwrap_err()), "trace");
        assert_eq!(name_of(cpu.trace_occlusion(&rays).unwrap_err()), "trace_occlusion");
        // The free functions too (they had zipped to the shortest field).
        let cpu_scene = CpuScene::build(&scene).unwrap();
        assert_eq!(name_of(trace_counted(&cpu_scene, &rays).unwrap_err()), "trace");
        assert_eq!(name_of(trace_occlusion_counted(&cpu_scene, &rays).unwrap_err()), "trace_occlusion");
        let zeroed = GenerateParams { width: 1, height: 1, ..bytemuck::Zeroable::zeroed() };
        assert_eq!(name_of(cpu.generate(&zeroed).unwrap_err()), "generate");
        let params = crate::frame::generate_params(&scene, 4, 4, 1);
        for broken in [
            GenerateParams { tmax: params.tmin, ..params },
            GenerateParams { lens_radius: 0.1, focus_distance: 0.0, ..params },
            GenerateParams { up: Vec4::splat(f32::NAN), ..params },
        ] {
            assert_eq!(name_of(cpu.generate(&broken).unwrap_err()), "generate", "{broken:?}");
        }

        let (rays, _) = cpu.generate(&params).unwrap();
        let (hits, _) = cpu.trace(&rays).unwrap();
        let valid = ShadeData::new(&scene).unwrap();
        let shade_params = valid.params(params.sampler, 4, 4, 0);
        type Edit = fn(&mut ShadeData);
        let edits: [(Edit, &str); 12] = [
            (|d| d.materials[0].emission_metallic.w = f32::NAN, "material.metallic"),
            (|d| d.materials[1].base_color_roughness.x = 2.0, "material.base_color"),
            (|d| d.ltc.clear(), "ltc"),
            (|d| d.first_triangle[1] = u32::MAX, "triangles"),
            // What the kernels would read past (the CPU) or from a zeroed stand-in (Vulkan).
            (|d| d.lights[0] = raywave_shared::Light::sphere(glam::Vec3::Y, 0.1, glam::Vec3::ONE), "light.kind"),
            (|d| d.materials.truncate(1), "materials"),
            (|d| d.light_nodes.push(bytemuck::Zeroable::zeroed()), "light_trails"),
            // Each rule at its boundary, one step past it: one material short of the instances,
            // one LTC entry too many, one vertex short of whole triangles, the last instance
            // starting past the last triangle (still ascending), an emission flag of 2.
            (|d| _ = d.materials.pop(), "materials"),
            (|d| d.ltc.push(Vec4::ZERO), "ltc"),
            (|d| _ = d.triangles.pop(), "triangles"),
            (|d| *d.first_triangle.last_mut().unwrap() = (d.triangles.len() / 3 + 1) as u32, "triangles"),
            (|d| d.materials[0].two_sided_emission = 2, "material.two_sided_emission"),
        ];
        for (edit, field) in edits {
            let mut data = ShadeData::new(&scene).unwrap();
            edit(&mut data);
            assert_eq!(name_of(cpu.shade(&shade_params, &data, &rays, &hits).unwrap_err()), field);
        }
        let mut short_hits = hits.clone();
        short_hits.instance.pop();
        assert_eq!(name_of(cpu.shade(&shade_params, &valid, &rays, &short_hits).unwrap_err()), "shade");
        for counts in [
            ShadeParams { light_count: shade_params.light_count + 1, ..shade_params },
            ShadeParams { light_node_count: 1, ..shade_params },
        ] {
            assert_eq!(name_of(cpu.shade(&counts, &valid, &rays, &hits).unwrap_err()), "shade", "{counts:?}");
        }

        let (shades, _) = cpu.shade(&shade_params, &valid, &rays, &hits).unwrap();
        let mut accumulator = ShadeAccumulator::new(16);
        assert_eq!(name_of(accumulator.add(&shades, &[0; 15]).unwrap_err()), "accumulate");
        assert_eq!(name_of(ShadeAccumulator::new(17).add(&shades, &[0; 16]).unwrap_err()), "accumulate");
        accumulator.add(&shades, &[0; 16]).unwrap();
        assert_eq!(accumulator.samples(), 1, "only the valid pass counted");
    }

    /// The Cornell box, the same box with its tall block moved
    /// ([`crate::scene::tests::cornell_and_moved`]) and a frame's generate parameters.
    fn cornell_and_moved() -> (Scene, Scene, GenerateParams) {
        let (scene, moved) = crate::scene::tests::cornell_and_moved();
        assert_eq!(scene.meshes()[TALL_BLOCK as usize].name, "tall block");
        let params = crate::frame::generate_params(&scene, 8, 6, 1);
        (scene, moved, params)
    }

    /// Shade data of another scene than the loaded one — the old data after loading the scene
    /// rebuilt with an object moved, or another scene's — is refused naming both scenes: it had
    /// been shaded with `Ok`, the trace's new geometry resolved on old triangles. Data of the
    /// loaded scene, of a clone of it, and with an engine's own light added is shaded; and
    /// without a loaded scene (hits of an engine's own trace) any data is.
    #[test]
    fn shade_data_of_another_scene_than_the_loaded_one_is_refused() {
        use crate::shading::ShadeData;
        let (scene, moved, params) = cornell_and_moved();
        let other = Scene::load("builtin:cornell-two-lights").unwrap();
        let (old_data, other_data) = (ShadeData::new(&scene).unwrap(), ShadeData::new(&other).unwrap());
        let shade_params = |data: &ShadeData| data.params(params.sampler, 8, 6, 0);
        let mut cpu = CpuBackend::new();
        let frame = generate(&params).unwrap();
        let hits = trace(&CpuScene::build(&scene).unwrap(), &frame).unwrap();
        for data in [&old_data, &other_data] {
            assert!(cpu.shade(&shade_params(data), data, &frame, &hits).is_ok(), "no scene loaded");
        }
        cpu.load_scene(&scene).unwrap();
        let frame = cpu.render(&params).unwrap();
        cpu.shade(&shade_params(&old_data), &old_data, &frame.rays, &frame.hits).unwrap();

        cpu.load_scene(&moved).unwrap();
        let frame = cpu.render(&params).unwrap();
        for data in [&old_data, &other_data] {
            match cpu.shade(&shade_params(data), data, &frame.rays, &frame.hits) {
                Err(error @ Error::SceneMismatch { .. }) => {
                    let message = error.to_string();
                    let (built, loaded) = (data.scene().to_string(), moved.identity().to_string());
                    assert!(built != loaded && message.contains(&built) && message.contains(&loaded), "{message}");
                }
                other => panic!("expected {} refused on {}, got {other:?}", data.scene(), moved.identity()),
            }
        }
        let mut fresh = ShadeData::new(&moved.clone()).unwrap();
        assert_eq!(fresh.scene(), moved.identity(), "a clone is the same scene");
        cpu.shade(&shade_params(&fresh), &fresh, &frame.rays, &frame.hits).unwrap();
        let mut lamp = fresh.lights[0];
        lamp.position.z -= 0.1;
        lamp.mesh = raywave_shared::Light::NO_MESH;
        fresh.lights.push(lamp);
        assert_eq!(shade_params(&fresh).light_count, 2);
        cpu.shade(&shade_params(&fresh), &fresh, &frame.rays, &frame.hits).expect("an engine's own light");
    }

    /// `shade_samples` checks that its data is its scene's before any work: before the backend
    /// renders (this one has no scene, which `render` would have refused first).
    #[test]
    fn shade_samples_refuses_another_scenes_data_before_rendering() {
        let (scene, moved, _) = cornell_and_moved();
        let data = crate::shading::ShadeData::new(&scene).unwrap();
        let settings = crate::lit_frame::LitFrameSettings::new(8, 6, 1);
        let result = crate::lit_frame::shade_samples(&mut CpuBackend::new(), &moved, &data, &settings);
        assert!(matches!(result, Err(crate::Error::SceneMismatch { .. })), "{:?}", result.err());
    }

    /// A rendered 8×6 Cornell frame on a loaded CPU backend, its shade data and shade parameters
    /// (sample 0 of one).
    fn shade_fixture() -> (CpuBackend, ShadeData, FrameOutput, ShadeParams) {
        let (scene, _, params) = cornell_and_moved();
        let data = ShadeData::new(&scene).unwrap();
        let mut cpu = CpuBackend::new();
        cpu.load_scene(&scene).unwrap();
        let frame = cpu.render(&params).unwrap();
        let shade_params = data.params(params.sampler, 8, 6, 0);
        (cpu, data, frame, shade_params)
    }

    /// The reason of a shade-stage refusal (`InvalidParameter` naming `shade`), or a panic naming
    /// what came back instead.
    fn shade_refusal(result: Result<(ShadeStream, StageReport)>) -> String {
        match result {
            Err(Error::InvalidParameter { name: "shade", reason }) => reason,
            other => panic!("expected the shade stage to refuse, got {:?}", other.map(|(shades, _)| shades.len())),
        }
    }

    /// One hit per ray: a ray stream one ray longer or shorter than its (self-consistent) hit
    /// stream, with `params.count` the hit count as the other checks want it, is refused naming
    /// both lengths. Each stream passes its own field-length check and the dense-pixel check, so
    /// only this one stands between them and the kernels: without it a longer ray stream panicked
    /// (`resolve` indexed the hits past their end) and a shorter one was shaded with `Ok`, fewer
    /// records than `params.count`.
    #[test]
    fn shade_refuses_a_ray_stream_of_another_length_than_its_hits() {
        let (mut cpu, data, frame, params) = shade_fixture();
        let (rays, hits) = (&frame.rays, &frame.hits);
        let mut longer = rays.clone();
        longer.origin.push(Vec4::ZERO);
        longer.direction.push(Vec4::Z);
        longer.pixel.push(rays.len() as u32);
        let mut shorter = rays.clone();
        shorter.origin.pop();
        shorter.direction.pop();
        shorter.pixel.pop();
        for rays in [&longer, &shorter] {
            let reason = shade_refusal(cpu.shade(&params, &data, rays, hits));
            assert!(reason.contains(&format!("{} rays but 48 hits", rays.len())), "{reason}");
        }
        assert_eq!(cpu.shade(&params, &data, rays, hits).expect("matched streams").0.len(), 48);
    }

    /// `params.width = 0` is refused naming the width: the stage lays invocation `i` out as pixel
    /// `(i mod width, i div width)`, and the sampler check sizes the image as `count ÷ width`
    /// rounded up — without this check a zero width divided by zero there and panicked.
    #[test]
    fn shade_refuses_a_zero_width() {
        let (mut cpu, data, frame, params) = shade_fixture();
        let reason = shade_refusal(cpu.shade(&ShadeParams { width: 0, ..params }, &data, &frame.rays, &frame.hits));
        assert!(reason.contains("params.width must be at least 1"), "{reason}");
    }

    /// The shade stage checks its sample index against the sampler's space as generate does, at the
    /// exact boundary: under a 4-sample ZSOBOL space sample 3 is shaded and sample 4 — which would
    /// redraw sample 0's points for every pixel, so the frame's light samples stop being
    /// independent — is refused naming the ZSOBOL space. The check counts `sample_index + 1`
    /// samples; counting `sample_index` let index 4 through.
    #[test]
    fn shade_refuses_the_first_sample_index_past_the_sampler_space() {
        let (mut cpu, data, frame, params) = shade_fixture();
        let sampler = crate::frame::sampler_params(raywave_shared::sampling::sampler_kind::ZSOBOL, 1, 8, 6, 4);
        assert_eq!(sampler.spp_log2, 2);
        let at = |sample_index| ShadeParams { sampler, sample_index, ..params };
        assert!(cpu.shade(&at(3), &data, &frame.rays, &frame.hits).is_ok(), "the last sample of four");
        let reason = shade_refusal(cpu.shade(&at(4), &data, &frame.rays, &frame.hits));
        assert!(
            reason.contains("ZSOBOL sampler's space") && reason.contains("repeats points for 5 samples"),
            "{reason}"
        );
    }

    /// The shade stage shades ray `i` as pixel `i` and reads no `pixel` field: a compacted stream
    /// (rays dropped before shading) or a reordered one is refused naming the first ray out of
    /// place. Both had been shaded with `Ok`, each sample drawn for the wrong pixel. A compacted
    /// stream that also keeps the frame's `params.count` is refused for the count.
    #[test]
    fn a_compacted_or_reordered_ray_stream_is_refused_by_shade() {
        let (mut cpu, data, frame, shade_params) = shade_fixture();
        let (rays, hits) = (&frame.rays, &frame.hits);
        cpu.shade(&shade_params, &data, rays, hits).expect("a dense stream");
        let mut refused = |rays: &RayStream, hits: &HitStream| {
            let params = ShadeParams { count: rays.len() as u32, ..shade_params };
            shade_refusal(cpu.shade(&params, &data, rays, hits))
        };
        // Rays that hit the floor dropped, as a compaction pass drops the rays it is done with.
        let kept: Vec<usize> = (0..rays.len()).filter(|&i| hits.instance[i] != FLOOR).collect();
        let first = kept.iter().enumerate().position(|(k, &i)| k != i).expect("a floor ray dropped");
        let compacted = RayStream {
            origin: kept.iter().map(|&i| rays.origin[i]).collect(),
            direction: kept.iter().map(|&i| rays.direction[i]).collect(),
            pixel: kept.iter().map(|&i| rays.pixel[i]).collect(),
        };
        let compacted_hits = HitStream {
            t: kept.iter().map(|&i| hits.t[i]).collect(),
            primitive: kept.iter().map(|&i| hits.primitive[i]).collect(),
            instance: kept.iter().map(|&i| hits.instance[i]).collect(),
            barycentrics: kept.iter().map(|&i| hits.barycentrics[i]).collect(),
        };
        let reason = refused(&compacted, &compacted_hits);
        assert!(reason.contains(&format!("rays.pixel[{first}] = {}", kept[first])), "{reason}");
        let mut swapped = rays.clone();
        swapped.pixel.swap(3, 4);
        let reason = refused(&swapped, hits);
        assert!(reason.contains("rays.pixel[3] = 4"), "{reason}");
        // With `params.count` still the full frame's, the count — the more basic fault, checked
        // in constant time — is the one named.
        let reason = shade_refusal(cpu.shade(&shade_params, &data, &compacted, &compacted_hits));
        assert!(reason.contains(&format!("params.count = {} but {} rays", rays.len(), kept.len())), "{reason}");
    }
}
