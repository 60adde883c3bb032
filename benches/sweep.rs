//! Parameter sweep: bake time, memory and single-thread trace speed of the PSF for each
//! level and tile count, on the 100k-triangle room, beside obvhs on the same rays.
//! `cargo bench --bench sweep` (plain timing, prints a table).

#[path = "common.rs"]
mod common;

use std::time::Instant;

use subfield::{Intersector, Psf, PsfParams};

fn main() {
    let n: usize = std::env::var("SWEEP_TRIS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(100_000);
    let tris = common::room(n);
    let cam = common::camera_rays(320, 240);
    let rnd = common::random_rays(100_000);
    let time = |f: &dyn Fn()| {
        let t = Instant::now();
        f();
        t.elapsed().as_secs_f64()
    };
    let ob = common::Obvhs::build(&tris);
    let ob_cam = time(&|| {
        cam.iter().for_each(|r| {
            std::hint::black_box(ob.intersect(r));
        })
    });
    let ob_rnd = time(&|| {
        rnd.iter().for_each(|r| {
            std::hint::black_box(ob.intersect(r));
        })
    });
    println!(
        "{n} triangles, one thread. obvhs: camera {:.2} Mrays/s, random {:.2} Mrays/s",
        cam.len() as f64 / ob_cam / 1e6,
        rnd.len() as f64 / ob_rnd / 1e6
    );
    println!("level tiles subfields  bake_s    MiB  cam_Mrays/s (x obvhs)  rnd_Mrays/s (x obvhs)  tiles/ray cand/ray (random) (camera)");
    let levels: Vec<u32> = std::env::var("SWEEP_LEVELS")
        .ok()
        .map(|s| s.split(',').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or(vec![1, 2, 3]);
    for level in levels {
        for tiles in [32u32, 64, 128, 256] {
            let t = Instant::now();
            let psf = Psf::build(&tris, &PsfParams { level, tiles }).unwrap();
            let bake = t.elapsed().as_secs_f64();
            let st = psf.stats();
            let c = time(&|| {
                cam.iter().for_each(|r| {
                    std::hint::black_box(psf.intersect(r));
                })
            });
            let r = time(&|| {
                rnd.iter().for_each(|r| {
                    std::hint::black_box(psf.intersect(r));
                })
            });
            let mut rs = subfield::psf::RayStats::default();
            for ray in &rnd[..10_000] {
                psf.intersect_counted(ray, &mut rs);
            }
            let mut cs = subfield::psf::RayStats::default();
            for ray in cam.iter().step_by(7) {
                psf.intersect_counted(ray, &mut cs);
            }
            println!(
                "{level:5} {tiles:5} {:9} {bake:7.2} {:6.0} {:11.2} ({:4.2}) {:14.2} ({:4.2}) {:13.1} {:9.1} {:6.1} {:6.1}",
                st.subfields,
                st.bytes as f64 / (1 << 20) as f64,
                cam.len() as f64 / c / 1e6,
                ob_cam / c,
                rnd.len() as f64 / r / 1e6,
                ob_rnd / r,
                rs.tiles_per_ray(),
                rs.candidates_per_ray(),
                cs.tiles_per_ray(),
                cs.candidates_per_ray()
            );
            println!(
                "      scanned/ray: random {:.1}, camera {:.1}",
                rs.entries_scanned as f64 / rs.rays as f64,
                cs.entries_scanned as f64 / cs.rays as f64
            );
        }
    }
}
