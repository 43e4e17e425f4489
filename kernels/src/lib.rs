//! raywave's stages, written once as plain `no_std` functions.
//!
//! Every stage is a pure function of an invocation index, its parameters and its inputs. The CPU
//! executor in `raywave-host` calls these functions over the same index range that a Vulkan
//! dispatch covers, and the `entry` module (behind the `entry-points` feature, which the host's
//! SPIR-V build enables) wraps them as `#[spirv(compute)]` entry points, so CPU tests and CPU–GPU
//! parity tests exercise the very same math. An engine's own rust-gpu shader crate that calls the
//! stage functions leaves the feature off and gets only its own entry points.
#![no_std]
#![cfg_attr(all(target_arch = "spirv", feature = "ray-query"), feature(asm_experimental_arch))]

#[cfg(test)]
extern crate std;

pub mod denoise;
#[cfg(feature = "entry-points")]
pub mod entry;
pub mod generate;
pub mod hash;
pub mod offset;
pub mod sampling;
pub mod sanitized;
pub mod shade;
pub mod trace;
pub mod triangle;
pub mod trig;

pub use raywave_shared as shared;
