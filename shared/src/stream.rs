//! Element types and sentinels of the SoA streams that stages pass to each other.
//!
//! Streams are split at field granularity (one buffer per field) so a stage touches only the bytes
//! it needs. Where two scalars always travel together they share a 16-byte lane:
//!
//! | stream | field | element | meaning |
//! |---|---|---|---|
//! | rays | origin | [`Vec4`](glam::Vec4) | xyz origin (scene units), w = `tmin` |
//! | rays | direction | [`Vec4`](glam::Vec4) | xyz direction (unit length from generate), w = `tmax` |
//! | rays | pixel | `u32` | linear pixel index `y · width + x` |
//! | hits | t | `f32` | ray parameter of the closest hit; 0 on a miss |
//! | hits | primitive | `u32` | triangle index within its instance's mesh; [`NO_HIT`] on a miss |
//! | hits | instance | `u32` | index of the instance (mesh) hit; [`NO_HIT`] on a miss |
//! | hits | barycentrics | [`Vec2`](glam::Vec2) | weights (u, v) of vertices 1 and 2 (Vulkan's convention); 0 on a miss |

/// Primitive and instance id written for a ray that hit nothing.
pub const NO_HIT: u32 = u32::MAX;

/// Bytes per ray in the ray stream (origin + direction + pixel).
pub const RAY_STREAM_BYTES_PER_RAY: u32 = 16 + 16 + 4;

/// Bytes per ray in the hit stream (t + primitive + instance + barycentrics).
pub const HIT_STREAM_BYTES_PER_RAY: u32 = 4 + 4 + 4 + 8;
