//! Criterion micro-benchmarks of the stages (generate, trace, shade, denoise) on the built-in
//! Cornell box and of the samplers they draw from: the CPU executor and,
//! when a Vulkan device opens (the one `--device auto` picks), the Vulkan backend (per call, including upload,
//! dispatch and readback; the GPU-only time is what `raywave render` prints per stage and
//! `raywave bench denoise` per denoise pass) — and two groups on the data layout (DESIGN's
//! "SoA vs AoS, wavefront vs inline"): `layout`, the denoiser's first pass over the SoA streams
//! the stages exchange against the same pass over one record per pixel, and `pipeline`, one
//! sample per pixel through generate → trace → shade → occlusion as wavefront passes over
//! streams against the same kernel functions called one after the other per pixel — and
//! `workgroup_size`, for occupancy tuning: the Vulkan compute trace methods and the shade stage
//! on a 512² frame in workgroups of 32 to 256 invocations (`BackendOptions::workgroup_sizes`),
//! timed by the GPU's timestamps around the dispatch alone, in benchmark mode after a warm-up.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use glam::{UVec2, Vec4};
use rayon::prelude::*;
use raywave::bench_denoise::{frame_input, DenoiseBenchOptions};
use raywave::cpu::{self, CpuScene};
use raywave::denoise::{frame_params, DenoiseMethod};
use raywave::frame::{generate_params, sampler_params};
use raywave::kernels::denoise::noise::ratio_pixel;
use raywave::kernels::generate::generate_ray;
use raywave::kernels::shade::stage::{resolve_surface, shade_sample};
use raywave::kernels::trace::{trace_closest, trace_occluded};
use raywave::shading::{shadow_rays, ShadeAccumulator, ShadeData};
use raywave::shared::sampling::{sampler_kind, SamplerProbeParams};
use raywave::shared::{GenerateParams, ShadeParams};
use raywave::{open_backend, Backend, BackendOptions, DeviceChoice, Scene};
use std::hint::black_box;

/// Image sizes benchmarked: a small tile and a 512² frame.
const SIZES: [(u32, u32); 2] = [(64, 64), (512, 512)];

/// What every group measures on: the built-in Cornell box, laid out for the CPU and, where one
/// opens, the best Vulkan device.
struct Setup {
    scene: Scene,
    cpu_scene: CpuScene,
    cpu: cpu::CpuBackend,
    vulkan: Option<Box<dyn Backend>>,
    data: ShadeData,
}

impl Setup {
    fn new() -> Self {
        let scene = Scene::load("builtin:cornell").expect("built-in scene");
        let mut cpu = cpu::CpuBackend::new();
        cpu.load_scene(&scene).expect("BVH builds");
        let options = BackendOptions { validation: validating(), ..Default::default() };
        let vulkan = match open_backend(DeviceChoice::Vulkan(None), &options) {
            Ok(mut v) => {
                v.load_scene(&scene).expect("acceleration structures build");
                Some(v)
            }
            // `cargo test` runs the benches once; in CI (lavapipe) the Vulkan rows must run too.
            Err(e) if cfg!(feature = "vulkan") && validating() => {
                panic!("CI=true but no Vulkan device opens: {e}")
            }
            Err(e) => {
                eprintln!("no Vulkan device opens ({e}): benchmarking the CPU backend only");
                None
            }
        };
        let (cpu_scene, data) =
            (CpuScene::build(&scene).expect("BVH builds"), ShadeData::new(&scene).expect("shade data"));
        Setup { scene, cpu_scene, cpu, vulkan, data }
    }

    /// The shade parameters of sample 0 of a one-sample `w × h` frame.
    fn shade_params(&self, w: u32, h: u32) -> ShadeParams {
        self.data.params(sampler_params(sampler_kind::ZSOBOL, 1, w, h, 1), w, h, 0)
    }
}

fn stages(c: &mut Criterion) {
    let mut setup = Setup::new();
    sampler(c, &mut setup);
    generate(c, &mut setup);
    trace_primary(c, &mut setup);
    shade(c, &mut setup);
    denoise(c, &mut setup);
    pipeline(c, &mut setup);
    layout(c);
    #[cfg(feature = "vulkan")]
    workgroup_size::group(c, &setup);
    if let Some(vulkan) = setup.vulkan.take() {
        raywave::close_backend(vulkan).expect("the validation layers reported nothing");
    }
}

/// Whether criterion measures (`cargo bench`) rather than runs every benchmark once to check
/// it (`cargo test`, or `--test`), as criterion decides from the same arguments.
fn benchmarking() -> bool {
    let args: Vec<String> = std::env::args().collect();
    args.iter().any(|a| a == "--bench") && !args.iter().any(|a| a == "--test")
}

/// Whether the Vulkan backends open with the validation layers, whose every warning or error
/// fails the run as it closes them: where the benches run once as tests under CI (`CI=true` or
/// `1`, where the layers are installed), not while they measure.
fn validating() -> bool {
    !benchmarking() && std::env::var("CI").is_ok_and(|v| v == "true" || v == "1")
}

/// The samplers alone: one 2-D slot of every sample of a 512² frame at 4 samples per pixel
/// (the sampler probe), per sampler kind. ZSobol hashes each base-4 digit of its index, so it
/// is the costly one; the generate and shade stages draw one such slot per number pair.
fn sampler(c: &mut Criterion, setup: &mut Setup) {
    let mut group = c.benchmark_group("sampler");
    let (w, h) = SIZES[1];
    for (name, kind) in
        [("zsobol", sampler_kind::ZSOBOL), ("sobol", sampler_kind::SOBOL), ("random", sampler_kind::INDEPENDENT)]
    {
        let params = SamplerProbeParams {
            sampler: sampler_params(kind, 0, w, h, 4),
            width: w,
            height: h,
            dimension: 3,
            padding: 0,
        };
        group.throughput(Throughput::Elements(u64::from(params.sample_count())));
        group.bench_function(BenchmarkId::new(format!("cpu-{name}"), params.sample_count()), |b| {
            b.iter(|| setup.cpu.sampler_probe(black_box(&params)).expect("probe"))
        });
        if let Some(v) = setup.vulkan.as_mut() {
            group.bench_function(BenchmarkId::new(format!("vulkan-{name}"), params.sample_count()), |b| {
                b.iter(|| v.sampler_probe(black_box(&params)).expect("probe"))
            });
        }
    }
    group.finish();
}

fn generate(c: &mut Criterion, setup: &mut Setup) {
    let mut group = c.benchmark_group("generate");
    for (w, h) in SIZES {
        let params = generate_params(&setup.scene, w, h, 1);
        group.throughput(Throughput::Elements(u64::from(w * h)));
        group.bench_with_input(BenchmarkId::new("cpu", w * h), &params, |b, p| {
            b.iter(|| cpu::generate(black_box(p)).expect("generate"))
        });
        if let Some(v) = setup.vulkan.as_mut() {
            group.bench_with_input(BenchmarkId::new("vulkan", w * h), &params, |b, p| {
                b.iter(|| v.generate(black_box(p)).expect("generate"))
            });
        }
    }
    group.finish();
}

fn trace_primary(c: &mut Criterion, setup: &mut Setup) {
    let mut group = c.benchmark_group("trace_primary");
    for (w, h) in SIZES {
        let rays = cpu::generate(&generate_params(&setup.scene, w, h, 1)).expect("generate");
        group.throughput(Throughput::Elements(rays.len() as u64));
        group.bench_with_input(BenchmarkId::new("cpu", rays.len()), &rays, |b, r| {
            b.iter(|| cpu::trace(&setup.cpu_scene, black_box(r)).expect("trace"))
        });
        if let Some(v) = setup.vulkan.as_mut() {
            group.bench_with_input(BenchmarkId::new("vulkan", rays.len()), &rays, |b, r| {
                b.iter(|| v.trace(black_box(r)).expect("trace"))
            });
        }
    }
    group.finish();
}

/// Criterion's `workgroup_size` group (with the `vulkan` feature, which opens the device and
/// lists what it runs).
#[cfg(feature = "vulkan")]
mod workgroup_size {
    use super::{
        benchmarking, black_box, cpu, generate_params, open_backend, validating, BackendOptions, DeviceChoice, Setup,
        SIZES,
    };
    use criterion::{BenchmarkId, Criterion, Throughput};
    use raywave::bench::{warm_up, GPU_SETTLE_SECONDS, SUSTAIN_SECONDS};
    use raywave::{Backend, StageReport, TraceMethod, WorkgroupSizes};
    use std::time::Duration;

    /// Workgroup sizes the group compares: powers of two lavapipe and every GPU measured so far
    /// run, the compiled 64 and the preferred shade size 256 among them. Vulkan guarantees only
    /// 128 invocations a workgroup: a device that does not run a size skips it, with a note.
    const WORKGROUP_SIZES: [u32; 4] = [32, 64, 128, 256];

    /// The compute trace methods the best Vulkan device has — software traversal, and ray query
    /// where it has it (`DeviceInfo::trace_methods`, as `raywave bench trace` picks them; the
    /// ray-tracing pipeline has no workgroups) — and the shade stage on the 512² frame, in each
    /// of [`WORKGROUP_SIZES`] the device runs, each size and method a backend of its own. Shade
    /// does not depend on the trace method: it is measured once per size, on the `sw` backend.
    /// As `raywave bench` measures: in benchmark mode ([`SUSTAIN_SECONDS`]), each backend after
    /// a [`warm_up`] that settles for [`GPU_SETTLE_SECONDS`], run before its first measurement
    /// (none where criterion's filter leaves it none, nor where criterion only checks that the
    /// benches run), so that every size meets the GPU at the same clocks. Criterion gets the GPU
    /// time of the dispatches (`StageReport`), not the wall clock around uploads and readbacks,
    /// which would hide what the size changes.
    pub fn group(c: &mut Criterion, setup: &Setup) {
        if setup.vulkan.is_none() {
            return;
        }
        let benchmarking = benchmarking();
        let device = &raywave::device::best_vulkan_device_info().expect("the Vulkan device the setup opened");
        let sizes: Vec<u32> = WORKGROUP_SIZES
            .into_iter()
            .filter(|size| {
                let runs = device.workgroup_sizes.contains(size);
                if !runs {
                    eprintln!("note: {} does not run workgroups of {size}: workgroup_size skips it", device.name);
                }
                runs
            })
            .collect();
        let methods: Vec<TraceMethod> =
            device.trace_methods().into_iter().filter(|&method| method != TraceMethod::RtPipeline).collect();
        let mut group = c.benchmark_group("workgroup_size");
        let (w, h) = SIZES[1];
        let rays = cpu::generate(&generate_params(&setup.scene, w, h, 1)).expect("generate");
        let hits = cpu::trace(&setup.cpu_scene, &rays).expect("trace");
        let params = setup.shade_params(w, h);
        let trace = |v: &mut dyn Backend| v.trace(black_box(&rays)).expect("trace").1;
        let shade = |v: &mut dyn Backend| v.shade(black_box(&params), &setup.data, &rays, &hits).expect("shade").1;
        group.throughput(Throughput::Elements(rays.len() as u64));
        for &size in &sizes {
            for &method in &methods {
                let options = BackendOptions {
                    trace: Some(method),
                    // Criterion's test mode runs each row once: no sustained submissions there.
                    sustain_seconds: if benchmarking { SUSTAIN_SECONDS } else { 0.0 },
                    workgroup_sizes: Some(WorkgroupSizes::all(size)),
                    validation: validating(),
                };
                let choice = DeviceChoice::Vulkan(Some(device.index));
                let mut v = open_backend(choice, &options).expect("a size and trace method the device runs");
                v.load_scene(&setup.scene).expect("acceleration structures build");
                let shades = method == TraceMethod::Software;
                let mut warmed = !benchmarking;
                let mut warm = |v: &mut dyn Backend| {
                    if !std::mem::replace(&mut warmed, true) {
                        warm_up(GPU_SETTLE_SECONDS, || {
                            let shade_seconds = if shades { shade(v).seconds } else { 0.0 };
                            Ok(trace(v).seconds + shade_seconds)
                        })
                        .expect("warm-up");
                    }
                };
                let backend = v.as_mut();
                group.bench_function(BenchmarkId::new(format!("vulkan-{}-trace", method.name()), size), |b| {
                    warm(backend);
                    b.iter_custom(|iters| gpu_time(iters, || trace(backend)))
                });
                if shades {
                    group.bench_function(BenchmarkId::new("vulkan-shade", size), |b| {
                        warm(backend);
                        b.iter_custom(|iters| gpu_time(iters, || shade(backend)))
                    });
                }
                raywave::close_backend(v).expect("the validation layers reported nothing");
            }
        }
        group.finish();
    }

    /// The summed GPU time of `iters` runs of a stage, as criterion's measured time.
    fn gpu_time(iters: u64, mut run: impl FnMut() -> StageReport) -> Duration {
        Duration::from_secs_f64((0..iters).map(|_| run().seconds).sum())
    }
}

/// Resolve + U of every light + one MIS sample per camera ray (per call, on the hits of one
/// primary pass).
fn shade(c: &mut Criterion, setup: &mut Setup) {
    let mut group = c.benchmark_group("shade");
    for (w, h) in SIZES {
        let rays = cpu::generate(&generate_params(&setup.scene, w, h, 1)).expect("generate");
        let hits = cpu::trace(&setup.cpu_scene, &rays).expect("trace");
        let params = setup.shade_params(w, h);
        // With every light's U_S from the GGX lobe's integral (ShadeParams::analytic_residual).
        let residual_params = ShadeParams { analytic_residual: 1, ..params };
        let (cpu, data) = (&mut setup.cpu, &setup.data);
        group.throughput(Throughput::Elements(rays.len() as u64));
        group.bench_function(BenchmarkId::new("cpu", rays.len()), |b| {
            b.iter(|| cpu.shade(black_box(&params), data, &rays, &hits).expect("shade"))
        });
        group.bench_function(BenchmarkId::new("cpu-residual", rays.len()), |b| {
            b.iter(|| cpu.shade(black_box(&residual_params), data, &rays, &hits).expect("shade"))
        });
        if let Some(v) = setup.vulkan.as_mut() {
            group.bench_function(BenchmarkId::new("vulkan", rays.len()), |b| {
                b.iter(|| v.shade(black_box(&params), data, &rays, &hits).expect("shade"))
            });
        }
    }
    group.finish();
}

/// The TV filter and the SVGF baseline on a 1-spp frame, at the radius each image size gets by
/// default (2 at 64², 6 at 512²).
fn denoise(c: &mut Criterion, setup: &mut Setup) {
    let mut group = c.benchmark_group("denoise");
    for (w, h) in SIZES {
        let input = frame_input(&denoise_options(w, h)).expect("the frame shades");
        let params = frame_params(w, h, None);
        group.throughput(Throughput::Elements(u64::from(w * h)));
        for method in [DenoiseMethod::Tv, DenoiseMethod::Svgf] {
            let id = |backend: &str| BenchmarkId::new(format!("{backend}-{}", method.name()), w * h);
            group.bench_function(id("cpu"), |b| {
                b.iter(|| setup.cpu.denoise(method, black_box(&params), &input).expect("denoise"))
            });
            if let Some(v) = setup.vulkan.as_mut() {
                group.bench_function(id("vulkan"), |b| {
                    b.iter(|| v.denoise(method, black_box(&params), &input).expect("denoise"))
                });
            }
        }
    }
    group.finish();
}

/// Wavefront against inline: one 512² sample pass through generate → trace → shade → occlusion
/// as the CPU backend's passes over streams, and as the same kernel functions per pixel
/// ([`inline_pass`]), first checked to give the same estimates.
fn pipeline(c: &mut Criterion, setup: &mut Setup) {
    let (w, h) = (512, 512);
    let generate = generate_params(&setup.scene, w, h, 1);
    let shade_params = setup.shade_params(w, h);
    let (cpu, data, cpu_scene) = (&mut setup.cpu, &setup.data, &setup.cpu_scene);
    // The stages' streams alone, as the inline pass returns its records alone: accumulating
    // them (which the inline pass would need as much) is left out of both.
    let mut wavefront = || {
        let frame = cpu.render(&generate).expect("generate and trace");
        let (shades, _) = cpu.shade(&shade_params, data, &frame.rays, &frame.hits).expect("shade");
        let (occluded, _) = cpu.trace_occlusion(&shadow_rays(&shades)).expect("occlusion");
        (shades, occluded)
    };
    let (shades, occluded) = wavefront();
    let mut sums = ShadeAccumulator::new((w * h) as usize);
    sums.add(&shades, &occluded).expect("one record per pixel");
    let inline = inline_pass(cpu_scene, data, &generate, &shade_params);
    let streams = [sums.analytic(), sums.unshadowed(), sums.shadowed(), sums.emitted()];
    for (i, pixel) in inline.iter().enumerate() {
        assert!(pixel.iter().zip(&streams).all(|(v, stream)| v.truncate() == stream[i]), "pixel {i}");
    }
    let mut group = c.benchmark_group("pipeline");
    group.throughput(Throughput::Elements(u64::from(w * h)));
    group.bench_function(BenchmarkId::new("cpu-wavefront", w * h), |b| b.iter(&mut wavefront));
    group.bench_function(BenchmarkId::new("cpu-inline", w * h), |b| {
        b.iter(|| inline_pass(cpu_scene, data, black_box(&generate), &shade_params))
    });
    group.finish();
}

/// SoA against AoS (DESIGN rule 3): the ratio pass reads S_N and U_N, two of a pixel's six
/// denoiser inputs. Over SoA streams it reads those 32 bytes per pixel; over one 96-byte record
/// per pixel (array of structures) it reads the 64-byte cache line they sit in. One 1080p frame,
/// one thread, the same kernel function.
fn layout(c: &mut Criterion) {
    let (w, h) = (1920, 1080);
    let input = frame_input(&denoise_options(w, h)).expect("the frame shades");
    let records: Vec<PixelRecord> = (0..input.len())
        .map(|i| PixelRecord {
            position: input.position[i],
            normal: input.normal[i],
            analytic: input.analytic[i],
            emitted: input.emitted[i],
            shadowed: input.shadowed[i],
            unshadowed: input.unshadowed[i],
        })
        .collect();
    let mut ratio = vec![Vec4::ZERO; input.len()];
    let mut group = c.benchmark_group("layout");
    group.throughput(Throughput::Elements(u64::from(w * h)));
    group.bench_function(BenchmarkId::new("ratio-soa", w * h), |b| {
        b.iter(|| {
            let streams = input.shadowed.iter().zip(&input.unshadowed);
            for (out, (&s, &u)) in ratio.iter_mut().zip(streams) {
                *out = ratio_pixel(s, u);
            }
            black_box(&ratio);
        })
    });
    group.bench_function(BenchmarkId::new("ratio-aos", w * h), |b| {
        b.iter(|| {
            for (out, record) in ratio.iter_mut().zip(black_box(&records)) {
                *out = ratio_pixel(record.shadowed, record.unshadowed);
            }
            black_box(&ratio);
        })
    });
    group.finish();
}

/// One sample per pixel of `scene` through every stage inline: per pixel, the kernels' generate,
/// closest-hit trace, resolve, shade and occlusion trace one after the other, nothing stored in
/// between. Returns per pixel `U`, `U_N`, `S_N` and the emitted radiance (rgb, w = 0) — what
/// one wavefront pass adds to a `ShadeAccumulator`.
fn inline_pass(scene: &CpuScene, data: &ShadeData, generate: &GenerateParams, shade: &ShadeParams) -> Vec<[Vec4; 4]> {
    let shade_scene = data.view_for(shade);
    (0..generate.ray_count())
        .into_par_iter()
        .map(|i| {
            let ray = generate_ray(i, generate);
            let hit = trace_closest(ray.origin, ray.direction, scene).value;
            let direction = ray.direction.truncate();
            let (triangles, first) = (&data.triangles, &data.first_triangle);
            let surface =
                resolve_surface(direction, hit.t, hit.instance, hit.primitive, hit.barycentrics, triangles, first);
            let pixel = UVec2::new(i % shade.width, i / shade.width);
            let s = shade_sample(shade, pixel, direction, &surface, &shade_scene).value;
            let blocked = trace_occluded(s.shadow_origin, s.shadow_direction, scene).value;
            [s.analytic, s.unshadowed, if blocked { Vec4::ZERO } else { s.unshadowed }, s.emitted]
        })
        .collect()
}

/// The denoise benchmark frame: the built-in Cornell box at `width × height` pixels, one sample
/// per pixel, at the default radius.
fn denoise_options(width: u32, height: u32) -> DenoiseBenchOptions {
    DenoiseBenchOptions {
        scene: "builtin:cornell".to_owned(),
        width,
        height,
        spp: 1,
        repeats: 1,
        vulkan: false,
        peak_gbps: None,
        denoise_radius: None,
        vulkan_options: Default::default(),
    }
}

/// A pixel's six denoiser inputs as one record: the array-of-structures layout the `layout` group
/// compares the SoA streams with.
#[derive(Clone, Copy)]
#[allow(dead_code, reason = "the fields the ratio pass does not read are the point: they share its cache lines")]
struct PixelRecord {
    position: Vec4,
    normal: Vec4,
    analytic: Vec4,
    emitted: Vec4,
    shadowed: Vec4,
    unshadowed: Vec4,
}

criterion_group! {
    name = benches;
    // No plots: criterion's plotters backend panics where fontconfig has no sans-serif face (as
    // on a minimal Debian 12 with only DejaVu Serif and Mono), after the first measurement.
    config = Criterion::default().sample_size(20).without_plots();
    targets = stages
}
criterion_main!(benches);
