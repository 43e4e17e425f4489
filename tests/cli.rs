//! The `raywave` command line end to end: device listing, rendering on each backend with images
//! that agree, and bad input rejected with a message and no output file.

mod common;

use std::path::Path;
use std::process::{Command, Output};

fn raywave(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_raywave")).args(args).output().expect("raywave runs")
}

/// The JSON object on each line of a command's standard output.
fn json_lines(out: &Output) -> Vec<serde_json::Value> {
    String::from_utf8_lossy(&out.stdout).lines().map(|l| serde_json::from_str(l).expect("a JSON line")).collect()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Runs the command `args` and checks that it fails with a message saying `expected` (no panic)
/// before printing any result.
fn assert_refused_before_measuring(args: &[&str], expected: &str) {
    let refused = raywave(args);
    let message = stderr(&refused);
    assert!(!refused.status.success() && refused.stdout.is_empty(), "{args:?} should fail at once: {message}");
    assert!(
        message.contains(expected) && !message.contains("panicked"),
        "{args:?}: expected {expected:?} in {message:?}"
    );
}

fn render(dir: &Path, name: &str, extra: &[&str]) -> (Output, std::path::PathBuf) {
    let path = dir.join(name);
    let mut args = vec!["render", "--out", path.to_str().unwrap()];
    if !extra.contains(&"--width") {
        args.extend(["--width", "96", "--height", "64"]);
    }
    args.extend_from_slice(extra);
    (raywave(&args), path)
}

/// CI runs the README's test command as the README gives it (`.ci/run`, its tests step): the
/// newcomer's command and CI's had agreed by convention only.
#[test]
fn ci_runs_the_readme_test_command() {
    let root = env!("CARGO_MANIFEST_DIR");
    let readme = std::fs::read_to_string(format!("{root}/README.md")).unwrap();
    let ci = std::fs::read_to_string(format!("{root}/.ci/run")).unwrap();
    let mut lines = readme.lines().skip_while(|l| !l.starts_with("# Run the tests"));
    let command = lines.nth(1).expect("the README's test command, after its comment line");
    assert!(command.starts_with("cargo test"), "{command:?}");
    let step = ci.lines().find(|l| l.contains("cargo test --workspace")).expect("the tests step");
    assert!(step.contains(&format!(" {command} 2>&1 | tee")), "README: {command:?}; .ci/run: {step:?}");
}

/// `render --help` names every built-in scene, so the help stays true when one is added.
#[test]
fn render_help_names_every_builtin_scene() {
    let out = raywave(&["render", "--help"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let help = String::from_utf8_lossy(&out.stdout);
    let scene_help = help.split("--scene").nth(1).and_then(|s| s.split("--device").next()).unwrap_or_default();
    for name in raywave::scene::BUILTIN_SCENES {
        let listed = scene_help.split(|c: char| !(c.is_alphanumeric() || c == '-')).any(|word| word == *name);
        assert!(listed, "`render --help` does not name builtin:{name}: {scene_help}");
    }
}

#[test]
fn devices_lists_the_cpu_and_json_is_valid() {
    let out = raywave(&["devices", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let value: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(value["cpu"]["backend"], "cpu");
    let text = raywave(&["devices"]);
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(text.contains("cpu"));
    // Each Vulkan device lists the workgroup sizes it runs the stream stages in: ascending powers
    // of two, the compiled 64 among them, as a range in the table.
    for device in value["vulkan"].as_array().into_iter().flatten() {
        let sizes: Vec<u64> =
            device["workgroup_sizes"].as_array().unwrap().iter().map(|s| s.as_u64().unwrap()).collect();
        assert!(sizes.contains(&64) && sizes.iter().all(|s| s.is_power_of_two()), "{device}");
        assert!(sizes.windows(2).all(|w| w[0] < w[1]), "{device}");
        let range = format!("workgroup_sizes={}..={}", sizes[0], sizes[sizes.len() - 1]);
        assert!(text.contains(&range), "{range} in {text}");
        // What a backend opened without sizes runs there, stage by stage.
        let sizes: Vec<u32> = sizes.iter().map(|&s| s as u32).collect();
        let preferred = raywave::WorkgroupSizes::preferred_on(&sizes);
        let expected = serde_json::json!({
            "generate": preferred.generate, "trace": preferred.trace, "shade": preferred.shade, "denoise": preferred.denoise,
        });
        assert_eq!(device["preferred_workgroup_sizes"], expected, "{device}");
        if sizes.contains(&256) {
            assert_eq!(device["preferred_workgroup_sizes"]["shade"], 256, "{device}");
        }
    }
}

#[cfg(feature = "vulkan")]
#[test]
fn devices_lists_a_vulkan_device_with_ray_query_and_under_ci_the_ray_tracing_pipeline() {
    let out = raywave(&["devices", "--json"]);
    let value: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let devices = value["vulkan"].as_array().cloned().unwrap_or_default();
    if devices.is_empty() {
        common::skip_or_fail("devices", &format!("no Vulkan device listed: {}", value["vulkan_error"]));
        return;
    }
    assert!(devices.iter().any(|d| d["ray_query"] == true && d["can_trace"] == true), "{value}");
    assert!(devices.iter().any(|d| d["runs_kernels"] == true && d["lacks"] == serde_json::json!([])), "{value}");
    // CI's lavapipe has the ray-tracing pipeline too: without it every rtpipe parity and
    // robustness case would drop out of CI unseen (the tests run each method a device has).
    if common::in_ci() {
        assert!(devices.iter().any(|d| d["ray_tracing_pipeline"] == true), "{value}");
    }
}

#[test]
fn cpu_render_writes_a_png_and_reports_stages() {
    let dir = tempfile::tempdir().unwrap();
    let (out, path) = render(dir.path(), "cpu.png", &["--device", "cpu"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    for stage in ["generate", "trace", "shade", "occlusion"] {
        assert!(stdout.contains(stage), "{stage} missing: {stdout}");
    }
    // Nothing went non-finite: no stage line counts sanitized values, no warning.
    assert!(!stdout.contains("sanitized") && !stderr(&out).contains("non-finite"), "{stdout}\n{}", stderr(&out));
    let image = image::open(&path).unwrap().to_rgb8();
    assert_eq!(image.dimensions(), (96, 64));
    // The lit box: the floor, the back and side walls (the ceiling faces away from the light and
    // the sides of the wide frame miss the box).
    assert!(image.pixels().filter(|p| p.0 != [0, 0, 0]).count() > 96 * 64 / 3, "the lit walls fill the frame");
    // The red wall is on the left, the green one on the right.
    let (left, right) = (image.get_pixel(22, 32).0, image.get_pixel(73, 32).0);
    assert!(left[0] > left[1] && right[1] > right[0], "left {left:?} right {right:?}");
}

#[cfg(feature = "vulkan")]
#[test]
fn vulkan_and_cpu_renders_agree() {
    let dir = tempfile::tempdir().unwrap();
    let (cpu, cpu_path) = render(dir.path(), "cpu.png", &["--device", "cpu"]);
    assert!(cpu.status.success(), "{}", stderr(&cpu));
    let (vk, vk_path) = render(dir.path(), "vk.png", &["--device", "vulkan", "--validate"]);
    if !vk.status.success() && !common::in_ci() && stderr(&vk).contains("Vulkan is unavailable") {
        common::skip_or_fail("vulkan render", &stderr(&vk));
        return;
    }
    assert!(vk.status.success(), "{}", stderr(&vk));
    assert!(!stderr(&vk).contains("[vulkan"), "validation messages: {}", stderr(&vk));
    assert!(!stderr(&vk).contains("non-finite"), "sanitized values: {}", stderr(&vk));
    let stdout = String::from_utf8_lossy(&vk.stdout);
    assert!(stdout.contains("timing   one frame"), "{stdout}");
    // Steady-state times (warm-up frames in benchmark mode) change the times, not the image.
    let steady_args = ["--device", "vulkan", "--settle-seconds", "0.05", "--validate"];
    let (steady, steady_path) = render(dir.path(), "steady.png", &steady_args);
    assert!(steady.status.success(), "{}", stderr(&steady));
    assert!(!stderr(&steady).contains("[vulkan"), "validation messages: {}", stderr(&steady));
    let stdout = String::from_utf8_lossy(&steady.stdout);
    assert!(stdout.contains("timing   steady state: the frame after"), "{stdout}");
    // In benchmark mode: each stage's time the mean of dispatches repeated back to back, more
    // than the one a sample of the 4 spp that one frame times.
    let shade = stdout.lines().find(|l| l.starts_with("stage    shade")).unwrap_or_default();
    let dispatches: u32 = shade.split("  (").nth(1).and_then(|s| s.split(' ').next()?.parse().ok()).unwrap_or(0);
    assert!(dispatches > 4, "{stdout}");
    assert_eq!(std::fs::read(&steady_path).unwrap(), std::fs::read(&vk_path).unwrap(), "the steady-state image");
    let a = image::open(cpu_path).unwrap().to_rgb8();
    let b = image::open(vk_path).unwrap().to_rgb8();
    // The parity tolerance (≥ 99.99 % same primitive, t within 1e-5) allows a pixel in 10 000 to
    // differ; at 6 144 pixels that is none, and shading differences stay within one 8-bit step.
    let differing =
        a.pixels().zip(b.pixels()).filter(|(p, q)| p.0.iter().zip(q.0).any(|(x, y)| x.abs_diff(y) > 1)).count();
    assert_eq!(differing, 0, "{differing} pixels differ by more than one step");
}

#[test]
fn renders_a_gltf_scene_and_reports_dropped_triangles() {
    let dir = tempfile::tempdir().unwrap();
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/tetrahedron.gltf");
    let (out, path) = render(dir.path(), "tetra.png", &["--device", "cpu", "--scene", scene, "--view", "normals"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("(4 triangles, 1 zero-area dropped, 0 quad lights)"), "{stdout}");
    let image = image::open(&path).unwrap().to_rgb8();
    assert!(image.pixels().any(|p| p.0 != [0, 0, 0]), "the tetrahedron is in view of the file's camera");
}

/// A render states its peak memory, and the lit frame's footprint per pixel that it is held to
/// before it starts covers what one more pixel costs: between 1024² and 1536² (with every output;
/// lavapipe's peak varies by ±10 MB from run to run, ±8 bytes per pixel here; at most 1.4 GB, beside
/// the other tests) the peak grows by at most that, and by more than 80 % of it — on the CPU
/// ([`raywave::cpu::LIT_FRAME_BYTES_PER_PIXEL`]) and on each Vulkan device in host memory
/// (lavapipe, [`raywave::vulkan::SOFTWARE_DEVICE_LIT_FRAME_BYTES_PER_PIXEL`]), both measured on a
/// release build.
///
/// Mesa's shader cache is off for these renders (`MESA_SHADER_CACHE_DISABLE`), so lavapipe
/// compiles the kernels in both and both peaks hold the compiler's memory (~105 MB on CI's
/// machine): with the cache on, a 1536² run that compiled after a 1024² run had read the cache
/// measured 637 bytes a pixel in CI, where the frame takes 554 (the same two runs with the cache
/// off: 844 and 1570 MB).
#[cfg(target_os = "linux")]
#[test]
fn a_render_states_its_peak_memory_and_its_footprint_covers_it() {
    let dir = tempfile::tempdir().unwrap();
    let peak = |device: &str, side: u32| {
        let side = side.to_string();
        let (png, exr, stochastic) = (dir.path().join("m.png"), dir.path().join("m.exr"), dir.path().join("s.png"));
        let outputs = ["--exr", exr.to_str().unwrap(), "--stochastic", stochastic.to_str().unwrap()];
        let size = ["--device", device, "--spp", "1", "--width", &side, "--height", &side];
        let out = Command::new(env!("CARGO_BIN_EXE_raywave"))
            .env("MESA_SHADER_CACHE_DISABLE", "true")
            .args(["render", "--out", png.to_str().unwrap()])
            .args(size)
            .args(outputs)
            .output()
            .expect("raywave runs");
        assert!(out.status.success(), "{}", stderr(&out));
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        let line = stdout.lines().find_map(|l| l.strip_prefix("memory   peak ")).unwrap_or_else(|| panic!("{stdout}"));
        line.strip_suffix(" MB resident").unwrap().parse::<f64>().unwrap() * 1e6
    };
    #[cfg(feature = "vulkan")]
    let software: Vec<(String, u64)> = {
        let devices = vulkan_devices("peak memory on a Vulkan device in host memory").unwrap_or_default();
        let footprint = raywave::vulkan::SOFTWARE_DEVICE_LIT_FRAME_BYTES_PER_PIXEL;
        let software: Vec<_> = devices
            .iter()
            .filter(|d| d.device_type == "CPU")
            .map(|d| (format!("vulkan:{}", d.index), footprint))
            .collect();
        assert!(!software.is_empty() || !common::in_ci(), "CI's Vulkan device is lavapipe");
        software
    };
    #[cfg(not(feature = "vulkan"))]
    let software: Vec<(String, u64)> = Vec::new();
    for (device, footprint) in
        std::iter::once(("cpu".to_owned(), raywave::cpu::LIT_FRAME_BYTES_PER_PIXEL)).chain(software)
    {
        let per_pixel = (peak(&device, 1536) - peak(&device, 1024)) / f64::from(1536 * 1536 - 1024 * 1024);
        let footprint = footprint as f64;
        assert!(
            per_pixel <= footprint && per_pixel > 0.8 * footprint,
            "{device}: {per_pixel:.1} bytes per pixel against {footprint}"
        );
    }
}

/// Runs a render expected to fail; checks the message mentions `needle` and no file appeared.
fn assert_rejected(extra: &[&str], needle: &str) {
    let dir = tempfile::tempdir().unwrap();
    let (out, path) = render(dir.path(), "out.png", extra);
    assert!(!out.status.success(), "{extra:?} should fail");
    let message = stderr(&out);
    assert!(message.contains(needle), "{extra:?}: expected {needle:?} in {message:?}");
    assert!(!message.contains("panicked"), "{message}");
    assert!(!path.exists(), "{extra:?} left an output file");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "{extra:?} left a temporary file");
}

#[test]
fn bad_input_is_a_typed_error_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let nan = dir.path().join("nan.obj");
    std::fs::write(&nan, "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n").unwrap();
    let flat = dir.path().join("flat.obj");
    std::fs::write(&flat, "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n").unwrap();
    let empty = dir.path().join("empty.obj");
    std::fs::write(&empty, "# no geometry\n").unwrap();

    assert_rejected(&["--device", "cpu", "--scene", nan.to_str().unwrap()], "line 3: `v 0 nan 0` has coordinate NaN");
    assert_rejected(&["--device", "cpu", "--scene", flat.to_str().unwrap()], "zero-area triangles dropped");
    assert_rejected(&["--device", "cpu", "--scene", empty.to_str().unwrap()], "no triangles");
    assert_rejected(&["--device", "cpu", "--scene", "/no/such/scene.obj"], "/no/such/scene.obj");
    assert_rejected(&["--device", "cpu", "--scene", "builtin:teapot"], "teapot");
    assert_rejected(&["--device", "cpu", "--width", "0"], "at least 1");
    assert_rejected(
        &["--device", "cpu", "--validate"],
        "invalid parameter validate: the CPU backend has no validation",
    );
    // The CPU's own pixel limit (2²⁶), at a sample count the sampler's index holds.
    assert_rejected(&["--device", "cpu", "--width", "65536", "--height", "2048", "--spp", "1"], "exceed the limit");
    // Naming the devices there are: "there is one Vulkan device, vulkan:0", or "… to vulkan:N".
    #[cfg(feature = "vulkan")]
    assert_rejected(&["--device", "vulkan:99"], "\"vulkan:99\": there");
    assert_rejected(&["--device", "gpu"], "expected auto, cpu, vulkan");
    assert_rejected(&["--device", "cpu", "--sampler", "halton"], "unknown sampler `halton`");
    assert_rejected(&["--device", "cpu", "--spp", "0"], "spp: 0 is outside 1..=65536");
    assert_rejected(&["--device", "cpu", "--spp", "70000"], "spp: 70000 is outside 1..=65536");
    // Before the scene loads (this one would fail to) and the device opens (nor would it).
    assert_rejected(&["--device", "vulkan:99", "--scene", "/no/such/scene.obj", "--spp", "0"], "spp: 0 is outside");
    // So are the options an explicit CPU choice cannot run, which need no backend.
    let on_cpu_nowhere = ["--device", "cpu", "--scene", "/no/such/scene.obj"];
    assert_rejected(&[&on_cpu_nowhere[..], &["--validate"]].concat(), "validate: the CPU backend has no validation");
    assert_rejected(
        &[&on_cpu_nowhere[..], &["--trace", "rtpipe"]].concat(),
        "trace: the CPU backend traces in software",
    );
    // So are the image size and the samples for it, which need no backend.
    let nowhere = ["--device", "vulkan:99", "--scene", "/no/such/scene.obj"];
    assert_rejected(&[&nowhere[..], &["--width", "0"]].concat(), "at least 1");
    assert_rejected(&[&nowhere[..], &["--width", "65536", "--height", "1024", "--spp", "4"]].concat(), "32-bit index");
    let sampler_overflow = ["--device", "cpu", "--width", "65536", "--height", "1024", "--spp", "4"];
    assert_rejected(&sampler_overflow, "exceed the sampler's 32-bit index");
    // A side over 65536 is refused for every backend, whatever the sampler: the size is named.
    for sampler in ["zsobol", "sobol"] {
        let too_wide = ["--device", "cpu", "--sampler", sampler, "--width", "70000", "--height", "1", "--spp", "1"];
        assert_rejected(&too_wide, "image size 70000×1 is invalid on every backend");
        assert_rejected(&too_wide, "a side of 70000 pixels exceeds 65536");
    }
    assert_rejected(&["--device", "cpu", "--view", "albedo"], "unknown view `albedo`");
    assert_rejected(&["--device", "cpu", "--exr", "/no/such/dir/out.exr"], "/no/such/dir/out.exr");
    assert_rejected(&["--device", "cpu", "--aperture=-1"], "aperture");
    let (jpg, hdr_png) = (dir.path().join("stochastic.jpg"), dir.path().join("hdr.png"));
    assert_rejected(&["--device", "cpu", "--stochastic", jpg.to_str().unwrap()], "must end in .png");
    assert_rejected(&["--device", "cpu", "--exr", hdr_png.to_str().unwrap()], "must end in .exr");
    assert!(!jpg.exists() && !hdr_png.exists());
    assert_rejected(&["--device", "cpu", "--aperture", "0.1", "--focus", "0"], "focus");
    // Beyond ±10⁸ the powers of lengths the kernels form may overflow (MAX_COORDINATE).
    let far = dir.path().join("far.obj");
    std::fs::write(&far, "v 0 0 0\nv 1e19 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    assert_rejected(
        &["--device", "cpu", "--scene", far.to_str().unwrap()],
        "line 2: `v 1e19 0 0` has coordinate 10000000000000000000; each must be finite and within ±1e8",
    );
    assert_rejected(&["--device", "cpu", "--aperture", "1e20"], "aperture: 100000000000000000000 is outside");
    // Within 10⁸, but over 10³ focus distances (the Cornell camera's 0.8, or the one given), in
    // either view: its rays had missed the plane in focus by scene-sized amounts.
    for view in ["lit", "normals"] {
        let wide = ["--device", "cpu", "--view", view, "--aperture", "1e6"];
        assert_rejected(&wide, "aperture: 1000000 exceeds 1e3 × the focus distance 0.8");
        assert_rejected(&[&wide[..], &["--focus", "2"]].concat(), "the focus distance 2:");
    }
    assert_rejected(&["--device", "cpu", "--settle-seconds", "31"], "settle-seconds: 31 is not within 0..=30 s");
    assert_rejected(&["--device", "cpu", "--settle-seconds", "NaN"], "settle-seconds: NaN is not within");
    assert_rejected(&["--device", "cpu", "--aperture", "0.1", "--focus", "1e19"], "focus");
    let normals_exr = dir.path().join("normals.exr");
    assert_rejected(&["--device", "cpu", "--view", "normals", "--exr", normals_exr.to_str().unwrap()], "normals view");
    // Options the normals view would ignore.
    for (option, needle) in [
        (&["--denoise", "svgf"][..], "denoise: the normals view"),
        (&["--denoise-radius", "3"], "denoise-radius: the normals view"),
        (&["--analytic-residual"], "analytic-residual: the normals view"),
    ] {
        assert_rejected(&[&["--device", "cpu", "--view", "normals"][..], option].concat(), needle);
    }
    assert!(!normals_exr.exists());
    // Options that another option's value would make the render ignore.
    assert_rejected(&["--device", "cpu", "--focus", "2"], "focus: a pinhole camera (no --aperture)");
    assert_rejected(
        &["--device", "cpu", "--denoise", "none", "--denoise-radius", "3"],
        "denoise-radius: --denoise none",
    );
    // The TV filter is the identity from spp = 4R² on (R = 2: 16); one below it filters.
    assert_rejected(
        &["--device", "cpu", "--spp", "16", "--denoise-radius", "2"],
        "denoise-radius: the TV filter at --spp 16 ≥ 4R² = 16 leaves every pixel as it is",
    );

    let out = raywave(&["render", "--device", "cpu", "--out", "/no/such/dir/out.png"]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("cannot write output /no/such/dir/out.png"), "{}", stderr(&out));

    // One file named by two outputs: the stochastic image silently replaced the main one.
    let twice = dir.path().join("twice.png");
    let (out, _) = render(dir.path(), "twice.png", &["--device", "cpu", "--stochastic", twice.to_str().unwrap()]);
    assert!(!out.status.success() && stderr(&out).contains("is also --out's file"), "{}", stderr(&out));
    assert!(!twice.exists());
    // The same file spelt through `..` or a symbolic link to its folder: compared as given, these
    // passed, and the stochastic image replaced the main one without a word.
    std::fs::create_dir(dir.path().join("sub")).unwrap();
    let mut spellings = vec![dir.path().join("sub/../twice.png")];
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(dir.path(), dir.path().join("link")).unwrap();
        spellings.push(dir.path().join("link/twice.png"));
    }
    for other in spellings {
        let (out, _) = render(dir.path(), "twice.png", &["--device", "cpu", "--stochastic", other.to_str().unwrap()]);
        assert!(!out.status.success() && stderr(&out).contains("is also --out's file"), "{other:?}: {}", stderr(&out));
        assert!(!twice.exists());
    }
    // A trailing separator or `.` names a directory: the rename failed only after the render.
    for tail in ["/", "/."] {
        let slash = format!("{}{tail}", dir.path().join("slash.png").display());
        let out = raywave(&["render", "--device", "cpu", "--out", &slash]);
        assert!(!out.status.success() && stderr(&out).contains("names a directory"), "{tail}: {}", stderr(&out));
    }
    // A folder that is a file is not a missing folder.
    let file = dir.path().join("file.txt");
    std::fs::write(&file, "").unwrap();
    let inside_file = file.join("out.png");
    let out = raywave(&["render", "--device", "cpu", "--out", inside_file.to_str().unwrap()]);
    assert!(!out.status.success() && stderr(&out).contains("file.txt is not a directory"), "{}", stderr(&out));
}

/// With `--device auto` (the default), options only Vulkan has — validation, a hardware trace
/// method — make a Vulkan failure an error: the CPU fallback dropped `--validate` without a word
/// and answered `--trace rtpipe` with "the CPU backend traces in software only". Without them it
/// falls back, and says why on stderr (a missing driver had looked like a deliberate CPU run).
#[cfg(feature = "vulkan")]
#[test]
fn vulkan_only_options_do_not_fall_back_to_the_cpu() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("out.png");
    let out = out_path.to_str().unwrap();
    let small = ["render", "--width", "16", "--height", "16", "--out", out];
    let run = |env: (&str, &Path), extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_raywave")).env(env.0, env.1).args(small).args(extra).output().unwrap()
    };
    // No validation layer where the loader looks for one.
    let no_layers = run(("VK_LAYER_PATH", dir.path()), &["--validate"]);
    assert!(!no_layers.status.success(), "{}", String::from_utf8_lossy(&no_layers.stdout));
    assert!(stderr(&no_layers).contains("VK_LAYER_KHRONOS_validation"), "{}", stderr(&no_layers));
    // No Vulkan driver at all.
    let no_driver = run(("VK_DRIVER_FILES", &dir.path().join("none.json")), &["--trace", "rtpipe"]);
    assert!(!no_driver.status.success() && !stderr(&no_driver).contains("CPU backend"), "{}", stderr(&no_driver));
    assert!(stderr(&no_driver).contains("Vulkan"), "{}", stderr(&no_driver));
    // Without them, auto still falls back.
    let fallback = run(("VK_DRIVER_FILES", &dir.path().join("none.json")), &["--spp", "1"]);
    let names_backend = |out: &Output, name: &str| {
        String::from_utf8_lossy(&out.stdout).lines().any(|l| l.starts_with("backend") && l.contains(name))
    };
    assert!(fallback.status.success() && names_backend(&fallback, "cpu"), "{}", stderr(&fallback));
    let why = "warning: --device auto found no usable Vulkan device, so the render runs on the CPU: Vulkan is \
               unavailable: no Vulkan 1.2 driver is installed";
    assert!(stderr(&fallback).contains(why), "{}", stderr(&fallback));
    assert!(out_path.exists());
    // Where a Vulkan device opens (lavapipe in CI), auto takes it without the warning.
    let on_vulkan = Command::new(env!("CARGO_BIN_EXE_raywave")).args(small).args(["--spp", "1"]).output().unwrap();
    assert!(on_vulkan.status.success() && names_backend(&on_vulkan, "vulkan"), "{}", stderr(&on_vulkan));
    assert!(!stderr(&on_vulkan).contains("--device auto"), "{}", stderr(&on_vulkan));
}

/// A closed standard output (`raywave render … | head -1`) ends the command quietly; `println!`
/// panicked on the broken pipe.
#[test]
fn closed_stdout_is_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("piped.png");
    let out = run_with_closed_stdout(&[
        "render",
        "--device",
        "cpu",
        "--width",
        "16",
        "--height",
        "16",
        "--out",
        path.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{:?}: {}", out.status, stderr(&out));
    assert!(path.exists(), "the image is written before anything is printed");
}

/// A report whose reader goes away (`raywave report error-vs-time --plot p.png | head -2`) ends
/// with a failure, since its plot is not written, and takes the plot's temporary file with it:
/// the pending output was left behind when a closed stdout exited on the spot, and the report
/// had exited 0 without its plot.
#[test]
fn closed_stdout_leaves_no_temporary_file() {
    let dir = tempfile::tempdir().unwrap();
    let plot = dir.path().join("plot.png");
    let args = ["report", "error-vs-time", "--scenes", "builtin:cornell", "--resolution", "16", "--reference-spp", "4"];
    let more = ["--max-spp", "1", "--reps", "1", "--device", "cpu", "--plot", plot.to_str().unwrap()];
    let out = run_with_closed_stdout(&[&args[..], &more[..]].concat());
    // The plot was asked for and not written: a failure, said on stderr (without a plot the
    // closed stdout would end the report quietly, as the test above checks).
    assert!(!out.status.success(), "{:?}", out.status);
    assert!(stderr(&out).contains("standard output closed before the output file was written"), "{}", stderr(&out));
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// Interrupted — SIGINT as Ctrl-C sends it, SIGTERM, SIGHUP — a render ends by that signal and
/// leaves neither its output nor the temporary file it was to be written to (the handler deletes
/// it; without one, a `.raywave-…` file stayed beside the output). A signal its parent ignores,
/// as `nohup` does SIGHUP, stays ignored.
#[cfg(unix)]
#[test]
fn an_interrupted_render_leaves_no_file() {
    use std::os::unix::process::{CommandExt, ExitStatusExt};
    use std::time::{Duration, Instant};
    for (signal, number) in [("INT", libc::SIGINT), ("TERM", libc::SIGTERM), ("HUP", libc::SIGHUP)] {
        let dir = tempfile::tempdir().unwrap();
        let mut render = Command::new(env!("CARGO_BIN_EXE_raywave"));
        render
            .args(["render", "--device", "cpu", "--width", "1920", "--height", "1080", "--spp", "64", "--out"])
            .arg(dir.path().join("frame.png"))
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null());
        let nohup = number == libc::SIGHUP;
        if nohup {
            // SAFETY: `signal` is async-signal-safe, as a `pre_exec` closure must be.
            unsafe {
                render.pre_exec(|| {
                    libc::signal(libc::SIGHUP, libc::SIG_IGN);
                    Ok(())
                });
            }
        }
        let mut child = render.spawn().unwrap();
        // The temporary file appears before any work is done (a minute of it on this machine).
        let give_up = Instant::now() + Duration::from_secs(60);
        while std::fs::read_dir(dir.path()).unwrap().count() == 0 {
            assert!(child.try_wait().unwrap().is_none(), "SIG{signal}: the render ended before its output began");
            assert!(Instant::now() < give_up, "SIG{signal}: no temporary file appeared");
            std::thread::sleep(Duration::from_millis(10));
        }
        let pid = child.id().to_string();
        // Sent by `kill(2)`: a minimal Debian has no `kill` program (procps).
        let kill = |number: i32| {
            // SAFETY: `kill` takes no pointers; the child is ours and not yet waited for.
            let sent = unsafe { libc::kill(child.id() as libc::pid_t, number) };
            assert_eq!(sent, 0, "kill({pid}, {number}): {}", std::io::Error::last_os_error());
        };
        // The handlers are in place once the temporary file exists: the signal is caught, or
        // left ignored where the parent ignored it.
        #[cfg(target_os = "linux")]
        {
            let (ignored, caught) = signal_masks(&pid);
            let bit = 1u64 << (number - 1);
            assert_eq!((ignored & bit != 0, caught & bit != 0), (nohup, !nohup), "SIG{signal}");
        }
        kill(number);
        let expected = if nohup {
            // An ignored SIGHUP leaves it rendering, so SIGTERM is what ends it (had SIGHUP ended
            // it, the status would name SIGHUP).
            kill(libc::SIGTERM);
            libc::SIGTERM
        } else {
            number
        };
        let status = child.wait().unwrap();
        assert_eq!(status.signal(), Some(expected), "SIG{signal}: {status:?}");
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|entry| entry.unwrap().file_name()).collect();
        assert!(left.is_empty(), "SIG{signal}: left {left:?}");
    }
}

/// The signals process `pid` ignores and those it catches (`SigIgn`, `SigCgt` of
/// `/proc/PID/status`: bit n − 1 for signal n).
#[cfg(target_os = "linux")]
fn signal_masks(pid: &str) -> (u64, u64) {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let mask = |key: &str| {
        let hex = status.lines().find_map(|line| line.strip_prefix(key)).unwrap_or_else(|| panic!("{key} in {status}"));
        u64::from_str_radix(hex.trim(), 16).unwrap()
    };
    (mask("SigIgn:"), mask("SigCgt:"))
}

/// A full standard output (`bench … --json > file` on a full disk) is an error, not the quiet
/// success of a closed one: it had exited 0 with the results lost. A full standard error loses
/// the warnings only: a warning's `eprintln!` had panicked (exit 101) before the results were
/// printed.
#[cfg(target_os = "linux")]
#[test]
fn full_standard_streams() {
    let full = || std::fs::OpenOptions::new().write(true).open("/dev/full").expect("/dev/full");
    let lost = Command::new(env!("CARGO_BIN_EXE_raywave")).arg("devices").stdout(full()).output().unwrap();
    let message = stderr(&lost);
    assert!(!lost.status.success(), "{:?}: {message}", lost.status);
    assert!(message.contains("cannot write standard output") && !message.contains("panicked"), "{message}");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dark.png");
    let args = ["render", "--device", "cpu", "--scene", "builtin:hairball", "--width", "8", "--height", "8"];
    let warned = Command::new(env!("CARGO_BIN_EXE_raywave"))
        .args(args)
        .args(["--out", path.to_str().unwrap()])
        .stderr(full())
        .output()
        .unwrap();
    assert!(warned.status.success(), "{:?}", warned.status);
    let printed = String::from_utf8_lossy(&warned.stdout);
    assert!(path.exists() && printed.lines().any(|l| l.starts_with("stage")), "{printed}");
}

/// Runs raywave with `args`, its standard output closed before it prints anything, and checks
/// that it ends with success and without a panic.
fn run_with_closed_stdout(args: &[&str]) -> std::process::Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_raywave"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    assert!(!stderr(&out).contains("panicked"), "{:?}: {}", out.status, stderr(&out));
    out
}

/// A scene without quad lights renders (emitters glow, nothing is lit) with a warning; the
/// reports, which measure direct light, refuse it instead of printing errors of 0.
#[test]
fn lightless_scenes_warn_in_render_and_are_refused_by_reports() {
    let dir = tempfile::tempdir().unwrap();
    let (out, path) = render(dir.path(), "dark.png", &["--device", "cpu", "--scene", "builtin:hairball"]);
    assert!(out.status.success() && path.exists(), "{}", stderr(&out));
    assert!(stderr(&out).contains("builtin:hairball has no quad light"), "{}", stderr(&out));
    for report in ["shade", "error-vs-time"] {
        let out = raywave(&["report", report, "--scenes", "builtin:cornell,builtin:hairball", "--json"]);
        assert!(!out.status.success(), "report {report} should fail");
        assert!(stderr(&out).contains("builtin:hairball has no quad light"), "{}", stderr(&out));
        assert!(out.stdout.is_empty(), "nothing measured before the check: {}", String::from_utf8_lossy(&out.stdout));
    }
}

/// A scene whose materials have textures renders with a warning that they are not sampled; one
/// whose materials are see-through, with a warning that they are opaque.
#[test]
fn textured_and_see_through_materials_are_rendered_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("t.mtl"), "newmtl wood\nKd 0.5 0.4 0.3\nmap_Kd wood.png\n").unwrap();
    let obj = dir.path().join("t.obj");
    std::fs::write(&obj, "mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl wood\nf 1 2 3\n").unwrap();
    let (out, path) = render(dir.path(), "t.png", &["--device", "cpu", "--scene", obj.to_str().unwrap()]);
    assert!(out.status.success() && path.exists(), "{}", stderr(&out));
    assert!(stderr(&out).contains("1 mesh(es) of") && stderr(&out).contains("have textures"), "{}", stderr(&out));
    assert!(!stderr(&out).contains("see-through"), "{}", stderr(&out));
    // A see-through one (MTL dissolve) renders opaque, with a warning.
    std::fs::write(dir.path().join("t.mtl"), "newmtl wood\nKd 0.5 0.4 0.3\nd 0.25\n").unwrap();
    let (out, path) = render(dir.path(), "d.png", &["--device", "cpu", "--scene", obj.to_str().unwrap()]);
    assert!(out.status.success() && path.exists(), "{}", stderr(&out));
    let warning = "1 mesh(es) of";
    assert!(stderr(&out).contains(warning) && stderr(&out).contains("see-through materials"), "{}", stderr(&out));
    assert!(!stderr(&out).contains("have textures"), "{}", stderr(&out));
}

/// A camera that sees none of the scene (a glTF camera facing away from it) renders an empty
/// image with a warning: the summary's "0 of N camera rays hit" had been the only word of it.
#[test]
fn a_camera_that_sees_none_of_the_scene_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let tetrahedron =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/tetrahedron.gltf")).unwrap();
    let in_front = "    0,\n    -3\n   ],";
    assert!(tetrahedron.contains(in_front));
    let behind = dir.path().join("behind.gltf");
    std::fs::write(&behind, tetrahedron.replacen(in_front, "    0,\n    3\n   ],", 1)).unwrap();
    let warning = "warning: no camera ray hit";
    for (scene, hits) in
        [(behind.to_str().unwrap(), false), (concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/tetrahedron.gltf"), true)]
    {
        let (out, path) = render(dir.path(), "o.png", &["--device", "cpu", "--scene", scene, "--spp", "1"]);
        assert!(out.status.success() && path.exists(), "{}", stderr(&out));
        assert_eq!(stderr(&out).contains(warning), !hits, "{scene}: {}", stderr(&out));
        let summary = String::from_utf8_lossy(&out.stdout);
        assert_eq!(summary.contains(" (0 of "), !hits, "{summary}");
    }
}

/// An orthographic camera is replaced by the framing one, a skinned mesh renders in its rest
/// pose, a punctual light lights nothing, an unlit material is lit and a primitive of lines is
/// not drawn, each with a warning.
#[test]
fn an_orthographic_camera_a_skinned_mesh_and_a_punctual_light_render_with_warnings() {
    let dir = tempfile::tempdir().unwrap();
    let lamp = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/emissive_quad.gltf")).unwrap();
    let perspective =
        "\"type\": \"perspective\",\n   \"perspective\": {\n    \"yfov\": 0.9,\n    \"znear\": 0.01\n   }";
    let orthographic = r#""type": "orthographic", "orthographic": {"xmag": 1, "ymag": 1, "znear": 0.01, "zfar": 10}"#;
    let skinned_floor = "\"name\": \"floor\",\n   \"mesh\": 0,\n   \"skin\": 0";
    let unlit_grey = r#""name": "grey", "extensions": {"KHR_materials_unlit": {}},"#;
    let lines =
        "     \"indices\": 3,\n     \"material\": 1\n    },\n    {\"attributes\": {\"POSITION\": 1}, \"mode\": 1}";
    let text = lamp
        .replacen(perspective, orthographic, 1)
        .replacen("\"name\": \"floor\",\n   \"mesh\": 0", skinned_floor, 1)
        .replacen("\"scene\": 0,", "\"scene\": 0,\n \"skins\": [{\"joints\": [1]}],", 1)
        .replacen(
            "\"scene\": 0,",
            r#""scene": 0, "extensions": {"KHR_lights_punctual": {"lights": [{"type": "point"}]}},"#,
            1,
        )
        // A node placing the light after the camera's (whose translation ends in 3), then in the scene.
        .replacen(
            "    3\n   ]\n  }\n ],",
            "    3\n   ]\n  },\n  {\"extensions\": {\"KHR_lights_punctual\": {\"light\": 0}}}\n ],",
            1,
        )
        .replacen("    1,\n    2\n   ]", "    1,\n    2,\n    3\n   ]", 1)
        .replacen("\"name\": \"grey\",", unlit_grey, 1)
        .replacen("     \"indices\": 3,\n     \"material\": 1\n    }", lines, 1);
    assert!(text.contains(orthographic) && text.contains(skinned_floor) && text.contains("skins"));
    assert!(text.contains(unlit_grey) && text.contains(lines));
    assert!(
        text.contains(r#"{"extensions": {"KHR_lights_punctual": {"light": 0}}}"#)
            && text.contains("    2,\n    3\n   ]")
    );
    let scene = dir.path().join("ortho.gltf");
    std::fs::write(&scene, text).unwrap();
    let (out, path) = render(dir.path(), "o.png", &["--device", "cpu", "--scene", scene.to_str().unwrap()]);
    assert!(out.status.success() && path.exists(), "{}", stderr(&out));
    assert!(stderr(&out).contains("are orthographic, which raywave does not render"), "{}", stderr(&out));
    let skinned = "1 mesh(es) of";
    assert!(stderr(&out).contains(skinned) && stderr(&out).contains("render in their rest pose"), "{}", stderr(&out));
    assert!(stderr(&out).contains("1 punctual light(s)"), "{}", stderr(&out));
    assert!(stderr(&out).contains("have unlit materials (KHR_materials_unlit)"), "{}", stderr(&out));
    assert!(stderr(&out).contains("1 glTF primitive(s) of"), "{}", stderr(&out));
    assert!(stderr(&out).contains("draw points or lines, which raywave does not render"), "{}", stderr(&out));
}

/// Benchmark and report options out of range: each command fails at once with the option named
/// (before, `--repeats 0` measured one repetition, `--spp 0` failed inside the denoiser, a
/// negative `--peak-gbps` gave negative bandwidth fractions, and a reference past the sampler's index
/// repeated its samples; a filter radius outside the shared-memory tile's must fail before the
/// frame is shaded or the reference converged).
#[test]
fn bench_and_report_options_out_of_range_are_typed_errors() {
    let cases: [(&[&str], &str); 35] = [
        (&["bench", "denoise", "--no-vulkan", "--repeats", "0"], "repeats: must be at least 1"),
        (&["bench", "denoise", "--no-vulkan", "--spp", "0"], "spp: 0 is outside"),
        // Before the scene loads, which would fail too.
        (&["bench", "denoise", "--scene", "/no/such/scene.obj", "--spp", "0"], "spp: 0 is outside"),
        // Before the backend opens, which would fail too.
        (&["report", "error-vs-time", "--device", "vulkan:99", "--denoise-radius", "11"], "denoise-radius: radius 11"),
        (&["report", "error-vs-time", "--device", "vulkan:99", "--settle-seconds", "31"], "settle-seconds: 31"),
        (&["bench", "denoise", "--no-vulkan", "--spp", "8192"], "exceed the sampler's 32-bit index"),
        (&["bench", "denoise", "--no-vulkan", "--peak-gbps=-5"], "peak-gbps: must be finite and > 0"),
        (&["bench", "denoise", "--no-vulkan", "--denoise-radius", "0"], "denoise-radius: radius 0 outside 1..=10"),
        (&["report", "error-vs-time", "--denoise-radius", "11"], "denoise-radius: radius 11 outside 1..=10"),
        (&["report", "error-vs-time", "--settle-seconds", "31"], "settle-seconds: 31 is not within 0..=30 s"),
        (&["bench", "trace", "--no-vulkan", "--repeats", "0"], "repeats: must be at least 1"),
        // Named as the option, not as the CPU backend's image size.
        (
            &["bench", "trace", "--no-vulkan", "--resolution", "0"],
            "resolution: 0×0 rays: width and height must be at least 1",
        ),
        (&["bench", "trace", "--no-vulkan", "--threads", "0"], "threads: 0 is outside 1..="),
        (&["bench", "trace", "--no-vulkan", "--bvh", "best"], "bvh: \"best\": expected fast, medium or slow"),
        // Sizes no device runs were ignored without a word.
        (
            &["bench", "shade", "--no-vulkan", "--workgroup-sizes", "64"],
            "workgroup-sizes: no Vulkan device is measured",
        ),
        // So were a settling time and a peak bandwidth.
        (&["bench", "trace", "--no-vulkan", "--settle-seconds", "1"], "settle-seconds: no Vulkan device is measured"),
        (&["bench", "denoise", "--no-vulkan", "--peak-gbps", "3350"], "peak-gbps: no Vulkan device is measured"),
        // rayon caps its pools at 65 535 threads without a word; the report named the count asked.
        (&["bench", "trace", "--no-vulkan", "--threads", "70000"], "threads: 70000 is outside 1..=65535"),
        (&["bench", "trace", "--settle-seconds", "31"], "settle-seconds: 31 is not within 0..=30 s"),
        (&["bench", "trace", "--settle-seconds", "NaN"], "settle-seconds: NaN is not within"),
        (&["bench", "shade", "--no-vulkan", "--repeats", "0"], "repeats: must be at least 1"),
        (&["bench", "shade", "--no-vulkan", "--resolution", "0"], "resolution: 0×0 rays: width and height"),
        // Measured twice, two lines of one key.
        (&["bench", "shade", "--no-vulkan", "--workgroup-sizes", "64,64"], "workgroup-sizes: 64 is listed twice"),
        (&["bench", "shade", "--settle-seconds=-1"], "settle-seconds: -1 is not within 0..=30 s"),
        (&["report", "shade", "--resolution", "1024", "--reference-spp", "8192"], "reference-spp: 8192 samples"),
        // Each named: one message named the report and listed every condition.
        (&["report", "shade", "--reps", "0"], "reps: 0 is outside 1..=4096"),
        (&["report", "error-vs-time", "--reps", "4097"], "reps: 4097 is outside 1..=4096"),
        (&["report", "sampling", "--reps", "100000"], "reps: 100000 is outside 2..=4096"),
        (&["report", "sampling", "--reps", "1"], "reps: 1 is outside 2..=4096: a variance needs two repetitions"),
        (&["report", "shade", "--max-spp", "0"], "max-spp: 0 is not a power of two"),
        (&["report", "shade", "--max-spp", "48"], "max-spp: 48 is not a power of two"),
        // The flag named, not the library's `validation` field.
        (&["report", "shade", "--validate"], "validate: the CPU backend has no validation layers"),
        (&["report", "sampling", "--validate"], "validate: the CPU backend has no validation layers"),
        (
            &["report", "error-vs-time", "--reference-spp", "8", "--max-spp", "4"],
            "reference-spp: 8 is below 4 × max-spp (4)",
        ),
        // Lines and plots are keyed by scene name: a repeated scene merged into the first.
        (
            &["report", "error-vs-time", "--scenes", "builtin:cornell,builtin:cornell-two-lights,builtin:cornell"],
            "scenes: builtin:cornell is listed twice",
        ),
    ];
    for (args, needle) in cases {
        assert_refused_before_measuring(args, needle);
    }
}

#[test]
fn thin_lens_render_with_each_sampler_writes_a_png() {
    let dir = tempfile::tempdir().unwrap();
    for sampler in ["zsobol", "sobol", "random"] {
        let extra = ["--device", "cpu", "--sampler", sampler, "--aperture", "0.02", "--focus", "1.0"];
        let (out, path) = render(dir.path(), &format!("{sampler}.png"), &extra);
        assert!(out.status.success(), "{sampler}: {}", stderr(&out));
        assert!(image::open(&path).is_ok(), "{sampler}: PNG readable");
    }
}

#[test]
fn sampling_report_prints_json_lines_for_every_case_and_spectrum() {
    let out = raywave(&["report", "sampling", "--json", "--resolution", "8", "--reps", "4"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let lines = json_lines(&out);
    let cases: Vec<&str> = lines.iter().filter_map(|l| l["case"].as_str()).collect();
    assert_eq!(
        cases,
        [
            "ao_cosine_vs_uniform",
            "sphere_cone_vs_area",
            "light_importance_vs_uniform",
            "sobol_vs_random",
            "error_spectrum",
            "error_spectrum",
            "error_spectrum"
        ]
    );
    for line in &lines[..4] {
        let ratio = line["variance_ratio"].as_f64().unwrap();
        let (low, high) = (line["variance_ratio_low"].as_f64().unwrap(), line["variance_ratio_high"].as_f64().unwrap());
        // The interval is built around the ratio (`exp(ln r ± t·se)`): it must have been
        // estimated, with a positive, finite width, not be checked against its own centre.
        assert!(ratio.is_finite() && 0.0 < low && low < high && high.is_finite(), "{line}");
        assert!(line["published"].as_f64().unwrap() > 1.0);
        assert_eq!(line["reps"], 4);
    }
    let bad = raywave(&["report", "sampling", "--reps", "1"]);
    assert!(!bad.status.success() && stderr(&bad).contains("reps"), "{}", stderr(&bad));
}

#[test]
fn lit_render_writes_png_exr_and_stochastic_images() {
    let dir = tempfile::tempdir().unwrap();
    let exr = dir.path().join("lit.exr");
    let stochastic = dir.path().join("stochastic.png");
    let frame = ["--device", "cpu", "--scene", "builtin:cornell-two-lights", "--spp", "2"];
    let extra = [&frame[..], &["--exr", exr.to_str().unwrap(), "--stochastic", stochastic.to_str().unwrap()]].concat();
    let (out, png) = render(dir.path(), "lit.png", &extra);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("2 quad lights"));
    let hdr = image::open(&exr).expect("EXR readable").into_rgb32f();
    assert_eq!(hdr.dimensions(), (96, 64));
    assert!(hdr.pixels().all(|p| p.0.iter().all(|c| c.is_finite() && *c >= 0.0)));
    let max = hdr.pixels().flat_map(|p| p.0).fold(0.0f32, f32::max);
    assert!(max > 1.0, "the emitters are visible in HDR (max {max})");
    assert!(image::open(&png).is_ok() && image::open(&stochastic).is_ok());
    // The same frame with the quadrature residual in U: valid, close, and not the same.
    let exr_residual = dir.path().join("residual.exr");
    let with_residual = [&frame[..], &["--exr", exr_residual.to_str().unwrap(), "--analytic-residual"]].concat();
    let (out, _) = render(dir.path(), "residual.png", &with_residual);
    assert!(out.status.success(), "{}", stderr(&out));
    let corrected = image::open(&exr_residual).expect("EXR readable").into_rgb32f();
    let channels = |image: &image::Rgb32FImage| image.pixels().flat_map(|p| p.0).collect::<Vec<f32>>();
    let (plain, corrected) = (channels(&hdr), channels(&corrected));
    assert!(corrected.iter().all(|c| c.is_finite() && *c >= 0.0));
    let changed = plain.iter().zip(&corrected).filter(|(a, b)| (*a - *b).abs() > 1e-6 * a.abs().max(1e-3)).count();
    let (sum_plain, sum_corrected) = (plain.iter().sum::<f32>(), corrected.iter().sum::<f32>());
    assert!(changed > 0, "--analytic-residual changed no pixel");
    assert!((sum_corrected / sum_plain - 1.0).abs() < 0.02, "{sum_corrected} vs {sum_plain}");
    let (out, normals) = render(dir.path(), "normals.png", &["--device", "cpu", "--view", "normals"]);
    assert!(out.status.success() && image::open(&normals).is_ok(), "{}", stderr(&out));
    // The sample index limits only what the frame draws: the normals view's one sample (not the
    // default `--spp 4`, which a lit 65536-wide frame exceeds), and only the blue-noise sampler's
    // Morton index (`sobol` draws 2 samples a pixel of a 65536-wide frame, which the blue-noise
    // sampler's 2^32 indices do not hold).
    for (name, extra) in [
        ("wide-normals.png", &["--view", "normals", "--width", "65536", "--height", "1"][..]),
        ("wide-sobol.png", &["--sampler", "sobol", "--spp", "2", "--width", "65536", "--height", "1"]),
    ] {
        let (out, path) = render(dir.path(), name, &[&["--device", "cpu"][..], extra].concat());
        assert!(out.status.success() && image::open(&path).is_ok(), "{name}: {}", stderr(&out));
    }
}

#[test]
fn shade_report_prints_json_lines() {
    let out = raywave(&[
        "report",
        "shade",
        "--json",
        "--scenes",
        "builtin:cornell",
        "--resolution",
        "8",
        "--reference-spp",
        "16",
        "--max-spp",
        "2",
        "--reps",
        "2",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let lines = json_lines(&out);
    assert_eq!(lines.len(), 3 + 2 * 2 * 3, "the 1-spp floor's regions, then spp × estimators × regions");
    for line in &lines {
        assert_eq!(line["scene"], "builtin:cornell");
        let estimator = line["estimator"].as_str().unwrap();
        assert!(["visibility-floor", "ratio", "stochastic"].contains(&estimator));
        assert!(["all", "shadow", "lit"].contains(&line["region"].as_str().unwrap()));
        assert!(line["rmse"].as_f64().unwrap().is_finite());
        // The repetitions' standard error, where there are repetitions (two here).
        let stderr = line.get("rmse_stderr").map(|e| e.as_f64().unwrap());
        assert_eq!(stderr.is_some(), estimator != "visibility-floor", "{line}");
        assert!(stderr.is_none_or(|e| e.is_finite() && e >= 0.0), "{line}");
    }
}

/// `report error-vs-time --settle-seconds` on a Vulkan device: the same errors, bit for bit, with
/// milliseconds measured in benchmark mode after a warm-up that each line states; the run without
/// it under the validation layers, silent.
#[cfg(feature = "vulkan")]
#[test]
fn error_vs_time_in_steady_state_measures_the_same_errors() {
    if vulkan_devices("steady-state error-vs-time").is_none() {
        return;
    }
    let args = ["report", "error-vs-time", "--scenes", "builtin:cornell", "--resolution", "16"];
    let args = [&args[..], &["--reference-spp", "16", "--max-spp", "2", "--reps", "1", "--device", "vulkan", "--json"]];
    // With the validation layers, which must say nothing.
    let once = raywave(&[&args.concat()[..], &["--validate"]].concat());
    assert!(once.status.success() && !stderr(&once).contains("[vulkan"), "{}", stderr(&once));
    let once = json_lines(&once);
    let steady = json_lines(&raywave(&[&args.concat()[..], &["--settle-seconds", "0.05"]].concat()));
    assert_eq!(once.len(), 2 * 5, "{once:?}");
    assert_eq!(steady.len(), once.len(), "{steady:?}");
    for (once, steady) in once.iter().zip(&steady) {
        for key in ["scene", "spp", "method", "relmse", "relmse_shadow", "relmse_lit", "flip"] {
            assert_eq!(once[key], steady[key], "{key}: {once} against {steady}");
        }
        assert!(once.get("warm_up_seconds").is_none() && once.get("relmse_stderr").is_none(), "{once}");
        assert!(steady["warm_up_seconds"].as_f64().unwrap() >= 0.05, "{steady}");
        assert!(steady["ms"].as_f64().unwrap() > 0.0, "{steady}");
        assert!(steady["backend"].as_str().unwrap().starts_with("vulkan:"), "{steady}");
    }
}

#[test]
fn error_vs_time_report_prints_every_method_and_draws_the_plot() {
    let dir = tempfile::tempdir().unwrap();
    let plot = dir.path().join("error-vs-time.png");
    let args = [
        "report",
        "error-vs-time",
        "--scenes",
        "builtin:cornell",
        "--resolution",
        "16",
        "--reference-spp",
        "16",
        "--max-spp",
        "2",
        "--reps",
        "2",
        "--json",
        "--plot",
        plot.to_str().unwrap(),
    ];
    let out = raywave(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    let lines = json_lines(&out);
    assert_eq!(lines.len(), 2 * 5, "spp × methods");
    for method in ["stochastic", "stochastic+tv", "ratio", "ratio+tv", "ratio+svgf"] {
        let line = lines.iter().find(|l| l["method"] == method && l["spp"] == 1).expect("method present");
        assert_eq!(line["scene"], "builtin:cornell");
        assert!(line["relmse"].as_f64().unwrap().is_finite() && line["ms"].as_f64().unwrap() > 0.0);
        assert!(line["backend"].as_str().unwrap().starts_with("cpu ("), "the default device: {line}");
        let flip = line["flip"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&flip), "FLIP {flip}");
        let part = |key: &str| line[key].as_f64().unwrap_or_else(|| panic!("{key} missing"));
        let (shadow, lit) = (part("relmse_shadow"), part("relmse_lit"));
        assert!(shadow >= 0.0 && lit >= 0.0 && shadow + lit <= line["relmse"].as_f64().unwrap() * (1.0 + 1e-12));
        // Two repetitions: the mean's standard error (absent for one, as the steady-state test sees).
        let stderr = part("relmse_stderr");
        assert!(stderr.is_finite() && stderr >= 0.0, "{line}");
    }
    // The table ends with the fastest method per error level.
    let table = raywave(&args[..args.len() - 3]);
    assert!(table.status.success(), "{}", stderr(&table));
    let text = String::from_utf8_lossy(&table.stdout);
    assert!(text.starts_with("backend  cpu ("), "the table names its backend first: {text}");
    assert!(text.lines().any(|l| l.contains("relMSE ≤") && l.contains("fastest")), "{text}");
    let image = image::open(&plot).expect("plot is a PNG").to_rgb8();
    assert_eq!(image.width(), 960);
    assert!(image.pixels().any(|p| p.0 != [255, 255, 255]), "something was drawn");
    // `--denoise-radius` widens the filters (R = 1 at 16² by default) and nothing else.
    let wider = json_lines(&raywave(&[&args[..args.len() - 2], &["--denoise-radius", "3"]].concat()));
    let relmse = |lines: &[serde_json::Value], method: &str| {
        lines.iter().find(|l| l["method"] == method && l["spp"] == 1).map(|l| l["relmse"].as_f64().unwrap())
    };
    for method in ["stochastic", "ratio"] {
        assert_eq!(relmse(&wider, method), relmse(&lines, method), "{method} is not filtered");
    }
    for method in ["stochastic+tv", "ratio+tv", "ratio+svgf"] {
        assert_ne!(relmse(&wider, method), relmse(&lines, method), "{method} at R = 3");
    }
    let bad =
        raywave(&["report", "error-vs-time", "--reps", "0", "--plot", plot.with_extension("x.png").to_str().unwrap()]);
    assert!(!bad.status.success() && stderr(&bad).contains("reps"));
    assert!(!plot.with_extension("x.png").exists(), "no partial plot");
}

#[test]
fn denoise_bench_prints_each_pass_and_the_total() {
    let args = ["bench", "denoise", "--width", "40", "--height", "24", "--repeats", "1", "--no-vulkan", "--json"];
    let out = raywave(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    let lines = json_lines(&out);
    assert_eq!(
        lines.len(),
        (6 + 1) + (4 + 1),
        "tv and svgf (one à-trous iteration at this size) passes, each with a total"
    );
    let copy_gb_per_s = lines[0]["copy_gb_per_s"].as_f64().unwrap();
    assert!(copy_gb_per_s.is_finite() && copy_gb_per_s > 0.0, "{:?}", lines[0]);
    for line in &lines {
        assert_eq!((line["stage"].as_str(), line["pixels"].as_u64()), (Some("denoise"), Some(960)));
        assert!(line["seconds"].as_f64().unwrap() > 0.0 && line["bytes"].as_u64().unwrap() > 0);
        // One copy probe per backend: every line of the CPU carries the same roof.
        assert_eq!(line["copy_gb_per_s"].as_f64(), Some(copy_gb_per_s), "{line:?}");
        let expected = line["gb_per_s"].as_f64().unwrap() / copy_gb_per_s;
        let fraction = line["copy_fraction"].as_f64().unwrap();
        assert!((fraction - expected).abs() <= 1e-12 * expected, "{line:?}");
    }
    let tv_total = lines.iter().find(|l| l["method"] == "tv" && l["pass"] == "total").unwrap();
    let tv_bytes: u64 = lines
        .iter()
        .filter(|l| l["method"] == "tv" && l["pass"] != "total")
        .map(|l| l["bytes"].as_u64().unwrap())
        .sum();
    assert_eq!(tv_total["bytes"].as_u64(), Some(tv_bytes));
    assert!(lines.iter().all(|l| l["radius"] == 1), "R follows the frame: 1 below a 128-pixel side");
    let wider = json_lines(&raywave(&[&args[..], &["--denoise-radius", "3"]].concat()));
    assert!(wider.iter().all(|l| l["radius"] == 3), "{wider:?}");
    let atrous: Vec<_> =
        wider.iter().filter_map(|l| l["pass"].as_str().filter(|p| p.starts_with("svgf atrous"))).collect();
    assert_eq!(
        atrous,
        ["svgf atrous step 1", "svgf atrous step 2", "svgf atrous step 4"],
        "three à-trous iterations at R = 3"
    );
}

/// `bench trace` and `bench shade` on the CPU alone, as any build measures on any machine: the
/// BVH build line, then each tracer's line per ray kind — its rate the one its own rays and
/// seconds make, the `--bvh` preset named where an obvhs tree was traversed — and the shade line.
#[test]
fn trace_and_shade_benches_measure_the_cpu_alone() {
    let args = ["bench", "trace", "--no-vulkan", "--scene", "builtin:cornell", "--resolution", "8", "--repeats", "2"];
    let out = raywave(&[&args[..], &["--threads", "1", "--bvh", "medium", "--json"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let lines = json_lines(&out);
    let rate_of = |line: &serde_json::Value, count: &str| {
        let seconds = line["seconds"].as_f64().unwrap();
        assert!(seconds > 0.0 && line["warm_up_seconds"].as_f64().unwrap() >= 0.5, "{line:?}");
        line[count].as_f64().unwrap() / seconds / 1e6
    };
    let build = &lines[0];
    assert_eq!((build["stage"].as_str(), build["impl"].as_str()), (Some("bvh_build"), Some("obvhs-cwbvh-medium")));
    assert!(build["triangles"].as_u64().unwrap() > 0 && build["bytes_per_triangle"].as_f64().unwrap() > 0.0);
    assert!(["portable", "x86-64-v3"].contains(&build["traversal_isa"].as_str().unwrap()), "{build:?}");
    let traces: Vec<_> = lines.iter().filter(|l| l["stage"] == "trace").collect();
    let tracers = 2 + usize::from(cfg!(feature = "embree"));
    assert_eq!(traces.len(), 3 * tracers, "{lines:?}");
    for (i, line) in traces.iter().enumerate() {
        assert_eq!(line["kind"], ["primary", "shadow", "diffuse"][i / tracers], "{line:?}");
        assert_eq!((line["threads"].as_u64(), line["dispatches"].as_u64()), (Some(1), Some(1)), "{line:?}");
        assert!(line.get("workgroup_size").is_none(), "{line:?}");
        let expected_bvh = if line["impl"] == "embree" { None } else { Some("medium") };
        assert_eq!(line.get("bvh").and_then(|b| b.as_str()), expected_bvh, "{line:?}");
        let rate = line["mrays_per_s"].as_f64().unwrap();
        assert!((rate - rate_of(line, "rays")).abs() <= 1e-12 * rate, "{line:?}");
    }
    // 8² primary rays; a shadow and a diffuse ray from each primary hit.
    let rays = |kind: &str| -> Vec<u64> {
        traces.iter().filter(|l| l["kind"] == kind).map(|l| l["rays"].as_u64().unwrap()).collect()
    };
    assert_eq!(rays("primary"), vec![64; tracers]);
    assert!(rays("shadow") == rays("diffuse") && (1..=64).contains(&rays("shadow")[0]), "{traces:?}");
    assert!(rays("shadow").iter().all(|&n| n == rays("shadow")[0]), "{traces:?}");

    let args = ["bench", "shade", "--no-vulkan", "--scene", "builtin:cornell-light-grid", "--resolution", "8"];
    let out = raywave(&[&args[..], &["--repeats", "1", "--json"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let lines = json_lines(&out);
    assert_eq!(lines.len(), 1, "{lines:?}");
    let line = &lines[0];
    assert_eq!(
        (line["stage"].as_str(), line["samples"].as_u64(), line["lights"].as_u64()),
        (Some("shade"), Some(64), Some(20))
    );
    assert!(line["impl"].as_str().unwrap().starts_with("cpu") && line.get("workgroup_size").is_none(), "{line:?}");
    assert_eq!(line["dispatches"].as_u64(), Some(1));
    let rate = line["msamples_per_s"].as_f64().unwrap();
    assert!((rate - rate_of(line, "samples")).abs() <= 1e-12 * rate, "{line:?}");
}

/// A command run with `--validate` fails (exit status 1) when the validation layers reported
/// anything, after printing it: a render writes no image, and a report prints its lines but draws
/// no plot. The messages are provoked by the layers' best-practices checks, which warn on every
/// run (raywave enables `VK_EXT_debug_utils` for the layers, itself a "special use" warning);
/// `VK_LAYER_ENABLES` turns them on (Khronos validation layers 1.3.239, Debian 12's). Without
/// them the same commands pass with `--validate` (`vulkan_and_cpu_renders_agree`,
/// `error_vs_time_in_steady_state_measures_the_same_errors`).
#[cfg(feature = "vulkan")]
#[test]
fn validation_messages_fail_the_command_and_write_nothing() {
    if vulkan_devices("validation messages").is_none() {
        return;
    }
    let best_practices = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_raywave"))
            .args(args)
            .env("VK_LAYER_ENABLES", "VK_VALIDATION_FEATURE_ENABLE_BEST_PRACTICES_EXT")
            .output()
            .expect("raywave runs")
    };
    let assert_failed_by_validation = |out: &Output, what: &str| {
        let message = stderr(out);
        assert_eq!(out.status.code(), Some(1), "{what}: {message}");
        assert!(message.contains("[vulkan WARNING]"), "{what}: no message provoked: {message}");
        assert!(message.contains("the Vulkan validation layers reported"), "{what}: {message}");
    };
    let dir = tempfile::tempdir().unwrap();
    let image = dir.path().join("validated.png");
    let args = ["render", "--device", "vulkan", "--validate", "--width", "16", "--height", "16", "--spp", "1"];
    let rendered = best_practices(&[&args[..], &["--out", image.to_str().unwrap()]].concat());
    assert_failed_by_validation(&rendered, "render");
    assert!(!image.exists() && rendered.stdout.is_empty(), "a faulted render wrote {}", image.display());

    let plot = dir.path().join("validated-plot.png");
    let args = ["report", "error-vs-time", "--scenes", "builtin:cornell", "--resolution", "8", "--reference-spp", "4"];
    let args = [&args[..], &["--max-spp", "1", "--reps", "1", "--device", "vulkan", "--validate", "--json", "--plot"]];
    let reported = best_practices(&[&args.concat()[..], &[plot.to_str().unwrap()]].concat());
    assert_failed_by_validation(&reported, "error-vs-time");
    assert_eq!(json_lines(&reported).len(), 5, "the report's lines come first: {}", stderr(&reported));
    assert!(!plot.exists(), "a faulted report drew {}", plot.display());
}

/// The Vulkan devices, or `None` after a loud SKIP (a failure under CI) when there are none.
#[cfg(feature = "vulkan")]
fn vulkan_devices(test: &str) -> Option<Vec<raywave::vulkan::DeviceInfo>> {
    let devices = raywave::vulkan::enumerate_devices().ok().filter(|d| !d.is_empty());
    if devices.is_none() {
        common::skip_or_fail(test, "no Vulkan device");
    }
    devices
}

/// `bench trace --workgroup-sizes`: each Vulkan compute trace method (`sw`, `rayquery`) measured
/// once per size and kind, every line naming its size; the ray-tracing pipeline and the CPU
/// tracers once, without one. A size the device does not run fails before anything is measured.
#[cfg(feature = "vulkan")]
#[test]
fn trace_bench_measures_each_workgroup_size_of_each_compute_method() {
    if vulkan_devices("trace bench workgroup sizes").is_none() {
        return;
    }
    // The bench measures the best device alone.
    let best = raywave::device::best_vulkan_device_info().expect("the device the bench measures");
    let base =
        ["bench", "trace", "--scene", "builtin:cornell", "--resolution", "8", "--repeats", "1", "--threads", "1"];
    let quick = [&base[..], &["--settle-seconds", "0.05", "--json"]].concat();
    let out = raywave(&[&quick[..], &["--workgroup-sizes", "32,128", "--bvh", "slow"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let lines: Vec<_> = json_lines(&out).into_iter().filter(|l| l["stage"] == "trace").collect();
    // `sw` traverses the `--bvh` tree, as the CPU does (it had built the default one); the
    // driver's structures and Embree's have no preset.
    for line in &lines {
        let obvhs_tree = ["raywave-cpu", "obvhs", "raywave-vk-sw"].contains(&line["impl"].as_str().unwrap());
        assert_eq!(line.get("bvh").and_then(|b| b.as_str()), obvhs_tree.then_some("slow"), "{line:?}");
    }
    let count = |implementation: &str, size: Option<u64>| {
        let matches = |l: &&serde_json::Value| l["impl"] == implementation && l["workgroup_size"].as_u64() == size;
        let kinds: Vec<_> = lines.iter().filter(matches).map(|l| l["kind"].as_str().unwrap().to_owned()).collect();
        assert!(kinds.is_empty() || kinds == ["primary", "shadow", "diffuse"], "{implementation} {size:?}: {kinds:?}");
        kinds.len()
    };
    assert_eq!(count("raywave-vk-sw", Some(32)), 3);
    assert_eq!(count("raywave-vk-sw", Some(128)), 3);
    assert_eq!(count("raywave-vk-sw", None), 0);
    let ray_query = best.missing_for_ray_query().is_empty();
    assert_eq!(
        count("raywave-vk-rayquery", Some(32)) + count("raywave-vk-rayquery", Some(128)),
        if ray_query { 6 } else { 0 }
    );
    assert_eq!(count("raywave-vk-rtpipe", Some(32)) + count("raywave-vk-rtpipe", Some(128)), 0);
    assert_eq!(count("raywave-cpu", None), 3);
    // The CPU tracers once each, without a size: raywave's, obvhs's, and Embree where built with it.
    let on_the_cpu = |l: &&serde_json::Value| !l["impl"].as_str().is_some_and(|i| i.starts_with("raywave-vk-"));
    let cpu_lines = lines.iter().filter(on_the_cpu).count();
    assert_eq!(cpu_lines, 3 * (2 + usize::from(cfg!(feature = "embree"))), "{lines:?}");
    let measured = 2 * 3 * (1 + usize::from(ray_query)) + count("raywave-vk-rtpipe", None) + cpu_lines;
    assert_eq!(lines.len(), measured, "{lines:?}");
    // Without `--workgroup-sizes`, `sw` runs each kind once, at the preferred size.
    let preferred_run = raywave(&quick);
    assert!(preferred_run.status.success(), "{}", stderr(&preferred_run));
    let preferred = json_lines(&preferred_run);
    let sw_sizes: Vec<_> = preferred
        .iter()
        .filter(|l| l["stage"] == "trace" && l["impl"] == "raywave-vk-sw")
        .map(|l| l["workgroup_size"].as_u64())
        .collect();
    assert_eq!(sw_sizes, [Some(64); 3], "{preferred:?}");
    let refused = [&quick[..], &["--workgroup-sizes", "64,96"]].concat();
    assert_refused_before_measuring(&refused, "workgroup-sizes: 96: this device runs the powers of two");
    // A frame the CPU takes and the device's streams cannot hold (lavapipe: 2897²) fails before
    // anything is measured: the CPU rows had run first, minutes at that size.
    let side = u32::try_from(best.max_stream_len(32).isqrt() + 1).unwrap_or(u32::MAX);
    if raywave::Backend::check_image_size(&raywave::cpu::CpuBackend::new(), side, side).is_ok() {
        let side = side.to_string();
        let too_large = [&base[..4], &["--resolution", &side, "--repeats", "1", "--workgroup-sizes", "32"]].concat();
        assert_refused_before_measuring(&too_large, &format!("is invalid on vulkan:{}", best.index));
    }
}

/// `bench shade --workgroup-sizes`: the CPU once and the Vulkan device once per shade workgroup
/// size, each Vulkan line naming its size, every line the same samples and lights at a positive
/// rate; a size the device does not run fails before anything is measured.
#[cfg(feature = "vulkan")]
#[test]
fn shade_bench_measures_the_cpu_and_each_shade_workgroup_size() {
    let Some(devices) = vulkan_devices("shade bench") else { return };
    let base = ["bench", "shade", "--scene", "builtin:cornell-light-grid", "--resolution", "16", "--repeats", "1"];
    let quick = [&base[..], &["--settle-seconds", "0.05", "--json"]].concat();
    let out = raywave(&[&quick[..], &["--workgroup-sizes", "32,256"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let lines = json_lines(&out);
    let sizes: Vec<_> = lines.iter().map(|l| l["workgroup_size"].as_u64()).collect();
    assert_eq!(sizes, [None, Some(32), Some(256)], "{lines:?}");
    for line in &lines {
        assert_eq!(
            (line["stage"].as_str(), line["samples"].as_u64(), line["lights"].as_u64()),
            (Some("shade"), Some(256), Some(20))
        );
        let rate = line["msamples_per_s"].as_f64().unwrap();
        assert!(rate.is_finite() && rate > 0.0 && line["seconds"].as_f64().unwrap() > 0.0, "{line:?}");
        assert!(line["dispatches"].as_u64().unwrap() >= 1 && line["warm_up_seconds"].as_f64().unwrap() >= 0.05);
    }
    // Without sizes: the device's preferred shade size (256 where it runs 256, as lavapipe does).
    let preferred = json_lines(&raywave(&quick));
    let sizes: Vec<_> = preferred.iter().map(|l| l["workgroup_size"].as_u64()).collect();
    let shade_size = |d: &raywave::vulkan::DeviceInfo| raywave::WorkgroupSizes::preferred_on(&d.workgroup_sizes).shade;
    assert!(devices.iter().any(|d| sizes == [None, Some(u64::from(shade_size(d)))]), "{preferred:?}");
    let refused = [&quick[..], &["--workgroup-sizes", "48"]].concat();
    assert_refused_before_measuring(&refused, "workgroup-sizes: 48: this device runs");
}

/// `bench denoise --workgroup-sizes`: every pass and total of both denoisers on the CPU once
/// and on the Vulkan device once per size of the per-pixel passes, each Vulkan line naming it.
#[cfg(feature = "vulkan")]
#[test]
fn denoise_bench_measures_each_workgroup_size_of_the_per_pixel_passes() {
    if vulkan_devices("denoise bench").is_none() {
        return;
    }
    let args = ["bench", "denoise", "--width", "40", "--height", "24", "--repeats", "1", "--json"];
    let out = raywave(&[&args[..], &["--settle-seconds", "0.05", "--workgroup-sizes", "32,256"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let lines = json_lines(&out);
    let per_backend = (6 + 1) + (4 + 1);
    assert_eq!(lines.len(), 3 * per_backend, "{lines:?}");
    let sizes: Vec<_> = lines.iter().map(|l| l["workgroup_size"].as_u64()).collect();
    for (block, expected) in sizes.chunks(per_backend).zip([None, Some(32), Some(256)]) {
        assert!(block.iter().all(|&size| size == expected), "{expected:?}: {block:?}");
    }
    let refused = [&args[..], &["--workgroup-sizes", "3"]].concat();
    assert_refused_before_measuring(&refused, "workgroup-sizes: 3: this device runs");
}

#[test]
fn render_denoises_by_default_and_takes_each_denoiser() {
    let dir = tempfile::tempdir().unwrap();
    let mut images = Vec::new();
    for denoise in ["tv", "svgf", "none"] {
        let (out, path) =
            render(dir.path(), &format!("{denoise}.png"), &["--device", "cpu", "--spp", "1", "--denoise", denoise]);
        assert!(out.status.success(), "{}", stderr(&out));
        let stdout = String::from_utf8_lossy(&out.stdout);
        // `none` is the composite alone; the filters run their passes before it.
        assert_eq!(stdout.contains("denoise noise"), denoise == "tv", "{stdout}");
        assert_eq!(stdout.contains("svgf"), denoise == "svgf", "{stdout}");
        assert!(stdout.contains("composite"), "{stdout}");
        images.push(image::open(&path).unwrap().to_rgb8());
    }
    assert_ne!(images[0], images[2], "TV changes the 1-spp image");
    assert_ne!(images[1], images[2], "SVGF changes the 1-spp image");
    let (default, path) = render(dir.path(), "default.png", &["--device", "cpu", "--spp", "1"]);
    assert!(default.status.success());
    assert_eq!(image::open(&path).unwrap().to_rgb8(), images[0], "TV is the default");
    // 96×64 filters with R = 2 unless told otherwise.
    let radius = |r: &str| {
        let (out, path) =
            render(dir.path(), &format!("r{r}.png"), &["--device", "cpu", "--spp", "1", "--denoise-radius", r]);
        assert!(out.status.success(), "{}", stderr(&out));
        image::open(&path).unwrap().to_rgb8()
    };
    assert_eq!(radius("2"), images[0], "R = 2 is this size's default");
    assert_ne!(radius("4"), images[0], "R = 4 filters wider");
    // One sample below 4R² the TV filter still filters, so R is accepted (from 4R² on it is
    // refused: `bad_input_is_a_typed_error_without_output`).
    let (out, _) = render(dir.path(), "spp15.png", &["--device", "cpu", "--spp", "15", "--denoise-radius", "2"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_rejected(&["--denoise", "blur"], "denoise");
    assert_rejected(&["--device", "cpu", "--denoise-radius", "11"], "denoise-radius: radius 11 outside 1..=10");
}
