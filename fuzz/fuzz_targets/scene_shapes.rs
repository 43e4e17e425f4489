//! The render checks of `scene_render` ([`raywave_fuzz::render_checked`]) on scenes built from
//! numbers rather than text ([`raywave_fuzz::shapes`]): lights, a receiver and an occluder of
//! any size, anywhere within raywave's coordinate range. Byte 0 chooses the estimator options.
//! `cargo +nightly fuzz run scene_shapes` from the repository root.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    let Some((&choices, shape_bytes)) = bytes.split_first() else { return };
    raywave_fuzz::with_scratch_dir(|dir| {
        let path = raywave_fuzz::shapes::write_shapes(dir, shape_bytes);
        raywave_fuzz::render_checked(dir, &path, choices);
    });
});
