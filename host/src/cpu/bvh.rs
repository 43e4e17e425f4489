//! The CPU trace scene: obvhs's compressed wide BVH (CWBVH) over all triangles, traversed by
//! obvhs and intersected with the kernels' watertight test.

use crate::scene::Scene;
use glam::{Vec3, Vec3A};
use obvhs::cwbvh::{builder::build_cwbvh_from_tris, CwBvh};
use obvhs::ray::{Ray as BvhRay, RayHit};
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use raywave_kernels::trace::{ClosestHitQuery, Hit, Ray};
use raywave_kernels::triangle::WatertightRay;
use std::time::Duration;

/// A scene prepared for CPU tracing. Triangles are stored in BVH leaf order for locality, each
/// with the (instance, primitive) ids a Vulkan TLAS/BLAS pair would report for it.
pub struct CpuScene {
    bvh: CwBvh,
    /// Triangle vertices in BVH order.
    triangles: Vec<[Vec3; 3]>,
    /// Instance (mesh) index of each triangle, in BVH order.
    instance: Vec<u32>,
    /// Triangle index within its mesh, in BVH order.
    primitive: Vec<u32>,
}

impl CpuScene {
    /// Builds the CWBVH (obvhs's "medium" preset, its default quality/build-time trade-off).
    pub fn build(scene: &Scene) -> Self {
        let mut flat = Vec::with_capacity(scene.triangle_count());
        let mut ids = Vec::with_capacity(scene.triangle_count());
        for (mesh_index, mesh) in scene.meshes().iter().enumerate() {
            for (triangle_index, t) in mesh.triangles.iter().enumerate() {
                flat.push(t.map(|i| mesh.positions[i as usize]));
                ids.push((mesh_index as u32, triangle_index as u32));
            }
        }
        let obvhs_triangles: Vec<Triangle> = flat
            .iter()
            .map(|[a, b, c]| Triangle {
                v0: Vec3A::from(*a),
                v1: Vec3A::from(*b),
                v2: Vec3A::from(*c),
            })
            .collect();
        let mut build_time = Duration::ZERO;
        let bvh = build_cwbvh_from_tris(
            &obvhs_triangles,
            BvhBuildParams::medium_build(),
            &mut build_time,
        );
        let order = &bvh.primitive_indices;
        Self {
            triangles: order.iter().map(|&i| flat[i as usize]).collect(),
            instance: order.iter().map(|&i| ids[i as usize].0).collect(),
            primitive: order.iter().map(|&i| ids[i as usize].1).collect(),
            bvh,
        }
    }
}

impl ClosestHitQuery for CpuScene {
    fn closest_hit(&self, ray: &Ray) -> Hit {
        let watertight = WatertightRay::new(ray.origin, ray.direction);
        let bvh_ray = BvhRay::new(ray.origin.into(), ray.direction.into(), ray.tmin, ray.tmax);
        let mut best = Hit::MISS;
        let mut best_t = ray.tmax;
        let mut obvhs_hit = RayHit::none();
        self.bvh.ray_traverse(bvh_ray, &mut obvhs_hit, |_, slot| {
            let [v0, v1, v2] = self.triangles[slot];
            match watertight.intersect(v0, v1, v2, ray.tmin, best_t) {
                Some(h) if !best.is_hit() || h.t < best_t => {
                    best_t = h.t;
                    best = Hit {
                        t: h.t,
                        primitive: self.primitive[slot],
                        instance: self.instance[slot],
                        barycentrics: h.barycentrics,
                    };
                    h.t
                }
                _ => f32::INFINITY,
            }
        });
        best
    }
}
