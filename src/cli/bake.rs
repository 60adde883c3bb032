//! `subfield bake SCENE -o FILE.psf [--levels L] [--tiles N] [--codec zstd|none]
//! [--quality default|high] [--threads T]`: the static part of a scene (all clips
//! playing), baked and written; with `--quality high` its parameters are chosen by
//! measured trace cost on the scene's own sample rays (`subfield::psf::tune`).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use subfield::format::{write_psf, Codec, WriteOptions};
use subfield::psf::{Quality, TuneEvent, Tuning};
use subfield::scene::{ClipSelection, Scene};
use subfield::{Psf, PsfParams};

use super::progress::Progress;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The scene: .gltf, .glb, USD (.usd, .usda, .usdc, .usdz), or a BART .aff / .nff file.
    pub scene: PathBuf,
    /// The baked file to write (atomically; its folder is created).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Direction level 0..=4 (4, 10, 34, 130, 514 directions; antipodes share a subfield;
    /// default: from the triangle count, 1 below 1,024 triangles, 3 below 16,384 for a scene
    /// with a directional light or none (else 2), 2 below 65,536, else 1; a render's
    /// camera rays, point lights' shadow rays and mirror rays mostly go through point
    /// grids, which the level does not change; use 2 or 1 for random directions).
    #[arg(long)]
    pub levels: Option<u32>,
    /// Tiles along the longer side of each subfield's grid, 1..=4096 (default: from the
    /// triangle count, 16 below 1,024 triangles, else 0.5·√n rounded to a power of two
    /// within 4..=256).
    #[arg(long)]
    pub tiles: Option<u32>,
    /// Section codec: zstd (smaller) or none (raw, opened in place).
    #[arg(long, default_value_t = Codec::Zstd)]
    pub codec: Codec,
    /// default: parameters from the triangle count (or --levels / --tiles); high: level,
    /// tiles and the BSP's layout chosen by measured trace cost on sample rays from the
    /// scene's cameras and lights (seconds to minutes), recorded in the file.
    #[arg(long, default_value_t = Quality::Default)]
    pub quality: Quality,
    /// Worker threads; 0 or absent: all cores.
    #[arg(long)]
    pub threads: Option<usize>,
    /// No progress or report.
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    super::set_threads(a.threads)?;
    if a.quality == Quality::High && (a.levels.is_some() || a.tiles.is_some()) {
        anyhow::bail!("--quality high chooses the level and tiles itself; give it without --levels and --tiles");
    }
    // Check the flags before reading the scene; the tile count may wait for it.
    PsfParams {
        level: a.levels.unwrap_or(1),
        tiles: a.tiles.unwrap_or(1),
    }
    .validate()?;
    super::prepare_output(&a.output)?;
    let scene = super::load_scene(&a.scene)?;
    let say = |s: String| {
        if !a.quiet {
            eprintln!("{s}");
        }
    };
    for w in &scene.warnings {
        say(format!("warning: {w}"));
    }
    let (psf, baked) = match a.quality {
        Quality::Default => bake_static(&scene, &a.scene, a.levels, a.tiles, a.quiet)?,
        Quality::High => {
            let (psf, tuning, secs) = bake_tuned(&scene, &a.scene, a.quiet)?;
            say(tuning_summary(&tuning));
            (psf, secs)
        }
    };

    let report = write_psf(
        &a.output,
        &psf,
        &WriteOptions {
            codec: a.codec,
            ..WriteOptions::default()
        },
    )
    .with_context(|| format!("cannot write {}", a.output.display()))?;
    say(format!(
        "wrote {}: {}, {} subfields, {} bytes ({} raw), baked in {:.2} s, scene hash {}, content hash {}",
        a.output.display(),
        subfield::plural(psf.triangles().len() as u64, "triangle"),
        psf.subfields().len(),
        report.file_length,
        report.raw_length,
        baked,
        report.scene_hash,
        report.content_hash
    ));
    // The content hash alone on stdout, for scripts (`H=$(subfield bake ... -q)`).
    super::print_stdout(&format!("{}\n", report.content_hash))?;
    Ok(ExitCode::SUCCESS)
}

/// Bakes the static part of `scene` (all clips playing), with `levels` and `tiles` or
/// the automatic choice for its triangle count; progress on stderr unless `quiet`.
/// Returns the tracer and the seconds it took.
pub fn bake_static(
    scene: &Scene,
    label: &Path,
    levels: Option<u32>,
    tiles: Option<u32>,
    quiet: bool,
) -> anyhow::Result<(Psf, f64)> {
    let split = scene.split(ClipSelection::All);
    if !quiet {
        eprintln!("{}: {}", label.display(), split.summary());
    }
    let soup = scene.static_triangles(&split);
    let auto = PsfParams::for_scene(soup.len(), scene.has_parallel_light());
    let params = PsfParams {
        level: levels.unwrap_or(auto.level),
        tiles: tiles.unwrap_or(auto.tiles),
    };
    let start = Instant::now();
    let dirs = subfield::psf::subfield_directions(params.level).len() as u64;
    let bar = Progress::new("subfields", dirs, quiet);
    let psf = Psf::build_with_progress(&soup.positions, &params, &|done, _| {
        bar.set(done as u64, "")
    })
    .with_context(|| format!("cannot bake {}", label.display()))?;
    bar.finish();
    Ok((psf, start.elapsed().as_secs_f64()))
}

/// Bakes the static part of `scene` with the parameters [`tune`](subfield::psf::tune)
/// chooses on the scene's sample rays, one line a trial on stderr unless `quiet`.
/// Returns the tracer, what tuning found and the seconds it all took.
pub fn bake_tuned(scene: &Scene, label: &Path, quiet: bool) -> anyhow::Result<(Psf, Tuning, f64)> {
    let split = scene.split(ClipSelection::All);
    if !quiet {
        eprintln!("{}: {}", label.display(), split.summary());
    }
    let start = Instant::now();
    let soup = scene.static_triangles(&split);
    let context = || format!("cannot bake {}", label.display());
    // Any bake finds the sample's hits (they do not depend on the parameters).
    let auto = PsfParams::for_scene(soup.len(), scene.has_parallel_light());
    let first = Psf::build(&soup.positions, &auto).with_context(context)?;
    let rays = subfield::render::tuning_rays(scene, &first);
    drop(first);
    if !quiet {
        eprintln!(
            "tuning on {} sample rays: {} closest-hit and {} shadow rays through the parallel subfields, {} through point grids (counted at the default's mean cost a ray)",
            rays.len(),
            rays.closest.len(),
            rays.any.len(),
            rays.point
        );
    }
    let n = std::cell::Cell::new(0u32);
    let default_cost = std::cell::Cell::new(0u64);
    let (psf, tuning) = subfield::psf::tune(&soup.positions, auto, &rays, &|e| {
        if quiet {
            return;
        }
        match e {
            TuneEvent::Stage(s) => eprintln!("tuning: {s}"),
            TuneEvent::Trial { trial: t, over_cap } => {
                n.set(n.get() + 1);
                if n.get() == 1 {
                    default_cost.set(t.cost.max(1));
                }
                eprintln!(
                    "  trial {:>2}: level {}, {:>4} tiles, {:>2} a slab, flat up to {:>2}: cost {} ({:.3}x the default), {:.2} MiB{}",
                    n.get(),
                    t.params.level,
                    t.params.tiles,
                    t.bsp.leaf,
                    t.bsp.flat_max,
                    t.cost,
                    t.cost as f64 / default_cost.get() as f64,
                    t.raw_bytes as f64 / (1024.0 * 1024.0),
                    if over_cap { " (over the size cap, not kept)" } else { "" }
                );
            }
        }
    })
    .with_context(context)?;
    Ok((psf, tuning, start.elapsed().as_secs_f64()))
}

/// One line: what tuning chose and what it gains over the default by its measure.
pub fn tuning_summary(t: &Tuning) -> String {
    let c = &t.chosen;
    let d = &t.default;
    format!(
        "chose level {}, {} tiles, {} entries a slab, flat tiles up to {}: cost {:.3}x the default's (level {}, {} tiles) over {} sample rays, {} trials, {:.2} MiB raw against {:.2}",
        c.params.level,
        c.params.tiles,
        c.bsp.leaf,
        c.bsp.flat_max,
        c.cost as f64 / d.cost.max(1) as f64,
        d.params.level,
        d.params.tiles,
        t.record.sample_rays,
        t.record.trials,
        c.raw_bytes as f64 / (1024.0 * 1024.0),
        d.raw_bytes as f64 / (1024.0 * 1024.0),
    )
}
