//! A glTF file's JSON as raywave hands it to the `gltf` crate: what valid files write that
//! gltf-json 1.4.1 refuses, and that raywave does not read, blanked out in place — each byte
//! replaced by a space, line breaks kept — so that every error the crate reports still points at
//! the file's own line and column (in a GLB, the JSON chunk keeps its length).
//!
//! - **`animations`**: raywave renders no animation, and gltf-json requires each channel's
//!   `target.node` and a `target.path` it knows, where glTF 2.0 makes `node` optional ("When
//!   undefined, the animated object MAY be defined by an extension") and `KHR_animation_pointer`
//!   files use both (`"path": "pointer"`): such files were refused whole. The array becomes `[]`.
//! - **A UTF-8 byte-order mark** before the JSON (which Windows editors write): serde_json
//!   refused the file at line 1, column 1, without saying why. glTF 2.0 asks for UTF-8 without
//!   one; raywave reads OBJ and MTL files past it too.
//! - **NUL bytes padding a GLB's JSON chunk**, which glTF 2.0 pads with spaces and some
//!   exporters pad with zeros: serde_json refused "trailing characters".
//!
//! It also reads the file's `asset.version` before the crate reads the JSON as glTF 2.0
//! ([`Readable::asset_version`]).

use serde_json::value::RawValue;
use std::borrow::Cow;
use std::collections::HashMap;

use crate::scene::UTF8_BYTE_ORDER_MARK;

/// A glTF file's bytes with their JSON made readable ([`readable`]), and what was read of the
/// JSON on the way.
pub(super) struct Readable<'a> {
    /// The file's bytes, its JSON made readable as the module documentation says; borrowed where
    /// nothing changes.
    pub(super) bytes: Cow<'a, [u8]>,
    /// The JSON's `asset.version`, where it has one: the string, or the JSON text of another
    /// value (collada2gltf wrote glTF 1.0's as the number `1`). Read before the crate reads the
    /// file as glTF 2.0, whose members a glTF 1.0 file writes otherwise (`meshes` an object, not
    /// an array), so that such a file can be refused for its version.
    pub(super) asset_version: Option<String>,
}

/// `bytes`, a `.gltf` file or a GLB (whose header [`super::check_glb_header`] checked), with its
/// JSON made readable as the module documentation says, and its `asset.version`.
pub(super) fn readable(bytes: &[u8]) -> Readable<'_> {
    let json = json_span(bytes);
    let mut text = Cow::Borrowed(bytes);
    if bytes[json.clone()].starts_with(UTF8_BYTE_ORDER_MARK) {
        blank(&mut text.to_mut()[json.start..json.start + UTF8_BYTE_ORDER_MARK.len()]);
    }
    let padding = bytes[json.clone()].iter().rev().take_while(|&&b| b == 0).count();
    if json.start > 0 && padding > 0 {
        blank(&mut text.to_mut()[json.end - padding..json.end]);
    }
    let Members { animations, asset_version } = Members::read(&text[json.clone()]);
    if let Some(animations) = animations {
        let array = &mut text.to_mut()[json.start + animations.start..json.start + animations.end];
        blank(array);
        array[0] = b'[';
        array[array.len() - 1] = b']';
    }
    Readable { bytes: text, asset_version }
}

/// Where the JSON lies in `bytes`: all of it for a `.gltf` file, the first chunk's data for a
/// GLB whose first chunk is JSON and lies within the file (else all of it, for the crate to
/// refuse).
fn json_span(bytes: &[u8]) -> std::ops::Range<usize> {
    let whole = 0..bytes.len();
    let [b'g', b'l', b'T', b'F', _, _, _, _, _, _, _, _, l0, l1, l2, l3, b'J', b'S', b'O', b'N', ..] = *bytes else {
        return whole;
    };
    let end = 20 + u32::from_le_bytes([l0, l1, l2, l3]) as usize;
    if end <= bytes.len() {
        20..end
    } else {
        whole
    }
}

/// What [`readable`] reads of the top-level members of the JSON, in one pass over it.
#[derive(Default)]
struct Members {
    /// Where the `animations` array lies in the JSON text.
    animations: Option<std::ops::Range<usize>>,
    /// [`Readable::asset_version`].
    asset_version: Option<String>,
}

impl Members {
    /// The members of the JSON `text`; none if it is not a JSON object (the crate then reports
    /// what is wrong with it). A byte-order mark blanked before is whitespace now.
    fn read(text: &[u8]) -> Self {
        let Ok(text) = std::str::from_utf8(text) else { return Self::default() };
        let Some(members) = object_members(text) else { return Self::default() };
        let animations = members.get("animations").map(|array| array.get()).filter(|array| array.starts_with('['));
        let animations = animations.map(|array| {
            let start = array.as_ptr() as usize - text.as_ptr() as usize;
            start..start + array.len()
        });
        let asset_version = members
            .get("asset")
            .and_then(|asset| object_members(asset.get()))
            .and_then(|asset| asset.get("version").map(|version| version.get()))
            .map(|version| serde_json::from_str(version).unwrap_or_else(|_| version.to_owned()));
        Self { animations, asset_version }
    }
}

/// The members of the JSON object `text`, each as its raw JSON text; none if `text` is not one.
fn object_members(text: &str) -> Option<HashMap<String, &RawValue>> {
    serde_json::from_str(text).ok()
}

/// Replaces every byte of `bytes` but line breaks by a space (JSON whitespace).
fn blank(bytes: &mut [u8]) {
    for b in bytes.iter_mut().filter(|b| !matches!(b, b'\n' | b'\r')) {
        *b = b' ';
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::glb_container;
    use super::*;

    /// The animations become `[]` with every line break where it was, a byte-order mark and a
    /// GLB's NUL padding spaces; text without any of them is borrowed as it is.
    #[test]
    fn what_raywave_does_not_read_is_blanked_in_place() {
        let text = b"{\"asset\": {\"version\": \"2.0\"},\n \"animations\": [{\"channels\": [\n{}]}],\n \"x\": 1}";
        let read = readable(text).bytes;
        // `[{"channels": [` (14 bytes after the bracket), the line break, then `{}]}` and `]`.
        let array = format!("[{}\n{}]", " ".repeat(14), " ".repeat(4));
        let expected = format!("{{\"asset\": {{\"version\": \"2.0\"}},\n \"animations\": {array},\n \"x\": 1}}");
        assert_eq!(std::str::from_utf8(&read).unwrap(), expected);
        let with_mark = [UTF8_BYTE_ORDER_MARK, b"{\"asset\": {}}"].concat();
        assert_eq!(&readable(&with_mark).bytes[..], b"   {\"asset\": {}}");
        let padded = glb_container(b"{\"a\":1}", 0, None);
        assert_eq!(&readable(&padded).bytes[..], &glb_container(b"{\"a\":1}", b' ', None)[..]);
        // A string that holds "animations" is no member; neither is a nested one.
        for unchanged in [&b"{\"asset\": \"animations\", \"b\": {\"animations\": []}}"[..], b"not json", b""] {
            assert!(matches!(readable(unchanged).bytes, Cow::Borrowed(_)), "{:?}", String::from_utf8_lossy(unchanged));
        }
        assert!(matches!(readable(&glb_container(b"{\"a\":1}", b' ', None)).bytes, Cow::Borrowed(_)));
    }
}
