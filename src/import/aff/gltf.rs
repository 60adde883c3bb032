//! [`AffScene`] → glTF ([`GltfBuilder`]). The mapping is described in the module docs of
//! [`crate::import::aff`]; materials in [`material_desc`].

use std::collections::HashMap;

use glam::{DQuat, DVec3, Quat, Vec3, Vec4};
use serde_json::json;

use super::{AffMaterial, AffScene, AffTexture, AffTransform, ImportError, MorphBatch, Tracks};
use crate::import::{
    AnimationDesc, CameraDesc, ChannelDesc, GltfBuilder, ImageDesc, MaterialDesc, MeshDesc,
    NodeDesc, PrimitiveDesc, TextureDesc,
};
use crate::scene::{Interpolation, LightDef, LightKind, Property};

/// The glTF material of an AFF material (with an optional base colour texture index):
///
/// | glTF | from AFF |
/// |---|---|
/// | `baseColorFactor` | diffuse colour (`f`: colour·Kd), clamped to [0, 1]; alpha 1. A texture is multiplied by it, as glTF does |
/// | `metallicFactor` | mirror weight: the largest specular component (`f`: Ks), clamped — a Whitted renderer's reflection coefficient |
/// | `roughnessFactor` | `(2/(shine+2))^¼` (Phong exponent → Beckmann-like α = √(2/(n+2)), roughness = √α); 1 for shine ≤ 0 |
/// | `KHR_materials_transmission` | `T`, clamped to [0, 1] |
/// | `KHR_materials_ior` | `ior` when ≥ 1 (AFF files write 0 for opaque surfaces: the glTF default 1.5 is kept) |
/// | `doubleSided` | when `T > 0` (AFF: transmissive surfaces are two-sided) |
/// | `extras.aff` | the exact AFF numbers: ambient, diffuse, specular, shine, T, ior |
///
/// AFF's per-material ambient colour has no glTF counterpart (kept in `extras`).
pub fn material_desc(m: &AffMaterial, texture: Option<u32>) -> MaterialDesc {
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
    MaterialDesc {
        name: None,
        base_color: Vec4::new(
            clamp01(m.diffuse.x),
            clamp01(m.diffuse.y),
            clamp01(m.diffuse.z),
            1.0,
        ),
        base_color_texture: texture,
        metallic: clamp01(m.specular.max_element()),
        roughness: clamp01(roughness),
        emissive: Vec3::ZERO,
        transmission: clamp01(m.transmittance),
        ior: if m.ior >= 1.0 { m.ior } else { 1.5 },
        double_sided: m.transmittance > 0.0,
        extras: Some(json!({ "aff": {
            "ambient": m.ambient.to_array(),
            "diffuse": m.diffuse.to_array(),
            "specular": m.specular.to_array(),
            "shine": m.shine,
            "transmittance": m.transmittance,
            "ior": m.ior,
        }})),
    }
}

/// Frame sampling: AFF times of the frames and their glTF key times (AFF − t0).
struct Frames {
    t0: f64,
    aff: Vec<f64>,
    keys: Vec<f32>,
}

struct Conv<'a> {
    aff: &'a AffScene,
    b: GltfBuilder,
    channels: Vec<ChannelDesc>,
    frames: Option<Frames>,
    rest: f64,
    materials: HashMap<(u32, Option<u32>), u32>,
    textures: HashMap<u32, u32>,
}

pub(super) fn to_gltf(aff: &AffScene) -> Result<GltfBuilder, ImportError> {
    let bad = |reason: String| ImportError::Convert {
        path: aff.source.clone(),
        reason,
    };
    let mut b = GltfBuilder::new();
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
                b.fps = Some(fps as f32);
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
    b.scene_extras.insert(
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
        b,
        channels: Vec::new(),
        frames,
        rest: aff.rest_time(),
        materials: HashMap::new(),
        textures: HashMap::new(),
    };
    let root = c.node(0)?;
    c.b.add_root(root);
    c.camera();
    c.lights();
    let channels = std::mem::take(&mut c.channels);
    if !channels.is_empty() {
        c.b.add_animation(AnimationDesc {
            name: Some("aff".into()),
            channels,
        });
    }
    Ok(c.b)
}

fn f32q(q: DQuat) -> Quat {
    let q = q.as_quat();
    let l = q.length();
    if l > 0.0 && l.is_finite() {
        q / l
    } else {
        Quat::IDENTITY
    }
}

/// Encodes an RGB8 image as PNG (fast compression: it is decoded again at once).
fn png(t: &AffTexture) -> Result<Vec<u8>, String> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder;
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Sub)
        .write_image(&t.rgb8, t.width, t.height, image::ExtendedColorType::Rgb8)
        .map_err(|e| e.to_string())?;
    Ok(out)
}

impl Conv<'_> {
    fn material(&mut self, material: u32, texture: Option<u32>) -> Result<u32, ImportError> {
        if let Some(&m) = self.materials.get(&(material, texture)) {
            return Ok(m);
        }
        let tex = match texture {
            None => None,
            Some(t) => Some(match self.textures.get(&t) {
                Some(&g) => g,
                None => {
                    let src = &self.aff.textures[t as usize];
                    let bytes = png(src).map_err(|reason| ImportError::Convert {
                        path: self.aff.source.clone(),
                        reason: format!("texture {:?}: {reason}", src.name),
                    })?;
                    let image = self.b.add_image(ImageDesc {
                        name: Some(src.name.clone()),
                        mime_type: "image/png".into(),
                        bytes,
                    });
                    let g = self.b.add_texture(TextureDesc { image });
                    self.textures.insert(t, g);
                    g
                }
            }),
        };
        let desc = material_desc(&self.aff.materials[material as usize], tex);
        let m = self.b.add_material(desc);
        self.materials.insert((material, texture), m);
        Ok(m)
    }

    /// Samples `f` at every frame into a LINEAR channel of `node` (nothing without frames).
    fn sampled(&mut self, node: u32, property: Property, f: impl Fn(f64) -> Vec<f32>) {
        let Some(fr) = &self.frames else { return };
        let values: Vec<f32> = fr.aff.iter().flat_map(|&t| f(t)).collect();
        self.channels.push(ChannelDesc {
            node,
            property,
            interpolation: Interpolation::Linear,
            times: fr.keys.clone(),
            values,
        });
    }

    /// Rotations at every frame, each in the hemisphere of the previous one.
    fn sampled_rotation(&mut self, node: u32, f: impl Fn(f64) -> Quat) {
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
        self.channels.push(ChannelDesc {
            node,
            property: Property::Rotation,
            interpolation: Interpolation::Linear,
            times: fr.keys.clone(),
            values,
        });
    }

    fn animate_trs(&mut self, node: u32, tr: &Tracks) {
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
    fn animate_visibility(&mut self, node: u32, tr: &Tracks) {
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
        self.channels.push(ChannelDesc {
            node,
            property: Property::Scale,
            interpolation: Interpolation::Step,
            times,
            values,
        });
    }

    /// One glTF node per AFF block (two with a visibility track), its batches as one mesh,
    /// its animated batches as child nodes with morph targets, then its sub-blocks.
    fn node(&mut self, index: usize) -> Result<u32, ImportError> {
        let aff = self.aff;
        let an = &aff.nodes[index];
        let mut desc = NodeDesc::default();
        let mut tracks = None;
        match &an.transform {
            AffTransform::Root => desc.name = Some("aff".into()),
            AffTransform::Static {
                scale,
                axis,
                angle,
                translation,
            } => {
                desc.scale = *scale;
                desc.rotation = f32q(super::spline::key_quat(
                    axis.as_dvec3(),
                    f64::from(*angle).to_radians(),
                ));
                desc.translation = *translation;
            }
            AffTransform::Animated(name) => {
                desc.name = Some(name.clone());
                if let Some(tr) = aff.tracks.get(name) {
                    let t = self.rest;
                    desc.translation = tr.translation_at(t).unwrap_or(DVec3::ZERO).as_vec3();
                    desc.rotation = f32q(tr.rotation_at(t).unwrap_or(DQuat::IDENTITY));
                    desc.scale = tr.scale_at(t).unwrap_or(DVec3::ONE).as_vec3();
                    tracks = Some(tr);
                }
            }
        }
        let outer = self.b.add_node(desc);
        if let Some(tr) = tracks {
            self.animate_trs(outer, tr);
        }
        let content = match tracks.filter(|tr| !tr.visibility.is_empty()) {
            None => outer,
            Some(tr) => {
                let visible = tr.visible_at(self.rest);
                let inner = self.b.add_node(NodeDesc {
                    name: Some(format!(
                        "{}:visibility",
                        self.b.nodes[outer as usize]
                            .name
                            .clone()
                            .unwrap_or_default()
                    )),
                    scale: if visible { Vec3::ONE } else { Vec3::ZERO },
                    ..NodeDesc::default()
                });
                self.b.nodes[outer as usize].children.push(inner);
                self.animate_visibility(inner, tr);
                inner
            }
        };

        let mut primitives = Vec::new();
        for batch in an.batches.iter().filter(|b| !b.indices.is_empty()) {
            primitives.push(PrimitiveDesc {
                positions: batch.positions.clone(),
                normals: batch.normals.clone(),
                uvs: batch.uvs.clone(),
                indices: Some(batch.indices.clone()),
                material: Some(self.material(batch.material, batch.texture)?),
                ..PrimitiveDesc::default()
            });
        }
        if !primitives.is_empty() {
            let mesh = self.b.add_mesh(MeshDesc {
                name: None,
                primitives,
                weights: Vec::new(),
            });
            self.b.nodes[content as usize].mesh = Some(mesh);
        }
        for mb in an.morphs.iter().filter(|m| m.triangle_count() > 0) {
            let n = self.morph(mb)?;
            self.b.nodes[content as usize].children.push(n);
        }
        for &child in &an.children {
            let n = self.node(child)?;
            self.b.nodes[content as usize].children.push(n);
        }
        Ok(outer)
    }

    /// A node whose mesh morphs through the keys of `mb`: target `k` is key `k+1` minus
    /// key 0, and weights `e_{j-1}·(1−f) + e_j·f` between keys `j` and `j+1`.
    fn morph(&mut self, mb: &MorphBatch) -> Result<u32, ImportError> {
        let keys = mb.times.len();
        let base = &mb.positions[0];
        let base_n = &mb.normals[0];
        let targets: Vec<Vec<Vec3>> = (1..keys)
            .map(|k| {
                mb.positions[k]
                    .iter()
                    .zip(base)
                    .map(|(p, q)| *p - *q)
                    .collect()
            })
            .collect();
        let target_normals: Vec<Vec<Vec3>> = (1..keys)
            .map(|k| {
                mb.normals[k]
                    .iter()
                    .zip(base_n)
                    .map(|(p, q)| *p - *q)
                    .collect()
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
        let material = self.material(mb.material, None)?;
        let mesh = self.b.add_mesh(MeshDesc {
            name: Some("tpa".into()),
            primitives: vec![PrimitiveDesc {
                positions: base.clone(),
                normals: Some(base_n.clone()),
                uvs: None,
                indices: None,
                material: Some(material),
                morph_targets: targets,
                morph_normals: target_normals,
            }],
            weights: weights_at(self.rest),
        });
        let node = self.b.add_node(NodeDesc {
            name: Some("tpa".into()),
            mesh: Some(mesh),
            ..NodeDesc::default()
        });
        if let Some(fr) = &self.frames {
            // Keys at or before t0 collapse into one key at glTF time 0 (the value at t0);
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
            self.channels.push(ChannelDesc {
                node,
                property: Property::Weights,
                interpolation: Interpolation::Linear,
                times,
                values,
            });
        }
        Ok(node)
    }

    fn camera(&mut self) {
        let aff = self.aff;
        let Some(cam) = aff.camera_at(self.rest) else {
            return;
        };
        let c = self.b.add_camera(CameraDesc {
            name: Some("camera".into()),
            yfov: cam.yfov,
            aspect: cam.aspect,
            znear: cam.znear,
            zfar: None,
        });
        let node = self.b.add_node(NodeDesc {
            name: Some("camera".into()),
            translation: cam.position.as_vec3(),
            rotation: f32q(cam.rotation),
            camera: Some(c),
            ..NodeDesc::default()
        });
        self.b.add_root(node);
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
            let light = self.b.add_light(LightDef {
                name: l.name.clone().or_else(|| Some(format!("light {i}"))),
                kind: LightKind::Point,
                color: l.color,
                intensity: 1.0,
                range: None,
            });
            let tracks = l
                .name
                .as_ref()
                .and_then(|n| aff.tracks.get(n))
                .filter(|tr| !tr.translation.is_empty());
            let position = tracks
                .and_then(|tr| tr.translation_at(self.rest))
                .map_or(l.position, |p| p.as_vec3());
            let node = self.b.add_node(NodeDesc {
                name: l.name.clone(),
                translation: position,
                light: Some(light),
                ..NodeDesc::default()
            });
            self.b.add_root(node);
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
