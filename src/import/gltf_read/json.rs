//! The glTF 2.0 JSON as the specification allows it: every property the schema makes
//! optional is an `Option` (or has its schema default), unknown properties, `extras` and
//! unknown extensions are skipped. Properties the schema requires are `Option` too, so
//! that [`super::check`] can name the object that lacks one (`accessors[3]: no count`)
//! rather than serde's line and column.
//!
//! Enumerations (component types, modes, paths, alpha modes...) stay raw numbers and
//! strings here; `check` refuses the values the specification does not define, and the
//! readers map them.
//!
//! Every property the schema types `integer` is read through [`int`]: JSON has one
//! number type, so `1.0`, `1e0` or `-0.0` is that integer (the Khronos validator accepts
//! them too); a fraction or a value out of range is refused, and [`parse`] names the
//! property (`accessors[0].count: invalid value: floating point `1.5`, ...`).

use std::collections::BTreeMap;
use std::fmt;
use std::marker::PhantomData;

use serde::de::{Deserializer, Error, Unexpected, Visitor};
use serde::Deserialize;

/// The document, or why it is not one, with the JSON path of the property at fault
/// (`accessors[0].count: ...`) ahead of serde's message, line and column.
pub(super) fn parse(bytes: &[u8]) -> Result<Root, String> {
    serde_json::from_slice(bytes).map_err(|e| {
        // Tracking the path takes up to twice the time of the parse (1.4-1.9x measured
        // on 66 MB of JSON: 300,000 accessors and a data URI), so only a failed parse
        // pays for it: the same bytes fail the same way, now with the path.
        let mut de = serde_json::Deserializer::from_slice(bytes);
        match serde_path_to_error::deserialize::<_, Root>(&mut de) {
            Err(p) if p.path().iter().next().is_some() => format!("{}: {e}", p.path()),
            _ => e.to_string(),
        }
    })
}

/// An integer property as JSON may write it: `1`, `1.0`, `1e0` (`-0.0` is 0). See [`int`].
struct Int<T>(T);

/// The unsigned types the model keeps integers in.
trait Unsigned: TryFrom<u64> {
    const MAX: u64;
}

impl Unsigned for u32 {
    const MAX: u64 = u32::MAX as u64;
}

impl Unsigned for usize {
    const MAX: u64 = usize::MAX as u64;
}

impl<'de, T: Unsigned> Deserialize<'de> for Int<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Whole<T>(PhantomData<T>);

        impl<T: Unsigned> Visitor<'_> for Whole<T> {
            type Value = Int<T>;

            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                write!(f, "a whole number from 0 to {}", T::MAX)
            }

            fn visit_u64<E: Error>(self, v: u64) -> Result<Int<T>, E> {
                T::try_from(v)
                    .map(Int)
                    .map_err(|_| E::invalid_value(Unexpected::Unsigned(v), &self))
            }

            fn visit_i64<E: Error>(self, v: i64) -> Result<Int<T>, E> {
                match u64::try_from(v) {
                    Ok(v) => self.visit_u64(v),
                    Err(_) => Err(E::invalid_value(Unexpected::Signed(v), &self)),
                }
            }

            fn visit_f64<E: Error>(self, v: f64) -> Result<Int<T>, E> {
                // 2^64 is exact in f64; every whole f64 below it is exact in u64.
                let whole = v.fract() == 0.0 && (0.0..18_446_744_073_709_551_616.0).contains(&v);
                whole
                    .then(|| T::try_from(v as u64).ok())
                    .flatten()
                    .map(Int)
                    .ok_or_else(|| E::invalid_value(Unexpected::Float(v), &self))
            }
        }

        d.deserialize_any(Whole(PhantomData))
    }
}

/// A model type made of integers ([`Int`] on the wire), bare or in the containers the
/// model keeps them in.
trait Integers: Sized {
    type Wire;
    fn from_wire(wire: Self::Wire) -> Self;
}

impl Integers for u32 {
    type Wire = Int<u32>;
    fn from_wire(wire: Int<u32>) -> u32 {
        wire.0
    }
}

impl Integers for usize {
    type Wire = Int<usize>;
    fn from_wire(wire: Int<usize>) -> usize {
        wire.0
    }
}

impl<T: Integers> Integers for Option<T> {
    type Wire = Option<T::Wire>;
    fn from_wire(wire: Self::Wire) -> Self {
        wire.map(T::from_wire)
    }
}

impl<T: Integers> Integers for Vec<T> {
    type Wire = Vec<T::Wire>;
    fn from_wire(wire: Self::Wire) -> Self {
        wire.into_iter().map(T::from_wire).collect()
    }
}

impl<T: Integers> Integers for BTreeMap<String, T> {
    type Wire = BTreeMap<String, T::Wire>;
    fn from_wire(wire: Self::Wire) -> Self {
        wire.into_iter()
            .map(|(k, v)| (k, T::from_wire(v)))
            .collect()
    }
}

/// `#[serde(deserialize_with = "int")]`: every property the schema types `integer` (and
/// arrays and maps of them), read leniently as [`Int`] says.
fn int<'de, D, T>(d: D) -> Result<T, D::Error>
where
    D: Deserializer<'de>,
    T: Integers,
    T::Wire: Deserialize<'de>,
{
    T::Wire::deserialize(d).map(T::from_wire)
}

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
    #[serde(deserialize_with = "int")]
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
    #[serde(deserialize_with = "int")]
    pub buffer_view: Option<Index>,
    #[serde(deserialize_with = "int")]
    pub byte_offset: usize,
    #[serde(deserialize_with = "int")]
    pub component_type: Option<u32>,
    pub normalized: bool,
    #[serde(deserialize_with = "int")]
    pub count: Option<usize>,
    #[serde(rename = "type")]
    pub type_: Option<String>,
    pub sparse: Option<Sparse>,
    pub name: Option<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Sparse {
    #[serde(deserialize_with = "int")]
    pub count: Option<usize>,
    pub indices: Option<SparseIndices>,
    pub values: Option<SparseValues>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct SparseIndices {
    #[serde(deserialize_with = "int")]
    pub buffer_view: Option<Index>,
    #[serde(deserialize_with = "int")]
    pub byte_offset: usize,
    #[serde(deserialize_with = "int")]
    pub component_type: Option<u32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct SparseValues {
    #[serde(deserialize_with = "int")]
    pub buffer_view: Option<Index>,
    #[serde(deserialize_with = "int")]
    pub byte_offset: usize,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Buffer {
    pub uri: Option<String>,
    #[serde(deserialize_with = "int")]
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
    #[serde(deserialize_with = "int")]
    pub buffer: Option<Index>,
    #[serde(deserialize_with = "int")]
    pub byte_offset: usize,
    #[serde(deserialize_with = "int")]
    pub byte_length: Option<usize>,
    #[serde(deserialize_with = "int")]
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
    #[serde(deserialize_with = "int")]
    pub buffer: Option<Index>,
    #[serde(deserialize_with = "int")]
    pub byte_offset: usize,
    #[serde(deserialize_with = "int")]
    pub byte_length: Option<usize>,
    #[serde(deserialize_with = "int")]
    pub byte_stride: Option<usize>,
    #[serde(deserialize_with = "int")]
    pub count: Option<usize>,
    pub mode: Option<String>,
    pub filter: Option<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Image {
    pub uri: Option<String>,
    #[serde(deserialize_with = "int")]
    pub buffer_view: Option<Index>,
    pub name: Option<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Sampler {
    #[serde(deserialize_with = "int")]
    pub mag_filter: Option<u32>,
    #[serde(deserialize_with = "int")]
    pub min_filter: Option<u32>,
    #[serde(deserialize_with = "int")]
    pub wrap_s: Option<u32>,
    #[serde(deserialize_with = "int")]
    pub wrap_t: Option<u32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Texture {
    #[serde(deserialize_with = "int")]
    pub sampler: Option<Index>,
    #[serde(deserialize_with = "int")]
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
    #[serde(deserialize_with = "int")]
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
    #[serde(deserialize_with = "int")]
    pub index: Option<Index>,
    #[serde(deserialize_with = "int")]
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
    #[serde(deserialize_with = "int")]
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
    #[serde(deserialize_with = "int")]
    pub attributes: Option<BTreeMap<String, Index>>,
    #[serde(deserialize_with = "int")]
    pub indices: Option<Index>,
    #[serde(deserialize_with = "int")]
    pub material: Option<Index>,
    #[serde(deserialize_with = "int")]
    pub mode: Option<u32>,
    #[serde(deserialize_with = "int")]
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
    #[serde(deserialize_with = "int")]
    pub children: Vec<Index>,
    #[serde(deserialize_with = "int")]
    pub mesh: Option<Index>,
    #[serde(deserialize_with = "int")]
    pub skin: Option<Index>,
    #[serde(deserialize_with = "int")]
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
    #[serde(deserialize_with = "int")]
    pub light: Option<Index>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct Scene {
    pub name: Option<String>,
    #[serde(deserialize_with = "int")]
    pub nodes: Vec<Index>,
    pub extras: Option<serde_json::Value>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(rename_all = "camelCase", default)]
pub(super) struct Skin {
    pub name: Option<String>,
    #[serde(deserialize_with = "int")]
    pub joints: Option<Vec<Index>>,
    #[serde(deserialize_with = "int")]
    pub inverse_bind_matrices: Option<Index>,
    #[serde(deserialize_with = "int")]
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
    #[serde(deserialize_with = "int")]
    pub sampler: Option<Index>,
    pub target: Option<Target>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub(super) struct Target {
    #[serde(deserialize_with = "int")]
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
    #[serde(deserialize_with = "int")]
    pub input: Option<Index>,
    #[serde(deserialize_with = "int")]
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

#[cfg(test)]
mod tests {
    use super::*;

    fn accessor(json: &str) -> Result<Accessor, String> {
        serde_json::from_str(json).map_err(|e| e.to_string())
    }

    #[test]
    fn integers_may_be_whole_floats() {
        for text in ["4", "4.0", "4e0", "0.4e1", "400e-2"] {
            let a = accessor(&format!(r#"{{"count": {text}, "componentType": {text}}}"#))
                .unwrap_or_else(|e| panic!("{text}: {e}"));
            assert_eq!((a.count, a.component_type), (Some(4), Some(4)), "{text}");
        }
        let a = accessor(r#"{"byteOffset": -0.0, "bufferView": 1e1}"#).unwrap();
        assert_eq!((a.byte_offset, a.buffer_view), (0, Some(10)));
        // Absent and null keep the schema's default and `None`.
        let a = accessor(r#"{"bufferView": null}"#).unwrap();
        assert_eq!((a.byte_offset, a.buffer_view, a.count), (0, None, None));
        // In arrays and maps too.
        let p: Primitive = serde_json::from_str(
            r#"{"attributes": {"POSITION": 2.0}, "targets": [{"NORMAL": 3.0}]}"#,
        )
        .unwrap();
        assert_eq!(p.attributes.unwrap()["POSITION"], 2);
        assert_eq!(p.targets[0]["NORMAL"], 3);
        let n: Node = serde_json::from_str(r#"{"children": [1.0, 2, 3e0]}"#).unwrap();
        assert_eq!(n.children, vec![1, 2, 3]);
    }

    #[test]
    fn fractions_negatives_and_overflow_are_refused() {
        for (json, value) in [
            (r#"{"count": 1.5}"#, "1.5"),
            (r#"{"count": -1}"#, "-1"),
            (r#"{"count": -1.0}"#, "-1"),
            (r#"{"count": 1e300}"#, "1e+300"),
            (r#"{"componentType": 4294967296}"#, "4294967296"),
            (r#"{"componentType": 4294967296.0}"#, "4294967296"),
            (r#"{"count": "3"}"#, "\"3\""),
        ] {
            let e = accessor(json).unwrap_err();
            assert!(
                e.contains(value) && e.contains("whole number"),
                "{json}: {e}"
            );
        }
        assert_eq!(
            accessor(r#"{"componentType": 4294967295.0}"#)
                .unwrap()
                .component_type,
            Some(u32::MAX)
        );
    }

    #[test]
    fn errors_name_the_property() {
        let e = parse(br#"{"accessors": [{}, {"count": 2.5}]}"#).unwrap_err();
        assert!(
            e.starts_with("accessors[1].count: invalid value: floating point `2.5`"),
            "{e}"
        );
        let e = parse(br#"{"meshes": [{"primitives": [{"attributes": {"NORMAL": -2}}]}]}"#)
            .unwrap_err();
        assert!(
            e.starts_with("meshes[0].primitives[0].attributes.NORMAL: "),
            "{e}"
        );
        // Trailing bytes after the document are still an error, as serde_json's own.
        assert!(parse(b"{} x").is_err());
        assert!(parse(b"{}").is_ok());
    }
}
