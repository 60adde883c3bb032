//! subfield: ray tracing of animated scenes with unstructured motion by parallel subfields.
//!
//! The data flows one way (DESIGN.md §2); each layer uses only those before it:
//!
//! * `geometry` (rays, boxes, triangles) → `psf` (bake, dynamic layer, traversal) →
//!   `format` (the `.psf` file: write, open);
//! * `scene`: the one Scene model (animation sampling, the static/dynamic split);
//! * `import` → `scene`: the glTF and AFF / NFF readers ([`import::load`]) and the glTF
//!   writer;
//! * `gen` → `import`, `scene`: scenes made in code (museum, animart, synthetic sets);
//! * `render` → `psf`, `format`, `scene`: camera, shading, EXR sequences.
//!
//! A module does not reach back up: `scene` knows no file format, `import` knows no
//! renderer, and nothing below `gen` uses it.

pub mod atomic;
pub mod farm;
pub mod format;
pub mod gen;
pub mod geometry;
pub mod import;
pub mod psf;
pub mod render;
pub mod scene;

// The psf unit tests scatter triangles with `crate::synth` (src/psf/ is edited by others;
// their two `use` lines can move to `crate::gen::synth` later). Private and test-only.
#[cfg(test)]
use gen::synth;

pub use geometry::{Aabb, BruteForce, Hit, Intersector, Ray};
pub use psf::{DynamicLayer, Psf, PsfError, PsfParams};

/// `n` and `noun`, the noun in the plural unless `n` is 1 ("1 frame", "3 frames"); for
/// nouns whose plural adds an `s`.
pub fn plural(n: impl Into<u64>, noun: &str) -> String {
    let n = n.into();
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}
