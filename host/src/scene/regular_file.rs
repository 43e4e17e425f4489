//! Reading a file a scene refers to (an OBJ's material library, a glTF's external buffer): only a
//! regular file, and at most the bytes the scene can use. The third-party loaders read such a
//! file whole, so `/dev/zero` filled memory, and opening a FIFO blocked until something wrote to
//! it.

use std::io::Read;
use std::path::Path;

/// Why a referenced file could not be read.
#[derive(Debug)]
pub(super) enum ReadError {
    /// The path names something other than a regular file (a device, a FIFO, a folder).
    NotRegular,
    /// The operating system's reason.
    Io(std::io::Error),
}

impl std::fmt::Display for ReadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NotRegular => f.write_str("not a regular file"),
            Self::Io(e) => e.fmt(f),
        }
    }
}

/// The first `limit` bytes of the regular file at `path`. Whether it is one is checked before
/// opening it, since opening a FIFO blocks.
pub(super) fn read_regular_file(path: &Path, limit: u64) -> Result<Vec<u8>, ReadError> {
    if !std::fs::metadata(path).map_err(ReadError::Io)?.is_file() {
        return Err(ReadError::NotRegular);
    }
    let mut data = Vec::new();
    std::fs::File::open(path).and_then(|file| file.take(limit).read_to_end(&mut data)).map_err(ReadError::Io)?;
    Ok(data)
}
