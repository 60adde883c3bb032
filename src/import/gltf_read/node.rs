//! The node hierarchy (transforms, parents), skins, camera definitions and
//! `KHR_lights_punctual` lights.

use glam::{Mat4, Quat, Vec3};

use super::{ImportError, Importer};
use crate::scene::{CameraDef, LightDef, LightKind, Node, NodeTransform, Projection, Skin, Trs};

impl Importer<'_> {
    pub(super) fn nodes(&self) -> Result<Vec<Node>, ImportError> {
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
                        return Err(ImportError::Node {
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
                    return Err(ImportError::Node {
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

    pub(super) fn skins(&self) -> Result<Vec<Skin>, ImportError> {
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

    /// Camera definitions (placed later by the nodes that reference them).
    pub(super) fn cameras(&self) -> Vec<CameraDef> {
        self.doc
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
            .collect()
    }

    pub(super) fn lights(&self) -> Vec<LightDef> {
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
}
