//! The G-buffer the denoiser's edge stops read, and the edge-stop weight itself.

use crate::shade::stage::SMALLEST_RADIANCE;
use glam::{Vec4, Vec4Swizzles};

/// A pixel's surface as the edge stops see it.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Guide {
    /// Surface point (xyz, scene units) and its depth along the camera ray (w, at least 2⁻¹²⁶:
    /// [`is_surface_depth`]); w = 0 where the camera ray hit nothing (such pixels are never
    /// filtered nor weigh as taps of the bilateral and à-trous passes; the noise lines and SVGF's
    /// variance prefilter read them, their ratio the fallback 1 and their variance 0).
    pub position: Vec4,
    /// Unit surface normal facing the camera (xyz) and the luminance of the analytic `U` (w).
    pub normal: Vec4,
}

impl Guide {
    /// A pixel without a surface (a miss, or a tap outside the image).
    pub const NONE: Guide = Guide { position: Vec4::ZERO, normal: Vec4::ZERO };

    /// Whether a camera ray hit a surface here ([`is_surface_depth`]).
    pub fn is_surface(&self) -> bool {
        is_surface_depth(self.position.w)
    }
}

/// Whether a depth (hit distance along the camera ray) marks a surface: depths below the
/// smallest normal `f32` (2⁻¹²⁶) count as none, like 0 and NaN, on every backend — a GPU may
/// flush a subnormal hit distance (a camera a hair from a wall) to 0 where the CPU keeps it, as
/// with [`SMALLEST_WEIGHT`].
pub fn is_surface_depth(depth: f32) -> bool {
    depth >= f32::MIN_POSITIVE
}

/// Filter weights below the smallest normal `f32` (2⁻¹²⁶) count as 0, on every backend: a GPU may
/// flush such a subnormal weight to 0 (Vulkan leaves denormals to the device) where the CPU keeps
/// it. The bilateral Gaussian `exp(−(r/g)²)` is subnormal for `(r/g)²` in 87.3 … 104, and SVGF's
/// luminance stop wherever the variance is small. (A weight within a few ulp of the threshold may
/// still land on either side: Vulkan bounds `exp`'s error at `3 + 2·|x|` ulp.)
pub const SMALLEST_WEIGHT: f32 = f32::MIN_POSITIVE;

/// Depth differences are measured relative to the centre's depth so the stop is unit-free: with
/// weight 1 a relative difference of 1/4 zeroes it — the reference's `1 − |Δz|·Wd` in metres for
/// a surface 4 m away [H-DX].
const DEPTH_SCALE: f32 = 4.0;

/// Tap offsets below this fraction of the centre's depth count as the same point for the plane
/// stop, which has no direction to measure there. Much smaller than the reference's
/// `dist² < 0.001` m² (3.2 cm; 7.9·10⁻³ of the depth at the 4 m of `DEPTH_SCALE`), which at 512²
/// and 90° skips the plane stop for the taps within two pixels: here it only guards the division
/// and applies to every other tap (a deviation, kept: the denoiser's measured figures use it).
const SAME_POINT: f32 = 1.0e-4;

/// The joint bilateral weight of `tap` seen from `center`, in `[0, 1]`: the product of the four
/// edge stops of the reference code [H-DX, H-CPU], with `weights` = (depth `Wd`, normal `Wn`,
/// plane `Wp`, analytic `Wa`):
/// - depth `max(0, 1 − Wd·4·|Δz|/z)` (relative, see `DEPTH_SCALE`);
/// - normal `max(0, 1 − Wn·(1 − clamp(n_c·n_t, 0, 1)⁴))` — the reference raises `n_c·n_t` itself
///   to the fourth power, which weighs opposite normals as equal ones; clamped here, they weigh
///   0, and normals not unit long cannot lift the stop above 1;
/// - plane `max(0, 1 − 2·Wp·max(|dq·n_t|, |dq·n_c|)/|dq|)²` (1 for coincident points);
/// - analytic `max(0, 1 − 10·Wa·|ΔL|/max(L_c, L_t))` — relative to the luminances so it does not
///   depend on the lights' units (the reference uses absolute display-referred values); 1 when
///   both are 0 (below [`SMALLEST_RADIANCE`]). The relative difference is at most 1, so with the
///   default `Wa` = 0.09 this stop only lowers a tap's weight, to 0.1 at the least, and never
///   rejects it — as the reference's does for luminances within [0, 1].
///
/// 0 when the tap has no surface. The host keeps each weight 0 or within
/// [`MIN_EDGE_WEIGHT`](raywave_shared::denoise::MIN_EDGE_WEIGHT) …
/// [`MAX_EDGE_WEIGHT`](raywave_shared::denoise::MAX_EDGE_WEIGHT), where `4·Wd` and `10·Wa` are
/// finite and normal (an infinite one times a zero difference had made every tap's stop NaN, so
/// 0).
///
/// Always inlined: called for every tap of the bilateral and à-trous passes, it was a call per tap
/// in the CPU build; inlined, the SVGF baseline takes 0.8× the time on the CPU (README).
#[inline(always)]
pub fn edge_stop(center: &Guide, tap: &Guide, weights: Vec4) -> f32 {
    if !tap.is_surface() || !center.is_surface() {
        return 0.0;
    }
    let depth_center = center.position.w;
    let depth = (1.0 - weights.x * DEPTH_SCALE * (tap.position.w - depth_center).abs() / depth_center).max(0.0);
    let (n_c, n_t) = (center.normal.xyz(), tap.normal.xyz());
    // At most 1 whatever the normals' lengths, so that every stop, and the weight, stays in
    // [0, 1]: the filters' overflow margin (`MAX_FILTERED_RADIANCE`) counts on it, and normals
    // 1.1 long had summed 41 taps to 39.8 (> 32) and overflowed U_N's sum.
    let cos = n_c.dot(n_t).clamp(0.0, 1.0);
    let cos4 = (cos * cos) * (cos * cos);
    let normal = (1.0 - weights.y * (1.0 - cos4)).max(0.0);
    // In units of the centre's depth before squaring, so that the length neither overflows (an
    // offset beyond 1.8·10¹⁹ had made the stop 1 for any geometry) nor turns subnormal (which a
    // GPU may flush) at scales the depth shares.
    let offset = (tap.position.xyz() - center.position.xyz()) / depth_center;
    let distance = offset.length();
    let plane = if distance <= SAME_POINT {
        1.0
    } else {
        let off_plane = offset.dot(n_t).abs().max(offset.dot(n_c).abs()) / distance;
        let w = (1.0 - 2.0 * weights.z * off_plane).max(0.0);
        w * w
    };
    let (l_c, l_t) = (center.normal.w.max(0.0), tap.normal.w.max(0.0));
    let brighter = l_c.max(l_t);
    let analytic = if brighter < SMALLEST_RADIANCE {
        1.0
    } else {
        (1.0 - 10.0 * weights.w * (l_c - l_t).abs() / brighter).max(0.0)
    };
    let w = depth * normal * plane * analytic;
    if w.is_finite() {
        w
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use raywave_shared::denoise::{DEFAULT_EDGE_WEIGHTS, MAX_EDGE_WEIGHT};

    fn guide(p: Vec3, depth: f32, n: Vec3, l: f32) -> Guide {
        Guide { position: p.extend(depth), normal: n.extend(l) }
    }

    #[test]
    fn same_plane_neighbours_weigh_one_and_edges_zero() {
        let c = guide(Vec3::ZERO, 10.0, Vec3::Y, 0.5);
        let neighbour = guide(Vec3::new(0.01, 0.0, 0.0), 10.0, Vec3::Y, 0.5);
        assert_eq!(edge_stop(&c, &neighbour, DEFAULT_EDGE_WEIGHTS), 1.0);
        let wall = guide(Vec3::new(0.01, 0.01, 0.0), 10.0, Vec3::X, 0.5);
        assert_eq!(edge_stop(&c, &wall, DEFAULT_EDGE_WEIGHTS), 0.0, "perpendicular normal");
        let behind = guide(Vec3::new(0.0, -5.0, 0.0), 15.0, Vec3::Y, 0.5);
        assert_eq!(edge_stop(&c, &behind, DEFAULT_EDGE_WEIGHTS), 0.0, "depth jump off the plane");
        assert_eq!(edge_stop(&c, &Guide::NONE, DEFAULT_EDGE_WEIGHTS), 0.0, "no surface");
        let subnormal = guide(Vec3::new(0.01, 0.0, 0.0), 1e-40, Vec3::Y, 0.5);
        assert!(!subnormal.is_surface(), "a subnormal depth, which a GPU may flush to 0");
        assert_eq!(edge_stop(&c, &subnormal, DEFAULT_EDGE_WEIGHTS), 0.0, "a subnormal depth");
        assert!(guide(Vec3::ZERO, f32::MIN_POSITIVE, Vec3::Y, 0.5).is_surface());
        let brighter = guide(Vec3::new(0.01, 0.0, 0.0), 10.0, Vec3::Y, 1.0);
        let w = edge_stop(&c, &brighter, DEFAULT_EDGE_WEIGHTS);
        assert!((w - (1.0 - 0.9 * 0.5)).abs() < 1e-6, "analytic stop {w}");
    }

    /// The depth stop's value between its all-or-nothing ends: `1 − Wd·4·|Δz|/z_c`, relative to
    /// the centre's depth, so the two sides of a pair differ (only the depth stop weighs here,
    /// the other weights 0). The other depth tests pass for any scale from ~0.2 to 10⁶ and for
    /// either pixel's depth as the divisor.
    #[test]
    fn the_depth_stop_is_four_relative_depth_differences_from_one() {
        let near = guide(Vec3::ZERO, 10.0, Vec3::Y, 0.5);
        let far = guide(Vec3::new(0.01, 0.0, 0.0), 10.1, Vec3::Y, 0.5);
        for depth_weight in [1.0f32, 2.0] {
            let depth_only = Vec4::new(depth_weight, 0.0, 0.0, 0.0);
            for (center, tap, expected) in [
                (&near, &far, 1.0 - depth_weight * 4.0 * 0.1 / 10.0),
                (&far, &near, 1.0 - depth_weight * 4.0 * 0.1 / 10.1),
            ] {
                let w = edge_stop(center, tap, depth_only);
                assert!((w - expected).abs() < 1e-6, "Wd {depth_weight}: {w} vs {expected}");
            }
        }
    }

    /// Opposite normals weigh 0 (the two faces of a thin wall, or a normal flipped by the
    /// camera-facing rule across a silhouette), however close the points: the reference's
    /// `(n_c·n_t)⁴` alone weighs them as equal ones, which the clamp of the cosine to [0, 1]
    /// prevents. Normals 120° apart weigh 0 as well, and 60° apart `1 − Wn·(1 − ½⁴)` (the
    /// plane stop is 1 there: the tap lies along the line where both planes meet).
    #[test]
    fn opposite_and_steep_normals_weigh_by_the_clamped_cosine() {
        let c = guide(Vec3::ZERO, 10.0, Vec3::Y, 0.5);
        let tap = |n: Vec3| guide(Vec3::new(0.0, 0.0, 0.01), 10.0, n, 0.5);
        assert_eq!(edge_stop(&c, &tap(Vec3::NEG_Y), DEFAULT_EDGE_WEIGHTS), 0.0, "opposite normals");
        let (sin, cos) = 120f32.to_radians().sin_cos();
        assert_eq!(edge_stop(&c, &tap(Vec3::new(sin, cos, 0.0)), DEFAULT_EDGE_WEIGHTS), 0.0, "120° apart");
        let weights = Vec4::new(1.0, 0.5, 1.5, 0.09);
        let (sin, cos) = 60f32.to_radians().sin_cos();
        let w = edge_stop(&c, &tap(Vec3::new(sin, cos, 0.0)), weights);
        let expected = 1.0 - 0.5 * (1.0 - cos.powi(4));
        assert!((w - expected).abs() < 1e-6, "60° apart: {w} vs {expected}");
    }

    /// The plane stop takes the larger distance of the tap from either surface's plane, so it is
    /// the same seen from either pixel: a tap in its own plane but off the centre's (an offset
    /// along the tap's tangent, not the centre's) is still stopped, by `(1 − 2·Wp·|dq·n_c|/|dq|)²`
    /// — only the plane stop weighs here (the other weights 0).
    #[test]
    fn the_plane_stop_measures_both_planes() {
        let n_t = Vec3::new(0.1, 1.0, 0.0).normalize();
        let offset = Vec3::new(1.0, -0.1, 0.0) * 0.01;
        assert!(offset.dot(n_t).abs() < 1e-9, "the tap lies in its own plane");
        let c = guide(Vec3::ZERO, 10.0, Vec3::Y, 0.5);
        let t = guide(offset, 10.0, n_t, 0.5);
        let plane_only = Vec4::new(0.0, 0.0, 1.0, 0.0);
        let expected = (1.0 - 2.0 * offset.dot(Vec3::Y).abs() / offset.length()).powi(2);
        let w = edge_stop(&c, &t, plane_only);
        assert!((w - expected).abs() < 1e-5 && expected < 0.7, "{w} vs {expected}");
        assert_eq!(edge_stop(&t, &c, plane_only), w, "the same from the tap's side");
    }

    /// Normals that are not unit long (a caller's own `DenoiseInput`) still weigh at most 1.
    #[test]
    fn weights_stay_in_the_unit_interval_for_normals_of_any_length() {
        for length in [1.0f32 + 1e-6, 1.1, 2.0, 1e3] {
            let c = guide(Vec3::ZERO, 10.0, Vec3::Y * length, 0.5);
            let t = guide(Vec3::new(0.01, 0.0, 0.0), 10.0, Vec3::new(0.1, 1.0, 0.0).normalize() * length, 0.5);
            for tap in [c, t] {
                let w = edge_stop(&c, &tap, DEFAULT_EDGE_WEIGHTS);
                assert!((0.0..=1.0).contains(&w), "normals {length} long: weight {w}");
            }
        }
    }

    #[test]
    fn weights_are_scale_free_and_finite() {
        // The plane stop's offset had overflowed (1e25: the stop became 1) or underflowed (1e-25:
        // a coincident point) when squared in scene units.
        for scale in [1e-25f32, 1e-3, 1.0, 1e5, 1e25] {
            let c = guide(Vec3::ZERO, 10.0 * scale, Vec3::Y, 0.5);
            let t = guide(Vec3::new(0.01, 0.001, 0.0) * scale, 10.1 * scale, Vec3::Y, 0.4);
            let w = edge_stop(&c, &t, DEFAULT_EDGE_WEIGHTS);
            let w1 = edge_stop(
                &guide(Vec3::ZERO, 10.0, Vec3::Y, 0.5),
                &guide(Vec3::new(0.01, 0.001, 0.0), 10.1, Vec3::Y, 0.4),
                DEFAULT_EDGE_WEIGHTS,
            );
            assert!((w - w1).abs() < 1e-4, "scale {scale}: {w} vs {w1}");
        }
        let nan = guide(Vec3::splat(f32::NAN), 1.0, Vec3::Y, f32::NAN);
        let c = guide(Vec3::ZERO, 1.0, Vec3::Y, 0.5);
        assert_eq!(edge_stop(&c, &nan, DEFAULT_EDGE_WEIGHTS), 0.0);
    }

    /// At the largest weights the host accepts, a tap identical to its centre still weighs 1 and
    /// a differing one 0. Beyond the limit, at `Wd` = 10³⁸ (or `Wa` = 10³⁸), the scaled
    /// weight overflowed, ∞·0 made even the identical tap's stop NaN, so 0: why the host refuses
    /// such weights (`DenoiseInput::check`).
    #[test]
    fn the_largest_accepted_weights_keep_identical_taps_and_reject_different_ones() {
        let c = guide(Vec3::ZERO, 10.0, Vec3::Y, 0.5);
        let largest = Vec4::splat(MAX_EDGE_WEIGHT);
        assert_eq!(edge_stop(&c, &c, largest), 1.0);
        let farther = guide(Vec3::ZERO, 10.0 * (1.0 + 4.0 * f32::EPSILON), Vec3::Y, 0.5);
        assert_eq!(edge_stop(&c, &farther, largest), 0.0, "a relative depth difference of 4 ulp");
        let brighter = guide(Vec3::ZERO, 10.0, Vec3::Y, 0.5 * (1.0 + 4.0 * f32::EPSILON));
        assert_eq!(edge_stop(&c, &brighter, largest), 0.0, "a relative luminance difference of 4 ulp");
        for beyond in [Vec4::new(1.0e38, 1.0, 1.0, 0.1), Vec4::new(1.0, 1.0, 1.0, 1.0e38)] {
            assert_eq!(edge_stop(&c, &c, beyond), 0.0, "{beyond}: the failure the limit prevents");
        }
    }
}
