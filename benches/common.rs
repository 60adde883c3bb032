//! Scenes and rays shared by the benchmarks (built in code, deterministic).
#![allow(dead_code)]

use glam::Vec3;
use subfield::gen::synth::{self, Rng};
use subfield::Ray;

/// The museum-like room of `n` triangles.
pub fn room(n: usize) -> Vec<[Vec3; 3]> {
    synth::room(&mut Rng::new(42), n)
}

/// Coherent primary rays: a `w × h` pinhole camera inside the room looking across it.
pub fn camera_rays(w: usize, h: usize) -> Vec<Ray> {
    let eye = Vec3::new(0.5, 3.0, -9.5);
    let fwd = Vec3::new(0.05, -0.05, 1.0).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let t = (45f32.to_radians() / 2.0).tan();
    let a = w as f32 / h as f32;
    let mut rays = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let px = (2.0 * (x as f32 + 0.5) / w as f32 - 1.0) * a * t;
            let py = (1.0 - 2.0 * (y as f32 + 0.5) / h as f32) * t;
            rays.push(Ray::new(eye, (fwd + right * px + up * py).normalize()));
        }
    }
    rays
}

/// Incoherent rays: random origins inside the room, random directions.
pub fn random_rays(n: usize) -> Vec<Ray> {
    let mut rng = Rng::new(7);
    (0..n)
        .map(|_| {
            Ray::new(
                rng.in_box(Vec3::new(-9.9, 0.1, -9.9), Vec3::new(9.9, 5.9, 9.9)),
                rng.unit(),
            )
        })
        .collect()
}

/// obvhs' CWBVH over the same triangles, with its own (Möller-Trumbore) triangle test.
pub struct Obvhs {
    pub tris: Vec<obvhs::triangle::Triangle>,
    pub bvh: obvhs::cwbvh::CwBvh,
}

impl Obvhs {
    pub fn build(tris: &[[Vec3; 3]]) -> Obvhs {
        Self::build_with(tris, obvhs::BvhBuildParams::medium_build())
    }

    /// With other build parameters (`fastest_build()` for per-frame rebuilds).
    pub fn build_with(tris: &[[Vec3; 3]], params: obvhs::BvhBuildParams) -> Obvhs {
        let tris: Vec<obvhs::triangle::Triangle> = tris
            .iter()
            .map(|t| obvhs::triangle::Triangle {
                v0: t[0].into(),
                v1: t[1].into(),
                v2: t[2].into(),
            })
            .collect();
        let bvh = obvhs::cwbvh::builder::build_cwbvh_from_tris(
            &tris,
            params,
            &mut std::time::Duration::default(),
        );
        Obvhs { tris, bvh }
    }

    pub fn intersect(&self, r: &Ray) -> Option<(f32, u32)> {
        let ray = obvhs::ray::Ray::new(r.origin.into(), r.dir.into(), r.t_min, r.t_max);
        let mut hit = obvhs::ray::RayHit::none();
        if self.bvh.ray_traverse(ray, &mut hit, |ray, id| {
            self.tris[self.bvh.primitive_indices[id] as usize].intersect(ray)
        }) {
            Some((hit.t, self.bvh.primitive_indices[hit.primitive_id as usize]))
        } else {
            None
        }
    }

    /// Whether anything is hit in `[t_min, t_max]`; stops at the first hit found.
    pub fn occluded(&self, r: &Ray) -> bool {
        let ray = obvhs::ray::Ray::new(r.origin.into(), r.dir.into(), r.t_min, r.t_max);
        !self.bvh.ray_traverse_miss(ray, |ray, id| {
            self.tris[self.bvh.primitive_indices[id] as usize].intersect(ray)
        })
    }
}

/// `n` triangles in unstructured motion inside the room: each on its own path (a
/// Lissajous curve with its own phases and rates), tumbling, about 0.15 units across.
pub fn moving(n: usize, t: f32, out: &mut Vec<[Vec3; 3]>) {
    out.clear();
    let mut rng = Rng::new(0xa11_7a27);
    for _ in 0..n {
        let c = rng.in_box(Vec3::new(-8.0, 0.5, -6.0), Vec3::new(8.0, 5.0, 8.0));
        let amp = rng.in_box(Vec3::splat(0.5), Vec3::new(6.0, 2.0, 6.0));
        let w = rng.in_box(Vec3::splat(0.2), Vec3::splat(1.5));
        let ph = rng.in_box(Vec3::ZERO, Vec3::splat(std::f32::consts::TAU));
        let (a, b, spin) = (rng.unit() * 0.15, rng.unit() * 0.15, rng.range(0.5, 3.0));
        let p = c + amp
            * Vec3::new(
                (w.x * t + ph.x).sin(),
                (w.y * t + ph.y).sin(),
                (w.z * t + ph.z).sin(),
            )
            * 0.5;
        let q = glam::Quat::from_axis_angle(a.cross(b).normalize_or(Vec3::Y), spin * t);
        out.push([p, p + q * a, p + q * b]);
    }
}
