//! Any bytes as an OBJ (with its material library), glTF (with its buffer) or GLB file: loading
//! ends in a scene or a typed error, never a panic, a hang or an abort; whatever loads also has
//! its BVH built, or refused as too deep (`Error::SceneTooLarge`). `cargo +nightly fuzz run
//! scene_load` from the repository root.
#![no_main]

use libfuzzer_sys::fuzz_target;
use raywave::cpu::CpuBackend;
use raywave::{Backend, Error, Scene};

fuzz_target!(|bytes: &[u8]| {
    raywave_fuzz::with_scratch_dir(|dir| {
        let Some(path) = raywave_fuzz::write_scene(dir, bytes) else { return };
        if let Ok(scene) = Scene::load(path.to_str().expect("a UTF-8 temporary path")) {
            match CpuBackend::new().load_scene(&scene) {
                Ok(()) | Err(Error::SceneTooLarge { .. }) => {}
                Err(err) => panic!("a scene that loads failed to build its BVH: {err}"),
            }
        }
    });
});
