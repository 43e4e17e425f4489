//! Procedural scenes for tests and benchmarks: closed icospheres, a field of spheres with over a
//! million triangles, and a "hairball" of thin random triangles for incoherent traversal.

use super::{Camera, Material, Mesh, MAX_TRIANGLES, MAX_VERTICES};
use crate::error::{Error, Result};
use glam::{UVec3, Vec3};
use raywave_kernels::hash::{pcg3d, unit_float};
use std::collections::HashMap;

/// Most subdivisions of an icosphere: 20·4¹¹ ≈ 8.4·10⁷ triangles, within [`MAX_TRIANGLES`].
pub const MAX_ICOSPHERE_SUBDIVISIONS: u32 = 11;

/// Triangles of an icosphere of `subdivisions` levels.
fn icosphere_triangles(subdivisions: u32) -> u64 {
    20 << (2 * u64::from(subdivisions.min(MAX_ICOSPHERE_SUBDIVISIONS + 1)))
}

/// A closed icosphere: the icosahedron subdivided `subdivisions` times (20·4ⁿ triangles), vertices
/// pushed onto the sphere, its triangles facing outwards. Shared edges use shared vertices, so
/// the mesh is watertight. A radius that is not positive and finite (a negative one turned the
/// sphere inside out) or more than [`MAX_ICOSPHERE_SUBDIVISIONS`] is an `InvalidParameter` error.
pub fn icosphere(name: &str, centre: Vec3, radius: f32, subdivisions: u32, albedo: Vec3) -> Result<Mesh> {
    if !(radius > 0.0 && radius.is_finite()) {
        return Err(Error::InvalidParameter {
            name: "icosphere radius",
            reason: format!("{radius} is not positive and finite"),
        });
    }
    if subdivisions > MAX_ICOSPHERE_SUBDIVISIONS {
        return Err(Error::InvalidParameter {
            name: "icosphere subdivisions",
            reason: format!("{subdivisions} exceeds {MAX_ICOSPHERE_SUBDIVISIONS}"),
        });
    }
    // The icosahedron's 12 vertices are the cyclic permutations of (0, ±1, ±φ).
    let phi = (1.0 + 5f32.sqrt()) * 0.5;
    let mut unit: Vec<Vec3> = [
        (-1.0, phi, 0.0),
        (1.0, phi, 0.0),
        (-1.0, -phi, 0.0),
        (1.0, -phi, 0.0),
        (0.0, -1.0, phi),
        (0.0, 1.0, phi),
        (0.0, -1.0, -phi),
        (0.0, 1.0, -phi),
        (phi, 0.0, -1.0),
        (phi, 0.0, 1.0),
        (-phi, 0.0, -1.0),
        (-phi, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut triangles: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut midpoint = |a: u32, b: u32, unit: &mut Vec<Vec3>| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                unit.push(((unit[a as usize] + unit[b as usize]) * 0.5).normalize());
                unit.len() as u32 - 1
            })
        };
        triangles = triangles
            .iter()
            .flat_map(|&[a, b, c]| {
                let ab = midpoint(a, b, &mut unit);
                let bc = midpoint(b, c, &mut unit);
                let ca = midpoint(c, a, &mut unit);
                [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            })
            .collect();
    }
    Ok(Mesh {
        name: name.to_owned(),
        positions: unit.iter().map(|&p| centre + p * radius).collect(),
        triangles,
        material: Material::diffuse(albedo),
    })
}

/// `per_axis³` icospheres of `subdivisions` levels on a unit-spaced grid, radius 0.4, with a camera
/// looking at the block from a corner. `per_axis = 4, subdivisions = 5` gives 1 310 720 triangles;
/// more than [`MAX_TRIANGLES`] in all is an `InvalidParameter` error.
pub fn sphere_field(per_axis: u32, subdivisions: u32) -> Result<(Vec<Mesh>, Camera)> {
    let triangles = u64::from(per_axis).saturating_pow(3).saturating_mul(icosphere_triangles(subdivisions));
    if triangles > MAX_TRIANGLES as u64 {
        return Err(Error::InvalidParameter {
            name: "sphere field",
            reason: format!("{per_axis}³ spheres of {subdivisions} subdivisions exceed {MAX_TRIANGLES} triangles"),
        });
    }
    let mut meshes = Vec::new();
    for x in 0..per_axis {
        for y in 0..per_axis {
            for z in 0..per_axis {
                let centre = Vec3::new(x as f32, y as f32, z as f32);
                let albedo =
                    Vec3::new(0.3 + 0.15 * x as f32, 0.3 + 0.15 * y as f32, 0.3 + 0.15 * z as f32).min(Vec3::ONE);
                meshes.push(icosphere(&format!("sphere {x},{y},{z}"), centre, 0.4, subdivisions, albedo)?);
            }
        }
    }
    let extent = per_axis as f32 - 1.0;
    let camera = Camera {
        position: Vec3::new(-1.5, extent * 0.5 + 1.0, -2.5),
        look_at: Vec3::splat(extent * 0.5),
        up: Vec3::Y,
        vertical_fov_degrees: 50.0,
        mirrored: false,
    };
    Ok((meshes, camera))
}

/// `count` thin random triangles ("hairs", 0.05 long and 0.001 wide, arbitrary orientation) in the
/// unit cube, seeded by `seed`, and a camera outside the cube: the incoherent-traversal stress case
/// (thin, overlapping, randomly oriented boxes). More triangles than [`MAX_TRIANGLES`], or more
/// than their three vertices each fit in [`MAX_VERTICES`], is an `InvalidParameter` error,
/// before anything is allocated.
pub fn hairball(count: u32, seed: u32) -> Result<(Vec<Mesh>, Camera)> {
    let count_fits = count as usize <= MAX_TRIANGLES && 3 * count as usize <= MAX_VERTICES;
    if !count_fits {
        return Err(Error::InvalidParameter {
            name: "hairball",
            reason: format!("{count} hairs exceed {MAX_TRIANGLES} triangles or {MAX_VERTICES} vertices"),
        });
    }
    let random3 = |i: u32, stream: u32| {
        let h = pcg3d(UVec3::new(i, stream, seed));
        Vec3::new(unit_float(h.x), unit_float(h.y), unit_float(h.z))
    };
    let mut positions = Vec::with_capacity(count as usize * 3);
    for i in 0..count {
        let root = random3(i, 0);
        let along = (random3(i, 1) * 2.0 - 1.0).normalize_or(Vec3::X);
        let side = along.any_orthonormal_vector();
        positions.extend([root, root + along * 0.05, root + side * 0.001]);
    }
    let triangles = (0..count).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
    let mesh = Mesh { name: "hairball".into(), positions, triangles, material: Material::diffuse(Vec3::splat(0.6)) };
    let camera = Camera {
        position: Vec3::new(0.5, 0.5, -1.6),
        look_at: Vec3::splat(0.5),
        up: Vec3::Y,
        vertical_fov_degrees: 45.0,
        mirrored: false,
    };
    Ok((vec![mesh], camera))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosphere_is_closed_and_on_the_sphere() {
        let mesh = icosphere("s", Vec3::new(1.0, 2.0, 3.0), 2.0, 3, Vec3::ONE).unwrap();
        let centre = Vec3::new(1.0, 2.0, 3.0);
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            assert!((b - a).cross(c - a).dot((a + b + c) / 3.0 - centre) > 0.0, "{t:?} faces inwards");
        }
        assert_eq!(mesh.triangles.len(), 20 * 4usize.pow(3));
        // Euler: V − E + F = 2 for a closed genus-0 mesh with E = 3F/2.
        let f = mesh.triangles.len();
        assert_eq!(mesh.positions.len() + f - 3 * f / 2, 2);
        for p in &mesh.positions {
            assert!(((*p - Vec3::new(1.0, 2.0, 3.0)).length() - 2.0).abs() < 1e-5);
        }
        // Every edge is shared by exactly two triangles.
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &mesh.triangles {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        assert!(edges.values().all(|&n| n == 2));
    }

    #[test]
    fn sphere_field_reaches_a_million_triangles() {
        let (meshes, _) = sphere_field(4, 5).unwrap();
        let triangles: usize = meshes.iter().map(|m| m.triangles.len()).sum();
        assert_eq!(triangles, 64 * 20 * 1024);
        assert!(triangles >= 1_000_000);
    }

    /// Sizes that would not fit the scene limits (or whose indices would wrap `u32`) and spheres
    /// that are not spheres are refused before anything is built.
    #[test]
    fn parameters_beyond_the_limits_are_refused() {
        for radius in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert!(icosphere("s", Vec3::ZERO, radius, 1, Vec3::ONE).is_err(), "{radius}");
        }
        assert!(icosphere("s", Vec3::ZERO, 1.0, MAX_ICOSPHERE_SUBDIVISIONS + 1, Vec3::ONE).is_err());
        assert!(icosphere("s", Vec3::ZERO, 1.0, u32::MAX, Vec3::ONE).is_err());
        assert!(sphere_field(20, 7).is_err(), "8000 × 327 680 triangles");
        assert!(sphere_field(u32::MAX, 0).is_err());
        assert!(hairball(u32::MAX, 0).is_err());
        assert!(hairball((MAX_VERTICES / 3 + 1) as u32, 0).is_err(), "its vertices exceed the limit");
    }

    #[test]
    fn hairball_is_deterministic_and_inside_its_box() {
        let (a, _) = hairball(1000, 7).unwrap();
        let (b, _) = hairball(1000, 7).unwrap();
        assert_eq!(a, b);
        assert!(a[0].positions.iter().all(|p| p.cmpge(Vec3::splat(-0.06)).all() && p.cmple(Vec3::splat(1.06)).all()));
    }
}
