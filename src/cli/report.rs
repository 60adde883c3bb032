//! What a render says, for people and for farms: the text lines and progress bar
//! (default), one JSON object a line on stderr (`--log-format json`, for dashboards and
//! `jq`), and the progress lines Open Job Description reads from stdout
//! (`openjd_progress: P`, `openjd_status: ...`, `openjd_fail: ...`; under `openjd run`
//! or a Deadline Cloud worker, `OPENJD_SESSION_WORKING_DIR` is set and they are on by
//! default). The choice is made once per process ([`set`]) so that `main` reports an
//! error the same way the run reported everything else.

use std::io::Write;
use std::sync::OnceLock;

use super::exit::ExitClass;

/// `--log-format`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum LogFormat {
    /// Lines for people, and a progress bar on a terminal.
    #[default]
    Text,
    /// One JSON object a line on stderr for every event; no progress bar.
    Json,
}

/// `--progress`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ProgressFormat {
    /// The bar on a terminal (none elsewhere).
    Bar,
    /// `openjd_progress:` / `openjd_status:` / `openjd_fail:` lines on stdout.
    Openjd,
}

/// How this process reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Reporting {
    pub log: LogFormat,
    pub openjd: bool,
}

static REPORTING: OnceLock<Reporting> = OnceLock::new();

/// Sets how this process reports (the first call wins), from the flags and the
/// environment: `--progress openjd`, or no `--progress` under an Open Job Description
/// session.
pub fn set(log: LogFormat, progress: Option<ProgressFormat>) -> Reporting {
    let openjd = match progress {
        Some(p) => p == ProgressFormat::Openjd,
        None => std::env::var_os("OPENJD_SESSION_WORKING_DIR").is_some_and(|v| !v.is_empty()),
    };
    let r = *REPORTING.get_or_init(|| Reporting { log, openjd });
    if r.log == LogFormat::Json {
        super::guard::json_lines();
    }
    r
}

/// `--log-format` and `--progress` as the raw arguments give them (`--flag value` or
/// `--flag=value`), for an error clap found before the arguments were parsed; an
/// unknown value counts as none.
pub fn formats_in(
    args: impl IntoIterator<Item = std::ffi::OsString>,
) -> (LogFormat, Option<ProgressFormat>) {
    use clap::ValueEnum;
    let args: Vec<String> = args
        .into_iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    let value = |flag: &str| -> Option<String> {
        let eq = format!("{flag}=");
        args.iter().enumerate().rev().find_map(|(i, a)| {
            if a == flag {
                args.get(i + 1).cloned()
            } else {
                a.strip_prefix(&eq).map(str::to_owned)
            }
        })
    };
    let log = value("--log-format")
        .and_then(|v| LogFormat::from_str(&v, false).ok())
        .unwrap_or_default();
    let progress = value("--progress").and_then(|v| ProgressFormat::from_str(&v, false).ok());
    (log, progress)
}

/// How this process reports (text alone until [`set`]).
pub fn get() -> Reporting {
    REPORTING.get().copied().unwrap_or_default()
}

pub fn json() -> bool {
    get().log == LogFormat::Json
}

/// Writes one event as a JSON line on stderr; a stderr that is gone is not an error.
pub fn event(value: serde_json::Value) {
    say(&value.to_string());
}

/// `text` and a newline on stderr in one write: stderr is unbuffered, and a line
/// formatted straight into it goes out in pieces, between which a stopping signal's
/// own line (`guard`, written from its handler) could land (seen once in a test: a
/// `signal` event inside a `frame` event). One write of a line under the pipe's
/// atomic size is never split.
fn say(text: &str) {
    let mut bytes = Vec::with_capacity(text.len() + 1);
    bytes.extend_from_slice(text.as_bytes());
    bytes.push(b'\n');
    let _ = std::io::stderr().lock().write_all(&bytes);
}

/// A line for people: itself in text mode, an `info` event in JSON mode (`warning: `
/// lines become `warning` events).
pub fn line(text: &str) {
    if json() {
        match text.strip_prefix("warning: ") {
            Some(w) => event(serde_json::json!({"event": "warning", "message": w})),
            None => event(serde_json::json!({"event": "info", "message": text})),
        }
    } else {
        say(text);
    }
}

/// Lines for Open Job Description on stdout, flushed at once (the session reads them as
/// they come); a closed stdout is not an error.
pub fn openjd(lines: &[String]) {
    if !get().openjd {
        return;
    }
    let mut out = std::io::stdout().lock();
    for l in lines {
        let _ = writeln!(out, "{l}");
    }
    let _ = out.flush();
}

/// After a frame (rendered or skipped as complete): `done` of `total`.
pub fn openjd_frame(frame: u32, done: usize, total: usize) {
    openjd(&[
        format!(
            "openjd_progress: {:.1}",
            100.0 * done as f64 / total.max(1) as f64
        ),
        format!("openjd_status: frame {done} of {total} (number {frame})"),
    ]);
}

/// The error that ends the command, as `main` reports it: one line on stderr (a JSON
/// `error` event with the exit code and class in JSON mode) and, for Open Job
/// Description, `openjd_fail:` with the same line.
pub fn error(message: &str, class: ExitClass) {
    let r = get();
    if r.log == LogFormat::Json {
        event(serde_json::json!({
            "event": "error",
            "message": message,
            "exit_code": class.code(),
            "class": class.name(),
        }));
    } else {
        say(&format!("error: {message}"));
    }
    openjd(&[format!("openjd_fail: {message}")]);
}

/// Peak resident memory of this process so far (`VmHWM` in `/proc/self/status`), bytes;
/// `None` where there is no such file.
pub fn peak_memory() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line
        .trim_start_matches("VmHWM:")
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peak_memory_is_read_where_linux_has_it() {
        if std::path::Path::new("/proc/self/status").exists() {
            let m = peak_memory().expect("VmHWM");
            // This test process holds more than a megabyte and less than a terabyte.
            assert!(m > 1 << 20 && m < 1 << 40, "{m}");
        }
    }
}
