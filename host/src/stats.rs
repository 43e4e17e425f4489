//! Statistical tests for the sampling code: chi-square goodness of fit of warped samples against
//! the pdf that is supposed to describe them.
//!
//! The method follows Mitsuba 3's `ChiSquareTest` (`mitsuba/python/chi2.py`) and pbrt-v4's warp
//! tests (`src/pbrt/util/sampling_test.cpp`): the domain is cut into cells, the samples are counted
//! per cell, the expected count of a cell is `N·∫cell pdf` (integrated numerically in `f64` on a
//! `SUBDIVISIONS × SUBDIVISIONS` sub-grid with the 2-point Gauss–Legendre rule per sub-cell and
//! axis, see [`SUBDIVISIONS`]), cells expecting fewer than
//! [`MIN_EXPECTED`] samples are pooled, and Pearson's statistic `Σ (O − E)²/E` is compared with
//! the χ² distribution with `cells − 1` degrees of freedom (statrs). A warp and its pdf agree when
//! the p-value is not tiny (the warp tests reject below a Šidák-corrected threshold over all their
//! domains, at fixed seeds), and the summed cell
//! integrals (`pdf_integral`) must be ≈ 1.
//!
//! Two domains: the unit sphere, cut into equal-area cells in `(cos θ, φ)`
//! ([`chi_square_sphere`]), and the unit square ([`chi_square_unit_square`]) for 2-D warps or
//! for directions mapped to local coordinates of a cone, a cap or a light.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Cells whose expected count is below this are pooled into one (the usual rule of thumb for the
/// χ² approximation of Pearson's statistic; Mitsuba uses the same value).
pub const MIN_EXPECTED: f64 = 5.0;

/// Default sub-grid resolution per cell and axis for integrating the pdf over a cell. Each
/// sub-interval uses the 2-point Gauss–Legendre rule (nodes at `mid ± h/(2√3)`): exact for cubics,
/// so a smooth but narrow lobe (GGX at α = 0.05) integrates to ~10⁻⁵ where the midpoint rule
/// leaves ~10⁻³ per cell — which a cell expecting 10⁵ samples notices. Like the midpoint rule it
/// never evaluates the pdf on a cell border, where pdfs have their discontinuities and
/// singularities. `(2·SUBDIVISIONS)²` evaluations per cell.
pub const SUBDIVISIONS: u32 = 8;

/// Result of a chi-square goodness-of-fit test.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ChiSquare {
    /// Pearson's statistic `Σ (O − E)²/E` over the cells after pooling.
    pub statistic: f64,
    /// Degrees of freedom: cells after pooling − 1.
    pub dof: u32,
    /// Probability that a χ² variable with `dof` degrees of freedom exceeds `statistic`
    /// (`1 − CDF`); small values reject the hypothesis that the samples follow the pdf. 0 where
    /// the statistic is infinite (samples in a cell, or pool, that expects none), and NaN where
    /// pooling left a single cell (`dof` 0), an expected count is negative or not finite (a NaN
    /// pdf) or the counts and expectations differ in number: the counts cannot test the pdf, so
    /// a check `p_value > α` fails rather than passing.
    pub p_value: f64,
    /// Integral of the pdf over the domain: the summed cell integrals (≈ 1 for a normalized pdf
    /// whose support lies in the domain).
    pub pdf_integral: f64,
    /// Samples that fell outside the domain (not finite, zero length, outside `[0,1]²`); they are
    /// not counted in any cell while the expected counts take `N` with them, which inflates the
    /// statistic, so callers should assert that there are none.
    pub outside: u64,
    /// Samples in cells whose integrated pdf is exactly 0. They join the pool of small cells;
    /// callers decide how many are plausible: a cell that a support boundary crosses may get 0
    /// from the sub-grid although a sliver of it has positive density, so a few such samples
    /// near a discontinuity of the pdf are expected, while many mean the warp produces samples
    /// where its pdf is 0.
    pub zero_expected_samples: u64,
}

impl core::fmt::Display for ChiSquare {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "χ² = {:.1}, dof = {}, p = {:.3e}, ∫pdf = {:.6}, outside = {}, in zero cells = {}",
            self.statistic, self.dof, self.p_value, self.pdf_integral, self.outside, self.zero_expected_samples
        )
    }
}

/// Observed and expected counts per cell of a domain.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Histogram {
    /// Samples counted per cell.
    pub observed: Vec<u64>,
    /// `N·∫cell pdf` per cell.
    pub expected: Vec<f64>,
    /// Samples outside the domain.
    pub outside: u64,
    /// `∫domain pdf` (= Σ expected / N).
    pub pdf_integral: f64,
}

impl Histogram {
    /// The chi-square test of this histogram ([`chi_square_counts`]), with its integral and
    /// outside count.
    pub fn test(&self) -> ChiSquare {
        let fit = chi_square_counts(&self.observed, &self.expected);
        ChiSquare { pdf_integral: self.pdf_integral, outside: self.outside, ..fit }
    }
}

/// Pearson's chi-square test of `observed` counts against `expected` counts (same length, else
/// the p-value is NaN),
/// pooling cells with expected counts below [`MIN_EXPECTED`]: cells are taken in increasing
/// order of expectation and merged until the pool reaches [`MIN_EXPECTED`]; a final pool still
/// below it is merged into the first cell kept (the first pool, or else the smallest cell). Cells expecting exactly 0 add their samples to
/// the pool and count them in `zero_expected_samples` (see there); empty ones are ignored.
/// `pdf_integral` is `Σ expected / Σ observed` and `outside` is 0. See
/// [`ChiSquare::p_value`] for a statistic that is infinite or a single cell left.
pub fn chi_square_counts(observed: &[u64], expected: &[f64]) -> ChiSquare {
    let total: u64 = observed.iter().sum();
    let expected_total: f64 = expected.iter().sum();
    let pdf_integral = if total > 0 { expected_total / total as f64 } else { 0.0 };
    let mut order: Vec<usize> = (0..observed.len().min(expected.len())).collect();
    order.sort_by(|&a, &b| expected[a].total_cmp(&expected[b]));

    let mut cells: Vec<(f64, f64)> = Vec::with_capacity(order.len());
    let (mut pool_o, mut pool_e) = (0.0f64, 0.0f64);
    let mut zero_expected_samples = 0;
    for &i in &order {
        let (o, e) = (observed[i] as f64, expected[i]);
        if e == 0.0 {
            zero_expected_samples += observed[i];
            pool_o += o;
            continue;
        }
        if e < MIN_EXPECTED {
            pool_o += o;
            pool_e += e;
            if pool_e >= MIN_EXPECTED {
                cells.push((pool_o, pool_e));
                pool_o = 0.0;
                pool_e = 0.0;
            }
        } else {
            cells.push((o, e));
        }
    }
    if pool_e > 0.0 || pool_o > 0.0 {
        match cells.first_mut() {
            Some(first) => {
                first.0 += pool_o;
                first.1 += pool_e;
            }
            None => cells.push((pool_o, pool_e)),
        }
    }
    let statistic: f64 = cells
        .iter()
        .map(|&(o, e)| {
            if e > 0.0 {
                (o - e) * (o - e) / e
            } else if o > 0.0 {
                f64::INFINITY
            } else {
                0.0
            }
        })
        .sum();
    let dof = cells.len().saturating_sub(1) as u32;
    // A NaN expectation fails every comparison above: it would stay a cell of its own, add 0
    // where nothing was observed, and count towards `dof`.
    // Slices of different lengths leave cells without a partner: unpaired counts (1000 samples
    // beside two cells of 50 had given p = 1).
    let sound_expectations =
        observed.len() == expected.len() && order.iter().all(|&i| expected[i].is_finite() && expected[i] >= 0.0);
    let p_value = if !sound_expectations {
        f64::NAN
    } else if statistic == f64::INFINITY {
        0.0
    } else if dof == 0 {
        f64::NAN
    } else {
        ChiSquared::new(dof as f64).map(|d| d.sf(statistic)).unwrap_or(f64::NAN)
    };
    ChiSquare { statistic, dof, p_value, pdf_integral, outside: 0, zero_expected_samples }
}

/// Nodes of the composite 2-point Gauss–Legendre rule on `[0, 1)` with `subdivisions`
/// sub-intervals (each node has weight `1/(2·subdivisions)`).
fn gauss_nodes(subdivisions: u32) -> Vec<f64> {
    let sub = subdivisions.max(1) as usize;
    let offset = 0.5 / 3f64.sqrt();
    (0..sub).flat_map(|k| [(k as f64 + 0.5 - offset) / sub as f64, (k as f64 + 0.5 + offset) / sub as f64]).collect()
}

/// The unit direction with `cos θ = z` and azimuth `phi` around +z.
fn sphere_point(z: f64, phi: f64) -> DVec3 {
    let r = (1.0 - z * z).max(0.0).sqrt();
    DVec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Histogram of direction samples over the sphere: `n_theta` bands of equal height in
/// `cos θ ∈ [−1, 1]` times `n_phi` sectors in `φ ∈ [−π, π)` (equal-area cells, θ from +z,
/// φ = atan2(y, x)); cell `i·n_phi + j` is band `i` (from cos θ = −1 up) and sector `j`. Samples
/// are normalized in `f64` first; non-finite or zero ones count as outside. `pdf` is the density
/// per steradian, integrated over `(cos θ, φ)` per cell on a `subdivisions²` sub-grid (see
/// [`SUBDIVISIONS`]).
pub fn sphere_histogram(
    samples: &[Vec3],
    pdf: impl Fn(DVec3) -> f64 + Sync,
    n_theta: u32,
    n_phi: u32,
    subdivisions: u32,
) -> Histogram {
    let (nt, np) = (n_theta.max(1) as usize, n_phi.max(1) as usize);
    let mut observed = vec![0u64; nt * np];
    let mut outside = 0;
    for s in samples {
        let v = s.as_dvec3();
        let len = v.length();
        if !(len > 0.0 && len.is_finite()) {
            outside += 1;
            continue;
        }
        let z = (v.z / len).clamp(-1.0, 1.0);
        let phi = v.y.atan2(v.x);
        let i = (((z + 1.0) * 0.5 * nt as f64) as usize).min(nt - 1);
        let j = (((phi + std::f64::consts::PI) / std::f64::consts::TAU * np as f64) as usize).min(np - 1);
        observed[i * np + j] += 1;
    }
    let nodes = gauss_nodes(subdivisions);
    let dz = 2.0 / nt as f64;
    let dphi = std::f64::consts::TAU / np as f64;
    let weight = dz * dphi / (nodes.len() * nodes.len()) as f64;
    let n = samples.len() as f64;
    let integrals: Vec<f64> = (0..nt * np)
        .into_par_iter()
        .map(|cell| {
            let (i, j) = (cell / np, cell % np);
            let mut sum = 0.0;
            for a in &nodes {
                let z = -1.0 + dz * (i as f64 + a);
                for b in &nodes {
                    let phi = -std::f64::consts::PI + dphi * (j as f64 + b);
                    sum += pdf(sphere_point(z, phi));
                }
            }
            sum * weight
        })
        .collect();
    let pdf_integral = integrals.iter().sum();
    Histogram { observed, expected: integrals.iter().map(|x| x * n).collect(), outside, pdf_integral }
}

/// Chi-square test of unit direction samples against a solid-angle pdf over the whole sphere
/// (equal-area cells in `(cos θ, φ)`, see [`sphere_histogram`]), on a [`SUBDIVISIONS`]² sub-grid
/// per cell. `pdf` takes a unit direction and returns its density per steradian.
pub fn chi_square_sphere(samples: &[Vec3], pdf: impl Fn(DVec3) -> f64 + Sync, n_theta: u32, n_phi: u32) -> ChiSquare {
    sphere_histogram(samples, pdf, n_theta, n_phi, SUBDIVISIONS).test()
}

/// Histogram of 2-D samples over `[0,1]²`: `nx × ny` equal cells, cell `i·ny + j` covering
/// `x ∈ [i/nx, (i+1)/nx)`, `y ∈ [j/ny, (j+1)/ny)` (x = 1 or y = 1 count into the last cell).
/// Samples outside `[0,1]²` or not finite count as outside. `pdf` is the density per unit area,
/// integrated per cell on a `subdivisions²` sub-grid (see [`SUBDIVISIONS`]).
pub fn unit_square_histogram(
    samples: &[[f64; 2]],
    pdf: impl Fn([f64; 2]) -> f64 + Sync,
    nx: u32,
    ny: u32,
    subdivisions: u32,
) -> Histogram {
    let (nx, ny) = (nx.max(1) as usize, ny.max(1) as usize);
    let mut observed = vec![0u64; nx * ny];
    let mut outside = 0;
    for &[x, y] in samples {
        if !((0.0..=1.0).contains(&x) && (0.0..=1.0).contains(&y)) {
            outside += 1;
            continue;
        }
        let i = ((x * nx as f64) as usize).min(nx - 1);
        let j = ((y * ny as f64) as usize).min(ny - 1);
        observed[i * ny + j] += 1;
    }
    let nodes = gauss_nodes(subdivisions);
    let (dx, dy) = (1.0 / nx as f64, 1.0 / ny as f64);
    let weight = dx * dy / (nodes.len() * nodes.len()) as f64;
    let n = samples.len() as f64;
    let integrals: Vec<f64> = (0..nx * ny)
        .into_par_iter()
        .map(|cell| {
            let (i, j) = (cell / ny, cell % ny);
            let mut sum = 0.0;
            for a in &nodes {
                let x = dx * (i as f64 + a);
                for b in &nodes {
                    let y = dy * (j as f64 + b);
                    sum += pdf([x, y]);
                }
            }
            sum * weight
        })
        .collect();
    let pdf_integral = integrals.iter().sum();
    Histogram { observed, expected: integrals.iter().map(|x| x * n).collect(), outside, pdf_integral }
}

/// Chi-square test of 2-D samples in `[0,1]²` against a pdf per unit area (see
/// [`unit_square_histogram`]), on a [`SUBDIVISIONS`]² sub-grid per cell. For 2-D warps of the
/// square, and for directions mapped into local coordinates: e.g. a cone's canonical coordinates
/// `((1 − cos θ)/(1 − cos θmax), φ/2π)`, where the pdf is the solid-angle pdf times the Jacobian
/// `2π(1 − cos θmax)`.
pub fn chi_square_unit_square(
    samples: &[[f64; 2]],
    pdf: impl Fn([f64; 2]) -> f64 + Sync,
    nx: u32,
    ny: u32,
) -> ChiSquare {
    unit_square_histogram(samples, pdf, nx, ny, SUBDIVISIONS).test()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// SplitMix64 (Steele, Lea & Flood 2014): a small, statistically strong generator.
    struct SplitMix64(u64);

    impl SplitMix64 {
        fn next_f64(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            (z >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn uniform_sphere(n: usize, seed: u64) -> Vec<Vec3> {
        let mut rng = SplitMix64(seed);
        (0..n)
            .map(|_| {
                let z = 1.0 - 2.0 * rng.next_f64();
                sphere_point(z, 2.0 * PI * rng.next_f64()).as_vec3()
            })
            .collect()
    }

    fn cosine_hemisphere(n: usize, seed: u64) -> Vec<Vec3> {
        let mut rng = SplitMix64(seed);
        (0..n).map(|_| sphere_point(rng.next_f64().sqrt(), 2.0 * PI * rng.next_f64()).as_vec3()).collect()
    }

    #[test]
    fn uniform_sphere_samples_pass() {
        let samples = uniform_sphere(200_000, 1);
        let r = chi_square_sphere(&samples, |_| 0.25 / PI, 20, 40);
        assert!(r.p_value > 0.01, "{r}");
        assert!((r.pdf_integral - 1.0).abs() < 1.0e-9, "{r}");
        assert_eq!((r.dof, r.outside), (799, 0));
    }

    #[test]
    fn cosine_samples_fail_against_the_uniform_hemisphere_pdf() {
        let samples = cosine_hemisphere(200_000, 2);
        let uniform = |d: DVec3| if d.z >= 0.0 { 0.5 / PI } else { 0.0 };
        let r = chi_square_sphere(&samples, uniform, 20, 40);
        assert!(r.p_value < 1.0e-6, "{r}");
        assert!((r.pdf_integral - 1.0).abs() < 1.0e-9, "{r}");
        // ... and pass against their own pdf.
        let cosine = |d: DVec3| d.z.max(0.0) / PI;
        let r = chi_square_sphere(&samples, cosine, 20, 40);
        assert!(r.p_value > 0.01, "{r}");
        assert!((r.pdf_integral - 1.0).abs() < 1.0e-4, "{r}");
    }

    #[test]
    fn unit_square_detects_a_wrong_density() {
        let mut rng = SplitMix64(3);
        let uniform: Vec<[f64; 2]> = (0..100_000).map(|_| [rng.next_f64(), rng.next_f64()]).collect();
        let r = chi_square_unit_square(&uniform, |_| 1.0, 16, 16);
        assert!(r.p_value > 0.01 && (r.pdf_integral - 1.0).abs() < 1.0e-12, "{r}");
        // x = √u has density 2x.
        let skewed: Vec<[f64; 2]> = uniform.iter().map(|&[x, y]| [x.sqrt(), y]).collect();
        let r = chi_square_unit_square(&skewed, |_| 1.0, 16, 16);
        assert!(r.p_value < 1.0e-6, "{r}");
        let r = chi_square_unit_square(&skewed, |[x, _]| 2.0 * x, 16, 16);
        assert!(r.p_value > 0.01 && (r.pdf_integral - 1.0).abs() < 1.0e-9, "{r}");
    }

    /// The cell integrals are exact for cubics per axis, as [`SUBDIVISIONS`] documents: the
    /// 2-point Gauss–Legendre nodes at `mid ± h/(2√3)` integrate `4x³·3y²` on the square and
    /// `(z³ + 1)/4π` on the sphere to rounding, per cell, with one sub-interval or three. Every
    /// warp test's pdf is constant or linear over its cells, which any rule symmetric about the
    /// midpoint integrates exactly: nodes at `mid ± h/4` (4x³ to 0.875 on `[0, 1]`) passed them
    /// all, and would have misjudged the curved lobes the rule is there for.
    #[test]
    fn cell_integrals_are_exact_for_cubics() {
        let close = |got: f64, exact: f64, what: &str| assert!((got - exact).abs() <= 1e-14, "{what}: {got} ≠ {exact}");
        for subdivisions in [1, 3] {
            let h = unit_square_histogram(&[[0.5, 0.5]], |[x, y]| 4.0 * x.powi(3) * 3.0 * y * y, 2, 2, subdivisions);
            for (cell, &expected) in h.expected.iter().enumerate() {
                let (x0, y0) = ((cell / 2) as f64 * 0.5, (cell % 2) as f64 * 0.5);
                let exact = ((x0 + 0.5).powi(4) - x0.powi(4)) * ((y0 + 0.5).powi(3) - y0.powi(3));
                close(expected, exact, &format!("square cell {cell}, {subdivisions} sub-intervals"));
            }
            close(h.pdf_integral, 1.0, "the square");

            let (n_theta, n_phi) = (4, 3);
            let h = sphere_histogram(&[Vec3::Z], |d| (d.z.powi(3) + 1.0) / (4.0 * PI), n_theta, n_phi, subdivisions);
            for (cell, &expected) in h.expected.iter().enumerate() {
                let z0 = -1.0 + 2.0 * (cell / n_phi as usize) as f64 / n_theta as f64;
                let z1 = z0 + 2.0 / n_theta as f64;
                let exact = ((z1.powi(4) - z0.powi(4)) / 4.0 + z1 - z0) * (2.0 * PI / n_phi as f64) / (4.0 * PI);
                close(expected, exact, &format!("sphere cell {cell}, {subdivisions} sub-intervals"));
            }
            close(h.pdf_integral, 1.0, "the sphere");
        }
    }

    #[test]
    fn samples_outside_the_domain_are_counted() {
        let samples = [[0.5, 0.5], [1.5, 0.5], [f64::NAN, 0.1], [1.0, 1.0]];
        let h = unit_square_histogram(&samples, |_| 1.0, 2, 2, 1);
        assert_eq!(h.outside, 2);
        assert_eq!(h.observed, vec![0, 0, 0, 2]);
        let sphere = [Vec3::ZERO, Vec3::NAN, Vec3::Z];
        assert_eq!(sphere_histogram(&sphere, |_| 0.25 / PI, 2, 2, 1).outside, 2);
    }

    #[test]
    fn pooling_and_zero_expectation() {
        // Five cells of expectation 1 pool into one of 5: 2 cells after pooling, dof 1.
        let r = chi_square_counts(&[1, 1, 1, 1, 1, 10], &[1.0, 1.0, 1.0, 1.0, 1.0, 10.0]);
        assert_eq!((r.statistic, r.dof), (0.0, 1));
        assert!((r.p_value - 1.0).abs() < 1.0e-12);
        // A leftover pool below the threshold merges into the first kept cell.
        let r = chi_square_counts(&[0, 6, 10], &[1.0, 6.0, 10.0]);
        assert_eq!(r.dof, 1);
        assert!((r.statistic - 1.0 / 7.0).abs() < 1.0e-12, "{r}");
        // Samples where nothing is expected join the pool and are counted.
        let r = chi_square_counts(&[1, 9, 11], &[0.0, 10.0, 11.0]);
        assert_eq!((r.zero_expected_samples, r.dof, r.statistic), (1, 1, 0.0));
        // Many of them fail the test.
        let r = chi_square_counts(&[100, 10, 10], &[0.0, 110.0, 10.0]);
        assert!(r.p_value < 1.0e-6, "{r}");
        // Cells with nothing expected and nothing observed are ignored.
        let r = chi_square_counts(&[0, 10, 10], &[0.0, 10.0, 10.0]);
        assert_eq!(r.dof, 1);
        // Pooled into a single cell, the counts cannot test the pdf: not a pass, even where they
        // plainly contradict it (every sample where nothing is expected: χ² = ∞; or 100 where
        // the one pool expects 4: χ² = 96²/4).
        for (observed, expected) in [(&[10u64][..], &[0.0][..]), (&[100, 0], &[0.0, 4.0]), (&[3, 2], &[2.5, 2.5])] {
            let r = chi_square_counts(observed, expected);
            assert!(r.dof == 0 && (r.p_value.is_nan() || r.p_value <= 0.01), "{observed:?} against {expected:?}: {r}");
        }
        // A NaN, infinite or negative expectation (a broken pdf) is no pass: it had stayed a
        // cell of its own, adding 0 where nothing was observed (p = 1 here).
        for bad in [f64::NAN, f64::INFINITY, -1.0] {
            let r = chi_square_counts(&[50, 50, 0], &[50.0, 50.0, bad]);
            assert!(r.p_value.is_nan(), "{bad}: {r}");
        }
        // Counts and expectations of different lengths pair no cells for the extra ones.
        for (observed, expected) in [(&[50u64, 50, 1000][..], &[50.0, 50.0][..]), (&[50, 50], &[50.0, 50.0, 1000.0])] {
            let r = chi_square_counts(observed, expected);
            assert!(r.p_value.is_nan(), "{observed:?} against {expected:?}: {r}");
        }
    }
}
