//! The lit scenes of the reports: the built-in Cornell box geometry with analytic lights placed
//! for each experiment of seed 002, and the shading points its camera sees.

use crate::kernels::offset::offset_ray_origin;
use crate::kernels::sampling::light_select::luminance;
use crate::kernels::triangle::geometric_normal;
use crate::shared::light::light_kind;
use crate::shared::stream::NO_HIT;
use crate::shared::Light;
use crate::{Backend, RayStream, Result, Scene};
use glam::{Vec3, Vec4, Vec4Swizzles};

/// A sphere light of radius `radius` (m) at `centre` with white radiance `radiance` (W·sr⁻¹·m⁻²).
pub fn sphere_light(centre: Vec3, radius: f32, radiance: f32) -> Light {
    Light {
        position: centre.extend(radius),
        edge_u: Vec4::ZERO,
        edge_v: Vec4::ZERO,
        radiance: Vec3::splat(radiance).extend(0.0),
        kind: light_kind::SPHERE,
        two_sided: 0,
        padding: [0; 2],
    }
}

/// A one-sided quad light emitting towards `edge_u × edge_v`, white radiance `radiance`.
pub fn quad_light(corner: Vec3, edge_u: Vec3, edge_v: Vec3, radiance: f32) -> Light {
    Light {
        position: corner.extend(0.0),
        edge_u: edge_u.extend(0.0),
        edge_v: edge_v.extend(0.0),
        radiance: Vec3::splat(radiance).extend(0.0),
        kind: light_kind::QUAD,
        two_sided: 0,
        padding: [0; 2],
    }
}

/// Seed 002's two-sphere-light scene, rebuilt in the Cornell box: a small bright light low by the
/// green wall, a larger dimmer one high near the red wall, both casting shadows of the blocks.
pub fn two_sphere_lights() -> Vec<Light> {
    vec![sphere_light(Vec3::new(0.07, 0.12, 0.40), 0.035, 60.0), sphere_light(Vec3::new(0.45, 0.42, 0.12), 0.06, 25.0)]
}

/// Seed 002's long, skinny area light (a thin triangle over a bunny there; a 0.40 m × 0.02 m
/// quad under the ceiling here), emitting downwards over the blocks.
pub fn skinny_quad_light() -> Light {
    quad_light(Vec3::new(0.08, 0.54, 0.40), Vec3::new(0.40, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.02), 40.0)
}

/// A surface point seen by a camera ray: where secondary rays start.
#[derive(Copy, Clone, Debug)]
pub struct ShadingPoint {
    /// Linear pixel index.
    pub pixel: u32,
    /// Ray origin for secondary rays: the hit point offset along the normal (Wächter & Binder).
    pub origin: Vec3,
    /// Unit geometric normal, facing the camera.
    pub normal: Vec3,
    /// Luminance of the diffuse albedo (Rec. 709 weights).
    pub albedo: f32,
}

/// Traces `rays` (a camera ray stream) on `backend`, whose loaded scene must be `scene`, and
/// returns the surfaces they hit; rays that miss are left out.
pub fn shading_points(scene: &Scene, backend: &mut dyn Backend, rays: &RayStream) -> Result<Vec<ShadingPoint>> {
    let (hits, _) = backend.trace(rays)?;
    let mut points = Vec::with_capacity(rays.len());
    for i in 0..rays.len() {
        if hits.primitive[i] == NO_HIT {
            continue;
        }
        let mesh = &scene.meshes()[hits.instance[i] as usize];
        let [a, b, c] = mesh.triangles[hits.primitive[i] as usize].map(|v| mesh.positions[v as usize]);
        let bary = hits.barycentrics[i];
        let p = a + bary.x * (b - a) + bary.y * (c - a);
        let mut normal = geometric_normal(a, b, c);
        if normal.dot(rays.direction[i].xyz()) > 0.0 {
            normal = -normal;
        }
        points.push(ShadingPoint {
            pixel: rays.pixel[i],
            origin: offset_ray_origin(p, normal),
            normal,
            albedo: luminance(mesh.material.base_color),
        });
    }
    Ok(points)
}
