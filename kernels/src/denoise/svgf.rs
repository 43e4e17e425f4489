//! The variance-guided à-trous baseline (SVGF, Schied et al. 2017, spatial part; constants from
//! Falcor's SVGFPass, see `../shared/reference/sampling-denoise.md` §3.1), applied to the shadow
//! ratio with the same edge stops as the TV filter so the comparison isolates the noise guide.
//! A single frame has no temporal history, so the variance is estimated spatially (Falcor's
//! `SVGFFilterMoments` path for histories shorter than 4 frames): luminance moments over 7×7
//! bilateral taps, boosted by `4/h` with `h = 1`. Falcor's path also hands the à-trous
//! iterations the ratio averaged over those taps; this baseline keeps each measured pixel's own
//! ratio, which measured better here: the pre-blur, guided by no variance, raised its 1-spp relMSE
//! at 128² from 2.99·10⁻⁴ to 5.76·10⁻⁴ on the Cornell box (FLIP 0.0129 → 0.0181) and from
//! 1.66·10⁻³ to 1.87·10⁻³ on the two-light box — so the TV filter is measured against the
//! stronger variant.
//!
//! Pixels whose ratio is the fallback 1 — no sample reached the light, `U_N = 0` — hold no
//! measurement of their visibility: both passes skip them as taps and fill them from the taps
//! that were measured, as the TV filter does by adding their zero `S_N`, `U_N` to both sums.
//! Averaged in as a visibility of 1 they lifted an umbra in which a fraction q of the pixels drew
//! no light sample to about q (the BRDF-sampled share of samples that miss the light). A pixel
//! counts as measured when any channel of `U_N` reached the light; a channel that did not keeps
//! its fallback 1 in the average (TV would leave that channel out), which matters only for lights
//! with a zero channel beside other lights, where `U` in that channel is their light alone.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use super::guide::{edge_stop, Guide, SMALLEST_WEIGHT};
use crate::sampling::light_select::luminance;
use glam::{IVec2, Vec3, Vec4, Vec4Swizzles};
use raywave_shared::denoise::DenoiseParams;

/// Radius of the spatial moments window: 7×7 (Falcor SVGFFilterMoments).
const MOMENTS_RADIUS: i32 = 3;

/// Per-axis à-trous kernel weights at offsets 0, 1, 2: the 5-tap B3 spline {1, 2/3, 1/6}
/// (Falcor SVGFAtrous).
const ATROUS_KERNEL: [f32; 3] = [1.0, 2.0 / 3.0, 1.0 / 6.0];

/// Falcor's `1e-10` under the variance's square root.
const VARIANCE_EPSILON: f32 = 1.0e-10;

/// The w of an à-trous input pixel that has no estimate of its ratio: neither it nor any tap of
/// the moments window was measured (its rgb is the fallback 1). Variances are ≥ 0, so the sign
/// tells the two apart; the à-trous iterations fill such a pixel from their wider taps, and one
/// that none reaches keeps the fallback.
pub const NO_ESTIMATE: f32 = -1.0;

/// The smallest sum of weights that fills a centre without an estimate (the moments pass and
/// the à-trous iterations): 2⁻⁶³, whose square — the carried variance's divisor — is the smallest
/// normal `f32`. Below it the sums are made of products a GPU may flush as subnormal where the CPU
/// keeps them; the centre then keeps no estimate on every backend. (A centre with an estimate
/// weighs 1 itself.)
pub const SMALLEST_TOTAL: f32 = 1.0 / (1u64 << 63) as f32;

/// Whether a ratio-image entry ([`super::noise::ratio_pixel`]) was measured rather than the
/// fallback.
fn is_measured(entry: Vec4) -> bool {
    entry.w > 0.0
}

/// Whether an à-trous input entry (ratio and variance) holds an estimate: see [`NO_ESTIMATE`].
fn has_estimate(entry: Vec4) -> bool {
    entry.w >= 0.0
}

/// The G-buffer entry of pixel `i`.
fn guide_at(position: &[Vec4], normal: &[Vec4], i: usize) -> Guide {
    Guide { position: position[i], normal: normal[i] }
}

/// The à-trous input of `pixel` (Falcor's `SVGFFilterMoments` for a history shorter than 4
/// frames): its shadow ratio (rgb) and the spatial variance of the ratio's luminance (w) — the
/// moments over the 7×7 taps that were measured ([`super::noise::ratio_pixel`]'s w), weighted by
/// the edge stops and, from a measured centre, Falcor's luminance stop
/// `exp(−|l_t − l_c| / phiColor)` (`params.svgf.x`), `max(0, m₂ − m₁²)` times `params.svgf.y` (the
/// history boost). A measured pixel keeps its own ratio (Falcor's path would average it over the
/// taps; see the module docs); one that was not takes the taps' mean without the luminance stop,
/// or keeps the fallback with w = [`NO_ESTIMATE`] where their weights sum below
/// [`SMALLEST_TOTAL`]. Pixels without a surface keep their ratio and variance 0.
pub fn ratio_and_variance(
    params: &DenoiseParams,
    pixel: IVec2,
    ratio: &[Vec4],
    position: &[Vec4],
    normal: &[Vec4],
) -> Vec4 {
    let Some(c) = params.index_of(pixel) else { return Vec4::new(1.0, 1.0, 1.0, 0.0) };
    let center = guide_at(position, normal, c);
    if !center.is_surface() {
        return ratio[c].xyz().extend(0.0);
    }
    let center_measured = is_measured(ratio[c]);
    let l_center = luminance(ratio[c].xyz());
    let (mut mean, mut m1, mut m2, mut total) = (Vec3::ZERO, 0.0, 0.0, 0.0);
    let mut dy = -MOMENTS_RADIUS;
    while dy <= MOMENTS_RADIUS {
        let mut dx = -MOMENTS_RADIUS;
        while dx <= MOMENTS_RADIUS {
            if let Some(t) = params.index_of(pixel + IVec2::new(dx, dy)) {
                let l = luminance(ratio[t].xyz());
                let w = if !is_measured(ratio[t]) {
                    0.0
                } else if t == c {
                    1.0
                } else {
                    let luminance_stop =
                        if center_measured { (-(l - l_center).abs() / params.svgf.x).exp() } else { 1.0 };
                    luminance_stop * edge_stop(&center, &guide_at(position, normal, t), params.edge_weights)
                };
                if w >= SMALLEST_WEIGHT {
                    mean += w * ratio[t].xyz();
                    m1 += w * l;
                    m2 += w * l * l;
                    total += w;
                }
            }
            dx += 1;
        }
        dy += 1;
    }
    if total < SMALLEST_TOTAL {
        return ratio[c].xyz().extend(NO_ESTIMATE);
    }
    let (m1, m2) = (m1 / total, m2 / total);
    let variance = ((m2 - m1 * m1).max(0.0) * params.svgf.y).max(0.0);
    let value = if center_measured { ratio[c].xyz() } else { mean / total };
    value.extend(if variance.is_finite() { variance } else { 0.0 })
}

/// The variance at `pixel` prefiltered by a 3×3 Gaussian {1/4, 1/8, 1/16} (Falcor), renormalized
/// over the taps inside the image that hold an estimate (0 where none does).
fn prefiltered_variance(params: &DenoiseParams, pixel: IVec2, ratio: &[Vec4]) -> f32 {
    let (mut sum, mut total) = (0.0, 0.0);
    let mut dy = -1;
    while dy <= 1 {
        let mut dx = -1;
        while dx <= 1 {
            if let Some(t) = params.index_of(pixel + IVec2::new(dx, dy)) {
                if has_estimate(ratio[t]) {
                    let k = if dx == 0 && dy == 0 {
                        0.25
                    } else if dx == 0 || dy == 0 {
                        0.125
                    } else {
                        0.0625
                    };
                    sum += k * ratio[t].w;
                    total += k;
                }
            }
            dx += 1;
        }
        dy += 1;
    }
    if total > 0.0 {
        sum / total
    } else {
        0.0
    }
}

/// One à-trous iteration at `pixel` with tap spacing `params.step`: 5×5 taps weighted by the B3
/// kernel, the edge stops and the luminance stop `exp(−|Δl| / (phiColor·sqrt(var₃ₓ₃)))`; the
/// variance (w) is carried with squared weights (Falcor SVGFAtrous). Taps without an estimate
/// ([`NO_ESTIMATE`]) are skipped; a centre without one takes the other taps' mean without the
/// luminance stop (it has no luminance to compare), or stays without where their weights sum
/// below [`SMALLEST_TOTAL`]. Pixels without a surface pass through.
pub fn atrous_step(params: &DenoiseParams, pixel: IVec2, ratio: &[Vec4], position: &[Vec4], normal: &[Vec4]) -> Vec4 {
    let Some(c) = params.index_of(pixel) else { return Vec4::new(1.0, 1.0, 1.0, 0.0) };
    let center = guide_at(position, normal, c);
    if !center.is_surface() {
        return ratio[c];
    }
    let center_has_estimate = has_estimate(ratio[c]);
    // The luminance stop's centre and scale; unused for a centre without an estimate.
    let (l_center, phi) = if center_has_estimate {
        let variance = prefiltered_variance(params, pixel, ratio);
        (luminance(ratio[c].xyz()), params.svgf.x * (VARIANCE_EPSILON + variance).max(0.0).sqrt())
    } else {
        (0.0, 0.0)
    };
    let step = params.step.max(1) as i32;
    let (mut color, mut variance, mut total) = (Vec3::ZERO, 0.0, 0.0);
    let mut dy = -2;
    while dy <= 2 {
        let mut dx = -2;
        while dx <= 2 {
            if let Some(t) = params.index_of(pixel + IVec2::new(dx, dy) * step) {
                let kernel = ATROUS_KERNEL[dx.unsigned_abs() as usize] * ATROUS_KERNEL[dy.unsigned_abs() as usize];
                let w = if !has_estimate(ratio[t]) {
                    0.0
                } else if t == c {
                    1.0
                } else {
                    let luminance_stop = if center_has_estimate {
                        (-(luminance(ratio[t].xyz()) - l_center).abs() / phi).exp()
                    } else {
                        1.0
                    };
                    kernel * luminance_stop * edge_stop(&center, &guide_at(position, normal, t), params.edge_weights)
                };
                if w >= SMALLEST_WEIGHT {
                    color += w * ratio[t].xyz();
                    // A squared weight or carried variance below the smallest normal f32 (a
                    // weight under 2⁻⁶³, or a tiny variance) is subnormal, which a GPU may flush
                    // where the CPU keeps it: such a term counts as 0 on every backend.
                    let squared = w * w;
                    let carried = squared * ratio[t].w;
                    if squared >= SMALLEST_WEIGHT && carried >= SMALLEST_WEIGHT {
                        variance += carried;
                    }
                    total += w;
                }
            }
            dx += 1;
        }
        dy += 1;
    }
    if total < SMALLEST_TOTAL {
        return ratio[c];
    }
    let out = (color / total).extend(variance / (total * total));
    if out.is_finite() {
        out
    } else {
        ratio[c]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hash::CounterRng;
    use raywave_shared::denoise::{
        DEFAULT_SVGF_PHI_COLOR, MAX_RADIUS, MAX_SVGF_PHI_COLOR, MAX_SVGF_VARIANCE_BOOST, MIN_SVGF_PHI_COLOR,
    };
    use std::{vec, vec::Vec};

    struct Image {
        shadowed: Vec<Vec4>,
        unshadowed: Vec<Vec4>,
        position: Vec<Vec4>,
        normal: Vec<Vec4>,
        params: DenoiseParams,
    }

    fn plane(width: u32, height: u32, visibility: impl Fn(u32, u32) -> f32) -> Image {
        let u = Vec4::new(0.4, 0.5, 0.6, 0.0);
        let n = (width * height) as usize;
        Image {
            shadowed: (0..width * height).map(|i| u * visibility(i % width, i / width)).collect(),
            unshadowed: vec![u; n],
            position: (0..width * height)
                .map(|i| Vec3::new((i % width) as f32, 0.0, (i / width) as f32).extend(100.0))
                .collect(),
            normal: vec![Vec3::Y.extend(0.5); n],
            params: DenoiseParams { radius: MAX_RADIUS, ..DenoiseParams::new(width, height) },
        }
    }

    /// `img` with `S_N = U_N = 0` where `unmeasured` says: pixels none of whose samples reached
    /// the light, so that their ratio is the fallback 1.
    fn without_light_samples(mut img: Image, unmeasured: impl Fn(u32, u32) -> bool) -> Image {
        let width = img.params.width;
        for (i, (s, u)) in img.shadowed.iter_mut().zip(&mut img.unshadowed).enumerate() {
            if unmeasured(i as u32 % width, i as u32 / width) {
                (*s, *u) = (Vec4::ZERO, Vec4::ZERO);
            }
        }
        img
    }

    /// The pixel at row-major index `i` of `img`.
    fn pixel(img: &Image, i: u32) -> IVec2 {
        img.params.pixel(i).expect("a pixel of the image")
    }

    /// The ratio image of `img` (the denoisers' ratio pass).
    fn raw_ratio(img: &Image) -> Vec<Vec4> {
        img.shadowed.iter().zip(&img.unshadowed).map(|(&s, &u)| super::super::noise::ratio_pixel(s, u)).collect()
    }

    fn svgf(img: &Image) -> Vec<Vec4> {
        let p = &img.params;
        let pixels = |i: u32| pixel(img, i);
        let raw = raw_ratio(img);
        let mut ratio: Vec<Vec4> =
            (0..p.pixels()).map(|i| ratio_and_variance(p, pixels(i), &raw, &img.position, &img.normal)).collect();
        for k in 0..4 {
            let params = DenoiseParams { step: 1 << k, ..*p };
            ratio =
                (0..p.pixels()).map(|i| atrous_step(&params, pixels(i), &ratio, &img.position, &img.normal)).collect();
        }
        ratio
    }

    #[test]
    fn constant_ratio_has_no_variance_and_stays_put() {
        let img = plane(16, 16, |_, _| 0.25);
        for v in svgf(&img) {
            assert!((v.x - 0.25).abs() < 1e-6 && v.w.abs() < 1e-9, "{v}");
        }
    }

    #[test]
    fn pixels_that_drew_no_light_sample_take_their_measured_neighbours_ratio() {
        // A third of the pixels drew no sample that reached the light (hashed, so no pattern).
        let unmeasured = |x: u32, y: u32| crate::hash::pcg3d(glam::UVec3::new(x, y, 5)).x.is_multiple_of(3);
        for visibility in [0.0, 1.0] {
            let img = without_light_samples(plane(24, 24, |_, _| visibility), unmeasured);
            for (i, v) in svgf(&img).iter().enumerate() {
                // Averaged in as measured, the fallback lifted the umbra to about a third.
                assert_eq!(v.truncate(), Vec3::splat(visibility), "visibility {visibility}, pixel {i}");
                assert!(v.w >= 0.0, "pixel {i} has an estimate: {v}");
            }
        }
    }

    #[test]
    fn a_pixel_no_moments_tap_measured_is_filled_by_the_atrous_taps_or_keeps_the_fallback() {
        // One measured pixel, at visibility ¼; the moments window reaches 3 pixels from it, the
        // four à-trous iterations (spacing 1, 2, 4, 8) 30 more: every pixel of the image.
        let img = without_light_samples(plane(20, 20, |_, _| 0.25), |x, y| (x, y) != (2, 3));
        let raw = raw_ratio(&img);
        let moments = |i: u32| ratio_and_variance(&img.params, pixel(&img, i), &raw, &img.position, &img.normal);
        assert_eq!(moments(3 * 20 + 2 + 3).truncate(), Vec3::splat(0.25), "3 pixels away: filled");
        assert_eq!(moments(3 * 20 + 2 + 4), Vec4::new(1.0, 1.0, 1.0, NO_ESTIMATE), "4 pixels away: no estimate");
        for (i, v) in svgf(&img).iter().enumerate() {
            assert!((v.truncate() - Vec3::splat(0.25)).abs().max_element() < 1e-6 && v.w >= 0.0, "pixel {i}: {v}");
        }
        // With no measured pixel at all, every pixel keeps the fallback 1 (the composite's `U`).
        let img = without_light_samples(plane(20, 20, |_, _| 0.25), |_, _| true);
        for v in svgf(&img) {
            assert_eq!(v, Vec4::new(1.0, 1.0, 1.0, NO_ESTIMATE));
        }
    }

    /// The largest `t` in `[0, 1]` at which `stop(t)` is still positive (`stop(0) > 0`,
    /// `stop(1) = 0`): the edge stop's smallest positive value along `t`, about 2⁻²⁴.
    fn last_positive(stop: impl Fn(f32) -> f32) -> f32 {
        let (mut lo, mut hi) = (0.0f32, 1.0f32);
        for _ in 0..64 {
            let mid = 0.5 * (lo + hi);
            if stop(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }

    /// The vanishing-weight tests' 5 × 5 à-trous step: every edge weight 1, spacing 1.
    const VANISHING_PARAMS: DenoiseParams =
        DenoiseParams { step: 1, edge_weights: Vec4::ONE, ..DenoiseParams::new(5, 5) };

    /// Their centre: depth 1, facing +z, analytic luminance 1.
    const VANISHING_CENTER: Guide =
        Guide { position: Vec4::new(0.0, 0.0, 0.0, 1.0), normal: Vec4::new(0.0, 0.0, 1.0, 1.0) };

    /// A tap 0.1 beside [`VANISHING_CENTER`], `depth` quarters deeper, its normal tilted by
    /// `angle` and its analytic luminance `luminance` higher: each moves one edge stop to 0.
    fn vanishing_tap(depth: f32, angle: f32, luminance: f32) -> Guide {
        Guide {
            position: Vec4::new(0.1, 0.0, 0.0, 1.0 + 0.25 * depth),
            normal: Vec3::new(0.0, -angle.sin(), angle.cos()).extend(1.0 + luminance),
        }
    }

    /// The normal tilt and the luminance step at which the normal and the analytic edge stop of
    /// [`vanishing_tap`] are each at their smallest positive value (~6·10⁻⁸).
    fn smallest_normal_and_luminance_stops() -> (f32, f32) {
        let stop = |g: Guide| edge_stop(&VANISHING_CENTER, &g, VANISHING_PARAMS.edge_weights);
        let right_angle = core::f32::consts::FRAC_PI_2;
        let angle = right_angle * last_positive(|t| stop(vanishing_tap(0.0, t * right_angle, 0.0)));
        (angle, 0.2 * last_positive(|t| stop(vanishing_tap(0.0, 0.0, 0.2 * t))))
    }

    #[test]
    fn a_centre_filled_only_through_vanishing_weights_keeps_no_estimate() {
        // A 5 × 5 image: the centre has no estimate, its diagonal neighbour (B3 kernel 4/9) has
        // one, the others no surface. The tap's depth, normal and luminance each put an edge stop
        // at its smallest positive value (~6·10⁻⁸): with all three its weight, ~10⁻²², sums below
        // 2⁻⁶³ — its square is subnormal, which the CPU keeps and a GPU may flush — and the centre
        // keeps no estimate; with two, ~10⁻¹⁵, it is filled, with a finite variance.
        let (params, center) = (VANISHING_PARAMS, VANISHING_CENTER);
        let stop = |g: Guide| edge_stop(&center, &g, params.edge_weights);
        let depth = last_positive(|t| stop(vanishing_tap(t, 0.0, 0.0)));
        let (angle, luminance) = smallest_normal_and_luminance_stops();
        let tap = vanishing_tap;
        let run = |g: Guide| {
            let mut position = vec![Vec4::ZERO; 25];
            let mut normal = vec![Vec4::ZERO; 25];
            let mut ratio = vec![Vec4::new(1.0, 1.0, 1.0, NO_ESTIMATE); 25];
            (position[12], normal[12]) = (center.position, center.normal);
            (position[18], normal[18], ratio[18]) = (g.position, g.normal, Vec4::new(0.25, 0.25, 0.25, 0.01));
            (stop(g), atrous_step(&params, IVec2::new(2, 2), &ratio, &position, &normal))
        };
        let (weight, out) = run(tap(depth, angle, luminance));
        let kernel = ATROUS_KERNEL[1] * ATROUS_KERNEL[1];
        assert!(weight * kernel > 0.0 && weight * kernel < SMALLEST_TOTAL, "{weight:e}");
        assert!((weight * kernel) * (weight * kernel) > 0.0, "the CPU keeps the subnormal square");
        assert_eq!(out, Vec4::new(1.0, 1.0, 1.0, NO_ESTIMATE));
        let (weight, out) = run(tap(depth, 0.0, luminance));
        assert!(weight * kernel > SMALLEST_TOTAL, "{weight:e}");
        assert!(out.truncate() == Vec3::splat(0.25) && out.w.is_finite() && out.w >= 0.0, "{out}");
    }

    #[test]
    fn variances_carried_by_subnormal_squared_weights_count_as_zero() {
        // The centre of a 5 × 5 image has no estimate; its four edge neighbours (B3 kernel 2/3)
        // have one and weigh w each, 2⁻⁶⁵ ≤ w < 2⁻⁶³: together enough to fill the centre, while
        // each w² is subnormal — kept by the CPU, flushed by a GPU that flushes — so the carried
        // variance is 0 on every backend, not the 0.01/4 the kept squares would give.
        let (params, center) = (VANISHING_PARAMS, VANISHING_CENTER);
        let stop = |g: Guide| edge_stop(&center, &g, params.edge_weights);
        let (angle, luminance) = smallest_normal_and_luminance_stops();
        let tap = vanishing_tap;
        let kernel = ATROUS_KERNEL[1] * ATROUS_KERNEL[0];
        let target = 1.0 / (1u64 << 63) as f32 / 2.0;
        // The depth at which the tap's weight falls to 2⁻⁶⁴: the last that still reaches it.
        let depth = last_positive(|t| (stop(tap(t, angle, luminance)) * kernel - target).max(0.0));
        let g = tap(depth, angle, luminance);
        let w = stop(g) * kernel;
        assert!(w >= 0.5 * target && w < 2.0 * target && w * w < f32::MIN_POSITIVE, "{w:e}");
        assert!(4.0 * w >= SMALLEST_TOTAL, "{w:e}");
        let mut position = vec![Vec4::ZERO; 25];
        let mut normal = vec![Vec4::ZERO; 25];
        let mut ratio = vec![Vec4::new(1.0, 1.0, 1.0, NO_ESTIMATE); 25];
        (position[12], normal[12]) = (center.position, center.normal);
        for t in [7, 11, 13, 17] {
            (position[t], normal[t], ratio[t]) = (g.position, g.normal, Vec4::new(0.25, 0.25, 0.25, 0.01));
        }
        let out = atrous_step(&params, IVec2::new(2, 2), &ratio, &position, &normal);
        assert!((out.truncate() - Vec3::splat(0.25)).abs().max_element() < 1e-6, "filled: {out}");
        assert_eq!(out.w, 0.0, "no carried variance");
    }

    #[test]
    fn the_moments_weigh_taps_by_falcors_luminance_stop_and_a_measured_centre_keeps_its_ratio() {
        // A 7 × 7 plane lit only at its centre: the 48 other taps pass every edge stop (weight 1)
        // and Falcor's luminance stop weighs each exp(−|0 − 1| / 10); the centre's own weight is
        // 1. The luminance moments are then m₁ = m₂ = 1/(1 + 48w), the variance 4·m₁·(1 − m₁);
        // the centre's ratio stays its own 1.
        let img = plane(7, 7, |x, y| if (x, y) == (3, 3) { 1.0 } else { 0.0 });
        let raw = raw_ratio(&img);
        let out = ratio_and_variance(&img.params, IVec2::new(3, 3), &raw, &img.position, &img.normal);
        let w = (-1.0f32 / DEFAULT_SVGF_PHI_COLOR).exp();
        let m1 = 1.0 / (1.0 + 48.0 * w);
        let variance = 4.0 * m1 * (1.0 - m1);
        assert_eq!(out.truncate(), Vec3::ONE);
        assert!((out.w - variance).abs() < 1e-5, "{} vs {variance} (without the stop: 4·48/49²)", out.w);
    }

    #[test]
    fn one_atrous_step_carries_the_variance_with_squared_normalised_weights() {
        // The centre of a 5 × 5 plane at spacing 1: every tap is inside, on the plane (edge stops
        // 1) and at the same ratio (luminance stop e^0 = 1), so tap (dx, dy) weighs the B3
        // spline's h(dx)·h(dy), h = [1, 4, 6, 4, 1]/16, up to a common factor. The variances
        // differ per pixel (and are exact in f32), so the carried w must be Σ wᵢ²·vᵢ / (Σ wᵢ)²,
        // which no common factor of the weights changes (÷ Σ wᵢ alone would give (64/9)× that,
        // the kernel summing to (8/3)² with its centre at 1).
        let img = plane(5, 5, |_, _| 0.25);
        let variance = |x: i32, y: i32| f64::from(1 + x + 5 * y) / 64.0;
        let ratio: Vec<Vec4> = (0..25).map(|i| Vec3::splat(0.25).extend(variance(i % 5, i / 5) as f32)).collect();
        let h = [1.0, 4.0, 6.0, 4.0, 1.0].map(|k: f64| k / 16.0);
        let (mut carried, mut total) = (0.0, 0.0);
        for (y, hy) in h.iter().enumerate() {
            for (x, hx) in h.iter().enumerate() {
                let w = hx * hy;
                carried += w * w * variance(x as i32, y as i32);
                total += w;
            }
        }
        let expected = carried / (total * total);
        let params = DenoiseParams { step: 1, ..img.params };
        let out = atrous_step(&params, IVec2::new(2, 2), &ratio, &img.position, &img.normal);
        assert!((out.truncate() - Vec3::splat(0.25)).abs().max_element() < 1e-6, "{out}");
        let w = f64::from(out.w);
        assert!((w / expected - 1.0).abs() < 1e-6, "{w} vs {expected}");
    }

    /// Within the `phiColor` and variance boost the host accepts, the luminance stops divide by
    /// normal, finite scales: the moments pass by `phiColor` itself, the à-trous iterations by
    /// `phiColor·√(VARIANCE_EPSILON + var)` ≥ 10⁻¹¹, so a GPU flushing subnormals computes them
    /// as the CPU does (a `phiColor` below ~10⁻³³ had made the à-trous scale subnormal); with
    /// ratios up to `shadow_ratio`'s 10⁴ the variance, and the scale, stay finite.
    #[test]
    fn the_luminance_stops_scales_stay_normal_and_finite_within_the_accepted_limits() {
        let smallest = MIN_SVGF_PHI_COLOR * VARIANCE_EPSILON.sqrt();
        assert!(MIN_SVGF_PHI_COLOR.is_normal() && smallest.is_normal(), "{smallest}");
        assert!((1.0e4 / smallest).is_finite());
        let largest_variance = 1.0e4f32 * 1.0e4 * MAX_SVGF_VARIANCE_BOOST;
        let largest = MAX_SVGF_PHI_COLOR * (VARIANCE_EPSILON + largest_variance).sqrt();
        assert!(largest_variance.is_finite() && largest.is_normal(), "{largest}");
        assert!(!(1.0e-34f32 * VARIANCE_EPSILON.sqrt()).is_normal(), "below the limit: subnormal");
    }

    #[test]
    fn coin_flip_visibility_is_smoothed_towards_its_mean() {
        let mut rng = CounterRng::new(9);
        let flips: Vec<f32> = (0..32 * 32).map(|_| if rng.next_f32() < 0.5 { 1.0 } else { 0.0 }).collect();
        let img = plane(32, 32, |x, y| flips[(y * 32 + x) as usize]);
        let out = svgf(&img);
        let rms = |v: &[Vec4]| (v.iter().map(|r| (r.x - 0.5) * (r.x - 0.5)).sum::<f32>() / v.len() as f32).sqrt();
        let before: Vec<Vec4> = flips.iter().map(|&f| Vec4::splat(f)).collect();
        assert!(rms(&out) < 0.3 * rms(&before), "{} vs {}", rms(&out), rms(&before));
        assert!(out.iter().all(|v| v.is_finite()));
    }
}
