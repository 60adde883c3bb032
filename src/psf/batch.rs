//! Batches of rays traced binned by subfield: rays are put in order of the subfield
//! their direction picks (a stable counting sort, so neighbouring pixels stay together
//! within a bin), traced in parallel in that order, and the results put back in the
//! order of the rays. Rays of one subfield then walk one grid and one set of tile lists
//! one after the other, instead of every ray of an incoherent batch (reflections,
//! shadows towards several lights) touching a different subfield's data.

use rayon::prelude::*;

use crate::geometry::Ray;

/// `out[i] = f(&rays[i])` for every ray, traced in order of `key(&rays[i])` (below
/// `bins`).
pub(crate) fn binned<T: Send + Copy>(
    rays: &[Ray],
    out: &mut [T],
    bins: usize,
    key: impl Fn(&Ray) -> usize + Sync,
    f: impl Fn(&Ray) -> T + Sync,
) {
    assert_eq!(rays.len(), out.len(), "one output slot per ray");
    let keys: Vec<u32> = rays.par_iter().map(|r| key(r) as u32).collect();
    let mut start = vec![0u32; bins + 1];
    for &k in &keys {
        start[k as usize + 1] += 1;
    }
    for b in 0..bins {
        start[b + 1] += start[b];
    }
    let mut order = vec![0u32; rays.len()];
    for (i, &k) in keys.iter().enumerate() {
        let s = &mut start[k as usize];
        order[*s as usize] = i as u32;
        *s += 1;
    }
    let results: Vec<T> = order
        .par_iter()
        .with_min_len(64)
        .map(|&i| f(&rays[i as usize]))
        .collect();
    for (&i, r) in order.iter().zip(results) {
        out[i as usize] = r;
    }
}
