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
use raywave_kernels::trace::cwbvh::{CwBvhScene, MAX_TREE_DEPTH};
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
    /// The scene's triangle count; `ids` holds one entry per leaf reference, more than this
    /// where spatial splits reference a triangle from several leaves.
    triangle_count: usize,
    /// obvhs's own BVH, kept for the benchmark that compares against obvhs's traversal.
    obvhs: CwBvh,
    build_time: Duration,
    /// Which build of the kernel traversal the queries run (detected once, at build time).
    isa: TraversalIsa,
}

/// The instruction-set build of the kernel traversal a [`CpuScene`] runs: the same source, compiled
/// for the baseline target or for x86-64-v3 when the CPU has it (detected at run time, so one binary
/// serves every x86-64 CPU). Both give bit-identical hits.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum TraversalIsa {
    /// The compile target's baseline (SSE2 on x86-64).
    Portable,
    /// AVX2, FMA, BMI1/2, LZCNT and POPCNT.
    X86_64V3,
}

impl TraversalIsa {
    /// The best build this CPU runs.
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2")
            && std::is_x86_feature_detected!("fma")
            && std::is_x86_feature_detected!("bmi1")
            && std::is_x86_feature_detected!("bmi2")
            && std::is_x86_feature_detected!("lzcnt")
            && std::is_x86_feature_detected!("popcnt")
        {
            return Self::X86_64V3;
        }
        Self::Portable
    }

    /// The name in benchmark output.
    pub fn name(self) -> &'static str {
        match self {
            Self::Portable => "portable",
            Self::X86_64V3 => "x86-64-v3",
        }
    }
}

impl CpuScene {
    /// Builds the CWBVH with the default preset ([`BvhQuality::default`]). Fails if the tree is
    /// deeper than the kernels' traversal stack walks ([`MAX_TREE_DEPTH`]).
    pub fn build(scene: &Scene) -> Result<Self> {
        Self::build_with(scene, BvhQuality::default())
    }

    /// Builds the CWBVH with obvhs preset `quality`. Spatial splits (the slow preset) may reference
    /// a triangle from several leaves; it is then stored once per reference.
    pub fn build_with(scene: &Scene, quality: BvhQuality) -> Result<Self> {
        #[cfg(feature = "vulkan")]
        crate::vulkan::driver_lock::debug_assert_unheld("a BVH build");
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
        check_tree_depth(scene.name(), tree_depth(&nodes))?;
        let order = &obvhs.primitive_indices;
        let vertices = order
            .iter()
            .flat_map(|&i| {
                let t = flat[i as usize];
                [t.v0, t.v1, t.v2].map(|v| v.extend(0.0))
            })
            .collect();
        let ids = order.iter().map(|&i| ids[i as usize]).collect();
        Ok(Self {
            nodes,
            vertices,
            ids,
            triangle_count: flat.len(),
            obvhs,
            build_time: start.elapsed(),
            isa: TraversalIsa::detect(),
        })
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

    /// The instruction-set build of the traversal this scene's queries run.
    pub fn traversal_isa(&self) -> TraversalIsa {
        self.isa
    }

    /// Runs this scene's queries with `isa` instead of the detected build (for tests comparing the
    /// builds). Fails if the CPU lacks the features `isa` needs.
    pub fn set_traversal_isa(&mut self, isa: TraversalIsa) -> Result<()> {
        if isa == TraversalIsa::X86_64V3 && TraversalIsa::detect() != TraversalIsa::X86_64V3 {
            return Err(Error::InvalidParameter {
                name: "traversal isa",
                reason: "this CPU lacks AVX2, FMA, BMI1/2, LZCNT or POPCNT".into(),
            });
        }
        self.isa = isa;
        Ok(())
    }

    /// Wall-clock time of the whole build (flattening, obvhs build, conversion).
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Bytes of nodes plus triangle data, divided by the scene's triangle count (not the leaf
    /// references, so the slow preset's spatial-split copies count against it).
    pub fn bytes_per_triangle(&self) -> f64 {
        let bytes = std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.vertices.as_slice())
            + std::mem::size_of_val(self.ids.as_slice());
        bytes as f64 / self.triangle_count.max(1) as f64
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
        #[cfg(target_arch = "x86_64")]
        if self.isa == TraversalIsa::X86_64V3 {
            // SAFETY: `isa` is X86_64V3 only where `TraversalIsa::detect` found every feature.
            return unsafe { self.view().closest_hit_x86_64_v3(ray) };
        }
        self.view().closest_hit(ray)
    }
}

impl OcclusionQuery for CpuScene {
    fn occluded(&self, ray: &Ray) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.isa == TraversalIsa::X86_64V3 {
            // SAFETY: as in `closest_hit`.
            return unsafe { self.view().occluded_x86_64_v3(ray) };
        }
        self.view().occluded(ray)
    }
}

/// Refuses a tree deeper than the traversal walks without dropping a subtree
/// ([`MAX_TREE_DEPTH`]) as [`Error::SceneTooLarge`] of `scene`.
fn check_tree_depth(scene: &str, depth: u32) -> Result<()> {
    if depth > MAX_TREE_DEPTH {
        return Err(Error::SceneTooLarge {
            scene: scene.to_owned(),
            what: format!("its BVH is {depth} levels deep, and the traversal walks at most {MAX_TREE_DEPTH}"),
        });
    }
    Ok(())
}

/// Depth of the tree (root = 1): the longest chain of internal nodes, as
/// [`MAX_TREE_DEPTH`] counts it.
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

    #[test]
    fn tree_depth_is_the_longest_chain_of_internal_nodes() {
        // Only the internal-child mask and the first child's index matter here.
        let node = |imask: u32, child_base: u32| CwBvhNode {
            exponents_and_imask: imask << 24,
            child_base,
            ..bytemuck::Zeroable::zeroed()
        };
        assert_eq!(tree_depth(&[node(0, 0)]), 1, "a root holding only leaves");
        // Root → internal children 1 (slot 2) and 2 (slot 5); node 2 → 3 (slot 0) → 4 (slot 7);
        // node 1 holds leaves. The longest chain is 0, 2, 3, 4.
        let nodes = [node(0b10_0100, 1), node(0, 0), node(0b1, 3), node(0b1000_0000, 4), node(0, 0)];
        assert_eq!(tree_depth(&nodes), 4);
        // The same with the deep branch in the first slot: order does not matter.
        let nodes = [node(0b10_0100, 1), node(0b1, 3), node(0, 0), node(0b1000_0000, 4), node(0, 0)];
        assert_eq!(tree_depth(&nodes), 4);
    }

    /// The deepest tree the traversal walks whole (33 levels, the kernels' test shows) is
    /// taken, one level deeper refused.
    #[test]
    fn trees_deeper_than_the_traversal_walks_are_refused() {
        assert_eq!(MAX_TREE_DEPTH, 33);
        assert!(check_tree_depth("deep.obj", MAX_TREE_DEPTH).is_ok());
        match check_tree_depth("deep.obj", MAX_TREE_DEPTH + 1) {
            Err(Error::SceneTooLarge { scene, what }) => {
                assert_eq!(
                    (scene.as_str(), what.as_str()),
                    ("deep.obj", "its BVH is 34 levels deep, and the traversal walks at most 33")
                )
            }
            other => panic!("expected SceneTooLarge, got {other:?}"),
        }
    }

    #[test]
    fn bytes_per_triangle_counts_the_scenes_triangles_not_the_leaf_references() {
        // The slow preset pre-splits large triangles: here two long slivers across a field of
        // 400 small ones end up referenced from several leaves each. The memory is still
        // charged to the scene's triangles.
        let dir = tempfile::tempdir().unwrap();
        let mut obj = String::new();
        for i in 0..400 {
            let (x, z) = ((i % 20) as f32, (i / 20) as f32);
            obj += &format!("v {x} 0 {z}\nv {} 0 {z}\nv {x} 0.1 {}\n", x + 0.1, z + 0.1);
        }
        obj += "v -1 0.5 -1\nv 21 0.6 21\nv -1 0.7 -0.9\nv 21 0.5 -1\nv -1 0.6 21\nv 20.9 0.7 -1\n";
        obj += &(0..402).map(|t| format!("f {} {} {}\n", 3 * t + 1, 3 * t + 2, 3 * t + 3)).collect::<String>();
        let path = dir.path().join("slivers.obj");
        std::fs::write(&path, obj).unwrap();
        let scene = Scene::load(path.to_str().unwrap()).unwrap();
        let cpu = CpuScene::build_with(&scene, BvhQuality::Slow).unwrap();
        assert!(cpu.ids.len() > scene.triangle_count(), "{} references", cpu.ids.len());
        let bytes = std::mem::size_of_val(cpu.nodes.as_slice())
            + std::mem::size_of_val(cpu.vertices.as_slice())
            + std::mem::size_of_val(cpu.ids.as_slice());
        assert_eq!(cpu.bytes_per_triangle(), bytes as f64 / scene.triangle_count() as f64);
    }

    /// Rays from random points of the scene's bounding box in random directions, some of them
    /// axis-aligned (with ±0 components), with random interval ends.
    fn random_rays(scene: &Scene, count: u32) -> Vec<Ray> {
        use raywave_kernels::hash::{pcg3d, unit_float};
        let (lo, hi) = scene.bounds();
        (0..count)
            .map(|i| {
                let [a, b] = [pcg3d(glam::UVec3::new(i, 1, 5)), pcg3d(glam::UVec3::new(i, 2, 5))];
                let origin = lo + (hi - lo) * glam::Vec3::new(unit_float(a.x), unit_float(a.y), unit_float(a.z));
                let mut direction = glam::Vec3::new(unit_float(b.x), unit_float(b.y), unit_float(b.z)) * 2.0 - 1.0;
                if i % 5 == 0 {
                    direction =
                        [glam::Vec3::X, glam::Vec3::NEG_Y, glam::Vec3::new(-0.0, 0.0, 1.0)][(i / 5 % 3) as usize];
                }
                let tmax = if b.x & 1 == 0 { 1e30 } else { (hi - lo).length() * unit_float(b.y) };
                Ray { origin, direction, tmin: 0.0, tmax }
            })
            .collect()
    }

    #[test]
    fn every_instruction_set_build_gives_identical_hits() {
        let scene = Scene::load("builtin:hairball").unwrap();
        let mut cpu = CpuScene::build(&scene).unwrap();
        let rays = random_rays(&scene, 20_000);
        cpu.set_traversal_isa(TraversalIsa::Portable).unwrap();
        let portable: Vec<(Hit, bool)> = rays.iter().map(|r| (cpu.closest_hit(r), cpu.occluded(r))).collect();
        assert!(portable.iter().filter(|(hit, _)| hit.is_hit()).count() > 1_000, "the rays must hit something");
        if TraversalIsa::detect() == TraversalIsa::Portable {
            // Nothing else to compare on this CPU; asking for the other build must fail cleanly.
            assert!(cpu.set_traversal_isa(TraversalIsa::X86_64V3).is_err());
            // CI's x86-64 machines run the x86-64-v3 build: there the comparison must happen.
            let ci_x86 = cfg!(target_arch = "x86_64") && crate::in_ci();
            assert!(!ci_x86, "no x86-64-v3 on this CI machine: the builds cannot be compared");
            std::eprintln!("SKIP: this CPU runs only the portable traversal: nothing to compare it with");
            return;
        }
        cpu.set_traversal_isa(TraversalIsa::X86_64V3).unwrap();
        for (ray, expected) in rays.iter().zip(&portable) {
            assert_eq!((cpu.closest_hit(ray), cpu.occluded(ray)), *expected, "{ray:?}");
        }
    }
}
