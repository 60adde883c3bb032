//! The writer's side of a render: frames on their way to disk ([`Job`]), written
//! atomically with their previews, and the folders made and checked for them.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::aov::FrameHeader;
use super::errors::OutputFile;
use super::options::RenderOptions;
use super::output::{encode_exr, encode_preview};
use super::shade::FrameBuffers;
use super::stats::FrameStats;
use super::RenderError;

/// A frame on its way to the writer.
pub(super) struct Job {
    pub(super) index: usize,
    pub(super) path: PathBuf,
    pub(super) frame: FrameBuffers,
    pub(super) header: FrameHeader,
    pub(super) stats: FrameStats,
    pub(super) preview: Option<PathBuf>,
}

fn create_parent(path: &Path) -> Result<(), RenderError> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        crate::atomic::create_folder(parent).map_err(|source| RenderError::Io {
            path: parent.to_path_buf(),
            source,
        })?;
    }
    Ok(())
}

/// Refuses `path` when it is not a regular file, nor nothing, nor a link to a regular
/// file (see [`crate::atomic::write_target`]).
pub(super) fn check_target(path: &Path) -> Result<(), RenderError> {
    crate::atomic::write_target(path)
        .map(drop)
        .map_err(|source| RenderError::NotAFile {
            path: path.to_path_buf(),
            source,
        })
}

/// Checks `path` can be written: refused when it is not a regular file
/// ([`check_target`]); else its folder is created and a file made there (the probe is
/// removed).
pub(super) fn check_writable(path: &Path) -> Result<(), RenderError> {
    check_target(path)?;
    create_parent(path)?;
    let folder = crate::atomic::folder_of(path);
    let probe = folder.join(format!(".subfield-probe-{}", std::process::id()));
    // Said as what failed: the folder exists (or was just made), a file in it did not.
    std::fs::File::create(&probe).map_err(|source| RenderError::Io {
        path: folder.clone(),
        source: std::io::Error::new(
            source.kind(),
            format!("cannot create a file in this folder: {source}"),
        ),
    })?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// Writes `bytes` to `path` atomically; an error names the file and what it is.
pub(super) fn write_file(path: &Path, file: OutputFile, bytes: &[u8]) -> Result<(), RenderError> {
    crate::atomic::write_atomically(path, bytes).map_err(|source| RenderError::Write {
        path: path.to_path_buf(),
        file,
        source,
    })
}

pub(super) fn write_job(job: &Job, opts: &RenderOptions) -> Result<f64, RenderError> {
    let clock = Instant::now();
    create_parent(&job.path)?;
    let bytes = encode_exr(&job.frame, opts.pixel_type, opts.compression, &job.header).map_err(
        |source| RenderError::Exr {
            path: job.path.clone(),
            source,
        },
    )?;
    write_file(&job.path, OutputFile::Frame(job.stats.frame), &bytes)?;
    if let Some(p) = &job.preview {
        let png = encode_preview(&job.frame).map_err(|source| RenderError::Png {
            path: p.clone(),
            source,
        })?;
        write_file(p, OutputFile::Preview, &png)?;
    }
    Ok(clock.elapsed().as_secs_f64() * 1e3)
}
