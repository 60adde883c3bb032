//! The import layer: scene files in, the one [`Scene`] model out; and the glTF writer,
//! the model out again.
//!
//! * [`load`]: one entry for every format we read, chosen by extension (any case):
//!   `.aff` / `.nff` go through the BART reader ([`aff`]), `.usd` / `.usda` / `.usdc` /
//!   `.usdz` through the USD reader (the `openusd` crate; feature `usd`), everything else
//!   through the glTF 2.0 reader (`.gltf` with external or data-URI buffers, `.glb`). Each reader
//!   produces a [`Scene`] on its own; neither goes through the other. A Blender `.blend`
//!   file is refused with a word on exporting glTF ([`ImportError::BlendFile`]).
//! * [`from_gltf_slice`]: glTF or GLB bytes already in memory.
//! * [`validate`]: the border check every importer runs before handing a scene out; past
//!   it the rest of the crate relies on the invariants it checks (every index in range,
//!   every float finite, the node hierarchy a forest).
//! * [`write_gltf`], [`to_glb`], [`to_gltf_json`]: a [`Scene`] written as glTF 2.0 (the
//!   `convert` command, the generators in `crate::gen`, tests that build scenes in code).
//! * Files a scene names beside itself (glTF URIs, AFF includes and textures) follow one
//!   policy: inside the scene's folder, or refused ([`Outside`]).
//!
//! Every failure is an [`ImportError`] naming the file and the accessor, node, URI or line.
//!
//! Layering: `import` uses `scene` (the model it fills and writes); `scene` never uses
//! `import`. The readers do not use the writer: `subfield convert` is AFF → `Scene` →
//! glTF, and the AFF reader builds the model as the glTF reader builds it from the
//! converted file, so `bake`, `render` and a converted file see the same scene
//! (`tests/aff_bart.rs` checks it at several frames).

pub mod aff;
mod error;
mod folder;
mod gltf_read;
mod gltf_write;
mod read;
#[cfg(feature = "usd")]
mod usd;
mod validate;

use std::path::Path;

pub use error::ImportError;
pub use folder::Outside;
pub use gltf_write::{to_glb, to_gltf_json, write_gltf};
/// The most one allocation may ask for on this thread while a USD stage is read here
/// (`None` elsewhere): a global allocator that refuses more turns a damaged array length
/// into an error instead of gigabytes allocated and filled (`import::usd::cap`).
#[cfg(feature = "usd")]
pub use usd::allocation_cap as usd_allocation_cap;
/// Triangles of the fan a USD disk light becomes (an emitting card).
#[cfg(feature = "usd")]
pub use usd::DISK_SEGMENTS as USD_DISK_SEGMENTS;
pub use validate::validate;

use crate::scene::Scene;

/// Imports a scene file, choosing the reader by extension (any case).
///
/// A `.gltf` (external or data-URI buffers and images) or `.glb` file, validated against
/// the glTF 2.0 specification: the default scene's hierarchy, triangle primitives (strips
/// and fans unrolled; points and lines skipped with one warning), normals, the
/// `TEXCOORD_n` set the material's textures use, skins, morph targets, materials (with
/// emissive strength, transmission, ior, texture transforms), textures decoded to RGBA8
/// (PNG, JPEG, WebP), cameras, `KHR_lights_punctual` lights, animation clips (node
/// channels and `KHR_animation_pointer` node pointers), quantized attributes and
/// `extras.fps`. The README lists exactly what is read and what is refused.
///
/// A BART `.aff` or `.nff` file is parsed and mapped onto the model
/// ([`aff::load_scene`]), as the file `subfield convert` writes would import.
///
/// A USD file (`.usd`, `.usda`, `.usdc`, `.usdz`), with the default feature `usd`: the
/// composed stage's meshes (time-sampled points as [`PointCache`](crate::scene::PointCache)s),
/// xforms, cameras, lights and UsdPreviewSurface materials (docs/INPUTS.md lists them).
pub fn load(path: &Path) -> Result<Scene, ImportError> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    let is_aff = ext.eq_ignore_ascii_case("aff") || ext.eq_ignore_ascii_case("nff");
    if is_aff {
        return aff::load_scene(path);
    }
    if is_usd(ext) {
        #[cfg(feature = "usd")]
        return usd::load(path);
        #[cfg(not(feature = "usd"))]
        return Err(ImportError::UsdNotBuilt {
            path: path.to_path_buf(),
        });
    }
    let magic = magic_of(path);
    if matches!(magic, Some(Magic::Baked)) {
        return Err(ImportError::BakedFile {
            path: path.to_path_buf(),
        });
    }
    if matches!(magic, Some(Magic::Blend)) || is_blend_name(ext) {
        return Err(ImportError::BlendFile {
            path: path.to_path_buf(),
        });
    }
    // Another extension is read as glTF only where the bytes are (a GLB or JSON under
    // another name); else the message names what is read.
    let gltf_name = ext.is_empty() || ["gltf", "glb"].iter().any(|g| ext.eq_ignore_ascii_case(g));
    if !gltf_name && matches!(magic, Some(Magic::Other)) {
        return Err(ImportError::UnknownFormat {
            path: path.to_path_buf(),
            ext: ext.to_owned(),
        });
    }
    gltf_read::load(path)
}

/// Whether the extension names a USD file (`.usd`, `.usda`, `.usdc`, `.usdz`).
fn is_usd(ext: &str) -> bool {
    ["usd", "usda", "usdc", "usdz"]
        .iter()
        .any(|u| ext.eq_ignore_ascii_case(u))
}

/// A file that is not a scene, known by its first bytes.
enum Magic {
    /// Blender's `BLENDER` (an uncompressed `.blend`, whatever its name).
    Blend,
    /// The baked file's signature ([`crate::format::MAGIC`]).
    Baked,
    /// Neither a GLB's `glTF` nor JSON (a `{` after any blanks): not glTF.
    Other,
}

/// What `path`'s first bytes say it is, where they say it is not a scene; a file that
/// cannot be read is not judged here: the reader reports it.
fn magic_of(path: &Path) -> Option<Magic> {
    let mut head = Vec::with_capacity(8);
    let f = std::fs::File::open(path).ok()?;
    std::io::Read::read_to_end(&mut std::io::Read::take(f, 8), &mut head).ok()?;
    if head.starts_with(b"BLENDER") {
        Some(Magic::Blend)
    } else if head == crate::format::MAGIC {
        Some(Magic::Baked)
    } else if head.starts_with(b"glTF")
        || head
            .iter()
            .find(|b| !b.is_ascii_whitespace())
            .is_none_or(|&b| b == b'{' || b == 0xEF)
    {
        // GLB, JSON (or a UTF-8 byte-order mark before it), or blanks alone: the glTF
        // reader says what is wrong with it.
        None
    } else {
        Some(Magic::Other)
    }
}

/// Whether the extension names a Blender file: `.blend` or a backup (`.blend1`,
/// `.blend2`…).
fn is_blend_name(ext: &str) -> bool {
    ext.to_ascii_lowercase()
        .strip_prefix("blend")
        .is_some_and(|n| n.bytes().all(|c| c.is_ascii_digit()))
}

/// Imports glTF or GLB bytes; external URIs resolve against `folder`.
/// `path` is only used to name the input in errors.
pub fn from_gltf_slice(bytes: &[u8], path: &Path, folder: &Path) -> Result<Scene, ImportError> {
    gltf_read::from_slice(bytes, path, folder)
}
