//! The demo at 640x480: per-frame update, trace, shade and write times and rays per
//! second, over frames spread across the museum's 300 (every 10th by default; `-- all`
//! renders all 300, `-- quick` every 50th). Frames go to a temporary folder, through the
//! same `render_sequence` as `subfield demo` (the static part opened from a baked file).
//! `cargo bench --bench demo`.

use std::time::Instant;

use subfield::format::{write_psf, WriteOptions};
use subfield::gen::museum::{write_museum, MuseumParams};
use subfield::import;
use subfield::render::{render_sequence, RenderOptions, Shard};
use subfield::scene::ClipSelection;
use subfield::{Psf, PsfParams};

fn stats(v: &[f64]) -> (f64, f64, f64) {
    let n = v.len().max(1) as f64;
    let mean = v.iter().sum::<f64>() / n;
    let max = v.iter().copied().fold(0.0, f64::max);
    let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    (mean, max, sd)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let step = if args.iter().any(|a| a == "all") {
        1
    } else if args.iter().any(|a| a == "quick") {
        50
    } else {
        10
    };
    let dir = std::env::temp_dir().join(format!("subfield-bench-demo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary folder");
    let params = MuseumParams::default();
    let glb = dir.join("museum.glb");
    write_museum(&params, &glb).expect("museum");
    let scene = import::load(&glb).expect("load museum");
    let statics = scene.static_triangles(&scene.split(ClipSelection::All));
    let t = Instant::now();
    let psf = Psf::build(&statics.positions, &PsfParams::for_triangles(statics.len())).unwrap();
    let bake_ms = t.elapsed().as_secs_f64() * 1e3;
    let psf_path = dir.join("museum.psf");
    write_psf(&psf_path, &psf, &WriteOptions::default()).expect("write psf");
    let opts = RenderOptions {
        output: dir.join("frame.####.exr"),
        baked: Some(psf_path),
        shard: Some(Shard {
            index: 0,
            count: step,
        }),
        ..RenderOptions::default()
    };
    let t = Instant::now();
    // On a pool thread, as `subfield demo` and `subfield render` run.
    // Per-frame figures from the frame events (a summary keeps only their sums).
    let mut per_frame = Vec::new();
    rayon::scope(|_| {
        render_sequence(&scene, &opts, &mut |e| {
            if let subfield::render::RenderEvent::Frame(r) = e {
                per_frame.extend(r.stats);
            }
        })
    })
    .expect("render");
    let wall = t.elapsed().as_secs_f64();
    let f = &per_frame;
    let col =
        |g: fn(&subfield::render::FrameStats) -> f64| stats(&f.iter().map(g).collect::<Vec<_>>());
    println!(
        "# cargo bench --bench demo: museum ({} static + {} moving triangles), 640x480, 1 spp, max depth 4, {} frames (every {step}th of {}), {} threads",
        statics.len(),
        params.dynamic_tris,
        f.len(),
        params.frames,
        rayon::current_num_threads()
    );
    println!("static part baked in {bake_ms:.0} ms (then opened from the .psf)\n");
    println!("| per frame | mean ms | max ms | std dev ms |");
    println!("|---|---|---|---|");
    for (name, g) in [
        (
            "update",
            (|s| s.update_ms) as fn(&subfield::render::FrameStats) -> f64,
        ),
        ("trace", |s| s.trace_ms),
        ("shade", |s| s.shade_ms),
        ("write (writer thread, overlapped)", |s| s.write_ms),
        ("frame (update + trace + shade)", |s| {
            s.update_ms + s.trace_ms + s.shade_ms
        }),
    ] {
        let (m, x, sd) = col(g);
        println!("| {name} | {m:.1} | {x:.1} | {sd:.1} |");
    }
    let rays: u64 = f.iter().map(|s| s.rays.total()).sum();
    let trace_s: f64 = f.iter().map(|s| s.trace_ms).sum::<f64>() / 1e3;
    let (pr, sh, se) = f.iter().fold((0, 0, 0), |a, s| {
        (
            a.0 + s.rays.primary,
            a.1 + s.rays.shadow,
            a.2 + s.rays.secondary,
        )
    });
    let n = f.len().max(1) as u64;
    println!(
        "\nrays per frame: {} primary, {} shadow, {} secondary; {:.2} Mrays/s while tracing",
        pr / n,
        sh / n,
        se / n,
        rays as f64 / trace_s.max(1e-9) / 1e6
    );
    println!(
        "wall {:.1} s for {} frames: {:.2} s a frame, 300 frames in about {:.0} s (goal: under 60 s)",
        wall,
        f.len(),
        wall / f.len().max(1) as f64,
        wall / f.len().max(1) as f64 * 300.0
    );
    let _ = std::fs::remove_dir_all(&dir);
}
