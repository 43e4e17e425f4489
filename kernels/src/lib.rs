//! raywave's stages, written once as plain `no_std` functions.
//!
//! Every stage is a pure function of an invocation index, its parameters and its inputs. The CPU
//! executor in `raywave-host` calls these functions over the same index range that a Vulkan
//! dispatch covers, and the [`entry`] module wraps them as `#[spirv(compute)]` entry points for the
//! SPIR-V build, so CPU tests and CPU–GPU parity tests exercise the very same math.
#![no_std]
#![cfg_attr(all(target_arch = "spirv", feature = "ray-query"), feature(asm_experimental_arch))]

#[cfg(test)]
extern crate std;

pub mod denoise;
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
