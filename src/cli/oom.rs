//! Out of memory as one line and exit 5 (`cli::exit`: an I/O or resource failure), not
//! an abort. Rust's allocation failure handler prints `memory allocation of N bytes
//! failed` and aborts (SIGABRT, which a farm sees as a crash with no file named); its
//! hook to do otherwise is not stable. So the command's global allocator is the
//! system's, with two differences:
//!
//! * where the system returns no memory, this writes the error line (naming the scene
//!   being read, if one is: a damaged file, such as a `.usdc` whose array length was
//!   corrupted, can ask the USD reader for more memory than any machine has) and exits
//!   with status 5 at once;
//! * while a USD stage is read, an allocation beyond what its layers can hold
//!   (`subfield::import::usd_allocation_cap`) is a damaged length: one line naming the
//!   file and exit 3 (bad input), before the memory is taken. Without it, a length that
//!   fits in memory was allocated and filled before the reader found the file too short
//!   (8 GB and 15 s for one such file; on a farm whose scheduler caps a task's memory,
//!   a kill without a word).
//!
//! The costs are a test of the returned pointer, which the system's allocator makes
//! anyway, and a thread-local read; `benches/PERF.md` (the robustness rounds after
//! issue 38's round 15) has the timings against the builds without them.

use std::alloc::{GlobalAlloc, Layout, System};
use std::fmt::Write as _;
use std::path::Path;
use std::sync::Mutex;

use super::exit::ExitClass;
use super::report::{self, LogFormat};

/// The system's allocator, exiting with one line where it has no memory.
pub struct Allocator;

// SAFETY: every method forwards its arguments unchanged to `System`, whose
// implementation meets `GlobalAlloc`'s contract; a pointer it returns is returned
// unchanged. Where it returns null, `out_of_memory` never returns: it ends the process
// with `_exit`, which `GlobalAlloc` allows (an allocator may abort on exhaustion) and
// which does not unwind; `within_cap` ends it the same way before `System` is asked,
// or returns having changed nothing. Neither allocates (their lines are formatted into
// buffers on the stack, and `usd_allocation_cap` reads a constant-initialised
// thread-local `Cell`), so they cannot recurse into this allocator.
unsafe impl GlobalAlloc for Allocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        within_cap(layout.size());
        // SAFETY: the caller's guarantees for `alloc` are `System::alloc`'s.
        let p = unsafe { System.alloc(layout) };
        if p.is_null() {
            out_of_memory(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        within_cap(layout.size());
        // SAFETY: as for `alloc`.
        let p = unsafe { System.alloc_zeroed(layout) };
        if p.is_null() {
            out_of_memory(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from this allocator, so from `System`, with `layout`.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        within_cap(new_size);
        // SAFETY: `ptr` came from `System` with `layout`; the caller's guarantees for
        // `new_size` are `System::realloc`'s.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if p.is_null() {
            out_of_memory(new_size);
        }
        p
    }
}

/// Ends the process (`beyond_cap`) where a USD stage is being read on this thread and
/// `bytes` is more than its layers can hold: the check is a thread-local read.
#[inline]
fn within_cap(bytes: usize) {
    #[cfg(feature = "usd")]
    if let Some(cap) = subfield::import::usd_allocation_cap() {
        if bytes as u64 > cap {
            beyond_cap(bytes, cap);
        }
    }
    #[cfg(not(feature = "usd"))]
    let _ = bytes;
}

/// The scene file being read: its path as text and as the inside of a JSON string.
static READING: Mutex<Option<(String, String)>> = Mutex::new(None);

/// While this lives, an allocation that fails names `path` as the file being read, and
/// so does a stack overflow (`guard::ReadingFile`).
pub struct Reading {
    _stack: super::guard::ReadingFile,
}

impl Reading {
    pub fn file(path: &Path) -> Reading {
        let text = path.display().to_string();
        let json = serde_json::to_string(&text).unwrap_or_default();
        let json = json
            .strip_prefix('"')
            .and_then(|j| j.strip_suffix('"'))
            .unwrap_or("")
            .to_string();
        if let Ok(mut r) = READING.lock() {
            *r = Some((text, json));
        }
        Reading {
            _stack: super::guard::ReadingFile::new(path),
        }
    }
}

impl Drop for Reading {
    fn drop(&mut self) {
        let old = READING.lock().ok().and_then(|mut r| r.take());
        drop(old);
    }
}

/// A line built on the stack (the allocator has just failed): what does not fit is cut.
struct StackLine {
    buf: [u8; 4096],
    len: usize,
}

impl StackLine {
    fn new() -> StackLine {
        StackLine {
            buf: [0; 4096],
            len: 0,
        }
    }
}

impl std::fmt::Write for StackLine {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let n = s.len().min(self.buf.len() - self.len);
        self.buf[self.len..self.len + n].copy_from_slice(&s.as_bytes()[..n]);
        self.len += n;
        Ok(())
    }
}

fn gib(bytes: usize) -> f64 {
    bytes as f64 / f64::from(1u32 << 30)
}

/// The file being read, as its line shows it (JSON-escaped in a JSON log), given to
/// `f`; `None` where no file is being read or its name is being set.
fn with_reading<R>(json: bool, f: impl FnOnce(Option<&str>) -> R) -> R {
    // `try_lock`: a thread may hold the lock while it sets or clears the name; then the
    // line goes without it rather than waiting.
    match READING.try_lock() {
        Ok(r) => f(r
            .as_ref()
            .map(|(t, j)| if json { j.as_str() } else { t.as_str() })),
        Err(_) => f(None),
    }
}

fn out_of_memory(bytes: usize) -> ! {
    let json = report::get().log == LogFormat::Json;
    let mut message = StackLine::new();
    with_reading(json, |file| match file {
        Some(file) => write!(
            message,
            "{file}: out of memory while reading it: {bytes} bytes ({:.1} GiB) could not be \
             allocated at once (a damaged file can ask for more than any machine has)",
            gib(bytes)
        ),
        None => write!(
            message,
            "out of memory: {bytes} bytes ({:.1} GiB) could not be allocated at once; retry \
             with fewer --threads or --frames-in-flight, or on a machine with more memory",
            gib(bytes)
        ),
    })
    .ok();
    end(ExitClass::Resource, &message)
}

/// An allocation beyond what the USD file being read can hold
/// (`subfield::import::usd_allocation_cap`): a damaged length, refused before the
/// memory is taken.
#[cfg(feature = "usd")]
fn beyond_cap(bytes: usize, cap: u64) -> ! {
    let json = report::get().log == LogFormat::Json;
    let mut message = StackLine::new();
    with_reading(json, |file| {
        write!(
            message,
            "{}: reading it asked for {bytes} bytes ({:.1} GiB) at once, more than its layers \
             can hold ({:.1} GiB at most for their size); the file is probably damaged (a \
             corrupt array length)",
            file.unwrap_or("the USD file being read"),
            gib(bytes),
            cap as f64 / f64::from(1u32 << 30)
        )
    })
    .ok();
    end(ExitClass::BadInput, &message)
}

/// Writes `message` as the command's one error line (and `openjd_fail:` where the
/// job asks for it) and ends the process with `class`'s status, allocating nothing.
fn end(class: ExitClass, message: &StackLine) -> ! {
    let reporting = report::get();
    let json = reporting.log == LogFormat::Json;
    let text = &message.buf[..message.len];
    let mut line = StackLine::new();
    // A cut line may end inside a character: keep what is whole.
    let text = match std::str::from_utf8(text) {
        Ok(t) => t,
        Err(e) => std::str::from_utf8(&text[..e.valid_up_to()]).unwrap_or("error"),
    };
    // The keys in the order `report::error`'s events have them.
    let _ = if json {
        writeln!(
            line,
            "{{\"class\":\"{}\",\"event\":\"error\",\"exit_code\":{},\"message\":\"{text}\"}}",
            class.name(),
            class.code()
        )
    } else {
        writeln!(line, "error: {text}")
    };
    let mut fail = StackLine::new();
    if reporting.openjd {
        let _ = writeln!(fail, "openjd_fail: {text}");
    }
    // SAFETY: write(2) reads `len` initialised bytes of a live stack buffer; _exit(2)
    // ends the process without running destructors or handlers, so nothing that the
    // failed allocation left half-done runs again.
    unsafe {
        libc::write(2, line.buf.as_ptr().cast(), line.len);
        if fail.len > 0 {
            libc::write(1, fail.buf.as_ptr().cast(), fail.len);
        }
        libc::_exit(i32::from(class.code()));
    }
}
