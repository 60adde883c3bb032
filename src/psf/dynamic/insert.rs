//! Insertion of a frame's triangles into one direction's grid: the first pass (each
//! triangle's rectangle of tiles, the entries counted per tile, densely or tile by tile)
//! and the second (the entries written into their runs).

use glam::Vec3;

use super::tiles::{DynSubfield, Rect, Slot};
use crate::geometry::Aabb;
use crate::psf::bsp::LANES;
use crate::psf::{Entry, GridFrame};

/// Triangles spanning at most this many tiles are listed in each with their whole depth
/// range, unclipped. `cargo bench --bench dynamic -- update` (16,384 moving triangles,
/// level 1, 128 tiles, 2 cores): 21.5 ms per update with exact clipping everywhere, 8.5
/// ms with a limit of 4 tiles. On the museum (`cargo bench --bench embree`, 160x120, every
/// 30th frame), where gathered shapes make triangles span many small tiles, a limit of 4
/// left frames at 18-27 ms; 16 keeps them under about 10 ms, tracing no slower.
pub(super) const COARSE: u32 = 16;

/// The first pass's counting of entries per tile (see [`DynSubfield::insert`]): a
/// method forced inline rather than a closure, which its two callers had kept out of
/// line (a call for every triangle).
struct Counts<'a> {
    dense: bool,
    nu: usize,
    gv: u32,
    /// The difference array, `(nu + 1) × (nv + 1)`, when dense.
    diff: &'a mut [i32],
    slots: &'a mut [Slot],
    touched: &'a mut Vec<u32>,
}

impl Counts<'_> {
    /// One entry more in every tile of columns `i0..=i1` and rows `j0..=j1`.
    #[inline(always)]
    fn add(&mut self, i0: u32, i1: u32, j0: u32, j1: u32) {
        let (i0, i1, j0, j1) = (i0 as usize, i1 as usize, j0 as usize, j1 as usize);
        if self.dense {
            let stride = self.nu + 1;
            let (a, b) = (j0 * stride, (j1 + 1) * stride);
            self.diff[a + i0] += 1;
            self.diff[a + i1 + 1] -= 1;
            self.diff[b + i0] -= 1;
            self.diff[b + i1 + 1] += 1;
            return;
        }
        for j in j0..=j1 {
            for i in i0..=i1 {
                let tile = j * self.nu + i;
                let slot = &mut self.slots[tile];
                if slot.version != self.gv {
                    *slot = Slot {
                        version: self.gv,
                        start: 0,
                        count: 0,
                    };
                    self.touched.push(tile as u32);
                }
                slot.count += 1;
            }
        }
    }
}

impl DynSubfield {
    /// The first pass of an insertion of this frame's triangles (generation `gv`), in
    /// their input order: each triangle's rectangle of tiles, and the entries per tile
    /// counted. A triangle spanning more than `COARSE` tiles is clipped tile by tile
    /// here and its entries kept for [`write`](Self::write), the second pass.
    ///
    /// Counting is dense where [`dense_counts`] says so (or `dense`, in tests): a
    /// rectangle is counted by its four corners in a difference array, and the counts
    /// come from its prefix sums, runs in tile order; no loop over the rectangle's tiles
    /// and none of their branches. Otherwise each tile is counted and stamped on first
    /// touch, runs in that order, so that time follows the entries, never the grid. The
    /// buffers are reused.
    pub(super) fn count(
        &mut self,
        tris: &[[Vec3; 3]],
        gv: u32,
        margin: f32,
        clip: &Aabb,
        tiles: u32,
        dense: Option<bool>,
    ) {
        self.frame = GridFrame::new(self.dir, clip, tiles);
        let frame = &self.frame;
        let dense = dense.unwrap_or_else(|| dense_counts(frame, tris.len()));
        self.dense = dense;
        let (nu, nv) = (frame.nu as usize, frame.nv as usize);
        let stride = nu + 1;
        let (slots, diff, touched) = (&mut self.slots, &mut self.diff, &mut self.touched);
        let (rects, raw) = (&mut self.rects, &mut self.raw);
        rects.clear();
        raw.clear();
        touched.clear();
        diff.clear();
        if dense {
            diff.resize(stride * (nv + 1), 0);
        }
        let mut counts = Counts {
            dense,
            nu,
            gv,
            diff,
            slots,
            touched,
        };
        for t in tris {
            match frame.coarse_footprint(t, margin, COARSE) {
                Some(f) => {
                    counts.add(f.i0, f.i1, f.j0, f.j1);
                    // Tile indices are below `PsfParams::MAX_TILES` (4096): they fit.
                    rects.push(Rect {
                        i0: f.i0 as u16,
                        i1: f.i1 as u16,
                        j0: f.j0 as u16,
                        j1: f.j1 as u16,
                        lo: f.zmin.to_bits(),
                        hi: f.zmax.to_bits(),
                    });
                }
                None => {
                    let from = raw.len() as u32;
                    frame.raster_with(t, margin, COARSE, |tile, zmin, zmax| {
                        let (i, j) = (tile % nu as u32, tile / nu as u32);
                        counts.add(i, i, j, j);
                        raw.push((tile, zmin, zmax));
                    });
                    rects.push(Rect {
                        i0: Rect::CLIPPED,
                        lo: from,
                        hi: raw.len() as u32,
                        ..Rect::default()
                    });
                }
            }
        }
    }

    /// The second pass, after [`count`](Self::count): places each tile's run, then writes
    /// the entries in the input order, each naming its triangle by its place in the
    /// Morton order (`rank[i]` for the update's `tris[i]`), so a tile lists its
    /// triangles in the input order. The rectangles are read in the order the first pass
    /// wrote them: read in the Morton order instead, the pass took 2–3 times as long.
    pub(super) fn write(&mut self, rank: &[u32], gv: u32) {
        let (nu, nv) = (self.frame.nu as usize, self.frame.nv as usize);
        let stride = nu + 1;
        let (dense, slots, diff, touched) =
            (self.dense, &mut self.slots, &mut self.diff, &self.touched);
        // Place the runs, each starting at a multiple of `LANES`; `cursor` is where the
        // next entry of a tile goes.
        let cursor = &mut self.cursor;
        cursor.resize(nu * nv, 0);
        let mut at = 0u32;
        if dense {
            // Prefix sums, row by row: row `j` of `diff` becomes the counts of row `j`.
            for j in 0..nv {
                let mut run = 0i32;
                for i in 0..nu {
                    run += diff[j * stride + i];
                    let c = run + if j > 0 { diff[(j - 1) * stride + i] } else { 0 };
                    diff[j * stride + i] = c;
                    if c > 0 {
                        let tile = j * nu + i;
                        slots[tile] = Slot {
                            version: gv,
                            start: at,
                            count: c as u32,
                        };
                        cursor[tile] = at;
                        at += (c as u32).next_multiple_of(LANES as u32);
                    }
                }
            }
        } else {
            for &t in touched.iter() {
                let slot = &mut slots[t as usize];
                slot.start = at;
                cursor[t as usize] = at;
                at += slot.count.next_multiple_of(LANES as u32);
            }
        }
        let at = at as usize;
        // The buffer is written in place: each run's last block, where it is not full,
        // padded first (instead of padding the whole buffer every frame).
        self.entries.ensure(at);
        let mut pad = |slot: &Slot| {
            let end = (slot.start + slot.count) as usize;
            if !end.is_multiple_of(LANES) {
                self.entries.pad(end);
            }
        };
        if dense {
            slots[..nu * nv]
                .iter()
                .filter(|s| s.version == gv && s.count > 0)
                .for_each(&mut pad);
        } else {
            touched.iter().for_each(|&t| pad(&slots[t as usize]));
        }
        let (entries, rects, raw) = (&mut self.entries, &self.rects, &self.raw);
        let mut put = |tile: usize, e: &Entry| {
            let at = &mut cursor[tile];
            entries.set(*at as usize, e);
            *at += 1;
        };
        for (r, &k) in rects.iter().zip(rank) {
            if r.i0 == Rect::CLIPPED {
                for &(tile, zmin, zmax) in &raw[r.lo as usize..r.hi as usize] {
                    put(tile as usize, &Entry { tri: k, zmin, zmax });
                }
                continue;
            }
            let e = Entry {
                tri: k,
                zmin: f32::from_bits(r.lo),
                zmax: f32::from_bits(r.hi),
            };
            // The rectangle's tiles row by row in one loop, the step to the next row by
            // selects: one loop exit to mispredict a triangle, not one a row (−18% on
            // this pass, `benches/PERF.md` step 43).
            let (i0, i1) = (r.i0 as usize, r.i1 as usize);
            let w = i1 - i0 + 1;
            let n = w * (r.j1 as usize - r.j0 as usize + 1);
            let (mut tile, mut i) = (r.j0 as usize * nu + i0, i0);
            for _ in 0..n {
                put(tile, &e);
                let wrap = i == i1;
                i = if wrap { i0 } else { i + 1 };
                tile = if wrap { tile + nu + 1 - w } else { tile + 1 };
            }
        }
    }
}

/// Whether an insertion counts by a difference array over the whole grid: when the
/// grid's cells are few beside the triangles (`DynamicLayer::for_triangles` gives a
/// quarter as many tiles as triangles), so that the prefix sums cost a small part of
/// the insertion. A grid of many tiles for few triangles counts tile by tile instead.
fn dense_counts(frame: &GridFrame, triangles: usize) -> bool {
    let cells = (frame.nu as usize + 1) * (frame.nv as usize + 1);
    cells <= 4 * triangles + 1024
}
