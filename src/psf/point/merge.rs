//! The merge of a kept static grid with a batch's moving grid on the same tiling into
//! one grid, tile by tile, near to far.

use rayon::prelude::*;

use super::types::{by_tiles, PEntry, PointGrid};

impl PointGrid {
    /// `a`'s lists and `b`'s (on the same tiling, `b`'s triangles numbered from
    /// `offset` on) merged tile by tile, near to far, `a`'s entry first where depths
    /// tie: the grid over both sets of triangles, so a ray scans one list.
    pub(super) fn merged(a: &PointGrid, b: &PointGrid, offset: u32) -> PointGrid {
        assert_eq!(
            a.starts.len(),
            b.starts.len(),
            "merged grids share their tiling"
        );
        let total = a.starts.len() - 1;
        let starts: Vec<u32> = a.starts.iter().zip(&b.starts).map(|(x, y)| x + y).collect();
        let mut entries = vec![PEntry::default(); starts[total] as usize];
        // Tiles in ranges, one job a range, each writing its own part of `entries`.
        let jobs = (4 * rayon::current_num_threads()).clamp(1, total.max(1));
        let parts = by_tiles(&starts, &mut entries, jobs);
        let moved = |e: &PEntry| PEntry {
            tri: e.tri + offset,
            ..*e
        };
        parts.into_par_iter().for_each(|(lo, hi, out)| {
            let mut k = 0;
            for t in lo..hi {
                let (ra, rb) = (a.run(t), b.run(t));
                let (mut i, mut j) = (0, 0);
                while i < ra.len() && j < rb.len() {
                    if ra[i].zmin.to_bits() <= rb[j].zmin.to_bits() {
                        out[k] = ra[i];
                        i += 1;
                    } else {
                        out[k] = moved(&rb[j]);
                        j += 1;
                    }
                    k += 1;
                }
                for e in &ra[i..] {
                    out[k] = *e;
                    k += 1;
                }
                for e in &rb[j..] {
                    out[k] = moved(e);
                    k += 1;
                }
            }
        });
        let near = a.near.iter().copied();
        PointGrid {
            faces: a.faces,
            starts,
            entries,
            near: near.chain(b.near.iter().map(|&g| g + offset)).collect(),
        }
    }
}
