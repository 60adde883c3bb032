//! The watertight ray-triangle test of Woop, Benthin and Wald, "Watertight Ray/Triangle
//! Intersection" (JCGT 2013). The ray is sheared so it runs along +z from the origin;
//! the 2D edge functions are then evaluated consistently for an edge shared by two
//! triangles, so a ray through a shared edge or vertex of a closed mesh hits at least
//! one of them. Where an edge function is exactly zero in f32 it is recomputed in f64,
//! as the paper prescribes.

use glam::{Mat3A, Mat4, Vec3, Vec3A, Vec4, Vec4Swizzles};

/// What the test needs from a ray, computed once per ray: the origin and the shear,
/// as a matrix whose rows pick and shear the coordinates, `(x, y, z)' = (p[kx] - sx
/// p[kz], p[ky] - sy p[kz], sz p[kz])`. Each row has one or two non-zero entries and
/// the others exactly 0 or 1, so `m * p` rounds exactly as the scalar formulas do (a
/// product by 0 or 1 and a sum with 0 are exact), with no indexing by `kx, ky, kz`.
#[derive(Clone, Copy, Debug)]
pub struct RayPre {
    pub org: Vec3A,
    shear: Mat3A,
    /// For [`intersect_pre`]: the origin's coordinates and the shear's entries (row by
    /// row), each splatted over four lanes.
    org4: [Vec4; 3],
    rows4: [Vec4; 9],
}

/// The shear of a ray direction as the paper writes it: the dominant axis `kz`, the two
/// others `(kx, ky)` in winding order, and `(sx, sy, sz) = (d[kx] / d[kz], d[ky] / d[kz],
/// 1 / d[kz])`. [`RayPre::new`] builds its matrix from it; the GPU tracer
/// (`src/gpu/trace.rs`) receives it with each ray, so the divisions are the CPU's, bit for
/// bit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shear {
    pub kx: usize,
    pub ky: usize,
    pub kz: usize,
    pub sx: f32,
    pub sy: f32,
    pub sz: f32,
}

impl Shear {
    #[inline]
    pub fn new(dir: Vec3) -> Shear {
        let a = dir.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        // (kx, ky) = (kz + 1, kz + 2) mod 3, swapped when the ray runs along -z to keep
        // the winding.
        let d = dir.to_array();
        let (kx, ky) = match (kz, d[kz] < 0.0) {
            (0, false) => (1, 2),
            (0, true) => (2, 1),
            (1, false) => (2, 0),
            (1, true) => (0, 2),
            (_, false) => (0, 1),
            (_, true) => (1, 0),
        };
        let (sx, sy, sz) = (d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]);
        Shear {
            kx,
            ky,
            kz,
            sx,
            sy,
            sz,
        }
    }
}

impl RayPre {
    /// Inline: made once a ray in every query, whose own module may sit in another
    /// codegen unit than this one (where it was not inlined, an unrelated change
    /// moved it out of the queries: 3 % of a dolly frame in calls).
    #[inline]
    pub fn new(org: Vec3, dir: Vec3) -> RayPre {
        let Shear {
            kx,
            ky,
            kz,
            sx,
            sy,
            sz,
        } = Shear::new(dir);
        // The shear by columns: column kx is (1, 0, 0), column ky (0, 1, 0), column kz
        // (-sx, -sy, sz). Whole vectors are stored and loaded, never single lanes.
        let mut cols = [Vec3A::ZERO; 3];
        cols[kx] = Vec3A::X;
        cols[ky] = Vec3A::Y;
        cols[kz] = Vec3A::new(-sx, -sy, sz);
        let [c0, c1, c2] = cols;
        let s = Vec4::splat;
        RayPre {
            org: org.into(),
            shear: Mat3A::from_cols(c0, c1, c2),
            org4: [s(org.x), s(org.y), s(org.z)],
            rows4: [
                s(c0.x),
                s(c1.x),
                s(c2.x),
                s(c0.y),
                s(c1.y),
                s(c2.y),
                s(c0.z),
                s(c1.z),
                s(c2.z),
            ],
        }
    }
}

/// A triangle laid out for [`intersect_pre`] (the paper's pre-processed triangle data):
/// the x, y and z of its three vertices as three 4-wide vectors, so one test shears all
/// three vertices at once. 48 bytes, 16-aligned. Lane 3 of `x` is 1 for a triangle
/// [`is_degenerate`] (which no test hits), else 0, and lane 3 of `y` and `z` is 0: a test
/// reads the flag where it would otherwise compute the triangle's area after every
/// hit, 2.4 % of a dolly frame's instructions (`benches/PERF.md`, issue 38, round 21).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct TriPre {
    x: Vec4,
    y: Vec4,
    z: Vec4,
}

impl TriPre {
    /// Three vertices at the origin: no ray meets it (a stand-in where a group of four
    /// has fewer).
    pub const NONE: TriPre = TriPre {
        x: Vec4::ZERO,
        y: Vec4::ZERO,
        z: Vec4::ZERO,
    };

    pub fn new(t: &[Vec3; 3]) -> TriPre {
        let flat = if is_degenerate(t) { 1.0 } else { 0.0 };
        TriPre {
            x: Vec4::new(t[0].x, t[1].x, t[2].x, flat),
            y: Vec4::new(t[0].y, t[1].y, t[2].y, 0.0),
            z: Vec4::new(t[0].z, t[1].z, t[2].z, 0.0),
        }
    }

    /// Whether the triangle [`is_degenerate`], as [`new`](Self::new) found it.
    #[inline(always)]
    fn degenerate(&self) -> bool {
        self.x.w != 0.0
    }

    /// The vertices back, exactly.
    pub fn vertices(&self) -> [Vec3; 3] {
        let (x, y, z) = (self.x, self.y, self.z);
        [
            Vec3::new(x.x, y.x, z.x),
            Vec3::new(x.y, y.y, z.y),
            Vec3::new(x.z, y.z, z.z),
        ]
    }
}

/// [`intersect_triangle`] on a [`TriPre`], bit for bit: the same products and sums in
/// the same order, lane by lane (a product by the shear's 0 and 1 entries and a sum with
/// 0 are exact in both), so the two agree on every ray and triangle; the property test
/// below checks it. On the museum-class scene it traced 3.7% faster than the plain
/// layout in both layers (`benches/PERF.md`, step 11). The dynamic layer uses it, and
/// since issue 38's round 9 the static PSF too (its copy made on first use, 48 bytes a
/// triangle, which the point grids had made already): its share of a dolly frame's
/// instructions had grown to some 5 %.
#[inline]
pub fn intersect_pre(r: &RayPre, tri: &TriPre, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
    let (x, y, z) = (tri.x - r.org4[0], tri.y - r.org4[1], tri.z - r.org4[2]);
    let m = &r.rows4;
    // Lane k of `sx`, `sy`, `sz`: vertex k after the shear (glam's `Mat3A * Vec3A` sums
    // the column products in this order too).
    let sx = x * m[0] + y * m[1] + z * m[2];
    let sy = x * m[3] + y * m[4] + z * m[5];
    let sz = x * m[6] + y * m[7] + z * m[8];
    // (u, v, w) = (cx by - cy bx, ax cy - ay cx, bx ay - by ax).
    let uvw = sx.zxyw() * sy.yzxw() - sy.zxyw() * sx.yzxw();
    let (u, v, w) = edge_weights(uvw, [sx.x, sy.x, sx.y, sy.y, sx.z, sy.z])?;
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let t_scaled = u * sz.x + v * sz.y + w * sz.z;
    let inv = 1.0 / det;
    let t = t_scaled * inv;
    if !(t >= t_min && t <= t_max) {
        return None;
    }
    if tri.degenerate() {
        return None;
    }
    Some((t, v * inv, w * inv))
}

/// [`intersect_pre`] on four triangles at once, calling `hit(lane, (t, u, v))` for each
/// lane whose triangle the ray meets, in lane order: the answers of four calls of
/// [`intersect_pre`], bit for bit (the property test below holds it). The
/// triangles' vertices go across the lanes (a transpose of their rows), and each lane
/// does the scalar test's products and sums in its order; a lane with an edge function
/// exactly zero, which the scalar test recomputes in f64, is handed to
/// [`intersect_pre`] itself. One branch decides the four where the scalar test takes
/// one each, a coin toss for a candidate a ray may or may not meet.
#[inline]
pub fn intersect_pre4(
    r: &RayPre,
    tris: [&TriPre; 4],
    t_min: f32,
    t_max: f32,
    mut hit: impl FnMut(usize, (f32, f32, f32)),
) {
    let across = |f: fn(&TriPre) -> Vec4| {
        Mat4::from_cols(f(tris[0]), f(tris[1]), f(tris[2]), f(tris[3])).transpose()
    };
    let (xs, ys, zs) = (across(|t| t.x), across(|t| t.y), across(|t| t.z));
    let m = &r.rows4;
    // Vertex `k` of the four triangles, sheared: the scalar test's lane `k`.
    let sheared = |k: usize| {
        let (x, y, z) = (
            xs.col(k) - r.org4[0],
            ys.col(k) - r.org4[1],
            zs.col(k) - r.org4[2],
        );
        (
            x * m[0] + y * m[1] + z * m[2],
            x * m[3] + y * m[4] + z * m[5],
            x * m[6] + y * m[7] + z * m[8],
        )
    };
    let ((ax, ay, az), (bx, by, bz), (cx, cy, cz)) = (sheared(0), sheared(1), sheared(2));
    let (u, v, w) = (cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax);
    let zero = Vec4::ZERO;
    let exact = (u.cmpeq(zero) | v.cmpeq(zero) | w.cmpeq(zero)).bitmask();
    let neg = u.cmplt(zero) | v.cmplt(zero) | w.cmplt(zero);
    let pos = u.cmpgt(zero) | v.cmpgt(zero) | w.cmpgt(zero);
    let det = u + v + w;
    let t_scaled = u * az + v * bz + w * cz;
    let inv = Vec4::ONE / det;
    let t = t_scaled * inv;
    // Lane k: triangle k's flag of `TriPre::new` (the rows' fourth entries).
    let degenerate = xs.col(3).cmpne(zero);
    let met = !(neg & pos)
        & !degenerate
        & det.cmpne(zero)
        & det.abs().cmplt(Vec4::INFINITY)
        & t.cmpge(Vec4::splat(t_min))
        & t.cmple(Vec4::splat(t_max));
    let mut todo = met.bitmask() | exact;
    if todo == 0 {
        return;
    }
    let (ts, vs, ws) = (t.to_array(), (v * inv).to_array(), (w * inv).to_array());
    while todo != 0 {
        let k = todo.trailing_zeros() as usize;
        todo &= todo - 1;
        if exact & (1 << k) != 0 {
            if let Some(h) = intersect_pre(r, tris[k], t_min, t_max) {
                hit(k, h);
            }
        } else {
            hit(k, (ts[k], vs[k], ws[k]));
        }
    }
}

/// Intersects one triangle; returns `(t, u, v)` with `t` in `[t_min, t_max]` (both
/// inclusive), `u`, `v` the weights of vertices 1 and 2. Both faces are hit; a triangle
/// of zero area in the ray's view is never hit.
#[inline(always)]
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

    let uvw = Vec4::new(cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax, 0.0);
    let (u, v, w) = edge_weights(uvw, [ax, ay, bx, by, cx, cy])?;
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

/// The edge functions `(u, v, w) = (cx by - cy bx, ax cy - ay cx, bx ay - by ax)` of the
/// sheared vertices `[ax, ay, bx, by, cx, cy]`, given in f32 as lanes 0..3 of `uvw`:
/// recomputed in f64 where one is exactly zero, and `None` when their signs differ (the
/// ray passes beside the triangle). The checks are lane masks, one branch each: branches
/// on the signs one by one are mispredicted about half the time (a ray meets or misses
/// the triangles it is tested against about evenly), which cost 15% of a query
/// (`benches/PERF.md`, step 14).
#[inline(always)]
fn edge_weights(mut uvw: Vec4, sheared: [f32; 6]) -> Option<(f32, f32, f32)> {
    if uvw.cmpeq(Vec4::ZERO).bitmask() & 7 != 0 {
        let [ax, ay, bx, by, cx, cy] = sheared.map(f64::from);
        uvw = Vec4::new(
            (cx * by - cy * bx) as f32,
            (ax * cy - ay * cx) as f32,
            (bx * ay - by * ax) as f32,
            0.0,
        );
    }
    let neg = uvw.cmplt(Vec4::ZERO).bitmask() & 7;
    let pos = uvw.cmpgt(Vec4::ZERO).bitmask() & 7;
    if (neg != 0) & (pos != 0) {
        return None;
    }
    Some((uvw.x, uvw.y, uvw.z))
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

    /// A triangle `is_degenerate` calls degenerate carries the flag in its test form,
    /// and neither test reports it, in a group beside triangles that are hit; without
    /// the flag the sliver below would be hit (so the flag is what the tests read).
    #[test]
    fn degenerate_triangles_flagged_and_never_hit() {
        let sliver = [Vec3::ZERO, Vec3::X, Vec3::new(0.5, 1e-7, 0.0)];
        let slivers = [
            sliver,
            [Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
            [Vec3::ZERO, Vec3::ZERO, Vec3::Y],
        ];
        let good = [
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(3.0, -1.0, 0.0),
            Vec3::new(-1.0, 3.0, -0.5),
        ];
        let g = TriPre::new(&good);
        assert!(!g.degenerate());
        let pre = RayPre::new(Vec3::new(0.5, 2.5e-8, 1.0), Vec3::NEG_Z);
        for s in &slivers {
            assert!(is_degenerate(s));
            let p = TriPre::new(s);
            assert!(p.degenerate());
            assert_eq!(p.vertices(), *s);
            assert_eq!(intersect_pre(&pre, &p, 0.0, f32::INFINITY), None);
            assert_eq!(intersect_triangle(&pre, s, 0.0, f32::INFINITY), None);
            let want = intersect_pre(&pre, &g, 0.0, f32::INFINITY);
            assert!(want.is_some());
            let mut got = [None; 4];
            intersect_pre4(&pre, [&p, &g, &p, &g], 0.0, f32::INFINITY, |k, h| {
                got[k] = Some(h)
            });
            assert_eq!(got, [None, want, None, want]);
        }
        let mut unflagged = TriPre::new(&sliver);
        unflagged.x.w = 0.0;
        assert!(intersect_pre(&pre, &unflagged, 0.0, f32::INFINITY).is_some());
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

    use proptest::prelude::*;

    /// Coordinates that make the edge cases likely: small integers (rays through edges
    /// and vertices, zero edge functions, zero-area triangles) mixed with arbitrary
    /// floats of several magnitudes.
    fn coord() -> impl Strategy<Value = f32> {
        prop_oneof![
            (-3i32..=3).prop_map(|i| i as f32),
            (-3i32..=3).prop_map(|i| i as f32 * 0.5),
            -10.0f32..10.0,
            -1e6f32..1e6,
        ]
    }

    fn vec3() -> impl Strategy<Value = Vec3> {
        (coord(), coord(), coord()).prop_map(|(x, y, z)| Vec3::new(x, y, z))
    }

    /// The shear as the paper writes it, entry by entry: row 0 picks `kx` and takes `sx`
    /// times `kz`, row 1 the same with `ky` and `sy`, row 2 scales `kz` by `sz`.
    fn reference_rows(dir: Vec3) -> [[f32; 3]; 3] {
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
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let (sx, sy, sz) = (dir[kx] / dir[kz], dir[ky] / dir[kz], 1.0 / dir[kz]);
        let mut rows = [[0.0f32; 3]; 3];
        rows[0][kx] = 1.0;
        rows[0][kz] = -sx;
        rows[1][ky] = 1.0;
        rows[1][kz] = -sy;
        rows[2][kz] = sz;
        rows
    }

    #[test]
    fn shear_matches_the_reference_entry_by_entry() {
        let mut dirs = vec![];
        // every dominant axis, both signs, and ties between axes
        for &(x, y, z) in &[
            (1.0, 0.2, -0.3),
            (-1.0, 0.2, 0.3),
            (0.2, 1.0, -0.3),
            (0.2, -1.0, 0.3),
            (0.2, -0.3, 1.0),
            (0.2, 0.3, -1.0),
            (1.0, 1.0, 1.0),
            (-1.0, -1.0, 0.5),
            (0.5, -1.0, -1.0),
            (0.0, 0.0, -2.0),
            (-0.0, 3.0, 0.0),
        ] {
            dirs.push(Vec3::new(x, y, z));
        }
        let mut rng = crate::gen::synth::Rng::new(7);
        dirs.extend((0..2000).map(|_| rng.in_box(Vec3::splat(-1.0), Vec3::ONE)));
        for d in dirs {
            let rows = reference_rows(d);
            let pre = RayPre::new(Vec3::new(1.0, 2.0, 3.0), d);
            let got = pre.shear.transpose().to_cols_array_2d();
            let bits = |m: [[f32; 3]; 3]| m.map(|r| r.map(f32::to_bits));
            assert_eq!(bits(got), bits(rows), "direction {d}");
            let splats: Vec<Vec4> = rows.iter().flatten().map(|&x| Vec4::splat(x)).collect();
            assert_eq!(pre.rows4.to_vec(), splats, "direction {d}");
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]
        /// The pre-processed layout gives exactly the scalar test's answer.
        #[test]
        fn pre_layout_agrees_bit_for_bit(
            a in vec3(), b in vec3(), c in vec3(), o in vec3(), d in vec3(),
            t_max in prop_oneof![Just(f32::INFINITY), 0.0f32..20.0],
        ) {
            let tri = [a, b, c];
            let pre = RayPre::new(o, d);
            let want = intersect_triangle(&pre, &tri, 0.0, t_max);
            let got = intersect_pre(&pre, &TriPre::new(&tri), 0.0, t_max);
            let bits = |h: Option<(f32, f32, f32)>| h.map(|(t, u, v)| [t.to_bits(), u.to_bits(), v.to_bits()]);
            prop_assert_eq!(bits(got), bits(want));
            prop_assert_eq!(TriPre::new(&tri).vertices(), tri);
        }

        /// Four triangles at once give the answers of four single tests, lane by lane
        /// and bit for bit; on rays aimed at one of them
        /// (so that lanes hit, some through an edge or a vertex) and on any ray.
        #[test]
        fn four_at_once_agree_bit_for_bit(
            tris in proptest::collection::vec((vec3(), vec3(), vec3()), 4),
            o in vec3(), d in vec3(),
            aim in prop_oneof![Just(None), (0usize..4, 0.0f32..0.5, 0.0f32..0.5, 0.5f32..4.0).prop_map(Some)],
            t_max in prop_oneof![Just(f32::INFINITY), 0.0f32..20.0],
        ) {
            let tris: Vec<TriPre> = tris.iter().map(|&(a, b, c)| TriPre::new(&[a, b, c])).collect();
            let o = match aim {
                Some((k, u, v, back)) => {
                    let [a, b, c] = tris[k].vertices();
                    a + (b - a) * u + (c - a) * v - d * back
                }
                None => o,
            };
            let pre = RayPre::new(o, d);
            let bits = |h: Option<(f32, f32, f32)>| h.map(|(t, u, v)| [t.to_bits(), u.to_bits(), v.to_bits()]);
            let mut got = [None; 4];
            intersect_pre4(&pre, [&tris[0], &tris[1], &tris[2], &tris[3]], 0.0, t_max, |k, h| {
                assert!(got[k].is_none(), "lane {k} reported twice");
                got[k] = Some(h);
            });
            for k in 0..4 {
                let want = intersect_pre(&pre, &tris[k], 0.0, t_max);
                prop_assert_eq!(bits(got[k]), bits(want), "lane {}", k);
            }
        }

        /// The same on rays aimed at a point of the triangle (most of them hit, some
        /// through an edge or a vertex).
        #[test]
        fn pre_layout_agrees_on_aimed_rays(
            a in vec3(), b in vec3(), c in vec3(), d in vec3(),
            u in prop_oneof![Just(0.0f32), Just(0.5), 0.0f32..1.0],
            v in prop_oneof![Just(0.0f32), Just(0.5), 0.0f32..1.0],
            back in 0.5f32..4.0,
        ) {
            let (u, v) = if u + v > 1.0 { (1.0 - u, 1.0 - v) } else { (u, v) };
            let p = a + (b - a) * u + (c - a) * v;
            let o = p - d * back;
            let tri = [a, b, c];
            let pre = RayPre::new(o, d);
            let want = intersect_triangle(&pre, &tri, 0.0, f32::INFINITY);
            let got = intersect_pre(&pre, &TriPre::new(&tri), 0.0, f32::INFINITY);
            let bits = |h: Option<(f32, f32, f32)>| h.map(|(t, u, v)| [t.to_bits(), u.to_bits(), v.to_bits()]);
            prop_assert_eq!(bits(got), bits(want));
        }
    }
}
