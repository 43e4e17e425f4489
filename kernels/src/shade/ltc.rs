//! Analytic unshadowed lighting U from quad lights with linearly transformed cosines (Heitz,
//! Dupuy, Hill, Neubelt 2016) over raywave's own fitted GGX table
//! (`raywave_shared::ltc_table`, fitted by `raywave_host::ltc_fit`).
//!
//! Per shading point and light the stage needs two *hit probabilities* (seed 000): `U_D`, the
//! clamped-cosine form factor of the light (the diffuse lobe), and `U_S`, the integral of the
//! specular LTC lobe over the light. Each is a form factor of the light's corners after a linear
//! map (identity, or the table's `M⁻¹`), so both come from one form factor
//! ([`super::polygon::Polygon::form_factor`]), and [`lobe_form_factors`] gives the pair; the
//! stage calls [`parallelogram_form_factors`], which integrates thin lights from their centre
//! lines instead ([`super::thin_strip`]).
//! The table's lobe is a mixture of two LTCs (one clamped cosine has lighter tails than GGX), so
//! `U_S` is the weighted sum of two such form factors.
//! With the directional albedos `E_D`, `E_S` the unshadowed radiance is
//! `U = L · (E_D·U_D + E_S·U_S)`.

use super::ggx::GgxLobe;
use super::polygon::Polygon;
use super::slope_quadrature::ggx_integral;
use super::thin_strip::{thin_parallelogram_form_factor, thin_parallelogram_ggx_integral};
use crate::sampling::warp;
use glam::{Mat3, Vec2, Vec3, Vec4};
use raywave_shared::ltc_table::LTC_SIZE;
#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

/// Entries of the packed LTC table buffer: `LTC_SIZE²` first-lobe matrices, `LTC_SIZE²`
/// second-lobe matrices, then `LTC_SIZE²` amplitudes (`raywave_shared::ltc_table::packed_entries`
/// as `Vec4`s), so the GPU binds one storage buffer.
pub const LTC_TABLE_LEN: u32 = 3 * LTC_SIZE * LTC_SIZE;

/// The fitted GGX lobe at one (roughness, view angle): a mixture `w·D₁ + (1 − w)·D₂` of two LTCs
/// (their normalized `M⁻¹` in the shading frame) and the lobe's amplitude terms.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LtcLobe {
    /// The first LTC's `M⁻¹`, normalized to `m⁻¹₁₁ = 1` (scale does not change the distribution).
    pub inv_m: Mat3,
    /// The second LTC's `M⁻¹`, normalized likewise.
    pub inv_m_2: Mat3,
    /// Weight `w ∈ [0, 1]` of the first LTC.
    pub weight: f32,
    /// Directional albedo of the GGX BRDF with F = 1: `∫ f·cos dω`.
    pub magnitude: f32,
    /// The Schlick Fresnel weight: specular albedo `E_S = F0·magnitude + (1 − F0)·fresnel`.
    pub fresnel: f32,
}

impl LtcLobe {
    /// A single LTC `inv_m` (both mixture lobes the same) with unit magnitude and no Fresnel term:
    /// for tests and for callers with their own transform.
    pub fn single(inv_m: Mat3) -> Self {
        Self { inv_m, inv_m_2: inv_m, weight: 1.0, magnitude: 1.0, fresnel: 0.0 }
    }

    /// Specular directional albedo `E_S` for normal-incidence reflectance `f0` (RGB).
    pub fn specular_albedo(&self, f0: Vec3) -> Vec3 {
        f0 * self.magnitude + (Vec3::ONE - f0) * self.fresnel
    }

    /// The mixture's density (sr⁻¹) at the local unit direction `local`.
    pub fn pdf(&self, local: Vec3) -> f32 {
        self.weight * warp::ltc_pdf(self.inv_m, local) + (1.0 - self.weight) * warp::ltc_pdf(self.inv_m_2, local)
    }

    /// A local direction drawn from the mixture with `u ∈ [0,1)²`: `u.x` picks the lobe (the
    /// first below `w`) and is rescaled to `[0, 1)` for that lobe's own cosine sample (which
    /// clamps it to `[0, 1 − 2⁻²⁴]` where the rescaling rounds up to 1). Its density is
    /// [`LtcLobe::pdf`].
    pub fn sample(&self, u: Vec2) -> Vec3 {
        let w = self.weight;
        let (inv_m, x) = if u.x < w { (self.inv_m, u.x / w) } else { (self.inv_m_2, (u.x - w) / (1.0 - w)) };
        warp::sample_ltc(warp::ltc_inverse(inv_m), Vec2::new(x, u.y))
    }
}

/// Bilinear lookup of the lobe for perceptual `roughness` ∈ [0, 1] and `cos_theta_v = n·v`
/// (clamped to [0, 1]) in `table` ([`LTC_TABLE_LEN`] entries): rows are roughness, columns
/// `sqrt(1 − n·v)`, samples at `i/63`, as the table's header documents. Of each cell's amplitudes
/// `(magnitude, fresnel, w, sphere)` the lobe takes the first three; the fourth, the sphere form
/// factor, is kept in the table for sphere lights (the clipless horizon-clipping variant) and
/// unused by this quad path, which clips each light to the horizon.
///
/// The four cells' mixtures are blended lobe by lobe, each lobe's `M⁻¹` weighted by the mass it
/// carries in its cell (bilinear weight × lobe weight), after each cell's two lobes are put in
/// the order closer to those of the cell weighing most (a weighted L1 distance of the entries).
/// The fit stores a cell's lobes in either order, and where neighbours differ, a plain bilinear
/// blend of the entries mixed a sharp lobe with a wide one (relative L1 error 0.23 halfway
/// between cells (7, 38) and (7, 39), whose own errors are 0.004); and a lobe of no weight in
/// its cell, whose entries the fit left anywhere up to ±10³, no longer pulls its neighbours'.
/// Below roughness 0.1 the blend of two sharp lobes points between them: halfway between cells
/// the lobe errs up to 1.98 of 2 (relative L1) at roughness < 0.016 and grazing views, where the
/// cells themselves err below 10⁻³ (README, Shading).
///
/// The heaviest cell changes at the midlines `fs = ½` and `ft = ½` of each square; the blend is
/// continuous across them where the four cells' orders agree whichever of them is the
/// reference — in every square of the committed table but one (tested). In the square of cells
/// (18, 34)–(19, 35) (roughness 0.286–0.302, θ_v 44.9°–46.3°) the pairwise matches contradict
/// one another around the square: cell (18, 35) holds two similar lobes (weights 0.60 / 0.40) and
/// keeps its order against (18, 34) and (19, 34) but swaps it against (19, 35), so no order rule
/// blending two lobes is continuous there. The lookup steps across `ft = ½` and across `fs = ½`
/// where `ft > ½`: the densities either side are up to 0.015 (across `ft = ½`) and 0.017
/// (across `fs = ½`) apart in L1 (of 2; the same at ±2·10⁻³ and ±2·10⁻⁴), so any light's `U_S`,
/// which differs by at most half the L1 distance, steps by at most 0.9 % of `E_S`.
///
/// # Panics
/// On the CPU, like slice indexing, if `table` holds fewer than [`LTC_TABLE_LEN`] entries (the
/// host's `ShadeData` always holds the whole table; a SPIR-V access out of bounds is undefined).
pub fn lookup(table: &[Vec4], roughness: f32, cos_theta_v: f32) -> LtcLobe {
    let last = (LTC_SIZE - 1) as f32;
    let r = if roughness > 0.0 { roughness.min(1.0) } else { 0.0 };
    let c = if cos_theta_v > 0.0 { cos_theta_v.min(1.0) } else { 0.0 };
    let s = r * last;
    let t = (1.0 - c).sqrt() * last;
    let s0 = (s as u32).min(LTC_SIZE - 2);
    let t0 = (t as u32).min(LTC_SIZE - 2);
    let (fs, ft) = (s - s0 as f32, t - t0 as f32);
    let cells = LTC_SIZE * LTC_SIZE;
    let at = |row: u32, col: u32, offset: u32| table[(offset + row * LTC_SIZE + col) as usize];
    let cell = |row: u32, col: u32| StoredMixture {
        first: at(row, col, 0),
        second: at(row, col, cells),
        weight: at(row, col, 2 * cells).z,
    };
    let corners = [
        (cell(s0, t0), (1.0 - fs) * (1.0 - ft)),
        (cell(s0, t0 + 1), (1.0 - fs) * ft),
        (cell(s0 + 1, t0), fs * (1.0 - ft)),
        (cell(s0 + 1, t0 + 1), fs * ft),
    ];
    let mut heaviest = 0;
    let mut k = 1;
    while k < 4 {
        if corners[k].1 > corners[heaviest].1 {
            heaviest = k;
        }
        k += 1;
    }
    let reference = corners[heaviest].0;
    let mut blend = LobeBlend::default();
    let mut k = 0;
    while k < 4 {
        let (mixture, bilinear) = corners[k];
        blend.add(mixture.aligned_with(&reference), bilinear);
        k += 1;
    }
    let amplitude = {
        let top = at(s0, t0, 2 * cells) * (1.0 - ft) + at(s0, t0 + 1, 2 * cells) * ft;
        let bottom = at(s0 + 1, t0, 2 * cells) * (1.0 - ft) + at(s0 + 1, t0 + 1, 2 * cells) * ft;
        top * (1.0 - fs) + bottom * fs
    };
    let inverse = |m: Vec4| Mat3::from_cols(Vec3::new(m.x, 0.0, m.y), Vec3::Y, Vec3::new(m.z, 0.0, m.w));
    let (first, second) = blend.lobes();
    LtcLobe {
        inv_m: inverse(first),
        inv_m_2: inverse(second),
        // The f32 sum of the four corners' masses: 1 + 2⁻²³ where all four store w = 1.
        weight: blend.first_mass.clamp(0.0, 1.0),
        magnitude: amplitude.x,
        fresnel: amplitude.y,
    }
}

/// One table cell's mixture as stored: the two lobes' packed `M⁻¹` entries
/// `(m⁻¹₀₀, m⁻¹₂₀, m⁻¹₀₂, m⁻¹₂₂)` and the first lobe's weight.
#[derive(Copy, Clone, Debug, PartialEq)]
struct StoredMixture {
    first: Vec4,
    second: Vec4,
    weight: f32,
}

impl StoredMixture {
    /// The same mixture with its lobes in the other order.
    fn swapped(self) -> Self {
        Self { first: self.second, second: self.first, weight: 1.0 - self.weight }
    }

    /// How far apart two cells' lobes are, slot by slot as a blend pairs them: each slot's L1
    /// distance between the entries weighted by its mean weight in the two cells, plus the
    /// difference of the weights.
    fn distance(&self, other: &Self) -> f32 {
        let l1 = |a: Vec4, b: Vec4| (a - b).abs().element_sum();
        0.5 * (self.weight + other.weight) * l1(self.first, other.first)
            + 0.5 * (2.0 - self.weight - other.weight) * l1(self.second, other.second)
            + (self.weight - other.weight).abs()
    }

    /// This mixture with its lobes in the order closer to `reference`'s.
    fn aligned_with(self, reference: &Self) -> Self {
        let swapped = self.swapped();
        if swapped.distance(reference) < self.distance(reference) {
            swapped
        } else {
            self
        }
    }
}

/// Sums for blending cells lobe by lobe: each lobe's entries weighted by its mass (bilinear
/// weight × lobe weight), and by the bilinear weight alone for a lobe of no mass anywhere.
#[derive(Copy, Clone, Default)]
struct LobeBlend {
    first_sum: Vec4,
    first_mass: f32,
    second_sum: Vec4,
    second_mass: f32,
    first_plain: Vec4,
    second_plain: Vec4,
}

impl LobeBlend {
    fn add(&mut self, mixture: StoredMixture, bilinear: f32) {
        let (first, second) = (bilinear * mixture.weight, bilinear * (1.0 - mixture.weight));
        self.first_sum += mixture.first * first;
        self.first_mass += first;
        self.second_sum += mixture.second * second;
        self.second_mass += second;
        self.first_plain += mixture.first * bilinear;
        self.second_plain += mixture.second * bilinear;
    }

    /// The blended lobes' entries.
    fn lobes(&self) -> (Vec4, Vec4) {
        let first = if self.first_mass > 0.0 { self.first_sum / self.first_mass } else { self.first_plain };
        let second = if self.second_mass > 0.0 { self.second_sum / self.second_mass } else { self.second_plain };
        (first, second)
    }
}

/// The LTC frame at a shading point: z = normal, x = the view direction projected onto the
/// tangent plane (any tangent when the view is along the normal), y = z × x.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ShadingFrame {
    /// Tangent towards the view.
    pub tangent: Vec3,
    /// `normal × tangent`.
    pub bitangent: Vec3,
    /// Unit shading normal.
    pub normal: Vec3,
}

impl ShadingFrame {
    /// The frame for unit normal `n` and unit view direction `v` (pointing away from the surface).
    /// The view's part across `n` keeps a rounding error of ~ε along `n`, which normalising a
    /// short one magnifies (a view 1.2·10⁻⁶ rad from `n` gave a tangent 0.26 along it, and `U`
    /// 12–51 % off): the tangent is projected off `n` once more after normalising.
    pub fn new(n: Vec3, v: Vec3) -> Self {
        let projected = v - n * n.dot(v);
        let tangent = if projected.length_squared() > 1.0e-12 {
            let rough = projected.normalize();
            (rough - n * n.dot(rough)).normalize()
        } else {
            n.any_orthonormal_vector()
        };
        Self { tangent, bitangent: n.cross(tangent), normal: n }
    }

    /// `w` in the frame's coordinates.
    pub fn to_local(&self, w: Vec3) -> Vec3 {
        Vec3::new(self.tangent.dot(w), self.bitangent.dot(w), self.normal.dot(w))
    }
}

/// The corners of the parallelogram `corner + s·edge_u + t·edge_v` relative to `p`, in `frame`.
pub fn local_quad(frame: &ShadingFrame, p: Vec3, corner: Vec3, edge_u: Vec3, edge_v: Vec3) -> [Vec3; 4] {
    let o = corner - p;
    // Written out: rust-gpu cannot compile `<[T; N]>::map` (it offsets pointers into the array).
    [frame.to_local(o), frame.to_local(o + edge_u), frame.to_local(o + edge_u + edge_v), frame.to_local(o + edge_v)]
}

/// `(U_D, U_S)` of the quad (local corners `quad`), the quad clipped to the surface's horizon
/// once for both lobes.
///
/// - `U_D`: the clamped-cosine form factor, in `[0, 1]`.
/// - `U_S`: the integral of the LTC mixture `lobe` over the clipped quad — each lobe's `M⁻¹` maps
///   it and a form factor integrates it (which clips it again, in the cosine's space), and the
///   two are mixed by the lobe's weight. The horizon clip comes first because the BRDF·cos the
///   LTC stands for is zero below the horizon while the LTC itself is not (its support is the
///   half-space `(M⁻¹ω).z > 0`): a light crossing the horizon would otherwise collect lobe mass
///   that does not exist.
/// - With `ggx`, `U_S` is instead that of the GGX lobe the table cell stands for: the LTC's plus
///   its residual towards GGX, the GGX lobe's integral over the light by [`ggx_integral`]
///   normalized by the table's magnitude (so that it takes the same albedo terms), in `[0, 1]`.
///   Accurate also where the LTC is not — lights that catch only the lobe's far tail, grazing
///   views — at the cost of about 14 radial integrals per light on the Cornell box's surfaces,
///   100–200 for a thin grazing strip ([`super::slope_quadrature`]).
pub fn lobe_form_factors(lobe: &LtcLobe, ggx: Option<GgxLobe>, quad: [Vec3; 4]) -> (f32, f32) {
    corners_form_factors(lobe, ggx, &Polygon::quad(quad).clip_to_horizon(), ThinLobes::NONE)
}

/// `(U_D, U_S)` as [`lobe_form_factors`] gives them, of the parallelogram light
/// `corner + s·edge_u + t·edge_v` (`s`, `t` in `[0, 1]`; world space) seen from `p` in `frame`.
/// Where the light is a thin strip in a lobe's space ([`super::thin_strip::THIN`]), that lobe's
/// integral comes from lines across the strip's width ([`thin_parallelogram_form_factor`]; with
/// `ggx`, [`thin_parallelogram_ggx_integral`]), which take the width as a vector: the corners'
/// edge sum and quadrature lose about `ε·d/w` of themselves to the corners' rounding
/// (`thin_strip::tests`). Other lobes take the corners' path, bit for bit as
/// [`lobe_form_factors`] of [`local_quad`].
pub fn parallelogram_form_factors(
    lobe: &LtcLobe,
    ggx: Option<GgxLobe>,
    frame: &ShadingFrame,
    p: Vec3,
    corner: Vec3,
    edge_u: Vec3,
    edge_v: Vec3,
) -> (f32, f32) {
    let (o, u, v) = (frame.to_local(corner - p), frame.to_local(edge_u), frame.to_local(edge_v));
    // The cosine's map, then the two LTCs' where no GGX lobe stands in for them. One call in a
    // loop rather than one per lobe: the thin path is then in the kernel once, not three times
    // (SPIR-V inlines every call, and lavapipe's compile time grows with the copies).
    let maps = [Mat3::IDENTITY, lobe.inv_m, lobe.inv_m_2];
    let map_count = if ggx.is_some() { 1 } else { maps.len() };
    let mut thin = [None; 3];
    let mut i = 0;
    while i < map_count {
        thin[i] = thin_parallelogram_form_factor(maps[i], o, u, v);
        i += 1;
    }
    let lobes = ThinLobes {
        diffuse: thin[0],
        first: thin[1],
        second: thin[2],
        residual: match ggx {
            Some(ggx) => thin_parallelogram_ggx_integral(&ggx, lobe.inv_m, o, u, v),
            None => None,
        },
    };
    if let Some(both) = lobes.all(lobe, ggx.is_some()) {
        return both;
    }
    let above = Polygon::quad(local_quad(frame, p, corner, edge_u, edge_v)).clip_to_horizon();
    corners_form_factors(lobe, ggx, &above, lobes)
}

/// The lobes' integrals that the thin-strip path gave ([`parallelogram_form_factors`]); `None`
/// where the corners integrate a lobe.
#[derive(Copy, Clone)]
struct ThinLobes {
    /// The clamped cosine's form factor.
    diffuse: Option<f32>,
    /// The first and second LTC's form factors.
    first: Option<f32>,
    second: Option<f32>,
    /// The GGX lobe's `∫ G dω` (with the residual).
    residual: Option<f32>,
}

impl ThinLobes {
    /// Nothing from the thin-strip path.
    const NONE: Self = Self { diffuse: None, first: None, second: None, residual: None };

    /// `(U_D, U_S)` where the thin-strip path gave every lobe they need.
    fn all(&self, lobe: &LtcLobe, with_residual: bool) -> Option<(f32, f32)> {
        let specular = if with_residual {
            by_magnitude(lobe, self.residual?)
        } else {
            match (self.first, self.second) {
                (Some(first), Some(second)) => mixed(lobe, first, second),
                _ => return None,
            }
        };
        self.diffuse.map(|diffuse| (diffuse, specular))
    }
}

/// `(U_D, U_S)` over `above` (local corners, already clipped to the horizon) for the lobes that
/// `thin` does not give.
fn corners_form_factors(lobe: &LtcLobe, ggx: Option<GgxLobe>, above: &Polygon, thin: ThinLobes) -> (f32, f32) {
    let diffuse = match thin.diffuse {
        Some(thin) => thin,
        None => above.form_factor_above_horizon(),
    };
    let specular = match ggx {
        Some(ggx) => by_magnitude(
            lobe,
            match thin.residual {
                Some(thin) => thin,
                None => ggx_integral(above, &ggx),
            },
        ),
        None => {
            // Both LTCs by one call in a loop, as in `parallelogram_form_factors`.
            let (maps, thin_ltcs) = ([lobe.inv_m, lobe.inv_m_2], [thin.first, thin.second]);
            let mut form_factors = [0.0; 2];
            let mut i = 0;
            while i < maps.len() {
                let map = maps[i];
                form_factors[i] = match thin_ltcs[i] {
                    Some(form_factor) => form_factor,
                    None => above.map(|q| map * q).form_factor(),
                };
                i += 1;
            }
            mixed(lobe, form_factors[0], form_factors[1])
        }
    };
    (diffuse, specular)
}

/// The GGX lobe's `∫ G dω` over a light as a `U_S`: over the table's magnitude (so that it takes
/// the same albedo terms), in `[0, 1]`; 0 where the magnitude is not positive.
fn by_magnitude(lobe: &LtcLobe, integral: f32) -> f32 {
    if lobe.magnitude.is_nan() || lobe.magnitude <= 0.0 {
        return 0.0;
    }
    (integral / lobe.magnitude).clamp(0.0, 1.0)
}

/// The mixture's `U_S` from its two LTCs' form factors.
#[inline]
fn mixed(lobe: &LtcLobe, first: f32, second: f32) -> f32 {
    lobe.weight * first + (1.0 - lobe.weight) * second
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hash::{pcg3d, unit_float};
    use raywave_shared::ltc_table::{packed_entries, LTC_AMPLITUDE, LTC_MATRIX, LTC_MATRIX_2};
    use std::vec::Vec;

    fn table() -> Vec<Vec4> {
        packed_entries().map(Vec4::from_array).collect()
    }

    /// The lookup between cells depends neither on the order a cell stores its lobes in nor on
    /// the entries of a lobe of no weight: around cells (7, 38) and (7, 39), the committed table
    /// with (7, 38) stored swapped gives the same density (to rounding), and so does (7, 39)
    /// made single-lobe (weight 1) with garbage as its second lobe instead of a copy of the first,
    /// stored either way round. The committed table holds the two cells in opposite orders: with
    /// a plain bilinear blend the density halfway between them erred by 0.23 (relative L1
    /// against GGX), by 0.010 with the lobes matched.
    #[test]
    fn lookup_ignores_lobe_order_and_weightless_lobes() {
        let table = table();
        let cells = (LTC_SIZE * LTC_SIZE) as usize;
        let index = |row: u32, col: u32| (row * LTC_SIZE + col) as usize;
        let swap = |table: &[Vec4], i: usize| {
            let mut table = table.to_vec();
            table.swap(i, cells + i);
            table[2 * cells + i].z = 1.0 - table[2 * cells + i].z;
            table
        };
        let single_lobe = |second: Vec4| {
            let (mut table, i) = (table.clone(), index(7, 39));
            table[2 * cells + i].z = 1.0;
            table[cells + i] = second;
            table
        };
        let copy = single_lobe(table[index(7, 39)]);
        let garbage = single_lobe(Vec4::new(-999.0, -41.0, 182.0, -22.8));
        let variants = [
            ("(7, 38) swapped", swap(&table, index(7, 38)), &table),
            ("a weightless lobe's entries", garbage.clone(), &copy),
            ("a weightless lobe, swapped", swap(&garbage, index(7, 39)), &copy),
        ];
        let directions = [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(-0.3, 0.5, 0.81), Vec3::new(0.9, 0.1, 0.42)];
        for (s, t) in [(7.0, 38.0), (7.5, 38.5), (7.25, 38.9), (6.6, 38.1), (7.9, 39.2), (8.0, 39.0)] {
            let (roughness, x) = (s / 63.0, t / 63.0);
            let cos_v = 1.0 - x * x;
            for (name, variant, reference) in &variants {
                let (a, b) = (lookup(variant, roughness, cos_v), lookup(reference, roughness, cos_v));
                for d in directions.map(Vec3::normalize) {
                    let (p, q) = (a.pdf(d), b.pdf(d));
                    assert!((p - q).abs() <= 1e-4 * p.max(q).max(1e-3), "{name} at ({s}, {t}), {d}: {p} vs {q}");
                }
            }
        }
    }

    /// `true` where a square's four cells (`lookup`'s corner order) are matched in the same
    /// relative orders whichever of them is the reference.
    fn orders_agree(corners: [StoredMixture; 4]) -> bool {
        let orders = |reference: &StoredMixture| corners.map(|c| c.aligned_with(reference) == c);
        let first = orders(&corners[0]);
        corners.iter().map(orders).all(|o| o == first || o == first.map(|kept| !kept))
    }

    /// The lookup's continuity across its squares' midlines, as its documentation states: the
    /// cells' orders agree in every square but (18, 34) (where no order rule can: the pairwise
    /// matches around it contradict one another), and there the density steps across `ft = ½`
    /// and across `fs = ½` where `ft > ½` — by the same L1 distance 2·10⁻³ and 2·10⁻⁴ either side
    /// — where elsewhere it changes by less than 10⁻³.
    #[test]
    fn lookup_steps_at_a_midline_only_where_the_cells_orders_contradict() {
        let table = table();
        let cells = (LTC_SIZE * LTC_SIZE) as usize;
        let cell = |row: u32, col: u32| {
            let i = (row * LTC_SIZE + col) as usize;
            StoredMixture { first: table[i], second: table[cells + i], weight: table[2 * cells + i].z }
        };
        let mut contradicting = Vec::new();
        for row in 0..LTC_SIZE - 1 {
            for col in 0..LTC_SIZE - 1 {
                let corners = [cell(row, col), cell(row, col + 1), cell(row + 1, col), cell(row + 1, col + 1)];
                if !orders_agree(corners) {
                    contradicting.push((row, col));
                }
            }
        }
        assert_eq!(contradicting, [(18, 34)]);

        // ∫|p − q| by 2¹⁴ fixed samples of (p + q)/2: the mean of 2|p − q|/(p + q).
        let l1 = |p: &LtcLobe, q: &LtcLobe| {
            let n = 1u32 << 14;
            let mut sum = 0.0f64;
            for i in 0..n {
                let h = pcg3d(glam::UVec3::new(i, 3, 5));
                let d = if i % 2 == 0 { p } else { q }.sample(Vec2::new(unit_float(h.x), unit_float(h.y)));
                let (a, b) = (p.pdf(d), q.pdf(d));
                sum += f64::from(2.0 * (a - b).abs() / (a + b));
            }
            sum / f64::from(n)
        };
        // The lookup at table coordinates (s, t): roughness s/63, sqrt(1 − cos θ_v) = t/63.
        let at = |s: f32, t: f32| lookup(&table, s / 63.0, 1.0 - (t / 63.0) * (t / 63.0));
        for delta in [2e-3, 2e-4] {
            let across_ft = |s: f32, t: f32| l1(&at(s, t - delta), &at(s, t + delta));
            let across_fs = |s: f32, t: f32| l1(&at(s - delta, t), &at(s + delta, t));
            let steps = [across_ft(18.6, 34.5), across_fs(18.5, 34.6)];
            assert!(steps.iter().all(|step| (0.01..0.02).contains(step)), "(18, 34), ±{delta}: {steps:?}");
            // In the same square across fs = ½ where ft < ½ (the heaviest cell changes between
            // cells whose orders the others agree on), and in its neighbour: continuous.
            let smooth = [across_fs(18.5, 34.25), across_ft(18.6, 33.5), across_fs(18.5, 33.6)];
            assert!(smooth.iter().all(|l1| *l1 < 1e-3), "±{delta}: {smooth:?}");
        }
    }

    #[test]
    fn lookup_at_grid_points_returns_the_table_entries() {
        let table = table();
        for (row, col) in [(0u32, 0u32), (10, 20), (63, 63), (40, 0), (0, 63)] {
            let roughness = row as f32 / 63.0;
            let t = col as f32 / 63.0;
            let lobe = lookup(&table, roughness, 1.0 - t * t);
            let i = (row * 64 + col) as usize;
            for (inv_m, m) in [(lobe.inv_m, LTC_MATRIX[i]), (lobe.inv_m_2, LTC_MATRIX_2[i])] {
                let got = [inv_m.x_axis.x, inv_m.x_axis.z, inv_m.z_axis.x, inv_m.z_axis.z];
                for k in 0..4 {
                    assert!((got[k] - m[k]).abs() <= 1e-4 * m[k].abs().max(1.0), "({row},{col}) {got:?} vs {m:?}");
                }
            }
            assert!((lobe.magnitude - LTC_AMPLITUDE[i][0]).abs() < 1e-4);
            assert!((lobe.weight - LTC_AMPLITUDE[i][2]).abs() < 1e-4);
        }
    }

    #[test]
    fn identity_lobe_is_the_diffuse_form_factor_and_a_hemisphere_light_catches_the_lobe() {
        let frame = ShadingFrame::new(Vec3::Y, Vec3::new(0.6, 0.8, 0.0));
        let quad = local_quad(&frame, Vec3::ZERO, Vec3::new(-0.3, 1.0, -0.2), Vec3::X * 0.5, Vec3::Z * 0.4);
        let (diffuse, specular) = lobe_form_factors(&LtcLobe::single(Mat3::IDENTITY), None, quad);
        assert!(diffuse > 0.01, "the light is above the horizon: {diffuse}");
        assert_eq!(specular, diffuse);
        // A huge light over the hemisphere holds (nearly) the whole LTC lobe at normal incidence,
        // also before each form factor's clamp to [0, 1], which would hide one too large.
        let table = table();
        for roughness in [0.1f32, 0.5, 1.0] {
            let lobe = lookup(&table, roughness, 1.0);
            let frame = ShadingFrame::new(Vec3::Z, Vec3::Z);
            let big = local_quad(&frame, Vec3::ZERO, Vec3::new(-1e4, -1e4, 1.0), Vec3::X * 2e4, Vec3::Y * 2e4);
            let u = lobe_form_factors(&lobe, None, big).1;
            let unclamped_form_factor = |inv_m: Mat3| {
                let clipped = Polygon::quad(big).clip_to_horizon().map(|q| inv_m * q).clip_to_horizon();
                (crate::shade::polygon::portable_edge_sum(&clipped.corners, clipped.count as usize)
                    / core::f32::consts::TAU)
                    .abs()
            };
            let unclamped = lobe.weight * unclamped_form_factor(lobe.inv_m)
                + (1.0 - lobe.weight) * unclamped_form_factor(lobe.inv_m_2);
            assert!(
                (u - 1.0).abs() < 2e-3 && (unclamped - 1.0).abs() < 2e-3,
                "roughness {roughness}: {u}, {unclamped}"
            );
        }
    }

    #[test]
    fn mixture_sampling_matches_its_pdf_and_form_factor() {
        // Two different lobes, 30 % / 70 %: a tilted sharp one and a wide one.
        let lobe = LtcLobe {
            inv_m: Mat3::from_cols(Vec3::new(4.0, 0.0, -1.0), Vec3::Y, Vec3::new(1.5, 0.0, 0.3)),
            inv_m_2: Mat3::from_cols(Vec3::new(1.0, 0.0, 0.0), Vec3::Y, Vec3::new(0.2, 0.0, 1.5)),
            weight: 0.3,
            ..LtcLobe::single(Mat3::IDENTITY)
        };
        let quad = [
            Vec3::new(-0.2, -0.5, 1.0),
            Vec3::new(0.8, -0.5, 1.0),
            Vec3::new(0.8, 0.5, 1.0),
            Vec3::new(-0.2, 0.5, 1.0),
        ];
        // The quad spans x ∈ [−0.2, 0.8], y ∈ [−0.5, 0.5] on the plane z = 1.
        let through_quad = |l: Vec3| {
            let p = l / l.z;
            l.z > 0.0 && (-0.2..=0.8).contains(&p.x) && (-0.5..=0.5).contains(&p.y)
        };
        let n = 1u32 << 18;
        let (mut hits, mut ratio_1, mut ratio_2) = (0u32, 0.0f64, 0.0f64);
        for i in 0..n {
            let h = pcg3d(glam::UVec3::new(i, 7, 11));
            let l = lobe.sample(Vec2::new(unit_float(h.x), unit_float(h.y)));
            let pdf = lobe.pdf(l);
            assert!(pdf > 0.0 && l.is_finite(), "{l} {pdf}");
            // E[p_k/p] = ∫ p_k = 1 for each lobe: the pdf is the density the sampler draws from.
            ratio_1 += f64::from(warp::ltc_pdf(lobe.inv_m, l) / pdf);
            ratio_2 += f64::from(warp::ltc_pdf(lobe.inv_m_2, l) / pdf);
            hits += u32::from(through_quad(l));
        }
        let (ratio_1, ratio_2) = (ratio_1 / f64::from(n), ratio_2 / f64::from(n));
        assert!((ratio_1 - 1.0).abs() < 0.02 && (ratio_2 - 1.0).abs() < 0.02, "{ratio_1} {ratio_2}");
        // The fraction of samples through the quad is the mixture's form factor (4σ binomial).
        let fraction = f64::from(hits) / f64::from(n);
        let form_factor = f64::from(lobe_form_factors(&lobe, None, quad).1);
        let sigma = (form_factor * (1.0 - form_factor) / f64::from(n)).sqrt();
        assert!((fraction - form_factor).abs() < 4.0 * sigma, "{fraction} vs {form_factor} ± {sigma}");
    }

    #[test]
    fn mixture_weights_stay_within_zero_and_one() {
        // Where all four cells store w = 1 (the smoothest rows), the f32 sum of the masses had
        // come to 1 + 2⁻²³, and the second lobe's weight 1 − w below 0.
        let table = table();
        assert_eq!(lookup(&table, 0.004_762_004_6, 0.899_067_7).weight, 1.0);
        for i in 0..4000 {
            let (roughness, t) = ((i % 200) as f32 / 199.0 * 4.0 / 63.0, (i / 200) as f32 / 19.0);
            let weight = lookup(&table, roughness, 1.0 - t * t).weight;
            assert!((0.0..=1.0).contains(&weight), "({roughness}, {t}): {weight}");
        }
    }

    #[test]
    fn hard_cases_stay_finite() {
        let table = table();
        for (roughness, cos_v) in [(0.0, 1.0), (0.0, 0.0), (1.0, 0.0), (f32::NAN, f32::NAN), (-1.0, 2.0)] {
            let lobe = lookup(&table, roughness, cos_v);
            assert!(lobe.inv_m.is_finite() && lobe.inv_m_2.is_finite() && lobe.weight.is_finite());
            assert!(lobe.magnitude.is_finite() && lobe.fresnel.is_finite());
            let frame = ShadingFrame::new(Vec3::Z, Vec3::new(1.0, 0.0, 1e-7).normalize());
            let quad = local_quad(&frame, Vec3::ZERO, Vec3::new(-1.0, -1.0, 0.5), Vec3::X * 2.0, Vec3::Y * 2.0);
            let u = lobe_form_factors(&lobe, None, quad).1;
            assert!(u.is_finite() && (0.0..=1.0).contains(&u), "{roughness} {cos_v}: {u}");
        }
        // View along the normal: any tangent, still orthonormal.
        let frame = ShadingFrame::new(Vec3::Z, Vec3::Z);
        assert!((frame.tangent.length() - 1.0).abs() < 1e-6 && frame.tangent.dot(Vec3::Z).abs() < 1e-6);
    }

    /// The specular albedo is Schlick's Fresnel split in F0, `F0·magnitude + (1 − F0)·fresnel`
    /// per channel: a surface of F0 = 1 reflects the magnitude alone, one of F0 = 0 only the
    /// Fresnel term, and between them the albedo is linear in F0 — checked per channel on a lobe
    /// with distinct amplitudes. No other kernel test separated the two terms.
    #[test]
    fn specular_albedo_is_the_schlick_split_sum() {
        let lobe = LtcLobe { magnitude: 0.8, fresnel: 0.1, ..LtcLobe::single(Mat3::IDENTITY) };
        assert_eq!(lobe.specular_albedo(Vec3::ONE), Vec3::splat(0.8));
        assert_eq!(lobe.specular_albedo(Vec3::ZERO), Vec3::splat(0.1));
        let albedo = lobe.specular_albedo(Vec3::new(0.04, 0.5, 0.9));
        let expected = Vec3::new(0.04 * 0.8 + 0.96 * 0.1, 0.5 * 0.8 + 0.5 * 0.1, 0.9 * 0.8 + 0.1 * 0.1);
        assert!((albedo - expected).abs().max_element() < 1e-6, "{albedo} vs {expected}");
    }

    /// Roughness and `n·v` outside [0, 1] are clamped, as documented: the lobe is exactly the
    /// one at the nearest end. The host refuses such roughness in scene files, but the stage
    /// takes whatever the material buffer holds; past row 63 the bilinear weights had
    /// extrapolated the last two rows (`fs` of 32 at roughness 1.5).
    #[test]
    fn roughness_and_cosine_outside_the_unit_interval_are_clamped() {
        let table = table();
        for cos_v in [0.0, 0.37, 1.0] {
            assert_eq!(lookup(&table, 1.5, cos_v), lookup(&table, 1.0, cos_v), "cos {cos_v}");
            assert_eq!(lookup(&table, -0.3, cos_v), lookup(&table, 0.0, cos_v), "cos {cos_v}");
        }
        for roughness in [0.0, 0.41, 1.0] {
            assert_eq!(lookup(&table, roughness, 1.8), lookup(&table, roughness, 1.0), "roughness {roughness}");
            assert_eq!(lookup(&table, roughness, -0.5), lookup(&table, roughness, 0.0), "roughness {roughness}");
        }
    }

    /// Two lights whose horizon crossings lie beside a far corner (`Polygon::clip_to_horizon`
    /// steps a crossing from the edge's end nearer the plane): `U_S` within 10⁻⁵ of the `f64`
    /// integral of the same looked-up lobe (clip, `M⁻¹`, clip, edge sum), where stepped from the
    /// edge's first end it came out 0.666 for 0.98860 (a shading point 3.5·10⁻⁶ of the light's
    /// size above its plane, beside its edge, roughness 10⁻³) and 0.803 for 0.98761 (a light
    /// 5·10⁵ times its distance, roughness 10⁻⁴): cases of a random sweep against that reference.
    #[test]
    fn horizon_crossings_beside_a_far_corner_keep_u_s() {
        let table = table();
        let cases = [
            (
                [
                    Vec3::new(0.019_226_85, 0.001_361_456_4, 0.020_053_694),
                    Vec3::new(-0.382_011_56, 0.778_104_8, -0.498_618_22),
                    Vec3::new(-0.474_302_38, -0.625_791_4, -0.619_211_26),
                    Vec3::new(0.005_245_579, 0.002_684_161_3, 0.021_096_053),
                    Vec3::new(0.022_944_279, -0.002_170_547_6, -0.001_710_505_5),
                    Vec3::new(0.0, -0.001_167_298_3, 0.001_481_244_3),
                ],
                1.054e-3,
                0.988_600_72,
            ),
            (
                [
                    Vec3::new(19.985_205, -76.195_145, -27.207_315),
                    Vec3::new(-0.771_254_6, -0.408_798_2, -0.487_904_04),
                    Vec3::new(-0.400_356_95, 0.907_180_25, -0.129_376_65),
                    Vec3::new(-8_577_047.0, -14_290_952.0, -12_695_864.0),
                    Vec3::new(18_572_232.0, 30_985_718.0, 27_585_210.0),
                    Vec3::new(28_129.791, 13_689.166, -34_315.55),
                ],
                1.168e-4,
                0.987_605_3,
            ),
        ];
        for ([p, n, v, corner, edge_u, edge_v], roughness, exact) in cases {
            let frame = ShadingFrame::new(n, v);
            let lobe = lookup(&table, roughness, n.dot(v));
            let (_, u_s) = parallelogram_form_factors(&lobe, None, &frame, p, corner, edge_u, edge_v);
            assert!((u_s - exact).abs() < 1e-5, "roughness {roughness}: {u_s} vs {exact}");
        }
    }

    /// Views within 10⁻⁶…10⁻³ rad of random normals: the frame stays orthonormal to 10⁻⁶ (a
    /// tangent normalised once leant up to 0.26 towards the normal at 1.2·10⁻⁶ rad).
    #[test]
    fn the_frame_is_orthonormal_for_views_near_the_normal() {
        let mut worst = 0.0f32;
        for i in 0..20_000u32 {
            let h = pcg3d(glam::UVec3::new(i, 17, 3));
            let [a, b, c] = [h.x, h.y, h.z].map(unit_float);
            let n = Vec3::new(2.0 * a - 1.0, 2.0 * b - 1.0, 2.0 * c - 1.0).normalize();
            if !n.is_finite() {
                continue;
            }
            let across = n.any_orthonormal_vector();
            let angle = 1.0e-6 * 1000f32.powf(unit_float(h.x ^ h.y));
            let v = (n + across * angle).normalize();
            let frame = ShadingFrame::new(n, v);
            let skew = [frame.tangent.dot(n), frame.bitangent.dot(n), frame.tangent.dot(frame.bitangent)]
                .into_iter()
                .chain([frame.tangent.length() - 1.0, frame.bitangent.length() - 1.0])
                .fold(0.0f32, |m, x| m.max(x.abs()));
            worst = worst.max(skew);
        }
        assert!(worst <= 1e-6, "worst departure from orthonormal {worst:e}");
    }
}
