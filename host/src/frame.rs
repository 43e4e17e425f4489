//! Per-frame parameters derived from the scene: the camera basis and ray interval the generate
//! stage needs.

use crate::scene::Scene;
use raywave_shared::GenerateParams;

/// Generate-stage parameters for `scene`'s camera at `width × height` (both ≥ 1), sample
/// `sample_index` with jitter seed `seed`. `tmax` covers the whole scene: twice the distance from
/// the camera to the farthest corner of the scene bounds, so it is finite and never clips geometry.
pub fn generate_params(scene: &Scene, width: u32, height: u32, sample_index: u32, seed: u32) -> GenerateParams {
    let camera = scene.camera();
    let forward = (camera.look_at - camera.position).normalize();
    let right = forward.cross(camera.up).normalize();
    let up = right.cross(forward);
    let tan_half_y = (camera.vertical_fov_degrees.to_radians() * 0.5).tan();
    let tan_half_x = tan_half_y * width as f32 / height as f32;
    let (lo, hi) = scene.bounds();
    let far = (lo - camera.position).abs().max((hi - camera.position).abs()).length();
    GenerateParams {
        origin: camera.position.extend(0.0),
        forward: forward.extend(0.0),
        right: (right * tan_half_x).extend(0.0),
        up: (up * tan_half_y).extend(0.0),
        width,
        height,
        sample_index,
        seed,
        tmin: 0.0,
        tmax: 2.0 * far.max(f32::MIN_POSITIVE),
        padding: [0; 2],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec4Swizzles;

    #[test]
    fn cornell_camera_looks_down_z_with_red_wall_on_the_left() {
        let scene = Scene::load("builtin:cornell").unwrap();
        let p = generate_params(&scene, 64, 32, 0, 0);
        assert!((p.forward.xyz() - glam::Vec3::Z).length() < 1e-6);
        // The red wall is at x ≈ 0.55 m; image right must point towards x = 0 (the green wall).
        assert!(p.right.x < 0.0);
        assert!((p.right.length() / p.up.length() - 2.0).abs() < 1e-5, "aspect 2:1");
        assert!(p.tmax.is_finite() && p.tmax > 1.0);
    }
}
