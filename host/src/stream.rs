//! Host-side SoA streams: one `Vec` per field, in the layout of [`raywave_shared::stream`] (and, for
//! the shade stage's outputs, of the kernels' `ShadeSample`).

use crate::error::{Error, Result};
use glam::{Vec2, Vec4};
use raywave_shared::stream::{HIT_STREAM_BYTES_PER_RAY, NO_HIT, RAY_STREAM_BYTES_PER_RAY};

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
        let fields =
            [("origins", self.origin.len()), ("directions", self.direction.len()), ("pixels", self.pixel.len())];
        check_field_lengths(stage, "ray", &fields)
    }

    /// The rays at `indices`, in their order (each below [`Self::len`] in every field; panics
    /// otherwise, as slice indexing does).
    pub(crate) fn select(&self, indices: &[u32]) -> Self {
        Self {
            origin: select(&self.origin, indices),
            direction: select(&self.direction, indices),
            pixel: select(&self.pixel, indices),
        }
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
        let fields = [
            ("t", self.t.len()),
            ("primitives", self.primitive.len()),
            ("instances", self.instance.len()),
            ("barycentrics", self.barycentrics.len()),
        ];
        check_field_lengths(stage, "hit", &fields)
    }

    /// Whether the stream holds no records.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Records whose ray hit something ([`count_hits`] of the primitives).
    pub fn hit_count(&self) -> usize {
        count_hits(&self.primitive)
    }

    /// Bytes the stream occupies.
    pub fn bytes(&self) -> u64 {
        self.len() as u64 * u64::from(HIT_STREAM_BYTES_PER_RAY)
    }

    /// The records at `indices`, in their order (each below [`Self::len`] in every field; panics
    /// otherwise, as slice indexing does).
    pub(crate) fn select(&self, indices: &[u32]) -> Self {
        Self {
            t: select(&self.t, indices),
            primitive: select(&self.primitive, indices),
            instance: select(&self.instance, indices),
            barycentrics: select(&self.barycentrics, indices),
        }
    }
}

/// How many of a hit stream's `primitive` field hit something (not `NO_HIT`).
pub fn count_hits(primitive: &[u32]) -> usize {
    primitive.iter().filter(|&&p| p != NO_HIT).count()
}

/// The entries of `pixels` whose record in a hit stream's `primitive` field hit something (not
/// `NO_HIT`, as [`count_hits`] counts), in their order; an entry past the stream's end is
/// skipped (a request's check refuses such entries first).
pub fn hits_among(pixels: &[u32], primitive: &[u32]) -> Vec<u32> {
    pixels.iter().copied().filter(|&i| primitive.get(i as usize).is_some_and(|&p| p != NO_HIT)).collect()
}

/// The first `k` where `values[k] ≥ values[k + 1]`: where a list that must be strictly
/// ascending is not.
pub(crate) fn first_not_ascending(values: &[u32]) -> Option<usize> {
    values.windows(2).position(|pair| pair[0] >= pair[1])
}

/// `field`'s entries at `indices`, in their order.
fn select<T: Copy>(field: &[T], indices: &[u32]) -> Vec<T> {
    indices.iter().map(|&i| field[i as usize]).collect()
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
        let fields = [
            ("analytic", self.analytic.len()),
            ("unshadowed", self.unshadowed.len()),
            ("emitted", self.emitted.len()),
            ("shadow origins", self.shadow_origin.len()),
            ("shadow directions", self.shadow_direction.len()),
        ];
        check_field_lengths(stage, "shade", &fields)
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

/// The streams' shared check: every `(field, length)` of a `stream` stream equal, else an error
/// naming `stage` and listing them.
/// Checks that the fields of `rays` and `hits` hold one entry per ray each ([`RayStream::check`],
/// [`HitStream::check`]) and that there is one hit per ray: an error naming `stage` otherwise.
pub(crate) fn check_one_hit_per_ray(rays: &RayStream, hits: &HitStream, stage: &'static str) -> Result<()> {
    rays.check(stage)?;
    hits.check(stage)?;
    if rays.len() != hits.len() {
        let reason = format!("{} rays but {} hits", rays.len(), hits.len());
        return Err(Error::InvalidParameter { name: stage, reason });
    }
    Ok(())
}

fn check_field_lengths(stage: &'static str, stream: &str, fields: &[(&str, usize)]) -> Result<()> {
    if fields.iter().all(|&(_, n)| n == fields[0].1) {
        return Ok(());
    }
    let listed: Vec<String> = fields.iter().map(|(name, n)| format!("{n} {name}")).collect();
    let reason = format!("the {stream} stream's fields differ in length: {}", listed.join(", "));
    Err(Error::InvalidParameter { name: stage, reason })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hit is a record whose primitive is not `NO_HIT`; primitive 0, its mesh's first
    /// triangle, is one (the count `raywave render` reports).
    #[test]
    fn hit_count_counts_the_records_that_name_a_primitive() {
        let mut hits = HitStream::zeroed(4);
        hits.primitive = vec![0, NO_HIT, 7, NO_HIT];
        assert_eq!(hits.hit_count(), 2);
    }

    /// The listed records that hit, by the same rule, keep the list's order; a selection takes
    /// every field's entries at the indices given.
    #[test]
    fn selections_take_the_listed_records_that_hit() {
        let mut hits = HitStream::zeroed(5);
        hits.primitive = vec![0, NO_HIT, 7, 3, NO_HIT];
        hits.t = vec![1.0, 0.0, 3.0, 4.0, 0.0];
        assert_eq!(hits_among(&[1, 2, 3, 4, 9], &hits.primitive), vec![2, 3]);
        assert_eq!(hits_among(&[], &hits.primitive), Vec::<u32>::new());
        let picked = hits.select(&[3, 0]);
        assert_eq!((picked.t, picked.primitive), (vec![4.0, 1.0], vec![3, 0]));
        let mut rays = RayStream::zeroed(5);
        rays.pixel = vec![10, 11, 12, 13, 14];
        rays.direction[2] = Vec4::X;
        let picked = rays.select(&[2, 4]);
        assert_eq!((picked.pixel, picked.direction), (vec![12, 14], vec![Vec4::X, Vec4::ZERO]));
    }
}
