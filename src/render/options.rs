//! What a render is asked to do ([`RenderOptions`]) and the parsers of the command-line
//! spellings (`A..B`, `WxH`, `I/N`, `X,Y,Z`), kept here so every front end (the
//! `render` and `demo` commands, library users) reads them the same way and reports a
//! bad value as one [`RenderError::Option`] line.

use std::path::PathBuf;

use glam::Vec3;

use super::RenderError;

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

fn bad(flag: &str, value: &str, why: impl std::fmt::Display) -> RenderError {
    RenderError::Option(format!("{flag} {value:?}: {why}"))
}

/// `A..B` with integers `A < B`.
pub fn parse_frames(s: &str) -> Result<FrameRange, RenderError> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| bad("--frames", s, "expected A..B (integers, B exclusive)"))?;
    let num = |x: &str| {
        x.trim()
            .parse::<u32>()
            .map_err(|_| bad("--frames", s, format!("{x:?} is not a frame number")))
    };
    let (start, end) = (num(a)?, num(b)?);
    if end <= start {
        return Err(bad(
            "--frames",
            s,
            "the range is empty (the end is exclusive and must be above the start)",
        ));
    }
    Ok(FrameRange { start, end })
}

/// Largest image side accepted (keeps `W × H × spp` far from overflow).
pub const MAX_SIDE: u32 = 32768;

/// `WxH`, both in `1..=32768`.
pub fn parse_size(s: &str) -> Result<(u32, u32), RenderError> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| bad("--size", s, "expected WxH, e.g. 640x480"))?;
    let side = |x: &str| match x.trim().parse::<u32>() {
        Ok(v) if (1..=MAX_SIDE).contains(&v) => Ok(v),
        _ => Err(bad(
            "--size",
            s,
            format!("{x:?} is not a side length in 1..={MAX_SIDE}"),
        )),
    };
    Ok((side(w)?, side(h)?))
}

/// `I/N` with `N >= 1` and `I < N`.
pub fn parse_shard(s: &str) -> Result<Shard, RenderError> {
    let (i, n) = s
        .split_once('/')
        .ok_or_else(|| bad("--shard", s, "expected I/N, e.g. 0/4"))?;
    let num = |x: &str| {
        x.trim()
            .parse::<u32>()
            .map_err(|_| bad("--shard", s, format!("{x:?} is not a whole number")))
    };
    let (index, count) = (num(i)?, num(n)?);
    if count == 0 || index >= count {
        return Err(bad("--shard", s, "needs N >= 1 and 0 <= I < N"));
    }
    Ok(Shard { index, count })
}

/// `X,Y,Z` (finite numbers).
pub fn parse_vec3(flag: &str, s: &str) -> Result<Vec3, RenderError> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(bad(flag, s, "expected X,Y,Z"));
    }
    let mut v = [0.0f32; 3];
    for (dst, p) in v.iter_mut().zip(&parts) {
        *dst = match p.trim().parse::<f32>() {
            Ok(x) if x.is_finite() => x,
            _ => return Err(bad(flag, s, format!("{p:?} is not a finite number"))),
        };
    }
    Ok(Vec3::from_array(v))
}

/// `depth,normal,albedo` in any order and subset.
pub fn parse_aovs(s: &str) -> Result<Aovs, RenderError> {
    let mut a = Aovs::default();
    for name in s.split(',').map(str::trim).filter(|n| !n.is_empty()) {
        match name {
            "depth" | "Z" | "z" => a.depth = true,
            "normal" | "N" => a.normal = true,
            "albedo" => a.albedo = true,
            other => {
                return Err(bad(
                    "--aov",
                    s,
                    format!("unknown AOV {other:?} (known: depth, normal, albedo)"),
                ))
            }
        }
    }
    Ok(a)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_parse_and_reject() {
        assert_eq!(
            parse_frames("0..10").unwrap(),
            FrameRange { start: 0, end: 10 }
        );
        assert_eq!(
            parse_frames(" 3 .. 4").unwrap(),
            FrameRange { start: 3, end: 4 }
        );
        for s in ["5..2", "2..2", "a..3", "3", "-1..4", "1..b"] {
            let e = parse_frames(s).unwrap_err().to_string();
            assert!(e.contains("--frames"), "{s}: {e}");
        }
    }

    #[test]
    fn size_shard_vec_aov() {
        assert_eq!(parse_size("640x480").unwrap(), (640, 480));
        assert_eq!(parse_size("1X1").unwrap(), (1, 1));
        for s in ["0x10", "10x", "x", "640*480", "99999x2", "-3x4"] {
            assert!(parse_size(s).is_err(), "{s}");
        }
        assert_eq!(parse_shard("1/2").unwrap(), Shard { index: 1, count: 2 });
        for s in ["2/2", "0/0", "1", "a/b", "-1/2"] {
            assert!(parse_shard(s).is_err(), "{s}");
        }
        assert_eq!(
            parse_vec3("--up", "0, 1,0").unwrap(),
            Vec3::new(0.0, 1.0, 0.0)
        );
        for s in ["1,2", "1,2,3,4", "1,nan,2", "1,inf,2", "a,b,c"] {
            assert!(parse_vec3("--up", s).is_err(), "{s}");
        }
        let a = parse_aovs("albedo,depth").unwrap();
        assert!(a.depth && a.albedo && !a.normal);
        assert!(parse_aovs("depth,colour").is_err());
    }
}
