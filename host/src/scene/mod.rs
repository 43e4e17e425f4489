//! Scenes: triangle meshes with a camera, validated before any stage sees them, and the analytic
//! quad lights derived from their emissive parallelograms (see [`Scene::lights`]).

mod cornell;
mod emitters;
mod gltf;
mod identity;
mod line_counter;
mod obj;
pub mod procedural;
mod regular_file;
mod unrendered;

use crate::error::{Error, Result};
use glam::{DVec3, Vec2, Vec3};
pub use identity::SceneIdentity;
use raywave_shared::Light;
use std::path::Path;
pub use unrendered::Unrendered;

/// A triangle mesh, one instance in the acceleration structures.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    /// Name, used in error messages and reports.
    pub name: String,
    /// Vertex positions in scene units (metres for the built-in scenes).
    pub positions: Vec<Vec3>,
    /// Triangles as vertex-index triples, counter-clockwise seen from the front.
    pub triangles: Vec<[u32; 3]>,
    /// The surface's material.
    pub material: Material,
}

/// A metallic-roughness material (the glTF 2.0 model).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Material {
    /// Base colour (linear RGB, each in [0, 1]): diffuse albedo for dielectrics, F0 for metals.
    pub base_color: Vec3,
    /// Perceptual roughness in [0, 1].
    pub roughness: f32,
    /// Metalness in [0, 1].
    pub metallic: f32,
    /// Emitted radiance (linear RGB, in whatever radiometric unit the scene uses — the rendered
    /// radiance comes out in the same unit; zero for non-emitters).
    pub emission: Vec3,
    /// Emits from both faces (glTF's `doubleSided`): both glow where seen, and an emissive
    /// parallelogram with this material becomes a two-sided quad light. Otherwise only the front
    /// face, the side its counter-clockwise winding faces, glows and lights; the back is black.
    pub double_sided: bool,
}

impl Material {
    /// A rough, non-metallic, non-emissive surface of the given albedo.
    pub const fn diffuse(albedo: Vec3) -> Self {
        Self { base_color: albedo, roughness: 1.0, metallic: 0.0, emission: Vec3::ZERO, double_sided: false }
    }

    /// Checks each parameter's range — base colour, roughness and metalness in `[0, 1]`, emission
    /// in `[0, MAX_EMISSION]` ([`MAX_EMISSION`]) — returning the first offender's field name and
    /// what is wrong with it.
    pub(crate) fn check(&self) -> std::result::Result<(), (&'static str, String)> {
        let e = self.emission;
        // `min_element`/`max_element` skip NaN, hence `is_finite`.
        if !(e.is_finite() && e.min_element() >= 0.0 && e.max_element() <= MAX_EMISSION) {
            return Err(("material.emission", format!("emits {e}; each component must be in [0, {MAX_EMISSION:e}]")));
        }
        let b = self.base_color;
        if !(b.is_finite() && b.min_element() >= 0.0 && b.max_element() <= 1.0) {
            return Err(("material.base_color", format!("has base colour {b}; each component must be in [0, 1]")));
        }
        for (name, value) in [("material.roughness", self.roughness), ("material.metallic", self.metallic)] {
            if !(0.0..=1.0).contains(&value) {
                return Err((name, format!("has {value}; it must be in [0, 1]")));
            }
        }
        Ok(())
    }
}

/// A pinhole camera, in a right-handed world (glTF's and glam's `look_at_rh` convention): the
/// image's right axis is `forward × up`, so with +y up and the view along −z, +x is to the right.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Camera {
    /// Eye position in scene units.
    pub position: Vec3,
    /// A point the camera looks at. Its distance from `position` is also the thin lens's default
    /// focus distance (`frame::generate_params_with`), so a loader puts it where the scene is: a
    /// glTF camera looks at the point along its view at the depth of the scene bounds' centre
    /// (at least half the bounds' radius away; the glTF loader's `PlacedCamera::aimed`), a
    /// framing camera at the bounds' centre.
    pub look_at: Vec3,
    /// Approximate up direction (need not be orthogonal to the view direction).
    pub up: Vec3,
    /// Full vertical field of view in degrees, in (0, 180).
    pub vertical_fov_degrees: f32,
    /// Whether the image is mirrored left to right: its right axis is `up × forward` rather than
    /// the usual `forward × up`. A camera placed by a mirroring transform (a glTF camera node whose
    /// world transform has a negative determinant, as under the root `scale: [1, 1, −1]` that
    /// converters add over the whole scene) has image right along its transformed +x, which is
    /// `up × forward` there: without this flag the mirrored scene rendered as a mirror image of
    /// what viewers show. `false` for every camera not placed by such a transform.
    pub mirrored: bool,
}

impl Camera {
    /// Whether the view direction and the right axis normalize to finite vectors, as the generate
    /// stage's parameters take them (`frame::generate_params_with`): a view direction or up vector
    /// too short to normalize in f32 (1e-30) passed an exact-zero test and gave NaN rays.
    pub(crate) fn has_view_basis(&self) -> bool {
        let forward = (self.look_at - self.position).normalize();
        forward.is_finite() && forward.cross(self.up).normalize().is_finite()
    }
}

/// A point where a ray hit a scene's surface (see [`Scene::hit_surface`]).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SurfaceHit {
    /// The hit point in scene units.
    pub position: Vec3,
    /// Unit geometric normal facing the side the ray came from.
    pub normal: Vec3,
    /// The hit triangle's largest absolute vertex coordinate, in scene units
    /// ([`raywave_kernels::offset::triangle_extent`]).
    pub extent: f32,
    /// The hit mesh's material.
    pub material: Material,
}

impl SurfaceHit {
    /// Where a ray leaving the surface towards the side the hitting ray came from starts: the
    /// point offset along the normal by [`raywave_kernels::offset::offset_ray_origin`].
    pub fn secondary_ray_origin(&self) -> Vec3 {
        raywave_kernels::offset::offset_ray_origin(self.position, self.normal, self.extent)
    }
}

/// A validated scene: meshes, a camera and the quad lights derived from the emissive meshes.
/// Construct it with [`Scene::load`] or [`Scene::new`], which both validate. Its geometry and
/// materials cannot be changed once built (to move an object, build a new scene; the view moves
/// with [`Scene::set_camera`]), and each build has its own
/// [`Scene::identity`]; `==` compares the contents, not the identity.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Given by [`Scene::new`], kept by clones.
    identity: SceneIdentity,
    name: String,
    meshes: Vec<Mesh>,
    camera: Camera,
    /// [`Scene::bounds`], found once: a scan of every triangle, which the generate stage's
    /// parameters read each sample (35 ms a call, serial, on `builtin:spheres`' 1.3 M triangles).
    bounds: (Vec3, Vec3),
    dropped_degenerate: usize,
    unrendered: Unrendered,
    lights: emitters::DerivedLights,
}

impl PartialEq for Scene {
    /// Equal contents — name, meshes, camera, counts and lights — whatever the identities.
    fn eq(&self, other: &Self) -> bool {
        // The bounds follow from the meshes.
        let Scene { identity: _, bounds: _, name, meshes, camera, dropped_degenerate, unrendered, lights } = self;
        (name, meshes, camera, dropped_degenerate, unrendered, lights)
            == (&other.name, &other.meshes, &other.camera, &other.dropped_degenerate, &other.unrendered, &other.lights)
    }
}

/// Names of the built-in scenes, usable as `builtin:NAME`: the Cornell box; the Cornell box lit by
/// two smaller coloured ceiling lights, with a glossy and a metallic block; the Cornell box lit
/// by a grid of 20 small coloured lights (chosen through the light BVH); a field of 64
/// icospheres (1.3 M triangles) and a hairball of 200 000 thin random triangles.
pub const BUILTIN_SCENES: &[&str] = &["cornell", "cornell-two-lights", "cornell-light-grid", "spheres", "hairball"];

impl Scene {
    /// Loads a scene: `builtin:NAME` for a built-in scene, otherwise a path to a Wavefront OBJ
    /// (`.obj`) or glTF 2.0 (`.gltf`, `.glb`) file.
    pub fn load(spec: &str) -> Result<Scene> {
        match spec.strip_prefix("builtin:") {
            Some("cornell") => Scene::new("builtin:cornell", cornell::meshes(), cornell::camera()),
            Some("cornell-two-lights") => {
                Scene::new("builtin:cornell-two-lights", cornell::two_lights_meshes(), cornell::camera())
            }
            Some("cornell-light-grid") => {
                Scene::new("builtin:cornell-light-grid", cornell::light_grid_meshes(), cornell::camera())
            }
            Some("spheres") => {
                let (meshes, camera) = procedural::sphere_field(4, 5)?;
                Scene::new("builtin:spheres", meshes, camera)
            }
            Some("hairball") => {
                let (meshes, camera) = procedural::hairball(200_000, 1)?;
                Scene::new("builtin:hairball", meshes, camera)
            }
            Some(name) => {
                Err(Error::UnknownBuiltinScene { name: name.to_owned(), available: BUILTIN_SCENES.join(", ") })
            }
            None => {
                let path = Path::new(spec);
                match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
                    Some("obj") => obj::load(path),
                    Some("gltf" | "glb") => gltf::load(path),
                    _ => Err(Error::SceneLoad {
                        path: path.to_owned(),
                        message: "unsupported scene format (expected .obj, .gltf or .glb)".into(),
                    }),
                }
            }
        }
    }

    /// Builds a scene from meshes and a camera after validating every vertex and triangle.
    /// `name` identifies the scene in error messages (a file path or `builtin:NAME`). Zero-area
    /// triangles are dropped and counted ([`Scene::dropped_degenerate`]), and meshes left empty
    /// are removed; a non-finite vertex or one beyond [`MAX_COORDINATE`], an out-of-range index, a
    /// degenerate camera (or one beyond [`MAX_COORDINATE`]), an emission outside
    /// `[0, MAX_EMISSION]` ([`MAX_EMISSION`]), a base colour, roughness or metalness outside
    /// `[0, 1]`, a derived light whose power overflows `f32`, more than [`MAX_VERTICES`] vertices
    /// or [`MAX_TRIANGLES`] triangles, or a scene without any triangle of non-zero area is an
    /// error.
    ///
    /// Every remaining mesh whose material emits (non-zero emission) and whose triangles form one
    /// planar parallelogram becomes one quad light ([`Scene::lights`]); other emissive meshes are
    /// counted ([`Scene::unsupported_emitters`]). Emissive meshes stay in the scene either way, a
    /// light's mesh moved onto the light (each vertex to the corner it matched, by at most the
    /// tolerance [`Scene::lights`] gives), so that its triangles cannot block the light's shadow
    /// rays.
    pub fn new(name: &str, mut meshes: Vec<Mesh>, camera: Camera) -> Result<Scene> {
        check_indices_and_vertices(name, &meshes)?;
        // Every mesh's material, before meshes of only zero-area triangles are removed: an
        // emission of NaN on such a mesh passed unchecked.
        check_materials(name, &meshes)?;
        let before: usize = meshes.iter().map(|m| m.triangles.len()).sum();
        for mesh in &mut meshes {
            let positions = &mesh.positions;
            mesh.triangles.retain(|t| has_area(t.map(|i| positions[i as usize])));
        }
        meshes.retain(|m| !m.triangles.is_empty());
        let dropped_degenerate = before - meshes.iter().map(|m| m.triangles.len()).sum::<usize>();
        let lights =
            if u32::try_from(meshes.len()).is_ok() { emitters::derive(&mut meshes) } else { Default::default() };
        let scene = Scene {
            identity: SceneIdentity::new(name),
            name: name.to_owned(),
            bounds: triangle_bounds(&meshes),
            meshes,
            camera,
            dropped_degenerate,
            unrendered: Unrendered::default(),
            lights,
        };
        scene.validate()?;
        Ok(scene)
    }

    /// The analytic lights: one [`Light::quad`] per emissive mesh whose triangles form
    /// one planar parallelogram (two triangles sharing a diagonal, matched within the tolerance
    /// the `emitters` module documents: 10⁻⁴ of the shape's size, at most 5 % of its narrower side,
    /// plus the rounding of coordinates far from the origin, capped at a quarter of the shortest
    /// edge) whose corners, rebuilt from the light's edges, stay within [`MAX_COORDINATE`], in
    /// mesh order, with the mesh's emission as radiance. Each emits on
    /// the side its triangles' counter-clockwise winding faces (the glTF and OBJ front face), or
    /// from both where its material is [`Material::double_sided`]:
    /// the light's corner is the first triangle's corner off the diagonal and its edges run to
    /// that triangle's next and previous corners, so `edge_u × edge_v` is the triangle's
    /// counter-clockwise normal. The meshes stay in [`Scene::meshes`], so rays still hit them,
    /// each moved onto its light's corners ([`Scene::new`]); each light is [`Light::made_of`] its
    /// mesh, which it does not light.
    pub fn lights(&self) -> &[Light] {
        &self.lights.lights
    }

    /// The index in [`Scene::meshes`] (the instance index) of the mesh that light `light` came
    /// from. Panics if `light` is not below `lights().len()`, like slice indexing.
    pub fn light_mesh(&self, light: usize) -> usize {
        self.lights.lights[light].mesh as usize
    }

    /// The index in [`Scene::lights`] of mesh (instance) `mesh`'s light, or `None` if that mesh
    /// is not a light. Panics if `mesh` is not below `meshes().len()`, like slice indexing.
    pub fn mesh_light(&self, mesh: usize) -> Option<u32> {
        self.lights.mesh_lights[mesh]
    }

    /// Emissive meshes that did not become lights because their triangles are not one planar
    /// parallelogram. They still emit where a ray hits their front face (either face if
    /// [`Material::double_sided`]), but are never sampled as lights.
    pub fn unsupported_emitters(&self) -> usize {
        self.lights.unsupported
    }

    /// What the scene's file asked for that raywave does not render ([`Unrendered`]); all zero
    /// for built-in scenes and scenes made with [`Scene::new`].
    pub fn unrendered(&self) -> Unrendered {
        self.unrendered
    }

    /// This scene, noting what its file asked for that raywave does not render.
    pub(crate) fn with_unrendered(self, unrendered: Unrendered) -> Self {
        Self { unrendered, ..self }
    }

    /// Zero-area triangles removed when the scene was built.
    pub fn dropped_degenerate(&self) -> usize {
        self.dropped_degenerate
    }

    /// The scene's name (file path or `builtin:NAME`).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// This build's identity, which its clones share: what [`crate::shading::ShadeData`] records
    /// of the scene it lays out and a backend of the scene it loaded, so that `shade` can refuse
    /// the data of another scene ([`crate::Error::SceneMismatch`]).
    pub fn identity(&self) -> &SceneIdentity {
        &self.identity
    }

    /// The meshes, in instance order.
    pub fn meshes(&self) -> &[Mesh] {
        &self.meshes
    }

    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Moves the view to `camera`, checked as [`Scene::new`] checks a camera: how an engine's own
    /// camera follows the player without rebuilding the scene (its meshes, lights and bounds stay;
    /// so does every backend's loaded copy of it, and [`crate::shading::ShadeData`], which read
    /// no camera). A degenerate camera is an error and leaves the scene's camera as it was.
    pub fn set_camera(&mut self, camera: Camera) -> Result<()> {
        check_camera(&self.name, &camera)?;
        self.camera = camera;
        Ok(())
    }

    /// Total number of triangles over all meshes.
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.triangles.len()).sum()
    }

    /// The surface of the hit `(instance, primitive, barycentrics)` (as the trace stage reports
    /// it) seen along `incoming`: the point interpolated from the triangle's vertices — the most
    /// accurate hit point, which the error-bounded ray offset expects (Wächter & Binder, RTG ch. 6)
    /// — and the unit geometric normal turned against `incoming`. Indices must come from a hit on
    /// this scene (panics otherwise, like slice indexing).
    pub fn hit_surface(&self, instance: u32, primitive: u32, barycentrics: Vec2, incoming: Vec3) -> SurfaceHit {
        let mesh = &self.meshes[instance as usize];
        let [a, b, c] = mesh.triangles[primitive as usize].map(|v| mesh.positions[v as usize]);
        let position = a * (1.0 - barycentrics.x - barycentrics.y) + b * barycentrics.x + c * barycentrics.y;
        let normal = raywave_kernels::triangle::geometric_normal(a, b, c);
        let normal = if normal.dot(incoming) > 0.0 { -normal } else { normal };
        let extent = raywave_kernels::offset::triangle_extent(a, b, c);
        SurfaceHit { position, normal, extent, material: mesh.material }
    }

    /// Axis-aligned bounds (min, max) of every vertex used by a triangle (not of vertices no
    /// triangle uses, nor of those only zero-area triangles used, which were dropped); found once,
    /// when the scene is built.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.bounds
    }

    fn validate(&self) -> Result<()> {
        if self.triangle_count() == 0 {
            return Err(Error::EmptyScene { scene: self.name.clone(), dropped_degenerate: self.dropped_degenerate });
        }
        if u32::try_from(self.triangle_count()).is_err() || u32::try_from(self.meshes.len()).is_err() {
            let what = "its triangles or meshes exceed the streams' 32-bit indices".into();
            return Err(Error::SceneTooLarge { scene: self.name.clone(), what });
        }
        let vertices: usize = self.meshes.iter().map(|m| m.positions.len()).sum();
        if vertices > MAX_VERTICES {
            let what = format!("its {vertices} vertices exceed {MAX_VERTICES}");
            return Err(Error::SceneTooLarge { scene: self.name.clone(), what });
        }
        if self.triangle_count() > MAX_TRIANGLES {
            let what = format!("its {} triangles exceed {MAX_TRIANGLES}", self.triangle_count());
            return Err(Error::SceneTooLarge { scene: self.name.clone(), what });
        }
        check_camera(&self.name, &self.camera)?;
        for (index, light) in self.lights().iter().enumerate() {
            crate::lights::validate_light(index, light).map_err(|err| match err {
                Error::InvalidParameter { name, reason } => Error::InvalidParameter {
                    name,
                    reason: format!("{}: mesh {:?}: {reason}", self.name, self.meshes[self.light_mesh(index)].name),
                },
                other => other,
            })?;
        }
        Ok(())
    }
}

/// The UTF-8 byte-order mark (EF BB BF) that Windows editors write before a text file's first
/// line. The OBJ and MTL loaders strip it; the glTF loader reads it as spaces, keeping the JSON's
/// columns (its errors name them).
const UTF8_BYTE_ORDER_MARK: &[u8] = b"\xEF\xBB\xBF";

/// The largest coordinate magnitude `M` of a vertex or of the camera, in scene units (10⁸: 10⁵ km
/// in metres, where `f32` spacing is already 8 m). Up to it every difference of two points stays
/// within 2·10⁸ per axis, and the highest powers of lengths the kernels form stay finite in `f32`
/// (max 3.4·10³⁸): fourth powers such as a quad light's squared `|edge_u × edge_v|²`
/// (≤ 144·M⁴ ≈ 1.4·10³⁴) and the triangle test's cubic `t·det` (≤ 333·M³). The limit was 10¹⁸,
/// where those overflowed: fuzzing found the trace stage replacing the infinite `t` of a scene
/// 10¹⁶ across, and the Cornell box scaled to 10¹⁸ was refused as a light whose power overflows.
pub const MAX_COORDINATE: f32 = 1.0e8;

/// The most vertices a scene holds, over all its meshes: 2²⁸ (268 M, 3 GiB of positions). The
/// streams' 32-bit indices would address 2³² triangles, but a GPU storage buffer holds at most
/// 4 GiB on NVIDIA's drivers (the software trace's 48 bytes per triangle reach that at 89 M
/// triangles), and the glTF loader counts the meshes its nodes instance against this limit before
/// reading them, so that a small file cannot make it allocate without bound (one 10⁶-vertex
/// sparse accessor instanced by 10⁴ nodes asked for 10¹⁰ vertices); the OBJ loader refuses a
/// file of more `v` lines, or of faces making more triangles, before tobj builds them (tobj
/// may still make more vertices than `v` lines, one per distinct index triple, which the scene's
/// own check counts).
pub const MAX_VERTICES: usize = 1 << 28;

/// The most triangles a scene holds, over all its meshes: 2²⁸ (3 GiB of vertex indices), for the
/// reasons of [`MAX_VERTICES`]; the glTF loader counts its nodes' instances against it before
/// reading them too (one 10⁶-index accessor of a 1 MB buffer instanced by 10⁴ nodes asked for
/// 10¹⁰ indices while it counted only their few vertices).
pub const MAX_TRIANGLES: usize = 1 << 28;

/// The largest emitted radiance component accepted, in W/(m²·sr): 10⁶ times the sun's disc
/// (≈ 2·10⁷), and small enough that sums over every sample of a pixel
/// ([`crate::frame::MAX_SAMPLES_PER_PIXEL`] = 65 536) and over thousands of lights stay finite in
/// `f32` (a component of 3·10³⁸ reached the EXR output as infinity after 4 samples).
pub const MAX_EMISSION: f32 = 1.0e20;

/// Checks that camera `c` of scene `scene` can view: its position and look-at point finite, within
/// [`MAX_COORDINATE`] and apart, not in line with its up direction, and its vertical field of
/// view in (0°, 180°), wide enough that the generate stage's image plane has a half height of at
/// least √[`MIN_IMAGE_PLANE_AXIS_SQUARED`](crate::backend::MIN_IMAGE_PLANE_AXIS_SQUARED) (a
/// field of view of 10⁻³⁶° had passed, to be refused by the generate stage, without the camera
/// named).
fn check_camera(scene: &str, c: &Camera) -> Result<()> {
    let half_height = crate::frame::image_plane_half_height(c.vertical_fov_degrees);
    let fov_ok = c.vertical_fov_degrees > 0.0
        && c.vertical_fov_degrees < 180.0
        && half_height * half_height >= crate::backend::MIN_IMAGE_PLANE_AXIS_SQUARED;
    let finite = in_range(c.position) && in_range(c.look_at) && c.up.is_finite();
    if !(finite && fov_ok && c.has_view_basis()) {
        return Err(Error::InvalidParameter {
            name: "camera",
            reason: format!(
                "{scene}: degenerate camera {c:?} (the position and look-at point must be finite and within \
                 ±{MAX_COORDINATE:e}, apart, and not in line with the up direction; the vertical field of \
                 view in (0°, 180°), its tan(fov / 2) at least {:e})",
                crate::backend::MIN_IMAGE_PLANE_AXIS_SQUARED.sqrt()
            ),
        });
    }
    Ok(())
}

/// Whether every coordinate of `p` is finite and within [`MAX_COORDINATE`].
fn in_range(p: Vec3) -> bool {
    // `max_element` skips NaN, hence `is_finite`.
    p.is_finite() && p.abs().max_element() <= MAX_COORDINATE
}

/// Checks every vertex is finite and within [`MAX_COORDINATE`] and every index is in range,
/// naming the first offender.
fn check_indices_and_vertices(scene: &str, meshes: &[Mesh]) -> Result<()> {
    for mesh in meshes {
        if let Some((vertex, p)) = mesh.positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(Error::NonFiniteVertex {
                scene: scene.to_owned(),
                mesh: mesh.name.clone(),
                vertex,
                position: p.to_string(),
            });
        }
        if let Some((vertex, p)) = mesh.positions.iter().enumerate().find(|(_, p)| !in_range(**p)) {
            return Err(Error::VertexOutOfRange {
                scene: scene.to_owned(),
                mesh: mesh.name.clone(),
                vertex,
                position: p.to_string(),
                limit: MAX_COORDINATE,
            });
        }
        for (triangle, indices) in mesh.triangles.iter().enumerate() {
            if let Some(&index) = indices.iter().find(|&&i| i as usize >= mesh.positions.len()) {
                return Err(Error::IndexOutOfRange {
                    scene: scene.to_owned(),
                    mesh: mesh.name.clone(),
                    triangle,
                    index,
                    vertex_count: mesh.positions.len(),
                });
            }
        }
    }
    Ok(())
}

/// Checks every mesh's material ([`Material::check`]), naming the first offender's mesh and
/// field — all meshes, also those `Scene::new` then removes for having no triangle of non-zero
/// area, as [`check_indices_and_vertices`] checks their vertices.
fn check_materials(scene: &str, meshes: &[Mesh]) -> Result<()> {
    for mesh in meshes {
        mesh.material.check().map_err(|(name, reason)| Error::InvalidParameter {
            name,
            reason: format!("{scene}: mesh {:?} {reason}", mesh.name),
        })?;
    }
    Ok(())
}

/// Whether a triangle of corners `[a, b, c]` has non-zero area in `f32`: the triangles
/// `Scene::new` keeps.
fn has_area([a, b, c]: [Vec3; 3]) -> bool {
    (b - a).cross(c - a) != Vec3::ZERO
}

/// The corners of `meshes`' triangles of non-zero area — the scene `Scene::new` keeps, also where
/// a loader frames its camera before it; a triangle with an index past its mesh's positions
/// (refused by `Scene::new`) is skipped.
fn kept_triangles(meshes: &[Mesh]) -> impl Iterator<Item = [Vec3; 3]> + '_ {
    let corners = |mesh: &Mesh, t: &[u32; 3]| -> Option<[Vec3; 3]> {
        let [a, b, c] = t.map(|i| mesh.positions.get(i as usize).copied());
        Some([a?, b?, c?])
    };
    meshes
        .iter()
        .flat_map(move |mesh| mesh.triangles.iter().filter_map(move |t| corners(mesh, t)))
        .filter(|&corners| has_area(corners))
}

/// Axis-aligned bounds (min, max) of the vertices of [`kept_triangles`]. `(f32::MAX, f32::MIN)`
/// per axis where no triangle is left.
fn triangle_bounds(meshes: &[Mesh]) -> (Vec3, Vec3) {
    kept_triangles(meshes)
        .flatten()
        .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), p| (lo.min(p), hi.max(p)))
}

/// Below this share of the area that the scene shows along x or y, the area it shows along z
/// frames it from x or y ([`framing_camera`]): a floor or a wall in a plane through the z axis,
/// seen edge-on from +z, had filled no pixel (a real OBJ lamp, floor or wall alone rendered an
/// empty image). A share, not 0, so that a plane tilted by a few degrees counts too (5 %: 2.9°).
const EDGE_ON_SHARE: f64 = 0.05;

/// The axis a camera frames `meshes` along (0 x, 1 y, 2 z) and the side it looks from (±1): z,
/// from +z — unless the triangles show less than [`EDGE_ON_SHARE`] of the area along z that they
/// show along x or y (the sums of their areas projected on each axis), then that axis of x and y
/// that shows more, from the side their front faces (counter-clockwise) face more, +1 where
/// neither does. Over [`kept_triangles`], in `f64` (twice their areas, which the ratios ignore).
fn framing_axis(meshes: &[Mesh]) -> (usize, f32) {
    let (mut shown, mut facing) = (DVec3::ZERO, DVec3::ZERO);
    for [a, b, c] in kept_triangles(meshes).map(|corners| corners.map(Vec3::as_dvec3)) {
        let area = (b - a).cross(c - a);
        shown += area.abs();
        facing += area;
    }
    let across = if shown.y > shown.x { 1 } else { 0 };
    // (False for NaN areas, which validation refuses, and for no triangles: z.)
    let edge_on = shown.z < EDGE_ON_SHARE * shown[across];
    if !edge_on {
        return (2, 1.0);
    }
    (across, if facing[across] < 0.0 { -1.0 } else { 1.0 })
}

/// A camera on the +z side of the bounds' centre that sees the whole bounding sphere with a 45°
/// vertical field of view, y up — or, for a scene that shows almost no area to +z
/// ([`framing_axis`]: a floor or wall in a plane through the z axis), on the side of the x or y
/// axis it shows more area to, the side its front faces face (y up, or −z up looking down y
/// and +z up looking up it, so that +x stays to the right). From farther, with a narrower field
/// of view, where that camera would lie within 64 steps of `f32` of the centre (a small scene far
/// from the origin). Where that camera would lie beyond [`MAX_COORDINATE`] (a scene more than
/// 3.8·10⁷ across), it goes to the other side if it fits there, else to the side with more room,
/// just inside the limit, with the field of view widened to still see the sphere (at most 120°,
/// which sees all of it from 1.15 radii and more). Non-finite bounds are left for validation to
/// report.
pub(crate) fn framing_camera(meshes: &[Mesh]) -> Camera {
    let (lo, hi) = triangle_bounds(meshes);
    let (axis, preferred_side) = framing_axis(meshes);
    let along = Vec3::AXES[axis];
    let centre = (lo + hi) * 0.5;
    // At least √(f32::MIN_POSITIVE) ≈ 10⁻¹⁹, only so that the camera's distance has a normal
    // square and its view direction normalizes: a floor of 10⁻³ framed a scene 3·10⁻⁵ across from
    // 70 times too far, and no camera ray hit it.
    let radius = ((hi - lo).length() * 0.5).max(f32::MIN_POSITIVE.sqrt());
    // At least 64 steps of f32 from the centre: far from the origin, the 45° camera of a small
    // scene (a 1 mm triangle at z = 10⁵) rounded onto its look-at point and was refused as
    // degenerate. Farther away, the field of view narrows to keep the scene framed.
    let resolvable = 64.0 * f32::EPSILON * centre.abs().max_element();
    let at_45_degrees = radius / 22.5f32.to_radians().sin();
    let wanted = at_45_degrees.max(resolvable);
    // The room between the centre and the coordinate limit on the preferred side and on the other.
    // (0.999 of it: the camera's coordinate must not round past the limit.)
    let room = |side: f32| 0.999 * (MAX_COORDINATE - side * centre[axis]);
    let other_side = -preferred_side;
    let (side, distance) = if wanted <= room(preferred_side) {
        (preferred_side, wanted)
    } else if wanted <= room(other_side) {
        (other_side, wanted)
    } else if room(preferred_side) >= room(other_side) {
        (preferred_side, room(preferred_side))
    } else {
        (other_side, room(other_side))
    };
    let position = centre + along * (side * distance);
    let vertical_fov_degrees = if wanted == at_45_degrees && distance == wanted {
        45.0
    } else {
        // Against the coordinate limit, wider; moved out to be resolvable, narrower: the angle
        // under which the sphere is seen from where the camera lies after rounding (up to half a
        // step closer), at most 120° (a camera in or near the sphere sees what that shows).
        let seen_from = (position[axis] - centre[axis]).abs();
        2.0 * (radius / seen_from).min(1.0).asin().to_degrees().min(60.0)
    };
    let position = if position.is_finite() { position } else { along };
    let centre = if centre.is_finite() { centre } else { Vec3::ZERO };
    let up = if axis == 1 { Vec3::Z * -side } else { Vec3::Y };
    Camera { position, look_at: centre, up, vertical_fov_degrees, mirrored: false }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The Cornell box and the same box with its tall block (mesh 6) moved 5 cm along x, built
    /// apart as an engine rebuilds its scene after moving an object.
    pub(crate) fn cornell_and_moved() -> (Scene, Scene) {
        let scene = Scene::load("builtin:cornell").unwrap();
        let mut meshes = scene.meshes().to_vec();
        meshes[6].positions.iter_mut().for_each(|p| p.x += 0.05);
        let moved = Scene::new(scene.name(), meshes, *scene.camera()).unwrap();
        (scene, moved)
    }

    fn triangle_mesh(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Mesh {
        Mesh { name: "m".into(), positions, triangles, material: Material::diffuse(Vec3::ONE) }
    }

    fn unit_triangle() -> Vec<Vec3> {
        vec![Vec3::ZERO, Vec3::X, Vec3::Y]
    }

    fn scene_with(mesh: Mesh) -> Result<Scene> {
        Scene::new("test", vec![mesh], cornell::camera())
    }

    /// The bounds hold the vertices triangles use, not one no triangle uses nor one only a dropped
    /// zero-area triangle used (both had been folded in), and so does the camera a loader frames
    /// before `Scene::new` drops that triangle (it had framed the empty space out to it).
    #[test]
    fn bounds_hold_the_vertices_triangles_use() {
        let far = Vec3::splat(1e7);
        let mut positions = unit_triangle();
        positions.extend([far, far * 0.5]);
        let mesh = triangle_mesh(positions, vec![[0, 1, 2], [3, 4, 3]]);
        assert_eq!(
            framing_camera(std::slice::from_ref(&mesh)),
            framing_camera(&[triangle_mesh(unit_triangle(), vec![[0, 1, 2]])])
        );
        let scene = scene_with(mesh).unwrap();
        assert_eq!(scene.dropped_degenerate(), 1);
        assert_eq!(scene.bounds(), (Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0)));
    }

    /// `set_camera` moves the view the generate stage's parameters are made from, and refuses a
    /// camera `Scene::new` would refuse (NaN, beyond the coordinate limit, on its look-at point,
    /// looking along its up), leaving the camera as it was.
    #[test]
    fn set_camera_moves_the_view_and_refuses_degenerate_cameras() {
        let mut scene = scene_with(triangle_mesh(unit_triangle(), vec![[0, 1, 2]])).unwrap();
        let moved =
            Camera { position: Vec3::new(0.25, 0.25, 3.0), look_at: Vec3::new(0.25, 0.25, 0.0), ..*scene.camera() };
        scene.set_camera(moved).unwrap();
        assert_eq!(*scene.camera(), moved);
        let params = crate::frame::generate_params(&scene, 8, 8, 0);
        assert_eq!((params.origin.truncate(), params.forward.truncate()), (moved.position, Vec3::NEG_Z));
        for (what, camera) in [
            ("NaN position", Camera { position: Vec3::NAN, ..moved }),
            ("beyond the limit", Camera { position: Vec3::splat(2.0 * MAX_COORDINATE), ..moved }),
            ("on its look-at point", Camera { look_at: moved.position, ..moved }),
            ("looking along its up", Camera { up: Vec3::NEG_Z, ..moved }),
            ("a 180° field of view", Camera { vertical_fov_degrees: 180.0, ..moved }),
            ("a 10⁻³⁶° field of view", Camera { vertical_fov_degrees: 1e-36, ..moved }),
        ] {
            let err = scene.set_camera(camera).unwrap_err();
            assert!(err.to_string().contains("degenerate camera"), "{what}: {err}");
            assert_eq!(*scene.camera(), moved, "{what}: the camera is kept");
        }
    }

    /// A 2 × 2 wall and a 0.4 × 0.4 lamp 1 above it, scaled by 2⁻¹³ (≈ 10⁻⁴) and 2⁻²⁰ (≈ 10⁻⁶):
    /// the framing camera's rays hit it exactly as at scale 1 (a power of two scales the camera
    /// and the hits without rounding). A floor of 10⁻³ on the radius had framed the 10⁻⁴ scene from
    /// 5 times too far and the 10⁻⁶ one from 700 times, where no ray hit.
    #[test]
    fn tiny_scenes_are_framed_as_at_scale_one() {
        let hits = |scale: f32| {
            let quad = |half: f32, z: f32| {
                let corners = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];
                corners.map(|[x, y]| Vec3::new(x * half, y * half, z) * scale).to_vec()
            };
            let meshes: Vec<Mesh> = [(1.0, 0.0), (0.2, 1.0)]
                .into_iter()
                .map(|(half, z)| triangle_mesh(quad(half, z), vec![[0, 1, 2], [0, 2, 3]]))
                .collect();
            let camera = framing_camera(&meshes);
            let scene = Scene::new("tiny", meshes, camera).unwrap();
            let rays = crate::cpu::generate(&crate::frame::generate_params(&scene, 32, 32, 0)).unwrap();
            crate::cpu::trace(&crate::cpu::CpuScene::build(&scene).unwrap(), &rays).unwrap().hit_count()
        };
        let at_one = hits(1.0);
        assert!(at_one > 32 * 32 / 8, "{at_one} hits at scale 1");
        for log2 in [-13, -20] {
            assert_eq!(hits(2f32.powi(log2)), at_one, "scale 2^{log2}");
        }
    }

    /// A floor or a wall alone, in a plane through the z axis (or tilted 2° off it), is framed
    /// along the axis it faces, from the side its front faces face, with +x to the right looking
    /// down or up y: from +z, edge-on, no camera ray had hit it (real OBJ lamps, floors and walls
    /// rendered empty images). A scene with area facing z keeps the +z camera.
    #[test]
    fn flat_scenes_through_the_z_axis_are_framed_from_the_side_they_face() {
        let quad = |corners: [Vec3; 4]| triangle_mesh(corners.to_vec(), vec![[0, 1, 2], [0, 2, 3]]);
        let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);
        let tilt = 2f32.to_radians();
        let tilted_wall = [Vec3::ZERO, (y * tilt.cos() + z * tilt.sin()) * 2.0, (y + z) * 2.0, z * 2.0];
        // (what, corners, the camera's side of the look-at point, its up, its right)
        for (what, corners, along, up, right) in [
            ("floor facing +y", [Vec3::ZERO, z * 2.0, (x + z) * 2.0, x * 2.0], y, -z, x),
            ("floor facing -y", [Vec3::ZERO, x * 2.0, (x + z) * 2.0, z * 2.0], -y, z, x),
            ("wall facing +x", [Vec3::ZERO, y * 2.0, (y + z) * 2.0, z * 2.0], x, y, -z),
            ("wall facing +x, tilted 2°", tilted_wall, x, y, -z),
            ("quad facing +z", [Vec3::ZERO, x * 2.0, (x + y) * 2.0, y * 2.0], z, y, x),
            ("quad facing -z", [Vec3::ZERO, y * 2.0, (x + y) * 2.0, x * 2.0], z, y, x),
        ] {
            let meshes = vec![quad(corners)];
            let camera = framing_camera(&meshes);
            let view = (camera.position - camera.look_at).normalize();
            assert!(view.abs_diff_eq(along, 1e-6) && camera.up == up, "{what}: {camera:?}");
            let forward = camera.look_at - camera.position;
            assert!(forward.cross(camera.up).normalize().abs_diff_eq(right, 1e-6), "{what}: mirrored or turned");
            let scene = Scene::new(what, meshes, camera).unwrap();
            let rays = crate::cpu::generate(&crate::frame::generate_params(&scene, 32, 32, 0)).unwrap();
            let hits = crate::cpu::trace(&crate::cpu::CpuScene::build(&scene).unwrap(), &rays).unwrap().hit_count();
            assert!(hits > 32 * 32 / 8, "{what}: {hits} hits");
        }
    }

    #[test]
    fn builtin_cornell_box_is_valid() {
        let scene = Scene::load("builtin:cornell").unwrap();
        assert_eq!(scene.meshes().len(), 8);
        assert_eq!(scene.triangle_count(), 2 * (5 + 1 + 5 + 5));
    }

    fn emitter(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>, emission: Vec3) -> Mesh {
        Mesh { material: Material { emission, ..Material::diffuse(Vec3::ONE) }, ..triangle_mesh(positions, triangles) }
    }

    fn facing(light: &Light) -> Vec3 {
        light.edge_u.truncate().cross(light.edge_v.truncate()).normalize()
    }

    #[test]
    fn cornell_has_one_downward_light_of_the_published_radiance() {
        let scene = Scene::load("builtin:cornell").unwrap();
        assert_eq!(scene.lights().len(), 1);
        assert_eq!(scene.unsupported_emitters(), 0);
        let light = scene.lights()[0];
        assert_eq!(light.radiance.truncate(), cornell::LIGHT);
        assert_eq!(light.two_sided, 0);
        assert!(facing(&light).abs_diff_eq(Vec3::NEG_Y, 1e-6), "{}", facing(&light));
        let area = light.edge_u.truncate().cross(light.edge_v.truncate()).length();
        assert!((area - 0.130 * 0.105).abs() < 1e-6, "{area}");
        assert_eq!(scene.meshes()[scene.light_mesh(0)].name, "light");
        assert_eq!(scene.mesh_light(scene.light_mesh(0)), Some(0));
        assert_eq!((0..scene.meshes().len()).filter(|&m| scene.mesh_light(m).is_some()).count(), 1);
    }

    #[test]
    fn cornell_light_grid_has_twenty_lights_within_the_published_one() {
        let scene = Scene::load("builtin:cornell-light-grid").unwrap();
        let published = Scene::load("builtin:cornell").unwrap();
        assert_eq!(scene.camera(), published.camera());
        assert_eq!((scene.lights().len(), scene.unsupported_emitters()), (20, 0));
        assert!(crate::lights::wants_bvh(scene.lights().len()));
        let bounds = |light: &Light| raywave_kernels::sampling::light_select::light_bounds(light);
        let outer = bounds(&published.lights()[0]);
        for (k, light) in scene.lights().iter().enumerate() {
            assert!(facing(light).abs_diff_eq(Vec3::NEG_Y, 1e-6), "light {k}: {}", facing(light));
            let inner = bounds(light);
            let inside = outer.min.truncate().cmple(inner.min.truncate() + 1e-6).all()
                && outer.max.truncate().cmpge(inner.max.truncate() - 1e-6).all();
            assert!(inside, "light {k}: {inner:?} outside {outer:?}");
        }
        let ratio = scene.lights().iter().map(|l| bounds(l).phi).sum::<f32>() / outer.phi;
        assert!((ratio - 0.8).abs() < 0.05, "{ratio}");
    }

    #[test]
    fn cornell_two_lights_has_two_coloured_lights_and_glossy_blocks() {
        let scene = Scene::load("builtin:cornell-two-lights").unwrap();
        assert!(BUILTIN_SCENES.contains(&"cornell-two-lights"));
        assert_eq!(scene.camera(), Scene::load("builtin:cornell").unwrap().camera());
        assert_eq!((scene.lights().len(), scene.unsupported_emitters()), (2, 0));
        let radiances: Vec<Vec3> = scene.lights().iter().map(|l| l.radiance.truncate()).collect();
        assert_eq!(radiances, [cornell::WARM_LIGHT, cornell::COOL_LIGHT]);
        for (k, light) in scene.lights().iter().enumerate() {
            assert!(facing(light).abs_diff_eq(Vec3::NEG_Y, 1e-6), "light {k}: {}", facing(light));
            assert!((light.position.y - 0.5487).abs() < 1e-6);
            assert_eq!(scene.mesh_light(scene.light_mesh(k)), Some(k as u32));
        }
        let block = |name: &str| scene.meshes().iter().find(|m| m.name == name).unwrap().material;
        assert_eq!((block("short block").roughness, block("short block").metallic), (0.25, 0.0));
        assert_eq!((block("tall block").roughness, block("tall block").metallic), (0.3, 1.0));
        assert!(scene.meshes().iter().all(|m| m.name != "light"));
    }

    #[test]
    fn builtin_scenes_have_no_unsupported_emitters() {
        for name in BUILTIN_SCENES {
            let scene = Scene::load(&format!("builtin:{name}")).unwrap();
            assert_eq!(scene.unsupported_emitters(), 0, "{name}");
        }
    }

    #[test]
    fn emissive_parallelograms_become_lights_facing_their_front() {
        // A unit square in the z = 1 plane; counter-clockwise seen from +z is 0 1 2 3. Both
        // diagonals, both windings, indexed or as six separate vertices.
        let c =
            [Vec3::new(0.0, 0.0, 1.0), Vec3::new(1.0, 0.0, 1.0), Vec3::new(1.0, 1.0, 1.0), Vec3::new(0.0, 1.0, 1.0)];
        let splits: [([[u32; 3]; 2], Vec3); 4] = [
            ([[0, 1, 2], [0, 2, 3]], Vec3::Z),
            ([[0, 1, 3], [1, 2, 3]], Vec3::Z),
            ([[0, 2, 1], [0, 3, 2]], Vec3::NEG_Z),
            ([[0, 3, 1], [1, 3, 2]], Vec3::NEG_Z),
        ];
        for (triangles, front) in splits {
            let flat: Vec<Vec3> = triangles.iter().flatten().map(|&i| c[i as usize]).collect();
            for mesh in [
                emitter(c.to_vec(), triangles.to_vec(), Vec3::splat(2.0)),
                emitter(flat, vec![[0, 1, 2], [3, 4, 5]], Vec3::splat(2.0)),
            ] {
                let floor = triangle_mesh(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
                let scene = Scene::new("test", vec![floor, mesh], cornell::camera()).unwrap();
                assert_eq!((scene.lights().len(), scene.unsupported_emitters()), (1, 0), "{triangles:?}");
                let light = scene.lights()[0];
                assert_eq!(facing(&light), front, "{triangles:?}");
                assert_eq!(light.edge_u.truncate().cross(light.edge_v.truncate()).length(), 1.0);
                assert_eq!((scene.light_mesh(0), scene.mesh_light(0), scene.mesh_light(1)), (1, None, Some(0)));
                // The emitter stays geometry.
                assert_eq!(scene.triangle_count(), 3);
            }
        }
    }

    #[test]
    fn non_planar_and_other_emitters_are_counted_not_lit() {
        let quad = vec![[0, 1, 2], [0, 2, 3]];
        let bent = emitter(vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.2), Vec3::Y], quad.clone(), Vec3::ONE);
        let trapezoid = emitter(vec![Vec3::ZERO, Vec3::X, Vec3::new(0.7, 1.0, 0.0), Vec3::Y], quad.clone(), Vec3::ONE);
        let sphere = Mesh {
            material: Material { emission: Vec3::ONE, ..Material::diffuse(Vec3::ONE) },
            ..procedural::icosphere("ball", Vec3::ZERO, 1.0, 1, Vec3::ONE).unwrap()
        };
        let scene = Scene::new("test", vec![bent, trapezoid, sphere], cornell::camera()).unwrap();
        assert_eq!((scene.lights().len(), scene.unsupported_emitters()), (0, 3));
        assert!((0..3).all(|m| scene.mesh_light(m).is_none()));
    }

    #[test]
    fn dark_and_degenerate_quads_are_not_lights() {
        let square = vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        let dark = emitter(square.clone(), vec![[0, 1, 2], [0, 2, 3]], Vec3::ZERO);
        // One triangle is degenerate and dropped; the single triangle left is no parallelogram.
        let half = emitter(square.clone(), vec![[0, 1, 2], [0, 2, 2]], Vec3::ONE);
        let scene = Scene::new("test", vec![dark, half], cornell::camera()).unwrap();
        assert_eq!(scene.dropped_degenerate(), 1);
        assert_eq!((scene.lights().len(), scene.unsupported_emitters()), (0, 1));
        // A quad collapsed onto a line has only zero-area triangles: dropped, no light, no mesh.
        let line =
            emitter(vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0, Vec3::X * 3.0], vec![[0, 1, 2], [0, 2, 3]], Vec3::ONE);
        let lit = emitter(square, vec![[0, 1, 2], [0, 2, 3]], Vec3::ONE);
        let scene = Scene::new("test", vec![line, lit], cornell::camera()).unwrap();
        assert_eq!((scene.meshes().len(), scene.lights().len(), scene.unsupported_emitters()), (1, 1, 0));
        assert_eq!(scene.light_mesh(0), 0, "mesh indices count after empty meshes are removed");
    }

    #[test]
    fn invalid_emission_is_an_error_and_the_largest_light_loads() {
        let square = vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        for (emission, field) in [
            (Vec3::new(1.0, -1.0, 0.0), "material.emission"),
            (Vec3::new(f32::NAN, 1.0, 1.0), "material.emission"),
            (Vec3::splat(f32::INFINITY), "material.emission"),
            (Vec3::splat(f32::MAX), "material.emission"),
            (Vec3::new(0.0, 2.0 * MAX_EMISSION, 0.0), "material.emission"),
        ] {
            match scene_with(emitter(square.clone(), vec![[0, 1, 2], [0, 2, 3]], emission)) {
                Err(Error::InvalidParameter { name, reason }) => {
                    assert_eq!(name, field, "{emission}");
                    assert!(reason.contains("test") && reason.contains("\"m\""), "{reason}");
                }
                other => panic!("{emission}: expected an invalid {field}, got {other:?}"),
            }
        }
        // Within both limits a light's power fits in `f32`: the largest square light, spanning
        // ±MAX_COORDINATE, at the largest emission (π · (2·10⁸)² · 10²⁰ ≈ 1.3·10³⁷ W) loads.
        // At the former limit of 10¹⁸ such a light's power overflowed (`lights::validate_light`
        // still refuses that for lights given directly).
        let largest = square.iter().map(|p| (*p * 2.0 - Vec3::new(1.0, 1.0, 0.0)) * MAX_COORDINATE).collect();
        let scene = scene_with(emitter(largest, vec![[0, 1, 2], [0, 2, 3]], Vec3::splat(MAX_EMISSION))).unwrap();
        assert_eq!(scene.lights().len(), 1);
    }

    /// A mesh whose triangles all have zero area (a lamp too small for `f32` far from the origin,
    /// or a collapsed one) is removed, but an emission outside `[0, MAX_EMISSION]` on it is still
    /// an error naming the mesh, as a NaN vertex of such a mesh is: the materials were checked
    /// only on the meshes left, so `Scene::new` took NaN, negative and infinite emission (215 of
    /// 4000 random emissive meshes in a helper's sweep, every one a lamp collapsed by rounding).
    #[test]
    fn invalid_emission_on_a_mesh_of_only_zero_area_triangles_is_an_error() {
        let floor = triangle_mesh(unit_triangle(), vec![[0, 1, 2]]);
        // A 10⁻⁴ lamp 3·10⁶ from the origin: its corners round onto one f32 point.
        let lamp: Vec<Vec3> = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y]
            .iter()
            .map(|p| *p * 1e-4 + Vec3::new(3e6, 0.0, 0.0))
            .collect();
        for emission in [Vec3::new(f32::NAN, 1.0, 1.0), Vec3::new(1.0, -1.0, 0.0), Vec3::splat(f32::INFINITY)] {
            let lamp = Mesh { name: "lamp".into(), ..emitter(lamp.clone(), vec![[0, 1, 2], [0, 2, 3]], emission) };
            match Scene::new("test", vec![floor.clone(), lamp], cornell::camera()) {
                Err(Error::InvalidParameter { name, reason }) => {
                    assert_eq!(name, "material.emission", "{emission}");
                    assert!(reason.contains("test") && reason.contains("\"lamp\""), "{reason}");
                }
                other => panic!("{emission}: expected an invalid material.emission, got {other:?}"),
            }
        }
    }

    #[test]
    fn materials_outside_their_ranges_are_errors() {
        let lit = Material::diffuse(Vec3::splat(0.5));
        for (material, field) in [
            (Material { base_color: Vec3::new(0.5, -0.1, 0.5), ..lit }, "material.base_color"),
            (Material { base_color: Vec3::new(0.5, 1.5, 0.5), ..lit }, "material.base_color"),
            (Material { base_color: Vec3::new(f32::NAN, 0.5, 0.5), ..lit }, "material.base_color"),
            (Material { roughness: -0.5, ..lit }, "material.roughness"),
            (Material { metallic: f32::NAN, ..lit }, "material.metallic"),
        ] {
            let mesh = Mesh { material, ..triangle_mesh(unit_triangle(), vec![[0, 1, 2]]) };
            match scene_with(mesh) {
                Err(Error::InvalidParameter { name, reason }) => {
                    assert_eq!(name, field, "{material:?}");
                    assert!(reason.contains("test") && reason.contains("\"m\""), "{reason}");
                }
                other => panic!("{material:?}: expected an invalid {field}, got {other:?}"),
            }
        }
        let edges = Material { base_color: Vec3::ONE, roughness: 0.0, metallic: 1.0, ..lit };
        assert!(scene_with(Mesh { material: edges, ..triangle_mesh(unit_triangle(), vec![[0, 1, 2]]) }).is_ok());
    }

    #[test]
    fn coordinates_beyond_the_limit_are_errors_and_the_limit_itself_is_not() {
        let far = |scale: f32| unit_triangle().into_iter().map(|p| p * scale).collect::<Vec<_>>();
        let err = scene_with(triangle_mesh(far(2.0 * MAX_COORDINATE), vec![[0, 1, 2]])).unwrap_err();
        assert!(matches!(err, Error::VertexOutOfRange { vertex: 1, .. }), "{err}");
        assert!(err.to_string().contains("\"m\"") && err.to_string().contains("1e8"), "{err}");
        let cornell = cornell::camera();
        for camera in [
            Camera { position: Vec3::new(0.0, 0.0, -2.0 * MAX_COORDINATE), ..cornell },
            Camera { position: Vec3::new(f32::NAN, 0.0, -1.0), ..cornell },
            // Non-zero, but too short to normalize in f32 (the generate stage's rays were NaN).
            Camera { look_at: cornell.position + Vec3::new(1e-30, 0.0, 0.0), ..cornell },
            Camera { position: Vec3::ZERO, look_at: Vec3::X, up: Vec3::new(1.0, 1e-30, 0.0), ..cornell },
        ] {
            let err = Scene::new("test", vec![triangle_mesh(unit_triangle(), vec![[0, 1, 2]])], camera).unwrap_err();
            assert!(matches!(err, Error::InvalidParameter { name: "camera", .. }), "{camera:?}: {err}");
        }
        // At the limit the scene loads, and the CPU backend builds its BVH (obvhs' CWBVH build
        // panicked from about 10¹⁹ on).
        let camera = Camera { position: Vec3::new(0.0, 0.0, MAX_COORDINATE), ..cornell::camera() };
        let scene = Scene::new("test", vec![triangle_mesh(far(MAX_COORDINATE), vec![[0, 1, 2]])], camera).unwrap();
        crate::Backend::load_scene(&mut crate::cpu::CpuBackend::new(), &scene).unwrap();
    }

    #[test]
    fn unknown_builtin_is_named() {
        let err = Scene::load("builtin:nope").unwrap_err();
        assert!(matches!(err, Error::UnknownBuiltinScene { ref name, .. } if name == "nope"), "{err}");
    }

    #[test]
    fn empty_scene_is_rejected() {
        assert!(matches!(
            scene_with(triangle_mesh(vec![], vec![])),
            Err(Error::EmptyScene { dropped_degenerate: 0, .. })
        ));
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
    fn zero_area_triangles_are_dropped_and_counted_and_out_of_range_ones_rejected() {
        let scene = scene_with(triangle_mesh(unit_triangle(), vec![[0, 1, 2], [0, 1, 1], [2, 2, 2]])).unwrap();
        assert_eq!((scene.triangle_count(), scene.dropped_degenerate()), (1, 2));
        let err = scene_with(triangle_mesh(unit_triangle(), vec![[0, 1, 1]])).unwrap_err();
        assert!(matches!(err, Error::EmptyScene { dropped_degenerate: 1, .. }), "{err}");
        let err = scene_with(triangle_mesh(unit_triangle(), vec![[0, 1, 3]])).unwrap_err();
        assert!(matches!(err, Error::IndexOutOfRange { index: 3, vertex_count: 3, .. }), "{err}");
    }

    #[test]
    fn tiny_but_non_degenerate_triangles_are_kept() {
        let p = unit_triangle().into_iter().map(|v| v * 1e-6).collect();
        assert!(scene_with(triangle_mesh(p, vec![[0, 1, 2]])).is_ok());
    }
}
