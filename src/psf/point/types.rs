//! The types the point grids' parts share: a grid's tiles and entries, the point a grid
//! is built around, the rectangles a batch's rays project into, and the triangles a grid
//! is built over. Nothing here uses the sibling files but [`project`](super::project).

use std::sync::{Arc, Mutex, OnceLock};

use glam::{DVec3, Vec3};

use super::project::aim;
use crate::geometry::{Aabb, Ray, TriPre};

/// Rays traced together by one task.
pub(crate) const CHUNK: usize = 1024;

/// A triangle's entry in a tile: the depth range (along the face's axis) of its part
/// beyond `r / 2`, and its number in the grid's own triangle array.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct PEntry {
    pub(super) zmin: f32,
    pub(super) zmax: f32,
    pub(super) tri: u32,
}

/// One cube face's grid over the rectangle `[u0, u0 + nu / inv] x [v0, v0 + nv / inv]`
/// of the projection, tiles numbered from `first`; `nu == 0` when no ray uses the face.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Face {
    pub(super) u0: f64,
    pub(super) v0: f64,
    pub(super) inv: f64,
    pub(super) nu: usize,
    pub(super) nv: usize,
    pub(super) first: usize,
}

impl Face {
    /// The tile holding point `p`, `None` outside the grid (or for a face without one).
    #[inline]
    pub(super) fn tile(&self, p: [f32; 2]) -> Option<usize> {
        let x = (p[0] as f64 - self.u0) * self.inv;
        let y = (p[1] as f64 - self.v0) * self.inv;
        // A face has at most 4,096 tiles a side (`build`): `u32` converts in one
        // instruction where `usize` takes several (2.7 % of a dolly frame's instructions
        // were this lookup, benches/PERF.md, issue 38, round 9).
        let (nu, nv) = (self.nu as u32, self.nv as u32);
        let inside = x >= 0.0 && y >= 0.0 && x < f64::from(nu) && y < f64::from(nv);
        inside.then(|| self.first + (y as u32 * nu + x as u32) as usize)
    }
}

/// A triangle listed in a rectangle of tiles of one face (face 6: the near list).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Item {
    pub(super) face: u8,
    pub(super) i0: u32,
    pub(super) i1: u32,
    pub(super) j0: u32,
    pub(super) j1: u32,
    pub(super) zmin: f32,
    pub(super) zmax: f32,
    pub(super) tri: u32,
}

pub(super) const NEAR: u8 = 6;

/// The triangles a point grid is built over: the static PSF's, then the dynamic layer's
/// in its own (Morton) order, and the hit number each one reports; and the static
/// PSF's cache of grids.
pub(crate) struct Sources<'a> {
    pub statics: &'a [[Vec3; 3]],
    /// The moving triangles in the test's form, which holds their vertices exactly.
    pub moving_pre: &'a [TriPre],
    /// Hit number of moving triangle `k`, less `statics.len()`.
    pub moving_number: &'a [u32],
    /// The rounding allowance of the queries (the larger of the two layers').
    pub margin: f32,
    /// Bounds of both layers' triangles.
    pub bounds: Aabb,
    /// The static PSF's grids over `statics`, kept from batch to batch.
    pub cache: &'a PointCache,
    /// Whether every ray of the batch is known to meet the triangles' bounds (the
    /// moving triangles traced apart, the rays that miss them left out): such a ray
    /// walks through them in the parallel subfields, which costs [`WITHIN`] times the
    /// planner's usual figure or more.
    pub within: bool,
    /// The merged grids built in this frame, shared by its batches (the moving
    /// triangles do not move within a frame); `None` where none are shared.
    pub frame: Option<&'a FrameGrids>,
}

/// A frame's merged grids (a kept static grid and the moving triangles' grid on its
/// tiles, [`Plan`](super::plan::Plan)'s `MERGE`), each with the kept grid it was built
/// on: a light's shadow rays come in a batch at each depth level, and the grid one
/// batch built serves the next. The owner (a dynamic layer) empties it whenever its
/// triangles change.
#[derive(Default)]
pub(crate) struct FrameGrids {
    grids: Mutex<Vec<(Arc<StaticGrid>, Arc<super::plan::BatchGrid<'static>>)>>,
}

impl std::fmt::Debug for FrameGrids {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let grids = self.grids.lock().map_or(0, |g| g.len());
        f.debug_struct("FrameGrids").field("grids", &grids).finish()
    }
}

impl FrameGrids {
    /// The merged grid built this frame on `kept`, if any.
    pub(super) fn get(
        &self,
        kept: &Arc<StaticGrid>,
    ) -> Option<Arc<super::plan::BatchGrid<'static>>> {
        let g = self.grids.lock().unwrap_or_else(|e| e.into_inner());
        g.iter()
            .find(|(k, _)| Arc::ptr_eq(k, kept))
            .map(|(_, b)| b.clone())
    }

    /// Keeps `grid`, built this frame on `kept`.
    pub(super) fn put(&self, kept: Arc<StaticGrid>, grid: Arc<super::plan::BatchGrid<'static>>) {
        let mut g = self.grids.lock().unwrap_or_else(|e| e.into_inner());
        g.push((kept, grid));
    }

    /// Forgets every grid (the triangles changed).
    pub(crate) fn clear(&mut self) {
        self.grids
            .get_mut()
            .unwrap_or_else(|e| e.into_inner())
            .clear();
    }
}

/// What a ray that meets the (moving) triangles' bounds costs in the parallel subfields,
/// over the planner's usual figure: 17 µs a ray of two threads' time where the moving
/// triangles are clustered (the first frames of the museum-class scene), against the
/// 0.4–0.6 µs the planner takes (`benches/PERF.md`, issue 23, step 12).
pub(super) const WITHIN: usize = 8;

/// A grid's point and the numbers fixed with it: the near cube's half size `r`, how
/// closely a line must pass `c` to qualify (`rho_max`), the furthest squared distance
/// of a ray's origin from `c` allowed for (`reach2`), and the rounding margin.
#[derive(Clone, Copy, Debug)]
pub(super) struct Around {
    pub(super) c: DVec3,
    pub(super) r: f64,
    pub(super) rho_max: f64,
    pub(super) reach2: f64,
    pub(super) margin: f64,
}

impl Around {
    /// How far a ray's computed hit may lie from its entry: the rounding margin the
    /// triangles are grown by, `rho_max`, and 1e-6 of the furthest a ray's origin or the
    /// scene reaches from `c`, for the candidate test's own rounding (it works relative
    /// to the ray's origin).
    pub(super) fn allowance(&self) -> f64 {
        self.margin + self.rho_max + 1e-6 * (self.reach2.sqrt() + self.margin * 1e5)
    }

    /// The ray's face and projected point when it qualifies ([`aim`]).
    #[inline]
    pub(super) fn aim(&self, ray: &Ray) -> Option<(u8, [f32; 2])> {
        aim(self.c, self.r, self.rho_max, ray)
    }
}

/// A grid over the static triangles, the point it was built around and the rectangles
/// of its faces.
pub(super) struct StaticGrid {
    pub(super) at: Around,
    pub(super) rects: Rects,
    pub(super) grid: PointGrid,
}

/// A grid around one point over one set of triangles, numbered `0..n` in that set.
pub(crate) struct PointGrid {
    pub(super) faces: [Face; 6],
    pub(super) starts: Vec<u32>,
    pub(super) entries: Vec<PEntry>,
    pub(super) near: Vec<u32>,
}

/// Per cube face, the rectangle its rays' points span (`u0, v0, u1, v1`) and their
/// number.
pub(super) type Rects = [(f64, f64, f64, f64, usize); 6];

pub(super) const NO_RECT: (f64, f64, f64, f64, usize) = (
    f64::INFINITY,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::NEG_INFINITY,
    0,
);

/// The rectangles grown by a fiftieth of their size.
pub(super) fn grown(mut rects: Rects) -> Rects {
    for b in rects.iter_mut().filter(|b| b.4 > 0) {
        let grow = 0.02 * (b.2 - b.0).max(b.3 - b.1) + 1e-6;
        *b = (b.0 - grow, b.1 - grow, b.2 + grow, b.3 + grow, b.4);
    }
    rects
}

/// The smallest rectangle holding both, with both counts.
pub(super) fn union(
    x: (f64, f64, f64, f64, usize),
    y: (f64, f64, f64, f64, usize),
) -> (f64, f64, f64, f64, usize) {
    (
        x.0.min(y.0),
        x.1.min(y.1),
        x.2.max(y.2),
        x.3.max(y.3),
        x.4 + y.4,
    )
}

/// A grid's entries (`starts` over `total` tiles) cut into `jobs` ranges of whole tiles:
/// `(first tile, end tile, their entries)`, for jobs that each write their own part.
pub(super) fn by_tiles<'e>(
    starts: &[u32],
    entries: &'e mut [PEntry],
    jobs: usize,
) -> Vec<(usize, usize, &'e mut [PEntry])> {
    let total = starts.len() - 1;
    let cut = |k: usize| k * total / jobs;
    let mut parts = Vec::with_capacity(jobs);
    let mut rest = entries;
    for k in 0..jobs {
        let (head, tail) = rest.split_at_mut((starts[cut(k + 1)] - starts[cut(k)]) as usize);
        parts.push((cut(k), cut(k + 1), head));
        rest = tail;
    }
    parts
}

impl PointGrid {
    /// Tile `t`'s entries, near to far.
    #[inline]
    pub(super) fn run(&self, t: usize) -> &[PEntry] {
        &self.entries[self.starts[t] as usize..self.starts[t + 1] as usize]
    }
}

/// Grids over a PSF's static triangles kept from batch to batch, so that a camera or a
/// light that stays put has the static part of its grid built once; a batch then builds
/// a grid over the moving triangles only and scans both. At most [`KEPT`] grids (or the capacity set), the
/// least recently used dropped first; and one copy of the static triangles in the
/// test's form (48 bytes a triangle), made on first use, which the grids and the
/// parallel subfields' walk share ([`PointCache::pre_of`]).
#[derive(Default)]
pub(crate) struct PointCache {
    pub(super) state: Mutex<CacheState>,
    pub(super) pre: OnceLock<Arc<[TriPre]>>,
}

/// Static grids kept at most by default (and points seen that took no grid).
pub(super) const KEPT: usize = 8;

/// What the cache holds, behind its lock.
pub(super) struct CacheState {
    /// Grids with the stamp of their last use.
    pub(super) grids: Vec<(u64, Arc<StaticGrid>)>,
    pub(super) stamp: u64,
    /// Points of recent batches that took no grid: a batch through one of them again
    /// predicts more, so its static part is built even when one batch would not pay.
    pub(super) seen: Vec<Around>,
    /// Grids kept at most ([`KEPT`] unless set otherwise).
    pub(super) capacity: usize,
}
