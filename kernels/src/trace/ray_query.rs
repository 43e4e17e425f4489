//! [`ClosestHitQuery`] through `VK_KHR_ray_query` (SPIR-V only).

use super::{ClosestHitQuery, Hit, OcclusionQuery, Ray};
use spirv_std::ray_query;
use spirv_std::ray_tracing::{AccelerationStructure, CommittedIntersection, RayFlags, RayQuery};

/// Closest-hit queries against a top-level acceleration structure with an inline ray query.
/// All geometry is treated as opaque and both faces are hit, as in the CPU backend.
pub struct RayQueryScene<'a> {
    /// The scene's TLAS, bound at `bindings::trace::TLAS`.
    pub tlas: &'a AccelerationStructure,
}

impl ClosestHitQuery for RayQueryScene<'_> {
    fn closest_hit(&self, ray: &Ray) -> Hit {
        ray_query!(let mut query);
        // SAFETY: `tlas` is a valid acceleration structure bound by the host, and the ray has been
        // checked by `Ray::is_traceable`, as `OpRayQueryInitializeKHR` requires.
        unsafe {
            query.initialize(self.tlas, RayFlags::OPAQUE, 0xff, ray.origin, ray.tmin, ray.direction, ray.tmax);
            while query.proceed() {}
            match query.get_committed_intersection_type() {
                CommittedIntersection::Triangle => Hit {
                    t: query.get_committed_intersection_t(),
                    primitive: query.get_committed_intersection_primitive_index(),
                    instance: query.get_committed_intersection_instance_id(),
                    barycentrics: query.get_committed_intersection_barycentrics(),
                },
                _ => Hit::MISS,
            }
        }
    }
}

impl OcclusionQuery for RayQueryScene<'_> {
    fn occluded(&self, ray: &Ray) -> bool {
        ray_query!(let mut query);
        // SAFETY: as in `closest_hit`.
        unsafe {
            query.initialize(
                self.tlas,
                RayFlags::OPAQUE | RayFlags::TERMINATE_ON_FIRST_HIT,
                0xff,
                ray.origin,
                ray.tmin,
                ray.direction,
                ray.tmax,
            );
            while query.proceed() {}
            !matches!(query.get_committed_intersection_type(), CommittedIntersection::None)
        }
    }
}
