//! The USD reader against arbitrary bytes, through `import::load` (the `openusd` crate's
//! text and binary readers and composition, then ours): the input is written to a file
//! named `.usdc` when it starts with the crate file magic `PXR-USDC`, else `.usda`. The
//! claim: an error naming the file, or a scene whose moving triangles pose at a few
//! times (any time, not only samples) without panicking.
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

fuzz_target!(|data: &[u8]| {
    let ext = if data.starts_with(b"PXR-USDC") { "usdc" } else { "usda" };
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
