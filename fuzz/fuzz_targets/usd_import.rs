//! The USD reader against arbitrary bytes, through `import::load` (the `openusd` crate's
//! text and binary readers and composition, then ours): the input is written to a file
//! named `.usdc` when it starts with the crate file magic `PXR-USDC`, else `.usda`. The
//! claim: an error naming the file, or a scene whose moving triangles pose at a few
//! times (any time, not only samples) without panicking.
//!
//! The `openusd` crate (0.6) panics on some damaged data; `import::load` contains those
//! panics and returns an error naming the file, so this target lets a panic raised in
//! that crate's code unwind to it and aborts (a finding) on any other.
//!
//! A corrupt array length makes that crate allocate what it says. The command refuses
//! an allocation beyond `import::usd_allocation_cap` while a stage is read (`cli::oom`:
//! one line naming the file, exit 3); this target keeps the same bound ([`Bounded`]) and
//! turns the refusal into a panic in the reader's code, which `import::load` contains
//! like the others: an error naming the file, and the fuzzer goes on. (Without it, a
//! length beyond AddressSanitizer's largest allocation, 1 TiB, stopped every run within
//! seconds, whatever libFuzzer's `-malloc_limit_mb` said.) An allocation beyond the
//! bound outside the reader's code still aborts: a finding. Run it as
//! `cargo +nightly fuzz run usd_import -- -max_total_time=900 -rss_limit_mb=4096`.
#![no_main]
#![feature(alloc_error_hook)]

use std::alloc::{GlobalAlloc, Layout, System};

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use subfield::import;
use subfield::scene::{ClipSelection, TriangleSoup};

fn folder() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = std::env::temp_dir().join(format!("subfield-fuzz-usd-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&d);
        d
    })
}

/// The system's allocator, refusing (a null pointer) an allocation beyond the command's
/// bound on the thread that reads a stage, where `cli::oom` ends the command with one
/// line.
struct Bounded;

fn beyond(size: usize) -> bool {
    import::usd_allocation_cap().is_some_and(|cap| size as u64 > cap)
}

// SAFETY: every call goes to `System` with the caller's own arguments, so `System`'s
// guarantees hold for what it returns; the only other answer is a null pointer from
// `alloc`, `alloc_zeroed` or `realloc`, which `GlobalAlloc` allows for any layout (an
// allocation that failed; `realloc` then leaves the old block as it was, untouched
// here). `beyond` allocates nothing and does not panic (`usd_allocation_cap` reads a
// constant-initialised thread local).
unsafe impl GlobalAlloc for Bounded {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if beyond(layout.size()) {
            return std::ptr::null_mut();
        }
        // SAFETY: the caller's layout, as `GlobalAlloc::alloc` requires of it.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if beyond(layout.size()) {
            return std::ptr::null_mut();
        }
        // SAFETY: as in `alloc`.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System` (this allocator hands out nothing else) with
        // `layout`, as the caller guarantees.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if beyond(new_size) {
            return std::ptr::null_mut();
        }
        // SAFETY: as in `dealloc`, with the caller's `new_size`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Bounded = Bounded;

/// libFuzzer's hook aborts on every panic; this one lets the USD reader's unwind to
/// `import::load`, which turns them into errors.
fn contain_usd_reader_panics() {
    static HOOK: OnceLock<()> = OnceLock::new();
    HOOK.get_or_init(|| {
        // An allocation [`Bounded`] refuses panics where it was asked for.
        std::alloc::set_alloc_error_hook(|layout| {
            panic!(
                "an allocation of {} bytes, beyond what the layers read so far can hold",
                layout.size()
            )
        });
        std::panic::set_hook(Box::new(|info| {
            // The innermost frame's source outside the standard library and this hook
            // (a capacity overflow's location is in `alloc`, its cause in the caller).
            let trace = std::backtrace::Backtrace::force_capture().to_string();
            let innermost = trace
                .lines()
                .filter_map(|l| l.trim().strip_prefix("at "))
                .find(|f| !f.starts_with("/rustc/") && !f.contains("fuzz_targets/usd_import.rs"))
                .map(str::to_string);
            let in_reader = innermost
                .as_deref()
                .is_some_and(|f| f.contains("/openusd-"));
            if !in_reader {
                eprintln!("{info} (innermost frame outside std: {innermost:?})");
                std::process::abort();
            }
        }));
    });
}

fuzz_target!(|data: &[u8]| {
    contain_usd_reader_panics();
    let ext = if data.starts_with(b"PXR-USDC") {
        "usdc"
    } else {
        "usda"
    };
    let path = folder().join(format!("fuzz-input.{ext}"));
    if std::fs::write(&path, data).is_err() {
        return;
    }
    match import::load(&path) {
        Ok(scene) => {
            let split = scene.split(ClipSelection::All);
            // Bounded work per input: the reader is what is fuzzed.
            if split.summary().dynamic_triangles < 100_000 {
                let mut soup = TriangleSoup::new();
                for t in [-1.0, 0.0, 0.37, 1.0, 1e6] {
                    scene.dynamic_triangles_at(&split, t, &mut soup);
                    scene.dynamic_triangles_carried(&split, t + 0.04, t, &mut soup);
                }
            }
        }
        Err(e) => {
            let m = e.to_string();
            assert!(m.contains("fuzz-input.usd"), "error without the file: {m}");
            assert!(!m.contains('\n'), "error of more than one line: {m}");
        }
    }
});
