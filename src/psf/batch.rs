//! Batches of rays traced binned by subfield. The batch is cut into runs of `RUN`
//! consecutive rays (shorter for a small batch, so every thread gets some), traced in
//! parallel; within a run, rays are put in order of the
//! subfield their direction picks (a stable counting sort, so neighbouring pixels stay
//! together within a bin), traced in that order, and each result written straight to
//! the ray's slot. Rays of one subfield then walk one grid and one set of tile lists one
//! after the other, instead of every ray of an incoherent run (reflections, shadows
//! towards several lights) touching a different subfield's data. Sorting runs instead of
//! the whole batch keeps every step parallel: the whole-batch sort and the scatter of its
//! results back into ray order were serial and took about a tenth of a batch on two
//! threads (`benches/PERF.md`, step 49).

use rayon::prelude::*;

use crate::geometry::Ray;

/// Rays sorted and traced together: enough that a run's rays of one subfield share its
/// data, few enough that two threads share a batch evenly.
const RUN: usize = 4096;

/// The shortest run a small batch is cut into, so that it still spreads over the
/// threads: a still camera's mirror rays that a moving cloud may meet are ~1,700 a
/// frame, each testing many of its triangles (10 ms a frame), and were one run on one
/// thread whatever the thread count (`benches/PERF.md`, issue 38).
const MIN_RUN: usize = 128;

/// The run length for `n` rays: [`RUN`], or shorter so that every thread gets about
/// eight runs, not below [`MIN_RUN`]. Each ray's answer does not depend on its run.
fn run_for(n: usize) -> usize {
    n.div_ceil(8 * rayon::current_num_threads().max(1))
        .clamp(MIN_RUN, RUN)
}

/// `out[i] = f(&rays[i], key(&rays[i]))` for every ray, each run of [`RUN`] rays traced
/// in order of the key (below `bins`).
pub(crate) fn binned<T: Send + Copy>(
    rays: &[Ray],
    out: &mut [T],
    bins: usize,
    key: impl Fn(&Ray) -> usize + Sync,
    f: impl Fn(&Ray, usize) -> T + Sync,
) {
    assert_eq!(rays.len(), out.len(), "one output slot per ray");
    let run = run_for(rays.len());
    rays.par_chunks(run)
        .zip(out.par_chunks_mut(run))
        .for_each(|(rays, out)| {
            let mut keys = [0u16; RUN];
            let mut start = vec![0u32; bins + 1];
            for (k, r) in keys.iter_mut().zip(rays) {
                // Bins are subfields: at most 469 (level 4), so a u16 holds them.
                let b = key(r);
                debug_assert!(b < bins && b <= u16::MAX as usize);
                *k = b as u16;
                start[*k as usize + 1] += 1;
            }
            for b in 0..bins {
                start[b + 1] += start[b];
            }
            let mut order = [0u16; RUN];
            for (i, &k) in keys[..rays.len()].iter().enumerate() {
                let s = &mut start[k as usize];
                order[*s as usize] = i as u16;
                *s += 1;
            }
            for &i in &order[..rays.len()] {
                out[i as usize] = f(&rays[i as usize], keys[i as usize] as usize);
            }
        });
}
