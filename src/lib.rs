//! subfield: ray tracing of animated scenes with unstructured motion by parallel subfields.
//!
//! The data flows one way (see README): `scene` → `psf` (bake, dynamic, traverse) →
//! `format` (write, open) → `render` (camera, shading, EXR sequences). A module does not
//! reach back up.
//!
//! `unsafe` is confined to two places, each block with its `// SAFETY:` argument: the
//! memory map in `format::read` and the SSE2 intrinsics in `psf::grid`.
#![deny(clippy::undocumented_unsafe_blocks)]

pub mod aff;
pub mod atomic;
pub mod format;
pub mod geometry;
pub mod museum;
pub mod psf;
pub mod render;
pub mod scene;
pub mod synth;

pub use geometry::{Aabb, BruteForce, Hit, Intersector, Ray};
pub use psf::{DynamicLayer, Psf, PsfError, PsfParams};
