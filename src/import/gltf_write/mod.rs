//! A glTF 2.0 writer for scenes built in code (the `convert` command, and tests that
//! build their scenes instead of shipping files).
//!
//! The JSON is written with `serde_json` directly: the subset we emit is small, and every
//! file is checked by the importer in the round-trip tests (which runs the `gltf` crate's
//! validation). The writer refuses inconsistent input (an index out of range, a length
//! mismatch, a non-finite number) rather than write a file the importer would reject.
//! Files are written atomically: a temporary file in the same folder, fsync, rename.

use std::path::Path;

use glam::{Quat, Vec2, Vec3, Vec4};
use serde_json::{json, Map, Value};

mod check;
mod document;

use super::ImportError;
use crate::scene::{Interpolation, LightDef, Property};

/// A metallic-roughness material: factors, and optionally a base colour texture.
#[derive(Clone, Debug, PartialEq)]
pub struct MaterialDesc {
    pub name: Option<String>,
    pub base_color: Vec4,
    /// Index into [`GltfBuilder::textures`], read with `TEXCOORD_0`.
    pub base_color_texture: Option<u32>,
    pub metallic: f32,
    pub roughness: f32,
    /// Linear emitted colour; components above 1 are carried by
    /// `KHR_materials_emissive_strength` (the factor itself must stay in `[0, 1]`).
    pub emissive: Vec3,
    pub transmission: f32,
    pub ior: f32,
    pub double_sided: bool,
    /// Written as the material's `extras` (an object) when present.
    pub extras: Option<Value>,
}

impl Default for MaterialDesc {
    fn default() -> Self {
        MaterialDesc {
            name: None,
            base_color: Vec4::ONE,
            base_color_texture: None,
            metallic: 0.0,
            roughness: 1.0,
            emissive: Vec3::ZERO,
            transmission: 0.0,
            ior: 1.5,
            double_sided: false,
            extras: None,
        }
    }
}

/// An encoded image embedded in the buffer (PNG or JPEG bytes, as glTF allows).
#[derive(Clone, Debug, PartialEq)]
pub struct ImageDesc {
    pub name: Option<String>,
    /// `"image/png"` or `"image/jpeg"`.
    pub mime_type: String,
    pub bytes: Vec<u8>,
}

/// A texture: an image sampled with the default sampler (linear, repeat).
#[derive(Clone, Debug, PartialEq)]
pub struct TextureDesc {
    /// Index into [`GltfBuilder::images`].
    pub image: u32,
}

/// Triangles (mode TRIANGLES) with optional attributes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PrimitiveDesc {
    pub positions: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
    pub uvs: Option<Vec<Vec2>>,
    /// Three per triangle; `None` means consecutive vertices form triangles.
    pub indices: Option<Vec<u32>>,
    pub material: Option<u32>,
    /// Morph targets as POSITION displacements, one per vertex each.
    pub morph_targets: Vec<Vec<Vec3>>,
    /// NORMAL displacements of the morph targets: empty, or one list per target.
    pub morph_normals: Vec<Vec<Vec3>>,
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshDesc {
    pub name: Option<String>,
    pub primitives: Vec<PrimitiveDesc>,
    /// Default morph weights (one per target, or empty).
    pub weights: Vec<f32>,
}

/// A perspective camera.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraDesc {
    pub name: Option<String>,
    /// Radians.
    pub yfov: f32,
    pub aspect: Option<f32>,
    pub znear: f32,
    pub zfar: Option<f32>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct NodeDesc {
    pub name: Option<String>,
    pub translation: Vec3,
    pub rotation: Quat,
    pub scale: Vec3,
    pub children: Vec<u32>,
    pub mesh: Option<u32>,
    pub camera: Option<u32>,
    pub light: Option<u32>,
    pub weights: Option<Vec<f32>>,
}

impl Default for NodeDesc {
    fn default() -> Self {
        NodeDesc {
            name: None,
            translation: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
            children: Vec::new(),
            mesh: None,
            camera: None,
            light: None,
            weights: None,
        }
    }
}

/// One animated property. `values` is laid out as in [`super::Channel`].
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelDesc {
    pub node: u32,
    pub property: Property,
    pub interpolation: Interpolation,
    pub times: Vec<f32>,
    pub values: Vec<f32>,
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct AnimationDesc {
    pub name: Option<String>,
    pub channels: Vec<ChannelDesc>,
}

/// Collects a scene and writes it as `.glb` or `.gltf`.
#[derive(Clone, Debug, Default)]
pub struct GltfBuilder {
    pub materials: Vec<MaterialDesc>,
    pub meshes: Vec<MeshDesc>,
    pub cameras: Vec<CameraDesc>,
    pub lights: Vec<LightDef>,
    pub nodes: Vec<NodeDesc>,
    pub roots: Vec<u32>,
    pub animations: Vec<AnimationDesc>,
    pub images: Vec<ImageDesc>,
    pub textures: Vec<TextureDesc>,
    /// Written as `scenes[0].extras.fps`.
    pub fps: Option<f32>,
    /// Further members of `scenes[0].extras` (`fps` is set from [`GltfBuilder::fps`]).
    pub scene_extras: Map<String, Value>,
}

fn push<T>(v: &mut Vec<T>, x: T) -> u32 {
    v.push(x);
    (v.len() - 1) as u32
}

impl GltfBuilder {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn add_material(&mut self, m: MaterialDesc) -> u32 {
        push(&mut self.materials, m)
    }
    pub fn add_mesh(&mut self, m: MeshDesc) -> u32 {
        push(&mut self.meshes, m)
    }
    pub fn add_camera(&mut self, c: CameraDesc) -> u32 {
        push(&mut self.cameras, c)
    }
    pub fn add_light(&mut self, l: LightDef) -> u32 {
        push(&mut self.lights, l)
    }
    pub fn add_node(&mut self, n: NodeDesc) -> u32 {
        push(&mut self.nodes, n)
    }
    /// Adds `node` to the roots of the (single) scene.
    pub fn add_root(&mut self, node: u32) {
        self.roots.push(node);
    }
    pub fn add_animation(&mut self, a: AnimationDesc) -> u32 {
        push(&mut self.animations, a)
    }
    pub fn add_image(&mut self, i: ImageDesc) -> u32 {
        push(&mut self.images, i)
    }
    pub fn add_texture(&mut self, t: TextureDesc) -> u32 {
        push(&mut self.textures, t)
    }

    /// Writes `path` atomically: JSON with an embedded data-URI buffer when the
    /// extension is `.gltf`, GLB otherwise.
    pub fn write(&self, path: &Path) -> Result<(), ImportError> {
        let gltf = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("gltf"));
        let bytes = if gltf {
            self.to_gltf_json()?.into_bytes()
        } else {
            self.to_glb()?
        };
        write_atomically(path, &bytes)
    }

    /// The scene as a GLB container.
    pub fn to_glb(&self) -> Result<Vec<u8>, ImportError> {
        let (mut root, bin) = self.document()?;
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

    /// The scene as glTF JSON, its buffer embedded as a base64 data URI.
    pub fn to_gltf_json(&self) -> Result<String, ImportError> {
        let (mut root, bin) = self.document()?;
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
        let mut b = GltfBuilder::new();
        b.add_mesh(MeshDesc {
            primitives: vec![PrimitiveDesc {
                positions: vec![Vec3::ZERO; 3],
                indices: Some(vec![0, 1, 3]),
                ..Default::default()
            }],
            ..Default::default()
        });
        let e = b.to_glb().unwrap_err().to_string();
        assert!(e.contains("index 3 past the vertex count 3"), "{e}");
        let mut b = GltfBuilder::new();
        let n = b.add_node(NodeDesc::default());
        b.nodes[0].children.push(n); // its own child
        b.add_root(n);
        assert!(b.to_glb().is_err());
    }
}
