//! The samplers: `(pixel, sample index, dimension) →` a 2-D point in `[0, 1−2⁻²⁴]²`.
//!
//! A *dimension* here is a 2-D slot (see [`super::dims`]): each call returns two numbers, and a
//! 1-D request takes the slot's first. Every sampler is a pure function of its arguments, so any
//! stage can draw any slot of any sample with no state carried between dispatches.
//!
//! - `ZSOBOL` (default): one Owen-scrambled Sobol' sequence over the whole image, indexed by the
//!   pixel's Morton code with the sample index below it, its base-4 digits randomly permuted
//!   level by level (Ahmed & Wonka 2020, "Screen-space blue-noise diffusion of Monte Carlo sampling
//!   error via hierarchical ordering of pixels"; pbrt-v4's `ZSobolSampler` [sampling-denoise.md
//!   §1.2]). Neighbouring pixels receive complementary, stratified samples, so the error of a
//!   1-spp image is blue noise.
//! - `SOBOL`: per pixel, the Sobol' (0,2)-sequence with a hash-based Owen scramble of the values
//!   and a nested-uniform shuffle of the index (Burley 2020), seeded per pixel and per dimension:
//!   each pixel's samples are stratified, pixels are independent.
//! - `INDEPENDENT`: pcg3d counter hashing, uniform and independent (the baseline).
//!
//! Both Sobol' samplers pad to more dimensions with an independent shuffle and scramble per slot.
//! With `SOBOL` every slot's first `2^k` samples of a pixel form a (0,k,2)-net; with `ZSOBOL` a
//! pixel's whole `2^spp_log2` samples do, but not every power-of-two prefix of them: its base-4
//! digits are permuted, so samples {0, 1} of a digit may fall in one half of the square.

use super::owen::{hash_combine, mix_bits, nested_uniform_scramble};
use super::sobol::{sobol_dimension_0, sobol_dimension_1};
use crate::hash::{pcg3d, unit_float};
use glam::{UVec2, UVec3, Vec2};
use raywave_shared::sampling::{sampler_kind, SamplerParams};

/// Raw 32-bit fractions of slot `dimension` of sample `sample_index` at `pixel`; the top 24 bits
/// become the float sample. Bit-identical on every backend (the parity tests compare these).
pub fn sample_bits(params: &SamplerParams, pixel: UVec2, sample_index: u32, dimension: u32) -> UVec2 {
    if params.kind == sampler_kind::SOBOL {
        shuffled_sobol_bits(params.seed, pixel, sample_index, dimension)
    } else if params.kind == sampler_kind::INDEPENDENT {
        independent_bits(params.seed, pixel, sample_index, dimension)
    } else {
        zsobol_bits(params, pixel, sample_index, dimension)
    }
}

/// Slot `dimension` of sample `sample_index` at `pixel` as a point in `[0, 1−2⁻²⁴]²`.
pub fn sample_2d(params: &SamplerParams, pixel: UVec2, sample_index: u32, dimension: u32) -> Vec2 {
    let bits = sample_bits(params, pixel, sample_index, dimension);
    Vec2::new(unit_float(bits.x), unit_float(bits.y))
}

/// The first number of slot `dimension`, in `[0, 1−2⁻²⁴]`.
pub fn sample_1d(params: &SamplerParams, pixel: UVec2, sample_index: u32, dimension: u32) -> f32 {
    unit_float(sample_bits(params, pixel, sample_index, dimension).x)
}

/// Point `index` of the Sobol' (0,2)-sequence with both coordinates Owen-scrambled by seeds
/// derived from `seed`.
fn scrambled_sobol_2d(index: u32, seed: u32) -> UVec2 {
    UVec2::new(
        nested_uniform_scramble(sobol_dimension_0(index), hash_combine(seed, 1)),
        nested_uniform_scramble(sobol_dimension_1(index), hash_combine(seed, 2)),
    )
}

/// Burley's shuffled, scrambled Sobol': independent per (pixel, dimension).
fn shuffled_sobol_bits(seed: u32, pixel: UVec2, sample_index: u32, dimension: u32) -> UVec2 {
    // One to one in the pixel (its Morton code, sides being at most 2¹⁶, then a bijection), and
    // so is `hash_combine` in its first argument: a 32-bit hash of (x, y, seed) had given pixel
    // pairs one seed, and so the same samples in every slot (11 pairs at 512², seed 0).
    let pixel_seed = hash_combine(morton_encode(pixel), seed);
    let slot_seed = hash_combine(pixel_seed, dimension);
    let shuffled = nested_uniform_scramble(sample_index, hash_combine(slot_seed, 0));
    scrambled_sobol_2d(shuffled, slot_seed)
}

/// Independent uniform bits: pcg3d of the pixel and seed, then of (that, sample, dimension). For a
/// fixed pixel the second input is injective in (sample, dimension).
fn independent_bits(seed: u32, pixel: UVec2, sample_index: u32, dimension: u32) -> UVec2 {
    let pixel_hash = pcg3d(UVec3::new(pixel.x, pixel.y, seed));
    let bits = pcg3d(UVec3::new(pixel_hash.x ^ sample_index, pixel_hash.y ^ dimension, pixel_hash.z));
    UVec2::new(bits.x, bits.y)
}

/// Interleaves the low 16 bits of `x` (even bits) and `y` (odd bits).
pub fn morton_encode(pixel: UVec2) -> u32 {
    spread_bits(pixel.x) | (spread_bits(pixel.y) << 1)
}

/// Spreads the low 16 bits of `v` to the even bit positions.
fn spread_bits(v: u32) -> u32 {
    let mut x = v & 0x0000_ffff;
    x = (x | (x << 8)) & 0x00ff_00ff;
    x = (x | (x << 4)) & 0x0f0f_0f0f;
    x = (x | (x << 2)) & 0x3333_3333;
    x = (x | (x << 1)) & 0x5555_5555;
    x
}

/// The 24 permutations of `{0, 1, 2, 3}` in lexicographic order, one byte each (entry `d` of
/// permutation `p` in bits `2d..2d+2` of byte `p mod 4` of word `p / 4`): a table packed into
/// six constants. Regenerate with `itertools.permutations(range(4))`; the test
/// `permutations_of_four_digits_are_lexicographic` checks it.
const BASE4_PERMUTATIONS: [u32; 6] = [0x78d8_b4e4, 0xb1e1_6c9c, 0x2d8d_39c9, 0x36c6_72d2, 0x6393_1e4e, 0x1b4b_2787];

/// Permutation `b mod 24` of `{0, 1, 2, 3}` for a byte `b` (0..256) — how ZSobol picks a digit's
/// permutation from a hash's top byte — as one byte whose bits `2d..2d+2` hold entry `d`. On the
/// CPU one load from [`DIGIT_PERMUTATION_BY_BYTE`]: `zsobol_index` calls this once per base-4
/// digit, and the table spares it the `mod 24` and the word and byte selection; SPIR-V selects the
/// word by comparisons instead (`base4_permutation_word_by_selects`, built for SPIR-V and tests).
#[cfg(not(target_arch = "spirv"))]
fn digit_permutation(b: u32) -> u32 {
    DIGIT_PERMUTATION_BY_BYTE[(b & 0xff) as usize] as u32
}

/// [`digit_permutation`] in the SPIR-V build.
#[cfg(target_arch = "spirv")]
fn digit_permutation(b: u32) -> u32 {
    digit_permutation_by_selects(b)
}

/// [`digit_permutation`] without a dynamically indexed array: in SPIR-V one becomes a
/// function-local copy in memory, while this chain compiles to selects between constants. The
/// CPU build tests it against the table.
#[cfg(any(target_arch = "spirv", test))]
fn digit_permutation_by_selects(b: u32) -> u32 {
    let p = b % 24;
    (base4_permutation_word_by_selects(p) >> (8 * (p % 4))) & 0xff
}

/// [`digit_permutation`] for every byte, built at compile time from [`BASE4_PERMUTATIONS`].
#[cfg(not(target_arch = "spirv"))]
const DIGIT_PERMUTATION_BY_BYTE: [u8; 256] = {
    let mut table = [0u8; 256];
    let mut b = 0usize;
    while b < 256 {
        let p = b % 24;
        table[b] = (BASE4_PERMUTATIONS[p / 4] >> (8 * (p % 4))) as u8;
        b += 1;
    }
    table
};

/// Word `min(p / 4, 5)` of `BASE4_PERMUTATIONS`, by comparisons (see
/// [`digit_permutation_by_selects`]).
#[cfg(any(target_arch = "spirv", test))]
fn base4_permutation_word_by_selects(p: u32) -> u32 {
    if p < 4 {
        BASE4_PERMUTATIONS[0]
    } else if p < 8 {
        BASE4_PERMUTATIONS[1]
    } else if p < 12 {
        BASE4_PERMUTATIONS[2]
    } else if p < 16 {
        BASE4_PERMUTATIONS[3]
    } else if p < 20 {
        BASE4_PERMUTATIONS[4]
    } else {
        BASE4_PERMUTATIONS[5]
    }
}

/// The ZSobol index of `(pixel, sample_index)`: the Morton code with the sample index below it,
/// its base-4 digits permuted from the most significant down, each by a permutation chosen by a
/// hash of the digits above it, the dimension and the seed. When the samples per pixel are a power
/// of 2 but not of 4, the lowest bit is flipped by a hash of the bits above it instead.
pub fn zsobol_index(params: &SamplerParams, pixel: UVec2, sample_index: u32, dimension: u32) -> u32 {
    let spp_log2 = params.spp_log2.min(31);
    let morton = (morton_encode(pixel) << spp_log2) | sample_index;
    let odd = spp_log2 & 1;
    let digits = params.resolution_log2.min(16) + spp_log2.div_ceil(2);
    let salt = hash_combine(params.seed, dimension);
    let mut index = 0u32;
    let mut i = digits;
    while i > odd {
        i -= 1;
        let shift = 2 * i - odd;
        if shift < 32 {
            let digit = (morton >> shift) & 3;
            let higher = if shift + 2 < 32 { morton >> (shift + 2) } else { 0 };
            let permutation = digit_permutation(mix_bits(higher ^ salt) >> 24);
            index |= ((permutation >> (2 * digit)) & 3) << shift;
        }
    }
    if odd == 1 {
        index |= (morton & 1) ^ (mix_bits((morton >> 1) ^ salt) & 1);
    }
    index
}

/// ZSobol: the scrambled Sobol' point at the permuted Morton index; the scramble depends on the
/// dimension and seed only, so the image shares one sequence.
fn zsobol_bits(params: &SamplerParams, pixel: UVec2, sample_index: u32, dimension: u32) -> UVec2 {
    let index = zsobol_index(params, pixel, sample_index, dimension);
    scrambled_sobol_2d(index, hash_combine(mix_bits(params.seed), dimension))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hash::ONE_MINUS_EPSILON;

    fn params(kind: u32, spp_log2: u32) -> SamplerParams {
        SamplerParams { kind, seed: 7, spp_log2, resolution_log2: 5 }
    }

    /// Asserts that the first `2^m` samples of (pixel, dimension) form a (0,m,2)-net.
    fn assert_net(p: &SamplerParams, pixel: UVec2, dimension: u32, m: u32) {
        for row_bits in 0..=m {
            let col_bits = m - row_bits;
            let mut seen = std::vec![false; 1 << m];
            for i in 0..(1u32 << m) {
                let b = sample_bits(p, pixel, i, dimension);
                let x = if col_bits == 0 { 0 } else { b.x >> (32 - col_bits) };
                let y = if row_bits == 0 { 0 } else { b.y >> (32 - row_bits) };
                let cell = ((y << col_bits) | x) as usize;
                assert!(!seen[cell], "kind {} pixel {pixel} dim {dimension}: 2^{col_bits}x2^{row_bits}", p.kind);
                seen[cell] = true;
            }
        }
    }

    #[test]
    fn sobol_samples_of_every_slot_are_nets() {
        for m in 0..=8 {
            let p = params(sampler_kind::SOBOL, m);
            for dimension in [0, 1, 5, 31] {
                for pixel in [UVec2::new(0, 0), UVec2::new(3, 9), UVec2::new(31, 31)] {
                    assert_net(&p, pixel, dimension, m);
                }
            }
        }
    }

    #[test]
    fn zsobol_samples_of_every_pixel_are_nets() {
        // With 2^m samples per pixel, a pixel's samples are an aligned block of the permuted
        // Sobol' index space (the digits below the pixel's code), hence a (0,m,2)-net.
        for m in 0..=8 {
            let p = params(sampler_kind::ZSOBOL, m);
            for dimension in [0, 1, 5] {
                for pixel in [UVec2::new(0, 0), UVec2::new(3, 9), UVec2::new(31, 31)] {
                    assert_net(&p, pixel, dimension, m);
                }
            }
        }
    }

    #[test]
    fn zsobol_pixels_of_an_aligned_square_form_a_net_at_one_sample() {
        // At 1 spp the 2^k × 2^k pixels of an aligned square share one aligned index block:
        // their samples are jointly stratified, which is what makes the error blue.
        let p = params(sampler_kind::ZSOBOL, 0);
        for (origin, k) in [(UVec2::new(0, 0), 2u32), (UVec2::new(8, 4), 2), (UVec2::new(16, 16), 3)] {
            let m = 2 * k;
            for row_bits in 0..=m {
                let col_bits = m - row_bits;
                let mut seen = std::vec![false; 1 << m];
                for dy in 0..(1u32 << k) {
                    for dx in 0..(1u32 << k) {
                        let b = sample_bits(&p, origin + UVec2::new(dx, dy), 0, 3);
                        let x = if col_bits == 0 { 0 } else { b.x >> (32 - col_bits) };
                        let y = if row_bits == 0 { 0 } else { b.y >> (32 - row_bits) };
                        let cell = ((y << col_bits) | x) as usize;
                        assert!(!seen[cell], "square at {origin} size {k}: 2^{col_bits}x2^{row_bits}");
                        seen[cell] = true;
                    }
                }
            }
        }
    }

    #[test]
    fn the_cpu_and_spirv_digit_permutations_agree() {
        for b in 0..256 {
            assert_eq!(digit_permutation(b), digit_permutation_by_selects(b), "byte {b}");
        }
    }

    #[test]
    fn permutations_of_four_digits_are_lexicographic() {
        // Every entry is a permutation of 0..4, and each is the lexicographic successor of the
        // one before: the 24 permutations in order, each once.
        let perms: std::vec::Vec<[u32; 4]> =
            (0..24).map(|p| core::array::from_fn(|d| (digit_permutation(p) >> (2 * d)) & 3)).collect();
        for (p, perm) in perms.iter().enumerate() {
            let mut sorted = *perm;
            sorted.sort();
            assert_eq!(sorted, [0, 1, 2, 3], "permutation {p}: {perm:?}");
        }
        assert_eq!(perms[0], [0, 1, 2, 3]);
        assert!(perms.windows(2).all(|w| w[0] < w[1]), "{perms:?}");
    }

    #[test]
    fn zsobol_index_is_a_bijection_on_the_sample_space() {
        for spp_log2 in [0u32, 1, 2, 3] {
            let p = SamplerParams { kind: sampler_kind::ZSOBOL, seed: 3, spp_log2, resolution_log2: 3 };
            let mut seen = std::collections::BTreeSet::new();
            for y in 0..8 {
                for x in 0..8 {
                    for s in 0..(1u32 << spp_log2) {
                        let index = zsobol_index(&p, UVec2::new(x, y), s, 2);
                        assert!(index < (64 << spp_log2), "index {index} out of range");
                        assert!(seen.insert(index), "spp 2^{spp_log2}: duplicate {index}");
                    }
                }
            }
        }
    }

    /// The largest fields (`spp_log2` = 31, `resolution_log2` = 16) with extreme pixels, samples
    /// and dimensions draw without a shift overflowing, which panics in test builds (overflow
    /// checks on). The range assertion only restates `unit_float`'s construction.
    #[test]
    fn extreme_sampler_fields_and_indices_draw_without_a_shift_overflow() {
        for kind in 0..sampler_kind::COUNT {
            let p = SamplerParams { kind, seed: u32::MAX, spp_log2: 31, resolution_log2: 16 };
            for pixel in [UVec2::ZERO, UVec2::splat(u32::MAX), UVec2::new(65_535, 65_535)] {
                for i in [0u32, 1, u32::MAX] {
                    for d in [0u32, u32::MAX] {
                        let u = sample_2d(&p, pixel, i, d);
                        assert!(u.x <= ONE_MINUS_EPSILON && u.y <= ONE_MINUS_EPSILON && u.min_element() >= 0.0);
                    }
                }
            }
        }
    }

    #[test]
    fn slots_and_seeds_decorrelate() {
        // The correlation between two slots (and between two seeds) of the same samples is ~0.
        for kind in 0..sampler_kind::COUNT {
            let a = params(kind, 8);
            let b = SamplerParams { seed: 8, ..a };
            let n = 4096u32;
            let mut cross_slot = 0.0f64;
            let mut cross_seed = 0.0f64;
            for i in 0..n {
                let pixel = UVec2::new(i % 16, i / 256);
                let s = i % 256;
                let u0 = sample_2d(&a, pixel, s, 0).x as f64 - 0.5;
                let u1 = sample_2d(&a, pixel, s, 1).x as f64 - 0.5;
                let v0 = sample_2d(&b, pixel, s, 0).x as f64 - 0.5;
                cross_slot += u0 * u1;
                cross_seed += u0 * v0;
            }
            // Uniform variance 1/12; σ of the mean product ≈ (1/12)/√n = 0.0013: 5σ.
            assert!((cross_slot / n as f64).abs() < 0.0065, "kind {kind}: slot correlation");
            assert!((cross_seed / n as f64).abs() < 0.0065, "kind {kind}: seed correlation");
        }
    }

    /// No two pixels of a 512² image share their samples, with any sampler: the per-pixel Sobol'
    /// sampler had seeded pixels by a 32-bit hash, and 11 pairs (seed 0; (75, 10) and (157, 34)
    /// the first) drew the same samples in every slot.
    #[test]
    fn no_two_pixels_share_their_samples() {
        for kind in 0..sampler_kind::COUNT {
            let p = SamplerParams { kind, seed: 0, spp_log2: 2, resolution_log2: 9 };
            let mut seen = std::collections::HashSet::new();
            for (x, y) in (0..512).flat_map(|y| (0..512).map(move |x| (x, y))) {
                let pixel = UVec2::new(x, y);
                let samples: [UVec2; 4] = core::array::from_fn(|s| sample_bits(&p, pixel, s as u32, 0));
                assert!(seen.insert(samples), "kind {kind}: ({x}, {y}) draws another pixel's samples");
            }
        }
    }

    /// Across the 32 × 32 pixels of an image, each of a pixel's first two samples falls in the
    /// lower half of [0, 1) for about half the pixels, in every dimension and either coordinate,
    /// at every sample count, odd powers of 2 included. There the lowest digit of the index is a
    /// single bit, scrambled like the others by a hash of the digits above it (pbrt-v4's
    /// `ZSobolSampler`); left unscrambled it is the sample index's lowest bit, which is the first
    /// Sobol' point's top bit in both coordinates — every pixel's sample 0 in the same half of
    /// every dimension's square, the same half of every light for the whole frame. Binomial(1024,
    /// ½) has σ = 16: the test allows 5σ.
    #[test]
    fn zsobol_samples_are_balanced_across_pixels_at_every_sample_count() {
        for spp_log2 in 0..=5 {
            let p = params(sampler_kind::ZSOBOL, spp_log2);
            for dimension in [0u32, 1, 4] {
                for s in [0u32, 1].into_iter().filter(|&s| s < 1 << spp_log2) {
                    let mut lower = [0u32; 2];
                    for y in 0..32 {
                        for x in 0..32 {
                            let u = sample_2d(&p, UVec2::new(x, y), s, dimension);
                            lower[0] += u32::from(u.x < 0.5);
                            lower[1] += u32::from(u.y < 0.5);
                        }
                    }
                    for count in lower {
                        assert!(
                            count.abs_diff(512) < 80,
                            "spp 2^{spp_log2}, dim {dimension}, sample {s}: {count} of 1024"
                        );
                    }
                }
            }
        }
    }
}
