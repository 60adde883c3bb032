//! The batch driver: each ray through the first plan that takes it, the rest gathered,
//! traced together by the fallback and scattered back.

use rayon::prelude::*;

use super::plan::Plan;
use super::types::{Sources, CHUNK};
use crate::geometry::{Hit, Ray};

/// A batch's rays as the plans sample them: one slice, or several traced as one
/// ([`Lists`]), numbered in order.
pub(crate) trait RayBatch: Sync {
    /// How many rays.
    fn len(&self) -> usize;
    /// Ray `i` (`i < len()`).
    fn ray(&self, i: usize) -> &Ray;
    /// Rays `from`, `from + step`, ... below `to` (`to <= len()`, `step > 0`), copied
    /// into `into`.
    fn stepped(&self, from: usize, to: usize, step: usize, into: &mut Vec<Ray>);
}

impl RayBatch for [Ray] {
    #[inline]
    fn len(&self) -> usize {
        <[Ray]>::len(self)
    }

    #[inline]
    fn ray(&self, i: usize) -> &Ray {
        &self[i]
    }

    fn stepped(&self, from: usize, to: usize, step: usize, into: &mut Vec<Ray>) {
        into.extend(self[from..to].iter().step_by(step).copied());
    }
}

/// Lists of rays traced as one batch: the rays of the first list, then the second's,
/// and so on (a renderer's rays as its tasks made them, not copied into one).
pub(crate) struct Lists<'a> {
    lists: &'a [&'a [Ray]],
    /// Where each list starts in the batch's numbering, and the total after them.
    start: Vec<usize>,
}

impl<'a> Lists<'a> {
    pub(crate) fn new(lists: &'a [&'a [Ray]]) -> Lists<'a> {
        let mut start = Vec::with_capacity(lists.len() + 1);
        let mut n = 0;
        start.push(0);
        for l in lists {
            n += l.len();
            start.push(n);
        }
        Lists { lists, start }
    }
}

impl RayBatch for Lists<'_> {
    fn len(&self) -> usize {
        self.start.last().copied().unwrap_or(0)
    }

    fn ray(&self, i: usize) -> &Ray {
        let k = self.list_of(i);
        &self.lists[k][i - self.start[k]]
    }

    /// The list found once, then followed (a search a ray cost a batch's sampling
    /// 1–2 ms a frame).
    fn stepped(&self, from: usize, to: usize, step: usize, into: &mut Vec<Ray>) {
        if from >= to {
            return;
        }
        let mut k = self.list_of(from);
        let mut i = from;
        while i < to {
            while self.start[k + 1] <= i {
                k += 1;
            }
            into.push(self.lists[k][i - self.start[k]]);
            i += step;
        }
    }
}

impl Lists<'_> {
    /// The list whose span holds ray `i` (`i < len()`): the last to start at or
    /// before it (an empty list starts where the next one does, and is passed over).
    fn list_of(&self, i: usize) -> usize {
        self.start.partition_point(|&s| s <= i) - 1
    }
}

/// `out` cut into one part per list, each as long as its list.
fn cut<'o, T>(mut out: &'o mut [T], lists: &[&[Ray]]) -> Vec<&'o mut [T]> {
    let mut parts = Vec::with_capacity(lists.len());
    for l in lists {
        let (head, tail) = std::mem::take(&mut out).split_at_mut(l.len());
        parts.push(head);
        out = tail;
    }
    parts
}

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
    let chunks: Vec<&[Ray]> = rays.chunks(CHUNK).collect();
    trace_lists::<ANY, T>(&chunks, Some(rays), out, src, wrap, fallback);
}

/// [`trace_batch`] of the rays of `lists` in turn, `out` holding a slot per ray of
/// every list in that order, without copying the lists into one batch: each list is
/// one task's rays (as each `CHUNK` of one batch is), and only the rays no grid takes
/// are gathered for `fallback`. The answers are those of `trace_batch` of the
/// concatenation. `whole` is that concatenation where the caller has it: a batch that
/// no grid takes then goes to `fallback` without a copy.
pub(crate) fn trace_lists<const ANY: bool, T: Send + Sync + Copy + Default>(
    lists: &[&[Ray]],
    whole: Option<&[Ray]>,
    out: &mut [T],
    src: &Sources,
    wrap: impl Fn(Option<Hit>) -> T + Sync,
    fallback: impl Fn(&[Ray], &mut [T]),
) {
    let batch = Lists::new(lists);
    assert_eq!(batch.len(), out.len(), "one output slot per ray");
    // The plans sample the same rays either way; from one slice without the search.
    let plans = match whole {
        Some(rays) => Plan::for_batch(rays, src),
        None => Plan::for_batch(&batch, src),
    };
    if plans.is_empty() {
        return match (whole, lists) {
            (Some(rays), _) | (None, &[rays]) => fallback(rays, out),
            _ => fallback(&lists.concat(), out),
        };
    }
    // Each ray through a grid that takes it; per list, the others' places.
    let missed: Vec<Vec<u32>> = lists
        .par_iter()
        .zip(cut(&mut *out, lists))
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
    // back list by list.
    // In parallel, list by list into its own part (a serial gather of the 100,000 or
    // so reflections that take the parallel subfields cost 1–2 ms a frame).
    let Some(any) = lists.iter().find_map(|l| l.first()) else {
        return;
    };
    let mut gathered: Vec<Ray> = (0..total).into_par_iter().map(|_| *any).collect();
    let mut into = Vec::with_capacity(missed.len());
    let mut rest = &mut gathered[..];
    for m in &missed {
        let (head, tail) = rest.split_at_mut(m.len());
        into.push(head);
        rest = tail;
    }
    into.into_par_iter()
        .zip(missed.par_iter().zip(lists.par_iter()))
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
    cut(out, lists)
        .into_par_iter()
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
