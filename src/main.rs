//! The `subfield` command. Each subcommand lives in `src/cli/`; this file parses the
//! command line, runs one, and turns an error into one line on stderr and a non-zero
//! exit (the only place that prints errors or exits).

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(code) => code,
        Err(e) => {
            // One line: the chain of causes, outermost first.
            let mut line = format!("error: {e}");
            // Causes that the message already quotes are not repeated.
            for cause in e.chain().skip(1) {
                let c = cause.to_string();
                if !line.contains(&c) {
                    line.push_str(&format!(": {c}"));
                }
            }
            eprintln!("{line}");
            ExitCode::FAILURE
        }
    }
}
