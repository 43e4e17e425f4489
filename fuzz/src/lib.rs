//! What the fuzz targets share: turning the fuzzer's bytes into scene files.

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

/// A temporary directory for one fuzzing process, created on first use and reused by every input.
pub fn with_scratch_dir<T>(f: impl FnOnce(&Path) -> T) -> T {
    thread_local! {
        static DIR: tempfile::TempDir = tempfile::tempdir().expect("a temporary directory");
    }
    DIR.with(|dir| f(dir.path()))
}
