//! What can go wrong reading or writing a baked file. Every variant carries the evidence:
//! the section it concerns (`"entries[17]"`), the value found, the value expected.

use std::path::PathBuf;

use super::SceneHash;
use crate::psf::PsfError;

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FormatError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("not a baked subfield file: magic bytes {0:02x?}")]
    Magic([u8; 8]),
    /// A glTF scene where a baked file was expected: it is to be baked first.
    #[error("this is a glTF scene ({kind}), not a baked file: bake it first (subfield bake SCENE -o FILE.psf)")]
    GltfScene {
        /// `"GLB"` or `"JSON"`.
        kind: &'static str,
    },
    #[error("format version {found} is not supported (this build reads versions 2 to {supported}); re-bake the scene")]
    Version { found: u32, supported: u32 },
    #[error("file is truncated in {section}: needs {needed} bytes, has {have}")]
    Truncated {
        section: String,
        needed: u64,
        have: u64,
    },
    #[error("checksum mismatch in {section}: stored {expected:#018x}, computed {found:#018x}")]
    Checksum {
        section: String,
        expected: u64,
        found: u64,
    },
    #[error("invalid {section}: {detail}")]
    Invalid { section: String, detail: String },
    #[error("not supported: {what}")]
    NotSupported { what: String },
    #[error("the baked file was made from another static scene (its scene hash is {found}, the scene's is {expected}); re-bake it")]
    StaleScene {
        expected: SceneHash,
        found: SceneHash,
    },
    #[error(transparent)]
    Psf(#[from] PsfError),
}

impl FormatError {
    pub(crate) fn invalid(section: impl Into<String>, detail: impl Into<String>) -> FormatError {
        FormatError::Invalid {
            section: section.into(),
            detail: detail.into(),
        }
    }

    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> FormatError {
        FormatError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}
