//! What a render is asked to do ([`RenderOptions`]). The command-line spellings of these
//! values (`A..B`, `WxH`, `I/N`, `X,Y,Z`) are parsed by the CLI (`src/cli/parse.rs`).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use glam::Vec3;

use super::errors::{FramesProblem, OptionError};

/// Frames `start..end`: inclusive start, exclusive end.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameRange {
    pub start: u32,
    pub end: u32,
}

/// Most frames one render takes: a typo such as `0..4000000000` is refused at once, in
/// one line. (A render's memory does not grow with its frame count: the frames are
/// planned lazily and their statistics streamed; the limit only catches typos.)
pub const MAX_FRAMES: u64 = 10_000_000;

/// Every `step`-th frame of `start..end` (end exclusive, `step >= 1`): `--frames A..B:S`;
/// `N` is `N..N+1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameSpan {
    pub start: u32,
    pub end: u32,
    pub step: u32,
}

impl FrameSpan {
    /// How many frames the span names (0 when empty or with step 0).
    pub fn count(&self) -> u64 {
        if self.end <= self.start || self.step == 0 {
            return 0;
        }
        (self.end - self.start - 1) as u64 / self.step as u64 + 1
    }
}

impl FrameSpan {
    /// The span's first frame at or after `from`.
    fn next_from(&self, from: u32) -> Option<u32> {
        if self.step == 0 || self.end <= self.start {
            return None;
        }
        let k = from.saturating_sub(self.start).div_ceil(self.step) as u64;
        let f = self.start as u64 + k * self.step as u64;
        (f < self.end as u64).then_some(f as u32)
    }

    /// Whether the span names `frame`.
    pub fn contains(&self, frame: u32) -> bool {
        self.step != 0
            && (self.start..self.end).contains(&frame)
            && (frame - self.start).is_multiple_of(self.step)
    }
}

impl From<FrameRange> for FrameSpan {
    fn from(r: FrameRange) -> Self {
        FrameSpan {
            start: r.start,
            end: r.end,
            step: 1,
        }
    }
}

impl std::fmt::Display for FrameSpan {
    /// As `--frames` spells it: `N`, `A..B` or `A..B:S`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.count() == 1 {
            write!(f, "{}", self.start)
        } else if self.step == 1 {
            write!(f, "{}..{}", self.start, self.end)
        } else {
            write!(f, "{}..{}:{}", self.start, self.end, self.step)
        }
    }
}

/// The frames a render is asked for (`--frames 0..10,47,50..60:2`): a list of spans, in
/// any order, possibly overlapping. [`FrameSet::frames`] checks it and lists its frames
/// sorted, each once; `Display` spells it back as `--frames` reads it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameSet {
    spans: Vec<FrameSpan>,
}

impl FrameSet {
    pub fn new(spans: Vec<FrameSpan>) -> FrameSet {
        FrameSet { spans }
    }

    /// The frames of a sorted list, spelled compactly (runs with one step become spans).
    pub fn from_sorted(frames: &[u32]) -> FrameSet {
        let mut spans = Vec::new();
        let mut i = 0;
        while i < frames.len() {
            let a = frames[i];
            let mut j = i + 1;
            if let Some(&b) = frames.get(j).filter(|&&b| b > a) {
                let step = b - a;
                while let (Some(&n), Some(e)) = (frames.get(j + 1), frames[j].checked_add(step)) {
                    if n != e {
                        break;
                    }
                    j += 1;
                }
                // A run of two with a step is clearer as two single frames.
                if step == 1 || j > i + 1 {
                    spans.push(FrameSpan {
                        start: a,
                        end: frames[j].saturating_add(1),
                        step,
                    });
                    i = j + 1;
                    continue;
                }
                j = i + 1;
            }
            spans.push(FrameSpan {
                start: a,
                end: a.saturating_add(1),
                step: 1,
            });
            i = j;
        }
        FrameSet { spans }
    }

    pub fn spans(&self) -> &[FrameSpan] {
        &self.spans
    }

    /// How many frames the spans name together, repeats counted (cheap: nothing listed).
    pub fn count(&self) -> u64 {
        self.spans.iter().map(FrameSpan::count).sum()
    }

    /// Checks the set: refuses an empty span, a step of 0, an empty set and more than
    /// [`MAX_FRAMES`] frames (repeats counted), without listing anything.
    pub fn check(&self) -> Result<(), OptionError> {
        let bad = |problem| OptionError::Frames {
            set: self.to_string(),
            problem,
        };
        for s in &self.spans {
            if s.step == 0 {
                return Err(bad(FramesProblem::ZeroStep {
                    span: s.to_string(),
                }));
            }
            if s.end <= s.start {
                return Err(bad(FramesProblem::EmptySpan {
                    span: s.to_string(),
                }));
            }
        }
        match self.count() {
            0 => Err(bad(FramesProblem::NoFrames)),
            n if n > MAX_FRAMES => Err(bad(FramesProblem::TooMany { count: n })),
            _ => Ok(()),
        }
    }

    /// Whether the set names `frame`.
    pub fn contains(&self, frame: u32) -> bool {
        self.spans.iter().any(|s| s.contains(frame))
    }

    /// The set's first frame at or after `from`.
    pub fn next_from(&self, from: u32) -> Option<u32> {
        self.spans.iter().filter_map(|s| s.next_from(from)).min()
    }

    /// The frames, ascending, each once, listed lazily (nothing is allocated: a set of
    /// ten million frames costs what one costs).
    pub fn iter(&self) -> impl Iterator<Item = u32> + '_ {
        let mut next = self.next_from(0);
        std::iter::from_fn(move || {
            let f = next?;
            next = f.checked_add(1).and_then(|n| self.next_from(n));
            Some(f)
        })
    }

    /// The frames, ascending, each once, as a list, after [`FrameSet::check`].
    pub fn frames(&self) -> Result<Vec<u32>, super::RenderError> {
        self.check()?;
        Ok(self.iter().collect())
    }
}

impl From<FrameRange> for FrameSet {
    fn from(r: FrameRange) -> Self {
        FrameSet::new(vec![r.into()])
    }
}

impl std::fmt::Display for FrameSet {
    /// As `--frames` reads it: the spans joined by commas.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (i, s) in self.spans.iter().enumerate() {
            if i > 0 {
                f.write_str(",")?;
            }
            write!(f, "{s}")?;
        }
        Ok(())
    }
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

/// Extra EXR channels (`--aov depth,normal,albedo,position,motion,cryptomatte` and the
/// light-path passes `diffuse,specular,transmission,emission`). Each is computed only
/// when asked for: a render without AOVs does none of their work.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Aovs {
    /// `Z`: distance along the primary ray through the pixel centre; `+inf` on a miss.
    pub depth: bool,
    /// `N.X N.Y N.Z`: world-space shading normal (facing the camera); 0 on a miss.
    pub normal: bool,
    /// `albedo.R/G/B`: base colour (factor × texture) at the hit; 0 on a miss.
    pub albedo: bool,
    /// `P.X P.Y P.Z`: world-space hit point of the centre ray; 0 on a miss.
    pub position: bool,
    /// `motion.X motion.Y`: where the centre ray's surface point is one frame later
    /// (`t + 1/fps`, the point carried by its own triangle, seen by the camera of that
    /// time), minus where it is now, in pixels; +x right, +y down. 0 on a miss, on a
    /// point behind the next frame's camera, and where nothing moves.
    pub motion: bool,
    /// Cryptomatte ID layers `CryptoObject00…` and `CryptoMaterial00…` (Psyop's spec),
    /// ranked by coverage over every sample of the pixel.
    pub cryptomatte: bool,
    /// Ranks of Cryptomatte kept per pixel (`--crypto-levels`, default 6): two ranks a
    /// layer, so `ceil(levels / 2)` layers of each kind.
    pub crypto_levels: u32,
    /// `diffuse.R/G/B`: light that reached the camera through a diffuse event at the
    /// camera ray's hit (direct and bounced light, and the ambient term). The four
    /// light-path passes add up to `R G B` (see `shade`'s [`LightPath`]).
    ///
    /// [`LightPath`]: super::shade::LightPath
    pub diffuse: bool,
    /// `specular.R/G/B`: the highlights of lights at the camera ray's hit, and all the
    /// light its mirror or GGX reflection ray brings (whatever that ray meets next).
    pub specular: bool,
    /// `transmission.R/G/B`: all the light the refracted ray of the camera ray's hit
    /// brings.
    pub transmission: bool,
    /// `emission.R/G/B`: emissive surfaces and the background or environment seen by
    /// camera rays (through alpha-cut or blended surfaces too).
    pub emission: bool,
}

/// Default of `--crypto-levels`.
pub const DEFAULT_CRYPTO_LEVELS: u32 = 6;

impl Default for Aovs {
    fn default() -> Self {
        Aovs {
            depth: false,
            normal: false,
            albedo: false,
            position: false,
            motion: false,
            cryptomatte: false,
            crypto_levels: DEFAULT_CRYPTO_LEVELS,
            diffuse: false,
            specular: false,
            transmission: false,
            emission: false,
        }
    }
}

impl Aovs {
    /// Every AOV (tests and benchmarks).
    pub fn all() -> Aovs {
        Aovs {
            depth: true,
            normal: true,
            albedo: true,
            position: true,
            motion: true,
            cryptomatte: true,
            crypto_levels: DEFAULT_CRYPTO_LEVELS,
            diffuse: true,
            specular: true,
            transmission: true,
            emission: true,
        }
    }

    /// Whether any AOV made from the pixel-centre ray is asked for.
    pub fn any_centre(&self) -> bool {
        self.depth || self.normal || self.albedo || self.position || self.motion
    }

    /// Whether any light-path pass is asked for (then all four are traced: they are one
    /// split of the same contributions).
    pub fn any_light_path(&self) -> bool {
        self.diffuse || self.specular || self.transmission || self.emission
    }

    /// The light-path passes asked for, in [`LightPath`](super::shade::LightPath) order
    /// (`diffuse`, `specular`, `transmission`, `emission`).
    pub fn light_paths(&self) -> [bool; 4] {
        [
            self.diffuse,
            self.specular,
            self.transmission,
            self.emission,
        ]
    }

    /// Cryptomatte layers of each kind (two ranks a layer).
    pub fn crypto_layers(&self) -> usize {
        if self.cryptomatte {
            self.crypto_levels.max(1).div_ceil(2) as usize
        } else {
            0
        }
    }

    /// The names, comma-separated, as `--aov` spells them (empty when none).
    pub fn names(&self) -> String {
        let all = [
            (self.depth, "depth"),
            (self.normal, "normal"),
            (self.albedo, "albedo"),
            (self.position, "position"),
            (self.motion, "motion"),
            (self.cryptomatte, "cryptomatte"),
            (self.diffuse, "diffuse"),
            (self.specular, "specular"),
            (self.transmission, "transmission"),
            (self.emission, "emission"),
        ];
        all.iter()
            .filter(|(on, _)| *on)
            .map(|(_, n)| *n)
            .collect::<Vec<_>>()
            .join(",")
    }
}

/// Pixel type of the RGBA channels (AOVs are always 32-bit float).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum PixelType {
    #[default]
    Half,
    Float,
}

/// How the frame's EXR is compressed (`--compression`). One part holds every channel,
/// so the choice applies to the AOVs too; only lossless codecs are offered, so data
/// AOVs and Cryptomatte stay exact whatever is chosen. DWAA (lossy) is refused: the
/// `exr` crate (1.74) reads it but cannot write it (`OptionError::Compression`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum ExrCompression {
    /// OpenEXR's `ZIP_COMPRESSION` (16 lines a block), written by `exr_zip` in parallel.
    #[default]
    Zip,
    /// OpenEXR's `PIZ_COMPRESSION` (wavelet + Huffman, 32 lines a block), by the `exr`
    /// crate.
    Piz,
    /// No compression.
    None,
}

impl ExrCompression {
    /// The name `--compression` takes.
    pub fn name(self) -> &'static str {
        match self {
            ExrCompression::Zip => "zip",
            ExrCompression::Piz => "piz",
            ExrCompression::None => "none",
        }
    }
}

/// A tone-mapped sRGB PNG of one frame, written beside the sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct PreviewOptions {
    /// Which frame; `None` is the first frame rendered by this run.
    pub frame: Option<u32>,
    pub path: PathBuf,
}

/// Shading constants: the ambient term and the default light, which the command line
/// does not expose, and what rays see when they leave the scene.
#[derive(Clone, Debug, PartialEq)]
pub struct ShadingOptions {
    /// Ambient light (linear RGB radiance times diffuse albedo), so unlit sides are not
    /// pitch black.
    pub ambient: Vec3,
    /// Radiance of rays that leave the scene (primary misses have alpha 0), where no
    /// `environment` is given (`--background R,G,B`).
    pub background: Vec3,
    /// An equirectangular map seen by rays that leave the scene, in place of
    /// `background` (`--environment FILE`).
    pub environment: Option<std::sync::Arc<super::environment::EnvironmentMap>>,
    /// Cosine-weighted diffuse bounces a sample, each with shadow rays to every light
    /// (`--diffuse-bounces`); 0 is Whitted's model, where `ambient` stands in for them.
    pub diffuse_bounces: u32,
    /// Where the scene has no light at all, add a directional light from over the
    /// camera's shoulder (irradiance π, so a white diffuse surface facing it has radiance 1).
    pub default_light: bool,
}

impl Default for ShadingOptions {
    fn default() -> Self {
        ShadingOptions {
            ambient: Vec3::splat(0.05),
            background: Vec3::ZERO,
            environment: None,
            diffuse_bounces: 0,
            default_light: true,
        }
    }
}

/// A flag that stops a render after the frames in flight when set (from another thread or
/// a signal handler): [`render_sequence`](super::render_sequence) then answers
/// [`RenderError::Cancelled`](super::RenderError::Cancelled). Two flags are equal when
/// they are the same flag.
#[derive(Clone, Debug, Default)]
pub struct CancelFlag(Option<Arc<AtomicBool>>);

impl CancelFlag {
    /// A render stopped when `flag` becomes true.
    pub fn new(flag: Arc<AtomicBool>) -> CancelFlag {
        CancelFlag(Some(flag))
    }

    /// Whether the render is to stop.
    pub fn is_set(&self) -> bool {
        self.0.as_ref().is_some_and(|f| f.load(Ordering::Relaxed))
    }
}

impl PartialEq for CancelFlag {
    fn eq(&self, other: &Self) -> bool {
        match (&self.0, &other.0) {
            (Some(a), Some(b)) => Arc::ptr_eq(a, b),
            (a, b) => a.is_none() && b.is_none(),
        }
    }
}

/// Where frames are traced (`--device`, DESIGN.md §4); on the GPU they are shaded there
/// too where their data fit it (`render::gpu_frame`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TraceDevice {
    /// The CPU tracer on every core (the default).
    #[default]
    Cpu,
    /// A Vulkan adapter through wgpu (`src/gpu/`); an error when there is none.
    Gpu,
    /// A discrete GPU when there is one, else the CPU.
    Auto,
}

impl TraceDevice {
    /// The name in the options string and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            TraceDevice::Cpu => "cpu",
            TraceDevice::Gpu => "gpu",
            TraceDevice::Auto => "auto",
        }
    }
}

/// Default of `--motion-steps` when `--shutter` is above 0.
pub const DEFAULT_MOTION_STEPS: u32 = 5;

/// Most `--motion-steps` a frame takes: each step is an insertion of the moving
/// triangles, and a pixel's samples are spread over the steps (a byte a sample says which).
pub const MAX_MOTION_STEPS: u32 = 256;

/// Motion blur (`--shutter S --motion-steps K`, DESIGN.md §4; docs/IMAGES.md, "Motion
/// blur"): the shutter is open for `shutter` of the frame interval, centred on the
/// frame's time, and the moving triangles, the camera and the lights are posed at `steps`
/// times within it, `t + (S/fps)·((k + 0.5)/K − 0.5)` for `k` in `0..K`. Each sample of a
/// pixel traces one of the steps. A shutter of 0 is no blur: the frames are those made
/// without it, to the byte.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionBlur {
    /// Fraction of the frame interval the shutter is open, in `[0, 1]`.
    pub shutter: f32,
    /// Sub-frame times, `1..=MAX_MOTION_STEPS`.
    pub steps: u32,
}

impl MotionBlur {
    /// The shutter open for `shutter` of a frame, at the default step count.
    pub fn new(shutter: f32) -> MotionBlur {
        MotionBlur {
            shutter,
            steps: DEFAULT_MOTION_STEPS,
        }
    }

    /// Time of step `k` of the frame shown at `time` (seconds) at `fps`: the middle of
    /// the `k`-th of `steps` equal parts of the shutter interval.
    pub fn step_time(&self, time: f64, fps: f32, k: u32) -> f64 {
        let open = self.shutter as f64 / fps as f64;
        time + open * ((k as f64 + 0.5) / self.steps.max(1) as f64 - 0.5)
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
    /// `None`: the authored range at `fps`, from the frame of the earliest key to the frame
    /// of the latest of the clips that play (frame 0 alone without animation).
    pub frames: Option<FrameSet>,
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
    /// `--exposure EV`: the RGB written (EXR and preview) is the radiance × 2^EV; alpha
    /// and the AOVs are unchanged. 0 leaves the pixels as traced.
    pub exposure: f32,
    /// Where frames are traced. The options string names the device that traced (for
    /// `Auto`, the one it chose), so `--resume` re-renders frames made on the other.
    pub device: TraceDevice,
    /// On the GPU, shade on the CPU even where the GPU frame path could shade (the CLI's
    /// environment variable `SUBFIELD_GPU_SHADING=cpu`, a diagnostic: it tells a
    /// difference the GPU's shading makes from one its tracing makes). Named in the
    /// options string, so a sequence never mixes the two.
    pub cpu_shading: bool,
    /// `--compression`: the EXR's codec. Lossless, so not part of the options string
    /// (a frame resumed with another codec has the same pixels and is kept).
    pub compression: ExrCompression,
    /// `--overscan PX`: pixels traced beyond every edge of the image; the EXR's data
    /// window is `−PX..W+PX−1 × −PX..H+PX−1`, its display window `0..W−1 × 0..H−1`.
    pub overscan: u32,
    /// Motion blur; `None` (or a shutter of 0) renders each frame at its own time.
    pub motion_blur: Option<MotionBlur>,
    /// Stops the run after the frames in flight (Ctrl-C); not an option of the pixels.
    pub cancel: CancelFlag,
    /// `--frames-in-flight N`: frames the CPU path renders at once, each with its own
    /// moving layer and buffers, all sharing the threads (0: chosen from the thread
    /// count, [`RenderOptions::lanes`]). Not an option of the pixels: a frame is the same
    /// bytes whichever frames render beside it.
    pub frames_in_flight: usize,
    /// Samples the CPU path traces together at most (0: the default, 2^19, a 640x480
    /// frame in one): a smaller chunk takes less memory and pays each batch's set-up
    /// more often. Not an option of the pixels: the tests render with small chunks to
    /// hold that a frame is the same bytes however it is cut.
    pub chunk_samples: usize,
    /// The memory a still camera's kept shading may take in slots, a frame in flight (0,
    /// the default: none, so that only the records of the samples that settle are kept;
    /// 256 MB holds two levels at 640x480 and none at 1920x1080; `render::replay`).
    /// Not an option of the pixels: the tests set it to hold that a frame is the same
    /// bytes whatever is kept.
    pub replay_bytes: usize,
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
            exposure: 0.0,
            device: TraceDevice::Cpu,
            cpu_shading: false,
            compression: ExrCompression::Zip,
            overscan: 0,
            motion_blur: None,
            cancel: CancelFlag::default(),
            frames_in_flight: 0,
            chunk_samples: 0,
            replay_bytes: 0,
        }
    }
}

impl RenderOptions {
    /// The motion blur frames get: `None` without it or with a shutter of 0.
    pub fn blur(&self) -> Option<MotionBlur> {
        self.motion_blur.filter(|b| b.shutter > 0.0)
    }

    /// The options that change pixels, as one string: it goes into every frame's header
    /// (`subfield/options`) and `--resume` re-renders a frame whose string differs.
    /// `fps` is the resolved rate (the plan's); `scene_ambient`, the scene's own ambient
    /// light where it has one (the plan's), is written in place of the options' ambient
    /// term, which it replaces (`ambient=scene:R,G,B`); `default_light`, whether the
    /// default light is added (the plan's: asked for and the scene has no light).
    /// Deterministic: no time stamps, no paths.
    pub fn options_string(
        &self,
        fps: f32,
        scene_ambient: Option<Vec3>,
        default_light: bool,
    ) -> String {
        let mut s = format!(
            "size={}x{} spp={} max-depth={} pixel={} fps={} animation={}",
            self.width,
            self.height,
            self.spp.max(1),
            self.max_depth,
            match self.pixel_type {
                PixelType::Half => "half",
                PixelType::Float => "float",
            },
            fps,
            self.animation.as_deref().unwrap_or("default"),
        );
        match (&self.look_at, &self.camera) {
            (Some(l), _) => {
                s += &format!(
                    " camera=look-from:{},{},{}/look-at:{},{},{}/up:{},{},{}/yfov:{}",
                    l.from.x,
                    l.from.y,
                    l.from.z,
                    l.at.x,
                    l.at.y,
                    l.at.z,
                    l.up.x,
                    l.up.y,
                    l.up.z,
                    l.yfov_deg
                )
            }
            (None, Some(c)) => s += &format!(" camera={c}"),
            (None, None) => s += " camera=default",
        }
        let names = self.aovs.names();
        s += &format!(" aov={}", if names.is_empty() { "none" } else { &names });
        if self.aovs.cryptomatte {
            s += &format!(" crypto-levels={}", self.aovs.crypto_levels.max(1));
        }
        let sh = &self.shading;
        let (from, a) = match scene_ambient {
            Some(a) => ("scene:", a),
            None => ("", sh.ambient),
        };
        s += &format!(
            " ambient={from}{},{},{} background={},{},{} default-light={}",
            a.x, a.y, a.z, sh.background.x, sh.background.y, sh.background.z, default_light
        );
        if sh.diffuse_bounces > 0 {
            s += &format!(" diffuse-bounces={}", sh.diffuse_bounces);
        }
        if let Some(env) = &sh.environment {
            s += &format!(" environment={}", env.describe());
        }
        s += &format!(" exposure={}", self.exposure);
        s += &format!(" device={}", self.device.name());
        if self.cpu_shading && self.device != TraceDevice::Cpu {
            s += " shading=cpu";
        }
        // Only when asked for: frames without overscan keep the string (and bytes) they
        // had before the option existed.
        if self.overscan > 0 {
            s += &format!(" overscan={}", self.overscan);
        }
        // Only with blur: frames without it keep the string they had before it existed.
        if let Some(b) = self.blur() {
            s += &format!(" shutter={} motion-steps={}", b.shutter, b.steps);
        }
        s
    }
}

/// Largest image side accepted (keeps `W × H × spp` far from overflow).
pub const MAX_SIDE: u32 = 32768;

/// Largest `--overscan` accepted (the data window's side is at most
/// `MAX_SIDE + 2·MAX_OVERSCAN`).
pub const MAX_OVERSCAN: u32 = 4096;

#[cfg(test)]
mod tests {
    use super::*;

    fn span(start: u32, end: u32, step: u32) -> FrameSpan {
        FrameSpan { start, end, step }
    }

    /// The lazy listing against the obvious one (every frame of every span, sorted,
    /// each once), on overlapping spans with steps and at the top of the range.
    #[test]
    fn lazy_frames_are_the_sorted_union() {
        let sets = [
            vec![span(0, 10, 1)],
            vec![span(0, 800, 100), span(50, 60, 3), span(5, 6, 1)],
            vec![
                span(10, 30, 4),
                span(12, 31, 6),
                span(0, 1, 1),
                span(29, 40, 1),
            ],
            vec![
                span(u32::MAX - 5, u32::MAX, 2),
                span(u32::MAX - 1, u32::MAX, 1),
            ],
        ];
        for spans in sets {
            let set = FrameSet::new(spans.clone());
            let mut want: Vec<u32> = spans
                .iter()
                .flat_map(|s| (s.start..s.end).step_by(s.step as usize))
                .collect();
            want.sort_unstable();
            want.dedup();
            assert_eq!(set.iter().collect::<Vec<_>>(), want, "{set}");
            assert_eq!(set.frames().unwrap(), want);
            for f in 0..1000 {
                assert_eq!(set.contains(f), want.contains(&f), "{set} {f}");
            }
        }
    }

    #[test]
    fn huge_sets_are_refused_before_anything_is_listed() {
        let set = FrameSet::new(vec![span(0, 4_000_000_000, 1)]);
        assert_eq!(
            set.check(),
            Err(OptionError::Frames {
                set: "0..4000000000".into(),
                problem: FramesProblem::TooMany {
                    count: 4_000_000_000
                }
            })
        );
        let set = FrameSet::new(vec![span(3, 3, 1)]);
        assert!(matches!(
            set.check(),
            Err(OptionError::Frames {
                problem: FramesProblem::EmptySpan { .. },
                ..
            })
        ));
    }

    #[test]
    fn cancel_flags_are_equal_when_they_are_the_same_flag() {
        let a = Arc::new(AtomicBool::new(false));
        let (x, y) = (CancelFlag::new(a.clone()), CancelFlag::new(a.clone()));
        assert_eq!(x, y);
        assert_ne!(x, CancelFlag::new(Arc::new(AtomicBool::new(false))));
        assert_eq!(CancelFlag::default(), CancelFlag::default());
        assert!(!x.is_set() && !CancelFlag::default().is_set());
        a.store(true, Ordering::Relaxed);
        assert!(x.is_set());
    }
}
