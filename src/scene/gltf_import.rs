//! glTF 2.0 import (`.gltf` with external or data-URI buffers and images, and `.glb`).
//!
//! The `gltf` crate parses and validates the JSON (indices in range, required fields);
//! everything that touches bytes is ours: the GLB container, buffers, URIs, accessors
//! (bounds, types, sparse storage, finite floats) and images. Its `import` helpers are
//! not used because they trust the offsets they read and can panic on malformed files;
//! here every failure is a [`SceneError`] naming the file and the accessor, node or URI.

use std::path::{Component, Path, PathBuf};

use glam::{Mat4, Quat, Vec2, Vec3, Vec4};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use rayon::prelude::*;

use super::{
    AlphaMode, Animation, CameraDef, Channel, Image, Interpolation, LightDef, LightKind, Material,
    Mesh, MorphTarget, Node, NodeTransform, Primitive, Projection, Property, Scene, SceneError,
    Skin, Texture, TextureRef, Trs, Warning, Wrap,
};

/// Refuse accessors claiming more components than this.
const MAX_COMPONENTS: usize = 1 << 28;
/// An accessor without a buffer view is all zeros (plus sparse values): its count is not
/// bounded by any buffer, so it gets a tighter cap (16 Mi components, 128 MiB decoded).
const MAX_ZERO_COMPONENTS: usize = 1 << 24;

/// Extensions whose absence from our reader would change the picture; files that
/// require any other extension are refused rather than drawn wrongly.
const SUPPORTED_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_transmission",
    "KHR_materials_ior",
];

pub(super) fn load(path: &Path) -> Result<Scene, SceneError> {
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let folder = path.parent().unwrap_or(Path::new("."));
    from_slice(&bytes, path, folder)
}

pub(super) fn from_slice(bytes: &[u8], path: &Path, folder: &Path) -> Result<Scene, SceneError> {
    let (json, bin) = if bytes.starts_with(b"glTF") {
        split_glb(bytes).map_err(|reason| SceneError::Glb {
            path: path.to_path_buf(),
            reason,
        })?
    } else {
        (bytes, None)
    };
    let root: gltf::json::Root =
        gltf::json::deserialize::from_slice(json).map_err(|e| SceneError::Json {
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
        return Err(SceneError::Invalid {
            path: path.to_path_buf(),
            problems,
        });
    }
    let doc = gltf::Document::from_json(root).map_err(|e| match e {
        gltf::Error::Validation(list) => SceneError::Invalid {
            path: path.to_path_buf(),
            problems: list.iter().map(|(p, e)| format!("{p}: {e}")).collect(),
        },
        other => SceneError::Json {
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

/// Decoded accessor contents, exact (f64 holds every u32 and f32 value).
struct Raw {
    values: Vec<f64>,
    comps: usize,
    data_type: DataType,
    normalized: bool,
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

    fn acc_err(&self, accessor: usize, usage: &str, reason: impl Into<String>) -> SceneError {
        SceneError::Accessor {
            path: self.path.to_path_buf(),
            accessor,
            usage: usage.to_string(),
            reason: reason.into(),
        }
    }

    fn check_extensions(&mut self) -> Result<(), SceneError> {
        for ext in self.doc.extensions_required() {
            if !SUPPORTED_EXTENSIONS.contains(&ext) {
                return Err(SceneError::Unsupported {
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

    // ---- buffers and URIs -------------------------------------------------------------

    fn load_buffers(&self, bin: Option<&[u8]>) -> Result<Vec<Vec<u8>>, SceneError> {
        let mut out = Vec::new();
        for buffer in self.doc.buffers() {
            let i = buffer.index();
            let err = |reason: String| SceneError::Buffer {
                path: self.path.to_path_buf(),
                buffer: i,
                reason,
            };
            let mut data = match buffer.source() {
                gltf::buffer::Source::Bin => match (i, bin) {
                    (0, Some(b)) => b.to_vec(),
                    _ => {
                        return Err(err(
                            "has no URI and there is no GLB binary chunk for it".into()
                        ))
                    }
                },
                gltf::buffer::Source::Uri(uri) => self.load_uri(uri, &format!("buffers[{i}]"))?,
            };
            if data.len() < buffer.length() {
                return Err(err(format!(
                    "holds {} bytes but byteLength is {}",
                    data.len(),
                    buffer.length()
                )));
            }
            data.truncate(buffer.length());
            out.push(data);
        }
        Ok(out)
    }

    /// Reads a `data:` URI or a file relative to the scene's folder. A URI that leaves the
    /// folder (absolute, `..` above it, another scheme) is refused.
    fn load_uri(&self, uri: &str, what: &str) -> Result<Vec<u8>, SceneError> {
        if let Some(rest) = uri.strip_prefix("data:") {
            let bad = |reason: String| SceneError::BadUri {
                path: self.path.to_path_buf(),
                what: what.to_string(),
                reason,
            };
            let (meta, payload) = rest
                .split_once(',')
                .ok_or_else(|| bad("data URI without a comma".into()))?;
            return if meta.ends_with(";base64") {
                decode_base64(payload).map_err(|r| bad(format!("bad base64 in data URI: {r}")))
            } else {
                Ok(percent_decode(payload))
            };
        }
        let refuse = || SceneError::UriOutsideFolder {
            path: self.path.to_path_buf(),
            what: what.to_string(),
            uri: uri.to_string(),
        };
        // A scheme ("http:", "file:", "C:") is never a relative reference.
        if let Some(colon) = uri.find(':') {
            if !uri[..colon].contains('/') {
                return Err(refuse());
            }
        }
        let decoded = String::from_utf8(percent_decode(uri)).map_err(|_| refuse())?;
        // Resolved lexically ("a/../b" is "b" whether or not "a" exists), so the check
        // and the file opened are the same path.
        let mut rel = PathBuf::new();
        for c in Path::new(&decoded).components() {
            match c {
                Component::Normal(part) => rel.push(part),
                Component::CurDir => {}
                Component::ParentDir => {
                    if !rel.pop() {
                        return Err(refuse());
                    }
                }
                Component::RootDir | Component::Prefix(_) => return Err(refuse()),
            }
        }
        let resolved: PathBuf = self.folder.join(rel);
        std::fs::read(&resolved).map_err(|source| SceneError::MissingFile {
            path: self.path.to_path_buf(),
            what: what.to_string(),
            uri: uri.to_string(),
            resolved,
            source,
        })
    }

    /// The bytes of a buffer view, checked against its buffer.
    fn view_bytes(
        &self,
        view: &gltf::buffer::View,
        accessor: usize,
        usage: &str,
    ) -> Result<&[u8], SceneError> {
        let b = view.buffer().index();
        let buf = self.buffers.get(b).map(Vec::as_slice).unwrap_or(&[]);
        let start = view.offset();
        let end = start.checked_add(view.length());
        end.and_then(|end| buf.get(start..end)).ok_or_else(|| {
            self.acc_err(
                accessor,
                usage,
                format!(
                    "bufferViews[{}] (bytes {start}..+{}) lies outside buffers[{b}] ({} bytes)",
                    view.index(),
                    view.length(),
                    buf.len()
                ),
            )
        })
    }

    // ---- accessors --------------------------------------------------------------------

    fn read_raw(&self, acc: &gltf::Accessor, usage: &str) -> Result<Raw, SceneError> {
        let ai = acc.index();
        let data_type = acc.data_type();
        let dims = acc.dimensions();
        let comps = dims.multiplicity();
        let csize = data_type.size();
        if matches!(dims, Dimensions::Mat2 | Dimensions::Mat3) && csize < 4 {
            return Err(self.acc_err(ai, usage, "padded matrix columns are not supported"));
        }
        let elem = csize * comps;
        let count = acc.count();
        let total = count
            .checked_mul(comps)
            .filter(|&n| n <= MAX_COMPONENTS)
            .ok_or_else(|| self.acc_err(ai, usage, format!("count {count} is too large")))?;
        let mut values = Vec::new();
        if let Some(view) = acc.view() {
            let bytes = self.view_bytes(&view, ai, usage)?;
            let stride = match view.stride() {
                Some(s) if s < elem => {
                    return Err(self.acc_err(
                        ai,
                        usage,
                        format!("byteStride {s} is smaller than the element size {elem}"),
                    ))
                }
                Some(s) => s,
                None => elem,
            };
            let start = acc.offset();
            if count > 0 {
                let need = (count - 1)
                    .checked_mul(stride)
                    .and_then(|x| x.checked_add(start))
                    .and_then(|x| x.checked_add(elem));
                match need {
                    Some(n) if n <= bytes.len() => {}
                    _ => {
                        return Err(self.acc_err(
                            ai,
                            usage,
                            format!(
                            "{count} elements of {elem} bytes (stride {stride}) from byte {start} \
                                 run past bufferViews[{}] ({} bytes)",
                            view.index(),
                            bytes.len()
                        ),
                        ))
                    }
                }
            }
            values.resize(total, 0.0);
            for e in 0..count {
                let base = start + e * stride;
                for c in 0..comps {
                    let at = base + c * csize;
                    values[e * comps + c] = component(&bytes[at..at + csize], data_type);
                }
            }
        } else if total <= MAX_ZERO_COMPONENTS {
            values.resize(total, 0.0); // no buffer view: zeros (then sparse values)
        } else {
            return Err(self.acc_err(
                ai,
                usage,
                format!("count {count} without a buffer view is too large"),
            ));
        }
        if let Some(sparse) = acc.sparse() {
            let n = sparse.count();
            let idx = sparse.indices();
            let vals = sparse.values();
            let isize = match idx.index_type() {
                gltf::accessor::sparse::IndexType::U8 => 1,
                gltf::accessor::sparse::IndexType::U16 => 2,
                gltf::accessor::sparse::IndexType::U32 => 4,
            };
            let ibytes = self.view_bytes(&idx.view(), ai, usage)?;
            let vbytes = self.view_bytes(&vals.view(), ai, usage)?;
            let ifits = n
                .checked_mul(isize)
                .and_then(|x| x.checked_add(idx.offset()))
                .is_some_and(|end| end <= ibytes.len());
            let vfits = n
                .checked_mul(elem)
                .and_then(|x| x.checked_add(vals.offset()))
                .is_some_and(|end| end <= vbytes.len());
            if !ifits || !vfits {
                return Err(self.acc_err(ai, usage, "sparse data runs past its buffer view"));
            }
            for k in 0..n {
                let at = idx.offset() + k * isize;
                let target = match isize {
                    1 => usize::from(ibytes[at]),
                    2 => usize::from(u16::from_le_bytes([ibytes[at], ibytes[at + 1]])),
                    _ => u32::from_le_bytes([
                        ibytes[at],
                        ibytes[at + 1],
                        ibytes[at + 2],
                        ibytes[at + 3],
                    ]) as usize,
                };
                if target >= count {
                    return Err(self.acc_err(
                        ai,
                        usage,
                        format!("sparse index {target} past the count {count}"),
                    ));
                }
                for c in 0..comps {
                    let at = vals.offset() + k * elem + c * csize;
                    values[target * comps + c] = component(&vbytes[at..at + csize], data_type);
                }
            }
        }
        Ok(Raw {
            values,
            comps,
            data_type,
            normalized: acc.normalized(),
        })
    }

    /// Floats, with integer components normalised when the accessor says so or
    /// `normalize_ints` (weights, uvs, rotations: the spec only allows normalised ints).
    fn floats(
        &self,
        acc: &gltf::Accessor,
        usage: &str,
        comps: usize,
        normalize_ints: bool,
    ) -> Result<Vec<f32>, SceneError> {
        let raw = self.read_raw(acc, usage)?;
        if raw.comps != comps {
            return Err(self.acc_err(
                acc.index(),
                usage,
                format!("has {} components per element, expected {comps}", raw.comps),
            ));
        }
        let normalize = raw.normalized || normalize_ints;
        let scale = match raw.data_type {
            DataType::F32 => None,
            DataType::I8 if normalize => Some(127.0),
            DataType::U8 if normalize => Some(255.0),
            DataType::I16 if normalize => Some(32767.0),
            DataType::U16 if normalize => Some(65535.0),
            DataType::U32 if normalize => {
                return Err(self.acc_err(acc.index(), usage, "normalised UNSIGNED_INT"))
            }
            _ => None,
        };
        let mut out = Vec::with_capacity(raw.values.len());
        for (i, v) in raw.values.iter().enumerate() {
            let f = match scale {
                Some(s) => (v / s).max(-1.0) as f32,
                None => *v as f32,
            };
            if !f.is_finite() {
                return Err(self.acc_err(
                    acc.index(),
                    usage,
                    format!(
                        "element {} component {} is {f} (not finite)",
                        i / comps,
                        i % comps
                    ),
                ));
            }
            out.push(f);
        }
        Ok(out)
    }

    fn vec3s(&self, acc: &gltf::Accessor, usage: &str) -> Result<Vec<Vec3>, SceneError> {
        let f = self.floats(acc, usage, 3, false)?;
        Ok(f.chunks_exact(3).map(Vec3::from_slice).collect())
    }

    /// Unsigned integers (indices, joints): must be an unsigned, non-normalised type.
    fn uints(
        &self,
        acc: &gltf::Accessor,
        usage: &str,
        comps: usize,
    ) -> Result<Vec<u32>, SceneError> {
        let raw = self.read_raw(acc, usage)?;
        if raw.comps != comps
            || !matches!(raw.data_type, DataType::U8 | DataType::U16 | DataType::U32)
        {
            return Err(self.acc_err(
                acc.index(),
                usage,
                format!(
                    "expected {comps} unsigned integer component(s), found {} of {:?}",
                    raw.comps, raw.data_type
                ),
            ));
        }
        Ok(raw.values.iter().map(|&v| v as u32).collect())
    }

    // ---- the scene --------------------------------------------------------------------

    fn build(mut self) -> Result<Scene, SceneError> {
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
        scene.cameras = self
            .doc
            .cameras()
            .map(|c| CameraDef {
                name: c.name().map(str::to_string),
                projection: match c.projection() {
                    gltf::camera::Projection::Perspective(p) => Projection::Perspective {
                        yfov: p.yfov(),
                        aspect: p.aspect_ratio(),
                        znear: p.znear(),
                        zfar: p.zfar(),
                    },
                    gltf::camera::Projection::Orthographic(o) => Projection::Orthographic {
                        xmag: o.xmag(),
                        ymag: o.ymag(),
                        znear: o.znear(),
                        zfar: o.zfar(),
                    },
                },
            })
            .collect();
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
        scene.validate()?;
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

    fn texture_ref(
        &mut self,
        info: Option<gltf::texture::Info>,
        used: &mut Vec<usize>,
    ) -> Option<TextureRef> {
        let info = info?;
        let t = info.texture().index();
        if info.tex_coord() != 0 {
            self.warn(format!(
                "textures[{t}] uses TEXCOORD_{}; only TEXCOORD_0 is imported",
                info.tex_coord()
            ));
        }
        if info.texture_transform().is_some() {
            self.warn(format!("KHR_texture_transform on textures[{t}] is ignored"));
        }
        // Remapped later to the compact list of textures actually used.
        let slot = used.iter().position(|&u| u == t).unwrap_or_else(|| {
            used.push(t);
            used.len() - 1
        });
        Some(TextureRef {
            texture: slot as u32,
            tex_coord: info.tex_coord(),
        })
    }

    fn materials(&mut self) -> (Vec<Material>, Vec<usize>) {
        let mut used = Vec::new();
        let mut out = Vec::new();
        for m in self.doc.materials() {
            let pbr = m.pbr_metallic_roughness();
            let base_color_texture = self.texture_ref(pbr.base_color_texture(), &mut used);
            let metallic_roughness_texture =
                self.texture_ref(pbr.metallic_roughness_texture(), &mut used);
            let emissive_texture = self.texture_ref(m.emissive_texture(), &mut used);
            if m.transmission()
                .and_then(|t| t.transmission_texture())
                .is_some()
            {
                self.warn(format!(
                    "materials[{}]: transmission texture ignored (factor used)",
                    m.index().unwrap_or(0)
                ));
            }
            out.push(Material {
                name: m.name().map(str::to_string),
                base_color: Vec4::from_array(pbr.base_color_factor()),
                base_color_texture,
                metallic: pbr.metallic_factor(),
                roughness: pbr.roughness_factor(),
                metallic_roughness_texture,
                emissive: Vec3::from_array(m.emissive_factor()),
                emissive_strength: m.emissive_strength().unwrap_or(1.0),
                emissive_texture,
                transmission: m.transmission().map_or(0.0, |t| t.transmission_factor()),
                ior: m.ior().unwrap_or(1.5),
                double_sided: m.double_sided(),
                alpha_mode: match m.alpha_mode() {
                    gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
                    gltf::material::AlphaMode::Mask => AlphaMode::Mask {
                        cutoff: m.alpha_cutoff().unwrap_or(0.5),
                    },
                    gltf::material::AlphaMode::Blend => AlphaMode::Blend,
                },
            });
        }
        (out, used)
    }

    /// Builds the textures that materials use and decodes only the images behind them.
    fn textures_and_images(
        &self,
        used: &[usize],
    ) -> Result<(Vec<Texture>, Vec<Image>), SceneError> {
        let json = self.doc.as_json();
        let mut image_ids: Vec<usize> = Vec::new();
        let mut textures = Vec::new();
        for &t in used {
            let Some(tex) = self.doc.textures().nth(t) else {
                continue; // validated: cannot happen
            };
            let img = tex.source().index();
            let slot = image_ids.iter().position(|&i| i == img).unwrap_or_else(|| {
                image_ids.push(img);
                image_ids.len() - 1
            });
            let wrap = |w| match w {
                gltf::texture::WrappingMode::ClampToEdge => Wrap::ClampToEdge,
                gltf::texture::WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
                gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
            };
            let sampler = tex.sampler();
            textures.push(Texture {
                image: slot as u32,
                wrap_s: wrap(sampler.wrap_s()),
                wrap_t: wrap(sampler.wrap_t()),
                nearest: sampler.mag_filter() == Some(gltf::texture::MagFilter::Nearest),
            });
        }
        // Gather the encoded bytes (sequential: reads files), decode in parallel.
        let mut encoded = Vec::with_capacity(image_ids.len());
        for &i in &image_ids {
            let Some(img) = json.images.get(i) else {
                continue;
            };
            let what = format!("images[{i}]");
            let bytes = match (&img.buffer_view, &img.uri) {
                (Some(v), _) => {
                    let view =
                        self.doc
                            .views()
                            .nth(v.value())
                            .ok_or_else(|| SceneError::Image {
                                path: self.path.to_path_buf(),
                                image: i,
                                reason: "buffer view missing".into(),
                            })?;
                    let b = view.buffer().index();
                    let buf = self.buffers.get(b).map(Vec::as_slice).unwrap_or(&[]);
                    view.offset()
                        .checked_add(view.length())
                        .and_then(|end| buf.get(view.offset()..end))
                        .ok_or_else(|| SceneError::Image {
                            path: self.path.to_path_buf(),
                            image: i,
                            reason: format!("bufferViews[{}] lies outside buffers[{b}]", v.value()),
                        })?
                        .to_vec()
                }
                (None, Some(uri)) => self.load_uri(uri, &what)?,
                (None, None) => {
                    return Err(SceneError::Image {
                        path: self.path.to_path_buf(),
                        image: i,
                        reason: "neither uri nor bufferView".into(),
                    })
                }
            };
            encoded.push((i, img.name.clone(), bytes));
        }
        let images = encoded
            .into_par_iter()
            .map(|(i, name, bytes)| {
                let decoded = image::load_from_memory(&bytes).map_err(|e| SceneError::Image {
                    path: self.path.to_path_buf(),
                    image: i,
                    reason: e.to_string(),
                })?;
                let rgba = decoded.to_rgba8();
                Ok(Image {
                    name,
                    width: rgba.width(),
                    height: rgba.height(),
                    rgba8: rgba.into_raw(),
                })
            })
            .collect::<Result<Vec<_>, SceneError>>()?;
        Ok((textures, images))
    }

    fn meshes(&mut self) -> Result<Vec<Mesh>, SceneError> {
        let mut skipped = Vec::new();
        let mut meshes = Vec::new();
        for mesh in self.doc.meshes() {
            let mi = mesh.index();
            let mut primitives = Vec::new();
            for prim in mesh.primitives() {
                let pi = prim.index();
                let mode = prim.mode();
                if matches!(
                    mode,
                    Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip
                ) {
                    skipped.push(format!("meshes[{mi}].primitives[{pi}] ({mode:?})"));
                    continue;
                }
                primitives.push(self.primitive(&prim, mi, pi, mode)?);
            }
            meshes.push(Mesh {
                name: mesh.name().map(str::to_string),
                primitives,
                weights: mesh.weights().map(<[f32]>::to_vec).unwrap_or_default(),
            });
        }
        if !skipped.is_empty() {
            self.warn(format!(
                "skipped {} point/line primitive(s), only triangles are traced: {}",
                skipped.len(),
                skipped.join(", ")
            ));
        }
        Ok(meshes)
    }

    fn primitive(
        &mut self,
        prim: &gltf::Primitive,
        mi: usize,
        pi: usize,
        mode: Mode,
    ) -> Result<Primitive, SceneError> {
        let at = format!("meshes[{mi}].primitives[{pi}]");
        let get = |s: gltf::Semantic| prim.get(&s);
        let pos_acc = get(gltf::Semantic::Positions).ok_or_else(|| SceneError::Model {
            path: self.path.to_path_buf(),
            reason: format!("{at} has no POSITION"),
        })?;
        let positions = self.vec3s(&pos_acc, &format!("{at}.POSITION"))?;
        let nv = positions.len();
        let same_count = |this: &Self, acc: &gltf::Accessor, usage: &str| {
            if acc.count() != nv {
                Err(this.acc_err(
                    acc.index(),
                    usage,
                    format!("count {} differs from the POSITION count {nv}", acc.count()),
                ))
            } else {
                Ok(())
            }
        };
        let normals = match get(gltf::Semantic::Normals) {
            Some(acc) => {
                let usage = format!("{at}.NORMAL");
                same_count(self, &acc, &usage)?;
                Some(self.vec3s(&acc, &usage)?)
            }
            None => None,
        };
        let uvs = match get(gltf::Semantic::TexCoords(0)) {
            Some(acc) => {
                let usage = format!("{at}.TEXCOORD_0");
                same_count(self, &acc, &usage)?;
                let f = self.floats(&acc, &usage, 2, true)?;
                Some(f.chunks_exact(2).map(Vec2::from_slice).collect())
            }
            None => None,
        };

        // Skin influences, every JOINTS_n/WEIGHTS_n pair, interleaved per vertex.
        let mut sets: Vec<(Vec<u32>, Vec<f32>)> = Vec::new();
        for s in 0u32.. {
            let (Some(j), Some(w)) = (
                get(gltf::Semantic::Joints(s)),
                get(gltf::Semantic::Weights(s)),
            ) else {
                break;
            };
            let (ju, wu) = (format!("{at}.JOINTS_{s}"), format!("{at}.WEIGHTS_{s}"));
            same_count(self, &j, &ju)?;
            same_count(self, &w, &wu)?;
            let joints = self.uints(&j, &ju, 4)?;
            if let Some(big) = joints.iter().find(|&&x| x > u32::from(u16::MAX)) {
                return Err(self.acc_err(j.index(), &ju, format!("joint {big} out of range")));
            }
            sets.push((joints, self.floats(&w, &wu, 4, true)?));
        }
        let mut joints = Vec::with_capacity(nv * sets.len());
        let mut weights = Vec::with_capacity(nv * sets.len());
        for v in 0..nv {
            for (j, w) in &sets {
                let j4 = &j[v * 4..v * 4 + 4];
                joints.push([j4[0] as u16, j4[1] as u16, j4[2] as u16, j4[3] as u16]);
                weights.push([w[v * 4], w[v * 4 + 1], w[v * 4 + 2], w[v * 4 + 3]]);
            }
        }

        let indices: Vec<u32> = match prim.indices() {
            Some(acc) => {
                let usage = format!("{at}.indices");
                let idx = self.uints(&acc, &usage, 1)?;
                if let Some((k, &i)) = idx.iter().enumerate().find(|(_, &i)| i as usize >= nv) {
                    return Err(self.acc_err(
                        acc.index(),
                        &usage,
                        format!("index {i} (element {k}) is past the vertex count {nv}"),
                    ));
                }
                idx
            }
            None => (0..nv as u32).collect(),
        };
        let triangles = match mode {
            Mode::Triangles => {
                if indices.len() % 3 != 0 {
                    self.warn(format!(
                        "{at}: {} indices is not a multiple of 3; the last {} dropped",
                        indices.len(),
                        indices.len() % 3
                    ));
                }
                indices
                    .chunks_exact(3)
                    .map(|c| [c[0], c[1], c[2]])
                    .collect()
            }
            // Spec 3.7.2.1: strip triangle i is (v_i, v_{i+1+i%2}, v_{i+2-i%2}).
            Mode::TriangleStrip => (0..indices.len().saturating_sub(2))
                .map(|i| {
                    let odd = i % 2;
                    [indices[i], indices[i + 1 + odd], indices[i + 2 - odd]]
                })
                .collect(),
            // Spec: fan triangle i is (v_{i+1}, v_{i+2}, v_0).
            Mode::TriangleFan => (0..indices.len().saturating_sub(2))
                .map(|i| [indices[i + 1], indices[i + 2], indices[0]])
                .collect(),
            _ => Vec::new(),
        };

        let mut morph_targets = Vec::new();
        for (ti, target) in prim.morph_targets().enumerate() {
            let read = |acc: Option<gltf::Accessor>, what: &str| -> Result<Vec<Vec3>, SceneError> {
                match acc {
                    Some(acc) => {
                        let usage = format!("{at}.targets[{ti}].{what}");
                        same_count(self, &acc, &usage)?;
                        self.vec3s(&acc, &usage)
                    }
                    None => Ok(Vec::new()),
                }
            };
            let positions = read(target.positions(), "POSITION")?;
            let normals = read(target.normals(), "NORMAL")?;
            morph_targets.push(MorphTarget { positions, normals });
        }

        Ok(Primitive {
            positions,
            normals,
            uvs,
            triangles,
            material: prim.material().index().map_or(u32::MAX, |m| m as u32),
            joints,
            weights,
            morph_targets,
        })
    }

    fn nodes(&self) -> Result<Vec<Node>, SceneError> {
        let mut nodes: Vec<Node> = Vec::new();
        for n in self.doc.nodes() {
            let transform = match n.transform() {
                gltf::scene::Transform::Matrix { matrix } => {
                    NodeTransform::Matrix(Mat4::from_cols_array_2d(&matrix))
                }
                gltf::scene::Transform::Decomposed {
                    translation,
                    rotation,
                    scale,
                } => {
                    let q = Quat::from_array(rotation);
                    // The spec asks for a unit quaternion; tolerate rounding, refuse zero.
                    if q.length().is_nan() || q.length() <= 1e-3 {
                        return Err(SceneError::Node {
                            path: self.path.to_path_buf(),
                            node: n.index(),
                            name: n.name().map(str::to_string),
                            reason: format!("rotation {rotation:?} is not a unit quaternion"),
                        });
                    }
                    NodeTransform::Trs(Trs {
                        translation: Vec3::from_array(translation),
                        rotation: q.normalize(),
                        scale: Vec3::from_array(scale),
                    })
                }
            };
            nodes.push(Node {
                name: n.name().map(str::to_string),
                parent: None,
                children: n.children().map(|c| c.index()).collect(),
                transform,
                mesh: n.mesh().map(|m| m.index()),
                skin: n.skin().map(|s| s.index()),
                camera: n.camera().map(|c| c.index()),
                // From the JSON: the wrapper unwraps an index the validation may not cover.
                light: self.doc.as_json().nodes.get(n.index()).and_then(|j| {
                    let ext = j.extensions.as_ref()?.khr_lights_punctual.as_ref()?;
                    Some(ext.light.value())
                }),
                weights: n.weights().map(<[f32]>::to_vec),
            });
        }
        for p in 0..nodes.len() {
            for k in 0..nodes[p].children.len() {
                let c = nodes[p].children[k];
                let Some(child) = nodes.get_mut(c) else {
                    continue; // validated
                };
                if let Some(other) = child.parent {
                    return Err(SceneError::Node {
                        path: self.path.to_path_buf(),
                        node: c,
                        name: child.name.clone(),
                        reason: format!("is a child of both node {other} and node {p}"),
                    });
                }
                child.parent = Some(p);
            }
        }
        Ok(nodes)
    }

    fn skins(&self) -> Result<Vec<Skin>, SceneError> {
        let mut out = Vec::new();
        for s in self.doc.skins() {
            let joints: Vec<usize> = s.joints().map(|j| j.index()).collect();
            let inverse_bind_matrices = match s.inverse_bind_matrices() {
                Some(acc) => {
                    let usage = format!("skins[{}].inverseBindMatrices", s.index());
                    let f = self.floats(&acc, &usage, 16, false)?;
                    if f.len() / 16 < joints.len() {
                        return Err(self.acc_err(
                            acc.index(),
                            &usage,
                            format!("{} matrices for {} joints", f.len() / 16, joints.len()),
                        ));
                    }
                    f.chunks_exact(16)
                        .take(joints.len())
                        .map(Mat4::from_cols_slice)
                        .collect()
                }
                None => vec![Mat4::IDENTITY; joints.len()],
            };
            out.push(Skin {
                name: s.name().map(str::to_string),
                joints,
                inverse_bind_matrices,
            });
        }
        Ok(out)
    }

    fn lights(&self) -> Vec<LightDef> {
        let Some(lights) = self.doc.lights() else {
            return Vec::new();
        };
        lights
            .map(|l| LightDef {
                name: l.name().map(str::to_string),
                kind: match l.kind() {
                    gltf::khr_lights_punctual::Kind::Point => LightKind::Point,
                    gltf::khr_lights_punctual::Kind::Directional => LightKind::Directional,
                    gltf::khr_lights_punctual::Kind::Spot {
                        inner_cone_angle,
                        outer_cone_angle,
                    } => LightKind::Spot {
                        inner_cone_angle,
                        outer_cone_angle,
                    },
                },
                color: Vec3::from_array(l.color()),
                intensity: l.intensity(),
                range: l.range(),
            })
            .collect()
    }

    /// Read from the JSON rather than the `gltf` wrappers: the crate's validation does not
    /// check channel targets, and its accessors unwrap them.
    fn animations(&self) -> Result<Vec<Animation>, SceneError> {
        use gltf::json::validation::Checked;
        let json = self.doc.as_json();
        let mut out = Vec::new();
        for (ai, a) in json.animations.iter().enumerate() {
            let mut channels = Vec::new();
            for (ci, ch) in a.channels.iter().enumerate() {
                let err = |reason: String| SceneError::Animation {
                    path: self.path.to_path_buf(),
                    animation: ai,
                    channel: ci,
                    reason,
                };
                let sampler = a
                    .samplers
                    .get(ch.sampler.value())
                    .ok_or_else(|| err(format!("sampler {} missing", ch.sampler.value())))?;
                let accessor = |i: usize| {
                    self.doc
                        .accessors()
                        .nth(i)
                        .ok_or_else(|| err(format!("accessor {i} missing")))
                };
                let (input, output) = (
                    accessor(sampler.input.value())?,
                    accessor(sampler.output.value())?,
                );
                let at = format!("animations[{ai}].channels[{ci}]");
                let times = self.floats(&input, &format!("{at} input"), 1, false)?;
                let comps = output.dimensions().multiplicity();
                let values = self.floats(&output, &format!("{at} output"), comps, true)?;
                use gltf::json::animation::{Interpolation as I, Property as P};
                let property = match ch.target.path {
                    Checked::Valid(P::Translation) => Property::Translation,
                    Checked::Valid(P::Rotation) => Property::Rotation,
                    Checked::Valid(P::Scale) => Property::Scale,
                    Checked::Valid(P::MorphTargetWeights) => Property::Weights,
                    Checked::Invalid => return Err(err("unknown target path".into())),
                };
                let interpolation = match sampler.interpolation {
                    Checked::Valid(I::Step) => Interpolation::Step,
                    Checked::Valid(I::Linear) => Interpolation::Linear,
                    Checked::Valid(I::CubicSpline) => Interpolation::CubicSpline,
                    Checked::Invalid => return Err(err("unknown interpolation".into())),
                };
                channels.push(Channel {
                    // Range-checked by Scene::validate.
                    node: ch.target.node.value(),
                    property,
                    interpolation,
                    times,
                    values,
                });
            }
            out.push(Animation {
                name: a.name.clone(),
                channels,
            });
        }
        Ok(out)
    }
}

/// One little-endian component as an exact number.
fn component(b: &[u8], t: DataType) -> f64 {
    match (t, b) {
        (DataType::I8, [x]) => f64::from(*x as i8),
        (DataType::U8, [x]) => f64::from(*x),
        (DataType::I16, [a, b]) => f64::from(i16::from_le_bytes([*a, *b])),
        (DataType::U16, [a, b]) => f64::from(u16::from_le_bytes([*a, *b])),
        (DataType::U32, [a, b, c, d]) => f64::from(u32::from_le_bytes([*a, *b, *c, *d])),
        (DataType::F32, [a, b, c, d]) => f64::from(f32::from_le_bytes([*a, *b, *c, *d])),
        _ => f64::NAN, // sizes come from the type itself: unreachable
    }
}

/// `%XX` escapes decoded; malformed escapes kept as they are.
fn percent_decode(s: &str) -> Vec<u8> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            let hex = |c: u8| (c as char).to_digit(16);
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    out
}

/// Standard or URL-safe base64, padding optional.
fn decode_base64(s: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(s.len() / 4 * 3 + 3);
    let mut acc: u32 = 0;
    let mut bits = 0u32;
    for (i, c) in s.bytes().enumerate() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            _ => return Err(format!("invalid character {:?} at {i}", c as char)),
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_known_vectors() {
        assert_eq!(decode_base64("").unwrap(), b"");
        assert_eq!(decode_base64("Zg==").unwrap(), b"f");
        assert_eq!(decode_base64("Zm8=").unwrap(), b"fo");
        assert_eq!(decode_base64("Zm9v").unwrap(), b"foo");
        assert_eq!(decode_base64("Zm9vYmFy").unwrap(), b"foobar");
        assert_eq!(decode_base64("Zm9vYg").unwrap(), b"foob");
        assert!(decode_base64("Zm9v!").is_err());
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("a%20b.bin"), b"a b.bin");
        assert_eq!(percent_decode("100%"), b"100%");
        assert_eq!(percent_decode("%4"), b"%4");
        assert_eq!(percent_decode("%zz"), b"%zz");
    }

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
