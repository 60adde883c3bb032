//! `subfield inspect FILE.psf [--verbose] [--json]`: a one-screen summary, every section
//! and direction with `--verbose`, or everything as JSON.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;

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
    let ins = subfield::format::inspect(&a.file)
        .with_context(|| format!("cannot inspect {}", a.file.display()))?;
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
