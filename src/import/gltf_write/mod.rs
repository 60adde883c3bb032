//! The glTF 2.0 writer: the one [`Scene`] model out as `.glb` or `.gltf` (the `convert`
//! command, the generators in `crate::gen`, and tests that build their scenes in code).
//!
//! It writes what the model holds: meshes (positions, normals, `TEXCOORD_0`, skin
//! influences, morph targets), materials with their textures and images (encoded as PNG),
//! nodes, skins, cameras, `KHR_lights_punctual` lights, animation clips, `fps`
//! (`scenes[0].extras.fps`) and the scene's [`Extras`](crate::scene::Extras). A primitive
//! whose triangles are its vertices in order is written without indices.
//!
//! The JSON is written with `serde_json` directly: the subset we emit is small, and every
//! file is checked by the importer in the round-trip tests and by the Khronos validator in
//! `tests/aff_bart.rs`. The writer refuses a scene the border check `import::validate`
//! refuses, and what glTF cannot hold (see `check`), rather than write a file the importer
//! would reject. Files are written atomically: a temporary file in the same folder, fsync,
//! rename.

use std::path::Path;

use serde_json::json;

mod check;
mod document;

use super::ImportError;
use crate::scene::Scene;

/// Writes `scene` to `path` atomically: JSON with an embedded data-URI buffer when the
/// extension is `.gltf` (any case), GLB otherwise.
pub fn write_gltf(scene: &Scene, path: &Path) -> Result<(), ImportError> {
    let gltf = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gltf"));
    let bytes = if gltf {
        to_gltf_json(scene)?.into_bytes()
    } else {
        to_glb(scene)?
    };
    write_atomically(path, &bytes)
}

/// `scene` as a GLB container.
pub fn to_glb(scene: &Scene) -> Result<Vec<u8>, ImportError> {
    let (mut root, bin) = document::document(scene)?;
    if !bin.is_empty() {
        root["buffers"] = json!([{ "byteLength": bin.len() }]);
    }
    let mut json = serde_json::to_vec(&root).map_err(|e| ImportError::Write {
        reason: e.to_string(),
    })?;
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let mut bin = bin;
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    let total = u32::try_from(total).map_err(|_| ImportError::Write {
        reason: "scene larger than 4 GiB, too large for GLB".into(),
    })?;
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total.to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
    }
    Ok(out)
}

/// `scene` as glTF JSON, its buffer embedded as a base64 data URI.
pub fn to_gltf_json(scene: &Scene) -> Result<String, ImportError> {
    let (mut root, bin) = document::document(scene)?;
    if !bin.is_empty() {
        root["buffers"] = json!([{
            "byteLength": bin.len(),
            "uri": format!("data:application/octet-stream;base64,{}", encode_base64(&bin)),
        }]);
    }
    serde_json::to_string(&root).map_err(|e| ImportError::Write {
        reason: e.to_string(),
    })
}

fn encode_base64(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(data.len().div_ceil(3) * 4);
    for chunk in data.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(T[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), ImportError> {
    crate::atomic::write_atomically(path, bytes).map_err(|source| ImportError::WriteIo {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Mesh, Node, Primitive};
    use glam::Vec3;

    #[test]
    fn base64_encoding_round_trips_with_the_importer_decoder() {
        assert_eq!(encode_base64(b""), "");
        assert_eq!(encode_base64(b"f"), "Zg==");
        assert_eq!(encode_base64(b"fo"), "Zm8=");
        assert_eq!(encode_base64(b"foo"), "Zm9v");
        assert_eq!(encode_base64(b"foobar"), "Zm9vYmFy");
    }

    #[test]
    fn refuses_inconsistent_input() {
        let mut s = Scene::default();
        s.materials.push(crate::scene::Material::default());
        s.meshes.push(Mesh {
            primitives: vec![Primitive {
                positions: vec![Vec3::ZERO; 3],
                triangles: vec![[0, 1, 3]],
                ..Default::default()
            }],
            ..Default::default()
        });
        let e = to_glb(&s).unwrap_err().to_string();
        assert!(e.contains("vertex index 3 past the vertex count 3"), "{e}");
        let mut s = Scene::default();
        s.nodes.push(Node {
            parent: Some(0),
            children: vec![0], // its own child
            ..Node::default()
        });
        s.roots.push(0);
        assert!(to_glb(&s).is_err());
    }
}
