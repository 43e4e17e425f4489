//! Wavefront OBJ scenes (through the `tobj` crate): every OBJ model (object, or part of one with
//! its own `usemtl` material) becomes a mesh with the material of its MTL entry, and the camera
//! frames the scene's bounds. Polylines (`l`) are skipped: they have no area; so are vertex
//! colours, which raywave does not use.

use super::line_counter::LineCounter;
use super::regular_file::read_regular_file;
use super::{framing_camera, Material, Mesh, Scene, Unrendered, MAX_COORDINATE, MAX_TRIANGLES, MAX_VERTICES};
use crate::error::{Error, Result};
use glam::{DVec3, Vec3};
use std::borrow::Cow;
use std::cell::RefCell;
use std::path::{Path, PathBuf};

/// Albedo of meshes without a material (no `usemtl`, or an MTL entry without `Kd`).
const DEFAULT_ALBEDO: Vec3 = Vec3::splat(0.7);

/// Loads and validates an OBJ file and the material library (`mtllib`) it names.
pub fn load(path: &Path) -> Result<Scene> {
    let load_error = |message: String| Error::SceneLoad { path: path.to_owned(), message };
    // Opened here first: tobj reports any failure to open as a bare "open file failed". Only a
    // regular file: opening a FIFO blocks, and a device such as /dev/zero never ends.
    if path.is_dir() {
        return Err(load_error("is a directory".into()));
    }
    let bytes = read_regular_file(path, u64::MAX).map_err(|e| load_error(e.to_string()))?;
    // Every check below reads the text tobj reads.
    let text = as_read(without_byte_order_mark(&bytes)).map_err(load_error)?;
    check_vertices_and_indices(path, &text, Limits { positions: MAX_VERTICES, triangles: MAX_TRIANGLES })?;
    check_polygon_fans(&text).map_err(load_error)?;
    let options = tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() };
    // tobj reads line by line and stops at its first error, so the reader's line is the one at fault.
    let mut reader = LineCounter::new(&text[..]);
    let directory = path.parent().unwrap_or(Path::new(""));
    // tobj's material-library errors carry no text of their own: the first one's is kept here.
    // And the libraries each `mtllib` line read, each with the number of materials it added, in
    // order, which the materials' errors name.
    let library_error = RefCell::new(None);
    let libraries: RefCell<Vec<Vec<(PathBuf, usize)>>> = RefCell::new(Vec::new());
    // The library that defines each material name (a library named twice may define it twice).
    let defined_in: RefCell<std::collections::HashMap<String, PathBuf>> = RefCell::default();
    let load_library = |library: PathBuf| {
        let fail = |message: String| {
            library_error.borrow_mut().get_or_insert_with(|| format!("{}: {message}", library.display()));
        };
        let text = match read_material_library(&library) {
            Ok(text) => text,
            Err(message) => {
                fail(message);
                return Err(tobj::LoadError::MaterialParseError);
            }
        };
        let mut lines = LineCounter::new(text.as_bytes());
        let loaded = tobj::load_mtl_buf(&mut lines).inspect_err(|e| fail(format!("line {}: {e}", lines.line())))?;
        // tobj would give a name two libraries define the later library's material (one file
        // named twice, even as `a.mtl` and `./a.mtl`, is one definition).
        let mut defined_in = defined_in.borrow_mut();
        let same_file =
            |a: &Path, b: &Path| a == b || a.canonicalize().ok().is_some_and(|a| b.canonicalize().ok() == Some(a));
        for m in &loaded.0 {
            match defined_in.get(&m.name) {
                Some(earlier) if !same_file(earlier, &library) => {
                    fail(format!("material `{}` is defined in {} too", m.name, earlier.display()));
                    return Err(tobj::LoadError::MaterialParseError);
                }
                _ => defined_in.insert(m.name.clone(), library.clone()),
            };
        }
        Ok((library, loaded))
    };
    let (models, materials) = tobj::load_obj_buf(&mut reader, &options, |named| {
        // One line's libraries as one, each library's indices after those before it, as tobj
        // merges the libraries of successive lines.
        let (mut line, mut merged): (_, Option<(Vec<tobj::Material>, _)>) = (Vec::new(), None);
        for library in library_paths(directory, named) {
            let (library, (mut materials, names)) = load_library(library)?;
            line.push((library, materials.len()));
            match &mut merged {
                None => merged = Some((materials, names)),
                Some((all, all_names)) => {
                    let offset = all.len();
                    all.append(&mut materials);
                    all_names.extend(names.into_iter().map(|(name, index)| (name, index + offset)));
                }
            }
        }
        libraries.borrow_mut().push(line);
        Ok(merged.unwrap_or_default())
    })
    .map_err(|e| load_error(locate(e, reader.line())))?;
    // A library that cannot be read would leave every mesh grey and every light dark — also when
    // another library loads, whose materials tobj then returns without a word.
    let materials = match (materials, library_error.take()) {
        (Ok(materials), None) => materials,
        (result, reason) => {
            let reason = reason.or_else(|| result.err().map(|e| e.to_string())).unwrap_or_default();
            return Err(load_error(format!("the material library its `mtllib` line names cannot be loaded: {reason}")));
        }
    };
    let libraries = libraries.into_inner();
    check_material_names(&text, &libraries, &materials).map_err(load_error)?;
    // Each MTL entry as a material, checked once, naming its library (tobj appends each
    // library's materials in the order read).
    let library_of = libraries.iter().flatten().flat_map(|(library, count)| std::iter::repeat_n(library, *count));
    let mut converted = Vec::with_capacity(materials.len());
    for (m, library) in materials.iter().zip(library_of) {
        let material = mtl_material(m)
            .map_err(|reason| load_error(format!("{}: material `{}`: {reason}", library.display(), m.name)))?;
        converted.push(material);
    }
    let meshes_whose_material = |property: fn(&tobj::Material) -> bool| {
        models
            .iter()
            .filter(|model| model.mesh.material_id.and_then(|id| materials.get(id)).is_some_and(property))
            .count()
    };
    let unrendered = Unrendered {
        textured_meshes: meshes_whose_material(has_textures),
        see_through_meshes: meshes_whose_material(is_see_through),
        ..Unrendered::default()
    };
    let meshes: Vec<Mesh> = models
        .into_iter()
        .enumerate()
        .map(|(i, model)| {
            // tobj names objects without an `o`/`g` line "unnamed_object".
            let object =
                if model.name.is_empty() || model.name == "unnamed_object" { format!("mesh {i}") } else { model.name };
            let entry = model.mesh.material_id.and_then(|id| Some((&materials.get(id)?.name, *converted.get(id)?)));
            Mesh {
                name: entry.map_or_else(|| object.clone(), |(name, _)| format!("{object} ({name})")),
                positions: model.mesh.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])).collect(),
                triangles: model.mesh.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
                material: entry.map_or(Material::diffuse(DEFAULT_ALBEDO), |(_, material)| material),
            }
        })
        .collect();
    let name = path.display().to_string();
    let camera = framing_camera(&meshes);
    Ok(Scene::new(&name, meshes, camera)?.with_unrendered(unrendered))
}

/// `bytes` without a leading [`super::UTF8_BYTE_ORDER_MARK`], which Windows editors write: kept,
/// it made the first line's keyword one that no reader knows (an OBJ's `mtllib`, an MTL's
/// `newmtl`), and the file failed on a later line for want of it.
fn without_byte_order_mark(bytes: &[u8]) -> &[u8] {
    bytes.strip_prefix(super::UTF8_BYTE_ORDER_MARK).unwrap_or(bytes)
}

/// The OBJ `text` as raywave reads it, line numbers kept — what tobj parses and every check
/// reads. Real files write what tobj 4.0.5 refuses or misreads, where tinyobjloader and the
/// format read them (tinyobjloader's own regression files among them):
/// - a trailing `#` comment on a line of numbers (`v`, `vt`, `vn`, `f`) cut off: tobj took its
///   words for data (`v 1 2 3 # top` failed as a colour, `f 1 2 3 # cap` as a face). Not on a
///   line that names something (`usemtl`, `mtllib`, `o`, `g`), whose name may hold a `#`
///   (`usemtl Material #25`);
/// - a line naming something (`mtllib`, `usemtl`, `o`, `g`) that is indented or separates its
///   keyword by a tab written `keyword name`: tobj takes the name after the line's first space,
///   so `usemtl<TAB>lamp` failed and an indented `usemtl lamp` named the material `usemtl lamp`;
///   an `mtllib` or `usemtl` naming nothing is an error here (tobj had looked for a library named
///   by the folder);
/// - texture coordinates and normals, which raywave does not read, kept only as places for the
///   faces' indices where tobj would refuse them: `vt u` (the format's `v` defaults to 0) as
///   `vt u 0`, and a `vt` or `vn` whose numbers are too few or do not parse (MSVC writes NaN as
///   `-1.#IND`) as `vt 0 0` or `vn 0 0 1`;
/// - a comment line that is not UTF-8 text (an old file's Latin-1 `# Créé`) blanked: tobj reads
///   lines as UTF-8 and refused the file;
/// - polylines (`l`) blanked: tobj 4.0.5 reads them as faces, so `l 1 2 3 4` around a square
///   became a filled quad (under an emissive material, a quad light), and a polyline has no area
///   for a ray to hit;
/// - vertex colours (`v x y z r g b`) cut off: raywave does not use them, and tobj refused a file
///   that gives some vertices colours and others none ("face vertex color index out of bounds");
/// - a vertex's weight (`v x y z w`) cut off: the OBJ format gives it only to rational curves and
///   surfaces, meaningless for a polygon's vertex (tinyobjloader ignores it), and tobj divided
///   the position by it — `v 1 1 1 2` was at (0.5, 0.5, 0.5), `w` = 0 infinitely far.
///
/// Borrowed where no line changes. An error names the line.
fn as_read(text: &[u8]) -> std::result::Result<Cow<'_, [u8]>, String> {
    // The rewritten text once a line has changed: the lines before it, then every line.
    let mut rewritten: Option<Vec<u8>> = None;
    let mut start = 0;
    for (index, line) in text.split(|&b| b == b'\n').enumerate() {
        let new = line_as_read(line).map_err(|reason| format!("line {}: {reason}", index + 1))?;
        match (&mut rewritten, new) {
            (None, None) => {}
            (None, Some(new)) => {
                let mut kept = Vec::with_capacity(text.len());
                kept.extend_from_slice(&text[..start]);
                kept.extend_from_slice(&new);
                rewritten = Some(kept);
            }
            (Some(kept), new) => {
                kept.push(b'\n');
                kept.extend_from_slice(new.as_deref().unwrap_or(line));
            }
        }
        start += line.len() + 1;
    }
    Ok(rewritten.map_or(Cow::Borrowed(text), Cow::Owned))
}

/// One line of an OBJ file as [`as_read`] gives it to tobj: `None` where it stays as it is. A
/// rewritten line is the line cut short (borrowed), or a few words: no list of its words is made,
/// since the file's size is checked after this ([`check_vertices_and_indices`]: a face line of
/// 3·10⁸ corners had taken gigabytes).
fn line_as_read(line: &[u8]) -> std::result::Result<Option<Cow<'_, [u8]>>, String> {
    let text = String::from_utf8_lossy(line);
    let mut words = text.split_whitespace();
    let Some(keyword) = words.next() else { return Ok(None) };
    if keyword.starts_with('#') {
        // Blanked where it is not UTF-8 text (an old file's Latin-1): tobj refused the file.
        return Ok(matches!(text, Cow::Owned(_)).then_some(Cow::Borrowed(&[])));
    }
    // The first few words before any comment, and the line cut before the comment or after a word.
    let head: Vec<&str> = before_comment(words.clone()).take(7).collect();
    let numbers = |count: usize| head.len() >= count && head[..count].iter().all(|w| w.parse::<f32>().is_ok());
    let offset = |word: &str| word.as_ptr() as usize - text.as_ptr() as usize;
    let cut = |end: usize| match &text {
        Cow::Borrowed(_) => Cow::Borrowed(&line[..end]),
        Cow::Owned(text) => Cow::Owned(text.as_bytes()[..end].to_vec()),
    };
    let through = |word: &str| Some(cut(offset(word) + word.len()));
    let uncommented = || words.clone().find(|w| w.starts_with('#')).map(|c| cut(text[..offset(c)].trim_end().len()));
    Ok(match keyword {
        "l" => Some(Cow::Borrowed(&[][..])),
        // Colours or a weight after the position (every word a number).
        "v" if matches!(head.len(), 4 | 6) && numbers(head.len()) => through(head[2]),
        "v" | "f" => uncommented(),
        "vt" if numbers(2) => uncommented(),
        "vt" if numbers(1) => Some(Cow::Owned(format!("vt {} 0", head[0]).into_bytes())),
        "vt" => Some(Cow::Borrowed(&b"vt 0 0"[..])),
        "vn" if numbers(3) => uncommented(),
        "vn" => Some(Cow::Borrowed(&b"vn 0 0 1"[..])),
        "mtllib" | "usemtl" | "o" | "g" => {
            let name = text.trim_start()[keyword.len()..].trim();
            if name.is_empty() && matches!(keyword, "mtllib" | "usemtl") {
                return Err(format!("`{keyword}` names nothing"));
            }
            // tobj takes the name after the line's first space.
            let as_tobj_reads = text.strip_prefix(keyword).is_some_and(|rest| rest.starts_with(' '));
            if as_tobj_reads || name.is_empty() {
                None
            } else {
                Some(Cow::Owned(format!("{keyword} {name}").into_bytes()))
            }
        }
        _ => None,
    })
}

/// The material libraries an `mtllib` line names, `named` the rest of the line (as tobj 4.0.5
/// reads it, so that a name may hold spaces or a `#`), each under `directory`: that one file where
/// it is one, else each of its words before any `#` comment — the OBJ format's `mtllib filename1
/// filename2 ...`, which tobj had read as one name and refused.
fn library_paths(directory: &Path, named: &Path) -> Vec<PathBuf> {
    let whole = directory.join(named);
    let words: Vec<&str> =
        named.to_str().map_or_else(Vec::new, |named| before_comment(named.split_whitespace()).collect());
    if words.is_empty() || whole.is_file() {
        return vec![whole];
    }
    words.into_iter().map(|word| directory.join(word)).collect()
}

/// The text of the material library at `path`, less a leading byte-order mark
/// ([`without_byte_order_mark`]), or why it cannot be used: the OS's reason, not a regular file,
/// or the line at fault — one that is not UTF-8 text, or a colour (`Ka`, `Kd`, `Ks`, `Ke`) with
/// other than one or three words (before any trailing `#` comment), refused here before tobj
/// parses the text: tobj 4.0.5 panics on fewer than three (found by fuzzing the loader) and ignores
/// what follows the third. One number is a grey, `Kd 0.5` as `Kd 0.5 0.5 0.5`, as the MTL
/// format says (g and b default to r), written out so here for tobj. Also refused, because tobj
/// would drop them without a word: a property before the first `newmtl` (it belongs to no
/// material), and a material name defined twice (the later definition would hide the earlier);
/// and an `Ns` that is not one finite number ≥ 0 (a Phong exponent, [`mtl_material`]), which tobj
/// takes from its first word and the roughness had taken a negative one as 0.
fn read_material_library(path: &Path) -> std::result::Result<String, String> {
    let bytes = read_regular_file(path, u64::MAX).map_err(|e| e.to_string())?;
    let bytes = without_byte_order_mark(&bytes);
    let text = std::str::from_utf8(bytes).map_err(|e| {
        let valid = &bytes[..e.valid_up_to()];
        format!("line {}: not UTF-8 text", 1 + valid.iter().filter(|&&b| b == b'\n').count())
    })?;
    let mut defined: std::collections::HashMap<&str, usize> = std::collections::HashMap::new();
    let mut kept = String::with_capacity(text.len());
    for (index, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let key = words.next();
        let arguments: Vec<&str> = before_comment(words).collect();
        match (key, &arguments[..]) {
            (Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")), [grey]) => kept.push_str(&format!("{key} {grey} {grey} {grey}")),
            _ => kept.push_str(line),
        }
        kept.push('\n');
        match key {
            Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) if ![1, 3].contains(&arguments.len()) => {
                return Err(format!(
                    "line {}: `{key}` needs three numbers (or one, a grey), not {}",
                    index + 1,
                    arguments.len()
                ));
            }
            Some("Ns") if !is_exponent(&arguments) => {
                return Err(format!(
                    "line {}: `Ns {}`: the specular exponent must be one finite number ≥ 0",
                    index + 1,
                    arguments.join(" ")
                ));
            }
            Some("newmtl") => {
                let name = line.trim_start()["newmtl".len()..].trim();
                if let Some(first) = defined.insert(name, index + 1) {
                    return Err(format!(
                        "line {}: material `{name}` is defined again (first on line {first})",
                        index + 1
                    ));
                }
            }
            Some(key) if defined.is_empty() && !key.starts_with('#') => {
                return Err(format!("line {}: `{key}` before the first `newmtl` belongs to no material", index + 1));
            }
            _ => {}
        }
    }
    Ok(kept)
}

/// The words of a line before any trailing `#` comment (`Kd 1 1 1 # red`): of an MTL line, which
/// tobj reads past for the keys it parses itself, and raywave for `Pr` and `Pm`
/// ([`mtl_material`]); of an OBJ line of numbers ([`as_read`]).
fn before_comment<'a>(words: impl Iterator<Item = &'a str>) -> impl Iterator<Item = &'a str> {
    words.take_while(|word| !word.starts_with('#'))
}

/// Whether `words`, those after an MTL `Ns`, are one Phong exponent: a finite number ≥ 0.
fn is_exponent(words: &[&str]) -> bool {
    matches!(words, [ns] if ns.parse::<f32>().is_ok_and(|ns| ns.is_finite() && ns >= 0.0))
}

/// tobj's error `error`, raised while its reader was in line `line`, with that line: the line at
/// fault for the errors of one line (a number that does not parse, a malformed face), or the
/// line that closed the object whose faces index past the data defined by then (tobj checks them
/// as it closes an object: at the next `o`, `g` or `usemtl` line, or at the end of the file; an
/// index past the whole file's data was refused before, naming its face's line).
fn locate(error: tobj::LoadError, line: usize) -> String {
    use tobj::LoadError::{
        FaceColorOutOfBounds, FaceNormalOutOfBounds, FaceTexCoordOutOfBounds, FaceVertexOutOfBounds, InvalidPolygon,
        ReadError,
    };
    match error {
        FaceVertexOutOfBounds
        | FaceTexCoordOutOfBounds
        | FaceNormalOutOfBounds
        | FaceColorOutOfBounds
        | InvalidPolygon => format!("{error} in a face of the object closed at line {line}"),
        // tobj reads lines as UTF-8 and drops the I/O error, which for a file it could open is
        // almost always that one.
        ReadError => format!("line {line}: {error} (not UTF-8 text, or the file could not be read)"),
        _ => format!("line {line}: {error}"),
    }
}

/// Whether MTL entry `m` has a texture that would change its colour, roughness, metalness or
/// emission (`map_Kd`, `map_Ke`, `map_Pr`, `map_Pm`), which raywave does not sample
/// ([`Unrendered::textured_meshes`]).
fn has_textures(m: &tobj::Material) -> bool {
    m.diffuse_texture.is_some() || ["map_Ke", "map_Pr", "map_Pm"].iter().any(|key| m.unknown_param.contains_key(*key))
}

/// Whether MTL entry `m` lets light through somewhere (a dissolve `d` below 1, or a `map_d`),
/// which raywave does not render ([`Unrendered::see_through_meshes`]). Without a `d`, a
/// transparency `Tr` strictly between 0 and 1 does too: exporters write `Tr` as `1 − d`
/// (tinyobjloader reads it so, where `d` is missing) or, in older ones, as `d` itself, so only
/// the ends 0 and 1 are in doubt (opaque or invisible).
fn is_see_through(m: &tobj::Material) -> bool {
    let transparency = || {
        let value = m.unknown_param.get("Tr")?;
        before_comment(value.split_whitespace()).next()?.parse::<f32>().ok()
    };
    m.dissolve.is_some_and(|d| d < 1.0)
        || m.dissolve_texture.is_some()
        || (m.dissolve.is_none() && transparency().is_some_and(|tr| tr > 0.0 && tr < 1.0))
}

/// Checks the OBJ `text` before tobj reads it, naming the line at fault (tobj's vertex numbers
/// are not the file's, so [`Scene::new`]'s errors could not name it):
/// - every index of the faces (`f`) is not 0 (indices are 1-based), not past 2³²,
///   a negative (relative) one within the vertex data (`v`, `vt`, `vn`) defined before it, and
///   a positive one within the whole file's data of its kind.
///   tobj 4.0.5 turns `0` and relative indices past the start into indices near `usize::MAX` and
///   multiplies them, which overflows — a panic where overflow checks are on (debug and test
///   builds);
/// - no face corner leaves its vertex position number out (`f /1/2 …`): tobj keeps such corners
///   and fails the file only when it closes the object, and [`GeometryCount`], which counts
///   position numbers, would not have counted them;
/// - every vertex position (`v`) a face uses has coordinates finite and within
///   [`MAX_COORDINATE`]. Vertices no face uses are
///   not loaded (tobj keeps the used ones), so they may hold anything;
/// - the file has at most `limits.positions` vertex positions and makes at most
///   `limits.triangles` triangles ([`GeometryCount`]), counted before anything is built (an
///   [`Error::SceneTooLarge`] naming the line where the count passes its limit): a 600 MB face
///   line of 3·10⁸ corners had tobj allocate gigabytes of indices until memory ran out, where a
///   glTF file that large is counted first. tobj may still make more vertices than `v` lines
///   (one per distinct position, texture and normal index), which [`Scene::new`] counts.
///
/// Other tokens that are not numbers are left to tobj, which reports them. Other errors are
/// [`Error::SceneLoad`]s naming the line.
fn check_vertices_and_indices(path: &Path, text: &[u8], limits: Limits) -> Result<()> {
    let load_error = |message: String| Error::SceneLoad { path: path.to_owned(), message };
    // Per vertex out of range, by its position's number (0-based): its line and first bad
    // coordinate. A map, so that checking a million faces against many such vertices stays linear.
    let mut out_of_range: std::collections::HashMap<i64, (usize, f32)> = std::collections::HashMap::new();
    let mut count = GeometryCount::default();
    let mut too_large = None;
    let walked = each_vertex_and_index(text, |line, token| {
        count.add(line, &token);
        if let Some(what) = count.excess(limits) {
            too_large = Some(format!("{what} (passed at line {line})"));
            return Err(String::new());
        }
        if let ObjToken::Vertex(vertex, words) = token {
            if let Some(c) = coordinates(words).into_iter().find(|c| !(c.is_finite() && c.abs() <= MAX_COORDINATE)) {
                out_of_range.insert(vertex, (line, c));
            }
        }
        Ok(())
    });
    if let Some(what) = too_large {
        return Err(Error::SceneTooLarge { scene: path.display().to_string(), what });
    }
    walked.map_err(load_error)?;
    if out_of_range.is_empty() {
        return Ok(());
    }
    let lines: Vec<&[u8]> = text.split(|&b| b == b'\n').collect();
    each_vertex_and_index(text, |face_line, token| match token {
        ObjToken::Index { kind: 0, vertex } => match out_of_range.get(&vertex) {
            Some(&(line, c)) => Err(format!(
                "line {line}: `{}` has coordinate {c}; each must be finite and within ±{MAX_COORDINATE:e} (the face \
                 on line {face_line} uses it)",
                String::from_utf8_lossy(lines[line - 1]).trim()
            )),
            None => Ok(()),
        },
        _ => Ok(()),
    })
    .map_err(load_error)
}

/// The most vertex positions and triangles an OBJ file may hold ([`check_vertices_and_indices`]).
#[derive(Copy, Clone, Debug)]
struct Limits {
    positions: usize,
    triangles: usize,
}

/// Running counts of an OBJ file's vertex positions (`v` lines) and of the triangles tobj makes
/// of its faces, fed token by token from [`each_vertex_and_index`].
#[derive(Default)]
struct GeometryCount {
    positions: usize,
    /// Triangles of the faces before the current one.
    triangles: usize,
    /// The current face's line and position indices so far.
    face: (usize, usize),
}

impl GeometryCount {
    /// Triangles tobj 4.0.5 makes of a face of `corners` corners: its fan's `corners − 2`, and
    /// one (degenerate, `a a a` or `a b b`) of a face of one or two, which it keeps too.
    fn fan(corners: usize) -> usize {
        if corners == 0 {
            0
        } else {
            corners.saturating_sub(2).max(1)
        }
    }

    fn add(&mut self, line: usize, token: &ObjToken) {
        match token {
            ObjToken::Vertex(..) => self.positions += 1,
            ObjToken::Index { kind: 0, .. } => {
                if self.face.0 != line {
                    self.triangles += Self::fan(self.face.1);
                    self.face = (line, 0);
                }
                self.face.1 += 1;
            }
            ObjToken::Index { .. } => {}
        }
    }

    /// What passes `limits` so far, the current face included, if anything.
    fn excess(&self, limits: Limits) -> Option<String> {
        if self.positions > limits.positions {
            Some(format!("more than {} vertex positions", limits.positions))
        } else if self.triangles + Self::fan(self.face.1) > limits.triangles {
            Some(format!("more than {} triangles", limits.triangles))
        } else {
            None
        }
    }
}

/// The coordinates of a vertex position (`v`) from the words after `v` in the text as read
/// ([`as_read`], which cuts off a weight or colours), read as tobj reads them: a number too large
/// for `f32` becomes infinite. Fewer than three where the line has fewer numbers.
fn coordinates(words: &str) -> Vec<f32> {
    words.split_whitespace().map_while(|word| word.parse().ok()).take(3).collect()
}

/// Checks that tobj's triangulation of every face of four or more corners in the OBJ `text` is
/// the face: tobj fans each one out from its first corner, which covers a convex face (or one
/// whose first corner sees all the others) but fills a concave one's notch with a triangle that
/// faces backwards — wrong geometry without a word. Each fan triangle's normal must point along
/// the face's own (Newell's) normal, and that normal must not vanish against the triangles'
/// areas, as it does where they cancel (a self-crossing face of zero net area); an error names
/// the face's line. Faces with missing or unreadable corners are left to tobj and
/// [`check_vertices_and_indices`].
fn check_polygon_fans(text: &[u8]) -> std::result::Result<(), String> {
    // Every vertex position as tobj keeps it (f32, 12 bytes each); NaN where a line has fewer
    // than three numbers.
    let mut positions: Vec<Vec3> = Vec::new();
    // Faces of four or more corners (the position numbers), with their lines.
    let mut polygons: Vec<(usize, Vec<i64>)> = Vec::new();
    each_vertex_and_index(text, |line, token| {
        match token {
            ObjToken::Vertex(_, words) => positions.push(match coordinates(words)[..] {
                [x, y, z] => Vec3::new(x, y, z),
                _ => Vec3::NAN,
            }),
            ObjToken::Index { kind: 0, vertex } => match polygons.last_mut() {
                Some((face_line, corners)) if *face_line == line => corners.push(vertex),
                _ => {
                    if polygons.last().is_some_and(|(_, corners)| corners.len() < 4) {
                        polygons.pop();
                    }
                    polygons.push((line, vec![vertex]));
                }
            },
            _ => {}
        }
        Ok(())
    })?;
    for (line, corners) in polygons.iter().filter(|(_, corners)| corners.len() >= 4) {
        let corner = |&v: &i64| {
            let position = positions.get(usize::try_from(v).ok()?)?;
            position.is_finite().then(|| position.as_dvec3())
        };
        let Some(points) = corners.iter().map(corner).collect::<Option<Vec<DVec3>>>() else { continue };
        let n = points.len();
        let normal: DVec3 = (0..n).map(|i| points[i].cross(points[(i + 1) % n])).sum();
        // The fan's triangles, as twice their area vectors (which sum to `normal`).
        let fan = || (1..n - 1).map(|i| (points[i] - points[0]).cross(points[i + 1] - points[0]));
        // A little below 0 still counts as collinear corners, not as a fold.
        let folds = fan().any(|triangle| triangle.dot(normal) < -1e-9 * triangle.length() * normal.length());
        if folds {
            return Err(format!(
                "line {line}: this {n}-cornered face is not convex where it is split into triangles from its \
                 first corner, which would fill its notch with a backward-facing triangle; split it into \
                 triangles or convex faces"
            ));
        }
        // A face whose triangles' areas cancel (a bowtie symmetric about its crossing) has no
        // normal for them to disagree with: one of them faces backwards all the same.
        let area: f64 = fan().map(DVec3::length).sum();
        if normal.length() < 1e-9 * area {
            return Err(format!(
                "line {line}: this {n}-cornered face crosses itself so that its area cancels out, and the \
                 triangles it is split into from its first corner would face opposite ways; split it into \
                 triangles or convex faces"
            ));
        }
    }
    Ok(())
}

/// What [`each_vertex_and_index`] hands on.
enum ObjToken<'a> {
    /// A vertex position (`v`): its number (0-based) and the words after `v`.
    Vertex(i64, &'a str),
    /// An index of a face (`f`): which kind of vertex data (0 position, 1 texture coordinate,
    /// 2 normal) and the 0-based number it names.
    Index { kind: usize, vertex: i64 },
}

/// Walks the OBJ `text` as read ([`as_read`]: polylines blanked), handing `visit` each vertex
/// position and each face index with its 1-based line number, and refusing an index that is 0,
/// past 2³², or negative (relative) beyond the vertex data defined before it (see
/// [`check_vertices_and_indices`]), and, once the walk is done, the face with the largest index
/// past the whole file's data of its kind.
fn each_vertex_and_index(
    text: &[u8],
    mut visit: impl FnMut(usize, ObjToken) -> std::result::Result<(), String>,
) -> std::result::Result<(), String> {
    let mut defined = [0i64; 3];
    // Per kind, the largest positive index of any face and its line.
    let mut furthest = [(0i64, 0usize); 3];
    for (index, line) in text.split(|&b| b == b'\n').enumerate() {
        let line = String::from_utf8_lossy(line);
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let rest = line.trim_start().trim_start_matches('v');
                visit(index + 1, ObjToken::Vertex(defined[0], rest))?;
                defined[0] += 1;
            }
            Some("vt") => defined[1] += 1,
            Some("vn") => defined[2] += 1,
            Some("f") => {
                for vertex in words {
                    for (kind, part) in vertex.split('/').enumerate().take(3) {
                        if kind == 0 && part.is_empty() {
                            // tobj 4.0.5 keeps such a corner (and every one after it, in memory,
                            // before failing the file), uncounted by the limits.
                            return Err(format!(
                                "line {}: face corner `{vertex}` has no vertex position number",
                                index + 1
                            ));
                        }
                        let Ok(value) = part.parse::<i64>() else { continue };
                        if value == 0 || value > i64::from(u32::MAX) || value < -defined[kind] {
                            return Err(format!(
                                "line {}: `{vertex}` holds index {value}, which names no vertex data defined before it",
                                index + 1
                            ));
                        }
                        if value > furthest[kind].0 {
                            furthest[kind] = (value, index + 1);
                        }
                        let number = if value > 0 { value - 1 } else { defined[kind] + value };
                        visit(index + 1, ObjToken::Index { kind, vertex: number })?;
                    }
                }
            }
            _ => {}
        }
    }
    // tobj checks indices only as it closes an object, so its error could not name the face.
    const DATA: [&str; 3] = ["vertex positions (`v` lines)", "texture coordinates (`vt`)", "normals (`vn`)"];
    for ((value, line), (count, data)) in furthest.into_iter().zip(defined.into_iter().zip(DATA)) {
        if value > count {
            return Err(format!("line {line}: a face's index {value} is past the file's {count} {data}"));
        }
    }
    Ok(())
}

/// Checks that every `usemtl` line of the OBJ `text` names a material of the `libraries` read
/// before it (those of each `mtllib` line, each with the number of materials it added, in order),
/// as tobj reads the name: tobj leaves a mesh whose material it does not find without one, so a
/// typo (`usemtl lmap`) or a `usemtl` before the `mtllib` line of its library or without any
/// made a grey mesh and no light. Errors name the line and the libraries.
fn check_material_names(
    text: &[u8],
    libraries: &[Vec<(PathBuf, usize)>],
    materials: &[tobj::Material],
) -> std::result::Result<(), String> {
    // The libraries read so far, and the materials they added (tobj appends in order).
    let (mut read, mut known) = (0, 0);
    // Each name's first material: a lookup per `usemtl` line, not a scan of every material.
    let mut first_definition: std::collections::HashMap<&str, usize> = std::collections::HashMap::new();
    for (index, material) in materials.iter().enumerate() {
        first_definition.entry(material.name.as_str()).or_insert(index);
    }
    for (index, line) in text.split(|&b| b == b'\n').enumerate() {
        let line = String::from_utf8_lossy(line);
        match line.split_whitespace().next() {
            Some("mtllib") if read < libraries.len() => {
                known += libraries[read].iter().map(|(_, count)| count).sum::<usize>();
                read += 1;
            }
            Some("usemtl") => {
                // tobj 4.0.5 takes everything after the line's first space.
                let name = line.split_once(' ').unwrap_or_default().1.trim();
                let (line_number, written) = (index + 1, line.trim());
                if read == 0 {
                    return Err(format!(
                        "line {line_number}: `{written}` comes before any `mtllib` line, so it names no material"
                    ));
                }
                let defined = |name: &str| first_definition.get(name).is_some_and(|&first| first < known);
                if !defined(name) {
                    let names: Vec<String> =
                        libraries[..read].iter().flatten().map(|(library, _)| library.display().to_string()).collect();
                    // `usemtl lamp # bright`: the name keeps its `#`, as MTL's `newmtl` does.
                    let comment_hint = match name.split_once('#') {
                        Some((before, _)) if defined(before.trim()) => format!(
                            " (a name keeps a `#` and what follows it: `{}` is a material; put a comment on a line \
                             of its own)",
                            before.trim()
                        ),
                        _ => String::new(),
                    };
                    return Err(format!(
                        "line {line_number}: `{written}` names no material of {}{comment_hint}",
                        names.join(", ")
                    ));
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// The material of an MTL entry: `Kd` is the base colour ([`DEFAULT_ALBEDO`] without it), `Ke`
/// the emitted radiance, and the PBR extension's `Pr`/`Pm` (as Blender and 3ds Max write it)
/// the perceptual roughness and metalness, each one number (a trailing `#` comment is no part of
/// it, as for the keys tobj reads). Without `Pr` the roughness follows the Phong exponent
/// `Ns` by Walter et al. 2007's correspondence `α = √(2/(Ns + 2))` (§5.2; roughness = √α), and
/// is 1 without either — and where the entry says it has no specular lobe, whose exponent `Ns`
/// is (`Ks 0 0 0`, or `illum` 0 or 1: a colour, or a colour with ambient and Lambertian terms
/// only); exporters write an `Ns` for every material, which had made such diffuse walls glossy
/// (`Ns 1000`: roughness 0.21). Without `Pm` the surface is a dielectric — but for an entry whose
/// only reflection is specular (`Kd 0 0 0` and a `Ks` other than black, where `illum` allows it, as
/// exporters write a mirror: `Ks 0.95 0.95 0.95`, `illum 3`), a metal of base colour `Ks`, the
/// colour of that reflection (a black dielectric reflects 4 % at normal incidence). A `Pr` or `Pm`
/// that is not a number, or a value out of range ([`Material::check`]), is an error naming the MTL
/// keyword; `Ns` is finite and ≥ 0 ([`read_material_library`] refused other lines).
fn mtl_material(m: &tobj::Material) -> std::result::Result<Material, String> {
    let pbr = |key: &str| {
        m.unknown_param
            .get(key)
            .map(|v| match before_comment(v.split_whitespace()).collect::<Vec<_>>()[..] {
                [value] => value.parse::<f32>().map_err(|_| format!("`{key} {value}` is not a number")),
                ref words => Err(format!("`{key}` needs one number, not {}", words.len())),
            })
            .transpose()
    };
    let from_exponent = |ns: f32| (2.0 / (ns + 2.0)).sqrt().sqrt();
    let no_specular = m.specular.is_some_and(|ks| ks == [0.0; 3]) || matches!(m.illumination_model, Some(0 | 1));
    let exponent = m.shininess.filter(|_| !no_specular);
    let roughness = pbr("Pr")?.or_else(|| exponent.map(from_exponent));
    let metallic = pbr("Pm")?;
    let specular_only = m.specular.filter(|_| !no_specular && metallic.is_none() && m.diffuse == Some([0.0; 3]));
    let material = Material {
        base_color: specular_only.or(m.diffuse).map_or(DEFAULT_ALBEDO, Vec3::from_array),
        roughness: roughness.unwrap_or(1.0),
        metallic: metallic.unwrap_or(if specular_only.is_some() { 1.0 } else { 0.0 }),
        emission: m.emissive.map_or(Vec3::ZERO, Vec3::from_array),
        double_sided: false,
    };
    material.check().map_err(|(field, reason)| {
        let keyword = match field {
            "material.base_color" if specular_only.is_some() => "Ks",
            "material.base_color" => "Kd",
            "material.emission" => "Ke",
            "material.roughness" => "Pr",
            _ => "Pm",
        };
        format!("{keyword}: {reason}")
    })?;
    Ok(material)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn obj_file(text: &str) -> tempfile::NamedTempFile {
        let mut f = tempfile::Builder::new().suffix(".obj").tempfile().unwrap();
        f.write_all(text.as_bytes()).unwrap();
        f
    }

    /// A fresh folder holding the material `libraries` (file name, text), and the path of a
    /// `scene.obj` beside them for the test to write.
    fn folder_with(libraries: &[(&str, &str)]) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        for (name, text) in libraries {
            std::fs::write(dir.path().join(name), text).unwrap();
        }
        let path = dir.path().join("scene.obj");
        (dir, path)
    }

    #[test]
    fn loads_a_quad() {
        let f = obj_file("o quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n");
        let scene = load(f.path()).unwrap();
        assert_eq!(scene.triangle_count(), 2);
        assert_eq!(scene.meshes()[0].name, "quad");
        let f = obj_file("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n");
        assert_eq!(load(f.path()).unwrap().meshes()[0].name, "mesh 0", "an object without a name");
    }

    #[test]
    fn missing_file_names_the_path() {
        let err = load(Path::new("/nonexistent/scene.obj")).unwrap_err();
        assert!(matches!(err, Error::SceneLoad { .. }), "{err}");
        assert!(err.to_string().contains("/nonexistent/scene.obj"));
        assert!(err.to_string().contains("No such file"), "the OS's reason: {err}");
        let dir = tempfile::Builder::new().suffix(".obj").tempdir().unwrap();
        let err = load(dir.path()).unwrap_err();
        assert!(err.to_string().contains("is a directory"), "{err}");
        let zero = dir.path().join("zero.obj");
        std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
        let err = load(&zero).unwrap_err();
        assert!(err.to_string().contains("not a regular file"), "{err}");
    }

    #[test]
    fn scenes_up_to_the_coordinate_limit_get_a_framing_camera() {
        // The 45° camera would sit 2.6 radii from the centre, beyond MAX_COORDINATE for these.
        for (obj, centre_z) in [
            ("v -6e7 -6e7 0\nv 6e7 -6e7 0\nv 0 6e7 0\nf 1 2 3\n", 0.0),
            ("v -1e8 -1e8 -1e8\nv 1e8 -1e8 1e8\nv 0 1e8 1e8\nf 1 2 3\n", 0.0),
            ("v -1e8 -1e8 9e7\nv 1e8 -1e8 1e8\nv 0 1e8 1e8\nf 1 2 3\n", 9.5e7),
            // Small scenes far from the origin: the 45° camera rounded onto its look-at point
            // (z + 0.0026 = z in f32 at 10⁵) and the scene was refused as a degenerate camera.
            ("v 0 0 1e5\nv 0.001 0 1e5\nv 0 0.001 1e5\nf 1 2 3\n", 1e5),
            ("v 0 0 1e8\nv 1 0 1e8\nv 0 1 1e8\nf 1 2 3\n", 1e8),
            ("v 0 0 -1e8\nv 1 0 -1e8\nv 0 1 -1e8\nf 1 2 3\n", -1e8),
        ] {
            let f = obj_file(obj);
            let scene = load(f.path()).unwrap_or_else(|e| panic!("{obj}: {e}"));
            let camera = scene.camera();
            assert!(camera.position.abs().max_element() <= super::super::MAX_COORDINATE, "{camera:?}");
            assert_eq!(camera.look_at.z, centre_z);
            // It still sees the bounding sphere (its outline, under asin(radius/distance)), or
            // looks at it as widely as it may (120°) from within 1.15 radii.
            let (lo, hi) = scene.bounds();
            let radius = (hi - lo).length() * 0.5;
            let distance = (camera.position - camera.look_at).length();
            let half_fov = (camera.vertical_fov_degrees * 0.5).to_radians();
            let widest = camera.vertical_fov_degrees >= 119.99 && distance < radius * 1.155;
            assert!(distance * half_fov.sin() >= radius * 0.999 || widest, "{camera:?} radius {radius}");
        }
    }

    /// A floor and a lamp quad wound to face down, with an MTL library: the lamp's `Ke` makes it
    /// a quad light, `Kd`/`Pr`/`Pm` and `Ns` set the materials, a mesh before any `usemtl` stays grey
    /// (a `usemtl` holds for the objects after it, as in the format).
    #[test]
    fn mtl_materials_and_emissive_quads_become_materials_and_lights() {
        let library = "newmtl floor\nKd 0.5 0.25 1\nNs 198\n\
                       newmtl lamp\nKd 1 1 1\nKe 4 2 1\n\
                       newmtl metal\nKd 0.9 0.8 0.7\nPr 0.3\nPm 1\n";
        let (dir, path) = folder_with(&[("scene.mtl", library)]);
        let obj = "mtllib scene.mtl\n\
                   v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\n\
                   v -0.25 1.5 -0.25\nv 0.25 1.5 -0.25\nv 0.25 1.5 0.25\nv -0.25 1.5 0.25\n\
                   v 0 0.2 0\nv 0.2 0.2 0\nv 0 0.4 0\n\
                   o plain\nf 9 11 10\n\
                   o floor\nusemtl floor\nf 1 4 3 2\n\
                   o lamp\nusemtl lamp\nf 5 6 7 8\n\
                   o chip\nusemtl metal\nf 9 10 11\n";
        std::fs::write(&path, obj).unwrap();
        let scene = load(&path).unwrap();
        let by_name = |name: &str| scene.meshes().iter().find(|m| m.name == name).unwrap_or_else(|| panic!("{name}"));
        let floor = by_name("floor (floor)").material;
        assert_eq!(floor.base_color, Vec3::new(0.5, 0.25, 1.0));
        assert!((floor.roughness - 0.1f32.sqrt()).abs() < 1e-6, "Ns 198: α = √(2/200) = 0.1, {}", floor.roughness);
        assert_eq!(scene.unrendered(), Unrendered::default());
        let metal = by_name("chip (metal)").material;
        assert_eq!((metal.roughness, metal.metallic), (0.3, 1.0));
        assert_eq!(by_name("plain").material, Material::diffuse(DEFAULT_ALBEDO));
        assert_eq!(scene.lights().len(), 1, "the lamp quad is a light");
        let lamp = scene.lights()[0];
        assert_eq!(lamp.radiance.truncate(), Vec3::new(4.0, 2.0, 1.0));
        let facing = lamp.edge_u.truncate().cross(lamp.edge_v.truncate());
        assert!(facing.y < 0.0, "counter-clockwise seen from below: emits down, {facing}");

        // A library that is missing is an error naming the file; a value out of range or a `Pr`,
        // `Pm` that is not a number names the library, the material and its keyword; a `usemtl`
        // of a material the library lacks names the OBJ's line and the library.
        std::fs::remove_file(dir.path().join("scene.mtl")).unwrap();
        let err = load(&path).unwrap_err();
        assert!(err.to_string().contains("material library") && err.to_string().contains("scene.obj"), "{err}");
        for (text, expected) in [
            ("newmtl floor\nKd 2 0 0\nnewmtl lamp\nnewmtl metal\n", "scene.mtl: material `floor`: Kd: has base colour"),
            ("newmtl floor\nnewmtl lamp\nKe -1 0 0\nnewmtl metal\n", "scene.mtl: material `lamp`: Ke: emits"),
            (
                "newmtl floor\nnewmtl lamp\nnewmtl metal\nPr 0.5x\n",
                "scene.mtl: material `metal`: `Pr 0.5x` is not a number",
            ),
            (
                "newmtl floor\nnewmtl lamp\nnewmtl metal\nPm 0.5 0.5 # two\n",
                "scene.mtl: material `metal`: `Pm` needs one number, not 2",
            ),
            (
                "newmtl floor\nnewmtl lamp\nnewmtl metal\nPr\n",
                "scene.mtl: material `metal`: `Pr` needs one number, not 0",
            ),
            ("newmtl floor\nnewmtl lamp\nnewmtl metal\nPm 2\n", "scene.mtl: material `metal`: Pm: has 2"),
            ("newmtl floor\nnewmtl lmap\nnewmtl metal\n", "line 19: `usemtl lamp` names no material of"),
        ] {
            std::fs::write(dir.path().join("scene.mtl"), text).unwrap();
            let err = load(&path).unwrap_err().to_string();
            assert!(err.contains(expected) && err.contains("scene.mtl"), "{text:?}: {err}");
        }
        // A `usemtl` tobj cannot resolve though the name is in the library: without an `mtllib`
        // line or before it. Each once loaded a grey lamp and no light.
        std::fs::write(dir.path().join("scene.mtl"), "newmtl floor\nnewmtl lamp\nKe 1 1 1\nnewmtl metal\n").unwrap();
        assert_eq!(load(&path).unwrap().lights().len(), 1);
        for (obj, expected) in [
            (obj.replace("mtllib scene.mtl\n", ""), "line 15: `usemtl floor` comes before any `mtllib` line"),
            (
                obj.replace("mtllib scene.mtl\n", "") + "mtllib scene.mtl\n",
                "line 15: `usemtl floor` comes before any `mtllib` line",
            ),
        ] {
            std::fs::write(&path, &obj).unwrap();
            let err = load(&path).unwrap_err().to_string();
            assert!(err.contains(expected), "{obj:?}: {err}");
        }
        // Indented, or with a tab after the keyword, it names its material as tinyobjloader reads
        // it (tobj took the name after the line's first space: `usemtl lamp`, a grey lamp).
        for written in [" usemtl lamp", "\tusemtl\tlamp", "usemtl \t lamp \t"] {
            std::fs::write(&path, obj.replace("usemtl lamp", written)).unwrap();
            let scene = load(&path).unwrap_or_else(|e| panic!("{written:?}: {e}"));
            assert_eq!(scene.lights().len(), 1, "{written:?}");
        }
        std::fs::write(&path, obj).unwrap();
        // One number is a grey, as the MTL format says (it had been refused): on line 2 of a
        // library whose line 4 is at fault, which the error still names.
        std::fs::write(dir.path().join("scene.mtl"), "newmtl floor\nKd 0.5 # grey\nnewmtl lamp\nKe 1 x 1\n").unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("scene.mtl: line 4: material"), "{err}");
        std::fs::write(dir.path().join("scene.mtl"), "newmtl floor\nKd 0.5 # grey\nnewmtl lamp\nnewmtl metal\n")
            .unwrap();
        let scene = load(&path).unwrap();
        let floor = scene.meshes().iter().find(|m| m.name == "floor (floor)").unwrap().material;
        assert_eq!(floor.base_color, Vec3::splat(0.5));
        // A colour with other than one or three numbers (tobj 4.0.5 panics on fewer and ignored a
        // fourth), an `Ns` that is not one finite number ≥ 0 (a negative one was taken as 0, an
        // infinite one as a mirror) or a number that does not parse names the library and its line.
        let library = dir.path().join("scene.mtl");
        for (text, expected) in [
            (
                "newmtl floor\nKd 0.5 0.5\nnewmtl lamp\nnewmtl metal\n",
                "scene.mtl: line 2: `Kd` needs three numbers (or one, a grey), not 2",
            ),
            ("newmtl floor\nnewmtl lamp\n  Ke 1 1\nnewmtl metal\n", "scene.mtl: line 3: `Ke` needs three numbers"),
            ("newmtl floor\nKa\n", "scene.mtl: line 2: `Ka` needs three numbers"),
            (
                "newmtl floor\nnewmtl lamp\nKe 1 1 1 1\nnewmtl metal\n",
                "scene.mtl: line 3: `Ke` needs three numbers (or one, a grey), not 4",
            ),
            (
                "newmtl floor\nKd 0.5 0.5 0.5 0.5\nnewmtl lamp\nnewmtl metal\n",
                "scene.mtl: line 2: `Kd` needs three numbers (or one, a grey), not 4",
            ),
            ("newmtl floor\nKs 1 2 x\n", "scene.mtl: line 2: material"),
            ("newmtl floor\n\nNi many\n", "scene.mtl: line 3: material"),
            (
                "newmtl floor\nNs -5\nnewmtl lamp\nnewmtl metal\n",
                "scene.mtl: line 2: `Ns -5`: the specular exponent must be one finite number ≥ 0",
            ),
            ("newmtl floor\n\nNs nan\nnewmtl lamp\nnewmtl metal\n", "scene.mtl: line 3: `Ns nan`: the specular"),
            ("newmtl floor\nNs inf\nnewmtl lamp\nnewmtl metal\n", "scene.mtl: line 2: `Ns inf`: the specular"),
            ("newmtl floor\nNs 10 20\nnewmtl lamp\nnewmtl metal\n", "scene.mtl: line 2: `Ns 10 20`: the specular"),
            ("newmtl floor\nNs many\nnewmtl lamp\nnewmtl metal\n", "scene.mtl: line 2: `Ns many`: the specular"),
            // tobj would drop these without a word: a lamp's `Ke` before its `newmtl`, and a
            // second `lamp` hiding the first.
            ("# lamp\nKe 10 10 10\nnewmtl lamp\n", "scene.mtl: line 2: `Ke` before the first `newmtl`"),
            (
                "newmtl lamp\nKe 5 5 5\nnewmtl  lamp \nKd 1 1 1\n",
                "line 3: material `lamp` is defined again (first on line 1)",
            ),
        ] {
            std::fs::write(&library, text).unwrap();
            let err = load(&path).unwrap_err().to_string();
            assert!(err.contains("material library") && err.contains(expected), "{text:?}: {err}");
        }
        // `Ns 0`, the least exponent, is the roughest surface; a trailing comment is no argument,
        // of the keys tobj reads nor of `Pr` and `Pm`, which raywave reads.
        std::fs::write(
            &library,
            "newmtl floor\nNs 0 # rough\nKd 0.25 0.5 1 #blue\nnewmtl lamp\nnewmtl metal\nPr 0.25 # x\nPm 1 #metal\n",
        )
        .unwrap();
        let scene = load(&path).unwrap();
        let material = |name: &str| scene.meshes().iter().find(|m| m.name == name).unwrap().material;
        let (floor, metal) = (material("floor (floor)"), material("chip (metal)"));
        assert_eq!((floor.roughness, floor.base_color), (1.0, Vec3::new(0.25, 0.5, 1.0)));
        assert_eq!((metal.roughness, metal.metallic), (0.25, 1.0));
        // `Ns` is the exponent of the specular lobe: where `Ks 0 0 0` or `illum` 0 or 1 says
        // there is none, it leaves the roughness at 1 (it had made such walls glossy); with a
        // lobe (`Ks` given or not, `illum` 2) it sets it; `Pr` overrides either way.
        for (entry, roughness) in [
            ("Ks 0 0 0\nNs 1000", 1.0),
            ("Ks 0.5 0.5 0.5\nNs 1000\nillum 1", 1.0),
            ("Ns 1000\nillum 0", 1.0),
            ("Ks 0 0 0\nNs 1000\nPr 0.4", 0.4),
            ("Ks 0.5 0.5 0.5\nNs 198\nillum 2", 0.1f32.sqrt()),
            ("Ns 198", 0.1f32.sqrt()),
        ] {
            std::fs::write(&library, format!("newmtl floor\n{entry}\nnewmtl lamp\nnewmtl metal\n")).unwrap();
            let floor = load(&path).unwrap().meshes().iter().find(|m| m.name == "floor (floor)").unwrap().material;
            assert!((floor.roughness - roughness).abs() < 1e-6, "{entry:?}: roughness {}", floor.roughness);
        }
        // An entry whose only reflection is specular (`Kd 0 0 0`, `Ks` not black, a lobe `illum`
        // allows) is a metal of base colour `Ks`: a mirror (it had loaded as a black dielectric);
        // with a diffuse colour, no lobe, or its own `Pm`, it stays as it says.
        let mirror = "Kd 0 0 0\nKs 0.95 0.9 0.85\nNs 1000";
        for (entry, base_color, metallic) in [
            (format!("{mirror}\nillum 3"), Vec3::new(0.95, 0.9, 0.85), 1.0),
            (mirror.to_owned(), Vec3::new(0.95, 0.9, 0.85), 1.0),
            (format!("{mirror}\nillum 1"), Vec3::ZERO, 0.0),
            (format!("{mirror}\nPm 0"), Vec3::ZERO, 0.0),
            ("Kd 0.1 0 0\nKs 0.95 0.9 0.85\nillum 3".to_owned(), Vec3::new(0.1, 0.0, 0.0), 0.0),
            ("Kd 0 0 0\nKs 0 0 0".to_owned(), Vec3::ZERO, 0.0),
        ] {
            std::fs::write(&library, format!("newmtl floor\n{entry}\nnewmtl lamp\nnewmtl metal\n")).unwrap();
            let floor = load(&path).unwrap().meshes().iter().find(|m| m.name == "floor (floor)").unwrap().material;
            assert_eq!((floor.base_color, floor.metallic), (base_color, metallic), "{entry:?}");
        }
        std::fs::write(&library, "newmtl floor\nKd 0 0 0\nKs 1.5 1 1\nnewmtl lamp\nnewmtl metal\n").unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("material `floor`: Ks:"), "the base colour's keyword: {err}");
        for (not_a_file, expected) in [("/dev/zero", "/dev/zero: not a regular file"), (".", "/.: not a regular file")]
        {
            let scene = dir.path().join("device.obj");
            std::fs::write(&scene, format!("mtllib {not_a_file}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")).unwrap();
            let err = load(&scene).unwrap_err().to_string();
            assert!(err.contains("material library") && err.contains(expected), "{err}");
        }
        // Meshes whose materials have textures (which raywave does not sample) are counted.
        std::fs::write(
            &library,
            "newmtl floor\nmap_Kd wood.png\nnewmtl lamp\nKe 1 1 1\nmap_Ke screen.png\nnewmtl metal\n",
        )
        .unwrap();
        assert_eq!(load(&path).unwrap().unrendered().textured_meshes, 2);
        // So are those whose materials are see-through (`d` below 1, or a `map_d`).
        std::fs::write(&library, "newmtl floor\nd 0.5\nnewmtl lamp\nKe 1 1 1\nd 1\nnewmtl metal\nmap_d cut.png\n")
            .unwrap();
        let unrendered = load(&path).unwrap().unrendered();
        assert_eq!((unrendered.see_through_meshes, unrendered.textured_meshes), (2, 0));
        // A transparency `Tr` between 0 and 1 is see-through too, where no `d` says otherwise; `Tr 1`
        // may mean opaque or invisible (exporters disagree), so it is not counted.
        std::fs::write(
            &library,
            "newmtl floor\nTr 0.5 # frosted\nnewmtl lamp\nKe 1 1 1\nTr 1\nnewmtl metal\nTr 0.25\nd 1\n",
        )
        .unwrap();
        assert_eq!(load(&path).unwrap().unrendered().see_through_meshes, 1);
        std::fs::write(&library, b"newmtl floor\nKd 1 1 1\n\nKs 1 1 \xff\n").unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("scene.mtl: line 4: not UTF-8 text"), "{err}");
    }

    /// With two `mtllib` lines, a material's error named the last library read, and a library
    /// that failed was dropped without a word when the other loaded (tobj returns what loaded).
    #[test]
    fn each_material_library_answers_for_its_own_materials() {
        let (dir, path) = folder_with(&[]);
        std::fs::write(
            &path,
            "mtllib a.mtl\nmtllib b.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\nusemtl blue\nf 1 3 2\n",
        )
        .unwrap();
        std::fs::write(dir.path().join("b.mtl"), "newmtl blue\nKd 0 0 1\n").unwrap();
        std::fs::write(dir.path().join("a.mtl"), "newmtl red\nKd 1 0 0\n").unwrap();
        assert_eq!(load(&path).unwrap().meshes().len(), 2);
        std::fs::write(dir.path().join("a.mtl"), "newmtl red\nKd 2 0 0\n").unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("a.mtl: material `red`: Kd"), "{err}");
        std::fs::remove_file(dir.path().join("a.mtl")).unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("material library") && err.contains("a.mtl"), "{err}");
        // tobj looks a name up in the libraries read so far: `blue` before b.mtl's line is none.
        std::fs::write(dir.path().join("a.mtl"), "newmtl red\nKd 1 0 0\n").unwrap();
        std::fs::write(&path, "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl blue\nf 1 2 3\nmtllib b.mtl\n").unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("line 5: `usemtl blue` names no material of") && !err.contains("b.mtl"), "{err}");
    }

    /// One `mtllib` line may name several libraries (the OBJ format's `mtllib filename1 filename2
    /// ...`): tobj had read `a.mtl b.mtl` as one file name and refused the scene. A file whose
    /// name holds a space is still one library.
    #[test]
    fn one_mtllib_line_may_name_several_libraries() {
        let (dir, path) = folder_with(&[]);
        let obj = |mtllib: &str| {
            format!("mtllib {mtllib}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\nusemtl lamp\nf 1 3 2\n")
        };
        std::fs::write(dir.path().join("a.mtl"), "newmtl red\nKd 1 0 0\n").unwrap();
        std::fs::write(dir.path().join("b.mtl"), "newmtl green\nKd 0 1 0\nnewmtl lamp\nKe 5 5 5\n").unwrap();
        std::fs::write(&path, obj("a.mtl  b.mtl")).unwrap();
        let scene = load(&path).unwrap();
        let materials: Vec<_> =
            scene.meshes().iter().map(|mesh| (mesh.material.base_color, mesh.material.emission)).collect();
        assert_eq!(materials, [(Vec3::X, Vec3::ZERO), (DEFAULT_ALBEDO, Vec3::splat(5.0))]);
        // Each library still answers for its own materials, and a library that cannot be read
        // is named, also when it is not the line's first.
        std::fs::write(dir.path().join("b.mtl"), "newmtl lamp\nKe -5 5 5\n").unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("b.mtl: material `lamp`"), "{err}");
        std::fs::remove_file(dir.path().join("b.mtl")).unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("material library") && err.contains("b.mtl:") && !err.contains("a.mtl "), "{err}");
        // A name the line's libraries do not define lists them all.
        std::fs::write(dir.path().join("b.mtl"), "newmtl green\nKd 0 1 0\n").unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("line 7: `usemtl lamp` names no material of") && err.contains("a.mtl, "), "{err}");
        assert!(err.contains("b.mtl"), "{err}");
        // A file named with a space is one library, as tobj reads the line.
        std::fs::write(dir.path().join("a b.mtl"), "newmtl red\nKd 0 0 1\nnewmtl lamp\nKe 1 1 1\n").unwrap();
        std::fs::write(&path, obj("a b.mtl")).unwrap();
        assert_eq!(load(&path).unwrap().meshes()[0].material.base_color, Vec3::Z);
    }

    /// A name two libraries define: tobj gave it the later library's material without a word (an
    /// emitter in a.mtl became a grey surface from b.mtl). A library named twice, also by another
    /// path to it, is one definition.
    #[test]
    fn a_material_two_libraries_define_is_refused() {
        let (dir, path) = folder_with(&[]);
        let triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl lamp\nf 1 2 3\n";
        std::fs::write(dir.path().join("a.mtl"), "newmtl lamp\nKe 10 10 10\n").unwrap();
        std::fs::write(dir.path().join("b.mtl"), "newmtl lamp\nKd 0.5 0.5 0.5\n").unwrap();
        std::fs::write(&path, format!("mtllib a.mtl\nmtllib b.mtl\n{triangle}")).unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("b.mtl: material `lamp` is defined in") && err.contains("a.mtl too"), "{err}");
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        std::fs::write(&path, format!("mtllib a.mtl\nmtllib sub/../a.mtl\n{triangle}")).unwrap();
        assert_eq!(load(&path).unwrap().meshes()[0].material.emission, Vec3::splat(10.0));
    }

    /// Vertex colours on some vertices and not on others: tobj refused the file ("face vertex
    /// color index out of bounds"), naming no `v` line; raywave does not use them.
    #[test]
    fn vertex_colours_are_ignored_even_when_only_some_vertices_have_them() {
        for obj in [
            "v 0 0 0 1 0 0\nv 1 0 0\nv 0 1 0 0 0 1\nf 1 2 3\n",
            "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 1 2 3\n",
        ] {
            let scene = load(obj_file(obj).path()).unwrap_or_else(|e| panic!("{obj:?}: {e}"));
            assert_eq!(scene.meshes()[0].positions, [Vec3::ZERO, Vec3::X, Vec3::Y]);
        }
        // Line numbers still name the line at fault.
        let err = load(obj_file("v 0 0 0 1 0 0\nv 1 0 0\nv 0 1 0\nf 1 2/x 3\n").path()).unwrap_err().to_string();
        assert!(err.contains("line 4: face parse error"), "{err}");
    }

    /// A vertex's weight (`v x y z w`, for rational curves and surfaces) is ignored: tobj had
    /// divided the position by it, and a weight of 0 had put the vertex at infinity.
    #[test]
    fn vertex_weights_are_ignored() {
        // Also where dividing by it would have put the vertex out of range (the range check had
        // divided, and refused the file).
        let scene = load(obj_file("v 0 0 0 2\nv 1 0 0 0\nv 0 1 0 1e-9\nf 1 2 3\n").path()).unwrap();
        assert_eq!(scene.meshes()[0].positions, [Vec3::ZERO, Vec3::X, Vec3::Y]);
        let err = load(obj_file("v 0 0 0 2\nv 1 0 0\nv 0 1 0\nf 1 2/x 3\n").path()).unwrap_err().to_string();
        assert!(err.contains("line 4: face parse error"), "line numbers kept: {err}");
    }

    #[test]
    fn polylines_are_not_surfaces() {
        let (_dir, path) = folder_with(&[("lamp.mtl", "newmtl lamp\nKe 1 1 1\n")]);
        let square = "mtllib lamp.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl lamp\n";
        std::fs::write(&path, format!("{square}f 1 2 3\nl 1 2 3 4\n  l 4 3\n")).unwrap();
        let scene = load(&path).unwrap();
        assert_eq!((scene.triangle_count(), scene.lights().len()), (1, 0), "the face alone, no quad light");
        std::fs::write(&path, format!("{square}l 1 2 3 4\n")).unwrap();
        assert!(matches!(load(&path), Err(Error::EmptyScene { dropped_degenerate: 0, .. })));
        // Line numbers still name the line at fault.
        std::fs::write(&path, format!("{square}l 1 2\nf 1 2/x 3\n")).unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("line 8: face parse error"), "{err}");
    }

    /// A trailing `#` comment on a line of numbers is no data (tinyobjloader's
    /// `issue-389-comment.obj`: tobj read `v 1 2 3 # top` as a colour and failed), while a name
    /// keeps its `#` (`Material #25`), as MTL's `newmtl` does.
    #[test]
    fn comments_after_numbers_are_no_data_and_names_keep_their_hash() {
        let (dir, path) = folder_with(&[("lamp.mtl", "newmtl Material #25\nKe 1 1 1\n")]);
        let obj = "mtllib lamp.mtl # the library\n\
                   v 0 0 0 # origin\nv 1 0 0 0.5 0.5 0.5 # coloured\nv 1 1 0 1 #weighted\nv 0 1 0\n\
                   vt 0 0 # corner\nvn 0 0 1 # up\n\
                   usemtl Material #25\nf 1/1/1 2/1/1 3/1/1 4/1/1 # the lamp\n";
        std::fs::write(&path, obj.replace("mtllib lamp.mtl # the library", "mtllib lamp.mtl")).unwrap();
        let scene = load(&path).unwrap();
        assert_eq!(scene.meshes()[0].positions, [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y]);
        assert_eq!(scene.lights().len(), 1, "`usemtl Material #25` names the material `Material #25`");
        // After a library's name, where no file has the whole line's name, the words before a
        // comment name the libraries (a file may hold `#` in its name).
        std::fs::write(&path, obj).unwrap();
        assert_eq!(load(&path).unwrap().lights().len(), 1);
        std::fs::write(dir.path().join("lamp.mtl # the library"), "newmtl Material #25\n").unwrap();
        assert_eq!(load(&path).unwrap().lights().len(), 0, "the library named by the whole line");
        // Line numbers still name the line at fault.
        let err = load(obj_file("v 0 0 0 # a\nv 1 0 0\nv 0 1 0\nf 1 2/x 3 # b\n").path()).unwrap_err().to_string();
        assert!(err.contains("line 4: face parse error"), "{err}");
        // Comments in Latin-1, whole lines or after numbers, are no part of what is read.
        let mut latin1 = obj_file("");
        latin1.write_all(b"# cr\xe9\xe9 par\nv 0 0 0 # \xe9t\xe9\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(load(latin1.path()).unwrap().meshes()[0].positions, [Vec3::ZERO, Vec3::X, Vec3::Y]);
    }

    /// Texture coordinates and normals, which raywave does not read, refuse no file: `vt u` (the
    /// format's `v` defaults to 0) and a `vt` or `vn` tobj cannot parse (MSVC writes NaN as
    /// `-1.#IND00`) keep their place for the faces' indices.
    #[test]
    fn unread_texture_coordinates_and_normals_refuse_no_file() {
        for extra in ["vt 0.5\nvn 0 0 1\n", "vt\nvn -1.#IND00 0 0\n", "vt 0.5 x\nvn 0 1\n", "vt 1 # u\nvn # none\n"] {
            let obj = format!("v 0 0 0\nv 1 0 0\nv 0 1 0\n{extra}f 1/1/1 2/1/1 3/1/1\n");
            let scene = load(obj_file(&obj).path()).unwrap_or_else(|e| panic!("{obj:?}: {e}"));
            assert_eq!(scene.meshes()[0].positions, [Vec3::ZERO, Vec3::X, Vec3::Y], "{obj:?}");
        }
        // A face index past them is still an error.
        let err = load(obj_file("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.5\nf 1/2 2/1 3/1\n").path()).unwrap_err();
        assert!(err.to_string().contains("line 5: a face's index 2 is past the file's 1 texture coordinates"), "{err}");
    }

    /// A library's or material's name after a tab, or on an indented line, is read as
    /// tinyobjloader reads it (tobj took the name after the line's first space: `mtllib<TAB>a.mtl`
    /// had looked for the OBJ's folder); an `mtllib` or `usemtl` naming nothing is an error by line,
    /// and a `usemtl` naming a material followed by a comment says the `#` is part of the name.
    #[test]
    fn names_after_tabs_and_indents_are_read_and_a_missing_name_is_an_error() {
        let (_dir, path) = folder_with(&[("lamp.mtl", "newmtl lamp\nKe 1 1 1\n")]);
        let quad = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";
        for (library, material) in [("mtllib\tlamp.mtl", "usemtl\tlamp"), ("  mtllib lamp.mtl ", "\tusemtl lamp\r")] {
            std::fs::write(&path, format!("{library}\n\t o\tlamp\n{material}\n{quad}")).unwrap();
            let scene = load(&path).unwrap_or_else(|e| panic!("{library:?}, {material:?}: {e}"));
            assert_eq!(scene.lights().len(), 1, "{library:?}, {material:?}");
            assert_eq!(scene.meshes()[0].name, "lamp (lamp)");
        }
        for (obj, expected) in [
            (format!("mtllib\nusemtl lamp\n{quad}"), "line 1: `mtllib` names nothing"),
            (format!("mtllib lamp.mtl\n  usemtl \t\n{quad}"), "line 2: `usemtl` names nothing"),
            (
                format!("mtllib lamp.mtl\nusemtl lamp # bright\n{quad}"),
                "line 2: `usemtl lamp # bright` names no material of",
            ),
            (
                format!("mtllib lamp.mtl\nusemtl lmap # bright\n{quad}"),
                "line 2: `usemtl lmap # bright` names no material of",
            ),
        ] {
            std::fs::write(&path, &obj).unwrap();
            let err = load(&path).unwrap_err().to_string();
            assert!(err.contains(expected) && err.contains("scene.obj"), "{obj:?}: {err}");
            let hinted = err.contains("a name keeps a `#` and what follows it: `lamp` is a material");
            assert_eq!(hinted, obj.contains("lamp #"), "only where the name before the `#` is one: {obj:?}: {err}");
        }
    }

    /// A UTF-8 byte-order mark (which Windows editors write) before an OBJ's `mtllib` line or an
    /// MTL's first `newmtl` is no part of them: it had made the OBJ's `usemtl` come "before any
    /// `mtllib` line", and the MTL's `newmtl` a property of no material. Line numbers still count
    /// from the line it starts.
    #[test]
    fn a_byte_order_mark_is_no_part_of_the_first_line() {
        let (dir, path) = folder_with(&[]);
        let obj = "mtllib lamp.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl lamp\nf 1 2 3 4\n";
        for (obj_mark, mtl_mark) in [("\u{feff}", ""), ("", "\u{feff}"), ("\u{feff}", "\u{feff}")] {
            std::fs::write(dir.path().join("lamp.mtl"), format!("{mtl_mark}newmtl lamp\nKe 1 1 1\n")).unwrap();
            std::fs::write(&path, format!("{obj_mark}{obj}")).unwrap();
            let scene = load(&path).unwrap_or_else(|e| panic!("{obj_mark:?} {mtl_mark:?}: {e}"));
            assert_eq!(scene.lights().len(), 1, "the lamp material's quad is a light");
        }
        std::fs::write(&path, format!("\u{feff}{obj}f 1 2 x\n")).unwrap();
        let err = load(&path).unwrap_err().to_string();
        assert!(err.contains("line 8: face parse error"), "{err}");
    }

    #[test]
    fn faces_that_a_fan_would_triangulate_wrongly_are_refused() {
        // A square with a notch at its fourth corner: the fan from corner 1 makes (1, 2, 3),
        // twice the face's area, and a backward triangle (1, 3, 4) inside it.
        let notched = "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 1.5 0.5 0\nf 1 2 3 4\n";
        let err = load(obj_file(notched).path()).unwrap_err().to_string();
        assert!(err.contains("line 5: this 4-cornered face is not convex"), "{err}");
        // The same corners from the notch: every fan triangle faces the same way — it is the face.
        let from_the_notch = "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 1.5 0.5 0\nf 4 1 2 3\n";
        assert_eq!(load(obj_file(from_the_notch).path()).unwrap().triangle_count(), 2);
        // A bowtie symmetric about its crossing: its lobes' areas cancel, so its Newell normal is
        // zero and no fan triangle points against it, but the fan's two triangles face opposite
        // ways (it loaded as such).
        let bowtie = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 4 3\n";
        let err = load(obj_file(bowtie).path()).unwrap_err().to_string();
        assert!(err.contains("line 5: this 4-cornered face crosses itself so that its area cancels out"), "{err}");
        // Convex faces, a pentagon far from the origin with three collinear corners, a face that
        // refers to corners defined after it, and quads wound either way all load.
        let convex = "v 1e5 0 0\nv 100002 0 0\nv 100004 0 0\nv 100004 2 0\nv 1e5 2 0\nf 1 2 3 4 5\nf 5 4 3 2 1\n";
        // (The first fan's triangle (1, 2, 3) is degenerate and dropped; the reversed face's are not.)
        assert_eq!(load(obj_file(convex).path()).unwrap().triangle_count(), 2 + 3);
        let forward = "f 1 2 3 4\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n";
        assert_eq!(load(obj_file(forward).path()).unwrap().triangle_count(), 2);
    }

    #[test]
    fn parse_errors_name_the_line_at_fault() {
        let quad = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";
        let error = |text: &str| load(obj_file(text).path()).unwrap_err().to_string();
        let mut not_utf8 = obj_file(quad);
        not_utf8.write_all(b"f 1 2 3\no caf\xe9\n").unwrap();
        let not_utf8 = load(not_utf8.path()).unwrap_err().to_string();
        assert!(not_utf8.contains("line 6: read error (not UTF-8 text"), "{not_utf8}");
        let position = error(&format!("# a comment\n{quad}v 1 zero 2\nf 1 2 3\n"));
        assert!(position.contains("line 6: position parse error"), "{position}");
        let face = error(&format!("{quad}o quad\nf 1 2/x 3\nf 1 2 3\n"));
        assert!(face.contains("line 6: face parse error"), "{face}");
        // A corner without a position number, which tobj 4.0.5 keeps until the object closes
        // (uncounted, a face line of 3·10⁸ of them took gigabytes), is refused on its line.
        for corner in ["/", "/1", "//1"] {
            let face = error(&format!("{quad}o quad\nf 1 2 {corner}\nf 1 2 3\n"));
            let expected = format!("line 6: face corner `{corner}` has no vertex position number");
            assert!(face.contains(&expected), "{face}");
        }
        let last = error(&format!("{quad}f 1 2 3\nv 0 1"));
        assert!(last.contains("line 6: position parse error"), "the last line, without a line break: {last}");
        // Indices that are 0, past 2³² or relative past the data defined so far (tobj 4.0.5
        // overflowed on them) name their line.
        for (face, line) in [("f 1 2 0", 5), ("f 1 2 4294967297", 5), ("f -5 -1 -2", 5), ("vt 0 0\nf 1/1 2/-2 3/1", 6)]
        {
            let refused = error(&format!("{quad}{face}\n"));
            assert!(
                refused.contains(&format!("line {line}: ")) && refused.contains("names no vertex data"),
                "{refused}"
            );
        }
        assert_eq!(load(obj_file(&format!("{quad}vt 0 0\nf -4/-1 -3/1 -2/-1\n")).path()).unwrap().triangle_count(), 1);
        // An index past the whole file's data names its face: the largest such one.
        let past = error(&format!("{quad}f 1 2 3\nf 1 2 7\nf 1 2 9\nf 1 2 5\n"));
        assert!(past.contains("line 7: a face's index 9 is past the file's 4 vertex positions"), "{past}");
        let past = error(&format!("{quad}vn 0 0 1\nf 1//1 2//2 3//1\n"));
        assert!(past.contains("line 6: a face's index 2 is past the file's 1 normals (`vn`)"), "{past}");
        // One within it, but defined after the object closes, is tobj's error, found as the object
        // closes: at the next `o` line, here line 7.
        let closed = error(&format!("{quad}o a\nf 1 2 5\no b\nv 0 0 1\nf 1 2 3\n"));
        assert!(
            closed.contains("face vertex index out of bounds in a face of the object closed at line 7"),
            "{closed}"
        );
    }

    #[test]
    fn vertices_out_of_range_and_zero_area_faces_are_rejected() {
        // Once `NonFiniteVertex` / `VertexOutOfRange` errors numbering the vertex as tobj does
        // (not the file's order once faces reuse or skip vertices), without the line.
        for (vertex, expected) in [
            ("v nan 1 0", "line 4: `v nan 1 0` has coordinate NaN"),
            ("v 1 inf 0", "line 4: `v 1 inf 0` has coordinate inf"),
            ("v 1 1 1e39", "line 4: `v 1 1 1e39` has coordinate inf"),
            ("v 0 -1.5e8 0", "line 4: `v 0 -1.5e8 0` has coordinate -150000000; each must be finite and within ±1e8"),
        ] {
            let f = obj_file(&format!("v 0 0 0\nv 1 0 0\nv 0 1 0\n{vertex}\nf 1 2 3\nf 4 2 3\n"));
            let err = load(f.path()).unwrap_err();
            assert!(matches!(err, Error::SceneLoad { .. }) && err.to_string().contains(expected), "{err}");
        }
        let at_the_limit = obj_file("v 0 0 0\nv 1e8 0 0\nv 0 -1e8 0\nf 1 2 3\n");
        assert!(load(at_the_limit.path()).is_ok());
        // Named with the face that uses it, found by a relative index too.
        let relative = obj_file("v 0 0 0\nv 1e9 0 0\nv 0 1 0\nf -3 -2 -1\n");
        let err = load(relative.path()).unwrap_err().to_string();
        assert!(err.contains("line 2: `v 1e9 0 0` has coordinate 1000000000; each must be finite and within ±1e8 (the face on line 4 uses it)"), "{err}");
        // A vertex no face uses is not loaded, so it may hold anything (also one a polyline uses).
        let unused = obj_file("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5e8 0 nan\nf 1 2 3\nl 1 4\n");
        assert_eq!(load(unused.path()).unwrap().triangle_count(), 1);
        let f = obj_file("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n");
        assert!(matches!(load(f.path()).unwrap_err(), Error::EmptyScene { dropped_degenerate: 1, .. }));
    }

    #[test]
    fn files_over_the_size_limits_are_refused_before_they_are_built() {
        // 5 positions; a triangle, a quad and a pentagon (1 + 2 + 3 triangles), a polyline (none),
        // faces of one and two corners (one degenerate triangle each, as tobj makes them), and
        // the corners of a face given with texture and normal indices counted once.
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 2 0\nvt 0 0\nvn 0 0 1\n\
                    f 1 2 3\nf 1/1/1 2/1/1 3/1/1 4/1/1\nl 1 2 3 4 5\nf 1 2 3 5 4\nf 1\nf 1 2\n";
        let f = obj_file(text);
        let check = |positions, triangles| {
            check_vertices_and_indices(f.path(), text.as_bytes(), Limits { positions, triangles })
        };
        assert!(check(5, 8).is_ok());
        let scene = f.path().display().to_string();
        for (limits, what) in [
            ((4, 8), "more than 4 vertex positions (passed at line 5)"),
            ((5, 7), "more than 7 triangles (passed at line 13)"),
            ((5, 5), "more than 5 triangles (passed at line 11)"),
        ] {
            match check(limits.0, limits.1) {
                Err(Error::SceneTooLarge { scene: s, what: w }) => assert_eq!((s, w.as_str()), (scene.clone(), what)),
                other => panic!("{limits:?}: expected SceneTooLarge, got {other:?}"),
            }
        }
    }

    #[test]
    fn out_of_range_face_and_empty_file_are_rejected() {
        let f = obj_file("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
        let err = load(f.path()).unwrap_err().to_string();
        assert!(err.contains("line 4: a face's index 9 is past the file's 3 vertex positions (`v` lines)"), "{err}");
        let f = obj_file("# nothing here\n");
        assert!(matches!(load(f.path()).unwrap_err(), Error::EmptyScene { .. }));
    }
}
