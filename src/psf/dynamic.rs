//! The dynamic layer: triangles that move, re-inserted every frame, and the query that
//! combines them with the static PSF.
//!
//! API (stable; the interior is being replaced by per-tile lists with generation stamps):
//! `DynamicLayer::new(&psf)`, `update(&tris)` each frame, `psf.with_dynamic(&layer)`
//! gives an [`Intersector`] whose hits number static triangles `0..S` and the layer's
//! triangles `S..S+D` (in the order given to `update`).

use glam::Vec3;

use super::{Psf, PsfError, PsfParams};
use crate::geometry::{Hit, Intersector, Ray};

/// Moving triangles, rebuilt by [`DynamicLayer::update`] each frame.
#[derive(Debug)]
pub struct DynamicLayer {
    params: PsfParams,
    inner: Psf,
}

impl DynamicLayer {
    /// An empty layer with the static PSF's direction level and tile count.
    pub fn new(static_psf: &Psf) -> DynamicLayer {
        Self::with_params(*static_psf.params())
    }

    /// An empty layer with its own parameters.
    pub fn with_params(params: PsfParams) -> DynamicLayer {
        DynamicLayer {
            params,
            inner: Psf::build(&[], &params).expect("an empty PSF always builds"),
        }
    }

    /// Replaces the layer's triangles with `tris` (this frame's positions).
    pub fn update(&mut self, tris: &[[Vec3; 3]]) -> Result<(), PsfError> {
        self.inner = Psf::build(tris, &self.params)?;
        Ok(())
    }

    /// The triangles of the last update.
    pub fn triangles(&self) -> &[[Vec3; 3]] {
        self.inner.triangles()
    }

    pub fn len(&self) -> usize {
        self.inner.triangles().len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The static PSF and a dynamic layer queried together.
#[derive(Clone, Copy, Debug)]
pub struct Layered<'a> {
    psf: &'a Psf,
    dynamic: &'a DynamicLayer,
}

impl Psf {
    /// Queries over this PSF and `dynamic` together; dynamic triangle `i` is reported
    /// as `self.triangles().len() + i`.
    pub fn with_dynamic<'a>(&'a self, dynamic: &'a DynamicLayer) -> Layered<'a> {
        Layered { psf: self, dynamic }
    }
}

impl Intersector for Layered<'_> {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let s = self.psf.intersect(ray);
        let mut r = *ray;
        if let Some(h) = &s {
            r.t_max = h.t;
        }
        let offset = self.psf.triangles().len() as u32;
        let d = self.dynamic.inner.intersect(&r).map(|mut h| {
            h.tri += offset;
            h
        });
        match (s, d) {
            (Some(a), Some(b)) => Some(if b.is_closer_than(&a) { b } else { a }),
            (a, b) => a.or(b),
        }
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.psf.occluded(ray) || self.dynamic.inner.occluded(ray)
    }
}
