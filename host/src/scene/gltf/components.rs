//! Accessor components as the numbers they stand for: each glTF 2.0 component type read from its
//! little-endian bytes, and integer components of a `normalized` accessor mapped into [0, 1] or
//! [−1, 1] (glTF 2.0 § 3.11) — as `KHR_mesh_quantization` stores positions and
//! `EXT_mesh_gpu_instancing` rotations.

use gltf::accessor::DataType;

/// The integer that a normalized component of `data_type` holds for 1 (`2ⁿ − 1` unsigned,
/// `2ⁿ⁻¹ − 1` signed: glTF 2.0 § 3.11); `None` for the types glTF does not normalize (`FLOAT`,
/// `UNSIGNED_INT`).
pub(super) fn normalized_one(data_type: DataType) -> Option<f32> {
    match data_type {
        DataType::I8 => Some(127.0),
        DataType::U8 => Some(255.0),
        DataType::I16 => Some(32767.0),
        DataType::U16 => Some(65535.0),
        DataType::U32 | DataType::F32 => None,
    }
}

/// What the normalized integer component `c` stands for, where `one` ([`normalized_one`]) stands
/// for 1: `max(c / one, −1)` (glTF 2.0 § 3.11; the clamp takes a signed type's lowest value,
/// one step below −`one`, to −1).
pub(super) fn normalized(c: f32, one: f32) -> f32 {
    (c / one).max(-1.0)
}

/// How an accessor stores each component of its elements: its component type, and whether an
/// integer type is `normalized`.
#[derive(Clone, Copy)]
pub(super) struct ComponentFormat {
    /// The component type.
    data_type: DataType,
    /// The number an integer component stands for when the accessor is normalized.
    normalized_one: Option<f32>,
}

impl ComponentFormat {
    /// The format of `accessor`'s components (its `normalized` flag ignored on the types glTF does
    /// not normalize, which [`super::check_accessor`] refuses).
    pub(super) fn of(accessor: &gltf::Accessor) -> Self {
        let data_type = accessor.data_type();
        Self { data_type, normalized_one: normalized_one(data_type).filter(|_| accessor.normalized()) }
    }

    /// Bytes per component.
    pub(super) fn size(self) -> usize {
        self.data_type.size()
    }

    /// The number the component at the start of `bytes` stands for, or `None` where `bytes` is
    /// shorter than [`Self::size`].
    pub(super) fn value(self, bytes: &[u8]) -> Option<f32> {
        let b = bytes.get(..self.size())?;
        let stored = match self.data_type {
            DataType::I8 => f32::from(i8::from_le_bytes([b[0]])),
            DataType::U8 => f32::from(b[0]),
            DataType::I16 => f32::from(i16::from_le_bytes([b[0], b[1]])),
            DataType::U16 => f32::from(u16::from_le_bytes([b[0], b[1]])),
            // Rounded to the nearest `f32` above 2²⁴; no attribute raywave reads is of this type.
            DataType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
            DataType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        };
        Some(self.normalized_one.map_or(stored, |one| normalized(stored, one)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each type's extremes and zero as glTF 2.0 § 3.11 maps them when normalized (the signed
    /// types' lowest value clamped to −1), and as themselves when not.
    #[test]
    fn components_read_as_gltf_maps_them() {
        let format = |data_type, normalized_one| ComponentFormat { data_type, normalized_one };
        let cases: [(DataType, &[u8], f32, f32); 10] = [
            (DataType::I8, &[0x7f], 127.0, 1.0),
            (DataType::I8, &[0x81], -127.0, -1.0),
            (DataType::I8, &[0x80], -128.0, -1.0),
            (DataType::U8, &[0xff], 255.0, 1.0),
            (DataType::U8, &[0x00], 0.0, 0.0),
            (DataType::I16, &[0xff, 0x7f], 32767.0, 1.0),
            (DataType::I16, &[0x00, 0x80], -32768.0, -1.0),
            (DataType::I16, &[0x00, 0xc0], -16384.0, -16384.0 / 32767.0),
            (DataType::U16, &[0xff, 0xff], 65535.0, 1.0),
            (DataType::U16, &[0x01, 0x00], 1.0, 1.0 / 65535.0),
        ];
        for (data_type, bytes, stored, normalized) in cases {
            assert_eq!(format(data_type, None).value(bytes), Some(stored), "{data_type:?} {bytes:?}");
            let one = normalized_one(data_type);
            assert_eq!(format(data_type, one).value(bytes), Some(normalized), "normalized {data_type:?} {bytes:?}");
        }
        assert_eq!(format(DataType::F32, None).value(&1.5f32.to_le_bytes()), Some(1.5));
        assert_eq!(format(DataType::U32, None).value(&7u32.to_le_bytes()), Some(7.0));
        assert_eq!(format(DataType::U16, None).value(&[1]), None, "one byte of two");
        assert_eq!((normalized_one(DataType::F32), normalized_one(DataType::U32)), (None, None));
    }
}
