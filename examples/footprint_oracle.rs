//! How far the TV filter's footprint alone could take issue 6's 1-spp target (ratio+tv relMSE
//! ≤ 0.25 × stochastic+tv): an **oracle** that picks, for each `tile × tile` block of pixels, the
//! radius R ∈ 1…10 (or no filter) whose image has the least error there against the converged
//! reference — knowledge no filter has — so its error bounds from below every rule that sets the
//! footprint per tile of that size.
//!
//! ```text
//! cargo run --release --no-default-features --example footprint_oracle -- --resolution 128 --tile 8
//! ```
//!
//! Per scene and input (the ratio estimate and the fully stochastic `S_N`), it prints the relMSE
//! parts made in shadowed and in unshadowed pixels (`raywave report error-vs-time`'s split) of the
//! TV filter at every fixed R, then the oracle's shadowed part, and that part over stochastic+tv's
//! whole relMSE at the image's default R. The tiles are chosen by their shadowed pixels only, so
//! the oracle's lit part would be no better than the best fixed R's. CPU backend; the frames are
//! the report's (`PreparedScene`, seeds 0 … reps − 1, one sample per pixel).

use clap::Parser;
use glam::Vec3;
use raywave::cpu::CpuBackend;
use raywave::denoise::{rgb, DenoiseInput, DenoiseMethod};
use raywave::report::error_vs_time::{relmse_part, PreparedScene};
use raywave::report::shade::accumulate;
use raywave::report::SceneReportOptions;
use raywave::shared::denoise::MAX_RADIUS;
use raywave::shared::DenoiseParams;
use raywave::{Backend, Scene};
use std::process::ExitCode;

#[derive(Parser)]
#[command(about = "Bound the TV filter's 1-spp error under the best footprint per tile")]
struct Args {
    /// Built-in scenes, comma-separated.
    #[arg(long, default_value = "builtin:cornell,builtin:cornell-two-lights", value_delimiter = ',')]
    scenes: Vec<String>,
    /// Image side in pixels (4 to 1024).
    #[arg(long, default_value_t = 128)]
    resolution: u32,
    /// Side of the blocks the oracle chooses a radius for, in pixels (≥ 1).
    #[arg(long, default_value_t = 8)]
    tile: u32,
    /// Samples per pixel of the reference.
    #[arg(long, default_value_t = 4096)]
    reference_spp: u32,
    /// Frames (seeds) averaged.
    #[arg(long, default_value_t = 4)]
    reps: u32,
}

/// Relative-MSE parts of one input, summed over the frames.
struct Parts {
    /// Shadowed and unshadowed parts per candidate: no filter, then R = 1 … MAX_RADIUS.
    fixed: Vec<(f64, f64)>,
    /// The oracle's shadowed part.
    oracle: f64,
}

/// The pixels of `region` in each `tile × tile` block of a `side × side` image.
fn tiles(region: &[usize], side: u32, tile: u32) -> Vec<Vec<usize>> {
    let per_row = side.div_ceil(tile) as usize;
    let mut blocks = vec![Vec::new(); per_row * per_row];
    for &i in region {
        let (x, y) = (i % side as usize, i / side as usize);
        blocks[(y / tile as usize) * per_row + x / tile as usize].push(i);
    }
    blocks
}

/// Every candidate's image of one frame: the raw composite, then the TV filter at R = 1 … 10.
fn candidates(backend: &mut CpuBackend, input: &DenoiseInput, side: u32, seed: u32) -> raywave::Result<Vec<Vec<Vec3>>> {
    let params =
        |radius| DenoiseParams { seed, samples_per_pixel: 1, ..DenoiseParams::with_radius(side, side, radius) };
    let mut images = vec![rgb(&backend.denoise(DenoiseMethod::None, &params(1), input)?.0)];
    for radius in 1..=MAX_RADIUS {
        images.push(rgb(&backend.denoise(DenoiseMethod::Tv, &params(radius), input)?.0));
    }
    Ok(images)
}

fn measure(args: &Args, name: &str, scene: &Scene) -> raywave::Result<()> {
    let mut backend = CpuBackend::new();
    let side = args.resolution;
    let prepared = PreparedScene::new(&mut backend, scene, side)?;
    let (reference, sanitized) = prepared.reference(&mut backend, args.reference_spp)?;
    if sanitized > 0 {
        eprintln!("warning: {name}: the reference's stages replaced {sanitized} non-finite value(s)");
    }
    let regions = prepared.shadow_regions(&reference);
    let blocks = tiles(&regions.shadow, side, args.tile);
    // Candidates: no filter, then R = 1 … MAX_RADIUS.
    let fixed = vec![(0.0, 0.0); 1 + MAX_RADIUS as usize];
    let mut parts = [Parts { fixed: fixed.clone(), oracle: 0.0 }, Parts { fixed, oracle: 0.0 }];
    for seed in 0..args.reps {
        let (run, _) = accumulate(&mut backend, &prepared.gbuffer, &prepared.data, side, 1, seed)?;
        let ratio = DenoiseInput::new(&prepared.surfaces, &run);
        let stochastic = ratio.stochastic();
        for (input, parts) in [&ratio, &stochastic].into_iter().zip(&mut parts) {
            let images = candidates(&mut backend, input, side, seed)?;
            for (sum, image) in parts.fixed.iter_mut().zip(&images) {
                sum.0 += relmse_part(image, &reference, &regions.shadow);
                sum.1 += relmse_part(image, &reference, &regions.lit);
            }
            parts.oracle += blocks
                .iter()
                .map(|block| images.iter().map(|image| relmse_part(image, &reference, block)).fold(f64::MAX, f64::min))
                .sum::<f64>();
        }
    }
    let mean = |x: f64| x / f64::from(args.reps);
    for (label, parts) in ["ratio", "stochastic"].iter().zip(&parts) {
        println!("{name} {side}² {label}: relMSE shadowed part (unshadowed part)");
        for (k, &(shadow, lit)) in parts.fixed.iter().enumerate() {
            let candidate = if k == 0 { "no filter".to_owned() } else { format!("tv R = {k}") };
            println!("  {candidate:<10} {:.3e} ({:.3e})", mean(shadow), mean(lit));
        }
        println!("  oracle per {0}×{0} tile: shadowed part {1:.3e}", args.tile, mean(parts.oracle));
    }
    let default_radius = DenoiseParams::default_radius(side, side) as usize;
    let (shadow, lit) = parts[1].fixed[default_radius];
    println!(
        "{name} {side}²: oracle ratio+tv shadowed part / stochastic+tv relMSE at R = {default_radius}: {:.2}",
        parts[0].oracle / (shadow + lit)
    );
    Ok(())
}

/// Checks the options as the reports do and loads every scene before measuring any.
fn scenes(args: &Args) -> raywave::Result<Vec<Scene>> {
    if args.tile == 0 {
        return Err(raywave::Error::InvalidParameter { name: "tile", reason: "must be at least 1".into() });
    }
    let report = SceneReportOptions {
        scenes: args.scenes.clone(),
        resolution: args.resolution,
        reference_spp: args.reference_spp,
        max_spp: 1,
        reps: args.reps,
    };
    report.check()?;
    report.load_scenes()
}

fn main() -> ExitCode {
    let args = Args::parse();
    let run = || -> raywave::Result<()> {
        for (name, scene) in args.scenes.iter().zip(scenes(&args)?) {
            measure(&args, name, &scene)?;
        }
        Ok(())
    };
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
