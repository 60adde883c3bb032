//! The glTF importer against arbitrary bytes: glTF JSON or GLB through
//! `import::from_gltf_slice`, with external URIs resolving against an empty folder. The
//! claim: it returns an error naming the input, or a scene whose split, static and
//! dynamic triangles, camera and lights evaluate without panicking.
#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use subfield::import;
use subfield::scene::{ClipSelection, TriangleSoup};

/// An empty folder for external URIs (so none resolves to a real file).
fn folder() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = std::env::temp_dir().join(format!("subfield-fuzz-gltf-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&d);
        d
    })
}

fuzz_target!(|data: &[u8]| {
    let name = Path::new("fuzz-input.gltf");
    match import::from_gltf_slice(data, name, folder()) {
        Ok(scene) => {
            let split = scene.split(ClipSelection::All);
            let _ = scene.static_triangles(&split);
            let mut soup = TriangleSoup::new();
            for t in [0.0, 0.5, 7.0] {
                scene.dynamic_triangles_at(&split, t, &mut soup);
            }
            let _ = scene.camera_at(ClipSelection::All, 0.5, None);
            let _ = scene.lights_at(ClipSelection::All, 0.5);
        }
        Err(e) => {
            let m = e.to_string();
            assert!(m.contains("fuzz-input.gltf"), "error without the file: {m}");
        }
    }
});
