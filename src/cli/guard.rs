//! Signals turned into words. **SIGINT** (Ctrl-C) during a render: the first stops the
//! run after the frame in flight (the render's cancel flag; the CLI then says what was
//! written, that `--resume` carries on, and exits with 130), a second stops at once
//! (exit 130; a frame being written is lost, its hidden temporary removed by the next
//! run). **SIGBUS**: one clear line instead of a bare signal when a baked file mapped
//! by this process is truncated under it. A raw (`--codec none`) bake is used in place from its memory
//! mapping; if another process cuts the file short (`cp new.psf scene.psf` over it), the
//! next touch of a lost page raises SIGBUS, which by default kills the render with exit
//! 135 and no word of why. The handler here writes a line that names the file and the
//! cause, then exits with status 1 like any other error. A staged bake
//! (`--stage-dir`, `--baked-hash`) is never written again, so it cannot fault this way.

use std::path::Path;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

use subfield::render::CancelFlag;

/// The exit status of a run stopped by Ctrl-C (128 + SIGINT, as shells report it).
pub fn interrupted_exit() -> ExitCode {
    ExitCode::from(130)
}

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
    // which is what a handler for a fault must do.
    unsafe { libc::_exit(1) }
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

/// The cancel flag of the render in progress; set by the first SIGINT.
static INTERRUPT: OnceLock<Arc<AtomicBool>> = OnceLock::new();

const STOPPING: &[u8] =
    b"\ninterrupt: stopping after the frame in flight (Ctrl-C again stops at once)\n";
const STOPPED: &[u8] =
    b"\ninterrupt: stopped at once; the frame in flight is lost, run again with --resume\n";

/// A cancel flag that SIGINT sets, with the handler installed (once per process; later
/// calls share the flag).
pub fn stop_on_interrupt() -> CancelFlag {
    let mut first = false;
    let flag = INTERRUPT.get_or_init(|| {
        first = true;
        Arc::new(AtomicBool::new(false))
    });
    if first {
        install_sigint();
    }
    CancelFlag::new(flag.clone())
}

extern "C" fn on_sigint(_signal: libc::c_int) {
    if let Some(flag) = INTERRUPT.get() {
        if !flag.swap(true, Ordering::SeqCst) {
            // SAFETY: write(2) is async-signal-safe; STOPPING is a static byte string.
            unsafe {
                libc::write(2, STOPPING.as_ptr().cast(), STOPPING.len());
            }
            return;
        }
    }
    // SAFETY: as above, and _exit(2) ends the process at once without running any
    // handler or destructor (what a handler must do to stop the process).
    unsafe {
        libc::write(2, STOPPED.as_ptr().cast(), STOPPED.len());
        libc::_exit(130)
    }
}

fn install_sigint() {
    // SAFETY: as in `install`: a zero-initialised `sigaction` with an empty mask and an
    // `extern "C" fn(c_int)` handler (no SA_SIGINFO); SA_RESTART so that reads and writes
    // in flight are restarted, not failed with EINTR. `on_sigint` touches only an atomic
    // (`OnceLock::get` is an atomic load once set, and it is set before the handler is
    // installed) and async-signal-safe calls.
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_sigint as extern "C" fn(libc::c_int) as libc::sighandler_t;
        sa.sa_flags = libc::SA_RESTART;
        libc::sigemptyset(&mut sa.sa_mask);
        libc::sigaction(libc::SIGINT, &sa, std::ptr::null_mut());
    }
}
