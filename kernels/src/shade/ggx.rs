//! The isotropic GGX lobe (height-correlated Smith masking-shadowing, `F = 1`) that the LTC table
//! was fitted to, at one shading point: what `U_S` stands for. With
//! `ShadeParams::analytic_residual` the stage integrates it over each light
//! ([`super::slope_quadrature`]) and its stochastic estimates evaluate it per sample.

// `!(x > 0.0)` sends NaN down the "below the horizon" branch on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

use crate::sampling::warp::{ggx_d, GGX_MIN_ALPHA};
use glam::{Vec2, Vec3};

/// `cos θ` of the most grazing view the table was fitted at (θ = 1.57,
/// `raywave_host::ltc_fit::MAX_THETA`); views beyond are evaluated there, as the lookup does.
pub const MIN_COS_VIEW: f32 = 7.963e-4;

/// The isotropic GGX lobe `f·cos θ_l` (F = 1, height-correlated Smith masking-shadowing) the LTC
/// table stands for, at one shading point, in the LTC frame (z = normal, view in the `+x` half).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct GgxLobe {
    /// `α = max(roughness², GGX_MIN_ALPHA)` (the table's fit clamps to the same 10⁻⁴).
    alpha: f32,
    /// Unit view direction, `z ≥ MIN_COS_VIEW`.
    view: Vec3,
    /// Smith `Λ` of the view.
    lambda_view: f32,
}

impl GgxLobe {
    /// The lobe for perceptual `roughness` (clamped to `[0, 1]`) seen from `cos_theta_v = n·v`
    /// (clamped to `[MIN_COS_VIEW, 1]`), the view in the frame's `+x` half as [`super::ltc::ShadingFrame`]
    /// puts it.
    pub fn new(roughness: f32, cos_theta_v: f32) -> Self {
        let r = if roughness > 0.0 { roughness.min(1.0) } else { 0.0 };
        let alpha = (r * r).max(GGX_MIN_ALPHA);
        let z = if cos_theta_v > MIN_COS_VIEW { cos_theta_v.min(1.0) } else { MIN_COS_VIEW };
        let view = Vec3::new((1.0 - z * z).max(0.0).sqrt(), 0.0, z);
        Self { alpha, view, lambda_view: smith_lambda(alpha * alpha, z) }
    }

    /// `f(v, l)·cos θ_l` (sr⁻¹) at the unit local direction `l`: `D(h)·G₂/(4 cos θ_v)`, 0 at or
    /// below the horizon. Integrates to the lobe's albedo (the table's magnitude).
    pub fn eval(&self, l: Vec3) -> f32 {
        if !(l.z > 0.0) {
            return 0.0;
        }
        let h = (self.view + l).normalize_or_zero();
        let d = ggx_d(h, Vec2::splat(self.alpha));
        d * self.masking(l.z) / (4.0 * self.view.z)
    }

    /// `α`, the slope-space width of the lobe's microfacet distribution.
    pub fn alpha(&self) -> f32 {
        self.alpha
    }

    /// The unit view direction in the frame (`+x` half, `z ≥ MIN_COS_VIEW`).
    pub fn view(&self) -> Vec3 {
        self.view
    }

    /// Smith's height-correlated masking-shadowing `G₂ = 1/(1 + Λ(v) + Λ(l))` towards a light
    /// direction with `cos θ_l = l_z > 0`.
    pub fn masking(&self, l_z: f32) -> f32 {
        1.0 / (1.0 + self.lambda_view + smith_lambda(self.alpha * self.alpha, l_z))
    }
}

/// Smith's `Λ = (√(1 + α² tan²θ) − 1)/2` for `cos θ = z ∈ (0, 1]`, as `ε/(2(1 + √(1 + ε)))`
/// with `ε = α² tan²θ` (no cancellation near the normal).
fn smith_lambda(alpha2: f32, z: f32) -> f32 {
    let z2 = z * z;
    // z2 floored: a direction a hair above the horizon (z² underflowing) gets a huge Λ, not ∞/∞.
    let eps = alpha2 * (1.0 - z2).max(0.0) / z2.max(1.0e-30);
    eps / (2.0 * (1.0 + (1.0 + eps).sqrt()))
}
