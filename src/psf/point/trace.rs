//! The batch driver: each ray through the first plan that takes it, the rest gathered,
//! traced together by the fallback and scattered back.

use rayon::prelude::*;

use super::plan::Plan;
use super::types::{Sources, CHUNK};
use crate::geometry::{Hit, Ray};

/// `out[i] = query(rays[i])` through point grids where the batch takes any
/// ([`Plan::for_batch`]), `wrap` turning a grid's answer into `T`; the rays no grid takes
/// (all of them, when the batch takes no grid) are answered together by `fallback`.
pub(crate) fn trace_batch<const ANY: bool, T: Send + Sync + Copy + Default>(
    rays: &[Ray],
    out: &mut [T],
    src: &Sources,
    wrap: impl Fn(Option<Hit>) -> T + Sync,
    fallback: impl Fn(&[Ray], &mut [T]),
) {
    assert_eq!(rays.len(), out.len(), "one output slot per ray");
    let plans = Plan::for_batch(rays, src);
    if plans.is_empty() {
        return fallback(rays, out);
    }
    // Each ray through a grid that takes it; per chunk, the others' places.
    let missed: Vec<Vec<u32>> = rays
        .par_chunks(CHUNK)
        .zip(out.par_chunks_mut(CHUNK))
        .map(|(rays, out)| {
            let mut miss = Vec::new();
            // Neighbouring rays mostly take the same grid (a mirror plane's reflections
            // lie together in the image): the one that took the last ray is tried
            // first, which saved a reflection batch a qualification or two a ray
            // (`benches/PERF.md`, step 85). Any grid that takes a ray gives it the same
            // hit.
            let mut last = 0;
            for (i, (ray, o)) in rays.iter().zip(out).enumerate() {
                let hit = plans[last].query::<ANY>(ray).or_else(|| {
                    plans.iter().enumerate().find_map(|(k, p)| {
                        let h = if k == last { None } else { p.query::<ANY>(ray) };
                        h.inspect(|_| last = k)
                    })
                });
                match hit {
                    Some(hit) => *o = wrap(hit),
                    None => miss.push(i as u32),
                }
            }
            miss
        })
        .collect();
    let total: usize = missed.iter().map(Vec::len).sum();
    if total == 0 {
        return;
    }
    // The rest traced as one batch (binned by subfield, in parallel), the answers put
    // back chunk by chunk.
    // In parallel, chunk by chunk into its own part (a serial gather of the 100,000 or
    // so reflections that take the parallel subfields cost 1–2 ms a frame).
    let mut gathered: Vec<Ray> = (0..total).into_par_iter().map(|_| rays[0]).collect();
    let mut into = Vec::with_capacity(missed.len());
    let mut rest = &mut gathered[..];
    for m in &missed {
        let (head, tail) = rest.split_at_mut(m.len());
        into.push(head);
        rest = tail;
    }
    into.into_par_iter()
        .zip(missed.par_iter().zip(rays.par_chunks(CHUNK)))
        .for_each(|(out, (m, rays))| {
            for (o, &i) in out.iter_mut().zip(m) {
                *o = rays[i as usize];
            }
        });
    let mut answers: Vec<T> = (0..total).into_par_iter().map(|_| T::default()).collect();
    fallback(&gathered, &mut answers);
    let mut parts = Vec::with_capacity(missed.len());
    let mut rest = &answers[..];
    for m in &missed {
        let (head, tail) = rest.split_at(m.len());
        parts.push(head);
        rest = tail;
    }
    out.par_chunks_mut(CHUNK)
        .zip(missed.par_iter().zip(parts))
        .for_each(|(out, (m, a))| {
            for (&i, &x) in m.iter().zip(a) {
                out[i as usize] = x;
            }
        });
}

/// Which of `rays`, traced as one batch, the point grids take: `Plan::for_batch` over
/// `src`, then a ray is taken when some plan answers it (as in [`trace_batch`], which
/// tries every plan before the fallback). The rest are those `trace_batch` hands to the
/// parallel subfields. The grids' answers are found and dropped (a point grid's query
/// is what decides whether it takes a ray), and planning keeps or marks grids in
/// `src`'s cache as a render's batch would.
pub(crate) fn taken<const ANY: bool>(rays: &[Ray], src: &Sources) -> Vec<bool> {
    let plans = Plan::for_batch(rays, src);
    if plans.is_empty() {
        return vec![false; rays.len()];
    }
    rays.par_iter()
        .map(|ray| plans.iter().any(|p| p.query::<ANY>(ray).is_some()))
        .collect()
}

impl crate::psf::Psf {
    /// Which of `rays`, traced as one batch (closest hit, or any hit when `any`), this
    /// PSF's batch queries ([`Intersector::intersect_batch`],
    /// [`Intersector::occluded_batch`]) send through point grids rather than the
    /// parallel subfields ([`taken`]).
    ///
    /// [`Intersector::intersect_batch`]: crate::geometry::Intersector::intersect_batch
    /// [`Intersector::occluded_batch`]: crate::geometry::Intersector::occluded_batch
    pub(crate) fn point_grids_take(&self, rays: &[Ray], any: bool) -> Vec<bool> {
        let src = self.point_sources();
        if any {
            taken::<true>(rays, &src)
        } else {
            taken::<false>(rays, &src)
        }
    }
}
