//! Whatever scene loads renders on the CPU (12×8 pixels) without a panic, without any stage
//! replacing a non-finite value (sound input sanitizes nothing), and to a finite HDR image — or
//! ends in the typed error of a scene the render may refuse (one that does not load, whose BVH is
//! too deep, or whose lights fail their checks). Byte 0 chooses the estimator options
//! ([`raywave_fuzz::render_checked`]), the rest is `scene_load`'s input.
//! `cargo +nightly fuzz run scene_render` from the repository root.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let Some((&choices, scene_bytes)) = bytes.split_first() else { return };
    raywave_fuzz::with_scratch_dir(|dir| {
        let Some(path) = raywave_fuzz::write_scene(dir, scene_bytes) else { return };
        raywave_fuzz::render_checked(dir, &path, choices);
    });
});
