//! Light selection: choosing one light among many, uniformly or in proportion to a conservative
//! bound of its contribution, with the probability of every choice available for MIS.
//!
//! The bound is the light importance of Conty Estevez & Kulla, "Importance Sampling of Many Lights
//! with Adaptive Tree Splitting" (HPG 2018), as pbrt-v4 implements it in `LightBounds::Importance`
//! (lights.cpp:107-160): `Φ · cos θ' / d²` with `θ' = max(0, θw − θo − θb)` and, at a surface, the
//! factor `cos(max(0, θi − θb))` (see [`importance`]). It is zero only where no point of the light
//! can emit towards the point, or where the whole light lies below the surface (within rounding:
//! see [`quad_lights_nothing`] and `out_of_reach`), so a light that contributes is never given
//! probability 0. For one quad light — each light of the scan, each BVH leaf — the zero set is
//! the shade stage's own where its `U` is 0, but for one rule the choice does not know: a light
//! lights nothing of the mesh it is made of (`Light::mesh`). raywave's host moves such a mesh
//! onto its light, so its points lie in the light's plane, where both are 0; a mesh an engine
//! leaves bent in front of the plane (by up to the emitter fit's 10⁻⁴) gives that light a
//! positive probability at its own points for a contribution of 0 — unbiased, a little variance
//! where other lights compete (the MIS review's F3). The two cosine factors are bounded further by
//! the quad's own plane and corners ([`quad_cosine_bounds`], [`light_importance`]): the sphere
//! alone bounds nothing inside it, so a large lamp seen edge-on had starved the lamp that lit a
//! point.
//!
//! Three ways to choose, each a pure function with a matching pmf function:
//!
//! - [`select_uniform`] / [`uniform_pmf`]: `1/N`.
//! - [`select_importance`] / [`importance_pmf`]: a linear scan over the lights, `pmf = I_k / Σ I`
//!   with `I_k` the [`light_importance`].
//!   Cost: about 1.5·N importance evaluations per choice, exact per-light importance. When every
//!   importance is zero (all lights behind the surface, or all of zero power) it falls back to the
//!   uniform choice, so it returns a light whenever there is one; that light contributes nothing
//!   there, which keeps the estimator unbiased.
//! - [`select_bvh`] / [`bvh_pmf`]: stochastic descent of a light BVH built by the host
//!   (`raywave_host::lights::LightBvh`), for many lights. At each interior node both children's
//!   importance is evaluated and the first child is taken with probability `I₀ / (I₀ + I₁)`
//!   (`1/2` when both are zero); the sample is rescaled to be reused at the next level and the
//!   branch probabilities multiply into the pmf. Cost: 2 importance evaluations per level.
//!
//! [`LightSet`] picks between the scan and the BVH for a scene (the host decides whether a scene
//! gets a BVH) and mixes in a uniform choice, [`UNIFORM_SHARE`] = 1/32 of the choices (with the
//! scan, among the lights of positive importance), so that every light that can light a point
//! keeps a pmf of at least `1/(32 N)`: importance is a bound — a node's cannot see that all of
//! its lights light nothing at a point, a lamp's own is loose close to its plane — and the light
//! that did light the point had been left a pmf below 2⁻²⁴, never drawn.
//!
//! **BVH layout** ([`LightBvhNode`], 80 bytes): depth-first in one array, node 0 the root. An
//! interior node's first child is the next node, its second child is `child_or_light`; a leaf holds
//! one light, `child_or_light`. The host builder keeps leaves at depth ≤ [`MAX_BVH_DEPTH`] = 32.
//! **Trails**: `trails[light]` is the path from the root to that light's leaf, one bit per level,
//! bit `d` (from the least significant) for the edge leaving depth `d`: 0 = first child, 1 = second.
//! [`bvh_pmf`] follows the trail and checks that the leaf it reaches holds the light; lights left
//! out of the BVH (zero power) reach another light's leaf and so get pmf 0.
//!
//! Precision: each level rescales the 24-bit sample, so how often a subtree is drawn moves in
//! steps of 2⁻²⁴ (measured within 1.2–2.2 steps of `pmf · 2²⁴` at depths 8–24): a subtree whose
//! pmf is ≲ 2⁻²⁴ is drawn with frequency 0, or at least 2⁻²⁴ whatever its pmf (`u = 0` always
//! takes first children), and a branch probability below 2⁻²⁴ relative to its sibling rounds the
//! sibling's to 1 (pbrt-v4 behaves the same). The pmf itself stays positive — each branch
//! probability is its own importance's share, not 1 minus its sibling's — unless the product
//! underflows (a subtree below ≈ 10⁻³⁸ of the total, never drawn), and [`bvh_pmf`] is exactly
//! the product [`select_bvh`] forms, so MIS weights stay consistent. A subtree never
//! drawn holds at most ≈ 2⁻²⁴ of the total importance — a bound, which inside a cluster of
//! lights ignores where they face, so the BVH also gives 0 to an interior node whose box no
//! light can reach the point from (see `node_importance`).
//! The linear scan has the same limit: its target `u·Σ I` moves in steps of 2⁻²⁴ of the total,
//! so a light whose importance is below that step may fall between two steps and never be
//! chosen, though [`importance_pmf`] gives it its share; the light missed is at most ≈ 2⁻²⁴ of
//! the total importance. [`LightSet`]'s uniform share keeps every light of positive importance
//! above that step (for up to [`UNIFORM_SHARE`]·2²⁴ = 2¹⁹ such lights). With the BVH its uniform
//! light is picked by a number of its own, so each of `N` lights is drawn by the share within
//! `N/2²⁴` of its `α/N` (drawn at all for `N` up to 2²⁴).
//!
//! All functions are `no_std`, loop-bounded, allocation- and panic-free, and return finite values:
//! importances are clamped to `[0,` [`MAX_IMPORTANCE`]`]` so that sums over up to 2³² lights stay
//! finite; a non-finite point and a NaN power give importance 0, a NaN normal counts as no
//! surface.

use glam::{Vec2, Vec3};
use raywave_shared::light::{light_kind, Light, LightBounds, LightBvhNode};
use spirv_std::num_traits::Float;

use crate::hash::ONE_MINUS_EPSILON;
use crate::sampling::warp::{clamp_sample, clamp_sample_1d, safe_sqrt};

/// Rec. 709 luminance weights of linear RGB (ITU-R BT.709, `Y = 0.2126 R + 0.7152 G + 0.0722 B`).
pub const LUMINANCE: Vec3 = Vec3::new(0.2126, 0.7152, 0.0722);

/// Upper clamp of [`importance`]: 2³² · 10²⁸ ≈ 4.3·10³⁷ stays below `f32::MAX` ≈ 3.4·10³⁸, so
/// a sum over any number of lights the `u32` indices allow is finite.
pub const MAX_IMPORTANCE: f32 = 1e28;

/// Deepest leaf of a light BVH: the 32 bits of a trail.
pub const MAX_BVH_DEPTH: u32 = 32;

/// Light index of [`LightChoice::NONE`].
pub const NO_LIGHT: u32 = u32::MAX;

/// One chosen light and the probability of having chosen it.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LightChoice {
    /// Index into the light list, or [`NO_LIGHT`].
    pub index: u32,
    /// Probability of choosing `index` (discrete pmf); 0 for [`LightChoice::NONE`].
    pub pmf: f32,
}

impl LightChoice {
    /// No light: the list is empty (or the BVH malformed).
    pub const NONE: LightChoice = LightChoice { index: NO_LIGHT, pmf: 0.0 };

    /// Whether a light was chosen (`pmf > 0`).
    pub fn is_valid(&self) -> bool {
        self.index != NO_LIGHT && self.pmf > 0.0
    }
}

/// `sin θ` from `cos θ` for θ ∈ [0, π].
fn sin_from_cos(cos: f32) -> f32 {
    safe_sqrt(1.0 - cos * cos)
}

/// `cos(max(0, θa − θb))` from the sines and cosines of θa, θb ∈ [0, π] (pbrt-v4 `cosSubClamped`).
fn cos_sub_clamped(sin_a: f32, cos_a: f32, sin_b: f32, cos_b: f32) -> f32 {
    if cos_a > cos_b {
        1.0
    } else {
        cos_a * cos_b + sin_a * sin_b
    }
}

/// `sin(max(0, θa − θb))` from the sines and cosines of θa, θb ∈ [0, π] (pbrt-v4 `sinSubClamped`).
fn sin_sub_clamped(sin_a: f32, cos_a: f32, sin_b: f32, cos_b: f32) -> f32 {
    if cos_a > cos_b {
        0.0
    } else {
        sin_a * cos_b - cos_a * sin_b
    }
}

/// Rec. 709 luminance of linear RGB, clamped to ≥ 0 (NaN → 0).
pub fn luminance(rgb: Vec3) -> f32 {
    let y = LUMINANCE.dot(rgb);
    if y > 0.0 {
        y
    } else {
        0.0
    }
}

/// Bounds of one light: its box, its power and its normal cone.
///
/// Power is the emitted flux of a diffuse emitter with the luminance of the RGB radiance:
/// `Φ = π · A · Y(L)`, with `A = 4πr²` for a sphere and `A = |edge_u × edge_v|` for a quad,
/// doubled for a two-sided quad. Cones: a sphere emits in every direction (`θo = π`, axis +z); a
/// quad's normals are all `normalize(edge_u × edge_v)` (`θo = 0`), and a two-sided quad keeps that
/// cone with `two_sided = 1`, which [`importance`] mirrors (pbrt-v4's choice: tighter than
/// widening the cone to `θo = π`). Diffuse emitters emit within `θe = π/2` of their normal.
/// An unknown kind or a degenerate light gets `Φ = 0`.
pub fn light_bounds(light: &Light) -> LightBounds {
    let radiance = luminance(light.radiance.truncate());
    let origin = light.position.truncate();
    let mut bounds = LightBounds {
        min: origin.extend(0.0),
        max: origin.extend(0.0),
        axis: Vec3::Z.extend(0.0),
        phi: 0.0,
        cos_theta_o: -1.0,
        cos_theta_e: 0.0,
        two_sided: 0,
    };
    if light.kind == light_kind::SPHERE {
        let r = light.position.w.abs();
        let area = 4.0 * core::f32::consts::PI * r * r;
        bounds.min = (origin - Vec3::splat(r)).extend(0.0);
        bounds.max = (origin + Vec3::splat(r)).extend(0.0);
        // The box's centre may round away from the sphere's by an ulp.
        let centre = (bounds.min + bounds.max).truncate() * 0.5;
        bounds.max.w = r + (centre - origin).length();
        bounds.phi = core::f32::consts::PI * area * radiance;
    } else if light.kind == light_kind::QUAD {
        let eu = light.edge_u.truncate();
        let ev = light.edge_v.truncate();
        let normal = eu.cross(ev);
        let area = normal.length();
        let sides = if light.two_sided != 0 { 2.0 } else { 1.0 };
        let corners = [origin, origin + eu, origin + ev, origin + eu + ev];
        let mut lo = origin;
        let mut hi = origin;
        let mut i = 1;
        while i < 4 {
            lo = lo.min(corners[i]);
            hi = hi.max(corners[i]);
            i += 1;
        }
        let centre = (lo + hi) * 0.5;
        // The corners relative to the centre from the edges, not from the rounded absolute
        // corners: far from the origin a light smaller than its coordinates' spacing rounds to a
        // box of a point or two (a 5 mm lamp 10⁶ out: radius 0, and a centre up to 3 cm off), and
        // a sphere about it missed the light the shade stage sees from `corner − p`, so its
        // importance was 0 where its `U` was half the point's. `centre − origin` is exact there
        // (both lie in one binade).
        let offset = centre - origin;
        let relative = [Vec3::ZERO, eu, ev, eu + ev];
        let mut radius = 0.0f32;
        i = 0;
        while i < 4 {
            radius = radius.max((relative[i] - offset).length());
            i += 1;
        }
        bounds.min = lo.extend(0.0);
        bounds.max = hi.extend(radius);
        if area > 0.0 {
            bounds.axis = (normal / area).extend(0.0);
        }
        bounds.phi = core::f32::consts::PI * area * radiance * sides;
        bounds.cos_theta_o = 1.0;
        bounds.two_sided = (light.two_sided != 0) as u32;
    }
    if bounds.phi.is_nan() || bounds.phi <= 0.0 {
        bounds.phi = 0.0;
    }
    // Coordinates near f32::MAX overflow the centre: such a light may be anywhere.
    let radius = bounds.max.w;
    bounds.max.w = if radius.is_finite() { radius } else { f32::INFINITY };
    bounds.min.w = if radius.is_finite() { radius } else { 0.0 };
    bounds
}

/// Conservative importance of the lights inside `bounds` for the point `p` with surface normal
/// `n` (Conty Estevez & Kulla 2018; pbrt-v4 `LightBounds::Importance`).
///
/// With `pc` the box centre, `d² = max(|p − pc|², r²)`, `r` the bounding-sphere radius of the
/// largest single light inside (`bounds.min.w`; for one light, its own), `θw` the angle between
/// the cone axis and `p − pc` (its absolute cosine for two-sided bounds), `θb` the half-angle of
/// the cone from `p` around the lights' sphere about `pc` (radius `bounds.max.w`; `θb = π` when
/// `p` is inside it), `θ' = max(0, θw − θo − θb)`:
/// `I = Φ · cos θ' / d²`, and 0 when `cos θ' ≤ cos θe`.
///
/// At a surface (`n ≠ 0`; need not be normalised) it is multiplied by `cos(max(0, θi − θb))`, θi
/// the angle between `n` and `pc − p`, and clamped to ≥ 0: lights entirely below the surface get 0.
/// This uses the signed cosine, unlike pbrt-v4's `AbsDot` (which keeps lights behind the surface
/// for transmission): pass the normal on the side where light is wanted, or `n = 0` (a medium
/// point, or a transmissive surface) for no surface factor.
///
/// Finite and in `[0, MAX_IMPORTANCE]` for every input; 0 for a non-finite `p` and for a NaN or
/// zero power. A NaN normal counts as no surface (`n = 0`): the light keeps its importance, which
/// cannot make a lit point dark.
pub fn importance(bounds: &LightBounds, p: Vec3, n: Vec3) -> f32 {
    bounded_importance(bounds, p, n, Vec2::ONE)
}

/// [`importance`] with its emitter factor `cos θ'` and its surface factor bounded further by
/// `cosines` (x and y, in `[0, 1]`; 0 gives 0): a single quad's [`quad_cosine_bounds`], which know
/// the quad's plane and corners.
fn bounded_importance(bounds: &LightBounds, p: Vec3, n: Vec3, cosines: Vec2) -> f32 {
    let phi = bounds.phi;
    if phi.is_nan() || phi <= 0.0 {
        return 0.0;
    }
    let lo = bounds.min.truncate();
    let hi = bounds.max.truncate();
    let center = (lo + hi) * 0.5;
    let radius = bounds.max.w;
    let to_p = p - center;
    let dist2 = to_p.length_squared();
    if !dist2.is_finite() {
        // p is NaN or infinite.
        return 0.0;
    }
    let light_radius = bounds.min.w;
    let d2 = dist2.max(light_radius * light_radius).max(f32::MIN_POSITIVE);
    let mut cos_theta_p = 1.0;
    let mut cos_theta_pi = 1.0;
    // Inside the bounding sphere every direction may reach the lights: both factors are 1.
    if dist2 > radius * radius {
        let wi = to_p / Float::sqrt(dist2);
        let sin2_b = (radius * radius / dist2).min(1.0);
        let cos_b = safe_sqrt(1.0 - sin2_b);
        let sin_b = safe_sqrt(sin2_b);

        let mut cos_w = bounds.axis.truncate().dot(wi);
        if bounds.two_sided != 0 {
            cos_w = cos_w.abs();
        }
        let cos_w = cos_w.clamp(-1.0, 1.0);
        let sin_w = sin_from_cos(cos_w);
        let cos_o = bounds.cos_theta_o.clamp(-1.0, 1.0);
        let sin_o = sin_from_cos(cos_o);
        let cos_x = cos_sub_clamped(sin_w, cos_w, sin_o, cos_o);
        let sin_x = sin_sub_clamped(sin_w, cos_w, sin_o, cos_o);
        cos_theta_p = cos_sub_clamped(sin_x, cos_x, sin_b, cos_b);
        if cos_theta_p <= bounds.cos_theta_e {
            return 0.0;
        }

        let n_len2 = n.length_squared();
        if n_len2 > 0.0 {
            let cos_i = (-n.dot(wi) / Float::sqrt(n_len2)).clamp(-1.0, 1.0);
            let sin_i = sin_from_cos(cos_i);
            cos_theta_pi = cos_sub_clamped(sin_i, cos_i, sin_b, cos_b);
        }
    }
    let value = phi * cos_theta_p.min(cosines.x) * cos_theta_pi.min(cosines.y) / d2;
    if value > 0.0 {
        value.min(MAX_IMPORTANCE)
    } else {
        0.0
    }
}

/// How far from a quad light's plane a point counts as lying in it, relative to the larger of the
/// point's and the light's corner's largest coordinate: 8 ε, 8 to 16 ulp of that coordinate. A hit
/// point lies a few ulp off its triangle's plane (the Cornell lamp's hits 0–2 ulp by their ray
/// parameter, on the CPU and an H100), and the side test's own rounding adds up to 1.6 ε (a
/// simulation of tilted lights of 1 mm to 1000 units up to 10⁴ out): about 2× headroom.
pub const IN_LIGHT_PLANE_TOLERANCE: f32 = 8.0 * f32::EPSILON;

/// Whether `p` is on the emitting side of quad light `light` — the shade stage's test, which
/// light selection shares so that it gives 0 exactly where the stage's `U` is 0. Not where `p`
/// lies in the light's plane (within [`IN_LIGHT_PLANE_TOLERANCE`]): a light lights nothing there
/// — a point beside it sees it edge-on — and on its own surface rounding alone would decide the
/// side, between `U` = 0 and a light that fills the hemisphere (the back of a one-sided lamp
/// speckled with full `U`, differently on each backend).
pub fn quad_faces(light: &Light, p: Vec3) -> bool {
    facing_height(light, p) != 0.0
}

/// [`quad_faces`]' test, keeping its measure for [`quad_cosine_bounds`]: `p`'s height over
/// `light`'s plane along `e_u × e_v` (`(e_u × e_v)·(p − corner)`, scene units times the
/// parallelogram's area; negative on a two-sided light's back) where `p` is on its emitting side,
/// and 0 behind a one-sided light or in its plane.
fn facing_height(light: &Light, p: Vec3) -> f32 {
    let corner = light.position.truncate();
    let normal = light.edge_u.truncate().cross(light.edge_v.truncate());
    let side = normal.dot(p - corner);
    let emitting_side = side > 0.0 || (light.two_sided != 0 && side < 0.0);
    // The tolerance (a square root) only for the lights that pass the sign test.
    if emitting_side
        && side.abs() > IN_LIGHT_PLANE_TOLERANCE * p.abs().max(corner.abs()).max_element() * normal.length()
    {
        side
    } else {
        0.0
    }
}

/// Whether quad light `light` lights nothing at `p` (surface normal `n`, need not be normalised;
/// 0 or NaN: no surface), by the shade stage's own zero set: `p` not on its emitting side
/// ([`quad_faces`]: behind a one-sided quad, or in its plane), or every corner of the quad on or
/// below `p`'s tangent plane, where the horizon clips it away (a corner a rounding error above
/// it, whose `U` is of that order squared, may count as below). False for a sphere light.
///
/// [`importance`]'s bound has no cone or surface factor inside a light's bounding sphere, so
/// without this test a quad weighed as if it filled the hemisphere of points on it, beside it in
/// its plane, or just below its edge: points on a 0.5 m ceiling lamp, lit by a wall lamp 2 m
/// away, drew the wall lamp with a pmf of 0.012 (now 1). A bound-only version of the test,
/// against the box centre's plane, had culled points a few µm in front of a lamp whose `U` was
/// 1 (its band scaled with the centre's coordinates, not the stage's), and lost a normal's tilt
/// of up to 3.5·10⁻⁴ rad to cancellation.
pub fn quad_lights_nothing(light: &Light, p: Vec3, n: Vec3) -> bool {
    if light.kind != light_kind::QUAD {
        return false;
    }
    let to_corner = light.position.truncate() - p;
    !quad_faces(light, p) || highest_corner(light, to_corner, n).is_none()
}

/// The largest height `n·(c − p)` of quad `light`'s corners `c` over `p`'s tangent plane
/// (`to_corner` = the light's corner − `p`; NaN heights skipped), or `None` where every corner is
/// on or below it and `n` is a surface's normal (positive length) — the horizon's half of
/// [`quad_lights_nothing`]'s zero set, shared with [`quad_cosine_bounds`].
#[allow(clippy::neg_cmp_op_on_partial_ord)] // `!(h <= 0)`: a NaN height counts as above
fn highest_corner(light: &Light, to_corner: Vec3, n: Vec3) -> Option<f32> {
    let (eu, ev) = (light.edge_u.truncate(), light.edge_v.truncate());
    let corners = [to_corner, to_corner + eu, to_corner + ev, to_corner + eu + ev];
    let (mut highest, mut above) = (f32::NEG_INFINITY, !(n.length_squared() > 0.0));
    let mut i = 0;
    while i < 4 {
        let height = n.dot(corners[i]);
        highest = highest.max(height);
        above = above || !(height <= 0.0);
        i += 1;
    }
    if above {
        Some(highest)
    } else {
        None
    }
}

/// One light's importance at `p` (surface normal `n`): [`importance`] of its [`light_bounds`],
/// its two cosine factors no larger than a quad's own [`quad_cosine_bounds`] — which are 0 where
/// the shade stage's `U` is 0 for a quad ([`quad_lights_nothing`]). What the linear scan weighs
/// each light by; a BVH leaf weighs its light the same way, from the leaf's bounds (the light's,
/// as raywave's builder stores them).
pub fn light_importance(light: &Light, p: Vec3, n: Vec3) -> f32 {
    bounded_importance(&light_bounds(light), p, n, quad_cosine_bounds(light, p, n))
}

/// For quad light `light` and a point `p` (surface normal `n`, need not be normalised; 0 or NaN:
/// no surface), upper bounds of the two cosines of any direction between the light and `p`: at
/// the light (x), `h / D`, and at the surface (y), `max_c n̂·(c − p) / D` over the corners `c` (a
/// linear function's largest value on the parallelogram), with `h` the height of `p` over the
/// light's plane, `D = √(h² + d²)` and `d` a lower bound of the distance in that plane from `p`'s
/// foot to the parallelogram (the largest distance outside one of its four edge lines), so that
/// `D` is at most the distance from `p` to any point of the light; each clamped to 1 (and 1
/// where not finite). Both 0 where the light lights nothing at `p` ([`quad_lights_nothing`],
/// whose tests this shares); 1 for a sphere light.
///
/// [`importance`]'s cone and surface factors know only the light's bounding sphere, which bounds
/// nothing inside it and little near it (`sin θb`): a large lamp seen nearly edge-on from just in
/// front of its plane beside it, or whose sliver above the horizon was all `p` saw of it, weighed
/// as if it faced `p` while its `U` was ~0 — the lamp (`U` 0) took a pmf of 0.99999997 and the
/// lamp that alone lit the point got 3·10⁻⁸, below 2⁻²⁴, never drawn (`U_N` 0 where `U` was not;
/// a helper's study). Both bounds are positive wherever the shade stage's `U` is: `h` is above
/// [`quad_faces`]' tolerance, a corner above the horizon by the same products as
/// [`quad_lights_nothing`]'s, and `D` is formed without squaring the larger of `h` and `d`.
pub fn quad_cosine_bounds(light: &Light, p: Vec3, n: Vec3) -> Vec2 {
    if light.kind != light_kind::QUAD {
        return Vec2::ONE;
    }
    let to_corner = light.position.truncate() - p;
    let side = facing_height(light, p);
    if side == 0.0 {
        return Vec2::ZERO;
    }
    let Some(highest) = highest_corner(light, to_corner, n) else {
        return Vec2::ZERO;
    };
    let (eu, ev) = (light.edge_u.truncate(), light.edge_v.truncate());
    let normal = eu.cross(ev);
    let (area, len_u, len_v) = (normal.length(), eu.length(), ev.length());
    let unit = normal / area;
    let to_p = -to_corner;
    let h = side.abs() / area;
    // In-plane unit normals of the edge lines through the corner (along `ev`, along `eu`),
    // pointing into the parallelogram, whose widths across them are `m_v·eu` and `m_u·ev`; no
    // `area²`, which a device flushes to 0 for lights 10⁻¹⁰ across.
    let m_v = ev.cross(unit) / len_v;
    let m_u = unit.cross(eu) / len_u;
    let (a, b) = (m_v.dot(to_p), m_u.dot(to_p));
    let d = (-a).max(a - m_v.dot(eu)).max(-b).max(b - m_u.dot(ev)).max(0.0);
    // √(h² + d²) without overflow or underflow: the larger times √(1 + (smaller/larger)²).
    let (large, small) = (h.max(d), h.min(d));
    let distance = large * Float::sqrt(1.0 + (small / large) * (small / large));
    let (emission, horizon) = (h / distance, highest / (n.length() * distance));
    // NaN (no surface, a degenerate light) or a rounding above 1: no bound.
    Vec2::new(if emission < 1.0 { emission } else { 1.0 }, if horizon < 1.0 { horizon.max(0.0) } else { 1.0 })
}

/// A light-BVH node's importance for `p` (surface normal `n`): [`importance`] of its bounds, and 0
/// for an interior node with `p` inside its bounding sphere when its box is [`out_of_reach`].
///
/// Inside a cluster's sphere [`importance`] drops its cone and surface factors and clamps the
/// distance at the radius of the largest light inside (clamping at the cluster's own size had
/// starved the cluster a point stands in), so a sparse cluster of small lights about `p` weighed
/// as if they all lit it: ceiling points amid an array of 5 mm LEDs, in their plane or just below
/// it, which none of them lights, gave the lamp that alone lit them a pmf down to 6·10⁻⁸ —
/// 10⁷ times the variance, and below 2⁻²⁴ never drawn, a black `U_N` where `U` is not (now 1 by
/// the walk, about 0.97 in [`LightSet`] with its uniform share: `raywave_host::lights`' tests).
/// A leaf weighs its light as [`light_importance`] does — by [`importance`] of the leaf's bounds
/// (the light's own, as raywave's builder stores them), and 0 where [`quad_lights_nothing`], the
/// shade stage's `U` is 0 — so that a box, which turns with the scene, never decides for one
/// light; a leaf whose light index is beyond `set`'s lights keeps [`importance`] of its bounds. A
/// leaf's cosine factors are bounded by its quad's [`quad_cosine_bounds`] as well, as in
/// [`light_importance`].
fn node_importance(set: &LightSet, node: &LightBvhNode, p: Vec3, n: Vec3) -> f32 {
    let bounds = &node.bounds;
    let mut cosines = Vec2::ONE;
    if node.is_leaf != 0 {
        if node.child_or_light < set.light_count() {
            cosines = quad_cosine_bounds(&set.lights[node.child_or_light as usize], p, n);
        }
    } else {
        let centre = (bounds.min.truncate() + bounds.max.truncate()) * 0.5;
        if (p - centre).length_squared() <= bounds.max.w * bounds.max.w && out_of_reach(bounds, p, n) {
            cosines = Vec2::ZERO;
        }
    }
    // One call of `importance` for every kind of node: rust-gpu inlines each call site.
    bounded_importance(bounds, p, n, cosines)
}

/// Whether no light inside the box of `bounds` can light `p` (surface normal `n`, need not be
/// normalised; 0 or NaN: no surface): every corner of the box on or below `p`'s tangent plane,
/// within 4 ε of the larger coordinate of `p` and the corner above it (each light then lies
/// below the horizon, or a rounding error above it, where `U` clips it away: a hit point lies a
/// few ulp off its triangle's plane, and ceiling points amid coplanar LEDs, 1 ulp above their
/// plane, had given the lamp that lit them a pmf of 6·10⁻⁸ again), or — for one-sided emitters
/// whose normals lie within `θo < π/2` of the axis and emit within `θe ≤ π/2` of them — `p` on or
/// behind each of them, `axis·(p − c) + sin θo·|p − c| ≤ 0` at every corner `c`. Both tested
/// functions are convex in the corner, so their largest value over the box is at a corner. A
/// comparison with a NaN (an infinite box) counts as within reach. Lights no more than that band
/// above the horizon may be culled: a large one keeps `U` of the band's order squared, but one
/// that lies wholly within the band loses `U` of the order band/distance — the band is 0.5 mm at
/// 10³ from the origin and 0.5 m at 10⁶ (a helper's study: a 4 cm lamp 2.6 m from a point 10⁶ out,
/// all of its `U`, got pmf 0 in the BVH; LEDs 6 ulp above a tilted horizon 10³ out, 4.6·10⁻⁵ of
/// it). The scan's and the leaves' test ([`quad_lights_nothing`]) has no band.
#[allow(clippy::neg_cmp_op_on_partial_ord)] // `!(x <= 0)`: a NaN is within reach
fn out_of_reach(bounds: &LightBounds, p: Vec3, n: Vec3) -> bool {
    let (lo, hi) = (bounds.min.truncate(), bounds.max.truncate());
    let axis = bounds.axis.truncate();
    let cos_o = bounds.cos_theta_o;
    let one_sided_cone = bounds.two_sided == 0 && cos_o > 0.0 && bounds.cos_theta_e >= 0.0;
    let sin_o = sin_from_cos(cos_o.min(1.0));
    let horizon_band = 4.0 * f32::EPSILON * n.length();
    let (mut above_horizon, mut in_front) = (false, false);
    let mut corner = 0;
    while corner < 8 {
        let c = Vec3::new(
            if corner & 1 != 0 { hi.x } else { lo.x },
            if corner & 2 != 0 { hi.y } else { lo.y },
            if corner & 4 != 0 { hi.z } else { lo.z },
        );
        let w = p - c;
        let scale = p.abs().max(c.abs()).max_element();
        above_horizon = above_horizon || !(n.dot(-w) <= horizon_band * scale);
        in_front = in_front || !(axis.dot(w) + sin_o * w.length() <= 0.0);
        corner += 1;
    }
    let surface = n.length_squared() > 0.0;
    (surface && !above_horizon) || (one_sided_cone && !in_front)
}

/// Uniform choice among `count` lights: index `⌊u·count⌋`, pmf `1/count`; [`LightChoice::NONE`]
/// when `count` is 0.
pub fn select_uniform(count: u32, u: f32) -> LightChoice {
    if count == 0 {
        return LightChoice::NONE;
    }
    let index = ((clamp_sample_1d(u) * count as f32) as u32).min(count - 1);
    LightChoice { index, pmf: 1.0 / count as f32 }
}

/// Pmf of [`select_uniform`]: `1/count` for a valid index, else 0.
pub fn uniform_pmf(count: u32, index: u32) -> f32 {
    if index < count {
        1.0 / count as f32
    } else {
        0.0
    }
}

/// The linear scan behind [`scan_choice`], over the first `count` lights: pass 0 sums their
/// [`light_importance`]s `I` in index order and counts the positive ones, `M`; pass 1 gives each
/// light the weight `(1 − share)·I + share·ΣI/M` if `I > 0`, else 0 — its importance mixed with a
/// uniform choice among the `M` lights, summing to `ΣI` — and walks them again to light `index`
/// if `index < count`, else to the first light of positive weight whose running sum passes
/// `u`·total (the last such light where rounding leaves the sum short of it), and returns that
/// light with its weight over the total as its pmf. With `share` 0 the weight is `I` exactly.
/// `None` where the total is 0 or NaN (the callers' uniform fallback). One call of
/// `light_importance` serves both passes and both callers, so that select and pmf agree bit for
/// bit and the shade kernel holds the light's bounds and importance once (rust-gpu inlines each
/// call site).
fn scan(lights: &[Light], count: u32, p: Vec3, n: Vec3, u: f32, index: u32, share: f32) -> Option<LightChoice> {
    // Without an index in range, pass 1 draws a light by `u`.
    let drawing = index >= count;
    let (mut total, mut target, mut running, mut spread) = (0.0, 0.0, 0.0, 0.0);
    let mut positive = 0u32;
    let mut last = LightChoice::NONE;
    let mut pass = 0;
    while pass < 2 {
        let mut i = 0;
        while i < count {
            let importance = light_importance(&lights[i as usize], p, n);
            let weight = if importance > 0.0 { (1.0 - share) * importance + spread } else { 0.0 };
            if pass == 0 {
                total += importance;
                if importance > 0.0 {
                    positive += 1;
                }
            } else if i == index {
                return Some(LightChoice { index: i, pmf: weight / total });
            } else if drawing && weight > 0.0 {
                last = LightChoice { index: i, pmf: weight / total };
                running += weight;
                if target < running {
                    return Some(last);
                }
            }
            i += 1;
        }
        if pass == 0 {
            if total.is_nan() || total <= 0.0 {
                return None;
            }
            target = clamp_sample_1d(u) * total;
            spread = share * total / positive as f32;
        }
        pass += 1;
    }
    Some(last)
}

/// The scan's choice over the first `count` lights (`count ≤ lights.len()`), with `share` of it
/// uniform among the lights of positive importance (see [`scan`]): light `index` with its pmf
/// when `index < count`, else the light drawn with `u`. With `share` 0 these are
/// [`importance_pmf`] and [`select_importance`].
fn scan_choice(lights: &[Light], count: u32, p: Vec3, n: Vec3, u: f32, index: u32, share: f32) -> LightChoice {
    if count == 1 {
        // What the scan returns for one light — with `share` 0 `I / I` = 1 exactly
        // ([`importance`] is finite), with a share 1 within rounding, or the uniform fallback's 1
        // when `I` = 0 — without evaluating `I` twice per sample.
        return LightChoice { index: 0, pmf: 1.0 };
    }
    match scan(lights, count, p, n, u, index, share) {
        Some(choice) => choice,
        None if index < count => LightChoice { index, pmf: uniform_pmf(count, index) },
        None => select_uniform(count, u),
    }
}

/// Chooses a light with probability proportional to its [`light_importance`] at `p` (normal `n`,
/// or 0) by a linear scan: the total, then the inverse CDF at `u`. Falls back to
/// [`select_uniform`] when every importance is 0. [`LightChoice::NONE`] for an empty list.
pub fn select_importance(lights: &[Light], p: Vec3, n: Vec3, u: f32) -> LightChoice {
    let count = lights.len() as u32;
    scan_choice(lights, count, p, n, u, count, 0.0)
}

/// Probability that [`select_importance`] chooses light `index` at `p`, `n`: `I_index / Σ I`, or
/// `1/N` in the all-zero fallback; 0 for an index out of range.
pub fn importance_pmf(lights: &[Light], p: Vec3, n: Vec3, index: u32) -> f32 {
    let count = lights.len() as u32;
    if index < count {
        scan_choice(lights, count, p, n, 0.0, index, 0.0).pmf
    } else {
        0.0
    }
}

/// Probabilities of taking the first and the second child of an interior node (children `first`,
/// `second`): `I₀ / (I₀ + I₁)` and `I₁ / (I₀ + I₁)` of their [`node_importance`]s, or 1/2 each
/// when both are 0. The second is not `1 − p₀`, which rounds to 0 when `I₁ < 2⁻²⁵ I₀` and had
/// given every light under a dim second child pmf 0, though it was the first child's positive
/// share when the children were the other way round.
fn child_probabilities(set: &LightSet, first: u32, second: u32, p: Vec3, n: Vec3) -> (f32, f32) {
    // Both children by one call in a loop, so that the kernel holds `node_importance` once.
    let (children, mut weights) = ([first, second], [0.0f32; 2]);
    let mut c = 0;
    while c < 2 {
        weights[c] = node_importance(set, &set.nodes[children[c] as usize], p, n);
        c += 1;
    }
    let [i0, i1] = weights;
    let sum = i0 + i1;
    if sum > 0.0 {
        (i0 / sum, i1 / sum)
    } else {
        (0.5, 0.5)
    }
}

/// [`select_bvh`] over `set`'s nodes.
fn bvh_select(set: &LightSet, p: Vec3, n: Vec3, u: f32) -> LightChoice {
    bvh_descend(set, p, n, u, false, 0)
}

/// [`bvh_pmf`] over `set`'s nodes.
fn bvh_light_pmf(set: &LightSet, p: Vec3, n: Vec3, light: u32) -> f32 {
    if set.node_count() == 0 || light as usize >= set.trails.len() {
        return 0.0;
    }
    let reached = bvh_descend(set, p, n, 0.0, true, set.trails[light as usize]);
    if reached.index == light {
        reached.pmf
    } else {
        0.0
    }
}

/// The descent of `set`'s BVH from the root to a leaf: at each interior node the first child with
/// probability `I₀/(I₀ + I₁)` — taken by the sample `u`, rescaled to `[0, 1)` for the next level,
/// or, with `follow_trail`, by `trail`'s bit for the level (`u` then unused) — the pmf the
/// product of the probabilities of the branches taken. One loop for both, so that a kernel
/// choosing either way holds it once. [`LightChoice::NONE`] for an empty or malformed tree
/// (deeper than [`MAX_BVH_DEPTH`] or a child index out of range).
fn bvh_descend(set: &LightSet, p: Vec3, n: Vec3, u: f32, follow_trail: bool, trail: u32) -> LightChoice {
    let (nodes, count) = (set.nodes, set.node_count());
    if count == 0 {
        return LightChoice::NONE;
    }
    let mut u = clamp_sample_1d(u);
    let mut node = 0u32;
    let mut pmf = 1.0f32;
    let mut depth = 0u32;
    while depth <= MAX_BVH_DEPTH {
        let current = nodes[node as usize];
        if current.is_leaf != 0 {
            return LightChoice { index: current.child_or_light, pmf };
        }
        let first = node + 1;
        let second = current.child_or_light;
        if depth == MAX_BVH_DEPTH || first >= count || second >= count {
            break;
        }
        let (p_first, p_second) = child_probabilities(set, first, second, p, n);
        let take_first = if follow_trail { (trail >> depth) & 1 == 0 } else { u < p_first };
        if take_first {
            u = (u / p_first).min(ONE_MINUS_EPSILON);
            pmf *= p_first;
            node = first;
        } else {
            u = ((u - p_first) / (1.0 - p_first)).min(ONE_MINUS_EPSILON);
            pmf *= p_second;
            node = second;
        }
        depth += 1;
    }
    LightChoice::NONE
}

/// Chooses one of `lights` by stochastic descent of their light BVH `nodes` (layout in the module
/// docs): at each interior node the first child with probability `I₀/(I₀ + I₁)` (1/2 if both are
/// 0), `u` rescaled to `[0, 1)` for the next level, the pmf the product of the branch
/// probabilities; a leaf weighs its light by [`light_importance`].
/// [`LightChoice::NONE`] for an empty or malformed tree. A one-node tree returns its light with
/// pmf 1. With 24-bit samples, the decisions below depth ≈ 20 reuse few remaining bits.
pub fn select_bvh(lights: &[Light], nodes: &[LightBvhNode], p: Vec3, n: Vec3, u: f32) -> LightChoice {
    bvh_select(&LightSet::new(lights, nodes, &[]), p, n, u)
}

/// Probability that [`select_bvh`] chooses `light` at `p`, `n`: the product of the branch
/// probabilities along `trails[light]`, bit-identical to the pmf [`select_bvh`] returns for it;
/// 0 when the trail does not end at that light's leaf (a light left out of the BVH) or `light` is
/// out of range of `trails`.
pub fn bvh_pmf(lights: &[Light], nodes: &[LightBvhNode], trails: &[u32], p: Vec3, n: Vec3, light: u32) -> f32 {
    bvh_light_pmf(&LightSet::new(lights, nodes, trails), p, n, light)
}

/// Share of [`LightSet::select`]'s choices made uniformly rather than by importance: with a BVH
/// among all `N` lights, `pmf = α/N + (1 − α)·bvh_pmf`; in the linear scan among the `M` lights
/// of positive importance, `pmf = α/M + (1 − α)·importance_pmf` for those and 0 for the rest,
/// which light nothing there (with `M` = 0, the uniform fallback's `1/N` each). The scan sees
/// every importance; the walk would have to visit every leaf to count them. Importance is a
/// bound, and a loose one can starve the light that lights `p`:
/// - the walk's branch probabilities come from cluster bounds, which cannot see that every light
///   under a node lights nothing at `p` (behind one-sided lamps, below the horizon), so such a
///   node kept its share and the light that did light `p` got a pmf far below its share of `U` —
///   3.5·10⁻⁹ for the only lit light of 4, below 2⁻²⁴, never drawn (a helper's study: in
///   adversarial sets of more than 8 lights, 4–15 % of lit points had a light's pmf below 10⁻³
///   of its share);
/// - in the scan, at a point close to a lamp's plane (within about 1 cm for 5 cm lamps) whose
///   foot lies on the lamp, that lamp's cosine bounds are 1 and its distance is clamped at its
///   radius, though only a sliver of it may be above the point's horizon: a neighbour holding
///   0.26 % of `U` got pmf 2.5·10⁻⁹, never drawn (with a second neighbour drawn less often than
///   its pmf said, the choice left `U_N` 0.5 % low; in one row of 30 m lamps three lamps with
///   58 % of the stage's `U` were never drawn either, where that `U` is itself at its `f32`
///   floor; a second helper's study, 2026-11-30).
///
/// With the mixture every light that can light `p` has pmf ≥ α/N (≥ 2⁻²⁴ for
/// N ≤ α·2²⁴ ≈ 5·10⁵); the selection's second moment `Σ s²/pmf` on
/// `builtin:cornell-light-grid` went 1.078 → 1.083 in the first study. A single light keeps
/// pmf 1. A power of two, so that the walk's sample loses no bits to the share: `u − 1/32` is
/// exact, and the division by 31/32 that rescales it rounds but stays one to one (its steps,
/// 1.03·2⁻²⁴, exceed the grid's).
pub const UNIFORM_SHARE: f32 = 1.0 / 32.0;

/// [`UNIFORM_SHARE`]'s mixture of the uniform pmf over `count` lights and the walk's `pmf`.
fn mixed_pmf(count: u32, pmf: f32) -> f32 {
    UNIFORM_SHARE / count as f32 + (1.0 - UNIFORM_SHARE) * pmf
}

/// A scene's lights as light selection reads them: the light list and, for scenes with many
/// lights, their BVH. The counts, not the slice lengths, say what is valid, because a GPU binding
/// cannot be empty (an unused buffer holds one dummy element).
#[derive(Copy, Clone)]
pub struct LightSet<'a> {
    /// The lights.
    pub lights: &'a [Light],
    /// Light BVH nodes (node 0 the root); ignored when `node_count` is 0.
    pub nodes: &'a [LightBvhNode],
    /// Per light, its trail in the BVH; ignored when `node_count` is 0.
    pub trails: &'a [u32],
    /// Number of valid lights in `lights`.
    pub light_count: u32,
    /// Number of valid nodes in `nodes`: 0 selects the linear importance scan.
    pub node_count: u32,
}

impl<'a> LightSet<'a> {
    /// A light set whose counts are the slice lengths (an empty `nodes` means no BVH).
    pub fn new(lights: &'a [Light], nodes: &'a [LightBvhNode], trails: &'a [u32]) -> Self {
        LightSet { lights, nodes, trails, light_count: lights.len() as u32, node_count: nodes.len() as u32 }
    }

    fn light_count(&self) -> u32 {
        self.light_count.min(self.lights.len() as u32)
    }

    /// Number of lights in the set.
    pub fn len(&self) -> u32 {
        self.light_count()
    }

    /// Whether the set has no light.
    pub fn is_empty(&self) -> bool {
        self.light_count() == 0
    }

    fn node_count(&self) -> u32 {
        self.node_count.min(self.nodes.len() as u32)
    }

    /// Chooses a light for `p`, `n` with the 2-D sample `u`, by importance mixed with a uniform
    /// choice ([`UNIFORM_SHARE`]): by the BVH when there is one — uniform among all the lights —
    /// else by the linear scan — uniform among the lights of positive importance.
    /// [`LightChoice::NONE`] when there is no light to choose. `u.x` chooses between the share
    /// and the walk, and walks; `u.y` picks the BVH's uniform light with all its 24 bits, so that
    /// each of `N` lights is drawn by the share within `N/2²⁴` of its `α/N` (`u.x` rescaled from
    /// below the share holds only 2¹⁹ values: each light drawn a whole number of them, up to
    /// `N/2¹⁹` off, +14 % at 10⁵ lights).
    pub fn select(&self, p: Vec3, n: Vec3, u: Vec2) -> LightChoice {
        let lights = self.light_count();
        if lights == 0 {
            return LightChoice::NONE;
        }
        if self.node_count() > 0 {
            // A share of the choices uniform among all the lights — one descent along the chosen
            // light's trail gives its walk pmf — and the rest by the walk, with the sample
            // rescaled to [0, 1) (one to one, [`UNIFORM_SHARE`]).
            let (u, u_pick) = (clamp_sample_1d(u.x), u.y);
            let uniform = u < UNIFORM_SHARE;
            let picked = select_uniform(lights, u_pick).index;
            let trail = if uniform && (picked as usize) < self.trails.len() { self.trails[picked as usize] } else { 0 };
            let rescaled = ((u - UNIFORM_SHARE) / (1.0 - UNIFORM_SHARE)).min(ONE_MINUS_EPSILON);
            let reached = bvh_descend(self, p, n, rescaled, uniform, trail);
            let index = if uniform { picked } else { reached.index };
            // A light left out of the tree (zero power) is reached by no walk.
            let walked = if reached.index == index { reached.pmf } else { 0.0 };
            if index < lights {
                LightChoice { index, pmf: mixed_pmf(lights, walked) }
            } else {
                LightChoice::NONE
            }
        } else {
            scan_choice(self.lights, lights, p, n, u.x, lights, UNIFORM_SHARE)
        }
    }

    /// Probability that [`LightSet::select`] chooses light `index` at `p`, `n`.
    pub fn pmf(&self, p: Vec3, n: Vec3, index: u32) -> f32 {
        let lights = self.light_count();
        if index >= lights {
            return 0.0;
        }
        if self.node_count() > 0 {
            mixed_pmf(lights, bvh_light_pmf(self, p, n, index))
        } else {
            scan_choice(self.lights, lights, p, n, 0.0, index, UNIFORM_SHARE).pmf
        }
    }
}

/// A point on `light`'s surface, uniform by area, with its outward unit normal (quads: the front
/// normal `edge_u × edge_v`), from the 2-D sample `u`. Independent of any receiver, it is what a
/// test oracle or a photon emitter needs.
pub fn uniform_light_point(light: &Light, u: Vec2) -> (Vec3, Vec3) {
    let corner = light.position.truncate();
    if light.kind == light_kind::SPHERE {
        let d = super::warp::sample_uniform_sphere(u);
        (corner + d * light.position.w, d)
    } else {
        let (eu, ev) = (light.edge_u.truncate(), light.edge_v.truncate());
        let u = clamp_sample(u);
        (corner + u.x * eu + u.y * ev, eu.cross(ev).normalize_or(Vec3::Z))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hash::{pcg3d, unit_float, CounterRng};
    use glam::UVec3;
    use std::{vec, vec::Vec};

    fn random_light(rng: &mut CounterRng) -> Light {
        let radiance = Vec3::new(rng.range(0.1, 5.0), rng.range(0.1, 5.0), rng.range(0.1, 5.0));
        let kind = rng.next_f32();
        if kind < 0.34 {
            Light::sphere(rng.vec3(-3.0, 3.0), rng.range(0.05, 1.0), radiance)
        } else {
            let eu = rng.unit_vec3() * rng.range(0.1, 2.0);
            let ev = eu.cross(rng.unit_vec3()).normalize_or_zero() * rng.range(0.1, 2.0);
            Light::quad(rng.vec3(-3.0, 3.0), eu, ev, radiance, kind > 0.67)
        }
    }

    /// Points on the light with their outward unit normal (quads: front normal).
    fn light_points(light: &Light, rng: &mut CounterRng, count: usize) -> Vec<(Vec3, Vec3)> {
        (0..count).map(|_| uniform_light_point(light, Vec2::new(rng.next_f32(), rng.next_f32()))).collect()
    }

    /// Whether some sampled point of `light` sends light to `p` with cosines above `margin` at the
    /// emitter and (for `n ≠ 0`) at the receiver: a clearly positive unoccluded contribution.
    fn contributes(light: &Light, points: &[(Vec3, Vec3)], p: Vec3, n: Vec3, margin: f32) -> bool {
        points.iter().any(|&(x, nx)| {
            let w = (p - x).normalize_or_zero();
            let emit = if light.kind == light_kind::QUAD && light.two_sided != 0 { nx.dot(w).abs() } else { nx.dot(w) };
            emit > margin && (n == Vec3::ZERO || n.dot(-w) > margin)
        })
    }

    #[test]
    fn bounds_of_a_sphere_and_quads() {
        let s = light_bounds(&Light::sphere(Vec3::new(1.0, 2.0, 3.0), 0.5, Vec3::ONE));
        assert_eq!(s.min.truncate(), Vec3::new(0.5, 1.5, 2.5));
        assert_eq!(s.max.truncate(), Vec3::new(1.5, 2.5, 3.5));
        let area = 4.0 * core::f32::consts::PI * 0.25;
        assert!((s.phi - core::f32::consts::PI * area).abs() < 1e-5 * s.phi, "{}", s.phi);
        assert_eq!((s.cos_theta_o, s.cos_theta_e, s.two_sided), (-1.0, 0.0, 0));
        // The sphere about the box's centre is the light's own, not the box's (√3 times wider).
        assert_eq!((s.min.w, s.max.w), (0.5, 0.5));

        let eu = Vec3::new(2.0, 0.0, 0.0);
        let ev = Vec3::new(0.0, 3.0, 0.0);
        let green = Vec3::new(0.0, 1.0, 0.0);
        let q = light_bounds(&Light::quad(Vec3::new(-1.0, -1.0, 4.0), eu, ev, green, false));
        assert_eq!(q.min.truncate(), Vec3::new(-1.0, -1.0, 4.0));
        assert_eq!(q.max.truncate(), Vec3::new(1.0, 2.0, 4.0));
        assert_eq!(q.axis.truncate(), Vec3::Z);
        assert!((q.phi - core::f32::consts::PI * 6.0 * 0.7152).abs() < 1e-5);
        assert_eq!((q.cos_theta_o, q.cos_theta_e, q.two_sided), (1.0, 0.0, 0));
        assert_eq!((q.min.w, q.max.w), (13f32.sqrt() / 2.0, 13f32.sqrt() / 2.0));
        // Turned off the axes, a quad's box grows but its sphere does not.
        let turn = glam::Quat::from_rotation_z(0.6) * glam::Quat::from_rotation_x(0.9);
        let turned = light_bounds(&Light::quad(turn * Vec3::new(-1.0, -1.0, 4.0), turn * eu, turn * ev, green, false));
        assert!(0.5 * (turned.max - turned.min).truncate().length() > 1.2 * q.max.w);
        assert!((turned.max.w - q.max.w).abs() < 1e-6 && turned.min.w == turned.max.w, "{turned:?}");
        let q2 = light_bounds(&Light::quad(Vec3::new(-1.0, -1.0, 4.0), eu, ev, green, true));
        assert_eq!((q2.phi, q2.two_sided), (2.0 * q.phi, 1));

        // Degenerate and unknown lights have zero power.
        assert_eq!(light_bounds(&Light::sphere(Vec3::ZERO, 0.0, Vec3::ONE)).phi, 0.0);
        assert_eq!(light_bounds(&Light::quad(Vec3::ZERO, eu, eu, Vec3::ONE, false)).phi, 0.0);
        let mut unknown = Light::sphere(Vec3::ZERO, 1.0, Vec3::ONE);
        unknown.kind = 7;
        assert_eq!(light_bounds(&unknown).phi, 0.0);
        assert_eq!(light_bounds(&Light::sphere(Vec3::ZERO, 1.0, Vec3::NAN)).phi, 0.0);
    }

    #[test]
    fn importance_is_conservative() {
        // A light that clearly contributes (cosines > 1e-4 at both ends for some sampled point)
        // never gets importance 0; count both outcomes so the test is known to exercise them.
        let mut rng = CounterRng::new(1);
        let (mut contributing, mut culled) = (0, 0);
        for case in 0..20_000 {
            let light = random_light(&mut rng);
            let p = rng.vec3(-5.0, 5.0);
            let n = if case % 5 == 0 { Vec3::ZERO } else { rng.unit_vec3() };
            let points = light_points(&light, &mut rng, 48);
            let value = light_importance(&light, p, n);
            assert!(value.is_finite() && value >= 0.0);
            if contributes(&light, &points, p, n, 1e-4) {
                contributing += 1;
                assert!(value > 0.0, "case {case}: {light:?} at p={p} n={n} contributes but has importance 0");
            } else if value == 0.0 {
                culled += 1;
            }
        }
        assert!(contributing > 8_000 && culled > 1_000, "contributing {contributing}, culled {culled}");
    }

    #[test]
    fn importance_falls_off_with_distance_and_angle() {
        let light = light_bounds(&Light::quad(Vec3::new(-0.5, -0.5, 0.0), Vec3::X, Vec3::Y, Vec3::ONE, false));
        let near = importance(&light, Vec3::new(0.0, 0.0, 2.0), Vec3::ZERO);
        let far = importance(&light, Vec3::new(0.0, 0.0, 20.0), Vec3::ZERO);
        assert!(near > 50.0 * far, "{near} vs {far}");
        // Behind a one-sided quad: nothing; two-sided: as in front.
        assert_eq!(importance(&light, Vec3::new(0.0, 0.0, -2.0), Vec3::ZERO), 0.0);
        let two = light_bounds(&Light::quad(Vec3::new(-0.5, -0.5, 0.0), Vec3::X, Vec3::Y, Vec3::ONE, true));
        assert_eq!(
            importance(&two, Vec3::new(0.0, 0.0, -2.0), Vec3::ZERO),
            importance(&two, Vec3::new(0.0, 0.0, 2.0), Vec3::ZERO)
        );
        // A surface facing away from the light: nothing; facing it: the unsurfaced value.
        assert_eq!(importance(&light, Vec3::new(0.0, 0.0, 2.0), Vec3::Z), 0.0);
        assert_eq!(importance(&light, Vec3::new(0.0, 0.0, 2.0), -Vec3::Z), near);
        // An unnormalised normal gives the same value as the normalised one.
        let slanted = Vec3::new(1.0, 0.0, -1.0);
        let p = Vec3::new(0.0, 0.0, 2.0);
        assert!(
            (importance(&light, p, slanted * 7.0) - importance(&light, p, slanted.normalize())).abs() < 1e-5 * near
        );
    }

    #[test]
    fn importance_hard_cases_are_finite() {
        let sphere = Light::sphere(Vec3::new(1.0, 1.0, 1.0), 0.5, Vec3::ONE);
        let quad = Light::quad(Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE, false);
        let s = light_bounds(&sphere);
        // p at the sphere's centre, on its surface (both reached); p on the quad and on its plane
        // beyond its sphere (a quad lights nothing in its plane, the shade stage's own test), and
        // just in front of it (reached).
        for (light, p, reached) in [
            (sphere, Vec3::ONE, true),
            (sphere, Vec3::new(1.5, 1.0, 1.0), true),
            (quad, Vec3::new(0.5, 0.5, 0.0), false),
            (quad, Vec3::new(0.1, 0.2, 0.0), false),
            (quad, Vec3::new(0.5, 0.5, 1.0e-3), true),
            (quad, Vec3::new(3.0, 0.5, 0.0), false),
        ] {
            for n in [Vec3::ZERO, Vec3::Z, -Vec3::Z, Vec3::X] {
                let value = light_importance(&light, p, n);
                assert!(value.is_finite() && value >= 0.0, "{p} {n}: {value}");
            }
            assert_eq!(light_importance(&light, p, Vec3::ZERO) > 0.0, reached, "{p}");
        }
        // Zero-size bounds with power, at their own point; zero power; NaN and infinite inputs.
        let mut point = s;
        point.min = point.max;
        assert!(importance(&point, point.max.truncate(), Vec3::ZERO).is_finite());
        assert!(importance(&point, point.max.truncate() + Vec3::X, Vec3::X).is_finite());
        let mut dark = s;
        dark.phi = 0.0;
        assert_eq!(importance(&dark, Vec3::ZERO, Vec3::ZERO), 0.0);
        assert_eq!(importance(&s, Vec3::NAN, Vec3::ZERO), 0.0);
        assert_eq!(importance(&s, Vec3::INFINITY, Vec3::ZERO), 0.0);
        assert!(importance(&s, Vec3::ZERO, Vec3::NAN) > 0.0);
        let mut huge = s;
        huge.phi = f32::MAX;
        assert_eq!(importance(&huge, Vec3::ONE, Vec3::ZERO), MAX_IMPORTANCE);
    }

    /// Points on a ceiling lamp and beside it in its plane, inside its bounding sphere, which it
    /// does not light, and a wall lamp that does: the scan draws the wall lamp every time. Inside
    /// the sphere the bound had weighed the ceiling lamp as if it filled their hemisphere (the
    /// wall lamp's pmf 0.012).
    #[test]
    fn a_quad_weighs_nothing_in_its_own_plane() {
        let ceiling = Light::quad(Vec3::new(-0.25, 3.0, -0.25), Vec3::X * 0.5, Vec3::Z * 0.5, Vec3::splat(5.0), false);
        let wall = Light::quad(Vec3::new(-2.0, 1.75, -0.25), Vec3::Y * 0.5, Vec3::Z * 0.5, Vec3::splat(5.0), false);
        let lights = [ceiling, wall];
        let emits = |l: &Light| l.edge_u.truncate().cross(l.edge_v.truncate());
        let (down, right) = (emits(&ceiling), emits(&wall));
        assert!(down.y < 0.0 && right.x > 0.0, "the ceiling lamp emits down, the wall lamp towards +x");
        for p in [Vec3::new(0.1, 3.0, 0.05), Vec3::new(0.3, 3.0, 0.1), Vec3::new(-0.2, 3.0, -0.2)] {
            for n in [-Vec3::Y, Vec3::ZERO] {
                let wall_pmf = importance_pmf(&lights, p, n, 1);
                std::println!("{p} {n}: the wall lamp's pmf {wall_pmf}");
                assert_eq!(wall_pmf, 1.0, "{p} {n}");
            }
        }
        // A centimetre below the ceiling lamp, facing up (or no surface), the lamp lights the
        // point and dominates again.
        for n in [Vec3::Y, Vec3::ZERO] {
            assert!(importance_pmf(&lights, Vec3::new(0.1, 2.99, 0.05), n, 0) > 0.9, "{n}");
        }
    }

    /// Where the shade stage's `U` of a lamp is not 0, selection gives it a positive pmf: at points
    /// a few µm in front of a 10 m lamp with a corner at the origin (a band the cull had scaled by
    /// the lamp's centre, 5 m out, not by the stage's coordinates: pmf 0 where the lamp filled the
    /// hemisphere), and just below a 1 m lamp from a normal tilted 2·10⁻⁴ rad towards it (a tilt
    /// the disc test had lost to cancellation: pmf 0). A second lamp takes the rest.
    #[test]
    fn a_lamp_whose_u_is_not_zero_keeps_its_pmf() {
        let floor_lamp = Light::quad(Vec3::ZERO, Vec3::Z * 10.0, Vec3::X * 10.0, Vec3::ONE, false);
        let other = Light::quad(Vec3::new(3.0, -5.0, 3.0), Vec3::Z, Vec3::X, Vec3::ONE, false);
        for h in [1.0e-7, 1.0e-6, 2.0e-6, 3.0e-6] {
            let p = Vec3::new(0.1, h, 0.1);
            assert!(quad_faces(&floor_lamp, p), "{h}: the stage lights p");
            let pmf = importance_pmf(&[floor_lamp, other], p, -Vec3::Y, 0);
            assert!(pmf > 0.9, "{h}: the lamp's pmf {pmf}");
        }
        let ceiling_lamp = Light::quad(Vec3::new(-0.5, 3.0, -0.5), Vec3::X, Vec3::Z, Vec3::ONE, false);
        let other = Light::quad(Vec3::new(3.0, 3.5, -0.5), Vec3::X, Vec3::Z, Vec3::ONE, false);
        let (p, n) = (Vec3::new(0.3, 3.0 - 5.0e-5, 0.0), Vec3::new(2.0e-4, 1.0, 0.0).normalize());
        assert!(quad_faces(&ceiling_lamp, p));
        let pmf = importance_pmf(&[ceiling_lamp, other], p, n, 0);
        assert!(pmf > 0.9, "the ceiling lamp's pmf {pmf}");
    }

    /// A 1 cm lamp 10⁶ out, smaller than the spacing of its coordinates (0.0625): its corners
    /// rounded to one point, so its bounding sphere had radius 0 about a centre 1 cm off, which
    /// the point's horizon cut, and its importance was 0 where the shade stage lit the point with
    /// it (`U` 5.2·10⁻⁷, 45 % of the point's; a helper's study). Its sphere now holds its corners
    /// as the stage forms them from `corner − p`, and its pmf is 0.988 (the other lamp's `U` is
    /// 55 %, its pmf 0.012).
    #[test]
    fn a_lamp_smaller_than_the_spacing_of_its_coordinates_keeps_its_pmf() {
        let small = Light::quad(
            Vec3::new(999999.4, 1000002.6, 1000002.2),
            Vec3::new(0.0, 0.0, 0.010630406),
            Vec3::new(-0.010630406, 0.0, 0.0),
            Vec3::splat(15768.981),
            false,
        );
        let other = Light::quad(
            Vec3::new(1000002.94, 999999.25, 999997.4),
            Vec3::new(-0.05061938, 0.09522605, 0.12708),
            Vec3::new(-0.029864777, 0.011556857, -0.020555953),
            Vec3::splat(0.072254606),
            false,
        );
        let (p, n) = (Vec3::new(999999.4, 1000000.7, 1000002.2), Vec3::new(0.9929158, -0.00020129842, 0.11882049));
        assert!(!quad_lights_nothing(&small, p, n), "the stage lights p with the small lamp");
        let pmf = importance_pmf(&[small, other], p, n, 0);
        assert!(pmf > 0.5, "the small lamp's pmf {pmf}");
        // Its sphere holds its corners relative to its own corner (f64).
        let b = light_bounds(&small);
        let centre = (b.min.truncate() + b.max.truncate()).as_dvec3() * 0.5;
        let (corner, eu, ev) = (small.position.truncate().as_dvec3(), small.edge_u.truncate(), small.edge_v.truncate());
        for rel in [Vec3::ZERO, eu, ev, eu + ev] {
            let distance = (corner + rel.as_dvec3() - centre).length();
            assert!(distance <= f64::from(b.max.w) * (1.0 + 1e-6), "{distance} beyond {}", b.max.w);
        }
    }

    /// An 8 m lamp seen nearly edge-on, from a point 19 µm in front of its plane and 4 m beside
    /// it — outside its bounding sphere, where `sin θb` = 0.65 of its cone bound let it weigh as
    /// if it faced the point (its `U` is 0 there): the lamp that alone lights the point got pmf
    /// 3.0·10⁻⁸, below 2⁻²⁴, never drawn (`U_N` 0 where `U` is not; a helper's study), in the
    /// scan and in a BVH leaf alike. The quad's own cosine bound, `h / D`, gives it 0.998.
    #[test]
    fn a_lamp_seen_edge_on_does_not_starve_the_lamp_that_lights_the_point() {
        let edge_on = Light::quad(
            Vec3::new(4.0800004, 1.8405485, -0.010178082),
            Vec3::new(-0.019834992, -7.8155446, 2.1256008),
            Vec3::new(-8.098079, -0.019834993, -0.1484976),
            Vec3::splat(751.2568),
            false,
        );
        let lit = Light::quad(
            Vec3::new(2.0071056, -2.9293492, 2.2894611),
            Vec3::new(-0.0030784165, 0.041051235, 0.015199469),
            Vec3::new(-0.039869785, 0.0030278135, -0.016252626),
            Vec3::splat(4.6057),
            false,
        );
        let (p, n) = (Vec3::new(-2.4352605, -10.192575, 3.139228), Vec3::new(-0.018334247, 0.26243722, 0.9647749));
        let lights = [edge_on, lit];
        assert!(quad_faces(&edge_on, p), "the edge-on lamp keeps a positive pmf: p is in front of it");
        let scanned = importance_pmf(&lights, p, n, 1);
        assert!(scanned > 0.5, "scan: the lit lamp's pmf {scanned}");
        assert!(importance_pmf(&lights, p, n, 0) > 0.0);
        let (a, b) = (leaf_node(&lights, 0).bounds, leaf_node(&lights, 1).bounds);
        let root = union_bounds(&a, &b, Vec3::Z, -1.0);
        let nodes = [
            LightBvhNode { bounds: root, child_or_light: 2, is_leaf: 0, padding: [0; 2] },
            leaf_node(&lights, 0),
            leaf_node(&lights, 1),
        ];
        let walked = bvh_pmf(&lights, &nodes, &[0b0, 0b1], p, n, 1);
        assert!(walked > 0.5, "BVH: the lit lamp's pmf {walked}");
    }

    /// A 20 m ceiling lamp of which the point's horizon leaves a 0.4 m strip 10 m away, and a
    /// 10 cm lamp facing the point 1.4 m off, which gives 97 % of its `U` (the shade stage's form
    /// factors): the small lamp's pmf was 2.4·10⁻³ (the big lamp's sphere bounds no horizon),
    /// and is 0.057 with the quad's own bound `max_c n̂·(c − p) / D`.
    #[test]
    fn a_lamp_mostly_below_the_horizon_weighs_by_what_is_above_it() {
        let lamp = Light::quad(
            Vec3::new(-10.0, 4.0, -10.0),
            Vec3::new(20.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 20.0),
            Vec3::ONE,
            false,
        );
        let (eu, ev) = (Vec3::new(0.0, 0.0, 0.1), Vec3::new(0.0707, 0.0707, 0.0));
        let small = Light::quad(Vec3::new(1.0, -1.0, 0.0) - 0.5 * (eu + ev), eu, ev, Vec3::ONE, false);
        let n = Vec3::new(1.0, -2.4, 0.0).normalize();
        let pmf = importance_pmf(&[lamp, small], Vec3::ZERO, n, 1);
        assert!(pmf > 0.02, "the small lamp's pmf {pmf}");
    }

    /// [`quad_cosine_bounds`] bounds the cosines at the light and at the surface of every sampled
    /// direction between a random quad and a random point (1 + 10⁻⁴ for rounding), both are
    /// positive wherever a sampled direction clearly lights the point, and both are 0 where
    /// [`quad_lights_nothing`]; each case is counted.
    #[test]
    fn quad_cosine_bounds_bound_every_cosine() {
        let mut rng = CounterRng::new(93);
        let (mut tight, mut lit, mut nothing) = (0, 0, 0);
        for case in 0..5_000 {
            let mut light = random_light(&mut rng);
            if light.kind != light_kind::QUAD {
                light =
                    Light::quad(rng.vec3(-2.0, 2.0), rng.unit_vec3(), rng.unit_vec3() * 0.3, Vec3::ONE, case % 2 == 0);
            }
            let p = rng.vec3(-4.0, 4.0);
            let n = if case % 5 == 0 { Vec3::ZERO } else { rng.unit_vec3() * rng.range(0.5, 2.0) };
            let bound = quad_cosine_bounds(&light, p, n);
            if quad_lights_nothing(&light, p, n) {
                assert_eq!(bound, Vec2::ZERO, "case {case}: a light that lights nothing");
                nothing += 1;
                continue;
            }
            assert!(bound.x > 0.0 && bound.x <= 1.0 && (0.0..=1.0).contains(&bound.y), "{bound}");
            tight += usize::from(bound.x < 0.5 || bound.y < 0.5);
            let points = light_points(&light, &mut rng, 48);
            for &(x, nx) in &points {
                let w = (p - x).normalize();
                let emit = nx.dot(w).abs();
                assert!(emit <= bound.x * (1.0 + 1e-4) + 1e-6, "case {case}: emission {emit} > {}", bound.x);
                if n != Vec3::ZERO {
                    let receive = n.normalize().dot(-w);
                    assert!(receive <= bound.y * (1.0 + 1e-4) + 1e-6, "case {case}: horizon {receive} > {}", bound.y);
                }
            }
            if contributes(&light, &points, p, n, 1e-4) {
                lit += 1;
                assert!(bound.x > 0.0 && bound.y > 0.0, "case {case}: {bound}");
            }
        }
        assert!(tight > 1_000 && lit > 1_000 && nothing > 500, "tight {tight}, lit {lit}, nothing {nothing}");
    }

    /// A dim light beside a bright one keeps its positive pmf in the BVH whichever child it is, as
    /// in the scan: as the second child, `1 − p₀` had rounded to 0 for it.
    #[test]
    fn a_dim_second_child_keeps_its_pmf() {
        let bright = Light::quad(Vec3::new(-2.0, 2.0, -0.5), Vec3::X, Vec3::Z, Vec3::ONE, false);
        let dim = Light::quad(Vec3::new(1.0, 2.0, -0.5), Vec3::X, Vec3::Z, Vec3::splat(1.0e-8), false);
        let (p, n) = (Vec3::ZERO, Vec3::Y);
        let scanned = importance_pmf(&[bright, dim], p, n, 1);
        assert!(scanned > 0.0 && scanned < 1.0e-7, "{scanned}");
        for lights in [[bright, dim], [dim, bright]] {
            let leaf = |k: u32| leaf_node(&lights, k);
            let (a, b) = (leaf(0).bounds, leaf(1).bounds);
            let (lo, hi) = (a.min.min(b.min).truncate(), a.max.max(b.max).truncate());
            let root = LightBounds {
                min: lo.extend(a.min.w.max(b.min.w)),
                max: hi.extend(0.5 * (hi - lo).length()),
                phi: a.phi + b.phi,
                cos_theta_o: -1.0,
                ..a
            };
            let nodes =
                [LightBvhNode { bounds: root, child_or_light: 2, is_leaf: 0, padding: [0; 2] }, leaf(0), leaf(1)];
            let index = if lights[0].radiance == dim.radiance { 0 } else { 1 };
            let pmf = bvh_pmf(&lights, &nodes, &[0b0, 0b1], p, n, index);
            assert!((pmf - scanned).abs() <= 1.0e-6 * scanned, "dim light {index}: pmf {pmf}, scan {scanned}");
        }
    }

    #[test]
    fn uniform_selection() {
        assert_eq!(select_uniform(0, 0.5), LightChoice::NONE);
        assert!(!LightChoice::NONE.is_valid());
        assert_eq!(select_uniform(4, 0.0), LightChoice { index: 0, pmf: 0.25 });
        assert_eq!(select_uniform(4, 0.99), LightChoice { index: 3, pmf: 0.25 });
        assert_eq!(select_uniform(4, 1.0).index, 3);
        assert_eq!(select_uniform(4, f32::NAN).index, 0);
        assert!(select_uniform(u32::MAX, ONE_MINUS_EPSILON).index < u32::MAX);
        assert_eq!((uniform_pmf(4, 3), uniform_pmf(4, 4)), (0.25, 0.0));
    }

    fn random_lights(seed: u32, count: usize) -> Vec<Light> {
        let mut rng = CounterRng::new(seed);
        (0..count).map(|_| random_light(&mut rng)).collect()
    }

    #[test]
    fn importance_pmfs_sum_to_one_and_match_selection() {
        let lights = random_lights(2, 7);
        let mut rng = CounterRng::new(3);
        for case in 0..2_000 {
            let p = rng.vec3(-5.0, 5.0);
            let n = if case % 4 == 0 { Vec3::ZERO } else { rng.unit_vec3() };
            let sum: f32 = (0..7).map(|k| importance_pmf(&lights, p, n, k)).sum();
            assert!((sum - 1.0).abs() < 1e-5, "case {case}: sum {sum}");
            let choice = select_importance(&lights, p, n, rng.next_f32());
            assert!(choice.is_valid());
            assert_eq!(choice.pmf, importance_pmf(&lights, p, n, choice.index));
            assert_eq!(importance_pmf(&lights, p, n, 7), 0.0);
        }
        assert_eq!(select_importance(&[], Vec3::ZERO, Vec3::ZERO, 0.5), LightChoice::NONE);
        assert_eq!(importance_pmf(&[], Vec3::ZERO, Vec3::ZERO, 0), 0.0);
    }

    #[test]
    fn importance_selection_frequencies_match_the_pmf() {
        // Six lights of which all are visible from p: chi-square with 5 dof; 20.515 is its 0.999
        // quantile. 10⁵ draws from pcg3d at a fixed seed.
        let lights = [
            Light::sphere(Vec3::new(0.0, 3.0, 0.0), 0.3, Vec3::ONE),
            Light::sphere(Vec3::new(2.0, 2.0, 0.0), 0.5, Vec3::new(2.0, 1.0, 0.5)),
            Light::sphere(Vec3::new(-4.0, 1.0, 1.0), 1.0, Vec3::ONE),
            Light::quad(Vec3::new(-1.0, 4.0, -1.0), Vec3::X, Vec3::Z, Vec3::splat(3.0), false),
            Light::quad(Vec3::new(3.0, 1.0, 3.0), Vec3::X * 0.5, Vec3::Y * 0.5, Vec3::ONE, true),
            Light::sphere(Vec3::new(0.0, 8.0, 0.0), 2.0, Vec3::splat(0.5)),
        ];
        let (p, n) = (Vec3::new(0.2, 0.0, 0.1), Vec3::Y);
        let pmfs: Vec<f32> = (0..6).map(|k| importance_pmf(&lights, p, n, k)).collect();
        assert!(pmfs.iter().all(|&q| q > 0.004), "{pmfs:?}");
        const DRAWS: u32 = 100_000;
        let mut counts = [0u32; 6];
        for i in 0..DRAWS {
            let choice = select_importance(&lights, p, n, unit_float(pcg3d(UVec3::new(i, 17, 4)).x));
            counts[choice.index as usize] += 1;
        }
        let chi2: f32 = (0..6)
            .map(|k| {
                let expected = pmfs[k] * DRAWS as f32;
                (counts[k] as f32 - expected).powi(2) / expected
            })
            .sum();
        assert!(chi2 < 20.515, "chi-square {chi2}, counts {counts:?}, pmfs {pmfs:?}");
    }

    /// Scaling a scene scales every distance and every light's area alike, so each importance
    /// (power over squared distance) is unchanged, and with it the choice: at points inside,
    /// near and far from the lights' bounding spheres, on surfaces and in media. (pbrt-v4 clamps
    /// `d²` with half the diagonal's length, not its square, so near a light the importance
    /// depended on the scene's unit: one here changed 380× at ×10⁻³.)
    #[test]
    fn importance_does_not_depend_on_the_scene_scale() {
        let lights = [
            Light::quad(Vec3::new(-0.06, 0.55, 0.1), Vec3::X * 0.12, Vec3::Z * 0.1, Vec3::splat(20.0), false),
            Light::sphere(Vec3::new(0.3, 0.4, 0.2), 0.05, Vec3::splat(30.0)),
        ];
        let mut rng = crate::hash::CounterRng::new(5);
        for _ in 0..2000 {
            let p = rng.vec3(-0.1, 0.6);
            let n = if rng.next_f32() < 0.5 { rng.unit_vec3() } else { Vec3::ZERO };
            for light in &lights {
                let at_unit_scale = light_importance(light, p, n);
                for scale in [1e-3f32, 1e-2, 10.0, 1e3] {
                    let scaled = Light {
                        position: light.position * scale,
                        edge_u: light.edge_u * scale,
                        edge_v: light.edge_v * scale,
                        ..*light
                    };
                    let value = light_importance(&scaled, p * scale, n);
                    let close = (value - at_unit_scale).abs() <= 1e-4 * at_unit_scale.max(value) + 1e-30;
                    assert!(close, "p {p}, n {n}, ×{scale}: {value} against {at_unit_scale}");
                }
            }
        }
    }

    /// Turning the scene about any axis turns the lights and the points alike, so each importance
    /// is unchanged (up to rounding): the bounds' sphere is each light's own, not its box's, whose
    /// size depends on how the light lies to the axes (the two-light Cornell box drew other light
    /// samples when rotated; with the box's sphere 1547 of these 4000 importances moved by more
    /// than the tolerance, up to 18×, and 19 lights were culled in one orientation only).
    #[test]
    fn importance_does_not_depend_on_the_scene_rotation() {
        let mut rng = crate::hash::CounterRng::new(9);
        let mut compared = 0;
        for _ in 0..4000 {
            let light = random_light(&mut rng);
            let (p, n) = (rng.vec3(-5.0, 5.0), if rng.next_f32() < 0.5 { rng.unit_vec3() } else { Vec3::ZERO });
            let turn = glam::Quat::from_axis_angle(rng.unit_vec3(), rng.range(0.1, 3.0));
            let turned = Light {
                position: (turn * light.position.truncate()).extend(light.position.w),
                edge_u: (turn * light.edge_u.truncate()).extend(0.0),
                edge_v: (turn * light.edge_v.truncate()).extend(0.0),
                ..light
            };
            let before = light_importance(&light, p, n);
            let after = light_importance(&turned, turn * p, turn * n);
            // Rounding may move a point across the cut-off angle, where the importance is ~0.
            let scale = light_bounds(&light).phi / (p - light.position.truncate()).length_squared();
            let close = (after - before).abs() <= 1e-3 * before.max(after) + 1e-4 * scale;
            assert!(close, "{light:?}, p {p}, n {n}: {after} turned, {before} as built");
            compared += usize::from(before > 0.0);
        }
        assert!(compared > 1500, "{compared}");
    }

    #[test]
    fn selection_hard_cases() {
        // All lights behind the surface: every importance is 0, so the scan falls back to uniform.
        let lights = [
            Light::sphere(Vec3::new(0.0, -3.0, 0.0), 0.5, Vec3::ONE),
            Light::quad(Vec3::new(-1.0, -2.0, -1.0), Vec3::X, Vec3::Z, Vec3::ONE, true),
            Light::sphere(Vec3::new(2.0, -5.0, 1.0), 1.0, Vec3::ONE),
        ];
        let (p, n) = (Vec3::ZERO, Vec3::Y);
        for k in 0..3 {
            assert_eq!(light_importance(&lights[k], p, n), 0.0);
            assert_eq!(importance_pmf(&lights, p, n, k as u32), 1.0 / 3.0);
        }
        assert_eq!(select_importance(&lights, p, n, 0.5), LightChoice { index: 1, pmf: 1.0 / 3.0 });
        // The same lights without a surface: all selectable.
        assert!((0..3).all(|k| importance_pmf(&lights, p, Vec3::ZERO, k) > 0.0));

        // All-zero radiance: uniform.
        let dark = [Light::sphere(Vec3::ZERO, 1.0, Vec3::ZERO), Light::sphere(Vec3::X, 1.0, Vec3::ZERO)];
        assert_eq!(select_importance(&dark, Vec3::Y * 3.0, Vec3::ZERO, 0.7), LightChoice { index: 1, pmf: 0.5 });

        // p at a sphere's centre: that light dominates; on a quad (emitting +x), which lights
        // nothing in its plane: the spheres share, the nearer dominating; a hair in front, the
        // quad dominates again; nothing is NaN.
        let lights = [
            Light::sphere(Vec3::ZERO, 0.5, Vec3::ONE),
            Light::quad(Vec3::new(5.0, 0.0, 0.0), Vec3::Y, Vec3::Z, Vec3::ONE, false),
            Light::sphere(Vec3::new(-5.0, 0.0, 0.0), 0.5, Vec3::ONE),
        ];
        for (p, dominant) in [(Vec3::ZERO, 0), (Vec3::new(5.0, 0.5, 0.5), 0), (Vec3::new(5.001, 0.5, 0.5), 1)] {
            for n in [Vec3::ZERO, Vec3::X, -Vec3::X] {
                let pmfs: Vec<f32> = (0..3).map(|k| importance_pmf(&lights, p, n, k)).collect();
                assert!(pmfs.iter().all(|q| q.is_finite()), "{pmfs:?}");
                assert!((pmfs.iter().sum::<f32>() - 1.0).abs() < 1e-5);
                // Facing +x, on the quad's plane or in front of it, every light is behind the
                // surface or lights nothing: the uniform fallback.
                let none_reaches = p.x >= 5.0 && n == Vec3::X;
                if none_reaches {
                    assert!(pmfs.iter().all(|&q| q == 1.0 / 3.0), "{p} {n}: {pmfs:?}");
                } else {
                    assert!(pmfs[dominant] > 0.5, "{p} {n}: {pmfs:?}");
                }
                if p.x == 5.0 && !none_reaches {
                    assert_eq!(pmfs[1], 0.0, "{p} {n}: {pmfs:?}");
                }
            }
        }

        // Coincident lights share the probability equally.
        let same = [Light::sphere(Vec3::ONE, 0.5, Vec3::ONE); 4];
        for p in [Vec3::ZERO, Vec3::ONE] {
            assert!((0..4).all(|k| importance_pmf(&same, p, Vec3::ZERO, k) == 0.25));
            let counts = (0..1000).fold([0u32; 4], |mut c, i| {
                c[select_importance(&same, p, Vec3::ZERO, i as f32 / 1000.0).index as usize] += 1;
                c
            });
            assert!(counts.iter().all(|&c| (240..=260).contains(&c)), "{counts:?}");
        }
    }

    /// The leaf node of light `k` of `lights`.
    fn leaf_node(lights: &[Light], k: u32) -> LightBvhNode {
        LightBvhNode { bounds: light_bounds(&lights[k as usize]), child_or_light: k, is_leaf: 1, padding: [0; 2] }
    }

    /// A hand-built tree over three lights: root → (leaf 0, interior → (leaf 1, leaf 2)).
    fn three_light_tree(lights: &[Light; 3]) -> ([LightBvhNode; 5], [u32; 3]) {
        let leaf = |k: u32| leaf_node(lights, k);
        let union = |a: &LightBounds, b: &LightBounds| {
            let (lo, hi) = (a.min.min(b.min).truncate(), a.max.max(b.max).truncate());
            LightBounds {
                min: lo.extend(a.min.w.max(b.min.w)),
                max: hi.extend(0.5 * (hi - lo).length()),
                axis: Vec3::Z.extend(0.0),
                phi: a.phi + b.phi,
                cos_theta_o: -1.0,
                cos_theta_e: 0.0,
                two_sided: 0,
            }
        };
        let inner = union(&leaf(1).bounds, &leaf(2).bounds);
        let root = union(&leaf(0).bounds, &inner);
        let interior = |bounds, second| LightBvhNode { bounds, child_or_light: second, is_leaf: 0, padding: [0; 2] };
        ([interior(root, 2), leaf(0), interior(inner, 4), leaf(1), leaf(2)], [0b0, 0b01, 0b11])
    }

    /// Two sphere lights and a two-sided quad, the lights of the hand-built three-light tree.
    fn three_lights() -> [Light; 3] {
        [
            Light::sphere(Vec3::new(0.0, 3.0, 0.0), 0.3, Vec3::ONE),
            Light::sphere(Vec3::new(4.0, 2.0, 0.0), 0.5, Vec3::ONE),
            Light::quad(Vec3::new(4.0, 4.0, -1.0), Vec3::X, Vec3::Z, Vec3::splat(3.0), true),
        ]
    }

    #[test]
    fn bvh_pmf_matches_selection() {
        let lights = three_lights();
        let (nodes, trails) = three_light_tree(&lights);
        let mut rng = CounterRng::new(9);
        for case in 0..2_000 {
            let p = rng.vec3(-6.0, 6.0);
            let n = if case % 3 == 0 { Vec3::ZERO } else { rng.unit_vec3() };
            let sum: f32 = (0..3).map(|k| bvh_pmf(&lights, &nodes, &trails, p, n, k)).sum();
            assert!((sum - 1.0).abs() < 1e-5, "sum {sum}");
            let choice = select_bvh(&lights, &nodes, p, n, rng.next_f32());
            assert!(choice.is_valid());
            assert_eq!(choice.pmf, bvh_pmf(&lights, &nodes, &trails, p, n, choice.index));
            let set = LightSet::new(&lights, &nodes, &trails);
            assert_eq!(set.pmf(p, n, choice.index), mixed_pmf(3, choice.pmf));
        }
        assert_eq!(bvh_pmf(&lights, &nodes, &trails, Vec3::ZERO, Vec3::ZERO, 3), 0.0);
        // A light whose trail leads elsewhere (left out of the tree) has pmf 0.
        assert_eq!(bvh_pmf(&lights, &nodes, &[0, 0, 0], Vec3::ZERO, Vec3::ZERO, 2), 0.0);
    }

    #[test]
    fn empty_single_and_malformed_trees() {
        let light = Light::sphere(Vec3::ZERO, 1.0, Vec3::ONE);
        assert_eq!(select_bvh(&[], &[], Vec3::ZERO, Vec3::ZERO, 0.5), LightChoice::NONE);
        assert_eq!(bvh_pmf(&[], &[], &[], Vec3::ZERO, Vec3::ZERO, 0), 0.0);
        let single = [LightBvhNode { bounds: light_bounds(&light), child_or_light: 0, is_leaf: 1, padding: [0; 2] }];
        assert_eq!(select_bvh(&[light], &single, Vec3::X * 3.0, Vec3::X, 0.3), LightChoice { index: 0, pmf: 1.0 });
        assert_eq!(bvh_pmf(&[light], &single, &[0], Vec3::X * 3.0, Vec3::X, 0), 1.0);
        // A child index out of range, and a cycle deeper than 32 levels: no light, no panic.
        let mut broken = single;
        broken[0].is_leaf = 0;
        broken[0].child_or_light = 9;
        assert_eq!(select_bvh(&[light], &broken, Vec3::ZERO, Vec3::ZERO, 0.3), LightChoice::NONE);
        assert_eq!(bvh_pmf(&[light], &broken, &[0], Vec3::ZERO, Vec3::ZERO, 0), 0.0);
        let cycle = [LightBvhNode { bounds: light_bounds(&light), child_or_light: 0, is_leaf: 0, padding: [0; 2] }; 2];
        assert_eq!(select_bvh(&[light], &cycle, Vec3::X, Vec3::ZERO, 0.9), LightChoice::NONE);
        assert_eq!(bvh_pmf(&[light], &cycle, &[u32::MAX], Vec3::X, Vec3::ZERO, 0), 0.0);
    }

    #[test]
    fn a_single_light_is_chosen_with_pmf_one_as_the_scan_would() {
        // The scan's answer for one light, whatever its importance at (p, n): I / I or the
        // all-zero fallback — for points in front of, behind and inside the light, NaN ones too.
        let mut rng = CounterRng::new(41);
        let lights = [random_light(&mut rng), Light::sphere(Vec3::ZERO, 1.0, Vec3::ONE)];
        for light in lights {
            let mut zero_seen = false;
            for k in 0..2000 {
                let p = if k == 0 { Vec3::NAN } else { rng.vec3(-4.0, 4.0) };
                let n = if k % 7 == 0 { Vec3::ZERO } else { rng.unit_vec3() };
                let weight = light_importance(&light, p, n);
                zero_seen |= weight == 0.0;
                let scanned = if weight > 0.0 { weight / weight } else { uniform_pmf(1, 0) };
                let choice = select_importance(&[light], p, n, rng.next_f32());
                assert_eq!(choice, LightChoice { index: 0, pmf: scanned }, "p {p} n {n}");
                assert_eq!(importance_pmf(&[light], p, n, 0), scanned, "p {p} n {n}");
                assert_eq!(importance_pmf(&[light], p, n, 1), 0.0);
            }
            assert!(zero_seen, "some points see the light with importance 0");
        }
    }

    #[test]
    fn light_set_dispatches_and_honours_counts() {
        let lights = three_lights();
        let (nodes, trails) = three_light_tree(&lights);
        let (p, n) = (Vec3::new(1.0, 0.0, 0.5), Vec3::Y);
        let linear = LightSet::new(&lights, &[], &[]);
        let tree = LightSet::new(&lights, &nodes, &trails);
        // The scan mixes its uniform share over the lights of positive importance (all three
        // here), the tree over all the lights.
        assert!((0..3).all(|k| light_importance(&lights[k], p, n) > 0.0));
        for k in 0..3 {
            let mixed = UNIFORM_SHARE / 3.0 + (1.0 - UNIFORM_SHARE) * importance_pmf(&lights, p, n, k);
            assert!((linear.pmf(p, n, k) / mixed - 1.0).abs() < 1e-6, "{} vs {mixed}", linear.pmf(p, n, k));
            assert_eq!(tree.pmf(p, n, k), mixed_pmf(3, bvh_pmf(&lights, &nodes, &trails, p, n, k)));
        }
        let u = Vec2::new(0.4, 0.9);
        let scanned = linear.select(p, n, u);
        assert_eq!(scanned.pmf, linear.pmf(p, n, scanned.index));
        // Past the uniform share the walk draws with the rescaled sample's x (y does not count);
        // within it, y picks uniformly.
        let walked = select_bvh(&lights, &nodes, p, n, (0.4 - UNIFORM_SHARE) / (1.0 - UNIFORM_SHARE));
        for y in [0.0, 0.5, 0.9] {
            let expected = LightChoice { index: walked.index, pmf: mixed_pmf(3, walked.pmf) };
            assert_eq!(tree.select(p, n, Vec2::new(0.4, y)), expected);
        }
        for (y, index) in [(0.0, 0), (0.5, 1), (0.9, 2)] {
            let uniform = tree.select(p, n, Vec2::new(0.5 * UNIFORM_SHARE, y));
            assert_eq!(uniform, LightChoice { index, pmf: tree.pmf(p, n, index) });
        }
        // Dummy one-element buffers with zero counts: no light, and the scan, respectively.
        let none = LightSet { light_count: 0, ..tree };
        assert_eq!(none.select(p, n, u), LightChoice::NONE);
        assert_eq!(none.pmf(p, n, 0), 0.0);
        let no_tree = LightSet { node_count: 0, ..tree };
        assert_eq!(no_tree.select(p, n, u), linear.select(p, n, u));
        let two = LightSet { light_count: 2, node_count: 0, ..tree };
        assert!(((0..3).map(|k| two.pmf(p, n, k)).sum::<f32>() - 1.0).abs() < 1e-6);
        assert_eq!(two.pmf(p, n, 2), 0.0);
    }

    /// A dim lamp far above the point, the only light that lights it, beside a node of two bright
    /// one-sided lamps just above it that face away (`U` 0, culled at their leaves, but their
    /// node's bounds cannot tell): the walk gives the lit lamp 2·10⁻¹⁰, below 2⁻²⁴ — never drawn,
    /// `U_N` 0 where `U` is not (a helper's study). With the uniform share every light keeps at
    /// least α/N, and the set's choices over 2¹⁶ stratified samples draw it as often as that pmf
    /// says, each with the pmf [`LightSet::pmf`] gives; the pmfs sum to 1.
    #[test]
    fn a_lit_light_beside_a_node_that_lights_nothing_keeps_the_uniform_share() {
        let up = |x: f32| Light::quad(Vec3::new(x, 1.0, -0.5), Vec3::Z, Vec3::X, Vec3::splat(1.0e4), false);
        let far = Light::quad(Vec3::new(-0.05, 50.0, -0.05), Vec3::X * 0.1, Vec3::Z * 0.1, Vec3::ONE, false);
        let lights = [far, up(0.5), up(-1.5)];
        let emits = |l: &Light| l.edge_u.truncate().cross(l.edge_v.truncate());
        assert!(emits(&lights[1]).y > 0.0 && emits(&far).y < 0.0, "the bright lamps face up, the far one down");
        let (nodes, trails) = three_light_tree(&lights);
        let (p, n) = (Vec3::ZERO, Vec3::Y);
        assert!(!quad_lights_nothing(&far, p, n) && quad_lights_nothing(&lights[1], p, n));
        let walked = bvh_pmf(&lights, &nodes, &trails, p, n, 0);
        assert!(walked > 0.0 && walked < 1.0 / 16_777_216.0, "the walk alone: {walked}");
        let set = LightSet::new(&lights, &nodes, &trails);
        assert!(set.pmf(p, n, 0) >= UNIFORM_SHARE / 3.0, "{}", set.pmf(p, n, 0));
        assert_draws_follow_the_pmf(&set, p, n);
    }

    /// The uniform share's pick among 10⁵ lights, over every one of the 2²⁴ values of `u.y`
    /// below the share: each light is drawn ⌊2²⁴/N⌋ or ⌈2²⁴/N⌉ times (167 or 168 of 167.8, within
    /// 0.5 % of its share `α/N`), and carries its pmf. From `u.x` below the share, as before, it
    /// had only 2¹⁹ values, 5 or 6 a light for 5.24 (+14 %). One leaf, light 0's: the walk
    /// reaches no other light, so each of them is drawn by the share alone, with pmf `α/N`.
    #[test]
    fn the_uniform_share_draws_each_of_many_lights_as_often_as_its_pmf_says() {
        const N: u32 = 100_000;
        let lights: Vec<Light> = (0..N)
            .map(|k| Light::quad(Vec3::new(k as f32, 2.0, 0.0), Vec3::X * 0.5, Vec3::Z * 0.5, Vec3::ONE, false))
            .collect();
        let nodes = [leaf_node(&lights, 0)];
        let trails = vec![0u32; N as usize];
        let set = LightSet::new(&lights, &nodes, &trails);
        let (p, n) = (Vec3::new(0.25, 0.0, 0.25), Vec3::Y);
        let mut drawn = vec![0u32; N as usize];
        let steps = 1u32 << 24;
        // Light 0's pmf holds the walk's share too.
        let pmf = |k: u32| if k == 0 { set.pmf(p, n, 0) } else { UNIFORM_SHARE / N as f32 };
        for j in 0..steps {
            let choice = set.select(p, n, Vec2::new(0.5 * UNIFORM_SHARE, j as f32 / steps as f32));
            assert_eq!(choice.pmf, pmf(choice.index), "value {j}: {choice:?}");
            drawn[choice.index as usize] += 1;
        }
        let (fewest, most) = (drawn.iter().min().unwrap(), drawn.iter().max().unwrap());
        assert!(*fewest >= steps / N && *most <= steps.div_ceil(N), "{fewest}..={most} draws a light");
    }

    /// Draws `set`'s choice at `p`, `n` with 2¹⁶ stratified samples (x stratified over them all,
    /// y over each run of 2¹¹, the draws of the uniform share among them): each choice carries the
    /// pmf [`LightSet::pmf`] gives, the pmfs sum to 1, and each light is drawn as often as its pmf
    /// says (within 10⁻⁴, a few steps of the stratification).
    fn assert_draws_follow_the_pmf(set: &LightSet, p: Vec3, n: Vec3) {
        let pmfs: Vec<f32> = (0..set.len()).map(|k| set.pmf(p, n, k)).collect();
        let total: f32 = pmfs.iter().sum();
        assert!((total - 1.0).abs() < 1e-6, "{total}");
        let draws = 1u32 << 16;
        let mut drawn = vec![0u32; pmfs.len()];
        for i in 0..draws {
            let run = draws as f32 * UNIFORM_SHARE;
            let u = Vec2::new((i as f32 + 0.5) / draws as f32, ((i as f32 % run) + 0.5) / run);
            let choice = set.select(p, n, u);
            assert_eq!(choice.pmf, pmfs[choice.index as usize], "sample {i}");
            drawn[choice.index as usize] += 1;
        }
        for (light, (&count, &pmf)) in drawn.iter().zip(&pmfs).enumerate() {
            let frequency = count as f32 / draws as f32;
            assert!((frequency - pmf).abs() < 1e-4, "light {light} drawn {frequency}, pmf {pmf}");
        }
    }

    /// A row of seven 5.3 cm one-sided lamps in one plane and a point 13.4 µm over the first, its
    /// normal tilted 1.27·10⁻³ along the row (a helper's study found the case): only a strip of
    /// the lamp under the point lies above its horizon, but the point's foot is on that lamp, so
    /// its cosine bounds are 1 and its distance is clamped at its radius, and the scan gives
    /// every other lamp a pmf below 10⁻⁶ — lamps 2–6 below 2⁻²⁴, never drawn, though an `f64`
    /// integral of the form factors gives them 6 % of the point's `U` (lamp 1: 32 %, pmf
    /// 4.5·10⁻⁷). The set's uniform share keeps each of them at `α/M` at least, `M` the lamps of
    /// positive importance, and its draws follow its pmf. An eighth lamp, facing away, lights
    /// nothing there: it keeps pmf 0 and is never drawn.
    #[test]
    fn a_lamp_the_point_stands_over_does_not_starve_its_lit_neighbours_in_the_scan() {
        let size = 0.053;
        let lamp = |k: u32| {
            let corner = Vec3::new(-0.5 * size, -0.5 * size - 0.06 * k as f32, 1.0);
            let (edge_u, edge_v) = if k < 7 { (Vec3::X, Vec3::Y) } else { (Vec3::Y, Vec3::X) };
            Light::quad(corner, edge_u * size, edge_v * size, Vec3::ONE, false)
        };
        let lights: Vec<Light> = (0..8).map(lamp).collect();
        let (p, n) = (Vec3::new(0.0, 0.0, 1.0 + 13.4e-6), Vec3::new(0.0, -1.27e-3, 1.0).normalize());
        let shares = form_factor_shares(&lights, p, n);
        let starved: f64 = (0..8u32)
            .filter(|&k| importance_pmf(&lights, p, n, k) < 1.0 / 16_777_216.0)
            .map(|k| shares[k as usize])
            .sum();
        assert!(starved > 0.05, "the scan alone starves lamps with {starved} of the form factor");
        assert!(quad_lights_nothing(&lights[7], p, n) && shares[7] == 0.0);
        let set = LightSet::new(&lights, &[], &[]);
        for k in 0..7 {
            assert!(set.pmf(p, n, k) >= UNIFORM_SHARE / 7.0, "lamp {k}: {}", set.pmf(p, n, k));
        }
        assert_eq!(set.pmf(p, n, 7), 0.0);
        assert_draws_follow_the_pmf(&set, p, n);
    }

    /// Each quad light's share of the diffuse form factor at `p` (normal `n`): a 400² midpoint
    /// rule in `f64` of `cos θ_p cos θ_l / r²` over the light's front side.
    fn form_factor_shares(lights: &[Light], p: Vec3, n: Vec3) -> Vec<f64> {
        let (p, n) = (p.as_dvec3(), n.as_dvec3());
        let steps = 400;
        let factors: Vec<f64> = lights
            .iter()
            .map(|light| {
                let corner = light.position.truncate().as_dvec3();
                let (eu, ev) = (light.edge_u.truncate().as_dvec3(), light.edge_v.truncate().as_dvec3());
                let front = eu.cross(ev).normalize();
                let mut sum = 0.0;
                for i in 0..steps {
                    for j in 0..steps {
                        let (a, b) = ((i as f64 + 0.5) / steps as f64, (j as f64 + 0.5) / steps as f64);
                        let d = corner + eu * a + ev * b - p;
                        sum += n.dot(d).max(0.0) * (-front.dot(d)).max(0.0) / d.length_squared().powi(2);
                    }
                }
                sum * eu.cross(ev).length() / (steps * steps) as f64
            })
            .collect();
        let total: f64 = factors.iter().sum();
        factors.iter().map(|f| f / total).collect()
    }

    /// Inside a light's bounding sphere the importance stops growing: the distance term is
    /// clamped to the sphere's radius (pbrt-v4's `LightBounds::Importance`), and there the cone
    /// terms are 1, so the value is Φ / r² in closed form. A unit quad of unit radiance
    /// (Φ = π·area·Y = π, r² = ½) gives 2π anywhere above it within r; a sphere light of radius ½
    /// (Φ = π·4π·¼ = π², r² = ¼) gives 4π² anywhere inside it. Without the clamp a point close to
    /// a light drew it with a probability near 1 (1/d² unbounded), starving every other light.
    #[test]
    fn importance_inside_a_lights_sphere_is_its_value_on_the_sphere() {
        let quad = light_bounds(&Light::quad(Vec3::new(-0.5, -0.5, 0.0), Vec3::X, Vec3::Y, Vec3::ONE, false));
        let sphere = light_bounds(&Light::sphere(Vec3::ZERO, 0.5, Vec3::ONE));
        let pi = core::f32::consts::PI;
        for (bounds, points, expected) in [
            (quad, [Vec3::new(0.0, 0.0, 1e-3), Vec3::new(0.1, -0.2, 0.3), Vec3::new(0.0, 0.0, 0.7)], 2.0 * pi),
            (sphere, [Vec3::new(0.0, 0.0, 1e-3), Vec3::new(0.1, -0.2, 0.3), Vec3::new(0.0, 0.49, 0.0)], 4.0 * pi * pi),
        ] {
            for p in points {
                for n in [Vec3::ZERO, -p.normalize()] {
                    let value = importance(&bounds, p, n);
                    assert!((value / expected - 1.0).abs() < 1e-5, "{bounds:?} at {p}, n {n}: {value} vs {expected}");
                }
            }
        }
    }

    /// Bounds over two lights, as the host's tree builder makes them: the box and the light
    /// spheres' largest radius, the half-diagonal as the node's sphere, the powers summed; the
    /// emitters' cone (`axis`, `cos_theta_o`) is the caller's.
    fn union_bounds(a: &LightBounds, b: &LightBounds, axis: Vec3, cos_theta_o: f32) -> LightBounds {
        let (lo, hi) = (a.min.min(b.min).truncate(), a.max.max(b.max).truncate());
        LightBounds {
            min: lo.extend(a.min.w.max(b.min.w)),
            max: hi.extend(0.5 * (hi - lo).length()),
            axis: axis.extend(0.0),
            phi: a.phi + b.phi,
            cos_theta_o,
            cos_theta_e: 0.0,
            two_sided: 0,
        }
    }

    /// A node over two one-sided quads facing different ways (normals 30°–150° apart), whose
    /// cone of normals is the pair's (axis along their sum, half-angle to either): at points
    /// inside the node's sphere — where the corner-wise reach test applies — with random
    /// surface normals, the node never weighs 0 while one of its lights clearly lights the point
    /// (cosines above 10⁻⁴ at both ends for some sampled point of it). A node culled there loses
    /// that light's light for good: the walk never reaches it. Both outcomes are counted, so the
    /// test is known to reach the cone test.
    #[test]
    fn a_node_of_quads_facing_apart_is_never_culled_while_one_lights_the_point() {
        let mut rng = CounterRng::new(77);
        let (mut contributing, mut culled) = (0, 0);
        for case in 0..20_000 {
            let make = |rng: &mut CounterRng| {
                let eu = rng.unit_vec3() * rng.range(0.2, 1.5);
                let ev = eu.cross(rng.unit_vec3()).normalize_or_zero() * rng.range(0.2, 1.5);
                Light::quad(rng.vec3(-1.0, 1.0), eu, ev, Vec3::ONE, false)
            };
            let lights = [make(&mut rng), make(&mut rng)];
            let normals = lights.map(|l| l.edge_u.truncate().cross(l.edge_v.truncate()).normalize());
            let cos_between = normals[0].dot(normals[1]);
            if !(-0.866..=0.866).contains(&cos_between) {
                continue;
            }
            let axis = (normals[0] + normals[1]).normalize();
            let cos_theta_o = axis.dot(normals[0]).min(axis.dot(normals[1])) - 1e-6;
            let bounds = union_bounds(&light_bounds(&lights[0]), &light_bounds(&lights[1]), axis, cos_theta_o);
            let node = LightBvhNode { bounds, child_or_light: 2, is_leaf: 0, padding: [0; 2] };
            let set = LightSet::new(&lights, &[], &[]);
            let centre = (bounds.min.truncate() + bounds.max.truncate()) * 0.5;
            let p = centre + rng.unit_vec3() * bounds.max.w * rng.next_f32();
            let n = if case % 5 == 0 { Vec3::ZERO } else { rng.unit_vec3() };
            let value = node_importance(&set, &node, p, n);
            let lit = lights.iter().any(|l| contributes(l, &light_points(l, &mut rng, 48), p, n, 1e-4));
            if lit {
                contributing += 1;
                assert!(value > 0.0, "case {case}: {lights:?} light p={p} n={n} but the node has importance 0");
            } else if value == 0.0 {
                culled += 1;
            }
        }
        assert!(contributing > 5_000 && culled > 90, "contributing {contributing}, culled {culled}");
    }

    /// A node of two coplanar one-sided quads facing down (emitter cone of half-angle 0, emission
    /// within π/2) weighs 0 at points behind them inside its sphere, where no light of it shines,
    /// and more than 0 in front: the one-sided cone cull. Turned off, the behind points kept the
    /// node's full importance (variance only: `U` there is 0), and no test had noticed.
    #[test]
    fn a_node_of_one_sided_quads_weighs_nothing_behind_them() {
        let down = |x: f32| Light::quad(Vec3::new(x, 2.0, -0.5), Vec3::X, Vec3::Z, Vec3::ONE, false);
        let lights = [down(-1.0), down(0.2)];
        let bounds = union_bounds(&light_bounds(&lights[0]), &light_bounds(&lights[1]), Vec3::NEG_Y, 1.0);
        let node = LightBvhNode { bounds, child_or_light: 2, is_leaf: 0, padding: [0; 2] };
        let set = LightSet::new(&lights, &[], &[]);
        for x in [-0.8f32, 0.0, 0.7] {
            for n in [Vec3::ZERO, Vec3::Y, Vec3::NEG_Y, Vec3::X] {
                let behind = node_importance(&set, &node, Vec3::new(x, 2.3, 0.1), n);
                assert_eq!(behind, 0.0, "behind at x {x}, n {n}");
            }
            let in_front = node_importance(&set, &node, Vec3::new(x, 1.7, 0.1), Vec3::Y);
            assert!(in_front > 0.0, "in front at x {x}: {in_front}");
        }
    }

    /// A balanced tree over four lights: root → (interior → (leaf 0, leaf 1), interior → (leaf 2,
    /// leaf 3)), every interior node a first child as well as a second one.
    fn four_light_tree(lights: &[Light; 4]) -> ([LightBvhNode; 7], [u32; 4]) {
        let leaf = |k: u32| leaf_node(lights, k);
        let interior = |bounds, second| LightBvhNode { bounds, child_or_light: second, is_leaf: 0, padding: [0; 2] };
        let union = |a: &LightBounds, b: &LightBounds| union_bounds(a, b, Vec3::Z, -1.0);
        let left = union(&leaf(0).bounds, &leaf(1).bounds);
        let right = union(&leaf(2).bounds, &leaf(3).bounds);
        let root = union(&left, &right);
        (
            [interior(root, 4), interior(left, 3), leaf(0), leaf(1), interior(right, 6), leaf(2), leaf(3)],
            [0b00, 0b10, 0b01, 0b11],
        )
    }

    /// A spine of `depth` interior nodes, each with a dim sphere light as its first child and
    /// the rest of the spine as its second, ending in a bright light's leaf at depth `depth`:
    /// the deepest leaf the walk can reach when `depth` is [`MAX_BVH_DEPTH`]. Node `2k` is the
    /// spine at depth `k`, node `2k + 1` light `k`'s leaf; the last node is the bright light's.
    fn spine_tree(depth: u32) -> (Vec<Light>, Vec<LightBvhNode>, Vec<u32>) {
        let lights: Vec<Light> = (0..=depth)
            .map(|k| {
                let radiance = if k == depth { Vec3::ONE } else { Vec3::splat(1e-6) };
                Light::sphere(Vec3::new(k as f32 * 0.1, 3.0, 0.0), 0.05, radiance)
            })
            .collect();
        let leaf = |k: u32| leaf_node(&lights, k);
        let mut nodes = vec![leaf(depth)];
        for k in (0..depth).rev() {
            let bounds = union_bounds(&leaf(k).bounds, &nodes[0].bounds, Vec3::Z, -1.0);
            let spine = LightBvhNode { bounds, child_or_light: 2 * k + 2, is_leaf: 0, padding: [0; 2] };
            nodes.splice(0..0, [spine, leaf(k)]);
        }
        // Light k < depth: k second children, then a first; the bright light: `depth` seconds.
        let trails = (0..=depth).map(|k| ((1u64 << k) - 1) as u32).collect();
        (lights, nodes, trails)
    }

    /// The walk reaches a leaf at [`MAX_BVH_DEPTH`], the deepest the host's builder makes, and no
    /// deeper: at depth 32 the bright light at the end of a spine of dim ones is drawn with
    /// nearly all the probability, and its pmf agrees; one level deeper the tree is malformed
    /// (no light, pmf 0). A walk that stopped a level early had never drawn a light at depth 32.
    #[test]
    fn the_walk_reaches_leaves_at_the_largest_depth_and_no_deeper() {
        let (p, n) = (Vec3::new(1.6, 0.0, 0.0), Vec3::Y);
        let (lights, nodes, trails) = spine_tree(MAX_BVH_DEPTH);
        assert_eq!(nodes.len() as u32, 2 * MAX_BVH_DEPTH + 1);
        let deepest = MAX_BVH_DEPTH;
        let choice = select_bvh(&lights, &nodes, p, n, 0.5);
        assert_eq!(choice.index, deepest, "{choice:?}");
        assert!(choice.pmf > 0.99, "{choice:?}");
        assert_eq!(bvh_pmf(&lights, &nodes, &trails, p, n, deepest), choice.pmf);
        let total: f32 = (0..=deepest).map(|k| bvh_pmf(&lights, &nodes, &trails, p, n, k)).sum();
        assert!((total - 1.0).abs() < 1e-5, "the pmfs sum to {total}");
        let (lights, nodes, _) = spine_tree(MAX_BVH_DEPTH + 1);
        assert!(!select_bvh(&lights, &nodes, p, n, 0.5).is_valid(), "a leaf at depth 33");
    }

    /// The tree walk draws each light as often as its pmf says: over 2¹⁶ stratified `u` at random
    /// points of a four-light tree (where a first child is an interior node, so `u` must be
    /// rescaled on the way down), each light's frequency is within 2·10⁻⁴ of its pmf (stratified
    /// draws err by about the number of branch boundaries over the count, 3/65 536). A walk that
    /// reused `u` without rescaling chose within a subtree by the fraction of the parent's
    /// interval, not the child's — a biased estimate, as the shade stage divides by the pmf.
    #[test]
    fn bvh_selection_frequencies_match_the_pmf() {
        let lights = [
            Light::sphere(Vec3::new(0.0, 3.0, 0.0), 0.3, Vec3::ONE),
            Light::sphere(Vec3::new(1.0, 2.5, 0.5), 0.5, Vec3::splat(2.0)),
            Light::sphere(Vec3::new(4.0, 2.0, 0.0), 0.4, Vec3::ONE),
            Light::quad(Vec3::new(4.0, 4.0, -1.0), Vec3::X, Vec3::Z, Vec3::splat(3.0), true),
        ];
        let (nodes, trails) = four_light_tree(&lights);
        let mut rng = CounterRng::new(5);
        let draws = 1u32 << 16;
        for _ in 0..20 {
            let p = rng.vec3(-6.0, 6.0);
            let n = rng.unit_vec3();
            let mut counts = [0u32; 4];
            for i in 0..draws {
                let choice = select_bvh(&lights, &nodes, p, n, (i as f32 + 0.5) / draws as f32);
                assert!(choice.is_valid(), "p {p} n {n}");
                counts[choice.index as usize] += 1;
            }
            for (k, count) in (0u32..).zip(counts) {
                let pmf = bvh_pmf(&lights, &nodes, &trails, p, n, k);
                let frequency = count as f32 / draws as f32;
                assert!((frequency - pmf).abs() < 2e-4, "p {p} n {n}: light {k} drawn {frequency}, pmf {pmf}");
            }
        }
    }
}
