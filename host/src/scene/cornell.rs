//! The Cornell box, from the measurements published by the Cornell University Program of Computer
//! Graphics ("Cornell Box Data", <https://www.graphics.cornell.edu/online/box/data.html>).
//!
//! Coordinates there are millimetres; we convert to metres. Reflectances are the published spectra
//! reduced to approximate linear sRGB. The light is lowered 0.1 mm below the ceiling (as most
//! renderers of the data do) so the two coplanar surfaces do not fight for the same hits.
//!
//! Light quads list their corners counter-clockwise seen from below, so their triangles face −y
//! (into the box) and the scene derives downward-emitting quad lights from them.

use super::{Camera, Material, Mesh};
use glam::Vec3;

/// Millimetres to scene units (metres).
const MM: f32 = 0.001;

/// A quad given by four corners in millimetres (published order), as two triangles.
fn quad(name: &str, corners: [[f32; 3]; 4], material: Material) -> Mesh {
    Mesh {
        name: name.to_owned(),
        positions: corners.iter().map(|c| Vec3::from_array(*c) * MM).collect(),
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        material,
    }
}

/// A box given by its five published faces (top and four sides) in millimetres, merged into one mesh.
fn block(name: &str, faces: [[[f32; 3]; 4]; 5], material: Material) -> Mesh {
    let mut mesh = Mesh { name: name.to_owned(), positions: vec![], triangles: vec![], material };
    for face in faces {
        let q = quad(name, face, material);
        let base = mesh.positions.len() as u32;
        mesh.positions.extend(q.positions);
        mesh.triangles.extend(q.triangles.iter().map(|t| t.map(|i| i + base)));
    }
    mesh
}

/// Approximate linear-sRGB reflectances of the published white, red and green paints.
const WHITE: Vec3 = Vec3::new(0.725, 0.71, 0.68);
const RED: Vec3 = Vec3::new(0.63, 0.065, 0.05);
const GREEN: Vec3 = Vec3::new(0.14, 0.45, 0.091);

/// The published light's radiance reduced to linear sRGB (the spectrum peaks near 18.4 at 700 nm).
pub(super) const LIGHT: Vec3 = Vec3::new(17.0, 12.0, 4.0);

/// The published light's extent in x and z, mm.
const PUBLISHED_LIGHT: ([f32; 2], [f32; 2]) = ([213.0, 343.0], [227.0, 332.0]);

/// Height of the lights' planes: 0.1 mm below the ceiling (548.8 mm).
const LIGHT_Y: f32 = 548.7;

/// `cornell-two-lights`: a warm light, 120 mm × 100 mm, over the front left (towards the red wall,
/// in front of the tall block), and a cool one, 90 mm × 90 mm, over the back right (towards the
/// green wall, behind the short block). Luminance × area: 17.0 · 12 000 mm² for the warm one, 10.2 · 8100 mm² for the cool
/// one (2.5 times less), together 1.7 times the published light's 12.5 · 13 650 mm².
pub(super) const WARM_LIGHT: Vec3 = Vec3::new(24.0, 16.0, 6.0);
/// See [`WARM_LIGHT`].
pub(super) const COOL_LIGHT: Vec3 = Vec3::new(6.0, 10.0, 24.0);

/// Silver's reflectance at normal incidence (F0) in linear sRGB, the usual PBR reference value.
const SILVER: Vec3 = Vec3::new(0.972, 0.960, 0.915);

/// A rectangular light on the ceiling spanning `x0..x1` × `z0..z1` mm, corners counter-clockwise
/// seen from below so it faces down.
fn ceiling_light(name: &str, [x0, x1]: [f32; 2], [z0, z1]: [f32; 2], radiance: Vec3) -> Mesh {
    quad(
        name,
        [[x1, LIGHT_Y, z0], [x1, LIGHT_Y, z1], [x0, LIGHT_Y, z1], [x0, LIGHT_Y, z0]],
        Material { emission: radiance, ..Material::diffuse(Vec3::ONE) },
    )
}

/// The eight meshes of the box: floor, ceiling, back wall, right (green) and left (red) walls, the
/// short and tall blocks, and the light.
pub fn meshes() -> Vec<Mesh> {
    let mut meshes = room(Material::diffuse(WHITE), Material::diffuse(WHITE));
    meshes.push(ceiling_light("light", PUBLISHED_LIGHT.0, PUBLISHED_LIGHT.1, LIGHT));
    meshes
}

/// The nine meshes of `cornell-two-lights`: the box of [`meshes`] with a glossy white short block
/// (dielectric, roughness 0.25) and a metallic silver tall block (roughness 0.3), and the published
/// light replaced by a warm and a cool light ([`WARM_LIGHT`], [`COOL_LIGHT`]).
pub fn two_lights_meshes() -> Vec<Mesh> {
    let glossy = Material { roughness: 0.25, ..Material::diffuse(WHITE) };
    let metal = Material { base_color: SILVER, roughness: 0.3, metallic: 1.0, ..Material::diffuse(SILVER) };
    let mut meshes = room(glossy, metal);
    meshes.push(ceiling_light("warm light", [330.0, 450.0], [120.0, 220.0], WARM_LIGHT));
    meshes.push(ceiling_light("cool light", [105.0, 195.0], [335.0, 425.0], COOL_LIGHT));
    meshes
}

/// The meshes of `cornell-light-grid`: the box of [`meshes`] with the published light's rectangle
/// cut into a grid of 4 × 5 smaller lights, each 80 % of its cell (so they are separate quads),
/// tinted red, green or blue in turn and 0.5…2 times as bright, together 0.8 times the published
/// light's power. Beyond 8 lights the shade stage chooses among them through the light BVH, which
/// the other Cornell scenes (one and two lights) never reach.
pub fn light_grid_meshes() -> Vec<Mesh> {
    const COLUMNS: usize = 4;
    const ROWS: usize = 5;
    let ([x0, x1], [z0, z1]) = PUBLISHED_LIGHT;
    let (cell_x, cell_z) = ((x1 - x0) / COLUMNS as f32, (z1 - z0) / ROWS as f32);
    let tints = [Vec3::new(1.6, 0.7, 0.7), Vec3::new(0.7, 1.6, 0.7), Vec3::new(0.7, 0.7, 1.6)];
    let mut meshes = room(Material::diffuse(WHITE), Material::diffuse(WHITE));
    for k in 0..COLUMNS * ROWS {
        let (i, j) = ((k % COLUMNS) as f32, (k / COLUMNS) as f32);
        let x = [x0 + cell_x * (i + 0.1), x0 + cell_x * (i + 0.9)];
        let z = [z0 + cell_z * (j + 0.1), z0 + cell_z * (j + 0.9)];
        let brightness = 0.5 + 1.5 * (k * 7 % 11) as f32 / 10.0;
        meshes.push(ceiling_light(&format!("light {i},{j}"), x, z, LIGHT * tints[k % 3] * brightness));
    }
    meshes
}

/// The box without its light: floor, ceiling, back, right and left walls, then the short and tall
/// blocks in the given materials.
fn room(short_block: Material, tall_block: Material) -> Vec<Mesh> {
    vec![
        quad(
            "floor",
            [[552.8, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 559.2], [549.6, 0.0, 559.2]],
            Material::diffuse(WHITE),
        ),
        quad(
            "ceiling",
            [[556.0, 548.8, 0.0], [556.0, 548.8, 559.2], [0.0, 548.8, 559.2], [0.0, 548.8, 0.0]],
            Material::diffuse(WHITE),
        ),
        quad(
            "back wall",
            [[549.6, 0.0, 559.2], [0.0, 0.0, 559.2], [0.0, 548.8, 559.2], [556.0, 548.8, 559.2]],
            Material::diffuse(WHITE),
        ),
        quad(
            "right wall",
            [[0.0, 0.0, 559.2], [0.0, 0.0, 0.0], [0.0, 548.8, 0.0], [0.0, 548.8, 559.2]],
            Material::diffuse(GREEN),
        ),
        quad(
            "left wall",
            [[552.8, 0.0, 0.0], [549.6, 0.0, 559.2], [556.0, 548.8, 559.2], [556.0, 548.8, 0.0]],
            Material::diffuse(RED),
        ),
        block(
            "short block",
            [
                [[130.0, 165.0, 65.0], [82.0, 165.0, 225.0], [240.0, 165.0, 272.0], [290.0, 165.0, 114.0]],
                [[290.0, 0.0, 114.0], [290.0, 165.0, 114.0], [240.0, 165.0, 272.0], [240.0, 0.0, 272.0]],
                [[130.0, 0.0, 65.0], [130.0, 165.0, 65.0], [290.0, 165.0, 114.0], [290.0, 0.0, 114.0]],
                [[82.0, 0.0, 225.0], [82.0, 165.0, 225.0], [130.0, 165.0, 65.0], [130.0, 0.0, 65.0]],
                [[240.0, 0.0, 272.0], [240.0, 165.0, 272.0], [82.0, 165.0, 225.0], [82.0, 0.0, 225.0]],
            ],
            short_block,
        ),
        block(
            "tall block",
            [
                [[423.0, 330.0, 247.0], [265.0, 330.0, 296.0], [314.0, 330.0, 456.0], [472.0, 330.0, 406.0]],
                [[423.0, 0.0, 247.0], [423.0, 330.0, 247.0], [472.0, 330.0, 406.0], [472.0, 0.0, 406.0]],
                [[472.0, 0.0, 406.0], [472.0, 330.0, 406.0], [314.0, 330.0, 456.0], [314.0, 0.0, 456.0]],
                [[314.0, 0.0, 456.0], [314.0, 330.0, 456.0], [265.0, 330.0, 296.0], [265.0, 0.0, 296.0]],
                [[265.0, 0.0, 296.0], [265.0, 330.0, 296.0], [423.0, 330.0, 247.0], [423.0, 0.0, 247.0]],
            ],
            tall_block,
        ),
    ]
}

/// The published camera: at (278, 273, −800) mm looking along +z, 35 mm focal length on a
/// 25 mm × 25 mm film, i.e. a vertical field of view of 2·atan(12.5 / 35) ≈ 39.31°.
pub fn camera() -> Camera {
    Camera {
        position: Vec3::new(278.0, 273.0, -800.0) * MM,
        look_at: Vec3::new(278.0, 273.0, 0.0) * MM,
        up: Vec3::Y,
        vertical_fov_degrees: 2.0 * (12.5f32 / 35.0).atan().to_degrees(),
        mirrored: false,
    }
}
