//! How well `bake --quality high`'s cost (`subfield::psf::tune::cost`) follows trace
//! time: bakes each scene given with a spread of parameters, traces the scene's tuning
//! sample through each on one thread (best of three runs), and prints the three counts
//! the traversal keeps (tiles visited, candidates tested, entries scanned), the cost and
//! the time, and the least-squares nanoseconds per cost unit with the rows' spread
//! around it.
//!
//!     cargo run --release --example tune_weights -- SCENE...
//!
//! Timing is noisy on a shared machine; the weights in `tune.rs` were estimated by hand
//! from these rows (see there).

use std::time::Instant;

use subfield::geometry::Intersector;
use subfield::psf::{tune, BspParams, SampleRays};
use subfield::scene::ClipSelection;
use subfield::{Psf, PsfParams};

fn time_trace(psf: &Psf, rays: &SampleRays) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let t = Instant::now();
        let mut n = 0usize;
        for r in &rays.closest {
            n += psf.intersect(r).is_some() as usize;
        }
        for r in &rays.any {
            n += psf.occluded(r) as usize;
        }
        std::hint::black_box(n);
        best = best.min(t.elapsed().as_secs_f64());
    }
    best
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let scenes: Vec<String> = std::env::args().skip(1).collect();
    if scenes.is_empty() {
        return Err("usage: tune_weights SCENE...".into());
    }
    // (cost, nanoseconds) per bake.
    let mut rows: Vec<(f64, f64)> = Vec::new();
    for path in &scenes {
        let scene = subfield::import::load(path.as_ref())?;
        let split = scene.split(ClipSelection::All);
        let soup = scene.static_triangles(&split);
        let tris = &soup.positions;
        let auto = PsfParams::for_triangles(tris.len());
        let rays = subfield::render::tuning_rays(&scene, &Psf::build(tris, &auto)?);
        println!(
            "{path}: {} triangles, {} sample rays",
            tris.len(),
            rays.len()
        );
        let mut configs = Vec::new();
        for level in 0..=4 {
            for tiles in [4, 16, 64, 256] {
                configs.push((PsfParams { level, tiles }, BspParams::default()));
            }
        }
        for (leaf, flat_max) in [(1, 0), (8, 0), (1, 32), (8, 32), (3, 8)] {
            configs.push((auto, BspParams { leaf, flat_max }));
        }
        for (params, bsp) in configs {
            let psf = Psf::build_with_layout(tris, &params, &bsp, &|_, _| {})?;
            if psf.raw_bytes() > 512 << 20 {
                continue;
            }
            let s = tune::measure(&psf, &rays);
            let secs = time_trace(&psf, &rays);
            let c = tune::cost(&s);
            println!(
                "  level {} tiles {:>3} leaf {} flat {:>2}: {:>11} tiles {:>11} candidates {:>11} scanned, cost {:>12} {:>8.2} ms",
                params.level,
                params.tiles,
                bsp.leaf,
                bsp.flat_max,
                s.tiles_visited,
                s.candidates_tested,
                s.entries_scanned,
                c,
                secs * 1e3
            );
            rows.push((c as f64, secs * 1e9));
        }
    }
    // time = k · cost, least squares; and each row's time over k · cost.
    let k = rows.iter().map(|(c, t)| c * t).sum::<f64>()
        / rows.iter().map(|(c, _)| c * c).sum::<f64>().max(1.0);
    let ratios: Vec<f64> = rows.iter().map(|(c, t)| t / (k * c).max(1.0)).collect();
    let lo = ratios.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = ratios.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    println!(
        "over {} bakes: {k:.3} ns a cost unit; time / (that × cost) from {lo:.2} to {hi:.2}",
        rows.len()
    );
    Ok(())
}
