//! The USD reader against arbitrary bytes, through `import::load` (the `openusd` crate's
//! text and binary readers and composition, then ours): the input is written to a file
//! named `.usdc` when it starts with the crate file magic `PXR-USDC`, else `.usda`. The
//! claim: an error naming the file, or a scene whose moving triangles pose at a few
//! times (any time, not only samples) without panicking.
//!
//! The `openusd` crate (0.6) panics on some damaged data; `import::load` contains those
//! panics and returns an error naming the file, so this target lets a panic raised in
//! that crate's code unwind to it and aborts (a finding) on any other. An allocation
//! larger than any machine has (a corrupt array length) is the command's to report
//! (`cli::oom`: one line, exit 5); run with `-fork=1 -ignore_ooms=1 -malloc_limit_mb=2048`
//! to go on past those inputs.
#![no_main]

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

/// libFuzzer's hook aborts on every panic; this one lets the USD reader's unwind to
/// `import::load`, which turns them into errors.
fn contain_usd_reader_panics() {
    static HOOK: OnceLock<()> = OnceLock::new();
    HOOK.get_or_init(|| {
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
