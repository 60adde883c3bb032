//! Directions from recursive subdivision of a regular tetrahedron (the paper's §3.1),
//! merged into subfields (`d` and `-d` describe the same beams), and the table that maps
//! a ray direction to the subfield of the closest direction in O(1).

use std::collections::BTreeMap;

use glam::{DVec3, Vec3};

/// The most subdivision levels we build: level 4 gives 514 directions.
pub const MAX_LEVEL: u32 = 4;

/// The unit directions of a subdivided tetrahedron: 4, 10, 34, 130, 514 for levels 0-4.
/// Computed in f64 and rounded once, so the set is the same on every machine.
pub fn tetrahedron_directions(level: u32) -> Vec<Vec3> {
    let s = 1.0 / 3f64.sqrt();
    let mut verts: Vec<DVec3> = vec![
        DVec3::new(s, s, s),
        DVec3::new(s, -s, -s),
        DVec3::new(-s, s, -s),
        DVec3::new(-s, -s, s),
    ];
    let mut faces: Vec<[usize; 3]> = vec![[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]];
    for _ in 0..level {
        // BTreeMap keeps the numbering of new vertices independent of hashing.
        let mut mid: BTreeMap<(usize, usize), usize> = BTreeMap::new();
        let mut next = Vec::with_capacity(faces.len() * 4);
        let mut midpoint = |a: usize, b: usize, verts: &mut Vec<DVec3>| -> usize {
            let key = (a.min(b), a.max(b));
            *mid.entry(key).or_insert_with(|| {
                verts.push((verts[a] + verts[b]).normalize());
                verts.len() - 1
            })
        };
        for [a, b, c] in faces {
            let ab = midpoint(a, b, &mut verts);
            let bc = midpoint(b, c, &mut verts);
            let ca = midpoint(c, a, &mut verts);
            next.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        }
        faces = next;
    }
    verts.into_iter().map(|v| v.as_vec3()).collect()
}

/// One subfield per direction, except that a direction whose opposite is already in the
/// list shares that one's subfield (from level 1 on the six axis directions pair up).
pub fn subfield_directions(level: u32) -> Vec<Vec3> {
    let mut kept: Vec<Vec3> = Vec::new();
    for d in tetrahedron_directions(level) {
        if !kept.iter().any(|k| k.dot(d) < -1.0 + 1e-6) {
            kept.push(d);
        }
    }
    kept
}

/// An orthonormal frame `(u, v, d)` for a unit `d` (Duff et al., "Building an
/// Orthonormal Basis, Revisited", JCGT 2017): branch-light and continuous except at
/// `d.z = -0`, and deterministic.
pub fn frame_for(d: Vec3) -> (Vec3, Vec3) {
    let sign = 1f32.copysign(d.z);
    let a = -1.0 / (sign + d.z);
    let b = d.x * d.y * a;
    let u = Vec3::new(1.0 + sign * d.x * d.x * a, sign * b, -sign * d.x);
    let v = Vec3::new(b, sign + d.y * d.y * a, -d.y);
    (u.normalize(), v.normalize())
}

/// Maps a ray direction to the subfield whose direction is closest (largest `|dot|`).
/// Directions are folded so their largest component is positive (`d` and `-d` share a
/// subfield), then looked up in a cube map of `res × res` cells on each of the 3 faces.
/// Each cell holds the subfield closest to the cell's centre: within a cell the choice is
/// near-best, never wrong (any subfield gives exact answers; the closest one walks the
/// fewest tiles).
#[derive(Clone, Debug)]
pub struct DirectionTable {
    res: u32,
    cells: Vec<u16>,
}

impl DirectionTable {
    /// 64 × 64 cells a face: a cell spans under 2° while level-4 directions are about 9°
    /// apart, so the table's choice is the closest or a next neighbour.
    pub const RES: u32 = 64;

    pub fn new(dirs: &[Vec3]) -> DirectionTable {
        let res = Self::RES;
        let mut cells = Vec::with_capacity((3 * res * res) as usize);
        for face in 0..3usize {
            for j in 0..res {
                for i in 0..res {
                    let s = ((i as f32 + 0.5) / res as f32) * 2.0 - 1.0;
                    let t = ((j as f32 + 0.5) / res as f32) * 2.0 - 1.0;
                    let mut w = Vec3::ZERO;
                    w[face] = 1.0;
                    w[(face + 1) % 3] = s;
                    w[(face + 2) % 3] = t;
                    let w = w.normalize();
                    let mut best = 0usize;
                    let mut best_dot = -1.0f32;
                    for (k, d) in dirs.iter().enumerate() {
                        let c = d.dot(w).abs();
                        if c > best_dot {
                            best_dot = c;
                            best = k;
                        }
                    }
                    cells.push(best as u16);
                }
            }
        }
        DirectionTable { res, cells }
    }

    /// The subfield for a direction; `dir` must be finite and non-zero.
    #[inline]
    /// Cells along each side of a cube face (the GPU tracer uploads the table as is).
    pub fn res(&self) -> u32 {
        self.res
    }

    /// The subfield of each cell: face by face, rows of `res` cells.
    pub fn cells(&self) -> &[u16] {
        &self.cells
    }

    pub fn lookup(&self, dir: Vec3) -> usize {
        let a = dir.abs();
        let face = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let m = a[face];
        // The fold to the positive face flips the other two coordinates' signs with it.
        let sgn = if dir[face] < 0.0 { -1.0 } else { 1.0 };
        let s = dir[(face + 1) % 3] * sgn / m;
        let t = dir[(face + 2) % 3] * sgn / m;
        let r = self.res as f32;
        let i = (((s + 1.0) * 0.5 * r) as i32).clamp(0, self.res as i32 - 1) as usize;
        let j = (((t + 1.0) * 0.5 * r) as i32).clamp(0, self.res as i32 - 1) as usize;
        self.cells[(face * self.res as usize + j) * self.res as usize + i] as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_per_level() {
        let counts: Vec<usize> = (0..=MAX_LEVEL)
            .map(|l| tetrahedron_directions(l).len())
            .collect();
        assert_eq!(counts, vec![4, 10, 34, 130, 514]);
        for l in 0..=MAX_LEVEL {
            for d in tetrahedron_directions(l) {
                assert!((d.length() - 1.0).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn opposite_directions_share_a_subfield() {
        assert_eq!(subfield_directions(0).len(), 4);
        // the 6 axis directions of level 1 pair up
        assert_eq!(subfield_directions(1).len(), 7);
        for l in 0..=MAX_LEVEL {
            let s = subfield_directions(l);
            for (i, a) in s.iter().enumerate() {
                for b in &s[i + 1..] {
                    assert!(a.dot(*b) > -1.0 + 1e-6);
                }
            }
        }
    }

    #[test]
    fn frames_are_orthonormal() {
        for d in tetrahedron_directions(3) {
            let (u, v) = frame_for(d);
            assert!(u.dot(v).abs() < 1e-5 && u.dot(d).abs() < 1e-5 && v.dot(d).abs() < 1e-5);
            assert!((u.length() - 1.0).abs() < 1e-5 && (v.length() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn table_picks_a_near_best_direction() {
        for level in 0..=MAX_LEVEL {
            let dirs = subfield_directions(level);
            let table = DirectionTable::new(&dirs);
            let mut seed = 12345u64;
            for _ in 0..5000 {
                let mut r = || {
                    seed = seed
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    ((seed >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
                };
                let w = Vec3::new(r(), r(), r());
                if w.length() < 1e-3 {
                    continue;
                }
                let w = w.normalize();
                let best = dirs.iter().map(|d| d.dot(w).abs()).fold(0.0f32, f32::max);
                let got = dirs[table.lookup(w)].dot(w).abs();
                // a cell spans < 2 degrees: the chosen one is within that of the best
                assert!(got >= best - 0.035, "level {level}: {got} vs {best}");
                assert_eq!(
                    table.lookup(w),
                    table.lookup(-w),
                    "d and -d share a subfield"
                );
            }
        }
    }
}
