//! FLIP, the perceptual difference between an image and its reference (Andersson, Nilsson,
//! Akenine-Möller, Oskarsson, Åström & Fairchild, "FLIP: A Difference Evaluator for Alternating
//! Images", HPG 2020), through the `nv-flip` bindings to NVIDIA's implementation. It is the LDR
//! variant, so both images are compared as an sRGB display shows them: linear radiance clamped to
//! [0, 1] at exposure 1 and encoded to 8 bits ([`srgb_image`], as `raywave render` writes PNGs).

use crate::visualize::srgb_image;
use glam::Vec3;

/// Mean FLIP error of `image` against `reference`, in [0, 1] (0: indistinguishable), both
/// `width × height` linear RGB, row-major; observed at nv-flip's default 67 pixels per degree (a
/// 0.7 m wide 4K monitor at 0.7 m).
///
/// # Panics
/// If either image does not hold `width · height` pixels (the callers pass frames of one size).
pub fn mean_flip(image: &[Vec3], reference: &[Vec3], width: u32, height: u32) -> f64 {
    let pixels = (width * height) as usize;
    assert!(image.len() == pixels && reference.len() == pixels, "FLIP of images of different sizes");
    let encode =
        |colors: &[Vec3]| nv_flip::FlipImageRgb8::with_data(width, height, srgb_image(colors, width, height).as_raw());
    let error_map = nv_flip::flip(encode(reference), encode(image), nv_flip::DEFAULT_PIXELS_PER_DEGREE);
    // The mean in f64: nv-flip's `FlipPool::mean` sums in f32, 0.97 % low over a 1024² map of 0.03.
    let errors = error_map.to_vec();
    errors.iter().map(|&e| f64::from(e)).sum::<f64>() / errors.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_images_score_zero_and_differences_score_more() {
        let (width, height) = (32, 24);
        let reference: Vec<Vec3> =
            (0..width * height).map(|i| Vec3::splat(0.2 + 0.6 * (i % width) as f32 / width as f32)).collect();
        assert_eq!(mean_flip(&reference, &reference, width, height), 0.0);
        let slightly: Vec<Vec3> = reference.iter().map(|&c| c * 1.05).collect();
        let very: Vec<Vec3> = reference.iter().map(|&c| c * 0.3).collect();
        let (small, large) =
            (mean_flip(&slightly, &reference, width, height), mean_flip(&very, &reference, width, height));
        assert!(0.0 < small && small < large && large <= 1.0, "{small} {large}");
    }

    /// Two flat images differ by the same FLIP error at every pixel, whatever their size: the
    /// mean over a 1024² map (the reports' largest) is that of a 16² one. Summed in f32 it had
    /// come out 0.97 % low for an error of 0.03.
    #[test]
    fn the_mean_holds_over_the_largest_report_image() {
        let mean_of_flat = |side: u32| {
            let pixels = (side * side) as usize;
            mean_flip(&vec![Vec3::splat(0.5); pixels], &vec![Vec3::splat(0.45); pixels], side, side)
        };
        let (small, large) = (mean_of_flat(16), mean_of_flat(1024));
        assert!(small > 0.0 && (large - small).abs() <= 1e-5 * small, "{large} against {small}");
    }
}
