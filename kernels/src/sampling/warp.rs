//! Warps from `[0,1)²` to directions, each with its pdf.
//!
//! Every warp comes as a pair: `sample_*` maps a 2-D sample `u` to a direction (or a point on a
//! light) and `*_pdf` evaluates the density, **with respect to solid angle**, with which that
//! sampler produces a given direction. The pairs agree to rounding, which is what multiple
//! importance sampling needs; `tests/warps.rs` checks every pair with a chi-square test.
//!
//! Formulas follow pbrt-v4 (`src/pbrt/util/sampling.h/.cpp`, `src/pbrt/shapes.h`,
//! `src/pbrt/util/scattering.h`) and the papers cited on each function; the numeric facts are
//! collected in `shared/reference/sampling-denoise.md` §2.
//!
//! # Numerics
//!
//! No NaN or Inf leaves this module. Every sample is clamped to `[0, 1 − 2⁻²⁴]`
//! ([`clamp_sample`]), every square root and inverse trigonometric function goes through a safe
//! helper ([`safe_sqrt`], [`safe_asin`], [`safe_acos`]), and every division is guarded. An input
//! that admits no density — a zero-solid-angle cone, a light seen exactly edge-on, a point light
//! in disguise (radius 0), a singular LTC matrix — yields **pdf 0 and a valid unit direction**
//! (+z, or the direction towards the light where that is defined): callers treat pdf 0 as "no
//! sample". Clamps are branches on comparisons rather than `f32::max`/`min`, so a NaN input
//! takes a defined path on GPUs too (SPIR-V `FMax`/`FMin` leave NaN operands undefined).
//!
//! Directions are unit vectors; "local frame" means z = surface normal (or cone axis).

// `!(a > b)` is how this module sends NaN down the safe branch; `partial_cmp` would obscure it.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::hash::ONE_MINUS_EPSILON;
use crate::trig;
use core::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};
use glam::{Mat3, Vec2, Vec3, Vec4, Vec4Swizzles};
use raywave_shared::sampling::warp_kind;
use raywave_shared::WarpParams;
#[cfg(target_arch = "spirv")]
use spirv_std::num_traits::Float;

/// 1/π: the cosine-hemisphere normalization.
const INV_PI: f32 = 1.0 / PI;
/// 1/(2π): the uniform-hemisphere pdf.
const INV_2PI: f32 = 1.0 / TAU;
/// 1/(4π): the uniform-sphere pdf.
const INV_4PI: f32 = 1.0 / (2.0 * TAU);

/// Angular slack (radians) with which the pdf functions of cone-shaped light warps accept a
/// direction just outside the cone: 4 `f32` ulps of 1. A direction sampled on the silhouette of
/// a sphere light (`u₀ → 1`), built from `1 − cos θ` and turned into the world by the cone's
/// frame, may round that far outside the exact cone — any of its directions, for a cone
/// narrower than that (a sphere 10⁸ radii away) —; the slack keeps `pdf(sample(u))` consistent
/// with the sampler. It widens the support by 4.8·10⁻⁷ rad (in `1 − cos θ`: `s·sin θmax + s²/2`),
/// negligible against any cone `f32` directions can resolve.
pub const CONE_SLACK: f32 = 4.0 * f32::EPSILON;

/// Slack with which the quad pdf functions accept a ray that hits the quad's plane just outside
/// an edge, relative to the rounding of the hit point: a ray of length `t` meeting the plane at
/// angle θl is accepted within `QUAD_EDGE_SLACK · t` (scene units) of an edge in any direction,
/// plus `QUAD_EDGE_SLACK · t · sin θl / |cos θl|` along the ray's projection onto the plane. Sampled
/// points lie on or inside the edges, but `normalize(point − p)` and the ray–plane intersection of
/// the pdf round them by a few ulps of `t` — the direction's rounding moves the hit point by that
/// much sideways, and by `1/|cos θl|` times it along the ray, as does the rounding of `t` itself —
/// so 16 ulps keeps `pdf(sample(u))` consistent while widening the quad by `~2·10⁻⁶·t` sideways
/// and `~2·10⁻⁶·t·tan θl` along the ray. (A slack of `t/|cos θl|` in every direction, as before,
/// let a ray at `|cos θl|` = 7.6·10⁻⁶ pass 0.15 units beside a light half a unit wide.)
pub const QUAD_EDGE_SLACK: f32 = 16.0 * f32::EPSILON;

/// Below this solid angle (sr) a quad light is sampled uniformly by area, both by
/// [`sample_quad_spherical`] and in [`quad_spherical_pdf`]: the spherical-rectangle sampler loses
/// precision in `f32` (its `sin(au)` is a difference of angles near π), and for such a small
/// quad area sampling is almost uniform in solid angle anyway. The value is pbrt-v4's threshold
/// in `SampleSphericalRectangle` (sampling.cpp).
pub const QUAD_MIN_SPHERICAL_SOLID_ANGLE: f32 = 1.0e-3;

/// The largest `|cos|` of the angle `ψ` between a quad's edges for which [`sample_quad_spherical`]
/// samples it by the spherical-rectangle method, whose frame needs perpendicular edges: as a
/// rectangle, each sample and its density sheared onto it ([`SphericalQuad`]). That is exact for
/// any shear; the threshold picks the strategy. The density's factor `(d_quad/d_rectangle)³` is
/// within `1 ± 2·|cot ψ|`: near 1 for a near-rectangle, far from uniform for a 60° rhombus
/// (`|cot ψ|` 0.58), which, with every parallelogram beyond the threshold, is sampled by area.
/// The scenes' lights are parallelograms within a relative 10⁻⁴ (`Scene::lights`), and a
/// rectangle's `f32` corners make `|cos ψ|` grow with its distance from the origin over its size
/// (~2·10⁻⁵ for a 10 cm lamp 20 m out): those keep the spherical method. Until 2026-11-30 the
/// rectangle's own samples were taken for the parallelogram's, off by `O(cos ψ)` of the lobe's
/// whole integral and, relative to a light's own `U` near its plane beside its edges, about `cos ψ`
/// × size / distance: a sweep measured `U_N` 3.0 % below `U` at `|cos ψ|` = 7·10⁻⁵ from a point
/// 4·10⁻⁵ of the light's size above its plane and 1.2·10⁻³ of it beside a corner, and the form
/// factor came out up to 5.9 % high beside an edge (test).
pub const QUAD_RECTANGLE_MAX_COS: f32 = 1.0e-4;

/// Whether the quad with edges `eu`, `ev` is a rectangle for [`sample_quad_spherical`]
/// ([`QUAD_RECTANGLE_MAX_COS`]), compared squared: no square roots on the sampling path (the
/// squares stay finite for edges within the scenes' coordinate limit).
fn is_rectangle(eu: Vec3, ev: Vec3) -> bool {
    let dot = eu.dot(ev);
    dot * dot <= QUAD_RECTANGLE_MAX_COS * QUAD_RECTANGLE_MAX_COS * eu.length_squared() * ev.length_squared()
}

/// A quad light as the spherical-rectangle method samples it from one point: computed once by
/// [`spherical_quad`] for a sample ([`sample_quad_spherical_with`]) and a pdf
/// ([`quad_spherical_pdf_at_hit`]), which must agree on it. A parallelogram within
/// [`QUAD_RECTANGLE_MAX_COS`] of a rectangle, `ev = ev⊥ + c·eu`, is sampled as a rectangle with
/// edges `eu`, `ev⊥` and each sample sheared onto it, `(s, t) ↦ (s + c·(t − t_p), t)`, pivoting
/// on the line `t = t_p` through the foot of the shading point, where the two coincide. The
/// shear keeps areas and the plane, so the density in solid angle becomes
/// `(d_quad/d_rectangle)³/Ω` (`dω = cos θl·dA/d²`, `cos θl = h/d` at the point's height `h`
/// above the plane), and the shear moves a point by at most `|cot ψ|` (≈ `|cos ψ|`) of its
/// in-plane distance from the point's foot: `d_quad²/d_rectangle²` is within `1 ± |cot ψ|`, and
/// the factor within `1 ± 2·|cot ψ|` (2·10⁻⁴ at the threshold) however close the point is to
/// the plane. (Pivoting on the edge `t = 0` moved the point's foot by `c·t_p·|eu|`, which
/// near the plane, `h` below that, made the factor heavy-tailed: a sweep's form factor 65 % low
/// to 10× high at 2¹⁶ samples, and `pdf(sample)` off by up to 3.7·10³×.)
#[derive(Copy, Clone, Debug)]
pub struct SphericalQuad {
    /// Solid angle (sr) of the rectangle the method samples ([`quad_solid_angle`]): the quad's
    /// own for a rectangle and for a parallelogram beyond [`QUAD_RECTANGLE_MAX_COS`], else the
    /// pivoted rectangle's. Below [`QUAD_MIN_SPHERICAL_SOLID_ANGLE`] the quad is sampled by area.
    solid_angle: f32,
    /// The sampled rectangle's corner `o + c·t_p·eu` relative to the shading point (`o − p` for
    /// a rectangle, but for the sign of a zero coordinate).
    corner: Vec3,
    /// The rectangle's second edge `ev⊥`: `ev` less its part along `eu` (`ev` itself, but for
    /// the sign of a zero coordinate, where `eu·ev` = 0 and for a parallelogram beyond
    /// [`QUAD_RECTANGLE_MAX_COS`]).
    edge_v: Vec3,
    /// `c`, `ev`'s part along `eu` in units of `eu`: 0 for a rectangle.
    shear: f32,
    /// Sampled by the spherical method: a quad within [`QUAD_RECTANGLE_MAX_COS`] of a rectangle
    /// whose rectangle subtends at least [`QUAD_MIN_SPHERICAL_SOLID_ANGLE`]; else by area
    /// ([`sample_quad_area`]), or not at all where the solid angle is 0.
    spherical: bool,
}

/// The quad light `o + s·eu + t·ev` seen from `p` as [`SphericalQuad`] describes it.
pub fn spherical_quad(p: Vec3, o: Vec3, eu: Vec3, ev: Vec3) -> SphericalQuad {
    let rectangle = eu.length_squared() > 0.0 && is_rectangle(eu, ev);
    let shear = if rectangle { eu.dot(ev) / eu.length_squared() } else { 0.0 };
    let edge_v = ev - shear * eu;
    // The pivot: `c·t_p` with `t_p = (p − o)·ev⊥/|ev⊥|²`, formed relative to p (no rounding
    // against the coordinates' magnitude far from the origin).
    let po = o - p;
    let corner = po - (shear * (po.dot(edge_v) / edge_v.length_squared())) * eu;
    let solid_angle = quad_solid_angle(Vec3::ZERO, corner, eu, edge_v);
    SphericalQuad {
        solid_angle,
        corner,
        edge_v,
        shear,
        spherical: rectangle && solid_angle >= QUAD_MIN_SPHERICAL_SOLID_ANGLE,
    }
}

/// Smallest GGX roughness α the GGX functions use; smaller inputs (including 0) are clamped to
/// it. At α = 10⁻⁴ the lobe is about as narrow as the angular resolution of `f32` unit vectors
/// near the normal (√(2⁻²⁴) ≈ 2.4·10⁻⁴ rad) and the peak of D is 1/(πα²) ≈ 3.2·10⁷, still finite.
/// Renderers should switch to a specular (delta) path well before, as pbrt-v4's
/// `TrowbridgeReitzDistribution::EffectivelySmooth` does below α = 10⁻³.
pub const GGX_MIN_ALPHA: f32 = 1.0e-4;

/// Largest GGX roughness α; larger inputs are clamped to it (keeps `αx·αy·t²` in range).
pub const GGX_MAX_ALPHA: f32 = 1.0e4;

/// Smallest cosine of the view direction with the normal that the GGX functions use: views more
/// grazing than this (or below the horizon) are treated as this grazing. `G1(v)/cos θv` stays
/// bounded by `2/α` there, so no pdf overflows.
pub const GGX_MIN_COS_VIEW: f32 = 1.0e-6;

// ---------------------------------------------------------------------------------------------
// Numeric helpers
// ---------------------------------------------------------------------------------------------

/// `sqrt(max(0, x))`, with NaN mapped to 0 (pbrt-v4 `SafeSqrt`, math.h). For quantities that
/// are ≥ 0 mathematically but may round slightly negative, such as `1 − cos²θ`.
pub fn safe_sqrt(x: f32) -> f32 {
    if x > 0.0 {
        x.sqrt()
    } else {
        0.0
    }
}

/// `x` clamped to `[−1, 1]`, NaN mapped to 0. The argument clamp of [`safe_asin`] and
/// [`safe_acos`].
pub fn clamp_unit_interval(x: f32) -> f32 {
    if x >= 1.0 {
        1.0
    } else if x <= -1.0 {
        -1.0
    } else if !x.is_nan() {
        x
    } else {
        0.0
    }
}

/// `asin` with its argument clamped to `[−1, 1]` (pbrt-v4 `SafeASin`, math.h); result in
/// `[−π/2, π/2]`.
pub fn safe_asin(x: f32) -> f32 {
    trig::asin(clamp_unit_interval(x))
}

/// `acos` with its argument clamped to `[−1, 1]` (pbrt-v4 `SafeACos`, math.h); result in `[0, π]`.
pub fn safe_acos(x: f32) -> f32 {
    trig::acos(clamp_unit_interval(x))
}

/// One sample component clamped to `[0, 1 − 2⁻²⁴]` ([`ONE_MINUS_EPSILON`]); NaN maps to 0.
pub fn clamp_sample_1d(x: f32) -> f32 {
    if x >= ONE_MINUS_EPSILON {
        ONE_MINUS_EPSILON
    } else if x > 0.0 {
        x
    } else {
        0.0
    }
}

/// A 2-D sample clamped to `[0, 1 − 2⁻²⁴]²`: every warp calls this first, so `u = 1` or a NaN
/// from a caller cannot push a warp outside its domain.
pub fn clamp_sample(u: Vec2) -> Vec2 {
    Vec2::new(clamp_sample_1d(u.x), clamp_sample_1d(u.y))
}

/// `x` if it is finite, else 0.
pub fn finite_or_zero(x: f32) -> f32 {
    if x.is_finite() {
        x
    } else {
        0.0
    }
}

/// A pdf made safe to return: finite and ≥ 0, anything else becomes 0.
pub fn sanitize_pdf(pdf: f32) -> f32 {
    if pdf.is_finite() && pdf > 0.0 {
        pdf
    } else {
        0.0
    }
}

/// The unit vector with polar angle θ (given as sin θ, cos θ) and azimuth φ around +z.
pub fn spherical_direction(sin_theta: f32, cos_theta: f32, phi: f32) -> Vec3 {
    let (sin_phi, cos_phi) = trig::sin_cos(phi);
    Vec3::new(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta)
}

/// `local` (z along `axis`) in world space, in the frame `axis.any_orthonormal_pair()` spans
/// around the unit `axis`: how a direction warped around +z is turned to a normal or cone axis.
pub fn local_to_world(axis: Vec3, local: Vec3) -> Vec3 {
    let (tangent, bitangent) = axis.any_orthonormal_pair();
    tangent * local.x + bitangent * local.y + axis * local.z
}

/// `direction` if it is finite and has a usable length, else +z; paired with a pdf that is zeroed
/// whenever the direction had to be replaced. The last step of every warp.
fn sanitize_sample(direction: Vec3, pdf: f32) -> Vec4 {
    let length_squared = direction.length_squared();
    if direction.is_finite() && length_squared > 0.5 && length_squared < 2.0 {
        direction.extend(sanitize_pdf(pdf))
    } else {
        Vec4::Z
    }
}

// ---------------------------------------------------------------------------------------------
// Disk, hemisphere, sphere, cone
// ---------------------------------------------------------------------------------------------

/// Shirley–Chiu concentric map of `[0,1)²` onto the unit disk (P. Shirley and K. Chiu, "A Low
/// Distortion Map Between Disk and Square", JGT 2(3), 1997; pbrt-v4 `SampleUniformDiskConcentric`,
/// sampling.h). Uniform in area (pdf 1/π per unit area); maps concentric squares to concentric
/// circles, so it keeps the stratification of low-discrepancy samples. Result in the closed unit
/// disk. Also the lens sample of the thin-lens camera.
pub fn sample_concentric_disk(u: Vec2) -> Vec2 {
    let u = clamp_sample(u);
    let offset = 2.0 * u - Vec2::ONE;
    if offset.x == 0.0 && offset.y == 0.0 {
        return Vec2::ZERO;
    }
    // Each branch divides by the component of larger magnitude, which is non-zero here.
    let (r, theta) = if offset.x.abs() > offset.y.abs() {
        (offset.x, FRAC_PI_4 * (offset.y / offset.x))
    } else {
        (offset.y, FRAC_PI_2 - FRAC_PI_4 * (offset.x / offset.y))
    };
    let (sin_theta, cos_theta) = trig::sin_cos(theta);
    r * Vec2::new(cos_theta, sin_theta)
}

/// Uniform direction on the hemisphere around +z: z = u₀, φ = 2πu₁ (pbrt-v4
/// `SampleUniformHemisphere`, sampling.h). Its pdf is [`uniform_hemisphere_pdf`] = 1/(2π).
pub fn sample_uniform_hemisphere(u: Vec2) -> Vec3 {
    let u = clamp_sample(u);
    let z = u.x;
    spherical_direction(safe_sqrt(1.0 - z * z), z, TAU * u.y)
}

/// Solid-angle pdf of [`sample_uniform_hemisphere`]: 1/(2π) for `dir.z ≥ 0`, else 0 (sr⁻¹).
pub fn uniform_hemisphere_pdf(dir: Vec3) -> f32 {
    if dir.z >= 0.0 {
        INV_2PI
    } else {
        0.0
    }
}

/// Cosine-weighted direction on the hemisphere around +z by Malley's method: a uniform point on
/// the concentric disk ([`sample_concentric_disk`]) lifted to the hemisphere, z = √(1 − x² − y²)
/// (pbrt-v4 `SampleCosineHemisphere`, sampling.h). Its pdf is [`cosine_hemisphere_pdf`] = cos θ/π;
/// points on the rim of the disk (u on the border of the square, e.g. u = 0) give z = 0 and pdf 0.
pub fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = sample_concentric_disk(u);
    Vec3::new(d.x, d.y, safe_sqrt(1.0 - d.x * d.x - d.y * d.y))
}

/// Solid-angle pdf of [`sample_cosine_hemisphere`]: `max(z, 0)/π` (sr⁻¹).
pub fn cosine_hemisphere_pdf(dir: Vec3) -> f32 {
    if dir.z > 0.0 {
        dir.z * INV_PI
    } else {
        0.0
    }
}

/// Uniform direction on the unit sphere: z = 1 − 2u₀, φ = 2πu₁ (pbrt-v4 `SampleUniformSphere`,
/// sampling.h). Its pdf is [`uniform_sphere_pdf`].
pub fn sample_uniform_sphere(u: Vec2) -> Vec3 {
    let u = clamp_sample(u);
    let z = 1.0 - 2.0 * u.x;
    spherical_direction(safe_sqrt(1.0 - z * z), z, TAU * u.y)
}

/// Solid-angle pdf of [`sample_uniform_sphere`]: 1/(4π) sr⁻¹ for every direction.
pub fn uniform_sphere_pdf() -> f32 {
    INV_4PI
}

/// `cos θmax` of a cone clamped to `[−1, 1]` (NaN → 0) and its `1 − cos θmax`.
fn cone_extent(cos_theta_max: f32) -> (f32, f32) {
    let cos_max = clamp_unit_interval(cos_theta_max);
    (cos_max, 1.0 - cos_max)
}

/// Uniform direction in the cone of half-angle θmax around +z: `1 − cos θ = u₀·(1 − cos θmax)`,
/// φ = 2πu₁ (pbrt-v4 `SampleUniformCone`, sampling.h, written with `1 − cos θ` as the variable so
/// that sin θ = √((1 − cos θ)(1 + cos θ)) keeps full precision in tiny cones). `cos_theta_max` is
/// clamped to `[−1, 1]`; −1 is the whole sphere. Its pdf is [`uniform_cone_pdf`].
///
/// Degenerate cone: for `cos_theta_max = 1` (a cone of zero solid angle — a delta distribution,
/// which no solid-angle pdf represents) the direction is +z and [`uniform_cone_pdf`] is 0, so
/// callers see "no sample". Cones of any positive `1 − cos θmax` representable in `f32` (down to
/// 2⁻²⁴, e.g. `cos θmax = 1 − 10⁻⁷` which rounds to `1 − 2⁻²³`) are sampled normally, with a large
/// but finite pdf (≈ 1.3·10⁶ sr⁻¹ at `1 − 2⁻²³`).
pub fn sample_uniform_cone(u: Vec2, cos_theta_max: f32) -> Vec3 {
    let u = clamp_sample(u);
    let (_, one_minus_cos_max) = cone_extent(cos_theta_max);
    let one_minus_cos = u.x * one_minus_cos_max;
    let sin_theta = safe_sqrt(one_minus_cos * (2.0 - one_minus_cos));
    spherical_direction(sin_theta, 1.0 - one_minus_cos, TAU * u.y)
}

/// Solid-angle pdf of [`sample_uniform_cone`]: `1/(2π(1 − cos θmax))` for unit `dir` with
/// `dir.z ≥ cos θmax`, else 0 (sr⁻¹). 0 for the degenerate cone `cos θmax = 1`.
pub fn uniform_cone_pdf(dir: Vec3, cos_theta_max: f32) -> f32 {
    let (cos_max, one_minus_cos_max) = cone_extent(cos_theta_max);
    if one_minus_cos_max > 0.0 && dir.z >= cos_max {
        sanitize_pdf(1.0 / (TAU * one_minus_cos_max))
    } else {
        0.0
    }
}

// ---------------------------------------------------------------------------------------------
// Lights
// ---------------------------------------------------------------------------------------------

/// A point sampled on a light, seen from the shading point `p`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LightSample {
    /// Unit direction from `p` towards `point`.
    pub direction: Vec3,
    /// Distance from `p` to `point` (scene units, finite, ≥ 0): the `tmax` of the shadow ray.
    pub distance: f32,
    /// Density of the sample with respect to solid angle at `p` (sr⁻¹); 0 means "no sample".
    pub pdf: f32,
    /// The sampled point on the light's surface (scene units).
    pub point: Vec3,
    /// Unit surface normal of the light at `point`: outward for spheres, `normalize(eu × ev)` for
    /// quads (whichever side `p` is on; the caller decides which side emits).
    pub normal: Vec3,
}

impl LightSample {
    /// The sample that means "no sample": pdf 0, direction +z, zero distance, `point` and `normal`
    /// as given (sanitized).
    fn none(point: Vec3, normal: Vec3) -> Self {
        LightSample {
            direction: Vec3::Z,
            distance: 0.0,
            pdf: 0.0,
            point: if point.is_finite() { point } else { Vec3::ZERO },
            normal: if normal.is_finite() { normal } else { Vec3::Z },
        }
    }

    /// The sample towards `point` with pdf `pdf`, given `w = point − p` formed without going
    /// through `point`'s absolute coordinates (from `p`'s offset to the light, as `(c − p) + r·n`):
    /// far from the origin, `(p + w) − p` would round `w` to the grid of `p`'s coordinates — a
    /// light a centimetre across 10⁴ units out would get a few hundred distinct directions, some
    /// of which miss it. [`LightSample::none`] when any part is not finite or `w` is zero.
    fn along(w: Vec3, point: Vec3, normal: Vec3, pdf: f32) -> Self {
        let distance = w.length();
        Self::toward(w / distance, distance, point, normal, pdf)
    }

    /// The sample towards `point` along the unit `direction` at `distance`, for a warp that
    /// builds them itself ([`LightSample::none`] when any part is not finite or the distance is
    /// not positive): `w = distance·direction` may be too small to square in `f32`.
    fn toward(direction: Vec3, distance: f32, point: Vec3, normal: Vec3, pdf: f32) -> Self {
        if distance > 0.0 && distance.is_finite() && direction.is_finite() && normal.is_finite() {
            LightSample { direction, distance, pdf: sanitize_pdf(pdf), point, normal }
        } else {
            Self::none(point, normal)
        }
    }
}

/// Sphere light of centre `c` and radius `r` seen from `p`: the pieces of its subtended cone.
/// `inside` is set when `p` is inside (or on) the sphere; the other fields are then unused.
struct SphereCone {
    inside: bool,
    /// Unit axis from `p` towards `c`.
    axis: Vec3,
    /// `|c − p|`.
    distance: f32,
    /// sin²θmax = r²/|c − p|².
    sin2_max: f32,
    /// 1 − cos θmax, computed as `sin²θmax / (1 + cos θmax)`, which does not cancel for tiny cones.
    one_minus_cos_max: f32,
}

fn sphere_cone(p: Vec3, c: Vec3, r: f32) -> SphereCone {
    let wc = c - p;
    // |c − p| scaled by its largest component, so that its square neither underflows (a sphere
    // 10⁻²³ across) nor overflows; 0/0 is NaN, which takes the inside path.
    let scale = wc.abs().max_element();
    let unit_wc = wc / scale;
    let dc = scale * unit_wc.length();
    // `!(a > b)` so that NaN inputs take the inside (area-sampling) path, which sanitizes them.
    // Judged on the distance, not its square: where |c − p| rounds to r the cone's sampler would
    // put every point at distance 0.
    if !(dc > r) {
        return SphereCone { inside: true, axis: Vec3::Z, distance: 0.0, sin2_max: 1.0, one_minus_cos_max: 1.0 };
    }
    let ratio = r / dc;
    let sin2_max = ratio * ratio;
    let one_minus_cos_max = sin2_max / (1.0 + safe_sqrt(1.0 - sin2_max));
    SphereCone { inside: false, axis: unit_wc.normalize(), distance: dc, sin2_max, one_minus_cos_max }
}

/// Samples the sphere light (centre `c`, radius `r > 0`) as seen from `p` uniformly within the
/// cone it subtends (pbrt-v4 `Sphere::Sample(ctx, u)`, shapes.h): `1 − cos θ = u₀·(1 − cos θmax)`
/// (equivalent to pbrt's `cos θ = (cos θmax − 1)u₀ + 1`, written without cancellation, and
/// `sin²θ = (1 − cos θ)(1 + cos θ)`). pbrt's small-angle branch, which samples `sin²θ =
/// sin²θmax·u₀` under the constant pdf below, is left out: that draw's density is
/// `cos θ/(π sin²θmax)`, up to `(1 − cos θmax)/(1 + cos θmax) ≈ sin²θmax/4` off the pdf it returns
/// (relative, at the cone's axis and rim), and the form used here needs no
/// such branch. The direction is built from `(θ, φ)` in the cone's frame, and the point on the
/// sphere from the distance to the near intersection, `t = (d − r)·((d + r)/d)/(cos θ + √(sin²θmax
/// − sin²θ))` (`d = |c − p|`; the product form does not cancel when `p` is near the sphere, and
/// forms neither `d²` nor `d·r`, which overflow or underflow at extreme scales), with
/// `sin²θmax − sin²θ = (1 − u₀)(1 − cos θmax)(cos θ + cos θmax)`, which does not cancel at the rim.
/// pbrt-v4 instead takes the point from the angle α at the centre, `cos α = sin²θ/sin θmax +
/// cos θ·√(1 − sin²θ/sin²θmax)`, and the direction back from it: `cos α` rounds to 1 in `f32`
/// for α below ~3·10⁻⁴, which `p` close to the sphere sees as a large angle — 10⁻³ off a unit
/// sphere that direction was 3·10⁻³ rad from the drawn one at the median and 0.46 rad at worst
/// (5·10⁻² off: 2.4·10⁻³ rad at worst); now both stay within a few ulps.
///
/// pdf = 1/(2π(1 − cos θmax)) sr⁻¹, every sampled direction hits the sphere's visible side.
/// If `p` is inside or on the sphere, falls back to [`sample_sphere_light_area`] (pbrt-v4 does the
/// same). Radius 0 (a point light) gives pdf 0. Its pdf is [`sphere_light_cone_pdf`].
pub fn sample_sphere_light_cone(p: Vec3, c: Vec3, r: f32, u: Vec2) -> LightSample {
    let u = clamp_sample(u);
    let r = r.abs();
    let cone = sphere_cone(p, c, r);
    if cone.inside {
        return sample_sphere_light_area(p, c, r, u);
    }
    if !(cone.sin2_max > 0.0) {
        // A point light (or a sphere too small for f32 at this distance): no density.
        return LightSample::none(c, Vec3::Z);
    }
    let one_minus_cos = u.x * cone.one_minus_cos_max;
    let (sin2_theta, cos_theta) = (one_minus_cos * (2.0 - one_minus_cos), 1.0 - one_minus_cos);
    // Azimuth φ + π, as pbrt-v4's point at azimuth φ around the centre is seen from `p`.
    let local = spherical_direction(safe_sqrt(sin2_theta), cos_theta, TAU * u.y);
    let direction = local_to_world(cone.axis, Vec3::new(-local.x, -local.y, local.z));
    let cos_max = 1.0 - cone.one_minus_cos_max;
    let rim = safe_sqrt((1.0 - u.x) * cone.one_minus_cos_max * (cos_theta + cos_max));
    let d = cone.distance;
    let t = (d - r) * ((d + r) / d) / (cos_theta + rim);
    // The normal at the point from the angle α at the centre (pbrt-v4's), its terms written
    // without cancellation: cos α = (d − t·cos θ)/r = (sin²θ + cos θ·√(sin²θmax − sin²θ))/sin θmax,
    // sin α = t·sin θ/r. As `(t·ω − (c − p))/r` it lost ulp(d)/r: 0.06 rad at d = 10⁶·r.
    let sin_max = cone.sin2_max.sqrt();
    let cos_alpha = clamp_unit_interval((sin2_theta + cos_theta * rim) / sin_max);
    let sin_alpha = t / r * safe_sqrt(sin2_theta);
    let normal = -local_to_world(cone.axis, spherical_direction(sin_alpha, cos_alpha, TAU * u.y)).normalize();
    LightSample::toward(direction, t, c + r * normal, normal, 1.0 / (TAU * cone.one_minus_cos_max))
}

/// Solid-angle pdf of [`sample_sphere_light_cone`] for unit `dir` (sr⁻¹):
/// 1/(2π(1 − cos θmax)) inside the subtended cone (widened by [`CONE_SLACK`]), else 0. The inside test uses `1 − cos θ = |d × a|²/(1 + d·a)`,
/// which stays accurate for tiny cones. If `p` is inside the sphere it is
/// [`sphere_light_area_pdf`], matching the sampler's fallback.
pub fn sphere_light_cone_pdf(p: Vec3, c: Vec3, r: f32, dir: Vec3) -> f32 {
    let r = r.abs();
    let cone = sphere_cone(p, c, r);
    if cone.inside {
        return sphere_light_area_pdf(p, c, r, dir);
    }
    if !(cone.sin2_max > 0.0) {
        return 0.0;
    }
    let d = dir.normalize_or_zero();
    let cos_theta = d.dot(cone.axis);
    if !(cos_theta > 0.0) {
        return 0.0;
    }
    let one_minus_cos = d.cross(cone.axis).length_squared() / (1.0 + cos_theta);
    // 1 − cos(θmax + s) ≤ 1 − cos θmax + s·sin θmax + s²/2 for the slack angle s.
    let slack = cone.sin2_max.sqrt() * CONE_SLACK + 0.5 * CONE_SLACK * CONE_SLACK;
    if one_minus_cos <= cone.one_minus_cos_max + slack {
        sanitize_pdf(1.0 / (TAU * cone.one_minus_cos_max))
    } else {
        0.0
    }
}

/// Samples the sphere light (centre `c`, radius `r`) uniformly by area over its **whole**
/// surface (pbrt-v4 `Sphere::Sample(u)`), and converts the area pdf 1/(4πr²) to solid angle at
/// `p`: `pdf = d²/(|cos θl|·4πr²)` with `d` the distance and θl the angle between the light
/// normal and the direction back to `p`.
///
/// Points on the far side (`normal·(p − point) ≤ 0`) are returned too, with `|cos θl|`: they
/// carry no light (the sphere emits outwards and occludes them) but are legitimate samples of
/// this strategy. The returned `pdf` is the density of *this point*; the density of the
/// *direction*, which two points (front and back) can produce, is [`sphere_light_area_pdf`].
/// A point seen exactly edge-on (`cos θl = 0`) gets pdf 0.
pub fn sample_sphere_light_area(p: Vec3, c: Vec3, r: f32, u: Vec2) -> LightSample {
    let r = r.abs();
    let normal = sample_uniform_sphere(u);
    let w = (c - p) + r * normal;
    let d2 = w.length_squared();
    let d = d2.sqrt();
    let cos_abs = normal.dot(w).abs();
    // d²/(|cos|·A) with |cos| = |n·w|/d: d³/(|n·w|·4πr²).
    let area = 2.0 * TAU * r * r;
    let pdf = if cos_abs > 0.0 && area > 0.0 { d2 * d / (cos_abs * area) } else { 0.0 };
    LightSample::along(w, c + r * normal, normal, pdf)
}

/// Solid-angle density (sr⁻¹) with which [`sample_sphere_light_area`] produces the unit
/// direction `dir` from `p`. A ray from `p` along `dir` meets the sphere at up to two points, and
/// area sampling can produce the direction through either, so the density is the **sum over the
/// intersections in front of `p`** of `tᵢ²/(|cos θᵢ|·4πr²)`. Both intersections see the same
/// `|cos θ| = √disc / r` (disc = r² − (distance from `c` to the ray)²), which gives the closed form
/// `(t₀² + t₁²)/(4πr·√disc)`. With `p` outside the sphere this integrates to 1 over the directions
/// that hit the sphere; from inside only the forward intersection counts. A ray that misses or
/// exactly grazes the sphere gets 0.
///
/// Precision: an `f32` direction fixes the ray's distance from `c` only to about
/// `|c − p|·2⁻²⁴`, so for a sphere far away (`|c − p| ≳ 10³·r`) directions within that distance
/// of the silhouette may be judged to miss (pdf 0) or get a `|cos θ|` off by a large factor.
/// Such directions carry almost no light (`cos θ → 0` there); the cone sampler has no such issue.
pub fn sphere_light_area_pdf(p: Vec3, c: Vec3, r: f32, dir: Vec3) -> f32 {
    let r = r.abs();
    let d = dir.normalize_or_zero();
    let wc = c - p;
    let b = d.dot(wc);
    // Discriminant from the perpendicular distance (pbrt-v4's robust quadratic for spheres).
    let perp = wc - b * d;
    let disc = r * r - perp.length_squared();
    if !(disc > 0.0) {
        return 0.0;
    }
    let root = disc.sqrt();
    let far = b + root;
    if !(far > 0.0) {
        return 0.0;
    }
    let dc = wc.length();
    // t₀·t₁ = |wc|² − r², written as a product to keep precision when p is near the surface.
    let near = (dc - r) * (dc + r) / far;
    let sum = if near > 0.0 { far * far + near * near } else { far * far };
    sanitize_pdf(sum / (2.0 * TAU * r * root))
}

/// Quad light `o + s·eu + t·ev`, `(s, t) ∈ [0,1]²`, relative to `p`: the pieces every quad warp
/// needs.
struct QuadGeometry {
    /// Unnormalized plane normal `eu × ev`; its length is the area.
    n: Vec3,
    area: f32,
    /// `o − p`.
    po: Vec3,
}

fn quad_geometry(p: Vec3, o: Vec3, eu: Vec3, ev: Vec3) -> QuadGeometry {
    let n = eu.cross(ev);
    QuadGeometry { n, area: n.length(), po: o - p }
}

/// Solid angle (sr) that the quad `o + s·eu + t·ev`, `(s, t) ∈ [0,1]²`, subtends at `p`, as the
/// sum of its two spherical triangles by Van Oosterom & Strackee's formula
/// `Ω = 2·atan2(|a·(b × c)|, 1 + a·b + a·c + b·c)` for unit corner directions (pbrt-v4
/// `SphericalTriangleArea`, vecmath.h; A. van Oosterom and J. Strackee, "The Solid Angle of a
/// Plane Triangle", IEEE TBME 30(2), 1983). Unlike pbrt-v4's `g₀ + g₁ + g₂ + g₃ − 2π` (which
/// needs `f64`), it keeps full relative precision for small quads — and, its terms formed as
/// [`spherical_triangle_area`] says, for a point nearly on the line of an edge. Returns 0 for
/// degenerate quads and for `p` in the quad's plane. Valid for any parallelogram.
pub fn quad_solid_angle(p: Vec3, o: Vec3, eu: Vec3, ev: Vec3) -> f32 {
    let g = quad_geometry(p, o, eu, ev);
    if !(g.area > 0.0) || g.n.dot(g.po) == 0.0 {
        return 0.0;
    }
    let a = g.po.normalize_or_zero();
    let corners =
        [(g.po + eu).normalize_or_zero(), (g.po + eu + ev).normalize_or_zero(), (g.po + ev).normalize_or_zero()];
    // The two triangles (a, b, c) and (a, c, d) by one call in a loop, so that a kernel holds
    // the triangle's code once.
    let mut omega = 0.0;
    let mut k = 0;
    while k < 2 {
        omega += spherical_triangle_area(a, corners[k], corners[k + 1]);
        k += 1;
    }
    finite_or_zero(omega)
}

/// Solid angle of the spherical triangle with unit corners `a`, `b`, `c` (Van Oosterom &
/// Strackee; pbrt-v4 `SphericalTriangleArea`), in `[0, 2π]`. Where two corners are more than
/// 120° apart, both terms are formed from the corners' pairwise sums instead, the same values for
/// unit corners — `2·a·(b × c) = (a + b)·((b + c) × (c + a))`, and `1 + a·b + a·c + b·c` the dot
/// product of the two shortest sums (`(a + b)·(b + c)` for the longest `c + a`) — since for two
/// nearly opposite corners (a point nearly on the line of a light's edge, close to its plane)
/// their sum is short and keeps its relative precision where the dot products as written cancel:
/// a point 3.4·10⁻⁶ beside a 7-unit edge and 1.2·10⁻⁷ above its light's plane got 3.14 sr
/// for 0.07 (test).
pub fn spherical_triangle_area(a: Vec3, b: Vec3, c: Vec3) -> f32 {
    let (ab, bc, ca) = (a + b, b + c, c + a);
    let (ab2, bc2, ca2) = (ab.length_squared(), bc.length_squared(), ca.length_squared());
    // |x + y|² = 2 + 2 x·y < 1: x and y more than 120° apart.
    let (triple, denominator) = if ab2.min(bc2).min(ca2) < 1.0 {
        let shortest_two = if ab2 >= bc2 && ab2 >= ca2 {
            bc.dot(ca)
        } else if bc2 >= ca2 {
            ca.dot(ab)
        } else {
            ab.dot(bc)
        };
        (0.5 * ab.dot(bc.cross(ca)), shortest_two)
    } else {
        (a.dot(b.cross(c)), 1.0 + a.dot(b) + a.dot(c) + b.dot(c))
    };
    2.0 * trig::atan2(triple.abs(), denominator)
}

/// Ray from `p` along unit `d` against the quad: the ray parameter `t` of the hit, or 0 when the
/// ray misses (beyond [`QUAD_EDGE_SLACK`]), is parallel to the plane or points away.
fn quad_hit(g: &QuadGeometry, eu: Vec3, ev: Vec3, d: Vec3, slack: f32) -> f32 {
    let denom = d.dot(g.n);
    let t = g.po.dot(g.n) / denom;
    // No point of the quad is farther from `p` than `|o − p| + |eu| + |ev|` (the triangle
    // inequality), whose square is at most `3·(|o − p|² + |eu|² + |ev|²)` (Cauchy–Schwarz). A ray
    // meeting the plane beyond twice that — compared in squares, without roots — misses the quad,
    // however the slack below widens it: nearly parallel to the plane (`|cos θl|` below ~16 ε), its slack along the
    // ray, `~QUAD_EDGE_SLACK·t/cos²θl` of the height above the plane, outgrows the distance by
    // which it misses, `~t·tan θl`, and would accept it wherever it meets the plane (10⁴ light
    // widths away). A sampled direction's own `t` is off by a relative few ε/`|cos θl|` — near 1
    // only where the shade stage's shadow ray has no room before the light anyway
    // (`offset::ray_stop_before`).
    let farthest_squared = 3.0 * (g.po.length_squared() + eu.length_squared() + ev.length_squared());
    if !(t > 0.0) || !(t * t <= 4.0 * farthest_squared) {
        return 0.0;
    }
    // Hit point relative to o, then its coordinates in the (eu, ev) basis (any parallelogram):
    // s = q·∇s, v = q·∇v.
    let q = t * d - g.po;
    let n2 = g.n.length_squared();
    let s = q.cross(ev).dot(g.n) / n2;
    let v = eu.cross(q).dot(g.n) / n2;
    // Slack (see QUAD_EDGE_SLACK) in each coordinate: `reach` in any direction of the plane, plus
    // `reach/|cos θl|` along the ray's projection onto it, i.e. `d`'s in-plane part over |cos θl|.
    let cos_abs = denom.abs() / g.area;
    let reach = slack * t;
    let (grad_s, grad_v) = (ev.cross(g.n) / n2, g.n.cross(eu) / n2);
    let slack_s = reach * (grad_s.length() + d.dot(grad_s).abs() / cos_abs);
    let slack_v = reach * (grad_v.length() + d.dot(grad_v).abs() / cos_abs);
    let inside = s >= -slack_s && s <= 1.0 + slack_s && v >= -slack_v && v <= 1.0 + slack_v;
    if inside {
        t
    } else {
        0.0
    }
}

/// Samples the quad light `o + s·eu + t·ev` uniformly by area, `(s, t) = u`, and converts to
/// solid angle at `p`: `pdf = d²/(|cos θl|·A)` = `d³/|n·w|` with `n = eu × ev` (|n| = A) and
/// `w = point − p` (pbrt-v4 area sampling + `Shape::PDF` conversion). Both sides of the quad are
/// sampled alike; a point seen exactly edge-on gets pdf 0. Its pdf is [`quad_area_pdf`].
pub fn sample_quad_area(p: Vec3, o: Vec3, eu: Vec3, ev: Vec3, u: Vec2) -> LightSample {
    let u = clamp_sample(u);
    let g = quad_geometry(p, o, eu, ev);
    let normal = g.n / g.area;
    let w = g.po + u.x * eu + u.y * ev;
    let d2 = w.length_squared();
    let n_dot_w = g.n.dot(w).abs();
    let pdf = if n_dot_w > 0.0 { d2 * d2.sqrt() / n_dot_w } else { 0.0 };
    LightSample::along(w, o + u.x * eu + u.y * ev, normal, pdf)
}

/// Solid-angle pdf of [`sample_quad_area`] for unit `dir` (sr⁻¹): `t²/|dir·n|` where the ray
/// `p + t·dir` hits the quad (`n = eu × ev`, so this is `d²/(|cos θl|·A)`; edges widened by
/// [`QUAD_EDGE_SLACK`]), else 0. Either side.
pub fn quad_area_pdf(p: Vec3, o: Vec3, eu: Vec3, ev: Vec3, dir: Vec3) -> f32 {
    let g = quad_geometry(p, o, eu, ev);
    let d = dir.normalize_or_zero();
    area_pdf_at_hit(g.n, d, quad_hit(&g, eu, ev, d, QUAD_EDGE_SLACK))
}

/// [`quad_area_pdf`] where the ray along unit `dir` hits the quad of unnormalized normal `n`
/// (`eu × ev`) at `distance` (> 0; else 0): `t²/|dir·n|`.
fn area_pdf_at_hit(n: Vec3, dir: Vec3, distance: f32) -> f32 {
    if distance > 0.0 {
        sanitize_pdf(distance * distance / dir.dot(n).abs())
    } else {
        0.0
    }
}

/// Samples the quad light `o + s·eu + t·ev` (edges `eu ⟂ ev`, or within
/// [`QUAD_RECTANGLE_MAX_COS`] of it: see below) uniformly in the solid angle it subtends at `p`:
/// C. Ureña, M. Fajardo and A. King, "An Area-Preserving Parametrization for
/// Spherical Rectangles", EGSR 2013, following pbrt-v4 `SampleSphericalRectangle`
/// (sampling.cpp) including its clamps: `cu` clamped to `±(1 − 2⁻²⁴)`, `xu` clamped to
/// `[x₀, x₁]` and `yv` to `[y₀, y₁]`. Four changes for `f32`: the solid angle
/// comes from [`quad_solid_angle`] (pbrt sums the four corner angles minus 2π in `f64`); the first
/// angle is `au = u₀·Ω − (g₂ + g₃)`, the same value as pbrt's
/// `u₀(g₀ + g₁ − 2π) + (u₀ − 1)(g₂ + g₃)` without the cancellation; and for a quad seen nearly
/// edge-on, where `cos au`, `b₀` and `b₁` all near ±1 and `cu` near ±1, neither
/// `fu = (cos au·b₀ − b₁)/sin au` nor `xu = −cu·z₀/√(1 − cu²)` is computed as written:
/// `edge_on_numerator` takes the numerator from the three factors' distances to ±1, and
/// `xu = sign(fu)·|z₀|/√(fu² − (1 − b₀²))` with `1 − b₀² = n₀ₓ² + n₀ᵧ²`, the same value without
/// `cu`. 1–5 mm below the Cornell light the `f32` sample was up to 2.6·10⁻³ from the `f64`
/// evaluation of pbrt's formulas — and an NVIDIA GPU's fused multiply-adds moved it by as much —
/// now within 2·10⁻⁶ (test). Seen edge-on from beyond an `ev` edge, `hv = lerp(h₀, h₁, u₁)`,
/// `h = y/√(dd² + y²)`, rounds to ±1 within ulps, so `yv = hv·dd/√(1 − hv²)` is formed from h's
/// distances to ±1 instead (`edge_distances`; pbrt's cut at `hv² ≥ 1 − 10⁻⁶`, which sent those
/// samples to `y₁`, is gone).
///
/// pdf = 1/Ω sr⁻¹; for a parallelogram within [`QUAD_RECTANGLE_MAX_COS`] of a rectangle,
/// sampled as a rectangle and sheared onto it, `(d_quad/d_rectangle)³/Ω` with Ω the rectangle's
/// ([`SphericalQuad`]). Special cases, mirrored by [`quad_spherical_pdf`]:
/// - `p` in the quad's plane or a degenerate quad (Ω = 0): the bilinear point `o + u₀eu + u₁ev`
///   with pdf 0 (as pbrt-v4).
/// - Ω < [`QUAD_MIN_SPHERICAL_SOLID_ANGLE`] (the rectangle's Ω for a sheared one): uniform area
///   sampling ([`sample_quad_area`]) with
///   *its* pdf. (pbrt-v4 also returns the bilinear point there but keeps pdf 1/Ω, which is
///   inconsistent for small quads seen at grazing angles; the area pdf keeps sample and pdf in
///   agreement.)
/// - A parallelogram farther from a rectangle (edges off perpendicular by more than
///   [`QUAD_RECTANGLE_MAX_COS`]): uniform area sampling too.
pub fn sample_quad_spherical(p: Vec3, o: Vec3, eu: Vec3, ev: Vec3, u: Vec2) -> LightSample {
    sample_quad_spherical_with(p, o, eu, ev, &spherical_quad(p, o, eu, ev), u)
}

/// [`sample_quad_spherical`] given the quad as seen from `p` ([`spherical_quad`]), for a caller
/// that also needs its [`quad_spherical_pdf_at_hit`]: its solid angle is the costliest part of
/// each (two spherical triangles, two `atan2`s).
pub fn sample_quad_spherical_with(p: Vec3, o: Vec3, eu: Vec3, ev: Vec3, quad: &SphericalQuad, u: Vec2) -> LightSample {
    let u = clamp_sample(u);
    let exl = eu.length();
    let solid_angle = quad.solid_angle;
    if !(solid_angle > 0.0) || !(exl > 0.0) || !(ev.length_squared() > 0.0) {
        let point = o + u.x * eu + u.y * ev;
        return LightSample::none(point, eu.cross(ev).normalize_or(Vec3::Z));
    }
    if !quad.spherical {
        return sample_quad_area(p, o, eu, ev, u);
    }
    // Local frame: x along eu, y along the rectangle's other edge (ev less its part along eu,
    // the shear), z flipped so that the quad lies at z0 < 0.
    let (shear, eyl) = (quad.shear, quad.edge_v.length());
    let ex = eu / exl;
    let ey = quad.edge_v / eyl;
    let mut ez = ex.cross(ey);
    let normal = ez.normalize_or(Vec3::Z);
    let po = quad.corner;
    let x0 = ex.dot(po);
    let y0 = ey.dot(po);
    let mut z0 = ez.dot(po);
    if z0 > 0.0 {
        ez = -ez;
        z0 = -z0;
    }
    let x1 = x0 + exl;
    let y1 = y0 + eyl;
    // Normals of the planes through p and each edge, and the internal angles g₂, g₃ (pbrt's n₁,
    // g₀ and g₁ are only needed for the solid angle, which comes from `quad_solid_angle`).
    let v00 = Vec3::new(x0, y0, z0);
    let v01 = Vec3::new(x0, y1, z0);
    let v10 = Vec3::new(x1, y0, z0);
    let v11 = Vec3::new(x1, y1, z0);
    let n0 = v00.cross(v10).normalize_or_zero();
    let n2 = v11.cross(v01).normalize_or_zero();
    let n3 = v01.cross(v00).normalize_or_zero();
    // Sample cu. The paper's au = u₀·Ω − (g₂ + g₃) lies near −π for small quads, where sin(au) is
    // tiny and a GPU `sin` (Vulkan bounds it only to 2⁻¹¹ absolute) loses all its digits: on
    // lavapipe that biased the sampler completely at Ω = 2.5·10⁻³. So e^{i·au} is assembled
    // without trigonometry on large angles: e^{−i·g} of each internal angle g comes exactly from
    // its plane normals (cos g = −nᵢ·nⱼ, sin g = |nᵢ × nⱼ|), and e^{i·u₀Ω} from
    // [`trig::sin_cos`], the same polynomial on every backend.
    let (cos_g2, sin_g2) = (-n2.dot(n3), n2.cross(n3).length());
    let (cos_g3, sin_g3) = (-n3.dot(n0), n3.cross(n0).length());
    let (cos_g, sin_g) = (cos_g2 * cos_g3 - sin_g2 * sin_g3, sin_g2 * cos_g3 + cos_g2 * sin_g3);
    let (sin_uo, cos_uo) = trig::sin_cos(u.x * solid_angle);
    let sin_au = sin_uo * cos_g - cos_uo * sin_g;
    let cos_au = cos_uo * cos_g + sin_uo * sin_g;
    let fu = edge_on_numerator(cos_au, sin_au, n0, n2) / sin_au;
    // xu along the x edge: −cu·z0/√(1 − cu²) with cu = sign(fu)/√(fu² + b0²), written without cu
    // (1 − cu² cancels when the quad is seen edge-on), then clamped to the rectangle. A radicand
    // ≤ 0 is cu at ±1 (pbrt clamps it to ±(1 − 2⁻²⁴)): the far edge on fu's side.
    let radicand = fu * fu - (n0.x * n0.x + n0.y * n0.y);
    let xu = if radicand > 0.0 {
        (-z0 / radicand.sqrt()).copysign(fu)
    } else if fu >= 0.0 {
        x1
    } else {
        x0
    };
    let xu = if xu >= x1 {
        x1
    } else if xu > x0 {
        xu
    } else {
        x0
    };
    // yv along the y edge: hv = lerp(h₀, h₁, u₁) with h = y/√(dd² + y²), then yv = hv·dd/√(1 − hv²).
    // Seen nearly edge-on from beyond the y edge (|y| ≫ dd) every h rounds to within ulps of ±1,
    // which left hv a few values and 1 − hv² no digits (samples 0.49 of the edge off, and a cut at
    // 1 − hv² < 10⁻⁶ sent more onto the far edge); so h's distances to 1 and to −1, c = 1 − h and
    // d = 1 + h, are interpolated instead, each formed without cancellation ([`edge_distances`]):
    // the same map in real arithmetic, with 1 − hv² = c·d. Where |hv| < ½ (a light overhead), hv
    // itself is interpolated: 1 − c would lose its relative precision (2·10⁻⁶ of the edge there).
    let dd = scaled_length(xu, z0);
    let (c0, d0, h0) = edge_distances(y0, dd);
    let (c1, d1, h1) = edge_distances(y1, dd);
    let cv = c0 + u.y * (c1 - c0);
    let dv = d0 + u.y * (d1 - d0);
    let hv = if cv.min(dv) > 0.5 {
        h0 + u.y * (h1 - h0)
    } else if cv < dv {
        1.0 - cv
    } else {
        dv - 1.0
    };
    // c·d = 0 only at an end at infinity: ±∞, clamped to that edge below.
    let yv = hv * dd / (cv * dv).sqrt();
    let yv = if yv >= y1 {
        y1
    } else if yv > y0 {
        yv
    } else {
        y0
    };
    // The rectangle's point sheared onto the quad, `c·(t − t_p)·|eu|` along x with `t − t_p` =
    // `yv/|ev⊥|` (the point's foot at y = 0; exactly on the plane), and the direction from its
    // local vector (no cancellation against p). The density: [`SphericalQuad`].
    let t = (yv - y0) / eyl;
    let xq = xu + yv * (shear * exl / eyl);
    let local = Vec3::new(xq, yv, z0);
    let distance = local.length();
    let direction = (xq * ex + yv * ey + z0 * ez) / distance;
    let point = o + ((xu - x0) / exl) * eu + t * ev;
    let pdf = shear_density(distance, Vec3::new(xu, yv, z0).length(), solid_angle);
    if direction.is_finite() && distance > 0.0 && distance.is_finite() && point.is_finite() {
        LightSample { direction, distance, pdf: sanitize_pdf(pdf), point, normal }
    } else {
        LightSample::none(point, normal)
    }
}

/// The solid-angle density `(d_quad/d_rectangle)³/Ω` of a direction the spherical method drew on
/// the rectangle (uniform, `1/Ω`) at distance `d_rectangle` and sheared onto the quad at
/// `d_quad` ([`SphericalQuad`]); `1/Ω` exactly where the two distances are equal (no shear), as
/// IEEE division gives `x/x` = 1.
fn shear_density(quad_distance: f32, rectangle_distance: f32, solid_angle: f32) -> f32 {
    let ratio = quad_distance / rectangle_distance;
    (1.0 / solid_angle) * (ratio * ratio * ratio)
}

/// `√(a² + b²)` from the two scaled by the larger, so that neither square overflows nor
/// underflows (0 for two zeros).
fn scaled_length(a: f32, b: f32) -> f32 {
    let scale = a.abs().max(b.abs());
    if scale > 0.0 {
        scale * ((a / scale) * (a / scale) + (b / scale) * (b / scale)).sqrt()
    } else {
        0.0
    }
}

/// `(1 − h, 1 + h, h)` for `h = y/√(dd² + y²)` (`dd > 0`) of [`sample_quad_spherical`], the
/// first two without cancellation: the one near 0 as `(dd/r)·(dd/(r + |y|))`, `r = √(dd² + y²)`
/// ([`scaled_length`]), the other as `1 + |y|/r`.
fn edge_distances(y: f32, dd: f32) -> (f32, f32, f32) {
    let r = scaled_length(dd, y);
    let near = (dd / r) * (dd / (r + y.abs()));
    let far = 1.0 + y.abs() / r;
    if y >= 0.0 {
        (near, far, y / r)
    } else {
        (far, near, y / r)
    }
}

/// `cos au·b₀ − b₁` of [`sample_quad_spherical`] (`b₀ = n₀.z`, `b₁ = n₂.z` of the unit edge-plane
/// normals `n₀`, `n₂`). When the product and `b₁` have the same sign, as for a quad seen nearly
/// edge-on where all three factors near ±1, the difference is formed from their distances to ±1 —
/// `1 − |cos au| = sin²au/(1 + |cos au|)`, `1 − |b| = (n_x² + n_y²)/(1 + |b|)`, each accurate to a
/// few ulps — as `±(c₁ − a − c₀ + a·c₀)`, which equals it exactly in real arithmetic; as written
/// it lost up to four digits in `f32` there.
fn edge_on_numerator(cos_au: f32, sin_au: f32, n0: Vec3, n2: Vec3) -> f32 {
    let (b0, b1) = (n0.z, n2.z);
    if (cos_au * b0 >= 0.0) != (b1 >= 0.0) {
        // Opposite signs: the magnitudes add, nothing cancels.
        return cos_au * b0 - b1;
    }
    // cos au = s·(1 − a), b₀ = s₀·(1 − c₀), b₁ = s·s₀·(1 − c₁):
    // cos au·b₀ − b₁ = s·s₀·(c₁ − a − c₀ + a·c₀).
    let a = sin_au * sin_au / (1.0 + cos_au.abs());
    let c0 = (n0.x * n0.x + n0.y * n0.y) / (1.0 + b0.abs());
    let c1 = (n2.x * n2.x + n2.y * n2.y) / (1.0 + b1.abs());
    let difference = c1 - a - c0 + a * c0;
    if b1 >= 0.0 {
        difference
    } else {
        -difference
    }
}

/// Distance along the ray from `p` in unit direction `dir` to the quad `o + s·eu + t·ev` (either
/// side, edges widened by [`QUAD_EDGE_SLACK`]), or 0 when the ray misses it: where a direction
/// the light's own sampler drew meets it, as its pdf ([`quad_spherical_pdf`]) needs. A direction
/// drawn from a BRDF meets the light only without the slack
/// ([`quad_ray_distance_with_slack`] with 0, as the shade stage asks).
pub fn quad_ray_distance(p: Vec3, o: Vec3, eu: Vec3, ev: Vec3, dir: Vec3) -> f32 {
    quad_ray_distance_with_slack(p, o, eu, ev, dir, QUAD_EDGE_SLACK)
}

/// [`quad_ray_distance`] with the edges widened by `slack` instead of [`QUAD_EDGE_SLACK`]: 0 for
/// a direction not drawn on the light (a BRDF sample), which only the quad itself may catch.
/// The slack keeps `pdf(sample(u))` consistent for the light's own samples, which round a few
/// ulps past its edges; a BRDF sample in that band is off the light, and counting it there added
/// `~2·10⁻⁶·t` of width to every edge — 10 % of `U_N` where an edge ran through the mirror
/// direction of a roughness-0 lobe seen at 85°, whose width is ~10⁻⁵ rad.
pub fn quad_ray_distance_with_slack(p: Vec3, o: Vec3, eu: Vec3, ev: Vec3, dir: Vec3, slack: f32) -> f32 {
    let g = quad_geometry(p, o, eu, ev);
    if !(g.area > 0.0) {
        return 0.0;
    }
    quad_hit(&g, eu, ev, dir, slack)
}

/// Solid-angle pdf of [`sample_quad_spherical`] for unit `dir` (sr⁻¹): `1/Ω` if the ray from `p`
/// along `dir` hits the quad (either side; edges widened by [`QUAD_EDGE_SLACK`]), else 0 — for a
/// sheared rectangle `(d_quad/d_rectangle)³/Ω` at the hit ([`SphericalQuad`]). Mirrors the
/// sampler's special cases: 0 when Ω = 0, [`quad_area_pdf`] when Ω <
/// [`QUAD_MIN_SPHERICAL_SOLID_ANGLE`] or the quad is no rectangle ([`QUAD_RECTANGLE_MAX_COS`]).
pub fn quad_spherical_pdf(p: Vec3, o: Vec3, eu: Vec3, ev: Vec3, dir: Vec3) -> f32 {
    let d = dir.normalize_or_zero();
    quad_spherical_pdf_at_hit(eu, ev, &spherical_quad(p, o, eu, ev), d, quad_ray_distance(p, o, eu, ev, d))
}

/// [`quad_spherical_pdf`] for a caller that has the quad as seen from `p` ([`spherical_quad`])
/// and the `distance` along unit `dir` to where it hits the quad ([`quad_ray_distance`], 0 for
/// a miss; for a direction the light's own sampler drew, the shade stage passes the sampler's
/// distance where that ray test misses) already, as a caller that drew `dir` and traces it to the
/// light does: neither is formed again.
pub fn quad_spherical_pdf_at_hit(eu: Vec3, ev: Vec3, quad: &SphericalQuad, dir: Vec3, distance: f32) -> f32 {
    if !(distance > 0.0) || !(quad.solid_angle > 0.0) || !(eu.length_squared() > 0.0) || !(ev.length_squared() > 0.0) {
        return 0.0;
    }
    if !quad.spherical {
        return area_pdf_at_hit(eu.cross(ev), dir, distance);
    }
    // The rectangle's point the sampler shears to the hit: `c·(t − t_p)·eu` back, with
    // `t − t_p = (hit − p)·ev⊥/|ev⊥|²` ([`SphericalQuad`]).
    let to_hit = distance * dir;
    let pivot_offset = quad.shear * (to_hit.dot(quad.edge_v) / quad.edge_v.length_squared());
    let rectangle_distance = if quad.shear == 0.0 { distance } else { (to_hit - pivot_offset * eu).length() };
    sanitize_pdf(shear_density(distance, rectangle_distance, quad.solid_angle))
}

// ---------------------------------------------------------------------------------------------
// GGX (Trowbridge–Reitz) microfacets
// ---------------------------------------------------------------------------------------------

/// GGX roughness clamped to `[GGX_MIN_ALPHA, GGX_MAX_ALPHA]` per component (NaN → minimum).
fn ggx_alpha(alpha: Vec2) -> Vec2 {
    Vec2::new(ggx_alpha_1d(alpha.x), ggx_alpha_1d(alpha.y))
}

/// One GGX roughness component clamped to `[GGX_MIN_ALPHA, GGX_MAX_ALPHA]` (NaN → minimum).
fn ggx_alpha_1d(a: f32) -> f32 {
    if a >= GGX_MAX_ALPHA {
        GGX_MAX_ALPHA
    } else if a > GGX_MIN_ALPHA {
        a
    } else {
        GGX_MIN_ALPHA
    }
}

/// The view direction as the GGX functions use it: unit, with `z ≥` [`GGX_MIN_COS_VIEW`]
/// (grazing and below-horizon views are lifted to that grazing angle). Non-finite or zero input
/// becomes +z.
fn ggx_view(v: Vec3) -> Vec3 {
    let v = v.normalize_or(Vec3::Z);
    if v.z >= GGX_MIN_COS_VIEW {
        v
    } else {
        let t = Vec2::new(v.x, v.y).normalize_or(Vec2::X) * safe_sqrt(1.0 - GGX_MIN_COS_VIEW * GGX_MIN_COS_VIEW);
        Vec3::new(t.x, t.y, GGX_MIN_COS_VIEW)
    }
}

/// Anisotropic GGX / Trowbridge–Reitz normal distribution D(h) for a unit microfacet normal `h`
/// in the local frame (z = macro-surface normal), roughness `alpha = (αx, αy)` (clamped to
/// [`GGX_MIN_ALPHA`]…[`GGX_MAX_ALPHA`]): `D = 1/(π αx αy (hx²/αx² + hy²/αy² + hz²)²)` for
/// `hz > 0`, else 0 (B. Walter et al., "Microfacet Models for Refraction through Rough
/// Surfaces", EGSR 2007; pbrt-v4 `TrowbridgeReitzDistribution::D`, scattering.h, in the
/// algebraically equal form without tan²θ). Units: sr⁻¹ of microfacet normals, normalized so that
/// `∫ D(h) hz dω = 1`.
pub fn ggx_d(h: Vec3, alpha: Vec2) -> f32 {
    if !(h.z > 0.0) {
        return 0.0;
    }
    let a = ggx_alpha(alpha);
    let sx = h.x / a.x;
    let sy = h.y / a.y;
    let t = sx * sx + sy * sy + h.z * h.z;
    sanitize_pdf(1.0 / (PI * a.x * a.y * t * t))
}

/// `G1(v)/cos θv` for the Smith GGX masking function: `2/(vz + √(vz² + αx²vx² + αy²vy²))`
/// (from `G1 = 1/(1 + Λ)`, `Λ = (√(1 + α²tan²θ) − 1)/2`). Bounded by `2/α` as vz → 0, so the
/// pdfs below never divide by a grazing cosine. `v` is expected from [`ggx_view`].
fn ggx_g1_over_cos(v: Vec3, a: Vec2) -> f32 {
    let ax = a.x * v.x;
    let ay = a.y * v.y;
    2.0 / (v.z + (v.z * v.z + ax * ax + ay * ay).sqrt())
}

/// Smith masking function G1(v) of anisotropic GGX for a unit direction `v` in the local frame:
/// `G1 = 1/(1 + Λ(v))`, `Λ = (√(1 + (αx²vx² + αy²vy²)/vz²) − 1)/2` (E. Heitz, "Understanding the
/// Masking-Shadowing Function in Microfacet-Based BRDFs", JCGT 3(2), 2014; pbrt-v4
/// `TrowbridgeReitzDistribution::G1`). Dimensionless in `[0, 1]`. The microfacet-side factor
/// χ⁺(v·h) is not included (the VNDF pdf applies it as `max(0, v·h)`). `v` is lifted to
/// [`GGX_MIN_COS_VIEW`] like everywhere in the GGX functions.
pub fn ggx_g1(v: Vec3, alpha: Vec2) -> f32 {
    let v = ggx_view(v);
    sanitize_pdf(ggx_g1_over_cos(v, ggx_alpha(alpha)) * v.z)
}

/// Samples a microfacet normal `h` from the distribution of normals visible from `v`,
/// `D_v(h) = G1(v)·max(0, v·h)·D(h)/vz`: E. Heitz, "Sampling the GGX Distribution of Visible
/// Normals", JCGT 7(4), 2018 (the listing of §2 with a polar disk sample, as pbrt-v4
/// `TrowbridgeReitzDistribution::Sample_wm`). `v` is the unit view direction in the local frame
/// (z = normal), lifted to [`GGX_MIN_COS_VIEW`] if grazing or below the horizon; `alpha` clamped
/// to [`GGX_MIN_ALPHA`]…[`GGX_MAX_ALPHA`]. Returns a unit `h` with `hz ≥ 0`; its pdf is
/// [`ggx_vndf_pdf`].
pub fn sample_ggx_vndf(v: Vec3, alpha: Vec2, u: Vec2) -> Vec3 {
    let u = clamp_sample(u);
    let v = ggx_view(v);
    let a = ggx_alpha(alpha);
    // Stretch the view into the hemisphere configuration (α = 1).
    let vh = Vec3::new(a.x * v.x, a.y * v.y, v.z).normalize_or(Vec3::Z);
    // Orthonormal basis around vh (T1 = +x when vh is the normal). (−vh.y, vh.x) is scaled by its
    // larger component before it is normalised: its squared length is subnormal for |vh.xy|
    // below 1.1·10⁻¹⁹, where dividing by the root of `vh.x² + vh.y²` had made |T1| 0.71 … 1.07
    // (slopes 7 % too wide) and a GPU flushing subnormals had taken the `Vec3::X` branch. A
    // subnormal component is 0 on such a GPU, so the fallback takes every pair below the
    // smallest normal f32 on every backend.
    let largest = vh.x.abs().max(vh.y.abs());
    let t1 = if largest >= f32::MIN_POSITIVE {
        let t = Vec2::new(-vh.y, vh.x) / largest;
        (t / t.length()).extend(0.0)
    } else {
        Vec3::X
    };
    let t2 = vh.cross(t1);
    // Uniform point on the disk, warped onto the visible half of the projected hemisphere.
    let r = u.x.sqrt();
    let (sin_phi, cos_phi) = trig::sin_cos(TAU * u.y);
    let p1 = r * cos_phi;
    let p2 = r * sin_phi;
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * safe_sqrt(1.0 - p1 * p1) + s * p2;
    // Reproject onto the hemisphere, then unstretch.
    let nh = p1 * t1 + p2 * t2 + safe_sqrt(1.0 - p1 * p1 - p2 * p2) * vh;
    let nz = if nh.z > 0.0 { nh.z } else { 0.0 };
    Vec3::new(a.x * nh.x, a.y * nh.y, nz).normalize_or(Vec3::Z)
}

/// Density of [`sample_ggx_vndf`] over microfacet normals (sr⁻¹):
/// `D_v(h) = G1(v)·max(0, v·h)·D(h)/vz` (Heitz 2018, eq. 1), for unit `h`; `v` and `alpha` as in
/// the sampler.
pub fn ggx_vndf_pdf(v: Vec3, h: Vec3, alpha: Vec2) -> f32 {
    let v = ggx_view(v);
    let a = ggx_alpha(alpha);
    let v_dot_h = v.dot(h);
    if !(v_dot_h > 0.0) {
        return 0.0;
    }
    sanitize_pdf(ggx_g1_over_cos(v, a) * v_dot_h * ggx_d(h, a))
}

/// `reflect(−v, h) = 2(v·h)h − v`, normalized (unit for unit inputs; +z if degenerate).
fn reflect_view(v: Vec3, h: Vec3) -> Vec3 {
    (2.0 * v.dot(h) * h - v).normalize_or(Vec3::Z)
}

/// Samples a reflected direction `l = reflect(−v, h)` with `h` from [`sample_ggx_vndf`]: the
/// importance-sampling half of a GGX specular BRDF (Heitz 2018 §1). `l` may point below the
/// horizon (`lz < 0`) for rough or grazing configurations; such samples are valid samples of this
/// warp (the BRDF is zero there, so the caller discards them). Its pdf is
/// [`ggx_reflection_pdf`].
pub fn sample_ggx_reflection(v: Vec3, alpha: Vec2, u: Vec2) -> Vec3 {
    let v = ggx_view(v);
    reflect_view(v, sample_ggx_vndf(v, alpha, u))
}

/// Density of `l` under [`sample_ggx_reflection`] (sr⁻¹): `D_v(h)/(4|v·h|)` with
/// `h = normalize(v + l)` (the reflection Jacobian, Walter et al. 2007 eq. 14), computed as
/// `G1(v)/vz · D(h)/4` so that no grazing `v·h` is divided by. Directions below the horizon
/// are *not* zeroed: the pdf integrates to 1 over the whole sphere. 0 for `l = −v`.
pub fn ggx_reflection_pdf(v: Vec3, l: Vec3, alpha: Vec2) -> f32 {
    let v = ggx_view(v);
    let a = ggx_alpha(alpha);
    let h = (v + l.normalize_or_zero()).normalize_or_zero();
    if !(v.dot(h) > 0.0) {
        return 0.0;
    }
    sanitize_pdf(0.25 * ggx_g1_over_cos(v, a) * ggx_d(h, a))
}

// ---------------------------------------------------------------------------------------------
// Linearly transformed cosines
// ---------------------------------------------------------------------------------------------

/// `M⁻¹` for [`ltc_pdf`], or the zero matrix when `M` is singular or not finite (then every pdf
/// is 0). LTC tables (Heitz et al. 2016) usually store `M⁻¹` directly; use this for an `M` built
/// at run time.
pub fn ltc_inverse(m: Mat3) -> Mat3 {
    let det = m.determinant();
    if !(det.abs() > 0.0) || !det.is_finite() {
        return Mat3::ZERO;
    }
    let inv = m.inverse();
    if inv.is_finite() {
        inv
    } else {
        Mat3::ZERO
    }
}

/// Samples a linearly transformed cosine distribution (E. Heitz, J. Dupuy, S. Hill and
/// D. Neubelt, "Real-Time Polygonal-Light Shading with Linearly Transformed Cosines", SIGGRAPH
/// 2016): `ω = normalize(M·ω_o)` with `ω_o` from [`sample_cosine_hemisphere`]. `M` is the 3×3
/// transform (columns as in glam), in the local frame. Directions may fall below the horizon if
/// `M` tilts the lobe. Its pdf is [`ltc_pdf`] with `M⁻¹` ([`ltc_inverse`]). A singular `M`
/// yields +z (and pdf 0 from [`ltc_pdf`]).
pub fn sample_ltc(m: Mat3, u: Vec2) -> Vec3 {
    (m * sample_cosine_hemisphere(u)).normalize_or(Vec3::Z)
}

/// Density of [`sample_ltc`] at unit `dir` (sr⁻¹), given `m_inv = M⁻¹`:
/// `D_o(ω_o)·|det M⁻¹|/|M⁻¹ω|³` with `ω_o = M⁻¹ω/|M⁻¹ω|` and `D_o(ω_o) = max(0, ω_o.z)/π`
/// (Heitz et al. 2016, eq. 2), i.e. `max(0, (M⁻¹ω).z)·|det M⁻¹|/(π|M⁻¹ω|⁴)`. Taking `M⁻¹` lets a
/// shader evaluate it without inverting per call; the zero matrix (singular `M`) gives 0.
pub fn ltc_pdf(m_inv: Mat3, dir: Vec3) -> f32 {
    let w = m_inv * dir.normalize_or_zero();
    if !(w.z > 0.0) {
        return 0.0;
    }
    let l2 = w.length_squared();
    sanitize_pdf(w.z * m_inv.determinant().abs() * INV_PI / (l2 * l2))
}

/// The LTC direction and its density computed from the cosine sample itself:
/// `pdf = (ω_o.z/π)·|Mω_o|³/|det M|` (the same value as [`ltc_pdf`], without `M⁻¹`).
fn sample_ltc_with_pdf(m: Mat3, u: Vec2) -> Vec4 {
    let wo = sample_cosine_hemisphere(u);
    let w = m * wo;
    let len = w.length();
    let det = m.determinant().abs();
    let pdf = if det > 0.0 { wo.z * INV_PI * len * len * len / det } else { 0.0 };
    sanitize_sample(w / len, pdf)
}

// ---------------------------------------------------------------------------------------------
// Dispatcher
// ---------------------------------------------------------------------------------------------

/// The light sample as a probe result: xyz direction, w pdf.
fn light_vec4(s: LightSample) -> Vec4 {
    sanitize_sample(s.direction, s.pdf)
}

/// Warps `u ∈ [0,1)²` with the warp `params.kind` (one of
/// [`raywave_shared::sampling::warp_kind`], parameters `a`, `b`, `c` as documented there; the
/// shading point of the light warps is the origin). Returns xyz = unit direction, w = its
/// solid-angle pdf (sr⁻¹), equal to [`pdf`]`(params, xyz)` up to rounding. For
/// `SPHERE_LIGHT_AREA` w is the density of the *direction* ([`sphere_light_area_pdf`], summed over
/// the front and back points), not of the sampled point. An unknown kind returns `Vec4::ZERO`.
pub fn sample(params: &WarpParams, u: Vec2) -> Vec4 {
    let kind = params.kind;
    let a = params.a;
    let b = params.b;
    let c = params.c;
    if kind == warp_kind::UNIFORM_HEMISPHERE {
        let d = sample_uniform_hemisphere(u);
        sanitize_sample(d, uniform_hemisphere_pdf(d))
    } else if kind == warp_kind::COSINE_HEMISPHERE {
        let d = sample_cosine_hemisphere(u);
        sanitize_sample(d, cosine_hemisphere_pdf(d))
    } else if kind == warp_kind::UNIFORM_SPHERE {
        sanitize_sample(sample_uniform_sphere(u), uniform_sphere_pdf())
    } else if kind == warp_kind::UNIFORM_CONE {
        let d = sample_uniform_cone(u, a.x);
        sanitize_sample(d, uniform_cone_pdf(d, a.x))
    } else if kind == warp_kind::SPHERE_LIGHT_CONE {
        light_vec4(sample_sphere_light_cone(Vec3::ZERO, a.xyz(), a.w, u))
    } else if kind == warp_kind::SPHERE_LIGHT_AREA {
        let s = sample_sphere_light_area(Vec3::ZERO, a.xyz(), a.w, u);
        sanitize_sample(s.direction, sphere_light_area_pdf(Vec3::ZERO, a.xyz(), a.w, s.direction))
    } else if kind == warp_kind::QUAD_SPHERICAL {
        light_vec4(sample_quad_spherical(Vec3::ZERO, a.xyz(), b.xyz(), c.xyz(), u))
    } else if kind == warp_kind::QUAD_AREA {
        light_vec4(sample_quad_area(Vec3::ZERO, a.xyz(), b.xyz(), c.xyz(), u))
    } else if kind == warp_kind::GGX_VNDF {
        // The pdf of l via h = normalize(v + l), as `pdf` computes it: at the rim of the visible
        // hemisphere (v·h → 0, l → −v) the sampled h cannot be recovered from l in f32, and a pdf
        // from the sampled h would disagree with `pdf(l)` there (it agrees to ~10⁻⁴ elsewhere).
        let alpha = Vec2::new(b.x, b.y);
        let l = sample_ggx_reflection(a.xyz(), alpha, u);
        sanitize_sample(l, ggx_reflection_pdf(a.xyz(), l, alpha))
    } else if kind == warp_kind::LTC {
        sample_ltc_with_pdf(Mat3::from_cols(a.xyz(), b.xyz(), c.xyz()), u)
    } else {
        Vec4::ZERO
    }
}

/// Solid-angle pdf (sr⁻¹) with which [`sample`] produces the unit direction `direction` for warp
/// `params.kind`; 0 for directions the warp never produces and for unknown kinds.
pub fn pdf(params: &WarpParams, direction: Vec3) -> f32 {
    let kind = params.kind;
    let a = params.a;
    let b = params.b;
    let c = params.c;
    let pdf = if kind == warp_kind::UNIFORM_HEMISPHERE {
        uniform_hemisphere_pdf(direction)
    } else if kind == warp_kind::COSINE_HEMISPHERE {
        cosine_hemisphere_pdf(direction)
    } else if kind == warp_kind::UNIFORM_SPHERE {
        uniform_sphere_pdf()
    } else if kind == warp_kind::UNIFORM_CONE {
        uniform_cone_pdf(direction, a.x)
    } else if kind == warp_kind::SPHERE_LIGHT_CONE {
        sphere_light_cone_pdf(Vec3::ZERO, a.xyz(), a.w, direction)
    } else if kind == warp_kind::SPHERE_LIGHT_AREA {
        sphere_light_area_pdf(Vec3::ZERO, a.xyz(), a.w, direction)
    } else if kind == warp_kind::QUAD_SPHERICAL {
        quad_spherical_pdf(Vec3::ZERO, a.xyz(), b.xyz(), c.xyz(), direction)
    } else if kind == warp_kind::QUAD_AREA {
        quad_area_pdf(Vec3::ZERO, a.xyz(), b.xyz(), c.xyz(), direction)
    } else if kind == warp_kind::GGX_VNDF {
        ggx_reflection_pdf(a.xyz(), direction, Vec2::new(b.x, b.y))
    } else if kind == warp_kind::LTC {
        ltc_pdf(ltc_inverse(Mat3::from_cols(a.xyz(), b.xyz(), c.xyz())), direction)
    } else {
        0.0
    };
    sanitize_pdf(pdf)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hash::{pcg3d, unit_float};
    use crate::shade::polygon::tests::form_factor_f64;
    use glam::{DVec3, UVec3};
    use std::vec::Vec;

    /// Samples that stress the clamps: the corners of the square, `1 − 2⁻²⁴`, and values a careless
    /// caller might pass (1, negative, NaN, Inf).
    fn hard_samples() -> Vec<Vec2> {
        let e = ONE_MINUS_EPSILON;
        let values = [0.0, e, 0.5, 0.25, 1.0e-7, 1.0, -0.5, 2.0, f32::NAN, f32::INFINITY];
        let mut out = Vec::new();
        for &x in &values {
            for &y in &values {
                out.push(Vec2::new(x, y));
            }
        }
        out
    }

    fn random_samples(n: u32, seed: u32) -> Vec<Vec2> {
        (0..n)
            .map(|i| {
                let bits = pcg3d(UVec3::new(i, 0, seed));
                Vec2::new(unit_float(bits.x), unit_float(bits.y))
            })
            .collect()
    }

    fn params(kind: u32, a: Vec4, b: Vec4, c: Vec4) -> WarpParams {
        WarpParams {
            kind,
            count: 0,
            padding: [0; 2],
            sampler: raywave_shared::SamplerParams { kind: 0, seed: 0, spp_log2: 0, resolution_log2: 0 },
            a,
            b,
            c,
        }
    }

    fn quad(o: Vec3, eu: Vec3, ev: Vec3, kind: u32) -> WarpParams {
        params(kind, o.extend(0.0), eu.extend(0.0), ev.extend(0.0))
    }

    fn ggx(theta_v: f32, alpha: Vec2) -> WarpParams {
        let v = Vec3::new(theta_v.sin(), 0.0, theta_v.cos());
        params(warp_kind::GGX_VNDF, v.extend(0.0), alpha.extend(0.0).extend(0.0), Vec4::ZERO)
    }

    /// Every parameter set of every kind, ordinary and hard.
    fn all_params() -> Vec<(&'static str, WarpParams)> {
        let z = Vec4::ZERO;
        let sphere = |kind, c: Vec3, r: f32| params(kind, c.extend(r), z, z);
        let mut v = Vec::new();
        v.push(("uniform hemisphere", params(warp_kind::UNIFORM_HEMISPHERE, z, z, z)));
        v.push(("cosine hemisphere", params(warp_kind::COSINE_HEMISPHERE, z, z, z)));
        v.push(("uniform sphere", params(warp_kind::UNIFORM_SPHERE, z, z, z)));
        for cos_max in [0.9, 0.0, -1.0, 1.0 - 1.0e-7, 1.0, 2.0, f32::NAN] {
            v.push(("cone", params(warp_kind::UNIFORM_CONE, Vec4::splat(cos_max), z, z)));
        }
        for kind in [warp_kind::SPHERE_LIGHT_CONE, warp_kind::SPHERE_LIGHT_AREA] {
            v.push(("sphere d=3", sphere(kind, Vec3::new(0.0, 0.0, 3.0), 1.0)));
            v.push(("sphere crossing the horizon", sphere(kind, Vec3::new(2.0, 0.3, 0.4), 1.0)));
            v.push(("sphere d=1e3", sphere(kind, Vec3::new(600.0, 0.0, 800.0), 1.0)));
            v.push(("sphere d=1e6", sphere(kind, Vec3::new(0.0, 6.0e5, 8.0e5), 1.0)));
            v.push(("p inside sphere", sphere(kind, Vec3::new(0.2, 0.1, -0.3), 1.0)));
            v.push(("p on sphere", sphere(kind, Vec3::new(0.0, 0.0, 1.0), 1.0)));
            v.push(("point light", sphere(kind, Vec3::new(0.0, 0.0, 1.0), 0.0)));
            v.push(("sphere at p", sphere(kind, Vec3::ZERO, 0.0)));
            v.push(("nan sphere", sphere(kind, Vec3::new(f32::NAN, 0.0, 1.0), 1.0)));
        }
        for kind in [warp_kind::QUAD_SPHERICAL, warp_kind::QUAD_AREA] {
            let (x, y) = (Vec3::X, Vec3::Y);
            v.push(("quad overhead", quad(Vec3::new(-0.5, -0.5, 1.0), x, y, kind)));
            v.push(("quad crossing the horizon", quad(Vec3::new(-1.0, 2.0, -0.5), 2.0 * x, 1.5 * Vec3::Z, kind)));
            v.push(("p on quad plane", quad(Vec3::new(0.5, -0.5, 0.0), x, y, kind)));
            v.push(("p on quad", quad(Vec3::new(-0.5, -0.5, 0.0), x, y, kind)));
            v.push(("quad edge-on", quad(Vec3::new(1.0, -0.5, 1.0e-6), x, y, kind)));
            v.push(("quad almost edge-on", quad(Vec3::new(1.0, -0.5, 1.0e-3), x, y, kind)));
            v.push(("quad 1e6 away", quad(Vec3::new(-0.5, -0.5, 1.0e6), x, y, kind)));
            v.push(("huge quad 1e6 away", quad(Vec3::new(-1.0e6, -1.0e6, 1.0e6), 2.0e6 * x, 2.0e6 * y, kind)));
            v.push(("degenerate quad", quad(Vec3::new(-0.5, -0.5, 1.0), x, Vec3::ZERO, kind)));
            v.push(("tiny quad", quad(Vec3::new(-0.5e-3, -0.5e-3, 1.0), 1.0e-3 * x, 1.0e-3 * y, kind)));
        }
        for theta in [0.0, 1.0, 1.4835, core::f32::consts::FRAC_PI_2, 2.0] {
            for alpha in [0.0, 1.0e-6, 0.05, 0.3, 1.0, 1.0e5] {
                v.push(("ggx", ggx(theta, Vec2::splat(alpha))));
            }
            v.push(("ggx anisotropic", ggx(theta, Vec2::new(0.01, 0.5))));
        }
        let grazing = Vec3::new((1.0f32 - 1.0e-12).sqrt(), 0.0, 1.0e-6);
        v.push(("ggx v.z = 1e-6", params(warp_kind::GGX_VNDF, grazing.extend(0.0), Vec4::splat(0.3), z)));
        v.push(("ggx v.z = 1e-6 alpha 0", params(warp_kind::GGX_VNDF, grazing.extend(0.0), z, z)));
        let m = |c0: Vec3, c1: Vec3, c2: Vec3| params(warp_kind::LTC, c0.extend(0.0), c1.extend(0.0), c2.extend(0.0));
        v.push(("ltc identity", m(Vec3::X, Vec3::Y, Vec3::Z)));
        v.push(("ltc skewed", m(Vec3::new(0.5, 0.0, 0.1), Vec3::new(0.0, 0.7, 0.0), Vec3::new(0.2, 0.0, 1.0))));
        v.push(("ltc singular", m(Vec3::X, Vec3::X, Vec3::Z)));
        v.push(("ltc zero", m(Vec3::ZERO, Vec3::ZERO, Vec3::ZERO)));
        v
    }

    fn assert_finite_sample(name: &str, s: Vec4) {
        assert!(s.is_finite(), "{name}: {s}");
        assert!((s.xyz().length() - 1.0).abs() < 1.0e-5, "{name}: |{}| = {}", s.xyz(), s.xyz().length());
        assert!(s.w >= 0.0, "{name}: pdf {}", s.w);
    }

    #[test]
    fn every_output_is_finite_for_hard_inputs() {
        let mut u = hard_samples();
        u.extend(random_samples(256, 1));
        for (name, p) in all_params() {
            for &ui in &u {
                let s = sample(&p, ui);
                assert_finite_sample(name, s);
                let q = pdf(&p, s.xyz());
                assert!(q.is_finite() && q >= 0.0, "{name} u={ui}: pdf {q}");
            }
            for d in [Vec3::Z, -Vec3::Z, Vec3::X, Vec3::ZERO, Vec3::NAN, Vec3::new(1.0, 1.0, 1.0)] {
                let q = pdf(&p, d);
                assert!(q.is_finite() && q >= 0.0, "{name} dir={d}: pdf {q}");
            }
        }
    }

    #[test]
    fn light_samples_are_finite_for_hard_inputs() {
        let p = Vec3::new(0.1, -0.2, 0.3);
        for &u in &hard_samples() {
            for (c, r) in [(Vec3::new(0.0, 0.0, 3.0), 1.0), (p, 1.0), (p, 0.0), (Vec3::new(1.0e6, 0.0, 0.0), 1.0)] {
                for s in [sample_sphere_light_cone(p, c, r, u), sample_sphere_light_area(p, c, r, u)] {
                    assert!(s.direction.is_finite() && (s.direction.length() - 1.0).abs() < 1.0e-5, "{s:?}");
                    assert!(s.distance.is_finite() && s.distance >= 0.0, "{s:?}");
                    assert!(s.pdf.is_finite() && s.pdf >= 0.0, "{s:?}");
                    assert!(s.point.is_finite() && s.normal.is_finite(), "{s:?}");
                }
            }
            let (o, eu, ev) = (Vec3::new(-0.5, -0.5, 0.3), Vec3::X, Vec3::Y);
            for s in [sample_quad_spherical(p, o, eu, ev, u), sample_quad_area(p, o, eu, ev, u)] {
                assert!(s.direction.is_finite() && s.distance.is_finite() && s.pdf.is_finite(), "{s:?}");
                assert!(s.point.is_finite() && (s.normal.length() - 1.0).abs() < 1.0e-5, "{s:?}");
            }
        }
    }

    /// Area sampling's pdf is the returned point's own density, `d²/(|cos θl|·4πr²)`, checked in
    /// f64 from the point and normal it returns (the warp probe's check calls the sampler's own
    /// conversion, so it cannot see a wrong one).
    #[test]
    fn sphere_area_samples_carry_their_points_solid_angle_density() {
        let (p, c, r) = (Vec3::new(0.2, -0.1, 0.4), Vec3::new(1.0, 2.0, 3.0), 0.7f32);
        for u in random_samples(512, 7) {
            let s = sample_sphere_light_area(p, c, r, u);
            let to_point = (s.point - p).as_dvec3();
            let cos = s.normal.as_dvec3().dot(to_point.normalize()).abs();
            assert!(((s.point - c).length() - r).abs() < 1e-5 && (s.normal.length() - 1.0).abs() < 1e-5, "{s:?}");
            if cos < 1e-3 {
                continue; // edge-on: the density is ill-conditioned there
            }
            let expected = to_point.length_squared() / (cos * 4.0 * core::f64::consts::PI * f64::from(r * r));
            assert!((f64::from(s.pdf) / expected - 1.0).abs() < 1e-4, "u {u}: pdf {} vs {expected}", s.pdf);
        }
    }

    /// The visible-normal pdf and the reflection pdf are computed apart (`D_v(h)` against
    /// `G1(v)/vz · D(h)/4`); the reflection Jacobian ties them: `D_v(h) = 4(v·h)·p(l)` for
    /// `l = reflect(v, h)`. The reflection pdf is chi-square tested, so this checks the other.
    #[test]
    fn the_visible_normal_pdf_is_the_reflection_pdf_through_its_jacobian() {
        let u = random_samples(256, 8);
        for (v, alpha) in [
            (Vec3::new(0.3, -0.2, 0.93).normalize(), Vec2::splat(0.3)),
            (Vec3::new(0.9, 0.1, 0.2).normalize(), Vec2::new(0.05, 0.6)),
            (Vec3::Z, Vec2::splat(1.0)),
        ] {
            for &ui in &u {
                let h = sample_ggx_vndf(v, alpha, ui);
                let vh = v.dot(h);
                if vh < 1e-3 {
                    continue;
                }
                let l = reflect_view(v, h);
                let (vndf, reflection) = (ggx_vndf_pdf(v, h, alpha), ggx_reflection_pdf(v, l, alpha));
                let relation = 4.0 * vh * reflection;
                assert!((vndf / relation - 1.0).abs() < 2e-3, "v {v} α {alpha} h {h}: {vndf} vs {relation}");
            }
        }
    }

    /// The cone sampler draws uniformly in solid angle, as its constant pdf says: the sample's
    /// `1 − cos θ` is `u₀·(1 − cos θmax)`, computed here in f64 from the returned direction as
    /// `|d × a|²/(1 + d·a)`, from the axis to the rim, and the sampled point lies along the
    /// direction at the returned distance. Cones from `p` 10⁻³ off the sphere (where pbrt-v4's
    /// point from the angle at the centre put the directions up to 0.46 rad off) to 100 radii
    /// away, and around sin²θmax = 6.85·10⁻⁴, where pbrt-v4's small-angle branch drew `sin²θ`
    /// uniformly instead (up to 4.3·10⁻⁵ off in this fraction, at u₀ = ½). Measured: the fraction
    /// within 2.5·10⁻⁷ at 1.001 (pbrt-v4's construction: 5.2·10⁻³), 4.4·10⁻⁷ at 3, 4.0·10⁻⁶ at 38
    /// and 8.6·10⁻⁶ at 100 (the f32 direction's rounding, which grows as the cone narrows).
    #[test]
    fn sphere_cone_samples_are_uniform_in_solid_angle_near_and_far() {
        let p = Vec3::new(0.3, -0.2, 0.1);
        let (mut worst_fraction, mut worst_point) = (0.0f64, 0.0f32);
        for distance in [1.001f32, 1.05, 3.0, 10.0, 38.0, 38.3, 100.0] {
            let c = p + Vec3::new(0.36, 0.48, 0.8) * distance;
            let axis = (c - p).as_dvec3().normalize();
            let sin2_max = 1.0 / (c - p).as_dvec3().length_squared();
            let one_minus_cos_max = sin2_max / (1.0 + (1.0 - sin2_max).sqrt());
            for k in 0..=16 {
                for phi in [0.3, 0.8] {
                    let u = Vec2::new((k as f32 / 16.0).min(ONE_MINUS_EPSILON), phi);
                    let s = sample_sphere_light_cone(p, c, 1.0, u);
                    let d = s.direction.as_dvec3();
                    let one_minus_cos = d.cross(axis).length_squared() / (1.0 + d.dot(axis));
                    let fraction = (one_minus_cos / one_minus_cos_max - f64::from(u.x)).abs();
                    // Relative to the point's coordinates, which round it.
                    let along = (p + s.distance * s.direction - s.point).length() / (1.0 + distance);
                    assert!(s.pdf > 0.0, "distance {distance}, u {u}: {s:?}");
                    assert!(fraction < 2.0e-5, "distance {distance}, u {u}: fraction off by {fraction}");
                    assert!(along < 1.0e-6, "distance {distance}, u {u}: the point is {along} off the ray");
                    worst_fraction = worst_fraction.max(fraction);
                    worst_point = worst_point.max(along);
                }
            }
        }
        std::println!("worst fraction {worst_fraction:.2e}, point {worst_point:.2e}");
    }

    /// The cone sampler's light normal is the same construction evaluated in f64 — along the
    /// kernel's own (rounded) axis and frame, `(t·ω − d·axis)/r` — within 10⁻⁵ rad, for spheres
    /// from 10⁻³ to 10⁻⁸ of their distance across (1 km from the origin) and from the axis out to
    /// the rim, and it faces `p`. Built as `(t·ω − (c − p))/r` in f32 it was 0.06 rad off at 10⁻⁶
    /// and zero below ~3·10⁻⁸; with `√(sin²θmax − sin²θ)` as written, 2.4·10⁻⁴ rad off at the rim.
    #[test]
    fn sphere_cone_normals_match_their_f64_construction_out_to_the_rim() {
        let p = Vec3::new(1000.0, -20.0, 3.0);
        let mut worst = 0.0f64;
        for ratio in [1.0e-3f32, 1.0e-5, 1.0e-6, 1.0e-7, 1.0e-8] {
            let (c, r) = (p + Vec3::new(0.36, 0.48, 0.8) * 1000.0, ratio * 1000.0);
            let wc = c - p;
            let axis = wc / wc.length();
            let (t1, t2) = axis.any_orthonormal_pair();
            let (t1, t2, axis) = (t1.as_dvec3(), t2.as_dvec3(), axis.as_dvec3());
            let (d, r64) = (wc.as_dvec3().length(), f64::from(r));
            let sin2_max = (r64 / d) * (r64 / d);
            let one_minus_cos_max = sin2_max / (1.0 + (1.0 - sin2_max).sqrt());
            for k in 0..=16 {
                for phi in [0.0f32, 0.3, 0.8] {
                    let u = Vec2::new((k as f32 / 16.0).min(ONE_MINUS_EPSILON), phi);
                    let s = sample_sphere_light_cone(p, c, r, u);
                    let omc = f64::from(u.x) * one_minus_cos_max;
                    let (cos, sin) = (1.0 - omc, (omc * (2.0 - omc)).sqrt());
                    let azimuth = f64::from(TAU * u.y);
                    let omega = -sin * azimuth.cos() * t1 - sin * azimuth.sin() * t2 + cos * axis;
                    let t = d * cos - d * (sin2_max - sin * sin).max(0.0).sqrt();
                    let expected = ((t * omega - d * axis) / r64).normalize();
                    let normal = s.normal.as_dvec3();
                    let off = normal.cross(expected).length().atan2(normal.dot(expected));
                    let facing = normal.dot(-s.direction.as_dvec3());
                    assert!(s.pdf > 0.0 && off < 1.0e-5, "r/d {ratio}, u {u}: the normal is {off} rad off: {s:?}");
                    assert!(facing > 0.0 || k == 16 && facing > -1.0e-5, "r/d {ratio}, u {u}: n·(−ω) = {facing}");
                    worst = worst.max(off);
                }
            }
        }
        std::println!("normals at most {worst:.1e} rad off");
    }

    /// The cone sampler and its pdf agree, with unit directions and normals, at extreme scales
    /// (a review's cases): a sphere 10⁻²³ across (`d·r` underflowed and every sample was lost
    /// while the pdf was 4.4; `|c − p|²` underflows too), one 10¹⁹ away (`d·r` overflowed:
    /// normals on the axis for directions off it), `p` within an ulp of the surface (where
    /// `|c − p|` rounded to `r` every sample lay at distance 0 and was lost while the pdf was
    /// 1/2π), and spheres 10⁸ and 10¹⁰ radii away, narrower than an `f32` direction resolves.
    #[test]
    fn sphere_cone_sample_and_pdf_agree_at_extreme_scales() {
        let cases = [
            (Vec3::ZERO, Vec3::new(0.0, 0.0, 3.74e-23), 1.0e-23),
            (Vec3::ZERO, Vec3::new(0.0, 0.0, 1.8e19), 1.79e19),
            (Vec3::ZERO, Vec3::new(0.0, 0.000_345_267, 1.0), 1.0),
            (Vec3::new(0.0, 0.3, 0.0), Vec3::new(359_996_512.0, 480_015_328.0, 799_992_256.0), 1.0),
            (Vec3::new(0.0, 0.3, 0.0), Vec3::new(3.6e9, 4.8e9, 8.0e9), 1.0),
        ];
        for (p, c, r) in cases {
            let mut lost = 0;
            for ui in random_samples(4096, 11) {
                let s = sample_sphere_light_cone(p, c, r, ui);
                let q = sphere_light_cone_pdf(p, c, r, s.direction);
                lost += usize::from(!(s.pdf > 0.0));
                let unit = (s.normal.length() - 1.0).abs() < 1.0e-5 && (s.direction.length() - 1.0).abs() < 1.0e-5;
                assert!(unit && s.point.is_finite(), "p {p}, c {c}, r {r}, u {ui}: {s:?}");
                assert!((q - s.pdf).abs() <= 1.0e-3 * s.pdf, "p {p}, c {c}, r {r}, u {ui}: pdf {q} vs {s:?}");
            }
            assert_eq!(lost, 0, "p {p}, c {c}, r {r}: samples without a pdf");
        }
    }

    /// For ordinary inputs every sample has a positive pdf that the pdf function reproduces, and
    /// for light warps the sampled point lies on the light along the returned direction.
    #[test]
    fn sample_and_pdf_agree() {
        let u = random_samples(4096, 2);
        let mut failures = 0;
        for (name, p) in all_params() {
            let degenerate = name.contains("p on")
                || name.contains("point light")
                || name.contains("sphere at p")
                || name.contains("nan")
                || name.contains("degenerate")
                || name.contains("singular")
                || name.contains("zero")
                || name.contains("edge-on")
                || (p.kind == warp_kind::UNIFORM_CONE && !(p.a.x < 1.0));
            // Beyond what f32 directions resolve: GGX lobes narrower than ~0.01 or seen at
            // grazing angles (h = normalize(v + l) loses the digits that D depends on), absurd
            // roughness (l ≈ −v), and directions to the silhouette of a sphere 10³·r away or
            // more, which cannot tell whether they hit it (see `sphere_light_area_pdf`).
            let ggx_extreme = p.kind == warp_kind::GGX_VNDF
                && (p.b.x < 0.01 || p.b.y < 0.01 || p.b.x > 2.0 || p.b.y > 2.0 || p.a.z < 0.05);
            let far_area = p.kind == warp_kind::SPHERE_LIGHT_AREA && p.a.xyz().length() > 100.0;
            if degenerate || ggx_extreme || far_area {
                continue;
            }
            let mut bad = 0;
            for &ui in &u {
                let s = sample(&p, ui);
                let q = pdf(&p, s.xyz());
                if !(s.w > 0.0) || !((q - s.w).abs() <= 1.0e-3 * s.w) {
                    if bad < 3 {
                        std::println!("{name} {p:?} u={ui}: sampled pdf {} vs pdf {q}", s.w);
                    }
                    bad += 1;
                }
            }
            failures += bad;
        }
        assert_eq!(failures, 0);
    }

    /// Area sampling of a far sphere: the few directions near its silhouette that f32 cannot
    /// place inside or outside get pdf 0 from the pdf function (and so from `sample`).
    #[test]
    fn far_sphere_area_sampling_rarely_loses_samples() {
        let p = params(warp_kind::SPHERE_LIGHT_AREA, Vec4::new(600.0, 0.0, 800.0, 1.0), Vec4::ZERO, Vec4::ZERO);
        let u = random_samples(1 << 16, 6);
        let zero = u.iter().filter(|&&u| sample(&p, u).w == 0.0).count();
        assert!(zero < u.len() / 100, "{zero} of {} samples with pdf 0", u.len());
    }

    /// A light a centimetre across (10⁻⁶ sr, area-sampled), 10 units from a point 10⁴ units from
    /// the origin: every sample's direction hits the light and has the pdf the sample carries.
    /// Formed through the sampled point's absolute coordinates, whose grid there is 10⁻³, the
    /// directions took 156 distinct values in 20 000 samples and 4.8 % of them missed the light.
    #[test]
    fn far_from_the_origin_area_samples_of_a_small_light_hit_it() {
        let far = Vec3::splat(1.0e4);
        let (p, o, eu, ev) = (far, far + Vec3::new(0.3, -0.2, 10.0), Vec3::X * 0.0107, Vec3::Y * 0.0113);
        assert!(quad_solid_angle(p, o, eu, ev) < QUAD_MIN_SPHERICAL_SOLID_ANGLE, "the area-sampled regime");
        let samples: Vec<LightSample> =
            random_samples(20_000, 11).into_iter().map(|u| sample_quad_spherical(p, o, eu, ev, u)).collect();
        for s in &samples {
            let pdf = quad_spherical_pdf(p, o, eu, ev, s.direction);
            assert!(s.pdf > 0.0 && (pdf / s.pdf - 1.0).abs() < 1.0e-3, "{s:?}: pdf {pdf}");
        }
        let mut directions: Vec<[u32; 3]> = samples.iter().map(|s| s.direction.to_array().map(f32::to_bits)).collect();
        directions.sort_unstable();
        directions.dedup();
        assert!(directions.len() > samples.len() / 2, "{} distinct directions", directions.len());
    }

    /// Each sample's point along `ev` is where the inverse of `h(y) = y/√(dd² + y²)`, in `f64`,
    /// puts `lerp(h(y₀), h(y₁), u₁)`, within 1.5·10⁻⁶ of the edge's length, for a square seen
    /// nearly edge-on from beyond either `ev` edge (10⁻³ off its plane), overhead (a Cornell-sized
    /// light 2 units up, whose samples `1 − c` had put 2·10⁻⁶ off), from 10⁻²⁵ off its plane at
    /// its edge, and two controls.
    /// Interpolating `h` itself, which rounds to ±1 within ulps edge-on, put samples up to 0.49
    /// off and sent 0.02 % onto the far edge.
    #[test]
    fn samples_along_the_far_edge_follow_the_drawn_fraction_edge_on() {
        let unit = Vec3::new(-0.5, -0.5, 0.0);
        let mut worst = 0.0f64;
        // (p, the square's corner o, its side): edges along x and y.
        for (p, o, side) in [
            (Vec3::new(0.0, -1.0, -1.0e-3), unit, 1.0),
            (Vec3::new(0.0, 1.0, -1.0e-3), unit, 1.0),
            (Vec3::new(0.01, 0.02, -2.0), Vec3::new(-0.125, -0.125, 0.0), 0.25),
            (Vec3::new(0.0, 0.0, 1.0e-25), Vec3::new(-0.5, -1.0, 0.0), 1.0),
            (Vec3::new(0.2, -1.5, 0.1), unit, 1.0),
            (Vec3::new(0.0, -1.0, -1.0), unit, 1.0),
        ] {
            let (eu, ev) = (Vec3::X * side, Vec3::Y * side);
            assert!(quad_solid_angle(p, o, eu, ev) >= QUAD_MIN_SPHERICAL_SOLID_ANGLE, "the spherical regime at {p}");
            for u in random_samples(20_000, 5) {
                let s = sample_quad_spherical(p, o, eu, ev, u);
                assert!(s.pdf > 0.0, "{p} {u}");
                // The point's coordinates in the sampler's frame: x along eu, y along ev, from p.
                let local = s.point.as_dvec3() - p.as_dvec3();
                let (x, y, z) = (local.x, local.y, local.z);
                let y0 = f64::from(o.y) - f64::from(p.y);
                let y1 = y0 + f64::from(side);
                let dd = (x * x + z * z).sqrt();
                let h = |y: f64| y / (dd * dd + y * y).sqrt();
                let hv = h(y0) + f64::from(u.y) * (h(y1) - h(y0));
                let expected = hv * dd / (1.0 - hv * hv).sqrt();
                let error = (y - expected).abs() / f64::from(side);
                assert!(error < 1.5e-6, "{p} u {u}: y {y} where {expected} was drawn");
                worst = worst.max(error);
            }
        }
        std::println!("worst y error {worst:e} of the edge");
    }

    /// Seen nearly edge-on (`|cos θl|` ≈ 7.6·10⁻⁶), a light is widened only along the ray's
    /// projection onto its plane, where rounding moves the hit point by `1/|cos θl|`: a ray that
    /// passes 0.15 units beside it (0.11 rad off) misses, one just inside its far edge hits.
    #[test]
    fn a_quad_seen_edge_on_is_not_widened_sideways() {
        let (p, o, eu, ev) = (Vec3::new(0.0, 0.0, 1.0e-5), Vec3::new(1.0, -0.25, 0.0), Vec3::X * 0.5, Vec3::Y * 0.5);
        let towards = |point: Vec3| (point - p).normalize();
        assert_eq!(quad_ray_distance(p, o, eu, ev, towards(Vec3::new(1.25, 0.4, 0.0))), 0.0, "beside the light");
        assert!(quad_ray_distance(p, o, eu, ev, towards(Vec3::new(1.499, 0.249, 0.0))) > 0.0, "inside its far corner");
        assert!(quad_ray_distance(p, o, eu, ev, towards(Vec3::new(1.0001, 0.0, 0.0))) > 0.0, "inside its near edge");
    }

    /// Rays nearly parallel to a light's plane (`|cos θl|` of 10⁻⁵ … 10⁻⁷) from a point 10⁻²
    /// above it meet the plane 10³ … 10⁵ light widths beside it: they miss, and every quad pdf is
    /// 0 there. The slack along the ray, which grows as `1/cos²θl`, had accepted those from
    /// `|cos θl|` ≈ 2·10⁻⁶ on (distance 10⁴, area pdf 10¹⁴).
    #[test]
    fn rays_nearly_parallel_to_a_light_miss_it_far_beside_it() {
        let (p, o, eu, ev) = (Vec3::ZERO, Vec3::new(-0.5, -0.5, -0.01), Vec3::X, Vec3::Y);
        for e in [1e-5f32, 1e-6, 3e-7, 1e-7] {
            let d = Vec3::new(-1.0, 0.0, -e).normalize();
            assert_eq!(quad_ray_distance(p, o, eu, ev, d), 0.0, "e {e}");
            assert_eq!(quad_area_pdf(p, o, eu, ev, d), 0.0, "e {e}");
            assert_eq!(quad_spherical_pdf(p, o, eu, ev, d), 0.0, "e {e}");
        }
        // A control: the same plane reached inside the light, at 0.2 from its centre.
        let inside = Vec3::new(-0.2, 0.0, -0.01).normalize();
        assert!(quad_ray_distance(p, o, eu, ev, inside) > 0.0 && quad_area_pdf(p, o, eu, ev, inside) > 0.0);
    }

    #[test]
    fn degenerate_inputs_give_pdf_zero() {
        let z = Vec4::ZERO;
        // Zero-solid-angle cone.
        let cone = params(warp_kind::UNIFORM_CONE, Vec4::ONE, z, z);
        assert_eq!(sample(&cone, Vec2::splat(0.3)), Vec4::Z);
        assert_eq!(pdf(&cone, Vec3::Z), 0.0);
        // Point light.
        let s = sample_sphere_light_cone(Vec3::ZERO, Vec3::Z, 0.0, Vec2::splat(0.5));
        assert_eq!(s.pdf, 0.0);
        // p in the quad's plane.
        let (o, eu, ev) = (Vec3::new(-0.5, -0.5, 0.0), Vec3::X, Vec3::Y);
        assert_eq!(quad_solid_angle(Vec3::ZERO, o, eu, ev), 0.0);
        assert_eq!(sample_quad_spherical(Vec3::ZERO, o, eu, ev, Vec2::splat(0.5)).pdf, 0.0);
        assert_eq!(quad_spherical_pdf(Vec3::ZERO, o, eu, ev, Vec3::X), 0.0);
        assert_eq!(quad_area_pdf(Vec3::ZERO, o + Vec3::X, eu, ev, Vec3::X), 0.0);
        // Singular LTC.
        assert_eq!(ltc_inverse(Mat3::from_cols(Vec3::X, Vec3::X, Vec3::Z)), Mat3::ZERO);
        assert_eq!(ltc_pdf(Mat3::ZERO, Vec3::Z), 0.0);
    }

    #[test]
    fn concentric_disk_maps_into_the_disk() {
        assert_eq!(sample_concentric_disk(Vec2::splat(0.5)), Vec2::ZERO);
        for u in hard_samples().into_iter().chain(random_samples(1000, 3)) {
            let d = sample_concentric_disk(u);
            assert!(d.is_finite() && d.length() <= 1.0 + 1.0e-6, "{u} → {d}");
        }
        // The border of the square maps to the circle.
        let d = sample_concentric_disk(Vec2::new(0.0, 0.3));
        assert!((d.length() - 1.0).abs() < 1.0e-6);
    }

    #[test]
    fn simple_pdfs_have_their_closed_forms() {
        assert!((uniform_hemisphere_pdf(Vec3::X) - 0.5 / PI).abs() < 1.0e-7);
        assert_eq!(uniform_hemisphere_pdf(-Vec3::Z), 0.0);
        assert!((cosine_hemisphere_pdf(Vec3::Z) - 1.0 / PI).abs() < 1.0e-7);
        assert_eq!(cosine_hemisphere_pdf(-Vec3::Z), 0.0);
        assert!((uniform_sphere_pdf() - 0.25 / PI).abs() < 1.0e-7);
        assert!((uniform_cone_pdf(Vec3::Z, 0.0) - 0.5 / PI).abs() < 1.0e-7);
        assert_eq!(uniform_cone_pdf(Vec3::X, 0.5), 0.0);
        // LTC with M = I is the cosine lobe.
        for d in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.0, 0.8, -0.6)] {
            assert!((ltc_pdf(Mat3::IDENTITY, d) - cosine_hemisphere_pdf(d)).abs() < 1.0e-6);
        }
    }

    #[test]
    fn tiny_cones_stay_inside_and_finite() {
        let cos_max = 1.0 - 1.0e-7;
        for u in hard_samples().into_iter().chain(random_samples(1000, 4)) {
            let d = sample_uniform_cone(u, cos_max);
            assert!(d.is_finite() && (d.length() - 1.0).abs() < 1.0e-6);
            assert!(d.z >= cos_max, "{d}");
            let q = uniform_cone_pdf(d, cos_max);
            assert!(q.is_finite() && q > 1.0e6, "{q}");
        }
    }

    /// pbrt-v4's `SampleSphericalRectangle` in `f64` (corner angles from `acos`, the solid angle
    /// as their sum minus 2π, `cu` and `xu` as written): the oracle of the `f32` sampler.
    fn spherical_rectangle_f64(p: DVec3, o: DVec3, eu: DVec3, ev: DVec3, u: [f64; 2]) -> DVec3 {
        let (ex, ey) = (eu.normalize(), ev.normalize());
        let mut ez = ex.cross(ey);
        let po = o - p;
        let (x0, y0, mut z0) = (ex.dot(po), ey.dot(po), ez.dot(po));
        if z0 > 0.0 {
            ez = -ez;
            z0 = -z0;
        }
        let (x1, y1) = (x0 + eu.length(), y0 + ev.length());
        let corners = [DVec3::new(x0, y0, z0), DVec3::new(x1, y0, z0), DVec3::new(x1, y1, z0), DVec3::new(x0, y1, z0)];
        let n: Vec<DVec3> = (0..4).map(|i| corners[i].cross(corners[(i + 1) % 4]).normalize()).collect();
        let g: Vec<f64> = (0..4).map(|i| (-n[i].dot(n[(i + 1) % 4])).acos()).collect();
        let solid_angle = g.iter().sum::<f64>() - 2.0 * core::f64::consts::PI;
        let au = u[0] * solid_angle - g[2] - g[3];
        let fu = (au.cos() * n[0].z - n[2].z) / au.sin();
        let cu = (1.0 / (fu * fu + n[0].z * n[0].z).sqrt()).copysign(fu).clamp(-1.0, 1.0);
        let xu = (-(cu * z0) / (1.0 - cu * cu).sqrt()).clamp(x0, x1);
        let dd = (xu * xu + z0 * z0).sqrt();
        let (h0, h1) = (y0 / (dd * dd + y0 * y0).sqrt(), y1 / (dd * dd + y1 * y1).sqrt());
        let hv = h0 + u[1] * (h1 - h0);
        let yv = if hv * hv < 1.0 - 1.0e-12 { hv * dd / (1.0 - hv * hv).sqrt() } else { y1 };
        (xu * ex + yv * ey + z0 * ez).normalize()
    }

    #[test]
    fn spherical_rectangle_samples_match_f64_also_seen_edge_on() {
        // The Cornell light (130 × 105 mm at y = 548.7 mm) from points 1 mm … 10 cm below its plane
        // across the box: from the walls' tops it is seen nearly edge-on (z₀ ≪ x₀).
        let (o, eu, ev) = (Vec3::new(0.343, 0.5487, 0.227), Vec3::new(0.0, 0.0, 0.105), Vec3::new(-0.13, 0.0, 0.0));
        for below in [1.0e-3f32, 5.0e-3, 2.0e-2, 1.0e-1] {
            let mut worst = 0.0f64;
            for (x, z) in [(0.0f32, 0.0f32), (0.1, 0.15), (0.45, 0.5), (0.556, 0.559), (0.0, 0.3), (0.3, 0.0)] {
                let p = Vec3::new(x, 0.5487 - below, z);
                if quad_solid_angle(p, o, eu, ev) < QUAD_MIN_SPHERICAL_SOLID_ANGLE {
                    continue;
                }
                for i in 0..64 {
                    for j in 0..8 {
                        let u = Vec2::new((i as f32 + 0.5) / 64.0, (j as f32 + 0.5) / 8.0);
                        let sample = sample_quad_spherical(p, o, eu, ev, u);
                        let exact = spherical_rectangle_f64(
                            p.as_dvec3(),
                            o.as_dvec3(),
                            eu.as_dvec3(),
                            ev.as_dvec3(),
                            [f64::from(u.x), f64::from(u.y)],
                        );
                        worst = worst.max((sample.direction.as_dvec3() - exact).abs().max_element());
                    }
                }
            }
            // As pbrt writes it, in f32: up to 2.6e-3 at 1 mm, 9e-4 at 5 mm.
            assert!(worst < 5.0e-6, "{below} m below the light: direction off by {worst:e}");
        }
    }

    #[test]
    fn quad_solid_angle_matches_the_closed_form() {
        // Rectangle of half-sides a, b centred at distance d: Ω = 4·asin(ab/√((a² + d²)(b² + d²))).
        for (a, b, d) in [(1.0f32, 1.0, 1.0), (0.5, 2.0, 0.3), (1.0e-3, 1.0e-3, 1.0), (1.0, 1.0, 1.0e3)] {
            let exact = 4.0 * (a * b / ((a * a + d * d) * (b * b + d * d)).sqrt()).asin();
            let o = Vec3::new(-a, -b, d);
            for p in [Vec3::ZERO, Vec3::new(0.0, 0.0, 2.0 * d)] {
                let omega = quad_solid_angle(p, o, 2.0 * a * Vec3::X, 2.0 * b * Vec3::Y);
                assert!((omega - exact).abs() <= 1.0e-5 * exact, "{a} {b} {d}: {omega} vs {exact}");
            }
        }
    }

    #[test]
    fn light_points_lie_on_the_light_along_the_direction() {
        let p = Vec3::new(0.1, -0.2, 0.3);
        let (c, r) = (Vec3::new(1.0, 2.0, 3.0), 0.7);
        let (o, eu, ev) = (Vec3::new(-0.5, 1.0, -0.5), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 0.6, 0.8));
        for u in random_samples(1000, 5) {
            for s in [sample_sphere_light_cone(p, c, r, u), sample_sphere_light_area(p, c, r, u)] {
                assert!(((s.point - c).length() - r).abs() < 1.0e-5, "{s:?}");
                assert!((s.normal - (s.point - c) / r).length() < 1.0e-4, "{s:?}");
                assert!((p + s.distance * s.direction - s.point).length() < 1.0e-5, "{s:?}");
            }
            // The cone sampler only produces the visible side.
            let s = sample_sphere_light_cone(p, c, r, u);
            assert!(s.normal.dot(p - s.point) >= -1.0e-4, "{s:?}");
            for s in [sample_quad_spherical(p, o, eu, ev, u), sample_quad_area(p, o, eu, ev, u)] {
                assert!((s.point - o).dot(eu.cross(ev)).abs() < 1.0e-5, "{s:?}");
                assert!((p + s.distance * s.direction - s.point).length() < 1.0e-5, "{s:?}");
            }
        }
    }

    #[test]
    fn ggx_is_finite_at_grazing_views_and_tiny_roughness() {
        let grazing = Vec3::new((1.0f32 - 1.0e-12).sqrt(), 0.0, 1.0e-6);
        for alpha in [0.0, 1.0e-6, 1.0e-4, 0.3, 1.0] {
            let a = Vec2::splat(alpha);
            for v in [grazing, Vec3::Z, Vec3::new(0.6, 0.0, -0.8)] {
                for u in hard_samples() {
                    let h = sample_ggx_vndf(v, a, u);
                    assert!(h.is_finite() && (h.length() - 1.0).abs() < 1.0e-5 && h.z >= 0.0, "{h}");
                    let l = sample_ggx_reflection(v, a, u);
                    assert!(l.is_finite() && (l.length() - 1.0).abs() < 1.0e-5, "{l}");
                    for q in [ggx_vndf_pdf(v, h, a), ggx_reflection_pdf(v, l, a), ggx_d(h, a), ggx_g1(v, a)] {
                        assert!(q.is_finite() && q >= 0.0, "α {alpha} v {v}: {q}");
                    }
                }
            }
        }
        // D is normalized over projected area: ∫ D(h) h.z dω = 1 (midpoint rule in (cos θ, φ)).
        for alpha in [Vec2::splat(0.3), Vec2::new(0.2, 0.6), Vec2::ONE] {
            let (n_theta, n_phi) = (2000, 64);
            let mut sum = 0.0f64;
            for i in 0..n_theta {
                let z = (i as f32 + 0.5) / n_theta as f32;
                for j in 0..n_phi {
                    let phi = TAU * (j as f32 + 0.5) / n_phi as f32;
                    let h = spherical_direction(safe_sqrt(1.0 - z * z), z, phi);
                    sum += (ggx_d(h, alpha) * z) as f64;
                }
            }
            let integral = sum * (TAU as f64) / (n_theta * n_phi) as f64;
            assert!((integral - 1.0).abs() < 2.0e-3, "α {alpha}: ∫D cos = {integral}");
        }
    }

    /// Views a hair off the normal sample the normal's slopes, up to a rotation about it. At
    /// v = (4·10⁻¹⁹, 0, 1) and α = 10⁻⁴ the stretched view's |vh.xy| is 4·10⁻²³, whose square is
    /// subnormal: the tangent had been divided by the root of that square, |T1| = 1.07, and the
    /// median of tan θh/α had been 1.0735 instead of 1 (the median of the slope distribution at
    /// normal incidence, whose CDF is t²/(1 + t²)).
    #[test]
    fn ggx_vndf_samples_views_a_hair_off_the_normal_like_the_normal() {
        let alpha = Vec2::splat(GGX_MIN_ALPHA);
        let slope = |h: Vec3| Vec2::new(h.x, h.y).length() / h.z / GGX_MIN_ALPHA;
        // Stratified in u.x, which alone sets the slope at normal incidence (t = √(u.x/(1 − u.x))).
        let grid: Vec<Vec2> =
            (0..4096).map(|i| Vec2::new((i as f32 + 0.5) / 4096.0, (i as f32 * 0.618_034).fract())).collect();
        let views = [
            Vec3::new(4.0e-19, 0.0, 1.0),
            Vec3::new(0.0, -1.0e-19, 1.0),
            Vec3::new(3.0e-20, 2.0e-20, 1.0),
            Vec3::new(2.0e-15, 1.0e-16, 1.0),
            Vec3::new(1.0e-36, 0.0, 1.0),
        ];
        for v in views {
            let mut slopes = Vec::new();
            for &u in &grid {
                let (tilted, normal) = (slope(sample_ggx_vndf(v, alpha, u)), slope(sample_ggx_vndf(Vec3::Z, alpha, u)));
                assert!((tilted - normal).abs() <= 1.0e-5 * normal.max(1.0), "v {v}, u {u}: {tilted} vs {normal}");
                slopes.push(tilted);
            }
            slopes.sort_by(f32::total_cmp);
            let median = slopes[slopes.len() / 2];
            assert!((median - 1.0).abs() < 1.0e-3, "v {v}: median tan θh/α {median}");
        }
    }

    #[test]
    fn safe_helpers_clamp() {
        assert_eq!(safe_sqrt(-1.0e-9), 0.0);
        assert_eq!(safe_sqrt(f32::NAN), 0.0);
        assert_eq!(safe_acos(1.0 + 1.0e-6), 0.0);
        assert!((safe_asin(-2.0) + FRAC_PI_2).abs() < 1.0e-7);
        assert_eq!(clamp_sample(Vec2::new(1.0, f32::NAN)), Vec2::new(ONE_MINUS_EPSILON, 0.0));
    }

    /// The form factor `∫ max(0, n·ω)/π dω` of the quad light `o + s·eu + t·ev` at `p` estimated
    /// from `side²` stratified samples of [`sample_quad_spherical`] (the grid's midpoints), each
    /// handed to `check` first.
    fn sampled_form_factor(
        p: Vec3,
        o: Vec3,
        eu: Vec3,
        ev: Vec3,
        n: Vec3,
        side: u32,
        check: impl Fn(&LightSample),
    ) -> f64 {
        let mut sum = 0.0f64;
        for i in 0..side * side {
            let cell = Vec2::new((i % side) as f32, (i / side) as f32);
            let s = sample_quad_spherical(p, o, eu, ev, (cell + 0.5) / side as f32);
            check(&s);
            sum += f64::from(n.dot(s.direction).max(0.0) / s.pdf);
        }
        sum / f64::from(side * side) / core::f64::consts::PI
    }

    /// A parallelogram within [`QUAD_RECTANGLE_MAX_COS`] of a rectangle is sampled as a
    /// rectangle, its samples sheared onto it and their density with them ([`SphericalQuad`]):
    /// seen from points 4·10⁻⁵ of the light's size above and below its plane and 1.2·10⁻³ of it
    /// beside its corners and edges, and 10⁻⁶ above and 10⁻⁷ beside it — closer than the shear
    /// moves its points — the form factor estimated from 2¹⁸ stratified samples matches the `f64`
    /// edge sum within 2.5·10⁻⁴, and every sample's pdf is what `quad_spherical_pdf` gives its
    /// direction. Measured: the rectangle within 2.9·10⁻⁵ (the grid's own error, 3·10⁻⁶ at 2²²
    /// samples); the sheared quads too but beside the far `eu` edge, up to 1.1·10⁻⁴, where the
    /// pivoted rectangle's corner `o + c·t_p·eu` rounds to its coordinate's `f32` step (up to
    /// 6·10⁻⁸ for a point 1.2·10⁻³ from the edge): an `f64` model of the sampler converges to
    /// the edge sum, and with that corner rounded to `f32` reproduces the offset within 7·10⁻⁶.
    /// The rectangle's own samples taken as the parallelogram's, as before, were up to 5.9 % high
    /// beside an edge at `cos ψ` = 7·10⁻⁵ (0.58 % at 7·10⁻⁶), with samples off the light; the
    /// shear pivoting on the edge `t = 0` was 65 % low 10⁻⁶ above the light's middle (a sweep).
    #[test]
    fn a_near_rectangle_is_sampled_exactly_beside_its_edges() {
        let (o, eu) = (Vec3::ZERO, Vec3::X);
        let near = -1.2e-3;
        // (x, y, height): beside the light's corners and edges, then above it and beside its
        // sheared edge, closer to its plane than a shear about the edge t = 0 moves its points.
        let points = [
            (near, near, 4.0e-5),
            (near, 0.3, 4.0e-5),
            (0.5, near, 4.0e-5),
            (1.0 - near, 1.0 - near, 4.0e-5),
            (near, 1.0 - near, 4.0e-5),
            (1.0 - near, 0.7, 4.0e-5),
            (0.5, 0.5, 1.0e-6),
            (0.5, 0.9, 1.0e-6),
            (1.0e-5, 0.5, 1.0e-7),
        ];
        // Shears in steps of 2⁻²³, so that the oracle's corner 1 + c is exact in f32 too.
        for shear in [0.0, 2.0f32.powi(-17), -(2.0f32.powi(-14)), 13.0 * 2.0f32.powi(-17)] {
            let ev = Vec3::new(shear, 1.0, 0.0);
            assert!(is_rectangle(eu, ev), "within the threshold: {shear}");
            // Above the light's plane and below it, the normal facing the plane.
            for (p, n) in points
                .into_iter()
                .flat_map(|(x, y, h)| [(Vec3::new(x, y, h), Vec3::NEG_Z), (Vec3::new(x, y, -h), Vec3::Z)])
            {
                assert!(spherical_quad(p, o, eu, ev).spherical);
                let estimate = sampled_form_factor(p, o, eu, ev, n, 512, |s| {
                    let pdf = quad_spherical_pdf(p, o, eu, ev, s.direction);
                    assert!(s.pdf > 0.0 && (pdf / s.pdf - 1.0).abs() < 1.0e-5, "{p} {shear}: {pdf} vs {}", s.pdf);
                    let off_ray = (s.point - p - s.distance * s.direction).length();
                    assert!(off_ray < 1.0e-6, "{p} {shear}: {off_ray} off the ray");
                });
                // Mirrored in z where the normal is −z (exactly), it becomes the oracle's +z.
                let corner = |c: Vec3| (c - p) * Vec3::new(1.0, 1.0, n.z);
                let exact = form_factor_f64([o, o + eu, o + eu + ev, o + ev].map(corner));
                assert!((estimate / exact - 1.0).abs() < 2.5e-4, "{p} {shear}: {estimate} vs {exact}");
            }
        }
    }

    /// A point nearly on the line of a light's edge, close to its plane, sees the edge's corners
    /// nearly opposite: its solid angle matches the `f64` sum of its two spherical triangles
    /// within 10⁻⁴ (relative), where Van Oosterom's terms as written gave 3.14 sr for 0.07 (a
    /// sweep's point 3.4·10⁻⁶ beside a 7-unit edge and 1.2·10⁻⁷ above the light's plane), and
    /// the light's form factor from 2¹⁶ of its samples matches the `f64` edge sum within 10⁻³.
    #[test]
    fn a_point_nearly_on_an_edge_line_keeps_its_solid_angle() {
        let triangle_f64 = |a: DVec3, b: DVec3, c: DVec3| {
            let (a, b, c) = (a.normalize(), b.normalize(), c.normalize());
            2.0 * a.dot(b.cross(c)).abs().atan2(1.0 + a.dot(b) + a.dot(c) + b.dot(c))
        };
        let (eu, ev) = (Vec3::new(0.0, 0.0, -7.432868e-3), Vec3::new(7.0394464, 0.0, 0.0));
        for (beside, height) in [(3.4e-6f32, 1.2e-7f32), (3.4e-5, 1.2e-7), (-3.4e-6, 1.2e-7), (1.0e-5, 1.0e-9)] {
            // p `beside` beyond the edge s = 1 (along −z), 96 % along it, `height` above the plane.
            let o = Vec3::new(-6.758, 0.0, 7.432868e-3 - beside);
            let p = Vec3::new(0.0, height, 0.0);
            let po = (o - p).as_dvec3();
            let (eud, evd) = (eu.as_dvec3(), ev.as_dvec3());
            let exact = triangle_f64(po, po + eud, po + eud + evd) + triangle_f64(po, po + eud + evd, po + evd);
            let omega = quad_solid_angle(p, o, eu, ev);
            assert!((f64::from(omega) / exact - 1.0).abs() < 1.0e-4, "{beside} {height}: {omega} vs {exact}");
            let estimate = sampled_form_factor(p, o, eu, ev, Vec3::NEG_Y, 256, |_| {});
            let flip = |c: Vec3| {
                let d = c - p;
                Vec3::new(d.x, d.z, -d.y)
            };
            let form_factor = form_factor_f64([o, o + eu, o + eu + ev, o + ev].map(flip));
            assert!((estimate / form_factor - 1.0).abs() < 1.0e-3, "{beside} {height}: {estimate} vs {form_factor}");
        }
    }
}
