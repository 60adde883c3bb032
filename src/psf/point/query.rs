//! A ray's query through a plan's grids: its tile (one grid's or two, merged by depth)
//! and near lists, scanned near to far with the early exit.

use super::plan::{BatchGrid, Plan};
use super::project::{down, face_coords, up};
use super::types::{PointGrid, StaticGrid};
use crate::geometry::{intersect_pre, Hit, Ray, RayPre};

/// Keeps `hit` in `best` when it is closer; `true` when that answers the query (any
/// hit will do).
#[inline]
fn take<const ANY: bool>(best: &mut Option<Hit>, hit: Hit) -> bool {
    if best.is_none_or(|b| hit.is_closer_than(&b)) {
        *best = Some(hit);
    }
    ANY
}

impl<'a> Plan<'a> {
    /// The ray's hit through these grids, `None` when they do not take it (it does not
    /// qualify, or lands outside them).
    #[inline]
    pub(super) fn query<const ANY: bool>(&self, ray: &Ray) -> Option<Option<Hit>> {
        let (f, p) = self.at.aim(ray)?;
        let f = f as usize;
        if (ray.origin.as_dvec3() - self.at.c).length_squared() > self.at.reach2 {
            return None;
        }
        match (&self.fixed, self.batch.as_deref()) {
            (Some(s), None) => {
                let t = s.grid.faces[f].tile(p)?;
                let test = |pre: &RayPre, g: u32, ray: &Ray, best: &Option<Hit>| {
                    self.test_static(pre, g, ray, best)
                };
                Some(self.trace_one::<ANY>(ray, f, &s.grid, t, test))
            }
            (None, Some(m)) => {
                let t = m.grid.faces[f].tile(p)?;
                let test = |pre: &RayPre, g: u32, ray: &Ray, best: &Option<Hit>| {
                    Self::test_batch(m, pre, g, ray, best)
                };
                Some(self.trace_one::<ANY>(ray, f, &m.grid, t, test))
            }
            (Some(s), Some(m)) => {
                let a = s.grid.faces[f].tile(p)?;
                let b = m.grid.faces[f].tile(p)?;
                Some(self.trace_two::<ANY>(ray, f, s, a, m, b))
            }
            (None, None) => None,
        }
    }

    /// Static triangle `g`'s hit, if closer than `best`.
    #[inline]
    fn test_static(&self, pre: &RayPre, g: u32, ray: &Ray, best: &Option<Hit>) -> Option<Hit> {
        let t_max = best.map_or(ray.t_max, |b| b.t);
        intersect_pre(pre, &self.pre[g as usize], ray.t_min, t_max).map(|(t, u, v)| Hit {
            t,
            tri: g,
            u,
            v,
        })
    }

    /// The hit of triangle `g` of the batch's grid, if closer than `best`.
    #[inline]
    fn test_batch(
        m: &BatchGrid,
        pre: &RayPre,
        g: u32,
        ray: &Ray,
        best: &Option<Hit>,
    ) -> Option<Hit> {
        let t_max = best.map_or(ray.t_max, |b| b.t);
        intersect_pre(pre, &m.tris[g as usize], ray.t_min, t_max).map(|(t, u, v)| Hit {
            t,
            tri: m.number[g as usize],
            u,
            v,
        })
    }

    /// The depth window of a ray on face `f` up to `t_far`, as a function of `t_far`, and
    /// the margin in `t` of the early exit.
    #[inline]
    fn window(&self, ray: &Ray, f: usize) -> (impl Fn(f64) -> (f32, f32), f64) {
        let o = ray.origin.as_dvec3();
        let d = ray.dir.as_dvec3();
        let (_, _, z0) = face_coords(f, o - self.at.c);
        let (_, _, dz) = face_coords(f, d);
        // How far (in t) a computed hit may sit from where the line truly meets its
        // triangle, as in the parallel subfields' early exit.
        let m = self.depth_margin;
        let t_min = ray.t_min as f64;
        let window = move |t_far: f64| {
            let (za, zb) = (z0 + t_min * dz, z0 + t_far * dz);
            (down(za.min(zb) - m), up(za.max(zb) + m))
        };
        (window, m / d.length())
    }

    /// The ray's hit among `grid`'s near list and tile `tile` (tested by `test`),
    /// scanned near to far.
    #[inline]
    fn trace_one<const ANY: bool>(
        &self,
        ray: &Ray,
        f: usize,
        grid: &PointGrid,
        tile: usize,
        test: impl Fn(&RayPre, u32, &Ray, &Option<Hit>) -> Option<Hit>,
    ) -> Option<Hit> {
        // The shear is made only for a ray that tests a triangle: over the moving
        // triangles alone most rays land in an empty tile, or stop before its first
        // entry (`benches/PERF.md`, issue 23, step 12).
        let run = grid.run(tile);
        if grid.near.is_empty() && run.is_empty() {
            return None;
        }
        let mut shear: Option<RayPre> = None;
        let mut best: Option<Hit> = None;
        for &g in &grid.near {
            let pre = shear.get_or_insert_with(|| RayPre::new(ray.origin, ray.dir));
            if let Some(hit) = test(pre, g, ray, &best) {
                if take::<ANY>(&mut best, hit) {
                    return best;
                }
            }
        }
        let (window, slack) = self.window(ray, f);
        let (mut lo, mut hi) = window(best.map_or(ray.t_max as f64, |b| b.t as f64 + slack));
        for e in run {
            if e.zmin > hi {
                break;
            }
            if e.zmax < lo {
                continue;
            }
            let pre = shear.get_or_insert_with(|| RayPre::new(ray.origin, ray.dir));
            if let Some(hit) = test(pre, e.tri, ray, &best) {
                if take::<ANY>(&mut best, hit) {
                    return best;
                }
                (lo, hi) = window(best.map_or(hit.t, |b| b.t) as f64 + slack);
            }
        }
        best
    }

    /// The ray's hit among the near lists and tile `a` of the static grid and `b` of
    /// the batch's, the two tiles' lists merged by depth and scanned near to far: the
    /// scan stops at the first entry beyond the window, whichever list it is in.
    fn trace_two<const ANY: bool>(
        &self,
        ray: &Ray,
        f: usize,
        s: &StaticGrid,
        a: usize,
        m: &BatchGrid,
        b: usize,
    ) -> Option<Hit> {
        let pre = RayPre::new(ray.origin, ray.dir);
        let mut best: Option<Hit> = None;
        let near = s.grid.near.iter().map(|&g| (true, g));
        for (stat, g) in near.chain(m.grid.near.iter().map(|&g| (false, g))) {
            let hit = if stat {
                self.test_static(&pre, g, ray, &best)
            } else {
                Self::test_batch(m, &pre, g, ray, &best)
            };
            if let Some(hit) = hit {
                if take::<ANY>(&mut best, hit) {
                    return best;
                }
            }
        }
        let (window, slack) = self.window(ray, f);
        let (mut lo, mut hi) = window(best.map_or(ray.t_max as f64, |b| b.t as f64 + slack));
        let (ra, rb) = (s.grid.run(a), m.grid.run(b));
        let (mut i, mut j) = (0, 0);
        loop {
            let from_a = match (ra.get(i), rb.get(j)) {
                (Some(x), Some(y)) => x.zmin <= y.zmin,
                (Some(_), None) => true,
                (None, Some(_)) => false,
                (None, None) => break,
            };
            let e = if from_a {
                i += 1;
                &ra[i - 1]
            } else {
                j += 1;
                &rb[j - 1]
            };
            if e.zmin > hi {
                break;
            }
            if e.zmax < lo {
                continue;
            }
            let hit = if from_a {
                self.test_static(&pre, e.tri, ray, &best)
            } else {
                Self::test_batch(m, &pre, e.tri, ray, &best)
            };
            if let Some(hit) = hit {
                if take::<ANY>(&mut best, hit) {
                    return best;
                }
                (lo, hi) = window(best.map_or(hit.t, |b| b.t) as f64 + slack);
            }
        }
        best
    }
}
