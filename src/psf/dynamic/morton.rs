//! The Morton order of a frame's triangles (by centroid), so that a tile's candidates
//! and its neighbours' sit together in memory.

use glam::Vec3;

use crate::geometry::Aabb;
use crate::psf::grid::clamped_floor;

/// The low 10 bits of `v` moved to every third bit.
const fn spread3(v: u32) -> u32 {
    let mut v = v & 0x3ff;
    v = (v | (v << 16)) & 0x0300_00ff;
    v = (v | (v << 8)) & 0x0300_f00f;
    v = (v | (v << 4)) & 0x030c_30c3;
    (v | (v << 2)) & 0x0924_9249
}

/// [`spread3`] of every 10-bit number: three loads instead of twelve shifts and masks
/// a key (the keys were a third of the reorder's time).
static SPREAD3: [u32; 1024] = {
    let mut t = [0u32; 1024];
    let mut i = 0;
    while i < 1024 {
        t[i] = spread3(i as u32);
        i += 1;
    }
    t
};

/// Interleaves the low 10 bits of `x`, `y`, `z` (`x` lowest).
#[inline]
fn morton3(x: u32, y: u32, z: u32) -> u32 {
    let t = |v: u32| SPREAD3[(v & 0x3ff) as usize];
    t(x) | (t(y) << 1) | (t(z) << 2)
}

/// Fills `order` with the triangles sorted by the Morton code of their centroid within
/// `bounds`, cut to a bucket for every one to eight triangles (a stable counting sort,
/// so ties keep the input order and the result depends on the input alone); `keys` and
/// `counts` are scratch.
pub(super) fn morton_order(
    tris: &[[Vec3; 3]],
    bounds: &Aabb,
    keys: &mut Vec<u32>,
    counts: &mut Vec<u32>,
    order: &mut Vec<u32>,
    rank: &mut Vec<u32>,
) {
    let n = tris.len();
    // 3 bits of code per level of an octree with n / 8 to n leaves, 3..=27 bits. A
    // level finer (up to eight buckets a triangle) sorted no better for the insertions
    // and the queries and updated 4-6% slower: its counts outgrow the first-level cache
    // (`benches/PERF.md`, step 80).
    let levels = ((usize::BITS - n.leading_zeros()).div_ceil(3)).clamp(2, 10) - 1;
    let bits = 3 * levels;
    let scale = Vec3::splat((1u32 << levels) as f32) / bounds.extent().max(Vec3::splat(1e-30));
    let top = (1u32 << levels) - 1;
    keys.clear();
    keys.extend(tris.iter().map(|t| {
        let c = ((t[0] + t[1] + t[2]) * (1.0 / 3.0) - bounds.min) * scale;
        let [x, y, z, _] = clamped_floor([c.x, c.y, c.z, 0.0], [top; 4]);
        morton3(x, y, z)
    }));
    counts.clear();
    counts.resize((1usize << bits) + 1, 0);
    for &k in keys.iter() {
        counts[k as usize + 1] += 1;
    }
    for i in 0..1usize << bits {
        counts[i + 1] += counts[i];
    }
    order.clear();
    order.resize(n, 0);
    rank.clear();
    for (i, &k) in keys.iter().enumerate() {
        let at = &mut counts[k as usize];
        order[*at as usize] = i as u32;
        rank.push(*at);
        *at += 1;
    }
}
