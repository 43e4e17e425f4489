//! The explicit allocation of sampler dimensions (2-D slots) to stages.
//!
//! Every random decision in a frame reads a named slot, so stages never collide and two
//! estimators can deliberately share numbers: the shade stage draws U_N and S_N (seed 000's ratio
//! estimator) from the very same slots, which is what makes their ratio low-variance. A 1-D
//! decision reads the slot's first number.

/// Generate: sub-pixel position of the camera ray.
pub const PIXEL_JITTER: u32 = 0;
/// Generate: point on the thin-lens aperture (only read when the lens radius is > 0).
pub const LENS: u32 = 1;
/// Shade: x chooses BRDF versus light sampling (the seed's P_BRDF), y chooses the BRDF lobe
/// (P_Diff).
pub const SHADE_STRATEGY: u32 = 2;
/// Shade: the light's selection (x: by importance or uniformly, and the importance walk; y: the
/// uniformly chosen light, `LightSet::select`).
pub const SHADE_LIGHT_SELECT: u32 = 3;
/// Shade: the 2-D point warped to a light sample or a BRDF/ambient-occlusion direction.
pub const SHADE_DIRECTION: u32 = 4;
