//! Scenes and rays shared by the benchmarks (built in code, deterministic).
#![allow(dead_code)]

use glam::Vec3;
use subfield::synth::{self, Rng};
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
            obvhs::BvhBuildParams::medium_build(),
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
}
