//! `subfield generate KIND ...`: test scenes written to files. Each kind is a variant of
//! [`Kind`] with its own arguments and `run` function.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use subfield::aff::{generate_animart, AnimartParams};

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    pub kind: Kind,
}

/// What to generate.
#[derive(clap::Subcommand, Debug)]
pub enum Kind {
    /// BART-style animart: N triangles in unstructured motion, as an AFF file of `tpa`
    /// entries sized to pair with the BART museum's static part.
    Animart(AnimartArgs),
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    match a.kind {
        Kind::Animart(a) => animart(a),
    }
}

#[derive(clap::Args, Debug)]
pub struct AnimartArgs {
    /// Number of animated triangles.
    #[arg(long, default_value_t = AnimartParams::default().triangles)]
    pub triangles: usize,
    /// The AFF file to write (atomically).
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
    let text = generate_animart(&AnimartParams {
        triangles: a.triangles,
        seed: a.seed,
        frames: a.frames,
    });
    write_atomically(&a.output, text.as_bytes())
        .with_context(|| format!("cannot write {}", a.output.display()))?;
    if !a.quiet {
        eprintln!(
            "wrote {}: {} animated triangles (seed {}, {} frames)",
            a.output.display(),
            a.triangles,
            a.seed,
            a.frames
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Temporary file in the same folder, fsync, rename.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| std::io::Error::other("no file name"))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".tmp-{}", std::process::id()));
    let tmp = folder.join(tmp_name);
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}
