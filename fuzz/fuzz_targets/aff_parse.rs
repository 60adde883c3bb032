//! The AFF / NFF parser against arbitrary text, through its public entry
//! `AffScene::parse_str` (includes and textures resolve against an empty folder). The
//! claim: it returns an error naming the input, or a scene whose triangle counts and
//! rest-time triangles evaluate without panicking.
#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use subfield::import::aff::AffScene;

fn folder() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = std::env::temp_dir().join(format!("subfield-fuzz-aff-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&d);
        d
    })
}

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let name = Path::new("fuzz-input.aff");
    match AffScene::parse_str(&text, name, folder()) {
        Ok(aff) => {
            let n = aff.triangle_count();
            let _ = aff.animated_triangle_count();
            // Bounded work per input: the parser's claim is what is fuzzed, not the
            // evaluation of a huge scene.
            if n < 100_000 {
                let _ = aff.triangles_at(aff.rest_time());
            }
        }
        Err(e) => {
            let m = e.to_string();
            assert!(m.contains("fuzz-input.aff"), "error without the file: {m}");
        }
    }
});
