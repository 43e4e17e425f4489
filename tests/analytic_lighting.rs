//! Analytic U against a converged f64 Monte Carlo reference: the diffuse (clamped-cosine) and
//! specular (LTC over raywave's fitted GGX table) hit integrals of quad lights, over roughness
//! 0…1, view angles up to 89.9° and lights partly below the horizon.
//!
//! Reference: `∫_light f(v, l)·cos θ_l dω` in f64 with the true GGX BRDF (F = 1,
//! height-correlated Smith; `raywave::ltc_fit::Ggx`) — or `cos θ_l/π` for the diffuse lobe —
//! estimated with two strategies combined by the balance heuristic (visible-normal sampling of the
//! lobe and uniform area sampling of the quad), 2 × 2¹⁹ stratified samples per case (10⁶ in
//! all, as issue 5 asks). Its relative standard error is estimated too, and each comparison allows
//! 3σ of it. The figures below are with this reference; with the 2 × 2¹⁷ samples of earlier
//! versions (a 3σ allowance twice as wide) every error read smaller — the LTC's median 0.43 %
//! instead of 0.68 % — and the earlier fits' figures quoted here were measured that way.
//!
//! Issue 5's targets: diffuse relative error ≤ 0.5 % (asserted); specular median ≤ 1 % and max
//! ≤ 5 % at roughness ≥ 0.1, relative to the reference. Two specular variants are measured:
//!
//! - **The LTC alone** (`parallelogram_form_factors` without a GGX lobe, the default). The median is met with the two-lobe
//!   table (FIT_VERSION 4: 0.68 %, 0.67 % before the lookup aligned the cells' lobes; with the smaller reference 0.43 %, FIT_VERSION 3 0.68 %, one
//!   lobe, FIT_VERSION 2, 4.2 %) and asserted; the max is not: lights that catch only a lobe's far
//!   tail (a light low on the view's side, or overhead at grazing views; reference `U_S` below
//!   0.006) keep errors of 30–174 %, and at 89.9° the lookup between the table's last two columns
//!   adds some (roughness 0.75, light around the mirror direction: 59 %; 3.6 % with FIT_VERSION 3,
//!   whose grazing column had not switched basin — `tests/ltc_interpolation.rs`). 15 of 120 cases
//!   exceed 30 %, 33 exceed 5 % (smaller reference: 14 and 33; FIT_VERSION 3: 12 and 32). The error
//!   relative to the lobe's albedo, which is what a shaded pixel sees (`|U_S − ref|·E_S` against
//!   `E_S`), is asserted at its measured envelope: median ≤ 0.1 %, 90th percentile ≤ 1.5 %, max ≤
//!   5 % (measured 0.01 %, 0.78 %, 4.0 %; the earlier versions, at the next case up for the
//!   percentile: FIT_VERSION 3 0.00 %, 0.87 %, 3.5 %; one lobe 0.14 %, 1.6 %, 9.0 %; ltc_code's
//!   fixed frame 0.17 %, 4.5 %, 13 %), so a regression of the fit or of the polygon integration
//!   fails.
//! - **With the residual towards GGX** (`parallelogram_form_factors` with the GGX lobe: its own
//!   integral by `raywave::kernels::shade::slope_quadrature`; `raywave render --analytic-residual`):
//!   median 0.00 %, max 1.07 % over every view up to 89.9° (issue 5's ≤ 5 %, met and asserted at
//!   ≤ 2 %); at roughness 0.05, below the range, all 20 cases within the reference's 3σ
//!   (asserted within 0.1 % beyond it), and at roughness 0 (a mirror: `α` at its floor, 10⁻⁴, in
//!   the kernels and the reference alike) all 16 up to 80° too; at 89.9°, where the mirror's lobe
//!   is about 10⁻⁷ rad wide, the two lights that hold its mirror direction come out 0.69 % low
//!   (asserted ≤ 1 %). The LTC alone there: at most 0.91 % (0.05) and 1.86 % (0, at 89.9°) of the
//!   lobe's albedo (asserted ≤ 2.5 %). Relative to the lobe's albedo: max below 0.005 %
//!   (asserted ≤ 0.1 %; 0.23 % before the radial rule was split into pieces of π/16, which took
//!   lights reaching towards the horizon up to 1.9 % high). Its predecessor, a fixed 3 × 3 Gauss rule on a fan
//!   of the light's triangles, left 3.2 % up to 80° and 10.0 % at 89.9° (two lights around the
//!   mirror direction).
//!
//! A second test draws 400 random quads, views and roughnesses (fixed seed) and asserts that the
//! GGX integral leaves none of them beyond 5 % (measured on the 357 lights that reach the surface:
//! the LTC alone 182, with the residual none — its largest error relative to the lobe's albedo
//! 0.03 %, the LTC's 2.13 %; the fan left 3), and a third
//! checks the kernels' f32 GGX lobe against the fitter's f64 one.

use glam::{DVec3, Vec3, Vec4};
use rayon::prelude::*;
use raywave::kernels::hash::{pcg3d, unit_float};
use raywave::kernels::shade::ggx::GgxLobe;
use raywave::kernels::shade::ltc::{lookup, parallelogram_form_factors, ShadingFrame};
use raywave::ltc_fit::Ggx;
use raywave::shared::ltc_table::packed_entries;

/// Samples per strategy (a 2⁹ × 2¹⁰ jittered grid).
const SAMPLES: u32 = 1 << 19;

/// A quad light in the local frame (z = normal): corner and two edges.
#[derive(Copy, Clone, Debug)]
struct Quad {
    corner: DVec3,
    u: DVec3,
    v: DVec3,
}

impl Quad {
    /// Ray from the origin along unit `l` against the quad: the hit distance, if any.
    fn hit(&self, l: DVec3) -> Option<f64> {
        let n = self.u.cross(self.v);
        let denom = l.dot(n);
        if denom == 0.0 {
            return None;
        }
        let t = self.corner.dot(n) / denom;
        if t <= 0.0 {
            return None;
        }
        let q = t * l - self.corner;
        let n2 = n.length_squared();
        let s = q.cross(self.v).dot(n) / n2;
        let r = self.u.cross(q).dot(n) / n2;
        ((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&r)).then_some(t)
    }

    /// Solid-angle density of uniform area sampling at the point at distance `t` along `l`:
    /// `t²/(A·|cos θ_light|)`, and `A·|cos θ_light| = |l·(u × v)|`.
    fn area_pdf(&self, l: DVec3, t: f64) -> f64 {
        t * t / l.dot(self.u.cross(self.v)).abs()
    }
}

/// `(estimate, relative standard error)` of `∫_quad g(l) dω` where `g` returns `(value, pdf of
/// lobe sampling)` and `lobe_sample(u)` draws a lobe direction.
fn reference(
    quad: &Quad,
    g: impl Fn(DVec3) -> (f64, f64),
    lobe_sample: impl Fn(f64, f64) -> DVec3,
    salt: u32,
) -> (f64, f64) {
    let (mut sum, mut sum2) = (0.0, 0.0);
    let cols = 512u32;
    for i in 0..SAMPLES {
        let h = pcg3d(glam::UVec3::new(i, salt, 0xa11));
        let u1 = ((i % cols) as f64 + f64::from(unit_float(h.x))) / f64::from(cols);
        let u2 = ((i / cols) as f64 + f64::from(unit_float(h.y))) / f64::from(SAMPLES / cols);
        let mut contribution = 0.0;
        // Lobe sampling.
        let l = lobe_sample(u1, u2);
        if let Some(t) = quad.hit(l) {
            let (value, pdf_lobe) = g(l);
            let pdf_area = quad.area_pdf(l, t);
            if pdf_lobe > 0.0 {
                contribution += value / (pdf_lobe + pdf_area);
            }
        }
        // Area sampling.
        let x = quad.corner + u1 * quad.u + u2 * quad.v;
        let t = x.length();
        let l = x / t;
        let (value, pdf_lobe) = g(l);
        let pdf_area = quad.area_pdf(l, t);
        if value > 0.0 {
            contribution += value / (pdf_lobe + pdf_area);
        }
        sum += contribution;
        sum2 += contribution * contribution;
    }
    let n = f64::from(SAMPLES);
    let mean = sum / n;
    let variance = (sum2 / n - mean * mean).max(0.0) / n;
    (mean, if mean > 0.0 { variance.sqrt() / mean } else { 0.0 })
}

struct Case {
    roughness: f32,
    view_degrees: f32,
    light: &'static str,
    diffuse: (f64, f64, f64),
    specular: (f64, f64, f64),
    /// The specular lobe with the quadrature residual (`parallelogram_form_factors` with the GGX
    /// lobe).
    corrected: (f64, f64, f64),
    magnitude: f64,
}

fn lights(view: DVec3) -> [(&'static str, Quad); 4] {
    let mirror = DVec3::new(-view.x, -view.y, view.z);
    let (a, b) = mirror.any_orthonormal_pair();
    let centre = mirror * 2.0;
    [
        ("overhead", Quad { corner: DVec3::new(-0.5, -0.5, 1.0), u: DVec3::X, v: DVec3::Y }),
        ("around the mirror direction", Quad { corner: centre - 0.3 * a - 0.3 * b, u: 0.6 * a, v: 0.6 * b }),
        (
            "crossing the horizon",
            Quad { corner: DVec3::new(-1.0, -0.6, -0.4), u: DVec3::new(0.0, 1.2, 0.0), v: DVec3::new(0.0, 0.0, 1.0) },
        ),
        (
            "low, to the side",
            Quad { corner: DVec3::new(0.3, 1.0, 0.05), u: DVec3::new(1.0, 0.0, 0.0), v: DVec3::new(0.0, 0.5, 0.5) },
        ),
    ]
}

#[test]
fn analytic_u_matches_the_f64_reference() {
    let table: Vec<Vec4> = packed_entries().map(Vec4::from_array).collect();
    let grid: Vec<(f32, f32)> = [0.0f32, 0.05, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0]
        .into_iter()
        .flat_map(|r| [0.0f32, 30.0, 60.0, 80.0, 89.9].into_iter().map(move |t| (r, t)))
        .collect();
    let cases: Vec<Case> = grid
        .par_iter()
        .enumerate()
        .flat_map_iter(|(k, &(roughness, view_degrees))| {
            let theta = f64::from(view_degrees).to_radians();
            let view = DVec3::new(theta.sin(), 0.0, theta.cos());
            let table = &table;
            lights(view).into_iter().enumerate().map(move |(j, (light, quad))| {
                let salt = (k * 8 + j) as u32;
                let alpha = f64::from(roughness * roughness).max(1e-4);
                let ggx = Ggx::new(alpha, view);
                let specular_ref = reference(&quad, |l| ggx.eval_pdf(l), |u1, u2| ggx.sample(u1, u2).0, salt);
                let cosine = |l: DVec3| {
                    let c = l.z.max(0.0) / std::f64::consts::PI;
                    (c, c)
                };
                let cosine_sample = |u1: f64, u2: f64| {
                    let (r, phi) = (u1.sqrt(), std::f64::consts::TAU * u2);
                    DVec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u1).max(0.0).sqrt())
                };
                let diffuse_ref = reference(&quad, cosine, cosine_sample, salt + 1000);
                let frame = ShadingFrame::new(Vec3::Z, view.as_vec3());
                let (corner, u, v) = (quad.corner.as_vec3(), quad.u.as_vec3(), quad.v.as_vec3());
                let lobe = lookup(table, roughness, view.z as f32);
                let ggx = GgxLobe::new(roughness, view.z as f32);
                let (diffuse, specular) = parallelogram_form_factors(&lobe, None, &frame, Vec3::ZERO, corner, u, v);
                let corrected = parallelogram_form_factors(&lobe, Some(ggx), &frame, Vec3::ZERO, corner, u, v).1;
                let magnitude = f64::from(lobe.magnitude);
                let (diffuse, specular, corrected) =
                    (f64::from(diffuse), magnitude * f64::from(specular), magnitude * f64::from(corrected));
                Case {
                    roughness,
                    view_degrees,
                    light,
                    diffuse: (diffuse, diffuse_ref.0, diffuse_ref.1),
                    specular: (specular, specular_ref.0, specular_ref.1),
                    corrected: (corrected, specular_ref.0, specular_ref.1),
                    magnitude,
                }
            })
        })
        .collect();

    println!("roughness  view°   light                         diffuse err   specular: LTC  corrected  reference   err: LTC  corrected");
    for c in &cases {
        let d = relative_excess(c.diffuse);
        println!(
            "{:>9} {:>6} {:<30} {:>9.2e}    {:>10.5} {:>10.5} {:>10.5} {:>9.2}% {:>9.2}%",
            c.roughness,
            c.view_degrees,
            c.light,
            d,
            c.specular.0,
            c.corrected.0,
            c.specular.1,
            100.0 * relative_excess(c.specular),
            100.0 * relative_excess(c.corrected)
        );
        assert!(c.diffuse.0.is_finite() && c.specular.0.is_finite() && c.corrected.0.is_finite());
        assert!(d <= 0.005, "diffuse lobe off by {d} at {} {}° {}", c.roughness, c.view_degrees, c.light);
    }
    let ltc = SpecularErrors::new(&cases, |c| c.specular);
    let corrected = SpecularErrors::new(&cases, |c| c.corrected);
    ltc.print("LTC");
    corrected.print("LTC + quadrature residual");
    // The LTC alone, at its measured envelope (module documentation).
    assert!(
        ltc.albedo_relative(0.5) <= 0.001,
        "LTC specular median error (albedo-relative) {}",
        ltc.albedo_relative(0.5)
    );
    assert!(ltc.albedo_relative(0.9) <= 0.015, "LTC specular p90 error (albedo-relative) {}", ltc.albedo_relative(0.9));
    assert!(ltc.albedo_relative(1.0) <= 0.05, "LTC specular max error (albedo-relative) {}", ltc.albedo_relative(1.0));
    assert!(ltc.relative(0.5) <= 0.01, "LTC specular median error (relative to the reference) {}", ltc.relative(0.5));
    // With the residual towards GGX: issue 5's median and max at every view (module documentation).
    assert!(corrected.relative(0.5) <= 0.01, "corrected specular median error {}", corrected.relative(0.5));
    assert!(corrected.relative(1.0) <= 0.02, "corrected specular max error {}", corrected.relative(1.0));
    assert!(
        corrected.albedo_relative(1.0) <= 0.001,
        "corrected albedo-relative max {}",
        corrected.albedo_relative(1.0)
    );
    // Below issue 5's roughness range too (module documentation): roughness 0.05, and 0 (a mirror,
    // α at its floor of 10⁻⁴) whose lobe at 89.9° is about 10⁻⁷ rad wide.
    for (roughness, most_grazing) in [(0.05, 90.0), (0.0, 80.0)] {
        let sharp: Vec<&Case> = cases.iter().filter(|c| c.roughness == roughness).collect();
        assert!(!sharp.is_empty(), "the grid holds roughness {roughness}");
        let excess = |c: &&Case| relative_excess(c.corrected);
        let worst = sharp.iter().filter(|c| c.view_degrees <= most_grazing).map(excess).fold(0.0, f64::max);
        let grazing = sharp.iter().filter(|c| c.view_degrees > most_grazing).map(excess).fold(0.0, f64::max);
        let ltc = sharp.iter().map(|c| albedo_excess(c.specular, c.magnitude)).fold(0.0, f64::max);
        let beyond = sharp.iter().map(excess).filter(|&e| e > 0.0).count();
        println!(
            "roughness {roughness}: corrected specular {beyond} of {} cases beyond 3σ, by at most {worst:e} at views \
             to {most_grazing}° and {grazing:e} beyond; the LTC alone at most {ltc:e} of the lobe's albedo",
            sharp.len()
        );
        assert!(worst <= SHARPEST_CORRECTED_EXCESS, "corrected specular at roughness {roughness}: {worst} beyond 3σ");
        assert!(grazing <= MIRROR_GRAZING_CORRECTED_EXCESS, "corrected mirror at 89.9°: {grazing} beyond 3σ");
        assert!(ltc <= SHARP_LTC_ALBEDO_EXCESS, "LTC specular at roughness {roughness}: {ltc} of the albedo");
    }
}

/// Largest error of the corrected specular term at roughness 0.05 beyond the reference's 3σ,
/// relative to the reference: a regression guard (measured 0; 3·10⁻⁵ before the radial rule's
/// pieces, module documentation).
const SHARPEST_CORRECTED_EXCESS: f64 = 1e-3;

/// Largest error of the corrected specular term of a mirror (roughness 0) seen at 89.9° beyond the
/// reference's 3σ, relative to the reference: measured 0.69 % low under both lights that hold its
/// mirror direction (0.99116 against 0.99817), a lobe about 10⁻⁷ rad wide (module documentation).
const MIRROR_GRAZING_CORRECTED_EXCESS: f64 = 1e-2;

/// Largest error of the LTC alone at roughness 0.05 and 0, relative to the lobe's albedo beyond the
/// reference's 3σ: measured 0.91 % (0.05) and 1.86 % (0, at 89.9°).
const SHARP_LTC_ALBEDO_EXCESS: f64 = 2.5e-2;

/// Error of `ours` relative to `reference` beyond the reference's own 3σ (`rel_sigma` is its
/// relative standard error); values below 1e-4 are compared absolutely.
fn relative_excess((ours, reference, rel_sigma): (f64, f64, f64)) -> f64 {
    ((ours - reference).abs() / reference.max(1e-4) - 3.0 * rel_sigma).max(0.0)
}

/// Error of a specular `ours` beyond the reference's 3σ, relative to the lobe's albedo
/// `magnitude` (what a shaded pixel sees).
fn albedo_excess((ours, reference, rel_sigma): (f64, f64, f64), magnitude: f64) -> f64 {
    ((ours - reference).abs() - 3.0 * rel_sigma * reference).max(0.0) / magnitude
}

/// Specular errors at roughness ≥ 0.1, each sorted: relative to the reference (issue 5's metric)
/// and relative to the lobe's albedo (what a pixel sees).
struct SpecularErrors {
    relative: Vec<f64>,
    /// Relative, views ≤ 80° only.
    relative_to_80: Vec<f64>,
    albedo_relative: Vec<f64>,
    /// Albedo-relative, views ≤ 80° only.
    albedo_relative_to_80: Vec<f64>,
}

impl SpecularErrors {
    fn new(cases: &[Case], value: impl Fn(&Case) -> (f64, f64, f64)) -> Self {
        let (mut relative, mut relative_to_80) = (Vec::new(), Vec::new());
        let (mut albedo_relative, mut albedo_relative_to_80) = (Vec::new(), Vec::new());
        for c in cases.iter().filter(|c| c.roughness >= 0.1) {
            let measured = value(c);
            let r = relative_excess(measured);
            let e = albedo_excess(measured, c.magnitude);
            relative.push(r);
            albedo_relative.push(e);
            if c.view_degrees <= 80.0 {
                relative_to_80.push(r);
                albedo_relative_to_80.push(e);
            }
        }
        for v in [&mut relative, &mut relative_to_80, &mut albedo_relative, &mut albedo_relative_to_80] {
            v.sort_by(f64::total_cmp);
        }
        Self { relative, relative_to_80, albedo_relative, albedo_relative_to_80 }
    }

    fn quantile(v: &[f64], q: f64) -> f64 {
        v[((v.len() - 1) as f64 * q).round() as usize]
    }

    fn relative(&self, q: f64) -> f64 {
        Self::quantile(&self.relative, q)
    }

    fn albedo_relative(&self, q: f64) -> f64 {
        Self::quantile(&self.albedo_relative, q)
    }

    fn print(&self, name: &str) {
        let above = |x: f64| self.relative.iter().filter(|&&e| e > x).count();
        println!(
            "{name}, roughness ≥ 0.1: relative to the reference median {:.2} %, max {:.2} % (views ≤ 80°: {:.2} %; \
             {} of {} above 5 %, {} above 30 %); relative to the lobe's albedo median {:.2} %, p90 {:.2} %, max {:.2} % \
             (views ≤ 80°: {:.2} %)",
            100.0 * self.relative(0.5),
            100.0 * self.relative(1.0),
            100.0 * Self::quantile(&self.relative_to_80, 1.0),
            above(0.05),
            self.relative.len(),
            above(0.3),
            100.0 * self.albedo_relative(0.5),
            100.0 * self.albedo_relative(0.9),
            100.0 * self.albedo_relative(1.0),
            100.0 * Self::quantile(&self.albedo_relative_to_80, 1.0)
        );
    }
}

#[test]
fn the_kernels_ggx_lobe_is_the_fitted_one() {
    // `GgxLobe` (f32; `eval`, the integrand whose integral `slope_quadrature` computes) against
    // the fitter's f64 `Ggx`.
    for (k, &(roughness, cos_v)) in
        [(0.0f32, 1.0f32), (0.1, 0.9), (0.35, 0.5), (0.7, 0.05), (1.0, 0.002)].iter().enumerate()
    {
        let ggx = GgxLobe::new(roughness, cos_v);
        let v = DVec3::new((1.0 - f64::from(cos_v).powi(2)).sqrt(), 0.0, f64::from(cos_v));
        let reference = Ggx::new(f64::from(roughness * roughness).max(1e-4), v);
        for i in 0..2000u32 {
            let h = pcg3d(glam::UVec3::new(i, k as u32, 0x99));
            let (u1, u2) = (f64::from(unit_float(h.x)), f64::from(unit_float(h.y)));
            let l = reference.sample(u1, u2).0;
            let expected = reference.eval_pdf(l).0;
            let got = f64::from(ggx.eval(l.as_vec3()));
            assert!(got.is_finite() && got >= 0.0, "{roughness} {cos_v} {l}: {got}");
            assert!((got - expected).abs() <= 2e-3 * expected + 1e-6, "{roughness} {cos_v} {l}: {got} vs {expected}");
        }
    }
}

/// Random quad lights, views and roughnesses (fixed seed): with the residual towards GGX no
/// light's `U_S` is worse than the LTC's by more than 1 % of the reference (where the LTC happens
/// to be exact the residual keeps its own quadrature error, up to about 0.1 %), and none is beyond
/// 5 % of the reference.
#[test]
fn the_residual_helps_on_random_lights() {
    let table: Vec<Vec4> = packed_entries().map(Vec4::from_array).collect();
    const CONFIGURATIONS: u32 = 400;
    let results: Vec<RandomLightErrors> = (0..CONFIGURATIONS)
        .into_par_iter()
        .filter_map(|k| {
            let h = |i: u32| {
                let x = pcg3d(glam::UVec3::new(k, i, 0x5eed));
                [unit_float(x.x), unit_float(x.y), unit_float(x.z)].map(f64::from)
            };
            let [a, b, c] = h(0);
            let roughness = (0.1 + 0.9 * a) as f32;
            let cos_v = 0.0005 + 0.9995 * b;
            let view = DVec3::new((1.0 - cos_v * cos_v).sqrt(), 0.0, cos_v);
            // Light centre: any direction, a quarter of them below the horizon.
            let [d, e, f] = h(1);
            let phi = std::f64::consts::TAU * d;
            let z = if c < 0.75 { e } else { -0.3 * e };
            let r = (1.0 - z * z).sqrt();
            let centre_dir = DVec3::new(r * phi.cos(), r * phi.sin(), z);
            let distance = 0.5 + 4.5 * f;
            let [g, s1, s2] = h(2);
            let size = 0.01 + 2.0 * g;
            let (t1, t2) = centre_dir.any_orthonormal_pair();
            let tilt = 2.0 * s1 - 1.0;
            let u = size * (t1 * tilt.cos() + centre_dir * tilt.sin());
            let v = size * (0.3 + 1.2 * s2) * t2;
            let corner = centre_dir * distance - 0.5 * u - 0.5 * v;
            // Emitting towards the shading point.
            let (u, v) = if u.cross(v).dot(centre_dir) < 0.0 { (u, v) } else { (v, u) };
            let quad = Quad { corner, u, v };
            let alpha = f64::from(roughness * roughness).max(1e-4);
            let ggx = Ggx::new(alpha, view);
            let (reference, rel_sigma) =
                reference(&quad, |l| ggx.eval_pdf(l), |u1, u2| ggx.sample(u1, u2).0, 0x1000 + k);
            if reference.is_nan() || reference <= 0.0 {
                return None;
            }
            let frame = ShadingFrame::new(Vec3::Z, view.as_vec3());
            let (corner, u, v) = (quad.corner.as_vec3(), quad.u.as_vec3(), quad.v.as_vec3());
            let lobe = lookup(&table, roughness, cos_v as f32);
            let magnitude = f64::from(lobe.magnitude);
            let ltc =
                magnitude * f64::from(parallelogram_form_factors(&lobe, None, &frame, Vec3::ZERO, corner, u, v).1);
            let ggx = GgxLobe::new(roughness, cos_v as f32);
            let corrected =
                magnitude * f64::from(parallelogram_form_factors(&lobe, Some(ggx), &frame, Vec3::ZERO, corner, u, v).1);
            let (ltc, corrected) = ((ltc, reference, rel_sigma), (corrected, reference, rel_sigma));
            Some(RandomLightErrors {
                relative: [relative_excess(ltc), relative_excess(corrected)],
                albedo_relative: [albedo_excess(ltc, magnitude), albedo_excess(corrected, magnitude)],
            })
        })
        .collect();
    let n = results.len();
    let worse = results.iter().filter(|r| r.relative[1] > r.relative[0] + 0.01).count();
    let above = |i: usize| results.iter().filter(|r| r.relative[i] > 0.05).count();
    let (ltc_above, corrected_above) = (above(0), above(1));
    let max_albedo_relative = |i: usize| results.iter().map(|r| r.albedo_relative[i]).fold(0.0, f64::max);
    println!(
        "{n} random lights: above 5 % of the reference LTC {ltc_above}, with the residual {corrected_above}; \
         max albedo-relative error LTC {:.2} %, with the residual {:.2} %; worse by > 1 %: {worse}",
        100.0 * max_albedo_relative(0),
        100.0 * max_albedo_relative(1)
    );
    assert!(n >= CONFIGURATIONS as usize * 3 / 4, "only {n} lights reach the surface");
    assert_eq!(worse, 0, "the residual made some light's U_S worse than the LTC alone");
    assert_eq!(
        corrected_above, 0,
        "{corrected_above} lights beyond 5 % with the residual (the LTC alone: {ltc_above})"
    );
    let (ltc_max, corrected_max) = (max_albedo_relative(0), max_albedo_relative(1));
    assert!(corrected_max <= ltc_max, "albedo-relative max error {corrected_max} vs the LTC's {ltc_max}");
}

/// One random light's specular errors beyond the reference's 3σ, `[LTC, with the residual]`.
struct RandomLightErrors {
    /// Relative to the reference.
    relative: [f64; 2],
    /// Relative to the lobe's albedo.
    albedo_relative: [f64; 2],
}
