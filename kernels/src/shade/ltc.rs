//! Analytic unshadowed lighting U from quad lights with linearly transformed cosines (Heitz,
//! Dupuy, Hill, Neubelt 2016) over raywave's own fitted GGX table
//! (`raywave_shared::ltc_table`, fitted by `raywave_host::ltc_fit`).
//!
//! Per shading point and light the stage needs two *hit probabilities* (seed 000): `U_D`, the
//! clamped-cosine form factor of the light (the diffuse lobe), and `U_S`, the integral of the
//! specular LTC lobe over the light. Each is a form factor of the light's corners after a linear
//! map (identity, or the table's `M⁻¹`), so both come from [`super::polygon::quad_form_factor`].
//! With the directional albedos `E_D`, `E_S` the unshadowed radiance is
//! `U = L · (E_D·U_D + E_S·U_S)`.

use super::polygon::{quad_form_factor, Polygon};
use glam::{Mat3, Vec3, Vec4};
use raywave_shared::ltc_table::LTC_SIZE;
#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

/// Entries of the packed LTC table buffer: `LTC_SIZE²` matrices followed by `LTC_SIZE²`
/// amplitudes (`raywave_shared::ltc_table::{LTC_MATRIX, LTC_AMPLITUDE}` as `Vec4`s), so the GPU
/// binds one storage buffer.
pub const LTC_TABLE_LEN: u32 = 2 * LTC_SIZE * LTC_SIZE;

/// The fitted GGX lobe at one (roughness, view angle): the normalized `M⁻¹` in the shading frame
/// and the lobe's amplitude terms.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LtcLobe {
    /// `M⁻¹`, normalized to `m⁻¹₁₁ = 1` (scale does not change the distribution).
    pub inv_m: Mat3,
    /// Directional albedo of the GGX BRDF with F = 1: `∫ f·cos dω`.
    pub magnitude: f32,
    /// The Schlick Fresnel weight: specular albedo `E_S = F0·magnitude + (1 − F0)·fresnel`.
    pub fresnel: f32,
}

impl LtcLobe {
    /// Specular directional albedo `E_S` for normal-incidence reflectance `f0` (RGB).
    pub fn specular_albedo(&self, f0: Vec3) -> Vec3 {
        f0 * self.magnitude + (Vec3::ONE - f0) * self.fresnel
    }
}

/// Bilinear lookup of the lobe for perceptual `roughness` ∈ [0, 1] and `cos_theta_v = n·v`
/// (clamped to [0, 1]) in `table` ([`LTC_TABLE_LEN`] entries): rows are roughness, columns
/// `sqrt(1 − n·v)`, samples at `i/63`, as the table's header documents.
pub fn lookup(table: &[Vec4], roughness: f32, cos_theta_v: f32) -> LtcLobe {
    let last = (LTC_SIZE - 1) as f32;
    let r = if roughness > 0.0 { roughness.min(1.0) } else { 0.0 };
    let c = if cos_theta_v > 0.0 { cos_theta_v.min(1.0) } else { 0.0 };
    let s = r * last;
    let t = (1.0 - c).sqrt() * last;
    let s0 = (s as u32).min(LTC_SIZE - 2);
    let t0 = (t as u32).min(LTC_SIZE - 2);
    let (fs, ft) = (s - s0 as f32, t - t0 as f32);
    let at = |row: u32, col: u32, offset: u32| table[(offset + row * LTC_SIZE + col) as usize];
    let bilinear = |offset: u32| {
        let top = at(s0, t0, offset) * (1.0 - ft) + at(s0, t0 + 1, offset) * ft;
        let bottom = at(s0 + 1, t0, offset) * (1.0 - ft) + at(s0 + 1, t0 + 1, offset) * ft;
        top * (1.0 - fs) + bottom * fs
    };
    let m = bilinear(0);
    let amplitude = bilinear(LTC_SIZE * LTC_SIZE);
    LtcLobe {
        inv_m: Mat3::from_cols(Vec3::new(m.x, 0.0, m.y), Vec3::Y, Vec3::new(m.z, 0.0, m.w)),
        magnitude: amplitude.x,
        fresnel: amplitude.y,
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
    pub fn new(n: Vec3, v: Vec3) -> Self {
        let projected = v - n * n.dot(v);
        let tangent =
            if projected.length_squared() > 1.0e-12 { projected.normalize() } else { n.any_orthonormal_vector() };
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

/// `U_D`: the clamped-cosine form factor of the quad (local corners `quad`).
pub fn diffuse_form_factor(quad: [Vec3; 4]) -> f32 {
    quad_form_factor(quad)
}

/// `U_S`: the integral of the LTC lobe `inv_m` over the quad (local corners `quad`). The quad is
/// first clipped to the surface's horizon — the BRDF·cos the LTC stands for is zero below it,
/// while the LTC itself is not (its support is the half-space `(M⁻¹ω).z > 0`), so a light
/// crossing the horizon would otherwise collect lobe mass that does not exist — then mapped by
/// `M⁻¹` and integrated as a form factor (which clips it again, in the cosine's space).
pub fn specular_form_factor(inv_m: Mat3, quad: [Vec3; 4]) -> f32 {
    Polygon::quad(quad).clip_to_horizon().map(|q| inv_m * q).form_factor()
}

#[cfg(test)]
mod tests {
    use super::*;
    use raywave_shared::ltc_table::{LTC_AMPLITUDE, LTC_MATRIX};
    use std::vec::Vec;

    fn table() -> Vec<Vec4> {
        LTC_MATRIX.iter().chain(LTC_AMPLITUDE.iter()).map(|&v| Vec4::from_array(v)).collect()
    }

    #[test]
    fn lookup_at_grid_points_returns_the_table_entries() {
        let table = table();
        for (row, col) in [(0u32, 0u32), (10, 20), (63, 63), (40, 0), (0, 63)] {
            let roughness = row as f32 / 63.0;
            let t = col as f32 / 63.0;
            let lobe = lookup(&table, roughness, 1.0 - t * t);
            let i = (row * 64 + col) as usize;
            let m = LTC_MATRIX[i];
            let got = [lobe.inv_m.x_axis.x, lobe.inv_m.x_axis.z, lobe.inv_m.z_axis.x, lobe.inv_m.z_axis.z];
            for k in 0..4 {
                assert!((got[k] - m[k]).abs() <= 1e-4 * m[k].abs().max(1.0), "({row},{col}) {got:?} vs {m:?}");
            }
            assert!((lobe.magnitude - LTC_AMPLITUDE[i][0]).abs() < 1e-4);
        }
    }

    #[test]
    fn identity_lobe_is_the_diffuse_form_factor_and_a_hemisphere_light_catches_the_lobe() {
        let frame = ShadingFrame::new(Vec3::Y, Vec3::new(0.6, 0.8, 0.0));
        let quad = local_quad(&frame, Vec3::ZERO, Vec3::new(-0.3, 1.0, -0.2), Vec3::X * 0.5, Vec3::Z * 0.4);
        assert_eq!(specular_form_factor(Mat3::IDENTITY, quad), diffuse_form_factor(quad));
        // A huge light over the hemisphere holds (nearly) the whole LTC lobe at normal incidence.
        let table = table();
        for roughness in [0.1f32, 0.5, 1.0] {
            let lobe = lookup(&table, roughness, 1.0);
            let frame = ShadingFrame::new(Vec3::Z, Vec3::Z);
            let big = local_quad(&frame, Vec3::ZERO, Vec3::new(-1e4, -1e4, 1.0), Vec3::X * 2e4, Vec3::Y * 2e4);
            let u = specular_form_factor(lobe.inv_m, big);
            assert!((u - 1.0).abs() < 2e-3, "roughness {roughness}: {u}");
        }
    }

    #[test]
    fn hard_cases_stay_finite() {
        let table = table();
        for (roughness, cos_v) in [(0.0, 1.0), (0.0, 0.0), (1.0, 0.0), (f32::NAN, f32::NAN), (-1.0, 2.0)] {
            let lobe = lookup(&table, roughness, cos_v);
            assert!(lobe.inv_m.is_finite() && lobe.magnitude.is_finite() && lobe.fresnel.is_finite());
            let frame = ShadingFrame::new(Vec3::Z, Vec3::new(1.0, 0.0, 1e-7).normalize());
            let quad = local_quad(&frame, Vec3::ZERO, Vec3::new(-1.0, -1.0, 0.5), Vec3::X * 2.0, Vec3::Y * 2.0);
            let u = specular_form_factor(lobe.inv_m, quad);
            assert!(u.is_finite() && (0.0..=1.0).contains(&u), "{roughness} {cos_v}: {u}");
        }
        // View along the normal: any tangent, still orthonormal.
        let frame = ShadingFrame::new(Vec3::Z, Vec3::Z);
        assert!((frame.tangent.length() - 1.0).abs() < 1e-6 && frame.tangent.dot(Vec3::Z).abs() < 1e-6);
    }
}
