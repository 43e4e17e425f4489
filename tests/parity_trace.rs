//! Parity of the trace stage: the CPU executor and every Vulkan device × trace method (software
//! CWBVH traversal, ray query against a BLAS/TLAS) report the same closest hits on the same rays.
//!
//! Tolerance: the same (instance, primitive) for ≥ 99.99 % of rays (rays grazing a shared edge may
//! legitimately pick either triangle); t within 1e-5 relative to max(t, |origin|) — a ray starting
//! next to a surface has a tiny t computed at the origin's scale —; the hit point rebuilt from the
//! barycentrics within 1e-5 of max(t, |point|). Barycentrics themselves are compared through the
//! point they give: on needle triangles (the hairball's are 50× longer than wide) a driver's own
//! intersection arithmetic moves them by ~1e-4 while the point moves by far less than the t error.
#![cfg(feature = "vulkan")]

mod common;

use common::{close, cornell, vulkan};
use raywave::cpu::{self, CpuScene};
use raywave::frame::generate_params;
use raywave::shared::stream::NO_HIT;
use raywave::{Backend, HitStream, RayStream, Scene};

const MIN_AGREEMENT: f64 = 0.9999;
const T_REL_TOLERANCE: f32 = 1e-5;
const POINT_REL_TOLERANCE: f32 = 1e-5;

/// The hit point a record describes, rebuilt from its triangle and barycentrics.
fn hit_point(scene: &Scene, hits: &HitStream, i: usize) -> glam::Vec3 {
    let mesh = &scene.meshes()[hits.instance[i] as usize];
    let [a, b, c] = mesh.triangles[hits.primitive[i] as usize].map(|v| mesh.positions[v as usize]);
    let bary = hits.barycentrics[i];
    a * (1.0 - bary.x - bary.y) + b * bary.x + c * bary.y
}

/// Compares two hit streams and returns the fraction of rays that agree on the hit primitive; a
/// miss must be written as the stream defines it (t and barycentrics 0) on both.
fn compare(scene: &Scene, rays: &RayStream, expected: &HitStream, actual: &HitStream) -> f64 {
    assert_eq!(expected.len(), actual.len());
    let mut same = 0usize;
    for i in 0..expected.len() {
        assert!(actual.t[i].is_finite() && actual.barycentrics[i].is_finite(), "ray {i}: non-finite output");
        for hits in [expected, actual] {
            if hits.primitive[i] == NO_HIT {
                assert_eq!((hits.t[i], hits.barycentrics[i]), (0.0, glam::Vec2::ZERO), "ray {i}: a miss's fields");
            }
        }
        let same_hit = expected.primitive[i] == actual.primitive[i] && expected.instance[i] == actual.instance[i];
        if !same_hit {
            continue;
        }
        same += 1;
        if expected.primitive[i] != NO_HIT {
            let origin_scale = rays.origin[i].truncate().abs().max_element();
            assert!(
                close(expected.t[i], actual.t[i], T_REL_TOLERANCE, origin_scale),
                "ray {i}: t {} vs {}",
                expected.t[i],
                actual.t[i]
            );
            let (p, q) = (hit_point(scene, expected, i), hit_point(scene, actual, i));
            let bound = POINT_REL_TOLERANCE * expected.t[i].max(p.abs().max_element());
            assert!(
                (p - q).length() <= bound,
                "ray {i}: hit points {p} vs {q} (barycentrics {} vs {})",
                expected.barycentrics[i],
                actual.barycentrics[i]
            );
        }
    }
    same as f64 / expected.len() as f64
}

/// Camera rays plus, for variety, rays from inside the box in hashed directions.
fn test_rays(scene: &Scene) -> RayStream {
    let mut rays = cpu::generate(&generate_params(scene, 320, 320, 3)).expect("generate");
    let centre = glam::Vec3::new(0.278, 0.274, 0.28);
    for i in 0..rays.len() / 2 {
        let h = raywave::kernels::hash::pcg3d(glam::UVec3::new(i as u32, 11, 5));
        let u = glam::Vec3::new(h.x as f32, h.y as f32, h.z as f32) / u32::MAX as f32 * 2.0 - 1.0;
        let dir = if u.length_squared() > 1e-6 { u.normalize() } else { glam::Vec3::Y };
        rays.origin[i] = centre.extend(0.0);
        rays.direction[i] = dir.extend(10.0);
    }
    rays
}

#[test]
fn trace_matches_cpu_on_every_vulkan_device() {
    let scene = cornell();
    let cpu_scene = CpuScene::build(&scene).expect("BVH builds");
    let rays = test_rays(&scene);
    assert!(rays.len() >= 100_000);
    let expected = cpu::trace(&cpu_scene, &rays).expect("trace");
    let hit_fraction = expected.primitive.iter().filter(|&&p| p != NO_HIT).count() as f64 / rays.len() as f64;
    // The box is open towards the camera (no front wall), so about a tenth of the rays escape.
    assert!(hit_fraction > 0.85, "the test rays must mostly hit the box ({hit_fraction})");
    for mut device in vulkan::every_device("trace parity") {
        device.load_scene(&scene).expect("acceleration structures build");
        let (hits, _) = device.trace(&rays).expect("trace runs");
        let agreement = compare(&scene, &rays, &expected, &hits);
        assert!(agreement >= MIN_AGREEMENT, "{}: only {:.5} of rays agree", device.info().name, agreement);
        eprintln!("{}: {:.6} of {} rays agree with the CPU", device.info().name, agreement, rays.len());
        vulkan::assert_clean(device);
    }
}

#[test]
fn whole_frame_matches_cpu_on_every_vulkan_device() {
    let scene = cornell();
    let params = generate_params(&scene, 257, 193, 9);
    let mut cpu_backend = raywave::cpu::CpuBackend::new();
    cpu_backend.load_scene(&scene).unwrap();
    let expected = cpu_backend.render(&params).unwrap();
    for mut device in vulkan::every_device("frame parity") {
        device.load_scene(&scene).unwrap();
        let frame = device.render(&params).unwrap();
        common::assert_rays_match(&expected.rays, &frame.rays, &device.name());
        assert!(compare(&scene, &frame.rays, &expected.hits, &frame.hits) >= MIN_AGREEMENT);
        assert_eq!(frame.timings.iter().map(|t| t.stage).collect::<Vec<_>>(), ["generate", "trace"]);
        assert!(frame.timings.iter().all(|t| t.sanitized == 0), "{}: {:?}", device.name(), frame.timings);
        vulkan::assert_clean(device);
    }
}

/// Rays that cannot be traced miss and are not occluded on every backend; the two that are not
/// finite (a NaN origin, an infinite tmax) — not the zero direction or the empty interval
/// (`tmin` 0.3 > `tmax` 0.1, around a hit at t ≈ 0.26) — are counted as sanitized by both the
/// closest-hit and the occlusion trace.
#[test]
fn untraceable_rays_miss_on_every_backend() {
    let scene = cornell();
    let mut rays = RayStream::zeroed(4);
    let ok_dir = glam::Vec4::new(0.0, 0.0, 1.0, 10.0);
    rays.origin = vec![
        glam::Vec4::new(f32::NAN, 0.3, 0.3, 0.0),
        glam::Vec4::new(0.3, 0.3, 0.3, 0.0),
        glam::Vec4::new(0.3, 0.3, 0.3, 0.3),
        glam::Vec4::new(0.3, 0.3, 0.3, 0.0),
    ];
    let empty_interval = glam::Vec4::new(0.0, 0.0, 1.0, 0.1);
    rays.direction = vec![
        ok_dir,
        glam::Vec4::new(0.0, 0.0, 0.0, 10.0),
        empty_interval,
        glam::Vec4::new(0.0, 0.0, 1.0, f32::INFINITY),
    ];
    let mut cpu_backend = raywave::cpu::CpuBackend::new();
    cpu_backend.load_scene(&scene).unwrap();
    // Within an interval that holds it, the empty interval's ray hits the back wall.
    let mut open = rays.clone();
    (open.origin[2].w, open.direction[2].w) = (0.0, 10.0);
    let t = cpu_backend.trace(&open).unwrap().0.t[2];
    assert!(t > 0.1 && t < 0.3, "the empty interval lies around the hit ({t})");
    let (expected, report) = cpu_backend.trace(&rays).unwrap();
    assert!(expected.primitive.iter().all(|&p| p == NO_HIT));
    assert_eq!(report.sanitized, 2, "cpu trace");
    let (occluded, report) = cpu_backend.trace_occlusion(&rays).unwrap();
    assert_eq!((occluded, report.sanitized), (vec![0; 4], 2), "cpu occlusion");
    for mut device in vulkan::every_device("untraceable rays") {
        device.load_scene(&scene).unwrap();
        let (hits, report) = device.trace(&rays).unwrap();
        assert_eq!(hits, expected);
        assert_eq!(report.sanitized, 2, "{} trace", device.name());
        let (occluded, report) = device.trace_occlusion(&rays).unwrap();
        assert_eq!((occluded, report.sanitized), (vec![0; 4], 2), "{} occlusion", device.name());
        vulkan::assert_clean(device);
    }
}

/// Rays whose directions are as short as a traceable ray's may be ([`MIN_DIRECTION`]), or as
/// long ([`MAX_DIRECTION`]), hit what the same rays of direction `d / scale` hit, at `t / scale`,
/// on every backend — an axis-aligned one too, whose zero components the box test floors far
/// below it (a floor as large as the direction had traced `(0, 0, d)` as a diagonal and missed);
/// shorter and longer ones miss uncounted.
#[test]
fn the_shortest_and_longest_traceable_directions_hit_what_unit_ones_hit_on_every_backend() {
    use raywave::kernels::trace::{MAX_DIRECTION, MIN_DIRECTION};
    let scene = cornell();
    // Largest component 1: scaled by MIN_DIRECTION, exactly the shortest traceable.
    let units = [glam::Vec3::Z, glam::Vec3::NEG_Y, glam::Vec3::X, glam::Vec3::new(0.375, -0.625, 1.0)];
    let origin = glam::Vec4::new(0.3, 0.3, 0.3, 0.0);
    let stream = |scale: f32, tmax: f32| RayStream {
        origin: vec![origin; units.len()],
        direction: units.iter().map(|d| (*d * scale).extend(tmax)).collect(),
        pixel: (0..units.len() as u32).collect(),
    };
    let cpu_scene = CpuScene::build(&scene).unwrap();
    let unit = cpu::trace(&cpu_scene, &stream(1.0, 10.0)).expect("trace");
    assert!(unit.primitive.iter().all(|&p| p != NO_HIT), "every ray hits the box");
    // (the rays, their hits on the CPU) at the shortest and the longest traceable directions.
    let traceable: Vec<(RayStream, HitStream)> = [MIN_DIRECTION, MAX_DIRECTION]
        .into_iter()
        .map(|scale| {
            let rays = stream(scale, 10.0 / scale);
            let hits = cpu::trace(&cpu_scene, &rays).expect("trace");
            for i in 0..units.len() {
                let what = format!("ray {i}, direction × {scale:e}");
                assert_eq!((hits.instance[i], hits.primitive[i]), (unit.instance[i], unit.primitive[i]), "{what}");
                let t = hits.t[i] * scale;
                assert!((t - unit.t[i]).abs() <= T_REL_TOLERANCE * unit.t[i], "{what}: {t} vs {}", unit.t[i]);
            }
            (rays, hits)
        })
        .collect();
    // (the rays, their misses on the CPU) shorter and longer than traceable.
    let untraceable: Vec<(RayStream, HitStream)> =
        [stream(0.5 * MIN_DIRECTION, 20.0 / MIN_DIRECTION), stream(4.0 * MAX_DIRECTION, 1.0)]
            .into_iter()
            .map(|rays| {
                let (misses, sanitized) = cpu::trace_counted(&cpu_scene, &rays).expect("trace");
                assert!(misses.primitive.iter().all(|&p| p == NO_HIT) && sanitized == 0, "not traceable, not replaced");
                (rays, misses)
            })
            .collect();
    let (shortest, shorter) = (&traceable[0].0, &untraceable[0].0);
    for mut device in vulkan::every_device("shortest and longest directions") {
        device.load_scene(&scene).unwrap();
        for (rays, expected) in &traceable {
            let (hits, report) = device.trace(rays).unwrap();
            assert_eq!(compare(&scene, rays, expected, &hits), 1.0, "{}", device.name());
            assert_eq!(report.sanitized, 0, "{}", device.name());
        }
        for (rays, misses) in &untraceable {
            let (hits, report) = device.trace(rays).unwrap();
            assert_eq!((&hits, report.sanitized), (misses, 0), "{}", device.name());
        }
        let (occluded, report) = device.trace_occlusion(shortest).unwrap();
        assert_eq!((occluded, report.sanitized), (vec![1; units.len()], 0), "{}", device.name());
        let (occluded, report) = device.trace_occlusion(shorter).unwrap();
        assert_eq!((occluded, report.sanitized), (vec![0; units.len()], 0), "{}", device.name());
        vulkan::assert_clean(device);
    }
}

/// Every backend refuses to trace — closest hits, occlusion, a whole frame — before a scene is
/// loaded, with the same typed error naming the scene.
#[test]
fn tracing_without_a_scene_is_refused_on_every_backend() {
    let scene = cornell();
    let rays = test_rays(&scene);
    let params = generate_params(&scene, 8, 6, 1);
    let refusals = |backend: &mut dyn Backend| {
        let name = |result: raywave::Result<()>| match result {
            Err(raywave::Error::InvalidParameter { name, .. }) => name,
            other => panic!("{other:?}"),
        };
        [
            name(backend.trace(&rays).map(drop)),
            name(backend.trace_occlusion(&rays).map(drop)),
            name(backend.render(&params).map(drop)),
        ]
    };
    assert_eq!(refusals(&mut cpu::CpuBackend::new()), ["scene"; 3], "cpu");
    for mut device in vulkan::every_device("tracing without a scene") {
        assert_eq!(refusals(&mut device), ["scene"; 3], "{}", device.name());
        vulkan::assert_clean(device);
    }
}

/// Rays from random points in the scene bounds in random directions (incoherent, like diffuse
/// bounces), plus the scene's camera rays.
fn incoherent_rays(scene: &Scene, count: u32) -> RayStream {
    let mut rays = cpu::generate(&generate_params(scene, 128, 128, 5)).expect("generate");
    let (lo, hi) = scene.bounds();
    for i in 0..count {
        let h = raywave::kernels::hash::pcg3d(glam::UVec3::new(i, 21, 8));
        let g = raywave::kernels::hash::pcg3d(glam::UVec3::new(i, 22, 8));
        let u = |bits: u32| raywave::kernels::hash::unit_float(bits);
        let origin = lo + (hi - lo) * glam::Vec3::new(u(h.x), u(h.y), u(h.z));
        let dir = glam::Vec3::new(u(g.x) - 0.5, u(g.y) - 0.5, u(g.z) - 0.5).normalize_or(glam::Vec3::Y);
        rays.origin.push(origin.extend(0.0));
        rays.direction.push(dir.extend((hi - lo).length()));
        rays.pixel.push(i);
    }
    rays
}

#[test]
fn trace_matches_cpu_on_incoherent_scenes() {
    use raywave::scene::procedural::{hairball, sphere_field};
    let (hair_meshes, hair_camera) = hairball(50_000, 4).expect("a hairball");
    let (sphere_meshes, sphere_camera) = sphere_field(2, 4).expect("a sphere field");
    let scenes = [
        Scene::new("hairball", hair_meshes, hair_camera).unwrap(),
        Scene::new("spheres", sphere_meshes, sphere_camera).unwrap(),
    ];
    for scene in &scenes {
        let rays = incoherent_rays(scene, 100_000);
        let expected = cpu::trace(&CpuScene::build(scene).unwrap(), &rays).expect("trace");
        let hits = expected.primitive.iter().filter(|&&p| p != NO_HIT).count();
        assert!(hits > rays.len() / 10, "{}: the rays must hit often ({hits})", scene.name());
        for mut device in vulkan::every_device("incoherent parity") {
            device.load_scene(scene).unwrap();
            let (actual, _) = device.trace(&rays).unwrap();
            let agreement = compare(scene, &rays, &expected, &actual);
            eprintln!("{} on {}: {agreement:.6} of {} rays agree", device.name(), scene.name(), rays.len());
            assert!(agreement >= MIN_AGREEMENT, "{} on {}: {agreement}", device.name(), scene.name());
            vulkan::assert_clean(device);
        }
    }
}

#[test]
fn occlusion_matches_cpu_on_every_vulkan_device() {
    let (meshes, camera) = raywave::scene::procedural::hairball(50_000, 6).expect("a hairball");
    let scene = Scene::new("hairball", meshes, camera).unwrap();
    let mut rays = incoherent_rays(&scene, 100_000);
    // Shorter intervals than the scene, so both blocked and free rays are common.
    for d in &mut rays.direction {
        d.w = 1.0;
    }
    let cpu_scene = CpuScene::build(&scene).unwrap();
    let (expected, sanitized) = cpu::trace_occlusion_counted(&cpu_scene, &rays).expect("occlusion");
    assert_eq!(sanitized, 0);
    let blocked = expected.iter().filter(|&&o| o == 1).count();
    assert!(blocked > rays.len() / 10 && blocked < rays.len() * 9 / 10, "a mix of blocked and free rays ({blocked})");
    for mut device in vulkan::every_device("occlusion parity") {
        device.load_scene(&scene).unwrap();
        let (occluded, report) = device.trace_occlusion(&rays).unwrap();
        assert_eq!((report.stage, report.sanitized), ("occlusion", 0));
        assert!(occluded.iter().all(|&o| o <= 1));
        let agree = occluded.iter().zip(&expected).filter(|(a, b)| a == b).count();
        let agreement = agree as f64 / rays.len() as f64;
        eprintln!("{} occlusion: {agreement:.6} of {} rays agree", device.name(), rays.len());
        assert!(agreement >= MIN_AGREEMENT, "{}: {agreement}", device.name());
        vulkan::assert_clean(device);
    }
}

/// Several threads opening, tracing with and dropping their own backends at once, as an engine
/// may, all finish and agree with the CPU. On NVIDIA's driver this hung until the backend ordered
/// device creation and destruction against the other threads' driver calls (`vulkan/driver_lock.rs`).
#[test]
fn backends_on_several_threads_at_once_match_cpu() {
    const THREADS: usize = 4;
    const ROUNDS: usize = 2;
    let scene = cornell();
    let cpu_scene = CpuScene::build(&scene).unwrap();
    let rays = cpu::generate(&generate_params(&scene, 64, 48, 1)).expect("generate");
    let expected = cpu::trace(&cpu_scene, &rays).expect("trace");
    let start = std::sync::Barrier::new(THREADS);
    std::thread::scope(|threads| {
        for thread in 0..THREADS {
            let (scene, rays, expected, start) = (&scene, &rays, &expected, &start);
            threads.spawn(move || {
                start.wait();
                for round in 0..ROUNDS {
                    for mut device in vulkan::every_device("threaded trace parity") {
                        device.load_scene(scene).unwrap();
                        let (hits, _) = device.trace(rays).unwrap();
                        let agreement = compare(scene, rays, expected, &hits);
                        let name = device.name();
                        assert!(agreement >= MIN_AGREEMENT, "thread {thread} round {round} {name}: {agreement}");
                        vulkan::assert_clean(device);
                    }
                }
            });
        }
    });
}
