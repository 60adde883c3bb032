//! Scenes and frames of moving triangles for the suites that check a tracer against
//! brute force (tests/dynamic_vs_brute.rs on the CPU, tests/gpu_vs_brute.rs on the GPU):
//! a static room, frames whose triangles jump anywhere, leave the bounds, pile into one
//! tile, vanish to zero area or straddle the bounds, clustered frames, and rays through
//! vertices and edges, at triangles from near and far, at last frame's places, shadow
//! segments and rays from far outside.

use glam::Vec3;
use subfield::gen::synth::{self, Rng};
use subfield::geometry::Ray;

pub const LO: Vec3 = Vec3::splat(0.0);
pub const HI: Vec3 = Vec3::splat(8.0);

pub fn static_scene(rng: &mut Rng) -> Vec<[Vec3; 3]> {
    let mut tris = synth::box_faces(LO, HI);
    let n = rng.below(150);
    let size = rng.range(0.1, 3.0);
    tris.extend(synth::soup(rng, n, LO, HI, size));
    if rng.below(2) == 0 {
        tris.extend(synth::sphere(Vec3::splat(4.0), 1.5, 6, 9));
    }
    tris
}

/// One triangle of size about `s` around `c`.
pub fn tri_at(rng: &mut Rng, c: Vec3, s: f32) -> [Vec3; 3] {
    [c + rng.unit() * s, c + rng.unit() * s, c + rng.unit() * s]
}

/// This frame's moving triangles. The count changes from frame to frame too.
pub fn frame_tris(rng: &mut Rng, n: usize) -> (Vec<[Vec3; 3]>, &'static str) {
    let n = if rng.below(3) == 0 {
        rng.below(2 * n + 1)
    } else {
        n
    };
    let far = |rng: &mut Rng| {
        let mut c = rng.in_box(LO, HI);
        c[rng.below(3)] += if rng.below(2) == 0 { 1.0 } else { -1.0 } * rng.range(20.0, 5000.0);
        c
    };
    let mode = rng.below(6);
    let mut out = Vec::with_capacity(n);
    let pile = rng.in_box(LO, HI);
    for _ in 0..n {
        let k = if mode == 5 { rng.below(5) } else { mode };
        let t = match k {
            // jump anywhere inside the static bounds
            0 => {
                let c = rng.in_box(LO - 1.0, HI + 1.0);
                let s = rng.range(0.01, 2.0);
                tri_at(rng, c, s)
            }
            // leave the bounds, far away
            1 => {
                let c = far(rng);
                let s = rng.range(0.1, 20.0);
                tri_at(rng, c, s)
            }
            // pile into one tile
            2 => {
                let c = pile + rng.unit() * 1e-3;
                tri_at(rng, c, 1e-3)
            }
            // vanish to zero area: a point, or a segment
            3 => {
                let a = rng.in_box(LO, HI);
                if rng.below(2) == 0 {
                    [a, a, a]
                } else {
                    let b = rng.in_box(LO, HI);
                    [a, b, a.lerp(b, rng.f32())]
                }
            }
            // straddle the bounds: one vertex far, two inside
            _ => {
                let a = rng.in_box(LO, HI);
                let b = rng.in_box(LO, HI);
                [a, b, far(rng)]
            }
        };
        out.push(t);
    }
    let name = ["jump", "leave", "pile", "vanish", "straddle", "mixed"][mode];
    (out, name)
}

pub fn rays(rng: &mut Rng, n: usize, moving: &[[Vec3; 3]], before: &[[Vec3; 3]]) -> Vec<Ray> {
    let mut out = Vec::with_capacity(n);
    // A point on a triangle (or its centroid region).
    let on = |rng: &mut Rng, t: &[Vec3; 3]| {
        let (a, b) = (rng.f32(), rng.f32());
        let (a, b) = if a + b > 1.0 {
            (1.0 - a, 1.0 - b)
        } else {
            (a, b)
        };
        t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b
    };
    while out.len() < n {
        let inside = rng.in_box(LO, HI);
        let ray = match rng.below(7) {
            // through a vertex or along an edge of a moving triangle: hits on the
            // boundaries between triangles, and in the corners of tiles
            5 if !moving.is_empty() => {
                let t = moving[rng.below(moving.len())];
                let a = rng.below(3);
                let p = if rng.below(2) == 0 {
                    t[a]
                } else {
                    t[a].lerp(t[(a + 1) % 3], rng.f32())
                };
                Ray::new(inside, p - inside)
            }
            0 => Ray::new(inside, rng.unit()),
            // at a moving triangle, from near or far
            1 | 2 if !moving.is_empty() => {
                let k = rng.below(moving.len());
                let p = on(rng, &moving[k]);
                let o = if rng.below(2) == 0 {
                    inside
                } else {
                    p + rng.unit() * rng.range(0.01, 100.0)
                };
                Ray::new(o, p - o)
            }
            // at where a triangle was last frame: a stale entry would answer
            3 if !before.is_empty() => {
                let k = rng.below(before.len());
                let p = on(rng, &before[k]);
                Ray::new(inside, p - inside)
            }
            // a shadow-ray segment
            4 => {
                let p = rng.in_box(LO, HI);
                Ray::segment(inside, p - inside, 0.0, 1.0)
            }
            // from far outside everything, inwards
            _ => {
                let o = Vec3::splat(4.0) + rng.unit() * rng.range(20.0, 10_000.0);
                Ray::new(o, inside - o)
            }
        };
        out.push(ray);
    }
    out
}

/// This frame's moving triangles gathered tightly (issue 23): every triangle in a ball a
/// few of its widths across (the shared generator's clusters), on a thin spherical
/// shell, stacked on one another (each spanning the whole grid, ties between equal
/// copies decided by the triangle number), a ball with a few far outliers (the bounds
/// wide, the triangles small), or a ball of large triangles beside tiny ones.
pub fn clustered_tris(rng: &mut Rng, n: usize) -> (Vec<[Vec3; 3]>, &'static str) {
    let n = if rng.below(4) == 0 {
        1 + rng.below(2 * n + 1)
    } else {
        n
    };
    let mode = rng.below(5);
    let c = rng.in_box(LO + 1.0, HI - 1.0);
    let s = rng.range(0.02, 1.0);
    let mut out = Vec::with_capacity(n);
    let base = tri_at(rng, c, s);
    for k in 0..n {
        let t = match mode {
            // a ball 2-5 triangle widths across
            0 => {
                let r = s * rng.range(1.0, 2.5);
                let p = c + rng.unit() * r * rng.f32().cbrt();
                tri_at(rng, p, s)
            }
            // a thin shell: triangles tangent-ish to a sphere of a few widths
            1 => {
                let r = s * rng.range(1.5, 3.0);
                let u = rng.unit();
                let p = c + u * r;
                let (a, b) = u.any_orthonormal_pair();
                let w = s * rng.range(0.5, 1.0);
                [
                    p + a * w,
                    p - a * w * 0.5 + b * w,
                    p - a * w * 0.5 - b * w + u * 1e-4,
                ]
            }
            // stacked: copies of one triangle, some exact, some a hair apart
            2 => {
                if rng.below(2) == 0 {
                    base
                } else {
                    base.map(|v| v + rng.unit() * 1e-5)
                }
            }
            // a ball with a few far outliers
            3 => {
                if k % 97 == 1 {
                    let mut p = c;
                    p[rng.below(3)] += rng.range(20.0, 2000.0);
                    tri_at(rng, p, s)
                } else {
                    let p = c + rng.unit() * s * 2.0 * rng.f32();
                    tri_at(rng, p, s)
                }
            }
            // a ball of mixed sizes: large triangles among tiny ones
            _ => {
                let p = c + rng.unit() * s * 2.0 * rng.f32();
                let size = if rng.below(3) == 0 { s * 3.0 } else { s * 0.02 };
                tri_at(rng, p, size)
            }
        };
        out.push(t);
    }
    let name = ["ball", "shell", "stacked", "ball+outliers", "mixed sizes"][mode];
    (out, name)
}
