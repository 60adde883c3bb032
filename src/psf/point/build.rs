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
        // Tiles in ranges, one job a range: each goes through the items that reach its
        // tiles, in order, and counts (then writes) the entries of its own tiles. Which
        // items reach which ranges is one serial pass; each job had gone through every
        // item, so the count and write passes took as long at any thread count (0.9 ms
        // for the 16,384 moving triangles around a light, at 1 and 2 threads;
        // `benches/PERF.md`, issue 38, round 6).
        let jobs = (2 * rayon::current_num_threads()).clamp(1, total.max(1));
        let cut = |k: usize| k * total / jobs;
        let cuts: Vec<usize> = (0..=jobs).map(cut).collect();
        // The range holding tile `t`: the last `k` with `cut(k) <= t`.
        let job_of = |t: usize| cuts.partition_point(|&c| c <= t) - 1;
        let span = |it: &Item| {
            let face = &faces[it.face as usize];
            let first = face.first + it.j0 as usize * face.nu + it.i0 as usize;
            let last = face.first + it.j1 as usize * face.nu + it.i1 as usize;
            (first, last)
        };
        let mut reach: Vec<Vec<u32>> = vec![Vec::new(); jobs];
        for (i, it) in items.iter().enumerate() {
            let (first, last) = span(it);
            for r in &mut reach[job_of(first)..=job_of(last)] {
                r.push(i as u32);
            }
        }
        // The row spans `a..b` of range `k`'s tiles that each item reaching it covers,
        // in the items' order (empty, `a >= b`, where the row's part lies outside it).
        let each_span = |k: usize, visit: &mut dyn FnMut(usize, usize, &Item)| {
            let (lo, hi) = (cut(k), cut(k + 1));
            for &i in &reach[k] {
                let it = &items[i as usize];
                let face = &faces[it.face as usize];
                for j in it.j0 as usize..=it.j1 as usize {
                    let row = face.first + j * face.nu;
                    let a = (row + it.i0 as usize).max(lo);
                    let b = (row + it.i1 as usize + 1).min(hi);
                    visit(a, b, it);
                }
            }
        };
        let mut starts = vec![0u32; total + 1];
        {
            let mut parts: Vec<(usize, &mut [u32])> = Vec::with_capacity(jobs);
            let mut rest = &mut starts[1..];
            for k in 0..jobs {
                let (head, tail) = rest.split_at_mut(cut(k + 1) - cut(k));
                parts.push((k, head));
                rest = tail;
            }
            // Each range's counts from a difference array: one add at the start and one
            // subtract past the end of each row span of its tiles an item covers, then a
            // running sum; the spans' lengths vary from item to item, and a loop over
            // each span's tiles ended on a mispredicted branch about once a span
            // (`benches/PERF.md`, issue 38, round 21).
            parts.into_par_iter().for_each(|(k, counts)| {
                let lo = cut(k);
                let mut diff = vec![0i32; counts.len() + 1];
                each_span(k, &mut |a, b, _| {
                    if a < b {
                        diff[a - lo] += 1;
                        diff[b - lo] -= 1;
                    }
                });
                let mut run = 0i32;
                for (c, d) in counts.iter_mut().zip(&diff) {
                    run += d;
                    *c = run as u32;
                }
            });
        }
        for k in 0..total {
            starts[k + 1] += starts[k];
        }
        let mut entries = vec![PEntry::default(); starts[total] as usize];
        {
            let parts = by_tiles(&starts, &mut entries, jobs);
            let starts = &starts;
            parts
                .into_par_iter()
                .enumerate()
                .for_each(|(k, (lo, hi, out))| {
                    let base = starts[lo] as usize;
                    let mut cursor: Vec<u32> = starts[lo..hi].to_vec();
                    each_span(k, &mut |a, b, it| {
                        for t in a..b {
                            let c = &mut cursor[t - lo];
                            out[*c as usize - base] = PEntry {
                                zmin: it.zmin,
                                zmax: it.zmax,
                                tri: it.tri,
                            };
                            *c += 1;
                        }
                    });
                });
        }
        (starts, entries)
    }
}

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};

    use super::super::types::{Around, PointGrid, NO_RECT};
    use super::by_depth;
    use crate::gen::synth::Rng;

    /// The tiles' lists `fill` writes, whatever the number of jobs (twice the pool's
    /// threads), are those of one serial pass that lists each item, in depth order, in
    /// every tile of its rectangle: the jobs' ranges of tiles split the items that
    /// reach several of them, and no entry is lost or doubled at a range's edge.
    #[test]
    fn tiles_are_filled_as_one_serial_pass_fills_them_at_any_job_count() {
        let mut rng = Rng::new(41);
        let at = Around {
            c: DVec3::new(0.2, -0.4, 0.3),
            r: 0.05,
            rho_max: 1e-4,
            reach2: 4.0,
            margin: 1e-4,
        };
        let tris: Vec<[Vec3; 3]> = (0..900)
            .map(|k| {
                let a = rng.in_box(Vec3::splat(-6.0), Vec3::splat(6.0));
                // Some large triangles, which span many tiles and several ranges.
                let size = if k % 30 == 0 { 8.0 } else { 0.05 + rng.f32() };
                [a, a + size * rng.unit(), a + size * rng.unit()]
            })
            .collect();
        let mut rects = [NO_RECT; 6];
        rects[0] = (-0.9, -0.7, 0.8, 0.9, 5000);
        rects[3] = (-1.0, -1.0, 1.0, 1.0, 3000);
        rects[4] = (-0.3, -0.2, 0.4, 0.5, 700);
        let (faces, total) = PointGrid::faces_for(&rects, 0);
        let items_of = PointGrid::lister(&at, &faces, |g| tris[g]);
        let (items, _) = PointGrid::gather(tris.len(), items_of);
        let items = by_depth(items);
        // The serial pass.
        let mut lists: Vec<Vec<(u32, u32, u32)>> = vec![Vec::new(); total];
        for it in &items {
            let face = &faces[it.face as usize];
            for j in it.j0 as usize..=it.j1 as usize {
                for i in it.i0 as usize..=it.i1 as usize {
                    let t = face.first + j * face.nu + i;
                    lists[t].push((it.zmin.to_bits(), it.zmax.to_bits(), it.tri));
                }
            }
        }
        let spanning = items
            .iter()
            .filter(|it| it.i1 > it.i0 + 2 && it.j1 > it.j0 + 2)
            .count();
        assert!(
            total > 200 && spanning > 10,
            "{total} tiles, {spanning} large items"
        );
        for threads in [1, 2, 3, 5, 16] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let (starts, entries) = pool.install(|| PointGrid::fill(&faces, total, &items));
            assert_eq!(starts.len(), total + 1);
            for (t, want) in lists.iter().enumerate() {
                let got: Vec<(u32, u32, u32)> = entries[starts[t] as usize..starts[t + 1] as usize]
                    .iter()
                    .map(|e| (e.zmin.to_bits(), e.zmax.to_bits(), e.tri))
                    .collect();
                assert_eq!(&got, want, "tile {t}, {threads} threads");
            }
        }
    }
}
