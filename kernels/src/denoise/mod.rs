//! The denoise stage (seed 000): a total-variation estimate of the shadow ratio's noise drives a
//! separable joint bilateral filter that applies the same weights to `S_N` and `U_N`; the
//! composite is `U · den(S_N) / den(U_N)`. The SVGF-style à-trous filter of the ratio is the
//! baseline it is compared with. Every function here is what both the CPU executor and the
//! SPIR-V entry points run.

pub mod bilateral;
pub mod guide;
pub mod noise;
pub mod svgf;

pub use guide::{edge_stop, Guide};
