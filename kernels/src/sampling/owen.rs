//! Hash-based Owen scrambling (Burley 2020, "Practical Hash-based Owen Scrambling", JCGT 9(4)).
//!
//! A nested uniform (Owen) scramble flips each bit of a value depending on a random function of
//! all the more significant bits. Burley's observation: a Laine–Karras style hash applied to the
//! *bit-reversed* value does exactly that (each bit of a product depends only on lower bits), so a
//! scramble is two bit reversals around a few multiplies. The same scramble shuffles sample
//! indices: it maps every aligned block of `2^k` indices onto an aligned block of `2^k` indices,
//! so a shuffled prefix of a (0,2)-sequence is still a (0,k,2)-net.

/// The improved Laine–Karras hash on bit-reversed values, whose bit `i` depends only on bits
/// `0..=i` of `x`. Constants from the Psychopath blog post of 2021-01-30 as updated on
/// 2021-05-08, the same as pbrt-v4's `FastOwenScrambler` and Blender Cycles' `reversed_bit_owen`
/// [sampling-denoise.md §1.1, §1.3].
pub fn laine_karras_permutation(mut x: u32, seed: u32) -> u32 {
    x ^= x.wrapping_mul(0x3d20_adea);
    x = x.wrapping_add(seed);
    x = x.wrapping_mul((seed >> 16) | 1);
    x ^= x.wrapping_mul(0x0552_6c56);
    x ^= x.wrapping_mul(0x53a2_2864);
    x
}

/// Nested uniform scramble of `x` with `seed`: each bit is flipped by a pseudo-random function of
/// `seed` and the bits above it. A bijection on `u32` that maps aligned blocks to aligned blocks.
pub fn nested_uniform_scramble(x: u32, seed: u32) -> u32 {
    laine_karras_permutation(x.reverse_bits(), seed).reverse_bits()
}

/// A 32-bit integer finalizer (the "lowbias32" hash of Chris Wellons' hash-prospector, bias
/// 0.17), used to derive independent seeds from (seed, dimension) pairs.
pub fn mix_bits(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// Combines two values into one well-mixed seed (order matters).
pub fn hash_combine(a: u32, b: u32) -> u32 {
    mix_bits(a ^ mix_bits(b).wrapping_add(0x9e37_79b9))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scramble_is_a_bijection_on_small_prefixes() {
        // Indices 0..2^k map onto one aligned block of 2^k values (bits ≥ k only depend on bits
        // above them, which are 0 for every index of the prefix).
        for seed in [0u32, 1, 0xdead_beef, 0x1234_5678] {
            for k in 0..=10u32 {
                let mut seen = std::vec![false; 1 << k];
                let base = nested_uniform_scramble(0, seed) >> k;
                for i in 0..(1u32 << k) {
                    let s = nested_uniform_scramble(i, seed);
                    assert_eq!(s >> k, base, "seed {seed:#x} k {k}: block changed");
                    let low = (s & ((1u32 << k).wrapping_sub(1))) as usize;
                    let low = if k == 0 { 0 } else { low };
                    assert!(!seen[low], "seed {seed:#x} k {k}: {i} collides");
                    seen[low] = true;
                }
            }
        }
    }

    #[test]
    fn scramble_flips_each_bit_about_half_the_time_over_seeds() {
        // Over many seeds, every output bit of a fixed input is 1 about half of the time.
        let mut ones = [0u32; 32];
        const SEEDS: u32 = 4096;
        for s in 0..SEEDS {
            let v = nested_uniform_scramble(0x0f0f_1234, mix_bits(s));
            for (b, count) in ones.iter_mut().enumerate() {
                *count += (v >> b) & 1;
            }
        }
        for (b, &count) in ones.iter().enumerate() {
            // Binomial(4096, 1/2): σ = 32; 5σ.
            assert!((count as i32 - 2048).abs() < 160, "bit {b}: {count}");
        }
    }
}
