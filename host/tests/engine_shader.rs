//! An engine links the kernels into its own rust-gpu shader crate: building the fixture
//! `host/tests/data/engine-shader` (one compute entry point that calls `raywave_kernels::trig::sin_cos`)
//! must give a module with the engine's entry point alone. rust-gpu emits every `#[spirv(...)]`
//! entry point of every crate it links, so before the kernels' `entry` module went behind the
//! `entry-points` feature an engine's module carried raywave's 15 compute kernels as well. The
//! same build with the feature on is the control: it finds them.
#![cfg(feature = "vulkan")]

use cargo_gpu_install::install::Install;
use cargo_gpu_install::spirv_builder::{Capability, ModuleResult};
use std::path::{Path, PathBuf};

/// The fixture's entry points and its module, built with `features` (of the fixture crate) on.
fn build(features: &[&str]) -> (Vec<String>, Vec<u8>) {
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
    let built = builder.build().expect("the fixture builds to SPIR-V");
    let ModuleResult::SingleModule(path) = &built.module else { panic!("one module: {:?}", built.module) };
    let mut entries = built.entry_points.clone();
    entries.sort();
    (entries, std::fs::read(path).expect("the module"))
}

#[test]
fn an_engine_shader_gets_only_its_own_entry_points() {
    let (entries, module) = build(&[]);
    assert_eq!(entries, ["engine_main"]);
    // The engine passes its module through `without_contraction` (README, Linking the kernels
    // into your engine): the kernels' arithmetic it calls is then marked as in raywave's own.
    let code: Vec<u32> = module.chunks_exact(4).map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]])).collect();
    let decorated = raywave_host::vulkan::spirv::without_contraction(&code).expect("a module");
    // `OpDecorate %id NoContraction`: three words, opcode 71, decoration 42.
    let marks_in = |words: &[u32]| words.windows(3).filter(|w| w[0] == (3 << 16 | 71) && w[2] == 42).count();
    assert_eq!(marks_in(&code), 0, "rust-gpu marks none");
    let marks = marks_in(&decorated);
    assert!(marks >= 20, "{marks} operations marked in the engine's sin_cos");
    assert_eq!(decorated.len(), code.len() + 3 * marks, "only the decorations added");
    let (with_raywave_entries, _) = build(&["raywave-kernels/entry-points"]);
    for raywave_entry in ["entry::generate", "entry::shade", "entry::trace_cwbvh"] {
        assert!(with_raywave_entries.iter().any(|e| e == raywave_entry), "control: {with_raywave_entries:?}");
    }
}
