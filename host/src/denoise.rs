//! The denoise stage on the host: its inputs (the accumulated `U`, `U_N`, `S_N` and a G-buffer),
//! the methods compared in the error-vs-time report, their passes and the bytes each moves.
//! The passes themselves are `raywave_kernels::denoise`, run by each backend's `denoise`.

use crate::error::{Error, Result};
use crate::shading::ShadeAccumulator;
use glam::{Vec3, Vec4};
use raywave_kernels::denoise::guide::is_surface_depth;
use raywave_kernels::sampling::light_select::luminance;
use raywave_kernels::shade::stage::{Surface, SMALLEST_RADIANCE};
use raywave_shared::denoise::{
    axis, MAX_EDGE_WEIGHT, MAX_FILTERED_RADIANCE, MAX_RADIUS, MAX_SVGF_PHI_COLOR, MAX_SVGF_VARIANCE_BOOST,
    MIN_EDGE_WEIGHT, MIN_SVGF_PHI_COLOR,
};
use raywave_shared::DenoiseParams;

/// A denoiser of the shadow term.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum DenoiseMethod {
    /// Seed 000's filter: TV noise estimate → separable joint bilateral of `S_N` and `U_N` →
    /// `U · den(S_N)/den(U_N)`.
    Tv,
    /// The baseline: SVGF-style variance-guided à-trous of the ratio `S_N/U_N`
    /// (`params.atrous_iterations`, Falcor's 4 on large frames), same edge stops →
    /// `U · den(ratio)`.
    Svgf,
    /// No filter: the composite pass alone, `emitted + U · S_N/U_N` — the raw ratio estimate
    /// (or, given [`DenoiseInput::stochastic`], the raw `S_N`), made by the same pass that ends the
    /// filters, so a report times every method's image alike.
    None,
}

/// The TV filter's passes, in order, where it filters (see [`DenoiseMethod::passes`]).
pub(crate) const TV_PASSES: [DenoisePass; 6] = [
    DenoisePass::Ratio,
    DenoisePass::Noise,
    DenoisePass::NoiseBlur,
    DenoisePass::BilateralX,
    DenoisePass::BilateralY,
    DenoisePass::Composite,
];

impl DenoiseMethod {
    /// The method's name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::Tv => "tv",
            Self::Svgf => "svgf",
            Self::None => "none",
        }
    }

    /// The passes the method runs with `params`, in order. The TV filter is only its composite
    /// (it reduces to [`DenoiseMethod::None`]) where it would leave every pixel as it is
    /// ([`DenoiseParams::tv_filter_is_identity`]).
    pub fn passes(self, params: &DenoiseParams) -> Vec<DenoisePass> {
        match self {
            Self::None => vec![DenoisePass::Composite],
            Self::Tv if params.tv_filter_is_identity() => Self::None.passes(params),
            Self::Tv => TV_PASSES.to_vec(),
            Self::Svgf => {
                let mut passes = vec![DenoisePass::Ratio, DenoisePass::SvgfVariance];
                let iterations = params.atrous_iterations.clamp(1, MAX_ATROUS_ITERATIONS);
                passes.extend((0..iterations).map(|k| DenoisePass::SvgfAtrous { step: 1 << k }));
                passes.push(DenoisePass::SvgfComposite);
                passes
            }
        }
    }
}

impl std::str::FromStr for DenoiseMethod {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "tv" => Ok(Self::Tv),
            "svgf" => Ok(Self::Svgf),
            "none" => Ok(Self::None),
            other => Err(Error::InvalidParameter {
                name: "denoise",
                reason: format!("unknown denoiser `{other}` (expected tv, svgf or none)"),
            }),
        }
    }
}

/// Most à-trous iterations of the SVGF baseline: 4, Falcor SVGFPass's `mFilterIterations`
/// (steps 1, 2, 4, 8).
pub const MAX_ATROUS_ITERATIONS: u32 = 4;

/// One pass of a denoiser.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum DenoisePass {
    /// The ratio image `S_N/U_N`.
    Ratio,
    /// Raw TV noise estimate of the ratio.
    Noise,
    /// 3×3 blur of the noise estimate.
    NoiseBlur,
    /// Joint bilateral pass along rows.
    BilateralX,
    /// Joint bilateral pass along columns.
    BilateralY,
    /// `emitted + U · den(S_N)/den(U_N)`.
    Composite,
    /// SVGF: the ratio's spatial variance.
    SvgfVariance,
    /// SVGF: one à-trous iteration with this tap spacing.
    SvgfAtrous {
        /// Tap spacing in pixels.
        step: u32,
    },
    /// SVGF: `emitted + U · den(ratio)`.
    SvgfComposite,
}

impl DenoisePass {
    /// The pass's name in timings.
    pub fn name(self) -> &'static str {
        match self {
            Self::Ratio => "denoise ratio",
            Self::Noise => "denoise noise",
            Self::NoiseBlur => "denoise noise blur",
            Self::BilateralX => "denoise bilateral x",
            Self::BilateralY => "denoise bilateral y",
            Self::Composite => "denoise composite",
            Self::SvgfVariance => "svgf variance",
            // Each iteration by its step (`MAX_ATROUS_ITERATIONS` makes them 1, 2, 4, 8), so that
            // a timing or bench line says which it is.
            Self::SvgfAtrous { step: 1 } => "svgf atrous step 1",
            Self::SvgfAtrous { step: 2 } => "svgf atrous step 2",
            Self::SvgfAtrous { step: 4 } => "svgf atrous step 4",
            Self::SvgfAtrous { step: 8 } => "svgf atrous step 8",
            Self::SvgfAtrous { .. } => "svgf atrous",
            Self::SvgfComposite => "svgf composite",
        }
    }

    /// Whether the pass is a composite: a denoiser's last pass, its stage boundary, and the only
    /// pass that counts sanitized values ([`crate::backend::StageReport::sanitized`]).
    pub fn is_composite(self) -> bool {
        matches!(self, Self::Composite | Self::SvgfComposite)
    }

    /// Bytes the pass must move per pixel: each buffer it reads or writes, once (neighbourhood
    /// taps are assumed to hit the cache or, for the bilateral passes, workgroup memory). `Vec4`
    /// buffers are 16 bytes, the noise 4.
    pub fn bytes_per_pixel(self) -> u64 {
        const V: u64 = 16;
        const F: u64 = 4;
        match self {
            Self::Ratio => 3 * V,
            Self::Noise => V + F,
            Self::NoiseBlur => 2 * F,
            Self::BilateralX | Self::BilateralY => 4 * V + F + 2 * V,
            Self::Composite => 4 * V + V,
            Self::SvgfVariance => 3 * V + V,
            Self::SvgfAtrous { .. } => 3 * V + V,
            Self::SvgfComposite => 3 * V + V,
        }
    }
}

/// Which working buffers a method's passes write beyond its inputs: a backend (raywave's, or an
/// engine's that runs the passes itself) allocates those at the image's size and no others (rule 4
/// of the design, model only what the frame needs), so that `--denoise none`, the composite
/// alone, takes none of them.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct WorkingBuffers {
    /// The raw and the blurred TV noise estimate ([`DenoisePass::Noise`], [`DenoisePass::NoiseBlur`]).
    pub noise: bool,
    /// What the bilateral passes write: the filtered `S_N` and `U_N`.
    pub filtered: bool,
    /// The ratio image ([`DenoisePass::Ratio`]).
    pub ratio: bool,
    /// What the SVGF passes write: the filtered ratio.
    pub filtered_ratio: bool,
}

impl WorkingBuffers {
    /// The buffers `passes` write.
    pub fn for_passes(passes: &[DenoisePass]) -> Self {
        let written_by = |wanted: fn(&DenoisePass) -> bool| passes.iter().any(wanted);
        Self {
            noise: written_by(|pass| matches!(pass, DenoisePass::Noise | DenoisePass::NoiseBlur)),
            filtered: written_by(|pass| matches!(pass, DenoisePass::BilateralX | DenoisePass::BilateralY)),
            ratio: written_by(|pass| *pass == DenoisePass::Ratio),
            filtered_ratio: written_by(|pass| {
                matches!(pass, DenoisePass::SvgfVariance | DenoisePass::SvgfAtrous { .. })
            }),
        }
    }

    /// Whether a pass reads the geometry guides, position and normal: the edge-stopping filters
    /// (bilateral and SVGF), which are the passes that write the filtered buffers.
    pub fn guides_read(self) -> bool {
        self.filtered || self.filtered_ratio
    }
}

/// Whether the denoiser's edge stops see `surface` (a finite point at a depth of at least
/// 2⁻¹²⁶, [`is_surface_depth`]); where not, its pixel has no G-buffer surface.
pub fn is_guide_surface(surface: &Surface) -> bool {
    surface.position.is_finite() && is_surface_depth(surface.position.w)
}

/// Everything a denoiser reads, one entry per pixel of a `width × height` image (row-major).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DenoiseInput {
    /// Surface point and depth along the camera ray (w > 0; 0 = no surface).
    pub position: Vec<Vec4>,
    /// Unit normal facing the camera and the analytic luminance `lum(U)` (w).
    pub normal: Vec<Vec4>,
    /// Analytic unshadowed radiance `U` (rgb).
    pub analytic: Vec<Vec4>,
    /// Emitted radiance seen directly (rgb).
    pub emitted: Vec<Vec4>,
    /// `S_N` (rgb).
    pub shadowed: Vec<Vec4>,
    /// `U_N` (rgb).
    pub unshadowed: Vec<Vec4>,
}

impl DenoiseInput {
    /// The inputs of a frame: the accumulated estimates and the G-buffer of `surfaces` (the
    /// surface each pixel's camera ray hit; when the camera jitters, that of the first sample
    /// whose ray hit one, [`crate::lit_frame::shade_samples`]). Both are
    /// one entry per pixel; a `surfaces` of another length than the accumulator's gives buffers
    /// of different lengths, which [`DenoiseInput::check`] (run by every denoiser) refuses.
    pub fn new(surfaces: &[Surface], accumulator: &ShadeAccumulator) -> Self {
        let analytic = accumulator.analytic();
        let position = surfaces.iter().map(|s| if is_guide_surface(s) { s.position } else { Vec4::ZERO }).collect();
        let normal = surfaces.iter().zip(&analytic).map(|(s, &u)| s.normal.truncate().extend(luminance(u))).collect();
        let four = |v: Vec<Vec3>| v.into_iter().map(|c| c.extend(0.0)).collect();
        Self {
            position,
            normal,
            analytic: four(analytic),
            emitted: four(accumulator.emitted()),
            shadowed: four(accumulator.shadowed()),
            unshadowed: four(accumulator.unshadowed()),
        }
    }

    /// The inputs that make a denoiser filter the fully stochastic image `S_N` (the
    /// "stochastic+tv" baseline): `U_N` and `U` replaced by one constant per channel — the mean of `S_N`
    /// over the surfaces — so the noise estimate sees `S_N` at the scale of a ratio and the
    /// composite returns `den(S_N)` (up to rounding, for pixels below 10⁴ times that mean, where
    /// `shadow_ratio` clamps). The G-buffer (edge stops) stays the same.
    pub fn stochastic(&self) -> Self {
        // Summed in f64: 2·10⁶ pixels of 2·10³² overflow an f32 sum (the mean becoming ∞ and
        // every pixel NaN), and an f32 sum of that many terms drifts by percents long before.
        let (sum, count) = self
            .shadowed
            .iter()
            .zip(&self.position)
            .filter(|(_, p)| is_surface_depth(p.w))
            .fold((glam::DVec4::ZERO, 0usize), |(sum, count), (&s, _)| (sum + s.as_dvec4(), count + 1));
        let mean = (sum / count.max(1) as f64).as_vec4();
        // A channel no light reaches (mean 0) takes any constant: its S_N is 0 everywhere.
        let lit = mean.cmpge(Vec4::splat(SMALLEST_RADIANCE));
        let scale = Vec4::select(lit, mean, Vec4::ONE).truncate().extend(0.0);
        Self {
            unshadowed: vec![scale; self.shadowed.len()],
            analytic: vec![scale; self.shadowed.len()],
            ..self.clone()
        }
    }

    /// Pixels in the image.
    pub fn len(&self) -> usize {
        self.position.len()
    }

    /// Whether the image is empty.
    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// Checks the inputs against `params`: the bilateral passes' invocation counts fit 32 bits
    /// ([`DenoiseParams::bilateral_invocations`]; for every method, so that every backend and
    /// method accept the same images), every buffer holds `width · height` entries, the radius
    /// is within `1..=MAX_RADIUS`, the estimates average at least one sample, each edge weight
    /// is 0 or within [[`MIN_EDGE_WEIGHT`], [`MAX_EDGE_WEIGHT`]], SVGF's `phiColor` within
    /// [[`MIN_SVGF_PHI_COLOR`], [`MAX_SVGF_PHI_COLOR`]], its variance boost within
    /// [0, [`MAX_SVGF_VARIANCE_BOOST`]] (so that every scaled weight in the kernels is finite and
    /// normal; the error names the field), SVGF's à-trous iterations within
    /// `1..=MAX_ATROUS_ITERATIONS` (checked for every method, as the radius is), and every value
    /// is finite, with the radiances (`U`, emitted, `S_N`, `U_N`: rgb) and the analytic
    /// luminance (`normal.w`) not negative, and `S_N`, `U_N` at most [`MAX_FILTERED_RADIANCE`],
    /// below which the filter's sums stay finite. One NaN or negative pixel would otherwise spread
    /// through the noise estimate and the filter taps to its neighbours (a 7 × 7 block at R = 3),
    /// or leave the stage as NaN (an emitted NaN).
    /// Cost: one read of the six buffers, about 20 ms for a 1920 × 1080 frame on the 2-vCPU test
    /// machine (≈ 10 GB/s, memory-bound; the upload to a Vulkan device reads them once more).
    pub fn check(&self, params: &DenoiseParams) -> Result<()> {
        #[cfg(feature = "vulkan")]
        crate::vulkan::driver_lock::debug_assert_unheld("the denoise inputs' scan");
        let pixels = u64::from(params.width) * u64::from(params.height);
        let lengths = self.buffers().map(|(_, buffer, _)| buffer.len());
        let reason = if pixels == 0 {
            Some("the image is empty".to_owned())
        } else if let Some(reason) = bilateral_problem(params) {
            Some(reason)
        } else if lengths.iter().any(|&len| len as u64 != pixels) {
            Some(format!("{}×{} pixels but buffers of {lengths:?} entries", params.width, params.height))
        } else if let Some(reason) = radius_problem(params.radius) {
            Some(reason)
        } else if params.samples_per_pixel == 0 {
            Some("samples per pixel is 0 (the estimates average at least one sample)".to_owned())
        } else if let Some(reason) = weight_problem(params) {
            Some(reason)
        } else if !(1..=MAX_ATROUS_ITERATIONS).contains(&params.atrous_iterations) {
            // The passes had clamped it silently: 0 ran one iteration, 8 ran four.
            Some(format!(
                "SVGF's à-trous iterations {} are outside 1..={MAX_ATROUS_ITERATIONS}",
                params.atrous_iterations
            ))
        } else {
            self.first_invalid_value(params.width)
        };
        match reason {
            Some(reason) => Err(Error::InvalidParameter { name: "denoise", reason }),
            None => Ok(()),
        }
    }

    /// The six buffers, named, in declaration order, with the rule their values follow.
    fn buffers(&self) -> [(&'static str, &[Vec4], ValueRule); 6] {
        [
            ("position", &self.position, ValueRule::Finite),
            ("normal", &self.normal, ValueRule::LuminanceInW),
            ("analytic", &self.analytic, ValueRule::Radiance),
            ("emitted", &self.emitted, ValueRule::Radiance),
            ("shadowed", &self.shadowed, ValueRule::FilteredRadiance),
            ("unshadowed", &self.unshadowed, ValueRule::FilteredRadiance),
        ]
    }

    /// The first pixel holding a value the denoiser cannot filter ([`ValueRule`]), named by
    /// buffer and pixel `(x, y)` of a `width`-wide image.
    fn first_invalid_value(&self, width: u32) -> Option<String> {
        self.buffers().into_iter().find_map(|(name, buffer, rule)| {
            buffer.iter().enumerate().find_map(|(i, &value)| {
                let why = rule.violation(value)?;
                let (x, y) = (i as u64 % u64::from(width), i as u64 / u64::from(width));
                Some(format!("{name}[{i}] (pixel {x}, {y}) = {value} {why}"))
            })
        })
    }
}

/// What the values of one [`DenoiseInput`] buffer must be.
#[derive(Clone, Copy)]
enum ValueRule {
    /// Finite.
    Finite,
    /// Finite, rgb not negative (a radiance).
    Radiance,
    /// A radiance the filter sums: also at most [`MAX_FILTERED_RADIANCE`].
    FilteredRadiance,
    /// Finite, w not negative (the analytic luminance beside the normal).
    LuminanceInW,
}

impl ValueRule {
    /// Why `value` breaks the rule, if it does.
    fn violation(self, value: Vec4) -> Option<&'static str> {
        if !value.is_finite() {
            Some("is not finite")
        } else if matches!(self, Self::Radiance | Self::FilteredRadiance) && value.truncate().min_element() < 0.0 {
            Some("is a negative radiance")
        } else if matches!(self, Self::FilteredRadiance) && value.truncate().max_element() > MAX_FILTERED_RADIANCE {
            Some("exceeds MAX_FILTERED_RADIANCE (f32::MAX / 32), beyond which the filter's sums overflow")
        } else if matches!(self, Self::LuminanceInW) && value.w < 0.0 {
            Some("has a negative analytic luminance (w)")
        } else {
            None
        }
    }
}

/// Why `params`' filter weights fall outside the limits within which every scaled weight in the
/// kernels is finite and normal, naming the field, or `None`: each edge weight 0 or within
/// [[`MIN_EDGE_WEIGHT`], [`MAX_EDGE_WEIGHT`]], SVGF's `phiColor` (`svgf.x`) within
/// [[`MIN_SVGF_PHI_COLOR`], [`MAX_SVGF_PHI_COLOR`]] and its variance boost (`svgf.y`) within
/// [0, [`MAX_SVGF_VARIANCE_BOOST`]] (NaN is in none). Beyond them the filter had silently done
/// nothing (`Wd` = 10³⁸) or a GPU flushing a subnormal `phiColor` had dropped taps the CPU kept
/// (the limits' docs). Below them: a negative edge weight lifts its stop above 1 (the filter's
/// sums could then overflow below [`MAX_FILTERED_RADIANCE`]), `phiColor` ≤ 0 turns the luminance
/// stop into `exp(+|Δl|/|φ|)` (favouring the most different taps) or NaN, and a negative boost
/// zeroes the variance.
fn weight_problem(params: &DenoiseParams) -> Option<String> {
    const EDGE_FIELDS: [&str; 4] = [
        "edge_weights.x (depth Wd)",
        "edge_weights.y (normal Wn)",
        "edge_weights.z (plane Wp)",
        "edge_weights.w (analytic Wa)",
    ];
    let edge_range = MIN_EDGE_WEIGHT..=MAX_EDGE_WEIGHT;
    for (field, weight) in EDGE_FIELDS.into_iter().zip(params.edge_weights.to_array()) {
        if !(weight == 0.0 || edge_range.contains(&weight)) {
            return Some(format!(
                "edge weight {field} = {weight:e} is neither 0 nor within [{MIN_EDGE_WEIGHT:e}, {MAX_EDGE_WEIGHT:e}]"
            ));
        }
    }
    let (phi_color, boost) = (params.svgf.x, params.svgf.y);
    if !(MIN_SVGF_PHI_COLOR..=MAX_SVGF_PHI_COLOR).contains(&phi_color) {
        Some(format!(
            "SVGF phiColor (svgf.x) = {phi_color:e} is outside [{MIN_SVGF_PHI_COLOR:e}, {MAX_SVGF_PHI_COLOR:e}]"
        ))
    } else if !(0.0..=MAX_SVGF_VARIANCE_BOOST).contains(&boost) {
        Some(format!("SVGF variance boost (svgf.y) = {boost:e} is outside [0, {MAX_SVGF_VARIANCE_BOOST:e}]"))
    } else {
        None
    }
}

/// Why `radius` cannot be a filter radius, or `None` if it can: it must be within
/// `1..=MAX_RADIUS`, the pixels a Vulkan bilateral workgroup keeps on each side of its segment.
fn radius_problem(radius: u32) -> Option<String> {
    (!(1..=MAX_RADIUS).contains(&radius)).then(|| format!("radius {radius} outside 1..={MAX_RADIUS}"))
}

/// The invocations of `params`' bilateral pass along `params.axis`
/// ([`DenoiseParams::bilateral_invocations`]), or why no dispatch covers them: more than
/// `u32::MAX`, as along y for a 2^26 × 1 image, whose 2^26 columns take one workgroup each.
pub(crate) fn bilateral_invocations(params: &DenoiseParams) -> std::result::Result<u32, String> {
    params.bilateral_invocations().ok_or_else(|| {
        let along = if params.axis == axis::Y { "y" } else { "x" };
        format!(
            "{}×{} pixels need more than {} invocations in the bilateral pass along {along}",
            params.width,
            params.height,
            u32::MAX
        )
    })
}

/// Why the bilateral passes along x or y cannot be dispatched for `params`' image, or `None`
/// if both can ([`bilateral_invocations`]).
fn bilateral_problem(params: &DenoiseParams) -> Option<String> {
    [axis::X, axis::Y]
        .into_iter()
        .find_map(|along| bilateral_invocations(&DenoiseParams { axis: along, ..*params }).err())
}

/// Checks a filter radius given as option `name` (`--denoise-radius`) before any work is done:
/// a typed error naming the option if it is outside `1..=MAX_RADIUS`.
pub fn check_radius(name: &'static str, radius: Option<u32>) -> Result<()> {
    match radius.and_then(radius_problem) {
        Some(reason) => Err(Error::InvalidParameter { name, reason }),
        None => Ok(()),
    }
}

/// The denoise parameters of a `width × height` frame with filter radius `radius` — `None` for
/// the one that follows the image size ([`DenoiseParams::default_radius`]) — and the SVGF
/// baseline's matching à-trous iterations ([`DenoiseParams::with_radius`]).
pub fn frame_params(width: u32, height: u32, radius: Option<u32>) -> DenoiseParams {
    DenoiseParams::with_radius(width, height, radius.unwrap_or(DenoiseParams::default_radius(width, height)))
}

/// Converts a denoiser's `Vec4` colours to RGB.
pub fn rgb(color: &[Vec4]) -> Vec<Vec3> {
    color.iter().map(|c| c.truncate()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use raywave_shared::denoise::{DEFAULT_EDGE_WEIGHTS, DEFAULT_SVGF_PHI_COLOR, DEFAULT_SVGF_VARIANCE_BOOST};

    fn input(pixels: usize) -> DenoiseInput {
        let v = vec![Vec4::ZERO; pixels];
        DenoiseInput {
            position: v.clone(),
            normal: v.clone(),
            analytic: v.clone(),
            emitted: v.clone(),
            shadowed: v.clone(),
            unshadowed: v,
        }
    }

    #[test]
    fn a_radius_option_is_checked_and_sets_the_footprint() {
        assert!(check_radius("denoise-radius", None).is_ok());
        assert!(check_radius("denoise-radius", Some(1)).is_ok() && check_radius("r", Some(MAX_RADIUS)).is_ok());
        for bad in [0, MAX_RADIUS + 1, u32::MAX] {
            match check_radius("denoise-radius", Some(bad)) {
                Err(Error::InvalidParameter { name: "denoise-radius", reason }) => {
                    assert!(reason.contains(&format!("radius {bad} outside 1..={MAX_RADIUS}")), "{reason}")
                }
                other => panic!("radius {bad}: expected an error naming the option, got {other:?}"),
            }
        }
        assert_eq!(frame_params(128, 96, None), DenoiseParams::new(128, 96));
        let chosen = frame_params(128, 96, Some(6));
        assert_eq!((chosen.radius, chosen.atrous_iterations, chosen.width, chosen.height), (6, 4, 128, 96));
    }

    #[test]
    fn check_names_what_is_wrong() {
        let params = DenoiseParams::new(4, 3);
        assert!(input(12).check(&params).is_ok());
        let reason = |input: DenoiseInput, params: DenoiseParams| match input.check(&params) {
            Err(Error::InvalidParameter { name: "denoise", reason }) => reason,
            other => panic!("expected a denoise parameter error, got {other:?}"),
        };
        assert!(reason(input(0), DenoiseParams::new(0, 3)).contains("empty"));
        assert!(reason(input(11), params).contains("4×3 pixels"));
        assert!(reason(input(12), DenoiseParams { radius: 0, ..params }).contains("radius 0"));
        assert!(reason(input(12), DenoiseParams { radius: MAX_RADIUS + 1, ..params }).contains("radius 11"));
        assert!(reason(input(12), DenoiseParams { samples_per_pixel: 0, ..params }).contains("samples per pixel"));
        // Refused before the buffers are looked at, so no 2^26-pixel image is needed here.
        let row = reason(input(1), DenoiseParams::new(1 << 26, 1));
        assert!(row.contains("67108864×1 pixels") && row.contains("bilateral pass along y"), "{row}");
        assert!(reason(input(1), DenoiseParams::new(1, 1 << 26)).contains("along x"));
        let widest = DenoiseParams::new((1 << 26) - 1, 1);
        assert!(reason(input(1), widest).contains("pixels but buffers"), "a dispatch of 2^32 − 64 fits");
    }

    /// Edge weights, `phiColor` and the variance boost are refused outside the limits within
    /// which the kernels' scaled weights stay finite and normal, the error naming the field: at
    /// `Wd` = 10³⁸ `4·Wd` had overflowed and every tap's depth stop been NaN, so 0 (the filter
    /// did nothing), and a subnormal `phiColor` had been 0 on a GPU flushing subnormals.
    #[test]
    fn check_refuses_filter_weights_beyond_their_limits_naming_the_field() {
        let params = DenoiseParams::new(4, 3);
        let refusal = |edited: DenoiseParams| match input(12).check(&edited) {
            Err(Error::InvalidParameter { name: "denoise", reason }) => reason,
            other => panic!("expected {edited:?} refused, got {other:?}"),
        };
        let edge = |field: usize, weight: f32| {
            let mut weights = DEFAULT_EDGE_WEIGHTS.to_array();
            weights[field] = weight;
            DenoiseParams { edge_weights: Vec4::from_array(weights), ..params }
        };
        let fields = ["edge_weights.x (depth Wd)", "edge_weights.y", "edge_weights.z", "edge_weights.w (analytic Wa)"];
        for (i, field) in fields.into_iter().enumerate() {
            for weight in [1.0e38, 3.4e37, MAX_EDGE_WEIGHT * 1.01, -0.5, 1.0e-39, MIN_EDGE_WEIGHT * 0.99, f32::NAN] {
                let reason = refusal(edge(i, weight));
                assert!(reason.contains(field) && reason.contains("neither 0 nor within"), "{weight}: {reason}");
            }
            for weight in [0.0, MIN_EDGE_WEIGHT, MAX_EDGE_WEIGHT] {
                assert!(input(12).check(&edge(i, weight)).is_ok(), "{field} = {weight}");
            }
        }
        let svgf = |phi_color: f32, boost: f32| DenoiseParams { svgf: Vec4::new(phi_color, boost, 0.0, 0.0), ..params };
        for phi_color in [1.0e-39, 1.0e-34, MIN_SVGF_PHI_COLOR * 0.99, MAX_SVGF_PHI_COLOR * 1.01, 0.0, -10.0, f32::NAN]
        {
            let reason = refusal(svgf(phi_color, DEFAULT_SVGF_VARIANCE_BOOST));
            assert!(reason.contains("phiColor (svgf.x)") && reason.contains("outside"), "{phi_color}: {reason}");
        }
        for boost in [-1.0, MAX_SVGF_VARIANCE_BOOST * 1.01, f32::INFINITY, f32::NAN] {
            let reason = refusal(svgf(DEFAULT_SVGF_PHI_COLOR, boost));
            assert!(reason.contains("variance boost (svgf.y)") && reason.contains("outside"), "{boost}: {reason}");
        }
        for (phi_color, boost) in [(MIN_SVGF_PHI_COLOR, 0.0), (MAX_SVGF_PHI_COLOR, MAX_SVGF_VARIANCE_BOOST)] {
            assert!(input(12).check(&svgf(phi_color, boost)).is_ok(), "{phi_color}, {boost}");
        }
        // The documented defaults, which every caller (CLI, reports, benches) passes.
        assert_eq!(params.edge_weights, DEFAULT_EDGE_WEIGHTS);
        assert_eq!(params.svgf, Vec4::new(DEFAULT_SVGF_PHI_COLOR, DEFAULT_SVGF_VARIANCE_BOOST, 0.0, 0.0));
        assert!(input(12).check(&params).is_ok());
    }

    #[test]
    fn check_names_the_buffer_and_pixel_of_a_value_the_filter_cannot_take() {
        let params = DenoiseParams::new(4, 3);
        let reason = |edit: &dyn Fn(&mut DenoiseInput)| {
            let mut bad = input(12);
            edit(&mut bad);
            match bad.check(&params) {
                Err(Error::InvalidParameter { name: "denoise", reason }) => reason,
                other => panic!("expected a denoise parameter error, got {other:?}"),
            }
        };
        let nan = reason(&|d| d.shadowed[6].y = f32::NAN);
        assert!(nan.contains("shadowed[6] (pixel 2, 1)") && nan.contains("not finite"), "{nan}");
        let inf = reason(&|d| d.position[11].x = f32::INFINITY);
        assert!(inf.contains("position[11] (pixel 3, 2)") && inf.contains("not finite"), "{inf}");
        assert!(reason(&|d| d.emitted[0].z = -1e-3)
            .contains("emitted[0] (pixel 0, 0) = [0, 0, -0.001, 0] is a negative radiance"));
        assert!(reason(&|d| d.unshadowed[3].x = -1.0).contains("unshadowed[3]"));
        // Radiances whose weighted sums overflow the filter; the composite's inputs may be larger.
        let huge = reason(&|d| d.unshadowed[7].z = MAX_FILTERED_RADIANCE * 2.0);
        assert!(huge.contains("unshadowed[7] (pixel 3, 1)") && huge.contains("exceeds MAX_FILTERED_RADIANCE"));
        assert!(reason(&|d| d.shadowed[2].x = f32::MAX).contains("shadowed[2]"));
        for atrous_iterations in [0, MAX_ATROUS_ITERATIONS + 1] {
            match input(12).check(&DenoiseParams { atrous_iterations, ..params }) {
                Err(Error::InvalidParameter { name: "denoise", reason }) => {
                    assert!(reason.contains("à-trous iterations"), "{reason}")
                }
                other => panic!("expected {atrous_iterations} à-trous iterations refused, got {other:?}"),
            }
        }
        assert!(input(12).check(&DenoiseParams { atrous_iterations: MAX_ATROUS_ITERATIONS, ..params }).is_ok());
        assert!(reason(&|d| d.analytic[4].x = -1.0).contains("analytic[4]"));
        assert!(reason(&|d| d.normal[5].w = -0.5).contains("normal[5] (pixel 1, 1)"));
        // Negative normals and positions are directions and points, not radiances.
        let mut fine = input(12);
        fine.normal[5] = Vec4::new(0.0, 0.0, -1.0, 0.5);
        fine.position[2] = Vec4::new(-3.0, -1.0, -2.0, 4.0);
        fine.shadowed[1].w = -1.0;
        fine.unshadowed[8] = Vec4::splat(MAX_FILTERED_RADIANCE);
        fine.analytic[9] = Vec4::splat(f32::MAX);
        assert!(fine.check(&params).is_ok(), "w of a radiance is unused");
    }

    /// The stochastic baseline's constant is the mean of `S_N` over the surfaces, summed in f64:
    /// 100 pixels of 10³⁷ had summed to ∞ in f32 (every ratio then 0 and every composite NaN).
    #[test]
    fn the_stochastic_baseline_takes_the_mean_of_large_radiances() {
        let mut large = input(101);
        large.position.iter_mut().take(100).for_each(|p| p.w = 1.0);
        large.shadowed.iter_mut().for_each(|s| *s = Vec4::new(1e37, 3.0, 0.0, 0.0));
        let baseline = large.stochastic();
        assert_eq!(baseline.unshadowed[0], Vec4::new(1e37, 3.0, 1.0, 0.0), "the unlit channel takes 1");
        assert_eq!(baseline.analytic, baseline.unshadowed);
    }

    /// A subnormal depth (a camera a hair from a wall) is no surface, as on a GPU that flushes it
    /// to 0: the G-buffer drops it, and the stochastic baseline's mean leaves it out.
    #[test]
    fn subnormal_depths_count_as_no_surface() {
        let surface = |depth: f32| Surface { position: Vec4::new(1.0, 2.0, 3.0, depth), ..Surface::MISS };
        let surfaces = [surface(0.5), surface(1e-40), surface(f32::MIN_POSITIVE)];
        let frame = DenoiseInput::new(&surfaces, &ShadeAccumulator::new(3));
        assert_eq!(frame.position, [surfaces[0].position, Vec4::ZERO, surfaces[2].position]);
        let mut frame = input(2);
        frame.position[0].w = 1.0;
        frame.position[1].w = 1e-40;
        frame.shadowed = vec![Vec4::new(2.0, 2.0, 2.0, 0.0), Vec4::new(6.0, 6.0, 6.0, 0.0)];
        assert_eq!(frame.stochastic().unshadowed[0], Vec4::new(2.0, 2.0, 2.0, 0.0), "the mean of the one surface");
    }

    /// The G-buffer of [`DenoiseInput::new`]: each surface's point (none where it is not finite)
    /// and its normal beside the analytic luminance `lum(U)`, which the analytic edge stop `Wa`
    /// compares — the luminance, not another measure of `U` such as its largest channel.
    #[test]
    fn the_g_buffer_holds_surface_points_normals_and_the_analytic_luminance() {
        let surface = |position: Vec4| Surface { position, normal: Vec4::new(0.0, 0.6, 0.8, 0.0), ..Surface::MISS };
        let point = Vec4::new(1.0, 2.0, 3.0, 0.5);
        let surfaces = [
            surface(point),
            surface(Vec4::new(f32::NAN, 2.0, 3.0, 0.5)),
            surface(Vec4::new(f32::INFINITY, 0.0, 0.0, 1.0)),
        ];
        let u = Vec3::new(0.2, 0.7, 0.1);
        let mut shades = crate::stream::ShadeStream::zeroed(3);
        shades.analytic.fill(u.extend(0.0));
        let mut accumulator = ShadeAccumulator::new(3);
        accumulator.add(&shades, &[0; 3]).unwrap();
        let frame = DenoiseInput::new(&surfaces, &accumulator);
        assert_eq!(frame.position, [point, Vec4::ZERO, Vec4::ZERO], "a non-finite point is no surface");
        assert_ne!(luminance(u), u.max_element());
        assert_eq!(frame.normal, [Vec4::new(0.0, 0.6, 0.8, luminance(u)); 3]);
        assert_eq!(frame.analytic, [u.extend(0.0); 3]);
    }

    /// The SVGF baseline runs Falcor's schedule: the ratio, its variance, à-trous iterations whose
    /// tap spacing doubles from 1 (steps 1, 2, 4, 8 at `MAX_ATROUS_ITERATIONS`), the composite.
    #[test]
    fn svgf_runs_its_atrous_steps_from_one_doubling() {
        let atrous = |iterations: u32| {
            let params = DenoiseParams { atrous_iterations: iterations, ..DenoiseParams::new(64, 64) };
            let passes = DenoiseMethod::Svgf.passes(&params);
            let (first, last) = (&passes[..2], passes[passes.len() - 1]);
            assert_eq!(
                (first, last),
                (&[DenoisePass::Ratio, DenoisePass::SvgfVariance][..], DenoisePass::SvgfComposite)
            );
            passes[2..passes.len() - 1].to_vec()
        };
        let step = |step| DenoisePass::SvgfAtrous { step };
        assert_eq!(atrous(MAX_ATROUS_ITERATIONS), [step(1), step(2), step(4), step(8)]);
        assert_eq!(atrous(2), [step(1), step(2)]);
        assert_eq!(step(8).name(), "svgf atrous step 8");
    }

    #[test]
    fn an_identity_tv_filter_runs_only_the_composite() {
        let params = DenoiseParams::new(128, 128);
        assert_eq!(DenoiseMethod::Tv.passes(&params).len(), 6);
        let many = DenoiseParams { samples_per_pixel: 4 * params.radius * params.radius, ..params };
        assert_eq!(DenoiseMethod::Tv.passes(&many), vec![DenoisePass::Composite]);
        assert_eq!(DenoiseMethod::Svgf.passes(&many), DenoiseMethod::Svgf.passes(&params), "SVGF keeps its passes");
        assert_eq!(DenoiseMethod::None.passes(&params), vec![DenoisePass::Composite], "no filter at any N");
    }

    #[test]
    fn each_method_needs_only_the_working_buffers_its_passes_write() {
        let params = DenoiseParams::new(128, 128);
        let needs = |method: DenoiseMethod| WorkingBuffers::for_passes(&method.passes(&params));
        let none = WorkingBuffers { noise: false, filtered: false, ratio: false, filtered_ratio: false };
        assert_eq!(needs(DenoiseMethod::None), none);
        assert!(!needs(DenoiseMethod::None).guides_read());
        assert_eq!(needs(DenoiseMethod::Tv), WorkingBuffers { noise: true, filtered: true, ratio: true, ..none });
        assert!(needs(DenoiseMethod::Tv).guides_read());
        assert_eq!(needs(DenoiseMethod::Svgf), WorkingBuffers { ratio: true, filtered_ratio: true, ..none });
        assert!(needs(DenoiseMethod::Svgf).guides_read());
    }

    #[test]
    fn methods_parse_from_their_names() {
        for method in [DenoiseMethod::Tv, DenoiseMethod::Svgf, DenoiseMethod::None] {
            assert_eq!(method.name().parse::<DenoiseMethod>().ok(), Some(method));
        }
        assert!(matches!("blur".parse::<DenoiseMethod>(), Err(Error::InvalidParameter { name: "denoise", .. })));
    }
}
