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

    #[test]
    fn offset_is_finite_for_extreme_inputs() {
        for p in [Vec3::ZERO, Vec3::splat(-0.0), Vec3::splat(f32::MAX / 2.0), Vec3::splat(1e-38)] {
            assert!(offset_ray_origin(p, Vec3::Y).is_finite(), "{p}");
        }
    }
}
