//! Analytic U against a converged f64 Monte Carlo reference: the diffuse (clamped-cosine) and
//! specular (LTC over raywave's fitted GGX table) hit integrals of quad lights, over roughness
//! 0.05…1, view angles up to 89.9° and lights partly below the horizon.
//!
//! Reference: `∫_light f(v, l)·cos θ_l dω` in f64 with the true GGX BRDF (F = 1,
//! height-correlated Smith; `raywave::ltc_fit::Ggx`) — or `cos θ_l/π` for the diffuse lobe —
//! estimated with two strategies combined by the balance heuristic (visible-normal sampling of the
//! lobe and uniform area sampling of the quad), 2 × 2¹⁷ stratified samples per case. Its relative
//! standard error is estimated too, and each comparison allows 3σ of it.
//!
//! Issue 5's targets: diffuse relative error ≤ 0.5 % (asserted); specular median ≤ 1 % and max
//! ≤ 5 % at roughness ≥ 0.1, relative to the reference. The median is **met** with the two-lobe
//! table (FIT_VERSION 4: 0.43 %; FIT_VERSION 3: 0.68 %; one lobe, FIT_VERSION 2: 4.2 %) and
//! asserted; the max is **not**: lights that catch only a lobe's far tail (a light low on the
//! view's side, or overhead at grazing views; reference `U_S` below 0.006) keep errors of
//! 30–173 %, and at 89.9° the lookup between the table's last two columns adds some (roughness
//! 0.75, light around the mirror direction: 60 %; 3.6 % with FIT_VERSION 3, whose grazing
//! column had not switched basin — `tests/ltc_interpolation.rs`). 14 of 120 cases exceed 30 %,
//! 33 exceed 5 % (FIT_VERSION 3: 12 and 32). The test prints that table and
//! also asserts the error relative to the lobe's albedo, which is what a shaded pixel sees
//! (`|U_S − ref|·E_S` against `E_S`), at its measured envelope: median ≤ 0.1 %, 90th percentile
//! ≤ 1.5 %, max ≤ 5 % (measured 0.00 %, 0.74 %, 3.9 %; FIT_VERSION 3 0.00 %, 0.87 %, 3.5 %; one
//! lobe 0.14 %, 1.6 %, 9.0 %; ltc_code's fixed frame 0.17 %, 4.5 %, 13 %), so a regression of
//! the fit or of the polygon integration fails.

use glam::{DVec3, Vec3, Vec4};
use rayon::prelude::*;
use raywave::kernels::hash::{pcg3d, unit_float};
use raywave::kernels::shade::ltc::{diffuse_form_factor, local_quad, lookup, specular_form_factor, ShadingFrame};
use raywave::ltc_fit::Ggx;
use raywave::shared::ltc_table::packed_entries;

/// Samples per strategy (a 2⁹ × 2⁸ jittered grid).
const SAMPLES: u32 = 1 << 17;

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
    let grid: Vec<(f32, f32)> = [0.05f32, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0]
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
                let corners = local_quad(&frame, Vec3::ZERO, quad.corner.as_vec3(), quad.u.as_vec3(), quad.v.as_vec3());
                let lobe = lookup(table, roughness, view.z as f32);
                let specular = f64::from(lobe.magnitude) * f64::from(specular_form_factor(&lobe, corners));
                let diffuse = f64::from(diffuse_form_factor(corners));
                Case {
                    roughness,
                    view_degrees,
                    light,
                    diffuse: (diffuse, diffuse_ref.0, diffuse_ref.1),
                    specular: (specular, specular_ref.0, specular_ref.1),
                    magnitude: f64::from(lobe.magnitude),
                }
            })
        })
        .collect();

    // Relative error beyond the reference's own 3σ; values below 1e-4 are compared absolutely.
    let excess = |(ours, reference, rel_sigma): (f64, f64, f64)| {
        let scale = reference.max(1e-4);
        ((ours - reference).abs() / scale - 3.0 * rel_sigma).max(0.0)
    };
    let mut spec_errors = Vec::new();
    let mut energy_errors = Vec::new();
    let mut energy_errors_to_80 = Vec::new();
    println!("roughness  view°   light                         diffuse err   specular: LTC      reference   err");
    for c in &cases {
        let d = excess(c.diffuse);
        let s = excess(c.specular);
        println!(
            "{:>9} {:>6} {:<30} {:>9.2e}    {:>10.5} {:>10.5} {:>7.2}%",
            c.roughness,
            c.view_degrees,
            c.light,
            d,
            c.specular.0,
            c.specular.1,
            100.0 * s
        );
        assert!(c.diffuse.0.is_finite() && c.specular.0.is_finite());
        assert!(d <= 0.005, "diffuse lobe off by {d} at {} {}° {}", c.roughness, c.view_degrees, c.light);
        if c.roughness >= 0.1 {
            spec_errors.push(s);
            let e = ((c.specular.0 - c.specular.1).abs() - 3.0 * c.specular.2 * c.specular.1).max(0.0) / c.magnitude;
            energy_errors.push(e);
            if c.view_degrees <= 80.0 {
                energy_errors_to_80.push(e);
            }
        }
    }
    energy_errors.sort_by(f64::total_cmp);
    println!(
        "specular error relative to the lobe's albedo at roughness ≥ 0.1: median {:.2} %, p90 {:.2} %, max {:.2} %",
        100.0 * energy_errors[energy_errors.len() / 2],
        100.0 * energy_errors[energy_errors.len() * 9 / 10],
        100.0 * energy_errors[energy_errors.len() - 1]
    );
    energy_errors_to_80.sort_by(f64::total_cmp);
    println!("… views ≤ 80°: max {:.2} %", 100.0 * energy_errors_to_80[energy_errors_to_80.len() - 1]);
    spec_errors.sort_by(f64::total_cmp);
    let median = spec_errors[spec_errors.len() / 2];
    let max = spec_errors[spec_errors.len() - 1];
    println!(
        "specular relative to the reference at roughness ≥ 0.1: median {:.2} %, max {:.2} %",
        100.0 * median,
        100.0 * max
    );
    let at = |q: f64| energy_errors[((energy_errors.len() - 1) as f64 * q) as usize];
    assert!(at(0.5) <= 0.001, "specular median error (albedo-relative) {}", at(0.5));
    assert!(at(0.9) <= 0.015, "specular p90 error (albedo-relative) {}", at(0.9));
    assert!(at(1.0) <= 0.05, "specular max error (albedo-relative) {}", at(1.0));
    assert!(median <= 0.01, "specular median error (relative to the reference) {median}");
}
