//! The static PSF and a dynamic layer queried together ([`Layered`]).

use rayon::prelude::*;

use super::DynamicLayer;
use crate::geometry::{closest_of, Aabb, Hit, Intersector, Layers, Ray, RayPre};
use crate::psf::batch::binned;
use crate::psf::point::{trace_batch, trace_lists, Plan, Sources, POINT_CHUNK};
use crate::psf::stats::{Counter, NoCount, RayStats};
use crate::psf::Psf;

/// The static PSF and a dynamic layer queried together.
#[derive(Clone, Debug)]
pub struct Layered<'a> {
    psf: &'a Psf,
    dynamic: &'a DynamicLayer,
    /// Per static subfield, the dynamic subfield of the closest direction: a batch,
    /// which knows each ray's static subfield, walks that dynamic grid without a second
    /// direction lookup (a doubled lookup had cost 4.7% of the trace, `benches/PERF.md`
    /// step 51).
    dyn_of: Vec<u8>,
}

/// Which triangle a [`Layered`] hit names: its [`Hit::tri`] numbers the static PSF's
/// triangles first, then the dynamic layer's (`static count + i`); this tells the two
/// apart ([`Layered::prim`], [`Prim::from_index`]).
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Prim {
    /// Static triangle `i`: `psf.triangles()[i]`.
    Static(u32),
    /// Moving triangle `i`: the `i`-th of the last [`DynamicLayer::update`]'s input.
    Moving(u32),
}

impl Prim {
    /// What hit number `tri` names over `statics` static triangles.
    #[inline]
    pub fn from_index(tri: u32, statics: usize) -> Prim {
        if (tri as usize) < statics {
            Prim::Static(tri)
        } else {
            Prim::Moving(tri - statics as u32)
        }
    }
}

impl Psf {
    /// Queries over this PSF and `dynamic` together; dynamic triangle `i` is reported
    /// as `self.triangles().len() + i` ([`Layered::prim`] tells which is which).
    pub fn with_dynamic<'a>(&'a self, dynamic: &'a DynamicLayer) -> Layered<'a> {
        // At most 7 dynamic subfields at level 1, 469 at level 4: a u16 would do for any
        // level, a u8 holds the levels up to 3 (109); level 4 falls back to the lookup.
        let dyn_of = if dynamic.subfields.len() <= u8::MAX as usize + 1 {
            let dirs = self.subfields.iter().map(|s| s.frame.d);
            dirs.map(|d| dynamic.table.lookup(d) as u8).collect()
        } else {
            Vec::new()
        };
        Layered {
            psf: self,
            dynamic,
            dyn_of,
        }
    }
}

impl Layered<'_> {
    /// Whether `hit` (one of this query's) names a static or a moving triangle, and
    /// which.
    #[inline]
    pub fn prim(&self, hit: &Hit) -> Prim {
        Prim::from_index(hit.tri, self.psf.triangles().len())
    }

    /// `sub`: the static subfield, when a batch knows it already.
    fn trace<const ANY: bool, C: Counter>(
        &self,
        ray: &Ray,
        sub: Option<usize>,
        count: &mut C,
    ) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        // One shear for both layers: the dynamic walk's ray differs in `t_max` alone.
        let pre = RayPre::new(ray.origin, ray.dir);
        let s = self.psf.static_pre::<ANY, C>(ray, &pre, sub, count);
        if ANY && s.is_some() {
            return s;
        }
        // The dynamic walk stops at the static hit: a dynamic triangle at the same t
        // loses the tie anyway (its number is larger).
        let mut r = *ray;
        if let Some(h) = &s {
            r.t_max = h.t;
        }
        let d = self.moving_pre::<ANY, C>(&r, &pre, sub, count);
        closest_of(s, d)
    }

    /// The moving triangles' hit of a valid ray with its shear `pre` (numbered after
    /// the static ones); `sub`: the static subfield when a batch knows it.
    #[inline]
    fn moving_pre<const ANY: bool, C: Counter>(
        &self,
        ray: &Ray,
        pre: &RayPre,
        sub: Option<usize>,
        count: &mut C,
    ) -> Option<Hit> {
        let dyn_sub = sub.and_then(|k| self.dyn_of.get(k)).map(|&k| k as usize);
        let offset = self.psf.triangles().len() as u32;
        self.dynamic
            .trace_pre::<ANY, C>(ray, pre, dyn_sub, count)
            .map(|mut h| {
                h.tri += offset;
                h
            })
    }

    /// The moving triangles alone (numbered after the static ones), `sub`: the static
    /// subfield when a batch knows it.
    fn trace_moving<const ANY: bool>(&self, ray: &Ray, sub: Option<usize>) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let pre = RayPre::new(ray.origin, ray.dir);
        self.moving_pre::<ANY, _>(ray, &pre, sub, &mut NoCount)
    }

    /// A batch through the moving triangles alone: point grids over them where the
    /// batch pays for one (the grids the layered batch would build over them, with the
    /// same margin and bounds, but no static grid beside), the rest binned.
    fn moving_batch_of<const ANY: bool, T: Send + Sync + Copy + Default>(
        &self,
        rays: &[Ray],
        out: &mut [T],
        wrap: impl Fn(Option<Hit>) -> T + Sync,
    ) {
        let d = self.dynamic;
        if d.is_empty() {
            out.fill(wrap(None));
            return;
        }
        // Rays that miss the moving triangles' bounds (grown by their rounding
        // allowance, as the layer's own walk clips them) meet none of them: only the
        // others are traced, which in a clustered frame is a few of them (most miss by
        // far, and the clip's f32 check passes over them).
        let near: Vec<u32> = rays
            .par_iter()
            .enumerate()
            .with_min_len(1024)
            .filter(|(_, r)| !d.clip.misses(r))
            .map(|(i, _)| i as u32)
            .collect();
        if near.len() < rays.len() {
            out.par_iter_mut().for_each(|o| *o = wrap(None));
            if near.is_empty() {
                return;
            }
            let some: Vec<Ray> = near.par_iter().map(|&i| rays[i as usize]).collect();
            let mut answers = vec![wrap(None); some.len()];
            self.moving_traced::<ANY, T>(&some, &mut answers, wrap);
            for (&i, a) in near.iter().zip(answers) {
                out[i as usize] = a;
            }
            return;
        }
        self.moving_traced::<ANY, T>(rays, out, wrap);
    }

    /// [`moving_batch_of`](Self::moving_batch_of) for rays that may meet the moving
    /// triangles' bounds.
    fn moving_traced<const ANY: bool, T: Send + Sync + Copy + Default>(
        &self,
        rays: &[Ray],
        out: &mut [T],
        wrap: impl Fn(Option<Hit>) -> T + Sync,
    ) {
        let d = self.dynamic;
        let offset = self.psf.triangles().len() as u32;
        let number: Vec<u32> = d.order.iter().map(|&k| k + offset).collect();
        let all = self.sources();
        let src = Sources {
            statics: &[],
            moving_number: &number,
            cache: &d.moving_points,
            within: true,
            frame: None,
            ..all
        };
        let walk = |rays: &[Ray], out: &mut [T]| {
            self.binned(rays, out, |r, k| wrap(self.trace_moving::<ANY>(r, Some(k))))
        };
        trace_batch::<ANY, _>(rays, out, &src, &wrap, walk);
    }

    /// `out[i] = f(&rays[i], subfield)`, the rays binned by the static PSF's subfield
    /// (`psf::batch`).
    fn binned<T: Send + Copy>(
        &self,
        rays: &[Ray],
        out: &mut [T],
        f: impl Fn(&Ray, usize) -> T + Sync,
    ) {
        let bins = self.psf.subfields().len().max(1);
        binned(rays, out, bins, |r| self.psf.bin_of(r), f);
    }

    /// The batch of `lists` (their concatenation `whole`, where the caller has it)
    /// through point grids where they pay, the rest binned by the static PSF's subfield
    /// (`psf::batch`), `wrap` making each answer.
    fn traced<const ANY: bool, T: Send + Sync + Copy + Default>(
        &self,
        lists: &[&[Ray]],
        whole: Option<&[Ray]>,
        out: &mut [T],
        wrap: impl Fn(Option<Hit>) -> T + Sync,
    ) {
        let walk = |rays: &[Ray], out: &mut [T]| {
            self.binned(rays, out, |r, k| {
                wrap(self.trace::<ANY, _>(r, Some(k), &mut NoCount))
            })
        };
        trace_lists::<ANY, _>(lists, whole, out, &self.sources(), &wrap, walk);
    }

    /// Whether [`intersect_batch`](Intersector::intersect_batch) and
    /// [`occluded_batch`](Intersector::occluded_batch) trace some of `rays` through point
    /// grids (grids by central projection around a point rays pass through): when a share
    /// of a sample passes one point (a camera's rays, a light's shadow rays, reflections
    /// off one plane) and those rays are enough to pay for what must be built (for camera
    /// and shadow rays at least a twelfth as many as triangles times the cube faces they
    /// use, for rays that merely pass the point six times that; only the moving triangles
    /// count once the static PSF keeps a grid around the point, which it does for a
    /// point seen in an earlier batch). Either way the hits are the same. It builds the
    /// grids to find out, and keeps and remembers what a batch would.
    pub fn point_grid_for(&self, rays: &[Ray]) -> bool {
        !Plan::for_batch(rays, &self.sources()).is_empty()
    }

    /// Both layers' triangles, for a point grid.
    fn sources(&self) -> Sources<'_> {
        let d = self.dynamic;
        Sources {
            statics: self.psf.triangles(),
            moving_pre: &d.local,
            moving_number: &d.order,
            margin: self
                .psf
                .margin()
                .max(if d.is_empty() { 0.0 } else { d.margin }),
            bounds: if d.is_empty() {
                *self.psf.bounds()
            } else {
                self.psf.bounds().union(&d.clip.aabb())
            },
            cache: self.psf.point_cache(),
            within: false,
            frame: Some(&d.frame_grids),
        }
    }

    /// The closest hit, also counting the work done (both layers) into `stats`.
    pub fn intersect_counted(&self, ray: &Ray, stats: &mut RayStats) -> Option<Hit> {
        stats.rays += 1;
        self.trace::<false, _>(ray, None, stats)
    }

    /// Any hit, also counting the work done into `stats`.
    pub fn occluded_counted(&self, ray: &Ray, stats: &mut RayStats) -> bool {
        stats.rays += 1;
        self.trace::<true, _>(ray, None, stats).is_some()
    }
}

impl Intersector for Layered<'_> {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.trace::<false, _>(ray, None, &mut NoCount)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.trace::<true, _>(ray, None, &mut NoCount).is_some()
    }

    /// Through point grids for the rays that pass a point grids pay for (a camera's
    /// primary rays, shadow rays towards a point light, reflections off a plane;
    /// [`Layered::point_grid_for`]); the others binned by the static PSF's subfield
    /// (`psf::batch`).
    fn intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        let chunks: Vec<&[Ray]> = rays.chunks(POINT_CHUNK).collect();
        self.traced::<false, _>(&chunks, Some(rays), out, |h| h);
    }

    fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        let chunks: Vec<&[Ray]> = rays.chunks(POINT_CHUNK).collect();
        self.traced::<true, _>(&chunks, Some(rays), out, |h| h.is_some());
    }

    /// As `intersect_batch`, the lists traced in place (`psf::point::trace_lists`).
    fn intersect_lists(&self, lists: &[&[Ray]], out: &mut [Option<Hit>]) {
        self.traced::<false, _>(lists, None, out, |h| h);
    }

    fn occluded_lists(&self, lists: &[&[Ray]], out: &mut [bool]) {
        self.traced::<true, _>(lists, None, out, |h| h.is_some());
    }

    fn layers(&self) -> Option<&dyn Layers> {
        Some(self)
    }
}

impl Layers for Layered<'_> {
    fn static_count(&self) -> usize {
        self.psf.triangles().len()
    }

    fn static_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        self.psf.intersect_batch(rays, out);
    }

    fn static_occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        self.psf.occluded_batch(rays, out);
    }

    fn moving_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        self.moving_batch_of::<false, _>(rays, out, |h| h);
    }

    fn moving_occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        self.moving_batch_of::<true, _>(rays, out, |h| h.is_some());
    }

    /// The layer's clip box: `moving_batch_of` answers `None` for a ray whose clipped
    /// span is empty, and an empty layer answers `None` for every ray.
    fn moving_bounds(&self) -> Option<Aabb> {
        Some(if self.dynamic.is_empty() {
            Aabb::EMPTY
        } else {
            self.dynamic.clip.aabb()
        })
    }
}
