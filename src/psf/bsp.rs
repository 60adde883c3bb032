//! The per-tile 1D BSP along the beam (the paper's "low resolution 1D BSP").
//!
//! A tile's depth range `[z0, z1]` is split at midpoints down to a fixed depth; the
//! leaves of that complete tree are equal slabs, so we store them flattened: descending
//! the tree to the leaf holding a depth is one multiply (`slab_of`), and visiting the
//! leaves near to far is walking the slab array forwards (ray along `+d`) or backwards
//! (along `-d`). An entry is listed in every slab its depth range overlaps. Walking, an
//! entry is tested only in the first slab of the walk that lists it, so nothing is
//! tested twice within a tile.

use bytemuck::{Pod, Zeroable};

/// One tile: where its slabs start, how many, and the affine map from depth to slab.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TileHeader {
    /// Index of the tile's first slab start in the subfield's `slab_starts`; the tile owns
    /// `slab_count + 1` consecutive starts (the last one ends its last slab).
    pub first_slab: u32,
    /// 0 for an empty tile.
    pub slab_count: u32,
    pub z0: f32,
    /// `slab_count / (z1 - z0)`, 0 when all entries share one depth.
    pub inv_slab: f32,
}

/// A triangle listed in a tile, with the depth range of its part over the tile.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Entry {
    pub tri: u32,
    pub zmin: f32,
    pub zmax: f32,
}

const _: () = assert!(std::mem::size_of::<TileHeader>() == 16);
const _: () = assert!(std::mem::size_of::<Entry>() == 12);

/// Slabs a tile gets for `n` entries: about `LEAF` entries a slab, at most `MAX_SLABS`.
/// Low resolution on purpose: most tiles hold a handful of triangles.
pub const LEAF: usize = 3;
pub const MAX_SLABS: usize = 32;

pub fn slab_count_for(n: usize) -> u32 {
    if n == 0 {
        0
    } else {
        n.div_ceil(LEAF).clamp(1, MAX_SLABS) as u32
    }
}

impl TileHeader {
    /// The slab holding depth `z`, clamped into the tile. Monotone in `z`.
    #[inline]
    pub fn slab_of(&self, z: f32) -> u32 {
        // Truncation is floor once negatives are clamped to 0 (and `floor` is a libm call
        // on baseline x86-64: 5% of trace time). `as` saturates; NaN gives 0.
        (((z - self.z0) * self.inv_slab).max(0.0) as u32).min(self.slab_count - 1)
    }
}

/// Builds one tile's slabs from its entries, appending to `slab_starts` and `out`
/// (offsets in `slab_starts` are absolute indices into `out`).
pub fn build_tile(
    entries: &[Entry],
    slab_starts: &mut Vec<u32>,
    out: &mut Vec<Entry>,
) -> TileHeader {
    let first_slab = slab_starts.len() as u32;
    let n = slab_count_for(entries.len());
    if n == 0 {
        return TileHeader {
            first_slab,
            slab_count: 0,
            z0: 0.0,
            inv_slab: 0.0,
        };
    }
    let z0 = entries.iter().map(|e| e.zmin).fold(f32::INFINITY, f32::min);
    let z1 = entries
        .iter()
        .map(|e| e.zmax)
        .fold(f32::NEG_INFINITY, f32::max);
    let inv = if z1 > z0 { n as f32 / (z1 - z0) } else { 0.0 };
    let hdr = TileHeader {
        first_slab,
        slab_count: n,
        z0,
        inv_slab: if inv.is_finite() { inv } else { 0.0 },
    };
    let mut counts = vec![0u32; n as usize];
    for e in entries {
        for s in hdr.slab_of(e.zmin)..=hdr.slab_of(e.zmax) {
            counts[s as usize] += 1;
        }
    }
    let mut start = out.len() as u32;
    let mut cursor = Vec::with_capacity(n as usize);
    for c in &counts {
        slab_starts.push(start);
        cursor.push(start as usize);
        start += c;
    }
    slab_starts.push(start);
    out.resize(start as usize, Entry::default());
    // Entries keep their order (ascending triangle index) within each slab.
    for e in entries {
        for s in hdr.slab_of(e.zmin)..=hdr.slab_of(e.zmax) {
            out[cursor[s as usize]] = *e;
            cursor[s as usize] += 1;
        }
    }
    hdr
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_land_in_every_slab_they_overlap() {
        let entries: Vec<Entry> = (0..12)
            .map(|i| Entry {
                tri: i,
                zmin: i as f32,
                zmax: i as f32 + if i == 5 { 6.0 } else { 0.5 },
            })
            .collect();
        let mut starts = Vec::new();
        let mut out = Vec::new();
        let h = build_tile(&entries, &mut starts, &mut out);
        assert_eq!(h.slab_count, 4);
        assert_eq!(starts.len(), 5);
        for s in 0..h.slab_count as usize {
            let slab = &out[starts[s] as usize..starts[s + 1] as usize];
            for e in &entries {
                let listed = slab.contains(e);
                let overlaps = h.slab_of(e.zmin) as usize <= s && s <= h.slab_of(e.zmax) as usize;
                assert_eq!(listed, overlaps, "entry {} slab {s}", e.tri);
            }
        }
        // the long entry spans several slabs
        assert!(h.slab_of(entries[5].zmax) > h.slab_of(entries[5].zmin));
    }

    #[test]
    fn equal_depths_use_one_slab() {
        let entries = vec![
            Entry {
                tri: 0,
                zmin: 1.0,
                zmax: 1.0
            };
            10
        ];
        let mut starts = Vec::new();
        let mut out = Vec::new();
        let h = build_tile(&entries, &mut starts, &mut out);
        assert_eq!(h.inv_slab, 0.0);
        assert_eq!(h.slab_of(1e30), 0);
        assert_eq!(starts[1] - starts[0], 10);
    }
}
