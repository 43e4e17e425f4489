//! Wavefront OBJ scenes (through the `tobj` crate): every OBJ model becomes a mesh, materials are
//! ignored for now (grey albedo), and the camera frames the scene's bounds.

use super::{framing_camera, Material, Mesh, Scene};
use crate::error::{Error, Result};
use glam::Vec3;
use std::path::Path;

/// Albedo given to meshes of an OBJ file (materials come with the shade stage).
const DEFAULT_ALBEDO: Vec3 = Vec3::splat(0.7);

/// Loads and validates an OBJ file.
pub fn load(path: &Path) -> Result<Scene> {
    let load_error = |message: String| Error::SceneLoad { path: path.to_owned(), message };
    // Opened here first: tobj reports any failure to open as a bare "open file failed".
    if path.is_dir() {
        return Err(load_error("is a directory".into()));
    }
    std::fs::File::open(path).map_err(|e| load_error(e.to_string()))?;
    let options = tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() };
    let (models, _materials) = tobj::load_obj(path, &options).map_err(|e| load_error(e.to_string()))?;
    let meshes: Vec<Mesh> = models
        .into_iter()
        .enumerate()
        .map(|(i, model)| Mesh {
            // tobj names objects without an `o`/`g` line "unnamed_object".
            name: if model.name.is_empty() || model.name == "unnamed_object" {
                format!("mesh {i}")
            } else {
                model.name
            },
            positions: model.mesh.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])).collect(),
            triangles: model.mesh.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
            material: Material::diffuse(DEFAULT_ALBEDO),
        })
        .collect();
    let name = path.display().to_string();
    let camera = framing_camera(&meshes);
    Scene::new(&name, meshes, camera)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn obj_file(text: &str) -> tempfile::NamedTempFile {
        let mut f = tempfile::Builder::new().suffix(".obj").tempfile().unwrap();
        f.write_all(text.as_bytes()).unwrap();
        f
    }

    #[test]
    fn loads_a_quad() {
        let f = obj_file("o quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n");
        let scene = load(f.path()).unwrap();
        assert_eq!(scene.triangle_count(), 2);
        assert_eq!(scene.meshes()[0].name, "quad");
        let f = obj_file("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n");
        assert_eq!(load(f.path()).unwrap().meshes()[0].name, "mesh 0", "an object without a name");
    }

    #[test]
    fn missing_file_names_the_path() {
        let err = load(Path::new("/nonexistent/scene.obj")).unwrap_err();
        assert!(matches!(err, Error::SceneLoad { .. }), "{err}");
        assert!(err.to_string().contains("/nonexistent/scene.obj"));
        assert!(err.to_string().contains("No such file"), "the OS's reason: {err}");
        let dir = tempfile::Builder::new().suffix(".obj").tempdir().unwrap();
        let err = load(dir.path()).unwrap_err();
        assert!(err.to_string().contains("is a directory"), "{err}");
    }

    #[test]
    fn nan_vertex_and_zero_area_faces_are_rejected() {
        let f = obj_file("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n");
        let err = load(f.path()).unwrap_err();
        assert!(matches!(err, Error::NonFiniteVertex { vertex: 2, .. }), "{err}");
        let f = obj_file("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n");
        assert!(matches!(load(f.path()).unwrap_err(), Error::EmptyScene { dropped_degenerate: 1, .. }));
    }

    #[test]
    fn out_of_range_face_and_empty_file_are_rejected() {
        let f = obj_file("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
        assert!(load(f.path()).is_err());
        let f = obj_file("# nothing here\n");
        assert!(matches!(load(f.path()).unwrap_err(), Error::EmptyScene { .. }));
    }
}
