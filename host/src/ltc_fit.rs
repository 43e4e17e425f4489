//! Our own fit of the linearly transformed cosine (LTC) table for GGX: the generator of
//! `raywave_shared::ltc_table`.
//!
//! LTCs (E. Heitz, J. Dupuy, S. Hill and D. Neubelt, "Real-Time Polygonal-Light Shading with
//! Linearly Transformed Cosines", SIGGRAPH 2016) approximate the cosine-weighted BRDF lobe
//! `f(v, l)·cos θ_l` of one view direction by `magnitude · D(l)`, where `D` is a clamped cosine
//! `D_o(ω_o) = max(0, ω_o.z)/π` warped by a 3×3 matrix `M`: `l = normalize(M ω_o)`. Integrals of
//! `D` over polygons and spheres have closed forms, which is what the shading stage uses for the
//! analytic unshadowed term `U` of the ratio estimator.
//!
//! The procedure follows the reference fitter (selfshadow/ltc_code `fit/fitLTC.cpp` at HEAD
//! 31e5e96; see `shared/reference/ddgi-ratio-ltc.md` §3). This is our own implementation, in
//! `f64`, with these choices:
//!
//! * **BRDF.** GGX with height-correlated Smith masking–shadowing
//!   `G2 = 1/(1 + Λ(v) + Λ(l))`, `Λ(ω) = (√(1 + α² tan² θ_ω) − 1)/2`, and no Fresnel (F = 1):
//!   `f·cos θ_l = D(h)·G2/(4 cos θ_v)` for `v.z, l.z > 0`, else 0. `α = max(r², MIN_ALPHA)` with
//!   `r` the perceptual roughness ([`MIN_ALPHA`] = 10⁻⁴, the value of the initial ltc_code release
//!   and of the kernels' `GGX_MIN_ALPHA`).
//! * **View.** `v = (sin θ, 0, cos θ)` in the x–z plane, `θ ≤` [`MAX_THETA`] = 1.57 (as ltc_code).
//! * **BRDF sampling** draws visible normals (Heitz 2018, "Sampling the GGX Distribution of
//!   Visible Normals") and reflects `v`; its pdf is `G1(v)·D(h)/(4 cos θ_v)`, so the weight
//!   `f·cos/pdf = G2/G1(v)` lies in `[0, 1]` and the moments below converge fast. (ltc_code samples
//!   `D(h)·cos θ_h` instead; either works for the MIS error.)
//! * **Moments** of the lobe, by stratified VNDF sampling ([`FitConfig::moment_samples`]² points):
//!   `magnitude = ∫ f·cos dl` (the directional albedo with F = 1) and
//!   `fresnel = ∫ f·cos·(1 − v·h)⁵ dl`. With Schlick's Fresnel `F = F0 + (1 − F0)(1 − v·h)⁵` the
//!   specular albedo is `E_S(F0) = F0·magnitude + (1 − F0)·fresnel`, exactly as ltc_code's shader
//!   uses its `ltc_2.xy`.
//! * **LTC form** ([`LtcParams`]). `M = [X Y Z]·K`, `K = [[m11, 0, m13], [0, m22, 0], [0, 0, 1]]`
//!   (rows), in the frame `Z = (sin ψ, 0, cos ψ)`, `X = (cos ψ, 0, −sin ψ)`, `Y = (0, 1, 0)`. That is
//!   every transform the table's four `M⁻¹` entries can store, up to scale. **Unlike ltc_code**,
//!   which fixes `Z` to the lobe's average direction and fits the other three, the frame angle `ψ`
//!   is fitted too: at grazing views the clamped cosine's own horizon, tilted with `Z`, must line
//!   up with the surface's, and fixing `Z` leaves up to 10 % of the LTC's mass below the surface
//!   for views to 78° (where the horizon clipping of `U` drops it; at most 1.3 % with `ψ`
//!   fitted). Freeing `ψ` (and the L1 error below) halves the fit's L1 error at roughness 0.6
//!   (0.16 → 0.07 at θ = 42°, 0.31 → 0.14 at 65°). At θ = 0 the lobe is rotationally symmetric
//!   and the fit is isotropic (`ψ = 0`, `m22 = m11`, `m13 = 0`).
//!   Nelder–Mead works on `p = (ln m11, ln m22, m13/m11, ψ)` (one parameter, `ln m11`, when
//!   isotropic): the log keeps `m11, m22 > 0` and gives sharp lobes (`m ~ α`) the same relative
//!   resolution as rough ones; ltc_code optimizes `(m11, m22, m13)` directly with `m ≥ 10⁻⁷`.
//! * **Two lobes** ([`LtcMixture`]). A cell holds `g = magnitude·(w·D₁ + (1 − w)·D₂)`, a mixture of
//!   two LTCs of the form above, and the fit optimizes both lobes' four coordinates and `logit w`
//!   (nine parameters; three at θ = 0). One clamped cosine has lighter tails than GGX; the
//!   second, usually wider lobe follows more of them. Measured per cell (relative L1 error, one
//!   lobe → two): roughness 0.51 at θ = 0 0.035 → 0.003, 1.0 at 85° 0.13 → 0.02, 0.63 at 53°
//!   0.094 → 0.049, 0.32 at 68° 0.14 → 0.089; median over all cells 0.015. Against an f64
//!   reference (`tests/analytic_lighting.rs`) the median error of `U` fell from 4.2 % to 0.68 %
//!   (0.43 % with FIT_VERSION 4's warm starts, below; 0.68 % against the test's 10⁶-sample
//!   reference, whose 3σ allowance is narrower); lights that catch only a far tail still
//!   see 30–174 %. The price at
//!   run time is a second polygon integral in `U_S` and a lobe choice in the LTC sampling.
//!   Tried on single cells and rejected (no better `U` against the f64 reference): a fitted
//!   scale above the horizon (so a mixture may straddle it at grazing views; the fit keeps the
//!   scale within 1 ± 0.08 and the error at roughness 0.35, θ = 90° stays at relative L1 0.31);
//!   13 more starts per grazing cell, 12 of them random (best 0.31 there, 0.12 for 0.13 at
//!   roughness 0.49, 79.5°); and tail-weighted errors `|f·cos − g|/√(f·cos + g)` or
//!   `/(f·cos + g)`, which trade the lobe's peak for its tails (a mirror-direction light's error
//!   0.4 % → 5–27 %) or diverge at sharp roughness. A **third lobe** (14 parameters, from the
//!   committed pair plus a third of weight 0.05, best of three starts) was probed on eight
//!   cells behind the failing cases of `tests/analytic_lighting.rs`, scoring `U` of its four
//!   lights against the f64 reference. With the L1 error the mirror light at roughness 0.35,
//!   θ = 90° improves (−18 % → −8 %) but the far tails do not (the light low on the side
//!   −72 % → −55 % there; overhead at roughness 0.095, θ = 79.5° +109 % → +154 %). With
//!   `|f·cos − g|/(f·cos + g + 0.01·magnitude)` the tails come within 4 % in five of the eight
//!   cells, but the mirror light falls to −89…−98 % in four (a sharp peak covers too little
//!   solid angle to count). With the sum of the two (the relative part weighted 0.1) the low
//!   light stays at −26…−99 % in seven cells. A third polygon integral per light would not buy
//!   the ≤ 5 % target. What does, at run time and at every view, is the GGX lobe's own integral
//!   over the light — the LTC's plus its residual `GGX − LTC` — by quadrature in the half-vector's
//!   slope space (`raywave_kernels::shade::slope_quadrature`, opt-in for its cost).
//! * **Error** (minimized): `Σ |f·cos − g|ᵖ/(pdf₁ + pdf₂ + pdf_brdf)` over `n²` directions drawn
//!   from each LTC lobe and `n²` BRDF-sampled ones (stratified grids, `n =`
//!   [`FitConfig::fit_samples`]), divided by `n²`: the balance-heuristic estimate of
//!   `∫|f·cos − g|ᵖ`, `p =` [`FitConfig::error_power`]. ltc_code uses `p = 3`; we use `p = 1`,
//!   because the L1 error bounds what the table is for: for any light `P`,
//!   `|∫_P f·cos − ∫_P g| ≤ ∫|f·cos − g|`, so a cell's relative L1 error bounds the error of `U`
//!   relative to the lobe's albedo for every light at once. (With `ψ` free, `p = 3` and `p = 2`
//!   also let Nelder–Mead run off on the sharpest rows, to lobes disjoint from the GGX lobe.)
//! * **Order and warm starts** ([`warm_starts`]). As ltc_code, roughness runs from 1 down to 0:
//!   at θ = 0 the fit starts from the θ = 0 fit of the next rougher row ([`LtcMixture::START`] at
//!   r = 1), and for θ > 0 from the previous θ of the same row (all nine parameters). **Unlike
//!   ltc_code**, a cell with θ > 0 below the roughest row is also fitted from the same θ of the
//!   next rougher row, and the start that reaches the lower objective wins. Along θ alone a row
//!   stays in the basin its θ = 0 fit chose, and rows 10–33 (roughness 0.16–0.52) switched to a
//!   better one only somewhere past θ = 40°, some never: FIT_VERSION 3's error rose from 0.030
//!   to 0.041 between columns 36 and 40 of row 16 and to 0.35 at its grazing end, where a re-fit
//!   from row 15's or row 17's cell reached 0.023, 0.029 and 0.23. With both starts
//!   (FIT_VERSION 4) row 16's 90th-percentile error fell from 0.213 to 0.143 and its maximum
//!   from 0.66 to 0.42, row 19's median from 0.029 to 0.018, row 33's from 0.057 to 0.043; no
//!   cell got worse than its along-θ fit would have been from the same neighbours. A cell keeps
//!   its winning start's lobe order, so neighbours may store the same two lobes in opposite
//!   orders (20 pairs, rows 0–18), and a lobe of no weight drifts (entries up to ±10³, 24 lobes
//!   in rows 0–3): the kernels' lookup (`raywave_kernels::shade::ltc::lookup`) aligns the four
//!   cells' orders and weights each lobe by its mass, so neither shows between cells
//!   (`tests/ltc_interpolation.rs`: no seam; a plain bilinear blend left 39 at roughness ≥ 0.1).
//!   Fixing the order in the fit instead — each cell aligned with the two neighbours it starts
//!   from, the table fitted again (56 minutes) — left 42 flipped pairs and 53 seams: orders
//!   propagated along rows and along columns disagree where the lobes trade roles. Cell `(a, t)`
//!   needs `(a, t − 1)` and `(a + 1, t)`, so [`fit_table`] fits the anti-diagonals `t + 63 − a`
//!   one after another, each one's cells in parallel (rayon). The warm starts are the neighbours
//!   **as stored** (their `f32` table entries read back, [`CellFit::stored_mixture`]), so
//!   re-fitting any cell from the committed table repeats the fit exactly: the nine-parameter
//!   search is sensitive enough that an `f32`-rounded start moved a grazing cell by L1 4·10⁻³.
//! * **Nelder–Mead** ([`nelder_mead`]): initial simplex step 0.05 per parameter, stop when
//!   `2|f_hi − f_lo| ≤ tol·(|f_hi| + |f_lo|)` or after `max_iters`; then restarted from the best
//!   point with a fresh simplex until a restart improves by less than `tol` (relative), which
//!   makes the result depend little on the start.
//!
//! # Table layout (what [`table_source`] writes)
//!
//! 64 × 64 cells, `index = row·64 + col`:
//! * `row = a`: perceptual roughness `r = a/63`;
//! * `col = t`: `x = sqrt(1 − cos θ) = t/63`, i.e. `cos θ = 1 − x²`.
//!
//! Cells sit **at** `i/63` (the corners of a bilinear patch, ltc_code's texel centres), so the
//! run-time lookup is `s = clamp(r, 0, 1)·63`, `u = clamp(sqrt(1 − saturate(n·v)), 0, 1)·63`,
//! between `floor` and `floor + 1` (clamped to 62 and 63). On a GPU texture those cells are the
//! texels at `uv = coord·(63/64) + 0.5/64` with `coord = (x, r)` (a row of the texture is a row
//! of this array, one roughness; ltc_code's tables run the other way), but its bilinear filter is a
//! plain blend of the entries, which leaves seams where neighbouring cells store their two lobes
//! in the other order: fetch the four cells and blend them lobe by lobe as
//! `raywave_kernels::shade::ltc::lookup` does (above).
//!
//! Per cell, three `Vec4`s:
//! * `LTC_MATRIX[i] = (m⁻¹₀₀, m⁻¹₂₀, m⁻¹₀₂, m⁻¹₂₂)` — the four non-trivial entries of the first
//!   lobe's `M⁻¹` (row, column), normalized so that `m⁻¹₁₁ = 1` (the scale of `M` does not change
//!   the distribution); `LTC_MATRIX_2[i]` the second lobe's. In glam: `M⁻¹ = Mat3::from_cols(vec3(t.x, 0, t.y), Vec3::Y, vec3(t.z, 0, t.w))`,
//!   in the frame `x = normalize(v − n(n·v))`, `y = n × x`, `z = n` (the view in the `+x` half).
//!   ltc_code's `ltc_1`, in the same order.
//! * `LTC_AMPLITUDE[i] = (magnitude, fresnel, w, sphere)` — ltc_code's `ltc_2`: the albedo with
//!   F = 1 and the Schlick term above (specular albedo `F0·x + (1 − F0)·y`), the first lobe's
//!   weight `w`, and the horizon-clipped sphere form factor for the "clipless" path
//!   ([`sphere_form_factor`]). That last one has its **own** coordinates on the same grid:
//!   `row ↔ (z_F + 1)/2`, `col ↔ |F|`, where `F` is the vector form factor of the (unclipped)
//!   light in the LTC's cosine space (with the 1/2π of the edge integral built in) and
//!   `z_F = F.z/|F|`; the form factor is then `|F|·sphere`. The column is kept for sphere lights
//!   (that clipless horizon-clipping variant); **no kernel reads it**: raywave's shade stage
//!   integrates quad lights only (it refuses sphere lights), clips them to the horizon instead,
//!   and its lookup interpolates `sphere` with the other amplitudes but returns only magnitude,
//!   fresnel and `w`.

use glam::{DMat3, DVec3, Mat3};
use rayon::prelude::*;
use raywave_kernels::shade::ltc::LtcLobe;
use std::f64::consts::PI;

/// Version of the fitting procedure; bump it whenever a change alters the fitted values, and
/// regenerate the table (the generated file records the version it came from).
pub const FIT_VERSION: u32 = 4;

/// Largest magnitude of a stored `M⁻¹` entry (normalized to `m⁻¹₁₁ = 1`) the fit accepts. Where
/// the first lobe's weight saturates at 1 the second lobe does not change the error, and
/// Nelder–Mead let it drift: to entries of 3·10¹² in FIT_VERSION 3 (176 cells of the sharpest
/// rows) and past `f32`'s range in FIT_VERSION 4's first run — values the kernels would still
/// transform polygons with, and interpolate bilinearly into the neighbouring cells, whose weight
/// is below 1. Lobes with any weight stayed below 6 (the first lobes below 3).
pub const MAX_STORED_ENTRY: f64 = 1.0e3;

/// Table resolution per axis.
pub const LTC_SIZE: usize = 64;

/// Smallest GGX `α` fitted (roughness 0 is clamped to it): ltc_code's initial release and the
/// kernels' `GGX_MIN_ALPHA`. ltc_code's HEAD uses 10⁻⁵.
pub const MIN_ALPHA: f64 = 1.0e-4;

/// Largest view angle fitted, in radians: the last column (cos θ = 0) is fitted at θ = 1.57
/// (cos θ ≈ 8·10⁻⁴), as ltc_code, because the lobe degenerates at exactly grazing views.
pub const MAX_THETA: f64 = 1.57;

/// The GGX `α` of table row `a` (perceptual roughness `a/63`, squared, clamped to [`MIN_ALPHA`]).
pub fn cell_alpha(a: usize) -> f64 {
    alpha_at(a as f64)
}

/// GGX α at fractional table row `s` (between cells, where the kernels interpolate):
/// `max(r², MIN_ALPHA)`, `r = s/63`.
pub fn alpha_at(s: f64) -> f64 {
    let r = s / (LTC_SIZE - 1) as f64;
    (r * r).max(MIN_ALPHA)
}

/// The view direction of table column `t`: `sqrt(1 − cos θ) = t/63`, θ clamped to [`MAX_THETA`];
/// `v = (sin θ, 0, cos θ)`.
pub fn cell_view(t: usize) -> DVec3 {
    view_at(t as f64)
}

/// The view direction at fractional table column `t` (see [`cell_view`]).
pub fn view_at(t: f64) -> DVec3 {
    let x = t / (LTC_SIZE - 1) as f64;
    let theta = (1.0 - x * x).clamp(-1.0, 1.0).acos().min(MAX_THETA);
    DVec3::new(theta.sin(), 0.0, theta.cos())
}

/// Index of cell (`a` roughness row, `t` view column) in the flat table. Panics if `a` or `t` is
/// not below [`LTC_SIZE`] (a column past the last would address the next row's first cell).
pub fn cell_index(a: usize, t: usize) -> usize {
    assert!(a < LTC_SIZE && t < LTC_SIZE, "LTC cell ({a}, {t}) outside the {LTC_SIZE}² table");
    a * LTC_SIZE + t
}

/// Stratified sample `(i + ½)/n, (j + ½)/n` of an `n × n` grid, index `k = j·n + i`.
fn grid_sample(k: usize, n: usize) -> (f64, f64) {
    let i = k % n;
    let j = k / n;
    ((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64)
}

// ---------------------------------------------------------------------------------------------
// GGX
// ---------------------------------------------------------------------------------------------

/// The isotropic GGX microfacet BRDF times the cosine, F = 1, height-correlated Smith masking,
/// for one view direction `v` (unit, `v.y` may be nonzero, `v.z > 0`).
#[derive(Copy, Clone, Debug)]
pub struct Ggx {
    /// Roughness `α` (not perceptual).
    pub alpha: f64,
    /// View direction (unit).
    pub v: DVec3,
    lambda_v: f64,
}

impl Ggx {
    /// The lobe for roughness `alpha` and unit view `v`.
    pub fn new(alpha: f64, v: DVec3) -> Self {
        Self { alpha, v, lambda_v: Self::lambda(alpha, v.z) }
    }

    /// Smith's `Λ(ω) = (√(1 + α² tan² θ) − 1)/2` for `cos θ = z > 0`, written as
    /// `ε/(2(1 + √(1 + ε)))` with `ε = α² tan² θ` to avoid cancellation. `z²` is floored at
    /// the smallest normal `f64` (the kernels' `smith_lambda` floors it at 10⁻³⁰ in `f32`): a
    /// direction a hair above the horizon (`z ≲ 10⁻¹⁵⁴`, where `α²/z²` overflowed) gets a huge
    /// `Λ`, not ∞/∞.
    pub fn lambda(alpha: f64, z: f64) -> f64 {
        if z >= 1.0 {
            return 0.0;
        }
        let z2 = z * z;
        let eps = alpha * alpha * (1.0 - z2) / z2.max(f64::MIN_POSITIVE);
        eps / (2.0 * (1.0 + (1.0 + eps).sqrt()))
    }

    /// Normal distribution `D(h) = α²/(π (h.x² + h.y² + α² h.z²)²)` for a unit `h` with `h.z > 0`
    /// (the form with `sin² θ_h = h.x² + h.y²` keeps full precision near the normal), else 0.
    pub fn d(&self, h: DVec3) -> f64 {
        if h.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        let q = h.x * h.x + h.y * h.y + a2 * h.z * h.z;
        a2 / (PI * q * q)
    }

    /// Masking `G1(v) = 1/(1 + Λ(v))`.
    pub fn g1_v(&self) -> f64 {
        1.0 / (1.0 + self.lambda_v)
    }

    /// `(f·cos θ_l, pdf)` at the unit direction `l`: the BRDF times the cosine (F = 1; 0 below the
    /// horizon) and the density of [`Ggx::sample`] (visible-normal reflection).
    pub fn eval_pdf(&self, l: DVec3) -> (f64, f64) {
        let v = self.v;
        let sum = v + l;
        let len2 = sum.length_squared();
        // l = −v (or a NaN input): no half vector.
        if len2.is_nan() || len2 <= 0.0 || v.z <= 0.0 {
            return (0.0, 0.0);
        }
        let h = sum / len2.sqrt();
        if h.z <= 0.0 || v.dot(h) <= 0.0 {
            return (0.0, 0.0);
        }
        let d = self.d(h);
        let pdf = d * self.g1_v() / (4.0 * v.z);
        let f = if l.z > 0.0 {
            let g2 = 1.0 / (1.0 + self.lambda_v + Self::lambda(self.alpha, l.z));
            d * g2 / (4.0 * v.z)
        } else {
            0.0
        };
        (f, pdf)
    }

    /// Samples a visible normal (Heitz 2018) with `u ∈ [0,1)²` and reflects `v` about it. The
    /// result may lie below the horizon (then `f = 0`); its density is `eval_pdf(l).1`.
    /// Returns `(l, h)`.
    pub fn sample(&self, u1: f64, u2: f64) -> (DVec3, DVec3) {
        let a = self.alpha;
        let v = self.v;
        let vh = DVec3::new(a * v.x, a * v.y, v.z).normalize();
        let lensq = vh.x * vh.x + vh.y * vh.y;
        let t1 = if lensq > 0.0 { DVec3::new(-vh.y, vh.x, 0.0) / lensq.sqrt() } else { DVec3::X };
        let t2 = vh.cross(t1);
        let r = u1.sqrt();
        let phi = 2.0 * PI * u2;
        let p1 = r * phi.cos();
        let s = 0.5 * (1.0 + vh.z);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
        let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
        let h = DVec3::new(a * nh.x, a * nh.y, nh.z.max(0.0)).normalize();
        let l = 2.0 * v.dot(h) * h - v;
        (l, h)
    }
}

/// Moments of one GGX lobe `f·cos` (F = 1).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LobeMoments {
    /// `∫ f·cos dl`: directional albedo with F = 1.
    pub magnitude: f64,
    /// `∫ f·cos·(1 − v·h)⁵ dl`: the Schlick part, `E_S(F0) = F0·magnitude + (1 − F0)·fresnel`.
    pub fresnel: f64,
}

/// The moments of `ggx` by `n × n` stratified visible-normal samples.
pub fn lobe_moments(ggx: &Ggx, n: usize) -> LobeMoments {
    let mut magnitude = 0.0;
    let mut fresnel = 0.0;
    for k in 0..n * n {
        let (u1, u2) = grid_sample(k, n);
        let (l, h) = ggx.sample(u1, u2);
        if l.z <= 0.0 {
            continue;
        }
        // f·cos/pdf = G2/G1(v), computed directly.
        let g2 = 1.0 / (1.0 + ggx.lambda_v + Ggx::lambda(ggx.alpha, l.z));
        let w = g2 / ggx.g1_v();
        magnitude += w;
        fresnel += w * (1.0 - ggx.v.dot(h).max(0.0)).powi(5);
    }
    let inv = 1.0 / (n * n) as f64;
    LobeMoments { magnitude: magnitude * inv, fresnel: fresnel * inv }
}

// ---------------------------------------------------------------------------------------------
// LTC
// ---------------------------------------------------------------------------------------------

/// A linearly transformed cosine distribution (normalized: it integrates to 1 over the sphere).
#[derive(Copy, Clone, Debug)]
pub struct Ltc {
    /// The transform `M`.
    pub m: DMat3,
    /// `M⁻¹`.
    pub m_inv: DMat3,
    /// `|det M|`.
    pub det: f64,
}

impl Ltc {
    /// The LTC of transform `m` (assumed invertible).
    pub fn new(m: DMat3) -> Self {
        Self { m, m_inv: m.inverse(), det: m.determinant().abs() }
    }

    /// The LTC of a stored, normalized inverse `(m⁻¹₀₀, m⁻¹₂₀, m⁻¹₀₂, m⁻¹₂₂)` (one
    /// `LTC_MATRIX` entry).
    pub fn from_packed(t: [f32; 4]) -> Self {
        let t = t.map(f64::from);
        let m_inv = DMat3::from_cols(DVec3::new(t[0], 0.0, t[1]), DVec3::Y, DVec3::new(t[2], 0.0, t[3]));
        let m = m_inv.inverse();
        Self { m, m_inv, det: m.determinant().abs() }
    }

    /// Density at the unit direction `l`: `max(0, (M⁻¹l).z)·|det M⁻¹|/(π|M⁻¹l|⁴)`.
    pub fn pdf(&self, l: DVec3) -> f64 {
        let w = self.m_inv * l;
        if w.z <= 0.0 {
            return 0.0;
        }
        let l2 = w.length_squared();
        w.z / (PI * self.det * l2 * l2)
    }

    /// Maps the unit cosine-distributed `wo` to `(l, pdf(l))`, with the pdf computed from `wo`:
    /// `(wo.z/π)·|M wo|³/|det M|`.
    pub fn warp(&self, wo: DVec3) -> (DVec3, f64) {
        let w = self.m * wo;
        let len = w.length();
        (w / len, wo.z / PI * len * len * len / self.det)
    }

    /// The normalized inverse as stored in `LTC_MATRIX`: `(m⁻¹₀₀, m⁻¹₂₀, m⁻¹₀₂, m⁻¹₂₂)/m⁻¹₁₁`.
    pub fn packed(&self) -> [f64; 4] {
        let inv = self.m_inv / self.m_inv.y_axis.y;
        [inv.x_axis.x, inv.x_axis.z, inv.z_axis.x, inv.z_axis.z]
    }
}

/// Cosine-distributed direction for `u ∈ [0,1)²` (the LTC's `D_o`): `r = √u1`, `φ = 2πu2`.
fn cosine_direction(u1: f64, u2: f64) -> DVec3 {
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    DVec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u1).max(0.0).sqrt())
}

/// The parameters of one cell's LTC: `M = [X Y Z]·K` with
/// `K = [[m11, 0, m13], [0, m22, 0], [0, 0, 1]]` (rows) and the frame `Z = (sin ψ, 0, cos ψ)`,
/// `X = (cos ψ, 0, −sin ψ)`, `Y = (0, 1, 0)` (see the module documentation).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LtcParams {
    /// Scale along `X` (> 0).
    pub m11: f64,
    /// Scale along `Y` (> 0).
    pub m22: f64,
    /// Skew: `X` component of the image of `Z`.
    pub m13: f64,
    /// Frame angle ψ in radians: `Z` leans by ψ from the normal towards `+x` (the view's side).
    pub psi: f64,
}

/// The frame `(X, Z)` of angle ψ: `Z = (sin ψ, 0, cos ψ)`, `X = (cos ψ, 0, −sin ψ)`.
fn frame_at(psi: f64) -> (DVec3, DVec3) {
    let (sin, cos) = psi.sin_cos();
    (DVec3::new(cos, 0.0, -sin), DVec3::new(sin, 0.0, cos))
}

impl LtcParams {
    /// The clamped cosine itself (`M = I`): the first lobe of [`LtcMixture::START`].
    pub const IDENTITY: Self = Self { m11: 1.0, m22: 1.0, m13: 0.0, psi: 0.0 };

    /// The frame `(X, Z)`.
    pub fn frame(&self) -> (DVec3, DVec3) {
        frame_at(self.psi)
    }

    /// The transform `M = [X Y Z]·K`.
    pub fn matrix(&self) -> DMat3 {
        let (x, z) = self.frame();
        let r = DMat3::from_cols(x, DVec3::Y, z);
        let k = DMat3::from_cols(
            DVec3::new(self.m11, 0.0, 0.0),
            DVec3::new(0.0, self.m22, 0.0),
            DVec3::new(self.m13, 0.0, 1.0),
        );
        r * k
    }

    /// The (normalized) LTC.
    pub fn ltc(&self) -> Ltc {
        Ltc::new(self.matrix())
    }

    /// Recovers the parameters from a stored normalized inverse (the inverse of
    /// [`LtcParams::matrix`] up to the scale `s` of `M`): `M`'s first column is `s·m11·X`, which
    /// gives ψ; then `S = [X Y Z]ᵀ·M` is `s·K`, and the normalization `m⁻¹₁₁ = 1` makes
    /// `s = 1/m22`.
    pub fn from_packed(t: [f32; 4]) -> Self {
        let m = Ltc::from_packed(t).m;
        let psi = (-m.x_axis.z).atan2(m.x_axis.x);
        let (x, z) = frame_at(psi);
        let s = DMat3::from_cols(x, DVec3::Y, z).transpose() * m;
        let m22 = 1.0 / s.z_axis.z;
        Self { m11: s.x_axis.x * m22, m22, m13: s.z_axis.x * m22, psi }
    }
}

/// The fitted model of one cell: a mixture of two LTCs, `weight·D₀ + (1 − weight)·D₁`. One
/// clamped cosine has lighter tails than GGX; the second lobe follows more of them (see the
/// module documentation for what it gains and what it does not).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LtcMixture {
    /// The two lobes' transforms.
    pub lobes: [LtcParams; 2],
    /// Weight of `lobes[0]`, in `[0, 1]`.
    pub weight: f64,
}

impl LtcMixture {
    /// The warm start of the roughest θ = 0 cell: two clamped cosines, the second wider.
    pub const START: Self =
        Self { lobes: [LtcParams::IDENTITY, LtcParams { m11: 2.0, m22: 2.0, ..LtcParams::IDENTITY }], weight: 0.7 };

    /// The (normalized) mixture density.
    pub fn density(&self) -> LtcMixtureDensity {
        LtcMixtureDensity { ltcs: [self.lobes[0].ltc(), self.lobes[1].ltc()], weight: self.weight }
    }

    /// Recovers the mixture from its stored entries: the two normalized inverses and the weight.
    pub fn from_packed(m0: [f32; 4], m1: [f32; 4], weight: f32) -> Self {
        Self { lobes: [LtcParams::from_packed(m0), LtcParams::from_packed(m1)], weight: f64::from(weight) }
    }

    /// The mixture the kernels' table lookup ([`raywave_kernels::shade::ltc::lookup`]) returned:
    /// what a shading point uses, possibly interpolated between cells.
    pub fn from_lookup(lobe: &LtcLobe) -> Self {
        let packed = |m: Mat3| [m.x_axis.x, m.x_axis.z, m.z_axis.x, m.z_axis.z];
        Self::from_packed(packed(lobe.inv_m), packed(lobe.inv_m_2), lobe.weight)
    }
}

/// An evaluated [`LtcMixture`]: the two LTCs and the weight of the first.
#[derive(Copy, Clone, Debug)]
pub struct LtcMixtureDensity {
    /// The lobes.
    pub ltcs: [Ltc; 2],
    /// Weight of `ltcs[0]`.
    pub weight: f64,
}

impl LtcMixtureDensity {
    /// Density at the unit direction `l`.
    pub fn pdf(&self, l: DVec3) -> f64 {
        self.mix(self.ltcs[0].pdf(l), self.ltcs[1].pdf(l))
    }

    /// `weight·p0 + (1 − weight)·p1`.
    fn mix(&self, p0: f64, p1: f64) -> f64 {
        self.weight * p0 + (1.0 - self.weight) * p1
    }
}

// ---------------------------------------------------------------------------------------------
// Nelder–Mead
// ---------------------------------------------------------------------------------------------

/// Result of [`nelder_mead`].
#[derive(Copy, Clone, Debug)]
pub struct Minimum<const D: usize> {
    /// Best point found.
    pub x: [f64; D],
    /// Objective there.
    pub value: f64,
    /// Objective evaluations used.
    pub evals: usize,
}

/// Nelder–Mead from `x0`, restarted from the best point (up to `cfg.max_runs` runs) until a run
/// no longer improves by more than `cfg.tolerance` relative: `(best x, best value, evaluations)`.
fn minimize_with_restarts<const D: usize>(
    f: impl Fn(&[f64; D]) -> f64 + Copy,
    x0: [f64; D],
    cfg: &FitConfig,
) -> ([f64; D], f64, usize) {
    let (mut x, mut best, mut evals) = (x0, f64::INFINITY, 0);
    for _ in 0..cfg.max_runs {
        let r = nelder_mead(f, x, cfg.step, cfg.tolerance, cfg.max_iters);
        evals += r.evals;
        let improved = best - r.value > cfg.tolerance * r.value.abs();
        if r.value <= best {
            (x, best) = (r.x, r.value);
        }
        if !improved {
            break;
        }
    }
    (x, best, evals)
}

/// Downhill simplex (Nelder & Mead 1965) with the standard coefficients (reflection 1, expansion
/// 2, contraction ½, shrink ½), starting from `start` and `start + step·eᵢ`. Stops when
/// `2|f_hi − f_lo| ≤ tol·(|f_hi| + |f_lo|)` with `f_hi` finite (the Numerical Recipes criterion),
/// when the simplex's values are equal (also all +∞), or after `max_iters` iterations. A NaN value counts as +∞,
/// the worst: a NaN start had stayed first in the order and been returned as the minimum.
pub fn nelder_mead<const D: usize>(
    mut objective: impl FnMut(&[f64; D]) -> f64,
    start: [f64; D],
    step: f64,
    tol: f64,
    max_iters: usize,
) -> Minimum<D> {
    let mut f = |p: &[f64; D]| {
        let value = objective(p);
        if value.is_nan() {
            f64::INFINITY
        } else {
            value
        }
    };
    let mut pts: Vec<[f64; D]> = (0..=D)
        .map(|i| {
            let mut p = start;
            if i > 0 {
                p[i - 1] += step;
            }
            p
        })
        .collect();
    let mut vals: Vec<f64> = pts.iter().map(&mut f).collect();
    let mut evals = D + 1;
    let along = |o: &[f64; D], p: &[f64; D], c: f64| -> [f64; D] { core::array::from_fn(|k| o[k] + c * (o[k] - p[k])) };
    for _ in 0..max_iters {
        // Order: best first, worst last.
        let mut order: Vec<usize> = (0..=D).collect();
        order.sort_by(|&i, &j| vals[i].total_cmp(&vals[j]));
        pts = order.iter().map(|&i| pts[i]).collect();
        vals = order.iter().map(|&i| vals[i]).collect();
        let (lo, hi) = (vals[0], vals[D]);
        // An infinite worst value passes the relative test (∞ ≤ ∞) without converging.
        if hi == lo || (hi.is_finite() && 2.0 * (hi - lo).abs() <= tol * (hi.abs() + lo.abs())) {
            break;
        }
        let centroid: [f64; D] = core::array::from_fn(|k| pts[..D].iter().map(|p| p[k]).sum::<f64>() / D as f64);
        let worst = pts[D];
        let r = along(&centroid, &worst, 1.0);
        let fr = f(&r);
        evals += 1;
        if fr < vals[0] {
            let e = along(&centroid, &worst, 2.0);
            let fe = f(&e);
            evals += 1;
            if fe < fr {
                (pts[D], vals[D]) = (e, fe);
            } else {
                (pts[D], vals[D]) = (r, fr);
            }
            continue;
        }
        if fr < vals[D - 1] {
            (pts[D], vals[D]) = (r, fr);
            continue;
        }
        // Contraction: outside if the reflection beat the worst point, else inside.
        let (c, threshold) =
            if fr < vals[D] { (along(&centroid, &worst, 0.5), fr) } else { (along(&centroid, &worst, -0.5), vals[D]) };
        let fc = f(&c);
        evals += 1;
        if fc < threshold {
            (pts[D], vals[D]) = (c, fc);
            continue;
        }
        let best = pts[0];
        for i in 1..=D {
            pts[i] = core::array::from_fn(|k| best[k] + 0.5 * (pts[i][k] - best[k]));
            vals[i] = f(&pts[i]);
            evals += 1;
        }
    }
    let best = (0..=D).fold(0, |b, i| if vals[i] < vals[b] { i } else { b });
    Minimum { x: pts[best], value: vals[best], evals }
}

// ---------------------------------------------------------------------------------------------
// The fit
// ---------------------------------------------------------------------------------------------

/// Parameters of the fit. Every one that affects the stored values is recorded in the generated
/// file's header; [`FitConfig::error_samples`], which sets only the precision of the reported
/// error ([`CellFit::rel_l1_error`]), is not.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FitConfig {
    /// `n`: each error evaluation uses `n²` samples of each LTC lobe and `n²` BRDF samples
    /// (ltc_code: 32, one lobe).
    pub fit_samples: usize,
    /// Per-axis stratified VNDF samples for magnitude and fresnel.
    pub moment_samples: usize,
    /// Power `p` of the minimized error `∫|f·cos − g|ᵖ` (ltc_code: 3; ours: 1, see the module
    /// documentation).
    pub error_power: i32,
    /// Per-axis samples (per technique) of the reported relative L1 error.
    pub error_samples: usize,
    /// Initial Nelder–Mead simplex step (in each lobe's `(ln m11, ln m22, m13/m11, ψ)` and in
    /// `logit w`).
    pub step: f64,
    /// Relative Nelder–Mead tolerance on the objective.
    pub tolerance: f64,
    /// Iteration cap per Nelder–Mead run.
    pub max_iters: usize,
    /// Cap on Nelder–Mead runs per cell (the first plus restarts from the best point).
    pub max_runs: usize,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            fit_samples: 64,
            moment_samples: 512,
            error_power: 1,
            error_samples: 64,
            step: 0.05,
            tolerance: 1.0e-7,
            max_iters: 400,
            max_runs: 4,
        }
    }
}

/// The fitted LTC of one cell and what went into it.
#[derive(Copy, Clone, Debug)]
pub struct CellFit {
    /// Roughness row.
    pub a: usize,
    /// View column.
    pub t: usize,
    /// GGX `α`.
    pub alpha: f64,
    /// View direction.
    pub view: DVec3,
    /// Lobe moments (magnitude, fresnel).
    pub moments: LobeMoments,
    /// The fitted mixture.
    pub params: LtcMixture,
    /// Final objective (the MIS estimate of `∫|f·cos − g|ᵖ`).
    pub objective: f64,
    /// `∫|f·cos − magnitude·D_mix| / magnitude`, estimated with
    /// [`FitConfig::error_samples`]² samples per technique: 0 is a perfect fit, 2 the worst.
    pub rel_l1_error: f64,
    /// Objective evaluations the fit used.
    pub evals: usize,
}

impl CellFit {
    /// The cell's `LTC_MATRIX` and `LTC_MATRIX_2` entries (the two lobes).
    pub fn packed_matrices(&self) -> [[f32; 4]; 2] {
        self.params.lobes.map(|lobe| lobe.ltc().packed().map(|x| x as f32))
    }

    /// The mixture as the table stores it (`f32` entries read back): the warm start its
    /// neighbours get, in the full fit and in a re-fit from the committed table alike, so a re-fit
    /// repeats the fit exactly.
    pub fn stored_mixture(&self) -> LtcMixture {
        let [m0, m1] = self.packed_matrices();
        LtcMixture::from_packed(m0, m1, self.params.weight as f32)
    }

    /// The cell's `LTC_AMPLITUDE` entry: `(magnitude, fresnel, weight of the first lobe, sphere
    /// form factor)`.
    pub fn packed_amplitude(&self) -> [f32; 4] {
        let sphere = sphere_table_value(self.a, self.t);
        [self.moments.magnitude as f32, self.moments.fresnel as f32, self.params.weight as f32, sphere as f32]
    }
}

/// One cell's fitting problem: the lobe and the fixed samples of the error.
struct CellProblem {
    ggx: Ggx,
    moments: LobeMoments,
    /// Power of the error (`FitConfig::error_power`).
    power: i32,
    /// BRDF samples: `(l, f·cos, pdf_brdf)`; fixed for the cell.
    brdf: Vec<(DVec3, f64, f64)>,
    /// Cosine-distributed directions, warped by each candidate lobe.
    cosine: Vec<DVec3>,
}

/// `1/(1 + e⁻ˣ)`: the mixture weight from its search coordinate.
fn logistic(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// The inverse of [`logistic`], for weights clamped to `[10⁻⁹, 1 − 10⁻⁹]`.
fn logit(w: f64) -> f64 {
    let w = w.clamp(1e-9, 1.0 - 1e-9);
    (w / (1.0 - w)).ln()
}

impl LtcParams {
    /// The Nelder–Mead coordinates `(ln m11, ln m22, m13/m11, ψ)`.
    fn to_search(self) -> [f64; 4] {
        let m11 = self.m11.max(1e-12);
        [m11.ln(), self.m22.max(1e-12).ln(), self.m13 / m11, self.psi]
    }

    /// The parameters at Nelder–Mead coordinates `p` (see [`LtcParams::to_search`]).
    fn from_search(p: &[f64]) -> Self {
        let m11 = p[0].exp();
        Self { m11, m22: p[1].exp(), m13: p[2] * m11, psi: p[3] }
    }

    /// The isotropic lobe `m11 = m22 = eˣ` (θ = 0).
    fn isotropic(ln_m: f64) -> Self {
        let m = ln_m.exp();
        Self { m11: m, m22: m, ..Self::IDENTITY }
    }
}

impl CellProblem {
    fn new(a: usize, t: usize, cfg: &FitConfig) -> Self {
        let ggx = Ggx::new(cell_alpha(a), cell_view(t));
        let moments = lobe_moments(&ggx, cfg.moment_samples);
        let n = cfg.fit_samples;
        let brdf = (0..n * n)
            .map(|k| {
                let (u1, u2) = grid_sample(k, n);
                let l = ggx.sample(u1, u2).0;
                let (f, pdf) = ggx.eval_pdf(l);
                (l, f, pdf)
            })
            .collect();
        let cosine = (0..n * n)
            .map(|k| {
                let (u1, u2) = grid_sample(k, n);
                cosine_direction(u1, u2)
            })
            .collect();
        Self { ggx, moments, power: cfg.error_power, brdf, cosine }
    }

    /// The objective: the balance-heuristic estimate of `∫|f·cos − magnitude·D_mix|ᵖ` with one
    /// sample per stratum from each lobe and from the BRDF.
    fn error(&self, mix: &LtcMixtureDensity) -> f64 {
        let mag = self.moments.magnitude;
        // A direction no technique can draw (all densities 0) adds nothing; a NaN density (a
        // degenerate lobe) propagates, so `objective` scores the candidate +∞ rather than letting
        // Nelder–Mead walk to lobes whose samples all drop out (FIT_VERSION 3's first run did).
        let term = |f: f64, p0: f64, p1: f64, pdf_brdf: f64| {
            let den = p0 + p1 + pdf_brdf;
            if den == 0.0 {
                0.0
            } else {
                (f - mag * mix.mix(p0, p1)).abs().powi(self.power) / den
            }
        };
        let [ltc0, ltc1] = &mix.ltcs;
        let mut sum = 0.0;
        for &wo in &self.cosine {
            let (l, p0) = ltc0.warp(wo);
            let (f, pdf_brdf) = self.ggx.eval_pdf(l);
            sum += term(f, p0, ltc1.pdf(l), pdf_brdf);
            let (l, p1) = ltc1.warp(wo);
            let (f, pdf_brdf) = self.ggx.eval_pdf(l);
            sum += term(f, ltc0.pdf(l), p1, pdf_brdf);
        }
        for &(l, f, pdf_brdf) in &self.brdf {
            sum += term(f, ltc0.pdf(l), ltc1.pdf(l), pdf_brdf);
        }
        sum / self.cosine.len() as f64
    }

    /// Objective at `mix`; `+∞` where it is not finite or where a lobe's stored (`f32`) entries
    /// would exceed [`MAX_STORED_ENTRY`] or make a singular transform.
    fn objective(&self, mix: LtcMixture) -> f64 {
        let density = mix.density();
        // What the table test asserts of every stored lobe: bounded entries, and a transform that
        // stays invertible after rounding to `f32` (FIT_VERSION 4's second run stored an unused
        // lobe whose entries all underflowed to 0).
        let storable = |ltc: &Ltc| {
            let stored = ltc.packed().map(|x| x as f32);
            let det = Ltc::from_packed(stored).det;
            stored.iter().all(|x| f64::from(x.abs()) <= MAX_STORED_ENTRY) && det.is_finite() && det > 0.0
        };
        if !density.ltcs.iter().all(storable) {
            return f64::INFINITY;
        }
        let e = self.error(&density);
        if e.is_finite() {
            e
        } else {
            f64::INFINITY
        }
    }

    /// Nelder–Mead from `start`, with restarts: on `(ln m, ln m′, logit w)` when isotropic (both
    /// lobes with `m22 = m11`, `m13 = ψ = 0`), else on both lobes' four coordinates and
    /// `logit w`. Returns `(mixture, objective, evals)`.
    fn fit(&self, start: LtcMixture, isotropic: bool, cfg: &FitConfig) -> (LtcMixture, f64, usize) {
        if isotropic {
            let mix = |p: &[f64; 3]| LtcMixture {
                lobes: [LtcParams::isotropic(p[0]), LtcParams::isotropic(p[1])],
                weight: logistic(p[2]),
            };
            let f = |p: &[f64; 3]| self.objective(mix(p));
            let ln_m = |l: &LtcParams| l.m11.max(1e-12).ln();
            let x0 = [ln_m(&start.lobes[0]), ln_m(&start.lobes[1]), logit(start.weight)];
            let (x, best, evals) = minimize_with_restarts(f, x0, cfg);
            (mix(&x), best, evals)
        } else {
            let mix = |p: &[f64; 9]| LtcMixture {
                lobes: [LtcParams::from_search(&p[0..4]), LtcParams::from_search(&p[4..8])],
                weight: logistic(p[8]),
            };
            let f = |p: &[f64; 9]| self.objective(mix(p));
            let (l0, l1) = (start.lobes[0].to_search(), start.lobes[1].to_search());
            let x0 = core::array::from_fn(|k| match k {
                0..4 => l0[k],
                4..8 => l1[k - 4],
                _ => logit(start.weight),
            });
            let (x, best, evals) = minimize_with_restarts(f, x0, cfg);
            (mix(&x), best, evals)
        }
    }
}

/// A distribution of directions the balance-heuristic integrals below draw from.
trait DirectionSampler {
    /// The direction for the stratified point `u ∈ [0,1)²`.
    fn sample(&self, u1: f64, u2: f64) -> DVec3;
    /// Its density at the unit direction `l`.
    fn pdf(&self, l: DVec3) -> f64;
}

impl DirectionSampler for Ltc {
    fn sample(&self, u1: f64, u2: f64) -> DVec3 {
        self.warp(cosine_direction(u1, u2)).0
    }
    fn pdf(&self, l: DVec3) -> f64 {
        Ltc::pdf(self, l)
    }
}

impl DirectionSampler for Ggx {
    fn sample(&self, u1: f64, u2: f64) -> DVec3 {
        Ggx::sample(self, u1, u2).0
    }
    fn pdf(&self, l: DVec3) -> f64 {
        self.eval_pdf(l).1
    }
}

/// `∫ h(l) dl` over the sphere by the balance heuristic: `n²` stratified directions from each of
/// `samplers` (the grid shifted by `shift` cells), each weighted by `1/Σ pdf`.
fn balance_heuristic_integral(
    samplers: &[&dyn DirectionSampler],
    n: usize,
    shift: f64,
    h: impl Fn(DVec3) -> f64,
) -> f64 {
    let mut sum = 0.0;
    for k in 0..n * n {
        let (u1, u2) = grid_sample(k, n);
        let (u1, u2) = ((u1 + shift / n as f64).fract(), (u2 + shift / n as f64).fract());
        for sampler in samplers {
            let l = sampler.sample(u1, u2);
            let den: f64 = samplers.iter().map(|s| s.pdf(l)).sum();
            // As in the fit's objective: zero density adds nothing, NaN shows in the result.
            if den != 0.0 {
                sum += h(l) / den;
            }
        }
    }
    sum / (n * n) as f64
}

/// `∫|f·cos − magnitude·D_mix| / magnitude` by the balance heuristic with `n²` stratified samples
/// per lobe and from the BRDF (grids offset by ¼ cell against the fit's, so the estimate does not
/// reuse the fit's points).
pub fn relative_l1_error(ggx: &Ggx, magnitude: f64, mix: &LtcMixtureDensity, n: usize) -> f64 {
    let samplers: [&dyn DirectionSampler; 3] = [&mix.ltcs[0], &mix.ltcs[1], ggx];
    balance_heuristic_integral(&samplers, n, 0.25, |l| (ggx.eval_pdf(l).0 - magnitude * mix.pdf(l)).abs()) / magnitude
}

/// Fits cell `(a, t)` from `start` and, if given, also from `alternative`, keeping the fit with
/// the lower objective (`start`'s on a tie); `evals` counts both.
pub fn fit_cell(a: usize, t: usize, start: LtcMixture, alternative: Option<LtcMixture>, cfg: &FitConfig) -> CellFit {
    let problem = CellProblem::new(a, t, cfg);
    let isotropic = t == 0;
    let first = problem.fit(start, isotropic, cfg);
    let (params, objective, evals) = match alternative.map(|s| problem.fit(s, isotropic, cfg)) {
        Some(other) if other.1 < first.1 => (other.0, other.1, first.2 + other.2),
        Some(other) => (first.0, first.1, first.2 + other.2),
        None => first,
    };
    let rel_l1_error = relative_l1_error(&problem.ggx, problem.moments.magnitude, &params.density(), cfg.error_samples);
    CellFit {
        a,
        t,
        alpha: problem.ggx.alpha,
        view: problem.ggx.v,
        moments: problem.moments,
        params,
        objective,
        rel_l1_error,
        evals,
    }
}

/// The warm starts of cell `(a, t)` (module documentation, "Order and warm starts"), with
/// `stored(a, t)` the mixture a neighbour's table entries hold: `(start, alternative)` for
/// [`fit_cell`]. θ = 0: the next rougher row's θ = 0 cell ([`LtcMixture::START`] for the
/// roughest), no alternative; θ > 0: the previous θ of the row, and the next rougher row's cell
/// at this θ unless the row is the roughest.
pub fn warm_starts(
    a: usize,
    t: usize,
    stored: impl Fn(usize, usize) -> LtcMixture,
) -> (LtcMixture, Option<LtcMixture>) {
    let rougher = (a + 1 < LTC_SIZE).then(|| stored(a + 1, t));
    if t == 0 {
        (rougher.unwrap_or(LtcMixture::START), None)
    } else {
        (stored(a, t - 1), rougher)
    }
}

/// The whole fitted table, `cells[cell_index(a, t)]`.
#[derive(Clone, Debug)]
pub struct LtcTable {
    /// The configuration it was fitted with.
    pub config: FitConfig,
    /// All 64 × 64 cells, row-major by roughness.
    pub cells: Vec<CellFit>,
}

impl LtcTable {
    /// Cell `(a, t)`; panics outside the table, as [`cell_index`].
    pub fn cell(&self, a: usize, t: usize) -> &CellFit {
        &self.cells[cell_index(a, t)]
    }
}

/// Fits the whole table. Cell `(a, t)` starts from `(a, t − 1)` and `(a + 1, t)` ([`warm_starts`]),
/// so the anti-diagonals `k = t + 63 − a` (`k = 0` the roughest θ = 0 cell, `k = 126` the sharpest
/// most grazing one) are fitted in order, the cells of each in parallel. `progress(k + 1)` is
/// called as anti-diagonal `k` finishes (of `2·64 − 1`).
pub fn fit_table(cfg: &FitConfig, progress: &(dyn Fn(usize) + Sync)) -> LtcTable {
    let n = LTC_SIZE;
    let mut cells: Vec<Option<CellFit>> = vec![None; n * n];
    for k in 0..2 * n - 1 {
        let diagonal: Vec<(usize, usize)> =
            (0..n).filter_map(|t| (n - 1 + t).checked_sub(k).filter(|&a| a < n).map(|a| (a, t))).collect();
        let stored = |a: usize, t: usize| {
            cells[cell_index(a, t)].as_ref().expect("warm starts lie on the previous anti-diagonal").stored_mixture()
        };
        let fitted: Vec<CellFit> = diagonal
            .par_iter()
            .map(|&(a, t)| {
                let (start, alternative) = warm_starts(a, t, stored);
                fit_cell(a, t, start, alternative, cfg)
            })
            .collect();
        for c in fitted {
            cells[cell_index(c.a, c.t)] = Some(c);
        }
        progress(k + 1);
    }
    LtcTable { config: *cfg, cells: cells.into_iter().flatten().collect() }
}

// ---------------------------------------------------------------------------------------------
// Sphere form factor (the clipless path: stored for sphere lights, read by no kernel)
// ---------------------------------------------------------------------------------------------

/// Projected solid angle `∫_cap max(0, cos θ) dω` of a spherical cap of angular radius `σ`
/// (`sin² σ = sin2_sigma`) whose centre makes the angle `ω` with the normal (`cos ω = z`), i.e. the
/// cap's form factor times π, clipped to the horizon. Closed form of J. Snyder, "Area light
/// sources for real-time graphics" (1996), in the form of S. Lagarde and C. de Rousiers, "Moving
/// Frostbite to PBR" (2014, §4.7.2): `π cos ω sin² σ` while the cap is above the horizon,
/// `(cos ω·acos y − x·s)·sin² σ + atan(s/x)` with `x = cot σ`, `y = −x cot ω`, `s = sin ω √(1 − y²)`
/// while it straddles it, and 0 below.
pub fn sphere_cap_projected_solid_angle(z: f64, sin2_sigma: f64) -> f64 {
    let z = z.clamp(-1.0, 1.0);
    let s2 = sin2_sigma.clamp(0.0, 1.0);
    let sin_sigma = s2.sqrt();
    let sin_omega = (1.0 - z * z).max(0.0).sqrt();
    // Above the horizon: ω ≤ π/2 − σ ⇔ cos ω ≥ sin σ.
    if z >= sin_sigma {
        return PI * z * s2;
    }
    // Below: ω ≥ π/2 + σ ⇔ cos ω ≤ −sin σ.
    if z <= -sin_sigma {
        return 0.0;
    }
    let cos_sigma = (1.0 - s2).max(0.0).sqrt();
    let x = cos_sigma / sin_sigma;
    // sin ω > 0 here (|cos ω| < sin σ ≤ 1).
    let y = (-x * z / sin_omega).clamp(-1.0, 1.0);
    let s = sin_omega * (1.0 - y * y).max(0.0).sqrt();
    ((z * y.acos() - x * s) * s2 + s.atan2(x)).max(0.0)
}

/// The clipless-path table value: the horizon-clipped form factor of a sphere cap divided by its
/// unclipped vector form factor length `|F| = sin² σ`, as a function of `z = cos ω` and `len = |F|`:
/// `I(ω, σ)/(π·len)` (= `max(z, 0)` when `len = 0`). ltc_code's `ltc_2.w`. Stored for sphere lights;
/// unused by the quad path, which clips each quad to the horizon (see the module documentation).
pub fn sphere_form_factor(z: f64, len: f64) -> f64 {
    if len <= 0.0 {
        return z.max(0.0);
    }
    sphere_cap_projected_solid_angle(z, len) / (PI * len)
}

/// [`sphere_form_factor`] at table cell `(a, t)`: `z = 2a/63 − 1`, `len = t/63`.
pub fn sphere_table_value(a: usize, t: usize) -> f64 {
    let s = (LTC_SIZE - 1) as f64;
    sphere_form_factor(2.0 * a as f64 / s - 1.0, t as f64 / s)
}

// ---------------------------------------------------------------------------------------------
// Generated source, statistics and checks
// ---------------------------------------------------------------------------------------------

/// The command that regenerates the committed table.
pub const REGENERATE_COMMAND: &str =
    "cargo run --release --no-default-features --example fit_ltc -- --out shared/src/ltc_table.rs";

/// The packed entries of a table, as `shared/src/ltc_table.rs` stores them (one slice per
/// array, `LTC_SIZE²` entries each).
#[derive(Copy, Clone, Debug)]
pub struct PackedTable<'a> {
    /// `LTC_MATRIX`: the first lobe's normalized `M⁻¹`.
    pub matrix: &'a [[f32; 4]],
    /// `LTC_MATRIX_2`: the second lobe's.
    pub matrix_2: &'a [[f32; 4]],
    /// `LTC_AMPLITUDE`: `(magnitude, fresnel, weight, sphere)` (`sphere` read by no kernel).
    pub amplitude: &'a [[f32; 4]],
}

impl PackedTable<'_> {
    /// The 64-bit FNV-1a digest (Fowler–Noll–Vo; offset basis and prime of its 64-bit variant) of
    /// every value's bits, little-endian, in the packed order ([`packed_table_source`] writes it
    /// into the file as `LTC_VALUES_DIGEST`): a value edited in place after generation no longer
    /// matches it, which the file's text, written from the committed values, cannot show.
    pub fn digest(&self) -> u64 {
        const OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
        const PRIME: u64 = 0x0000_0100_0000_01b3;
        self.matrix
            .iter()
            .chain(self.matrix_2)
            .chain(self.amplitude)
            .flatten()
            .flat_map(|value| value.to_bits().to_le_bytes())
            .fold(OFFSET_BASIS, |hash, byte| (hash ^ u64::from(byte)).wrapping_mul(PRIME))
    }
}

impl PackedTable<'static> {
    /// The committed table.
    pub fn committed() -> Self {
        use raywave_shared::ltc_table::{LTC_AMPLITUDE, LTC_MATRIX, LTC_MATRIX_2};
        Self { matrix: &LTC_MATRIX, matrix_2: &LTC_MATRIX_2, amplitude: &LTC_AMPLITUDE }
    }
}

impl PackedTable<'_> {
    /// The mixture stored for cell `(a, t)`.
    pub fn mixture(&self, a: usize, t: usize) -> LtcMixture {
        let i = cell_index(a, t);
        LtcMixture::from_packed(self.matrix[i], self.matrix_2[i], self.amplitude[i][2])
    }

    /// Its density.
    pub fn density(&self, a: usize, t: usize) -> LtcMixtureDensity {
        self.mixture(a, t).density()
    }
}

/// The Rust source of `shared/src/ltc_table.rs` for `table`. Floats are written with Rust's
/// shortest round-trip formatting of the `f32` value, so the file reproduces the `f32`s exactly.
pub fn table_source(table: &LtcTable) -> String {
    let matrices: Vec<[[f32; 4]; 2]> = table.cells.iter().map(CellFit::packed_matrices).collect();
    let matrix: Vec<[f32; 4]> = matrices.iter().map(|m| m[0]).collect();
    let matrix_2: Vec<[f32; 4]> = matrices.iter().map(|m| m[1]).collect();
    let amplitude: Vec<[f32; 4]> = table.cells.iter().map(CellFit::packed_amplitude).collect();
    packed_table_source(&table.config, PackedTable { matrix: &matrix, matrix_2: &matrix_2, amplitude: &amplitude })
}

/// [`table_source`] from the packed entries and the config they were fitted with (lets a test
/// check that the committed file is exactly what the generator writes).
pub fn packed_table_source(c: &FitConfig, table: PackedTable<'_>) -> String {
    use std::fmt::Write;
    let n = LTC_SIZE;
    let mut s = String::new();
    let _ = write!(
        s,
        "//! GGX linearly transformed cosine (LTC) table — GENERATED, do not edit.
//!
//! Regenerate with `{REGENERATE_COMMAND}`
//! (fitter: `raywave_host::ltc_fit`, FIT_VERSION = {FIT_VERSION}); check with `--check`.
//!
//! Fit: GGX, height-correlated Smith G2, F = 1; α = max(r², {MIN_ALPHA:e}), r = row/63; view
//! `v = (sin θ, 0, cos θ)`, `sqrt(1 − cos θ) = col/63`, θ ≤ {MAX_THETA}. A mixture of two LTCs,
//! `w·D₁ + (1 − w)·D₂`; Nelder–Mead on each lobe's (ln m11, ln m22, m13/m11, ψ) — the frame
//! angle ψ fitted too — and logit w, step {step}, tolerance {tol:e}, ≤ {iters} iterations × ≤ {runs}
//! runs, warm-started from the previous θ and from the next rougher row (the lower objective
//! kept). Error: balance-heuristic `Σ|f·cos − g|^{power}/(pdf_1 + pdf_2 + pdf_brdf)` with {fs}²
//! samples of each lobe and {fs}² VNDF samples; moments with {ms}² VNDF samples. See
//! `raywave_host::ltc_fit` for the details.
//!
//! Layout: `index = row·{n} + col` (row = roughness `a`, col = view `t`), values at `i/63`; look up
//! with `s = r·63`, `u = sqrt(1 − n·v)·63` between the four cells around, lobe by lobe as
//! `raywave_kernels::shade::ltc::lookup` blends them (a texture's bilinear filter leaves seams).
//! * `LTC_MATRIX[i]`, `LTC_MATRIX_2[i] = (m⁻¹₀₀, m⁻¹₂₀, m⁻¹₀₂, m⁻¹₂₂)` of the two lobes' inverse
//!   transforms normalized to `m⁻¹₁₁ = 1`: `M⁻¹ = Mat3::from_cols(vec3(x, 0, y), Vec3::Y,
//!   vec3(z, 0, w))` in the frame (`normalize(v − n(n·v))`, `n × x`, `n`).
//! * `LTC_AMPLITUDE[i] = (magnitude, fresnel, w, sphere)`: specular albedo
//!   `F0·magnitude + (1 − F0)·fresnel`; `w` the first lobe's weight; `sphere` is the
//!   horizon-clipped sphere form factor over `|F|` at `row = 63·(z + 1)/2`, `col = 63·|F|`
//!   (clipless path), kept for sphere lights and read by no kernel: the shade stage integrates
//!   quad lights only, clipped to the horizon.

/// Cells per table axis.
pub const LTC_SIZE: u32 = {n};

/// `raywave_host::ltc_fit::FIT_VERSION` of the fitter that wrote this file.
pub const LTC_FIT_VERSION: u32 = {FIT_VERSION};

/// The FNV-1a digest of every value below as written (`raywave_host::ltc_fit::PackedTable::digest`):
/// a value edited after generation no longer matches it (tested).
pub const LTC_VALUES_DIGEST: u64 = {digest:#018x};

// `const` rather than `static`: a const is emitted only where it is used, so the SPIR-V build of
// this crate carries no 64 KiB tables (the host uploads them as one storage buffer,
// `LTC_MATRIX ++ LTC_MATRIX_2 ++ LTC_AMPLITUDE`; see `packed_entries`).
",
        step = c.step,
        tol = c.tolerance,
        iters = c.max_iters,
        runs = c.max_runs,
        power = c.error_power,
        fs = c.fit_samples,
        ms = c.moment_samples,
        digest = table.digest(),
    );
    let array = |s: &mut String, doc: &str, name: &str, values: &[[f32; 4]]| {
        let _ = write!(
            s,
            "
/// {doc}
#[rustfmt::skip]
#[allow(clippy::large_const_arrays)]
pub const {name}: [[f32; 4]; {}] = [
",
            n * n
        );
        for v in values {
            let _ = writeln!(s, "    [{:e}, {:e}, {:e}, {:e}],", v[0], v[1], v[2], v[3]);
        }
        s.push_str("];\n");
    };
    array(
        &mut s,
        "The first lobe's normalized `M⁻¹` entries per cell (see the module documentation).",
        "LTC_MATRIX",
        table.matrix,
    );
    array(&mut s, "The second lobe's normalized `M⁻¹` entries per cell.", "LTC_MATRIX_2", table.matrix_2);
    array(
        &mut s,
        "`(magnitude, fresnel, first lobe's weight, sphere form factor)` per cell (see the module documentation).",
        "LTC_AMPLITUDE",
        table.amplitude,
    );
    s.push_str(
        "
/// Every entry in the order of the packed storage buffer the shade stage reads:
/// `LTC_MATRIX`, then `LTC_MATRIX_2`, then `LTC_AMPLITUDE`.
pub fn packed_entries() -> impl Iterator<Item = [f32; 4]> {
    LTC_MATRIX.iter().chain(LTC_MATRIX_2.iter()).chain(LTC_AMPLITUDE.iter()).copied()
}
",
    );
    s
}

/// `(median, 90th percentile, maximum)` of a row's relative L1 errors over its 64 columns
/// (the 90th percentile is the 58th smallest of 64).
pub fn row_error_stats(table: &LtcTable, a: usize) -> (f64, f64, f64) {
    error_percentiles((0..LTC_SIZE).map(|t| table.cell(a, t).rel_l1_error).collect())
}

/// `(median, 90th percentile, maximum)` of errors `e` (any order; a row's 64, or a table's): the
/// median averages the two middle values of an even count, the 90th percentile is the smallest
/// value at or above 90 % of them. `e` must not be empty.
pub fn error_percentiles(mut e: Vec<f64>) -> (f64, f64, f64) {
    e.sort_by(f64::total_cmp);
    let n = e.len();
    let median = 0.5 * (e[(n - 1) / 2] + e[n / 2]);
    (median, e[(n * 9).div_ceil(10) - 1], e[n - 1])
}

/// `∫|p − q|` over the sphere for two LTC mixtures (in `[0, 2]`), by the balance heuristic with
/// `n²` samples of each of their four lobes.
pub fn mixture_l1_distance(p: &LtcMixtureDensity, q: &LtcMixtureDensity, n: usize) -> f64 {
    let samplers: [&dyn DirectionSampler; 4] = [&p.ltcs[0], &p.ltcs[1], &q.ltcs[0], &q.ltcs[1]];
    balance_heuristic_integral(&samplers, n, 0.0, |l| (p.pdf(l) - q.pdf(l)).abs())
}

/// Result of re-fitting one committed cell.
#[derive(Copy, Clone, Debug)]
pub struct CellCheck {
    /// The re-fit.
    pub refit: CellFit,
    /// `∫|D_committed − D_refit|` (0 identical, 2 disjoint).
    pub l1_distance: f64,
    /// `|magnitude_refit − magnitude_committed|`.
    pub magnitude_diff: f64,
    /// `|fresnel_refit − fresnel_committed|`.
    pub fresnel_diff: f64,
    /// `|sphere_refit − sphere_committed|`.
    pub sphere_diff: f64,
}

/// Re-fits the given cells from their committed warm starts and compares them with the committed
/// `table` (in parallel).
pub fn check_cells(cells: &[(usize, usize)], table: &PackedTable<'_>, cfg: &FitConfig) -> Vec<CellCheck> {
    cells
        .par_iter()
        .map(|&(a, t)| {
            let (start, alternative) = warm_starts(a, t, |a, t| table.mixture(a, t));
            let refit = fit_cell(a, t, start, alternative, cfg);
            let amp = refit.packed_amplitude();
            let fresh = refit.stored_mixture().density();
            let committed = table.amplitude[cell_index(a, t)];
            CellCheck {
                refit,
                l1_distance: mixture_l1_distance(&table.density(a, t), &fresh, 64),
                magnitude_diff: (f64::from(amp[0]) - f64::from(committed[0])).abs(),
                fresnel_diff: (f64::from(amp[1]) - f64::from(committed[1])).abs(),
                sphere_diff: (f64::from(amp[3]) - f64::from(committed[3])).abs(),
            }
        })
        .collect()
}

/// Largest `∫|D_committed − D_refit|` (of 2 for disjoint lobes) with which a re-fitted cell still
/// counts as reproduced. Re-fits from the committed warm starts repeat the fit's own start
/// exactly ([`CellFit::stored_mixture`]), so they land on the committed cell up to `f32` rounding;
/// the margin allows for floating-point differences between machines. Changing the fit's sample
/// count from 32² to 64² moved single-lobe cells by ~10⁻³. The fit's `exp`, `ln`, `sin`, `cos`,
/// `acos` and `atan2` come from the platform's libm, which rounds them its own way: re-fitted with
/// the `libm` crate's (musl's) instead of glibc's, 249 of 252 cells (`CHECK_CELLS` and 240 spread)
/// were bit-identical and the worst moved by 6.8·10⁻⁵ (2026-11-28).
pub const CHECK_L1_TOLERANCE: f64 = 1.0e-3;

/// Largest absolute difference of magnitude, fresnel and sphere terms in a re-fit: they do not
/// depend on the warm start, so they agree to `f32` rounding.
pub const CHECK_VALUE_TOLERANCE: f64 = 1.0e-6;

/// `extra` more cells for [`check_cells`] besides [`CHECK_CELLS`], spread over the table by a
/// fixed odd stride (deterministic): distinct cells, none of `CHECK_CELLS`, until the table's
/// other cells are all taken.
pub fn spread_cells(extra: usize) -> Vec<(usize, usize)> {
    let n = (LTC_SIZE * LTC_SIZE) as u64;
    (0..n)
        .map(|k| (k.wrapping_mul(2_654_435_761).wrapping_add(17) % n) as usize)
        .map(|i| (i / LTC_SIZE, i % LTC_SIZE))
        .filter(|cell| !CHECK_CELLS.contains(cell))
        .take(extra)
        .collect()
}

/// A spread of cells for checks: the corners, the first (sharpest) and last (roughest) rows, the
/// θ = 0 and most grazing columns, and a few interior cells.
pub const CHECK_CELLS: [(usize, usize); 12] =
    [(63, 0), (63, 63), (0, 0), (0, 1), (0, 63), (1, 40), (8, 20), (20, 62), (32, 32), (45, 10), (55, 63), (62, 5)];

#[cfg(test)]
mod tests {
    use super::*;
    use raywave_shared::ltc_table::{LTC_AMPLITUDE, LTC_FIT_VERSION, LTC_MATRIX, LTC_MATRIX_2, LTC_SIZE as TABLE_SIZE};

    /// With as many extra cells as the table has besides [`CHECK_CELLS`], `fit_ltc --check
    /// --extra` checks every cell once (the spread had re-taken the fixed cells and missed 12).
    #[test]
    fn the_check_spread_and_the_fixed_cells_cover_the_table_once() {
        let mut cells = spread_cells(LTC_SIZE * LTC_SIZE - CHECK_CELLS.len());
        cells.extend(CHECK_CELLS);
        cells.sort_unstable();
        cells.dedup();
        assert_eq!(cells.len(), LTC_SIZE * LTC_SIZE);
    }

    /// SplitMix64: a small deterministic generator for the Monte Carlo checks.
    struct Rng(u64);
    impl Rng {
        fn next_f64(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^= z >> 31;
            (z >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// `∫ f(ω) dω` over the directions within `max_theta` of `axis`, by the midpoint rule in
    /// `(ξ, φ)` with `θ = max_theta·ξᵖ` (dense near the axis, for lobes peaked there).
    fn graded_quadrature(axis: DVec3, max_theta: f64, p: i32, n: usize, f: impl Fn(DVec3) -> f64) -> f64 {
        let z = axis.normalize();
        let x = if z.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
        let x = (x - z * z.dot(x)).normalize();
        let y = z.cross(x);
        let n_phi = 2 * n;
        let mut sum = 0.0;
        for i in 0..n {
            let xi = (i as f64 + 0.5) / n as f64;
            let theta = max_theta * xi.powi(p);
            let dtheta = max_theta * p as f64 * xi.powi(p - 1) / n as f64;
            let (st, ct) = theta.sin_cos();
            let mut ring = 0.0;
            for j in 0..n_phi {
                let phi = 2.0 * PI * (j as f64 + 0.5) / n_phi as f64;
                ring += f(st * phi.cos() * x + st * phi.sin() * y + ct * z);
            }
            sum += ring * st * dtheta * 2.0 * PI / n_phi as f64;
        }
        sum
    }

    /// `(∫ f·cos dl, ∫ f·cos·(1 − v·h)⁵ dl)` by quadrature: for sharp lobes (α < 0.1) over half
    /// vectors (`dl = 4 (v·h) dh`) on a grid graded towards the normal, where `D` peaks; for rough
    /// ones directly over `l` on a uniform `(θ, φ)` grid (the integrand is continuous there).
    fn albedo_by_quadrature(ggx: &Ggx, n: usize) -> (f64, f64) {
        let v = ggx.v;
        let fresnel = |l: DVec3| (1.0 - v.dot((v + l).normalize()).max(0.0)).powi(5);
        if ggx.alpha < 0.1 {
            let f = |h: DVec3, with_fresnel: bool| {
                let vh = v.dot(h);
                if vh <= 0.0 {
                    return 0.0;
                }
                let l = 2.0 * vh * h - v;
                let w = ggx.eval_pdf(l).0 * 4.0 * vh;
                if with_fresnel {
                    w * (1.0 - vh).powi(5)
                } else {
                    w
                }
            };
            let mag = graded_quadrature(DVec3::Z, PI / 2.0, 4, n, |h| f(h, false));
            let fr = graded_quadrature(DVec3::Z, PI / 2.0, 4, n, |h| f(h, true));
            (mag, fr)
        } else {
            let mag = graded_quadrature(DVec3::Z, PI / 2.0, 1, n, |l| ggx.eval_pdf(l).0);
            let fr = graded_quadrature(DVec3::Z, PI / 2.0, 1, n, |l| ggx.eval_pdf(l).0 * fresnel(l));
            (mag, fr)
        }
    }

    #[test]
    fn committed_table_is_from_this_fitter() {
        assert_eq!(LTC_FIT_VERSION, FIT_VERSION, "regenerate shared/src/ltc_table.rs: {REGENERATE_COMMAND}");
        assert_eq!(TABLE_SIZE as usize, LTC_SIZE);
        assert_eq!(LTC_MATRIX.len(), LTC_SIZE * LTC_SIZE);
        assert_eq!(LTC_MATRIX_2.len(), LTC_SIZE * LTC_SIZE);
        for (i, amp) in LTC_AMPLITUDE.iter().enumerate() {
            for m in [LTC_MATRIX[i], LTC_MATRIX_2[i]] {
                assert!(m.iter().chain(amp.iter()).all(|x| x.is_finite()), "cell {i}");
                assert!(m.iter().all(|x| f64::from(x.abs()) <= MAX_STORED_ENTRY), "cell {i}: {m:?}");
                let ltc = Ltc::from_packed(m);
                assert!(ltc.det.is_finite() && ltc.det > 0.0, "cell {i}: det {}", ltc.det);
            }
            assert!(amp[0] > 0.0 && amp[0] <= 1.0, "cell {i}: magnitude {}", amp[0]);
            assert!(amp[1] >= 0.0 && amp[1] <= amp[0], "cell {i}: fresnel {}", amp[1]);
            assert!((0.0..=1.0).contains(&amp[2]), "cell {i}: weight {}", amp[2]);
            assert!((0.0..=1.0).contains(&amp[3]), "cell {i}: sphere {}", amp[3]);
        }
        // θ = 0 cells are isotropic: M⁻¹ = diag(1, 1, m11) after normalization, for both lobes.
        for a in 0..LTC_SIZE {
            for m in [LTC_MATRIX[cell_index(a, 0)], LTC_MATRIX_2[cell_index(a, 0)]] {
                assert!((m[0] - 1.0).abs() < 1e-6 && m[1] == 0.0 && m[2] == 0.0, "{m:?}");
            }
        }
    }

    #[test]
    fn committed_file_is_what_the_generator_writes() {
        // Same header (fit parameters, version, layout) and formatting: a fit with a non-default
        // value of a parameter the header records (every one but `error_samples`, which changes
        // no stored value), or an edit of the header or the format, shows up here; a value edited in
        // place (the expected text is written from the committed values) in the digest the
        // generator wrote. The re-fit of `CHECK_CELLS` and the table's own tests check values.
        let committed = include_str!("../../shared/src/ltc_table.rs");
        let generated = packed_table_source(&FitConfig::default(), PackedTable::committed());
        assert_eq!(
            raywave_shared::ltc_table::LTC_VALUES_DIGEST,
            PackedTable::committed().digest(),
            "a value of shared/src/ltc_table.rs was edited after generation"
        );
        assert!(committed == generated, "shared/src/ltc_table.rs differs from the generator's output");
    }

    #[test]
    fn ggx_ndf_and_visible_normals_are_normalized() {
        for alpha in [1e-3, 0.05, 0.3, 1.0] {
            let ggx = Ggx::new(alpha, DVec3::new(0.6, 0.0, 0.8));
            let ndf = graded_quadrature(DVec3::Z, PI / 2.0, 4, 600, |h| ggx.d(h) * h.z);
            assert!((ndf - 1.0).abs() < 1e-4, "α {alpha}: ∫D cos = {ndf}");
            // Visible normals: ∫ G1(v) max(0, v·h) D(h) / v.z dh = 1.
            let v = ggx.v;
            let vis =
                graded_quadrature(DVec3::Z, PI / 2.0, 4, 600, |h| ggx.g1_v() * v.dot(h).max(0.0) * ggx.d(h) / v.z);
            assert!((vis - 1.0).abs() < 1e-4, "α {alpha}: ∫D_v = {vis}");
        }
    }

    #[test]
    fn ggx_sampler_matches_its_pdf() {
        // pdf(sample(u)) against the density implied by the reflection, and the VNDF weight.
        let ggx = Ggx::new(0.3, DVec3::new(0.8, 0.0, 0.6));
        let mut rng = Rng(7);
        for _ in 0..1000 {
            let (l, h) = ggx.sample(rng.next_f64(), rng.next_f64());
            assert!((l.length() - 1.0).abs() < 1e-12);
            assert!((h - (l + ggx.v).normalize()).length() < 1e-9);
            let (f, pdf) = ggx.eval_pdf(l);
            let expect = ggx.g1_v() * ggx.d(h) / (4.0 * ggx.v.z);
            assert!((pdf - expect).abs() <= 1e-9 * expect);
            if l.z > 0.0 {
                assert!(f / pdf <= 1.0 + 1e-12);
            }
        }
        // ∫ pdf = 1 over the sphere (the sampler never fails).
        let total = graded_quadrature(DVec3::new(-0.8, 0.0, 0.6), PI, 3, 600, |l| ggx.eval_pdf(l).1);
        assert!((total - 1.0).abs() < 1e-3, "∫ pdf = {total}");
    }

    /// `(α, view, light, f·cos θ_l)` worked out by hand from the textbook formulas —
    /// `D = α²/(π((n·h)²(α² − 1) + 1)²)`, `Λ = (√(1 + α² tan²θ) − 1)/2`,
    /// `f·cos θ_l = D/(1 + Λ(v) + Λ(l))/(4 n·v)` — in `f64`, independently of the code (the
    /// `f64` references of the analytic-lighting tests integrate the fitter's own GGX, which the
    /// kernels' `GgxLobe` is held to there, so an error in it would pass them): the mirror
    /// direction (`h = n`), one off the plane of incidence, and one in it off the mirror.
    const CLOSED_FORM_POINTS: [(f64, [f64; 3], [f64; 3], f64); 3] = [
        (0.5, [0.6, 0.0, 0.8], [-0.6, 0.0, 0.8], 0.372_553_542),
        (0.3, [0.6, 0.0, 0.8], [0.0, 0.6, 0.8], 0.104_028_809),
        (0.3, [0.6, 0.0, 0.8], [-0.28, 0.0, 0.96], 0.621_955_898),
    ];

    /// The fitter's lobe at [`CLOSED_FORM_POINTS`], within 10⁻⁹ (the digits written).
    #[test]
    fn ggx_matches_the_textbook_formulas_at_worked_points() {
        for (alpha, view, light, expected) in CLOSED_FORM_POINTS {
            let (value, _) = Ggx::new(alpha, DVec3::from_array(view)).eval_pdf(DVec3::from_array(light));
            assert!((value - expected).abs() <= 1e-9, "α {alpha}, l {light:?}: {value} vs {expected}");
        }
    }

    #[test]
    fn ggx_albedo_is_at_most_one_and_matches_quadrature() {
        let mut previous = f64::INFINITY;
        for a in [0, 8, 16, 32, 48, 63] {
            for t in [0, 20, 40, 56, 63] {
                let ggx = Ggx::new(cell_alpha(a), cell_view(t));
                let m = lobe_moments(&ggx, 256);
                assert!(m.magnitude > 0.0 && m.magnitude <= 1.0, "({a}, {t}): {}", m.magnitude);
                assert!(m.fresnel >= 0.0 && m.fresnel < m.magnitude);
                if t == 0 {
                    // At normal incidence the albedo falls with roughness (masking loss).
                    assert!(m.magnitude < previous + 1e-9);
                    previous = m.magnitude;
                }
            }
        }
        // Nearly smooth, normal incidence: no masking loss, albedo 1.
        let smooth = lobe_moments(&Ggx::new(MIN_ALPHA, DVec3::Z), 64).magnitude;
        assert!((smooth - 1.0).abs() < 1e-6, "{smooth}");
        // Known value: at α = 1, D = 1/π, so the albedo at normal incidence is
        // ∫ cos/(4π(1 + Λ(l))) dl = ½∫₀¹ 1/(1 + Λ(μ)) dμ = ∫₀¹ μ/(1 + μ) dμ = 1 − ln 2 = 0.30685
        // (1-D quadrature, below).
        let n = 200_000;
        let one_d: f64 = (0..n)
            .map(|i| {
                let mu = (i as f64 + 0.5) / n as f64;
                // f·cos = D·G2/(4 v.z) with v.z = 1, Λ(v) = 0; dl = dμ dφ.
                2.0 * PI * (1.0 / PI) / (4.0 * (1.0 + Ggx::lambda(1.0, mu))) / n as f64
            })
            .sum();
        let vndf = lobe_moments(&Ggx::new(1.0, DVec3::Z), 256).magnitude;
        assert!((vndf - one_d).abs() < 1e-4, "{vndf} vs {one_d}");
        assert!((one_d - 0.30685).abs() < 1e-4, "{one_d}");
    }

    #[test]
    fn ltc_integrates_to_one_and_warp_matches_pdf() {
        let mut cases = vec![
            Ltc::new(DMat3::IDENTITY),
            Ltc::new(DMat3::from_cols(DVec3::new(0.5, 0.0, 0.1), DVec3::new(0.0, 0.7, 0.0), DVec3::new(0.2, 0.0, 1.0))),
        ];
        for (a, t) in [(63, 0), (63, 63), (40, 32), (32, 63), (24, 50)] {
            cases.push(Ltc::from_packed(LTC_MATRIX[cell_index(a, t)]));
            cases.push(Ltc::from_packed(LTC_MATRIX_2[cell_index(a, t)]));
        }
        for ltc in &cases {
            let peak = ltc.warp(DVec3::Z).0;
            let total = graded_quadrature(peak, PI, 3, 700, |l| ltc.pdf(l));
            assert!((total - 1.0).abs() < 1e-4, "∫ D = {total} for {:?}", ltc.m);
            let mut rng = Rng(3);
            for _ in 0..200 {
                let wo = cosine_direction(rng.next_f64(), rng.next_f64());
                let (l, pdf) = ltc.warp(wo);
                assert!((ltc.pdf(l) - pdf).abs() <= 1e-9 * pdf.max(1e-300), "{pdf} vs {}", ltc.pdf(l));
            }
        }
    }

    #[test]
    fn ltc_packing_round_trips() {
        for psi in [0.0, -0.4, -1.3, 0.2] {
            let params = LtcParams { m11: 0.3, m22: 0.2, m13: -0.05, psi };
            let ltc = params.ltc();
            let packed = ltc.packed().map(|x| x as f32);
            let back = LtcParams::from_packed(packed);
            let close = |x: f64, y: f64| (x - y).abs() < 1e-5 * (1.0 + x.abs());
            assert!(
                close(back.m11, 0.3) && close(back.m22, 0.2) && close(back.m13, -0.05) && close(back.psi, psi),
                "{params:?} → {back:?}"
            );
            // Same distribution from the packed form.
            let as_mixture = |ltc: Ltc| LtcMixtureDensity { ltcs: [ltc, ltc], weight: 1.0 };
            assert!(mixture_l1_distance(&as_mixture(ltc), &as_mixture(Ltc::from_packed(packed)), 32) < 1e-5);
        }
    }

    #[test]
    fn fitted_lobes_keep_their_mass_above_the_horizon() {
        // The LTC's mass below the surface is lost to the horizon clipping of `U`. Fitting the
        // frame angle keeps it small: measured over every third cell (FIT_VERSION 4), mean 0.3 %,
        // 90th percentile 1.0 %, at most 1.3 % for cos θ ≥ 0.2099 (col ≤ 56) (the single-lobe
        // FIT_VERSION 2: 0.25 %, 0.8 %, 1.2 %). ltc_code's fixed average-direction frame
        // (FIT_VERSION 1) left 2.1 %, 6.7 % and 10 %.
        let n = 64;
        let mut below: Vec<(f64, usize)> = vec![];
        for a in (0..LTC_SIZE).step_by(3) {
            for t in (0..LTC_SIZE).step_by(3) {
                let mix = PackedTable::committed().density(a, t);
                let below_of = |ltc: &Ltc| {
                    let count = (0..n * n)
                        .filter(|&k| {
                            let (u1, u2) = grid_sample(k, n);
                            ltc.warp(cosine_direction(u1, u2)).0.z < 0.0
                        })
                        .count();
                    count as f64 / (n * n) as f64
                };
                let below_horizon = mix.mix(below_of(&mix.ltcs[0]), below_of(&mix.ltcs[1]));
                below.push((below_horizon, t));
            }
        }
        let inner_max = below.iter().filter(|c| c.1 <= 56).map(|c| c.0).fold(0.0, f64::max);
        below.sort_by(|x, y| x.0.total_cmp(&y.0));
        let p90 = below[below.len() * 9 / 10].0;
        assert!(inner_max < 0.02 && p90 < 0.015, "below the horizon: col ≤ 56 max {inner_max}, p90 {p90}");
    }

    #[test]
    fn fit_error_changes_smoothly_with_roughness() {
        // A row whose warm-start chain along θ stays in a worse basin than its neighbours' shows
        // as a spike in its error across roughness: FIT_VERSION 3's row 16 had a 90th-percentile
        // relative L1 error of 0.213 against 0.137 and 0.154 in rows 15 and 17 (1.38×), and a
        // maximum of 0.66 against 0.43 and 0.41 (1.54×); no other row exceeded the larger of its
        // neighbours' by more than 9 %.
        const SPIKE_LIMIT: f64 = 1.2;
        let table = PackedTable::committed();
        let stats: Vec<[f64; 2]> = (0..LTC_SIZE)
            .into_par_iter()
            .map(|a| {
                let errors = (0..LTC_SIZE).map(|t| {
                    let ggx = Ggx::new(cell_alpha(a), cell_view(t));
                    let magnitude = f64::from(table.amplitude[cell_index(a, t)][0]);
                    relative_l1_error(&ggx, magnitude, &table.density(a, t), 64)
                });
                let (_, p90, max) = error_percentiles(errors.collect());
                [p90, max]
            })
            .collect();
        for a in 1..LTC_SIZE - 1 {
            for (k, name) in ["90th percentile", "maximum"].iter().enumerate() {
                let neighbours = stats[a - 1][k].max(stats[a + 1][k]);
                assert!(
                    stats[a][k] <= SPIKE_LIMIT * neighbours,
                    "row {a}: {name} error {} against {neighbours} in its neighbours",
                    stats[a][k]
                );
            }
        }
    }

    #[test]
    fn nelder_mead_finds_the_rosenbrock_minimum() {
        let rosen = |p: &[f64; 2]| (1.0 - p[0]).powi(2) + 100.0 * (p[1] - p[0] * p[0]).powi(2);
        let m = nelder_mead(rosen, [-1.2, 1.0], 0.1, 1e-14, 2000);
        assert!((m.x[0] - 1.0).abs() < 1e-4 && (m.x[1] - 1.0).abs() < 1e-4, "{m:?}");
    }

    #[test]
    fn nelder_mead_takes_nan_as_the_worst_value() {
        // NaN at the start: it had stayed first in the order, so the search ran every iteration
        // (its stop test NaN) and returned the start.
        let nan_at_start = |p: &[f64; 1]| if p[0] == 0.0 { f64::NAN } else { (p[0] - 1.0 / 3.0).powi(2) };
        let m = nelder_mead(nan_at_start, [0.0], 0.1, 1e-12, 400);
        assert!(m.value.is_finite() && (m.x[0] - 1.0 / 3.0).abs() < 1e-4, "{m:?}");
        // Nowhere finite: it stops at once instead of shrinking for every iteration.
        let m = nelder_mead(|_: &[f64; 2]| f64::NAN, [0.0, 0.0], 0.1, 1e-12, 400);
        assert_eq!((m.value, m.evals), (f64::INFINITY, 3));
    }

    #[test]
    fn sphere_form_factor_matches_numerical_integration() {
        let mut rng = Rng(11);
        for &(z, len) in &[
            (1.0, 0.3),
            (0.5, 0.1),
            (0.2, 0.3),
            (0.0, 0.5),
            (-0.3, 0.4),
            (-0.05, 0.01),
            (0.7, 0.9),
            (-0.3, 0.2),
            (-0.9, 0.99),
        ] {
            // Monte Carlo over the cap: uniform directions in the cone, weight max(0, cos).
            let sin2 = len;
            let cos_sigma = (1.0f64 - sin2).sqrt();
            let axis = DVec3::new((1.0f64 - z * z).sqrt(), 0.0, z);
            let x = DVec3::new(z, 0.0, -(1.0f64 - z * z).sqrt());
            let y = DVec3::Y;
            let n = 200_000;
            let mut sum = 0.0;
            for _ in 0..n {
                let c = 1.0 - rng.next_f64() * (1.0 - cos_sigma);
                let s = (1.0 - c * c).sqrt();
                let phi = 2.0 * PI * rng.next_f64();
                let d = s * phi.cos() * x + s * phi.sin() * y + c * axis;
                sum += d.z.max(0.0);
            }
            let mc = sum / n as f64 * 2.0 * PI * (1.0 - cos_sigma);
            let exact = sphere_cap_projected_solid_angle(z, sin2);
            assert!((mc - exact).abs() < 3e-3 * (PI * sin2), "z {z} len {len}: {exact} vs MC {mc}");
            // The form factor is that integral over the projected disc's area π·sin²σ.
            let ff = sphere_form_factor(z, len);
            assert!(
                (ff - mc / (PI * sin2)).abs() < 3e-3,
                "z {z} len {len}: form factor {ff} vs MC {}",
                mc / (PI * sin2)
            );
        }
        assert_eq!(sphere_form_factor(0.5, 0.0), 0.5);
        assert_eq!(sphere_form_factor(-0.5, 0.0), 0.0);
        // Continuous across the cases.
        for &len in &[0.1, 0.5, 0.99] {
            let s: f64 = f64::sqrt(len);
            for z in [s, -s] {
                let (a, b) = (sphere_form_factor(z + 1e-9, len), sphere_form_factor(z - 1e-9, len));
                assert!((a - b).abs() < 1e-6, "len {len} z {z}: {a} {b}");
            }
        }
    }

    #[test]
    fn committed_magnitude_and_fresnel_match_independent_integration() {
        // (1) Deterministic quadrature (see `albedo_by_quadrature`).
        for (a, t) in [(0, 0), (0, 40), (8, 63), (20, 32), (40, 60), (63, 0), (63, 63), (50, 20)] {
            let amp = LTC_AMPLITUDE[cell_index(a, t)];
            let (mag, fr) = albedo_by_quadrature(&Ggx::new(cell_alpha(a), cell_view(t)), 500);
            assert!((f64::from(amp[0]) - mag).abs() < 1e-3 * mag, "({a}, {t}): magnitude {} vs {mag}", amp[0]);
            assert!((f64::from(amp[1]) - fr).abs() < 1e-3 * mag, "({a}, {t}): fresnel {} vs {fr}", amp[1]);
        }
        // (2) Monte Carlo with pseudo-random normals drawn from D(h)·h.z (ltc_code's sampler, not
        //     the visible normals the fit uses), 1 %.
        for (a, t) in [(4, 10), (20, 40), (40, 50), (63, 30)] {
            let ggx = Ggx::new(cell_alpha(a), cell_view(t));
            let alpha = ggx.alpha;
            let mut rng = Rng(a as u64 * 100 + t as u64);
            let n = 400_000;
            let (mut mag, mut fr) = (0.0, 0.0);
            for _ in 0..n {
                let (u1, u2) = (rng.next_f64(), rng.next_f64());
                let phi = 2.0 * PI * u1;
                let r = alpha * (u2 / (1.0 - u2)).sqrt();
                let h = DVec3::new(r * phi.cos(), r * phi.sin(), 1.0).normalize();
                let vh = ggx.v.dot(h);
                if vh <= 0.0 {
                    continue;
                }
                let l = 2.0 * vh * h - ggx.v;
                let pdf = ggx.d(h) * h.z / (4.0 * vh);
                let w = ggx.eval_pdf(l).0 / pdf;
                mag += w;
                fr += w * (1.0 - vh).powi(5);
            }
            let (mag, fr) = (mag / n as f64, fr / n as f64);
            let amp = LTC_AMPLITUDE[cell_index(a, t)];
            assert!((f64::from(amp[0]) - mag).abs() < 0.01 * mag, "({a}, {t}): magnitude {} vs MC {mag}", amp[0]);
            assert!((f64::from(amp[1]) - fr).abs() < 0.01 * mag, "({a}, {t}): fresnel {} vs MC {fr}", amp[1]);
        }
    }

    #[test]
    fn refitting_committed_cells_reproduces_them() {
        let cfg = FitConfig::default();
        let checks = check_cells(&CHECK_CELLS, &PackedTable::committed(), &cfg);
        assert!(checks.len() >= 8);
        for c in &checks {
            let (a, t) = (c.refit.a, c.refit.t);
            assert!(c.l1_distance < CHECK_L1_TOLERANCE, "({a}, {t}): L1 {}", c.l1_distance);
            let v = CHECK_VALUE_TOLERANCE;
            assert!(c.magnitude_diff <= v && c.fresnel_diff <= v && c.sphere_diff <= v, "({a}, {t}): {c:?}");
        }
    }
}
