//! Per-frame parameters derived from the scene: the camera basis and ray interval the generate
//! stage needs.

use crate::scene::Scene;
use raywave_shared::sampling::{sampler_kind, SamplerParams};
use raywave_shared::GenerateParams;

/// Names of the sampler kinds on the command line, indexed by their [`sampler_kind`] value.
pub const SAMPLER_NAMES: [&str; sampler_kind::COUNT as usize] = ["zsobol", "sobol", "random"];

/// Parses a sampler name (`zsobol`, `sobol` or `random`) into its [`sampler_kind`] value.
pub fn parse_sampler_kind(name: &str) -> crate::error::Result<u32> {
    SAMPLER_NAMES.iter().position(|&n| n == name).map(|k| k as u32).ok_or_else(|| {
        crate::error::Error::InvalidParameter {
            name: "sampler",
            reason: format!("unknown sampler `{name}` (expected one of {})", SAMPLER_NAMES.join(", ")),
        }
    })
}

/// The sampler `kind` (one of [`sampler_kind`]) with `seed` for a `width × height` frame of
/// `samples_per_pixel` samples: the Morton-ordered sample space of `ZSOBOL` covers the image's
/// power-of-two square and the sample count rounded up to a power of two (Sobol' nets want
/// power-of-two counts [sampling-denoise.md §1.2, §1.5]).
pub fn sampler_params(kind: u32, seed: u32, width: u32, height: u32, samples_per_pixel: u32) -> SamplerParams {
    // A side above 2³¹ rounds up to 2³², which `u32` cannot hold: 32 then fails `fits_index`.
    let log2_ceil = |n: u32| n.max(1).checked_next_power_of_two().map_or(32, u32::trailing_zeros);
    SamplerParams { kind, seed, spp_log2: log2_ceil(samples_per_pixel), resolution_log2: log2_ceil(width.max(height)) }
}

/// Most samples per pixel a frame takes (2¹⁶): far past convergence for every estimator here
/// (the reports' references use 4096).
pub const MAX_SAMPLES_PER_PIXEL: u32 = 65_536;

/// Checks a sample count per pixel before anything is known of the frame: within
/// `1..=`[`MAX_SAMPLES_PER_PIXEL`]. `name` is the option's name for the error.
pub fn check_sample_count(name: &'static str, samples_per_pixel: u32) -> crate::error::Result<()> {
    if (1..=MAX_SAMPLES_PER_PIXEL).contains(&samples_per_pixel) {
        Ok(())
    } else {
        let reason = format!("{samples_per_pixel} is outside 1..={MAX_SAMPLES_PER_PIXEL}");
        Err(crate::error::Error::InvalidParameter { name, reason })
    }
}

/// The end of [`check_samples_per_pixel`]'s errors: the samplers without its limit.
const OTHER_SAMPLERS: &str = "the sobol and random samplers have no such limit";

/// Checks a sample count per pixel for a `width × height` frame drawn by the sampler of `kind`
/// (one of [`sampler_kind`]): within `1..=`[`MAX_SAMPLES_PER_PIXEL`], and, for the blue-noise `ZSOBOL`
/// sampler, its Morton-ordered sample space (image side and count rounded up to powers of two,
/// [`SamplerParams::indexes`]) within the 32-bit index, beyond which sample indices would wrap
/// and repeat; the other kinds index any sample. `name` is the option's name for the error; an
/// image whose longer side alone overflows the index (above 65536) is named `width/height`.
pub fn check_samples_per_pixel(
    name: &'static str,
    kind: u32,
    width: u32,
    height: u32,
    samples_per_pixel: u32,
) -> crate::error::Result<()> {
    check_sample_count(name, samples_per_pixel)?;
    let fits = |samples| sampler_params(kind, 0, width, height, samples).indexes(width, height, samples);
    if !fits(1) {
        // Not the sample count's fault: the image's longer side alone overflows the index.
        let reason = format!(
            "a {width}×{height} image exceeds the sampler's 32-bit index even at 1 sample per pixel \
             (2·log2(longer side), rounded up, must be ≤ 32: a side of at most 65536; {OTHER_SAMPLERS})"
        );
        return Err(crate::error::Error::InvalidParameter { name: "width/height", reason });
    }
    if !fits(samples_per_pixel) {
        let reason = format!(
            "{samples_per_pixel} samples per pixel of a {width}×{height} image exceed the sampler's 32-bit \
             index (2·log2(side) + log2(samples), each rounded up, must be ≤ 32; {OTHER_SAMPLERS})"
        );
        return Err(crate::error::Error::InvalidParameter { name, reason });
    }
    Ok(())
}

/// Generate-stage parameters for `scene`'s pinhole camera at `width × height` (both ≥ 1): a
/// one-sample frame drawn by the default blue-noise sampler (`ZSOBOL`) with `seed`. Frames of
/// more samples take [`generate_params_with`] and a sampler sized for them ([`sampler_params`]).
pub fn generate_params(scene: &Scene, width: u32, height: u32, seed: u32) -> GenerateParams {
    let sampler = sampler_params(sampler_kind::ZSOBOL, seed, width, height, 1);
    generate_params_with(scene, width, height, 0, sampler)
}

/// Generate-stage parameters for `scene`'s camera at `width × height` (both ≥ 1), sample
/// `sample_index` drawn by `sampler`; a pinhole camera focused on the camera's look-at point
/// (set `lens_radius` for depth of field), its image right axis `forward × up`, or the reverse
/// for a [`crate::scene::Camera::mirrored`] one. `tmax` covers the whole scene: twice the distance from
/// the camera to the farthest corner of the scene bounds, so it is finite and never clips geometry
/// seen from the camera (a thin lens moves the rays' origins: add twice its radius, as
/// [`crate::lit_frame::LitFrameSettings::generate_params`] does).
pub fn generate_params_with(
    scene: &Scene,
    width: u32,
    height: u32,
    sample_index: u32,
    sampler: SamplerParams,
) -> GenerateParams {
    let camera = scene.camera();
    let forward = (camera.look_at - camera.position).normalize();
    let right = forward.cross(camera.up).normalize();
    // Made orthogonal to `forward` again: with an `up` nearly along the view, the cross product
    // is short and its rounding tilts `right` out of the image plane (beyond the generate
    // stage's check, `backend::check_generate_params`).
    let right = right.reject_from_normalized(forward).normalize();
    let up = right.cross(forward);
    // Reversed after `up` is formed from it, so that `up` keeps the camera's up side.
    let right = if camera.mirrored { -right } else { right };
    let tan_half_y = image_plane_half_height(camera.vertical_fov_degrees);
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
        tmin: 0.0,
        tmax: 2.0 * far.max(f32::MIN_POSITIVE),
        lens_radius: 0.0,
        focus_distance: (camera.look_at - camera.position).length().max(f32::MIN_POSITIVE),
        padding: 0,
        sampler,
    }
}

/// The generate stage's image-plane half height, `tan(fov / 2)`, for a vertical field of view in
/// degrees (a camera's `vertical_fov_degrees`): the length of its `up` axis, which a scene loader
/// checks against [`crate::backend::MIN_IMAGE_PLANE_AXIS_SQUARED`] exactly as formed here.
pub(crate) fn image_plane_half_height(vertical_fov_degrees: f32) -> f32 {
    (vertical_fov_degrees.to_radians() * 0.5).tan()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec4Swizzles;

    /// The sampler's own limit, for callers that check it without a backend's size check: a side
    /// over 65536 overflows the blue-noise index at any sample count and is named as the size;
    /// a count that overflows it at a size that fits is named as the option.
    #[test]
    fn the_blue_noise_index_names_the_size_or_the_samples_that_overflow_it() {
        let name = |kind, width, spp| match check_samples_per_pixel("spp", kind, width, 1, spp) {
            Err(crate::error::Error::InvalidParameter { name, .. }) => Some(name),
            Ok(()) => None,
            Err(other) => panic!("{other}"),
        };
        assert_eq!(name(sampler_kind::ZSOBOL, 65537, 1), Some("width/height"));
        assert_eq!(name(sampler_kind::ZSOBOL, 65536, 2), Some("spp"));
        assert_eq!(name(sampler_kind::ZSOBOL, 65536, 1), None);
        assert_eq!(name(sampler_kind::SOBOL, 65537, 4), None, "its own index has no such limit");
        // The longer side sizes the square, whichever it is: a portrait frame's too.
        assert_eq!(sampler_params(sampler_kind::ZSOBOL, 0, 3, 17, 4).resolution_log2, 5);
        assert!(check_samples_per_pixel("spp", sampler_kind::ZSOBOL, 1, 65536, 1).is_ok());
    }

    /// `tmax` reaches every vertex from the camera (twice the farthest corner of the bounds), also
    /// for a camera inside the scene by one corner, where the nearest corner is a hair away.
    #[test]
    fn tmax_reaches_the_farthest_vertex() {
        let cornell = Scene::load("builtin:cornell").unwrap();
        let (lo, _) = cornell.bounds();
        let camera = crate::scene::Camera {
            position: lo + glam::Vec3::splat(0.02),
            look_at: lo + glam::Vec3::splat(0.5),
            ..*cornell.camera()
        };
        let corner = Scene::new("corner camera", cornell.meshes().to_vec(), camera).unwrap();
        for scene in [&cornell, &corner] {
            let eye = scene.camera().position;
            let farthest =
                scene.meshes().iter().flat_map(|m| &m.positions).map(|p| p.distance(eye)).fold(0.0, f32::max);
            let tmax = generate_params(scene, 16, 9, 0).tmax;
            assert!(tmax >= 2.0 * farthest, "{}: tmax {tmax}, farthest vertex {farthest}", scene.name());
        }
    }

    #[test]
    fn cornell_camera_looks_down_z_with_red_wall_on_the_left() {
        let scene = Scene::load("builtin:cornell").unwrap();
        let p = generate_params(&scene, 64, 32, 0);
        assert!((p.forward.xyz() - glam::Vec3::Z).length() < 1e-6);
        // The red wall is at x ≈ 0.55 m; image right must point towards x = 0 (the green wall).
        assert!(p.right.x < 0.0);
        assert!((p.right.length() / p.up.length() - 2.0).abs() < 1e-5, "aspect 2:1");
        assert!(p.tmax.is_finite() && p.tmax > 1.0);
    }

    /// A scene camera whose `up` lies nearly along its view — which the scene accepts while their
    /// cross product normalizes — gives a basis the generate stage accepts: `right` made
    /// orthogonal to the view again after the short cross product's rounding.
    #[test]
    fn a_camera_looking_nearly_along_its_up_gives_a_valid_basis() {
        let cornell = Scene::load("builtin:cornell").unwrap();
        let mut rng = raywave_kernels::hash::CounterRng::new(5);
        for angle in [1e-3f32, 1e-4, 1e-5, 3e-6] {
            for _ in 0..200 {
                let view = rng.unit_vec3();
                let up = (view + view.any_orthonormal_vector() * angle).normalize();
                let camera = crate::scene::Camera {
                    position: glam::Vec3::ZERO,
                    look_at: view,
                    up,
                    vertical_fov_degrees: 40.0,
                    mirrored: false,
                };
                let Ok(scene) = Scene::new("nearly up", cornell.meshes().to_vec(), camera) else { continue };
                let params = generate_params(&scene, 16, 9, 0);
                crate::backend::check_generate_params(&params).unwrap_or_else(|e| panic!("{angle} {view}: {e}"));
            }
        }
    }
}
