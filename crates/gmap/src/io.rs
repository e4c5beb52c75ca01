//! The `.tmg` file format: a whole G-map with its embeddings, round-trip exact.

use std::path::Path;

use crate::GMap;

/// Why a map could not be saved or loaded.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The OS refused.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// Not a `.tmg` file.
    #[error("not a topomech G-map file (bad magic header)")]
    Magic,
    /// A version this build cannot read.
    #[error("unsupported .tmg version {0} (this build reads version {1})")]
    Version(u32, u32),
    /// The file ends early.
    #[error("file truncated at byte {0}")]
    Truncated(usize),
    /// The content is inconsistent.
    #[error("corrupt file at byte {at}: {why}")]
    Corrupt {
        /// Byte offset.
        at: usize,
        /// What is wrong.
        why: String,
    },
}

/// Writes `g` to bytes.
pub fn to_bytes(g: &GMap) -> Vec<u8> {
    let _ = g;
    todo!()
}

/// Reads a map from bytes.
pub fn from_bytes(b: &[u8]) -> Result<GMap, FormatError> {
    let _ = b;
    todo!()
}

/// Saves `g` to `path`.
pub fn save(g: &GMap, path: &Path) -> Result<(), FormatError> {
    std::fs::write(path, to_bytes(g)).map_err(|source| FormatError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// Loads a map from `path`.
pub fn load(path: &Path) -> Result<GMap, FormatError> {
    let b = std::fs::read(path).map_err(|source| FormatError::Io {
        path: path.display().to_string(),
        source,
    })?;
    from_bytes(&b)
}
