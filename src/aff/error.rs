//! Errors of AFF import. Syntax errors name the file and line (of an included file where
//! the problem is there).

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum AffError {
    /// The top-level file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// Malformed input: unknown keyword, too few numbers, a missing include, a `k` block
    /// naming nothing, an index out of range...
    #[error("{path}:{line}: {message}")]
    Syntax {
        path: PathBuf,
        line: u32,
        message: String,
    },

    /// A texture named at `path:line` could not be read or decoded.
    #[error("{path}:{line}: texture {name:?}: {reason}")]
    Texture {
        path: PathBuf,
        line: u32,
        name: String,
        reason: String,
    },

    /// The scene is fine as AFF but cannot be written as glTF (too large, degenerate time
    /// range...).
    #[error("{path}: cannot convert to glTF: {reason}")]
    Convert { path: PathBuf, reason: String },

    /// The glTF writer refused the converted document.
    #[error(transparent)]
    Gltf(#[from] crate::scene::SceneError),
}
