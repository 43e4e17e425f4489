//! `EXT_mesh_gpu_instancing`, a vendor extension (KhronosGroup/glTF,
//! `extensions/2.0/Vendor/EXT_mesh_gpu_instancing`) that foliage, crowds and `gltfpack -mi`
//! output use: a node places its mesh once per instance, at `NodeWorldXform · T · R · S`, the
//! instance's translation, rotation (a unit quaternion) and scale read from accessors named by
//! the extension's `attributes`. The non-instanced mesh is not drawn (the extension's note).

use super::components::{normalized, normalized_one};
use super::{check_accessor, holds_zeros, unreadable, AccessorUse, CheckedAccessors, TRANSFORM_TOLERANCE};
use glam::{Mat4, Quat, Vec3};
use gltf::accessor::util::{Item, Iter};
use gltf::accessor::DataType;
use gltf::buffer;
use gltf::json::Value;
use gltf::Document;

/// The extension's name, as files list it in `extensionsUsed` and on nodes.
pub(super) const EXTENSION: &str = "EXT_mesh_gpu_instancing";

/// The attributes that make an instance's transform, each read as the extension's table allows;
/// any other attribute (custom ones, such as `_ID`, are prefixed with an underscore) only counts
/// instances.
const TRANSFORM_ATTRIBUTES: [(&str, AccessorUse); 3] = [
    ("TRANSLATION", AccessorUse::InstanceTranslation),
    ("ROTATION", AccessorUse::InstanceRotation),
    ("SCALE", AccessorUse::InstanceScale),
];

/// The transforms, in `node`'s space, of the instances `node` places its mesh at by
/// [`EXTENSION`]: each `T · R · S`, a part missing from `attributes` the identity. `None` where
/// the node has no mesh (the extension defines nothing there), no such extension, or one
/// without `attributes` (nothing says how many instances): the mesh is drawn once, at the node.
///
/// Errors name the JSON field: an `attributes` that is not an object of accessor indices or is
/// empty (the schema's `minProperties` 1), an index without its accessor, accessors of different
/// counts (the extension requires one count), an accessor of a type the extension's table does
/// not allow or outside its buffer ([`check_accessor`], unless `checked` holds it), a translation
/// or scale that is not finite, a rotation that is not a unit quaternion within
/// [`TRANSFORM_TOLERANCE`] plus the rounding of its component type (a normalized `BYTE` rounds
/// each component to 1/254, so a unit quaternion may be up to 1/127 off). Rotations are
/// normalized.
pub(super) fn instance_transforms(
    document: &Document,
    node: &gltf::Node,
    buffers: &[buffer::Data],
    checked: &mut CheckedAccessors,
) -> Result<Option<Vec<Mat4>>, String> {
    let Some(extension) = node.mesh().and(node.extension_value(EXTENSION)) else { return Ok(None) };
    let field = format!("nodes[{}].extensions.{EXTENSION}", node.index());
    let Some(attributes) = extension.get("attributes") else { return Ok(None) };
    let Value::Object(attributes) = attributes else {
        return Err(format!("{field}.attributes: not an object of accessor indices"));
    };
    let mut count = None;
    let mut accessors = Vec::new();
    for (name, index) in attributes {
        let attribute_field = format!("{field}.attributes.{name}");
        let accessor = index
            .as_u64()
            .and_then(|index| document.accessors().nth(usize::try_from(index).ok()?))
            .ok_or_else(|| format!("{attribute_field}: {index} is not the index of an accessor"))?;
        match count {
            None => count = Some((accessor.count(), name)),
            Some((first, first_name)) if first != accessor.count() => {
                return Err(format!(
                    "{attribute_field}: accessor {} has {} elements, attributes.{first_name} {first}; the extension \
                     requires one count",
                    accessor.index(),
                    accessor.count()
                ));
            }
            Some(_) => {}
        }
        accessors.push((name.as_str(), accessor, attribute_field));
    }
    let Some((count, _)) = count else {
        return Err(format!("{field}.attributes: empty; the extension requires at least one attribute"));
    };
    let (mut translations, mut rotations, mut scales) =
        (vec![Vec3::ZERO; count], vec![Quat::IDENTITY; count], vec![Vec3::ONE; count]);
    for (name, accessor, attribute_field) in accessors {
        let Some(&(_, use_)) = TRANSFORM_ATTRIBUTES.iter().find(|(known, _)| *known == name) else { continue };
        if checked.insert((accessor.index(), use_)) {
            check_accessor(&accessor, buffers, &attribute_field, use_)?;
        }
        match use_ {
            AccessorUse::InstanceRotation => rotations = read_rotations(&accessor, buffers, &attribute_field)?,
            _ => {
                let vectors: Vec<Vec3> =
                    read::<[f32; 3]>(&accessor, buffers, &attribute_field)?.into_iter().map(Vec3::from).collect();
                if let Some((k, v)) = vectors.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                    return Err(format!("{attribute_field}: element {k} is {v}; each component must be finite"));
                }
                *(if use_ == AccessorUse::InstanceScale { &mut scales } else { &mut translations }) = vectors;
            }
        }
    }
    let transforms =
        (0..count).map(|k| Mat4::from_scale_rotation_translation(scales[k], rotations[k], translations[k])).collect();
    Ok(Some(transforms))
}

/// The unit quaternions of a ROTATION accessor (checked: VEC4 of `FLOAT`, normalized `BYTE` or
/// normalized `SHORT`), each normalized after its length is checked ([`instance_transforms`]).
fn read_rotations(accessor: &gltf::Accessor, buffers: &[buffer::Data], field: &str) -> Result<Vec<Quat>, String> {
    let stored: Vec<[f32; 4]> = match accessor.data_type() {
        DataType::I8 => read::<[i8; 4]>(accessor, buffers, field)?.into_iter().map(|q| q.map(f32::from)).collect(),
        DataType::I16 => read::<[i16; 4]>(accessor, buffers, field)?.into_iter().map(|q| q.map(f32::from)).collect(),
        _ => read::<[f32; 4]>(accessor, buffers, field)?,
    };
    // Normalized integers (the only integer types allowed here) for 1; `None` for `f32`.
    let one = normalized_one(accessor.data_type());
    let quaternions = stored.into_iter().map(|q| one.map_or(q, |one| q.map(|c| normalized(c, one))));
    // Each component rounds by at most half a step, so the length by at most 1/one.
    let tolerance = TRANSFORM_TOLERANCE + one.map_or(0.0, f32::recip);
    quaternions
        .enumerate()
        .map(|(k, q)| {
            let length = glam::Vec4::from_array(q).length();
            // Written so that a NaN length fails too.
            if (length - 1.0).abs() <= tolerance {
                Ok(Quat::from_array(q).normalize())
            } else {
                Err(format!("{field}: element {k} is {q:?}, {length} long; the extension requires a unit quaternion"))
            }
        })
        .collect()
}

/// Every element of `accessor` (checked by [`check_accessor`], its elements `T`), read by the
/// `gltf` crate's reader, which applies sparse substitutions, or zeros ([`holds_zeros`]).
fn read<T: Item + Copy>(accessor: &gltf::Accessor, buffers: &[buffer::Data], field: &str) -> Result<Vec<T>, String> {
    if holds_zeros(accessor) {
        return Ok(vec![T::zero(); accessor.count()]);
    }
    let elements =
        Iter::<T>::new(accessor.clone(), |buffer: buffer::Buffer| buffers.get(buffer.index()).map(|data| &data.0[..]))
            .ok_or_else(|| unreadable(accessor, field))?;
    Ok(elements.collect())
}
