//! `subfield demo [-o DIR]`: the built-in museum (10,284 static triangles, 16,384 moving
//! ones on their own paths, a camera, two lights) written as `DIR/museum.glb`, its static
//! part baked to `DIR/museum.psf`, and the animation rendered from that baked file to
//! `DIR/frame.####.exr` with `DIR/preview.png`, `DIR/stats.csv` and `DIR/plot.svg`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use subfield::format::{write_psf, WriteOptions};
use subfield::gen::museum::{write_museum, MuseumParams};
use subfield::render::{OutputPattern, PreviewOptions, RenderOptions, TraceDevice};
use subfield::scene::ClipSelection;
use subfield::{Psf, PsfParams};

use super::parse;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The folder to write into (created).
    #[arg(short, long, default_value = "demo")]
    pub output: PathBuf,
    /// Frames of the 300 (10 s at 30 fps): A..B, N, A..B:S or a comma list; default all.
    #[arg(long, value_name = "A..B|N|A..B:S,...")]
    pub frames: Option<String>,
    /// Image size.
    #[arg(long, value_name = "WxH", default_value = "640x480")]
    pub size: String,
    /// Exposure in stops: the RGB written (frames and preview) is the radiance × 2^EV.
    #[arg(
        long,
        value_name = "EV",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub exposure: f32,
    /// Where frames are traced: cpu (the default), gpu (a Vulkan adapter through wgpu;
    /// an error when there is none), auto (a discrete GPU when there is one, else the CPU;
    /// says which). On the GPU frames are shaded there too, unless their data do not
    /// fit it (then on the CPU, and the log says why; docs/GPU.md).
    #[arg(long, value_name = "cpu|gpu|auto", default_value = "cpu", value_parser = parse::parse_device)]
    pub device: TraceDevice,
    /// Skip frames already in DIR that read back complete.
    #[arg(long)]
    pub resume: bool,
    /// Worker threads; 0 or absent: all cores.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Frames rendered at once, as `render --frames-in-flight` (absent: the render's
    /// choice).
    #[arg(long, value_name = "N")]
    pub frames_in_flight: Option<usize>,
    /// No progress or report.
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let frames = a.frames.as_deref().map(parse::parse_frames).transpose()?;
    if a.frames_in_flight == Some(0) {
        anyhow::bail!(
            "--frames-in-flight 0: give 1 or more, or leave it out to let the render choose"
        );
    }
    let (width, height) = parse::parse_size(&a.size)?;
    super::set_threads(a.threads)?;
    let dir = &a.output;
    check_outputs(dir)?;
    // `--device gpu` without an adapter fails before the scene and bake are written.
    subfield::render::check_device(a.device)?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;

    let clock = Instant::now();
    let scene_path = dir.join("museum.glb");
    let params = MuseumParams::default();
    write_museum(&params, &scene_path)
        .with_context(|| format!("cannot write {}", scene_path.display()))?;
    let scene = super::load_scene(&scene_path)?;
    let statics = scene.static_triangles(&scene.split(ClipSelection::All));
    let psf = Psf::build(
        &statics.positions,
        &PsfParams::for_scene(statics.len(), scene.has_parallel_light()),
    )?;
    let psf_path = dir.join("museum.psf");
    write_psf(&psf_path, &psf, &WriteOptions::default())
        .with_context(|| format!("cannot write {}", psf_path.display()))?;
    if !a.quiet {
        eprintln!(
            "wrote {} and {} ({} static triangles baked) in {:.2} s",
            scene_path.display(),
            psf_path.display(),
            statics.len(),
            clock.elapsed().as_secs_f64()
        );
    }

    let mid = match &frames {
        Some(set) => {
            set.check()?;
            let n = set.iter().count();
            set.iter().nth(n / 2).unwrap_or_default()
        }
        None => params.frames / 2,
    };
    let opts = RenderOptions {
        output: dir.join("frame.####.exr"),
        baked: Some(psf_path),
        frames,
        width,
        height,
        resume: a.resume,
        exposure: a.exposure,
        device: a.device,
        frames_in_flight: a.frames_in_flight.unwrap_or(0),
        stats: Some(dir.join("stats.csv")),
        plot: Some(dir.join("plot.svg")),
        // The middle frame of the range (of the whole animation: the triangles gathered
        // into a torus).
        preview: Some(PreviewOptions {
            frame: Some(mid),
            path: dir.join("preview.png"),
        }),
        ..RenderOptions::default()
    };
    let Some(summary) = super::render::drive(&scene, &scene_path, &opts, a.quiet, Vec::new())?
    else {
        return Ok(super::guard::interrupted_exit());
    };
    if !a.quiet {
        if let Some(p) = &summary.preview {
            eprintln!("preview: {}", p.display());
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// Refuses, before anything is written, a folder that holds something other than a
/// regular file where the demo writes one: its scene, bake, stats, plot, preview, or a
/// frame (any `frame.####.exr`).
fn check_outputs(dir: &std::path::Path) -> anyhow::Result<()> {
    if dir.exists() && !dir.is_dir() {
        anyhow::bail!("-o {}: is not a folder", dir.display());
    }
    for name in [
        "museum.glb",
        "museum.psf",
        "stats.csv",
        "plot.svg",
        "preview.png",
    ] {
        super::check_target("-o", &dir.join(name))?;
    }
    let frames = OutputPattern::parse(&dir.join("frame.####.exr"))?;
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            let frame = e.file_name().to_str().and_then(|n| frames.frame_of(n));
            if frame.is_some() && !e.file_type().is_ok_and(|t| t.is_file()) {
                super::check_target("-o", &e.path())?;
            }
        }
    }
    Ok(())
}
