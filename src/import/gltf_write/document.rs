//! The JSON document and binary blob of a [`Scene`], one function per top-level array
//! (materials, meshes, cameras, lights, nodes, animations, skins, images, textures and
//! samplers). The blob is filled in that order, so the bytes are the same for the same
//! scene. Members equal to the spec's defaults are left out.

use std::collections::BTreeSet;

use glam::{Quat, Vec3};
use serde_json::{json, Map, Value};

use super::ImportError;
use crate::scene::{
    AlphaMode, Falloff, Image, Interpolation, LightKind, Material, NodeTransform, Primitive,
    Projection, Property, Scene, Texture, TextureRef, Wrap, LUMENS_PER_WATT,
};

/// Names of the extensions the document uses (`extensionsUsed`).
type Used = BTreeSet<&'static str>;

/// The JSON document (without `buffers`) and the binary blob it refers to.
pub(super) fn document(scene: &Scene) -> Result<(Value, Vec<u8>), ImportError> {
    super::check::check(scene)?;
    let mut w = Blob::default();
    let mut used = Used::new();
    let materials = materials_json(scene, &mut used);
    let meshes = meshes_json(scene, &mut w);
    let cameras = cameras_json(scene);
    let lights = lights_json(scene);
    if !lights.is_empty() {
        used.insert("KHR_lights_punctual");
    }
    let nodes = nodes_json(scene);
    let animations = animations_json(scene, &mut w);
    let skins = skins_json(scene, &mut w);
    let images = images_json(scene, &mut w)?;
    let (textures, samplers) = textures_json(scene);

    let mut root = Map::new();
    root.insert(
        "asset".into(),
        json!({ "version": "2.0", "generator": concat!("subfield ", env!("CARGO_PKG_VERSION")) }),
    );
    root.insert("scene".into(), json!(0));
    root.insert("scenes".into(), json!([scene_json(scene)]));
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
    put("skins", skins);
    put("images", images);
    put("textures", textures);
    put("samplers", samplers);
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

/// `{ "index": i }`, with `texCoord` when it is not 0.
/// A texture reference. The writer writes each primitive's one uv set as `TEXCOORD_0`
/// (the set its material's textures read), so every reference reads set 0; a uv
/// transform becomes `KHR_texture_transform`.
fn texture_info(r: &TextureRef, used: &mut Used) -> Value {
    let mut o = json!({ "index": r.texture });
    if let Some(t) = &r.transform {
        used.insert("KHR_texture_transform");
        o["extensions"] = json!({ "KHR_texture_transform": {
            "offset": t.offset.to_array(),
            "rotation": t.rotation,
            "scale": t.scale.to_array(),
        }});
    }
    o
}

/// Materials; notes the extensions they need in `used`.
fn materials_json(scene: &Scene, used: &mut Used) -> Vec<Value> {
    scene
        .materials
        .iter()
        .enumerate()
        .map(|(i, m)| material_json(m, scene.extras.materials.get(i), used))
        .collect()
}

fn material_json(m: &Material, extras: Option<&Option<Value>>, used: &mut Used) -> Value {
    let mut o = Map::new();
    if let Some(n) = &m.name {
        o.insert("name".into(), json!(n));
    }
    let mut pbr = json!({
        "baseColorFactor": m.base_color.to_array(),
        "metallicFactor": m.metallic,
        "roughnessFactor": m.roughness,
    });
    if let Some(t) = &m.base_color_texture {
        pbr["baseColorTexture"] = texture_info(t, used);
    }
    if let Some(t) = &m.metallic_roughness_texture {
        pbr["metallicRoughnessTexture"] = texture_info(t, used);
    }
    o.insert("pbrMetallicRoughness".into(), pbr);
    let mut extras = match extras {
        Some(Some(e)) => e.clone(),
        _ => Value::Null,
    };
    if let Some(a) = m.ambient {
        // The ambient colour (AFF's) beside the application's extras, read back by
        // subfield's reader.
        if !extras.is_object() {
            extras = json!({});
        }
        extras["ambient"] = json!(a.to_array());
    }
    if !extras.is_null() {
        o.insert("extras".into(), extras);
    }
    // The factor must stay in [0, 1]: a brighter emission is carried by the strength.
    let peak = m.emissive.max_element();
    let mut ext = Map::new();
    if peak > 0.0 {
        let (factor, strength) = if peak > 1.0 {
            (m.emissive / peak, m.emissive_strength * peak)
        } else {
            (m.emissive, m.emissive_strength)
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
    if let Some(t) = &m.emissive_texture {
        o.insert("emissiveTexture".into(), texture_info(t, used));
    }
    if let Some(t) = &m.normal_texture {
        let mut info = texture_info(t, used);
        if m.normal_scale != 1.0 {
            info["scale"] = json!(m.normal_scale);
        }
        o.insert("normalTexture".into(), info);
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
    match m.alpha_mode {
        AlphaMode::Opaque => {}
        AlphaMode::Mask { cutoff } => {
            o.insert("alphaMode".into(), json!("MASK"));
            if cutoff != 0.5 {
                o.insert("alphaCutoff".into(), json!(cutoff));
            }
        }
        AlphaMode::Blend => {
            o.insert("alphaMode".into(), json!("BLEND"));
        }
    }
    Value::Object(o)
}

/// Whether the triangles are the vertices in order (`0 1 2`, `3 4 5`, ...): such a
/// primitive is written without indices.
fn consecutive(p: &Primitive) -> bool {
    p.triangles.len() * 3 == p.positions.len()
        && p.triangles
            .iter()
            .enumerate()
            .all(|(i, t)| *t == [3 * i as u32, 3 * i as u32 + 1, 3 * i as u32 + 2])
}

/// Meshes, their attributes, indices and morph targets written to the blob.
fn meshes_json(scene: &Scene, w: &mut Blob) -> Vec<Value> {
    let mut meshes = Vec::new();
    for m in &scene.meshes {
        let mut prims = Vec::new();
        for p in &m.primitives {
            prims.push(primitive_json(p, w));
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

fn primitive_json(p: &Primitive, w: &mut Blob) -> Value {
    let mut attrs = Map::new();
    attrs.insert("POSITION".into(), json!(w.vec3s(&p.positions, true)));
    if let Some(n) = &p.normals {
        attrs.insert("NORMAL".into(), json!(w.vec3s(n, false)));
    }
    if let Some(uv) = &p.uvs {
        let flat: Vec<f32> = uv.iter().flat_map(|v| v.to_array()).collect();
        attrs.insert("TEXCOORD_0".into(), json!(w.floats(&flat, "VEC2", false)));
    }
    // Skin influences: set `s` of vertex `v` is entry `v * sets + s`.
    let sets = p.influence_sets();
    for s in 0..sets {
        let joints: Vec<u16> = (0..p.positions.len())
            .flat_map(|v| p.joints[v * sets + s])
            .collect();
        let weights: Vec<f32> = (0..p.positions.len())
            .flat_map(|v| p.weights[v * sets + s])
            .collect();
        attrs.insert(format!("JOINTS_{s}"), json!(w.joints(&joints)));
        attrs.insert(
            format!("WEIGHTS_{s}"),
            json!(w.floats(&weights, "VEC4", false)),
        );
    }
    let mut o = Map::new();
    o.insert("attributes".into(), Value::Object(attrs));
    if !consecutive(p) {
        let flat: Vec<u32> = p.triangles.iter().flatten().copied().collect();
        o.insert("indices".into(), json!(w.indices(&flat)));
    }
    o.insert("material".into(), json!(p.material));
    if !p.morph_targets.is_empty() {
        let zeros = vec![Vec3::ZERO; p.positions.len()];
        let t: Vec<Value> = p
            .morph_targets
            .iter()
            .map(|d| {
                // A target must name an attribute: no displacement is written as zeros.
                let positions = if d.positions.is_empty() {
                    &zeros
                } else {
                    &d.positions
                };
                let mut t = json!({ "POSITION": w.vec3s(positions, true) });
                if !d.normals.is_empty() {
                    t["NORMAL"] = json!(w.vec3s(&d.normals, false));
                }
                t
            })
            .collect();
        o.insert("targets".into(), json!(t));
    }
    Value::Object(o)
}

/// Perspective and orthographic cameras.
fn cameras_json(scene: &Scene) -> Vec<Value> {
    scene
        .cameras
        .iter()
        .map(|c| {
            let mut p = Map::new();
            let kind = match c.projection {
                Projection::Perspective {
                    yfov,
                    aspect,
                    znear,
                    zfar,
                } => {
                    p.insert("yfov".into(), json!(yfov));
                    p.insert("znear".into(), json!(znear));
                    if let Some(a) = aspect {
                        p.insert("aspectRatio".into(), json!(a));
                    }
                    if let Some(f) = zfar {
                        p.insert("zfar".into(), json!(f));
                    }
                    "perspective"
                }
                Projection::Orthographic {
                    xmag,
                    ymag,
                    znear,
                    zfar,
                } => {
                    p.insert("xmag".into(), json!(xmag));
                    p.insert("ymag".into(), json!(ymag));
                    p.insert("znear".into(), json!(znear));
                    p.insert("zfar".into(), json!(zfar));
                    "orthographic"
                }
            };
            let mut o = Map::new();
            o.insert("type".into(), json!(kind));
            o.insert(kind.into(), Value::Object(p));
            if let Some(n) = &c.name {
                o.insert("name".into(), json!(n));
            }
            Value::Object(o)
        })
        .collect()
}

/// `KHR_lights_punctual` lights, intensities in the spec's candela and lux; a point or
/// spot light without falloff gets `"extras": { "falloff": "none" }`.
fn lights_json(scene: &Scene) -> Vec<Value> {
    scene
        .lights
        .iter()
        .map(|l| {
            let mut o = Map::new();
            if let Some(n) = &l.name {
                o.insert("name".into(), json!(n));
            }
            o.insert("color".into(), json!(l.color.to_array()));
            // The spec's candela and lux (the model's W/sr and W/m² × 683), in f64:
            // exact, so the reader's division gives back the f32.
            o.insert(
                "intensity".into(),
                json!(f64::from(l.intensity) * LUMENS_PER_WATT),
            );
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
            // KHR_lights_punctual lights always fall off with the inverse square; a light
            // without falloff (AFF) says so in its extras, which the reader here reads back.
            if l.falloff == Falloff::None && l.kind != LightKind::Directional {
                o.insert("extras".into(), json!({ "falloff": "none" }));
            }
            Value::Object(o)
        })
        .collect()
}

/// Nodes: TRS (defaults left out) or matrix, children, mesh, skin, camera, light, weights.
fn nodes_json(scene: &Scene) -> Vec<Value> {
    scene
        .nodes
        .iter()
        .map(|n| {
            let mut o = Map::new();
            if let Some(s) = &n.name {
                o.insert("name".into(), json!(s));
            }
            match &n.transform {
                NodeTransform::Matrix(m) => {
                    o.insert("matrix".into(), json!(m.to_cols_array()));
                }
                NodeTransform::Trs(t) => {
                    if t.translation != Vec3::ZERO {
                        o.insert("translation".into(), json!(t.translation.to_array()));
                    }
                    if t.rotation != Quat::IDENTITY {
                        o.insert("rotation".into(), json!(t.rotation.to_array()));
                    }
                    if t.scale != Vec3::ONE {
                        o.insert("scale".into(), json!(t.scale.to_array()));
                    }
                }
            }
            if !n.children.is_empty() {
                o.insert("children".into(), json!(n.children));
            }
            if let Some(m) = n.mesh {
                o.insert("mesh".into(), json!(m));
            }
            if let Some(s) = n.skin {
                o.insert("skin".into(), json!(s));
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
fn animations_json(scene: &Scene, w: &mut Blob) -> Vec<Value> {
    let mut animations = Vec::new();
    for a in &scene.animations {
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
            samplers
                .push(json!({ "input": input, "output": output, "interpolation": interpolation }));
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

/// Skins: joints and their inverse bind matrices (written to the blob).
fn skins_json(scene: &Scene, w: &mut Blob) -> Vec<Value> {
    scene
        .skins
        .iter()
        .map(|s| {
            let flat: Vec<f32> = s
                .inverse_bind_matrices
                .iter()
                .flat_map(|m| m.to_cols_array())
                .collect();
            let mut o = Map::new();
            o.insert("joints".into(), json!(s.joints));
            if !flat.is_empty() {
                o.insert(
                    "inverseBindMatrices".into(),
                    json!(w.floats(&flat, "MAT4", false)),
                );
            }
            if let Some(n) = &s.name {
                o.insert("name".into(), json!(n));
            }
            Value::Object(o)
        })
        .collect()
}

/// Encodes an image as PNG: RGB when every pixel is opaque, else RGBA (fast compression:
/// the files are for rendering, not archiving).
fn png(i: &Image) -> Result<Vec<u8>, String> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::{ExtendedColorType, ImageEncoder};
    let opaque = i.rgba8.chunks_exact(4).all(|p| p[3] == 255);
    let rgb: Vec<u8>;
    let (data, color) = if opaque {
        rgb = i
            .rgba8
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        (rgb.as_slice(), ExtendedColorType::Rgb8)
    } else {
        (i.rgba8.as_slice(), ExtendedColorType::Rgba8)
    };
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Sub)
        .write_image(data, i.width, i.height, color)
        .map_err(|e| e.to_string())?;
    Ok(out)
}

/// Images, encoded as PNG into the blob.
fn images_json(scene: &Scene, w: &mut Blob) -> Result<Vec<Value>, ImportError> {
    let mut images = Vec::with_capacity(scene.images.len());
    for (ii, i) in scene.images.iter().enumerate() {
        let bytes = png(i).map_err(|reason| ImportError::Write {
            reason: format!("image {ii}: {reason}"),
        })?;
        let mut o = Map::new();
        o.insert("bufferView".into(), json!(w.view(&bytes)));
        o.insert("mimeType".into(), json!("image/png"));
        if let Some(n) = &i.name {
            o.insert("name".into(), json!(n));
        }
        images.push(Value::Object(o));
    }
    Ok(images)
}

/// The sampler of a texture; `None` for glTF's default (repeat, no filter given, which
/// the reader takes as linear).
fn sampler_json(t: &Texture) -> Option<Value> {
    let wrap = |w: Wrap| match w {
        Wrap::Repeat => 10497,
        Wrap::MirroredRepeat => 33648,
        Wrap::ClampToEdge => 33071,
    };
    if t.wrap_s == Wrap::Repeat && t.wrap_t == Wrap::Repeat && !t.nearest {
        return None;
    }
    let mut o = Map::new();
    if t.nearest {
        o.insert("magFilter".into(), json!(9728));
    }
    if t.wrap_s != Wrap::Repeat {
        o.insert("wrapS".into(), json!(wrap(t.wrap_s)));
    }
    if t.wrap_t != Wrap::Repeat {
        o.insert("wrapT".into(), json!(wrap(t.wrap_t)));
    }
    Some(Value::Object(o))
}

/// Textures, and the distinct samplers they use (in order of first use).
fn textures_json(scene: &Scene) -> (Vec<Value>, Vec<Value>) {
    let mut samplers: Vec<Value> = Vec::new();
    let textures = scene
        .textures
        .iter()
        .map(|t| {
            let mut o = json!({ "source": t.image });
            if let Some(s) = sampler_json(t) {
                let k = samplers.iter().position(|x| *x == s).unwrap_or_else(|| {
                    samplers.push(s);
                    samplers.len() - 1
                });
                o["sampler"] = json!(k);
            }
            o
        })
        .collect();
    (textures, samplers)
}

/// The one scene: its roots, and `extras` (the scene's extras, `fps`, `ambient` and
/// `timeRange`).
fn scene_json(scene: &Scene) -> Value {
    let mut o = Map::new();
    o.insert("nodes".into(), json!(scene.roots));
    let mut extras = scene.extras.scene.clone();
    if let Some(fps) = scene.fps {
        extras.insert("fps".into(), json!(fps));
    }
    if let Some(a) = scene.ambient {
        extras.insert("ambient".into(), json!(a.to_array()));
    }
    if let Some((start, end)) = scene.time_range {
        extras.insert("timeRange".into(), json!([start, end]));
    }
    if !extras.is_empty() {
        o.insert("extras".into(), Value::Object(extras));
    }
    Value::Object(o)
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
        while !self.bin.len().is_multiple_of(4) {
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
            "MAT4" => 16,
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

    /// `JOINTS_n`: unsigned shorts, four per vertex.
    fn joints(&mut self, j: &[u16]) -> usize {
        let view = self.view(bytemuck::cast_slice(j));
        self.accessors.push(json!({
            "bufferView": view, "componentType": 5123, "count": j.len() / 4, "type": "VEC4"
        }));
        self.accessors.len() - 1
    }
}
