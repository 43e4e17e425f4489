//! The warp test cases and their check, shared by the CPU warp test (`tests/warps.rs`) and the
//! Vulkan warp parity tests: a table of `(name, WarpParams)` covering every
//! [`warp_kind`], and [`check_warp`], which judges a sample set `xyz = direction, w = pdf` the same
//! way wherever it was produced.
//!
//! What [`check_warp`] asserts for `N` samples (statistical confidence: the whole family of
//! chi-square tests has significance [`FAMILY_SIGNIFICANCE`] = 0.01 at the fixed seed [`SEED`];
//! each test rejects at the Šidák-corrected p-value [`min_p_value`], as Mitsuba's
//! `ChiSquareTest` does, so a correct warp set fails with probability 0.01 in all):
//! - every sample is finite, unit length within [`UNIT_LENGTH_TOLERANCE`], pdf ≥ 0;
//! - its pdf equals `warp::pdf(params, dir)` within [`PDF_REL_TOLERANCE`] relative (or
//!   [`PDF_ABS_TOLERANCE`] absolute), or lies within what `warp::pdf` gives a few ulps from `dir`
//!   ([`pdf_spread`]: where the pdf is ill-conditioned in `f32`, a device's own rounding moves it);
//! - pdf > 0 for all but [`ZERO_PDF_FRACTION`] of the samples (a far sphere sampled by area:
//!   [`ZERO_PDF_FRACTION_FAR_SPHERE_AREA`], see `warp::sphere_light_area_pdf`);
//! - the pdf integrates to 1 within [`MAX_INTEGRAL_ERROR`] over a domain holding its support,
//!   and the directions pass a chi-square test against it in that domain. Domains
//!   ([`domains`]): the sphere in equal-area `(cos θ, φ)` cells, a cap's canonical coordinates
//!   (cones, sphere lights: the support is the cap, so narrow cones are resolved), the quad's own
//!   `(s, t)` (quad lights), and for GGX both the sphere (turned so the lobe lies on its equator)
//!   and a cap around the mirror direction with one overflow cell;
//! - fewer than [`ZERO_CELL_FRACTION`] of the samples land in cells where the pdf integrates to 0.
#![allow(dead_code)] // each test binary uses a different subset

use glam::{DVec3, Vec2, Vec3, Vec4, Vec4Swizzles};
use rayon::prelude::*;
use raywave::kernels::sampling::warp;
use raywave::shared::sampling::{sampler_kind, warp_kind};
use raywave::shared::{SamplerParams, WarpParams};
use raywave::stats::{self, ChiSquare, Histogram};
use std::f64::consts::{PI, TAU};
use std::fmt;

/// Samples per case.
pub const SAMPLE_COUNT: u32 = 1_000_000;
/// Seed of the independent random numbers the cases draw.
pub const SEED: u32 = 0x5EED;
/// Significance level of the whole family of chi-square tests (all domains of all cases).
pub const FAMILY_SIGNIFICANCE: f64 = 0.01;

/// The per-test p-value below which a chi-square test fails: Šidák's correction
/// `1 − (1 − α)^(1/m)` of [`FAMILY_SIGNIFICANCE`] over the `m` domain tests of [`warp_cases`].
pub fn min_p_value() -> f64 {
    let tests: usize = warp_cases().iter().map(|(_, params)| domains(params).len()).sum();
    1.0 - (1.0 - FAMILY_SIGNIFICANCE).powf(1.0 / tests.max(1) as f64)
}
/// Largest accepted `|∫pdf − 1|` over a domain that holds the whole support.
pub const MAX_INTEGRAL_ERROR: f64 = 2.0e-3;
/// Largest accepted relative difference between a sample's pdf and `warp::pdf` of its direction.
pub const PDF_REL_TOLERANCE: f32 = 1.0e-3;
/// Absolute floor (sr⁻¹) of the pdf comparison: at a rim of the support a sample may get pdf 0
/// where `warp::pdf` of its rounded direction gives ~10⁻¹¹, or the reverse.
pub const PDF_ABS_TOLERANCE: f32 = 1.0e-6;
/// Largest accepted `| |dir| − 1 |`.
pub const UNIT_LENGTH_TOLERANCE: f32 = 1.0e-4;
/// Largest accepted fraction of samples with pdf 0 (measure-zero borders, e.g. the rim of the
/// cosine hemisphere, may give a few). Area sampling of a sphere light allows more, see
/// [`zero_pdf_allowance`].
pub const ZERO_PDF_FRACTION: f64 = 1.0e-4;
/// Largest accepted fraction of samples in cells whose integrated pdf is 0 (cells that a
/// discontinuity of the pdf crosses; see `stats::ChiSquare::zero_expected_samples`).
pub const ZERO_CELL_FRACTION: f64 = 1.0e-5;

/// `(cos θ, φ)` cells of the sphere domain.
const SPHERE_BINS: (u32, u32) = (40, 80);
/// (radial, azimuthal) cells of a cap domain.
const CAP_BINS: (u32, u32) = (32, 64);
/// `(s, t)` cells of a quad domain.
const QUAD_BINS: (u32, u32) = (40, 40);
/// Sub-grid per cell and axis for integrating the pdf: [`stats::SUBDIVISIONS`], and four times
/// that for GGX on the sphere, whose lobe at α = 0.05 seen at 85° is only ~0.01 rad wide across
/// the plane of incidence while a cell is 0.05 high (with 2× the p-values of that case over
/// seeds were still skewed towards 0; with 4× they are uniform).
const GGX_SPHERE_SUBDIVISIONS: u32 = 4 * stats::SUBDIVISIONS;
/// Samples this far outside a domain that holds the support (relative, in the domain's
/// coordinates) are clamped onto it: rounding of the `f32` directions.
const DOMAIN_SLACK: f64 = 1.0e-3;

/// Warp parameters with [`SAMPLE_COUNT`] samples of independent random numbers seeded [`SEED`].
pub fn warp_params(kind: u32, a: Vec4, b: Vec4, c: Vec4) -> WarpParams {
    WarpParams {
        kind,
        count: SAMPLE_COUNT,
        padding: [0; 2],
        sampler: SamplerParams { kind: sampler_kind::INDEPENDENT, seed: SEED, spp_log2: 0, resolution_log2: 0 },
        a,
        b,
        c,
    }
}

fn sphere_light(kind: u32, c: Vec3, r: f32) -> WarpParams {
    warp_params(kind, c.extend(r), Vec4::ZERO, Vec4::ZERO)
}

fn quad_light(kind: u32, o: Vec3, eu: Vec3, ev: Vec3) -> WarpParams {
    warp_params(kind, o.extend(0.0), eu.extend(0.0), ev.extend(0.0))
}

/// GGX with view angle `theta_deg` from the normal at azimuth `phi_deg`, roughness `alpha`.
fn ggx(theta_deg: f32, phi_deg: f32, alpha: Vec2) -> WarpParams {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    let v = Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos());
    warp_params(warp_kind::GGX_VNDF, v.extend(0.0), Vec4::new(alpha.x, alpha.y, 0.0, 0.0), Vec4::ZERO)
}

/// LTC with `M` given by rows.
fn ltc(rows: [[f32; 3]; 3]) -> WarpParams {
    let col = |j: usize| Vec4::new(rows[0][j], rows[1][j], rows[2][j], 0.0);
    warp_params(warp_kind::LTC, col(0), col(1), col(2))
}

/// Every warp case: several parameter sets per [`warp_kind`], ordinary and hard.
pub fn warp_cases() -> Vec<(String, WarpParams)> {
    let z = Vec4::ZERO;
    let mut cases: Vec<(String, WarpParams)> = vec![
        ("uniform hemisphere".into(), warp_params(warp_kind::UNIFORM_HEMISPHERE, z, z, z)),
        ("cosine hemisphere".into(), warp_params(warp_kind::COSINE_HEMISPHERE, z, z, z)),
        ("uniform sphere".into(), warp_params(warp_kind::UNIFORM_SPHERE, z, z, z)),
    ];
    for cos_max in [0.9f32, 0.999_999, 0.0, -0.5] {
        cases.push((
            format!("cone cos θmax = {cos_max}"),
            warp_params(warp_kind::UNIFORM_CONE, Vec4::splat(cos_max), z, z),
        ));
    }
    for (kind, strategy) in [(warp_kind::SPHERE_LIGHT_CONE, "cone"), (warp_kind::SPHERE_LIGHT_AREA, "area")] {
        for (what, c, r) in [
            ("d = 3, r = 1", Vec3::new(1.0, 2.0, 2.0), 1.0),
            ("d = 30, r = 1", Vec3::new(0.0, 18.0, 24.0), 1.0),
            ("d = 1e3, r = 1 (small angle)", Vec3::new(0.0, 600.0, 800.0), 1.0),
            ("d = 1.05, r = 1 (nearly touching)", Vec3::new(0.63, 0.0, 0.84), 1.0),
            ("d = 1.001, r = 1 (10⁻³ off the surface)", Vec3::new(0.6006, 0.0, 0.8008), 1.0),
            ("crossing the horizon", Vec3::new(2.5, 0.0, 0.5), 1.0),
            ("p inside", Vec3::new(0.2, 0.1, -0.3), 1.0),
        ] {
            // Area sampling of a sphere 10³ radii away is not a sensible strategy, and f32
            // directions cannot resolve its pdf near the silhouette (warp::sphere_light_area_pdf);
            // 10⁻³ off the surface, a few ulps of a direction near the silhouette move that pdf
            // from a value to 0, beyond what the check allows a device's rounding.
            let area = kind == warp_kind::SPHERE_LIGHT_AREA;
            if area && (c.length() > 100.0 * r || c.length() < 1.01 * r && c.length() > r) {
                continue;
            }
            cases.push((format!("sphere light {strategy}, {what}"), sphere_light(kind, c, r)));
        }
    }
    let tilted = Vec3::new(0.6, 0.0, 0.8);
    let grazing = Vec3::new(75f32.to_radians().cos(), 0.0, 75f32.to_radians().sin());
    for (kind, strategy) in [(warp_kind::QUAD_SPHERICAL, "spherical"), (warp_kind::QUAD_AREA, "area")] {
        for (what, o, eu, ev) in [
            ("overhead", Vec3::new(-0.5, -0.5, 1.0), Vec3::X, Vec3::Y),
            ("tilted, off axis", Vec3::new(0.5, -1.0, 0.3), 2.0 * Vec3::Y, 1.5 * tilted),
            ("partly below p's horizon", Vec3::new(-1.0, 2.0, -0.5), 2.0 * Vec3::X, 1.5 * Vec3::Z),
            ("large and close", Vec3::new(-2.0, -2.0, 0.2), 4.0 * Vec3::X, 4.0 * Vec3::Y),
            ("back side towards p", Vec3::new(-0.5, -0.5, -1.0), Vec3::Y, Vec3::X),
            ("far, Ω ≈ 2.5e-3", Vec3::new(-0.5, -0.5, 20.0), Vec3::X, Vec3::Y),
            ("far and grazing, Ω < 1e-3", Vec3::new(10.0, -0.5, 40.0), Vec3::Y, grazing),
            // p 10⁻³ below its plane and beyond its ev edge: h = y/√(dd² + y²) rounds to 1 there.
            ("edge-on beyond its ev edge", Vec3::new(-0.5, 0.5, 1.0e-3), Vec3::X, Vec3::Y),
            // Not a rectangle: the spherical-rectangle method's frame needs perpendicular edges.
            ("a 60° rhombus", Vec3::new(-0.75, -0.5, 0.6), Vec3::X, Vec3::new(0.5, 0.866_025_4, 0.0)),
            // Within `QUAD_RECTANGLE_MAX_COS` of a rectangle: sampled as a rectangle, its samples
            // and their density sheared onto it about p's foot. p 4·10⁻³ beyond the eu edge, half
            // way along it: the shear moves the light's ends by 4.5·10⁻⁵.
            ("sheared 9e-5, beyond its eu edge", Vec3::new(0.004, -0.5, -0.002), Vec3::X, Vec3::new(9.0e-5, 1.0, 0.0)),
        ] {
            cases.push((format!("quad {strategy}, {what}"), quad_light(kind, o, eu, ev)));
        }
    }
    for alpha in [0.05f32, 0.3, 1.0] {
        for theta in [0.0f32, 60.0, 85.0] {
            cases.push((format!("GGX α = {alpha}, view {theta}°"), ggx(theta, 0.0, Vec2::splat(alpha))));
        }
    }
    cases.push(("GGX α = (0.1, 0.4), view 60° at φ 30°".into(), ggx(60.0, 30.0, Vec2::new(0.1, 0.4))));
    cases.push(("LTC identity (cosine)".into(), ltc([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])));
    cases.push((
        "LTC M = [[0.5,0,0.2],[0,0.7,0],[0.1,0,1]]".into(),
        ltc([[0.5, 0.0, 0.2], [0.0, 0.7, 0.0], [0.1, 0.0, 1.0]]),
    ));
    cases.push((
        "LTC M = [[0.3,0,0.6],[0,0.2,0],[-0.4,0,1]]".into(),
        ltc([[0.3, 0.0, 0.6], [0.0, 0.2, 0.0], [-0.4, 0.0, 1.0]]),
    ));
    cases
}

/// `params.count` samples of the warp on the CPU backend: the kernels' warp probe, which draws sample `i`
/// from `params.sampler` (independent random numbers seeded [`SEED`]) exactly as the SPIR-V
/// probe does on a Vulkan device.
pub fn cpu_samples(params: &WarpParams) -> Vec<Vec4> {
    use raywave::Backend;
    raywave::cpu::CpuBackend::new().warp_probe(params).expect("the warp cases fit the probe's limit")
}

/// Where the directions of a warp are binned and its pdf integrated.
#[derive(Copy, Clone, Debug)]
pub enum Domain {
    /// The whole sphere, in equal-area `(cos θ, φ)` cells around `pole`.
    Sphere { pole: DVec3 },
    /// The cap `1 − cos θ ≤ one_minus_cos_max` around `axis`, in coordinates `(x, φ/2π)` with
    /// the radial coordinate `x` per [`Radial`]. `support`: the cap holds the whole support
    /// (samples outside are errors and the integral must be 1); otherwise samples outside go to
    /// one overflow cell whose expectation is the sphere integral minus the cap integral.
    Cap { axis: DVec3, one_minus_cos_max: f64, radial: Radial, support: bool },
    /// The quad `o + s·eu + t·ev` in its own coordinates `(s, t) ∈ [0,1]²` (directions from the
    /// origin that hit it).
    Quad { o: DVec3, eu: DVec3, ev: DVec3 },
}

/// Radial coordinate `x ∈ [0, 1]` of a cap, with `s = (1 − cos θ)/(1 − cos θmax)`.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Radial {
    /// `x = s`: the cone's canonical coordinate, equal-area, uniform for a uniform cone.
    Area,
    /// `x = θ/θmax`: resolves lobes that are narrow near the axis (GGX at grazing views).
    Angle,
    /// `x = 1 − √(1 − s)`: stretches the rim, where area sampling of a sphere has the integrable
    /// `1/cos θl` singularity of its silhouette, so that the quadrature integrates it.
    Silhouette,
}

impl fmt::Display for Domain {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Domain::Sphere { .. } => write!(f, "sphere"),
            Domain::Cap { one_minus_cos_max, radial, .. } => {
                write!(f, "cap 1−cosθmax={one_minus_cos_max:.3e} {radial:?}")
            }
            Domain::Quad { .. } => write!(f, "quad (s,t)"),
        }
    }
}

/// The reflection of `v` about +z, the centre of a GGX lobe.
fn mirror(v: DVec3) -> DVec3 {
    DVec3::new(-v.x, -v.y, v.z)
}

/// The domains in which a warp's samples are tested (see [`Domain`]).
pub fn domains(params: &WarpParams) -> Vec<Domain> {
    let a = params.a.xyz().as_dvec3();
    let sphere_z = Domain::Sphere { pole: DVec3::Z };
    match params.kind {
        warp_kind::UNIFORM_CONE => {
            let cos_max = (params.a.x as f64).clamp(-1.0, 1.0);
            vec![Domain::Cap { axis: DVec3::Z, one_minus_cos_max: 1.0 - cos_max, radial: Radial::Area, support: true }]
        }
        warp_kind::SPHERE_LIGHT_CONE | warp_kind::SPHERE_LIGHT_AREA => {
            let r = params.a.w as f64;
            let d2 = a.length_squared();
            if d2 <= r * r {
                vec![sphere_z]
            } else {
                let sin2_max = r * r / d2;
                let one_minus_cos_max = sin2_max / (1.0 + (1.0 - sin2_max).sqrt());
                let radial =
                    if params.kind == warp_kind::SPHERE_LIGHT_AREA { Radial::Silhouette } else { Radial::Area };
                vec![Domain::Cap { axis: a.normalize(), one_minus_cos_max, radial, support: true }]
            }
        }
        warp_kind::QUAD_SPHERICAL | warp_kind::QUAD_AREA => {
            vec![Domain::Quad { o: a, eu: params.b.xyz().as_dvec3(), ev: params.c.xyz().as_dvec3() }]
        }
        warp_kind::GGX_VNDF => {
            let v = a.normalize();
            let m = mirror(v);
            // The pole is the normal of the plane of incidence: the lobe lies on the equator and
            // its narrow extent (across that plane) runs along cos θ, the finely integrated axis.
            let pole = v.cross(DVec3::Z).try_normalize().unwrap_or(DVec3::Y);
            let alpha = params.b.x.max(params.b.y) as f64;
            let half_angle = (8.0 * alpha).min(1.2);
            vec![
                Domain::Sphere { pole },
                Domain::Cap {
                    axis: m,
                    one_minus_cos_max: 1.0 - half_angle.cos(),
                    radial: Radial::Angle,
                    support: false,
                },
            ]
        }
        _ => vec![sphere_z],
    }
}

/// One chi-square test of a warp in one domain.
#[derive(Clone, Debug)]
pub struct DomainTest {
    /// The domain.
    pub domain: Domain,
    /// The test's result.
    pub result: ChiSquare,
    /// Whether `result.pdf_integral` must be 1 (the domain holds the support).
    pub integral_is_total: bool,
}

/// Everything [`check_warp`] measured about one sample set.
#[derive(Clone, Debug)]
pub struct WarpReport {
    /// Case name.
    pub name: String,
    /// Number of samples.
    pub samples: usize,
    /// Samples with a non-finite component.
    pub non_finite: usize,
    /// Samples whose direction is not unit length.
    pub not_unit: usize,
    /// Samples with pdf 0.
    pub zero_pdf: usize,
    /// Samples whose pdf differs from `warp::pdf(params, dir)`.
    pub pdf_mismatch: usize,
    /// Largest relative pdf difference seen.
    pub worst_pdf_difference: f32,
    /// Chi-square tests, one per domain.
    pub tests: Vec<DomainTest>,
    /// Violated assertions; empty when the warp passes.
    pub errors: Vec<String>,
}

impl fmt::Display for WarpReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: ", self.name)?;
        for (i, t) in self.tests.iter().enumerate() {
            let sep = if i > 0 { "; " } else { "" };
            write!(f, "{sep}[{}] p = {:.4}, ∫pdf = {:.6}", t.domain, t.result.p_value, t.result.pdf_integral)?;
        }
        let zero_cells: u64 = self.tests.iter().map(|t| t.result.zero_expected_samples).sum();
        write!(f, "; max pdf rel. diff {:.1e}, pdf 0: {}", self.worst_pdf_difference, self.zero_pdf)?;
        if zero_cells > 0 {
            write!(f, ", in zero cells: {zero_cells}")?;
        }
        for e in &self.errors {
            write!(f, "\n    FAIL {e}")?;
        }
        Ok(())
    }
}

impl WarpReport {
    /// `Ok` when every assertion held, else the report as the error.
    pub fn result(&self) -> Result<(), String> {
        if self.errors.is_empty() {
            Ok(())
        } else {
            Err(self.to_string())
        }
    }
}

/// An orthonormal frame `(t1, t2, axis)`.
fn frame(axis: DVec3) -> (DVec3, DVec3, DVec3) {
    let (t1, t2) = axis.any_orthonormal_pair();
    (t1, t2, axis)
}

/// Cap coordinates of unit `d`, or `None` outside the cap (beyond [`DOMAIN_SLACK`] if it holds
/// the support).
fn cap_coords(
    d: DVec3,
    f: (DVec3, DVec3, DVec3),
    one_minus_cos_max: f64,
    radial: Radial,
    support: bool,
) -> Option<[f64; 2]> {
    let (t1, t2, axis) = f;
    let c = d.dot(axis);
    // 1 − cos θ without cancellation for directions near the axis.
    let one_minus_cos = if c > 0.0 { d.cross(axis).length_squared() / (1.0 + c) } else { 1.0 - c };
    let mut s = one_minus_cos / one_minus_cos_max;
    if s > 1.0 {
        if support && s <= 1.0 + DOMAIN_SLACK {
            s = 1.0;
        } else {
            return None;
        }
    }
    let phi = d.dot(t2).atan2(d.dot(t1));
    let x = match radial {
        Radial::Area => s,
        Radial::Angle => half_angle(s * one_minus_cos_max) / half_angle(one_minus_cos_max),
        Radial::Silhouette => 1.0 - (1.0 - s).max(0.0).sqrt(),
    };
    Some([x.min(1.0), (phi + PI) / TAU])
}

/// θ from `1 − cos θ` without cancellation: `2·asin(√((1 − cos θ)/2))`.
fn half_angle(one_minus_cos: f64) -> f64 {
    2.0 * (0.5 * one_minus_cos).max(0.0).sqrt().min(1.0).asin()
}

/// The unit direction at cap coordinates `[x, t]` and the Jacobian `dω/(dx dt)`.
fn cap_direction(xt: [f64; 2], f: (DVec3, DVec3, DVec3), one_minus_cos_max: f64, radial: Radial) -> (DVec3, f64) {
    let (t1, t2, axis) = f;
    let [x, t] = xt;
    // 1 − cos θ at x, and d(1 − cos θ)/dx (dω = d(1 − cos θ)·dφ).
    let (omc, domc_dx) = match radial {
        Radial::Area => (x * one_minus_cos_max, one_minus_cos_max),
        Radial::Angle => {
            let theta_max = half_angle(one_minus_cos_max);
            let theta = x * theta_max;
            (2.0 * (0.5 * theta).sin().powi(2), theta.sin() * theta_max)
        }
        Radial::Silhouette => {
            let s = 1.0 - (1.0 - x) * (1.0 - x);
            (s * one_minus_cos_max, 2.0 * (1.0 - x) * one_minus_cos_max)
        }
    };
    let cos = 1.0 - omc;
    let sin = (omc * (2.0 - omc)).max(0.0).sqrt();
    let phi = TAU * t - PI;
    let d = sin * (phi.cos() * t1 + phi.sin() * t2) + cos * axis;
    (d, domc_dx * TAU)
}

/// Quad coordinates `(s, t)` of the ray from the origin along unit `d`, or `None` if it misses
/// (beyond [`DOMAIN_SLACK`]).
fn quad_coords(d: DVec3, o: DVec3, eu: DVec3, ev: DVec3) -> Option<[f64; 2]> {
    let n = eu.cross(ev);
    let t = o.dot(n) / d.dot(n);
    if !(t > 0.0 && t.is_finite()) {
        return None;
    }
    let q = t * d - o;
    let n2 = n.length_squared();
    let st = [q.cross(ev).dot(n) / n2, eu.cross(q).dot(n) / n2];
    let inside = |x: f64| (-DOMAIN_SLACK..=1.0 + DOMAIN_SLACK).contains(&x);
    if inside(st[0]) && inside(st[1]) {
        Some(st.map(|x| x.clamp(0.0, 1.0)))
    } else {
        None
    }
}

/// The warp's pdf (from the kernels, in `f32`) at a unit `f64` direction.
fn pdf_at(params: &WarpParams, d: DVec3) -> f64 {
    warp::pdf(params, d.as_vec3()) as f64
}

/// Runs the chi-square test of `dirs` in `domain`. `sphere_integral` is the pdf's integral over
/// the whole sphere, needed by a cap that does not hold the support.
fn test_domain(params: &WarpParams, dirs: &[DVec3], domain: Domain, sphere_integral: Option<f64>) -> DomainTest {
    let n = dirs.len() as f64;
    match domain {
        Domain::Sphere { pole } => {
            let (t1, t2, z) = frame(pole);
            let local: Vec<Vec3> = dirs.iter().map(|d| DVec3::new(d.dot(t1), d.dot(t2), d.dot(z)).as_vec3()).collect();
            let sub = if params.kind == warp_kind::GGX_VNDF { GGX_SPHERE_SUBDIVISIONS } else { stats::SUBDIVISIONS };
            let h = stats::sphere_histogram(
                &local,
                |l| pdf_at(params, l.x * t1 + l.y * t2 + l.z * z),
                SPHERE_BINS.0,
                SPHERE_BINS.1,
                sub,
            );
            DomainTest { domain, result: h.test(), integral_is_total: true }
        }
        Domain::Cap { axis, one_minus_cos_max, radial, support } => {
            let f = frame(axis);
            let coords: Vec<[f64; 2]> = dirs
                .par_iter()
                .map(|&d| cap_coords(d, f, one_minus_cos_max, radial, support).unwrap_or([f64::NAN; 2]))
                .collect();
            let pdf = |xt: [f64; 2]| {
                let (d, jacobian) = cap_direction(xt, f, one_minus_cos_max, radial);
                pdf_at(params, d) * jacobian
            };
            let h = stats::unit_square_histogram(&coords, pdf, CAP_BINS.0, CAP_BINS.1, stats::SUBDIVISIONS);
            let result = if support {
                h.test()
            } else {
                // One more cell for everything outside the cap.
                let outside_mass = (sphere_integral.unwrap_or(1.0) - h.pdf_integral).max(0.0);
                let mut observed = h.observed.clone();
                let mut expected = h.expected.clone();
                observed.push(h.outside);
                expected.push(n * outside_mass);
                let fit = stats::chi_square_counts(&observed, &expected);
                ChiSquare { pdf_integral: h.pdf_integral, ..fit }
            };
            DomainTest { domain, result, integral_is_total: support }
        }
        Domain::Quad { o, eu, ev } => {
            let coords: Vec<[f64; 2]> =
                dirs.par_iter().map(|&d| quad_coords(d, o, eu, ev).unwrap_or([f64::NAN; 2])).collect();
            let n_quad = eu.cross(ev);
            let pdf = |[s, t]: [f64; 2]| {
                let w = o + s * eu + t * ev;
                let len = w.length();
                pdf_at(params, w / len) * n_quad.dot(w).abs() / (len * len * len)
            };
            let h: Histogram =
                stats::unit_square_histogram(&coords, pdf, QUAD_BINS.0, QUAD_BINS.1, stats::SUBDIVISIONS);
            DomainTest { domain, result: h.test(), integral_is_total: true }
        }
    }
}

/// Largest accepted fraction of samples with pdf 0 for warp `params`: [`ZERO_PDF_FRACTION`],
/// or for area sampling of a sphere light seen from outside, the fraction of uniformly sampled
/// surface points whose `|cos θl|` is below `√(2·|c|·2⁻²⁴/r)`, four times over: an `f32` direction
/// fixes the ray's distance from the centre `c` only to ~`|c|·2⁻²⁴`, so `warp::pdf` cannot tell
/// whether those silhouette directions hit (see `warp::sphere_light_area_pdf`). `|cos θl|` of
/// uniform points is uniform in [0, 1], so that is also the fraction.
pub fn zero_pdf_allowance(params: &WarpParams) -> f64 {
    let (d, r) = (params.a.xyz().length() as f64, params.a.w.abs() as f64);
    if params.kind == warp_kind::SPHERE_LIGHT_AREA && d > r && r > 0.0 {
        let cos_uncertain = (2.0 * d * (f32::EPSILON as f64 / 2.0) / r).sqrt();
        ZERO_PDF_FRACTION.max(4.0 * cos_uncertain)
    } else {
        ZERO_PDF_FRACTION
    }
}

/// How far, in units of `f32::EPSILON` along each axis, [`pdf_spread`] moves a direction.
const PDF_SPREAD_STEP: f32 = 4.0;

/// The range of `warp::pdf` over the direction `d` (whose pdf is `pdf`) and its 26 neighbours
/// [`PDF_SPREAD_STEP`] ulps away in x, y and/or z: how much the pdf itself moves when the
/// direction or the pdf's own arithmetic is rounded differently — what a device that rounds its
/// own way (an NVIDIA driver fuses `a·b + c`) may differ by. Area sampling of a sphere is the case
/// in point: within about 10⁻³ rad of the silhouette its pdf `(t₀² + t₁²)/(4πr·√disc)` takes
/// `disc = r² − dist²` from a cancellation, and one ulp of the direction (1.8·10⁻⁷ of the ray's
/// distance from the centre at `d = 3`) moves it by tens of percent: 0.2 % of the samples differed
/// so between an NVIDIA H200 and the CPU.
pub fn pdf_spread(params: &WarpParams, d: Vec3, pdf: f32) -> (f32, f32) {
    let step = PDF_SPREAD_STEP * f32::EPSILON;
    let (lo, hi) = (0..27)
        .map(|i| Vec3::new((i % 3) as f32 - 1.0, (i / 3 % 3) as f32 - 1.0, (i / 9) as f32 - 1.0))
        .filter(|offset| *offset != Vec3::ZERO)
        .map(|offset| warp::pdf(params, (d + step * offset).normalize()))
        .fold((pdf, pdf), |(lo, hi), q| (lo.min(q), hi.max(q)));
    // A neighbour outside the support (pdf 0) puts `d` within a few ulps of a singular edge, such
    // as the silhouette where `√disc → 0`: there any value is the pdf of a nearby direction.
    if lo == 0.0 {
        (0.0, f32::INFINITY)
    } else {
        (lo, hi)
    }
}

/// Whether `pdf` lies within [`pdf_spread`] around direction `d` (whose own pdf is `reference`),
/// widened by `rel` relative and `abs` absolute.
pub fn within_pdf_spread(params: &WarpParams, d: Vec3, reference: f32, pdf: f32, rel: f32, abs: f32) -> bool {
    let (lo, hi) = pdf_spread(params, d, reference);
    pdf >= lo * (1.0 - rel) - abs && pdf <= hi * (1.0 + rel) + abs
}

/// Measures a sample set of warp `params` (`xyz` = direction, `w` = pdf, from any backend)
/// against the assertions listed in the module documentation.
pub fn warp_report(name: &str, params: &WarpParams, samples: &[Vec4]) -> WarpReport {
    let mut errors = Vec::new();
    // Per-sample checks, in parallel: (non-finite, not unit, zero pdf, mismatch, worst difference).
    let (non_finite, not_unit, zero_pdf, pdf_mismatch, worst) = samples
        .par_iter()
        .map(|s| {
            if !s.is_finite() || s.w < 0.0 {
                return (1usize, 0usize, 0usize, 0usize, 0.0f32);
            }
            let d = s.xyz();
            let not_unit = ((d.length() - 1.0).abs() > UNIT_LENGTH_TOLERANCE) as usize;
            let q = warp::pdf(params, d);
            let scale = s.w.max(q);
            let diff = (q - s.w).abs();
            // Beyond the tolerance of the pdf at `d`, and of the pdf a few ulps from `d` too.
            let mismatch = diff > (PDF_REL_TOLERANCE * scale).max(PDF_ABS_TOLERANCE)
                && !within_pdf_spread(params, d, q, s.w, PDF_REL_TOLERANCE, PDF_ABS_TOLERANCE);
            let relative = if scale > 0.0 && diff > PDF_ABS_TOLERANCE { diff / scale } else { 0.0 };
            (0, not_unit, (s.w == 0.0) as usize, mismatch as usize, relative)
        })
        .reduce(|| (0, 0, 0, 0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2, a.3 + b.3, a.4.max(b.4)));
    let n = samples.len();
    if n != params.count as usize {
        errors.push(format!("{n} samples, expected {}", params.count));
    }
    if non_finite > 0 {
        errors.push(format!("{non_finite} samples not finite or with negative pdf"));
    }
    if not_unit > 0 {
        errors.push(format!("{not_unit} directions not unit length"));
    }
    if pdf_mismatch > 0 {
        errors.push(format!("{pdf_mismatch} sample pdfs differ from warp::pdf (worst {worst:.2e} relative)"));
    }
    let zero_allowed = zero_pdf_allowance(params);
    if zero_pdf as f64 > zero_allowed * n as f64 {
        errors.push(format!("{zero_pdf} samples with pdf 0 (allowed {zero_allowed} of {n})"));
    }

    let dirs: Vec<DVec3> = samples
        .par_iter()
        .filter(|s| s.is_finite())
        .map(|s| s.xyz().as_dvec3().normalize_or_zero())
        .filter(|d| *d != DVec3::ZERO)
        .collect();
    let mut tests: Vec<DomainTest> = Vec::new();
    let min_p = min_p_value();
    for domain in domains(params) {
        let sphere_integral =
            tests.iter().find(|t| matches!(t.domain, Domain::Sphere { .. })).map(|t| t.result.pdf_integral);
        let t = test_domain(params, &dirs, domain, sphere_integral);
        let r = &t.result;
        // NaN (a NaN pdf) fails too.
        if r.p_value.is_nan() || r.p_value <= min_p {
            errors.push(format!("[{domain}] chi-square rejects: {r}"));
        }
        let integral_error = (r.pdf_integral - 1.0).abs();
        if t.integral_is_total && (integral_error.is_nan() || integral_error >= MAX_INTEGRAL_ERROR) {
            errors.push(format!("[{domain}] pdf integrates to {:.6}", r.pdf_integral));
        }
        if t.integral_is_total && r.outside > 0 {
            errors.push(format!("[{domain}] {} samples outside the support", r.outside));
        }
        if r.zero_expected_samples as f64 > ZERO_CELL_FRACTION * n as f64 {
            errors
                .push(format!("[{domain}] {} samples in cells where the pdf integrates to 0", r.zero_expected_samples));
        }
        tests.push(t);
    }
    WarpReport {
        name: name.to_string(),
        samples: n,
        non_finite,
        not_unit,
        zero_pdf,
        pdf_mismatch,
        worst_pdf_difference: worst,
        tests,
        errors,
    }
}

/// Checks a sample set of warp `params` (`xyz` = direction, `w` = pdf; from the CPU or a Vulkan
/// device) against the assertions listed in the module documentation; `Err` holds the report.
pub fn check_warp(name: &str, params: &WarpParams, samples: &[Vec4]) -> Result<(), String> {
    warp_report(name, params, samples).result()
}
