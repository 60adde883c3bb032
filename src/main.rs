//! The `subfield` command. Each subcommand lives in `src/cli/`; this file parses the
//! command line, runs one, and turns an error into one line on stderr and a non-zero
//! exit (the only place that prints errors or exits).
//!
//! The command line is safe code but for two modules, `cli::guard` (a SIGBUS handler that
//! turns a bake cut short under its mapping into one line) and `cli::oom` (the global
//! allocator, which turns out of memory into one line and exit 5), whose blocks carry
//! their `// SAFETY:` argument; the library's few `unsafe` blocks are its own.
#![deny(unsafe_code)]
#![deny(clippy::undocumented_unsafe_blocks)]

mod cli;

/// The system's allocator, but out of memory is an error line and exit 5 (`cli::oom`).
#[global_allocator]
static ALLOCATOR: cli::oom::Allocator = cli::oom::Allocator;

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
            // The reporter says `error:` itself.
            let joined = parts.join(" ");
            let line = format!(
                "{} (see --help)",
                joined.strip_prefix("error: ").unwrap_or(&joined)
            );
            let class = cli::exit::clap_class(&e);
            // Reported as every other error is: a JSON event with `--log-format json`,
            // and `openjd_fail:` under Open Job Description, read off the raw arguments.
            let (log, progress) = cli::report::formats_in(std::env::args_os().skip(1));
            cli::report::set(log, progress);
            cli::report::error(&line, class);
            return ExitCode::from(class.code());
        }
    };
    let quiet = panics_in_one_line();
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
        Err(_) => {
            let class = cli::exit::ExitClass::Internal;
            // The default hook has written the panic's report above (RUST_BACKTRACE set);
            // else the line says what panicked where.
            let what = match FIRST_PANIC.lock().ok().and_then(|mut p| p.take()) {
                Some(what) if quiet => what,
                _ => "a panic, above".into(),
            };
            cli::report::error(
                &format!(
                    "internal error ({what}): please report it with the command that caused it"
                ),
                class,
            );
            ExitCode::from(class.code())
        }
    }
}

/// The first panic's message and place (later ones are mostly its echoes: a scoped
/// thread's panic raises another where the scope ends).
static FIRST_PANIC: std::sync::Mutex<Option<String>> = std::sync::Mutex::new(None);

/// A panic that reaches `main` is one line like every other error, and a panic that the
/// library contains (the USD reader's on a damaged file, which becomes an error naming
/// the file) writes nothing: the hook only notes the first panic for `main`. With
/// `RUST_BACKTRACE` set the default hook stays, with its report and backtrace. Whether
/// the hook was replaced.
fn panics_in_one_line() -> bool {
    if std::env::var_os("RUST_BACKTRACE").is_some_and(|v| v != "0") {
        return false;
    }
    std::panic::set_hook(Box::new(|info| {
        let payload = info.payload();
        let message = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "no message".into());
        let at = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        if let Ok(mut first) = FIRST_PANIC.lock() {
            first.get_or_insert_with(|| format!("{}{at}", message.replace('\n', " ")));
        }
    }));
    true
}
