//! The separable joint bilateral filter of seed 000 (the reference code's two 1-D passes as its
//! ports quote them [H-DX, H-CPU, H-UNITY, H-SD]; `../shared/reference/ddgi-ratio-ltc.md` §2.2):
//! a Gaussian whose radius follows the noise estimate, times the edge stops, with the **same
//! weights** applied to `S_N` and `U_N` so their ratio is filtered without the analytic
//! shading's detail leaking into it.

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use super::guide::{edge_stop, Guide, SMALLEST_WEIGHT};
use glam::Vec4;
use raywave_shared::denoise::{DenoiseParams, MAX_RADIUS};

/// One pixel of a line as the filter reads it.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FilterTap {
    /// `S_N` (rgb; w unused).
    pub shadowed: Vec4,
    /// `U_N` (rgb; w unused).
    pub unshadowed: Vec4,
    /// The pixel's G-buffer.
    pub guide: Guide,
}

impl FilterTap {
    /// A tap outside the image: no surface, so its weight is 0.
    pub const OUTSIDE: FilterTap = FilterTap { shadowed: Vec4::ZERO, unshadowed: Vec4::ZERO, guide: Guide::NONE };
}

/// The pixels of one filter line around a centre: the CPU reads them from the image, the Vulkan
/// pass from a workgroup-shared tile.
pub trait FilterLine {
    /// The pixel `offset` steps from the centre along the line (`|offset| ≤ MAX_RADIUS`);
    /// [`FilterTap::OUTSIDE`] past the image.
    fn tap(&self, offset: i32) -> FilterTap;
}

/// The Gaussian's radius in pixels for a noise estimate `noise` of an `N`-sample ratio
/// (`samples_per_pixel`, 0 counts as 1): `saturate(1.5·noise)·R/√N`.
///
/// At `N = 1` this is the reference code's `saturate(1.5·noise)·R` [H-DX], which was tuned for
/// one sample per pixel. The `1/√N` is ours: the ratio's per-pixel variance falls as `1/N`, so a
/// footprint `N` times smaller in area (`√N` narrower) leaves the same residual noise, while the
/// blur's bias at shadow edges — which the TV estimate cannot tell from noise, since a clean edge
/// has second differences at any `N` — shrinks with it. Without it the filter kept blurring edges
/// at 16 spp and more, and the raw ratio beat it there (measured in `tests/denoise_quality.rs`).
/// The TV estimate itself is no standard deviation and falls with `N` too — saturated at 1 spp,
/// then roughly as `σ^½` (simulated, R = 6, a grey binary visibility ½ in every pixel, the
/// noisiest case: 1.00, 0.92, 0.66, 0.46 at 1, 4, 16, 64 spp, 3^¼ above a single channel's
/// 0.97, 0.71, 0.50, 0.35 since a grey difference's RGB length is √3 its channel's) — so the
/// radius narrows faster than `1/√N`: 6, 3.0, 1.5 and 0.52 px on average there, a quarter of
/// those pixels passing through at 64 spp, quieter ones sooner; the alternatives below were
/// measured on top of that same estimate.
/// A slower narrowing trades one built-in scene against the other (`raywave report
/// error-vs-time`, 128², R = 2, ratio+tv relMSE at 2/4/8/16 spp): `N^(−1/3)` costs the Cornell
/// box 5/11/10/27 % (the wider blur's bias outweighs the variance it removes) and gains the
/// two-light box 7/15/40/34 % (its raw ratio is 8× noisier at 16 spp; at 16 spp both against
/// the unfiltered ratio, where `N^(−1/2)` has switched the filter off); `N^(−1/4)` costs
/// 8–89 % and gains 9–43 %.
///
/// A per-pixel sample variance does not tell the cases apart either (measured with the same
/// report; the ratio's standard error `σ̂` by the delta method from per-pixel luminance moments of
/// `S_N` and `U_N`, its 3×3 RMS, in place of `1/√N` from 2 spp on, the filter running at every
/// `N`): `max(1/√N, min(1, 2σ̂))`, which widens only pixels noisier than one binary sample,
/// changed either scene by at most 2 % — the two-light box's raw ratio is noisier because more
/// of its pixels are in penumbra, not because they are noisier; `min(1, 4σ̂)` gained the
/// two-light box 27/23/6 % at 8/16/32 spp and cost the Cornell box 14/26/14/6 % at 2/4/8/16;
/// the unblurred `σ̂` of a few samples, often 0 in a penumbra, left noisy pixels unfiltered
/// (2.8× and 7.8× the error at 2 spp). What separates the scenes is signal — the blur's bias at
/// the Cornell box's contact shadows — which neither the TV estimate nor a variance can tell
/// from noise.
pub fn gaussian_radius(noise: f32, radius: u32, samples_per_pixel: u32) -> f32 {
    let width = (1.5 * noise).clamp(0.0, 1.0) * radius.clamp(1, MAX_RADIUS) as f32;
    width / (samples_per_pixel.max(1) as f32).sqrt()
}

/// One 1-D pass at a pixel: returns the filtered `(S_N, U_N)`. Taps `r ∈ [−R, R]` weigh
/// `exp(−(r/g)²) · edge_stop`, with `g` the [`gaussian_radius`], or nothing below
/// [`SMALLEST_WEIGHT`]; the centre weighs 1. A pixel
/// whose `g ≤ 0.5` — no shadow noise — or that has no surface passes through untouched [H-DX].
pub fn bilateral_pass<L: FilterLine>(line: &L, noise: f32, params: &DenoiseParams) -> (Vec4, Vec4) {
    let center = line.tap(0);
    let sigma = gaussian_radius(noise, params.radius, params.samples_per_pixel);
    // `sigma` is finite: the noise estimate is clamped to [0, 1].
    if sigma <= 0.5 || !center.guide.is_surface() {
        return (center.shadowed, center.unshadowed);
    }
    let radius = params.radius.clamp(1, MAX_RADIUS) as i32;
    let (mut shadowed, mut unshadowed, mut total) = (center.shadowed, center.unshadowed, 1.0);
    let mut r = 1;
    while r <= radius {
        let gaussian = (-(r as f32 / sigma) * (r as f32 / sigma)).exp();
        let mut side = -1;
        while side <= 1 {
            let tap = line.tap(side * r);
            let w = gaussian * edge_stop(&center.guide, &tap.guide, params.edge_weights);
            if w >= SMALLEST_WEIGHT {
                shadowed += w * tap.shadowed;
                unshadowed += w * tap.unshadowed;
                total += w;
            }
            side += 2;
        }
        r += 1;
    }
    (shadowed / total, unshadowed / total)
}

/// The pixel `along` steps into filter line `line` of a pass along `params.axis`: `(along, line)`
/// along x, `(line, along)` along y.
pub fn line_pixel(params: &DenoiseParams, line: u32, along: i32) -> glam::IVec2 {
    if params.axis == raywave_shared::denoise::axis::Y {
        glam::IVec2::new(line as i32, along)
    } else {
        glam::IVec2::new(along, line as i32)
    }
}

/// [`FilterLine`] over whole images in memory (the CPU executor, and tests): the line through
/// `center` along `params.axis`.
pub struct ImageLine<'a> {
    /// `S_N` per pixel.
    pub shadowed: &'a [Vec4],
    /// `U_N` per pixel.
    pub unshadowed: &'a [Vec4],
    /// Surface point and depth per pixel (see [`Guide::position`]).
    pub position: &'a [Vec4],
    /// Normal and analytic luminance per pixel (see [`Guide::normal`]).
    pub normal: &'a [Vec4],
    /// The centre pixel.
    pub center: glam::IVec2,
    /// The filter's parameters (size and axis).
    pub params: &'a DenoiseParams,
}

impl FilterLine for ImageLine<'_> {
    fn tap(&self, offset: i32) -> FilterTap {
        let step = line_pixel(self.params, 0, offset);
        let Some(i) = self.params.index_of(self.center + step) else { return FilterTap::OUTSIDE };
        FilterTap {
            shadowed: self.shadowed[i],
            unshadowed: self.unshadowed[i],
            guide: Guide { position: self.position[i], normal: self.normal[i] },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{IVec2, Vec3};
    use std::{vec, vec::Vec};

    #[derive(Clone)]
    struct Plane {
        shadowed: Vec<Vec4>,
        unshadowed: Vec<Vec4>,
        position: Vec<Vec4>,
        normal: Vec<Vec4>,
        params: DenoiseParams,
    }

    /// A `w × 1` strip on the plane y = 0 seen from 10 units, with `visibility` per pixel.
    fn strip(visibility: &[f32]) -> Plane {
        let n = visibility.len();
        let u = Vec4::new(0.4, 0.5, 0.6, 0.0);
        Plane {
            shadowed: visibility.iter().map(|&v| u * v).collect(),
            unshadowed: vec![u; n],
            position: (0..n).map(|x| Vec3::new(x as f32 * 0.01, 0.0, 0.0).extend(10.0)).collect(),
            normal: vec![Vec3::Y.extend(0.5); n],
            params: DenoiseParams { radius: MAX_RADIUS, ..DenoiseParams::new(n as u32, 1) },
        }
    }

    fn filter(p: &Plane, x: i32, noise: f32) -> (Vec4, Vec4) {
        let line = ImageLine {
            shadowed: &p.shadowed,
            unshadowed: &p.unshadowed,
            position: &p.position,
            normal: &p.normal,
            center: IVec2::new(x, 0),
            params: &p.params,
        };
        bilateral_pass(&line, noise, &p.params)
    }

    #[test]
    fn quiet_pixels_pass_through_and_noisy_ones_average() {
        let visibility: Vec<f32> = (0..41).map(|x| (x % 2) as f32).collect();
        let p = strip(&visibility);
        assert_eq!(filter(&p, 20, 0.0), (p.shadowed[20], p.unshadowed[20]), "no noise: untouched");
        assert_eq!(filter(&p, 20, 0.03), (p.shadowed[20], p.unshadowed[20]), "g = 0.45 px: untouched");
        assert_ne!(filter(&p, 20, 0.04), (p.shadowed[20], p.unshadowed[20]), "g = 0.6 px: filtered");
        assert!((gaussian_radius(0.5, 10, 1) - 7.5).abs() < 1e-6 && gaussian_radius(2.0, 10, 1) == 10.0);
        assert_eq!(gaussian_radius(0.5, 10, 0), gaussian_radius(0.5, 10, 1), "0 samples count as 1");
        assert!((gaussian_radius(0.5, 10, 9) - 2.5).abs() < 1e-6, "√N narrower at N samples");
    }

    #[test]
    fn more_samples_narrow_the_gaussian_until_it_is_the_identity() {
        // A shadow edge: lit left of pixel 20, shadowed from it on.
        let visibility: Vec<f32> = (0..41).map(|x| if x < 20 { 1.0 } else { 0.0 }).collect();
        let mut p = strip(&visibility);
        let untouched = (p.shadowed[20], p.unshadowed[20]);
        let leak_at = |p: &Plane, samples_per_pixel| {
            let p = Plane { params: DenoiseParams { samples_per_pixel, ..p.params }, ..p.clone() };
            let (s, u) = filter(&p, 20, 1.0);
            s.x / u.x
        };
        // A narrower Gaussian leaks less light into the edge's first shadowed pixel, yet still
        // filters at N = 399, just below 4R².
        let (one, four, many) = (leak_at(&p, 1), leak_at(&p, 4), leak_at(&p, 399));
        assert!(one > four && four > many && many > 0.0, "{one} {four} {many}");
        p.params.samples_per_pixel = 4 * MAX_RADIUS * MAX_RADIUS;
        assert!(p.params.tv_filter_is_identity());
        assert_eq!(filter(&p, 20, 1.0), untouched, "g = R/√N = ½ px at N = 4R²");
    }

    #[test]
    fn same_weights_for_both_signals_keep_the_ratio_in_range() {
        let visibility: Vec<f32> = (0..41).map(|x| (x % 2) as f32).collect();
        let p = strip(&visibility);
        let (s, u) = filter(&p, 20, 1.0);
        let ratio = s.x / u.x;
        assert!((ratio - 0.5).abs() < 0.1, "alternating visibility filters to ≈ 1/2: {ratio}");
        assert!((s.y / u.y - ratio).abs() < 1e-6, "one ratio for every channel");
        // Unshadowed everywhere under a U_N that varies from pixel to pixel: S_N and U_N weighed
        // alike filter to the same value, bit for bit (a constant U_N would hide a difference,
        // normalised weights returning it whatever they are).
        let mut lit = strip(&[1.0; 41]);
        for (x, (s, u)) in lit.shadowed.iter_mut().zip(&mut lit.unshadowed).enumerate() {
            *u *= 0.25 + (x % 7) as f32;
            *s = *u;
        }
        let (s, u) = filter(&lit, 20, 1.0);
        assert_eq!(s, u, "S_N and U_N weighed alike");
        assert_ne!(u, lit.unshadowed[20], "the pixel was filtered");
    }

    /// At the largest radiance the denoiser accepts, the widest filter's sums stay finite and
    /// alternating visibility still filters to ≈ ½ (sums that overflowed had given 0 or 1).
    #[test]
    fn the_largest_filtered_radiance_keeps_the_sums_finite() {
        let visibility: Vec<f32> = (0..41).map(|x| (x % 2) as f32).collect();
        let mut p = strip(&visibility);
        for (s, u) in p.shadowed.iter_mut().zip(&mut p.unshadowed) {
            let scale = raywave_shared::denoise::MAX_FILTERED_RADIANCE / u.max_element();
            (*s, *u) = (*s * scale, *u * scale);
        }
        assert_eq!(p.unshadowed[0].z, raywave_shared::denoise::MAX_FILTERED_RADIANCE);
        let (s, u) = filter(&p, 20, 1.0);
        assert!(s.is_finite() && u.is_finite(), "{s} {u}");
        let ratio = s.z / u.z;
        assert!((ratio - 0.5).abs() < 0.1, "{ratio}");
    }

    /// The outermost taps, at r = ±R, count with their Gaussian weight and the taps beyond them
    /// not at all: the filtered value is the closed form of the weights over |r| ≤ R.
    #[test]
    fn the_taps_at_plus_and_minus_the_radius_count_and_none_beyond() {
        // Pixel 20 of a 41-pixel strip on one plane (every edge stop 1) at R = 10 and noise 1:
        // g = min(1, 1.5)·10/√1 = 10 px, so the tap at r weighs e^−(r/10)², e^−1 at r = ±10 — a
        // normal float far above SMALLEST_WEIGHT. Only the taps at and beyond ±R see light: 1
        // at x ≤ 10, ½ at x ≥ 30, so S_N filters to U·(1 + ½)·e^−1 / Σ_{|r|≤10} e^−(r/10)²;
        // without the taps at ±R it would be 0, with those at ±11 larger.
        let visibility: Vec<f32> = (0..41)
            .map(|x| match x {
                ..=10 => 1.0,
                30.. => 0.5,
                _ => 0.0,
            })
            .collect();
        let p = strip(&visibility);
        assert_eq!(p.params.radius, 10);
        let weight = |r: i32| (-(f64::from(r) / 10.0).powi(2)).exp();
        let total: f64 = (-10..=10).map(weight).sum();
        let expected = (1.0 + 0.5) * weight(10) / total;
        let (s, _) = filter(&p, 20, 1.0);
        for channel in 0..3 {
            let want = f64::from(p.unshadowed[20][channel]) * expected;
            let got = f64::from(s[channel]);
            assert!((got / want - 1.0).abs() < 1e-6, "channel {channel}: {got} vs {want}");
        }
    }

    #[test]
    fn subnormal_weights_count_as_zero_on_every_backend() {
        // g = 15 · 0.0684 = 1.026 px: the taps at r = ±10 weigh e^−95 ≈ 5·10⁻⁴², a subnormal a
        // GPU may flush; r = 9 weighs e^−77 ≈ 4·10⁻³⁴, a normal number. Only the tap at +10 sees
        // light, 10³⁰ times the others' U_N: kept, it would lift S_N to ~2·10⁻¹².
        let mut p = strip(&[0.0; 41]);
        p.shadowed[30] = p.unshadowed[30] * 1.0e30;
        let g = gaussian_radius(0.0684, MAX_RADIUS, 1);
        assert!((87.4..103.2).contains(&(10.0 / g).powi(2)) && (9.0 / g).powi(2) < 87.3, "g = {g}");
        assert_eq!(filter(&p, 20, 0.0684).0, Vec4::ZERO);
        p.shadowed[29] = p.unshadowed[29] * 1.0e30;
        assert!(filter(&p, 20, 0.0684).0.x > 0.0, "the normal weight at r = 9 counts");
    }

    #[test]
    fn taps_outside_the_image_or_the_surface_are_ignored() {
        let mut p = strip(&[1.0, 0.0, 1.0, 0.0]);
        p.position[3] = Vec4::ZERO;
        // Pixel 0 at R = 10, g = 10: its own tap (weight 1, visible) and pixels 1 and 2 (Gaussian
        // weights e^-0.01, e^-0.04; 2 visible); the ten taps left of the image and the miss at 3
        // count for nothing. Clamped border taps would give 0.902, a counted miss 0.507.
        let (s, u) = filter(&p, 0, 1.0);
        let ratio = s.x / u.x;
        let expected = (1.0 + (-0.04f32).exp()) / (1.0 + (-0.01f32).exp() + (-0.04f32).exp());
        assert!((ratio - expected).abs() < 1e-5, "{ratio} vs {expected}");
        let (s, u) = filter(&p, 3, 1.0);
        assert_eq!((s, u), (p.shadowed[3], p.unshadowed[3]), "a miss passes through");
    }
}
