//! The static part's budget: how finely the room, pillars, spheres and torus are
//! tessellated for a given triangle count, and the counts those choices give.

use super::*;

/// Half extents of the room: x and z in [-10, 10], y (up) in [0, 8].
pub(super) const ROOM_HALF: f32 = 10.0;
pub(super) const ROOM_HEIGHT: f32 = 8.0;
/// Where the dynamic formations gather.
pub(super) const CENTRE: Vec3 = Vec3::new(0.0, 3.6, 0.0);
pub(super) const PILLARS: [Vec2; 4] = [
    Vec2::new(-6.0, -6.0),
    Vec2::new(6.0, -6.0),
    Vec2::new(-6.0, 6.0),
    Vec2::new(6.0, 6.0),
];

/// Triangles of the parts whose tessellation does not depend on the budget: 7 paintings
/// and a mirror (canvas 2 + frame 4 boxes), 3 pedestals, 2 benches (3 boxes), and each
/// pillar's base and capital (2 boxes).
pub(super) const FRAMED: usize = 2 + 4 * 12;
pub(super) const FIXED_TRIS: usize = 8 * FRAMED + 3 * 12 + 2 * 3 * 12 + 4 * 2 * 12;
/// The baseboard takes what is left; it needs one quad per wall.
pub(super) const BASEBOARD_MIN: usize = 8;
pub(super) const MIN_SCALABLE: usize =
    shell_tris(1) + 4 * pillar_tris(6) + 2 * sphere_tris(3) + torus_tris(6);

pub(super) const fn wall_rows(n: usize) -> usize {
    // Walls are 8 high and 20 wide: keep their cells near square.
    let m = (2 * n + 2) / 5;
    if m == 0 {
        1
    } else {
        m
    }
}
/// Floor and ceiling `n × n`, four walls `n × wall_rows(n)`.
pub(super) const fn shell_tris(n: usize) -> usize {
    4 * n * n + 8 * n * wall_rows(n)
}
/// One pillar's open cylinder: `s` segments around, `s / 2` rings up.
pub(super) const fn pillar_tris(s: usize) -> usize {
    let r = if s / 2 == 0 { 1 } else { s / 2 };
    2 * s * r
}
/// UV sphere with `r` rings and `2r` segments.
pub(super) const fn sphere_tris(r: usize) -> usize {
    4 * r * (r - 1)
}
/// Torus with `a` segments around and `a / 2` (at least 3) around the tube.
pub(super) const fn torus_tris(a: usize) -> usize {
    2 * a * torus_tube(a)
}
pub(super) const fn torus_tube(a: usize) -> usize {
    if a / 2 < 3 {
        3
    } else {
        a / 2
    }
}

/// Tessellation levels for a static budget.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Plan {
    pub(super) shell: usize,
    pub(super) pillar: usize,
    pub(super) sphere: usize,
    pub(super) torus: usize,
    pub(super) baseboard: usize,
}

impl Plan {
    /// Shares of what is left above the minimum: room shell 35 %, pillars 15 %, each
    /// sphere 15 %, the torus the rest (about 20 %); the baseboard takes the rounding
    /// (8 to about 100 triangles at the default budget), so the total is exact.
    /// `static_tris` must be at least [`MIN_STATIC_TRIS`].
    pub(super) fn for_budget(static_tris: usize) -> Plan {
        let budget = static_tris.saturating_sub(FIXED_TRIS + BASEBOARD_MIN);
        let extra = budget.saturating_sub(MIN_SCALABLE) as f64;
        let cap = |min: usize, share: f64| min + (share * extra) as usize;
        // Largest level whose count fits the cap (counts grow with the level).
        let fit = |start: usize, count: &dyn Fn(usize) -> usize, cap: usize| {
            let mut l = start;
            while count(l + 1) <= cap {
                l += 1;
            }
            l
        };
        let shell = fit(1, &|n| shell_tris(n), cap(shell_tris(1), 0.35));
        let pillar = fit(6, &|s| 4 * pillar_tris(s), cap(4 * pillar_tris(6), 0.15));
        let sphere = fit(3, &sphere_tris, cap(sphere_tris(3), 0.15));
        let used = shell_tris(shell) + 4 * pillar_tris(pillar) + 2 * sphere_tris(sphere);
        let torus = fit(6, &torus_tris, budget.saturating_sub(used));
        let baseboard = static_tris
            .saturating_sub(FIXED_TRIS + used + torus_tris(torus))
            .max(BASEBOARD_MIN);
        Plan {
            shell,
            pillar,
            sphere,
            torus,
            baseboard,
        }
    }
}
