//! Parameters of the generate stage (camera rays).

use crate::sampling::SamplerParams;
use bytemuck::{Pod, Zeroable};
use glam::Vec4;

/// Push constants of the generate stage: a pinhole or thin-lens camera, the image it covers and
/// the sampler that places the rays.
///
/// The camera basis is pre-scaled on the host so the kernel needs no trigonometry: a pixel at
/// normalised device coordinates `(x, y)` in `[-1, 1]²` (y up) looks along
/// `forward + x·right + y·up`.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Pod, Zeroable)]
pub struct GenerateParams {
    /// Camera position in scene units (xyz); w is unused and 0.
    pub origin: Vec4,
    /// Unit view direction (xyz); w unused.
    pub forward: Vec4,
    /// Camera right axis scaled by `tan(horizontal_fov / 2)` (xyz); w unused.
    pub right: Vec4,
    /// Camera up axis scaled by `tan(vertical_fov / 2)` (xyz); w unused.
    pub up: Vec4,
    /// Image width in pixels, ≥ 1.
    pub width: u32,
    /// Image height in pixels, ≥ 1.
    pub height: u32,
    /// Index of the sample within the pixel (0 for the first sample of a frame).
    pub sample_index: u32,
    /// Ray `tmin` in scene units (≥ 0).
    pub tmin: f32,
    /// Ray `tmax` in scene units (finite, > `tmin`).
    pub tmax: f32,
    /// Thin-lens aperture radius in scene units; 0 is a pinhole camera.
    pub lens_radius: f32,
    /// Distance along the view direction of the plane in focus, in scene units (> 0; only read
    /// when `lens_radius` > 0).
    pub focus_distance: f32,
    /// Explicit padding to a 16-byte multiple; always 0.
    pub padding: u32,
    /// The sampler of the pixel jitter and lens positions (slots `PIXEL_JITTER` and `LENS`).
    pub sampler: SamplerParams,
}

const _: () = assert!(core::mem::size_of::<GenerateParams>() == 112);
const _: () = assert!(core::mem::align_of::<GenerateParams>() == 16);

impl GenerateParams {
    /// Number of rays (= pixels) the stage writes: one per pixel, `width · height`.
    pub fn ray_count(&self) -> u32 {
        self.width * self.height
    }
}
