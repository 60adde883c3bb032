//! Scenes made in code: the museum demo (glTF), BART-style animart (AFF text), and
//! synthetic triangle sets for tests, benchmarks and examples.
//!
//! A generator uses `import` (the glTF writer) and `scene`; nothing below uses `gen`.

pub mod animart;
pub mod museum;
pub mod synth;
