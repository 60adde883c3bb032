//! [`AffScene`] → the one [`Scene`] model. The mapping is described in the module docs of
//! [`crate::import::aff`]; materials in [`material`].
//!
//! The scene is built as the glTF reader would build it from the file `subfield convert`
//! writes (node rotations normalised as the reader does, textures with the default
//! sampler, non-indexed `tpa` primitives as consecutive triangles), so an `.aff` and its
//! converted `.glb` import to the same model.

use std::collections::HashMap;

use glam::{DQuat, DVec3, Quat, Vec3};
use serde_json::{json, Value};

use super::{AffMaterial, AffScene, AffTexture, AffTransform, ImportError, MorphBatch, Tracks};
use crate::scene::{
    AlphaMode, Animation, CameraDef, Channel, Falloff, Image, Interpolation, LightDef, LightKind,
    Material, Mesh, MorphTarget, Node, NodeTransform, Primitive, Projection, Property, Scene,
    Texture, TextureRef, Trs, Wrap,
};

/// The model's material of an AFF material (with an optional base colour texture index):
///
/// | model (glTF) | from AFF |
/// |---|---|
/// | `base_color` (`baseColorFactor`) | diffuse colour (`f`: colour·Kd), clamped to [0, 1]; alpha 1. A texture is multiplied by it, as glTF does. A transmissive material's is `min(1, kd + T)` (below) |
/// | `metallic` | mirror weight: the largest specular component (`f`: Ks), clamped — a Whitted renderer's reflection coefficient |
/// | `roughness` | `(2/(shine+2))^¼` (Phong exponent → Beckmann-like α = √(2/(n+2)), roughness = √α); 1 for shine ≤ 0 |
/// | `transmission` (`KHR_materials_transmission`) | `T / max(base_color)`, clamped to [0, 1] (below) |
/// | `ior` (`KHR_materials_ior`) | `ior` when ≥ 1 (AFF files write 0 for opaque surfaces: the glTF default 1.5 is kept) |
/// | `double_sided` | when `T > 0` (AFF: transmissive surfaces are two-sided) |
///
/// | `ambient` | the ambient colour (`f`: colour·Kd, the diffuse colour), negatives as 0: the scene's ambient light `am` is reflected with it |
///
/// Transmission: AFF (as NFF) adds `T ×` the refracted colour, untinted, beside the
/// diffuse colour `kd`; glTF tints the transmitted light by the base colour `b` and
/// shares it with the diffuse lobe: transmitted `b·t`, diffuse `b·(1 − t)`. Taking
/// `b = kd` (as for opaque materials) made BART's glass a dark grey filter (the
/// kitchen's dragon, `kd` 0.2 and `T` 0.85, passed 0.17 of the light at each surface
/// instead of 0.85: issue 35). So `b = min(1, kd + T)` and `t = T / max(b)`: exact
/// (transmitted `T`, diffuse `kd`) for a grey `kd` with `kd + T ≤ 1`; otherwise the
/// brightest channel transmits `T` and the diffuse colour is what is left.
///
/// The exact AFF numbers (ambient, diffuse, specular, shine, T, ior) are kept by
/// [`material_extras`]: AFF's per-material ambient colour has no glTF counterpart (the
/// converted file carries it as the material's `extras.ambient`).
pub fn material(m: &AffMaterial, texture: Option<u32>) -> Material {
    let clamp01 = |x: f32| {
        if x.is_finite() {
            x.clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    let roughness = if m.shine > 0.0 {
        (2.0 / (m.shine + 2.0)).powf(0.25)
    } else {
        1.0
    };
    let kd = Vec3::new(
        clamp01(m.diffuse.x),
        clamp01(m.diffuse.y),
        clamp01(m.diffuse.z),
    );
    let t = clamp01(m.transmittance);
    let (base, transmission) = if t > 0.0 {
        let b = (kd + Vec3::splat(t)).min(Vec3::ONE);
        (b, clamp01(t / b.max_element()))
    } else {
        (kd, 0.0)
    };
    Material {
        name: None,
        base_color: base.extend(1.0),
        base_color_texture: texture.map(|texture| TextureRef {
            texture,
            tex_coord: 0,
            transform: None,
        }),
        metallic: clamp01(m.specular.max_element()),
        roughness: clamp01(roughness),
        metallic_roughness_texture: None,
        emissive: Vec3::ZERO,
        emissive_strength: 1.0,
        emissive_texture: None,
        normal_texture: None,
        normal_scale: 1.0,
        transmission,
        ior: if m.ior >= 1.0 { m.ior } else { 1.5 },
        double_sided: m.transmittance > 0.0,
        alpha_mode: AlphaMode::Opaque,
        ambient: Some(if m.ambient.is_finite() {
            m.ambient.max(Vec3::ZERO)
        } else {
            Vec3::ZERO
        }),
    }
}

/// The material's `extras` (`extras.aff`: the exact AFF numbers).
pub fn material_extras(m: &AffMaterial) -> Value {
    json!({ "aff": {
        "ambient": m.ambient.to_array(),
        "diffuse": m.diffuse.to_array(),
        "specular": m.specular.to_array(),
        "shine": m.shine,
        "transmittance": m.transmittance,
        "ior": m.ior,
    }})
}

/// Frame sampling: AFF times of the frames and their model key times (AFF − t0).
struct Frames {
    t0: f64,
    aff: Vec<f64>,
    keys: Vec<f32>,
}

struct Conv<'a> {
    aff: &'a AffScene,
    s: Scene,
    channels: Vec<Channel>,
    frames: Option<Frames>,
    rest: f64,
    materials: HashMap<(u32, Option<u32>), u32>,
    textures: HashMap<u32, u32>,
}

pub(super) fn to_scene(aff: &AffScene) -> Result<Scene, ImportError> {
    let bad = |reason: String| ImportError::Convert {
        path: aff.source.clone(),
        reason,
    };
    let mut s = Scene {
        source: aff.source.clone(),
        ..Scene::default()
    };
    let frames = match aff.time {
        Some(r) => match r.fps() {
            Some(fps) => {
                let times: Vec<f64> = (0..r.frames).map(|i| r.frame_time(i)).collect();
                let keys: Vec<f32> = times.iter().map(|t| (t - r.start) as f32).collect();
                if keys.windows(2).any(|w| w[1] <= w[0]) || !(fps as f32).is_finite() {
                    return Err(bad(format!(
                        "time range {}..{} is too short for {} frames in single precision",
                        r.start, r.end, r.frames
                    )));
                }
                s.fps = Some(fps as f32);
                // The `a` line's frames are the authored range, whatever the keys
                // cover: frame `i` at model time `keys[i]`, so 0..n by default.
                s.time_range = keys.last().map(|&end| (0.0, end));
                Some(Frames {
                    t0: r.start,
                    aff: times,
                    keys,
                })
            }
            None => None,
        },
        None => None,
    };
    // `am` (default 1 1 1) is the scene's ambient light: the renderer's ambient term
    // `kd · ambient` (NFF's is the material's ambient colour times it; see the module).
    s.ambient = Some(if aff.ambient.is_finite() {
        aff.ambient.max(Vec3::ZERO)
    } else {
        Vec3::ZERO
    });
    s.extras.scene.insert(
        "aff".into(),
        json!({
            "background": aff.background.to_array(),
            "ambient": aff.ambient.to_array(),
            "t0": aff.rest_time(),
            "frames": aff.time.map_or(1, |r| r.frames),
        }),
    );
    let mut c = Conv {
        aff,
        s,
        channels: Vec::new(),
        frames,
        rest: aff.rest_time(),
        materials: HashMap::new(),
        textures: HashMap::new(),
    };
    let root = c.node(0)?;
    c.s.roots.push(root);
    c.camera();
    c.lights();
    let channels = std::mem::take(&mut c.channels);
    if !channels.is_empty() {
        c.s.animations.push(Animation {
            name: Some("aff".into()),
            channels,
        });
    }
    let mut scene = c.s;
    scene.warnings = aff
        .warnings
        .iter()
        .cloned()
        .map(crate::scene::Warning)
        .collect();
    crate::import::validate(&scene)?;
    Ok(scene)
}

/// A unit `f32` quaternion: rounded, divided by its length, then normalised once more as
/// the glTF reader normalises the rotation it reads, so the model is the one the converted
/// file imports to.
fn f32q(q: DQuat) -> Quat {
    let q = q.as_quat();
    let l = q.length();
    if l > 0.0 && l.is_finite() {
        q / l
    } else {
        Quat::IDENTITY
    }
}

/// A node's rest rotation (see [`f32q`]).
fn rest_rotation(q: DQuat) -> Quat {
    f32q(q).normalize()
}

/// An RGB8 image as the model's RGBA8 (opaque).
fn rgba(t: &AffTexture) -> Image {
    let rgba8 = t
        .rgb8
        .chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2], 255])
        .collect();
    Image {
        name: Some(t.name.clone()),
        width: t.width,
        height: t.height,
        rgba8,
    }
}

/// A TRS rest transform.
fn trs(translation: Vec3, rotation: Quat, scale: Vec3) -> NodeTransform {
    NodeTransform::Trs(Trs {
        translation,
        rotation,
        scale,
    })
}

impl Conv<'_> {
    fn add_node(&mut self, node: Node) -> usize {
        self.s.nodes.push(node);
        self.s.nodes.len() - 1
    }

    fn attach(&mut self, parent: usize, child: usize) {
        self.s.nodes[parent].children.push(child);
        self.s.nodes[child].parent = Some(parent);
    }

    fn material(&mut self, material: u32, texture: Option<u32>) -> u32 {
        if let Some(&m) = self.materials.get(&(material, texture)) {
            return m;
        }
        let tex = texture.map(|t| match self.textures.get(&t) {
            Some(&g) => g,
            None => {
                self.s.images.push(rgba(&self.aff.textures[t as usize]));
                self.s.textures.push(Texture {
                    image: (self.s.images.len() - 1) as u32,
                    wrap_s: Wrap::Repeat,
                    wrap_t: Wrap::Repeat,
                    nearest: false,
                });
                let g = (self.s.textures.len() - 1) as u32;
                self.textures.insert(t, g);
                g
            }
        });
        let am = &self.aff.materials[material as usize];
        self.s.materials.push(self::material(am, tex));
        let m = (self.s.materials.len() - 1) as u32;
        let extras = &mut self.s.extras.materials;
        extras.resize(m as usize, None);
        extras.push(Some(material_extras(am)));
        self.materials.insert((material, texture), m);
        m
    }

    /// Samples `f` at every frame into a LINEAR channel of `node` (nothing without frames).
    fn sampled(&mut self, node: usize, property: Property, f: impl Fn(f64) -> Vec<f32>) {
        let Some(fr) = &self.frames else { return };
        let values: Vec<f32> = fr.aff.iter().flat_map(|&t| f(t)).collect();
        self.channels.push(Channel {
            node,
            property,
            interpolation: Interpolation::Linear,
            times: fr.keys.clone(),
            values,
        });
    }

    /// Rotations at every frame, each in the hemisphere of the previous one.
    fn sampled_rotation(&mut self, node: usize, f: impl Fn(f64) -> Quat) {
        let Some(fr) = &self.frames else { return };
        let mut values = Vec::with_capacity(4 * fr.aff.len());
        let mut prev = Quat::IDENTITY;
        for (i, &t) in fr.aff.iter().enumerate() {
            let mut q = f(t);
            if i > 0 && prev.dot(q) < 0.0 {
                q = -q;
            }
            values.extend(q.to_array());
            prev = q;
        }
        self.channels.push(Channel {
            node,
            property: Property::Rotation,
            interpolation: Interpolation::Linear,
            times: fr.keys.clone(),
            values,
        });
    }

    fn animate_trs(&mut self, node: usize, tr: &Tracks) {
        let vec3 = |v: Option<DVec3>, rest: DVec3| v.unwrap_or(rest).as_vec3().to_array().to_vec();
        if !tr.translation.is_empty() {
            self.sampled(node, Property::Translation, |t| {
                vec3(tr.translation_at(t), DVec3::ZERO)
            });
        }
        if !tr.rotation.is_empty() {
            self.sampled_rotation(node, |t| f32q(tr.rotation_at(t).unwrap_or(DQuat::IDENTITY)));
        }
        if !tr.scale.is_empty() {
            self.sampled(node, Property::Scale, |t| vec3(tr.scale_at(t), DVec3::ONE));
        }
    }

    /// STEP scale channel (1 visible, 0 hidden) at the visibility keys.
    fn animate_visibility(&mut self, node: usize, tr: &Tracks) {
        let Some(fr) = &self.frames else { return };
        let scale = |v: bool| if v { [1.0f32; 3] } else { [0.0; 3] };
        let mut times = vec![0.0f32];
        let mut values = scale(tr.visible_at(fr.t0)).to_vec();
        for &(k, _) in &tr.visibility {
            let g = (k - fr.t0) as f32;
            if g > times.last().copied().unwrap_or(0.0) {
                times.push(g);
                values.extend(scale(tr.visible_at(k)));
            }
        }
        self.channels.push(Channel {
            node,
            property: Property::Scale,
            interpolation: Interpolation::Step,
            times,
            values,
        });
    }

    /// One node per AFF block (two with a visibility track), its batches as one mesh, its
    /// animated batches as child nodes with morph targets, then its sub-blocks.
    fn node(&mut self, index: usize) -> Result<usize, ImportError> {
        let aff = self.aff;
        let an = &aff.nodes[index];
        let mut node = Node::default();
        let mut tracks = None;
        match &an.transform {
            AffTransform::Root => node.name = Some("aff".into()),
            AffTransform::Static {
                scale,
                axis,
                angle,
                translation,
            } => {
                let rotation = rest_rotation(super::spline::key_quat(
                    axis.as_dvec3(),
                    f64::from(*angle).to_radians(),
                ));
                node.transform = trs(*translation, rotation, *scale);
            }
            AffTransform::Animated(name) => {
                node.name = Some(name.clone());
                if let Some(tr) = aff.tracks.get(name) {
                    let t = self.rest;
                    node.transform = trs(
                        tr.translation_at(t).unwrap_or(DVec3::ZERO).as_vec3(),
                        rest_rotation(tr.rotation_at(t).unwrap_or(DQuat::IDENTITY)),
                        tr.scale_at(t).unwrap_or(DVec3::ONE).as_vec3(),
                    );
                    tracks = Some(tr);
                }
            }
        }
        let outer = self.add_node(node);
        if let Some(tr) = tracks {
            self.animate_trs(outer, tr);
        }
        let content = match tracks.filter(|tr| !tr.visibility.is_empty()) {
            None => outer,
            Some(tr) => {
                let visible = if tr.visible_at(self.rest) { 1.0 } else { 0.0 };
                let name = self.s.nodes[outer].name.clone().unwrap_or_default();
                let inner = self.add_node(Node {
                    name: Some(format!("{name}:visibility")),
                    transform: trs(Vec3::ZERO, Quat::IDENTITY, Vec3::splat(visible)),
                    ..Node::default()
                });
                self.attach(outer, inner);
                self.animate_visibility(inner, tr);
                inner
            }
        };

        let mut primitives = Vec::new();
        for batch in an.batches.iter().filter(|b| !b.indices.is_empty()) {
            primitives.push(Primitive {
                positions: batch.positions.clone(),
                normals: batch.normals.clone(),
                uvs: batch.uvs.clone(),
                triangles: batch
                    .indices
                    .chunks_exact(3)
                    .map(|t| [t[0], t[1], t[2]])
                    .collect(),
                material: self.material(batch.material, batch.texture),
                ..Primitive::default()
            });
        }
        if !primitives.is_empty() {
            self.s.meshes.push(Mesh {
                name: None,
                primitives,
                weights: Vec::new(),
            });
            self.s.nodes[content].mesh = Some(self.s.meshes.len() - 1);
        }
        for mb in an.morphs.iter().filter(|m| m.triangle_count() > 0) {
            let n = self.morph(mb);
            self.attach(content, n);
        }
        for &child in &an.children {
            let n = self.node(child)?;
            self.attach(content, n);
        }
        Ok(outer)
    }

    /// A node whose mesh morphs through the keys of `mb`: target `k` is key `k+1` minus
    /// key 0, and weights `e_{j-1}·(1−f) + e_j·f` between keys `j` and `j+1`.
    fn morph(&mut self, mb: &MorphBatch) -> usize {
        let keys = mb.times.len();
        let base = &mb.positions[0];
        let base_n = &mb.normals[0];
        let diff = |a: &[Vec3], b: &[Vec3]| -> Vec<Vec3> {
            a.iter().zip(b).map(|(p, q)| *p - *q).collect()
        };
        let morph_targets: Vec<MorphTarget> = (1..keys)
            .map(|k| MorphTarget {
                positions: diff(&mb.positions[k], base),
                normals: diff(&mb.normals[k], base_n),
            })
            .collect();
        let weights_at = |t: f64| -> Vec<f32> {
            let mut w = vec![0.0f32; keys - 1];
            let (a, b, f) = mb.bracket(t);
            if a > 0 {
                w[a - 1] += (1.0 - f) as f32;
            }
            if b > 0 {
                w[b - 1] += f as f32;
            }
            w
        };
        let material = self.material(mb.material, None);
        let n = base.len() as u32;
        self.s.meshes.push(Mesh {
            name: Some("tpa".into()),
            primitives: vec![Primitive {
                positions: base.clone(),
                normals: Some(base_n.clone()),
                uvs: None,
                // Consecutive vertices form triangles.
                triangles: (0..n / 3).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect(),
                material,
                morph_targets,
                ..Primitive::default()
            }],
            weights: weights_at(self.rest),
        });
        let node = self.add_node(Node {
            name: Some("tpa".into()),
            mesh: Some(self.s.meshes.len() - 1),
            ..Node::default()
        });
        if let Some(fr) = &self.frames {
            // Keys at or before t0 collapse into one key at time 0 (the value at t0);
            // later keys keep their times (exact: weights are linear between keys).
            let mut times = vec![0.0f32];
            let mut values = weights_at(fr.t0);
            for &k in &mb.times {
                let g = (k - fr.t0) as f32;
                if g > times.last().copied().unwrap_or(0.0) {
                    times.push(g);
                    values.extend(weights_at(k));
                }
            }
            self.channels.push(Channel {
                node,
                property: Property::Weights,
                interpolation: Interpolation::Linear,
                times,
                values,
            });
        }
        node
    }

    fn camera(&mut self) {
        let aff = self.aff;
        let Some(cam) = aff.camera_at(self.rest) else {
            return;
        };
        self.s.cameras.push(CameraDef {
            name: Some("camera".into()),
            projection: Projection::Perspective {
                yfov: cam.yfov,
                aspect: cam.aspect,
                znear: cam.znear,
                zfar: None,
            },
        });
        let node = self.add_node(Node {
            name: Some("camera".into()),
            transform: trs(
                cam.position.as_vec3(),
                rest_rotation(cam.rotation),
                Vec3::ONE,
            ),
            camera: Some(self.s.cameras.len() - 1),
            ..Node::default()
        });
        self.s.roots.push(node);
        if let Some(tr) = aff.tracks.get("camera") {
            if !tr.translation.is_empty() {
                self.sampled(node, Property::Translation, |t| {
                    aff.camera_at(t)
                        .map_or([0.0; 3], |c| c.position.as_vec3().to_array())
                        .to_vec()
                });
            }
            if !tr.rotation.is_empty() {
                self.sampled_rotation(node, |t| {
                    aff.camera_at(t)
                        .map_or(Quat::IDENTITY, |c| f32q(c.rotation))
                });
            }
        }
    }

    fn lights(&mut self) {
        let aff = self.aff;
        for (i, l) in aff.lights.iter().enumerate() {
            self.s.lights.push(LightDef {
                name: l.name.clone().or_else(|| Some(format!("light {i}"))),
                kind: LightKind::Point,
                color: l.color,
                // NFF/AFF shade a light as `diffuse · colour · N·L` at any distance; the
                // renderer's `kd/π · E · cos` gives that with `E = π` and no falloff.
                intensity: std::f32::consts::PI,
                range: None,
                falloff: Falloff::None,
            });
            let tracks = l
                .name
                .as_ref()
                .and_then(|n| aff.tracks.get(n))
                .filter(|tr| !tr.translation.is_empty());
            let position = tracks
                .and_then(|tr| tr.translation_at(self.rest))
                .map_or(l.position, |p| p.as_vec3());
            let node = self.add_node(Node {
                name: l.name.clone(),
                transform: trs(position, Quat::IDENTITY, Vec3::ONE),
                light: Some(self.s.lights.len() - 1),
                ..Node::default()
            });
            self.s.roots.push(node);
            if let Some(tr) = tracks {
                self.sampled(node, Property::Translation, |t| {
                    tr.translation_at(t)
                        .unwrap_or(DVec3::ZERO)
                        .as_vec3()
                        .to_array()
                        .to_vec()
                });
            }
        }
    }
}
