//! `subfield generate museum -o FILE.glb [--static-tris N] [--dynamic-tris M] [--frames F]
//! [--fps R] [--seed S]` and `subfield generate animart --triangles N -o FILE.aff`: built-in
//! scenes written to files (one subcommand per scene).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use subfield::gen::animart::{generate_animart, AnimartParams};
use subfield::gen::museum::{write_museum, MuseumParams, MUSEUM_KEYS};

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub scene: Generator,
}

/// The scenes `generate` can write.
#[derive(clap::Subcommand, Debug)]
pub enum Generator {
    /// The demo scene as glTF: a museum room (static) and triangles flying between
    /// formations (morph targets).
    #[command(allow_negative_numbers = true)]
    Museum(MuseumArgs),
    /// BART-style animart: N triangles in unstructured motion, as an AFF file of `tpa`
    /// entries sized to pair with the BART museum's static part.
    #[command(allow_negative_numbers = true)]
    Animart(AnimartArgs),
}

#[derive(clap::Args, Debug)]
pub struct MuseumArgs {
    /// The file to write (atomically): .glb, or .gltf for JSON with an embedded buffer.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Static triangles, exactly (the room, pillars, paintings, sculptures); at least
    /// 852, the room at its coarsest.
    #[arg(long, default_value_t = MuseumParams::default().static_tris)]
    pub static_tris: usize,
    /// Moving triangles, each on its own path.
    #[arg(long, default_value_t = MuseumParams::default().dynamic_tris)]
    pub dynamic_tris: usize,
    /// Frames of the animation; the last key falls on the last frame.
    #[arg(long, default_value_t = MuseumParams::default().frames)]
    pub frames: u32,
    /// Frames per second, recorded in the file (scenes[0].extras.fps).
    #[arg(long, default_value_t = MuseumParams::default().fps)]
    pub fps: f32,
    /// Seed of the moving triangles' shapes and paths.
    #[arg(long, default_value_t = MuseumParams::default().seed)]
    pub seed: u64,
    /// No report.
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    match a.scene {
        Generator::Museum(m) => museum(m),
        Generator::Animart(a) => animart(a),
    }
}

fn museum(a: MuseumArgs) -> anyhow::Result<ExitCode> {
    let p = MuseumParams {
        static_tris: a.static_tris,
        dynamic_tris: a.dynamic_tris,
        frames: a.frames,
        fps: a.fps,
        seed: a.seed,
    };
    p.validate()?;
    // What sits at the path first (a FIFO, a folder), then the name.
    super::check_target("-o", &a.output)?;
    output_is(&a.output, "the museum is glTF", &["glb", "gltf"])?;
    super::prepare_output(&a.output)?;
    write_museum(&p, &a.output)
        .with_context(|| format!("cannot write the museum to {}", a.output.display()))?;
    if !a.quiet {
        let bytes = std::fs::metadata(&a.output).map(|m| m.len()).unwrap_or(0);
        super::print_stdout(&format!(
            "wrote {}: {} static + {} dynamic triangles, {} at {} fps ({:.3} s, {} keys), {} bytes\n",
            a.output.display(),
            p.static_tris,
            p.dynamic_tris,
            subfield::plural(p.frames, "frame"),
            p.fps,
            p.duration(),
            MUSEUM_KEYS,
            bytes
        ))?;
    }
    Ok(ExitCode::SUCCESS)
}

#[derive(clap::Args, Debug)]
pub struct AnimartArgs {
    /// Number of animated triangles.
    #[arg(long, default_value_t = AnimartParams::default().triangles)]
    pub triangles: usize,
    /// The AFF file to write (atomically; its folder is created).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Seed of the random motion (same seed, same file).
    #[arg(long, default_value_t = AnimartParams::default().seed)]
    pub seed: u64,
    /// Frames of the file's `a -1 5 F` line.
    #[arg(long, default_value_t = AnimartParams::default().frames)]
    pub frames: u32,
    /// No report.
    #[arg(long, short)]
    pub quiet: bool,
}

fn animart(a: AnimartArgs) -> anyhow::Result<ExitCode> {
    if a.triangles == 0 {
        anyhow::bail!("--triangles must be at least 1");
    }
    if a.frames < 2 {
        anyhow::bail!("--frames must be at least 2");
    }
    super::check_target("-o", &a.output)?;
    output_is(&a.output, "animart is an AFF scene", &["aff"])?;
    let text = generate_animart(&AnimartParams {
        triangles: a.triangles,
        seed: a.seed,
        frames: a.frames,
    });
    super::prepare_output(&a.output)?;
    subfield::atomic::write_atomically(&a.output, text.as_bytes())
        .with_context(|| format!("cannot write {}", a.output.display()))?;
    if !a.quiet {
        eprintln!(
            "wrote {}: {} (seed {}, {})",
            a.output.display(),
            subfield::plural(a.triangles as u64, "animated triangle"),
            a.seed,
            subfield::plural(a.frames as u64, "frame")
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Refuses an output whose extension is not one of `exts` (any case): a scene written
/// under another name would be read as something it is not.
fn output_is(path: &std::path::Path, what: &str, exts: &[&str]) -> anyhow::Result<()> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    if exts.iter().any(|e| e.eq_ignore_ascii_case(ext)) {
        return Ok(());
    }
    let names: Vec<String> = exts.iter().map(|e| format!(".{e}")).collect();
    anyhow::bail!(
        "{}: {what}: give a file ending in {}",
        path.display(),
        names.join(" or ")
    )
}
