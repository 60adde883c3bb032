//! Out of memory as one line and exit 5 (`cli::exit`: an I/O or resource failure), not
//! an abort. Rust's allocation failure handler prints `memory allocation of N bytes
//! failed` and aborts (SIGABRT, which a farm sees as a crash with no file named); its
//! hook to do otherwise is not stable. So the command's global allocator is the
//! system's, with one difference: where the system returns no memory, this writes the
//! error line (naming the scene being read, if one is: a damaged file, such as a
//! `.usdc` whose array length was corrupted, can ask the USD reader for more memory
//! than any machine has) and exits with status 5 at once.
//!
//! The one cost is a test of the returned pointer, which the system's allocator makes
//! anyway; `benches/PERF.md` (the robustness round after issue 38's round 15) has the
//! timing against the build without it.

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
// which does not unwind. `out_of_memory` itself allocates nothing (its line is
// formatted into a buffer on the stack), so it cannot recurse into this allocator.
unsafe impl GlobalAlloc for Allocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's guarantees for `alloc` are `System::alloc`'s.
        let p = unsafe { System.alloc(layout) };
        if p.is_null() {
            out_of_memory(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
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
        // SAFETY: `ptr` came from `System` with `layout`; the caller's guarantees for
        // `new_size` are `System::realloc`'s.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if p.is_null() {
            out_of_memory(new_size);
        }
        p
    }
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

fn out_of_memory(bytes: usize) -> ! {
    let class = ExitClass::Resource;
    let reporting = report::get();
    let json = reporting.log == LogFormat::Json;
    let mut message = StackLine {
        buf: [0; 4096],
        len: 0,
    };
    // `try_lock`: a thread may hold the lock while it sets or clears the name; then the
    // line goes without it rather than waiting.
    match READING.try_lock() {
        Ok(r) if r.is_some() => {
            let (text, escaped) = r
                .as_ref()
                .map(|(t, j)| (t.as_str(), j.as_str()))
                .unwrap_or_default();
            let _ = write!(
                message,
                "{}: out of memory while reading it: {bytes} bytes ({:.1} GiB) could not be \
                 allocated at once (a damaged file can ask for more than any machine has)",
                if json { escaped } else { text },
                gib(bytes)
            );
        }
        _ => {
            let _ = write!(
                message,
                "out of memory: {bytes} bytes ({:.1} GiB) could not be allocated at once; retry \
                 with fewer --threads or --frames-in-flight, or on a machine with more memory",
                gib(bytes)
            );
        }
    }
    let text = &message.buf[..message.len];
    let mut line = StackLine {
        buf: [0; 4096],
        len: 0,
    };
    // A cut line may end inside a character: keep what is whole.
    let text = match std::str::from_utf8(text) {
        Ok(t) => t,
        Err(e) => std::str::from_utf8(&text[..e.valid_up_to()]).unwrap_or("out of memory"),
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
    let mut fail = StackLine {
        buf: [0; 4096],
        len: 0,
    };
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
