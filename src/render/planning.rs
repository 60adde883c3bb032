//! Planning a render: the output pattern, the camera source, the frames (range, shard)
//! and the checks made before anything is written (option values against the scene,
//! output folders), and which frames a resumed run skips.

use std::path::{Path, PathBuf};

use glam::Vec3;

use super::camera::{animation_bounds, aspect_warning, CameraModel, MAX_EXPOSURE};
use super::options::{FrameRange, FrameSet, RenderOptions, MAX_FRAMES, MAX_SIDE};
use super::output::is_complete;
use super::stats;
use super::writer::check_writable;
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
            return Err(RenderError::Option(
                "-o: the output pattern is empty".into(),
            ));
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
            return Err(RenderError::Option(format!(
                "-o {s:?}: the pattern has {runs} runs of '#'; it needs exactly one (or none for a single frame)"
            )));
        }
        let parts = s.find('#').map(|a| {
            let b = s[a..].find(|c| c != '#').map_or(s.len(), |k| a + k);
            (s[..a].to_string(), b - a, s[b..].to_string())
        });
        if s.ends_with('/') || pattern.file_name().is_none() {
            return Err(RenderError::Option(format!(
                "-o {s:?}: names a folder, not a file"
            )));
        }
        let exr = pattern
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        if !exr {
            return Err(RenderError::Option(format!(
                "-o {s:?}: frames are OpenEXR files; the pattern must end in .exr"
            )));
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
pub enum CameraSource {
    /// A scene camera (by name, or the first), posed every frame.
    Scene(Option<String>),
    /// A fixed camera: given outright, or framing the scene.
    Fixed(CameraModel),
}

/// A checked render: which frames, at what times, from which camera.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderPlan {
    pub selection: ClipSelection,
    pub fps: f32,
    /// The frames asked for (`--frames`, else the whole animation), before sharding.
    pub set: FrameSet,
    /// Their span: the first frame to one past the last, before sharding.
    pub range: FrameRange,
    /// The frames this run renders (after `--shard`), ascending, each once.
    pub frames: Vec<u32>,
    /// Warnings about the plan (clips left out by the default selection, a `--size` off
    /// the camera's aspect ratio, `--frames` past the end of the animation), one line
    /// each, without the `warning: ` prefix.
    pub warnings: Vec<String>,
    pub pattern: OutputPattern,
    pub camera: CameraSource,
    pub split: SplitSummary,
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
        Some(f) => {
            return Err(RenderError::Option(format!(
                "--fps {f}: must be a positive number"
            )))
        }
        None => scene
            .fps
            .filter(|f| f.is_finite() && *f > 0.0)
            .unwrap_or(24.0),
    };
    for (v, what) in [(opts.width, "width"), (opts.height, "height")] {
        if !(1..=MAX_SIDE).contains(&v) {
            return Err(RenderError::Option(format!(
                "--size: the {what} {v} is not in 1..={MAX_SIDE}"
            )));
        }
    }
    if !(1..=65536).contains(&opts.spp) {
        return Err(RenderError::Option(format!(
            "--spp {}: must be in 1..=65536",
            opts.spp
        )));
    }
    if !(opts.exposure.is_finite() && opts.exposure.abs() <= MAX_EXPOSURE) {
        return Err(RenderError::Option(format!(
            "--exposure {}: must be a number of stops between -{MAX_EXPOSURE} and {MAX_EXPOSURE}",
            opts.exposure
        )));
    }
    if opts.max_depth > 64 {
        return Err(RenderError::Option(format!(
            "--max-depth {}: at most 64",
            opts.max_depth
        )));
    }
    // The last frame at or before the end of the animation; `None` without animation.
    let duration = scene.duration(selection) as f64;
    let last = (duration > 0.0).then(|| {
        // The end is an f32 key time, a few ulps (2^-24 each, relative) off the frame time
        // it stands for: 299/30 s is stored as 9.966666 s, 298.99999 frames at 30 fps.
        // Allow 2^-20 of it, so the last key's frame is not dropped.
        let x = duration * fps as f64;
        (x + x * (1.0 / 1_048_576.0) + 1e-6)
            .floor()
            .min(u32::MAX as f64 - 1.0) as u32
    });
    let set = match &opts.frames {
        Some(s) => s.clone(),
        None => FrameSet::from(FrameRange {
            start: 0,
            end: last.unwrap_or(0) + 1,
        }),
    };
    let all = set.frames().map_err(|e| match opts.frames {
        Some(_) => e,
        None => RenderError::Option(format!(
            "the animation runs {} frames at {fps} fps, more than the {MAX_FRAMES} a render takes: give --frames",
            last.unwrap_or(0) as u64 + 1
        )),
    })?;
    let (first, final_) = (all[0], all[all.len() - 1]);
    let range = FrameRange {
        start: first,
        end: final_ + 1,
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
        return Err(RenderError::Option(format!(
            "-o {}: {} frames ({set}) need a '#' in the pattern for the frame number",
            opts.output.display(),
            all.len(),
        )));
    }
    let frames: Vec<u32> = match opts.shard {
        Some(s) if s.count == 0 || s.index >= s.count => {
            return Err(RenderError::Option(format!(
                "--shard {}/{}: needs N >= 1 and 0 <= I < N",
                s.index, s.count
            )))
        }
        Some(s) => all.into_iter().filter(|k| k % s.count == s.index).collect(),
        None => all,
    };
    if let (Some(name), Some(_)) = (&opts.camera, &opts.look_at) {
        return Err(RenderError::Option(format!(
            "--camera {name:?} and --look-from both choose the camera; give one of them"
        )));
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
            return Err(RenderError::Option(format!(
                "--preview {}: the preview is a PNG file; the name must end in .png",
                p.path.display()
            )));
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
    })
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
/// of the checks before a frame is rendered, and removes the temporaries a killed run left
/// beside this run's frames.
pub(super) fn check_outputs(plan: &RenderPlan, opts: &RenderOptions) -> Result<(), RenderError> {
    if let Some(&first) = plan.frames.first() {
        let first = plan.pattern.path(first);
        check_writable(&first)?;
        // Temporaries a killed run left beside this run's frames go; those of a live
        // process (a concurrent shard) stay. Best effort: a folder that cannot be
        // listed has failed the check above already.
        let names: std::collections::HashSet<String> = plan
            .frames
            .iter()
            .filter_map(|&f| Some(plan.pattern.path(f).file_name()?.to_str()?.to_owned()))
            .collect();
        let dir = crate::atomic::folder_of(&first);
        let _ = crate::atomic::remove_stale_temporaries(&dir, |t| names.contains(t));
    }
    for p in [&opts.stats, &opts.plot].into_iter().flatten() {
        check_writable(p)?;
    }
    if let Some(p) = &opts.preview {
        check_writable(&p.path)?;
    }
    Ok(())
}

/// Whether a resumed run skips `path`: its file is complete for these options
/// (`options`: [`RenderOptions::options_string`], compared with the file's header).
pub(super) fn skips(opts: &RenderOptions, path: &Path, options: &str) -> bool {
    opts.resume
        && is_complete(
            path,
            opts.width,
            opts.height,
            opts.aovs,
            opts.pixel_type,
            options,
        )
}

#[cfg(test)]
mod tests {
    use super::*;

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
