//! Exit codes, the same for every command (DESIGN.md §4): what a farm needs to decide
//! whether to retry a task. The library's errors are typed; this is the one place that
//! maps them to a class, walking an error's chain of causes from the outermost and
//! taking the first cause it knows.
//!
//! | code | class | retry? |
//! |---|---|---|
//! | 0 | done | |
//! | 1 | internal error (a bug) | report it |
//! | 2 | usage: unknown flag, bad flag syntax (clap) | no |
//! | 3 | bad input: scene, bake, option values | no |
//! | 4 | a bake or scene file whose hash is not the one expected | re-bake or resubmit |
//! | 5 | I/O or resource failure: disk full, out of memory, GPU lost | yes, perhaps elsewhere |
//! | 129, 130, 143 | stopped by SIGHUP, SIGINT, SIGTERM (128 + the signal) | as the sender wishes |

use std::io::ErrorKind;

use subfield::farm::FarmError;
use subfield::format::{BadContentHash, FormatError};
use subfield::gen::museum::MuseumError;
use subfield::import::ImportError;
use subfield::psf::PsfError;
use subfield::render::{EnvironmentError, OptionError, RenderError};
use subfield::scene::SceneError;

/// Why a command failed, as a farm reads it (see the module's table).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExitClass {
    Internal,
    Usage,
    BadInput,
    HashMismatch,
    Resource,
}

impl ExitClass {
    pub fn code(self) -> u8 {
        match self {
            ExitClass::Internal => 1,
            ExitClass::Usage => 2,
            ExitClass::BadInput => 3,
            ExitClass::HashMismatch => 4,
            ExitClass::Resource => 5,
        }
    }

    /// The class in words, as the JSON log names it.
    pub fn name(self) -> &'static str {
        match self {
            ExitClass::Internal => "internal",
            ExitClass::Usage => "usage",
            ExitClass::BadInput => "bad-input",
            ExitClass::HashMismatch => "hash-mismatch",
            ExitClass::Resource => "resource",
        }
    }
}

/// The table `--help` ends with.
pub const HELP: &str = "\
Exit codes (the same for every command):
  0            done
  1            internal error (a bug: please report it)
  2            usage: unknown flag, bad flag syntax, a flag without its value
  3            bad input: scene, bake or option values, a value a flag cannot take (retrying cannot help)
  4            a bake or scene file whose hash is not the one expected (re-bake or resubmit)
  5            I/O or resource failure: disk full, out of memory, GPU lost (retry, perhaps elsewhere)
  129/130/143  stopped by SIGHUP/SIGINT/SIGTERM after the frames in flight (--resume carries on)";

/// The class of a command's error: the first cause in its chain (outermost first) that
/// is one of the library's typed errors or an I/O error decides. A message the command
/// line made itself with no typed cause (a flag value it checked) is bad input.
/// The class of an error clap finds in the arguments: a value it cannot take (not a
/// number, not one of the choices, refused by the flag's parser) is an option value, 3;
/// the rest (an unknown flag, a flag without its value, two that conflict) is usage, 2.
pub fn clap_class(e: &clap::Error) -> ExitClass {
    use clap::error::{ContextKind, ContextValue, ErrorKind::*};
    match e.kind() {
        // clap says "a value is required" as an invalid empty value: that is syntax.
        InvalidValue => match e.get(ContextKind::InvalidValue) {
            Some(ContextValue::String(v)) if !v.is_empty() => ExitClass::BadInput,
            _ => ExitClass::Usage,
        },
        ValueValidation | InvalidUtf8 => ExitClass::BadInput,
        _ => ExitClass::Usage,
    }
}

pub fn exit_class(e: &anyhow::Error) -> ExitClass {
    e.chain().find_map(classify).unwrap_or(ExitClass::BadInput)
}

fn classify(e: &(dyn std::error::Error + 'static)) -> Option<ExitClass> {
    use ExitClass::*;
    if let Some(e) = e.downcast_ref::<RenderError>() {
        return Some(render(e));
    }
    if let Some(e) = e.downcast_ref::<FormatError>() {
        return Some(format(e));
    }
    if let Some(e) = e.downcast_ref::<FarmError>() {
        return Some(match e {
            FarmError::Io { source, .. } => io(source),
            FarmError::HashMismatch { .. } => HashMismatch,
            // A scheduler program missing or failing on this host: another may do.
            FarmError::Spawn { .. } | FarmError::Command { .. } => Resource,
            FarmError::Invalid(_) => BadInput,
            _ => Internal,
        });
    }
    if let Some(e) = e.downcast_ref::<ImportError>() {
        return Some(import(e));
    }
    if let Some(e) = e.downcast_ref::<MuseumError>() {
        return Some(match e {
            MuseumError::Gltf(g) => import(g),
            _ => BadInput,
        });
    }
    if let Some(e) = e.downcast_ref::<PsfError>() {
        return Some(psf(e));
    }
    if let Some(e) = e.downcast_ref::<EnvironmentError>() {
        return Some(match e {
            EnvironmentError::Io { source, .. } => io(source),
            _ => BadInput,
        });
    }
    if let Some(e) = e.downcast_ref::<exr::error::Error>() {
        return Some(match e {
            exr::error::Error::Io(source) => io(source),
            _ => BadInput,
        });
    }
    if e.is::<OptionError>()
        || e.is::<SceneError>()
        || e.is::<BadContentHash>()
        || e.is::<subfield::atomic::NotRegular>()
    {
        return Some(BadInput);
    }
    #[cfg(feature = "gpu")]
    if let Some(e) = e.downcast_ref::<subfield::gpu::GpuError>() {
        return Some(gpu(e));
    }
    if let Some(e) = e.downcast_ref::<std::io::Error>() {
        return Some(io(e));
    }
    None
}

fn render(e: &RenderError) -> ExitClass {
    use ExitClass::*;
    match e {
        RenderError::Option(_)
        | RenderError::UnknownCamera { .. }
        | RenderError::Scene(_)
        | RenderError::NotAFile { .. }
        | RenderError::NoGpuSupport(_) => BadInput,
        RenderError::Format(f) | RenderError::BakedFile { source: f, .. } => format(f),
        RenderError::Psf(p) => psf(p),
        RenderError::Io { source, .. } | RenderError::Write { source, .. } => io(source),
        RenderError::Exr {
            source: exr::error::Error::Io(source),
            ..
        }
        | RenderError::Png {
            source: image::ImageError::IoError(source),
            ..
        } => io(source),
        // Our own frame that the encoder refuses.
        RenderError::Exr { .. } | RenderError::Png { .. } => Internal,
        #[cfg(feature = "gpu")]
        RenderError::Gpu { source, .. } => gpu(source),
        // Cancelled is answered as a signal before it gets here; the writer gone is a bug.
        _ => Internal,
    }
}

fn format(e: &FormatError) -> ExitClass {
    match e {
        FormatError::Io { source, .. } => io(source),
        FormatError::StaleScene { .. } => ExitClass::HashMismatch,
        FormatError::Psf(p) => psf(p),
        _ => ExitClass::BadInput,
    }
}

fn psf(e: &PsfError) -> ExitClass {
    match e {
        // Parameters, non-finite triangles, too many, or a file's data that does not add up.
        PsfError::Params(_)
        | PsfError::NonFinite { .. }
        | PsfError::TooManyTriangles { .. }
        | PsfError::Inconsistent { .. } => ExitClass::BadInput,
        _ => ExitClass::Internal,
    }
}

fn import(e: &ImportError) -> ExitClass {
    match e {
        ImportError::Io { source, .. }
        | ImportError::MissingFile { source, .. }
        | ImportError::WriteIo { source, .. } => io(source),
        _ => ExitClass::BadInput,
    }
}

/// Every GPU failure may go away on another machine (another driver, more memory, a GPU
/// at all), so all are resource failures; a scene too large for every GPU would be bad
/// input, but this host cannot tell that apart.
#[cfg(feature = "gpu")]
fn gpu(e: &subfield::gpu::GpuError) -> ExitClass {
    match e {
        subfield::gpu::GpuError::Triangles(p) => psf(p),
        _ => ExitClass::Resource,
    }
}

/// A path that names nothing or holds data that is not what it should be is bad input;
/// everything else an I/O error can say (no space, a quota or file-size limit, no
/// permission, out of memory, a device or network failing) may pass or be different on
/// another machine.
fn io(e: &std::io::Error) -> ExitClass {
    match e.kind() {
        ErrorKind::NotFound
        | ErrorKind::InvalidData
        | ErrorKind::InvalidInput
        | ErrorKind::IsADirectory
        | ErrorKind::NotADirectory
        | ErrorKind::UnexpectedEof => ExitClass::BadInput,
        _ => ExitClass::Resource,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_typed_cause_decides() {
        use anyhow::Context;
        let full: anyhow::Result<()> = Err(std::io::Error::from(ErrorKind::StorageFull))
            .context("cannot write out/frame.0001.exr");
        assert_eq!(exit_class(&full.unwrap_err()), ExitClass::Resource);
        let missing: anyhow::Result<()> =
            Err(std::io::Error::from(ErrorKind::NotFound)).context("scene.glb");
        assert_eq!(exit_class(&missing.unwrap_err()), ExitClass::BadInput);
        let stale = RenderError::BakedFile {
            path: "a.psf".into(),
            source: FormatError::StaleScene {
                expected: Default::default(),
                found: Default::default(),
            },
        };
        let e = anyhow::Error::new(stale).context("cannot render a.glb");
        assert_eq!(exit_class(&e), ExitClass::HashMismatch);
        assert_eq!(
            exit_class(&anyhow::Error::new(RenderError::WriterGone)),
            ExitClass::Internal
        );
        assert_eq!(
            exit_class(&anyhow::anyhow!("--tasks 0: a job needs at least one task")),
            ExitClass::BadInput
        );
    }
}
