//! What a scene file asked for that raywave does not render, counted while loading so that a
//! caller can say so instead of showing a different image without a word.

/// The parts of a scene file raywave loads but does not render as the file describes them.
/// `raywave render` prints a warning for each non-zero count.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Unrendered {
    /// Meshes whose materials have textures (glTF base colour, metallic-roughness or emissive
    /// textures; an MTL `map_Kd`, `map_Ke`, `map_Pr` or `map_Pm`), or that have glTF vertex
    /// colours (`COLOR_0`, a multiplier of the base colour). raywave samples no texture and reads
    /// no vertex colour: their materials' factors alone apply, so such a mesh is one colour — and
    /// an emissive texture's mesh emits its factor (Blender writes 1) over its whole surface.
    pub textured_meshes: usize,
    /// Meshes whose materials are see-through: glTF `alphaMode` `BLEND` with a base-colour alpha
    /// below 1 or a base-colour texture (whose alpha may be below 1), or `MASK` with an alpha
    /// below `alphaCutoff` or a base-colour texture, or `KHR_materials_transmission` with a
    /// `transmissionFactor` above 0 or a `transmissionTexture` (Blender's glass, an extension
    /// files use without requiring it); an MTL `d` below 1 or a `map_d`. raywave renders every
    /// surface opaque (a `MASK`ed-out mesh, invisible in a glTF viewer, is seen and casts shadows).
    /// MTL's `Tr` counts only without a `d` and strictly between 0 and 1, where both of the ways
    /// exporters write it (`d` or `1 − d`) make the material partly see-through.
    pub see_through_meshes: usize,
    /// Meshes whose glTF materials are unlit (`KHR_materials_unlit`: the base colour is the
    /// colour seen, whatever the light), which raywave shades as lit metallic-roughness
    /// materials, as the extension's fallback is.
    pub unlit_meshes: usize,
    /// Meshes that a skin or morph targets would deform: glTF primitives of a node with a `skin`,
    /// or with morph `targets` and a non-zero weight (the node's `weights`, else the mesh's; glTF
    /// 2.0 § 3.7.2.2 defaults them to 0). raywave renders them in their rest pose: POSITION under
    /// the node's transform, which glTF says a skinned mesh ignores.
    pub deformed_meshes: usize,
    /// The file's only cameras were orthographic, which raywave does not render (its cameras are
    /// a pinhole or a thin lens): the scene is seen through the camera that frames its bounds,
    /// as for a file without a camera.
    pub orthographic_camera: bool,
    /// glTF primitives that draw points or lines (modes `POINTS`, `LINES`, `LINE_LOOP`,
    /// `LINE_STRIP`), counted once per node that places their mesh. raywave traces surfaces only:
    /// these are not drawn. (A primitive without POSITION, which glTF 2.0 has skipped, is not
    /// counted.)
    pub point_and_line_primitives: usize,
    /// Nodes of the scene that place a punctual light (glTF `KHR_lights_punctual`: point, spot
    /// and directional lights, which Blender exports its lamps as). raywave renders area lights
    /// only (emissive parallelograms): these light nothing.
    pub punctual_lights: usize,
}
