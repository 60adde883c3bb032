//! The glTF 2.0 JSON as the specification allows it: every property the schema makes
//! optional is an `Option` (or has its schema default), unknown properties, `extras` and
//! unknown extensions are skipped. Properties the schema requires are `Option` too, so
//! that [`super::check`] can name the object that lacks one (`accessors[3]: no count`)
//! rather than serde's line and column.
//!
//! Enumerations (component types, modes, paths, alpha modes...) stay raw numbers and
//! strings here; `check` refuses the values the specification does not define, and the
//! readers map them.

use std::collections::BTreeMap;

use serde::Deserialize;

/// An index into one of the root's arrays (range-checked by `check`).
pub(super) type Index = usize;

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Root {
    pub asset: Option<Asset>,
    pub extensions_used: Vec<String>,
    pub extensions_required: Vec<String>,
    pub accessors: Vec<Accessor>,
    pub animations: Vec<Animation>,
    pub buffers: Vec<Buffer>,
    pub buffer_views: Vec<BufferView>,
    pub cameras: Vec<Camera>,
    pub images: Vec<Image>,
    pub materials: Vec<Material>,
    pub meshes: Vec<Mesh>,
    pub nodes: Vec<Node>,
    pub samplers: Vec<Sampler>,
    pub scene: Option<Index>,
    pub scenes: Vec<Scene>,
    pub skins: Vec<Skin>,
    pub textures: Vec<Texture>,
    pub extensions: Option<RootExtensions>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Asset {
    pub version: Option<String>,
    pub min_version: Option<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct RootExtensions {
    #[serde(rename = "KHR_lights_punctual")]
    pub lights_punctual: Option<LightsPunctual>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct LightsPunctual {
    pub lights: Vec<Light>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Accessor {
    pub buffer_view: Option<Index>,
    pub byte_offset: usize,
    pub component_type: Option<u32>,
    pub normalized: bool,
    pub count: Option<usize>,
    #[serde(rename = "type")]
    pub type_: Option<String>,
    pub sparse: Option<Sparse>,
    pub name: Option<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Sparse {
    pub count: Option<usize>,
    pub indices: Option<SparseIndices>,
    pub values: Option<SparseValues>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct SparseIndices {
    pub buffer_view: Option<Index>,
    pub byte_offset: usize,
    pub component_type: Option<u32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct SparseValues {
    pub buffer_view: Option<Index>,
    pub byte_offset: usize,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Buffer {
    pub uri: Option<String>,
    pub byte_length: Option<usize>,
    pub extensions: Option<BufferExtensions>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct BufferExtensions {
    #[serde(rename = "EXT_meshopt_compression")]
    pub ext_meshopt: Option<MeshoptBuffer>,
    #[serde(rename = "KHR_meshopt_compression")]
    pub khr_meshopt: Option<MeshoptBuffer>,
}

/// A buffer's meshopt extension: `fallback` marks a buffer only compressed views
/// reference, which a decoder need not load (it may have no data at all).
#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct MeshoptBuffer {
    pub fallback: bool,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct BufferView {
    pub buffer: Option<Index>,
    pub byte_offset: usize,
    pub byte_length: Option<usize>,
    pub byte_stride: Option<usize>,
    pub extensions: Option<BufferViewExtensions>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct BufferViewExtensions {
    #[serde(rename = "EXT_meshopt_compression")]
    pub ext_meshopt: Option<Meshopt>,
    #[serde(rename = "KHR_meshopt_compression")]
    pub khr_meshopt: Option<Meshopt>,
}

/// A compressed buffer view (`EXT_meshopt_compression` / `KHR_meshopt_compression`): the
/// view's bytes are `count * byteStride` bytes decoded from
/// `buffer[byteOffset..+byteLength]` by `mode`, then `filter` (see `meshopt`).
#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Meshopt {
    pub buffer: Option<Index>,
    pub byte_offset: usize,
    pub byte_length: Option<usize>,
    pub byte_stride: Option<usize>,
    pub count: Option<usize>,
    pub mode: Option<String>,
    pub filter: Option<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Image {
    pub uri: Option<String>,
    pub buffer_view: Option<Index>,
    pub name: Option<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Sampler {
    pub mag_filter: Option<u32>,
    pub min_filter: Option<u32>,
    pub wrap_s: Option<u32>,
    pub wrap_t: Option<u32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Texture {
    pub sampler: Option<Index>,
    pub source: Option<Index>,
    pub extensions: Option<TextureExtensions>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct TextureExtensions {
    #[serde(rename = "EXT_texture_webp")]
    pub webp: Option<ImageSource>,
    #[serde(rename = "KHR_texture_basisu")]
    pub basisu: Option<ImageSource>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct ImageSource {
    pub source: Option<Index>,
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Material {
    pub name: Option<String>,
    pub pbr_metallic_roughness: Option<Pbr>,
    pub emissive_texture: Option<TextureInfo>,
    pub normal_texture: Option<TextureInfo>,
    pub occlusion_texture: Option<TextureInfo>,
    pub emissive_factor: [f32; 3],
    pub alpha_mode: Option<String>,
    pub alpha_cutoff: Option<f32>,
    pub double_sided: bool,
    pub extensions: Option<MaterialExtensions>,
    pub extras: Option<serde_json::Value>,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: None,
            pbr_metallic_roughness: None,
            emissive_texture: None,
            normal_texture: None,
            occlusion_texture: None,
            emissive_factor: [0.0; 3],
            alpha_mode: None,
            alpha_cutoff: None,
            double_sided: false,
            extensions: None,
            extras: None,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Pbr {
    pub base_color_factor: [f32; 4],
    pub base_color_texture: Option<TextureInfo>,
    pub metallic_factor: f32,
    pub roughness_factor: f32,
    pub metallic_roughness_texture: Option<TextureInfo>,
}

impl Default for Pbr {
    fn default() -> Self {
        Pbr {
            base_color_factor: [1.0; 4],
            base_color_texture: None,
            metallic_factor: 1.0,
            roughness_factor: 1.0,
            metallic_roughness_texture: None,
        }
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct MaterialExtensions {
    #[serde(rename = "KHR_materials_emissive_strength")]
    pub emissive_strength: Option<EmissiveStrength>,
    #[serde(rename = "KHR_materials_transmission")]
    pub transmission: Option<Transmission>,
    #[serde(rename = "KHR_materials_ior")]
    pub ior: Option<Ior>,
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct EmissiveStrength {
    pub emissive_strength: f32,
}

impl Default for EmissiveStrength {
    fn default() -> Self {
        EmissiveStrength {
            emissive_strength: 1.0,
        }
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Transmission {
    pub transmission_factor: f32,
    pub transmission_texture: Option<TextureInfo>,
}

#[derive(Debug, Deserialize)]
#[serde(default)]
pub(super) struct Ior {
    pub ior: f32,
}

impl Default for Ior {
    fn default() -> Self {
        Ior { ior: 1.5 }
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct TextureInfo {
    pub index: Option<Index>,
    pub tex_coord: u32,
    /// `normalTexture.scale` (only a normal texture info has it).
    pub scale: Option<f32>,
    pub extensions: Option<TextureInfoExtensions>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct TextureInfoExtensions {
    #[serde(rename = "KHR_texture_transform")]
    pub transform: Option<TextureTransform>,
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct TextureTransform {
    pub offset: [f32; 2],
    pub rotation: f32,
    pub scale: [f32; 2],
    pub tex_coord: Option<u32>,
}

impl Default for TextureTransform {
    fn default() -> Self {
        TextureTransform {
            offset: [0.0; 2],
            rotation: 0.0,
            scale: [1.0; 2],
            tex_coord: None,
        }
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct Mesh {
    pub name: Option<String>,
    pub primitives: Option<Vec<Primitive>>,
    pub weights: Option<Vec<f32>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct Primitive {
    pub attributes: Option<BTreeMap<String, Index>>,
    pub indices: Option<Index>,
    pub material: Option<Index>,
    pub mode: Option<u32>,
    pub targets: Vec<BTreeMap<String, Index>>,
    pub extensions: Option<PrimitiveExtensions>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct PrimitiveExtensions {
    #[serde(rename = "KHR_draco_mesh_compression")]
    pub draco: Option<serde_json::Value>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct Node {
    pub name: Option<String>,
    pub children: Vec<Index>,
    pub mesh: Option<Index>,
    pub skin: Option<Index>,
    pub camera: Option<Index>,
    pub matrix: Option<[f32; 16]>,
    pub translation: Option<[f32; 3]>,
    pub rotation: Option<[f32; 4]>,
    pub scale: Option<[f32; 3]>,
    pub weights: Option<Vec<f32>>,
    pub extensions: Option<NodeExtensions>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct NodeExtensions {
    #[serde(rename = "KHR_lights_punctual")]
    pub light: Option<NodeLight>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct NodeLight {
    pub light: Option<Index>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct Scene {
    pub name: Option<String>,
    pub nodes: Vec<Index>,
    pub extras: Option<serde_json::Value>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Skin {
    pub name: Option<String>,
    pub joints: Option<Vec<Index>>,
    pub inverse_bind_matrices: Option<Index>,
    pub skeleton: Option<Index>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct Camera {
    pub name: Option<String>,
    #[serde(rename = "type")]
    pub type_: Option<String>,
    pub perspective: Option<Perspective>,
    pub orthographic: Option<Orthographic>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Perspective {
    pub yfov: Option<f32>,
    pub aspect_ratio: Option<f32>,
    pub znear: Option<f32>,
    pub zfar: Option<f32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct Orthographic {
    pub xmag: Option<f32>,
    pub ymag: Option<f32>,
    pub znear: Option<f32>,
    pub zfar: Option<f32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct Animation {
    pub name: Option<String>,
    pub channels: Option<Vec<Channel>>,
    pub samplers: Option<Vec<AnimationSampler>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct Channel {
    pub sampler: Option<Index>,
    pub target: Option<Target>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct Target {
    pub node: Option<Index>,
    pub path: Option<String>,
    pub extensions: Option<TargetExtensions>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct TargetExtensions {
    #[serde(rename = "KHR_animation_pointer")]
    pub pointer: Option<AnimationPointer>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct AnimationPointer {
    pub pointer: Option<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct AnimationSampler {
    pub input: Option<Index>,
    pub output: Option<Index>,
    pub interpolation: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(default)]
pub(super) struct Light {
    pub name: Option<String>,
    #[serde(rename = "type")]
    pub type_: Option<String>,
    pub color: [f32; 3],
    /// Candela (point, spot) or lux (directional). Read as f64: the writer's
    /// `intensity × 683` of an f32 is exact in f64, so dividing it back gives the f32.
    pub intensity: f64,
    pub range: Option<f32>,
    pub spot: Option<Spot>,
    pub extras: Option<serde_json::Value>,
}

impl Default for Light {
    fn default() -> Self {
        Light {
            name: None,
            type_: None,
            color: [1.0; 3],
            intensity: 1.0,
            range: None,
            spot: None,
            extras: None,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Spot {
    pub inner_cone_angle: f32,
    pub outer_cone_angle: f32,
}

impl Default for Spot {
    fn default() -> Self {
        Spot {
            inner_cone_angle: 0.0,
            outer_cone_angle: std::f32::consts::FRAC_PI_4,
        }
    }
}

/// Component types (spec 3.6.2.2), with their size in bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ComponentType {
    I8,
    U8,
    I16,
    U16,
    U32,
    F32,
}

impl ComponentType {
    pub(super) fn from_code(code: u32) -> Option<ComponentType> {
        Some(match code {
            5120 => ComponentType::I8,
            5121 => ComponentType::U8,
            5122 => ComponentType::I16,
            5123 => ComponentType::U16,
            5125 => ComponentType::U32,
            5126 => ComponentType::F32,
            _ => return None,
        })
    }

    pub(super) fn size(self) -> usize {
        match self {
            ComponentType::I8 | ComponentType::U8 => 1,
            ComponentType::I16 | ComponentType::U16 => 2,
            ComponentType::U32 | ComponentType::F32 => 4,
        }
    }
}

/// Components per element of an accessor `type`, `None` for an unknown type.
pub(super) fn type_components(t: &str) -> Option<usize> {
    Some(match t {
        "SCALAR" => 1,
        "VEC2" => 2,
        "VEC3" => 3,
        "VEC4" => 4,
        "MAT2" => 4,
        "MAT3" => 9,
        "MAT4" => 16,
        _ => return None,
    })
}
