//! Scenes made in code: the museum demo (glTF), BART-style animart (AFF text), and
//! synthetic triangle sets for tests, benchmarks and examples.
//!
//! A generator builds `scene` values (the museum is written with `import`'s glTF writer);
//! nothing below uses `gen`.

pub mod animart;
pub mod museum;
pub mod synth;
