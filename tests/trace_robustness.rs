//! Hard cases of the trace stage, on the CPU and on every Vulkan device × trace method:
//! watertightness at shared edges and vertices, self-intersection of offset secondary rays far
//! from and near the origin, axis-aligned and grazing rays, tiny and huge triangles — each traced
//! for the closest hit and by the occlusion (any-hit) variant, with no value replaced in either.

mod common;

use glam::{UVec3, Vec3};
use raywave::cpu::{self, CpuScene};
use raywave::kernels::hash::{pcg3d, unit_float};
use raywave::kernels::offset::{offset_ray_origin, triangle_extent};
use raywave::kernels::triangle::geometric_normal;
use raywave::scene::procedural::icosphere;
use raywave::scene::{Camera, Material, Mesh};
use raywave::shared::stream::NO_HIT;
use raywave::{HitStream, RayStream, Scene};

/// Uniform random vector in [0, 1)³ from a counter.
fn random3(i: u32, stream: u32) -> Vec3 {
    let h = pcg3d(UVec3::new(i, stream, 0x5eed));
    Vec3::new(unit_float(h.x), unit_float(h.y), unit_float(h.z))
}

/// Uniform random unit vector.
fn random_direction(i: u32, stream: u32) -> Vec3 {
    let u = random3(i, stream);
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = std::f32::consts::TAU * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

fn scene_of(meshes: Vec<Mesh>) -> Scene {
    let camera = Camera {
        position: Vec3::new(0.0, 0.0, -10.0),
        look_at: Vec3::ZERO,
        up: Vec3::Y,
        vertical_fov_degrees: 40.0,
        mirrored: false,
    };
    Scene::new("robustness", meshes, camera).expect("valid test scene")
}

/// A ray stream with unit directions, so `tmax` and hit distances are in scene units.
fn rays_from(origins: &[Vec3], directions: &[Vec3], tmax: f32) -> RayStream {
    RayStream {
        origin: origins.iter().map(|o| o.extend(0.0)).collect(),
        direction: directions.iter().map(|d| d.normalize().extend(tmax)).collect(),
        pixel: (0..origins.len() as u32).collect(),
    }
}

/// One backend's answer: its name, whether the triangle test is the driver's (ray query) rather
/// than raywave's own watertight kernel, the closest hits, the occlusion results (1 = blocked), and
/// how many values of the trace and occlusion stages went non-finite and were replaced
/// ([`raywave::StageReport::sanitized`]).
struct Traced {
    backend: String,
    driver_intersection: bool,
    hits: HitStream,
    occluded: Vec<u32>,
    sanitized: [u64; 2],
}

/// Traces `rays` on the CPU and on every Vulkan device × trace method, for the closest hits and
/// with the occlusion (any-hit) variant the shadow rays take. Every answer holds one hit record per
/// ray (a short stream would make the counts below vacuous), replaced no value in either stage —
/// the stages turn a non-finite hit into a miss, which a test expecting a miss would otherwise
/// pass — and blocks exactly the rays it found a closest hit for: the hard rays meet the same
/// triangles in both traversals.
fn trace_everywhere(test: &str, scene: &Scene, rays: &RayStream) -> Vec<Traced> {
    let cpu_scene = CpuScene::build(scene).expect("BVH builds");
    let (hits, trace_sanitized) = cpu::trace_counted(&cpu_scene, rays).expect("trace");
    let (occluded, occlusion_sanitized) = cpu::trace_occlusion_counted(&cpu_scene, rays).expect("occlusion");
    let cpu = Traced {
        backend: "cpu".to_owned(),
        driver_intersection: false,
        hits,
        occluded,
        sanitized: [trace_sanitized, occlusion_sanitized],
    };
    let traced: Vec<Traced> = std::iter::once(cpu).chain(trace_on_vulkan(test, scene, rays)).collect();
    for t in &traced {
        let occluded = &t.occluded;
        t.hits.check("trace").expect("hit fields of one length");
        assert_eq!(t.hits.len(), rays.origin.len(), "{test}: {} answered a different number of rays", t.backend);
        assert_eq!(t.sanitized, [0, 0], "{test}: {} replaced non-finite [trace, occlusion] values", t.backend);
        assert_eq!(occluded.len(), rays.origin.len(), "{test}: {} answered a different number of rays", t.backend);
        let disagreeing: Vec<usize> =
            (0..occluded.len()).filter(|&i| (occluded[i] == 1) != (t.hits.primitive[i] != NO_HIT)).collect();
        assert!(
            disagreeing.is_empty(),
            "{test}: {}: {} rays blocked or not against their closest hit, first {:?}",
            t.backend,
            disagreeing.len(),
            &disagreeing[..disagreeing.len().min(8)]
        );
    }
    traced
}

/// Counts the rays that hit something among the first `leaving` rays, and among the rest (the
/// control rays, each sent back into the surface it left) those that missed it or met it farther
/// than 1.5 × their origin's distance from their start point `starts[j]`: a tracer that drops hits
/// near a ray's origin, or an offset too large, fails the control.
fn self_hits_and_failed_controls(traced: &Traced, rays: &RayStream, leaving: usize, starts: &[Vec3]) -> (usize, usize) {
    let self_hits = traced.hits.primitive[..leaving].iter().filter(|&&p| p != NO_HIT).count();
    let failed_controls = (leaving..rays.origin.len())
        .filter(|&i| {
            let offset = rays.origin[i].truncate().distance(starts[i - leaving]);
            let near = traced.hits.t[i] <= 1.5 * offset; // false for a NaN distance
            traced.hits.primitive[i] == NO_HIT || !near
        })
        .count();
    (self_hits, failed_controls)
}

/// [`trace_everywhere`]'s answers from every Vulkan device × trace method.
#[cfg(feature = "vulkan")]
fn trace_on_vulkan(test: &str, scene: &Scene, rays: &RayStream) -> Vec<Traced> {
    use raywave::Backend;
    common::vulkan::every_device(test)
        .into_iter()
        .map(|mut device| {
            device.load_scene(scene).expect("scene loads");
            let (hits, trace) = device.trace(rays).expect("trace runs");
            let (occluded, occlusion) = device.trace_occlusion(rays).expect("occlusion runs");
            let driver_intersection = device.trace_method() != raywave::TraceMethod::Software;
            let backend = device.name();
            common::vulkan::assert_clean(device);
            let sanitized = [trace.sanitized, occlusion.sanitized];
            Traced { backend, driver_intersection, hits, occluded, sanitized }
        })
        .collect()
}

#[cfg(not(feature = "vulkan"))]
fn trace_on_vulkan(_test: &str, _scene: &Scene, _rays: &RayStream) -> Vec<Traced> {
    Vec::new()
}

/// Largest leak rates accepted from a driver's own ray–triangle test on a closed mesh, of rays aimed
/// exactly at a vertex and at a point on an edge. The Vulkan spec requires watertightness on closed
/// fans, but lavapipe (mesa 25.0.7, ray query) leaks 1.1 % of the rays aimed at vertices (5 404 of
/// 500 000, from inside and from outside alike) and 0.009 % of those aimed at edges (45); these
/// bounds catch a regression from that, and raywave's own traversal (`--trace sw`) is held to zero.
const DRIVER_LEAK_RATE_BOUND: [f64; 2] = [0.02, 0.0005];

#[test]
fn no_ray_leaks_through_shared_edges_and_vertices_of_closed_spheres() {
    const RAYS: u32 = 1_000_000;
    let sphere = icosphere("sphere", Vec3::new(0.3, -0.2, 0.1), 1.0, 3, Vec3::ONE).expect("an icosphere");
    let (positions, triangles) = (sphere.positions.clone(), sphere.triangles.clone());
    let scene = scene_of(vec![sphere]);
    let mut origins = Vec::with_capacity(RAYS as usize);
    let mut directions = Vec::with_capacity(RAYS as usize);
    for i in 0..RAYS {
        // Aim at a vertex (i % 4 = 0, 1) or at a point on an edge (shared by two triangles;
        // i % 4 = 2, 3) of a random triangle, from inside (even i) or outside (odd i).
        let t = triangles[(pcg3d(UVec3::new(i, 1, 3)).x % triangles.len() as u32) as usize];
        let r = random3(i, 2);
        let (a, b) = (positions[t[(i % 3) as usize] as usize], positions[t[((i + 1) % 3) as usize] as usize]);
        let target = if i % 4 < 2 { a } else { a.lerp(b, r.x) };
        // Half the rays start inside; half start outside and come in steeply (within 30° of the
        // inward radial direction), so every ray must cross the surface at or before the target.
        // (Rays grazing the silhouette can legitimately miss a convex mesh: they are not leaks.)
        let centre = Vec3::new(0.3, -0.2, 0.1);
        let origin = if i % 2 == 0 {
            centre + (r - 0.5) * 0.8
        } else {
            let outward = ((target - centre).normalize() + random_direction(i, 4) * 0.5).normalize();
            target + outward * (0.5 + 2.0 * r.y)
        };
        origins.push(origin);
        directions.push(target - origin);
    }
    let rays = rays_from(&origins, &directions, 10.0);
    // Every backend is counted before any is judged, so one run reports them all.
    let mut failures = Vec::new();
    for traced in trace_everywhere("watertightness", &scene, &rays) {
        // Leaks by category: [inside, outside] × [vertex, edge]. An inside ray that slips through
        // misses (nothing is outside the sphere); an outside ray that slips through at its target
        // goes on to the far side, so it leaks if it meets nothing at or before the target.
        let mut leaks = [[0u32; 2]; 2];
        for (i, (&p, &t)) in traced.hits.primitive.iter().zip(&traced.hits.t).enumerate() {
            let to_target = directions[i].length();
            let leaked = p == NO_HIT || (i % 2 == 1 && t > to_target * (1.0 + 1e-4));
            if leaked {
                leaks[i % 2][usize::from(i % 4 >= 2)] += 1;
            }
        }
        let total: u32 = leaks.iter().flatten().sum();
        let report = format!(
            "{}: {total} of {RAYS} rays leaked (inside: {} at vertices, {} at edges; outside: {} at vertices, {} at edges)",
            traced.backend, leaks[0][0], leaks[0][1], leaks[1][0], leaks[1][1]
        );
        eprintln!("{report}");
        let within_bounds = if traced.driver_intersection {
            DRIVER_LEAK_RATE_BOUND
                .iter()
                .enumerate()
                .all(|(kind, bound)| f64::from(leaks[0][kind] + leaks[1][kind]) / f64::from(RAYS / 2) <= *bound)
        } else {
            total == 0
        };
        if !within_bounds {
            failures.push(report);
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn offset_secondary_rays_never_hit_their_own_convex_surface() {
    const RAYS_PER_SCALE: u32 = 250_000;
    // Distance of the sphere from the origin, and its radius.
    let scales = [(1e-3f32, 5e-4f32), (1.0, 0.5), (1e3, 1.0), (1e5, 1.0)];
    for (scale_index, (distance, radius)) in scales.into_iter().enumerate() {
        let centre = Vec3::splat(distance / 3f32.sqrt());
        let sphere = icosphere("sphere", centre, radius, 3, Vec3::ONE).expect("an icosphere");
        let scene = scene_of(vec![sphere.clone()]);
        // Primary rays from outside towards random points near the sphere's centre.
        let primary_origins: Vec<Vec3> =
            (0..RAYS_PER_SCALE).map(|i| centre + random_direction(i, 10 + scale_index as u32) * radius * 3.0).collect();
        let primary_dirs: Vec<Vec3> = primary_origins
            .iter()
            .enumerate()
            .map(|(i, o)| centre + (random3(i as u32, 20) - 0.5) * radius - *o)
            .collect();
        let primary =
            cpu::trace(&CpuScene::build(&scene).unwrap(), &rays_from(&primary_origins, &primary_dirs, radius * 10.0))
                .expect("trace");
        // Secondary rays: from the barycentric hit point, offset along the outward geometric
        // normal, into the outward hemisphere (grazing directions included). The icosphere is
        // convex, so any hit is a false self-intersection.
        let mut origins = Vec::new();
        let mut directions = Vec::new();
        // (origin, direction, surface point) of the control rays.
        let mut controls = Vec::new();
        for i in 0..RAYS_PER_SCALE as usize {
            assert_ne!(primary.primitive[i], NO_HIT, "primary ray {i} at scale {distance} missed");
            let [a, b, c] = sphere.triangles[primary.primitive[i] as usize].map(|v| sphere.positions[v as usize]);
            let bary = primary.barycentrics[i];
            let p = a * (1.0 - bary.x - bary.y) + b * bary.x + c * bary.y;
            let mut n = geometric_normal(a, b, c);
            if n.dot(p - centre) < 0.0 {
                n = -n;
            }
            let d = random_direction(i as u32, 30 + scale_index as u32);
            let d = if d.dot(n) < 0.0 { d - 2.0 * d.dot(n) * n } else { d };
            // Every 8th ray grazes: 1e-4 rad above the tangent plane.
            let d = if i % 8 == 0 { (d - d.dot(n) * n).normalize_or(n.any_orthonormal_vector()) + n * 1e-4 } else { d };
            let origin = offset_ray_origin(p, n, triangle_extent(a, b, c));
            origins.push(origin);
            directions.push(d);
            // Every 16th point also sends a control ray straight back in.
            if i % 16 == 0 {
                controls.push((origin, -n, p));
            }
        }
        let leaving = origins.len();
        origins.extend(controls.iter().map(|c| c.0));
        directions.extend(controls.iter().map(|c| c.1));
        let starts: Vec<Vec3> = controls.iter().map(|c| c.2).collect();
        let rays = rays_from(&origins, &directions, radius * 10.0);
        for traced in trace_everywhere("self-intersection", &scene, &rays) {
            let (false_hits, failed) = self_hits_and_failed_controls(&traced, &rays, leaving, &starts);
            assert_eq!(false_hits, 0, "{}: {false_hits} self-hits at distance {distance}", traced.backend);
            assert_eq!(
                failed, 0,
                "{}: {failed} control rays did not meet the surface they left at distance {distance}",
                traced.backend
            );
        }
    }
}

/// A ground plane through the origin (two triangles, 2·10^k across), left from points within 30 %
/// of its size of the origin by rays into the upper hemisphere, most of them grazing: the plane
/// is flat, so any hit is a false self-intersection. With the offset counted in ulps of each of
/// the point's coordinates, whose height is 0 (Wächter & Binder), about 5 % of such rays met a
/// 2 km plane again and a third a 20 km one (`raywave_kernels::offset`); the offset now scales
/// with the triangle's extent.
#[test]
fn rays_leaving_large_planes_through_the_origin_never_meet_them() {
    const RAYS_PER_SIZE: u32 = 50_000;
    for (size_index, half_size) in [1.0f32, 1e3, 1e4, 1e6].into_iter().enumerate() {
        let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
        let ground = Mesh {
            name: "ground".into(),
            positions: corners.iter().map(|&(x, z)| Vec3::new(x, 0.0, z) * half_size).collect(),
            triangles: vec![[0, 2, 1], [0, 3, 2]],
            material: raywave::scene::Material::diffuse(Vec3::splat(0.5)),
        };
        let extent = triangle_extent(ground.positions[0], ground.positions[1], ground.positions[2]);
        let scene = scene_of(vec![ground]);
        let stream = 40 + size_index as u32;
        let starts: Vec<Vec3> = (0..RAYS_PER_SIZE)
            .map(|i| {
                let u = random3(i, stream) - 0.5;
                Vec3::new(u.x, 0.0, u.z) * 0.6 * half_size
            })
            .collect();
        let mut origins: Vec<Vec3> = starts.iter().map(|&p| offset_ray_origin(p, Vec3::Y, extent)).collect();
        let mut directions: Vec<Vec3> = (0..RAYS_PER_SIZE)
            .map(|i| {
                let u = random3(i, stream + 10);
                Vec3::new(u.x - 0.5, u.y * u.y * u.y * 0.3 + 1e-4, u.z - 0.5)
            })
            .collect();
        // Control rays: every 16th origin straight back down.
        let leaving = origins.len();
        let control_starts: Vec<Vec3> = starts.iter().step_by(16).copied().collect();
        let control_origins: Vec<Vec3> = origins.iter().step_by(16).copied().collect();
        origins.extend(control_origins);
        directions.resize(origins.len(), Vec3::NEG_Y);
        let rays = rays_from(&origins, &directions, 4.0 * half_size);
        for traced in trace_everywhere("large planes", &scene, &rays) {
            let (false_hits, failed) = self_hits_and_failed_controls(&traced, &rays, leaving, &control_starts);
            assert_eq!(false_hits, 0, "{}: {false_hits} self-hits on a plane {half_size} across", traced.backend);
            assert_eq!(
                failed, 0,
                "{}: {failed} control rays did not meet the plane {half_size} across that they left",
                traced.backend
            );
        }
    }
}

#[test]
fn axis_aligned_grazing_tiny_and_huge_cases() {
    // A unit quad in z = 0, a tiny (1e-6) triangle at x = 5, a huge (1e6) triangle at z = 100.
    let quad = Mesh {
        name: "quad".into(),
        positions: vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        material: raywave::scene::Material::diffuse(Vec3::ONE),
    };
    let tiny = Mesh {
        name: "tiny".into(),
        positions: vec![Vec3::new(5.0, 0.0, 0.0), Vec3::new(5.0 + 1e-6, 0.0, 0.0), Vec3::new(5.0, 1e-6, 0.0)],
        triangles: vec![[0, 1, 2]],
        ..quad.clone()
    };
    let huge = Mesh {
        name: "huge".into(),
        positions: vec![Vec3::new(-1e6, -1e6, 100.0), Vec3::new(1e6, -1e6, 100.0), Vec3::new(0.0, 1e6, 100.0)],
        triangles: vec![[0, 1, 2]],
        ..quad.clone()
    };
    let scene = scene_of(vec![quad, tiny, huge]);
    // (origin, direction, expected instance or NO_HIT, expected t)
    let cases: Vec<(Vec3, Vec3, u32, f32)> = vec![
        (Vec3::new(0.25, 0.5, -2.0), Vec3::Z, 0, 2.0), // axis-aligned
        (Vec3::new(0.25, 0.5, -2.0), Vec3::new(-0.0, 0.0, 1.0), 0, 2.0), // −0 components
        (Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z, 0, 5.0), // through the shared diagonal
        (Vec3::new(1.0, 1.0, -1.0), Vec3::Z, 0, 1.0),  // exactly at a corner
        (Vec3::new(-9.5, 0.5, -1e-3), Vec3::new(1.0, 0.0, 1e-4), 0, 10.0), // grazing, z = 0 at x = 0.5
        (Vec3::new(-3.0, 0.5, 0.0), Vec3::X, NO_HIT, 0.0), // in the quad's plane
        (Vec3::new(5.0 + 2.5e-7, 2.5e-7, -1.0), Vec3::Z, 1, 1.0), // tiny triangle
        (Vec3::new(5.0 + 2e-6, 2e-6, -1.0), Vec3::Z, 2, 101.0), // beside it: the huge one behind
        (Vec3::new(3e5, 2e5, -50.0), Vec3::Z, 2, 150.0), // huge triangle
        (Vec3::new(0.5, 0.5, 1.0), Vec3::Y, NO_HIT, 0.0), // parallel, above
    ];
    let origins: Vec<Vec3> = cases.iter().map(|c| c.0).collect();
    let directions: Vec<Vec3> = cases.iter().map(|c| c.1).collect();
    let rays = rays_from(&origins, &directions, 1e4);
    // A ray exactly through the corner of an open mesh: Vulkan leaves the hit to the driver
    // (watertightness is only required on closed fans); raywave's own test counts it as inside.
    const OPEN_CORNER_CASE: usize = 3;
    for traced in trace_everywhere("hard cases", &scene, &rays) {
        let (backend, hits) = (&traced.backend, &traced.hits);
        for (i, &(_, _, instance, t)) in cases.iter().enumerate() {
            if traced.driver_intersection && i == OPEN_CORNER_CASE {
                continue;
            }
            assert_eq!(hits.instance[i], instance, "{backend}: case {i}");
            if instance != NO_HIT {
                assert!((hits.t[i] - t).abs() <= 1e-5 * t, "{backend}: case {i}: t {} vs {t}", hits.t[i]);
            }
        }
    }
}

/// The closest hit of ray `i` of `rays` (within its `[tmin, tmax]`) among every triangle of
/// `scene`, by the kernels' watertight triangle test alone, no BVH: `(t, mesh, triangle)`.
fn brute_force_closest(scene: &Scene, rays: &RayStream, i: usize) -> Option<(f32, u32, u32)> {
    let (origin, direction) = (rays.origin[i], rays.direction[i]);
    let ray = raywave::kernels::triangle::WatertightRay::new(origin.truncate(), direction.truncate());
    (scene.meshes().iter().enumerate())
        .flat_map(|(m, mesh)| mesh.triangles.iter().enumerate().map(move |(k, t)| (m, k, mesh, t)))
        .filter_map(|(m, k, mesh, t)| {
            let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
            ray.intersect(a, b, c, origin.w, direction.w).map(|h| (h.t, m as u32, k as u32))
        })
        .min_by(|x, y| x.0.total_cmp(&y.0))
}

#[test]
fn kernel_traversal_matches_brute_force_on_incoherent_rays() {
    let (meshes, _) = raywave::scene::procedural::hairball(60_000, 2).expect("a hairball");
    let scene = scene_of(meshes);
    let cpu_scene = CpuScene::build(&scene).unwrap();
    let n = 5_000u32;
    let origins: Vec<Vec3> = (0..n).map(|i| random3(i, 40) * 1.6 - 0.3).collect();
    let directions: Vec<Vec3> = (0..n).map(|i| random_direction(i, 41)).collect();
    let rays = rays_from(&origins, &directions, 5.0);
    let hits = cpu::trace(&cpu_scene, &rays).expect("trace");
    let mut agree = 0;
    for i in 0..origins.len() {
        match brute_force_closest(&scene, &rays, i) {
            None => assert_eq!(hits.primitive[i], NO_HIT, "ray {i}"),
            Some((t, _, k)) => {
                assert_eq!(hits.t[i], t, "ray {i}: traversal and brute force disagree on the closest t");
                agree += usize::from(hits.primitive[i] == k);
            }
        }
    }
    let hit_count = hits.primitive.iter().filter(|&&p| p != NO_HIT).count();
    assert!(hit_count > 500, "the test must exercise hits ({hit_count})");
    assert!(agree as f64 >= 0.9999 * hit_count as f64, "{agree} of {hit_count} agree on the primitive");
}

/// Traversal finds what brute force over every triangle finds — the same closest `t`, and no hit
/// where there is none — for every BVH preset (the slow one pre-splits large triangles, whose
/// clipped reference boxes obvhs computes in `f32`), with the scene scaled from 10⁻⁶ to 10⁶ and
/// moved 10⁴ and 10⁷ from the origin (the quantized child boxes are relative to their node's
/// corner), for random and axis-aligned rays (±0 components) starting at `tmin` 0 or beyond. The
/// test above covers one preset near the origin.
#[test]
fn kernel_traversal_matches_brute_force_for_every_preset_scale_and_offset() {
    use raywave::cpu::BvhQuality;
    let (mut meshes, _) = raywave::scene::procedural::hairball(6_000, 5).expect("a hairball");
    // Large triangles across the hairball's box, which the slow preset splits.
    let large: Vec<Vec3> = (0..3 * 40).map(|i| random3(i, 60) * 1.6 - 0.3).collect();
    let triangles = (0..40).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect();
    meshes.push(Mesh { name: "large".into(), positions: large, triangles, material: Material::diffuse(Vec3::ONE) });
    let axis_aligned = [
        Vec3::X,
        Vec3::NEG_X,
        Vec3::new(-0.0, 1.0, 0.0),
        Vec3::new(0.0, -1.0, -0.0),
        Vec3::new(-0.0, -0.0, 1.0),
        Vec3::NEG_Z,
    ];
    let n = 1_200u32;
    for (scale, offset) in [(1e-6f32, 0.0f32), (1.0, 0.0), (1e6, 0.0), (10.0, 1e4), (1e4, 1e7)] {
        let moved = meshes
            .iter()
            .map(|mesh| Mesh {
                positions: mesh.positions.iter().map(|&p| p * scale + Vec3::splat(offset)).collect(),
                ..mesh.clone()
            })
            .collect();
        let scene = scene_of(moved);
        // Every fourth ray axis-aligned and exactly through a vertex (its other two coordinates
        // the vertex's), so along the planes of the boxes that vertex bounds.
        let vertices: Vec<Vec3> = scene.meshes().iter().flat_map(|mesh| mesh.positions.iter().copied()).collect();
        let axis_aligned_ray = |i: u32| i.is_multiple_of(4);
        let directions: Vec<Vec3> = (0..n)
            .map(|i| {
                if axis_aligned_ray(i) {
                    axis_aligned[(i / 4) as usize % axis_aligned.len()]
                } else {
                    random_direction(i, 62)
                }
            })
            .collect();
        let origins: Vec<Vec3> = (0..n)
            .map(|i| {
                let random = (random3(i, 61) * 1.6 - 0.3) * scale + Vec3::splat(offset);
                if !axis_aligned_ray(i) {
                    return random;
                }
                let vertex = vertices[pcg3d(UVec3::new(i, 63, 0)).x as usize % vertices.len()];
                let along = directions[i as usize].abs().cmpgt(Vec3::splat(0.5));
                Vec3::select(along, random, vertex)
            })
            .collect();
        let mut rays = rays_from(&origins, &directions, 3.0 * scale);
        for (i, origin) in rays.origin.iter_mut().enumerate() {
            origin.w = if i.is_multiple_of(3) { 0.2 * scale } else { 0.0 };
        }
        for quality in [BvhQuality::Fast, BvhQuality::Medium, BvhQuality::Slow] {
            let case = format!("{} preset, scale {scale:e}, offset {offset:e}", quality.name());
            let cpu_scene = CpuScene::build_with(&scene, quality).unwrap();
            let hits = cpu::trace(&cpu_scene, &rays).expect("trace");
            let (mut hit_count, mut agree) = (0, 0);
            for i in 0..n as usize {
                match brute_force_closest(&scene, &rays, i) {
                    None => assert_eq!(hits.primitive[i], NO_HIT, "{case}: ray {i} hits nothing"),
                    Some((t, mesh, primitive)) => {
                        assert_eq!(hits.t[i], t, "{case}: ray {i}: traversal and brute force disagree on t");
                        hit_count += 1;
                        agree += usize::from((hits.instance[i], hits.primitive[i]) == (mesh, primitive));
                    }
                }
            }
            assert!(hit_count > 300 && hit_count < n as usize - 100, "{case}: a mix of hits and misses ({hit_count})");
            assert!(agree as f64 >= 0.999 * hit_count as f64, "{case}: {agree} of {hit_count} agree on the primitive");
        }
    }
}

#[test]
fn occlusion_agrees_with_closest_hit_and_exits_early() {
    let (meshes, _) = raywave::scene::procedural::hairball(200_000, 3).expect("a hairball");
    let scene = scene_of(meshes);
    let cpu_scene = CpuScene::build(&scene).unwrap();
    let n = 50_000u32;
    let origins: Vec<Vec3> = (0..n).map(|i| random3(i, 50) * 1.6 - 0.3).collect();
    let directions: Vec<Vec3> = (0..n).map(|i| random_direction(i, 51)).collect();
    let rays = rays_from(&origins, &directions, 2.0);
    let hits = cpu::trace(&cpu_scene, &rays).expect("trace");
    let occluded = cpu::trace_occlusion(&cpu_scene, &rays).expect("occlusion");
    let (mut closest_tests, mut any_tests) = (0u64, 0u64);
    for (i, &blocked) in occluded.iter().enumerate() {
        assert_eq!(blocked == 1, hits.primitive[i] != NO_HIT, "ray {i}");
        let ray = raywave::kernels::trace::Ray::from_stream(rays.origin[i], rays.direction[i]);
        let closest = cpu_scene.view().traversal_stats(&ray, false);
        let any = cpu_scene.view().traversal_stats(&ray, true);
        assert!(any.triangles <= closest.triangles && any.nodes <= closest.nodes, "ray {i}: {any:?} vs {closest:?}");
        closest_tests += u64::from(closest.triangles);
        any_tests += u64::from(any.triangles);
        assert_eq!(cpu_scene.obvhs_occluded(&ray), blocked == 1, "ray {i}: obvhs reference disagrees");
    }
    let blocked = occluded.iter().filter(|&&o| o == 1).count();
    assert!(blocked > 1000 && blocked < n as usize - 1000, "a mix of blocked and free rays ({blocked})");
    // Without an early exit the two traversals would do exactly the same work; stopping at the
    // first hit must save tests (how many depends on how well front-to-back order already prunes).
    assert!(any_tests < closest_tests, "any-hit {any_tests} vs closest-hit {closest_tests} triangle tests");
    eprintln!("triangle tests: closest-hit {closest_tests}, any-hit {any_tests}");
}

/// A small quad just above a plane of the BVH's frame, beside a triangle 9·10⁴ across (found by
/// fuzzing `scene_shapes` with debug assertions): obvhs quantizes a child box relative to its
/// node's corner in `f32` (`(child.max − node.min) / e`), where 45 568 + 0.000427 rounds to
/// 45 568, so the box stops at y = 0 while the quad reaches y = 0.000427. obvhs's own debug
/// validation (which the workspace turns off for obvhs: see Cargo.toml) panicked on it; the
/// traversals expand every child box by one quantization cell, so every ray onto that strip above
/// y = 0 must still hit the quad, on every backend.
#[test]
fn boxes_quantized_in_a_wide_frame_still_hold_what_they_bound() {
    let quad = |name: &str, corners: [[f32; 3]; 4]| Mesh {
        name: name.into(),
        positions: corners.map(Vec3::from_array).to_vec(),
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        material: Material::diffuse(Vec3::splat(0.5)),
    };
    let strip =
        quad("strip", [[-0.25, 0.000427, 0.0], [0.25, 0.000427, 0.0], [0.25, -0.156, 0.5], [-0.25, -0.156, 0.5]]);
    let floor = quad("floor", [[-1.0, 0.0, -0.234], [1.0, 0.0, -0.234], [1.0, -2.0, -0.235], [-1.0, -2.0, -0.235]]);
    let wide = Mesh {
        name: "wide".into(),
        positions: vec![
            Vec3::new(-6238.0, -45568.0, -47282.0),
            Vec3::new(-45234.0, 5966.0, 0.0),
            Vec3::splat(-45234.0),
        ],
        triangles: vec![[0, 1, 2]],
        material: Material::diffuse(Vec3::splat(0.5)),
    };
    let scene = scene_of(vec![strip, floor, wide]);
    // Straight down onto the strip where it lies above y = 0 (z < 0.0014).
    let origins: Vec<Vec3> = (0..4000)
        .map(|i| Vec3::new(-0.24 + 0.48 * (i / 4) as f32 / 999.0, 1.0, [1e-5, 1e-4, 5e-4, 1e-3][i % 4]))
        .collect();
    let rays = rays_from(&origins, &vec![Vec3::NEG_Y; origins.len()], 10.0);
    for traced in trace_everywhere("wide-frame quantization", &scene, &rays) {
        let missed = traced.hits.instance.iter().zip(&traced.hits.primitive).filter(|(&i, &p)| p == NO_HIT || i != 0);
        assert_eq!(missed.count(), 0, "{}: rays onto the strip above y = 0 missed it", traced.backend);
    }
}
