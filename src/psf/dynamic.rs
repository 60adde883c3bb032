//! The dynamic layer: triangles that move, re-inserted every frame into per-direction
//! tile grids, and the query that combines them with the static PSF.
//!
//! Every subfield of the layer keeps, per tile, a list of entries and a version `V`; the
//! layer keeps a generation `GV`. A list is current only when its `V` equals `GV`, so
//! advancing `GV` at the start of an update invalidates every list at once without
//! visiting any. Insertion stamps the tiles it fills; after the first frames an update
//! allocates nothing. It costs time in proportion to the tiles the moved triangles
//! cover, plus, on grids of no more cells than a few per triangle (the defaults), one
//! prefix-sum pass over the grid (`dense_counts`); finer grids are counted tile by
//! tile on first touch, never visiting the rest of the grid.
//!
//! The grids cover this frame's bounds of the moving triangles, wherever they are: far
//! outside the static scene is fine. Queries walk the static PSF first, then the dynamic
//! grid of the same direction up to the static hit, scanning each tile's list.

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use super::batch::binned;
use super::bsp::{Block, LANES, PADDING};
use super::grid::clamped_floor;
use super::point::{trace_batch, Plan, Sources};
use super::stats::{Counter, NoCount, RayStats};
use super::traverse::{block_window, clipped_span, scan_blocks, walk_tiles};
use super::{
    check_triangles, margin_for, DirectionTable, Entry, GridFrame, Psf, PsfError, PsfParams,
};
use crate::geometry::{Aabb, Hit, Intersector, Ray, RayPre, TriPre};

/// Triangles spanning at most this many tiles are listed in each with their whole depth
/// range, unclipped. `cargo bench --bench dynamic -- update` (16,384 moving triangles,
/// level 1, 128 tiles, 2 cores): 21.5 ms per update with exact clipping everywhere, 8.5
/// ms with a limit of 4 tiles. On the museum (`cargo bench --bench embree`, 160x120, every
/// 30th frame), where gathered shapes make triangles span many small tiles, a limit of 4
/// left frames at 18-27 ms; 16 keeps them under about 10 ms, tracing no slower.
const COARSE: u32 = 16;

/// Moving triangles, re-inserted by [`DynamicLayer::update`] each frame.
#[derive(Debug)]
pub struct DynamicLayer {
    params: PsfParams,
    table: DirectionTable,
    /// `GV`: lists stamped with another value are stale. 0 before the first update.
    generation: u32,
    margin: f32,
    /// This frame's bounds grown by the rounding allowance; rays are clipped to it.
    clip: Aabb,
    /// This frame's triangles in the order of their centroids' Morton codes (`local[k]`
    /// is the update's `tris[order[k]]`; no copy in the input order is kept), laid out
    /// for the candidate test: entries name positions in `local`, so the candidates of a
    /// tile, and of neighbouring tiles, sit together in memory whatever the input order.
    /// Overwritten in place by each update (its length is the last one's count).
    local: Vec<TriPre>,
    order: Vec<u32>,
    /// `rank[i]`: the position in `local` of the update's `tris[i]`.
    rank: Vec<u32>,
    /// Scratch of the reordering: per-triangle keys and bucket counts.
    keys: Vec<u32>,
    counts: Vec<u32>,
    subfields: Vec<DynSubfield>,
}

#[derive(Debug)]
struct DynSubfield {
    dir: Vec3,
    frame: GridFrame,
    /// Per tile of the largest grid the parameters allow (`tiles × tiles`): its version
    /// `V` and, when current, its run of `entries`.
    slots: Vec<Slot>,
    /// This frame's entries, grouped by tile (in tile order, or in order of first touch
    /// when counted tile by tile), in blocks of 8, so a query filters a tile's list by
    /// depth eight entries at a time (`depth_mask`). Each tile's run starts at a
    /// multiple of 8 and is padded to one with entries no depth interval meets.
    entries: Entries,
    /// Scratch reused every update: whether this frame counts densely, each triangle's
    /// rectangle of tiles in the input order (for a triangle clipped tile by tile, where
    /// its entries lie in `raw`), the clipped triangles' entries in raster order as
    /// (tile, zmin, zmax), the tiles touched (counting tile by tile), the difference
    /// array of the counts (dense counting, `(nu + 1) × (nv + 1)`) and each tile's write
    /// position.
    dense: bool,
    rects: Vec<Rect>,
    raw: Vec<(u32, f32, f32)>,
    touched: Vec<u32>,
    diff: Vec<i32>,
    cursor: Vec<u32>,
}

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

/// A coarse triangle's [`Footprint`](super::grid::Footprint), packed in 16 bytes: the
/// second pass of an insertion reads it instead of an entry record per tile. `lo` and
/// `hi` are the bits of its depth range or, for a triangle clipped tile by tile (`i0 ==
/// Rect::CLIPPED`), the range of its entries in `raw`.
#[derive(Clone, Copy, Debug, Default)]
struct Rect {
    i0: u16,
    i1: u16,
    j0: u16,
    j1: u16,
    lo: u32,
    hi: u32,
}

impl Rect {
    /// No column is this (tile indices are below `PsfParams::MAX_TILES`, 4096).
    const CLIPPED: u16 = u16::MAX;
}

/// Entries in blocks of `LANES`, each block's depths by columns: a query filters a
/// block by depth with two loads (`depth_mask`) and reads the triangle numbers beside
/// them, and an insertion writes an entry into one block.
#[derive(Debug, Default)]
struct Entries {
    blocks: Vec<Block>,
}

impl Entries {
    fn capacity(&self) -> usize {
        self.blocks.capacity() * LANES
    }

    /// At least `n` entries (a multiple of `LANES`). The buffer only grows, its new
    /// blocks padding, and keeps headroom: grown to 5/4 of the need whenever it is short,
    /// so it settles after the first frames instead of doubling whenever a frame sets a
    /// record. What lies beyond this frame's runs is never read.
    fn ensure(&mut self, n: usize) {
        let need = n / LANES;
        if self.blocks.capacity() < need {
            let want = (n + n / 4).div_ceil(LANES);
            self.blocks.reserve_exact(want - self.blocks.len());
        }
        if self.blocks.len() < need {
            self.blocks.resize(need, PADDING);
        }
    }

    /// Padding in the block holding entry `i` (the first place after a run whose last
    /// block is not full; the run's entries are written into the block afterwards).
    #[inline]
    fn pad(&mut self, i: usize) {
        self.blocks[i / LANES] = PADDING;
    }

    #[inline]
    fn set(&mut self, i: usize, e: &Entry) {
        let b = &mut self.blocks[i / LANES];
        b.zmin[i % LANES] = e.zmin;
        b.zmax[i % LANES] = e.zmax;
        b.tri[i % LANES] = e.tri;
    }
}

/// The low 10 bits of `v` moved to every third bit.
const fn spread3(v: u32) -> u32 {
    let mut v = v & 0x3ff;
    v = (v | (v << 16)) & 0x0300_00ff;
    v = (v | (v << 8)) & 0x0300_f00f;
    v = (v | (v << 4)) & 0x030c_30c3;
    (v | (v << 2)) & 0x0924_9249
}

/// [`spread3`] of every 10-bit number: three loads instead of twelve shifts and masks
/// a key (the keys were a third of the reorder's time).
static SPREAD3: [u32; 1024] = {
    let mut t = [0u32; 1024];
    let mut i = 0;
    while i < 1024 {
        t[i] = spread3(i as u32);
        i += 1;
    }
    t
};

/// Interleaves the low 10 bits of `x`, `y`, `z` (`x` lowest).
#[inline]
fn morton3(x: u32, y: u32, z: u32) -> u32 {
    let t = |v: u32| SPREAD3[(v & 0x3ff) as usize];
    t(x) | (t(y) << 1) | (t(z) << 2)
}

/// Fills `order` with the triangles sorted by the Morton code of their centroid within
/// `bounds`, cut to a bucket for every one to eight triangles (a stable counting sort,
/// so ties keep the input order and the result depends on the input alone); `keys` and
/// `counts` are scratch.
fn morton_order(
    tris: &[[Vec3; 3]],
    bounds: &Aabb,
    keys: &mut Vec<u32>,
    counts: &mut Vec<u32>,
    order: &mut Vec<u32>,
    rank: &mut Vec<u32>,
) {
    let n = tris.len();
    // 3 bits of code per level of an octree with n / 8 to n leaves, 3..=27 bits. A
    // level finer (up to eight buckets a triangle) sorted no better for the insertions
    // and the queries and updated 4-6% slower: its counts outgrow the first-level cache
    // (`benches/PERF.md`, step 80).
    let levels = ((usize::BITS - n.leading_zeros()).div_ceil(3)).clamp(2, 10) - 1;
    let bits = 3 * levels;
    let scale = Vec3::splat((1u32 << levels) as f32) / bounds.extent().max(Vec3::splat(1e-30));
    let top = (1u32 << levels) - 1;
    keys.clear();
    keys.extend(tris.iter().map(|t| {
        let c = ((t[0] + t[1] + t[2]) * (1.0 / 3.0) - bounds.min) * scale;
        let [x, y, z, _] = clamped_floor([c.x, c.y, c.z, 0.0], [top; 4]);
        morton3(x, y, z)
    }));
    counts.clear();
    counts.resize((1usize << bits) + 1, 0);
    for &k in keys.iter() {
        counts[k as usize + 1] += 1;
    }
    for i in 0..1usize << bits {
        counts[i + 1] += counts[i];
    }
    order.clear();
    order.resize(n, 0);
    rank.clear();
    for (i, &k) in keys.iter().enumerate() {
        let at = &mut counts[k as usize];
        order[*at as usize] = i as u32;
        rank.push(*at);
        *at += 1;
    }
}

#[derive(Clone, Copy, Debug, Default)]
struct Slot {
    version: u32,
    start: u32,
    count: u32,
}

/// Occupancy and memory of the layer after an update.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DynamicStats {
    pub triangles: usize,
    /// Entries in current lists, over all subfields.
    pub entries: usize,
    /// Tiles holding a current list, over all subfields.
    pub tiles_used: usize,
    /// The longest current list.
    pub max_list: usize,
    /// Bytes held by the layer (list capacity included): flat once the motion has been
    /// seen, whatever the number of frames.
    pub bytes: usize,
}

impl DynamicLayer {
    /// An empty layer with the static PSF's direction level and tile count.
    pub fn new(static_psf: &Psf) -> DynamicLayer {
        Self::with_params(*static_psf.params()).expect("a built PSF has valid parameters")
    }

    /// An empty layer sized for `n` moving triangles: the tile count of
    /// [`PsfParams::for_triangles`], level 0, and [`grids_for(n)`](Self::grids_for) of
    /// its four directions. Since camera and shadow rays take point grids, only the
    /// other rays walk this layer: level 0 updated 30–35% faster than level 1 on the
    /// museum scenes (1k to 100k moving triangles, and with the 1M room), for frames
    /// within −2% to +4% (`benches/PERF.md`, step 62).
    pub fn for_triangles(n: usize) -> DynamicLayer {
        let params = PsfParams {
            level: 0,
            ..PsfParams::for_triangles(n)
        };
        Self::with_grids(params, Self::grids_for(n)).expect("for_triangles gives valid parameters")
    }

    /// How many of level 0's four directions [`for_triangles`](Self::for_triangles)
    /// lists `n` moving triangles in: two below 32,768, all four from there. Fewer grids
    /// shorten the update (its grids are independent jobs: on two cores, two are one
    /// round of them, four two rounds) and lengthen the walk of the rays far from both
    /// directions, which costs more the more moving triangles there are. On the museum
    /// scenes, two threads, 640x480 (`benches/PERF.md`, step 93): at 16,384 two grids
    /// updated in 1.13 ms against 1.84 with a trace as fast (+0.1 ± 0.9 ms), at 40,000
    /// in 2.8 against 4.4 ms but traced 4.2 ± 1.1 ms slower, a slower frame.
    pub fn grids_for(n: usize) -> usize {
        if n < 32_768 {
            2
        } else {
            4
        }
    }

    /// Moving triangles from which an update runs its jobs on the pool's threads; with
    /// fewer, the hand-overs between threads cost more than they share, and the calling
    /// thread does it all (`benches/PERF.md`, step 95).
    pub const PARALLEL_FROM: usize = 2048;

    /// An empty layer with its own direction level and tile count, over every direction
    /// of the level.
    pub fn with_params(params: PsfParams) -> Result<DynamicLayer, PsfError> {
        params.validate()?;
        Self::with_grids(params, super::subfield_directions(params.level).len())
    }

    /// An empty layer over the first `grids` directions of `params.level` (1 up to all of
    /// them: 4 at level 0, 7 at level 1). A ray walks the grid of the closest of those
    /// directions; any grid gives the same hits, a farther one a longer walk.
    pub fn with_grids(params: PsfParams, grids: usize) -> Result<DynamicLayer, PsfError> {
        params.validate()?;
        let mut dirs = super::subfield_directions(params.level);
        if grids == 0 || grids > dirs.len() {
            return Err(PsfError::Params(format!(
                "grids {grids} is outside 1..={} for level {}",
                dirs.len(),
                params.level
            )));
        }
        dirs.truncate(grids);
        let n = (params.tiles * params.tiles) as usize;
        let subfields = dirs
            .iter()
            .map(|&dir| DynSubfield {
                dir,
                frame: GridFrame::new(dir, &Aabb::EMPTY, 1),
                slots: vec![Slot::default(); n],
                entries: Entries::default(),
                dense: false,
                rects: Vec::new(),
                raw: Vec::new(),
                touched: Vec::new(),
                diff: Vec::new(),
                cursor: Vec::new(),
            })
            .collect();
        Ok(DynamicLayer {
            params,
            table: DirectionTable::new(&dirs),
            generation: 0,
            margin: 0.0,
            clip: Aabb::EMPTY,
            local: Vec::new(),
            order: Vec::new(),
            rank: Vec::new(),
            keys: Vec::new(),
            counts: Vec::new(),
            subfields,
        })
    }

    pub fn params(&self) -> &PsfParams {
        &self.params
    }

    /// The number of grids (directions) the layer lists its triangles in.
    pub fn grids(&self) -> usize {
        self.subfields.len()
    }

    /// Replaces the layer's triangles with `tris` (this frame's positions). On error
    /// (a non-finite coordinate) the layer is left empty.
    ///
    /// After the bounds, two rounds of parallel jobs, both passes of every grid reading
    /// the triangles in their input order: the Morton order beside the grids' first
    /// passes, then the test form in that order beside their second passes, which name
    /// each triangle by its place in it. The order and the sorted copy had been made
    /// first, alone, the other threads idle (`benches/PERF.md`, step 94).
    pub fn update(&mut self, tris: &[[Vec3; 3]]) -> Result<(), PsfError> {
        // Everything that describes the last frame's triangles is replaced, the sorted
        // copy too (overwritten in place): the point grids read it, and a frame without
        // moving triangles (or a refused one) must leave none of the last frame's behind.
        self.order.clear();
        self.next_generation();
        let bounds = match checked_bounds(tris) {
            Ok(b) => b,
            Err(e) => {
                self.local.clear();
                return Err(e);
            }
        };
        self.margin = margin_for(&bounds);
        self.clip = bounds.padded(2.0 * self.margin);
        if tris.is_empty() {
            self.local.clear();
            return Ok(());
        }
        let (gv, margin, clip, tiles) =
            (self.generation, self.margin, self.clip, self.params.tiles);
        let (keys, counts, order, rank) = (
            &mut self.keys,
            &mut self.counts,
            &mut self.order,
            &mut self.rank,
        );
        // The calling thread takes the order and the last grid, another the rest: a job
        // of the calling thread's own is not handed back from a thread that stole it.
        let grids = self.subfields.len();
        let (rest, last) = self.subfields.split_at_mut(grids - 1);
        let last = &mut last[0];
        // Few triangles are not worth the hand-overs between threads.
        let serial = tris.len() < Self::PARALLEL_FROM;
        let both = |a: &mut (dyn FnMut() + Send), b: &mut (dyn FnMut() + Send)| {
            if serial {
                a();
                b();
            } else {
                rayon::join(a, b);
            }
        };
        let each = |grids: &mut [DynSubfield], f: &(dyn Fn(&mut DynSubfield) + Sync)| {
            if serial {
                grids.iter_mut().for_each(f)
            } else {
                grids.par_iter_mut().for_each(f)
            }
        };
        both(
            &mut || {
                morton_order(tris, &bounds, keys, counts, order, rank);
                last.count(tris, gv, margin, &clip, tiles, None);
            },
            &mut || each(rest, &|s| s.count(tris, gv, margin, &clip, tiles, None)),
        );
        // Overwritten in place: resizing writes only where the count grew.
        self.local.resize(tris.len(), TriPre::default());
        let (order, rank, local) = (&self.order, &self.rank, &mut self.local);
        both(
            &mut || {
                for (o, &i) in local.iter_mut().zip(order) {
                    *o = TriPre::new(&tris[i as usize]);
                }
                last.write(rank, gv);
            },
            &mut || each(rest, &|s| s.write(rank, gv)),
        );
        Ok(())
    }

    /// Advances `GV`; on the (4-billion-frame) wrap every stamp is reset once.
    fn next_generation(&mut self) {
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            for s in &mut self.subfields {
                s.slots.fill(Slot::default());
            }
            self.generation = 1;
        }
    }

    /// The number of triangles of the last update.
    pub fn len(&self) -> usize {
        self.local.len()
    }

    pub fn is_empty(&self) -> bool {
        self.local.is_empty()
    }

    /// Occupancy and memory now (visits every tile: for reports, not per frame).
    pub fn stats(&self) -> DynamicStats {
        let mut st = DynamicStats {
            triangles: self.len(),
            bytes: std::mem::size_of::<Self>()
                + self.local.capacity() * std::mem::size_of::<TriPre>()
                + (self.order.capacity()
                    + self.rank.capacity()
                    + self.keys.capacity()
                    + self.counts.capacity())
                    * 4,
            ..DynamicStats::default()
        };
        for s in &self.subfields {
            st.bytes += s.slots.capacity() * std::mem::size_of::<Slot>()
                + s.entries.capacity() * std::mem::size_of::<Entry>()
                + s.rects.capacity() * std::mem::size_of::<Rect>()
                + s.raw.capacity() * std::mem::size_of::<(u32, f32, f32)>()
                + (s.touched.capacity() + s.diff.capacity() + s.cursor.capacity()) * 4;
            if self.is_empty() {
                continue;
            }
            for slot in s.slots.iter().filter(|x| x.version == self.generation) {
                st.entries += slot.count as usize;
                st.tiles_used += 1;
                st.max_list = st.max_list.max(slot.count as usize);
            }
        }
        st
    }

    /// The closest hit among this frame's triangles, also counting the work done.
    pub fn intersect_counted(&self, ray: &Ray, stats: &mut RayStats) -> Option<Hit> {
        stats.rays += 1;
        self.trace::<false, _>(ray, stats)
    }

    /// Any hit among this frame's triangles, also counting the work done.
    pub fn occluded_counted(&self, ray: &Ray, stats: &mut RayStats) -> bool {
        stats.rays += 1;
        self.trace::<true, _>(ray, stats).is_some()
    }

    #[inline]
    fn trace<const ANY: bool, C: Counter>(&self, ray: &Ray, count: &mut C) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        self.trace_pre::<ANY, C>(ray, &RayPre::new(ray.origin, ray.dir), None, count)
    }

    /// [`trace`](Self::trace) of a valid ray with its [`RayPre`] given. `sub`: a subfield
    /// to walk instead of the one the ray's direction picks (any grid gives the same
    /// hits, a grid further from the ray's direction a longer walk).
    fn trace_pre<const ANY: bool, C: Counter>(
        &self,
        ray: &Ray,
        pre: &RayPre,
        sub: Option<usize>,
        count: &mut C,
    ) -> Option<Hit> {
        if self.is_empty() {
            return None;
        }
        let (o, d, t0, t1) = clipped_span(&self.clip, ray)?;
        let sf = &self.subfields[sub.unwrap_or_else(|| self.table.lookup(ray.dir))];
        let (margin, gv, tris, order) = (self.margin, self.generation, &self.local, &self.order);
        let slack = (margin as f64 + 1e-6 * o.length()) / d.length();
        let fd: DVec3 = sf.frame.d.as_dvec3();
        let (oz, dz) = (o.dot(fd), d.dot(fd));
        let mut best: Option<Hit> = None;
        walk_tiles(&sf.frame, o, d, t0, t1, |tile, t_enter, t_exit| {
            count.tile();
            let slot = sf.slots[tile];
            if slot.version != gv {
                return true;
            }
            let (start, len) = (slot.start as usize, slot.count as usize);
            let e = &sf.entries;
            count.scanned(len);
            let window = block_window(oz, dz, t_enter, t_exit, &best, slack, margin);
            let blocks = &e.blocks[start / LANES..(start + len).div_ceil(LANES)];
            let number = |t: u32| order[t as usize];
            if !scan_blocks::<ANY, _, _>(blocks, window, pre, tris, ray, &mut best, count, number) {
                return false;
            }
            !matches!(&best, Some(b) if b.t as f64 + slack <= t_exit)
        });
        best
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
    fn count(
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
    fn write(&mut self, rank: &[u32], gv: u32) {
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
            if end % LANES != 0 {
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

/// The triangles' bounds, found in the same pass that checks their coordinates: one
/// pass over the nine coordinates of each triangle (lanes the compiler vectorises), where
/// any infinity or NaN turns a sum of `x * 0` into NaN; [`check_triangles`] then names
/// the first. Two passes (the check, then [`Aabb::from_triangles`]) had taken 0.19–0.27
/// ms of a 1.5–2.5 ms update at 16,384 triangles.
fn checked_bounds(tris: &[[Vec3; 3]]) -> Result<Aabb, PsfError> {
    if tris.len() > u32::MAX as usize {
        check_triangles(tris)?;
    }
    // Four vertices (twelve coordinates, three vector registers) a step: lane `k` holds
    // axis `k % 3`. Nine lanes a triangle had left the compiler a poor loop.
    let flat: &[f32] = bytemuck::cast_slice(tris);
    let (mut lo, mut hi, mut poison) = ([f32::INFINITY; 12], [f32::NEG_INFINITY; 12], [0f32; 12]);
    let mut step = |t: &[f32]| {
        for k in 0..t.len() {
            // Compares rather than `f32::min`, whose NaN rule costs the vectorised loop.
            lo[k] = if t[k] < lo[k] { t[k] } else { lo[k] };
            hi[k] = if t[k] > hi[k] { t[k] } else { hi[k] };
            poison[k] += t[k] * 0.0;
        }
    };
    let mut chunks = flat.chunks_exact(12);
    for t in &mut chunks {
        step(t);
    }
    // What is left is whole vertices (the length is a multiple of 3).
    step(chunks.remainder());
    if poison.iter().any(|p| !p.is_finite()) {
        check_triangles(tris)?;
    }
    let fold = |a: [f32; 12], f: fn(f32, f32) -> f32| {
        Vec3::from_array(std::array::from_fn(|k| {
            f(f(a[k], a[k + 3]), f(a[k + 6], a[k + 9]))
        }))
    };
    Ok(Aabb {
        min: fold(lo, f32::min),
        max: fold(hi, f32::max),
    })
}

/// Whether an insertion counts by a difference array over the whole grid: when the
/// grid's cells are few beside the triangles (`DynamicLayer::for_triangles` gives a
/// quarter as many tiles as triangles), so that the prefix sums cost a small part of
/// the insertion. A grid of many tiles for few triangles counts tile by tile instead.
fn dense_counts(frame: &GridFrame, triangles: usize) -> bool {
    let cells = (frame.nu as usize + 1) * (frame.nv as usize + 1);
    cells <= 4 * triangles + 1024
}

impl Intersector for DynamicLayer {
    /// The closest hit among the layer's triangles alone (numbered from 0).
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.trace::<false, _>(ray, &mut NoCount)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.trace::<true, _>(ray, &mut NoCount).is_some()
    }
}

/// The static PSF and a dynamic layer queried together.
#[derive(Clone, Debug)]
pub struct Layered<'a> {
    psf: &'a Psf,
    dynamic: &'a DynamicLayer,
    /// Per static subfield, the dynamic subfield of the closest direction: a batch,
    /// which knows each ray's static subfield, walks that dynamic grid without a second
    /// direction lookup (a doubled lookup had cost 4.7% of the trace, `benches/PERF.md`
    /// step 51).
    dyn_of: Vec<u8>,
}

impl Psf {
    /// Queries over this PSF and `dynamic` together; dynamic triangle `i` is reported
    /// as `self.triangles().len() + i`.
    pub fn with_dynamic<'a>(&'a self, dynamic: &'a DynamicLayer) -> Layered<'a> {
        // At most 7 dynamic subfields at level 1, 469 at level 4: a u16 would do for any
        // level, a u8 holds the levels up to 3 (109); level 4 falls back to the lookup.
        let dyn_of = if dynamic.subfields.len() <= u8::MAX as usize + 1 {
            let dirs = self.subfields.iter().map(|s| s.frame.d);
            dirs.map(|d| dynamic.table.lookup(d) as u8).collect()
        } else {
            Vec::new()
        };
        Layered {
            psf: self,
            dynamic,
            dyn_of,
        }
    }
}

impl Layered<'_> {
    /// `sub`: the static subfield, when a batch knows it already.
    fn trace<const ANY: bool, C: Counter>(
        &self,
        ray: &Ray,
        sub: Option<usize>,
        count: &mut C,
    ) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        // One shear for both layers: the dynamic walk's ray differs in `t_max` alone.
        let pre = RayPre::new(ray.origin, ray.dir);
        let s = self.psf.trace_pre::<ANY, C>(ray, &pre, sub, count);
        let dyn_sub = sub.and_then(|k| self.dyn_of.get(k)).map(|&k| k as usize);
        if ANY && s.is_some() {
            return s;
        }
        // The dynamic walk stops at the static hit: a dynamic triangle at the same t
        // loses the tie anyway (its number is larger).
        let mut r = *ray;
        if let Some(h) = &s {
            r.t_max = h.t;
        }
        let offset = self.psf.triangles().len() as u32;
        let d = self
            .dynamic
            .trace_pre::<ANY, C>(&r, &pre, dyn_sub, count)
            .map(|mut h| {
                h.tri += offset;
                h
            });
        match (s, d) {
            (Some(a), Some(b)) => Some(if b.is_closer_than(&a) { b } else { a }),
            (a, b) => a.or(b),
        }
    }

    /// Whether [`intersect_batch`](Intersector::intersect_batch) and
    /// [`occluded_batch`](Intersector::occluded_batch) trace some of `rays` through point
    /// grids (grids by central projection around a point rays pass through): when a share
    /// of a sample passes one point (a camera's rays, a light's shadow rays, reflections
    /// off one plane) and those rays are enough to pay for what must be built (for camera
    /// and shadow rays at least a twelfth as many as triangles times the cube faces they
    /// use, for rays that merely pass the point six times that; only the moving triangles
    /// count once the static PSF keeps a grid around the point, which it does for a
    /// point seen in an earlier batch). Either way the hits are the same. It builds the
    /// grids to find out, and keeps and remembers what a batch would.
    pub fn point_grid_for(&self, rays: &[Ray]) -> bool {
        !Plan::for_batch(rays, &self.sources()).is_empty()
    }

    /// Both layers' triangles, for a point grid.
    fn sources(&self) -> Sources<'_> {
        let d = self.dynamic;
        Sources {
            statics: self.psf.triangles(),
            moving_pre: &d.local,
            moving_number: &d.order,
            margin: self
                .psf
                .margin()
                .max(if d.is_empty() { 0.0 } else { d.margin }),
            bounds: if d.is_empty() {
                *self.psf.bounds()
            } else {
                self.psf.bounds().union(&d.clip)
            },
            cache: self.psf.point_cache(),
        }
    }

    /// The closest hit, also counting the work done (both layers) into `stats`.
    pub fn intersect_counted(&self, ray: &Ray, stats: &mut RayStats) -> Option<Hit> {
        stats.rays += 1;
        self.trace::<false, _>(ray, None, stats)
    }

    /// Any hit, also counting the work done into `stats`.
    pub fn occluded_counted(&self, ray: &Ray, stats: &mut RayStats) -> bool {
        stats.rays += 1;
        self.trace::<true, _>(ray, None, stats).is_some()
    }
}

impl Intersector for Layered<'_> {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.trace::<false, _>(ray, None, &mut NoCount)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.trace::<true, _>(ray, None, &mut NoCount).is_some()
    }

    /// Through point grids for the rays that pass a point grids pay for (a camera's
    /// primary rays, shadow rays towards a point light, reflections off a plane;
    /// [`Layered::point_grid_for`]); the others binned by the static PSF's subfield
    /// (`psf::batch`).
    fn intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        let bins = self.psf.subfields().len().max(1);
        let walk = |rays: &[Ray], out: &mut [Option<Hit>]| {
            binned(
                rays,
                out,
                bins,
                |r| self.psf.bin_of(r),
                |r, k| self.trace::<false, _>(r, Some(k), &mut NoCount),
            )
        };
        trace_batch::<false, _>(rays, out, &self.sources(), |h| h, walk);
    }

    fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        let bins = self.psf.subfields().len().max(1);
        let walk = |rays: &[Ray], out: &mut [bool]| {
            binned(
                rays,
                out,
                bins,
                |r| self.psf.bin_of(r),
                |r, k| self.trace::<true, _>(r, Some(k), &mut NoCount).is_some(),
            )
        };
        trace_batch::<true, _>(rays, out, &self.sources(), |h| h.is_some(), walk);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{soup, Rng};

    /// The ranks of triangles already in the order their entries name them.
    fn identity(n: usize) -> Vec<u32> {
        (0..n as u32).collect()
    }

    /// A tile's list as (triangle, zmin bits, zmax bits), in list order.
    type List = Vec<(u32, u32, u32)>;

    /// Each current tile with its list.
    fn lists(s: &DynSubfield, gv: u32) -> Vec<(usize, List)> {
        let mut out = Vec::new();
        for (tile, slot) in s.slots.iter().enumerate() {
            if slot.version != gv {
                continue;
            }
            let list = (slot.start..slot.start + slot.count)
                .map(|i| {
                    let b = &s.entries.blocks[i as usize / LANES];
                    let j = i as usize % LANES;
                    (b.tri[j], b.zmin[j].to_bits(), b.zmax[j].to_bits())
                })
                .collect();
            out.push((tile, list));
        }
        out
    }

    #[test]
    fn checked_bounds_are_the_bounds_and_name_any_non_finite_coordinate() {
        let mut rng = Rng::new(11);
        let tris = soup(
            &mut rng,
            333,
            Vec3::splat(-7.0),
            Vec3::new(3.0, 9.0, 1.0),
            2.0,
        );
        let b = checked_bounds(&tris).expect("finite");
        let want = Aabb::from_triangles(&tris);
        assert_eq!((b.min, b.max), (want.min, want.max));
        let e = checked_bounds(&[]).expect("empty");
        assert_eq!((e.min, e.max), (Aabb::EMPTY.min, Aabb::EMPTY.max));
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            for vertex in 0..3 {
                for axis in 0..3 {
                    let mut t = tris.clone();
                    t[200][vertex][axis] = bad;
                    t[250][0][0] = bad;
                    match checked_bounds(&t) {
                        Err(PsfError::NonFinite {
                            triangle: 200,
                            vertex: v,
                            ..
                        }) => assert_eq!(v, vertex),
                        other => panic!("{bad} at {vertex}/{axis}: {other:?}"),
                    }
                }
            }
        }
    }

    /// The entry buffer is reused from frame to frame: after a frame of many triangles,
    /// a frame of fewer leaves every run's last block padded beyond its entries (a stale
    /// entry there would be tested, against a triangle that may no longer exist).
    #[test]
    fn runs_end_in_padding_after_a_larger_frame() {
        let mut rng = Rng::new(5);
        let (lo, hi) = (Vec3::new(-4.0, -2.0, -3.0), Vec3::new(4.0, 2.0, 3.0));
        let many = soup(&mut rng, 3000, lo, hi, 0.4);
        let few = soup(&mut rng, 200, lo, hi, 0.3);
        for dense in [true, false] {
            let layer = DynamicLayer::with_params(PsfParams {
                level: 0,
                tiles: 32,
            });
            let mut s = layer.expect("params").subfields.remove(0);
            for (gv, tris) in [(1, &many), (2, &few)] {
                let bounds = Aabb::from_triangles(tris);
                let margin = margin_for(&bounds);
                let clip = bounds.padded(2.0 * margin);
                s.count(tris, gv, margin, &clip, 32, Some(dense));
                s.write(&identity(tris.len()), gv);
            }
            let mut runs = 0;
            for slot in s.slots.iter().filter(|x| x.version == 2) {
                let (start, end) = (slot.start as usize, (slot.start + slot.count) as usize);
                for i in end..end.next_multiple_of(LANES) {
                    let b = &s.entries.blocks[i / LANES];
                    let j = i % LANES;
                    assert_eq!(
                        (b.zmin[j], b.zmax[j]),
                        (f32::INFINITY, f32::NEG_INFINITY),
                        "dense {dense}: run {start}..{end}, lane {i}"
                    );
                }
                runs += 1;
            }
            assert!(runs > 10, "dense {dense}: {runs} runs");
        }
    }

    #[test]
    fn dense_and_tile_by_tile_counting_give_the_same_lists() {
        let mut rng = Rng::new(7);
        // Small triangles (coarse) and large ones (clipped tile by tile).
        let (lo, hi) = (Vec3::new(-4.0, -2.0, -3.0), Vec3::new(4.0, 2.0, 3.0));
        let mut tris = soup(&mut rng, 600, lo, hi, 0.2);
        tris.extend(soup(&mut rng, 20, lo, hi, 5.0));
        let bounds = Aabb::from_triangles(&tris);
        let margin = margin_for(&bounds);
        let clip = bounds.padded(2.0 * margin);
        for level in 0..2 {
            for tiles in [1, 7, 32, 64] {
                let layer = || DynamicLayer::with_params(PsfParams { level, tiles });
                let (da, db) = (layer().expect("params"), layer().expect("params"));
                for (mut a, mut b) in da.subfields.into_iter().zip(db.subfields) {
                    a.count(&tris, 3, margin, &clip, tiles, Some(true));
                    b.count(&tris, 3, margin, &clip, tiles, Some(false));
                    a.write(&identity(tris.len()), 3);
                    b.write(&identity(tris.len()), 3);
                    let (la, lb) = (lists(&a, 3), lists(&b, 3));
                    assert!(!la.is_empty());
                    assert_eq!(la, lb, "level {level}, {tiles} tiles, direction {}", a.dir);
                }
            }
        }
    }

    #[test]
    fn grids_are_the_first_directions_of_the_level_and_refused_outside_it() {
        let p = |level| PsfParams { level, tiles: 8 };
        for (level, all) in [(0, 4), (1, 7)] {
            assert_eq!(
                DynamicLayer::with_params(p(level)).expect("params").grids(),
                all
            );
            let dirs = crate::psf::subfield_directions(level);
            for g in 1..=all {
                let layer = DynamicLayer::with_grids(p(level), g).expect("grids");
                let got: Vec<Vec3> = layer.subfields.iter().map(|s| s.dir).collect();
                assert_eq!(got, dirs[..g], "level {level}, {g} grids");
            }
            for g in [0, all + 1] {
                let e = DynamicLayer::with_grids(p(level), g).expect_err("out of range");
                assert!(
                    e.to_string()
                        .contains(&format!("grids {g} is outside 1..={all}")),
                    "{e}"
                );
            }
        }
        assert_eq!(DynamicLayer::for_triangles(16_384).grids(), 2);
        assert_eq!(DynamicLayer::for_triangles(32_767).grids(), 2);
        assert_eq!(DynamicLayer::for_triangles(32_768).grids(), 4);
        assert_eq!(DynamicLayer::for_triangles(100_000).params().level, 0);
    }

    /// An update lists in each tile the triangles an insertion of the Morton-sorted copy
    /// lists there, each with the same depths and named by its place in that copy; in
    /// the input order, where the insertion lists them in the sorted one.
    #[test]
    fn update_lists_what_an_insertion_of_the_sorted_copy_lists() {
        let mut rng = Rng::new(23);
        let (lo, hi) = (Vec3::new(-4.0, -2.0, -3.0), Vec3::new(4.0, 2.0, 3.0));
        // Below and above `PARALLEL_FROM`: the update on one thread, then on the pool's.
        let small = DynamicLayer::PARALLEL_FROM - 100;
        let sizes = [
            (small, 0, 32, 2),
            (small, 1, 64, 7),
            (900, 0, 7, 4),
            (900, 0, 1, 1),
        ];
        let large = DynamicLayer::PARALLEL_FROM + 400;
        let sizes = sizes
            .into_iter()
            .chain([(large, 0, 32, 2), (large, 1, 16, 7)]);
        for (n, level, tiles, grids) in sizes {
            let mut tris = soup(&mut rng, n, lo, hi, 0.3);
            tris.extend(soup(&mut rng, 15, lo, hi, 5.0));
            let params = PsfParams { level, tiles };
            let mut layer = DynamicLayer::with_grids(params, grids).expect("params");
            // A larger frame first: the buffers it leaves must not show through.
            layer
                .update(&soup(&mut rng, 1500, lo, hi, 0.5))
                .expect("update");
            layer.update(&tris).expect("update");
            let sorted: Vec<[Vec3; 3]> = layer.order.iter().map(|&i| tris[i as usize]).collect();
            let local: Vec<[Vec3; 3]> = layer.local.iter().map(TriPre::vertices).collect();
            assert_eq!(local, sorted);
            for k in 0..tris.len() {
                assert_eq!(layer.rank[layer.order[k] as usize] as usize, k);
            }
            let gv = layer.generation;
            let mut fresh = DynamicLayer::with_grids(params, grids).expect("params");
            for (s, f) in layer.subfields.iter().zip(&mut fresh.subfields) {
                f.count(&sorted, gv, layer.margin, &layer.clip, tiles, None);
                f.write(&identity(sorted.len()), gv);
                let (got, want) = (lists(s, gv), lists(f, gv));
                assert_eq!(got.len(), want.len(), "level {level}, {tiles} tiles");
                assert!(want.iter().any(|(_, l)| l.len() > 1));
                for ((tg, lg), (tw, lw)) in got.iter().zip(&want) {
                    assert_eq!(tg, tw);
                    let input: Vec<u32> = lg.iter().map(|e| layer.order[e.0 as usize]).collect();
                    assert!(input.is_sorted(), "tile {tg}: {input:?}");
                    let mut sg = lg.clone();
                    sg.sort_unstable();
                    assert_eq!(sg, *lw, "tile {tg}, level {level}, {tiles} tiles");
                }
            }
        }
    }
}
