//! Analytic quad lights derived from emissive meshes.
//!
//! A mesh becomes one [`Light::quad`] when its material's emission is non-zero and its (already
//! non-degenerate) triangles form one planar parallelogram:
//!
//! - exactly two triangles that share one edge, the parallelogram's diagonal (shared corners are
//!   matched by position within the tolerance, so duplicated vertices, as non-indexed glTF
//!   primitives have, still match);
//! - the four corners form a parallelogram (`p + q = s₀ + s₁` for the off-diagonal corners `p`,
//!   `q` and the diagonal's ends `s₀`, `s₁`, i.e. opposite edges are equal), which also puts `q`
//!   on the first triangle's plane;
//! - both triangles wind the same way, so the mesh has one front face — unless its material is
//!   [`Material::double_sided`](super::Material::double_sided): it emits from both faces, and
//!   its triangles may wind either way.
//!
//! Tolerance: `min(1e-4 · d, 0.05 · h) + 16 ε · m`, with `d` the longest distance between the six
//! triangle corners, `h` the smaller of the two triangles' heights over their longest edge (a
//! parallelogram's width across its diagonal), `m` the corners' largest absolute coordinate and
//! `ε` the `f32` machine epsilon: a relative error of 10⁻⁴ in the shape — but at most 5 % of its
//! narrower side, which binds above an aspect ratio of about 350: relative to the length alone, a
//! strip of aspect ratio 2000 had passed 15 % off in width or twisted 8° out of its plane, while a
//! strip written with few decimals, a 2 m × 1 mm one to 10 µm say, still passes — plus the
//! rounding of vertices far from the origin (transformed glTF positions); at most a quarter of the
//! shortest triangle edge, so that no corner is within it of two others. The checks run in `f64`.
//! Far from the origin the rounding slack dominates, and small lamps pass bent: at 10⁵ it is 0.19
//! (24 `f32` ulps there), so a 1 × 1 lamp with a corner 0.15 out of plane is a light, following
//! its first triangle. 16 ε is what a node transform's rounding, over four corners, may reach —
//! of the world coordinates, as the glTF loader transforms in `f64` and rounds once (in `f32` the
//! rounding of a transform's terms, which may be far larger than its result, had bent lamps
//! modelled 10³ from their node's origin past the tolerance).
//!
//! **Orientation.** The light's corner is the first triangle's corner off the diagonal, `p`; its
//! edges run from `p` to the triangle's next and previous corners in the triangle's own order.
//! Then `edge_u × edge_v` is the first triangle's counter-clockwise normal, the side glTF and OBJ
//! call the front face, and the light emits there (one-sided; the kernels' quad lights emit
//! towards `edge_u × edge_v`) — or from both faces where the material is
//! [`Material::double_sided`](super::Material::double_sided). The second triangle must agree.
//!
//! **Reach.** The light's corners are rebuilt from its corner and edges in `f32`
//! (`corner + edge_u + edge_v`, as the kernels and light validation rebuild them), which may land
//! off the mesh's fourth corner by up to the tolerance: a parallelogram whose rebuilt corners
//! pass the coordinate limit (`crate::lights::reach_within_limit`), though every vertex is within
//! it, is no light — light validation would refuse it and fail the whole scene.
//!
//! **Snapped.** A mesh that becomes a light is moved onto it: each vertex to the light's corner
//! it matched, as rebuilt in `f32`, by at most the tolerance. Its triangles then lie in the
//! light's plane to rounding, where the shade stage's shadow rays, which stop short of that plane
//! by the ray-origin offset, cannot meet them (bent by the tolerance, they had blocked the light).
//!
//! Everything else that emits (more or fewer triangles, non-planar or non-parallelogram shapes,
//! inconsistent winding, a rebuilt corner out of range) is counted as an unsupported emitter and
//! stays plain geometry.

use super::Mesh;
use glam::{DVec3, Vec3};
use raywave_kernels::sampling::light_select::light_bounds;
use raywave_shared::Light;

/// Relative shape tolerance (see the module documentation).
const RELATIVE_TOLERANCE: f64 = 1e-4;

/// Largest shape error as a fraction of the narrower side (see the module documentation).
const NARROW_SIDE_TOLERANCE: f64 = 0.05;

/// Rounding slack in units of `f32::EPSILON` times the largest absolute coordinate.
const ROUNDING_SLACK: f64 = 16.0 * f32::EPSILON as f64;

/// The lights derived from a scene's meshes.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct DerivedLights {
    /// One quad light per emissive parallelogram mesh, in mesh order, each [`Light::made_of`] its
    /// mesh.
    pub lights: Vec<Light>,
    /// For each mesh, the index of its light, if it has one.
    pub mesh_lights: Vec<Option<u32>>,
    /// Emissive meshes that are not parallelograms.
    pub unsupported: usize,
}

/// Derives a quad light from every emissive parallelogram mesh (see the module documentation)
/// and snaps that mesh onto its light ([`snap_onto`]). Mesh and light counts must fit in `u32`
/// (the scene checks the mesh count before this).
pub(super) fn derive(meshes: &mut [Mesh]) -> DerivedLights {
    let mut derived = DerivedLights { mesh_lights: vec![None; meshes.len()], ..Default::default() };
    for (index, mesh) in meshes.iter_mut().enumerate() {
        let emission = mesh.material.emission;
        if emission == Vec3::ZERO {
            continue;
        }
        match parallelogram(mesh) {
            Some(quad) => {
                snap_onto(mesh, &quad);
                derived.mesh_lights[index] = Some(derived.lights.len() as u32);
                let two_sided = mesh.material.double_sided;
                let light = Light::quad(quad.corner, quad.edge_u, quad.edge_v, emission, two_sided);
                derived.lights.push(light.made_of(index as u32));
            }
            None => derived.unsupported += 1,
        }
    }
    derived
}

/// Moves each vertex of a parallelogram mesh's triangles to the nearest corner of its light, as
/// the kernels rebuild the corners in `f32` ([`Parallelogram::corners`]), so that
/// the lamp's own triangles lie in the light's plane to rounding. The shade stage's shadow rays
/// stop short of that plane by the ray-origin offset (64 `f32` steps of the larger coordinate,
/// `raywave_kernels::offset::ray_stop_before`) so that the lamp cannot block them; a mesh the fit
/// accepted bent by up to its tolerance (10⁻⁴ of the lamp's size) reaches past that margin
/// wherever the lamp is more than ~6 % of its coordinates across: the Cornell box's lamp with a
/// corner lowered by 0.9·10⁻⁴ of its diagonal had blocked the shadow rays to about a quarter of
/// itself, `S_N` 5–91 % low (12–24 % of `U`) at the hard points of `shadowed_estimate.rs`
/// (test). Each vertex moves by at most the tolerance, which is under a quarter of the shortest
/// edge, so its nearest corner is the one it was matched to. The distances are compared in
/// `f64`: in `f32` the squared distances across a lamp narrower than about 10⁻¹⁹ are subnormal,
/// and below about 2.6·10⁻²³ they underflowed to 0, the tie went to the first corner, and a
/// 192.5 × 2.6·10⁻²³ strip (found by `scene_shapes`) had two vertices moved across it, which
/// left it no area and the scene no bounds.
fn snap_onto(mesh: &mut Mesh, quad: &Parallelogram) {
    let corners = quad.corners();
    for &index in mesh.triangles.iter().flatten() {
        let vertex = &mut mesh.positions[index as usize];
        let distance = |corner: &&Vec3| corner.as_dvec3().distance_squared(vertex.as_dvec3());
        let nearest = corners.iter().min_by(|a, b| distance(a).total_cmp(&distance(b)));
        if let Some(&nearest) = nearest {
            *vertex = nearest;
        }
    }
}

/// A parallelogram `corner + s·edge_u + t·edge_v`, `s, t ∈ [0, 1]`, facing `edge_u × edge_v`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(super) struct Parallelogram {
    pub corner: Vec3,
    pub edge_u: Vec3,
    pub edge_v: Vec3,
}

impl Parallelogram {
    /// The four corners in cyclic order from `corner`, rebuilt in `f32` as the kernels rebuild a
    /// quad light's (`corner + edge_u + edge_v` for the third).
    pub fn corners(&self) -> [Vec3; 4] {
        let (c, u, v) = (self.corner, self.edge_u, self.edge_v);
        [c, c + u, c + u + v, c + v]
    }
}

/// The mesh as one front-facing parallelogram, if it is one (see the module documentation).
pub(super) fn parallelogram(mesh: &Mesh) -> Option<Parallelogram> {
    let [first, second] = mesh.triangles.as_slice() else { return None };
    let corners = |t: &[u32; 3]| t.map(|i| mesh.positions.get(i as usize).copied());
    let (a, b) = (corners(first), corners(second));
    let a: [Vec3; 3] = [a[0]?, a[1]?, a[2]?];
    let b: [Vec3; 3] = [b[0]?, b[1]?, b[2]?];
    let (ad, bd) = (a.map(Vec3::as_dvec3), b.map(Vec3::as_dvec3));
    let all = [ad, bd].concat();
    let magnitude = all.iter().fold(0.0f64, |m, p| m.max(p.abs().max_element()));
    let diameter = all.iter().flat_map(|p| all.iter().map(move |q| p.distance(*q))).fold(0.0, f64::max);
    // Per triangle: its shortest edge, and its height over its longest (twice the area over it).
    let measures = |t: [DVec3; 3]| {
        let edges = [0, 1, 2].map(|i| t[i].distance(t[(i + 1) % 3]));
        let longest = edges.into_iter().fold(0.0, f64::max);
        (edges.into_iter().fold(f64::INFINITY, f64::min), (t[1] - t[0]).cross(t[2] - t[0]).length() / longest)
    };
    let ((shortest_a, height_a), (shortest_b, height_b)) = (measures(ad), measures(bd));
    // At most a quarter of the shortest triangle edge, so that no corner lies within it of two
    // others: the rounding slack alone is 0.19 at 10⁵ from the origin, wider than a small lamp
    // there.
    let shortest_edge = shortest_a.min(shortest_b);
    let shape = (RELATIVE_TOLERANCE * diameter).min(NARROW_SIDE_TOLERANCE * height_a.min(height_b));
    let tolerance = (shape + ROUNDING_SLACK * magnitude).min(0.25 * shortest_edge);

    // Match the first triangle's corners to the second's: exactly two shared corners. Two corners
    // of a triangle lie at least the shortest edge apart, more than twice the tolerance, so no
    // corner has two partners and no two corners share one.
    let partner = ad.map(|p| (0..3).find(|&j| p.distance(bd[j]) <= tolerance));
    let shared: Vec<usize> = partner.iter().flatten().copied().collect();
    if shared.len() != 2 {
        return None;
    }
    let off_a = partner.iter().position(Option::is_none)?;
    let off_b = (0..3).find(|j| !shared.contains(j))?;

    // The first triangle from its off-diagonal corner, in its own (counter-clockwise) order.
    let (p, x, y) = (ad[off_a], ad[(off_a + 1) % 3], ad[(off_a + 2) % 3]);
    let q = bd[off_b];
    let normal = (x - p).cross(y - p);
    let second_normal = (bd[1] - bd[0]).cross(bd[2] - bd[0]);
    let unit = normal.try_normalize()?;
    let consistent = unit.dot(second_normal.try_normalize()?) > 0.0 || mesh.material.double_sided;
    // Also puts `q` on the first triangle's plane: `q − p = (x − p) + (y − p) − (x + y − p − q)`,
    // whose first two terms lie in it.
    let parallelogram = (x + y - p - q).length() <= tolerance;
    if !(consistent && parallelogram) {
        return None;
    }

    let corner = a[off_a];
    let edge_u = a[(off_a + 1) % 3] - corner;
    let edge_v = a[(off_a + 2) % 3] - corner;
    // An area the kernels can compute with, in `f32` as they do: a 10⁻¹² m square's cross
    // product is 10⁻²⁴, its squared length underflows, and light validation would refuse it.
    let area = edge_u.cross(edge_v);
    if !area.is_finite() || area.length() < f32::MIN_POSITIVE || area.as_dvec3().dot(normal) <= 0.0 {
        return None;
    }
    // The corners rebuilt as the light's validation rebuilds them (its radiance plays no part).
    let rebuilt = light_bounds(&Light::quad(corner, edge_u, edge_v, Vec3::ZERO, false));
    crate::lights::reach_within_limit(&rebuilt).ok()?;
    Some(Parallelogram { corner, edge_u, edge_v })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Material;

    fn emissive(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Mesh {
        Mesh {
            name: "emitter".into(),
            positions,
            triangles,
            material: Material { emission: Vec3::new(3.0, 2.0, 1.0), ..Material::diffuse(Vec3::ONE) },
        }
    }

    /// Whether every corner of `got` is near one of `want` and vice versa.
    fn same_corner_set(got: [Vec3; 4], want: [Vec3; 4], tolerance: f32) -> bool {
        let covers = |a: &[Vec3; 4], b: &[Vec3; 4]| a.iter().all(|p| b.iter().any(|q| p.distance(*q) <= tolerance));
        covers(&got, &want) && covers(&want, &got)
    }

    #[test]
    fn parallelograms_split_either_way_with_either_winding() {
        // A slanted parallelogram (not a rectangle) in a tilted plane, away from the origin.
        let origin = Vec3::new(10.0, -3.0, 4.5);
        let (u, v) = (Vec3::new(2.0, 0.5, 0.0), Vec3::new(0.75, 0.25, 1.5));
        let c = [origin, origin + u, origin + u + v, origin + v];
        let front = u.cross(v).normalize();
        // Counter-clockwise seen from `front`: 0 1 2 3. Both diagonals, both windings, rotated starts.
        let splits: [([[u32; 3]; 2], f32); 6] = [
            ([[0, 1, 2], [0, 2, 3]], 1.0),
            ([[0, 1, 3], [1, 2, 3]], 1.0),
            ([[2, 3, 1], [3, 0, 1]], 1.0),
            ([[0, 2, 1], [0, 3, 2]], -1.0),
            ([[0, 3, 1], [1, 3, 2]], -1.0),
            ([[3, 2, 0], [2, 1, 0]], -1.0),
        ];
        for (triangles, facing) in splits {
            // Indexed and unindexed (six vertices, like a glTF primitive without indices).
            let indexed = emissive(c.to_vec(), triangles.to_vec());
            let flat = triangles.iter().flatten().map(|&i| c[i as usize]).collect();
            let unindexed = emissive(flat, vec![[0, 1, 2], [3, 4, 5]]);
            for mesh in [indexed, unindexed] {
                let q = parallelogram(&mesh).unwrap_or_else(|| panic!("{triangles:?} not detected"));
                assert!(same_corner_set(q.corners(), c, 1e-5), "{triangles:?}: {q:?}");
                let n = q.edge_u.cross(q.edge_v);
                assert!((n.length() - u.cross(v).length()).abs() < 1e-4, "{triangles:?}: area {}", n.length());
                assert!((n.normalize().dot(front) - facing).abs() < 1e-5, "{triangles:?}: facing {n}");
                assert!(c.contains(&q.corner));
            }
        }
    }

    /// A small lamp far from the origin and a thin strip light: the lamp's rounding slack (0.19 at
    /// 10⁵ from the origin) is capped below its short sides, so each corner still has one
    /// partner; the strip's tolerance follows its width.
    #[test]
    fn small_lights_far_out_and_thin_strips_are_parallelograms() {
        let square = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        let far = square.map(|p| p * 0.15 + Vec3::new(1.0e5, 0.0, 0.0));
        let strip = square.map(|p| p * Vec3::new(2.0, 1.0e-4, 1.0));
        for corners in [far, strip] {
            let mesh = emissive(corners.to_vec(), vec![[0, 1, 2], [0, 2, 3]]);
            let q = parallelogram(&mesh).unwrap_or_else(|| panic!("{corners:?} not detected"));
            assert!(same_corner_set(q.corners(), corners, 1e-2), "{q:?}");
        }
    }

    /// A lamp 10⁵ from the origin, tilted off every axis, whose corners carry their own `f32`
    /// rounding (an ulp there is 0.0078): the rounding bends it 0.002 out of a parallelogram, 15
    /// times the shape tolerance of a lamp its size (10⁻⁴ of its diameter), and the rounding slack
    /// `16 ε · m` (0.19 at 10⁵) is what still makes it a quad light — a scene's light, not an
    /// unsupported emitter left as plain geometry. Without the slack it was refused. (The other
    /// far lamps in these tests are axis-aligned: their corners share rounded coordinates, whose
    /// errors cancel.)
    #[test]
    fn a_lamp_whose_corners_carry_f32_rounding_far_out_is_a_light() {
        let far = DVec3::new(1e5, -6e4, 3e4);
        let (u, v) = (DVec3::new(0.8, 0.36, -0.48), DVec3::new(0.1, 0.6, 0.45));
        let corners = [far, far + u, far + u + v, far + v].map(DVec3::as_vec3);
        let bend = corners.map(Vec3::as_dvec3);
        let bend = (bend[0] + bend[2] - bend[1] - bend[3]).length();
        let shape = RELATIVE_TOLERANCE * (u + v).length();
        assert!(bend > 10.0 * shape, "the rounding bends it {bend}, within the shape tolerance {shape}");
        let mesh = emissive(corners.to_vec(), vec![[0, 1, 2], [0, 2, 3]]);
        let q = parallelogram(&mesh).expect("a quad light despite the rounding");
        assert!(same_corner_set(q.corners(), corners, 0.01), "{q:?}");
        let scene = crate::scene::Scene::new("far lamp", vec![mesh], crate::scene::cornell::camera()).unwrap();
        assert_eq!((scene.lights().len(), scene.unsupported_emitters()), (1, 0));
    }

    /// A 2 m × 1 mm strip light in any orientation, its coordinates written to 10 µm (five
    /// decimals, as exporters write them): its shape error, up to 3.5 % of its width, is within
    /// the 5 % the narrow side allows.
    #[test]
    fn a_strip_written_with_five_decimals_is_a_parallelogram() {
        let mut rng = raywave_kernels::hash::CounterRng::new(9);
        for _ in 0..200 {
            let (along, across) = (rng.unit_vec3(), rng.unit_vec3());
            let across = (across - along * along.dot(across)).normalize_or(along.any_orthonormal_vector());
            let origin = rng.vec3(-1.0, 1.0);
            let corners = [Vec3::ZERO, along * 2.0, along * 2.0 + across * 1e-3, across * 1e-3]
                .map(|c| ((origin + c) * 1e5).round() / 1e5);
            let mesh = emissive(corners.to_vec(), vec![[0, 1, 2], [0, 2, 3]]);
            assert!(parallelogram(&mesh).is_some(), "{corners:?}");
        }
    }

    /// A square too small for `f32` area arithmetic (side 10⁻¹², area 10⁻²⁴, its squared length
    /// below the smallest float) is no light, rather than a light that validation refuses — which
    /// failed the whole scene.
    #[test]
    fn a_light_too_small_for_f32_area_is_no_light_and_the_scene_loads() {
        let square = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y].map(|p| p * 1.0e-12);
        let mesh = emissive(square.to_vec(), vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(parallelogram(&mesh), None);
        let scene = crate::scene::Scene::new("tiny lamp", vec![mesh], crate::scene::cornell::camera());
        let scene = scene.expect("a scene with a too-small lamp loads");
        assert!(scene.lights().is_empty());
    }

    /// A parallelogram within the tolerance whose every vertex lies within the coordinate limit,
    /// but whose fourth corner rebuilt as `corner + edge_u + edge_v` lands 5000 past it: no light,
    /// and the scene loads (light validation refused the light, which failed the whole scene).
    #[test]
    fn a_light_whose_rebuilt_corner_passes_the_coordinate_limit_is_no_light_and_the_scene_loads() {
        let corners = [Vec3::ZERO, Vec3::new(1e8, 5e3, 0.0), Vec3::new(1e8, 1e8, 0.0), Vec3::new(5e3, 1e8, 0.0)];
        let mesh = emissive(corners.to_vec(), vec![[0, 1, 3], [1, 2, 3]]);
        assert_eq!(parallelogram(&mesh), None);
        let scene = crate::scene::Scene::new("far lamp", vec![mesh], crate::scene::cornell::camera());
        let scene = scene.expect("a scene with a lamp at the coordinate limit loads");
        assert!(scene.lights().is_empty());
        assert_eq!(scene.unsupported_emitters(), 1);
    }

    /// A lamp at the coordinate limit, every vertex within it and an exact parallelogram, whose
    /// corner rebuilt as `corner + edge_u + edge_v` rounds one ulp (8) past it: `edge_u` =
    /// 10⁸ − 8 − (−4) rounds up to 10⁸ and `corner + edge_u` = 10⁸ − 4 ties up to 10⁸ again. It is
    /// a light: `reach_within_limit`'s 8-ulp slack is for such double rounding of vertices at the
    /// limit. Without the slack it was an unsupported emitter, plain geometry.
    #[test]
    fn a_lamp_at_the_coordinate_limit_whose_rebuilt_corner_rounds_past_it_is_a_light() {
        let limit = crate::scene::MAX_COORDINATE;
        let (height, last) = (1e3, limit - 8.0);
        assert_eq!(last.next_up(), limit, "the ulp below the limit");
        let corners = [
            Vec3::new(-4.0, 0.0, 0.0),
            Vec3::new(last, 0.0, 0.0),
            Vec3::new(limit, height, 0.0),
            Vec3::new(4.0, height, 0.0),
        ];
        let mesh = emissive(corners.to_vec(), vec![[0, 1, 3], [1, 2, 3]]);
        let q = parallelogram(&mesh).expect("a quad light at the limit");
        assert_eq!(
            (q.corner, q.edge_u, q.edge_v),
            (corners[0], Vec3::new(limit, 0.0, 0.0), Vec3::new(8.0, height, 0.0))
        );
        let rebuilt = light_bounds(&Light::quad(q.corner, q.edge_u, q.edge_v, Vec3::ZERO, false));
        assert_eq!(rebuilt.max.x, limit + 8.0, "the rebuilt corner one ulp past the limit");
        let scene = crate::scene::Scene::new("lamp at the limit", vec![mesh], crate::scene::cornell::camera()).unwrap();
        assert_eq!((scene.lights().len(), scene.unsupported_emitters()), (1, 0));
    }

    #[test]
    fn near_parallelograms_within_tolerance_are_detected() {
        // Corners off by e (the parallelogram's error √3·e) in a unit square of diameter √2: the
        // tolerance is 1.41e-4 (plus rounding).
        let near = |e: f32| {
            let c =
                vec![Vec3::ZERO, Vec3::new(1.0, 0.0, e), Vec3::new(1.0 + e, 1.0, 0.0), Vec3::new(0.0, 1.0 - e, 0.0)];
            parallelogram(&emissive(c, vec![[0, 1, 2], [0, 2, 3]])).is_some()
        };
        assert!(near(3e-5));
        assert!(!near(3e-4));
        // Far from the origin, f32 rounding of the coordinates is tolerated too.
        let far = Vec3::new(4096.0, 1024.0, -4096.0);
        let c = [Vec3::ZERO, Vec3::new(0.1, 0.0, 0.0), Vec3::new(0.1, 0.0, 0.3), Vec3::new(0.0, 0.0, 0.3)];
        let q = parallelogram(&emissive(c.map(|p| p + far).to_vec(), vec![[0, 2, 1], [0, 3, 2]])).unwrap();
        assert!(q.edge_u.cross(q.edge_v).normalize().abs_diff_eq(Vec3::Y, 1e-3));
    }

    #[test]
    fn other_shapes_are_not_parallelograms() {
        type Case = (&'static str, Vec<Vec3>, Vec<[u32; 3]>);
        let square = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        let cases: Vec<Case> = vec![
            ("one triangle", square.to_vec(), vec![[0, 1, 2]]),
            ("three triangles", square.to_vec(), vec![[0, 1, 2], [0, 2, 3], [0, 1, 3]]),
            ("non-planar", vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.1), Vec3::Y], vec![[0, 1, 2], [0, 2, 3]]),
            ("trapezoid", vec![Vec3::ZERO, Vec3::X, Vec3::new(0.8, 1.0, 0.0), Vec3::Y], vec![[0, 1, 2], [0, 2, 3]]),
            // A strip 2 long and 10⁻³ wide, 15 % narrower at one end, and one twisted 8.5° out of
            // its plane there: within 10⁻⁴ of its length, outside 5 % of its width.
            (
                "narrowing strip",
                vec![Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0), Vec3::new(2.0, 0.85e-3, 0.0), Vec3::new(0.0, 1e-3, 0.0)],
                vec![[0, 1, 3], [1, 2, 3]],
            ),
            (
                "twisted strip",
                vec![Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0), Vec3::new(2.0, 1e-3, 1.5e-4), Vec3::new(0.0, 1e-3, 0.0)],
                vec![[0, 1, 3], [1, 2, 3]],
            ),
            ("kite", vec![Vec3::ZERO, Vec3::X, Vec3::new(1.5, 1.5, 0.0), Vec3::Y], vec![[0, 1, 2], [0, 2, 3]]),
            (
                "sharing one corner",
                [square.to_vec(), vec![Vec3::new(2.0, 1.0, 0.0), Vec3::new(2.0, 2.0, 0.0)]].concat(),
                vec![[0, 1, 2], [2, 4, 5]],
            ),
            (
                "disjoint",
                [square.to_vec(), square.map(|p| p + Vec3::Z * 5.0).to_vec()].concat(),
                vec![[0, 1, 2], [4, 6, 7]],
            ),
            ("same triangle twice", square.to_vec(), vec![[0, 1, 2], [0, 1, 2]]),
            ("front and back", square.to_vec(), vec![[0, 1, 2], [0, 2, 1]]),
            ("inconsistent winding", square.to_vec(), vec![[0, 1, 2], [0, 3, 2]]),
            (
                "folded onto one side",
                vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::new(0.5, 0.2, 0.0)],
                vec![[0, 1, 2], [0, 2, 3]],
            ),
        ];
        for (what, positions, triangles) in cases {
            assert_eq!(parallelogram(&emissive(positions, triangles)), None, "{what}");
        }
        // A two-sided lamp has no front face for its triangles to agree on: wound either way, it
        // is a light (it had been refused), facing its first triangle's way; the same triangle
        // twice is still none.
        let two_sided = |triangles| {
            let mut mesh = emissive(square.to_vec(), triangles);
            mesh.material.double_sided = true;
            parallelogram(&mesh)
        };
        let light = two_sided(vec![[0, 1, 2], [0, 3, 2]]).expect("a two-sided light");
        assert!(light.edge_u.cross(light.edge_v).z > 0.0, "{light:?}");
        assert_eq!(two_sided(vec![[0, 1, 2], [0, 2, 1]]), None);
    }

    /// A lamp bent within the tolerance — its second triangle's own corner off the first
    /// triangle's plane — is moved onto its light: indexed or not (six vertices, the shared
    /// corners written twice), split along either diagonal, every vertex becomes one of the
    /// light's corners as the kernels rebuild them, all four used, so both triangles lie in the
    /// light's plane; vertices not in a triangle stay where they were.
    #[test]
    fn a_bent_lamp_is_moved_onto_its_light() {
        let origin = Vec3::new(10.0, -3.0, 4.5);
        let (u, v) = (Vec3::new(2.0, 0.5, 0.0), Vec3::new(0.75, 0.25, 1.5));
        let normal = u.cross(v).normalize();
        let unused = Vec3::new(-7.0, 8.0, 9.0);
        for (triangles, bent) in [([[0, 1, 2], [0, 2, 3]], 3), ([[0, 1, 3], [1, 2, 3]], 2)] {
            let mut c = vec![origin, origin + u, origin + u + v, origin + v, unused];
            // 0.8·10⁻⁴ of the diagonal, within the fit's 10⁻⁴.
            c[bent] += 0.8e-4 * (u + v).length() * normal;
            let flat = triangles.iter().flatten().map(|&i| c[i as usize]).collect();
            for mesh in [emissive(c.clone(), triangles.to_vec()), emissive(flat, vec![[0, 1, 2], [3, 4, 5]])] {
                let mut meshes = [mesh];
                let light = derive(&mut meshes).lights[0];
                let (corner, eu, ev) = (light.position.truncate(), light.edge_u.truncate(), light.edge_v.truncate());
                let corners = Parallelogram { corner, edge_u: eu, edge_v: ev }.corners();
                let snapped = &meshes[0];
                let used: Vec<Vec3> =
                    snapped.triangles.iter().flatten().map(|&i| snapped.positions[i as usize]).collect();
                assert!(used.iter().all(|p| corners.contains(p)), "{triangles:?}: {used:?} vs {corners:?}");
                assert!(corners.iter().all(|c| used.contains(c)), "{triangles:?}: a corner unused");
                let off_plane =
                    used.iter().map(|p| (*p - corner).dot(eu.cross(ev).normalize()).abs()).fold(0.0, f32::max);
                // A few f32 steps of the coordinates (the bend was 2.6·10⁻⁴).
                let steps = 8.0 * f32::EPSILON * (origin + u + v).abs().max_element();
                assert!(off_plane < steps, "{triangles:?}: {off_plane} off the plane");
                if snapped.positions.len() == 5 {
                    assert_eq!(snapped.positions[4], unused);
                }
            }
        }
    }

    /// Strip lights 192.5 and 10⁷ long, down to the narrowest a light can be at such a length
    /// (the squared length of `edge_u × edge_v` just above `f32`'s smallest), along and across
    /// the axes: moved onto their lights, their vertices stay where they were (each is its light's
    /// corner), so their triangles keep their area, the scene its bounds and the render a finite
    /// ray extent. Compared in `f32`, the squared distances across a strip narrower than about
    /// 2.6·10⁻²³ underflowed to 0 and two vertices went to the far side: the fuzzer's strip left
    /// its scene no bounds, and the render was refused for an infinite ray extent.
    #[test]
    fn a_strip_narrower_than_f32_squared_distances_keeps_its_vertices() {
        for (length, width) in [(192.5f32, 1e-12f32), (192.5, 1e-20), (192.5, 2.646_978e-23), (1e7, 1e-28)] {
            for (along, across) in [(Vec3::Z, -Vec3::X), (Vec3::new(0.6, 0.8, 0.0), Vec3::Z)] {
                let (u, v) = (along * length, across * width);
                let corners = vec![Vec3::ZERO, u, u + v, v];
                let mesh = emissive(corners.clone(), vec![[0, 1, 2], [0, 2, 3]]);
                let scene = crate::scene::Scene::new("strip", vec![mesh], crate::scene::cornell::camera())
                    .unwrap_or_else(|err| panic!("width {width}, {along}: {err}"));
                assert_eq!(scene.lights().len(), 1, "width {width}, {along}");
                let mesh = &scene.meshes()[0];
                assert_eq!(mesh.positions, corners, "width {width}, {along}: vertices moved");
                let lo = corners.iter().fold(Vec3::MAX, |lo, &p| lo.min(p));
                let hi = corners.iter().fold(Vec3::MIN, |hi, &p| hi.max(p));
                assert_eq!(scene.bounds(), (lo, hi), "width {width}, {along}");
                let tmax = crate::frame::generate_params(&scene, 16, 9, 0).tmax;
                assert!(tmax.is_finite(), "width {width}, {along}: tmax {tmax}");
            }
        }
    }

    #[test]
    fn derive_maps_lights_and_meshes_both_ways() {
        let square = vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        let lit = emissive(square.clone(), vec![[0, 1, 2], [0, 2, 3]]);
        let dark = Mesh { material: Material::diffuse(Vec3::ONE), ..lit.clone() };
        let bent = emissive(vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.5), Vec3::Y], vec![[0, 1, 2], [0, 2, 3]]);
        let derived = derive(&mut [dark, lit.clone(), bent, lit]);
        assert_eq!(derived.lights.len(), 2);
        assert_eq!(derived.lights.iter().map(|l| l.mesh).collect::<Vec<_>>(), vec![1, 3]);
        assert_eq!(derived.mesh_lights, vec![None, Some(0), None, Some(1)]);
        assert_eq!(derived.unsupported, 1);
        let light = derived.lights[0];
        assert_eq!(light.radiance.truncate(), Vec3::new(3.0, 2.0, 1.0));
        assert_eq!(light.two_sided, 0);
        assert_eq!(light.edge_u.truncate().cross(light.edge_v.truncate()), Vec3::Z);
    }
}
