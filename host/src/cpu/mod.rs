//! The CPU executor: runs the kernel functions of `raywave-kernels` in parallel (rayon) over the
//! same invocation range a Vulkan dispatch covers.

mod bvh;

pub use bvh::CpuScene;

use crate::backend::{check_image_size_common, Backend, FrameOutput, StageTiming};
use crate::error::{Error, Result};
use crate::scene::Scene;
use crate::stream::{HitStream, RayStream};
use rayon::prelude::*;
use raywave_kernels::{generate::generate_ray, trace::trace_closest};
use raywave_shared::GenerateParams;
use std::time::Instant;

/// Largest image the CPU backend accepts: 2²⁶ pixels (≈ 3.8 GB of ray and hit streams).
pub const MAX_PIXELS: u64 = 1 << 26;

/// The CPU backend.
#[derive(Default)]
pub struct CpuBackend {
    scene: Option<CpuScene>,
}

impl CpuBackend {
    /// A CPU backend with no scene loaded.
    pub fn new() -> Self {
        Self::default()
    }

    /// The loaded scene, or an error naming the stage that needs it.
    fn scene(&self) -> Result<&CpuScene> {
        self.scene.as_ref().ok_or(Error::InvalidParameter {
            name: "scene",
            reason: "trace needs a loaded scene".into(),
        })
    }
}

/// Runs the generate stage over `0..params.ray_count()`.
pub fn generate(params: &GenerateParams) -> RayStream {
    let mut rays = RayStream::zeroed(params.ray_count() as usize);
    (&mut rays.origin, &mut rays.direction, &mut rays.pixel)
        .into_par_iter()
        .enumerate()
        .for_each(|(i, (origin, direction, pixel))| {
            let ray = generate_ray(i as u32, params);
            (*origin, *direction, *pixel) = (ray.origin, ray.direction, ray.pixel);
        });
    rays
}

/// Runs the trace stage over every ray of `rays`.
pub fn trace(scene: &CpuScene, rays: &RayStream) -> HitStream {
    let mut hits = HitStream::zeroed(rays.len());
    (
        &mut hits.t,
        &mut hits.primitive,
        &mut hits.instance,
        &mut hits.barycentrics,
    )
        .into_par_iter()
        .zip((&rays.origin, &rays.direction).into_par_iter())
        .for_each(
            |((t, primitive, instance, barycentrics), (origin, direction))| {
                let hit = trace_closest(*origin, *direction, scene);
                (*t, *primitive, *instance, *barycentrics) =
                    (hit.t, hit.primitive, hit.instance, hit.barycentrics);
            },
        );
    hits
}

fn timed<T>(stage: &'static str, f: impl FnOnce() -> T) -> (T, StageTiming) {
    let start = Instant::now();
    let value = f();
    (
        value,
        StageTiming {
            stage,
            seconds: start.elapsed().as_secs_f64(),
        },
    )
}

impl Backend for CpuBackend {
    fn name(&self) -> String {
        format!("cpu ({} threads)", rayon::current_num_threads())
    }

    fn check_image_size(&self, width: u32, height: u32) -> Result<()> {
        check_image_size_common(width, height, MAX_PIXELS, &self.name())
    }

    fn load_scene(&mut self, scene: &Scene) -> Result<()> {
        self.scene = Some(CpuScene::build(scene));
        Ok(())
    }

    fn generate(&mut self, params: &GenerateParams) -> Result<(RayStream, StageTiming)> {
        self.check_image_size(params.width, params.height)?;
        Ok(timed("generate", || generate(params)))
    }

    fn trace(&mut self, rays: &RayStream) -> Result<(HitStream, StageTiming)> {
        let scene = self.scene()?;
        Ok(timed("trace", || trace(scene, rays)))
    }

    fn render(&mut self, params: &GenerateParams) -> Result<FrameOutput> {
        let (rays, generate_time) = self.generate(params)?;
        let (hits, trace_time) = self.trace(&rays)?;
        Ok(FrameOutput {
            rays,
            hits,
            timings: vec![generate_time, trace_time],
        })
    }
}
