//! The first two dimensions of the Sobol' sequence as 32×32 binary generator matrices.
//!
//! Together they form a (0,2)-sequence in base 2: every aligned block of `2^m` consecutive points
//! is a (0,m,2)-net, stratified in every elementary interval of area `2^-m`. raywave only uses this
//! 2-D pair and pads to higher dimensions by independent per-dimension shuffles and scrambles
//! (as pbrt-v4's `PaddedSobolSampler` and `ZSobolSampler` do) [sampling-denoise.md §1.2].

/// Sobol' dimension 0 of `index` as a 32-bit fraction: the van der Corput radical inverse, i.e.
/// the bit-reversed index.
pub fn sobol_dimension_0(index: u32) -> u32 {
    index.reverse_bits()
}

/// Sobol' dimension 1 of `index` as a 32-bit fraction: the XOR of the generator-matrix columns
/// selected by the set bits of `index`. The columns (direction numbers) of the primitive
/// polynomial `x + 1` with `m₁ = 1` follow `v₁ = 2³¹`, `vₖ₊₁ = vₖ ⊕ (vₖ >> 1)` (the recurrence
/// `mₖ = 2mₖ₋₁ ⊕ mₖ₋₁` of Bratley & Fox 1988 shifted into place), so they are generated on the
/// fly: no table to keep in sync, and no array for the SPIR-V build to index.
pub fn sobol_dimension_1(index: u32) -> u32 {
    let mut result = 0u32;
    let mut bits = index;
    let mut direction = 1u32 << 31;
    while bits != 0 {
        if bits & 1 != 0 {
            result ^= direction;
        }
        bits >>= 1;
        direction ^= direction >> 1;
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_points_match_the_published_sequence() {
        // Sobol' dimension 1 (Joe & Kuo's second dimension) in natural (not Gray-code) order.
        let expected = [0.0, 0.5, 0.75, 0.25, 0.625, 0.125, 0.375, 0.875];
        for (i, &e) in expected.iter().enumerate() {
            assert_eq!(sobol_dimension_1(i as u32) as f64 / 4_294_967_296.0, e, "index {i}");
        }
        let vdc = [0.0, 0.5, 0.25, 0.75, 0.125, 0.625, 0.375, 0.875];
        for (i, &e) in vdc.iter().enumerate() {
            assert_eq!(sobol_dimension_0(i as u32) as f64 / 4_294_967_296.0, e, "index {i}");
        }
    }

    #[test]
    fn aligned_blocks_are_zero_m_two_nets() {
        // Every elementary interval of area 2^-m holds exactly one point of each aligned block.
        for m in 0..=10u32 {
            for block in [0u32, 1, 7, 1000] {
                for row_bits in 0..=m {
                    let col_bits = m - row_bits;
                    let mut seen = std::vec![false; 1 << m];
                    for i in 0..(1u32 << m) {
                        let index = (block << m) | i;
                        let x = if col_bits == 0 { 0 } else { sobol_dimension_0(index) >> (32 - col_bits) };
                        let y = if row_bits == 0 { 0 } else { sobol_dimension_1(index) >> (32 - row_bits) };
                        let cell = ((y << col_bits) | x) as usize;
                        assert!(!seen[cell], "m {m} block {block} intervals 2^{col_bits}x2^{row_bits}");
                        seen[cell] = true;
                    }
                }
            }
        }
    }
}
