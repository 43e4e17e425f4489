//! Counter-based hashing: random numbers as a pure function of (index, sample, seed), so every
//! backend produces bit-identical values with no state to carry between dispatches.

use glam::UVec3;

/// Largest value [`unit_float`] returns: 1 − 2⁻²⁴, the largest `f32` below 1. Samples must stay
/// strictly below 1 so warps such as `floor(u · n)` never index past their range.
pub const ONE_MINUS_EPSILON: f32 = 1.0 - 1.0 / 16_777_216.0;

/// The `pcg3d` hash of Jarzynski & Olano, "Hash Functions for GPU Rendering", JCGT 9(3), 2020:
/// one LCG step on each component, a round of cross-multiplication (each component plus the
/// product of the other two), a `>> 16` xorshift of each, and a second round of
/// cross-multiplication, which together mix all three inputs into all three outputs. Chosen there
/// as the best quality/speed trade-off for 3-D inputs.
pub fn pcg3d(v: UVec3) -> UVec3 {
    // LCG constants from Numerical Recipes, as in the paper.
    let mut x = v.x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
    let mut y = v.y.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
    let mut z = v.z.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
    x = x.wrapping_add(y.wrapping_mul(z));
    y = y.wrapping_add(z.wrapping_mul(x));
    z = z.wrapping_add(x.wrapping_mul(y));
    x ^= x >> 16;
    y ^= y >> 16;
    z ^= z >> 16;
    x = x.wrapping_add(y.wrapping_mul(z));
    y = y.wrapping_add(z.wrapping_mul(x));
    z = z.wrapping_add(x.wrapping_mul(y));
    UVec3::new(x, y, z)
}

/// Maps 32 random bits to a float in `[0, 1 − 2⁻²⁴]`, using the top 24 bits so every value is
/// exactly representable and the mapping is bit-identical on every backend.
pub fn unit_float(bits: u32) -> f32 {
    (bits >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// A deterministic stream of uniform floats in `[0, 1 − 2⁻²⁴]`: [`pcg3d`] of a counter and a
/// seed. For host-side tools and tests that need many reproducible random values; kernels draw
/// from the samplers instead, which are pure functions of (pixel, sample, dimension). Not part
/// of the SPIR-V build.
#[cfg(not(target_arch = "spirv"))]
#[derive(Clone, Debug)]
pub struct CounterRng {
    seed: u32,
    counter: u32,
}

#[cfg(not(target_arch = "spirv"))]
impl CounterRng {
    /// A stream seeded `seed`; different seeds give independent streams.
    pub fn new(seed: u32) -> Self {
        Self { seed, counter: 0 }
    }

    /// The next float in `[0, 1 − 2⁻²⁴]`.
    pub fn next_f32(&mut self) -> f32 {
        self.counter = self.counter.wrapping_add(1);
        unit_float(pcg3d(UVec3::new(self.counter, self.seed, 0x6c67)).x)
    }

    /// The next float in `[lo, hi]`: `lo + (hi − lo)·u` with `u ≤ 1 − 2⁻²⁴` can still round to
    /// `hi` (0.5 + 1.0·(1 − 2⁻²⁴) is 1.5 in `f32`), so callers that need `hi` excluded must not
    /// rely on it.
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next_f32()
    }

    /// A vector with each component uniform in `[lo, hi]` (see [`Self::range`]).
    pub fn vec3(&mut self, lo: f32, hi: f32) -> glam::Vec3 {
        glam::Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }

    /// A uniformly distributed unit vector (rejection from the cube).
    pub fn unit_vec3(&mut self) -> glam::Vec3 {
        loop {
            let v = self.vec3(-1.0, 1.0);
            let len2 = v.length_squared();
            if len2 > 1e-3 && len2 <= 1.0 {
                return v / len2.sqrt();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_float_covers_the_half_open_interval() {
        assert_eq!(unit_float(0), 0.0);
        assert_eq!(unit_float(u32::MAX), ONE_MINUS_EPSILON);
        assert!(unit_float(u32::MAX) < 1.0);
    }

    #[test]
    fn pcg3d_is_deterministic_and_mixes_every_input() {
        let base = pcg3d(UVec3::new(1, 2, 3));
        assert_eq!(base, pcg3d(UVec3::new(1, 2, 3)));
        for changed in [UVec3::new(2, 2, 3), UVec3::new(1, 3, 3), UVec3::new(1, 2, 4)] {
            let other = pcg3d(changed);
            // A small change of one input (1 to 3 bits) flips about half of the 96 output bits.
            let flipped = (base ^ other).to_array().iter().map(|w| w.count_ones()).sum::<u32>();
            assert!((30..=66).contains(&flipped), "{changed}: {flipped} bits flipped");
        }
    }

    #[test]
    fn pcg3d_floats_are_uniform() {
        // 64 bins over 2^16 draws: chi-square with 63 dof; 110 is its 0.9998 quantile.
        const BINS: usize = 64;
        const DRAWS: u32 = 1 << 16;
        let mut counts = [0u32; BINS];
        for i in 0..DRAWS {
            let u = unit_float(pcg3d(UVec3::new(i, 0, 7)).x);
            counts[(u * BINS as f32) as usize] += 1;
        }
        let expected = DRAWS as f32 / BINS as f32;
        let chi2: f32 = counts.iter().map(|&c| (c as f32 - expected).powi(2) / expected).sum();
        assert!(chi2 < 110.0, "chi-square {chi2}");
    }
}
