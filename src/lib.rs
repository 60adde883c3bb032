//! subfield: ray tracing of animated scenes with unstructured motion by parallel subfields.
//!
//! The data flows one way (see README): `scene` → `psf` (bake, dynamic, traverse) →
//! `format` (write, open) → `render` (camera, shading, EXR sequences). A module does not
//! reach back up.

pub mod aff;
pub mod atomic;
pub mod format;
pub mod gen;
pub mod geometry;
pub mod psf;
pub mod render;
pub mod scene;

// The psf unit tests scatter triangles with `crate::synth` (src/psf/ is edited by others;
// their two `use` lines can move to `crate::gen::synth` later). Private and test-only.
#[cfg(test)]
use gen::synth;

pub use geometry::{Aabb, BruteForce, Hit, Intersector, Ray};
pub use psf::{DynamicLayer, Psf, PsfError, PsfParams};
