//! The shade stage (seed 000): form factors of polygonal lights under linearly transformed
//! cosines (analytic U), an optional quadrature residual towards the exact GGX lobe, and the
//! stage that pairs them with stochastic shadows.

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub mod edge_lanes;
pub mod ggx;
pub mod ltc;
pub mod polygon;
pub mod slope_quadrature;
pub mod stage;
pub mod thin_strip;
