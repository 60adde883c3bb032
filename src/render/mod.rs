//! The renderer: camera, Whitted shading, EXR frames streamed to disk (DESIGN.md §4,
//! `subfield render`).
//!
//! ```no_run
//! # use subfield::render::{render_sequence, RenderOptions, RenderEvent};
//! let scene = subfield::import::load("scene.glb".as_ref())?;
//! let opts = RenderOptions { output: "out/frame.####.exr".into(), ..Default::default() };
//! let summary = render_sequence(&scene, &opts, &mut |e: RenderEvent<'_>| {
//!     if let RenderEvent::Frame(f) = e { println!("frame {} done", f.frame) }
//! })?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Flow: [`plan`] checks every option against the scene without writing anything
//! (range, shard, pattern, camera, plot format; the frames are a lazy [`FramePlan`], so
//! nothing grows with their count); [`render_sequence`] then opens or bakes the static
//! part, checks the outputs (writable folders; no folder, FIFO, socket or device where
//! a file goes), and for each frame poses the scene, updates the dynamic layer, traces
//! and shades (`render::shade`) in parallel and hands the finished frame to a writer thread over a channel of capacity 1, so one
//! frame is written while the next is traced and memory stays flat. `--stats` rows are
//! streamed as frames are written; [`RenderOptions::cancel`] stops the loop between
//! frames.
//!
//! Files: `planning` (pattern, camera source, frames, the checks before writing, resume
//! skips), `sequence` (the static part and the frame loop), `writer` (jobs, atomic
//! writes, folders), `aov` (header matrices, projection, Cryptomatte ids), `wavefront` (one frame traced level by level), `shade` (Whitted shading of a hit, with
//! glossy reflection and area lights), `lights` (emissive triangles as area lights),
//! `sampling` (deterministic random numbers, GGX), `mips` (mip-maps, trilinear
//! lookups), `camera`, `environment` (`--background`, `--environment`: what rays leaving the scene see), `stats`, `options` / `output` (the options and the EXR / PNG
//! encoders), and `errors` (the typed option and output errors).

mod aov;
mod camera;
mod cpu_clock;
mod environment;
mod errors;
mod exr_zip;
#[cfg(feature = "gpu")]
mod gpu_frame;
mod lights;
mod memo;
mod mips;
mod options;
mod output;
mod planning;
mod replay;
mod sampling;
mod sequence;
mod shade;
mod stats;
mod tuning_rays;
mod wavefront;
mod writer;
use std::path::PathBuf;
use std::time::Duration;

pub use aov::{
    camera_to_ndc, crypto_hash, crypto_key, exr_matrix, fps_rational, murmur3_32, project,
    world_to_camera, CryptoKind, CryptoNames, FrameHeader,
};
pub use camera::{
    animation_bounds, apply_exposure, aspect_warning, camera_aspect, default_size, size_for_aspect,
    size_matches, CameraModel, DEFAULT_WIDTH, MAX_EXPOSURE,
};
pub use environment::{EnvironmentError, EnvironmentMap};
pub use errors::{FramesProblem, OptionError, OutputFile};
pub use mips::TextureMips;
pub use options::{
    Aovs, CancelFlag, ExrCompression, FrameRange, FrameSet, FrameSpan, LookAt, MotionBlur,
    PixelType, PreviewOptions, RenderOptions, ShadingOptions, Shard, TraceDevice,
    DEFAULT_CRYPTO_LEVELS, DEFAULT_MOTION_STEPS, MAX_FRAMES, MAX_MOTION_STEPS, MAX_OVERSCAN,
    MAX_SIDE,
};
pub use output::{
    channel_names, encode_exr, encode_preview, frame_file, is_complete, linear_to_srgb8, software,
    FrameFile, OPTIONS_ATTRIBUTE,
};
pub use planning::{plan, CameraSource, FramePlan, OutputPattern, RenderPlan};
pub use sequence::{check_device, render_sequence};
pub use shade::{
    CryptoBuffers, FrameBuffers, FrameWork, LightPath, LightPathBuffers, RayCounts, ShadeContext,
};
pub use stats::{plot_png, plot_svg, stats_csv, FrameStats, FrameTotals, Kept, PLOT_BARS};
pub use tuning_rays::tuning_rays;
pub use wavefront::{render_frame, sample_offset, AovInputs};

use crate::format::FormatError;
use crate::psf::PsfError;
use crate::scene::SceneError;

/// Everything that can stop a render.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// A bad option value (the message names the flag).
    #[error(transparent)]
    Option(#[from] OptionError),
    #[error("no camera {requested:?} in the scene (give a camera's name or its index in the file's cameras); available: {}", list(.available))]
    UnknownCamera {
        requested: String,
        available: Vec<String>,
    },
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Format(#[from] FormatError),
    #[error(transparent)]
    Psf(#[from] PsfError),
    /// The baked file (`--baked`) cannot be used; the message names it.
    #[error("{}: {source}", path.display())]
    BakedFile {
        path: PathBuf,
        #[source]
        source: FormatError,
    },
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot encode {}: {source}", path.display())]
    Exr {
        path: PathBuf,
        #[source]
        source: exr::error::Error,
    },
    #[error("cannot encode {}: {source}", path.display())]
    Png {
        path: PathBuf,
        #[source]
        source: image::ImageError,
    },
    /// An output path (a frame, `--stats`, `--plot`, the preview) exists and is not a
    /// regular file, or is a link to none: refused before anything is rendered.
    #[error("{}: {source}", path.display())]
    NotAFile {
        path: PathBuf,
        #[source]
        source: crate::atomic::NotRegular,
    },
    /// Writing one of the run's files failed (a full disk, say); nothing partial is left
    /// of it, and the frames written before it are complete.
    #[error("cannot write {file} to {}: {source}", path.display())]
    Write {
        path: PathBuf,
        file: OutputFile,
        #[source]
        source: std::io::Error,
    },
    /// The run was stopped through [`RenderOptions::cancel`] after the frames in flight:
    /// every frame file written is complete, and a run with `resume` carries on.
    #[error("interrupted: {} written by this run ({skipped} complete before it), {left} left; the same command with --resume carries on", crate::plural(*written as u64, "frame"))]
    Cancelled {
        /// Frames this run rendered and wrote.
        written: usize,
        /// Frames skipped as complete (`resume`).
        skipped: usize,
        /// Planned frames neither written nor skipped.
        left: usize,
    },
    /// The writer thread ended without an answer (it cannot, short of a bug).
    #[error("the frame writer stopped unexpectedly")]
    WriterGone,
    /// The GPU tracer (`--device gpu`): no adapter, a scene too large for it, or the
    /// device failing mid-run (the frame in flight, `frame`, is not written; the frames
    /// before it are, and `--resume` carries on from it).
    #[cfg(feature = "gpu")]
    #[error("--device {device}: {}{source}", frame.map(|f| format!("frame {f}: ")).unwrap_or_default())]
    Gpu {
        device: &'static str,
        /// The frame being rendered when it failed (`None`: before the first); the frame
        /// loop fills it in ([`RenderError::in_frame`]).
        frame: Option<u32>,
        #[source]
        source: crate::gpu::GpuError,
    },
    /// `--device gpu` or `auto` in a build without the cargo feature `gpu`.
    #[error(
        "--device {0}: this build of subfield has no GPU tracer (the cargo feature `gpu` is off)"
    )]
    NoGpuSupport(&'static str),
}

impl RenderError {
    /// A fault of `--device gpu` outside any one frame (`in_frame` names the frame).
    #[cfg(feature = "gpu")]
    pub(crate) fn gpu(source: crate::gpu::GpuError) -> RenderError {
        RenderError::Gpu {
            device: "gpu",
            frame: None,
            source,
        }
    }

    /// The error as it stopped the rendering of `frame`: a GPU fault names the frame
    /// (the one line a render prints then says which frame was lost and why).
    pub(crate) fn in_frame(self, frame: u32) -> RenderError {
        match self {
            #[cfg(feature = "gpu")]
            RenderError::Gpu {
                device,
                frame: None,
                source,
            } => RenderError::Gpu {
                device,
                frame: Some(frame),
                source,
            },
            e => {
                // Only a GPU fault names its frame (and without the GPU there is none).
                let _ = frame;
                e
            }
        }
    }

    /// An error opening the baked file `path`, naming it (an I/O error names it already).
    pub(crate) fn baked(path: &std::path::Path, e: FormatError) -> RenderError {
        match e {
            FormatError::Io { .. } => RenderError::Format(e),
            source => RenderError::BakedFile {
                path: path.to_path_buf(),
                source,
            },
        }
    }
}

fn list(v: &[String]) -> String {
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

/// What happened to one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameReport {
    pub frame: u32,
    /// Position in the plan (0-based) and the plan's length.
    pub index: usize,
    pub total: usize,
    pub path: PathBuf,
    /// Skipped by `resume` (its file was complete).
    pub skipped: bool,
    /// Times and rays; `None` when skipped.
    pub stats: Option<FrameStats>,
}

/// Progress of [`render_sequence`], in order: `Planned`, `StaticReady`, then one
/// `Frame` per planned frame (rendered frames are reported once written).
#[derive(Debug)]
#[non_exhaustive]
pub enum RenderEvent<'a> {
    Planned(&'a RenderPlan),
    /// Where the frames will be traced: `cpu`, or `gpu: ` and the adapter in words
    /// (`--device auto` says here which it took).
    Device(&'a str),
    /// The static part is ready: baked in memory, or opened from `--baked`.
    StaticReady {
        triangles: usize,
        baked_file: bool,
        seconds: f64,
    },
    Frame(&'a FrameReport),
    /// A note for the log, said once: e.g. which feature of the scene or the options
    /// keeps `--device gpu`'s shading on the CPU (`note: ` goes before it).
    Note(&'a str),
}

/// The outcome of a whole run.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSummary {
    pub plan: RenderPlan,
    pub rendered: usize,
    pub skipped: usize,
    /// Frames rendered again by `resume` although their file was whole: it was made with
    /// other options (its header's options string differs).
    pub replaced: usize,
    /// The rendered frames' times and rays, summed (per-frame figures go to `--stats` as
    /// each frame is written: a summary stays the same size whatever the frame count).
    pub totals: FrameTotals,
    /// The preview written, if any.
    pub preview: Option<PathBuf>,
    pub static_seconds: f64,
    pub wall: Duration,
}

#[cfg(all(test, feature = "gpu"))]
mod tests {
    use super::RenderError;
    use crate::gpu::GpuError;

    #[test]
    fn a_gpu_fault_in_a_frame_names_the_frame_and_the_cause() {
        let lost = || RenderError::Gpu {
            device: "gpu",
            frame: None,
            source: GpuError::OutOfMemory("a buffer of 2 GiB".into()),
        };
        assert_eq!(
            lost().in_frame(12).to_string(),
            "--device gpu: frame 12: the GPU ran out of memory (a buffer of 2 GiB)"
        );
        // Before any frame (opening the device): no frame to name.
        assert_eq!(
            lost().to_string(),
            "--device gpu: the GPU ran out of memory (a buffer of 2 GiB)"
        );
        // A frame already named stays named; other errors are left as they are.
        let named = lost().in_frame(3).in_frame(4).to_string();
        assert!(named.contains("frame 3:"), "{named}");
        let other = RenderError::WriterGone.in_frame(5).to_string();
        assert!(!other.contains("frame 5"), "{other}");
    }
}
