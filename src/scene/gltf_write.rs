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

use super::{Interpolation, LightDef, LightKind, Property, SceneError};

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
    pub fn write(&self, path: &Path) -> Result<(), SceneError> {
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
    pub fn to_glb(&self) -> Result<Vec<u8>, SceneError> {
        let (mut root, bin) = self.document()?;
        if !bin.is_empty() {
            root["buffers"] = json!([{ "byteLength": bin.len() }]);
        }
        let mut json = serde_json::to_vec(&root).map_err(|e| SceneError::Write {
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
        let total = u32::try_from(total).map_err(|_| SceneError::Write {
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
    pub fn to_gltf_json(&self) -> Result<String, SceneError> {
        let (mut root, bin) = self.document()?;
        if !bin.is_empty() {
            root["buffers"] = json!([{
                "byteLength": bin.len(),
                "uri": format!("data:application/octet-stream;base64,{}", encode_base64(&bin)),
            }]);
        }
        serde_json::to_string(&root).map_err(|e| SceneError::Write {
            reason: e.to_string(),
        })
    }

    fn check(&self) -> Result<(), SceneError> {
        let bad = |reason: String| Err(SceneError::Write { reason });
        let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
        let in_range = |i: Option<u32>, len: usize| i.is_none_or(|i| (i as usize) < len);
        for (mi, m) in self.meshes.iter().enumerate() {
            for (pi, p) in m.primitives.iter().enumerate() {
                let at = format!("mesh {mi} primitive {pi}");
                let nv = p.positions.len();
                if nv == 0 {
                    return bad(format!("{at}: no positions"));
                }
                let flat: Vec<f32> = p.positions.iter().flat_map(|v| v.to_array()).collect();
                if !finite(&flat) {
                    return bad(format!("{at}: non-finite position"));
                }
                if p.normals.as_ref().is_some_and(|n| n.len() != nv)
                    || p.uvs.as_ref().is_some_and(|n| n.len() != nv)
                    || p.morph_targets.iter().any(|t| t.len() != nv)
                    || p.morph_normals.iter().any(|t| t.len() != nv)
                {
                    return bad(format!("{at}: attribute count differs from positions"));
                }
                let idx_len = p.indices.as_ref().map_or(nv, Vec::len);
                if idx_len % 3 != 0 {
                    return bad(format!(
                        "{at}: {idx_len} indices/vertices is not whole triangles"
                    ));
                }
                if let Some(i) = p.indices.iter().flatten().find(|&&i| i as usize >= nv) {
                    return bad(format!("{at}: index {i} past the vertex count {nv}"));
                }
                if !in_range(p.material, self.materials.len()) {
                    return bad(format!("{at}: material missing"));
                }
                if !p.morph_normals.is_empty() && p.morph_normals.len() != p.morph_targets.len() {
                    return bad(format!("{at}: morph normals for some targets only"));
                }
                if p.morph_targets.len() != m.primitives[0].morph_targets.len() {
                    return bad(format!(
                        "mesh {mi}: primitives differ in morph target count"
                    ));
                }
            }
            let targets = m.primitives.first().map_or(0, |p| p.morph_targets.len());
            if !m.weights.is_empty() && m.weights.len() != targets {
                return bad(format!(
                    "mesh {mi}: {} weights for {targets} targets",
                    m.weights.len()
                ));
            }
        }
        for (mi, m) in self.materials.iter().enumerate() {
            if !in_range(m.base_color_texture, self.textures.len()) {
                return bad(format!("material {mi}: texture missing"));
            }
            if m.extras.as_ref().is_some_and(|e| !e.is_object()) {
                return bad(format!("material {mi}: extras must be an object"));
            }
        }
        for (ti, t) in self.textures.iter().enumerate() {
            if t.image as usize >= self.images.len() {
                return bad(format!("texture {ti}: image {} missing", t.image));
            }
        }
        for (ii, i) in self.images.iter().enumerate() {
            if i.bytes.is_empty() || !matches!(i.mime_type.as_str(), "image/png" | "image/jpeg") {
                return bad(format!("image {ii}: empty, or not image/png or image/jpeg"));
            }
        }
        let mut parent = vec![None; self.nodes.len()];
        for (ni, n) in self.nodes.iter().enumerate() {
            if !in_range(n.mesh, self.meshes.len())
                || !in_range(n.camera, self.cameras.len())
                || !in_range(n.light, self.lights.len())
            {
                return bad(format!("node {ni}: mesh, camera or light missing"));
            }
            let trs = [n.translation.to_array(), n.scale.to_array()].concat();
            if !finite(&trs) || !n.rotation.is_finite() {
                return bad(format!("node {ni}: non-finite transform"));
            }
            for &c in &n.children {
                match parent.get_mut(c as usize) {
                    None => return bad(format!("node {ni}: child {c} missing")),
                    Some(Some(_)) => return bad(format!("node {c} has two parents")),
                    Some(p) => *p = Some(ni),
                }
            }
        }
        for &r in &self.roots {
            match parent.get(r as usize) {
                None => return bad(format!("root {r} missing")),
                Some(Some(p)) => return bad(format!("root {r} is a child of node {p}")),
                Some(None) => {}
            }
        }
        for (ai, a) in self.animations.iter().enumerate() {
            for (ci, c) in a.channels.iter().enumerate() {
                let at = format!("animation {ai} channel {ci}");
                let Some(node) = self.nodes.get(c.node as usize) else {
                    return bad(format!("{at}: node {} missing", c.node));
                };
                let width = match c.property {
                    Property::Translation | Property::Scale => 3,
                    Property::Rotation => 4,
                    Property::Weights => node
                        .mesh
                        .and_then(|m| self.meshes.get(m as usize))
                        .and_then(|m| m.primitives.first())
                        .map_or(0, |p| p.morph_targets.len()),
                };
                let per_key = if c.interpolation == Interpolation::CubicSpline {
                    3
                } else {
                    1
                };
                if width == 0
                    || c.times.is_empty()
                    || c.values.len() != c.times.len() * width * per_key
                {
                    return bad(format!(
                        "{at}: {} values for {} keys of width {width}",
                        c.values.len(),
                        c.times.len()
                    ));
                }
                if !finite(&c.times)
                    || !finite(&c.values)
                    || c.times.windows(2).any(|w| w[1] < w[0])
                {
                    return bad(format!(
                        "{at}: times must be finite and increasing, values finite"
                    ));
                }
            }
        }
        if let Some(fps) = self.fps {
            if !(fps.is_finite() && fps > 0.0) {
                return bad(format!("fps {fps} is not positive"));
            }
        }
        Ok(())
    }

    /// The JSON document (without `buffers`) and the binary blob it refers to.
    fn document(&self) -> Result<(Value, Vec<u8>), SceneError> {
        self.check()?;
        let mut w = Blob::default();
        let mut used = std::collections::BTreeSet::new();

        let materials: Vec<Value> = self
            .materials
            .iter()
            .map(|m| {
                let mut o = Map::new();
                if let Some(n) = &m.name {
                    o.insert("name".into(), json!(n));
                }
                let mut pbr = json!({
                    "baseColorFactor": m.base_color.to_array(),
                    "metallicFactor": m.metallic,
                    "roughnessFactor": m.roughness,
                });
                if let Some(t) = m.base_color_texture {
                    pbr["baseColorTexture"] = json!({ "index": t });
                }
                o.insert("pbrMetallicRoughness".into(), pbr);
                if let Some(e) = &m.extras {
                    o.insert("extras".into(), e.clone());
                }
                let peak = m.emissive.max_element();
                let mut ext = Map::new();
                if peak > 0.0 {
                    let (factor, strength) = if peak > 1.0 {
                        (m.emissive / peak, peak)
                    } else {
                        (m.emissive, 1.0)
                    };
                    o.insert("emissiveFactor".into(), json!(factor.to_array()));
                    if strength != 1.0 {
                        used.insert("KHR_materials_emissive_strength");
                        ext.insert(
                            "KHR_materials_emissive_strength".into(),
                            json!({ "emissiveStrength": strength }),
                        );
                    }
                }
                if m.transmission != 0.0 {
                    used.insert("KHR_materials_transmission");
                    ext.insert(
                        "KHR_materials_transmission".into(),
                        json!({ "transmissionFactor": m.transmission }),
                    );
                }
                if m.ior != 1.5 {
                    used.insert("KHR_materials_ior");
                    ext.insert("KHR_materials_ior".into(), json!({ "ior": m.ior }));
                }
                if !ext.is_empty() {
                    o.insert("extensions".into(), Value::Object(ext));
                }
                if m.double_sided {
                    o.insert("doubleSided".into(), json!(true));
                }
                Value::Object(o)
            })
            .collect();

        let mut meshes = Vec::new();
        for m in &self.meshes {
            let mut prims = Vec::new();
            for p in &m.primitives {
                let mut attrs = Map::new();
                attrs.insert("POSITION".into(), json!(w.vec3s(&p.positions, true)));
                if let Some(n) = &p.normals {
                    attrs.insert("NORMAL".into(), json!(w.vec3s(n, false)));
                }
                if let Some(uv) = &p.uvs {
                    let flat: Vec<f32> = uv.iter().flat_map(|v| v.to_array()).collect();
                    attrs.insert("TEXCOORD_0".into(), json!(w.floats(&flat, "VEC2", false)));
                }
                let mut o = Map::new();
                o.insert("attributes".into(), Value::Object(attrs));
                if let Some(i) = &p.indices {
                    o.insert("indices".into(), json!(w.indices(i)));
                }
                if let Some(mat) = p.material {
                    o.insert("material".into(), json!(mat));
                }
                if !p.morph_targets.is_empty() {
                    let t: Vec<Value> = p
                        .morph_targets
                        .iter()
                        .enumerate()
                        .map(|(k, d)| {
                            let mut t = json!({ "POSITION": w.vec3s(d, true) });
                            if let Some(n) = p.morph_normals.get(k) {
                                t["NORMAL"] = json!(w.vec3s(n, false));
                            }
                            t
                        })
                        .collect();
                    o.insert("targets".into(), json!(t));
                }
                prims.push(Value::Object(o));
            }
            let mut o = Map::new();
            o.insert("primitives".into(), json!(prims));
            if let Some(n) = &m.name {
                o.insert("name".into(), json!(n));
            }
            if !m.weights.is_empty() {
                o.insert("weights".into(), json!(m.weights));
            }
            meshes.push(Value::Object(o));
        }

        let cameras: Vec<Value> = self
            .cameras
            .iter()
            .map(|c| {
                let mut p = Map::new();
                p.insert("yfov".into(), json!(c.yfov));
                p.insert("znear".into(), json!(c.znear));
                if let Some(a) = c.aspect {
                    p.insert("aspectRatio".into(), json!(a));
                }
                if let Some(f) = c.zfar {
                    p.insert("zfar".into(), json!(f));
                }
                let mut o = Map::new();
                o.insert("type".into(), json!("perspective"));
                o.insert("perspective".into(), Value::Object(p));
                if let Some(n) = &c.name {
                    o.insert("name".into(), json!(n));
                }
                Value::Object(o)
            })
            .collect();

        let lights: Vec<Value> = self
            .lights
            .iter()
            .map(|l| {
                let mut o = Map::new();
                if let Some(n) = &l.name {
                    o.insert("name".into(), json!(n));
                }
                o.insert("color".into(), json!(l.color.to_array()));
                o.insert("intensity".into(), json!(l.intensity));
                if let Some(r) = l.range {
                    o.insert("range".into(), json!(r));
                }
                let kind = match l.kind {
                    LightKind::Point => "point",
                    LightKind::Directional => "directional",
                    LightKind::Spot {
                        inner_cone_angle,
                        outer_cone_angle,
                    } => {
                        o.insert(
                            "spot".into(),
                            json!({
                                "innerConeAngle": inner_cone_angle,
                                "outerConeAngle": outer_cone_angle,
                            }),
                        );
                        "spot"
                    }
                };
                o.insert("type".into(), json!(kind));
                Value::Object(o)
            })
            .collect();
        if !lights.is_empty() {
            used.insert("KHR_lights_punctual");
        }

        let nodes: Vec<Value> = self
            .nodes
            .iter()
            .map(|n| {
                let mut o = Map::new();
                if let Some(s) = &n.name {
                    o.insert("name".into(), json!(s));
                }
                if n.translation != Vec3::ZERO {
                    o.insert("translation".into(), json!(n.translation.to_array()));
                }
                if n.rotation != Quat::IDENTITY {
                    o.insert("rotation".into(), json!(n.rotation.to_array()));
                }
                if n.scale != Vec3::ONE {
                    o.insert("scale".into(), json!(n.scale.to_array()));
                }
                if !n.children.is_empty() {
                    o.insert("children".into(), json!(n.children));
                }
                if let Some(m) = n.mesh {
                    o.insert("mesh".into(), json!(m));
                }
                if let Some(c) = n.camera {
                    o.insert("camera".into(), json!(c));
                }
                if let Some(l) = n.light {
                    o.insert(
                        "extensions".into(),
                        json!({ "KHR_lights_punctual": { "light": l } }),
                    );
                }
                if let Some(wts) = &n.weights {
                    o.insert("weights".into(), json!(wts));
                }
                Value::Object(o)
            })
            .collect();

        let mut animations = Vec::new();
        for a in &self.animations {
            let mut channels = Vec::new();
            let mut samplers = Vec::new();
            for (k, c) in a.channels.iter().enumerate() {
                let input = w.floats(&c.times, "SCALAR", true);
                let ty = match c.property {
                    Property::Translation | Property::Scale => "VEC3",
                    Property::Rotation => "VEC4",
                    Property::Weights => "SCALAR",
                };
                let output = w.floats(&c.values, ty, false);
                let interpolation = match c.interpolation {
                    Interpolation::Step => "STEP",
                    Interpolation::Linear => "LINEAR",
                    Interpolation::CubicSpline => "CUBICSPLINE",
                };
                let path = match c.property {
                    Property::Translation => "translation",
                    Property::Rotation => "rotation",
                    Property::Scale => "scale",
                    Property::Weights => "weights",
                };
                samplers.push(
                    json!({ "input": input, "output": output, "interpolation": interpolation }),
                );
                channels.push(json!({ "sampler": k, "target": { "node": c.node, "path": path } }));
            }
            let mut o = Map::new();
            o.insert("channels".into(), json!(channels));
            o.insert("samplers".into(), json!(samplers));
            if let Some(n) = &a.name {
                o.insert("name".into(), json!(n));
            }
            animations.push(Value::Object(o));
        }

        let images: Vec<Value> = self
            .images
            .iter()
            .map(|i| {
                let mut o = Map::new();
                o.insert("bufferView".into(), json!(w.view(&i.bytes)));
                o.insert("mimeType".into(), json!(i.mime_type));
                if let Some(n) = &i.name {
                    o.insert("name".into(), json!(n));
                }
                Value::Object(o)
            })
            .collect();
        let textures: Vec<Value> = self
            .textures
            .iter()
            .map(|t| json!({ "source": t.image }))
            .collect();

        let mut scene = Map::new();
        scene.insert("nodes".into(), json!(self.roots));
        let mut extras = self.scene_extras.clone();
        if let Some(fps) = self.fps {
            extras.insert("fps".into(), json!(fps));
        }
        if !extras.is_empty() {
            scene.insert("extras".into(), Value::Object(extras));
        }

        let mut root = Map::new();
        root.insert(
            "asset".into(),
            json!({ "version": "2.0", "generator": concat!("subfield ", env!("CARGO_PKG_VERSION")) }),
        );
        root.insert("scene".into(), json!(0));
        root.insert("scenes".into(), json!([Value::Object(scene)]));
        let mut put = |k: &str, v: Vec<Value>| {
            if !v.is_empty() {
                root.insert(k.into(), Value::Array(v));
            }
        };
        put("nodes", nodes);
        put("meshes", meshes);
        put("materials", materials);
        put("cameras", cameras);
        put("animations", animations);
        put("images", images);
        put("textures", textures);
        put("accessors", std::mem::take(&mut w.accessors));
        put("bufferViews", std::mem::take(&mut w.views));
        if !lights.is_empty() {
            root.insert(
                "extensions".into(),
                json!({ "KHR_lights_punctual": { "lights": lights } }),
            );
        }
        if !used.is_empty() {
            root.insert(
                "extensionsUsed".into(),
                json!(used.into_iter().collect::<Vec<_>>()),
            );
        }
        Ok((Value::Object(root), w.bin))
    }
}

/// The binary buffer under construction, with its views and accessors.
#[derive(Default)]
struct Blob {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Blob {
    fn view(&mut self, bytes: &[u8]) -> usize {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        self.views.push(json!({
            "buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()
        }));
        self.bin.extend_from_slice(bytes);
        self.views.len() - 1
    }

    /// Float accessor of type `ty`; `bounds` writes min/max (required for POSITION and
    /// animation inputs).
    fn floats(&mut self, data: &[f32], ty: &str, bounds: bool) -> usize {
        let comps = match ty {
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            _ => 1,
        };
        let view = self.view(bytemuck::cast_slice(data));
        let mut o = json!({
            "bufferView": view, "componentType": 5126, "count": data.len() / comps, "type": ty
        });
        if bounds && !data.is_empty() {
            let mut lo = vec![f32::INFINITY; comps];
            let mut hi = vec![f32::NEG_INFINITY; comps];
            for e in data.chunks_exact(comps) {
                for c in 0..comps {
                    lo[c] = lo[c].min(e[c]);
                    hi[c] = hi[c].max(e[c]);
                }
            }
            o["min"] = json!(lo);
            o["max"] = json!(hi);
        }
        self.accessors.push(o);
        self.accessors.len() - 1
    }

    fn vec3s(&mut self, v: &[Vec3], bounds: bool) -> usize {
        let flat: Vec<f32> = v.iter().flat_map(|x| x.to_array()).collect();
        self.floats(&flat, "VEC3", bounds)
    }

    fn indices(&mut self, i: &[u32]) -> usize {
        let view = self.view(bytemuck::cast_slice(i));
        self.accessors.push(json!({
            "bufferView": view, "componentType": 5125, "count": i.len(), "type": "SCALAR"
        }));
        self.accessors.len() - 1
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

fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), SceneError> {
    crate::atomic::write_atomically(path, bytes).map_err(|source| SceneError::WriteIo {
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
