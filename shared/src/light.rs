//! Analytic lights as the kernels read them.

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};

/// Light kinds (values of [`Light::kind`]).
pub mod light_kind {
    /// A sphere emitting uniformly from its surface: `position.xyz` centre, `position.w` radius.
    pub const SPHERE: u32 = 0;
    /// A parallelogram emitting from its front face (the side `edge_u × edge_v` points to), or
    /// both faces when `two_sided` is 1: `position.xyz` corner, `edge_u.xyz`, `edge_v.xyz` edges.
    pub const QUAD: u32 = 1;
}

/// One analytic area light. 80 bytes, 16-byte aligned, so a light list is one storage buffer.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Pod, Zeroable)]
pub struct Light {
    /// Sphere: centre (xyz) and radius (w). Quad: corner (xyz), w = 0.
    pub position: Vec4,
    /// Quad: first edge from the corner (xyz); unused for spheres. w = 0.
    pub edge_u: Vec4,
    /// Quad: second edge from the corner (xyz); unused for spheres. w = 0.
    pub edge_v: Vec4,
    /// Emitted radiance, linear RGB in W·sr⁻¹·m⁻² (xyz); w = 0.
    pub radiance: Vec4,
    /// One of [`light_kind`].
    pub kind: u32,
    /// 1 if a quad emits from both faces, else 0.
    pub two_sided: u32,
    /// The scene mesh (hit records' instance) this light is made of, which it does not light: a
    /// planar emitter lights nothing on itself, and a mesh taken for a quad light may bend off the
    /// light's plane by the emitter fit's tolerance, where the shade stage would see its own
    /// light in front of it. [`Light::NO_MESH`] for a light made of no mesh.
    pub mesh: u32,
    /// Explicit padding; always 0.
    pub padding: u32,
}

const _: () = assert!(core::mem::size_of::<Light>() == 80);

impl Light {
    /// [`Light::mesh`] of a light made of no mesh.
    pub const NO_MESH: u32 = u32::MAX;

    /// This light as the one made of scene mesh `mesh` (see [`Light::mesh`]).
    pub fn made_of(self, mesh: u32) -> Self {
        Self { mesh, ..self }
    }

    /// A sphere light at `centre` of `radius` emitting `radiance` (linear RGB, W·sr⁻¹·m⁻²).
    pub fn sphere(centre: Vec3, radius: f32, radiance: Vec3) -> Self {
        Self {
            position: centre.extend(radius),
            edge_u: Vec4::ZERO,
            edge_v: Vec4::ZERO,
            radiance: radiance.extend(0.0),
            kind: light_kind::SPHERE,
            two_sided: 0,
            mesh: Self::NO_MESH,
            padding: 0,
        }
    }

    /// A parallelogram light `corner + s·edge_u + t·edge_v` (s, t ∈ [0, 1]) emitting `radiance`
    /// towards `edge_u × edge_v`, or from both faces if `two_sided`.
    pub fn quad(corner: Vec3, edge_u: Vec3, edge_v: Vec3, radiance: Vec3, two_sided: bool) -> Self {
        Self {
            position: corner.extend(0.0),
            edge_u: edge_u.extend(0.0),
            edge_v: edge_v.extend(0.0),
            radiance: radiance.extend(0.0),
            kind: light_kind::QUAD,
            two_sided: u32::from(two_sided),
            mesh: Self::NO_MESH,
            padding: 0,
        }
    }
}
const _: () = assert!(core::mem::align_of::<Light>() == 16);

/// Conservative bounds of the emission of one light or of a cluster of lights, after Conty Estevez
/// & Kulla, "Importance Sampling of Many Lights with Adaptive Tree Splitting" (HPG 2018), in the
/// form of pbrt-v4's `LightBounds`: an axis-aligned box, the emitted power, and an orientation cone
/// (every surface normal lies within `θo` of `axis`, and every emitting normal emits only within
/// `θe` of itself) — plus a sphere about the box's centre that holds the lights, which pbrt-v4
/// takes as the box's own bounding sphere: that one grows when a light turns off the axes (√3× a
/// sphere light's radius), so the choice among lights depended on how the scene was rotated.
/// 64 bytes.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Pod, Zeroable)]
pub struct LightBounds {
    /// Box minimum (xyz); w = the bounding-sphere radius of the largest single light inside: the
    /// distance within which the importance stops growing as `1/d²`.
    pub min: Vec4,
    /// Box maximum (xyz); w = the radius of a sphere about the box's centre `(min + max) / 2`
    /// that holds every light inside (for one light its own bounding sphere, which does not
    /// change when the light rotates; never more than the box's half diagonal).
    pub max: Vec4,
    /// Unit axis of the normal cone (xyz); w = 0. Any unit vector when `cos_theta_o` is −1.
    pub axis: Vec4,
    /// Emitted power Φ in W, luminance-weighted (Rec. 709 Y of the RGB radiance); ≥ 0.
    pub phi: f32,
    /// cos θo: every emitter normal lies within θo of `axis` (1: one direction, −1: any direction).
    pub cos_theta_o: f32,
    /// cos θe: each emitter emits only within θe of its normal (0 for diffuse emitters, θe = π/2).
    pub cos_theta_e: f32,
    /// 1 if some emitter is two-sided (emits around its normal and around the opposite direction:
    /// the importance then uses |cos θw|), else 0.
    pub two_sided: u32,
}

const _: () = assert!(core::mem::size_of::<LightBounds>() == 64);
const _: () = assert!(core::mem::align_of::<LightBounds>() == 16);

/// One node of a light BVH: a binary tree over light bounds, stored depth-first in one flat array
/// with node 0 as the root. An interior node's first child is the next node (`index + 1`); its
/// second child is `child_or_light`. A leaf holds exactly one light, `child_or_light`. 80 bytes.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Pod, Zeroable)]
pub struct LightBvhNode {
    /// Bounds of every light below this node.
    pub bounds: LightBounds,
    /// Interior node: index of the second child. Leaf: index of its light in the light list.
    pub child_or_light: u32,
    /// 1 for a leaf, 0 for an interior node.
    pub is_leaf: u32,
    /// Explicit padding; always 0.
    pub padding: [u32; 2],
}

const _: () = assert!(core::mem::size_of::<LightBvhNode>() == 80);
const _: () = assert!(core::mem::align_of::<LightBvhNode>() == 16);
