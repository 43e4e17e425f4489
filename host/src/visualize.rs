//! Views of a frame for humans: the lit image tone-mapped to sRGB PNG or written as HDR OpenEXR,
//! and a shaded normal/depth view.

use crate::error::{Error, Result};
use crate::scene::Scene;
use crate::stream::{HitStream, RayStream};
use glam::{Vec3, Vec4Swizzles};
use image::{EncodableLayout, ImageBuffer, ImageFormat, PixelWithColorType, RgbImage};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, PoisonError};

/// The normal/depth view: each hit pixel shows its face-forward geometric normal mapped to colour
/// (`0.5 + 0.5·n`), darkened with distance so depth edges read; misses are black. `rays` and
/// `hits` come from one trace of `scene` over a `width × height` image; otherwise this panics,
/// like slice indexing.
pub fn normal_depth_image(scene: &Scene, rays: &RayStream, hits: &HitStream, width: u32, height: u32) -> RgbImage {
    let mut image = RgbImage::new(width, height);
    let t_max = hits.t.iter().copied().fold(f32::MIN_POSITIVE, f32::max);
    for i in 0..hits.len() {
        if hits.primitive[i] == raywave_shared::stream::NO_HIT {
            continue;
        }
        let view = rays.direction[i].xyz();
        let n = scene.hit_surface(hits.instance[i], hits.primitive[i], hits.barycentrics[i], view).normal;
        let depth_shade = 1.0 - 0.6 * (hits.t[i] / t_max);
        let colour = (Vec3::splat(0.5) + 0.5 * n) * depth_shade;
        let pixel = rays.pixel[i];
        let rgb = colour.to_array().map(|c| (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
        image.put_pixel(pixel % width, pixel / width, image::Rgb(rgb));
    }
    image
}

/// Linear radiance to an 8-bit sRGB image: each channel clamped to [0, 1] (exposure 1, no tone
/// curve, so values are comparable across renders; a channel of +∞ is full, −∞ and NaN are 0)
/// and encoded with the sRGB transfer function
/// (IEC 61966-2-1). `colors` is row-major, `width · height` long (shorter panics, like slice
/// indexing).
pub fn srgb_image(colors: &[Vec3], width: u32, height: u32) -> RgbImage {
    let encode = |c: f32| {
        let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
        let srgb = if c <= 0.003_130_8 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
        (srgb * 255.0 + 0.5) as u8
    };
    RgbImage::from_fn(width, height, |x, y| {
        let c = colors[(y * width + x) as usize];
        image::Rgb([encode(c.x), encode(c.y), encode(c.z)])
    })
}

/// An image file that appears only when complete: it is created as a temporary file beside the
/// destination (so an unwritable path fails before any work) and renamed over it when finished.
pub struct PendingOutput {
    path: PathBuf,
    format: ImageFormat,
    temp: PendingFile,
    /// The permissions of the regular file the output replaces, which it keeps; `None` for a new
    /// file, created with a new file's (`0o666` less the umask, on Unix).
    replaced: Option<std::fs::Permissions>,
}

impl PendingOutput {
    /// Reserves `path` for an image in `format`; fails with [`Error::Output`] if the file name's
    /// extension is not that format's (a `.jpg` holding PNG bytes would mislead every viewer), or
    /// if its directory is missing or not writable.
    pub fn create(path: &Path, format: ImageFormat) -> Result<Self> {
        let dir = directory_of(path);
        let output_error = |source| Error::Output { path: path.to_owned(), source };
        if ImageFormat::from_path(path).ok() != Some(format) {
            let extensions = format.extensions_str();
            let kind = extensions.first().map_or_else(|| format!("{format:?}"), |e| e.to_uppercase());
            let reason =
                format!("the file name must end in .{} (the image is written as {kind})", extensions.join(", ."));
            return Err(output_error(std::io::Error::new(std::io::ErrorKind::InvalidInput, reason)));
        }
        // `Path` drops a trailing separator or `.` (`y.png/` and `y.png/.` have the file name
        // `y.png`), but the rename at the end would fail on them, after all the work.
        let ends_in_its_name =
            path.file_name().is_some_and(|name| path.as_os_str().as_encoded_bytes().ends_with(name.as_encoded_bytes()));
        if path.is_dir() || !ends_in_its_name {
            return Err(output_error(std::io::Error::new(std::io::ErrorKind::IsADirectory, "names a directory")));
        }
        // Checked here: tempfile's error would name its random temporary file, not the output.
        if !dir.is_dir() {
            let (kind, reason) = if dir.exists() {
                (std::io::ErrorKind::NotADirectory, format!("{} is not a directory", dir.display()))
            } else {
                (std::io::ErrorKind::NotFound, format!("directory {} does not exist", dir.display()))
            };
            return Err(output_error(std::io::Error::new(kind, reason)));
        }
        // Not a symbolic link's: moving the output into place replaces the link itself.
        let replaced = path.symlink_metadata().ok().filter(std::fs::Metadata::is_file).map(|m| m.permissions());
        let temp = PendingFile::create_in(dir, replaced.is_none()).map_err(output_error)?;
        Ok(Self { path: path.to_owned(), format, temp, replaced })
    }

    /// Encodes linear radiance `colors` (row-major, `width · height`) as 32-bit float RGB in the
    /// output's format (OpenEXR keeps the HDR values) into the temporary file; see
    /// [`WrittenOutput`] for moving it into place. Any other number of colours is an
    /// [`Error::Encode`] naming both (`image` would have dropped the surplus silently).
    pub fn write_linear_rgb(self, colors: &[Vec3], width: u32, height: u32) -> Result<WrittenOutput> {
        let pixels = u64::from(width) * u64::from(height);
        let size_error = || {
            let message = format!("{} colours for a {width}×{height} image of {pixels} pixels", colors.len());
            Error::Encode { path: self.path.clone(), message }
        };
        if colors.len() as u64 != pixels {
            return Err(size_error());
        }
        let data: Vec<f32> = colors.iter().flat_map(|c| c.to_array()).collect();
        let image = image::Rgb32FImage::from_raw(width, height, data).ok_or_else(size_error)?;
        self.write_image(&image)
    }

    /// Encodes `image` (8-bit sRGB for PNG, 32-bit float for OpenEXR) in the output's format into
    /// the temporary file; see [`WrittenOutput`] for moving it into place.
    pub fn write_image<P>(self, image: &ImageBuffer<P, Vec<P::Subpixel>>) -> Result<WrittenOutput>
    where
        P: PixelWithColorType,
        [P::Subpixel]: EncodableLayout,
    {
        let mut encoded = std::io::Cursor::new(Vec::new());
        image
            .write_to(&mut encoded, self.format)
            .map_err(|e| Error::Encode { path: self.path.clone(), message: e.to_string() })?;
        self.write(encoded.get_ref())
    }

    /// [`PendingOutput::write_image`], then moves the file into place: for a job with one output.
    pub fn finish_image<P>(self, image: &ImageBuffer<P, Vec<P::Subpixel>>) -> Result<()>
    where
        P: PixelWithColorType,
        [P::Subpixel]: EncodableLayout,
    {
        self.write_image(image)?.persist()
    }

    /// Writes `bytes` to the temporary file and makes it an ordinary, durable file.
    fn write(mut self, bytes: &[u8]) -> Result<WrittenOutput> {
        let path = self.path.clone();
        let output_error = |source| Error::Output { path: path.clone(), source };
        let temp = &mut self.temp.temp;
        temp.write_all(bytes).map_err(output_error)?;
        temp.as_file().sync_all().map_err(output_error)?;
        // A replaced file's permissions, which had been widened to 0644 (and a new file's
        // narrowed umask ignored): its temporary file was created private (0600).
        if let Some(permissions) = self.replaced {
            temp.as_file().set_permissions(permissions).map_err(output_error)?;
        }
        Ok(WrittenOutput { path: self.path, temp: self.temp })
    }
}

/// An image written completely to its temporary file beside the destination, not yet in place.
/// A job with several outputs writes them all before it moves any ([`persist_all`]), so a
/// failure while encoding or writing one (a full disk, a directory removed meanwhile) leaves none
/// of them behind. Dropped, it deletes its temporary file.
#[derive(Debug)]
pub struct WrittenOutput {
    path: PathBuf,
    temp: PendingFile,
}

impl WrittenOutput {
    /// Renames the temporary file over the destination.
    pub fn persist(self) -> Result<()> {
        let _placing = lock(&PLACING);
        self.rename()
    }

    /// [`persist`](Self::persist), with [`PLACING`] held by the caller.
    fn rename(self) -> Result<()> {
        let PendingFile { temp, listed } = self.temp;
        let path = self.path;
        temp.persist(&path).map_err(|e| Error::Output { path: path.clone(), source: e.error })?;
        drop(listed);
        Ok(())
    }
}

/// Moves every output into place, in order. Should a rename fail, the outputs this call already
/// moved are removed again and the files they replaced put back (the remaining temporary files
/// are deleted when dropped), so a job's outputs appear all together or not at all — also when
/// the process is interrupted meanwhile ([`remove_pending_outputs`] waits until this returns).
pub fn persist_all(outputs: Vec<WrittenOutput>) -> Result<()> {
    let _placing = lock(&PLACING);
    let mut placed: Vec<(PathBuf, Option<tempfile::TempPath>)> = Vec::new();
    for output in outputs {
        let path = output.path.clone();
        let previous = keep_previous(&path);
        if let Err(err) = output.rename() {
            // Best effort: the error that matters is the one being returned.
            for (done, previous) in placed.into_iter().rev() {
                let _ = match previous {
                    Some(previous) => previous.persist(&done).map_err(|e| e.error),
                    None => std::fs::remove_file(&done),
                };
            }
            return Err(err);
        }
        placed.push((path, previous));
    }
    // Dropping `placed` deletes the second names of the replaced files.
    Ok(())
}

/// A second name, beside it, for the file now at `path` (deleted when dropped), so that
/// [`persist_all`] can put it back should a later output fail to move into place: a hard link,
/// or where the file system makes none, a copy of a regular file. `None` where there is no file
/// or neither works — the previous file is then removed with the new one.
fn keep_previous(path: &Path) -> Option<tempfile::TempPath> {
    keep_previous_by(path, |from, to| std::fs::hard_link(from, to))
}

/// [`keep_previous`], making the second name with `link`.
fn keep_previous_by(path: &Path, link: impl Fn(&Path, &Path) -> std::io::Result<()>) -> Option<tempfile::TempPath> {
    // A copy of a symbolic link would put back its target's contents as a file in its place.
    let regular = path.symlink_metadata().is_ok_and(|metadata| metadata.is_file());
    let kept = temporary_names().make_in(directory_of(path), |second| {
        // Not on `AlreadyExists`: the temporary name is taken, and `make_in` retries another.
        link(path, second).or_else(|err| match err.kind() {
            std::io::ErrorKind::AlreadyExists => Err(err),
            _ if regular => std::fs::copy(path, second).map(drop),
            _ => Err(err),
        })
    });
    kept.ok().map(tempfile::NamedTempFile::into_temp_path)
}

/// How this module names its temporary files beside an output: `.raywave-` and a random suffix,
/// hidden from directory listings.
fn temporary_names() -> tempfile::Builder<'static, 'static> {
    let mut builder = tempfile::Builder::new();
    builder.prefix(".raywave-");
    builder
}

/// The file an output `path` names, for telling whether two outputs name one file: its
/// directory resolved (`..`, symbolic links) joined with its file name, or the absolute path as
/// given where the directory cannot be resolved (it does not exist, and
/// [`PendingOutput::create`] refuses it). The file name itself is not resolved: moving the output
/// into place replaces a symbolic link there, not its target.
pub fn output_destination(path: &Path) -> PathBuf {
    let absolute = || std::path::absolute(path).unwrap_or_else(|_| path.to_owned());
    match (std::fs::canonicalize(directory_of(path)), path.file_name()) {
        (Ok(directory), Some(name)) => directory.join(name),
        _ => absolute(),
    }
}

/// The directory a file at `path` goes in (`.` for a bare file name).
fn directory_of(path: &Path) -> &Path {
    match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    }
}

/// The temporary files of this process's outputs that are not in place yet, by path.
static PENDING: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Held while outputs move into place, so that [`remove_pending_outputs`] never sees a job's
/// outputs half moved.
static PLACING: Mutex<()> = Mutex::new(());

/// Locks one of this module's registries. They hold only paths, which a panic elsewhere cannot
/// leave inconsistent, so a poisoned lock is used as it is.
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// An output's temporary file, listed in [`PENDING`] for as long as it exists.
#[derive(Debug)]
struct PendingFile {
    /// Declared first, so that a dropped file is deleted before it leaves the list.
    temp: tempfile::NamedTempFile,
    listed: Listed,
}

impl PendingFile {
    /// A new temporary file in `dir`, listed before anyone can see it: the list stays locked
    /// while the file is created, so [`remove_pending_outputs`] finds every file that exists.
    /// `as_new_file`: created with the permissions of any new file (on Unix `0o666` less the
    /// umask, as `File::create` makes it), else private (`0o600`) until given those of the file
    /// it replaces.
    fn create_in(dir: &Path, as_new_file: bool) -> std::io::Result<Self> {
        let mut names = temporary_names();
        #[cfg(unix)]
        if as_new_file {
            use std::os::unix::fs::PermissionsExt;
            names.permissions(std::fs::Permissions::from_mode(0o666));
        }
        #[cfg(not(unix))]
        let _ = as_new_file;
        let mut pending = lock(&PENDING);
        let temp = names.tempfile_in(dir)?;
        let path = temp.path().to_owned();
        pending.push(path.clone());
        Ok(Self { temp, listed: Listed(path) })
    }
}

/// A path in [`PENDING`], taken out of it when dropped.
#[derive(Debug)]
struct Listed(PathBuf);

impl Drop for Listed {
    fn drop(&mut self) {
        let mut pending = lock(&PENDING);
        if let Some(index) = pending.iter().position(|path| *path == self.0) {
            pending.swap_remove(index);
        }
    }
}

/// Deletes the temporary files of every output not yet in place — after waiting for outputs being
/// moved into place to get there — for a program about to end without unwinding: `raywave`
/// calls it when interrupted (Ctrl-C, `SIGTERM`, `SIGHUP`), which would otherwise leave a
/// `.raywave-…` file beside each output of the interrupted job. Until the returned guard is
/// dropped, no output can be created or moved into place (other threads trying wait): hold it
/// until the process ends.
#[must_use = "outputs may be created again once the guard is dropped"]
pub fn remove_pending_outputs() -> OutputsHeld {
    let placing = lock(&PLACING);
    let mut pending = lock(&PENDING);
    for path in pending.drain(..) {
        // Best effort: a file already gone is what was wanted.
        let _ = std::fs::remove_file(path);
    }
    OutputsHeld { _placing: placing, _pending: pending }
}

/// Returned by [`remove_pending_outputs`]: while it lives, no output is created or moved into
/// place.
pub struct OutputsHeld {
    _placing: MutexGuard<'static, ()>,
    _pending: MutexGuard<'static, Vec<PathBuf>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unwritable_output_fails_before_work_and_leaves_nothing() {
        let err = PendingOutput::create(Path::new("/nonexistent-dir/out.png"), ImageFormat::Png).err().unwrap();
        assert!(matches!(err, Error::Output { .. }), "{err}");
        assert!(!err.to_string().contains(".raywave-"), "names the output, not the temporary file: {err}");
        let dir = tempfile::tempdir().unwrap();
        assert!(PendingOutput::create(dir.path(), ImageFormat::Png).is_err(), "a directory is not a file");
        let png_dir = dir.path().join("frames.png");
        std::fs::create_dir(&png_dir).unwrap();
        assert!(PendingOutput::create(&png_dir, ImageFormat::Png).is_err(), "a directory named .png is not a file");
    }

    #[test]
    fn outputs_appear_together_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let (first, later) = (dir.path().join("a.png"), dir.path().join("sub"));
        std::fs::create_dir(&later).unwrap();
        let write = |path: &Path| {
            PendingOutput::create(path, ImageFormat::Png).unwrap().write_image(&RgbImage::new(2, 2)).unwrap()
        };
        let outputs = vec![write(&first), write(&later.join("b.png"))];
        assert!(!first.exists(), "written, not yet in place");
        // The second output's directory disappears before the job moves its files into place.
        std::fs::remove_dir_all(&later).unwrap();
        let err = persist_all(outputs).unwrap_err();
        assert!(matches!(err, Error::Output { ref path, .. } if path.ends_with("sub/b.png")), "{err}");
        assert!(!first.exists(), "the first output was taken back");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "no temporary file left either");
        let second = dir.path().join("b.png");
        persist_all(vec![write(&first), write(&second)]).unwrap();
        assert!(first.exists() && second.exists());
    }

    /// A job that fails part-way leaves the files its outputs were to replace as they were —
    /// the one already replaced put back — and no temporary file or second name.
    #[test]
    fn a_failed_job_puts_back_the_files_it_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let (first, second, later) = (dir.path().join("a.png"), dir.path().join("b.png"), dir.path().join("sub"));
        std::fs::write(&first, b"previous a").unwrap();
        std::fs::write(&second, b"previous b").unwrap();
        std::fs::create_dir(&later).unwrap();
        let write = |path: &Path| {
            PendingOutput::create(path, ImageFormat::Png).unwrap().write_image(&RgbImage::new(2, 2)).unwrap()
        };
        let outputs = vec![write(&first), write(&second), write(&later.join("c.png"))];
        std::fs::remove_dir_all(&later).unwrap();
        assert!(persist_all(outputs).is_err());
        assert_eq!(std::fs::read(&first).unwrap(), b"previous a");
        assert_eq!(std::fs::read(&second).unwrap(), b"previous b");
        let names = |dir: &Path| {
            let mut names: Vec<_> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name()).collect();
            names.sort();
            names
        };
        assert_eq!(names(dir.path()), ["a.png", "b.png"]);
        // Succeeding, the job replaces them and leaves no second name behind.
        persist_all(vec![write(&first), write(&second)]).unwrap();
        assert!(std::fs::read(&first).unwrap().starts_with(b"\x89PNG"));
        assert_eq!(names(dir.path()), ["a.png", "b.png"]);
    }

    /// Where the file system makes no hard links (FAT, some network shares), the previous file
    /// is kept as a copy: a failed job then removed it with the new one.
    #[test]
    fn the_previous_file_is_copied_where_no_hard_link_can_be_made() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        let no_links = |_: &Path, _: &Path| Err(std::io::Error::from(std::io::ErrorKind::Unsupported));
        assert!(keep_previous_by(&path, no_links).is_none(), "no file, nothing to keep");
        std::fs::write(&path, b"previous").unwrap();
        let kept = keep_previous_by(&path, no_links).expect("a copy");
        std::fs::write(&path, b"new").unwrap();
        assert_eq!(std::fs::read(&kept).unwrap(), b"previous", "a copy, not a second name of the new file");
        kept.persist(&path).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"previous");
        // A temporary name already taken is not copied over: another name is tried.
        let first = std::cell::RefCell::new(None);
        let taken_once = |_: &Path, second: &Path| {
            if first.borrow().is_some() {
                return Err(std::io::Error::from(std::io::ErrorKind::Unsupported));
            }
            std::fs::write(second, b"someone else's")?;
            first.replace(Some(second.to_owned()));
            Err(std::io::Error::from(std::io::ErrorKind::AlreadyExists))
        };
        let kept = keep_previous_by(&path, taken_once).expect("a copy under another name");
        let first = first.take().unwrap();
        assert_ne!(kept.to_path_buf(), first);
        assert_eq!(std::fs::read(&first).unwrap(), b"someone else's", "the taken name was overwritten");
        assert_eq!(std::fs::read(&kept).unwrap(), b"previous");
        drop(kept);
        #[cfg(unix)]
        {
            // Not a symbolic link, whose copy would be its target's contents.
            let link = dir.path().join("link.png");
            std::os::unix::fs::symlink(&path, &link).unwrap();
            assert!(keep_previous_by(&link, no_links).is_none());
        }
    }

    #[test]
    fn output_appears_only_on_finish() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.png");
        let pending = PendingOutput::create(&path, ImageFormat::Png).unwrap();
        assert!(!path.exists());
        pending.finish_image(&RgbImage::new(2, 2)).unwrap();
        assert!(path.exists());
        drop(dir);
    }

    /// A finished image has the permissions of any new file (the umask's, where it had been 0644
    /// whatever the umask), and one that replaces a file keeps that file's (a private image had
    /// become readable by everyone).
    #[cfg(unix)]
    #[test]
    fn an_output_has_a_new_files_permissions_or_keeps_the_replaced_files() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let mode = |path: &Path| std::fs::metadata(path).unwrap().permissions().mode() & 0o7777;
        let reference = dir.path().join("reference.png");
        std::fs::File::create(&reference).unwrap();
        let path = dir.path().join("out.png");
        PendingOutput::create(&path, ImageFormat::Png).unwrap().finish_image(&RgbImage::new(2, 2)).unwrap();
        assert_eq!(mode(&path), mode(&reference), "a new file's permissions");
        for private in [0o600, 0o640, 0o604] {
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(private)).unwrap();
            PendingOutput::create(&path, ImageFormat::Png).unwrap().finish_image(&RgbImage::new(2, 2)).unwrap();
            assert_eq!(mode(&path), private, "the replaced file's permissions");
        }
    }

    #[test]
    fn file_name_must_carry_the_format_extension() {
        let dir = tempfile::tempdir().unwrap();
        for (name, format) in
            [("out.jpg", ImageFormat::Png), ("out", ImageFormat::Png), ("out.png", ImageFormat::OpenExr)]
        {
            let err = PendingOutput::create(&dir.path().join(name), format).err().expect(name);
            assert!(matches!(err, Error::Output { .. }) && err.to_string().contains("must end in ."), "{name}: {err}");
            let kind = if format == ImageFormat::Png { "written as PNG" } else { "written as EXR" };
            assert!(err.to_string().contains(kind), "{name}: {err}");
        }
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "nothing created");
        let exr = dir.path().join("OUT.EXR");
        let pending = PendingOutput::create(&exr, ImageFormat::OpenExr).expect("upper-case extension");
        pending.write_linear_rgb(&[Vec3::new(0.5, 2.0, 1e3)], 1, 1).unwrap().persist().unwrap();
        let read = image::open(&exr).unwrap().into_rgb32f();
        assert_eq!(read.get_pixel(0, 0).0, [0.5, 2.0, 1e3], "HDR values survive");
        // Too many colours or too few: refused, naming both counts.
        for colors in [&[Vec3::ONE; 3][..], &[Vec3::ONE; 1]] {
            let pending = PendingOutput::create(&dir.path().join("sized.exr"), ImageFormat::OpenExr).unwrap();
            let err = pending.write_linear_rgb(colors, 2, 1).expect_err("refused");
            let message = format!("{} colours for a 2×1 image of 2 pixels", colors.len());
            assert!(matches!(err, Error::Encode { .. }) && err.to_string().contains(&message), "{err}");
        }
    }

    #[test]
    fn normal_depth_view_faces_normals_to_the_ray_shades_depth_and_places_pixels() {
        use crate::scene::{Camera, Material, Mesh, Scene};
        use glam::{Vec2, Vec4};
        use raywave_shared::stream::NO_HIT;
        // One square in the plane z = 0, its winding facing +z.
        let square = Mesh {
            name: "square".into(),
            positions: vec![
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(-1.0, 1.0, 0.0),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            material: Material::diffuse(Vec3::ONE),
        };
        let camera =
            Camera { position: Vec3::Z, look_at: Vec3::ZERO, up: Vec3::Y, vertical_fov_degrees: 40.0, mirrored: false };
        let scene = Scene::new("square", vec![square], camera).expect("scene");
        // A 3 × 2 image whose rays come in a shuffled pixel order: from the front at t = 1 and at
        // t = 2 (the farthest hit), from behind at t = 2, and three misses.
        let (down, up) = (Vec4::new(0.0, 0.0, -1.0, 10.0), Vec4::new(0.0, 0.0, 1.0, 10.0));
        let rays = RayStream {
            origin: vec![Vec4::ZERO; 6],
            direction: vec![down, up, down, up, down, down],
            pixel: vec![4, 0, 5, 1, 3, 2],
        };
        let hits = HitStream {
            t: vec![1.0, 2.0, 2.0, 0.0, 0.0, 0.0],
            primitive: vec![0, 1, 1, NO_HIT, NO_HIT, NO_HIT],
            instance: vec![0, 0, 0, NO_HIT, NO_HIT, NO_HIT],
            barycentrics: vec![Vec2::splat(0.25); 6],
        };
        let image = normal_depth_image(&scene, &rays, &hits, 3, 2);
        let at = |pixel: u32| image.get_pixel(pixel % 3, pixel / 3).0;
        // Colour (0.5 + 0.5·n)·(1 − 0.6·t/t_max), rounded: the front face +z at t = 1 is
        // (0.35, 0.35, 0.7); +z at t = 2 is (0.2, 0.2, 0.4); seen from behind, −z at t = 2, (0.2, 0.2, 0).
        assert_eq!(at(4), [89, 89, 179]);
        assert_eq!(at(5), [51, 51, 102]);
        assert_eq!(at(0), [51, 51, 0]);
        for miss in [1, 2, 3] {
            assert_eq!(at(miss), [0, 0, 0], "pixel {miss} missed");
        }
    }

    #[test]
    fn srgb_encoding_clamps_and_follows_the_transfer_function() {
        let infinite = Vec3::new(f32::INFINITY, f32::NEG_INFINITY, 0.0);
        let colors = [Vec3::new(0.0, 1.0, 0.5), Vec3::new(-1.0, 7.0, f32::NAN), Vec3::splat(0.002), infinite];
        let image = srgb_image(&colors, 2, 2);
        assert_eq!(image.get_pixel(0, 0).0, [0, 255, 188]); // 0.5 → 0.7354 → 188
        assert_eq!(image.get_pixel(1, 0).0, [0, 255, 0]);
        assert_eq!(image.get_pixel(0, 1).0, [7, 7, 7]); // linear segment: 12.92·0.002 → 6.6
        assert_eq!(image.get_pixel(1, 1).0, [255, 0, 0], "+∞ is clamped to white, not taken for NaN");
    }

    /// Whether the temporary file at `path` is listed for [`remove_pending_outputs`].
    fn listed(path: &Path) -> bool {
        lock(&PENDING).iter().any(|pending| pending == path)
    }

    /// A temporary file is listed from its creation until it is moved into place or dropped, and
    /// no longer (other tests list their own files meanwhile, so only these are checked).
    #[test]
    fn temporary_files_are_listed_while_they_exist() {
        let dir = tempfile::tempdir().unwrap();
        let create = |name: &str| PendingOutput::create(&dir.path().join(name), ImageFormat::Png).unwrap();
        let (kept, dropped, failed) = (create("kept.png"), create("dropped.png"), create("failed.png"));
        let paths = [&kept, &dropped, &failed].map(|output| output.temp.temp.path().to_owned());
        assert!(paths.iter().all(|path| listed(path)));
        let written = kept.write_image(&RgbImage::new(2, 2)).unwrap();
        assert!(listed(&paths[0]), "written, not yet in place");
        written.persist().unwrap();
        drop(dropped);
        let failed = failed.write_image(&RgbImage::new(2, 2)).unwrap();
        std::fs::remove_dir_all(dir.path()).unwrap();
        assert!(failed.persist().is_err(), "its directory is gone");
        assert!(!paths.iter().any(|path| listed(path)), "unlisted once moved, dropped or failed");
    }

    #[test]
    fn dropped_output_leaves_no_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.png");
        drop(PendingOutput::create(&path, ImageFormat::Png).unwrap());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
