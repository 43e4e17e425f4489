//! Probes that expose the samplers and warps as streams, so the very same numbers can be produced
//! on the CPU and by a SPIR-V dispatch and compared (bit-exact for the sampler's integers).

use super::{sampler, warp};
use glam::{UVec2, Vec4};
use raywave_shared::{SamplerProbeParams, WarpParams};

/// Raw bits of sample `i` of the sampler probe: pixel `i >> spp_log2` in row-major order, sample
/// `i mod 2^spp_log2`, slot `params.dimension`.
pub fn sampler_probe(i: u32, params: &SamplerProbeParams) -> UVec2 {
    let spp_log2 = params.sampler.spp_log2.min(31);
    let pixel_index = i >> spp_log2;
    let width = params.width.max(1);
    let pixel = UVec2::new(pixel_index % width, pixel_index / width);
    sampler::sample_bits(&params.sampler, pixel, i & ((1u32 << spp_log2) - 1), params.dimension)
}

/// Sample `i` of the warp probe: warp `params.kind` applied to sample `i` of `params.sampler` at
/// pixel (0, 0), slot 0. xyz = direction, w = pdf.
pub fn warp_probe(i: u32, params: &WarpParams) -> Vec4 {
    let u = sampler::sample_2d(&params.sampler, UVec2::ZERO, i, 0);
    warp::sample(params, u)
}
