//! The GPU tracer against brute force and the CPU tracer, on the scenes and frames of
//! moving triangles the CPU suite uses (tests/common/motion.rs): every ray's closest hit
//! (triangle, and t, u, v to the bit) and any-hit answer must be brute force's and the
//! CPU's `Layered` query's. Rays along tile edges and corner lines, grazing rays in the
//! planes of the room's faces, degenerate triangles and clustered frames included. Small
//! inputs: on lavapipe (CI) each case takes a second or two.
//!
//! Needs a GPU adapter (tests/common/gpu.rs): fails under CI without one, skips elsewhere.
//! A failure prints the seed, the frame and the ray.

mod common;

use common::motion::{clustered_tris, frame_tris, rays, static_scene, HI, LO};
use glam::Vec3;
use subfield::gen::synth::Rng;
use subfield::geometry::{BruteForce, Hit, Intersector, Ray};
use subfield::gpu::{GpuMoving, GpuStatic, GpuTracer};
use subfield::{DynamicLayer, Psf, PsfParams};

/// A hit's numbers as bits: `-0.0` and `0.0` differ, NaN equals itself.
fn bits(h: Option<Hit>) -> Option<(u32, u32, u32, u32)> {
    h.map(|h| (h.tri, h.t.to_bits(), h.u.to_bits(), h.v.to_bits()))
}

/// Rays along the static subfields' tile edges and corner lines (parallel to a beam,
/// through a tile corner; along a tile edge in the base plane), and grazing rays in the
/// planes of the room's faces.
fn edge_rays(rng: &mut Rng, psf: &Psf, n: usize) -> Vec<Ray> {
    let mut out = Vec::with_capacity(n);
    let subs = psf.subfields();
    while out.len() < n && !subs.is_empty() {
        let f = &subs[rng.below(subs.len())].frame;
        let (i, j) = (rng.below(f.nu as usize + 1), rng.below(f.nv as usize + 1));
        let corner = f.u * (f.u0 + i as f32 * f.tile) + f.v * (f.v0 + j as f32 * f.tile);
        let ray = match rng.below(4) {
            // down a beam's corner line, from outside the bounds
            0 => Ray::new(corner - f.d * 100.0, f.d),
            // along a tile edge, in a plane of constant depth through the room
            1 => {
                let o = corner + f.d * rng.range(-20.0, 20.0) - f.u * 50.0;
                Ray::new(o, f.u)
            }
            // grazing: in the plane of a face of the room (x, y or z = 0 or 8)
            2 => {
                let k = rng.below(3);
                let mut o = rng.in_box(LO - 4.0, HI + 4.0);
                o[k] = if rng.below(2) == 0 { LO[k] } else { HI[k] };
                let mut d = rng.unit();
                d[k] = 0.0;
                Ray::new(o, d)
            }
            // through a corner line at a slant
            _ => {
                let p = corner + f.d * rng.range(-10.0, 10.0);
                let o = p + rng.unit() * rng.range(1.0, 30.0);
                Ray::new(o, p - o)
            }
        };
        out.push(ray);
    }
    out
}

/// One case: `frames` frames of moving triangles over a static room, every ray checked.
fn check_case(seed: u64, params: PsfParams, frames: usize, moving: usize, nrays: usize) {
    check_case_split(seed, params, frames, moving, nrays, false);
}

/// [`check_case`], with `split` every array of the static part uploaded in 2 to 4
/// bindings, as a scene larger than one binding (128 MiB on lavapipe) is.
fn check_case_split(
    seed: u64,
    params: PsfParams,
    frames: usize,
    moving: usize,
    nrays: usize,
    split: bool,
) {
    let Some(dev) = common::gpu::device() else {
        return;
    };
    let mut rng = Rng::new(seed);
    let mut stat = static_scene(&mut rng);
    if split {
        // Dense enough that tiles hold slabs (over 32 entries), not only flat blocks.
        stat.extend(subfield::gen::synth::soup(&mut rng, 1500, LO, HI, 0.8));
    }
    let psf = Psf::build(&stat, &params).expect("bake");
    let gstat = if split {
        let g = GpuStatic::upload_split(dev, &psf).expect("split upload");
        assert!(
            g.chunks().iter().all(|&c| c >= 2),
            "every array in two parts or more: {:?}",
            g.chunks()
        );
        g
    } else {
        GpuStatic::upload(dev, &psf).expect("upload")
    };
    let mut layer = DynamicLayer::new(&psf);
    let mut gmov = GpuMoving::new(dev).expect("moving part");
    let mut before: Vec<[Vec3; 3]> = Vec::new();
    for frame in 0..frames {
        let (moving, mode) = if frame % 2 == 0 {
            frame_tris(&mut rng, moving)
        } else {
            clustered_tris(&mut rng, moving)
        };
        layer.update(&moving).expect("update");
        gmov.update(dev, &moving).expect("gpu update");
        let all: Vec<[Vec3; 3]> = stat.iter().chain(&moving).copied().collect();
        let brute = BruteForce::new(&all);
        let cpu = psf.with_dynamic(&layer);
        let gpu = GpuTracer::new(dev, &gstat, &gmov);
        let mut rs = rays(&mut rng, nrays, &moving, &before);
        rs.extend(edge_rays(&mut rng, &psf, nrays / 2));
        let n = rs.len();
        let (mut g, mut c, mut b) = (vec![None; n], vec![None; n], vec![None; n]);
        gpu.try_intersect_batch(&rs, &mut g).expect("gpu trace");
        cpu.intersect_batch(&rs, &mut c);
        brute.intersect_batch(&rs, &mut b);
        let (mut ga, mut ba) = (vec![false; n], vec![false; n]);
        gpu.try_occluded_batch(&rs, &mut ga).expect("gpu any hit");
        brute.occluded_batch(&rs, &mut ba);
        let hits = b.iter().filter(|h| h.is_some()).count();
        for i in 0..n {
            let at = || {
                format!(
                    "seed {seed}, {params:?}, frame {frame} ({mode}), ray {i} {:?}",
                    rs[i]
                )
            };
            assert_eq!(
                bits(g[i]),
                bits(b[i]),
                "closest hit differs from brute force: {}",
                at()
            );
            assert_eq!(
                bits(g[i]),
                bits(c[i]),
                "closest hit differs from the CPU tracer: {}",
                at()
            );
            assert_eq!(ga[i], ba[i], "any hit differs from brute force: {}", at());
        }
        // The rays must exercise the tracer: most of them hit something.
        assert!(hits * 2 > n, "only {hits} of {n} rays hit: seed {seed}");
        before = moving;
    }
}

#[test]
fn gpu_equals_brute_force_and_cpu_over_frames() {
    let params = [
        PsfParams { level: 0, tiles: 4 },
        PsfParams {
            level: 1,
            tiles: 16,
        },
        PsfParams {
            level: 2,
            tiles: 32,
        },
        PsfParams { level: 1, tiles: 7 },
    ];
    for seed in 0..8u64 {
        let p = params[seed as usize % params.len()];
        check_case(0x9e37_79b9 ^ seed, p, 4, 60 + 40 * (seed as usize % 3), 400);
    }
}

/// The static part's arrays split over several bindings (what a scene larger than one
/// binding needs) answer as one binding does: brute force's hits, to the bit.
#[test]
fn gpu_split_arrays_equal_brute_force() {
    for (seed, level, tiles) in [(0x5b17_u64, 0, 4), (0x5b18, 1, 7)] {
        check_case_split(seed, PsfParams { level, tiles }, 2, 80, 500, true);
    }
}

#[test]
fn gpu_equals_brute_force_on_large_moving_frames() {
    // Enough moving triangles that the grid has many cells and the scan several blocks.
    check_case(
        0x5eed_0001,
        PsfParams {
            level: 1,
            tiles: 16,
        },
        2,
        3000,
        600,
    );
}

/// Shadow segments whose end lies exactly on a triangle (`t_max` on the hit), and rays
/// that start on one (`t_min` on it), as the renderer sends them.
#[test]
fn gpu_segments_ending_and_starting_on_triangles() {
    let Some(dev) = common::gpu::device() else {
        return;
    };
    let mut rng = Rng::new(77);
    let stat = static_scene(&mut rng);
    let psf = Psf::build(&stat, &PsfParams::default()).expect("bake");
    let gstat = GpuStatic::upload(dev, &psf).expect("upload");
    let (moving, _) = frame_tris(&mut rng, 80);
    let mut gmov = GpuMoving::new(dev).expect("moving part");
    gmov.update(dev, &moving).expect("gpu update");
    let all: Vec<[Vec3; 3]> = stat.iter().chain(&moving).copied().collect();
    let brute = BruteForce::new(&all);
    let gpu = GpuTracer::new(dev, &gstat, &gmov);
    let probe: Vec<Ray> = (0..800)
        .map(|_| Ray::new(rng.in_box(LO, HI), rng.unit()))
        .collect();
    let mut first = vec![None; probe.len()];
    brute.intersect_batch(&probe, &mut first);
    let mut rs = Vec::new();
    for (r, h) in probe.iter().zip(&first) {
        if let Some(h) = h {
            rs.push(Ray::segment(r.origin, r.dir, 0.0, h.t));
            rs.push(Ray::segment(r.origin, r.dir, h.t, f32::INFINITY));
            rs.push(Ray::segment(r.origin, r.dir, 0.0, h.t * (1.0 - 1e-6)));
        }
    }
    let n = rs.len();
    let (mut g, mut b) = (vec![None; n], vec![None; n]);
    gpu.try_intersect_batch(&rs, &mut g).expect("gpu trace");
    brute.intersect_batch(&rs, &mut b);
    let (mut ga, mut ba) = (vec![false; n], vec![false; n]);
    gpu.try_occluded_batch(&rs, &mut ga).expect("gpu any hit");
    brute.occluded_batch(&rs, &mut ba);
    for i in 0..n {
        assert_eq!(bits(g[i]), bits(b[i]), "closest hit, ray {i} {:?}", rs[i]);
        assert_eq!(ga[i], ba[i], "any hit, ray {i} {:?}", rs[i]);
    }
}

/// Invalid rays (NaN, zero direction) and empty parts answer no hit, as on the CPU.
#[test]
fn gpu_invalid_rays_and_empty_parts() {
    let Some(dev) = common::gpu::device() else {
        return;
    };
    let psf = Psf::build(&[], &PsfParams::default()).expect("bake");
    let gstat = GpuStatic::upload(dev, &psf).expect("upload");
    let mut gmov = GpuMoving::new(dev).expect("moving part");
    let tri = [
        Vec3::new(-1.0, -1.0, 2.0),
        Vec3::new(1.0, -1.0, 2.0),
        Vec3::new(0.0, 1.0, 2.0),
    ];
    let rs = [
        Ray::new(Vec3::ZERO, Vec3::Z),
        Ray::new(Vec3::ZERO, Vec3::ZERO),
        Ray::new(Vec3::splat(f32::NAN), Vec3::Z),
        Ray::segment(Vec3::ZERO, Vec3::Z, f32::INFINITY, f32::INFINITY),
    ];
    let mut out = vec![
        Some(Hit {
            t: 0.0,
            tri: 0,
            u: 0.0,
            v: 0.0
        });
        rs.len()
    ];
    GpuTracer::new(dev, &gstat, &gmov)
        .try_intersect_batch(&rs, &mut out)
        .expect("trace");
    assert_eq!(out, vec![None; rs.len()], "nothing to hit");
    gmov.update(dev, &[tri]).expect("update");
    GpuTracer::new(dev, &gstat, &gmov)
        .try_intersect_batch(&rs, &mut out)
        .expect("trace");
    let one = [tri];
    let want = BruteForce::new(&one);
    for (r, h) in rs.iter().zip(&out) {
        assert_eq!(bits(*h), bits(want.intersect(r)), "ray {r:?}");
    }
    assert_eq!(out[0].map(|h| h.t), Some(2.0));
}

/// Two runs over the same input give the same bytes.
#[test]
fn gpu_runs_are_deterministic() {
    let Some(dev) = common::gpu::device() else {
        return;
    };
    let run = || {
        let mut rng = Rng::new(4242);
        let stat = static_scene(&mut rng);
        let psf = Psf::build(
            &stat,
            &PsfParams {
                level: 1,
                tiles: 16,
            },
        )
        .expect("bake");
        let gstat = GpuStatic::upload(dev, &psf).expect("upload");
        let mut gmov = GpuMoving::new(dev).expect("moving part");
        let (moving, _) = clustered_tris(&mut rng, 200);
        gmov.update(dev, &moving).expect("update");
        let rs = rays(&mut rng, 1000, &moving, &[]);
        let mut out = vec![None; rs.len()];
        GpuTracer::new(dev, &gstat, &gmov)
            .try_intersect_batch(&rs, &mut out)
            .expect("trace");
        out.into_iter().map(bits).collect::<Vec<_>>()
    };
    assert_eq!(run(), run());
}

/// A baked file opened again, mapped raw (`--codec none`, the arrays used in place) and
/// zstd-compressed, uploads to the same hits as brute force's.
#[test]
fn gpu_traces_opened_baked_files() {
    use subfield::format::{open_psf, write_psf, Codec, OpenOptions, WriteOptions};
    let Some(dev) = common::gpu::device() else {
        return;
    };
    let mut rng = Rng::new(901);
    let stat = static_scene(&mut rng);
    let psf = Psf::build(
        &stat,
        &PsfParams {
            level: 2,
            tiles: 16,
        },
    )
    .expect("bake");
    let dir = std::env::temp_dir().join(format!("subfield-gpu-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let brute = BruteForce::new(&stat);
    let rs = rays(&mut rng, 1500, &[], &[]);
    let mut want = vec![None; rs.len()];
    brute.intersect_batch(&rs, &mut want);
    let gmov = GpuMoving::new(dev).expect("moving part");
    for codec in [Codec::None, Codec::Zstd] {
        let path = dir.join(format!("{codec:?}.psf"));
        let opts = WriteOptions {
            codec,
            ..Default::default()
        };
        write_psf(&path, &psf, &opts).expect("write");
        let opened = open_psf(&path, &OpenOptions::default()).expect("open").psf;
        let gstat = GpuStatic::upload(dev, &opened).expect("upload");
        let mut got = vec![None; rs.len()];
        GpuTracer::new(dev, &gstat, &gmov)
            .try_intersect_batch(&rs, &mut got)
            .expect("trace");
        for i in 0..rs.len() {
            assert_eq!(
                bits(got[i]),
                bits(want[i]),
                "{codec:?}: ray {i} {:?}",
                rs[i]
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
