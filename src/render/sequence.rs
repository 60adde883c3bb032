//! The sequence loop: the static part opened or baked, then frame by frame the scene
//! posed, the dynamic layer updated, the frame traced and shaded and handed to the
//! writer thread (a channel of a round's frames, so one round is written while the next
//! is traced), and the tables written at the end.
//!
//! Frames in flight (`--frames-in-flight`): the loop renders a round of frames at once,
//! one a lane (a moving layer, or moving triangles on the GPU, soups and scratch of its
//! own, kept from one of its frames to its next), the lanes side by side on the one
//! pool, each frame's own parallel loops nested in it; the round's frames go to the
//! writer in order. On the GPU the lanes share the adapter, the static part and the
//! frame path's kernels, and one lane's CPU side runs while another's kernels do. What
//! a lane keeps (the static memo, the replay) is exact, so a frame's bytes do not depend
//! on its lane or on the frames rendered before it.

use std::path::PathBuf;
use std::sync::mpsc;
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::aov::{CryptoNames, FrameHeader};
use super::camera::CameraModel;
use super::errors::OutputFile;
use super::mips::TextureMips;
use super::options::{RenderOptions, ShadingOptions, TraceDevice};
use super::output::FrameFile;
use super::planning::{
    check_outputs, plan, resumed, static_dynamic_split, CameraSource, RenderPlan,
};
use super::shade::FrameWork;
use super::shade::{FrameBuffers, ShadeContext};
use super::stats::{self, FrameStats, FrameTotals, PlotBars};
use super::wavefront::{
    begin_blurred, finish_blurred, new_frame, render_pass_with, AovInputs, FrameArgs, FrameScratch,
    StepPass,
};
use super::writer::{write_file, write_job, Job};
use super::{FrameReport, RenderError, RenderEvent, RenderSummary};
use crate::atomic::AtomicFile;
use crate::format::{self, OpenOptions};
use crate::psf::{DynamicLayer, Psf, PsfParams};
use crate::scene::{ClipSelection, Scene, Split, TriangleSoup};

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
    // The adapter first: `--device gpu` without one fails before any bake.
    let device = open_device(opts.device)?;
    let used = match &device {
        Some(_) => TraceDevice::Gpu,
        None => TraceDevice::Cpu,
    };
    on_event(RenderEvent::Device(&device_words(&device)));

    // The static part: opened (refused when stale) or baked in memory.
    let split_all = scene.split(ClipSelection::All);
    let split = static_dynamic_split(scene, plan.selection);
    let static_soup = scene.static_triangles(&split_all);
    // `--device gpu`: whole frames on the GPU where the scene is inside the frame path's
    // subset, else shading on the CPU, said once.
    #[cfg(feature = "gpu")]
    let frame_path = match &device {
        Some(d) => match super::gpu_frame::outside_subset(
            scene,
            opts,
            static_soup.len(),
            plan.split.dynamic_triangles,
            d.max_binding(),
        ) {
            None => true,
            Some(why) => {
                on_event(RenderEvent::Note(&format!(
                    "shading on the CPU, tracing on the GPU: the GPU frame path does not \
                     take {why} (docs/GPU.md)"
                )));
                false
            }
        },
        None => false,
    };
    #[cfg(not(feature = "gpu"))]
    let frame_path = false;
    let clock = Instant::now();
    let psf = static_part(&static_soup, scene.has_parallel_light(), used, opts)?;
    let static_seconds = clock.elapsed().as_secs_f64();

    // Folders, last of the checks.
    check_outputs(&plan, opts)?;
    on_event(RenderEvent::StaticReady {
        triangles: static_soup.len(),
        baked_file: opts.baked.is_some(),
        seconds: static_seconds,
    });

    let mips = TextureMips::build(scene);
    let tracing = tracing(
        device,
        &psf,
        plan.split.dynamic_triangles,
        frame_path.then_some((&static_soup, scene, &mips)),
    )?;
    let frames = Frames {
        scene,
        mips: &mips,
        opts,
        plan: &plan,
        split: &split,
        psf: &psf,
        static_soup: &static_soup,
        options: RenderOptions {
            device: used,
            ..opts.clone()
        }
        .options_string(plan.fps, plan.ambient, plan.default_light),
        crypto: opts
            .aovs
            .cryptomatte
            .then(|| std::sync::Arc::new(CryptoNames::new(scene))),
    };
    // The stats file is streamed, a row as each frame is written (frames are written in
    // ascending order), into a temporary that becomes the file at the end.
    let stats_file = match &opts.stats {
        Some(p) => Some((StatsFile::create(p)?, p.clone())),
        None => None,
    };
    let Done {
        totals,
        stats_file,
        plot,
        skipped,
        replaced,
        preview_written,
    } = frames.run(tracing, stats_file, on_event)?;
    if let Some((f, p)) = stats_file {
        f.file.commit().map_err(|source| RenderError::Write {
            path: p,
            file: OutputFile::Stats,
            source,
        })?;
    }
    if let Some(p) = &opts.plot {
        let (bars, per_bar) = plot.means();
        write_file(p, OutputFile::Plot, &stats::plot_bytes(p, &bars, per_bar)?)?;
    }
    Ok(RenderSummary {
        rendered: totals.frames,
        skipped,
        replaced,
        totals,
        preview: preview_written,
        static_seconds,
        wall: wall.elapsed(),
        plan,
    })
}

/// The static part of a render: opened from `--baked` (refused when stale) or baked in
/// memory, for the CPU at level 0 ([`PsfParams::for_cpu_render`]), for the GPU with the
/// scene's default parameters (`parallel_light`:
/// [`Scene::has_parallel_light`](crate::scene::Scene::has_parallel_light)).
fn static_part(
    static_soup: &TriangleSoup,
    parallel_light: bool,
    device: TraceDevice,
    opts: &RenderOptions,
) -> Result<Psf, RenderError> {
    Ok(match &opts.baked {
        Some(path) => {
            let hash = format::scene_hash(&static_soup.positions);
            format::open_psf(
                path,
                &OpenOptions {
                    expect_scene_hash: Some(hash),
                },
            )
            .map_err(|e| RenderError::baked(path, e))?
            .psf
        }
        None => {
            let n = static_soup.len();
            let params = match device {
                TraceDevice::Cpu => PsfParams::for_cpu_render(n, parallel_light),
                _ => PsfParams::for_scene(n, parallel_light),
            };
            Psf::build(&static_soup.positions, &params)?
        }
    })
}

/// Where the frames are traced: the CPU's dynamic layer beside the static PSF, or the
/// GPU's copies of both. Either is traced by the same `render_frame_with`.
enum Tracing {
    Cpu(Box<DynamicLayer>),
    #[cfg(feature = "gpu")]
    Gpu(Box<GpuParts>),
}

/// A frame in flight's part of the GPU: the parts every frame shares (the adapter,
/// the static part, the frame path's kernels) and its own moving triangles.
#[cfg(feature = "gpu")]
struct GpuParts {
    shared: std::sync::Arc<GpuShared>,
    moving: crate::gpu::GpuMoving,
}

#[cfg(feature = "gpu")]
struct GpuShared {
    dev: crate::gpu::GpuDevice,
    stat: crate::gpu::GpuStatic,
    /// The GPU frame path's kernels and static surfaces, when the scene is inside its
    /// subset (`gpu_frame`).
    shading: Option<crate::gpu::GpuShading>,
}

#[cfg(feature = "gpu")]
impl GpuParts {
    /// Another frame in flight's parts: the same shared ones, moving triangles of its own.
    fn another(&self) -> Result<GpuParts, RenderError> {
        Ok(GpuParts {
            shared: self.shared.clone(),
            moving: crate::gpu::GpuMoving::new(&self.shared.dev).map_err(RenderError::gpu)?,
        })
    }
}

#[cfg(feature = "gpu")]
type Device = crate::gpu::GpuDevice;
#[cfg(not(feature = "gpu"))]
type Device = std::convert::Infallible;

/// Checks that `choice` can be served (`--device gpu`: an adapter is there and opens)
/// before a command writes anything else (the demo writes its scene and bake first); the
/// render opens the adapter again. `auto` and `cpu` always can.
pub fn check_device(choice: TraceDevice) -> Result<(), RenderError> {
    match choice {
        TraceDevice::Gpu => open_device(choice).map(|_| ()),
        TraceDevice::Cpu | TraceDevice::Auto => Ok(()),
    }
}

/// The adapter `choice` asks for: `None` for the CPU (`cpu`, or `auto` without a
/// discrete GPU).
fn open_device(choice: TraceDevice) -> Result<Option<Device>, RenderError> {
    #[cfg(feature = "gpu")]
    {
        use crate::gpu::{AdapterPolicy, GpuDevice};
        let policy = match choice {
            TraceDevice::Cpu => return Ok(None),
            TraceDevice::Gpu => AdapterPolicy::Any,
            TraceDevice::Auto => AdapterPolicy::Discrete,
        };
        GpuDevice::open(policy).map_err(|source| RenderError::Gpu {
            device: choice.name(),
            frame: None,
            source,
        })
    }
    #[cfg(not(feature = "gpu"))]
    match choice {
        TraceDevice::Cpu => Ok(None),
        other => Err(RenderError::NoGpuSupport(other.name())),
    }
}

fn device_words(device: &Option<Device>) -> String {
    match device {
        None => "cpu".to_string(),
        #[cfg(feature = "gpu")]
        Some(d) => format!("gpu: {}", d.describe()),
        #[cfg(not(feature = "gpu"))]
        Some(d) => match *d {},
    }
}

/// The frame loop's tracer: on the GPU, the static part uploaded once, and with
/// `frame_path` (the static triangles, the scene and its texture chains) their surfaces
/// and the textures for the GPU frame path.
fn tracing(
    device: Option<Device>,
    psf: &Psf,
    moving: usize,
    frame_path: Option<(&TriangleSoup, &Scene, &TextureMips)>,
) -> Result<Tracing, RenderError> {
    match device {
        None => {
            // The static queries no point grid takes go through the box tree: built
            // here on every thread, before any frame traces.
            psf.prepare_tree();
            Ok(Tracing::Cpu(Box::new(DynamicLayer::for_triangles(moving))))
        }
        #[cfg(feature = "gpu")]
        Some(dev) => {
            let stat = crate::gpu::GpuStatic::upload(&dev, psf).map_err(RenderError::gpu)?;
            let moving = crate::gpu::GpuMoving::new(&dev).map_err(RenderError::gpu)?;
            let shading = match frame_path {
                Some((soup, scene, mips)) => Some(
                    crate::gpu::GpuShading::new_textured(
                        &dev,
                        &super::gpu_frame::surfaces(soup, scene.materials.len()),
                        &super::gpu_frame::textures(scene, mips),
                    )
                    .map_err(RenderError::gpu)?,
                ),
                None => None,
            };
            Ok(Tracing::Gpu(Box::new(GpuParts {
                shared: std::sync::Arc::new(GpuShared { dev, stat, shading }),
                moving,
            })))
        }
        #[cfg(not(feature = "gpu"))]
        Some(d) => {
            let _ = (psf, frame_path);
            match d {}
        }
    }
}

/// What the frame loop renders from.
struct Frames<'a> {
    scene: &'a Scene,
    /// The scene's texture mip-maps, built once for the whole sequence.
    mips: &'a TextureMips,
    opts: &'a RenderOptions,
    plan: &'a RenderPlan,
    split: &'a Split,
    psf: &'a Psf,
    static_soup: &'a TriangleSoup,
    /// This run's options string (frame headers, `--resume`).
    options: String,
    /// Cryptomatte ids and manifests, when asked for.
    crypto: Option<std::sync::Arc<CryptoNames>>,
}

/// `--stats` on its way: the header and a row per written frame, in a temporary.
struct StatsFile {
    file: AtomicFile,
}

impl StatsFile {
    fn create(path: &std::path::Path) -> Result<StatsFile, RenderError> {
        let err = |source| RenderError::Write {
            path: path.to_path_buf(),
            file: OutputFile::Stats,
            source,
        };
        let mut file = AtomicFile::create(path).map_err(err)?;
        file.write_all(stats::CSV_HEADER.as_bytes()).map_err(err)?;
        Ok(StatsFile { file })
    }
}

/// What the frame loop leaves: the written frames' figures summed, the stats file with
/// their rows and the plot's bars, the frames skipped, the preview written.
struct Done {
    totals: FrameTotals,
    stats_file: Option<(StatsFile, PathBuf)>,
    plot: PlotBars,
    skipped: usize,
    /// Whole frames made with other options, rendered again.
    replaced: usize,
    preview_written: Option<PathBuf>,
}

/// The frame loop's account of the frames written, and the first error.
struct Written {
    total: usize,
    totals: FrameTotals,
    stats_file: Option<(StatsFile, PathBuf)>,
    plot: PlotBars,
    preview_written: Option<PathBuf>,
    first_error: Option<RenderError>,
    /// The buffers of the frames written, for the next frames to reuse.
    spare: Vec<FrameBuffers>,
}

impl Written {
    /// Takes the writer's answer for one frame: its stats and event, or the error.
    fn finish(
        &mut self,
        r: Result<(Job, f64), RenderError>,
        on_event: &mut dyn FnMut(RenderEvent<'_>),
    ) {
        match r {
            Ok((job, ms)) => {
                let mut st = job.stats;
                st.write_ms = ms;
                self.totals.add(&st);
                self.plot.push(&st);
                if let Some((f, p)) = &mut self.stats_file {
                    if let Err(source) = f.file.write_all(stats::csv_row(&st).as_bytes()) {
                        self.first_error.get_or_insert(RenderError::Write {
                            path: p.clone(),
                            file: OutputFile::Stats,
                            source,
                        });
                    }
                }
                if job.preview.is_some() {
                    self.preview_written = job.preview.clone();
                }
                self.spare.push(job.frame);
                on_event(RenderEvent::Frame(&FrameReport {
                    frame: st.frame,
                    index: job.index,
                    total: self.total,
                    path: job.path,
                    skipped: false,
                    stats: Some(st),
                }));
            }
            Err(e) => {
                self.first_error.get_or_insert(e);
            }
        }
    }
}

/// The preview still to write: (its frame, its file, whether the first rendered frame
/// takes it).
type PreviewPending = Option<(u32, PathBuf, bool)>;

/// The preview's file when `frame` is the one it shows (the first rendered, or the one
/// asked for); it is then no longer pending.
fn take_preview(pending: &mut PreviewPending, frame: u32) -> Option<PathBuf> {
    match pending {
        Some((f, p, first)) if *first || *f == frame => {
            let p = p.clone();
            *pending = None;
            Some(p)
        }
        _ => None,
    }
}

/// What one frame in flight renders with: a moving layer (or the GPU's parts) and the
/// buffers a frame fills, kept from one of its frames to its next.
struct Lane {
    tracing: Tracing,
    dyn_soup: TriangleSoup,
    next_soup: TriangleSoup,
    scratch: FrameScratch,
}

impl Lane {
    fn new(tracing: Tracing, opts: &RenderOptions) -> Lane {
        Lane {
            tracing,
            dyn_soup: TriangleSoup::new(),
            next_soup: TriangleSoup::new(),
            scratch: FrameScratch::with_budgets(opts.chunk_samples, opts.replay_bytes),
        }
    }

    fn render(
        &mut self,
        frames: &Frames<'_>,
        static_bounds: Option<(Vec3, Vec3)>,
        frame: u32,
        next: Option<u32>,
    ) -> Result<(FrameBuffers, FrameHeader, FrameStats), RenderError> {
        frames.render_one(
            static_bounds,
            &mut self.tracing,
            &mut self.dyn_soup,
            &mut self.next_soup,
            &mut self.scratch,
            frame,
            next,
        )
    }
}

/// A frame plan's frames by position, read ahead as far as asked; the last `keep`
/// frames read are known again, none further back (`None`).
struct Ahead<I> {
    frames: std::iter::Enumerate<I>,
    /// The last frames read, with their positions, oldest first.
    read: std::collections::VecDeque<(usize, u32)>,
    keep: usize,
}

impl<I: Iterator<Item = u32>> Ahead<I> {
    fn new(frames: I, keep: usize) -> Ahead<I> {
        Ahead {
            frames: frames.enumerate(),
            read: std::collections::VecDeque::with_capacity(keep.max(1) + 1),
            keep: keep.max(1),
        }
    }

    /// The frame at position `at` of the plan, `None` past its end (or too far behind).
    fn at(&mut self, at: usize) -> Option<u32> {
        while self.read.back().is_none_or(|&(i, _)| i < at) {
            self.read.push_back(self.frames.next()?);
            if self.read.len() > self.keep {
                self.read.pop_front();
            }
        }
        self.read.iter().find(|&&(i, _)| i == at).map(|&(_, f)| f)
    }
}

/// Frames the CPU path renders at once: `asked` (`--frames-in-flight`), or for 0 one a
/// [`THREADS_A_FRAME`] threads of the pool's `threads`, two at least from two threads
/// on and [`MAX_AUTO_LANES`] at most, and no more than half the memory `available`
/// (bytes; `None` where unknown) holds at [`LANE_BYTES_A_PIXEL`] for each of a frame's
/// `pixels`. On 2 cores two frames in flight made a dollying camera's whole render 8 %
/// faster, and a still camera's 4-9 % over 72 frames (benches/PERF.md, issue 38,
/// frames in flight): a frame alone leaves the threads waiting at the ends of its many
/// parallel loops, which another frame's work fills.
pub(super) fn lanes(asked: usize, threads: usize, pixels: u64, available: Option<u64>) -> usize {
    if asked > 0 {
        return asked;
    }
    if threads < 2 {
        return 1;
    }
    let wanted = (threads / THREADS_A_FRAME).clamp(2, MAX_AUTO_LANES);
    let fit = available.map_or(wanted, |bytes| {
        let lane = pixels.max(1).saturating_mul(LANE_BYTES_A_PIXEL);
        usize::try_from(bytes / 2 / lane).unwrap_or(usize::MAX)
    });
    wanted.min(fit).max(1)
}

/// Frames in flight on the GPU when `--frames-in-flight` is left to the render: while
/// one frame's kernels run, the other's CPU side (posing, the tables, uploads, reading
/// the pixels back, the AOVs) runs beside them (at most [`crate::gpu::ROOMS`]).
#[cfg(feature = "gpu")]
const GPU_LANES: usize = 2;

/// Frames in flight from which a still stretch is filled once and copied to the other
/// lanes ([`Frames::starts_still`]). 24 still frames at 640x480 on 2 threads: four in
/// flight 2.08 → 1.84 s with it; two in flight no faster (1.69 s either way), and a
/// stretch of three frames slower (0.59 → 0.65 s) (benches/PERF.md, issue 38, round 7).
/// Two where the replay keeps records alone, as it does by default
/// ([`Frames::seed_lanes`]).
const SEED_LANES: usize = 3;

/// The threads a frame in flight gets when `--frames-in-flight` is left to the render.
const THREADS_A_FRAME: usize = 4;

/// The most frames in flight the render chooses by itself.
const MAX_AUTO_LANES: usize = 8;

/// What a frame in flight may cost a pixel of the frame, for the render's own choice:
/// measured 490 bytes (a moving camera) and 1,070 (a still one: its memo and replay) at
/// 640x480, 230 at 1920x1080 (benches/PERF.md, issue 38, frames in flight).
const LANE_BYTES_A_PIXEL: u64 = 1200;

/// The memory this process can still take without swapping or being killed: Linux's
/// `MemAvailable`, and no more than its control group's limit leaves (a farm's
/// scheduler or a container sets one: `--mem` under Slurm); `None` where neither is
/// known.
fn available_memory() -> Option<u64> {
    let read = |p: &str| std::fs::read_to_string(p).ok();
    let system = read("/proc/meminfo").and_then(|t| mem_available(&t));
    let group = read("/proc/self/cgroup").and_then(|own| {
        let (v2, v1) = cgroup_paths(&own);
        let room = |limit: String, usage: String| cgroup_room(&read(&limit)?, &read(&usage)?);
        v2.and_then(|p| {
            room(
                format!("/sys/fs/cgroup{p}/memory.max"),
                format!("/sys/fs/cgroup{p}/memory.current"),
            )
        })
        .or_else(|| {
            v1.and_then(|p| {
                room(
                    format!("/sys/fs/cgroup/memory{p}/memory.limit_in_bytes"),
                    format!("/sys/fs/cgroup/memory{p}/memory.usage_in_bytes"),
                )
            })
        })
    });
    match (system, group) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// `MemAvailable` of `/proc/meminfo`'s text, in bytes.
fn mem_available(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// This process's control group in `/proc/self/cgroup`'s text: its path in the unified
/// hierarchy (v2, `0::PATH`) and in v1's memory controller (`N:memory:PATH`).
fn cgroup_paths(own: &str) -> (Option<&str>, Option<&str>) {
    let mut v2 = None;
    let mut v1 = None;
    for line in own.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(id), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        if id == "0" && controllers.is_empty() {
            v2 = Some(path);
        } else if controllers.split(',').any(|c| c == "memory") {
            v1 = Some(path);
        }
    }
    (v2, v1)
}

/// What a control group's memory `limit` leaves over its `usage` (the two files' text):
/// `None` without a limit (`max` in v2; v1 says so with a number near 2^63).
fn cgroup_room(limit: &str, usage: &str) -> Option<u64> {
    let limit: u64 = limit.trim().parse().ok()?;
    if limit >= 1 << 60 {
        return None;
    }
    let usage: u64 = usage.trim().parse().ok()?;
    Some(limit.saturating_sub(usage))
}

impl Frames<'_> {
    /// Every planned frame rendered (or skipped when resumed) and handed to a writer
    /// thread in order, several at once on the CPU (a round of one a lane); stops at
    /// the first error, once the writer has answered for the frames sent.
    fn run(
        &self,
        tracing: Tracing,
        stats_file: Option<(StatsFile, PathBuf)>,
        on_event: &mut dyn FnMut(RenderEvent<'_>),
    ) -> Result<Done, RenderError> {
        let (opts, plan) = (self.opts, self.plan);
        let preview_frame = opts.preview.as_ref().map(|p| {
            (
                p.frame.unwrap_or(u32::MAX),
                p.path.clone(),
                p.frame.is_none(),
            )
        });
        let static_bounds = self.static_soup.bounds();
        let total = plan.frames.len();
        let mut written = Written {
            total,
            totals: FrameTotals::default(),
            stats_file,
            plot: PlotBars::default(),
            preview_written: None,
            first_error: None,
            spare: Vec::new(),
        };
        let mut skipped = 0usize;
        let mut replaced = 0usize;
        // Frames handed to the writer or skipped, and whether the loop stopped for the
        // cancel flag or because the writer was gone.
        let mut done = 0usize;
        let mut cancelled = false;
        let mut writer_gone = false;

        // The frames rendered at once (`--frames-in-flight`): lanes of their own moving
        // layer (or moving triangles on the GPU) and buffers.
        let lanes_wanted = match &tracing {
            Tracing::Cpu(_) => lanes(
                opts.frames_in_flight,
                rayon::current_num_threads(),
                u64::from(opts.width + 2 * opts.overscan)
                    * u64::from(opts.height + 2 * opts.overscan),
                available_memory(),
            ),
            #[cfg(feature = "gpu")]
            Tracing::Gpu(_) => match opts.frames_in_flight {
                0 => GPU_LANES,
                n if n > crate::gpu::ROOMS => {
                    on_event(RenderEvent::Note(&format!(
                        "--frames-in-flight {n}: the GPU renders {} frames at once at most",
                        crate::gpu::ROOMS
                    )));
                    crate::gpu::ROOMS
                }
                n => n,
            },
        }
        .clamp(1, total.max(1));
        let mut lanes: Vec<Lane> = Vec::with_capacity(lanes_wanted);
        for _ in 1..lanes_wanted {
            let more = match &tracing {
                Tracing::Cpu(_) => Tracing::Cpu(Box::new(DynamicLayer::for_triangles(
                    plan.split.dynamic_triangles,
                ))),
                #[cfg(feature = "gpu")]
                Tracing::Gpu(g) => Tracing::Gpu(Box::new(g.another()?)),
            };
            lanes.push(Lane::new(more, opts));
        }
        lanes.insert(0, Lane::new(tracing, opts));

        std::thread::scope(|sc| {
            // A round's frames wait here while the writer writes the round before.
            let (tx, rx) = mpsc::sync_channel::<Job>(lanes.len());
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

            let mut preview_pending = preview_frame;
            // The render threads' CPU time a frame, beside its wall time (`--stats`).
            let cpu_clock = super::cpu_clock::CpuClock::of_pool();
            let mut pending = plan.frames.iter().enumerate().peekable();
            // The frames in order again, read ahead of `pending` as far as a round's
            // lanes look (planned lazily as `pending` is: a huge range costs nothing).
            // A round asks as far as its first frame plus the lanes and two (a still
            // stretch's test), and then the frames a lane's width after its own.
            let mut ahead = Ahead::new(plan.frames.iter(), lanes.len() + 3);
            'rounds: while pending.peek().is_some() {
                while let Ok(r) = done_rx.try_recv() {
                    written.finish(r, on_event);
                }
                if written.first_error.is_some() {
                    break;
                }
                // Stop between rounds: the frames in flight are written, nothing else
                // started.
                if opts.cancel.is_set() {
                    cancelled = true;
                    break;
                }
                // The round: the next frames to render, one a lane, in order; the frames
                // resumed before them skipped.
                let mut round: Vec<(usize, u32, PathBuf)> = Vec::with_capacity(lanes.len());
                let mut room = lanes.len();
                while round.len() < room {
                    let Some((index, frame)) = pending.next() else {
                        break;
                    };
                    done += 1;
                    let path = plan.pattern.path(frame);
                    let found = resumed(opts, &path, &self.options);
                    replaced += usize::from(found == Some(FrameFile::OtherOptions));
                    if found == Some(FrameFile::Complete) {
                        skipped += 1;
                        on_event(RenderEvent::Frame(&FrameReport {
                            frame,
                            index,
                            total,
                            path,
                            skipped: true,
                            stats: None,
                        }));
                    } else {
                        round.push((index, frame, path));
                        // A still camera from here on: this frame alone, on every
                        // thread, fills what it keeps, and the other lanes copy it
                        // (below) rather than each filling its own.
                        if round.len() == 1 && room >= self.seed_lanes() {
                            let after = [ahead.at(index + 1), ahead.at(index + room + 2)];
                            if self.starts_still(&lanes, frame, after) {
                                room = 1;
                            }
                        }
                    }
                }
                self.share_kept(&mut lanes, &round);
                // Written frames' buffers come back for the next.
                for (lane, fb) in lanes.iter_mut().zip(written.spare.drain(..)) {
                    lane.scratch.recycle(fb);
                }
                let cpu_start = cpu_clock.as_ref().and_then(|c| c.now_ns());
                // The frame each lane renders next, as far as the plan tells (a frame
                // resumed later may take its place): where its camera is this frame's,
                // the lane keeps this frame's shading for it.
                let step = round.len();
                let next: Vec<Option<u32>> = round
                    .iter()
                    .map(|(index, _, _)| ahead.at(index + step))
                    .collect();
                let rendered: Vec<_> = match round.as_slice() {
                    [] => continue,
                    [(_, frame, _)] => {
                        vec![lanes[0].render(self, static_bounds, *frame, next[0])]
                    }
                    _ => lanes
                        .par_iter_mut()
                        .zip(round.par_iter().zip(&next))
                        .map(|(lane, ((_, frame, _), next))| {
                            lane.render(self, static_bounds, *frame, *next)
                        })
                        .collect(),
                };
                // The round's CPU time, shared by its frames.
                let cpu_ms = cpu_clock
                    .as_ref()
                    .and_then(|c| c.ms_since(cpu_start))
                    .map(|ms| ms / round.len() as f64);
                for ((index, frame, path), r) in round.into_iter().zip(rendered) {
                    match r {
                        Ok((fb, header, mut st)) => {
                            if let Some(c) = &cpu_clock {
                                st.cpu_ms = cpu_ms;
                                st.threads = c.threads();
                            }
                            let job = Job {
                                index,
                                path,
                                frame: fb,
                                header,
                                stats: st,
                                preview: take_preview(&mut preview_pending, frame),
                            };
                            if tx.send(job).is_err() {
                                // The writer stopped: its error is on `done_rx`.
                                writer_gone = true;
                                break 'rounds;
                            }
                        }
                        Err(e) => {
                            written.first_error.get_or_insert(e.in_frame(frame));
                            break 'rounds;
                        }
                    }
                }
            }
            drop(tx);
            for r in done_rx {
                written.finish(r, on_event);
            }
        });
        if let Some(e) = written.first_error {
            return Err(e);
        }
        if writer_gone {
            return Err(RenderError::WriterGone);
        }
        if cancelled {
            return Err(RenderError::Cancelled {
                written: written.totals.frames,
                skipped,
                left: total - done,
            });
        }
        Ok(Done {
            totals: written.totals,
            stats_file: written.stats_file,
            plot: written.plot,
            skipped,
            replaced,
            preview_written: written.preview_written,
        })
    }

    /// Whether `frame` starts a still stretch that three lanes or more would each fill
    /// the kept static hits and shading of: its camera is that of `after` (the plan's
    /// next frame, and the one that lane 2's second frame would be) to the bit, the
    /// memo can keep it (one sample a pixel, no motion blur, the CPU path), and no lane
    /// keeps it already. A fill costs a still camera's frame about five times a frame
    /// that reuses (437 against 75-90 ms of CPU at 640x480): one lane fills, on every
    /// thread, and the others copy ([`Frames::share_kept`]). With two lanes, or a
    /// shorter stretch, that was no faster (two fills) or slower (one fill and a
    /// frame that keeps nothing, side by side, against a lone fill and a copy; see
    /// [`SEED_LANES`]).
    fn starts_still(&self, lanes: &[Lane], frame: u32, after: [Option<u32>; 2]) -> bool {
        let opts = self.opts;
        let pixels =
            u64::from(opts.width + 2 * opts.overscan) * u64::from(opts.height + 2 * opts.overscan);
        if lanes.len() < 2
            || !matches!(lanes[0].tracing, Tracing::Cpu(_))
            || opts.blur().is_some()
            || !super::memo::may_keep(opts.spp.max(1) as usize, pixels as usize)
        {
            return false;
        }
        let camera = |f: u32| self.camera_at(self.plan.time(f) as f32).ok();
        let Some(a) = camera(frame) else {
            return false;
        };
        after
            .iter()
            .all(|f| f.and_then(camera).is_some_and(|b| b.bits() == a.bits()))
            && !lanes.iter().any(|l| l.scratch.keeps_for(&a))
    }

    /// Before a round: each lane whose frame's camera another lane keeps the static
    /// hits and shading of, and that keeps none for it itself, copies them: exact
    /// answers for the rays kept with them, so the frames' bytes do not change, and the
    /// copy (some 230 MB at 640x480, a memory copy) replaces a fill of the lane's own.
    fn share_kept(&self, lanes: &mut [Lane], round: &[(usize, u32, PathBuf)]) {
        if round.len() < 2 || !matches!(lanes[0].tracing, Tracing::Cpu(_)) {
            return;
        }
        let cameras: Vec<Option<CameraModel>> = round
            .iter()
            .map(|(_, f, _)| self.camera_at(self.plan.time(*f) as f32).ok())
            .collect();
        for (i, camera) in cameras.iter().enumerate() {
            let Some(camera) = camera else { continue };
            if lanes[i].scratch.keeps_for(camera) {
                continue;
            }
            let Some(from) = (0..lanes.len()).find(|&j| lanes[j].scratch.keeps_for(camera)) else {
                continue;
            };
            let source = std::mem::take(&mut lanes[from].scratch);
            lanes[i].scratch.copy_kept(&source);
            lanes[from].scratch = source;
        }
    }

    /// Lanes from which a still stretch is filled once ([`SEED_LANES`]); two where the
    /// frame has no room for the replay's slots (by default, which keeps the records
    /// alone; with slots asked for, from 1920x1080): its records and sums, copied, let
    /// the other lane's first frame settle its samples, where filling its own was a
    /// whole frame's tracing and shading again (benches/PERF.md, issue 38, round 24).
    fn seed_lanes(&self) -> usize {
        let opts = self.opts;
        let pixels =
            u64::from(opts.width + 2 * opts.overscan) * u64::from(opts.height + 2 * opts.overscan);
        if super::replay::slots_do_not_fit(pixels as usize, opts.replay_bytes) {
            2
        } else {
            SEED_LANES
        }
    }

    /// The camera at time `t`.
    fn camera_at(&self, t: f32) -> Result<CameraModel, RenderError> {
        let (scene, opts, plan) = (self.scene, self.opts, self.plan);
        Ok(match &plan.camera {
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
        })
    }

    /// Poses the moving triangles at `t` into `dyn_soup` and hands them to the tracer.
    fn pose_moving(
        &self,
        t: f32,
        tracing: &mut Tracing,
        dyn_soup: &mut TriangleSoup,
    ) -> Result<(), RenderError> {
        self.scene.dynamic_triangles_at(self.split, t, dyn_soup);
        match tracing {
            Tracing::Cpu(dl) => dl.update(&dyn_soup.positions)?,
            #[cfg(feature = "gpu")]
            Tracing::Gpu(g) => g
                .moving
                .update(&g.shared.dev, &dyn_soup.positions)
                .map_err(RenderError::gpu)?,
        }
        Ok(())
    }

    /// The shading context of time `t`: the lights posed then, the moving triangles as
    /// posed in `dyn_soup`.
    fn context<'s>(
        &'s self,
        t: f32,
        static_bounds: Option<(Vec3, Vec3)>,
        dyn_soup: &'s TriangleSoup,
        camera: &CameraModel,
    ) -> ShadeContext<'s> {
        let lights = self.scene.lights_at(self.plan.selection, t);
        let bounds = match (static_bounds, dyn_soup.bounds()) {
            (Some((a, b)), Some((c, d))) => Some((a.min(c), b.max(d))),
            (a, b) => a.or(b),
        };
        let extent = bounds.map_or(1.0, |(lo, hi)| (hi - lo).length());
        ShadeContext::new(
            self.scene,
            self.static_soup,
            dyn_soup,
            &lights,
            camera,
            ShadingOptions {
                default_light: self.plan.default_light,
                ..self.opts.shading.clone()
            },
            extent,
            self.mips,
        )
    }

    /// Traces one pass of a frame into `fb` through the tracer `tracing` holds: the whole
    /// frame (`pass` `None`) or a step of a blurred one. One renderer, generic over the
    /// tracer (the seam: `geometry::Intersector`).
    #[allow(clippy::too_many_arguments)]
    fn trace(
        &self,
        tracing: &Tracing,
        scratch: &mut FrameScratch,
        ctx: &ShadeContext<'_>,
        args: &FrameArgs<'_>,
        pass: Option<StepPass>,
        fb: &mut FrameBuffers,
        work: &mut FrameWork,
    ) -> Result<(), RenderError> {
        match tracing {
            Tracing::Cpu(dl) => {
                let tracer = self.psf.with_dynamic(dl);
                render_pass_with(scratch, fb, work, ctx, &tracer, args, pass);
            }
            #[cfg(feature = "gpu")]
            Tracing::Gpu(g) => {
                let GpuShared { dev, stat, shading } = &*g.shared;
                if let Some(shading) = shading {
                    // The whole frame (or a blurred frame's step) on the GPU (`gpu_frame`).
                    let parts = super::gpu_frame::GpuParts {
                        dev,
                        stat,
                        moving: &g.moving,
                        shading,
                    };
                    return super::gpu_frame::render_frame_gpu(
                        &parts, scratch, ctx, args, pass, fb, work,
                    )
                    .map_err(RenderError::gpu);
                }
                let tracer = crate::gpu::GpuTracer::new(dev, stat, &g.moving);
                render_pass_with(scratch, fb, work, ctx, &tracer, args, pass);
                // A batch that failed answered "no hit": the frame is not written.
                if let Some(source) = tracer.take_error() {
                    return Err(RenderError::gpu(source));
                }
            }
        }
        Ok(())
    }

    /// Poses, updates and renders one frame; its header values. With motion blur, once
    /// for each time step within the shutter (`MotionBlur`), each step tracing its share
    /// of the samples; the AOVs come from the frame's own time (the middle step when the
    /// step count is odd, else a pass of their own).
    #[allow(clippy::too_many_arguments)]
    fn render_one(
        &self,
        static_bounds: Option<(Vec3, Vec3)>,
        tracing: &mut Tracing,
        dyn_soup: &mut TriangleSoup,
        next_soup: &mut TriangleSoup,
        scratch: &mut FrameScratch,
        frame: u32,
        next_frame: Option<u32>,
    ) -> Result<(FrameBuffers, FrameHeader, FrameStats), RenderError> {
        let (scene, opts, plan) = (self.scene, self.opts, self.plan);
        let time = plan.time(frame);
        let t = time as f32;
        let clock = Instant::now();
        let camera = self.camera_at(t)?;
        // Whether the lane's next frame sees through the same camera, to the bit (an
        // error there is that frame's to report).
        let still_ahead = next_frame.is_some_and(|n| {
            self.camera_at(plan.time(n) as f32)
                .is_ok_and(|c| c.bits() == camera.bits())
        });
        // The motion AOV: the moving triangles and the camera one frame later.
        let next = if opts.aovs.motion {
            let t1 = plan.time(frame.saturating_add(1)) as f32;
            scene.dynamic_triangles_carried(self.split, t1, t, next_soup);
            Some((&*next_soup, self.camera_at(t1)?))
        } else {
            None
        };
        let inputs = AovInputs {
            aovs: opts.aovs,
            overscan: opts.overscan,
            next,
            crypto: self.crypto.as_deref(),
        };
        let mut update_ms = clock.elapsed().as_secs_f64() * 1e3;
        let mut work = FrameWork::default();
        let mut fb = new_frame(scratch, &camera, &inputs);
        // The passes: (time, what each traces).
        let passes: Vec<(f32, Option<StepPass>)> = match opts.blur() {
            None => vec![(t, None)],
            Some(b) => {
                let centre = (b.steps % 2 == 1).then_some(b.steps / 2);
                let mut v: Vec<(f32, Option<StepPass>)> = (0..b.steps)
                    .map(|k| {
                        let tk = if Some(k) == centre {
                            t
                        } else {
                            b.step_time(time, plan.fps, k) as f32
                        };
                        let aovs = Some(k) == centre;
                        (
                            tk,
                            Some(StepPass {
                                samples: Some(k),
                                aovs,
                            }),
                        )
                    })
                    .collect();
                if centre.is_none() && opts.aovs.any_centre() {
                    v.push((
                        t,
                        Some(StepPass {
                            samples: None,
                            aovs: true,
                        }),
                    ));
                }
                fb = begin_blurred(scratch, &camera, frame, opts.spp, b.steps, &inputs);
                v
            }
        };
        for (tk, pass) in passes {
            let clock = Instant::now();
            self.pose_moving(tk, tracing, dyn_soup)?;
            let cam = if tk == t { camera } else { self.camera_at(tk)? };
            let ctx = self.context(tk, static_bounds, dyn_soup, &cam);
            update_ms += clock.elapsed().as_secs_f64() * 1e3;
            let args = FrameArgs {
                camera: &cam,
                frame,
                spp: opts.spp,
                max_depth: opts.max_depth,
                inputs: &inputs,
                still_ahead,
            };
            self.trace(tracing, scratch, &ctx, &args, pass, &mut fb, &mut work)?;
        }
        if opts.blur().is_some() {
            finish_blurred(scratch, &mut fb, opts.spp);
        }
        fb.apply_exposure(opts.exposure);
        let header = FrameHeader::new(&camera, plan.fps, self.options.clone(), self.crypto.clone());
        Ok((
            fb,
            header,
            FrameStats {
                frame,
                time,
                update_ms,
                trace_ms: work.trace.as_secs_f64() * 1e3,
                shade_ms: work.shade.as_secs_f64() * 1e3,
                write_ms: 0.0,
                rays: work.rays,
                cpu_ms: None,
                threads: 0,
                kept: work.kept,
                settled: work.settled,
            },
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plan_is_read_ahead_by_position() {
        let frames = [4u32, 5, 7, 9, 10, 12];
        let mut ahead = Ahead::new(frames.iter().copied(), 2);
        assert_eq!(ahead.at(1), Some(5));
        assert_eq!(ahead.at(2), Some(7));
        assert_eq!(ahead.at(2), Some(7));
        assert_eq!(ahead.at(4), Some(10));
        // Within the last two read: known again; further behind: forgotten.
        assert_eq!(ahead.at(3), Some(9));
        assert_eq!(ahead.at(2), None);
        assert_eq!(ahead.at(5), Some(12));
        assert_eq!(ahead.at(4), Some(10));
        assert_eq!(ahead.at(6), None);
        assert_eq!(ahead.at(9), None);
        assert_eq!(ahead.at(5), Some(12));
        // A huge plan is read only as far as asked.
        let mut read = 0;
        {
            let mut huge = Ahead::new((0..u32::MAX).inspect(|_| read += 1), 4);
            assert_eq!(huge.at(3), Some(3));
            assert_eq!(huge.at(5), Some(5));
        }
        assert_eq!(read, 6);
    }

    #[test]
    fn frames_in_flight_follow_the_threads_and_fit_the_memory() {
        let px = 640 * 480;
        // Asked for: taken as asked.
        assert_eq!(lanes(3, 1, px, Some(0)), 3);
        // Left to the render: one frame on one thread, two from two threads, one a
        // four threads beyond, eight at most.
        assert_eq!(lanes(0, 1, px, None), 1);
        assert_eq!(lanes(0, 2, px, None), 2);
        assert_eq!(lanes(0, 8, px, None), 2);
        assert_eq!(lanes(0, 16, px, None), 4);
        assert_eq!(lanes(0, 128, px, None), MAX_AUTO_LANES);
        // Half the available memory at LANE_BYTES_A_PIXEL a pixel, one at least.
        let lane = px * LANE_BYTES_A_PIXEL;
        assert_eq!(lanes(0, 16, px, Some(6 * lane)), 3);
        assert_eq!(lanes(0, 16, px, Some(lane)), 1);
        assert_eq!(lanes(0, 16, px, Some(0)), 1);
        assert_eq!(lanes(0, 16, 3840 * 2160, Some(64 << 30)), 3);
    }

    #[test]
    fn the_memory_a_render_may_take_is_the_systems_and_its_control_groups() {
        let meminfo =
            "MemTotal:       24105000 kB\nMemFree:  100 kB\nMemAvailable:   20000000 kB\n";
        assert_eq!(mem_available(meminfo), Some(20_000_000 * 1024));
        assert_eq!(mem_available("MemTotal: 5 kB\n"), None);
        // v2 (the unified hierarchy) and v1 (a memory controller's line).
        let v2 = "0::/system.slice/slurmstepd.scope/job_42\n";
        assert_eq!(
            cgroup_paths(v2),
            (Some("/system.slice/slurmstepd.scope/job_42"), None)
        );
        let v1 = "12:pids:/\n4:memory:/slurm/uid_0/job_7\n1:name=systemd:/\n";
        assert_eq!(cgroup_paths(v1), (None, Some("/slurm/uid_0/job_7")));
        let both = "5:cpu,memory:/a\n0::/b\n";
        assert_eq!(cgroup_paths(both), (Some("/b"), Some("/a")));
        // Limits: a number leaves limit - usage; `max` and v1's "none" are no limit.
        assert_eq!(cgroup_room("8589934592\n", "1073741824\n"), Some(7 << 30));
        assert_eq!(cgroup_room("1000\n", "5000\n"), Some(0));
        assert_eq!(cgroup_room("max\n", "5000\n"), None);
        assert_eq!(cgroup_room("9223372036854771712\n", "5000\n"), None);
    }
}
