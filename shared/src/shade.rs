//! Parameters and stream element types of the shade stage (seed 000's ratio estimator).

use crate::sampling::SamplerParams;
use bytemuck::{Pod, Zeroable};
use glam::Vec4;

/// A surface material as the kernels read it (the glTF 2.0 metallic-roughness model).
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Pod, Zeroable)]
pub struct MaterialParams {
    /// Linear RGB base colour (xyz, each in [0, 1]) and perceptual roughness (w, in [0, 1]).
    pub base_color_roughness: Vec4,
    /// Emitted radiance, linear RGB in W·sr⁻¹·m⁻² (xyz), and metalness (w, in [0, 1]).
    pub emission_metallic: Vec4,
    /// 1 if the surface emits from both faces (glTF's `doubleSided`), 0 if only from its front
    /// face — the side its triangles' counter-clockwise winding faces, where the quad light made
    /// of it emits (pbrt's and Mitsuba's one-sided area lights, whose backs are black).
    pub two_sided_emission: u32,
    /// Explicit padding; always 0.
    pub padding: [u32; 3],
}

const _: () = assert!(core::mem::size_of::<MaterialParams>() == 48);

/// Push constants of the shade stage: one invocation per camera sample (= pixel) of one pass.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct ShadeParams {
    /// The frame's sampler; the stage reads slots `SHADE_STRATEGY`, `SHADE_LIGHT_SELECT` and
    /// `SHADE_DIRECTION`.
    pub sampler: SamplerParams,
    /// Image width in pixels (pixel `(i mod width, i / width)`).
    pub width: u32,
    /// Number of invocations (`width · height`).
    pub count: u32,
    /// Index of the sample within each pixel.
    pub sample_index: u32,
    /// Number of valid lights in the light buffer (a GPU binding cannot be empty, so an unused
    /// buffer holds one dummy element).
    pub light_count: u32,
    /// Number of valid light BVH nodes; 0 selects lights by the linear importance scan.
    pub light_node_count: u32,
    /// 1: each light's specular hit probability `U_S` takes the residual towards GGX — it becomes
    /// the GGX lobe's own integral over the light (`raywave_kernels::shade::slope_quadrature`:
    /// accurate far-tail and grazing `U`, 5–7× the stage's time on the CPU, 5.2–6.6× measured on
    /// the Cornell box, README); 0: the LTC form factors alone.
    pub analytic_residual: u32,
    /// Explicit padding; always 0.
    pub padding: [u32; 2],
}

const _: () = assert!(core::mem::size_of::<ShadeParams>() == 48);
