//! The software-traced scene's memory layout: compressed 8-wide BVH nodes and triangles in BVH
//! leaf order.

use bytemuck::{Pod, Zeroable};

/// One node of a compressed wide BVH8 (Ylitie, Karras & Laine, "Efficient Incoherent Ray Traversal
/// on GPUs Through Compressed Wide BVHs", HPG 2017), byte-for-byte the 80-byte node obvhs 0.4
/// builds (`obvhs::cwbvh::node::CwBvhNode`), with its byte arrays packed into `u32` words so
/// SPIR-V can read them (byte `i` of a word array is `(words[i / 4] >> 8·(i % 4)) & 0xff`).
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Pod, Zeroable)]
pub struct CwBvhNode {
    /// Minimum corner of the node's quantisation grid (scene units).
    pub origin: [f32; 3],
    /// Bytes 0–2: biased exponents of the grid's cell size per axis (cell = 2^(e − 127));
    /// byte 3: `imask`, bit i set when child slot i is an internal node.
    pub exponents_and_imask: u32,
    /// Index of the first internal child node; internal children are stored contiguously.
    pub child_base: u32,
    /// Index of the first triangle referenced by leaf children.
    pub primitive_base: u32,
    /// Per child slot (8 bytes): internal child = `0b001_11xxx` (24 + slot); leaf = triangle count
    /// in unary in the top 3 bits and triangle offset from `primitive_base` (< 24) in the low 5;
    /// empty slot = 0.
    pub child_meta: [u32; 2],
    /// Quantised child bounds, 8 bytes each in the order min x, max x, min y, max y, min z, max z.
    pub child_bounds: [u32; 12],
}

const _: () = assert!(core::mem::size_of::<CwBvhNode>() == 80);
const _: () = assert!(core::mem::align_of::<CwBvhNode>() == 4);

/// Bytes a software-traced scene stores per triangle besides its nodes: three `Vec4` vertices
/// (48 bytes) and its (instance, primitive) id pair (8 bytes).
pub const TRIANGLE_BYTES: u32 = 3 * 16 + 8;
