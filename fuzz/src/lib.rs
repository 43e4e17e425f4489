//! What the fuzz targets share: turning the fuzzer's bytes into scene files, and rendering a
//! scene file with the checks every render must pass.

pub mod shapes;

use raywave::denoise::DenoiseMethod;
use raywave::render::{render, RenderOptions, RenderView};
use raywave::shading::ShadeData;
use raywave::{BackendOptions, DeviceChoice, Error, Scene, StageReport};
use std::path::{Path, PathBuf};

/// Writes `bytes` as a scene into `dir` and returns the path to load: `bytes[0] % 3` picks an OBJ
/// (`s.obj`), a glTF (`s.gltf`) or a GLB (`s.glb`, the rest of the bytes); for the first two the
/// rest is split at its first zero byte into the scene and its side file — the material library
/// `m.mtl` an OBJ's `mtllib` may name, or the buffer `b.bin` a glTF's `uri` may name. `None` for
/// no bytes.
pub fn write_scene(dir: &Path, bytes: &[u8]) -> Option<PathBuf> {
    let (&kind, rest) = bytes.split_first()?;
    let (main, side) = match rest.iter().position(|&b| b == 0) {
        Some(i) => (&rest[..i], &rest[i + 1..]),
        None => (rest, &[][..]),
    };
    let (name, main, side) = match kind % 3 {
        0 => ("s.obj", main, Some(("m.mtl", side))),
        1 => ("s.gltf", main, Some(("b.bin", side))),
        _ => ("s.glb", rest, None),
    };
    if let Some((side_name, side)) = side {
        std::fs::write(dir.join(side_name), side).expect("the fuzz directory is writable");
    }
    let path = dir.join(name);
    std::fs::write(&path, main).expect("the fuzz directory is writable");
    Some(path)
}

/// Renders the scene file `scene` on the CPU (12×8 pixels) into `dir`, with the estimator options
/// `choices` picks (bit 0: `--analytic-residual`; the next bits: the denoiser — TV, SVGF or none
/// — and 1, 2 or 4 samples per pixel), and asserts what every render must give: no stage replacing
/// a non-finite value (sound input sanitizes nothing) and a finite HDR image — or the typed error
/// of a scene the render may refuse: one that does not load, whose BVH is too deep, or whose
/// lights fail their checks. Any other error (options, streams, outputs) is a defect. Returns
/// whether the scene rendered (false: it did not load, or the render refused it).
pub fn render_checked(dir: &Path, scene: &Path, choices: u8) -> bool {
    let denoise = [DenoiseMethod::Tv, DenoiseMethod::Svgf, DenoiseMethod::None][(choices as usize >> 1) % 3];
    let scene_name = scene.to_str().expect("a UTF-8 temporary path");
    let Ok(loaded) = Scene::load(scene_name) else { return false };
    let options = RenderOptions {
        scene: scene_name.to_owned(),
        device: DeviceChoice::Cpu,
        width: 12,
        height: 8,
        spp: 1 << ((choices >> 3) % 3),
        seed: 1,
        sampler: 0,
        lens_radius: 0.0,
        focus_distance: None,
        view: RenderView::Lit,
        out: dir.join("out.png"),
        exr: Some(dir.join("out.exr")),
        stochastic: Some(dir.join("stochastic.png")),
        denoise,
        denoise_radius: None,
        analytic_residual: choices & 1 == 1,
        backend: BackendOptions::default(),
        settle_seconds: None,
    };
    match render(&options) {
        Ok(report) => {
            assert_eq!(StageReport::total_sanitized(&report.timings), 0, "{:?}", report.timings);
            let hdr = image::open(dir.join("out.exr")).expect("the EXR reads back").into_rgba32f();
            assert!(hdr.pixels().all(|p| p.0.iter().all(|v| v.is_finite())), "a non-finite pixel");
            true
        }
        Err(Error::SceneTooLarge { .. }) => false,
        Err(err) => {
            assert!(ShadeData::new(&loaded).is_err(), "a scene that loads, with valid lights, refused: {err}");
            false
        }
    }
}

/// `scene_render`'s input: byte 0 chooses the estimator options ([`render_checked`]), the rest is
/// the scene ([`write_scene`]), rendered in a scratch directory ([`with_scratch_dir`]). Returns
/// whether the scene rendered.
pub fn render_input(bytes: &[u8]) -> bool {
    let Some((&choices, scene_bytes)) = bytes.split_first() else { return false };
    with_scratch_dir(|dir| write_scene(dir, scene_bytes).is_some_and(|path| render_checked(dir, &path, choices)))
}

/// An empty directory for one input: `input/` inside a temporary directory of the fuzzing
/// process, emptied before each input, so that no input reads the files an earlier one wrote (a
/// crash then reproduces from its input alone), and a scene's `../` reaches only that directory.
/// The temporary directory is in memory where the system has such a place (`RAM_TEMP_DIR`).
pub fn with_scratch_dir<T>(f: impl FnOnce(&Path) -> T) -> T {
    thread_local! {
        static DIR: tempfile::TempDir = tempfile::tempdir_in(RAM_TEMP_DIR)
            .or_else(|_| tempfile::tempdir())
            .expect("a temporary directory");
    }
    DIR.with(|dir| {
        let input = dir.path().join("input");
        match std::fs::remove_dir_all(&input) {
            Err(err) if err.kind() != std::io::ErrorKind::NotFound => panic!("cannot empty {}: {err}", input.display()),
            _ => {}
        }
        std::fs::create_dir(&input).expect("the fuzz directory is writable");
        f(&input)
    })
}

/// Linux's memory-backed file system, where each input's scene and the render's outputs (4–6
/// files created, written, synced and removed per input) cost no disk I/O: on a 2-vCPU VM with an
/// ext4 disk, CI's runs took 58 s (`scene_load`) and 478 s (`scene_shapes`) there against 164 s
/// and 626 s in `/tmp`.
/// Where it is missing or not writable, the system's temporary directory serves.
const RAM_TEMP_DIR: &str = "/dev/shm";

#[cfg(test)]
mod tests {
    use super::*;

    /// The seed inputs CI's `scene_render` run starts from (`fuzz/seed-render-corpus`) each
    /// render: seeds that stopped loading would leave that run where an empty corpus leaves it,
    /// short of the render.
    #[test]
    fn the_render_seeds_render() {
        let seeds = tempfile::tempdir().expect("a temporary directory");
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("seed-render-corpus");
        let status = std::process::Command::new("bash").arg(&script).arg(seeds.path()).status().expect("bash runs");
        assert!(status.success(), "{} failed: {status}", script.display());
        let mut names = Vec::new();
        for entry in std::fs::read_dir(seeds.path()).expect("the seeds' directory reads") {
            let path = entry.expect("an entry").path();
            let bytes = std::fs::read(&path).expect("a seed reads");
            assert!(render_input(&bytes), "{} did not render", path.display());
            names.push(path.file_name().expect("a name").to_string_lossy().into_owned());
        }
        names.sort();
        assert_eq!(names, ["emissive_quad", "lamp_occluder_floor", "tetrahedron"]);
    }
}
