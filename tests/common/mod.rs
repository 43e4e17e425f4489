//! Helpers shared by the integration tests: every Vulkan device opened with validation on, the
//! CI rule for missing devices, and tolerance checks.
#![allow(dead_code)] // each test binary uses a different subset

use raywave::Scene;

pub mod warp_cases;

/// True when running under CI (`CI=true`), where a missing Vulkan device or validation layer is a
/// failure rather than a skip.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true" || v == "1")
}

/// Reports that the GPU part of `test` cannot run: a loud SKIP locally, a failure under CI.
pub fn skip_or_fail(test: &str, reason: &str) {
    assert!(!in_ci(), "{test}: {reason} (CI=true requires a Vulkan device)");
    eprintln!("\n*** SKIP {test}: {reason} ***\n");
}

/// The built-in Cornell box.
pub fn cornell() -> Scene {
    Scene::load("builtin:cornell").expect("built-in scene loads")
}

/// Whether `a` and `b` agree within `rel` relative to `scale` (the magnitude the quantity is
/// measured against, e.g. the length of the vector it belongs to), with `rel · scale` as the
/// absolute floor for values near zero.
pub fn close(a: f32, b: f32, rel: f32, scale: f32) -> bool {
    (a - b).abs() <= rel * scale.max(a.abs()).max(b.abs())
}

/// Documented float tolerance of the generate stage's rays on a device against the CPU,
/// relative: origins (and `tmin`) to the origin's length, directions to 1 and `tmax` to itself.
pub const GENERATE_REL_TOLERANCE: f32 = 2e-6;

/// Fails unless `actual`'s rays are `expected`'s — pixels identical, origins and directions
/// within [`GENERATE_REL_TOLERANCE`] — naming `who` and the ray.
pub fn assert_rays_match(expected: &raywave::RayStream, actual: &raywave::RayStream, who: &str) {
    assert_eq!(actual.len(), expected.len(), "{who}");
    assert_eq!(actual.pixel, expected.pixel, "{who}: pixel indices must be identical");
    for i in 0..actual.len() {
        let (o, e) = (actual.origin[i], expected.origin[i]);
        let (d, f) = (actual.direction[i], expected.direction[i]);
        let o_scale = e.truncate().length();
        for k in 0..4 {
            assert!(close(o[k], e[k], GENERATE_REL_TOLERANCE, o_scale), "{who}: ray {i} origin {o} vs {e}");
            let d_scale = if k < 3 { 1.0 } else { f.w.abs() };
            assert!(close(d[k], f[k], GENERATE_REL_TOLERANCE, d_scale), "{who}: ray {i} direction {d} vs {f}");
        }
    }
}

/// Fails unless at most `fraction` of `total` items are `outliers`, saying `what` they are and
/// showing `examples` of them: how the parity tests bound the few values a device may round
/// differently.
pub fn assert_within_budget(outliers: usize, total: usize, fraction: f64, what: &str, examples: &[String]) {
    let budget = (fraction * total as f64).floor() as usize;
    assert!(outliers <= budget, "{what}: {outliers} of {total} (budget {budget}):\n{}", examples.join("\n"));
}

#[cfg(feature = "vulkan")]
pub mod vulkan {
    use raywave::vulkan::{enumerate_devices, ContextOptions, DeviceInfo, VulkanBackend};
    use raywave::TraceMethod;

    /// Opens every Vulkan device once per trace method it supports (software everywhere, ray
    /// query and the ray-tracing pipeline where exposed), with validation layers on. Without devices this SKIPs loudly (fails
    /// under CI). Validation is required under CI; elsewhere it is used when installed.
    pub fn every_device(test: &str) -> Vec<VulkanBackend> {
        every_device_with(test, &ContextOptions::default())
    }

    /// [`every_device`] with `options` (benchmark mode, a workgroup size; validation is on
    /// whatever `options` say).
    pub fn every_device_with(test: &str, options: &ContextOptions) -> Vec<VulkanBackend> {
        let mut backends = Vec::new();
        let open = |device, trace| open(device, trace, options);
        for device in &devices(test) {
            for method in device.trace_methods() {
                backends.push(open(device, method));
            }
        }
        backends
    }

    /// Opens every Vulkan device once (software trace), with validation layers on, for stages
    /// that do not trace. SKIPs loudly without devices (fails under CI).
    pub fn each_device(test: &str) -> Vec<VulkanBackend> {
        each_device_with(test, &ContextOptions::default())
    }

    /// [`each_device`] with `options` (validation on whatever they say).
    pub fn each_device_with(test: &str, options: &ContextOptions) -> Vec<VulkanBackend> {
        devices(test).iter().map(|device| open(device, TraceMethod::Software, options)).collect()
    }

    /// Every Vulkan device; none (after a loud SKIP, or a failure under CI) if there are none.
    fn devices(test: &str) -> Vec<DeviceInfo> {
        match enumerate_devices() {
            Ok(d) if !d.is_empty() => d,
            Ok(_) => {
                super::skip_or_fail(test, "no Vulkan device");
                vec![]
            }
            Err(e) => {
                super::skip_or_fail(test, &format!("{e}"));
                vec![]
            }
        }
    }

    fn open(info: &DeviceInfo, trace: TraceMethod, options: &ContextOptions) -> VulkanBackend {
        let options = ContextOptions { validation: true, ..options.clone() };
        match VulkanBackend::open(info.index, &options, Some(trace)) {
            Ok(b) => b,
            Err(e) if !super::in_ci() && e.to_string().contains("VK_LAYER_KHRONOS_validation") => {
                eprintln!("*** validation layer missing: testing {} without it ***", info.name);
                let options = ContextOptions { validation: false, ..options };
                VulkanBackend::open(info.index, &options, Some(trace)).expect("device opens")
            }
            Err(e) => panic!("cannot open {} with {}: {e}", info.name, trace.name()),
        }
    }

    /// Fails if `backend`'s validation layers reported any warning or error so far: the check
    /// within a test that goes on using the backend ([`assert_clean`] ends it).
    pub fn assert_no_messages_yet(backend: &VulkanBackend) {
        let messages = backend.validation_messages();
        let name = &backend.info().name;
        assert!(messages.is_empty(), "{} validation messages on {name}:\n{}", messages.len(), messages.join("\n"));
    }

    /// Drops `backend` and fails if its validation layers reported any warning or error, its
    /// teardown's included (objects still alive when the device is destroyed, say), which arrive
    /// only as it drops.
    pub fn assert_clean(backend: VulkanBackend) {
        let log = raywave::Backend::validation_log(&backend).expect("a Vulkan backend has a validation log");
        let name = backend.info().name.clone();
        drop(backend);
        let messages = log.messages();
        assert!(messages.is_empty(), "{} validation messages on {name}:\n{}", messages.len(), messages.join("\n"));
    }
}
