//! glTF 2.0 scenes (through the `gltf` crate): the default scene's node hierarchy with its
//! transforms, every triangle primitive as a mesh, metallic-roughness materials with emission
//! (and `KHR_materials_emissive_strength`), and the first perspective camera, if any.

use super::{framing_camera, Camera, Material, Mesh, Scene};
use crate::error::{Error, Result};
use glam::{Mat4, Vec3};
use std::path::Path;

/// Loads and validates a `.gltf` or `.glb` file.
pub fn load(path: &Path) -> Result<Scene> {
    let load_error = |message: String| Error::SceneLoad { path: path.to_owned(), message };
    let (document, buffers, _images) = gltf::import(path).map_err(|e| load_error(e.to_string()))?;
    let scene = document
        .default_scene()
        .or_else(|| document.scenes().next())
        .ok_or_else(|| load_error("the file defines no scene".into()))?;
    let mut meshes = Vec::new();
    let mut camera = None;
    // Depth-first over the node tree, carrying each node's world transform.
    let mut pending: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    while let Some((node, parent)) = pending.pop() {
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let (None, Some(node_camera)) = (&camera, node.camera()) {
            if let gltf::camera::Projection::Perspective(p) = node_camera.projection() {
                camera = Some(Camera {
                    position: world.transform_point3(Vec3::ZERO),
                    look_at: world.transform_point3(Vec3::NEG_Z),
                    up: world.transform_vector3(Vec3::Y),
                    vertical_fov_degrees: p.yfov().to_degrees(),
                });
            }
        }
        if let Some(mesh) = node.mesh() {
            for (index, primitive) in mesh.primitives().enumerate() {
                let name = format!("{} primitive {index}", mesh.name().unwrap_or("mesh"));
                if primitive.mode() != gltf::mesh::Mode::Triangles {
                    return Err(load_error(format!(
                        "{name}: mode {:?} is not supported (triangles only)",
                        primitive.mode()
                    )));
                }
                let reader = primitive.reader(|buffer| buffers.get(buffer.index()).map(|data| &data.0[..]));
                let positions: Vec<Vec3> = reader
                    .read_positions()
                    .ok_or_else(|| load_error(format!("{name}: no POSITION attribute")))?
                    .map(|p| world.transform_point3(Vec3::from_array(p)))
                    .collect();
                let indices: Vec<u32> = match reader.read_indices() {
                    Some(indices) => indices.into_u32().collect(),
                    None => (0..positions.len() as u32).collect(),
                };
                if !indices.len().is_multiple_of(3) {
                    return Err(load_error(format!(
                        "{name}: {} indices is not a whole number of triangles",
                        indices.len()
                    )));
                }
                let triangles = indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
                meshes.push(Mesh { name, positions, triangles, material: material(&primitive.material()) });
            }
        }
        pending.extend(node.children().map(|child| (child, world)));
    }
    let camera = camera.unwrap_or_else(|| framing_camera(&meshes));
    Scene::new(&path.display().to_string(), meshes, camera)
}

/// The metallic-roughness parameters of a glTF material (factors only; textures are not sampled).
fn material(m: &gltf::Material) -> Material {
    let pbr = m.pbr_metallic_roughness();
    let [r, g, b, _alpha] = pbr.base_color_factor();
    Material {
        base_color: Vec3::new(r, g, b),
        roughness: pbr.roughness_factor().clamp(0.0, 1.0),
        metallic: pbr.metallic_factor().clamp(0.0, 1.0),
        emission: Vec3::from_array(m.emissive_factor()) * m.emissive_strength().unwrap_or(1.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use raywave_shared::Light;
    use std::io::Write;

    /// A glTF file with one quad (two triangles) in an embedded base64 buffer: 4 positions
    /// (48 bytes) followed by 6 u16 indices (12 bytes), under a node translated by (0, 0, -2),
    /// with an emissive material and a camera node.
    fn quad_gltf(index_count: u32) -> String {
        let mut bytes = Vec::new();
        for p in [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
            for c in p {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
        for i in [0u16, 1, 2, 0, 2, 3] {
            bytes.extend_from_slice(&i.to_le_bytes());
        }
        let data = base64_encode(&bytes);
        format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0,1]}}],
            "nodes":[{{"mesh":0,"translation":[0,0,-2]}},{{"camera":0,"translation":[0.5,0.5,3]}}],
            "cameras":[{{"type":"perspective","perspective":{{"yfov":0.8,"znear":0.01}}}}],
            "materials":[{{"pbrMetallicRoughness":{{"baseColorFactor":[0.5,0.25,1,1],"metallicFactor":0.5,"roughnessFactor":0.3}},"emissiveFactor":[1,0.5,0]}}],
            "meshes":[{{"name":"quad","primitives":[{{"attributes":{{"POSITION":0}},"indices":1,"material":0}}]}}],
            "buffers":[{{"byteLength":60,"uri":"data:application/octet-stream;base64,{data}"}}],
            "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":48}},{{"buffer":0,"byteOffset":48,"byteLength":12}}],
            "accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
                         {{"bufferView":1,"componentType":5123,"count":{index_count},"type":"SCALAR"}}]}}"#
        )
    }

    fn base64_encode(bytes: &[u8]) -> String {
        const TABLE: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        bytes
            .chunks(3)
            .flat_map(|chunk| {
                let n = chunk.iter().enumerate().fold(0u32, |acc, (i, &b)| acc | (u32::from(b) << (16 - 8 * i)));
                (0..4).map(
                    move |k| if k <= chunk.len() { TABLE[((n >> (18 - 6 * k)) & 63) as usize] as char } else { '=' },
                )
            })
            .collect()
    }

    fn file(text: &str) -> tempfile::NamedTempFile {
        let mut f = tempfile::Builder::new().suffix(".gltf").tempfile().unwrap();
        f.write_all(text.as_bytes()).unwrap();
        f
    }

    #[test]
    fn loads_geometry_transforms_materials_and_camera() {
        let f = file(&quad_gltf(6));
        let scene = load(f.path()).unwrap();
        assert_eq!(scene.triangle_count(), 2);
        let mesh = &scene.meshes()[0];
        assert_eq!(mesh.positions[2], Vec3::new(1.0, 1.0, -2.0), "node translation applied");
        assert_eq!(mesh.material.base_color, Vec3::new(0.5, 0.25, 1.0));
        assert_eq!((mesh.material.metallic, mesh.material.roughness), (0.5, 0.3));
        assert_eq!(mesh.material.emission, Vec3::new(1.0, 0.5, 0.0));
        let camera = scene.camera();
        assert_eq!(camera.position, Vec3::new(0.5, 0.5, 3.0));
        assert!((camera.vertical_fov_degrees - 0.8f32.to_degrees()).abs() < 1e-4);
    }

    #[test]
    fn malformed_and_truncated_files_name_the_file() {
        for text in ["{ not json", r#"{"asset":{"version":"2.0"}}"#, &quad_gltf(6)[..200]] {
            let f = file(text);
            let err = load(f.path()).unwrap_err();
            assert!(matches!(err, Error::SceneLoad { .. }), "{err}");
            assert!(err.to_string().contains(&f.path().display().to_string()), "{err}");
        }
    }

    #[test]
    fn missing_buffer_file_is_an_error() {
        let mut text = quad_gltf(6);
        let start = text.find("data:application").unwrap();
        let end = start + text[start..].find('"').unwrap();
        text.replace_range(start..end, "missing.bin");
        let f = file(&text);
        let err = load(f.path()).unwrap_err();
        assert!(matches!(err, Error::SceneLoad { .. }), "{err}");
    }

    #[test]
    fn emissive_rectangle_becomes_one_downward_quad_light() {
        // tests/data/emissive_quad.gltf: a 2 m × 2 m floor facing +y at y = 0 and a 0.5 m × 0.25 m
        // lamp node translated to y = 1.5, its rectangle split along the (1, 3) diagonal and
        // wound counter-clockwise seen from below; emissive factor (1, 0.5, 0.25), strength 4.
        let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/data/emissive_quad.gltf"));
        let scene = load(path).unwrap();
        assert_eq!(scene.meshes().len(), 2);
        assert_eq!(scene.unsupported_emitters(), 0);
        let lamp = Light::quad(
            Vec3::new(-0.25, 1.5, -0.125),
            Vec3::new(0.5, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 0.25),
            Vec3::new(4.0, 2.0, 1.0),
            false,
        );
        assert_eq!(scene.lights(), &[lamp]);
        let light_mesh = scene.light_mesh(0);
        assert_eq!(scene.meshes()[light_mesh].name, "lamp primitive 0");
        assert_eq!(scene.mesh_light(light_mesh), Some(0));
        assert_eq!(scene.mesh_light(1 - light_mesh), None);
        let facing = lamp.edge_u.truncate().cross(lamp.edge_v.truncate());
        assert!(facing.normalize().abs_diff_eq(Vec3::NEG_Y, 1e-6), "emits down, towards the floor: {facing}");
        assert!(crate::lights::validate_lights(scene.lights()).is_ok());
    }

    #[test]
    fn negative_emissive_strength_is_an_error() {
        let lamp =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/data/emissive_quad.gltf")).unwrap();
        let text = lamp.replace(r#""emissiveStrength": 4"#, r#""emissiveStrength": -2"#);
        assert_ne!(text, lamp);
        let f = file(&text);
        match load(f.path()) {
            Err(Error::InvalidParameter { name: "material.emission", reason }) => {
                assert!(reason.contains("lamp primitive 0"), "{reason}");
            }
            other => panic!("expected an invalid material.emission, got {other:?}"),
        }
    }

    #[test]
    fn index_count_that_is_not_triangles_is_an_error() {
        let f = file(&quad_gltf(5));
        let err = load(f.path()).unwrap_err();
        assert!(err.to_string().contains("whole number of triangles"), "{err}");
    }
}
