//! Radially averaged power spectra of error images: the evidence that a sampler distributes its
//! error as blue noise (little power at low spatial frequencies) rather than white noise (flat).

use rustfft::num_complex::Complex;
use rustfft::FftPlanner;

/// Accumulates the 2-D power spectrum `|DFT(e)|²` of square error images and averages it over
/// rings of equal spatial frequency.
pub struct PowerSpectrum {
    side: usize,
    power: Vec<f64>,
}

impl PowerSpectrum {
    /// An empty accumulator for `side × side` images. Panics if `side` < 2: a 1 × 1 image has no
    /// frequency but DC, so there is no spectrum to average (the reports hold images to ≥ 4).
    pub fn new(side: usize) -> Self {
        assert!(side >= 2, "a power spectrum needs images of at least 2 × 2 pixels, not {side} × {side}");
        Self { side, power: vec![0.0; side * side] }
    }

    /// Adds the spectrum of one row-major `side × side` error image (its mean is removed first,
    /// so the DC term does not dominate). Panics if `error` does not hold `side²` values.
    pub fn add(&mut self, error: &[f64]) {
        let n = self.side;
        assert_eq!(error.len(), n * n, "PowerSpectrum::add: not a {n} × {n} image");
        let mean = error.iter().sum::<f64>() / error.len() as f64;
        let mut data: Vec<Complex<f64>> = error.iter().map(|&e| Complex::new(e - mean, 0.0)).collect();
        let fft = FftPlanner::new().plan_fft_forward(n);
        for row in data.chunks_mut(n) {
            fft.process(row);
        }
        let mut column = vec![Complex::new(0.0, 0.0); n];
        for x in 0..n {
            for y in 0..n {
                column[y] = data[y * n + x];
            }
            fft.process(&mut column);
            for y in 0..n {
                data[y * n + x] = column[y];
            }
        }
        for (p, d) in self.power.iter_mut().zip(&data) {
            *p += d.norm_sqr();
        }
    }

    /// Mean power in each ring `r = round(|k|)` for `r = 0 ..= side/2` (frequencies in cycles
    /// per image), normalised by the mean power over all non-DC frequencies, so white noise is
    /// ≈ 1 at every radius.
    pub fn radial_average(&self) -> Vec<f64> {
        let n = self.side as i64;
        let half = (n / 2) as usize;
        let mut sums = vec![0.0; half + 1];
        let mut counts = vec![0u32; half + 1];
        for y in 0..n {
            for x in 0..n {
                let kx = if x <= n / 2 { x } else { x - n };
                let ky = if y <= n / 2 { y } else { y - n };
                let r = ((kx * kx + ky * ky) as f64).sqrt().round() as usize;
                if r <= half {
                    sums[r] += self.power[(y * n + x) as usize];
                    counts[r] += 1;
                }
            }
        }
        let non_dc: f64 = self.power.iter().skip(1).sum::<f64>() / (self.power.len() - 1).max(1) as f64;
        sums.iter()
            .zip(&counts)
            .map(|(&s, &c)| if c == 0 { 0.0 } else { s / f64::from(c) / non_dc.max(1e-300) })
            .collect()
    }

    /// Mean normalised power of the lowest frequencies, rings `1 ..= max(1, side/8)` — up to
    /// about ⅛ cycle per pixel (ring 1 alone below a side of 16): ≈ 1 for white noise, well
    /// below 1 for blue noise.
    pub fn low_frequency_power(&self) -> f64 {
        let radial = self.radial_average();
        let top = (self.side / 8).max(1);
        radial[1..=top].iter().sum::<f64>() / top as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn white_noise_is_flat_and_a_checkerboard_is_all_high_frequency() {
        let side = 32;
        let mut white = PowerSpectrum::new(side);
        let mut state = 12345u64;
        for _ in 0..64 {
            let image: Vec<f64> = (0..side * side)
                .map(|_| {
                    state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
                })
                .collect();
            white.add(&image);
        }
        let low = white.low_frequency_power();
        assert!((low - 1.0).abs() < 0.2, "white noise low-frequency power {low}");
        let mut checker = PowerSpectrum::new(side);
        checker.add(
            &(0..side * side).map(|i| if (i % side + i / side) % 2 == 0 { 1.0 } else { -1.0 }).collect::<Vec<_>>(),
        );
        assert!(checker.low_frequency_power() < 1e-9);
    }

    /// A cosine of `k` cycles along x or y puts its power in ring `k` alone, on an odd and an
    /// even side, up to the Nyquist ring of the even one (the checkerboard's power lies at
    /// |k| = side/√2, outside every ring, so it does not test the binning).
    #[test]
    fn a_cosine_lands_in_the_ring_of_its_frequency() {
        for (side, k) in [(9usize, 2usize), (9, 4), (32, 3), (32, 16)] {
            for along_y in [false, true] {
                let mut spectrum = PowerSpectrum::new(side);
                let image: Vec<f64> = (0..side * side)
                    .map(|i| {
                        let coordinate = if along_y { i / side } else { i % side };
                        (std::f64::consts::TAU * (k * coordinate) as f64 / side as f64).cos()
                    })
                    .collect();
                spectrum.add(&image);
                let radial = spectrum.radial_average();
                assert_eq!(radial.len(), side / 2 + 1);
                for (ring, &power) in radial.iter().enumerate() {
                    assert_eq!(power > 1e-6, ring == k, "side {side}, k {k}, ring {ring}: {power}");
                }
            }
        }
    }
}
