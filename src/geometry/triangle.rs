//! The watertight ray-triangle test of Woop, Benthin and Wald, "Watertight Ray/Triangle
//! Intersection" (JCGT 2013). The ray is sheared so it runs along +z from the origin;
//! the 2D edge functions are then evaluated consistently for an edge shared by two
//! triangles, so a ray through a shared edge or vertex of a closed mesh hits at least
//! one of them. Where an edge function is exactly zero in f32 it is recomputed in f64,
//! as the paper prescribes.

use glam::{Mat3A, Vec3, Vec3A};

/// What the test needs from a ray, computed once per ray: the origin and the shear,
/// as a matrix whose rows pick and shear the coordinates, `(x, y, z)' = (p[kx] - sx
/// p[kz], p[ky] - sy p[kz], sz p[kz])`. Each row has one or two non-zero entries and
/// the others exactly 0 or 1, so `m * p` rounds exactly as the scalar formulas do (a
/// product by 0 or 1 and a sum with 0 are exact), with no indexing by `kx, ky, kz`.
#[derive(Clone, Copy, Debug)]
pub struct RayPre {
    pub org: Vec3A,
    shear: Mat3A,
}

impl RayPre {
    pub fn new(org: Vec3, dir: Vec3) -> RayPre {
        let a = dir.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keep the winding: swapping x and y when the ray runs along -z.
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let (sx, sy, sz) = (dir[kx] / dir[kz], dir[ky] / dir[kz], 1.0 / dir[kz]);
        // Rows of the shear; the matrix is stored by columns.
        let mut rows = [[0.0f32; 3]; 3];
        rows[0][kx] = 1.0;
        rows[0][kz] = -sx;
        rows[1][ky] = 1.0;
        rows[1][kz] = -sy;
        rows[2][kz] = sz;
        RayPre {
            org: org.into(),
            shear: Mat3A::from_cols_array_2d(&rows).transpose(),
        }
    }
}

/// Intersects one triangle; returns `(t, u, v)` with `t` in `[t_min, t_max]` (both
/// inclusive), `u`, `v` the weights of vertices 1 and 2. Both faces are hit; a triangle
/// of zero area in the ray's view is never hit.
#[inline]
pub fn intersect_triangle(
    r: &RayPre,
    tri: &[Vec3; 3],
    t_min: f32,
    t_max: f32,
) -> Option<(f32, f32, f32)> {
    let a = r.shear * (Vec3A::from(tri[0]) - r.org);
    let b = r.shear * (Vec3A::from(tri[1]) - r.org);
    let c = r.shear * (Vec3A::from(tri[2]) - r.org);
    let (ax, ay, bx, by, cx, cy) = (a.x, a.y, b.x, b.y, c.x, c.y);

    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;

    if u == 0.0 || v == 0.0 || w == 0.0 {
        let (ax, ay, bx, by, cx, cy) = (
            ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64,
        );
        u = (cx * by - cy * bx) as f32;
        v = (ax * cy - ay * cx) as f32;
        w = (bx * ay - by * ax) as f32;
    }

    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }

    let (az, bz, cz) = (a.z, b.z, c.z);
    let t_scaled = u * az + v * bz + w * cz;
    let inv = 1.0 / det;
    let t = t_scaled * inv;
    if !(t >= t_min && t <= t_max) {
        return None;
    }
    if is_degenerate(tri) {
        return None;
    }
    Some((t, v * inv, w * inv))
}

/// A triangle without area up to float rounding: the sine of its angle at `a` below
/// 2^-17. A ray through such a triangle gets edge functions that are rounding noise, and
/// the `t` they give need not lie on the triangle at all; no query could find such a hit
/// by where it is, so no query reports it. Checked after a hit only, where it is cheap.
#[inline]
pub fn is_degenerate(tri: &[Vec3; 3]) -> bool {
    let (e1, e2) = (tri[1] - tri[0], tri[2] - tri[0]);
    let n2 = e1.cross(e2).length_squared();
    // sin² < 2^-34, without dividing (zero-length edges count as degenerate).
    let bound = e1.length_squared() * e2.length_squared() * (1.0 / 17_179_869_184.0);
    // Written so that NaN counts as degenerate.
    n2.partial_cmp(&bound) != Some(std::cmp::Ordering::Greater)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hit(o: Vec3, d: Vec3, tri: [Vec3; 3]) -> Option<(f32, f32, f32)> {
        intersect_triangle(&RayPre::new(o, d), &tri, 0.0, f32::INFINITY)
    }

    #[test]
    fn hits_centre_with_barycentrics() {
        let tri = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let (t, u, v) = hit(Vec3::new(0.25, 0.5, 2.0), Vec3::new(0.0, 0.0, -1.0), tri).unwrap();
        assert_eq!(t, 2.0);
        assert!((u - 0.25).abs() < 1e-6 && (v - 0.5).abs() < 1e-6);
        // from behind: both faces are hit
        let (t, _, _) = hit(Vec3::new(0.25, 0.5, -3.0), Vec3::new(0.0, 0.0, 2.0), tri).unwrap();
        assert_eq!(t, 1.5);
    }

    #[test]
    fn misses_outside_and_behind_and_degenerate() {
        let tri = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        assert!(hit(Vec3::new(0.75, 0.75, 1.0), Vec3::NEG_Z, tri).is_none());
        assert!(hit(Vec3::new(0.2, 0.2, 1.0), Vec3::Z, tri).is_none());
        let flat = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
        assert!(hit(Vec3::new(0.5, 0.0, 1.0), Vec3::NEG_Z, flat).is_none());
        // ray in the triangle's plane: zero area as seen from the ray
        assert!(hit(Vec3::new(-1.0, 0.2, 0.0), Vec3::X, tri).is_none());
    }

    /// A ray through the shared edge (and through the shared vertex) of a fan of
    /// triangles around a point must hit at least one of them.
    #[test]
    fn watertight_on_shared_edges_and_vertices() {
        let n = 7;
        let centre = Vec3::new(0.1, -0.3, 0.0);
        let ring: Vec<Vec3> = (0..n)
            .map(|i| {
                let a = i as f32 / n as f32 * std::f32::consts::TAU;
                centre + Vec3::new(a.cos(), a.sin(), 0.13 * (i as f32 - 3.0))
            })
            .collect();
        let tris: Vec<[Vec3; 3]> = (0..n)
            .map(|i| [centre, ring[i], ring[(i + 1) % n]])
            .collect();
        let dirs = [
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(0.3, -0.2, -1.0),
            Vec3::new(-0.7, 0.1, -0.4),
        ];
        for d in dirs {
            // through the shared vertex
            let o = centre - d * 3.0;
            assert!(
                tris.iter().any(|t| hit(o, d, *t).is_some()),
                "slipped through the centre"
            );
            // through points on each shared edge
            for (i, r) in ring.iter().enumerate() {
                for s in [0.1f32, 0.37, 0.5, 0.93] {
                    let p = centre + (*r - centre) * s;
                    let o = p - d * 3.0;
                    assert!(
                        tris.iter().any(|t| hit(o, d, *t).is_some()),
                        "slipped through edge {i} at {s}"
                    );
                }
            }
        }
    }
}
