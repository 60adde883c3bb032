use glam::Vec3;

use super::{intersect_triangle, Hit, Intersector, Ray, RayPre};

/// Tests every triangle for every ray. The reference the other structures are checked
/// against, and the floor the benchmarks measure from.
pub struct BruteForce<'a> {
    tris: &'a [[Vec3; 3]],
}

impl<'a> BruteForce<'a> {
    pub fn new(tris: &'a [[Vec3; 3]]) -> Self {
        BruteForce { tris }
    }
}

impl Intersector for BruteForce<'_> {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let pre = RayPre::new(ray.origin, ray.dir);
        let mut best: Option<Hit> = None;
        for (i, tri) in self.tris.iter().enumerate() {
            let t_max = best.map_or(ray.t_max, |b| b.t);
            if let Some((t, u, v)) = intersect_triangle(&pre, tri, ray.t_min, t_max) {
                let h = Hit {
                    t,
                    tri: i as u32,
                    u,
                    v,
                };
                // Ascending index order: an equal t never replaces an earlier triangle.
                if best.is_none_or(|b| h.is_closer_than(&b)) {
                    best = Some(h);
                }
            }
        }
        best
    }

    fn occluded(&self, ray: &Ray) -> bool {
        if !ray.is_valid() {
            return false;
        }
        let pre = RayPre::new(ray.origin, ray.dir);
        self.tris
            .iter()
            .any(|tri| intersect_triangle(&pre, tri, ray.t_min, ray.t_max).is_some())
    }
}
