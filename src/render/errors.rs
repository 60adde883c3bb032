//! The typed parts of [`RenderError`](super::RenderError) a caller may match: a bad
//! option ([`OptionError`], each variant naming its flag and carrying the value), and
//! which of a render's files a write error is about ([`OutputFile`]).

use std::path::PathBuf;

use super::camera::MAX_EXPOSURE;
use super::options::{MAX_FRAMES, MAX_MOTION_STEPS, MAX_OVERSCAN, MAX_SIDE};

/// A bad option value; the message names the flag as the command line spells it.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum OptionError {
    #[error("-o: the output pattern is empty")]
    EmptyPattern,
    #[error("-o {pattern:?}: the pattern has {runs} runs of '#'; it needs exactly one (or none for a single frame)")]
    PatternRuns { pattern: String, runs: usize },
    #[error("-o {pattern:?}: names a folder, not a file")]
    PatternIsFolder { pattern: String },
    #[error("-o {pattern:?}: frames are OpenEXR files; the pattern must end in .exr")]
    PatternNotExr { pattern: String },
    /// Several frames and no `#` to number them.
    #[error("-o {}: {frames} frames ({set}) need a '#' in the pattern for the frame number", pattern.display())]
    PatternNotNumbered {
        pattern: PathBuf,
        frames: usize,
        set: String,
    },
    #[error("--fps {0}: must be a positive number")]
    Fps(f32),
    #[error("--size: the width {0} is not in 1..={MAX_SIDE}")]
    Width(u32),
    #[error("--size: the height {0} is not in 1..={MAX_SIDE}")]
    Height(u32),
    #[error("--overscan {0}: at most {MAX_OVERSCAN} pixels")]
    Overscan(u32),
    #[error("--spp {0}: must be in 1..=65536")]
    Spp(u32),
    #[error("--max-depth {0}: at most 64")]
    MaxDepth(u32),
    #[error("--diffuse-bounces {0}: at most 64")]
    DiffuseBounces(u32),
    #[error(
        "--exposure {0}: must be a number of stops between -{MAX_EXPOSURE} and {MAX_EXPOSURE}"
    )]
    Exposure(f32),
    #[error("--shutter {0}: must be a fraction of the frame interval, from 0 to 1")]
    Shutter(f32),
    #[error("--motion-steps {0}: must be in 1..={MAX_MOTION_STEPS}")]
    MotionSteps(u32),
    /// `--frames` as given (spelled back) and what is wrong with it.
    #[error("--frames {set}: {problem}")]
    Frames { set: String, problem: FramesProblem },
    /// No `--frames`, and the whole animation is more frames than a render takes.
    #[error("the animation runs {frames} frames at {fps} fps, more than the {MAX_FRAMES} a render takes: give --frames")]
    AnimationTooLong { frames: u64, fps: f32 },
    #[error("--shard {index}/{count}: needs N >= 1 and 0 <= I < N")]
    Shard { index: u32, count: u32 },
    #[error("--camera {camera:?} and --look-from both choose the camera; give one of them")]
    CameraAndLookFrom { camera: String },
    #[error("--look-from and --look-at are the same point")]
    LookAtSamePoint,
    #[error("--yfov {0}: must be between 0 and 180 degrees")]
    Yfov(f32),
    #[error("--up is parallel to the viewing direction (or zero)")]
    UpParallel,
    #[error("--plot {}: the file must end in .svg or .png", path.display())]
    PlotExtension { path: PathBuf },
    #[error("--preview {}: the preview is a PNG file; the name must end in .png", path.display())]
    PreviewExtension { path: PathBuf },
}

/// What is wrong with a `--frames` set.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FramesProblem {
    #[error("{span}: the step must be at least 1")]
    ZeroStep { span: String },
    #[error("{span}: the range is empty (the end is exclusive and must be above the start)")]
    EmptySpan { span: String },
    #[error("no frames")]
    NoFrames,
    #[error("{count} frames, more than the {MAX_FRAMES} a render takes (a typo?)")]
    TooMany { count: u64 },
}

/// Which of a render's files an error is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum OutputFile {
    /// The EXR of this frame.
    Frame(u32),
    /// `--stats`.
    Stats,
    /// `--plot`.
    Plot,
    /// The preview PNG.
    Preview,
}

impl std::fmt::Display for OutputFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            OutputFile::Frame(n) => write!(f, "frame {n}"),
            OutputFile::Stats => f.write_str("the stats"),
            OutputFile::Plot => f.write_str("the plot"),
            OutputFile::Preview => f.write_str("the preview"),
        }
    }
}
