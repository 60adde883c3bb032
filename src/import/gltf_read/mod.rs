//! glTF 2.0 import (`.gltf` with external or data-URI buffers and images, and `.glb`).
//!
//! The JSON is read into our own model of the specification ([`json`]: every optional
//! property optional, unknown properties, extras and extensions skipped) and validated by
//! [`check`] against the specification itself, so a file the specification allows is
//! never refused for a rule of a library's. Everything that touches bytes is ours too:
//! the GLB container, buffers, URIs, accessors (bounds, types, sparse storage, finite
//! floats) and images. Every failure is an [`ImportError`] naming the file and the
//! accessor, node, extension or URI; what we read but cannot draw is a warning.
//!
//! One concept per file: this one holds the entry points, the GLB container, the
//! extension policy and the scene assembly; `json` the document model, `check` its
//! validation, `uri` buffers and URIs, `meshopt` compressed buffer views, `accessor` typed accessor reads, `material`
//! materials, textures and images, `mesh` primitives, `node` nodes, skins, cameras and
//! lights, `animation` clips.

mod accessor;
mod animation;
mod check;
mod json;
mod material;
mod mesh;
mod meshopt;
mod node;
mod uri;

use std::borrow::Cow;
use std::path::Path;

use glam::Vec3;

use super::ImportError;
use crate::scene::{Scene, Warning};

/// Extensions we read; a file may require any of these.
const SUPPORTED_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_transmission",
    "KHR_materials_ior",
    "KHR_mesh_quantization",
    "KHR_texture_transform",
    "EXT_texture_webp",
    // Compressed buffer views, decoded with meshoptimizer (see `meshopt`).
    "EXT_meshopt_compression",
    "KHR_meshopt_compression",
    // Pointers to node TRS and weights are animated; other pointers are skipped with a
    // warning (see `animation`).
    "KHR_animation_pointer",
];

/// Extensions we know but do not decode, with how to convert a file that requires one.
/// A file that only uses them (with the fallback the extension keeps) imports, warned.
const UNDECODED_EXTENSIONS: &[(&str, &str)] = &[
    (
        "KHR_draco_mesh_compression",
        "Draco-compressed geometry is not decoded (no maintained pure-Rust decoder); \
         re-export the file without Draco compression (e.g. Blender's glTF exporter with \
         Compression off)",
    ),
    (
        "KHR_texture_basisu",
        "KTX2 / Basis Universal textures are not decoded; extract them to PNG (e.g. with \
         KTX-Software's `ktx extract`) and give the textures those images as `source`",
    ),
];

pub(crate) fn load(path: &Path) -> Result<Scene, ImportError> {
    let bytes = super::read::read_whole(path).map_err(|source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let folder = path.parent().unwrap_or(Path::new("."));
    from_slice(&bytes, path, folder)
}

pub(crate) fn from_slice<'a>(
    bytes: &'a [u8],
    path: &'a Path,
    folder: &'a Path,
) -> Result<Scene, ImportError> {
    let (json, bin) = if bytes.starts_with(b"glTF") {
        split_glb(bytes).map_err(|reason| ImportError::Glb {
            path: path.to_path_buf(),
            reason,
        })?
    } else {
        (bytes, None)
    };
    let root = json::parse(json).map_err(|reason| ImportError::Json {
        path: path.to_path_buf(),
        reason,
    })?;
    let problems = check::check(&root);
    if !problems.is_empty() {
        return Err(ImportError::Invalid {
            path: path.to_path_buf(),
            problems,
        });
    }
    let mut importer = Importer {
        path,
        folder,
        root: &root,
        buffers: Vec::new(),
        decoded_views: Vec::new(),
        warnings: Vec::new(),
    };
    importer.check_extensions()?;
    importer.buffers = importer.load_buffers(bin)?;
    importer.decoded_views = importer.decode_views()?;
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
    root: &'a json::Root,
    /// Per buffer, its bytes; `None` when it has none (`uri::load_buffers`). A .glb's
    /// binary chunk is borrowed from the file's bytes, not copied.
    buffers: Vec<Option<Cow<'a, [u8]>>>,
    /// Per buffer view, its decoded bytes when it is meshopt-compressed (`meshopt`).
    decoded_views: Vec<Option<Vec<u8>>>,
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

    /// A required extension we do not read is one clear error (with how to convert the
    /// file when we know one); one only used is a warning.
    fn check_extensions(&mut self) -> Result<(), ImportError> {
        for ext in &self.root.extensions_required {
            if SUPPORTED_EXTENSIONS.contains(&ext.as_str()) {
                continue;
            }
            let what = match UNDECODED_EXTENSIONS.iter().find(|(e, _)| e == ext) {
                Some((_, how)) => format!("required extension {ext}: {how}"),
                None => format!("required extension {ext} is not supported"),
            };
            return Err(ImportError::Unsupported {
                path: self.path.to_path_buf(),
                what,
            });
        }
        let ignored: Vec<String> = self
            .root
            .extensions_used
            .iter()
            .filter(|e| !SUPPORTED_EXTENSIONS.contains(&e.as_str()))
            .cloned()
            .collect();
        for ext in ignored {
            self.warn(format!("extension {ext} is not supported; ignored"));
        }
        Ok(())
    }

    /// Whether the file declares `ext` in `extensionsUsed`.
    fn uses(&self, ext: &str) -> bool {
        self.root.extensions_used.iter().any(|e| e == ext)
    }

    fn build(mut self) -> Result<Scene, ImportError> {
        let path = self.path.to_path_buf();
        let texture_images = self.texture_images();
        let (materials, used_textures) = self.materials(&texture_images);
        let (textures, images) = self.textures_and_images(&used_textures, &texture_images)?;
        let mut scene = Scene {
            source: path.clone(),
            materials,
            textures,
            images,
            ..Scene::default()
        };
        scene.meshes = self.meshes(&scene.materials)?;
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
        let (lights, light_slots) = self.lights();
        scene.lights = lights;
        scene.nodes = self.nodes(&light_slots)?;
        scene.skins = self.skins()?;
        scene.cameras = self.cameras();
        scene.animations = self.animations()?;
        let root = self.root;
        let shown = root
            .scene
            .and_then(|s| root.scenes.get(s))
            .or_else(|| root.scenes.first());
        match shown {
            Some(s) => scene.roots = s.nodes.clone(),
            None => {
                scene.roots = (0..scene.nodes.len())
                    .filter(|&i| scene.nodes[i].parent.is_none())
                    .collect();
                if !scene.nodes.is_empty() {
                    self.warn("no scene defined: showing every root node".into());
                }
            }
        }
        scene.fps = self.fps(shown);
        scene.ambient = self.ambient(shown);
        scene.time_range = self.time_range(shown);
        scene.warnings = std::mem::take(&mut self.warnings);
        super::validate(&scene)?;
        Ok(scene)
    }

    /// The shown scene's `extras.key`, else the first scene's.
    fn scene_extra(&self, shown: Option<&json::Scene>, key: &str) -> Option<serde_json::Value> {
        let read = |s: &json::Scene| s.extras.as_ref()?.get(key).cloned();
        shown
            .and_then(read)
            .or_else(|| self.root.scenes.first().and_then(read))
    }

    /// The scene's ambient light, `extras.ambient` (three numbers, none negative), as
    /// subfield writes it for AFF's `am`.
    fn ambient(&mut self, shown: Option<&json::Scene>) -> Option<Vec3> {
        let v = self.scene_extra(shown, "ambient")?;
        let rgb: Option<Vec<f32>> = v.as_array().and_then(|a| {
            a.iter()
                .map(|x| x.as_f64().map(|x| x as f32))
                .collect::<Option<Vec<f32>>>()
        });
        match rgb.as_deref() {
            Some(&[r, g, b]) if [r, g, b].iter().all(|x| x.is_finite() && *x >= 0.0) => {
                Some(Vec3::new(r, g, b))
            }
            _ => {
                self.warn(format!(
                    "scene extras.ambient {v} is not three numbers of at least 0; ignored"
                ));
                None
            }
        }
    }

    /// The scene's authored time range, `extras.timeRange` (two numbers of seconds,
    /// the first no later than the second), as subfield writes it for an AFF scene's
    /// `a t0 t1 n` line (from 0, its `t0`, to its last frame).
    fn time_range(&mut self, shown: Option<&json::Scene>) -> Option<(f32, f32)> {
        let v = self.scene_extra(shown, "timeRange")?;
        let pair = v.as_array().and_then(|a| match a.as_slice() {
            [a, b] => Some((a.as_f64()?, b.as_f64()?)),
            _ => None,
        });
        match pair {
            Some((a, b))
                if a.is_finite()
                    && b.is_finite()
                    && a <= b
                    && a.abs() < f64::from(f32::MAX)
                    && b.abs() < f64::from(f32::MAX) =>
            {
                Some((a as f32, b as f32))
            }
            _ => {
                self.warn(format!(
                    "scene extras.timeRange {v} is not two numbers of seconds, the first \
                     no later than the second; ignored"
                ));
                None
            }
        }
    }

    fn fps(&mut self, shown: Option<&json::Scene>) -> Option<f32> {
        let read = |s: &json::Scene| -> Option<f64> { s.extras.as_ref()?.get("fps")?.as_f64() };
        let fps = shown
            .and_then(read)
            .or_else(|| self.root.scenes.first().and_then(read))?;
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
