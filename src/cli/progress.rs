//! Progress reporting: an indicatif bar on a terminal, plain lines otherwise (logs of
//! render farms), nothing with `--quiet`. Everything goes to stderr.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

pub struct Progress {
    inner: Inner,
}

enum Inner {
    Quiet,
    Bar(ProgressBar),
    Lines {
        what: String,
        total: u64,
        last: Mutex<(Instant, u64)>,
    },
}

impl Progress {
    /// Progress over `total` steps of `what` ("subfields", "frames").
    pub fn new(what: &str, total: u64, quiet: bool) -> Progress {
        let inner = if quiet {
            Inner::Quiet
        } else if std::io::stderr().is_terminal() {
            let bar = ProgressBar::new(total);
            bar.set_style(
                ProgressStyle::with_template(
                    "{msg:>10} [{bar:30}] {pos}/{len} {prefix} ({elapsed} elapsed, ETA {eta})",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            bar.set_message(what.to_string());
            Inner::Bar(bar)
        } else {
            Inner::Lines {
                what: what.to_string(),
                total,
                last: Mutex::new((Instant::now(), 0)),
            }
        };
        Progress { inner }
    }

    /// `done` steps are complete; `extra` is shown beside the count (e.g. "3.1 Mrays/s").
    pub fn set(&self, done: u64, extra: &str) {
        match &self.inner {
            Inner::Quiet => {}
            Inner::Bar(b) => {
                b.set_prefix(extra.to_string());
                b.set_position(done);
            }
            Inner::Lines { what, total, last } => {
                // At most one line a second, and always the last one.
                let mut l = last.lock().unwrap_or_else(|p| p.into_inner());
                if done == *total || l.0.elapsed() >= Duration::from_secs(1) && done > l.1 {
                    *l = (Instant::now(), done);
                    eprintln!("{what}: {done}/{total} {extra}");
                }
            }
        }
    }

    pub fn finish(&self) {
        if let Inner::Bar(b) = &self.inner {
            b.finish();
        }
    }

    /// A message line that does not tear the bar.
    pub fn println(&self, msg: &str) {
        match &self.inner {
            Inner::Quiet => {}
            Inner::Bar(b) => b.println(msg),
            Inner::Lines { .. } => eprintln!("{msg}"),
        }
    }
}
