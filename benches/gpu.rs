//! The GPU tracer beside the CPU tracer (all cores), same triangles, same rays, one run.
//!
//! A museum-class scene: a 10,284-triangle static room (`common::room`) and N moving
//! triangles in unstructured motion (16,384, the museum's count, and 1,048,576 by
//! default), new positions every frame. Per frame: the moving part's update (the CPU's
//! `DynamicLayer::update`; the GPU's upload + grid build, wall time), then camera rays
//! (a pinhole, `--size`), shadow rays from each camera hit to a point light, mirror rays
//! from each camera hit, and random rays (as many as camera rays), each batch traced by
//! both. The GPU's time is given twice: wall time with the transfers (rays up, hits
//! down), and the trace pass alone by timestamp queries (where the adapter has them; the
//! update's GPU time likewise: count, scan, scatter). Every GPU answer is compared with
//! the CPU's and the mismatches printed (0 expected).
//!
//! With `--scene FILE.glb` (the peers' generator, `../shared/peers/gen_scene.py`, which
//! Embree's harness reads too) the triangles, the camera and the point light are the
//! file's, posed at frames 0, S, 2S, ... (`--step S`, default 10) as the harness's
//! `--frames 0:F·S:S` poses them: the same rays as Embree's camera, shadow and mirror
//! rays (`benches/gpu.sh` runs both in one go).
//!
//! `cargo bench --bench gpu -- [--size WxH] [--moving N,M | --scene F.glb [--step S]]
//! [--frames F]`. Needs a Vulkan adapter (`--device gpu`'s choice); on lavapipe (a CPU
//! driver) use a tiny size: the figures then say nothing about a GPU, only that the
//! benchmark runs.

#[path = "common.rs"]
mod common;

use std::time::Instant;

use glam::Vec3;
use subfield::gen::synth::{self, Rng};
use subfield::gpu::{AdapterPolicy, GpuDevice, GpuMoving, GpuStatic, GpuTracer};
use subfield::{DynamicLayer, Hit, Intersector, Psf, PsfParams, Ray};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn arg<T: std::str::FromStr>(name: &str) -> Option<T> {
    let args: Vec<String> = std::env::args().collect();
    let i = args.iter().position(|a| a == name)?;
    args.get(i + 1)?.parse().ok()
}

/// `n` triangles of about `size` scattered in the room (a frame of unstructured motion).
fn moving_frame(rng: &mut Rng, n: usize) -> Vec<[Vec3; 3]> {
    let size = (20.0 / (n as f32).cbrt()).clamp(0.01, 0.5);
    synth::soup(
        rng,
        n,
        Vec3::new(-9.0, 0.5, -9.0),
        Vec3::new(9.0, 5.5, 9.0),
        size,
    )
}

/// Per batch kind: its name, CPU seconds, GPU wall seconds and GPU pass seconds per
/// frame, rays, mismatches.
type Row = (&'static str, Vec<f64>, Vec<f64>, Vec<f64>, usize, usize);

/// A shadow ray to the light and a mirror ray about the triangle's normal from each
/// camera hit (`tris`: the static triangles, then the moving ones, as hits number them).
fn secondary(
    camera: &[Ray],
    hits: &[Option<Hit>],
    light: Vec3,
    stat: &[[Vec3; 3]],
    moving: &[[Vec3; 3]],
) -> (Vec<Ray>, Vec<Ray>) {
    let (mut shadow, mut mirror) = (Vec::new(), Vec::new());
    for (r, h) in camera.iter().zip(hits) {
        let Some(h) = h else { continue };
        let i = h.tri as usize;
        let t = if i < stat.len() {
            stat[i]
        } else {
            moving[i - stat.len()]
        };
        let p = r.at(h.t);
        let d = r.dir;
        let o = p - d * 1e-4;
        shadow.push(Ray::segment(o, light - o, 0.0, 1.0 - 1e-4));
        let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
        mirror.push(Ray::segment(o, d - n * 2.0 * d.dot(n), 1e-4, f32::INFINITY));
    }
    (shadow, mirror)
}

/// One frame of a case: the moving triangles and the camera rays.
type Frame = (Vec<[Vec3; 3]>, std::sync::Arc<Vec<Ray>>);

/// One measured case: a label (the moving count) and its frames.
struct Case {
    label: String,
    moving: usize,
    frames: Vec<Frame>,
}

/// The static triangles, the light and the cases of `--scene FILE`: the file's moving
/// triangles and camera at frames 0, step, 2·step, ...
fn scene_cases(
    path: &std::path::Path,
    w: usize,
    h: usize,
    frames: usize,
    step: usize,
) -> (Vec<[Vec3; 3]>, Vec3, Vec<Case>) {
    use subfield::render::CameraModel;
    use subfield::scene::{ClipSelection, TriangleSoup};
    let scene = subfield::import::load(path).unwrap_or_else(|e| {
        eprintln!("gpu bench: {}: {e}", path.display());
        std::process::exit(1);
    });
    let sel = ClipSelection::All;
    let split = scene.split(sel);
    let stat = scene.static_triangles(&split).positions;
    let fps = scene.fps.unwrap_or(24.0);
    let light = scene
        .lights_at(sel, 0.0)
        .first()
        .map_or(Vec3::new(0.0, 5.5, 0.0), |l| l.position);
    let mut soup = TriangleSoup::new();
    let mut per = Vec::new();
    for k in 0..frames {
        let t = (k * step) as f32 / fps;
        scene.dynamic_triangles_at(&split, t, &mut soup);
        let cam = scene.camera_at(sel, t, None).unwrap_or_else(|| {
            eprintln!("gpu bench: {} has no camera", path.display());
            std::process::exit(1);
        });
        let model = CameraModel::from_scene(&cam, w as u32, h as u32);
        let rays: Vec<Ray> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| model.ray(x as f32 + 0.5, y as f32 + 0.5))
            .collect();
        per.push((soup.positions.clone(), std::sync::Arc::new(rays)));
    }
    let n = per.first().map_or(0, |f| f.0.len());
    let case = Case {
        label: format!(
            "{n} ({})",
            path.file_name().map_or("".into(), |f| f.to_string_lossy())
        ),
        moving: n,
        frames: per,
    };
    (stat, light, vec![case])
}

fn main() {
    let size: String = arg("--size").unwrap_or_else(|| "640x480".into());
    let (w, h) = size
        .split_once('x')
        .and_then(|(a, b)| Some((a.parse().ok()?, b.parse().ok()?)))
        .unwrap_or((640usize, 480usize));
    let moving: Vec<usize> = arg::<String>("--moving")
        .unwrap_or_else(|| "16384,1048576".into())
        .split(',')
        .filter_map(|s| s.parse().ok())
        .collect();
    let frames: usize = arg("--frames").unwrap_or(5).max(1);
    let scene: Option<String> = arg("--scene");
    let step: usize = arg("--step").unwrap_or(10).max(1);
    let dev = match GpuDevice::open(AdapterPolicy::Any) {
        Ok(Some(d)) => d,
        Ok(None) => unreachable!("AdapterPolicy::Any answers an error, not None"),
        Err(e) => {
            eprintln!("gpu bench: {e}");
            std::process::exit(1);
        }
    };
    println!(
        "# GPU tracer: {}; CPU tracer on {} threads; {w}x{h}, median of {frames} frames",
        dev.describe(),
        rayon::current_num_threads()
    );
    let (stat, light, cases) = match &scene {
        Some(p) => scene_cases(std::path::Path::new(p), w, h, frames, step),
        None => {
            let camera = std::sync::Arc::new(common::camera_rays(w, h));
            let cases = moving
                .iter()
                .map(|&n| {
                    let mut rng = Rng::new(11);
                    Case {
                        label: n.to_string(),
                        moving: n,
                        frames: (0..frames)
                            .map(|_| (moving_frame(&mut rng, n), camera.clone()))
                            .collect(),
                    }
                })
                .collect();
            (common::room(10_284), Vec3::new(0.0, 5.5, 0.0), cases)
        }
    };
    let psf = Psf::build(&stat, &PsfParams::for_static(stat.len())).expect("bake");
    let clock = Instant::now();
    let gstat = GpuStatic::upload(&dev, &psf).expect("upload");
    println!(
        "static part: {} triangles, {:.1} MB uploaded in {:.1} ms",
        stat.len(),
        gstat.bytes() as f64 / 1e6,
        clock.elapsed().as_secs_f64() * 1e3
    );
    let random = common::random_rays(w * h);
    println!(
        "\n| moving | batch | rays | CPU Mrays/s | GPU Mrays/s (wall, transfers) | GPU Mrays/s (pass, timestamps) | GPU wall/CPU | mismatches |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for case in cases {
        let (label, n) = (case.label, case.moving);
        let mut layer = DynamicLayer::for_triangles(n);
        let mut gmov = GpuMoving::new(&dev).expect("moving part");
        gmov.set_timing(true);
        let (mut up_cpu, mut up_gpu, mut up_pass) = (Vec::new(), Vec::new(), Vec::new());
        let mut rows: Vec<Row> = Vec::new();
        for (tris, camera) in &case.frames {
            let camera: &[Ray] = camera;
            let t = Instant::now();
            layer.update(tris).expect("update");
            up_cpu.push(t.elapsed().as_secs_f64() * 1e3);
            let t = Instant::now();
            gmov.update(&dev, tris).expect("gpu update");
            dev.finish().expect("gpu update");
            up_gpu.push(t.elapsed().as_secs_f64() * 1e3);
            up_pass.push(gmov.gpu_seconds().map_or(f64::NAN, |s| s * 1e3));
            let cpu = psf.with_dynamic(&layer);
            let mut cam_hits = vec![None; camera.len()];
            cpu.intersect_batch(camera, &mut cam_hits);
            let (shadow, mirror) = secondary(camera, &cam_hits, light, &stat, tris);
            let batches: [(&'static str, &[Ray], bool); 4] = [
                ("camera", camera, false),
                ("shadow", &shadow, true),
                ("reflection", &mirror, false),
                ("random", &random, false),
            ];
            for (k, (name, rays, any)) in batches.iter().enumerate() {
                let gpu = GpuTracer::new(&dev, &gstat, &gmov).timed();
                let (cs, gs, bad) = if *any {
                    let (mut a, mut b) = (vec![false; rays.len()], vec![false; rays.len()]);
                    let t = Instant::now();
                    cpu.occluded_batch(rays, &mut a);
                    let cs = t.elapsed().as_secs_f64();
                    let t = Instant::now();
                    gpu.try_occluded_batch(rays, &mut b).expect("gpu");
                    let gs = t.elapsed().as_secs_f64();
                    (cs, gs, a.iter().zip(&b).filter(|(x, y)| x != y).count())
                } else {
                    let (mut a, mut b) = (vec![None; rays.len()], vec![None; rays.len()]);
                    let t = Instant::now();
                    cpu.intersect_batch(rays, &mut a);
                    let cs = t.elapsed().as_secs_f64();
                    let t = Instant::now();
                    gpu.try_intersect_batch(rays, &mut b).expect("gpu");
                    let gs = t.elapsed().as_secs_f64();
                    (cs, gs, a.iter().zip(&b).filter(|(x, y)| x != y).count())
                };
                if rows.len() <= k {
                    rows.push((name, Vec::new(), Vec::new(), Vec::new(), rays.len(), 0));
                }
                rows[k].1.push(cs);
                rows[k].2.push(gs);
                rows[k].3.push(gpu.gpu_seconds().unwrap_or(f64::NAN));
                rows[k].4 = rays.len();
                rows[k].5 += bad;
            }
        }
        for (name, cs, gs, ps, nrays, bad) in rows {
            let (c, g, p) = (median(cs), median(gs), median(ps));
            println!(
                "| {label} | {name} | {nrays} | {:.2} | {:.2} | {:.2} | {:.2} | {bad} |",
                nrays as f64 / c / 1e6,
                nrays as f64 / g / 1e6,
                nrays as f64 / p / 1e6,
                c / g
            );
        }
        let (grid, entries) = gmov.grid();
        println!(
            "| {label} | update (ms) | | CPU {:.2} | GPU {:.2} wall (grid {:?}, {entries} entries) | GPU {:.2} passes | | |",
            median(up_cpu),
            median(up_gpu),
            grid,
            median(up_pass)
        );
    }
}
