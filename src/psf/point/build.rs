//! The grid build: each triangle clipped and projected into rectangles of tiles face by
//! face, the rectangles sorted by depth, then counted and written tile by tile in parallel.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::project::{down, face_coords, up, EPS_P};
use super::types::{by_tiles, Around, Face, Item, PEntry, PointGrid, Rects, CHUNK, NEAR};

/// Rays per tile the grid aims at: smaller tiles shorten the lists a ray scans and
/// lengthen the build (a large triangle is listed in more tiles).
pub(super) const RAYS_PER_TILE: usize = 16;

/// `items` sorted by `zmin`, ties in their order (a stable radix sort, 11 bits a pass,
/// a pass skipped where every key has the same digit). Depths are positive (at least
/// `r / 2`), so their bits order them; items come in triangle order, so ties go to the
/// earlier triangle and a grid depends on its input alone. Two or three passes over a
/// few thousand items cost less than a comparison sort of them (`benches/PERF.md`,
/// step 82).
pub(super) fn by_depth(mut items: Vec<Item>) -> Vec<Item> {
    let mut spare = vec![Item::default(); items.len()];
    for shift in [0, 11, 22] {
        let digit = |it: &Item| ((it.zmin.to_bits() >> shift) & 0x7ff) as usize;
        let mut at = [0u32; 2048];
        for it in &items {
            at[digit(it)] += 1;
        }
        if items
            .first()
            .is_none_or(|it| at[digit(it)] as usize == items.len())
        {
            continue;
        }
        let mut sum = 0;
        for a in at.iter_mut() {
            (*a, sum) = (sum, sum + *a);
        }
        for it in &items {
            let k = &mut at[digit(it)];
            spare[*k as usize] = *it;
            *k += 1;
        }
        std::mem::swap(&mut items, &mut spare);
    }
    items
}

impl PointGrid {
    /// The grid around `at.c` over `count` triangles (`tri(g)`, numbered `g`) for rays
    /// that qualify by `at` and project into `rects`; `None` when it would list too
    /// many entries.
    pub(super) fn build(
        at: &Around,
        rects: &Rects,
        count: usize,
        tri: impl Fn(usize) -> [Vec3; 3] + Sync,
        min_tiles: usize,
    ) -> Option<PointGrid> {
        let (faces, total) = Self::faces_for(rects, min_tiles);
        let rays: u64 = rects.iter().map(|b| b.4 as u64).sum();
        Self::build_on(at, faces, total, rays, count, tri)
    }

    /// The tiling of the faces for rays that project into `rects`: a tile for about
    /// [`RAYS_PER_TILE`] of them, at least `min_tiles` a face used; and the tiles in all.
    pub(super) fn faces_for(rects: &Rects, min_tiles: usize) -> ([Face; 6], usize) {
        let mut faces = [Face::default(); 6];
        let mut total = 0;
        for (face, &(u0, v0, u1, v1, n)) in faces.iter_mut().zip(rects) {
            if n == 0 {
                continue;
            }
            let (w, h) = (u1 - u0, v1 - v0);
            let tiles = (n / RAYS_PER_TILE).max(min_tiles).max(1) as f64;
            let side = (w * h / tiles).sqrt().max(w.max(h) / 4096.0).max(1e-12);
            let (nu, nv) = (
                ((w / side).ceil() as usize).clamp(1, 4096),
                ((h / side).ceil() as usize).clamp(1, 4096),
            );
            *face = Face {
                u0,
                v0,
                inv: 1.0 / side,
                nu,
                nv,
                first: total,
            };
            total += nu * nv;
        }
        (faces, total)
    }

    /// The grid over `count` triangles on the tiling `faces` (`total` tiles), for some
    /// `rays` rays; `None` when it would list too many entries.
    pub(super) fn build_on(
        at: &Around,
        faces: [Face; 6],
        total: usize,
        rays: u64,
        count: usize,
        tri: impl Fn(usize) -> [Vec3; 3] + Sync,
    ) -> Option<PointGrid> {
        // Each triangle's rectangles of tiles, face by face, in triangle order.
        let items_of = Self::lister(at, &faces, tri);
        let (items, near) = Self::gather(count, items_of);
        if Self::too_many(&items, rays, count) {
            return None;
        }
        // Near to far within every tile: the entries are written in order of depth.
        let items = by_depth(items);
        let (starts, entries) = Self::fill(&faces, total, &items);
        Some(PointGrid {
            faces,
            starts,
            entries,
            near,
        })
    }

    /// What triangle `g` (`tri(g)`) is listed as, pushed onto `out`: the near list when its
    /// box meets the near cube, else, face by face, the rectangle of tiles its part beyond
    /// `r / 2`, projected and grown by `eps`, meets, with that part's depth range (see the
    /// module's notes).
    fn lister<'t>(
        at: &Around,
        faces: &'t [Face; 6],
        tri: impl Fn(usize) -> [Vec3; 3] + Sync + 't,
    ) -> impl Fn(usize, &mut Vec<Item>) + Sync + 't {
        let (c, r) = (at.c, at.r);
        let allowance = at.allowance();
        let h = 0.5 * r;
        // The most any `eps` below can be: its clipped part's least depth is at least `h`.
        let eps_max = 4.0 * allowance / h + EPS_P;
        let beyond = faces.map(|f| {
            [
                f.u0 - eps_max,
                f.v0 - eps_max,
                f.u0 + f.nu as f64 / f.inv + eps_max,
                f.v0 + f.nv as f64 / f.inv + eps_max,
            ]
        });
        move |g: usize, out: &mut Vec<Item>| {
            let q = tri(g).map(|v| v.as_dvec3() - c);
            let lo = q[0].min(q[1]).min(q[2]);
            let hi = q[0].max(q[1]).max(q[2]);
            if lo.cmple(DVec3::splat(r)).all() && hi.cmpge(DVec3::splat(-r)).all() {
                out.push(Item {
                    face: NEAR,
                    i0: 0,
                    i1: 0,
                    j0: 0,
                    j1: 0,
                    zmin: 0.0,
                    zmax: 0.0,
                    tri: g as u32,
                });
                return;
            }
            for (f, face) in faces.iter().enumerate() {
                if face.nu == 0 {
                    continue;
                }
                let p = q.map(|x| face_coords(f, x));
                if p.iter().all(|x| x.2 < h) {
                    continue;
                }
                // Wholly beyond one side of the face's grid grown by `eps_max`: every
                // point of the triangle with `z > 0` projects further out than the
                // grown rectangle below could reach (`u > k z` is a half-space through
                // `c`, and the clipped corners lie in it), so nothing is listed and no
                // corner need be projected.
                let [ku0, kv0, ku1, kv1] = beyond[f];
                if p.iter().all(|x| x.0 > ku1 * x.2)
                    || p.iter().all(|x| x.0 < ku0 * x.2)
                    || p.iter().all(|x| x.1 > kv1 * x.2)
                    || p.iter().all(|x| x.1 < kv0 * x.2)
                {
                    continue;
                }
                // Clip to z >= h (at most four corners), project, bound.
                let (mut pu0, mut pv0, mut pu1, mut pv1) = (
                    f64::INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::NEG_INFINITY,
                );
                let (mut z0, mut z1) = (f64::INFINITY, f64::NEG_INFINITY);
                let mut add = |(u, v, z): (f64, f64, f64)| {
                    // One division a corner: the product differs from `u / z` by an
                    // ulp of f64, far inside `eps`.
                    let inv = 1.0 / z;
                    let (pu, pv) = (u * inv, v * inv);
                    pu0 = pu0.min(pu);
                    pv0 = pv0.min(pv);
                    pu1 = pu1.max(pu);
                    pv1 = pv1.max(pv);
                    z0 = z0.min(z);
                    z1 = z1.max(z);
                };
                for j in 0..3 {
                    let (a, b) = (p[j], p[(j + 1) % 3]);
                    if a.2 >= h {
                        add(a);
                    }
                    if (a.2 >= h) != (b.2 >= h) {
                        let t = (h - a.2) / (b.2 - a.2);
                        add((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1), h));
                    }
                }
                let eps = 4.0 * allowance / z0 + EPS_P;
                let (a0, a1) = (
                    (pu0 - eps - face.u0) * face.inv,
                    (pu1 + eps - face.u0) * face.inv,
                );
                let (b0, b1) = (
                    (pv0 - eps - face.v0) * face.inv,
                    (pv1 + eps - face.v0) * face.inv,
                );
                // NaN (a degenerate projection) fails these and lists nothing, so a
                // triangle with a non-finite corner never gets here: the layers reject
                // those.
                if !(a1 >= 0.0 && b1 >= 0.0 && a0 < face.nu as f64 && b0 < face.nv as f64) {
                    continue;
                }
                out.push(Item {
                    face: f as u8,
                    i0: a0.max(0.0) as u32,
                    i1: (a1 as usize).min(face.nu - 1) as u32,
                    j0: b0.max(0.0) as u32,
                    j1: (b1 as usize).min(face.nv - 1) as u32,
                    zmin: down(z0),
                    zmax: up(z1),
                    tri: g as u32,
                });
            }
        }
    }

    /// The items of triangles `0..count` in triangle order (listed in parallel, a chunk a
    /// task), and the near list apart.
    fn gather(
        count: usize,
        items_of: impl Fn(usize, &mut Vec<Item>) + Sync,
    ) -> (Vec<Item>, Vec<u32>) {
        let chunks: Vec<Vec<Item>> = (0..count.div_ceil(CHUNK))
            .into_par_iter()
            .map(|k| {
                let range = k * CHUNK..((k + 1) * CHUNK).min(count);
                let mut out = Vec::with_capacity(2 * range.len());
                for g in range {
                    items_of(g, &mut out);
                }
                out
            })
            .collect();
        let mut items = chunks.concat();
        let near: Vec<u32> = items
            .iter()
            .filter(|i| i.face == NEAR)
            .map(|i| i.tri)
            .collect();
        items.retain(|i| i.face != NEAR);
        (items, near)
    }

    /// Whether `items` list too many entries for a grid over `count` triangles for some
    /// `rays` rays.
    fn too_many(items: &[Item], rays: u64, count: usize) -> bool {
        // A scene whose triangles each cover much of the view would list too many
        // entries: the parallel subfields take such a batch.
        let listed: u64 = items
            .iter()
            .map(|i| (i.i1 - i.i0 + 1) as u64 * (i.j1 - i.j0 + 1) as u64)
            .sum();
        // Entries are counted in u32: a grid of more is not built either.
        listed > 32 * rays + 8 * count as u64 || listed >= u32::MAX as u64
    }

    /// The tiles' lists (`starts` over `total` tiles, and the entries) of `items`, sorted
    /// by depth, on the tiling `faces`.
    fn fill(faces: &[Face; 6], total: usize, items: &[Item]) -> (Vec<u32>, Vec<PEntry>) {
        // Tiles in ranges, one job a range: each goes through all the items in order
        // and counts (then writes) the entries of its own tiles.
        let jobs = (2 * rayon::current_num_threads()).clamp(1, total.max(1));
        let cut = |k: usize| k * total / jobs;
        let each_tile = |lo: usize, hi: usize, visit: &mut dyn FnMut(usize, &Item)| {
            for it in items {
                let face = &faces[it.face as usize];
                let first = face.first + it.j0 as usize * face.nu + it.i0 as usize;
                let last = face.first + it.j1 as usize * face.nu + it.i1 as usize;
                if last < lo || first >= hi {
                    continue;
                }
                for j in it.j0 as usize..=it.j1 as usize {
                    let row = face.first + j * face.nu;
                    let a = (row + it.i0 as usize).max(lo);
                    let b = (row + it.i1 as usize + 1).min(hi);
                    for t in a..b {
                        visit(t, it);
                    }
                }
            }
        };
        let mut starts = vec![0u32; total + 1];
        {
            let mut parts: Vec<(usize, &mut [u32])> = Vec::with_capacity(jobs);
            let mut rest = &mut starts[1..];
            for k in 0..jobs {
                let (head, tail) = rest.split_at_mut(cut(k + 1) - cut(k));
                parts.push((cut(k), head));
                rest = tail;
            }
            parts.into_par_iter().for_each(|(lo, counts)| {
                let hi = lo + counts.len();
                each_tile(lo, hi, &mut |t, _| counts[t - lo] += 1);
            });
        }
        for k in 0..total {
            starts[k + 1] += starts[k];
        }
        let mut entries = vec![PEntry::default(); starts[total] as usize];
        {
            let parts = by_tiles(&starts, &mut entries, jobs);
            let starts = &starts;
            parts.into_par_iter().for_each(|(lo, hi, out)| {
                let base = starts[lo] as usize;
                let mut cursor: Vec<u32> = starts[lo..hi].to_vec();
                each_tile(lo, hi, &mut |t, it| {
                    let k = &mut cursor[t - lo];
                    out[*k as usize - base] = PEntry {
                        zmin: it.zmin,
                        zmax: it.zmax,
                        tri: it.tri,
                    };
                    *k += 1;
                });
            });
        }
        (starts, entries)
    }
}
