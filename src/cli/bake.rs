//! `subfield bake SCENE -o FILE.psf [--levels L] [--tiles N] [--codec zstd|none]
//! [--threads T]`: the static part of a scene (all clips playing), baked and written.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use subfield::format::{write_psf, Codec, WriteOptions};
use subfield::import;
use subfield::scene::{ClipSelection, Scene};
use subfield::{Psf, PsfParams};

use super::progress::Progress;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The scene: .gltf, .glb, or a BART .aff / .nff file.
    pub scene: PathBuf,
    /// The baked file to write (atomically; its folder is created).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Direction level 0..=4 (4, 10, 34, 130, 514 directions; antipodes share a subfield;
    /// default: from the triangle count, 3 below 16,384 triangles, 2 below 65,536, else
    /// 1; these suit camera, shadow and mirror rays, use 2 or 1 for random directions).
    #[arg(long)]
    pub levels: Option<u32>,
    /// Tiles along the longer side of each subfield's grid, 1..=4096 (default: from the
    /// triangle count, 0.5·√n rounded to a power of two within 4..=256).
    #[arg(long)]
    pub tiles: Option<u32>,
    /// Section codec: zstd (smaller) or none (raw, opened in place).
    #[arg(long, default_value_t = Codec::Zstd)]
    pub codec: Codec,
    /// Worker threads; 0 or absent: all cores.
    #[arg(long)]
    pub threads: Option<usize>,
    /// No progress or report.
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    super::set_threads(a.threads)?;
    // Check the flags before reading the scene; the tile count may wait for it.
    PsfParams {
        level: a.levels.unwrap_or(1),
        tiles: a.tiles.unwrap_or(1),
    }
    .validate()?;
    super::prepare_output(&a.output)?;
    let scene = import::load(&a.scene)?;
    let say = |s: String| {
        if !a.quiet {
            eprintln!("{s}");
        }
    };
    for w in &scene.warnings {
        say(format!("warning: {w}"));
    }
    let (psf, baked) = bake_static(&scene, &a.scene, a.levels, a.tiles, a.quiet)?;

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
    let auto = PsfParams::for_triangles(soup.len());
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
