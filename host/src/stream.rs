//! Host-side SoA streams: one `Vec` per field, in the layout of [`raywave_shared::stream`] (and, for
//! the shade stage's outputs, of the kernels' `ShadeSample`).

use crate::error::{Error, Result};
use glam::{Vec2, Vec4};
use raywave_shared::stream::{HIT_STREAM_BYTES_PER_RAY, RAY_STREAM_BYTES_PER_RAY};

/// The ray stream: what generate writes and trace reads.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RayStream {
    /// xyz origin, w = tmin.
    pub origin: Vec<Vec4>,
    /// xyz direction, w = tmax.
    pub direction: Vec<Vec4>,
    /// Linear pixel index of each ray.
    pub pixel: Vec<u32>,
}

impl RayStream {
    /// A zero-filled stream of `len` rays.
    pub fn zeroed(len: usize) -> Self {
        Self { origin: vec![Vec4::ZERO; len], direction: vec![Vec4::ZERO; len], pixel: vec![0; len] }
    }

    /// Number of rays.
    pub fn len(&self) -> usize {
        self.pixel.len()
    }

    /// Whether the stream holds no rays.
    pub fn is_empty(&self) -> bool {
        self.pixel.is_empty()
    }

    /// Bytes the stream occupies.
    pub fn bytes(&self) -> u64 {
        self.len() as u64 * u64::from(RAY_STREAM_BYTES_PER_RAY)
    }

    /// Checks that the fields hold one entry per ray each: an error naming `stage` otherwise (the
    /// trace stages read origins and directions for `len()` rays, which the pixel field counts).
    pub fn check(&self, stage: &'static str) -> Result<()> {
        if self.origin.len() == self.len() && self.direction.len() == self.len() {
            return Ok(());
        }
        Err(Error::InvalidParameter {
            name: stage,
            reason: format!(
                "the ray stream's fields differ in length: {} origins, {} directions, {} pixels",
                self.origin.len(),
                self.direction.len(),
                self.pixel.len()
            ),
        })
    }
}

/// The hit stream: what trace writes, one record per ray.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HitStream {
    /// Ray parameter of the closest hit; 0 on a miss.
    pub t: Vec<f32>,
    /// Triangle index within the instance's mesh, or `NO_HIT`.
    pub primitive: Vec<u32>,
    /// Instance (mesh) index, or `NO_HIT`.
    pub instance: Vec<u32>,
    /// Weights of vertices 1 and 2.
    pub barycentrics: Vec<Vec2>,
}

impl HitStream {
    /// A zero-filled stream of `len` records.
    pub fn zeroed(len: usize) -> Self {
        Self { t: vec![0.0; len], primitive: vec![0; len], instance: vec![0; len], barycentrics: vec![Vec2::ZERO; len] }
    }

    /// Number of records.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Checks that the fields hold one entry per record each: an error naming `stage` otherwise.
    pub fn check(&self, stage: &'static str) -> Result<()> {
        let lengths = [self.primitive.len(), self.instance.len(), self.barycentrics.len()];
        if lengths.iter().all(|&n| n == self.len()) {
            return Ok(());
        }
        let reason = format!(
            "the hit stream's fields differ in length: {} t, {} primitives, {} instances, {} barycentrics",
            self.len(),
            lengths[0],
            lengths[1],
            lengths[2]
        );
        Err(Error::InvalidParameter { name: stage, reason })
    }

    /// Whether the stream holds no records.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Bytes the stream occupies.
    pub fn bytes(&self) -> u64 {
        self.len() as u64 * u64::from(HIT_STREAM_BYTES_PER_RAY)
    }
}

/// The shade stream: what the shade stage writes, one record per camera ray (ray `i` is pixel `i`
/// of the pass). The fields of the kernels' `ShadeSample`, one `Vec` each.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ShadeStream {
    /// Analytic unshadowed radiance `U` (rgb; w = 0).
    pub analytic: Vec<Vec4>,
    /// This sample's contribution to `U_N` (rgb; w = 0); its contribution to `S_N` is the same
    /// times the shadow ray's visibility.
    pub unshadowed: Vec<Vec4>,
    /// Radiance emitted by the surface itself towards the camera (rgb; w = 0).
    pub emitted: Vec<Vec4>,
    /// Shadow-ray origin (xyz), w = tmin.
    pub shadow_origin: Vec<Vec4>,
    /// Shadow-ray direction (xyz), w = tmax; tmax = 0 when there is nothing to trace.
    pub shadow_direction: Vec<Vec4>,
}

/// Bytes per camera ray in the shade stream (five `Vec4` fields).
pub const SHADE_STREAM_BYTES_PER_RAY: u32 = 5 * std::mem::size_of::<Vec4>() as u32;

impl ShadeStream {
    /// A zero-filled stream of `len` records.
    pub fn zeroed(len: usize) -> Self {
        let zero = vec![Vec4::ZERO; len];
        Self {
            analytic: zero.clone(),
            unshadowed: zero.clone(),
            emitted: zero.clone(),
            shadow_origin: zero.clone(),
            shadow_direction: zero,
        }
    }

    /// Number of records.
    pub fn len(&self) -> usize {
        self.analytic.len()
    }

    /// Checks that the fields hold one entry per record each: an error naming `stage` otherwise.
    pub fn check(&self, stage: &'static str) -> Result<()> {
        let fields = [&self.unshadowed, &self.emitted, &self.shadow_origin, &self.shadow_direction];
        if fields.iter().all(|f| f.len() == self.len()) {
            return Ok(());
        }
        let reason = format!(
            "the shade stream's fields differ in length: {} analytic, {:?} unshadowed, emitted, shadow origins and directions",
            self.len(),
            fields.map(|f| f.len())
        );
        Err(Error::InvalidParameter { name: stage, reason })
    }

    /// Whether the stream holds no records.
    pub fn is_empty(&self) -> bool {
        self.analytic.is_empty()
    }

    /// Bytes the stream occupies.
    pub fn bytes(&self) -> u64 {
        self.len() as u64 * u64::from(SHADE_STREAM_BYTES_PER_RAY)
    }
}
