//! One clear line instead of a bare signal when a baked file mapped by this process is
//! truncated under it. A raw (`--codec none`) bake is used in place from its memory
//! mapping; if another process cuts the file short (`cp new.psf scene.psf` over it), the
//! next touch of a lost page raises SIGBUS, which by default kills the render with exit
//! 135 and no word of why. The handler here writes a line that names the file and the
//! cause, then exits with status 1 like any other error. A staged bake
//! (`--stage-dir`, `--baked-hash`) is never written again, so it cannot fault this way.

use std::path::Path;
use std::sync::OnceLock;

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
