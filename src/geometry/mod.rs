//! Rays, boxes and the watertight triangle test: the vocabulary every later stage shares.

mod aabb;
mod brute;
mod triangle;

pub use aabb::Aabb;
pub use brute::BruteForce;
pub use triangle::{
    intersect_pre, intersect_pre4, intersect_triangle, is_degenerate, RayPre, Shear, TriPre,
};

use glam::Vec3;
use rayon::prelude::*;

/// A ray `origin + t * dir` over `t` in `[t_min, t_max]`. `dir` need not be unit length:
/// `t` is measured in multiples of `dir`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub t_min: f32,
    pub t_max: f32,
}

impl Ray {
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Ray {
            origin,
            dir,
            t_min: 0.0,
            t_max: f32::INFINITY,
        }
    }

    pub fn segment(origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Self {
        Ray {
            origin,
            dir,
            t_min,
            t_max,
        }
    }

    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }

    /// The bits of its numbers, for an exact comparison (`-0.0` is not `0.0` here, and a
    /// NaN is itself).
    #[inline]
    pub fn bits(&self) -> [u32; 8] {
        [
            self.origin.x.to_bits(),
            self.origin.y.to_bits(),
            self.origin.z.to_bits(),
            self.dir.x.to_bits(),
            self.dir.y.to_bits(),
            self.dir.z.to_bits(),
            self.t_min.to_bits(),
            self.t_max.to_bits(),
        ]
    }

    /// Whether `other` is this ray to the bit ([`Ray::bits`]), without a call to
    /// `memcmp` (a still camera compares two rays a pixel and level every frame).
    #[inline]
    pub fn same_bits(&self, other: &Ray) -> bool {
        same_words(&self.bits(), &other.bits())
    }

    /// A ray is traceable when its numbers are finite and its direction is not zero.
    /// Queries on other rays return no hit.
    pub fn is_valid(&self) -> bool {
        self.origin.is_finite()
            && self.dir.is_finite()
            && self.dir != Vec3::ZERO
            && !self.t_min.is_nan()
            && !self.t_max.is_nan()
    }
}

/// Whether two arrays of words are equal, by folding their differences (inlined and
/// branch-free, where `==` on arrays of this size calls `memcmp`).
#[inline]
pub(crate) fn same_words<const N: usize>(a: &[u32; N], b: &[u32; N]) -> bool {
    a.iter().zip(b).fold(0, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// A ray-triangle hit: parameter `t` along the ray, the triangle's index, and the
/// barycentric weights `u` of vertex 1 and `v` of vertex 2 (vertex 0 has `1 - u - v`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub tri: u32,
    pub u: f32,
    pub v: f32,
}

impl Hit {
    /// The bits of its numbers, for an exact comparison.
    #[inline]
    pub fn bits(&self) -> [u32; 4] {
        [
            self.t.to_bits(),
            self.tri,
            self.u.to_bits(),
            self.v.to_bits(),
        ]
    }

    /// The tie rule every intersector in this crate follows: the smaller `t` wins; at an
    /// exactly equal `t` the smaller triangle index wins. It makes "the closest hit" a
    /// function of the scene and the ray alone, so different structures can be compared
    /// hit for hit.
    #[inline]
    pub fn is_closer_than(&self, other: &Hit) -> bool {
        self.t < other.t || (self.t == other.t && self.tri < other.tri)
    }
}

/// Closest-hit and any-hit queries over a set of triangles: the tracer seam. The
/// renderer is generic over it; the CPU's `psf::Layered` and the GPU's `gpu::GpuTracer`
/// implement it, with the same hits to the bit (docs/GPU.md). Batch calls trace in
/// parallel with rayon; results come back in the order of the rays. Called from outside
/// rayon's pool, a batch parks the calling thread until the pool's workers (which may
/// have to wake first) are done: a program tracing batch after batch runs them from a
/// pool thread (inside `rayon::scope`), as the renderer does.
pub trait Intersector: Sync {
    /// The closest hit in `[t_min, t_max]` under the tie rule of [`Hit::is_closer_than`].
    fn intersect(&self, ray: &Ray) -> Option<Hit>;

    /// Whether anything is hit in `[t_min, t_max]` (shadow rays).
    fn occluded(&self, ray: &Ray) -> bool;

    fn intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one output slot per ray");
        rays.par_iter()
            .zip(out.par_iter_mut())
            .with_min_len(64)
            .for_each(|(r, o)| *o = self.intersect(r));
    }

    fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one output slot per ray");
        rays.par_iter()
            .zip(out.par_iter_mut())
            .with_min_len(64)
            .for_each(|(r, o)| *o = self.occluded(r));
    }

    /// The rays of `lists` one list after another, traced as one batch: the answers of
    /// [`intersect_batch`](Self::intersect_batch) of their concatenation, `out` holding
    /// a slot per ray of every list in that order. A renderer hands its tasks' lists
    /// over this way instead of copying them into one; the default copies them.
    fn intersect_lists(&self, lists: &[&[Ray]], out: &mut [Option<Hit>]) {
        self.intersect_batch(&lists.concat(), out);
    }

    /// [`occluded_batch`](Self::occluded_batch) of the concatenation of `lists`, as
    /// [`intersect_lists`](Self::intersect_lists) is of `intersect_batch`.
    fn occluded_lists(&self, lists: &[&[Ray]], out: &mut [bool]) {
        self.occluded_batch(&lists.concat(), out);
    }

    /// The structure's static and moving triangles traced apart ([`Layers`]), where it
    /// has the two; `None` (the default) where it is one set.
    fn layers(&self) -> Option<&dyn Layers> {
        None
    }
}

/// A set of triangles made of a static part, which stays from frame to frame, and a
/// moving part, traced apart: what a ray meets in the static part can then be kept for
/// the same ray in a later frame, and only the moving part traced again.
///
/// Hits are numbered as the whole structure numbers them, every static triangle before
/// every moving one, so the closest hit of the whole is [`closest_of`] the two parts' (the moving part traced up to the static hit), and a ray is blocked when
/// either part blocks it: the same hits, ties included, as the structure's own queries.
pub trait Layers: Sync {
    /// The static triangles' count: hits below it name static triangles.
    fn static_count(&self) -> usize;
    /// The closest static hit of each ray.
    fn static_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]);
    /// Whether a static triangle blocks each ray.
    fn static_occluded_batch(&self, rays: &[Ray], out: &mut [bool]);
    /// The closest moving hit of each ray.
    fn moving_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]);
    /// Whether a moving triangle blocks each ray.
    fn moving_occluded_batch(&self, rays: &[Ray], out: &mut [bool]);
    /// A box that every moving triangle's hits lie in, as the moving part clips rays to
    /// it: a ray whose part of `[t_min, t_max]` inside it is empty
    /// (`psf::traverse::clipped_span`) gets no hit from [`moving_batch`](Self::moving_batch)
    /// and is not blocked by [`moving_occluded_batch`](Self::moving_occluded_batch).
    /// `None` (the default) where no such box is known.
    fn moving_bounds(&self) -> Option<Aabb> {
        None
    }
}

/// The closer of two hits under [`Hit::is_closer_than`] (either, where one is `None`).
#[inline]
pub fn closest_of(a: Option<Hit>, b: Option<Hit>) -> Option<Hit> {
    match (a, b) {
        (Some(a), Some(b)) => Some(if b.is_closer_than(&a) { b } else { a }),
        (a, b) => a.or(b),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn valid_rays_are_finite_with_a_direction() {
        let ok = Ray::segment(
            Vec3::new(1.0, -2.0, 3.0),
            Vec3::new(0.0, 0.0, -1.0),
            0.0,
            5.0,
        );
        assert!(ok.is_valid());
        assert!(Ray {
            t_max: f32::INFINITY,
            ..ok
        }
        .is_valid());
        assert!(
            Ray { t_min: 7.0, ..ok }.is_valid(),
            "an empty interval is still a ray"
        );
        for (i, bad) in [
            Ray {
                origin: Vec3::new(f32::NAN, 0.0, 0.0),
                ..ok
            },
            Ray {
                origin: Vec3::new(0.0, 0.0, f32::INFINITY),
                ..ok
            },
            Ray {
                dir: Vec3::new(0.0, f32::NEG_INFINITY, 1.0),
                ..ok
            },
            Ray {
                dir: Vec3::new(0.0, 0.0, f32::NAN),
                ..ok
            },
            Ray {
                dir: Vec3::ZERO,
                ..ok
            },
            Ray {
                dir: Vec3::new(-0.0, 0.0, -0.0),
                ..ok
            },
            Ray {
                t_min: f32::NAN,
                ..ok
            },
            Ray {
                t_max: f32::NAN,
                ..ok
            },
        ]
        .into_iter()
        .enumerate()
        {
            assert!(!bad.is_valid(), "ray {i}: {bad:?}");
        }
    }
}
