//! glTF 2.0 import (`.gltf` with external or data-URI buffers and images, and `.glb`).
//!
//! The `gltf` crate parses and validates the JSON (indices in range, required fields);
//! everything that touches bytes is ours: the GLB container, buffers, URIs, accessors
//! (bounds, types, sparse storage, finite floats) and images. Its `import` helpers are
//! not used because they trust the offsets they read and can panic on malformed files;
//! here every failure is an [`ImportError`] naming the file and the accessor, node or URI.
//!
//! One concept per file: this one holds the entry points, the GLB container and the
//! scene assembly; `uri` buffers and URIs, `accessor` typed accessor reads, `material`
//! materials, textures and images, `mesh` primitives, `node` nodes, skins, cameras and
//! lights, `animation` clips.

mod accessor;
mod animation;
mod material;
mod mesh;
mod node;
mod uri;

use std::path::Path;

use super::ImportError;
use crate::scene::{Scene, Warning};

/// Extensions whose absence from our reader would change the picture; files that
/// require any other extension are refused rather than drawn wrongly.
const SUPPORTED_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_transmission",
    "KHR_materials_ior",
];

pub(crate) fn load(path: &Path) -> Result<Scene, ImportError> {
    let bytes = std::fs::read(path).map_err(|source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let folder = path.parent().unwrap_or(Path::new("."));
    from_slice(&bytes, path, folder)
}

pub(crate) fn from_slice(bytes: &[u8], path: &Path, folder: &Path) -> Result<Scene, ImportError> {
    let (json, bin) = if bytes.starts_with(b"glTF") {
        split_glb(bytes).map_err(|reason| ImportError::Glb {
            path: path.to_path_buf(),
            reason,
        })?
    } else {
        (bytes, None)
    };
    let root: gltf::json::Root =
        gltf::json::deserialize::from_slice(json).map_err(|e| ImportError::Json {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
    // gltf-json's validation indexes `accessors` with the POSITION index unchecked (and
    // panics when it is out of range): check that one first.
    let mut problems = Vec::new();
    for (mi, m) in root.meshes.iter().enumerate() {
        for (pi, p) in m.primitives.iter().enumerate() {
            let pos = gltf::json::validation::Checked::Valid(gltf::json::mesh::Semantic::Positions);
            if let Some(i) = p.attributes.get(&pos) {
                if i.value() >= root.accessors.len() {
                    problems.push(format!(
                        "meshes[{mi}].primitives[{pi}].attributes.POSITION: accessor {} out of range",
                        i.value()
                    ));
                }
            }
        }
    }
    if !problems.is_empty() {
        return Err(ImportError::Invalid {
            path: path.to_path_buf(),
            problems,
        });
    }
    let doc = gltf::Document::from_json(root).map_err(|e| match e {
        gltf::Error::Validation(list) => ImportError::Invalid {
            path: path.to_path_buf(),
            problems: list.iter().map(|(p, e)| format!("{p}: {e}")).collect(),
        },
        other => ImportError::Json {
            path: path.to_path_buf(),
            reason: other.to_string(),
        },
    })?;
    let mut importer = Importer {
        path,
        folder,
        doc: &doc,
        buffers: Vec::new(),
        warnings: Vec::new(),
    };
    importer.check_extensions()?;
    importer.buffers = importer.load_buffers(bin)?;
    importer.build()
}

/// Splits a GLB container into its JSON chunk and optional BIN chunk.
fn split_glb(bytes: &[u8]) -> Result<(&[u8], Option<&[u8]>), String> {
    let u32_at = |at: usize| -> Option<u32> {
        let b = bytes.get(at..at.checked_add(4)?)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let version = u32_at(4).ok_or("truncated header (under 12 bytes)")?;
    if version != 2 {
        return Err(format!("version {version}, only 2 is supported"));
    }
    let length = u32_at(8).ok_or("truncated header (under 12 bytes)")? as usize;
    if length > bytes.len() {
        return Err(format!(
            "truncated: header says {length} bytes, file has {}",
            bytes.len()
        ));
    }
    if length < 20 {
        return Err(format!("length {length} leaves no room for the JSON chunk"));
    }
    let mut at = 12usize;
    let mut json = None;
    let mut bin = None;
    while at < length {
        let (Some(len), Some(kind)) = (u32_at(at), u32_at(at + 4)) else {
            return Err(format!("truncated chunk header at byte {at}"));
        };
        let start = at + 8;
        let end = start
            .checked_add(len as usize)
            .filter(|&e| e <= length)
            .ok_or_else(|| {
                format!("chunk at byte {at} claims {len} bytes, past the end ({length})")
            })?;
        let data = &bytes[start..end];
        match (&kind.to_le_bytes(), json.is_none()) {
            (b"JSON", true) => json = Some(data),
            (_, true) => return Err("the first chunk is not JSON".to_string()),
            (b"BIN\0", false) if bin.is_none() => bin = Some(data),
            _ => {} // unknown chunks are skipped, as the spec asks
        }
        // Chunks are padded to 4 bytes.
        at = end.div_ceil(4) * 4;
    }
    Ok((json.ok_or("no JSON chunk")?, bin))
}

struct Importer<'a> {
    path: &'a Path,
    folder: &'a Path,
    doc: &'a gltf::Document,
    buffers: Vec<Vec<u8>>,
    warnings: Vec<Warning>,
}

impl Importer<'_> {
    fn warn(&mut self, message: String) {
        self.warnings.push(Warning(message));
    }

    fn acc_err(&self, accessor: usize, usage: &str, reason: impl Into<String>) -> ImportError {
        ImportError::Accessor {
            path: self.path.to_path_buf(),
            accessor,
            usage: usage.to_string(),
            reason: reason.into(),
        }
    }

    fn check_extensions(&mut self) -> Result<(), ImportError> {
        for ext in self.doc.extensions_required() {
            if !SUPPORTED_EXTENSIONS.contains(&ext) {
                return Err(ImportError::Unsupported {
                    path: self.path.to_path_buf(),
                    what: format!("required extension {ext}"),
                });
            }
        }
        let ignored: Vec<String> = self
            .doc
            .extensions_used()
            .filter(|e| !SUPPORTED_EXTENSIONS.contains(e))
            .map(str::to_string)
            .collect();
        for ext in ignored {
            self.warn(format!("extension {ext} is ignored"));
        }
        Ok(())
    }

    fn build(mut self) -> Result<Scene, ImportError> {
        let path = self.path.to_path_buf();
        let (materials, used_textures) = self.materials();
        let (textures, images) = self.textures_and_images(&used_textures)?;
        let mut scene = Scene {
            source: path.clone(),
            materials,
            textures,
            images,
            ..Scene::default()
        };
        scene.meshes = self.meshes()?;
        if scene
            .meshes
            .iter()
            .flat_map(|m| &m.primitives)
            .any(|p| p.material == u32::MAX)
        {
            let d = scene.default_material_index();
            for p in scene.meshes.iter_mut().flat_map(|m| &mut m.primitives) {
                if p.material == u32::MAX {
                    p.material = d;
                }
            }
        }
        scene.nodes = self.nodes()?;
        scene.skins = self.skins()?;
        scene.cameras = self.cameras();
        scene.lights = self.lights();
        scene.animations = self.animations()?;
        let shown = self
            .doc
            .default_scene()
            .or_else(|| self.doc.scenes().next());
        match &shown {
            Some(s) => scene.roots = s.nodes().map(|n| n.index()).collect(),
            None => {
                scene.roots = (0..scene.nodes.len())
                    .filter(|&i| scene.nodes[i].parent.is_none())
                    .collect();
                self.warn("no scene defined: showing every root node".into());
            }
        }
        scene.fps = self.fps(shown.as_ref());
        scene.warnings = std::mem::take(&mut self.warnings);
        super::validate(&scene)?;
        Ok(scene)
    }

    fn fps(&mut self, shown: Option<&gltf::Scene>) -> Option<f32> {
        let read = |s: &gltf::Scene| -> Option<f64> {
            let raw = s.extras().as_ref()?;
            let v: serde_json::Value = serde_json::from_str(raw.get()).ok()?;
            v.get("fps")?.as_f64()
        };
        let fps = shown
            .and_then(read)
            .or_else(|| self.doc.scenes().next().as_ref().and_then(read))?;
        if fps.is_finite() && fps > 0.0 && fps < f64::from(f32::MAX) {
            Some(fps as f32)
        } else {
            self.warn(format!(
                "scene extras.fps {fps} is not a positive number; ignored"
            ));
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glb_header_checks() {
        assert!(split_glb(b"glTF").is_err());
        let mut glb = Vec::new();
        glb.extend_from_slice(b"glTF");
        glb.extend_from_slice(&2u32.to_le_bytes());
        glb.extend_from_slice(&28u32.to_le_bytes());
        glb.extend_from_slice(&8u32.to_le_bytes());
        glb.extend_from_slice(b"JSON");
        glb.extend_from_slice(b"{}      ");
        let (json, bin) = split_glb(&glb).unwrap();
        assert_eq!(json, b"{}      ");
        assert!(bin.is_none());
        assert!(split_glb(&glb[..27]).unwrap_err().contains("truncated"));
        let mut v3 = glb.clone();
        v3[4] = 3;
        assert!(split_glb(&v3).unwrap_err().contains("version"));
        let mut long_chunk = glb.clone();
        long_chunk[12] = 200;
        assert!(split_glb(&long_chunk).unwrap_err().contains("past the end"));
    }
}
