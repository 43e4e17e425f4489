//! Whatever scene loads renders on the CPU (12×8 pixels) without a panic, without any stage
//! replacing a non-finite value (sound input sanitizes nothing), and to a finite HDR image — or
//! ends in a typed error (a scene that does not load, or one without a light). Byte 0 chooses the
//! estimator options, the rest is `scene_load`'s input. `cargo +nightly fuzz run scene_render`
//! from the repository root.
#![no_main]

use libfuzzer_sys::fuzz_target;
use raywave::denoise::DenoiseMethod;
use raywave::render::{render, RenderOptions, RenderView};
use raywave::{BackendOptions, DeviceChoice, StageReport};

fuzz_target!(|bytes: &[u8]| {
    let Some((&choices, scene_bytes)) = bytes.split_first() else { return };
    raywave_fuzz::with_scratch_dir(|dir| {
        let Some(path) = raywave_fuzz::write_scene(dir, scene_bytes) else { return };
        let scene = path.to_str().expect("a UTF-8 temporary path").to_owned();
        let denoise = [DenoiseMethod::Tv, DenoiseMethod::Svgf, DenoiseMethod::None][(choices as usize >> 1) % 3];
        let options = RenderOptions {
            scene,
            device: DeviceChoice::Cpu,
            width: 12,
            height: 8,
            spp: 1 << ((choices >> 3) % 3),
            seed: 1,
            sampler: 0,
            lens_radius: 0.0,
            focus_distance: None,
            view: RenderView::Lit,
            out: dir.join("out.png"),
            exr: Some(dir.join("out.exr")),
            stochastic: Some(dir.join("stochastic.png")),
            denoise,
            denoise_radius: None,
            analytic_residual: choices & 1 == 1,
            backend: BackendOptions::default(),
            settle_seconds: None,
        };
        // `render` loads the scene first: what does not load is refused there, as by `Scene::load`.
        match render(&options) {
            Ok(report) => {
                assert_eq!(StageReport::total_sanitized(&report.timings), 0, "{:?}", report.timings);
                let hdr = image::open(dir.join("out.exr")).expect("the EXR reads back").into_rgba32f();
                assert!(hdr.pixels().all(|p| p.0.iter().all(|v| v.is_finite())), "a non-finite pixel");
            }
            Err(err) => assert!(!err.to_string().is_empty()),
        }
    });
});
