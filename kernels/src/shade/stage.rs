//! The shade stage (seed 000, Heitz, Hill & McGuire 2018): per camera sample, the analytic
//! unshadowed radiance `U` of every quad light, and one stochastic sample shared by the unshadowed
//! estimate `U_N` and the shadowed estimate `S_N` — the same direction and weight, visibility only
//! in `S_N` — so that `U · S_N / U_N` keeps the analytic lighting and takes only the shadow from
//! the noisy estimate.
//!
//! **Which BRDF the stochastic estimates evaluate**: the lobes whose integral `U` is. By default
//! that is the LTC approximation (`E_D·cos/π + E_S·D_LTC`, zero below the surface's horizon), not
//! the exact GGX. With [`ShadeParams::analytic_residual`] `U_S` takes the residual towards the GGX
//! lobe — it becomes the GGX lobe's own integral over the light ([`super::slope_quadrature`]) —
//! and the estimates evaluate that lobe too (`E_S·G/magnitude`, still sampled from the LTC:
//! only the weights change), so `U_N` is unbiased for the GGX lobe's exact integral, which `U`
//! computes to within the quadrature's tolerance (at most 1.07 % of `U_S` measured,
//! `tests/analytic_lighting.rs`, and 0.096 % for a light edge exactly in the plane of incidence:
//! [`super::slope_quadrature`]; `U_S` is capped at 1, the whole lobe, so where that error would
//! take it above — a light holding nearly all the lobe, within 0.05 % — `U` is that much below
//! the mean of `U_N`), and the fully stochastic `S_N` converges to the GGX shading
//! the ratio estimate converges to. One exception: the LTC's support is a half-space of its own
//! (the image of the cosine's hemisphere under its `M`), so a sliver of the GGX lobe by the
//! horizon lies outside it — at most 0.25 % of the lobe over the table's cells and the midpoints
//! between them (roughness 0.40–0.47, views 34–43°; a 300 × 600 grid of the hemisphere) — which
//! only light samples reach. Where `P_BRDF` is exactly 1 (`U_S` capped at 1 under a light
//! holding the whole lobe, on a metal, which has no diffuse lobe, or under a light filling the
//! hemisphere) no light sample is drawn, and `U_N` and `S_N`
//! both miss that sliver, up to 0.25 % low; the ratio, whose two estimates miss the same
//! directions, only by the sliver's share of the shadow. Capping `P_BRDF` below 1 would reach it
//! at a variance growing as `1/(1 − cap)`; not adopted. Either way `S_N = U_N` sample
//! by sample without an occluder, so `U · S_N / U_N = U` exactly: the ratio adds no noise where
//! nothing casts a shadow.
//!
//! **Sampling** (seed 000's MIS): with the chosen light's hit probabilities `U_D`, `U_S` (form
//! factors of the diffuse and specular lobes over the light) and the albedos `E_D`, `E_S`:
//! `P_Diff = E_D/(E_D + E_S)` (luminances), `P_BRDF = lerp(U_S, U_D, P_Diff)`; with probability
//! `P_BRDF` sample the BRDF (its diffuse lobe with probability `P_Diff`, else the LTC lobe), else
//! the light (spherical rectangle). One-sample MIS pdf
//! `lerp(pdf_light, lerp(pdf_spec, pdf_diff, P_Diff), P_BRDF)`. The light itself is chosen by
//! [`crate::sampling::light_select::LightSet`] (importance, or a light BVH for many lights,
//! mixed with a uniform choice).
//! A BRDF sample that misses the light contributes 0 to both estimates (at 1 spp the ratio then
//! falls back to `U`). Measured and not adopted: redrawing such a sample up to 8 times — `P_BRDF`
//! is exactly its hit probability, so the retried density stays analytic — lowered the Cornell
//! box's stochastic RMSE at 1 spp by 15 % (64², `raywave report shade`) and left the ratio's
//! unchanged (0.0068): the fallback pixels are too few to matter, and it departs from seed 000's MIS.
//! Measured and not adopted either: choosing the light in proportion to its share of `U` (the
//! luminance of its analytic contribution, which the loop below computes anyway), drawn after
//! that loop by the inverse CDF so that ZSobol's strata survive, with each light's weight and
//! form factors kept in arrays. It never draws a light that lights nothing at the point (the
//! own-mesh case the bound misses), and it left the Cornell box's images byte-identical (one
//! light), but the ratio estimate gained little at 1 spp and lost from 2 spp on: on the
//! two-light box (64², reference 4096 spp, 4 repetitions, CPU) its RMSE went 0.01772 → 0.01730
//! at 1 spp, 0.01030 → 0.01045 at 2, 0.00574 → 0.00610 (± 0.00007) at 4, 0.00359 → 0.00372 at 8
//! and 0.00248 → 0.00259 at 16, the stochastic estimate's 1–2 % lower at 1–2 spp. On the light
//! grid (its 20 lights chosen so instead of by the BVH, up to 16 spp) the ratio's was unchanged
//! up to 8 spp (0.00560 → 0.00561 at 1) and 13 % lower at 16, the stochastic estimate's 10–16 %
//! lower at 1–2 spp and 15 % higher at 8–16. It grew the shade module from 372.3 to 381.9 KB
//! (the first render's compile the same). The ratio's error is its visibility's, which no choice
//! by the unshadowed `U` sees.
//!
//! **Far from the origin** the resolution is the coordinates' `f32` rounding: a shadow ray starts
//! 64·ε·extent off its surface and stops as far before the light's plane ([`crate::offset`]), 7.6
//! units each at 10⁶, so a point within about 15 units of a light's plane there draws no sample
//! from it (`U_N` = 0: the ratio falls back to `U`, unshadowed), and one within about 1 unit of the
//! plane (the facing test's tolerance) gets no `U` from it. The offset start moves the whole shadow
//! ray: `S_N` converges to the light seen from the offset point, not from the surface, which is
//! far apart where a thin part of a light shows past an edge. On the Cornell box, floor points in
//! a block's deep penumbra (3–17 % of the light visible) came out 6–8 % too bright 10² units from
//! the origin (an offset of 0.8 mm), 53–110 % at 10³ and up to 24 times at 10⁴, the other
//! penumbrae 1–3 % at 10³ — each within three standard errors of the integral seen from the offset
//! point (raywave-host's `tests/shadowed_estimate.rs`, which holds the box as built to the
//! integral seen from the surface). A scene shaded there should be built near the origin and
//! placed by the camera.

// `!(x > 0.0)` sends NaN down the "no contribution" branch on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::ggx::GgxLobe;
use super::ltc::{self, LtcLobe, ShadingFrame};
use crate::offset::{offset_ray_origin, ray_stop_before, triangle_extent};
use crate::sampling::light_select::{luminance, quad_faces, LightSet};
use crate::sampling::{dims, sampler, warp};
use crate::sanitized::Sanitized;
use glam::{UVec2, Vec2, Vec3, Vec4, Vec4Swizzles};
use raywave_shared::stream::NO_HIT;
use raywave_shared::{Light, MaterialParams, ShadeParams};

/// A surface seen by a camera ray, as the shade stage reads it (the G-buffer).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Surface {
    /// Hit point (xyz, scene units) and hit distance along the camera ray (w); w = 0 for a miss.
    pub position: Vec4,
    /// Unit geometric normal facing the camera (xyz); w = 0.
    pub normal: Vec4,
    /// The hit triangle's largest absolute vertex coordinate (scene units), which the shadow
    /// ray's origin offset scales with ([`crate::offset::triangle_extent`]); 0 for a miss.
    pub extent: f32,
    /// Instance (mesh) index of the hit, [`NO_HIT`] for a miss; selects the material.
    pub instance: u32,
    /// The camera ray met the triangle's front face, the side its counter-clockwise winding
    /// faces, which a one-sided emitter emits from (`MaterialParams::two_sided_emission`).
    pub front_face: bool,
    /// The hit record was not finite and is read as a miss: the shade stage flags the sample as
    /// replaced ([`crate::sanitized`]).
    pub replaced: bool,
}

impl Surface {
    /// A camera ray that hit nothing.
    pub const MISS: Surface = Surface {
        position: Vec4::ZERO,
        normal: Vec4::ZERO,
        extent: 0.0,
        instance: NO_HIT,
        front_face: false,
        replaced: false,
    };
}

/// Turns a hit into a surface: the point interpolated from the triangle's vertices (the most
/// accurate hit point, which the shadow-ray offset expects) and the unit geometric normal facing
/// the incoming `direction`. `triangles` holds three `Vec4` vertices per triangle in (instance,
/// primitive) order, instance `m` starting at triangle `first_triangle[m]`. Malformed indices (an
/// instance or primitive that is [`NO_HIT`] or beyond that instance's triangles) or a degenerate
/// triangle give [`Surface::MISS`], and so does a `direction` the trace stage would not trace
/// (shorter than [`crate::trace::MIN_DIRECTION`]); a hit distance, barycentrics or `direction`
/// that are not finite give a miss flagged as [`Surface::replaced`] (a NaN direction had read as
/// a front face seen head-on: a wrong, finite, unflagged sample).
pub fn resolve_surface(
    direction: Vec3,
    hit_t: f32,
    instance: u32,
    primitive: u32,
    barycentrics: glam::Vec2,
    triangles: &[Vec4],
    first_triangle: &[u32],
) -> Surface {
    if !(hit_t.is_finite() && barycentrics.is_finite() && direction.is_finite()) {
        return Surface { replaced: true, ..Surface::MISS };
    }
    let untraceable = direction.abs().max_element() < crate::trace::MIN_DIRECTION;
    if untraceable || instance == NO_HIT || instance as usize >= first_triangle.len() {
        return Surface::MISS;
    }
    // The instance's triangles run from its first to the next instance's (or the last).
    let triangle_count = (triangles.len() / 3) as u32;
    let first = first_triangle[instance as usize];
    let end = if (instance as usize) + 1 < first_triangle.len() {
        first_triangle[instance as usize + 1].min(triangle_count)
    } else {
        triangle_count
    };
    // Compared, not added first: `first + primitive` wraps for `primitive = NO_HIT`.
    if first >= end || primitive >= end - first {
        return Surface::MISS;
    }
    let base = (first + primitive) as usize * 3;
    let (a, b, c) = (triangles[base].xyz(), triangles[base + 1].xyz(), triangles[base + 2].xyz());
    let position = a * (1.0 - barycentrics.x - barycentrics.y) + b * barycentrics.x + c * barycentrics.y;
    let normal = crate::triangle::geometric_normal(a, b, c);
    if normal == Vec3::ZERO || !position.is_finite() {
        return Surface::MISS;
    }
    let front_face = !(normal.dot(direction) > 0.0);
    let normal = if front_face { normal } else { -normal };
    Surface {
        position: position.extend(hit_t),
        normal: normal.extend(0.0),
        extent: triangle_extent(a, b, c),
        instance,
        front_face,
        replaced: false,
    }
}

/// The scene data the shade stage reads.
#[derive(Copy, Clone)]
pub struct ShadeScene<'a> {
    /// Material per instance.
    pub materials: &'a [MaterialParams],
    /// The quad lights and how to choose among them.
    pub lights: LightSet<'a>,
    /// The packed LTC table ([`ltc::LTC_TABLE_LEN`] entries).
    pub ltc: &'a [Vec4],
}

/// What one shade invocation produces for its pixel.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ShadeSample {
    /// Analytic unshadowed radiance `U` (rgb; w = 0).
    pub analytic: Vec4,
    /// This sample's contribution to `U_N` (rgb; w = 0); its contribution to `S_N` is the same
    /// times the shadow ray's visibility.
    pub unshadowed: Vec4,
    /// Radiance emitted by the surface itself towards the camera (rgb; w = 0).
    pub emitted: Vec4,
    /// Shadow-ray origin (xyz), w = tmin = 0.
    pub shadow_origin: Vec4,
    /// Shadow-ray direction (xyz), w = tmax; tmax = 0 when there is nothing to trace.
    pub shadow_direction: Vec4,
}

impl ShadeSample {
    /// The sample of a pixel whose camera ray missed: all zero, no shadow ray.
    pub const NONE: ShadeSample = ShadeSample {
        analytic: Vec4::ZERO,
        unshadowed: Vec4::ZERO,
        emitted: Vec4::ZERO,
        shadow_origin: Vec4::ZERO,
        shadow_direction: Vec4::new(0.0, 0.0, 1.0, 0.0),
    };
}

/// A material at one shading point: the lobes' albedos and the LTC lobe.
#[derive(Copy, Clone, Debug)]
struct Lobes {
    /// Diffuse albedo `E_D = base·(1 − metallic)` (Lambert): glTF 2.0's diffuse lobe without
    /// its per-direction `1 − F(v·h)` weight, which no constant albedo — what the form factor
    /// `U_D` takes — can carry (4.0–6.1 % of the diffuse for views up to 85°). Like glTF's own
    /// model it does not conserve energy at grazing views: a white dielectric of roughness 0
    /// reflects `E_D + E_S` = 1.04 at normal view, 1.29 at 76°, 1.99 at 90°.
    diffuse: Vec3,
    /// Specular albedo `E_S` from the table's magnitude and Fresnel terms.
    specular: Vec3,
    /// The LTC lobe (a two-LTC mixture, each `M⁻¹` in `frame`).
    ltc: LtcLobe,
    /// The GGX lobe the LTC stands for, when `U_S` takes the residual towards it
    /// ([`ShadeParams::analytic_residual`]).
    ggx: Option<GgxLobe>,
    frame: ShadingFrame,
}

impl Lobes {
    fn new(material: &MaterialParams, frame: ShadingFrame, cos_view: f32, table: &[Vec4], residual: bool) -> Self {
        let base = material.base_color_roughness.xyz();
        let roughness = material.base_color_roughness.w;
        let metallic = material.emission_metallic.w;
        // glTF 2.0's dielectric F0 = 0.04 (the metallic-roughness model).
        let f0 = Vec3::splat(0.04) * (1.0 - metallic) + base * metallic;
        let ltc = ltc::lookup(table, roughness, cos_view);
        let ggx = if residual { Some(GgxLobe::new(roughness, cos_view)) } else { None };
        Lobes { diffuse: base * (1.0 - metallic), specular: ltc.specular_albedo(f0), ltc, ggx, frame }
    }

    /// At world direction `w`: the BRDF·cos the estimates evaluate, `E_D·cos/π + E_S·D_LTC` — or
    /// `E_S·G/magnitude` for the specular lobe with the residual towards GGX — (zero below the
    /// horizon, see the module documentation), and the two lobes' sampling densities (diffuse,
    /// the LTC's) — one evaluation of the LTC mixture serves both.
    fn eval_and_pdfs(&self, w: Vec3) -> (Vec3, f32, f32) {
        let local = self.frame.to_local(w);
        let (pdf_diffuse, pdf_specular) = (warp::cosine_hemisphere_pdf(local), self.ltc.pdf(local));
        let specular = match &self.ggx {
            // The lobe whose integral the corrected `U_S` is, normalized as that is.
            Some(ggx) if self.ltc.magnitude > 0.0 => ggx.eval(local) / self.ltc.magnitude,
            Some(_) => 0.0,
            None => pdf_specular,
        };
        let f = if local.z > 0.0 { self.diffuse * pdf_diffuse + self.specular * specular } else { Vec3::ZERO };
        (f, pdf_diffuse, pdf_specular)
    }

    fn world_direction(&self, local: Vec3) -> Vec3 {
        self.frame.tangent * local.x + self.frame.bitangent * local.y + self.frame.normal * local.z
    }
}

/// Hit probabilities `(U_D, U_S)` of `light` at `p`, a point of scene mesh `instance`, for
/// `lobes`; zero if `p` sees its back or lies in its plane ([`quad_faces`], the test light
/// selection shares), or on the light itself: points of the mesh a light is made of are excluded
/// by identity too ([`Light::mesh`]; an emitter mesh may bend off the light's plane by the fit's
/// 10⁻⁴), the plane test covers lights made of no mesh and other geometry in their plane.
fn hit_probabilities(light: &Light, p: Vec3, instance: u32, lobes: &Lobes) -> (f32, f32) {
    if light.mesh == instance || !quad_faces(light, p) {
        return (0.0, 0.0);
    }
    let (corner, edge_u, edge_v) = (light.position.xyz(), light.edge_u.xyz(), light.edge_v.xyz());
    ltc::parallelogram_form_factors(&lobes.ltc, lobes.ggx, &lobes.frame, p, corner, edge_u, edge_v)
}

/// `a` at `t = 0` to `b` at `t = 1`, written `a·(1 − t) + b·t` so that both ends are exact: as
/// `a + (b − a)·t` a tiny `b` beside a large `a` rounded to 0 at `t = 1` (a pdf of 3·10⁻⁹ beside
/// 0.16 dropped its sample).
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a * (1.0 - t) + b * t
}

/// The shade stage for one camera sample at `pixel` looking along `view_direction` (from the
/// camera, of any length: the direction [`resolve_surface`] resolved `surface` with) at
/// `surface`: `U` summed over all lights, and one MIS sample of the chosen light
/// shared by `U_N` and `S_N`. Flagged as replaced when a non-finite value was — the surface's
/// hit record (a miss), `U` (zero) or the sample's weight (no sample).
pub fn shade_sample(
    params: &ShadeParams,
    pixel: UVec2,
    view_direction: Vec3,
    surface: &Surface,
    scene: &ShadeScene<'_>,
) -> Sanitized<ShadeSample> {
    if surface.instance == NO_HIT || surface.instance as usize >= scene.materials.len() {
        return Sanitized { value: ShadeSample::NONE, replaced: surface.replaced };
    }
    let material = &scene.materials[surface.instance as usize];
    let p = surface.position.xyz();
    let n = surface.normal.xyz();
    // Normalised here: the trace stage takes directions of any length. Scaled to a largest
    // component of 1 first: a traceable direction 10²⁵ long, whose square overflows, had
    // normalised to 0 (a finite, wrong, unflagged sample), and one 10⁻²⁰ long has a subnormal one.
    let v = -(view_direction / view_direction.abs().max_element()).normalize_or_zero();
    let frame = ShadingFrame::new(n, v);
    let lobes = Lobes::new(material, frame, n.dot(v), scene.ltc, params.analytic_residual != 0);
    // A one-sided emitter's back is black, as the light made of it casts nothing there.
    let emits = surface.front_face || material.two_sided_emission != 0;
    let emitted = if emits { material.emission_metallic.xyz().extend(0.0) } else { Vec4::ZERO };

    // One light for the stochastic sample of U_N and S_N.
    // The three slots by one call in a loop, so that the kernel holds the sampler's code once.
    let slots = [dims::SHADE_STRATEGY, dims::SHADE_LIGHT_SELECT, dims::SHADE_DIRECTION];
    let mut drawn = [Vec2::ZERO; 3];
    let mut slot = 0;
    while slot < slots.len() {
        drawn[slot] = sampler::sample_2d(&params.sampler, pixel, params.sample_index, slots[slot]);
        slot += 1;
    }
    let (strategy, u_select, u) = (drawn[0], drawn[1], drawn[2]);
    let choice = scene.lights.select(p, n, u_select);

    // U: every light, analytically, keeping the chosen light's hit probabilities for the MIS.
    let mut analytic = Vec3::ZERO;
    let (mut u_d, mut u_s) = (0.0f32, 0.0f32);
    let light_count = scene.lights.len();
    let mut k = 0u32;
    while k < light_count {
        let light = &scene.lights.lights[k as usize];
        let (d, s) = hit_probabilities(light, p, surface.instance, &lobes);
        analytic += light.radiance.xyz() * (lobes.diffuse * d + lobes.specular * s);
        if k == choice.index {
            (u_d, u_s) = (d, s);
        }
        k += 1;
    }

    // Lights are finite, but the sum of many bright ones may not be: no `U` at all then.
    let analytic_finite = analytic.is_finite();
    let analytic = if analytic_finite { analytic.extend(0.0) } else { Vec4::ZERO };
    let mut result =
        Sanitized { value: ShadeSample { analytic, emitted, ..ShadeSample::NONE }, replaced: !analytic_finite };
    if !analytic_finite || !choice.is_valid() || (u_d <= 0.0 && u_s <= 0.0) {
        return result;
    }
    let light = &scene.lights.lights[choice.index as usize];
    let (corner, eu, ev) = (light.position.xyz(), light.edge_u.xyz(), light.edge_v.xyz());
    let (e_d, e_s) = (luminance(lobes.diffuse), luminance(lobes.specular));
    let p_diff = if e_d + e_s > 0.0 { e_d / (e_d + e_s) } else { 1.0 };
    let p_brdf = lerp(u_s, u_d, p_diff);

    // The light as its sampler sees it (its solid angle, `warp::SphericalQuad`) serves its sample
    // and its pdf: computed once for either strategy, even for a BRDF direction that misses the
    // light and does not need it, so that the kernel holds it once and a GPU's lanes run it
    // together.
    let light_sampled = !(strategy.x < p_brdf);
    let quad = warp::spherical_quad(p, corner, eu, ev);
    let (direction, sampled_distance) = if light_sampled {
        let sample = warp::sample_quad_spherical_with(p, corner, eu, ev, &quad, u);
        // pdf 0 is "no sample": its direction (+z) is a placeholder, not a direction to the light.
        if !(sample.pdf > 0.0) {
            return result;
        }
        (sample.direction, sample.distance)
    } else {
        let local = if strategy.y < p_diff { warp::sample_cosine_hemisphere(u) } else { lobes.ltc.sample(u) };
        (lobes.world_direction(local).normalize_or_zero(), 0.0)
    };
    // A BRDF direction counts only where it meets the light itself: the edge slack that keeps the
    // light's own samples on it would widen the light for a lobe as narrow as a near-mirror's.
    let slack = if light_sampled { warp::QUAD_EDGE_SLACK } else { 0.0 };
    let hit = warp::quad_ray_distance_with_slack(p, corner, eu, ev, direction, slack);
    // A light sample lies on the light even where the ray test misses it: the test rounds the
    // height over the light's plane apart from the sampler, by ~ε of the distance to its far
    // corner, and from just beside a light seen edge-on met the plane past the slack (`U_N` was
    // 1.6 % low, test). Its own distance then (the ray test's elsewhere, as the stop expects).
    let distance = if hit > 0.0 { hit } else { sampled_distance };
    let (f, pdf_diffuse, pdf_specular) = lobes.eval_and_pdfs(direction);
    if !(distance > 0.0) || f == Vec3::ZERO {
        return result;
    }
    let pdf_brdf = lerp(pdf_specular, pdf_diffuse, p_diff);
    let pdf_light = warp::quad_spherical_pdf_at_hit(eu, ev, &quad, direction, distance);
    let pdf = lerp(pdf_light, pdf_brdf, p_brdf) * choice.pmf;
    if !(pdf > 0.0) {
        return result;
    }
    let weight = f * light.radiance.xyz() / pdf;
    let origin = offset_ray_origin(p, n, surface.extent);
    // Stop short of the light — its own emitter geometry may be in the scene — by a margin that
    // holds at grazing angles and far from the origin. A point within that margin of the light's
    // plane (which sees the light edge-on) has no such stop and draws no sample.
    let light_normal = crate::triangle::unit_normal(eu.cross(ev));
    // The extent of the light's two triangles: its four corners' largest coordinate.
    let light_extent = triangle_extent(corner, corner + eu, corner + ev).max((corner + eu + ev).abs().max_element());
    let t_max = ray_stop_before(origin, direction, p + distance * direction, light_normal, light_extent);
    if !weight.is_finite() {
        result.replaced = true;
        return result;
    }
    if !(t_max > 0.0) {
        return result;
    }
    result.value.unshadowed = weight.extend(0.0);
    result.value.shadow_origin = origin.extend(0.0);
    result.value.shadow_direction = direction.extend(t_max);
    result
}

/// Radiances (and their luminances) below this count as 0: the smallest normal `f32` (2⁻¹²⁶),
/// since a device may flush smaller ones to 0. Not an absolute threshold like the reference
/// code's (`U < 10⁻⁴` in display units), which would make the result depend on the lights' units:
/// a light of radiance 10⁻⁵ (a lamp in a scene exposed for the sun) would lose its shadows.
pub const SMALLEST_RADIANCE: f32 = f32::MIN_POSITIVE;

/// The shadow ratio `S_N / U_N` per channel, in `[0, 1]` for a pixel's means, raw or filtered
/// with the same weights (`S_N ≤ U_N` sample by sample): 1 — "unshadowed" — where `U_N` is 0
/// (below [`SMALLEST_RADIANCE`]), i.e. no sample reached the light and the ratio is undefined, so
/// the composite falls back to `U` [H-DX, H-CPU]. Clamped to `[0, 10⁴]` for other inputs: the
/// stochastic+tv baseline divides `S_N` by one constant per channel (its mean over the image,
/// `raywave::denoise::DenoiseInput::stochastic`), where a bright pixel's ratio exceeds 1. A NaN
/// `S_N` (which raywave's own inputs never hold) is undefined too: 1; an `S_N` below
/// [`SMALLEST_RADIANCE`] counts as 0, as `U_N` does, since a device may flush it to 0.
pub fn shadow_ratio(shadowed: Vec3, unshadowed: Vec3) -> Vec3 {
    // `s == u_n` (no occluder: the same sample in both) is 1 exactly, not `s / u_n`: Vulkan bounds
    // `OpFDiv` only to 2.5 ulp, so a device may round `x / x` off 1 and `U · S_N / U_N` off `U`.
    let ratio = |s: f32, u_n: f32| {
        if s == u_n || !(u_n >= SMALLEST_RADIANCE) || s.is_nan() {
            1.0
        } else if s < SMALLEST_RADIANCE {
            0.0
        } else {
            (s / u_n).clamp(0.0, 1.0e4)
        }
    };
    Vec3::new(ratio(shadowed.x, unshadowed.x), ratio(shadowed.y, unshadowed.y), ratio(shadowed.z, unshadowed.z))
}

/// A pixel's colour from its analytic unshadowed radiance `U` and its shadow `visibility` (a
/// [`shadow_ratio`], raw or denoised): `emitted + U · visibility`, or `emitted` alone (flagged
/// as replaced) should that not be finite — the denoiser's final pass, its stage boundary.
pub fn apply_visibility(analytic: Vec3, visibility: Vec3, emitted: Vec3) -> Sanitized<Vec3> {
    let color = emitted + analytic * visibility;
    if color.is_finite() {
        Sanitized::clean(color)
    } else {
        Sanitized::replacing(emitted)
    }
}

/// The ratio estimator's composite for one pixel: `U · S_N / U_N` per channel, falling back to
/// `U` where `U_N` is (nearly) 0 (see [`shadow_ratio`]), plus the emitted radiance. All inputs
/// are per-pixel means (or their denoised values).
pub fn composite(analytic: Vec3, unshadowed: Vec3, shadowed: Vec3, emitted: Vec3) -> Sanitized<Vec3> {
    apply_visibility(analytic, shadow_ratio(shadowed, unshadowed), emitted)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::light_select::LightSet;
    use raywave_shared::ltc_table::packed_entries;
    use raywave_shared::sampling::{sampler_kind, SamplerParams};
    use std::format;
    use std::vec::Vec;

    fn table() -> Vec<Vec4> {
        packed_entries().map(Vec4::from_array).collect()
    }

    fn material(base: Vec3, roughness: f32, metallic: f32) -> MaterialParams {
        MaterialParams {
            base_color_roughness: base.extend(roughness),
            emission_metallic: Vec3::ZERO.extend(metallic),
            two_sided_emission: 0,
            padding: [0; 3],
        }
    }

    fn surface_at_origin() -> Surface {
        Surface {
            position: Vec4::new(0.0, 0.0, 0.0, 1.0),
            normal: Vec4::new(0.0, 0.0, 1.0, 0.0),
            // On a triangle about a unit across.
            extent: 1.0,
            instance: 0,
            front_face: true,
            replaced: false,
        }
    }

    /// A downward-facing quad light of half-size `h` centred at `centre`.
    fn ceiling_light(centre: Vec3, h: f32, radiance: Vec3) -> Light {
        // edge_u × edge_v = (2h,0,0) × (0,−2h,0) = −z: emits downwards.
        Light::quad(
            centre + Vec3::new(-h, h, 0.0),
            Vec3::new(2.0 * h, 0.0, 0.0),
            Vec3::new(0.0, -2.0 * h, 0.0),
            radiance,
            false,
        )
    }

    fn params(kind: u32, seed: u32, sample_index: u32) -> ShadeParams {
        ShadeParams {
            sampler: SamplerParams { kind, seed, spp_log2: (SEEDS / REPLICATES).trailing_zeros(), resolution_log2: 0 },
            width: 1,
            count: 1,
            sample_index,
            light_count: 0,
            light_node_count: 0,
            analytic_residual: 0,
            padding: [0; 2],
        }
    }

    /// Samples per statistical test: at least the 10⁵ seeds issue 5 asks for.
    const SEEDS: u32 = 1 << 17;

    /// Independent runs a statistical test's samples are split into, each of `SEEDS / REPLICATES`
    /// samples with its own seed (for the Sobol' sampler its own scramble), so that the scatter of
    /// their means gives the standard error whatever the sampler.
    const REPLICATES: u32 = 64;

    /// Each statistical test runs with both samplers, each with `U_S` from the LTC alone and with
    /// the residual towards GGX (`ShadeParams::analytic_residual`).
    const KINDS_AND_RESIDUAL: [(u32, u32); 4] = [
        (sampler_kind::INDEPENDENT, 0),
        (sampler_kind::SOBOL, 0),
        (sampler_kind::INDEPENDENT, 1),
        (sampler_kind::SOBOL, 1),
    ];

    /// Means of the per-sample estimates of `U_N` and `S_N`, channel by channel, with their
    /// standard errors, and the analytic `U`.
    struct Estimate {
        unshadowed: [MeanAndError; 3],
        shadowed: [MeanAndError; 3],
        analytic: [f64; 3],
    }

    /// The mean of [`REPLICATES`] replicate means and its standard error, estimated from their
    /// scatter. The error of one sample's scatter would not do for the Sobol' sampler: a
    /// replicate's samples form an Owen-scrambled (0, m, 2)-net, whose mean's variance may be far
    /// below that of independent samples for a smooth integrand or up to twice it (A. B. Owen,
    /// "Monte Carlo Variance of Scrambled Net Quadrature", SIAM J. Numer. Anal. 34(5), 1997),
    /// while the replicates, scrambled apart, are independent whatever the sampler.
    #[derive(Copy, Clone, Debug)]
    struct MeanAndError {
        mean: f64,
        error: f64,
    }

    /// Standard errors a mean may stray from what it estimates in the statistical tests below:
    /// 4.3, Student's t with the replicates' 63 degrees of freedom beyond which lies a chance of
    /// 6.0·10⁻⁵ (two-sided), so that this module's 68 comparisons of three channels (204) raise a
    /// false alarm with a chance near 1.2 % (Šidák: 1 − (1 − 6.0·10⁻⁵)²⁰⁴), and a bias of 1.5 %
    /// of a mean 0.3 % uncertain still fails.
    const Z: f64 = 4.3;

    /// Whether every channel of `estimates` is within [`Z`] standard errors of `reference`, plus
    /// 10⁻⁴ relative for the `f32` arithmetic of `U` and of each sample: with the Sobol' sampler
    /// a smooth integrand's mean is known to a few 10⁻⁶ (a thin strip's `U_N` with the residual
    /// lies 2.3·10⁻⁵ below its `U`, nine such errors).
    fn agrees(estimates: [MeanAndError; 3], reference: [f64; 3]) -> bool {
        estimates.iter().zip(reference).all(|(e, r)| (e.mean - r).abs() <= Z * e.error + 1e-4 * r)
    }

    /// Adds `y`'s channels and their squares to `sums` (per channel: the sum, the sum of squares).
    fn accumulate(sums: &mut [[f64; 2]; 3], y: glam::DVec3) {
        for (sum, y) in sums.iter_mut().zip(y.to_array()) {
            sum[0] += y;
            sum[1] += y * y;
        }
    }

    /// Per channel, the mean of the [`REPLICATES`] replicate means whose sums [`accumulate`]
    /// gathered, and its standard error (from their sample variance, `n − 1` in the divisor).
    fn mean_and_error(sums: [[f64; 2]; 3]) -> [MeanAndError; 3] {
        let n = f64::from(REPLICATES);
        sums.map(|[sum, sum2]| {
            let mean = sum / n;
            let variance = ((sum2 - n * mean * mean) / (n - 1.0)).max(0.0);
            MeanAndError { mean, error: (variance / n).sqrt() }
        })
    }

    /// Per channel, the means of `sample(seed, index)`'s `N` estimates over `samples` split into
    /// [`REPLICATES`] replicates seeded `seed`, `seed + 1`, …, with their standard errors from
    /// the replicates' scatter.
    fn replicated<const N: usize>(
        samples: u32,
        seed: u32,
        mut sample: impl FnMut(u32, u32) -> [glam::DVec3; N],
    ) -> [[MeanAndError; 3]; N] {
        let per_replicate = samples / REPLICATES;
        assert!(
            per_replicate > 0 && samples.is_multiple_of(REPLICATES),
            "{samples} samples in {REPLICATES} replicates"
        );
        // Per estimate and channel: the sum and the sum of squares of the replicate means.
        let mut sums = [[[0.0f64; 2]; 3]; N];
        for replicate in 0..REPLICATES {
            let mut totals = [glam::DVec3::ZERO; N];
            for i in 0..per_replicate {
                for (total, y) in totals.iter_mut().zip(sample(seed + replicate, i)) {
                    *total += y;
                }
            }
            for (sums, total) in sums.iter_mut().zip(totals) {
                accumulate(sums, total / f64::from(per_replicate));
            }
        }
        sums.map(mean_and_error)
    }

    /// `f` of the scene of `lights` over a surface of `material`, with the committed LTC table.
    fn with_scene<R>(lights: &[Light], material: MaterialParams, f: impl FnOnce(&ShadeScene<'_>) -> R) -> R {
        let table = table();
        let materials = [material];
        f(&ShadeScene { materials: &materials, lights: LightSet::new(lights, &[], &[]), ltc: &table })
    }

    /// The analytic `U` at the origin (normal +z, viewed from `view`) under `lights`, with
    /// `ShadeParams::analytic_residual` = `analytic_residual`.
    fn analytic_u(lights: &[Light], material: MaterialParams, view: Vec3, analytic_residual: u32) -> [f64; 3] {
        with_scene(lights, material, |scene| {
            let p = ShadeParams { analytic_residual, ..params(sampler_kind::SOBOL, 5, 0) };
            let s = shade_sample(&p, UVec2::ZERO, -view, &surface_at_origin(), scene).value;
            s.analytic.xyz().as_dvec3().to_array()
        })
    }

    /// [`SEEDS`] samples in [`REPLICATES`] replicates at the origin (normal +z, viewed from
    /// `view`) under `lights`, with `ShadeParams::analytic_residual` = `analytic_residual`; a
    /// sample's `S_N` is its `U_N` if `visible(shadow_origin, shadow_direction)` (direction's
    /// w = tmax).
    fn estimate(
        lights: &[Light],
        material: MaterialParams,
        view: Vec3,
        kind: u32,
        analytic_residual: u32,
        visible: impl Fn(Vec4, Vec4) -> bool,
    ) -> Estimate {
        let [unshadowed, shadowed] = with_scene(lights, material, |scene| {
            replicated(SEEDS, 5, |seed, i| {
                let p = ShadeParams { analytic_residual, ..params(kind, seed, i) };
                let s = shade_sample(&p, UVec2::ZERO, -view, &surface_at_origin(), scene).value;
                let unshadowed = s.unshadowed.xyz().as_dvec3();
                let has_ray = s.shadow_direction.w > 0.0;
                let visible = has_ray && visible(s.shadow_origin, s.shadow_direction);
                assert!(s.unshadowed.is_finite() && s.shadow_direction.is_finite() && s.shadow_origin.is_finite());
                // A shadow ray leaves the lit side, offset along the normal (+z), towards the light.
                assert!(!has_ray || (s.shadow_origin.z > 0.0 && s.shadow_direction.z > 0.0), "sample {i}: {s:?}");
                [unshadowed, if visible { unshadowed } else { glam::DVec3::ZERO }]
            })
        });
        Estimate { unshadowed, shadowed, analytic: analytic_u(lights, material, view, analytic_residual) }
    }

    /// Every shadow ray reaches its light: no occluder.
    fn unoccluded(_: Vec4, _: Vec4) -> bool {
        true
    }

    #[test]
    fn unshadowed_estimate_is_unbiased_for_u() {
        // Mean of 2^17 samples (64 replicates) within `Z` standard errors (plus 1e-4 relative: f32
        // arithmetic) of the analytic U, channel by channel (a `U_N` of the right luminance in
        // the wrong colour fails): glossy and diffuse materials, one and two lights, a light
        // crossing the horizon, a grazing view, a rhombus, near-mirror surfaces (roughness 0,
        // 0.02, 0.05) under a light about the mirror direction of a view 84° from the normal;
        // with and without the residual towards GGX, whose U_N evaluates the GGX lobe.
        let view = Vec3::new(0.6, 0.0, 0.8);
        let one = [ceiling_light(Vec3::new(0.3, 0.2, 1.0), 0.4, Vec3::new(5.0, 4.0, 3.0))];
        let two = [one[0], ceiling_light(Vec3::new(-1.5, 0.0, 0.3), 0.5, Vec3::splat(2.0))];
        let crossing = [Light::quad(
            Vec3::new(1.0, -0.5, -0.3),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::ONE,
            true,
        )];
        // A parallelogram that is no rectangle (a 60° rhombus), sampled by area: the
        // spherical-rectangle method sent 38 % of its samples past such a light, and U_N fell to
        // 0.56 U.
        let rhombus = [Light::quad(
            Vec3::new(-0.6, 0.4, 1.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.5, -0.866_025_4, 0.0),
            Vec3::new(3.0, 3.0, 2.0),
            false,
        )];
        // 84° from the normal, and a 0.6 × 0.6 light a unit along its mirror direction (6° above
        // the horizon: the light crosses it), facing the point.
        let (sin_84, cos_84) = crate::trig::sin_cos(84.0f32.to_radians());
        let view_84 = Vec3::new(sin_84, 0.0, cos_84);
        let mirror = Vec3::new(-sin_84, 0.0, cos_84);
        let across = mirror.cross(Vec3::Y);
        let about_mirror = [Light::quad(
            mirror - 0.3 * (Vec3::Y + across),
            0.6 * across,
            0.6 * Vec3::Y,
            Vec3::new(3.0, 2.0, 1.0),
            false,
        )];
        let emitting = about_mirror[0].edge_u.xyz().cross(about_mirror[0].edge_v.xyz());
        assert!(emitting.dot(mirror) < 0.0, "the light faces the point");
        let tinted = Vec3::new(0.9, 0.7, 0.5);
        let cases = [
            (&one[..], material(Vec3::new(0.8, 0.6, 0.4), 0.3, 0.5), view),
            (&one[..], material(Vec3::splat(0.7), 1.0, 0.0), view),
            (&two[..], material(Vec3::new(0.9, 0.9, 0.9), 0.2, 1.0), view),
            (&crossing[..], material(Vec3::splat(0.5), 0.5, 0.0), Vec3::new(-0.99, 0.0, 0.141).normalize()),
            (&rhombus[..], material(Vec3::splat(0.7), 0.6, 0.0), view),
            (&about_mirror[..], material(tinted, 0.0, 1.0), view_84),
            (&about_mirror[..], material(tinted, 0.02, 0.0), view_84),
            (&about_mirror[..], material(tinted, 0.05, 1.0), view_84),
        ];
        assert_unshadowed_estimate_is_unbiased(&cases, &KINDS_AND_RESIDUAL);
    }

    /// [`unshadowed_estimate_is_unbiased_for_u`] for lights 10⁻⁷ as wide as they are far, whose
    /// `U` the corners' edge sum had lost to their rounding (power held: radiance ∝ 1/width),
    /// one of them across the view's mirror direction; with and without the residual (whose
    /// quadrature over the corners had put `U` 0.95 % above `U_N` at roughness 0.3).
    #[test]
    fn unshadowed_estimate_is_unbiased_for_u_of_thin_strips() {
        let view = Vec3::new(0.6, 0.0, 0.8);
        let width = 1.0e-7;
        let strip = [Light::quad(
            Vec3::new(-0.5, 0.5 * width, 1.0),
            Vec3::X,
            Vec3::new(0.0, -width, 0.0),
            Vec3::new(3.0, 2.0, 1.0) * (0.1 / width),
            false,
        )];
        let mirror_strip = [Light::quad(
            Vec3::new(-0.75 - 0.5 * width, -0.5, 1.0),
            Vec3::Y,
            Vec3::new(width, 0.0, 0.0),
            Vec3::new(1.0, 2.0, 3.0) * (0.1 / width),
            false,
        )];
        let tinted = Vec3::new(0.9, 0.7, 0.5);
        let cases = [
            (&strip[..], material(tinted, 1.0, 0.0), view),
            (&strip[..], material(tinted, 0.3, 0.5), view),
            (&mirror_strip[..], material(tinted, 0.1, 1.0), view),
        ];
        assert_unshadowed_estimate_is_unbiased(&cases, &KINDS_AND_RESIDUAL);
    }

    /// A near-mirror lobe seen at 85° under a light one of whose edges lies in the plane of
    /// incidence through the mirror direction, so that the light holds half the lobe, whose width
    /// across that edge is ~10⁻⁵ rad. BRDF samples that met the light within the quad sampler's
    /// edge slack (`warp::QUAD_EDGE_SLACK`, ~2·10⁻⁶ of the distance) counted as hits: `U_N` was
    /// 10.5 % above `U` at roughness 0 and 5 % at 0.01 (about 20 and 10 standard errors of 2^17
    /// samples; 1 % at a head-on view). Without the residual: its `U_N` is light-tailed there
    /// (the largest sample ~4·10⁻⁶ of the sum), the residual's is not (the LTC does not sample
    /// the GGX lobe at 85°).
    #[test]
    fn unshadowed_estimate_is_unbiased_for_u_of_a_near_mirror_lobe_cut_by_an_edge() {
        let (sin_85, cos_85) = crate::trig::sin_cos(85.0f32.to_radians());
        let view_85 = Vec3::new(sin_85, 0.0, cos_85);
        let mirror = Vec3::new(-sin_85, 0.0, cos_85);
        let across = mirror.cross(Vec3::Y);
        // 0.6 × 0.6, a unit along the mirror direction, spanning y ∈ [0, 0.6]: its edge y = 0
        // runs through the mirror direction in the plane of incidence.
        let light = Light::quad(mirror - 0.3 * across, 0.6 * across, 0.6 * Vec3::Y, Vec3::new(3.0, 2.0, 1.0), false);
        let emitting = light.edge_u.xyz().cross(light.edge_v.xyz());
        assert!(emitting.dot(mirror) < 0.0, "the light faces the point");
        let edge = [light];
        let tinted = Vec3::new(0.9, 0.7, 0.5);
        let cases = [
            (&edge[..], material(tinted, 0.0, 1.0), view_85),
            (&edge[..], material(tinted, 0.01, 1.0), view_85),
            (&edge[..], material(tinted, 0.0, 0.0), view_85),
        ];
        let without_residual = [(sampler_kind::INDEPENDENT, 0), (sampler_kind::SOBOL, 0)];
        assert_unshadowed_estimate_is_unbiased(&cases, &without_residual);
    }

    /// A point 2.1·10⁻⁶ units (1.6·10⁻⁶ of the light's size) above a tilted light's plane and
    /// 2.7·10⁻³ units beyond its edge, just outside the stop margin, sees the light edge-on: the
    /// spherical-rectangle sampler and a ray test of its direction each round the point's height
    /// over the plane by ~ε of the distance to the light's far corner, so 1.2 % of the light's
    /// own samples met the plane past the edge slack (which scales with the hit's distance) and
    /// were dropped: `U_N` was 1.7 % below `U` here (10 standard errors over these 2^18 samples;
    /// 1.6 %, 27 standard errors, over 2^21 fresh ones in the helper's sweep of random
    /// configurations that found it). Mean of 2^18 samples within `Z` standard errors (plus 10⁻⁴
    /// relative) of `U`, channel by channel.
    #[test]
    fn unshadowed_estimate_keeps_light_samples_of_a_light_seen_edge_on_from_beside_it() {
        let light = Light::quad(
            Vec3::new(0.10493055, -0.44312453, -0.7347761),
            Vec3::new(-0.9215332, 0.6873765, 0.59066933),
            Vec3::new(0.7116721, 0.1988726, 0.8788828),
            Vec3::new(1.0977786, 2.184556, 0.7711575),
            false,
        );
        let lights = [light];
        let (p, n) = (Vec3::new(-0.7783525, 0.2569375, -0.09322104), Vec3::new(0.83526844, 0.5486612, 0.036021132));
        let view = Vec3::new(0.77675015, 0.6295081, -0.019464422);
        let surface = Surface { position: p.extend(1.0), normal: n.extend(0.0), ..surface_at_origin() };
        let table = table();
        let materials = [material(Vec3::new(0.9460666, 0.62173045, 0.6543907), 0.0, 0.0)];
        let scene = ShadeScene { materials: &materials, lights: LightSet::new(&lights, &[], &[]), ltc: &table };
        let mut analytic = [0.0f64; 3];
        let [estimates] = replicated(1 << 18, 1, |seed, i| {
            let s =
                shade_sample(&params(sampler_kind::INDEPENDENT, seed, i), UVec2::ZERO, -view, &surface, &scene).value;
            analytic = s.analytic.xyz().as_dvec3().to_array();
            [s.unshadowed.xyz().as_dvec3()]
        });
        assert!(analytic.iter().all(|&u| u > 0.0), "U = {analytic:?}");
        assert!(agrees(estimates, analytic), "U_N {estimates:?} vs U {analytic:?}");
    }

    /// Each case's mean `U_N` over [`SEEDS`] samples [`agrees`] with its analytic `U`, for each
    /// sampler kind and residual setting of `kinds`.
    fn assert_unshadowed_estimate_is_unbiased(cases: &[(&[Light], MaterialParams, Vec3)], kinds: &[(u32, u32)]) {
        for (k, &(lights, material, view)) in cases.iter().enumerate() {
            for &(kind, residual) in kinds {
                let e = estimate(lights, material, view, kind, residual, unoccluded);
                assert!(e.analytic.iter().all(|&u| u > 0.0), "case {k}: U = {:?}", e.analytic);
                assert!(
                    agrees(e.unshadowed, e.analytic),
                    "case {k} kind {kind} residual {residual}: U_N {:?} vs U {:?}",
                    e.unshadowed,
                    e.analytic
                );
            }
        }
    }

    #[test]
    fn shadowed_estimate_is_unbiased_for_the_visible_part_of_the_light() {
        // An occluder — the half-plane z = 1/2, x > 1/10 — hides the part x > 1/5 of the ceiling
        // light (x ∈ [−0.1, 0.7], y ∈ [−0.2, 0.6] at z = 1) from the shading point at the origin.
        // `S_N` samples the whole light and counts only unoccluded rays, so its mean is the
        // integral of the lobes it evaluates over the visible part — exactly the analytic `U` of
        // the sub-quad x ∈ [−0.1, 0.2]. Mean of 2^17 samples within `Z` standard errors (plus
        // 1e-4 relative: f32 arithmetic, and the shadow ray's origin offset, which moves the
        // shadow's edge on the light by ~1e-5) of that `U`, channel by channel; diffuse, glossy
        // and metallic materials, a grazing view, a second light below the occluder's plane (never occluded),
        // both samplers, with and without the residual towards GGX.
        let occluder_visible = |origin: Vec4, direction: Vec4| {
            let (o, d, t_max) = (origin.xyz(), direction.xyz(), direction.w);
            let t = (0.5 - o.z) / d.z;
            !(d.z > 0.0 && t > 0.0 && t < t_max && o.x + t * d.x > 0.1)
        };
        let radiance = Vec3::new(5.0, 4.0, 3.0);
        let light = ceiling_light(Vec3::new(0.3, 0.2, 1.0), 0.4, radiance);
        let visible_part = Light::quad(
            Vec3::new(-0.1, 0.6, 1.0),
            Vec3::new(0.3, 0.0, 0.0),
            Vec3::new(0.0, -0.8, 0.0),
            radiance,
            false,
        );
        let low = ceiling_light(Vec3::new(-1.5, 0.0, 0.3), 0.5, Vec3::splat(2.0));
        let view = Vec3::new(0.6, 0.0, 0.8);
        let grazing = Vec3::new(-0.99, 0.0, 0.141).normalize();
        // Each case takes the first `count` of these lights.
        let (all_lights, all_visible) = ([light, low], [visible_part, low]);
        let cases = [
            (1, material(Vec3::new(0.8, 0.6, 0.4), 1.0, 0.0), view),
            (1, material(Vec3::splat(0.7), 0.3, 0.5), view),
            (2, material(Vec3::splat(0.9), 0.2, 1.0), view),
            (2, material(Vec3::splat(0.9), 0.1, 1.0), grazing),
        ];
        for (k, (count, material, view)) in cases.into_iter().enumerate() {
            let (lights, visible_lights) = (&all_lights[..count], &all_visible[..count]);
            for (kind, residual) in KINDS_AND_RESIDUAL {
                let reference = analytic_u(visible_lights, material, view, residual);
                let e = estimate(lights, material, view, kind, residual, occluder_visible);
                let hides_part = reference.iter().zip(e.analytic).all(|(&r, u)| r > 0.0 && r < 0.95 * u);
                assert!(hides_part, "case {k}: the occluder hides part of U");
                assert!(
                    agrees(e.shadowed, reference),
                    "case {k} kind {kind} residual {residual}: S_N {:?} vs U of the visible part {reference:?}",
                    e.shadowed
                );
            }
        }
    }

    /// Under a light that fills the hemisphere, `U` is the radiance times the directional
    /// albedos, channel by channel: `L·(base·(1 − m) + F0·magnitude + (1 − F0)·fresnel)` with
    /// glTF's `F0 = 0.04·(1 − m) + base·m` — a metal tinted by its base colour and without a
    /// diffuse lobe, a dielectric's specular lobe white. (The unbiasedness tests compare `U_N`
    /// with `U`, which take the lobes' colours from the same code: a metal's untinted F0, or a
    /// diffuse lobe kept under metal, passed them.) The albedos are read from the committed
    /// table at a grid cell, not through the lookup under test.
    #[test]
    fn u_under_a_hemisphere_light_is_the_albedo_of_each_channel() {
        use raywave_shared::ltc_table::LTC_AMPLITUDE;
        // Grid row 32 (roughness 32/63), column 0 (seen along the normal: the LTC lobe
        // symmetric, all of it above the horizon).
        let (base, radiance, roughness) = (Vec3::new(0.9, 0.5, 0.1), Vec3::new(2.0, 3.0, 4.0), 32.0 / 63.0);
        let [magnitude, fresnel, _, _] = LTC_AMPLITUDE[32 * 64];
        // 10 × 10 and 10⁻³ above the point: both lobes' form factors within ~10⁻⁴ of 1.
        let lights = [ceiling_light(Vec3::new(0.0, 0.0, 1.0e-3), 5.0, radiance)];
        for metallic in [0.0f32, 0.5, 1.0] {
            let f0 = Vec3::splat(0.04) * (1.0 - metallic) + base * metallic;
            let diffuse = base * (1.0 - metallic);
            let expected = radiance * (diffuse + f0 * magnitude + (Vec3::ONE - f0) * fresnel);
            let material = material(base, roughness, metallic);
            let u = analytic_u(&lights, material, Vec3::Z, 0);
            for (channel, (u, expected)) in u.into_iter().zip(expected.to_array()).enumerate() {
                let expected = f64::from(expected);
                assert!(
                    (u - expected).abs() <= 2e-3 * expected,
                    "metallic {metallic}, channel {channel}: U {u}, expected {expected}"
                );
            }
        }
    }

    #[test]
    fn without_occluders_the_ratio_returns_u_exactly() {
        let u = Vec3::new(0.3, 1.7, 12.5);
        let u_n = Vec3::new(0.2, 3.0, 9.0);
        assert_eq!(composite(u, u_n, u_n, Vec3::ZERO), Sanitized::clean(u));
        let fallback = composite(u, Vec3::ZERO, Vec3::ZERO, Vec3::ONE);
        assert_eq!(fallback, Sanitized::clean(u + Vec3::ONE), "U_N ≈ 0 falls back to U, which is not a replacement");
    }

    /// The ratio keeps values above 1 up to 10⁴ — the stochastic+tv baseline divides `S_N` by
    /// an image mean, which a bright pixel exceeds — and clamps beyond, and below 0.
    #[test]
    fn the_shadow_ratio_is_clamped_to_its_documented_range() {
        let ratio = shadow_ratio(Vec3::new(3.0, 2.0e5, -1.0), Vec3::ONE);
        assert_eq!(ratio, Vec3::new(3.0, 1.0e4, 0.0));
        assert_eq!(shadow_ratio(Vec3::new(0.25, 0.0, 1.0), Vec3::new(1.0, 2.0, 1.0)), Vec3::new(0.25, 0.0, 1.0));
        let below = SMALLEST_RADIANCE / 2.0;
        assert_eq!(shadow_ratio(Vec3::splat(0.5), Vec3::new(0.0, below, f32::NAN)), Vec3::ONE, "U_N ≈ 0 or NaN: 1");
    }

    /// The view direction's length does not matter (the trace stage takes any): a view at 60°
    /// from the normal given 2, 10⁻³, 10²⁵ and 10⁻²⁰ long shades as given unit long, to rounding,
    /// and a zero one stays finite. Taken as it came, the long view had read as normal incidence;
    /// normalised as it came, the 10²⁵ one (its square ∞) as grazing.
    #[test]
    fn the_view_direction_may_have_any_length() {
        let table = table();
        let materials = [material(Vec3::splat(0.5), 0.3, 0.0)];
        let lights = [ceiling_light(Vec3::new(0.5, 0.0, 1.0), 0.4, Vec3::ONE)];
        let scene = ShadeScene { materials: &materials, lights: LightSet::new(&lights, &[], &[]), ltc: &table };
        let view = Vec3::new(0.75f32.sqrt(), 0.0, 0.5);
        let shade = |scale: f32| {
            shade_sample(&params(sampler_kind::SOBOL, 5, 3), UVec2::ZERO, -view * scale, &surface_at_origin(), &scene)
                .value
        };
        let unit = shade(1.0);
        assert!(unit.analytic.x > 0.0 && unit.shadow_direction.w > 0.0);
        for scale in [2.0, 1e-3, 1e25, 1e-20] {
            let scaled = shade(scale);
            for (a, b) in [(scaled.analytic, unit.analytic), (scaled.unshadowed, unit.unshadowed)] {
                assert!(a.abs_diff_eq(b, 1e-5 * b.abs().max_element()), "scale {scale}: {a} against {b}");
            }
            assert!(scaled.shadow_direction.abs_diff_eq(unit.shadow_direction, 1e-5), "scale {scale}");
        }
        let zero = shade(0.0);
        assert!(zero.analytic.is_finite() && zero.unshadowed.is_finite() && zero.shadow_direction.is_finite());
    }

    /// Both ends of the MIS blends are exact: a tiny pdf beside a large one is kept at `t = 1`.
    #[test]
    fn lerp_is_exact_at_both_ends() {
        assert_eq!(lerp(0.161, 3e-9, 1.0), 3e-9);
        assert_eq!(lerp(0.161, 3e-9, 0.0), 0.161);
        assert_eq!(lerp(2.0, 4.0, 0.5), 3.0);
    }

    /// What the stage cannot compute is replaced and flagged, never passed on: a hit record that
    /// is not finite (a miss), lights whose summed `U` overflows `f32` (no `U`, no sample), and a
    /// composite that overflows (the emitted radiance alone).
    #[test]
    fn non_finite_values_are_replaced_and_flagged() {
        let triangles = [Vec4::ZERO, Vec4::X, Vec4::Y];
        for (direction, t, barycentrics) in [
            (Vec3::Z, f32::NAN, glam::Vec2::splat(0.25)),
            (Vec3::Z, 1.0, glam::Vec2::new(f32::INFINITY, 0.0)),
            (Vec3::new(0.0, f32::NAN, 1.0), 1.0, glam::Vec2::splat(0.25)),
            (Vec3::new(f32::NEG_INFINITY, 0.0, 1.0), 1.0, glam::Vec2::splat(0.25)),
        ] {
            let s = resolve_surface(direction, t, 0, 0, barycentrics, &triangles, &[0]);
            assert_eq!(s, Surface { replaced: true, ..Surface::MISS });
            let table = table();
            let scene = ShadeScene { materials: &[], lights: LightSet::new(&[], &[], &[]), ltc: &table };
            let shaded = shade_sample(&params(0, 0, 0), UVec2::ZERO, Vec3::Z, &s, &scene);
            assert_eq!(shaded, Sanitized::replacing(ShadeSample::NONE));
        }

        let table = table();
        let bright = ceiling_light(Vec3::Z, 0.5, Vec3::splat(f32::MAX));
        // Each light's `U` is finite (a fifth of f32::MAX); eight of them are not.
        let lights = [bright; 8];
        let materials = [material(Vec3::splat(0.9), 0.5, 0.0)];
        let scene = ShadeScene { materials: &materials, lights: LightSet::new(&lights, &[], &[]), ltc: &table };
        let shaded =
            shade_sample(&params(sampler_kind::SOBOL, 1, 0), UVec2::ZERO, -Vec3::Z, &surface_at_origin(), &scene);
        let s = shaded.value;
        assert!(shaded.replaced, "{s:?}");
        assert_eq!((s.analytic, s.unshadowed, s.shadow_direction.w), (Vec4::ZERO, Vec4::ZERO, 0.0));

        let overflow = apply_visibility(Vec3::splat(f32::MAX), Vec3::ONE, Vec3::new(f32::MAX, 1.0, 0.0));
        assert_eq!(overflow, Sanitized::replacing(Vec3::new(f32::MAX, 1.0, 0.0)));
    }

    #[test]
    fn hard_cases_stay_finite() {
        let table = table();
        let normal_light = ceiling_light(Vec3::new(0.0, 0.0, 1.0), 0.5, Vec3::splat(3.0));
        let lights = [
            normal_light,
            // Behind the surface facing away, above it facing away, below its horizon facing it,
            // crossing its horizon facing it, on the shading plane, tiny (≈1e-6 sr), huge.
            ceiling_light(Vec3::new(0.0, 0.0, -1.0), 0.5, Vec3::ONE),
            Light::quad(Vec3::new(-0.5, -0.5, 1.0), Vec3::X, Vec3::Y, Vec3::ONE, false),
            Light::quad(Vec3::new(-0.5, -0.5, -1.0), Vec3::X, Vec3::Y, Vec3::ONE, false),
            Light::quad(Vec3::new(1.0, -0.5, -0.5), Vec3::Z, Vec3::Y, Vec3::ONE, false),
            Light::quad(Vec3::new(1.0, -0.5, 0.0), Vec3::X, Vec3::Y, Vec3::ONE, false),
            ceiling_light(Vec3::new(0.0, 0.0, 1.0), 5.0e-4, Vec3::splat(1.0e6)),
            ceiling_light(Vec3::new(0.0, 0.0, 1.0e-3), 1.0e3, Vec3::ONE),
        ];
        let materials = [
            material(Vec3::splat(0.5), 0.0, 0.0),
            material(Vec3::splat(0.5), 1.0, 1.0),
            material(Vec3::ZERO, 0.5, 1.0),
            material(Vec3::ONE, 0.01, 0.0),
        ];
        let views = [
            Vec3::Z,
            Vec3::new(1.0, 0.0, 1.0e-6).normalize(),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.3, 0.3, -0.9).normalize(),
        ];
        // Each light alone, then all of them chosen between by importance.
        let sets: Vec<&[Light]> = lights.iter().map(core::slice::from_ref).chain([&lights[..]]).collect();
        for set in sets {
            let light = if set.len() == 1 { format!("{:?}", set[0]) } else { format!("all {} lights", set.len()) };
            for m in 0..materials.len() {
                let scene = ShadeScene { materials: &materials, lights: LightSet::new(set, &[], &[]), ltc: &table };
                let surface = Surface { instance: m as u32, ..surface_at_origin() };
                for (view, analytic_residual) in views.into_iter().flat_map(|v| [(v, 0), (v, 1)]) {
                    for i in 0..64 {
                        let p = ShadeParams { analytic_residual, ..params(sampler_kind::SOBOL, 1, i) };
                        let shaded = shade_sample(&p, UVec2::ZERO, -view, &surface, &scene);
                        let s = shaded.value;
                        let all = [s.analytic, s.unshadowed, s.emitted, s.shadow_origin, s.shadow_direction];
                        assert!(all.iter().all(|v| v.is_finite()), "{light:?} {m} {view}: {s:?}");
                        assert!(!shaded.replaced, "computed, not sanitized: {light:?} {m} {view}: {s:?}");
                        assert!(s.analytic.min_element() >= 0.0 && s.unshadowed.min_element() >= 0.0);
                        let c = composite(s.analytic.xyz(), s.unshadowed.xyz(), Vec3::ZERO, Vec3::ZERO);
                        assert!(c.value.is_finite() && !c.replaced);
                    }
                }
            }
        }
        // A light behind the surface contributes nothing and traces nothing.
        let behind = [lights[1]];
        let scene = ShadeScene { materials: &materials, lights: LightSet::new(&behind, &[], &[]), ltc: &table };
        let s = shade_sample(&params(sampler_kind::SOBOL, 1, 0), UVec2::ZERO, -Vec3::Z, &surface_at_origin(), &scene);
        assert_eq!((s.value.analytic, s.value.unshadowed, s.value.shadow_direction.w), (Vec4::ZERO, Vec4::ZERO, 0.0));
        // A miss shades nothing.
        let miss = shade_sample(&params(0, 0, 0), UVec2::ZERO, Vec3::Z, &Surface::MISS, &scene);
        assert_eq!(miss, Sanitized::clean(ShadeSample::NONE));
    }

    /// The shade sample of `lamp` (one of [`lamps`]: edges `turn · x̂`, `turn · ŷ`, emitting
    /// towards `turn · ẑ`) at the point `z` along that normal from its point `(0.6, 0.7)`, facing
    /// it (normal `−turn · ẑ`: the back of a lamp seen from below), on mesh `instance` (0 or 1,
    /// two alike materials).
    fn shade_by_lamp(lamp: Light, turn: glam::Quat, z: f32, instance: u32) -> ShadeSample {
        let table = table();
        let materials = [material(Vec3::splat(0.8), 1.0, 0.0); 2];
        let lights = [lamp];
        let scene = ShadeScene { materials: &materials, lights: LightSet::new(&lights, &[], &[]), ltc: &table };
        let normal = turn * Vec3::Z;
        let p = lamp.position.xyz() + turn * Vec3::new(0.6, 0.7, 0.0) + normal * z;
        let surface =
            Surface { position: p.extend(1.0), normal: (-normal).extend(0.0), instance, ..surface_at_origin() };
        shade_sample(&params(sampler_kind::SOBOL, 1, 0), UVec2::ZERO, normal, &surface, &scene).value
    }

    /// The lamps of the own-plane tests: axis-aligned at the origin, and turned far from it, where
    /// an ulp is larger and the side test rounds in every coordinate. With the rotation and about
    /// the ulp of the larger coordinates (ε times 0.5 and ~300: the tolerance's unit).
    fn lamps(two_sided: bool) -> [(Light, glam::Quat, f32); 2] {
        let turn = glam::Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
        let far = Vec3::new(300.0, -200.0, 100.0);
        let lamp = |centre: Vec3, turn: glam::Quat| {
            let corner = centre - turn * Vec3::new(0.5, 0.5, 0.0);
            Light::quad(corner, turn * Vec3::X, turn * Vec3::Y, Vec3::ONE, two_sided)
        };
        [
            (lamp(Vec3::ZERO, glam::Quat::IDENTITY), glam::Quat::IDENTITY, 0.5 * f32::EPSILON),
            (lamp(far, turn), turn, 300.5 * f32::EPSILON),
        ]
    }

    #[test]
    fn a_light_lights_nothing_in_its_own_plane() {
        // The back of a lamp: a point on an emitting quad, its normal facing away from the
        // emission (towards a camera on the other side). Rounding puts such a hit point a few
        // ulp in front or behind; in front, the light filled its hemisphere (U = albedo · L).
        for two_sided in [false, true] {
            for (lamp, turn, ulp) in lamps(two_sided) {
                let what = |steps| std::format!("{steps} ulp off {lamp:?}");
                for steps in -4..=4 {
                    let s = shade_by_lamp(lamp, turn, steps as f32 * ulp, 0);
                    let unlit = (s.analytic, s.unshadowed, s.shadow_direction.w);
                    assert_eq!(unlit, (Vec4::ZERO, Vec4::ZERO, 0.0), "{}", what(steps));
                }
                // About twice the tolerance off is no rounding: the light fills the point's hemisphere
                // (U: the diffuse albedo 0.8 plus the specular lobe's 0.01).
                let lit = shade_by_lamp(lamp, turn, 16.0 * ulp, 0).analytic;
                assert!((0.75..0.85).contains(&lit.x), "{}: U {lit}", what(16));
            }
        }
    }

    #[test]
    fn a_light_lights_nothing_of_the_mesh_it_is_made_of() {
        // A point 10⁻⁵ of the coordinates in front of the lamp — where the emitter fit lets the
        // second triangle of a lamp's mesh bend (10⁻⁴ of its size) — is lit by a light of another
        // mesh, and not by the light made of its own.
        for (lamp, turn, ulp) in lamps(false) {
            let z = 1.0e-5 * ulp / f32::EPSILON;
            for (light, instance, lit) in [(lamp, 0, true), (lamp.made_of(1), 0, true), (lamp.made_of(1), 1, false)] {
                let u = shade_by_lamp(light, turn, z, instance).analytic.x;
                assert_eq!(u > 0.75, lit, "mesh {} seen from mesh {instance}: U {u}", light.mesh);
                assert!(lit || u == 0.0, "{u}");
            }
        }
    }

    #[test]
    fn with_the_residual_u_n_follows_the_ggx_lobe() {
        // A metallic surface seen at 75° and a light far from its mirror direction (a far tail,
        // where the LTC alone is off by tens of per cent): the residual moves U away from the
        // LTC's, and U_N, which then evaluates the GGX lobe, follows it (`Z` standard errors of
        // 2^17 samples) — it does not stay with the LTC's U.
        let material = material(Vec3::splat(0.8), 0.2, 1.0);
        let lights = [ceiling_light(Vec3::new(0.5, 0.0, 1.0), 0.3, Vec3::splat(4.0))];
        let view = Vec3::new(0.966, 0.0, 0.259);
        // A grey light on a grey metal: the channels agree, so the first stands for all.
        let ltc_u = analytic_u(&lights, material, view, 0);
        let e = estimate(&lights, material, view, sampler_kind::SOBOL, 1, unoccluded);
        let (MeanAndError { mean, error }, corrected_u, ltc_u) = (e.unshadowed[0], e.analytic[0], ltc_u[0]);
        assert!((corrected_u - ltc_u).abs() > 0.05 * ltc_u, "U {corrected_u} vs the LTC's {ltc_u}");
        assert!(agrees(e.unshadowed, e.analytic), "U_N {:?} vs U {:?}", e.unshadowed, e.analytic);
        assert!((mean - ltc_u).abs() > Z * error, "U_N {mean} ± {error} stayed with the LTC's U {ltc_u}");
    }

    #[test]
    fn resolve_interpolates_and_faces_the_camera() {
        let triangles = [Vec4::new(0.0, 0.0, 0.0, 0.0), Vec4::new(1.0, 0.0, 0.0, 0.0), Vec4::new(0.0, 1.0, 0.0, 0.0)];
        let s = resolve_surface(Vec3::Z, 2.0, 0, 0, glam::Vec2::new(0.25, 0.5), &triangles, &[0]);
        assert_eq!(s.position, Vec4::new(0.25, 0.5, 0.0, 2.0));
        assert_eq!(s.normal, Vec4::new(0.0, 0.0, -1.0, 0.0), "faces against the ray");
        assert_eq!(resolve_surface(Vec3::Z, 2.0, NO_HIT, 0, glam::Vec2::ZERO, &triangles, &[0]), Surface::MISS);
        assert_eq!(resolve_surface(Vec3::Z, 2.0, 0, 5, glam::Vec2::ZERO, &triangles, &[0]), Surface::MISS);
        assert_eq!(resolve_surface(Vec3::Z, 2.0, 3, 0, glam::Vec2::ZERO, &triangles, &[0]), Surface::MISS);
        // A direction the trace stage would not trace has no surface; the shortest it traces does.
        let along = |z: f32| resolve_surface(Vec3::new(0.0, 0.0, z), 2.0, 0, 0, glam::Vec2::ZERO, &triangles, &[0]);
        assert_eq!((along(0.0), along(0.5 * crate::trace::MIN_DIRECTION)), (Surface::MISS, Surface::MISS));
        assert_eq!(along(crate::trace::MIN_DIRECTION).normal, Vec4::new(0.0, 0.0, -1.0, 0.0));
        // Two instances of one triangle each: a primitive past instance 0's own triangles, and
        // NO_HIT as the primitive of instance 1 (whose first + primitive wrapped to triangle 0).
        let two = [triangles, triangles.map(|v| v + Vec4::Z)].concat();
        let hit =
            |instance, primitive| resolve_surface(Vec3::Z, 2.0, instance, primitive, glam::Vec2::ZERO, &two, &[0, 1]);
        assert_eq!(hit(1, 0).position.z, 1.0, "instance 1's own triangle");
        assert_eq!(hit(0, 1), Surface::MISS, "instance 0 has one triangle");
        assert_eq!(hit(1, NO_HIT), Surface::MISS);
        assert_eq!(hit(1, 1), Surface::MISS);
        // The counter-clockwise face is the front: met by a ray along −z, not by one along +z.
        let from_above = resolve_surface(Vec3::NEG_Z, 2.0, 0, 0, glam::Vec2::ZERO, &triangles, &[0]);
        assert!(from_above.front_face && !s.front_face);
    }

    /// A one-sided emitter glows only on its front face, where the quad light made of it emits;
    /// a two-sided one on both. Its back glowed, though it lit nothing on that side.
    #[test]
    fn a_one_sided_emitter_is_black_from_behind() {
        let table = table();
        let triangles = [Vec4::new(0.0, 0.0, 0.0, 0.0), Vec4::new(1.0, 0.0, 0.0, 0.0), Vec4::new(0.0, 1.0, 0.0, 0.0)];
        let glow = Vec3::new(4.0, 2.0, 1.0);
        for two_sided_emission in [0, 1] {
            let lamp = MaterialParams {
                emission_metallic: glow.extend(0.0),
                two_sided_emission,
                ..material(Vec3::ONE, 1.0, 0.0)
            };
            let materials = [lamp];
            let scene = ShadeScene { materials: &materials, lights: LightSet::new(&[], &[], &[]), ltc: &table };
            for (direction, front) in [(Vec3::NEG_Z, true), (Vec3::Z, false)] {
                let surface = resolve_surface(direction, 2.0, 0, 0, glam::Vec2::splat(0.25), &triangles, &[0]);
                let s = shade_sample(&params(sampler_kind::SOBOL, 1, 0), UVec2::ZERO, direction, &surface, &scene);
                let expected = if front || two_sided_emission == 1 { glow } else { Vec3::ZERO };
                assert_eq!(s.value.emitted, expected.extend(0.0), "two-sided {two_sided_emission}, front {front}");
            }
        }
    }
}
