//! subfield's side of the Embree comparison: the workload of
//! `../shared/peers/embree_anchor.py`, on the same glTF file, in our tracer.
//!
//! `cargo bench --bench embree -- SCENE.glb [--frames A:B[:S] | --frames F1,F2,..]
//! [--width W] [--height H] [--psf LEVEL:TILES] [--dyn LEVEL:TILES[:GRIDS]]` (defaults
//! `0:300:30`, 640x480, as the harness's; `--dyn` without `GRIDS` takes every direction of
//! the level).
//! `benches/embree.sh` runs both sides and prints the table.
//!
//! What it mirrors, point by point (read off the harness's code):
//! * the scene through our importer; the static part (`split(All)`) baked once into a
//!   PSF with `PsfParams::for_triangles` (what `subfield render` does), timed apart as
//!   `static_build_ms`; the dynamic layer sized by `DynamicLayer::for_triangles`;
//! * the frames of the list, plus the first one again in front as an untimed warm-up;
//!   frame `f` shows `t = f / fps`, `fps` the scene's `extras.fps`, else 30 (the
//!   harness's fallback; our renderer's is 24, and the museum always records its fps);
//! * per frame: `eval` = sampling the moving triangles at `t`, `update` = the dynamic
//!   layer's update, then three timed batches through `psf.with_dynamic(&layer)`:
//!   primary rays (one per pixel centre, the first camera, aspect `W/H` as the harness
//!   takes it, unit directions), one shadow segment per hit to the first point light
//!   (origin `P + eps·n`, `n` the unit geometric normal facing the ray, `eps = 1e-4` of
//!   the static part's bounding-box diagonal, segment length `dist·(1 − 1e-4)`), and one
//!   mirror reflection ray per hit from the same origin. Building the secondary rays is
//!   timed as `setup_ms` and, as in the harness, left out of the frame time;
//! * `frame_ms = eval + update + primary + shadow + reflect`; Mrays/s per kind is the sum
//!   of that kind's rays over the sum of its trace time.
//!
//! Output: a `{"setup": ..}` line, one JSON line per frame, and a `{"summary": ..,
//! "config": ..}` line with the harness's keys (`mean_blas_ms`/`mean_tlas_ms` are
//! `null`: there is no BVH here) plus the total rays and hits per kind, so the two
//! sides' workloads can be checked against each other. Threads: rayon's pool
//! (`RAYON_NUM_THREADS`, else all cores); the frames run on one of its threads.
//!
//! The harness poses camera and light from the nodes' rest transforms and animates only
//! morph weights; the museum animates nothing else, so taking them at `t = 0` here is the
//! same camera and light.

use std::path::PathBuf;
use std::process::exit;
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;
use serde_json::{json, Map, Value};
use subfield::import;
use subfield::psf::{Prim, RayStats};
use subfield::render::CameraModel;
use subfield::scene::{ClipSelection, LightKind, TriangleSoup};
use subfield::{DynamicLayer, Hit, Intersector, Psf, PsfParams, Ray};

/// Untimed, on the warm-up frame: the work per ray of each kind in each layer (tiles
/// walked, entries scanned, candidates tested), as a `{"work": ..}` line, which
/// `benches/embree.sh` passes over; for the perf log.
fn work(psf: &Psf, layer: &DynamicLayer, kinds: [&[Ray]; 3]) {
    let mut out = Map::new();
    for (name, rays) in ["primary", "shadow", "reflect"].iter().zip(kinds) {
        let (mut st, mut dy) = (RayStats::default(), RayStats::default());
        for ray in rays {
            let any = *name == "shadow";
            let mut r = *ray;
            if any {
                if psf.occluded_counted(ray, &mut st) {
                    continue;
                }
                layer.occluded_counted(&r, &mut dy);
            } else {
                if let Some(h) = psf.intersect_counted(ray, &mut st) {
                    r.t_max = h.t;
                }
                layer.intersect_counted(&r, &mut dy);
            }
        }
        let per = |s: &RayStats| {
            let n = s.rays.max(1) as f64;
            json!({"rays": s.rays, "tiles": r3(s.tiles_visited as f64 / n),
                   "scanned": r3(s.entries_scanned as f64 / n),
                   "candidates": r3(s.candidates_tested as f64 / n)})
        };
        out.insert(
            name.to_string(),
            json!({"static": per(&st), "dynamic": per(&dy)}),
        );
    }
    println!("{}", json!({ "work": out }));
}

fn fail(msg: &str) -> ! {
    eprintln!("embree bench: {msg}");
    exit(2)
}

struct Args {
    scene: PathBuf,
    frames: Vec<i64>,
    width: u32,
    height: u32,
    /// Overrides of the defaults, for parameter sweeps: `--psf L:N`, `--dyn L:N[:G]`.
    psf: Option<PsfParams>,
    dynamic: Option<(PsfParams, Option<usize>)>,
}

/// `start:stop[:step]` like Python's `range`, or a comma list.
fn parse_frames(s: &str) -> Result<Vec<i64>, String> {
    let bad = || format!("--frames {s}: want A:B[:S] or F1,F2,...");
    let num = |x: &str| x.trim().parse::<i64>().map_err(|_| bad());
    if s.contains(':') {
        let p: Vec<i64> = s.split(':').map(num).collect::<Result<_, _>>()?;
        let (a, b, st) = match p[..] {
            [a, b] => (a, b, 1),
            [a, b, st] => (a, b, st),
            _ => return Err(bad()),
        };
        if st == 0 {
            return Err(format!("--frames {s}: step 0"));
        }
        let mut out = Vec::new();
        let mut f = a;
        while (st > 0 && f < b) || (st < 0 && f > b) {
            out.push(f);
            f += st;
        }
        Ok(out)
    } else {
        s.split(',').map(num).collect()
    }
}

fn parse_args() -> Args {
    let mut scene = None;
    let mut frames = "0:300:30".to_string();
    let (mut width, mut height) = (640u32, 480u32);
    let (mut psf, mut dynamic) = (None, None);
    let mut it = std::env::args().skip(1).filter(|a| a != "--bench");
    while let Some(a) = it.next() {
        let mut val = |name: &str| {
            it.next()
                .unwrap_or_else(|| fail(&format!("{name} needs a value")))
        };
        match a.as_str() {
            "--frames" => frames = val("--frames"),
            "--width" | "--height" => {
                let v = val(&a);
                let n: u32 = v
                    .parse()
                    .ok()
                    .filter(|&n| n > 0 && n <= 16384)
                    .unwrap_or_else(|| fail(&format!("{a} {v}: want an integer in 1..=16384")));
                if a == "--width" {
                    width = n
                } else {
                    height = n
                }
            }
            "--psf" | "--dyn" => {
                let v = val(&a);
                let want = if a == "--psf" {
                    "LEVEL:TILES"
                } else {
                    "LEVEL:TILES[:GRIDS]"
                };
                let msg = format!("{a} {v}: want {want}");
                let bad = || -> ! { fail(&msg) };
                let f: Vec<&str> = v.split(':').collect();
                let (l, n, g) = match f[..] {
                    [l, n] => (l, n, None),
                    [l, n, g] if a == "--dyn" => (l, n, Some(g)),
                    _ => bad(),
                };
                let p = l
                    .parse()
                    .ok()
                    .zip(n.parse().ok())
                    .map(|(level, tiles)| PsfParams { level, tiles })
                    .filter(|p| p.validate().is_ok())
                    .unwrap_or_else(|| bad());
                let g = g.map(|g| g.parse::<usize>().unwrap_or_else(|_| bad()));
                if a == "--psf" {
                    psf = Some(p)
                } else {
                    dynamic = Some((p, g))
                }
            }
            _ if a.starts_with('-') => fail(&format!(
                "unknown option {a}; usage: cargo bench --bench embree -- SCENE.glb \
                 [--frames A:B[:S]] [--width W] [--height H] [--psf LEVEL:TILES] \
                 [--dyn LEVEL:TILES[:GRIDS]]"
            )),
            _ if scene.is_none() => scene = Some(PathBuf::from(a)),
            _ => fail(&format!("one scene only (got {a} too)")),
        }
    }
    let scene = scene.unwrap_or_else(|| {
        fail("usage: cargo bench --bench embree -- SCENE.glb [--frames A:B[:S]] [--width W] [--height H]")
    });
    let frames = parse_frames(&frames).unwrap_or_else(|e| fail(&e));
    if frames.is_empty() {
        fail("--frames gives no frame");
    }
    Args {
        scene,
        frames,
        width,
        height,
        psf,
        dynamic,
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Rounded like the harness's output (3 decimals).
fn r3(x: f64) -> Value {
    json!((x * 1e3).round() / 1e3)
}

/// Per-frame figures, with the harness's names.
#[derive(Clone, Copy, Default)]
struct FrameRow {
    eval_ms: f64,
    update_ms: f64,
    primary_ms: f64,
    setup_ms: f64,
    shadow_ms: f64,
    reflect_ms: f64,
    primary_rays: usize,
    primary_hits: usize,
    dynamic_hits: usize,
    shadow_rays: usize,
    shadow_occluded: usize,
    reflect_rays: usize,
    reflect_hits: usize,
}

impl FrameRow {
    fn trace_ms(&self) -> f64 {
        self.primary_ms + self.shadow_ms + self.reflect_ms
    }
    fn frame_ms(&self) -> f64 {
        self.eval_ms + self.update_ms + self.trace_ms()
    }
}

fn main() {
    let a = parse_args();
    let scene = import::load(&a.scene)
        .unwrap_or_else(|e| fail(&format!("cannot load {}: {e}", a.scene.display())));
    let split = scene.split(ClipSelection::All);
    let statics = scene.static_triangles(&split);
    if statics.is_empty() {
        fail("the scene has no static triangles (the harness needs some too)");
    }
    let ndyn = split.summary().dynamic_triangles;
    let fps = scene
        .fps
        .filter(|f| f.is_finite() && *f > 0.0)
        .unwrap_or(30.0);

    // Camera: the first one, pixel centres, aspect W/H (the harness ignores aspectRatio).
    let cam = scene
        .camera_at(ClipSelection::All, 0.0, None)
        .unwrap_or_else(|| fail("the scene has no camera (the harness needs one)"));
    if cam.is_orthographic() {
        fail("the first camera is orthographic; the harness traces perspective cameras only");
    }
    let mut model = CameraModel::from_scene(&cam, a.width, a.height);
    model.aspect = a.width as f32 / a.height as f32;
    let primary: Vec<Ray> = (0..a.height)
        .flat_map(|y| (0..a.width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let r = model.ray(x as f32 + 0.5, y as f32 + 0.5);
            Ray::new(r.origin, r.dir.normalize())
        })
        .collect();
    // Light: the first point light; else the first light; else the camera (the harness's
    // fallback). The museum's first light is its point light on both sides.
    let lights = scene.lights_at(ClipSelection::All, 0.0);
    let light = lights
        .iter()
        .find(|l| l.kind == LightKind::Point)
        .or(lights.first())
        .map_or(cam.position, |l| l.position);

    let diag = statics
        .bounds()
        .map_or(0.0, |(lo, hi)| (hi - lo).length() as f64);
    let eps = (1e-4 * diag) as f32;

    let params = a
        .psf
        .unwrap_or_else(|| PsfParams::for_triangles(statics.len()));
    let t = Instant::now();
    let psf = Psf::build(&statics.positions, &params)
        .unwrap_or_else(|e| fail(&format!("baking the static part: {e}")));
    let static_build_ms = ms(t);
    let mut layer = match a.dynamic {
        Some((p, grids)) => match grids {
            Some(g) => DynamicLayer::with_grids(p, g),
            None => DynamicLayer::with_params(p),
        }
        .unwrap_or_else(|e| fail(&format!("--dyn: {e}"))),
        None => DynamicLayer::for_triangles(ndyn),
    };
    let nstat = statics.len() as u32;

    let threads = rayon::current_num_threads();
    let nproc = std::thread::available_parallelism().map_or(0, |n| n.get());
    println!(
        "{}",
        json!({"setup": {
            "side": "subfield", "threads": threads, "nproc": nproc,
            "static_tris": statics.len(), "dynamic_tris": ndyn,
            "width": a.width, "height": a.height, "fps": fps,
            "psf_level": params.level, "psf_tiles": params.tiles,
            "dyn_level": layer.params().level, "dyn_tiles": layer.params().tiles,
            "dyn_grids": layer.grids(),
            "light": light.to_array(), "eps": eps,
            "static_build_ms": static_build_ms,
        }})
    );

    let mut soup = TriangleSoup::new();
    let mut hits: Vec<Option<Hit>> = vec![None; primary.len()];
    let mut rows = Vec::new();
    let mut run = vec![a.frames[0]];
    run.extend_from_slice(&a.frames);
    // The frames run on a pool thread, as the harness's calling thread takes its share
    // of each batch (`trace_helper.c` runs one worker itself) and of Embree's builds
    // (TBB's caller joins the work): a call from outside the pool would park this thread
    // and wait for a sleeping worker instead (`benches/PERF.md`, step 79).
    rayon::scope(|_| {
        for (fi, &f) in run.iter().enumerate() {
            let mut r = FrameRow::default();
            let tsec = (f as f64 / fps as f64) as f32;
            let t = Instant::now();
            scene.dynamic_triangles_at(&split, tsec, &mut soup);
            r.eval_ms = ms(t);
            let t = Instant::now();
            layer
                .update(&soup.positions)
                .unwrap_or_else(|e| fail(&format!("frame {f}: dynamic update: {e}")));
            r.update_ms = ms(t);
            let both = psf.with_dynamic(&layer);

            let t = Instant::now();
            both.intersect_batch(&primary, &mut hits);
            r.primary_ms = ms(t);
            r.primary_rays = primary.len();
            r.primary_hits = hits.iter().flatten().count();
            r.dynamic_hits = (hits.iter().flatten())
                .filter(|h| matches!(both.prim(h), Prim::Moving(_)))
                .count();

            // Secondary rays, as the harness builds them (untimed in the frame).
            let t = Instant::now();
            let tri = |i: u32| {
                if i < nstat {
                    statics.positions[i as usize]
                } else {
                    soup.positions[(i - nstat) as usize]
                }
            };
            let (shadow, reflect): (Vec<Ray>, Vec<Ray>) = primary
                .par_iter()
                .zip(hits.par_iter())
                .filter_map(|(ray, h)| {
                    let h = h.as_ref()?;
                    let v = tri(h.tri);
                    let n = (v[1] - v[0]).cross(v[2] - v[0]).normalize_or(Vec3::Y);
                    let n = if n.dot(ray.dir) > 0.0 { -n } else { n };
                    let o = ray.at(h.t) + eps * n;
                    let l = light - o;
                    let dist = l.length();
                    let sd = l / dist.max(1e-30);
                    let rd = ray.dir - 2.0 * ray.dir.dot(n) * n;
                    Some((
                        Ray::segment(o, sd, 0.0, dist * (1.0 - 1e-4)),
                        Ray::new(o, rd),
                    ))
                })
                .unzip();
            r.setup_ms = ms(t);

            let mut occ = vec![false; shadow.len()];
            let t = Instant::now();
            both.occluded_batch(&shadow, &mut occ);
            r.shadow_ms = ms(t);
            r.shadow_rays = shadow.len();
            r.shadow_occluded = occ.iter().filter(|&&o| o).count();

            let mut rhits = vec![None; reflect.len()];
            let t = Instant::now();
            both.intersect_batch(&reflect, &mut rhits);
            r.reflect_ms = ms(t);
            r.reflect_rays = reflect.len();
            r.reflect_hits = rhits.iter().flatten().count();

            if fi == 0 {
                work(&psf, &layer, [&primary, &shadow, &reflect]);
            }
            println!(
                "{}",
                json!({
                    "frame": f, "warmup": fi == 0, "eval_ms": r3(r.eval_ms),
                    "update_ms": r3(r.update_ms), "primary_ms": r3(r.primary_ms),
                    "primary_rays": r.primary_rays, "primary_hits": r.primary_hits,
                    "dynamic_hits": r.dynamic_hits, "setup_ms": r3(r.setup_ms),
                    "shadow_ms": r3(r.shadow_ms), "shadow_rays": r.shadow_rays,
                    "shadow_occluded": r.shadow_occluded, "reflect_ms": r3(r.reflect_ms),
                    "reflect_rays": r.reflect_rays, "reflect_hits": r.reflect_hits,
                    "trace_ms": r3(r.trace_ms()), "frame_ms": r3(r.frame_ms()),
                })
            );
            if fi > 0 {
                rows.push(r);
            }
        }
    });

    let n = rows.len() as f64;
    let mean = |g: fn(&FrameRow) -> f64| rows.iter().map(g).sum::<f64>() / n;
    let sum_f = |g: fn(&FrameRow) -> f64| rows.iter().map(g).sum::<f64>();
    let sum_n = |g: fn(&FrameRow) -> usize| rows.iter().map(g).sum::<usize>();
    let mrays = |rays: usize, ms: f64| rays as f64 / ms / 1e3;
    let all_rays = sum_n(|r| r.primary_rays) + sum_n(|r| r.shadow_rays) + sum_n(|r| r.reflect_rays);
    let mut s = Map::new();
    s.insert("frames".into(), json!(rows.len()));
    s.insert("static_build_ms".into(), r3(static_build_ms));
    s.insert("mean_eval_ms".into(), r3(mean(|r| r.eval_ms)));
    s.insert("mean_update_ms".into(), r3(mean(|r| r.update_ms)));
    s.insert("mean_blas_ms".into(), Value::Null);
    s.insert("mean_tlas_ms".into(), Value::Null);
    s.insert(
        "max_update_ms".into(),
        r3(rows.iter().map(|r| r.update_ms).fold(0.0, f64::max)),
    );
    s.insert(
        "primary_mrays_s".into(),
        r3(mrays(sum_n(|r| r.primary_rays), sum_f(|r| r.primary_ms))),
    );
    s.insert(
        "shadow_mrays_s".into(),
        r3(mrays(sum_n(|r| r.shadow_rays), sum_f(|r| r.shadow_ms))),
    );
    s.insert(
        "reflect_mrays_s".into(),
        r3(mrays(sum_n(|r| r.reflect_rays), sum_f(|r| r.reflect_ms))),
    );
    s.insert(
        "all_mrays_s".into(),
        r3(mrays(all_rays, sum_f(FrameRow::trace_ms))),
    );
    s.insert("mean_trace_ms".into(), r3(mean(FrameRow::trace_ms)));
    s.insert("mean_frame_ms".into(), r3(mean(FrameRow::frame_ms)));
    s.insert("fps".into(), r3(1e3 / mean(FrameRow::frame_ms)));
    for (k, g) in [
        (
            "primary_rays",
            (|r| r.primary_rays) as fn(&FrameRow) -> usize,
        ),
        ("primary_hits", |r| r.primary_hits),
        ("dynamic_hits", |r| r.dynamic_hits),
        ("shadow_rays", |r| r.shadow_rays),
        ("shadow_occluded", |r| r.shadow_occluded),
        ("reflect_rays", |r| r.reflect_rays),
        ("reflect_hits", |r| r.reflect_hits),
    ] {
        s.insert(format!("total_{k}"), json!(sum_n(g)));
    }
    println!(
        "{}",
        json!({"summary": s, "config": {
            "side": "subfield", "threads": threads, "update": "dynamic layer",
            "layout": "static PSF + dynamic layer", "static_tris": statics.len(),
            "dynamic_tris": ndyn,
        }})
    );
}
