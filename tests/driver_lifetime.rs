//! Closing the last Vulkan backend must leave the drivers' libraries loaded: NVIDIA's driver can
//! still run a thread of its own in its library when the loader would unload it, which crashed
//! `trace_robustness` on an H100 (a segmentation fault at an unmapped instruction address, in 2
//! of 5 runs). The backend keeps them loaded with an instance it never destroys; this test checks
//! that on whichever device the machine has (lavapipe in CI), through the process's own memory
//! map. It is alone in its binary so that no other test's backend holds the drivers meanwhile.
//! (On lavapipe, before, the loader and Mesa's other Vulkan drivers were unmapped.)
#![cfg(all(feature = "vulkan", target_os = "linux"))]

mod common;

use common::vulkan;
use std::collections::BTreeSet;

/// The shared libraries mapped into this process, by path.
fn mapped_libraries() -> BTreeSet<String> {
    let maps = std::fs::read_to_string("/proc/self/maps").expect("/proc/self/maps is readable");
    maps.lines()
        .filter_map(|line| line.split_whitespace().nth(5))
        .filter(|path| path.ends_with(".so") || path.contains(".so."))
        .map(str::to_owned)
        .collect()
}

#[test]
fn drivers_stay_loaded_after_the_last_backend_closes() {
    let before = mapped_libraries();
    let backends = vulkan::every_device("driver lifetime");
    if backends.is_empty() {
        return; // SKIPped loudly (a failure under CI) by `every_device`
    }
    for backend in &backends {
        vulkan::assert_no_messages_yet(backend);
    }
    // What opening the backends brought in of the loader and the drivers (`libvulkan_lvp.so`,
    // NVIDIA's `libnvidia-*.so`, …), by name: libraries that only their dependencies or the
    // validation layer load may come and go.
    let opened: Vec<String> = mapped_libraries()
        .difference(&before)
        .filter(|library| {
            let name = library.rsplit('/').next().unwrap_or(library).to_lowercase();
            name.contains("vulkan") || name.contains("nvidia")
        })
        .cloned()
        .collect();
    assert!(
        opened.iter().any(|library| library.contains("libvulkan.so")),
        "opening a backend mapped no Vulkan loader: {opened:?}"
    );
    backends.into_iter().for_each(vulkan::assert_clean);
    let after = mapped_libraries();
    let unloaded: Vec<&String> = opened.iter().filter(|library| !after.contains(*library)).collect();
    assert!(unloaded.is_empty(), "unloaded when the last backend closed: {unloaded:?}");
}
