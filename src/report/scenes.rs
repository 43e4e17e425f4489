//! The lit scenes of the reports: the built-in Cornell box geometry with analytic lights placed
//! for each experiment of seed 002, and the shading points its camera sees.

use crate::kernels::sampling::light_select::luminance;
use crate::shared::stream::NO_HIT;
use crate::shared::Light;
use crate::{Backend, RayStream, Result, Scene};
use glam::{Vec3, Vec4Swizzles};

/// Seed 002's two-sphere-light scene, rebuilt in the Cornell box: a small bright light low by the
/// green wall, a larger dimmer one high near the red wall, both casting shadows of the blocks.
pub fn two_sphere_lights() -> Vec<Light> {
    vec![
        Light::sphere(Vec3::new(0.07, 0.12, 0.40), 0.035, Vec3::splat(60.0)),
        Light::sphere(Vec3::new(0.45, 0.42, 0.12), 0.06, Vec3::splat(25.0)),
    ]
}

/// Seed 002's long, skinny area light (a thin triangle over a bunny there; a 0.40 m × 0.02 m
/// quad under the ceiling here), emitting downwards over the blocks.
pub fn skinny_quad_light() -> Light {
    Light::quad(
        Vec3::new(0.08, 0.54, 0.40),
        Vec3::new(0.40, 0.0, 0.0),
        Vec3::new(0.0, 0.0, 0.02),
        Vec3::splat(40.0),
        false,
    )
}

/// A surface point seen by a camera ray: where secondary rays start.
#[derive(Copy, Clone, Debug)]
pub struct ShadingPoint {
    /// Linear pixel index.
    pub pixel: u32,
    /// Ray origin for secondary rays: the hit point offset along the normal
    /// ([`crate::scene::SurfaceHit::secondary_ray_origin`]).
    pub origin: Vec3,
    /// Unit geometric normal, facing the camera.
    pub normal: Vec3,
    /// Luminance of the diffuse albedo (Rec. 709 weights).
    pub albedo: f32,
}

/// Traces `rays` (a camera ray stream) on `backend`, whose loaded scene must be `scene`, and
/// returns the surfaces they hit (rays that miss are left out) and the rays and hits the trace
/// stage sanitized ([`crate::StageReport::sanitized`]).
pub fn shading_points(scene: &Scene, backend: &mut dyn Backend, rays: &RayStream) -> Result<(Vec<ShadingPoint>, u64)> {
    let (hits, report) = backend.trace(rays)?;
    let mut points = Vec::with_capacity(rays.len());
    for i in 0..rays.len() {
        if hits.primitive[i] == NO_HIT {
            continue;
        }
        let surface =
            scene.hit_surface(hits.instance[i], hits.primitive[i], hits.barycentrics[i], rays.direction[i].xyz());
        points.push(ShadingPoint {
            pixel: rays.pixel[i],
            origin: surface.secondary_ray_origin(),
            normal: surface.normal,
            albedo: luminance(surface.material.base_color),
        });
    }
    Ok((points, report.sanitized))
}
