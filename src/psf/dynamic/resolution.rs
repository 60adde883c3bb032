//! The moving grid's resolution, chosen per frame from the triangles' sizes.
//!
//! The grids cover this frame's bounds of the moving triangles. With a fixed tile count,
//! triangles gathered into a ball a few of their widths across span hundreds of tiles
//! each, every one clipped tile by tile: the update had taken 70 ms on the first frames
//! of the shared generator's scenes (issue 23) against 2 ms once they spread out. So the
//! tile count is capped by the typical triangle's size: the tile is kept no smaller than
//! about `1 / SPAN` of the median triangle's extent, whatever the spread. Spread-out
//! frames keep the parameters' tile count. Any grid gives the same hits (the lists are
//! conservative whatever the tiles), so the choice changes only the time.

use glam::Vec3;

use crate::geometry::Aabb;

/// Tiles across the median triangle's extent, at most (within a factor of 2: the count
/// is a power of two). On the shared generator's 16k scene at its cluster
/// (`benches/PERF.md`, issue 23, step 1), one thread, fastest frames: updates of 1.1–1.3
/// ms at 2, 1.9–2.0 at 4 and 43–47 at 8 (triangles clipped again), against 460–620 ms
/// with the fixed tile count (two threads); dynamic candidates a reflection ray 2.9,
/// 1.1, 0.2, and 0.04 with the fixed count. 2 was kept then; once the rest of the frame
/// had grown faster, 4 paid: the benchmark's dolly and still frames traced 3–4 ms
/// faster for an update 1 ms longer, other scenes unchanged (issue 38, round 14).
pub(super) const SPAN: f32 = 4.0;

/// Bins of the histogram of `log2(extent of the bounds / extent of a triangle)`.
const BINS: usize = 32;

/// The tile count of this frame's grids: `max_tiles`, or fewer when the median
/// triangle's extent (its bounding box's longest side) is more than `1 / SPAN` of the
/// tile `max_tiles` would give over `bounds`. One pass over the triangles, no sort and
/// no allocation: the median is taken on a histogram of powers of two, so the count is
/// `SPAN` times a power of two (at least 1), the same on every machine. `tris` must be
/// finite and inside `bounds` (as [`super::checked_bounds`] gives them).
pub(super) fn frame_tiles(tris: &[[Vec3; 3]], bounds: &Aabb, max_tiles: u32) -> u32 {
    let side = (bounds.max - bounds.min).max_element();
    if tris.is_empty() || !side.is_finite() || side <= 0.0 {
        return max_tiles;
    }
    let mut hist = [0u32; BINS];
    for t in tris {
        let ext = (t[0].max(t[1]).max(t[2]) - t[0].min(t[1]).min(t[2])).max_element();
        // The exponent of side / ext, read off the bits: ext == 0 gives infinity, the
        // top bin (such a triangle never asks for larger tiles).
        let ratio = side / ext;
        let e = ((ratio.to_bits() >> 23) & 0xff) as i32 - 127;
        hist[e.clamp(0, BINS as i32 - 1) as usize] += 1;
    }
    // The bin holding the median triangle: its ratio is at least 2^bin.
    let half = tris.len().div_ceil(2) as u32;
    let mut seen = 0;
    let mut bin = BINS - 1;
    for (k, &n) in hist.iter().enumerate() {
        seen += n;
        if seen >= half {
            bin = k;
            break;
        }
    }
    let want = SPAN * (1u64 << bin) as f32;
    if want >= max_tiles as f32 {
        max_tiles
    } else {
        (want as u32).clamp(1, max_tiles)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(c: Vec3, s: f32) -> [Vec3; 3] {
        [c, c + Vec3::new(s, 0.0, 0.0), c + Vec3::new(0.0, s, 0.0)]
    }

    fn bounds(tris: &[[Vec3; 3]]) -> Aabb {
        Aabb::from_triangles(tris)
    }

    #[test]
    fn spread_small_triangles_keep_the_parameters_tiles() {
        // 100 triangles of side 0.1 along a 100-wide line: ratio 1000 > 64.
        let tris: Vec<_> = (0..100)
            .map(|k| tri(Vec3::new(k as f32, 0.0, 0.0), 0.1))
            .collect();
        assert_eq!(frame_tiles(&tris, &bounds(&tris), 64), 64);
    }

    #[test]
    fn clustered_triangles_get_tiles_about_their_size() {
        // Triangles of side 1 in a box 3.25 across: every ratio is 3.25, in [2, 4).
        let tris: Vec<_> = (0..50)
            .map(|k| tri(Vec3::splat((k % 4) as f32 * 0.75), 1.0))
            .collect();
        let b = bounds(&tris);
        assert_eq!((b.max - b.min).max_element(), 3.25);
        assert_eq!(frame_tiles(&tris, &b, 64), (SPAN * 2.0) as u32);
        // A finer cap still caps.
        assert_eq!(frame_tiles(&tris, &b, 1), 1);
    }

    #[test]
    fn one_triangle_spanning_everything_gives_one_tile_per_span() {
        let tris = [tri(Vec3::ZERO, 3.0)];
        assert_eq!(
            frame_tiles(&tris, &bounds(&tris), 128),
            (SPAN as u32).max(1)
        );
    }

    #[test]
    fn degenerate_frames_keep_the_parameters_tiles() {
        // All points at one place: no extent anywhere.
        let p = [[Vec3::ONE; 3]; 10];
        assert_eq!(frame_tiles(&p, &bounds(&p), 32), 32);
        assert_eq!(frame_tiles(&[], &Aabb::EMPTY, 32), 32);
        // Points spread out, one real triangle: the median is a point (top bin).
        let mut t: Vec<_> = (0..9).map(|k| [Vec3::splat(k as f32); 3]).collect();
        t.push(tri(Vec3::ZERO, 8.0));
        assert_eq!(frame_tiles(&t, &bounds(&t), 32), 32);
    }

    #[test]
    fn the_median_not_the_mean_decides() {
        // 60 small triangles spread out, 40 spanning the whole bounds: the small decide.
        let mut tris: Vec<_> = (0..60)
            .map(|k| tri(Vec3::new(k as f32, 0.0, 0.0), 0.01))
            .collect();
        tris.extend((0..40).map(|_| tri(Vec3::ZERO, 60.0)));
        assert_eq!(frame_tiles(&tris, &bounds(&tris), 256), 256);
    }
}
