//! The noise estimate that steers the filter radius (seed 000; the reference code's
//! `estimateNoise` as quoted by its public ports [H-PF, H-EST, H-CPU], see
//! `../shared/reference/ddgi-ratio-ltc.md` §2.1): the total variation — summed second-difference
//! magnitudes — of the shadow ratio `S_N/U_N` along randomly rotated lines through the pixel,
//! the maximum over the lines, normalized; then a 3×3 box blur. (The talk says the lines'
//! results are averaged; the reference code as its ports quote it takes the maximum, as here.)

use crate::hash::{pcg3d, unit_float};
use crate::shade::stage::{shadow_ratio, SMALLEST_RADIANCE};
use crate::trig;
use core::f32::consts::FRAC_PI_4;
use glam::{IVec2, UVec3, Vec2, Vec3, Vec4, Vec4Swizzles};
use raywave_shared::denoise::{DenoiseParams, MAX_RADIUS, NOISE_LINES};

/// Clamps `p` into the image and returns its pixel index.
fn clamped_index(p: IVec2, width: u32, height: u32) -> usize {
    let x = p.x.clamp(0, width as i32 - 1);
    let y = p.y.clamp(0, height as i32 - 1);
    (y as u32 * width + x as u32) as usize
}

/// The ratio image's entry for one pixel: its shadow ratio `S_N/U_N` (rgb; 1 where `U_N ≈ 0`),
/// computed once per pixel by the ratio pass so the noise estimate's many taps only load it; w is
/// 1 where the ratio was measured — some channel of `U_N` reached the light — and 0 where the
/// rgb is that fallback (no sample reached the light), which the SVGF baseline must not average
/// in as a visibility of 1 (`svgf::ratio_and_variance`).
pub fn ratio_pixel(shadowed: Vec4, unshadowed: Vec4) -> Vec4 {
    let measured = unshadowed.xyz().cmpge(Vec3::splat(SMALLEST_RADIANCE)).any();
    shadow_ratio(shadowed.xyz(), unshadowed.xyz()).extend(if measured { 1.0 } else { 0.0 })
}

/// Added to a tap's offset (within ±[`MAX_RADIUS`]) before truncation and taken off after, so
/// that the truncated sum is positive and `as i32` rounds the offset to nearest without the
/// software `round` of `no_std`.
const ROUNDING_SHIFT: i32 = 16;
const _: () = assert!(MAX_RADIUS < ROUNDING_SHIFT as u32);

/// The pixel nearest to `pixel + offset` (`offset` within ±[`MAX_RADIUS`]). The offset is
/// rounded on its own, in pixels, and added to the integer pixel: rounding the sum in `f32` moved
/// the taps of pixels beyond 2²⁴ to even pixels, a staircase of repeated values.
#[inline(always)]
fn nearest_pixel(pixel: IVec2, offset: Vec2) -> IVec2 {
    let shift = ROUNDING_SHIFT as f32 + 0.5;
    pixel + IVec2::new((offset.x + shift) as i32, (offset.y + shift) as i32) - IVec2::splat(ROUNDING_SHIFT)
}

/// The ratio at the pixel nearest to `pixel + offset` ([`nearest_pixel`]), clamped into the image.
/// Always inlined, as is [`line_taps`]: left to itself the CPU build called it for every tap and
/// returned the `Vec3` through memory; inlined, the 1080p noise pass takes 0.7× the time (CPU,
/// 2 threads, alternating runs: 706 → 500 ms), with the same results.
#[inline(always)]
fn line_tap(pixel: IVec2, offset: Vec2, width: u32, height: u32, ratio: &[Vec4]) -> Vec3 {
    ratio[clamped_index(nearest_pixel(pixel, offset), width, height)].xyz()
}

/// The lines run in the four lanes of a `Vec4`.
const _: () = assert!(NOISE_LINES == 4);

/// `d` rotated by π/4: each noise line is the previous one rotated so.
fn rotate_quarter_pi(d: Vec2) -> Vec2 {
    let (sin, cos) = (core::f32::consts::FRAC_1_SQRT_2, core::f32::consts::FRAC_1_SQRT_2);
    Vec2::new(d.x * cos - d.y * sin, d.x * sin + d.y * cos)
}

/// One tap of each of the four noise lines, channel by channel: lane `k` is line `k`'s.
#[derive(Copy, Clone)]
struct LineTaps {
    red: Vec4,
    green: Vec4,
    blue: Vec4,
}

/// The taps `r` steps along the four lines through `center` with direction components `dx`,
/// `dy` (lane `k` = line `k`): the ratio at the pixel nearest to `center + r·direction_k`.
#[inline(always)]
fn line_taps(center: IVec2, dx: Vec4, dy: Vec4, r: f32, width: u32, height: u32, ratio: &[Vec4]) -> LineTaps {
    let (xs, ys) = (dx * r, dy * r);
    let t0 = line_tap(center, Vec2::new(xs.x, ys.x), width, height, ratio);
    let t1 = line_tap(center, Vec2::new(xs.y, ys.y), width, height, ratio);
    let t2 = line_tap(center, Vec2::new(xs.z, ys.z), width, height, ratio);
    let t3 = line_tap(center, Vec2::new(xs.w, ys.w), width, height, ratio);
    LineTaps {
        red: Vec4::new(t0.x, t1.x, t2.x, t3.x),
        green: Vec4::new(t0.y, t1.y, t2.y, t3.y),
        blue: Vec4::new(t0.z, t1.z, t2.z, t3.z),
    }
}

/// The raw noise estimate of pixel `pixel` from the ratio image `ratio` ([`ratio_pixel`] per
/// pixel), in `[0, 1]`: along [`NOISE_LINES`] lines at angles
/// `angle0 + k·π/4` (`angle0` hashed from the pixel and `params.seed`), the ratio is tapped at
/// the nearest pixel to each offset `r ∈ [−R_e, R_e]`, `R_e = min(10, R)` (taps past the border
/// clamp to it); `d2 = Σ |v[r−2] − 2·v[r−1] + v[r]|` (RGB length), and the estimate is
/// `clamp(sqrt(d2/R)/1.5, 0, 1)`, the maximum over the lines [H-CPU, H-EST]. The four lines run
/// side by side in the lanes of `Vec4`s (one square root for four taps), each with the
/// operations, in the order, of a line on its own.
pub fn noise_estimate(params: &DenoiseParams, pixel: IVec2, ratio: &[Vec4]) -> f32 {
    let radius = params.radius.clamp(1, MAX_RADIUS) as i32;
    let (width, height) = (params.width.max(1), params.height.max(1));
    let bits = pcg3d(UVec3::new(pixel.x as u32, pixel.y as u32, params.seed)).x;
    let (sin0, cos0) = trig::sin_cos(unit_float(bits) * FRAC_PI_4);
    let d0 = Vec2::new(cos0, sin0);
    let d1 = rotate_quarter_pi(d0);
    let d2 = rotate_quarter_pi(d1);
    let d3 = rotate_quarter_pi(d2);
    let (dx, dy) = (Vec4::new(d0.x, d1.x, d2.x, d3.x), Vec4::new(d0.y, d1.y, d2.y, d3.y));
    let center = pixel;
    let mut before = line_taps(center, dx, dy, -radius as f32, width, height, ratio);
    let mut previous = line_taps(center, dx, dy, (1 - radius) as f32, width, height, ratio);
    let mut variation = Vec4::ZERO;
    let mut r = 2 - radius;
    while r <= radius {
        let v = line_taps(center, dx, dy, r as f32, width, height, ratio);
        let red = before.red - 2.0 * previous.red + v.red;
        let green = before.green - 2.0 * previous.green + v.green;
        let blue = before.blue - 2.0 * previous.blue + v.blue;
        variation += (red * red + green * green + blue * blue).sqrt();
        before = previous;
        previous = v;
        r += 1;
    }
    // A ratio that is not finite (only a caller's own ratio image holds one: `ratio_pixel`'s
    // are in [0, 10⁴]) counts as the loudest noise, decided before the clamp, whose `max` and
    // `min` pass NaN on in some lanes and drop it in others, by platform.
    if !variation.element_sum().is_finite() {
        return 1.0;
    }
    let per_line = ((variation / radius as f32).sqrt() / 1.5).clamp(Vec4::ZERO, Vec4::ONE);
    per_line.max_element()
}

/// The noise blur: the mean of the raw estimates in the 3×3 box around `pixel` that lies inside
/// the image [H-CPU, H-UNITY].
pub fn blurred_noise(params: &DenoiseParams, pixel: IVec2, raw: &[f32]) -> f32 {
    let (mut sum, mut count) = (0.0, 0.0);
    let mut dy = -1;
    while dy <= 1 {
        let mut dx = -1;
        while dx <= 1 {
            if let Some(i) = params.index_of(pixel + IVec2::new(dx, dy)) {
                sum += raw[i];
                count += 1.0;
            }
            dx += 1;
        }
        dy += 1;
    }
    if count > 0.0 {
        sum / count
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hash::CounterRng;
    use std::{vec, vec::Vec};

    fn image(width: u32, height: u32, visibility: impl Fn(u32, u32) -> f32) -> Vec<Vec4> {
        let unshadowed = Vec4::new(0.5, 0.4, 0.3, 0.0);
        (0..width * height).map(|i| ratio_pixel(unshadowed * visibility(i % width, i / width), unshadowed)).collect()
    }

    #[test]
    fn smooth_ratios_are_quiet_and_binary_noise_is_loud() {
        let params = DenoiseParams { radius: MAX_RADIUS, ..DenoiseParams::new(48, 32) };
        let r = image(48, 32, |_, _| 0.3);
        assert_eq!(noise_estimate(&params, IVec2::new(24, 16), &r), 0.0, "a constant ratio");
        // Along rotated lines the nearest-pixel taps of a ramp step unevenly, so it is not 0.
        let r = image(48, 32, |x, _| x as f32 / 47.0);
        let ramp = noise_estimate(&params, IVec2::new(24, 16), &r);
        assert!(ramp < 0.2, "a smooth ramp is quiet: {ramp}");
        let r = image(48, 32, |x, _| if x < 24 { 1.0 } else { 0.0 });
        let edge = noise_estimate(&params, IVec2::new(24, 16), &r);
        let mut rng = CounterRng::new(3);
        let values: Vec<f32> = (0..48 * 32).map(|_| if rng.next_f32() < 0.5 { 1.0 } else { 0.0 }).collect();
        let r = image(48, 32, |x, y| values[(y * 48 + x) as usize]);
        let noisy = noise_estimate(&params, IVec2::new(24, 16), &r);
        assert_eq!(noisy, 1.0, "coin-flip visibility saturates the estimate");
        assert!(edge < noisy, "a clean shadow edge ({edge}) is less noisy than coin flips");
    }

    /// The estimate's scale, pinned on a lone grey spike of height `h` in a ratio image of 0,
    /// at least `R` pixels from the border: every tap of a line at `|r| ≥ 1` lies at least one
    /// pixel out, so it rounds to another pixel whatever the line's angle, and each line sees
    /// the spike only at `r = 0`. The three second differences over it sum to `(1 + 2 + 1)·h·√3`
    /// (the RGB length of a grey step), so the estimate is `clamp(sqrt(4√3·h/R)/1.5, 0, 1)`
    /// at any angle (seed); at `R` = 1 only the difference centred on the spike counts, `2√3·h`.
    /// The other tests pass for any scale and divisor that keep a constant at 0 and coin flips
    /// at 1.
    #[test]
    fn a_lone_spike_gives_the_estimate_of_its_second_differences() {
        let (width, height) = (24, 24);
        let center = IVec2::new(12, 12);
        for height_of_spike in [0.02f32, 0.1, 0.5, 2.0] {
            let r = image(width, height, |x, y| if (x, y) == (12, 12) { height_of_spike } else { 0.0 });
            for (radius, sum) in [(1, 2.0), (2, 4.0), (5, 4.0), (MAX_RADIUS, 4.0)] {
                let expected = ((sum * 3f32.sqrt() * height_of_spike / radius as f32).sqrt() / 1.5).min(1.0);
                for seed in [0, 1, 7, 1234] {
                    let params = DenoiseParams { radius, seed, ..DenoiseParams::new(width, height) };
                    let estimate = noise_estimate(&params, center, &r);
                    assert!(
                        (estimate - expected).abs() < 1e-5,
                        "h {height_of_spike}, R {radius}, seed {seed}: {estimate} vs {expected}"
                    );
                }
            }
        }
    }

    /// The estimate one line at a time, in plain scalar code: what the four-lane version must
    /// reproduce bit for bit.
    fn noise_one_line_at_a_time(params: &DenoiseParams, pixel: IVec2, ratio: &[Vec4]) -> f32 {
        let radius = params.radius.clamp(1, MAX_RADIUS) as i32;
        let bits = pcg3d(UVec3::new(pixel.x as u32, pixel.y as u32, params.seed)).x;
        let (sin0, cos0) = trig::sin_cos(unit_float(bits) * FRAC_PI_4);
        let mut direction = Vec2::new(cos0, sin0);
        let mut estimate: f32 = 0.0;
        for _ in 0..NOISE_LINES {
            let tap = |r: i32| line_tap(pixel, direction * r as f32, params.width, params.height, ratio);
            let mut variation = 0.0;
            for r in 2 - radius..=radius {
                variation += (tap(r - 2) - 2.0 * tap(r - 1) + tap(r)).length();
            }
            estimate = estimate.max(((variation / radius as f32).sqrt() / 1.5).clamp(0.0, 1.0));
            direction = rotate_quarter_pi(direction);
        }
        estimate
    }

    #[test]
    fn four_lanes_match_one_line_at_a_time_exactly() {
        let mut rng = CounterRng::new(17);
        let values: Vec<f32> = (0..37 * 23).map(|_| rng.next_f32()).collect();
        let r = image(37, 23, |x, y| values[(y * 37 + x) as usize]);
        for radius in [1, 2, 5, MAX_RADIUS] {
            let params = DenoiseParams { radius, seed: radius * 3, ..DenoiseParams::new(37, 23) };
            for y in 0..23 {
                for x in 0..37 {
                    let p = IVec2::new(x, y);
                    assert_eq!(
                        noise_estimate(&params, p, &r),
                        noise_one_line_at_a_time(&params, p, &r),
                        "{p} R {radius}"
                    );
                }
            }
        }
    }

    /// A radius outside 1…[`MAX_RADIUS`] is clamped into it, as documented: the host refuses
    /// such radii (`check_radius`), but the kernel takes what the parameters hold. Radius 0 had
    /// divided the variation by 0, and the NaN estimate read as a quiet 0 on coin-flip noise.
    #[test]
    fn radii_outside_the_range_are_clamped_into_it() {
        let mut rng = CounterRng::new(41);
        let values: Vec<f32> = (0..24 * 16).map(|_| if rng.next_f32() < 0.5 { 1.0 } else { 0.0 }).collect();
        let r = image(24, 16, |x, y| values[(y * 24 + x) as usize]);
        let with = |radius| DenoiseParams { radius, ..DenoiseParams::new(24, 16) };
        for p in [IVec2::new(12, 8), IVec2::new(0, 0), IVec2::new(23, 5)] {
            let smallest = noise_estimate(&with(1), p, &r);
            assert!(smallest > 0.0, "{p}: coin flips are noisy at R = 1");
            assert_eq!(noise_estimate(&with(0), p, &r), smallest, "{p}: R = 0");
            let largest = noise_estimate(&with(MAX_RADIUS), p, &r);
            for radius in [MAX_RADIUS + 1, u32::MAX] {
                assert_eq!(noise_estimate(&with(radius), p, &r), largest, "{p}: R = {radius}");
            }
        }
    }

    #[test]
    fn undefined_ratios_count_as_unshadowed_and_stay_finite() {
        let params = DenoiseParams { radius: MAX_RADIUS, ..DenoiseParams::new(16, 16) };
        let zero: Vec<Vec4> = (0..256).map(|_| ratio_pixel(Vec4::ZERO, Vec4::ZERO)).collect();
        assert_eq!(noise_estimate(&params, IVec2::new(8, 8), &zero), 0.0);
        for (shadowed, unshadowed) in [(f32::NAN, f32::NAN), (f32::NAN, 1.0), (1.0, f32::NAN)] {
            let r = ratio_pixel(Vec4::splat(shadowed), Vec4::splat(unshadowed));
            assert_eq!(r.truncate(), Vec3::ONE, "an undefined ratio is 1: {shadowed} / {unshadowed}");
        }
        // A subnormal S_N beside a normal U_N is 0, as on a device that flushes it.
        let flushed = ratio_pixel(Vec4::splat(0.9 * SMALLEST_RADIANCE), Vec4::splat(SMALLEST_RADIANCE));
        assert_eq!(flushed, Vec4::new(0.0, 0.0, 0.0, 1.0));
        for bad in [f32::NAN, f32::INFINITY] {
            assert_eq!(noise_estimate(&params, IVec2::new(0, 0), &vec![Vec4::splat(bad); 256]), 1.0, "{bad}: loudest");
        }
        let single = DenoiseParams { radius: MAX_RADIUS, ..DenoiseParams::new(1, 1) };
        assert_eq!(noise_estimate(&single, IVec2::ZERO, &zero[..1]), 0.0);
    }

    /// Pixels beyond 2²⁴ (which `f32` cannot hold one by one) tap the same neighbours, relative to
    /// themselves, as pixels near the origin. Rounded as `pixel + offset` in `f32`, pixel 2²⁴ + 1
    /// tapped even pixels only, never itself.
    #[test]
    fn taps_are_exact_beyond_two_to_the_24_pixels() {
        let mut rng = CounterRng::new(29);
        for _ in 0..2000 {
            let (sin, cos) = trig::sin_cos(rng.next_f32() * FRAC_PI_4 * 8.0);
            let offset = Vec2::new(cos, sin) * ((rng.next_f32() * 2.0 - 1.0) * MAX_RADIUS as f32);
            let near = IVec2::new(20 + (rng.next_f32() * 8.0) as i32, 20);
            for base in [IVec2::new(1 << 24, 0), IVec2::new((1 << 26) - 64, 1 << 25)] {
                let far = near + base;
                assert_eq!(nearest_pixel(far, offset) - far, nearest_pixel(near, offset) - near, "{far} + {offset}");
            }
        }
    }

    #[test]
    fn blur_averages_inside_the_image() {
        let params = DenoiseParams { radius: MAX_RADIUS, ..DenoiseParams::new(3, 2) };
        let raw = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(blurred_noise(&params, IVec2::new(0, 0), &raw), 0.25);
        assert_eq!(blurred_noise(&params, IVec2::new(2, 1), &raw), 0.0);
        assert!((blurred_noise(&params, IVec2::new(1, 1), &raw) - 1.0 / 6.0).abs() < 1e-7);
    }
}
