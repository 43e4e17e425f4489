//! An engine links the kernels into its own rust-gpu shader crate: building the fixture
//! `host/tests/data/engine-shader` (one compute entry point that calls `raywave_kernels::trig::sin_cos`)
//! must give a module with the engine's entry point alone. rust-gpu emits every `#[spirv(...)]`
//! entry point of every crate it links, so before the kernels' `entry` module went behind the
//! `entry-points` feature an engine's module carried raywave's 15 compute kernels as well. The
//! same build with the feature on is the control: it finds them.
#![cfg(feature = "vulkan")]

use cargo_gpu_install::install::Install;
use cargo_gpu_install::spirv_builder::Capability;
use std::path::{Path, PathBuf};

/// The fixture's entry points, built with `features` (of the fixture crate) on.
fn entry_points(features: &[&str]) -> Vec<String> {
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/engine-shader");
    let backend = Install::from_shader_crate(fixture.clone()).run().expect("rust-gpu backend");
    let mut builder = backend.to_spirv_builder(&fixture, "spirv-unknown-vulkan1.2");
    builder.release = true;
    builder.shader_crate_features.features = features.iter().map(|f| f.to_string()).collect();
    // raywave's entry points declare `SignedZeroInfNanPreserve` (README, Linking the kernels into
    // your engine), which a build that emits them must enable.
    builder.capabilities.push(Capability::SignedZeroInfNanPreserve);
    // Inside the target dir, so repeated runs (and CI's cached target dir) build incrementally.
    builder.target_dir_path = Some(PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("engine-shader"));
    let mut entries = builder.build().expect("the fixture builds to SPIR-V").entry_points;
    entries.sort();
    entries
}

#[test]
fn an_engine_shader_gets_only_its_own_entry_points() {
    assert_eq!(entry_points(&[]), ["engine_main"]);
    let with_raywave_entries = entry_points(&["raywave-kernels/entry-points"]);
    for raywave_entry in ["entry::generate", "entry::shade", "entry::trace_cwbvh"] {
        assert!(with_raywave_entries.iter().any(|e| e == raywave_entry), "control: {with_raywave_entries:?}");
    }
}
