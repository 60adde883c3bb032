//! `subfield render SCENE [--baked FILE.psf] -o PATTERN [...]`: a thin shell over
//! `subfield::render::render_sequence` (flags as DESIGN.md §4 fixes them).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context};
use subfield::farm;
use subfield::format::ContentHash;
use subfield::render::{
    self, LookAt, PixelType, PreviewOptions, RenderEvent, RenderOptions, TraceDevice,
};
use subfield::scene::Scene;

use super::parse;
use super::progress::Progress;
use super::report::{self, LogFormat, ProgressFormat};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The scene: .gltf, .glb, USD (.usd, .usda, .usdc, .usdz), or a BART .aff / .nff file.
    pub scene: PathBuf,
    /// Output pattern; one run of '#' becomes the zero-padded frame number
    /// (out/frame.####.exr). Parent folders are created.
    #[arg(short, long)]
    pub output: PathBuf,
    /// A baked file of the scene's static part (from `subfield bake`); without it the
    /// static part is baked in memory.
    #[arg(long)]
    pub baked: Option<PathBuf>,
    /// Frames: A..B (inclusive A, exclusive B), a single frame N, every S-th frame A..B:S,
    /// or a comma list of these (0..10,47,50..60); default: the authored range, from the
    /// frame of the earliest key to the frame of the latest (frame 0 alone without
    /// animation).
    #[arg(long, value_name = "A..B|N|A..B:S,...")]
    pub frames: Option<String>,
    /// Frames per second; frame i shows time i/F (default: the scene's extras.fps, else 24).
    #[arg(long, allow_negative_numbers = true)]
    pub fps: Option<f32>,
    /// Play one animation clip (name or index); default: all clips together when they
    /// animate disjoint targets, else the first (warned).
    #[arg(long, value_name = "NAME|INDEX")]
    pub animation: Option<String>,
    /// Image size; default: 640 wide at the camera's aspect ratio, else 640x480. Pixels
    /// are square: a size of another shape shows more or less of the scene (warned).
    #[arg(long, value_name = "WxH", allow_hyphen_values = true)]
    pub size: Option<String>,
    /// Exposure in stops: the RGB written is the radiance × 2^EV (alpha and AOVs as
    /// traced).
    #[arg(
        long,
        value_name = "EV",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub exposure: f32,
    /// Radiance seen by rays that leave the scene (linear RGB; primary misses keep alpha
    /// 0). Default 0,0,0. Not with --environment.
    #[arg(long, value_name = "R,G,B", allow_hyphen_values = true)]
    pub background: Option<String>,
    /// An equirectangular environment map (.hdr or .exr, linear RGB) seen by rays that
    /// leave the scene; its centre looks along +X, its top straight up (+Y), as Blender
    /// shows an HDRI behind an imported glTF scene.
    #[arg(long, value_name = "FILE.hdr|FILE.exr")]
    pub environment: Option<PathBuf>,
    /// Turn the environment map about +Y by DEG degrees (counter-clockwise seen from
    /// above).
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 0.0,
        allow_negative_numbers = true,
        requires = "environment"
    )]
    pub environment_rotation: f32,
    /// Scale the environment map's radiance by X.
    #[arg(
        long,
        value_name = "X",
        default_value_t = 1.0,
        allow_negative_numbers = true,
        requires = "environment"
    )]
    pub environment_intensity: f32,
    /// Diffuse bounces a sample (cosine-weighted, with shadow rays to every light at each
    /// bounce), converging with --spp; 0 is Whitted's model, where an ambient term stands
    /// in for bounce light.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub diffuse_bounces: u32,
    /// Motion blur: the shutter is open for S of the frame interval (0 to 1), centred on
    /// the frame's time; moving triangles, the camera and the lights blur. 0 (the
    /// default) is no blur.
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub shutter: Option<f32>,
    /// Times within the shutter at which the moving triangles, the camera and the lights
    /// are posed, each sample tracing one (1 to 256; default 5); needs --shutter.
    #[arg(long, value_name = "K")]
    pub motion_steps: Option<u32>,
    /// Also write the first frame this run renders as a tone-mapped sRGB PNG.
    #[arg(long, value_name = "FILE.png")]
    pub preview: Option<PathBuf>,
    /// Samples per pixel (stratified; 1 = the pixel centre).
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Reflection/refraction depth.
    #[arg(long, default_value_t = 4)]
    pub max_depth: u32,
    /// A scene camera by name or by its index in the file's cameras (default: the first;
    /// else one framing the scene). Not with --look-from.
    #[arg(long, value_name = "NAME|INDEX")]
    pub camera: Option<String>,
    /// Camera position (world), overriding the scene's camera; needs --look-at.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub look_from: Option<String>,
    /// Point the camera looks at (world).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub look_at: Option<String>,
    /// Camera up vector (default 0,1,0).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub up: Option<String>,
    /// Vertical field of view in degrees for --look-from (default 45).
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    pub yfov: Option<f32>,
    /// Extra EXR channels: depth (Z), normal (N.X/Y/Z), albedo (albedo.R/G/B), position
    /// (P.X/Y/Z), motion (motion.X/Y, pixels to the next frame), cryptomatte
    /// (CryptoObject00…, CryptoMaterial00…); light-path passes diffuse, specular,
    /// transmission, emission (diffuse.R/G/B …, adding up to R,G,B).
    #[arg(
        long,
        value_name = "depth,normal,albedo,position,motion,cryptomatte,diffuse,specular,transmission,emission"
    )]
    pub aov: Option<String>,
    /// EXR compression (lossless codecs only; dwaa is refused: the exr crate cannot
    /// write it).
    #[arg(long, value_name = "zip|piz|none", default_value = "zip", value_parser = parse::parse_compression)]
    pub compression: render::ExrCompression,
    /// Trace PX more pixels beyond every edge: the EXR's data window grows by PX on each
    /// side, its display window stays the image.
    #[arg(long, value_name = "PX", default_value_t = 0)]
    pub overscan: u32,
    /// Cryptomatte ranks kept per pixel (two a layer); default 6.
    #[arg(long, value_name = "N")]
    pub crypto_levels: Option<u32>,
    /// RGBA as 16-bit half floats (the default).
    #[arg(long, conflicts_with = "float")]
    pub half: bool,
    /// RGBA as 32-bit floats.
    #[arg(long)]
    pub float: bool,
    /// Where frames are traced: cpu (the default), gpu (a Vulkan adapter through wgpu;
    /// an error when there is none), auto (a discrete GPU when there is one, else the CPU;
    /// says which). On the GPU frames are shaded there too, unless their data do not
    /// fit it (then on the CPU, and the log says why; docs/GPU.md).
    #[arg(long, value_name = "cpu|gpu|auto", default_value = "cpu", value_parser = parse::parse_device)]
    pub device: TraceDevice,
    /// Skip frames whose output file exists and reads back complete.
    #[arg(long)]
    pub resume: bool,
    /// Render only the frames k with k % N == I.
    #[arg(long, value_name = "I/N")]
    pub shard: Option<String>,
    /// Worker threads; 0 or absent: all cores.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Frames rendered at once, each with its own moving layer and buffers (on the CPU
    /// 150-330 MB a frame at 640x480); the same bytes whatever N. Absent: on the CPU
    /// one a 4 threads, 2 at least from 2 threads, 8 at most, within half the free
    /// memory; on the GPU 2 (4 at most: one frame's kernels run while another's CPU
    /// side does).
    #[arg(long, value_name = "N")]
    pub frames_in_flight: Option<usize>,
    /// Samples the CPU path traces together at most (0 or absent: 2^19); for tests,
    /// which hold that frames do not depend on it.
    #[arg(long, value_name = "N", hide = true)]
    pub chunk_samples: Option<usize>,
    /// Bytes a still camera's kept shading may take in slots, a frame in flight (0 or
    /// absent: none, only the settled samples' records); for tests, which hold
    /// that frames do not depend on it.
    #[arg(long, value_name = "BYTES", hide = true)]
    pub replay_bytes: Option<usize>,
    /// No progress or report.
    #[arg(long, short)]
    pub quiet: bool,
    /// Per-frame times (update, trace, shade, write), ray counts, and the CPU time the
    /// render's threads spent on the frame (`cpu_ms`, over `threads` threads) as CSV.
    #[arg(long, value_name = "FILE.csv")]
    pub stats: Option<PathBuf>,
    /// Per-frame times as a stacked bar chart.
    #[arg(long, value_name = "FILE.svg|png")]
    pub plot: Option<PathBuf>,
    /// Refuse the baked file unless its content hash (printed by `bake`) is HASH; the
    /// bake is then staged (see --stage-dir).
    #[arg(long, value_name = "HASH", requires = "baked")]
    pub baked_hash: Option<String>,
    /// Refuse the scene file unless its content hash is HASH.
    #[arg(long, value_name = "HASH")]
    pub scene_file_hash: Option<String>,
    /// Stage the baked file into this node-local cache (as <hash>.psf, copied once,
    /// verified) and map the copy (default with --baked-hash: $TMPDIR/subfield-stage).
    #[arg(long, value_name = "DIR")]
    pub stage_dir: Option<PathBuf>,
    /// text: lines for people and a progress bar; json: one JSON object a line on stderr
    /// for every event (start, each frame with its file's content hash, warnings, the
    /// end, an error with its exit code), and no bar.
    #[arg(long, value_name = "text|json", default_value = "text")]
    pub log_format: LogFormat,
    /// openjd: also print `openjd_progress: P` and `openjd_status: ...` after each
    /// frame and `openjd_fail: ...` on error, on stdout (the default when
    /// OPENJD_SESSION_WORKING_DIR is set, as under `openjd run` and Deadline Cloud);
    /// bar: not those lines.
    #[arg(long, value_name = "bar|openjd")]
    pub progress: Option<ProgressFormat>,
}

/// A content hash given on the command line.
pub fn parse_hash(flag: &str, s: &str) -> anyhow::Result<ContentHash> {
    s.parse().with_context(|| flag.to_string())
}

/// Checks the scene file's hash and resolves the bake through the stage, as the flags
/// ask; returns the path to map and a line saying what was done. A task on a farm
/// gets here with both hashes and a stage.
pub fn resolve_inputs(a: &Args) -> anyhow::Result<(Option<PathBuf>, Option<String>)> {
    if let Some(h) = &a.scene_file_hash {
        let want = parse_hash("--scene-file-hash", h)?;
        farm::verify_file("scene file", &a.scene, want)?;
    }
    let Some(baked) = &a.baked else {
        if a.stage_dir.is_some() {
            bail!("--stage-dir stages a baked file: give it with --baked");
        }
        return Ok((None, None));
    };
    let want = a
        .baked_hash
        .as_deref()
        .map(|h| parse_hash("--baked-hash", h))
        .transpose()?;
    if want.is_none() && a.stage_dir.is_none() {
        return Ok((Some(baked.clone()), None));
    }
    let dir = a.stage_dir.clone().unwrap_or_else(farm::default_stage_dir);
    let st = farm::stage_file(baked, want, &dir)?;
    let line = format!(
        "staged {} as {} ({}, {:.1} MiB in {:.2} s)",
        baked.display(),
        st.path.display(),
        match (st.copied, st.replaced_bad_copy) {
            (false, _) => "cached, verified",
            (true, false) => "copied, verified",
            (true, true) => "copied over a damaged cached copy, verified",
        },
        st.bytes as f64 / (1024.0 * 1024.0),
        st.seconds
    );
    Ok((Some(st.path), Some(line)))
}

/// The library's options from the flags (every value checked, one error line each).
pub fn options(a: &Args) -> anyhow::Result<RenderOptions> {
    let (width, height) = match &a.size {
        Some(s) => parse::parse_size(s)?,
        None => (render::DEFAULT_WIDTH, 480),
    };
    let look_at = match (&a.look_from, &a.look_at) {
        (Some(f), Some(t)) => Some(LookAt {
            from: parse::parse_vec3("--look-from", f)?,
            at: parse::parse_vec3("--look-at", t)?,
            up: match &a.up {
                Some(u) => parse::parse_vec3("--up", u)?,
                None => glam::Vec3::Y,
            },
            yfov_deg: a.yfov.unwrap_or(45.0),
        }),
        (None, None) => {
            if a.up.is_some() || a.yfov.is_some() {
                bail!("--up and --yfov describe a camera given with --look-from and --look-at");
            }
            None
        }
        _ => bail!("--look-from and --look-at go together"),
    };
    let crypto_levels = a.crypto_levels.unwrap_or(render::DEFAULT_CRYPTO_LEVELS);
    if crypto_levels == 0 || crypto_levels > 64 {
        bail!("--crypto-levels {crypto_levels}: must be 1 to 64");
    }
    let mut aovs = a
        .aov
        .as_deref()
        .map(parse::parse_aovs)
        .transpose()?
        .unwrap_or_default();
    aovs.crypto_levels = crypto_levels;
    let mut shading = render::ShadingOptions {
        diffuse_bounces: a.diffuse_bounces,
        ..Default::default()
    };
    match (&a.background, &a.environment) {
        (Some(_), Some(_)) => {
            bail!(
                "--background and --environment both say what rays leaving the scene see: give one"
            )
        }
        (Some(b), None) => {
            shading.background = parse::parse_vec3("--background", b)?;
            if shading.background.min_element() < 0.0 {
                bail!("--background {b}: radiance cannot be negative");
            }
        }
        (None, Some(path)) => {
            if !a.environment_rotation.is_finite() {
                bail!("--environment-rotation must be a finite number of degrees");
            }
            if !(a.environment_intensity.is_finite() && a.environment_intensity >= 0.0) {
                bail!(
                    "--environment-intensity {}: must be a finite number, 0 or more",
                    a.environment_intensity
                );
            }
            let map =
                render::EnvironmentMap::load(path, a.environment_rotation, a.environment_intensity)
                    .map_err(|e| anyhow::anyhow!("--environment {e}"))?;
            shading.environment = Some(std::sync::Arc::new(map));
        }
        (None, None) => {}
    }
    Ok(RenderOptions {
        output: a.output.clone(),
        baked: a.baked.clone(),
        frames: a.frames.as_deref().map(parse::parse_frames).transpose()?,
        fps: a.fps,
        animation: a.animation.clone(),
        width,
        height,
        spp: a.spp,
        max_depth: a.max_depth,
        camera: a.camera.clone(),
        look_at,
        aovs,
        pixel_type: if a.float {
            PixelType::Float
        } else {
            PixelType::Half
        },
        resume: a.resume,
        shard: a.shard.as_deref().map(parse::parse_shard).transpose()?,
        stats: a.stats.clone(),
        plot: a.plot.clone(),
        preview: a
            .preview
            .clone()
            .map(|path| PreviewOptions { frame: None, path }),
        shading,
        exposure: a.exposure,
        device: a.device,
        cpu_shading: cpu_shading()?,
        compression: a.compression,
        overscan: a.overscan,
        motion_blur: motion_blur(a)?,
        cancel: Default::default(),
        frames_in_flight: match a.frames_in_flight {
            Some(0) => bail!(
                "--frames-in-flight 0: give 1 or more, or leave it out to let the render choose"
            ),
            Some(n) => n,
            None => 0,
        },
        chunk_samples: a.chunk_samples.unwrap_or(0),
        replay_bytes: a.replay_bytes.unwrap_or(0),
    })
}

/// `--shutter` and `--motion-steps` (their ranges are the library's to check).
fn motion_blur(a: &Args) -> anyhow::Result<Option<render::MotionBlur>> {
    Ok(match (a.shutter, a.motion_steps) {
        (None, None) => None,
        (None, Some(k)) => {
            bail!("--motion-steps {k} needs --shutter: the steps are times within the shutter")
        }
        (Some(s), k) => Some(render::MotionBlur {
            shutter: s,
            steps: k.unwrap_or(render::DEFAULT_MOTION_STEPS),
        }),
    })
}

/// The JSON log's `start` event lists this run's frame numbers up to this many; beyond,
/// `frame_set` (the `--frames` form) and `frame_count` say them.
const LISTED_FRAMES: usize = 10_000;

/// Options given that this run leaves unused or cannot use in full, each said once
/// before the render: a user who typed them expected something of them.
fn ignored_options(a: &Args) -> Vec<String> {
    let mut w = Vec::new();
    if let (Some(s), Some(k)) = (a.shutter, a.motion_steps) {
        if s == 0.0 {
            w.push(format!(
                "--motion-steps {k} does nothing with --shutter 0 (no motion blur)"
            ));
        }
    }
    if let Some(n) = a.crypto_levels {
        if !a.aov.as_deref().is_some_and(|v| v.contains("cryptomatte")) {
            w.push(format!(
                "--crypto-levels {n} does nothing without --aov cryptomatte"
            ));
        }
    }
    if let Some(t) = a.threads.filter(|&t| t > super::cores()) {
        w.push(format!(
            "--threads {t} is more than the {} cores this process may use: the threads \
             take turns on them",
            super::cores()
        ));
    }
    w
}

/// Without `--size`, the image is 640 wide at the aspect ratio of the camera the options
/// choose (DESIGN.md §4); `options` left 640x480 until the scene is known.
pub fn size_from_scene(a: &Args, scene: &Scene, opts: &mut RenderOptions) {
    if a.size.is_none() {
        (opts.width, opts.height) = render::default_size(scene, opts);
    }
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    report::set(a.log_format, a.progress);
    let mut opts = options(&a)?;
    super::set_threads(a.threads)?;
    let (baked, staged) = resolve_inputs(&a)?;
    if let Some(p) = &baked {
        super::guard::name_mapped_file(p);
    }
    opts.baked = baked;
    let clock = std::time::Instant::now();
    let scene = super::load_scene(&a.scene)?;
    size_from_scene(&a, &scene, &mut opts);
    let mut preface: Vec<String> = staged.into_iter().collect();
    preface.extend(
        ignored_options(&a)
            .into_iter()
            .map(|w| format!("warning: {w}")),
    );
    preface.push(format!(
        "imported {} in {:.2} s",
        a.scene.display(),
        clock.elapsed().as_secs_f64()
    ));
    let Some(summary) = drive(&scene, &a.scene, &opts, a.quiet, preface)
        .with_context(|| format!("cannot render {}", a.scene.display()))?
    else {
        return Ok(super::guard::interrupted_exit());
    };
    if !a.quiet {
        match (&summary.preview, &opts.preview) {
            (Some(p), _) => report::line(&format!("preview: {}", p.display())),
            (None, Some(p)) => report::line(&format!(
                "no preview written to {}: every frame was skipped as complete",
                p.path.display()
            )),
            (None, None) => {}
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// Renders with progress and a closing report (shared with `subfield demo`). Ctrl-C,
/// SIGTERM or SIGHUP stops the run after the frames in flight: a line says what was
/// written and how to carry on, and the answer is `None` (the command then exits with
/// 128 + the signal).
pub fn drive(
    scene: &Scene,
    label: &Path,
    opts: &RenderOptions,
    quiet: bool,
    preface: Vec<String>,
) -> anyhow::Result<Option<render::RenderSummary>> {
    let mut opts = opts.clone();
    opts.cancel = super::guard::stop_on_interrupt();
    let opts = &opts;
    let json = report::json();
    // The `start` event of --log-format json, made from the plan and the device.
    let mut start = serde_json::json!({
        "event": "start",
        "scene": label.display().to_string(),
        "output": opts.output.display().to_string(),
    });
    let mut bar: Option<Progress> = None;
    // Messages wait until every check has passed, so that an error is the only line;
    // `preface` comes first (what was done before the scene was planned).
    let mut pending = preface;
    let mut static_said = false;
    pending.extend(scene.warnings.iter().map(|w| format!("warning: {w}")));
    let mut done = 0u64;
    // The sequence runs on a pool thread (this one waits): each of its parallel loops
    // then starts at once on that thread, where from outside the pool each would park its
    // caller and wait for a sleeping worker to wake, which took 0.5–2 ms a time on the
    // shared machines (`benches/PERF.md`, step 79: the demo's frame 409 → 383 ms). The
    // writer thread it feeds encodes without rayon (`non_parallel`), so a frame waiting
    // for the writer cannot hold up work the writer needs.
    let result = rayon::scope(|_| {
        render::render_sequence(scene, opts, &mut |e| match e {
            RenderEvent::Planned(p) => {
                if json {
                    start["options"] = opts
                        .options_string(p.fps, p.ambient, p.default_light)
                        .into();
                    start["frame_set"] = p.set.to_string().into();
                    start["frame_count"] = p.frames.len().into();
                    // Listed up to a bound: a line of megabytes chokes log shippers.
                    if p.frames.len() <= LISTED_FRAMES {
                        start["frames"] = p.frames.iter().collect::<Vec<u32>>().into();
                    }
                    start["fps"] = p.fps.into();
                    start["size"] = serde_json::json!([opts.width, opts.height]);
                    start["spp"] = opts.spp.into();
                }
                pending.extend(p.warnings.iter().map(|w| format!("warning: {w}")));
                pending.push(format!(
                    "{}: {}; frames {} at {} fps, {} to render, {}x{} at {} spp",
                    label.display(),
                    p.split,
                    p.set,
                    p.fps,
                    p.frames.len(),
                    opts.width,
                    opts.height,
                    opts.spp
                ));
            }
            RenderEvent::Device(d) => {
                start["device"] = d.into();
                pending.push(format!("tracing on: {d}"));
            }
            RenderEvent::Note(n) => {
                let line = format!("note: {n}");
                // Said with the preface, or at once when that was said already.
                if !static_said {
                    pending.push(line);
                } else if !quiet || json {
                    report::line(&line);
                }
            }
            RenderEvent::StaticReady {
                triangles,
                baked_file,
                seconds,
            } => {
                pending.push(format!(
                    "static part: {}, {} in {:.2} s",
                    subfield::plural(triangles as u64, "triangle"),
                    if baked_file {
                        "opened from the baked file"
                    } else {
                        "baked in memory"
                    },
                    seconds
                ));
                static_said = true;
                if !quiet || json {
                    for line in pending.drain(..) {
                        report::line(&line);
                    }
                }
                if json {
                    start["static"] = serde_json::json!({
                        "triangles": triangles,
                        "from_baked_file": baked_file,
                        "seconds": seconds,
                    });
                    report::event(std::mem::take(&mut start));
                }
            }
            RenderEvent::Frame(f) => {
                let b = bar
                    .get_or_insert_with(|| Progress::new("frames", f.total as u64, quiet || json));
                done += 1;
                if json {
                    report::event(frame_event(f));
                }
                report::openjd_frame(f.frame, done as usize, f.total);
                let extra = match &f.stats {
                    Some(s) => {
                        let secs = (s.trace_ms + s.shade_ms) / 1e3;
                        format!(
                            "frame {} {:.0} ms, {:.2} Mrays/s",
                            f.frame,
                            s.update_ms + s.trace_ms + s.shade_ms,
                            s.rays.total() as f64 / secs.max(1e-9) / 1e6
                        )
                    }
                    None => format!("frame {} complete, skipped", f.frame),
                };
                b.set(done, &extra);
            }
            // Events a later version adds (the enum is non-exhaustive) need no word here.
            _ => {}
        })
    });
    let summary = match result {
        Err(e @ render::RenderError::Cancelled { .. }) => {
            if let Some(b) = &bar {
                b.finish();
            }
            // Said even with --quiet: it is the outcome of the run. Not `eprintln!`,
            // which panics when stderr is gone (a terminal closed: SIGHUP).
            if json {
                let mut v = serde_json::json!({
                    "event": "interrupted",
                    "message": e.to_string(),
                    "exit_code": super::guard::interrupted_code(),
                });
                if let render::RenderError::Cancelled {
                    written,
                    skipped,
                    left,
                } = &e
                {
                    v["written"] = (*written).into();
                    v["skipped"] = (*skipped).into();
                    v["left"] = (*left).into();
                }
                report::event(v);
            } else {
                let _ = writeln!(std::io::stderr().lock(), "{e}");
            }
            report::openjd(&[format!("openjd_status: {e}")]);
            return Ok(None);
        }
        r => r?,
    };
    if !quiet && summary.replaced > 0 {
        // `--resume` rendered over whole frames: say so, once (issue 35).
        let line = format!(
            "--resume rendered {} again: {} made with other options (the options string in the header differs)",
            subfield::plural(summary.replaced as u64, "finished frame"),
            if summary.replaced == 1 { "it was" } else { "they were" },
        );
        match &bar {
            Some(b) if !json => b.println(&line),
            _ => report::line(&line),
        }
    }
    if json {
        let t = &summary.totals;
        report::event(serde_json::json!({
            "event": "end",
            "rendered": summary.rendered,
            "skipped": summary.skipped,
            "replaced": summary.replaced,
            "wall_seconds": summary.wall.as_secs_f64(),
            "times_ms": {
                "update": t.update_ms,
                "trace": t.trace_ms,
                "shade": t.shade_ms,
                "write": t.write_ms,
            },
            "peak_memory_bytes": report::peak_memory(),
        }));
    } else if !quiet {
        let t = &summary.totals;
        let n = t.frames.max(1) as f64;
        let per = |ms: f64| ms / n;
        let line = format!(
            "rendered {} ({} skipped as complete) to {} in {:.2} s; per frame: update {:.1} ms, trace {:.1} ms, shade {:.1} ms, write {:.1} ms",
            subfield::plural(summary.rendered as u64, "frame"),
            summary.skipped,
            opts.output.display(),
            summary.wall.as_secs_f64(),
            per(t.update_ms),
            per(t.trace_ms),
            per(t.shade_ms),
            per(t.write_ms),
        );
        match &bar {
            Some(b) => {
                b.finish();
                b.println(&line);
            }
            None => eprintln!("{line}"),
        }
    }
    Ok(Some(summary))
}

/// The `frame` event of `--log-format json`: the frame written (with the content hash of
/// its file's bytes, read back: what a farm can check the copy it fetches against) or
/// skipped as complete.
fn frame_event(f: &render::FrameReport) -> serde_json::Value {
    let hash = std::fs::read(&f.path)
        .ok()
        .map(|b| ContentHash::of(&b).to_string());
    let mut v = serde_json::json!({
        "event": "frame",
        "frame": f.frame,
        "index": f.index,
        "total": f.total,
        "path": f.path.display().to_string(),
        "skipped": f.skipped,
        "hash": hash,
        "peak_memory_bytes": report::peak_memory(),
    });
    if let Some(s) = &f.stats {
        v["time"] = s.time.into();
        v["times_ms"] = serde_json::json!({
            "update": s.update_ms,
            "trace": s.trace_ms,
            "shade": s.shade_ms,
            "write": s.write_ms,
        });
        v["rays"] = serde_json::json!({
            "primary": s.rays.primary,
            "shadow": s.rays.shadow,
            "secondary": s.rays.secondary,
            "total": s.rays.total(),
        });
        v["kept"] = s.kept.word().into();
        v["settled"] = s.settled.into();
    }
    v
}

/// `SUBFIELD_GPU_SHADING`: `cpu` keeps shading on the CPU with `--device gpu` (a
/// diagnostic, docs/GPU.md); `gpu` or unset, the GPU frame path where it can.
fn cpu_shading() -> anyhow::Result<bool> {
    match std::env::var("SUBFIELD_GPU_SHADING") {
        Err(std::env::VarError::NotPresent) => Ok(false),
        Ok(v) if v == "gpu" || v.is_empty() => Ok(false),
        Ok(v) if v == "cpu" => Ok(true),
        Ok(v) => bail!("SUBFIELD_GPU_SHADING={v}: expected cpu or gpu"),
        Err(std::env::VarError::NotUnicode(v)) => {
            bail!("SUBFIELD_GPU_SHADING={v:?}: expected cpu or gpu")
        }
    }
}
