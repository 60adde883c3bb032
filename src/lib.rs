//! subfield: ray tracing of animated scenes with unstructured motion by parallel subfields.
//!
//! The data flows one way (see README): `scene` → `psf` (bake, dynamic, traverse) →
//! `format` (write, open) → `render` (camera, shading, EXR sequences). A module does not
//! reach back up.

pub mod aff;
pub mod atomic;
pub mod farm;
pub mod format;
pub mod geometry;
pub mod museum;
pub mod psf;
pub mod render;
pub mod scene;
pub mod synth;

pub use geometry::{Aabb, BruteForce, Hit, Intersector, Ray};
pub use psf::{DynamicLayer, Psf, PsfError, PsfParams};
