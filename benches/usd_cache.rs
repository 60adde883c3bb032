//! Import and per-frame posing of USD simulation caches (issue 39): a shattering cache
//! (every triangle on its own path, time-sampled `points`) written as `.usda` text, read
//! by `import::load` (openusd's parser and composition, then ours), then posed at every
//! frame by `Scene::dynamic_triangles_at` (the call the renderer makes each frame).
//!
//! `cargo bench --bench usd_cache` runs both cases: 48 frames of 10k triangles (30k
//! points), and 1M points (333k triangles) over 3 frames. `-- shatter` or `-- million`
//! runs one; `-- quick` makes them 10x smaller. Times are wall clock, one run of the
//! import, the median of the frames' posing.
//!
//! Beside it, in the same run and on the same file, Pixar's usd-core (`pip install
//! usd-core`, skipped with a line when `python3` cannot import `pxr`) does the same
//! work: `Usd.Stage.Open`, then at each frame the mesh's `points` and its
//! local-to-world transform applied to them (`benches/usd_core_peer.py`).

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

use subfield::import;
use subfield::scene::{ClipSelection, TriangleSoup};

/// A `.usda` shattering cache: `tris` triangles, each moving on its own straight path
/// and turning, sampled at frames 1..=frames.
fn write_cache(path: &Path, tris: usize, frames: u32) {
    let mut s = String::with_capacity(tris * 3 * 40 * frames as usize + 1024);
    let _ = write!(
        s,
        "#usda 1.0\n(\n    startTimeCode = 1\n    endTimeCode = {frames}\n    timeCodesPerSecond = 24\n    metersPerUnit = 1\n    upAxis = \"Y\"\n)\n\ndef Mesh \"Debris\"\n{{\n    int[] faceVertexCounts = ["
    );
    for i in 0..tris {
        s.push_str(if i == 0 { "3" } else { ", 3" });
    }
    s.push_str("]\n    int[] faceVertexIndices = [");
    for i in 0..tris * 3 {
        if i > 0 {
            s.push_str(", ");
        }
        let _ = write!(s, "{i}");
    }
    s.push_str("]\n    point3f[] points.timeSamples = {\n");
    // A small deterministic hash for each triangle's path.
    let h = |i: usize, k: u64| -> f32 {
        let mut x =
            (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ k.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        x ^= x >> 29;
        x = x.wrapping_mul(0x94D0_49BB_1331_11EB);
        ((x >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    };
    let side = (tris as f32).sqrt().ceil() as usize;
    for f in 1..=frames {
        let t = (f - 1) as f32;
        let _ = write!(s, "        {f}: [");
        for i in 0..tris {
            let (cx, cy) = ((i % side) as f32, (i / side) as f32);
            let (dx, dy, dz) = (h(i, 1), h(i, 2), h(i, 3));
            let a = h(i, 4) * 0.3 * t;
            let (sin, cos) = a.sin_cos();
            for (k, (ox, oy)) in [(-0.4f32, -0.4f32), (0.4, -0.4), (0.0, 0.4)]
                .into_iter()
                .enumerate()
            {
                let x = cx + dx * 0.5 * t + ox * cos - oy * sin;
                let y = cy + dy * 0.5 * t + ox * sin + oy * cos;
                let z = dz * 0.5 * t;
                let sep = if i == 0 && k == 0 { "" } else { ", " };
                let _ = write!(s, "{sep}({x:.4}, {y:.4}, {z:.4})");
            }
        }
        s.push_str("],\n");
    }
    s.push_str("    }\n}\n");
    std::fs::write(path, s).unwrap();
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn case(name: &str, tris: usize, frames: u32) {
    let dir = std::env::temp_dir().join(format!("subfield-bench-usd-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("{name}.usda"));
    write_cache(&path, tris, frames);
    let bytes = std::fs::metadata(&path).unwrap().len();
    let clock = Instant::now();
    let scene = import::load(&path).unwrap();
    let import_s = clock.elapsed().as_secs_f64();
    let split = scene.split(ClipSelection::All);
    let fps = scene.fps.unwrap_or(24.0);
    let mut soup = TriangleSoup::new();
    let mut pose = Vec::new();
    for f in 1..=frames {
        let clock = Instant::now();
        scene.dynamic_triangles_at(&split, f as f32 / fps, &mut soup);
        pose.push(clock.elapsed().as_secs_f64() * 1e3);
        assert_eq!(soup.len(), tris);
    }
    // A sub-frame time (motion blur's): interpolated, not held.
    let clock = Instant::now();
    scene.dynamic_triangles_at(&split, 1.5 / fps, &mut soup);
    let sub = clock.elapsed().as_secs_f64() * 1e3;
    let pose = median(pose);
    println!(
        "{name}: {tris} triangles ({} points) x {frames} frames, {:.1} MB of usda: import {import_s:.2} s; posing a frame {pose:.2} ms (median), a sub-frame time {sub:.2} ms",
        tris * 3,
        bytes as f64 / 1e6,
    );
    peer(name, &path, frames, import_s, pose);
    let _ = std::fs::remove_dir_all(&dir);
}

/// usd-core on the same file: its open and its median frame, and ours over its.
fn peer(name: &str, path: &Path, frames: u32, import_s: f64, pose_ms: f64) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/usd_core_peer.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(path)
        .arg(frames.to_string())
        .output();
    let Some(out) = out.ok().filter(|o| o.status.success()) else {
        println!("{name}: usd-core: not run (python3 with pxr: pip install usd-core)");
        return;
    };
    let text = String::from_utf8_lossy(&out.stdout);
    let mut nums = text
        .split_whitespace()
        .filter_map(|w| w.parse::<f64>().ok());
    let (Some(open_s), Some(frame_ms)) = (nums.next(), nums.next()) else {
        println!("{name}: usd-core: no figures in {text:?}");
        return;
    };
    println!(
        "{name}: usd-core {open_s:.2} s to open, {frame_ms:.2} ms a frame (median); subfield / usd-core: import {:.2}, posing {:.2}",
        import_s / open_s,
        pose_ms / frame_ms,
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let quick = args.iter().any(|a| a == "quick");
    let only = |n: &str| {
        !args.iter().any(|a| a == "shatter" || a == "million") || args.iter().any(|a| a == n)
    };
    let scale = if quick { 10 } else { 1 };
    if only("shatter") {
        case("shatter", 10_000 / scale, 48);
    }
    if only("million") {
        case("million", 333_334 / scale, 3);
    }
}
