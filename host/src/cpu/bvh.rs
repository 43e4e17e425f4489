//! The software-traced scene: obvhs builds a compressed wide BVH8 over all triangles; its nodes are
//! reinterpreted (byte-identical) as [`CwBvhNode`]s and traversed by the kernels' own traversal,
//! the same code the Vulkan software trace runs.

use crate::error::{Error, Result};
use crate::scene::Scene;
use glam::{UVec2, Vec3A, Vec4};
use obvhs::cwbvh::{builder::build_cwbvh_from_tris, CwBvh};
use obvhs::ray::{Ray as BvhRay, RayHit};
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use raywave_kernels::trace::cwbvh::{CwBvhScene, STACK_SIZE};
use raywave_kernels::trace::{ClosestHitQuery, Hit, OcclusionQuery, Ray};
use raywave_kernels::triangle::WatertightRay;
use raywave_shared::bvh::CwBvhNode;
use std::time::{Duration, Instant};

/// obvhs's CWBVH build presets (`BvhBuildParams`). The default, `Fast`, was chosen by
/// `raywave bench trace --bvh …` on the 2-core CI machine: it built fastest and traced as fast or
/// faster than the others (sphere field, 2 threads, primary/shadow/diffuse Mrays/s: fast
/// 2.90/3.32/2.24, medium 2.62/3.19/2.18, slow 2.36/3.37/2.01; hairball: fast 0.91/0.59/0.46,
/// medium 0.86/0.53/0.45, slow 0.91/0.59/0.45).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Default)]
pub enum BvhQuality {
    /// `fast_build`: low PLOC search distance, little reinsertion.
    #[default]
    Fast,
    /// `medium_build`: obvhs's "about Embree's build time" preset.
    Medium,
    /// `slow_build`: high search distance, more reinsertion, pre-splitting of large triangles.
    Slow,
}

impl BvhQuality {
    /// The preset's name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::Fast => "fast",
            Self::Medium => "medium",
            Self::Slow => "slow",
        }
    }

    fn params(self) -> BvhBuildParams {
        match self {
            Self::Fast => BvhBuildParams::fast_build(),
            Self::Medium => BvhBuildParams::medium_build(),
            Self::Slow => BvhBuildParams::slow_build(),
        }
    }
}

impl std::str::FromStr for BvhQuality {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        match s {
            "fast" => Ok(Self::Fast),
            "medium" => Ok(Self::Medium),
            "slow" => Ok(Self::Slow),
            _ => Err(Error::InvalidParameter { name: "bvh", reason: format!("{s:?}: expected fast, medium or slow") }),
        }
    }
}

/// A scene prepared for software tracing: CWBVH nodes, triangle vertices in BVH leaf order (three
/// `Vec4` each) and the (instance, primitive) ids a Vulkan TLAS/BLAS pair would report.
pub struct CpuScene {
    nodes: Vec<CwBvhNode>,
    vertices: Vec<Vec4>,
    ids: Vec<UVec2>,
    /// obvhs's own BVH, kept for the benchmark that compares against obvhs's traversal.
    obvhs: CwBvh,
    build_time: Duration,
}

impl CpuScene {
    /// Builds the CWBVH with the default preset ([`BvhQuality::default`]). Fails if the tree is
    /// deeper than the kernels' traversal stack.
    pub fn build(scene: &Scene) -> Result<Self> {
        Self::build_with(scene, BvhQuality::default())
    }

    /// Builds the CWBVH with obvhs preset `quality`. Spatial splits (the slow preset) may reference
    /// a triangle from several leaves; it is then stored once per reference.
    pub fn build_with(scene: &Scene, quality: BvhQuality) -> Result<Self> {
        let start = Instant::now();
        let mut flat = Vec::with_capacity(scene.triangle_count());
        let mut ids = Vec::with_capacity(scene.triangle_count());
        for (mesh_index, mesh) in scene.meshes().iter().enumerate() {
            for (triangle_index, t) in mesh.triangles.iter().enumerate() {
                let [a, b, c] = t.map(|i| Vec3A::from(mesh.positions[i as usize]));
                flat.push(Triangle { v0: a, v1: b, v2: c });
                ids.push(UVec2::new(mesh_index as u32, triangle_index as u32));
            }
        }
        let mut core_time = Duration::ZERO;
        let obvhs = build_cwbvh_from_tris(&flat, quality.params(), &mut core_time);
        let nodes: Vec<CwBvhNode> = bytemuck::cast_slice(&obvhs.nodes).to_vec();
        let depth = tree_depth(&nodes);
        if depth >= STACK_SIZE as u32 {
            return Err(Error::SceneTooLarge {
                scene: scene.name().to_owned(),
                what: format!("BVH depth {depth} (traversal stack holds {STACK_SIZE})"),
            });
        }
        let order = &obvhs.primitive_indices;
        let vertices = order
            .iter()
            .flat_map(|&i| {
                let t = flat[i as usize];
                [t.v0, t.v1, t.v2].map(|v| v.extend(0.0))
            })
            .collect();
        let ids = order.iter().map(|&i| ids[i as usize]).collect();
        Ok(Self { nodes, vertices, ids, obvhs, build_time: start.elapsed() })
    }

    /// The scene as the trace kernels read it.
    pub fn view(&self) -> CwBvhScene<'_> {
        CwBvhScene { nodes: &self.nodes, vertices: &self.vertices, ids: &self.ids }
    }

    /// BVH nodes, for upload to a device.
    pub fn nodes(&self) -> &[CwBvhNode] {
        &self.nodes
    }

    /// Triangle vertices in BVH order (three per triangle), for upload to a device.
    pub fn vertices(&self) -> &[Vec4] {
        &self.vertices
    }

    /// (instance, primitive) per triangle in BVH order, for upload to a device.
    pub fn ids(&self) -> &[UVec2] {
        &self.ids
    }

    /// Wall-clock time of the whole build (flattening, obvhs build, conversion).
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Bytes of nodes plus triangle data, divided by the triangle count.
    pub fn bytes_per_triangle(&self) -> f64 {
        let bytes = std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.vertices.as_slice())
            + std::mem::size_of_val(self.ids.as_slice());
        bytes as f64 / self.ids.len().max(1) as f64
    }

    /// Closest hit through obvhs's own `CwBvh::ray_traverse` with the same watertight triangle
    /// test: the reference the benchmarks compare the kernel traversal against.
    pub fn obvhs_closest_hit(&self, ray: &Ray) -> Hit {
        let watertight = WatertightRay::new(ray.origin, ray.direction);
        let bvh_ray = BvhRay::new(ray.origin.into(), ray.direction.into(), ray.tmin, ray.tmax);
        let mut best = Hit::MISS;
        let mut best_t = ray.tmax;
        let mut obvhs_hit = RayHit::none();
        self.obvhs.ray_traverse(bvh_ray, &mut obvhs_hit, |_, slot| {
            let v = &self.vertices[slot * 3..slot * 3 + 3];
            match watertight.intersect(v[0].truncate(), v[1].truncate(), v[2].truncate(), ray.tmin, best_t) {
                Some(h) if !best.is_hit() || h.t < best_t => {
                    best_t = h.t;
                    let id = self.ids[slot];
                    best = Hit { t: h.t, primitive: id.y, instance: id.x, barycentrics: h.barycentrics };
                    h.t
                }
                _ => f32::INFINITY,
            }
        });
        best
    }
}

impl CpuScene {
    /// Occlusion through obvhs's own early-exit `CwBvh::ray_traverse_miss`, with the same
    /// watertight test: the reference the benchmarks compare the kernel traversal against.
    pub fn obvhs_occluded(&self, ray: &Ray) -> bool {
        let watertight = WatertightRay::new(ray.origin, ray.direction);
        let bvh_ray = BvhRay::new(ray.origin.into(), ray.direction.into(), ray.tmin, ray.tmax);
        !self.obvhs.ray_traverse_miss(bvh_ray, |_, slot| {
            let v = &self.vertices[slot * 3..slot * 3 + 3];
            watertight
                .intersect(v[0].truncate(), v[1].truncate(), v[2].truncate(), ray.tmin, ray.tmax)
                .map_or(f32::INFINITY, |h| h.t)
        })
    }
}

impl ClosestHitQuery for CpuScene {
    fn closest_hit(&self, ray: &Ray) -> Hit {
        self.view().closest_hit(ray)
    }
}

impl OcclusionQuery for CpuScene {
    fn occluded(&self, ray: &Ray) -> bool {
        self.view().occluded(ray)
    }
}

/// Depth of the tree (root = 1): the longest chain of internal children.
fn tree_depth(nodes: &[CwBvhNode]) -> u32 {
    let mut deepest = 0;
    let mut pending = vec![(0u32, 1u32)];
    while let Some((index, depth)) = pending.pop() {
        deepest = deepest.max(depth);
        let node = &nodes[index as usize];
        let internal_children = (node.exponents_and_imask >> 24).count_ones();
        pending.extend((0..internal_children).map(|k| (node.child_base + k, depth + 1)));
    }
    deepest
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_node_layout_is_obvhs_layout() {
        let scene = Scene::load("builtin:cornell").unwrap();
        let cpu = CpuScene::build(&scene).unwrap();
        let original = &cpu.obvhs.nodes[0];
        let shared = &cpu.nodes[0];
        assert_eq!(shared.origin, original.p.to_array());
        assert_eq!(
            shared.exponents_and_imask.to_le_bytes(),
            [original.e[0], original.e[1], original.e[2], original.imask]
        );
        assert_eq!(shared.child_base, original.child_base_idx);
        assert_eq!(shared.primitive_base, original.primitive_base_idx);
        assert_eq!(bytemuck::bytes_of(&shared.child_meta), &original.child_meta);
        assert_eq!(&bytemuck::bytes_of(&shared.child_bounds)[8..16], &original.child_max_x);
        assert_eq!(&bytemuck::bytes_of(&shared.child_bounds)[40..48], &original.child_max_z);
        assert!(tree_depth(&cpu.nodes) >= 1);
    }
}
