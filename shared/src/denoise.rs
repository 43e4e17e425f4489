//! Parameters of the denoise stage: seed 000's total-variation-guided joint bilateral filter of
//! `S_N` and `U_N` (Heitz, Hill & McGuire 2018), and the SVGF-style à-trous baseline (Schied et
//! al. 2017). Source keys refer to `../shared/reference/ddgi-ratio-ltc.md` §2 and
//! `sampling-denoise.md` §3.1.

use crate::bindings::WORKGROUP_SIZE;
use bytemuck::{Pod, Zeroable};
use glam::{IVec2, Vec4};

/// Largest filter radius R in pixels: the reference code's R = 10 [H-DX, H-CPU, H-SD]. The
/// Vulkan bilateral pass keeps `WORKGROUP_SIZE + 2·MAX_RADIUS` pixels of a line in workgroup
/// memory, so the radius is bounded at compile time.
pub const MAX_RADIUS: u32 = 10;

/// Largest `S_N` or `U_N` channel the denoiser filters: `f32::MAX / 32` (≈ 1.06·10³⁷). The
/// bilateral passes sum up to `2·MAX_RADIUS + 1 = 21` taps of weight ≤ 1, which stays finite
/// below it; above it a sum could overflow to ∞ and the ratio `S/U` silently become 0 or 1.
/// Scenes' radiance stops far below (`scene::MAX_EMISSION` = 10²⁰).
pub const MAX_FILTERED_RADIANCE: f32 = f32::MAX / 32.0;

/// The 21 taps' weights sum below 32: `MAX_FILTERED_RADIANCE`'s margin.
const _: () = assert!(2 * MAX_RADIUS < 32);

/// Pixels of one line a bilateral workgroup loads into shared memory: its own
/// `WORKGROUP_SIZE` plus `MAX_RADIUS` on each side.
pub const TILE_LEN: u32 = WORKGROUP_SIZE + 2 * MAX_RADIUS;

/// The widest footprint [`DenoiseParams::default_radius`] picks: the ratio+tv relMSE minimum at
/// 1 spp lies at R = 5–7 on the built-in scenes at 512² and 1024² (README, Denoising).
pub const DEFAULT_MAX_RADIUS: u32 = 6;

/// Number of randomly rotated lines the noise estimate measures total variation along: 4, at
/// `angle0 + k·π/4` [H-PF, H-EST, H-CPU].
pub const NOISE_LINES: u32 = 4;

/// Default edge-stop weights (depth, normal, plane, analytic) = (1.0, 1.5, 1.5, 0.09) of the DX
/// port and ShadowDenoiser [H-DX, H-SD].
pub const DEFAULT_EDGE_WEIGHTS: Vec4 = Vec4::new(1.0, 1.5, 1.5, 0.09);

/// Default SVGF colour edge stop `phiColor` = 10 (Falcor SVGFPass `mPhiColor`).
pub const DEFAULT_SVGF_PHI_COLOR: f32 = 10.0;

/// Default SVGF variance boost 4: Falcor multiplies the spatial variance estimate by `4/h` for a
/// history of `h` frames, and a single frame has `h = 1` (SVGFFilterMoments).
pub const DEFAULT_SVGF_VARIANCE_BOOST: f32 = 4.0;

/// Largest edge-stop weight the denoiser accepts (each of [`DenoiseParams::edge_weights`]): 10⁶.
/// The stops scale the weights by at most 10 (`4·Wd`, `10·Wa`, see
/// `raywave_kernels::denoise::guide::edge_stop`), which then stay finite: a zero difference gives
/// the stop 1, and a product with a difference overflows only where the exact stop is 0 anyway.
/// At `Wd` = 10³⁸ (or `Wa` above `f32::MAX/10` ≈ 3.4·10³⁷) the scaled weight itself had overflowed to ∞, ∞·0 made the
/// stop of every tap at the same depth NaN and so 0, and the filter silently did nothing. 10⁶
/// already zeroes the depth stop at a relative depth difference of 2.5·10⁻⁷ (a few ulp) and the
/// others at differences of 10⁻⁶ or less.
pub const MAX_EDGE_WEIGHT: f32 = 1.0e6;

/// Smallest nonzero edge-stop weight the denoiser accepts: 10⁻⁶, so that the scaled weights
/// `4·Wd`, `10·Wa`, `2·Wp` are normal numbers; a subnormal weight would be 0 on a GPU that
/// flushes subnormals and not on the CPU (a parity break wherever its product with a large
/// relative depth difference matters). Such a weight moves the normal, plane and analytic stops
/// by at most 10⁻⁵; 0 (accepted) turns a stop off.
pub const MIN_EDGE_WEIGHT: f32 = 1.0e-6;

/// Smallest SVGF `phiColor` the denoiser accepts: 10⁻⁶. The luminance stops divide by it (the
/// moments pass) and by `phiColor·√(10⁻¹⁰ + variance)` ≥ 10⁻¹¹ (the à-trous iterations), which
/// stay normal above it: a subnormal `phiColor` (below 1.2·10⁻³⁸, or below ~10⁻³³ for the
/// à-trous scale) is 0 on a GPU that flushes subnormals, where `|Δl|/0` drops taps the CPU
/// keeps. At 10⁻⁶ the stops already reject any tap whose ratio luminance differs by more than
/// about 10⁻⁴ (10⁻⁹ at the à-trous scale's least).
pub const MIN_SVGF_PHI_COLOR: f32 = 1.0e-6;

/// Largest SVGF `phiColor` the denoiser accepts: 10⁶, where the luminance stops are 1 for any
/// difference of shadow ratios (at most 10⁴) to within 10⁻²; with the variance at most
/// [`MAX_SVGF_VARIANCE_BOOST`] times 10⁸ (ratios up to 10⁴), the à-trous scale stays below 10¹³.
pub const MAX_SVGF_PHI_COLOR: f32 = 1.0e6;

/// Largest SVGF variance boost the denoiser accepts: 10⁶. The ratio's luminance is at most 10⁴
/// (`shadow_ratio` clamps), its variance at most 10⁸, and the boosted variance at most 10¹⁴;
/// above ~3·10³⁰ the product could overflow, and the moments pass turns a non-finite variance
/// into 0 — the opposite of a large boost.
pub const MAX_SVGF_VARIANCE_BOOST: f32 = 1.0e6;

/// Filter axis of a bilateral pass.
pub mod axis {
    /// Along image rows (x).
    pub const X: u32 = 0;
    /// Along image columns (y).
    pub const Y: u32 = 1;
}

/// Push constants of every denoise pass. One invocation per pixel, except the bilateral pass,
/// which runs `WORKGROUP_SIZE`-pixel segments of lines (see [`DenoiseParams::bilateral_invocations`]).
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Pod, Zeroable)]
pub struct DenoiseParams {
    /// Image width in pixels (pixel `i` is `(i mod width, i / width)`).
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Filter radius R in pixels, `1..=MAX_RADIUS`; also bounds the noise lines (`min(10, R)`).
    pub radius: u32,
    /// The bilateral pass's [`axis`].
    pub axis: u32,
    /// The à-trous pass's tap spacing in pixels (1, 2, 4, 8 over the iterations).
    pub step: u32,
    /// Seed of the per-pixel rotation of the noise lines.
    pub seed: u32,
    /// À-trous iterations of the SVGF baseline (the host's pass list; the kernels ignore it).
    pub atrous_iterations: u32,
    /// Samples per pixel `N` behind `S_N` and `U_N` (≥ 1; 0 counts as 1). The TV filter's
    /// Gaussian narrows as `1/√N` (see `raywave_kernels::denoise::bilateral::gaussian_radius`).
    pub samples_per_pixel: u32,
    /// Edge-stop weights (depth, normal, plane, analytic), see [`DEFAULT_EDGE_WEIGHTS`].
    pub edge_weights: Vec4,
    /// SVGF baseline: (`phiColor`, variance boost, 0, 0).
    pub svgf: Vec4,
}

const _: () = assert!(core::mem::size_of::<DenoiseParams>() == 64);

impl DenoiseParams {
    /// The defaults for a `width × height` image: the DX port's edge weights, Falcor's SVGF
    /// constants, and the footprint [`Self::default_radius`] picks for the image size.
    pub const fn new(width: u32, height: u32) -> Self {
        Self::with_radius(width, height, Self::default_radius(width, height))
    }

    /// The defaults with filter radius `radius` (`1..=MAX_RADIUS`; the denoiser refuses others)
    /// and the SVGF baseline's à-trous iterations `k`: 4 (Falcor) with R ≥ 5, one fewer per
    /// halving of R below, so that small images, whose R is small, are not blurred across. The
    /// baseline blurs wider than the TV filter: its reach is `2·(2^k − 1)` pixels (30 at k = 4)
    /// and its kernel's standard deviation `√((4^k − 1)/3)` pixels (9.2 at k = 4; each B3 level
    /// adds a variance of its step squared), against the TV Gaussian's at most `R/√2` (4.2 at
    /// R = 6).
    pub const fn with_radius(width: u32, height: u32, radius: u32) -> Self {
        let atrous_iterations = if radius >= 5 {
            4
        } else if radius >= 3 {
            3
        } else if radius == 2 {
            2
        } else {
            1
        };
        Self {
            width,
            height,
            radius,
            axis: axis::X,
            step: 1,
            seed: 0,
            atrous_iterations,
            samples_per_pixel: 1,
            edge_weights: DEFAULT_EDGE_WEIGHTS,
            svgf: Vec4::new(DEFAULT_SVGF_PHI_COLOR, DEFAULT_SVGF_VARIANCE_BOOST, 0.0, 0.0),
        }
    }

    /// The filter radius that follows the image size: `R = 10 · (s / 1080)^(2/3)` for a short
    /// side of `s` pixels, rounded, within 1 … [`DEFAULT_MAX_RADIUS`] = 6 — narrower on smaller
    /// frames, whose penumbrae span fewer pixels. Measured (`raywave report error-vs-time
    /// --denoise-radius`, `examples/footprint_oracle.rs`; 1 spp, the README's Denoising section):
    /// on the built-in scenes the ratio+tv relMSE minimum moves from R = 2 at 128² to 3–4 at
    /// 256² and 5 at 512², about as the 2/3 power of the image (the earlier `s / 64` gave R = 8 at
    /// 512², with 1.7× (Cornell box) and 1.4× (two lights) the error of R = 6), but no further:
    /// at 1024² it is 5 (Cornell) and 7 (two lights). There the reference code's R = 10 at 1080p
    /// [H-DX, H-SD] leaves 2.5× and 1.3× the minimum's error, R = 6 1.1× and 1.03×; so the rule
    /// stops at 6 (from s = 441 up), and R = 10 stays one option away.
    ///
    /// In integers (no `powf` in `no_std` const code): the largest `r ≤ 6` with
    /// `10·(s/1080)^(2/3) ≥ r − ½`, i.e. `729·(2r − 1)³ ≤ 5·s²`.
    pub const fn default_radius(width: u32, height: u32) -> u32 {
        let short = if width < height { width } else { height };
        // Every side from 441 up gives the cap; the clamp keeps `s²` far from overflowing.
        let short = (if short > 1080 { 1080 } else { short }) as u64;
        let mut radius = 1;
        while radius < DEFAULT_MAX_RADIUS && 729 * (2 * radius as u64 + 1).pow(3) <= 5 * short * short {
            radius += 1;
        }
        radius
    }

    /// Whether the TV filter leaves every pixel as it is: its widest Gaussian, `R/√N`
    /// pixels, is ≤ ½ pixel (`N ≥ 4R²`), where every pixel passes through — so the host skips
    /// the noise and bilateral passes.
    pub fn tv_filter_is_identity(&self) -> bool {
        let radius = u64::from(self.radius.clamp(1, MAX_RADIUS));
        u64::from(self.samples_per_pixel) >= 4 * radius * radius
    }

    /// Pixels in the image.
    pub const fn pixels(&self) -> u32 {
        self.width * self.height
    }

    /// The pixel at row-major index `i` (`(i mod width, i / width)`), if `i` lies inside the
    /// image: what an invocation of a per-pixel pass works on.
    pub fn pixel(&self, i: u32) -> Option<IVec2> {
        if i < self.pixels() {
            Some(IVec2::new((i % self.width) as i32, (i / self.width) as i32))
        } else {
            None
        }
    }

    /// The row-major index of `pixel`, if it lies inside the image: where a filter tap reads.
    pub fn index_of(&self, pixel: IVec2) -> Option<usize> {
        let inside = pixel.x >= 0 && pixel.y >= 0 && (pixel.x as u32) < self.width && (pixel.y as u32) < self.height;
        if inside {
            Some((pixel.y as u32 * self.width + pixel.x as u32) as usize)
        } else {
            None
        }
    }

    /// Length of the lines the bilateral pass filters along and how many there are:
    /// `(width, height)` along x, `(height, width)` along y.
    pub const fn lines(&self) -> (u32, u32) {
        if self.axis == axis::Y {
            (self.height, self.width)
        } else {
            (self.width, self.height)
        }
    }

    /// Workgroup-sized segments each line splits into.
    pub const fn segments_per_line(&self) -> u32 {
        self.lines().0.div_ceil(WORKGROUP_SIZE)
    }

    /// Invocations of a bilateral pass: every line padded to whole workgroups; `None` where that
    /// exceeds `u32::MAX`, which no dispatch covers, although the image's pixels may fit (a
    /// 2^26 × 1 image along y: 2^26 lines of one workgroup each, 2^32 invocations). The host's
    /// denoiser refuses such images; kernels do not call this.
    pub fn bilateral_invocations(&self) -> Option<u32> {
        self.lines().1.checked_mul(self.segments_per_line())?.checked_mul(WORKGROUP_SIZE)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn footprint_follows_the_image_size() {
        let footprint = |w, h| {
            let p = DenoiseParams::new(w, h);
            (p.radius, p.atrous_iterations)
        };
        assert_eq!(footprint(1920, 1080), (DEFAULT_MAX_RADIUS, 4), "6, not the reference code's 10, at 1080p");
        assert_eq!(footprint(4000, 1001), (6, 4));
        assert_eq!(footprint(1000, 1000), (6, 4));
        assert_eq!(footprint(512, 512), (6, 4), "the render's default size");
        assert_eq!(footprint(441, 4000), (6, 4));
        assert_eq!(footprint(440, 4000), (5, 4));
        assert_eq!(footprint(256, 300), (4, 3));
        assert_eq!(footprint(128, 128), (2, 2));
        assert_eq!(footprint(64, 96), (2, 2));
        assert_eq!(footprint(62, 5000), (1, 1));
        assert_eq!(footprint(1, 1), (1, 1));
        assert_eq!(footprint(u32::MAX, u32::MAX), (DEFAULT_MAX_RADIUS, 4));
        // The rule it implements, in floating point, at every side up to 1100.
        for side in 1..=1100u32 {
            let exact = 10.0 * (side as f64 / 1080.0).powf(2.0 / 3.0);
            let expected = (exact + 0.5).floor().clamp(1.0, DEFAULT_MAX_RADIUS as f64) as u32;
            assert_eq!(DenoiseParams::default_radius(side, side), expected, "side {side}: {exact}");
        }
        let chosen = |radius| {
            let p = DenoiseParams::with_radius(1920, 1080, radius);
            (p.radius, p.atrous_iterations)
        };
        assert_eq!([chosen(1), chosen(2), chosen(3), chosen(4), chosen(5)], [(1, 1), (2, 2), (3, 3), (4, 3), (5, 4)]);
        assert_eq!(DenoiseParams::with_radius(128, 128, 2), DenoiseParams::new(128, 128));
    }

    #[test]
    fn pixels_and_indices_are_row_major_and_only_inside_the_image() {
        let p = DenoiseParams::new(7, 3);
        for i in 0..p.pixels() {
            let pixel = p.pixel(i).expect("an index below the pixel count");
            assert_eq!(p.index_of(pixel), Some(i as usize), "pixel {pixel}");
        }
        assert_eq!((p.pixel(8), p.pixel(20)), (Some(IVec2::new(1, 1)), Some(IVec2::new(6, 2))));
        assert_eq!((p.pixel(21), p.pixel(u32::MAX)), (None, None));
        let outside = [IVec2::new(-1, 0), IVec2::new(0, -1), IVec2::new(7, 0), IVec2::new(0, 3), IVec2::MIN];
        assert!(outside.iter().all(|&pixel| p.index_of(pixel).is_none()));
        assert_eq!(DenoiseParams::new(0, 5).pixel(0), None, "an empty image has no pixel");
    }

    #[test]
    fn the_tv_filter_switches_off_once_its_widest_gaussian_is_half_a_pixel() {
        let at = |radius, samples_per_pixel| {
            DenoiseParams { radius, samples_per_pixel, ..DenoiseParams::new(64, 64) }.tv_filter_is_identity()
        };
        assert!(!at(2, 1) && !at(2, 15) && at(2, 16) && at(2, 1 << 20));
        assert!(!at(MAX_RADIUS, 399) && at(MAX_RADIUS, 400) && at(MAX_RADIUS + 5, 400));
        assert!(!at(0, 3) && at(0, 4), "radius 0 is filtered as 1");
        assert!(!at(1, 0), "0 samples count as 1");
    }

    #[test]
    fn bilateral_dispatch_pads_every_line_to_whole_workgroups() {
        let p = DenoiseParams { axis: axis::Y, ..DenoiseParams::new(70, 130) };
        assert_eq!((p.lines(), p.segments_per_line()), ((130, 70), 3));
        assert_eq!(p.bilateral_invocations(), Some(70 * 3 * WORKGROUP_SIZE));
        let p = DenoiseParams { axis: axis::X, ..p };
        assert_eq!(p.bilateral_invocations(), Some(130 * 2 * WORKGROUP_SIZE));
    }

    #[test]
    fn a_bilateral_dispatch_past_32_bits_has_no_invocation_count() {
        let along = |axis, width, height| DenoiseParams { axis, ..DenoiseParams::new(width, height) };
        // 2^26 pixels in one row: 2^26 invocations along x, 2^26 one-pixel columns of one
        // workgroup each (2^32 invocations) along y.
        assert_eq!(along(axis::X, 1 << 26, 1).bilateral_invocations(), Some(1 << 26));
        assert_eq!(along(axis::Y, 1 << 26, 1).bilateral_invocations(), None);
        assert_eq!(along(axis::Y, (1 << 26) - 1, 1).bilateral_invocations(), Some(u32::MAX - (WORKGROUP_SIZE - 1)));
        assert_eq!(along(axis::X, u32::MAX, 1).bilateral_invocations(), None, "the last segment's padding");
        assert_eq!(along(axis::X, 1 << 16, 1 << 16).bilateral_invocations(), None);
    }
}
