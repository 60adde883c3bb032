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
//! (range, shard, pattern, camera, plot format); [`render_sequence`] then opens or bakes
//! the static part, checks the output folders are writable, and for each frame poses
//! the scene, updates the dynamic layer, traces and shades (`render::shade`) in parallel and
//! hands the finished frame to a writer thread over a channel of capacity 1, so one
//! frame is written while the next is traced and memory stays flat.

mod camera;
mod options;
mod output;
mod shade;
mod stats;

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use glam::Vec3;

pub use camera::{animation_bounds, CameraModel};
pub use options::{
    Aovs, FrameRange, LookAt, PixelType, PreviewOptions, RenderOptions, ShadingOptions, Shard,
    MAX_SIDE,
};
pub use output::{channel_names, encode_exr, encode_preview, is_complete, linear_to_srgb8};
pub use shade::{render_frame, sample_offset, FrameBuffers, FrameWork, RayCounts, ShadeContext};
pub use stats::{plot_png, plot_svg, stats_csv, FrameStats};

use crate::format::{self, FormatError, OpenOptions};
use crate::psf::{DynamicLayer, Psf, PsfError, PsfParams};
use crate::scene::{ClipSelection, Scene, SceneError, Split, SplitSummary, TriangleSoup};

/// Everything that can stop a render.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A bad option value (the message names the flag).
    #[error("{0}")]
    Option(String),
    #[error("no camera {requested:?} in the scene; available: {}", list(.available))]
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
    #[error("the frame writer stopped unexpectedly")]
    WriterGone,
}

fn list(v: &[String]) -> String {
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

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
    /// The range before sharding.
    pub range: FrameRange,
    /// The frames this run renders (after `--shard`), ascending.
    pub frames: Vec<u32>,
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
    let selection = match &opts.animation {
        Some(a) => scene.resolve_clip(a)?,
        None => ClipSelection::All,
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
    if opts.max_depth > 64 {
        return Err(RenderError::Option(format!(
            "--max-depth {}: at most 64",
            opts.max_depth
        )));
    }
    let range = match opts.frames {
        Some(r) if r.end > r.start => r,
        Some(r) => {
            return Err(RenderError::Option(format!(
                "--frames {}..{}: the range is empty (the end is exclusive and must be above the start)",
                r.start, r.end
            )))
        }
        None => {
            let d = scene.duration(selection) as f64;
            // The last frame at or before the end of the animation. The end is an f32 key
            // time, a few ulps (2^-24 each, relative) off the frame time it stands for:
            // 299/30 s is stored as 9.966666 s, 298.99999 frames at 30 fps. Allow 2^-20
            // of it, so the last key's frame is not dropped.
            let last = if d > 0.0 {
                let x = d * fps as f64;
                (x + x * (1.0 / 1_048_576.0) + 1e-6)
                    .floor()
                    .min(u32::MAX as f64 - 1.0) as u32
            } else {
                0
            };
            FrameRange {
                start: 0,
                end: last + 1,
            }
        }
    };
    let pattern = OutputPattern::parse(&opts.output)?;
    if !pattern.is_numbered() && range.end - range.start != 1 {
        return Err(RenderError::Option(format!(
            "-o {}: {} frames ({}..{}) need a '#' in the pattern for the frame number",
            opts.output.display(),
            range.end - range.start,
            range.start,
            range.end
        )));
    }
    let frames: Vec<u32> = match opts.shard {
        Some(s) if s.count == 0 || s.index >= s.count => {
            return Err(RenderError::Option(format!(
                "--shard {}/{}: needs N >= 1 and 0 <= I < N",
                s.index, s.count
            )))
        }
        Some(s) => (range.start..range.end)
            .filter(|k| k % s.count == s.index)
            .collect(),
        None => (range.start..range.end).collect(),
    };
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
    if let Some(p) = &opts.plot {
        stats::plot_kind(p)?;
    }
    Ok(RenderPlan {
        selection,
        fps,
        range,
        frames,
        pattern,
        camera,
        split: static_dynamic_split(scene, selection).summary(),
    })
}

/// The split a render uses: the static instances of *all* clips (exactly what `subfield
/// bake` writes, so one baked file serves every `--animation`), the other instances
/// dynamic and posed with the selected clips.
fn static_dynamic_split(scene: &Scene, sel: ClipSelection) -> Split {
    let all = scene.split(ClipSelection::All);
    Split {
        selection: sel,
        ..all
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
pub enum RenderEvent<'a> {
    Planned(&'a RenderPlan),
    /// The static part is ready: baked in memory, or opened from `--baked`.
    StaticReady {
        triangles: usize,
        baked_file: bool,
        seconds: f64,
    },
    Frame(&'a FrameReport),
}

/// The outcome of a whole run.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSummary {
    pub plan: RenderPlan,
    pub rendered: usize,
    pub skipped: usize,
    /// Stats of the rendered frames, by frame number.
    pub frames: Vec<FrameStats>,
    /// The preview written, if any.
    pub preview: Option<PathBuf>,
    pub static_seconds: f64,
    pub wall: Duration,
}

/// A frame on its way to the writer.
struct Job {
    index: usize,
    path: PathBuf,
    frame: FrameBuffers,
    stats: FrameStats,
    preview: Option<PathBuf>,
}

fn create_parent(path: &Path) -> Result<(), RenderError> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|source| {
            // "File exists" says little when a file sits where a folder should be.
            match parent.ancestors().find(|a| a.exists()) {
                Some(a) if !a.is_dir() => RenderError::Io {
                    path: parent.to_path_buf(),
                    source: std::io::Error::other(format!(
                        "cannot create the folder: {} is a file",
                        a.display()
                    )),
                },
                _ => RenderError::Io {
                    path: parent.to_path_buf(),
                    source,
                },
            }
        })?;
    }
    Ok(())
}

/// Creates `path`'s folder and checks a file can be made there (the probe is removed).
fn check_writable(path: &Path) -> Result<(), RenderError> {
    create_parent(path)?;
    let folder = crate::atomic::folder_of(path);
    let probe = folder.join(format!(".subfield-probe-{}", std::process::id()));
    std::fs::File::create(&probe).map_err(|source| RenderError::Io {
        path: folder.clone(),
        source,
    })?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

fn write_job(job: &Job, opts: &RenderOptions) -> Result<f64, RenderError> {
    let clock = Instant::now();
    create_parent(&job.path)?;
    let bytes = encode_exr(&job.frame, opts.pixel_type).map_err(|source| RenderError::Exr {
        path: job.path.clone(),
        source,
    })?;
    output::write_atomically(&job.path, &bytes)?;
    if let Some(p) = &job.preview {
        let png = encode_preview(&job.frame).map_err(|source| RenderError::Png {
            path: p.clone(),
            source,
        })?;
        output::write_atomically(p, &png)?;
    }
    Ok(clock.elapsed().as_secs_f64() * 1e3)
}

/// Renders the planned frames of `scene` to EXR files (see the module docs). Every
/// option is checked before the first file is written; `on_event` sees the plan, the
/// static part, and each frame as it is written or skipped. Its parallel loops start
/// soonest when it is called from a rayon pool thread (`subfield render` calls it inside
/// `rayon::scope`; [`Intersector`](crate::Intersector) says why).
pub fn render_sequence(
    scene: &Scene,
    opts: &RenderOptions,
    on_event: &mut dyn FnMut(RenderEvent<'_>),
) -> Result<RenderSummary, RenderError> {
    let wall = Instant::now();
    let plan = plan(scene, opts)?;
    on_event(RenderEvent::Planned(&plan));

    // The static part: opened (refused when stale) or baked in memory.
    let split_all = scene.split(ClipSelection::All);
    let split = static_dynamic_split(scene, plan.selection);
    let static_soup = scene.static_triangles(&split_all);
    let clock = Instant::now();
    let psf = match &opts.baked {
        Some(path) => {
            let hash = format::scene_hash(&static_soup.positions);
            format::open_psf(
                path,
                &OpenOptions {
                    expect_scene_hash: Some(hash),
                },
            )?
            .psf
        }
        None => Psf::build(
            &static_soup.positions,
            &PsfParams::for_triangles(static_soup.len()),
        )?,
    };
    let static_seconds = clock.elapsed().as_secs_f64();

    // Folders, last of the checks.
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
    on_event(RenderEvent::StaticReady {
        triangles: static_soup.len(),
        baked_file: opts.baked.is_some(),
        seconds: static_seconds,
    });

    let preview_frame = opts.preview.as_ref().map(|p| {
        (
            p.frame.unwrap_or(u32::MAX),
            p.path.clone(),
            p.frame.is_none(),
        )
    });
    let static_bounds = static_soup.bounds();
    let total = plan.frames.len();
    let mut stats_out: Vec<FrameStats> = Vec::with_capacity(total);
    let mut skipped = 0usize;
    let mut preview_written = None;
    let mut first_error: Option<RenderError> = None;

    std::thread::scope(|sc| {
        let (tx, rx) = mpsc::sync_channel::<Job>(1);
        let (done_tx, done_rx) = mpsc::channel::<Result<(Job, f64), RenderError>>();
        sc.spawn(move || {
            for job in rx {
                let r = write_job(&job, opts).map(|ms| (job, ms));
                let failed = r.is_err();
                if done_tx.send(r).is_err() || failed {
                    break;
                }
            }
        });

        let mut finish = |r: Result<(Job, f64), RenderError>,
                          stats_out: &mut Vec<FrameStats>,
                          on_event: &mut dyn FnMut(RenderEvent<'_>),
                          first_error: &mut Option<RenderError>| {
            match r {
                Ok((job, ms)) => {
                    let mut st = job.stats;
                    st.write_ms = ms;
                    stats_out.push(st);
                    if job.preview.is_some() {
                        preview_written = job.preview.clone();
                    }
                    on_event(RenderEvent::Frame(&FrameReport {
                        frame: st.frame,
                        index: job.index,
                        total,
                        path: job.path,
                        skipped: false,
                        stats: Some(st),
                    }));
                }
                Err(e) => {
                    first_error.get_or_insert(e);
                }
            }
        };

        // The moving triangles get their own grids, sized for their count like a bake.
        let mut dl = DynamicLayer::for_triangles(plan.split.dynamic_triangles);
        let mut dyn_soup = TriangleSoup::new();
        let mut preview_pending = preview_frame;
        for (index, &frame) in plan.frames.iter().enumerate() {
            while let Ok(r) = done_rx.try_recv() {
                finish(r, &mut stats_out, on_event, &mut first_error);
            }
            if first_error.is_some() {
                break;
            }
            let path = plan.pattern.path(frame);
            if opts.resume
                && is_complete(&path, opts.width, opts.height, opts.aovs, opts.pixel_type)
            {
                skipped += 1;
                on_event(RenderEvent::Frame(&FrameReport {
                    frame,
                    index,
                    total,
                    path,
                    skipped: true,
                    stats: None,
                }));
                continue;
            }
            match render_one(
                scene,
                opts,
                &plan,
                &split,
                &psf,
                &static_soup,
                static_bounds,
                &mut dl,
                &mut dyn_soup,
                frame,
            ) {
                Ok((fb, st)) => {
                    let preview = match &preview_pending {
                        Some((f, p, first)) if *first || *f == frame => {
                            let p = p.clone();
                            preview_pending = None;
                            Some(p)
                        }
                        _ => None,
                    };
                    let job = Job {
                        index,
                        path,
                        frame: fb,
                        stats: st,
                        preview,
                    };
                    if tx.send(job).is_err() {
                        first_error.get_or_insert(RenderError::WriterGone);
                        break;
                    }
                }
                Err(e) => {
                    first_error.get_or_insert(e);
                    break;
                }
            }
        }
        drop(tx);
        for r in done_rx {
            finish(r, &mut stats_out, on_event, &mut first_error);
        }
    });
    if let Some(e) = first_error {
        return Err(e);
    }
    stats_out.sort_by_key(|s| s.frame);
    if let Some(p) = &opts.stats {
        output::write_atomically(p, stats_csv(&stats_out).as_bytes())?;
    }
    if let Some(p) = &opts.plot {
        output::write_atomically(p, &stats::plot_bytes(p, &stats_out)?)?;
    }
    Ok(RenderSummary {
        rendered: stats_out.len(),
        skipped,
        frames: stats_out,
        preview: preview_written,
        static_seconds,
        wall: wall.elapsed(),
        plan,
    })
}

/// Poses, updates and renders one frame.
#[allow(clippy::too_many_arguments)]
fn render_one(
    scene: &Scene,
    opts: &RenderOptions,
    plan: &RenderPlan,
    split: &Split,
    psf: &Psf,
    static_soup: &TriangleSoup,
    static_bounds: Option<(Vec3, Vec3)>,
    dl: &mut DynamicLayer,
    dyn_soup: &mut TriangleSoup,
    frame: u32,
) -> Result<(FrameBuffers, FrameStats), RenderError> {
    let time = plan.time(frame);
    let t = time as f32;
    let clock = Instant::now();
    scene.dynamic_triangles_at(split, t, dyn_soup);
    dl.update(&dyn_soup.positions)?;
    let camera = match &plan.camera {
        CameraSource::Fixed(c) => *c,
        CameraSource::Scene(name) => {
            let cam = scene
                .camera_at(plan.selection, t, name.as_deref())
                .ok_or_else(|| RenderError::UnknownCamera {
                    requested: name.clone().unwrap_or_default(),
                    available: scene.camera_names(),
                })?;
            CameraModel::from_scene(&cam, opts.width, opts.height)
        }
    };
    let lights = scene.lights_at(plan.selection, t);
    let bounds = match (static_bounds, dyn_soup.bounds()) {
        (Some((a, b)), Some((c, d))) => Some((a.min(c), b.max(d))),
        (a, b) => a.or(b),
    };
    let extent = bounds.map_or(1.0, |(lo, hi)| (hi - lo).length());
    let ctx = ShadeContext::new(
        scene,
        static_soup,
        dyn_soup,
        &lights,
        &camera,
        opts.shading,
        extent,
    );
    let update_ms = clock.elapsed().as_secs_f64() * 1e3;
    let tracer = psf.with_dynamic(dl);
    let (fb, work) = render_frame(
        &ctx,
        &tracer,
        &camera,
        frame,
        opts.spp,
        opts.max_depth,
        opts.aovs,
    );
    Ok((
        fb,
        FrameStats {
            frame,
            time,
            update_ms,
            trace_ms: work.trace.as_secs_f64() * 1e3,
            shade_ms: work.shade.as_secs_f64() * 1e3,
            write_ms: 0.0,
            rays: work.rays,
        },
    ))
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
        for bad in ["a#b#.exr", "#x#", "", "out/"] {
            assert!(OutputPattern::parse(Path::new(bad)).is_err(), "{bad}");
        }
    }
}
