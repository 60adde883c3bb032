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
//! batch gets grids around up to [`MAX_POINTS`](plan::MAX_POINTS) points, a ray takes the first that
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
//! ([`MERGE`](plan::MERGE)): the copy costs less than every ray's second tile. Where the static
//! triangles are few beside the batch's rays the second tile costs more than the build
//! saves, and the batch builds one grid over all the triangles instead ([`SPLIT`](plan::SPLIT)).
//! Every grid lists its triangles by the rules below, whatever batch it was built for,
//! and a kept grid serves a batch only with its own point and numbers (the rays qualify
//! by them) and only where its margin covers the batch's: so the hits do not depend on
//! which grids were kept.
//!
//! # Why every hit is found
//!
//! The six faces of a cube around `C` each get a grid over the projection
//! `p = (u / z, v / z)` of their frustum (`z` along the face's axis). A ray qualifies
//! ([`aim`](project::aim)) when its line passes within `rho_max` of `C` and its segment lies on one
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
//!
//! # Files
//!
//! One concept a file; [`types`] holds what the others share and uses only [`project`].
//!
//! * [`project`]: the cube faces' geometry, qualification, outward rounding.
//! * [`types`]: tiles, entries, the point ([`Around`](types::Around)), rectangles, sources.
//! * [`center`]: the centre search over a sample of the batch.
//! * [`spread`]: the sampling of a batch's rays by point.
//! * [`plan`]: which grids a batch gets around which points.
//! * [`build`]: the grid build (triangles listed, sorted by depth, written by tile).
//! * [`merge`]: a kept static grid and a moving one merged into one.
//! * [`cache`]: the kept static grids.
//! * [`query`]: one ray through a plan's grids.
//! * [`trace`]: a batch through its plans, the rest through the fallback.

mod build;
mod cache;
mod center;
mod merge;
mod plan;
mod project;
mod query;
mod spread;
mod trace;
mod types;

#[cfg(test)]
mod tests;

pub(crate) use plan::Plan;
pub(crate) use query::Group;
pub(crate) use trace::{trace_batch, trace_lists};
pub(crate) use types::{FrameGrids, PointCache, Sources, CHUNK as POINT_CHUNK};
