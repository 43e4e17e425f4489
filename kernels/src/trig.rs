//! Trigonometry from polynomials alone, so that the CPU and every Vulkan device compute the same
//! angles.
//!
//! Vulkan bounds its built-in `sin` and `cos` only to 2⁻¹¹ *absolute* error on `[−π, π]`, and
//! `asin`, `acos`, `atan` and `atan2` to 4096 ulp (Vulkan specification, "Precision and Operation
//! of SPIR-V Instructions"). lavapipe (LLVM's libm) is far better than that bound, an NVIDIA
//! driver is not: on an H200 the built-ins moved light samples and shadow-ray directions by up to
//! 4·10⁻³ against the CPU and failed the shade and warp parity tests. These functions use only
//! `+ − × ÷ √`, which Vulkan bounds to a few ulp, and `round`, which is exact, so every backend
//! agrees with the CPU to a few ulp; each is within a few ulp of the correctly rounded result
//! (tests below, against `f64`).

#![allow(clippy::neg_cmp_op_on_partial_ord)]

use core::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};
#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

/// tan(π/8) = √2 − 1: above it [`atan_unit`] reduces its argument by π/4.
pub(crate) const TAN_PI_8: f32 = 0.414_213_57;

/// `[c₇, c₅, c₃, c₁]` of S. L. Moshier's Cephes `atanf` polynomial (see [`atan_unit`]):
/// `atan t ≈ t + t·z·(((c₇·z + c₅)·z + c₃)·z + c₁)`, `z = t²`, on `|t| ≤ tan(π/8)`.
pub(crate) const ATAN_POLYNOMIAL: [f32; 4] = [8.053_744_5e-2, -1.387_768_6e-1, 1.997_771_1e-1, -3.333_295e-1];

/// `(sin x, cos x)` for `x` in `[−4π, 4π]` to within a few `f32` ulps (tested over that range:
/// 2 where the result is above 10⁻³, 10 at the zeros `kπ/2`; measured 1.2 and 8.6): Cody–Waite
/// reduction by π/2 in three parts (S. L. Moshier's Cephes `sinf` constants, doubled: the first
/// two have 8 and 11 significant bits, so `k` times either is exact for the `|k| ≤ 8` of that
/// range (and up to 2¹³), and no fused multiply–add changes those steps) to `|r| ≤ π/4`, then
/// Taylor polynomials to r⁹ and r¹⁰ (truncation below 2·10⁻⁹). Meant for that range, which
/// every caller keeps to (most within `[−2π, 2π]`; `slope_quadrature`'s azimuth integral runs
/// its last gap to just under 4π): beyond it the error grows with `|x|` (the third constant's
/// rounding times `k`), and past ~10⁸ the result is no longer bounded by 1.
pub fn sin_cos(x: f32) -> (f32, f32) {
    // π/2 = PI_2_A + PI_2_B + PI_2_C; A = 201/128 (8 significant bits), B 11 bits (Cephes `sinf`'s
    // DP1, DP2, DP3 for π/4, times 2). A two-part split with A = FRAC_PI_2 (24 bits) rounded
    // 3·A by 2⁻²³, an error of 1.2·10⁻⁷ in r for x near 3π/2: cos(4.712389) came out 11× too large.
    const PI_2_A: f32 = 1.570_312_5;
    const PI_2_B: f32 = 4.837_513e-4;
    const PI_2_C: f32 = 7.549_79e-8;
    let k = (x * (2.0 / PI)).round();
    let r = ((x - k * PI_2_A) - k * PI_2_B) - k * PI_2_C;
    let r2 = r * r;
    let sin_r = r * (1.0 + r2 * (-1.0 / 6.0 + r2 * (1.0 / 120.0 + r2 * (-1.0 / 5040.0 + r2 * (1.0 / 362_880.0)))));
    let cos_r =
        1.0 + r2 * (-0.5 + r2 * (1.0 / 24.0 + r2 * (-1.0 / 720.0 + r2 * (1.0 / 40_320.0 + r2 * (-1.0 / 3_628_800.0)))));
    // Quadrant k mod 4 (k may be negative).
    let quadrant = (k as i32) & 3;
    if quadrant == 0 {
        (sin_r, cos_r)
    } else if quadrant == 1 {
        (cos_r, -sin_r)
    } else if quadrant == 2 {
        (-sin_r, -cos_r)
    } else {
        (-cos_r, sin_r)
    }
}

/// `atan t` for `t` in `[0, 1]`: above tan(π/8) reduced by the identity
/// `atan t = π/4 + atan((t − 1)/(t + 1))`, then the odd polynomial of S. L. Moshier's Cephes
/// `atanf` on `|t| ≤ tan(π/8)` (Cephes Mathematical Library, atanf.c; "Methods and Programs for
/// Mathematical Functions", 1989: relative error 1.9·10⁻⁷ peak).
fn atan_unit(t: f32) -> f32 {
    let (offset, t) = if t > TAN_PI_8 { (FRAC_PI_4, (t - 1.0) / (t + 1.0)) } else { (0.0, t) };
    let z = t * t;
    let [c7, c5, c3, c1] = ATAN_POLYNOMIAL;
    let poly = ((c7 * z + c5) * z + c3) * z + c1;
    offset + (poly * z * t + t)
}

/// `atan2(y, x)`: the angle of the point `(x, y)` in `[−π, π]`, with the IEEE conventions of the
/// standard library's for signed zeros and infinities (`atan2(±0, −0) = ±π`,
/// `atan2(±∞, ±∞) = ±π/4` or `±3π/4`); NaN if either argument is. From `atan_unit` of the
/// smaller magnitude over the larger, so it keeps full relative precision for tiny angles.
pub fn atan2(y: f32, x: f32) -> f32 {
    if x.is_nan() || y.is_nan() {
        return x + y;
    }
    let (ax, ay) = (x.abs(), y.abs());
    let (small, large) = if ay > ax { (ax, ay) } else { (ay, ax) };
    let ratio = if large == 0.0 {
        0.0
    } else if large.is_infinite() {
        if small.is_infinite() {
            1.0
        } else {
            0.0
        }
    } else {
        small / large
    };
    let mut angle = atan_unit(ratio);
    if ay > ax {
        angle = FRAC_PI_2 - angle;
    }
    if x.is_sign_negative() {
        angle = PI - angle;
    }
    if y.is_sign_negative() {
        -angle
    } else {
        angle
    }
}

/// `atan x` in `[−π/2, π/2]`.
pub fn atan(x: f32) -> f32 {
    atan2(x, 1.0)
}

/// `asin x` in `[−π/2, π/2]` for `x` in `[−1, 1]` (NaN outside, as the standard library's), as
/// `atan2(x, √((1 − x)(1 + x)))`: the factored radicand keeps its precision near `|x| = 1`.
pub fn asin(x: f32) -> f32 {
    atan2(x, ((1.0 - x) * (1.0 + x)).sqrt())
}

/// `acos x` in `[0, π]` for `x` in `[−1, 1]` (NaN outside), as `atan2(√((1 − x)(1 + x)), x)`.
pub fn acos(x: f32) -> f32 {
    atan2(((1.0 - x) * (1.0 + x)).sqrt(), x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f32::consts::TAU;

    /// Distance in ulps (of the `f32` nearest `exact`, at least that of `f32::MIN_POSITIVE`)
    /// between `a` and the `f64` value `exact`.
    fn ulps(a: f32, exact: f64) -> f64 {
        let ulp = f64::from(f32::EPSILON) * f64::from((exact as f32).abs()).max(f64::from(f32::MIN_POSITIVE));
        (f64::from(a) - exact).abs() / ulp
    }

    #[test]
    fn sin_cos_is_within_a_few_ulps_of_libm() {
        // A fine sweep of [−4π, 4π] (`slope_quadrature`'s last azimuth gap runs to just under
        // 4π) and the f32s nearest each zero kπ/2 with their neighbours, where the reduction's
        // rounding shows most (a two-part split had been 8·10⁷ ulps off at 3π/2, 1.2·10⁻⁷
        // absolute, within the absolute bound this test used to have).
        let sweep = (-400_000..=400_000).map(|i| i as f32 * (TAU / 100_000.0));
        let zeros = (-8..=8).flat_map(|k| {
            let nearest = (f64::from(k) * core::f64::consts::FRAC_PI_2) as f32;
            (-8..=8).map(move |step: i32| f32::from_bits(nearest.to_bits().wrapping_add_signed(step)))
        });
        let (mut worst, mut worst_above_milli) = (0.0f64, 0.0f64);
        for x in sweep.chain(zeros).filter(|x| x.abs() <= 2.0 * TAU) {
            let (s, c) = sin_cos(x);
            for (value, exact) in [(s, f64::from(x).sin()), (c, f64::from(x).cos())] {
                let error = ulps(value, exact);
                worst = worst.max(error);
                if exact.abs() >= 1.0e-3 {
                    worst_above_milli = worst_above_milli.max(error);
                }
            }
        }
        std::println!("sin_cos: worst {worst:.2} ulps, {worst_above_milli:.2} where |result| ≥ 10⁻³");
        assert!(worst_above_milli <= 2.0 && worst <= 10.0, "{worst_above_milli} {worst}");
        for x in [1.0e-30f32, 1.0e-6, 3.0e-3] {
            let (s, c) = sin_cos(x);
            assert!(
                ((s - x.sin()) / x).abs() <= 2.0 * f32::EPSILON && (c - x.cos()).abs() <= 2.0 * f32::EPSILON,
                "{x}"
            );
        }
    }

    #[test]
    fn atan2_is_within_three_ulps_everywhere() {
        // Every direction on a fine circle, at radii from 10⁻³⁰ to 10³⁰.
        let mut worst = 0.0f64;
        for i in 0..20_000 {
            let phi = f64::from(i) * (core::f64::consts::TAU / 20_000.0) - core::f64::consts::PI;
            for radius in [1.0e-30f64, 1.0e-3, 1.0, 7.5e2, 1.0e30] {
                let (x, y) = ((radius * phi.cos()) as f32, (radius * phi.sin()) as f32);
                let exact = f64::from(y).atan2(f64::from(x));
                worst = worst.max(ulps(atan2(y, x), exact));
            }
        }
        assert!(worst <= 3.0, "atan2 is {worst} ulps off");
    }

    #[test]
    fn atan2_keeps_relative_precision_for_tiny_angles() {
        for y in [1.0e-38f32, 1.0e-20, 1.0e-7, 3.0e-4] {
            for x in [1.0f32, 4.0, 1.0e5] {
                let exact = f64::from(y).atan2(f64::from(x));
                assert!(ulps(atan2(y, x), exact) <= 2.0, "atan2({y}, {x})");
                assert!(ulps(atan2(-y, x), -exact) <= 2.0, "atan2(-{y}, {x})");
            }
        }
    }

    #[test]
    fn atan2_follows_the_standard_librarys_special_values() {
        let specials = [0.0f32, -0.0, 1.0, -1.0, f32::INFINITY, f32::NEG_INFINITY, f32::MIN_POSITIVE, f32::MAX];
        for y in specials {
            for x in specials {
                let (ours, std) = (atan2(y, x), y.atan2(x));
                assert!(
                    ours.to_bits() == std.to_bits() || ulps(ours, f64::from(y).atan2(f64::from(x))) <= 2.0,
                    "atan2({y}, {x}) = {ours}, std {std}"
                );
            }
        }
        assert!(atan2(f32::NAN, 1.0).is_nan() && atan2(1.0, f32::NAN).is_nan());
    }

    #[test]
    fn atan_asin_acos_are_within_a_few_ulps() {
        for i in -10_000..=10_000 {
            let x = i as f32 / 10_000.0;
            assert!(ulps(asin(x), f64::from(x).asin()) <= 3.0, "asin({x}) = {}", asin(x));
            // acos(x) near x = 1 is ~√(2(1 − x)): judged relative to its own size there.
            assert!(ulps(acos(x), f64::from(x).acos()) <= 3.0, "acos({x}) = {}", acos(x));
            let t = x * 1.0e3;
            assert!(ulps(atan(t), f64::from(t).atan()) <= 3.0, "atan({t})");
        }
        for x in [1.0f32, -1.0, 1.0 - f32::EPSILON / 2.0, -1.0 + f32::EPSILON / 2.0] {
            assert!(ulps(asin(x), f64::from(x).asin()) <= 3.0 && ulps(acos(x), f64::from(x).acos()) <= 3.0);
        }
        assert!(asin(1.5).is_nan() && acos(-1.5).is_nan());
    }
}
