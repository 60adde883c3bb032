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
//! * `gpu` → `psf`, `geometry` (the cargo feature `gpu`): the same tracer seam on a GPU
//!   (wgpu over Vulkan), the hits the CPU's to the bit;
//! * `render` → `psf`, `format`, `scene` (and `gpu` for `--device gpu`): camera, shading,
//!   EXR sequences;
//! * `farm` → `format`: staging bakes by content hash, Slurm and Open Job Description jobs.
//!
//! A module does not reach back up: `scene` knows no file format, `import` knows no
//! renderer, and nothing below `gen` uses it.
//!
//! `unsafe` is confined to two places, each block with its `// SAFETY:` argument: the
//! memory map in `format::read` and the cache hints (`_mm_prefetch`) in
//! `render::replay`, which a still camera's frames pay for (benches/PERF.md, issue 38,
//! round 11).
#![deny(clippy::undocumented_unsafe_blocks)]

pub mod atomic;
pub mod farm;
pub mod format;
pub mod gen;
pub mod geometry;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod import;
pub mod psf;
pub mod render;
pub mod scene;

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
