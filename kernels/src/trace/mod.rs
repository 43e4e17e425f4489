//! The trace stage: closest hit of every ray in the ray stream.
//!
//! The stage is written against [`ClosestHitQuery`] and [`OcclusionQuery`], so one function
//! serves every backend: the software traversal ([`cwbvh`], obvhs's CWBVH with
//! [`crate::triangle`]'s watertight test) on the CPU and in SPIR-V, and `VK_KHR_ray_query`
//! (`trace::ray_query`, SPIR-V only); the ray-tracing pipeline's ray-generation shaders, whose
//! traversal is a shader call rather than a query, run the same checks through
//! [`trace_closest_with`] and [`trace_occluded_with`].

pub mod cwbvh;
#[cfg(all(target_arch = "spirv", feature = "ray-query"))]
pub mod ray_query;

use crate::sanitized::Sanitized;
use glam::{Vec2, Vec3, Vec4, Vec4Swizzles};
use raywave_shared::stream::NO_HIT;

/// A ray read from the ray stream.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Ray {
    /// Origin in scene units.
    pub origin: Vec3,
    /// Direction, of any length whose largest component is at least [`MIN_DIRECTION`] and at
    /// most [`MAX_DIRECTION`] in magnitude (a shorter or longer one is not traceable, as a zero
    /// one is not).
    pub direction: Vec3,
    /// Start of the valid interval (≥ 0).
    pub tmin: f32,
    /// End of the valid interval (≥ `tmin`, finite).
    pub tmax: f32,
}

impl Ray {
    /// Unpacks the stream layout (origin.w = tmin, direction.w = tmax).
    pub fn from_stream(origin: Vec4, direction: Vec4) -> Self {
        Self { origin: origin.xyz(), direction: direction.xyz(), tmin: origin.w, tmax: direction.w }
    }

    /// Whether the ray can be traced: all components finite, a direction whose largest
    /// component lies in [[`MIN_DIRECTION`], [`MAX_DIRECTION`]] in magnitude, and
    /// `0 ≤ tmin ≤ tmax`. Vulkan leaves rays of a zero direction undefined, so the stage never
    /// passes them on; one of subnormal components made the watertight test's `1/d` overflow
    /// into NaN, and one beyond 2¹²⁶ makes it subnormal, which a GPU may flush to 0.
    pub fn is_traceable(&self) -> bool {
        self.origin.is_finite()
            && self.direction.is_finite()
            && self.direction.abs().max_element() >= MIN_DIRECTION
            && self.direction.abs().max_element() <= MAX_DIRECTION
            && self.tmin.is_finite()
            && self.tmax.is_finite()
            && self.tmin >= 0.0
            && self.tmin <= self.tmax
    }

    /// Whether every component is finite: a ray that is not is an input the stage replaces by a
    /// miss and counts ([`crate::sanitized`]); one that is finite but not traceable (a zero
    /// direction, an empty interval) misses without being counted.
    pub fn is_finite(&self) -> bool {
        self.origin.is_finite() && self.direction.is_finite() && self.tmin.is_finite() && self.tmax.is_finite()
    }
}

/// Smallest largest-component of a traceable ray's direction ([`Ray::is_traceable`]), 10⁻¹²:
/// `1/d` of the dominant component is then finite in the watertight test, and the sheared
/// depths `Δz/d` of a scene within its 10⁸ coordinate limit stay far from overflow. (The box
/// test scales every direction to a largest component in [1, 2) first, `cwbvh`; a floor of
/// 10⁻³⁰ under unscaled components, as large as such a direction, had traced it as a diagonal.)
pub const MIN_DIRECTION: f32 = 1e-12;

/// Largest largest-component of a traceable ray's direction ([`Ray::is_traceable`]), 10²⁰: the
/// watertight test's `1/d` of the dominant component is then at least 10⁻²⁰, a normal float, and
/// so are the sheared depths `Δz/d` of vertices more than ~10⁻¹⁸ away along it. Beyond 2¹²⁶ `1/d`
/// is subnormal, and a GPU that flushes it (Vulkan leaves denormals to the device; the kernels
/// do not ask to keep them) made every sheared depth 0: a triangle behind the origin was hit at
/// `t` = 0 (the trace review's case: direction (0, 0, −2·10³⁸)). Ten orders of magnitude above
/// the longest coordinate difference of a scene within its 10⁸ limit.
pub const MAX_DIRECTION: f32 = 1e20;

/// The closest hit of one ray, as the trace stage writes it into the hit stream.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit; 0 on a miss.
    pub t: f32,
    /// Triangle index within the instance's mesh; [`NO_HIT`] on a miss.
    pub primitive: u32,
    /// Instance index; [`NO_HIT`] on a miss.
    pub instance: u32,
    /// Weights of vertices 1 and 2; zero on a miss.
    pub barycentrics: Vec2,
}

impl Hit {
    /// The record of a ray that hit nothing.
    pub const MISS: Hit = Hit { t: 0.0, primitive: NO_HIT, instance: NO_HIT, barycentrics: Vec2::ZERO };

    /// Whether the ray hit anything.
    pub fn is_hit(&self) -> bool {
        self.primitive != NO_HIT
    }
}

/// A closest-hit query against the scene: implemented by each trace backend.
pub trait ClosestHitQuery {
    /// The closest hit of a traceable ray (see [`Ray::is_traceable`]) with `t ∈ [tmin, tmax]`,
    /// both faces of every triangle counted, or [`Hit::MISS`].
    fn closest_hit(&self, ray: &Ray) -> Hit;
}

/// An any-hit (occlusion) query against the scene: implemented by each trace backend.
pub trait OcclusionQuery {
    /// Whether any triangle is hit with `t ∈ [tmin, tmax]`, both faces counted. Implementations
    /// stop at the first hit found.
    fn occluded(&self, ray: &Ray) -> bool;
}

/// The occlusion variant of the trace stage for one invocation (shadow rays): whether the ray is
/// blocked within its interval. Rays that are not traceable report "not occluded", like a miss;
/// those that are not finite are also flagged as replaced.
pub fn trace_occluded<Q: OcclusionQuery>(origin: Vec4, direction: Vec4, query: &Q) -> Sanitized<bool> {
    trace_occluded_with(origin, direction, |ray| query.occluded(ray))
}

/// [`trace_occluded`] with the any-hit query `occluded`, called for traceable rays only.
#[inline(always)]
pub fn trace_occluded_with(origin: Vec4, direction: Vec4, occluded: impl FnOnce(&Ray) -> bool) -> Sanitized<bool> {
    let ray = Ray::from_stream(origin, direction);
    Sanitized { value: ray.is_traceable() && occluded(&ray), replaced: !ray.is_finite() }
}

/// The trace stage for one invocation: reads the ray at its stream fields and returns its closest
/// hit. Rays that are not traceable (NaN, Inf, a direction shorter than [`MIN_DIRECTION`] or
/// longer than [`MAX_DIRECTION`], a bad interval) miss, and a hit whose
/// values are not finite is written as a miss, so no NaN or Inf leaves the stage; both are
/// flagged as replaced (a non-finite ray, a non-finite hit).
pub fn trace_closest<Q: ClosestHitQuery>(origin: Vec4, direction: Vec4, query: &Q) -> Sanitized<Hit> {
    trace_closest_with(origin, direction, |ray| query.closest_hit(ray))
}

/// [`trace_closest`] with the closest-hit query `closest_hit`, called for traceable rays only.
#[inline(always)]
pub fn trace_closest_with(origin: Vec4, direction: Vec4, closest_hit: impl FnOnce(&Ray) -> Hit) -> Sanitized<Hit> {
    let ray = Ray::from_stream(origin, direction);
    if !ray.is_traceable() {
        return Sanitized { value: Hit::MISS, replaced: !ray.is_finite() };
    }
    sanitize(closest_hit(&ray))
}

/// A hit as it may leave the stage: one whose values are not all finite becomes a miss.
pub fn sanitize(hit: Hit) -> Sanitized<Hit> {
    if hit.t.is_finite() && hit.barycentrics.is_finite() {
        Sanitized::clean(hit)
    } else {
        Sanitized::replacing(Hit::MISS)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A query that returns a fixed record, to test the stage's boundary handling on its own.
    struct Fixed(Hit);
    impl ClosestHitQuery for Fixed {
        fn closest_hit(&self, _ray: &Ray) -> Hit {
            self.0
        }
    }

    const HIT: Hit = Hit { t: 2.0, primitive: 3, instance: 1, barycentrics: Vec2::new(0.25, 0.5) };

    impl OcclusionQuery for Fixed {
        fn occluded(&self, _ray: &Ray) -> bool {
            self.0.is_hit()
        }
    }

    #[test]
    fn traceable_rays_reach_the_query() {
        let o = Vec4::new(0.0, 0.0, 0.0, 0.0);
        let longest = Vec4::new(MAX_DIRECTION, -1.0, 0.0, 10.0);
        for d in [Vec4::new(0.0, 0.0, 1.0, 10.0), Vec4::new(0.0, -MIN_DIRECTION, 0.0, 10.0), longest] {
            assert_eq!(trace_closest(o, d, &Fixed(HIT)), Sanitized::clean(HIT), "{d}");
            assert_eq!(trace_occluded(o, d, &Fixed(HIT)), Sanitized::clean(true), "{d}");
        }
    }

    /// Rays that cannot be traced miss (and are not occluded); only the non-finite ones — inputs
    /// the stage had to replace — are flagged, not the finite but empty or zero-length ones.
    #[test]
    fn untraceable_rays_miss_and_non_finite_ones_are_flagged() {
        let ok_origin = Vec4::ZERO;
        let ok_dir = Vec4::new(0.0, 0.0, 1.0, 10.0);
        let cases = [
            (Vec4::new(f32::NAN, 0.0, 0.0, 0.0), ok_dir, true),
            (Vec4::new(f32::INFINITY, 0.0, 0.0, 0.0), ok_dir, true),
            (ok_origin, Vec4::new(0.0, f32::NAN, 1.0, 10.0), true),
            (ok_origin, Vec4::new(0.0, 0.0, 1.0, f32::INFINITY), true),
            (ok_origin, Vec4::new(0.0, 0.0, 0.0, 10.0), false),
            // Below the floor: `1/d` overflows in the watertight test (it had traced a NaN hit).
            (ok_origin, Vec4::new(0.0, 0.0, 1e-40, 10.0), false),
            (ok_origin, Vec4::new(-0.9e-12, 0.9e-12, 0.0, 10.0), false),
            // Beyond the ceiling: `1/d` is subnormal there, which a GPU may flush to 0.
            (ok_origin, Vec4::new(0.0, 0.0, -2e38, 10.0), false),
            (ok_origin, Vec4::new(0.0, 1.01e20, 1.0, 10.0), false),
            (Vec4::new(0.0, 0.0, 0.0, -1.0), ok_dir, false),
            (Vec4::new(0.0, 0.0, 0.0, 11.0), ok_dir, false),
        ];
        for (o, d, non_finite) in cases {
            let expected = Sanitized { value: Hit::MISS, replaced: non_finite };
            assert_eq!(trace_closest(o, d, &Fixed(HIT)), expected, "{o} {d}");
            assert_eq!(trace_occluded(o, d, &Fixed(HIT)), Sanitized { value: false, replaced: non_finite }, "{o} {d}");
        }
    }

    #[test]
    fn non_finite_hits_are_sanitized_to_misses_and_flagged() {
        let (o, d) = (Vec4::ZERO, Vec4::new(0.0, 0.0, 1.0, 10.0));
        for bad in [Hit { t: f32::NAN, ..HIT }, Hit { barycentrics: Vec2::new(0.5, f32::INFINITY), ..HIT }] {
            assert_eq!(trace_closest(o, d, &Fixed(bad)), Sanitized::replacing(Hit::MISS), "{bad:?}");
        }
    }
}
