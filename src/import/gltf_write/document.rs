//! The JSON document and binary blob of a [`GltfBuilder`], one function per top-level
//! array (materials, meshes, cameras, lights, nodes, animations, images and textures). The
//! blob is filled in that order, so the bytes are the same for the same input.

use std::collections::BTreeSet;

use glam::{Quat, Vec3};
use serde_json::{json, Map, Value};

use super::{GltfBuilder, ImportError};
use crate::scene::{Interpolation, LightKind, Property};

/// Names of the extensions the document uses (`extensionsUsed`).
type Used = BTreeSet<&'static str>;

impl GltfBuilder {
    /// The JSON document (without `buffers`) and the binary blob it refers to.
    pub(super) fn document(&self) -> Result<(Value, Vec<u8>), ImportError> {
        self.check()?;
        let mut w = Blob::default();
        let mut used = Used::new();
        let materials = self.materials_json(&mut used);
        let meshes = self.meshes_json(&mut w);
        let cameras = self.cameras_json();
        let lights = self.lights_json();
        if !lights.is_empty() {
            used.insert("KHR_lights_punctual");
        }
        let nodes = self.nodes_json();
        let animations = self.animations_json(&mut w);
        let (images, textures) = self.images_and_textures_json(&mut w);
        let scene = self.scene_json();

        let mut root = Map::new();
        root.insert(
            "asset".into(),
            json!({ "version": "2.0", "generator": concat!("subfield ", env!("CARGO_PKG_VERSION")) }),
        );
        root.insert("scene".into(), json!(0));
        root.insert("scenes".into(), json!([scene]));
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

    /// Materials; notes the extensions they need in `used`.
    fn materials_json(&self, used: &mut Used) -> Vec<Value> {
        self.materials
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
            .collect()
    }

    /// Meshes, their attributes, indices and morph targets written to the blob.
    fn meshes_json(&self, w: &mut Blob) -> Vec<Value> {
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
        meshes
    }

    /// Perspective cameras.
    fn cameras_json(&self) -> Vec<Value> {
        self.cameras
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
            .collect()
    }

    /// `KHR_lights_punctual` lights.
    fn lights_json(&self) -> Vec<Value> {
        self.lights
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
            .collect()
    }

    /// Nodes: TRS (defaults left out), children, mesh, camera, light, weights.
    fn nodes_json(&self) -> Vec<Value> {
        self.nodes
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
            .collect()
    }

    /// Clips: one sampler per channel, keyframes written to the blob.
    fn animations_json(&self, w: &mut Blob) -> Vec<Value> {
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
        animations
    }

    /// Images (embedded in the blob) and the textures that sample them.
    fn images_and_textures_json(&self, w: &mut Blob) -> (Vec<Value>, Vec<Value>) {
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
        (images, textures)
    }

    /// The one scene: its roots, and `extras` (`fps` and the builder's extras).
    fn scene_json(&self) -> Value {
        let mut scene = Map::new();
        scene.insert("nodes".into(), json!(self.roots));
        let mut extras = self.scene_extras.clone();
        if let Some(fps) = self.fps {
            extras.insert("fps".into(), json!(fps));
        }
        if !extras.is_empty() {
            scene.insert("extras".into(), Value::Object(extras));
        }
        Value::Object(scene)
    }
}

/// The binary buffer under construction, with its views and accessors.
#[derive(Default)]
pub(super) struct Blob {
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
