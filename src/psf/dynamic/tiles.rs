//! The dynamic layer's store per direction: each tile's version and run ([`Slot`]), the
//! entries in blocks, and the scratch an insertion reuses. Uses none of its siblings.

use glam::Vec3;

use crate::psf::bsp::{Block, LANES, PADDING};
use crate::psf::{Entry, GridFrame};

#[derive(Debug)]
pub(super) struct DynSubfield {
    pub(super) dir: Vec3,
    pub(super) frame: GridFrame,
    /// Per tile of the largest grid the parameters allow (`tiles × tiles`): its version
    /// `V` and, when current, its run of `entries`.
    pub(super) slots: Vec<Slot>,
    /// This frame's entries, grouped by tile (in tile order, or in order of first touch
    /// when counted tile by tile), in blocks of 8, so a query filters a tile's list by
    /// depth eight entries at a time (`depth_mask`). Each tile's run starts at a
    /// multiple of 8 and is padded to one with entries no depth interval meets.
    pub(super) entries: Entries,
    /// Scratch reused every update: whether this frame counts densely, each triangle's
    /// rectangle of tiles in the input order (for a triangle clipped tile by tile, where
    /// its entries lie in `raw`), the clipped triangles' entries in raster order as
    /// (tile, zmin, zmax), the tiles touched (counting tile by tile), the difference
    /// array of the counts (dense counting, `(nu + 1) × (nv + 1)`) and each tile's write
    /// position.
    pub(super) dense: bool,
    pub(super) rects: Vec<Rect>,
    pub(super) raw: Vec<(u32, f32, f32)>,
    pub(super) touched: Vec<u32>,
    pub(super) diff: Vec<i32>,
    pub(super) cursor: Vec<u32>,
}

#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Slot {
    pub(super) version: u32,
    pub(super) start: u32,
    pub(super) count: u32,
}

/// Entries in blocks of `LANES`, each block's depths by columns: a query filters a
/// block by depth with two loads (`depth_mask`) and reads the triangle numbers beside
/// them, and an insertion writes an entry into one block.
#[derive(Debug, Default)]
pub(super) struct Entries {
    pub(super) blocks: Vec<Block>,
}

impl Entries {
    pub(super) fn capacity(&self) -> usize {
        self.blocks.capacity() * LANES
    }

    /// At least `n` entries (a multiple of `LANES`). The buffer only grows, its new
    /// blocks padding, and keeps headroom: grown to 5/4 of the need whenever it is short,
    /// so it settles after the first frames instead of doubling whenever a frame sets a
    /// record. What lies beyond this frame's runs is never read.
    pub(super) fn ensure(&mut self, n: usize) {
        let need = n / LANES;
        if self.blocks.capacity() < need {
            let want = (n + n / 4).div_ceil(LANES);
            self.blocks.reserve_exact(want - self.blocks.len());
        }
        if self.blocks.len() < need {
            self.blocks.resize(need, PADDING);
        }
    }

    /// Padding in the block holding entry `i` (the first place after a run whose last
    /// block is not full; the run's entries are written into the block afterwards).
    #[inline]
    pub(super) fn pad(&mut self, i: usize) {
        self.blocks[i / LANES] = PADDING;
    }

    #[inline]
    pub(super) fn set(&mut self, i: usize, e: &Entry) {
        let b = &mut self.blocks[i / LANES];
        b.zmin[i % LANES] = e.zmin;
        b.zmax[i % LANES] = e.zmax;
        b.tri[i % LANES] = e.tri;
    }
}

/// A coarse triangle's [`Footprint`](super::grid::Footprint), packed in 16 bytes: the
/// second pass of an insertion reads it instead of an entry record per tile. `lo` and
/// `hi` are the bits of its depth range or, for a triangle clipped tile by tile (`i0 ==
/// Rect::CLIPPED`), the range of its entries in `raw`.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Rect {
    pub(super) i0: u16,
    pub(super) i1: u16,
    pub(super) j0: u16,
    pub(super) j1: u16,
    pub(super) lo: u32,
    pub(super) hi: u32,
}

impl Rect {
    /// No column is this (tile indices are below `PsfParams::MAX_TILES`, 4096).
    pub(super) const CLIPPED: u16 = u16::MAX;
}
