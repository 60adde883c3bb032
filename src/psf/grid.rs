//! A subfield's tile grid: the frame `(u, v, d)`, the base rectangle of the scene bounds
//! in that frame cut into square tiles, and the conservative rasterisation of triangles
//! into those tiles with the depth range each covers over each tile.

use bytemuck::{Pod, Zeroable};
use glam::{Mat3A, Vec3, Vec3A};

use super::directions::frame_for;
use crate::geometry::Aabb;

/// The frame and tile grid of one subfield. `repr(C)` and plain: it is stored as is in
/// the baked file.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct GridFrame {
    /// The beam direction and the two axes of the base plane.
    pub d: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    /// The base rectangle's lower corner in `(u, v)` coordinates.
    pub u0: f32,
    pub v0: f32,
    /// Side of a square tile, and its inverse.
    pub tile: f32,
    pub inv_tile: f32,
    /// Tiles along `u` and `v`.
    pub nu: u32,
    pub nv: u32,
}

const _: () = assert!(std::mem::size_of::<GridFrame>() == 60);

impl GridFrame {
    /// The grid for direction `d` over `bounds`: the longer side of the base rectangle
    /// is cut into `tiles` tiles, the shorter into as many as it takes (at least one).
    pub fn new(d: Vec3, bounds: &Aabb, tiles: u32) -> GridFrame {
        let (u, v) = frame_for(d);
        let (mut lo_u, mut hi_u, mut lo_v, mut hi_v) = (
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
        );
        for c in bounds.corners() {
            let (pu, pv) = (c.dot(u), c.dot(v));
            lo_u = lo_u.min(pu);
            hi_u = hi_u.max(pu);
            lo_v = lo_v.min(pv);
            hi_v = hi_v.max(pv);
        }
        let tiles = tiles.max(1);
        let ext = (hi_u - lo_u).max(hi_v - lo_v);
        let tile = if ext > 0.0 && ext.is_finite() {
            ext / tiles as f32
        } else {
            1.0
        };
        let count = |e: f32| ((e / tile).ceil() as u32).clamp(1, tiles);
        GridFrame {
            d,
            u,
            v,
            u0: lo_u,
            v0: lo_v,
            tile,
            inv_tile: 1.0 / tile,
            nu: count(hi_u - lo_u),
            nv: count(hi_v - lo_v),
        }
    }

    pub fn tile_count(&self) -> usize {
        self.nu as usize * self.nv as usize
    }

    /// A point in grid coordinates: tile units along `u` and `v` from the base corner,
    /// and depth along `d`.
    #[inline]
    pub fn project(&self, p: Vec3) -> [f32; 3] {
        [
            (p.dot(self.u) - self.u0) * self.inv_tile,
            (p.dot(self.v) - self.v0) * self.inv_tile,
            p.dot(self.d),
        ]
    }

    /// Calls `emit(tile_index, zmin, zmax)` for every tile the triangle touches, with the
    /// depth range of the part of the triangle over that tile. Conservative: the tile
    /// rectangles are grown by `margin` (world units) on every side, and depths by
    /// `margin` plus a relative allowance for the rounding of the clip, so a triangle
    /// that touches a tile, even at a corner, is listed in it whatever the rounding.
    pub fn raster(&self, tri: &[Vec3; 3], margin: f32, emit: impl FnMut(u32, f32, f32)) {
        self.raster_with(tri, margin, 1, emit)
    }

    /// As [`raster`](Self::raster), but a triangle whose grown bounding rectangle spans at
    /// most `coarse` tiles is listed in all of them with its whole depth range, without
    /// clipping: looser lists, much faster insertion (the dynamic layer, every frame).
    #[inline]
    pub fn raster_with(
        &self,
        tri: &[Vec3; 3],
        margin: f32,
        coarse: u32,
        mut emit: impl FnMut(u32, f32, f32),
    ) {
        let (p, m, dz, f) = self.prepare(tri, margin);
        if f.tiles() <= coarse {
            for j in f.j0..=f.j1 {
                for i in f.i0..=f.i1 {
                    emit(j * self.nu + i, f.zmin, f.zmax);
                }
            }
            return;
        }
        // Clipping takes the rectangle's sides in the order u_lo, u_hi, v_lo, v_hi, so
        // every tile of a column shares its first two clips: each column's strip is
        // clipped once (`Strip`), and each tile clips that by its own v sides alone. The
        // polygons, and so the depth ranges, are the ones a tile-by-tile clip gives, bit
        // for bit; a bake spent most of its time here (`benches/PERF.md`, issue 23,
        // step 5). `tests::column_clipping_is_tile_clipping_bit_for_bit` holds it to the
        // tile-by-tile clip.
        let columns = (f.i1 - f.i0 + 1) as usize;
        let strip = |i: u32| Strip::of(&p, i as f32 - m, i as f32 + 1.0 + m);
        let mut local = [Strip::EMPTY; 16];
        let mut heap = Vec::new();
        let strips: &[Strip] = if columns <= local.len() {
            for (k, s) in local[..columns].iter_mut().enumerate() {
                *s = strip(f.i0 + k as u32);
            }
            &local[..columns]
        } else {
            heap.extend((f.i0..=f.i1).map(strip));
            &heap
        };
        for j in f.j0..=f.j1 {
            let (v_lo, v_hi) = (j as f32 - m, j as f32 + 1.0 + m);
            for (i, s) in (f.i0..=f.i1).zip(strips) {
                if let Some((a, b)) = s.depth_range(v_lo, v_hi) {
                    emit(j * self.nu + i, a - dz, b + dz);
                }
            }
        }
    }

    /// The coarse listing of [`raster_with`](Self::raster_with) as one rectangle, when
    /// the triangle's grown bounding rectangle spans at most `coarse` tiles: every tile
    /// of it, each with the whole grown depth range. `None` for a larger triangle, which
    /// `raster_with` clips tile by tile.
    #[inline]
    pub fn coarse_footprint(&self, tri: &[Vec3; 3], margin: f32, coarse: u32) -> Option<Footprint> {
        let (_, _, _, f) = self.prepare(tri, margin);
        (f.tiles() <= coarse).then_some(f)
    }

    /// The triangle in grid coordinates, the margin in tile units, the depth allowance
    /// and the grown bounding rectangle with the grown depth range.
    #[inline(always)]
    fn prepare(&self, tri: &[Vec3; 3], margin: f32) -> ([[f32; 3]; 3], f32, f32, Footprint) {
        // `project` for the three vertices, three lanes at a time: the same products
        // summed in the same order, so the same bits (`projection_is_project` below).
        let (u, v, d) = (self.u, self.v, self.d);
        let m3 = Mat3A::from_cols(
            Vec3A::new(u.x, v.x, d.x),
            Vec3A::new(u.y, v.y, d.y),
            Vec3A::new(u.z, v.z, d.z),
        );
        let (off, scale) = (
            Vec3A::new(self.u0, self.v0, 0.0),
            Vec3A::new(self.inv_tile, self.inv_tile, 1.0),
        );
        let q = tri.map(|x| (m3 * Vec3A::from(x) - off) * scale);
        let p = q.map(|x| x.to_array());
        let (lo, hi) = (q[0].min(q[1]).min(q[2]), q[0].max(q[1]).max(q[2]));
        let m = margin * self.inv_tile;
        let (lo_u, hi_u, lo_v, hi_v) = (lo.x - m, hi.x + m, lo.y - m, hi.y + m);
        let (zmin, zmax) = (lo.z, hi.z);
        let dz = margin + 1e-5 * (zmax - zmin);
        let [i0, i1, j0, j1] = cells([lo_u, hi_u, lo_v, hi_v], self.nu, self.nv);
        let f = Footprint {
            i0,
            i1,
            j0,
            j1,
            zmin: zmin - dz,
            zmax: zmax + dz,
        };
        (p, m, dz, f)
    }
}

/// The columns and rows of tiles that the rectangle `[lo_u, hi_u, lo_v, hi_v]` (tile
/// units) reaches: each bound clamped to `0..=n - 1` and truncated, which is its floor
/// once clamped; NaN gives 0. `nu` and `nv` are at least 1 and at most
/// [`PsfParams::MAX_TILES`](super::PsfParams::MAX_TILES).
#[inline(always)]
fn cells(r: [f32; 4], nu: u32, nv: u32) -> [u32; 4] {
    clamped_floor(r, [nu - 1, nu - 1, nv - 1, nv - 1])
}

/// Each of `r` clamped to `0..=top` and truncated, which is its floor once clamped; NaN
/// gives 0. Every `top` at most `i16::MAX`.
///
/// On x86-64 the four go through one clamp and one conversion (SSE2, always there):
/// four scalar conversions, each with its saturation checks, had been a fifth of an
/// insertion's time (`benches/PERF.md`, step 90). The result is the same.
#[inline(always)]
pub(crate) fn clamped_floor(r: [f32; 4], top: [u32; 4]) -> [u32; 4] {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    // SAFETY: these intrinsics are unsafe only for the target feature they need, SSE2
    // (SSE for some), and the `cfg` above compiles this block only where the build
    // enables it (always, on x86-64); none of them reads or writes memory.
    unsafe {
        use std::arch::x86_64::*;
        let t = top.map(|t| t as i32 as f32);
        // `maxps` gives its second operand, 0, where the first is NaN.
        let x = _mm_max_ps(_mm_set_ps(r[3], r[2], r[1], r[0]), _mm_setzero_ps());
        let x = _mm_min_ps(x, _mm_set_ps(t[3], t[2], t[1], t[0]));
        // Whole numbers in 0..=i16::MAX: exact as i32, and as i16 after packing.
        let w = _mm_cvtsi128_si64(_mm_packs_epi32(_mm_cvttps_epi32(x), _mm_setzero_si128()));
        let w = w as u64;
        [0, 16, 32, 48].map(|s| (w >> s) as u16 as u32)
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
    clamped_floor_scalar(r, top)
}

/// [`clamped_floor`] one at a time.
#[cfg_attr(all(target_arch = "x86_64", target_feature = "sse2"), allow(dead_code))]
fn clamped_floor_scalar(r: [f32; 4], top: [u32; 4]) -> [u32; 4] {
    // Truncation is floor once negatives are clamped to 0, without `floor`'s libm call;
    // `as` saturates and maps NaN to 0.
    std::array::from_fn(|k| ((r[k].max(0.0) as i64).min(top[k] as i64)) as u32)
}

/// A rectangle of tiles, columns `i0..=i1` and rows `j0..=j1`, with a depth range.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Footprint {
    pub i0: u32,
    pub i1: u32,
    pub j0: u32,
    pub j1: u32,
    pub zmin: f32,
    pub zmax: f32,
}

impl Footprint {
    /// Tiles in the rectangle.
    #[inline]
    pub fn tiles(&self) -> u32 {
        (self.i1 - self.i0 + 1) * (self.j1 - self.j0 + 1)
    }
}

/// A convex polygon of at most nine vertices (grid coordinates, depth carried along):
/// a triangle clipped by up to four axis-aligned planes.
#[derive(Clone, Copy)]
struct Poly {
    v: [[f32; 3]; 9],
    n: usize,
}

impl Poly {
    /// The part of the polygon on the kept side of one plane (Sutherland-Hodgman,
    /// boundary inclusive): `axis` 0 (u) or 1 (v), the side `>= bound` when `sign` is
    /// +1, `<= bound` when -1. `n == 0` when nothing is left.
    #[inline]
    fn clip(&self, axis: usize, bound: f32, sign: f32) -> Poly {
        let mut out = Poly {
            v: [[0.0; 3]; 9],
            n: 0,
        };
        let n = self.n;
        for k in 0..n {
            let a = self.v[k];
            let b = self.v[(k + 1) % n];
            let da = (a[axis] - bound) * sign;
            let db = (b[axis] - bound) * sign;
            if da >= 0.0 {
                out.v[out.n] = a;
                out.n += 1;
            }
            if (da >= 0.0) != (db >= 0.0) {
                let s = da / (da - db);
                out.v[out.n] = [
                    a[0] + (b[0] - a[0]) * s,
                    a[1] + (b[1] - a[1]) * s,
                    a[2] + (b[2] - a[2]) * s,
                ];
                out.n += 1;
            }
        }
        out
    }

    /// The depth range of the vertices.
    fn depth_range(&self) -> (f32, f32) {
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        for q in &self.v[..self.n] {
            lo = lo.min(q[2]);
            hi = hi.max(q[2]);
        }
        (lo, hi)
    }
}

/// A triangle clipped to one column of tiles, `u_lo <= u <= u_hi`: the first two of the
/// four clips that give a tile's depth range ([`GridFrame::raster`]).
#[derive(Clone, Copy)]
struct Strip(Poly);

impl Strip {
    const EMPTY: Strip = Strip(Poly {
        v: [[0.0; 3]; 9],
        n: 0,
    });

    #[inline]
    fn of(tri: &[[f32; 3]; 3], u_lo: f32, u_hi: f32) -> Strip {
        let mut p = Poly {
            v: [[0.0; 3]; 9],
            n: 3,
        };
        p.v[..3].copy_from_slice(tri);
        let p = p.clip(0, u_lo, 1.0);
        if p.n == 0 {
            return Strip::EMPTY;
        }
        Strip(p.clip(0, u_hi, -1.0))
    }

    /// The depth range of the column's part within `v_lo <= v <= v_hi`, `None` when
    /// there is none: the last two clips.
    #[inline]
    fn depth_range(&self, v_lo: f32, v_hi: f32) -> Option<(f32, f32)> {
        if self.0.n == 0 {
            return None;
        }
        let p = self.0.clip(1, v_lo, 1.0);
        if p.n == 0 {
            return None;
        }
        let p = p.clip(1, v_hi, -1.0);
        (p.n > 0).then(|| p.depth_range())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_clamp_and_floor_every_bound() {
        // The vector form against one bound at a time, and both against the definition.
        let special = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -0.0,
            0.0,
            -1e-30,
            0.999_999_94,
            1.0,
            7.0,
            7.5,
            8.0,
            4095.0,
            4096.0,
            1e9,
            -1e9,
        ];
        let mut rng = crate::gen::synth::Rng::new(5);
        for (nu, nv) in [(1, 1), (8, 3), (64, 64), (4096, 17), (1, 4096)] {
            for k in 0..4000 {
                let r: [f32; 4] = std::array::from_fn(|c| {
                    let x = special[(k * 7 + c * 3) % special.len()];
                    if k % 3 == 0 {
                        x
                    } else {
                        (rng.f32() - 0.25) * 1.5 * [nu, nu, nv, nv][c] as f32
                    }
                });
                let want: [u32; 4] = std::array::from_fn(|c| {
                    let n = [nu, nu, nv, nv][c];
                    let x = r[c];
                    if x.is_nan() || x < 1.0 {
                        0
                    } else {
                        (x.floor() as f64).min((n - 1) as f64) as u32
                    }
                });
                assert_eq!(cells(r, nu, nv), want, "{r:?} in {nu} x {nv}");
                let top = [nu - 1, nu - 1, nv - 1, nv - 1];
                assert_eq!(clamped_floor_scalar(r, top), want, "{r:?} in {nu} x {nv}");
            }
        }
    }

    #[test]
    fn projection_is_project() {
        // The raster's three-lane projection against `project`, bit for bit.
        let mut rng = crate::gen::synth::Rng::new(99);
        for level in 0..3 {
            for dir in crate::psf::subfield_directions(level) {
                let b = Aabb {
                    min: Vec3::new(-3.0, -1.0, -7.0),
                    max: Vec3::new(5.0, 2.0, 1.0),
                };
                let g = GridFrame::new(dir, &b, 37);
                for _ in 0..200 {
                    let (lo, hi) = (Vec3::new(-9.0, -4.0, -11.0), Vec3::new(9.0, 4.0, 11.0));
                    let tri = [(); 3].map(|_| rng.in_box(lo, hi));
                    let (p, _, _, _) = g.prepare(&tri, 1e-3);
                    for k in 0..3 {
                        let want = g.project(tri[k]).map(f32::to_bits);
                        assert_eq!(p[k].map(f32::to_bits), want, "{dir} {tri:?}");
                    }
                }
            }
        }
    }

    fn grid() -> GridFrame {
        let b = Aabb {
            min: Vec3::ZERO,
            max: Vec3::splat(8.0),
        };
        GridFrame::new(Vec3::Z, &b, 8)
    }

    #[test]
    fn grid_covers_the_bounds_with_square_tiles() {
        let g = grid();
        assert_eq!((g.nu, g.nv), (8, 8));
        assert!((g.tile - 1.0).abs() < 1e-6);
        let b = Aabb {
            min: Vec3::ZERO,
            max: Vec3::new(8.0, 2.0, 1.0),
        };
        let g = GridFrame::new(Vec3::Z, &b, 8);
        assert_eq!(g.nu.max(g.nv), 8);
        assert_eq!(g.nu.min(g.nv), 2);
    }

    fn tiles_of(g: &GridFrame, tri: [Vec3; 3], margin: f32) -> Vec<(u32, f32, f32)> {
        let mut v = Vec::new();
        g.raster(&tri, margin, |t, a, b| v.push((t, a, b)));
        v
    }

    #[test]
    fn corner_touch_is_listed() {
        let g = grid();
        // A frame in which u, v are some rotation of x, y: find the grid position of a
        // tile corner and put a tiny triangle whose vertex sits exactly on it.
        let corner = g.u * (g.u0 + 3.0 * g.tile) + g.v * (g.v0 + 5.0 * g.tile) + g.d * 4.0;
        let tri = [corner, corner + g.u * 0.3, corner + g.v * 0.3];
        let t = tiles_of(&g, tri, 1e-5);
        let ids: Vec<u32> = t.iter().map(|x| x.0).collect();
        for (i, j) in [(2, 4), (3, 4), (2, 5), (3, 5)] {
            assert!(
                ids.contains(&(j * g.nu + i)),
                "tile ({i},{j}) missing from {ids:?}"
            );
        }
    }

    #[test]
    fn depth_range_is_per_tile() {
        let g = grid();
        // a slanted triangle: depth rises along u across many tiles
        let a = g.u * (g.u0 + 0.5) + g.v * (g.v0 + 0.5);
        let tri = [a, a + g.u * 6.0 + g.d * 6.0, a + g.v * 6.0];
        for (tile, lo, hi) in tiles_of(&g, tri, 1e-5) {
            let i = tile % g.nu;
            // depth over tile column i is at most about (i + 1) - 0.5 and at least i - 0.5 (clamped at 0)
            assert!(hi <= i as f32 + 0.6, "tile {tile}: hi {hi}");
            assert!(lo >= (i as f32 - 0.6).max(-0.1), "tile {tile}: lo {lo}");
        }
    }

    #[test]
    fn edge_on_triangle_is_listed_where_its_segment_runs() {
        let g = grid();
        let a = g.u * (g.u0 + 0.5) + g.v * (g.v0 + 0.5);
        // the triangle contains d: seen edge-on, a segment along u
        let tri = [a, a + g.u * 4.0, a + g.d * 3.0];
        let t = tiles_of(&g, tri, 1e-5);
        let ids: Vec<u32> = t.iter().map(|x| x.0).collect();
        assert_eq!(ids, vec![0, 1, 2, 3, 4]);
    }

    /// The tile-by-tile clip `raster` did before its columns were shared: the rectangle's
    /// four sides in turn (Sutherland-Hodgman), then the depth range.
    fn reference_clip(tri: &[[f32; 3]; 3], rect: [f32; 4]) -> Option<(f32, f32)> {
        let mut poly = [[0f32; 3]; 9];
        let mut n = 3;
        poly[..3].copy_from_slice(tri);
        let mut tmp = [[0f32; 3]; 9];
        let planes = [
            (0usize, rect[0], 1.0f32),
            (0, rect[1], -1.0),
            (1, rect[2], 1.0),
            (1, rect[3], -1.0),
        ];
        for (axis, bound, sign) in planes {
            let mut m = 0;
            for k in 0..n {
                let a = poly[k];
                let b = poly[(k + 1) % n];
                let da = (a[axis] - bound) * sign;
                let db = (b[axis] - bound) * sign;
                if da >= 0.0 {
                    tmp[m] = a;
                    m += 1;
                }
                if (da >= 0.0) != (db >= 0.0) {
                    let s = da / (da - db);
                    tmp[m] = [
                        a[0] + (b[0] - a[0]) * s,
                        a[1] + (b[1] - a[1]) * s,
                        a[2] + (b[2] - a[2]) * s,
                    ];
                    m += 1;
                }
            }
            if m == 0 {
                return None;
            }
            n = m;
            poly[..n].copy_from_slice(&tmp[..n]);
        }
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for q in &poly[..n] {
            lo = lo.min(q[2]);
            hi = hi.max(q[2]);
        }
        Some((lo, hi))
    }

    #[test]
    fn column_clipping_is_tile_clipping_bit_for_bit() {
        // Triangles small and large (more columns than the stack holds), thin and
        // edge-on, over grids of several tile counts and directions.
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for case in 0..400u32 {
            let seed = case;
            let d = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize_or(Vec3::Z);
            let tiles = [1u32, 3, 16, 40, 64][case as usize % 5];
            let b = Aabb {
                min: Vec3::splat(-1.0),
                max: Vec3::splat(1.0),
            };
            let frame = GridFrame::new(d, &b, tiles);
            let size = [0.01f32, 0.2, 1.5][case as usize % 3];
            let c = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
            let mut tri =
                [0; 3].map(|_| c + Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * size);
            if case % 7 == 0 {
                tri[2] = tri[0] + (tri[1] - tri[0]) * 0.5; // degenerate: a segment
            }
            let margin = 1e-3;
            let mut got = Vec::new();
            frame.raster(&tri, margin, |t, a, b| {
                got.push((t, a.to_bits(), b.to_bits()))
            });
            let (p, m, dz, f) = frame.prepare(&tri, margin);
            let mut want = Vec::new();
            for j in f.j0..=f.j1 {
                for i in f.i0..=f.i1 {
                    let rect = [
                        i as f32 - m,
                        i as f32 + 1.0 + m,
                        j as f32 - m,
                        j as f32 + 1.0 + m,
                    ];
                    if let Some((a, b)) = reference_clip(&p, rect) {
                        want.push((j * frame.nu + i, (a - dz).to_bits(), (b + dz).to_bits()));
                    }
                }
            }
            assert_eq!(got, want, "case {seed}");
        }
    }
}
