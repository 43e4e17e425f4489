//! What the denoise stage must get right, on the CPU backend (the Vulkan passes run the same
//! kernel functions; `parity_denoise.rs` holds them to the CPU).
//!
//! **Hard cases, built directly as [`DenoiseInput`]s** (no scene):
//! - a depth discontinuity — a fully lit near plane beside a far plane in a coin-flip shadow, the
//!   configuration of a contact shadow seen past an occluder's silhouette: the noise lines of the
//!   lit pixels near the edge cross into the shadow, so those pixels are filtered with a wide
//!   Gaussian, and only the edge stops keep the shadow from leaking onto them. A control with both
//!   halves at the same depth shows the leak the edge stops prevent (measured: the lit side
//!   exactly `U` with the depth edge, for TV and SVGF; 0.199 (TV) and 0.191 (SVGF) relative off
//!   next to the edge without it; the shadow's RMS 0.023 (TV), 0.013 (SVGF), raw 0.5);
//! - regions where `U ≈ 0` (no light reaches them, `U_N = 0` too): the output is exactly the
//!   emitted radiance there, and nothing becomes NaN or Inf when inputs are zero;
//! - a noise-free ratio (`S_N = U_N` everywhere): the TV filter returns `U + emitted` exactly.
//!
//! **Scene quality** against a converged reference (the ratio estimate at [`REFERENCE_SPP`] spp,
//! cached under `CARGO_TARGET_TMPDIR` per build of this test, so a change to the shading code or
//! its tables never meets a stale reference), relMSE averaged over [`SEEDS`], at 128² with the
//! footprint `DenoiseParams::new` picks there (R = 2, two à-trous iterations — the 1-spp relMSE
//! minimum on the Cornell box; the two-light box would prefer R = 3 by 15 %), at each of [`SPP`]: on both built-in scenes the
//! TV-guided filter of the ratio must beat the raw ratio, the SVGF baseline and the stochastic
//! image raw and TV-filtered, at 1, 4 and 8 spp, each ordering at 95 % one-sided confidence (a
//! paired Student-t test over the seeds' frames, [`assert_lower`]); at 16 = 4R² spp, where its Gaussian
//! (`R/√N` at most) is down to ½ pixel, it must be the raw ratio exactly. At 1 spp it must also
//! have the lowest mean FLIP (`raywave::report::flip`, the LDR display image) of every method.
//!
//! Measured (CPU, 128², seeds 1–4, reference 4096 spp; the two-light rows again 2026-11-30, after
//! the light choice took the quads' own cosine bounds and a uniform share in the scan), relMSE:
//!
//! | scene | spp | stochastic | stochastic+tv | ratio | ratio+tv | ratio+svgf |
//! |---|---|---|---|---|---|---|
//! | cornell-two-lights | 1 | 0.02765 | 0.00114 | 0.00826 | 0.00049 | 0.00165 |
//! | cornell-two-lights | 4 | 0.00233 | 0.00046 | 0.00105 | 0.00022 | 0.00039 |
//! | cornell-two-lights | 8 | 0.00086 | 0.00041 | 0.00040 | 0.00022 | 0.00035 |
//! | cornell-two-lights | 16 | 0.00031 | 0.00031 | 0.00016 | 0.00016 | 0.00035 |
//! | cornell | 1 | 0.00464 | 0.00028 | 0.00180 | 0.00017 | 0.00030 |
//! | cornell | 4 | 0.00039 | 0.00012 | 0.00018 | 0.00007 | 0.00027 |
//! | cornell | 8 | 0.00015 | 0.00009 | 0.00006 | 0.00005 | 0.00027 |
//! | cornell | 16 | 0.000055 | 0.000055 | 0.000020 | 0.000020 | 0.00027 |
//!
//! Mean FLIP at 1 spp (stochastic, stochastic+tv, ratio, ratio+tv, ratio+svgf): two lights 0.045,
//! 0.039, 0.026, **0.013**, 0.025; Cornell 0.029, 0.027, 0.0092, **0.0082**, 0.013 — ratio+tv at
//! 0.33× and 0.31× of stochastic+tv. Re-measured 2026-11-27 after the SVGF baseline's fix
//! (pixels that drew no light sample skipped as taps and filled, not averaged in as visibility
//! 1): its 1-spp column read 0.00167 / 0.00031 in the measurement before (f7ac952), which also
//! predates shade-stage changes that moved the stochastic column by 0.1 %, so only part of that
//! difference is the fix — these scenes have few such pixels. From 4 spp on, ratio+tv
//! and the raw ratio are within 2 % in FLIP (Cornell at 4 spp: 0.0045 vs 0.0044), so only the
//! 1-spp ordering is asserted.
//!
//! Before the `1/√N` narrowing the filter kept its 1-spp width at every `N` and plateaued at
//! ≈ 1·10⁻⁴ (Cornell) from 4 spp on, blurring shadow edges, so the raw ratio beat it from
//! ~8 spp.
//!
//! Issue 6 asks for ratio+tv ≤ 0.25 × stochastic+tv at 1 spp; measured 0.43 (two lights) and 0.62
//! (Cornell), so that target is printed, not asserted, until it is met. Where the error is: split
//! by region (Cornell, 1 spp), ratio+tv is 20× better than stochastic+tv in unshadowed pixels
//! (6·10⁻⁶ vs 1.1·10⁻⁴ of the image's relMSE) but equal in penumbrae (1.3·10⁻⁴ each) and umbrae
//! (4·10⁻⁵ each): there both filter one binary visibility sample per pixel, and ~60 % of that
//! error is the blur's bias at the shadows' edges. The split is `MethodError::relmse_shadow` /
//! `relmse_lit`; the test prints it and asserts ratio+tv's lit part below a tenth of
//! stochastic+tv's. With a lit part of 0, ratio+tv would still be 0.60× (Cornell) and 0.42× (two
//! lights) of stochastic+tv. No footprint gets there (`--denoise-radius` 1 … 6 at 128², 3 and 4
//! at 256²: 0.43–0.78× on the Cornell box, 0.32–0.53× with two lights), nor one picked per 8×8
//! tile by an oracle that knows the reference (`examples/footprint_oracle.rs`: 0.51× and 0.30×
//! from the shadowed part alone). (With R = 10 at 64² the ratio held on the
//! two-light box, 0.18, but ratio+tv then did no better than the raw ratio on the Cornell box: the
//! wide blur spread lit floor into the umbrae under the blocks.)
//!
//! Computing a reference takes about 140 s in the test profile (both at once on two cores), once
//! per build of this test; the cached ones load in milliseconds.

use glam::{Vec3, Vec4};
use raywave::cpu::CpuBackend;
use raywave::denoise::{DenoiseInput, DenoiseMethod};
use raywave::kernels::hash::CounterRng;
use raywave::kernels::sampling::light_select::luminance;
use raywave::report::error_vs_time::{MethodError, PreparedScene, METHODS};
use raywave::shared::denoise::MAX_RADIUS;
use raywave::shared::DenoiseParams;
use raywave::{Backend, Scene};
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::path::PathBuf;
use std::time::Instant;

/// 1 or 0 with equal probability: a coin-flip visibility.
fn coin(rng: &mut CounterRng) -> f32 {
    if rng.next_f32() < 0.5 {
        1.0
    } else {
        0.0
    }
}

/// One pixel of a synthetic input.
#[derive(Copy, Clone, Debug, Default)]
struct Pixel {
    /// Surface point; `None` for a miss.
    point: Option<Vec3>,
    normal: Vec3,
    analytic: Vec3,
    unshadowed: Vec3,
    shadowed: Vec3,
    emitted: Vec3,
}

/// A `width × height` input from `pixel(x, y)`; depth is the distance from the origin (the
/// camera).
fn build(width: u32, height: u32, mut pixel: impl FnMut(u32, u32) -> Pixel) -> (DenoiseParams, DenoiseInput) {
    let mut input = DenoiseInput::default();
    for y in 0..height {
        for x in 0..width {
            let p = pixel(x, y);
            match p.point {
                Some(point) => {
                    input.position.push(point.extend(point.length()));
                    input.normal.push(p.normal.extend(luminance(p.analytic)));
                }
                None => {
                    input.position.push(Vec4::ZERO);
                    input.normal.push(Vec4::ZERO);
                }
            }
            input.analytic.push(p.analytic.extend(0.0));
            input.unshadowed.push(p.unshadowed.extend(0.0));
            input.shadowed.push(p.shadowed.extend(0.0));
            input.emitted.push(p.emitted.extend(0.0));
        }
    }
    // The widest footprint, whatever the image size: the hard cases are hardest with it.
    let params = DenoiseParams { seed: 5, ..DenoiseParams::with_radius(width, height, MAX_RADIUS) };
    (params, input)
}

/// The point of a camera-facing plane at distance `distance` seen through pixel `(x, y)` of a
/// `width × height` image (90° field of view).
fn on_plane(x: u32, y: u32, width: u32, height: u32, distance: f32) -> Vec3 {
    let side = width.max(height) as f32;
    let u = (x as f32 + 0.5 - 0.5 * width as f32) / (0.5 * side);
    let v = (0.5 * height as f32 - y as f32 - 0.5) / (0.5 * side);
    Vec3::new(u, v, -1.0) * distance
}

/// `method`'s image of `input` on the CPU, finite, and computed so: the passes replace a value
/// that went non-finite and count it, and the hard cases here must not make one.
fn denoise(method: DenoiseMethod, params: &DenoiseParams, input: &DenoiseInput) -> Vec<Vec3> {
    let (color, timings) = CpuBackend::new().denoise(method, params, input).expect("denoise");
    assert_eq!(timings.len(), method.passes(params).len());
    assert_eq!(color.len(), input.len());
    for pass in &timings {
        assert_eq!(pass.sanitized, 0, "{}: pass {} replaced non-finite values", method.name(), pass.stage);
    }
    let bad = color.iter().filter(|c| !c.is_finite()).count();
    assert_eq!(bad, 0, "{}: {bad} non-finite pixels", method.name());
    raywave::denoise::rgb(&color)
}

/// Largest relative difference of the channels of `a` and `b`.
fn rel(a: Vec3, b: Vec3) -> f32 {
    ((a - b).abs() / a.abs().max(b.abs()).max(Vec3::splat(1e-6))).max_element()
}

const EDGE_WIDTH: u32 = 64;
const EDGE_HEIGHT: u32 = 32;
/// First column of the shadowed far plane.
const EDGE: u32 = 32;
const LIT: Vec3 = Vec3::new(0.8, 0.7, 0.6);
const SHADOWED: Vec3 = Vec3::new(0.5, 0.5, 0.5);

/// Left of [`EDGE`] a near plane (distance `near`) fully lit — `S_N = U_N`, `U_N` itself noisy —
/// right of it a plane at distance 10 in a coin-flip shadow.
fn depth_edge(near: f32) -> (DenoiseParams, DenoiseInput) {
    let mut rng = CounterRng::new(42);
    build(EDGE_WIDTH, EDGE_HEIGHT, |x, y| {
        let lit = x < EDGE;
        let analytic = if lit { LIT } else { SHADOWED };
        let unshadowed = analytic * (0.5 + rng.next_f32());
        let visible = if lit { 1.0 } else { coin(&mut rng) };
        Pixel {
            point: Some(on_plane(x, y, EDGE_WIDTH, EDGE_HEIGHT, if lit { near } else { 10.0 })),
            normal: Vec3::Z,
            analytic,
            unshadowed,
            shadowed: unshadowed * visible,
            emitted: Vec3::ZERO,
        }
    })
}

/// Largest relative deviation from `U` on the lit side, within `columns` of the edge.
fn lit_deviation(color: &[Vec3], input: &DenoiseInput, columns: u32) -> f32 {
    let mut worst: f32 = 0.0;
    for y in 0..EDGE_HEIGHT {
        for x in EDGE - columns..EDGE {
            let i = (y * EDGE_WIDTH + x) as usize;
            worst = worst.max(rel(color[i], input.analytic[i].truncate()));
        }
    }
    worst
}

/// RMS deviation of the shadowed side's visibility (colour / `U`, luminance) from its mean.
fn shadow_rms(color: &[Vec3]) -> f32 {
    let visibility: Vec<f32> = (0..EDGE_HEIGHT)
        .flat_map(|y| (EDGE..EDGE_WIDTH).map(move |x| (y * EDGE_WIDTH + x) as usize))
        .map(|i| luminance(color[i]) / luminance(SHADOWED))
        .collect();
    let mean = visibility.iter().sum::<f32>() / visibility.len() as f32;
    (visibility.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / visibility.len() as f32).sqrt()
}

#[test]
fn shadows_do_not_leak_across_depth_edges() {
    let (params, input) = depth_edge(1.0);
    let raw: Vec<Vec3> = (0..input.len())
        .map(|i| {
            let (u, s, u_n) =
                (input.analytic[i].truncate(), input.shadowed[i].truncate(), input.unshadowed[i].truncate());
            u * s / u_n
        })
        .collect();
    let raw_rms = shadow_rms(&raw);
    for method in [DenoiseMethod::Tv, DenoiseMethod::Svgf] {
        let color = denoise(method, &params, &input);
        let adjacent = lit_deviation(&color, &input, 1);
        let lit = lit_deviation(&color, &input, EDGE);
        let rms = shadow_rms(&color);
        eprintln!(
            "{}: lit side off U by {adjacent:.2e} next to the edge, {lit:.2e} anywhere; shadow RMS {rms:.3} \
             (raw {raw_rms:.3})",
            method.name()
        );
        assert!(lit <= 1e-3, "{}: the shadow leaks onto the lit plane ({lit:.2e} relative)", method.name());
        assert!(rms < 0.5 * raw_rms, "{}: the shadow is not denoised (RMS {rms} vs {raw_rms})", method.name());
    }
    // The control: the same image with both halves at the same depth (one plane, same normal)
    // does leak — the TV filter's noise lines reach across, and only the analytic stop, not the
    // depth stop, weighs the shadowed taps down — so the assertion above measures the edge stops.
    let (params, flat) = depth_edge(10.0);
    for method in [DenoiseMethod::Tv, DenoiseMethod::Svgf] {
        let color = denoise(method, &params, &flat);
        let leak = lit_deviation(&color, &flat, 1);
        eprintln!("{} without the depth edge: lit side off U by {leak:.2e} next to the edge", method.name());
        assert!(leak > 1e-2, "{}: the control does not leak ({leak:.2e})", method.name());
    }
}

#[test]
fn unlit_regions_show_their_emission_exactly_and_zeros_stay_finite() {
    const SIZE: u32 = 32;
    let mut rng = CounterRng::new(7);
    let dark = |x: u32, y: u32| (8..16).contains(&x) && (8..20).contains(&y);
    let (params, input) = build(SIZE, SIZE, |x, y| {
        let point = on_plane(x, y, SIZE, SIZE, 5.0);
        if y == SIZE - 1 {
            // A row of background: no surface.
            return Pixel { emitted: Vec3::new(0.1, 0.2, 0.3), ..Pixel::default() };
        }
        if dark(x, y) {
            // No light reaches it (U = U_N = S_N = 0), but it glows.
            let emitted = if (x + y) % 3 == 0 { Vec3::new(2.0, 1.0, 0.5) } else { Vec3::ZERO };
            return Pixel { point: Some(point), normal: Vec3::Z, emitted, ..Pixel::default() };
        }
        let analytic = Vec3::new(0.7, 0.6, 0.5);
        // Some lit pixels drew no sample that reached the light: U_N = S_N = 0.
        let unshadowed = if (x * 7 + y * 3) % 11 == 0 { Vec3::ZERO } else { analytic * (0.5 + rng.next_f32()) };
        Pixel {
            point: Some(point),
            normal: Vec3::Z,
            analytic,
            unshadowed,
            shadowed: unshadowed * coin(&mut rng),
            emitted: Vec3::ZERO,
        }
    });
    let zeros = DenoiseInput {
        position: input.position.clone(),
        normal: input.normal.iter().map(|n| n.truncate().extend(0.0)).collect(),
        ..build(SIZE, SIZE, |_, _| Pixel::default()).1
    };
    for method in [DenoiseMethod::Tv, DenoiseMethod::Svgf] {
        let color = denoise(method, &params, &input);
        let mut dark_pixels = 0;
        for y in 0..SIZE {
            for x in 0..SIZE {
                let i = (y * SIZE + x) as usize;
                if dark(x, y) {
                    assert_eq!(color[i], input.emitted[i].truncate(), "{}: pixel ({x}, {y})", method.name());
                    dark_pixels += 1;
                }
            }
        }
        assert_eq!(dark_pixels, 8 * 12);
        // A lit pixel that drew no sample reaching the light (U_N = 0) takes the filtered ratio of
        // its neighbours, not the raw fallback to U: its visibility is about the coin's ½. (TV adds
        // it as 0 to both sums; SVGF skips it as a tap and fills it from its measured neighbours.)
        {
            let mut fallbacks = 0;
            for y in 0..SIZE - 1 {
                for x in (0..SIZE).filter(|&x| !dark(x, y) && (x * 7 + y * 3) % 11 == 0) {
                    let i = (y * SIZE + x) as usize;
                    let visibility = color[i].x / input.analytic[i].x;
                    assert!((0.2..0.8).contains(&visibility), "pixel ({x}, {y}): visibility {visibility}");
                    fallbacks += 1;
                }
            }
            assert!(fallbacks > 50, "{fallbacks}");
        }
        // A black image (and its stochastic variant, whose S_N mean is 0) stays black.
        for (what, inputs) in [("zeros", &zeros), ("stochastic zeros", &zeros.stochastic())] {
            let color = denoise(method, &params, inputs);
            assert!(color.iter().all(|&c| c == Vec3::ZERO), "{}: {what} not black", method.name());
        }
        denoise(method, &params, &input.stochastic());
    }
}

#[test]
fn an_umbra_stays_dark_where_pixels_drew_no_light_sample() {
    // An umbra (S_N = 0) under a light the surface faces (U > 0), in which a third of the pixels,
    // at random, and an 8 × 8 block drew no sample that reached the light (U_N = S_N = 0, ratio
    // undefined, fallback 1). Those are no measurement of visibility: every pixel must come out
    // dark. Averaged in as visibility 1, as the SVGF baseline did, they lifted the umbra to about
    // a third of U; the block's middle has no measured pixel in SVGF's 7 × 7 moments window.
    const SIZE: u32 = 32;
    let mut rng = CounterRng::new(11);
    let (params, input) = build(SIZE, SIZE, |x, y| {
        let analytic = Vec3::new(0.7, 0.6, 0.5);
        let block = (8..16).contains(&x) && (8..16).contains(&y);
        let drew_no_light_sample = rng.next_f32() < 1.0 / 3.0 || block;
        let unshadowed = if drew_no_light_sample { Vec3::ZERO } else { analytic * (0.5 + rng.next_f32()) };
        Pixel {
            point: Some(on_plane(x, y, SIZE, SIZE, 5.0)),
            normal: Vec3::Z,
            analytic,
            unshadowed,
            shadowed: Vec3::ZERO,
            emitted: Vec3::ZERO,
        }
    });
    for method in [DenoiseMethod::Tv, DenoiseMethod::Svgf] {
        let color = denoise(method, &params, &input);
        let lit = color.iter().filter(|&&c| c != Vec3::ZERO).count();
        assert_eq!(lit, 0, "{}: {lit} of {} umbra pixels lit", method.name(), color.len());
    }
}

#[test]
fn a_noise_free_ratio_passes_through_exactly() {
    const WIDTH: u32 = 41;
    const HEIGHT: u32 = 27;
    let mut rng = CounterRng::new(3);
    let (params, input) = build(WIDTH, HEIGHT, |x, y| {
        if x == 0 {
            return Pixel { emitted: Vec3::splat(0.25), ..Pixel::default() };
        }
        // Depth, analytic term and U_N all vary (U_N is noisy and sometimes 0); the ratio is 1.
        let analytic = Vec3::new(0.9, 0.5, 0.2) * (0.2 + rng.next_f32());
        let unshadowed = if rng.next_f32() < 0.1 { Vec3::ZERO } else { analytic * (0.2 + 2.0 * rng.next_f32()) };
        Pixel {
            point: Some(on_plane(x, y, WIDTH, HEIGHT, 3.0 + 0.1 * x as f32)),
            normal: Vec3::new(0.0, 0.3, 1.0).normalize(),
            analytic,
            unshadowed,
            shadowed: unshadowed,
            emitted: if (x + y) % 5 == 0 { Vec3::new(0.0, 1.5, 3.0) } else { Vec3::ZERO },
        }
    });
    let expected: Vec<Vec3> = (0..input.len()).map(|i| (input.analytic[i] + input.emitted[i]).truncate()).collect();
    assert_eq!(denoise(DenoiseMethod::Tv, &params, &input), expected, "TV changed a noise-free ratio");
    let svgf = denoise(DenoiseMethod::Svgf, &params, &input);
    let worst = svgf.iter().zip(&expected).map(|(&a, &b)| rel(a, b)).fold(0.0, f32::max);
    assert!(worst < 1e-6, "SVGF moved a noise-free ratio by {worst:e}");
}

/// Side of the scene images.
const RESOLUTION: u32 = 128;
/// Samples per pixel of the reference.
const REFERENCE_SPP: u32 = 4096;
/// Sampler seeds of the measured frames (the reference uses its own).
const SEEDS: [u32; 4] = [1, 2, 3, 4];

/// A fingerprint of this test binary: the reference depends on every piece of shading code and
/// data (the LTC table, the sampler, the kernels) compiled into it, so the cache is keyed on the
/// binary itself. Computed once per process (the scene tests share it).
fn build_fingerprint() -> u64 {
    static FINGERPRINT: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
    *FINGERPRINT.get_or_init(|| {
        use std::hash::{Hash, Hasher};
        let exe = std::env::current_exe().and_then(std::fs::read).expect("read the test binary");
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        exe.hash(&mut hasher);
        hasher.finish()
    })
}

/// The reference image of `scene_name`, from the cache under `CARGO_TARGET_TMPDIR` (raw
/// little-endian f32 RGB, one file per scene and [`build_fingerprint`]) or computed and cached;
/// references of other builds are deleted.
fn reference(backend: &mut CpuBackend, prepared: &PreparedScene, scene_name: &str) -> Vec<Vec3> {
    let file = scene_name.replace(|c: char| !c.is_ascii_alphanumeric(), "_");
    let prefix = format!("denoise-reference-{file}-{RESOLUTION}px-{REFERENCE_SPP}spp");
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let path = dir.join(format!("{prefix}-{:016x}.f32", build_fingerprint()));
    let pixels = (RESOLUTION * RESOLUTION) as usize;
    if let Ok(bytes) = std::fs::read(&path) {
        if bytes.len() == pixels * 12 {
            let floats: Vec<f32> =
                bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
            return floats.chunks_exact(3).map(Vec3::from_slice).collect();
        }
    }
    let start = Instant::now();
    let (image, sanitized) = prepared.reference(backend, REFERENCE_SPP).expect("reference");
    assert_eq!(sanitized, 0, "{scene_name}: the reference's stages replaced values");
    eprintln!("{scene_name}: reference at {REFERENCE_SPP} spp took {:.1} s", start.elapsed().as_secs_f64());
    let bytes: Vec<u8> = image.iter().flat_map(|c| c.to_array()).flat_map(f32::to_le_bytes).collect();
    let partial = path.with_extension(format!("{}.partial", std::process::id()));
    std::fs::write(&partial, bytes).expect("write the reference");
    std::fs::rename(&partial, &path).expect("cache the reference");
    let stale = std::fs::read_dir(&dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        // Not another test process's file in progress, which it is about to rename.
        .filter(|p| {
            let name = p.file_name().and_then(|n| n.to_str());
            p != &path && name.is_some_and(|n| n.starts_with(&prefix) && !n.ends_with(".partial"))
        });
    for old in stale {
        let _ = std::fs::remove_file(old);
    }
    image
}

/// Samples per pixel the scene tests measure: 1 (issue 6's target), the filter narrowing as
/// `1/√N` at 4 and 8, and 16 = 4R², where the TV filter at R = 2 is the identity.
const SPP: [u32; 4] = [1, 4, 8, 16];

/// One-sided confidence of each ordering the scene tests assert ([`assert_lower`]).
const CONFIDENCE: f64 = 0.95;

/// Every method's errors ([`METHODS`] order) in the frame of each of [`SEEDS`].
type SeedErrors = Vec<[MethodError; METHODS.len()]>;

/// [`SeedErrors`] at each of [`SPP`]; prints every method's means over the seeds.
fn scene_errors(scene_name: &str) -> Vec<(u32, SeedErrors)> {
    let mut backend = CpuBackend::new();
    let scene = Scene::load(scene_name).expect("built-in scene loads");
    let prepared = PreparedScene::new(&mut backend, &scene, RESOLUTION).expect("G-buffer");
    let reference = reference(&mut backend, &prepared, scene_name);
    SPP.iter()
        .map(|&spp| {
            let seed_errors: SeedErrors = SEEDS
                .iter()
                .map(|&seed| {
                    let (errors, sanitized) = prepared.errors(&mut backend, &reference, spp, &[seed]).expect("frames");
                    assert_eq!(sanitized, 0, "{scene_name} at {spp} spp, seed {seed}");
                    errors
                })
                .collect();
            for method in METHODS {
                let (relmse, flip) = (mean(&of(&seed_errors, method, relmse)), mean(&of(&seed_errors, method, flip)));
                eprintln!("{scene_name}: {spp:>2} spp {method:<14} relMSE {relmse:.6}  FLIP {flip:.4}");
            }
            (spp, seed_errors)
        })
        .collect()
}

/// A method's relative MSE ([`MethodError::relmse`]).
fn relmse(error: &MethodError) -> f64 {
    error.relmse
}

/// A method's mean FLIP ([`MethodError::flip`]).
fn flip(error: &MethodError) -> f64 {
    error.flip
}

/// `metric` of `method` in each seed's frame.
fn of(seed_errors: &SeedErrors, method: &str, metric: fn(&MethodError) -> f64) -> Vec<f64> {
    let index = METHODS.iter().position(|m| *m == method).expect("a method");
    seed_errors.iter().map(|errors| metric(&errors[index])).collect()
}

/// The mean of `values`.
fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// Asserts that the expectation of `lower` is below that of `higher` with [`CONFIDENCE`]: a
/// one-sided paired Student-t test over the seeds, each pair measured on the same frames, so the
/// differences `higher − lower` must have a mean above `t · s/√n` (`s` their sample standard
/// deviation, `t` the quantile for `n − 1` degrees of freedom: 2.35 for 4 seeds). Each value is
/// a mean over every pixel of a frame, close to normal. `what` names the case in the message.
fn assert_lower(lower: &[f64], higher: &[f64], what: &str) {
    let mut differences = raywave::report::Repeated::default();
    for (low, high) in lower.iter().zip(higher) {
        differences.add(high - low);
    }
    let degrees = (lower.len() - 1) as f64;
    let t = StudentsT::new(0.0, 1.0, degrees).expect("at least two seeds").inverse_cdf(CONFIDENCE);
    let standard_error = differences.standard_error().expect("at least two seeds");
    let margin = differences.mean() - t * standard_error;
    assert!(
        margin > 0.0,
        "{what}: {lower:?} vs {higher:?} — the mean difference {:.3e} is not above t·s/√n = {:.3e}",
        differences.mean(),
        t * standard_error
    );
}

/// Asserts that ratio+tv's `metric` is below that of every other method — the raw ratio, the SVGF
/// baseline and the stochastic image raw and TV-filtered ([`assert_lower`]); `what` names the case
/// in the message.
fn assert_ratio_tv_lowest(seed_errors: &SeedErrors, metric: fn(&MethodError) -> f64, what: &str) {
    let ratio_tv = of(seed_errors, "ratio+tv", metric);
    for other in ["ratio", "ratio+svgf", "stochastic+tv", "stochastic"] {
        assert_lower(&ratio_tv, &of(seed_errors, other, metric), &format!("{what}, ratio+tv vs {other}"));
    }
}

/// Asserts what holds on `scene_name`: at every measured spp below 4R², ratio+tv beats the raw
/// ratio, the SVGF baseline and the TV filter of the stochastic image (raw and filtered) in
/// relMSE, and at 1 spp in FLIP too, each at [`CONFIDENCE`]; from 4R² on it is the raw ratio
/// exactly, in every frame. Prints the 1-spp gain over stochastic+tv that issue 6 asks to be
/// ≤ 0.25 in relMSE (not met yet; see the module documentation), and the same gain in FLIP.
fn assert_ratio_tv_wins(scene_name: &str) {
    let shipped = DenoiseParams::new(RESOLUTION, RESOLUTION);
    for (spp, seed_errors) in scene_errors(scene_name) {
        let gain = |metric: fn(&MethodError) -> f64| {
            mean(&of(&seed_errors, "ratio+tv", metric)) / mean(&of(&seed_errors, "stochastic+tv", metric))
        };
        if spp == 1 {
            eprintln!("{scene_name}: ratio+tv / stochastic+tv = {:.3}", gain(relmse));
            eprintln!("{scene_name}: FLIP ratio+tv / stochastic+tv = {:.3}", gain(flip));
            assert_ratio_tv_lowest(&seed_errors, flip, &format!("{scene_name} at 1 spp, FLIP"));
            assert_ratio_tv_gains_where_lit(scene_name, &seed_errors);
        }
        let params = DenoiseParams { samples_per_pixel: spp, ..shipped };
        if params.tv_filter_is_identity() {
            assert_eq!(
                of(&seed_errors, "ratio+tv", relmse),
                of(&seed_errors, "ratio", relmse),
                "{scene_name} at {spp} spp: the identity filter"
            );
            continue;
        }
        assert_ratio_tv_lowest(&seed_errors, relmse, &format!("{scene_name} at {spp} spp, relMSE"));
    }
}

/// Asserts where ratio+tv's advantage over stochastic+tv is made at 1 spp: in unshadowed pixels,
/// where its `U · S_N/U_N` is exactly `U`, its part of the relMSE is under a tenth of
/// stochastic+tv's (at [`CONFIDENCE`]); in shadowed ones both filter one binary visibility sample
/// per pixel, and the parts (printed, means over the seeds) are alike. In every frame the parts
/// add up to no more than the whole.
fn assert_ratio_tv_gains_where_lit(scene_name: &str, seed_errors: &SeedErrors) {
    for method in ["ratio+tv", "stochastic+tv"] {
        let [whole, shadow, lit] = [relmse, |e: &MethodError| e.relmse_shadow, |e: &MethodError| e.relmse_lit]
            .map(|m| of(seed_errors, method, m));
        eprintln!(
            "{scene_name}: 1 spp {method:<14} relMSE {:.6} = shadow {:.6} + lit {:.6} + unlit {:.6}",
            mean(&whole),
            mean(&shadow),
            mean(&lit),
            mean(&whole) - mean(&shadow) - mean(&lit)
        );
        for ((whole, shadow), lit) in whole.iter().zip(&shadow).zip(&lit) {
            assert!(shadow + lit <= whole * (1.0 + 1e-12), "{method}: parts beyond the whole");
        }
    }
    let lit = |e: &MethodError| e.relmse_lit;
    let tenth_of_stochastic_tv: Vec<f64> = of(seed_errors, "stochastic+tv", lit).iter().map(|e| 0.1 * e).collect();
    assert_lower(&of(seed_errors, "ratio+tv", lit), &tenth_of_stochastic_tv, &format!("{scene_name} lit"));
}

#[test]
fn ratio_tv_beats_every_baseline_on_the_two_light_cornell_box() {
    assert_ratio_tv_wins("builtin:cornell-two-lights");
}

#[test]
fn ratio_tv_beats_every_baseline_on_the_cornell_box() {
    assert_ratio_tv_wins("builtin:cornell");
}
