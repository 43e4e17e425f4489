//! Parameters of the sampling module: which sampler draws the random numbers of a stage, and the
//! warp probe used by the warp and parity tests.

use bytemuck::{Pod, Zeroable};
use glam::Vec4;

/// Sampler kinds (values of [`SamplerParams::kind`]).
pub mod sampler_kind {
    /// Owen-scrambled Sobol' in Morton (Z) order over the image: one global sequence whose
    /// consecutive indices visit neighbouring pixels, which spreads the error over screen space
    /// as blue noise (Ahmed & Wonka 2020, as pbrt-v4's `ZSobolSampler`). The default.
    pub const ZSOBOL: u32 = 0;
    /// Owen-scrambled Sobol' with a per-pixel hash-based index shuffle (Burley 2020): every pixel
    /// gets an independent randomized sequence (white-noise error across pixels).
    pub const SOBOL: u32 = 1;
    /// Independent uniform random numbers from a counter hash (pcg3d): the baseline.
    pub const INDEPENDENT: u32 = 2;
    /// Number of sampler kinds.
    pub const COUNT: u32 = 3;
}

/// Which sampler a stage draws from, and the shape of the sample space it indexes.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct SamplerParams {
    /// One of [`sampler_kind`].
    pub kind: u32,
    /// Seed: different seeds give statistically independent randomizations.
    pub seed: u32,
    /// log₂ of the samples per pixel the frame will take (`ZSOBOL` interleaves the sample index
    /// below the pixel's Morton code; other kinds ignore it). A sample index at or past
    /// `2^spp_log2` is merged into the Morton code and repeats another (pixel, sample)'s point,
    /// so set it from the real count ([`Self::indexes`]; the host refuses such indices).
    pub spp_log2: u32,
    /// log₂ of the power-of-two square covering the image (`ZSOBOL` only):
    /// `ceil(log2(max(width, height)))`. `2·resolution_log2 + spp_log2` must be ≤ 32
    /// ([`Self::fits_index`]).
    pub resolution_log2: u32,
}

const _: () = assert!(core::mem::size_of::<SamplerParams>() == 16);

impl SamplerParams {
    /// Whether the Morton-ordered sample space of a `ZSOBOL` sampler fits its 32-bit index:
    /// `2·resolution_log2 + spp_log2 ≤ 32`, and `spp_log2 ≤ 31`, the most the kernels shift a
    /// sample index by (a 1 × 1 frame of 2³² samples had passed, its samples from 2³¹ on
    /// repeating earlier points).
    pub fn fits_index(&self) -> bool {
        // In u64: fields from outside may be anything, and u32 arithmetic could wrap.
        2 * u64::from(self.resolution_log2) + u64::from(self.spp_log2) <= 32 && self.spp_log2 <= 31
    }

    /// Whether samples `0..sample_count` of every pixel of a `width × height` image each get their
    /// own point: for `ZSOBOL`, the index fits ([`Self::fits_index`]), the square of side
    /// `2^resolution_log2` covers the image and `sample_count ≤ 2^spp_log2` — else pixels or
    /// samples share a Morton index and repeat each other's points. `SOBOL` and `INDEPENDENT`
    /// index any sample; the kernels draw any other kind as `ZSOBOL`, and so it is judged here.
    pub fn indexes(&self, width: u32, height: u32, sample_count: u32) -> bool {
        self.kind == sampler_kind::SOBOL
            || self.kind == sampler_kind::INDEPENDENT
            || (self.fits_index()
                && (1u64 << self.resolution_log2) >= u64::from(width.max(height))
                && u64::from(sample_count) <= 1u64 << self.spp_log2)
    }
}

/// Warp kinds (values of [`WarpParams::kind`]); each warp maps `[0,1)²` to directions and comes
/// with its pdf. The meaning of [`WarpParams::a`]…`d` per kind is documented on each constant.
pub mod warp_kind {
    /// Uniform hemisphere around +z. No parameters.
    pub const UNIFORM_HEMISPHERE: u32 = 0;
    /// Cosine-weighted hemisphere around +z (Malley's method on the concentric disk). No parameters.
    pub const COSINE_HEMISPHERE: u32 = 1;
    /// Uniform sphere. No parameters.
    pub const UNIFORM_SPHERE: u32 = 2;
    /// Uniform cone around +z: `a.x` = cos θmax.
    pub const UNIFORM_CONE: u32 = 3;
    /// Sphere light seen from the origin, sampled uniformly in its subtended cone: `a.xyz` =
    /// centre, `a.w` = radius.
    pub const SPHERE_LIGHT_CONE: u32 = 4;
    /// Sphere light seen from the origin, sampled uniformly by area over the whole sphere, pdf
    /// converted to solid angle (directions to back-facing points included): `a` as above.
    pub const SPHERE_LIGHT_AREA: u32 = 5;
    /// Quad light seen from the origin, spherical-rectangle sampling (Ureña et al. 2013):
    /// `a.xyz` = corner, `b.xyz` = edge u, `c.xyz` = edge v (perpendicular edges).
    pub const QUAD_SPHERICAL: u32 = 6;
    /// Quad light seen from the origin, uniform by area, pdf in solid angle: `a`, `b`, `c` as above.
    pub const QUAD_AREA: u32 = 7;
    /// GGX visible-normal sampling (Heitz 2018) reflected into a direction: `a.xyz` = unit view
    /// direction (z up), `b.x` = α_x, `b.y` = α_y.
    pub const GGX_VNDF: u32 = 8;
    /// Linearly transformed cosine (Heitz et al. 2016): `a.xyz`, `b.xyz`, `c.xyz` = columns of M.
    pub const LTC: u32 = 9;
    /// Number of warp kinds.
    pub const COUNT: u32 = 10;
}

/// Push constants of the warp probe: `count` samples of warp `kind`, drawn with `sampler` at
/// pixel (0, 0), sample indices `0..count`, sampler dimension 0.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Pod, Zeroable)]
pub struct WarpParams {
    /// One of [`warp_kind`].
    pub kind: u32,
    /// Number of samples (invocations at or past it do nothing).
    pub count: u32,
    /// Explicit padding; always 0.
    pub padding: [u32; 2],
    /// Random numbers used.
    pub sampler: SamplerParams,
    /// Warp parameter, per [`warp_kind`].
    pub a: Vec4,
    /// Warp parameter, per [`warp_kind`].
    pub b: Vec4,
    /// Warp parameter, per [`warp_kind`].
    pub c: Vec4,
}

const _: () = assert!(core::mem::size_of::<WarpParams>() == 80);
const _: () = assert!(core::mem::align_of::<WarpParams>() == 16);

/// Push constants of the sampler probe: raw 32-bit sample values of `sampler` for a
/// `width × height` image at `2^sampler.spp_log2` samples per pixel, sampler dimension `dimension`.
/// Invocation `i` covers pixel `i >> spp_log2` (row-major) and sample `i & (spp − 1)`.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct SamplerProbeParams {
    /// Random numbers probed.
    pub sampler: SamplerParams,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Sampler dimension (2-D slot) probed.
    pub dimension: u32,
    /// Explicit padding; always 0.
    pub padding: u32,
}

const _: () = assert!(core::mem::size_of::<SamplerProbeParams>() == 32);

impl SamplerProbeParams {
    /// Invocations (= samples) the probe writes: `width · height · 2^spp_log2`.
    pub fn sample_count(&self) -> u32 {
        (self.width * self.height) << self.sampler.spp_log2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The index holds `2·resolution_log2 + spp_log2` bits, at most 32, and a sample index
    /// shifted by at most 31.
    #[test]
    fn the_zsobol_index_fits_32_bits_and_31_sample_bits() {
        let fits = |resolution_log2, spp_log2| {
            SamplerParams { kind: sampler_kind::ZSOBOL, seed: 0, spp_log2, resolution_log2 }.fits_index()
        };
        assert!(fits(16, 0) && fits(8, 16) && fits(0, 31) && fits(1, 30));
        assert!(!fits(16, 1) && !fits(0, 32) && !fits(u32::MAX, u32::MAX));
        let one_pixel = SamplerParams { kind: sampler_kind::ZSOBOL, seed: 0, spp_log2: 32, resolution_log2: 0 };
        assert!(!one_pixel.indexes(1, 1, u32::MAX));
    }
}
