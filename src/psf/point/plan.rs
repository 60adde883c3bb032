//! The plan of a batch: the points its rays pass, and for each the grids that pay for
//! themselves (a kept static grid, a moving grid built for the batch, both merged, or
//! one grid over all the triangles).

use std::borrow::Cow;
use std::sync::Arc;

use glam::DVec3;
use rayon::prelude::*;

use super::cache::{static_pre, Keep};
use super::center::center;
use super::project::aim;
use super::spread::{spread, Spread};
use super::trace::RayBatch;
use super::types::{grown, union, Around, PointGrid, Sources, StaticGrid, WITHIN};
use crate::geometry::{Ray, TriPre};

/// A kept static grid has at least a tile for this many of its triangles (and
/// faces), however few rays built it: its build is paid once.
const TRIS_PER_TILE: usize = 4;

/// Rays sampled to find the centre and to judge whether enough rays pass through it.
pub(super) const SAMPLE: usize = 256;

/// Batches of fewer rays take no grid.
const MIN_RAYS: usize = 256;

/// A static part that one batch does not pay for is built for a point seen before
/// only when this many batches would pay for it: a point seen twice and never again
/// costs at most this many batches' worth.
const REUSE: usize = 8;

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
    pub(super) at: Around,
    /// The static triangles' grid, when kept apart from the batch's.
    pub(super) fixed: Option<Arc<StaticGrid>>,
    pub(super) pre: Arc<[TriPre]>,
    /// The grid built for the batch: over the moving triangles beside `fixed`, over
    /// all of them without it.
    pub(super) batch: Option<Held<'a>>,
    /// How far a hit's depth may lie outside its entry's range, and the margin of the
    /// early exit.
    pub(super) depth_margin: f64,
}

/// A grid built for one batch, its triangles in the test's form and their hit numbers.
pub(crate) struct BatchGrid<'a> {
    pub(super) grid: PointGrid,
    pub(super) tris: Cow<'a, [TriPre]>,
    pub(super) number: Vec<u32>,
}

/// A plan's batch grid: its own, or a merged grid the frame's batches share
/// ([`FrameGrids`](super::types::FrameGrids)).
pub(super) enum Held<'a> {
    Own(Box<BatchGrid<'a>>),
    Shared(Arc<BatchGrid<'static>>),
}

impl<'a> std::ops::Deref for Held<'a> {
    type Target = BatchGrid<'a>;

    fn deref(&self) -> &BatchGrid<'a> {
        match self {
            Held::Own(b) => b,
            Held::Shared(b) => b,
        }
    }
}

/// Two grids (the static part kept, the moving part built) cost each ray a second
/// tile and a merged scan; one grid over all triangles costs building the static part
/// again. The static part is kept apart when it has at least a sixth as many
/// triangles times faces as the batch has rays, or the scene has nothing moving
/// (`benches/PERF.md`, step 68).
pub(super) const SPLIT: usize = 6;

/// For rays that start or end at the point, a kept static grid is merged with the
/// batch's moving one (built on its tiles) into one grid when it has at most this many
/// entries a ray of the batch. Copying its entries costs about what a ray's second tile
/// and merged scan cost per ray: shadow rays 19.6 -> 21.1 Mrays/s on the museum-class
/// scene (n=6). Merging the grids of reflections off mirror planes as well cost more
/// than it saved there (reflection 6.21 -> 6.11 Mrays/s, n=6; `benches/PERF.md`, step
/// 87).
pub(super) const MERGE: usize = 4;

/// Points a batch may have grids around, at most.
pub(super) const MAX_POINTS: usize = 8;

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
    pub(crate) fn for_batch<B: RayBatch + ?Sized>(rays: &B, src: &'a Sources<'a>) -> Vec<Plan<'a>> {
        let ntri = src.statics.len() + src.moving_pre.len();
        let n = rays.len();
        if ntri == 0 || n < MIN_RAYS || ntri >= u32::MAX as usize {
            return Vec::new();
        }
        let margin = src.margin as f64;
        let valid = |i: usize| rays.ray(i).is_valid();
        let sample: Vec<(&Ray, Option<&Ray>)> = (0..n)
            .step_by((n / SAMPLE).max(1))
            .filter(|&i| valid(i))
            .map(|i| {
                (
                    rays.ray(i),
                    (i + 1 < n && valid(i + 1)).then(|| rays.ray(i + 1)),
                )
            })
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
        let batch = Self::all_of(src, &pre, grid);
        Self::through(at, pre, Held::Own(Box::new(batch)))
    }

    /// The plan through `batch`, a grid over all the triangles.
    fn through(at: Around, pre: Arc<[TriPre]>, batch: Held<'a>) -> Plan<'a> {
        Plan {
            at,
            fixed: None,
            pre,
            batch: Some(batch),
            depth_margin: 2.0 * at.allowance(),
        }
    }

    /// `grid`, over all the triangles numbered static ones first (`pre` the static
    /// ones' test form), with its triangles in one array and their hit numbers.
    fn all_of(src: &Sources<'_>, pre: &[TriPre], grid: PointGrid) -> BatchGrid<'static> {
        let nstat = src.statics.len();
        let mut tris = Vec::with_capacity(nstat + src.moving_pre.len());
        tris.extend_from_slice(pre);
        tris.extend_from_slice(src.moving_pre);
        let number = (0..nstat as u32)
            .chain(src.moving_number.iter().map(|&k| nstat as u32 + k))
            .collect();
        BatchGrid {
            grid,
            tris: Cow::Owned(tris),
            number,
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
        let saves = if 2 * spread.ends >= n { 12 } else { 2 } * if src.within { WITHIN } else { 1 };
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
                // Both rectangles, tiled for the more rays of the two: adding the
                // counts (as a batch's own rays are added up) made every rebuild finer
                // than the one before, and a dollying frame's light grid, rebuilt as
                // its rectangles crept, had grown to 104,000 tiles (650,000 entries
                // merged a frame) for the 18,800 its batches ask (benches/PERF.md,
                // issue 38, round 13).
                for (a, b) in all.iter_mut().zip(&g.rects) {
                    if b.4 > 0 {
                        *a = if a.4 > 0 {
                            let u = union(*a, *b);
                            (u.0, u.1, u.2, u.3, a.4.max(b.4))
                        } else {
                            *b
                        };
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
        // A grid merged on this kept grid earlier in the frame (a light's shadow rays
        // of the level before) serves as it is: 3 ms a frame of the museum-class dolly
        // at 1 thread (benches/PERF.md, issue 38, round 6).
        if let Some(b) = src.frame.filter(|_| nmov > 0).and_then(|f| f.get(&fixed)) {
            return Some(Self::through(at, pre, Held::Shared(b)));
        }
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
            let batch = Self::all_of(src, &pre, grid);
            let held = match src.frame {
                Some(f) => {
                    let b = Arc::new(batch);
                    f.put(fixed.clone(), b.clone());
                    Held::Shared(b)
                }
                None => Held::Own(Box::new(batch)),
            };
            return Some(Self::through(at, pre, held));
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
            Some(Held::Own(Box::new(BatchGrid {
                grid,
                tris: Cow::Borrowed(src.moving_pre),
                number: src
                    .moving_number
                    .iter()
                    .map(|&k| nstat as u32 + k)
                    .collect(),
            })))
        };
        Some(Plan {
            at,
            fixed: Some(fixed),
            pre,
            batch,
            depth_margin: 2.0 * at.allowance(),
        })
    }
}
