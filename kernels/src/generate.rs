//! The generate stage: one camera ray per pixel, placed by the sampler within the pixel and, for a
//! thin-lens camera, on the aperture.

use crate::sampling::{dims, sampler, warp};
use glam::{UVec2, Vec2, Vec3, Vec4, Vec4Swizzles};
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

/// The pixel `(x, y)` of ray `ray_index` (row-major from the top-left pixel).
pub fn ray_pixel(ray_index: u32, params: &GenerateParams) -> UVec2 {
    let width = params.width.max(1);
    UVec2::new(ray_index % width, ray_index / width)
}

/// Sub-pixel position of ray `ray_index` in `[0, 1 − 2⁻²⁴]²`: slot
/// [`dims::PIXEL_JITTER`] of the frame's sampler.
pub fn pixel_jitter(ray_index: u32, params: &GenerateParams) -> Vec2 {
    sampler::sample_2d(&params.sampler, ray_pixel(ray_index, params), params.sample_index, dims::PIXEL_JITTER)
}

/// The generate stage for one invocation: the camera ray through pixel `ray_index`
/// (`< width · height`) at its sampled sub-pixel position. With `lens_radius > 0` the origin is a
/// sampled point on the aperture (concentric disk, slot [`dims::LENS`]) and the ray passes through
/// the point the pinhole ray reaches on the plane in focus, so that plane stays sharp.
pub fn generate_ray(ray_index: u32, params: &GenerateParams) -> CameraRay {
    let pixel = ray_pixel(ray_index, params);
    let jitter = pixel_jitter(ray_index, params);
    let ndc_x = (pixel.x as f32 + jitter.x) / params.width as f32 * 2.0 - 1.0;
    let ndc_y = 1.0 - (pixel.y as f32 + jitter.y) / params.height as f32 * 2.0;
    // `forward` is unit and `right`, `up` are orthogonal to it, so this direction's component
    // along the view axis is exactly 1 and `focus_distance · pinhole` lies on the focal plane.
    let pinhole: Vec3 = params.forward.xyz() + ndc_x * params.right.xyz() + ndc_y * params.up.xyz();
    let mut origin = params.origin.xyz();
    let mut direction = pinhole.normalize();
    if params.lens_radius > 0.0 {
        let lens =
            warp::sample_concentric_disk(sampler::sample_2d(&params.sampler, pixel, params.sample_index, dims::LENS))
                * params.lens_radius;
        let offset = lens.x * params.right.xyz().normalize() + lens.y * params.up.xyz().normalize();
        // From the lens point to the focal point, both relative to the camera: in world
        // coordinates each had rounded to the camera position's `f32` grid, and their difference
        // with them — 10⁵ from the origin with a 1 m focus, directions snapped to 2.5-pixel
        // steps, and a focus below half a grid step turned every ray sideways. Only the start
        // point rounds there now, a shift as fine as the scene's own vertices.
        let to_focus = pinhole * params.focus_distance - offset;
        origin += offset;
        // Scaled before its length is taken: `|to_focus|²` overflows f32 from about 10¹⁹ (a far
        // focus plane with a wide field of view), which left rays without a direction.
        let scale = to_focus.abs().max_element();
        // Its component along the view is the focus distance (the offset lies in the lens
        // plane): a subnormal one underflows, and 0/0 had made the ray NaN: that ray keeps the
        // pinhole's. `MIN_POSITIVE`, not 0, so that a GPU flushing a subnormal scale to 0 takes
        // the same branch.
        if scale >= f32::MIN_POSITIVE {
            direction = (to_focus / scale).normalize();
        }
    }
    CameraRay { origin: origin.extend(params.tmin), direction: direction.extend(params.tmax), pixel: ray_index }
}

#[cfg(test)]
mod tests {
    use super::*;
    use raywave_shared::sampling::{sampler_kind, SamplerParams};

    fn params(width: u32, height: u32) -> GenerateParams {
        GenerateParams {
            origin: Vec4::new(1.0, 2.0, 3.0, 0.0),
            forward: Vec4::new(0.0, 0.0, 1.0, 0.0),
            right: Vec4::new(0.5, 0.0, 0.0, 0.0),
            up: Vec4::new(0.0, 0.25, 0.0, 0.0),
            width,
            height,
            sample_index: 0,
            tmin: 0.0,
            tmax: 100.0,
            lens_radius: 0.0,
            focus_distance: 1.0,
            padding: 0,
            sampler: SamplerParams { kind: sampler_kind::ZSOBOL, seed: 9, spp_log2: 2, resolution_log2: 3 },
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
        for kind in 0..sampler_kind::COUNT {
            for sample_index in 0..4 {
                let mut p = params(8, 4);
                p.sampler.kind = kind;
                p.sample_index = sample_index;
                for i in 0..p.ray_count() {
                    let d = generate_ray(i, &p).direction.xyz();
                    // Project back onto the image plane at distance 1 and recover the pixel.
                    let plane = d / d.z;
                    let px = (plane.x / 0.5 + 1.0) * 0.5 * 8.0;
                    let py = (1.0 - plane.y / 0.25) * 0.5 * 4.0;
                    assert_eq!(px.floor() as u32, i % 8, "kind {kind} ray {i} x {px}");
                    assert_eq!(py.floor() as u32, i / 8, "kind {kind} ray {i} y {py}");
                }
            }
        }
    }

    #[test]
    fn image_corners_map_to_the_frustum_corners() {
        // With one pixel the jitter spans the whole frustum: over its samples, direction/z stays
        // within ±right, ±up and comes near every corner.
        let mut p = params(1, 1);
        p.sampler.spp_log2 = 8;
        let mut near_corner = [false; 4];
        for sample_index in 0..256 {
            let d = generate_ray(0, &GenerateParams { sample_index, ..p }).direction.xyz();
            let (x, y) = (d.x / d.z / 0.5, d.y / d.z / 0.25);
            assert!(x.abs() <= 1.0 && y.abs() <= 1.0, "sample {sample_index}: ({x}, {y}) outside the frustum");
            if x.abs() > 0.8 && y.abs() > 0.8 {
                near_corner[usize::from(x > 0.0) + 2 * usize::from(y > 0.0)] = true;
            }
        }
        assert_eq!(near_corner, [true; 4], "256 stratified samples reach within 10 % of each corner");
    }

    #[test]
    fn jitter_depends_on_sample_and_seed() {
        let a = params(4, 4);
        let b = GenerateParams { sample_index: 1, ..a };
        let mut c = a;
        c.sampler.seed = 10;
        assert_ne!(pixel_jitter(3, &a), pixel_jitter(3, &b));
        assert_ne!(pixel_jitter(3, &a), pixel_jitter(3, &c));
    }

    #[test]
    fn thin_lens_rays_start_on_the_aperture_and_meet_on_the_focal_plane() {
        let mut p = params(4, 4);
        p.lens_radius = 0.1;
        p.focus_distance = 5.0;
        let mut widest: f32 = 0.0;
        for i in 0..p.ray_count() {
            for sample_index in 0..4 {
                let ray = generate_ray(i, &GenerateParams { sample_index, ..p });
                let offset = ray.origin.xyz() - p.origin.xyz();
                assert!(offset.length() <= 0.1 + 1e-6 && offset.z.abs() < 1e-6, "origin off the lens");
                widest = widest.max(offset.length());
                let d = ray.direction.xyz();
                assert!((d.length() - 1.0).abs() < 1e-5);
                // Where the ray crosses the focal plane z = 3 + 5: where the pinhole ray of the
                // same sample (the same pixel jitter) crosses it.
                let focus_point = ray.origin.xyz() + ((8.0 - ray.origin.z) / d.z) * d;
                let pinhole = generate_ray(i, &GenerateParams { sample_index, lens_radius: 0.0, ..p });
                let d = pinhole.direction.xyz();
                let expected = pinhole.origin.xyz() + (5.0 / d.z) * d;
                assert!((focus_point - expected).length() < 1e-4, "{focus_point:?} vs {expected:?}");
            }
        }
        assert!(widest > 0.05, "the lens samples its aperture (widest offset {widest})");
    }

    #[test]
    fn far_focus_planes_and_wide_apertures_keep_unit_directions() {
        // 10¹⁸, far beyond the host's limit for both (10⁸); with a wide field of view (179°: right and up about
        // a hundred times forward) the focus point lies near 10²⁰ and its squared distance
        // overflows f32.
        let mut p = params(4, 4);
        p.right *= 200.0;
        p.up *= 400.0;
        for (lens_radius, focus_distance) in [(1.0e18, 1.0), (0.1, 1.0e18), (1.0e18, 1.0e18)] {
            let p = GenerateParams { lens_radius, focus_distance, ..p };
            for i in 0..p.ray_count() {
                let d = generate_ray(i, &p).direction.xyz();
                assert!(d.is_finite() && (d.length() - 1.0).abs() < 1e-5, "{lens_radius} {focus_distance}: {d}");
            }
        }
    }

    /// A subnormal focus distance (and an aperture within its limit) leaves no direction to the
    /// focal point that `f32` can hold: the ray keeps the pinhole's (it had been 0/0, NaN, for
    /// every pixel).
    #[test]
    fn a_focus_below_the_normal_floats_keeps_the_pinhole_direction() {
        let pinhole = params(4, 4);
        let p = GenerateParams { lens_radius: 1e-42, focus_distance: 1e-40, ..pinhole };
        for i in 0..p.ray_count() {
            let ray = generate_ray(i, &p);
            assert_eq!(ray.origin, pinhole.origin, "the lens offset rounds away");
            assert_eq!(ray.direction, generate_ray(i, &pinhole).direction);
        }
    }

    /// A camera 512² wide, 40° high, looking along +z from `origin`, with a lens.
    fn far_camera(origin: Vec3, lens_radius: f32, focus_distance: f32) -> GenerateParams {
        let t = 20f32.to_radians().tan();
        GenerateParams {
            origin: origin.extend(0.0),
            right: Vec4::new(t, 0.0, 0.0, 0.0),
            up: Vec4::new(0.0, t, 0.0, 0.0),
            sampler: SamplerParams { kind: sampler_kind::ZSOBOL, seed: 1, spp_log2: 0, resolution_log2: 9 },
            lens_radius,
            focus_distance,
            ..params(512, 512)
        }
    }

    /// Far from the origin a barely open lens aims as the pinhole does (its rays within the
    /// lens's 10⁻⁶ rad of it), and a macro focus along the view still looks ahead: the focal and
    /// lens points, built in world coordinates, had rounded to the camera position's grid — at
    /// 10⁵ directions 3.6·10⁻³ rad (2.5 pixels) off, and with a 3 mm focus every ray sideways.
    #[test]
    fn thin_lens_directions_do_not_round_with_the_camera_position() {
        for origin in [Vec3::new(1e5, 0.0, 0.0), Vec3::new(-3e6, 2e6, 0.0)] {
            let lens = far_camera(origin, 1e-6, 1.0);
            let pinhole = GenerateParams { lens_radius: 0.0, ..lens };
            for i in (256 * 512..257 * 512).chain(0..512) {
                let [a, b] = [&lens, &pinhole].map(|p| generate_ray(i, p).direction.truncate());
                // The sine of their angle (`acos` of the dot product has no precision near 0).
                assert!(a.cross(b).length() < 1e-5, "at {origin}, ray {i}: {a} against the pinhole's {b}");
            }
        }
        let macro_lens = far_camera(Vec3::new(0.0, 0.0, 1e5), 1e-3, 0.003);
        for i in 0..macro_lens.ray_count() {
            let direction = generate_ray(i, &macro_lens).direction;
            assert!(direction.z > 0.5, "ray {i}: {direction}");
        }
    }
}
