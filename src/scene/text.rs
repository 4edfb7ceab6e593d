//! Text files of scenes (OBJ, MTL, `cameras.json`): UTF-8 checks and errors
//! that name a file and line.

use std::path::Path;

use crate::error::{Error, Result};

/// An `Error::Scene` for `path` at 1-based `line`.
pub(crate) fn scene_error(path: &Path, line: Option<usize>, message: impl Into<String>) -> Error {
    Error::Scene { path: path.to_path_buf(), line, message: message.into() }
}

/// The 1-based line of byte offset `pos` in `bytes`.
pub(crate) fn line_of(bytes: &[u8], pos: usize) -> usize {
    bytes[..pos.min(bytes.len())].iter().filter(|&&b| b == b'\n').count() + 1
}

/// `bytes` as UTF-8 text without a leading byte-order mark, or an error naming
/// the line of the first invalid byte.
pub(crate) fn as_text<'a>(path: &Path, bytes: &'a [u8]) -> Result<&'a str> {
    match std::str::from_utf8(bytes) {
        Ok(text) => Ok(text.strip_prefix('\u{feff}').unwrap_or(text)),
        Err(e) => {
            Err(scene_error(path, Some(line_of(bytes, e.valid_up_to())), "not UTF-8 text (is this a binary file?)"))
        }
    }
}
