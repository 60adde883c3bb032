//! `subfield inspect FILE.psf [--json]`.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The baked file.
    pub file: PathBuf,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let ins = subfield::format::inspect(&a.file)
        .with_context(|| format!("cannot inspect {}", a.file.display()))?;
    let text = if a.json {
        format!("{}\n", ins.to_json())
    } else {
        ins.to_string()
    };
    super::print_stdout(&text)?;
    Ok(ExitCode::SUCCESS)
}
