//! Self-intersection avoidance for secondary rays: the origin offset of Wächter & Binder, "A Fast
//! and Robust Method for Avoiding Self-Intersection", Ray Tracing Gems, ch. 6, 2019.
//!
//! The hit point is moved along the geometric normal by a fixed number of ulps (integer
//! arithmetic on the float bits), so the offset scales with the point's own rounding error at any
//! distance from the origin; near the origin, where ulps vanish, a small absolute offset is used.

use glam::Vec3;

/// Below this magnitude a component is offset by an absolute amount (the paper's `origin()`).
const ORIGIN: f32 = 1.0 / 32.0;
/// Absolute offset scale used near the origin (the paper's `float_scale()`).
const FLOAT_SCALE: f32 = 1.0 / 65536.0;
/// Ulps per unit normal used elsewhere (the paper's `int_scale()`).
const INT_SCALE: f32 = 256.0;

fn offset_component(p: f32, n: f32) -> f32 {
    if p.abs() < ORIGIN {
        return p + FLOAT_SCALE * n;
    }
    let ulps = (INT_SCALE * n) as i32;
    // Moving the bit pattern away from zero grows |p|; towards zero shrinks it: flip for p < 0.
    let step = if p < 0.0 { -ulps } else { ulps };
    f32::from_bits((p.to_bits() as i32).wrapping_add(step) as u32)
}

/// The origin for a ray leaving a surface at `p` on the side `n` points to. `n` is the unit
/// geometric normal, flipped by the caller to face the side the new ray travels into; `p` should
/// come from the barycentric interpolation of the triangle's vertices, the most accurate hit point.
pub fn offset_ray_origin(p: Vec3, n: Vec3) -> Vec3 {
    Vec3::new(offset_component(p.x, n.x), offset_component(p.y, n.y), offset_component(p.z, n.z))
}

/// Where a ray from `origin` along unit `direction`, sent to `target` on a surface with unit
/// normal `target_normal` (either orientation), must stop so that the surface itself cannot block
/// it: the distance to the plane through `target` lifted off the surface towards the ray by the
/// same offset [`offset_ray_origin`] gives the ray's start (pbrt-v4's `SpawnRayTo` offsets both
/// ends alike). The margin along the ray is that offset over `|cos|` of the angle between the ray
/// and the normal, so it holds at grazing angles, where a margin relative to the distance alone
/// falls below the rounding of the surface's points (one far from the origin, above all).
/// Returns 0 when no such stop exists — the ray parallel to the surface, or the lifted plane
/// behind the origin — or the inputs are not finite.
pub fn ray_stop_before(origin: Vec3, direction: Vec3, target: Vec3, target_normal: Vec3) -> f32 {
    let towards_origin = if target_normal.dot(direction) > 0.0 { -target_normal } else { target_normal };
    let lifted = offset_ray_origin(target, towards_origin);
    let t = (lifted - origin).dot(towards_origin) / direction.dot(towards_origin);
    if t > 0.0 && t.is_finite() {
        t
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offset_moves_to_the_normal_side_at_every_scale() {
        for scale in [1e-6f32, 1e-3, 1.0, 1e3, 1e5, 1e7] {
            for sign in [1.0f32, -1.0] {
                let p = Vec3::new(scale * sign, -scale, 0.5 * scale);
                let n = Vec3::new(0.6, 0.0, -0.8);
                let q = offset_ray_origin(p, n);
                assert!((q - p).dot(n) > 0.0, "scale {scale}: {p} → {q}");
                assert_eq!(q.y, p.y, "no movement along a zero normal component");
                // The step stays a few hundred ulps (or 2⁻¹⁶ near the origin): tiny against p.
                let ulp = (p.x.abs().max(ORIGIN)) * f32::EPSILON;
                assert!((q.x - p.x).abs() <= 256.0 * ulp.max(FLOAT_SCALE / 256.0), "scale {scale}: {}", q.x - p.x);
            }
        }
    }

    /// Rays sent from 0.4 away to random points of a 0.1 × 0.1 quad (two triangles, in an
    /// axis-aligned and in a tilted plane) at cosines to its normal from 1 down to 10⁻³ — or down
    /// to where the ray's start is 4 offsets from the plane — with the quad up to 1 km from the
    /// origin: stopped by [`ray_stop_before`], none meets the quad in raywave's watertight triangle
    /// test, and none stops further short than twice the lifted plane's offset over the cosine.
    #[test]
    fn a_ray_stopped_before_a_surface_never_meets_it_at_any_distance_or_angle() {
        let mut rng = crate::hash::CounterRng::new(11);
        for scale in [0.0f32, 1.0, 1e2, 1e3] {
            for normal in [Vec3::Y, Vec3::new(0.3, -0.8, 0.52).normalize()] {
                let centre = scale * Vec3::new(1.0, -0.5, 0.7);
                let eu = 0.1 * normal.any_orthonormal_vector();
                let ev = normal.cross(eu);
                let corner = centre - 0.5 * (eu + ev);
                let vertices = [corner, corner + eu, corner + eu + ev, corner + ev];
                let ulp = centre.abs().max_element().max(ORIGIN) * f32::EPSILON;
                let lift = 256.0 * ulp + FLOAT_SCALE;
                let min_cos = (4.0 * lift / 0.4).max(1e-3);
                for _ in 0..20_000 {
                    let target = corner + rng.next_f32() * eu + rng.next_f32() * ev;
                    let cos = min_cos.powf(rng.next_f32());
                    let side = if rng.next_f32() < 0.5 { 1.0 } else { -1.0 };
                    let along = (eu * rng.range(-1.0, 1.0) + ev * rng.range(-1.0, 1.0)).normalize();
                    let origin = target + 0.4 * (side * cos * normal + (1.0 - cos * cos).sqrt() * along);
                    let direction = (target - origin).normalize();
                    let distance = (target - origin).length();
                    let t = ray_stop_before(origin, direction, target, normal);
                    let case = std::format!("scale {scale}, normal {normal}, cos {cos}: t {t} of {distance}");
                    assert!(t > 0.0 && t < distance, "{case}");
                    let ray = crate::triangle::WatertightRay::new(origin, direction);
                    for [a, b, c] in [[0, 1, 2], [0, 2, 3]] {
                        let hit = ray.intersect(vertices[a], vertices[b], vertices[c], 0.0, t);
                        assert!(hit.is_none(), "{case}: meets the quad");
                    }
                    let cos_to_plane = direction.dot(normal).abs();
                    assert!(distance - t <= 2.0 * lift / cos_to_plane, "{case}");
                }
            }
        }
    }

    #[test]
    fn no_stop_exists_along_the_surface_behind_the_start_or_within_the_offset() {
        let (origin, target) = (Vec3::new(0.0, 1.0, 0.0), Vec3::new(1.0, 1.0, 0.0));
        assert_eq!(ray_stop_before(origin, Vec3::X, target, Vec3::Y), 0.0);
        assert_eq!(ray_stop_before(origin, Vec3::X, target, Vec3::NAN), 0.0);
        assert_eq!(ray_stop_before(Vec3::NAN, Vec3::X, target, Vec3::X), 0.0);
        // A target behind the origin.
        assert_eq!(ray_stop_before(origin, -Vec3::X, target, Vec3::X), 0.0);
        // A start closer to the surface than its lifted plane (here 256 ulps of 100: 2 mm).
        let (surface, near) = (Vec3::new(100.0, 0.0, 0.0), Vec3::new(99.999, 0.0, 1.0));
        assert_eq!(ray_stop_before(near, (surface - near).normalize(), surface, Vec3::X), 0.0);
    }

    #[test]
    fn offset_is_finite_for_extreme_inputs() {
        for p in [Vec3::ZERO, Vec3::splat(-0.0), Vec3::splat(f32::MAX / 2.0), Vec3::splat(1e-38)] {
            assert!(offset_ray_origin(p, Vec3::Y).is_finite(), "{p}");
        }
    }
}
