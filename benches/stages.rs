//! Criterion micro-benchmarks of the stages (generate, trace, shade) on the built-in Cornell box:
//! the CPU executor and,
//! when a Vulkan device with ray query is present, the Vulkan backend (per call, including upload,
//! dispatch and readback; the GPU-only time is what `raywave render` prints per stage).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use raywave::cpu::{self, CpuScene};
use raywave::frame::{generate_params, sampler_params};
use raywave::shading::ShadeData;
use raywave::shared::sampling::sampler_kind;
use raywave::shared::ShadeParams;
use raywave::{open_backend, Backend, BackendOptions, DeviceChoice, Scene};
use std::hint::black_box;

/// Image sizes benchmarked: a small tile and a 512² frame.
const SIZES: [(u32, u32); 2] = [(64, 64), (512, 512)];

fn stages(c: &mut Criterion) {
    let scene = Scene::load("builtin:cornell").expect("built-in scene");
    let cpu_scene = CpuScene::build(&scene).expect("BVH builds");
    let mut vulkan = open_backend(DeviceChoice::Vulkan(None), &BackendOptions::default()).ok();
    match vulkan.as_mut() {
        Some(v) => v.load_scene(&scene).expect("acceleration structures build"),
        None => eprintln!("no Vulkan device with ray query: benchmarking the CPU backend only"),
    }

    let mut group = c.benchmark_group("generate");
    for (w, h) in SIZES {
        let params = generate_params(&scene, w, h, 0, 1);
        group.throughput(Throughput::Elements(u64::from(w * h)));
        group.bench_with_input(BenchmarkId::new("cpu", w * h), &params, |b, p| b.iter(|| cpu::generate(black_box(p))));
        if let Some(v) = vulkan.as_mut() {
            group.bench_with_input(BenchmarkId::new("vulkan", w * h), &params, |b, p| {
                b.iter(|| v.generate(black_box(p)).expect("generate"))
            });
        }
    }
    group.finish();

    let mut group = c.benchmark_group("trace_primary");
    for (w, h) in SIZES {
        let rays = cpu::generate(&generate_params(&scene, w, h, 0, 1));
        group.throughput(Throughput::Elements(rays.len() as u64));
        group.bench_with_input(BenchmarkId::new("cpu", rays.len()), &rays, |b, r| {
            b.iter(|| cpu::trace(&cpu_scene, black_box(r)))
        });
        if let Some(v) = vulkan.as_mut() {
            group.bench_with_input(BenchmarkId::new("vulkan", rays.len()), &rays, |b, r| {
                b.iter(|| v.trace(black_box(r)).expect("trace"))
            });
        }
    }
    group.finish();

    // Shade: resolve + U of every light + one MIS sample per camera ray (per call, on the hits of
    // one primary pass).
    let data = ShadeData::new(&scene).expect("shade data");
    let mut cpu_backend = cpu::CpuBackend::new();
    cpu_backend.load_scene(&scene).expect("BVH builds");
    let mut group = c.benchmark_group("shade");
    for (w, h) in SIZES {
        let rays = cpu::generate(&generate_params(&scene, w, h, 0, 1));
        let hits = cpu::trace(&cpu_scene, &rays);
        let params = data.params(sampler_params(sampler_kind::ZSOBOL, 1, w, h, 1), w, h, 0);
        group.throughput(Throughput::Elements(rays.len() as u64));
        group.bench_function(BenchmarkId::new("cpu", rays.len()), |b| {
            b.iter(|| cpu_backend.shade(black_box(&params), &data, &rays, &hits).expect("shade"))
        });
        // With every light's U_S from the GGX lobe's integral (ShadeParams::analytic_residual).
        let residual_params = ShadeParams { analytic_residual: 1, ..params };
        group.bench_function(BenchmarkId::new("cpu-residual", rays.len()), |b| {
            b.iter(|| cpu_backend.shade(black_box(&residual_params), &data, &rays, &hits).expect("shade"))
        });
        if let Some(v) = vulkan.as_mut() {
            group.bench_function(BenchmarkId::new("vulkan", rays.len()), |b| {
                b.iter(|| v.shade(black_box(&params), &data, &rays, &hits).expect("shade"))
            });
        }
    }
    group.finish();
}

criterion_group! {
    name = benches;
    // No plots: criterion's plotters backend panics where fontconfig has no sans-serif face (as
    // on a minimal Debian 12 with only DejaVu Serif and Mono), after the first measurement.
    config = Criterion::default().sample_size(20).without_plots();
    targets = stages
}
criterion_main!(benches);
