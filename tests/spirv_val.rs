//! Every SPIR-V module the build embeds, as embedded and as the Vulkan backend loads it (every
//! float operation decorated `NoContraction`), passes `spirv-val --target-env vulkan1.2`, and
//! declares ray-query capability only if it is the ray-query trace kernel.
#![cfg(feature = "vulkan")]

mod common;

use raywave::vulkan::spirv::{words, MODULES};
use std::process::Command;

#[test]
fn every_module_passes_spirv_val() {
    assert!(MODULES.len() >= 2, "expected the generate and trace modules, got {}", MODULES.len());
    if Command::new("spirv-val").arg("--version").output().is_err() {
        common::skip_or_fail("spirv-val", "spirv-val (Debian package spirv-tools) is not installed");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for (entry, bytes) in MODULES {
        let loaded: Vec<u8> = words(entry, None).unwrap().iter().flat_map(|w| w.to_le_bytes()).collect();
        for (form, bytes) in [("embedded", *bytes), ("loaded", &loaded[..])] {
            let path = dir.path().join(format!("{}-{form}.spv", entry.replace("::", "-")));
            std::fs::write(&path, bytes).unwrap();
            let out = Command::new("spirv-val").args(["--target-env", "vulkan1.2"]).arg(&path).output().unwrap();
            let errors = String::from_utf8_lossy(&out.stderr);
            assert!(out.status.success(), "{entry}, {form}, fails spirv-val:\n{errors}");
        }
    }
}

#[test]
fn only_ray_query_kernels_declare_ray_query() {
    // OpCapability RayQueryKHR is instruction word (2 << 16 | 17) followed by capability 4472.
    let ray_query_capability = [(2u32 << 16) | 17, 4472];
    let mut ray_query_modules = 0;
    for (entry, bytes) in MODULES {
        let words: Vec<u32> = bytes.chunks_exact(4).map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]])).collect();
        let declares = words.windows(2).any(|w| w == ray_query_capability);
        assert_eq!(declares, entry.contains("ray_query"), "{entry}: RayQueryKHR declared = {declares}");
        ray_query_modules += usize::from(declares);
    }
    // Else the check above holds vacuously: the build embeds the ray-query trace kernels.
    assert!(ray_query_modules > 0, "no embedded module declares RayQueryKHR");
}
