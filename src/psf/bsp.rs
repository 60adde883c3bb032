//! The per-tile 1D BSP along the beam (the paper's "low resolution 1D BSP"), and the
//! flat tiles that replace it for short lists.
//!
//! A tile's depth range `[z0, z1]` is split at midpoints down to a fixed depth; the
//! leaves of that complete tree are equal slabs, so we store them flattened: descending
//! the tree to the leaf holding a depth is one multiply (`slab_of`), and visiting the
//! leaves near to far is walking the slab array forwards (ray along `+d`) or backwards
//! (along `-d`). An entry is listed in every slab its depth range overlaps. Walking, an
//! entry is tested only in the first slab of the walk that lists it, so nothing is
//! tested twice within a tile.
//!
//! A tile of at most [`FLAT_MAX`] entries is *flat* instead: its entries in order of
//! `zmin`, in [`Block`]s of eight with the depths by columns, which a query filters by
//! its depth interval eight at a time ([`depth_mask`]) with no slab to find and no entry
//! to skip. The slab machinery (the depth map, two slab lookups, a loop over slabs and
//! the check against testing an entry twice) cost more than scanning a short list: on
//! the museum-class scene flat tiles up to 32 entries traced 7–8% faster, and 17%
//! faster on the 1M-triangle room, where every tile flat was slower (`benches/PERF.md`,
//! step 48).

use bytemuck::{Pod, Zeroable};
use glam::Vec4;

/// One tile: where its slabs start, how many, and the affine map from depth to slab; or,
/// for a flat tile (`FLAT` set in `slab_count`), where its blocks start and how many.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TileHeader {
    /// Index of the tile's first slab start in the subfield's `slab_starts`; the tile owns
    /// `slab_count + 1` consecutive starts (the last one ends its last slab). For a flat
    /// tile, the index of its first block in the subfield's `blocks`.
    pub first_slab: u32,
    /// 0 for an empty tile; `FLAT` plus the block count (1..=4) for a flat tile.
    pub slab_count: u32,
    pub z0: f32,
    /// `slab_count / (z1 - z0)`, 0 when all entries share one depth (0 for a flat tile).
    pub inv_slab: f32,
}

/// The bit of [`TileHeader::slab_count`] that marks a flat tile.
pub const FLAT: u32 = 1 << 31;

/// Tiles of at most this many entries are flat: up to four blocks.
pub const FLAT_MAX: usize = 32;

/// Entries in a block: one bit each in [`depth_mask`].
pub const LANES: usize = 8;

/// Eight entries, the depths by columns: a query filters them by depth with two
/// loads a column and reads the triangle numbers beside them. Unused lanes are
/// `PADDING`'s: a depth range from +inf to -inf, which no interval meets.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Block {
    pub zmin: [f32; LANES],
    pub zmax: [f32; LANES],
    pub tri: [u32; LANES],
}

/// A block of padding.
pub const PADDING: Block = Block {
    zmin: [f32::INFINITY; LANES],
    zmax: [f32::NEG_INFINITY; LANES],
    tri: [0; LANES],
};

impl Block {
    /// The lanes holding entries (not padding).
    pub fn used(&self) -> impl Iterator<Item = Entry> + '_ {
        (0..LANES)
            .filter(|&j| self.zmin[j] <= self.zmax[j])
            .map(|j| Entry {
                tri: self.tri[j],
                zmin: self.zmin[j],
                zmax: self.zmax[j],
            })
    }
}

/// Bit `j` set where entry `j` of a block overlaps `[lo, hi]`: two 4-wide compares and a
/// move-mask each half.
#[inline(always)]
pub fn depth_mask(b: &Block, lo: Vec4, hi: Vec4) -> u32 {
    let (zmin, zmax) = (&b.zmin, &b.zmax);
    let lower =
        (Vec4::from_slice(&zmax[..4]).cmpge(lo) & Vec4::from_slice(&zmin[..4]).cmple(hi)).bitmask();
    let upper =
        (Vec4::from_slice(&zmax[4..]).cmpge(lo) & Vec4::from_slice(&zmin[4..]).cmple(hi)).bitmask();
    lower | upper << 4
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
const _: () = assert!(std::mem::size_of::<Block>() == 96);

/// Slabs a tile gets for `n` entries by default: about `LEAF` entries a slab, at most
/// `MAX_SLABS`. Low resolution on purpose: most tiles hold a handful of triangles.
pub const LEAF: usize = 3;
pub const MAX_SLABS: usize = 32;

/// How a tile's list is laid out: the BSP's resolution and the flat tiles' threshold.
/// Only the bake reads these (a reader traces whatever layout each tile header gives),
/// so `bake --quality high` may tune them per scene; the file records them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BspParams {
    /// Entries a slab aims at, `1..=MAX_SLABS` (slabs: `ceil(n / leaf)`, at most
    /// [`MAX_SLABS`]); fewer make a deeper BSP.
    pub leaf: u32,
    /// Tiles of at most this many entries are flat, `0..=FLAT_MAX` (0: none).
    pub flat_max: u32,
}

impl Default for BspParams {
    fn default() -> Self {
        BspParams {
            leaf: LEAF as u32,
            flat_max: FLAT_MAX as u32,
        }
    }
}

impl BspParams {
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=MAX_SLABS as u32).contains(&self.leaf) {
            return Err(format!(
                "entries a slab {} is outside 1..={MAX_SLABS}",
                self.leaf
            ));
        }
        if self.flat_max > FLAT_MAX as u32 {
            return Err(format!(
                "flat-tile threshold {} is above {FLAT_MAX}",
                self.flat_max
            ));
        }
        Ok(())
    }
}

/// Slabs for `n` entries, about `leaf` entries a slab, at most [`MAX_SLABS`].
pub fn slab_count_with(n: usize, leaf: usize) -> u32 {
    if n == 0 {
        0
    } else {
        n.div_ceil(leaf.max(1)).clamp(1, MAX_SLABS) as u32
    }
}

impl TileHeader {
    pub fn is_flat(&self) -> bool {
        self.slab_count & FLAT != 0
    }

    /// A flat tile's blocks, as indices into the subfield's `blocks` (empty for a BSP
    /// tile).
    pub fn blocks(&self) -> std::ops::Range<usize> {
        if self.is_flat() {
            let first = self.first_slab as usize;
            first..first + (self.slab_count & !FLAT) as usize
        } else {
            0..0
        }
    }

    /// A BSP tile's slab count (0 for an empty or a flat tile).
    pub fn slabs(&self) -> u32 {
        if self.is_flat() {
            0
        } else {
            self.slab_count
        }
    }

    /// The slab holding depth `z`, clamped into the tile. Monotone in `z`.
    #[inline]
    pub fn slab_of(&self, z: f32) -> u32 {
        // Truncation is floor once negatives are clamped to 0 (and `floor` is a libm call
        // on baseline x86-64: 5% of trace time). `as` saturates; NaN gives 0.
        (((z - self.z0) * self.inv_slab).max(0.0) as u32).min(self.slab_count - 1)
    }
}

/// Builds one tile from its entries (at most one a triangle): flat, its entries in
/// order of `zmin` (ties by triangle) appended to `blocks`, when there are at most
/// `bsp.flat_max`; otherwise its slabs (about `bsp.leaf` entries each), appended to
/// `slab_starts` and `out` (offsets in `slab_starts` are absolute indices into `out`).
pub fn build_tile(
    entries: &[Entry],
    bsp: &BspParams,
    slab_starts: &mut Vec<u32>,
    out: &mut Vec<Entry>,
    blocks: &mut Vec<Block>,
) -> TileHeader {
    if !entries.is_empty() && entries.len() <= (bsp.flat_max as usize).min(FLAT_MAX) {
        let mut list = entries.to_vec();
        list.sort_by(|a, b| a.zmin.total_cmp(&b.zmin).then(a.tri.cmp(&b.tri)));
        let first = blocks.len() as u32;
        for chunk in list.chunks(LANES) {
            let mut b = PADDING;
            for (j, e) in chunk.iter().enumerate() {
                b.zmin[j] = e.zmin;
                b.zmax[j] = e.zmax;
                b.tri[j] = e.tri;
            }
            blocks.push(b);
        }
        return TileHeader {
            first_slab: first,
            slab_count: FLAT | (blocks.len() as u32 - first),
            z0: 0.0,
            inv_slab: 0.0,
        };
    }
    build_slabs_with(entries, bsp.leaf as usize, slab_starts, out)
}

/// A tile's BSP slabs, about `leaf` entries a slab, whatever its entry count.
pub fn build_slabs_with(
    entries: &[Entry],
    leaf: usize,
    slab_starts: &mut Vec<u32>,
    out: &mut Vec<Entry>,
) -> TileHeader {
    let first_slab = slab_starts.len() as u32;
    let n = slab_count_with(entries.len(), leaf);
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
        let h = build_slabs_with(&entries, LEAF, &mut starts, &mut out);
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
        let h = build_slabs_with(&entries, LEAF, &mut starts, &mut out);
        assert_eq!(h.inv_slab, 0.0);
        assert_eq!(h.slab_of(1e30), 0);
        assert_eq!(starts[1] - starts[0], 10);
    }

    #[test]
    fn short_lists_are_flat_in_order_of_zmin() {
        let entries: Vec<Entry> = (0..11)
            .map(|i| Entry {
                tri: i,
                zmin: ((i * 7) % 11) as f32,
                zmax: ((i * 7) % 11) as f32 + 0.5,
            })
            .collect();
        let (mut starts, mut out, mut blocks) = (Vec::new(), Vec::new(), vec![PADDING]);
        let h = build_tile(
            &entries,
            &BspParams::default(),
            &mut starts,
            &mut out,
            &mut blocks,
        );
        assert!(h.is_flat());
        assert_eq!(h.slabs(), 0);
        assert_eq!(h.blocks(), 1..3);
        assert!(starts.is_empty() && out.is_empty());
        let listed: Vec<Entry> = blocks[h.blocks()].iter().flat_map(|b| b.used()).collect();
        assert_eq!(listed.len(), 11);
        assert!(listed.windows(2).all(|w| w[0].zmin <= w[1].zmin));
        let mut tris: Vec<u32> = listed.iter().map(|e| e.tri).collect();
        tris.sort();
        assert_eq!(tris, (0..11).collect::<Vec<_>>());
        // The padding lanes of the last block meet no interval.
        let wide = (Vec4::splat(f32::MIN), Vec4::splat(f32::MAX));
        assert_eq!(depth_mask(&blocks[2], wide.0, wide.1), 0b111);
    }

    #[test]
    fn the_layout_sets_the_flat_threshold_and_the_slab_count() {
        let entries: Vec<Entry> = (0..12)
            .map(|i| Entry {
                tri: i,
                zmin: i as f32,
                zmax: i as f32 + 0.5,
            })
            .collect();
        let build = |leaf, flat_max| {
            let (mut starts, mut out, mut blocks) = (Vec::new(), Vec::new(), Vec::new());
            build_tile(
                &entries,
                &BspParams { leaf, flat_max },
                &mut starts,
                &mut out,
                &mut blocks,
            )
        };
        assert!(build(3, 32).is_flat());
        assert!(build(3, 12).is_flat());
        assert!(!build(3, 11).is_flat());
        assert_eq!(build(3, 0).slabs(), 4);
        assert_eq!(build(1, 0).slabs(), 12);
        assert_eq!(build(8, 0).slabs(), 2);
        assert!(BspParams {
            leaf: 0,
            flat_max: 0
        }
        .validate()
        .is_err());
        assert!(BspParams {
            leaf: 3,
            flat_max: 33
        }
        .validate()
        .is_err());
        assert!(BspParams::default().validate().is_ok());
    }

    #[test]
    fn long_lists_keep_the_bsp() {
        let entries: Vec<Entry> = (0..FLAT_MAX as u32 + 1)
            .map(|i| Entry {
                tri: i,
                zmin: i as f32,
                zmax: i as f32 + 1.0,
            })
            .collect();
        let (mut starts, mut out, mut blocks) = (Vec::new(), Vec::new(), Vec::new());
        let h = build_tile(
            &entries,
            &BspParams::default(),
            &mut starts,
            &mut out,
            &mut blocks,
        );
        assert!(!h.is_flat());
        assert_eq!(h.slabs(), slab_count_with(entries.len(), LEAF));
        assert!(blocks.is_empty());
        assert_eq!(h.blocks(), 0..0);
    }
}
