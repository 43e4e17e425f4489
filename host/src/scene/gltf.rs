//! glTF 2.0 scenes (through the `gltf` crate): the default scene's node hierarchy with its
//! transforms (and `EXT_mesh_gpu_instancing`'s instances, [`instancing`]), every triangle primitive
//! as a mesh (one without POSITION is skipped, as glTF 2.0 § 3.7.2.1 asks; its positions may be
//! `KHR_mesh_quantization`'s integers, [`MESH_QUANTIZATION`]), buffer views compressed by meshopt
//! ([`meshopt`]), metallic-roughness materials with emission (and
//! `KHR_materials_emissive_strength`; `doubleSided` makes an emissive rectangle a two-sided light,
//! and is read for nothing else: rays meet both sides of every triangle, so `doubleSided: false`
//! culls no back face), and the first perspective camera, if any — looking at the point along its
//! view at the depth of the scene's centre, which sets the default focus ([`PlacedCamera::aimed`]).
//! What raywave does not render — textures, see-through materials, skins and morph targets,
//! orthographic cameras, punctual lights — is counted ([`Scene::unrendered`]).
//!
//! Bad files give an [`Error::SceneLoad`] naming the file and the JSON field, never a panic or a
//! hang: on top of the `gltf` crate's validation this checks what that crate trusts (POSITION
//! accessor indices, the accessor types of POSITION and indices, accessor counts and spans
//! against their buffer views and buffers), that the node hierarchy is a tree, and what glTF 2.0
//! forbids that the crate takes (such as `normalized` POSITION or indices, a mesh without
//! primitives, a GLB length other than the file's). Images are not loaded (textures are not
//! sampled), so a missing texture file is no error.

use super::regular_file::{read_regular_file, ReadError};
use super::{
    framing_camera, in_range, triangle_bounds, Camera, Material, Mesh, Scene, Unrendered, MAX_COORDINATE,
    MAX_TRIANGLES, MAX_VERTICES,
};
use crate::error::{Error, Result};
use components::ComponentFormat;
use glam::{DMat3, DVec3, Mat4, Vec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::json::validation::Checked;
use gltf::mesh::Mode;
use gltf::{buffer, Document, Semantic};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

mod components;
mod instancing;
mod json_text;
mod meshopt;

/// Loads and validates a `.gltf` or `.glb` file.
pub fn load(path: &Path) -> Result<Scene> {
    let load_error = |message: String| Error::SceneLoad { path: path.to_owned(), message };
    let bytes = read_regular_file(path, u64::MAX).map_err(|e| load_error(e.to_string()))?;
    let (document, buffers) = parse(&bytes, path.parent()).map_err(load_error)?;
    let scene = document
        .default_scene()
        .or_else(|| document.scenes().next())
        .ok_or_else(|| load_error("the file defines no scene".into()))?;
    let nodes = scene_nodes(&document, &scene).map_err(load_error)?;
    // Counted before any is read: nodes (and each node's `EXT_mesh_gpu_instancing` instances) may
    // instance one large accessor many times over. Each mesh's accessors are checked once,
    // however many nodes instance it, and its instances counted, so that the last one can take
    // the geometry read for them all.
    let (mut vertices, mut triangle_count): (u64, u64) = (0, 0);
    let mut mesh_sizes: HashMap<usize, (u64, u64)> = HashMap::new();
    let mut checked_accessors = CheckedAccessors::new();
    let position_use = AccessorUse::position_in(&document);
    let mut instances_left: HashMap<usize, usize> = HashMap::new();
    // Where each node places its mesh (none for a node without one).
    let mut node_placements: Vec<Vec<Placement>> = Vec::with_capacity(nodes.len());
    let mut hidden_meshes = 0usize;
    for SceneNode { node, world, visible } in &nodes {
        hidden_meshes += usize::from(node.mesh().is_some() && !visible);
        let Some(mesh) = node.mesh().filter(|_| *visible) else {
            node_placements.push(Vec::new());
            continue;
        };
        let placements =
            Placement::of_node(&document, node, *world, &buffers, &mut checked_accessors).map_err(load_error)?;
        let (mesh_vertices, mesh_triangles) = match mesh_sizes.get(&mesh.index()) {
            Some(&size) => size,
            None => *mesh_sizes
                .entry(mesh.index())
                .or_insert(mesh_size(&mesh, &buffers, position_use, &mut checked_accessors).map_err(load_error)?),
        };
        let copies = placements.len() as u64;
        vertices = vertices.saturating_add(mesh_vertices.saturating_mul(copies));
        triangle_count = triangle_count.saturating_add(mesh_triangles.saturating_mul(copies));
        *instances_left.entry(mesh.index()).or_default() += placements.len();
        node_placements.push(placements);
    }
    for (count, limit, what) in [(vertices, MAX_VERTICES, "vertices"), (triangle_count, MAX_TRIANGLES, "triangles")] {
        if count > limit as u64 {
            return Err(Error::SceneTooLarge {
                scene: path.display().to_string(),
                what: format!("its nodes instance {count} {what}, more than {limit}"),
            });
        }
    }
    let placed_meshes: usize = instances_left.values().sum();
    let mut meshes = Vec::new();
    // Each primitive read once, kept while nodes still to come instance its mesh.
    let mut geometries: HashMap<(usize, usize), PrimitiveGeometry> = HashMap::new();
    let mut unrendered = Unrendered::default();
    let (mut placed_camera, mut orthographic) = (None, false);
    for (SceneNode { node, world, visible }, placements) in nodes.iter().zip(node_placements) {
        unrendered.punctual_lights += usize::from(node.light().is_some() && *visible);
        if let (None, Some(node_camera)) = (&placed_camera, node.camera()) {
            match node_camera.projection() {
                gltf::camera::Projection::Perspective(p) => {
                    placed_camera = Some(PlacedCamera::new(node, &node_camera, &p, *world).map_err(load_error)?);
                }
                gltf::camera::Projection::Orthographic(_) => orthographic = true,
            }
        }
        let Some(mesh) = node.mesh() else { continue };
        for placement in &placements {
            let last_instance = instances_left.get_mut(&mesh.index()).is_some_and(|left| {
                *left -= 1;
                *left == 0
            });
            for (index, primitive) in mesh.primitives().enumerate() {
                if !draws_surfaces(&primitive) {
                    let positions = primitive.get(&Semantic::Positions).is_some();
                    unrendered.point_and_line_primitives += usize::from(positions);
                    continue;
                }
                // An unnamed mesh is named by its JSON path, so errors that name the mesh find it.
                let mesh_name = mesh.name().map_or_else(|| format!("meshes[{}]", mesh.index()), str::to_owned);
                let name = format!("{mesh_name} primitive {index}");
                let field = primitive_field(&mesh, index);
                let in_primitive = |e: String| load_error(format!("{e} (in {name:?})"));
                let key = (mesh.index(), index);
                let geometry = match geometries.remove(&key) {
                    Some(geometry) => geometry,
                    None => PrimitiveGeometry::read(&primitive, &buffers, &field).map_err(in_primitive)?,
                };
                let (positions, triangles) = if last_instance {
                    geometry.into_instance(&field, placement)
                } else {
                    let instance = geometry.instance(&field, placement);
                    geometries.insert(key, geometry);
                    instance
                }
                .map_err(in_primitive)?;
                let material = material(&primitive.material()).map_err(load_error)?;
                let coloured = has_textures(&primitive.material()) || has_vertex_colours(&primitive);
                unrendered.textured_meshes += usize::from(coloured);
                unrendered.see_through_meshes += usize::from(is_see_through(&primitive.material()));
                unrendered.unlit_meshes += usize::from(primitive.material().extension_value(UNLIT).is_some());
                unrendered.deformed_meshes += usize::from(is_deformed(node, &mesh, &primitive));
                meshes.push(Mesh { name, positions, triangles, material });
            }
        }
    }
    unrendered.orthographic_camera = orthographic && placed_camera.is_none();
    let camera = match placed_camera {
        Some(placed) => placed.aimed(&meshes).map_err(load_error)?,
        None => framing_camera(&meshes),
    };
    let scene = Scene::new(&path.display().to_string(), meshes, camera).map_err(|e| match e {
        // Else the error blamed zero-area triangles, of which there may be none.
        Error::EmptyScene { .. } if placed_meshes == 0 && hidden_meshes > 0 => load_error(format!(
            "its scene shows no mesh: the {hidden_meshes} node(s) with a mesh are hidden ({NODE_VISIBILITY} \
             `visible: false` on them or an ancestor)"
        )),
        Error::EmptyScene { .. } if placed_meshes == 0 => {
            load_error("its scene places no mesh: none of its nodes, nor their children, has `mesh`".to_owned())
        }
        Error::EmptyScene { dropped_degenerate, .. } if unrendered.point_and_line_primitives > 0 => {
            load_error(format!(
                "its meshes draw no surface: {} primitive(s) draw points or lines, which raywave does not render \
             ({dropped_degenerate} zero-area triangles dropped)",
                unrendered.point_and_line_primitives
            ))
        }
        e => e,
    })?;
    Ok(scene.with_unrendered(unrendered))
}

/// Whether material `m` has a texture that would change its colour, roughness, metalness or
/// emission — which raywave does not sample ([`Unrendered::textured_meshes`]).
fn has_textures(m: &gltf::Material) -> bool {
    let pbr = m.pbr_metallic_roughness();
    pbr.base_color_texture().is_some() || pbr.metallic_roughness_texture().is_some() || m.emissive_texture().is_some()
}

/// Whether `primitive` has vertex colours, `COLOR_0`, which glTF 2.0 (§ 3.9.2) multiplies into
/// the base colour and raywave does not read ([`Unrendered::textured_meshes`]): a
/// vertex-coloured file, often with a white base colour, would render in one colour unsaid.
fn has_vertex_colours(primitive: &gltf::Primitive) -> bool {
    primitive.get(&gltf::Semantic::Colors(0)).is_some()
}

/// The extension that makes a glTF material unlit ([`Unrendered::unlit_meshes`]).
const UNLIT: &str = "KHR_materials_unlit";

/// Whether material `m` lets light through somewhere, which raywave does not render
/// ([`Unrendered::see_through_meshes`]): its alpha (factor, or a base-colour texture's, unknown
/// as images are not read) is blended, or masked below the cutoff (glTF 2.0 § 3.9.4: `OPAQUE`
/// ignores alpha; the cutoff defaults to 0.5), or it transmits light (`KHR_materials_transmission`:
/// a factor above 0, its default, or a texture, whose values are not read).
fn is_see_through(m: &gltf::Material) -> bool {
    let pbr = m.pbr_metallic_roughness();
    let [.., alpha] = pbr.base_color_factor();
    let textured = pbr.base_color_texture().is_some();
    let transmits = m.extension_value("KHR_materials_transmission").is_some_and(|transmission| {
        transmission.get("transmissionTexture").is_some()
            || transmission.get("transmissionFactor").and_then(gltf::json::Value::as_f64).is_some_and(|f| f > 0.0)
    });
    transmits
        || match m.alpha_mode() {
            gltf::material::AlphaMode::Opaque => false,
            gltf::material::AlphaMode::Blend => textured || alpha < 1.0,
            gltf::material::AlphaMode::Mask => textured || alpha < m.alpha_cutoff().unwrap_or(0.5),
        }
}

/// One place a node puts its mesh at: the node's world transform, or one of its instances under
/// `EXT_mesh_gpu_instancing` ([`instancing`]).
struct Placement {
    /// From the mesh's space to world space.
    world: Mat4,
    /// The node's index, which errors name.
    node: usize,
    /// The instance's index, which errors name; `None` for the node's own transform.
    instance: Option<usize>,
}

impl Placement {
    /// Where `node`, of world transform `world`, puts its mesh: at each of its instances
    /// ([`instancing::instance_transforms`], whose errors this returns), else at the node.
    fn of_node(
        document: &Document,
        node: &gltf::Node,
        world: Mat4,
        buffers: &[buffer::Data],
        checked: &mut CheckedAccessors,
    ) -> std::result::Result<Vec<Self>, String> {
        let node_index = node.index();
        Ok(match instancing::instance_transforms(document, node, buffers, checked)? {
            Some(instances) => instances
                .into_iter()
                .enumerate()
                .map(|(k, instance)| Self { world: world * instance, node: node_index, instance: Some(k) })
                .collect(),
            None => vec![Self { world, node: node_index, instance: None }],
        })
    }

    /// The transform's source, as errors name it.
    fn source(&self) -> String {
        match self.instance {
            Some(k) => format!("nodes[{}]'s instance {k} ({})", self.node, instancing::EXTENSION),
            None => format!("nodes[{}]", self.node),
        }
    }
}

/// Whether node `node` would deform `primitive` of its mesh `mesh` in a way raywave does not
/// apply ([`Unrendered::deformed_meshes`]): a skin, or morph targets with a non-zero weight (the
/// node's weights, else the mesh's; glTF 2.0 § 3.7.2.2 defaults them to 0).
fn is_deformed(node: &gltf::Node, mesh: &gltf::Mesh, primitive: &gltf::Primitive) -> bool {
    let weights = node.weights().or_else(|| mesh.weights()).unwrap_or_default();
    node.skin().is_some() || (primitive.morph_targets().next().is_some() && weights.iter().any(|&w| w != 0.0))
}

/// The JSON path of primitive `index` of `mesh`, which errors name.
fn primitive_field(mesh: &gltf::Mesh, index: usize) -> String {
    format!("meshes[{}].primitives[{index}]", mesh.index())
}

/// A node of the scene, as [`scene_nodes`] reaches it.
struct SceneNode<'a> {
    /// The node.
    node: gltf::Node<'a>,
    /// Its world transform.
    world: Mat4,
    /// Whether its mesh and lights are shown ([`NODE_VISIBILITY`]); its camera is used either way.
    visible: bool,
}

/// The extension that hides a node and every node below it (`"visible": false`), whatever their
/// own value: "a value of `false` causes all nodes below in the hierarchy to be omitted from
/// display … Visibility affects neither cameras, nor node's interactivity features" (the
/// extension's specification, ratified by Khronos).
const NODE_VISIBILITY: &str = "KHR_node_visibility";

/// Whether `node` itself is visible ([`NODE_VISIBILITY`]; true without the extension): an error
/// if `visible` is there but not a boolean.
fn own_visibility(node: &gltf::Node) -> std::result::Result<bool, String> {
    let Some(visible) = node.extension_value(NODE_VISIBILITY).and_then(|extension| extension.get("visible")) else {
        return Ok(true);
    };
    visible.as_bool().ok_or_else(|| {
        format!("nodes[{}].extensions.{NODE_VISIBILITY}.visible is {visible}, not true or false", node.index())
    })
}

/// The nodes of `scene` with their world transforms and visibility, depth-first in document order
/// (a node's subtree before its next sibling): an error if a node is reached twice.
fn scene_nodes<'a>(document: &'a Document, scene: &gltf::Scene<'a>) -> std::result::Result<Vec<SceneNode<'a>>, String> {
    let mut nodes = Vec::new();
    // The stack pops the first pending node first.
    let mut pending: Vec<(gltf::Node, Mat4, bool)> = scene.nodes().map(|n| (n, Mat4::IDENTITY, true)).collect();
    pending.reverse();
    let mut visited = vec![false; document.nodes().len()];
    while let Some((node, parent, parent_visible)) = pending.pop() {
        if std::mem::replace(&mut visited[node.index()], true) {
            return Err(format!(
                "nodes[{}] is reached twice from scenes[{}] (a cycle, or a node with two parents; \
                 glTF node hierarchies must be trees)",
                node.index(),
                scene.index()
            ));
        }
        let world = parent * local_transform(&node)?;
        let visible = parent_visible && own_visibility(&node)?;
        let children: Vec<_> = node.children().map(|child| (child, world, visible)).collect();
        pending.extend(children.into_iter().rev());
        nodes.push(SceneNode { node, world, visible });
    }
    Ok(nodes)
}

/// Largest departure from glTF's requirements on a node's own transform that is taken as
/// rounding: of a `matrix`'s last row from (0, 0, 0, 1), and of a `rotation`'s length from 1.
const TRANSFORM_TOLERANCE: f32 = 1e-3;

/// `node`'s own transform, checked as far as raywave depends on it: a `matrix` affine (its last
/// row 0, 0, 0, 1 within [`TRANSFORM_TOLERANCE`], then set to exactly that: glam's point transform
/// ignores that row, but kept in the product with the parent it would carry the parent's
/// translation into the children's linear parts — a last row of (0.0009, 0, 0, 1) under a parent
/// translated by 1000 made a child's lamp 1.9 times wider) — glTF 2.0 also forbids shear, which
/// is not checked: a sheared matrix is still a well-defined transform of the geometry —, a
/// `rotation` a unit quaternion (otherwise it also scales and shears).
fn local_transform(node: &gltf::Node) -> std::result::Result<Mat4, String> {
    let index = node.index();
    match node.transform() {
        gltf::scene::Transform::Matrix { mut matrix } => {
            let last_row = [matrix[0][3], matrix[1][3], matrix[2][3], matrix[3][3]];
            let departure = last_row.iter().zip([0.0, 0.0, 0.0, 1.0]).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
            if departure > TRANSFORM_TOLERANCE {
                return Err(format!(
                    "nodes[{index}].matrix: its last row is {last_row:?}; glTF requires 0, 0, 0, 1 (a transform \
                     of translation, rotation and scale)"
                ));
            }
            // Columns first: the last row is each column's last element.
            for (column, exact) in matrix.iter_mut().zip([0.0, 0.0, 0.0, 1.0]) {
                column[3] = exact;
            }
            Ok(Mat4::from_cols_array_2d(&matrix))
        }
        transform @ gltf::scene::Transform::Decomposed { rotation, .. } => {
            let length = glam::Vec4::from_array(rotation).length();
            if (length - 1.0).abs() > TRANSFORM_TOLERANCE {
                return Err(format!(
                    "nodes[{index}].rotation: {rotation:?} is {length} long; glTF requires a unit quaternion"
                ));
            }
            Ok(Mat4::from_cols_array_2d(&transform.matrix()))
        }
    }
}

/// Parses and validates a `.gltf` or `.glb` file's bytes and loads its buffers, resolving
/// external URIs against `base` (the file's folder).
fn parse(bytes: &[u8], base: Option<&Path>) -> std::result::Result<(Document, Vec<buffer::Data>), String> {
    check_glb_header(bytes)?;
    let json_text::Readable { bytes, asset_version } = json_text::readable(bytes);
    // Before the crate reads the JSON as glTF 2.0, which fails on some other field of a 1.0 file.
    if let Some(version) = asset_version {
        check_major_version(&version)?;
    }
    let gltf::Gltf { document, blob } = gltf::Gltf::from_slice_without_validation(&bytes).map_err(|e| e.to_string())?;
    check_position_accessor_indices(document.as_json())?;
    let mut json = document.into_json();
    check_asset_version(&json.asset)?;
    check_required_extensions(&json.extensions_required)?;
    // Read here, so a file may require them: the crate's validation refuses any it does not know.
    json.extensions_required.retain(|required| !taken_without_gltf_json(required));
    let document = Document::from_json_without_validation(json);
    validate(&document)?;
    check_camera_projections(document.as_json())?;
    check_node_matrices_alone(document.as_json())?;
    check_meshes_have_primitives(document.as_json())?;
    let buffers = load_buffers(&document, base, bytes.starts_with(b"glTF"), blob)?;
    Ok((document, buffers))
}

/// Validates `document` as `gltf::Document::from_json` does (with its message, the paths
/// written as the file writes them: [`as_written`]), less the errors that glTF 2.0 does not make:
/// a primitive without POSITION, which gltf-json 1.4 reports missing, where the specification
/// allows it (§ 3.7.2.1: "When positions are not specified, client implementations SHOULD skip
/// primitive's rendering", [`draws_surfaces`]); a texture without `source`, which the schema
/// makes optional (an extension may give the image) and raywave reads no image of; and an accessor
/// with neither `bufferView` nor `sparse`, which the schema allows ("When undefined, the accessor
/// MUST be initialized with zeros") and [`PositionElements`] reads as zeros.
fn validate(document: &Document) -> std::result::Result<(), String> {
    use gltf::json::validation::{Error as Invalid, Validate};
    use gltf::json::Path as JsonPath;
    let root = document.as_json();
    let without_positions: Vec<JsonPath> = (root.meshes.iter().enumerate())
        .flat_map(|(m, mesh)| mesh.primitives.iter().enumerate().map(move |(p, primitive)| (m, p, primitive)))
        .filter(|(_, _, primitive)| !primitive.attributes.contains_key(&Checked::Valid(Semantic::Positions)))
        .map(|(m, p, _)| JsonPath::new().field("meshes").index(m).field("primitives").index(p))
        .map(|primitive| primitive.field("attributes").key("POSITION"))
        .collect();
    let without_source: Vec<JsonPath> =
        (0..root.textures.len()).map(|t| JsonPath::new().field("textures").index(t).field("source")).collect();
    let without_view: Vec<JsonPath> =
        (0..root.accessors.len()).map(|a| JsonPath::new().field("accessors").index(a).field("bufferView")).collect();
    let mut errors = String::new();
    root.validate(root, JsonPath::new, &mut |path, error| {
        let path = path();
        let allowed = [&without_positions, &without_source, &without_view].iter().any(|paths| paths.contains(&path));
        if !(matches!(error, Invalid::Missing) && allowed) {
            errors.push_str(&format!(" {}: {error};", as_written(&path.to_string())));
        }
    });
    if errors.is_empty() {
        Ok(())
    } else {
        // As `gltf::Error::Validation` writes it.
        Err(format!("invalid glTF:{errors}"))
    }
}

/// A gltf-json validation path as the file writes it: extension members under their names
/// (`KHR_lights_punctual`), which gltf-json writes as its fields' (`khrLightsPunctual`) — an
/// error had named a field no file holds.
fn as_written(path: &str) -> String {
    let member = |name: &str| -> String {
        let vendor =
            ["khr", "ext"].into_iter().find(|v| name.starts_with(v) && name[3..].starts_with(char::is_uppercase));
        let Some(vendor) = vendor else { return name.to_owned() };
        let mut written = vendor.to_uppercase();
        for c in name[3..].chars() {
            if c.is_uppercase() {
                written.push('_');
            }
            written.push(c.to_ascii_lowercase());
        }
        written
    };
    path.split('.')
        .map(|part| match part.find('[') {
            Some(at) => member(&part[..at]) + &part[at..],
            None => member(part),
        })
        .collect::<Vec<_>>()
        .join(".")
}

/// Checks that a glTF 2.0 reader may read the file: its `asset.version` of major version 2, and
/// its `asset.minVersion` ("the minimum glTF version that this asset targets"), where it has
/// one, no later than 2.0 — a file asking for 2.1 "should fail to load on a 2.0 client"
/// (glTF-Asset-Generator's compatibility model 04). gltf-json reads neither, so a 2.1 file loaded
/// (and a glTF 1.0 file failed on some other field: [`check_major_version`] reads it first).
fn check_asset_version(asset: &gltf::json::Asset) -> std::result::Result<(), String> {
    check_major_version(&asset.version)?;
    match asset.min_version.as_deref().map(|min| (min, major_minor(min))) {
        None => Ok(()),
        Some((_, Some(version))) if version <= (2, 0) => Ok(()),
        Some((min, _)) => {
            Err(format!("asset.minVersion is {min:?}: the file needs a glTF reader of that version; raywave reads 2.0"))
        }
    }
}

/// A glTF version's major and minor numbers (`"2.0"`: (2, 0)); `None` where it is not of that form.
fn major_minor(version: &str) -> Option<(u32, u32)> {
    let (major, minor) = version.split_once('.')?;
    Some((major.parse().ok()?, minor.parse().ok()?))
}

/// Checks that `version`, the file's `asset.version`, is 2.x: the glTF raywave reads.
fn check_major_version(version: &str) -> std::result::Result<(), String> {
    match major_minor(version) {
        Some((2, _)) => Ok(()),
        _ => Err(format!("asset.version is {version:?}: raywave reads glTF 2.x files")),
    }
}

/// The extensions raywave reads itself rather than through gltf-json, whose validation refuses a
/// file that requires one of them.
const EXTENSIONS_READ_HERE: [&str; 5] =
    [instancing::EXTENSION, MESH_QUANTIZATION, meshopt::EXTENSIONS[0], meshopt::EXTENSIONS[1], NODE_VISIBILITY];

/// Extensions that change only how a texture is read — its image's format (KTX2 with Basis
/// Universal, WebP, AVIF, DDS) or its coordinates' transform —, which raywave does not sample: a
/// textured mesh renders with its material's factors, and the render warns of it
/// ([`Unrendered::textured_meshes`]). A file that requires one loads as one whose textures
/// raywave skips (`gltfpack -tc` requires `KHR_texture_basisu`).
const TEXTURE_EXTENSIONS: [&str; 5] =
    ["KHR_texture_basisu", "EXT_texture_webp", "EXT_texture_avif", "MSFT_texture_dds", "KHR_texture_transform"];

/// Whether a file may require `name` though gltf-json does not read it: raywave reads it
/// ([`EXTENSIONS_READ_HERE`]), or it changes only textures ([`TEXTURE_EXTENSIONS`]).
fn taken_without_gltf_json(name: &str) -> bool {
    EXTENSIONS_READ_HERE.iter().chain(&TEXTURE_EXTENSIONS).any(|taken| *taken == name)
}

/// Checks that the file requires (`extensionsRequired`) no extension but those raywave reads —
/// the ones gltf-json is built to read (`KHR_lights_punctual`, `KHR_materials_emissive_strength`)
/// and [`EXTENSIONS_READ_HERE`] — and those that change only the textures it does not sample
/// ([`TEXTURE_EXTENSIONS`]). A file that requires another "should fail to load"
/// (glTF-Asset-Generator's compatibility model 05), but it is valid glTF, which gltf-json's
/// validation had called it not ("invalid glTF: … Unsupported extension").
fn check_required_extensions(required: &[String]) -> std::result::Result<(), String> {
    use gltf::json::extensions::ENABLED_EXTENSIONS;
    let read: Vec<&str> = ENABLED_EXTENSIONS.iter().copied().chain(EXTENSIONS_READ_HERE).collect();
    let unread: Vec<String> = (required.iter().enumerate())
        .filter(|(_, name)| !(ENABLED_EXTENSIONS.contains(&name.as_str()) || taken_without_gltf_json(name)))
        .map(|(index, name)| format!("{name:?} (extensionsRequired[{index}])"))
        .collect();
    if unread.is_empty() {
        return Ok(());
    }
    Err(format!(
        "the file requires {}, which raywave does not read (it reads {}, and takes those that change only the \
         textures it does not sample: {})",
        unread.join(", "),
        read.join(", "),
        TEXTURE_EXTENSIONS.join(", ")
    ))
}

/// Checks a GLB header: its version (bytes 4–7) must be 2 — glTF 1.0's binary GLB (version 1,
/// another layout) failed on its chunk lengths, or on its total length, without a word about its
/// version —, and its total length (bytes 8–11) the file's size, as glTF 2.0 requires (§ 4.4.2:
/// "the total length of the Binary glTF, including header and all chunks"): gltf 1.4.1's
/// `Glb::from_slice` subtracts 12 from it unchecked, which panics with overflow checks on (debug
/// and test builds) and wraps without them; it refuses a length past the end without saying which,
/// and reads the chunks to the end of the file whatever a shorter length says. Each chunk's length
/// must also fit in the file (§ 4.4.3), where the crate's refusal ("BIN\0 chunk length exceeds that
/// of slice") named neither the chunk nor its length. Text glTF (no `glTF` magic) passes untouched.
fn check_glb_header(bytes: &[u8]) -> std::result::Result<(), String> {
    let [b'g', b'l', b'T', b'F', v0, v1, v2, v3, l0, l1, l2, l3, ..] = *bytes else { return Ok(()) };
    let version = u32::from_le_bytes([v0, v1, v2, v3]);
    if version != 2 {
        return Err(format!(
            "GLB header: version {version}: raywave reads glTF 2.0's GLB, version 2 (version 1 is glTF 1.0's)"
        ));
    }
    let length = u32::from_le_bytes([l0, l1, l2, l3]);
    if u64::from(length) != bytes.len() as u64 {
        return Err(format!(
            "GLB header: length {length} is not the file's size, {} bytes; glTF 2.0 requires them equal",
            bytes.len()
        ));
    }
    // Each chunk: its data's length, its type, its data. Fewer than 8 bytes left are the crate's.
    let (mut offset, mut chunk) = (12, 0);
    while let Some(&[l0, l1, l2, l3, t0, t1, t2, t3]) = bytes.get(offset..offset + 8) {
        let length = u32::from_le_bytes([l0, l1, l2, l3]) as usize;
        let left = bytes.len() - (offset + 8);
        if length > left {
            let kind = String::from_utf8_lossy(&[t0, t1, t2, t3]).trim_end_matches('\0').escape_debug().to_string();
            return Err(format!(
                "GLB chunk {chunk} ({kind}): length {length} runs past the file's end, {left} bytes after its header"
            ));
        }
        (offset, chunk) = (offset + 8 + length, chunk + 1);
    }
    Ok(())
}

/// The data of every buffer an accessor reads ([`buffers_read_by_accessors`]; the others are
/// left empty), as `gltf::import_buffers` loads it but with errors that name the buffer and its
/// source, with the compressed views accessors read decoded into their places
/// ([`meshopt::decode_views`]); `glb` tells whether the file is a GLB, `blob` is its BIN chunk.
fn load_buffers(
    document: &Document,
    base: Option<&Path>,
    glb: bool,
    mut blob: Option<Vec<u8>>,
) -> std::result::Result<Vec<buffer::Data>, String> {
    let (read, compressed_views) = buffers_read_by_accessors(document)?;
    let load = |buffer: buffer::Buffer| {
        if !read[buffer.index()] {
            return Ok(buffer::Data(Vec::new()));
        }
        let bin_chunk = glb && buffer.index() == 0;
        let source = match buffer.source() {
            buffer::Source::Uri(uri) if uri.starts_with("data:") => "embedded data URI".to_owned(),
            buffer::Source::Uri(uri) => format!("{uri:?}"),
            buffer::Source::Bin if bin_chunk => "the GLB BIN chunk".to_owned(),
            buffer::Source::Bin => "no `uri`".to_owned(),
        };
        let field = format!("buffers[{}] ({source})", buffer.index());
        let data = match buffer.source() {
            buffer::Source::Uri(uri) if !uri.starts_with("data:") => {
                external_buffer(uri, base, buffer.length()).map(padded)
            }
            // The crate takes the BIN chunk for the first buffer without `uri`, whichever it is.
            buffer::Source::Bin if !bin_chunk => {
                Err("only a GLB's first buffer may omit `uri` (its data is then the BIN chunk)".to_owned())
            }
            // The crate decodes all after `data:` as base64 and fails inside the media type.
            buffer::Source::Uri(uri) if !uri.contains(";base64,") => percent_encoded_data(uri).map(padded),
            source => buffer::Data::from_source_and_blob(source, base, &mut blob).map_err(|e| e.to_string()),
        }
        .map_err(|e| format!("{field}: {e}"))?;
        // `Data` is padded to a multiple of 4 bytes, as `gltf::import_buffers` checks it.
        if data.len() < buffer.length() {
            return Err(format!("{field}: byteLength is {} but the data has {} bytes", buffer.length(), data.len()));
        }
        Ok(data)
    };
    let mut buffers = document.buffers().map(load).collect::<std::result::Result<Vec<_>, _>>()?;
    let declared_lengths: Vec<usize> = document.buffers().map(|buffer| buffer.length()).collect();
    meshopt::decode_views(&compressed_views, &mut buffers, &declared_lengths)?;
    Ok(buffers)
}

/// Which buffers (by index) hold data an accessor reads, through its `bufferView` or its sparse
/// views, and the views among those that are compressed ([`meshopt`], by view index), whose
/// compressed data's buffer is read instead of their own: raywave reads buffers through
/// accessors only, so a buffer that holds only images, or a placeholder without `uri`
/// (glTF-Validator's `buffer/valid_placeholder.glb` holds one, and so do compressed files), is not
/// loaded, and when missing refuses no file.
fn buffers_read_by_accessors(
    document: &Document,
) -> std::result::Result<(Vec<bool>, BTreeMap<usize, meshopt::CompressedView>), String> {
    let mut read = vec![false; document.buffers().len()];
    let mut compressed = BTreeMap::new();
    for accessor in document.accessors() {
        let sparse_views = accessor.sparse().map(|sparse| [sparse.indices().view(), sparse.values().view()]);
        for view in accessor.view().into_iter().chain(sparse_views.into_iter().flatten()) {
            let buffer = match meshopt::CompressedView::of(&view)? {
                Some(view_data) => compressed.entry(view.index()).or_insert(view_data).source_buffer(),
                None => view.buffer().index(),
            };
            let Some(read) = read.get_mut(buffer) else {
                return Err(format!(
                    "bufferViews[{}]: its compressed data's buffer {buffer} does not exist",
                    view.index()
                ));
            };
            *read = true;
        }
    }
    Ok((read, compressed))
}

/// The bytes of a data URI without `;base64`: RFC 2397 (`data:[<mediatype>][;base64],<data>`)
/// writes them after the first comma, percent-encoded, as glTF-Validator's
/// `buffer/data_uri.glb` does (`data:application/gltf-buffer,0`).
fn percent_encoded_data(uri: &str) -> std::result::Result<Vec<u8>, String> {
    let (_, data) = uri.split_once(',').ok_or("the data URI has no `,` before its data (RFC 2397)")?;
    Ok(urlencoding::decode_binary(data.as_bytes()).into_owned())
}

/// A buffer's `data` zero-padded to a multiple of 4 bytes, as the `gltf` crate pads the buffers
/// it loads itself.
fn padded(mut data: Vec<u8>) -> buffer::Data {
    data.resize(data.len().next_multiple_of(4), 0);
    buffer::Data(data)
}

/// The first `length` bytes (its `byteLength`) of the external buffer file `uri` names. The URI
/// resolves as the `gltf` crate resolves it — `file:` and `file://` take the path as written, a URI
/// without a scheme is percent-decoded and joined to `base`, other schemes are unsupported — but
/// the crate itself panics on a URI whose percent-decoded bytes are not UTF-8 (gltf 1.4.1 unwraps
/// the decoding) and reads the whole file whatever the buffer's length, so `/dev/zero` filled
/// memory and a FIFO blocked. Here the path must be a regular file and only `length` bytes are
/// read.
fn external_buffer(uri: &str, base: Option<&Path>, length: usize) -> std::result::Result<Vec<u8>, String> {
    let path = if let Some(path) = uri.strip_prefix("file://").or_else(|| uri.strip_prefix("file:")) {
        PathBuf::from(path)
    } else if uri.contains(':') {
        return Err("unsupported URI scheme (a buffer is a relative path, a file: URI or a data: URI)".into());
    } else {
        let decoded = urlencoding::decode(uri).map_err(|_| "the percent-decoded URI is not UTF-8 text".to_owned())?;
        base.ok_or("a relative URI needs the scene file's folder")?.join(&*decoded)
    };
    read_regular_file(&path, length as u64).map_err(|e| match e {
        ReadError::NotRegular => format!("{} is not a regular file", path.display()),
        ReadError::Io(e) => format!("{}: {e}", path.display()),
    })
}

/// Checks that every primitive's POSITION attribute names an existing accessor, before the `gltf`
/// crate validates the file: gltf-json 1.4's validation indexes the accessor array with it
/// unchecked (`mesh::primitive_validate_hook`) and panics on a bad index.
fn check_position_accessor_indices(root: &gltf::json::Root) -> std::result::Result<(), String> {
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            if let Some(index) = primitive.attributes.get(&Checked::Valid(Semantic::Positions)) {
                if index.value() >= root.accessors.len() {
                    return Err(format!(
                        "meshes[{m}].primitives[{p}].attributes.POSITION: accessor {} does not exist \
                         (the file has {})",
                        index.value(),
                        root.accessors.len()
                    ));
                }
            }
        }
    }
    Ok(())
}

/// Checks that each camera defines the projection its `type` names and not the other, as glTF 2.0
/// requires: gltf 1.4.1's validation asks only for one of the two, and its
/// `Camera::projection` unwraps the one `type` names (a panic on `"type":"perspective"` with only
/// an `orthographic` object).
fn check_camera_projections(root: &gltf::json::Root) -> std::result::Result<(), String> {
    use gltf::json::camera::Type;
    for (index, camera) in root.cameras.iter().enumerate() {
        let (named, other, defines_named, defines_other) = match camera.type_ {
            Checked::Valid(Type::Perspective) => {
                ("perspective", "orthographic", camera.perspective.is_some(), camera.orthographic.is_some())
            }
            Checked::Valid(Type::Orthographic) => {
                ("orthographic", "perspective", camera.orthographic.is_some(), camera.perspective.is_some())
            }
            // Refused by `Document::from_json` already.
            Checked::Invalid => return Err(format!("cameras[{index}].type: not a camera type")),
        };
        if !defines_named {
            return Err(format!("cameras[{index}].{named}: missing (the camera's type is {named})"));
        }
        if defines_other {
            return Err(format!("cameras[{index}].{other}: defined, but the camera's type is {named}"));
        }
    }
    Ok(())
}

/// Checks that no node has a `matrix` beside a `translation`, `rotation` or `scale` that says
/// otherwise: glTF 2.0 allows one or the other, and the `gltf` crate takes the matrix and drops
/// the rest without a word (a node's translation had vanished). Both load where they agree —
/// each entry within [`TRANSFORM_TOLERANCE`] of the larger of 1 and the matrix's largest — as an
/// exporter that writes both means them.
fn check_node_matrices_alone(root: &gltf::json::Root) -> std::result::Result<(), String> {
    for (index, node) in root.nodes.iter().enumerate() {
        let Some(matrix) = node.matrix else { continue };
        if node.translation.is_none() && node.rotation.is_none() && node.scale.is_none() {
            continue;
        }
        let decomposed = Mat4::from_scale_rotation_translation(
            Vec3::from(node.scale.unwrap_or([1.0; 3])),
            glam::Quat::from_array(node.rotation.map_or([0.0, 0.0, 0.0, 1.0], |rotation| rotation.0)),
            Vec3::from(node.translation.unwrap_or([0.0; 3])),
        );
        let largest = matrix.iter().fold(1.0f32, |largest, entry| largest.max(entry.abs()));
        // The largest difference, NaN where any is (a composition that overflowed): `f32::max`
        // would pass over it.
        let differences = (Mat4::from_cols_array(&matrix) - decomposed).to_cols_array();
        let departure = differences.iter().fold(0.0f32, |d, e| if e.is_nan() || e.abs() > d { e.abs() } else { d });
        if departure.is_nan() || departure > TRANSFORM_TOLERANCE * largest {
            return Err(format!(
                "nodes[{index}]: has both a matrix and a translation, rotation or scale, which differ (by up to \
                 {departure}); glTF allows one or the other"
            ));
        }
    }
    Ok(())
}

/// Checks that every mesh has a primitive, as glTF 2.0 requires (`mesh.primitives`: at least one
/// item): the `gltf` crate takes an empty array, and such a mesh added nothing without a word.
fn check_meshes_have_primitives(root: &gltf::json::Root) -> std::result::Result<(), String> {
    match root.meshes.iter().position(|mesh| mesh.primitives.is_empty()) {
        Some(index) => Err(format!("meshes[{index}].primitives: empty; glTF 2.0 requires at least one primitive")),
        None => Ok(()),
    }
}

/// What a primitive reads an accessor as, which sets what glTF 2.0 allows it ([`check_accessor`]).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
enum AccessorUse {
    /// A POSITION attribute: VEC3 of `f32`.
    Position,
    /// A POSITION attribute in a file that uses [`MESH_QUANTIZATION`]: VEC3 of `f32` or of any 8-
    /// or 16-bit integer type, normalized or not (the extension's table).
    QuantizedPosition,
    /// Vertex indices: SCALAR unsigned integers, tightly packed — glTF 2.0 gives a `byteStride`
    /// to vertex attributes alone.
    Indices,
    /// An `EXT_mesh_gpu_instancing` TRANSLATION: VEC3 of `f32`.
    InstanceTranslation,
    /// An `EXT_mesh_gpu_instancing` ROTATION: VEC4 of `f32`, normalized `i8` or normalized `i16`.
    InstanceRotation,
    /// An `EXT_mesh_gpu_instancing` SCALE: VEC3 of `f32`.
    InstanceScale,
}

impl AccessorUse {
    /// What POSITION attributes are read as in `document`: [`Self::QuantizedPosition`] where it
    /// lists [`MESH_QUANTIZATION`] in `extensionsUsed`.
    fn position_in(document: &Document) -> Self {
        if document.extensions_used().any(|used| used == MESH_QUANTIZATION) {
            Self::QuantizedPosition
        } else {
            Self::Position
        }
    }

    /// The element type glTF 2.0 (or the extension) requires: its dimensions and the component
    /// types it allows, each with whether it is `normalized`.
    fn element(self) -> (Dimensions, &'static [(DataType, bool)]) {
        const F32: (DataType, bool) = (DataType::F32, false);
        match self {
            Self::Position | Self::InstanceTranslation | Self::InstanceScale => (Dimensions::Vec3, &[F32]),
            Self::QuantizedPosition => (Dimensions::Vec3, &QUANTIZED_POSITION_COMPONENTS),
            Self::Indices => {
                (Dimensions::Scalar, &[(DataType::U8, false), (DataType::U16, false), (DataType::U32, false)])
            }
            Self::InstanceRotation => (Dimensions::Vec4, &[F32, (DataType::I8, true), (DataType::I16, true)]),
        }
    }
}

/// The extension that lets POSITION (and other attributes, which raywave does not read) hold
/// 8- and 16-bit integers (KhronosGroup/glTF, `extensions/2.0/Khronos/KHR_mesh_quantization`), as
/// `gltfpack` writes them, with the dequantizing scale and offset in the node's transform. Files
/// must require it (the extension: "the extension is not optional").
const MESH_QUANTIZATION: &str = "KHR_mesh_quantization";

/// The component types [`MESH_QUANTIZATION`] allows POSITION: `f32`, and every 8- and 16-bit
/// integer type, normalized or not.
const QUANTIZED_POSITION_COMPONENTS: [(DataType, bool); 9] = [
    (DataType::F32, false),
    (DataType::I8, false),
    (DataType::I8, true),
    (DataType::U8, false),
    (DataType::U8, true),
    (DataType::I16, false),
    (DataType::I16, true),
    (DataType::U16, false),
    (DataType::U16, true),
];

/// A component type as an error names it: `F32`, `normalized I16`.
fn component_name((data_type, normalized): (DataType, bool)) -> String {
    format!("{}{data_type:?}", if normalized { "normalized " } else { "" })
}

/// Accessors already checked ([`check_accessor`]) for each use: each is checked once however
/// many primitives share it (its sparse indices are read in full).
type CheckedAccessors = std::collections::HashSet<(usize, AccessorUse)>;

/// The vertices (at most its POSITION count and its corners) and triangles that `mesh`'s surface
/// primitives ([`draws_surfaces`]) add to the scene each time a node instances it, their POSITION
/// (read as `position_use`: [`AccessorUse::position_in`]) and indices accessors checked first
/// ([`check_accessor`]: their counts are the file's) unless `checked` holds them.
fn mesh_size(
    mesh: &gltf::Mesh,
    buffers: &[buffer::Data],
    position_use: AccessorUse,
    checked: &mut CheckedAccessors,
) -> std::result::Result<(u64, u64), String> {
    let (mut vertices, mut triangles) = (0u64, 0u64);
    for (index, primitive) in mesh.primitives().enumerate() {
        let Some(position) = primitive.get(&Semantic::Positions).filter(|_| draws_surfaces(&primitive)) else {
            continue;
        };
        let field = primitive_field(mesh, index);
        if holds_zeros(&position) && primitive.extension_value(DRACO).is_some() {
            return Err(format!(
                "{field}: compressed with {DRACO}, which raywave does not read, and without uncompressed data \
                 (attributes.POSITION has no bufferView)"
            ));
        }
        if checked.insert((position.index(), position_use)) {
            let position_field = format!("{field}.attributes.POSITION");
            check_accessor(&position, buffers, &position_field, position_use)?;
        }
        let corners = match primitive.indices() {
            Some(indices) => {
                if checked.insert((indices.index(), AccessorUse::Indices)) {
                    check_accessor(&indices, buffers, &format!("{field}.indices"), AccessorUse::Indices)?;
                }
                indices.count()
            }
            None => position.count(),
        };
        // A primitive keeps the vertices its indices use ([`PrimitiveGeometry::read`]).
        vertices += position.count().min(corners) as u64;
        triangles += surface_triangles(primitive.mode(), corners as u64);
    }
    Ok((vertices, triangles))
}

/// The extension that compresses a primitive's geometry (Draco). A file may use it without
/// requiring it only if it keeps the uncompressed accessors as well, which raywave reads (the
/// extension's specification: "If the uncompressed version of the asset is not provided, then
/// KHR_draco_mesh_compression must be added to extensionsRequired"); one that requires it is
/// refused for that ([`check_required_extensions`]).
const DRACO: &str = "KHR_draco_mesh_compression";

/// One surface primitive ([`surface_triangles`]) as its accessors hold it, read once however many
/// nodes instance its mesh: the POSITION elements its indices use, renumbered in order of first
/// use (primitives may share one large POSITION accessor, each drawing a range of it), and its
/// triangles over them.
struct PrimitiveGeometry {
    /// The POSITION element of each vertex, which errors name.
    elements: Vec<u32>,
    /// Each vertex in the mesh's space.
    positions: Vec<Vec3>,
    /// Triangles over `positions`, counter-clockwise seen from the front in the mesh's space.
    triangles: Vec<[u32; 3]>,
}

impl PrimitiveGeometry {
    /// Reads `primitive`, whose JSON path `field` the errors name, its accessors checked by
    /// [`mesh_size`] (POSITION a VEC3 accessor of `f32`, or of integers under
    /// [`MESH_QUANTIZATION`], and indices, if any, a SCALAR unsigned integer one, as glTF 2.0
    /// requires — the `gltf` crate's reader would panic on float indices and read other types as
    /// garbage —, each inside its buffer); every index must be below the POSITION count (which
    /// [`Scene::new`] would report without the JSON path).
    fn read(primitive: &gltf::Primitive, buffers: &[buffer::Data], field: &str) -> std::result::Result<Self, String> {
        #[cfg(test)]
        tests::PRIMITIVE_READS.with(|reads| reads.set(reads.get() + 1));
        let reader = primitive.reader(|buffer| buffers.get(buffer.index()).map(|data| &data.0[..]));
        let position = primitive.get(&Semantic::Positions).ok_or_else(|| format!("{field}: no POSITION attribute"))?;
        let position_field = format!("{field}.attributes.POSITION");
        let unreadable_position = || unreadable(&position, &position_field);
        let accessor_positions = PositionElements::new(&position, buffers).ok_or_else(unreadable_position)?;
        let mut indices: Vec<u32> = match primitive.indices() {
            // Every triangle degenerate, dropped (the crate's reader returns nothing).
            Some(accessor) if holds_zeros(&accessor) => vec![0; accessor.count()],
            Some(accessor) => {
                let indices_field = format!("{field}.indices");
                reader.read_indices().ok_or_else(|| unreadable(&accessor, &indices_field))?.into_u32().collect()
            }
            None => (0..position.count() as u32).collect(),
        };
        if let Some((element, index)) = indices.iter().enumerate().find(|(_, &i)| i as usize >= position.count()) {
            return Err(format!(
                "{field}.indices element {element} is {index}, but attributes.POSITION has {} elements",
                position.count()
            ));
        }
        let mut renumbering = Renumbering::new(position.count(), indices.len());
        let (mut elements, mut positions) = (Vec::new(), Vec::new());
        for index in &mut indices {
            let (vertex, first_use) = renumbering.vertex(*index, positions.len() as u32);
            if first_use {
                elements.push(*index);
                positions.push(accessor_positions.get(*index as usize).ok_or_else(unreadable_position)?);
            }
            *index = vertex;
        }
        let triangles: Vec<[u32; 3]> = match primitive.mode() {
            Mode::TriangleStrip => strip_triangles(&indices),
            Mode::TriangleFan => fan_triangles(&indices),
            _ if !indices.len().is_multiple_of(3) => {
                return Err(format!("{field}: {} indices is not a whole number of triangles", indices.len()));
            }
            _ => indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
        };
        Ok(Self { elements, positions, triangles })
    }

    /// The positions (moved to world space by `placement`) and triangles (counter-clockwise in
    /// world space seen from the front, reversed where the placement mirrors) of this primitive
    /// (JSON path `field`) as placed there, in new vectors ([`place`]).
    fn instance(&self, field: &str, placement: &Placement) -> std::result::Result<(Vec<Vec3>, Vec<[u32; 3]>), String> {
        let (mut positions, mut triangles) = (self.positions.clone(), self.triangles.clone());
        place(&mut positions, &mut triangles, &self.elements, field, placement)?;
        Ok((positions, triangles))
    }

    /// [`Self::instance`] made in this primitive's own vectors, for its last instance.
    fn into_instance(
        mut self,
        field: &str,
        placement: &Placement,
    ) -> std::result::Result<(Vec<Vec3>, Vec<[u32; 3]>), String> {
        place(&mut self.positions, &mut self.triangles, &self.elements, field, placement)?;
        Ok((self.positions, self.triangles))
    }
}

/// The vertex numbers of a primitive's POSITION elements, given in order of first use: in an
/// array as long as the accessor where its indices are about as many (a lookup per index), in a
/// map where the accessor is far larger than what they draw (primitives may share one).
enum Renumbering {
    /// Each element's vertex, or `u32::MAX` before its first use.
    Dense(Vec<u32>),
    /// The vertices of the elements used so far.
    Sparse(HashMap<u32, u32>),
}

impl Renumbering {
    /// For `indices` indices into an accessor of `count` elements.
    fn new(count: usize, indices: usize) -> Self {
        if count <= 4 * indices {
            Self::Dense(vec![u32::MAX; count])
        } else {
            Self::Sparse(HashMap::new())
        }
    }

    /// The vertex of `element` (below the count), and whether this is its first use, which gives
    /// it the vertex `next`.
    fn vertex(&mut self, element: u32, next: u32) -> (u32, bool) {
        let slot = match self {
            Self::Dense(vertices) => &mut vertices[element as usize],
            Self::Sparse(vertices) => vertices.entry(element).or_insert(u32::MAX),
        };
        if *slot == u32::MAX {
            *slot = next;
            (next, true)
        } else {
            (*slot, false)
        }
    }
}

/// Random access to the elements of a POSITION accessor (VEC3 of `f32`, or of the integer types
/// [`MESH_QUANTIZATION`] allows, its type and spans checked by [`check_accessor`]): reading a
/// primitive costs what its indices use, not the accessor's count, which the `gltf` crate's reader
/// decodes whole — per primitive, so primitives sharing one large (or sparse, bufferless) accessor
/// made a small file take hours.
struct PositionElements<'a> {
    /// How each component is stored.
    format: ComponentFormat,
    /// The base elements' bytes from the first one on, and their stride; `None`: zeros (a sparse
    /// accessor without a buffer view).
    base: Option<(&'a [u8], usize)>,
    /// The sparse substitutions' element indices, strictly increasing ([`check_sparse_indices`]),
    /// and their values, packed; `None` for an accessor that is not sparse.
    sparse: Option<(SparseIndices<'a>, &'a [u8])>,
}

impl<'a> PositionElements<'a> {
    /// The accessor's elements, or `None` if its data lies outside `buffers`.
    fn new(accessor: &gltf::Accessor, buffers: &'a [buffer::Data]) -> Option<Self> {
        let format = ComponentFormat::of(accessor);
        let bytes_from = |view: buffer::View, offset: usize| {
            buffers.get(view.buffer().index())?.0.get(view.offset().checked_add(offset)?..)
        };
        let base = match accessor.view() {
            Some(view) => {
                Some((bytes_from(view.clone(), accessor.offset())?, view.stride().unwrap_or(3 * format.size())))
            }
            None => None,
        };
        let sparse = match accessor.sparse() {
            Some(sparse) => {
                let values = sparse.values();
                let indices = SparseIndices::new(&sparse.indices(), sparse.count(), buffers).ok()?;
                Some((indices, bytes_from(values.view(), values.offset())?))
            }
            None => None,
        };
        Some(Self { format, base, sparse })
    }

    /// Element `index` (below the accessor's count), or `None` if its bytes lie outside the data.
    fn get(&self, index: usize) -> Option<Vec3> {
        let size = self.format.size();
        let element = |bytes: &[u8], at: usize| {
            let component = |k: usize| self.format.value(bytes.get(at.checked_add(k * size)?..)?);
            Some(Vec3::new(component(0)?, component(1)?, component(2)?))
        };
        let substitution = self.sparse.and_then(|(indices, values)| Some((indices.position(index)?, values)));
        match (substitution, self.base) {
            (Some((k, values)), _) => element(values, k.checked_mul(3 * size)?),
            (None, Some((bytes, stride))) => element(bytes, index.checked_mul(stride)?),
            (None, None) => Some(Vec3::ZERO),
        }
    }
}

/// Moves `positions` (each POSITION element `elements` names, of the primitive at JSON path
/// `field`) to world space by `placement`, and reverses `triangles` where it mirrors; an error if
/// a world position is not finite and within [`MAX_COORDINATE`].
fn place(
    positions: &mut [Vec3],
    triangles: &mut [[u32; 3]],
    elements: &[u32],
    field: &str,
    placement: &Placement,
) -> std::result::Result<(), String> {
    // In `f64`, rounded once: in `f32` each world coordinate carried the rounding of the
    // transform's terms, which may be far larger than the result (a lamp modelled 10³ from its
    // node's origin and moved back near the world's was bent past the quad-light tolerance).
    let world_f64 = placement.world.as_dmat4();
    for (position, element) in positions.iter_mut().zip(elements) {
        let p = world_f64.transform_point3(position.as_dvec3()).as_vec3();
        if !in_range(p) {
            return Err(format!(
                "{field}.attributes.POSITION element {element} is at {p} in world space under {}'s transform; each \
                 coordinate must be finite and within ±{MAX_COORDINATE:e}",
                placement.source()
            ));
        }
        *position = p;
    }
    // A mirroring transform makes the clockwise face the front one (glTF 2.0, 3.7.4): reversing
    // each triangle keeps the counter-clockwise front face every mesh has here, which decides the
    // side a quad light emits from.
    if mirrors(DMat3::from_mat4(world_f64)) {
        triangles.iter_mut().for_each(|triangle| triangle.swap(1, 2));
    }
    Ok(())
}

/// Whether a world transform whose linear part is `linear` mirrors (its determinant is negative).
/// The sign is taken in `f64`: in `f32` a tiny scale's determinant underflows to −0 (10⁻⁴⁸ for a
/// scale of 10⁻¹⁶), and a huge one may be ∞ − ∞.
fn mirrors(linear: DMat3) -> bool {
    linear.determinant() < 0.0
}

/// How many triangles a primitive of `mode` with `corners` vertices (or indices) draws: the
/// surface modes (glTF 2.0, 3.7.2.1) — `corners/3` separate triangles, `corners − 2` for a strip
/// or a fan — and none for points and lines, which have no area and are skipped, as an OBJ's
/// polylines are.
fn surface_triangles(mode: Mode, corners: u64) -> u64 {
    match mode {
        Mode::Triangles => corners / 3,
        Mode::TriangleStrip | Mode::TriangleFan => corners.saturating_sub(2),
        Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip => 0,
    }
}

/// Whether `primitive` draws triangles: one of [`surface_triangles`]' surface modes, with
/// positions (glTF 2.0 § 3.7.2.1 has a primitive without POSITION skipped).
fn draws_surfaces(primitive: &gltf::Primitive) -> bool {
    primitive.get(&Semantic::Positions).is_some() && surface_triangles(primitive.mode(), 3) > 0
}

/// The triangles of a strip (glTF 2.0, 3.7.2.1): triangle `i` is `(pᵢ, pᵢ₊₁₊ᵢ﹪₂, pᵢ₊₂₋ᵢ﹪₂)`, every
/// other one reversed so that all keep the strip's winding. Degenerate ones (a repeated index, as
/// strips joined by restarts have) are dropped with the other zero-area triangles by `Scene::new`.
fn strip_triangles(indices: &[u32]) -> Vec<[u32; 3]> {
    indices
        .windows(3)
        .enumerate()
        .map(|(i, w)| if i % 2 == 0 { [w[0], w[1], w[2]] } else { [w[0], w[2], w[1]] })
        .collect()
}

/// The triangles of a fan (glTF 2.0, 3.7.2.1): triangle `i` is `(pᵢ₊₁, pᵢ₊₂, p₀)`.
fn fan_triangles(indices: &[u32]) -> Vec<[u32; 3]> {
    indices.windows(2).skip(1).map(|w| [w[0], w[1], indices[0]]).collect()
}

/// Checks what the `gltf` crate's reader trusts of an accessor read at `field` as `use_`, and what
/// glTF 2.0 forbids there that the crate takes: its element type (one glTF allows there, and
/// `normalized` only where that allows it — the reader ignores the flag, and glTF forbids it for
/// float and 32-bit components), no `byteStride` on an indices view, `count ≥ 1` (glTF's minimum)
/// and at most one element per byte of the buffers loaded (those accessors read:
/// [`buffers_read_by_accessors`]) and below 2³² (32-bit indices; an accessor without a buffer
/// view would otherwise allocate `count` zeros, however large), `1 ≤
/// sparse.count ≤ count`, and that its elements, and its sparse indices and values, lie inside
/// their buffer views and buffers ([`check_span`]).
fn check_accessor(
    accessor: &gltf::Accessor,
    buffers: &[buffer::Data],
    field: &str,
    use_: AccessorUse,
) -> std::result::Result<(), String> {
    let error = |what: String| Err(format!("{field}: accessor {}: {what}", accessor.index()));
    let count = accessor.count();
    let (dimensions, components) = use_.element();
    let found = (accessor.data_type(), accessor.normalized());
    if accessor.dimensions() != dimensions || !components.contains(&found) {
        let allowed: Vec<String> = components.iter().copied().map(component_name).collect();
        // An integer VEC3 POSITION that the extension would allow.
        let quantized = use_ == AccessorUse::Position
            && accessor.dimensions() == dimensions
            && found.0 != DataType::F32
            && QUANTIZED_POSITION_COMPONENTS.contains(&found);
        return error(format!(
            "holds {:?} of {}, glTF requires {dimensions:?} of {}{}",
            accessor.dimensions(),
            component_name(found),
            allowed.join(" or "),
            if quantized {
                format!(
                    " ({MESH_QUANTIZATION} allows {}, but the file does not list it in extensionsUsed)",
                    component_name(found)
                )
            } else {
                String::new()
            }
        ));
    }
    if let (AccessorUse::Indices, Some(view)) = (use_, accessor.view()) {
        if let Err(what) = check_packed(&view, "indices") {
            return error(what);
        }
    }
    let limit = buffers.iter().map(|data| data.len()).sum::<usize>().min(u32::MAX as usize);
    if !(1..=limit).contains(&count) {
        return error(format!(
            "count {count} is outside 1..={limit} (an element per byte of the buffers read, at most 2³²−1)"
        ));
    }
    let component = accessor.data_type().size();
    if let Err(what) = check_alignment(accessor.view(), accessor.offset(), component) {
        return error(what);
    }
    let size = accessor.size();
    if let Err(what) = check_span(accessor.view(), accessor.offset(), count, size, buffers) {
        return error(what);
    }
    if let Some(sparse) = accessor.sparse() {
        let (indices, values) = (sparse.indices(), sparse.values());
        if !(1..=count).contains(&sparse.count()) {
            return error(format!("sparse.count {} is outside 1..={count}", sparse.count()));
        }
        // The reader steps through a strided view, this check and glTF 2.0 (which forbids the
        // stride there) do not: with one, the check passed indices the reader never read.
        for (part, view) in [("sparse.indices", indices.view()), ("sparse.values", values.view())] {
            if let Err(what) = check_packed(&view, "sparse data") {
                return error(format!("{part}: {what}"));
            }
        }
        let index_size = indices.index_type().size();
        for (part, view, offset, component) in [
            ("sparse.indices", indices.view(), indices.offset(), index_size),
            ("sparse.values", values.view(), values.offset(), component),
        ] {
            if let Err(what) = check_alignment(Some(view), offset, component) {
                return error(format!("{part}: {what}"));
            }
        }
        if let Err(what) = check_span(Some(indices.view()), indices.offset(), sparse.count(), index_size, buffers) {
            return error(format!("sparse.indices: {what}"));
        }
        if let Err(what) = check_span(Some(values.view()), values.offset(), sparse.count(), size, buffers) {
            return error(format!("sparse.values: {what}"));
        }
        if let Err(what) = check_sparse_indices(&indices, sparse.count(), count, buffers) {
            return error(format!("sparse.indices: {what}"));
        }
    }
    Ok(())
}

/// Checks that the `sparse_count` indices of a sparse accessor of `count` elements (tightly packed
/// from their view, as glTF 2.0 stores them, and inside it: [`check_span`] first) increase strictly
/// and stay below `count`, as glTF 2.0 requires: the `gltf` crate's reader skips an index past the
/// end without a word, leaving that element at its base value.
fn check_sparse_indices(
    indices: &gltf::accessor::sparse::Indices,
    sparse_count: usize,
    count: usize,
    buffers: &[buffer::Data],
) -> std::result::Result<(), String> {
    let mut previous: Option<usize> = None;
    let indices = SparseIndices::new(indices, sparse_count, buffers)?;
    for (k, value) in (0..indices.len()).map(|k| (k, indices.get(k))) {
        if value >= count || previous.is_some_and(|p| value <= p) {
            return Err(format!(
                "index {k} is {value}; sparse indices must increase strictly and stay below the count {count}"
            ));
        }
        previous = Some(value);
    }
    Ok(())
}

/// The indices of a sparse accessor, read in place from their bytes (tightly packed from their
/// view, as glTF 2.0 stores them): however many there are, nothing is copied.
#[derive(Clone, Copy)]
struct SparseIndices<'a> {
    /// The indices' bytes, `size` each, little-endian.
    bytes: &'a [u8],
    /// Bytes per index (1, 2 or 4).
    size: usize,
}

impl<'a> SparseIndices<'a> {
    /// The `sparse_count` indices of `indices`, or an error if they lie outside their buffer.
    fn new(
        indices: &gltf::accessor::sparse::Indices,
        sparse_count: usize,
        buffers: &'a [buffer::Data],
    ) -> std::result::Result<Self, &'static str> {
        let view = indices.view();
        let size = indices.index_type().size();
        let start = view.offset().checked_add(indices.offset());
        let end = sparse_count.checked_mul(size).and_then(|length| start?.checked_add(length));
        let bytes = buffers
            .get(view.buffer().index())
            .and_then(|data| data.get(start?..end?))
            .ok_or("the indices lie outside their buffer")?;
        Ok(Self { bytes, size })
    }

    /// How many indices there are.
    fn len(&self) -> usize {
        self.bytes.len() / self.size
    }

    /// Index `k` (below [`Self::len`]).
    fn get(&self, k: usize) -> usize {
        let index = &self.bytes[k * self.size..(k + 1) * self.size];
        index.iter().rev().fold(0usize, |value, &byte| value << 8 | usize::from(byte))
    }

    /// Where `element` is among the indices, which must increase strictly
    /// ([`check_sparse_indices`]): a binary search.
    fn position(&self, element: usize) -> Option<usize> {
        let (mut low, mut high) = (0, self.len());
        while low < high {
            let middle = low + (high - low) / 2;
            match self.get(middle).cmp(&element) {
                std::cmp::Ordering::Less => low = middle + 1,
                std::cmp::Ordering::Greater => high = middle,
                std::cmp::Ordering::Equal => return Some(middle),
            }
        }
        None
    }
}

/// Checks that `view`, which holds `what`, has no `byteStride`: glTF 2.0 gives one to vertex
/// attributes alone, so indices and sparse data are tightly packed.
fn check_packed(view: &buffer::View, what: &str) -> std::result::Result<(), String> {
    match view.stride() {
        Some(stride) => {
            Err(format!("bufferViews[{}] has byteStride {stride}, which glTF 2.0 forbids for {what}", view.index()))
        }
        None => Ok(()),
    }
}

/// Checks that data at byte `offset` of `view` starts at a multiple of its `component` size, both
/// in the view and in its buffer, as glTF 2.0 requires: misaligned data had been read as it lay
/// and refused for the garbage values that gave. No view (a sparse accessor's zero base) is
/// aligned.
fn check_alignment(view: Option<buffer::View>, offset: usize, component: usize) -> std::result::Result<(), String> {
    let Some(view) = view else { return Ok(()) };
    let in_buffer = view.offset() as u128 + offset as u128;
    if !offset.is_multiple_of(component) || !in_buffer.is_multiple_of(component as u128) {
        return Err(format!(
            "byteOffset {offset} (byte {in_buffer} of its buffer, through bufferViews[{}]) is not a multiple of \
             its component size, {component} bytes, as glTF 2.0 requires",
            view.index()
        ));
    }
    Ok(())
}

/// Checks that `count ≥ 1` elements of `size` bytes from byte `offset` of `view`, `byteStride`
/// apart (packed without one), lie inside the view, and the view inside its buffer's data — in
/// checked arithmetic, since the `gltf` reader's own overflows on a huge `count` (a panic in debug
/// builds, garbage in release). No view (a sparse accessor's zero base) spans nothing.
fn check_span(
    view: Option<buffer::View>,
    offset: usize,
    count: usize,
    size: usize,
    buffers: &[buffer::Data],
) -> std::result::Result<(), String> {
    let Some(view) = view else { return Ok(()) };
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!("bufferViews[{}].byteStride {stride} is less than the element size {size}", view.index()));
    }
    let end = stride.checked_mul(count - 1).and_then(|bytes| bytes.checked_add(size)?.checked_add(offset));
    if end.is_none_or(|end| end > view.length()) {
        return Err(format!(
            "{count} elements of {size} bytes from byte {offset} reach past the end of bufferViews[{}] ({} bytes)",
            view.index(),
            view.length()
        ));
    }
    let buffer = view.buffer().index();
    let data = buffers.get(buffer).map_or(0, |data| data.len());
    if view.offset().checked_add(view.length()).is_none_or(|end| end > data) {
        return Err(format!(
            "bufferViews[{}] (byteOffset {}, byteLength {}) reaches past the end of buffers[{buffer}] ({data} bytes)",
            view.index(),
            view.offset(),
            view.length()
        ));
    }
    Ok(())
}

/// Whether `accessor` has neither `bufferView` nor `sparse`, and so holds zeros (glTF 2.0
/// § 3.6.2.1: "When undefined, the accessor MUST be initialized with zeros").
fn holds_zeros(accessor: &gltf::Accessor) -> bool {
    accessor.view().is_none() && accessor.sparse().is_none()
}

/// The error of an accessor that passed [`check_accessor`] but that the reader still cannot read.
fn unreadable(accessor: &gltf::Accessor, field: &str) -> String {
    format!("{field}: accessor {}: its data cannot be read", accessor.index())
}

/// The metallic-roughness parameters of a glTF material (factors only; textures are not
/// sampled), each checked against the range glTF 2.0 gives it; an error names the field.
fn material(m: &gltf::Material) -> std::result::Result<Material, String> {
    let field = m.index().map_or_else(|| "the default material".to_owned(), |k| format!("materials[{k}]"));
    let in_unit_range = |name: &str, values: &[f32]| {
        if values.iter().all(|v| (0.0..=1.0).contains(v)) {
            Ok(())
        } else {
            Err(format!("{field}.{name} is {values:?}; glTF 2.0 requires each component in [0, 1]"))
        }
    };
    let pbr = m.pbr_metallic_roughness();
    let base_color = pbr.base_color_factor();
    in_unit_range("pbrMetallicRoughness.baseColorFactor", &base_color)?;
    in_unit_range("pbrMetallicRoughness.roughnessFactor", &[pbr.roughness_factor()])?;
    in_unit_range("pbrMetallicRoughness.metallicFactor", &[pbr.metallic_factor()])?;
    in_unit_range("emissiveFactor", &m.emissive_factor())?;
    let strength = m.emissive_strength().unwrap_or(1.0);
    if !(strength.is_finite() && strength >= 0.0) {
        return Err(format!(
            "{field}.extensions.KHR_materials_emissive_strength.emissiveStrength is {strength}; it must be \
             finite and ≥ 0"
        ));
    }
    let [r, g, b, _alpha] = base_color;
    let material = Material {
        base_color: Vec3::new(r, g, b),
        roughness: pbr.roughness_factor(),
        metallic: pbr.metallic_factor(),
        emission: Vec3::from_array(m.emissive_factor()) * strength,
        double_sided: m.double_sided(),
    };
    // Each factor was checked above against glTF's range; the emission's upper limit is left,
    // which only the product of the factor and the strength can pass.
    material.check().map_err(|(name, reason)| {
        let json = match name {
            "material.emission" => "emissiveFactor × extensions.KHR_materials_emissive_strength.emissiveStrength",
            "material.base_color" => "pbrMetallicRoughness.baseColorFactor",
            "material.roughness" => "pbrMetallicRoughness.roughnessFactor",
            _ => "pbrMetallicRoughness.metallicFactor",
        };
        format!("{field}.{json}: {reason}")
    })?;
    Ok(material)
}

/// The least distance from a glTF camera to its look-at point, in units of `f32::EPSILON` times
/// the camera position's largest coordinate, so that the point does not round onto the camera
/// (the framing camera's 64 steps; see [`PlacedCamera::aimed`]).
const LOOK_AT_RESOLUTION: f64 = 64.0;

/// A glTF perspective camera as its node places it, before the scene's geometry gives it a
/// look-at point ([`PlacedCamera::aimed`]).
struct PlacedCamera {
    /// The camera's node, which errors name.
    node: usize,
    /// The camera (`cameras[…]`), which errors name.
    camera: usize,
    /// The node's world origin.
    position: Vec3,
    /// The unit view direction: the node's −z through the linear part of its world transform.
    forward: DVec3,
    /// The unit up direction: the node's +y through that linear part.
    up: Vec3,
    /// The full vertical field of view, in degrees.
    vertical_fov_degrees: f32,
    /// Whether the world transform mirrors ([`Camera::mirrored`]).
    mirrored: bool,
}

impl PlacedCamera {
    /// The camera of node `node` (world transform `world`) with perspective projection `p`: the
    /// node looks along its −z with +y up and its +x to the image's right — [`Camera::mirrored`]
    /// where `world` mirrors, since there +x is `up × forward`. The directions come from the
    /// linear part of `world` alone (in `f64`), not from two transformed points, which a node
    /// scale of 0.01 put 0.01 apart and, far from the origin, rounded 0.25° off the view. An error
    /// names the node whose transform puts the camera beyond [`MAX_COORDINATE`] or collapses its
    /// view or up axis, or the field.
    fn new(
        node: &gltf::Node,
        camera: &gltf::Camera,
        p: &gltf::camera::Perspective,
        world: Mat4,
    ) -> std::result::Result<Self, String> {
        let yfov = p.yfov();
        if !(yfov > 0.0 && yfov < std::f32::consts::PI) {
            return Err(format!("cameras[{}].perspective.yfov is {yfov} rad; it must be in (0, π)", camera.index()));
        }
        // The field of view in degrees, as the camera keeps it, and the image plane's half height
        // that the generate stage forms from it (`frame::generate_params_with`): 3.1415925 rad
        // rounded to 180°, which `Scene::new` refuses, and 10⁻³⁰ rad gave a half height that the
        // generate stage refuses — neither error named the field.
        let vertical_fov_degrees = yfov.to_degrees();
        let half_height = crate::frame::image_plane_half_height(vertical_fov_degrees);
        if vertical_fov_degrees >= 180.0 {
            return Err(format!(
                "cameras[{}].perspective.yfov is {yfov} rad, which rounds to {vertical_fov_degrees}° in f32; it \
                 must be below 180°",
                camera.index()
            ));
        }
        if half_height * half_height < crate::backend::MIN_IMAGE_PLANE_AXIS_SQUARED {
            return Err(format!(
                "cameras[{}].perspective.yfov is {yfov:e} rad; the image plane's half height tan(yfov / 2) = \
                 {half_height:e} must be at least {:e} to normalize in f32",
                camera.index(),
                crate::backend::MIN_IMAGE_PLANE_AXIS_SQUARED.sqrt()
            ));
        }
        let (node, camera) = (node.index(), camera.index());
        let position = world.transform_point3(Vec3::ZERO);
        if !in_range(position) {
            return Err(format!(
                "nodes[{node}] (camera {camera}): its world transform puts the camera at {position}; each \
                 coordinate must be finite and within ±{MAX_COORDINATE:e}"
            ));
        }
        let linear = DMat3::from_mat4(world.as_dmat4());
        let forward = (linear * DVec3::NEG_Z).normalize();
        let up = (linear * DVec3::Y).normalize();
        if !(forward.is_finite() && up.is_finite() && forward.cross(up).normalize().as_vec3().is_finite()) {
            return Err(format!(
                "nodes[{node}] (camera {camera}): its world transform collapses the camera's view or up axis \
                 (a zero scale?)"
            ));
        }
        Ok(Self { node, camera, position, forward, up: up.as_vec3(), vertical_fov_degrees, mirrored: mirrors(linear) })
    }

    /// The camera looking at the point along its view at the depth of the bounds' centre of
    /// `meshes` (the scene's triangles of non-zero area) — at least half the bounds' radius
    /// (half their diagonal) away, for a camera inside the scene or past its centre, and at least
    /// [`LOOK_AT_RESOLUTION`] `f32` steps of the camera position's largest coordinate, so that it
    /// does not round onto the camera; at most as far as the coordinate limit lets it lie. Its
    /// distance is the thin lens's default focus distance (`frame::generate_params_with`): the
    /// plane through the scene's centre is in focus. The view direction rebuilt from the two points
    /// is off by at most the point's `f32` rounding over that distance, the order of the camera
    /// position's own rounding seen from the scene. (A point one local unit along the view, as it
    /// had been, put the focus 1 cm away under a root scale of 0.01, and 0.01 from a camera 3000
    /// from the origin it turned the view 0.25°.) An error names the node where the point still
    /// falls out of range or onto the camera.
    fn aimed(&self, meshes: &[Mesh]) -> std::result::Result<Camera, String> {
        let (lo, hi) = triangle_bounds(meshes);
        let (lo, hi, position) = (lo.as_dvec3(), hi.as_dvec3(), self.position.as_dvec3());
        let (centre, radius) = ((lo + hi) * 0.5, (hi - lo).length() * 0.5);
        // No triangle (an empty scene, which `Scene::new` refuses): any distance.
        let scene_depth =
            if lo.cmple(hi).all() { (centre - position).dot(self.forward).max(0.5 * radius) } else { 1.0 };
        // Near the origin, a floor that `f32` still normalizes over.
        let magnitude = position.abs().max_element().max(1e-12);
        let resolvable = LOOK_AT_RESOLUTION * f64::from(f32::EPSILON) * magnitude;
        // Along each axis the view moves on, the room before the coordinate limit (0.999 of it,
        // so that the point does not round past the limit).
        let room = (0..3)
            .filter(|&axis| self.forward[axis] != 0.0)
            .map(|axis| {
                let limit = f64::from(MAX_COORDINATE).copysign(self.forward[axis]);
                0.999 * (limit - position[axis]) / self.forward[axis]
            })
            .fold(f64::INFINITY, f64::min);
        let distance = scene_depth.max(resolvable).min(room);
        let camera = Camera {
            position: self.position,
            look_at: (position + self.forward * distance).as_vec3(),
            up: self.up,
            vertical_fov_degrees: self.vertical_fov_degrees,
            mirrored: self.mirrored,
        };
        if !(in_range(camera.look_at) && camera.has_view_basis()) {
            return Err(format!(
                "nodes[{}] (camera {}): the camera at {} looks at {} (along its view, at the depth of the \
                 scene's centre), which lies beyond ±{MAX_COORDINATE:e} or on the camera",
                self.node, self.camera, camera.position, camera.look_at
            ));
        }
        Ok(camera)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    thread_local! {
        /// [`PrimitiveGeometry::read`]'s calls on this thread (each test runs on its own).
        pub(super) static PRIMITIVE_READS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
    }
    use raywave_shared::Light;
    use std::io::Write;

    /// A glTF file with one quad (two triangles) in an embedded base64 buffer: 4 positions
    /// (48 bytes) followed by 6 u16 indices (12 bytes), under a node translated by (0, 0, -2),
    /// with an emissive material and a camera node.
    fn quad_gltf(index_count: u32) -> String {
        let data = base64_encode(&quad_buffer());
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

    /// [`quad_gltf`]'s 60-byte buffer.
    fn quad_buffer() -> Vec<u8> {
        quad_buffer_with(1.0, [0, 1, 2, 0, 2, 3])
    }

    /// A 60-byte buffer like [`quad_buffer`]'s: the unit square's corners times `scale`, then
    /// six u16 `indices`.
    fn quad_buffer_with(scale: f32, indices: [u16; 6]) -> Vec<u8> {
        let mut bytes = Vec::new();
        for p in [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
            for c in p {
                bytes.extend_from_slice(&(c * scale).to_le_bytes());
            }
        }
        for i in indices {
            bytes.extend_from_slice(&i.to_le_bytes());
        }
        bytes
    }

    /// [`quad_gltf`]`(index_count)` with `buffer` in place of its data, `primitive` in place of
    /// its one primitive's JSON and `node` in place of its mesh node's: the one light it loads
    /// as, or the error.
    fn quad_light_from(index_count: u32, buffer: &[u8], primitive: &str, node: &str) -> Result<Light> {
        let text = quad_gltf(index_count)
            .replacen(&base64_encode(&quad_buffer()), &base64_encode(buffer), 1)
            .replacen(r#"{"attributes":{"POSITION":0},"indices":1,"material":0}"#, primitive, 1)
            .replacen(r#"{"mesh":0,"translation":[0,0,-2]}"#, node, 1);
        let f = file(&text);
        let scene = load(f.path())?;
        assert_eq!(scene.lights().len(), 1, "{text}");
        Ok(scene.lights()[0])
    }

    /// The unit normal a quad light faces.
    fn facing(light: &Light) -> Vec3 {
        light.edge_u.truncate().cross(light.edge_v.truncate()).normalize()
    }

    /// The quad drawn as a triangle strip (indices 0 1 3 2) and as a fan (no indices: 0 1 2 3),
    /// beside a line loop around it, is the same light as drawn with triangles, facing +z; the
    /// lines, which have no area, are skipped (they were an error for the whole file).
    #[test]
    fn strips_and_fans_are_triangles_and_lines_are_skipped() {
        let node = r#"{"mesh":0,"translation":[0,0,-2]}"#;
        let triangles = r#"{"attributes":{"POSITION":0},"indices":1,"material":0}"#;
        let lines = r#"{"attributes":{"POSITION":0},"mode":2}"#;
        let expected = quad_light_from(6, &quad_buffer(), triangles, node).unwrap();
        let corners = |l: &Light| {
            let (c, u, v) = (l.position.truncate(), l.edge_u.truncate(), l.edge_v.truncate());
            let mut corners = [c, c + u, c + u + v, c + v].map(|p| p.to_array().map(f32::to_bits));
            corners.sort_unstable();
            corners
        };
        for primitive in [
            format!(r#"{{"attributes":{{"POSITION":0}},"indices":1,"material":0,"mode":5}},{lines}"#),
            format!(r#"{lines},{{"attributes":{{"POSITION":0}},"material":0,"mode":6}}"#),
        ] {
            let light = quad_light_from(4, &quad_buffer_with(1.0, [0, 1, 3, 2, 0, 0]), &primitive, node).unwrap();
            assert_eq!(corners(&light), corners(&expected), "{primitive}");
            assert!(facing(&light).abs_diff_eq(Vec3::Z, 1e-6), "{primitive}: faces {}", facing(&light));
        }
    }

    /// One mesh under a mirroring node and under a plain one, in either order: each instance winds
    /// by its own transform (the geometry read once is copied for the first and taken by the last).
    #[test]
    fn instances_of_one_mesh_wind_by_their_own_transforms() {
        let one = r#""nodes":[{"mesh":0,"translation":[0,0,-2]},{"camera":0,"translation":[0.5,0.5,3]}],"#;
        for (first, second) in [("[-1,1,1]", "[1,1,1]"), ("[1,1,1]", "[-1,1,1]")] {
            let two = format!(r#""nodes":[{{"mesh":0,"scale":{first}}},{{"mesh":0,"scale":{second}}}],"#);
            let text = quad_gltf(6).replacen(one, &two, 1);
            assert!(text.contains(&two));
            let scene = load(file(&text).path()).unwrap();
            let [a, b] = [0, 1].map(|i| scene.meshes()[i].triangles.clone());
            let reversed: Vec<[u32; 3]> = b.iter().map(|&[x, y, z]| [x, z, y]).collect();
            assert!(!a.is_empty() && a == reversed, "{first} then {second}: {a:?} against {b:?}");
            let mirrored = if first == "[-1,1,1]" { 0 } else { 1 };
            assert!(scene.meshes()[mirrored].positions.iter().all(|p| p.x <= 0.0), "{first} then {second}");
        }
    }

    /// A mirroring node with a tiny scale: its `f32` determinant, −10⁻⁴⁸, underflows to −0, so
    /// the mirror went unnoticed and the lamp emitted from its back.
    #[test]
    fn a_tiny_mirroring_scale_still_reverses_the_triangles() {
        let triangles = r#"{"attributes":{"POSITION":0},"indices":1,"material":0}"#;
        for (scale, node) in
            [(1.0, r#"{"mesh":0,"scale":[-1,1,1]}"#), (1.0e16, r#"{"mesh":0,"scale":[-1e-16,1e-16,1e-16]}"#)]
        {
            let light = quad_light_from(6, &quad_buffer_with(scale, [0, 1, 2, 0, 2, 3]), triangles, node).unwrap();
            assert!(facing(&light).abs_diff_eq(Vec3::Z, 1e-6), "{node}: faces {}", facing(&light));
        }
    }

    /// A 1 × 1 lamp modelled 1.5·10³ from its node's origin, which the node's scale, rotation
    /// and translation bring back near the world's (as a model recentred by its root node is):
    /// placed in `f32`, each corner carried the rounding of the 10³-sized terms, which bent the
    /// lamp past its tolerance (10⁻⁴ of its size plus 16 ε of its world coordinates), and it
    /// stayed an unsupported emitter. Placed in `f64` and rounded once, it is a quad light. (A
    /// helper's sweep of such lamps, offsets 10³..10⁵ and scales 0.1..10: 8300 of 20 000 refused,
    /// every one a light when rounded once.)
    #[test]
    fn a_lamp_far_out_in_its_node_space_is_placed_as_a_parallelogram() {
        let offset = Vec3::new(339.28693, -413.79184, -1463.6217);
        let local = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y].map(|p| p + offset);
        let rotation = glam::Quat::from_axis_angle(Vec3::new(-0.77815384, -0.574024, 0.2548981), 0.57355255);
        let scale = 0.4223223;
        let translation = Vec3::new(0.5, 1.0, 2.0) - rotation * offset * scale;
        let world = Mat4::from_scale_rotation_translation(Vec3::splat(scale), rotation, translation);
        let (mut positions, mut triangles) = (local.to_vec(), vec![[0, 1, 2], [0, 2, 3]]);
        let placement = Placement { world, node: 0, instance: None };
        place(&mut positions, &mut triangles, &[0, 1, 2, 3], "meshes[0].primitives[0]", &placement).unwrap();
        let c = positions.iter().map(|p| p.as_dvec3()).collect::<Vec<_>>();
        let bend = (c[0] + c[2] - c[1] - c[3]).length();
        let material = Material { emission: Vec3::ONE, ..Material::diffuse(Vec3::ONE) };
        let lamp = Mesh { name: "lamp".into(), positions, triangles, material };
        assert!(super::super::emitters::parallelogram(&lamp).is_some(), "bent {bend:e} out of a parallelogram");
    }

    /// A primitive without POSITION is skipped, as glTF 2.0 § 3.7.2.1 asks ("client
    /// implementations SHOULD skip primitive's rendering"): gltf-json 1.4's validation had
    /// refused the file. Its other errors stand — a POSITION accessor without `min` among them —,
    /// and a file with nothing else renders nothing.
    #[test]
    fn a_primitive_without_positions_is_skipped() {
        let quad = quad_gltf(6);
        let primitive = r#"{"attributes":{"POSITION":0},"indices":1,"material":0}"#;
        let unpositioned = r#"{"attributes":{},"mode":0}"#;
        let with_normals_only = r#"{"attributes":{"NORMAL":0},"indices":1}"#;
        let three = quad.replace(primitive, &format!("{unpositioned},{primitive},{with_normals_only}"));
        assert_ne!(three, quad);
        let scene = load(file(&three).path()).unwrap();
        let names: Vec<&str> = scene.meshes().iter().map(|mesh| mesh.name.as_str()).collect();
        assert_eq!(names, ["quad primitive 1"]);
        let without_min = three.replace(r#""min":[0,0,0],"#, "");
        assert_ne!(without_min, three);
        let err = load(file(&without_min).path()).unwrap_err().to_string();
        let expected = r#"invalid glTF: meshes[0].primitives[1].attributes["POSITION"].min: Missing data;"#;
        assert!(err.contains(expected) && !err.contains("primitives[0]"), "{err}");
        let err = load(file(&quad.replace(primitive, unpositioned)).path()).unwrap_err().to_string();
        assert!(err.contains("contains no triangles"), "{err}");
    }

    /// [`quad_gltf`] with its buffer at `uri` instead of in a data URI.
    fn quad_gltf_with_buffer_uri(uri: &str) -> String {
        let mut text = quad_gltf(6);
        let start = text.find("data:application").unwrap();
        let end = start + text[start..].find('"').unwrap();
        text.replace_range(start..end, uri);
        text
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
        file_of(".gltf", text.as_bytes())
    }

    /// A temporary file named `*suffix` holding `bytes`.
    fn file_of(suffix: &str, bytes: &[u8]) -> tempfile::NamedTempFile {
        let mut f = tempfile::Builder::new().suffix(suffix).tempfile().unwrap();
        f.write_all(bytes).unwrap();
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
        let f = file(&quad_gltf_with_buffer_uri("missing.bin"));
        let err = load(f.path()).unwrap_err();
        assert!(matches!(err, Error::SceneLoad { .. }), "{err}");
        assert!(err.to_string().contains(r#"buffers[0] ("missing.bin")"#), "{err}");
    }

    /// Primitives that share one POSITION accessor of 4·10⁶ elements (sparse, without a buffer
    /// view: zeros but for 2·10⁵ substituted elements) and each draw three of them — element 0,
    /// a zero, and the first two substitutions: each primitive is read at the cost of what it
    /// draws and the accessor is checked once. Decoding the whole accessor per primitive, as the
    /// `gltf` reader does, took a test like this one (500 primitives, 3 substitutions) 25 s on the
    /// 2-vCPU VM and a file of 10⁵ such primitives hours; reading and checking the sparse indices
    /// per primitive took this one 3.7 s (0.02 s now). No time is asserted: a regression shows as
    /// this test's.
    #[test]
    fn primitives_sharing_a_huge_position_accessor_read_only_what_they_draw() {
        const ELEMENTS: usize = 4_000_000;
        const SUBSTITUTED: usize = 200_000;
        const PRIMITIVES: usize = 2000;
        let dir = tempfile::tempdir().unwrap();
        let mut data = Vec::new();
        for k in 0..SUBSTITUTED {
            let value = match k {
                0 => [1f32, 0., 0.],
                1 => [0., 1., 0.],
                _ => [5., 5., 5.],
            };
            data.extend(value.iter().flat_map(|c| c.to_le_bytes()));
        }
        data.extend((1..=SUBSTITUTED as u32).flat_map(u32::to_le_bytes));
        data.extend([0u16, 1, 2].iter().flat_map(|i| i.to_le_bytes()));
        data.resize(ELEMENTS, 0);
        std::fs::write(dir.path().join("big.bin"), &data).unwrap();
        let (values, indices) = (12 * SUBSTITUTED, 4 * SUBSTITUTED);
        let primitive = r#"{"attributes":{"POSITION":0},"indices":1}"#;
        let primitives = vec![primitive; PRIMITIVES].join(",");
        let text = format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
            "meshes":[{{"primitives":[{primitives}]}}],
            "buffers":[{{"byteLength":{ELEMENTS},"uri":"big.bin"}}],
            "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":{values}}},
                           {{"buffer":0,"byteOffset":{values},"byteLength":{indices}}},
                           {{"buffer":0,"byteOffset":{},"byteLength":6}}],
            "accessors":[{{"componentType":5126,"count":{ELEMENTS},"type":"VEC3","min":[0,0,0],"max":[5,5,5],
                           "sparse":{{"count":{SUBSTITUTED},"indices":{{"bufferView":1,"componentType":5125}},"values":{{"bufferView":0}}}}}},
                         {{"bufferView":2,"componentType":5123,"count":3,"type":"SCALAR"}}]}}"#,
            values + indices
        );
        let path = dir.path().join("shared.gltf");
        std::fs::write(&path, text).unwrap();
        let scene = load(&path).unwrap();
        assert_eq!(scene.meshes().len(), PRIMITIVES);
        for mesh in scene.meshes() {
            assert_eq!(mesh.positions, [Vec3::ZERO, Vec3::X, Vec3::Y], "{}", mesh.name);
            assert_eq!(mesh.triangles, [[0, 1, 2]], "{}", mesh.name);
        }
    }

    /// A POSITION accessor in an interleaved buffer view (`byteStride` 24: each position followed
    /// by 12 bytes of something else) reads every 24 bytes, as the view says.
    #[test]
    fn positions_in_an_interleaved_view_follow_its_stride() {
        let mut data = Vec::new();
        for p in [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
            data.extend(p.iter().flat_map(|c| c.to_le_bytes()));
            data.extend([9f32; 3].iter().flat_map(|c| c.to_le_bytes()));
        }
        data.extend([0u16, 1, 2, 0, 2, 3].iter().flat_map(|i| i.to_le_bytes()));
        let text = quad_gltf(6)
            .replacen(&base64_encode(&quad_buffer()), &base64_encode(&data), 1)
            .replacen(r#""byteLength":60"#, r#""byteLength":108"#, 1)
            .replacen(
                r#"{"buffer":0,"byteOffset":0,"byteLength":48}"#,
                r#"{"buffer":0,"byteOffset":0,"byteLength":96,"byteStride":24}"#,
                1,
            )
            .replacen(
                r#"{"buffer":0,"byteOffset":48,"byteLength":12}"#,
                r#"{"buffer":0,"byteOffset":96,"byteLength":12}"#,
                1,
            );
        let scene = load(file(&text).path()).unwrap();
        let corners = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]].map(|[x, y]| Vec3::new(x, y, -2.0));
        assert_eq!(scene.meshes()[0].positions, corners);
    }

    /// External buffers resolve as the `gltf` crate resolves them (percent-decoded relative
    /// paths, `file:` URIs), and only their `byteLength` is read; what that crate panicked on (a
    /// percent-decoded URI that is not UTF-8) or read without end (`/dev/zero`) is an error. Data
    /// URIs without `;base64`, which the crate read as base64, are percent-decoded.
    #[test]
    fn external_buffers_are_read_up_to_their_length_from_regular_files_only() {
        let dir = tempfile::tempdir().unwrap();
        let mut long = quad_buffer();
        long.resize(1 << 20, 0xff);
        std::fs::write(dir.path().join("quad data.bin"), &long).unwrap();
        let scene_at = |uri: &str| {
            let path = dir.path().join("scene.gltf");
            std::fs::write(&path, quad_gltf_with_buffer_uri(uri)).unwrap();
            load(&path)
        };
        let absolute = dir.path().join("quad data.bin").display().to_string();
        for uri in ["quad%20data.bin".to_owned(), format!("file://{absolute}"), format!("file:{absolute}")] {
            let scene = scene_at(&uri).unwrap_or_else(|e| panic!("{uri}: {e}"));
            assert_eq!(scene.triangle_count(), 2, "{uri}");
        }
        let refused = [
            ("%ff.bin", "the percent-decoded URI is not UTF-8 text"),
            ("no%20such.bin", "no such.bin: No such file"),
            (".", "is not a regular file"),
            ("file:///dev/zero", "/dev/zero is not a regular file"),
            ("https://example.invalid/quad.bin", "unsupported URI scheme"),
        ];
        for (uri, expected) in refused {
            let err = scene_at(uri).unwrap_err().to_string();
            assert!(err.contains(&format!("buffers[0] ({uri:?}): ")) && err.contains(expected), "{uri}: {err}");
        }
        // A data URI in RFC 2397's percent-encoded form, as glTF-Validator's `data_uri.glb` has.
        let byte = |b: &u8| if b.is_ascii_alphanumeric() { char::from(*b).to_string() } else { format!("%{b:02X}") };
        let encoded: String = quad_buffer().iter().map(byte).collect();
        let scene = scene_at(&format!("data:application/gltf-buffer,{encoded}")).unwrap();
        assert_eq!(scene.triangle_count(), 2);
        for (uri, expected) in [
            ("data:application/octet-stream", "the data URI has no `,` before its data"),
            ("data:,%00%01", "byteLength is 60 but the data has 4 bytes"),
        ] {
            let err = scene_at(uri).unwrap_err().to_string();
            assert!(err.contains(&format!("buffers[0] (embedded data URI): {expected}")), "{uri}: {err}");
        }
        // Padded to 52 bytes, as the `gltf` crate pads, which is less than the 60 of byteLength.
        std::fs::write(dir.path().join("short.bin"), &quad_buffer()[..50]).unwrap();
        let err = scene_at("short.bin").unwrap_err().to_string();
        assert!(err.contains("byteLength is 60 but the data has 52 bytes"), "{err}");
    }

    /// Files the `gltf` crate accepts or panics on, each made from [`quad_gltf`] by replacing one
    /// piece of its JSON: each must give a `SceneLoad` error naming the field. Before these
    /// checks the first two panicked in `gltf`, the node cycle hung, the doubly listed root loaded
    /// its mesh twice, VEC2 positions loaded as garbage, the huge sparse count aborted on a 24 GiB
    /// allocation, and the rest failed with misleading messages ("no POSITION attribute"; an
    /// unreadable index accessor was ignored, the primitive read unindexed).
    #[test]
    fn invalid_accessors_and_node_cycles_are_errors_naming_the_field() {
        let cases = [
            (r#""POSITION":0"#, r#""POSITION":7"#, "attributes.POSITION: accessor 7 does not exist"),
            (r#""componentType":5123"#, r#""componentType":5126"#, "indices: accessor 1: holds Scalar of F32"),
            (r#""type":"VEC3""#, r#""type":"VEC2""#, "POSITION: accessor 0: holds Vec2 of F32"),
            (
                r#""count":4"#,
                r#""count":40"#,
                "40 elements of 12 bytes from byte 0 reach past the end of bufferViews[0]",
            ),
            (r#""byteOffset":48"#, r#""byteOffset":52"#, "bufferViews[1] (byteOffset 52, byteLength 12) reaches past"),
            // Misaligned: once read as they lay, and refused for the garbage values.
            (
                r#""count":4,"type":"VEC3""#,
                r#""count":3,"byteOffset":2,"type":"VEC3""#,
                "POSITION: accessor 0: byteOffset 2 (byte 2 of its buffer, through bufferViews[0]) is not a multiple \
                 of its component size, 4 bytes",
            ),
            (r#""byteOffset":48"#, r#""byteOffset":47"#, "indices: accessor 1: byteOffset 0 (byte 47 of its buffer"),
            (r#""count":4"#, r#""count":0"#, "POSITION: accessor 0: count 0 is outside"),
            (r#""count":4"#, r#""count":4,"byteOffset":18446744073709551608"#, "from byte 18446744073709551608 reach"),
            (
                r#"{"bufferView":0,"componentType":5126,"count":4"#,
                r#"{"componentType":5126,"count":2147483648,"sparse":{"count":1,"indices":{"bufferView":1,"componentType":5123},"values":{"bufferView":0}}"#,
                "count 2147483648 is outside 1..=60",
            ),
            (r#"{"mesh":0,"translation""#, r#"{"mesh":0,"children":[0],"translation""#, "nodes[0] is reached twice"),
            (r#""nodes":[0,1]"#, r#""nodes":[0,1,0]"#, "nodes[0] is reached twice"),
            // Three positions for indices up to 3: once a generic error naming the mesh's triangle.
            (
                r#""count":4,"type":"VEC3""#,
                r#""count":3,"type":"VEC3""#,
                "meshes[0].primitives[0].indices element 5 is 3, but attributes.POSITION has 3 elements",
            ),
        ];
        for (from, to, expected) in cases {
            let text = quad_gltf(6);
            assert!(text.contains(from), "{from}");
            let f = file(&text.replacen(from, to, 1));
            match load(f.path()) {
                Err(err @ Error::SceneLoad { .. }) => assert!(err.to_string().contains(expected), "{to}: {err}"),
                other => panic!("{to}: expected a SceneLoad error containing {expected:?}, got {other:?}"),
            }
        }
    }

    #[test]
    fn sparse_accessor_and_missing_texture_image_load() {
        // POSITION as a sparse accessor without a buffer view: 4 zeros, of which elements 0, 1, 2
        // (the index view's first three u16) take the first three corners; and an image that
        // does not exist (textures are not sampled, so it is not loaded).
        let text = quad_gltf(6)
            .replacen(
                r#"{"bufferView":0,"componentType":5126,"count":4"#,
                r#"{"componentType":5126,"count":4,"sparse":{"count":3,"indices":{"bufferView":1,"componentType":5123},"values":{"bufferView":0}}"#,
                1,
            )
            .replacen(r#""scene":0,"#, r#""scene":0,"images":[{"uri":"no_such_texture.png"}],"#, 1);
        let f = file(&text);
        let scene = load(f.path()).unwrap();
        let corners = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0]].map(|[x, y]| Vec3::new(x, y, -2.0));
        assert_eq!(scene.meshes()[0].positions, corners);
    }

    /// Valid files that gltf-json 1.4.1 refused, with what raywave does not read: an animation
    /// channel without `target.node` or with `KHR_animation_pointer`'s `"path": "pointer"`, and a
    /// texture without `source` (each optional in glTF 2.0's schema), an accessor with neither
    /// `bufferView` nor `sparse` (zeros), `extras` that are not an object and an attribute named
    /// `_…` (gltf-json reads both with its `extras` feature only). An error after the blanked
    /// animations still names its line. Versions a 2.0 reader may not read are refused, by field,
    /// glTF 1.0 files among them (they failed on some other member).
    #[test]
    fn valid_files_with_unread_animations_and_textures_load_and_versions_are_checked() {
        let animations = r#""animations":[{"channels":[{"sampler":0,"target":{"path":"pointer",
            "extensions":{"KHR_animation_pointer":{"pointer":"/materials/0/emissiveFactor"}}}},
            {"sampler":0,"target":{"path":"rotation"}}],
            "samplers":[{"input":3,"output":3}]}],"#;
        let textures = r#""textures":[{"sampler":0}],"samplers":[{}],"#;
        let zeros = r#""type":"SCALAR"},{"componentType":5126,"count":4,"type":"VEC3"}]"#;
        // `extras` of any JSON type, and an application's own attribute (named with a leading `_`).
        let extras = r#""extras":42,"#;
        let text = (quad_gltf(6).replacen(r#""scene":0,"#, &format!(r#""scene":0,{extras}{animations}{textures}"#), 1))
            .replacen(r#""type":"SCALAR"}]"#, zeros, 1)
            .replacen(r#""POSITION":0}"#, r#""POSITION":0,"_PRESSURE":2}"#, 1);
        assert!(text.contains(zeros) && text.contains("_PRESSURE"));
        let scene = load(file(&text).path()).unwrap();
        assert_eq!((scene.triangle_count(), scene.lights().len()), (2, 1));
        // The accessor the animation names need not even exist, as nothing reads it; an error
        // past the animations keeps its line (3 lines of animations, then the quad's 5th).
        let broken = text.replacen(r#""yfov":0.8"#, r#""yfov":"wide""#, 1);
        let err = load(file(&broken).path()).unwrap_err().to_string();
        assert!(err.contains("line 6"), "{err}");
        for (version, expected) in [
            (r#""version":"1.0""#, r#"asset.version is "1.0": raywave reads glTF 2.x files"#),
            (r#""version":"2""#, r#"asset.version is "2""#),
            (r#""version":"2.0","minVersion":"2.1""#, r#"asset.minVersion is "2.1": the file needs a glTF reader"#),
        ] {
            let text = quad_gltf(6).replacen(r#""version":"2.0""#, version, 1);
            let err = load(file(&text).path()).unwrap_err().to_string();
            assert!(err.contains(expected), "{version}: {err}");
        }
        // A glTF 1.0 file, whose members are not glTF 2.0's (`meshes` an object), is refused
        // for its version, not for a member; as is glTF 1.0's binary GLB, by its header.
        for (version, expected) in [(r#""1.0""#, r#""1.0""#), ("1", r#""1""#)] {
            let version_1 = format!(r#"{{"asset":{{"version":{version}}},"meshes":{{"box":{{"primitives":[]}}}}}}"#);
            let err = load(file(&version_1).path()).unwrap_err().to_string();
            assert!(err.contains(&format!("asset.version is {expected}: raywave reads glTF 2.x files")), "{err}");
        }
        let mut glb_1 = glb_container(quad_gltf(6).as_bytes(), b' ', None);
        glb_1[4..8].copy_from_slice(&1u32.to_le_bytes());
        let err = load(file_of(".glb", &glb_1).path()).unwrap_err().to_string();
        assert!(err.contains("GLB header: version 1: raywave reads glTF 2.0's GLB, version 2"), "{err}");
        for version in [r#""version":"2.1""#, r#""version":"2.0","minVersion":"2.0""#] {
            let text = quad_gltf(6).replacen(r#""version":"2.0""#, version, 1);
            assert!(load(file(&text).path()).is_ok(), "{version}");
        }
    }

    /// A validation error names an extension's member as the file writes it
    /// (`KHR_lights_punctual`), not as gltf-json's field (`khrLightsPunctual`).
    #[test]
    fn validation_errors_name_extensions_as_files_write_them() {
        assert_eq!(
            as_written("extensions.khrLightsPunctual.lights[2].spot"),
            "extensions.KHR_lights_punctual.lights[2].spot"
        );
        assert_eq!(
            as_written("nodes[0].extensions.extMeshGpuInstancing"),
            "nodes[0].extensions.EXT_mesh_gpu_instancing"
        );
        assert_eq!(as_written("meshes[0].primitives[1].attributes"), "meshes[0].primitives[1].attributes");
        let spot = r#""extensions":{"KHR_lights_punctual":{"lights":[{"type":"spot"}]}},"#;
        let text = quad_gltf(6).replacen(r#""scene":0,"#, &format!(r#""scene":0,{spot}"#), 1);
        let err = load(file(&text).path()).unwrap_err().to_string();
        assert!(err.contains("extensions.KHR_lights_punctual.lights[0].spot: Missing data"), "{err}");
    }

    /// Material factors outside glTF 2.0's ranges (once clamped or passed on silently) and
    /// cameras that cannot see: each a `SceneLoad` error with the JSON path of the field.
    #[test]
    fn materials_and_cameras_out_of_range_are_errors_naming_the_field() {
        let lamp =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/data/emissive_quad.gltf")).unwrap();
        let cases = [
            (
                "\"baseColorFactor\": [\n     0.7",
                "\"baseColorFactor\": [\n     -0.7",
                "materials[0].pbrMetallicRoughness.baseColorFactor",
            ),
            ("\"roughnessFactor\": 1", "\"roughnessFactor\": 1.5", "materials[0].pbrMetallicRoughness.roughnessFactor"),
            ("\"metallicFactor\": 0", "\"metallicFactor\": -1", "materials[0].pbrMetallicRoughness.metallicFactor"),
            ("\"emissiveFactor\": [\n    1,", "\"emissiveFactor\": [\n    3e38,", "materials[1].emissiveFactor"),
            ("\"yfov\": 0.9", "\"yfov\": 4.0", "cameras[0].perspective.yfov is 4 rad"),
            // Within (0, π), but 180° once in degrees, or an image plane too small to normalize:
            // once refused by `Scene::new` and the generate stage without naming the field.
            (
                "\"yfov\": 0.9",
                "\"yfov\": 3.1415925",
                "cameras[0].perspective.yfov is 3.1415925 rad, which rounds to 180° in f32; it must be below 180°",
            ),
            ("\"yfov\": 0.9", "\"yfov\": 1e-30", "cameras[0].perspective.yfov is 1e-30 rad; the image plane's"),
            (
                "\"camera\": 0,",
                "\"camera\": 0, \"scale\": [0, 0, 0],",
                "nodes[2] (camera 0): its world transform collapses",
            ),
            // Each factor in range, their product beyond MAX_EMISSION: once a generic error naming
            // the mesh's `material.emission`.
            (
                "\"emissiveStrength\": 4",
                "\"emissiveStrength\": 1e21",
                "materials[1].emissiveFactor × extensions.KHR_materials_emissive_strength.emissiveStrength: emits",
            ),
            // A node transform that moves a vertex or the camera beyond MAX_COORDINATE, or makes it
            // not finite: once errors naming the mesh's vertex or the scene's camera, not the node.
            (
                "\"mesh\": 1,",
                "\"mesh\": 1, \"scale\": [1e9, 1, 1],",
                "meshes[1].primitives[0].attributes.POSITION element 0 is at [-250000000, 1.5, -0.125] in world space under nodes[1]",
            ),
            (
                "\"mesh\": 1,",
                "\"mesh\": 1, \"scale\": [1e39, 1, 1],",
                "meshes[1].primitives[0].attributes.POSITION element 0 is at [NaN, NaN, NaN] in world space under nodes[1]",
            ),
            (
                "0.75,\n    3\n",
                "0.75,\n    3e9\n",
                "nodes[2] (camera 0): its world transform puts the camera at [0, 0.75, 3000000000]",
            ),
        ];
        for (from, to, field) in cases {
            let text = lamp.replacen(from, to, 1);
            assert_ne!(text, lamp, "{from:?} is in the file");
            let f = file(&text);
            let err = load(f.path()).unwrap_err();
            assert!(matches!(err, Error::SceneLoad { .. }) && err.to_string().contains(field), "{field}: {err}");
        }
        // Just inside both of yfov's bounds: the scene loads and the generate stage takes its camera.
        for yfov in ["3.14159", "1e-18"] {
            let f = file(&lamp.replacen("\"yfov\": 0.9", &format!("\"yfov\": {yfov}"), 1));
            let scene = load(f.path()).unwrap_or_else(|e| panic!("yfov {yfov}: {e}"));
            crate::backend::check_generate_params(&crate::frame::generate_params(&scene, 4, 4, 0)).unwrap();
        }
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
        let light_mesh = scene.light_mesh(0);
        assert_eq!(scene.lights(), &[lamp.made_of(light_mesh as u32)]);
        assert_eq!(scene.lights()[0].mesh, 1, "the lamp is the second mesh, after the floor");
        assert_eq!(scene.meshes()[light_mesh].name, "lamp primitive 0");
        assert_eq!(scene.mesh_light(light_mesh), Some(0));
        assert_eq!(scene.mesh_light(1 - light_mesh), None);
        let built = scene.lights()[0];
        let facing = built.edge_u.truncate().cross(built.edge_v.truncate());
        assert!(facing.normalize().abs_diff_eq(Vec3::NEG_Y, 1e-6), "emits down, towards the floor: {facing}");
    }

    /// A `doubleSided` emissive rectangle lights both sides, as it is seen glowing from both:
    /// it was a one-sided light, leaving what lay behind it dark.
    #[test]
    fn a_double_sided_lamp_is_a_two_sided_light() {
        let lamp =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/data/emissive_quad.gltf")).unwrap();
        let text = lamp.replacen(
            r#""name": "lamp",
   "pbrMetallicRoughness""#,
            r#""name": "lamp", "doubleSided": true,
   "pbrMetallicRoughness""#,
            1,
        );
        assert_ne!(text, lamp);
        let single = load(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/data/emissive_quad.gltf"))).unwrap();
        let double = load(file(&text).path()).unwrap();
        assert_eq!(single.lights()[0].two_sided, 0);
        assert_eq!(double.lights()[0], Light { two_sided: 1, ..single.lights()[0] });
        assert!(double.meshes()[double.light_mesh(0)].material.double_sided);
    }

    #[test]
    fn negative_emissive_strength_is_an_error() {
        let lamp =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/data/emissive_quad.gltf")).unwrap();
        let text = lamp.replace(r#""emissiveStrength": 4"#, r#""emissiveStrength": -2"#);
        assert_ne!(text, lamp);
        let f = file(&text);
        let err = load(f.path()).unwrap_err();
        assert!(matches!(err, Error::SceneLoad { .. }), "{err}");
        let field = "materials[1].extensions.KHR_materials_emissive_strength.emissiveStrength is -2";
        assert!(err.to_string().contains(field), "{err}");
    }

    #[test]
    fn index_count_that_is_not_triangles_is_an_error() {
        let f = file(&quad_gltf(5));
        let err = load(f.path()).unwrap_err();
        assert!(err.to_string().contains("whole number of triangles"), "{err}");
    }

    #[test]
    fn a_mirrored_lamp_still_emits_towards_the_floor() {
        // glTF 2.0 §3.7.4: under a transform with a negative determinant the clockwise face is
        // the front. Mirrored in x (or in y, which also moves it below the floor's plane: only
        // its facing is checked), the lamp keeps facing down; mirrored in y, its front turns up.
        let lamp =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/data/emissive_quad.gltf")).unwrap();
        for scale in ["[-1, 1, 1]", "[1, -1, 1]", "[-1, -1, -1]"] {
            let text = lamp.replacen(r#""mesh": 1,"#, &format!(r#""mesh": 1, "scale": {scale},"#), 1);
            assert_ne!(text, lamp);
            let f = file(&text);
            let scene = load(f.path()).unwrap();
            let facing = facing(&scene.lights()[0]);
            // Mirrored in y (alone or with x and z: a point reflection) the lamp's front turns up.
            let expected = if scale == "[-1, 1, 1]" { Vec3::NEG_Y } else { Vec3::Y };
            assert!(facing.abs_diff_eq(expected, 1e-6), "scale {scale}: faces {facing}");
        }
    }

    /// A camera whose `type` names a projection it does not define panicked inside the `gltf`
    /// crate; one that defines both is as invalid. Both are errors naming the field, whether or
    /// not a node uses the camera.
    #[test]
    fn a_camera_must_define_the_projection_its_type_names_and_only_it() {
        let perspective = r#"{"type":"perspective","perspective":{"yfov":0.8,"znear":0.01}}"#;
        let orthographic_object = r#""orthographic":{"xmag":1,"ymag":1,"znear":0.01,"zfar":10}"#;
        let perspective_object = r#""perspective":{"yfov":0.8,"znear":0.01}"#;
        for (camera, expected) in [
            (format!(r#"{{"type":"perspective",{orthographic_object}}}"#), "cameras[0].perspective: missing"),
            (format!(r#"{{"type":"orthographic",{perspective_object}}}"#), "cameras[0].orthographic: missing"),
            (
                format!(r#"{{"type":"perspective",{perspective_object},{orthographic_object}}}"#),
                "cameras[0].orthographic: defined",
            ),
            (
                format!(r#"{perspective},{{"type":"orthographic",{perspective_object}}}"#),
                "cameras[1].orthographic: missing",
            ),
        ] {
            let text = quad_gltf(6).replacen(perspective, &camera, 1);
            assert_ne!(text, quad_gltf(6));
            let f = file(&text);
            let err = load(f.path()).unwrap_err().to_string();
            assert!(err.contains(expected) && err.contains(&f.path().display().to_string()), "{camera}: {err}");
        }
    }

    /// A node `matrix` that is not translation, rotation and scale (a projective last row), a
    /// `rotation` that is not a unit quaternion, and a matrix beside a translation that differs are
    /// errors naming the node (and its field); a rotation off by rounding, the identity written
    /// out, and a matrix beside the same translation and scale, load.
    #[test]
    fn node_transforms_must_be_what_gltf_allows() {
        let node = r#"{"mesh":0,"translation":[0,0,-2]}"#;
        for (bad, expected) in [
            (
                r#"{"mesh":0,"matrix":[1,0,0,0, 0,1,0,0, 0,0,1,0.5, 0,0,-2,1]}"#,
                "nodes[0].matrix: its last row is [0.0, 0.0, 0.5, 1.0]",
            ),
            (r#"{"mesh":0,"rotation":[0,0,1,1]}"#, "nodes[0].rotation: [0.0, 0.0, 1.0, 1.0] is 1.4142135 long"),
            (r#"{"mesh":0,"rotation":[0,0,0,0]}"#, "nodes[0].rotation"),
            // A matrix beside a translation it does not hold: the crate had dropped the translation.
            (
                r#"{"mesh":0,"matrix":[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1],"translation":[0,0,-2]}"#,
                "nodes[0]: has both a matrix and a translation, rotation or scale, which differ (by up to 2)",
            ),
        ] {
            let text = quad_gltf(6).replacen(node, bad, 1);
            assert_ne!(text, quad_gltf(6));
            let err = load(file(&text).path()).unwrap_err().to_string();
            assert!(err.contains(expected), "{bad}: {err}");
        }
        for fine in [
            r#"{"mesh":0,"matrix":[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,-2,1]}"#,
            r#"{"mesh":0,"rotation":[0,0,0.7071,0.7071],"translation":[0,0,-2]}"#,
            // Both, saying the same.
            r#"{"mesh":0,"matrix":[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,-2,1],"translation":[0,0,-2],"scale":[1,1,1]}"#,
        ] {
            let text = quad_gltf(6).replacen(node, fine, 1);
            assert!(load(file(&text).path()).is_ok(), "{fine}");
        }
    }

    /// A `matrix` whose last row is off (0, 0, 0, 1) by less than [`TRANSFORM_TOLERANCE`] is taken
    /// as rounding and made exact: kept, its 0.0009 carried the parent's translation by 1000 into
    /// the child's linear part, and the unit lamp came out 1.9 wide.
    #[test]
    fn a_matrix_last_row_off_by_rounding_is_made_exact() {
        let nodes = r#""nodes":[{"mesh":0,"translation":[0,0,-2]},{"camera":0,"translation":[0.5,0.5,3]}],"#;
        let parented = r#""nodes":[{"translation":[1000,0,0],"children":[2]},{"camera":0,"translation":[0.5,0.5,3]},
            {"mesh":0,"matrix":[1,0,0,0.0009, 0,1,0,0, 0,0,1,0, 0,0,-2,1]}],"#;
        let text = quad_gltf(6).replacen(nodes, parented, 1);
        assert_ne!(text, quad_gltf(6));
        let scene = load(file(&text).path()).unwrap();
        let light = scene.lights()[0];
        let (u, v) = (light.edge_u.truncate(), light.edge_v.truncate());
        assert!((u.length() - 1.0).abs() < 1e-4 && (v.length() - 1.0).abs() < 1e-4, "edges {u} and {v}");
        let xs = scene.meshes()[0].positions.iter().map(|p| p.x);
        let (lo, hi) = xs.fold((f32::MAX, f32::MIN), |(lo, hi), x| (lo.min(x), hi.max(x)));
        assert_eq!((lo, hi), (1000.0, 1001.0));
    }

    /// Primitives that draw points or lines are counted ([`Unrendered::point_and_line_primitives`])
    /// and not drawn; a scene of nothing else is an error that says so (it blamed zero-area
    /// triangles, of which it had none).
    #[test]
    fn point_and_line_primitives_are_counted_and_a_scene_of_them_alone_is_an_error_saying_so() {
        let quad = r#"{"attributes":{"POSITION":0},"indices":1,"material":0}"#;
        let others = r#"{"attributes":{"POSITION":0},"mode":0},{"attributes":{"POSITION":0},"indices":1,"mode":3}"#;
        let mixed = quad_gltf(6).replacen(quad, &format!("{quad},{others}"), 1);
        assert!(mixed.contains(others));
        let scene = load(file(&mixed).path()).unwrap();
        assert_eq!((scene.triangle_count(), scene.unrendered().point_and_line_primitives), (2, 2));
        assert_eq!(load(file(&quad_gltf(6)).path()).unwrap().unrendered().point_and_line_primitives, 0);
        let lines = quad_gltf(6).replacen(quad, r#"{"attributes":{"POSITION":0},"indices":1,"mode":1}"#, 1);
        let err = load(file(&lines).path()).unwrap_err().to_string();
        let expected =
            "its meshes draw no surface: 1 primitive(s) draw points or lines, which raywave does not render \
                        (0 zero-area triangles dropped)";
        assert!(err.contains(expected), "{err}");
    }

    /// An indices accessor with neither `bufferView` nor `sparse` reads as zeros (glTF 2.0), so
    /// its triangles are degenerate and dropped; it had been refused as "its data cannot be read".
    #[test]
    fn indices_without_buffer_view_are_zeros() {
        let indices = r#"{"bufferView":1,"componentType":5123,"count":6,"type":"SCALAR"}"#;
        let zeros = quad_gltf(6).replacen(indices, r#"{"componentType":5123,"count":6,"type":"SCALAR"}"#, 1);
        assert_ne!(zeros, quad_gltf(6));
        assert!(matches!(load(file(&zeros).path()), Err(Error::EmptyScene { dropped_degenerate: 2, .. })));
        let zero_accessor = r#",{"componentType":5123,"count":6,"type":"SCALAR"}]}"#;
        let mixed = quad_gltf(6).replacen(&format!("{indices}]}}"), &format!("{indices}{zero_accessor}"), 1).replacen(
            r#""material":0}]"#,
            r#""material":0},{"attributes":{"POSITION":0},"indices":2}]"#,
            1,
        );
        let scene = load(file(&mixed).path()).unwrap();
        assert_eq!((scene.triangle_count(), scene.dropped_degenerate()), (2, 2), "{mixed}");
    }

    /// A Draco-compressed primitive is read from its uncompressed accessors, as a file that uses
    /// the extension without requiring it must keep them; where POSITION has no data, the error
    /// says that it is compressed (it said "count 4 is outside 1..=0", or would render zeros).
    #[test]
    fn draco_primitives_are_read_uncompressed_or_refused_for_their_compression() {
        let plain = r#"{"attributes":{"POSITION":0},"indices":1,"material":0}"#;
        let draco = r#"{"attributes":{"POSITION":0},"indices":1,"material":0,"extensions":{"KHR_draco_mesh_compression":{"bufferView":1,"attributes":{"POSITION":0}}}}"#;
        let used = quad_gltf(6).replacen(plain, draco, 1).replacen(
            r#""scene":0,"#,
            r#""scene":0,"extensionsUsed":["KHR_draco_mesh_compression"],"#,
            1,
        );
        assert!(used.contains("extensionsUsed") && used.contains(draco));
        assert_eq!(load(file(&used).path()).unwrap().triangle_count(), 2);
        let compressed_only = used.replacen(r#"{"bufferView":0,"componentType":5126"#, r#"{"componentType":5126"#, 1);
        assert_ne!(compressed_only, used);
        let err = load(file(&compressed_only).path()).unwrap_err().to_string();
        let expected = "meshes[0].primitives[0]: compressed with KHR_draco_mesh_compression, which raywave does not \
                        read, and without uncompressed data (attributes.POSITION has no bufferView)";
        assert!(err.contains(expected), "{err}");
    }

    /// `KHR_node_visibility`: a node with `"visible": false` hides its mesh and every mesh below
    /// it, whatever their own value, and its lights; its camera is still the view. A file may
    /// require the extension; a `visible` that is not a boolean is an error naming it.
    #[test]
    fn hidden_nodes_show_no_mesh_but_keep_their_camera() {
        let hidden = |visible: &str| format!(r#""extensions":{{"KHR_node_visibility":{{"visible":{visible}}}}}"#);
        let mesh_node = r#"{"mesh":0,"translation":[0,0,-2]}"#;
        let camera_node = r#"{"camera":0,"translation":[0.5,0.5,3]}"#;
        // Two copies of the quad, the second hidden (or not) by its parent, nodes[3].
        let with = |parent: &str, child: &str, camera: &str| {
            quad_gltf(6)
                .replacen(
                    &format!("[{mesh_node},{camera_node}]"),
                    &format!(
                        r#"[{mesh_node},{{"camera":0,"translation":[0.5,0.5,3]{camera}}},{{"mesh":0,"translation":[2,0,-2]{child}}},{{"children":[2]{parent}}}]"#
                    ),
                    1,
                )
                .replacen(r#""nodes":[0,1]}],"#, r#""nodes":[0,1,3]}],"#, 1)
        };
        let shown = with("", "", "");
        assert_ne!(shown, quad_gltf(6));
        assert_eq!(load(file(&shown).path()).unwrap().triangle_count(), 4);
        let off = format!(",{}", hidden("false"));
        let on = format!(",{}", hidden("true"));
        for (parent, child) in [(off.as_str(), ""), (&off, &on), ("", &off)] {
            let scene = load(file(&with(parent, child, &off)).path()).unwrap();
            assert_eq!(scene.triangle_count(), 2, "parent {parent:?}, child {child:?}");
            assert_eq!(scene.camera().position, Vec3::new(0.5, 0.5, 3.0), "a hidden node's camera is the view");
        }
        let required = shown.replacen(
            r#""scene":0,"#,
            r#""scene":0,"extensionsRequired":["KHR_node_visibility"],"extensionsUsed":["KHR_node_visibility"],"#,
            1,
        );
        assert_eq!(load(file(&required).path()).unwrap().triangle_count(), 4);

        let all_hidden =
            quad_gltf(6).replacen(mesh_node, &format!(r#"{{"mesh":0,"translation":[0,0,-2],{}}}"#, hidden("false")), 1);
        let err = load(file(&all_hidden).path()).unwrap_err().to_string();
        let expected = "its scene shows no mesh: the 1 node(s) with a mesh are hidden (KHR_node_visibility `visible: \
                        false` on them or an ancestor)";
        assert!(err.contains(expected), "{err}");
        let not_boolean = all_hidden.replacen(r#""visible":false"#, r#""visible":0"#, 1);
        let err = load(file(&not_boolean).path()).unwrap_err().to_string();
        assert!(err.contains("nodes[0].extensions.KHR_node_visibility.visible is 0, not true or false"), "{err}");
    }

    /// [`quad_gltf`]'s file with its positions stored as `component_type` (5120 `BYTE` … 5123
    /// `UNSIGNED_SHORT`), `normalized` or not, each coordinate 1 of the unit square written as
    /// `one`, in a view strided to 4-byte elements (glTF's alignment of vertex attributes), and
    /// `members` (such as `extensionsUsed`) before its `"scene"`.
    fn quantized_quad_gltf(component_type: u32, normalized: bool, one: u16, members: &str) -> String {
        let size = if component_type < 5122 { 1 } else { 2 };
        let stride = 4 * size;
        let mut data = Vec::new();
        for corner in [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]] {
            for c in corner {
                data.extend_from_slice(&(c * one).to_le_bytes()[..size]);
            }
            data.resize(data.len() + stride - 3 * size, 0);
        }
        data.extend([0u16, 1, 2, 0, 2, 3].iter().flat_map(|i| i.to_le_bytes()));
        let positions = 4 * stride;
        quad_gltf(6)
            .replacen(&base64_encode(&quad_buffer()), &base64_encode(&data), 1)
            .replacen(r#""byteLength":60"#, &format!(r#""byteLength":{}"#, data.len()), 1)
            .replacen(
                r#"{"buffer":0,"byteOffset":0,"byteLength":48}"#,
                &format!(r#"{{"buffer":0,"byteOffset":0,"byteLength":{positions},"byteStride":{stride}}}"#),
                1,
            )
            .replacen(
                r#"{"buffer":0,"byteOffset":48,"byteLength":12}"#,
                &format!(r#"{{"buffer":0,"byteOffset":{positions},"byteLength":12}}"#),
                1,
            )
            .replacen(
                r#""componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0]"#,
                &format!(
                    r#""componentType":{component_type},"normalized":{normalized},"count":4,"type":"VEC3","min":[0,0,0],"max":[{one},{one},0]"#
                ),
                1,
            )
            .replacen(r#""scene":0,"#, &format!(r#"{members}"scene":0,"#), 1)
    }

    /// Positions of `KHR_mesh_quantization` — each integer type it allows, normalized or not,
    /// in 4-byte elements, a sparse accessor's substitutions in the accessor's type, and integers
    /// dequantized by the node's scale (as gltfpack writes them) — load as the quad of `f32`
    /// ones and its light; they were refused with the extension. A file that does not list the
    /// extension gets an error saying that it allows the type, and `UNSIGNED_INT` stays refused.
    #[test]
    fn quantized_positions_load_as_the_float_quad() {
        let float = load(file(&quad_gltf(6)).path()).unwrap();
        let uses = r#""extensionsUsed":["KHR_mesh_quantization"],"extensionsRequired":["KHR_mesh_quantization"],"#;
        let loads_as_float = |text: &str, case: &str| {
            let scene = load(file(text).path()).unwrap_or_else(|e| panic!("{case}: {e}"));
            assert_eq!(scene.meshes()[0].positions, float.meshes()[0].positions, "{case}");
            assert_eq!(scene.lights(), float.lights(), "{case}");
        };
        let data_types = [(5120, DataType::I8), (5121, DataType::U8), (5122, DataType::I16), (5123, DataType::U16)];
        for (component_type, data_type) in data_types {
            loads_as_float(&quantized_quad_gltf(component_type, false, 1, uses), &format!("{data_type:?}"));
            let one = components::normalized_one(data_type).unwrap() as u16;
            loads_as_float(&quantized_quad_gltf(component_type, true, one, uses), &format!("normalized {data_type:?}"));
        }
        let node = r#"{"mesh":0,"translation":[0,0,-2]}"#;
        let scaled = quantized_quad_gltf(5123, false, 1000, uses).replacen(
            node,
            r#"{"mesh":0,"translation":[0,0,-2],"scale":[0.001,0.001,0.001]}"#,
            1,
        );
        let scene = load(file(&scaled).path()).unwrap();
        for (p, q) in scene.meshes()[0].positions.iter().zip(&float.meshes()[0].positions) {
            assert!(p.abs_diff_eq(*q, 1e-6), "dequantized by the node's scale: {p} against {q}");
        }
        // Elements 1–3 substituted (u8 indices, then u16 values) over zeros (no base view).
        let mut data: Vec<u8> = [0u16, 1, 2, 0, 2, 3].iter().flat_map(|i| i.to_le_bytes()).collect();
        data.extend([1, 2, 3, 0]);
        data.extend([1u16, 0, 0, 1, 1, 0, 0, 1, 0].iter().flat_map(|i| i.to_le_bytes()));
        let sparse = quad_gltf(6)
            .replacen(&base64_encode(&quad_buffer()), &base64_encode(&data), 1)
            .replacen(r#""byteLength":60"#, r#""byteLength":34"#, 1)
            .replacen(
                r#"{"buffer":0,"byteOffset":0,"byteLength":48}"#,
                r#"{"buffer":0,"byteOffset":16,"byteLength":18}"#,
                1,
            )
            .replacen(
                r#"{"buffer":0,"byteOffset":48,"byteLength":12}"#,
                r#"{"buffer":0,"byteOffset":0,"byteLength":12},{"buffer":0,"byteOffset":12,"byteLength":3}"#,
                1,
            )
            .replacen(
                r#"{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}"#,
                r#"{"componentType":5123,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0],"sparse":{"count":3,"indices":{"bufferView":2,"componentType":5121},"values":{"bufferView":0}}}"#,
                1,
            )
            .replacen(r#""scene":0,"#, &format!(r#"{uses}"scene":0,"#), 1);
        loads_as_float(&sparse, "sparse");
        for (text, expected) in [
            (
                quantized_quad_gltf(5123, false, 1, ""),
                "meshes[0].primitives[0].attributes.POSITION: accessor 0: holds Vec3 of U16, glTF requires Vec3 of \
                 F32 (KHR_mesh_quantization allows U16, but the file does not list it in extensionsUsed)",
            ),
            (
                quad_gltf(6)
                    .replacen(r#""componentType":5126,"count":4"#, r#""componentType":5125,"count":4"#, 1)
                    .replacen(r#""scene":0,"#, &format!(r#"{uses}"scene":0,"#), 1),
                "accessor 0: holds Vec3 of U32, glTF requires Vec3 of F32 or I8 or normalized I8 or U8 or \
                 normalized U8 or I16 or normalized I16 or U16 or normalized U16",
            ),
        ] {
            let err = load(file(&text).path()).unwrap_err().to_string();
            assert!(err.contains(expected), "{err}");
        }
        // The type is right, the dimensions are not: no word of the extension.
        let flat = quad_gltf(6).replacen(r#""count":4,"type":"VEC3""#, r#""count":4,"type":"VEC2""#, 1);
        let err = load(file(&flat).path()).unwrap_err().to_string();
        assert!(err.contains("holds Vec2 of F32, glTF requires Vec3 of F32") && !err.contains("allows"), "{err}");
    }

    /// [`quad_gltf`]'s quad with both its views compressed by `extension` (meshopt): its
    /// positions as `positions` (mode ATTRIBUTES, 4 elements of 12 bytes) and its indices as
    /// `indices` (mode `index_mode`, 6 of 2 bytes), in the embedded buffer, decoding into a
    /// placeholder without `uri` (`"fallback": true`), as `gltfpack -c` writes files.
    fn meshopt_quad_gltf(extension: &str, positions: &[u8], indices: &[u8], index_mode: &str) -> String {
        let mut data = positions.to_vec();
        data.resize(data.len().next_multiple_of(4), 0);
        let index_offset = data.len();
        data.extend(indices);
        let compressed = |offset: usize, length: usize, stride: usize, count: usize, mode: &str| {
            format!(
                r#"{{"{extension}":{{"buffer":0,"byteOffset":{offset},"byteLength":{length},"byteStride":{stride},"count":{count},"mode":"{mode}"}}}}"#
            )
        };
        let uri = |bytes: &[u8]| format!("data:application/octet-stream;base64,{}", base64_encode(bytes));
        quad_gltf(6)
            .replacen(
                r#""scene":0,"#,
                &format!(r#""extensionsUsed":["{extension}"],"extensionsRequired":["{extension}"],"scene":0,"#),
                1,
            )
            .replacen(
                &format!(r#"{{"byteLength":60,"uri":"{}"}}"#, uri(&quad_buffer())),
                &format!(
                    r#"{{"byteLength":{},"uri":"{}"}},{{"byteLength":60,"extensions":{{"{extension}":{{"fallback":true}}}}}}"#,
                    data.len(),
                    uri(&data)
                ),
                1,
            )
            .replacen(
                r#"{"buffer":0,"byteOffset":0,"byteLength":48}"#,
                &format!(
                    r#"{{"buffer":1,"byteOffset":0,"byteLength":48,"extensions":{}}}"#,
                    compressed(0, positions.len(), 12, 4, "ATTRIBUTES")
                ),
                1,
            )
            .replacen(
                r#"{"buffer":0,"byteOffset":48,"byteLength":12}"#,
                &format!(
                    r#"{{"buffer":1,"byteOffset":48,"byteLength":12,"extensions":{}}}"#,
                    compressed(index_offset, indices.len(), 2, 6, index_mode)
                ),
                1,
            )
    }

    /// Views compressed by meshopt (`EXT_meshopt_compression` with the attribute codec's
    /// version 0 and `KHR_meshopt_compression` with version 1, indices as triangles and as a
    /// sequence, positions plain and through the exponential filter), decoded by meshoptimizer
    /// into a placeholder buffer without data, load as the quad of uncompressed views; they were
    /// refused with the extension. What the extension forbids, data that does not decode or is
    /// too short for its view, and a placeholder the views overrun are errors naming the view's
    /// extension object; views that would make a small file allocate without end (a terabyte
    /// view, a view a terabyte into its placeholder, one stream shared by 1 300 views) are
    /// refused before anything is allocated.
    #[test]
    fn meshopt_compressed_views_load_as_the_uncompressed_quad() {
        let float = load(file(&quad_gltf(6)).path()).unwrap();
        let corners = [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]];
        // Version 1 of the attribute codec, meshoptimizer's default, which KHR_ defines; EXT_
        // defines version 0 alone.
        let positions = ::meshopt::encode_vertex_buffer(&corners).unwrap();
        let positions_v0 = ::meshopt::encode_vertex_buffer_level(&corners, 2, Some(0)).unwrap();
        assert_eq!((positions[0], positions_v0[0]), (0xa1, 0xa0), "the streams' headers");
        let triangles = ::meshopt::encode_index_buffer(&[0, 1, 2, 0, 2, 3], 4).unwrap();
        let sequence = ::meshopt::encode_index_sequence(&[0, 1, 2, 0, 2, 3], 4).unwrap();
        let exponential = ::meshopt::encode_filter_exp(&corners, 23, ::meshopt::EncodeExpMode::Separate);
        let exponential = ::meshopt::encode_vertex_buffer(&exponential).unwrap();
        let [ext, khr] = meshopt::EXTENSIONS;
        let cases = [
            (meshopt_quad_gltf(ext, &positions_v0, &triangles, "TRIANGLES"), "EXT, triangles"),
            (meshopt_quad_gltf(khr, &positions, &sequence, "INDICES"), "KHR, an index sequence"),
            (
                meshopt_quad_gltf(khr, &exponential, &triangles, "TRIANGLES").replacen(
                    r#""mode":"ATTRIBUTES""#,
                    r#""mode":"ATTRIBUTES","filter":"EXPONENTIAL""#,
                    1,
                ),
                "the exponential filter",
            ),
        ];
        for (text, case) in cases {
            let scene = load(file(&text).path()).unwrap_or_else(|e| panic!("{case}: {e}"));
            assert_eq!(scene.meshes()[0].positions, float.meshes()[0].positions, "{case}");
            assert_eq!(scene.lights(), float.lights(), "{case}");
        }
        let mut broken = positions.clone();
        broken[0] = 0;
        let text = meshopt_quad_gltf(ext, &positions, &triangles, "TRIANGLES");
        let field = "bufferViews[0].extensions.EXT_meshopt_compression";
        for (text, expected) in [
            (
                meshopt_quad_gltf(ext, &broken, &triangles, "TRIANGLES"),
                format!("{field}: its {} bytes of compressed data do not decode as ATTRIBUTES", positions.len()),
            ),
            (
                text.replacen(r#""count":4"#, r#""count":5"#, 1),
                format!("{field}: count 5 times byteStride 12 is not the view's byteLength 48"),
            ),
            (
                text.replacen(r#""mode":"ATTRIBUTES""#, r#""mode":"ATTRIBUTES","filter":"QUATERNION""#, 1),
                format!(
                    "{field}: byteStride 12 is not one the extension allows for mode ATTRIBUTES and filter QUATERNION"
                ),
            ),
            (
                text.replacen(r#""mode":"TRIANGLES""#, r#""mode":"TRIANGLES","filter":"OCTAHEDRAL""#, 1),
                "bufferViews[1].extensions.EXT_meshopt_compression: mode TRIANGLES takes no filter".to_owned(),
            ),
            (text.replacen(r#","mode":"ATTRIBUTES""#, "", 1), format!("{field}.mode: missing")),
            (
                text.replacen(r#""mode":"ATTRIBUTES""#, r#""mode":"VERTICES""#, 1),
                format!(r#"{field}.mode is "VERTICES", not one of ATTRIBUTES, TRIANGLES, INDICES"#),
            ),
            (
                text.replacen(r#"{"byteLength":60,"extensions""#, r#"{"byteLength":50,"extensions""#, 1),
                format!("{field}: buffers[1] is made of decoded views up to byte 60, past its byteLength 50"),
            ),
            (
                // Decoded into the buffer that holds the compressed data (loaded), from none of it.
                text.replacen(
                    r#"{"buffer":1,"byteOffset":0,"byteLength":48,"#,
                    r#"{"buffer":0,"byteOffset":0,"byteLength":48,"#,
                    1,
                )
                .replacen(
                    &format!(r#""byteOffset":0,"byteLength":{},"byteStride":12"#, positions.len()),
                    r#""byteOffset":0,"byteLength":0,"byteStride":12"#,
                    1,
                ),
                format!(
                    "{field}: 0 bytes of compressed data cannot decode to the view's 48 (at most 1024 bytes per byte)"
                ),
            ),
            (
                // A terabyte placeholder for a terabyte view whose data is said to be a gigabyte:
                // refused before anything is allocated (the test process had aborted).
                text.replacen(r#"{"byteLength":60,"extensions""#, r#"{"byteLength":1099511627776,"extensions""#, 1)
                    .replacen(r#""byteOffset":0,"byteLength":48,"#, r#""byteOffset":0,"byteLength":1099511627776,"#, 1)
                    .replacen(
                        &format!(r#""byteOffset":0,"byteLength":{},"byteStride":12,"count":4"#, positions.len()),
                        r#""byteOffset":0,"byteLength":1073741824,"byteStride":4,"count":274877906944"#,
                        1,
                    ),
                format!("{field}: its compressed data (buffer 0, bytes 0+1073741824) lies outside that buffer"),
            ),
            (
                // The view a terabyte into a placeholder that large.
                text.replacen(r#"{"byteLength":60,"extensions""#, r#"{"byteLength":2199023255552,"extensions""#, 1)
                    .replacen(
                        r#""byteOffset":0,"byteLength":48,"#,
                        r#""byteOffset":1099511627776,"byteLength":48,"#,
                        1,
                    ),
                "into placeholder buffers of 1099511627824, more than 1024 bytes per byte".to_owned(),
            ),
            (shared_stream_views(&text, 1300), "its compressed buffer views decode to 62460 bytes".to_owned()),
        ] {
            let err = load(file(&text).path()).unwrap_err().to_string();
            assert!(err.contains(&expected), "expected {expected:?} in {err}");
        }
        // As many sharing views as the bound allows load.
        load(file(&shared_stream_views(&text, 1000)).path()).unwrap();
    }

    /// [`meshopt_quad_gltf`]'s `text` with `views` more accessors, each on a view of its own whose
    /// compressed data is the positions' stream: one stream decoded `views` times over.
    fn shared_stream_views(text: &str, views: usize) -> String {
        let position_view = r#"{"buffer":1,"byteOffset":0,"byteLength":48,"extensions":"#;
        let start = text.find(position_view).unwrap();
        let end = start + text[start..].find("}}}").unwrap() + 3;
        let view = &text[start..end];
        let extra_views: String = (0..views).map(|_| format!(",{view}")).collect();
        let extra_accessors: String = (0..views)
            .map(|k| format!(r#",{{"bufferView":{},"componentType":5126,"count":4,"type":"VEC3"}}"#, k + 2))
            .collect();
        let mut edited = text.to_owned();
        let accessors_close = edited.rfind(']').unwrap();
        edited.insert_str(accessors_close, &extra_accessors);
        let views_close = edited[..edited.find(r#""accessors""#).unwrap()].rfind(']').unwrap();
        edited.insert_str(views_close, &extra_views);
        edited
    }

    /// A scene that places no mesh says so (it was refused for having no triangles of non-zero
    /// area, "0 zero-area triangles dropped").
    #[test]
    fn a_scene_that_places_no_mesh_is_an_error_saying_so() {
        let camera_only = quad_gltf(6).replacen(r#""nodes":[0,1]}],"#, r#""nodes":[1]}],"#, 1);
        assert_ne!(camera_only, quad_gltf(6));
        let err = load(file(&camera_only).path()).unwrap_err().to_string();
        assert!(err.contains("its scene places no mesh: none of its nodes, nor their children, has `mesh`"), "{err}");
    }

    /// Punctual lights (`KHR_lights_punctual`), which raywave does not render, are counted per
    /// node of the scene that places one (they had vanished without a word).
    #[test]
    fn punctual_lights_are_counted() {
        let lights = r#""extensionsUsed":["KHR_lights_punctual"],"extensions":{"KHR_lights_punctual":{"lights":[{"type":"point","intensity":100},{"type":"directional"}]}},"#;
        let text = quad_gltf(6).replacen(r#""scene":0,"#, &format!(r#""scene":0,{lights}"#), 1).replacen(
            r#"{"camera":0,"translation":[0.5,0.5,3]}]"#,
            r#"{"camera":0,"translation":[0.5,0.5,3]},{"extensions":{"KHR_lights_punctual":{"light":0}}},{"extensions":{"KHR_lights_punctual":{"light":1}}},{"extensions":{"KHR_lights_punctual":{"light":0}}}]"#,
            1,
        ).replacen(r#""nodes":[0,1]}],"#, r#""nodes":[0,1,2,3]}],"#, 1);
        let scene = load(file(&text).path()).unwrap();
        assert_eq!(scene.unrendered().punctual_lights, 2, "two of the three light nodes are in the scene");
        assert_eq!(load(file(&quad_gltf(6)).path()).unwrap().unrendered().punctual_lights, 0);
    }

    /// Unlit materials (`KHR_materials_unlit`), an extension a file may use without requiring it,
    /// are counted (they had been rendered lit without a word).
    #[test]
    fn unlit_materials_are_counted() {
        let material = r#""emissiveFactor":[1,0.5,0]}"#;
        let unlit = quad_gltf(6).replacen(
            material,
            r#""emissiveFactor":[1,0.5,0],"extensions":{"KHR_materials_unlit":{}}}"#,
            1,
        );
        assert_ne!(unlit, quad_gltf(6));
        assert_eq!(load(file(&unlit).path()).unwrap().unrendered().unlit_meshes, 1);
        assert_eq!(load(file(&quad_gltf(6)).path()).unwrap().unrendered(), Unrendered::default());
    }

    /// [`quad_gltf`] whose mesh node places the quad by `EXT_mesh_gpu_instancing` with
    /// `attributes` (JSON), beside a second buffer holding `data`: `views` and `accessors` (JSON,
    /// each starting with a comma) follow the file's own, so the first of each is index 2.
    fn gpu_instanced_quad(attributes: &str, data: &[u8], views: &str, accessors: &str) -> String {
        let quad_data = format!(r#"{}"}}],"#, base64_encode(&quad_buffer()));
        let buffers = format!(
            r#"{}"}},{{"byteLength":{},"uri":"data:application/octet-stream;base64,{}"}}],"#,
            base64_encode(&quad_buffer()),
            data.len(),
            base64_encode(data)
        );
        let node = r#"{"mesh":0,"translation":[0,0,-2]}"#;
        let instanced = format!(
            r#"{{"mesh":0,"translation":[0,0,-2],"extensions":{{"EXT_mesh_gpu_instancing":{{"attributes":{attributes}}}}}}}"#
        );
        let last_view = r#"{"buffer":0,"byteOffset":48,"byteLength":12}"#;
        let text = quad_gltf(6)
            .replacen(node, &instanced, 1)
            .replacen(r#""scene":0,"#, r#""scene":0,"extensionsUsed":["EXT_mesh_gpu_instancing"],"#, 1)
            .replacen(&quad_data, &buffers, 1)
            .replacen(last_view, &format!("{last_view}{views}"), 1)
            .replacen(r#""type":"SCALAR"}]"#, &format!(r#""type":"SCALAR"}}{accessors}]"#), 1);
        assert!(text.contains(&instanced) && text.contains(&buffers), "{text}");
        text
    }

    /// Little-endian bytes of `values`, each `f32`.
    fn f32_bytes(values: &[f32]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    /// Three instances' TRANSLATION, SCALE and ROTATION (as `f32`), for [`gpu_instanced_quad`]:
    /// the quad as it is; turned 90° about z, doubled and moved 5 along x; turned 180° about y,
    /// mirrored in x and moved to (0, 3, 1) — in the node's space, moved by its (0, 0, −2).
    const INSTANCE_TRANSLATIONS: [f32; 9] = [0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 3.0, 1.0];
    const INSTANCE_SCALES: [f32; 9] = [1.0, 1.0, 1.0, 2.0, 2.0, 2.0, -1.0, 1.0, 1.0];
    const INSTANCE_ROTATIONS: [f32; 12] = [
        0.0,
        0.0,
        0.0,
        1.0,
        0.0,
        0.0,
        std::f32::consts::FRAC_1_SQRT_2,
        std::f32::consts::FRAC_1_SQRT_2,
        0.0,
        1.0,
        0.0,
        0.0,
    ];

    /// The views (from byte 0 of the second buffer) and accessors of the translations, scales and
    /// rotations [`INSTANCE_TRANSLATIONS`]… hold, the rotations as `component_type` (5126 `f32`,
    /// 5122 normalized `i16`, 5120 normalized `i8`), after the buffer that holds them.
    fn instance_accessors(component_type: u32) -> (Vec<u8>, String, String) {
        let mut data = f32_bytes(&INSTANCE_TRANSLATIONS);
        data.extend(f32_bytes(&INSTANCE_SCALES));
        let rotations: Vec<u8> = match component_type {
            5126 => f32_bytes(&INSTANCE_ROTATIONS),
            5122 => INSTANCE_ROTATIONS.iter().flat_map(|c| ((c * 32767.0).round() as i16).to_le_bytes()).collect(),
            _ => INSTANCE_ROTATIONS.iter().map(|c| (c * 127.0).round() as i8 as u8).collect(),
        };
        let normalized = if component_type == 5126 { "" } else { r#","normalized":true"# };
        let views = format!(
            r#",{{"buffer":1,"byteLength":36}},{{"buffer":1,"byteOffset":36,"byteLength":36}},{{"buffer":1,"byteOffset":72,"byteLength":{}}}"#,
            rotations.len()
        );
        let accessors = format!(
            r#",{{"bufferView":2,"componentType":5126,"count":3,"type":"VEC3"}},{{"bufferView":3,"componentType":5126,"count":3,"type":"VEC3"}},{{"bufferView":4,"componentType":{component_type}{normalized},"count":3,"type":"VEC4"}}"#
        );
        data.extend(rotations);
        (data, views, accessors)
    }

    /// A node with `EXT_mesh_gpu_instancing` places its mesh at each instance, `node · T · R · S`
    /// (the extension's order), with rotations as `f32`, normalized `i16` and normalized `i8`
    /// (the last rounded 0.4 % off unit length); a mirroring instance's lamp still emits from its
    /// front face; the primitive is read once. It had been drawn once, at the node.
    #[test]
    fn gpu_instances_place_the_mesh_at_each_instance() {
        let attributes = r#"{"TRANSLATION":2,"SCALE":3,"ROTATION":4}"#;
        let corners = |points: &[Vec3]| {
            let mut sorted: Vec<[i32; 3]> =
                points.iter().map(|p| p.to_array().map(|c| (c * 1e4).round() as i32)).collect();
            sorted.sort_unstable();
            sorted
        };
        let expected = [
            [[0.0, 0.0, -2.0], [1.0, 0.0, -2.0], [1.0, 1.0, -2.0], [0.0, 1.0, -2.0]],
            [[5.0, 0.0, -2.0], [5.0, 2.0, -2.0], [3.0, 2.0, -2.0], [3.0, 0.0, -2.0]],
            [[0.0, 3.0, -1.0], [1.0, 3.0, -1.0], [1.0, 4.0, -1.0], [0.0, 4.0, -1.0]],
        ]
        .map(|quad| corners(&quad.map(Vec3::from)));
        for component_type in [5126, 5122, 5120] {
            let (data, views, accessors) = instance_accessors(component_type);
            PRIMITIVE_READS.with(|reads| reads.set(0));
            let scene = load(file(&gpu_instanced_quad(attributes, &data, &views, &accessors)).path()).unwrap();
            assert_eq!(PRIMITIVE_READS.with(std::cell::Cell::get), 1, "the primitive read once");
            let placed: Vec<_> = scene.meshes().iter().map(|mesh| corners(&mesh.positions)).collect();
            assert_eq!(placed, expected, "rotations of component type {component_type}");
            let facings: Vec<Vec3> = scene.lights().iter().map(|light| facing(light).round()).collect();
            assert_eq!(facings, [Vec3::Z, Vec3::Z, Vec3::NEG_Z], "rotations of component type {component_type}");
        }
    }

    /// Instance rotations compressed by meshopt through its quaternion filter (as the KHR
    /// extension suggests for `EXT_mesh_gpu_instancing`), decoded over their view's own bytes
    /// (zeros here), place the instances as the uncompressed normalized `i16` rotations do, within
    /// the filter's 16-bit rounding.
    #[test]
    fn meshopt_quaternion_rotations_place_the_instances() {
        let attributes = r#"{"TRANSLATION":2,"SCALE":3,"ROTATION":4}"#;
        let (plain_data, plain_views, plain_accessors) = instance_accessors(5122);
        let plain = load(file(&gpu_instanced_quad(attributes, &plain_data, &plain_views, &plain_accessors)).path());
        let (mut data, views, accessors) = instance_accessors(5122);
        data[72..96].fill(0);
        let rotations: Vec<[f32; 4]> = INSTANCE_ROTATIONS.chunks_exact(4).map(|q| [q[0], q[1], q[2], q[3]]).collect();
        let compressed = ::meshopt::encode_vertex_buffer(&::meshopt::encode_filter_quat(&rotations, 16)).unwrap();
        let offset = data.len();
        data.extend(&compressed);
        let rotation_view = r#"{"buffer":1,"byteOffset":72,"byteLength":24}"#;
        assert!(views.contains(rotation_view), "{views}");
        let views = views.replacen(
            rotation_view,
            &format!(
                r#"{{"buffer":1,"byteOffset":72,"byteLength":24,"extensions":{{"EXT_meshopt_compression":{{"buffer":1,"byteOffset":{offset},"byteLength":{},"byteStride":8,"count":3,"mode":"ATTRIBUTES","filter":"QUATERNION"}}}}}}"#,
                compressed.len()
            ),
            1,
        );
        let text = gpu_instanced_quad(attributes, &data, &views, &accessors).replacen(
            r#""extensionsUsed":["EXT_mesh_gpu_instancing"]"#,
            r#""extensionsUsed":["EXT_mesh_gpu_instancing","EXT_meshopt_compression"]"#,
            1,
        );
        let (scene, plain) = (load(file(&text).path()).unwrap(), plain.unwrap());
        assert_eq!(scene.meshes().len(), 3);
        for (mesh, plain_mesh) in scene.meshes().iter().zip(plain.meshes()) {
            for (p, q) in mesh.positions.iter().zip(&plain_mesh.positions) {
                assert!(p.abs_diff_eq(*q, 1e-3), "{p} against {q}");
            }
        }
    }

    /// Instancing without a transform attribute: a custom `_ID` alone sets the count (each
    /// instance at the node), an extension without `attributes` draws the mesh once; a file may
    /// require the extension (the `gltf` crate refused it as unknown).
    #[test]
    fn gpu_instancing_counts_custom_attributes_and_may_be_required() {
        let (data, views, accessors) = instance_accessors(5126);
        let ids = gpu_instanced_quad(r#"{"_ID":2}"#, &data, &views, &accessors);
        assert_eq!(load(file(&ids).path()).unwrap().meshes().len(), 3);
        let unsaid = ids.replacen(r#"{"attributes":{"_ID":2}}"#, "{}", 1);
        assert_ne!(unsaid, ids);
        assert_eq!(load(file(&unsaid).path()).unwrap().meshes().len(), 1);
        let required =
            ids.replacen(r#""scene":0,"#, r#""scene":0,"extensionsRequired":["EXT_mesh_gpu_instancing"],"#, 1);
        assert_ne!(required, ids);
        assert_eq!(load(file(&required).path()).unwrap().meshes().len(), 3);
    }

    /// Bad instancing is refused naming the node's extension field (or the accessor's): each
    /// case a substitution in the three-instance file of [`instance_accessors`].
    #[test]
    fn bad_gpu_instancing_names_the_field() {
        let field = "nodes[0].extensions.EXT_mesh_gpu_instancing.attributes";
        let attributes = r#"{"TRANSLATION":2,"SCALE":3,"ROTATION":4}"#;
        let translation_accessor = r#"{"bufferView":2,"componentType":5126,"count":3,"type":"VEC3"}"#;
        let rotation_accessor = r#"{"bufferView":4,"componentType":5126,"count":3,"type":"VEC4"}"#;
        let huge = f32::to_le_bytes(1e9);
        let nan = f32::to_le_bytes(f32::NAN);
        let two = f32::to_le_bytes(2.0);
        // Bytes to overwrite in the file's data, at an offset.
        type Overwrite = Option<(usize, [u8; 4])>;
        // (what is replaced, by what, the bytes overwritten, the error)
        let cases: [(&str, &str, Overwrite, String); 9] = [
            (attributes, "{}", None, format!("{field}: empty; the extension requires at least one attribute")),
            (attributes, "[2]", None, format!("{field}: not an object of accessor indices")),
            (attributes, r#"{"TRANSLATION":9}"#, None, format!("{field}.TRANSLATION: 9 is not the index of an accessor")),
            (attributes, r#"{"TRANSLATION":-1}"#, None, format!("{field}.TRANSLATION: -1 is not the index of an accessor")),
            (
                r#"{"bufferView":3,"componentType":5126,"count":3,"#,
                r#"{"bufferView":3,"componentType":5126,"count":2,"#,
                None,
                format!("{field}.SCALE: accessor 3 has 2 elements, attributes.ROTATION 3; the extension requires one count"),
            ),
            (
                translation_accessor,
                r#"{"bufferView":2,"componentType":5126,"count":3,"type":"VEC4"}"#,
                None,
                format!("{field}.TRANSLATION: accessor 2: holds Vec4 of F32, glTF requires Vec3 of F32"),
            ),
            (
                rotation_accessor,
                r#"{"bufferView":4,"componentType":5122,"count":3,"type":"VEC4"}"#,
                None,
                format!(
                    "{field}.ROTATION: accessor 4: holds Vec4 of I16, glTF requires Vec4 of F32 or normalized I8 or \
                     normalized I16"
                ),
            ),
            (
                "",
                "",
                Some((72 + 12, two)),
                format!("{field}.ROTATION: element 0 is [0.0, 0.0, 0.0, 2.0], 2 long; the extension requires a unit quaternion"),
            ),
            ("", "", Some((36 + 12, nan)), format!("{field}.SCALE: element 1 is [NaN, 2, 2]; each component must be finite")),
        ];
        for (from, to, bytes, expected) in cases.into_iter().chain([(
            "",
            "",
            Some((0, huge)),
            "element 0 is at [1000000000, 0, -2] in world space under nodes[0]'s instance 0 (EXT_mesh_gpu_instancing)'s \
             transform"
                .to_owned(),
        )]) {
            let (mut data, views, accessors) = instance_accessors(5126);
            if let Some((at, value)) = bytes {
                data[at..at + 4].copy_from_slice(&value);
            }
            let text = gpu_instanced_quad(attributes, &data, &views, &accessors);
            assert!(text.contains(from), "{from}");
            match load(file(&text.replacen(from, to, 1)).path()) {
                Err(err @ Error::SceneLoad { .. }) => assert!(err.to_string().contains(&expected), "{to}: {err}"),
                other => panic!("{to}: expected a SceneLoad error containing {expected:?}, got {other:?}"),
            }
        }
    }

    /// raywave renders no orthographic projection: a file whose cameras are all orthographic is
    /// framed as one without a camera, which the scene notes (it was silent); beside a
    /// perspective camera, an orthographic one changes nothing.
    #[test]
    fn an_orthographic_camera_is_skipped_and_noted() {
        let orthographic = r#"{"type":"orthographic","orthographic":{"xmag":1,"ymag":1,"znear":0.01,"zfar":10}}"#;
        let perspective = r#"{"type":"perspective","perspective":{"yfov":0.8,"znear":0.01}}"#;
        let only = quad_gltf(6).replacen(perspective, orthographic, 1);
        assert_ne!(only, quad_gltf(6));
        let scene = load(file(&only).path()).unwrap();
        assert!(scene.unrendered().orthographic_camera);
        assert_eq!(*scene.camera(), framing_camera(scene.meshes()));
        // cameras[0] orthographic on a new node 2, met first; cameras[1] perspective on node 1.
        let both = quad_gltf(6)
            .replacen(perspective, &format!("{orthographic},{perspective}"), 1)
            .replacen(
                r#"{"camera":0,"translation":[0.5,0.5,3]}]"#,
                r#"{"camera":1,"translation":[0.5,0.5,3]},{"camera":0}]"#,
                1,
            )
            .replacen(r#""nodes":[0,1]}],"#, r#""nodes":[2,0,1]}],"#, 1);
        let scene = load(file(&both).path()).unwrap();
        assert!(!scene.unrendered().orthographic_camera);
        assert_eq!(scene.camera().position, Vec3::new(0.5, 0.5, 3.0));
        assert!(!load(file(&quad_gltf(6)).path()).unwrap().unrendered().orthographic_camera);
    }

    /// [`quad_gltf`] with its mesh and camera nodes under a root node of `transform` (JSON members).
    fn quad_gltf_under(transform: &str) -> String {
        let text = quad_gltf(6).replacen(r#""nodes":[0,1]}],"#, r#""nodes":[2]}],"#, 1).replacen(
            r#"{"camera":0,"translation":[0.5,0.5,3]}]"#,
            &format!(r#"{{"camera":0,"translation":[0.5,0.5,3]}},{{{transform},"children":[0,1]}}]"#),
            1,
        );
        assert_ne!(text, quad_gltf(6));
        text
    }

    /// A scene and its camera under a mirroring root (`scale: [1, 1, −1]`, as converters add):
    /// the image's right axis is the camera node's world +x, the mirror of the plain scene's, so
    /// each pixel's ray is the mirror of the plain scene's ray for that pixel and sees the same
    /// (mirrored) triangle — the image is the plain one, where it had come out left-right flipped.
    #[test]
    fn a_mirrored_scene_and_camera_render_the_plain_image() {
        use crate::backend::Backend;
        let plain = load(file(&quad_gltf_under(r#""scale":[1,1,1]"#)).path()).unwrap();
        let mirrored = load(file(&quad_gltf_under(r#""scale":[1,1,-1]"#)).path()).unwrap();
        assert!(!plain.camera().mirrored && mirrored.camera().mirrored);
        let mirror = Vec3::new(1.0, 1.0, -1.0);
        let (p, m) =
            (crate::frame::generate_params(&plain, 16, 12, 0), crate::frame::generate_params(&mirrored, 16, 12, 0));
        // World +x of the camera node is +x either way: `right` is along it.
        for params in [p, m] {
            assert!(params.right.truncate().normalize().abs_diff_eq(Vec3::X, 1e-6), "{}", params.right);
        }
        for (a, b) in [(p.forward, m.forward), (p.right, m.right), (p.up, m.up), (p.origin, m.origin)] {
            assert!((a.truncate() * mirror).abs_diff_eq(b.truncate(), 1e-6), "{a} against {b}");
        }
        let hits = |scene: &Scene, params| {
            let mut cpu = crate::cpu::CpuBackend::new();
            cpu.load_scene(scene).unwrap();
            let (rays, _) = cpu.generate(&params).unwrap();
            let (hits, _) = cpu.trace(&rays).unwrap();
            (hits.instance, hits.primitive)
        };
        let (plain_hits, mirrored_hits) = (hits(&plain, p), hits(&mirrored, m));
        assert!(plain_hits.0.contains(&0) && plain_hits.0.iter().any(|&i| i != 0), "{plain_hits:?}");
        assert_eq!(plain_hits, mirrored_hits);
    }

    /// The scene and its camera under a root scale of 0.01 (and a root translation of 3000, far from
    /// the origin), the camera 300 local units from the quad: the camera looks at the point along
    /// its view at the depth of the quad's centre, about 3 away, which is the default focus
    /// distance (it had been one local unit, 0.01), and its view direction, turned 0.3 rad about y
    /// and 0.2 about x, is the node's within 10⁻⁴ rad (the look-at point's rounding near 3000,
    /// 1.2·10⁻⁴ per axis, over 3; taken from two points 0.01 apart it was 3.2·10⁻³ off).
    /// A camera past the scene's centre looks half the bounds' radius ahead.
    #[test]
    fn a_gltf_camera_looks_and_focuses_at_the_depth_of_the_scene_centre() {
        use glam::{DQuat, Vec4Swizzles};
        let (ay, ax) = (0.3f64, 0.2f64);
        let turn = DQuat::from_rotation_y(ay) * DQuat::from_rotation_x(ax);
        let [x, y, z, w] = turn.to_array();
        let camera_node = format!(r#"{{"camera":0,"translation":[0.5,0.5,300],"rotation":[{x},{y},{z},{w}]}}"#);
        let text = quad_gltf_under(r#""translation":[3000,0,0],"scale":[0.01,0.01,0.01]"#).replacen(
            r#"{"camera":0,"translation":[0.5,0.5,3]}"#,
            &camera_node,
            1,
        );
        let scene = load(file(&text).path()).unwrap();
        let camera = *scene.camera();
        let forward = turn * DVec3::NEG_Z;
        let centre = DVec3::new(3000.005, 0.005, -0.02);
        let depth = (centre - camera.position.as_dvec3()).dot(forward);
        let params = crate::frame::generate_params(&scene, 16, 12, 0);
        assert!(
            (f64::from(params.focus_distance) / depth - 1.0).abs() < 1e-3,
            "{} against {depth}",
            params.focus_distance
        );
        assert!((depth - 3.0).abs() < 0.5, "{depth}");
        let angle = params.forward.xyz().as_dvec3().angle_between(forward);
        assert!(angle < 1e-4, "the view is {angle} rad off");
        // Past the centre, near the origin: the quad spans 0.01 (radius 0.0071) around z = −0.02.
        let inside = quad_gltf_under(r#""scale":[0.01,0.01,0.01]"#).replacen(
            r#"{"camera":0,"translation":[0.5,0.5,3]}"#,
            r#"{"camera":0,"translation":[0.5,0.5,-2.5]}"#,
            1,
        );
        let params = crate::frame::generate_params(&load(file(&inside).path()).unwrap(), 16, 12, 0);
        let half_radius = 0.5 * 0.5 * 0.01 * 2f32.sqrt();
        assert!((params.focus_distance / half_radius - 1.0).abs() < 1e-3, "{}", params.focus_distance);
    }

    #[test]
    fn the_first_camera_in_document_order_is_the_scene_camera() {
        // Two camera nodes: the first root, then a child of the second root (the mesh its other).
        let text = quad_gltf(6).replacen(r#""nodes":[0,1]}],"#, r#""nodes":[1,2]}],"#, 1).replacen(
            r#"{"camera":0,"translation":[0.5,0.5,3]}]"#,
            r#"{"camera":0,"translation":[0.5,0.5,3]},{"children":[3,0]},{"camera":0,"translation":[0,0,9]}]"#,
            1,
        );
        let f = file(&text);
        let scene = load(f.path()).unwrap();
        assert_eq!(scene.camera().position, Vec3::new(0.5, 0.5, 3.0));
    }

    #[test]
    fn sparse_indices_past_the_count_or_out_of_order_are_errors() {
        // quad_gltf's index view holds the u16 indices 0, 1, 2, 0, 2, 3: as 3 sparse indices
        // (0, 1, 2) of a 4-element accessor they are valid, and from the view's 4th index on
        // (0, 2, 3) too; of a 3-element accessor, 3 is past the end; from the 3rd index on
        // (2, 0, 2) they are out of order.
        let sparse = |count: u32, byte_offset: u32| {
            quad_gltf(6).replacen(
                r#"{"bufferView":0,"componentType":5126,"count":4"#,
                &format!(
                    r#"{{"componentType":5126,"count":{count},"sparse":{{"count":3,"indices":{{"bufferView":1,"byteOffset":{byte_offset},"componentType":5123}},"values":{{"bufferView":0}}}}"#
                ),
                1,
            )
        };
        assert!(load(file(&sparse(4, 0)).path()).is_ok());
        assert!(load(file(&sparse(4, 6)).path()).is_ok());
        for (count, offset, expected) in [(3, 6, "index 2 is 3"), (4, 4, "index 1 is 0")] {
            let err = load(file(&sparse(count, offset)).path()).unwrap_err().to_string();
            assert!(err.contains("sparse.indices: index") && err.contains(expected), "{err}");
        }
        // Indices one byte into their view: u16s read across their bytes, once refused (or not)
        // for what that gave.
        let err = load(file(&sparse(4, 1)).path()).unwrap_err().to_string();
        assert!(err.contains("sparse.indices: byteOffset 1 (byte 49 of its buffer"), "{err}");
        // A strided index view, which glTF 2.0 forbids for sparse data: the check read the
        // indices packed (0, 1, 2: valid), the reader strided (0, 2, 2: never checked).
        let strided = sparse(4, 0).replacen(r#""byteLength":12}"#, r#""byteLength":12,"byteStride":4}"#, 1);
        let err = load(file(&strided).path()).unwrap_err().to_string();
        assert!(err.contains("sparse.indices: bufferViews[1] has byteStride 4, which glTF 2.0 forbids"), "{err}");
    }

    #[test]
    fn meshes_with_textures_are_counted() {
        assert_eq!(load(file(&quad_gltf(6)).path()).unwrap().unrendered().textured_meshes, 0);
        let textures = r#""scene":0,"textures":[{"source":0}],"images":[{"uri":"no_such_texture.png"}],"#;
        // The mesh's material (index 0) is a new one with a texture, ahead of the file's own.
        for texture in
            [r#""emissiveTexture":{"index":0},"#, r#""pbrMetallicRoughness":{"baseColorTexture":{"index":0}},"#]
        {
            let text = quad_gltf(6).replacen(r#""scene":0,"#, textures, 1).replacen(
                r#""materials":[{"pbrMetallicRoughness""#,
                &format!(r#""materials":[{{{texture}"extras":{{}}}},{{"pbrMetallicRoughness""#),
                1,
            );
            let scene = load(file(&text).path()).unwrap_or_else(|e| panic!("{texture}: {e}"));
            assert_eq!(scene.unrendered().textured_meshes, 1, "{texture}");
        }
        // Vertex colours (here the positions' numbers: black to white), which glTF multiplies
        // into the base colour: a viewer shades the quad from black to its colour, and raywave
        // counts it.
        let coloured = quad_gltf(6).replacen(r#""POSITION":0"#, r#""POSITION":0,"COLOR_0":2"#, 1).replacen(
            r#""type":"SCALAR"}"#,
            r#""type":"SCALAR"},{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3"}"#,
            1,
        );
        let scene = load(file(&coloured).path()).unwrap();
        assert_eq!(scene.unrendered().textured_meshes, 1, "{coloured}");
        // A file that requires the extensions of its textures (here a KTX2 image, as
        // `gltfpack -tc` writes, and a transform), which raywave does not sample: it loads, its
        // textured mesh counted; it had been refused for requiring them.
        let required = quad_gltf(6)
            .replacen(
                r#""scene":0,"#,
                r#""extensionsUsed":["KHR_texture_basisu","KHR_texture_transform"],"extensionsRequired":["KHR_texture_basisu","KHR_texture_transform"],"scene":0,"textures":[{"extensions":{"KHR_texture_basisu":{"source":0}}}],"images":[{"uri":"no_such_texture.ktx2","mimeType":"image/ktx2"}],"#,
                1,
            )
            .replacen(
                r#""materials":[{"pbrMetallicRoughness":{"#,
                r#""materials":[{"pbrMetallicRoughness":{"baseColorTexture":{"index":0,"extensions":{"KHR_texture_transform":{"scale":[2,2]}}},"#,
                1,
            );
        let scene = load(file(&required).path()).unwrap_or_else(|e| panic!("{required}: {e}"));
        assert_eq!(scene.unrendered().textured_meshes, 1);
    }

    #[test]
    fn see_through_materials_are_counted() {
        // The quad's material with (its base colour, its alpha mode and cutoff), and whether it
        // is see-through: OPAQUE ignores alpha; MASK cuts below alphaCutoff (0.5 unless given).
        let material = r#"{"pbrMetallicRoughness":{"baseColorFactor":[0.5,0.25,1,1],"metallicFactor":0.5,"roughnessFactor":0.3},"emissiveFactor":[1,0.5,0]}"#;
        // Transmission (Blender's glass), in an extension the file uses without requiring it:
        // its factor defaults to 0; a texture's values are not read.
        let transmission = |extension: &str| format!(r#","extensions":{{"KHR_materials_transmission":{extension}}}"#);
        let [transmits, opaque, by_default, textured] = [
            r#"{"transmissionFactor":1}"#,
            r#"{"transmissionFactor":0}"#,
            "{}",
            r#"{"transmissionTexture":{"index":0}}"#,
        ]
        .map(transmission);
        for (colour, mode, see_through) in [
            (r#""baseColorFactor":[1,1,1,0.2]"#, "", false),
            (r#""baseColorFactor":[1,1,1,0.9]"#, r#","alphaMode":"BLEND""#, true),
            (r#""baseColorFactor":[1,1,1,1]"#, r#","alphaMode":"BLEND""#, false),
            (r#""baseColorTexture":{"index":0}"#, r#","alphaMode":"BLEND""#, true),
            (r#""baseColorTexture":{"index":0}"#, "", false),
            (r#""baseColorFactor":[1,1,1,0.4]"#, r#","alphaMode":"MASK""#, true),
            (r#""baseColorFactor":[1,1,1,0.6]"#, r#","alphaMode":"MASK""#, false),
            (r#""baseColorFactor":[1,1,1,0.6]"#, r#","alphaMode":"MASK","alphaCutoff":0.7"#, true),
            (r#""baseColorFactor":[1,1,1,1]"#, transmits.as_str(), true),
            (r#""baseColorFactor":[1,1,1,1]"#, opaque.as_str(), false),
            (r#""baseColorFactor":[1,1,1,1]"#, by_default.as_str(), false),
            (r#""baseColorFactor":[1,1,1,1]"#, textured.as_str(), true),
        ] {
            let edited = format!(r#"{{"pbrMetallicRoughness":{{{colour}}}{mode}}}"#);
            let text = quad_gltf(6).replacen(material, &edited, 1).replacen(
                r#""scene":0,"#,
                r#""scene":0,"textures":[{"source":0}],"images":[{"uri":"t.png"}],"#,
                1,
            );
            assert!(text.contains(&edited), "{edited}");
            let scene = load(file(&text).path()).unwrap_or_else(|e| panic!("{edited}: {e}"));
            assert_eq!(scene.unrendered().see_through_meshes, usize::from(see_through), "{edited}");
        }
    }

    #[test]
    fn skinned_and_morphed_meshes_are_counted_and_required_extensions_refused() {
        let node = r#"{"mesh":0,"translation":[0,0,-2]}"#;
        let primitive = r#"{"attributes":{"POSITION":0},"indices":1,"material":0}"#;
        let targets = r#"{"attributes":{"POSITION":0},"indices":1,"material":0,"targets":[{"POSITION":0}]}"#;
        // (node edit, primitive edit, mesh weights, deformed): a skin; morph targets weighted by
        // the mesh, unless the node's weights override them with 0; targets without weights.
        for (node_edit, primitive_edit, mesh_weights, deformed) in [
            (r#"{"mesh":0,"translation":[0,0,-2],"skin":0}"#, primitive, "", true),
            (node, targets, r#""weights":[0.5],"#, true),
            (r#"{"mesh":0,"translation":[0,0,-2],"weights":[0]}"#, targets, r#""weights":[0.5],"#, false),
            (node, targets, "", false),
            (node, primitive, "", false),
        ] {
            let text = quad_gltf(6)
                .replacen(node, node_edit, 1)
                .replacen(primitive, primitive_edit, 1)
                .replacen(r#""name":"quad","#, &format!(r#""name":"quad",{mesh_weights}"#), 1)
                .replacen(r#""scene":0,"#, r#""scene":0,"skins":[{"joints":[1]}],"#, 1);
            let scene = load(file(&text).path()).unwrap_or_else(|e| panic!("{node_edit} {primitive_edit}: {e}"));
            assert_eq!(scene.unrendered().deformed_meshes, usize::from(deformed), "{node_edit} {primitive_edit}");
        }
        let required = quad_gltf(6).replacen(
            r#""scene":0,"#,
            r#""scene":0,"extensionsUsed":["KHR_materials_pbrSpecularGlossiness"],"extensionsRequired":["KHR_materials_pbrSpecularGlossiness"],"#,
            1,
        );
        let err = load(file(&required).path()).unwrap_err().to_string();
        let expected = r#"the file requires "KHR_materials_pbrSpecularGlossiness" (extensionsRequired[0]), which raywave does not read (it reads KHR_lights_punctual, KHR_materials_emissive_strength, EXT_mesh_gpu_instancing, KHR_mesh_quantization, EXT_meshopt_compression, KHR_meshopt_compression, KHR_node_visibility, and takes those that change only the textures it does not sample: KHR_texture_basisu, EXT_texture_webp, EXT_texture_avif, MSFT_texture_dds, KHR_texture_transform)"#;
        assert!(err.contains(expected) && !err.contains("invalid glTF"), "{err}");
        // Each is named by its own index, EXT_mesh_gpu_instancing (read) among them.
        let required = quad_gltf(6).replacen(
            r#""scene":0,"#,
            r#""scene":0,"extensionsUsed":["EXT_mesh_gpu_instancing","KHR_materials_variants","KHR_materials_unlit"],"extensionsRequired":["EXT_mesh_gpu_instancing","KHR_materials_variants","KHR_materials_unlit"],"#,
            1,
        );
        let err = load(file(&required).path()).unwrap_err().to_string();
        let expected = r#"requires "KHR_materials_variants" (extensionsRequired[1]), "KHR_materials_unlit" (extensionsRequired[2]), which"#;
        assert!(err.contains(expected), "{err}");
    }

    #[test]
    fn an_unnamed_mesh_is_named_by_its_json_path() {
        let text = quad_gltf(6).replacen(r#""name":"quad","#, "", 1);
        let f = file(&text);
        assert_eq!(load(f.path()).unwrap().meshes()[0].name, "meshes[0] primitive 0");
        // So is an error about it, raised when the scene is validated.
        let far = text.replacen(r#""translation":[0,0,-2]"#, r#""translation":[0,0,2e8]"#, 1);
        let err = load(file(&far).path()).unwrap_err().to_string();
        assert!(err.contains("meshes[0] primitive 0"), "{err}");
    }

    /// A GLB container (glTF 2.0 § 4.4): the 12-byte header, `json` as the JSON chunk padded
    /// with `json_padding` (glTF's is a space) and `bin`, if any, as the BIN chunk padded with
    /// zeros.
    pub(super) fn glb_container(json: &[u8], json_padding: u8, bin: Option<&[u8]>) -> Vec<u8> {
        let json = (*b"JSON", json.to_vec(), json_padding);
        let mut chunks = Vec::new();
        for (kind, mut data, padding) in std::iter::once(json).chain(bin.map(|bin| (*b"BIN\0", bin.to_vec(), 0))) {
            data.resize(data.len().next_multiple_of(4), padding);
            chunks.extend_from_slice(&(data.len() as u32).to_le_bytes());
            chunks.extend_from_slice(&kind);
            chunks.extend_from_slice(&data);
        }
        let mut glb = b"glTF".to_vec();
        glb.extend_from_slice(&2u32.to_le_bytes());
        glb.extend_from_slice(&(12 + chunks.len() as u32).to_le_bytes());
        glb.extend(chunks);
        glb
    }

    /// Buffers are read through accessors only ([`buffers_read_by_accessors`]): a placeholder
    /// without `uri` (glTF-Validator's `buffer/valid_placeholder.glb`) or a missing file that no
    /// accessor reads refuses no file. A GLB's first buffer without `uri` is its BIN chunk; any
    /// other buffer without `uri` that an accessor reads is an error naming it (the `gltf` crate
    /// gave the BIN chunk to whichever such buffer it loaded first).
    #[test]
    fn only_the_buffers_that_accessors_read_are_loaded() {
        let data = base64_encode(&quad_buffer());
        let with_buffers = |text: &str, buffers: &str| {
            let changed = text.replacen(&format!(r#"{data}"}}]"#), &format!(r#"{data}"}},{buffers}]"#), 1);
            assert_ne!(changed, text);
            changed
        };
        let indices_view = r#"{"buffer":0,"byteOffset":48,"byteLength":12}"#;
        let unread = with_buffers(&quad_gltf(6), r#"{"byteLength":4},{"byteLength":8,"uri":"missing.bin"}"#).replacen(
            indices_view,
            &format!(r#"{indices_view},{{"buffer":2,"byteLength":8}}"#),
            1,
        );
        assert_eq!(load(file(&unread).path()).unwrap().triangle_count(), 2);
        for (buffer, expected) in [
            (1, "buffers[1] (no `uri`): only a GLB's first buffer may omit `uri`"),
            (2, r#"buffers[2] ("missing.bin"): "#),
        ] {
            let read = unread.replacen(indices_view, &format!(r#"{{"buffer":{buffer},"byteLength":4}}"#), 1);
            let err = load(file(&read).path()).unwrap_err().to_string();
            assert!(err.contains(expected), "{err}");
        }
        // The quad's buffer as a GLB's BIN chunk, with and without a placeholder read.
        let in_bin = quad_gltf(6).replacen(&format!(r#","uri":"data:application/octet-stream;base64,{data}""#), "", 1);
        let glb = |json: &str| file_of(".glb", &glb_container(json.as_bytes(), b' ', Some(&quad_buffer())));
        assert_eq!(load(glb(&in_bin).path()).unwrap().triangle_count(), 2);
        let placeholder = in_bin.replacen(r#""byteLength":60}]"#, r#""byteLength":60},{"byteLength":1024}]"#, 1);
        assert_ne!(placeholder, in_bin);
        assert_eq!(load(glb(&placeholder).path()).unwrap().triangle_count(), 2);
        let read = placeholder.replacen(indices_view, r#"{"buffer":1,"byteOffset":48,"byteLength":12}"#, 1);
        let err = load(glb(&read).path()).unwrap_err().to_string();
        assert!(err.contains("buffers[1] (no `uri`): only a GLB's first buffer may omit `uri`"), "{err}");
    }

    /// A GLB header's length must be the file's size (glTF 2.0 § 4.4.2): one shorter than the
    /// header itself overflowed inside the `gltf` crate (a panic with overflow checks on), one
    /// shorter than the file loaded (the crate reads the chunks to the end of the file), and one
    /// longer failed without naming the header's length; a chunk's length past the file's end
    /// failed without naming the chunk.
    #[test]
    fn a_glb_header_length_other_than_the_file_size_is_an_error() {
        let glb_file = |bytes: &[u8]| file_of(".glb", bytes);
        for length in [0u32, 11] {
            let mut glb = b"glTF".to_vec();
            glb.extend_from_slice(&2u32.to_le_bytes());
            glb.extend_from_slice(&length.to_le_bytes());
            let err = load(glb_file(&glb).path()).unwrap_err();
            let expected = format!("GLB header: length {length} is not the file's size, 12 bytes");
            assert!(err.to_string().contains(&expected), "{err}");
        }
        // quad_gltf in a JSON chunk padded with spaces (its buffer keeps its data URI).
        let quad = glb_container(quad_gltf(6).as_bytes(), b' ', None);
        let (size, json_length) = (quad.len() as u32, quad.len() as u32 - 20);
        let glb = |length: u32| {
            let mut glb = quad.clone();
            glb[8..12].copy_from_slice(&length.to_le_bytes());
            glb
        };
        assert_eq!(load(glb_file(&glb(size)).path()).unwrap().triangle_count(), 2);
        for length in [size - 4, size + 4] {
            let err = load(glb_file(&glb(length)).path()).unwrap_err();
            let expected = format!("GLB header: length {length} is not the file's size, {size} bytes");
            assert!(matches!(err, Error::SceneLoad { .. }) && err.to_string().contains(&expected), "{err}");
        }
        // A chunk longer than what follows its header names the chunk (glTF 2.0 § 4.4.3): a BIN
        // chunk of 16 bytes with 8 in the file, and the JSON chunk itself.
        let mut short_bin = glb(size + 16);
        short_bin.extend_from_slice(&16u32.to_le_bytes());
        short_bin.extend_from_slice(b"BIN\0");
        short_bin.extend_from_slice(&[0; 8]);
        let mut long_json = glb(size);
        long_json[12..16].copy_from_slice(&(json_length + 4).to_le_bytes());
        for (bytes, expected) in [
            (short_bin, "GLB chunk 1 (BIN): length 16 runs past the file's end, 8 bytes after its header".to_owned()),
            (long_json, format!("GLB chunk 0 (JSON): length {} runs past the file's end", json_length + 4)),
        ] {
            let err = load(glb_file(&bytes).path()).unwrap_err();
            assert!(matches!(err, Error::SceneLoad { .. }) && err.to_string().contains(&expected), "{err}");
        }
    }

    /// What glTF 2.0 forbids and the `gltf` crate took without a word, refused naming the field:
    /// normalized POSITION or indices (the reader ignored the flag), a mesh without primitives (it
    /// added nothing), a strided view under indices (the reader stepped through it).
    #[test]
    fn normalized_accessors_meshes_without_primitives_and_strided_indices_are_errors() {
        let cases = [
            (
                r#""componentType":5126,"count":4"#,
                r#""componentType":5126,"normalized":true,"count":4"#,
                "meshes[0].primitives[0].attributes.POSITION: accessor 0: holds Vec3 of normalized F32, glTF requires \
                 Vec3 of F32",
            ),
            (
                r#""componentType":5123,"count":6"#,
                r#""componentType":5123,"normalized":true,"count":6"#,
                "meshes[0].primitives[0].indices: accessor 1: holds Scalar of normalized U16",
            ),
            (
                r#""indices":1,"material":0}]}"#,
                r#""indices":1,"material":0}]},{"primitives":[]}"#,
                "meshes[1].primitives: empty; glTF 2.0 requires at least one primitive",
            ),
        ];
        for (from, to, expected) in cases {
            let text = quad_gltf(6);
            assert!(text.contains(from), "{from}");
            match load(file(&text.replacen(from, to, 1)).path()) {
                Err(err @ Error::SceneLoad { .. }) => assert!(err.to_string().contains(expected), "{to}: {err}"),
                other => panic!("{to}: expected a SceneLoad error containing {expected:?}, got {other:?}"),
            }
        }
        // Three indices four bytes apart (0, 1, 2 between 7s): the reader stepped through them and
        // the triangle loaded.
        let strided = quad_gltf(3)
            .replacen(&base64_encode(&quad_buffer()), &base64_encode(&quad_buffer_with(1.0, [0, 7, 1, 7, 2, 7])), 1)
            .replacen(r#""byteOffset":48,"byteLength":12}"#, r#""byteOffset":48,"byteLength":12,"byteStride":4}"#, 1);
        match load(file(&strided).path()) {
            Err(err @ Error::SceneLoad { .. }) => assert!(
                err.to_string().contains(
                    "meshes[0].primitives[0].indices: accessor 1: bufferViews[1] has byteStride 4, which glTF 2.0 \
                     forbids for indices"
                ),
                "{err}"
            ),
            other => panic!("a strided indices view: expected a SceneLoad error, got {other:?}"),
        }
    }

    /// [`quad_gltf`]'s file with its mesh node instanced by `instances` root nodes (no camera)
    /// and a second buffer, `zeros.bin` of `zeros` zero bytes, as buffer 0 (the quad's becomes 1),
    /// edited by `edit`, then given a last accessor of `zeros.bin`'s bytes that the mesh does not
    /// use: raywave loads only the buffers accessors read, and their bytes bound an accessor's
    /// count ([`check_accessor`]). Written to a new folder, whose file path is returned with it.
    fn instanced_quad_gltf(
        instances: usize,
        zeros: usize,
        edit: impl Fn(String) -> String,
    ) -> (tempfile::TempDir, std::path::PathBuf) {
        let nodes: Vec<String> = (0..instances).map(|_| r#"{"mesh":0}"#.to_owned()).collect();
        let roots: Vec<String> = (0..instances).map(|i| i.to_string()).collect();
        let text = quad_gltf(6)
            .replacen(r#""nodes":[0,1]}],"#, &format!(r#""nodes":[{}]}}],"#, roots.join(",")), 1)
            .replacen(
                r#""nodes":[{"mesh":0,"translation":[0,0,-2]},{"camera":0,"translation":[0.5,0.5,3]}],"#,
                &format!(r#""nodes":[{}],"#, nodes.join(",")),
                1,
            )
            .replacen(
                r#""buffers":[{"byteLength":60,"#,
                &format!(r#""buffers":[{{"byteLength":{zeros},"uri":"zeros.bin"}},{{"byteLength":60,"#),
                1,
            )
            .replace(r#"{"buffer":0,"#, r#"{"buffer":1,"#);
        let mut json: serde_json::Value = serde_json::from_str(&edit(text)).unwrap();
        let views = json["bufferViews"].as_array_mut().unwrap();
        views.push(serde_json::json!({"buffer": 0, "byteLength": zeros}));
        let zeros_view = views.len() - 1;
        let zeros_accessor =
            serde_json::json!({"bufferView": zeros_view, "componentType": 5121, "count": zeros, "type": "SCALAR"});
        json["accessors"].as_array_mut().unwrap().push(zeros_accessor);
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("zeros.bin"), vec![0u8; zeros]).unwrap();
        let path = dir.path().join("instanced.gltf");
        std::fs::write(&path, json.to_string()).unwrap();
        (dir, path)
    }

    /// Two primitives sharing the quad's POSITION accessor, each drawing one triangle of it, keep
    /// the three vertices each uses (they copied all four); and a vertex no triangle uses may lie
    /// beyond the coordinate limit (it failed the file).
    #[test]
    fn primitives_keep_only_the_vertices_their_indices_use() {
        let halves = r#"{"attributes":{"POSITION":0},"indices":1,"material":0},{"attributes":{"POSITION":0},"indices":2,"material":0}"#;
        let text = quad_gltf(3)
            .replacen(r#"{"attributes":{"POSITION":0},"indices":1,"material":0}"#, halves, 1)
            .replacen(
                r#"{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}"#,
                r#"{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"},{"bufferView":1,"byteOffset":6,"componentType":5123,"count":3,"type":"SCALAR"}"#,
                1,
            );
        let f = file(&text);
        let scene = load(f.path()).unwrap();
        let kept: Vec<usize> = scene.meshes().iter().map(|m| m.positions.len()).collect();
        assert_eq!(kept, [3, 3], "{text}");
        assert_eq!(
            scene.meshes()[1].positions,
            [Vec3::new(0.0, 0.0, -2.0), Vec3::new(1.0, 1.0, -2.0), Vec3::new(0.0, 1.0, -2.0)]
        );
        assert_eq!(scene.meshes()[1].triangles, [[0, 1, 2]]);

        // Vertex 3 far beyond the limit, the indices drawing only the first triangle.
        let mut buffer = quad_buffer();
        buffer[36..40].copy_from_slice(&1.0e30f32.to_le_bytes());
        let text = quad_gltf(3).replacen(&base64_encode(&quad_buffer()), &base64_encode(&buffer), 1);
        let f = file(&text);
        assert_eq!(load(f.path()).unwrap().meshes()[0].positions.len(), 3);
        let f = file(&quad_gltf(6).replacen(&base64_encode(&quad_buffer()), &base64_encode(&buffer), 1));
        let err = load(f.path()).unwrap_err().to_string();
        assert!(err.contains("attributes.POSITION element 3"), "{err}");
    }

    /// An indices accessor whose `count` is near 2⁶⁴, instanced by four nodes: its triangles,
    /// counted before the accessor is checked, overflowed the count (a panic where overflow is
    /// checked); the file is refused with a typed error instead.
    #[test]
    fn a_huge_index_count_is_refused_without_overflow() {
        let (_dir, path) = instanced_quad_gltf(4, 1 << 20, |text| {
            text.replacen(r#""count":6,"type":"SCALAR""#, r#""count":18446744073709551615,"type":"SCALAR""#, 1)
        });
        // The accessor's count is checked before the limits use it: the error names the field,
        // not a scene too large.
        let err = load(&path).unwrap_err();
        let expected = "meshes[0].primitives[0].indices: accessor 1: count 18446744073709551615 is outside 1..=";
        assert!(matches!(err, Error::SceneLoad { .. }) && err.to_string().contains(expected), "{err}");
    }

    #[test]
    fn a_large_accessor_instanced_many_times_is_read_once() {
        // POSITION a sparse accessor of 2²⁰ elements, of which the quad's six indices use four,
        // under 10⁴ nodes: each instance adds its four vertices, within every limit, and the
        // accessor is read once (counted; in milliseconds) — read per instance, 10¹⁰ element reads took
        // 54 s in the test profile, and the limits, which count the vertices kept, allowed
        // 2²⁶ instances.
        let (instances, elements) = (10_000, 1 << 20);
        let (_dir, path) = instanced_quad_gltf(instances, elements, |text| {
            text.replacen(
                r#"{"bufferView":0,"componentType":5126,"count":4"#,
                &format!(
                    r#"{{"componentType":5126,"count":{elements},"sparse":{{"count":3,"indices":{{"bufferView":1,"componentType":5123}},"values":{{"bufferView":0}}}}"#
                ),
                1,
            )
        });
        PRIMITIVE_READS.with(|reads| reads.set(0));
        let scene = load(&path).unwrap();
        assert_eq!(PRIMITIVE_READS.with(std::cell::Cell::get), 1, "the primitive read once");
        assert_eq!(scene.meshes.len(), instances);
        assert!(scene.meshes.iter().all(|mesh| mesh.positions.len() == 4), "each instance keeps the four it uses");
    }

    #[test]
    fn instancing_beyond_the_vertex_limit_is_refused_before_reading() {
        // POSITION a sparse accessor of 2²⁰ elements (the file's 1 MiB zeros allow it), drawn
        // without indices (so every vertex is used), instanced by 257 nodes: 2²⁸ + 2²⁰
        // vertices, refused before any is read — without allocating the 3 GiB it asks for.
        let per_instance = 1 << 20;
        let (_dir, path) = instanced_quad_gltf(MAX_VERTICES / per_instance + 1, per_instance, |text| {
            text.replacen(
                r#"{"bufferView":0,"componentType":5126,"count":4"#,
                &format!(
                    r#"{{"componentType":5126,"count":{per_instance},"sparse":{{"count":3,"indices":{{"bufferView":1,"componentType":5123}},"values":{{"bufferView":0}}}}"#
                ),
                1,
            )
            .replacen(r#""indices":1,"#, "", 1)
        });
        match load(&path) {
            Err(err @ Error::SceneTooLarge { .. }) => {
                assert!(err.to_string().contains("instance 269484032 vertices, more than 268435456"), "{err}")
            }
            other => panic!("expected SceneTooLarge, got {other:?}"),
        }
    }

    /// The vertex limit counts a node's `EXT_mesh_gpu_instancing` instances as copies: 2²⁰
    /// vertices (a sparse POSITION accessor, drawn without indices) placed by 257 instances (a
    /// TRANSLATION accessor of the zeros) pass 2²⁸, refused before any is read.
    #[test]
    fn gpu_instancing_beyond_the_vertex_limit_is_refused_before_reading() {
        let per_instance = 1 << 20;
        let instances = MAX_VERTICES / per_instance + 1;
        let (_dir, path) = instanced_quad_gltf(1, per_instance, |text| {
            let node = r#"{"mesh":0}"#;
            let instanced = r#"{"mesh":0,"extensions":{"EXT_mesh_gpu_instancing":{"attributes":{"TRANSLATION":2}}}}"#;
            let views = format!(r#""byteLength":12}},{{"buffer":0,"byteLength":{}}}]"#, 12 * instances);
            let translations = format!(
                r#""type":"SCALAR"}},{{"bufferView":2,"componentType":5126,"count":{instances},"type":"VEC3"}}]"#
            );
            text.replacen(
                r#"{"bufferView":0,"componentType":5126,"count":4"#,
                &format!(
                    r#"{{"componentType":5126,"count":{per_instance},"sparse":{{"count":3,"indices":{{"bufferView":1,"componentType":5123}},"values":{{"bufferView":0}}}}"#
                ),
                1,
            )
            .replacen(r#""indices":1,"#, "", 1)
            .replacen(node, instanced, 1)
            .replacen(r#""byteLength":12}]"#, &views, 1)
            .replacen(r#""type":"SCALAR"}]"#, &translations, 1)
        });
        PRIMITIVE_READS.with(|reads| reads.set(0));
        match load(&path) {
            Err(err @ Error::SceneTooLarge { .. }) => {
                assert!(err.to_string().contains("instance 269484032 vertices, more than 268435456"), "{err}")
            }
            other => panic!("expected SceneTooLarge, got {other:?}"),
        }
        assert_eq!(PRIMITIVE_READS.with(std::cell::Cell::get), 0, "nothing read");
    }

    #[test]
    fn instancing_beyond_the_triangle_limit_is_refused_before_reading() {
        // A few vertices but 999 999 u8 indices from a 1 MB buffer of zeros, instanced by enough
        // nodes to pass 2²⁸ triangles: counting only the vertices, the loader read them all (8·10⁸
        // indices, 3 GiB) before dropping them as degenerate.
        let per_instance = 999_999;
        let instances = MAX_TRIANGLES / (per_instance / 3) + 1;
        let indices = |text: String| {
            text.replacen(r#""byteLength":12}]"#, r#""byteLength":12},{"buffer":0,"byteLength":999999}]"#, 1).replacen(
                r#"{"bufferView":1,"componentType":5123,"count":6,"type":"SCALAR"}"#,
                &format!(r#"{{"bufferView":2,"componentType":5121,"count":{per_instance},"type":"SCALAR"}}"#),
                1,
            )
        };
        let (_dir, path) = instanced_quad_gltf(instances, 1 << 20, indices);
        match load(&path) {
            Err(err @ Error::SceneTooLarge { .. }) => {
                let expected =
                    format!("instance {} triangles, more than {MAX_TRIANGLES}", instances * (per_instance / 3));
                assert!(err.to_string().contains(&expected), "{err}");
            }
            other => panic!("expected SceneTooLarge, got {other:?}"),
        }
        // One instance of it loads (every triangle degenerate: an empty scene, but read).
        let (_dir, path) = instanced_quad_gltf(1, 1 << 20, indices);
        assert!(matches!(load(&path), Err(Error::EmptyScene { dropped_degenerate: 333_333, .. })));
    }

    #[test]
    fn a_scene_path_that_is_not_a_regular_file_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["zero.gltf", "zero.glb"] {
            let link = dir.path().join(name);
            std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
            let err = load(&link).unwrap_err();
            assert!(err.to_string().contains("not a regular file"), "{err}");
        }
    }
}
