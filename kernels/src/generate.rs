//! The generate stage: one pinhole-camera ray per pixel, jittered within the pixel.

use crate::hash::{pcg3d, unit_float};
use glam::{UVec3, Vec2, Vec3, Vec4, Vec4Swizzles};
use raywave_shared::GenerateParams;

/// One generated ray, as the generate stage writes it into the ray stream.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct CameraRay {
    /// xyz origin in scene units, w = `tmin`.
    pub origin: Vec4,
    /// xyz unit direction, w = `tmax`.
    pub direction: Vec4,
    /// Linear pixel index `y · width + x`.
    pub pixel: u32,
}

/// Sub-pixel jitter of ray `ray_index` in `[0, 1 − 2⁻²⁴]²`, a pure function of
/// (ray index, sample index, seed). The low-discrepancy sampler replaces this in a later stage of
/// the project; this hash keeps every backend bit-identical meanwhile.
pub fn pixel_jitter(ray_index: u32, params: &GenerateParams) -> Vec2 {
    let bits = pcg3d(UVec3::new(ray_index, params.sample_index, params.seed));
    Vec2::new(unit_float(bits.x), unit_float(bits.y))
}

/// The generate stage for one invocation: the camera ray through pixel `ray_index`
/// (`< width · height`, row-major from the top-left pixel) at its jittered sub-pixel position.
pub fn generate_ray(ray_index: u32, params: &GenerateParams) -> CameraRay {
    let x = ray_index % params.width;
    let y = ray_index / params.width;
    let jitter = pixel_jitter(ray_index, params);
    let ndc_x = (x as f32 + jitter.x) / params.width as f32 * 2.0 - 1.0;
    let ndc_y = 1.0 - (y as f32 + jitter.y) / params.height as f32 * 2.0;
    let direction: Vec3 = (params.forward.xyz() + ndc_x * params.right.xyz() + ndc_y * params.up.xyz()).normalize();
    CameraRay {
        origin: params.origin.xyz().extend(params.tmin),
        direction: direction.extend(params.tmax),
        pixel: ray_index,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(width: u32, height: u32) -> GenerateParams {
        GenerateParams {
            origin: Vec4::new(1.0, 2.0, 3.0, 0.0),
            forward: Vec4::new(0.0, 0.0, 1.0, 0.0),
            right: Vec4::new(0.5, 0.0, 0.0, 0.0),
            up: Vec4::new(0.0, 0.25, 0.0, 0.0),
            width,
            height,
            sample_index: 0,
            seed: 9,
            tmin: 0.0,
            tmax: 100.0,
            padding: [0; 2],
        }
    }

    #[test]
    fn rays_are_unit_length_and_carry_their_pixel_and_range() {
        let p = params(7, 5);
        for i in 0..p.ray_count() {
            let ray = generate_ray(i, &p);
            assert_eq!(ray.pixel, i);
            assert_eq!(ray.origin, Vec4::new(1.0, 2.0, 3.0, 0.0));
            assert_eq!(ray.direction.w, 100.0);
            assert!((ray.direction.xyz().length() - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn each_ray_stays_inside_its_pixel_footprint() {
        let p = params(8, 4);
        for i in 0..p.ray_count() {
            let d = generate_ray(i, &p).direction.xyz();
            // Project back onto the image plane at distance 1 and recover the pixel coordinates.
            let plane = d / d.z;
            let px = (plane.x / 0.5 + 1.0) * 0.5 * 8.0;
            let py = (1.0 - plane.y / 0.25) * 0.5 * 4.0;
            assert_eq!(px.floor() as u32, i % 8, "ray {i} x {px}");
            assert_eq!(py.floor() as u32, i / 8, "ray {i} y {py}");
        }
    }

    #[test]
    fn image_corners_map_to_the_frustum_corners() {
        let p = params(1, 1);
        // With one pixel the jitter spans the whole frustum; direction/z stays within ±right, ±up.
        let d = generate_ray(0, &p).direction.xyz();
        assert!((d.x / d.z).abs() <= 0.5 && (d.y / d.z).abs() <= 0.25);
    }

    #[test]
    fn jitter_depends_on_sample_and_seed() {
        let a = params(4, 4);
        let b = GenerateParams { sample_index: 1, ..a };
        let c = GenerateParams { seed: 10, ..a };
        assert_ne!(pixel_jitter(3, &a), pixel_jitter(3, &b));
        assert_ne!(pixel_jitter(3, &a), pixel_jitter(3, &c));
    }
}
