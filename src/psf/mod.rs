//! Parallel subfields (the paper's PSF): for each of a set of directions, the scene's
//! triangles rasterised into a grid of beams (tiles) with a 1D BSP along the beam.
//!
//! * `directions`: subdivided tetrahedron, subfields shared by `d` and `-d`, lookup table.
//! * `grid`: a subfield's frame and tiles; conservative raster with per-tile depths.
//! * `bsp`: the per-tile 1D BSP, flattened to slabs.
//! * [`bake`](Psf::build): all of it for a static triangle set, in parallel and deterministic.
//! * `traverse`: closest-hit and any-hit queries (2D DDA near to far, early exit).
//! * `dynamic`: the moving triangles' layer ([`DynamicLayer`]) and the two layers queried
//!   together ([`Layered`], whose hits [`Prim`] tells apart).
//! * `point`: grids by central projection around a point that a batch's rays pass.
//!
//! The modules are the crate's own; what callers use is re-exported here, so the file
//! layout is no part of the API.

mod batch;
pub(crate) mod bsp;
pub(crate) mod directions;
pub(crate) mod dynamic;
pub(crate) mod grid;
mod point;
mod stats;
mod storage;
mod traverse;
mod tree;
pub(crate) use traverse::BoxTest;
pub mod tune;

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

use glam::Vec3;
use rayon::prelude::*;

pub use bsp::{Block, BspParams, Entry, TileHeader};
pub use directions::{subfield_directions, tetrahedron_directions, DirectionTable, MAX_LEVEL};
pub use dynamic::{DynamicLayer, DynamicStats, Layered, Prim};
pub use grid::GridFrame;
pub use stats::{Histogram, PsfStats, RayStats};
pub use storage::{Buf, SharedBytes};
pub use tune::{tune, Quality, SampleRays, Trial, TuneEvent, TuneRecord, Tuning};

use crate::geometry::Aabb;
use point::PointCache;

/// How a PSF is built. The defaults (level 1, 128 tiles) come from `cargo bench --bench
/// sweep` on a 100k-triangle room: the best random-ray speed, near-best camera-ray
/// speed, and a third of level 2's memory (see README).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PsfParams {
    /// Tetrahedron subdivision level, 0..=4 (4, 10, 34, 130, 514 directions).
    pub level: u32,
    /// Tiles along the longer side of each subfield's base rectangle, 1..=4096.
    pub tiles: u32,
}

impl Default for PsfParams {
    fn default() -> Self {
        PsfParams {
            level: 1,
            tiles: 128,
        }
    }
}

impl PsfParams {
    pub const MAX_TILES: u32 = 4096;

    /// Parameters for `n` static triangles. Tiles: `0.5·√n` rounded to a power of two,
    /// within 4..=256 (10k → 64, 100k → 128, 1M → 256); `SWEEP_TRIS=10000 cargo bench
    /// --bench sweep` put 64 tiles ahead of 128 at 10k (camera 0.35× against 0.30×
    /// obvhs, random 0.27× against 0.14×), and at 100k the sweep chose 128. Level: 3
    /// below 16,384 triangles, 2 below 65,536, else 1, for the renderer's coherent rays
    /// (camera, shadow, mirror). On the museum-class scene (10,284 static + 16,384
    /// moving, camera + shadow + mirror rays, `benches/embree.rs --psf L:N`) level 2
    /// traced 9% faster than level 1 at 64 tiles (`benches/PERF.md` step 3), and level
    /// 3 8.7% faster than level 2 (PERF.md round 3, step 27; two threads, 640x480) for
    /// four times the bake time (0.06 → 0.25 s) and memory (14 → 60 MB raw, 7 → 33 MB
    /// stored); with flat tiles (PERF.md step 48) level 3 is still 5% faster there.
    /// Incoherent rays lose with more directions: on the 10k room level 3 traces random
    /// rays 37% slower than level 2 (`SWEEP_TRIS=10000 cargo bench --bench sweep`),
    /// camera rays 6% faster. At 100k the sweep put level 1 ahead on random rays, and
    /// level 2 costs 3.4 times the bake time and memory there.
    pub fn for_triangles(n: usize) -> PsfParams {
        let want = (0.5 * (n as f64).sqrt()).max(1.0);
        let tiles = (2f64.powf(want.log2().round()) as u32).clamp(4, 256);
        let level = if n < 16_384 {
            3
        } else if n < 65_536 {
            2
        } else {
            1
        };
        PsfParams { level, tiles }
    }

    /// Parameters for a bake of `n` static triangles (`subfield bake`, a render's bake in
    /// memory): [`for_triangles`](Self::for_triangles), but below [`SMALL`](Self::SMALL)
    /// triangles level 1 (7 subfields, not 109) and 16 tiles. A small scene needs few
    /// directions: on BoxAnimated (192 triangles) level 1 with 16 tiles does less
    /// counted work on its tuning sample than level 3 with 8 (`examples/tune_weights`,
    /// weighted as `psf::tune::cost`: 1.05M against 1.59M) in a file 10 times smaller
    /// (100 KB against 1.0 MB, zstd), and on CornellBox (36 triangles) 12.9M against
    /// 13.5M (level 3, 4 tiles) in 46 KB against 184 KB. The moving triangles' layer
    /// keeps `for_triangles`.
    pub fn for_static(n: usize) -> PsfParams {
        if n < Self::SMALL {
            PsfParams {
                level: 1,
                tiles: 16,
            }
        } else {
            Self::for_triangles(n)
        }
    }

    /// A scene's default bake ([`for_static`](Self::for_static)), at most level 2 (25
    /// subfields) unless its renders send parallel shadow rays (`parallel_light`: a
    /// directional light, or none at all, the default light being one; see
    /// `Scene::has_parallel_light`). The point grids take a render's camera rays, its
    /// shadow rays towards point and spot lights and its reflections off planes, so the
    /// static subfields see only the rays those leave, and there level 3 no longer
    /// pays for its bake: on the museum class (10,284 static triangles, a point light)
    /// level 2 baked in 0.08 s against 0.32 s (one thread), 8 MB against 37 MB, and
    /// traced as fast: 167 / 171 against 168 / 168 ms a frame (dolly), 57 against 57
    /// (still camera), the demo at depth 4 218–224 against 226–232, BART museum5 67–68
    /// against 67–70, each the same frames. A directional light's shadow rays are
    /// parallel, no grid gathers them, and the subfield nearest their direction serves
    /// them better the more directions there are: the demo museum lit by a sun traced
    /// 235 ms a frame at level 2 against 213 at level 3 (`benches/PERF.md`, issue 38,
    /// round 5).
    pub fn for_scene(n: usize, parallel_light: bool) -> PsfParams {
        let p = Self::for_static(n);
        if parallel_light {
            p
        } else {
            PsfParams {
                level: p.level.min(2),
                ..p
            }
        }
    }

    /// A CPU render's bake in memory (`render` without `--baked`): [`for_scene`](Self::for_scene)'s
    /// tiles at level 0 (4 subfields, not 25 or 109). On the CPU the point grids and the
    /// box tree answer a render's static queries, all but those of a ray beyond the
    /// tree's `f32` range (`BoxTree::takes`), so more directions buy a render nothing
    /// and cost it their bake: on the museum class (10,284 triangles, 2 threads) the
    /// start before the first frame went from 0.10 to 0.05 s, 0.16 to 0.07 s of CPU
    /// (`benches/PERF.md`, issue 38, round 28), the same frames to the bit. A file
    /// (`subfield bake`) keeps `for_scene`: the GPU walks its subfields.
    pub fn for_cpu_render(n: usize, parallel_light: bool) -> PsfParams {
        PsfParams {
            level: 0,
            ..Self::for_scene(n, parallel_light)
        }
    }

    /// Below this many static triangles a bake is small ([`for_static`](Self::for_static)).
    pub const SMALL: usize = 1024;

    pub fn validate(&self) -> Result<(), PsfError> {
        if self.level > MAX_LEVEL {
            return Err(PsfError::Params(format!(
                "level {} is above the maximum {MAX_LEVEL}",
                self.level
            )));
        }
        if self.tiles == 0 || self.tiles > Self::MAX_TILES {
            return Err(PsfError::Params(format!(
                "tiles {} is outside 1..={}",
                self.tiles,
                Self::MAX_TILES
            )));
        }
        Ok(())
    }
}

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PsfError {
    #[error("invalid parameters: {0}")]
    Params(String),
    #[error("triangle {triangle} has a non-finite coordinate at vertex {vertex}: {value:?}")]
    NonFinite {
        triangle: usize,
        vertex: usize,
        value: [f32; 3],
    },
    #[error("{count} triangles is more than a PSF can index ({max})")]
    TooManyTriangles { count: usize, max: usize },
    #[error("inconsistent subfield data in {what}: {detail}")]
    Inconsistent { what: String, detail: String },
}

/// One subfield: its grid and, per tile, the BSP slabs listing triangle entries, or the
/// blocks of a flat tile.
#[derive(Debug)]
pub struct Subfield {
    pub frame: GridFrame,
    /// `nu * nv` headers, row-major (`v` rows of `u` tiles).
    pub tiles: Buf<TileHeader>,
    /// Per BSP tile, `slab_count + 1` offsets into `entries`.
    pub slab_starts: Buf<u32>,
    pub entries: Buf<Entry>,
    /// The flat tiles' entries.
    pub blocks: Buf<Block>,
}

/// The static scene's parallel subfields: triangles plus one [`Subfield`] per direction.
#[derive(Debug)]
pub struct Psf {
    params: PsfParams,
    /// How the tiles' lists were laid out (not needed to trace; recorded in a file).
    bsp: BspParams,
    /// What tuning measured, for a PSF whose parameters `tune` chose.
    tuned: Option<TuneRecord>,
    bounds: Aabb,
    margin: f32,
    /// `bounds` grown by the rounding allowance: rays are clipped to it.
    clip: Aabb,
    triangles: Buf<[Vec3; 3]>,
    subfields: Vec<Subfield>,
    table: DirectionTable,
    /// Point grids over `triangles` kept from batch to batch (`point/cache.rs`).
    points: PointCache,
    /// The box tree over `triangles` (`tree.rs`), made on the first query that needs it;
    /// `None` inside where the coordinates are beyond its range.
    tree: OnceLock<Option<tree::BoxTree>>,
}

/// Refuses more triangles than a `u32` can number, and non-finite coordinates (naming
/// the triangle and vertex).
pub(crate) fn check_triangles(tris: &[[Vec3; 3]]) -> Result<(), PsfError> {
    if tris.len() > u32::MAX as usize {
        return Err(PsfError::TooManyTriangles {
            count: tris.len(),
            max: u32::MAX as usize,
        });
    }
    for (i, t) in tris.iter().enumerate() {
        for (k, v) in t.iter().enumerate() {
            if !v.is_finite() {
                return Err(PsfError::NonFinite {
                    triangle: i,
                    vertex: k,
                    value: v.to_array(),
                });
            }
        }
    }
    Ok(())
}

/// The rounding allowance for a scene within `bounds`: 1e-5 of its scale (the largest
/// coordinate magnitude or extent), some 80 float ulps. Raster, depth ranges and the
/// traversal's early exit all widen by it, so the PSF never misses a hit that the
/// triangle test reports.
pub fn margin_for(bounds: &Aabb) -> f32 {
    let scale = bounds.magnitude().max(bounds.extent().max_element());
    (1e-5 * scale).max(1e-30)
}

impl Psf {
    /// Bakes the PSF of a static triangle set.
    pub fn build(tris: &[[Vec3; 3]], params: &PsfParams) -> Result<Psf, PsfError> {
        Self::build_with_progress(tris, params, &|_, _| {})
    }

    /// As [`Psf::build`], calling `progress(done, total)` as subfields complete (from
    /// worker threads).
    pub fn build_with_progress(
        tris: &[[Vec3; 3]],
        params: &PsfParams,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<Psf, PsfError> {
        Self::build_with_layout(tris, params, &BspParams::default(), progress)
    }

    /// As [`Psf::build_with_progress`], the tiles' lists laid out by `bsp`.
    pub fn build_with_layout(
        tris: &[[Vec3; 3]],
        params: &PsfParams,
        bsp: &BspParams,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<Psf, PsfError> {
        let raster = Rasters::build(tris, params, progress)?;
        Ok(raster.assemble(tris, bsp))
    }
}

/// Every subfield's triangles listed by tile, before the tiles' lists are laid out: what
/// a bake rasterises once, so that tuning can try several [`BspParams`] on it.
pub(crate) struct Rasters {
    params: PsfParams,
    bounds: Aabb,
    margin: f32,
    clip: Aabb,
    dirs: Vec<Vec3>,
    subfields: Vec<Raster>,
}

/// One subfield's raster: its frame, and its entries by tile (`start[i]..start[i + 1]`
/// of `by_tile`, in triangle order).
struct Raster {
    frame: GridFrame,
    start: Vec<u32>,
    by_tile: Vec<Entry>,
}

impl Rasters {
    pub(crate) fn build(
        tris: &[[Vec3; 3]],
        params: &PsfParams,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<Rasters, PsfError> {
        params.validate()?;
        check_triangles(tris)?;
        let bounds = Aabb::from_triangles(tris);
        let margin = margin_for(&bounds);
        let dirs = subfield_directions(params.level);
        let grid_bounds = bounds.padded(2.0 * margin);
        let done = AtomicUsize::new(0);
        let subfields: Vec<Raster> = if tris.is_empty() {
            Vec::new()
        } else {
            dirs.par_iter()
                .map(|d| {
                    let frame = GridFrame::new(*d, &grid_bounds, params.tiles);
                    let s = raster_subfield(frame, tris, margin);
                    progress(done.fetch_add(1, Ordering::Relaxed) + 1, dirs.len());
                    s
                })
                .collect()
        };
        Ok(Rasters {
            params: *params,
            bounds,
            margin,
            clip: grid_bounds,
            dirs,
            subfields,
        })
    }

    /// The PSF of these rasters with the tiles' lists laid out by `bsp` (`tris` are the
    /// triangles rasterised).
    pub(crate) fn assemble(&self, tris: &[[Vec3; 3]], bsp: &BspParams) -> Psf {
        let subfields = self
            .subfields
            .par_iter()
            .map(|r| lay_out_subfield(r, bsp))
            .collect();
        Psf {
            params: self.params,
            bsp: *bsp,
            tuned: None,
            bounds: self.bounds,
            margin: self.margin,
            clip: self.clip,
            triangles: Buf::Owned(tris.to_vec()),
            subfields,
            table: DirectionTable::new(&self.dirs),
            points: PointCache::default(),
            tree: OnceLock::new(),
        }
    }
}

impl Psf {
    /// Assembles a PSF from stored parts (a baked file), checking every index the
    /// traversal will follow: afterwards queries cannot go out of bounds.
    pub fn from_parts(
        params: PsfParams,
        margin: f32,
        triangles: Buf<[Vec3; 3]>,
        subfields: Vec<Subfield>,
    ) -> Result<Psf, PsfError> {
        params.validate()?;
        let bounds = Aabb::from_triangles(&triangles);
        let dirs = subfield_directions(params.level);
        let bad = |what: String, detail: String| PsfError::Inconsistent { what, detail };
        if margin != margin_for(&bounds) {
            return Err(bad(
                "header".into(),
                format!("margin {margin} does not match the triangles' bounds"),
            ));
        }
        let expected = if triangles.is_empty() { 0 } else { dirs.len() };
        if subfields.len() != expected {
            return Err(bad(
                "header".into(),
                format!(
                    "{} subfields, level {} needs {expected}",
                    subfields.len(),
                    params.level
                ),
            ));
        }
        for (i, t) in triangles.iter().enumerate() {
            if !t.iter().all(|v| v.is_finite()) {
                return Err(bad(
                    "triangles".into(),
                    format!("triangle {i} has a non-finite coordinate"),
                ));
            }
        }
        let ntri = triangles.len() as u64;
        // Per subfield, in parallel; the first failure in subfield order is reported.
        let check = |(k, s): (usize, &Subfield)| -> Result<(), PsfError> {
            let what = || format!("subfield[{k}]");
            let f = &s.frame;
            let nums = [f.d, f.u, f.v].iter().all(|v| v.is_finite())
                && [f.u0, f.v0, f.tile, f.inv_tile]
                    .iter()
                    .all(|x| x.is_finite())
                && f.tile > 0.0;
            if !nums
                || f.nu == 0
                || f.nv == 0
                || f.nu > PsfParams::MAX_TILES
                || f.nv > PsfParams::MAX_TILES
            {
                return Err(bad(
                    what(),
                    "frame has non-finite numbers or a bad tile count".into(),
                ));
            }
            if (f.d - dirs[k]).length() > 1e-6 {
                return Err(bad(
                    what(),
                    format!(
                        "direction {:?} is not direction {k} of level {}",
                        f.d, params.level
                    ),
                ));
            }
            if s.tiles.len() != f.tile_count() {
                return Err(bad(
                    what(),
                    format!(
                        "{} tile headers for a {}x{} grid",
                        s.tiles.len(),
                        f.nu,
                        f.nv
                    ),
                ));
            }
            let nslab = s.slab_starts.len() as u64;
            for (ti, h) in s.tiles.iter().enumerate() {
                if h.is_flat() {
                    let n = h.blocks().len();
                    if n == 0 || n * bsp::LANES > bsp::FLAT_MAX || h.blocks().end > s.blocks.len() {
                        return Err(bad(
                            what(),
                            format!("flat tile {ti} header {h:?} is out of range"),
                        ));
                    }
                    continue;
                }
                if h.slab_count == 0 {
                    continue;
                }
                let end = h.first_slab as u64 + h.slab_count as u64 + 1;
                if h.slab_count as usize > bsp::MAX_SLABS
                    || end > nslab
                    || !h.z0.is_finite()
                    || !h.inv_slab.is_finite()
                {
                    return Err(bad(
                        what(),
                        format!("tile {ti} header {h:?} is out of range"),
                    ));
                }
                let st = &s.slab_starts[h.first_slab as usize..end as usize];
                if st.windows(2).any(|w| w[0] > w[1]) || st[st.len() - 1] as usize > s.entries.len()
                {
                    return Err(bad(
                        what(),
                        format!("tile {ti} slab offsets are not ascending within the entries"),
                    ));
                }
            }
            if let Some((i, e)) = s
                .entries
                .iter()
                .enumerate()
                .find(|(_, e)| e.tri as u64 >= ntri)
            {
                return Err(bad(
                    what(),
                    format!("entry {i} names triangle {} of {ntri}", e.tri),
                ));
            }
            // Padding lanes name triangle 0, which exists whenever there are blocks (an
            // empty scene has no subfields).
            let top = s
                .blocks
                .iter()
                .map(|b| b.tri.iter().max().copied().unwrap_or(0))
                .max();
            if let Some((i, t)) = top.filter(|&t| t as u64 >= ntri).and_then(|_| {
                s.blocks
                    .iter()
                    .enumerate()
                    .find_map(|(i, b)| b.tri.iter().find(|&&t| t as u64 >= ntri).map(|t| (i, t)))
            }) {
                return Err(bad(
                    what(),
                    format!("block {i} names triangle {t} of {ntri}"),
                ));
            }
            Ok(())
        };
        let checked: Vec<Result<(), PsfError>> =
            subfields.par_iter().enumerate().map(check).collect();
        checked.into_iter().collect::<Result<(), PsfError>>()?;
        Ok(Psf {
            params,
            bsp: BspParams::default(),
            tuned: None,
            bounds,
            margin,
            clip: bounds.padded(2.0 * margin),
            triangles,
            subfields,
            table: DirectionTable::new(&dirs),
            points: PointCache::default(),
            tree: OnceLock::new(),
        })
    }

    /// The point grids kept for this PSF's triangles.
    pub(crate) fn point_cache(&self) -> &PointCache {
        &self.points
    }

    /// How many grids over the static triangles around a camera, a light or a mirror
    /// image (point grids) are kept from batch to batch now: at most eight (see
    /// [`set_point_grid_capacity`](Psf::set_point_grid_capacity)), the least recently
    /// used dropped first. A camera that moves every frame leaves up to eight behind;
    /// each holds 12 bytes an entry and 4 a tile (33 MiB for a camera's view of the
    /// million-triangle room at 640x480).
    pub fn kept_point_grids(&self) -> usize {
        self.points.len()
    }

    /// How many point grids are kept at most (eight unless set).
    pub fn point_grid_capacity(&self) -> usize {
        self.points.capacity()
    }

    /// Keeps at most `capacity` point grids from now on (0: none, each batch then
    /// builds its grids again), dropping the least recently used beyond it now. Hits do
    /// not depend on it, only the time a batch takes and the memory held.
    pub fn set_point_grid_capacity(&self, capacity: usize) {
        self.points.set_capacity(capacity);
    }

    /// Drops every kept point grid, to free their memory; later batches build them
    /// again. The capacity stays, and so does the static triangles' copy in the test's
    /// form (48 bytes a triangle), which the parallel subfields' walk reads too.
    pub fn clear_point_grids(&self) {
        self.points.clear();
    }

    pub fn params(&self) -> &PsfParams {
        &self.params
    }

    /// How the tiles' lists were laid out: as baked, or as a baked file records it.
    pub fn bsp_params(&self) -> &BspParams {
        &self.bsp
    }

    /// What tuning measured, when [`tune`] chose this PSF's parameters (or the file it
    /// was opened from records it).
    pub fn tuning(&self) -> Option<&TuneRecord> {
        self.tuned.as_ref()
    }

    /// Records how the file this PSF was opened from says it was baked (the reader has
    /// checked the record's ranges). Hits do not depend on it.
    pub(crate) fn with_record(mut self, bsp: BspParams, tuned: Option<TuneRecord>) -> Psf {
        self.bsp = bsp;
        self.tuned = tuned;
        self
    }

    pub(crate) fn set_tuning(&mut self, t: TuneRecord) {
        self.tuned = Some(t);
    }

    /// Bytes of the arrays a baked file stores (before compression): triangles, frames,
    /// and every subfield's tile headers, slab starts, entries and blocks.
    pub fn raw_bytes(&self) -> u64 {
        let mut n = std::mem::size_of_val(self.triangles()) as u64
            + (self.subfields.len() * std::mem::size_of::<GridFrame>()) as u64;
        for sf in &self.subfields {
            n += (std::mem::size_of_val(&*sf.tiles)
                + std::mem::size_of_val(&*sf.slab_starts)
                + std::mem::size_of_val(&*sf.entries)
                + std::mem::size_of_val(&*sf.blocks)) as u64;
        }
        n
    }

    pub fn bounds(&self) -> &Aabb {
        &self.bounds
    }

    pub fn margin(&self) -> f32 {
        self.margin
    }

    /// The box tree over the triangles (`None` where the coordinates are beyond its
    /// range): the one [`prepare_tree`](Self::prepare_tree) built, or built now on this
    /// thread alone while any other query that needs it waits (a build forked on the
    /// pool here could take, while it waits for a half, another query's task that would
    /// find the lock held by its own thread).
    #[inline]
    pub(crate) fn tree(&self) -> Option<&tree::BoxTree> {
        self.tree
            .get_or_init(|| tree::BoxTree::build(&self.triangles, self.margin, false))
            .as_ref()
    }

    /// Builds the box tree on the pool's threads, unless it is built: for a caller about
    /// to trace, while no query runs (a render before its frames). 5 ms for the museum's
    /// 10,284 triangles, 0.4 s for a million on 2 threads.
    pub fn prepare_tree(&self) {
        if self.tree.get().is_none() {
            let built = tree::BoxTree::build(&self.triangles, self.margin, true);
            let _ = self.tree.set(built);
        }
    }

    pub fn triangles(&self) -> &[[Vec3; 3]] {
        &self.triangles
    }

    pub fn subfields(&self) -> &[Subfield] {
        &self.subfields
    }

    /// The box rays are clipped to: the bounds grown by the rounding allowance.
    pub fn clip(&self) -> &Aabb {
        &self.clip
    }

    /// The direction → subfield table a query picks its subfield by.
    pub fn direction_table(&self) -> &DirectionTable {
        &self.table
    }
}

/// Rasterises every triangle into one subfield, the entries sorted by tile. Sequential
/// within the subfield, so the layout depends on the input order alone.
fn raster_subfield(frame: GridFrame, tris: &[[Vec3; 3]], margin: f32) -> Raster {
    let ntiles = frame.tile_count();
    let mut raw: Vec<(u32, Entry)> = Vec::new();
    for (i, t) in tris.iter().enumerate() {
        frame.raster(t, margin, |tile, zmin, zmax| {
            raw.push((
                tile,
                Entry {
                    tri: i as u32,
                    zmin,
                    zmax,
                },
            ))
        });
    }
    // Counting sort by tile; stable, so entries stay in triangle order.
    let mut start = vec![0u32; ntiles + 1];
    for (t, _) in &raw {
        start[*t as usize + 1] += 1;
    }
    for i in 0..ntiles {
        start[i + 1] += start[i];
    }
    let mut by_tile = vec![Entry::default(); raw.len()];
    let mut cursor = start.clone();
    for (t, e) in raw {
        by_tile[cursor[t as usize] as usize] = e;
        cursor[t as usize] += 1;
    }
    Raster {
        frame,
        start,
        by_tile,
    }
}

/// One subfield's tiles laid out from its raster: each tile flat or a BSP (`bsp`).
fn lay_out_subfield(r: &Raster, layout: &BspParams) -> Subfield {
    let (frame, start, by_tile) = (r.frame, &r.start, &r.by_tile);
    let ntiles = frame.tile_count();
    let mut tiles = Vec::with_capacity(ntiles);
    let mut slab_starts = Vec::new();
    let mut entries = Vec::new();
    let mut blocks = Vec::new();
    for i in 0..ntiles {
        let list = &by_tile[start[i] as usize..start[i + 1] as usize];
        tiles.push(bsp::build_tile(
            list,
            layout,
            &mut slab_starts,
            &mut entries,
            &mut blocks,
        ));
    }
    Subfield {
        frame,
        tiles: tiles.into(),
        slab_starts: slab_starts.into(),
        entries: entries.into(),
        blocks: blocks.into(),
    }
}

#[cfg(test)]
mod params_tests {
    use super::PsfParams;

    #[test]
    fn tile_count_follows_the_triangle_count() {
        let t = |n| PsfParams::for_triangles(n).tiles;
        assert_eq!(
            [t(0), t(36), t(10_000), t(100_000), t(1_000_000)],
            [4, 4, 64, 128, 256]
        );
        assert!(PsfParams::for_triangles(123_456).validate().is_ok());
        let s = |n| PsfParams::for_static(n);
        assert_eq!(
            s(192),
            PsfParams {
                level: 1,
                tiles: 16
            }
        );
        assert_eq!(
            s(1023),
            PsfParams {
                level: 1,
                tiles: 16
            }
        );
        assert_eq!(s(1024), PsfParams::for_triangles(1024));
        assert_eq!(s(100_000), PsfParams::for_triangles(100_000));
        // Without parallel shadow rays level 3 gives way to 2; with them it stays.
        let lit = |n, sun| PsfParams::for_scene(n, sun).level;
        assert_eq!(
            [
                lit(1023, false),
                lit(10_284, false),
                lit(16_384, false),
                lit(100_000, false)
            ],
            [1, 2, 2, 1]
        );
        assert_eq!(
            [
                lit(1023, true),
                lit(10_284, true),
                lit(16_384, true),
                lit(100_000, true)
            ],
            [1, 3, 2, 1]
        );
        assert_eq!(
            PsfParams::for_scene(10_284, false).tiles,
            PsfParams::for_static(10_284).tiles
        );
        // A CPU render's bake in memory: level 0, the scene's tiles.
        for (n, sun) in [(500, false), (10_284, true), (100_000, false)] {
            assert_eq!(
                PsfParams::for_cpu_render(n, sun),
                PsfParams {
                    level: 0,
                    ..PsfParams::for_scene(n, sun)
                }
            );
        }
        let l = |n| PsfParams::for_triangles(n).level;
        assert_eq!(
            [
                l(36),
                l(16_383),
                l(16_384),
                l(65_535),
                l(65_536),
                l(1_000_000)
            ],
            [3, 3, 2, 2, 1, 1]
        );
    }
}
