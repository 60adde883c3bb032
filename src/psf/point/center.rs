//! The centre search: the point most of a batch's sampled rays pass through.

use glam::{DMat3, DVec3};

use crate::geometry::Ray;

/// Sampled lines whose crossing with their neighbour's is tried as the centre.
const PAIRS: usize = 16;

/// The point most of `sample` passes through (by `passes`), with the number that do: an
/// origin they share (a camera's rays), else the crossing of a sampled ray's line with
/// its neighbour's in the batch (the second of each pair; both of a light's shadow rays
/// pass the light) that most of the sample passes, refined by least squares over the
/// lines that pass it. Trying crossings one by one keeps rays elsewhere from pulling the
/// point away.
pub(super) fn center(
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
