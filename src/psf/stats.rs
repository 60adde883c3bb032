//! Statistics: the structure's occupancy, and the work done per ray.

use super::Psf;

/// Work counters for traced rays, summed with `+=`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayStats {
    pub rays: u64,
    pub tiles_visited: u64,
    pub candidates_tested: u64,
    /// Tile entries looked at, whether or not their depth range let them through (a flat
    /// tile's blocks count eight lanes each).
    pub entries_scanned: u64,
    /// Flat tiles' blocks looked at (eight lanes filtered by depth at once; their lanes
    /// are in `entries_scanned` too).
    pub blocks_scanned: u64,
}

impl RayStats {
    pub fn tiles_per_ray(&self) -> f64 {
        self.tiles_visited as f64 / self.rays.max(1) as f64
    }

    pub fn candidates_per_ray(&self) -> f64 {
        self.candidates_tested as f64 / self.rays.max(1) as f64
    }
}

impl std::ops::AddAssign for RayStats {
    fn add_assign(&mut self, o: RayStats) {
        self.rays += o.rays;
        self.tiles_visited += o.tiles_visited;
        self.candidates_tested += o.candidates_tested;
        self.entries_scanned += o.entries_scanned;
        self.blocks_scanned += o.blocks_scanned;
    }
}

/// What the traversal counts; `NoCount` compiles to nothing.
pub(crate) trait Counter {
    /// Whether the count is of the parallel subfields' walk: a query that counts is
    /// answered by the walk, never by the box tree (`Psf::static_pre`).
    const WALK: bool;
    fn tile(&mut self);
    fn candidate(&mut self);
    fn scanned(&mut self, n: usize);
    fn blocks(&mut self, n: usize);
}

pub(crate) struct NoCount;

impl Counter for NoCount {
    const WALK: bool = false;
    #[inline(always)]
    fn tile(&mut self) {}
    #[inline(always)]
    fn candidate(&mut self) {}
    #[inline(always)]
    fn scanned(&mut self, _: usize) {}
    #[inline(always)]
    fn blocks(&mut self, _: usize) {}
}

impl Counter for RayStats {
    const WALK: bool = true;
    #[inline(always)]
    fn tile(&mut self) {
        self.tiles_visited += 1;
    }
    #[inline(always)]
    fn candidate(&mut self) {
        self.candidates_tested += 1;
    }
    #[inline(always)]
    fn scanned(&mut self, n: usize) {
        self.entries_scanned += n as u64;
    }
    #[inline(always)]
    fn blocks(&mut self, n: usize) {
        self.blocks_scanned += n as u64;
    }
}

/// Counts in power-of-two buckets: bucket 0 holds the value 0, bucket `k >= 1` holds
/// values in `[2^(k-1), 2^k)`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Histogram {
    pub buckets: Vec<u64>,
}

impl Histogram {
    pub fn add(&mut self, value: u64) {
        let k = if value == 0 {
            0
        } else {
            64 - value.leading_zeros() as usize
        };
        if self.buckets.len() <= k {
            self.buckets.resize(k + 1, 0);
        }
        self.buckets[k] += 1;
    }

    /// `(low, high_exclusive, count)` per bucket.
    pub fn rows(&self) -> impl Iterator<Item = (u64, u64, u64)> + '_ {
        self.buckets.iter().enumerate().map(|(k, &c)| match k {
            0 => (0, 1, c),
            _ => (1u64 << (k - 1), 1u64 << k, c),
        })
    }
}

/// Occupancy of a PSF: triangles listed per tile (an entry counts once per tile, however
/// many BSP slabs list it).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PsfStats {
    pub triangles: usize,
    pub subfields: usize,
    pub tiles: usize,
    pub empty_tiles: usize,
    /// Tiles stored as blocks of eight entries instead of a BSP.
    pub flat_tiles: usize,
    /// Entries over all slabs (with the BSP's duplicates).
    pub slab_entries: usize,
    pub entries_per_tile_mean: f64,
    pub entries_per_tile_max: u64,
    pub entries_per_tile: Histogram,
    /// Bytes of triangles, tile headers, slab offsets, entries and blocks.
    pub bytes: usize,
}

impl Psf {
    pub fn stats(&self) -> PsfStats {
        let mut s = PsfStats {
            triangles: self.triangles().len(),
            subfields: self.subfields().len(),
            ..Default::default()
        };
        s.bytes = std::mem::size_of_val(self.triangles());
        let mut total = 0u64;
        for sf in self.subfields() {
            s.bytes += std::mem::size_of_val(&*sf.tiles)
                + std::mem::size_of_val(&*sf.slab_starts)
                + std::mem::size_of_val(&*sf.entries)
                + std::mem::size_of_val(&*sf.blocks);
            s.slab_entries += sf.entries.len();
            for h in sf.tiles.iter() {
                s.tiles += 1;
                s.flat_tiles += h.is_flat() as usize;
                let n = if h.is_flat() {
                    sf.blocks[h.blocks()].iter().flat_map(|b| b.used()).count() as u64
                } else if h.slab_count == 0 {
                    0
                } else {
                    let st = &sf.slab_starts
                        [h.first_slab as usize..=(h.first_slab + h.slab_count) as usize];
                    let mut tris: Vec<u32> = sf.entries[st[0] as usize..st[st.len() - 1] as usize]
                        .iter()
                        .map(|e| e.tri)
                        .collect();
                    tris.sort_unstable();
                    tris.dedup();
                    tris.len() as u64
                };
                if n == 0 {
                    s.empty_tiles += 1;
                }
                total += n;
                s.entries_per_tile_max = s.entries_per_tile_max.max(n);
                s.entries_per_tile.add(n);
            }
        }
        s.entries_per_tile_mean = total as f64 / s.tiles.max(1) as f64;
        s
    }
}
