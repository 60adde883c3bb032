//! What a render is asked to do ([`RenderOptions`]). The command-line spellings of these
//! values (`A..B`, `WxH`, `I/N`, `X,Y,Z`) are parsed by the CLI (`src/cli/parse.rs`).

use std::path::PathBuf;

use glam::Vec3;

/// Frames `start..end`: inclusive start, exclusive end.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameRange {
    pub start: u32,
    pub end: u32,
}

/// `--shard I/N`: the frames `k` with `k % count == index`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: u32,
    pub count: u32,
}

/// A camera given outright (`--look-from/--look-at/--up/--yfov`), in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LookAt {
    pub from: Vec3,
    pub at: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub yfov_deg: f32,
}

/// Extra EXR channels (`--aov depth,normal,albedo`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Aovs {
    /// `Z`: distance along the primary ray through the pixel centre; `+inf` on a miss.
    pub depth: bool,
    /// `N.X N.Y N.Z`: world-space shading normal (facing the camera); 0 on a miss.
    pub normal: bool,
    /// `albedo.R/G/B`: base colour (factor × texture) at the hit; 0 on a miss.
    pub albedo: bool,
}

/// Pixel type of the RGBA channels (AOVs are always 32-bit float).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PixelType {
    #[default]
    Half,
    Float,
}

/// A tone-mapped sRGB PNG of one frame, written beside the sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct PreviewOptions {
    /// Which frame; `None` is the first frame rendered by this run.
    pub frame: Option<u32>,
    pub path: PathBuf,
}

/// Shading constants the command line does not expose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadingOptions {
    /// Ambient light (linear RGB radiance times diffuse albedo), so unlit sides are not
    /// pitch black.
    pub ambient: Vec3,
    /// Radiance of rays that leave the scene (primary misses have alpha 0).
    pub background: Vec3,
    /// Where the scene has no light at all, add a directional light from over the
    /// camera's shoulder (irradiance π, so a white diffuse surface facing it has radiance 1).
    pub default_light: bool,
}

impl Default for ShadingOptions {
    fn default() -> Self {
        ShadingOptions {
            ambient: Vec3::splat(0.05),
            background: Vec3::ZERO,
            default_light: true,
        }
    }
}

/// Everything `render_sequence` needs besides the scene. `Default` gives the command
/// line's defaults (640×480, 1 spp, depth 4, half floats) and an empty output pattern.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    /// Output pattern: one run of `#` becomes the zero-padded frame number.
    pub output: PathBuf,
    /// A baked `.psf` of the scene's static part; `None` bakes in memory.
    pub baked: Option<PathBuf>,
    /// `None`: the whole animation at `fps` (frame 0 alone without animation).
    pub frames: Option<FrameRange>,
    /// `None`: the scene's `extras.fps`, else 24.
    pub fps: Option<f32>,
    /// One clip by name or index; `None` plays all.
    pub animation: Option<String>,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub max_depth: u32,
    /// A scene camera by name; `None` is the first camera, else one framing the scene.
    pub camera: Option<String>,
    /// Overrides the scene's camera.
    pub look_at: Option<LookAt>,
    pub aovs: Aovs,
    pub pixel_type: PixelType,
    /// Skip frames whose file exists and reads back complete.
    pub resume: bool,
    pub shard: Option<Shard>,
    /// Per-frame times and ray counts as CSV.
    pub stats: Option<PathBuf>,
    /// Per-frame times as a stacked bar chart (`.svg` or `.png`).
    pub plot: Option<PathBuf>,
    pub preview: Option<PreviewOptions>,
    pub shading: ShadingOptions,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            output: PathBuf::new(),
            baked: None,
            frames: None,
            fps: None,
            animation: None,
            width: 640,
            height: 480,
            spp: 1,
            max_depth: 4,
            camera: None,
            look_at: None,
            aovs: Aovs::default(),
            pixel_type: PixelType::Half,
            resume: false,
            shard: None,
            stats: None,
            plot: None,
            preview: None,
            shading: ShadingOptions::default(),
        }
    }
}

/// Largest image side accepted (keeps `W × H × spp` far from overflow).
pub const MAX_SIDE: u32 = 32768;
