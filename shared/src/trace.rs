//! Parameters of the trace stage.

use bytemuck::{Pod, Zeroable};

/// Push constants of the trace stage.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct TraceParams {
    /// Number of valid rays in the ray stream; invocations at or past it do nothing.
    pub ray_count: u32,
    /// Explicit padding to 16 bytes; always 0.
    pub padding: [u32; 3],
}

const _: () = assert!(core::mem::size_of::<TraceParams>() == 16);
const _: () = assert!(core::mem::align_of::<TraceParams>() == 4);
