//! The sampling of a batch's rays by point: per point tried, the rectangles its rays
//! project into, how far their origins lie and how many start or end at it.

use rayon::prelude::*;

use super::project::{passes, project};
use super::trace::RayBatch;
use super::types::{union, Around, Rects, CHUNK, NO_RECT};
use crate::geometry::Ray;

/// The batch's rays sampled to find the rectangles its rays project into: one in this
/// many. Prime, so that the sampled columns of an image's rows move from row to row and
/// together reach its last columns at the usual widths (8, and round 7's 32, sampled the
/// same columns in every row; 17 spent half the time of 8 and 31 less again, for the
/// same rays taken, `benches/PERF.md`, steps 84 and 88).
const SPREAD: usize = 31;

/// The rays of a batch a point's grids would take, as sampled by [`spread`].
#[derive(Clone, Copy)]
pub(super) struct Spread {
    /// Per face, the rectangle their projected points span, and their number.
    pub(super) rects: Rects,
    /// The greatest squared distance of their origins from the point.
    pub(super) far2: f64,
    /// How many of them start at the point (within `r`) or end at it, as camera and
    /// shadow rays do.
    pub(super) ends: usize,
}

/// For each point of `ats`, every `SPREAD`th ray of `rays` that qualifies by it and by
/// none before it.
pub(super) fn spread<B: RayBatch + ?Sized>(rays: &B, ats: &[Around]) -> Vec<Spread> {
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
            let mut local: Vec<Ray> = Vec::with_capacity(CHUNK);
            rays.stepped(k * SPREAD * CHUNK, end, SPREAD, &mut local);
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
