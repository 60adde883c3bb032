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

//!
//! # Files
//!
//! * this file: the layer ([`DynamicLayer`]), its update and its own queries;
//! * `tiles`: the per-direction store (slots with versions, entry blocks), shared by
//!   the others and using none of them;
//! * `insert`: the two passes that insert a frame's triangles into one direction;
//! * `morton`: the triangles' Morton order;
//! * `resolution`: the tile count of a frame's grids, from the triangles' sizes;
//! * `layered`: the static PSF and the layer queried together ([`Layered`], [`Prim`]).

mod insert;
mod layered;
mod morton;
mod resolution;
mod tiles;

#[cfg(test)]
mod tests;

use glam::{DVec3, Vec3};
use rayon::prelude::*;

pub use layered::{Layered, Prim};

use super::bsp::LANES;
use super::point::{FrameGrids, PointCache};
use super::stats::{Counter, NoCount, RayStats};
use super::traverse::{block_window, scan_blocks, walk_tiles, BoxTest};
use super::{
    check_triangles, margin_for, DirectionTable, Entry, GridFrame, Psf, PsfError, PsfParams,
};
use crate::geometry::{Aabb, Hit, Intersector, Ray, RayPre, TriPre};
use morton::morton_order;
use tiles::{DynSubfield, Entries, Rect, Slot};

/// Moving triangles, re-inserted by [`DynamicLayer::update`] each frame.
#[derive(Debug)]
pub struct DynamicLayer {
    params: PsfParams,
    table: DirectionTable,
    /// `GV`: lists stamped with another value are stale. 0 before the first update.
    generation: u32,
    margin: f32,
    /// This frame's bounds grown by the rounding allowance; rays are clipped to it.
    clip: BoxTest,
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
    /// The cache of the point grids over the moving triangles alone
    /// ([`Layers`](crate::geometry::Layers)): it keeps none (they move), but planning
    /// needs one.
    pub(super) moving_points: PointCache,
    /// The point grids this frame's batches built over both layers and share
    /// ([`FrameGrids`]): emptied by every update.
    pub(super) frame_grids: FrameGrids,
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
            clip: BoxTest::EMPTY,
            local: Vec::new(),
            order: Vec::new(),
            rank: Vec::new(),
            keys: Vec::new(),
            counts: Vec::new(),
            subfields,
            moving_points: {
                let c = PointCache::default();
                c.set_capacity(0);
                c
            },
            frame_grids: FrameGrids::default(),
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
        self.frame_grids.clear();
        self.next_generation();
        let bounds = match checked_bounds(tris) {
            Ok(b) => b,
            Err(e) => {
                self.local.clear();
                return Err(e);
            }
        };
        self.margin = margin_for(&bounds);
        self.clip = BoxTest::new(bounds.padded(2.0 * self.margin));
        if tris.is_empty() {
            self.local.clear();
            return Ok(());
        }
        // Fewer tiles than the parameters' where the triangles are large beside their
        // spread (`resolution`): clustered frames would otherwise clip each triangle
        // into hundreds of tiles.
        let tiles = resolution::frame_tiles(tris, &bounds, self.params.tiles);
        let (gv, margin, clip) = (self.generation, self.margin, self.clip.aabb());
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
        let (o, d, t0, t1) = self.clip.span(ray)?;
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

impl Intersector for DynamicLayer {
    /// The closest hit among the layer's triangles alone (numbered from 0).
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.trace::<false, _>(ray, &mut NoCount)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.trace::<true, _>(ray, &mut NoCount).is_some()
    }
}
