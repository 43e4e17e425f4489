//! Sampling: where the random numbers come from and how they become directions.
//!
//! Seed 002 (Pharr 2018) is the brief: choose rays wisely (importance warps with their pdfs, light
//! selection by a contribution bound) and choose the (not-)random numbers carefully (Owen-scrambled
//! Sobol' with blue-noise screen-space error). Every function here is a pure function of its
//! inputs, `no_std`, and the same on the CPU and in SPIR-V.
//!
//! - [`sampler`]: `(pixel, sample index, dimension) → [0, 1−2⁻²⁴]²` for the three samplers of
//!   [`raywave_shared::sampling::sampler_kind`], built on [`sobol`] and [`owen`].
//! - [`dims`]: the explicit allocation of sampler dimensions to stages.
//! - [`warp`]: `[0,1)² →` directions, each with its pdf.
//! - [`light_select`]: choosing one light among many, uniformly or by importance.
//! - [`probe`]: the sampler and warp probes behind the CPU–SPIR-V parity tests.

pub mod dims;
pub mod light_select;
pub mod owen;
pub mod probe;
pub mod sampler;
pub mod sobol;
pub mod warp;
