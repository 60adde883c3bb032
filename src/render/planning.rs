//! Planning a render: the output pattern, the camera source, the frames (range, shard)
//! and the checks made before anything is written (option values against the scene,
//! output folders), and which frames a resumed run skips.

use std::path::{Path, PathBuf};

use glam::Vec3;

use super::camera::{animation_bounds, aspect_warning, CameraModel, MAX_EXPOSURE};
use super::errors::OptionError;
use super::options::{
    FrameRange, FrameSet, RenderOptions, Shard, MAX_MOTION_STEPS, MAX_OVERSCAN, MAX_SIDE,
};
use super::output::{frame_file, FrameFile};
use super::stats;
use super::writer::{check_target, check_writable};
use super::RenderError;
use crate::scene::{ClipSelection, Scene, Split, SplitSummary};

/// An output pattern: one run of `#` replaced by the zero-padded frame number.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OutputPattern {
    /// Text before and after the run of `#`, and the run's length; `None` without `#`.
    parts: Option<(String, usize, String)>,
    fixed: PathBuf,
}

impl OutputPattern {
    pub fn parse(pattern: &Path) -> Result<OutputPattern, RenderError> {
        if pattern.as_os_str().is_empty() {
            return Err(OptionError::EmptyPattern.into());
        }
        let Some(s) = pattern.to_str() else {
            // Not UTF-8: no '#' can be found reliably; take it as a fixed name.
            return Ok(OutputPattern {
                parts: None,
                fixed: pattern.to_path_buf(),
            });
        };
        let runs = s
            .as_bytes()
            .windows(2)
            .filter(|w| w[0] != b'#' && w[1] == b'#')
            .count()
            + usize::from(s.starts_with('#'));
        if runs > 1 {
            return Err(OptionError::PatternRuns {
                pattern: s.to_string(),
                runs,
            }
            .into());
        }
        let parts = s.find('#').map(|a| {
            let b = s[a..].find(|c| c != '#').map_or(s.len(), |k| a + k);
            (s[..a].to_string(), b - a, s[b..].to_string())
        });
        if s.ends_with('/') || pattern.file_name().is_none() {
            return Err(OptionError::PatternIsFolder {
                pattern: s.to_string(),
            }
            .into());
        }
        let exr = pattern
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        if !exr {
            return Err(OptionError::PatternNotExr {
                pattern: s.to_string(),
            }
            .into());
        }
        Ok(OutputPattern {
            parts,
            fixed: pattern.to_path_buf(),
        })
    }

    /// Whether the pattern numbers its frames.
    pub fn is_numbered(&self) -> bool {
        self.parts.is_some()
    }

    /// The frame whose file is named `name` in the frames' folder, when the run of `#`
    /// is in the file name (not in a folder of the pattern): `f.0012.exr` → 12 for
    /// `out/f.####.exr`. Exact: `f.012.exr` names no frame of that pattern.
    pub fn frame_of(&self, name: &str) -> Option<u32> {
        let (a, n, b) = self.parts.as_ref()?;
        if b.contains(std::path::is_separator) {
            return None;
        }
        let prefix = a.rsplit(std::path::is_separator).next().unwrap_or(a);
        let digits = name.strip_prefix(prefix)?.strip_suffix(b.as_str())?;
        if digits.is_empty() || !digits.bytes().all(|c| c.is_ascii_digit()) {
            return None;
        }
        let f: u32 = digits.parse().ok()?;
        (format!("{f:0n$}") == digits).then_some(f)
    }

    /// The file of `frame`.
    pub fn path(&self, frame: u32) -> PathBuf {
        match &self.parts {
            Some((a, n, b)) => PathBuf::from(format!("{a}{frame:0n$}{b}")),
            None => self.fixed.clone(),
        }
    }
}

/// Where each frame's camera comes from.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum CameraSource {
    /// A scene camera (by name, or the first), posed every frame.
    Scene(Option<String>),
    /// A fixed camera: given outright, or framing the scene.
    Fixed(CameraModel),
}

/// The frames a run renders: the frames asked for ([`FrameSet`]) that its shard takes,
/// ascending, each once. Listed lazily: planning, progress and the frame loop hold a
/// frame number at a time, whatever the count.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FramePlan {
    set: FrameSet,
    shard: Option<Shard>,
    len: usize,
    first: Option<u32>,
    last: Option<u32>,
}

impl FramePlan {
    /// The frames of `set` (checked already) that `shard` takes.
    fn new(set: FrameSet, shard: Option<Shard>) -> FramePlan {
        let mut p = FramePlan {
            set,
            shard,
            len: 0,
            first: None,
            last: None,
        };
        let (mut len, mut first, mut last) = (0, None, None);
        for f in p.iter() {
            len += 1;
            first.get_or_insert(f);
            last = Some(f);
        }
        (p.len, p.first, p.last) = (len, first, last);
        p
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn first(&self) -> Option<u32> {
        self.first
    }

    pub fn last(&self) -> Option<u32> {
        self.last
    }

    /// Whether this run renders `frame`.
    pub fn contains(&self, frame: u32) -> bool {
        self.set.contains(frame) && self.shard.is_none_or(|s| frame % s.count == s.index)
    }

    /// The frames, ascending.
    pub fn iter(&self) -> impl Iterator<Item = u32> + '_ {
        let shard = self.shard;
        self.set
            .iter()
            .filter(move |f| shard.is_none_or(|s| f % s.count == s.index))
    }
}

/// A checked render: which frames, at what times, from which camera.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderPlan {
    pub selection: ClipSelection,
    pub fps: f32,
    /// The frames asked for (`--frames`, else the authored range: the frame of the
    /// earliest key to the frame of the latest), before sharding.
    pub set: FrameSet,
    /// Their span: the first frame to one past the last, before sharding.
    pub range: FrameRange,
    /// The frames this run renders (after `--shard`), ascending, each once.
    pub frames: FramePlan,
    /// Warnings about the plan (clips left out by the default selection, a `--size` off
    /// the camera's aspect ratio, `--frames` past the end of the animation), one line
    /// each, without the `warning: ` prefix.
    pub warnings: Vec<String>,
    pub pattern: OutputPattern,
    pub camera: CameraSource,
    pub split: SplitSummary,
    /// The scene's own ambient light (AFF `am`), which replaces the options' ambient
    /// term; the options string records it in its place.
    pub ambient: Option<Vec3>,
    /// Whether the options' default light is added: asked for, and the shown scene has
    /// no punctual light and no emitting material. Frames say so in their header.
    pub default_light: bool,
}

impl RenderPlan {
    /// Animation time of `frame`, seconds.
    pub fn time(&self, frame: u32) -> f64 {
        frame as f64 / self.fps as f64
    }
}

/// Checks `opts` against `scene` without touching the file system.
pub fn plan(scene: &Scene, opts: &RenderOptions) -> Result<RenderPlan, RenderError> {
    let mut warnings = Vec::new();
    let selection = match &opts.animation {
        Some(a) => scene.resolve_clip(a)?,
        None => {
            let (sel, warning) = scene.default_clips();
            warnings.extend(warning);
            sel
        }
    };
    let fps = match opts.fps {
        Some(f) if f.is_finite() && f > 0.0 => f,
        Some(f) => return Err(OptionError::Fps(f).into()),
        None => scene
            .fps
            .filter(|f| f.is_finite() && *f > 0.0)
            .unwrap_or(24.0),
    };
    if !(1..=MAX_SIDE).contains(&opts.width) {
        return Err(OptionError::Width(opts.width).into());
    }
    if !(1..=MAX_SIDE).contains(&opts.height) {
        return Err(OptionError::Height(opts.height).into());
    }
    if opts.overscan > MAX_OVERSCAN {
        return Err(OptionError::Overscan(opts.overscan).into());
    }
    if !(1..=65536).contains(&opts.spp) {
        return Err(OptionError::Spp(opts.spp).into());
    }
    if !(opts.exposure.is_finite() && opts.exposure.abs() <= MAX_EXPOSURE) {
        return Err(OptionError::Exposure(opts.exposure).into());
    }
    if opts.max_depth > 64 {
        return Err(OptionError::MaxDepth(opts.max_depth).into());
    }
    if opts.shading.diffuse_bounces > 64 {
        return Err(OptionError::DiffuseBounces(opts.shading.diffuse_bounces).into());
    }
    if let Some(b) = opts.motion_blur {
        if !(0.0..=1.0).contains(&b.shutter) {
            return Err(OptionError::Shutter(b.shutter).into());
        }
        if !(1..=MAX_MOTION_STEPS).contains(&b.steps) {
            return Err(OptionError::MotionSteps(b.steps).into());
        }
    }
    // The authored range: the frames of the earliest and the latest key of the clips
    // that play; `None` without animation (or with every key at time 0).
    let duration = scene.duration(selection) as f64;
    let authored = scene
        .key_span(selection)
        .filter(|&(_, end)| end > 0.0)
        .map(|(start, end)| (key_frame(start, fps), key_frame(end, fps)));
    let last = authored.map(|(_, l)| l);
    let set = match &opts.frames {
        Some(s) => s.clone(),
        None => {
            let (start, end) = authored.unwrap_or((0, 0));
            FrameSet::from(FrameRange {
                start,
                end: end + 1,
            })
        }
    };
    set.check().map_err(|e| match opts.frames {
        Some(_) => e,
        None => OptionError::AnimationTooLong {
            frames: authored.map_or(1, |(a, b)| u64::from(b - a) + 1),
            fps,
        },
    })?;
    if let Some(s) = opts.shard {
        if s.count == 0 || s.index >= s.count {
            return Err(OptionError::Shard {
                index: s.index,
                count: s.count,
            }
            .into());
        }
    }
    // The whole set, then this shard's part of it: counted, never listed.
    let all = FramePlan::new(set.clone(), None);
    let (Some(first), Some(final_)) = (all.first(), all.last()) else {
        // `check` refuses an empty set.
        return Err(OptionError::Frames {
            set: set.to_string(),
            problem: super::errors::FramesProblem::NoFrames,
        }
        .into());
    };
    let range = FrameRange {
        start: first,
        end: final_.saturating_add(1),
    };
    if let (Some(_), Some(last)) = (&opts.frames, last) {
        if final_ > last {
            warnings.push(format!(
                "--frames {set} runs past the end of the animation (frame {last} at {fps} fps, {duration:.3} s); later frames show its last pose"
            ));
        }
    }
    let pattern = OutputPattern::parse(&opts.output)?;
    if !pattern.is_numbered() && all.len() != 1 {
        return Err(OptionError::PatternNotNumbered {
            pattern: opts.output.clone(),
            frames: all.len(),
            set: set.to_string(),
        }
        .into());
    }
    let frames = match opts.shard {
        Some(_) => FramePlan::new(set.clone(), opts.shard),
        None => all,
    };
    if let (Some(sh), true) = (opts.shard, frames.is_empty()) {
        // Stepped frames can leave a shard nothing (every frame even: `--shard 1/2`);
        // `subfield submit` picks its shard count so that none is, a shard by hand may
        // not be.
        warnings.push(format!(
            "--shard {}/{} holds none of the frames {set}: a shard takes the frames k with \
             k % {} == {}",
            sh.index, sh.count, sh.count, sh.index
        ));
    }
    if let (Some(name), Some(_)) = (&opts.camera, &opts.look_at) {
        return Err(OptionError::CameraAndLookFrom {
            camera: name.clone(),
        }
        .into());
    }
    let camera = if let Some(l) = &opts.look_at {
        CameraSource::Fixed(CameraModel::look_at(l, opts.width, opts.height)?)
    } else if let Some(name) = &opts.camera {
        if scene.camera_at(selection, 0.0, Some(name)).is_none() {
            return Err(RenderError::UnknownCamera {
                requested: name.clone(),
                available: scene.camera_names(),
            });
        }
        CameraSource::Scene(Some(name.clone()))
    } else if scene.camera_at(selection, 0.0, None).is_some() {
        CameraSource::Scene(None)
    } else {
        let (lo, hi) = animation_bounds(scene, selection).unwrap_or((-Vec3::ONE, Vec3::ONE));
        CameraSource::Fixed(CameraModel::framing(lo, hi, opts.width, opts.height))
    };
    if let CameraSource::Scene(_) = camera {
        warnings.extend(aspect_warning(scene, opts));
    }
    if let Some(p) = &opts.plot {
        stats::plot_kind(p)?;
    }
    if let Some(p) = &opts.preview {
        let png = p
            .path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("png"));
        if !png {
            return Err(OptionError::PreviewExtension {
                path: p.path.clone(),
            }
            .into());
        }
    }
    Ok(RenderPlan {
        selection,
        fps,
        set,
        range,
        frames,
        warnings,
        pattern,
        camera,
        split: static_dynamic_split(scene, selection).summary(),
        ambient: scene.ambient,
        default_light: adds_default_light(scene, opts),
    })
}

/// Whether a render adds the options' default light: they ask for it and the shown scene
/// has no light, neither a punctual light on a node nor an emitting material on a mesh.
/// The frames' `ShadeContext` adds it when this says so (and the scene has no light,
/// which this implies), so the header's `default-light` is what the frames show.
fn adds_default_light(scene: &Scene, opts: &RenderOptions) -> bool {
    let lit = |n: usize| {
        let node = &scene.nodes[n];
        node.light.is_some()
            || node
                .mesh
                .and_then(|m| scene.meshes.get(m))
                .is_some_and(|m| {
                    m.primitives.iter().any(|p| {
                        scene
                            .materials
                            .get(p.material as usize)
                            .is_some_and(super::lights::emits)
                    })
                })
    };
    opts.shading.default_light && !scene.scene_nodes().into_iter().any(lit)
}

/// The frame at or before a key time (seconds) at `fps`, clamped to `0..u32::MAX`.
/// The time is an f32, a few ulps (2^-24 each, relative) off the frame time it stands
/// for: 299/30 s is stored as 9.966666 s, 298.99999 frames at 30 fps, and 1001/24 s may
/// come out just under frame 1001. Allow 2^-20 of it, so a key's own frame is not lost.
fn key_frame(t: f32, fps: f32) -> u32 {
    let x = t as f64 * fps as f64;
    (x + x.abs() * (1.0 / 1_048_576.0) + 1e-6)
        .floor()
        .clamp(0.0, u32::MAX as f64 - 1.0) as u32
}

/// The split a render uses: the static instances of *all* clips (exactly what `subfield
/// bake` writes, so one baked file serves every `--animation`), the other instances
/// dynamic and posed with the selected clips.
pub(super) fn static_dynamic_split(scene: &Scene, sel: ClipSelection) -> Split {
    let all = scene.split(ClipSelection::All);
    Split {
        selection: sel,
        ..all
    }
}

/// Checks every file the run writes can be made (frames, stats, plot, preview), the last
/// of the checks before a frame is rendered: none of them may be a folder, FIFO, socket,
/// device or a link to one (every frame's path is checked, by one listing of the
/// frames' folder when the frame number is in the file name); and removes the
/// temporaries a killed run left beside this run's frames.
pub(super) fn check_outputs(plan: &RenderPlan, opts: &RenderOptions) -> Result<(), RenderError> {
    for p in [&opts.stats, &opts.plot].into_iter().flatten() {
        check_target(p)?;
    }
    if let Some(p) = &opts.preview {
        check_target(&p.path)?;
    }
    if let Some(first) = plan.frames.first() {
        let first = plan.pattern.path(first);
        check_writable(&first)?;
        let dir = crate::atomic::folder_of(&first);
        let first_name = first
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default();
        // Whether the frame number is in the file name (else in a folder, or nowhere:
        // one file name for every frame).
        let by_name = plan.pattern.frame_of(first_name).is_some();
        let ours = |name: &str| -> bool {
            if by_name {
                plan.pattern
                    .frame_of(name)
                    .is_some_and(|f| plan.frames.contains(f))
            } else {
                name == first_name
            }
        };
        if by_name {
            // One listing, whatever the frame count. A folder that cannot be listed
            // has failed the check above already.
            if let Ok(entries) = std::fs::read_dir(&dir) {
                for e in entries.flatten() {
                    let regular = e.file_type().is_ok_and(|t| t.is_file());
                    if !regular && e.file_name().to_str().is_some_and(ours) {
                        check_target(&e.path())?;
                    }
                }
            }
        } else {
            for f in plan.frames.iter() {
                check_target(&plan.pattern.path(f))?;
            }
        }
        // Temporaries a killed run left beside this run's frames go; those of a live
        // process (a concurrent shard) stay. Best effort.
        let _ = crate::atomic::remove_stale_temporaries(&dir, ours);
    }
    for p in [&opts.stats, &opts.plot].into_iter().flatten() {
        check_writable(p)?;
    }
    if let Some(p) = &opts.preview {
        check_writable(&p.path)?;
    }
    Ok(())
}

/// What a resumed run finds at `path` (`options`: [`RenderOptions::options_string`],
/// compared with the file's header): it skips a [`FrameFile::Complete`] one; `None`
/// when the run does not resume.
pub(super) fn resumed(opts: &RenderOptions, path: &Path, options: &str) -> Option<FrameFile> {
    opts.resume.then(|| {
        // The data window (the image and the overscan border) is what the file holds.
        frame_file(
            path,
            opts.width + 2 * opts.overscan,
            opts.height + 2 * opts.overscan,
            opts.aovs,
            opts.pixel_type,
            options,
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::FrameSpan;

    #[test]
    fn frame_plans_count_and_shard_without_listing() {
        let set = FrameSet::new(vec![
            FrameSpan {
                start: 0,
                end: 10,
                step: 1,
            },
            FrameSpan {
                start: 5,
                end: 30,
                step: 5,
            },
        ]);
        let all = FramePlan::new(set.clone(), None);
        let want: Vec<u32> = vec![0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 15, 20, 25];
        assert_eq!(all.iter().collect::<Vec<_>>(), want);
        assert_eq!(
            (all.len(), all.first(), all.last()),
            (14, Some(0), Some(25))
        );
        let shard = FramePlan::new(set, Some(Shard { index: 1, count: 5 }));
        assert_eq!(shard.iter().collect::<Vec<_>>(), [1, 6]);
        assert_eq!(shard.len(), 2);
        assert!(shard.contains(6) && !shard.contains(5) && !shard.contains(11));
    }

    #[test]
    fn patterns() {
        let p = OutputPattern::parse(Path::new("out/frame.####.exr")).unwrap();
        assert!(p.is_numbered());
        assert_eq!(p.path(7), PathBuf::from("out/frame.0007.exr"));
        assert_eq!(p.path(123456), PathBuf::from("out/frame.123456.exr"));
        let p = OutputPattern::parse(Path::new("#.exr")).unwrap();
        assert_eq!(p.path(3), PathBuf::from("3.exr"));
        let p = OutputPattern::parse(Path::new("still.exr")).unwrap();
        assert!(!p.is_numbered());
        assert_eq!(p.path(9), PathBuf::from("still.exr"));
        assert!(OutputPattern::parse(Path::new("out/F.####.EXR")).is_ok());
        let p = OutputPattern::parse(Path::new("out/f.####.exr")).unwrap();
        assert_eq!(p.frame_of("f.0012.exr"), Some(12));
        assert_eq!(p.frame_of("f.123456.exr"), Some(123456));
        for other in [
            "f.012.exr",
            "f.00012.exr",
            "f.12.exr",
            "g.0012.exr",
            "f.00a2.exr",
            "f..exr",
        ] {
            assert_eq!(p.frame_of(other), None, "{other}");
        }
        let p = OutputPattern::parse(Path::new("out/####/f.exr")).unwrap();
        assert_eq!(p.frame_of("f.exr"), None);
        for bad in [
            "a#b#.exr",
            "#x#",
            "",
            "out/",
            "f.####.png",
            "f.####",
            "f.####.exr.tmp",
            "exr",
        ] {
            assert!(OutputPattern::parse(Path::new(bad)).is_err(), "{bad}");
        }
    }
}
