//! `subfield inspect FILE.psf [--verbose] [--json]`: a one-screen summary, every section
//! and direction with `--verbose`, or everything as JSON.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use subfield::format::FormatError;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The baked file.
    pub file: PathBuf,
    /// Print JSON instead of text (everything, as --verbose).
    #[arg(long)]
    pub json: bool,
    /// Every section and every direction, one row each (default: a one-screen summary).
    #[arg(long, short)]
    pub verbose: bool,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let ins = match subfield::format::inspect(&a.file) {
        Ok(ins) => ins,
        // A scene given for its bake: the command that makes one (issue 35).
        Err(FormatError::GltfScene { kind }) => anyhow::bail!(
            "cannot inspect {}: this is a glTF scene ({kind}), not a baked file: bake it first: subfield bake {} -o {}",
            a.file.display(),
            a.file.display(),
            a.file.with_extension("psf").display(),
        ),
        Err(e) => {
            return Err(e).with_context(|| format!("cannot inspect {}", a.file.display()))
        }
    };
    let text = if a.json {
        format!("{}\n", ins.to_json())
    } else if a.verbose {
        ins.to_string()
    } else {
        ins.summary().to_string()
    };
    super::print_stdout(&text)?;
    Ok(ExitCode::SUCCESS)
}
