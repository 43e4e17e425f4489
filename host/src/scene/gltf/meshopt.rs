//! `EXT_meshopt_compression` and its ratified successor `KHR_meshopt_compression`
//! (KhronosGroup/glTF, `extensions/2.0/Vendor/EXT_meshopt_compression` and
//! `extensions/2.0/Khronos/KHR_meshopt_compression`), as `gltfpack -c` writes files: a buffer view
//! whose data is stored compressed elsewhere, decoded here by meshoptimizer's decoders (the
//! `meshopt` crate) into the view's own place, so that accessors read it as any other view. Its
//! own buffer may then be a placeholder without data ("fallback"), which is made of zeros.

use gltf::buffer;
use gltf::json::Value;
use std::collections::BTreeMap;

/// The extensions' names, as files list them in `extensionsUsed` and on buffer views.
pub(super) const EXTENSIONS: [&str; 2] = ["EXT_meshopt_compression", "KHR_meshopt_compression"];

/// The most bytes a valid stream decodes to per byte of it, which bounds what a file may make
/// raywave allocate ([`decode_views`]): an attribute block of the codec's version 1 spends
/// `byteStride / 4` control bytes on up to 256 elements that each repeat the one before (zero
/// deltas: 1 024 bytes per byte, the KHR extension's Appendix A); the index codecs spend at
/// least a byte per triangle, or per index.
const MAX_EXPANSION: usize = 1024;

/// The codec a view's data was compressed with (the extension's `mode`).
#[derive(Clone, Copy)]
enum Mode {
    /// `ATTRIBUTES`: elements of any stride (a multiple of 4 up to 256).
    Attributes,
    /// `TRIANGLES`: a triangle list's indices (`u16` or `u32`).
    Triangles,
    /// `INDICES`: any other index sequence (`u16` or `u32`).
    Indices,
}

/// The transform applied to an `ATTRIBUTES` view's elements after decoding (the extension's
/// `filter`, Appendix B).
#[derive(Clone, Copy)]
enum Filter {
    /// `NONE`: the elements as decoded.
    None,
    /// `OCTAHEDRAL`: unit vectors in octahedral encoding (stride 4 or 8).
    Octahedral,
    /// `QUATERNION`: unit quaternions of three components and an index (stride 8).
    Quaternion,
    /// `EXPONENTIAL`: `f32` components as an exponent and a mantissa (stride a multiple of 4).
    Exponential,
    /// `COLOR`: colours in YCoCg (stride 4 or 8). `KHR_meshopt_compression` defines it, and
    /// its codec version 1, which `EXT_meshopt_compression` does not; both are decoded under
    /// either name, as meshoptimizer decodes them.
    Color,
}

/// A value of an enumerated member of the extension object (`mode`, `filter`), which the
/// extension writes by name.
trait Named: Copy + 'static {
    /// Every value.
    const ALL: &'static [Self];

    /// The name the extension writes for this value.
    fn name(self) -> &'static str;
}

impl Named for Mode {
    const ALL: &'static [Self] = &[Self::Attributes, Self::Triangles, Self::Indices];

    fn name(self) -> &'static str {
        match self {
            Self::Attributes => "ATTRIBUTES",
            Self::Triangles => "TRIANGLES",
            Self::Indices => "INDICES",
        }
    }
}

impl Named for Filter {
    const ALL: &'static [Self] = &[Self::None, Self::Octahedral, Self::Quaternion, Self::Exponential, Self::Color];

    fn name(self) -> &'static str {
        match self {
            Self::None => "NONE",
            Self::Octahedral => "OCTAHEDRAL",
            Self::Quaternion => "QUATERNION",
            Self::Exponential => "EXPONENTIAL",
            Self::Color => "COLOR",
        }
    }
}

/// The value named `written`, or an error naming `field` and the names the extension defines.
fn parse_name<T: Named>(written: &str, field: &str) -> Result<T, String> {
    T::ALL.iter().copied().find(|value| value.name() == written).ok_or_else(|| {
        let names: Vec<&str> = T::ALL.iter().map(|value| value.name()).collect();
        format!("{field} is {written:?}, not one of {}", names.join(", "))
    })
}

/// A buffer view compressed by one of [`EXTENSIONS`], checked against the extension's rules
/// (which meshoptimizer's decoders assert): where its compressed data lies, and the layout it
/// decodes to in the view's own place.
pub(super) struct CompressedView {
    /// The extension object's JSON path (`bufferViews[2].extensions.EXT_meshopt_compression`),
    /// which errors name.
    field: String,
    /// The buffer that holds the compressed data, and the data's byte offset and length in it.
    source: (usize, usize, usize),
    /// The view's own buffer and byte offset, where the decoded data goes.
    target: (usize, usize),
    /// Bytes per decoded element.
    stride: usize,
    /// Decoded elements: `count × stride` is the view's `byteLength`.
    count: usize,
    /// The codec.
    mode: Mode,
    /// The transform after decoding.
    filter: Filter,
}

impl CompressedView {
    /// `view`'s compression, or `None` where it has neither extension object. An error names
    /// the field where the object is not what the extension defines: a required member missing
    /// or of the wrong type, an unknown `mode` or `filter`, a `count` and `byteStride` that do not
    /// make the view's `byteLength`, or a stride or count that the extension forbids for its
    /// mode and filter.
    pub(super) fn of(view: &buffer::View) -> Result<Option<Self>, String> {
        let Some((name, object)) = EXTENSIONS.iter().find_map(|name| Some((name, view.extension_value(name)?))) else {
            return Ok(None);
        };
        let field = format!("bufferViews[{}].extensions.{name}", view.index());
        let member = |key: &str| object.get(key);
        let integer = |key: &str, default: Option<usize>| match member(key) {
            None => default.ok_or_else(|| format!("{field}.{key}: missing; the extension requires it")),
            Some(value) => value
                .as_u64()
                .and_then(|n| usize::try_from(n).ok())
                .ok_or_else(|| format!("{field}.{key} is {value}, not a non-negative integer")),
        };
        let text = |key: &str, default: Option<&'static str>| match member(key) {
            None => {
                default.map(str::to_owned).ok_or_else(|| format!("{field}.{key}: missing; the extension requires it"))
            }
            Some(Value::String(text)) => Ok(text.clone()),
            Some(value) => Err(format!("{field}.{key} is {value}, not a string")),
        };
        let mode = parse_name(&text("mode", None)?, &format!("{field}.mode"))?;
        let filter = parse_name(&text("filter", Some("NONE"))?, &format!("{field}.filter"))?;
        let (stride, count) = (integer("byteStride", None)?, integer("count", None)?);
        let source = (integer("buffer", None)?, integer("byteOffset", Some(0))?, integer("byteLength", None)?);
        let compressed =
            Self { field, source, target: (view.buffer().index(), view.offset()), stride, count, mode, filter };
        compressed.check_layout(view.length())?;
        Ok(Some(compressed))
    }

    /// Checks the extension's rules on the layout (its "For the extension object to be valid"
    /// list), against the view's `byteLength` `view_length`.
    fn check_layout(&self, view_length: usize) -> Result<(), String> {
        let Self { field, stride, count, mode, filter, .. } = self;
        let error = |what: String| Err(format!("{field}: {what}"));
        let (mode_name, filter_name) = (mode.name(), filter.name());
        if count.checked_mul(*stride) != Some(view_length) {
            return error(format!(
                "count {count} times byteStride {stride} is not the view's byteLength {view_length}, as the \
                 extension requires"
            ));
        }
        let stride_allowed = match (mode, filter) {
            (Mode::Attributes, Filter::None | Filter::Exponential) => (4..=256).contains(stride) && stride % 4 == 0,
            (Mode::Attributes, Filter::Octahedral | Filter::Color) => [4, 8].contains(stride),
            (Mode::Attributes, Filter::Quaternion) => *stride == 8,
            (Mode::Triangles | Mode::Indices, Filter::None) => [2, 4].contains(stride),
            (Mode::Triangles | Mode::Indices, _) => {
                return error(format!("mode {mode_name} takes no filter, and its filter is {filter_name}"));
            }
        };
        if !stride_allowed {
            return error(format!(
                "byteStride {stride} is not one the extension allows for mode {mode_name} and filter {filter_name}"
            ));
        }
        if matches!(mode, Mode::Triangles) && count % 3 != 0 {
            return error(format!("count {count} is not a whole number of triangles, as mode TRIANGLES requires"));
        }
        Ok(())
    }

    /// The view's compressed data in `buffers` (its source buffer loaded); an error if it lies
    /// outside that buffer, or is too short for what it should decode to ([`MAX_EXPANSION`]).
    fn compressed_data<'a>(&self, buffers: &'a [buffer::Data]) -> Result<&'a [u8], String> {
        let Self { field, source: (buffer, offset, length), .. } = self;
        let data =
            buffers.get(*buffer).and_then(|data| data.get(*offset..offset.checked_add(*length)?)).ok_or_else(|| {
                format!(
                    "{field}: its compressed data (buffer {buffer}, bytes {offset}+{length}) lies outside that buffer"
                )
            })?;
        let decoded_length = self.decoded_length();
        if decoded_length > length.saturating_mul(MAX_EXPANSION) {
            return Err(format!(
                "{field}: {length} bytes of compressed data cannot decode to the view's {decoded_length} (at most \
                 {MAX_EXPANSION} bytes per byte)"
            ));
        }
        Ok(data)
    }

    /// Bytes the view decodes to, its `byteLength` ([`Self::check_layout`]).
    fn decoded_length(&self) -> usize {
        self.count * self.stride
    }

    /// The buffer that holds the compressed data, which must be loaded.
    pub(super) fn source_buffer(&self) -> usize {
        self.source.0
    }

    /// The view's data, decoded from `buffers` (its source buffer loaded) and filtered, as
    /// `count × stride` bytes in whole `u32` words (the filters work on aligned words); an error
    /// if the compressed data lies outside its buffer, is too short for what it should decode to
    /// ([`MAX_EXPANSION`]), or does not decode.
    fn decode(&self, buffers: &[buffer::Data]) -> Result<Vec<u32>, String> {
        let Self { field, source: (_, _, length), stride, count, mode, filter, .. } = self;
        let data = self.compressed_data(buffers)?;
        let mut decoded = vec![0u32; self.decoded_length().div_ceil(4)];
        let destination = decoded.as_mut_ptr().cast();
        // SAFETY: `destination` holds `count × stride` bytes (in whole, aligned words), all that
        // the decoders and filters write; `data` is a live slice, of which they read at most its
        // length. The strides and counts meet the preconditions the C++ asserts
        // ([`Self::check_layout`]).
        let status = unsafe {
            match mode {
                Mode::Attributes => {
                    meshopt::ffi::meshopt_decodeVertexBuffer(destination, *count, *stride, data.as_ptr(), data.len())
                }
                Mode::Triangles => {
                    meshopt::ffi::meshopt_decodeIndexBuffer(destination, *count, *stride, data.as_ptr(), data.len())
                }
                Mode::Indices => {
                    meshopt::ffi::meshopt_decodeIndexSequence(destination, *count, *stride, data.as_ptr(), data.len())
                }
            }
        };
        if status != 0 {
            return Err(format!(
                "{field}: its {length} bytes of compressed data do not decode as {} (meshoptimizer's status {status})",
                mode.name()
            ));
        }
        // SAFETY: as above; each filter reads and writes the `count` elements of `stride` bytes.
        unsafe {
            match filter {
                Filter::None => {}
                Filter::Octahedral => meshopt::ffi::meshopt_decodeFilterOct(destination, *count, *stride),
                Filter::Quaternion => meshopt::ffi::meshopt_decodeFilterQuat(destination, *count, *stride),
                Filter::Exponential => meshopt::ffi::meshopt_decodeFilterExp(destination, *count, *stride),
                Filter::Color => meshopt::ffi::meshopt_decodeFilterColor(destination, *count, *stride),
            }
        }
        Ok(decoded)
    }
}

/// Decodes `views` (each once) into their places in `buffers`, where the sources are loaded. A
/// view's own buffer that was not loaded (a fallback or placeholder: no accessor reads it
/// uncompressed) is made of zeros up to the last decoded view's end, which must lie within its
/// `byteLength` (`declared_lengths`).
///
/// Before anything is allocated, every view's compressed data is checked
/// ([`CompressedView::compressed_data`]), and both what the views decode to and the placeholders
/// made for them must stay within [`MAX_EXPANSION`] times the bytes of the buffers that hold the
/// compressed data, each counted once: views may share one stream, and a view may lie far into a
/// placeholder, so bounds per view alone let a small file allocate without end.
pub(super) fn decode_views(
    views: &BTreeMap<usize, CompressedView>,
    buffers: &mut [buffer::Data],
    declared_lengths: &[usize],
) -> Result<(), String> {
    let mut sources = std::collections::BTreeSet::new();
    let mut decoded_total = 0usize;
    let mut placeholders: BTreeMap<usize, (usize, &str)> = BTreeMap::new();
    for view in views.values() {
        view.compressed_data(buffers)?;
        sources.insert(view.source.0);
        decoded_total = decoded_total.saturating_add(view.decoded_length());
        if buffers[view.target.0].is_empty() {
            let (end, _) = placeholders.entry(view.target.0).or_insert((0, view.field.as_str()));
            *end = (*end).max(view.target.1.saturating_add(view.decoded_length()));
        }
    }
    let source_bytes: usize = sources.iter().map(|&buffer| buffers[buffer].len()).sum();
    let budget = source_bytes.saturating_mul(MAX_EXPANSION);
    let placeholder_total = placeholders.values().fold(0usize, |total, (end, _)| total.saturating_add(*end));
    if decoded_total > budget || placeholder_total > budget {
        return Err(format!(
            "its compressed buffer views decode to {decoded_total} bytes, into placeholder buffers of \
             {placeholder_total}, more than {MAX_EXPANSION} bytes per byte of the {source_bytes} bytes of the \
             buffers that hold their data"
        ));
    }
    for (&buffer, &(end, field)) in &placeholders {
        if end > declared_lengths[buffer] {
            return Err(format!(
                "{field}: buffers[{buffer}] is made of decoded views up to byte {end}, past its byteLength {}",
                declared_lengths[buffer]
            ));
        }
        buffers[buffer] = buffer::Data(vec![0; end]);
    }
    for view in views.values() {
        let decoded = view.decode(buffers)?;
        let (buffer, offset) = view.target;
        let bytes = &bytemuck::cast_slice::<u32, u8>(&decoded)[..view.decoded_length()];
        let place = buffers[buffer].0.get_mut(offset..offset.saturating_add(bytes.len())).ok_or_else(|| {
            format!("{}: the view (bytes {offset}+{}) lies outside buffers[{buffer}]", view.field, bytes.len())
        })?;
        place.copy_from_slice(bytes);
    }
    Ok(())
}
