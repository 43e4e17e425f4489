//! The shadowed estimate `S_N` of the shade stage is unbiased end to end: on the Cornell box as
//! built — the camera ray and the shadow rays traced by the CPU backend's BVH, the shadow ray's
//! origin offset and its stop before the light (`raywave_kernels::offset`), the light's own emitter
//! triangles and the ceiling 0.1 mm above them in the scene — the mean of `S_N` at a shading point
//! is the integral over the light of the lobes the stage evaluates times the radiance and the
//! visibility, computed here independently by brute force: a 256² midpoint grid over the light, the
//! solid angle from the `f64` geometry, and the visibility from an `f64` segment test against
//! every scene triangle but the light's own (which the stage's stop before the light is there to
//! skip). The kernel's own unit test
//! (`shadowed_estimate_is_unbiased_for_the_visible_part_of_the_light`) has an analytic half-plane
//! occluder and no trace; the reports compare against a reference made by the same pipeline,
//! which shares any bias of it.
//!
//! The points are the hard ones: floor points in the short block's deep penumbra (a few per cent of
//! the light visible past its top edge), in a penumbra between the blocks, 0.5 mm off a block's
//! face and 0.7 mm off a block's corner (contact corners), a block's face 0.5 mm above the floor
//! (the light partly below its horizon), and walls 1 mm and 0.1 mm below the light's plane (the
//! light seen edge-on, the shadow ray's stop up to 14 mm before it); each as built (all diffuse)
//! and with a glossy floor (dielectric, roughness 0.2), a metal back wall (roughness 0.1) and a
//! glossy short block (0.25), seen from a tilted view.
//!
//! Measured by a helper's study (2²⁰ samples at each of 55 such points, 41 of them lit, diffuse and
//! glossy, 2¹⁹ with the residual towards GGX): no bias as built — z² averaged 0.71, 0.85 and 1.16,
//! the largest |z| 3.0 (not repeated with other seeds), the relative error at the penumbra points
//! within 0.3–0.5 % (their standard errors). Moved 100 m from the origin, the deep-penumbra points
//! came out 5.7–8.1 % too bright (z 8–14 at 2¹⁸), 1 km away 53–110 %: the shadow ray starts
//! 64·ε·|p| off its surface (0.77 mm at 100 m) and sees past the block's edge from there — the
//! estimates then match an integral seen from that offset point (|z| ≤ 2.9 at 10², 10³ and 10⁴).
//! That is the far-from-origin resolution the shade stage documents; this test holds the box as
//! built, and checks that it would see a bias of that kind
//! (`a_shadow_origin_lifted_two_millimetres_is_seen`). With the stop before the light removed
//! (shadow rays reaching the light's plane, where its own triangles are) or the origin offset
//! raised to 16384 ulps (1.1 mm here, the offset ~140 m out), the first test fails (`S_N` ≈ 0, and
//! +7.7 % at z = 9 in a deep penumbra).

use glam::{DVec3, UVec2, Vec3, Vec4Swizzles};
use raywave_host::cpu::{trace, trace_occlusion, CpuScene};
use raywave_host::kernels::shade::ltc::{lookup, ShadingFrame};
use raywave_host::kernels::shade::stage::{shade_sample, Surface};
use raywave_host::shading::{resolve, ShadeData};
use raywave_host::shared::sampling::sampler_kind;
use raywave_host::shared::{Light, SamplerParams};
use raywave_host::stream::RayStream;
use raywave_host::Scene;

/// Samples per point.
const SAMPLES: u32 = 1 << 16;

/// Standard errors a mean may stray from its reference: 4, a chance of 6.3·10⁻⁵ per comparison
/// for independent samples, about 10⁻³ over this file's 16 such comparisons (Šidák); the seeds
/// are fixed, so the test is deterministic.
const Z: f64 = 4.0;

/// The brute-force reference's own error, relative to the point's `U`: the 256² midpoint grid is
/// within 5·10⁻⁵ of the analytic `U` without visibility at these points (checked against
/// [`VALIDATION`]), and its visibility steps (a cell's share of a partly hidden light) leave
/// under 10⁻⁴ (at the study's penumbra points, 256² and 1024² grids differed by up to 3·10⁻⁵ of
/// `U`).
const GRID_TOLERANCE: f64 = 2e-4;

/// How far the reference's integrand without visibility may be from the stage's analytic `U`.
const VALIDATION: f64 = 1e-4;

/// Grid cells per side of the light.
const GRID: usize = 256;

/// Rec. 709 luminance: the estimates are compared by it.
const LUMA: DVec3 = DVec3::new(0.2126, 0.7152, 0.0722);

/// Mesh indices of the built-in Cornell box.
const FLOOR: u32 = 0;
const BACK_WALL: u32 = 2;
const RIGHT_WALL: u32 = 3;
const SHORT_BLOCK: u32 = 5;

/// A shading point: the mesh, a point on it (metres) and where the camera ray comes from.
struct Case {
    what: &'static str,
    mesh: u32,
    target: Vec3,
    eye: Vec3,
    /// In a deep penumbra (a few per cent of the light visible past an edge): the most sensitive
    /// to where the shadow ray starts.
    deep: bool,
}

fn cases() -> Vec<Case> {
    let case = |what, mesh, target: [f32; 3], towards: [f32; 3], deep| {
        let target = Vec3::from_array(target);
        Case { what, mesh, target, eye: target + Vec3::from_array(towards).normalize() * 0.05, deep }
    };
    // The short block's face from (290, 114) to (240, 272) mm faces (0.954, 0, 0.302).
    vec![
        case("floor, deep penumbra of the short block", FLOOR, [0.0434, 0.0, 0.11125], [0.2, 1.0, -0.3], true),
        case("floor, deep penumbra of the short block (2)", FLOOR, [0.0702, 0.0, 0.03025], [0.2, 1.0, -0.3], true),
        case("floor, penumbra between the blocks", FLOOR, [0.2574, 0.0, 0.3273], [0.1, 1.0, -0.4], false),
        case("floor 0.5 mm off the short block's face", FLOOR, [0.26548, 0.0, 0.19315], [0.3, 1.0, -0.2], false),
        case("floor 0.7 mm off the tall block's corner", FLOOR, [0.313675, 0.0, 0.456621], [-0.2, 1.0, 0.4], false),
        case(
            "short block's face 0.5 mm above the floor",
            SHORT_BLOCK,
            [0.265, 0.0005, 0.193],
            [0.954, 0.2, 0.0],
            false,
        ),
        case("back wall 1 mm below the light's plane", BACK_WALL, [0.278, 0.5477, 0.5592], [0.0, -0.07, -1.0], false),
        case("right wall 0.1 mm below the light's plane", RIGHT_WALL, [0.0, 0.5486, 0.28], [1.0, -0.3, -0.2], false),
    ]
}

/// The surface the CPU trace and resolve give for a camera ray from `case.eye` to `case.target`.
fn surface(case: &Case, data: &ShadeData, cpu: &CpuScene) -> (Surface, Vec3) {
    let direction = (case.target - case.eye).normalize();
    let rays =
        RayStream { origin: vec![case.eye.extend(0.0)], direction: vec![direction.extend(f32::MAX)], pixel: vec![0] };
    let s = resolve(data, &rays, &trace(cpu, &rays).unwrap())[0];
    assert!(
        s.instance == case.mesh && (s.position.xyz() - case.target).length() < 1e-5,
        "{}: the camera ray met mesh {} at {}",
        case.what,
        s.instance,
        s.position
    );
    (s, direction)
}

/// Mean luminance of `S_N` over [`SAMPLES`] independent samples, and its standard error.
fn shadowed_mean(surface: &Surface, view: Vec3, data: &ShadeData, cpu: &CpuScene, seed: u32) -> (f64, f64) {
    let sampler = SamplerParams { kind: sampler_kind::INDEPENDENT, seed, spp_log2: 16, resolution_log2: 0 };
    let scene = data.view();
    let samples: Vec<_> = (0..SAMPLES)
        .map(|i| shade_sample(&data.params(sampler, 1, 1, i), UVec2::ZERO, view, surface, &scene).value)
        .collect();
    let rays = RayStream {
        origin: samples.iter().map(|s| s.shadow_origin).collect(),
        direction: samples.iter().map(|s| s.shadow_direction).collect(),
        pixel: (0..SAMPLES).collect(),
    };
    let occluded = trace_occlusion(cpu, &rays).unwrap();
    let (mut sum, mut sum2) = (0.0, 0.0);
    for (s, occluded) in samples.iter().zip(occluded) {
        // A sample without a shadow ray (tmax = 0) has U_N = 0.
        let visible = s.shadow_direction.w > 0.0 && occluded == 0;
        let y = if visible { s.unshadowed.xyz().as_dvec3().dot(LUMA) } else { 0.0 };
        sum += y;
        sum2 += y * y;
    }
    let n = f64::from(SAMPLES);
    let mean = sum / n;
    (mean, ((sum2 / n - mean * mean).max(0.0) / n).sqrt())
}

/// Whether the segment from `p` to `q` meets a triangle of `triangles` (mesh, vertices) strictly
/// between its ends, other than those of mesh `light_mesh` and those in the plane of the surface
/// `p` lies on (normal `n`; a segment leaving it cannot meet that plane again).
fn blocked(triangles: &[(u32, [DVec3; 3])], p: DVec3, n: DVec3, q: DVec3, light_mesh: u32) -> bool {
    let d = q - p;
    let in_plane_tolerance = 1e-7 + 8.0 * f64::from(f32::EPSILON) * p.abs().max_element();
    triangles.iter().any(|&(mesh, [a, b, c])| {
        let (e1, e2) = (b - a, c - a);
        let normal = e1.cross(e2).normalize();
        if mesh == light_mesh || (normal.dot(n).abs() > 1.0 - 1e-9 && (p - a).dot(normal).abs() < in_plane_tolerance) {
            return false;
        }
        // Möller–Trumbore on the segment (t in units of its length).
        let h = d.cross(e2);
        let det = e1.dot(h);
        if det == 0.0 {
            return false;
        }
        let s = p - a;
        let u = s.dot(h) / det;
        let k = s.cross(e1);
        let v = d.dot(k) / det;
        let t = e2.dot(k) / det;
        (0.0..=1.0).contains(&u) && v >= 0.0 && u + v <= 1.0 && t > 1e-9 && t < 1.0 - 1e-12
    })
}

/// The brute-force integral over `light` of the stage's lobes (as `Lobes::eval_and_pdfs` builds
/// them: `E_D·cos/π + E_S·D_LTC` from the stage's LTC lookup) times the radiance, as luminance:
/// without visibility, and with the visibility from the point `lift` metres above `surface`.
fn reference(
    surface: &Surface,
    view: Vec3,
    data: &ShadeData,
    light: &Light,
    triangles: &[(u32, [DVec3; 3])],
    lift: f64,
) -> (f64, f64) {
    let material = data.materials[surface.instance as usize];
    let n = surface.normal.xyz();
    let v = -view.normalize();
    let frame = ShadingFrame::new(n, v);
    let (base, roughness, metallic) =
        (material.base_color_roughness.xyz(), material.base_color_roughness.w, material.emission_metallic.w);
    let ltc = lookup(&data.ltc, roughness, n.dot(v));
    let specular = ltc.specular_albedo(Vec3::splat(0.04) * (1.0 - metallic) + base * metallic).as_dvec3();
    let diffuse = (base * (1.0 - metallic)).as_dvec3();
    let radiance = light.radiance.xyz().as_dvec3();
    let (p, n) = (surface.position.xyz().as_dvec3(), n.as_dvec3());
    let from = p + n * lift;
    let (corner, eu, ev) =
        (light.position.xyz().as_dvec3(), light.edge_u.xyz().as_dvec3(), light.edge_v.xyz().as_dvec3());
    let light_normal = eu.cross(ev).normalize();
    let area = eu.cross(ev).length() / (GRID * GRID) as f64;
    let (mut free, mut visible) = (0.0, 0.0);
    for i in 0..GRID {
        for j in 0..GRID {
            let q = corner + eu * ((i as f64 + 0.5) / GRID as f64) + ev * ((j as f64 + 0.5) / GRID as f64);
            let w = (q - p).normalize();
            let local = frame.to_local(w.as_vec3());
            if local.z <= 0.0 || n.dot(w) <= 0.0 || light_normal.dot(w) >= 0.0 {
                continue;
            }
            let f = diffuse * n.dot(w) / std::f64::consts::PI + specular * f64::from(ltc.pdf(local));
            let x = (f * radiance).dot(LUMA) * light_normal.dot(w).abs() / (q - p).length_squared() * area;
            free += x;
            if !blocked(triangles, from, n, q, light.mesh) {
                visible += x;
            }
        }
    }
    (free, visible)
}

/// The stage's analytic `U` (luminance).
fn analytic(surface: &Surface, view: Vec3, data: &ShadeData) -> f64 {
    let sampler = SamplerParams { kind: sampler_kind::INDEPENDENT, seed: 0, spp_log2: 0, resolution_log2: 0 };
    let s = shade_sample(&data.params(sampler, 1, 1, 0), UVec2::ZERO, view, surface, &data.view()).value;
    s.analytic.xyz().as_dvec3().dot(LUMA)
}

struct Setup {
    data: ShadeData,
    cpu: CpuScene,
    light: Light,
    triangles: Vec<(u32, [DVec3; 3])>,
}

fn cornell(glossy: bool) -> Setup {
    setup(&Scene::load("builtin:cornell").unwrap(), glossy)
}

/// [`cornell`] for `scene`, a Cornell box.
fn setup(scene: &Scene, glossy: bool) -> Setup {
    let mut data = ShadeData::new(scene).unwrap();
    if glossy {
        let mut set = |mesh: u32, roughness: f32, metallic: f32| {
            let m = &mut data.materials[mesh as usize];
            m.base_color_roughness.w = roughness;
            m.emission_metallic.w = metallic;
        };
        set(FLOOR, 0.2, 0.0);
        set(BACK_WALL, 0.1, 1.0);
        set(SHORT_BLOCK, 0.25, 0.0);
    }
    let triangles = scene
        .meshes()
        .iter()
        .enumerate()
        .flat_map(|(m, mesh)| {
            mesh.triangles.iter().map(move |t| (m as u32, t.map(|i| mesh.positions[i as usize].as_dvec3())))
        })
        .collect();
    assert_eq!(scene.lights().len(), 1);
    Setup { light: scene.lights()[0], cpu: CpuScene::build(scene).unwrap(), data, triangles }
}

#[test]
fn shadowed_estimate_matches_a_brute_force_integral_on_the_cornell_box() {
    for glossy in [false, true] {
        let Setup { data, cpu, light, triangles } = cornell(glossy);
        for (k, case) in cases().iter().enumerate() {
            let (surface, view) = surface(case, &data, &cpu);
            let u = analytic(&surface, view, &data);
            let (free, expected) = reference(&surface, view, &data, &light, &triangles, 0.0);
            assert!(
                u > 0.0 && (free / u - 1.0).abs() < VALIDATION,
                "{} (glossy {glossy}): the reference's integrand {free} against U {u}",
                case.what
            );
            assert!(expected < 0.99 * u || !case.deep, "{}: not in a shadow", case.what);
            let (mean, error) = shadowed_mean(&surface, view, &data, &cpu, 11 + k as u32 + 100 * glossy as u32);
            assert!(
                (mean - expected).abs() <= Z * error + GRID_TOLERANCE * u,
                "{} (glossy {glossy}): S_N {mean} ± {error} against the visible light's integral {expected} (U {u})",
                case.what
            );
        }
    }
}

/// The test above would see a bias the size the shadow ray's origin offset gives 260 m from the
/// origin (2 mm): at the deep-penumbra points, a reference taken from the point lifted 2 mm off
/// its surface is more than [`Z`] standard errors from the estimates.
#[test]
fn a_shadow_origin_lifted_two_millimetres_is_seen() {
    let Setup { data, cpu, light, triangles } = cornell(false);
    for (k, case) in cases().iter().enumerate().filter(|(_, c)| c.deep) {
        let (surface, view) = surface(case, &data, &cpu);
        let u = analytic(&surface, view, &data);
        let (_, lifted) = reference(&surface, view, &data, &light, &triangles, 2e-3);
        let (mean, error) = shadowed_mean(&surface, view, &data, &cpu, 11 + k as u32);
        assert!(
            (mean - lifted).abs() > Z * error + GRID_TOLERANCE * u,
            "{}: S_N {mean} ± {error} does not tell the reference lifted 2 mm, {lifted}",
            case.what
        );
    }
}

/// A lamp mesh bent within the emitter fit's tolerance does not shadow its own light: with the
/// Cornell lamp's fourth corner (its second triangle's own) lowered by 0.9·10⁻⁴ of the lamp's
/// diagonal — about 3.5 times the shadow rays' stop before the light's plane — the light is the
/// flat lamp's and `S_N` at every point of [`cases`] is the flat lamp's, from the same samples,
/// within 10⁻⁶ of `U`. Before the loader moved a light's mesh onto it, the shadow rays towards that
/// corner met the bent triangle: `S_N` 5–91 % low at these points (12–24 % of `U`).
#[test]
fn a_lamp_bent_within_the_emitter_fit_does_not_shadow_its_own_light() {
    let flat = Scene::load("builtin:cornell").unwrap();
    let mut meshes = flat.meshes().to_vec();
    let lamp = &mut meshes[flat.light_mesh(0)].positions;
    let diagonal = lamp[0].distance(lamp[2]);
    lamp[3].y -= 0.9e-4 * diagonal;
    let bent = Scene::new("cornell, bent lamp", meshes, *flat.camera()).unwrap();
    assert_eq!(bent.lights(), flat.lights());
    let (flat, bent) = (setup(&flat, false), setup(&bent, false));
    for (k, case) in cases().iter().enumerate() {
        let (surface, view) = surface(case, &flat.data, &flat.cpu);
        let u = analytic(&surface, view, &flat.data);
        let (expected, _) = shadowed_mean(&surface, view, &flat.data, &flat.cpu, 31 + k as u32);
        let (mean, _) = shadowed_mean(&surface, view, &bent.data, &bent.cpu, 31 + k as u32);
        assert!(
            (mean - expected).abs() <= 1e-6 * u,
            "{}: S_N {mean} under the bent lamp against {expected} under the flat one (U {u})",
            case.what
        );
    }
}
