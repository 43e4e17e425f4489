//! The one error type of raywave: every failure on user input (scene files, parameters, device
//! choice, output paths) and every Vulkan failure becomes a value that names what went wrong.

use std::path::PathBuf;

/// Result alias used throughout raywave.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in raywave, each variant naming the offending input.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A scene file could not be read or parsed.
    #[error("cannot load scene {path}: {message}")]
    SceneLoad {
        /// The scene file.
        path: PathBuf,
        /// What the parser reported.
        message: String,
    },
    /// A scene name of the form `builtin:NAME` names no built-in scene.
    #[error("unknown built-in scene {name:?} (available: {available})")]
    UnknownBuiltinScene {
        /// The requested name.
        name: String,
        /// Comma-separated list of the built-in scene names.
        available: String,
    },
    /// The scene has no triangle of non-zero area.
    #[error(
        "scene {scene}: contains no triangles of non-zero area ({dropped_degenerate} zero-area triangles dropped)"
    )]
    EmptyScene {
        /// The scene (file path or built-in name).
        scene: String,
        /// Zero-area triangles that were dropped.
        dropped_degenerate: usize,
    },
    /// A vertex position is NaN or infinite.
    #[error("scene {scene}: mesh {mesh:?} vertex {vertex} has a non-finite position {position}")]
    NonFiniteVertex {
        /// The scene (file path or built-in name).
        scene: String,
        /// The mesh's name.
        mesh: String,
        /// Index of the vertex within the mesh.
        vertex: usize,
        /// The offending position, as text.
        position: String,
    },
    /// A vertex coordinate's magnitude exceeds [`crate::scene::MAX_COORDINATE`].
    #[error(
        "scene {scene}: mesh {mesh:?} vertex {vertex} at {position} is out of range (each coordinate must lie \
         within ±{limit:e} scene units)"
    )]
    VertexOutOfRange {
        /// The scene (file path or built-in name).
        scene: String,
        /// The mesh's name.
        mesh: String,
        /// Index of the vertex within the mesh.
        vertex: usize,
        /// The offending position, as text.
        position: String,
        /// The largest coordinate magnitude accepted.
        limit: f32,
    },
    /// A triangle refers to a vertex that does not exist.
    #[error("scene {scene}: mesh {mesh:?} triangle {triangle} uses vertex {index} but the mesh has {vertex_count}")]
    IndexOutOfRange {
        /// The scene (file path or built-in name).
        scene: String,
        /// The mesh's name.
        mesh: String,
        /// Index of the triangle within the mesh.
        triangle: usize,
        /// The out-of-range vertex index.
        index: u32,
        /// Number of vertices in the mesh.
        vertex_count: usize,
    },
    /// The scene is larger than raywave handles: more vertices than [`crate::scene::MAX_VERTICES`],
    /// more triangles or meshes than the streams' 32-bit indices, or a BVH deeper than the
    /// traversal walks (`raywave_kernels::trace::cwbvh::MAX_TREE_DEPTH`).
    #[error("scene {scene} is too large: {what}")]
    SceneTooLarge {
        /// The scene (file path or built-in name).
        scene: String,
        /// What overflowed.
        what: String,
    },
    /// The requested image size is zero or above the backend's limit.
    #[error("image size {width}×{height} is invalid on {backend}: {reason}")]
    ImageSize {
        /// Requested width in pixels.
        width: u32,
        /// Requested height in pixels.
        height: u32,
        /// The backend that rejected it.
        backend: String,
        /// Which limit it broke.
        reason: String,
    },
    /// A device string is malformed or names a device that does not exist.
    #[error("device {requested:?}: {reason}")]
    DeviceChoice {
        /// What the user asked for.
        requested: String,
        /// Why it cannot be used.
        reason: String,
    },
    /// No Vulkan implementation could be loaded or it reports no devices.
    #[error("Vulkan is unavailable: {reason}")]
    VulkanUnavailable {
        /// Why.
        reason: String,
    },
    /// The chosen Vulkan device lacks features a stage needs.
    #[error("Vulkan device {device:?} cannot run {stage}: missing {}", missing.join(", "))]
    MissingFeatures {
        /// The device's name.
        device: String,
        /// The stage that needs them.
        stage: String,
        /// The missing extensions or features.
        missing: Vec<String>,
    },
    /// The Vulkan validation layers reported warnings or errors while a backend ran or closed
    /// ([`crate::device::close_backend`]); the messages went to stderr as they arrived.
    #[error("{backend}: the Vulkan validation layers reported {count} warning(s) or error(s), printed above")]
    Validation {
        /// The backend's name.
        backend: String,
        /// How many messages arrived.
        count: usize,
    },
    /// A Vulkan call failed.
    #[error("Vulkan call {call} failed: {result}")]
    Vulkan {
        /// The call, e.g. `vkCreateDevice`.
        call: &'static str,
        /// The error code as text.
        result: String,
    },
    /// The output file cannot be written.
    #[error("cannot write output {path}: {source}")]
    Output {
        /// The output path.
        path: PathBuf,
        /// The underlying I/O error.
        source: std::io::Error,
    },
    /// The image could not be encoded.
    #[error("cannot encode image {path}: {message}")]
    Encode {
        /// The output path.
        path: PathBuf,
        /// What the encoder reported.
        message: String,
    },
    /// The shade stage was given [`crate::shading::ShadeData`] built from another scene than the
    /// one it was to shade — the scene the backend loaded last ([`crate::Backend::load_scene`]),
    /// or the one [`crate::lit_frame::shade_samples`] renders: stale data after the scene was
    /// rebuilt (an object moved), or another scene's. The trace runs against the loaded scene, so
    /// shading its hits with that data's triangles and materials gave a wrong image.
    #[error(
        "the shade data was built from {data}, but is to shade {loaded} (the scene loaded on the backend, or \
         the frame's): build it again from that scene (ShadeData::new)"
    )]
    SceneMismatch {
        /// The scene the shade data was built from ([`crate::scene::SceneIdentity`], as text).
        data: String,
        /// The scene it was to shade, as text.
        loaded: String,
    },
    /// A parameter is outside its valid range.
    #[error("invalid parameter {name}: {reason}")]
    InvalidParameter {
        /// The parameter's name.
        name: &'static str,
        /// Why it is invalid.
        reason: String,
    },
}
