//! The dynamic layer against per-frame BVH rebuilds, same triangles, same rays, one run.
//!
//! * update: `DynamicLayer::update` for 1k, 16k and 100k triangles in unstructured motion
//!   against an obvhs CWBVH rebuilt from scratch (its fastest and its medium build).
//! * frame: a 10k-triangle static room plus the moving triangles; update, then primary
//!   rays (320x240), one shadow ray per hit to a point light and one mirror reflection
//!   ray per hit. subfield (static PSF baked once + dynamic layer) against the two-level
//!   baseline (static CWBVH built once + dynamic CWBVH rebuilt each frame, both queried).
//!   The secondary rays come from subfield's primary hits, and both sides trace those
//!   same rays.
//! * memory: 1,000 frames of 16k moving triangles; the layer's bytes and the process's
//!   peak resident memory along the way.
//!
//! `cargo bench --bench dynamic` (all), or `-- update`, `-- frame`, `-- memory`;
//! `-- quick` takes fewer frames. Times are medians over the frames; both sides use the
//! same rayon pool (all cores).

#[path = "common.rs"]
mod common;

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;
use subfield::{DynamicLayer, Hit, Intersector, Psf, PsfParams, Ray};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kib| kib / 1024.0)
}

fn update(frames: usize, dyn_params: &[PsfParams]) {
    println!("\n## update: ms per frame (median of {frames}), unstructured motion");
    print!("| moving triangles | subfield (for_triangles) |");
    for p in dyn_params {
        print!(" subfield L{} T{} |", p.level, p.tiles);
    }
    println!(" obvhs rebuild (fastest) | obvhs rebuild (medium) | ratio |");
    println!("|---|---|{}---|---|---|", "---|".repeat(dyn_params.len()));
    for n in [1_000usize, 16_384, 100_000] {
        let mut tris = Vec::new();
        let mut ours = Vec::new();
        let layers = std::iter::once(DynamicLayer::for_triangles(n)).chain(
            dyn_params
                .iter()
                .map(|p| DynamicLayer::with_params(*p).unwrap()),
        );
        for mut layer in layers {
            let mut times = Vec::new();
            for f in 0..frames + 2 {
                common::moving(n, f as f32 / 30.0, &mut tris);
                let t = Instant::now();
                layer.update(&tris).unwrap();
                if f >= 2 {
                    times.push(ms(t));
                }
            }
            ours.push(median(times));
        }
        let mut peer = Vec::new();
        for params in [
            obvhs::BvhBuildParams::fastest_build(),
            obvhs::BvhBuildParams::medium_build(),
        ] {
            let mut times = Vec::new();
            for f in 0..frames + 2 {
                common::moving(n, f as f32 / 30.0, &mut tris);
                let t = Instant::now();
                let b = common::Obvhs::build_with(&tris, params);
                std::hint::black_box(&b);
                if f >= 2 {
                    times.push(ms(t));
                }
            }
            peer.push(median(times));
        }
        print!("| {n} |");
        for o in &ours {
            print!(" {o:.2} |");
        }
        println!(
            " {:.2} | {:.2} | {:.2}x |",
            peer[0],
            peer[1],
            peer[0] / ours[0]
        );
    }
    let auto = |n: usize| {
        let l = DynamicLayer::for_triangles(n);
        format!("{} tiles, {} grids", l.params().tiles, l.grids())
    };
    println!(
        "(ratio: obvhs fastest rebuild time / subfield update time with the parameters the renderer uses, DynamicLayer::for_triangles(n): level {}, {} at 1k, {} at 16k, {} at 100k; > 1 means subfield is faster)",
        DynamicLayer::for_triangles(1_000).params().level,
        auto(1_000),
        auto(16_384),
        auto(100_000)
    );
}

/// Per-frame figures of one side.
#[derive(Default)]
struct FrameTimes {
    update: Vec<f64>,
    primary: Vec<f64>,
    shadow: Vec<f64>,
    reflect: Vec<f64>,
    total: Vec<f64>,
}

impl FrameTimes {
    fn push(&mut self, u: f64, p: f64, s: f64, r: f64) {
        self.update.push(u);
        self.primary.push(p);
        self.shadow.push(s);
        self.reflect.push(r);
        self.total.push(u + p + s + r);
    }
}

fn secondary(
    rays: &[Ray],
    hits: &[Option<Hit>],
    tris: &[[Vec3; 3]],
    light: Vec3,
) -> (Vec<Ray>, Vec<Ray>) {
    let mut shadow = Vec::new();
    let mut reflect = Vec::new();
    for (r, h) in rays.iter().zip(hits) {
        let Some(h) = h else { continue };
        let t = tris[h.tri as usize];
        let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or(Vec3::Y);
        let n = if n.dot(r.dir) > 0.0 { -n } else { n };
        let p = r.at(h.t) + n * 1e-4;
        shadow.push(Ray::segment(p, light - p, 0.0, 1.0));
        let d = r.dir - 2.0 * r.dir.dot(n) * n;
        reflect.push(Ray::new(p, d));
    }
    (shadow, reflect)
}

fn frame(frames: usize, dyn_params: Option<PsfParams>) {
    let stat = common::room(10_000);
    let light = Vec3::new(0.0, 5.5, 0.0);
    let primary = common::camera_rays(320, 240);
    println!(
        "\n## frame: {} static triangles + moving (dynamic layer: {}); ms per frame (median of {frames}); 320x240 primary + shadow + reflection",
        stat.len(),
        dyn_params.map_or("for_triangles(n), as the renderer".to_string(), |p| format!("L{} T{}", p.level, p.tiles))
    );
    println!("| moving | side | update | primary | shadow | reflection | frame | rays | Mrays/s (trace) |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let psf = Psf::build(&stat, &PsfParams::for_triangles(stat.len())).unwrap();
    let st_bvh = common::Obvhs::build(&stat);
    let nstat = stat.len() as u32;
    for n in [1_000usize, 16_384, 100_000] {
        let mut layer = match dyn_params {
            Some(p) => DynamicLayer::with_params(p).unwrap(),
            None => DynamicLayer::for_triangles(n),
        };
        let (mut ours, mut peer) = (FrameTimes::default(), FrameTimes::default());
        let mut tris = Vec::new();
        let mut nrays = 0usize;
        for f in 0..frames + 1 {
            common::moving(n, f as f32 / 30.0, &mut tris);
            // subfield
            let t = Instant::now();
            layer.update(&tris).unwrap();
            let u = ms(t);
            let both = psf.with_dynamic(&layer);
            let mut hits = vec![None; primary.len()];
            let t = Instant::now();
            both.intersect_batch(&primary, &mut hits);
            let p = ms(t);
            let all: Vec<[Vec3; 3]> = stat.iter().chain(&tris).copied().collect();
            let (sh, re) = secondary(&primary, &hits, &all, light);
            let mut occ = vec![false; sh.len()];
            let t = Instant::now();
            both.occluded_batch(&sh, &mut occ);
            let s = ms(t);
            let mut rh = vec![None; re.len()];
            let t = Instant::now();
            both.intersect_batch(&re, &mut rh);
            let r = ms(t);
            nrays = primary.len() + sh.len() + re.len();
            // two-level BVH: static built once, dynamic rebuilt
            let t = Instant::now();
            let dy_bvh = common::Obvhs::build_with(&tris, obvhs::BvhBuildParams::fastest_build());
            let pu = ms(t);
            let closest = |ray: &Ray| {
                let a = st_bvh.intersect(ray);
                let mut r2 = *ray;
                if let Some((t, _)) = a {
                    r2.t_max = t;
                }
                match (a, dy_bvh.intersect(&r2)) {
                    (_, Some((t, i))) => Some((t, i + nstat)),
                    (a, None) => a,
                }
            };
            let trace = |rays: &[Ray]| {
                let mut out = vec![None; rays.len()];
                rays.par_iter()
                    .zip(out.par_iter_mut())
                    .with_min_len(64)
                    .for_each(|(r, o)| *o = closest(r));
                out
            };
            let t = Instant::now();
            std::hint::black_box(trace(&primary));
            let pp = ms(t);
            let t = Instant::now();
            let mut pocc = vec![false; sh.len()];
            sh.par_iter()
                .zip(pocc.par_iter_mut())
                .with_min_len(64)
                .for_each(|(r, o)| *o = st_bvh.occluded(r) || dy_bvh.occluded(r));
            let ps = ms(t);
            let t = Instant::now();
            std::hint::black_box(trace(&re));
            let pr = ms(t);
            if f >= 1 {
                ours.push(u, p, s, r);
                peer.push(pu, pp, ps, pr);
            }
        }
        let mut rows = Vec::new();
        for (name, ft) in [("subfield", &ours), ("two-level obvhs", &peer)] {
            let tr =
                median(ft.primary.clone()) + median(ft.shadow.clone()) + median(ft.reflect.clone());
            println!(
                "| {n} | {name} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {nrays} | {:.2} |",
                median(ft.update.clone()),
                median(ft.primary.clone()),
                median(ft.shadow.clone()),
                median(ft.reflect.clone()),
                median(ft.total.clone()),
                nrays as f64 / tr / 1e3
            );
            rows.push(median(ft.total.clone()));
        }
        println!(
            "| {n} | ratio (obvhs / subfield frame) | | | | | {:.2}x | | |",
            rows[1] / rows[0]
        );
    }
}

/// `layer`: a fresh layer for 16,384 moving triangles.
fn memory(frames: usize, mut layer: DynamicLayer) {
    println!("\n## memory: {frames} frames of 16,384 moving triangles");
    println!("| frame | layer bytes (MiB) | entries | max list | peak RSS (MiB) |");
    println!("|---|---|---|---|---|");
    let mut tris = Vec::new();
    let start = Instant::now();
    for f in 1..=frames {
        common::moving(16_384, f as f32 / 30.0, &mut tris);
        layer.update(&tris).unwrap();
        if [1, 10, 100, 1000, frames].contains(&f) && (f <= frames) {
            let s = layer.stats();
            println!(
                "| {f} | {:.2} | {} | {} | {:.1} |",
                s.bytes as f64 / (1 << 20) as f64,
                s.entries,
                s.max_list,
                peak_rss_mib()
            );
        }
    }
    println!(
        "({frames} updates in {:.1} s)",
        start.elapsed().as_secs_f64()
    );
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let quick = args.iter().any(|a| a == "quick");
    let want = |k: &str| {
        args.iter().all(|a| a == "quick" || a.starts_with('-')) || args.iter().any(|a| a == k)
    };
    let frames = if quick { 5 } else { 20 };
    let default = PsfParams::default();
    println!(
        "# cargo bench --bench dynamic ({} threads)",
        rayon::current_num_threads()
    );
    if want("update") {
        update(
            frames,
            &[
                default,
                PsfParams {
                    level: 1,
                    tiles: 256,
                },
                PsfParams {
                    level: 1,
                    tiles: 64,
                },
            ],
        );
    }
    if want("frame") {
        for p in [
            None,
            Some(PsfParams {
                level: 1,
                tiles: 64,
            }),
        ] {
            frame(frames, p);
        }
    }
    if want("memory") {
        memory(
            if quick { 100 } else { 1000 },
            DynamicLayer::for_triangles(16_384),
        );
    }
}
