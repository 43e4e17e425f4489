//! `raywave bench trace`: trace throughput of every implementation on the same rays and the same
//! BVH input triangles — raywave's kernel traversal on the CPU, obvhs's own traversal, and each
//! Vulkan trace method — for primary, shadow (occlusion) and diffuse (incoherent) rays.

use crate::cpu::{self, CpuScene};
use crate::frame::generate_params;
use crate::kernels::hash::{pcg3d, unit_float};
use crate::kernels::sampling::warp::{local_to_world, sample_cosine_hemisphere};
use crate::kernels::trace::{trace_closest, trace_occluded, Ray};
use crate::output_line::{json_object, OutputLine};
use crate::shared::stream::NO_HIT;
use crate::{Error, RayStream, Result, Scene, StageReport};
use glam::{UVec3, Vec2, Vec3, Vec4, Vec4Swizzles};
use rayon::prelude::*;
use std::time::Instant;

/// What to measure.
#[derive(Clone, Debug)]
pub struct TraceBenchOptions {
    /// `builtin:NAME` or a scene file.
    pub scene: String,
    /// CPU thread counts to measure (each ≥ 1).
    pub threads: Vec<usize>,
    /// Camera rays per side (≥ 1, within the CPU backend's image size): `resolution²` primary rays.
    pub resolution: u32,
    /// Timed repetitions per measurement (≥ 1); the median is reported.
    pub repeats: u32,
    /// Also measure every Vulkan trace method of the best Vulkan device, if there is one.
    pub vulkan: bool,
    /// obvhs build preset of the BVH that raywave (on the CPU and in the Vulkan `sw` method) and
    /// obvhs traverse.
    pub bvh: crate::cpu::BvhQuality,
    /// The Vulkan device's workgroup sizes of the compute trace methods (`sw`, `rayquery`;
    /// [`crate::WorkgroupSizes::trace`]; the ray-tracing pipeline has no workgroups and is
    /// measured once) and warm-up.
    pub vulkan_options: crate::bench_device::VulkanBenchOptions,
}

/// One measurement, printed as one JSON line.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Measurement {
    /// Always `trace` (the build line is a [`BuildMeasurement`]).
    pub stage: &'static str,
    /// `raywave-cpu`, `obvhs`, `embree`, `raywave-vk-sw`, `raywave-vk-rayquery`, `raywave-vk-rtpipe`.
    #[serde(rename = "impl")]
    pub implementation: String,
    /// `primary`, `shadow` or `diffuse`.
    pub kind: &'static str,
    /// CPU threads (1 for Vulkan: the host thread that submits).
    pub threads: usize,
    /// Rays traced per repetition.
    pub rays: usize,
    /// Median seconds per repetition (Vulkan: GPU timestamps of the dispatch).
    pub seconds: f64,
    /// Millions of rays per second.
    pub mrays_per_s: f64,
    /// Vulkan: how many traces ran back to back in each timed submission (benchmark mode, 50 ms
    /// a submission; the last repetition's), `seconds` being their mean; 1 on the CPU.
    pub dispatches: u32,
    /// Seconds of the untimed warm-up before the measurement: on Vulkan until the times had not
    /// fallen for 5 s (`--settle-seconds`), long where the GPU had to raise its clocks first; on
    /// the CPU until the tracers, taking turns, had not got faster for [`CPU_SETTLE_SECONDS`]
    /// (one warm-up per thread count and ray kind, shared by its tracers' lines).
    pub warm_up_seconds: f64,
    /// Vulkan compute trace methods: invocations per workgroup; absent on the CPU and for the
    /// ray-tracing pipeline, which have none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub workgroup_size: Option<u32>,
    /// The obvhs build preset of the tree traversed (`fast`, `medium`, `slow`): raywave's CPU and
    /// `sw` traversals and obvhs's; absent for Embree and the driver-built acceleration
    /// structures of `rayquery` and `rtpipe`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bvh: Option<&'static str>,
}

/// The BVH build line: build time and memory per triangle.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BuildMeasurement {
    /// Always `bvh_build`.
    pub stage: &'static str,
    /// Builder and preset.
    #[serde(rename = "impl")]
    pub implementation: String,
    /// Triangles in the scene.
    pub triangles: usize,
    /// Wall-clock build seconds (all threads).
    pub seconds: f64,
    /// BVH nodes + triangle vertices + ids, bytes per triangle (NaN, printed as null, where the
    /// library does not report its memory).
    pub bytes_per_triangle: f64,
    /// The instruction-set build raywave's CPU traversal runs over this BVH (`portable` or
    /// `x86-64-v3`, detected at run time); absent for other libraries' builds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub traversal_isa: Option<&'static str>,
}

/// The three ray sets of one scene.
struct RaySets {
    primary: RayStream,
    shadow: RayStream,
    diffuse: RayStream,
}

/// Primary camera rays; from each primary hit, a shadow ray to a point light above the scene and a
/// cosine-distributed diffuse ray, both from the offset hit point.
fn ray_sets(scene: &Scene, cpu_scene: &CpuScene, resolution: u32) -> Result<RaySets> {
    let primary = cpu::generate(&generate_params(scene, resolution, resolution, 7))?;
    let hits = cpu::trace(cpu_scene, &primary)?;
    let (lo, hi) = scene.bounds();
    let light = Vec3::new((lo.x + hi.x) * 0.5, hi.y + (hi - lo).length() * 0.25, (lo.z + hi.z) * 0.5);
    let mut shadow = RayStream::default();
    let mut diffuse = RayStream::default();
    for i in 0..primary.len() {
        if hits.primitive[i] == NO_HIT {
            continue;
        }
        let view = primary.direction[i].xyz();
        let surface = scene.hit_surface(hits.instance[i], hits.primitive[i], hits.barycentrics[i], view);
        let (origin, n) = (surface.secondary_ray_origin(), surface.normal);
        let to_light = light - origin;
        shadow.origin.push(origin.extend(0.0));
        shadow.direction.push(to_light.normalize().extend(to_light.length() * (1.0 - 1e-4)));
        shadow.pixel.push(primary.pixel[i]);
        let h = pcg3d(UVec3::new(i as u32, 0, 99));
        let local = sample_cosine_hemisphere(Vec2::new(unit_float(h.x), unit_float(h.y)));
        let d = local_to_world(n, local);
        diffuse.origin.push(origin.extend(0.0));
        diffuse.direction.push(d.normalize_or(n).extend(primary.direction[i].w));
        diffuse.pixel.push(primary.pixel[i]);
    }
    Ok(RaySets { primary, shadow, diffuse })
}

/// How long a benchmark's times must have stopped falling before it measures, on the CPU
/// ([`warm_up`]): drivers compile pipelines lazily (lavapipe at the first dispatch), caches and
/// branch predictors warm up.
pub const CPU_SETTLE_SECONDS: f64 = 0.5;

/// The same on a GPU, whose clocks follow its load slowly: an NVIDIA H200 that had fallen to its
/// idle 345 MHz held them for ~3 s under the denoise bench's sustained submissions (30–70 %
/// busy) and then rose by ~150 MHz a second (README) — where opening a device gives it its
/// 1980 MHz boost at once, for a few seconds, which load then keeps.
pub const GPU_SETTLE_SECONDS: f64 = 5.0;

/// Longest the times may keep falling: a warm-up of settling time `S` ends at the first run that
/// ends past `S +` this, even if they still fall. Measured beyond `S` (the first round counts as
/// a fall, so a limit of its own would leave settling times near it unreachable).
pub const MAX_FALLING_SECONDS: f64 = 30.0;

/// Longest settling time accepted (`--settle-seconds`).
pub const MAX_SETTLE_SECONDS: f64 = 30.0;

/// The warm-up runs in rounds of at least this long and at least [`WARM_UP_ROUND_RUNS`] runs.
const WARM_UP_ROUND_SECONDS: f64 = 0.25;
const WARM_UP_ROUND_RUNS: usize = 3;

/// A round whose median time is more than this fraction below the best so far counts as still
/// falling.
const FALLING_FRACTION: f64 = 0.02;

/// The GPU busy time, in seconds, each timed Vulkan submission of a benchmark is stretched to by
/// repeating its dispatch ([`crate::BackendOptions::sustain_seconds`]). A GPU clocks down under
/// sparse work: on an NVIDIA H200 (345 MHz idle, 1980 MHz boost) the single dispatches of
/// `raywave bench denoise`, each submitted alone between uploads, kept it 5–10 % busy at 345 MHz,
/// 2.5–5.5× slower than at boost, whenever they missed the few seconds of boost that opening the
/// device gives — on a fresh machine, where compiling the pipelines outlasted them (README).
/// 50 ms of back-to-back dispatches per submission keep it mostly busy, so that it raises its
/// clocks ([`GPU_SETTLE_SECONDS`]) and holds them.
pub const SUSTAIN_SECONDS: f64 = 0.05;

/// `settle_seconds` (`--settle-seconds`) if it is a settling time the warm-up takes:
/// finite, within `0..=`[`MAX_SETTLE_SECONDS`]; else a typed error naming `settle-seconds`.
pub(crate) fn check_settle_seconds(settle_seconds: f64) -> Result<f64> {
    if (0.0..=MAX_SETTLE_SECONDS).contains(&settle_seconds) {
        Ok(settle_seconds)
    } else {
        Err(Error::InvalidParameter {
            name: "settle-seconds",
            reason: format!("{settle_seconds} is not within 0..={MAX_SETTLE_SECONDS} s"),
        })
    }
}

/// Runs `run`, which returns the seconds it measured, untimed until those times have stopped
/// falling for `settle_seconds` ([`CPU_SETTLE_SECONDS`], [`GPU_SETTLE_SECONDS`]): in rounds
/// (`WARM_UP_ROUND_SECONDS`, `WARM_UP_ROUND_RUNS`), each round's median against the best
/// before it (`FALLING_FRACTION`), until the first run that ends past `settle_seconds +`
/// [`MAX_FALLING_SECONDS`] (then with a note on stderr). Returns the warm-up's seconds. Every `raywave bench` runs it before it measures, and
/// so does criterion's `workgroup_size` group.
pub fn warm_up(settle_seconds: f64, run: impl FnMut() -> Result<f64>) -> Result<f64> {
    let start = Instant::now();
    warm_up_on(|| start.elapsed().as_secs_f64(), settle_seconds, run)
}

/// [`warm_up`] on the clock `now`, the seconds since the warm-up began: the wall clock there, a
/// simulated one in the tests, so that they do not depend on how fast the machine runs them.
fn warm_up_on(mut now: impl FnMut() -> f64, settle_seconds: f64, mut run: impl FnMut() -> Result<f64>) -> Result<f64> {
    let (mut best, mut last_fall) = (f64::INFINITY, 0.0);
    let limit = settle_seconds + MAX_FALLING_SECONDS;
    loop {
        let round_start = now();
        let mut times = Vec::new();
        // A round ends early at the limit: runs that each take seconds do not fill one in time.
        while times.is_empty()
            || (times.len() < WARM_UP_ROUND_RUNS || now() - round_start < WARM_UP_ROUND_SECONDS) && now() < limit
        {
            times.push(run()?);
        }
        let (round, elapsed) = (median(times), now());
        if round < best * (1.0 - FALLING_FRACTION) {
            last_fall = elapsed;
        }
        best = best.min(round);
        if elapsed - last_fall >= settle_seconds {
            return Ok(elapsed);
        }
        if elapsed >= limit {
            // The times fell last `elapsed − last_fall` ago (the first round counts as a fall).
            let steady = elapsed - last_fall;
            crate::output_line::warn(&format!(
                "note: warm-up ended at its {limit} s limit ({settle_seconds} s settling + {MAX_FALLING_SECONDS} s) \
                 after {elapsed:.1} s, the times steady for {steady:.1} s of the {settle_seconds} s asked (now \
                 {round:.3e} s a run)"
            ));
            return Ok(elapsed);
        }
    }
}

/// One stage (or pass) of a [`measure`]ment: its median seconds over the timed runs and how many
/// dispatches the last of them repeated.
pub(crate) struct StageMedian {
    pub seconds: f64,
    pub dispatches: u32,
}

/// What [`measure`] took: each stage's median, in the order `run` reports them, the median of
/// the runs' summed stage times (not the sum of the medians), and the seconds of the warm-up
/// before.
pub(crate) struct Measured {
    pub stages: Vec<StageMedian>,
    pub total_seconds: f64,
    pub warm_up_seconds: f64,
}

/// Times `run` — one run of the `stage_count` stages it reports, on one backend — as every
/// `raywave bench` does: a [`warm_up`] of `settle_seconds` on their summed times, then `repeats`
/// timed runs. A run that reports another number of stages — a defect of the backend, not of
/// the options — is an error naming `backend`, not stages silently dropped or a panic.
pub(crate) fn measure(
    settle_seconds: f64,
    repeats: u32,
    stage_count: usize,
    mut run: impl FnMut() -> Result<Vec<StageReport>>,
) -> Result<Measured> {
    let mut checked_run = || {
        let reports = run()?;
        if reports.len() != stage_count {
            let names: Vec<_> = reports.iter().map(|report| report.stage).collect();
            let reason = format!(
                "reported {} stage times {names:?} for a run of {stage_count} stages (a defect of the backend, not \
                 of the options)",
                reports.len()
            );
            return Err(Error::InvalidParameter { name: "backend", reason });
        }
        Ok(reports)
    };
    let warm_up_seconds = warm_up(settle_seconds, || Ok(checked_run()?.iter().map(|r| r.seconds).sum()))?;
    let runs = (0..repeats).map(|_| checked_run()).collect::<Result<Vec<_>>>()?;
    let stages = (0..stage_count)
        .map(|i| StageMedian {
            seconds: median(runs.iter().map(|r| r[i].seconds).collect()),
            dispatches: runs.last().map_or(1, |r| r[i].dispatches),
        })
        .collect();
    let total_seconds = median(runs.iter().map(|r| r.iter().map(|stage| stage.seconds).sum()).collect());
    Ok(Measured { stages, total_seconds, warm_up_seconds })
}

/// The median of a list of timings (the mean of the middle two of an even count; NaN for none,
/// which the benchmarks' checks of their repetitions rule out). Shared by every `raywave bench`.
pub(crate) fn median(mut times: Vec<f64>) -> f64 {
    times.sort_by(f64::total_cmp);
    let middle = times.len() / 2;
    match times.len() {
        0 => f64::NAN,
        n if n % 2 == 0 => 0.5 * (times[middle - 1] + times[middle]),
        _ => times[middle],
    }
}

fn wall(f: impl FnOnce()) -> f64 {
    let start = Instant::now();
    f();
    start.elapsed().as_secs_f64()
}

/// A CPU tracer under measurement: closest hit and occlusion of one stream ray.
trait CpuTracer: Sync {
    /// Closest-hit distance (0 on a miss).
    fn closest_t(&self, origin: Vec4, direction: Vec4) -> f32;
    /// Whether the ray is blocked.
    fn occluded(&self, origin: Vec4, direction: Vec4) -> bool;
}

/// raywave's kernel traversal through the trace stage functions.
struct RaywaveCpu<'a>(&'a CpuScene);

impl CpuTracer for RaywaveCpu<'_> {
    fn closest_t(&self, origin: Vec4, direction: Vec4) -> f32 {
        trace_closest(origin, direction, self.0).value.t
    }
    fn occluded(&self, origin: Vec4, direction: Vec4) -> bool {
        trace_occluded(origin, direction, self.0).value
    }
}

/// obvhs's own traversal of the same tree with the same triangle test.
struct ObvhsReference<'a>(&'a CpuScene);

impl CpuTracer for ObvhsReference<'_> {
    fn closest_t(&self, origin: Vec4, direction: Vec4) -> f32 {
        self.0.obvhs_closest_hit(&Ray::from_stream(origin, direction)).t
    }
    fn occluded(&self, origin: Vec4, direction: Vec4) -> bool {
        self.0.obvhs_occluded(&Ray::from_stream(origin, direction))
    }
}

#[cfg(feature = "embree")]
impl CpuTracer for crate::embree::EmbreeScene {
    fn closest_t(&self, origin: Vec4, direction: Vec4) -> f32 {
        self.closest_hit(&Ray::from_stream(origin, direction)).t
    }
    fn occluded(&self, origin: Vec4, direction: Vec4) -> bool {
        crate::embree::EmbreeScene::occluded(self, &Ray::from_stream(origin, direction))
    }
}

/// Wall-clock seconds for `tracer` to trace all of `rays` in parallel (in the current rayon pool):
/// occlusion for shadow rays, closest hit otherwise.
fn time_cpu(tracer: &dyn CpuTracer, kind: &str, rays: &RayStream) -> f64 {
    let pairs = || rays.origin.par_iter().zip(&rays.direction);
    wall(|| {
        if kind == "shadow" {
            std::hint::black_box(pairs().filter(|(o, d)| tracer.occluded(**o, **d)).count());
        } else {
            std::hint::black_box(pairs().map(|(o, d)| tracer.closest_t(*o, *d)).sum::<f32>());
        }
    })
}

fn measurement(
    implementation: &str,
    kind: &'static str,
    threads: usize,
    rays: usize,
    seconds: f64,
    dispatches: u32,
    warm_up_seconds: f64,
) -> Measurement {
    Measurement {
        stage: "trace",
        implementation: implementation.to_owned(),
        kind,
        threads,
        rays,
        seconds,
        mrays_per_s: per_second(rays as f64, seconds) / 1e6,
        dispatches,
        warm_up_seconds,
        workgroup_size: None,
        bvh: None,
    }
}

/// Checks a benchmark's timed repetitions: at least one, since the median of none is undefined.
pub(crate) fn check_repeats(repeats: u32) -> Result<()> {
    if repeats == 0 {
        return Err(Error::InvalidParameter { name: "repeats", reason: "must be at least 1".into() });
    }
    Ok(())
}

/// Checks a benchmark's `--resolution`, camera rays per side, against the CPU backend's image
/// size (every bench measures the CPU at it), naming the option rather than the backend.
pub(crate) fn check_rays_per_side(side: u32) -> Result<()> {
    match crate::Backend::check_image_size(&crate::cpu::CpuBackend::new(), side, side) {
        Err(Error::ImageSize { reason, .. }) => {
            Err(Error::InvalidParameter { name: "resolution", reason: format!("{side}×{side} rays: {reason}") })
        }
        other => other,
    }
}

/// `count` per second over `seconds`, the time floored at 1 ps: a measurement too short for its
/// clock (0 s) reads as very fast rather than infinite, which JSON cannot hold.
pub(crate) fn per_second(count: f64, seconds: f64) -> f64 {
    count / seconds.max(1e-12)
}

/// Runs the trace benchmark; `emit` receives each measurement as soon as it is taken.
pub fn bench_trace(options: &TraceBenchOptions, mut emit: impl FnMut(&dyn OutputLine)) -> Result<()> {
    // rayon makes at most this many threads, silently: the report would name a count it did not run.
    let max_threads = rayon::max_num_threads();
    if let Some(threads) = options.threads.iter().find(|&&t| !(1..=max_threads).contains(&t)) {
        let reason = format!("{threads} is outside 1..={max_threads}");
        return Err(Error::InvalidParameter { name: "threads", reason });
    }
    check_repeats(options.repeats)?;
    check_rays_per_side(options.resolution)?;
    let image = [options.resolution; 2];
    #[cfg_attr(not(feature = "vulkan"), allow(unused_variables))]
    let vulkan_device = options.vulkan_options.device(options.vulkan, crate::StreamStage::Trace, image)?;
    let scene = Scene::load(&options.scene)?;
    let cpu_scene = CpuScene::build_with(&scene, options.bvh)?;
    emit(&BuildMeasurement {
        stage: "bvh_build",
        implementation: format!("obvhs-cwbvh-{}", options.bvh.name()),
        triangles: scene.triangle_count(),
        seconds: cpu_scene.build_time().as_secs_f64(),
        bytes_per_triangle: cpu_scene.bytes_per_triangle(),
        traversal_isa: Some(cpu_scene.traversal_isa().name()),
    });
    #[cfg(feature = "embree")]
    let embree = {
        let embree = crate::embree::EmbreeScene::build(&scene)?;
        emit(&BuildMeasurement {
            stage: "bvh_build",
            implementation: "embree-high".into(),
            triangles: scene.triangle_count(),
            seconds: embree.build_time().as_secs_f64(),
            bytes_per_triangle: f64::NAN,
            traversal_isa: None,
        });
        embree
    };
    let sets = ray_sets(&scene, &cpu_scene, options.resolution)?;
    let kinds: [(&'static str, &RayStream); 3] =
        [("primary", &sets.primary), ("shadow", &sets.shadow), ("diffuse", &sets.diffuse)];
    for &threads in &options.threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| Error::InvalidParameter { name: "threads", reason: e.to_string() })?;
        for (kind, rays) in kinds {
            let raywave = RaywaveCpu(&cpu_scene);
            let obvhs = ObvhsReference(&cpu_scene);
            // Each with the obvhs preset of the tree it traverses (Embree builds its own).
            let tracers: [(&str, Option<&str>, &dyn CpuTracer); _] = [
                ("raywave-cpu", Some(options.bvh.name()), &raywave),
                ("obvhs", Some(options.bvh.name()), &obvhs),
                #[cfg(feature = "embree")]
                ("embree", None, &embree),
            ];
            let time = |tracer: &dyn CpuTracer| pool.install(|| time_cpu(tracer, kind, rays));
            // Untimed first, as `bench shade` and `bench denoise` measure the CPU: every tracer in
            // turn until their summed times have stopped falling.
            let warm_up_seconds =
                warm_up(CPU_SETTLE_SECONDS, || Ok(tracers.iter().map(|(_, _, tracer)| time(*tracer)).sum()))?;
            // Repetitions interleave the tracers, so that a slow spell of a shared machine lands on
            // all of them alike and their ratios stay comparable.
            let mut times = vec![Vec::new(); tracers.len()];
            for _ in 0..options.repeats {
                for ((_, _, tracer), times) in tracers.iter().zip(&mut times) {
                    times.push(time(*tracer));
                }
            }
            for ((name, bvh, _), times) in tracers.iter().zip(times) {
                let seconds = median(times);
                emit(&Measurement {
                    bvh: *bvh,
                    ..measurement(name, kind, threads, rays.len(), seconds, 1, warm_up_seconds)
                });
            }
        }
    }
    #[cfg(feature = "vulkan")]
    if let Some(device) = &vulkan_device {
        bench_vulkan(options, device, &scene, &kinds, &mut emit)?;
    }
    Ok(())
}

/// Every Vulkan trace method of the best device: closest hit for primary and diffuse rays,
/// occlusion for shadow rays; each after the [`warm_up`], its submissions sustained
/// ([`SUSTAIN_SECONDS`]); the compute methods in each of the options' workgroup sizes.
#[cfg(feature = "vulkan")]
fn bench_vulkan(
    options: &TraceBenchOptions,
    device: &crate::bench_device::BenchDevice,
    scene: &Scene,
    kinds: &[(&'static str, &RayStream); 3],
    emit: &mut impl FnMut(&dyn OutputLine),
) -> Result<()> {
    use crate::{Backend, TraceMethod};
    let no_workgroups = [device.preferred.trace];
    for method in device.info.trace_methods() {
        let has_workgroups = method != TraceMethod::RtPipeline;
        for &size in if has_workgroups { &device.sizes[..] } else { &no_workgroups } {
            let mut backend = device.open(size, Some(method), options.bvh)?;
            backend.load_scene(scene)?;
            for &(kind, rays) in kinds {
                let measured = measure(device.settle_seconds, options.repeats, 1, || {
                    let report = if kind == "shadow" {
                        backend.trace_occlusion(rays).map(|(_, t)| t)
                    } else {
                        backend.trace(rays).map(|(_, t)| t)
                    };
                    Ok(vec![report?])
                })?;
                let trace = &measured.stages[0];
                let name = format!("raywave-vk-{}", method.name());
                let warm_up = measured.warm_up_seconds;
                emit(&Measurement {
                    workgroup_size: has_workgroups.then(|| backend.workgroup_sizes().trace),
                    bvh: (method == TraceMethod::Software).then(|| backend.software_bvh().name()),
                    ..measurement(&name, kind, 1, rays.len(), trace.seconds, trace.dispatches, warm_up)
                });
            }
        }
    }
    Ok(())
}

impl OutputLine for Measurement {
    fn json(&self) -> String {
        json_object(self)
    }
    fn row(&self) -> String {
        let workgroup = crate::bench_device::workgroup_note(self.workgroup_size);
        let bvh = self.bvh.map(|preset| format!("  bvh {preset}")).unwrap_or_default();
        format!(
            "{:<20} {:<8} {:>2} threads {:>9} rays {:>9.4} s {:>8.2} Mrays/s  ×{}{workgroup}{bvh}",
            self.implementation, self.kind, self.threads, self.rays, self.seconds, self.mrays_per_s, self.dispatches
        )
    }
}

impl OutputLine for BuildMeasurement {
    fn json(&self) -> String {
        json_object(self)
    }
    fn row(&self) -> String {
        let isa = self.traversal_isa.map(|isa| format!(", raywave traversal build {isa}")).unwrap_or_default();
        format!(
            "{:<20} {} triangles built in {:.3} s, {:.1} bytes/triangle{isa}",
            self.implementation, self.triangles, self.seconds, self.bytes_per_triangle
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    /// The middle value of an odd count, the mean of the middle two of an even one (`--repeats 2`
    /// had reported the slower run), NaN for none.
    #[test]
    fn the_median_is_the_middle_of_the_sorted_times() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0]), 2.5);
        assert_eq!(median(vec![4.0, 1.0, 3.0, 2.0]), 2.5);
        assert!(median(Vec::new()).is_nan());
    }

    /// A run that reports another number of stages than the bench expects is a typed error, not
    /// stages dropped from the totals or a panic on a missing one.
    #[test]
    fn a_run_with_the_wrong_number_of_stages_is_refused() {
        let report = StageReport::clean("trace", 1e-3);
        let error = measure(0.0, 1, 2, || Ok(vec![report.clone()])).err().expect("refused");
        assert!(matches!(&error, Error::InvalidParameter { name: "backend", .. }), "{error}");
        assert!(measure(0.0, 2, 1, || Ok(vec![report.clone()])).is_ok());
    }

    #[test]
    fn rates_stay_finite_for_a_time_below_the_clock() {
        assert_eq!(per_second(6.0, 2.0), 3.0);
        assert!(per_second(1.0e9, 0.0).is_finite() && per_second(1.0e9, 0.0) > 1.0e20);
    }

    /// Seconds each simulated run takes: a binary fraction, so that the simulated clock adds up
    /// exactly (16 runs make a 0.25 s round).
    const TICK: f64 = 1.0 / 64.0;

    /// Runs [`warm_up_on`] on a simulated clock that each run advances by [`TICK`], run `n` (from
    /// 1) measuring `time(n)`: the warm-up's seconds and how many runs it took.
    fn simulated_warm_up(settle_seconds: f64, time: impl Fn(u32) -> f64) -> (f64, u32) {
        let runs = Cell::new(0);
        let run = || {
            runs.set(runs.get() + 1);
            Ok(time(runs.get()))
        };
        let seconds = warm_up_on(|| f64::from(runs.get()) * TICK, settle_seconds, run).expect("warm-up");
        (seconds, runs.get())
    }

    /// Times that hold for 0.5 s, fall for 0.5 s and hold again — as a GPU's that holds its idle
    /// clocks for a while under load before it raises them: a warm-up that must see no fall for
    /// 0.6 s outlasts the first hold and the fall, and ends within two rounds after 0.6 s more.
    #[test]
    fn the_warm_up_lasts_until_the_times_have_stopped_falling_for_its_settling_time() {
        let (seconds, runs) = simulated_warm_up(0.6, |n| 1.0 / f64::from(n.clamp(32, 64)));
        assert!(runs > 64 + WARM_UP_ROUND_RUNS as u32, "ended after {runs} runs, before the times stopped falling");
        assert!((1.6..=1.6 + 2.0 * WARM_UP_ROUND_SECONDS).contains(&seconds), "{seconds} s, {runs} runs");
        assert_eq!(seconds, f64::from(runs) * TICK, "the seconds are the clock's");
    }

    /// Steady times end the warm-up at its settling time, not before (the first round is a
    /// fall from no time at all); a settling time of 0 after one round.
    #[test]
    fn steady_times_end_the_warm_up_after_its_settling_time() {
        let (seconds, _) = simulated_warm_up(0.3, |_| 1e-3);
        assert!((0.3..=0.3 + 2.0 * WARM_UP_ROUND_SECONDS).contains(&seconds), "{seconds} s");
        assert_eq!(simulated_warm_up(0.0, |_| 1e-3), (WARM_UP_ROUND_SECONDS, 16));
    }

    /// Times that never stop falling end the warm-up [`MAX_FALLING_SECONDS`] past its settling
    /// time.
    #[test]
    fn times_that_keep_falling_end_the_warm_up_at_its_limit() {
        let (seconds, _) = simulated_warm_up(5.0, |n| 0.9f64.powi(n as i32));
        let limit = 5.0 + MAX_FALLING_SECONDS;
        assert!((limit..=limit + WARM_UP_ROUND_SECONDS).contains(&seconds), "{seconds}");
    }

    /// The longest settling time accepted is one steady times meet: they end the warm-up by
    /// settling, its first round's end (the first fall) plus the settling time, not at the limit
    /// (which once lay at 30 s from the start, so that a settling time near 30 s was never met).
    #[test]
    fn steady_times_meet_the_longest_settling_time_accepted() {
        let settle = check_settle_seconds(MAX_SETTLE_SECONDS).expect("the longest settling time");
        let (seconds, _) = simulated_warm_up(settle, |_| 1e-3);
        let settled = WARM_UP_ROUND_SECONDS + settle;
        assert!((settled..=settled + WARM_UP_ROUND_SECONDS).contains(&seconds), "{seconds} s");
        assert!(seconds < settle + MAX_FALLING_SECONDS, "{seconds} s: ended at the limit");
    }

    /// Runs of 20 s each: the warm-up stops at the first run that ends past its limit (two runs,
    /// 40 s), not at the end of a round of three (60 s).
    #[test]
    fn runs_longer_than_the_limit_end_the_warm_up_within_its_first_round() {
        let runs = Cell::new(0u32);
        let run = || {
            runs.set(runs.get() + 1);
            Ok(20.0)
        };
        let seconds = warm_up_on(|| 20.0 * f64::from(runs.get()), 1.0, run).expect("warm-up");
        assert_eq!((seconds, runs.get()), (40.0, 2));
    }

    /// On the wall clock the warm-up returns its own elapsed seconds: at least its settling time.
    #[test]
    fn the_wall_clock_warm_up_reports_at_least_its_settling_time() {
        let seconds = warm_up(0.05, || Ok(1e-3)).expect("warm-up");
        assert!(seconds >= 0.05, "{seconds} s");
    }
}
