//! Queries: pick the subfield of the closest direction (table lookup), clip the ray to
//! the scene bounds, walk the tiles under its projection near to far (2D DDA, in f64 so
//! far-away origins lose nothing), search each tile's BSP (or scan a flat tile's blocks)
//! over the ray's depth interval there, and stop as soon as the best hit lies before the
//! exit of the current tile.

use glam::{DVec3, Vec3A, Vec4};

use super::batch::binned;
use super::bsp::{depth_mask, Block, LANES};
use super::point::{trace_lists, Plan, Sources, POINT_CHUNK};
use super::stats::{Counter, NoCount, RayStats};
use super::{GridFrame, Psf};
use crate::geometry::{intersect_pre, Aabb, Hit, Intersector, Ray, RayPre, TriPre};

/// Walks the tiles of `frame` that the line `o + t d`, `t` in `[t0, t1]`, passes through,
/// in order of `t`, calling `visit(tile, t_enter, t_exit)` until it returns `false`.
/// Amanatides-Woo.
#[inline]
pub(crate) fn walk_tiles(
    f: &GridFrame,
    o: DVec3,
    d: DVec3,
    t0: f64,
    t1: f64,
    mut visit: impl FnMut(usize, f64, f64) -> bool,
) {
    let inv = f.inv_tile as f64;
    let (u, v) = (f.u.as_dvec3(), f.v.as_dvec3());
    let (ax, bx) = ((o.dot(u) - f.u0 as f64) * inv, d.dot(u) * inv);
    let (ay, by) = ((o.dot(v) - f.v0 as f64) * inv, d.dot(v) * inv);
    let (nu, nv) = (f.nu as i64, f.nv as i64);
    // Floor by truncation after clamping negatives to 0 (no libm call).
    let mut ix = ((ax + t0 * bx).max(0.0) as i64).min(nu - 1);
    let mut iy = ((ay + t0 * by).max(0.0) as i64).min(nv - 1);
    let (sx, sy) = (step(bx), step(by));
    // Parameter at which the line leaves the current column / row, and the parameter
    // span of one tile along each axis. Accumulating in f64 drifts by ~1e-13 of a tile
    // over the longest walk (4096 steps), far inside the rounding margin.
    let first = |i: i64, s: i64, a: f64, b: f64| {
        if s == 0 {
            f64::INFINITY
        } else {
            ((i + (s > 0) as i64) as f64 - a) / b
        }
    };
    let mut tx = first(ix, sx, ax, bx);
    let mut ty = first(iy, sy, ay, by);
    let (dtx, dty) = ((1.0 / bx).abs(), (1.0 / by).abs());
    let mut t = t0;
    loop {
        let t_exit = tx.min(ty).min(t1).max(t);
        if !visit((iy * nu + ix) as usize, t, t_exit) || t_exit >= t1 {
            return;
        }
        t = t_exit;
        if tx <= ty {
            ix += sx;
            if ix < 0 || ix >= nu {
                return;
            }
            tx += dtx;
        } else {
            iy += sy;
            if iy < 0 || iy >= nv {
                return;
            }
            ty += dty;
        }
    }
}

/// The ray as the f64 line `o + t d` and the part of `[t_min, t_max]` inside `clip`,
/// `(o, d, t0, t1)`; `None` when that is empty (NaN bounds, as of a segment like
/// `[NaN, 1]`, count as empty).
#[inline]
pub(crate) fn clipped_span(clip: &Aabb, ray: &Ray) -> Option<(DVec3, DVec3, f64, f64)> {
    let o = ray.origin.as_dvec3();
    let d = ray.dir.as_dvec3();
    let (ta, tb) = clip.clip_line(o.to_array(), d.to_array())?;
    let t0 = ta.max(ray.t_min as f64);
    let t1 = tb.min(ray.t_max as f64);
    if t0.is_nan() || t1.is_nan() || t0 > t1 {
        return None;
    }
    Some((o, d, t0, t1))
}

/// A box's bounds made ready for [`surely_outside`]: `None` where its coordinates are
/// not finite or too large for the f32 check's error bound (then every ray is "maybe").
#[derive(Clone, Copy, Debug)]
struct QuickClip {
    lo: Vec3A,
    hi: Vec3A,
}

/// Coordinates (of the box and of a ray's origin) up to this magnitude, and direction
/// components from [`QUICK_MIN_DIR`] on, keep every f32 value of [`surely_outside`]
/// finite and normal or zero: `1e15 · 1e20 = 1e35 < f32::MAX`.
const QUICK_MAX_COORD: f32 = 1e15;
const QUICK_MIN_DIR: f32 = 1e-20;

impl QuickClip {
    fn new(clip: &Aabb) -> Option<QuickClip> {
        let (lo, hi) = (Vec3A::from(clip.min), Vec3A::from(clip.max));
        let small = |v: Vec3A| v.abs().max_element() < QUICK_MAX_COORD;
        (small(lo) && small(hi) && lo.cmple(hi).all()).then_some(QuickClip { lo, hi })
    }
}

/// Whether [`clipped_span`] of `ray` against the box is certainly `None`, decided in f32
/// lanes (one division of three lanes where `clipped_span` makes three in f64): `false`
/// means "maybe", never "no".
///
/// Why a `true` is certain. With finite coordinates under `QUICK_MAX_COORD` and direction
/// components at least `QUICK_MIN_DIR` in size, every slab value `(lo - o) / d` (each
/// `(lo - o) · (1/d)` rounded three times) is the exact real value `v` times `1 + η`,
/// `|η| ≤ 3 · 2⁻²⁴ < 2e-7` (no overflow; an underflow only adds an absolute error under
/// `2⁻¹⁴⁹`), and `clip_line`'s f64 values are `v (1 + η')`, `|η'| < 1e-15`. `lower(v) =
/// v - s|v|` and `upper(v) = v + s|v|` are increasing for `s < 1`, so they pass through
/// `min` and `max`: the f32 entry `t0` lies in `[lower(T0), upper(T0)]` of the exact
/// entry `T0` (s = 2e-7), and so does f64's within 1e-15, likewise the exits. Widening the
/// f32 interval by `SLACK · |t|` (1e-5, fifty times that) plus `1e-30` thus contains the
/// f64 one, and `clipped_span` compares the f64 interval with `[t_min, t_max]` exactly:
/// an empty widened interval, or one wholly outside `[t_min, t_max]`, means `None`.
/// NaN bounds or a ray outside these ranges answer `false`.
#[inline]
fn surely_outside(clip: &QuickClip, ray: &Ray) -> bool {
    const SLACK: f32 = 1e-5;
    const TINY: f32 = 1e-30;
    let o = Vec3A::from(ray.origin);
    let d = Vec3A::from(ray.dir);
    // `<` is false for NaN: such a ray is "maybe".
    if !(o.abs().max_element() < QUICK_MAX_COORD && d.abs().min_element() >= QUICK_MIN_DIR) {
        return false;
    }
    let inv = Vec3A::ONE / d;
    let a = (clip.lo - o) * inv;
    let b = (clip.hi - o) * inv;
    let t0 = a.min(b).max_element();
    let t1 = a.max(b).min_element();
    let enter = t0 - SLACK * t0.abs() - TINY;
    let exit = t1 + SLACK * t1.abs() + TINY;
    enter > exit || enter > ray.t_max || exit < ray.t_min
}

/// A box that rays are clipped to ([`clipped_span`]), with its f32 form for the check
/// that passes over the rays far from it first ([`surely_outside`]): the moving layer's
/// bounds, which its walk, its batch filter and the replay's settled samples clip to.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BoxTest {
    clip: Aabb,
    quick: Option<QuickClip>,
}

impl BoxTest {
    pub(crate) const EMPTY: BoxTest = BoxTest {
        clip: Aabb::EMPTY,
        quick: None,
    };

    pub(crate) fn new(clip: Aabb) -> BoxTest {
        BoxTest {
            clip,
            quick: QuickClip::new(&clip),
        }
    }

    /// The box.
    pub(crate) fn aabb(&self) -> Aabb {
        self.clip
    }

    /// [`clipped_span`] of `ray` against the box, the clear misses decided in f32.
    #[inline]
    pub(crate) fn span(&self, ray: &Ray) -> Option<(DVec3, DVec3, f64, f64)> {
        if self.quick.is_some_and(|q| surely_outside(&q, ray)) {
            return None;
        }
        clipped_span(&self.clip, ray)
    }

    /// Whether [`clipped_span`] of `ray` against the box is `None`.
    #[inline]
    pub(crate) fn misses(&self, ray: &Ray) -> bool {
        self.span(ray).is_none()
    }
}

/// A triangle as a query tests it: both layers' in [`TriPre`] form (the static PSF's
/// made on first use and kept in its point cache, the dynamic layer's built every update,
/// in the Morton order).
pub(crate) trait Candidate {
    fn intersect(&self, pre: &RayPre, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)>;
}

impl Candidate for TriPre {
    #[inline(always)]
    fn intersect(&self, pre: &RayPre, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
        intersect_pre(pre, self, t_min, t_max)
    }
}

/// Tests triangle `tri` against the ray between `t_min` and the best hit so far (or
/// `t_max`): the one candidate test both layers share.
#[inline(always)]
pub(crate) fn test_candidate<T: Candidate>(
    pre: &RayPre,
    tris: &[T],
    tri: u32,
    ray: &Ray,
    best: &Option<Hit>,
) -> Option<Hit> {
    let t_max = best.map_or(ray.t_max, |b| b.t);
    tris[tri as usize]
        .intersect(pre, ray.t_min, t_max)
        .map(|(t, u, v)| Hit { t, tri, u, v })
}

/// The ray's depth interval over a tile, from `t_enter` to the tile's exit cut at the best
/// hit so far, grown by the margin: two splats for [`depth_mask`]. `oz + t dz` is the
/// ray's depth along the subfield's direction.
#[inline(always)]
pub(crate) fn block_window(
    oz: f64,
    dz: f64,
    t_enter: f64,
    t_exit: f64,
    best: &Option<Hit>,
    slack: f64,
    margin: f32,
) -> (Vec4, Vec4) {
    let t_far = best.map_or(t_exit, |b| t_exit.min(b.t as f64 + slack));
    let (za, zb) = (oz + t_enter * dz, oz + t_far * dz);
    let (lo, hi) = ((za.min(zb) as f32) - margin, (za.max(zb) as f32) + margin);
    (Vec4::splat(lo), Vec4::splat(hi))
}

/// Tests every entry of `blocks` whose depth range meets `window`, keeping the closest
/// hit in `best` (a hit reports `number` of the entry's triangle). `false` when an
/// any-hit query has found its hit and the walk should stop. Both layers' lists of
/// blocks (flat static tiles, dynamic tiles) are scanned by it.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn scan_blocks<const ANY: bool, T: Candidate, C: Counter>(
    blocks: &[Block],
    (lo, hi): (Vec4, Vec4),
    pre: &RayPre,
    tris: &[T],
    ray: &Ray,
    best: &mut Option<Hit>,
    count: &mut C,
    number: impl Fn(u32) -> u32,
) -> bool {
    for b in blocks {
        let mut mask = depth_mask(b, lo, hi);
        while mask != 0 {
            let j = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            count.candidate();
            if let Some(mut hit) = test_candidate(pre, tris, b.tri[j], ray, best) {
                hit.tri = number(hit.tri);
                if ANY {
                    *best = Some(hit);
                    return false;
                }
                if best.is_none_or(|b| hit.is_closer_than(&b)) {
                    *best = Some(hit);
                }
            }
        }
    }
    true
}

#[inline]
fn step(b: f64) -> i64 {
    if b > 0.0 {
        1
    } else if b < 0.0 {
        -1
    } else {
        0
    }
}

impl Psf {
    /// The closest hit, also counting the work done into `stats`.
    pub fn intersect_counted(&self, ray: &Ray, stats: &mut RayStats) -> Option<Hit> {
        stats.rays += 1;
        self.trace::<false, _>(ray, stats)
    }

    /// Any hit, also counting the work done into `stats`.
    pub fn occluded_counted(&self, ray: &Ray, stats: &mut RayStats) -> bool {
        stats.rays += 1;
        self.trace::<true, _>(ray, stats).is_some()
    }

    #[inline]
    pub(crate) fn trace<const ANY: bool, C: Counter>(
        &self,
        ray: &Ray,
        count: &mut C,
    ) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        self.static_pre::<ANY, C>(ray, &RayPre::new(ray.origin, ray.dir), None, count)
    }

    /// The static hit of a valid ray with its [`RayPre`]: through the box tree
    /// ([`BoxTree`](super::tree::BoxTree)) where it takes the ray and nothing counts the
    /// walk's work, else the walk ([`trace_pre`](Self::trace_pre)). The same hit either
    /// way: both report the least by [`Hit::is_closer_than`] over the triangles
    /// [`intersect_pre`] meets (benches/PERF.md, issue 38, round 25).
    #[inline]
    pub(crate) fn static_pre<const ANY: bool, C: Counter>(
        &self,
        ray: &Ray,
        pre: &RayPre,
        sub: Option<usize>,
        count: &mut C,
    ) -> Option<Hit> {
        if !C::WALK {
            if let Some(tree) = self.tree() {
                if tree.takes(ray) {
                    return tree.trace::<ANY>(ray, pre);
                }
            }
        }
        self.trace_pre::<ANY, C>(ray, pre, sub, count)
    }

    /// [`trace`](Self::trace) of a valid ray with its [`RayPre`] given: the layered
    /// query makes one for both layers (`benches/PERF.md`, step 31). `sub` is the
    /// subfield the ray's direction picks when the caller knows it already (a batch,
    /// binned by it).
    pub(crate) fn trace_pre<const ANY: bool, C: Counter>(
        &self,
        ray: &Ray,
        pre: &RayPre,
        sub: Option<usize>,
        count: &mut C,
    ) -> Option<Hit> {
        if self.subfields.is_empty() {
            return None;
        }
        let (o, d, t0, t1) = clipped_span(&self.clip, ray)?;
        let sf = &self.subfields[sub.unwrap_or_else(|| self.table.lookup(ray.dir))];
        let (tiles, starts, entries, blocks, tris) = (
            &*sf.tiles,
            &*sf.slab_starts,
            &*sf.entries,
            &*sf.blocks,
            &**self.points.pre_of(&self.triangles),
        );
        let margin = self.margin;
        // How far (in t) a computed hit may sit from where the line truly meets its
        // triangle: the early exit waits that much longer.
        let slack = (margin as f64 + 1e-6 * o.length()) / d.length();
        let fd = sf.frame.d.as_dvec3();
        let (oz, dz) = (o.dot(fd), d.dot(fd));
        let ascending = dz >= 0.0;
        let mut best: Option<Hit> = None;

        walk_tiles(&sf.frame, o, d, t0, t1, |tile, t_enter, t_exit| {
            count.tile();
            let h = tiles[tile];
            if h.slab_count == 0 {
                return true;
            }
            if h.is_flat() {
                // Every entry meeting the depth interval, eight at a time.
                let window = block_window(oz, dz, t_enter, t_exit, &best, slack, margin);
                let run = &blocks[h.blocks()];
                count.scanned(run.len() * LANES);
                count.blocks(run.len());
                if !scan_blocks::<ANY, _, _>(run, window, pre, tris, ray, &mut best, count, |t| t) {
                    return false;
                }
                return !matches!(&best, Some(b) if b.t as f64 + slack <= t_exit);
            }
            // The ray's depth interval over this tile, cut at the best hit so far.
            let (za, zb) = (oz + t_enter * dz, oz + t_exit * dz);
            let (mut lo, mut hi) = ((za.min(zb) as f32) - margin, (za.max(zb) as f32) + margin);
            let cut = |b: &Hit| (oz + (b.t as f64 + slack) * dz) as f32;
            if let Some(b) = &best {
                if ascending {
                    hi = hi.min(cut(b) + margin);
                } else {
                    lo = lo.max(cut(b) - margin);
                }
            }
            if lo > hi {
                return true;
            }
            let (s_lo, s_hi) = (h.slab_of(lo) as i64, h.slab_of(hi) as i64);
            // Near to far: forwards along +d, backwards along -d.
            let (mut s, mut s_end, dir) = if ascending {
                (s_lo, s_hi, 1)
            } else {
                (s_hi, s_lo, -1)
            };
            let s_first = s;
            while (s - s_end) * dir <= 0 {
                let base = h.first_slab as usize + s as usize;
                count.scanned((starts[base + 1] - starts[base]) as usize);
                for e in &entries[starts[base] as usize..starts[base + 1] as usize] {
                    // One branch for the two sides (`|`, not `||`): callgrind's model
                    // put 290,000 of a dolly frame's mispredicts on this test; 60,000
                    // fewer so (`benches/PERF.md`, issue 38, round 21).
                    if (e.zmax < lo) | (e.zmin > hi) {
                        continue;
                    }
                    // Tested already in an earlier slab of this walk?
                    if s != s_first
                        && h.slab_of(if ascending { e.zmin } else { e.zmax }) as i64 != s
                    {
                        continue;
                    }
                    count.candidate();
                    if let Some(hit) = test_candidate(pre, tris, e.tri, ray, &best) {
                        if ANY {
                            best = Some(hit);
                            return false;
                        }
                        if best.is_none_or(|b| hit.is_closer_than(&b)) {
                            best = Some(hit);
                            if ascending {
                                hi = hi.min(cut(&hit) + margin);
                                s_end = h.slab_of(hi) as i64;
                            } else {
                                lo = lo.max(cut(&hit) - margin);
                                s_end = h.slab_of(lo) as i64;
                            }
                        }
                    }
                }
                s += dir;
            }
            // Every triangle hit before the tile's exit is listed in a tile walked so far.
            !matches!(&best, Some(b) if b.t as f64 + slack <= t_exit)
        });
        best
    }
}

impl Intersector for Psf {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.trace::<false, _>(ray, &mut NoCount)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.trace::<true, _>(ray, &mut NoCount).is_some()
    }

    /// Through point grids for the rays that pass a point grids pay for
    /// ([`Psf::point_grid_for`]); the others binned by subfield (`psf::batch`).
    fn intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        let chunks: Vec<&[Ray]> = rays.chunks(POINT_CHUNK).collect();
        self.traced::<false, _>(&chunks, Some(rays), out, |h| h);
    }

    fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        let chunks: Vec<&[Ray]> = rays.chunks(POINT_CHUNK).collect();
        self.traced::<true, _>(&chunks, Some(rays), out, |h| h.is_some());
    }

    /// As `intersect_batch`, the lists traced in place (`psf::point::trace_lists`).
    fn intersect_lists(&self, lists: &[&[Ray]], out: &mut [Option<Hit>]) {
        self.traced::<false, _>(lists, None, out, |h| h);
    }

    fn occluded_lists(&self, lists: &[&[Ray]], out: &mut [bool]) {
        self.traced::<true, _>(lists, None, out, |h| h.is_some());
    }
}

impl Psf {
    /// The batch of `lists` (their concatenation `whole`, where the caller has it)
    /// through point grids where they pay, the rest binned by subfield (`psf::batch`),
    /// `wrap` making each answer.
    fn traced<const ANY: bool, T: Send + Sync + Copy + Default>(
        &self,
        lists: &[&[Ray]],
        whole: Option<&[Ray]>,
        out: &mut [T],
        wrap: impl Fn(Option<Hit>) -> T + Sync,
    ) {
        let bins = self.subfields.len().max(1);
        let walk = |rays: &[Ray], out: &mut [T]| {
            binned(
                rays,
                out,
                bins,
                |r| self.bin_of(r),
                |r, k| wrap(self.trace_bin::<ANY>(r, k)),
            )
        };
        trace_lists::<ANY, _>(lists, whole, out, &self.point_sources(), &wrap, walk);
    }

    /// Whether [`intersect_batch`](Intersector::intersect_batch) and
    /// [`occluded_batch`](Intersector::occluded_batch) trace some of `rays` through point
    /// grids
    /// (see [`Layered::point_grid_for`](super::Layered::point_grid_for)). Either way the
    /// hits are the same.
    pub fn point_grid_for(&self, rays: &[Ray]) -> bool {
        !Plan::for_batch(rays, &self.point_sources()).is_empty()
    }

    /// This PSF's triangles, for a point grid.
    pub(super) fn point_sources(&self) -> Sources<'_> {
        Sources {
            statics: &self.triangles,
            moving_pre: &[],
            moving_number: &[],
            margin: self.margin,
            bounds: self.bounds,
            cache: &self.points,
            within: false,
            frame: None,
        }
    }

    /// A batch's query of one ray, its subfield `sub` found by [`bin_of`](Self::bin_of)
    /// (which is the direction lookup for every valid ray).
    #[inline]
    fn trace_bin<const ANY: bool>(&self, ray: &Ray, sub: usize) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let pre = RayPre::new(ray.origin, ray.dir);
        self.static_pre::<ANY, _>(ray, &pre, Some(sub), &mut NoCount)
    }

    /// The subfield a ray's direction picks (0 for a direction without one).
    #[inline]
    pub(crate) fn bin_of(&self, ray: &Ray) -> usize {
        if self.subfields.is_empty() || !ray.dir.is_finite() {
            0
        } else {
            self.table.lookup(ray.dir)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use proptest::prelude::*;

    fn coord() -> impl Strategy<Value = f32> {
        prop_oneof![
            -100f32..100.0,
            -1e6f32..1e6,
            Just(0.0),
            (-1e3f32..1e3).prop_map(|x| x * 1e9),
        ]
    }

    fn component() -> impl Strategy<Value = f32> {
        prop_oneof![
            4 => -1f32..1.0,
            1 => prop_oneof![Just(0.0), Just(1e-19), Just(-1e-21), Just(1e-20), Just(-1e-20)],
            1 => (-1f32..1.0).prop_map(|x| x * 1e-6),
        ]
    }

    fn bound() -> impl Strategy<Value = f32> {
        prop_oneof![
            -10f32..1e3,
            Just(0.0),
            Just(f32::INFINITY),
            Just(f32::NAN),
            Just(-f32::INFINITY),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]

        /// The f32 check is never wrong about a miss: whenever it says "surely outside",
        /// `clipped_span`'s f64 clip finds nothing. Rays are random or aimed at a point
        /// of the box's surface (a corner, an edge or a face: grazing rays, where the two
        /// precisions disagree most), with tiny and zero direction components and every
        /// kind of bound.
        #[test]
        fn surely_outside_is_never_wrong(
            lo in prop::array::uniform3(coord()),
            size in prop::array::uniform3(prop_oneof![Just(0f32), 0f32..10.0, 0f32..1e4]),
            dir in prop::array::uniform3(component()),
            aim in prop::array::uniform3(0u8..4),
            back in prop_oneof![-2f32..2.0, -1e4f32..1e4],
            origin in prop::array::uniform3(coord()),
            aimed in any::<bool>(),
            t_min in bound(),
            t_max in bound(),
            nudge in -4i32..=4,
        ) {
            let lo = Vec3::from(lo);
            let hi = lo + Vec3::from(size);
            let clip = Aabb { min: lo, max: hi };
            let Some(quick) = QuickClip::new(&clip) else {
                return Ok(());
            };
            let d = Vec3::from(dir);
            let o = if aimed {
                // A point of the surface: each coordinate at a bound or between.
                let pick = |k: usize| match aim[k] {
                    0 => lo[k],
                    1 => hi[k],
                    _ => 0.5 * (lo[k] + hi[k]),
                };
                let p = Vec3::new(pick(0), pick(1), pick(2));
                let o = p - d * back;
                // Moved by a few ulps, to either side.
                Vec3::from(o.to_array().map(|x| f32::from_bits((x.to_bits() as i32).wrapping_add(nudge) as u32)))
            } else {
                Vec3::from(origin)
            };
            let ray = Ray { origin: o, dir: d, t_min, t_max };
            if surely_outside(&quick, &ray) {
                prop_assert!(
                    clipped_span(&clip, &ray).is_none(),
                    "said outside, but the f64 clip meets the box: {ray:?} {clip:?}"
                );
            }
        }
    }

    /// The check decides the plain cases: a ray away from the box, one that passes it by,
    /// one stopped short of it are outside; one through it is not.
    #[test]
    fn surely_outside_decides_plain_cases() {
        let clip = Aabb {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        };
        let q = QuickClip::new(&clip).expect("a finite box");
        let ray = |o: [f32; 3], d: [f32; 3], t_max: f32| Ray {
            origin: Vec3::from(o),
            dir: Vec3::from(d),
            t_min: 0.0,
            t_max,
        };
        assert!(surely_outside(
            &q,
            &ray([5.0, 0.3, 0.2], [1.0, 0.1, 0.1], f32::INFINITY)
        ));
        assert!(surely_outside(
            &q,
            &ray([5.0, 3.0, 0.2], [-1.0, 0.1, 0.1], f32::INFINITY)
        ));
        assert!(surely_outside(
            &q,
            &ray([5.0, 0.3, 0.2], [-1.0, 0.1, 0.1], 3.0)
        ));
        assert!(!surely_outside(
            &q,
            &ray([5.0, 0.3, 0.2], [-1.0, 0.1, 0.1], 4.5)
        ));
        assert!(!surely_outside(
            &q,
            &ray([0.0, 0.0, 0.0], [1.0, 0.5, 0.25], 1.0)
        ));
        // A zero component is left to the f64 clip.
        assert!(!surely_outside(
            &q,
            &ray([5.0, 0.3, 0.2], [1.0, 0.0, 0.0], f32::INFINITY)
        ));
        // A box too large for the check's bound is never used.
        let huge = Aabb {
            min: Vec3::splat(-1e16),
            max: Vec3::splat(1.0),
        };
        assert!(QuickClip::new(&huge).is_none());
    }
}
