//! Command-line parsing (clap) and dispatch. The names and meanings of commands and
//! flags are fixed by `../shared/DESIGN.md` §4.

mod bake;
mod convert;
mod demo;
pub mod exit;
mod generate;
// The two modules of the CLI with unsafe code (a signal handler; the allocator that
// turns out of memory into an error line; see their docs).
#[allow(unsafe_code)]
pub mod guard;
mod inspect;
#[allow(unsafe_code)]
pub mod oom;
mod parse;
mod progress;
mod render;
pub mod report;
mod submit;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "subfield",
    version,
    about = "Ray tracing of animated scenes with unstructured motion (parallel subfields)",
    after_help = exit::HELP
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Bake a scene's static triangles into a .psf file.
    #[command(allow_negative_numbers = true)]
    Bake(bake::Args),
    /// Show a .psf file's header, sections, directions and tile occupancy.
    Inspect(inspect::Args),
    /// Render a scene's animation to an EXR sequence (Whitted shading).
    #[command(allow_negative_numbers = true)]
    Render(Box<render::Args>),
    /// Render the built-in museum demo (no input needed) into a folder.
    #[command(allow_negative_numbers = true)]
    Demo(demo::Args),
    /// Convert a BART .aff / .nff scene to glTF 2.0 (.glb or .gltf), keyframes included.
    Convert(convert::Args),
    /// Write a built-in scene to a file (museum as glTF, animart as AFF).
    Generate(generate::Args),
    /// Render on a farm: a Slurm job array, or an Open Job Description template.
    Submit(submit::Args),
}

/// Runs one command. Errors carry their context (file, section, accessor); `main`
/// prints them as one line.
pub fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Bake(a) => bake::run(a),
        Command::Inspect(a) => inspect::run(a),
        Command::Convert(a) => convert::run(a),
        Command::Demo(a) => demo::run(a),
        Command::Generate(a) => generate::run(a),
        Command::Render(a) => render::run(*a),
        Command::Submit(a) => submit::run(a),
    }
}

/// A scene read from its file, which an allocation that fails meanwhile names
/// ([`oom::Reading`]).
pub fn load_scene(
    path: &std::path::Path,
) -> Result<subfield::scene::Scene, subfield::import::ImportError> {
    let _reading = oom::Reading::file(path);
    subfield::import::load(path)
}

/// The most threads a command starts (`--threads`): past the cores they only take
/// turns, and each costs its stack and its share of the work's hand-overs (3,000 took
/// 45 s to render one 8x8 frame, 100,000 did not finish one in two minutes).
pub const MAX_THREADS: usize = 1024;

/// The cores this process may run on (its affinity and control group's share), 1 where
/// unknown.
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Sets the size of rayon's global pool (`--threads`); 0 or absent keeps rayon's default
/// (all cores). More than [`MAX_THREADS`] is refused.
pub fn set_threads(threads: Option<usize>) -> anyhow::Result<()> {
    if let Some(t) = threads.filter(|&t| t > MAX_THREADS) {
        anyhow::bail!(
            "--threads {t}: at most {MAX_THREADS} (this machine has {} cores; 0 or no \
             --threads uses them all)",
            cores()
        );
    }
    if let Some(t) = threads.filter(|&t| t > 0) {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build_global()
            .map_err(|e| anyhow::anyhow!("cannot start {t} threads: {e}"))?;
    }
    Ok(())
}

/// Writes `text` to stdout; a closed pipe (`| head`) is not an error.
pub fn print_stdout(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|_| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

/// Refuses to write `path` when something other than a regular file is there (a
/// folder, FIFO, socket, device, or a link to one or to nothing; see
/// `subfield::atomic::write_target`); `flag` names the option that gave it.
pub fn check_target(flag: &str, path: &std::path::Path) -> anyhow::Result<()> {
    subfield::atomic::write_target(path)
        .map_err(|e| anyhow::anyhow!("{flag} {}: {e}", path.display()))?;
    Ok(())
}

/// Makes ready to write `path` (`-o`): refuses a path that is not a regular file
/// ([`check_target`]), creates its folder and checks a file can be made there, before
/// any work; an error names the output.
pub fn prepare_output(path: &std::path::Path) -> anyhow::Result<()> {
    use anyhow::Context;
    if path.is_dir() || path.as_os_str().to_string_lossy().ends_with('/') {
        anyhow::bail!("-o {}: names a folder, not a file", path.display());
    }
    check_target("-o", path)?;
    let folder = subfield::atomic::folder_of(path);
    subfield::atomic::create_folder(&folder).with_context(|| {
        format!(
            "cannot write {}: cannot create the folder {}",
            path.display(),
            folder.display()
        )
    })?;
    let probe = folder.join(format!(".subfield-probe-{}", std::process::id()));
    std::fs::File::create(&probe).with_context(|| {
        format!(
            "cannot write {}: cannot create a file in the folder {}",
            path.display(),
            folder.display()
        )
    })?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}
