//! Signals turned into words. **SIGINT** (Ctrl-C), **SIGTERM** (Slurm's `scancel`, time
//! limit and preemption; most farm managers) and **SIGHUP** during a render: the first
//! stops the run after the frames in flight (the render's cancel flag; the CLI then says
//! what was written, that `--resume` carries on, and exits with 128 + the signal: 130,
//! 143, 129), a second stops at once (exit 128 + the second signal; a frame being
//! written is lost, its hidden temporary removed by the next run). **SIGBUS**: one clear line instead of a bare signal when a baked file mapped
//! by this process is truncated under it. A raw (`--codec none`) bake is used in place from its memory
//! mapping; if another process cuts the file short (`cp new.psf scene.psf` over it), the
//! next touch of a lost page raises SIGBUS, which by default kills the render with exit
//! 135 and no word of why. The handler here writes a line that names the file and the
//! cause, then exits with status 5 (an I/O failure: a retry maps the file anew, and its
//! hash check then says whether it is the job's). A staged bake
//! (`--stage-dir`, `--baked-hash`) is never written again, so it cannot fault this way.
//! **SIGXFSZ** is ignored, so that a file-size limit is an error that names the file
//! (exit 5), not a silent kill ([`file_size_limit_as_error`]). **SIGSEGV while a scene
//! is read**: the USD reader (`openusd` 0.6) follows some malformed paths of a damaged
//! file without end (a relationship or connection target such as `<}>`: found by the
//! fuzz target `usd_import`; `import::usd` now refuses the kinds found) and parses
//! nesting recursively (100,000 nested prims overflow an 8 MB stack), until the stack
//! overflows, which Rust reports as `thread 'main' has overflowed its stack` and an
//! abort (exit 134, no file named). While a scene is read ([`ReadingFile`]) the fault is
//! instead one line naming the file, and exit 3 (bad input): reading is safe code, so a
//! fault there is that overflow.

use std::path::Path;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};
use std::sync::{Arc, OnceLock};

use subfield::render::CancelFlag;

/// The whole line, made before the handler is installed (the handler must not allocate).
static MESSAGE: OnceLock<Vec<u8>> = OnceLock::new();

/// Names the file this process maps and installs the handler (once; later calls keep
/// the first name).
pub fn name_mapped_file(path: &Path) {
    let line = format!(
        "error: {}: the baked file was truncated or overwritten while this render had it mapped (SIGBUS); \
         replace a bake in use by writing a new file and renaming it over the old one, or render with --stage-dir\n",
        path.display()
    );
    if MESSAGE.set(line.into_bytes()).is_ok() {
        install();
    }
}

extern "C" fn on_sigbus(_signal: libc::c_int) {
    if let Some(m) = MESSAGE.get() {
        // SAFETY: write(2) and _exit(2) are async-signal-safe; `m` is a fully
        // initialised, never-freed static buffer (OnceLock::get is a plain atomic load
        // once set, and it was set before the handler was installed).
        unsafe {
            libc::write(2, m.as_ptr().cast(), m.len());
        }
    }
    // SAFETY: _exit ends the process at once without running any handler or destructor,
    // which is what a handler for a fault must do. 5: an I/O failure (`cli::exit`).
    unsafe { libc::_exit(5) }
}

fn install() {
    // SAFETY: `sa` is zero-initialised (a valid `sigaction` on Linux and the BSDs: no
    // flags, an empty mask once sigemptyset has run), its handler is an `extern "C" fn`
    // of the signature sigaction expects without SA_SIGINFO, and a null old-action
    // pointer is allowed. Installing a handler for SIGBUS affects only this process.
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_sigbus as extern "C" fn(libc::c_int) as libc::sighandler_t;
        libc::sigemptyset(&mut sa.sa_mask);
        libc::sigaction(libc::SIGBUS, &sa, std::ptr::null_mut());
    }
}

/// A file-size limit (`ulimit -f`, RLIMIT_FSIZE, which Slurm propagates from the
/// submitting shell) kills a process that writes past it with SIGXFSZ, without a word.
/// Ignored, the write fails with EFBIG (`File too large`) instead, which the command
/// reports naming the file, with exit code 5 (`cli::exit`). Programs this process starts
/// (`sbatch`, `squeue`) inherit the ignored signal and likewise see EFBIG.
pub fn file_size_limit_as_error() {
    // SAFETY: signal(2) with SIG_IGN for SIGXFSZ only changes this process's disposition
    // of that signal; no handler code runs.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}

/// The cancel flag of the render in progress; set by the first stopping signal.
static INTERRUPT: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// The signal that set [`INTERRUPT`] (0 while none has): the exit status is 128 + it.
static SIGNAL: AtomicI32 = AtomicI32::new(0);

/// The signals that stop a render after the frames in flight, each with the line the
/// first one writes, as text and as a `--log-format json` event. SIGTERM is how Slurm
/// (`scancel`, a time limit, preemption) and most farm managers stop a task before they
/// SIGKILL it; SIGHUP is a closed terminal or ssh session.
const STOP_SIGNALS: [(libc::c_int, &[u8], &[u8]); 3] = [
    (
        libc::SIGINT,
        b"\ninterrupt: stopping after the frames in flight (Ctrl-C again stops at once)\n",
        b"{\"event\":\"signal\",\"signal\":\"SIGINT\",\"message\":\"stopping after the frames in flight\"}\n",
    ),
    (
        libc::SIGTERM,
        b"\nterminated (SIGTERM): stopping after the frames in flight (a second signal stops at once)\n",
        b"{\"event\":\"signal\",\"signal\":\"SIGTERM\",\"message\":\"stopping after the frames in flight\"}\n",
    ),
    (
        libc::SIGHUP,
        b"\nhangup (SIGHUP): stopping after the frames in flight (a second signal stops at once)\n",
        b"{\"event\":\"signal\",\"signal\":\"SIGHUP\",\"message\":\"stopping after the frames in flight\"}\n",
    ),
];
const STOPPED: &[u8] =
    b"\ninterrupt: stopped at once; the frames in flight are lost, run again with --resume\n";
const STOPPED_JSON: &[u8] = b"{\"event\":\"signal\",\"message\":\"stopped at once; the frames in flight are lost, run again with --resume\"}\n";

/// Whether the handlers write JSON events (`--log-format json`) rather than text.
static JSON_LINES: AtomicBool = AtomicBool::new(false);

/// Makes the signal handlers write their lines as JSON events.
pub fn json_lines() {
    JSON_LINES.store(true, Ordering::SeqCst);
}

/// The exit status of a run stopped by a signal: 128 + the signal, as shells report it
/// (130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP).
pub fn interrupted_exit() -> ExitCode {
    ExitCode::from(interrupted_code())
}

/// The number [`interrupted_exit`] exits with.
pub fn interrupted_code() -> u8 {
    let sig = match SIGNAL.load(Ordering::SeqCst) {
        0 => libc::SIGINT,
        s => s,
    };
    u8::try_from(128 + sig).unwrap_or(130)
}

/// A cancel flag that SIGINT, SIGTERM and SIGHUP set, with the handlers installed (once
/// per process; later calls share the flag). A signal this process inherited as ignored
/// (`nohup` ignores SIGHUP; a shell ignores SIGINT for a background job of a script)
/// stays ignored.
pub fn stop_on_interrupt() -> CancelFlag {
    let mut first = false;
    let flag = INTERRUPT.get_or_init(|| {
        first = true;
        Arc::new(AtomicBool::new(false))
    });
    if first {
        for (signal, _, _) in STOP_SIGNALS {
            install_stop(signal);
        }
    }
    CancelFlag::new(flag.clone())
}

extern "C" fn on_stop(signal: libc::c_int) {
    if let Some(flag) = INTERRUPT.get() {
        if !flag.swap(true, Ordering::SeqCst) {
            SIGNAL.store(signal, Ordering::SeqCst);
            let json = JSON_LINES.load(Ordering::SeqCst);
            let line = STOP_SIGNALS.iter().find(|(s, _, _)| *s == signal).map_or(
                STOP_SIGNALS[0].1,
                |(_, text, j)| if json { *j } else { *text },
            );
            // SAFETY: write(2) is async-signal-safe; `line` is a static byte string.
            unsafe {
                libc::write(2, line.as_ptr().cast(), line.len());
            }
            return;
        }
    }
    let line = if JSON_LINES.load(Ordering::SeqCst) {
        STOPPED_JSON
    } else {
        STOPPED
    };
    // SAFETY: as above, and _exit(2) ends the process at once without running any
    // handler or destructor (what a handler must do to stop the process).
    unsafe {
        libc::write(2, line.as_ptr().cast(), line.len());
        libc::_exit(128 + signal)
    }
}

fn install_stop(signal: libc::c_int) {
    // SAFETY: as in `install`: a zero-initialised `sigaction` with an empty mask and an
    // `extern "C" fn(c_int)` handler (no SA_SIGINFO); SA_RESTART so that reads and writes
    // in flight are restarted, not failed with EINTR. The first call only reads the
    // current action into `old` (a null new action is allowed). `on_stop` touches only
    // atomics (`OnceLock::get` is an atomic load once set, and it is set before the
    // handler is installed) and async-signal-safe calls.
    unsafe {
        let mut old: libc::sigaction = std::mem::zeroed();
        if libc::sigaction(signal, std::ptr::null(), &mut old) == 0
            && old.sa_sigaction == libc::SIG_IGN
        {
            return;
        }
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_stop as extern "C" fn(libc::c_int) as libc::sighandler_t;
        sa.sa_flags = libc::SA_RESTART;
        libc::sigemptyset(&mut sa.sa_mask);
        libc::sigaction(signal, &sa, std::ptr::null_mut());
    }
}

/// The line a fault while a scene is read writes (text or JSON), made before the
/// handler is installed; leaked, so that it lives as long as the handler may run.
static SEGV_LINE: std::sync::atomic::AtomicPtr<Vec<u8>> =
    std::sync::atomic::AtomicPtr::new(std::ptr::null_mut());

/// SIGSEGV's action before [`ReadingFile`] installed its own (Rust's stack overflow
/// report), put back when the file is read.
static SEGV_BEFORE: std::sync::Mutex<Option<libc::sigaction>> = std::sync::Mutex::new(None);

/// While this lives, a segmentation fault (a stack overflow while the scene is read) is
/// one line naming `path` and exit 3.
pub struct ReadingFile;

impl ReadingFile {
    pub fn new(path: &Path) -> ReadingFile {
        let message = format!(
            "{}: reading it overflowed the stack (prims nested deeper than the reader can \
             follow, or something it follows without end); the file is probably damaged",
            path.display()
        );
        let line = if JSON_LINES.load(Ordering::SeqCst) {
            format!(
                "{}\n",
                serde_json::json!({
                    "class": "bad-input",
                    "event": "error",
                    "exit_code": 3,
                    "message": message,
                })
            )
        } else {
            format!("error: {message}\n")
        };
        let old = SEGV_LINE.swap(Box::into_raw(Box::new(line.into_bytes())), Ordering::SeqCst);
        // The line before, if any, stays allocated: a handler may be reading it.
        let _ = old;
        // SAFETY: `sa` is zero-initialised with an empty mask and an `extern "C"
        // fn(c_int)` handler (no SA_SIGINFO); SA_ONSTACK runs it on the alternate
        // signal stack that Rust's runtime sets up for its own stack overflow handler
        // (the overflowed stack has no room left). The old action is read into `old`
        // and kept to be put back. `on_segv` touches only an atomic pointer to a
        // leaked, never-freed buffer and async-signal-safe calls.
        unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = on_segv as extern "C" fn(libc::c_int) as libc::sighandler_t;
            sa.sa_flags = libc::SA_ONSTACK;
            libc::sigemptyset(&mut sa.sa_mask);
            let mut old: libc::sigaction = std::mem::zeroed();
            if libc::sigaction(libc::SIGSEGV, &sa, &mut old) == 0 {
                if let Ok(mut before) = SEGV_BEFORE.lock() {
                    before.get_or_insert(old);
                }
            }
        }
        ReadingFile
    }
}

impl Drop for ReadingFile {
    fn drop(&mut self) {
        if let Some(old) = SEGV_BEFORE.lock().ok().and_then(|mut b| b.take()) {
            // SAFETY: `old` is the action `sigaction` itself returned for SIGSEGV.
            unsafe {
                libc::sigaction(libc::SIGSEGV, &old, std::ptr::null_mut());
            }
        }
    }
}

extern "C" fn on_segv(_signal: libc::c_int) {
    let line = SEGV_LINE.load(Ordering::SeqCst);
    // SAFETY: a non-null `line` points to a leaked `Vec<u8>` that is never freed or
    // changed (a new line replaces the pointer, not the buffer); write(2) and _exit(2)
    // are async-signal-safe, and _exit ends the process without running anything else.
    unsafe {
        if let Some(l) = line.as_ref() {
            libc::write(2, l.as_ptr().cast(), l.len());
        }
        libc::_exit(3)
    }
}
