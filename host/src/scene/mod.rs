//! Scenes: triangle meshes with a camera, validated before any stage sees them.

mod cornell;
mod obj;
pub mod procedural;

use crate::error::{Error, Result};
use glam::Vec3;
use std::path::Path;

/// A triangle mesh, one instance in the acceleration structures.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    /// Name, used in error messages and reports.
    pub name: String,
    /// Vertex positions in scene units (metres for the built-in scenes).
    pub positions: Vec<Vec3>,
    /// Triangles as vertex-index triples, counter-clockwise seen from the front.
    pub triangles: Vec<[u32; 3]>,
    /// Diffuse reflectance (linear RGB, each in [0, 1]).
    pub albedo: Vec3,
    /// Emitted radiance (linear RGB, W·sr⁻¹·m⁻²-like units; zero for non-emitters).
    pub emission: Vec3,
}

/// A pinhole camera.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Camera {
    /// Eye position in scene units.
    pub position: Vec3,
    /// A point the camera looks at.
    pub look_at: Vec3,
    /// Approximate up direction (need not be orthogonal to the view direction).
    pub up: Vec3,
    /// Full vertical field of view in degrees, in (0, 180).
    pub vertical_fov_degrees: f32,
}

/// A validated scene: meshes and a camera. Construct it with [`Scene::load`] or
/// [`Scene::new`], which both validate.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    name: String,
    meshes: Vec<Mesh>,
    camera: Camera,
}

/// Names of the built-in scenes, usable as `builtin:NAME`: the Cornell box, a field of 64
/// icospheres (1.3 M triangles) and a hairball of 200 000 thin random triangles.
pub const BUILTIN_SCENES: &[&str] = &["cornell", "spheres", "hairball"];

impl Scene {
    /// Loads a scene: `builtin:NAME` for a built-in scene, otherwise a path to a Wavefront OBJ file.
    pub fn load(spec: &str) -> Result<Scene> {
        match spec.strip_prefix("builtin:") {
            Some("cornell") => Scene::new("builtin:cornell", cornell::meshes(), cornell::camera()),
            Some("spheres") => {
                let (meshes, camera) = procedural::sphere_field(4, 5);
                Scene::new("builtin:spheres", meshes, camera)
            }
            Some("hairball") => {
                let (meshes, camera) = procedural::hairball(200_000, 1);
                Scene::new("builtin:hairball", meshes, camera)
            }
            Some(name) => {
                Err(Error::UnknownBuiltinScene { name: name.to_owned(), available: BUILTIN_SCENES.join(", ") })
            }
            None => obj::load(Path::new(spec)),
        }
    }

    /// Builds a scene from meshes and a camera after validating every vertex and triangle.
    /// `name` identifies the scene in error messages (a file path or `builtin:NAME`).
    pub fn new(name: &str, meshes: Vec<Mesh>, camera: Camera) -> Result<Scene> {
        let scene = Scene { name: name.to_owned(), meshes, camera };
        scene.validate()?;
        Ok(scene)
    }

    /// The scene's name (file path or `builtin:NAME`).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The meshes, in instance order.
    pub fn meshes(&self) -> &[Mesh] {
        &self.meshes
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Total number of triangles over all meshes.
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.triangles.len()).sum()
    }

    /// Axis-aligned bounds (min, max) of every vertex used by a triangle.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for mesh in &self.meshes {
            for p in &mesh.positions {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
        (lo, hi)
    }

    fn validate(&self) -> Result<()> {
        let scene = || self.name.clone();
        if self.triangle_count() == 0 {
            return Err(Error::EmptyScene { scene: scene() });
        }
        if u32::try_from(self.triangle_count()).is_err() || u32::try_from(self.meshes.len()).is_err() {
            return Err(Error::SceneTooLarge { scene: scene(), what: "the triangle count".into() });
        }
        for mesh in &self.meshes {
            if let Some((vertex, p)) = mesh.positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
                return Err(Error::NonFiniteVertex {
                    scene: scene(),
                    mesh: mesh.name.clone(),
                    vertex,
                    position: p.to_string(),
                });
            }
            for (triangle, indices) in mesh.triangles.iter().enumerate() {
                if let Some(&index) = indices.iter().find(|&&i| i as usize >= mesh.positions.len()) {
                    return Err(Error::IndexOutOfRange {
                        scene: scene(),
                        mesh: mesh.name.clone(),
                        triangle,
                        index,
                        vertex_count: mesh.positions.len(),
                    });
                }
                let [a, b, c] = indices.map(|i| mesh.positions[i as usize]);
                if (b - a).cross(c - a) == Vec3::ZERO {
                    return Err(Error::DegenerateTriangle { scene: scene(), mesh: mesh.name.clone(), triangle });
                }
            }
        }
        let c = &self.camera;
        let fov_ok = c.vertical_fov_degrees > 0.0 && c.vertical_fov_degrees < 180.0;
        let view = c.look_at - c.position;
        let finite = c.position.is_finite() && c.look_at.is_finite() && c.up.is_finite();
        if !(finite && fov_ok) || view.cross(c.up) == Vec3::ZERO {
            return Err(Error::InvalidParameter {
                name: "camera",
                reason: format!("{}: degenerate camera {c:?}", self.name),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle_mesh(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Mesh {
        Mesh { name: "m".into(), positions, triangles, albedo: Vec3::ONE, emission: Vec3::ZERO }
    }

    fn unit_triangle() -> Vec<Vec3> {
        vec![Vec3::ZERO, Vec3::X, Vec3::Y]
    }

    fn scene_with(mesh: Mesh) -> Result<Scene> {
        Scene::new("test", vec![mesh], cornell::camera())
    }

    #[test]
    fn builtin_cornell_box_is_valid() {
        let scene = Scene::load("builtin:cornell").unwrap();
        assert_eq!(scene.meshes().len(), 8);
        assert_eq!(scene.triangle_count(), 2 * (5 + 1 + 5 + 5));
    }

    #[test]
    fn unknown_builtin_is_named() {
        let err = Scene::load("builtin:nope").unwrap_err();
        assert!(matches!(err, Error::UnknownBuiltinScene { ref name, .. } if name == "nope"), "{err}");
    }

    #[test]
    fn empty_scene_is_rejected() {
        assert!(matches!(scene_with(triangle_mesh(vec![], vec![])), Err(Error::EmptyScene { .. })));
    }

    #[test]
    fn non_finite_vertices_are_rejected_with_their_index() {
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut p = unit_triangle();
            p[2].y = bad;
            let err = scene_with(triangle_mesh(p, vec![[0, 1, 2]])).unwrap_err();
            assert!(matches!(err, Error::NonFiniteVertex { vertex: 2, .. }), "{err}");
        }
    }

    #[test]
    fn zero_area_and_out_of_range_triangles_are_rejected() {
        let err = scene_with(triangle_mesh(unit_triangle(), vec![[0, 1, 2], [0, 1, 1]])).unwrap_err();
        assert!(matches!(err, Error::DegenerateTriangle { triangle: 1, .. }), "{err}");
        let err = scene_with(triangle_mesh(unit_triangle(), vec![[0, 1, 3]])).unwrap_err();
        assert!(matches!(err, Error::IndexOutOfRange { index: 3, vertex_count: 3, .. }), "{err}");
    }

    #[test]
    fn tiny_but_non_degenerate_triangles_are_kept() {
        let p = unit_triangle().into_iter().map(|v| v * 1e-6).collect();
        assert!(scene_with(triangle_mesh(p, vec![[0, 1, 2]])).is_ok());
    }
}
