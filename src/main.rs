//! The `subfield` command. Each subcommand lives in `src/cli/`; this file parses the
//! command line, runs one, and turns an error into one line on stderr and a non-zero
//! exit (the only place that prints errors or exits).
//!
//! The command line is safe code but for one module, `cli::guard` (a SIGBUS handler that
//! turns a bake cut short under its mapping into one line), whose blocks carry their
//! `// SAFETY:` argument; the library's few `unsafe` blocks are its own.
#![deny(unsafe_code)]
#![deny(clippy::undocumented_unsafe_blocks)]

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    cli::guard::file_size_limit_as_error();
    let args = match cli::Cli::try_parse() {
        Ok(a) => a,
        // --help and --version print in full; a usage error is one line.
        Err(e) if !e.use_stderr() => e.exit(),
        Err(e) => {
            // clap's message without its usage block, joined into one line.
            let text = e.to_string();
            let parts: Vec<&str> = text
                .lines()
                .map(str::trim)
                .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more"))
                .filter(|l| !l.is_empty())
                .collect();
            eprintln!("{} (see --help)", parts.join(" "));
            return ExitCode::from(cli::exit::ExitClass::Usage.code());
        }
    };
    let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| cli::run(args)));
    match run {
        Ok(Ok(code)) => code,
        Ok(Err(e)) => {
            // One line: the chain of causes, outermost first.
            let mut line = e.to_string();
            // Causes that the message already quotes are not repeated.
            for cause in e.chain().skip(1) {
                let c = cause.to_string();
                if !line.contains(&c) {
                    line.push_str(&format!(": {c}"));
                }
            }
            let class = cli::exit::exit_class(&e);
            cli::report::error(&line, class);
            ExitCode::from(class.code())
        }
        // The panic's message is on stderr already (the default hook wrote it).
        Err(_) => {
            let class = cli::exit::ExitClass::Internal;
            cli::report::error(
                "internal error (a panic, above): please report it with the command that caused it",
                class,
            );
            ExitCode::from(class.code())
        }
    }
}
