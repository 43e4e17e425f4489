//! Whatever scene loads renders on the CPU (12×8 pixels) without a panic, without any stage
//! replacing a non-finite value (sound input sanitizes nothing), and to a finite HDR image — or
//! ends in the typed error of a scene the render may refuse (one that does not load, whose BVH is
//! too deep, or whose lights fail their checks): [`raywave_fuzz::render_input`].
//! `cargo +nightly fuzz run scene_render` from the repository root.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    raywave_fuzz::render_input(bytes);
});
