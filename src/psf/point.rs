//! Point subfields: tile grids by central projection around one point `C`, built for a
//! batch of rays that pass through it, such as a pinhole camera's primary rays (which
//! start at `C`) or the shadow rays towards a point light (which end just short of it).
//!
//! Such a ray is a line through `C`: seen from `C` it projects to a single point, so it
//! visits one tile, whose list is sorted by depth and scanned near to far. This is the
//! parallel subfield's tile-and-depth scheme with the beams made to meet at `C` instead
//! of running parallel (the "light buffer" of Haines and Greenberg, 1986, and the
//! perspective grids of Hunt and Mark, 2008). The grids cover the part of the view the
//! batch's rays use, and are built only where the batch has rays enough to pay for them.
//!
//! A batch may pass several points: reflections off a plane pass the camera's mirror
//! image in it, so a batch of reflections has a point for each mirror plane in view. A
//! batch gets grids around up to [`MAX_POINTS`] points, a ray takes the first that
//! qualifies it (trying first the grid that took the ray before it: neighbouring rays
//! mostly reflect off the same plane), and the rays that none takes are traced together
//! through the parallel subfields.
//!
//! A camera or a light usually stays put from frame to frame, and the static triangles
//! do not move: their grid around such a point is kept in the static PSF ([`PointCache`])
//! and each batch builds a grid over the moving triangles only; a ray scans its tile in
//! both, the two lists merged by depth. For rays that start or end at the point (a
//! light's shadow rays) the moving grid is built on the kept grid's tiles and the two
//! are merged into one, tile by tile, where the kept lists are short beside the batch
//! ([`MERGE`]): the copy costs less than every ray's second tile. Where the static
//! triangles are few beside the batch's rays the second tile costs more than the build
//! saves, and the batch builds one grid over all the triangles instead ([`SPLIT`]).
//! Every grid lists its triangles by the rules below, whatever batch it was built for,
//! and a kept grid serves a batch only with its own point and numbers (the rays qualify
//! by them) and only where its margin covers the batch's: so the hits do not depend on
//! which grids were kept.
//!
//! # Why every hit is found
//!
//! The six faces of a cube around `C` each get a grid over the projection
//! `p = (u / z, v / z)` of their frustum (`z` along the face's axis). A ray qualifies
//! ([`aim`]) when its line passes within `rho_max` of `C` and its segment lies on one
//! side of `C`'s foot on the line (up to `r / 2`); its reference direction `a` is `d` or
//! `-d` accordingly, and picks its face and tile. Every point `X` of the segment is then
//! either within `r` of `C` in each coordinate (the *near* region) or sees `C` at an
//! angle of at most `rho_max / |X - C|` from `a`.
//!
//! * Triangles whose bounding box meets the near cube `C ± r` are listed apart and
//!   tested by every ray.
//! * Every other triangle `T` lies at `max-norm >= r` from `C`, so its part inside (or
//!   within a small angle of) face `f`'s frustum has `z >= r / 2`. `T` clipped to
//!   `z >= r / 2`, projected, gives a convex polygon whose bounding rectangle, grown by
//!   `eps = 4 allowance / zmin + EPS_P` (`allowance`: the rounding margin the triangle is
//!   grown by, `rho_max`, and 1e-6 of the furthest a ray's origin or the scene reaches
//!   from `C`, for the candidate test's own rounding; at the clipped part's least depth
//!   `zmin` the projection moves by at most `(1 + |p|^2) < 4` times an angle, or `4 /
//!   zmin` times a displacement, for `|p| <= 1`; `EPS_P` for the ray's point rounded to
//!   `f32`), is listed in every tile it meets, with the clipped part's depth range
//!   `[zmin, zmax]` rounded outwards.
//!
//! A ray therefore meets no triangle outside its tile's list and the near list; within
//! the list, one whose depth range misses the ray's own depths (plus twice the
//! allowance) over its interval cannot be hit. The candidates get the same exact test as in the
//! parallel subfields, so hits (and ties) are those of brute force. Rays that do not
//! qualify take the parallel subfields.

use std::borrow::Cow;
use std::sync::{Arc, Mutex};

use glam::{DMat3, DVec3, Vec3};
use rayon::prelude::*;

use crate::geometry::{intersect_pre, Aabb, Hit, Ray, RayPre, TriPre};

/// Rays per tile the grid aims at: smaller tiles shorten the lists a ray scans and
/// lengthen the build (a large triangle is listed in more tiles).
const RAYS_PER_TILE: usize = 16;

/// A kept static grid has at least a tile for this many of its triangles (and
/// faces), however few rays built it: its build is paid once.
const TRIS_PER_TILE: usize = 4;

/// Rays sampled to find the centre and to judge whether enough rays pass through it.
const SAMPLE: usize = 256;

/// Batches of fewer rays take no grid.
const MIN_RAYS: usize = 256;

/// Sampled lines whose crossing with their neighbour's is tried as the centre.
const PAIRS: usize = 16;

/// Rays traced together by one task.
const CHUNK: usize = 1024;

/// A triangle's entry in a tile: the depth range (along the face's axis) of its part
/// beyond `r / 2`, and its number in the grid's own triangle array.
#[derive(Clone, Copy, Debug, Default)]
struct PEntry {
    zmin: f32,
    zmax: f32,
    tri: u32,
}

/// One cube face's grid over the rectangle `[u0, u0 + nu / inv] x [v0, v0 + nv / inv]`
/// of the projection, tiles numbered from `first`; `nu == 0` when no ray uses the face.
#[derive(Clone, Copy, Debug, Default)]
struct Face {
    u0: f64,
    v0: f64,
    inv: f64,
    nu: usize,
    nv: usize,
    first: usize,
}

impl Face {
    /// The tile holding point `p`, `None` outside the grid (or for a face without one).
    #[inline]
    fn tile(&self, p: [f32; 2]) -> Option<usize> {
        let x = (p[0] as f64 - self.u0) * self.inv;
        let y = (p[1] as f64 - self.v0) * self.inv;
        let inside = x >= 0.0 && y >= 0.0 && x < self.nu as f64 && y < self.nv as f64;
        inside.then(|| self.first + y as usize * self.nu + x as usize)
    }
}

/// A triangle listed in a rectangle of tiles of one face (face 6: the near list).
#[derive(Clone, Copy, Debug, Default)]
struct Item {
    face: u8,
    i0: u32,
    i1: u32,
    j0: u32,
    j1: u32,
    zmin: f32,
    zmax: f32,
    tri: u32,
}

const NEAR: u8 = 6;

/// `items` sorted by `zmin`, ties in their order (a stable radix sort, 11 bits a pass,
/// a pass skipped where every key has the same digit). Depths are positive (at least
/// `r / 2`), so their bits order them; items come in triangle order, so ties go to the
/// earlier triangle and a grid depends on its input alone. Two or three passes over a
/// few thousand items cost less than a comparison sort of them (`benches/PERF.md`,
/// step 82).
fn by_depth(mut items: Vec<Item>) -> Vec<Item> {
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
}

/// Grids over a PSF's static triangles kept from batch to batch, so that a camera or a
/// light that stays put has the static part of its grid built once; a batch then builds
/// a grid over the moving triangles only and scans both. At most [`KEPT`] grids, the
/// least recently used dropped first, and one copy of the static triangles in the
/// test's form (48 bytes a triangle), made with the first grid.
#[derive(Default)]
pub(crate) struct PointCache {
    state: Mutex<CacheState>,
}

/// Static grids kept at most.
const KEPT: usize = 8;

/// A static part that one batch does not pay for is built for a point seen before
/// only when this many batches would pay for it: a point seen twice and never again
/// costs at most this many batches' worth.
const REUSE: usize = 8;

#[derive(Default)]
struct CacheState {
    pre: Option<Arc<[TriPre]>>,
    /// Grids with the stamp of their last use.
    grids: Vec<(u64, Arc<StaticGrid>)>,
    stamp: u64,
    /// Points of recent batches that took no grid: a batch through one of them again
    /// predicts more, so its static part is built even when one batch would not pay.
    seen: Vec<Around>,
}

impl std::fmt::Debug for PointCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let grids = self.state.lock().map_or(0, |s| s.grids.len());
        f.debug_struct("PointCache").field("grids", &grids).finish()
    }
}

impl PointCache {
    /// The grids kept now.
    pub(crate) fn len(&self) -> usize {
        self.lock().grids.len()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, CacheState> {
        // A panic elsewhere while the lock was held leaves a consistent state: every
        // change below is a single push, removal or assignment.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A grid's point and the numbers fixed with it: the near cube's half size `r`, how
/// closely a line must pass `c` to qualify (`rho_max`), the furthest squared distance
/// of a ray's origin from `c` allowed for (`reach2`), and the rounding margin.
#[derive(Clone, Copy, Debug)]
struct Around {
    c: DVec3,
    r: f64,
    rho_max: f64,
    reach2: f64,
    margin: f64,
}

impl Around {
    /// How far a ray's computed hit may lie from its entry: the rounding margin the
    /// triangles are grown by, `rho_max`, and 1e-6 of the furthest a ray's origin or the
    /// scene reaches from `c`, for the candidate test's own rounding (it works relative
    /// to the ray's origin).
    fn allowance(&self) -> f64 {
        self.margin + self.rho_max + 1e-6 * (self.reach2.sqrt() + self.margin * 1e5)
    }

    /// The ray's face and projected point when it qualifies ([`aim`]).
    #[inline]
    fn aim(&self, ray: &Ray) -> Option<(u8, [f32; 2])> {
        aim(self.c, self.r, self.rho_max, ray)
    }
}

/// A grid over the static triangles, the point it was built around and the rectangles
/// of its faces.
struct StaticGrid {
    at: Around,
    rects: Rects,
    grid: PointGrid,
}

/// A grid around one point over one set of triangles, numbered `0..n` in that set.
pub(crate) struct PointGrid {
    faces: [Face; 6],
    starts: Vec<u32>,
    entries: Vec<PEntry>,
    near: Vec<u32>,
}
/// `x` rounded to an `f32` no greater than it.
#[inline]
fn down(x: f64) -> f32 {
    let y = x as f32;
    if y as f64 <= x || x.is_nan() {
        y
    } else if y.is_infinite() {
        f32::MAX
    } else {
        // At least one unit in the last place below `y`, which rounding to nearest put
        // at most that far above `x`.
        y - (y.abs() * f32::EPSILON).max(f32::MIN_POSITIVE)
    }
}

/// `x` rounded to an `f32` no less than it.
#[inline]
fn up(x: f64) -> f32 {
    let y = x as f32;
    if y as f64 >= x || x.is_nan() {
        y
    } else if y.is_infinite() {
        f32::MIN
    } else {
        y + (y.abs() * f32::EPSILON).max(f32::MIN_POSITIVE)
    }
}

/// Face `f` (axis `f / 2`, negative when `f` is odd) coordinates `(u, v, z)` of `x`.
#[inline]
fn face_coords(f: usize, x: DVec3) -> (f64, f64, f64) {
    let k = f / 2;
    let a = x.to_array();
    let z = if f % 2 == 0 { a[k] } else { -a[k] };
    (a[(k + 1) % 3], a[(k + 2) % 3], z)
}

/// The face whose frustum holds direction `a`.
#[inline]
fn face_of(a: DVec3) -> usize {
    let m = a.abs();
    let k = if m.x >= m.y && m.x >= m.z {
        0
    } else if m.y >= m.z {
        1
    } else {
        2
    };
    2 * k + (a[k] < 0.0) as usize
}

/// Whether a ray qualifies for a grid around `c` (see the module's notes), and if so
/// its reference direction: `Some(true)` for `d`, `Some(false)` for `-d`. No division.
#[inline(always)]
fn passes(c: DVec3, r: f64, rho_max: f64, ray: &Ray) -> Option<bool> {
    if !ray.is_valid() || ray.t_min > ray.t_max {
        return None;
    }
    let o = ray.origin.as_dvec3() - c;
    let d = ray.dir.as_dvec3();
    let dd = d.length_squared();
    // The line misses `c` by |o x d| / |d|; NaN (numbers that overflow here) fails.
    if o.cross(d)
        .length_squared()
        .partial_cmp(&(rho_max * rho_max * dd))
        != Some(std::cmp::Ordering::Less)
    {
        return None;
    }
    // `c`'s foot on the line is at `tc = -o.d / dd`; `half` is `r / 2` in `t`, times dd.
    let (tc, half) = (-o.dot(d), 0.5 * r * dd.sqrt());
    if ray.t_min as f64 * dd >= tc - half {
        Some(true)
    } else if ray.t_max as f64 * dd <= tc + half {
        Some(false)
    } else {
        None
    }
}

/// The face and projected point of reference direction `a` (`dir`, negated unless
/// `forward`), the point rounded to `f32` (which [`EPS_P`] allows for).
#[inline(always)]
fn project(dir: Vec3, forward: bool) -> (u8, [f32; 2]) {
    let a = if forward { dir } else { -dir }.as_dvec3();
    let f = face_of(a);
    let (u, v, z) = face_coords(f, a);
    let inv = 1.0 / z;
    (f as u8, [(u * inv) as f32, (v * inv) as f32])
}

/// The rounding of a ray's projected point (`|p| <= 1`) to `f32`, with room to spare.
const EPS_P: f64 = 2e-7;

/// `passes` and `project` together, for tests and sampling.
#[inline]
fn aim(c: DVec3, r: f64, rho_max: f64, ray: &Ray) -> Option<(u8, [f32; 2])> {
    passes(c, r, rho_max, ray).map(|fw| project(ray.dir, fw))
}

/// The point most of `sample` passes through (by `passes`), with the number that do: an
/// origin they share (a camera's rays), else the crossing of a sampled ray's line with
/// its neighbour's in the batch (the second of each pair; both of a light's shadow rays
/// pass the light) that most of the sample passes, refined by least squares over the
/// lines that pass it. Trying crossings one by one keeps rays elsewhere from pulling the
/// point away.
fn center(
    sample: &[(&Ray, Option<&Ray>)],
    passes: impl Fn(DVec3, &Ray) -> bool,
) -> Option<(DVec3, usize)> {
    let votes = |c: DVec3| sample.iter().filter(|r| passes(c, r.0)).count();
    let mut best: Option<(DVec3, usize)> = None;
    let consider = |best: &mut Option<(DVec3, usize)>, c: DVec3| {
        if c.is_finite() {
            let v = votes(c);
            if best.is_none_or(|(_, bv)| v > bv) {
                *best = Some((c, v));
            }
        }
    };
    for (r, _) in sample.iter().take(3) {
        consider(&mut best, r.origin.as_dvec3());
    }
    if best.is_some_and(|(_, v)| v * 10 >= sample.len() * 9) {
        return best;
    }
    let line = |r: &Ray| (r.origin.as_dvec3(), r.dir.as_dvec3().normalize());
    let step = (sample.len() / PAIRS).max(1);
    for (a, b) in sample.iter().step_by(step) {
        let Some(b) = b else { continue };
        let ((o1, d1), (o2, d2)) = (line(a), line(b));
        // The midpoint of the two lines' closest points.
        let w = o1 - o2;
        let k = d1.dot(d2);
        let den = 1.0 - k * k;
        if den.is_nan() || den <= 1e-12 {
            continue;
        }
        let (d, e) = (d1.dot(w), d2.dot(w));
        consider(
            &mut best,
            0.5 * (o1 + d1 * ((k * e - d) / den) + o2 + d2 * ((e - k * d) / den)),
        );
    }
    let (c, v) = best?;
    // Least squares over the lines passing `c`: the sum of the projectors off their
    // directions (each with eigenvalues 0, 1, 1), singular only for parallel lines.
    let (mut a, mut rhs) = (DMat3::ZERO, DVec3::ZERO);
    for (r, _) in sample.iter().filter(|r| passes(c, r.0)) {
        let (o, d) = line(r);
        let p = DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += p;
        rhs += p * o;
    }
    let refined = a.inverse() * rhs;
    if refined.is_finite() {
        let rv = votes(refined);
        if rv >= v {
            return Some((refined, rv));
        }
    }
    Some((c, v))
}
/// Per cube face, the rectangle its rays' points span (`u0, v0, u1, v1`) and their
/// number.
type Rects = [(f64, f64, f64, f64, usize); 6];

const NO_RECT: (f64, f64, f64, f64, usize) = (
    f64::INFINITY,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::NEG_INFINITY,
    0,
);

/// The rectangles grown by a fiftieth of their size.
fn grown(mut rects: Rects) -> Rects {
    for b in rects.iter_mut().filter(|b| b.4 > 0) {
        let grow = 0.02 * (b.2 - b.0).max(b.3 - b.1) + 1e-6;
        *b = (b.0 - grow, b.1 - grow, b.2 + grow, b.3 + grow, b.4);
    }
    rects
}

/// The static triangles in the test's form, made once and kept in the cache.
fn static_pre(src: &Sources) -> Arc<[TriPre]> {
    if let Some(p) = &src.cache.lock().pre {
        if p.len() == src.statics.len() {
            return p.clone();
        }
    }
    let p: Arc<[TriPre]> = src.statics.par_iter().map(TriPre::new).collect();
    src.cache.lock().pre = Some(p.clone());
    p
}

/// The rays of a batch through one point traced through grids around it: the static
/// triangles' (kept in the cache) and, where the scene has moving triangles, theirs
/// (built for the batch); or one grid over all of them ([`SPLIT`]).
///
/// A batch has one such point for a camera's rays or the shadow rays towards one light,
/// and one for each mirror plane among reflections (they pass the camera's image in the
/// plane). Grids for those paid once the static part was kept and the rays no grid takes
/// were traced binned (`benches/PERF.md`, step 69; steps 54 and 57 had tried them
/// without either).
pub(crate) struct Plan<'a> {
    at: Around,
    /// The static triangles' grid, when kept apart from the batch's.
    fixed: Option<Arc<StaticGrid>>,
    pre: Arc<[TriPre]>,
    /// The grid built for the batch: over the moving triangles beside `fixed`, over
    /// all of them without it.
    batch: Option<BatchGrid<'a>>,
    /// How far a hit's depth may lie outside its entry's range, and the margin of the
    /// early exit.
    depth_margin: f64,
}

/// A grid built for one batch, its triangles in the test's form and their hit numbers.
struct BatchGrid<'a> {
    grid: PointGrid,
    tris: Cow<'a, [TriPre]>,
    number: Vec<u32>,
}

/// Two grids (the static part kept, the moving part built) cost each ray a second
/// tile and a merged scan; one grid over all triangles costs building the static part
/// again. The static part is kept apart when it has at least a sixth as many
/// triangles times faces as the batch has rays, or the scene has nothing moving
/// (`benches/PERF.md`, step 68).
const SPLIT: usize = 6;

/// For rays that start or end at the point, a kept static grid is merged with the
/// batch's moving one (built on its tiles) into one grid when it has at most this many
/// entries a ray of the batch. Copying its entries costs about what a ray's second tile
/// and merged scan cost per ray: shadow rays 19.6 -> 21.1 Mrays/s on the museum-class
/// scene (n=6). Merging the grids of reflections off mirror planes as well cost more
/// than it saved there (reflection 6.21 -> 6.11 Mrays/s, n=6; `benches/PERF.md`, step
/// 87).
const MERGE: usize = 4;

/// The batch's rays sampled to find the rectangles its rays project into: one in this
/// many. Prime, so that the sampled columns of an image's rows move from row to row and
/// together reach its last columns at the usual widths (8, and round 7's 32, sampled the
/// same columns in every row; 17 spent half the time of 8 and 31 less again, for the
/// same rays taken, `benches/PERF.md`, steps 84 and 88).
const SPREAD: usize = 31;

/// `out[i] = query(rays[i])` through point grids where the batch takes any
/// ([`Plan::for_batch`]), `wrap` turning a grid's answer into `T`; the rays no grid takes
/// (all of them, when the batch takes no grid) are answered together by `fallback`.
pub(crate) fn trace_batch<const ANY: bool, T: Send + Sync + Copy + Default>(
    rays: &[Ray],
    out: &mut [T],
    src: &Sources,
    wrap: impl Fn(Option<Hit>) -> T + Sync,
    fallback: impl Fn(&[Ray], &mut [T]),
) {
    assert_eq!(rays.len(), out.len(), "one output slot per ray");
    let plans = Plan::for_batch(rays, src);
    if plans.is_empty() {
        return fallback(rays, out);
    }
    // Each ray through a grid that takes it; per chunk, the others' places.
    let missed: Vec<Vec<u32>> = rays
        .par_chunks(CHUNK)
        .zip(out.par_chunks_mut(CHUNK))
        .map(|(rays, out)| {
            let mut miss = Vec::new();
            // Neighbouring rays mostly take the same grid (a mirror plane's reflections
            // lie together in the image): the one that took the last ray is tried
            // first, which saved a reflection batch a qualification or two a ray
            // (`benches/PERF.md`, step 85). Any grid that takes a ray gives it the same
            // hit.
            let mut last = 0;
            for (i, (ray, o)) in rays.iter().zip(out).enumerate() {
                let hit = plans[last].query::<ANY>(ray).or_else(|| {
                    plans.iter().enumerate().find_map(|(k, p)| {
                        let h = if k == last { None } else { p.query::<ANY>(ray) };
                        h.inspect(|_| last = k)
                    })
                });
                match hit {
                    Some(hit) => *o = wrap(hit),
                    None => miss.push(i as u32),
                }
            }
            miss
        })
        .collect();
    let total: usize = missed.iter().map(Vec::len).sum();
    if total == 0 {
        return;
    }
    // The rest traced as one batch (binned by subfield, in parallel), the answers put
    // back chunk by chunk.
    // In parallel, chunk by chunk into its own part (a serial gather of the 100,000 or
    // so reflections that take the parallel subfields cost 1–2 ms a frame).
    let mut gathered: Vec<Ray> = (0..total).into_par_iter().map(|_| rays[0]).collect();
    let mut into = Vec::with_capacity(missed.len());
    let mut rest = &mut gathered[..];
    for m in &missed {
        let (head, tail) = rest.split_at_mut(m.len());
        into.push(head);
        rest = tail;
    }
    into.into_par_iter()
        .zip(missed.par_iter().zip(rays.par_chunks(CHUNK)))
        .for_each(|(out, (m, rays))| {
            for (o, &i) in out.iter_mut().zip(m) {
                *o = rays[i as usize];
            }
        });
    let mut answers: Vec<T> = (0..total).into_par_iter().map(|_| T::default()).collect();
    fallback(&gathered, &mut answers);
    let mut parts = Vec::with_capacity(missed.len());
    let mut rest = &answers[..];
    for m in &missed {
        let (head, tail) = rest.split_at(m.len());
        parts.push(head);
        rest = tail;
    }
    out.par_chunks_mut(CHUNK)
        .zip(missed.par_iter().zip(parts))
        .for_each(|(out, (m, a))| {
            for (&i, &x) in m.iter().zip(a) {
                out[i as usize] = x;
            }
        });
}

/// The rays of a batch a point's grids would take, as sampled by [`spread`].
#[derive(Clone, Copy)]
struct Spread {
    /// Per face, the rectangle their projected points span, and their number.
    rects: Rects,
    /// The greatest squared distance of their origins from the point.
    far2: f64,
    /// How many of them start at the point (within `r`) or end at it, as camera and
    /// shadow rays do.
    ends: usize,
}

/// For each point of `ats`, every `SPREAD`th ray of `rays` that qualifies by it and by
/// none before it.
fn spread(rays: &[Ray], ats: &[Around]) -> Vec<Spread> {
    let n = rays.len();
    let none = Spread {
        rects: [NO_RECT; 6],
        far2: 0.0,
        ends: 0,
    };
    let empty = vec![none; ats.len()];
    (0..n.div_ceil(SPREAD * CHUNK))
        .into_par_iter()
        .map(|k| {
            let mut b = empty.clone();
            let end = ((k + 1) * SPREAD * CHUNK).min(n);
            // The sampled rays copied first: a loop of loads alone keeps many in flight.
            let local: Vec<Ray> = rays[k * SPREAD * CHUNK..end]
                .iter()
                .step_by(SPREAD)
                .copied()
                .collect();
            for ray in &local {
                let first = ats
                    .iter()
                    .enumerate()
                    .find_map(|(i, at)| Some((i, passes(at.c, at.r, at.rho_max, ray)?)));
                if let Some((i, forward)) = first {
                    let (f, q) = project(ray.dir, forward);
                    let (pu, pv) = (q[0] as f64, q[1] as f64);
                    let s = &mut b[i];
                    s.rects[f as usize] = union(s.rects[f as usize], (pu, pv, pu, pv, SPREAD));
                    let d2 = (ray.origin.as_dvec3() - ats[i].c).length_squared();
                    s.far2 = s.far2.max(d2);
                    if !forward || d2 <= ats[i].r * ats[i].r {
                        s.ends += SPREAD;
                    }
                }
            }
            b
        })
        .reduce(
            || empty.clone(),
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    for (r, s) in x.rects.iter_mut().zip(y.rects) {
                        *r = union(*r, s);
                    }
                    x.far2 = x.far2.max(y.far2);
                    x.ends += y.ends;
                }
                a
            },
        )
}

fn union(
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

/// Points a batch may have grids around, at most.
const MAX_POINTS: usize = 8;

/// What a batch's grids leave in the cache for later batches.
enum Keep {
    /// A point that took no grid: one of the points seen (the most recent [`KEPT`]).
    Seen(Around),
    /// A static grid built for the batch, kept (least recently used dropped beyond
    /// [`KEPT`]) in place of the one it `replaces`.
    Grid {
        fresh: Arc<StaticGrid>,
        replaces: Option<Arc<StaticGrid>>,
    },
}

impl Keep {
    fn enter(self, cache: &PointCache) {
        let mut st = cache.lock();
        match self {
            Keep::Seen(at) => {
                st.seen.retain(|s| (s.c - at.c).length() > at.r);
                st.seen.push(at);
                if st.seen.len() > KEPT {
                    st.seen.remove(0);
                }
            }
            Keep::Grid { fresh, replaces } => {
                st.stamp += 1;
                let stamp = st.stamp;
                let at = fresh.at;
                st.seen.retain(|s| (s.c - at.c).length() > at.r);
                if let Some(g) = &replaces {
                    st.grids.retain(|(_, x)| !Arc::ptr_eq(x, g));
                }
                st.grids.push((stamp, fresh));
                if st.grids.len() > KEPT {
                    let oldest = (0..st.grids.len())
                        .min_by_key(|&i| st.grids[i].0)
                        .unwrap_or(0);
                    st.grids.remove(oldest);
                }
            }
        }
    }
}

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
    /// Grids for `rays` over `src`: around each point that a share of a sample passes
    /// (at most [`MAX_POINTS`]), where the rays through it are enough to pay for what
    /// must be built. Empty when there are none.
    ///
    /// A camera's rays pass one point and a light's shadow rays another; reflections
    /// off a plane pass the camera's mirror image in it, a point a plane. The points of
    /// kept grids come first (the most recently used first), then crossings of the
    /// lines of the sample's other rays ([`center`]), the one most pass first.
    ///
    /// The build costs about 30 ns a triangle and cube face used (two threads), a ray
    /// taken off the parallel subfields saves some 0.4–0.6 µs: a point pays for a grid
    /// over at least a twelfth as many rays as triangles times faces. A camera's rays
    /// use one to three faces, a light's six (`benches/PERF.md`, step 64). The static
    /// part is built when the point's rays pay for all of it, or when the point was seen
    /// in a recent batch (a camera or light that stays put); once kept, a batch pays only
    /// for the moving triangles' grid.
    pub(crate) fn for_batch(rays: &[Ray], src: &'a Sources<'a>) -> Vec<Plan<'a>> {
        let ntri = src.statics.len() + src.moving_pre.len();
        let n = rays.len();
        if ntri == 0 || n < MIN_RAYS || ntri >= u32::MAX as usize {
            return Vec::new();
        }
        let margin = src.margin as f64;
        let valid = |i: usize| rays[i].is_valid();
        let sample: Vec<(&Ray, Option<&Ray>)> = (0..n)
            .step_by((n / SAMPLE).max(1))
            .filter(|&i| valid(i))
            .map(|i| (&rays[i], (i + 1 < n && valid(i + 1)).then(|| &rays[i + 1])))
            .collect();
        // A point is tried when this many of the sample pass it.
        let least = (sample.len() / 32).max(8);
        let mut rest = sample;
        let mut points: Vec<(Around, Option<Arc<StaticGrid>>, bool)> = Vec::new();
        let seen = {
            let mut st = src.cache.lock();
            st.stamp += 1;
            let stamp = st.stamp;
            for (used, g) in st.grids.iter_mut().rev() {
                if points.len() == MAX_POINTS {
                    break;
                }
                if g.at.margin < margin {
                    continue;
                }
                let v = rest.iter().filter(|r| g.at.aim(r.0).is_some()).count();
                if v >= least {
                    *used = stamp;
                    points.push((g.at, Some(g.clone()), false));
                    rest.retain(|r| g.at.aim(r.0).is_none());
                }
            }
            st.seen.clone()
        };
        // `margin` is 1e-5 of the scene's scale (`margin_for`); the near cube is a 256th
        // of it, so its list is short and `eps` stays small beyond it.
        let r = margin * 1e5 / 256.0;
        // How closely a line must pass the centre: a ray aimed at it from `o` misses it
        // by the rounding of its direction, some 1e-7 of the distance; allow a hundred
        // times that for a point as far from the scene as it is.
        let middle = src.bounds.center().as_dvec3();
        let rho_of = |c: DVec3| margin.max(1e-5 * ((c - middle).length() + margin * 1e5));
        while points.len() < MAX_POINTS && rest.len() >= least {
            let Some((c, v)) = center(&rest, |c, ray| aim(c, r, rho_of(c), ray).is_some()) else {
                break;
            };
            if v < least {
                break;
            }
            let at = Around {
                c,
                r,
                rho_max: rho_of(c),
                reach2: 0.0,
                margin,
            };
            // Seen before: nine in ten of the rays through this point pass a seen one.
            let mine: Vec<&Ray> = rest
                .iter()
                .map(|r| r.0)
                .filter(|r| at.aim(r).is_some())
                .collect();
            let again = seen.iter().any(|s| {
                s.margin >= margin
                    && mine.iter().filter(|r| s.aim(r).is_some()).count() * 10 >= mine.len() * 9
            });
            points.push((at, None, again));
            rest.retain(|r| at.aim(r.0).is_none());
        }
        let ats: Vec<Around> = points.iter().map(|p| p.0).collect();
        let spreads = spread(rays, &ats);
        // The points' grids built side by side: a build has serial stretches (the
        // gathering and sorting of its items, the prefix sums) that the other thread
        // fills with another point's build (`benches/PERF.md`, step 86). What a build
        // keeps is entered in the cache afterwards, in the points' order, so the cache,
        // and what later batches keep, does not depend on which build finished first.
        let built: Vec<(Option<Plan<'a>>, Option<Keep>)> = points
            .into_par_iter()
            .zip(spreads)
            .with_max_len(1)
            .map(|((at, kept, again), s)| {
                let mut keep = None;
                let plan = Self::around(src, at, kept, again, s, &mut keep);
                (plan, keep)
            })
            .collect();
        let mut plans = Vec::with_capacity(built.len());
        for (plan, keep) in built {
            if let Some(k) = keep {
                k.enter(src.cache);
            }
            plans.extend(plan);
        }
        plans
    }

    /// The plan through `grid`, a grid over all the triangles numbered static ones first:
    /// its triangles in one array, in the test's form, and their hit numbers.
    fn over_all(src: &'a Sources<'a>, at: Around, pre: Arc<[TriPre]>, grid: PointGrid) -> Plan<'a> {
        let nstat = src.statics.len();
        let mut tris = Vec::with_capacity(nstat + src.moving_pre.len());
        tris.extend_from_slice(&pre);
        tris.extend_from_slice(src.moving_pre);
        let number = (0..nstat as u32)
            .chain(src.moving_number.iter().map(|&k| nstat as u32 + k))
            .collect();
        Plan {
            at,
            fixed: None,
            pre,
            batch: Some(BatchGrid {
                grid,
                tris: Cow::Owned(tris),
                number,
            }),
            depth_margin: 2.0 * at.allowance(),
        }
    }

    /// The grids around `at` (kept's, when given) for the rays the batch takes through
    /// it (as [`spread`] sampled them), if they pay; `seen` when the point was seen
    /// before. What the cache should remember of it is left in `keep`.
    fn around(
        src: &'a Sources<'a>,
        at: Around,
        kept: Option<Arc<StaticGrid>>,
        seen: bool,
        spread: Spread,
        keep: &mut Option<Keep>,
    ) -> Option<Plan<'a>> {
        let margin = src.margin as f64;
        let ntri = src.statics.len() + src.moving_pre.len();
        let (rects, far2) = (spread.rects, spread.far2);
        let n: usize = rects.iter().map(|b| b.4).sum();
        // What a ray taken off the parallel subfields saves, in builds of a triangle
        // and face: 12 for camera and shadow rays; rays that pass the point on their way
        // elsewhere (reflections off a plane) saved about a quarter of that, and pay
        // for half of what that would.
        let saves = if 2 * spread.ends >= n { 12 } else { 2 };
        let faces = rects.iter().filter(|b| b.4 > 0).count();
        let nmov = src.moving_pre.len();
        // The kept grid serves when the batch's rectangles and origins lie within its
        // own; otherwise it is built again over both.
        let fits = kept.as_ref().is_some_and(|g| {
            far2 <= g.at.reach2
                && rects.iter().zip(&g.rects).all(|(a, b)| {
                    a.4 == 0 || (b.4 > 0 && a.0 >= b.0 && a.1 >= b.1 && a.2 <= b.2 && a.3 <= b.3)
                })
        });
        let nstat = src.statics.len();
        if nmov > 0 && SPLIT * nstat * faces < n {
            // One grid over all triangles, as the batch alone pays for.
            if saves * n < ntri * faces {
                return None;
            }
            let mut at = at;
            at.reach2 = 2.25 * far2 + margin * margin;
            let pre = static_pre(src);
            let grid = PointGrid::build(
                &at,
                &grown(rects),
                ntri,
                |g| {
                    if g < nstat {
                        src.statics[g]
                    } else {
                        src.moving_pre[g - nstat].vertices()
                    }
                },
                0,
            )?;
            return Some(Self::over_all(src, at, pre, grid));
        }
        let fixed = if fits {
            if saves * n < nmov * faces {
                return None;
            }
            kept?
        } else {
            // A static part kept for a point that comes again is paid for over the
            // batches to come: at the camera rays' rate, since the parallel subfields
            // trace a large scene's reflections slowly too (`benches/PERF.md`, step 76).
            let again = (kept.is_some() || seen)
                && saves * n >= nmov * faces
                && 12 * n * REUSE >= ntri * faces;
            if saves * n < ntri * faces && !again {
                *keep = Some(Keep::Seen(at));
                return None;
            }
            // The furthest origin from `c` with half again to spare, and the rectangles
            // grown by a fiftieth: a ray outside these takes the parallel subfields.
            let (mut at, mut all) = (at, grown(rects));
            at.reach2 = 2.25 * far2 + margin * margin;
            if let Some(g) = &kept {
                at.reach2 = at.reach2.max(g.at.reach2);
                for (a, b) in all.iter_mut().zip(&g.rects) {
                    if b.4 > 0 {
                        *a = if a.4 > 0 { union(*a, *b) } else { *b };
                    }
                }
            }
            let faces = all.iter().filter(|b| b.4 > 0).count().max(1);
            let min_tiles = nstat / (TRIS_PER_TILE * faces);
            let grid = PointGrid::build(&at, &all, nstat, |g| src.statics[g], min_tiles)?;
            let fresh = Arc::new(StaticGrid {
                at,
                rects: all,
                grid,
            });
            *keep = Some(Keep::Grid {
                fresh: fresh.clone(),
                replaces: kept,
            });
            fresh
        };
        let pre = static_pre(src);
        let at = fixed.at;
        let both = fixed.grid.entries.len() as u64 + 32 * n as u64 + 8 * nmov as u64;
        if nmov > 0
            && saves == 12
            && fixed.grid.entries.len() <= MERGE * n
            && both < u32::MAX as u64
        {
            let total = fixed.grid.starts.len() - 1;
            let (faces, rays) = (fixed.grid.faces, n as u64);
            let moving = PointGrid::build_on(&at, faces, total, rays, nmov, |g| {
                src.moving_pre[g].vertices()
            })?;
            let grid = PointGrid::merged(&fixed.grid, &moving, nstat as u32);
            return Some(Self::over_all(src, at, pre, grid));
        }
        let batch = if nmov == 0 {
            None
        } else {
            let grid = PointGrid::build(
                &at,
                &grown(rects),
                nmov,
                |g| src.moving_pre[g].vertices(),
                0,
            )?;
            Some(BatchGrid {
                grid,
                tris: Cow::Borrowed(src.moving_pre),
                number: src
                    .moving_number
                    .iter()
                    .map(|&k| nstat as u32 + k)
                    .collect(),
            })
        };
        Some(Plan {
            at,
            fixed: Some(fixed),
            pre,
            batch,
            depth_margin: 2.0 * at.allowance(),
        })
    }

    /// The ray's hit through these grids, `None` when they do not take it (it does not
    /// qualify, or lands outside them).
    #[inline]
    fn query<const ANY: bool>(&self, ray: &Ray) -> Option<Option<Hit>> {
        let (f, p) = self.at.aim(ray)?;
        let f = f as usize;
        if (ray.origin.as_dvec3() - self.at.c).length_squared() > self.at.reach2 {
            return None;
        }
        match (&self.fixed, &self.batch) {
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
        let pre = RayPre::new(ray.origin, ray.dir);
        let mut best: Option<Hit> = None;
        for &g in &grid.near {
            if let Some(hit) = test(&pre, g, ray, &best) {
                if take::<ANY>(&mut best, hit) {
                    return best;
                }
            }
        }
        let (window, slack) = self.window(ray, f);
        let (mut lo, mut hi) = window(best.map_or(ray.t_max as f64, |b| b.t as f64 + slack));
        for e in grid.run(tile) {
            if e.zmin > hi {
                break;
            }
            if e.zmax < lo {
                continue;
            }
            if let Some(hit) = test(&pre, e.tri, ray, &best) {
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

/// A grid's entries (`starts` over `total` tiles) cut into `jobs` ranges of whole tiles:
/// `(first tile, end tile, their entries)`, for jobs that each write their own part.
fn by_tiles<'e>(
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
    /// `a`'s lists and `b`'s (on the same tiling, `b`'s triangles numbered from
    /// `offset` on) merged tile by tile, near to far, `a`'s entry first where depths
    /// tie: the grid over both sets of triangles, so a ray scans one list.
    fn merged(a: &PointGrid, b: &PointGrid, offset: u32) -> PointGrid {
        assert_eq!(
            a.starts.len(),
            b.starts.len(),
            "merged grids share their tiling"
        );
        let total = a.starts.len() - 1;
        let starts: Vec<u32> = a.starts.iter().zip(&b.starts).map(|(x, y)| x + y).collect();
        let mut entries = vec![PEntry::default(); starts[total] as usize];
        // Tiles in ranges, one job a range, each writing its own part of `entries`.
        let jobs = (4 * rayon::current_num_threads()).clamp(1, total.max(1));
        let parts = by_tiles(&starts, &mut entries, jobs);
        let moved = |e: &PEntry| PEntry {
            tri: e.tri + offset,
            ..*e
        };
        parts.into_par_iter().for_each(|(lo, hi, out)| {
            let mut k = 0;
            for t in lo..hi {
                let (ra, rb) = (a.run(t), b.run(t));
                let (mut i, mut j) = (0, 0);
                while i < ra.len() && j < rb.len() {
                    if ra[i].zmin.to_bits() <= rb[j].zmin.to_bits() {
                        out[k] = ra[i];
                        i += 1;
                    } else {
                        out[k] = moved(&rb[j]);
                        j += 1;
                    }
                    k += 1;
                }
                for e in &ra[i..] {
                    out[k] = *e;
                    k += 1;
                }
                for e in &rb[j..] {
                    out[k] = moved(e);
                    k += 1;
                }
            }
        });
        let near = a.near.iter().copied();
        PointGrid {
            faces: a.faces,
            starts,
            entries,
            near: near.chain(b.near.iter().map(|&g| g + offset)).collect(),
        }
    }

    /// Tile `t`'s entries, near to far.
    #[inline]
    fn run(&self, t: usize) -> &[PEntry] {
        &self.entries[self.starts[t] as usize..self.starts[t + 1] as usize]
    }

    /// The grid around `at.c` over `count` triangles (`tri(g)`, numbered `g`) for rays
    /// that qualify by `at` and project into `rects`; `None` when it would list too
    /// many entries.
    fn build(
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
    fn faces_for(rects: &Rects, min_tiles: usize) -> ([Face; 6], usize) {
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
    fn build_on(
        at: &Around,
        faces: [Face; 6],
        total: usize,
        rays: u64,
        count: usize,
        tri: impl Fn(usize) -> [Vec3; 3] + Sync,
    ) -> Option<PointGrid> {
        let (c, r) = (at.c, at.r);
        let allowance = at.allowance();
        // Each triangle's rectangles of tiles, face by face, in triangle order.
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
        let items_of = |g: usize, out: &mut Vec<Item>| {
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
        };
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
        let near = items
            .iter()
            .filter(|i| i.face == NEAR)
            .map(|i| i.tri)
            .collect();
        items.retain(|i| i.face != NEAR);
        // A scene whose triangles each cover much of the view would list too many
        // entries: the parallel subfields take such a batch.
        let listed: u64 = items
            .iter()
            .map(|i| (i.i1 - i.i0 + 1) as u64 * (i.j1 - i.j0 + 1) as u64)
            .sum();
        // Entries are counted in u32: a grid of more is not built either.
        if listed > 32 * rays + 8 * count as u64 || listed >= u32::MAX as u64 {
            return None;
        }
        // Near to far within every tile: the entries are written in order of depth.
        let items = by_depth(items);
        // Tiles in ranges, one job a range: each goes through all the items in order
        // and counts (then writes) the entries of its own tiles.
        let jobs = (2 * rayon::current_num_threads()).clamp(1, total.max(1));
        let cut = |k: usize| k * total / jobs;
        let each_tile = |lo: usize, hi: usize, visit: &mut dyn FnMut(usize, &Item)| {
            for it in &items {
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
        Some(PointGrid {
            faces,
            starts,
            entries,
            near,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::Rng;

    #[test]
    fn rounding_goes_outwards() {
        let mut rng = Rng::new(3);
        for _ in 0..10_000 {
            let x = (rng.f32() as f64 - 0.5) * 10f64.powi(rng.below(20) as i32 - 10);
            assert!((down(x) as f64) <= x && (up(x) as f64) >= x, "{x}");
            // No further than two units in the last place.
            assert!(((x - down(x) as f64).abs()) <= 2.0 * (x.abs() * 1.2e-7).max(1e-38));
        }
        assert_eq!(down(1e300), f32::MAX);
        assert_eq!(up(-1e300), f32::MIN);
    }

    #[test]
    fn rays_qualify_only_on_one_side_of_the_centre() {
        let c = DVec3::new(1.0, 2.0, 3.0);
        let cf = c.as_vec3();
        let (r, rho) = (0.1, 1e-4);
        // From the centre: forwards.
        let from = Ray::new(cf, Vec3::new(0.3, -1.0, 0.2));
        assert_eq!(passes(c, r, rho, &from), Some(true));
        // Towards it, ending short of it: backwards, its face the one it comes from.
        let o = Vec3::new(5.0, 2.0, 3.0);
        let to = Ray::segment(o, (cf - o).normalize(), 0.0, 3.999);
        assert_eq!(passes(c, r, rho, &to), Some(false));
        assert_eq!(aim(c, r, rho, &to).map(|a| a.0), Some(0));
        // Through it, both sides: no.
        let through = Ray::segment(o, (cf - o).normalize(), 0.0, 8.0);
        assert_eq!(passes(c, r, rho, &through), None);
        // Missing it by more than `rho`: no.
        let off = Ray::new(cf + Vec3::new(0.0, 0.0, 1e-3), Vec3::X);
        assert_eq!(passes(c, r, rho, &off), None);
        // Not a ray at all.
        assert_eq!(passes(c, r, rho, &Ray::new(cf, Vec3::ZERO)), None);
    }

    #[test]
    fn items_sort_by_depth_ties_in_order() {
        let mut rng = Rng::new(5);
        for n in [0, 1, 2, 100, 5000] {
            let items: Vec<Item> = (0..n)
                .map(|k| Item {
                    // Few distinct depths (ties), spread over many binades.
                    zmin: (1 + rng.below(40)) as f32 * 10f32.powi(rng.below(12) as i32 - 6),
                    tri: k,
                    ..Item::default()
                })
                .collect();
            let mut want = items.clone();
            want.sort_by_key(|it| it.zmin.to_bits());
            let got = by_depth(items);
            let key = |v: &[Item]| v.iter().map(|it| (it.zmin, it.tri)).collect::<Vec<_>>();
            assert_eq!(key(&got), key(&want), "{n} items");
        }
    }

    /// A kept static grid merged with a moving one lists exactly what one grid built
    /// over both sets at once lists, entry for entry and in the same order.
    #[test]
    fn merged_grids_are_the_grid_over_both() {
        let mut rng = Rng::new(17);
        let at = Around {
            c: DVec3::new(0.5, 1.0, -0.5),
            r: 0.05,
            rho_max: 1e-4,
            reach2: 4.0,
            margin: 1e-4,
        };
        let mut tri = || {
            let a = rng.in_box(Vec3::splat(-6.0), Vec3::splat(6.0));
            let size = 0.05 + 2.0 * rng.f32();
            [a, a + size * rng.unit(), a + size * rng.unit()]
        };
        // One of each set in the near cube, listed apart.
        let c = at.c.as_vec3();
        let near = [c - Vec3::X, c + Vec3::Y, c + Vec3::Z];
        let mut statics: Vec<[Vec3; 3]> = (0..700).map(|_| tri()).collect();
        statics.push(near);
        // Some moving triangles repeat static ones, so that depths tie.
        let mut moving: Vec<[Vec3; 3]> = (0..500).map(|_| tri()).collect();
        moving.extend_from_slice(&statics[..40]);
        moving.push(near);
        // A view over three faces, rays enough for a few hundred tiles.
        let mut rects = [NO_RECT; 6];
        rects[0] = (-0.9, -0.7, 0.8, 0.9, 4000);
        rects[2] = (-1.0, -1.0, 1.0, 1.0, 2000);
        rects[5] = (-0.3, -0.2, 0.4, 0.5, 600);
        let (faces, total) = PointGrid::faces_for(&rects, 0);
        let ns = statics.len();
        let a = PointGrid::build_on(&at, faces, total, 6600, ns, |g| statics[g]).unwrap();
        let b = PointGrid::build_on(&at, faces, total, 6600, moving.len(), |g| moving[g]).unwrap();
        let all = PointGrid::build_on(&at, faces, total, 6600, ns + moving.len(), |g| {
            if g < ns {
                statics[g]
            } else {
                moving[g - ns]
            }
        })
        .unwrap();
        let m = PointGrid::merged(&a, &b, ns as u32);
        let key = |g: &PointGrid| {
            let e: Vec<(u32, u32, u32)> = g
                .entries
                .iter()
                .map(|e| (e.zmin.to_bits(), e.zmax.to_bits(), e.tri))
                .collect();
            (g.starts.clone(), e, g.near.clone())
        };
        assert!(
            all.entries.len() > 1000 && all.near.len() >= 2,
            "a grid worth merging"
        );
        assert_eq!(key(&m), key(&all));
    }

    /// A triangle whose projection lies beyond a face's grid by less than its `eps`
    /// can still be hit by a ray landing in the edge tile: the build's early cull of
    /// triangles beyond the grid must leave it listed, and drop one further out.
    #[test]
    fn triangles_just_beyond_a_grid_stay_listed() {
        let at = Around {
            c: DVec3::ZERO,
            r: 0.05,
            rho_max: 1e-4,
            reach2: 1.0,
            margin: 1e-4,
        };
        // Face 0 looks along +x: `(u, v, z) = (y, z, x)`.
        let mut rects = [NO_RECT; 6];
        rects[0] = (-0.5, -0.5, 0.5, 0.5, 64 * RAYS_PER_TILE);
        let depth = 10.0f64;
        let eps = 4.0 * at.allowance() / depth + EPS_P;
        let probe = |gap: f64| {
            let grid = PointGrid::build(
                &at,
                &rects,
                1,
                |_| {
                    // Its projection starts `gap` beyond the rectangle's right side.
                    let u = 0.5 + gap;
                    [
                        Vec3::new(depth as f32, (u * depth) as f32, 0.0),
                        Vec3::new(depth as f32, ((u + 0.01) * depth) as f32, 0.0),
                        Vec3::new(depth as f32, ((u + 0.01) * depth) as f32, 0.1),
                    ]
                },
                0,
            )
            .expect("a small grid");
            let face = grid.faces[0];
            let right = face.u0 + face.nu as f64 / face.inv;
            let edge = face.tile([(right - 1e-6) as f32, 0.0]).expect("inside");
            (right, grid.run(edge).iter().any(|e| e.tri == 0))
        };
        // Whole tiles put the grid's edge at or beyond the rectangle's: measure from it.
        let (right, _) = probe(1.0);
        let beyond = right - 0.5;
        assert!(
            probe(beyond + 0.25 * eps).1,
            "within eps of the edge: listed"
        );
        assert!(!probe(beyond + 0.01).1, "well beyond: not listed");
    }

    #[test]
    fn the_centre_of_shadow_rays_is_found_among_strays() {
        let mut rng = Rng::new(11);
        let light = Vec3::new(2.0, 7.5, -1.0);
        let rays: Vec<Ray> = (0..4000)
            .map(|_| {
                let o = rng.in_box(Vec3::splat(-5.0), Vec3::splat(5.0));
                if rng.below(5) == 0 {
                    Ray::new(o, rng.unit())
                } else {
                    let l = light - o;
                    Ray::segment(o, l / l.length(), 0.0, l.length() * (1.0 - 1e-4))
                }
            })
            .collect();
        let step = rays.len() / SAMPLE;
        let sample: Vec<(&Ray, Option<&Ray>)> = (0..rays.len())
            .step_by(step)
            .map(|i| (&rays[i], rays.get(i + 1)))
            .collect();
        let (c, v) = center(&sample, |c, ray| aim(c, 0.05, 1e-4, ray).is_some()).unwrap();
        assert!((c - light.as_dvec3()).length() < 1e-4, "{c:?}");
        assert!(v * 10 >= sample.len() * 7, "{v} of {}", sample.len());
    }
}
