//! A ray's query through a plan's grids: its tile (one grid's or two, merged by depth)
//! and near lists, scanned near to far with the early exit.

use super::plan::{BatchGrid, Plan};
use super::project::face_coords;
use super::types::{PointGrid, StaticGrid};
use crate::geometry::{intersect_pre, intersect_pre4, Hit, Ray, RayPre, TriPre};

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
                Some(self.trace_one::<ANY>(ray, f, &s.grid, t, &self.pre, |g| g))
            }
            (None, Some(m)) => {
                let t = m.grid.faces[f].tile(p)?;
                let number = |g: u32| m.number[g as usize];
                Some(self.trace_one::<ANY>(ray, f, &m.grid, t, &m.tris, number))
            }
            (Some(s), Some(m)) => {
                let a = s.grid.faces[f].tile(p)?;
                let b = m.grid.faces[f].tile(p)?;
                Some(self.trace_two::<ANY>(ray, f, s, a, m, b))
            }
            (None, None) => None,
        }
    }

    /// The depth window of a ray on face `f` up to `t_far`, as a function of `t_far`, and
    /// the margin in `t` of the early exit. The window stays in `f64`, and an entry's
    /// `f32` depths are compared with it exactly (an `f32` is an `f64`): rounding the
    /// window outwards to `f32` instead cost a query more than the two conversions an
    /// entry now takes.
    #[inline]
    fn window(&self, ray: &Ray, f: usize) -> (impl Fn(f64) -> (f64, f64), f64) {
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
            (za.min(zb) - m, za.max(zb) + m)
        };
        (window, m / d.length())
    }

    /// The ray's hit among `grid`'s near list and tile `tile`, scanned near to far, the
    /// candidates tested four at a time ([`Group`]); `tris` holds the grid's triangles
    /// and `number` gives the hit number of each.
    #[inline]
    fn trace_one<const ANY: bool>(
        &self,
        ray: &Ray,
        f: usize,
        grid: &PointGrid,
        tile: usize,
        tris: &[TriPre],
        number: impl Fn(u32) -> u32,
    ) -> Option<Hit> {
        // The shear is made only for a ray that tests a triangle: over the moving
        // triangles alone most rays land in an empty tile, or stop before its first
        // entry (`benches/PERF.md`, issue 23, step 12).
        let run = grid.run(tile);
        if grid.near.is_empty() && run.is_empty() {
            return None;
        }
        let mut shear: Option<RayPre> = None;
        let new = || RayPre::new(ray.origin, ray.dir);
        let mut best: Option<Hit> = None;
        let mut group = Group::default();
        for &g in &grid.near {
            if group.push(&tris[g as usize], number(g))
                && group
                    .test::<ANY>(shear.get_or_insert_with(new), ray, &mut best)
                    .0
            {
                return best;
            }
        }
        if group.n > 0
            && group
                .test::<ANY>(shear.get_or_insert_with(new), ray, &mut best)
                .0
        {
            return best;
        }
        let (window, slack) = self.window(ray, f);
        let (mut lo, mut hi) = window(best.map_or(ray.t_max as f64, |b| b.t as f64 + slack));
        for e in run {
            if f64::from(e.zmin) > hi {
                break;
            }
            if f64::from(e.zmax) < lo {
                continue;
            }
            if group.push(&tris[e.tri as usize], number(e.tri)) {
                let (answered, met) =
                    group.test::<ANY>(shear.get_or_insert_with(new), ray, &mut best);
                if answered {
                    return best;
                }
                if let (true, Some(b)) = (met, best) {
                    (lo, hi) = window(b.t as f64 + slack);
                }
            }
        }
        if group.n > 0 {
            group.test::<ANY>(shear.get_or_insert_with(new), ray, &mut best);
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
        let mut group = Group::default();
        // Triangle `g` of the static grid (`stat`) or of the batch's, and its number.
        let tri = |stat: bool, g: u32| {
            if stat {
                (&self.pre[g as usize], g)
            } else {
                (&m.tris[g as usize], m.number[g as usize])
            }
        };
        let near = s.grid.near.iter().map(|&g| (true, g));
        for (stat, g) in near.chain(m.grid.near.iter().map(|&g| (false, g))) {
            let (t, number) = tri(stat, g);
            if group.push(t, number) && group.test::<ANY>(&pre, ray, &mut best).0 {
                return best;
            }
        }
        if group.n > 0 && group.test::<ANY>(&pre, ray, &mut best).0 {
            return best;
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
            if f64::from(e.zmin) > hi {
                break;
            }
            if f64::from(e.zmax) < lo {
                continue;
            }
            let (t, number) = tri(from_a, e.tri);
            if group.push(t, number) {
                let (answered, met) = group.test::<ANY>(&pre, ray, &mut best);
                if answered {
                    return best;
                }
                if let (true, Some(b)) = (met, best) {
                    (lo, hi) = window(b.t as f64 + slack);
                }
            }
        }
        if group.n > 0 {
            group.test::<ANY>(&pre, ray, &mut best);
        }
        best
    }
}

/// Up to four candidates waiting for their test, with the hit number each reports: a
/// scan tests its candidates four at a time ([`intersect_pre4`]), one branch for four
/// where a test each had one, about as often taken as not. A group part full (a scan's
/// last few) is tested one at a time.
///
/// The hits are those of testing one at a time. The closest hit is the least by
/// [`Hit::is_closer_than`], a total order, whichever order the candidates are tested
/// in. A group may test up to three candidates that a scan one at a time would have
/// passed over, once a hit had narrowed its depth window: no such triangle is met
/// closer than that hit (the early exit's argument), so they change nothing. An
/// any-hit query is answered by any hit of the group: every caller asks only whether
/// there is one.
pub(crate) struct Group<'t> {
    tris: [&'t TriPre; 4],
    number: [u32; 4],
    pub(crate) n: usize,
}

impl Default for Group<'_> {
    fn default() -> Self {
        Group {
            tris: [&TriPre::NONE; 4],
            number: [0; 4],
            n: 0,
        }
    }
}

impl<'t> Group<'t> {
    /// Adds a candidate; `true` when the group is full.
    #[inline(always)]
    pub(crate) fn push(&mut self, tri: &'t TriPre, number: u32) -> bool {
        // `n < 4` here (a full group is tested and emptied at once); the mask tells
        // the compiler so.
        let k = self.n & 3;
        self.tris[k] = tri;
        self.number[k] = number;
        self.n = k + 1;
        self.n == 4
    }

    /// Tests the candidates, keeping the closest hit in `best` (any hit for `ANY`), and
    /// empties the group: (whether an any-hit query is answered, whether a triangle
    /// was met).
    #[inline(always)]
    pub(crate) fn test<const ANY: bool>(
        &mut self,
        pre: &RayPre,
        ray: &Ray,
        best: &mut Option<Hit>,
    ) -> (bool, bool) {
        let t_max = best.map_or(ray.t_max, |b| b.t);
        let (mut answered, mut met) = (false, false);
        let number = self.number;
        let mut keep = |best: &mut Option<Hit>, k: usize, (t, u, v): (f32, f32, f32)| {
            met = true;
            let hit = Hit {
                t,
                tri: number[k],
                u,
                v,
            };
            answered |= take::<ANY>(best, hit);
        };
        if self.n == 4 {
            intersect_pre4(pre, self.tris, ray.t_min, t_max, |k, h| keep(best, k, h));
        } else {
            // One at a time: a scan's last few (a group part full costs more than its
            // tests). Any-hit queries are grouped too since the still camera's samples
            // settle (its frames had traced 10 % slower grouped, round 10; now the
            // same, and the dolly's shadow rays 4.5 ms a frame faster: benches/PERF.md,
            // issue 38, round 12).
            for k in 0..self.n.min(4) {
                let t_max = best.map_or(ray.t_max, |b| b.t);
                if let Some(h) = intersect_pre(pre, self.tris[k], ray.t_min, t_max) {
                    keep(best, k, h);
                    if ANY {
                        break;
                    }
                }
            }
        }
        self.n = 0;
        (answered, met)
    }
}
