//! The geometry of the six cube faces around a point: which rays qualify for a grid
//! around it ([`passes`]), the face and projected point of a ray's reference direction
//! ([`project`]), and rounding to `f32` outwards. Used by every other part; uses none.

use glam::{DVec3, Vec3};

use crate::geometry::Ray;

/// `a` where `keep`, else `b`, without a branch (a mask over the bits).
#[inline(always)]
fn pick(keep: bool, a: f32, b: f32) -> f32 {
    let m = (keep as u32).wrapping_neg();
    f32::from_bits((a.to_bits() & m) | (b.to_bits() & !m))
}

/// `x` rounded to an `f32` no greater than it. Every outcome is computed and one picked
/// without a branch: whether rounding to nearest went up is a coin toss, and branching
/// on it was mispredicted about every other call (twice a ray in a query's depth
/// window, `benches/PERF.md`, issue 38, round 8).
#[inline]
pub(super) fn down(x: f64) -> f32 {
    let y = x as f32;
    // Otherwise at least one unit in the last place below `y`, which rounding to
    // nearest put at most that far above `x`; `f32::MAX` below an infinite `y`.
    let below = pick(
        y.is_infinite(),
        f32::MAX,
        y - (y.abs() * f32::EPSILON).max(f32::MIN_POSITIVE),
    );
    pick(y as f64 <= x || x.is_nan(), y, below)
}

/// `x` rounded to an `f32` no less than it (branch-free, as [`down`]).
#[inline]
pub(super) fn up(x: f64) -> f32 {
    let y = x as f32;
    let above = pick(
        y.is_infinite(),
        f32::MIN,
        y + (y.abs() * f32::EPSILON).max(f32::MIN_POSITIVE),
    );
    pick(y as f64 >= x || x.is_nan(), y, above)
}

/// Face `f` (axis `f / 2`, negative when `f` is odd) coordinates `(u, v, z)` of `x`:
/// the axes after the face's, in turn (`f` above 5 counts as 5). A match on the face, not
/// indices taken modulo 3 into the vector stored as an array (0.35 % of a dolly frame's
/// instructions fewer: `benches/PERF.md`, issue 38, round 20).
#[inline]
pub(super) fn face_coords(f: usize, x: DVec3) -> (f64, f64, f64) {
    match f {
        0 => (x.y, x.z, x.x),
        1 => (x.y, x.z, -x.x),
        2 => (x.z, x.x, x.y),
        3 => (x.z, x.x, -x.y),
        4 => (x.x, x.y, x.z),
        _ => (x.x, x.y, -x.z),
    }
}

/// The face whose frustum holds direction `a`.
#[inline]
pub(super) fn face_of(a: DVec3) -> usize {
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
pub(super) fn passes(c: DVec3, r: f64, rho_max: f64, ray: &Ray) -> Option<bool> {
    // Bounds that are NaN or inverted fail here; an origin or direction that is not
    // finite, or a zero direction, fails the test on `|o x d|` below (NaN or infinite
    // against a finite bound, or 0 < 0), so `Ray::is_valid` need not be asked: it was
    // 2.7 % of a dolly frame's instructions, once for every grid a ray tries
    // (benches/PERF.md, issue 38, round 9; a test holds the two to the same answers).
    let ordered = ray.t_min <= ray.t_max; // false when either is NaN
    if !ordered {
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
pub(super) fn project(dir: Vec3, forward: bool) -> (u8, [f32; 2]) {
    let a = if forward { dir } else { -dir }.as_dvec3();
    let f = face_of(a);
    let (u, v, z) = face_coords(f, a);
    let inv = 1.0 / z;
    (f as u8, [(u * inv) as f32, (v * inv) as f32])
}

/// The rounding of a ray's projected point (`|p| <= 1`) to `f32`, with room to spare.
pub(super) const EPS_P: f64 = 2e-7;

/// `passes` and `project` together, for tests and sampling.
#[inline]
pub(super) fn aim(c: DVec3, r: f64, rho_max: f64, ray: &Ray) -> Option<(u8, [f32; 2])> {
    passes(c, r, rho_max, ray).map(|fw| project(ray.dir, fw))
}
