//! The form factor of a thin parallelogram light from its centre line: the strip's width enters
//! as a vector, never as the difference of two rounded corners.
//!
//! Why: [`super::polygon`]'s edge sum takes a light through its corners relative to the shading
//! point, each rounded at `ε·d` for a light `d` away. A strip of width `w ≪ d` has two long
//! edges whose terms nearly cancel, so the sum errs by about `ε·d/w` of itself: on random strips
//! a unit away, 10⁻² of the strip's head-on form factor at `w/d` = 10⁻⁴, 0.12 at 10⁻⁵ and 11×
//! at 10⁻⁷ (`tests::thin_lights_keep_their_precision`).
//!
//! [`strip_form_factor`] integrates the strip `{m + s·e + t·w : s ∈ [s₀, s₁], t ∈ [−½, ½]}` by
//! the midpoint rule across its width (relative error about `(|w|/h)²`, `h` the distance from
//! the shading point to the line) and in closed form along it;
//! [`thin_parallelogram_form_factor`] sums two such lines across a parallelogram's width. With `x(s) = m + s·e`, the plane's normal
//! `e × w` makes `(e × w)·x(s)` constant, and
//! `∫ max(0, cos θ)/π dω = |(e × w)·m|/π · ∫ x_z/|x|⁴ ds`. Parametrized by the angle `φ` from
//! the foot of the perpendicular (`h·tan φ` along the line; Heitz and Hill 2017, "Real-Time Line-
//! and Disk-Light Shading with Linearly Transformed Cosines", integrate lines this way), that is
//! `|w·ĉ|/(π h) · [f̂_z (φ/2 + sin 2φ/4) + ê_z sin²φ/2]` between the ends, `ĉ` the unit normal
//! of the plane through the line and the shading point, `f̂` the foot's direction, `ê` the
//! line's. The difference between the ends is formed from `tan φ₁ − tan φ₀ = (s₁ − s₀)|e|/h`
//! directly (sums and differences of the angles through their sines and cosines), so a short
//! strip — a tiny light — keeps its precision too.

use core::f32::consts::PI;
use glam::{Mat3, Vec3};
#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

/// A strip is thin — integrated by [`thin_parallelogram_form_factor`] rather than by its
/// corners — where its width is below this fraction of its centre line's distance from the
/// shading point. The two lines across the width (`WIDTH_NODES`) then err by about the fourth
/// power of that fraction, while the corners' sum errs by about `ε·d/w`. Chosen by measurement
/// (400 random strips per width from 10⁻¹ to 10⁻⁷ of their distance; the cosine and the LTCs of
/// roughness 0.05, 0.1 and 0.3; errors relative to the larger of the exact value and 1 % of the
/// strip's head-on form factor): with 3 % the combination errs by at most 2.7·10⁻³; with 1 %
/// by 3.5·10⁻², on strips the corners keep that are thin in the world but not in an LTC's
/// space; with 10 % by 1.1·10⁻², on strips lying along the horizon, which cuts them across
/// their width.
pub const THIN: f32 = 3.0e-2;

/// The parameter interval `[s₀, s₁]` ⊂ `[lo, hi]` of the line `m + s·e` where `z ≥ 0`, or `None`
/// where none of it is (a line in the plane `z = 0` counts as above).
#[inline]
pub fn above_horizon(m: Vec3, e: Vec3, lo: f32, hi: f32) -> Option<(f32, f32)> {
    let (mut s0, mut s1) = (lo, hi);
    if e.z > 0.0 {
        s0 = s0.max(-m.z / e.z);
    } else if e.z < 0.0 {
        s1 = s1.min(-m.z / e.z);
    } else if m.z < 0.0 {
        return None;
    }
    if s0 < s1 {
        Some((s0, s1))
    } else {
        None
    }
}

/// The distance from the origin to the line `m + s·e` over the width `|w|`: the strip is thin
/// (see [`THIN`]) where this is below it. Infinite for a line through the origin or of no
/// length, and NaN for non-finite input (neither counts as thin).
#[inline]
pub fn width_over_distance(m: Vec3, e: Vec3, w: Vec3) -> f32 {
    // h = |m × e|/|e|.
    w.length() * e.length() / m.cross(e).length()
}

/// `∫ max(0, cos θ)/π dω` (z the normal) over the strip of centre line `m + s·e`,
/// `s ∈ [s0, s1]`, and width vector `w`, the centre line already cut to `z ≥ 0`
/// ([`above_horizon`]); in `[0, 1]`, for either orientation. 0 for a line through the origin.
#[inline]
pub fn strip_form_factor(m: Vec3, e: Vec3, w: Vec3, s0: f32, s1: f32) -> f32 {
    let c = m.cross(e);
    let c_length = c.length();
    let e_length = e.length();
    if !(c_length > 0.0 && e_length > 0.0) {
        return 0.0;
    }
    let e_unit = e / e_length;
    let c_unit = c / c_length;
    // The foot of the perpendicular, as a direction: m − (m·ê)ê normalized.
    let foot = e_unit.cross(c_unit);
    // tan φ at each end, and their difference from the parameters' (exact where s0, s1 are).
    let along = m.dot(e);
    let e_squared = e_length * e_length;
    let tan_0 = (along + s0 * e_squared) / c_length;
    let tan_1 = (along + s1 * e_squared) / c_length;
    let tan_difference = (s1 - s0) * e_squared / c_length;
    let (sin_0, cos_0) = sin_cos_of_atan(tan_0);
    let (sin_1, cos_1) = sin_cos_of_atan(tan_1);
    let sin_difference = tan_difference * cos_0 * cos_1;
    let cos_difference = cos_0 * cos_1 + sin_0 * sin_1;
    let angle = crate::trig::atan2(sin_difference, cos_difference);
    let sin_sum = sin_0 * cos_1 + cos_0 * sin_1;
    let cos_sum = cos_0 * cos_1 - sin_0 * sin_1;
    let along_line = foot.z * (angle + sin_difference * cos_sum) + e_unit.z * sin_sum * sin_difference;
    // |w·ĉ|/h with h = |m × e|/|e|.
    let scale = w.dot(c_unit).abs() * e_length / c_length;
    let form_factor = scale * along_line / (2.0 * PI);
    if form_factor.is_finite() {
        form_factor.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Where the two lines across a strip's width lie (Gauss–Legendre, two nodes on `[0, 1]`, each
/// of weight ½): exact for integrands cubic across the width, so the rule errs by the width's
/// fourth power.
const WIDTH_NODES: [f32; 2] = [0.211_324_87, 0.788_675_1];

/// `∫ max(0, cos θ)/π dω` over the parallelogram `o + s·u + t·v` (`s`, `t` in `[0, 1]`;
/// shading-frame coordinates, z the normal) cut to the surface's horizon `z ≥ 0`, after the
/// linear map `map` (identity for the diffuse lobe, an LTC's `M⁻¹` for the specular one), where
/// that parallelogram is thin in `map`'s space (see [`THIN`]); `None` where it is not, or where
/// the input is not finite, for the corners' edge sum to integrate. The narrower way round is
/// the width; two lines across it (`WIDTH_NODES`), each cut to the surface's horizon and then
/// to `map`'s, are integrated by [`strip_form_factor`].
#[inline]
pub fn thin_parallelogram_form_factor(map: Mat3, o: Vec3, u: Vec3, v: Vec3) -> Option<f32> {
    let (mapped_o, mapped_u, mapped_v) = (map * o, map * u, map * v);
    let along_u = width_over_distance(mapped_o + 0.5 * mapped_v, mapped_u, mapped_v);
    let along_v = width_over_distance(mapped_o + 0.5 * mapped_u, mapped_v, mapped_u);
    let (line, width, mapped_line, mapped_width, ratio) =
        if along_u <= along_v { (u, v, mapped_u, mapped_v, along_u) } else { (v, u, mapped_v, mapped_u, along_v) };
    if ratio.is_nan() || ratio >= THIN {
        return None;
    }
    let mut sum = 0.0;
    let mut i = 0usize;
    while i < WIDTH_NODES.len() {
        let t = WIDTH_NODES[i];
        if let Some((s0, s1)) = above_horizon(o + t * width, line, 0.0, 1.0) {
            let mapped = mapped_o + t * mapped_width;
            if let Some((s0, s1)) = above_horizon(mapped, mapped_line, s0, s1) {
                sum += 0.5 * strip_form_factor(mapped, mapped_line, mapped_width, s0, s1);
            }
        }
        i += 1;
    }
    Some(sum.min(1.0))
}

/// `(sin, cos)` of `atan t`: `(t, 1)/√(1 + t²)`, and `(±1, 0)` for `|t|` past the range where
/// `t²` is finite.
#[inline]
fn sin_cos_of_atan(t: f32) -> (f32, f32) {
    let squared = t * t;
    if squared.is_finite() {
        let cos = 1.0 / (1.0 + squared).sqrt();
        (t * cos, cos)
    } else {
        (t.signum(), 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hash::{pcg3d, unit_float};
    use crate::shade::ltc::{lobe_form_factors, local_quad, lookup, parallelogram_form_factors, ShadingFrame};
    use glam::{DMat3, DVec3, UVec3, Vec4};
    use raywave_shared::ltc_table::packed_entries;
    use std::vec::Vec;

    /// Sutherland–Hodgman against `z ≥ 0` in `f64`.
    fn clip64(polygon: &[DVec3]) -> Vec<DVec3> {
        let mut out = Vec::new();
        for i in 0..polygon.len() {
            let (a, b) = (polygon[i], polygon[(i + 1) % polygon.len()]);
            if a.z >= 0.0 {
                out.push(a);
            }
            if (a.z >= 0.0) != (b.z >= 0.0) {
                let t = a.z / (a.z - b.z);
                out.push(DVec3 { z: 0.0, ..a + t * (b - a) });
            }
        }
        if out.len() < 3 {
            out.clear();
        }
        out
    }

    /// The reference: the parallelogram `o + s·u + t·v` (the `f32` inputs, exactly) cut to the
    /// horizon, mapped by `map`, and integrated by the corners' edge sum, all in `f64` (whose
    /// rounding, `10⁻¹⁶·d/w`, is 10⁻⁹ at the thinnest strip here).
    fn reference(map: Mat3, o: Vec3, u: Vec3, v: Vec3) -> f64 {
        let (o, u, v) = (o.as_dvec3(), u.as_dvec3(), v.as_dvec3());
        let map: DMat3 = map.as_dmat3();
        let mapped: Vec<DVec3> = clip64(&[o, o + u, o + u + v, o + v]).into_iter().map(|x| map * x).collect();
        let clipped = clip64(&mapped);
        let mut sum = 0.0;
        for i in 0..clipped.len() {
            let a = clipped[i].normalize();
            let b = clipped[(i + 1) % clipped.len()].normalize();
            let c = a.cross(b);
            if c.length() > 0.0 {
                sum += c.length().atan2(a.dot(b)) * c.z / c.length();
            }
        }
        (sum / (2.0 * core::f64::consts::PI)).abs()
    }

    fn random_unit(seed: u32, k: u32) -> Vec3 {
        let h = pcg3d(UVec3::new(seed, k, 77));
        let z = 2.0 * unit_float(h.x) - 1.0;
        let phi = 2.0 * PI * unit_float(h.y);
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    /// Random strips `(o, u, v)` in the shading frame, `|v|` = `ratio` and `|u|` in 0.5…1.5, about
    /// a unit from the shading point, many crossing the horizon; with a random view cosine.
    fn strips(ratio: f32) -> impl Iterator<Item = (Vec3, Vec3, Vec3, f32)> {
        (0..400u32).map(move |seed| {
            let o = random_unit(seed, 0) + Vec3::new(0.0, 0.0, 0.6);
            let u = random_unit(seed, 1) * (0.5 + unit_float(pcg3d(UVec3::new(seed, 9, 9)).x));
            let v = u.cross(random_unit(seed, 2)).normalize() * ratio;
            (o, u, v, 0.2 + 0.8 * unit_float(pcg3d(UVec3::new(seed, 3, 3)).x))
        })
    }

    /// An error's size against the strip's head-on form factor `|u|·|v|/(π|o|²)` in the lobe's
    /// space (a relative error would judge the 10⁻¹⁰ slivers left above a horizon), or against
    /// the value itself where that is larger.
    fn scale(map: Mat3, o: Vec3, u: Vec3, v: Vec3, reference: f64) -> f64 {
        let head_on =
            ((map * u).length() * (map * v).length() / (map * o).length_squared()) as f64 / core::f64::consts::PI;
        reference.max(head_on)
    }

    /// The lobes the tests integrate: the clamped cosine, and the table's first LTC at three
    /// roughnesses (0.05 below the table's reliable range: the sharpest `M⁻¹`).
    fn maps(table: &[Vec4], cos_view: f32) -> [Mat3; 4] {
        [
            Mat3::IDENTITY,
            lookup(table, 0.05, cos_view).inv_m,
            lookup(table, 0.1, cos_view).inv_m,
            lookup(table, 0.3, cos_view).inv_m,
        ]
    }

    /// Wherever the strip path takes a strip, it matches the `f64` edge sum of the exact
    /// parallelogram within 10⁻³ of the strip's head-on form factor (measured at most 10⁻⁵),
    /// over 400 random strips per width from 10⁻² to 10⁻⁷ of their distance and four lobes; it
    /// takes every one at 10⁻⁵ and below. Halving the width's weight fails it.
    #[test]
    fn thin_strips_match_the_f64_edge_sum() {
        let table: Vec<Vec4> = packed_entries().map(Vec4::from_array).collect();
        for ratio in [1e-2f32, 1e-3, 1e-4, 1e-5, 1e-7] {
            let (mut taken, mut total, mut worst) = (0, 0, 0.0f64);
            for (o, u, v, cos_view) in strips(ratio) {
                for map in maps(&table, cos_view) {
                    let exact = reference(map, o, u, v);
                    total += 1;
                    if let Some(strip) = thin_parallelogram_form_factor(map, o, u, v) {
                        taken += 1;
                        let error = (strip as f64 - exact).abs() / scale(map, o, u, v, exact);
                        worst = worst.max(error);
                        assert!(error <= 1e-3, "w/d {ratio}: {strip} vs {exact} (o {o}, u {u}, v {v}, map {map})");
                    }
                }
            }
            std::println!("w/d {ratio:.0e}: {taken} of {total} strips thin, worst error {worst:.1e}");
            assert!(ratio > 1e-5 || taken == total, "w/d {ratio}: {taken} of {total} taken");
            assert!(taken > 0, "w/d {ratio}: none taken");
        }
    }

    /// Through the stage's entry (`parallelogram_form_factors`), thin lights keep `U_D` and
    /// `U_S` within 10⁻⁴ of their head-on form factor (measured: 3·10⁻⁵) down to widths of
    /// 10⁻⁷ of their distance, where the corners' edge sum alone (`lobe_form_factors`) erred by
    /// 10⁻² at 10⁻⁴, 0.12 at 10⁻⁵ and a factor 11 at 10⁻⁷. The midpoint of the width alone
    /// fails it (at 10⁻⁴, roughness 0.1).
    #[test]
    fn thin_lights_keep_their_precision() {
        let table: Vec<Vec4> = packed_entries().map(Vec4::from_array).collect();
        let frame = ShadingFrame { tangent: Vec3::X, bitangent: Vec3::Y, normal: Vec3::Z };
        for ratio in [1e-4f32, 1e-5, 1e-7] {
            let (mut worst, mut worst_corners) = (0.0f64, 0.0f64);
            for (o, u, v, cos_view) in strips(ratio) {
                for roughness in [0.05, 0.1, 0.3] {
                    let lobe = lookup(&table, roughness, cos_view);
                    let (diffuse, specular) = parallelogram_form_factors(&lobe, None, &frame, Vec3::ZERO, o, u, v);
                    let (corners_diffuse, corners_specular) =
                        lobe_form_factors(&lobe, None, local_quad(&frame, Vec3::ZERO, o, u, v));
                    let exact_diffuse = reference(Mat3::IDENTITY, o, u, v);
                    let (first, second) = (reference(lobe.inv_m, o, u, v), reference(lobe.inv_m_2, o, u, v));
                    let weight = lobe.weight as f64;
                    let exact_specular = weight * first + (1.0 - weight) * second;
                    let specular_scale = scale(lobe.inv_m, o, u, v, first).min(scale(lobe.inv_m_2, o, u, v, second));
                    let diffuse_scale = scale(Mat3::IDENTITY, o, u, v, exact_diffuse);
                    let errors = [
                        (diffuse as f64 - exact_diffuse).abs() / diffuse_scale,
                        (specular as f64 - exact_specular).abs() / specular_scale,
                    ];
                    let corner_errors = [
                        (corners_diffuse as f64 - exact_diffuse).abs() / diffuse_scale,
                        (corners_specular as f64 - exact_specular).abs() / specular_scale,
                    ];
                    worst = worst.max(errors[0]).max(errors[1]);
                    worst_corners = worst_corners.max(corner_errors[0]).max(corner_errors[1]);
                    assert!(
                        errors[0] <= 1e-4 && errors[1] <= 1e-4,
                        "w/d {ratio} roughness {roughness}: ({diffuse}, {specular}) vs ({exact_diffuse}, {exact_specular})"
                    );
                }
            }
            std::println!("w/d {ratio:.0e}: worst error {worst:.1e}, by the corners alone {worst_corners:.1e}");
            assert!(worst_corners > 100.0 * worst, "the corners' path is about as good here: the test shows nothing");
        }
    }

    /// Strips seen end-on, lying in the horizon, crossing it, of no width or length, or not
    /// finite: in `[0, 1]` (or left to the corners' path), never NaN.
    #[test]
    fn hard_strips_stay_finite() {
        let w = 1e-6;
        let cases = [
            // End-on: the line runs through the shading point.
            (Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.0, 0.0, 1.0), Vec3::new(w, 0.0, 0.0)),
            // In the horizon plane, and crossing it steeply and at a shallow angle.
            (Vec3::new(-0.5, 1.0, 0.0), Vec3::X, Vec3::new(0.0, w, 0.0)),
            (Vec3::new(0.3, 0.2, -0.5), Vec3::Z, Vec3::new(w, 0.0, 0.0)),
            (Vec3::new(-1.0, 0.5, -1e-3), Vec3::new(2.0, 0.0, 2e-3), Vec3::new(0.0, w, 0.0)),
            // Entirely below the horizon.
            (Vec3::new(-0.5, 0.5, -1.0), Vec3::X, Vec3::new(0.0, w, 0.0)),
            // No width, no length, far and huge.
            (Vec3::new(-0.5, 0.5, 1.0), Vec3::X, Vec3::ZERO),
            (Vec3::new(-0.5, 0.5, 1.0), Vec3::ZERO, Vec3::new(0.0, w, 0.0)),
            (Vec3::new(-1e30, 0.5, 1e20), Vec3::new(2e30, 0.0, 0.0), Vec3::new(0.0, 1e10, 0.0)),
            (Vec3::new(-1e-30, 0.5e-30, 1e-30), Vec3::new(2e-30, 0.0, 0.0), Vec3::new(0.0, 1e-37, 0.0)),
            // Not finite.
            (Vec3::new(f32::NAN, 0.5, 1.0), Vec3::X, Vec3::new(0.0, w, 0.0)),
            (Vec3::new(-0.5, 0.5, 1.0), Vec3::new(f32::INFINITY, 0.0, 0.0), Vec3::new(0.0, w, 0.0)),
        ];
        for (k, (o, u, v)) in cases.into_iter().enumerate() {
            for map in
                [Mat3::IDENTITY, Mat3::from_cols(Vec3::new(400.0, 0.0, -0.3), Vec3::new(0.0, 400.0, 0.0), Vec3::Z)]
            {
                if let Some(value) = thin_parallelogram_form_factor(map, o, u, v) {
                    assert!((0.0..=1.0).contains(&value), "case {k}: {value}");
                }
            }
        }
        // The horizon cases integrate what lies above it: nothing for the strip in and below it.
        for k in [1, 4] {
            let (o, u, v) = cases[k];
            assert_eq!(thin_parallelogram_form_factor(Mat3::IDENTITY, o, u, v), Some(0.0), "case {k}");
        }
    }
}
